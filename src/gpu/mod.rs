//! The GPU engine's device side: a context built once (instance, adapter,
//! device, queue, every kernel's pipeline and reusable buffers), and one host
//! module per kernel in `shaders/`.

mod chunk_kernel;
mod error;
mod roughness;

pub use error::GpuError;

use std::time::Duration;

/// A chunk kernel's shader: `shaders/shared.wgsl` (the sample records and
/// fixed-point helpers) followed by the kernel's own file.
macro_rules! chunk_shader {
    ($file:literal) => {
        wgpu::ShaderModuleDescriptor {
            label: Some($file),
            source: wgpu::ShaderSource::Wgsl(std::borrow::Cow::Borrowed(concat!(
                include_str!("../../shaders/shared.wgsl"),
                include_str!(concat!("../../shaders/", $file))
            ))),
        }
    };
}

/// Builds a kernel's compute pipeline (entry point `main`, layout from the
/// shader) and its bind-group layout; a shader that does not validate is an
/// error naming the kernel, not a panic.
pub(crate) fn compute_pipeline(
    device: &wgpu::Device,
    name: &'static str,
    source: wgpu::ShaderModuleDescriptor,
) -> Result<(wgpu::ComputePipeline, wgpu::BindGroupLayout), GpuError> {
    let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let module = device.create_shader_module(source);
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(name),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    if let Some(e) = pollster::block_on(scope.pop()) {
        return Err(GpuError::Validation {
            kernel: name,
            message: e.to_string(),
        });
    }
    let layout = pipeline.get_bind_group_layout(0);
    Ok((pipeline, layout))
}

/// Device, queue and pipelines, created once and shared by every run.
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter: wgpu::AdapterInfo,
    pub limits: wgpu::Limits,
    telemetry_reduce: chunk_kernel::ChunkKernel,
    energy_map: chunk_kernel::ChunkKernel,
    condition_map: chunk_kernel::ChunkKernel,
    /// The condition maps' bin table (binding 2 of `condition_map`).
    condition_table: wgpu::Buffer,
    roughness: roughness::RoughnessKernels,
    /// Samples and chunks, shared by the chunk kernels.
    chunk_inputs: chunk_kernel::InputScratch,
    /// Test overrides: samples per dispatch and workgroups per grid dimension.
    dispatch_samples: Option<usize>,
    grid_dim: Option<u32>,
}

/// Where a kernel's GPU time went.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct GpuTimings {
    pub upload: Duration,
    pub compute: Duration,
    pub readback: Duration,
}

impl GpuTimings {
    pub fn total(&self) -> Duration {
        self.upload + self.compute + self.readback
    }
    pub(crate) fn add(&mut self, o: &GpuTimings) {
        self.upload += o.upload;
        self.compute += o.compute;
        self.readback += o.readback;
    }
}

impl GpuContext {
    /// Opens the first adapter wgpu offers (a real GPU before a software
    /// one; `WGPU_BACKEND` and `WGPU_ADAPTER_NAME` select), with its own limits.
    pub fn new() -> Result<GpuContext, GpuError> {
        pollster::block_on(async { Self::open(Self::adapter().await?).await })
    }

    /// As [`GpuContext::new`], but only a hardware adapter: where the one it
    /// would open is a software rasteriser (lavapipe, WARP), its description,
    /// without building the device and compiling the kernels (0.1–0.35 s on
    /// lavapipe, up to a fifth of a one-core extraction of the demo).
    pub fn new_hardware() -> Result<Result<GpuContext, wgpu::AdapterInfo>, GpuError> {
        pollster::block_on(async {
            let adapter = Self::adapter().await?;
            let info = adapter.get_info();
            if info.device_type == wgpu::DeviceType::Cpu {
                return Ok(Err(info));
            }
            Self::open(adapter).await.map(Ok)
        })
    }

    /// The adapter to open.
    async fn adapter() -> Result<wgpu::Adapter, GpuError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        match wgpu::util::initialize_adapter_from_env(&instance, None).await {
            Ok(a) => Ok(a),
            Err(_) => instance
                .request_adapter(&wgpu::RequestAdapterOptions {
                    power_preference: wgpu::PowerPreference::HighPerformance,
                    force_fallback_adapter: false,
                    compatible_surface: None,
                    apply_limit_buckets: false,
                })
                .await
                .map_err(|e| GpuError::NoAdapter(e.to_string())),
        }
    }

    /// The device, queue and kernels of `adapter`.
    async fn open(adapter: wgpu::Adapter) -> Result<GpuContext, GpuError> {
        let info = adapter.get_info();
        let limits = adapter.limits();
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("tirewear"),
                required_features: wgpu::Features::empty(),
                required_limits: limits.clone(),
                experimental_features: wgpu::ExperimentalFeatures::default(),
                memory_hints: wgpu::MemoryHints::Performance,
                trace: wgpu::Trace::Off,
            })
            .await
            .map_err(|source| GpuError::Device {
                adapter: info.name.clone(),
                source,
            })?;
        let telemetry_reduce = chunk_kernel::ChunkKernel::new(
            &device,
            "telemetry_reduce",
            chunk_shader!("telemetry_reduce.wgsl"),
            chunk_kernel::Output::PerChunk(crate::kpi::cpu::telemetry_reduce::SUMS),
            chunk_kernel::Extra::Refs,
        )?;
        let energy_map = chunk_kernel::ChunkKernel::new(
            &device,
            "energy_map",
            chunk_shader!("energy_map.wgsl"),
            chunk_kernel::Output::PerWheel(2 * crate::kpi::cpu::energy_map::BINS),
            chunk_kernel::Extra::None,
        )?;
        let condition_map = chunk_kernel::ChunkKernel::new(
            &device,
            "condition_map",
            chunk_shader!("condition_map.wgsl"),
            chunk_kernel::Output::PerWheel(2 * crate::kpi::cpu::condition_map::MAP_BINS),
            chunk_kernel::Extra::ConditionTable,
        )?;
        let condition_table = {
            use wgpu::util::DeviceExt;
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("condition table"),
                contents: bytemuck::cast_slice(&crate::kpi::cpu::condition_map::condition_table()),
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let roughness = roughness::RoughnessKernels::new(&device)?;
        tracing::info!(
            "GPU: {} ({:?}, {:?} backend, driver {})",
            info.name,
            info.device_type,
            info.backend,
            info.driver_info
        );
        Ok(GpuContext {
            device,
            queue,
            adapter: info,
            limits,
            telemetry_reduce,
            energy_map,
            condition_map,
            condition_table,
            roughness,
            chunk_inputs: Default::default(),
            dispatch_samples: None,
            grid_dim: None,
        })
    }

    /// Blocks until the queue is idle.
    pub(crate) fn wait(&self) -> Result<(), GpuError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| GpuError::Poll(e.to_string()))
    }

    /// Reads a MAP_READ buffer's first `bytes` back.
    pub(crate) fn read_back(&self, buffer: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>, GpuError> {
        let slice = buffer.slice(..bytes);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.wait()?;
        rx.recv()
            .map_err(|e| GpuError::Map(e.to_string()))?
            .map_err(|e| GpuError::Map(e.to_string()))?;
        let out = slice
            .get_mapped_range()
            .map_err(|e| GpuError::Map(e.to_string()))?
            .to_vec();
        buffer.unmap();
        Ok(out)
    }

    /// Lowers the batch-splitting and grid limits below the device's, so tests
    /// reach the multi-dispatch and 2-D grid paths with small inputs.
    pub fn set_test_limits(&mut self, dispatch_samples: usize, workgroups_per_dimension: u32) {
        self.dispatch_samples = Some(dispatch_samples);
        self.grid_dim = Some(workgroups_per_dimension);
    }

    pub(crate) fn dispatch_samples_override(&self) -> Option<usize> {
        self.dispatch_samples
    }

    /// Workgroup grid for `n` workgroups: x up to the per-dimension limit, then y.
    pub(crate) fn grid(&self, n: u32) -> (u32, u32) {
        let max = self
            .grid_dim
            .unwrap_or(self.limits.max_compute_workgroups_per_dimension)
            .max(1);
        if n <= max {
            (n, 1)
        } else {
            (max, n.div_ceil(max))
        }
    }
}
