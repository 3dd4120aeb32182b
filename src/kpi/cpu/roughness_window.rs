//! CPU twin of `shaders/roughness_window.wgsl`: each Welch segment of
//! `FFT_N` heights, its mean removed, times the periodic Hann window scaled to
//! mean(w²) = 1, as complex numbers (imaginary part 0) for `fft_pass`.

use crate::kpi::roughness_batch::{FFT_N, RoughnessBatch};
use rayon::prelude::*;

/// √(3/8): the RMS of the periodic Hann window.
pub const HANN_RMS: f64 = 0.612_372_435_695_794_5;

pub fn roughness_window(batch: &RoughnessBatch) -> Vec<[f64; 2]> {
    let mut out = vec![[0.0; 2]; batch.segments.len() * FFT_N];
    out.par_chunks_mut(FFT_N)
        .zip(&batch.segments)
        .for_each(|(dst, seg)| {
            let z = &batch.heights[seg.start as usize..seg.start as usize + FFT_N];
            let mean = z.iter().map(|&v| v as f64).sum::<f64>() / FFT_N as f64;
            for (i, d) in dst.iter_mut().enumerate() {
                let w = 0.5 - 0.5 * (std::f64::consts::TAU * i as f64 / FFT_N as f64).cos();
                *d = [(z[i] as f64 - mean) * w / HANN_RMS, 0.0];
            }
        });
    out
}
