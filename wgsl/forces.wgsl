// Accelerations: the symmetric pressure force (report Eq. 6), viscosity (Eq. 7 with the volumes
// m_k / rho_k of Eq. 4, in the symmetric form of Mueller et al. 2003 Eq. 14), wall particles and
// gravity.
// Twin of src/cpu/forces.rs, which explains the wall and viscosity models.

@group(0) @binding(1) var<storage, read> positions: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> velocities: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> densities: array<f32>;
@group(0) @binding(4) var<storage, read> pressures: array<f32>;
@group(0) @binding(5) var<storage, read> starts: array<u32>;
@group(0) @binding(6) var<storage, read> wall_positions: array<vec4<f32>>;  // w: mass
@group(0) @binding(7) var<storage, read> wall_starts: array<u32>;
@group(0) @binding(8) var<storage, read_write> accelerations: array<vec4<f32>>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i >= params.fluid_count) {
        return;
    }
    let cubic = KERNEL == 1u;
    let viscous = VISCOSITY && params.viscosity > 0.0;
    let eps = 0.01 * params.h2;
    let xi = positions[i].xyz;
    let ui = velocities[i].xyz;
    let rho_i = densities[i];
    let p_i = pressures[i];
    let pi_over = p_i / (rho_i * rho_i);
    let wall_p_over = select(2.0 * max(p_i, 0.0) / (rho_i * rho_i), pi_over, CONSISTENT_WALL_PRESSURE);
    let c = cell_coords(xi);
    // Sums without their constant factors, applied once at the end.
    var fluid_pressure = vec3<f32>(0.0);
    var fluid_visc = vec3<f32>(0.0);
    var wall_pressure = vec3<f32>(0.0);
    var wall_visc = vec3<f32>(0.0);
    for (var run = 0u; run < 9u; run++) {
        let cells = stencil_run(c, run);
        for (var j = starts[cells.x]; j < starts[cells.y]; j++) {
            let rij = xi - positions[j].xyz;
            let r2 = dot(rij, rij);
            if (r2 >= params.h2) {
                continue;
            }
            let r = sqrt(r2);
            let grad = kernel_grad(rij, r);
            let rho_j = densities[j];
            let pj_over = pressures[j] / (rho_j * rho_j);
            fluid_pressure -= grad * (pi_over + pj_over);
            if (viscous) {
                let inv_rho = 1.0 / rho_j;
                let uij = ui - velocities[j].xyz;
                if (cubic) {
                    fluid_visc += grad * (inv_rho * dot(uij, rij) / (r2 + eps));
                } else {
                    fluid_visc -= uij * (inv_rho * kernel_laplacian(r));
                }
            }
        }
        if (WALLS) {
            for (var j = wall_starts[cells.x]; j < wall_starts[cells.y]; j++) {
                let w = wall_positions[j];
                let rij = xi - w.xyz;
                let r2 = dot(rij, rij);
                if (r2 >= params.h2) {
                    continue;
                }
                let r = sqrt(r2);
                let grad = kernel_grad(rij, r);
                wall_pressure -= grad * w.w;
                if (viscous) {
                    if (cubic) {
                        wall_visc += grad * (w.w * dot(ui, rij) / (r2 + eps));
                    } else {
                        wall_visc -= ui * (w.w * kernel_laplacian(r));
                    }
                }
            }
        }
    }
    let nu = select(params.viscosity, 10.0 * params.viscosity, cubic);
    let visc = fluid_visc * (nu * params.rest_density * params.fluid_mass / rho_i) + wall_visc * (nu * params.boundary_friction / rho_i);
    var a = fluid_pressure * params.fluid_mass + wall_pressure * wall_p_over + visc;
    if (GRAVITY) {
        a += params.gravity.xyz;
    }
    accelerations[i] = vec4<f32>(a, 0.0);
}
