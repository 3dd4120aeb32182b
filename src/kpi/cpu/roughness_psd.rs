//! CPU twin of `shaders/roughness_psd.wgsl`: per profile and frequency k,
//! the Welch average of |X_k|² over the profile's segments in the
//! SurfaceTopography convention, C_k = Δx²/L·|X_k|² (L = N·Δx), as `road::psd`.

use crate::kpi::roughness_batch::{FFT_N, RoughnessBatch};
use rayon::prelude::*;

pub fn roughness_psd(batch: &RoughnessBatch, spectra: &[[f64; 2]]) -> Vec<Vec<f64>> {
    batch
        .psd_profiles
        .par_iter()
        .map(|p| {
            let dx = p.dx_mm as f64;
            let scale = dx * dx / (FFT_N as f64 * dx);
            (0..=FFT_N / 2)
                .map(|k| {
                    let mut acc = 0.0;
                    for s in p.seg_first..p.seg_first + p.seg_count {
                        let x = spectra[s as usize * FFT_N + k];
                        acc += x[0] * x[0] + x[1] * x[1];
                    }
                    acc * scale / p.seg_count as f64
                })
                .collect()
        })
        .collect()
}
