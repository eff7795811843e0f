use wgsph::solver::compare::{step_and_compare, MANY_STEPS};
use wgsph::solver::{open, BackendChoice, Precision};
fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let scene = wgsph::Scene::load(&args[1])?;
    let steps: u64 = args[2].parse()?;
    let every: u64 = args[4].parse()?;
    let test = match args[3].as_str() { "gpu" => BackendChoice::gpu(), _ => BackendChoice::cpu(Precision::F32) };
    let mut a = open(&scene, &test)?.into_backend();
    let mut b = open(&scene, &BackendChoice::cpu(Precision::F64))?.into_backend();
    let mut done = 0;
    while done < steps {
        let c = step_and_compare(a.as_mut(), b.as_mut(), every, &MANY_STEPS)?;
        done += every;
        let (ha, hb) = (a.health()?, b.health()?);
        println!("{done}: pos {:.2e} rho {:.2e} p {:.2e} acc {:.2e} it {:?} {:?} dt {:?} {:?}", c.field("position").max, c.field("density").max, c.field("pressure").max, c.field("acceleration").max, ha.iterations.map(|i| (i.pressure.total, i.divergence.total)), hb.iterations.map(|i| (i.pressure.total, i.divergence.total)), a.dt_stats()?.last, b.dt_stats()?.last);
    }
    Ok(())
}
