//! Helpers shared by the GPU tests: every test runs on every adapter with compute shaders.

#![allow(dead_code)]

use wgsph::gpu::device::compute_adapters;
use wgsph::gpu::GpuContext;

/// A device on every adapter found. With none, the test is skipped with a visible message,
/// unless WGSPH_REQUIRE_GPU is set (CI sets it, so a missing driver fails there).
pub fn contexts() -> Vec<GpuContext> {
    let list: Vec<GpuContext> =
        compute_adapters().into_iter().map(|a| GpuContext::from_adapter(a).expect("device on a listed adapter")).collect();
    if list.is_empty() {
        if std::env::var_os("WGSPH_REQUIRE_GPU").is_some() {
            panic!("WGSPH_REQUIRE_GPU is set but no GPU adapter with compute shaders was found");
        }
        eprintln!("SKIPPED: no GPU adapter with compute shaders (install mesa-vulkan-drivers for lavapipe)");
    }
    list
}
