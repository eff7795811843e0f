//! What a rank's device runs across ranks: the [`DeviceStages`] a GPU rank implements (the
//! step's stages after the host's exchange, and the resident steps that keep the particles on
//! the device), the arrays the host lends them, and the solver's side of a step on a device.
//! See docs/scale-out.md, "The GPU across ranks".

use super::exchange::{GhostLink, Held, InitialSource};
use super::rank_gather::device_probes_across_ranks;
use super::resident_exchange::{OwnHealth, SlabFaces};
use super::CpuSolver;
use crate::model::initial::InitialState;
use crate::model::probes::ProbeGeometry;
use crate::model::real::{Real, V3};
use crate::solver::communicator::Communicator;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

/// The stages of a step that run on a device across ranks: after the host's exchange, the
/// binning, density, forces and integration of the held particles (own and ghosts, in the
/// one-process order), which come back in cell order with the cell starts of that binning and
/// the density stage's densities and pressures. The host keeps the exchange, the health and
/// the bookkeeping, so both paths share them.
pub trait DeviceStages<R: Real>: Send {
    /// The device in words (the summary's adapter).
    fn describe(&self) -> String;
    /// The wall particles near the rank's slab (again whenever its bounds move), in the
    /// order of the whole scene's walls.
    fn set_walls(&mut self, walls: &InitialState);
    /// Runs step `step` on `held` and writes the result back into it; returns the step's dt
    /// (with adaptive dt chosen from every rank's own particles, the ghosts left out).
    fn run_step(&mut self, step: u64, held: HeldArrays<'_, R>) -> anyhow::Result<f64>;
    /// The binning and density stage of `held` at step `step`, without advancing it (for a
    /// snapshot), written back the same way.
    fn run_fields(&mut self, step: u64, held: HeldArrays<'_, R>) -> anyhow::Result<()>;
    /// A device that keeps the held particles after a step (src/solver/cpu/resident_steps.rs):
    /// the band of the state its last step left, for the rank's slab `faces` (`None` where it
    /// keeps none, or the band outgrows its room).
    fn resident_band(&mut self, _faces: &SlabFaces) -> anyhow::Result<Option<ResidentBand<R>>> {
        Ok(None)
    }
    /// Step `step` from the state the device kept, without its `dropped` slots (sorted) and with
    /// the `received` particles (sorted in the one-process order; `ghosts` says which are
    /// ghosts; with DFSPH carrying their warm starts, and `solves` what the host keeps of the
    /// solves); `None`, and nothing changed, where they do not fit the device's arrays.
    fn run_resident_step(&mut self, _step: u64, _dropped: &[u32], _received: &Held<R>, _ghosts: &[bool], _solves: Option<ResidentSolves<'_>>) -> anyhow::Result<Option<ResidentStep>> {
        Ok(None)
    }
    /// The state the device kept, read back into `held` as a step writes it back.
    fn read_held(&mut self, _held: HeldArrays<'_, R>) -> anyhow::Result<()> {
        anyhow::bail!("this device keeps no particles between steps")
    }
    /// The own particles (ghosts left out) per cell layer along `axis` of the state the device
    /// kept (`None` where it keeps none), for a step that may move the slab bounds.
    fn own_layer_counts(&mut self, _axis: usize) -> anyhow::Result<Option<Vec<u32>>> {
        Ok(None)
    }
    /// The walls near the slab replaced by `walls` where they fit the device's buffers, the
    /// state it kept left as it is; false, and nothing changed, where they do not.
    fn replace_walls(&mut self, _walls: &InitialState) -> bool {
        false
    }
    /// The probes' rows the device sampled since the last call (a scene with probes:
    /// `CpuSolver::probes_on_device`), each its step and every column over the held particles,
    /// the ghosts left out of the forces and fronts.
    fn take_probe_rows(&mut self) -> anyhow::Result<Vec<(u64, Vec<f64>)>> {
        Ok(Vec::new())
    }
    /// Bytes of particles that crossed between the host and the device so far, both ways.
    fn bus_bytes(&self) -> u64 {
        0
    }
}

/// The band of a resident step (see [`DeviceStages::resident_band`]): the slots the rank drops
/// (its ghosts and the own particles that left its slab), sorted, and the band's particles (the
/// leaving ones and those next to a face), in the one-process order, with their slots.
pub struct ResidentBand<R: Real> {
    pub dropped: Vec<u32>,
    pub slots: Vec<u32>,
    pub particles: Held<R>,
}

/// DFSPH on a resident step: what the host keeps of the solves (as [`DfsphHeld`]), and the
/// step's link, checked by the host and made by the device from its binning on the slab
/// `faces`.
pub struct ResidentSolves<'a> {
    pub stats: &'a mut crate::model::state::IterationStats,
    pub link: &'a mut GhostLink,
    pub faces: SlabFaces,
    pub particles: usize,
}

/// What a resident step gives back: its dt and the own particles' health.
pub struct ResidentStep {
    pub dt: f64,
    pub health: OwnHealth,
}

/// Shared so that a cloned solver stays cloneable; a rank's solver is never cloned mid-run.
pub type SharedDeviceStages<R> = Arc<Mutex<Box<dyn DeviceStages<R>>>>;

/// The device stages, also after a panic elsewhere poisoned the lock (their state is whole
/// between calls).
pub fn lock<R: Real>(device: &SharedDeviceStages<R>) -> MutexGuard<'_, Box<dyn DeviceStages<R>>> {
    device.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// The particles a rank holds, handed to the device stages (see [`DeviceStages`]).
pub struct HeldArrays<'a, R: Real> {
    pub positions: &'a mut Vec<V3<R>>,
    pub velocities: &'a mut Vec<V3<R>>,
    pub ids: &'a mut Vec<u32>,
    /// Empty without continuity density.
    pub carried_densities: &'a mut Vec<R>,
    pub densities: &'a mut Vec<R>,
    pub pressures: &'a mut Vec<R>,
    /// Cells + 1 values, written by the device.
    pub starts: &'a mut Vec<u32>,
    /// Which of the particles handed over are ghosts (a neighbour's particles), in their order.
    pub ghosts: &'a [bool],
    /// DFSPH: what the host keeps of the solves between steps.
    pub dfsph: Option<DfsphHeld<'a, R>>,
}

/// DFSPH across ranks on a device: what the host keeps of the solves, lent with the held
/// particles.
pub struct DfsphHeld<'a, R: Real> {
    /// The warm-start stiffnesses (constant density, divergence), at `warm_keys[slot]` for each
    /// held slot; given back by the place of each particle in the upload, with `warm_keys` set
    /// to that place.
    pub warm_pressure: &'a mut Vec<R>,
    pub warm_divergence: &'a mut Vec<R>,
    pub warm_keys: &'a mut Vec<u32>,
    /// The solves' iterations so far (a step adds its own).
    pub stats: &'a mut crate::model::state::IterationStats,
    /// The last step's dt (adaptive dt: the divergence solve and the output pressure read it).
    pub last_dt: f64,
    /// The step's ghosts in the solves ([`GhostLink`], in the held order); a step leaves it in
    /// the device's order, with its messages' seconds and failure. `None` for the fields.
    pub link: Option<&'a mut GhostLink>,
    /// The fluid particles of the whole simulation (the solves' average error is over them).
    pub particles: usize,
    /// The rank's slab, whose face layers the link lists.
    pub faces: Option<SlabFaces>,
    /// Given by a step that samples the probes, for the velocities the prediction started from
    /// (after the divergence solve), in the device's order (the force probes' viscous part).
    pub prediction_start: Option<&'a mut Vec<V3<R>>>,
}

impl<R: Real> CpuSolver<R> {
    /// One rank's part on a device: like [`CpuSolver::new_part`], with the step's stages after
    /// the exchange run by `device`.
    pub(crate) fn new_part_on(params: &crate::model::params::Params, initial: InitialSource<'_>, comm: Arc<dyn Communicator>, balance_every: u64, mut device: Box<dyn DeviceStages<R>>) -> anyhow::Result<Self> {
        let (mut solver, part) = Self::new_part_and_walls(params, initial, comm, balance_every)?;
        device.set_walls(&part);
        solver.device = Some(Arc::new(Mutex::new(device)));
        Ok(solver)
    }

    /// The bytes the rank's device moved over the bus (0 without a device).
    pub(super) fn device_bus_bytes(&self) -> u64 {
        self.device.as_ref().map_or(0, |d| lock(d).bus_bytes())
    }

    /// The held arrays, lent to the device stages, with which of them are `ghosts` (and with
    /// DFSPH, the step's ghost link, and the room for the velocities the prediction started
    /// from where the step samples probes).
    pub(super) fn held_arrays<'a>(&'a mut self, ghosts: &'a [bool], with_link: bool, prediction_start: bool) -> HeldArrays<'a, R> {
        let particles = self.ranks.as_ref().map_or(self.positions.len(), |part| part.total_fluid);
        let faces = self.ranks.as_deref().map(|part| part.faces());
        let link = match with_link {
            true => self.ranks.as_deref_mut().and_then(|part| part.link.as_mut()),
            false => None,
        };
        HeldArrays {
            ghosts,
            dfsph: self.dfsph.as_mut().map(|d| DfsphHeld {
                warm_pressure: &mut d.warm_pressure,
                warm_divergence: &mut d.warm_divergence,
                warm_keys: &mut self.warm_keys,
                stats: &mut d.stats,
                last_dt: d.last_dt,
                link,
                particles,
                faces,
                prediction_start: if prediction_start { Some(&mut self.scratch_v3) } else { None },
            }),
            positions: &mut self.positions,
            velocities: &mut self.velocities,
            ids: &mut self.ids,
            carried_densities: &mut self.carried_densities,
            densities: &mut self.densities,
            pressures: &mut self.pressures,
            starts: &mut self.starts,
        }
    }

    /// The device's binning and density of the held particles (a snapshot's fields).
    pub(super) fn fields_on_device(&mut self) {
        self.lists.clear();
        let step = self.step;
        let ghosts = self.ghost_flags();
        let ran = self.on_device(|s, device| device.run_fields(step, s.held_arrays(&ghosts, false, false)));
        if let Err(e) = ran {
            if let Some(part) = &mut self.ranks {
                part.failure.get_or_insert(format!("rank {} of {}: the device's density stage failed: {e:#}", part.comm.rank(), part.comm.size()));
            }
        }
    }

    /// A step whose stages after the exchange run on the device; the health is taken from the
    /// own particles the device gave back, and reduced over the ranks as on the host. True
    /// where the device ran it (and keeps what it gave back).
    pub(super) fn step_on_device(&mut self) -> bool {
        // Probes are sampled on the host from the state the step starts from: the device bins it
        // and evaluates its density stage (as for a snapshot), and the CPU path's probe stage
        // reads the result with its own particles counted (probes_across_ranks). A device that
        // failed here has recorded its rank's failure; the collectives below still run, so no
        // rank waits for it, and the step's health stops every rank.
        // With DFSPH, as on the CPU path, the point probes (and the rest, to be sampled again) now,
        // the force and front probes after the solves, on the step's first positions.
        let dfsph = self.dfsph.is_some();
        let mut dfsph_points = None;
        let sampling = self.probes_due();
        let on_device = self.probes_on_device();
        if sampling && !on_device {
            self.fields_on_device();
            self.compute_wall_pressure();
            match dfsph {
                true => dfsph_points = Some(self.sample_probe_points()),
                false => self.sample_probes(),
            }
        }
        // The binned state's positions: the step bins them again in the same order (its binning
        // is stable and they are sorted), so its slots are these.
        let first_positions = dfsph_points.is_some().then(|| self.positions.clone());
        self.lists.clear();
        let step = self.step;
        let ghosts = self.ghost_flags();
        // DFSPH: the ghosts' part in the solves, in the held order (the device follows its own
        // binning with it).
        if dfsph {
            self.link_ghosts();
        }
        let ran = self.on_device(|s, device| device.run_step(step, s.held_arrays(&ghosts, dfsph, first_positions.is_some())));
        self.unlink_ghosts();
        let dt = match ran {
            Ok(dt) => dt,
            Err(e) => {
                if let Some(part) = &mut self.ranks {
                    part.failure.get_or_insert(format!("rank {} of {}: the device step failed: {e:#}", part.comm.rank(), part.comm.size()));
                }
                return false;
            }
        };

        if let Some(d) = &mut self.dfsph {
            d.last_dt = dt;
            d.dt = dt;
        }
        if let (Some(values), Some(mut positions)) = (dfsph_points, first_positions) {
            self.sample_dfsph_forces_on_device(values, dt, &mut positions);
        }
        if sampling && on_device {
            self.sample_probes_from_device();
        } else if sampling {
            // The host sampled them: the device's own rows are not used (read, so that its row
            // buffer never fills).
            let _ = self.on_device(|_, device| device.take_probe_rows());
        }
        let n = self.positions.len();
        self.accelerations.resize(n, V3::zero());
        let domain = (V3::<R>::from64(self.params.domain_min), V3::<R>::from64(self.params.domain_max));
        let mut found = super::integrate::StepHealth::default();
        for own in self.own_slots() {
            for i in own {
                let (x, v) = (self.positions[i], self.velocities[i]);
                let finite = x.is_finite() && v.is_finite();
                let inside = (0..3).all(|k| x.0[k] >= domain.0 .0[k] && x.0[k] <= domain.1 .0[k]);
                let speed = if finite { v.length().to64() } else { 0.0 };
                found = found.add(super::integrate::StepHealth { non_finite: (!finite) as u32, escaped: (finite && !inside) as u32, max_speed: speed });
            }
        }
        let max_density = self.largest_density();
        let (found, max_density) = self.all_step_health(found, max_density);
        self.health.max_density = self.health.max_density.max(max_density);
        self.record_step(dt, found, max_density);
        true
    }

    /// DFSPH on device ranks, after a step that samples the probes: the force and front probes
    /// from the step's first `positions` (the binned state's, in the same slots), the solves'
    /// stiffness sums (which the device gave back as the warm starts) and the velocities the
    /// prediction started from (given back for this step).
    fn sample_dfsph_forces_on_device(&mut self, values: Vec<f64>, dt: f64, positions: &mut Vec<V3<R>>) {
        let n = self.positions.len();
        let Some(d) = self.dfsph.as_mut() else { return };
        if positions.len() != n || self.scratch_v3.len() != n {
            // Only where the device gave back less than it was asked for (its failure stops the
            // run): the probes' collectives still run, so that no rank waits.
            self.scratch_v3.resize(n, V3::zero());
            positions.resize(n, V3::zero());
        }
        let key = |slot: usize| self.warm_keys.get(slot).map_or(slot, |&k| k as usize);
        d.pressure_sum = (0..n).map(|slot| d.warm_pressure.get(key(slot)).copied().unwrap_or(R::zero())).collect();
        d.divergence_sum = (0..n).map(|slot| d.warm_divergence.get(key(slot)).copied().unwrap_or(R::zero())).collect();
        std::mem::swap(&mut self.positions, positions);
        self.sample_dfsph_forces(values, dt);
        std::mem::swap(&mut self.positions, positions);
    }

    /// Whether each rank's device samples the probes (across ranks on devices): wgsl/sim/
    /// probes.wgsl runs on the held particles within the step, as on one device (with DFSPH the
    /// points after the factors, the rest after the solves), and the host adds the ranks' rows
    /// ([`device_probes_across_ranks`]), so a step that samples probes needs no particle on
    /// the host and may stay resident. A scene with a gauge whose vertical line crosses the
    /// slabs (cut along y) is sampled on the host instead, level by level.
    pub(super) fn probes_on_device(&self) -> bool {
        let Some(part) = self.ranks.as_deref() else { return false };
        let gauge = || self.params.probes.probes.iter().any(|p| matches!(p.geometry, ProbeGeometry::Gauge { .. }));
        self.device.is_some() && !self.params.probes.is_empty() && !(part.axis == 1 && gauge())
    }

    /// After a device step that sampled the probes ([`Self::probes_on_device`]): the device's
    /// row of this step, added over the ranks. A rank whose device gave no row still takes
    /// part in the collectives (with zeros and a flag that it failed), so no rank waits; every
    /// rank then leaves the step's sample out and stops, the failed one with its error.
    pub(super) fn sample_probes_from_device(&mut self) {
        let (step, count) = (self.step, self.params.probes.value_count());
        let rows = self.on_device(|_, device| device.take_probe_rows());
        let (device, mut failure) = match rows.map(|rows| rows.into_iter().find(|r| r.0 == step)) {
            Ok(Some((_, values))) if values.len() == count => (values, None),
            Ok(_) => (vec![0.0; count], Some(format!("the device sampled no probe row of step {step}"))),
            Err(e) => (vec![0.0; count], Some(format!("reading the device's probe rows failed: {e:#}"))),
        };
        let part = self.ranks.as_deref().expect("across ranks");
        if let Some(e) = failure.as_mut() {
            *e = format!("rank {} of {}: {e}", part.comm.rank(), part.comm.size());
        }
        let grid = self.grid;
        let evaluates = |x: [f64; 3]| part.slabs.owner(grid.layer(V3::<R>::from64(x), part.axis)) == part.comm.rank();
        let p = &self.params.probes;
        let t0 = Instant::now();
        let (values, reduced) = device_probes_across_ranks(&*part.comm, &p.probes, &p.offsets(), device, failure.is_some(), evaluates);
        if let Some(part) = self.ranks.as_deref_mut() {
            part.stats.exchange_seconds += t0.elapsed().as_secs_f64();
        }
        match failure.or(reduced) {
            Some(e) => self.note_failure(Some(e)),
            None => self.push_probe_sample(values),
        }
    }

    /// A call to the rank's device (`call` with this solver and the locked device), counted in
    /// the rank's device time less what the DFSPH solves inside it spent exchanging across ranks
    /// (that goes to the exchange time when the link is undone).
    pub(super) fn on_device<T>(&mut self, call: impl FnOnce(&mut Self, &mut dyn DeviceStages<R>) -> T) -> T {
        let device = self.device.clone().expect("only with device stages");
        let (started, linked) = (Instant::now(), self.link_seconds());
        let out = call(self, &mut **lock(&device));
        let exchanged = self.link_seconds() - linked;
        if let Some(part) = self.ranks.as_deref_mut() {
            part.stats.device_seconds += (started.elapsed().as_secs_f64() - exchanged).max(0.0);
        }
        out
    }

    fn link_seconds(&self) -> f64 {
        self.ranks.as_deref().and_then(|p| p.link.as_ref()).map_or(0.0, |link| link.seconds)
    }
}
