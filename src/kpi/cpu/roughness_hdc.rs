//! CPU twin of `shaders/roughness_hdc.wgsl`: per chunk (profile, lag k),
//! Σ (z[i + k] − z[i])² over the chunk's i, each thread adding its items,
//! then the tree (f64 here, f32 there).

use super::telemetry_reduce::{ITEMS, WG_SIZE};
use crate::kpi::roughness_batch::RoughnessBatch;
use rayon::prelude::*;

pub fn roughness_hdc(batch: &RoughnessBatch) -> Vec<f64> {
    batch
        .hdc_chunks
        .par_iter()
        .map(|c| {
            let mut acc = [0.0f64; WG_SIZE];
            for (lid, s) in acc.iter_mut().enumerate() {
                for k in 0..ITEMS {
                    let j = lid + k * WG_SIZE;
                    if j < c.count as usize {
                        let i = c.start as usize + j;
                        let d = batch.heights[i + c.lag as usize] as f64 - batch.heights[i] as f64;
                        *s += d * d;
                    }
                }
            }
            let mut stride = WG_SIZE / 2;
            while stride > 0 {
                for lid in 0..stride {
                    acc[lid] += acc[lid + stride];
                }
                stride /= 2;
            }
            acc[0]
        })
        .collect()
}
