//! Embedding the simulator in a program that has its own wgpu device: the scene is built in
//! code, the simulation runs on the program's device, and every "frame" the particle positions
//! are copied on the GPU into the program's own vertex buffer, as a renderer would draw them.
//!
//! `cargo run --release --example embed`

use wgsph::solver::gpu::GpuContext;
use wgsph::model::scene::Boundary;
use wgsph::model::scene::Domain;
use wgsph::model::scene::EquationOfState;
use wgsph::model::scene::FluidBlock;
use wgsph::model::scene::Kernel;
use wgsph::model::scene::Physics;
use wgsph::model::scene::Time;
use wgsph::model::scene::WallParticles;
use wgsph::model::scene::Scene;
use wgsph::solver::Simulation;

/// A 0.2 m cube of water dropped into a closed 0.5 m tank, built without a file.
fn drop_scene() -> Scene {
    let (s, h) = (0.02, 0.04);
    Scene {
        name: "cube_drop".into(),
        description: "a cube of water falling into a closed tank".into(),
        seed: 7,
        domain: Domain { min: [-0.1; 3], max: [0.6; 3] },
        physics: Physics {
            kernel: Kernel::Mueller,
            equation_of_state: EquationOfState::Tait,
            speed_of_sound: Some(30.0),
            viscosity: 0.01,
            boundary_friction: 0.0,
            ..Physics::new(h, s)
        },
        time: Time::fixed(2.5e-4, 0.5),
        fluid: vec![FluidBlock::new([0.15, 0.25, 0.15], [0.35, 0.45, 0.35])],
        boundary: vec![Boundary::Container { min: [0.0; 3], max: [0.5; 3], open_top: false, walls: WallParticles::default() }],
        camera: None,
        limits: Default::default(),
        probe: Vec::new(),
    }
}

/// Steps `frames` frames of `steps_per_frame` steps on `context`, copying the positions into
/// the program's own vertex buffer after each frame. Returns the vertex buffer's last contents
/// (x, y, z per particle in the solver's order, with the particle's original index as the u32
/// bits of w) and those indices.
fn run(context: GpuContext, frames: u32, steps_per_frame: u64) -> anyhow::Result<(Vec<[f32; 4]>, Vec<u32>, wgsph::Snapshot)> {
    let mut sim = Simulation::gpu_on(drop_scene(), context)?;
    let n = sim.fluid_count() as u64;
    let device = sim.device().expect("on the GPU").clone();
    // The program's own buffers: a vertex buffer it would draw as points, and a readback buffer.
    let vertices = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("particle vertices"),
        size: n * 16,
        usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    for frame in 0..frames {
        sim.step(steps_per_frame)?;
        let buffers = sim.particle_buffers().expect("on the GPU")?;
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") });
        encoder.copy_buffer_to_buffer(&buffers.positions, 0, &vertices, 0, n * 16);
        // ... a render pass drawing `vertices` as points would go here ...
        sim.queue().expect("on the GPU").submit([encoder.finish()]);
        if frame % 10 == 0 {
            println!("frame {frame}: t = {:.4} s", sim.time());
        }
    }
    let ctx = sim.gpu_context().expect("on the GPU");
    let data = wgsph::solver::gpu::readback::read_buffers(ctx, &[(&vertices, n * 16)])?;
    let snapshot = sim.snapshot()?;
    let vertices: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&data[0]);
    let ids = vertices.iter().map(|v| v[3].to_bits()).collect();
    Ok((vertices, ids, snapshot))
}

fn main() -> anyhow::Result<()> {
    // A program would open its device for its window; here the best adapter stands in for it.
    let context = match GpuContext::new() {
        Ok(c) => c,
        Err(e) => {
            println!("this example needs a GPU adapter: {e:#}");
            return Ok(());
        }
    };
    let (vertices, _, snapshot) = run(context, 40, 8)?;
    let lowest = vertices.iter().map(|v| v[1]).fold(f32::INFINITY, f32::min);
    println!("{} particles at t = {:.4} s; the lowest is at y = {lowest:.4} m", vertices.len(), snapshot.time);
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_programs_vertex_buffer_holds_the_simulated_positions() {
        for adapter in wgsph::solver::gpu::device::compute_adapters() {
            // The program's own device, as it would open it for its window.
            let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
                required_limits: adapter.limits(),
                ..Default::default()
            }))
            .unwrap();
            let context = wgsph::solver::gpu::GpuContext::from_device(adapter, device, queue).unwrap();
            let (vertices, ids, snapshot) = super::run(context, 3, 8).unwrap();
            assert_eq!(snapshot.step, 24);
            assert_eq!(vertices.len(), snapshot.len());
            // The copy made on the GPU is the state the snapshot reads back, particle by particle.
            for (slot, v) in vertices.iter().enumerate() {
                let p = snapshot.positions[ids[slot] as usize];
                assert_eq!([v[0] as f64, v[1] as f64, v[2] as f64], p, "slot {slot}");
            }
        }
    }
}
