//! The GPU executor: wgpu compute kernels from `shaders/`, each checked against its CPU twin
//! in [`crate::exec::cpu`] (see `docs/gpu.md`).
//!
//! Only the binary and the test harness create a [`GpuContext`]; kernels take the context (its
//! `device` and `queue`). Arrays larger than one storage binding (lavapipe: 128 MiB) are split
//! into chunks, each uploaded into its own buffers.
//!
//! Every upload, read-back, dispatch and submit goes through the context's helpers
//! (`GpuContext::storage`, `write`, `map_read`, `dispatch`, `submit`), which count it in
//! [`GpuTraffic`]: the report's `gpu_traffic` is measured, not derived from sizes.
//!
//! Environment: `VK_DRIVER_FILES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json` restricts Vulkan
//! to Mesa's software driver (lavapipe); `XDG_RUNTIME_DIR=/tmp` silences a harmless Mesa
//! warning when the variable is unset. Without any Vulkan driver, adapter selection fails
//! within milliseconds with [`GpuError::NoAdapter`].

pub mod assemble;
pub mod cg;
pub mod evaluate;
pub mod executor;
pub mod jacobian_check;
pub mod local_newton;
pub mod reflect;

use crate::math::BezierNet;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use wgpu::util::DeviceExt;

/// Floating-point type of the kernels (`--precision`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Precision {
    /// f32 everywhere (portable); accuracy from element-anchored coordinates and displacement
    /// unknowns with f64 residuals on the CPU.
    F32,
    /// f64 (needs `SHADER_F64`; lavapipe has it, Metal has not).
    F64,
}

impl Precision {
    /// Bytes per scalar.
    pub fn size(self) -> usize {
        match self {
            Precision::F32 => 4,
            Precision::F64 => 8,
        }
    }
    /// Machine epsilon of the scalar type.
    pub fn epsilon(self) -> f64 {
        match self {
            Precision::F32 => f32::EPSILON as f64,
            Precision::F64 => f64::EPSILON,
        }
    }
}

/// Which adapters may be used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AdapterChoice {
    /// Only hardware GPUs (integrated, discrete, virtual); a CPU-type adapter such as lavapipe
    /// is slower than the CPU path and is refused.
    HardwareOnly,
    /// Any adapter, hardware preferred.
    Any,
}

/// Everything the GPU path can fail with that a user can cause.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter found ({0}); install a Vulkan driver (e.g. `apt-get install mesa-vulkan-drivers` for the lavapipe software driver) or use --backend cpu"
    )]
    NoAdapter(String),
    #[error(
        "no hardware GPU adapter found (only the CPU-type adapter \"{0}\"; use --backend gpu to use it)"
    )]
    OnlySoftwareAdapter(String),
    #[error(
        "the GPU adapter \"{0}\" has no 64-bit float support (SHADER_F64); use --precision f32"
    )]
    NoF64(String),
    #[error("requesting the GPU device failed: {0}")]
    Device(String),
    #[error("reading back a GPU buffer failed: {0}")]
    Readback(String),
    #[error("the problem is too large for the GPU path: {0}")]
    TooLarge(String),
}

/// Name and type of the adapter in use, for reports.
#[deny(missing_docs)]
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct AdapterReport {
    /// Adapter name as the driver reports it.
    pub name: String,
    /// wgpu's device type (`DiscreteGpu`, `IntegratedGpu`, `VirtualGpu`, `Cpu`, `Other`).
    pub device_type: String,
    /// Driver name and version.
    pub driver: String,
}

/// A device and queue, with what the kernels need to know about them.
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter: AdapterReport,
    pub limits: wgpu::Limits,
    /// Whether SHADER_F64 was enabled.
    pub has_f64: bool,
    /// Kernel precision.
    pub precision: Precision,
    /// Compiled pipelines by entry point (compiling is slow on lavapipe).
    pipelines: std::sync::Mutex<std::collections::HashMap<String, wgpu::ComputePipeline>>,
    /// What the kernels moved and issued so far ([`GpuContext::traffic`]).
    counters: Counters,
}

/// What went between host and device and through device memory, counted by the context's
/// helpers (see the module docs); a stage's share is the difference of two snapshots
/// ([`GpuContext::traffic`]).
#[deny(missing_docs)]
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct GpuTraffic {
    /// Bytes copied from the host into device buffers (buffer contents at creation, uniform
    /// blocks, queue writes).
    pub uploaded_bytes: u64,
    /// Bytes copied from device buffers back to the host (mapped read-backs).
    pub downloaded_bytes: u64,
    /// Bytes of the buffers bound to each dispatch, summed over the dispatches: the
    /// device-memory traffic of kernels that stream each bound buffer once (an upper bound
    /// for the reductions' scalar buffers, a lower one for the SpMV's gathered vector).
    pub device_bytes: u64,
    /// Compute dispatches encoded.
    pub dispatches: u64,
    /// Command buffers submitted to the queue.
    pub submits: u64,
    /// Times the host waited for the device to finish (one per read-back).
    pub readbacks: u64,
    /// Seconds the host spent waiting for the device in those read-backs: on a software
    /// adapter the kernels' own time, on a hardware GPU mostly the kernels' and the copies'.
    pub wait_seconds: f64,
}

impl std::ops::Sub for GpuTraffic {
    type Output = GpuTraffic;
    fn sub(self, o: GpuTraffic) -> GpuTraffic {
        GpuTraffic {
            uploaded_bytes: self.uploaded_bytes - o.uploaded_bytes,
            downloaded_bytes: self.downloaded_bytes - o.downloaded_bytes,
            device_bytes: self.device_bytes - o.device_bytes,
            dispatches: self.dispatches - o.dispatches,
            submits: self.submits - o.submits,
            readbacks: self.readbacks - o.readbacks,
            wait_seconds: self.wait_seconds - o.wait_seconds,
        }
    }
}

impl std::ops::AddAssign for GpuTraffic {
    fn add_assign(&mut self, o: GpuTraffic) {
        self.uploaded_bytes += o.uploaded_bytes;
        self.downloaded_bytes += o.downloaded_bytes;
        self.device_bytes += o.device_bytes;
        self.dispatches += o.dispatches;
        self.submits += o.submits;
        self.readbacks += o.readbacks;
        self.wait_seconds += o.wait_seconds;
    }
}

/// The running totals behind [`GpuTraffic`] (relaxed atomics: the kernels are called from one
/// thread at a time, and a snapshot is taken between stages).
#[derive(Default)]
struct Counters {
    uploaded: AtomicU64,
    downloaded: AtomicU64,
    device: AtomicU64,
    dispatches: AtomicU64,
    submits: AtomicU64,
    readbacks: AtomicU64,
    wait_nanos: AtomicU64,
}

/// A bind group with the bytes of the buffers bound in it (counted per dispatch).
pub(crate) struct Bound {
    group: wgpu::BindGroup,
    bytes: u64,
}

impl std::fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuContext")
            .field("adapter", &self.adapter)
            .field("precision", &self.precision)
            .finish()
    }
}

fn is_hardware(t: wgpu::DeviceType) -> bool {
    matches!(
        t,
        wgpu::DeviceType::DiscreteGpu
            | wgpu::DeviceType::IntegratedGpu
            | wgpu::DeviceType::VirtualGpu
    )
}

impl GpuContext {
    /// Pick an adapter (hardware first; a CPU-type adapter only with [`AdapterChoice::Any`])
    /// and create a device with the adapter's own limits. `precision` None means f64 when the
    /// adapter has it, else f32.
    pub fn new(
        choice: AdapterChoice,
        precision: Option<Precision>,
    ) -> Result<GpuContext, GpuError> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        desc.backends = wgpu::Backends::VULKAN;
        let instance = wgpu::Instance::new(desc);
        let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::VULKAN));
        let rank = |a: &wgpu::Adapter| match a.get_info().device_type {
            wgpu::DeviceType::DiscreteGpu => 0,
            wgpu::DeviceType::IntegratedGpu => 1,
            wgpu::DeviceType::VirtualGpu => 2,
            wgpu::DeviceType::Cpu => 3,
            wgpu::DeviceType::Other => 4,
        };
        let Some(adapter) = adapters.into_iter().min_by_key(rank) else {
            return Err(GpuError::NoAdapter("no Vulkan adapter".into()));
        };
        let info = adapter.get_info();
        if choice == AdapterChoice::HardwareOnly && !is_hardware(info.device_type) {
            return Err(GpuError::OnlySoftwareAdapter(info.name));
        }
        let features = adapter.features();
        let has_f64 = features.contains(wgpu::Features::SHADER_F64);
        let precision = match precision {
            Some(Precision::F64) if !has_f64 => return Err(GpuError::NoF64(info.name)),
            Some(p) => p,
            None if has_f64 => Precision::F64,
            None => Precision::F32,
        };
        let required_features = if has_f64 {
            wgpu::Features::SHADER_F64
        } else {
            wgpu::Features::empty()
        };
        // wgpu's defaults are WebGPU's (8 storage buffers, 256 MiB buffers); ask for what the
        // adapter offers.
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("polyspline"),
            required_features,
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device(e.to_string()))?;
        Ok(GpuContext {
            device,
            queue,
            adapter: AdapterReport {
                name: info.name,
                device_type: format!("{:?}", info.device_type),
                driver: format!("{} {}", info.driver, info.driver_info)
                    .trim()
                    .to_string(),
            },
            limits,
            has_f64,
            precision,
            pipelines: Default::default(),
            counters: Default::default(),
        })
    }

    /// What the kernels moved and issued since the context was made.
    pub fn traffic(&self) -> GpuTraffic {
        let c = &self.counters;
        GpuTraffic {
            uploaded_bytes: c.uploaded.load(Relaxed),
            downloaded_bytes: c.downloaded.load(Relaxed),
            device_bytes: c.device.load(Relaxed),
            dispatches: c.dispatches.load(Relaxed),
            submits: c.submits.load(Relaxed),
            readbacks: c.readbacks.load(Relaxed),
            wait_seconds: c.wait_nanos.load(Relaxed) as f64 * 1e-9,
        }
    }

    /// Copy `data` into `buffer` from offset 0 (counted as uploaded).
    pub(crate) fn write(&self, buffer: &wgpu::Buffer, data: &[u8]) {
        self.counters.uploaded.fetch_add(data.len() as u64, Relaxed);
        self.queue.write_buffer(buffer, 0, data);
    }

    /// Submit the commands of `enc` (counted).
    pub(crate) fn submit(&self, enc: wgpu::CommandEncoder) {
        self.counters.submits.fetch_add(1, Relaxed);
        self.queue.submit([enc.finish()]);
    }

    /// Encode `pipeline` on `bound` over `workgroups` workgroups into `pass` (counted, with
    /// the bound buffers' bytes).
    pub(crate) fn dispatch(
        &self,
        pass: &mut wgpu::ComputePass<'_>,
        pipeline: &wgpu::ComputePipeline,
        bound: &Bound,
        workgroups: u32,
    ) {
        self.counters.dispatches.fetch_add(1, Relaxed);
        self.counters.device.fetch_add(bound.bytes, Relaxed);
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &bound.group, &[]);
        pass.dispatch_workgroups(workgroups, 1, 1);
    }

    /// Largest storage binding in bytes (lavapipe: 128 MiB).
    pub fn max_binding(&self) -> u64 {
        self.limits
            .max_storage_buffer_binding_size
            .min(self.limits.max_buffer_size)
    }

    /// Largest number of workgroups in one dispatch dimension.
    pub fn max_workgroups(&self) -> u32 {
        self.limits.max_compute_workgroups_per_dimension
    }

    /// A compute pipeline for `entry` of a shader, at the context's precision.
    pub(crate) fn pipeline(&self, source: &str, entry: &str) -> wgpu::ComputePipeline {
        let mut cache = self.pipelines.lock().unwrap_or_else(|e| e.into_inner());
        cache
            .entry(entry.to_string())
            .or_insert_with(|| self.compile(source, entry))
            .clone()
    }

    fn compile(&self, source: &str, entry: &str) -> wgpu::ComputePipeline {
        let module = self
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(entry),
                source: wgpu::ShaderSource::Wgsl(shader_source(source, self.precision).into()),
            });
        self.device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: None,
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
    }

    /// A storage buffer holding `data` (at least 16 bytes, so empty arrays bind too).
    pub(crate) fn storage(&self, label: &str, data: &[u8], writable: bool) -> wgpu::Buffer {
        let mut usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        if writable {
            usage |= wgpu::BufferUsages::COPY_SRC;
        }
        self.counters
            .uploaded
            .fetch_add(data.len().max(16) as u64, Relaxed);
        if data.len() < 16 {
            let mut padded = data.to_vec();
            padded.resize(16, 0);
            return self
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents: &padded,
                    usage,
                });
        }
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: data,
                usage,
            })
    }

    /// A zeroed storage buffer of `bytes` (read-write, copyable).
    pub(crate) fn storage_zeroed(&self, label: &str, bytes: u64) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes.max(16).next_multiple_of(4),
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// A uniform buffer holding a `Pod` value.
    pub(crate) fn uniform<T: bytemuck::Pod>(&self, label: &str, value: &T) -> wgpu::Buffer {
        self.counters
            .uploaded
            .fetch_add(std::mem::size_of::<T>() as u64, Relaxed);
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytemuck::bytes_of(value),
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            })
    }

    /// A bind group for group 0 of `pipeline` with whole-buffer bindings in binding order.
    pub(crate) fn bind(
        &self,
        pipeline: &wgpu::ComputePipeline,
        buffers: &[(u32, &wgpu::Buffer)],
    ) -> Bound {
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .map(|&(binding, b)| wgpu::BindGroupEntry {
                binding,
                resource: b.as_entire_binding(),
            })
            .collect();
        Bound {
            group: self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &pipeline.get_bind_group_layout(0),
                entries: &entries,
            }),
            bytes: buffers.iter().map(|(_, b)| b.size()).sum(),
        }
    }

    /// Bind `buffers` (binding, buffer) to `pipeline` and run it once over `n` invocations in
    /// workgroups of [`ITEM_WORKGROUP`].
    pub(crate) fn run_once(
        &self,
        pipeline: &wgpu::ComputePipeline,
        buffers: &[(u32, &wgpu::Buffer)],
        n: usize,
    ) {
        let bind = self.bind(pipeline, buffers);
        let mut enc = self.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            self.dispatch(&mut pass, pipeline, &bind, groups(n, ITEM_WORKGROUP));
        }
        self.submit(enc);
    }

    /// Copy `bytes` bytes of `src` (from offset 0) back to the host.
    pub(crate) fn read_back(&self, src: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>, GpuError> {
        let bytes = bytes.next_multiple_of(4).max(4);
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(src, 0, &staging, 0, bytes);
        self.submit(enc);
        self.map_read(&staging)
    }

    /// Map a MAP_READ buffer after the last submit, copy it out, unmap (counted as a
    /// read-back of the buffer's bytes, with the time waited for the device).
    pub(crate) fn map_read(&self, staging: &wgpu::Buffer) -> Result<Vec<u8>, GpuError> {
        let waiting = std::time::Instant::now();
        let (tx, rx) = std::sync::mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        rx.recv()
            .map_err(|e| GpuError::Readback(e.to_string()))?
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        let out = staging
            .get_mapped_range(..)
            .map_err(|e| GpuError::Readback(e.to_string()))?
            .to_vec();
        staging.unmap();
        let c = &self.counters;
        c.readbacks.fetch_add(1, Relaxed);
        c.downloaded.fetch_add(out.len() as u64, Relaxed);
        c.wait_nanos
            .fetch_add(waiting.elapsed().as_nanos() as u64, Relaxed);
        Ok(out)
    }
}

/// Which executor runs the heavy stages (sampling, certification, the CG solve).
#[derive(Clone, Debug, Default)]
pub enum Backend {
    /// The CPU reference path.
    #[default]
    Cpu,
    /// WGSL kernels on this device.
    Gpu(std::sync::Arc<GpuContext>),
}

/// The executor a caller asks for (`--backend`), resolved into a [`Backend`] by
/// [`BackendChoice::resolve`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BackendChoice {
    /// A hardware GPU when there is one, the CPU otherwise (never a software adapter).
    Auto,
    /// The CPU reference path.
    Cpu,
    /// Any GPU adapter, a software one such as lavapipe included; an error without one.
    Gpu,
}

impl BackendChoice {
    /// The executor: `gpu` fails without an adapter; `auto` falls back to the CPU unless a
    /// hardware GPU is present. `precision` None means f64 where the adapter has it.
    pub fn resolve(self, precision: Option<Precision>) -> Result<Backend, GpuError> {
        Ok(match self {
            BackendChoice::Cpu => Backend::Cpu,
            BackendChoice::Gpu => {
                Backend::Gpu(GpuContext::new(AdapterChoice::Any, precision)?.into())
            }
            // Loading the Vulkan drivers costs 0.1-0.3 s (lavapipe initialises LLVM), a large
            // share of a small mesh's job: not paid where no GPU device node exists.
            BackendChoice::Auto if !may_hold_a_gpu(std::path::Path::new("/dev")) => Backend::Cpu,
            BackendChoice::Auto => match GpuContext::new(AdapterChoice::HardwareOnly, precision) {
                Ok(ctx) => Backend::Gpu(ctx.into()),
                Err(_) => Backend::Cpu,
            },
        })
    }
}

/// Whether the device directory `dev` has a node a hardware GPU's Vulkan driver opens: on
/// Linux, DRM nodes (`dri/`: AMD, Intel, virtio and other Mesa drivers), NVIDIA's proprietary
/// `nvidiactl`, or WSL's `dxg`. Without any of them no hardware adapter can appear. Elsewhere
/// the drivers are always asked.
fn may_hold_a_gpu(dev: &std::path::Path) -> bool {
    !cfg!(target_os = "linux")
        || ["dri", "nvidiactl", "dxg"]
            .iter()
            .any(|node| dev.join(node).exists())
}

impl Backend {
    pub fn name(&self) -> &'static str {
        match self {
            Backend::Cpu => "cpu",
            Backend::Gpu(_) => "gpu",
        }
    }
    pub fn gpu(&self) -> Option<&GpuContext> {
        match self {
            Backend::Cpu => None,
            Backend::Gpu(c) => Some(c),
        }
    }
    /// What the device's kernels moved and issued so far ([`GpuContext::traffic`]); `None` on
    /// the CPU.
    pub fn traffic(&self) -> Option<GpuTraffic> {
        self.gpu().map(GpuContext::traffic)
    }
}

/// Shader source at a precision: every shader declares `alias real = f32;`, replaced by f64.
pub fn shader_source(source: &str, precision: Precision) -> String {
    match precision {
        Precision::F32 => source.to_string(),
        Precision::F64 => source.replace("alias real = f32;", "alias real = f64;"),
    }
}

/// The WGSL sources by file name, for validation.
pub const SHADERS: [(&str, &str); 8] = [
    ("assemble.wgsl", assemble::SOURCE),
    ("coupling.wgsl", cg::COUPLING_SOURCE),
    ("evaluate.wgsl", evaluate::SOURCE),
    ("jacobian_check.wgsl", jacobian_check::SOURCE),
    ("spmv.wgsl", cg::SPMV_SOURCE),
    ("dot.wgsl", cg::DOT_SOURCE),
    ("cg.wgsl", cg::CG_SOURCE),
    ("local_newton.wgsl", local_newton::SOURCE),
];

/// Scalars of the context's precision as bytes.
pub(crate) fn reals_to_bytes(p: Precision, v: impl Iterator<Item = f64>) -> Vec<u8> {
    match p {
        Precision::F32 => v.flat_map(|x| (x as f32).to_le_bytes()).collect(),
        Precision::F64 => v.flat_map(|x| x.to_le_bytes()).collect(),
    }
}

/// Bytes of scalars of the context's precision as f64.
pub(crate) fn bytes_to_reals(p: Precision, b: &[u8]) -> Vec<f64> {
    match p {
        Precision::F32 => b
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()) as f64)
            .collect(),
        Precision::F64 => b
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect(),
    }
}

/// Invocations per workgroup of the per-item kernels, as the shaders declare it (checked at
/// compile time by [`reflect`]).
pub(crate) const ITEM_WORKGROUP: usize = reflect::ITEM_WORKGROUP as usize;

/// Workgroups to cover `n` items with groups of `size`.
pub(crate) fn groups(n: usize, size: usize) -> u32 {
    n.div_ceil(size) as u32
}

/// Anchor of a Bézier net: its centre control point (index 4 in 2D, 13 in 3D). Kernels see
/// net − anchor, so f32 rounding scales with the element's size, not with its coordinates.
pub fn anchor(dim: usize, net: &BezierNet) -> [f64; 3] {
    net[if dim == 2 { 4 } else { 13 }]
}

#[cfg(test)]
mod tests {
    use super::may_hold_a_gpu;

    #[test]
    #[cfg(target_os = "linux")]
    fn gpu_device_nodes_decide_whether_drivers_are_asked() {
        let dev = tempfile::tempdir().unwrap();
        assert!(!may_hold_a_gpu(dev.path()), "no device node");
        for node in ["dri", "nvidiactl", "dxg"] {
            let dev = tempfile::tempdir().unwrap();
            std::fs::create_dir(dev.path().join(node)).unwrap();
            assert!(may_hold_a_gpu(dev.path()), "{node}");
        }
    }
}
