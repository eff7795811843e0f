// The smallest and largest value of the colouring field, for an automatic colour range, reduced
// on the GPU so that no particle data leaves it. Values are mapped to keys that order like the
// floats (flip every bit of a negative float, only the sign bit of a positive one), so that an
// atomic max over keys is a max over floats; the min is kept as the max of inverted keys, which
// lets both slots start from zero. Non-finite values are skipped.

struct RangeParams {
    count: u32,
    // 1: the value is the length of a vec4's xyz (speed); 4 floats per particle.
    // 0: one float per particle.
    vector: u32,
}

@group(0) @binding(0) var<uniform> range_params: RangeParams;
@group(0) @binding(1) var<storage, read> values: array<f32>;
// [0]: max of ~key, [1]: max of key.
@group(0) @binding(2) var<storage, read_write> range_keys: array<atomic<u32>, 2>;

//! include shared/reduce.wgsl

fn float_to_key(v: f32) -> u32 {
    let b = bitcast<u32>(v);
    if ((b & 0x80000000u) != 0u) {
        return ~b;
    }
    return b | 0x80000000u;
}

@compute @workgroup_size(256)
fn range(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    reduce_begin(lid);
    let i = gid.x + gid.y * groups.x * 256u;
    // The host binds the field one segment at a time: the binding's length bounds the count.
    let stride = select(1u, 4u, range_params.vector == 1u);
    if (i < min(range_params.count, arrayLength(&values) / stride)) {
        var v: f32;
        if (range_params.vector == 1u) {
            v = length(vec3<f32>(values[4u * i], values[4u * i + 1u], values[4u * i + 2u]));
        } else {
            v = values[i];
        }
        if ((bitcast<u32>(v) & 0x7f800000u) != 0x7f800000u) {
            let k = float_to_key(v);
            reduce_offer(0u, ~k);
            reduce_offer(1u, k);
        }
    }
    reduce_end();
    if (lid == 0u) {
        atomicMax(&range_keys[0], reduce_result(0u));
        atomicMax(&range_keys[1], reduce_result(1u));
    }
}
