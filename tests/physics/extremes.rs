//! Stability at the extremes: each test states what must happen, on the f64 CPU reference and on
//! every GPU adapter found.

use crate::common;
use crate::common::TestScene;

use wgsph::app::run::run;
use wgsph::app::run::RunOptions;
use wgsph::model::initial::InitialState;
use wgsph::model::scene::EquationOfState;
use wgsph::model::scene::Scene;
use wgsph::solver::Backend;
use wgsph::model::state::StepFields;

/// A block of 6 x 8 x 4 fluid particles in a closed tank of wall particles, backed by planes on
/// the tank's inner faces. h = 0.04, c0 = 20 m/s: the CFL number dt (c0 + |v|) / h is 0.1 at
/// dt = 2e-4.
fn tank() -> TestScene {
    let inside = [0.24, 0.24, 0.12];
    let mut tank = TestScene::new()
        .named("tank")
        .domain([-0.06; 3], [0.30, 0.30, 0.18])
        .smoothing_length(0.04)
        .particle_spacing(0.02)
        .equation_of_state(EquationOfState::Tait)
        .speed_of_sound(20.0)
        .clamp_negative_pressure(true)
        .viscosity(0.001)
        .boundary_friction(0.0)
        .dt(0.0002)
        .fluid([0.0; 3], [0.12, 0.16, 0.08])
        .closed_container([0.0; 3], inside);
    // Per axis, the face through the origin, then the far face.
    for axis in 0..3 {
        let (mut far, mut normal, mut inward) = ([0.0; 3], [0.0; 3], [0.0; 3]);
        far[axis] = inside[axis];
        normal[axis] = 1.0;
        inward[axis] = -1.0;
        tank = tank.plane([0.0; 3], normal, 0.0).plane(far, inward, 0.0);
    }
    tank
}

/// The f64 CPU reference and one GPU solver per adapter, all from the same state.
fn backends(scene: &Scene, initial: &InitialState) -> Vec<Box<dyn Backend>> {
    let mut list: Vec<Box<dyn Backend>> = vec![Box::new(common::cpu_from::<f64>(&scene, initial))];
    for ctx in common::contexts() {
        list.push(Box::new(common::gpu_from(ctx, &scene, initial)));
    }
    list
}

fn all_finite(s: &wgsph::Snapshot) -> bool {
    s.non_finite_count() == 0
}

fn inside(x: &[f64; 3], min: [f64; 3], max: [f64; 3]) -> bool {
    (0..3).all(|a| x[a] >= min[a] - 1e-6 && x[a] <= max[a] + 1e-6)
}

/// Runs `steps` steps through the run loop (health checks, snapshots, summary) into a temporary
/// directory and returns the summary and the snapshots written.
fn run_to_dir(backend: &mut dyn Backend, scene: &Scene, steps: u64, every: u64) -> (wgsph::io::summary::Summary, Vec<wgsph::Snapshot>) {
    let dir = tempfile::tempdir().unwrap();
    let opts = RunOptions { steps, out: dir.path().to_path_buf(), snapshot_every: every, check_every: every, progress: false, end_time: None, ..Default::default() };
    let summary = run(backend, scene, &opts).unwrap();
    let mut snaps = Vec::new();
    for e in std::fs::read_dir(dir.path().join("snapshots")).unwrap() {
        let path = e.unwrap().path();
        // Beside the snapshots: their index.
        if path.file_name().unwrap().to_string_lossy().starts_with("step_") {
            snaps.push(wgsph::io::snapshot::csv::read_snapshot_csv(&path).unwrap());
        }
    }
    (summary, snaps)
}

#[test]
fn a_time_step_far_over_the_cfl_limit_stops_within_bounded_steps_naming_the_step_and_the_cfl_number() {
    // dt 50x the stable step (CFL number 5), walls of particles only: the state blows up.
    let s = tank().without_planes().dt(0.01).build();
    for mut b in backends(&s, &s.initial_state()) {
        let who = b.adapter();
        let (summary, snaps) = run_to_dir(b.as_mut(), &s, 1000, 5);
        let failure = summary.failure.unwrap_or_else(|| panic!("{who}: not detected"));
        let bad_step = b.health().unwrap().first_bad_step.unwrap();
        assert!(bad_step <= 200, "{who}: went bad only at step {bad_step}");
        assert!(summary.steps <= bad_step + 50, "{who}: detected {} steps after step {bad_step}", summary.steps);
        assert!(failure.starts_with(&format!("step {bad_step} ")), "{who}: {failure}");
        assert!(failure.contains("CFL number dt (c0 + |v|max) / h = "), "{who}: {failure}");
        // No NaN reached a file: every snapshot written holds finite numbers only.
        assert!(!snaps.is_empty());
        assert!(snaps.iter().all(all_finite), "{who}");
    }
}

#[test]
fn very_low_and_very_high_stiffness_stay_finite_and_inside_the_tank() {
    // c0 = 0.01 m/s: almost no pressure, the fluid collapses onto the floor but the planes
    // hold it. c0 = 2000 m/s with dt at CFL number 0.2: nearly incompressible, the largest
    // density stays within 1 % of the largest at t = 0 (jitter and walls make that above rho0).
    for (c0, dt, steps, max_growth) in [(0.01, 2e-4, 600, 100.0), (2000.0, 4e-6, 300, 1.01)] {
        // Without the limits: at c0 = 0.01 m/s the fluid falls at Mach 100.
        let s = tank().speed_of_sound(c0).dt(dt).without_limits().build();
        for mut b in backends(&s, &s.initial_state()) {
            let who = format!("{} c0 = {c0}", b.adapter());
            let initial_max = b.snapshot().unwrap().densities.iter().cloned().fold(0.0, f64::max);
            b.step(steps).unwrap();
            let h = b.health().unwrap();
            assert!(h.is_ok(), "{who}: {h:?}");
            let snap = b.snapshot().unwrap();
            assert!(all_finite(&snap), "{who}");
            assert!(snap.positions.iter().all(|x| inside(x, [0.0; 3], [0.24, 0.24, 0.12])), "{who}");
            let growth = h.max_density / initial_max;
            assert!(growth.is_finite() && growth < max_growth, "{who}: max rho grew by {growth}");
        }
    }
}

#[test]
fn zero_viscosity_is_stable_and_very_high_viscosity_damps_or_is_detected() {
    // nu = 0: inviscid, stable at the CFL number 0.1.
    let s = tank().viscosity(0.0).build();
    for mut b in backends(&s, &s.initial_state()) {
        b.step(400).unwrap();
        assert!(b.health().unwrap().is_ok(), "{}", b.adapter());
        assert!(all_finite(&b.snapshot().unwrap()));
    }
    // nu = 10 m^2/s with dt under the viscous limit 0.125 h^2 / nu = 2e-5: a block moving at
    // 1 m/s against still fluid is damped to a common velocity.
    let viscous = |dt: f64| tank().viscosity(10.0).dt(dt).fluid([0.12, 0.0, 0.0], [0.2, 0.16, 0.08]).moving_at([1.0, 0.0, 0.0]);
    let s = viscous(0.00001).build();
    for mut b in backends(&s, &s.initial_state()) {
        let spread = |snap: &wgsph::Snapshot| {
            let n = snap.len() as f64;
            let mean = snap.velocities.iter().map(|v| v[0]).sum::<f64>() / n;
            (snap.velocities.iter().map(|v| (v[0] - mean).powi(2)).sum::<f64>() / n).sqrt()
        };
        let before = spread(&b.snapshot().unwrap());
        b.step(300).unwrap();
        assert!(b.health().unwrap().is_ok(), "{}", b.adapter());
        let snap = b.snapshot().unwrap();
        assert!(all_finite(&snap));
        assert!(spread(&snap) < 0.2 * before, "{}: velocity spread {before} -> {}", b.adapter(), spread(&snap));
    }
    // The same at dt = 2e-4, 10x over the viscous limit: explicit viscosity diverges, and the
    // run stops with a diagnosis.
    let s = viscous(0.0002).without_planes().build();
    for mut b in backends(&s, &s.initial_state()) {
        let (summary, snaps) = run_to_dir(b.as_mut(), &s, 2000, 10);
        assert!(summary.failure.is_some(), "{}: not detected", b.adapter());
        assert!(snaps.iter().all(all_finite));
    }
}

#[test]
fn particles_at_the_same_position_give_no_division_by_zero() {
    // Four particles in one place are four times as dense: without the density limit.
    let s = tank().without_limits().build();
    let mut init = s.initial_state();
    // Three particles stacked exactly on a fourth, and two more pairs elsewhere.
    for (dst, src) in [(1, 0), (2, 0), (3, 0), (40, 41), (100, 101)] {
        init.fluid_positions[dst] = init.fluid_positions[src];
    }
    let mut reference = None;
    for mut b in backends(&s, &init) {
        b.step(1).unwrap();
        let f = b.step_fields().unwrap();
        assert!(f.densities.iter().chain(&f.pressures).chain(f.accelerations.iter().flatten()).all(|v| v.is_finite()), "{}", b.adapter());
        b.step(99).unwrap();
        assert!(b.health().unwrap().is_ok(), "{}", b.adapter());
        let snap = b.snapshot().unwrap();
        assert!(all_finite(&snap), "{}", b.adapter());
        // Agrees with the reference after one step.
        agrees_with_reference(&mut reference, f, &b.adapter());
    }
}

/// Keeps the first backend's fields as the reference and checks the others' densities against
/// it to within 1e-5.
fn agrees_with_reference(reference: &mut Option<StepFields>, f: StepFields, adapter: &str) {
    match reference {
        None => *reference = Some(f),
        Some(r) => {
            for i in 0..r.densities.len() {
                assert!((f.densities[i] - r.densities[i]).abs() < 1e-5 * r.densities[i], "{adapter} particle {i}");
            }
        }
    }
}

#[test]
fn all_particles_in_one_grid_cell() {
    // h larger than the domain: one cell holds every particle (and every wall particle).
    let s = tank().smoothing_length(0.5).wall_layers(2).dt(0.002).build();
    assert_eq!(s.params().grid.cell_count(), 1);
    let mut reference = None;
    for mut b in backends(&s, &s.initial_state()) {
        b.step(1).unwrap();
        let f = b.step_fields().unwrap();
        b.step(49).unwrap();
        assert!(b.health().unwrap().is_ok(), "{}", b.adapter());
        assert!(all_finite(&b.snapshot().unwrap()));
        agrees_with_reference(&mut reference, f, &b.adapter());
    }
}

#[test]
fn a_single_particle_falls_freely_then_rests_on_a_floor_plane() {
    let particle = TestScene::new()
        .domain([0.0, -1.0, 0.0], [1.0; 3])
        .smoothing_length(0.1)
        .particle_spacing(0.05)
        .speed_of_sound(10.0)
        .viscosity(0.01)
        .dt(0.001)
        .fluid([0.5; 3], [0.55; 3])
        .jitter(0.0);
    let s = particle.clone().build();
    let p = s.params();
    assert_eq!(s.initial_state().fluid_positions.len(), 1);
    let n = 200u64;
    for mut b in backends(&s, &s.initial_state()) {
        let who = b.adapter();
        b.step(n).unwrap();
        let snap = b.snapshot().unwrap();
        // Symplectic Euler under gravity alone: v_n = g n dt, y_n = y_0 + g dt^2 n (n + 1) / 2.
        let (g, dt) = (-9.81, p.dt);
        let v = g * n as f64 * dt;
        let y = 0.525 + g * dt * dt * (n * (n + 1)) as f64 / 2.0;
        assert!((snap.velocities[0][1] - v).abs() < 1e-5 * v.abs(), "{who}: v = {:?}", snap.velocities[0]);
        assert!((snap.positions[0][1] - y).abs() < 1e-5, "{who}: x = {:?}", snap.positions[0]);
        assert_eq!(snap.velocities[0][0], 0.0);
        // Its density is its own mass times W(0) = 315 / (64 pi h^3): below rest, so pressure < 0.
        let w0 = 315.0 / (64.0 * std::f64::consts::PI * p.h.powi(3));
        assert!((snap.densities[0] - p.fluid_mass * w0).abs() < 1e-5 * snap.densities[0], "{who}");
    }
    // With a floor plane at y = 0 it lands and stays on it.
    let s = particle.plane([0.0; 3], [0.0, 1.0, 0.0], 0.0).build();
    for mut b in backends(&s, &s.initial_state()) {
        b.step(1000).unwrap();
        assert!(b.health().unwrap().is_ok());
        let snap = b.snapshot().unwrap();
        assert!(snap.positions[0][1] >= 0.0 && snap.positions[0][1] < 1e-3, "{}: {:?}", b.adapter(), snap.positions[0]);
        assert!(snap.velocities[0][1].abs() <= 9.81 * 0.001 + 1e-6, "{}: {:?}", b.adapter(), snap.velocities[0]);
    }
}

#[test]
fn a_scene_without_fluid_is_refused_and_the_solvers_step_zero_particles() {
    // The tank emptied of fluid (and boundaries) is refused, with an error naming the field.
    let e = tank().without_fluid().without_boundaries().validation_error();
    assert!(e.contains("fluid") && e.contains("at least one"), "{e}");
    // The solvers given no fluid particles (only walls) step, report health and write outputs.
    let s = tank().build();
    let mut init = s.initial_state();
    init.fluid_positions.clear();
    init.fluid_velocities.clear();
    for mut b in backends(&s, &init) {
        assert_eq!(b.fluid_count(), 0);
        let (summary, snaps) = run_to_dir(b.as_mut(), &s, 20, 10);
        assert!(summary.failure.is_none(), "{}", b.adapter());
        assert_eq!(summary.steps, 20);
        assert_eq!(summary.fluid_particles, 0);
        assert!(!snaps.is_empty() && snaps.iter().all(|s| s.is_empty()));
    }
}

#[test]
fn high_speed_impacts_lose_no_particle_through_a_wall() {
    // The block hits the tank's far wall at 50 m/s, faster than sound (c0 = 20); dt keeps the
    // CFL number dt (c0 + |v|) / h at 0.18. Far beyond weak compressibility (Mach 2.5): its
    // limits are off, since what is tested is the walls.
    let s = tank().moving_at([50.0, 0.0, 0.0]).dt(0.0001).without_limits().build();
    for mut b in backends(&s, &s.initial_state()) {
        let who = b.adapter();
        for _ in 0..10 {
            b.step(30).unwrap();
            let h = b.health().unwrap();
            assert!(h.is_ok(), "{who}: {h:?}");
            let snap = b.snapshot().unwrap();
            assert!(all_finite(&snap), "{who}");
            assert!(snap.positions.iter().all(|x| inside(x, [0.0; 3], [0.24, 0.24, 0.12])), "{who}: a particle went through a wall");
        }
    }
}

#[test]
fn particles_leaving_the_domain_are_counted_and_never_binned_out_of_bounds() {
    // No walls, no planes: a block flies out of the domain at 50 m/s (Mach 2.5: without the
    // limits, so that leaving the domain is what stops it).
    let s = tank().without_boundaries().moving_at([50.0, 0.0, 0.0]).dt(0.0001).without_limits().build();
    let n = s.initial_state().fluid_positions.len();
    let (dmin, dmax) = (s.domain.min, s.domain.max);
    for mut b in backends(&s, &s.initial_state()) {
        let who = b.adapter();
        let (summary, _) = run_to_dir(b.as_mut(), &s, 200, 5);
        let failure = summary.failure.unwrap_or_else(|| panic!("{who}: escape not detected"));
        assert!(failure.contains("left the domain"), "{who}: {failure}");
        let snap = b.snapshot().unwrap();
        let outside = snap.positions.iter().filter(|x| !inside(x, dmin, dmax)).count();
        assert!(outside > 0);
        // The summary counts the first bad step's particles; the health, those of the last step.
        let health = b.health().unwrap();
        assert_eq!(summary.escaped, health.bad_step.unwrap().measured.escaped, "{who}");
        assert_eq!(health.escaped as usize, outside, "{who}");
        // Stepping on with particles far outside is still safe: they are binned into the
        // border cells and nothing is lost.
        b.step(100).unwrap();
        let snap = b.snapshot().unwrap();
        assert_eq!(snap.len(), n);
        assert!(all_finite(&snap), "{who}");
        assert_eq!(b.health().unwrap().escaped as usize, snap.positions.iter().filter(|x| !inside(x, dmin, dmax)).count(), "{who}");
    }
    for ctx in common::contexts() {
        let mut gpu = common::gpu(ctx, &s);
        gpu.step(300).unwrap();
        let (ids, starts) = gpu.binning().unwrap();
        let mut sorted = ids.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..n as u32).collect::<Vec<_>>());
        assert!(starts.windows(2).all(|w| w[0] <= w[1]) && *starts.last().unwrap() as usize == n);
    }
}

#[test]
fn a_large_scene_steps_and_one_too_large_for_memory_is_refused() {
    // About 100 k fluid particles: one step agrees with the reference.
    let s = Scene::builtin("dam_break").unwrap().with_fluid_particles(100_000);
    let init = s.initial_state();
    assert!(init.fluid_positions.len() > 90_000);
    let mut reference = None;
    for mut b in backends(&s, &init) {
        b.step(1).unwrap();
        let f = b.step_fields().unwrap();
        assert!(b.health().unwrap().is_ok());
        match &reference {
            None => reference = Some(f),
            Some(r) => {
                let worst = (0..r.densities.len()).map(|i| (f.densities[i] - r.densities[i]).abs() / r.densities[i]).fold(0.0, f64::max);
                assert!(worst < 1e-5, "{}: density error {worst}", b.adapter());
            }
        }
    }
    // 10^9 particles: refused before any allocation, naming the count and the memory.
    let e = tank().domain([-0.06; 3], [20.0; 3]).without_boundaries().without_fluid().fluid([0.0; 3], [19.0; 3]).validation_error();
    assert!(e.contains("fluid") && e.contains("particles") && e.contains("MiB"), "{e}");
}

#[test]
fn a_long_run_of_100_000_steps_keeps_every_particle_and_bounded_energy() {
    // 8 particles in a box of planes with gravity and viscosity. 100 000 steps on the f64 and
    // f32 CPU paths (f32 is the GPU's arithmetic); 10 000 on each GPU adapter, where a software
    // adapter spends about 1 ms per step on dispatch overhead whatever the particle count.
    let mut box_of_planes = TestScene::new()
        .domain([-0.01; 3], [0.09; 3])
        .smoothing_length(0.04)
        .particle_spacing(0.02)
        .speed_of_sound(5.0)
        .viscosity(0.001)
        .clamp_negative_pressure(true)
        .dt(0.0005)
        .end_time(100.0)
        .fluid([0.02, 0.04, 0.02], [0.06, 0.08, 0.06])
        .jitter(0.1)
        .moving_at([0.5, 0.0, -0.3]);
    // The three faces through the origin, then the three through the far corner.
    for (point, normal) in [
        ([0.0; 3], [1.0, 0.0, 0.0]),
        ([0.0; 3], [0.0, 1.0, 0.0]),
        ([0.0; 3], [0.0, 0.0, 1.0]),
        ([0.08; 3], [-1.0, 0.0, 0.0]),
        ([0.08; 3], [0.0, -1.0, 0.0]),
        ([0.08; 3], [0.0, 0.0, -1.0]),
    ] {
        box_of_planes = box_of_planes.plane(point, normal, 0.0);
    }
    let s = box_of_planes.build();
    let (p, init) = (s.params(), s.initial_state());
    let m = p.fluid_mass;
    let energy = |snap: &wgsph::Snapshot| snap.kinetic_energy(m) + snap.positions.iter().map(|x| m * 9.81 * x[1]).sum::<f64>();
    let mut runs: Vec<(Box<dyn Backend>, u64)> =
        vec![(Box::new(common::cpu::<f64>(&s)), 100_000), (Box::new(common::cpu::<f32>(&s)), 100_000)];
    for ctx in common::contexts() {
        runs.push((Box::new(common::gpu(ctx, &s)), 10_000));
    }
    for (mut b, steps) in runs {
        let who = b.adapter();
        let e0 = energy(&b.snapshot().unwrap());
        // Gravity and the stored compression can only be released: viscosity and the inelastic
        // planes remove energy, so it never rises above its start (5 % allowed for the
        // compression energy of the jittered start).
        let mut last = e0;
        for _ in 0..10 {
            b.step(steps / 10).unwrap();
            let h = b.health().unwrap();
            assert!(h.is_ok(), "{who}: {h:?}");
            let snap = b.snapshot().unwrap();
            assert_eq!(snap.len(), init.fluid_positions.len(), "{who}");
            assert!(all_finite(&snap), "{who}");
            assert!(snap.positions.iter().all(|x| inside(x, [0.0; 3], [0.08; 3])), "{who}");
            last = energy(&snap);
            assert!(last <= 1.05 * e0, "{who}: energy {e0} -> {last}");
        }
        assert_eq!(b.steps_done(), steps);
        assert!(last < 0.5 * e0, "{who}: energy {e0} -> {last}: not dissipated");
    }
}

#[test]
fn a_closed_tank_s_grid_covers_only_the_tank_and_its_walls() {
    // The dam break's domain has room for the walls of its coarsest resolution; refined, the
    // grid keeps only the domain's cells over the tank and its walls, and holds every particle.
    let scene = Scene::builtin("dam_break").unwrap().with_fluid_particles(100_000);
    let grid = scene.grid();
    let h = scene.physics.smoothing_length;
    let whole: u64 = (0..3).map(|a| ((scene.domain.max[a] - scene.domain.min[a]) / h).ceil() as u64).product();
    let (lo, hi) = scene.boundary.iter().find_map(|b| scene.wall_span(b)).expect("a container");
    for a in 0..3 {
        let skipped = (grid.origin.0[a] - scene.domain.min[a]) / h;
        assert!((skipped - skipped.round()).abs() < 1e-9, "axis {a}: the cells lie on the domain's lattice ({skipped} cells in)");
        assert!(grid.origin.0[a] <= lo[a] && grid.origin.0[a] > lo[a] - h, "axis {a}: origin {} for walls from {}", grid.origin.0[a], lo[a]);
        let end = grid.origin.0[a] + grid.dims[a] as f64 * h;
        assert!(end >= hi[a] && end < hi[a] + h, "axis {a}: grid ends at {end} for walls up to {}", hi[a]);
    }
    assert!((grid.cell_count() as u64) * 2 < whole, "{} cells of the domain's {whole}", grid.cell_count());
    let initial = scene.initial_state();
    for p in initial.fluid_positions.iter().chain(&initial.wall_positions) {
        for a in 0..3 {
            let f = (p[a] - grid.origin.0[a]) / h;
            assert!(f >= 0.0 && f < grid.dims[a] as f64, "particle at {p:?} outside the grid on axis {a}");
        }
    }
    // Open at the top, the fluid can spill anywhere in the domain: every cell stays.
    let mut open = scene.clone();
    for b in &mut open.boundary {
        if let wgsph::model::scene::Boundary::Container { open_top, .. } = b {
            *open_top = true;
        }
    }
    assert_eq!(open.grid().cell_count() as u64, whole);
}
