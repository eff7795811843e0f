// DFSPH's constant-density solve iterations with the stencils of a subgroup walked together
// (`rate_tiled`, `apply_tiled`: shared/dfsph_tiles.wgsl): the same sums in the same order as
// dfsph_pressure.wgsl's, so the twin is the same, src/solver/cpu/dfsph_pressure.rs. A file of its own since its
// subgroup operations need an adapter with subgroups, which the other stages do not.

//! include sim/dfsph_pressure.wgsl
//! include shared/tiles.wgsl
//! include shared/dfsph_tiles.wgsl
