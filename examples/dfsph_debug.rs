use wgsph::solver::{open, BackendChoice, Precision};
fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let scene = wgsph::Scene::load(&args[1])?;
    let steps: u64 = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(10);
    let every: u64 = args.get(3).map(|s| s.parse().unwrap()).unwrap_or(1);
    let prec = if args.get(4).map(|s| s.as_str()) == Some("f64") { Precision::F64 } else { Precision::F32 };
    let mut sim = open(&scene, &BackendChoice::cpu(prec))?;
    let t0 = std::time::Instant::now();
    let mut s = 0;
    while s < steps {
        sim.step(every)?;
        s += every;
        let h = sim.health()?;
        if every < steps || !h.is_ok() {
            let snap = sim.snapshot()?;
            let rmax = snap.densities.iter().cloned().fold(0.0, f64::max);
            let (imax, _) = snap.velocities.iter().enumerate().map(|(i, v)| (i, (v[0]*v[0]+v[1]*v[1]+v[2]*v[2]).sqrt())).fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
            let mean_v = snap.velocities.iter().map(|v| (v[0]*v[0]+v[1]*v[1]+v[2]*v[2]).sqrt()).sum::<f64>() / snap.len() as f64;
            let comp = snap.densities.iter().map(|r| (r / scene.physics.rest_density - 1.0).max(0.0)).sum::<f64>() / snap.len() as f64;
            println!("   fastest at {:?} v {:?} rho {:.2}; mean speed {mean_v:.4}; mean compression {comp:.2e}", snap.positions[imax], snap.velocities[imax], snap.densities[imax]);
            println!("step {s}: rho max {rmax:.2} vmax {:.3} {:?}", snap.max_speed(), h.iterations.map(|i| (i.pressure.last, i.pressure.last_error, i.divergence.last, i.divergence.last_error)));
        }
        if !h.is_ok() { println!("BAD {:?}", h); break; }
    }
    let el = t0.elapsed().as_secs_f64();
    let h = sim.health()?;
    let it = h.iterations.unwrap();
    println!("{} steps in {:.3} s: {:.3e} particle-steps/s; pressure it mean {:.2} max {} unconv {}; divergence mean {:.2} max {} unconv {}", s, el, s as f64 * sim.fluid_count() as f64 / el,
        it.pressure.mean(s), it.pressure.max, it.pressure.unconverged, it.divergence.mean(s), it.divergence.max, it.divergence.unconverged);
    Ok(())
}
