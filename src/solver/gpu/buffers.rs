//! GPU buffers: allocation, the upload of a state, and the particle buffers handed to others
//! (the renderer, a program that draws the particles itself).

use super::device::GpuContext;
use wgpu::util::DeviceExt;

/// Particles per piece moved between the host and the GPU (uploads, streamed snapshots and
/// checkpoints).
pub const STREAM_CHUNK: u64 = 1 << 20;

/// Usage of every storage buffer of the solver. VERTEX: the renderer draws particles straight
/// from these buffers.
fn storage_usage() -> wgpu::BufferUsages {
    wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::VERTEX
}

/// A storage buffer of `bytes` bytes (at least 16: wgpu binds no empty buffer).
pub fn storage(device: &wgpu::Device, label: &str, bytes: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor { label: Some(label), size: bytes.max(16), usage: storage_usage(), mapped_at_creation: false })
}

/// A storage buffer holding `contents` (padded to at least 16 bytes).
pub fn storage_init(device: &wgpu::Device, label: &str, contents: &[u8]) -> wgpu::Buffer {
    let mut data = contents.to_vec();
    data.resize(data.len().max(16), 0);
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents: &data, usage: storage_usage() })
}

/// Points as `vec4<f32>` with `w(i)` in the fourth component.
pub fn vec4s(points: &[[f64; 3]], w: impl Fn(usize) -> f32) -> Vec<[f32; 4]> {
    points.iter().enumerate().map(|(i, p)| [p[0] as f32, p[1] as f32, p[2] as f32, w(i)]).collect()
}

/// The particle state: positions whose w holds each particle's original index as u32 bits,
/// and velocities (w = 0, or the carried density with the continuity equation).
#[derive(Clone)]
pub struct StateBuffers {
    pub positions: wgpu::Buffer,
    pub velocities: wgpu::Buffer,
}

/// How the particle state's buffers are used from one step to the next.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StateLayout {
    /// Two states of positions and velocities (32 bytes each per particle): the binning gathers
    /// one into the other, and the step writes the new state back into the first while other
    /// threads still read the old one. The fused forces-and-integration pass needs this.
    PingPong,
    /// Three `vec4` buffers (48 bytes per particle) whose roles change: positions, velocities
    /// and a spare. The binning keeps its ranks in the spare and gathers the positions into it
    /// and the velocities into the old positions' buffer; the weakly compressible step writes
    /// the accelerations into the spare and its integration, which reads only a particle's own
    /// slot of every array, writes the new state in place; DFSPH predicts the velocities into
    /// the spare, which then holds the velocities.
    InPlace,
}

/// In place, the buffers of each phase's roles: [positions, velocities, spare]. The rotations
/// first (the binning turns one into the next; the weakly compressible step reaches only
/// these), then the phases where DFSPH's prediction swapped velocities and spare.
const ROLES: [[usize; 3]; 6] = [[0, 1, 2], [2, 0, 1], [1, 2, 0], [0, 2, 1], [1, 0, 2], [2, 1, 0]];

/// The buffers of the particle state and which of them holds what in each phase: a phase is
/// an assignment of the roles to the buffers; the binning moves the state to another, and so do
/// the fused step's integration and DFSPH's prediction.
pub struct StateStore {
    pub layout: StateLayout,
    /// Ping-pong: positions 0, velocities 0, positions 1, velocities 1. In place: three buffers.
    buffers: Vec<wgpu::Buffer>,
    /// Whether a step predicts the velocities into a second buffer (DFSPH): in place all six
    /// assignments of the roles are then reached, else the three rotations.
    predicts: bool,
}

impl StateStore {
    pub fn new(device: &wgpu::Device, layout: StateLayout, fluid: u64, predicts: bool) -> Self {
        let labels: &[&str] = match layout {
            StateLayout::PingPong => &["positions 0", "velocities 0", "positions 1", "velocities 1"],
            StateLayout::InPlace => &["particle state 0", "particle state 1", "particle state 2"],
        };
        StateStore { layout, buffers: labels.iter().map(|l| storage(device, l, fluid * 16)).collect(), predicts }
    }

    /// The number of phases.
    pub fn phases(&self) -> usize {
        match (self.layout, self.predicts) {
            (StateLayout::PingPong, _) => 2,
            (StateLayout::InPlace, false) => 3,
            (StateLayout::InPlace, true) => 6,
        }
    }

    /// The positions and velocities of phase `c`.
    pub fn state(&self, c: usize) -> StateBuffers {
        match self.layout {
            StateLayout::PingPong => StateBuffers { positions: self.buffers[2 * c].clone(), velocities: self.buffers[2 * c + 1].clone() },
            StateLayout::InPlace => StateBuffers { positions: self.buffers[ROLES[c][0]].clone(), velocities: self.buffers[ROLES[c][1]].clone() },
        }
    }

    /// In place: the spare buffer of phase `c` (the binning's ranks, then the accelerations or
    /// DFSPH's predicted velocities).
    pub fn spare(&self, c: usize) -> wgpu::Buffer {
        debug_assert_eq!(self.layout, StateLayout::InPlace);
        self.buffers[ROLES[c][2]].clone()
    }

    /// The state a step of phase `c` writes where it does not write in place: the other pair,
    /// or in place the same positions with the spare as velocities (DFSPH's prediction).
    pub fn next(&self, c: usize) -> StateBuffers {
        match self.layout {
            StateLayout::PingPong => self.state(1 - c),
            StateLayout::InPlace => StateBuffers { positions: self.state(c).positions, velocities: self.spare(c) },
        }
    }

    /// In place, the phase with the roles `roles`.
    fn phase_of(roles: [usize; 3]) -> usize {
        ROLES.iter().position(|&r| r == roles).expect("every assignment of the roles is a phase")
    }

    /// The phase after the binning of phase `c`: the other pair, or in place the phase whose
    /// positions are `c`'s spare and whose velocities are `c`'s positions.
    pub fn after_binning(&self, c: usize) -> usize {
        match self.layout {
            StateLayout::PingPong => 1 - c,
            StateLayout::InPlace => {
                let [p, v, s] = ROLES[c];
                Self::phase_of([s, p, v])
            }
        }
    }

    /// The phase after the integration of phase `c`: the other pair (the fused step), or in
    /// place the same.
    pub fn after_integration(&self, c: usize) -> usize {
        match self.layout {
            StateLayout::PingPong => 1 - c,
            StateLayout::InPlace => c,
        }
    }

    /// The phase after a DFSPH step of phase `c`, whose velocities are the ones predicted into
    /// [`StateStore::next`].
    pub fn after_prediction(&self, c: usize) -> usize {
        match self.layout {
            StateLayout::PingPong => 1 - c,
            StateLayout::InPlace => {
                let [p, v, s] = ROLES[c];
                Self::phase_of([p, s, v])
            }
        }
    }

    /// Particles each buffer holds.
    pub fn capacity(&self) -> u64 {
        self.buffers[0].size() / 16
    }

    /// Bytes of every buffer.
    pub fn bytes(&self) -> u64 {
        self.buffers.iter().map(|b| b.size()).sum()
    }
}

impl StateBuffers {
    /// Writes positions (with the ids `id(i)` in their w) and velocities (w = 0, as the
    /// integration writes them), `STREAM_CHUNK` particles at a time with a submission after
    /// each piece, so the host converts and stages one piece instead of two whole `vec4` arrays
    /// (32 bytes per particle).
    pub fn upload(&self, ctx: &GpuContext, positions: &[[f64; 3]], velocities: &[[f64; 3]], id: impl Fn(usize) -> u32, velocity_w: &dyn Fn(usize) -> f32) {
        let chunk = STREAM_CHUNK as usize;
        for first in (0..positions.len()).step_by(chunk) {
            let end = (first + chunk).min(positions.len());
            let pos = vec4s(&positions[first..end], |i| f32::from_bits(id(first + i)));
            let vel = vec4s(&velocities[first..end], |i| velocity_w(first + i));
            ctx.queue.write_buffer(&self.positions, first as u64 * 16, bytemuck::cast_slice(&pos));
            ctx.queue.write_buffer(&self.velocities, first as u64 * 16, bytemuck::cast_slice(&vel));
            ctx.queue.submit([]);
            // Lets the device free the piece's staging memory before the next one.
            let _ = ctx.device.poll(wgpu::PollType::Wait { submission_index: None, timeout: None });
        }
    }
}

/// Cells per block of the wall cell index (one mask word).
pub const WALL_CELL_BLOCK: usize = 32;

/// The wall cell starts kept only for the cells that hold wall particles (walls cover a surface,
/// so most cells hold none): per block of [`WALL_CELL_BLOCK`] cells a mask of the cells that
/// hold walls and the number of such cells before the block (`blocks`), and the start of each
/// such cell, then the wall count (`firsts`). The start of cell c is then
/// `firsts[rank(c)]` with rank(c) the number of wall cells before c: the start of the first wall
/// cell from c on, which is c's own start (wgsl: `Alias::Derived` of `wall_starts`).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct WallCellIndex {
    pub blocks: Vec<[u32; 2]>,
    pub firsts: Vec<u32>,
}

impl WallCellIndex {
    /// The index of the dense starts `starts` (cells + 1 values, the last the wall count).
    pub fn new(starts: &[u32]) -> Self {
        let cells = starts.len().saturating_sub(1);
        // Blocks cover index `cells` too (the end of the last cell).
        let mut blocks = vec![[0u32; 2]; (cells + 1).div_ceil(WALL_CELL_BLOCK)];
        let mut firsts = Vec::new();
        for (c, pair) in starts.windows(2).enumerate() {
            if c % WALL_CELL_BLOCK == 0 {
                blocks[c / WALL_CELL_BLOCK][1] = firsts.len() as u32;
            }
            if pair[1] > pair[0] {
                blocks[c / WALL_CELL_BLOCK][0] |= 1 << (c % WALL_CELL_BLOCK);
                firsts.push(pair[0]);
            }
        }
        if cells % WALL_CELL_BLOCK == 0 {
            blocks[cells / WALL_CELL_BLOCK][1] = firsts.len() as u32;
        }
        firsts.push(starts.last().copied().unwrap_or(0));
        WallCellIndex { blocks, firsts }
    }

    /// The start of cell `c` (0 ..= cells), as the shaders compute it.
    pub fn start(&self, c: usize) -> u32 {
        let [mask, before] = self.blocks[c / WALL_CELL_BLOCK];
        let below = mask & ((1u32 << (c % WALL_CELL_BLOCK)) - 1);
        self.firsts[(before + below.count_ones()) as usize]
    }
}

/// The ids carried in the w components of positions read back from the GPU.
/// The top bit of a position's w marks a ghost across ranks (`GHOST_BIT` in
/// wgsl/shared/common.wgsl); the rest is the particle's id (with DFSPH its place in the rank's
/// upload).
pub const GHOST_BIT: u32 = 0x8000_0000;

pub fn ids_of(positions: &[[f32; 4]]) -> Vec<u32> {
    positions.iter().map(|p| p[3].to_bits()).collect()
}

/// Values in slot order put back into original order (`ids[slot]` is the original index).
pub fn unpermute<T: Copy + Default>(ids: &[u32], values: impl Iterator<Item = T>) -> Vec<T> {
    let mut out = vec![T::default(); ids.len()];
    for (slot, v) in values.enumerate() {
        out[ids[slot] as usize] = v;
    }
    out
}

/// The xyz of a `vec4<f32>`, widened to f64.
pub fn widen(v: &[f32; 4]) -> [f64; 3] {
    [v[0] as f64, v[1] as f64, v[2] as f64]
}

/// The buffers of the current particle state, for rendering or post-processing on the GPU, with
/// the device they live on. They are the solver's own buffers (handles, not copies), in its
/// cell order, all four in the same order; the solver's buffers change roles as it steps, so ask again
/// after every step.
#[derive(Clone, Debug)]
pub struct ParticleBuffers {
    pub context: GpuContext,
    /// `array<vec4<f32>>`: x, y, z, and in w the original index of the particle in each slot
    /// (u32 bits).
    pub positions: wgpu::Buffer,
    /// `array<vec4<f32>>`: vx, vy, vz, 0.
    pub velocities: wgpu::Buffer,
    /// `array<f32>`.
    pub densities: wgpu::Buffer,
    /// `array<f32>`.
    pub pressures: wgpu::Buffer,
    /// Number of fluid particles (elements of each array).
    pub count: u32,
}

/// The neighbour lists (wgsl/shared/neighbour_lists.wgsl): `capacity` slots per fluid particle
/// in `slots`, and each particle's counts.
pub(super) struct NeighbourLists {
    pub capacity: u32,
    pub slots: wgpu::Buffer,
    pub counts: wgpu::Buffer,
}

impl NeighbourLists {
    /// A particle's counts word when its list overflowed (LIST_FULL in neighbour_lists.wgsl).
    pub const FULL: u32 = u32::MAX;

    /// The slots a counts word says the list uses (fluid chunks in the low 16 bits, wall chunks
    /// above), or `None` for a list that overflowed.
    pub fn used(counts: u32) -> Option<u32> {
        (counts != Self::FULL).then_some((counts & 0xffff) + (counts >> 16))
    }
}
