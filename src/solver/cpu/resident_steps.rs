//! Steps across ranks whose device keeps the rank's particles from one step to the next
//! (docs/scale-out.md, "The GPU across ranks"). The full path reads every held particle back
//! after a step and uploads them all before the next; a resident step reads back only the band
//! the exchange touches (the particles that left the slab, and those in the layers next to a
//! face that the neighbours take as ghosts), runs the same exchange on it (the same messages
//! and collectives as the full path, so each rank may take either), and has the device merge
//! what the neighbours sent into the particles it kept, in the one-process order: the step's
//! stable binning then sees what the full path gives it, and computes the same bits.
//!
//! A step takes the full path where the host needs the particles: the first step, the first
//! after the host read them for an output (a snapshot, a checkpoint), a step whose probes the
//! host samples, a step whose moved bounds bring walls the device has no room for, or a band
//! or merge that outgrows the device's room. A step that may move the bounds counts the own
//! particles per layer on the device (`balance_on_device`). With DFSPH the warm starts travel
//! with the band and the received particles, the host checks the step's ghosts by their ids as
//! the full path does, and the device makes the solves' ghost link from its own binning. The
//! particles stay on the device from one batch of steps to the
//! next (a health check needs only the counts the steps gather); whatever reads the host's
//! arrays takes them back first (`CpuSolver::take_back_held`), so nothing sees them stale.

use super::exchange::{check_link_ids, Carried, GhostLink, Held};
use super::rank_device::{ResidentBand, ResidentSolves, ResidentStep};
use super::resident_exchange::SlabFaces;
use super::CpuSolver;
use crate::model::real::{Real, V3};
use std::time::Instant;

/// Whether the device holds what the host holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DeviceHeld {
    /// Nothing the next step may start from (outside a batch, or before its first step).
    #[default]
    Nothing,
    /// The state the last step left, which the host's arrays hold too.
    Same,
    /// The state the last step left, which the host's arrays lag behind: `own` of its particles
    /// are this rank's (the rest are ghosts), which the host's stale cell starts cannot count.
    Ahead { own: usize },
}

/// How a resident step's move of the slab bounds went.
enum Balanced {
    /// Balanced; the step goes on from the device.
    Resident,
    /// The step takes the full path (which balances where this did not).
    FullPath,
    /// A collective failed: the step stops.
    Failed,
}

impl<R: Real> CpuSolver<R> {
    /// Runs this step from the state the device kept, where it can; false where the step takes
    /// the full path (nothing done, or, where the merge did not fit the device, the exchange
    /// done and the full path's arrays made on the host).
    pub(super) fn step_resident(&mut self) -> bool {
        if self.device.is_none() || self.device_held == DeviceHeld::Nothing {
            return false;
        }
        let Some(part) = self.ranks.as_deref() else { return false };
        let balance = part.balance_due(self.step);
        // Probes sampled on the host need its particles; the device's own samples do not.
        let sampling = self.probes_due();
        let probes_on_device = self.probes_on_device();
        if part.first_order.is_some() || (sampling && !probes_on_device) {
            return false;
        }
        // This rank's own particles before the exchange, counted by the slab they were held for.
        let own = self.own_count();
        // The bounds' move first, as the full path's exchange makes it.
        match balance.then(|| self.balance_on_device()) {
            Some(Balanced::FullPath) => return false,
            Some(Balanced::Failed) => return true,
            Some(Balanced::Resident) | None => {}
        }
        let Some(part) = self.ranks.as_deref() else { return false };
        let (rank, size) = (part.comm.rank(), part.comm.size());
        let faces = part.faces();
        let particles = part.total_fluid;
        let mut band = match self.on_device(|_, device| device.resident_band(&faces)) {
            Ok(Some(band)) => band,
            Ok(None) => return false,
            Err(e) => {
                // The full path still runs the step's collectives, so no rank waits.
                self.note_failure(Some(format!("rank {rank} of {size}: reading the band back failed: {e:#}")));
                return false;
            }
        };
        let t0 = Instant::now();
        let exchanged = self.exchange_band(&faces, &mut band);
        if let Some(part) = self.ranks.as_deref_mut() {
            part.stats.exchange_seconds += t0.elapsed().as_secs_f64();
        }
        let (received, ghosts, (left, arrived)) = match exchanged {
            Ok(done) => done,
            Err(e) => {
                // A failed collective stops every rank after this step.
                self.note_failure(Some(format!("{e:#}")));
                return true;
            }
        };
        self.lists.clear();
        let ran = self.on_device(|s, device| {
            let solves = match (s.dfsph.as_mut(), s.ranks.as_deref_mut()) {
                (Some(d), Some(part)) => Some(ResidentSolves { stats: &mut d.stats, link: part.link.as_mut().expect("made by the exchange"), faces: faces.clone(), particles }),
                _ => None,
            };
            device.run_resident_step(s.step, &band.dropped, &received, &ghosts, solves)
        });
        if self.dfsph.is_some() {
            if let Ok(Some(done)) = &ran {
                let d = self.dfsph.as_mut().expect("DFSPH");
                (d.last_dt, d.dt) = (done.dt, done.dt);
            }
            // Where the merge did not fit, the full path below takes the link, checked already.
            if !matches!(ran, Ok(None)) {
                self.unlink_ghosts();
            }
        }
        match ran {
            Ok(Some(done)) => {
                if let Some(part) = self.ranks.as_deref_mut() {
                    part.stats.ghosts = ghosts.iter().filter(|&&g| g).count();
                    part.stats.resident_steps += 1;
                }
                self.device_held = DeviceHeld::Ahead { own: own + arrived - left };
                if sampling {
                    self.sample_probes_from_device();
                }
                self.record_resident_step(&done);
            }
            Ok(None) => {
                // The merge does not fit the device's room: the host makes the held arrays from
                // the state the device kept and the particles received, and the full path runs.
                if let Err(e) = self.merge_on_host(&band, received, &ghosts) {
                    self.note_failure(Some(format!("rank {rank} of {size}: {e:#}")));
                }
                if self.step_on_device() {
                    self.device_held = DeviceHeld::Same;
                }
            }
            Err(e) => {
                self.note_failure(Some(format!("rank {rank} of {size}: the device step failed: {e:#}")));
            }
        }
        true
    }

    /// A step that may move the slab bounds, balanced from the own particles the device counted
    /// per cell layer (none read back), with the full path's collective and rule
    /// ([`super::exchange::RankPart::balance`]). Where the bounds move, the walls near the new
    /// slab replace the old on the device, in its buffers where they fit; where they do not, the
    /// particles are read back first and the step takes the full path (which balances no more).
    fn balance_on_device(&mut self) -> Balanced {
        let part = self.ranks.as_deref().expect("across ranks");
        let (rank, size, axis) = (part.comm.rank(), part.comm.size(), part.axis);
        let counts = match self.on_device(|_, device| device.own_layer_counts(axis)) {
            Ok(Some(counts)) => counts,
            // The full path counts them on the host.
            Ok(None) => return Balanced::FullPath,
            Err(e) => {
                self.note_failure(Some(format!("rank {rank} of {size}: counting the particles per layer failed: {e:#}")));
                return Balanced::FullPath;
            }
        };
        let t0 = Instant::now();
        let step = self.step;
        let part = self.ranks.as_deref_mut().expect("across ranks");
        let layers: Vec<f64> = counts.iter().map(|&c| c as f64).collect();
        let moved = part.balance(&layers);
        part.balanced_step = Some(step);
        part.stats.exchange_seconds += t0.elapsed().as_secs_f64();
        match moved {
            Ok(false) => Balanced::Resident,
            Ok(true) => {
                let walls = self.walls_near_slab();
                if self.on_device(|_, device| device.replace_walls(&walls)) {
                    self.install_walls_on_host(&walls);
                    Balanced::Resident
                } else {
                    // The device makes its buffers again for these walls: its particles first.
                    self.take_back_held();
                    self.install_walls(&walls);
                    Balanced::FullPath
                }
            }
            Err(e) => {
                // A failed collective stops every rank after this step.
                self.note_failure(Some(format!("{e:#}")));
                Balanced::Failed
            }
        }
    }

    /// The exchange of the full path (migration, then ghosts) on the band, whose particles it
    /// takes: the particles the neighbours sent, sorted in the one-process order, and which of
    /// them are ghosts. With DFSPH the step's link too, checked by the ids as the full path
    /// checks it (its lists are the device's to make). Last, how many own particles left the
    /// slab and how many arrived.
    fn exchange_band(&mut self, faces: &SlabFaces, band: &mut ResidentBand<R>) -> anyhow::Result<(Held<R>, Vec<bool>, (usize, usize))> {
        let carried = Carried { density: self.params.continuity_density, warm: self.dfsph.is_some() };
        let grid = self.grid;
        let part = self.ranks.as_deref_mut().expect("across ranks");
        let comm = part.comm.clone();
        let rank = comm.rank();
        let layer_of = |p: V3<R>| grid.layer(p, faces.axis);
        // The band's particles that left are the dropped slots that are not ghosts: the host
        // and the device must agree on them, or a particle would be lost or held twice. Both
        // lists are sorted by slot, so one walk through the dropped slots answers for the band.
        let mut dropped = band.dropped.iter().copied().peekable();
        let mut left = 0;
        for (k, &slot) in band.slots.iter().enumerate() {
            let leaves = part.slabs.owner(layer_of(band.particles.x[k])) != rank;
            left += leaves as usize;
            while dropped.next_if(|&d| d < slot).is_some() {}
            anyhow::ensure!(leaves == (dropped.peek() == Some(&slot)), "rank {rank}: the device and the host disagree on whether the particle in slot {slot} leaves the slab");
        }
        // Migration, as the full path's.
        let (held, arrived) = part.migrate(std::mem::take(&mut band.particles), &grid, carried)?;
        // Ghosts, as the full path's, in the one-process order.
        let mut order: Vec<usize> = (0..held.len()).collect();
        order.sort_unstable_by_key(|&i| held.order[i]);
        let (from_lower, from_upper, sent) = part.exchange_ghosts(&held, order.iter().copied(), &grid, carried)?;
        // What the device does not hold: the migrants that arrived, and the ghosts.
        let arrived: Vec<usize> = order.iter().copied().filter(|&i| arrived[i]).collect();
        let mut received = held.picked(&arrived);
        let migrants = received.len();
        received.decode(&from_lower, carried)?;
        let from_lower_end = received.len();
        received.decode(&from_upper, carried)?;
        if carried.warm {
            // The full path's check of the link (link_ghosts), one message per neighbour, so that
            // every rank exchanges as many messages whichever path it takes: the ids of the
            // particles this rank sent as ghosts, against those of the ghosts it received.
            let ids = |slots: &mut dyn Iterator<Item = usize>, from: &Held<R>| slots.map(|i| from.id[i]).collect::<Vec<u32>>();
            let sent = sent.map(|side| ids(&mut side.into_iter(), &held));
            let ghosts = [ids(&mut (migrants..from_lower_end), &received), ids(&mut (from_lower_end..received.len()), &received)];
            let sizes = [sent[0].len(), sent[1].len(), ghosts[0].len(), ghosts[1].len()];
            let failure = check_link_ids(&*comm, sent, ghosts).err();
            part.link = Some(GhostLink::unmade(comm.clone(), sizes, failure));
        }
        // The migrants and each neighbour's ghosts are each in the one-process order already: a
        // stable sort merges such runs in about one pass.
        let mut sorted: Vec<usize> = (0..received.len()).collect();
        sorted.sort_by_key(|&i| received.order[i]);
        let ghosts = sorted.iter().map(|&i| i >= migrants).collect();
        Ok((received.picked(&sorted), ghosts, (left, migrants)))
    }

    /// The bookkeeping of a resident step: the own particles' health the device counted, over
    /// every rank, as after a full step.
    fn record_resident_step(&mut self, done: &ResidentStep) {
        let h = done.health;
        let found = super::integrate::StepHealth { non_finite: h.non_finite, escaped: h.escaped, max_speed: h.max_speed2.sqrt() as f64 };
        let (found, max_density) = self.all_step_health(found, h.max_density as f64);
        self.health.max_density = self.health.max_density.max(max_density);
        self.record_step(done.dt, found, max_density);
    }

    /// Where the merge does not fit the device: the held arrays made on the host from the
    /// state the device kept (read back) less the `band`'s dropped slots, and the `received`
    /// particles, in the one-process order, for the full path's upload.
    fn merge_on_host(&mut self, band: &ResidentBand<R>, received: Held<R>, ghosts: &[bool]) -> anyhow::Result<()> {
        self.on_device(|s, device| device.read_held(s.held_arrays(&[], false, false)))?;
        let mut all = Held::default();
        for cell in 0..self.starts.len() - 1 {
            for slot in self.starts[cell]..self.starts[cell + 1] {
                if band.dropped.binary_search(&slot).is_err() {
                    let i = slot as usize;
                    all.x.push(self.positions[i]);
                    all.v.push(self.velocities[i]);
                    all.id.push(self.ids[i]);
                    if !self.carried_densities.is_empty() {
                        all.rho.push(self.carried_densities[i]);
                    }
                    if let Some(d) = &self.dfsph {
                        // The warm starts were given back by place in the upload.
                        let k = self.warm_keys[i] as usize;
                        all.warm.push([d.warm_pressure[k], d.warm_divergence[k]]);
                    }
                    all.order.push((cell as u64) << 32 | (slot - self.starts[cell]) as u64);
                }
            }
        }
        for i in 0..received.len() {
            all.push_from(&received, i);
        }
        if let Some(part) = self.ranks.as_deref_mut() {
            part.stats.ghosts = ghosts.iter().filter(|&&g| g).count();
        }
        self.install_held(all.sorted());
        self.device_held = DeviceHeld::Nothing;
        Ok(())
    }

    /// The host's arrays read back from the device where they lag behind it.
    pub(super) fn sync_held(&mut self) {
        if !matches!(self.device_held, DeviceHeld::Ahead { .. }) {
            return;
        }
        if self.device.is_none() {
            return;
        }
        let read = self.on_device(|s, device| device.read_held(s.held_arrays(&[], false, false)));
        self.size_held_arrays();
        self.device_held = DeviceHeld::Same;
        if let Err(e) = read {
            if let Some(part) = self.ranks.as_deref() {
                let e = format!("rank {} of {}: reading the particles back failed: {e:#}", part.comm.rank(), part.comm.size());
                self.note_failure(Some(e));
            }
        }
    }

    /// The host takes the particles back to read or change them (a snapshot, a checkpoint, a
    /// restore): read back where the device is ahead, and the next step uploads them again
    /// (the host's exchange for an output moves ghosts and migrants the device does not see).
    pub(super) fn take_back_held(&mut self) {
        self.sync_held();
        self.device_held = DeviceHeld::Nothing;
    }

    /// The host's arrays replaced (a restore): the next step uploads them, whatever the device
    /// holds.
    pub(super) fn forget_device_state(&mut self) {
        self.device_held = DeviceHeld::Nothing;
    }

    /// This rank's own particles (the held less the ghosts), wherever they are.
    pub(super) fn own_count(&self) -> usize {
        match self.device_held {
            DeviceHeld::Ahead { own } => own,
            _ => self.own_slots().iter().map(|r| r.len()).sum(),
        }
    }
}
