//! Adapter choice and device creation.
//!
//! `WGPU_BACKEND` (vulkan, metal, dx12, gl) and `WGPU_ADAPTER_NAME` (a case-insensitive part of
//! the name) are honoured as in wgpu's own utilities; otherwise a discrete GPU is preferred.

use anyhow::Context;

/// An adapter, its device and queue (handles: clones share them).
#[derive(Clone)]
pub struct GpuContext {
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    /// Bytes per storage binding of a split array (see [`GpuContext::storage_segment_bytes`]).
    segment_bytes: u64,
    /// The first error the device reported (see [`GpuContext::check_device`]).
    device_error: std::sync::Arc<std::sync::Mutex<Option<String>>>,
}

impl std::fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "GpuContext({})", self.describe())
    }
}

/// The smallest segment a storage array may be split into: the scan of the cell counts needs
/// segments of whole 256-value blocks whose block totals start at 256-byte aligned offsets.
pub const MIN_SEGMENT_BYTES: u64 = 1 << 16;

/// Environment variable that lowers the segment size (to run split storage arrays on a small
/// scene, or to emulate an adapter with smaller bindings).
pub const SEGMENT_BYTES_VAR: &str = "WGSPH_STORAGE_SEGMENT_BYTES";

/// No usable adapter, or one that cannot hold the scene.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error("no GPU adapter with compute shaders was found{0}")]
    NoAdapter(String),
    #[error("adapter '{adapter}' ({backend}): {what} needs {need} but the adapter's {limit} is {have}")]
    Limit { adapter: String, backend: String, what: String, limit: &'static str, need: u64, have: u64 },
    #[error("adapter '{adapter}' ({backend}): subgroup tiles were asked for, but {why}; run without --subgroup-tiles")]
    NoSubgroupTiles { adapter: String, backend: String, why: String },
    /// A neighbour skin asked for where it cannot run (`skin::refusal`).
    #[error("{0}")]
    NoNeighbourSkin(String),
    /// The fused forces and integration asked for where they cannot run (`StepShape::new`).
    #[error("{0}")]
    NoFusion(String),
}

pub fn backends() -> wgpu::Backends {
    wgpu::Backends::from_env().unwrap_or(wgpu::Backends::all())
}

fn instance() -> wgpu::Instance {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    desc.backends = backends();
    wgpu::Instance::new(desc)
}

fn type_rank(t: wgpu::DeviceType) -> u32 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    }
}

fn backend_rank(b: wgpu::Backend) -> u32 {
    match b {
        wgpu::Backend::Vulkan | wgpu::Backend::Metal | wgpu::Backend::Dx12 => 0,
        wgpu::Backend::Gl => 1,
        _ => 2,
    }
}

fn supports_compute(a: &wgpu::Adapter) -> bool {
    a.get_downlevel_capabilities().flags.contains(wgpu::DownlevelFlags::COMPUTE_SHADERS)
}

/// Every adapter of the enabled backends, best first.
pub fn adapters() -> Vec<wgpu::Adapter> {
    best_first(pollster::block_on(instance().enumerate_adapters(backends())))
}

/// Sorts adapters: discrete before integrated before software; native APIs before OpenGL.
pub fn best_first(mut list: Vec<wgpu::Adapter>) -> Vec<wgpu::Adapter> {
    list.sort_by_key(|a| {
        let i = a.get_info();
        (type_rank(i.device_type), backend_rank(i.backend))
    });
    list
}

/// Every adapter with compute shaders, best first (what the tests run on).
pub fn compute_adapters() -> Vec<wgpu::Adapter> {
    adapters().into_iter().filter(supports_compute).collect()
}

/// The adapter a run uses: the best one with compute shaders, filtered by `WGPU_ADAPTER_NAME`.
pub fn choose_adapter() -> Result<wgpu::Adapter, GpuError> {
    choose_from(adapters())
}

/// The adapters a run may use, best first: those with compute shaders whose name matches
/// `WGPU_ADAPTER_NAME` (all of them when it is unset).
pub fn candidate_adapters() -> Vec<wgpu::Adapter> {
    let wanted = wanted_name();
    adapters().into_iter().filter(supports_compute).filter(|a| name_matches(a, wanted.as_deref())).collect()
}

fn wanted_name() -> Option<String> {
    std::env::var("WGPU_ADAPTER_NAME").ok().map(|s| s.to_lowercase())
}

fn name_matches(a: &wgpu::Adapter, wanted: Option<&str>) -> bool {
    wanted.is_none_or(|w| a.get_info().name.to_lowercase().contains(w))
}

/// The best of `all` (sorted best first) with compute shaders, filtered by `WGPU_ADAPTER_NAME`.
pub fn choose_from(all: Vec<wgpu::Adapter>) -> Result<wgpu::Adapter, GpuError> {
    let wanted = wanted_name();
    let names: Vec<String> = all.iter().map(|a| format!("{} ({:?})", a.get_info().name, a.get_info().backend)).collect();
    all.into_iter()
        .filter(supports_compute)
        .find(|a| name_matches(a, wanted.as_deref()))
        .ok_or_else(|| {
            let mut why = String::new();
            if let Some(w) = &wanted {
                why += &format!(" matching WGPU_ADAPTER_NAME='{w}'");
            }
            let asked = std::env::var("WGPU_BACKEND").ok().filter(|b| !b.trim().is_empty());
            if let (true, Some(b)) = (names.is_empty() && backends().is_empty(), &asked) {
                why += &format!(" (WGPU_BACKEND='{b}' names no backend: give vulkan, metal, dx12 or gl, or leave it unset)");
            } else if let (true, Some(b)) = (names.is_empty(), &asked) {
                why += &format!(" (none on the backends WGPU_BACKEND='{b}' allows: leave it unset to try every backend)");
            } else if names.is_empty() {
                why += " (no adapter at all: install a GPU driver, or Mesa's lavapipe/llvmpipe for a software adapter)";
            } else {
                why += &format!(" (adapters found: {})", names.join(", "));
            }
            GpuError::NoAdapter(why)
        })
}

/// The adapter a rank takes among `kinds`, the device types of the adapters it may use (best
/// first), by `node_rank`, its place among the `node_ranks` ranks of its machine: the
/// `node_rank`-th hardware adapter (round robin when the ranks outnumber them), or with no
/// hardware adapter the first, shared. Returns the index in `kinds` and why, in words.
pub fn rank_adapter(kinds: &[wgpu::DeviceType], node_rank: usize, node_ranks: usize) -> Option<(usize, String)> {
    let hardware: Vec<usize> = (0..kinds.len()).filter(|&i| matches!(kinds[i], wgpu::DeviceType::DiscreteGpu | wgpu::DeviceType::IntegratedGpu | wgpu::DeviceType::VirtualGpu)).collect();
    if hardware.is_empty() {
        let shared = if node_ranks > 1 { format!(", shared by the {node_ranks} ranks of this machine") } else { String::new() };
        return (!kinds.is_empty()).then(|| (0, format!("no hardware adapter: the first one{shared}")));
    }
    let k = node_rank % hardware.len();
    let sharing = node_ranks.div_ceil(hardware.len());
    let shared = if sharing > 1 { format!(", shared by up to {sharing} of the {node_ranks} ranks of this machine") } else { String::new() };
    Some((hardware[k], format!("hardware adapter {} of {} for node rank {node_rank}{shared}", k + 1, hardware.len())))
}

/// The first of `candidates` (best first) that `open` opens, or every failure in words.
pub fn first_that_opens<A, C>(candidates: Vec<A>, mut open: impl FnMut(A) -> anyhow::Result<C>) -> Result<C, Vec<String>> {
    let mut failures = Vec::new();
    for candidate in candidates {
        match open(candidate) {
            Ok(opened) => return Ok(opened),
            Err(e) => failures.push(format!("{e:#}")),
        }
    }
    Err(failures)
}

/// Invocations of a neighbour tile (TILE in wgsl/shared/tiles.wgsl).
pub const TILE_LANES: u32 = 8;

impl GpuContext {
    /// Why the neighbour stages cannot walk a subgroup's stencils together on this device
    /// (wgsl/shared/tiles.wgsl), or `None` where they can: that needs subgroup operations, and
    /// subgroups of exactly [`TILE_LANES`] invocations (a software adapter's 8-wide SIMD;
    /// hardware GPUs have 32 or 64 and use the one-particle-per-invocation stages).
    pub fn subgroup_tiles_unavailable(&self) -> Option<String> {
        if !self.device.features().contains(wgpu::Features::SUBGROUP) {
            return Some("the device has no subgroup operations".to_string());
        }
        let (min, max) = (self.info.subgroup_min_size, self.info.subgroup_max_size);
        if (min, max) != (TILE_LANES, TILE_LANES) {
            return Some(format!("its subgroups have {min} to {max} invocations, not exactly {TILE_LANES}"));
        }
        None
    }

    /// Opens the best adapter that can open a device, with all of its limits, so big scenes can
    /// use big buffers. An adapter that is listed with compute shaders but fails to open a device
    /// (a driver that lists an OpenGL context it cannot create, say) is passed over for the next.
    pub fn new() -> anyhow::Result<Self> {
        let candidates = candidate_adapters();
        if candidates.is_empty() {
            // The error that names what was found and why none fits.
            choose_adapter()?;
        }
        first_that_opens(candidates, Self::from_adapter)
            .map_err(|failures| anyhow::anyhow!("no GPU adapter could open a device: {}", failures.join("; ")))
    }

    pub fn from_adapter(adapter: wgpu::Adapter) -> anyhow::Result<Self> {
        let info = adapter.get_info();
        // Subgroups for the neighbour tiles (GpuContext::subgroup_tiles_unavailable).
        let features = adapter.features() & (wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::SUBGROUP);
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("wgsph"),
            required_features: features,
            required_limits: adapter.limits(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .with_context(|| format!("cannot open a device on adapter '{}' ({:?})", info.name, info.backend))?;
        Self::from_device(adapter, device, queue)
    }

    /// A context of a device the caller opened itself on `adapter` (for example the one it
    /// renders with). The device should have the adapter's storage-buffer limits for large
    /// scenes. `WGSPH_STORAGE_SEGMENT_BYTES` is honoured as in [`GpuContext::new`].
    pub fn from_device(adapter: wgpu::Adapter, device: wgpu::Device, queue: wgpu::Queue) -> anyhow::Result<Self> {
        let info = adapter.get_info();
        let natural = Self::natural_segment_bytes(&device.limits());
        // wgpu's default handler panics on an error it reports later than the call (a shader a
        // driver rejects, a buffer the device has no memory for): kept instead, and turned into
        // an error where the work is next checked (GpuContext::check_device).
        let device_error = std::sync::Arc::new(std::sync::Mutex::new(None::<String>));
        let kept = device_error.clone();
        device.on_uncaptured_error(std::sync::Arc::new(move |e: wgpu::Error| {
            let mut first = kept.lock().unwrap_or_else(|p| p.into_inner());
            if first.is_none() {
                *first = Some(e.to_string());
            }
        }));
        let ctx = GpuContext { adapter, device, queue, info, segment_bytes: natural, device_error };
        match std::env::var(SEGMENT_BYTES_VAR) {
            Ok(v) => {
                let bytes = v.trim().parse::<u64>().map_err(|_| {
                    anyhow::anyhow!("{SEGMENT_BYTES_VAR}='{v}' is not a number of bytes; allowed: a power of two from {MIN_SEGMENT_BYTES} to {natural}")
                })?;
                ctx.with_storage_segment_bytes(bytes).with_context(|| format!("{SEGMENT_BYTES_VAR}='{v}'"))
            }
            Err(_) => Ok(ctx),
        }
    }

    /// An error if the device reported one since it was opened (the first, with the adapter's
    /// name): its buffers and results can no longer be trusted. Checked after a solver is built,
    /// after every readback and after every picture drawn.
    pub fn check_device(&self) -> anyhow::Result<()> {
        let first = self.device_error.lock().unwrap_or_else(|p| p.into_inner()).clone();
        match first {
            Some(e) => Err(anyhow::anyhow!("the GPU device on {} reported an error: {}", self.describe(), e.trim())),
            None => Ok(()),
        }
    }

    /// The largest power of two that one storage binding and one buffer may hold.
    fn natural_segment_bytes(l: &wgpu::Limits) -> u64 {
        let most = (l.max_storage_buffer_binding_size as u64).min(l.max_buffer_size);
        1u64 << (63 - most.max(1).leading_zeros())
    }

    /// Bytes of one storage binding of an array split into segments: the largest power of two
    /// within the adapter's `max_storage_buffer_binding_size`, unless lowered. Arrays longer than
    /// one segment are bound as several ranges of one buffer (src/solver/gpu/shaders.rs), so the
    /// binding limit never bounds the particle count; `max_buffer_size` and memory still do.
    pub fn storage_segment_bytes(&self) -> u64 {
        self.segment_bytes
    }

    /// The same device with storage arrays split into segments of `bytes` (a power of two from
    /// [`MIN_SEGMENT_BYTES`] up to the adapter's own segment size): a small scene then runs the
    /// split-array path that only big scenes need otherwise.
    pub fn with_storage_segment_bytes(mut self, bytes: u64) -> anyhow::Result<Self> {
        let natural = Self::natural_segment_bytes(&self.device.limits());
        let align = self.device.limits().min_storage_buffer_offset_alignment as u64;
        anyhow::ensure!(
            bytes.is_power_of_two() && (MIN_SEGMENT_BYTES..=natural).contains(&bytes) && bytes % align == 0,
            "storage segment of {bytes} bytes: allowed is a power of two from {MIN_SEGMENT_BYTES} to {natural} (the adapter's largest) bytes"
        );
        self.segment_bytes = bytes;
        Ok(self)
    }

    pub fn describe(&self) -> String {
        format!("{} ({:?}, {:?})", self.info.name, self.info.backend, self.info.device_type)
    }

    /// The driver and its version as the adapter reports them ("llvmpipe Mesa 25.0.7 (LLVM
    /// 15.0.6)", "NVIDIA 580.159.04"); empty where it reports none. Two drivers of one adapter
    /// share its name, and a timing or a bit-for-bit result belongs to the driver too.
    pub fn driver(&self) -> String {
        format!("{} {}", self.info.driver, self.info.driver_info).trim().to_string()
    }
}

/// One line per adapter with the limits that matter for big scenes (`wgsph adapters`).
pub fn describe_adapters() -> Vec<String> {
    adapters()
        .iter()
        .map(|a| {
            let i = a.get_info();
            let l = a.limits();
            // Opening a device is the only sure test: some drivers list adapters they cannot open.
            let opens = if !supports_compute(a) {
                "-".to_string()
            } else {
                match GpuContext::from_adapter(a.clone()) {
                    Ok(_) => "yes".to_string(),
                    Err(e) => format!("no ({e:#}; passed over)"),
                }
            };
            format!(
                "{} | backend {:?} | type {:?} | driver {} {} | compute {} | opens a device {opens} | max_storage_buffer_binding_size {} MiB | max_buffer_size {} MiB | storage buffers per stage {} | workgroups per dimension {} | timestamps {} | subgroups {}",
                i.name,
                i.backend,
                i.device_type,
                i.driver,
                i.driver_info,
                if supports_compute(a) { "yes" } else { "no" },
                l.max_storage_buffer_binding_size as u64 >> 20,
                l.max_buffer_size >> 20,
                l.max_storage_buffers_per_shader_stage,
                l.max_compute_workgroups_per_dimension,
                if a.features().contains(wgpu::Features::TIMESTAMP_QUERY) { "yes" } else { "no" },
                if !a.features().contains(wgpu::Features::SUBGROUP) {
                    "no".to_string()
                } else if i.subgroup_min_size == i.subgroup_max_size {
                    format!("{} invocations", i.subgroup_min_size)
                } else {
                    format!("{} to {} invocations", i.subgroup_min_size, i.subgroup_max_size)
                },
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::{first_that_opens, rank_adapter};
    use wgpu::DeviceType::{Cpu, DiscreteGpu, IntegratedGpu};

    #[test]
    fn a_rank_takes_the_hardware_adapter_of_its_place_on_its_machine() {
        // Two GPUs listed after a software adapter: node ranks 0..4 go round the two GPUs.
        let kinds = [Cpu, DiscreteGpu, IntegratedGpu];
        let picked: Vec<usize> = (0..4).map(|r| rank_adapter(&kinds, r, 4).expect("an adapter").0).collect();
        assert_eq!(picked, [1, 2, 1, 2]);
        let (_, why) = rank_adapter(&kinds, 3, 4).expect("an adapter");
        assert!(why.contains("hardware adapter 2 of 2") && why.contains("shared by up to 2 of the 4 ranks"), "{why}");
        // One GPU per rank: no sharing said.
        let (index, why) = rank_adapter(&kinds, 1, 2).expect("an adapter");
        assert!(index == 2 && !why.contains("shared"), "{index} {why}");
    }

    #[test]
    fn with_only_software_adapters_every_rank_shares_the_first() {
        let kinds = [Cpu, Cpu];
        for rank in 0..3 {
            let (index, why) = rank_adapter(&kinds, rank, 3).expect("an adapter");
            assert!(index == 0 && why.contains("no hardware adapter") && why.contains("shared by the 3 ranks"), "{why}");
        }
        assert!(rank_adapter(&[], 0, 1).is_none(), "no adapter at all: none chosen");
    }

    #[test]
    fn an_adapter_that_cannot_open_a_device_is_passed_over() {
        let open = |name: &str| if name.starts_with("gl") { Err(anyhow::anyhow!("{name}: parent device is lost")) } else { Ok(name.to_string()) };
        assert_eq!(first_that_opens(vec!["gl-nvidia", "vulkan-nvidia", "vulkan-llvmpipe"], open), Ok("vulkan-nvidia".to_string()));
        assert_eq!(
            first_that_opens(vec!["gl-a", "gl-b"], open),
            Err(vec!["gl-a: parent device is lost".to_string(), "gl-b: parent device is lost".to_string()])
        );
        assert_eq!(first_that_opens(Vec::<&str>::new(), open), Err(vec![]));
    }
}
