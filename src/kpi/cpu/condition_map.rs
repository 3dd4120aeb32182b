//! Condition energy maps and the CPU twin of `shaders/condition_map.wgsl`:
//! per tire and run, the friction energy (total, longitudinal and lateral
//! parts) binned by each per-sample condition of [`CONDITIONS`] — slip
//! ratio, lateral slip (tan α), combined slip, sliding speed, load, friction
//! utilisation, temperatures, pressure, camber, speed — so that a wear
//! effect acting only under some condition can be looked for later without
//! re-reading telemetry. One 1-D map per condition; each sums to the run's
//! friction energy. And one 2-D map for each pair of [`PAIRS`], on each
//! condition's coarse bins (`Condition::coarse`): the energy where two
//! conditions hold together (sliding on a cold tread, say), which two 1-D
//! maps cannot tell apart from each acting alone.
//!
//! Raw channels are binned in their logged SI units (N, Pa), never rescaled,
//! so that a value both engines hold exactly lands in the same bin on both
//! (see [`ConditionBins`]). The bin table lives here only: the GPU engine uploads it (binding 2), so
//! the shader holds no bin edges. Energies are summed as fixed-point quanta
//! exactly as in `energy_map` (see `energy_map`), so both engines'
//! maps are deterministic and differ only by f32 against f64 per sample.

use super::energy_map::{
    BINS as ENERGY_BINS, add_to_wheel, from_quanta, per_wheel_sums, sample_energy, to_quanta,
};
use super::telemetry_reduce::{ITEMS, ReduceBatch, ReduceChunk, ReduceSample, WG_SIZE};
use crate::kpi::energy_maps::Bins;
use bytemuck::{Pod, Zeroable};

/// A per-sample condition: its name in the side table, unit, bins and formula.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Condition {
    pub name: &'static str,
    /// What the condition is, in words, for the diagnosis's findings
    /// ("surface temperature" for `t_surface_c`).
    pub words: &'static str,
    pub unit: &'static str,
    pub bins: Bins,
    /// Eight bins for the pair maps ([`PAIRS`]): their inner edges span the
    /// middle of a season's energy (about its 5–95 % energy quantiles on
    /// the demo) and lie on `bins`' edges, so a pair's threshold is a 1-D
    /// threshold too — except the slips', whose 1-D bins (0.02) are too
    /// wide for the 0.02–0.1 where most sliding energy lies: their pair
    /// bins are finer (0.01–0.015).
    pub coarse: Bins,
    /// How it is computed from the sample (docs/kpis.md repeats it).
    pub formula: &'static str,
}

/// Speed below which slip ratio and slip angle use this floor (m/s), so a
/// slow or stopped wheel does not divide by zero.
pub const SLIP_SPEED_FLOOR_MPS: f64 = 1.0;
/// Load below which friction utilisation uses this floor (N).
pub const LOAD_FLOOR_N: f64 = 100.0;

const fn bins(lo: f64, width: f64, n: usize) -> Bins {
    Bins { lo, width, n }
}

/// The conditions, in the order the shader computes them (`condition_values`).
/// Values outside a condition's bins go to its first or last bin.
pub const CONDITIONS: [Condition; N_CONDITIONS] = [
    Condition {
        name: "slip_ratio",
        words: "slip ratio",
        unit: "1",
        bins: bins(-0.3, 0.02, 30),
        coarse: bins(-0.06, 0.015, 8),
        formula: "κ = (ω·r − v_x) / max(|v_x|, 1 m/s) = −v_sx / max(|v_x|, 1 m/s)",
    },
    Condition {
        name: "lateral_slip",
        words: "lateral slip",
        unit: "1",
        bins: bins(-0.3, 0.02, 30),
        coarse: bins(-0.06, 0.015, 8),
        formula: "tan α = v_y / max(|v_x|, 1 m/s) (the slip angle's tangent: ±0.3 is ±16.7°)",
    },
    Condition {
        name: "combined_slip",
        words: "combined slip",
        unit: "1",
        bins: bins(0.0, 0.02, 30),
        coarse: bins(0.02, 0.01, 8),
        formula: "√(κ² + tan²α) = |v_s| / max(|v_x|, 1 m/s)",
    },
    Condition {
        name: "sliding_speed_mps",
        words: "sliding speed",
        unit: "m/s",
        bins: bins(0.0, 0.5, 20),
        coarse: bins(1.0, 0.5, 8),
        formula: "|v_s| = √(v_sx² + v_sy²)",
    },
    Condition {
        name: "load_n",
        words: "load",
        unit: "N",
        bins: bins(0.0, 500.0, 24),
        coarse: bins(1500.0, 1000.0, 8),
        formula: "F_z",
    },
    Condition {
        name: "friction_utilisation",
        words: "friction utilisation",
        unit: "1",
        bins: bins(0.0, 0.1, 25),
        coarse: bins(1.0, 0.1, 8),
        formula: "√(F_x² + F_y²) / max(F_z, 100 N)",
    },
    Condition {
        name: "t_surface_c",
        words: "surface temperature",
        unit: "°C",
        bins: bins(20.0, 5.0, 24),
        coarse: bins(45.0, 5.0, 8),
        formula: "T_surface",
    },
    Condition {
        name: "t_inner_c",
        words: "inner-liner temperature",
        unit: "°C",
        bins: bins(40.0, 5.0, 24),
        coarse: bins(70.0, 10.0, 8),
        formula: "T_inner (inner liner)",
    },
    Condition {
        name: "pressure_pa",
        words: "pressure",
        unit: "Pa",
        bins: bins(100e3, 5e3, 30),
        coarse: bins(105e3, 5e3, 8),
        formula: "p (inflation pressure)",
    },
    Condition {
        name: "camber_deg",
        words: "camber",
        unit: "deg",
        bins: bins(-6.0, 0.25, 32),
        coarse: bins(-4.0, 0.5, 8),
        formula: "γ",
    },
    Condition {
        name: "speed_mps",
        words: "speed",
        unit: "m/s",
        bins: bins(0.0, 4.0, 25),
        coarse: bins(24.0, 8.0, 8),
        formula: "v_x (wheel centre, longitudinal)",
    },
    // From format version 2 on.
    Condition {
        name: "t_bulk_c",
        words: "bulk temperature",
        unit: "°C",
        bins: bins(30.0, 5.0, 24),
        coarse: bins(65.0, 5.0, 8),
        formula: "(T_surface + T_inner) / 2 (bulk rubber)",
    },
    Condition {
        name: "t_surface_rate_kps",
        words: "surface temperature's rate of change",
        unit: "K/s",
        bins: bins(-15.0, 1.0, 30),
        coarse: bins(-2.0, 1.0, 8),
        formula: "(T_surface(j₁) − T_surface(j₀)) / (t(j₁) − t(j₀)), j₀ and j₁ the first and last kept samples within ±0.5 s",
    },
    Condition {
        name: "t_inner_rate_kps",
        words: "inner-liner temperature's rate of change",
        unit: "K/s",
        bins: bins(-1.5, 0.1, 30),
        coarse: bins(-0.8, 0.2, 8),
        formula: "as t_surface_rate_kps, of T_inner",
    },
    Condition {
        name: "relative_load",
        words: "relative load",
        unit: "1",
        bins: bins(0.0, 0.1, 30),
        coarse: bins(0.5, 0.2, 8),
        formula: "F_z / mean F_z of the tire's kept samples in the run",
    },
    Condition {
        name: "time_since_start_s",
        words: "time since the start",
        unit: "s",
        bins: bins(0.0, 120.0, 30),
        coarse: bins(0.0, 240.0, 8),
        formula: "t − t of the tire's first kept sample",
    },
    Condition {
        name: "distance_since_start_m",
        words: "distance since the start",
        unit: "m",
        bins: bins(0.0, 5000.0, 30),
        coarse: bins(0.0, 10000.0, 8),
        formula: "Σ v_x·Δt over the tire's kept samples before this one",
    },
    // From format version 4 on.
    Condition {
        name: "accel_x_mps2",
        words: "longitudinal acceleration",
        unit: "m/s²",
        bins: bins(-45.0, 3.0, 20),
        coarse: bins(-30.0, 6.0, 8),
        formula: "dv_x/dt = (v_x(j₁) − v_x(j₀)) / (t(j₁) − t(j₀)), over the window of t_surface_rate_kps (the wheel centre's longitudinal acceleration, braking negative)",
    },
    Condition {
        name: "accel_y_mps2",
        words: "lateral acceleration",
        unit: "m/s²",
        bins: bins(0.0, 3.0, 20),
        coarse: bins(6.0, 6.0, 8),
        formula: "|a_y| = |Σ F_y| / m, the four wheels' lateral forces at this sample over the car's mass (the car's lateral acceleration)",
    },
];

/// Conditions a format-version-1 side table holds (the first ones).
pub const V1_CONDITIONS: usize = 11;
/// Conditions a format-version-2 or 3 side table holds (the first ones).
pub const V3_CONDITIONS: usize = 17;

/// A pair of conditions with a 2-D map: the friction energy (the total
/// only) binned by both at once, on their coarse bins, [first's coarse
/// bin][second's coarse bin].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pair {
    /// Side-table names of the two conditions.
    pub first: &'static str,
    pub second: &'static str,
    /// Why this pair: the mechanism an engineer would look for in it.
    pub reason: &'static str,
}

/// The pairs with a 2-D map. A documented selection, not all 136: every
/// pair would be 8 704 cells per tire, more than four times what the
/// workgroup's 16 KiB histogram holds, and 2.7× the per-sample work of
/// the 1-D maps. Wear mechanisms combine how hard the tread slides with the
/// state it slides in (temperature, load, camber, speed), so each pair is
/// a sliding measure and a state (docs/kpis.md).
pub const PAIRS: [Pair; N_PAIRS] = [
    Pair {
        first: "combined_slip",
        second: "t_surface_c",
        reason: "sliding on a cold surface (graining) or a hot one (thermal degradation)",
    },
    Pair {
        first: "combined_slip",
        second: "t_bulk_c",
        reason: "sliding with a cold bulk (graining) or a hot one (blistering)",
    },
    Pair {
        first: "sliding_speed_mps",
        second: "t_surface_c",
        reason: "fast sliding on a hot surface (flash temperature)",
    },
    Pair {
        first: "friction_utilisation",
        second: "t_surface_c",
        reason: "grip used near its limit at a tread temperature",
    },
    Pair {
        first: "combined_slip",
        second: "relative_load",
        reason: "sliding under load transfer (tearing on the loaded tire)",
    },
    Pair {
        first: "slip_ratio",
        second: "relative_load",
        reason: "traction or braking slip under load",
    },
    Pair {
        first: "lateral_slip",
        second: "camber_deg",
        reason: "cornering on a tilted contact patch (shoulder wear)",
    },
    Pair {
        first: "combined_slip",
        second: "speed_mps",
        reason: "sliding at high road speed (energy density in the patch)",
    },
];

/// Number of pairs with a 2-D map. Must match `N_PAIRS` in the shader
/// (checked by tests/shader_contract.rs).
pub const N_PAIRS: usize = 8;

/// Number of conditions. Must match `N_CONDITIONS` in the shader (checked by tests/shader_contract.rs).
pub const N_CONDITIONS: usize = 19;
/// Bins of one energy component over all conditions' 1-D maps. Must match
/// `CONDITION_BINS` in the shader (checked by tests/shader_contract.rs).
pub const CONDITION_BINS: usize = 508;
/// Cells of all pair maps (total energy only). Must match `PAIR_BINS` in
/// the shader (checked by tests/shader_contract.rs).
pub const PAIR_BINS: usize = 512;
/// Energy components: total, longitudinal (−F_x·v_sx·Δt), lateral (−F_y·v_sy·Δt).
pub(crate) const COMPONENTS: usize = 3;
/// Components whose quanta the kernels sum: longitudinal and lateral. A
/// bin's total is their sum, taken when the sums are read
/// ([`condition_maps_from_quanta`]): a third of the additions fewer per
/// sample, and a third of the 1-D maps' workgroup memory free.
const SUMMED: usize = 2;
/// Bins of one wheel's sums: the longitudinal, then the lateral 1-D maps,
/// then the pair maps. Must match `MAP_BINS` in the shader (checked by
/// tests/shader_contract.rs).
pub const MAP_BINS: usize = SUMMED * CONDITION_BINS + PAIR_BINS;

const fn total_bins() -> usize {
    let mut n = 0;
    let mut c = 0;
    while c < N_CONDITIONS {
        n += CONDITIONS[c].bins.n;
        c += 1;
    }
    n
}
const _: () = assert!(CONDITION_BINS == total_bins());

/// Index of a condition by its side-table name (a const fn, so that the
/// pairs' conditions are found at compile time).
const fn condition_named(name: &str) -> Option<usize> {
    let mut c = 0;
    while c < N_CONDITIONS {
        let (a, b) = (CONDITIONS[c].name.as_bytes(), name.as_bytes());
        if a.len() == b.len() {
            let mut k = 0;
            while k < a.len() && a[k] == b[k] {
                k += 1;
            }
            if k == a.len() {
                return Some(c);
            }
        }
        c += 1;
    }
    None
}

/// [`condition_named`] for the [`PAIRS`] table: a name that is not a
/// condition fails the build.
const fn condition_at(name: &str) -> usize {
    match condition_named(name) {
        Some(c) => c,
        None => panic!("a PAIRS name is not a condition"),
    }
}

/// The conditions of every pair, found by name once, at build time: the
/// diagnosis asks for them per tire and candidate, where a name search
/// each time cost 7 % of a one-thread diagnosis of the demo.
const PAIR_CONDITIONS: [(usize, usize); N_PAIRS] = {
    let mut o = [(0, 0); N_PAIRS];
    let mut p = 0;
    while p < N_PAIRS {
        o[p] = (condition_at(PAIRS[p].first), condition_at(PAIRS[p].second));
        p += 1;
    }
    o
};

/// The conditions of pair `p` (indices into [`CONDITIONS`]).
pub(crate) const fn pair_conditions(p: usize) -> (usize, usize) {
    PAIR_CONDITIONS[p]
}

/// Cells of pair `p`'s map.
const fn pair_cells(p: usize) -> usize {
    let (a, b) = pair_conditions(p);
    CONDITIONS[a].coarse.n * CONDITIONS[b].coarse.n
}

/// First cell of each pair within the pair cells (a constant, as
/// [`PAIR_CONDITIONS`]).
const PAIR_OFFSETS: [usize; N_PAIRS] = {
    let mut o = [0; N_PAIRS];
    let mut p = 1;
    while p < N_PAIRS {
        o[p] = o[p - 1] + pair_cells(p - 1);
        p += 1;
    }
    o
};

/// A pair's side-table name: its conditions' names joined by ':'.
pub fn pair_name(p: usize) -> String {
    format!("{}:{}", PAIRS[p].first, PAIRS[p].second)
}

/// One condition's bins as both engines apply them: in f32, as
/// ⌊(x − lo)·inv_width⌋ clamped to 0..n−1 (NaN to 0). Subtraction and
/// multiplication are correctly rounded in Rust and in Vulkan's SPIR-V, so
/// a value both engines hold exactly — a raw channel, such as a camber
/// logged as a constant −1.5° that sits on an edge — lands in the same bin
/// on both. Must match `ConditionBins` in the shader (checked by
/// tests/shader_contract.rs).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct ConditionBins {
    pub lo: f32,
    /// 1 / width, rounded to f32.
    pub inv_width: f32,
    pub n: u32,
    /// First bin of this map: within a component's `CONDITION_BINS` (a
    /// condition), within the `PAIR_BINS` (a pair's first axis); 0, unused
    /// (a pair's second axis).
    pub offset: u32,
    /// Which condition value it bins (index into [`CONDITIONS`]).
    pub value: u32,
}

/// Entries of [`CONDITION_TABLE`]: one per condition, two per pair.
pub(crate) const TABLE_LEN: usize = N_CONDITIONS + 2 * N_PAIRS;

/// The table the GPU engine uploads (binding 2): one entry per condition's
/// 1-D map, in [`CONDITIONS`] order, then two per pair of [`PAIRS`] (its
/// first condition's coarse bins with the pair's offset, then its second's).
/// A constant, so that the CPU routes bin with folded constants.
pub(crate) const CONDITION_TABLE: [ConditionBins; TABLE_LEN] = condition_table_at_build();

const fn table_entry(bins: &Bins, offset: usize, value: usize) -> ConditionBins {
    ConditionBins {
        lo: bins.lo as f32,
        inv_width: (1.0 / bins.width) as f32,
        n: bins.n as u32,
        offset: offset as u32,
        value: value as u32,
    }
}

const fn condition_table_at_build() -> [ConditionBins; TABLE_LEN] {
    let zero = ConditionBins {
        lo: 0.0,
        inv_width: 0.0,
        n: 0,
        offset: 0,
        value: 0,
    };
    let mut out = [zero; TABLE_LEN];
    let o = OFFSETS;
    let mut c = 0;
    while c < N_CONDITIONS {
        out[c] = table_entry(&CONDITIONS[c].bins, o[c], c);
        c += 1;
    }
    let po = PAIR_OFFSETS;
    let mut p = 0;
    while p < N_PAIRS {
        let (a, b) = pair_conditions(p);
        out[N_CONDITIONS + 2 * p] = table_entry(&CONDITIONS[a].coarse, po[p], a);
        out[N_CONDITIONS + 2 * p + 1] = table_entry(&CONDITIONS[b].coarse, 0, b);
        p += 1;
    }
    out
}

// The table fits its maps: every condition's bins lie within the 1-D
// maps' `CONDITION_BINS`, every pair's `n_a·n_b` cells within `PAIR_BINS`;
// what lets `WheelHistogram::add` index without a bounds check.
const _: () = {
    let mut k = 0;
    while k < N_CONDITIONS {
        let t = &CONDITION_TABLE[k];
        assert!(t.n >= 1 && (t.offset + t.n) as usize <= CONDITION_BINS);
        k += 1;
    }
    while k < TABLE_LEN {
        let (a, b) = (&CONDITION_TABLE[k], &CONDITION_TABLE[k + 1]);
        assert!(a.n >= 1 && b.n >= 1 && (a.offset + a.n * b.n) as usize <= PAIR_BINS);
        k += 2;
    }
};

/// [`CONDITION_TABLE`] as the GPU engine uploads it and the twin reads it.
pub(crate) fn condition_table() -> Vec<ConditionBins> {
    CONDITION_TABLE.to_vec()
}

impl ConditionBins {
    /// The bin of a value (the shader's `bin_index`): the value is rounded
    /// to f32 first, then binned in f32.
    pub fn index(&self, x: f64) -> usize {
        bin_of(x as f32, self.lo, self.inv_width, (self.n - 1) as f32) as usize
    }
}

/// ⌊(x − lo)·inv_width⌋ clamped to 0..=last, NaN to 0, in f32. For i ≥ 0,
/// ⌊min(i, last)⌋ = min(⌊i⌋, last), and truncation is the shader's floor
/// (without the SSE4.1 libcall floor would be); `f32::max` drops a NaN.
/// Branch-free, so that the CPU route's loop over the table vectorises.
#[inline(always)]
fn bin_of(x: f32, lo: f32, inv_width: f32, last: f32) -> u32 {
    let i = ((x - lo) * inv_width).max(0.0).min(last);
    // SAFETY: `max` drops a NaN and the clamp keeps `i` in 0..=last, far
    // inside i32, so the unchecked conversion is exact (and vectorises,
    // where `as` adds a saturating check per value).
    unsafe { i.to_int_unchecked::<i32>() as u32 }
}

/// First bin of each condition within a component (a constant, as
/// [`PAIR_CONDITIONS`]).
const OFFSETS: [usize; N_CONDITIONS] = {
    let mut o = [0; N_CONDITIONS];
    let mut c = 1;
    while c < N_CONDITIONS {
        o[c] = o[c - 1] + CONDITIONS[c - 1].bins.n;
        c += 1;
    }
    o
};

/// The conditions of one sample, in [`CONDITIONS`] order (the shader's
/// `condition_values`, in f64).
pub(crate) fn condition_values(p: &ReduceSample) -> [f64; N_CONDITIONS] {
    let f = |x: f32| x as f64;
    let v_sx = f(p.vx) - f(p.omega) * f(p.radius); // eq. 21
    let v_sy = f(p.vy); // eq. 22
    let v_s = (v_sx * v_sx + v_sy * v_sy).sqrt();
    let v_ref = f(p.vx).abs().max(SLIP_SPEED_FLOOR_MPS);
    let force = (f(p.fx) * f(p.fx) + f(p.fy) * f(p.fy)).sqrt();
    [
        -v_sx / v_ref,
        f(p.vy) / v_ref,
        v_s / v_ref,
        v_s,
        f(p.fz),
        force / f(p.fz).max(LOAD_FLOOR_N),
        f(p.t_surface),
        f(p.t_inner),
        f(p.pressure),
        f(p.camber),
        f(p.vx),
        0.5 * (f(p.t_surface) + f(p.t_inner)),
        f(p.t_surface_rate),
        f(p.t_inner_rate),
        f(p.load_rel),
        f(p.time_s),
        f(p.distance_m),
        f(p.accel_x),
        f(p.accel_y),
    ]
}

/// A sample's friction energy as quanta: longitudinal, lateral (the
/// total is their sum).
#[inline(always)]
fn sample_quanta(p: &ReduceSample) -> [u64; SUMMED] {
    let f = |x: f32| x as f64;
    let dt = f(p.dt) + f(p.dt_lo);
    let v_sx = f(p.vx) - f(p.omega) * f(p.radius); // eq. 21
    let v_sy = f(p.vy); // eq. 22
    let e_x = -f(p.fx) * v_sx * dt; // eq. 23
    let e_y = -f(p.fy) * v_sy * dt; // eq. 24
    [to_quanta(e_x), to_quanta(e_y)]
}

fn workgroup(batch: &ReduceBatch, chunk: &ReduceChunk, table: &[ConditionBins], maps: &mut [u64]) {
    let count = chunk.count as usize;
    // Phase 0.
    let mut bins = [0u64; MAP_BINS];
    // Phase 1.
    for lid in 0..WG_SIZE {
        for k in 0..ITEMS {
            let j = lid + k * WG_SIZE;
            if j < count {
                let p = &batch.samples[chunk.start as usize + j];
                let q = sample_quanta(p);
                let q_total = q[0].wrapping_add(q[1]);
                let values = condition_values(p);
                for t in &table[..N_CONDITIONS] {
                    let b = t.offset as usize + t.index(values[t.value as usize]);
                    for (m, &qm) in q.iter().enumerate() {
                        let slot = &mut bins[m * CONDITION_BINS + b];
                        *slot = slot.wrapping_add(qm);
                    }
                }
                for pair in table[N_CONDITIONS..].chunks_exact(2) {
                    let (ta, tb) = (&pair[0], &pair[1]);
                    let ia = ta.index(values[ta.value as usize]);
                    let ib = tb.index(values[tb.value as usize]);
                    let cell = ta.offset as usize + ia * tb.n as usize + ib;
                    let slot = &mut bins[SUMMED * CONDITION_BINS + cell];
                    *slot = slot.wrapping_add(q_total);
                }
            }
        }
    }
    // Phase 2.
    add_to_wheel(&bins, chunk.wheel as usize, maps);
}

/// The CPU engine's kernel: every wheel's condition maps as `MAP_BINS` sums
/// of quanta (rayon over chunks; exact, so the split does not change them).
pub fn condition_map(batch: &ReduceBatch) -> Vec<u64> {
    let table = condition_table();
    per_wheel_sums(batch, MAP_BINS, |c, maps| workgroup(batch, c, &table, maps))
}

/// The CPU engine's route to [`condition_map`]'s sums, equal to them bit
/// for bit (integer sums are exact in any order; tested against the twin):
/// one private histogram per wheel rather than one per chunk of 1 024
/// samples, a bin's two summed components side by side (16 bytes), and
/// the bin table a constant the compiler folds into the loop. The twin
/// stays the shader's mirror and the reference in the parity tests.
pub(crate) fn condition_map_by_wheel(batch: &ReduceBatch) -> Vec<u64> {
    maps_by_wheel::<false>(batch).1
}

/// [`condition_map_by_wheel`] and, in the same pass over the samples,
/// `energy_map`'s sums (equal to that twin's bit for bit, tested): the
/// CPU engine's route to both histogram kernels, which reads each sample
/// once and computes its slips and sliding speed once for both.
pub(crate) fn histograms_by_wheel(batch: &ReduceBatch) -> (Vec<u64>, Vec<u64>) {
    maps_by_wheel::<true>(batch)
}

/// Energy maps (`ENERGY`; empty otherwise) and condition maps, per wheel.
fn maps_by_wheel<const ENERGY: bool>(batch: &ReduceBatch) -> (Vec<u64>, Vec<u64>) {
    use rayon::prelude::*;
    let wheels = batch.wheels();
    let histograms: Vec<WheelHistogram<ENERGY>> = (0..wheels)
        .into_par_iter()
        .map(|w| {
            let mut h = WheelHistogram::default();
            for c in batch.chunks.iter().filter(|c| c.wheel as usize == w) {
                h.add(&batch.samples[c.start as usize..(c.start + c.count) as usize]);
            }
            h
        })
        .collect();
    let mut energy = vec![0u64; if ENERGY { wheels * ENERGY_BINS } else { 0 }];
    let mut conditions = vec![0u64; wheels * MAP_BINS];
    for (w, h) in histograms.iter().enumerate() {
        let energy_maps = energy.get_mut(w * ENERGY_BINS..(w + 1) * ENERGY_BINS);
        h.write_to(
            &mut conditions[w * MAP_BINS..(w + 1) * MAP_BINS],
            energy_maps.unwrap_or_default(),
        );
    }
    (energy, conditions)
}

/// A two-component cell plus `q`, lane by lane with wrapping: on x86-64 one
/// 16-byte add and one store (SSE2, always there), where two scalar adds
/// take two stores.
#[inline(always)]
fn add_pair(cell: &mut [u64; SUMMED], q: [u64; SUMMED]) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{__m128i, _mm_add_epi64, _mm_loadu_si128, _mm_storeu_si128};
        let p = cell.as_mut_ptr().cast::<__m128i>();
        // SAFETY: `cell` is 16 valid, writable bytes (two u64s); the
        // unaligned load and store need no alignment.
        unsafe {
            let sum = _mm_add_epi64(_mm_loadu_si128(p), _mm_loadu_si128(q.as_ptr().cast()));
            _mm_storeu_si128(p, sum);
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    for (slot, qm) in cell.iter_mut().zip(q) {
        *slot = slot.wrapping_add(qm);
    }
}

/// One wheel's private histogram of quanta: [bin][longitudinal, lateral]
/// for the 1-D maps, then the pair cells (total only); and with `ENERGY`
/// the energy maps' bins (`energy_map`'s layout).
struct WheelHistogram<const ENERGY: bool> {
    one_d: Vec<[u64; SUMMED]>,
    pairs: Vec<u64>,
    energy: Vec<u64>,
}

impl<const ENERGY: bool> Default for WheelHistogram<ENERGY> {
    fn default() -> Self {
        WheelHistogram {
            one_d: vec![[0; SUMMED]; CONDITION_BINS],
            pairs: vec![0; PAIR_BINS],
            energy: vec![0; if ENERGY { ENERGY_BINS } else { 0 }],
        }
    }
}

/// [`CONDITION_TABLE`] split into columns for [`WheelHistogram::add`],
/// whose loops over them the compiler vectorises: the bins' lower edges,
/// inverse widths, last bins (as f32, exact) and offsets.
struct TableColumns {
    lo: [f32; TABLE_LEN],
    inv_width: [f32; TABLE_LEN],
    last: [f32; TABLE_LEN],
    offset: [u32; TABLE_LEN],
    /// Which condition value each entry bins.
    value: [usize; TABLE_LEN],
}

const COLUMNS: TableColumns = {
    let mut c = TableColumns {
        lo: [0.0; TABLE_LEN],
        inv_width: [0.0; TABLE_LEN],
        last: [0.0; TABLE_LEN],
        offset: [0; TABLE_LEN],
        value: [0; TABLE_LEN],
    };
    let mut k = 0;
    while k < TABLE_LEN {
        let t = &CONDITION_TABLE[k];
        c.lo[k] = t.lo;
        c.inv_width[k] = t.inv_width;
        c.last[k] = (t.n - 1) as f32;
        c.offset[k] = t.offset;
        c.value[k] = t.value as usize;
        k += 1;
    }
    c
};

impl<const ENERGY: bool> WheelHistogram<ENERGY> {
    #[allow(clippy::needless_range_loop)] // k indexes the table's columns in lockstep
    fn add(&mut self, samples: &[ReduceSample]) {
        let t = &COLUMNS;
        for p in samples {
            if ENERGY {
                let e = sample_energy(p);
                for (cell, q) in e.cells.into_iter().zip([e.total, e.total, e.lateral]) {
                    debug_assert!(cell < ENERGY_BINS);
                    // SAFETY: `sample_energy`'s cells are clamped bins of
                    // maps that tile `energy_map`'s BINS (its const
                    // assertions); `energy` has BINS entries with ENERGY.
                    let slot = unsafe { self.energy.get_unchecked_mut(cell) };
                    *slot = slot.wrapping_add(q);
                }
            }
            let q = sample_quanta(p);
            let q_total = q[0].wrapping_add(q[1]);
            let values = condition_values(p).map(|v| v as f32);
            let mut x = [0f32; TABLE_LEN];
            x[..N_CONDITIONS].copy_from_slice(&values);
            for k in N_CONDITIONS..TABLE_LEN {
                x[k] = values[t.value[k]];
            }
            let mut bin = [0u32; TABLE_LEN];
            for k in 0..TABLE_LEN {
                bin[k] = bin_of(x[k], t.lo[k], t.inv_width[k], t.last[k]);
            }
            for k in 0..N_CONDITIONS {
                let cell = (t.offset[k] + bin[k]) as usize;
                debug_assert!(cell < CONDITION_BINS);
                // SAFETY: bin_of clamps bin[k] to 0..n_k, every condition's
                // bins lie inside the map (the table-fits assertion after
                // `condition_table_at_build`), and `one_d` has
                // CONDITION_BINS cells.
                add_pair(unsafe { self.one_d.get_unchecked_mut(cell) }, q);
            }
            for k in 0..N_PAIRS {
                let (a, b) = (N_CONDITIONS + 2 * k, N_CONDITIONS + 2 * k + 1);
                let n_b = CONDITION_TABLE[b].n;
                let cell = (t.offset[a] + bin[a] * n_b + bin[b]) as usize;
                debug_assert!(cell < PAIR_BINS);
                // SAFETY: bin[a] < n_a and bin[b] < n_b (clamped), so the
                // cell is below offset + n_a·n_b ≤ PAIR_BINS (the table-fits
                // assertion), the length of `pairs`.
                let slot = unsafe { self.pairs.get_unchecked_mut(cell) };
                *slot = slot.wrapping_add(q_total);
            }
        }
    }

    /// The sums in the twins' layouts (`MAP_BINS` per wheel; the energy
    /// maps' `BINS`, with `ENERGY`).
    fn write_to(&self, maps: &mut [u64], energy_maps: &mut [u64]) {
        energy_maps.copy_from_slice(&self.energy);
        for (b, cell) in self.one_d.iter().enumerate() {
            for (m, &v) in cell.iter().enumerate() {
                maps[m * CONDITION_BINS + b] = v;
            }
        }
        maps[SUMMED * CONDITION_BINS..].copy_from_slice(&self.pairs);
    }
}

/// One tire and run's condition maps (J per bin): for each component, the
/// bins of every condition back to back in [`CONDITIONS`] order; and the
/// total energy's cells of every pair in [`PAIRS`] order.
#[derive(Debug, Clone, PartialEq)]
pub struct ConditionMaps {
    /// [component][CONDITION_BINS]: total, longitudinal, lateral.
    pub energy_j: [Vec<f64>; COMPONENTS],
    /// [PAIR_BINS]: the pair maps of the total energy.
    pub pairs_j: Vec<f64>,
    /// How many of [`CONDITIONS`] (the first ones) the maps hold: all, or
    /// [`V1_CONDITIONS`] or [`V3_CONDITIONS`] when read from an older side
    /// table.
    pub held: usize,
    /// Whether the maps hold the pair maps (not read from a side table
    /// older than format version 3).
    pub pairs_held: bool,
}

impl Default for ConditionMaps {
    fn default() -> Self {
        ConditionMaps {
            energy_j: std::array::from_fn(|_| vec![0.0; CONDITION_BINS]),
            pairs_j: vec![0.0; PAIR_BINS],
            held: N_CONDITIONS,
            pairs_held: true,
        }
    }
}

/// An energy component of the condition maps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum Component {
    Total,
    Longitudinal,
    Lateral,
}

impl Component {
    pub const ALL: [Component; COMPONENTS] = [
        Component::Total,
        Component::Longitudinal,
        Component::Lateral,
    ];
    /// How candidate names call it: "energy", "longitudinal energy", "lateral energy".
    pub(crate) fn energy_name(self) -> &'static str {
        match self {
            Component::Total => "energy",
            Component::Longitudinal => "longitudinal energy",
            Component::Lateral => "lateral energy",
        }
    }
}

impl ConditionMaps {
    /// One condition's map of one component (J per bin of `CONDITIONS[c].bins`).
    pub fn map(&self, component: Component, condition: usize) -> &[f64] {
        let o = OFFSETS[condition];
        &self.energy_j[component as usize][o..o + CONDITIONS[condition].bins.n]
    }
    /// Whether the maps hold a condition (an older side table lacks the
    /// later ones: their map is absent, not zero).
    pub fn holds(&self, condition: usize) -> bool {
        condition < self.held
    }
    /// Index of a condition by its side-table name.
    pub fn condition_index(name: &str) -> Option<usize> {
        condition_named(name)
    }
    /// Pair `p`'s map of the total energy (J per cell, [first's coarse
    /// bin][second's coarse bin], row-major).
    pub fn pair_map(&self, p: usize) -> &[f64] {
        let o = PAIR_OFFSETS[p];
        &self.pairs_j[o..o + pair_cells(p)]
    }
}

/// Each wheel's condition maps (J per bin) from its `MAP_BINS` sums of
/// quanta: the total of a bin is the sum of its longitudinal and lateral
/// quanta (exact, as every sum of quanta).
pub(crate) fn condition_maps_from_quanta(quanta: &[u64]) -> Vec<ConditionMaps> {
    quanta
        .chunks_exact(MAP_BINS)
        .map(|q| {
            let (x, y) = (
                &q[..CONDITION_BINS],
                &q[CONDITION_BINS..SUMMED * CONDITION_BINS],
            );
            let total: Vec<u64> = x.iter().zip(y).map(|(&a, &b)| a.wrapping_add(b)).collect();
            let joules = |v: &[u64]| v.iter().map(|&v| from_quanta(v)).collect();
            ConditionMaps {
                energy_j: [joules(&total), joules(x), joules(y)],
                pairs_j: joules(&q[SUMMED * CONDITION_BINS..]),
                held: N_CONDITIONS,
                pairs_held: true,
            }
        })
        .collect()
}

/// Schema-metadata key of the side table's format version.
pub(crate) const VERSION_KEY: &str = "tirewear.condition_maps.version";
/// The side table's format version this build writes. It also reads
/// version 3, which holds the first [`V3_CONDITIONS`] conditions (no
/// longitudinal acceleration), version 2, which also has no pair maps, and
/// version 1, which holds only the first [`V1_CONDITIONS`] conditions.
pub(crate) const VERSION: u32 = 4;

/// Side table of condition maps (`NAME.condition_maps.parquet`): one row per
/// tire, run, condition and non-empty bin: run, wheel, condition, unit, bin,
/// lo, hi (the bin's edges; the first and last bins also hold the values
/// below and above), energy_j, energy_x_j, energy_y_j, lo_2, hi_2. A pair
/// map's rows name the pair `first:second` (unit `u1:u2`), its cell
/// i·n₂ + j as the bin, the first condition's coarse edges of i in lo/hi
/// and the second's of j in lo_2/hi_2 (NaN in the 1-D rows; columns from
/// version 3 on). Versioned in the schema metadata ([`VERSION_KEY`]).
pub(crate) fn side_table(
    maps: &[(String, crate::Wheel, ConditionMaps)],
) -> arrow_array::RecordBatch {
    use arrow_array::{Float64Array, StringArray, UInt32Array};
    use arrow_schema::{DataType, Field, Schema};
    use std::sync::Arc;
    let (mut run, mut wheel, mut cond, mut unit) = (vec![], vec![], vec![], vec![]);
    let (mut bin, mut lo, mut hi, mut lo_2, mut hi_2) = (vec![], vec![], vec![], vec![], vec![]);
    let mut e: [Vec<f64>; COMPONENTS] = Default::default();
    let layouts = map_layouts();
    // Every tire has the same cells: their edges are worked out once.
    let edges: Vec<Vec<[f64; 4]>> = layouts
        .iter()
        .map(|l| (0..l.cells).map(|b| l.edges(b)).collect())
        .collect();
    for (r, w, m) in maps {
        for (l, edges) in layouts.iter().zip(&edges) {
            for (b, &[a, b_, c, d]) in edges.iter().enumerate() {
                let energies = l.energies(m, b);
                if energies.iter().all(|e| *e == 0.0 || e.is_nan()) {
                    continue;
                }
                run.push(r.as_str());
                wheel.push(w.name());
                cond.push(l.name.as_str());
                unit.push(l.unit.as_str());
                bin.push(b as u32);
                lo.push(a);
                hi.push(b_);
                lo_2.push(c);
                hi_2.push(d);
                for (col, v) in e.iter_mut().zip(energies) {
                    col.push(v);
                }
            }
        }
    }
    let schema = Schema::new(vec![
        Field::new("run", DataType::Utf8, false),
        Field::new("wheel", DataType::Utf8, false),
        Field::new("condition", DataType::Utf8, false),
        Field::new("unit", DataType::Utf8, false),
        Field::new("bin", DataType::UInt32, false),
        Field::new("lo", DataType::Float64, false),
        Field::new("hi", DataType::Float64, false),
        Field::new("energy_j", DataType::Float64, false),
        Field::new("energy_x_j", DataType::Float64, false),
        Field::new("energy_y_j", DataType::Float64, false),
        Field::new("lo_2", DataType::Float64, false),
        Field::new("hi_2", DataType::Float64, false),
    ])
    .with_metadata(std::collections::HashMap::from([(
        VERSION_KEY.to_string(),
        VERSION.to_string(),
    )]));
    let [et, ex, ey] = e;
    arrow_array::RecordBatch::try_new(
        Arc::new(schema),
        vec![
            Arc::new(StringArray::from(run)),
            Arc::new(StringArray::from(wheel)),
            Arc::new(StringArray::from(cond)),
            Arc::new(StringArray::from(unit)),
            Arc::new(UInt32Array::from(bin)),
            Arc::new(Float64Array::from(lo)),
            Arc::new(Float64Array::from(hi)),
            Arc::new(Float64Array::from(et)),
            Arc::new(Float64Array::from(ex)),
            Arc::new(Float64Array::from(ey)),
            Arc::new(Float64Array::from(lo_2)),
            Arc::new(Float64Array::from(hi_2)),
        ],
    )
    .expect("columns match the schema")
}

/// One map of the side table: a condition's 1-D map or a pair's 2-D map.
struct MapLayout {
    name: String,
    unit: String,
    /// First bin within a component's `CONDITION_BINS` (a condition) or
    /// within the `PAIR_BINS` (a pair).
    offset: usize,
    cells: usize,
    /// The condition (1-D) or the pair's first condition.
    condition: usize,
    /// The pair's second condition.
    second: Option<usize>,
}

impl MapLayout {
    /// A cell's energies (J): total, longitudinal, lateral; a pair map
    /// holds the total only (NaN for the parts).
    fn energies(&self, m: &ConditionMaps, cell: usize) -> [f64; COMPONENTS] {
        let k = self.offset + cell;
        match self.second {
            None => std::array::from_fn(|c| m.energy_j[c][k]),
            Some(_) => [m.pairs_j[k], f64::NAN, f64::NAN],
        }
    }

    /// A cell's edges: lo, hi and, for a pair, the second condition's lo_2,
    /// hi_2 (NaN for a 1-D map).
    fn edges(&self, cell: usize) -> [f64; 4] {
        let first = &CONDITIONS[self.condition];
        match self.second {
            None => [
                first.bins.lower_edge(cell),
                first.bins.lower_edge(cell + 1),
                f64::NAN,
                f64::NAN,
            ],
            Some(s) => {
                let n = CONDITIONS[s].coarse.n;
                let (i, j) = (cell / n, cell % n);
                [
                    first.coarse.lower_edge(i),
                    first.coarse.lower_edge(i + 1),
                    CONDITIONS[s].coarse.lower_edge(j),
                    CONDITIONS[s].coarse.lower_edge(j + 1),
                ]
            }
        }
    }
}

/// Every map in side-table order: the conditions, then the pairs.
fn map_layouts() -> Vec<MapLayout> {
    let mut out: Vec<MapLayout> = OFFSETS
        .iter()
        .enumerate()
        .map(|(c, &offset)| MapLayout {
            name: CONDITIONS[c].name.to_string(),
            unit: CONDITIONS[c].unit.to_string(),
            offset,
            cells: CONDITIONS[c].bins.n,
            condition: c,
            second: None,
        })
        .collect();
    for (p, o) in PAIR_OFFSETS.iter().enumerate() {
        let (a, b) = pair_conditions(p);
        out.push(MapLayout {
            name: pair_name(p),
            unit: format!("{}:{}", CONDITIONS[a].unit, CONDITIONS[b].unit),
            offset: *o,
            cells: pair_cells(p),
            condition: a,
            second: Some(b),
        });
    }
    out
}

/// What a condition-map table of one format version holds: its 1-D maps
/// for the conditions below `held` (1: [`V1_CONDITIONS`], 2 and 3:
/// [`V3_CONDITIONS`], 4: all), its pair maps from version 3 on.
struct TableVersion {
    version: u32,
    held: usize,
    pairs_held: bool,
}

impl TableVersion {
    /// The version a table's schema metadata declares ([`VERSION_KEY`]);
    /// one this build does not read, or none, is an error naming the file.
    fn of(
        path: &std::path::Path,
        schema: &arrow_schema::Schema,
    ) -> Result<TableVersion, crate::ingest::IngestError> {
        use crate::ingest::IngestError;
        let version: u32 = match schema.metadata().get(VERSION_KEY) {
            Some(v) if matches!(v.as_str(), "1" | "2" | "3" | "4") => v.parse().expect("a digit"),
            Some(v) => {
                return Err(IngestError::invalid(
                    path,
                    "schema metadata",
                    format!(
                        "condition maps of format version {v}; this build reads versions 1 to {VERSION}"
                    ),
                ));
            }
            None => {
                return Err(IngestError::invalid(
                    path,
                    "schema metadata",
                    format!("no '{VERSION_KEY}': not a condition-map table"),
                ));
            }
        };
        let held = match version {
            1 => V1_CONDITIONS,
            2 | 3 => V3_CONDITIONS,
            _ => N_CONDITIONS,
        };
        Ok(TableVersion {
            version,
            held,
            pairs_held: version >= 3,
        })
    }

    /// Whether a file of this version may hold the map `l`.
    fn holds(&self, l: &MapLayout) -> bool {
        match l.second {
            Some(_) => self.pairs_held,
            None => l.condition < self.held,
        }
    }
}

/// One batch of a condition-map table, its columns cast and checked
/// (`lo_2`, `hi_2` from version 3 on).
struct MapColumns {
    run: arrow_array::StringArray,
    wheel: arrow_array::StringArray,
    condition: arrow_array::StringArray,
    bin: arrow_array::UInt32Array,
    lo: arrow_array::Float64Array,
    hi: arrow_array::Float64Array,
    second: Option<(arrow_array::Float64Array, arrow_array::Float64Array)>,
    /// Total, longitudinal, lateral (J).
    energy_j: [arrow_array::Float64Array; COMPONENTS],
}

impl MapColumns {
    /// The columns of `batch`, whose first record is `record` + 1.
    fn of(
        path: &std::path::Path,
        batch: &arrow_array::RecordBatch,
        record: usize,
        pairs_held: bool,
    ) -> Result<MapColumns, crate::ingest::IngestError> {
        use arrow_array::{Array, Float64Array, StringArray, UInt32Array};
        use arrow_schema::DataType;
        let col = |name: &str, ty: &DataType| {
            crate::kpi::table::checked_column(path, batch, name, ty, record)
        };
        let text = |name: &str| -> Result<StringArray, crate::ingest::IngestError> {
            let a = col(name, &DataType::Utf8)?;
            Ok(a.as_any()
                .downcast_ref::<StringArray>()
                .expect("cast")
                .clone())
        };
        let float = |name: &str| -> Result<Float64Array, crate::ingest::IngestError> {
            let a = col(name, &DataType::Float64)?;
            Ok(a.as_any()
                .downcast_ref::<Float64Array>()
                .expect("cast")
                .clone())
        };
        let (run, wheel, condition) = (text("run")?, text("wheel")?, text("condition")?);
        let bin = col("bin", &DataType::UInt32)?;
        let bin = bin
            .as_any()
            .downcast_ref::<UInt32Array>()
            .expect("cast")
            .clone();
        let (lo, hi) = (float("lo")?, float("hi")?);
        let second = if pairs_held {
            Some((float("lo_2")?, float("hi_2")?))
        } else {
            None
        };
        let energy_j = [
            float("energy_j")?,
            float("energy_x_j")?,
            float("energy_y_j")?,
        ];
        Ok(MapColumns {
            run,
            wheel,
            condition,
            bin,
            lo,
            hi,
            second,
            energy_j,
        })
    }

    /// Row `k`'s bin edges as [`MapLayout::edges`] gives them: lo, hi and,
    /// for a pair map, lo_2, hi_2 (NaN for a 1-D map).
    fn edges(&self, k: usize, l: &MapLayout) -> [f64; 4] {
        match (&self.second, l.second) {
            (Some((lo_2, hi_2)), Some(_)) => [
                self.lo.value(k),
                self.hi.value(k),
                lo_2.value(k),
                hi_2.value(k),
            ],
            _ => [self.lo.value(k), self.hi.value(k), f64::NAN, f64::NAN],
        }
    }
}

/// Checks that bin `b` of map `l` has this build's edges in the file
/// (`got`, from [`MapColumns::edges`]); else an error naming the record.
fn check_edges(
    path: &std::path::Path,
    record: usize,
    l: &MapLayout,
    b: usize,
    got: [f64; 4],
) -> Result<(), crate::ingest::IngestError> {
    let want = l.edges(b);
    let close =
        |a: f64, b: f64| (a.is_nan() && b.is_nan()) || (a - b).abs() <= 1e-9 * (1.0 + b.abs());
    if got.iter().zip(&want).all(|(g, w)| close(*g, *w)) {
        return Ok(());
    }
    let show = |e: &[f64]| match l.second {
        None => format!("[{}, {})", e[0], e[1]),
        Some(_) => format!("[{}, {}) × [{}, {})", e[0], e[1], e[2], e[3]),
    };
    Err(crate::ingest::IngestError::invalid(
        path,
        format!("record {record}"),
        format!(
            "bin {b} of '{}' is {} in the file but {} in this build",
            l.name,
            show(&got),
            show(&want)
        ),
    ))
}

/// Reads a condition-map side table back, keyed by (run, wheel). A file of
/// another format version, an unknown condition, a bin outside its
/// condition's grid, a bin whose edges differ from this build's, a bin
/// given twice for one tire, or a non-finite energy is an error naming the
/// record.
pub fn read_condition_maps(
    path: &std::path::Path,
) -> Result<
    std::collections::BTreeMap<crate::kpi::TireRun, ConditionMaps>,
    crate::ingest::IngestError,
> {
    use crate::ingest::IngestError;
    let perr = |e: parquet::errors::ParquetError| IngestError::Parquet {
        path: path.to_path_buf(),
        source: e,
    };
    let opened = crate::ingest::checksum::open_parquet(path)?;
    let v = TableVersion::of(path, opened.schema())?;
    // The maps a file of this version may hold, by name.
    let layouts = map_layouts();
    let by_name: std::collections::HashMap<&str, &MapLayout> = layouts
        .iter()
        .filter(|l| v.holds(l))
        .map(|l| (l.name.as_str(), l))
        .collect();
    let reader = opened.batches().map_err(perr)?;
    let mut out: std::collections::BTreeMap<crate::kpi::TireRun, ConditionMaps> =
        Default::default();
    // The 1-D maps' bins, then the pair maps': one bit each per tire.
    let mut given = crate::kpi::table::CellsGiven::new(CONDITION_BINS + PAIR_BINS);
    let mut record = 0usize;
    for batch in reader {
        let batch = batch.map_err(|e| perr(e.into()))?;
        let c = MapColumns::of(path, &batch, record, v.pairs_held)?;
        for k in 0..batch.num_rows() {
            record += 1;
            let at = || format!("record {record}");
            let name = c.condition.value(k);
            let l = by_name.get(name).ok_or_else(|| {
                IngestError::invalid(
                    path,
                    at(),
                    format!(
                        "unknown condition '{name}' in a version-{} table",
                        v.version
                    ),
                )
            })?;
            let b = c.bin.value(k) as usize;
            if b >= l.cells {
                return Err(IngestError::invalid(
                    path,
                    at(),
                    format!("bin {b} outside the {} bins of '{name}'", l.cells),
                ));
            }
            check_edges(path, record, l, b, c.edges(k, l))?;
            let w = crate::kpi::wheel_cell(path, record, c.wheel.value(k))?;
            let tire = (c.run.value(k).to_string(), w);
            let cell = match l.second {
                None => l.offset + b,
                Some(_) => CONDITION_BINS + l.offset + b,
            };
            if !given.first(&tire, cell) {
                return Err(IngestError::invalid(
                    path,
                    at(),
                    format!(
                        "bin {b} of '{name}' for run {} wheel {w} given twice (a table holds \
                         each bin of a tire once)",
                        tire.0
                    ),
                ));
            }
            let m = out.entry(tire).or_insert_with(|| ConditionMaps {
                held: v.held,
                pairs_held: v.pairs_held,
                ..Default::default()
            });
            // A pair map holds the total only: its parts' columns are NaN.
            let parts = if l.second.is_some() { 1 } else { COMPONENTS };
            for (comp, col) in c.energy_j.iter().enumerate().take(parts) {
                let e = col.value(k);
                if !e.is_finite() {
                    return Err(IngestError::invalid(
                        path,
                        at(),
                        format!("energy {e} of '{name}' bin {b} is not finite"),
                    ));
                }
                if l.second.is_some() {
                    m.pairs_j[l.offset + b] += e;
                } else {
                    m.energy_j[comp][l.offset + b] += e;
                }
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_is_consistent() {
        let t = condition_table();
        assert_eq!(t.len(), N_CONDITIONS + 2 * N_PAIRS);
        assert_eq!(
            t[N_CONDITIONS - 1].offset + t[N_CONDITIONS - 1].n,
            CONDITION_BINS as u32
        );
        let mut names: Vec<_> = CONDITIONS.iter().map(|c| c.name).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), N_CONDITIONS, "condition names are unique");
        // The pairs: known, distinct conditions, each pair once, their cells
        // back to back after the 1-D bins and filling PAIR_BINS.
        let mut pairs: Vec<_> = (0..N_PAIRS).map(pair_conditions).collect();
        assert!(pairs.iter().all(|(a, b)| a != b));
        pairs.sort();
        pairs.dedup();
        assert_eq!(pairs.len(), N_PAIRS);
        let last = &t[N_CONDITIONS + 2 * (N_PAIRS - 1)..];
        assert_eq!(last[0].offset + last[0].n * last[1].n, PAIR_BINS as u32);
        assert_eq!((0..N_PAIRS).map(pair_cells).sum::<usize>(), PAIR_BINS);
    }

    /// The CPU engine's route sums exactly what the twin sums: random
    /// samples spread over every bin and past both ends, edge values,
    /// NaN and infinities, negative energies, wheels of one sample, of
    /// several chunks, and none.
    #[test]
    fn route_by_wheel_equals_the_twin_bit_for_bit() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(16);
        let odd = |rng: &mut rand_chacha::ChaCha8Rng, lo: f32, hi: f32| -> f32 {
            match rng.random_range(0..40) {
                0 => f32::NAN,
                1 => f32::INFINITY,
                2 => f32::NEG_INFINITY,
                3 => -0.0,
                _ => rng.random_range(lo..hi),
            }
        };
        let sample = |rng: &mut rand_chacha::ChaCha8Rng| ReduceSample {
            vx: odd(rng, -5.0, 110.0),
            vy: odd(rng, -6.0, 6.0),
            omega: odd(rng, 0.0, 330.0),
            radius: 0.33,
            fx: odd(rng, -9e3, 9e3),
            fy: odd(rng, -9e3, 9e3),
            fz: odd(rng, -500.0, 14e3),
            t_surface: odd(rng, 0.0, 160.0),
            t_inner: odd(rng, 20.0, 180.0),
            pressure: odd(rng, 90e3, 260e3),
            // A camber logged on a bin edge.
            camber: if rng.random_bool(0.3) {
                -1.5
            } else {
                odd(rng, -7.0, 1.0)
            },
            t_surface_rate: odd(rng, -20.0, 20.0),
            t_inner_rate: odd(rng, -2.0, 2.0),
            load_rel: odd(rng, 0.0, 3.5),
            time_s: odd(rng, 0.0, 4000.0),
            distance_m: odd(rng, 0.0, 160e3),
            accel_x: odd(rng, -50.0, 20.0),
            accel_y: odd(rng, 0.0, 70.0),
            dt: rng.random_range(0.0..0.1),
            dt_lo: rng.random_range(-1e-9..1e-9),
        };
        let mut batch = ReduceBatch::default();
        use super::super::telemetry_reduce::CHUNK;
        for n in [3000, 1, 0, 2 * CHUNK + 17, 5000] {
            let samples: Vec<_> = (0..n).map(|_| sample(&mut rng)).collect();
            batch.push_wheel(&samples);
        }
        assert_eq!(condition_map_by_wheel(&batch), condition_map(&batch));
        // Both histograms in one pass: each twin's sums.
        let (energy, conditions) = histograms_by_wheel(&batch);
        assert_eq!(conditions, condition_map(&batch));
        assert_eq!(energy, super::super::energy_map::energy_map(&batch));
    }

    #[test]
    fn coarse_edges_are_fine_edges() {
        // A pair's threshold is then a 1-D threshold of the same condition
        // (but for the slips, whose pair bins are finer than their 1-D ones).
        for c in &CONDITIONS {
            if c.coarse.width < c.bins.width {
                assert!(c.name.contains("slip"), "{}", c.name);
                continue;
            }
            for k in 1..c.coarse.n {
                let x = c.coarse.lower_edge(k);
                let fine = (x - c.bins.lo) / c.bins.width;
                assert!(
                    (fine - fine.round()).abs() < 1e-9 && fine > 0.0 && fine < c.bins.n as f64,
                    "{}: coarse edge {x} is not an inner edge of its bins",
                    c.name
                );
            }
        }
    }

    /// The hand-worked sample of the tests below: v_x 40, ω·r = 41.2 →
    /// v_sx = −1.2; v_y = −2; F = (3000, −4000), F_z 4000; 91 °C and 104 °C.
    fn sample_by_hand() -> ReduceSample {
        ReduceSample {
            vx: 40.0,
            vy: -2.0,
            omega: 103.0,
            radius: 0.4,
            fx: 3000.0,
            fy: -4000.0,
            fz: 4000.0,
            t_surface: 91.0,
            t_inner: 104.0,
            ..Default::default()
        }
    }

    #[test]
    fn pair_cell_of_one_sample_by_hand() {
        // combined slip √(0.03² + 0.05²) = 0.0583 → coarse (0.0583 − 0.02)/0.01
        // = 3.8 → 3; T_surface 91 °C → (91 − 45)/5 = 9.2 → last (7); cell 3·8 + 7 = 31.
        let p = ReduceSample {
            dt: 0.01,
            ..sample_by_hand()
        };
        let mut batch = ReduceBatch::default();
        batch.push_wheel(&[p]);
        let maps = condition_maps_from_quanta(&condition_map(&batch));
        let pair = (0..N_PAIRS)
            .find(|&k| pair_name(k) == "combined_slip:t_surface_c")
            .unwrap();
        let m = maps[0].pair_map(pair);
        // E = −F_x·v_sx·Δt − F_y·v_sy·Δt = 3000·1.2·0.01 − 4000·2·0.01 = −44 J
        // (made-up forces: a map sums whatever energy it is given), as every
        // 1-D map holds it.
        let total: f64 = maps[0].map(Component::Total, 0).iter().sum();
        // (ω·r = 41.2 is not exact in f32: 1e-3 J.)
        assert!((total + 44.0).abs() < 1e-3, "{total}");
        assert_eq!(m.iter().filter(|e| **e != 0.0).count(), 1);
        assert_eq!(m[31], total);
        for k in 0..N_PAIRS {
            let s: f64 = maps[0].pair_map(k).iter().sum();
            assert_eq!(s, total, "{}", pair_name(k));
        }
    }

    #[test]
    fn conditions_of_one_sample_by_hand() {
        // v_x 40, ω·r = 41.2 → v_sx = −1.2, κ = 0.03; v_y = −2 → tan α = −0.05; |v_s| = √(1.44 + 4) = 2.332; F = (3000, −4000) → |F| = 5000,
        // F_z 4000 → μ-use 1.25.
        let p = ReduceSample {
            pressure: 172_000.0,
            camber: -3.1,
            t_surface_rate: 2.5,
            t_inner_rate: -0.25,
            load_rel: 1.35,
            time_s: 700.0,
            distance_m: 31_000.0,
            accel_x: -13.0,
            accel_y: 31.0,
            ..sample_by_hand()
        };
        let v = condition_values(&p);
        let close = |a: f64, b: f64| (a - b).abs() < 1e-5;
        assert!(close(v[0], 0.03), "{}", v[0]);
        assert!(close(v[1], -0.05), "{}", v[1]);
        assert!(close(v[2], 2.332381 / 40.0), "{}", v[2]);
        assert!(close(v[3], 2.332381), "{}", v[3]);
        assert!(close(v[4], 4000.0) && close(v[5], 1.25));
        assert!(close(v[8], 172_000.0) && close(v[9], -3.1) && close(v[10], 40.0));
        // Bins: κ 0.03 → (0.03 + 0.3)/0.02 = 16.5 → 16; tan α → 12.5 → 12; load 4 kN → 8.
        let t = condition_table();
        assert_eq!(t[0].index(v[0]), 16);
        assert_eq!(t[1].index(v[1]), 12);
        assert_eq!(t[4].index(v[4]), 8);
        // An edge value lands in the bin above it; NaN and the ends clamp.
        assert_eq!(t[9].index(-1.5), 18);
        assert_eq!(t[9].index(f64::NAN), 0);
        assert_eq!(t[9].index(-99.0), 0);
        assert_eq!(t[9].index(99.0), 31);
        // Bulk (91 + 104)/2 = 97.5 °C → (97.5 − 30)/5 = 13.5 → 13; rates 2.5 K/s
        // → 17.5 → 17 and −0.25 K/s → 12.5 → 12; load ×1.35 → 13.5 → 13; 700 s → 5.83
        // → 5; 31 km → 6.2 → 6.
        assert!(close(v[11], 97.5) && close(v[12], 2.5) && close(v[13], -0.25));
        assert!(close(v[14], 1.35) && close(v[15], 700.0) && close(v[16], 31_000.0));
        // Braking at 13 m/s² → (−13 + 45)/3 = 10.67 → 10.
        // Cornering at 31 m/s² → 31/3 = 10.3 → 10.
        assert!(close(v[17], -13.0) && close(v[18], 31.0));
        let want = [
            (11, 13),
            (12, 17),
            (13, 12),
            (14, 13),
            (15, 5),
            (16, 6),
            (17, 10),
            (18, 10),
        ];
        for (c, b) in want {
            assert_eq!(t[c].index(v[c]), b, "{}", CONDITIONS[c].name);
        }
    }

    #[test]
    fn side_table_reads_back_and_refuses_other_versions_and_names() {
        use std::sync::Arc;
        let mut m = ConditionMaps::default();
        m.energy_j[0][3] = 12.5;
        m.energy_j[1][3] = 10.0;
        m.energy_j[2][3] = 2.5;
        // The last bin of the last condition a version-3 table holds.
        let distance_last = OFFSETS[V3_CONDITIONS - 1] + CONDITIONS[V3_CONDITIONS - 1].bins.n - 1;
        m.energy_j[0][distance_last] = -1.0;
        m.pairs_j[PAIR_BINS - 1] = 4.0; // the last pair's last cell
        let batch = side_table(&[("r1".into(), crate::Wheel::FL, m.clone())]);
        assert_eq!(batch.num_rows(), 3);
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str, b: &arrow_array::RecordBatch| {
            let path = dir.path().join(name);
            let f = std::fs::File::create(&path).unwrap();
            let mut w = parquet::arrow::ArrowWriter::try_new(f, b.schema(), None).unwrap();
            w.write(b).unwrap();
            w.close().unwrap();
            path
        };
        let back = read_condition_maps(&write("ok.parquet", &batch)).unwrap();
        assert_eq!(back[&("r1".to_string(), crate::Wheel::FL)], m);
        let with_version = |b: &arrow_array::RecordBatch, v: &str| {
            let mut meta = b.schema().metadata().clone();
            meta.insert(VERSION_KEY.to_string(), v.to_string());
            arrow_array::RecordBatch::try_new(
                Arc::new(b.schema().as_ref().clone().with_metadata(meta)),
                b.columns().to_vec(),
            )
            .unwrap()
        };
        let last = &back[&("r1".to_string(), crate::Wheel::FL)];
        assert_eq!(last.pair_map(N_PAIRS - 1)[63], 4.0);
        // A later format version is refused.
        let e = read_condition_maps(&write("v5.parquet", &with_version(&batch, "5"))).unwrap_err();
        assert!(e.to_string().contains("format version 5"), "{e}");
        // Version 3 has no accelerations: the lateral one's map in one is
        // an error, and its maps say they lack them.
        let mut m4 = m.clone();
        m4.energy_j[2][CONDITION_BINS - 1] = -2.0;
        let batch4 = side_table(&[("r1".into(), crate::Wheel::FL, m4.clone())]);
        let back = read_condition_maps(&write("v4.parquet", &batch4)).unwrap();
        assert_eq!(back[&("r1".to_string(), crate::Wheel::FL)], m4);
        let e = read_condition_maps(&write("v3bad.parquet", &with_version(&batch4, "3")))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("record 3") && e.contains("'accel_y_mps2' in a version-3"),
            "{e}"
        );
        let back = read_condition_maps(&write("v3.parquet", &with_version(&batch, "3"))).unwrap();
        let got = &back[&("r1".to_string(), crate::Wheel::FL)];
        assert!(got.pairs_held && got.held == V3_CONDITIONS);
        assert!(got.holds(V3_CONDITIONS - 1) && !got.holds(V3_CONDITIONS));
        assert_eq!(got.energy_j[0][distance_last], -1.0);
        // Version 2 has no pair maps: a pair in it is an error, and its
        // maps say they lack the pairs.
        let e = read_condition_maps(&write("v2bad.parquet", &with_version(&batch, "2")))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("record 3") && e.contains("in a version-2"),
            "{e}"
        );
        let v2 = with_version(&batch.slice(0, 2), "2");
        let got = read_condition_maps(&write("v2.parquet", &v2)).unwrap();
        let got = &got[&("r1".to_string(), crate::Wheel::FL)];
        assert!(!got.pairs_held && got.held == V3_CONDITIONS);
        assert_eq!(got.energy_j[0][distance_last], -1.0);
        // A pair cell whose second edges differ from this build's.
        let mut cols = batch.columns().to_vec();
        cols[10] = Arc::new(arrow_array::Float64Array::from(vec![
            f64::NAN,
            f64::NAN,
            0.0,
        ]));
        let bad = arrow_array::RecordBatch::try_new(batch.schema(), cols).unwrap();
        let e = read_condition_maps(&write("badedge.parquet", &bad)).unwrap_err();
        assert!(
            e.to_string().contains("record 3") && e.to_string().contains("× [0, "),
            "{e}"
        );
        // Version 1 holds the first conditions only: a later one in it is
        // an error, and its maps say which conditions they lack.
        let e = read_condition_maps(&write("v1bad.parquet", &with_version(&batch, "1")))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("record 2") && e.contains("'distance_since_start_m' in a version-1"),
            "{e}"
        );
        let v1 = with_version(&batch.slice(0, 1), "1");
        let back = read_condition_maps(&write("v1.parquet", &v1)).unwrap();
        let got = &back[&("r1".to_string(), crate::Wheel::FL)];
        assert_eq!(got.held, V1_CONDITIONS);
        assert!(got.holds(V1_CONDITIONS - 1) && !got.holds(V1_CONDITIONS));
        assert_eq!(got.energy_j[1][3], 10.0);
        // An unknown condition names its record.
        let mut cols = batch.columns().to_vec();
        cols[2] = Arc::new(arrow_array::StringArray::from(vec![
            "slip_ratio",
            "toe_deg",
            "combined_slip:speed_mps",
        ]));
        let bad = arrow_array::RecordBatch::try_new(batch.schema(), cols).unwrap();
        let e = read_condition_maps(&write("bad.parquet", &bad)).unwrap_err();
        assert!(
            e.to_string().contains("record 2") && e.to_string().contains("toe_deg"),
            "{e}"
        );
        // So does a wheel that is not a wheel position.
        let mut cols = batch.columns().to_vec();
        cols[1] = Arc::new(arrow_array::StringArray::from(vec!["FL", "LF", "FL"]));
        let bad = arrow_array::RecordBatch::try_new(batch.schema(), cols).unwrap();
        let e = read_condition_maps(&write("badwheel.parquet", &bad)).unwrap_err();
        assert!(
            e.to_string().contains("record 2") && e.to_string().contains("wheel 'LF'"),
            "{e}"
        );
        // A bin given twice for one tire is refused, not added up; the
        // same bin of another wheel is another tire's.
        let twice =
            arrow_select::concat::concat_batches(&batch.schema(), [&batch, &batch.slice(2, 1)])
                .unwrap();
        let e = read_condition_maps(&write("twice.parquet", &twice)).unwrap_err();
        assert!(
            e.to_string().contains("record 4") && e.to_string().contains("given twice"),
            "{e}"
        );
        let mut cols = twice.columns().to_vec();
        cols[1] = Arc::new(arrow_array::StringArray::from(vec!["FL", "FL", "FL", "RR"]));
        let other = arrow_array::RecordBatch::try_new(batch.schema(), cols).unwrap();
        let back = read_condition_maps(&write("other.parquet", &other)).unwrap();
        assert_eq!(back.len(), 2);
    }
}
