//! Threads per workgroup of each particle stage: a pipeline-overridable constant
//! (`WORKGROUP_SIZE` in wgsl/shared/common.wgsl), so that each stage can be tuned to an adapter
//! without touching the shaders (`wgsph profile --workgroup-size`), and the other choices of the GPU step that change no value.

use super::device::{GpuContext, GpuError};
use std::fmt;
use std::str::FromStr;

/// The stages whose workgroup size can be chosen, as named on the command line.
pub const TUNABLE_STAGES: [&str; 6] = ["bin_count", "bin_scatter", "reorder", "density", "forces", "integrate"];

/// Threads per workgroup of each particle stage. `forces` also sizes the fused forces and
/// integration, and `integrate` the adaptive dt's reduction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WorkgroupSizes {
    pub bin_count: u32,
    pub bin_scatter: u32,
    pub reorder: u32,
    pub density: u32,
    pub forces: u32,
    pub integrate: u32,
}

impl Default for WorkgroupSizes {
    fn default() -> Self {
        WorkgroupSizes::all(super::shaders::WORKGROUP_SIZE)
    }
}

/// Smallest and largest workgroup size accepted before the adapter's own limits are checked.
const SMALLEST: u32 = 1;
const LARGEST: u32 = 1024;

impl WorkgroupSizes {
    /// The same size for every stage.
    pub fn all(size: u32) -> Self {
        WorkgroupSizes { bin_count: size, bin_scatter: size, reorder: size, density: size, forces: size, integrate: size }
    }

    fn slot(&mut self, stage: &str) -> Option<&mut u32> {
        Some(match stage {
            "bin_count" => &mut self.bin_count,
            "bin_scatter" => &mut self.bin_scatter,
            "reorder" => &mut self.reorder,
            "density" => &mut self.density,
            "forces" => &mut self.forces,
            "integrate" => &mut self.integrate,
            _ => return None,
        })
    }

    fn values(&self) -> [(&'static str, u32); 6] {
        [
            ("bin_count", self.bin_count),
            ("bin_scatter", self.bin_scatter),
            ("reorder", self.reorder),
            ("density", self.density),
            ("forces", self.forces),
            ("integrate", self.integrate),
        ]
    }

    /// Fails, naming the adapter, the stage, its size and the limit, when a size exceeds what the
    /// adapter allows (`max_compute_workgroup_size_x`, `max_compute_invocations_per_workgroup`).
    pub fn check(&self, ctx: &GpuContext) -> Result<(), GpuError> {
        let l = ctx.device.limits();
        let (limit, have) = if l.max_compute_workgroup_size_x <= l.max_compute_invocations_per_workgroup {
            ("max_compute_workgroup_size_x", l.max_compute_workgroup_size_x)
        } else {
            ("max_compute_invocations_per_workgroup", l.max_compute_invocations_per_workgroup)
        };
        match self.values().into_iter().find(|&(_, size)| size > have) {
            Some((stage, size)) => Err(GpuError::Limit {
                adapter: ctx.info.name.clone(),
                backend: format!("{:?}", ctx.info.backend),
                what: format!("the workgroup size of stage '{stage}'"),
                limit,
                need: size as u64,
                have: have as u64,
            }),
            None => Ok(()),
        }
    }
}

impl fmt::Display for WorkgroupSizes {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        let parts: Vec<String> = self.values().iter().map(|(s, n)| format!("{s}={n}")).collect();
        write!(f, "{}", parts.join(","))
    }
}

/// A size for every stage (`64`), or sizes of some stages (`density=64,forces=256`; the others
/// keep the default).
impl FromStr for WorkgroupSizes {
    type Err = String;
    fn from_str(text: &str) -> Result<Self, String> {
        let size = |value: &str, what: &str| -> Result<u32, String> {
            match value.trim().parse::<u32>() {
                Ok(n) if (SMALLEST..=LARGEST).contains(&n) => Ok(n),
                _ => Err(format!("{what} '{}' is not a workgroup size; allowed: a whole number of threads from {SMALLEST} to {LARGEST}", value.trim())),
            }
        };
        if !text.contains('=') {
            return Ok(WorkgroupSizes::all(size(text, "the size")?));
        }
        let mut out = WorkgroupSizes::default();
        let mut seen: Vec<&str> = Vec::new();
        for part in text.split(',') {
            let (stage, value) = part.split_once('=').ok_or_else(|| format!("'{part}' is not STAGE=SIZE"))?;
            let stage = stage.trim();
            if seen.contains(&stage) {
                return Err(format!("stage '{stage}' is given twice; give each stage one size"));
            }
            seen.push(stage);
            let n = size(value, &format!("the size of stage '{stage}'"))?;
            *out.slot(stage).ok_or_else(|| format!("'{stage}' is not a stage with a workgroup size; allowed: {}", TUNABLE_STAGES.join(", ")))? = n;
        }
        Ok(out)
    }
}

/// How the GPU ends the loop of a DFSPH solve (the same iterations, so the same values, either
/// way). In every mode a one-thread check after each iteration decides on the GPU whether the
/// solve goes on and sizes the next iteration's dispatches (indirect): the full size, or zero
/// workgroups once it has ended, so that iterations recorded past the end are empty. The modes
/// differ in how many iterations the host records before it asks whether the solve has ended.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SolverLoop {
    /// Every iteration up to the limit is recorded with the step: no host round trip, but up
    /// to `max_iterations` empty iterations per solve.
    Indirect,
    /// The host reads the solve's state back after every block of this many iterations and
    /// records another block while it goes on (a host round trip per block).
    Readback(u32),
    /// As `Readback`, with a first block as long as the same solve needed in the last step
    /// (plus one) and blocks of [`ADAPTIVE_BLOCK`] after it: usually one round trip per solve
    /// and few empty iterations. Measured fastest (docs/dfsph.md).
    #[default]
    Adaptive,
}

/// The blocks of [`SolverLoop::Adaptive`] after its first.
pub const ADAPTIVE_BLOCK: u32 = 4;

impl fmt::Display for SolverLoop {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        match self {
            SolverLoop::Indirect => write!(f, "indirect"),
            SolverLoop::Readback(k) => write!(f, "readback:{k}"),
            SolverLoop::Adaptive => write!(f, "adaptive"),
        }
    }
}

/// `adaptive`, `indirect` or `readback:K` (K iterations per round trip, K >= 1).
impl FromStr for SolverLoop {
    type Err = String;
    fn from_str(text: &str) -> Result<Self, String> {
        let allowed = "allowed: adaptive, indirect, or readback:K with K iterations per host round trip (K from 1 to 1000)";
        match text.trim() {
            "indirect" => Ok(SolverLoop::Indirect),
            "adaptive" => Ok(SolverLoop::Adaptive),
            other => match other.strip_prefix("readback:").map(|k| k.trim().parse::<u32>()) {
                Some(Ok(k)) if (1..=1000).contains(&k) => Ok(SolverLoop::Readback(k)),
                _ => Err(format!("'{other}' is not a solver loop; {allowed}")),
            },
        }
    }
}

/// Choices of the GPU step that do not change its results (but for the neighbour skin's, which
/// changes the order the particles are held in, and with it the rounding of their sums).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GpuOptions {
    /// Fuse the forces and the integration into one pass when dt is fixed: the same values and
    /// one pass over the state less, but the state then needs two copies (64 bytes per fluid
    /// particle) instead of three buffers used in place (48). `None` (the default) and `false`
    /// run two passes in place.
    pub fuse_forces_and_integration: Option<bool>,
    /// Threads per workgroup of each particle stage.
    pub workgroup_sizes: WorkgroupSizes,
    /// Steps recorded into one command buffer (0: the default, 32).
    pub steps_per_submit: u64,
    /// Visit the neighbour stencil as 27 single cells instead of 9 runs of 3 (to measure what
    /// the runs gain; the same values).
    pub single_cells: bool,
    /// How a DFSPH solve's loop ends on the GPU.
    pub solver_loop: SolverLoop,
    /// Walk the neighbour stencils of a subgroup together in the density (summation or
    /// continuity), the two-pass forces and DFSPH's solve iterations (wgsl/shared/tiles.wgsl;
    /// the same values): `None` (the default) where the device
    /// can, `Some(true)` or an error where it cannot, `Some(false)` never.
    pub subgroup_tiles: Option<bool>,
    /// With subgroup tiles, the weakly compressible step's density stage (summation or
    /// continuity) records each particle's neighbours and the forces walk those lists, and
    /// DFSPH records them after its factors for every solve pass of the step
    /// (wgsl/shared/neighbour_lists.wgsl; the same values, 4 bytes per slot of each fluid
    /// particle's list): `None` or `Some(true)` (the default) wherever the tiles run, on one
    /// device, with the forces in a pass of their own, `Some(false)` never.
    pub neighbour_lists: Option<bool>,
    /// The slots of each list (each slot one chunk of eight candidates that holds a
    /// neighbour); `None`: 0.75 times a particle's neighbours at rest density, in whole rows of
    /// eight. A particle whose list overflows has its subgroup walk the tiles (the same values),
    /// so the capacity changes only the speed (kept within 1 to 65,535).
    pub neighbour_list_capacity: Option<u32>,
    /// A neighbour skin, as a fraction of h (wgsl/sim/neighbour_skin.wgsl): the grid's cells
    /// h (1 + skin) wide, the lists holding the candidates within h (1 + skin), and both
    /// rebuilt, with the particles' order, only once a particle has moved skin h since the last
    /// rebuild or two may have closed in by that much (wgsl/sim/neighbour_skin.wgsl); in
    /// between the density walks the lists. The same neighbours, each summed
    /// in the order of its particle's walk, but with the particles in the order of the last
    /// rebuild, so not the bits of a run without. `None` (the default): rebuilt every step.
    /// Weakly compressible scenes (summation or continuity density), on one device. Each step
    /// is then submitted alone, whatever `steps_per_submit` says: the host reads whether the
    /// next one rebuilds.
    pub neighbour_skin: Option<f64>,
    /// Across ranks, every step on the full path: every held particle read back after the step
    /// and uploaded again before the next, as the first step and a balance step take it.
    /// `false` (the default): the particles stay on the device from one step to the next, and
    /// only the band next to the slab's faces crosses the bus (src/solver/cpu/resident_steps.rs;
    /// the same values). For comparing the two; one device has nothing to exchange.
    pub full_exchange: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solver_loops_parse() {
        assert_eq!("indirect".parse::<SolverLoop>().unwrap(), SolverLoop::Indirect);
        assert_eq!("adaptive".parse::<SolverLoop>().unwrap(), SolverLoop::Adaptive);
        assert_eq!(SolverLoop::Adaptive.to_string().parse::<SolverLoop>().unwrap(), SolverLoop::Adaptive);
        assert_eq!("readback:4".parse::<SolverLoop>().unwrap(), SolverLoop::Readback(4));
        assert_eq!(SolverLoop::Readback(4).to_string().parse::<SolverLoop>().unwrap(), SolverLoop::Readback(4));
        for bad in ["readback", "readback:0", "readback:x", "loop"] {
            assert!(bad.parse::<SolverLoop>().unwrap_err().contains("indirect"), "{bad}");
        }
    }

    #[test]
    fn sizes_parse_for_all_stages_or_some() {
        assert_eq!("64".parse::<WorkgroupSizes>().unwrap(), WorkgroupSizes::all(64));
        let s: WorkgroupSizes = "density=32, forces=256".parse().unwrap();
        assert_eq!((s.density, s.forces, s.reorder), (32, 256, super::super::shaders::WORKGROUP_SIZE));
        assert_eq!(s.to_string().parse::<WorkgroupSizes>().unwrap(), s);
        for (bad, names) in [("0", "'0'"), ("density=abc", "'density'"), ("pressure=64", "'pressure'"), ("forces", "'forces'"), ("2048", "1024"), ("density=64,density=128", "'density' is given twice")] {
            let e = bad.parse::<WorkgroupSizes>().unwrap_err();
            assert!(e.contains(names), "{bad}: {e}");
        }
    }
}
