//! Telemetry indices (paper table 4) of one wheel over one run, and the
//! friction-energy maps, from the decoded channels. Cleaning rule (also in
//! docs/kpis.md):
//!
//! - a sample whose time does not increase is dropped ("time backwards");
//! - a sample with a non-finite or out-of-range channel is dropped
//!   (counted per channel);
//! - every kept sample stands for the time to the next kept sample, so
//!   rate changes are handled; a gap longer than [`MAX_BRIDGED_GAP_S`]
//!   (a dropout) contributes only one nominal period, and its missing time
//!   is reported, not integrated;
//! - a run is rejected if a wheel topic is missing, a channel is missing
//!   (every sample exactly 0.0: proto3 cannot tell an absent field from a
//!   zero, and no real channel is exactly zero throughout a run), fewer than
//!   80 % of its samples are valid, or it lasts less than 10 s.

use super::cpu::energy_map::{energy_map, maps_from_quanta};
use super::cpu::telemetry_reduce::{
    ReduceBatch, ReduceRef, ReduceSample, SUMS, Sum, merge, moments, telemetry_reduce,
};
use super::energy_maps::EnergyMaps;
use crate::ingest::telemetry::{VehicleSeries, WheelSeries};

/// Gaps up to this long are bridged (the last power holds); longer ones are dropouts.
pub const MAX_BRIDGED_GAP_S: f64 = 0.5;
/// Least share of valid samples for a run to be accepted.
pub(crate) const MIN_VALID_SHARE: f64 = 0.8;
pub(crate) const MIN_DURATION_S: f64 = 10.0;
/// Contact-patch model: mean contact pressure = inflation pressure + carcass share (Pa).
pub const CARCASS_PRESSURE_PA: f64 = 40_000.0;

/// Plausible ranges of the wheel channels (in the order of `WheelSeries`).
pub const WHEEL_RANGES: [(&str, f64, f64); 11] = [
    ("vx_mps", -5.0, 150.0),
    ("vy_mps", -50.0, 50.0),
    ("omega_radps", -10.0, 1000.0),
    ("rolling_radius_m", 0.1, 1.0),
    ("fx_n", -50e3, 50e3),
    ("fy_n", -50e3, 50e3),
    ("fz_n", 0.0, 50e3),
    ("t_surface_c", -30.0, 250.0),
    ("t_inner_c", -30.0, 250.0),
    ("pressure_pa", 0.0, 600e3),
    ("camber_deg", -15.0, 15.0),
];

/// Why samples were dropped, and what was lost.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct CleaningReport {
    pub samples: u64,
    pub kept: u64,
    pub time_backwards: u64,
    /// Dropped samples per channel (order of [`WHEEL_RANGES`]).
    pub invalid_per_channel: [u64; 11],
    pub bridged_gaps: u64,
    pub dropouts: u64,
    pub dropout_time_s: f64,
    /// Distinct sample periods seen (a rate change gives more than one).
    pub sample_periods: u32,
}

/// Table 4 indices of one wheel and run.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct WheelIndices {
    pub t_surface_avg_c: f64,
    pub t_surface_std_c: f64,
    pub t_inner_avg_c: f64,
    pub t_inner_std_c: f64,
    pub fx_avg_n: f64,
    pub fx_std_n: f64,
    pub fy_avg_n: f64,
    pub fy_std_n: f64,
    pub fz_avg_n: f64,
    pub fz_std_n: f64,
    /// Mean of |v_sx| (m/s): a sliding speed.
    pub vsx_avg_mps: f64,
    pub vsx_std_mps: f64,
    /// Mean of |v_sy| (m/s).
    pub vsy_avg_mps: f64,
    pub vsy_std_mps: f64,
    /// ∫ −F_x v_sx dt (J): the paper's FP_x as an energy.
    pub friction_energy_x_j: f64,
    pub friction_energy_y_j: f64,
    pub friction_energy_j: f64,
    /// ∫ |v_s| dt (m).
    pub sliding_distance_m: f64,
    pub camber_avg_deg: f64,
    pub pressure_avg_pa: f64,
    /// Mean of F_z / (p + p_carcass) (mm²).
    pub contact_patch_mm2: f64,
    /// Integrated time (s), dropouts excluded.
    pub duration_s: f64,
}

/// Vehicle indices of one run.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub(crate) struct VehicleIndices {
    pub t_track_avg_c: f64,
    pub t_air_avg_c: f64,
    /// Dist_TOT: last minus first of the distance channel (m).
    pub distance_m: f64,
}

/// Running mean (Welford update, f64).
#[derive(Default, Clone, Copy)]
struct Moments {
    n: f64,
    mean: f64,
}

impl Moments {
    fn push(&mut self, x: f64) {
        self.n += 1.0;
        self.mean += (x - self.mean) / self.n;
    }
}

/// A range's bounds as f32: the least f32 ≥ lo and the greatest ≤ hi, so
/// that for every f32 v, lo ≤ v ≤ hi in f64 ⇔ lo₃₂ ≤ v ≤ hi₃₂ in f32 (and
/// NaN and ±∞ fail both: the bounds are finite). A logged value is valid
/// when it is finite and within its channel's range in f64.
fn f32_bounds(lo: f64, hi: f64) -> (f32, f32) {
    let (mut l, mut h) = (lo as f32, hi as f32);
    if (l as f64) < lo {
        l = l.next_up();
    }
    if (h as f64) > hi {
        h = h.next_down();
    }
    (l, h)
}

/// Whether a value lies within f32 bounds from [`f32_bounds`].
#[inline(always)]
fn within(v: f32, (lo, hi): (f32, f32)) -> bool {
    (v >= lo) & (v <= hi)
}

/// Whether each sample has every channel within its `bounds`: one pass
/// per channel, which the compiler vectorises (a pass per sample with a
/// branch per channel took most of the cleaning's time).
fn in_range(channels: &[&[f32]; 11], bounds: &[(f32, f32); 11]) -> Vec<bool> {
    let mut ok = vec![true; channels[0].len()];
    for (&b, col) in bounds.iter().zip(channels) {
        for (o, &v) in ok.iter_mut().zip(*col) {
            *o &= within(v, b);
        }
    }
    ok
}

/// The samples the cleaning rule keeps.
#[derive(Debug)]
enum Kept {
    /// Every sample of the wheel (the usual case): no index list built.
    All(usize),
    /// The kept samples' indices, in order (their times strictly increase).
    Indices(Vec<usize>),
}

impl Kept {
    fn len(&self) -> usize {
        match self {
            Kept::All(n) => *n,
            Kept::Indices(kept) => kept.len(),
        }
    }

    /// The kept samples' indices, whichever the case.
    #[cfg(test)]
    fn indices(&self) -> Vec<usize> {
        match self {
            Kept::All(n) => (0..*n).collect(),
            Kept::Indices(kept) => kept.clone(),
        }
    }
}

/// The samples the cleaning rule keeps (their times strictly increase);
/// the drops are counted in `report`.
fn kept_samples(s: &WheelSeries, channels: &[&[f32]; 11], report: &mut CleaningReport) -> Kept {
    report.samples = s.len() as u64;
    let bounds = WHEEL_RANGES.map(|(_, lo, hi)| f32_bounds(lo, hi));
    // Every sample valid and the times strictly increasing, the usual
    // case: checked in passes without a branch per sample (which the
    // compiler vectorises), and neither a mask nor an index list built
    // (the loop below pushing every index cost ~40 instructions a sample;
    // callgrind, docs/performance.md).
    let all_valid = bounds
        .iter()
        .zip(channels)
        .all(|(&b, col)| col.iter().fold(true, |all, &v| all & within(v, b)));
    let in_order = s
        .time_ns
        .windows(2)
        .fold(true, |all, t| all & (t[0] < t[1]));
    if all_valid && in_order {
        report.kept = report.samples;
        return Kept::All(s.len());
    }
    let valid = in_range(channels, &bounds);
    let mut kept: Vec<usize> = Vec::with_capacity(s.len());
    let mut last_t: Option<u64> = None;
    for (i, (&t, &ok)) in s.time_ns.iter().zip(&valid).enumerate() {
        if let Some(last) = last_t
            && t <= last
        {
            report.time_backwards += 1;
            continue;
        }
        if !ok {
            // The first channel out of its range is the one counted (the
            // same test as the mask's, so there is one).
            let c = bounds
                .iter()
                .zip(channels)
                .position(|(&b, col)| !within(col[i], b))
                .unwrap_or(0);
            report.invalid_per_channel[c] += 1;
            continue;
        }
        last_t = Some(t);
        kept.push(i);
    }
    report.kept = kept.len() as u64;
    Kept::Indices(kept)
}

/// Which samples a wheel keeps, as the preparation reads them: all of them
/// (the usual case: no index to follow) or a strictly increasing list.
trait KeptSamples: Copy {
    fn len(self) -> usize;
    /// The sample index of the k-th kept sample.
    fn at(self, k: usize) -> usize;
}

/// Every sample kept.
#[derive(Clone, Copy)]
struct AllSamples(usize);

impl KeptSamples for AllSamples {
    fn len(self) -> usize {
        self.0
    }
    #[inline(always)]
    fn at(self, k: usize) -> usize {
        k
    }
}

impl KeptSamples for &[usize] {
    fn len(self) -> usize {
        <[usize]>::len(self)
    }
    #[inline(always)]
    fn at(self, k: usize) -> usize {
        self[k]
    }
}

/// A span of nanoseconds as f64, exactly as `d as f64` gives it: below
/// 2^63 through i64, one instruction where the u64 conversion takes a
/// dozen on baseline x86-64 (this runs several times per sample).
#[inline(always)]
fn ns_as_f64(d: u64) -> f64 {
    match i64::try_from(d) {
        Ok(v) => v as f64,
        Err(_) => d as f64,
    }
}

/// The nominal sample period (ns): the median step between kept samples.
/// Counts the distinct periods up to [`MAX_BRIDGED_GAP_S`] (within 1 %)
/// into `report`.
fn nominal_period(s: &WheelSeries, kept: impl KeptSamples, report: &mut CleaningReport) -> u64 {
    let time = |k: usize| s.time_ns[kept.at(k)];
    let n = kept.len();
    // Equally spaced samples (a logger's or a block's clock): the median
    // and the one period without sorting the steps.
    if n >= 2 {
        let first = time(1) - time(0);
        if (1..n - 1).all(|k| time(k + 1) - time(k) == first) {
            report.sample_periods = u32::from(bridged_step(first));
            return first;
        }
    }
    counted_period((1..n).map(|k| time(k) - time(k - 1)).collect(), report)
}

/// At most this many distinct steps are counted rather than sorted.
const COUNTED_STEPS: usize = 16;

/// [`sorted_period`]'s result, by counting the distinct steps when there
/// are few (a clock's period, a rate change, the odd dropout: the usual
/// case, where sorting every step took ~30 instructions a sample);
/// sorted when there are more than [`COUNTED_STEPS`].
fn counted_period(steps: Vec<u64>, report: &mut CleaningReport) -> u64 {
    let mut distinct: Vec<(u64, usize)> = Vec::with_capacity(COUNTED_STEPS);
    // The entry the previous step matched: most steps repeat it.
    let mut last = 0;
    for &d in &steps {
        if let Some(entry) = distinct.get_mut(last)
            && entry.0 == d
        {
            entry.1 += 1;
            continue;
        }
        last = match distinct.iter().position(|e| e.0 == d) {
            Some(k) => k,
            None if distinct.len() < COUNTED_STEPS => {
                distinct.push((d, 0));
                distinct.len() - 1
            }
            None => return sorted_period(steps, report),
        };
        distinct[last].1 += 1;
    }
    distinct.sort_unstable();
    // The median as `sorted_period` takes it: the step at index len/2 of
    // the sorted steps (0 with none).
    let mid = steps.len() / 2;
    let mut below = 0;
    let period_ns = distinct
        .iter()
        .find(|&&(_, count)| {
            below += count;
            below > mid
        })
        .map_or(0, |&(d, _)| d);
    // Equal steps fall together in its dedup as well: the distinct
    // periods are the same from the distinct steps.
    report.sample_periods = distinct_periods(distinct.iter().map(|e| e.0));
    period_ns
}

/// Whether a step between samples is bridged rather than a dropout.
fn bridged_step(step_ns: u64) -> bool {
    step_ns as f64 <= MAX_BRIDGED_GAP_S * 1e9
}

/// [`nominal_period`] from the steps, by sorting them.
fn sorted_period(mut steps: Vec<u64>, report: &mut CleaningReport) -> u64 {
    steps.sort_unstable();
    let period_ns = steps.get(steps.len() / 2).copied().unwrap_or(0);
    report.sample_periods = distinct_periods(steps.into_iter());
    period_ns
}

/// How many distinct sample periods sorted steps hold: the bridged ones,
/// each within 1 % of the last one counted falling together with it.
fn distinct_periods(sorted_steps: impl Iterator<Item = u64>) -> u32 {
    let mut periods: Vec<u64> = sorted_steps.filter(|&d| bridged_step(d)).collect();
    periods.dedup_by(|a, b| (*a as f64 - *b as f64).abs() <= 0.01 * *b as f64);
    periods.len() as u32
}

/// A wheel cleaned and ready for the engines: its kept samples as the
/// kernels take them, and the cleaning report.
pub(crate) struct PreparedWheel {
    pub samples: Vec<ReduceSample>,
    pub report: CleaningReport,
}

/// Cleans one wheel (the rule above), alone: the car's lateral
/// acceleration, which needs the other wheels, is unknown (NaN).
pub(crate) fn prepare_wheel(s: &WheelSeries) -> Result<PreparedWheel, String> {
    let mut samples = Vec::new();
    let report = prepare_wheel_into(s, &[], &mut samples)?;
    Ok(PreparedWheel { samples, report })
}

/// [`prepare_wheel`] appending the kept samples to `samples` (a run's
/// batch, filled wheel by wheel without a copy), with the car's lateral
/// acceleration at each of the wheel's samples ([`LateralAcceleration`];
/// empty: unknown); returns the report.
pub(crate) fn prepare_wheel_into(
    s: &WheelSeries,
    lateral_accel: &[f32],
    samples: &mut Vec<ReduceSample>,
) -> Result<CleaningReport, String> {
    let mut report = CleaningReport::default();
    if s.is_empty() {
        return Err("no samples".into());
    }
    let channels = s.channels();
    for ((name, _, _), c) in WHEEL_RANGES.iter().zip(channels) {
        if c.len() != s.len() {
            return Err(format!(
                "channel {name} has {} samples where the wheel has {} timestamps",
                c.len(),
                s.len()
            ));
        }
        if c.iter().all(|&v| v == 0.0) {
            return Err(format!("channel {name} is missing (every sample is 0)"));
        }
    }
    let kept = kept_samples(s, &channels, &mut report);
    if (report.kept as f64) < MIN_VALID_SHARE * report.samples as f64 {
        let worst = WHEEL_RANGES
            .iter()
            .zip(report.invalid_per_channel)
            .max_by_key(|(_, n)| *n)
            .map(|((name, _, _), n)| format!("{name}: {n} invalid"))
            .unwrap_or_default();
        return Err(format!(
            "only {} of {} samples valid ({} time-backwards; worst channel {worst})",
            report.kept, report.samples, report.time_backwards
        ));
    }
    samples.reserve(kept.len());
    let n = s.len();
    let c = Columns::new(channels, n).ok_or("a channel is shorter than the wheel's timestamps")?;
    let lateral = (lateral_accel.len() == n).then(|| &lateral_accel[..n]);
    // Every sample kept is the usual case: read without the index. The
    // closures are inlined into the loop (not inlined, the push was a call
    // per sample with eleven bounds checks).
    match kept {
        Kept::All(n) => for_each_kept(
            s,
            AllSamples(n),
            &mut report,
            #[inline(always)]
            |i, dt, d| push_sample(samples, &c, lateral, i, dt, d),
        ),
        Kept::Indices(kept) => for_each_kept(
            s,
            kept.as_slice(),
            &mut report,
            #[inline(always)]
            |i, dt, d| push_sample(samples, &c, lateral, i, dt, d),
        ),
    }
    Ok(report)
}

/// A wheel's eleven channels (in [`WheelSeries::channels`] order), each
/// cut to the same length: a sample's values read behind one bounds check
/// instead of eleven (the compiler kept all eleven in the push's loop,
/// even with the slices cut to the wheel's length: docs/performance.md).
struct Columns<'a> {
    channels: [&'a [f32]; 11],
    len: usize,
}

impl<'a> Columns<'a> {
    /// The channels cut to `len` values; `None` if one is shorter.
    fn new(channels: [&'a [f32]; 11], len: usize) -> Option<Self> {
        channels.iter().all(|c| c.len() >= len).then(|| Columns {
            channels: channels.map(|c| &c[..len]),
            len,
        })
    }

    /// Sample `i`'s values.
    #[inline(always)]
    fn row(&self, i: usize) -> [f32; 11] {
        assert!(i < self.len, "sample {i} of {}", self.len);
        // SAFETY: every channel holds exactly `len` values (cut in `new`,
        // the only constructor) and i < len, checked just above.
        self.channels.map(|c| unsafe { *c.get_unchecked(i) })
    }
}

/// Appends sample `i` of a wheel's channels as a [`ReduceSample`]; the
/// lateral acceleration NaN where unknown. Always inlined: called once per
/// sample.
#[inline(always)]
fn push_sample(
    samples: &mut Vec<ReduceSample>,
    c: &Columns,
    lateral: Option<&[f32]>,
    i: usize,
    dt: f64,
    d: DerivedConditions,
) {
    let (dt_hi, dt_lo) = ReduceSample::split_dt(dt);
    let [
        vx,
        vy,
        omega,
        radius,
        fx,
        fy,
        fz,
        t_surface,
        t_inner,
        pressure,
        camber,
    ] = c.row(i);
    samples.push(ReduceSample {
        vx,
        vy,
        omega,
        radius,
        fx,
        fy,
        fz,
        t_surface,
        t_inner,
        pressure,
        camber,
        t_surface_rate: d.t_surface_rate as f32,
        t_inner_rate: d.t_inner_rate as f32,
        load_rel: d.load_rel as f32,
        time_s: d.time_s as f32,
        distance_m: d.distance_m as f32,
        accel_x: d.accel_x_mps2 as f32,
        accel_y: lateral.map_or(f32::NAN, |a| a[i]),
        dt: dt_hi,
        dt_lo,
    });
}

/// The car's lateral acceleration |Σ F_y| / m (m/s²) at each sample of
/// each of a run's wheels: Newton's second law over the tires' lateral
/// forces, which the telemetry logs where it logs no acceleration
/// (docs/kpis.md, `accel_y_mps2`). Another wheel's force is taken at the
/// same index where the wheels share their clock (the usual case), else at
/// its latest sample not after this one (its first before it starts); a
/// non-finite force counts as that wheel's last finite one (0 before any),
/// so one wheel's lost sample does not lose the others'.
pub(crate) struct LateralAcceleration {
    /// One series per distinct clock among the wheels.
    series: Vec<Vec<f32>>,
    /// Which series each wheel reads.
    of_wheel: Vec<usize>,
}

impl LateralAcceleration {
    pub(crate) fn new(wheels: &[WheelSeries], mass_kg: f64) -> LateralAcceleration {
        // Forces with the lost samples held; copied only where one is lost.
        let forces: Vec<std::borrow::Cow<[f32]>> = wheels
            .iter()
            .map(|w| {
                if w.fy_n.iter().all(|f| f.is_finite()) {
                    return std::borrow::Cow::Borrowed(w.fy_n.as_slice());
                }
                let mut last = 0.0f32;
                let held = w.fy_n.iter().map(|&f| {
                    if f.is_finite() {
                        last = f;
                    }
                    last
                });
                std::borrow::Cow::Owned(held.collect())
            })
            .collect();
        // Each wheel's clock: the first wheel with the same timestamps.
        let clock: Vec<usize> = (0..wheels.len())
            .map(|k| {
                (0..k)
                    .find(|&j| wheels[j].time_ns == wheels[k].time_ns)
                    .unwrap_or(k)
            })
            .collect();
        let (mut series, mut of_wheel) = (Vec::new(), Vec::with_capacity(wheels.len()));
        for (k, target) in wheels.iter().enumerate() {
            // Wheels on one clock share one series.
            if clock[k] != k {
                of_wheel.push(of_wheel[clock[k]]);
                continue;
            }
            let mut sum = vec![0.0f64; target.len()];
            for ((src, f), &c) in wheels.iter().zip(&forces).zip(&clock) {
                if c == k {
                    sum.iter_mut()
                        .zip(f.iter())
                        .for_each(|(s, &f)| *s += f as f64);
                } else if !src.time_ns.is_empty() {
                    let mut j = 0;
                    for (s, &t) in sum.iter_mut().zip(&target.time_ns) {
                        while j + 1 < src.time_ns.len() && src.time_ns[j + 1] <= t {
                            j += 1;
                        }
                        // A force channel shorter than its clock (a series
                        // built by hand) adds nothing; its wheel is refused.
                        *s += f.get(j).map_or(0.0, |&f| f as f64);
                    }
                }
            }
            of_wheel.push(series.len());
            series.push(sum.iter().map(|s| (s.abs() / mass_kg) as f32).collect());
        }
        LateralAcceleration { series, of_wheel }
    }

    /// At each sample of wheel `k` (the index into the wheels given).
    pub(crate) fn of(&self, k: usize) -> &[f32] {
        self.of_wheel.get(k).map_or(&[], |&i| &self.series[i])
    }
}

/// Half-width of the window temperature rates are taken over (s). One
/// sample is too short: a surface sensor's 0.8 K of noise at 20 Hz is
/// 23 K/s over one step, 1.1 K/s over a second.
pub(crate) const RATE_HALF_WINDOW_S: f64 = 0.5;

/// The conditions of a kept sample that need the wheel's other samples
/// (the condition maps bin them; docs/kpis.md gives the formulas).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct DerivedConditions {
    /// (T(j₁) − T(j₀)) / (t(j₁) − t(j₀)), j₀ and j₁ the first and last kept
    /// samples within ±[`RATE_HALF_WINDOW_S`]; 0 when they are the same (K/s).
    pub t_surface_rate: f64,
    pub t_inner_rate: f64,
    /// F_z over the mean F_z of the kept samples (floored at `LOAD_FLOOR_N`).
    pub load_rel: f64,
    /// Time since the first kept sample (s).
    pub time_s: f64,
    /// Σ v_x·Δt over the kept samples before this one (m), Δt as the
    /// cleaning rule gives it (a dropout counts one period).
    pub distance_m: f64,
    /// dv_x/dt over the same window as the temperature rates (m/s²).
    pub accel_x_mps2: f64,
}

/// The time each kept sample stands for (s) and its [`DerivedConditions`].
#[cfg(test)]
pub(crate) fn derived_conditions(s: &WheelSeries, kept: &[usize]) -> Vec<(f64, DerivedConditions)> {
    let mut report = CleaningReport::default();
    let mut out = Vec::with_capacity(kept.len());
    for_each_kept(s, kept, &mut report, |_, dt, d| out.push((dt, d)));
    out
}

/// Calls `emit(i, dt, conditions)` for each kept sample in order: i its
/// index in the series, dt the time it
/// stands for (s) by the cleaning rule — up to the next kept sample; a
/// gap above [`MAX_BRIDGED_GAP_S`] (a dropout, counted with its missing
/// time in `report`) and the last sample count one nominal period.
fn for_each_kept(
    s: &WheelSeries,
    kept: impl KeptSamples,
    report: &mut CleaningReport,
    mut emit: impl FnMut(usize, f64, DerivedConditions),
) {
    use super::cpu::condition_map::LOAD_FLOOR_N;
    let n = kept.len();
    if n == 0 {
        return;
    }
    let period_s = nominal_period(s, kept, report) as f64 / 1e9;
    let time = |k: usize| s.time_ns[kept.at(k)];
    let start = time(0);
    let half_ns = (RATE_HALF_WINDOW_S * 1e9) as u64;
    let mean_fz = (0..n).map(|k| s.fz_n[kept.at(k)] as f64).sum::<f64>() / n as f64;
    let load_ref = mean_fz.max(LOAD_FLOOR_N);
    let (mut lo, mut hi, mut distance) = (0usize, 0usize, 0.0f64);
    // The window's span changes only where the sampling does: its
    // division is done again only then (0 ns is never a span or a step).
    let (mut span_ns, mut span_s) = (0u64, 0.0f64);
    // So does the step to the next sample (its time in seconds).
    let (mut step_ns, mut step_s) = (0u64, 0.0f64);
    for k in 0..n {
        let i = kept.at(k);
        let t = time(k);
        let dt = match k + 1 < n {
            true => {
                let step = time(k + 1) - t;
                if step != step_ns {
                    (step_ns, step_s) = (step, ns_as_f64(step) / 1e9);
                }
                step_s
            }
            false => period_s,
        };
        let dt = if dt > MAX_BRIDGED_GAP_S {
            report.dropouts += 1;
            report.dropout_time_s += dt - period_s;
            period_s
        } else {
            if dt > 1.5 * period_s {
                report.bridged_gaps += 1;
            }
            dt
        };
        // As differences from t, which cannot overflow (times near the
        // end of the u64 range would wrap a sum and run past the end).
        while t - time(lo) > half_ns {
            lo += 1;
        }
        while hi + 1 < n && time(hi + 1) - t <= half_ns {
            hi += 1;
        }
        // The rates over the same window.
        let (t_surface_rate, t_inner_rate, accel_x_mps2) = if hi == lo {
            (0.0, 0.0, 0.0)
        } else {
            let span = time(hi) - time(lo);
            if span != span_ns {
                (span_ns, span_s) = (span, ns_as_f64(span) / 1e9);
            }
            let (a, b) = (kept.at(lo), kept.at(hi));
            let rate = |c: &[f32]| (c[b] as f64 - c[a] as f64) / span_s;
            (rate(&s.t_surface_c), rate(&s.t_inner_c), rate(&s.vx_mps))
        };
        emit(
            i,
            dt,
            DerivedConditions {
                t_surface_rate,
                t_inner_rate,
                load_rel: s.fz_n[i] as f64 / load_ref,
                time_s: ns_as_f64(t - start) / 1e9,
                distance_m: distance,
                accel_x_mps2,
            },
        );
        distance += s.vx_mps[i] as f64 * dt;
    }
}

/// Table 4 indices from a wheel's merged sums.
pub fn finish_wheel(sums: &[f64; SUMS], r: &ReduceRef) -> Result<WheelIndices, String> {
    let duration_s = sums[Sum::DURATION];
    if duration_s < MIN_DURATION_S {
        return Err(format!("only {duration_s:.1} s of valid telemetry"));
    }
    let m = moments(sums, r);
    let n = sums[Sum::COUNT];
    let (energy_x, energy_y) = (sums[Sum::ENERGY_X], sums[Sum::ENERGY_Y]);
    Ok(WheelIndices {
        t_surface_avg_c: m[0].0,
        t_surface_std_c: m[0].1,
        t_inner_avg_c: m[1].0,
        t_inner_std_c: m[1].1,
        fx_avg_n: m[2].0,
        fx_std_n: m[2].1,
        fy_avg_n: m[3].0,
        fy_std_n: m[3].1,
        fz_avg_n: m[4].0,
        fz_std_n: m[4].1,
        vsx_avg_mps: m[5].0,
        vsx_std_mps: m[5].1,
        vsy_avg_mps: m[6].0,
        vsy_std_mps: m[6].1,
        friction_energy_x_j: energy_x,
        friction_energy_y_j: energy_y,
        friction_energy_j: energy_x + energy_y, // eq. 25
        sliding_distance_m: sums[Sum::SLIDING_DISTANCE],
        camber_avg_deg: sums[Sum::CAMBER] / n,
        pressure_avg_pa: sums[Sum::PRESSURE] / n,
        contact_patch_mm2: sums[Sum::CONTACT_PATCH] / n,
        duration_s,
    })
}

/// Reduces one wheel on the CPU: table-4 indices and energy maps, or why the
/// wheel is rejected (the engines reduce whole runs: `crate::engine`).
pub fn wheel_indices(
    s: &WheelSeries,
) -> Result<(WheelIndices, EnergyMaps, CleaningReport), String> {
    let p = prepare_wheel(s)?;
    let mut batch = ReduceBatch::default();
    batch.push_wheel(&p.samples);
    let sums = merge(&batch, &telemetry_reduce(&batch));
    let k = finish_wheel(&sums[0], &batch.refs[0])?;
    let maps = maps_from_quanta(&energy_map(&batch)).remove(0);
    Ok((k, maps, p.report))
}

/// One wheel's condition and pair maps on the CPU (the twin of
/// `shaders/condition_map.wgsl`), after the same cleaning as
/// [`wheel_indices`]: what an independent reader checks them against. The
/// wheel alone gives no lateral acceleration (it needs the car's four
/// wheels and mass): its map holds the energy in its first bin (NaN).
pub fn wheel_condition_maps(
    s: &WheelSeries,
) -> Result<crate::kpi::cpu::condition_map::ConditionMaps, String> {
    use crate::kpi::cpu::condition_map::{condition_map, condition_maps_from_quanta};
    let p = prepare_wheel(s)?;
    let mut batch = ReduceBatch::default();
    batch.push_wheel(&p.samples);
    Ok(condition_maps_from_quanta(&condition_map(&batch)).remove(0))
}

/// Vehicle indices; samples with a non-finite or out-of-range value are skipped.
pub(crate) fn vehicle_indices(v: &VehicleSeries) -> Result<VehicleIndices, String> {
    let ok = |x: f32, lo: f32, hi: f32| x.is_finite() && x >= lo && x <= hi;
    let (mut track, mut air) = (Moments::default(), Moments::default());
    for (&t, &a) in v.t_track_c.iter().zip(&v.t_air_c).take(v.len()) {
        if ok(t, -30.0, 120.0) && ok(a, -40.0, 70.0) {
            track.push(t as f64);
            air.push(a as f64);
        }
    }
    // The distance covered: the last valid reading less the first (two
    // searches, not a list of every valid reading).
    let dist = &v.distance_m[..v.len().min(v.distance_m.len())];
    let valid = |d: f64| d.is_finite() && d >= 0.0;
    let first = dist.iter().position(|&d| valid(d));
    let last = dist.iter().rposition(|&d| valid(d));
    match (first, last) {
        (Some(a), Some(b)) if track.n > 0.0 && a < b => Ok(VehicleIndices {
            t_track_avg_c: track.mean,
            t_air_avg_c: air.mean,
            distance_m: dist[b] - dist[a],
        }),
        _ => Err("no valid /vehicle samples (track/air temperature, distance)".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The f32 range test keeps exactly the values the f64 one keeps: at
    /// and next to every bound (0.1 is not an f32), and NaN and ±∞.
    /// The rule in f64: finite and lo ≤ v ≤ hi.
    fn in_bounds(v: f32, lo: f64, hi: f64) -> bool {
        let v = v as f64;
        v.is_finite() && v >= lo && v <= hi
    }

    #[test]
    fn vehicle_indices_are_the_mean_and_the_first_to_last_distance() {
        // Hand-made: temperatures kept only where both are in range; the
        // distance from the first to the last finite non-negative reading.
        let v = VehicleSeries {
            time_ns: (0..6).collect(),
            speed_mps: vec![10.0; 6],
            t_track_c: vec![30.0, 31.0, f32::NAN, 33.0, 200.0, 35.0],
            t_air_c: vec![20.0, 21.0, 22.0, 100.0, 24.0, 25.0],
            distance_m: vec![f64::NAN, -1.0, 100.0, f64::INFINITY, 350.5, -0.5],
        };
        let i = vehicle_indices(&v).unwrap();
        assert!((i.t_track_avg_c - (30.0 + 31.0 + 35.0) / 3.0).abs() < 1e-12);
        assert!((i.t_air_avg_c - (20.0 + 21.0 + 25.0) / 3.0).abs() < 1e-12);
        assert_eq!(i.distance_m, 250.5);
        // One valid distance, or no valid temperature pair: an error.
        let one = VehicleSeries {
            distance_m: vec![f64::NAN, -1.0, 100.0, f64::NAN, -2.0, f64::NAN],
            ..v.clone()
        };
        assert!(vehicle_indices(&one).is_err());
        let hot = VehicleSeries {
            t_track_c: vec![200.0; 6],
            ..v.clone()
        };
        assert!(vehicle_indices(&hot).is_err());
        // Channels shorter than the timestamps: an error or a value, not a panic.
        let short = VehicleSeries {
            distance_m: vec![1.0],
            t_air_c: vec![20.0],
            ..v
        };
        assert!(vehicle_indices(&short).is_err());
    }

    #[test]
    fn f32_range_test_is_the_f64_one() {
        for (name, lo, hi) in WHEEL_RANGES {
            let (l, h) = f32_bounds(lo, hi);
            let mut probes = vec![f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.0, -0.0];
            for b in [lo as f32, hi as f32] {
                let mut x = b.next_down().next_down();
                for _ in 0..5 {
                    probes.push(x);
                    x = x.next_up();
                }
            }
            for v in probes {
                assert_eq!(within(v, (l, h)), in_bounds(v, lo, hi), "{name}: {v:e}");
            }
        }
    }

    /// Constant slip: every quantity by hand.
    fn constant_series(n: usize, period_ns: u64) -> WheelSeries {
        let mut s = WheelSeries::default();
        for i in 0..n {
            s.time_ns.push(1_000_000_000 + i as u64 * period_ns);
            s.vx_mps.push(50.0);
            s.vy_mps.push(-1.0);
            s.omega_radps.push(148.5); // ΩR = 49.005 -> v_sx = 0.995 m/s (braking)
            s.rolling_radius_m.push(0.33);
            s.fx_n.push(-2000.0);
            s.fy_n.push(3000.0);
            s.fz_n.push(4000.0);
            s.t_surface_c.push(70.0);
            s.t_inner_c.push(100.0);
            s.pressure_pa.push(160_000.0);
            s.camber_deg.push(-3.0);
        }
        s
    }

    #[test]
    fn constant_slip_energy_by_hand() {
        // 100 Hz for 60 s: P_x = 2000·0.995 = 1990 W, P_y = 3000·1 = 3000 W.
        let s = constant_series(6000, 10_000_000);
        let (k, maps, rep) = wheel_indices(&s).unwrap();
        let vsx = 50.0 - 148.5f32 as f64 * 0.33f32 as f64;
        assert!((k.duration_s - 60.0).abs() < 1e-9);
        assert!((k.friction_energy_x_j - 2000.0 * vsx * 60.0).abs() < 1e-6);
        assert!((k.friction_energy_y_j - 3000.0 * 60.0).abs() < 1e-6);
        assert!((k.sliding_distance_m - vsx.hypot(1.0) * 60.0).abs() < 1e-6);
        // Contact patch: 4000 N / (160 kPa + 40 kPa) = 0.02 m² = 20000 mm².
        assert!((k.contact_patch_mm2 - 20_000.0).abs() < 1e-6);
        assert_eq!(k.t_surface_std_c, 0.0);
        assert!((maps.total() - k.friction_energy_j).abs() < 1e-6);
        let lateral: f64 = maps.lateral_surface_inner.iter().sum();
        assert!((lateral - k.friction_energy_y_j).abs() < 1e-6);
        assert_eq!((rep.dropouts, rep.sample_periods), (0, 1));
    }

    /// A series built by hand (an importer, a test) whose channel is
    /// shorter or longer than its timestamps is refused by name; before,
    /// the shorter one panicked on an index.
    #[test]
    fn channel_of_another_length_is_an_error_naming_it() {
        for (len, what) in [(99, "99 samples"), (101, "101 samples")] {
            let mut s = constant_series(100, 10_000_000);
            s.fy_n.resize(len, 3000.0);
            let e = prepare_wheel(&s).err().expect("refused");
            assert!(e.contains("channel fy_n") && e.contains(what), "{e}");
            assert!(e.contains("100 timestamps"), "{e}");
        }
    }

    /// The cleaning rule's keep list, fast path (every sample kept) or
    /// not, against the rule as docs/kpis.md states it, sample by sample
    /// in f64: kept when every channel is finite and within its range and
    /// its time is after the last kept sample's. Series with nothing wrong,
    /// one value out of range, NaN, ±∞, a repeated or a backward time.
    #[test]
    fn kept_samples_follow_the_rule_stated_sample_by_sample() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(17);
        let rule = |s: &WheelSeries| {
            let mut last: Option<u64> = None;
            let mut kept = Vec::new();
            for i in 0..s.len() {
                let valid = WHEEL_RANGES
                    .iter()
                    .zip(s.channels())
                    .all(|(&(_, lo, hi), c)| in_bounds(c[i], lo, hi));
                if valid && last.is_none_or(|t| s.time_ns[i] > t) {
                    last = Some(s.time_ns[i]);
                    kept.push(i);
                }
            }
            kept
        };
        for case in 0..300 {
            let n = rng.random_range(1..200);
            let mut s = constant_series(n, 10_000_000);
            let i = rng.random_range(0..n);
            match case % 6 {
                0 => {}
                1 => s.time_ns[i] = s.time_ns[i.saturating_sub(1)],
                2 => s.time_ns[i] = s.time_ns[i].saturating_sub(25_000_000),
                3 => s.fz_n[i] = f32::NAN,
                4 => s.t_inner_c[i] = if i % 2 == 0 { f32::INFINITY } else { 250.1 },
                _ => s.camber_deg[i] = -15.000_01,
            }
            let mut report = CleaningReport::default();
            let kept = kept_samples(&s, &s.channels(), &mut report);
            let expected = rule(&s);
            assert_eq!(kept.indices(), expected, "case {case}");
            assert_eq!(report.kept as usize, expected.len());
            assert_eq!(
                matches!(kept, Kept::All(_)),
                expected.len() == n,
                "case {case}"
            );
        }
    }

    /// The period from counted steps is the sorted steps' median, and the
    /// distinct periods the same count, on steps drawn from few values
    /// (within 1 % of each other or not, bridged or not) and from many.
    #[test]
    fn counted_period_is_the_sorted_median() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(29);
        let values = [
            10_000_000u64,
            10_000_001,
            10_050_000,
            10_200_000,
            20_000_000,
            300_000_000,
            500_000_000,
            500_000_001,
            900_000_000,
            2_000_000_000,
        ];
        for case in 0..400 {
            let n = rng.random_range(0..300);
            let few = rng.random_range(1..=values.len());
            let steps: Vec<u64> = (0..n)
                .map(|_| match case % 4 {
                    // Many distinct steps: the sort.
                    3 => rng.random_range(9_000_000..11_000_000),
                    // Mostly one step.
                    0 => {
                        values[if rng.random_bool(0.9) {
                            0
                        } else {
                            rng.random_range(0..few)
                        }]
                    }
                    _ => values[rng.random_range(0..few)],
                })
                .collect();
            let (mut a, mut b) = (CleaningReport::default(), CleaningReport::default());
            let counted = counted_period(steps.clone(), &mut a);
            assert_eq!(counted, sorted_period(steps, &mut b), "case {case}");
            assert_eq!(a.sample_periods, b.sample_periods, "case {case}");
        }
    }

    #[test]
    fn derived_conditions_by_hand() {
        // 10 Hz; the surface heats 2 K per sample (20 K/s), the inner liner
        // 0.1 K per sample (1 K/s); load alternates 3000 / 5000 N (mean 4000).
        let mut s = constant_series(40, 100_000_000);
        for i in 0..40 {
            s.t_surface_c[i] = 60.0 + 2.0 * i as f32;
            s.t_inner_c[i] = 90.0 + 0.1 * i as f32;
            s.fz_n[i] = if i % 2 == 0 { 3000.0 } else { 5000.0 };
        }
        // Sample 20 is lost (a NaN): its neighbours stand for 0.2 s.
        s.vx_mps[20] = f32::NAN;
        let mut report = CleaningReport::default();
        let kept = kept_samples(&s, &s.channels(), &mut report).indices();
        assert_eq!(kept.len(), 39);
        let d = derived_conditions(&s, &kept);
        // Sample 10 (k = 10): window t ± 0.5 s = samples 5..=15, 1 s apart.
        assert!(
            (d[10].1.t_surface_rate - 20.0).abs() < 1e-4,
            "{:?}",
            d[10].1
        );
        assert!((d[10].1.t_inner_rate - 1.0).abs() < 1e-3, "{:?}", d[10].1);
        // First sample: window 0..=5, rate over 0.5 s, the same slope.
        assert!((d[0].1.t_surface_rate - 20.0).abs() < 1e-4);
        // Mean load of the 39 kept samples: the lost sample 20 is an even
        // one (3000 N), so 19 × 3000 + 20 × 5000 = 157000 N over 39.
        let mean = 157_000.0 / 39.0;
        assert!((d[1].1.load_rel - 5000.0 / mean).abs() < 1e-12);
        // Time and distance: kept index 25 is sample 26, 2.6 s in; before
        // it 25 kept samples of 0.1 s at 50 m/s, one of them (19) standing
        // for 0.2 s across the lost one: 26 × 0.1 × 50 = 130 m.
        assert!((d[25].1.time_s - 2.6).abs() < 1e-12);
        assert!(
            (d[25].1.distance_m - 130.0).abs() < 1e-9,
            "{}",
            d[25].1.distance_m
        );
        assert_eq!(d[0].1.distance_m, 0.0);
        // The prepared samples carry them.
        let p = prepare_wheel(&s).unwrap();
        assert_eq!(p.samples[25].distance_m, 130.0);
        assert_eq!(p.samples[25].time_s, 2.6f32);
    }

    #[test]
    fn longitudinal_acceleration_by_hand() {
        // 10 Hz; braking 0.5 m/s per sample (−5 m/s²) from 60 m/s for 20
        // samples, then 50 m/s.
        let mut s = constant_series(40, 100_000_000);
        for i in 0..40 {
            s.vx_mps[i] = 60.0 - 0.5 * i.min(20) as f32;
        }
        let mut report = CleaningReport::default();
        let kept = kept_samples(&s, &s.channels(), &mut report).indices();
        let d = derived_conditions(&s, &kept);
        let a = |k: usize| d[k].1.accel_x_mps2;
        // Sample 10: window 5..=15, (52.5 − 57.5) / 1 s.
        assert!((a(10) + 5.0).abs() < 1e-9, "{}", a(10));
        // The first sample's window is 0..=5 (0.5 s), the same slope.
        assert!((a(0) + 5.0).abs() < 1e-9, "{}", a(0));
        // Sample 20, where the braking ends: (50 − 52.5) / 1 s.
        assert!((a(20) + 2.5).abs() < 1e-9, "{}", a(20));
        assert_eq!(a(30), 0.0);
        let p = prepare_wheel(&s).unwrap();
        assert_eq!(p.samples[20].accel_x, -2.5);
    }

    #[test]
    fn lateral_acceleration_by_hand() {
        // 10 Hz, a 800 kg car; F_y 3000, 2000, 2500, 500 N → 8000 N, 10 m/s².
        let mut wheels: Vec<WheelSeries> =
            (0..4).map(|_| constant_series(6, 100_000_000)).collect();
        for (w, f) in [3000.0, 2000.0, 2500.0, 500.0].into_iter().enumerate() {
            wheels[w].fy_n.iter_mut().for_each(|x| *x = f);
        }
        // A left turn's sign does not matter: |Σ F_y|.
        wheels.iter_mut().for_each(|w| w.fy_n[5] *= -1.0);
        // FR loses sample 2: its 2000 N from sample 1 stand in.
        wheels[1].fy_n[2] = f32::NAN;
        wheels[1].fy_n[1] = 2000.0;
        // RR logs on its own clock, 50 ms late, and its force steps to
        // 1300 N at its sample 3 (t = 0.35 s): the others see it from their
        // sample 4 (0.4 s) on.
        for t in &mut wheels[3].time_ns {
            *t += 50_000_000;
        }
        wheels[3].fy_n[3] = 1300.0;
        wheels[3].fy_n[4] = 1300.0;
        let lateral = LateralAcceleration::new(&wheels, 800.0);
        let a: Vec<&[f32]> = (0..4).map(|k| lateral.of(k)).collect();
        let close = |x: f32, y: f64| ((x as f64) - y).abs() < 1e-5;
        // Sample 0: RR's first sample (0.05 s) is after it; its first counts.
        assert!(close(a[0][0], 10.0), "{:?}", a[0]);
        assert!(close(a[0][2], 10.0) && close(a[1][2], 10.0), "{:?}", a[0]);
        assert!(close(a[0][3], 10.0), "{:?}", a[0]);
        assert!(close(a[0][4], 11.0), "{:?}", a[0]);
        // Sample 5 (0.5 s): −3000 − 2000 − 2500 and RR's 1300 N of 0.45 s.
        assert!(close(a[0][5], 6200.0 / 800.0), "{:?}", a[0]);
        // RR at its sample 3 (0.35 s) takes the others' sample 3 (0.3 s).
        assert!(close(a[3][3], 11.0) && close(a[3][0], 10.0), "{:?}", a[3]);
        assert_eq!(a[0], a[2], "wheels on one clock share the sum");
        // The prepared samples carry it; a wheel cleaned alone has none.
        let mut batch = Vec::new();
        prepare_wheel_into(&wheels[0], a[0], &mut batch).unwrap();
        assert_eq!(batch[4].accel_y, a[0][4]);
        assert!(
            prepare_wheel(&wheels[0]).unwrap().samples[4]
                .accel_y
                .is_nan()
        );
    }

    /// Every sample kept is read without the index; the result is the
    /// indexed route's bit for bit, on uneven steps (jitter, a bridged gap,
    /// a dropout, a rate change), and the equal-step shortcut for the
    /// period is the sorted median's.
    #[test]
    fn every_sample_kept_reads_as_the_indexed_route() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut s = constant_series(3000, 10_000_000);
        let mut t = 1_000_000_000u64;
        for i in 0..s.len() {
            s.time_ns[i] = t;
            t += match i {
                1000 => 300_000_000, // bridged
                2000 => 900_000_000, // a dropout
                _ if i > 2500 => 20_000_000,
                _ => 10_000_000 + rng.random_range(0..200_000),
            };
            s.t_surface_c[i] = 60.0 + rng.random_range(-5.0..5.0);
            s.t_inner_c[i] = 90.0 + rng.random_range(-1.0..1.0);
            s.fz_n[i] = rng.random_range(2000.0..6000.0);
            s.vx_mps[i] = rng.random_range(20.0..80.0);
        }
        let all: Vec<usize> = (0..s.len()).collect();
        let (mut by_index, mut direct) = (Vec::new(), Vec::new());
        let (mut report_by_index, mut report) = Default::default();
        for_each_kept(&s, all.as_slice(), &mut report_by_index, |i, dt, d| {
            by_index.push((i, dt, d))
        });
        for_each_kept(&s, AllSamples(s.len()), &mut report, |i, dt, d| {
            direct.push((i, dt, d))
        });
        assert_eq!(report_by_index, report);
        assert_eq!(by_index, direct);
        // Bridged: the 0.3 s gap and the 498 steps of 20 ms after sample
        // 2500 (twice the median period); one dropout.
        assert_eq!((report.bridged_gaps, report.dropouts), (499, 1));
        assert!(report.sample_periods >= 2);
        // Equal steps, bridged or not: the shortcut and the sort agree.
        for step in [10_000_000u64, 500_000_000, 500_000_001, 2_000_000_000] {
            let even = constant_series(50, step);
            let (mut a, mut b) = (CleaningReport::default(), CleaningReport::default());
            let shortcut = nominal_period(&even, AllSamples(even.len()), &mut a);
            let steps = even.time_ns.windows(2).map(|w| w[1] - w[0]).collect();
            assert_eq!(shortcut, sorted_period(steps, &mut b), "{step}");
            assert_eq!(a.sample_periods, b.sample_periods, "{step}");
        }
    }

    /// Times up to the end of the u64 range (a damaged or hand-written
    /// log time): the rate window neither wraps nor runs past the last
    /// sample, and the rates are those of the same samples anywhere else.
    #[test]
    fn times_at_the_end_of_the_range_prepare_like_any_others() {
        let mut s = constant_series(200, 10_000_000);
        for i in 0..200 {
            s.t_surface_c[i] = 60.0 + 0.5 * i as f32;
        }
        // The last sample 0.6 s after the one before: a window's start
        // then steps from 0.5 s below it to it.
        s.time_ns[199] = s.time_ns[198] + 600_000_000;
        // With a lateral acceleration (a wheel alone has NaN, never equal).
        let prepare = |s: &WheelSeries| {
            let a = LateralAcceleration::new(std::slice::from_ref(s), 800.0);
            let mut out = Vec::new();
            prepare_wheel_into(s, a.of(0), &mut out).unwrap();
            out
        };
        let early = prepare(&s);
        let last = u64::MAX - 100_000_000;
        let shift = last - s.time_ns[199];
        s.time_ns.iter_mut().for_each(|t| *t += shift);
        let late = prepare(&s);
        assert_eq!(late, early);
        // 0.5 K per 10 ms sample; 3000 N over 800 kg.
        assert!((late[150].t_surface_rate - 50.0).abs() < 1e-3);
        assert_eq!(late[150].accel_y, 3.75);
    }

    #[test]
    fn sample_rate_change_is_integrated_exactly() {
        // 10 s at 100 Hz, then 10 s at 50 Hz: 20 s, two periods, constant power 4990 W.
        let mut s = constant_series(1000, 10_000_000);
        let t_end = *s.time_ns.last().unwrap();
        let tail = constant_series(500, 20_000_000);
        s.time_ns.extend(
            tail.time_ns
                .iter()
                .map(|t| t - 1_000_000_000 + t_end + 10_000_000),
        );
        for (a, b) in [
            (&mut s.vx_mps, &tail.vx_mps),
            (&mut s.vy_mps, &tail.vy_mps),
            (&mut s.omega_radps, &tail.omega_radps),
            (&mut s.rolling_radius_m, &tail.rolling_radius_m),
            (&mut s.fx_n, &tail.fx_n),
            (&mut s.fy_n, &tail.fy_n),
            (&mut s.fz_n, &tail.fz_n),
            (&mut s.t_surface_c, &tail.t_surface_c),
            (&mut s.t_inner_c, &tail.t_inner_c),
            (&mut s.pressure_pa, &tail.pressure_pa),
            (&mut s.camber_deg, &tail.camber_deg),
        ] {
            a.extend_from_slice(b);
        }
        let (k, _, rep) = wheel_indices(&s).unwrap();
        assert_eq!(rep.sample_periods, 2);
        // The last sample stands for one median period (10 ms): 10 + 10 − 0.02 + 0.01 s.
        assert!((k.duration_s - 19.99).abs() < 1e-9, "{}", k.duration_s);
        let vsx = 50.0 - 148.5f32 as f64 * 0.33f32 as f64;
        let p = 2000.0 * vsx + 3000.0;
        assert!((k.friction_energy_j - p * k.duration_s).abs() < 1e-6);
    }

    #[test]
    fn cleaning_rule_drops_bad_samples_and_gaps() {
        let mut s = constant_series(2000, 10_000_000);
        s.fz_n[10] = f32::NAN;
        s.t_surface_c[11] = 900.0;
        s.time_ns[12] = s.time_ns[5]; // time going backwards
        // A 2 s dropout: remove samples 500..700.
        for v in [
            &mut s.vx_mps,
            &mut s.vy_mps,
            &mut s.omega_radps,
            &mut s.rolling_radius_m,
            &mut s.fx_n,
            &mut s.fy_n,
            &mut s.fz_n,
            &mut s.t_surface_c,
            &mut s.t_inner_c,
            &mut s.pressure_pa,
            &mut s.camber_deg,
        ] {
            v.drain(500..700);
        }
        s.time_ns.drain(500..700);
        let (k, _, rep) = wheel_indices(&s).unwrap();
        assert_eq!(rep.invalid_per_channel[6], 1);
        assert_eq!(rep.invalid_per_channel[7], 1);
        assert_eq!(rep.time_backwards, 1);
        assert_eq!(rep.dropouts, 1);
        assert!((rep.dropout_time_s - 2.0).abs() < 1e-9);
        // 1800 kept-or-dropped samples span 20 s minus the 2 s dropout; the three bad
        // samples are bridged by their neighbours.
        assert!((k.duration_s - 18.0).abs() < 1e-9, "{}", k.duration_s);
        // A channel absent from every message decodes as 0.0: rejected as missing.
        let mut missing = constant_series(100, 10_000_000);
        missing.camber_deg.iter_mut().for_each(|v| *v = 0.0);
        let err = wheel_indices(&missing).unwrap_err();
        assert!(err.contains("camber_deg is missing"), "{err}");
        // Mostly invalid: rejected with a reason naming the channel.
        let mut bad = constant_series(100, 10_000_000);
        bad.pressure_pa.iter_mut().take(50).for_each(|p| *p = -1.0);
        let err = wheel_indices(&bad).unwrap_err();
        assert!(err.contains("pressure_pa"), "{err}");
    }
}
