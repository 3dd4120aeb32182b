//! CPU twin of `shaders/energy_map.wgsl`: per chunk of one wheel, every
//! sample's friction energy binned into both energy maps and its lateral
//! part into the lateral map, as one partial map of `BINS` values; partials
//! are merged per wheel in f64. Phase 1 is the shader's loop for loop;
//! phase 2 adds each sample to its three bins in sample order, which is the
//! order in which the shader's owner thread of that bin adds it, so the two
//! differ only by f32 against f64.

use super::energy_map::{EnergyMaps, SLIDING_SPEED_BINS, T_INNER_BINS, T_SURFACE_BINS};
use super::telemetry_reduce::{CHUNK, ITEMS, ReduceBatch, ReduceChunk, WG_SIZE};
use rayon::prelude::*;

/// Bins of the (surface × inner) map. Must match `SURFACE_INNER_BINS` in the shader (checked by tests/shader_contract.rs).
pub const SURFACE_INNER_BINS: usize = 576;
/// First bin of the lateral map. Must match `LATERAL_BINS_AT` in the shader (checked by tests/shader_contract.rs).
pub const LATERAL_BINS_AT: usize = 1056;
/// Bins of the three maps. Must match `BINS` in the shader (checked by tests/shader_contract.rs).
pub const BINS: usize = 1632;

const _: () = assert!(SURFACE_INNER_BINS == T_SURFACE_BINS.n * T_INNER_BINS.n);
const _: () =
    assert!(LATERAL_BINS_AT == SURFACE_INNER_BINS + SLIDING_SPEED_BINS.n * T_SURFACE_BINS.n);
const _: () = assert!(BINS == LATERAL_BINS_AT + SURFACE_INNER_BINS);

fn workgroup(batch: &ReduceBatch, chunk: &ReduceChunk) -> Vec<f64> {
    let count = chunk.count as usize;
    let (mut bin_a, mut bin_b) = ([0usize; CHUNK], [0usize; CHUNK]);
    let (mut energy, mut energy_y) = ([0.0f64; CHUNK], [0.0f64; CHUNK]);
    // Phase 1.
    for lid in 0..WG_SIZE {
        for k in 0..ITEMS {
            let j = lid + k * WG_SIZE;
            if j < count {
                let p = &batch.samples[chunk.start as usize + j];
                let f = |x: f32| x as f64;
                let v_sx = f(p.vx) - f(p.omega) * f(p.radius); // eq. 21
                let v_sy = f(p.vy); // eq. 22
                let power = -f(p.fx) * v_sx - f(p.fy) * v_sy; // eqs. 23–25
                let s = T_SURFACE_BINS.index(f(p.t_surface));
                let i = T_INNER_BINS.index(f(p.t_inner));
                let v = SLIDING_SPEED_BINS.index((v_sx * v_sx + v_sy * v_sy).sqrt());
                bin_a[j] = s * T_INNER_BINS.n + i;
                bin_b[j] = SURFACE_INNER_BINS + v * T_SURFACE_BINS.n + s;
                energy[j] = power * (f(p.dt) + f(p.dt_lo));
                energy_y[j] = -f(p.fy) * v_sy * (f(p.dt) + f(p.dt_lo)); // eq. 24
            }
        }
    }
    // Phase 2.
    let mut out = vec![0.0; BINS];
    for j in 0..count {
        out[bin_a[j]] += energy[j];
        out[bin_b[j]] += energy[j];
        out[LATERAL_BINS_AT + bin_a[j]] += energy_y[j];
    }
    out
}

/// The CPU engine's kernel: every chunk's partial map (rayon over chunks).
pub fn energy_map(batch: &ReduceBatch) -> Vec<Vec<f64>> {
    batch
        .chunks
        .par_iter()
        .map(|c| workgroup(batch, c))
        .collect()
}

/// Merges chunk partials into each wheel's maps (f64, chunk order).
pub fn merge_maps(batch: &ReduceBatch, partials: &[Vec<f64>]) -> Vec<EnergyMaps> {
    let mut out = vec![EnergyMaps::new(); batch.wheels()];
    for (c, p) in batch.chunks.iter().zip(partials) {
        let m = &mut out[c.wheel as usize];
        for (d, s) in m.surface_inner.iter_mut().zip(&p[..SURFACE_INNER_BINS]) {
            *d += s;
        }
        for (d, s) in m
            .speed_surface
            .iter_mut()
            .zip(&p[SURFACE_INNER_BINS..LATERAL_BINS_AT])
        {
            *d += s;
        }
        for (d, s) in m
            .lateral_surface_inner
            .iter_mut()
            .zip(&p[LATERAL_BINS_AT..])
        {
            *d += s;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kpi::telemetry_reduce::ReduceSample;

    #[test]
    fn maps_by_hand_and_equal_to_per_sample_binning() {
        // Two kinds of samples: (T_s 82, T_i 101, v_s 0.5 → bins s 12, i 12, v 1)
        // with P = 1000 W, and (T_s 19 → bin 0, T_i 170 → last, v_s 12 → last) with P = 300 W.
        let (dt, dt_lo) = ReduceSample::split_dt(0.01);
        let a = ReduceSample {
            vx: 50.5,
            omega: 100.0,
            radius: 0.5,
            fx: -2000.0,
            t_surface: 82.0,
            t_inner: 101.0,
            dt,
            dt_lo,
            ..Default::default()
        };
        let b = ReduceSample {
            vy: 12.0,
            fy: -25.0,
            t_surface: 19.0,
            t_inner: 170.0,
            ..a
        };
        let b = ReduceSample {
            vx: 0.0,
            omega: 0.0,
            fx: 0.0,
            ..b
        };
        let mut wheel = vec![a; 1500];
        wheel.extend(vec![b; 700]);
        let mut batch = ReduceBatch::default();
        batch.push_wheel(&wheel);
        let m = &merge_maps(&batch, &energy_map(&batch))[0];
        let ea = 1000.0 * 0.01 * 1500.0;
        let eb = 300.0 * 0.01 * 700.0;
        assert!((m.surface_inner[12 * 24 + 12] - ea).abs() < 1e-9);
        assert!((m.speed_surface[24 + 12] - ea).abs() < 1e-9);
        assert!((m.surface_inner[23] - eb).abs() < 1e-9);
        assert!((m.speed_surface[19 * 24] - eb).abs() < 1e-9);
        assert!((m.total() - ea - eb).abs() < 1e-9);
        // Lateral map: only b slides sideways (−F_y·v_sy = 25·12 = 300 W).
        assert!((m.lateral_surface_inner[23] - eb).abs() < 1e-9);
        assert_eq!(m.lateral_surface_inner[12 * 24 + 12], 0.0);
        assert!((m.lateral_surface_inner.iter().sum::<f64>() - eb).abs() < 1e-9);
    }
}
