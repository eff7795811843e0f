// Symplectic Euler (v += dt a, then x += dt v), the analytic planes, and the health counters.
// Twin of src/cpu/integrate.rs.

@group(0) @binding(1) var<storage, read_write> positions: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> velocities: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> accelerations: array<vec4<f32>>;
// [0] steps done, [1] non-finite particles this step, [2] escaped particles this step,
// [3] first bad step (0xffffffff: none), [4] largest density (float bits).
@group(0) @binding(4) var<storage, read_write> status: array<atomic<u32>>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(gid, groups);
    if (i >= params.fluid_count) {
        return;
    }
    var v = velocities[i].xyz;
    var x = positions[i].xyz;
    v += accelerations[i].xyz * params.dt;
    x += v * params.dt;
    // A plane puts a particle behind it back on it and removes (or reflects, with restitution)
    // the velocity into it, so that no particle is lost through it.
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
    positions[i] = vec4<f32>(x, 0.0);
    velocities[i] = vec4<f32>(v, 0.0);
    let finite = is_finite_vec3(x) && is_finite_vec3(v);
    if (!finite) {
        atomicAdd(&status[1], 1u);
    } else if (any(x < params.domain_min.xyz) || any(x > params.domain_max.xyz)) {
        atomicAdd(&status[2], 1u);
    }
}

// One thread after every step: counts the step and remembers the first one that went wrong.
@compute @workgroup_size(1)
fn finish_step() {
    let step = atomicLoad(&status[0]) + 1u;
    atomicStore(&status[0], step);
    let bad = atomicLoad(&status[1]) + atomicLoad(&status[2]);
    if (bad > 0u && atomicLoad(&status[3]) == 0xffffffffu) {
        atomicStore(&status[3], step);
    }
}
