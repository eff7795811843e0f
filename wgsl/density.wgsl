// Density by kernel summation over fluid and wall neighbours (report Eq. 5) and pressure from
// the equation of state (Eq. 8 or 9). Twin of src/cpu/density.rs.

@group(0) @binding(1) var<storage, read> positions: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> starts: array<u32>;
@group(0) @binding(3) var<storage, read> wall_positions: array<vec4<f32>>;  // w: mass
@group(0) @binding(4) var<storage, read> wall_starts: array<u32>;
@group(0) @binding(5) var<storage, read_write> densities: array<f32>;
@group(0) @binding(6) var<storage, read_write> pressures: array<f32>;
// [4]: the largest density so far, as float bits (positive floats order like their bits).
@group(0) @binding(7) var<storage, read_write> status: array<atomic<u32>>;

var<workgroup> group_max: atomic<u32>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    if (lid == 0u) {
        atomicStore(&group_max, 0u);
    }
    workgroupBarrier();
    let i = thread_index(gid, groups);
    if (i < params.fluid_count) {
        let xi = positions[i].xyz;
        let c = cell_coords(xi);
        var fluid_sum = 0.0;
        var wall_sum = 0.0;
        for (var run = 0u; run < 9u; run++) {
            let cells = stencil_run(c, run);
            for (var j = starts[cells.x]; j < starts[cells.y]; j++) {
                let d = xi - positions[j].xyz;
                fluid_sum += kernel_w(dot(d, d));
            }
            if (WALLS) {
                for (var j = wall_starts[cells.x]; j < wall_starts[cells.y]; j++) {
                    let w = wall_positions[j];
                    let d = xi - w.xyz;
                    wall_sum += w.w * kernel_w(dot(d, d));
                }
            }
        }
        let rho = params.fluid_mass * fluid_sum + wall_sum;
        densities[i] = rho;
        pressures[i] = eos_pressure(rho);
        if (is_finite_f32(rho) && rho > 0.0) {
            atomicMax(&group_max, bitcast<u32>(rho));
        }
    }
    workgroupBarrier();
    if (lid == 0u) {
        atomicMax(&status[4], atomicLoad(&group_max));
    }
}
