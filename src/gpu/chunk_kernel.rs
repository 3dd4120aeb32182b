//! Host side of the chunk kernels (`shaders/telemetry_reduce.wgsl`,
//! `shaders/energy_map.wgsl`): one workgroup per chunk of one wheel, writing
//! either one partial result of fixed length per chunk (the reduction) or
//! adding into one result per wheel (the maps, integer atomics). The
//! samples are uploaded once per batch piece and every kernel asked for runs
//! on them. Pipelines are built once, buffers grown on demand and reused,
//! batches cut at chunk boundaries so no binding exceeds the device's limit,
//! grids over 65 535 workgroups in 2-D.

use super::{GpuContext, GpuError, GpuTimings};
use crate::engine::Reductions;
use crate::kpi::cpu::condition_map::{ConditionMaps, condition_maps_from_quanta};
use crate::kpi::cpu::energy_map::{BINS, maps_from_quanta};
use crate::kpi::cpu::telemetry_reduce::{CHUNK, ReduceBatch, ReduceChunk, ReduceSample, SUMS};
use crate::kpi::energy_maps::EnergyMaps;
use std::sync::Mutex;
use std::time::Instant;
use wgpu::util::DeviceExt;

/// What a chunk kernel's last binding holds.
#[derive(Clone, Copy)]
pub(crate) enum Output {
    /// This many u32 per chunk, read back after every dispatch.
    PerChunk(usize),
    /// This many u32 per wheel of the batch, zeroed once, added to by every
    /// dispatch of the batch and read back at its end.
    PerWheel(usize),
}

/// The kernels' shared inputs, grown on demand: (sample bytes, chunk bytes, buffers).
pub(crate) type InputScratch = Mutex<Option<(u64, u64, Inputs)>>;

pub(crate) struct Inputs {
    samples: wgpu::Buffer,
    chunks: wgpu::Buffer,
    /// Host-visible copy sources of the same sizes, reused across uploads:
    /// `queue.write_buffer` allocates fresh staging memory on every call, and
    /// first touching a gigabyte of it cost most of the upload on an H200
    /// (docs/performance.md).
    staging_samples: wgpu::Buffer,
    staging_chunks: wgpu::Buffer,
}

/// Bytes per copy thread's share of the staging buffer, at least (smaller
/// uploads are copied by the calling thread).
const COPY_PIECE: usize = 4 << 20;

/// Copy threads at most: a few saturate the memory bus.
const COPY_THREADS: usize = 8;

/// A chunk kernel's binding 2, where it has one (then the output is binding 3).
#[derive(Clone, Copy, PartialEq)]
pub(crate) enum Extra {
    None,
    /// The batch's per-wheel reference values (`ReduceRef`).
    Refs,
    /// The condition-map bin table (`ConditionBins`), uploaded once.
    ConditionTable,
}

pub(crate) struct ChunkKernel {
    name: &'static str,
    output: Output,
    extra: Extra,
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    /// Per-chunk outputs and their readback buffer: (bytes, partials, readback).
    partials: Mutex<Option<(u64, wgpu::Buffer, wgpu::Buffer)>>,
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

/// Copies `src` to the start of the mapped `staging` buffer, spread over
/// short-lived threads of its own (one core's memcpy is slower than the
/// bus), at most as many as the rayon pool has; each maps its own disjoint
/// range of the buffer. Not the pool's threads: in a pipelined extraction
/// they can all be blocked handing decoded runs to the thread that called
/// this (a deadlock at season scale; `tests/engines.rs`,
/// `gpu_uploads_while_every_rayon_thread_is_blocked`).
fn fill(staging: &wgpu::Buffer, src: &[u8]) -> Result<(), GpuError> {
    let copy = |at: usize, piece: &[u8]| -> Result<(), GpuError> {
        let at = at as u64;
        staging
            .slice(at..at + piece.len() as u64)
            .get_mapped_range_mut()
            .map_err(|e| GpuError::Map(e.to_string()))?
            .copy_from_slice(piece);
        Ok(())
    };
    // As many as the global pool has threads (`--jobs`), though none of them.
    let threads = rayon::current_num_threads()
        .min(COPY_THREADS)
        .min(src.len() / COPY_PIECE)
        .max(1);
    if threads == 1 {
        return if src.is_empty() { Ok(()) } else { copy(0, src) };
    }
    copy_in_threads(src, threads, copy)
}

/// Runs `copy(offset, share)` over `src` cut into `threads` shares of
/// whole [`COPY_PIECE`]s (the last one shorter), one plain thread each.
/// Each thread catches its own panic: a plain thread is no rayon worker,
/// so only a catch on it keeps the panic off standard error and gives its
/// place to the run's error.
fn copy_in_threads(
    src: &[u8],
    threads: usize,
    copy: impl Fn(usize, &[u8]) -> Result<(), GpuError> + Sync,
) -> Result<(), GpuError> {
    // Shares in whole pieces keep every mapped range 8-byte aligned.
    let share = src.len().div_ceil(threads).div_ceil(COPY_PIECE) * COPY_PIECE;
    let copy = &copy;
    std::thread::scope(|s| {
        let copies: Vec<_> = src
            .chunks(share)
            .enumerate()
            .map(|(i, piece)| s.spawn(move || crate::guard::catch_panic(|| copy(i * share, piece))))
            .collect();
        copies.into_iter().try_for_each(|c| match c.join() {
            Ok(Ok(copied)) => copied,
            Ok(Err(why)) => Err(GpuError::Map(format!(
                "a staging copy thread panicked: {why}"
            ))),
            Err(_) => Err(GpuError::Map("a staging copy thread panicked".into())),
        })
    })
}

fn bind(b: &wgpu::Buffer, size: u64) -> wgpu::BindingResource<'_> {
    wgpu::BindingResource::Buffer(wgpu::BufferBinding {
        buffer: b,
        offset: 0,
        size: wgpu::BufferSize::new(size.max(4)),
    })
}

impl ChunkKernel {
    pub(crate) fn new(
        device: &wgpu::Device,
        name: &'static str,
        source: wgpu::ShaderModuleDescriptor,
        output: Output,
        extra: Extra,
    ) -> Result<Self, GpuError> {
        let (pipeline, layout) = super::compute_pipeline(device, name, source)?;
        Ok(ChunkKernel {
            name,
            output,
            extra,
            pipeline,
            layout,
            partials: Mutex::new(None),
        })
    }
}

/// Where one kernel writes during one batch.
enum Target<'a> {
    /// Its own per-chunk buffers (this many words a chunk), read back after
    /// each dispatch into the vector.
    PerChunk(Vec<u32>, usize),
    /// The batch's per-wheel buffer (and its size in bytes).
    PerWheel(&'a wgpu::Buffer, u64),
}

fn per_chunk_words(sums: &[u32]) -> Vec<[f64; SUMS]> {
    sums.chunks_exact(SUMS)
        .map(|c| std::array::from_fn(|m| f32::from_bits(c[m]) as f64))
        .collect()
}

/// (lo, hi) u32 pairs as u64 sums of quanta.
fn quanta(words: &[u32]) -> Vec<u64> {
    words
        .chunks_exact(2)
        .map(|w| w[0] as u64 | (w[1] as u64) << 32)
        .collect()
}

fn maps_from_words(words: &[u32]) -> Vec<EnergyMaps> {
    maps_from_quanta(&quanta(words))
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
        let (out, t) = self.run_chunks(&[&self.telemetry_reduce], batch)?;
        Ok((per_chunk_words(&out[0]), t))
    }

    /// Every wheel's energy maps (exact sums of fixed-point quanta on the
    /// device) and the time split.
    pub fn energy_map(
        &self,
        batch: &ReduceBatch,
    ) -> Result<(Vec<EnergyMaps>, GpuTimings), GpuError> {
        let (out, t) = self.run_chunks(&[&self.energy_map], batch)?;
        debug_assert_eq!(out[0].len(), batch.wheels() * 2 * BINS);
        Ok((maps_from_words(&out[0]), t))
    }

    /// Every wheel's condition maps and the time split.
    pub fn condition_map(
        &self,
        batch: &ReduceBatch,
    ) -> Result<(Vec<ConditionMaps>, GpuTimings), GpuError> {
        let (out, t) = self.run_chunks(&[&self.condition_map], batch)?;
        Ok((condition_maps_from_quanta(&quanta(&out[0])), t))
    }

    /// All three: the samples cross the bus once for the three kernels.
    pub fn reductions(&self, batch: &ReduceBatch) -> Result<(Reductions, GpuTimings), GpuError> {
        let kernels = [
            &self.telemetry_reduce,
            &self.energy_map,
            &self.condition_map,
        ];
        let (out, t) = self.run_chunks(&kernels, batch)?;
        Ok((
            Reductions {
                partials: per_chunk_words(&out[0]),
                energy_maps: maps_from_words(&out[1]),
                condition_maps: condition_maps_from_quanta(&quanta(&out[2])),
            },
            t,
        ))
    }

    /// The kernels over a whole batch: each one's output words (per chunk,
    /// or per wheel) and the time split.
    fn run_chunks(
        &self,
        kernels: &[&ChunkKernel],
        batch: &ReduceBatch,
    ) -> Result<(Vec<Vec<u32>>, GpuTimings), GpuError> {
        let mut timings = GpuTimings::default();
        let refs = self
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("refs"),
                contents: bytemuck::cast_slice(&batch.refs),
                usage: wgpu::BufferUsages::STORAGE,
            });
        // Per-wheel outputs: one buffer per kernel for the whole batch (wgpu
        // zero-initialises new buffers).
        let per_wheel: Vec<Option<(wgpu::Buffer, u64)>> = kernels
            .iter()
            .map(|k| match k.output {
                Output::PerWheel(n) => {
                    let bytes = (batch.wheels() * n * 4) as u64;
                    use wgpu::BufferUsages as U;
                    let b = storage(&self.device, "maps", bytes, U::STORAGE | U::COPY_SRC);
                    Some((b, bytes))
                }
                Output::PerChunk(_) => None,
            })
            .collect();
        let mut targets: Vec<Target> = per_wheel
            .iter()
            .zip(kernels)
            .map(|(p, k)| match (p, k.output) {
                (Some((b, n)), _) => Target::PerWheel(b, *n),
                (None, Output::PerChunk(n)) | (None, Output::PerWheel(n)) => {
                    Target::PerChunk(Vec::new(), n)
                }
            })
            .collect();
        let mut inputs = self.chunk_inputs.lock().expect("inputs lock");
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
            let samples = &batch.samples[start..end];
            let t0 = Instant::now();
            let input = self.upload(&mut inputs, samples, &chunks)?;
            timings.upload += t0.elapsed();
            for (k, target) in kernels.iter().zip(&mut targets) {
                let t = self.dispatch(k, input, samples, &chunks, &refs, target)?;
                timings.add(&t);
            }
            first = last;
        }
        let mut out = Vec::with_capacity(kernels.len());
        for target in targets {
            out.push(match target {
                Target::PerChunk(words, _) => words,
                Target::PerWheel(maps, bytes) => {
                    let t0 = Instant::now();
                    let readback = storage(
                        &self.device,
                        "maps readback",
                        bytes,
                        wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    );
                    let mut enc = self.device.create_command_encoder(&Default::default());
                    enc.copy_buffer_to_buffer(maps, 0, &readback, 0, bytes);
                    self.queue.submit([enc.finish()]);
                    let b = self.read_back(&readback, bytes)?;
                    timings.readback += t0.elapsed();
                    bytemuck::cast_slice::<u8, u32>(&b).to_vec()
                }
            });
        }
        Ok((out, timings))
    }

    /// Writes one piece's samples and chunks into the shared input buffers
    /// (grown to the next power of two when too small) through the reused
    /// staging buffers, and waits until the queue is idle, so the upload is
    /// timed on its own.
    fn upload<'a>(
        &self,
        guard: &'a mut Option<(u64, u64, Inputs)>,
        samples: &[ReduceSample],
        chunks: &[ReduceChunk],
    ) -> Result<&'a Inputs, GpuError> {
        let sample_bytes = size_of_val(samples) as u64;
        let chunk_bytes = size_of_val(chunks) as u64;
        let fits = matches!(&*guard, Some((s, c, _)) if *s >= sample_bytes && *c >= chunk_bytes);
        if !fits {
            let (s, c) = (
                sample_bytes.next_power_of_two(),
                chunk_bytes.next_power_of_two(),
            );
            use wgpu::BufferUsages as U;
            *guard = None; // the old buffers go before the new ones are made
            *guard = Some((
                s,
                c,
                Inputs {
                    samples: storage(&self.device, "samples", s, U::STORAGE | U::COPY_DST),
                    chunks: storage(&self.device, "chunks", c, U::STORAGE | U::COPY_DST),
                    staging_samples: storage(
                        &self.device,
                        "staged samples",
                        s,
                        U::MAP_WRITE | U::COPY_SRC,
                    ),
                    staging_chunks: storage(
                        &self.device,
                        "staged chunks",
                        c,
                        U::MAP_WRITE | U::COPY_SRC,
                    ),
                },
            ));
        }
        let input = &guard.as_ref().expect("inputs").2;
        let staged: Vec<_> = [
            (&input.staging_samples, &input.samples, sample_bytes),
            (&input.staging_chunks, &input.chunks, chunk_bytes),
        ]
        .into_iter()
        .filter(|(_, _, bytes)| *bytes > 0)
        .collect();
        let (tx, rx) = std::sync::mpsc::channel();
        for &(staging, _, bytes) in &staged {
            let tx = tx.clone();
            staging
                .slice(..bytes)
                .map_async(wgpu::MapMode::Write, move |r| {
                    let _ = tx.send(r);
                });
        }
        drop(tx);
        self.wait()?;
        // Every mapping answered once the device is idle; a failed one
        // leaves the buffers as they are (the device is then likely lost).
        let answers: Vec<_> = rx.try_iter().collect();
        if answers.len() != staged.len() {
            return Err(GpuError::Map("a staging buffer was not mapped".into()));
        }
        for answer in answers {
            answer.map_err(|e| GpuError::Map(e.to_string()))?;
        }
        let filled = fill(&input.staging_samples, bytemuck::cast_slice(samples))
            .and_then(|()| fill(&input.staging_chunks, bytemuck::cast_slice(chunks)));
        let mut enc = self.device.create_command_encoder(&Default::default());
        for (staging, target, bytes) in staged {
            staging.unmap();
            enc.copy_buffer_to_buffer(staging, 0, target, 0, bytes);
        }
        filled?;
        self.queue.submit([enc.finish()]);
        self.wait()?;
        Ok(input)
    }

    fn dispatch(
        &self,
        k: &ChunkKernel,
        input: &Inputs,
        samples: &[ReduceSample],
        chunks: &[ReduceChunk],
        refs: &wgpu::Buffer,
        target: &mut Target,
    ) -> Result<GpuTimings, GpuError> {
        let sample_bytes = size_of_val(samples) as u64;
        let chunk_bytes = size_of_val(chunks) as u64;
        let mut t = GpuTimings::default();
        let mut partials = k.partials.lock().expect("partials lock");
        let out_binding = match &*target {
            Target::PerWheel(b, bytes) => bind(b, *bytes),
            Target::PerChunk(_, n) => {
                let bytes = (chunks.len() * n * 4) as u64;
                if !matches!(&*partials, Some((p, _, _)) if *p >= bytes) {
                    let p = bytes.next_power_of_two();
                    use wgpu::BufferUsages as U;
                    *partials = Some((
                        p,
                        storage(&self.device, "partials", p, U::STORAGE | U::COPY_SRC),
                        storage(&self.device, "readback", p, U::MAP_READ | U::COPY_DST),
                    ));
                }
                bind(&partials.as_ref().expect("partials").1, bytes)
            }
        };
        let mut entries = vec![
            wgpu::BindGroupEntry {
                binding: 0,
                resource: bind(&input.samples, sample_bytes),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: bind(&input.chunks, chunk_bytes),
            },
        ];
        let extra = match k.extra {
            Extra::None => None,
            Extra::Refs => Some(refs),
            Extra::ConditionTable => Some(&self.condition_table),
        };
        if let Some(b) = extra {
            entries.push(wgpu::BindGroupEntry {
                binding: 2,
                resource: b.as_entire_binding(),
            });
        }
        entries.push(wgpu::BindGroupEntry {
            binding: entries.len() as u32,
            resource: out_binding,
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

        if let Target::PerChunk(words, n) = target {
            let bytes = (chunks.len() * *n * 4) as u64;
            let (_, p, readback) = partials.as_ref().expect("partials");
            let t0 = Instant::now();
            let mut enc = self.device.create_command_encoder(&Default::default());
            enc.copy_buffer_to_buffer(p, 0, readback, 0, bytes);
            self.queue.submit([enc.finish()]);
            let b = self.read_back(readback, bytes)?;
            words.extend_from_slice(bytemuck::cast_slice::<u8, u32>(&b));
            t.readback = t0.elapsed();
        }
        Ok(t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    /// 5 pieces and 123 bytes over 3 threads: shares of ⌈(5 P + 123) / 3 / P⌉
    /// = 2 pieces, at 0, 2 P and 4 P, the last P + 123 bytes long.
    #[test]
    fn copies_cover_the_source_in_whole_pieces_and_a_panic_is_the_error() {
        let src: Vec<u8> = (0..5 * COPY_PIECE + 123).map(|i| (i % 251) as u8).collect();
        let got = Mutex::new(Vec::new());
        copy_in_threads(&src, 3, |at, piece| {
            got.lock().unwrap().push((at, piece.to_vec()));
            Ok(())
        })
        .unwrap();
        let mut got = got.into_inner().unwrap();
        got.sort_by_key(|g| g.0);
        let offsets: Vec<usize> = got.iter().map(|g| g.0).collect();
        assert_eq!(offsets, [0, 2 * COPY_PIECE, 4 * COPY_PIECE]);
        assert!(got.iter().flat_map(|g| &g.1).eq(&src));

        // A panic in one share's thread is the copy's error, with its
        // message; the other shares are copied.
        let copied = Mutex::new(0);
        let e = copy_in_threads(&src, 3, |at, piece| {
            if at == 2 * COPY_PIECE {
                panic!("share at {at} broke");
            }
            *copied.lock().unwrap() += piece.len();
            Ok(())
        })
        .unwrap_err();
        let said = format!(
            "a staging copy thread panicked: share at {} broke",
            2 * COPY_PIECE
        );
        assert!(
            matches!(&e, GpuError::Map(m) if m.starts_with(&said)),
            "{e}"
        );
        assert_eq!(copied.into_inner().unwrap(), src.len() - 2 * COPY_PIECE);

        // A copy's own error is returned as it is.
        let e = copy_in_threads(&src, 3, |at, _| match at {
            0 => Err(GpuError::Map("mapping refused".into())),
            _ => Ok(()),
        })
        .unwrap_err();
        assert!(
            matches!(&e, GpuError::Map(m) if m == "mapping refused"),
            "{e}"
        );
    }
}
