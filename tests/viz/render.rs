//! Rendered pictures on every adapter: size, content where the particles project, motion,
//! a surface without holes (screen-space and mesh), determinism, and the host-upload path of the
//! CPU backend.

use crate::common;
use crate::common::TestScene;

use glam::{Vec3, Vec4Swizzles};
use wgsph::solver::gpu::GpuContext;
use wgsph::solver::gpu::GpuSolver;
use wgsph::viz::render::frames::Offscreen;
use wgsph::viz::render::frames::Picture;
use wgsph::viz::render::Camera;
use wgsph::viz::render::ParticleBuffers;
use wgsph::viz::render::ColorBy;
use wgsph::viz::render::RenderOptions;
use wgsph::viz::render::Style;
use wgsph::viz::render::Walls;
use wgsph::model::scene::Scene;
use wgsph::solver::Backend;

/// A block of n x n x n particles alone in space (no walls, no gravity unless asked), on a
/// floor plane if asked.
fn block(n: usize, jitter: f64, gravity: f64, planes: bool) -> Scene {
    let spacing = 0.1;
    let side = n as f64 * spacing;
    let block = TestScene::new()
        .named("block")
        .domain([-2.0, -0.5, -2.0], [3.0; 3])
        .smoothing_length(0.2)
        .particle_spacing(spacing)
        .stiffness(1000.0)
        .gravity([0.0, gravity, 0.0])
        .dt(0.002)
        .fluid([0.0; 3], [side; 3])
        .jitter(jitter);
    if planes {
        block.plane([0.0; 3], [0.0, 1.0, 0.0], 0.0).build()
    } else {
        block.build()
    }
}

fn options(style: Style) -> RenderOptions {
    RenderOptions { width: 320, height: 200, style, color_by: ColorBy::Speed, range: None, walls: Walls::Hidden }
}

fn gpu_picture(ctx: &GpuContext, scene: &Scene, style: Style, steps: u64) -> (Picture, Offscreen, GpuSolver) {
    let init = scene.initial_state();
    let mut solver = common::gpu(ctx.clone(), &scene);
    solver.step(steps).unwrap();
    let mut offscreen = Offscreen::new(ctx, options(style), scene, &init.wall_positions);
    let particles: ParticleBuffers = solver.gpu_particles().unwrap().into();
    let picture = offscreen.picture(&particles).unwrap();
    (picture, offscreen, solver)
}

/// Whether a pixel differs from the background (the top-left corner, which nothing covers).
fn covered(p: &Picture) -> Vec<bool> {
    let bg = p.pixel(0, 0);
    (0..p.height)
        .flat_map(|y| (0..p.width).map(move |x| (x, y)))
        .map(|(x, y)| {
            let c = p.pixel(x, y);
            (0..3).any(|k| c[k].abs_diff(bg[k]) > 2)
        })
        .collect()
}

#[test]
fn particles_appear_where_they_project() {
    for ctx in common::contexts() {
        let scene = block(4, 0.3, 0.0, false);
        let (picture, offscreen, mut solver) = gpu_picture(&ctx, &scene, Style::Particles, 0);
        assert_eq!((picture.width, picture.height, picture.rgba.len()), (320, 200, 320 * 200 * 4));
        let mask = covered(&picture);
        let r = &offscreen.renderer;
        let centres: Vec<(f32, f32, f32)> = solver
            .snapshot()
            .unwrap()
            .positions
            .iter()
            .map(|p| {
                let w = Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32);
                let (x, y) = r.camera.project(w, 320, 200, &r.bounds).unwrap();
                (x, y, r.camera.projected_radius(w, 0.05, 200, &r.bounds))
            })
            .collect();
        // Every particle centre is drawn (by it or by one in front of it)...
        for &(x, y, _) in &centres {
            assert!(mask[y as usize * 320 + x as usize], "{}: nothing drawn at the centre ({x}, {y})", ctx.describe());
        }
        // ... and everything drawn lies on a particle's projected disc.
        let stray = (0..mask.len())
            .filter(|&i| mask[i])
            .filter(|&i| {
                let (px, py) = ((i % 320) as f32 + 0.5, (i / 320) as f32 + 0.5);
                !centres.iter().any(|&(x, y, rad)| ((px - x).powi(2) + (py - y).powi(2)).sqrt() <= rad * 1.1 + 1.5)
            })
            .count();
        assert_eq!(stray, 0, "{}: pixels drawn away from every particle", ctx.describe());
        let drawn = mask.iter().filter(|&&m| m).count();
        assert!(drawn > 500 && drawn < mask.len() / 2, "{}: {drawn} pixels drawn", ctx.describe());
    }
}

#[test]
fn a_moving_scene_gives_different_frames_and_the_same_frame_twice() {
    for ctx in common::contexts() {
        let scene = block(5, 0.05, -9.81, true);
        for style in [Style::Particles, Style::Surface] {
            let (first, mut offscreen, mut solver) = gpu_picture(&ctx, &scene, style, 0);
            let particles: ParticleBuffers = solver.gpu_particles().unwrap().into();
            let again = offscreen.picture(&particles).unwrap();
            assert!(first == again, "{} {style:?}: the same state rendered twice differs", ctx.describe());
            solver.step(150).unwrap();
            let particles: ParticleBuffers = solver.gpu_particles().unwrap().into();
            let later = offscreen.picture(&particles).unwrap();
            let changed = covered(&first).iter().zip(covered(&later)).filter(|(a, b)| **a != *b).count();
            assert!(changed > 300, "{} {style:?}: only {changed} pixels changed after 0.3 s of falling", ctx.describe());
        }
    }
}

/// The pixels whose view ray passes through the box [lo, hi].
fn pixels_through_box(camera: &Camera, bounds: &wgsph::viz::render::Bounds, w: u32, h: u32, lo: Vec3, hi: Vec3) -> Vec<usize> {
    let inverse = (camera.projection(w as f32 / h as f32, bounds) * camera.view()).inverse();
    let mut out = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let ndc = glam::Vec2::new((x as f32 + 0.5) / w as f32 * 2.0 - 1.0, 1.0 - (y as f32 + 0.5) / h as f32 * 2.0);
            let far = inverse * ndc.extend(0.5).extend(1.0);
            let dir = (far.xyz() / far.w - camera.eye).normalize();
            // Slab test.
            let (mut t0, mut t1) = (0.0f32, f32::INFINITY);
            for a in 0..3 {
                let (a0, a1) = ((lo[a] - camera.eye[a]) / dir[a], (hi[a] - camera.eye[a]) / dir[a]);
                t0 = t0.max(a0.min(a1));
                t1 = t1.min(a0.max(a1));
            }
            if t0 <= t1 {
                out.push((y * w + x) as usize);
            }
        }
    }
    out
}

#[test]
fn the_surface_of_a_resting_block_has_no_holes() {
    for ctx in common::contexts() {
        let scene = block(10, 0.05, 0.0, false);
        let (picture, offscreen, _) = gpu_picture(&ctx, &scene, Style::Surface, 0);
        let mask = covered(&picture);
        let r = &offscreen.renderer;
        // The block's particle centres span [0.05, 0.95]: every ray through its inside must hit fluid.
        let inside = pixels_through_box(&r.camera, &r.bounds, 320, 200, Vec3::splat(0.1), Vec3::splat(0.9));
        assert!(inside.len() > 2000, "{}: the block covers only {} pixels", ctx.describe(), inside.len());
        let holes = inside.iter().filter(|&&i| !mask[i]).count();
        assert_eq!(holes, 0, "{}: {holes} background pixels inside the block's surface", ctx.describe());
        // The surface does not spread far beyond the block either.
        let outside = pixels_through_box(&r.camera, &r.bounds, 320, 200, Vec3::splat(-0.1), Vec3::splat(1.1));
        let spill = (0..mask.len()).filter(|&i| mask[i] && outside.binary_search(&i).is_err()).count();
        assert_eq!(spill, 0, "{}: {spill} surface pixels outside the block", ctx.describe());
    }
}

/// A picture of the reconstructed surface mesh of the scene's initial state.
fn mesh_picture(ctx: &GpuContext, scene: &Scene) -> (Picture, Offscreen) {
    let init = scene.initial_state();
    let solver = common::gpu(ctx.clone(), &scene);
    let mut offscreen = Offscreen::new(ctx, options(Style::Mesh), scene, &init.wall_positions);
    let mut cpu = common::cpu::<f64>(&scene);
    offscreen.renderer.reconstruct_mesh(&cpu.snapshot()).unwrap();
    let particles: ParticleBuffers = solver.gpu_particles().unwrap().into();
    let picture = offscreen.picture(&particles).unwrap();
    (picture, offscreen)
}

#[test]
fn the_mesh_of_a_resting_block_has_no_holes_and_repeats_exactly() {
    for ctx in common::contexts() {
        let scene = block(10, 0.05, 0.0, false);
        let (picture, mut offscreen) = mesh_picture(&ctx, &scene);
        let mask = covered(&picture);
        let r = &offscreen.renderer;
        // The block's particle centres span [0.05, 0.95]: every ray through its inside must hit the mesh.
        let inside = pixels_through_box(&r.camera, &r.bounds, 320, 200, Vec3::splat(0.1), Vec3::splat(0.9));
        assert!(inside.len() > 2000, "{}: the block covers only {} pixels", ctx.describe(), inside.len());
        let holes = inside.iter().filter(|&&i| !mask[i]).count();
        assert_eq!(holes, 0, "{}: {holes} background pixels inside the block's mesh", ctx.describe());
        let outside = pixels_through_box(&r.camera, &r.bounds, 320, 200, Vec3::splat(-0.1), Vec3::splat(1.1));
        let spill = (0..mask.len()).filter(|&i| mask[i] && outside.binary_search(&i).is_err()).count();
        assert_eq!(spill, 0, "{}: {spill} mesh pixels outside the block", ctx.describe());
        // Lit faces differ in shade: the mesh is shaded, not a flat silhouette.
        let shades: std::collections::BTreeSet<[u8; 4]> =
            inside.iter().map(|&i| picture.pixel((i % 320) as u32, (i / 320) as u32)).collect();
        assert!(shades.len() > 20, "{}: only {} distinct colours on the mesh", ctx.describe(), shades.len());
        // Reconstructing and drawing the same state again gives the same picture.
        let mut cpu = common::cpu::<f64>(&scene);
        offscreen.renderer.reconstruct_mesh(&cpu.snapshot()).unwrap();
        let particles = offscreen.renderer.upload(&cpu.snapshot());
        let again = offscreen.picture(&particles).unwrap();
        assert!(picture == again, "{}: the same mesh rendered twice differs", ctx.describe());
        // An empty mesh draws nothing.
        offscreen.renderer.upload_mesh(&[], &[], &[]);
        let empty = offscreen.picture(&particles).unwrap();
        assert!(covered(&empty).iter().all(|&m| !m), "{}: an empty mesh drew pixels", ctx.describe());
    }
}

#[test]
fn cpu_particles_uploaded_from_the_host_look_like_the_gpu_ones() {
    for ctx in common::contexts() {
        let scene = block(4, 0.3, 0.0, false);
        let (gpu, mut offscreen, _) = gpu_picture(&ctx, &scene, Style::Particles, 0);
        let mut cpu = common::cpu::<f64>(&scene);
        let particles = offscreen.renderer.upload(&cpu.snapshot());
        let host = offscreen.picture(&particles).unwrap();
        let differ = covered(&gpu).iter().zip(covered(&host)).filter(|(a, b)| **a != *b).count();
        assert!(differ < 20, "{}: {differ} pixels differ in coverage between the two paths", ctx.describe());
    }
}

#[test]
fn colour_follows_the_chosen_field_and_range() {
    for ctx in common::contexts() {
        let scene = block(4, 0.3, 0.0, false);
        let solver = common::gpu(ctx.clone(), &scene);
        let particles: ParticleBuffers = solver.gpu_particles().unwrap().into();
        // All speeds are 0: with the range 1..2 every particle takes the low end of viridis
        // (dark violet), with -2..-1 the high end (yellow).
        let mut pictures = Vec::new();
        for range in [(1.0, 2.0), (-2.0, -1.0)] {
            let mut o = Offscreen::new(&ctx, RenderOptions { range: Some(range), ..options(Style::Particles) }, &scene, &[]);
            pictures.push(o.picture(&particles).unwrap());
        }
        let mean = |p: &Picture| {
            let m = covered(p);
            let px: Vec<[u8; 4]> = (0..m.len()).filter(|&i| m[i]).map(|i| p.pixel((i % 320) as u32, (i / 320) as u32)).collect();
            [0, 1, 2].map(|k| px.iter().map(|c| c[k] as f64).sum::<f64>() / px.len() as f64)
        };
        let (low, high) = (mean(&pictures[0]), mean(&pictures[1]));
        assert!(low[2] > low[1] && low[0] > low[1], "{}: low end not violet: {low:?}", ctx.describe());
        assert!(high[0] > high[2] && high[1] > high[2], "{}: high end not yellow: {high:?}", ctx.describe());
    }
}

#[test]
fn the_automatic_colour_range_covers_every_segment_of_a_split_field() {
    for ctx in common::contexts() {
        let split = ctx.clone().with_storage_segment_bytes(wgsph::solver::gpu::device::MIN_SEGMENT_BYTES).unwrap();
        // 17^3 = 4913 particles: the speeds (vec4s) fill more than one 4096-value segment.
        let scene = block(17, 0.0, 0.0, false);
        let mut cpu = common::cpu::<f64>(&scene);
        let mut snapshot = cpu.snapshot();
        assert!(snapshot.len() > 4096);
        // Every particle at rest but the last, which alone sets the top of the range: a range
        // taken from the first segment alone would be [0, 0] and colour the block differently.
        let last = snapshot.len() - 1;
        snapshot.velocities[last] = [1.0, 0.0, 0.0];
        let pictures: Vec<Picture> = [&ctx, &split]
            .into_iter()
            .map(|c| {
                let mut o = Offscreen::new(c, options(Style::Particles), &scene, &[]);
                let particles = o.renderer.upload(&snapshot);
                o.picture(&particles).unwrap()
            })
            .collect();
        assert!(pictures[0].rgba == pictures[1].rgba, "{}: the split field gives another picture", ctx.describe());
        // And the whole-field picture is the one of the range [0, 1] set by hand.
        let mut fixed = Offscreen::new(&ctx, RenderOptions { range: Some((0.0, 1.0)), ..options(Style::Particles) }, &scene, &[]);
        let particles = fixed.renderer.upload(&snapshot);
        assert!(fixed.picture(&particles).unwrap().rgba == pictures[0].rgba, "{}: automatic range is not [0, 1]", ctx.describe());
    }
}
