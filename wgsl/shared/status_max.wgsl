// A status word that holds a largest key (the step's largest density or speed), raised without
// a workgroup reduction by the stages that reduce over a subgroup instead
// (shared/density_write_tiled.wgsl, sim/integrate_tiled.wgsl). A key only grows, so one at or
// below the word's is not offered: most offers are a plain load, not an atomic write that the
// other cores must wait for. The including stage declares `status`.

fn raise_status_word(word: u32, key: u32) {
    if (key > atomicLoad(&status[word])) {
        atomicMax(&status[word], key);
    }
}
