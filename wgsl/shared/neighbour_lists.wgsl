// Neighbour lists, recorded by a tiled density stage (density_tiled.wgsl, continuity_tiled.wgsl,
// DFSPH's dfsph_factors_tiled.wgsl) and walked by the passes of the same step that follow it on
// the same positions (forces_tiled.wgsl; DFSPH's solves, shared/dfsph_tiles.wgsl). On a software
// adapter a tile evaluates every candidate of the union of its eight particles' stencils (216 in
// a resting block with cells one support wide) where a particle has about 33 neighbours; the
// passes over lists evaluate only those (docs/performance.md, "Neighbour lists").
//
// Particle i's list is a column of LIST_CAPACITY slots, slot t at t * fluid_count + i (the
// invocations of a subgroup read neighbouring words), each slot one chunk of the tile's walk
// that holds a neighbour (an entry: the chunk's first candidate and a mask of its neighbours):
// its fluid chunks from the top, its wall chunks from the bottom, each in the order the
// per-particle walk meets them, so the sums over a list are those of the walk bit for bit. One
// store per chunk rather than per neighbour: on a software adapter each store is eight scalar
// ones, and a store per neighbour cost the density more than the lists saved the forces.
// `neighbour_counts` holds the fluid chunks in its low 16 bits and the wall chunks above; a
// particle with more chunks than slots (counted on, not written) is marked full, and its
// subgroup walks the tiles.
//! array neighbours: u32, read_write, optional
//! array neighbour_counts: u32, read_write, optional

// The counts of a list being recorded.
struct ListCounts {
    fluid: u32,
    walls: u32,
}

fn list_slot(t: u32, i: u32) -> u32 {
    return t * params.fluid_count + i;
}

// An entry: the first candidate b of a chunk of TILE (low 24 bits) and which of them are
// neighbours (bit k: candidate b + k).
const ENTRY_MASK_SHIFT: u32 = 24u;
const ENTRY_BASE: u32 = 0xffffffu;

// `counts` after recording the chunk of fluid (or with `wall`, wall) candidates from b whose
// neighbours are `mask`. Written without a branch on the mask (one in the tile's walk costs a
// software adapter more than the store): the entry goes to the next free slot in any case and
// is counted only where the mask is not empty, so the next chunk overwrites one that is. A list
// with no free slot (whose particle's subgroup may still read it, if nothing more is kept) or
// an invocation without a particle writes nothing; nothing at all without NEIGHBOUR_LISTS (the
// recording stages call the helpers of this file unconditionally).
fn record_chunk(counts: ListCounts, i: u32, b: u32, mask: u32, wall: bool) -> ListCounts {
    if (!NEIGHBOUR_LISTS || !RECORD_LISTS) {
        return counts;
    }
    var c = counts;
    if (i < params.fluid_count && c.fluid + c.walls < LIST_CAPACITY) {
        let free = LIST_CAPACITY - 1u - c.walls;
        neighbours_set(list_slot(select(c.fluid, free, wall), i), b | (mask << ENTRY_MASK_SHIFT));
    }
    let kept = select(0u, 1u, mask != 0u);
    c.fluid += select(kept, 0u, wall);
    c.walls += select(0u, kept, wall);
    return c;
}

// The forces test r^2 < h^2 again with their own arithmetic, which a driver may compile
// differently from a density stage's (a fused multiply-add in the dot product), so the density
// stages keep a little more, up to LIST_MARGIN h^2, and the lists hold every pair the forces
// keep. With a skin the lists' radius is h (1 + skin) (LIST_RADIUS2 its square over h^2).
const LIST_MARGIN: f32 = 1.001;

// 1 where candidate j at xj is in the invocation's own span and within the lists' radius of xi.
fn list_bit(xi: vec3<f32>, xj: vec3<f32>, j: u32, span: vec2<u32>) -> u32 {
    let d = xi - xj;
    return select(0u, 1u, in_span(j, span) && !(dot(d, d) >= LIST_MARGIN * LIST_RADIUS2 * params.h2));
}

// `counts` after recording the chunk of fluid (or with `wall`, wall) candidates from b, this
// lane's at x, that lie in `span` within the lists' radius of xi (the chunk shuffled to every
// lane: the whole subgroup calls it).
fn record_shuffled_chunk(counts: ListCounts, i: u32, xi: vec3<f32>, x: vec3<f32>, b: u32, span: vec2<u32>, wall: bool) -> ListCounts {
    if (!NEIGHBOUR_LISTS) {
        return counts;
    }
    var mask = 0u;
    //! unroll 8 mask |= list_bit(xi, subgroupShuffle(x, {k}u), b + {k}u, span) << {k}u;
    return record_chunk(counts, i, b, mask, wall);
}

const LIST_FULL: u32 = 0xffffffffu;

// Particle i's counts, written by the recording stage once its walk has ended.
fn finish_list(i: u32, counts: ListCounts) {
    if (!NEIGHBOUR_LISTS || !RECORD_LISTS) {
        return;
    }
    let fits = counts.fluid + counts.walls <= LIST_CAPACITY;
    neighbour_counts_set(i, select(LIST_FULL, counts.fluid | (counts.walls << 16u), fits));
}

// Particle i's counts, or LIST_FULL.
fn list_counts(i: u32) -> u32 {
    return neighbour_counts_at(i);
}

// Whether the subgroup walks its particles' lists (p: this invocation's): where the step keeps
// lists and every one fits. The choice is the subgroup's, as the tiles' shuffles need all its
// lanes; each way should finish its own sums (forces_tiled.wgsl says why).
fn walks_lists(p: u32) -> bool {
    let counts = select(0u, list_counts(p), NEIGHBOUR_LISTS);
    return NEIGHBOUR_LISTS && subgroupAll(counts != LIST_FULL);
}

// The next neighbour j of the `count` entries of particle i's list from its top (or with
// `walls`, from its bottom), one neighbour per call, so that the invocations of a SIMD batch
// iterate about as often as the one with the most neighbours; false past the last. `at` starts
// at zero and holds the next entry's number (x), the mask left of the current entry (y) and its
// first candidate (z).
fn next_listed(i: u32, count: u32, walls: bool, at: ptr<function, vec3<u32>>, j: ptr<function, u32>) -> bool {
    if ((*at).y == 0u) {
        if ((*at).x == count) {
            return false;
        }
        let entry = neighbours_at(list_slot(select((*at).x, LIST_CAPACITY - 1u - (*at).x, walls), i));
        *at = vec3<u32>((*at).x + 1u, entry >> ENTRY_MASK_SHIFT, entry & ENTRY_BASE);
    }
    *j = (*at).z + firstTrailingBit((*at).y);
    (*at).y &= (*at).y - 1u;
    return true;
}
