// Exclusive prefix sum of the cell counts, in place, for any number of cells: each workgroup
// scans a block of SCAN_BLOCK values and writes the block's total; the totals are scanned the
// same way one level up, and added back (a multi-level scan, Blelloch 1990 / Harris et al. 2007).
// Twin of src/solver/cpu/prefix_sum.rs. Exact: integer arithmetic in a fixed order.

//! include shared/common.wgsl

// The scan keeps its own workgroup size: its workgroup array is sized by it.
const SCAN_WORKGROUP_SIZE: u32 = 128u;
const SCAN_BLOCK: u32 = 2u * SCAN_WORKGROUP_SIZE;

// Bound by the host per segment of the cell array (src/solver/gpu/prefix_sum.rs): `data` is one segment of
// whole blocks, `block_sums` the totals of that segment's blocks.
//! array data: u32, read_write, whole
//! array block_sums: u32, read_write, whole

var<workgroup> partial: array<u32, SCAN_WORKGROUP_SIZE>;

fn group_index(wid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return wid.x + wid.y * groups.x;
}

@compute @workgroup_size(SCAN_WORKGROUP_SIZE)
fn scan_blocks(
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let n = arrayLength(&data);
    let block = group_index(wid, groups);
    let t = lid.x;
    let i0 = block * SCAN_BLOCK + 2u * t;
    let i1 = i0 + 1u;
    var a = 0u;
    var b = 0u;
    if (i0 < n) {
        a = data[i0];
    }
    if (i1 < n) {
        b = data[i1];
    }
    // Inclusive Hillis-Steele scan of the pair sums.
    partial[t] = a + b;
    workgroupBarrier();
    for (var offset = 1u; offset < SCAN_WORKGROUP_SIZE; offset *= 2u) {
        var add = 0u;
        if (t >= offset) {
            add = partial[t - offset];
        }
        workgroupBarrier();
        partial[t] += add;
        workgroupBarrier();
    }
    let before = partial[t] - (a + b);
    if (i0 < n) {
        data[i0] = before;
    }
    if (i1 < n) {
        data[i1] = before + a;
    }
    if (t == SCAN_WORKGROUP_SIZE - 1u && block < arrayLength(&block_sums)) {
        block_sums[block] = partial[t];
    }
}

@compute @workgroup_size(SCAN_WORKGROUP_SIZE)
fn add_block_offsets(
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let n = arrayLength(&data);
    let block = group_index(wid, groups);
    let offset = block_sums[block];
    let i0 = block * SCAN_BLOCK + 2u * lid.x;
    if (i0 < n) {
        data[i0] += offset;
    }
    if (i0 + 1u < n) {
        data[i0 + 1u] += offset;
    }
}
