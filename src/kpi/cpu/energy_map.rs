//! CPU twin of `shaders/energy_map.wgsl`: per chunk of one wheel, every
//! sample's friction energy binned into both energy maps and its lateral
//! part into the lateral map, as fixed-point quanta in a private histogram
//! (phase 1) whose non-zero bins are then added to the wheel's map
//! (phase 2). The shader keeps each 64-bit sum as a (lo, hi) pair of u32
//! with an explicit carry; here a wrapping `u64` is the same number modulo
//! 2^64. Integer sums are exact in any order, so the two engines differ only
//! where an f32 energy (GPU) and an f64 one (here) round to different quanta
//! or land on different sides of a bin edge.

use super::telemetry_reduce::{ITEMS, ReduceBatch, ReduceChunk, ReduceSample, WG_SIZE};
use crate::kpi::energy_maps::{EnergyMaps, SLIDING_SPEED_BINS, T_INNER_BINS, T_SURFACE_BINS};
use rayon::prelude::*;

/// Bins of the (surface × inner) map. Must match `SURFACE_INNER_BINS` in the shader (checked by tests/shader_contract.rs).
pub const SURFACE_INNER_BINS: usize = 576;
/// First bin of the lateral map. Must match `LATERAL_BINS_AT` in the shader (checked by tests/shader_contract.rs).
pub const LATERAL_BINS_AT: usize = 1056;
/// Bins of the three maps. Must match `BINS` in the shader (checked by tests/shader_contract.rs).
pub const BINS: usize = 1632;
/// Fixed-point quanta per joule (2^24: a quantum is 6.0e-8 J; a bin holds up
/// to 2^63 quanta, 5.5e11 J). Must match `ENERGY_QUANTA_PER_J` in the shader
/// (checked by tests/shader_contract.rs).
pub const ENERGY_QUANTA_PER_J: f64 = 16_777_216.0;

const _: () = assert!(SURFACE_INNER_BINS == T_SURFACE_BINS.n * T_INNER_BINS.n);
const _: () =
    assert!(LATERAL_BINS_AT == SURFACE_INNER_BINS + SLIDING_SPEED_BINS.n * T_SURFACE_BINS.n);
const _: () = assert!(BINS == LATERAL_BINS_AT + SURFACE_INNER_BINS);

/// round(e · ENERGY_QUANTA_PER_J) in 64-bit two's complement (the shader's
/// `to_quanta`: ties to even, magnitude rounded then negated).
pub(crate) fn to_quanta(e: f64) -> u64 {
    let m = magnitude_to_u64(round_ties_even(e.abs() * ENERGY_QUANTA_PER_J));
    if e < 0.0 { m.wrapping_neg() } else { m }
}

/// `x as u64` for an integral x ≥ 0 (or NaN): below 2^63 one signed
/// conversion (what SSE2 has), where `as u64` takes two and a select
/// for every value; the rare rest (and NaN) as `as u64` converts them.
#[inline(always)]
fn magnitude_to_u64(x: f64) -> u64 {
    const TWO_63: f64 = 9_223_372_036_854_775_808.0;
    if x < TWO_63 {
        // SAFETY: 0 ≤ x < 2^63 here (NaN fails the test), so the value
        // fits an i64 and the conversion is exact.
        unsafe { x.to_int_unchecked::<i64>() as u64 }
    } else {
        x as u64
    }
}

/// `x.round_ties_even()` for x ≥ 0 (and NaN) without the libcall that
/// baseline x86-64 (no SSE4.1) makes of it: adding and subtracting 2^52
/// rounds to an integer in the current (ties-to-even) mode; from 2^52 on
/// every f64 is an integer already.
fn round_ties_even(x: f64) -> f64 {
    const TWO_52: f64 = 4_503_599_627_370_496.0;
    if x < TWO_52 { (x + TWO_52) - TWO_52 } else { x }
}

/// A 64-bit two's-complement sum of quanta back in joules.
pub(crate) fn from_quanta(q: u64) -> f64 {
    q as i64 as f64 / ENERGY_QUANTA_PER_J
}

/// Where one sample's energy goes in the maps, and how much: its friction
/// energy (eqs. 23–25) lands in `cells[0]` (surface × inner) and
/// `cells[1]` (speed × surface), its lateral part (eq. 24) in `cells[2]`.
pub(crate) struct SampleEnergy {
    pub cells: [usize; 3],
    /// Quanta of the friction energy and of its lateral part.
    pub total: u64,
    pub lateral: u64,
}

/// One sample's [`SampleEnergy`] (the shader's phase 1 for one sample).
#[inline(always)]
pub(crate) fn sample_energy(p: &ReduceSample) -> SampleEnergy {
    let f = |x: f32| x as f64;
    let dt = f(p.dt) + f(p.dt_lo);
    let v_sx = f(p.vx) - f(p.omega) * f(p.radius); // eq. 21
    let v_sy = f(p.vy); // eq. 22
    let power = -f(p.fx) * v_sx - f(p.fy) * v_sy; // eqs. 23–25
    let s = T_SURFACE_BINS.index(f(p.t_surface));
    let i = T_INNER_BINS.index(f(p.t_inner));
    let v = SLIDING_SPEED_BINS.index((v_sx * v_sx + v_sy * v_sy).sqrt());
    let a = s * T_INNER_BINS.n + i;
    SampleEnergy {
        cells: [
            a,
            SURFACE_INNER_BINS + v * T_SURFACE_BINS.n + s,
            LATERAL_BINS_AT + a,
        ],
        total: to_quanta(power * dt),
        lateral: to_quanta(-f(p.fy) * v_sy * dt), // eq. 24
    }
}

fn workgroup(batch: &ReduceBatch, chunk: &ReduceChunk, maps: &mut [u64]) {
    let count = chunk.count as usize;
    // Phase 0.
    let mut bins = [0u64; BINS];
    // Phase 1.
    for lid in 0..WG_SIZE {
        for k in 0..ITEMS {
            let j = lid + k * WG_SIZE;
            if j < count {
                let e = sample_energy(&batch.samples[chunk.start as usize + j]);
                let [a, b, c] = e.cells;
                bins[a] = bins[a].wrapping_add(e.total);
                bins[b] = bins[b].wrapping_add(e.total);
                bins[c] = bins[c].wrapping_add(e.lateral);
            }
        }
    }
    // Phase 2.
    add_to_wheel(&bins, chunk.wheel as usize, maps);
}

/// Phase 2 of a histogram kernel: a workgroup's non-zero bins added to its
/// wheel's bins (`maps` holds `bins.len()` per wheel).
pub(crate) fn add_to_wheel(bins: &[u64], wheel: usize, maps: &mut [u64]) {
    let n = bins.len();
    for (slot, &q) in maps[wheel * n..(wheel + 1) * n].iter_mut().zip(bins) {
        if q != 0 {
            *slot = slot.wrapping_add(q);
        }
    }
}

/// Runs a histogram kernel's workgroups over a batch: `per_wheel` sums of
/// quanta per wheel, each chunk added by `workgroup` (rayon over chunks;
/// the sums are exact, so the split does not change them).
pub(crate) fn per_wheel_sums(
    batch: &ReduceBatch,
    per_wheel: usize,
    workgroup: impl Fn(&ReduceChunk, &mut [u64]) + Sync,
) -> Vec<u64> {
    let n = batch.wheels() * per_wheel;
    batch
        .chunks
        .par_iter()
        .fold(
            || vec![0u64; n],
            |mut maps, c| {
                workgroup(c, &mut maps);
                maps
            },
        )
        .reduce(
            || vec![0u64; n],
            |mut a, b| {
                for (x, y) in a.iter_mut().zip(b) {
                    *x = x.wrapping_add(y);
                }
                a
            },
        )
}

/// The CPU engine's kernel: every wheel's maps as `BINS` sums of quanta
/// (rayon over chunks; exact, so the split does not change the result).
pub fn energy_map(batch: &ReduceBatch) -> Vec<u64> {
    per_wheel_sums(batch, BINS, |c, maps| workgroup(batch, c, maps))
}

/// Each wheel's maps (J per bin) from its `BINS` sums of quanta.
pub(crate) fn maps_from_quanta(quanta: &[u64]) -> Vec<EnergyMaps> {
    quanta
        .chunks_exact(BINS)
        .map(|q| {
            let j = |r: &[u64]| r.iter().map(|&v| from_quanta(v)).collect();
            EnergyMaps {
                surface_inner: j(&q[..SURFACE_INNER_BINS]),
                speed_surface: j(&q[SURFACE_INNER_BINS..LATERAL_BINS_AT]),
                lateral_surface_inner: j(&q[LATERAL_BINS_AT..]),
                conditions: None,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kpi::cpu::telemetry_reduce::ReduceSample;

    #[test]
    fn magnitude_conversion_is_as_u64_at_every_edge() {
        let two_63 = 9_223_372_036_854_775_808.0f64;
        for x in [
            0.0,
            1.0,
            4_503_599_627_370_496.0,
            two_63 - 1024.0,
            two_63,
            two_63 * 1.5,
            two_63 * 2.0,
            1e300,
            f64::INFINITY,
            f64::NAN,
        ] {
            assert_eq!(magnitude_to_u64(x), x as u64, "{x}");
        }
    }

    #[test]
    fn quanta_by_hand() {
        assert_eq!(to_quanta(1.0), 1 << 24);
        assert_eq!(to_quanta(-1.0), (1u64 << 24).wrapping_neg());
        assert_eq!(to_quanta(-1.0).wrapping_add(to_quanta(1.0)), 0);
        // Ties to even, as WGSL's round().
        assert_eq!(to_quanta(2.5 / ENERGY_QUANTA_PER_J), 2);
        assert_eq!(to_quanta(3.5 / ENERGY_QUANTA_PER_J), 4);
        assert_eq!(to_quanta(0.49999 / ENERGY_QUANTA_PER_J), 0);
        assert_eq!(to_quanta(1e40), u64::MAX); // saturates, as `as` does
        for x in [0.0, 0.5, 1.5, 2.5, 1e15 + 0.5, 4.5e15, 1e300] {
            assert_eq!(round_ties_even(x), x.round_ties_even(), "{x}");
        }
        assert_eq!(from_quanta(to_quanta(-1234.5)), -1234.5);
        // Past 2^32 quanta (256 J) the high word carries.
        assert_eq!(to_quanta(300.0), 300 << 24);
        assert_eq!(
            from_quanta(to_quanta(300.0).wrapping_add(to_quanta(-500.0))),
            -200.0
        );
    }

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
        let m = &maps_from_quanta(&energy_map(&batch))[0];
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
