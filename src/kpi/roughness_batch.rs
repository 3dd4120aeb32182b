//! Road profiles as the roughness kernels take them: heights as f32 back to
//! back, cut into chunks (moments, HDC) and Welch segments (PSD), and the
//! CPU-side merge of the kernels' partial results. The kernels, each a
//! shader with its CPU twin of the same name: `roughness_moments`,
//! `roughness_hdc`, `roughness_window`, `fft_pass`, `roughness_psd`.
//!
//! The GPU PSD needs segments of exactly [`WELCH_SEGMENT`] samples (a power
//! of two); shorter profiles are reduced on the CPU by every engine.

use super::cpu::telemetry_reduce::CHUNK;
use super::road::{HDC_LAGS, WELCH_SEGMENT, hdc_lags};
use bytemuck::{Pod, Zeroable};

/// FFT length of the GPU PSD. Must match `N` in the roughness shaders (checked by tests/shader_contract.rs).
pub const FFT_N: usize = WELCH_SEGMENT;
/// Segments per batch: 4096 × 4096 complex f32 = 128 MiB, WebGPU's default
/// (and guaranteed) largest storage binding.
pub const MAX_BATCH_SEGMENTS: usize = 4096;
/// Sums per moments chunk: Σd, Σ|d|, Σd², Σd³, Σd⁴ with d = z − ref.
pub const MOMENT_SUMS: usize = 5;

/// A chunk of one profile. Must match `Chunk` in roughness_moments.wgsl (checked by tests/shader_contract.rs).
/// and roughness_hdc.wgsl. `lag` is 0 for moments, the HDC lag in samples otherwise.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct RoughChunk {
    pub start: u32,
    pub count: u32,
    pub profile: u32,
    pub lag: u32,
}

/// A Welch segment. Must match `Segment` in roughness_window.wgsl (checked by tests/shader_contract.rs).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct Segment {
    pub start: u32,
    pub profile: u32,
}

/// Per-profile PSD parameters. Must match `PsdProfile` in roughness_psd.wgsl (checked by tests/shader_contract.rs).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct PsdProfile {
    pub seg_first: u32,
    pub seg_count: u32,
    pub dx_mm: f32,
    pub pad: u32,
}

/// Profiles ready for the kernels.
#[derive(Debug, Clone, Default)]
pub struct RoughnessBatch {
    pub heights: Vec<f32>,
    /// (offset, length, Δx in mm) per profile.
    pub spans: Vec<(usize, usize, f64)>,
    pub moment_chunks: Vec<RoughChunk>,
    /// HDC chunks; a profile's lags are those of `road::hdc`.
    pub hdc_chunks: Vec<RoughChunk>,
    pub hdc_lags: Vec<Vec<usize>>,
    pub segments: Vec<Segment>,
    pub psd_profiles: Vec<PsdProfile>,
}

impl RoughnessBatch {
    /// Adds a profile of at least `FFT_N` samples; returns its index.
    pub fn push(&mut self, z_mm: &[f64], dx_mm: f64) -> usize {
        assert!(z_mm.len() >= FFT_N, "the GPU PSD needs {FFT_N} samples");
        let p = self.spans.len();
        let off = self.heights.len();
        let n = z_mm.len();
        self.heights.extend(z_mm.iter().map(|&v| v as f32));
        self.spans.push((off, n, dx_mm));
        for s in (0..n).step_by(CHUNK) {
            self.moment_chunks.push(RoughChunk {
                start: (off + s) as u32,
                count: CHUNK.min(n - s) as u32,
                profile: p as u32,
                lag: 0,
            });
        }
        let lags = hdc_lags(n);
        for &k in &lags {
            for s in (0..n - k).step_by(CHUNK) {
                self.hdc_chunks.push(RoughChunk {
                    start: (off + s) as u32,
                    count: CHUNK.min(n - k - s) as u32,
                    profile: p as u32,
                    lag: k as u32,
                });
            }
        }
        self.hdc_lags.push(lags);
        let first = self.segments.len();
        let mut start = 0;
        while start + FFT_N <= n {
            self.segments.push(Segment {
                start: (off + start) as u32,
                profile: p as u32,
            });
            start += FFT_N / 2;
        }
        self.psd_profiles.push(PsdProfile {
            seg_first: first as u32,
            seg_count: (self.segments.len() - first) as u32,
            dx_mm: dx_mm as f32,
            pad: 0,
        });
        p
    }

    /// Segments a profile of `n` samples adds.
    pub(crate) fn segments_of(n: usize) -> usize {
        (n - FFT_N) / (FFT_N / 2) + 1
    }

    pub fn len(&self) -> usize {
        self.spans.len()
    }

    pub fn is_empty(&self) -> bool {
        self.spans.is_empty()
    }

    /// Per-profile reference heights for the first moments pass (first sample).
    pub(crate) fn first_heights(&self) -> Vec<f32> {
        self.spans
            .iter()
            .map(|&(o, _, _)| self.heights[o])
            .collect()
    }
}

/// What the engines return per profile: the inputs of `road::profile_indices_from`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Spectral {
    /// (Ra, Rq, Sk, Ku) about the mean line.
    pub moments: (f64, f64, f64, f64),
    /// PSD at k = 1 .. N/2 − 1 (q in rad/mm, C in mm³), as `road::psd`.
    pub psd_q: Vec<f64>,
    pub psd_c: Vec<f64>,
    /// HDC at the lags of `road::hdc` (mm, mm²).
    pub hdc_lag_mm: Vec<f64>,
    pub hdc_c: Vec<f64>,
}

/// Per-profile means from the first moments pass (ref = first height).
pub fn means(batch: &RoughnessBatch, refs: &[f32], partials: &[[f64; MOMENT_SUMS]]) -> Vec<f64> {
    let mut s = vec![0.0; batch.len()];
    for (c, p) in batch.moment_chunks.iter().zip(partials) {
        s[c.profile as usize] += p[0];
    }
    s.iter()
        .zip(&batch.spans)
        .zip(refs)
        .map(|((s, &(_, n, _)), &r)| r as f64 + s / n as f64)
        .collect()
}

/// Assembles every profile's outputs from the kernels' results: moments from
/// the second pass (ref = the mean, as f32), HDC sums, and the PSD rows.
pub(crate) fn assemble(
    batch: &RoughnessBatch,
    centred: &[[f64; MOMENT_SUMS]],
    hdc_sums: &[f64],
    psd_rows: &[Vec<f64>],
) -> Vec<Spectral> {
    let mut m = vec![[0.0; MOMENT_SUMS]; batch.len()];
    for (c, p) in batch.moment_chunks.iter().zip(centred) {
        for i in 0..MOMENT_SUMS {
            m[c.profile as usize][i] += p[i];
        }
    }
    let mut h: Vec<Vec<f64>> = batch.hdc_lags.iter().map(|l| vec![0.0; l.len()]).collect();
    let mut next = vec![0usize; batch.len()];
    let mut last_lag = vec![u32::MAX; batch.len()];
    for (c, s) in batch.hdc_chunks.iter().zip(hdc_sums) {
        let p = c.profile as usize;
        if last_lag[p] != u32::MAX && last_lag[p] != c.lag {
            next[p] += 1;
        }
        last_lag[p] = c.lag;
        h[p][next[p]] += s;
    }
    (0..batch.len())
        .map(|p| {
            let (_, n, dx) = batch.spans[p];
            let nf = n as f64;
            let [s1, sa, s2, s3, s4] = m[p];
            // Moments about the mean from sums about ref ≈ mean (d̄ = s1/n is tiny).
            let d = s1 / nf;
            let m2 = s2 / nf - d * d;
            let m3 = s3 / nf - 3.0 * d * s2 / nf + 2.0 * d.powi(3);
            let m4 = s4 / nf - 4.0 * d * s3 / nf + 6.0 * d * d * s2 / nf - 3.0 * d.powi(4);
            let lags = &batch.hdc_lags[p];
            let len = FFT_N as f64 * dx;
            Spectral {
                moments: (sa / nf, m2.sqrt(), m3 / m2.powf(1.5), m4 / (m2 * m2)),
                psd_q: (1..FFT_N / 2)
                    .map(|k| std::f64::consts::TAU * k as f64 / len)
                    .collect(),
                psd_c: psd_rows[p][1..FFT_N / 2].to_vec(),
                hdc_lag_mm: lags.iter().map(|&k| k as f64 * dx).collect(),
                hdc_c: lags
                    .iter()
                    .zip(&h[p])
                    .map(|(&k, s)| s / (n - k) as f64)
                    .collect(),
            }
        })
        .collect()
}

const _: () = assert!(HDC_LAGS > 2);

/// Cuts profiles (heights, Δx) of at least `FFT_N` samples into batches of at
/// most [`MAX_BATCH_SEGMENTS`] segments; returns each batch with the indices
/// of its profiles. A profile longer than one batch gets a batch of its own
/// (`RoughnessBatch::push` refuses nothing; the GPU then splits no further and
/// the device's own limit applies).
pub fn batches(profiles: &[(&[f64], f64)]) -> Vec<(Vec<usize>, RoughnessBatch)> {
    let mut out: Vec<(Vec<usize>, RoughnessBatch)> = Vec::new();
    for (i, (z, dx)) in profiles.iter().enumerate() {
        let seg = RoughnessBatch::segments_of(z.len());
        let full = out
            .last()
            .is_none_or(|(_, b)| b.segments.len() + seg > MAX_BATCH_SEGMENTS && !b.is_empty());
        if full {
            out.push((Vec::new(), RoughnessBatch::default()));
        }
        let (ids, b) = out.last_mut().expect("a batch");
        b.push(z, *dx);
        ids.push(i);
    }
    out
}

/// The CPU twins in the shaders' order (the reference of the GPU roughness).
pub(crate) fn cpu_twins(batch: &RoughnessBatch) -> Vec<Spectral> {
    use super::cpu::{
        fft_pass::fft, roughness_hdc::roughness_hdc, roughness_moments::roughness_moments,
        roughness_psd::roughness_psd, roughness_window::roughness_window,
    };
    let first = batch.first_heights();
    let mean = means(batch, &first, &roughness_moments(batch, &first));
    let mean32: Vec<f32> = mean.iter().map(|&m| m as f32).collect();
    let centred = roughness_moments(batch, &mean32);
    let hdc = roughness_hdc(batch);
    let psd = roughness_psd(batch, &fft(roughness_window(batch)));
    assemble(batch, &centred, &hdc, &psd)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kpi::road::{hdc, height_moments, psd};

    /// A rough profile with a few scales and an offset (f32-exact samples,
    /// so the f64 route sees the same heights).
    fn profile(n: usize) -> Vec<f64> {
        (0..n)
            .map(|i| {
                let x = i as f64 * 0.01;
                let z = 3.0 + (x * 0.7).sin() + 0.3 * (x * 13.0).sin() + 0.05 * (x * 171.0).cos();
                z as f32 as f64
            })
            .collect()
    }

    #[test]
    fn twins_equal_the_f64_road_functions() {
        let mut b = RoughnessBatch::default();
        let (z1, z2) = (profile(20_000), profile(4096 + 777));
        b.push(&z1, 0.01);
        b.push(&z2, 0.02);
        let out = cpu_twins(&b);
        for (o, (z, dx)) in out.iter().zip([(&z1, 0.01), (&z2, 0.02)]) {
            let m = height_moments(z);
            // Ra is taken about the mean rounded to f32 (the shader's reference): ≤ 1e-6.
            assert!((o.moments.0 - m.0).abs() < 1e-6, "{} {}", o.moments.0, m.0);
            assert!((o.moments.1 - m.1).abs() < 1e-9, "{} {}", o.moments.1, m.1);
            assert!((o.moments.2 - m.2).abs() < 1e-9 && (o.moments.3 - m.3).abs() < 1e-9);
            let (q, c) = psd(z, dx);
            assert_eq!(o.psd_q.len(), q.len());
            for k in 0..q.len() {
                assert!((o.psd_q[k] - q[k]).abs() < 1e-9 * q[k]);
                // dx passes through f32 in the batch: 1e-7 relative.
                assert!(
                    (o.psd_c[k] - c[k]).abs() <= 1e-6 * c[k] + 1e-12 * c[0],
                    "k {k}: {} vs {}",
                    o.psd_c[k],
                    c[k]
                );
            }
            let (lag, h) = hdc(z, dx);
            assert_eq!(o.hdc_lag_mm, lag);
            for (a, b) in o.hdc_c.iter().zip(&h) {
                assert!((a - b).abs() < 1e-9 * b);
            }
        }
    }
}
