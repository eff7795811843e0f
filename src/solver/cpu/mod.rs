//! The CPU reference path: the same stages as the GPU, one file per WGSL stage with the same
//! name and the same entry points, generic over f32 and f64. `f64` is the judge of every GPU
//! result.

pub mod bin_count;
pub mod bin_scatter;
pub mod cell_batches;
pub mod continuity;
pub mod density;
pub mod dfsph;
pub mod dfsph_convergence;
pub mod dfsph_divergence;
pub mod dfsph_factors;
pub mod dfsph_integrate;
pub mod dfsph_predict;
pub mod dfsph_pressure;
pub mod dfsph_shared;
pub mod exchange;
pub mod fields;
pub mod ghost_link;
pub mod ghost_velocities;
pub mod forces;
pub mod forces_integrate;
pub mod integrate;
pub mod neighbour_skin;
pub mod prefix_sum;
pub mod probes;
pub mod rank_device;
mod rank_gather;
pub mod reorder;
pub mod resident_exchange;
mod resident_steps;
pub mod surface_normals;
pub mod wall_pressure;

use super::backend::{Backend, StateArray, StatePiece};
use cell_batches::NeighbourLists;
use crate::model::initial::InitialState;
use crate::model::kernels::{sort_by_cell, KernelCoefficients, Neighbours};
use crate::model::params::{Grid, Params};
use crate::model::probes::{ProbeGeometry, ProbeSample};
use crate::model::real::{Real, V3};
use crate::model::scene::BoundaryPressure;
use crate::model::state::{BackendState, DfsphFields, DtStats, Health, Snapshot, StepFields};
use dfsph::{DfsphCpu, StepParts};
use integrate::{Backstops, PlaneR, SolidBoxR};

/// The CPU solver (cloned, it continues independently from the same state). Particle arrays
/// are kept in cell order (like the GPU's); `ids` maps each slot
/// back to the particle's original index.
#[derive(Clone)]
pub struct CpuSolver<R: Real> {
    params: Params,
    kernel: KernelCoefficients<R>,
    grid: Grid<R>,
    backstops: Backstops<R>,
    positions: Vec<V3<R>>,
    velocities: Vec<V3<R>>,
    ids: Vec<u32>,
    densities: Vec<R>,
    pressures: Vec<R>,
    accelerations: Vec<V3<R>>,
    /// With continuity density: the density each particle carries from the last step (empty
    /// otherwise).
    carried_densities: Vec<R>,
    scratch_r: Vec<R>,
    /// Whether density and forces run eight particles at a time ([`CpuSolver::use_lanes`]).
    lanes: bool,
    /// The neighbour lists of the last density stage, which the forces read (none without
    /// lanes).
    lists: NeighbourLists,
    /// Each particle's position and, once the forces have set it, p / rho^2 (the lane path's
    /// neighbour loads: one of 16 bytes each).
    fluid_points: Vec<[R; 4]>,
    /// Each wall particle's position and mass, for the lane path.
    wall_points: Vec<[R; 4]>,
    keys: Vec<u32>,
    counts: Vec<u32>,
    starts: Vec<u32>,
    sorted: Vec<u32>,
    scratch_v3: Vec<V3<R>>,
    scratch_ids: Vec<u32>,
    /// Across ranks with DFSPH: each slot's entry in the warm-start arrays, which hold the
    /// held particles' stiffnesses in the order of the last exchange (the binning moves these
    /// keys with the particles). Alone the arrays are by id and this is empty.
    warm_keys: Vec<u32>,
    wall_positions: Vec<V3<R>>,
    wall_masses: Vec<R>,
    wall_starts: Vec<u32>,
    /// With `boundary_pressure = "adami"`: each sorted wall particle's [pressure, density] of
    /// the last density stage (empty otherwise).
    wall_fields: Vec<[R; 2]>,
    /// The original index of each sorted wall particle.
    wall_order: Vec<u32>,
    /// With surface tension: each fluid particle's normal of the last forces stage, in cell
    /// order (empty otherwise).
    normals: Vec<V3<R>>,
    step: u64,
    health: Health,
    /// Simulated time and the steps' dt (adaptive dt makes them differ from step x dt).
    time: f64,
    dt_stats: DtStats,
    /// DFSPH's arrays, when the scene uses it.
    dfsph: Option<DfsphCpu<R>>,
    /// Each sorted wall particle's mask of the force probes that read it (empty without them).
    wall_probe_masks: Vec<u32>,
    /// The probe samples taken since they were last handed out.
    probe_samples: Vec<ProbeSample>,
    /// This rank's share when the simulation runs across ranks (`None`: one process).
    ranks: Option<Box<exchange::RankPart>>,
    /// Across ranks on a device: the stages between the exchange and the step's bookkeeping.
    device: Option<rank_device::SharedDeviceStages<R>>,
    /// Across ranks on a device: whether it holds what the host holds (resident steps).
    device_held: resident_steps::DeviceHeld,
}

impl<R: Real> CpuSolver<R> {
    /// The CPU solver of a scene. Programs build one through [`crate::solver::open`].
    pub(crate) fn new(params: &Params, initial: &InitialState) -> Self {
        let grid = params.grid.cast::<R>();
        let n = initial.fluid_positions.len();
        let backstops = Backstops {
            planes: params.planes.iter().map(|p| PlaneR { normal: V3::from64(p.normal), offset: R::of(p.offset), restitution: R::of(p.restitution) }).collect(),
            boxes: params.solid_boxes.iter().map(|b| SolidBoxR { min: V3::from64(b.min), max: V3::from64(b.max) }).collect(),
        };
        let mut solver = CpuSolver {
            params: params.clone(),
            kernel: KernelCoefficients::new(params.kernel, params.h),
            grid,
            backstops,
            positions: initial.fluid_positions.iter().map(|&p| V3::from64(p)).collect(),
            velocities: initial.fluid_velocities.iter().map(|&p| V3::from64(p)).collect(),
            ids: (0..n as u32).collect(),
            densities: vec![R::zero(); n],
            pressures: vec![R::zero(); n],
            accelerations: vec![V3::zero(); n],
            carried_densities: if params.continuity_density { (0..n).map(|i| R::of(initial.fluid_density(i, params.rest_density))).collect() } else { Vec::new() },
            scratch_r: Vec::new(),
            lanes: true,
            lists: NeighbourLists::default(),
            fluid_points: Vec::new(),
            wall_points: Vec::new(),
            keys: vec![0; n],
            counts: vec![0; grid.cell_count()],
            starts: vec![0; grid.cell_count() + 1],
            sorted: vec![0; n],
            scratch_v3: Vec::with_capacity(n),
            scratch_ids: Vec::with_capacity(n),
            warm_keys: Vec::new(),
            wall_positions: Vec::new(),
            wall_masses: Vec::new(),
            wall_starts: Vec::new(),
            wall_fields: Vec::new(),
            wall_order: Vec::new(),
            normals: Vec::new(),
            step: 0,
            health: Health::default(),
            time: 0.0,
            dt_stats: DtStats { min: f64::INFINITY, ..DtStats::default() },
            dfsph: params.dfsph.as_ref().map(|settings| DfsphCpu::new(settings, n)),
            wall_probe_masks: Vec::new(),
            probe_samples: Vec::new(),
            ranks: None,
            device: None,
            device_held: Default::default(),
        };
        solver.install_walls(initial);
        solver
    }

    /// The wall particles of `walls` (its fluid is not read): sorted by cell once, as walls
    /// never move; across ranks again whenever the slab's bounds move, and handed to the
    /// device stages too.
    pub(crate) fn install_walls(&mut self, initial: &InitialState) {
        self.install_walls_on_host(initial);
        if let Some(device) = &self.device {
            rank_device::lock(device).set_walls(initial);
        }
    }

    /// The host's wall arrays of [`Self::install_walls`] (a device's walls left as they are).
    fn install_walls_on_host(&mut self, initial: &InitialState) {
        let params = &self.params;
        let walls: Vec<V3<R>> = initial.wall_positions.iter().map(|&p| V3::from64(p)).collect();
        let (wall_order, wall_starts) = sort_by_cell(&self.grid, &walls);
        let masks = params.probes.wall_masks(&initial.wall_positions, &initial.wall_boundaries);
        self.wall_probe_masks = if params.probes.force_count() > 0 { wall_order.iter().map(|&i| masks[i as usize]).collect() } else { Vec::new() };
        // Without walls no stage visits them: no per-cell array.
        self.wall_starts = if walls.is_empty() { Vec::new() } else { wall_starts };
        self.wall_positions = wall_order.iter().map(|&i| walls[i as usize]).collect();
        self.wall_masses = wall_order.iter().map(|&i| R::of(initial.wall_masses[i as usize])).collect();
        self.wall_points = self.wall_positions.iter().zip(&self.wall_masses).map(|(x, &m)| [x.0[0], x.0[1], x.0[2], m]).collect();
        self.wall_fields = if params.boundary_pressure == BoundaryPressure::Adami { vec![[R::zero(), R::of(params.rest_density)]; walls.len()] } else { Vec::new() };
        self.wall_order = wall_order;
    }

    pub fn params(&self) -> &Params {
        &self.params
    }
    pub fn steps_done(&self) -> u64 {
        self.step
    }
    pub fn health(&self) -> Health {
        Health { iterations: self.dfsph.as_ref().map(|d| d.stats), ..self.health }
    }
    pub fn fluid_len(&self) -> usize {
        self.positions.len()
    }
    pub fn time(&self) -> f64 {
        if self.params.adaptive.is_some() {
            self.time
        } else {
            self.step as f64 * self.params.dt
        }
    }
    pub fn dt_stats(&self) -> DtStats {
        if self.step == 0 {
            DtStats::default()
        } else {
            DtStats { mean: self.time() / self.step as f64, ..self.dt_stats }
        }
    }
    /// Bytes of the solver's arrays.
    pub fn memory_bytes(&self) -> u64 {
        let r = std::mem::size_of::<R>() as u64;
        let v3 = 3 * r;
        let n = self.positions.len() as u64;
        n * (4 * v3 + 2 * r + 4 * 4) // positions, velocities, accelerations, scratch; densities, pressures; ids, keys, sorted, scratch ids
            + (self.counts.len() + self.starts.len() + self.wall_starts.len()) as u64 * 4
            + self.wall_positions.len() as u64 * (v3 + r)
            + self.wall_fields.len() as u64 * 2 * r
            + self.normals.capacity() as u64 * v3
            + self.dfsph.as_ref().map_or(0, |d| d.memory_bytes())
            + (self.carried_densities.len() + self.scratch_r.capacity() + 4 * (self.fluid_points.capacity() + self.wall_points.capacity())) as u64 * r
            + self.lists.bytes()
    }

    /// Density and forces eight particles at a time (`true`, the default, where the processor
    /// has AVX2) or each particle over its stencil as the GPU does (`false`): the same values bit
    /// for bit, which the parity tests check.
    pub fn use_lanes(&mut self, on: bool) {
        self.lanes = on;
    }

    /// Stage 1: counting-sort binning and reordering of the state into cell order.
    pub fn bin(&mut self) {
        self.counts.fill(0);
        bin_count::bin_count(&self.grid, &self.positions, &mut self.keys, &mut self.counts);
        prefix_sum::prefix_sum(&self.counts, &mut self.starts);
        bin_scatter::bin_scatter(&self.keys, &self.starts, &mut self.sorted);
        reorder::reorder(&self.sorted, &self.positions, &mut self.scratch_v3);
        std::mem::swap(&mut self.positions, &mut self.scratch_v3);
        reorder::reorder(&self.sorted, &self.velocities, &mut self.scratch_v3);
        std::mem::swap(&mut self.velocities, &mut self.scratch_v3);
        reorder::reorder(&self.sorted, &self.ids, &mut self.scratch_ids);
        std::mem::swap(&mut self.ids, &mut self.scratch_ids);
        if self.warm_keys.len() == self.ids.len() && !self.warm_keys.is_empty() {
            reorder::reorder(&self.sorted, &self.warm_keys, &mut self.scratch_ids);
            std::mem::swap(&mut self.warm_keys, &mut self.scratch_ids);
        }
        if !self.carried_densities.is_empty() {
            reorder::reorder(&self.sorted, &self.carried_densities, &mut self.scratch_r);
            std::mem::swap(&mut self.carried_densities, &mut self.scratch_r);
        }
    }

    /// Stage 2: density and pressure of every particle.
    pub fn compute_density(&mut self) {
        if self.lanes && cell_batches::lanes_available() {
            cell_batches::points(&self.positions, &mut self.fluid_points);
        }
        let p = &self.params;
        if p.continuity_density {
            let input = continuity::ContinuityInput {
                kernel: &self.kernel,
                grid: &self.grid,
                dt: R::of(match p.adaptive {
                    Some(a) => a.continuity_dt(p.h, p.speed_of_sound(), self.dt_stats.last),
                    None => p.dt,
                }),
                fluid_mass: R::of(p.fluid_mass),
                rest_density: R::of(p.rest_density),
                stiffness: R::of(p.stiffness),
                eos: p.eos,
                clamp_negative_pressure: p.clamp_negative_pressure,
                gravity: V3::from64(p.gravity),
                diffusion_factor: R::of(p.diffusion_factor()),
                fluid: Neighbours { positions: &self.positions, starts: &self.starts },
                velocities: &self.velocities,
                carried: &self.carried_densities,
                walls: Neighbours { positions: &self.wall_positions, starts: &self.wall_starts },
                wall_masses: &self.wall_masses,
            };
            continuity::continuity_density(&input, &mut self.densities, &mut self.pressures);
            // The forces read the neighbour lists that the summation builds.
            if self.lanes && cell_batches::lanes_available() {
                self.lists.build(&self.grid, input.fluid, input.walls, self.kernel.h2);
            } else {
                self.lists.clear();
            }
            return;
        }
        let input = density::DensityInput {
            kernel: &self.kernel,
            grid: &self.grid,
            fluid_mass: R::of(p.fluid_mass),
            rest_density: R::of(p.rest_density),
            stiffness: R::of(p.stiffness),
            eos: p.eos,
            clamp_negative_pressure: p.clamp_negative_pressure,
            fluid: Neighbours { positions: &self.positions, starts: &self.starts },
            walls: Neighbours { positions: &self.wall_positions, starts: &self.wall_starts },
            wall_masses: &self.wall_masses,
            fluid_points: &self.fluid_points,
            wall_points: &self.wall_points,
        };
        density::density(&input, self.lanes, &mut self.lists, &mut self.densities, &mut self.pressures);
    }

    /// Stage 2': with `boundary_pressure = "adami"`, each wall particle's pressure and density
    /// extrapolated from the fluid's fields of this step (nothing otherwise).
    pub fn compute_wall_pressure(&mut self) {
        if self.wall_fields.is_empty() {
            return;
        }
        let p = &self.params;
        let input = wall_pressure::WallPressureInput {
            kernel: &self.kernel,
            grid: &self.grid,
            rest_density: R::of(p.rest_density),
            stiffness: R::of(p.stiffness),
            eos: p.eos,
            clamp_negative_pressure: p.clamp_negative_pressure,
            gravity: V3::from64(p.gravity),
            fluid: Neighbours { positions: &self.positions, starts: &self.starts },
            densities: &self.densities,
            pressures: &self.pressures,
            wall_positions: &self.wall_positions,
        };
        wall_pressure::wall_pressure(&input, &mut self.wall_fields);
    }

    /// Each wall particle's [pressure, density] of the last density stage, in the walls'
    /// original order (`boundary_pressure = "adami"`; empty otherwise).
    pub fn wall_fields(&self) -> Vec<[f64; 2]> {
        let mut out = vec![[0.0; 2]; self.wall_fields.len()];
        for (slot, f) in self.wall_fields.iter().enumerate() {
            out[self.wall_order[slot] as usize] = [f[0].to64(), f[1].to64()];
        }
        out
    }

    /// What the forces read: the current state and the fields of the last density stage.
    fn forces_input(&self) -> forces::ForcesInput<'_, R> {
        let p = &self.params;
        forces::ForcesInput {
            kernel: &self.kernel,
            grid: &self.grid,
            fluid_mass: R::of(p.fluid_mass),
            viscosity: R::of(p.viscosity_at_step(self.step)),
            rest_density: R::of(p.rest_density),
            boundary_friction: R::of(p.boundary_friction),
            boundary_pressure: p.boundary_pressure,
            gravity: V3::from64(p.gravity),
            fluid: Neighbours { positions: &self.positions, starts: &self.starts },
            velocities: &self.velocities,
            densities: &self.densities,
            pressures: &self.pressures,
            walls: Neighbours { positions: &self.wall_positions, starts: &self.wall_starts },
            wall_masses: &self.wall_masses,
            artificial_viscosity_factor: R::of(p.artificial_viscosity_factor()),
            wall_fields: &self.wall_fields,
            lists: &self.lists,
            fluid_points: &self.fluid_points,
            wall_points: &self.wall_points,
            tension: forces::SurfaceTension::of(p),
            adhesion_factor: R::of(p.adhesion_factor()),
            normals: &self.normals,
        }
    }

    /// With surface tension, each fluid particle's normal from the fields of the last density
    /// stage (WCSPH) or factors stage (DFSPH), into `normals`; emptied otherwise.
    fn surface_normals_into(&self, normals: &mut Vec<V3<R>>) {
        if self.params.surface_tension <= 0.0 {
            normals.clear();
            return;
        }
        let input = surface_normals::SurfaceNormalsInput {
            kernel: &self.kernel,
            grid: &self.grid,
            fluid_mass: R::of(self.params.fluid_mass),
            fluid: Neighbours { positions: &self.positions, starts: &self.starts },
            densities: &self.densities,
            lists: &self.lists,
            fluid_points: &self.fluid_points,
        };
        surface_normals::surface_normals(&input, normals);
    }

    /// Stage 3a (wgsl/sim/surface_normals.wgsl): the normals the forces or DFSPH's prediction
    /// read, kept in the solver's array.
    fn update_surface_normals(&mut self) {
        let mut normals = std::mem::take(&mut self.normals);
        self.surface_normals_into(&mut normals);
        self.normals = normals;
    }

    /// Stage 3: accelerations.
    pub fn compute_forces(&mut self) {
        self.update_surface_normals();
        let mut accelerations = std::mem::take(&mut self.accelerations);
        if !self.lists.chunks().is_empty() {
            forces::pressure_terms(&self.densities, &self.pressures, &mut self.fluid_points);
        }
        forces::forces(&self.forces_input(), &mut accelerations);
        self.accelerations = accelerations;
    }

    /// Stages 3 and 4 fused with fixed dt ([`forces_integrate::forces_and_integrate`]): the
    /// next state, computed from the current one and the last density stage, without changing
    /// the solver (for the parity tests of the fused stage).
    pub fn forces_and_integrate(&self) -> (Vec<V3<R>>, Vec<V3<R>>, integrate::StepHealth) {
        let n = self.positions.len();
        let (mut x, mut v) = (vec![V3::zero(); n], vec![V3::zero(); n]);
        let mut rho = vec![R::zero(); self.carried_densities.len()];
        let domain = (V3::from64(self.params.domain_min), V3::from64(self.params.domain_max));
        let mut normals = Vec::new();
        self.surface_normals_into(&mut normals);
        let input = forces::ForcesInput { normals: &normals, ..self.forces_input() };
        let found = forces_integrate::forces_and_integrate(&input, R::of(self.params.dt), &self.backstops, domain, &mut x, &mut v, &mut rho);
        (x, v, found)
    }

    /// This step's dt: fixed, or with adaptive dt from the largest speed (at the start of the
    /// step) and acceleration (of this step), as wgsl/sim/integrate.wgsl `reduce_maxima` and
    /// `choose_dt`.
    pub fn choose_dt(&self) -> f64 {
        let Some(adaptive) = self.params.adaptive else {
            return self.params.dt;
        };
        let p = &self.params;
        let maxima = self.own_maxima();
        integrate::choose_dt(&adaptive, p.h, p.speed_of_sound(), maxima, p.viscosity_at_step(self.step))
    }

    /// Stage 4: integration and boundaries. Returns what went wrong in this step.
    pub fn integrate(&mut self) -> integrate::StepHealth {
        self.integrate_with(self.params.dt)
    }

    /// The integration of the own particles (all of them alone; across ranks the ghosts are
    /// left as they are, and replaced by the next exchange).
    fn integrate_with(&mut self, dt: f64) -> integrate::StepHealth {
        // The particles move: the density stage's neighbour lists no longer hold.
        self.lists.clear();
        let mut found: Option<integrate::StepHealth> = None;
        for own in self.own_slots() {
            let carried = if self.carried_densities.is_empty() { 0..0 } else { own.clone() };
            let input = integrate::IntegrateInput {
                dt: R::of(dt),
                backstops: &self.backstops,
                domain_min: V3::from64(self.params.domain_min),
                domain_max: V3::from64(self.params.domain_max),
                accelerations: &self.accelerations[own.clone()],
                densities: &self.densities[carried.clone()],
            };
            let part = integrate::integrate(&input, &mut self.positions[own.clone()], &mut self.velocities[own], &mut self.carried_densities[carried]);
            found = Some(found.map_or(part, |f| f.add(part)));
        }
        found.unwrap_or_default()
    }

    /// The largest speed (at the start of the step) and acceleration of the own particles.
    fn own_maxima(&self) -> (f64, f64) {
        self.own_slots()
            .into_iter()
            .map(|own| integrate::reduce_maxima(&self.velocities[own.clone()], &self.accelerations[own]))
            .fold((0.0, 0.0), |a, b| (a.0.max(b.0), a.1.max(b.1)))
    }

    /// The parts of the solver a DFSPH stage reads and writes, and DFSPH's own arrays.
    fn dfsph_parts(&mut self) -> Option<(&mut DfsphCpu<R>, StepParts<'_, R>)> {
        let dfsph = self.dfsph.as_mut()?;
        let (particles, link, warm_index) = match self.ranks.as_deref_mut() {
            Some(part) => (part.total_fluid, part.link.as_mut(), &self.warm_keys),
            None => (self.positions.len(), None, &self.ids),
        };
        let parts = StepParts {
            params: &self.params,
            kernel: &self.kernel,
            grid: &self.grid,
            backstops: &self.backstops,
            positions: &mut self.positions,
            velocities: &mut self.velocities,
            starts: &self.starts,
            scratch: &mut self.scratch_v3,
            warm_index,
            densities: &mut self.densities,
            pressures: &mut self.pressures,
            accelerations: &mut self.accelerations,
            wall_positions: &self.wall_positions,
            wall_starts: &self.wall_starts,
            wall_masses: &self.wall_masses,
            normals: &self.normals,
            step: self.step,
            lanes: self.lanes,
            particles,
            link,
        };
        Some((dfsph, parts))
    }

    /// DFSPH's arrays (for the stage tests).
    pub fn dfsph(&self) -> Option<&DfsphCpu<R>> {
        self.dfsph.as_ref()
    }

    /// DFSPH's arrays in original particle order (for the stage tests).
    pub fn dfsph_fields(&self) -> Option<DfsphFields> {
        let d = self.dfsph.as_ref()?;
        let ids = &self.ids;
        let scalars = |v: &[R]| unpermute(ids, v.iter().map(|x| x.to64()));
        let vectors = |v: &[V3<R>]| unpermute(ids, v.iter().map(|x| x.to64()));
        Some(DfsphFields {
            densities: scalars(&self.densities),
            pressures: scalars(&self.pressures),
            factors: scalars(&d.factors),
            wall_gradients: vectors(&d.wall_gradients),
            stiffness: scalars(&d.stiffness),
            pressure_sum: scalars(&d.pressure_sum),
            divergence_sum: scalars(&d.divergence_sum),
            velocities: vectors(&self.velocities),
        })
    }

    /// Runs one DFSPH stage on the current state (for the stage tests; [`CpuSolver::step_once`]
    /// runs them all in order). Returns the error sum of a stage that reduces one, and the
    /// step's dt after the prediction.
    pub fn dfsph_stage(&mut self, stage: crate::solver::backend::DfsphStage) -> Option<f64> {
        use crate::solver::backend::DfsphStage;
        if stage == DfsphStage::Predict {
            self.update_surface_normals();
        }
        let (d, mut s) = self.dfsph_parts()?;
        let volume = R::of(s.params.fluid_mass / s.params.rest_density);
        let input = dfsph_shared::SolveInput { pairs: &d.pairs, volume, factors: &d.factors, wall_gradients: &d.wall_gradients, ghosts: &[] };
        // The step's dt, as the prediction chose it.
        let dt = if d.dt > 0.0 { d.dt } else { s.params.dt };
        let share = R::of(dfsph_shared::WARM_START_SHARE);
        Some(match stage {
            DfsphStage::Factors => {
                d.factors_stage(&mut s);
                0.0
            }
            DfsphStage::DivergenceWarmStart => {
                let warm = dfsph_shared::WarmStart { ids: s.warm_index, last: &d.warm_divergence, share };
                dfsph_divergence::divergence_warm_start(&input, s.velocities, &warm, &mut d.stiffness);
                0.0
            }
            DfsphStage::PressureWarmStart => {
                let warm = dfsph_shared::WarmStart { ids: s.warm_index, last: &d.warm_pressure, share };
                dfsph_pressure::pressure_warm_start(&input, s.velocities, s.densities, R::of(s.params.rest_density), R::of(dt), &warm, &mut d.stiffness);
                0.0
            }
            DfsphStage::DivergenceRate => {
                let dt = R::of(d.divergence_dt(s.params));
                dfsph_divergence::divergence_rate(&input, s.velocities, dt, &mut d.stiffness) as f64
            }
            DfsphStage::DivergenceApply => {
                dfsph_divergence::divergence_apply(&input, &d.stiffness, s.velocities, &mut d.divergence_sum);
                0.0
            }
            DfsphStage::Predict => d.predict(&mut s),
            DfsphStage::PredictDensity => {
                dfsph_pressure::predict_density(&input, s.velocities, s.densities, R::of(s.params.rest_density), R::of(dt), &mut d.stiffness) as f64
            }
            DfsphStage::PressureApply => {
                dfsph_pressure::pressure_apply(&input, &d.stiffness, R::one() / R::of(dt), s.velocities, &mut d.pressure_sum);
                0.0
            }
        })
    }

    /// One full time step; records the first step that produced a non-finite or escaped particle.
    /// The neighbour grid is rebuilt every `rebuild_every` steps, as on the GPU.
    /// Across ranks the exchange stage comes first; alone it does nothing.
    pub fn step_once(&mut self) {
        if self.step % self.params.rebuild_every.max(1) as u64 == 0 {
            // Across ranks on a device that kept the last step's particles: the exchange on the
            // band alone, where the step allows it (resident_steps.rs).
            if self.step_resident() {
                return;
            }
            self.sync_held();
            self.exchange(true);
            if self.rank_failure().is_some() {
                return;
            }
            if self.device.is_some() {
                if self.step_on_device() {
                    // The device keeps what it gave back: the next step may start from it.
                    self.device_held = resident_steps::DeviceHeld::Same;
                }
                return;
            }
            self.bin();
        }
        if self.dfsph.is_some() {
            // The point probes and gauges sample the state the step starts from with the
            // factors' density and output pressure (wgsl: after the factors dispatch); the force
            // and front probes the step's first positions after the solves, whose wall push the
            // forces are (`sample_dfsph_forces`).
            let due = self.probes_due();
            // Across ranks, the ghosts' part in the solves (docs/scale-out.md).
            self.link_ghosts();
            let (dfsph, mut parts) = self.dfsph_parts().expect("a DFSPH scene");
            dfsph.factors_stage(&mut parts);
            // The prediction's surface normals, from the factors' densities.
            self.update_surface_normals();
            let points = due.then(|| self.sample_probe_points());
            let (dfsph, mut parts) = self.dfsph_parts().expect("a DFSPH scene");
            let dt = dfsph.solve(&mut parts);
            if let Some(values) = points {
                self.sample_dfsph_forces(values, dt);
            }
            let (dfsph, mut parts) = self.dfsph_parts().expect("a DFSPH scene");
            let (found, dt) = dfsph.finish(&mut parts, dt);
            self.unlink_ghosts();
            let max_density = self.largest_density();
            let (found, max_density) = self.all_step_health(found, max_density);
            self.health.max_density = self.health.max_density.max(max_density);
            self.record_step(dt, found, max_density);
            return;
        }
        self.compute_density();
        self.compute_wall_pressure();
        if self.probes_due() {
            self.sample_probes();
        }
        self.compute_forces();
        let dt = self.choose_dt_across_ranks();
        let max_density = self.largest_density();
        let h = self.integrate_with(dt);
        let (h, max_density) = self.all_step_health(h, max_density);
        self.health.max_density = self.health.max_density.max(max_density);
        self.record_step(dt, h, max_density);
    }

    /// [`CpuSolver::choose_dt`] with the maxima of every rank (the same dt everywhere).
    fn choose_dt_across_ranks(&mut self) -> f64 {
        let Some(adaptive) = self.params.adaptive else {
            return self.params.dt;
        };
        if self.ranks.is_none() {
            return self.choose_dt();
        }
        let (speed, accel) = self.own_maxima();
        let maxima = self.all_max(&[speed, accel]);
        let p = &self.params;
        integrate::choose_dt(&adaptive, p.h, p.speed_of_sound(), (maxima[0], maxima[1]), p.viscosity_at_step(self.step))
    }

    /// What the probes read: the solver's current arrays.
    fn probe_input(&self) -> probes::ProbeInput<'_, R> {
        let p = &self.params;
        probes::ProbeInput {
            kernel: &self.kernel,
            grid: &self.grid,
            fluid_mass: R::of(p.fluid_mass),
            viscosity: R::of(p.viscosity_at_step(self.step)),
            boundary_friction: R::of(p.boundary_friction),
            boundary_pressure: p.boundary_pressure,
            fluid: Neighbours { positions: &self.positions, starts: &self.starts },
            velocities: &self.velocities,
            densities: &self.densities,
            pressures: &self.pressures,
            walls: Neighbours { positions: &self.wall_positions, starts: &self.wall_starts },
            wall_masses: &self.wall_masses,
            wall_masks: &self.wall_probe_masks,
            wall_fields: &self.wall_fields,
            gravity: V3::from64(p.gravity),
            artificial_viscosity_factor: R::of(p.artificial_viscosity_factor()),
            adhesion_factor: R::of(p.adhesion_factor()),
        }
    }

    /// The force and front probes of a DFSPH step after its solves, into `values` (whose point
    /// probes and gauges are sampled), and the sample kept: the positions are the step's first,
    /// the forces the step's wall push ([`probes::wall_push_pressure`] through the consistent
    /// wall pressure), the viscous part from the velocities the prediction started from.
    fn sample_dfsph_forces(&mut self, values: Vec<f64>, dt: f64) {
        let d = self.dfsph.as_ref().expect("a DFSPH scene");
        let p = &self.params;
        let mut push = Vec::new();
        probes::wall_push_pressure(&self.densities, &d.pressure_sum, &d.divergence_sum, R::of(p.rest_density), R::of(dt), &mut push);
        let input = probes::ProbeInput {
            pressures: &push,
            velocities: &self.scratch_v3,
            boundary_pressure: BoundaryPressure::Consistent,
            artificial_viscosity_factor: R::zero(),
            ..self.probe_input()
        };
        let (list, offsets) = (&p.probes.probes, p.probes.offsets());
        let (values, failure) = match &self.ranks {
            None => {
                let mut values: Vec<R> = values.iter().map(|&v| R::of(v)).collect();
                let mut partials = Vec::new();
                probes::probe_particles(&input, list, None, &mut partials);
                probes::probe_finish(list, &offsets, &partials, &mut values);
                (values.iter().map(|v| v.to64()).collect(), None)
            }
            Some(_) => {
                // Every probe's values from the push (as one rank takes the gauges and fronts from
                // the same positions and densities), then the points' from the factors' state.
                let (mut all, failure) = self.probes_on_ranks(&input);
                for (probe, &at) in list.iter().zip(&offsets) {
                    if matches!(probe.geometry, ProbeGeometry::Point { .. }) {
                        let columns = at..at + probe.geometry.columns().len();
                        all[columns.clone()].copy_from_slice(&values[columns]);
                    }
                }
                (all, failure)
            }
        };
        self.note_failure(failure);
        self.push_probe_sample(values);
    }

    /// DFSPH: the point probes (and, alone, the gauges) on the state the step starts from, with
    /// the factors' density and output pressure; across ranks every probe's values of that state
    /// (the points' are kept, the rest sampled again after the solves).
    fn sample_probe_points(&mut self) -> Vec<f64> {
        let (list, offsets) = (&self.params.probes.probes, self.params.probes.offsets());
        match &self.ranks {
            None => {
                let mut values = vec![R::zero(); self.params.probes.value_count()];
                probes::probe_points(&self.probe_input(), list, &offsets, &mut values);
                values.iter().map(|v| v.to64()).collect()
            }
            Some(_) => {
                let (values, failure) = self.probes_on_ranks(&self.probe_input());
                self.note_failure(failure);
                values
            }
        }
    }

    /// Samples every probe on the state the step starts from and the fields of its density
    /// stage (wgsl/sim/probes.wgsl's three entry points in order).
    pub fn sample_probes(&mut self) {
        let input = self.probe_input();
        let p = &self.params;
        let list = &p.probes.probes;
        let offsets = p.probes.offsets();
        let mut values = vec![R::zero(); p.probes.value_count()];
        let values: Vec<f64> = match &self.ranks {
            None => {
                probes::probe_points(&input, list, &offsets, &mut values);
                let mut partials = Vec::new();
                probes::probe_particles(&input, list, None, &mut partials);
                probes::probe_finish(list, &offsets, &partials, &mut values);
                values.iter().map(|v| v.to64()).collect()
            }
            Some(_) => {
                let (values, failure) = self.probes_on_ranks(&input);
                self.note_failure(failure);
                values
            }
        };
        self.push_probe_sample(values);
    }

    /// Whether a probe samples the step under way (a scene with probes only).
    pub(super) fn probes_due(&self) -> bool {
        !self.params.probes.is_empty() && self.params.probes.samples_step(self.step, self.params.dt, self.params.adaptive.is_some())
    }

    /// Keeps a sample of the probes taken in the step under way.
    fn push_probe_sample(&mut self, values: Vec<f64>) {
        let p = &self.params;
        let (time, previous_time) = match p.adaptive {
            Some(_) => (self.time, if self.step == 0 { 0.0 } else { self.time - self.dt_stats.last }),
            None => (self.step as f64 * p.dt, self.step.saturating_sub(1) as f64 * p.dt),
        };
        self.probe_samples.push(ProbeSample { step: self.step, time, previous_time, values });
    }

    /// The probe samples taken since the last call, in step order.
    pub fn take_probe_samples(&mut self) -> Vec<ProbeSample> {
        std::mem::take(&mut self.probe_samples)
    }

    /// The largest density of the last density stage; non-finite densities are left out, as
    /// on the GPU (the integration counts the particles).
    fn largest_density(&self) -> f64 {
        self.own_slots().into_iter().flat_map(|own| self.densities[own].iter()).map(|d| d.to64()).filter(|d| d.is_finite()).fold(0.0, f64::max)
    }

    /// The bookkeeping after a step of `dt` whose density stage's largest density was
    /// `max_density`.
    fn record_step(&mut self, dt: f64, found: integrate::StepHealth, max_density: f64) {
        self.time += dt;
        self.dt_stats.min = self.dt_stats.min.min(dt);
        self.dt_stats.max = self.dt_stats.max.max(dt);
        self.dt_stats.last = dt;
        let end_time = if self.params.adaptive.is_some() { self.time } else { (self.step + 1) as f64 * self.params.dt };
        integrate::finish_step(&mut self.step, &mut self.health, found, max_density, dt, end_time, self.params.stop_levels());
    }

    /// Runs up to `n` steps, stopping early after a step that went wrong. Across ranks on a
    /// device, the steps may leave the particles on the device, from one call to the next:
    /// what reads the host's arrays takes them back first (`take_back_held`).
    pub fn step(&mut self, n: u64) {
        for _ in 0..n {
            self.step_once();
            if !self.health.is_ok() || self.rank_failure().is_some() {
                break;
            }
        }
    }

    /// A snapshot's fields for the current positions: the binning, then the density (and the
    /// walls' pressure), or for DFSPH its factors stage (density, and the pressure of the last
    /// constant-density solve).
    fn snapshot_fields(&mut self) {
        self.bin();
        match self.dfsph_parts() {
            Some((dfsph, mut parts)) => dfsph.factors_stage(&mut parts),
            None => {
                self.compute_density();
                self.compute_wall_pressure();
            }
        }
    }

    /// The state in the original particle order; density and pressure are evaluated for the
    /// current positions.
    pub fn snapshot(&mut self) -> Snapshot {
        self.snapshot_fields();
        let n = self.positions.len();
        let mut s = Snapshot::with_len(n, self.step, self.time());
        for (slot, &id) in self.ids.iter().enumerate() {
            let id = id as usize;
            s.positions[id] = self.positions[slot].to64();
            s.velocities[id] = self.velocities[slot].to64();
            s.densities[id] = self.densities[slot].to64();
            s.pressures[id] = self.pressures[slot].to64();
        }
        s
    }

    /// Density, pressure and acceleration of the last step, in original order.
    pub fn step_fields(&self) -> StepFields {
        let n = self.positions.len();
        let mut out = StepFields { densities: vec![0.0; n], pressures: vec![0.0; n], accelerations: vec![[0.0; 3]; n] };
        for (slot, &id) in self.ids.iter().enumerate() {
            out.densities[id as usize] = self.densities[slot].to64();
            out.pressures[id as usize] = self.pressures[slot].to64();
            out.accelerations[id as usize] = self.accelerations[slot].to64();
        }
        out
    }

    /// The name of this backend in a saved state: `cpu f32` or `cpu f64`.
    pub fn state_kind() -> String {
        format!("cpu f{}", 8 * std::mem::size_of::<R>())
    }

    /// The kind of state this solver saves and restores: a rank whose stages run on a GPU
    /// saves a GPU's state (its bits are a GPU's), which one GPU or GPU ranks continue.
    fn saved_kind(&self) -> String {
        match self.device {
            Some(_) => "gpu".into(),
            None => Self::state_kind(),
        }
    }

    /// The particles in their current internal order, the step and the health: all the next
    /// step reads (densities, pressures and accelerations are recomputed before use).
    pub fn save_state(&self) -> BackendState {
        BackendState {
            kind: self.saved_kind(),
            step: self.step,
            positions: self.positions.iter().map(|p| p.to64()).collect(),
            velocities: self.velocities.iter().map(|v| v.to64()).collect(),
            ids: self.ids.clone(),
            non_finite: self.health.non_finite,
            escaped: self.health.escaped,
            first_bad_step: self.health.first_bad_step,
            max_density: self.health.max_density,
            max_speed: self.health.max_speed,
            bad_step: self.health.bad_step,
            time: self.time,
            dt_min_max_last: [self.dt_stats.min, self.dt_stats.max, self.dt_stats.last],
            gpu_status: Vec::new(),
            warm_start: match &self.dfsph {
                Some(d) => d.warm_pressure.iter().zip(&d.warm_divergence).map(|(p, v)| [p.to64(), v.to64()]).collect(),
                None => Vec::new(),
            },
            iterations: self.dfsph.as_ref().map(|d| d.stats).unwrap_or_default(),
            densities: self.carried_densities.iter().map(|d| d.to64()).collect(),
        }
    }

    pub fn restore_state(&mut self, state: &BackendState) -> anyhow::Result<()> {
        state.check_fits(&self.saved_kind(), self.positions.len())?;
        self.lists.clear();
        self.positions = state.positions.iter().map(|&p| V3::from64(p)).collect();
        self.velocities = state.velocities.iter().map(|&v| V3::from64(v)).collect();
        self.ids = state.ids.clone();
        anyhow::ensure!(
            state.densities.len() == self.carried_densities.len(),
            "the state holds {} carried densities; the scene's density method needs {}",
            state.densities.len(),
            self.carried_densities.len()
        );
        self.carried_densities = state.densities.iter().map(|&d| R::of(d)).collect();
        self.step = state.step;
        self.probe_samples.clear();
        self.health = state.health();
        self.time = state.time;
        let [min, max, last] = state.dt_min_max_last;
        self.dt_stats = DtStats { min, max, last, ..DtStats::default() };
        if let Some(d) = &mut self.dfsph {
            let n = self.positions.len();
            anyhow::ensure!(state.warm_start.len() == n, "the state holds {} warm-start stiffnesses for DFSPH; the scene has {n} particles", state.warm_start.len());
            d.warm_pressure = state.warm_start.iter().map(|w| R::of(w[0])).collect();
            d.warm_divergence = state.warm_start.iter().map(|w| R::of(w[1])).collect();
            d.stats = state.iterations;
            d.last_dt = if state.step > 0 { last } else { 0.0 };
        }
        Ok(())
    }

    /// The particles in the solver's current (cell) order: positions, velocities and their
    /// original ids.
    pub fn particles(&self) -> (&[V3<R>], &[V3<R>], &[u32]) {
        (&self.positions, &self.velocities, &self.ids)
    }

    /// The sorted wall particles and their cell starts.
    pub fn walls(&self) -> (&[V3<R>], &[R], &[u32]) {
        (&self.wall_positions, &self.wall_masses, &self.wall_starts)
    }
}

impl<R: Real> Backend for CpuSolver<R> {
    fn kind(&self) -> &'static str {
        if self.device.is_some() {
            "gpu"
        } else {
            "cpu"
        }
    }
    fn adapter(&self) -> String {
        if let Some(device) = &self.device {
            return rank_device::lock(device).describe();
        }
        let threads = rayon::current_num_threads();
        let noun = if threads == 1 { "thread" } else { "threads" };
        format!("cpu ({}, {threads} {noun})", std::any::type_name::<R>())
    }
    fn params(&self) -> &Params {
        CpuSolver::params(self)
    }
    fn fluid_count(&self) -> usize {
        self.ranks.as_ref().map_or(self.fluid_len(), |p| p.total_fluid)
    }
    fn wall_count(&self) -> usize {
        // Across ranks, the simulation's: each rank holds only those near its slab.
        self.ranks.as_ref().map_or(self.walls().0.len(), |p| p.total_walls)
    }
    fn step(&mut self, n: u64) -> anyhow::Result<()> {
        CpuSolver::step(self, n);
        match self.rank_failure() {
            Some(e) => anyhow::bail!("{e}"),
            None => Ok(()),
        }
    }
    fn steps_done(&self) -> u64 {
        CpuSolver::steps_done(self)
    }
    fn time(&self) -> f64 {
        CpuSolver::time(self)
    }
    fn dt_stats(&mut self) -> anyhow::Result<DtStats> {
        Ok(CpuSolver::dt_stats(self))
    }
    fn memory_bytes(&self) -> Option<u64> {
        Some(CpuSolver::memory_bytes(self))
    }
    fn health(&mut self) -> anyhow::Result<Health> {
        Ok(CpuSolver::health(self))
    }
    fn snapshot(&mut self) -> anyhow::Result<Snapshot> {
        match self.ranks {
            Some(_) => self.snapshot_across_ranks(),
            None => Ok(CpuSolver::snapshot(self)),
        }
    }
    fn snapshot_piece(&mut self) -> Option<anyhow::Result<crate::solver::backend::SnapshotPiece>> {
        self.ranks.is_some().then(|| self.snapshot_piece_across_ranks())
    }
    fn step_fields(&mut self) -> anyhow::Result<StepFields> {
        match self.ranks {
            Some(_) if self.device.is_some() => anyhow::bail!("the accelerations of a GPU step across ranks are not read back: compare the step's fields on one rank"),
            Some(_) => self.step_fields_across_ranks(),
            None => Ok(CpuSolver::step_fields(self)),
        }
    }
    fn save_state(&mut self) -> anyhow::Result<BackendState> {
        match self.ranks {
            // On rank 0 (a checkpoint streams it instead, below).
            Some(_) => self.save_state_across_ranks(),
            None => Ok(CpuSolver::save_state(self)),
        }
    }
    fn save_state_header(&mut self) -> anyhow::Result<BackendState> {
        match self.ranks {
            Some(_) => Ok(self.state_header_across_ranks()),
            None => Ok(super::backend::state_header(CpuSolver::save_state(self))),
        }
    }
    fn visit_state_array(&mut self, array: StateArray, chunk: u64, visit: &mut dyn FnMut(StatePiece) -> anyhow::Result<()>) -> anyhow::Result<()> {
        match self.ranks {
            Some(_) => self.visit_state_array_across_ranks(array, chunk, visit),
            None => super::backend::visit_state_pieces(&CpuSolver::save_state(self), array, chunk, visit),
        }
    }
    fn restore_state(&mut self, state: &BackendState) -> anyhow::Result<()> {
        match self.ranks {
            Some(_) => self.restore_state_across_ranks(&mut super::backend::WholeState(state)),
            None => CpuSolver::restore_state(self, state),
        }
    }
    fn restore_state_part(&mut self, source: &mut dyn super::backend::StateSource) -> Option<anyhow::Result<()>> {
        self.ranks.is_some().then(|| self.restore_state_across_ranks(source))
    }
    fn take_probe_samples(&mut self) -> anyhow::Result<Vec<ProbeSample>> {
        Ok(CpuSolver::take_probe_samples(self))
    }
    fn rank_report(&self) -> Option<crate::solver::decomposition::RankReport> {
        CpuSolver::rank_report(self)
    }
    fn rank_reports(&mut self) -> anyhow::Result<Option<Vec<crate::solver::decomposition::RankReport>>> {
        self.gather_rank_reports()
    }
    fn any_rank(&mut self, flag: bool) -> anyhow::Result<bool> {
        Ok(self.all_max(&[flag as u8 as f64])[0] > 0.0)
    }

}

/// Values in slot order put back into original order (`ids[slot]` is the original index).
fn unpermute<T: Copy + Default>(ids: &[u32], values: impl Iterator<Item = T>) -> Vec<T> {
    let mut out = vec![T::default(); ids.len()];
    for (slot, v) in values.enumerate() {
        out[ids[slot] as usize] = v;
    }
    out
}
