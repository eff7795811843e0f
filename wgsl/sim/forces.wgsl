// Accelerations: the symmetric pressure force (report Eq. 6), viscosity (Eq. 7 with the volumes
// m_k / rho_k of Eq. 4, in the symmetric form of Mueller et al. 2003 Eq. 14), Monaghan's
// artificial viscosity, Akinci et al.'s surface tension and adhesion, wall particles and gravity.
// Twin of src/solver/cpu/forces.rs, which explains the wall and viscosity models. One invocation
// walks one particle's stencil; forces_tiled.wgsl walks a subgroup's together, with the pair
// terms below.

//! include shared/common.wgsl
//! array positions: vec4<f32>, read
//! array velocities: vec4<f32>, read
//! array densities: f32, read
//! array pressures: f32, read
//! array starts: u32, read
//! array wall_positions: vec4<f32>, read
//! array wall_starts: u32, read
// With ADAMI_WALL_PRESSURE, each wall particle's pressure (x) and density (y) of this step
// (wall_pressure.wgsl); not bound otherwise.
//! array wall_fields: vec2<f32>, read, optional
// With SURFACE_TENSION, each fluid particle's normal (surface_normals.wgsl); not bound otherwise.
//! array normals: vec4<f32>, read, optional
//! array accelerations: vec4<f32>, read_write

// What a fluid particle brings to its pairs.
struct OwnParticle {
    x: vec3<f32>,
    u: vec3<f32>,
    rho: f32,
    p: f32,
    p_over: f32,            // p / rho^2
    n: vec3<f32>,           // the surface normal (SURFACE_TENSION)
}

fn surface_normal_of(i: u32) -> vec3<f32> {
    var n = vec3<f32>(0.0);
    if (SURFACE_TENSION) {
        n = normals_at(i).xyz;
    }
    return n;
}

fn own_particle(i: u32) -> OwnParticle {
    let rho = densities_at(i);
    let p = pressures_at(i);
    return OwnParticle(positions_at(i).xyz, velocities_at(i).xyz, rho, p, p / (rho * rho), surface_normal_of(i));
}

// A fluid neighbour's part of a pair; its velocity and normal only where a term reads them.
struct FluidCandidate {
    x: vec3<f32>,
    u: vec3<f32>,
    rho: f32,
    p: f32,
    n: vec3<f32>,
}

fn reads_velocities() -> bool {
    return viscous_pairs() || ARTIFICIAL_VISCOSITY;
}

fn viscous_pairs() -> bool {
    return VISCOSITY && params.viscosity > 0.0;
}

fn fluid_candidate(j: u32, xj: vec3<f32>) -> FluidCandidate {
    var u = vec3<f32>(0.0);
    if (reads_velocities()) {
        u = velocities_at(j).xyz;
    }
    return FluidCandidate(xj, u, densities_at(j), pressures_at(j), surface_normal_of(j));
}

// The sums over the neighbours, without their constant factors (applied by
// finish_acceleration).
struct ForceSums {
    fluid_pressure: vec3<f32>,
    fluid_visc: vec3<f32>,
    wall_pressure: vec3<f32>,
    wall_visc: vec3<f32>,
    fluid_artificial: vec3<f32>,
    wall_artificial: vec3<f32>,
    // Surface tension with its factors (subtracted as it is), adhesion without its factor.
    tension: vec3<f32>,
    adhesion: vec3<f32>,
}

// The terms of fluid neighbour n, added where `counted` (its own stencil's candidate) and n is
// closer than h (NaN distances included, as a blow-up must show).
fn add_fluid_pair(sums: ptr<function, ForceSums>, own: OwnParticle, n: FluidCandidate, counted: bool) {
    let eps = 0.01 * params.h2;
    let rij = own.x - n.x;
    let r2 = dot(rij, rij);
    let counts = counted && !(r2 >= params.h2);
    let r = sqrt(r2);
    let grad = kernel_grad(rij, r);
    let pj_over = n.p / (n.rho * n.rho);
    (*sums).fluid_pressure -= select(vec3<f32>(0.0), grad * (own.p_over + pj_over), counts);
    let uij = own.u - n.u;
    if (viscous_pairs()) {
        let inv_rho = 1.0 / n.rho;
        if (gradient_viscosity()) {
            (*sums).fluid_visc += select(vec3<f32>(0.0), grad * (inv_rho * dot(uij, rij) / (r2 + eps)), counts);
        } else {
            (*sums).fluid_visc -= select(vec3<f32>(0.0), uij * (inv_rho * kernel_laplacian(r)), counts);
        }
    }
    if (ARTIFICIAL_VISCOSITY) {
        let approach = dot(uij, rij);
        (*sums).fluid_artificial += select(vec3<f32>(0.0), grad * (approach / ((r2 + eps) * (own.rho + n.rho))), counts && approach < 0.0);
    }
    if (SURFACE_TENSION) {
        (*sums).tension += select(vec3<f32>(0.0), surface_tension_pair(rij, r, own.rho, n.rho, own.n, n.n), counts);
    }
}

// A wall neighbour: position and mass (w), and with ADAMI_WALL_PRESSURE its pressure (x) and
// density (y).
struct WallCandidate {
    w: vec4<f32>,
    fields: vec2<f32>,
}

fn wall_candidate(j: u32, w: vec4<f32>) -> WallCandidate {
    var fields = vec2<f32>(0.0, 1.0);
    if (ADAMI_WALL_PRESSURE) {
        fields = wall_fields_at(j);
    }
    return WallCandidate(w, fields);
}

fn add_wall_pair(sums: ptr<function, ForceSums>, own: OwnParticle, n: WallCandidate, counted: bool) {
    let eps = 0.01 * params.h2;
    let rij = own.x - n.w.xyz;
    let r2 = dot(rij, rij);
    let counts = counted && !(r2 >= params.h2);
    let r = sqrt(r2);
    let grad = kernel_grad(rij, r);
    if (ADAMI_WALL_PRESSURE) {
        (*sums).wall_pressure -= select(vec3<f32>(0.0), grad * (n.w.w * (own.p_over + n.fields.x / (n.fields.y * n.fields.y))), counts);
    } else {
        (*sums).wall_pressure -= select(vec3<f32>(0.0), grad * n.w.w, counts);
    }
    if (viscous_pairs()) {
        if (gradient_viscosity()) {
            (*sums).wall_visc += select(vec3<f32>(0.0), grad * (n.w.w * dot(own.u, rij) / (r2 + eps)), counts);
        } else {
            (*sums).wall_visc -= select(vec3<f32>(0.0), own.u * (n.w.w * kernel_laplacian(r)), counts);
        }
    }
    if (ARTIFICIAL_VISCOSITY) {
        let approach = dot(own.u, rij);
        (*sums).wall_artificial += select(vec3<f32>(0.0), grad * (n.w.w * approach / ((r2 + eps) * own.rho)), counts && approach < 0.0);
    }
    if (WALL_ADHESION) {
        (*sums).adhesion += select(vec3<f32>(0.0), adhesion_pair(rij, r, n.w.w), counts);
    }
}

// The acceleration (xyz) from the sums, and the density (w), which the integration keeps in the
// w of the velocity: with CONTINUITY the density the next step advances, otherwise the one the
// outputs of this step read there (src/solver/gpu/solver.rs, `array_places`).
fn finish_acceleration(own: OwnParticle, sums: ForceSums) -> vec4<f32> {
    // The wall pressure term's factor outside the sum over wall particles (Adami: inside).
    var wall_p_over = select(2.0 * max(own.p, 0.0) / (own.rho * own.rho), own.p_over, CONSISTENT_WALL_PRESSURE);
    if (ADAMI_WALL_PRESSURE) {
        wall_p_over = 1.0;
    }
    let nu = viscous_nu();
    let visc = sums.fluid_visc * (nu * params.rest_density * params.fluid_mass / own.rho) + sums.wall_visc * (nu * params.boundary_friction / own.rho);
    var a = sums.fluid_pressure * params.fluid_mass + sums.wall_pressure * wall_p_over + visc;
    if (ARTIFICIAL_VISCOSITY) {
        let av = params.artificial_viscosity_factor;
        a += sums.fluid_artificial * (2.0 * av * params.fluid_mass) + sums.wall_artificial * (av * params.boundary_friction);
    }
    if (SURFACE_TENSION) {
        a -= sums.tension;
    }
    if (WALL_ADHESION) {
        a -= sums.adhesion * params.adhesion_factor;
    }
    if (GRAVITY) {
        a += params.gravity.xyz;
    }
    return vec4<f32>(a, own.rho);
}

fn no_sums() -> ForceSums {
    let zero = vec3<f32>(0.0);
    return ForceSums(zero, zero, zero, zero, zero, zero, zero, zero);
}

// The acceleration of fluid particle i, one particle over its stencil.
fn particle_acceleration(i: u32) -> vec4<f32> {
    let own = own_particle(i);
    let c = cell_coords(own.x);
    var sums = no_sums();
    for (var run = 0u; run < stencil_span_count(); run++) {
        let cells = stencil_run(c, run);
        for (var j = starts_at(cells.x); j < starts_at(cells.y); j++) {
            let xj = positions_at(j).xyz;
            let rij = own.x - xj;
            if (dot(rij, rij) >= params.h2) {
                continue;
            }
            add_fluid_pair(&sums, own, fluid_candidate(j, xj), true);
        }
        if (WALLS) {
            for (var j = wall_starts_at(cells.x); j < wall_starts_at(cells.y); j++) {
                let w = wall_positions_at(j);
                let rij = own.x - w.xyz;
                if (dot(rij, rij) >= params.h2) {
                    continue;
                }
                add_wall_pair(&sums, own, wall_candidate(j, w), true);
            }
        }
    }
    return finish_acceleration(own, sums);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn forces(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        accelerations_set(i, particle_acceleration(i));
    }
}
