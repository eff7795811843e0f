// Across ranks on a GPU, the exchange with the rank's interior left on the device
// (src/solver/gpu/resident.rs, docs/scale-out.md "The GPU across ranks"). After a step the
// device holds the rank's particles in the cell order of that step's binning, integrated;
// only the particles the exchange touches cross the bus:
//
// - `select_band` lists the slots the rank drops (its ghosts, and its own particles that left
//   its slab) and copies out the band: the leaving particles and those in the layers next to a
//   face, which the neighbour takes as ghosts, each with its place in the one-process order
//   (cell and place in the cell of the last binning, found in the cell starts);
// - the host exchanges the band with the neighbours and uploads the dropped slots, sorted, and
//   what it received (migrants and ghosts), sorted by their places in the one-process order;
// - `place_inserts` and `merge_kept` write the held particles again in that order: a kept
//   particle moves up by the received particles that come before it and down by the dropped
//   slots before it (two binary searches in short sorted lists), so the stable binning of the
//   step gives every cell the particles and order one process gives it, as the full upload does;
// - `own_health` counts the rank's own particles' health after the step (ghosts left out);
// - `count_layers` counts the rank's own particles in each cell layer of the slab axis, from
//   which the ranks move their slab bounds towards equal counts (src/solver/decomposition.rs).
//
// With DFSPH (DFSPH_PLACES) a position's w holds the particle's place in the upload, where its
// id and its warm starts live (the solves' arrays are indexed by it, and the binning moves only
// positions and velocities): the band carries the id in the position's w and the warm starts in
// the velocity's w and the place vector's last lane, a received particle brings them in the same
// lanes, and the merge writes every held particle's id and warm starts at its new slot, which
// becomes its place for the next step.
//
// Twin of src/solver/cpu/resident_exchange.rs.

//! include shared/common.wgsl
//! include shared/reduce.wgsl
//! array positions: vec4<f32>, read
//! array velocities: vec4<f32>, read
//! array densities: f32, read, optional
//! array starts: u32, read
// The words below (EXCHANGE_*), read and counted atomically.
//! array exchange_words: u32, atomic, whole
//! array dropped: u32, read_write
// Per band particle three vectors: position, velocity, (slot, cell, place in the cell, 0) as bits
// (DFSPH_PLACES: the id in the position's w, the warm starts in the velocity's w and the last lane).
//! array band: vec4<f32>, read_write
// Per received particle three vectors: position, velocity, (cell, place in the cell, 0, 0) as bits
// (DFSPH_PLACES: the warm starts in the velocity's w and the third lane).
//! array inserts: vec4<f32>, read
//! array insert_places: u32, read_write
//! array merged_positions: vec4<f32>, read_write
//! array merged_velocities: vec4<f32>, read_write
// DFSPH_PLACES: each place's id and warm starts (constant density, divergence), and the merged
// ones, [warm pressure | warm divergence | id bits] with EXCHANGE_PLACES entries each.
//! array place_ids: u32, read, optional
//! array warm_pressure: f32, read, optional
//! array warm_divergence: f32, read, optional
//! array merged_places: f32, read_write, optional
// count_layers: per cell layer of the slab axis, the own particles in it.
//! array layer_counts: u32, atomic, whole

// DFSPH across ranks: positions hold places, not ids (above).
override DFSPH_PLACES: bool = false;
// The step keeps its densities in their own array (bound as `densities`).
override DENSITY_ARRAY: bool = false;

const EXCHANGE_AXIS: u32 = 0u;            // the axis the slabs cut
const EXCHANGE_SLAB_START: u32 = 1u;      // the rank's cell layers along it, [start, end)
const EXCHANGE_SLAB_END: u32 = 2u;
const EXCHANGE_HALO: u32 = 3u;            // ghost layers on each side of a face
const EXCHANGE_NEIGHBOURS: u32 = 4u;      // bit 0: a lower neighbour, bit 1: an upper one
const EXCHANGE_DROPPED: u32 = 5u;         // dropped slots listed
const EXCHANGE_BAND: u32 = 6u;            // band particles copied out
const EXCHANGE_INSERTS: u32 = 7u;         // received particles uploaded
const EXCHANGE_HELD: u32 = 8u;            // held particles before the merge
const EXCHANGE_NON_FINITE: u32 = 9u;      // own_health: own particles not finite
const EXCHANGE_ESCAPED: u32 = 10u;        // finite, outside the domain
const EXCHANGE_MAX_SPEED2: u32 = 11u;     // the largest |v|^2 (bits of a positive f32)
const EXCHANGE_MAX_DENSITY: u32 = 12u;    // the largest finite positive density (bits)
const EXCHANGE_PLACES: u32 = 13u;         // DFSPH_PLACES: entries of each part of merged_places

fn word(k: u32) -> u32 {
    return atomicLoad(&exchange_words[k]);
}

// The slot's cell in the last binning: the last cell whose start is at or below the slot.
fn cell_of_slot(slot: u32) -> u32 {
    var low = 0u;
    var high = params.grid_dims.x * params.grid_dims.y * params.grid_dims.z;
    // starts[low] <= slot < starts[high + 1] holds throughout.
    while (low < high) {
        let mid = (low + high + 1u) / 2u;
        if (starts_at(mid) <= slot) {
            low = mid;
        } else {
            high = mid - 1u;
        }
    }
    return low;
}

// A workgroup's dropped slots and band particles are appended together: each invocation takes
// its place within the workgroup, and one invocation reserves the workgroup's run in each list
// (one global atomic per workgroup and list, not per particle).
var<workgroup> dropped_in_group: atomic<u32>;
var<workgroup> band_in_group: atomic<u32>;
var<workgroup> dropped_base: u32;
var<workgroup> band_base: u32;

@compute @workgroup_size(WORKGROUP_SIZE)
fn select_band(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    if (lid == 0u) {
        atomicStore(&dropped_in_group, 0u);
        atomicStore(&band_in_group, 0u);
    }
    workgroupBarrier();
    let i = thread_index(gid, groups);
    var drop = false;
    var in_band = false;
    var p = vec4<f32>();
    if (i < params.fluid_count) {
        p = positions_at(i);
        if (is_ghost(p.w)) {
            drop = true;
        } else {
            let layer = cell_coords(p.xyz)[word(EXCHANGE_AXIS)];
            let start = word(EXCHANGE_SLAB_START);
            let end = word(EXCHANGE_SLAB_END);
            let halo = word(EXCHANGE_HALO);
            let neighbours = word(EXCHANGE_NEIGHBOURS);
            let leaving = layer < start || layer >= end;
            let near_face = ((neighbours & 1u) != 0u && layer < start + halo) || ((neighbours & 2u) != 0u && layer + halo >= end);
            drop = leaving;
            in_band = leaving || near_face;
        }
    }
    var dropped_place = 0u;
    var band_place = 0u;
    if (drop) {
        dropped_place = atomicAdd(&dropped_in_group, 1u);
    }
    if (in_band) {
        band_place = atomicAdd(&band_in_group, 1u);
    }
    workgroupBarrier();
    if (lid == 0u) {
        dropped_base = atomicAdd(&exchange_words[EXCHANGE_DROPPED], atomicLoad(&dropped_in_group));
        band_base = atomicAdd(&exchange_words[EXCHANGE_BAND], atomicLoad(&band_in_group));
    }
    workgroupBarrier();
    if (drop) {
        dropped_set(dropped_base + dropped_place, i);
    }
    if (in_band) {
        let k = band_base + band_place;
        let cell = cell_of_slot(i);
        var position = p;
        var velocity = velocities_at(i);
        var warm_divergence_bits = 0u;
        if (DFSPH_PLACES) {
            // A band particle is never a ghost: its w is its place alone.
            let place = particle_id(p.w);
            position.w = bitcast<f32>(place_ids_at(place));
            velocity.w = warm_pressure_at(place);
            warm_divergence_bits = bitcast<u32>(warm_divergence_at(place));
        }
        band_set(3u * k, position);
        band_set(3u * k + 1u, velocity);
        band_set(3u * k + 2u, bitcast<vec4<f32>>(vec4<u32>(i, cell, i - starts_at(cell), warm_divergence_bits)));
    }
}

// How many of the first `count` dropped slots (sorted) lie below `slot`.
fn dropped_below(slot: u32, count: u32) -> u32 {
    var low = 0u;
    var high = count;
    while (low < high) {
        let mid = (low + high) / 2u;
        if (dropped_at(mid) < slot) {
            low = mid + 1u;
        } else {
            high = mid;
        }
    }
    return low;
}

// DFSPH_PLACES: the id and warm starts of the particle now at `slot`, which becomes its place;
// returns the w of its position (the slot, with the ghost bit of `w`).
fn write_place(slot: u32, w: f32, id: u32, warm_pressure: f32, warm_divergence: f32) -> f32 {
    let entries = word(EXCHANGE_PLACES);
    merged_places_set(slot, warm_pressure);
    merged_places_set(entries + slot, warm_divergence);
    merged_places_set(2u * entries + slot, bitcast<f32>(id));
    return bitcast<f32>(slot | (bitcast<u32>(w) & GHOST_BIT));
}

// Each received particle j goes before the first held slot whose place in the one-process order
// is after its own: a slot of its cell at its place or, past the cell's end, the next cell's
// first. Its new slot: the kept slots before that one, and the j received before it.
@compute @workgroup_size(WORKGROUP_SIZE)
fn place_inserts(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let j = thread_index(gid, groups);
    if (j >= word(EXCHANGE_INSERTS)) {
        return;
    }
    let key = bitcast<vec4<u32>>(inserts_at(3u * j + 2u));
    let before = min(starts_at(key.x) + key.y, starts_at(key.x + 1u));
    insert_places_set(j, before);
    let slot = before - dropped_below(before, word(EXCHANGE_DROPPED)) + j;
    var position = inserts_at(3u * j);
    var velocity = inserts_at(3u * j + 1u);
    if (DFSPH_PLACES) {
        // The id in the position's w, the warm starts in the velocity's w and the key's z.
        position.w = write_place(slot, position.w, particle_id(position.w), velocity.w, bitcast<f32>(key.z));
        velocity.w = 0.0;
    }
    merged_positions_set(slot, position);
    merged_velocities_set(slot, velocity);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn merge_kept(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i >= word(EXCHANGE_HELD)) {
        return;
    }
    let dropped_count = word(EXCHANGE_DROPPED);
    let below = dropped_below(i, dropped_count);
    if (below < dropped_count && dropped_at(below) == i) {
        return;
    }
    // The received particles placed at or before this slot.
    var low = 0u;
    var high = word(EXCHANGE_INSERTS);
    while (low < high) {
        let mid = (low + high) / 2u;
        if (insert_places_at(mid) <= i) {
            low = mid + 1u;
        } else {
            high = mid;
        }
    }
    let slot = i - below + low;
    var position = positions_at(i);
    if (DFSPH_PLACES) {
        let place = particle_id(position.w);
        position.w = write_place(slot, position.w, place_ids_at(place), warm_pressure_at(place), warm_divergence_at(place));
    }
    merged_positions_set(slot, position);
    merged_velocities_set(slot, velocities_at(i));
}

// The health the host takes from its own particles after a step (CpuSolver::step_on_device):
// the counts of non-finite and escaped particles (a bad particle's own atomic: they are rare),
// the largest |v|^2 and the largest density (each reduced over the workgroup first).
@compute @workgroup_size(WORKGROUP_SIZE)
fn own_health(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    reduce_begin(lid);
    let i = thread_index(gid, groups);
    var speed2 = 0.0;
    var density = 0.0;
    var p = vec4<f32>();
    if (i < params.fluid_count) {
        p = positions_at(i);
    }
    if (i < params.fluid_count && !is_ghost(p.w)) {
        let v = velocities_at(i);
        let finite = is_finite_vec3(p.xyz) && is_finite_vec3(v.xyz);
        let inside = all(p.xyz >= params.domain_min.xyz) && all(p.xyz <= params.domain_max.xyz);
        if (!finite) {
            atomicAdd(&exchange_words[EXCHANGE_NON_FINITE], 1u);
        } else {
            if (!inside) {
                atomicAdd(&exchange_words[EXCHANGE_ESCAPED], 1u);
            }
            speed2 = v.x * v.x + v.y * v.y + v.z * v.z;
        }
        // The density of the step's fields: in their own array where the step keeps one
        // (continuity density, DFSPH), else summed into the velocity's w.
        let rho = select(v.w, densities_at(i), DENSITY_ARRAY);
        if (is_finite_f32(rho) && rho > 0.0) {
            density = rho;
        }
    }
    reduce_offer(0u, bitcast<u32>(speed2));
    reduce_offer(1u, bitcast<u32>(density));
    reduce_end();
    if (lid == 0u) {
        atomicMax(&exchange_words[EXCHANGE_MAX_SPEED2], reduce_result(0u));
        atomicMax(&exchange_words[EXCHANGE_MAX_DENSITY], reduce_result(1u));
    }
}

// The rank's own particles (ghosts left out) per cell layer of the slab axis, as the host's
// balance counts them (`Grid::layer` of each own position), so that a step that moves the slab
// bounds needs no particle on the host. Zeroed by the host before.
@compute @workgroup_size(WORKGROUP_SIZE)
fn count_layers(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        let p = positions_at(i);
        if (!is_ghost(p.w)) {
            atomicAdd(&layer_counts[cell_coords(p.xyz)[word(EXCHANGE_AXIS)]], 1u);
        }
    }
}
