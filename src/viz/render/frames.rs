//! Frame dumps: pictures of the simulation rendered offscreen and written as PNG files.
//!
//! A picture is drawn on the GPU and copied into a staging buffer in the same submission; the
//! simulation goes on while the copy is mapped, and PNG encoding and writing happen on a thread
//! of their own, so a frame costs the simulation little more than the drawing itself.

use super::{ParticleBuffers, RenderOptions, Renderer};
use crate::io::atomic::write_atomic;
use crate::io::rundir::frame_file_name;
use crate::model::scene::Scene;
use crate::solver::gpu::GpuContext;
use crate::solver::Backend;
use anyhow::Context;
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::{mpsc, Arc};

/// Offscreen pictures are sRGB RGBA8.
pub const FRAME_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
/// Pictures in flight between the GPU and the encoder before the simulation waits.
const MAX_IN_FLIGHT: usize = 3;

/// The file of frame `index`: `DIR/frame_00000.png`.
pub fn frame_path(dir: &Path, index: u64) -> PathBuf {
    dir.join(frame_file_name(index))
}

/// A picture read back from the GPU: tightly packed RGBA8, rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct Picture {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<u8>,
}

impl Picture {
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 4] {
        let i = 4 * (y as usize * self.width as usize + x as usize);
        [self.rgba[i], self.rgba[i + 1], self.rgba[i + 2], self.rgba[i + 3]]
    }

    /// Encodes the picture as an RGB PNG.
    pub fn png_bytes(&self) -> anyhow::Result<Vec<u8>> {
        let rgb: Vec<u8> = self.rgba.chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
        let mut out = Vec::new();
        image::ImageEncoder::write_image(
            image::codecs::png::PngEncoder::new(&mut out),
            &rgb,
            self.width,
            self.height,
            image::ExtendedColorType::Rgb8,
        )?;
        Ok(out)
    }

    pub fn write_png(&self, path: &Path) -> anyhow::Result<()> {
        let bytes = self.png_bytes()?;
        write_atomic(path, |w| w.write_all(&bytes))
    }
}

const MAP_PENDING: u8 = 0;
const MAP_DONE: u8 = 1;
const MAP_FAILED: u8 = 2;

/// A copy of a picture on its way to the host.
struct InFlight {
    buffer: wgpu::Buffer,
    state: Arc<AtomicU8>,
    submission: wgpu::SubmissionIndex,
    path: PathBuf,
}

/// An offscreen colour target with its read-back machinery.
pub struct Offscreen {
    pub renderer: Renderer,
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    padded_row: u32,
    spare: Vec<wgpu::Buffer>,
}

impl Offscreen {
    pub fn new(ctx: &GpuContext, options: RenderOptions, scene: &Scene, walls: &[[f64; 3]]) -> Self {
        let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("frame"),
            size: wgpu::Extent3d { width: options.width, height: options.height, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: FRAME_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&Default::default());
        let padded_row = (options.width * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let renderer = Renderer::new(ctx, FRAME_FORMAT, options, scene, walls);
        Offscreen { renderer, texture, view, padded_row, spare: Vec::new() }
    }

    /// Draws `particles` and submits the copy into a staging buffer; returns the buffer and the
    /// submission that fills it.
    fn submit(&mut self, particles: &ParticleBuffers) -> (wgpu::Buffer, wgpu::SubmissionIndex) {
        let device = self.renderer.device().clone();
        let o = &self.renderer.options;
        let (w, h) = (o.width, o.height);
        let buffer = self.spare.pop().unwrap_or_else(|| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("frame staging"),
                size: self.padded_row as u64 * h as u64,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        });
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") });
        self.renderer.encode(&mut encoder, &self.view, particles);
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo { texture: &self.texture, mip_level: 0, origin: wgpu::Origin3d::ZERO, aspect: wgpu::TextureAspect::All },
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(self.padded_row), rows_per_image: Some(h) },
            },
            wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
        );
        let submission = self.renderer.queue().submit([encoder.finish()]);
        (buffer, submission)
    }

    /// Copies the rows out of a mapped staging buffer and puts the buffer back for reuse.
    fn unpack(&mut self, buffer: wgpu::Buffer) -> Picture {
        let o = &self.renderer.options;
        let (w, h) = (o.width, o.height);
        let mut rgba = Vec::with_capacity((w * h * 4) as usize);
        {
            let data = buffer.slice(..).get_mapped_range().expect("the buffer was mapped");
            for row in data.chunks(self.padded_row as usize).take(h as usize) {
                rgba.extend_from_slice(&row[..(w * 4) as usize]);
            }
        }
        buffer.unmap();
        self.spare.push(buffer);
        Picture { width: w, height: h, rgba }
    }

    /// Draws `particles` and waits for the picture.
    pub fn picture(&mut self, particles: &ParticleBuffers) -> anyhow::Result<Picture> {
        let (buffer, submission) = self.submit(particles);
        let (tx, rx) = mpsc::channel();
        buffer.slice(..).map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.renderer.device().poll(wgpu::PollType::Wait { submission_index: Some(submission), timeout: None })?;
        self.renderer.check_device()?;
        rx.recv()?.context("mapping the frame for reading")?;
        Ok(self.unpack(buffer))
    }
}

/// Where a backend's particles come from for a picture: its own GPU buffers, or a snapshot
/// uploaded from the host.
pub fn particles_of(backend: &mut dyn Backend, renderer: &mut Renderer) -> anyhow::Result<ParticleBuffers> {
    match backend.gpu_particles() {
        Some(p) => Ok(p.into()),
        None => {
            let s = backend.snapshot()?;
            Ok(renderer.upload(&s))
        }
    }
}

/// The device frames are drawn with: the backend's own, or (for the CPU backend) a new one.
pub fn render_context(backend: &dyn Backend) -> anyhow::Result<GpuContext> {
    match backend.gpu_particles() {
        Some(p) => Ok(p.context),
        None => GpuContext::new().context("rendering frames needs a GPU adapter (a software one such as llvmpipe serves)"),
    }
}

struct EncodeJob {
    path: PathBuf,
    picture: Picture,
}

/// Writes a picture of the simulation every `every` steps to `dir`.
pub struct FrameRecorder {
    offscreen: Offscreen,
    pub dir: PathBuf,
    pub every: u64,
    next_index: u64,
    in_flight: VecDeque<InFlight>,
    jobs: Option<mpsc::SyncSender<EncodeJob>>,
    encoder: Option<std::thread::JoinHandle<anyhow::Result<u64>>>,
}

impl FrameRecorder {
    pub fn new(backend: &dyn Backend, scene: &Scene, options: RenderOptions, dir: PathBuf, every: u64) -> anyhow::Result<Self> {
        let ctx = render_context(backend)?;
        std::fs::create_dir_all(&dir).with_context(|| format!("cannot create the frame directory {}", dir.display()))?;
        let walls = scene.initial_state().wall_positions;
        let offscreen = Offscreen::new(&ctx, options, scene, &walls);
        let (tx, rx) = mpsc::sync_channel::<EncodeJob>(2);
        let encoder = std::thread::Builder::new().name("png encoder".into()).spawn(move || -> anyhow::Result<u64> {
            let mut written = 0;
            for job in rx {
                job.picture.write_png(&job.path)?;
                written += 1;
            }
            Ok(written)
        })?;
        Ok(FrameRecorder { offscreen, dir, every, next_index: 0, in_flight: VecDeque::new(), jobs: Some(tx), encoder: Some(encoder) })
    }

    /// Draws the backend's current state and queues the picture for writing.
    pub fn capture(&mut self, backend: &mut dyn Backend) -> anyhow::Result<()> {
        let renderer = &mut self.offscreen.renderer;
        let particles = if renderer.options.style == super::Style::Mesh {
            // The surface is reconstructed on the host, from a snapshot.
            let s = backend.snapshot()?;
            renderer.reconstruct_mesh(&s)?;
            match backend.gpu_particles() {
                Some(p) => p.into(),
                None => renderer.upload(&s),
            }
        } else {
            particles_of(backend, renderer)?
        };
        let (buffer, submission) = self.offscreen.submit(&particles);
        let state = Arc::new(AtomicU8::new(MAP_PENDING));
        let flag = state.clone();
        buffer.slice(..).map_async(wgpu::MapMode::Read, move |r| {
            flag.store(if r.is_ok() { MAP_DONE } else { MAP_FAILED }, Ordering::Release);
        });
        let path = frame_path(&self.dir, self.next_index);
        self.next_index += 1;
        self.in_flight.push_back(InFlight { buffer, state, submission, path });
        self.drain(self.in_flight.len() > MAX_IN_FLIGHT)
    }

    /// Hands every picture that has arrived to the encoder; with `wait`, first waits for the
    /// oldest one.
    fn drain(&mut self, wait: bool) -> anyhow::Result<()> {
        let device = self.offscreen.renderer.device().clone();
        if wait {
            if let Some(oldest) = self.in_flight.front() {
                device.poll(wgpu::PollType::Wait { submission_index: Some(oldest.submission.clone()), timeout: None })?;
            }
        } else {
            device.poll(wgpu::PollType::Poll)?;
        }
        self.offscreen.renderer.check_device()?;
        while let Some(front) = self.in_flight.front() {
            match front.state.load(Ordering::Acquire) {
                MAP_PENDING => break,
                MAP_FAILED => anyhow::bail!("mapping frame {} for reading failed", front.path.display()),
                _ => {}
            }
            let f = self.in_flight.pop_front().expect("front exists");
            let picture = self.offscreen.unpack(f.buffer);
            let sent = self.jobs.as_ref().map(|tx| tx.send(EncodeJob { path: f.path, picture }).is_ok()).unwrap_or(false);
            if !sent {
                // The encoder stopped: its error says why.
                return Err(self.join().err().unwrap_or_else(|| anyhow::anyhow!("the PNG encoder stopped")));
            }
        }
        Ok(())
    }

    fn join(&mut self) -> anyhow::Result<u64> {
        self.jobs = None;
        match self.encoder.take() {
            Some(h) => h.join().map_err(|_| anyhow::anyhow!("the PNG encoder panicked"))?,
            None => Ok(0),
        }
    }

    /// Waits for every picture to be written; returns how many were.
    pub fn finish(mut self) -> anyhow::Result<u64> {
        while !self.in_flight.is_empty() {
            self.drain(true)?;
        }
        self.join()
    }

    pub fn frames_started(&self) -> u64 {
        self.next_index
    }
}

impl Drop for FrameRecorder {
    /// A recorder given up (the run failed) still lets its encoder finish the picture it is
    /// writing, so that no file appears after the run has cleaned up.
    fn drop(&mut self) {
        let _ = self.join();
    }
}
