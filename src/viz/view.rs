//! `wgsph view`: a window (winit) that runs the simulation on the GPU and draws every frame from
//! the simulation's own buffers, with an orbit camera and pause / step / reset keys.

use crate::model::scene::Scene;
use crate::solver::gpu::device::{backends, best_first, choose_from};
use crate::solver::gpu::GpuContext;
use crate::solver::{open, BackendChoice, Simulation};
use crate::viz::render::frames::Picture;
use crate::viz::render::{RenderOptions, Renderer};
use anyhow::Context;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::keyboard::{Key, NamedKey};
use winit::window::{Window, WindowId};

/// What `wgsph view` was asked for.
pub struct ViewOptions {
    pub picture: RenderOptions,
    /// Simulation steps between two drawn frames.
    pub steps_per_frame: u64,
    /// Save the picture of frame number `quit_after` here.
    pub screenshot: Option<PathBuf>,
    /// Close the window after this many frames (for scripts and tests).
    pub quit_after: Option<u64>,
}

/// Frames between two reads of the health counters and the simulated time.
const CHECK_EVERY_FRAMES: u64 = 8;

pub const KEYS_HELP: &str = "left drag: orbit, wheel: zoom, space: pause/run, n: one frame's steps while paused, r: reset, esc or q: quit";

struct Gfx {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    ctx: GpuContext,
    sim: Simulation,
    renderer: Renderer,
}

struct App {
    scene: Scene,
    opts: ViewOptions,
    instance: wgpu::Instance,
    gfx: Option<Gfx>,
    error: Option<anyhow::Error>,
    paused: bool,
    step_once: bool,
    dragging: bool,
    cursor: Option<(f64, f64)>,
    frames: u64,
    /// Simulated time at the last check of the health counters.
    sim_time: f64,
    rate_since: Instant,
    rate_steps: u64,
    steps_per_second: f64,
    failure: Option<String>,
}

/// Opens the window and runs until it is closed. Returns the exit code (1 when the simulation
/// went bad).
pub fn view(scene: Scene, opts: ViewOptions) -> anyhow::Result<i32> {
    let event_loop = EventLoop::new().map_err(|e| {
        // Without a display the windowing library's message names its own source file; the
        // cause is plain, and so is the remedy.
        let no_display = cfg!(all(unix, not(target_os = "macos"))) && ["DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"].iter().all(|v| std::env::var_os(v).is_none());
        if no_display {
            anyhow::anyhow!("cannot open a window: no display (set DISPLAY or WAYLAND_DISPLAY; on a headless machine run under Xvfb, see docs/pictures.md)")
        } else {
            anyhow::anyhow!("cannot open a window: {e}")
        }
    })?;
    let mut desc = wgpu::InstanceDescriptor::new_with_display_handle_from_env(Box::new(event_loop.owned_display_handle()));
    desc.backends = backends();
    let instance = wgpu::Instance::new(desc);
    let mut app = App {
        scene,
        opts,
        instance,
        gfx: None,
        error: None,
        paused: false,
        step_once: false,
        dragging: false,
        cursor: None,
        frames: 0,
        sim_time: 0.0,
        rate_since: Instant::now(),
        rate_steps: 0,
        steps_per_second: 0.0,
        failure: None,
    };
    println!("wgsph view: {KEYS_HELP}");
    event_loop.run_app(&mut app).context("the window's event loop failed")?;
    if let Some(e) = app.error {
        return Err(e);
    }
    Ok(if app.failure.is_some() { 1 } else { 0 })
}

impl App {
    fn init(&mut self, event_loop: &ActiveEventLoop) -> anyhow::Result<()> {
        let (w, h) = (self.opts.picture.width, self.opts.picture.height);
        let attrs = Window::default_attributes().with_title(format!("wgsph: {}", self.scene.name)).with_inner_size(PhysicalSize::new(w, h));
        let window = Arc::new(event_loop.create_window(attrs).context("cannot create the window")?);
        let surface = self.instance.create_surface(window.clone()).context("cannot draw into the window")?;
        let candidates = pollster::block_on(self.instance.enumerate_adapters(backends()));
        let usable: Vec<wgpu::Adapter> = candidates.into_iter().filter(|a| a.is_surface_supported(&surface)).collect();
        let adapter = choose_from(best_first(usable)).context("no GPU adapter can both compute and draw into this window")?;
        let ctx = GpuContext::from_adapter(adapter)?;
        let size = window.inner_size();
        let caps = surface.get_capabilities(&ctx.adapter);
        let format = caps.formats.iter().copied().find(|f| f.is_srgb()).or(caps.formats.first().copied()).context("the window offers no format")?;
        // COPY_SRC lets a screenshot read back exactly what was presented.
        let usage = if caps.usages.contains(wgpu::TextureUsages::COPY_SRC) {
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC
        } else {
            wgpu::TextureUsages::RENDER_ATTACHMENT
        };
        let config = wgpu::SurfaceConfiguration {
            usage,
            format,
            color_space: wgpu::SurfaceColorSpace::Auto,
            width: size.width.max(1),
            height: size.height.max(1),
            present_mode: wgpu::PresentMode::AutoVsync,
            desired_maximum_frame_latency: 2,
            alpha_mode: wgpu::CompositeAlphaMode::Auto,
            view_formats: vec![],
        };
        surface.configure(&ctx.device, &config);
        let init = self.scene.initial_state();
        let sim = open(&self.scene, &BackendChoice::gpu_on(ctx.clone()))?;
        let mut picture = self.opts.picture.clone();
        picture.width = config.width;
        picture.height = config.height;
        let renderer = Renderer::new(&ctx, format, picture, &self.scene, &init.wall_positions);
        println!("drawing on {}", ctx.describe());
        self.gfx = Some(Gfx { window, surface, config, ctx, sim, renderer });
        Ok(())
    }

    fn reset(&mut self) -> anyhow::Result<()> {
        if let Some(g) = &mut self.gfx {
            g.sim = open(&self.scene, &BackendChoice::gpu_on(g.ctx.clone()))?;
            self.failure = None;
            self.sim_time = 0.0;
            self.rate_steps = 0;
            self.rate_since = Instant::now();
        }
        Ok(())
    }

    fn frame(&mut self, event_loop: &ActiveEventLoop) -> anyhow::Result<()> {
        let Some(g) = &mut self.gfx else { return Ok(()) };
        if self.failure.is_none() && (!self.paused || self.step_once) {
            g.sim.step(self.opts.steps_per_frame)?;
            self.rate_steps += self.opts.steps_per_frame;
            // Reading the counters waits for the GPU: every few frames, and after a single step.
            if self.step_once || self.frames % CHECK_EVERY_FRAMES == 0 {
                let health = g.sim.health()?;
                self.sim_time = g.sim.time();
                if !health.is_ok() {
                    let scene = g.sim.scene().clone();
                    let why = crate::solver::backend::diagnose_failure(g.sim.backend(), &scene)?;
                    eprintln!("error: the simulation went bad at {why}");
                    self.failure = Some(why);
                }
            }
            self.step_once = false;
        }
        let texture = match g.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                g.surface.configure(&g.ctx.device, &g.config);
                return Ok(());
            }
            _ => return Ok(()),
        };
        let view = texture.texture.create_view(&Default::default());
        let particles: crate::viz::render::ParticleBuffers = g.sim.particle_buffers().expect("the viewer runs the GPU solver")?.into();
        let mut encoder = g.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("view frame") });
        g.renderer.encode(&mut encoder, &view, &particles);
        self.frames += 1;
        let last = self.opts.quit_after.is_some_and(|n| self.frames >= n);
        let shot = if last && self.opts.screenshot.is_some() {
            if g.config.usage.contains(wgpu::TextureUsages::COPY_SRC) {
                Some(read_texture(g, &texture.texture, encoder)?)
            } else {
                // This surface cannot be copied from (OpenGL): the same picture is drawn a
                // second time into a texture that can.
                let copy = g.ctx.device.create_texture(&wgpu::TextureDescriptor {
                    label: Some("screenshot"),
                    size: wgpu::Extent3d { width: g.config.width, height: g.config.height, depth_or_array_layers: 1 },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: g.config.format,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
                    view_formats: &[],
                });
                g.renderer.encode(&mut encoder, &copy.create_view(&Default::default()), &particles);
                Some(read_texture(g, &copy, encoder)?)
            }
        } else {
            g.ctx.queue.submit([encoder.finish()]);
            None
        };
        g.window.pre_present_notify();
        g.ctx.queue.present(texture);
        if let (Some(picture), Some(path)) = (shot, &self.opts.screenshot) {
            picture.write_png(path)?;
            println!("screenshot {}", path.display());
        }
        let elapsed = self.rate_since.elapsed().as_secs_f64();
        if elapsed >= 0.5 {
            self.steps_per_second = self.rate_steps as f64 / elapsed;
            self.rate_steps = 0;
            self.rate_since = Instant::now();
        }
        let state = if self.failure.is_some() {
            " [stopped: the state went bad]"
        } else if self.paused {
            " [paused]"
        } else {
            ""
        };
        g.window.set_title(&format!(
            "wgsph: {} | {} particles | {:.0} steps/s | t = {:.3} s{}",
            self.scene.name,
            g.sim.fluid_count(),
            self.steps_per_second,
            self.sim_time,
            state
        ));
        if last {
            event_loop.exit();
        } else {
            g.window.request_redraw();
        }
        Ok(())
    }
}

/// Copies the window's texture to the host (before it is presented).
fn read_texture(g: &Gfx, texture: &wgpu::Texture, mut encoder: wgpu::CommandEncoder) -> anyhow::Result<Picture> {
    let (w, h) = (g.config.width, g.config.height);
    let padded = (w * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
    let buffer = g.ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("screenshot"),
        size: padded as u64 * h as u64,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo { texture, mip_level: 0, origin: wgpu::Origin3d::ZERO, aspect: wgpu::TextureAspect::All },
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(padded), rows_per_image: Some(h) },
        },
        wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
    );
    let submission = g.ctx.queue.submit([encoder.finish()]);
    let (tx, rx) = std::sync::mpsc::channel();
    buffer.slice(..).map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    g.ctx.device.poll(wgpu::PollType::Wait { submission_index: Some(submission), timeout: None })?;
    g.ctx.check_device()?;
    rx.recv()?.context("mapping the screenshot")?;
    let bgra = matches!(g.config.format, wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb);
    let mut rgba = Vec::with_capacity((w * h * 4) as usize);
    {
        let data = buffer.slice(..).get_mapped_range().expect("mapped above");
        for row in data.chunks(padded as usize).take(h as usize) {
            for px in row[..(w * 4) as usize].chunks_exact(4) {
                if bgra {
                    rgba.extend_from_slice(&[px[2], px[1], px[0], 255]);
                } else {
                    rgba.extend_from_slice(&[px[0], px[1], px[2], 255]);
                }
            }
        }
    }
    Ok(Picture { width: w, height: h, rgba })
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.gfx.is_none() {
            if let Err(e) = self.init(event_loop) {
                self.error = Some(e);
                event_loop.exit();
                return;
            }
        }
        if let Some(g) = &self.gfx {
            g.window.request_redraw();
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        let result = match event {
            WindowEvent::CloseRequested => {
                event_loop.exit();
                Ok(())
            }
            WindowEvent::Resized(size) => {
                if let Some(g) = &mut self.gfx {
                    g.config.width = size.width.max(1);
                    g.config.height = size.height.max(1);
                    g.surface.configure(&g.ctx.device, &g.config);
                    g.renderer.resize(g.config.width, g.config.height);
                    g.window.request_redraw();
                }
                Ok(())
            }
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => match event.logical_key.as_ref() {
                Key::Named(NamedKey::Space) => {
                    self.paused = !self.paused;
                    Ok(())
                }
                Key::Named(NamedKey::Escape) => {
                    event_loop.exit();
                    Ok(())
                }
                Key::Character(c) => match c.to_lowercase().as_str() {
                    "q" => {
                        event_loop.exit();
                        Ok(())
                    }
                    "n" => {
                        self.step_once = true;
                        Ok(())
                    }
                    "r" => self.reset(),
                    _ => Ok(()),
                },
                _ => Ok(()),
            },
            WindowEvent::MouseInput { state, button: MouseButton::Left, .. } => {
                self.dragging = state == ElementState::Pressed;
                Ok(())
            }
            WindowEvent::CursorMoved { position, .. } => {
                if let (true, Some((x, y)), Some(g)) = (self.dragging, self.cursor, &mut self.gfx) {
                    let scale = std::f32::consts::PI / g.config.height as f32;
                    g.renderer.camera.orbit((position.x - x) as f32 * scale, (position.y - y) as f32 * scale);
                }
                self.cursor = Some((position.x, position.y));
                Ok(())
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let lines = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => p.y as f32 / 40.0,
                };
                if let Some(g) = &mut self.gfx {
                    g.renderer.camera.zoom(0.9f32.powf(lines));
                }
                Ok(())
            }
            WindowEvent::RedrawRequested => self.frame(event_loop),
            _ => Ok(()),
        };
        if let Err(e) = result {
            self.error = Some(e);
            event_loop.exit();
        }
    }
}
