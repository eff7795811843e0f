//! The validation scenes, built in code so that one description serves every resolution.
//!
//! All are SI and weakly compressible in the usual way (Monaghan 1994): Tait equation of state
//! with a speed of sound ten times the largest flow speed (density varies by about 1 %), h = 2
//! particle spacings, and dt = 0.25 h / c0 (CFL number 0.25 on the speed of sound).
//! A 3D run of a 2D experiment is a slab four particle spacings deep between walls in z.

use crate::model::scene::{Boundary, BoundaryPressure, Domain, EquationOfState, FluidBlock, Kernel, Physics, PressureSolver, Scene, SceneOrigin, Time, WallParticles};

pub const GRAVITY: f64 = 9.81;
/// Support radius in particle spacings.
pub const H_OVER_SPACING: f64 = 2.0;
/// CFL number on the speed of sound.
pub const CFL: f64 = 0.25;
/// Depth of the slab of a 2D experiment, in particle spacings.
pub const SLAB_SPACINGS: f64 = 4.0;
/// CFL number of a DFSPH case on its largest flow speed (c0 / 10), DFSPH's default (docs/dfsph.md).
pub const DFSPH_CFL: f64 = 0.4;
/// The explicit viscosity's bound on a step, dt <= 0.125 h^2 / nu (the adaptive step's viscous
/// number; Monaghan 1992 for diffusion).
pub const VISCOUS_NUMBER: f64 = 0.125;

/// Layers of wall particles: one more than a kernel support (h = 2 spacings), so that a
/// particle pressed into the wall at an impact still has wall particles behind it.
pub const WALL_LAYERS: u32 = 3;

/// A closed tank of wall particles (backed by analytic planes on its inner faces) holding boxes
/// of fluid.
#[derive(Clone, Debug)]
pub struct Tank {
    pub name: String,
    pub spacing: f64,
    /// Inner size of the tank; its inner faces are at 0 and at `size` on every axis.
    pub size: [f64; 3],
    /// Boxes of fluid: min, max, initial velocity.
    pub fluid: Vec<([f64; 3], [f64; 3], [f64; 3])>,
    /// Support radius h in particle spacings.
    pub h_over_spacing: f64,
    pub speed_of_sound: f64,
    /// Artificial viscosity coefficient alpha: nu = alpha h c0 / 8 (Monaghan 2005, Sec. 4.2;
    /// the value WCSPH codes use to damp acoustic noise is 0.01 to 0.1).
    pub alpha: f64,
    pub end_time: f64,
    pub gravity: [f64; 3],
    pub kernel: Kernel,
    /// Walls of wall particles backed by planes; `false`: the planes alone (a closed box whose
    /// walls exert no force until a particle touches them).
    pub walls: bool,
    /// Analytic planes on the inner faces (behind the wall particles).
    pub planes: bool,
    /// Layers of wall particles.
    pub wall_layers: u32,
    /// The wall particles' pressure term.
    pub boundary_pressure: BoundaryPressure,
    /// The pressure from DFSPH (default tolerances) instead of the equation of state; the speed
    /// of sound then only sets the viscosity (the same nu as the weakly compressible case) and
    /// the reference flow speed c0 / 10.
    pub dfsph: bool,
}

impl Tank {
    pub fn h(&self) -> f64 {
        self.h_over_spacing * self.spacing
    }
    /// WCSPH: CFL 0.25 on c0. DFSPH: CFL 0.4 on the largest flow speed, c0 / 10, bounded by the
    /// explicit viscosity's condition.
    pub fn dt(&self) -> f64 {
        if self.dfsph {
            let flow = DFSPH_CFL * self.h() / (0.1 * self.speed_of_sound);
            let nu = self.viscosity();
            if nu > 0.0 { flow.min(VISCOUS_NUMBER * self.h() * self.h() / nu) } else { flow }
        } else {
            CFL * self.h() / self.speed_of_sound
        }
    }
    /// The speed in the viscosity nu = alpha h c / 8: c0 with WCSPH; with DFSPH, which has no
    /// speed of sound, the largest flow speed c0 / 10 (with c0 the explicit viscosity would bound
    /// DFSPH's step below its CFL step, and made the still tank diverge at 13 times WCSPH's dt).
    pub fn viscosity_speed(&self) -> f64 {
        if self.dfsph {
            0.1 * self.speed_of_sound
        } else {
            self.speed_of_sound
        }
    }
    pub fn viscosity(&self) -> f64 {
        self.alpha * self.h() * self.viscosity_speed() / 8.0
    }

    pub fn scene(&self) -> anyhow::Result<Scene> {
        let s = self.spacing;
        let margin = (self.wall_layers as f64 + 1.0) * s;
        let mut boundary = Vec::new();
        if self.walls {
            boundary.push(Boundary::Container {
                min: [0.0; 3],
                max: self.size,
                open_top: false,
                walls: WallParticles { layers: Some(self.wall_layers), spacing: None, rest_density: None },
            });
        }
        // Planes on the inner faces back the wall particles up (see docs/equations.md).
        if self.planes {
            for a in 0..3 {
                let mut n = [0.0; 3];
                n[a] = 1.0;
                boundary.push(Boundary::Plane { point: [0.0; 3], normal: n, restitution: 0.0 });
                let mut p = [0.0; 3];
                p[a] = self.size[a];
                n[a] = -1.0;
                boundary.push(Boundary::Plane { point: p, normal: n, restitution: 0.0 });
            }
        }
        let (solver, speed_of_sound) = if self.dfsph { (PressureSolver::Dfsph, None) } else { (PressureSolver::Wcsph, Some(self.speed_of_sound)) };
        let scene = Scene {
            name: self.name.clone(),
            description: format!("validation scene {}", self.name),
            seed: 1,
            domain: Domain {
                min: [-margin; 3],
                max: [self.size[0] + margin, self.size[1] + margin, self.size[2] + margin],
            },
            physics: Physics {
                kernel: self.kernel,
                equation_of_state: EquationOfState::Tait,
                speed_of_sound,
                clamp_negative_pressure: true,
                viscosity: self.viscosity(),
                boundary_friction: 0.0,
                boundary_pressure: self.boundary_pressure,
                gravity: self.gravity,
                solver,
                ..Physics::new(self.h(), s)
            },
            time: Time::fixed(self.dt(), self.end_time),
            fluid: self
                .fluid
                .iter()
                .map(|&(min, max, velocity)| FluidBlock { min, max, jitter: 0.0, velocity, shape: Default::default() })
                .collect(),
            boundary,
            camera: None,
            limits: Default::default(),
            probe: Vec::new(),
        };
        scene.validate(&SceneOrigin::BuiltIn(self.name.clone()))?;
        Ok(scene)
    }
}

/// Steps to reach time `t`.
pub fn steps_to(t: f64, dt: f64) -> u64 {
    (t / dt - 1e-9).ceil().max(0.0) as u64
}

/// Sample steps every `every` seconds up to `end` (the last one at `end`).
pub fn sample_steps(every: f64, end: f64, dt: f64) -> Vec<u64> {
    let last = steps_to(end, dt);
    let k = steps_to(every, dt).max(1);
    let mut v: Vec<u64> = (1..).map(|i| i * k).take_while(|&s| s < last).collect();
    v.push(last);
    v
}
