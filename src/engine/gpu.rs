//! GPU sweep engine: WGSL compute shaders (wgpu, Vulkan) that generate monomial values on the fly.
//!
//! # What runs where
//! * [`GpuEngine::new`] picks a Vulkan adapter, requests a device with the adapter's own limits,
//!   plans the work (below), checks the memory it will need (refusing with the numbers), and
//!   uploads Z (as f32, sample-major) and the factor codes of every candidate once.
//! * [`SweepEngine::sweep`] uploads v (f32), runs `shaders/sweep.wgsl` (MODE 0) and
//!   `shaders/finalize.wgsl` over every candidate window, and reads back one (hi, lo) f32 pair per
//!   candidate, which the host adds in f64.
//! * [`SweepEngine::column_stats`] is two passes: a sweep with the weights gives the means; then
//!   `sweep.wgsl` in MODE 1 sums `w (x - mean32)^2` around the f32-rounded mean, and the host
//!   removes the (exact) bias of that rounded centre: `sum w (x-m)^2 = sum w (x-m32)^2 - W (m32-m)^2`.
//!   Centring on the GPU is what keeps the norm when the mean is large; a one-pass
//!   `sum w x^2 - W m^2` in f32 would cancel it away.
//! * [`SweepEngine::columns`] is computed on the host, exactly, from the f64 features (a few
//!   columns per LARS step; cheaper than a round trip and bit-identical to `Code::eval`).
//!
//! # Factor tables (why a sweep costs a few loads per pair, not d)
//! Every candidate is written as a product of at most NF "factors": monomials of degree <= FD
//! (FD = 1..3 chosen per problem), its sorted variables cut into groups of FD from the front.
//! For the samples in flight, a workgroup tabulates all C(n_z + FD, FD) factors in workgroup
//! memory; a pair then costs NF loads and NF multiplies whatever its degree. See the header of
//! `shaders/sweep.wgsl` for the memory layout.
//!
//! # Limits and tiling
//! Work is a grid of (candidate tile of WG*R, sample block) workgroups. Candidates are cut into
//! windows so that every binding stays within `max_storage_buffer_binding_size`, every dispatch
//! within `max_compute_workgroups_per_dimension`, and no dispatch exceeds a bounded number of
//! sample-candidate pairs (GPU watchdogs kill long dispatches). Each window is its own command
//! buffer. Sums over a block are Kahan-compensated f32 (the compensation is kept from the
//! compiler's float algebra by `opaque` in the shaders); blocks are reduced by the finalize shader.
//!
//! # Errors
//! wgpu's default error handler panics; this engine installs one that records, wraps device work
//! in validation and out-of-memory error scopes, records device loss, and turns all of these into
//! [`Error::Gpu`]. No adapter is [`Error::NoGpu`]. The caller decides about falling back (see
//! [`crate::engine::select`]); this engine never falls back silently.

use std::collections::HashMap;
use std::sync::{mpsc, Arc, Mutex, OnceLock};
use std::time::Duration;

use wgpu::util::DeviceExt as _;

use crate::basis::{count, Basis, Code};
use crate::engine::{ColumnStats, Features, SweepEngine};
use crate::error::{Error, Result};

mod shader;

/// Invocations per workgroup of the finalize shader.
const FINALIZE_WG: u32 = 64;

/// The shape of the sweep kernel. The defaults are the measured best (docs/gpu.md, "Kernel
/// shapes"); the other shapes exist to measure them (`benches/gpu_report.sh --shapes`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KernelShape {
    /// Invocations per workgroup: a multiple of 32 (every warp and wave size divides it); the
    /// plan lowers it to the adapter's limit (a multiple of 32 below it).
    pub workgroup: u32,
    /// Candidates per invocation (R), 1 to 32: each sample's weight and table row are loaded
    /// once for R candidates.
    pub per_invocation: u32,
    /// Largest degree of the factors tabulated in workgroup memory, 1 to 3 (the plan may choose
    /// less): a higher degree means fewer loads per pair and a larger table per workgroup.
    pub max_factor_degree: usize,
    /// Per-candidate state written out as scalars in the shader text (true) or as arrays that
    /// the driver must unroll to keep in registers (false).
    pub scalar_code: bool,
    /// Most samples staged in workgroup memory per round (fewer when the table does not fit):
    /// each round costs a few barriers.
    pub max_chunk: usize,
}

impl Default for KernelShape {
    fn default() -> Self {
        // Measured on an H200 (docs/gpu.md, "Kernel shapes"): large workgroups share one
        // factor table among many warps, and degree-2 tables (small) leave room for more
        // workgroups per multiprocessor; within 17 % of the best of 13 shapes at every size.
        KernelShape {
            workgroup: 1024,
            per_invocation: 2,
            max_factor_degree: 2,
            scalar_code: true,
            max_chunk: 32,
        }
    }
}

impl KernelShape {
    /// Candidates per workgroup tile.
    fn tile(&self) -> usize {
        (self.workgroup * self.per_invocation) as usize
    }

    /// The shape checked, with its workgroup lowered to what the adapter allows.
    fn fitted(&self, limits: &wgpu::Limits) -> Result<KernelShape> {
        let max_wg = limits
            .max_compute_invocations_per_workgroup
            .min(limits.max_compute_workgroup_size_x);
        if self.workgroup == 0 || !self.workgroup.is_multiple_of(32) || max_wg < 32 {
            return Err(Error::param(
                "workgroup",
                format!(
                    "{} invocations: must be a multiple of 32 (the adapter allows {max_wg})",
                    self.workgroup
                ),
            ));
        }
        if !(1..=32).contains(&self.per_invocation)
            || !(1..=3).contains(&self.max_factor_degree)
            || !(4..=1024).contains(&self.max_chunk)
        {
            return Err(Error::param(
                "kernel shape",
                format!(
                    "{} candidates per invocation (1 to 32), factor degree {} (1 to 3), chunk {} (4 to 1024)",
                    self.per_invocation, self.max_factor_degree, self.max_chunk
                ),
            ));
        }
        Ok(KernelShape {
            workgroup: self.workgroup.min(max_wg / 32 * 32),
            ..*self
        })
    }
}

/// Settings of the GPU engine; the defaults suit real use, the `max_*` fields exist so tests can
/// force several windows and blocks on tiny problems.
#[derive(Debug, Clone)]
pub struct GpuOptions {
    /// Accept a CPU (software) adapter such as lavapipe. `--engine gpu` allows it; `auto` never
    /// gets here with one (see [`crate::engine::select`]).
    pub allow_cpu_adapter: bool,
    /// Upper bound on candidates per window (rounded down to a multiple of the kernel's tile, [`KernelShape`] workgroup x per invocation).
    pub max_window_candidates: Option<usize>,
    /// Upper bound on samples per block (the span of one Kahan-compensated f32 sum).
    pub max_block_samples: usize,
    /// Upper bound on sample-candidate pairs per dispatch (watchdog safety).
    pub max_pairs_per_dispatch: u64,
    /// Refuse problems whose device buffers would exceed this many bytes.
    pub memory_budget_bytes: u64,
    /// How long to wait for one submission before calling the device hung.
    pub timeout: Duration,
    /// Keep wgpu's bounds checks in the shaders (default). Off only to measure what they cost.
    pub bounds_checks: bool,
    /// Lower bound on samples per block; tests use it to force long compensated sums on
    /// adapters whose layout would otherwise cut the samples into short blocks.
    pub min_block_samples: usize,
    /// The sweep kernel's shape (see [`KernelShape`]).
    pub kernel: KernelShape,
    /// Open a device for this engine alone instead of sharing the process's (tests that destroy
    /// their device use it).
    pub private_device: bool,
}

impl Default for GpuOptions {
    fn default() -> Self {
        GpuOptions {
            allow_cpu_adapter: true,
            max_window_candidates: None,
            max_block_samples: 2048,
            // About 2 ms on an H100 at the design rate; far below any watchdog.
            max_pairs_per_dispatch: 4_000_000_000,
            memory_budget_bytes: 4 << 30,
            timeout: Duration::from_secs(300),
            bounds_checks: true,
            min_block_samples: 0,
            kernel: KernelShape::default(),
            private_device: false,
        }
    }
}

pub use super::select::{AdapterSummary, DeviceType};

/// wgpu's device type as the selection's.
fn device_type(t: wgpu::DeviceType) -> DeviceType {
    match t {
        wgpu::DeviceType::DiscreteGpu => DeviceType::DiscreteGpu,
        wgpu::DeviceType::IntegratedGpu => DeviceType::IntegratedGpu,
        wgpu::DeviceType::VirtualGpu => DeviceType::VirtualGpu,
        wgpu::DeviceType::Other => DeviceType::Other,
        wgpu::DeviceType::Cpu => DeviceType::Cpu,
    }
}

/// Mesa's Vulkan drivers print `XDG_RUNTIME_DIR is invalid or not set in the environment` on
/// every instance when that variable is unset (containers, CI, services): 32 lines from one
/// identification. Before the first instance, a process without it gets a private folder
/// (`<tmp>/ctsid-xdg-<user>`, mode 0700), once. Nothing is set when the folder cannot be made.
fn quiet_vulkan_loader() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        if std::env::var_os("XDG_RUNTIME_DIR").is_some() {
            return;
        }
        let user = std::env::var("USER").unwrap_or_else(|_| owner_of_this_process());
        let user: String = user
            .chars()
            .filter(|c| c.is_ascii_alphanumeric() || *c == '_' || *c == '-')
            .collect();
        let dir = std::env::temp_dir().join(format!("ctsid-xdg-{user}"));
        if std::fs::create_dir_all(&dir).is_err() {
            return;
        }
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            if std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700)).is_err() {
                return;
            }
        }
        std::env::set_var("XDG_RUNTIME_DIR", &dir);
    });
}

/// The uid of this process where /proc tells it, else its pid.
fn owner_of_this_process() -> String {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let Ok(m) = std::fs::metadata("/proc/self") {
            return m.uid().to_string();
        }
    }
    std::process::id().to_string()
}

/// The process's one Vulkan instance (NVIDIA's driver refused the 30th instance or device that
/// one process opened, with "no adapter found"; docs/gpu.md).
fn new_instance() -> wgpu::Instance {
    static INSTANCE: OnceLock<wgpu::Instance> = OnceLock::new();
    INSTANCE
        .get_or_init(|| {
            quiet_vulkan_loader();
            let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
            desc.backends = wgpu::Backends::VULKAN;
            wgpu::Instance::new(desc)
        })
        .clone()
}

fn type_rank(t: DeviceType) -> u32 {
    match t {
        DeviceType::DiscreteGpu => 0,
        DeviceType::IntegratedGpu => 1,
        DeviceType::VirtualGpu => 2,
        DeviceType::Other => 3,
        DeviceType::Cpu => 4,
    }
}

/// Every Vulkan adapter, best first (discrete, integrated, virtual, other, CPU).
pub fn probe_adapters() -> Vec<AdapterSummary> {
    let instance = new_instance();
    let mut v: Vec<AdapterSummary> =
        pollster::block_on(instance.enumerate_adapters(wgpu::Backends::VULKAN))
            .iter()
            .map(|a| {
                let i = a.get_info();
                AdapterSummary {
                    name: i.name,
                    device_type: device_type(i.device_type),
                    driver: format!("{} {}", i.driver, i.driver_info),
                }
            })
            .collect();
    v.sort_by_key(|a| type_rank(a.device_type));
    v
}

/// How a problem is cut into factor tables, blocks and windows (public for tests and reports).
#[derive(Debug, Clone)]
pub struct GpuLayout {
    pub adapter: String,
    pub device_type: wgpu::DeviceType,
    /// Largest factor degree tabulated in workgroup memory.
    pub factor_degree: usize,
    /// Factors per sample row of the table.
    pub table_len: usize,
    /// Factors per candidate (loads per sample-candidate pair).
    pub factors_per_candidate: usize,
    /// Samples staged in workgroup memory at a time.
    pub chunk: usize,
    pub n_blocks: usize,
    pub block_samples: usize,
    /// Candidate windows `(start, len)`, each one dispatch of sweep + finalize.
    pub windows: Vec<(usize, usize)>,
    /// Bytes of device memory the engine allocated.
    pub device_bytes: u64,
    /// The sweep kernel's shape.
    pub kernel: KernelShape,
}

#[derive(Default)]
struct ErrorSink {
    uncaptured: Mutex<Vec<String>>,
    lost: Mutex<Option<String>>,
}

impl ErrorSink {
    /// No loss and no uncaptured error recorded: the device can serve another engine.
    fn healthy(&self) -> bool {
        self.lost.lock().map(|l| l.is_none()).unwrap_or(false)
            && self
                .uncaptured
                .lock()
                .map(|u| u.is_empty())
                .unwrap_or(false)
    }

    /// Records that the device can no longer be trusted (a wait that timed out: the device may
    /// be hung), as a loss: this engine's later calls fail at once instead of each waiting its
    /// timeout, and [`shared_device`] stops handing the device to new engines.
    fn give_up(&self, why: String) {
        let mut lost = self.lost.lock().unwrap_or_else(|p| p.into_inner());
        lost.get_or_insert(why);
    }
}

/// One [`Window`] per span of candidates: its parameters and the bind groups of its sweep
/// (`sweep_bufs`: z, v, recipe, cand, mean, partial, after the parameters) and finalize passes
/// (the partial sums and its slice of `out_buf`).
fn make_windows(
    device: &wgpu::Device,
    (spans, n_s, block_samples, n_blocks, window): (&[(usize, usize)], usize, usize, usize, usize),
    (sweep_bgl, finalize_bgl): (&wgpu::BindGroupLayout, &wgpu::BindGroupLayout),
    sweep_bufs: [&wgpu::Buffer; 6],
    out_buf: &wgpu::Buffer,
) -> Vec<Window> {
    // Bind groups list their resources in binding order: binding k is resources[k].
    let bind =
        |label: &str, layout: &wgpu::BindGroupLayout, resources: Vec<wgpu::BindingResource<'_>>| {
            let entries: Vec<wgpu::BindGroupEntry> = resources
                .into_iter()
                .enumerate()
                .map(|(k, resource)| wgpu::BindGroupEntry {
                    binding: k as u32,
                    resource,
                })
                .collect();
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(label),
                layout,
                entries: &entries,
            })
        };
    spans
        .iter()
        .map(|&(start, len)| {
            let params: [u32; 8] = [
                start as u32,
                len as u32,
                n_s as u32,
                block_samples as u32,
                n_blocks as u32,
                window as u32,
                // `zero`: the shaders' opaque 0 that keeps Kahan's compensation alive.
                0,
                0,
            ];
            let pbuf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("params"),
                contents: bytemuck::cast_slice(&params),
                usage: wgpu::BufferUsages::UNIFORM,
            });
            let sweep_bg = bind(
                "sweep",
                sweep_bgl,
                std::iter::once(&pbuf)
                    .chain(sweep_bufs)
                    .map(|b| b.as_entire_binding())
                    .collect(),
            );
            // The finalize pass writes this window's slice of the output only.
            let out_slice = wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: out_buf,
                offset: (start * 8) as u64,
                size: wgpu::BufferSize::new((len * 8) as u64),
            });
            let finalize_bg = bind(
                "finalize",
                finalize_bgl,
                vec![
                    pbuf.as_entire_binding(),
                    sweep_bufs[5].as_entire_binding(),
                    out_slice,
                ],
            );
            Window {
                start,
                len,
                sweep_bg,
                finalize_bg,
            }
        })
        .collect()
}

struct Window {
    start: usize,
    len: usize,
    sweep_bg: wgpu::BindGroup,
    finalize_bg: wgpu::BindGroup,
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Mode {
    Sweep,
    Centred,
}

/// Sweep engine on a wgpu (Vulkan) device; see the module docs.
pub struct GpuEngine {
    device: wgpu::Device,
    queue: wgpu::Queue,
    sink: Arc<ErrorSink>,
    sweep_pipe: wgpu::ComputePipeline,
    centred_pipe: wgpu::ComputePipeline,
    finalize_pipe: wgpu::ComputePipeline,
    v_buf: wgpu::Buffer,
    mean_buf: wgpu::Buffer,
    out_buf: wgpu::Buffer,
    staging: wgpu::Buffer,
    windows: Vec<Window>,
    layout: GpuLayout,
    features: Features,
    codes: Vec<Code>,
    timeout: Duration,
    n_samples: usize,
    n_candidates: usize,
    /// Fault injection for the end-to-end fallback test (tests/gpu_fallback.rs): with
    /// `CTSID_GPU_LOSE_DEVICE_AFTER=N` the device is destroyed before sweep N + 1, a real loss.
    lose_after: Option<usize>,
    sweeps: usize,
}

/// Factor degree, table length, factors per candidate and chunk for a problem (pure; see docs).
fn plan_factors(
    n_z: usize,
    degree: usize,
    shared_bytes: u32,
    shape: &KernelShape,
) -> Result<(usize, usize, usize, usize)> {
    let shared_floats = shared_bytes as usize / 4;
    let mut best: Option<(f64, usize, usize, usize, usize)> = None;
    for fd in 1..=shape.max_factor_degree.min(degree.max(1)) {
        let ts = count(n_z, fd).unwrap_or(u64::MAX) as usize;
        if ts > 0xffff {
            continue;
        }
        let chunk = (shared_floats / (ts + 1)).min(shape.max_chunk);
        if chunk < 4 {
            continue;
        }
        let nf = degree.div_ceil(fd).max(1);
        // Per-pair cost: nf loads + one weight load shared by R candidates, plus building the
        // table (ts multiplies per sample) spread over a tile.
        let cost = nf as f64 + 1.0 / shape.per_invocation as f64 + ts as f64 / shape.tile() as f64;
        if best.is_none_or(|b| cost < b.0) {
            best = Some((cost, fd, ts, nf, chunk));
        }
    }
    let (_, fd, ts, nf, chunk) = best.ok_or_else(|| {
        Error::Gpu(format!(
            "workgroup memory of {shared_bytes} bytes cannot hold the factor table of {n_z} variables; use --engine cpu"
        ))
    })?;
    Ok((fd, ts, nf, chunk))
}

/// What [`GpuEngine::new`] refuses before it looks for a device (see its docs).
fn check_inputs(features: &Features, basis: &Basis) -> Result<()> {
    features.check()?;
    let n_s = features.n_samples;
    let n_z = features.n_vars();
    let n_c = basis.len();
    if n_z != basis.n_vars() {
        return Err(Error::param(
            "features",
            format!(
                "{n_z} feature columns but the basis has {} variables",
                basis.n_vars()
            ),
        ));
    }
    if n_s == 0 || n_c == 0 {
        return Err(Error::param(
            "features",
            "the GPU engine needs at least one sample and one candidate",
        ));
    }
    if n_s > u32::MAX as usize / 64 || n_c > u32::MAX as usize / 64 {
        return Err(Error::param(
            "features",
            "more samples or candidates than the GPU engine indexes (u32)",
        ));
    }
    if let Some(k) = features.data.iter().position(|x| !x.is_finite()) {
        return Err(Error::InvalidData(format!(
            "feature '{}' has a non-finite value at sample {}",
            features.names[k / n_s],
            k % n_s
        )));
    }

    Ok(())
}

/// Fault injection for the end-to-end fallback test: `CTSID_GPU_LOSE_DEVICE_AFTER=N` (see
/// [`GpuEngine`]'s `lose_after`).
fn lose_after_from_env() -> Option<usize> {
    std::env::var("CTSID_GPU_LOSE_DEVICE_AFTER")
        .ok()
        .and_then(|x| x.parse().ok())
}

/// An opened device with what engines need of it.
#[derive(Clone)]
struct Opened {
    info: wgpu::AdapterInfo,
    limits: wgpu::Limits,
    device: wgpu::Device,
    queue: wgpu::Queue,
    sink: Arc<ErrorSink>,
}

/// The device for `options`: engines of one process share one device per kind of choice
/// (software adapter allowed or not) while it stays healthy (not lost, no uncaptured error), so
/// that building many engines neither opens many devices (a driver limit; docs/gpu.md) nor pays
/// the device's setup each time. `private` opens one for this engine alone (an engine that will
/// destroy its device on purpose must not take others' with it).
fn shared_device(options: &GpuOptions, private: bool) -> Result<Opened> {
    static OPEN: Mutex<Vec<(bool, Opened)>> = Mutex::new(Vec::new());
    if private {
        return open_device(options);
    }
    let mut open = OPEN.lock().unwrap_or_else(|p| p.into_inner());
    open.retain(|(_, o)| o.sink.healthy());
    if let Some((_, o)) = open
        .iter()
        .find(|(cpu, _)| *cpu == options.allow_cpu_adapter)
    {
        return Ok(o.clone());
    }
    let o = open_device(options)?;
    open.push((options.allow_cpu_adapter, o.clone()));
    Ok(o)
}

/// The first Vulkan adapter by kind (discrete first; a software one only when `options` allows),
/// opened with its own limits, with an error sink installed.
fn open_device(options: &GpuOptions) -> Result<Opened> {
    let instance = new_instance();
    let mut adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::VULKAN));
    adapters.sort_by_key(|a| type_rank(device_type(a.get_info().device_type)));
    let seen: Vec<String> = adapters.iter().map(|a| a.get_info().name).collect();
    let adapter = adapters
        .into_iter()
        .find(|a| options.allow_cpu_adapter || a.get_info().device_type != wgpu::DeviceType::Cpu)
        .ok_or_else(|| {
            if seen.is_empty() {
                Error::NoGpu(
                    "no Vulkan adapter found (is a Vulkan driver installed?); use --engine cpu"
                        .into(),
                )
            } else {
                Error::NoGpu(format!(
                    "only CPU (software) Vulkan adapters found ({}); use --engine cpu",
                    seen.join(", ")
                ))
            }
        })?;
    let info = adapter.get_info();
    let limits = adapter.limits();
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("ctsid"),
        required_features: wgpu::Features::empty(),
        required_limits: limits.clone(),
        experimental_features: wgpu::ExperimentalFeatures::disabled(),
        memory_hints: wgpu::MemoryHints::Performance,
        trace: wgpu::Trace::Off,
    }))
    .map_err(|e| Error::Gpu(format!("cannot open {}: {e}", info.name)))?;
    let sink = install_sink(&device);
    Ok(Opened {
        info,
        limits,
        device,
        queue,
        sink,
    })
}

/// How the candidates and samples are laid out on the device: the factor table (degree `fd`,
/// `ts` entries, `nf` factors per candidate in `nw` words), the sample blocks and the
/// candidate windows one dispatch covers.
struct Plan {
    /// Samples and candidates laid out.
    n_s: usize,
    n_c: usize,
    fd: usize,
    ts: usize,
    nf: usize,
    nw: usize,
    chunk: usize,
    n_blocks: usize,
    block_samples: usize,
    window: usize,
    /// (first candidate, count) of each window.
    spans: Vec<(usize, usize)>,
    /// The kernel's shape as fitted to the adapter.
    shape: KernelShape,
}

impl Plan {
    /// The layout for `n_s` samples and `n_c` candidates of `n_z` variables up to `degree`
    /// within the adapter's limits; refuses what they cannot hold.
    fn new(
        n_s: usize,
        n_z: usize,
        n_c: usize,
        degree: usize,
        info: &wgpu::AdapterInfo,
        limits: &wgpu::Limits,
        options: &GpuOptions,
    ) -> Result<Plan> {
        let shape = options.kernel.fitted(limits)?;
        let (fd, ts, nf, chunk) = plan_factors(
            n_z,
            degree,
            limits.max_compute_workgroup_storage_size,
            &shape,
        )?;
        let nw = nf.div_ceil(2);
        let tile = shape.tile();
        let tiles_total = n_c.div_ceil(tile);
        let target_wg: usize = if info.device_type == wgpu::DeviceType::Cpu {
            16
        } else {
            4096
        };
        let max_blocks = n_s
            .div_ceil(chunk)
            .min(limits.max_compute_workgroups_per_dimension as usize);
        let n_blocks = n_s
            .div_ceil(options.max_block_samples.max(chunk))
            .max(target_wg.div_ceil(tiles_total))
            .clamp(1, max_blocks.max(1));
        let n_blocks = n_blocks
            .min(n_s.div_ceil(options.min_block_samples.max(1)))
            .max(1);
        let block_samples = n_s.div_ceil(n_blocks).div_ceil(chunk) * chunk;
        let n_blocks = n_s.div_ceil(block_samples);

        let max_bind = limits.max_storage_buffer_binding_size;
        let mut window = n_c.div_ceil(tile) * tile;
        window = window.min((max_bind / (8 * n_blocks as u64)) as usize);
        window = window.min(limits.max_compute_workgroups_per_dimension as usize * tile);
        window =
            window.min(limits.max_compute_workgroups_per_dimension as usize * FINALIZE_WG as usize);
        window = window.min((options.max_pairs_per_dispatch / n_s as u64).max(1) as usize);
        if let Some(m) = options.max_window_candidates {
            window = window.min(m);
        }
        window = (window / tile).max(1) * tile;
        let align = limits.min_storage_buffer_offset_alignment as usize;
        if !(window * 8).is_multiple_of(align) {
            return Err(Error::Gpu(format!(
                "storage offset alignment {align} does not divide the window size"
            )));
        }
        let spans: Vec<(usize, usize)> = (0..n_c)
            .step_by(window)
            .map(|s| (s, window.min(n_c - s)))
            .collect();

        Ok(Plan {
            n_s,
            n_c,
            fd,
            ts,
            nf,
            nw,
            chunk,
            n_blocks,
            block_samples,
            window,
            spans,
            shape,
        })
    }

    /// Where each level (degree 0 to 3) of the factor table ends.
    fn level_end(&self, n_z: usize) -> [u32; 4] {
        let mut level_end = [0u32; 4];
        for (l, e) in level_end.iter_mut().enumerate() {
            *e = count(n_z, l.min(self.fd)).unwrap() as u32;
        }
        level_end
    }

    /// The device memory the layout needs, estimated before anything is allocated: refuses,
    /// with the numbers, a total above `options.memory_budget_bytes` and a buffer beyond the
    /// adapter's limits.
    fn device_bytes(
        &self,
        n_z: usize,
        adapter: (&wgpu::AdapterInfo, &wgpu::Limits),
        options: &GpuOptions,
    ) -> Result<u64> {
        let (info, limits) = adapter;
        let (n_s, n_c) = (self.n_s, self.n_c);
        let max_bind = limits.max_storage_buffer_binding_size;
        let sizes: [(&str, u64, bool); 8] = [
            ("features", (n_s * n_z * 4) as u64, true),
            ("sweep vector", (n_s * 4) as u64, true),
            ("factor recipes", (self.ts * 4) as u64, true),
            ("candidate codes", (n_c * self.nw * 4) as u64, true),
            ("means", (n_c * 4) as u64, true),
            (
                "partial sums",
                (self.n_blocks * self.window * 8) as u64,
                true,
            ),
            ("results", (n_c * 8) as u64, false),
            ("read-back", (n_c * 8) as u64, false),
        ];
        let total: u64 = sizes.iter().map(|s| s.1).sum();
        if total > options.memory_budget_bytes {
            return Err(Error::TooLarge {
                what: format!("the GPU engine for {n_s} samples x {n_c} candidates"),
                needed_mib: mib(total),
                budget_mib: mib(options.memory_budget_bytes),
                hint: "use fewer samples, a lower degree, or --engine cpu".into(),
            });
        }
        for (what, bytes, bound_whole) in sizes {
            if bytes > limits.max_buffer_size || (bound_whole && bytes > max_bind) {
                let cap = if bound_whole {
                    max_bind.min(limits.max_buffer_size)
                } else {
                    limits.max_buffer_size
                };
                return Err(Error::TooLarge {
                    what: format!("the GPU {what} buffer for {n_s} samples x {n_c} candidates"),
                    needed_mib: mib(bytes),
                    budget_mib: mib(cap),
                    hint: format!(
                        "{} allows no larger buffer; use fewer samples or --engine cpu",
                        info.name
                    ),
                });
            }
        }

        Ok(total)
    }
}

/// The tables the shaders read: each factor's recipe (parent and last variable), each
/// candidate's factors (two 16-bit indices per word), and the features as f32 row by row.
#[allow(clippy::type_complexity)]
fn host_tables(
    features: &Features,
    basis: &Basis,
    plan: &Plan,
) -> Result<(Vec<u32>, Vec<u32>, Vec<f32>)> {
    let (n_s, n_z, n_c) = (features.n_samples, features.n_vars(), basis.len());
    let (fd, ts, nw) = (plan.fd, plan.ts, plan.nw);
    let fnames: Vec<String> = (0..n_z).map(|k| format!("z{k}")).collect();
    let fbasis = Basis::new(&fnames, fd, Default::default())?;
    debug_assert_eq!(fbasis.len(), ts);
    let findex: HashMap<Code, u32> = fbasis
        .codes()
        .iter()
        .enumerate()
        .map(|(i, c)| (*c, i as u32))
        .collect();
    let recipe: Vec<u32> = (0..ts)
        .map(|f| match (fbasis.parent(f), fbasis.last_var(f)) {
            (Some(p), Some(v)) => p as u32 | ((v as u32) << 16),
            _ => 0,
        })
        .collect();
    let mut cand = vec![0u32; n_c * nw];
    for (j, code) in basis.codes().iter().enumerate() {
        let vars: Vec<usize> = code.vars().collect();
        for (q, group) in vars.chunks(fd).enumerate() {
            let g = group.iter().fold(Code::ONE, |c, &v| c.times(v));
            let f = findex[&g];
            cand[j * nw + q / 2] |= f << (16 * (q % 2));
        }
    }
    let mut z32 = vec![0f32; n_s * n_z];
    for k in 0..n_z {
        for (i, &x) in features.column(k).iter().enumerate() {
            z32[i * n_z + k] = x as f32;
        }
    }

    Ok((recipe, cand, z32))
}

/// The compiled shaders: the sweep (and its centred mode) and the finalize pass, with their bind
/// group layouts.
struct Pipelines {
    sweep_bgl: wgpu::BindGroupLayout,
    finalize_bgl: wgpu::BindGroupLayout,
    sweep_pipe: wgpu::ComputePipeline,
    centred_pipe: wgpu::ComputePipeline,
    finalize_pipe: wgpu::ComputePipeline,
}

impl Pipelines {
    /// The shaders specialised (by a header of constants) to `plan` and `n_z` variables.
    fn new(device: &wgpu::Device, plan: &Plan, n_z: usize, options: &GpuOptions) -> Pipelines {
        let level_end = plan.level_end(n_z);
        let consts = [
            ("CHUNK", plan.chunk as u32),
            ("NZ", n_z as u32),
            ("TS", plan.ts as u32),
            ("FD", plan.fd as u32),
            ("NF", plan.nf as u32),
            ("NW", plan.nw as u32),
            ("LEVEL_END0", level_end[0]),
            ("LEVEL_END1", level_end[1]),
            ("LEVEL_END2", level_end[2]),
            ("LEVEL_END3", level_end[3]),
        ];
        // naga's forced loop bounding puts a counter and an exit test in every loop, which keeps
        // the driver from unrolling the R- and NF-loops of sweep.wgsl and so from keeping the
        // per-candidate arrays in registers. Every loop in both shaders ends after a number of
        // iterations fixed by constants of the header or by uniform counts (`n_blocks`,
        // `block_samples`, `n_samples`), so the counters buy nothing.
        let checks = wgpu::ShaderRuntimeChecks {
            bounds_checks: options.bounds_checks,
            force_loop_bounding: false,
            ..wgpu::ShaderRuntimeChecks::checked()
        };
        let module = |label: &str, src: String| {
            let desc = wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(src.into()),
            };
            // SAFETY: the shaders are ours (no user text reaches them) and every loop in them
            // terminates (see above); with `bounds_checks` off, every index stays inside its
            // buffer by construction of the layout (windows, blocks and tables sized above).
            unsafe { device.create_shader_module_trusted(desc, checks) }
        };
        let shape = &plan.shape;
        let sweep_mod = module("sweep", shader::sweep(&consts, shape, plan.nf, 0));
        let centred_mod = module("centred", shader::sweep(&consts, shape, plan.nf, 1));
        let finalize_mod = module("finalize", shader::finalize(FINALIZE_WG));

        let entry = |binding: u32, ty: wgpu::BufferBindingType| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let ro = wgpu::BufferBindingType::Storage { read_only: true };
        let rw = wgpu::BufferBindingType::Storage { read_only: false };
        let uni = wgpu::BufferBindingType::Uniform;
        let sweep_bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("sweep"),
            entries: &[
                entry(0, uni),
                entry(1, ro),
                entry(2, ro),
                entry(3, ro),
                entry(4, ro),
                entry(5, ro),
                entry(6, rw),
            ],
        });
        let finalize_bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("finalize"),
            entries: &[entry(0, uni), entry(1, ro), entry(2, rw)],
        });
        let pipe = |bgl: &wgpu::BindGroupLayout, m: &wgpu::ShaderModule, label: &str| {
            let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(label),
                bind_group_layouts: &[Some(bgl)],
                immediate_size: 0,
            });
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: Some(&pl),
                module: m,
                entry_point: Some("main"),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let sweep_pipe = pipe(&sweep_bgl, &sweep_mod, "sweep");
        let centred_pipe = pipe(&sweep_bgl, &centred_mod, "centred");
        let finalize_pipe = pipe(&finalize_bgl, &finalize_mod, "finalize");

        Pipelines {
            sweep_bgl,
            finalize_bgl,
            sweep_pipe,
            centred_pipe,
            finalize_pipe,
        }
    }
}

fn mib(b: u64) -> f64 {
    b as f64 / 1048576.0
}

impl GpuEngine {
    /// Builds the engine for all candidates of `basis` on the rows of `features`. Refuses features
    /// that fail [`Features::check`], a number of variables other than the basis's, no samples or
    /// no candidates, more of either than u32 indexing allows (`u32::MAX / 64`), a feature value
    /// that is not finite, and buffers beyond `options.memory_budget_bytes` or the adapter's
    /// limits; [`Error::NoGpu`] when no Vulkan adapter (other than a software one, unless
    /// `options.allow_cpu_adapter`) is found, [`Error::Gpu`] when the device cannot be opened, its
    /// workgroup memory cannot hold the factor table, or the upload or setup fails.
    pub fn new(features: &Features, basis: &Basis, options: GpuOptions) -> Result<GpuEngine> {
        check_inputs(features, basis)?;
        let (n_s, n_z, n_c) = (features.n_samples, features.n_vars(), basis.len());

        let lose_after = lose_after_from_env();
        let o = shared_device(&options, lose_after.is_some() || options.private_device)?;
        let (info, limits, device, queue, sink) = (o.info, o.limits, o.device, o.queue, o.sink);

        let plan = Plan::new(n_s, n_z, n_c, basis.degree(), &info, &limits, &options)?;
        let Plan {
            fd,
            ts,
            nf,
            chunk,
            n_blocks,
            block_samples,
            window,
            ref spans,
            ..
        } = plan;

        let total = plan.device_bytes(n_z, (&info, &limits), &options)?;

        let (recipe, cand, z32) = host_tables(features, basis, &plan)?;

        // ---- device objects, inside error scopes ----
        let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let val = device.push_error_scope(wgpu::ErrorFilter::Validation);

        let storage = |label: &str, bytes: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytes,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            })
        };
        let z_buf = storage("z", bytemuck::cast_slice(&z32));
        let recipe_buf = storage("recipe", bytemuck::cast_slice(&recipe));
        let cand_buf = storage("cand", bytemuck::cast_slice(&cand));
        let plain = |label: &str, size: u64, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        let st = wgpu::BufferUsages::STORAGE;
        let v_buf = plain("v", (n_s * 4) as u64, st | wgpu::BufferUsages::COPY_DST);
        let mean_buf = plain("mean", (n_c * 4) as u64, st | wgpu::BufferUsages::COPY_DST);
        let partial_buf = plain("partial", (n_blocks * window * 8) as u64, st);
        let out_buf = plain(
            "out",
            (n_c * 8) as u64,
            st | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        );
        let staging = plain(
            "staging",
            (n_c * 8) as u64,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        );

        let Pipelines {
            sweep_bgl,
            finalize_bgl,
            sweep_pipe,
            centred_pipe,
            finalize_pipe,
        } = Pipelines::new(&device, &plan, n_z, &options);

        let windows = make_windows(
            &device,
            (spans, n_s, block_samples, n_blocks, window),
            (&sweep_bgl, &finalize_bgl),
            [
                &z_buf,
                &v_buf,
                &recipe_buf,
                &cand_buf,
                &mean_buf,
                &partial_buf,
            ],
            &out_buf,
        );

        let verr = pollster::block_on(val.pop());
        let merr = pollster::block_on(oom.pop());
        if let Some(e) = merr {
            return Err(Error::Gpu(format!(
                "out of device memory while uploading {n_s} x {n_c} ({:.0} MiB): {e}",
                mib(total)
            )));
        }
        if let Some(e) = verr {
            return Err(Error::Gpu(format!(
                "setup failed validation: {}",
                one_line(&e.to_string())
            )));
        }

        let layout = GpuLayout {
            adapter: info.name.clone(),
            device_type: info.device_type,
            factor_degree: fd,
            table_len: ts,
            factors_per_candidate: nf,
            chunk,
            n_blocks,
            block_samples,
            windows: spans.clone(),
            device_bytes: total,
            kernel: plan.shape,
        };
        let engine = GpuEngine {
            device,
            queue,
            sink,
            sweep_pipe,
            centred_pipe,
            finalize_pipe,
            v_buf,
            mean_buf,
            out_buf,
            staging,
            windows,
            layout,
            features: features.clone(),
            codes: basis.codes().to_vec(),
            timeout: options.timeout,
            lose_after,
            sweeps: 0,
            n_samples: n_s,
            n_candidates: n_c,
        };
        engine.check()?;
        Ok(engine)
    }

    /// How the problem was cut up (factor tables, blocks, windows).
    pub fn layout(&self) -> &GpuLayout {
        &self.layout
    }

    /// Whether the device has been lost (the caller should fall back to the CPU engine).
    pub fn is_lost(&self) -> bool {
        self.sink.lost.lock().map(|l| l.is_some()).unwrap_or(true)
    }

    fn check(&self) -> Result<()> {
        if let Some(msg) = self
            .sink
            .lost
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .as_ref()
        {
            return Err(Error::Gpu(format!(
                "device lost ({}); use --engine cpu",
                one_line(msg)
            )));
        }
        if let Some(msg) = self
            .sink
            .uncaptured
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .first()
        {
            return Err(Error::Gpu(format!("device error: {}", one_line(msg))));
        }
        Ok(())
    }

    /// Runs MODE `mode` with per-sample vector `v` over every window; `out[j] = hi + lo`.
    fn run(&mut self, mode: Mode, v: &[f32], out: &mut [f64]) -> Result<()> {
        self.check()?;
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let val = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        self.queue
            .write_buffer(&self.v_buf, 0, bytemuck::cast_slice(v));
        let tiles_y = self.layout.n_blocks as u32;
        let pipe = if mode == Mode::Sweep {
            &self.sweep_pipe
        } else {
            &self.centred_pipe
        };
        // One command buffer per window: each is bounded in work (see GpuOptions).
        let mut cbs = Vec::with_capacity(self.windows.len() + 1);
        for w in &self.windows {
            let mut enc = self
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("window"),
                });
            {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("sweep"),
                    timestamp_writes: None,
                });
                pass.set_pipeline(pipe);
                pass.set_bind_group(0, &w.sweep_bg, &[]);
                let tile = self.layout.kernel.tile();
                pass.dispatch_workgroups(w.len.div_ceil(tile) as u32, tiles_y, 1);
                pass.set_pipeline(&self.finalize_pipe);
                pass.set_bind_group(0, &w.finalize_bg, &[]);
                pass.dispatch_workgroups(w.len.div_ceil(FINALIZE_WG as usize) as u32, 1, 1);
            }
            debug_assert!(w.start + w.len <= self.n_candidates);
            cbs.push(enc.finish());
        }
        let bytes = (self.n_candidates * 8) as u64;
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("read-back"),
            });
        enc.copy_buffer_to_buffer(&self.out_buf, 0, &self.staging, 0, bytes);
        cbs.push(enc.finish());
        let idx = self.queue.submit(cbs);

        let slice = self.staging.slice(..);
        let (tx, rx) = mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        let verr = pollster::block_on(val.pop());
        let merr = pollster::block_on(oom.pop());
        let polled = self.device.poll(wgpu::PollType::Wait {
            submission_index: Some(idx),
            timeout: Some(self.timeout),
        });
        if let Some(e) = verr.or(merr) {
            self.staging.unmap();
            return Err(Error::Gpu(format!(
                "sweep failed: {}",
                one_line(&e.to_string())
            )));
        }
        if let Err(e) = polled {
            self.check()?;
            let msg = format!("waiting for the sweep failed after {:?}: {e}", self.timeout);
            self.sink.give_up(msg.clone());
            return Err(Error::Gpu(msg));
        }
        // Engines share the device: another thread's poll may be the one that runs this
        // mapping's callback, just after our wait returned; so wait for it, boundedly.
        match rx.recv_timeout(self.timeout) {
            Ok(Ok(())) => {}
            Ok(Err(e)) => {
                self.check()?;
                return Err(Error::Gpu(format!("cannot read the results back: {e}")));
            }
            Err(_) => {
                self.check()?;
                let msg = format!(
                    "the results were not ready {:?} after the device finished",
                    self.timeout
                );
                self.sink.give_up(msg.clone());
                return Err(Error::Gpu(msg));
            }
        }
        {
            let view = slice
                .get_mapped_range()
                .map_err(|e| Error::Gpu(format!("cannot map the results: {e:?}")))?;
            match bytemuck::try_cast_slice::<u8, [f32; 2]>(&view) {
                Ok(pairs) => {
                    for (o, p) in out.iter_mut().zip(pairs) {
                        *o = p[0] as f64 + p[1] as f64;
                    }
                }
                Err(_) => {
                    for (o, b) in out.iter_mut().zip(view.chunks_exact(8)) {
                        let hi = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                        let lo = f32::from_le_bytes([b[4], b[5], b[6], b[7]]);
                        *o = hi as f64 + lo as f64;
                    }
                }
            }
        }
        self.staging.unmap();
        self.check()
    }
}

/// Replaces wgpu's default uncaptured-error handler (which panics) with one that records, and
/// records device loss; [`GpuEngine::check`] turns both into errors.
fn install_sink(device: &wgpu::Device) -> Arc<ErrorSink> {
    let sink = Arc::new(ErrorSink::default());
    let s = sink.clone();
    device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
        s.uncaptured
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .push(e.to_string());
    }));
    let s = sink.clone();
    device.set_device_lost_callback(move |reason, msg| {
        *s.lost.lock().unwrap_or_else(|p| p.into_inner()) = Some(if msg.is_empty() {
            format!("{reason:?}")
        } else {
            format!("{reason:?}: {msg}")
        });
    });
    sink
}

fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

fn to_f32(what: &str, x: &[f64], n: usize) -> Result<Vec<f32>> {
    if x.len() != n {
        return Err(Error::param(
            what,
            format!("length {} but there are {n} samples", x.len()),
        ));
    }
    if let Some(i) = x
        .iter()
        .position(|a| !a.is_finite() || a.abs() > f32::MAX as f64)
    {
        return Err(Error::InvalidData(format!(
            "{what}[{i}] = {} is not a finite f32 value",
            x[i]
        )));
    }
    Ok(x.iter().map(|&a| a as f32).collect())
}

impl SweepEngine for GpuEngine {
    fn describe(&self) -> String {
        format!(
            "gpu ({}, {:?}; f32 products, factor degree {}, {} blocks x {} windows, f64 final sum)",
            self.layout.adapter,
            self.layout.device_type,
            self.layout.factor_degree,
            self.layout.n_blocks,
            self.layout.windows.len()
        )
    }

    fn n_samples(&self) -> usize {
        self.n_samples
    }

    fn n_candidates(&self) -> usize {
        self.n_candidates
    }

    fn column_stats(&mut self, weights: Option<&[f64]>) -> Result<ColumnStats> {
        let n = self.n_samples;
        let w64: Vec<f64> = match weights {
            Some(w) => w.to_vec(),
            None => vec![1.0; n],
        };
        let w32 = to_f32("weights", &w64, n)?;
        if w64.iter().any(|&a| a < 0.0) {
            return Err(Error::param("weights", "must be non-negative"));
        }
        // The GPU sees the f32 weights; use exactly those on the host side too.
        let wsum: f64 = w32.iter().map(|&a| a as f64).sum();
        if wsum <= 0.0 {
            return Err(Error::param(
                "weights",
                "sum to zero; at least one sample needs a positive weight",
            ));
        }
        let mut s1 = vec![0.0; self.n_candidates];
        self.run(Mode::Sweep, &w32, &mut s1)?;
        let mean: Vec<f64> = s1.iter().map(|s| s / wsum).collect();
        let mean32: Vec<f32> = mean.iter().map(|&m| m as f32).collect();
        self.queue
            .write_buffer(&self.mean_buf, 0, bytemuck::cast_slice(&mean32));
        let mut q = vec![0.0; self.n_candidates];
        self.run(Mode::Centred, &w32, &mut q)?;
        let norm = q
            .iter()
            .zip(&mean)
            .zip(&mean32)
            .map(|((&q, &m), &m32)| {
                let shift = m32 as f64 - m;
                (q - wsum * shift * shift).max(0.0).sqrt()
            })
            .collect();
        Ok(ColumnStats { mean, norm })
    }

    fn sweep(&mut self, v: &[f64], out: &mut [f64]) -> Result<()> {
        if out.len() != self.n_candidates {
            return Err(Error::param(
                "out",
                format!(
                    "length {} but there are {} candidates",
                    out.len(),
                    self.n_candidates
                ),
            ));
        }
        let v32 = to_f32("v", v, self.n_samples)?;
        if self.lose_after.is_some_and(|n| self.sweeps >= n) {
            self.device.destroy();
            let _ = self.device.poll(wgpu::PollType::Poll);
        }
        self.sweeps += 1;
        self.run(Mode::Sweep, &v32, out)
    }

    fn columns(&mut self, idx: &[usize]) -> Result<Vec<Vec<f64>>> {
        idx.iter()
            .map(|&j| {
                let code = *self.codes.get(j).ok_or_else(|| {
                    Error::param(
                        "columns",
                        format!(
                            "candidate {j} does not exist (there are {})",
                            self.n_candidates
                        ),
                    )
                })?;
                // Same operation order as Code::eval, so the values are bit-identical to it.
                let mut col = vec![1.0; self.n_samples];
                for v in code.vars() {
                    for (c, z) in col.iter_mut().zip(self.features.column(v)) {
                        *c *= z;
                    }
                }
                Ok(col)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn require_gpu() -> bool {
        std::env::var("CTSID_REQUIRE_GPU").as_deref() == Ok("1")
    }

    /// `n_vars` variables of `n` samples in [-1, 1], a fixed pattern, named a, b, c, ...
    fn pattern_features(n_vars: usize, n: usize) -> Features {
        let cols = (0..n_vars)
            .map(|k| {
                (0..n)
                    .map(|i| ((i * 7 + k * 3) % 11) as f64 / 5.0 - 1.0)
                    .collect()
            })
            .collect();
        let names = (0..n_vars)
            .map(|k| ((b'a' + k as u8) as char).to_string())
            .collect();
        Features::new(names, cols).unwrap()
    }

    fn tiny_engine() -> Option<GpuEngine> {
        let f = pattern_features(3, 200);
        let b = Basis::new(&f.names, 3, Default::default()).unwrap();
        // Private: one test destroys its device.
        let options = GpuOptions {
            private_device: true,
            ..GpuOptions::default()
        };
        engine_or_skip(&f, &b, options)
    }

    /// The engine, or `None` with a notice where there is no adapter and none is required.
    fn engine_or_skip(f: &Features, b: &Basis, options: GpuOptions) -> Option<GpuEngine> {
        match GpuEngine::new(f, b, options) {
            Ok(e) => Some(e),
            Err(Error::NoGpu(m)) if !require_gpu() => {
                println!("skipping: no GPU adapter ({m})");
                None
            }
            Err(e) => panic!("{e}"),
        }
    }

    #[test]
    fn validation_errors_are_caught_or_recorded_never_a_panic() {
        let Some(eng) = tiny_engine() else { return };
        let bad = || wgpu::ShaderModuleDescriptor {
            label: Some("bad"),
            source: wgpu::ShaderSource::Wgsl("fn main( {".into()),
        };
        // Inside an error scope: the scope gets it, the recorder does not.
        let val = eng.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let _m = eng.device.create_shader_module(bad());
        assert!(pollster::block_on(val.pop()).is_some());
        assert!(eng.check().is_ok());
        // Outside any scope: recorded (wgpu's default handler would panic here), then reported.
        let _m = eng.device.create_shader_module(bad());
        let e = eng.check().unwrap_err();
        assert!(matches!(e, Error::Gpu(_)), "{e}");
        assert!(!e.to_string().contains('\n'));
    }

    #[test]
    fn a_lost_device_is_an_error_not_a_panic() {
        let Some(mut eng) = tiny_engine() else { return };
        let mut out = vec![f64::NAN; eng.n_candidates()];
        eng.sweep(&[1.0; 200], &mut out).unwrap();
        assert!((out[0] - 200.0).abs() < 1e-9);
        eng.device.destroy();
        let _ = eng.device.poll(wgpu::PollType::Poll);
        let r = eng.sweep(&[1.0; 200], &mut out);
        assert!(matches!(r, Err(Error::Gpu(_))), "{r:?}");
        println!("after destroy: {}", r.unwrap_err());
    }

    #[test]
    fn a_timed_out_wait_retires_the_device() {
        let Some(mut eng) = tiny_engine() else { return };
        let mut out = vec![f64::NAN; eng.n_candidates()];
        eng.sweep(&[1.0; 200], &mut out).unwrap();
        assert!(eng.sink.healthy() && !eng.is_lost());
        // What the timeouts of `run` record: later calls fail at once, and the shared pool
        // (which keeps only healthy devices) would open a new one for the next engine.
        eng.sink
            .give_up("waiting for the sweep failed after 300s: timeout".into());
        assert!(!eng.sink.healthy() && eng.is_lost());
        let t = std::time::Instant::now();
        let e = eng.sweep(&[1.0; 200], &mut out).unwrap_err();
        assert!(t.elapsed() < std::time::Duration::from_secs(5));
        assert!(e.to_string().contains("timeout"), "{e}");
        // A loss recorded first is the one reported.
        eng.sink.give_up("another reason".into());
        assert!(eng.check().unwrap_err().to_string().contains("timeout"));
    }

    #[test]
    fn a_zero_timeout_fails_cleanly_and_retires_the_device() {
        // With no time to wait, a sweep either finds its work already done (a fast adapter) or
        // times out; a timeout must leave the engine lost, not waiting again on every call.
        let f = pattern_features(4, 20_000);
        let b = Basis::new(&f.names, 6, Default::default()).unwrap();
        let options = GpuOptions {
            private_device: true,
            timeout: Duration::ZERO,
            ..GpuOptions::default()
        };
        let Some(mut eng) = engine_or_skip(&f, &b, options) else {
            return;
        };
        let mut out = vec![0.0; eng.n_candidates()];
        match eng.sweep(&vec![1.0; 20_000], &mut out) {
            Ok(()) => {
                println!("notice: the sweep finished within a zero timeout; no timeout to check")
            }
            Err(e) => {
                assert!(matches!(e, Error::Gpu(_)), "{e}");
                assert!(eng.is_lost(), "{e}");
                assert!(eng.sweep(&vec![1.0; 20_000], &mut out).is_err());
            }
        }
    }

    #[test]
    fn factor_plan_prefers_few_loads_within_shared_memory() {
        let fd3 = KernelShape {
            max_factor_degree: 3,
            ..KernelShape::default()
        };
        // n_z = 13, d = 9 with 16 KiB: degree-3 factors (560 per sample), 3 per candidate.
        let (fd, ts, nf, chunk) = plan_factors(13, 9, 16384, &fd3).unwrap();
        assert_eq!((fd, ts, nf), (3, 560, 3));
        assert!(chunk >= 4 && (ts + 1) * chunk * 4 <= 16384);
        // n_z = 32, d = 12: degree-3 tables would not fit; degree-2 ones (561) do.
        let (fd, ts, nf, _) = plan_factors(32, 12, 16384, &fd3).unwrap();
        assert_eq!((fd, ts, nf), (2, 561, 6));
        // Constant-only basis.
        assert_eq!(plan_factors(4, 0, 16384, &fd3).unwrap().2, 1);
        // Impossibly small workgroup memory is an error, not a panic.
        assert!(plan_factors(32, 12, 64, &fd3).is_err());
        // The default shape stops at degree-2 factors (measured faster; docs/gpu.md).
        let (fd, ts, nf, chunk) = plan_factors(13, 9, 49152, &KernelShape::default()).unwrap();
        assert_eq!((fd, ts, nf, chunk), (2, 105, 5, 32));
    }
}
