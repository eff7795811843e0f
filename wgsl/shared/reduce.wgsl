// The largest of one value per invocation over a workgroup, in up to two slots: every
// invocation offers keys that order like the values (a non-negative float's bits do), and one
// invocation per workgroup then passes the workgroup's largest key on (an atomic max into a
// storage word). Used by the density (largest density), the adaptive step (largest speed and
// acceleration) and the renderer's colour range (smallest and largest value).
// Call reduce_begin and reduce_end from every invocation of the workgroup (uniform control flow).

var<workgroup> reduce_slots: array<atomic<u32>, 2>;

fn reduce_begin(lid: u32) {
    if (lid == 0u) {
        atomicStore(&reduce_slots[0], 0u);
        atomicStore(&reduce_slots[1], 0u);
    }
    workgroupBarrier();
}

fn reduce_offer(slot: u32, key: u32) {
    atomicMax(&reduce_slots[slot], key);
}

// After this, reduce_result(slot) is the workgroup's largest key offered to slot.
fn reduce_end() {
    workgroupBarrier();
}

fn reduce_result(slot: u32) -> u32 {
    return atomicLoad(&reduce_slots[slot]);
}
