//! Host side of the chunk kernels (`shaders/telemetry_reduce.wgsl`,
//! `shaders/energy_map.wgsl`): one workgroup per chunk of one wheel, writing
//! either one partial result of fixed length per chunk (the reduction) or
//! adding into one result per wheel (the maps, integer atomics). Pipelines
//! are built once, buffers grown on demand and reused, batches cut at chunk
//! boundaries so no binding exceeds the device's limit, grids over 65 535
//! workgroups in 2-D.

use super::{GpuContext, GpuError, GpuTimings};
use crate::kpi::energy_map::EnergyMaps;
use crate::kpi::energy_map_kernel::BINS;
use crate::kpi::energy_map_kernel::maps_from_quanta;
use crate::kpi::telemetry_reduce::{CHUNK, ReduceBatch, ReduceChunk, ReduceSample, SUMS};
use std::sync::Mutex;
use std::time::Instant;
use wgpu::util::DeviceExt;

struct Scratch {
    samples: wgpu::Buffer,
    chunks: wgpu::Buffer,
    partials: wgpu::Buffer,
    readback: wgpu::Buffer,
}

/// What a chunk kernel's last binding holds.
#[derive(Clone, Copy)]
pub(crate) enum Output {
    /// This many f32 per chunk, read back after every dispatch.
    PerChunk(usize),
    /// This many u32 per wheel of the batch, zeroed once, added to by every
    /// dispatch of the batch and read back at its end.
    PerWheel(usize),
}

pub(crate) struct ChunkKernel {
    name: &'static str,
    output: Output,
    /// Whether binding 2 is the per-wheel reference buffer (then partials are binding 3).
    uses_refs: bool,
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    scratch: Mutex<Option<(u64, u64, Scratch)>>,
}

fn storage(
    device: &wgpu::Device,
    label: &str,
    size: u64,
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(16),
        usage,
        mapped_at_creation: false,
    })
}

impl ChunkKernel {
    pub(crate) fn new(
        device: &wgpu::Device,
        name: &'static str,
        source: wgpu::ShaderModuleDescriptor,
        output: Output,
        uses_refs: bool,
    ) -> Result<Self, GpuError> {
        let (pipeline, layout) = super::compute_pipeline(device, name, source)?;
        Ok(ChunkKernel {
            name,
            output,
            uses_refs,
            pipeline,
            layout,
            scratch: Mutex::new(None),
        })
    }
}

impl GpuContext {
    /// Largest number of samples one dispatch may bind.
    fn max_samples_per_dispatch(&self) -> usize {
        let limit = self
            .limits
            .max_storage_buffer_binding_size
            .min(self.limits.max_buffer_size);
        let device = (limit as usize / size_of::<ReduceSample>()).max(CHUNK);
        self.dispatch_samples_override()
            .map_or(device, |o| o.clamp(CHUNK, device))
    }

    /// Every chunk's partial sums of the telemetry reduction (f32 on the
    /// device, returned as f64) and the time split.
    pub fn telemetry_reduce(
        &self,
        batch: &ReduceBatch,
    ) -> Result<(Vec<[f64; SUMS]>, GpuTimings), GpuError> {
        let (flat, t) = self.run_chunks(&self.telemetry_reduce, batch)?;
        let sums = flat
            .chunks_exact(SUMS)
            .map(|c| std::array::from_fn(|m| f32::from_bits(c[m]) as f64))
            .collect();
        Ok((sums, t))
    }

    /// Every wheel's energy maps (exact sums of fixed-point quanta on the
    /// device) and the time split.
    pub fn energy_map(
        &self,
        batch: &ReduceBatch,
    ) -> Result<(Vec<EnergyMaps>, GpuTimings), GpuError> {
        let (words, t) = self.run_chunks(&self.energy_map, batch)?;
        let quanta: Vec<u64> = words
            .chunks_exact(2)
            .map(|w| w[0] as u64 | (w[1] as u64) << 32)
            .collect();
        debug_assert_eq!(quanta.len(), batch.wheels() * BINS);
        Ok((maps_from_quanta(&quanta), t))
    }

    /// The kernel over a whole batch: its output words (per chunk, or per
    /// wheel) and the time split.
    fn run_chunks(
        &self,
        k: &ChunkKernel,
        batch: &ReduceBatch,
    ) -> Result<(Vec<u32>, GpuTimings), GpuError> {
        let mut out = Vec::new();
        let mut timings = GpuTimings::default();
        // Per-wheel outputs: one zeroed buffer for the whole batch (wgpu
        // zero-initialises new buffers).
        let per_wheel = match k.output {
            Output::PerWheel(n) => {
                let bytes = (batch.wheels() * n * 4) as u64;
                use wgpu::BufferUsages as U;
                let b = storage(&self.device, "maps", bytes, U::STORAGE | U::COPY_SRC);
                Some((b, bytes))
            }
            Output::PerChunk(_) => None,
        };
        let refs = self
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("refs"),
                contents: bytemuck::cast_slice(&batch.refs),
                usage: wgpu::BufferUsages::STORAGE,
            });
        // Cut the batch at chunk boundaries so the sample binding stays in limits.
        let max = self.max_samples_per_dispatch();
        let mut first = 0;
        while first < batch.chunks.len() {
            let start = batch.chunks[first].start as usize;
            let mut last = first;
            while last < batch.chunks.len() {
                let c = &batch.chunks[last];
                if c.start as usize + c.count as usize - start > max {
                    break;
                }
                last += 1;
            }
            let end = batch.chunks[last - 1].start as usize + batch.chunks[last - 1].count as usize;
            let chunks: Vec<ReduceChunk> = batch.chunks[first..last]
                .iter()
                .map(|c| ReduceChunk {
                    start: c.start - start as u32,
                    ..*c
                })
                .collect();
            let shared = per_wheel.as_ref().map(|(b, n)| (b, *n));
            let (p, t) = self.dispatch(k, &batch.samples[start..end], &chunks, &refs, shared)?;
            out.extend(p);
            timings.add(&t);
            first = last;
        }
        if let Some((maps, bytes)) = &per_wheel {
            let t0 = Instant::now();
            let readback = storage(
                &self.device,
                "maps readback",
                *bytes,
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            );
            let mut enc = self.device.create_command_encoder(&Default::default());
            enc.copy_buffer_to_buffer(maps, 0, &readback, 0, *bytes);
            self.queue.submit([enc.finish()]);
            let b = self.read_back(&readback, *bytes)?;
            out = bytemuck::cast_slice::<u8, u32>(&b).to_vec();
            timings.readback += t0.elapsed();
        }
        Ok((out, timings))
    }

    fn dispatch(
        &self,
        k: &ChunkKernel,
        samples: &[ReduceSample],
        chunks: &[ReduceChunk],
        refs: &wgpu::Buffer,
        shared: Option<(&wgpu::Buffer, u64)>,
    ) -> Result<(Vec<u32>, GpuTimings), GpuError> {
        let sample_bytes = size_of_val(samples) as u64;
        let chunk_bytes = size_of_val(chunks) as u64;
        let per_chunk = match k.output {
            Output::PerChunk(n) => n,
            Output::PerWheel(_) => 0,
        };
        let partial_bytes = (chunks.len() * per_chunk * 4) as u64;
        let mut guard = k.scratch.lock().expect("scratch lock");
        let fits = matches!(&*guard, Some((s, c, _)) if *s >= sample_bytes && *c >= chunk_bytes);
        if !fits {
            let (s, c) = (
                sample_bytes.next_power_of_two(),
                chunk_bytes.next_power_of_two(),
            );
            let p = c / size_of::<ReduceChunk>() as u64 * per_chunk as u64 * 4;
            use wgpu::BufferUsages as U;
            *guard = Some((
                s,
                c,
                Scratch {
                    samples: storage(&self.device, "samples", s, U::STORAGE | U::COPY_DST),
                    chunks: storage(&self.device, "chunks", c, U::STORAGE | U::COPY_DST),
                    partials: storage(&self.device, "partials", p, U::STORAGE | U::COPY_SRC),
                    readback: storage(&self.device, "readback", p, U::MAP_READ | U::COPY_DST),
                },
            ));
        }
        let sc = &guard.as_ref().expect("scratch").2;
        let mut t = GpuTimings::default();
        let t0 = Instant::now();
        self.queue
            .write_buffer(&sc.samples, 0, bytemuck::cast_slice(samples));
        self.queue
            .write_buffer(&sc.chunks, 0, bytemuck::cast_slice(chunks));
        self.queue.submit([]);
        self.wait()?;
        t.upload = t0.elapsed();

        fn bind(b: &wgpu::Buffer, size: u64) -> wgpu::BindingResource<'_> {
            wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: b,
                offset: 0,
                size: wgpu::BufferSize::new(size.max(4)),
            })
        }
        let mut entries = vec![
            wgpu::BindGroupEntry {
                binding: 0,
                resource: bind(&sc.samples, sample_bytes),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: bind(&sc.chunks, chunk_bytes),
            },
        ];
        if k.uses_refs {
            entries.push(wgpu::BindGroupEntry {
                binding: 2,
                resource: refs.as_entire_binding(),
            });
        }
        entries.push(wgpu::BindGroupEntry {
            binding: entries.len() as u32,
            resource: match shared {
                Some((b, bytes)) => bind(b, bytes),
                None => bind(&sc.partials, partial_bytes),
            },
        });
        let group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(k.name),
            layout: &k.layout,
            entries: &entries,
        });
        let t0 = Instant::now();
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut enc = self.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&k.pipeline);
            pass.set_bind_group(0, &group, &[]);
            let (x, y) = self.grid(chunks.len() as u32);
            pass.dispatch_workgroups(x, y, 1);
        }
        self.queue.submit([enc.finish()]);
        self.wait()?;
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Validation {
                kernel: k.name,
                message: e.to_string(),
            });
        }
        t.compute = t0.elapsed();

        if shared.is_some() {
            return Ok((Vec::new(), t));
        }
        let t0 = Instant::now();
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(&sc.partials, 0, &sc.readback, 0, partial_bytes);
        self.queue.submit([enc.finish()]);
        let bytes = self.read_back(&sc.readback, partial_bytes)?;
        let out = bytemuck::cast_slice::<u8, u32>(&bytes).to_vec();
        t.readback = t0.elapsed();
        Ok((out, t))
    }
}
