//! A minimal headless run through the library: a scene, some steps, a few numbers and a VTK
//! file of the last state.
//!
//! `cargo run --release --example headless -- [SCENE] [STEPS] [PARTICLES]`
//! (defaults: `dam_break`, 200 steps, 2000 particles; the GPU when there is one, else the CPU).

use std::path::Path;
use wgsph::model::scene::Scene;
use wgsph::solver::Simulation;
use wgsph::model::state::Snapshot;

/// Runs `steps` steps of `scene_name` at about `particles` fluid particles and writes the last
/// state to `vtk` (if given). Returns the first and the last snapshot.
fn run(scene_name: &str, steps: u64, particles: u64, vtk: Option<&Path>) -> anyhow::Result<(Snapshot, Snapshot)> {
    let scene = Scene::load(scene_name)?.with_fluid_particles(particles);
    let mut sim = match Simulation::gpu(scene.clone()) {
        Ok(sim) => sim,
        Err(e) => {
            eprintln!("no GPU ({e:#}); running on the CPU");
            Simulation::cpu(scene)?
        }
    };
    println!("{}: {} fluid particles on {}", sim.scene().name, sim.fluid_count(), sim.adapter());
    let first = sim.snapshot()?;
    sim.step(steps)?;
    let health = sim.health()?;
    anyhow::ensure!(health.is_ok(), "the run went bad at step {:?}", health.first_bad_step);
    let last = sim.snapshot()?;
    let mean_height = |s: &Snapshot| s.positions.iter().map(|p| p[1]).sum::<f64>() / s.len() as f64;
    println!(
        "t = {:.4}: mean height {:.4} -> {:.4}, max speed {:.3}, max rho/rho0 {:.4}",
        sim.time(),
        mean_height(&first),
        mean_height(&last),
        last.max_speed(),
        health.max_density / sim.params().rest_density
    );
    if let Some(path) = vtk {
        wgsph::io::snapshot::vtk::write_vtk(path, &last)?;
        println!("wrote {}", path.display());
    }
    Ok((first, last))
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scene = args.first().map(String::as_str).unwrap_or("dam_break");
    let steps = args.get(1).map(|s| s.parse()).transpose()?.unwrap_or(200);
    let particles = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(2000);
    run(scene, steps, particles, Some(Path::new("headless_last.vtk")))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_dam_break_column_falls() {
        let dir = tempfile::tempdir().unwrap();
        let vtk = dir.path().join("last.vtk");
        let (first, last) = super::run("dam_break", 40, 500, Some(&vtk)).unwrap();
        assert_eq!((first.step, last.step), (0, 40));
        assert_eq!(last.non_finite_count(), 0);
        let mean_vy = last.velocities.iter().map(|v| v[1]).sum::<f64>() / last.len() as f64;
        assert!(mean_vy < -0.01, "the column starts to fall: mean vy = {mean_vy}");
        assert!(vtk.exists());
    }
}
