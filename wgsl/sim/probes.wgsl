// Probes sampled on the state a step starts from (after its density stage): the row's head
// (the step and its time), point probes and gauges (probe_points, one invocation per probe;
// dispatched for every sample), force probes and fronts (probe_particles,
// one invocation per fluid particle, one partial per workgroup and slot), and the reduction of
// the partials into a row of the sample buffer (probe_finish, one invocation). Under DFSPH the
// last two run after the solves, on the pressure of the step's wall push (wall_push_pressure).
// Recorded only on the steps where a probe is due, and only in scenes with probes. What each
// probe measures is in src/model/probes.rs and docs/probes.md. Twin of
// src/solver/cpu/probes.rs.

//! include shared/common.wgsl
//! array positions: vec4<f32>, read
//! array velocities: vec4<f32>, read
//! array densities: f32, read
//! array pressures: f32, read
//! array starts: u32, read
//! array wall_positions: vec4<f32>, read
//! array wall_starts: u32, read
// Bit k: the wall particle belongs to the k-th force probe.
//! array wall_probe_masks: u32, read
// With ADAMI_WALL_PRESSURE, each wall particle's pressure (x) and density (y); not bound otherwise.
//! array wall_fields: vec2<f32>, read, optional
// Under DFSPH with force probes: the step's stiffness sums, and the pressure of its wall push
// that wall_push_pressure writes and probe_particles then reads in place of `pressures`; not
// bound otherwise.
//! array pressure_sum: f32, read, optional
//! array divergence_sum: f32, read, optional
//! array push_pressures: f32, read_write, optional
// The probe table written by the host (src/solver/gpu/probes.rs): floats as their bits, so that
// every word reaches the shader unchanged (no float move may flush a small integer's bits).
//! array probe_table: vec4<u32>, read
// [0]: rows written; then every probe's values; the partials; the rows (floats as their bits).
//! array probe_data: u32, read_write
//! array status: u32, atomic, whole

const PROBE_WORKGROUP: u32 = 128u;
const FORCE_SLOTS: u32 = 6u;
const FRONT_SLOTS: u32 = 2u;
// Words before a row's values: the step, the time (three words, shared/adaptive_dt.wgsl), dt.
const PROBE_ROW_HEAD: u32 = 5u;
// 4 force probes of 6 slots and 4 front probes of 2 (src/model/probes.rs MAX_*_PROBES).
const MAX_SLOTS: u32 = 32u;
const PROBE_POINT: u32 = 0u;
const PROBE_GAUGE: u32 = 1u;
const PROBE_FORCE: u32 = 2u;
const PROBE_FRONT: u32 = 3u;
const GAUGE_FRACTION: f32 = 0.5;
const LOWEST: f32 = -3.4028235e38;

// The table's header: probes, force probes, front probes, workgroups of probe_particles;
// values per sample, where the partials and the rows start, rows the buffer holds.
fn table_counts() -> vec4<u32> {
    return probe_table_at(0u);
}
fn table_layout() -> vec4<u32> {
    return probe_table_at(1u);
}
// Probe p: (type, first value, -, -), then its point or direction, and more, as floats.
fn probe_head(p: u32) -> vec4<u32> {
    return probe_table_at(2u + 3u * p);
}
fn probe_entry(p: u32, k: u32) -> vec4<f32> {
    return bitcast<vec4<f32>>(probe_table_at(2u + 3u * p + k));
}
fn data_float(i: u32) -> f32 {
    return bitcast<f32>(probe_data_at(i));
}
fn set_data_float(i: u32, v: f32) {
    probe_data_set(i, bitcast<u32>(v));
}

// Shepard sums at x over the fluid within h: sum V_j W, and sum V_j W f_j of pressure,
// density and velocity (V_j = m / rho_j); with ADAMI_WALL_PRESSURE also sum W, sum p_j W and
// sum rho_j (x - x_j) W, the wall particles' extrapolation (wall_pressure.wgsl) at x.
struct ShepardSums {
    fraction: f32,
    pressure: f32,
    density: f32,
    velocity: vec3<f32>,
    weights: f32,
    weighted_pressure: f32,
    hydrostatic: vec3<f32>,
}

fn shepard_sums(x: vec3<f32>) -> ShepardSums {
    var s = ShepardSums(0.0, 0.0, 0.0, vec3<f32>(0.0), 0.0, 0.0, vec3<f32>(0.0));
    let c = cell_coords(x);
    for (var run = 0u; run < stencil_span_count(); run++) {
        let cells = stencil_run(c, run);
        for (var j = starts_at(cells.x); j < starts_at(cells.y); j++) {
            let d = x - positions_at(j).xyz;
            let w = kernel_w(dot(d, d));
            let rho_j = densities_at(j);
            let vw = params.fluid_mass / rho_j * w;
            s.fraction += vw;
            s.pressure += vw * pressures_at(j);
            s.density += vw * rho_j;
            s.velocity += velocities_at(j).xyz * vw;
            if (ADAMI_WALL_PRESSURE) {
                s.weights += w;
                s.weighted_pressure += w * pressures_at(j);
                s.hydrostatic += d * (rho_j * w);
            }
        }
    }
    return s;
}

// A point probe's pressure: the Shepard average (r = 1 / fraction, 0 without fluid), or with
// ADAMI_WALL_PRESSURE the walls' extrapolation taken at the point (src/solver/cpu/probes.rs
// point_pressure); 0 without fluid.
fn point_pressure(s: ShepardSums, r: f32) -> f32 {
    if (!ADAMI_WALL_PRESSURE) {
        return s.pressure * r;
    }
    if (s.weights <= 0.0) {
        return 0.0;
    }
    var p = s.weighted_pressure;
    if (GRAVITY) {
        p += dot(params.gravity.xyz, s.hydrostatic);
    }
    return p / s.weights;
}

// The highest point of the line where the fluid fraction reaches GAUGE_FRACTION: levels from
// the top down, `step` apart, interpolated between the first that reaches it and the one above.
fn gauge_surface(x: f32, z: f32, bottom: f32, top: f32, step: f32) -> f32 {
    let levels = u32(floor((top - bottom) / step)) + 1u;
    var above = 0.0;
    var above_y = top;
    for (var k = 0u; k <= levels; k++) {
        let y = max(top - step * f32(k), bottom);
        let f = shepard_sums(vec3<f32>(x, y, z)).fraction;
        if (f >= GAUGE_FRACTION) {
            if (k == 0u) {
                return y;
            }
            return y + (above_y - y) * (f - GAUGE_FRACTION) / (f - above);
        }
        above = f;
        above_y = y;
        if (y <= bottom) {
            break;
        }
    }
    return bottom;
}

// Where row `r` of the sample buffer starts: the rows follow the values and the partials.
fn row_start(r: u32) -> u32 {
    let sizes = table_layout();
    return 1u + sizes.z + r * (PROBE_ROW_HEAD + sizes.x);
}

// The head of the row this sample fills: the step, the time (its three words) and the last
// step's dt, as the status words hold them when the sample starts. Written here, before the
// step's work, since a DFSPH step chooses its dt (and advances the time words) between its
// point probes and the rest of its sample.
fn write_row_head() {
    let row = row_start(probe_data_at(0u));
    probe_data_set(row, atomicLoad(&status[STATUS_STEPS]));
    probe_data_set(row + 1u, atomicLoad(&status[STATUS_TIME_LO]));
    probe_data_set(row + 2u, atomicLoad(&status[STATUS_TIME_HI]));
    probe_data_set(row + 3u, atomicLoad(&status[STATUS_TIME_EXPONENT]));
    probe_data_set(row + 4u, atomicLoad(&status[STATUS_DT]));
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn probe_points(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let p = thread_index(gid, groups);
    if (p == 0u) {
        write_row_head();
    }
    if (p >= table_counts().x) {
        return;
    }
    let head = probe_head(p);
    let at = 1u + head.y;
    let g = probe_entry(p, 1u);
    if (head.x == PROBE_POINT) {
        let s = shepard_sums(g.xyz);
        // No fluid within h: zeros (the fraction column says so).
        var r = 0.0;
        if (s.fraction > 0.0) {
            r = 1.0 / s.fraction;
        }
        set_data_float(at, point_pressure(s, r));
        set_data_float(at + 1u, s.density * r);
        set_data_float(at + 2u, s.velocity.x * r);
        set_data_float(at + 3u, s.velocity.y * r);
        set_data_float(at + 4u, s.velocity.z * r);
        set_data_float(at + 5u, s.fraction);
    } else if (head.x == PROBE_GAUGE) {
        let surface = gauge_surface(g.x, g.z, g.y, g.w, probe_entry(p, 2u).x);
        set_data_float(at, surface);
        set_data_float(at + 1u, surface - g.y);
    }
}

// A thread's sums over its particle, one per slot.
var<private> slot_sums: array<f32, MAX_SLOTS>;
var<workgroup> group_values: array<vec4<f32>, PROBE_WORKGROUP>;

// Adds the force fluid particle i exerts on the force probes' wall particles (and its moments)
// to slot_sums: the reaction to the wall terms of its acceleration in forces.wgsl, m_i times
// minus what wall particle w adds to a_i (pressure, viscosity, artificial viscosity, adhesion).
fn add_wall_forces(i: u32, forces: u32) {
    let viscous = VISCOSITY && params.viscosity > 0.0;
    let eps = 0.01 * params.h2;
    let xi = positions_at(i).xyz;
    let ui = velocities_at(i).xyz;
    let rho_i = densities_at(i);
    let p_i = pressures_at(i);
    let pi_over = p_i / (rho_i * rho_i);
    let wall_p_over = select(2.0 * max(p_i, 0.0) / (rho_i * rho_i), pi_over, CONSISTENT_WALL_PRESSURE);
    let nu = viscous_nu();
    let visc_factor = nu * params.boundary_friction / rho_i;
    let artificial_factor = params.artificial_viscosity_factor * params.boundary_friction / rho_i;
    let c = cell_coords(xi);
    for (var run = 0u; run < stencil_span_count(); run++) {
        let cells = stencil_run(c, run);
        for (var j = wall_starts_at(cells.x); j < wall_starts_at(cells.y); j++) {
            let mask = wall_probe_masks_at(j);
            if (mask == 0u) {
                continue;
            }
            let w = wall_positions_at(j);  // w: mass
            let rij = xi - w.xyz;
            let r2 = dot(rij, rij);
            if (r2 >= params.h2) {
                continue;
            }
            let r = sqrt(r2);
            let grad = kernel_grad(rij, r);
            var a = grad * (-w.w * wall_p_over);
            if (ADAMI_WALL_PRESSURE) {
                let own = wall_fields_at(j);
                a = grad * (-w.w * (pi_over + own.x / (own.y * own.y)));
            }
            if (viscous) {
                if (gradient_viscosity()) {
                    a += grad * (visc_factor * w.w * dot(ui, rij) / (r2 + eps));
                } else {
                    a += ui * (-visc_factor * w.w * kernel_laplacian(r));
                }
            }
            if (ARTIFICIAL_VISCOSITY) {
                let approach = dot(ui, rij);
                if (approach < 0.0) {
                    a += grad * (artificial_factor * w.w * approach / (r2 + eps));
                }
            }
            if (WALL_ADHESION) {
                a -= adhesion_pair(rij, r, w.w) * params.adhesion_factor;
            }
            let f = a * (-params.fluid_mass);
            for (var k = 0u; k < forces; k++) {
                if ((mask & (1u << k)) == 0u) {
                    continue;
                }
                let arm = w.xyz - probe_entry(force_probe(k), 1u).xyz;
                let m = cross(arm, f);
                let s = FORCE_SLOTS * k;
                slot_sums[s] += f.x;
                slot_sums[s + 1u] += f.y;
                slot_sums[s + 2u] += f.z;
                slot_sums[s + 3u] += m.x;
                slot_sums[s + 4u] += m.y;
                slot_sums[s + 5u] += m.z;
            }
        }
    }
}

// The probe index of the k-th force probe (or front probe, with `kind`).
fn nth_probe(kind: u32, k: u32) -> u32 {
    var seen = 0u;
    for (var p = 0u; p < table_counts().x; p++) {
        if (probe_head(p).x == kind) {
            if (seen == k) {
                return p;
            }
            seen++;
        }
    }
    return 0u;
}
fn force_probe(k: u32) -> u32 {
    return nth_probe(PROBE_FORCE, k);
}

// Whether slot s of the partials keeps a largest value (a front's projection) and not a sum.
fn is_max_slot(s: u32, forces: u32) -> bool {
    return s >= FORCE_SLOTS * forces && (s - FORCE_SLOTS * forces) % FRONT_SLOTS == 0u;
}

// Under DFSPH, after the solves: the pressure whose consistent wall force (-m_b p_i / rho_i^2
// grad W_ib, as probe_particles sums it) is the step's wall push, -K_i g_i^w over dt in the
// constant-density solve and once in the divergence solve, felt by the wall as the opposite of
// m_i dv_i / dt: p_i = rho_i^2 (Kp_i / dt^2 + Kd_i / dt) / rho0 (src/solver/cpu/probes.rs).
@compute @workgroup_size(WORKGROUP_SIZE)
fn wall_push_pressure(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i >= params.fluid_count) {
        return;
    }
    var dt = params.dt;
    if (ADAPTIVE_DT) {
        dt = bitcast<f32>(atomicLoad(&status[STATUS_DT]));
    }
    let rho = densities_at(i);
    push_pressures_set(i, rho * rho * (pressure_sum_at(i) / (dt * dt) + divergence_sum_at(i) / dt) / params.rest_density);
}

@compute @workgroup_size(PROBE_WORKGROUP)
fn probe_particles(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let counts = table_counts();
    let forces = counts.y;
    let fronts = counts.z;
    let slots = FORCE_SLOTS * forces + FRONT_SLOTS * fronts;
    for (var s = 0u; s < MAX_SLOTS; s++) {
        slot_sums[s] = select(0.0, LOWEST, is_max_slot(s, forces));
    }
    let i = gid.x + gid.y * groups.x * PROBE_WORKGROUP;
    // Across ranks each rank counts its own particles: a ghost's part is its owner's.
    if (i < params.fluid_count && !is_ghost(positions_at(i).w)) {
        if (WALLS && forces > 0u) {
            add_wall_forces(i, forces);
        }
        let xi = positions_at(i).xyz;
        for (var q = 0u; q < fronts; q++) {
            let e = probe_entry(nth_probe(PROBE_FRONT, q), 1u);
            let band = probe_entry(nth_probe(PROBE_FRONT, q), 2u);
            if (xi.y < band.x + band.y) {
                let s = FORCE_SLOTS * forces + FRONT_SLOTS * q;
                slot_sums[s] = max(slot_sums[s], dot(xi, e.xyz));
                slot_sums[s + 1u] += 1.0;
            }
        }
    }
    // Each slot folded over the workgroup in particle order by one invocation, four at a time.
    let group = wid.x + wid.y * groups.x;
    let partials = table_layout().y;
    let group_count = counts.w;
    for (var s0 = 0u; s0 < MAX_SLOTS; s0 += 4u) {
        group_values[lid] = vec4<f32>(slot_sums[s0], slot_sums[s0 + 1u], slot_sums[s0 + 2u], slot_sums[s0 + 3u]);
        workgroupBarrier();
        if (lid == 0u && s0 < slots) {
            var total = group_values[0];
            for (var t = 1u; t < PROBE_WORKGROUP; t++) {
                let v = group_values[t];
                for (var c = 0u; c < 4u; c++) {
                    if (is_max_slot(s0 + c, forces)) {
                        total[c] = max(total[c], v[c]);
                    } else {
                        total[c] += v[c];
                    }
                }
            }
            for (var c = 0u; c < 4u; c++) {
                if (s0 + c < slots) {
                    set_data_float(1u + partials + (s0 + c) * group_count + group, total[c]);
                }
            }
        }
        workgroupBarrier();
    }
}

@compute @workgroup_size(1)
fn probe_finish() {
    let counts = table_counts();
    let sizes = table_layout();
    let forces = counts.y;
    let groups = counts.w;
    let partial = 1u + sizes.y;
    var force = 0u;
    var front = 0u;
    for (var p = 0u; p < counts.x; p++) {
        let head = probe_head(p);
        let at = 1u + head.y;
        if (head.x == PROBE_FORCE) {
            for (var a = 0u; a < FORCE_SLOTS; a++) {
                let s = FORCE_SLOTS * force + a;
                var total = 0.0;
                for (var g = 0u; g < groups; g++) {
                    total += data_float(partial + s * groups + g);
                }
                set_data_float(at + a, total);
            }
            force++;
        } else if (head.x == PROBE_FRONT) {
            let s = FORCE_SLOTS * forces + FRONT_SLOTS * front;
            var count = 0.0;
            var far = 0.0;
            for (var g = 0u; g < groups; g++) {
                let c = data_float(partial + (s + 1u) * groups + g);
                if (c > 0.0) {
                    let x = data_float(partial + s * groups + g);
                    far = select(max(far, x), x, count == 0.0);
                    count += c;
                }
            }
            set_data_float(at, far);
            set_data_float(at + 1u, count);
            front++;
        }
    }
    // The row after its head (write_row_head): every value.
    let written = probe_data_at(0u);
    let values = sizes.x;
    let row = row_start(written);
    for (var v = 0u; v < values; v++) {
        probe_data_set(row + PROBE_ROW_HEAD + v, probe_data_at(1u + v));
    }
    probe_data_set(0u, written + 1u);
}
