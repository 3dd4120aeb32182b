//! CPU twin of `shaders/roughness_moments.wgsl`: per chunk of one profile,
//! Σd, Σ|d|, Σd², Σd³, Σd⁴ with d = z − ref(profile), each thread adding its
//! items, then the shared-memory tree (f64 here, f32 there). Run twice: with
//! ref = the first height (for the mean), then with ref = the mean.

use super::telemetry_reduce::{ITEMS, WG_SIZE};
use crate::kpi::roughness_batch::{MOMENT_SUMS, RoughnessBatch};
use rayon::prelude::*;

pub fn roughness_moments(batch: &RoughnessBatch, refs: &[f32]) -> Vec<[f64; MOMENT_SUMS]> {
    batch
        .moment_chunks
        .par_iter()
        .map(|c| {
            let r = refs[c.profile as usize] as f64;
            let mut acc = [[0.0f64; MOMENT_SUMS]; WG_SIZE];
            for (lid, s) in acc.iter_mut().enumerate() {
                for k in 0..ITEMS {
                    let j = lid + k * WG_SIZE;
                    if j < c.count as usize {
                        let d = batch.heights[c.start as usize + j] as f64 - r;
                        let d2 = d * d;
                        s[0] += d;
                        s[1] += d.abs();
                        s[2] += d2;
                        s[3] += d2 * d;
                        s[4] += d2 * d2;
                    }
                }
            }
            let mut stride = WG_SIZE / 2;
            while stride > 0 {
                for lid in 0..stride {
                    let other = acc[lid + stride];
                    for (a, o) in acc[lid].iter_mut().zip(other) {
                        *a += o;
                    }
                }
                stride /= 2;
            }
            acc[0]
        })
        .collect()
}
