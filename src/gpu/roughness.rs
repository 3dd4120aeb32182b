//! Host side of the roughness kernels (`shaders/roughness_moments.wgsl`,
//! `roughness_hdc.wgsl`, `roughness_window.wgsl`, `fft_pass.wgsl`,
//! `roughness_psd.wgsl`): pipelines and the twiddle table built once; one
//! batch of profiles per call (callers cut batches at
//! `MAX_BATCH_SEGMENTS`), every grid spread in 2-D past 65 535 workgroups.

use super::{GpuContext, GpuError, GpuTimings};
use crate::kpi::cpu::fft_pass::twiddles;
use crate::kpi::roughness_batch::{FFT_N, MOMENT_SUMS, RoughnessBatch, Spectral, assemble, means};
use std::time::Instant;
use wgpu::util::DeviceExt;

struct Kernel {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

pub(crate) struct RoughnessKernels {
    moments: Kernel,
    hdc: Kernel,
    window: Kernel,
    fft: Kernel,
    psd: Kernel,
    twiddles: wgpu::Buffer,
    /// One uniform per FFT pass (Ns = 1, 2, …, N/2); `butterflies` is set per call.
    passes: Vec<wgpu::Buffer>,
}

fn kernel(
    device: &wgpu::Device,
    name: &'static str,
    source: wgpu::ShaderModuleDescriptor,
) -> Result<Kernel, GpuError> {
    let (pipeline, layout) = super::compute_pipeline(device, name, source)?;
    Ok(Kernel { pipeline, layout })
}

impl RoughnessKernels {
    pub(crate) fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        let tw: Vec<[f32; 2]> = twiddles()
            .iter()
            .map(|t| [t[0] as f32, t[1] as f32])
            .collect();
        let passes = std::iter::successors(Some(1u32), |ns| Some(ns * 2))
            .take_while(|&ns| (ns as usize) < FFT_N)
            .map(|_| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("fft pass"),
                    size: 16,
                    usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            })
            .collect();
        Ok(RoughnessKernels {
            moments: kernel(
                device,
                "roughness_moments",
                wgpu::include_wgsl!("../../shaders/roughness_moments.wgsl"),
            )?,
            hdc: kernel(
                device,
                "roughness_hdc",
                wgpu::include_wgsl!("../../shaders/roughness_hdc.wgsl"),
            )?,
            window: kernel(
                device,
                "roughness_window",
                wgpu::include_wgsl!("../../shaders/roughness_window.wgsl"),
            )?,
            fft: kernel(
                device,
                "fft_pass",
                wgpu::include_wgsl!("../../shaders/fft_pass.wgsl"),
            )?,
            psd: kernel(
                device,
                "roughness_psd",
                wgpu::include_wgsl!("../../shaders/roughness_psd.wgsl"),
            )?,
            twiddles: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("twiddles"),
                contents: bytemuck::cast_slice(&tw),
                usage: wgpu::BufferUsages::STORAGE,
            }),
            passes,
        })
    }
}

impl GpuContext {
    fn buffer<T: bytemuck::Pod>(
        &self,
        label: &str,
        data: &[T],
        extra: wgpu::BufferUsages,
    ) -> wgpu::Buffer {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        if bytes.is_empty() {
            return self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 16,
                usage: wgpu::BufferUsages::STORAGE | extra,
                mapped_at_creation: false,
            });
        }
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytes,
                usage: wgpu::BufferUsages::STORAGE | extra,
            })
    }

    fn empty(&self, label: &str, bytes: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes.max(16),
            usage,
            mapped_at_creation: false,
        })
    }

    /// Records one dispatch of `k` with `buffers` bound at 0, 1, 2, … over `groups` workgroups.
    fn record(
        &self,
        enc: &mut wgpu::CommandEncoder,
        k: &Kernel,
        buffers: &[&wgpu::Buffer],
        groups: u32,
    ) {
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: b.as_entire_binding(),
            })
            .collect();
        let group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &k.layout,
            entries: &entries,
        });
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(&k.pipeline);
        pass.set_bind_group(0, &group, &[]);
        let (x, y) = self.grid(groups.max(1));
        pass.dispatch_workgroups(x, y, 1);
    }

    fn submit_and_read(
        &self,
        enc: wgpu::CommandEncoder,
        out: &wgpu::Buffer,
        bytes: u64,
        t: &mut GpuTimings,
    ) -> Result<Vec<f32>, GpuError> {
        let t0 = Instant::now();
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        self.queue.submit([enc.finish()]);
        self.wait()?;
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Validation {
                kernel: "roughness",
                message: e.to_string(),
            });
        }
        t.compute += t0.elapsed();
        let t0 = Instant::now();
        let staging = self.empty(
            "readback",
            bytes,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        );
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(out, 0, &staging, 0, bytes);
        self.queue.submit([enc.finish()]);
        let raw = self.read_back(&staging, bytes)?;
        t.readback += t0.elapsed();
        Ok(bytemuck::cast_slice::<u8, f32>(&raw).to_vec())
    }

    /// Moments, HDC and Welch PSD of every profile of the batch.
    pub fn roughness(
        &self,
        batch: &RoughnessBatch,
    ) -> Result<(Vec<Spectral>, GpuTimings), GpuError> {
        let k = &self.roughness;
        let mut t = GpuTimings::default();
        if batch.is_empty() {
            return Ok((Vec::new(), t));
        }
        use wgpu::BufferUsages as U;
        let t0 = Instant::now();
        let heights = self.buffer("heights", &batch.heights, U::empty());
        let mchunks = self.buffer("moment chunks", &batch.moment_chunks, U::empty());
        let hchunks = self.buffer("hdc chunks", &batch.hdc_chunks, U::empty());
        let segments = self.buffer("segments", &batch.segments, U::empty());
        let profiles = self.buffer("psd profiles", &batch.psd_profiles, U::empty());
        let first = batch.first_heights();
        let refs0 = self.buffer("refs", &first, U::empty());
        let m_bytes = (batch.moment_chunks.len() * MOMENT_SUMS * 4) as u64;
        let h_bytes = (batch.hdc_chunks.len() * 4) as u64;
        let c_bytes = (batch.segments.len() * FFT_N * 8) as u64;
        let bins = FFT_N / 2 + 1;
        let p_bytes = (batch.len() * bins * 4) as u64;
        let moments = self.empty("moments", m_bytes, U::STORAGE | U::COPY_SRC);
        let hdc = self.empty("hdc", h_bytes, U::STORAGE | U::COPY_SRC);
        let (a, b) = (
            self.empty("fft a", c_bytes, U::STORAGE),
            self.empty("fft b", c_bytes, U::STORAGE),
        );
        let psd = self.empty("psd", p_bytes, U::STORAGE | U::COPY_SRC);
        let butterflies = (batch.segments.len() * FFT_N / 2) as u32;
        for (i, u) in k.passes.iter().enumerate() {
            self.queue
                .write_buffer(u, 0, bytemuck::cast_slice(&[1u32 << i, butterflies, 0, 0]));
        }
        self.queue.submit([]);
        self.wait()?;
        t.upload += t0.elapsed();

        // Pass 1 of the moments: about the first height, for the mean.
        let mut enc = self.device.create_command_encoder(&Default::default());
        self.record(
            &mut enc,
            &k.moments,
            &[&heights, &mchunks, &refs0, &moments],
            batch.moment_chunks.len() as u32,
        );
        let p1 = self.submit_and_read(enc, &moments, m_bytes, &mut t)?;
        let p1: Vec<[f64; MOMENT_SUMS]> = p1
            .chunks_exact(MOMENT_SUMS)
            .map(|c| std::array::from_fn(|i| c[i] as f64))
            .collect();
        let mean: Vec<f32> = means(batch, &first, &p1)
            .iter()
            .map(|&m| m as f32)
            .collect();
        let t0 = Instant::now();
        let refs1 = self.buffer("refs", &mean, U::empty());
        t.upload += t0.elapsed();

        // Pass 2 (about the mean), the HDC, and the PSD chain in one submission.
        let mut enc = self.device.create_command_encoder(&Default::default());
        self.record(
            &mut enc,
            &k.moments,
            &[&heights, &mchunks, &refs1, &moments],
            batch.moment_chunks.len() as u32,
        );
        self.record(
            &mut enc,
            &k.hdc,
            &[&heights, &hchunks, &hdc],
            batch.hdc_chunks.len() as u32,
        );
        self.record(
            &mut enc,
            &k.window,
            &[&heights, &segments, &a],
            batch.segments.len() as u32,
        );
        let groups = butterflies.div_ceil(256);
        let (mut src, mut dst) = (&a, &b);
        for u in &k.passes {
            self.record(&mut enc, &k.fft, &[u, src, dst, &k.twiddles], groups);
            std::mem::swap(&mut src, &mut dst);
        }
        self.record(
            &mut enc,
            &k.psd,
            &[src, &profiles, &psd],
            ((batch.len() * bins) as u32).div_ceil(256),
        );
        let psd_flat = self.submit_and_read(enc, &psd, p_bytes, &mut t)?;
        let enc = self.device.create_command_encoder(&Default::default());
        let m2 = self.submit_and_read(enc, &moments, m_bytes, &mut t)?;
        let enc = self.device.create_command_encoder(&Default::default());
        let h = self.submit_and_read(enc, &hdc, h_bytes, &mut t)?;

        let centred: Vec<[f64; MOMENT_SUMS]> = m2
            .chunks_exact(MOMENT_SUMS)
            .map(|c| std::array::from_fn(|i| c[i] as f64))
            .collect();
        let hdc_sums: Vec<f64> = h.iter().map(|&v| v as f64).collect();
        let rows: Vec<Vec<f64>> = psd_flat
            .chunks_exact(bins)
            .map(|r| r.iter().map(|&v| v as f64).collect())
            .collect();
        Ok((assemble(batch, &centred, &hdc_sums, &rows), t))
    }
}
