// Shared by every stage (each includes it): the parameter block, the status words, the kernels,
// the equation of state and the grid. The formulas' twin is src/model/kernels.rs; the parameter
// block and the status words are declared on the host in src/solver/gpu/params.rs, and a test
// checks that the two agree.
// h is the kernel's support radius: every kernel is zero for r >= h.

// Specialisation constants, set per scene when the pipelines are built.
override KERNEL: u32 = 0u;                      // 0: Mueller et al. 2003, 1: cubic spline, 2: Wendland C2
override EOS: u32 = 0u;                         // 0: linear (report Eq. 8), 1: Tait (Eq. 9)
override CLAMP_NEGATIVE_PRESSURE: bool = false;
override CONSISTENT_WALL_PRESSURE: bool = false; // walls push with p_i/rho_i^2, not 2 max(p_i,0)/rho_i^2
// Walls push with p_i/rho_i^2 + p_w/rho_w^2, p_w extrapolated from the fluid (wall_pressure.wgsl).
override ADAMI_WALL_PRESSURE: bool = false;
// The terms a scene uses: a term that is off is compiled out of every stage.
override VISCOSITY: bool = true;                // some viscosity of the scene (or its schedule) > 0
override WALLS: bool = true;                    // the scene has wall particles
override PLANES: bool = true;                   // the scene has analytic planes
override SOLID_BOXES: bool = false;             // the scene has box obstacles, backed by their faces
override GRAVITY: bool = true;                  // gravity is not zero
override ADAPTIVE_DT: bool = false;             // dt chosen on the GPU every step (integrate.wgsl)
// Across ranks: the top bit of a position's w marks a ghost (a neighbour rank's particle), which
// the adaptive step's maxima, the resident exchange's health and DFSPH's error sums leave out;
// the rest of w is the particle's id (with DFSPH its place in the upload, where its warm starts
// are found).
override GHOSTS: bool = false;
const GHOST_BIT: u32 = 0x80000000u;

// Whether a particle (the w of its position) is a ghost: never alone.
fn is_ghost(w: f32) -> bool {
    return GHOSTS && (bitcast<u32>(w) & GHOST_BIT) != 0u;
}

// A particle's id (the w of its position) without the ghost bit: with DFSPH across ranks its
// place in the upload.
fn particle_id(w: f32) -> u32 {
    return select(bitcast<u32>(w), bitcast<u32>(w) & ~GHOST_BIT, GHOSTS);
}
// Density carried by the continuity equation (in each velocity's w) instead of summed.
override CONTINUITY: bool = false;
override DENSITY_DIFFUSION: bool = false;       // delta-SPH diffusion (with CONTINUITY only)
override ARTIFICIAL_VISCOSITY: bool = false;    // Monaghan's, on approaching pairs
// Akinci et al. 2013: cohesion and curvature between fluid particles (with the normals of
// surface_normals.wgsl), and the walls' adhesion.
override SURFACE_TENSION: bool = false;
override WALL_ADHESION: bool = false;
// The neighbour stencil as 9 runs of 3 cells (true) or as 27 single cells (false, kept to
// measure what the runs gain; the same neighbours in the same order).
override STENCIL_RUNS: bool = true;
// Neighbour lists (shared/neighbour_lists.wgsl): the tiled density records each particle's
// neighbours, at most LIST_CAPACITY of them, and the tiled forces walk those lists.
override NEIGHBOUR_LISTS: bool = false;
override LIST_CAPACITY: u32 = 0u;
// With a neighbour skin (neighbour_skin.wgsl) the lists hold the candidates within h (1 + skin)
// (LIST_RADIUS2 = (1 + skin)^2), and a density stage that walks lists recorded at an earlier
// step records none (RECORD_LISTS false).
override LIST_RADIUS2: f32 = 1.0;
override RECORD_LISTS: bool = true;

// Threads per workgroup of a particle stage, chosen per stage by the host (GpuOptions).
override WORKGROUP_SIZE: u32 = 128u;
const MAX_PLANES: u32 = 8u;

struct Params {
    domain_min: vec4<f32>,
    domain_max: vec4<f32>,
    gravity: vec4<f32>,
    grid_origin: vec4<f32>,
    // xyz: cells per axis.
    grid_dims: vec4<u32>,
    h: f32,
    h2: f32,
    inv_cell: f32,
    dt: f32,
    fluid_mass: f32,
    rest_density: f32,
    stiffness: f32,
    viscosity: f32,
    boundary_friction: f32,
    // the kernel's normalisation, gradient factor, Laplacian factor (see src/model/kernels.rs).
    w_coef: f32,
    grad_coef: f32,
    lap_coef: f32,
    fluid_count: u32,
    wall_count: u32,
    plane_count: u32,
    // gamma of surface tension (src/model/params.rs).
    surface_tension: f32,
    // xyz: unit normal, w: offset (plane n.x = w).
    planes: array<vec4<f32>, 8>,
    // x: restitution.
    plane_restitution: array<vec4<f32>, 8>,
    // Adaptive dt: speed of sound, C_cfl, C_f, C_visc, dt_min, dt_max.
    speed_of_sound: f32,
    cfl_number: f32,
    force_number: f32,
    viscous_number: f32,
    dt_min: f32,
    dt_max: f32,
    // The run stops at a step whose largest density or speed passes these (infinite: off).
    stop_density: f32,
    stop_speed: f32,
    // DFSPH: m / rho0, the smallest denominator of alpha, the warm start's share, the solves'
    // iteration limits, and the error sums (fixed-point, low and high word) that meet the
    // tolerances (src/solver/cpu/dfsph_shared.rs).
    fluid_volume: f32,
    factor_epsilon: f32,
    warm_start_share: f32,
    min_iterations: u32,
    max_iterations: u32,
    min_divergence_iterations: u32,
    max_divergence_iterations: u32,
    density_threshold: vec2<u32>,
    divergence_threshold: vec2<u32>,
    // delta h c0 of density diffusion, alpha h_s c0 of artificial viscosity (src/model/params.rs).
    diffusion_factor: f32,
    artificial_viscosity_factor: f32,
    // The solid boxes backed by their faces (SOLID_BOXES), and their corners (xyz).
    solid_box_count: u32,
    // gamma m 32 / (pi h^3) of cohesion, beta 0.007 / h^3 of adhesion (src/model/params.rs).
    cohesion_factor: f32,
    adhesion_factor: f32,
    solid_box_min: array<vec4<f32>, 8>,
    solid_box_max: array<vec4<f32>, 8>,
}

@group(0) @binding(0) var<uniform> params: Params;

// The words of the status buffer (health counters; the adaptive step's maxima, dt and time).
// Floats are stored as their bits.
const STATUS_STEPS: u32 = 0u;
const STATUS_NON_FINITE: u32 = 1u;
const STATUS_ESCAPED: u32 = 2u;
const STATUS_FIRST_BAD_STEP: u32 = 3u;        // STATUS_NO_BAD_STEP while none went wrong
const STATUS_MAX_DENSITY: u32 = 4u;           // positive floats order like their bits
const STATUS_MAX_SPEED: u32 = 5u;             // adaptive dt: this step's largest |v|
const STATUS_MAX_ACCELERATION: u32 = 6u;      // adaptive dt: this step's largest |a|
const STATUS_DT: u32 = 7u;                    // adaptive dt: this step's dt
const STATUS_TIME_LO: u32 = 8u;               // adaptive dt: time = (HI 2^32 + LO) 2^EXPONENT
const STATUS_TIME_HI: u32 = 9u;               // (shared/adaptive_dt.wgsl add_to_time)
const STATUS_DT_MIN: u32 = 10u;
const STATUS_DT_MAX: u32 = 11u;
const STATUS_STEP_MAX_DENSITY: u32 = 12u;     // this step's largest density (reset by finish_step)
const STATUS_STEP_MAX_SPEED: u32 = 13u;       // the largest speed after this step (reset by finish_step)
const STATUS_TOP_SPEED: u32 = 14u;            // the largest speed so far
// The first bad step's measures, written by finish_step with STATUS_FIRST_BAD_STEP, so that
// the host reads that step's figures and not those of a later one.
const STATUS_BAD_CAUSES: u32 = 15u;           // CAUSE_* bits
const STATUS_BAD_NON_FINITE: u32 = 16u;
const STATUS_BAD_ESCAPED: u32 = 17u;
const STATUS_BAD_MAX_DENSITY: u32 = 18u;
const STATUS_BAD_MAX_SPEED: u32 = 19u;
const STATUS_BAD_DT: u32 = 20u;
const STATUS_BAD_TIME: u32 = 21u;             // adaptive dt: the time at the end of the bad step
const STATUS_DFSPH_ERROR_LO: u32 = 22u;       // DFSPH: the error sum of the solve under way
const STATUS_DFSPH_ERROR_HI: u32 = 23u;
const STATUS_DFSPH_ITERATION: u32 = 24u;      // its iterations so far
const STATUS_DFSPH_SOLVING: u32 = 25u;        // 1 while it goes on
const STATUS_PRESSURE_ITERATIONS: u32 = 26u;  // the constant-density solve over the run
const STATUS_PRESSURE_ITERATIONS_MAX: u32 = 27u;
const STATUS_PRESSURE_ITERATIONS_LAST: u32 = 28u;
const STATUS_PRESSURE_ERROR: u32 = 29u;
const STATUS_PRESSURE_UNCONVERGED: u32 = 30u;
const STATUS_DIVERGENCE_ITERATIONS: u32 = 31u; // the divergence solve over the run
const STATUS_DIVERGENCE_ITERATIONS_MAX: u32 = 32u;
const STATUS_DIVERGENCE_ITERATIONS_LAST: u32 = 33u;
const STATUS_DIVERGENCE_ERROR: u32 = 34u;
const STATUS_DIVERGENCE_UNCONVERGED: u32 = 35u;
const STATUS_TIME_EXPONENT: u32 = 36u;        // adaptive dt: the time's power of two (an i32)
const STATUS_NO_BAD_STEP: u32 = 0xffffffffu;
const CAUSE_NON_FINITE: u32 = 1u;
const CAUSE_ESCAPED: u32 = 2u;
const CAUSE_TOO_DENSE: u32 = 4u;
const CAUSE_TOO_FAST: u32 = 8u;

// Dispatches of more than 65535 workgroups wrap into rows along y.
fn thread_index(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.x + gid.y * groups.x * WORKGROUP_SIZE;
}

fn is_finite_f32(v: f32) -> bool {
    // A bit test, since compilers may assume that NaN never occurs in float comparisons.
    return (bitcast<u32>(v) & 0x7f800000u) != 0x7f800000u;
}

fn is_finite_vec3(v: vec3<f32>) -> bool {
    return is_finite_f32(v.x) && is_finite_f32(v.y) && is_finite_f32(v.z);
}

// Integer cell of a point, clamped into the grid (a particle outside the domain is counted as
// escaped by the integration; here it only needs a valid cell).
fn cell_coords(p: vec3<f32>) -> vec3<u32> {
    let f = floor((p - params.grid_origin.xyz) * params.inv_cell);
    var c: vec3<u32>;
    for (var a = 0u; a < 3u; a++) {
        let max_c = params.grid_dims[a] - 1u;
        if (!is_finite_f32(f[a])) {
            c[a] = 0u;
        } else {
            c[a] = u32(clamp(f[a], 0.0, f32(max_c)));
        }
    }
    return c;
}

fn cell_key(c: vec3<u32>) -> u32 {
    return c.x + params.grid_dims.x * (c.y + params.grid_dims.y * c.z);
}

// The kernels below have no branches: each piece is computed and the one that applies selected
// (the same values, a NaN included), since on a SIMD software adapter a branch in a neighbour
// loop costs more than the arithmetic it skips (docs/performance.md).

// W(r) from r^2: poly6 (Mueller 2003 Eq. 20), the cubic spline (Monaghan 1992) or Wendland's
// C2 function (Wendland 1995; 3D normalisation as in Dehnen & Aly 2012).
fn kernel_w(r2: f32) -> f32 {
    if (KERNEL == 0u) {
        let d = params.h2 - r2;
        return select(params.w_coef * d * d * d, 0.0, r2 >= params.h2);
    }
    if (KERNEL == 2u) {
        let q = sqrt(r2) / params.h;
        let d = 1.0 - q;
        let d2 = d * d;
        return select(params.w_coef * d2 * d2 * (1.0 + 4.0 * q), 0.0, r2 >= params.h2);
    }
    let q = sqrt(r2) / params.h;
    let d = 1.0 - q;
    let w = select(params.w_coef * 2.0 * d * d * d, params.w_coef * (6.0 * (q * q * q - q * q) + 1.0), q <= 0.5);
    return select(w, 0.0, r2 >= params.h2);
}

// grad W at r_ij = x_i - x_j with |r_ij| = r; zero at r = 0 where the direction is undefined.
fn kernel_grad(rij: vec3<f32>, r: f32) -> vec3<f32> {
    var dwdr: f32;
    if (KERNEL == 0u) {
        // Spiky (Mueller 2003 Eq. 21).
        let d = params.h - r;
        dwdr = params.grad_coef * d * d;
    } else if (KERNEL == 2u) {
        // Wendland: dW/dr = -210 / (pi h^4) q (1 - q)^3 (grad_coef holds the negative factor).
        let q = r / params.h;
        let d = 1.0 - q;
        dwdr = params.grad_coef * q * d * d * d;
    } else {
        let q = r / params.h;
        let d = 1.0 - q;
        dwdr = select(-params.grad_coef * d * d, params.grad_coef * q * (3.0 * q - 2.0), q <= 0.5);
    }
    return select(rij * (dwdr / r), vec3<f32>(0.0), r >= params.h || r <= 1e-12 * params.h);
}

// Akinci et al.'s (2013) cohesion spline at q = r / h < 1 without its factor 32 / (pi h^3);
// the twin of cohesion_shape in src/model/kernels.rs.
fn cohesion_shape(q: f32) -> f32 {
    let d = 1.0 - q;
    let t = d * d * d * q * q * q;
    return select(2.0 * t - 1.0 / 64.0, t, q > 0.5);
}

// Akinci et al.'s (2013) adhesion spline at q = r / h without its factor 0.007 / h^3: zero
// outside 1/2 < q < 1; the twin of adhesion_shape in src/model/kernels.rs.
fn adhesion_shape(q: f32) -> f32 {
    let a = sqrt(sqrt(max(6.0 * q - 4.0 * q * q - 2.0, 0.0)));
    return select(0.0, a, q > 0.5 && q < 1.0);
}

// Akinci et al.'s (2013) cohesion and curvature: what fluid neighbour j at r_ij = x_i - x_j (|r_ij| = r < h) pulls
// particle i by, with its factors: K_ij (gamma m C(r) x_ij / r + gamma (n_i - n_j)),
// K_ij = 2 rho0 / (rho_i + rho_j); no cohesion where the direction is undefined. The twin of
// SurfaceTension::pair in src/solver/cpu/forces.rs.
fn surface_tension_pair(rij: vec3<f32>, r: f32, rho_i: f32, rho_j: f32, ni: vec3<f32>, nj: vec3<f32>) -> vec3<f32> {
    let k = 2.0 * params.rest_density / (rho_i + rho_j);
    var pull = (ni - nj) * params.surface_tension;
    if (r > 1e-12 * params.h) {
        pull += rij * (params.cohesion_factor * cohesion_shape(r / params.h) / r);
    }
    return pull * k;
}

// Akinci et al.'s (2013) adhesion without beta 0.007 / h^3: m_w A(r) x_iw / r for a wall particle of
// mass m_w (rho0 V_w); zero where the direction is undefined. The twin of adhesion_pair in
// src/solver/cpu/forces.rs.
fn adhesion_pair(rij: vec3<f32>, r: f32, mw: f32) -> vec3<f32> {
    return select(vec3<f32>(0.0), rij * (mw * adhesion_shape(r / params.h) / r), r > 1e-12 * params.h);
}

// Whether viscosity is the Morris/Monaghan term built on grad W (the cubic spline's and
// Wendland's, whose Laplacians change sign) rather than Mueller's viscosity Laplacian; the twin
// of Kernel::gradient_viscosity (src/model/scene.rs).
fn gradient_viscosity() -> bool {
    return KERNEL != 0u;
}

// The viscosity's nu as the pair sums use it: with the gradient form 2 (d + 2) nu (Monaghan 2005,
// Eq. 6.3); the twin of viscous_nu in src/model/kernels.rs.
fn viscous_nu() -> f32 {
    return select(params.viscosity, 10.0 * params.viscosity, gradient_viscosity());
}

// Laplacian of the viscosity kernel (Mueller 2003 Eq. 22).
fn kernel_laplacian(r: f32) -> f32 {
    return select(params.lap_coef * (params.h - r), 0.0, r >= params.h);
}

// Report Eq. 8 (linear) or Eq. 9 (Tait, exponent 7).
fn eos_pressure(density: f32) -> f32 {
    let ratio = density / params.rest_density;
    var p: f32;
    if (EOS == 0u) {
        p = params.stiffness * (ratio - 1.0);
    } else {
        let r2 = ratio * ratio;
        let r4 = r2 * r2;
        p = params.stiffness * (r4 * r2 * ratio - 1.0);
    }
    if (CLAMP_NEGATIVE_PRESSURE && p < 0.0) {
        p = 0.0;
    }
    return p;
}

// The density above rest density at which the equation of state gives the pressure p
// (Fourtakas et al. 2019, Eq. 12, for p = rho0 g . x_ji). Twin of density_above_rest in
// src/model/kernels.rs.
fn density_above_rest(p: f32) -> f32 {
    if (EOS == 0u) {
        return params.rest_density * p / params.stiffness;
    }
    return params.rest_density * (pow(1.0 + p / params.stiffness, 1.0 / 7.0) - 1.0);
}

// Spans of the stencil a particle visits: 9 runs of up to 3 cells, or 27 single cells.
fn stencil_span_count() -> u32 {
    return select(27u, 9u, STENCIL_RUNS);
}

// The 27-cell stencil as 9 runs of up to 3 cells along x: each run is one contiguous span of
// the cell-sorted arrays, from starts[run.x] to starts[run.y]. Without STENCIL_RUNS, span
// `index` is the single cell dx = index % 3 - 1 of run index / 3 (empty outside the grid).
fn stencil_run(c: vec3<u32>, index: u32) -> vec2<u32> {
    var run = index;
    if (!STENCIL_RUNS) {
        run = index / 3u;
    }
    let dy = i32(run % 3u) - 1;
    let dz = i32(run / 3u) - 1;
    let y = i32(c.y) + dy;
    let z = i32(c.z) + dz;
    if (y < 0 || z < 0 || y >= i32(params.grid_dims.y) || z >= i32(params.grid_dims.z)) {
        return vec2<u32>(0u, 0u);
    }
    let row = params.grid_dims.x * (u32(y) + params.grid_dims.y * u32(z));
    if (!STENCIL_RUNS) {
        let x = i32(c.x) + i32(index % 3u) - 1;
        if (x < 0 || x >= i32(params.grid_dims.x)) {
            return vec2<u32>(0u, 0u);
        }
        return vec2<u32>(row + u32(x), row + u32(x) + 1u);
    }
    let x0 = select(c.x - 1u, 0u, c.x == 0u);
    let x1 = min(c.x + 1u, params.grid_dims.x - 1u);
    return vec2<u32>(row + x0, row + x1 + 1u);
}

// A particle's position and velocity after the backstops (planes, solid boxes).
struct Backstopped {
    x: vec3<f32>,
    v: vec3<f32>,
}

// A particle strictly inside a solid box is put back on the box's nearest face and its velocity
// into the box removed (restitution 0), box after box; ties go to the first face in the order
// -x, +x, -y, +y, -z, +z. Twin of leave_solid_boxes in src/solver/cpu/integrate.rs.
fn leave_solid_boxes(x_in: vec3<f32>, v_in: vec3<f32>) -> Backstopped {
    var x = x_in;
    var v = v_in;
    for (var b = 0u; b < params.solid_box_count; b++) {
        let lo = params.solid_box_min[b].xyz;
        let hi = params.solid_box_max[b].xyz;
        if (!(all(x > lo) && all(x < hi))) {
            continue;
        }
        var axis = 0u;
        var upper = false;
        var nearest = x.x - lo.x;
        for (var k = 0u; k < 3u; k++) {
            let below = x[k] - lo[k];
            if (below < nearest) {
                axis = k;
                upper = false;
                nearest = below;
            }
            let above = hi[k] - x[k];
            if (above < nearest) {
                axis = k;
                upper = true;
                nearest = above;
            }
        }
        if (upper) {
            x[axis] = hi[axis];
            v[axis] = max(v[axis], 0.0);
        } else {
            x[axis] = lo[axis];
            v[axis] = min(v[axis], 0.0);
        }
    }
    return Backstopped(x, v);
}

// The backstops of a particle just moved to x with velocity v: a plane puts a particle behind
// it back on it and removes (or reflects, with restitution) the velocity into it, so that no
// particle is lost through it; then a solid box's faces do the same for a particle that entered
// the box. Twin of backstop in src/solver/cpu/integrate.rs.
fn backstop(x_in: vec3<f32>, v_in: vec3<f32>) -> Backstopped {
    var x = x_in;
    var v = v_in;
    if (PLANES) {
        for (var k = 0u; k < params.plane_count; k++) {
            let plane = params.planes[k];
            let d = dot(x, plane.xyz) - plane.w;
            if (d < 0.0) {
                x -= plane.xyz * d;
                let vn = dot(v, plane.xyz);
                if (vn < 0.0) {
                    v -= plane.xyz * ((1.0 + params.plane_restitution[k].x) * vn);
                }
            }
        }
    }
    if (SOLID_BOXES) {
        return leave_solid_boxes(x, v);
    }
    return Backstopped(x, v);
}
