//! What every validation case shares: the resolutions, the cases, the error figures and the
//! report of a case, the backend maker, the sampler that steps a backend and checks for leaks,
//! the CSV writer and the energy of a state.

use crate::io::atomic::write_atomic;
use crate::model::initial::{InitialState, SolidRegion};
use crate::model::params::Params;
use crate::model::scene::{EquationOfState, Scene};
use crate::model::state::Snapshot;
use crate::solver::backend::diagnose_failure;
use crate::solver::Backend;
use clap::ValueEnum;
use std::path::{Path, PathBuf};

#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum Resolution {
    /// The test suite's: about 2 k particles per case, looser tolerances.
    Coarse,
    /// `wgsph validate`'s: a few minutes for all cases on a software adapter.
    Default,
    /// Twice the default's linear resolution (8x the particles).
    Fine,
}

impl Resolution {
    pub fn name(self) -> &'static str {
        match self {
            Resolution::Coarse => "coarse",
            Resolution::Default => "default",
            Resolution::Fine => "fine",
        }
    }
    /// Linear refinement relative to the default resolution.
    pub fn refinement(self) -> f64 {
        match self {
            Resolution::Coarse => 0.5,
            Resolution::Default => 1.0,
            Resolution::Fine => 2.0,
        }
    }
}

#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum Case {
    Hydrostatic,
    DamBreakMartinMoyce,
    DamBreakKoshizukaOka,
    Conservation,
    BuchnerP1,
    /// The same tank and collapses with DFSPH's pressure instead of the equation of state.
    HydrostaticDfsph,
    DamBreakMartinMoyceDfsph,
    DamBreakKoshizukaOkaDfsph,
    /// The still tank with the density a sensor can read: carried by the continuity equation
    /// with delta-SPH diffusion, from a hydrostatic start.
    HydrostaticDiffusion,
}

impl Case {
    pub const ALL: [Case; 9] = [
        Case::Hydrostatic,
        Case::DamBreakMartinMoyce,
        Case::DamBreakKoshizukaOka,
        Case::Conservation,
        Case::BuchnerP1,
        Case::HydrostaticDfsph,
        Case::DamBreakMartinMoyceDfsph,
        Case::DamBreakKoshizukaOkaDfsph,
        Case::HydrostaticDiffusion,
    ];
    pub fn name(self) -> &'static str {
        match self {
            Case::Hydrostatic => "hydrostatic",
            Case::DamBreakMartinMoyce => "dam_break_martin_moyce",
            Case::DamBreakKoshizukaOka => "dam_break_koshizuka_oka",
            Case::Conservation => "conservation",
            Case::BuchnerP1 => "buchner_p1",
            Case::HydrostaticDfsph => "hydrostatic_dfsph",
            Case::DamBreakMartinMoyceDfsph => "dam_break_martin_moyce_dfsph",
            Case::DamBreakKoshizukaOkaDfsph => "dam_break_koshizuka_oka_dfsph",
            Case::HydrostaticDiffusion => "hydrostatic_diffusion",
        }
    }
    /// Whether the case runs DFSPH.
    pub fn dfsph(self) -> bool {
        matches!(self, Case::HydrostaticDfsph | Case::DamBreakMartinMoyceDfsph | Case::DamBreakKoshizukaOkaDfsph)
    }
    /// Whether the case carries the density by the continuity equation with delta-SPH
    /// diffusion and starts from the hydrostatic state.
    pub fn diffusion(self) -> bool {
        matches!(self, Case::HydrostaticDiffusion)
    }
    pub fn from_name(name: &str) -> Option<Case> {
        Case::ALL.into_iter().find(|c| c.name() == name)
    }
}

/// One error figure of a case and the tolerance it must stay within (value <= tolerance).
#[derive(Clone, Debug, PartialEq)]
pub struct Figure {
    pub name: String,
    pub value: f64,
    pub tolerance: f64,
}

impl Figure {
    pub fn new(name: impl Into<String>, value: f64, tolerance: f64) -> Self {
        Figure { name: name.into(), value, tolerance }
    }
    /// A figure measured and shown with no bound to meet (its tolerance is infinite).
    pub fn reported(name: impl Into<String>, value: f64) -> Self {
        Figure { name: name.into(), value, tolerance: f64::INFINITY }
    }
    /// NaN never passes.
    pub fn passed(&self) -> bool {
        self.value <= self.tolerance
    }
    /// The bound as shown: `<= TOLERANCE`, or `reported` where there is none.
    pub fn bound(&self) -> String {
        if self.tolerance.is_finite() {
            format!("<= {}", fmt_num(self.tolerance))
        } else {
            "reported".into()
        }
    }
}

/// The pressure-noise figure of a probe's series of (time, pressure): the standard deviation
/// of the pressure around its moving mean over `window` seconds centred on each sample (NaN for
/// fewer than two samples). The moving mean keeps the flow's own change of pressure; what
/// remains is the sample-to-sample scatter of weakly compressible SPH.
pub fn noise_around_moving_mean(series: &[(f64, f64)], window: f64) -> f64 {
    if series.len() < 2 {
        return f64::NAN;
    }
    let mut prefix = vec![0.0; series.len() + 1];
    for (i, &(_, p)) in series.iter().enumerate() {
        prefix[i + 1] = prefix[i] + p;
    }
    let (mut lo, mut hi, mut sum2) = (0, 0, 0.0);
    for &(t, p) in series {
        while series[lo].0 < t - 0.5 * window {
            lo += 1;
        }
        while hi < series.len() && series[hi].0 <= t + 0.5 * window {
            hi += 1;
        }
        let mean = (prefix[hi] - prefix[lo]) / (hi - lo) as f64;
        sum2 += (p - mean) * (p - mean);
    }
    (sum2 / series.len() as f64).sqrt()
}

/// What a case found.
#[derive(Clone, Debug)]
pub struct CaseReport {
    pub case: Case,
    pub resolution: Resolution,
    pub fluid_particles: usize,
    pub adapter: String,
    pub figures: Vec<Figure>,
    /// Fluid particles found inside a solid region, summed over the checked steps.
    pub wall_leaks: u64,
    /// Steps at which the leak count was checked.
    pub checked_steps: Vec<u64>,
    /// The deepest a fluid particle came past a wall's face, in particle spacings.
    pub deepest_spacings: f64,
    /// The largest rho/rho0 and Mach number of any step of the case's runs.
    pub regime: Regime,
    pub plot: PathBuf,
    pub csv: PathBuf,
    pub wall_seconds: f64,
    /// Why the run failed before it could be judged (a blow-up, an escaped particle).
    pub failure: Option<String>,
}

impl CaseReport {
    pub fn passed(&self) -> bool {
        self.failure.is_none() && self.wall_leaks == 0 && !self.figures.is_empty() && self.figures.iter().all(Figure::passed)
    }
    pub fn figure(&self, name: &str) -> Option<&Figure> {
        self.figures.iter().find(|f| f.name == name)
    }
    /// The case's row of validation.md.
    pub fn markdown_row(&self) -> String {
        let figs: Vec<String> = self
            .figures
            .iter()
            // A '|' would end the table cell.
            .map(|f| format!("{} = {} ({}{})", f.name.replace('|', "\\|"), fmt_num(f.value), f.bound(), if f.passed() { "" } else { ", FAILED" }))
            .collect();
        let mut notes = figs.join("; ");
        notes += &format!(
            "; fluid particles inside walls: {} over {} checked steps (deepest past a face: {} spacings); largest rho/rho0 {}",
            self.wall_leaks,
            self.checked_steps.len(),
            fmt_num(self.deepest_spacings),
            fmt_num(self.regime.max_density_ratio),
        );
        // An incompressible run (DFSPH) has no speed of sound, so no Mach number.
        if self.regime.max_mach.is_finite() {
            notes += &format!(", Mach {}", fmt_num(self.regime.max_mach));
        }
        if let Some(f) = &self.failure {
            notes += &format!("; run failed: {f}");
        }
        format!(
            "| {} | {} | {} | {} | {} | {:.0} s | {} |",
            self.case.name(),
            self.resolution.name(),
            self.fluid_particles,
            notes,
            if self.passed() { "pass" } else { "FAIL" },
            self.wall_seconds,
            self.plot.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default()
        )
    }
}

pub fn fmt_num(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else if !v.is_finite() {
        format!("{v}")
    } else if v.abs() >= 0.01 && v.abs() < 1e4 {
        format!("{v:.4}").trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{v:.2e}")
    }
}

/// Makes a backend for a scene, from its own particles or the ones given (the GPU path, or the
/// CPU): a closure around [`crate::solver::open_with`] and the backend the caller chose.
pub type MakeBackend<'a> = dyn FnMut(&Scene, Option<InitialState>) -> anyhow::Result<Box<dyn Backend>> + 'a;

/// How deep (in particle spacings) a fluid particle must be inside a solid region to count as a
/// leak: far below any real penetration, above the f32 rounding of a particle put back on a plane.
pub const LEAK_DEPTH_SPACINGS: f64 = 1e-3;

/// Fluid particles deeper than `depth` inside any of the solid regions.
pub fn particles_inside_solids(positions: &[[f64; 3]], solids: &[SolidRegion], depth: f64) -> u64 {
    positions
        .iter()
        .filter(|x| solids.iter().any(|r| (0..3).all(|a| x[a] > r.min[a] + depth && x[a] < r.max[a] - depth)))
        .count() as u64
}

/// How deep a point lies inside a solid region (0 when outside).
pub fn depth_inside(x: [f64; 3], r: &SolidRegion) -> f64 {
    (0..3).map(|a| (x[a] - r.min[a]).min(r.max[a] - x[a])).fold(f64::INFINITY, f64::min).max(0.0)
}

/// The largest density over the rest density and speed over the speed of sound of any step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Regime {
    pub max_density_ratio: f64,
    pub max_mach: f64,
}

impl Regime {
    /// The larger of each.
    pub fn max(self, o: Regime) -> Regime {
        Regime { max_density_ratio: self.max_density_ratio.max(o.max_density_ratio), max_mach: self.max_mach.max(o.max_mach) }
    }
}

/// Steps a backend to each of `sample_steps` (increasing), checking health and leaks at every
/// one, and hands each snapshot to `visit`. Returns the leaks, the checked steps, and a failure.
pub struct Sampler {
    /// The scene sampled (for the diagnosis of a failure).
    pub scene: Scene,
    pub solids: Vec<SolidRegion>,
    pub leak_depth: f64,
    pub wall_leaks: u64,
    /// The deepest any fluid particle was inside a solid region, at any checked step.
    pub deepest: f64,
    pub checked_steps: Vec<u64>,
    /// The regime the sampled run reached, read with the health at every sample.
    pub regime: Regime,
}

impl Sampler {
    pub fn new(scene: &Scene) -> Self {
        Sampler {
            scene: scene.clone(),
            solids: scene.solid_regions(),
            leak_depth: LEAK_DEPTH_SPACINGS * scene.physics.particle_spacing,
            wall_leaks: 0,
            deepest: 0.0,
            checked_steps: Vec::new(),
            regime: Regime::default(),
        }
    }

    /// Runs to every step of `sample_steps` and calls `visit` with the snapshot there.
    pub fn run(
        &mut self,
        backend: &mut dyn Backend,
        sample_steps: impl IntoIterator<Item = u64>,
        mut visit: impl FnMut(&Snapshot),
    ) -> anyhow::Result<Result<(), String>> {
        for target in sample_steps {
            let now = backend.steps_done();
            if target > now {
                backend.step(target - now)?;
            }
            let health = backend.health()?;
            let params = backend.params();
            self.regime = self.regime.max(Regime { max_density_ratio: health.max_density / params.rest_density, max_mach: health.max_speed / params.speed_of_sound() });
            if !health.is_ok() {
                return Ok(Err(diagnose_failure(backend, &self.scene)?));
            }
            let snap = backend.snapshot()?;
            self.wall_leaks += particles_inside_solids(&snap.positions, &self.solids, self.leak_depth);
            for x in &snap.positions {
                for r in &self.solids {
                    self.deepest = self.deepest.max(depth_inside(*x, r));
                }
            }
            self.checked_steps.push(snap.step);
            visit(&snap);
        }
        Ok(Ok(()))
    }
}

/// Writes a CSV with a header and rows of numbers, atomically.
pub fn write_csv(path: &Path, header: &[&str], rows: &[Vec<f64>]) -> anyhow::Result<()> {
    write_atomic(path, |w| {
        writeln!(w, "{}", header.join(","))?;
        for r in rows {
            let cells: Vec<String> = r.iter().map(|v| if v.is_finite() { format!("{v}") } else { String::new() }).collect();
            writeln!(w, "{}", cells.join(","))?;
        }
        Ok(())
    })
}

/// Kinetic + potential (in gravity) + elastic energy. The elastic energy per unit mass e(rho) is
/// the work integral of p / rho^2 from rho0 to rho (de/drho = p / rho^2, Monaghan 2005, Sec. 3):
/// for the Tait equation p = B ((rho/rho0)^7 - 1) it is
/// B / (6 rho0^7) (rho^6 - rho0^6) + B (1/rho - 1/rho0), for the linear p = k (rho/rho0 - 1)
/// k/rho0 ln(rho/rho0) + k (1/rho - 1/rho0); with clamped negative pressure it is 0 below rho0.
pub fn energy(s: &Snapshot, p: &Params) -> f64 {
    let m = p.fluid_mass;
    let (b, r0) = (p.stiffness, p.rest_density);
    let mut e = 0.0;
    for i in 0..s.len() {
        let v = s.velocities[i];
        let x = s.positions[i];
        e += m * (0.5 * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) - (p.gravity[0] * x[0] + p.gravity[1] * x[1] + p.gravity[2] * x[2]));
        let rho = s.densities[i];
        if rho > r0 || !p.clamp_negative_pressure {
            e += m * match p.eos {
                EquationOfState::Tait => b / (6.0 * r0.powi(7)) * (rho.powi(6) - r0.powi(6)) + b * (1.0 / rho - 1.0 / r0),
                EquationOfState::Linear => b / r0 * (rho / r0).ln() + b * (1.0 / rho - 1.0 / r0),
            };
        }
    }
    e
}

