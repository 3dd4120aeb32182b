//! Road roughness indices (paper table 3) of one profile, and their mean
//! over a track's measurement locations. Formulas and units: docs/kpis.md.

use super::roughness_batch::{FFT_N, Spectral, batches};
use crate::ingest::road::Profile;
use rayon::prelude::*;
use realfft::RealFftPlanner;

/// ISO 16610-21 Gaussian filter cut-off separating macro and micro texture
/// (ISO 13473-1: micro texture is below 0.5 mm).
pub(crate) const MACRO_MICRO_CUTOFF_MM: f64 = 0.5;
/// Self-affine band of the Hurst fit (wavelengths, mm).
pub const HURST_BAND_MM: (f64, f64) = (0.1, 5.0);
/// Welch segment length (samples) of the PSD; shorter profiles use one segment.
pub const WELCH_SEGMENT: usize = 4096;
/// Number of log-spaced HDC lags and of log bins of the PSD side table.
pub(crate) const HDC_LAGS: usize = 48;
pub(crate) const PSD_BINS: usize = 48;

/// Height moments about the mean line with 1/N: (Ra, Rq, Sk, Ku) — paper eqs. 14-16.
pub fn height_moments(z: &[f64]) -> (f64, f64, f64, f64) {
    let n = z.len() as f64;
    let m = z.iter().sum::<f64>() / n;
    let (mut a, mut m2, mut m3, mut m4) = (0.0, 0.0, 0.0, 0.0);
    for v in z {
        let d = v - m;
        a += d.abs();
        m2 += d * d;
        m3 += d * d * d;
        m4 += d * d * d * d;
    }
    let (ra, m2, m3, m4) = (a / n, m2 / n, m3 / n, m4 / n);
    (ra, m2.sqrt(), m3 / m2.powf(1.5), m4 / (m2 * m2))
}

/// ISO 4287 average wavelength λa = 2π·Ra/Δa with Δa the mean absolute slope
/// by forward differences (mm). Replaces the paper's eq. 17, which is dimensionless.
pub fn average_wavelength(z: &[f64], dx_mm: f64) -> f64 {
    let (ra, _, _, _) = height_moments(z);
    let slope =
        z.windows(2).map(|w| (w[1] - w[0]).abs()).sum::<f64>() / ((z.len() - 1) as f64 * dx_mm);
    2.0 * std::f64::consts::PI * ra / slope
}

/// ISO 16610-21 Gaussian low-pass (the mean line): weights
/// `exp(−π (x/(α λc))²)`, α = √(ln2/π), i.e. σ = λc·√(ln2/2)/π, truncated at
/// 4σ, with symmetric (half-sample) reflection at the ends.
pub fn gaussian_lowpass(z: &[f64], dx_mm: f64, cutoff_mm: f64) -> Vec<f64> {
    let sigma = cutoff_mm * (std::f64::consts::LN_2 / 2.0).sqrt() / std::f64::consts::PI / dx_mm;
    let radius = (4.0 * sigma + 0.5) as isize;
    let mut w: Vec<f64> = (-radius..=radius)
        .map(|k| (-0.5 * (k as f64 / sigma).powi(2)).exp())
        .collect();
    let s: f64 = w.iter().sum();
    w.iter_mut().for_each(|v| *v /= s);
    let n = z.len() as isize;
    let at = |i: isize| {
        // half-sample symmetric reflection: ... z1 z0 | z0 z1 ... z_{n-1} | z_{n-1} z_{n-2} ...
        let period = 2 * n;
        let mut j = i.rem_euclid(period);
        if j >= n {
            j = period - 1 - j;
        }
        z[j as usize]
    };
    let edge = |i: isize| -> f64 {
        (-radius..=radius)
            .zip(&w)
            .map(|(k, wk)| wk * at(i + k))
            .sum()
    };
    // Away from the ends the window lies inside the profile: a plain dot
    // product, in four partial sums so that it vectorises (the ends, and
    // profiles shorter than the window, reflect sample by sample).
    (0..n)
        .map(|i| {
            if i < radius || i + radius >= n {
                edge(i)
            } else {
                let u = (i - radius) as usize;
                dot(&z[u..u + w.len()], &w)
            }
        })
        .collect()
}

/// Σ term(a_i, b_i) in four interleaved partial sums (vectorisable; a
/// different rounding order from a serial sum, ~1e-16 relative): one
/// running sum waits on each addition's latency.
#[inline]
fn four_sums(a: &[f64], b: &[f64], term: impl Fn(f64, f64) -> f64) -> f64 {
    let mut acc = [0.0f64; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for l in 0..4 {
            acc[l] += term(x[l], y[l]);
        }
    }
    let tail: f64 = ra.iter().zip(rb).map(|(&x, &y)| term(x, y)).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// Σ a·b (the Gaussian filter's window).
#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    four_sums(a, b, |x, y| x * y)
}

/// Σ (a − b)² (the HDC's sums).
fn squared_differences(a: &[f64], b: &[f64]) -> f64 {
    four_sums(a, b, |x, y| (x - y) * (x - y))
}

/// One-sided PSD in the SurfaceTopography convention `C(q)` (mm³), with
/// `⟨h²⟩ = (1/π)∫C dq`: Welch averaging of Hann-windowed segments (50 %
/// overlap, mean removed per segment, window rescaled to mean(w²) = 1).
/// Returns (q in rad/mm, C) for k = 1..n_seg/2 − 1.
pub fn psd(z: &[f64], dx_mm: f64) -> (Vec<f64>, Vec<f64>) {
    let nseg = WELCH_SEGMENT.min(z.len());
    let step = nseg / 2;
    let mut planner = RealFftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(nseg);
    let w: Vec<f64> = (0..nseg)
        .map(|i| 0.5 - 0.5 * (std::f64::consts::TAU * i as f64 / nseg as f64).cos())
        .collect();
    let w_norm = (w.iter().map(|v| v * v).sum::<f64>() / nseg as f64).sqrt();
    let len = nseg as f64 * dx_mm;
    let mut acc = vec![0.0; nseg / 2 + 1];
    let mut segments = 0;
    let mut buf = fft.make_input_vec();
    let mut spec = fft.make_output_vec();
    let mut start = 0;
    while start + nseg <= z.len() {
        let seg = &z[start..start + nseg];
        let mean = seg.iter().sum::<f64>() / nseg as f64;
        for i in 0..nseg {
            buf[i] = (seg[i] - mean) * w[i] / w_norm;
        }
        fft.process(&mut buf, &mut spec)
            .expect("sizes from the plan");
        for (a, c) in acc.iter_mut().zip(&spec) {
            *a += (dx_mm * dx_mm / len) * c.norm_sqr();
        }
        segments += 1;
        start += step;
    }
    let q = (1..nseg / 2)
        .map(|k| std::f64::consts::TAU * k as f64 / len)
        .collect();
    let c = (1..nseg / 2).map(|k| acc[k] / segments as f64).collect();
    (q, c)
}

/// Height-difference correlation `C(Δ) = ⟨(z(x+Δ) − z(x))²⟩` (mm²) at
/// log-spaced integer lags from 1 sample to a quarter of the profile.
pub fn hdc(z: &[f64], dx_mm: f64) -> (Vec<f64>, Vec<f64>) {
    let lags = hdc_lags(z.len());
    let c = lags
        .iter()
        .map(|&k| {
            // No pairs at a lag beyond the profile: NaN (0/0), not a panic.
            let pairs = z.len().saturating_sub(k);
            squared_differences(&z[z.len() - pairs..], &z[..pairs]) / pairs as f64
        })
        .collect();
    (lags.iter().map(|&k| k as f64 * dx_mm).collect(), c)
}

/// The HDC's lags (samples) for a profile of `n` samples: [`HDC_LAGS`]
/// log-spaced integers from 1 to n/4, duplicates dropped.
pub(crate) fn hdc_lags(n: usize) -> Vec<usize> {
    let max_lag = (n / 4).max(2);
    let mut lags: Vec<usize> = (0..HDC_LAGS)
        .map(|i| {
            (max_lag as f64)
                .powf(i as f64 / (HDC_LAGS - 1) as f64)
                .round() as usize
        })
        .collect();
    lags.dedup();
    lags
}

/// Least-squares slope of log y against log x over points with x in [lo, hi].
fn loglog_slope(x: &[f64], y: &[f64], lo: f64, hi: f64) -> f64 {
    let pts: Vec<(f64, f64)> = x
        .iter()
        .zip(y)
        .filter(|(x, y)| **x >= lo && **x <= hi && **y > 0.0)
        .map(|(x, y)| (x.ln(), y.ln()))
        .collect();
    let n = pts.len() as f64;
    if n < 3.0 {
        return f64::NAN;
    }
    let (mx, my) = pts
        .iter()
        .fold((0.0, 0.0), |a, p| (a.0 + p.0 / n, a.1 + p.1 / n));
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    sxy / sxx
}

/// Averages a spectrum into `bins` log-spaced bins of q (empty bins dropped):
/// equal weight per decade for the fit, and the side table's curve.
pub fn log_bin(q: &[f64], c: &[f64], bins: usize) -> (Vec<f64>, Vec<f64>) {
    let (lo, hi) = (q[0].ln(), q[q.len() - 1].ln());
    let mut sum = vec![(0.0, 0.0, 0usize); bins];
    for (qi, ci) in q.iter().zip(c) {
        let b = (((qi.ln() - lo) / (hi - lo)) * bins as f64).min(bins as f64 - 1.0) as usize;
        sum[b].0 += qi.ln();
        sum[b].1 += ci;
        sum[b].2 += 1;
    }
    sum.iter()
        .filter(|s| s.2 > 0)
        .map(|s| ((s.0 / s.2 as f64).exp(), s.1 / s.2 as f64))
        .unzip()
}

/// Hurst exponent from the PSD: `C ∝ q^−(1+2H)` over [`HURST_BAND_MM`], fitted on log bins.
pub fn hurst_from_psd(q: &[f64], c: &[f64]) -> f64 {
    let (bq, bc) = log_bin(q, c, 64);
    let (lo, hi) = (
        std::f64::consts::TAU / HURST_BAND_MM.1,
        std::f64::consts::TAU / HURST_BAND_MM.0,
    );
    (-loglog_slope(&bq, &bc, lo, hi) - 1.0) / 2.0
}

/// Hurst exponent from the HDC: `C(Δ) ∝ Δ^2H` over the same band of lags.
pub(crate) fn hurst_from_hdc(lag: &[f64], c: &[f64]) -> f64 {
    loglog_slope(lag, c, HURST_BAND_MM.0 / 10.0, HURST_BAND_MM.1 / 10.0) / 2.0
}

/// The road indices of one profile.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct RoadIndices {
    /// λa of the macro texture, λ_Macro (mm).
    pub macro_wavelength_mm: f64,
    /// λa of the micro texture, λ_micro (mm).
    pub micro_wavelength_mm: f64,
    /// Hurst exponent H from the PSD.
    pub hurst: f64,
    /// Hurst exponent from the HDC (cross-check).
    pub hurst_hdc: f64,
    /// Ra of the macro texture, Ra_Macro (mm).
    pub ra_macro_mm: f64,
    /// Ra of the micro texture, Ra_micro (mm).
    pub ra_micro_mm: f64,
    /// Peakyness ζ⊥ = √2·σ (mm), paper eq. 18.
    pub peakyness_mm: f64,
    /// Skewness Sk (paper eq. 15).
    pub skewness: f64,
    /// Kurtosis Ku (paper eq. 16), 3 for Gaussian heights.
    pub kurtosis: f64,
    /// Rq = σ (mm).
    pub rq_mm: f64,
    /// Ra of the whole profile (mm), paper eq. 14.
    pub ra_mm: f64,
}

impl RoadIndices {
    /// Every index undefined (NaN): a track without a usable profile.
    pub const UNDEFINED: RoadIndices = RoadIndices {
        macro_wavelength_mm: f64::NAN,
        micro_wavelength_mm: f64::NAN,
        hurst: f64::NAN,
        hurst_hdc: f64::NAN,
        ra_macro_mm: f64::NAN,
        ra_micro_mm: f64::NAN,
        peakyness_mm: f64::NAN,
        skewness: f64::NAN,
        kurtosis: f64::NAN,
        rq_mm: f64::NAN,
        ra_mm: f64::NAN,
    };

    /// Names (KPI columns) of the indices that are not finite.
    pub(crate) fn undefined(&self) -> Vec<&'static str> {
        [
            ("macro_wavelength_mm", self.macro_wavelength_mm),
            ("micro_wavelength_mm", self.micro_wavelength_mm),
            ("hurst", self.hurst),
            ("hurst_hdc", self.hurst_hdc),
            ("ra_macro_mm", self.ra_macro_mm),
            ("ra_micro_mm", self.ra_micro_mm),
            ("peakyness_mm", self.peakyness_mm),
            ("skewness", self.skewness),
            ("kurtosis", self.kurtosis),
            ("rq_mm", self.rq_mm),
            ("ra_mm", self.ra_mm),
        ]
        .into_iter()
        .filter(|(_, v)| !v.is_finite())
        .map(|(n, _)| n)
        .collect()
    }
}

/// Curves kept for plots and the CPU/GPU comparison.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RoadCurves {
    pub psd_q: Vec<f64>,
    pub psd_c: Vec<f64>,
    pub hdc_lag_mm: Vec<f64>,
    pub hdc_c: Vec<f64>,
}

/// Road indices of every profile with an engine's roughness kernels for
/// profiles of at least one Welch segment (shorter ones, and the ISO split,
/// λa and Hurst fits, on the CPU): the GPU engine's route.
pub(crate) fn profile_indices_on(
    profiles: Vec<Profile>,
    engine: &dyn crate::engine::ReduceEngine,
) -> Result<Vec<(Profile, RoadIndices, RoadCurves)>, crate::engine::EngineError> {
    let long: Vec<(&[f64], f64)> = profiles
        .iter()
        .filter(|p| p.z_mm.len() >= FFT_N)
        .map(|p| (p.z_mm.as_slice(), p.dx_mm))
        .collect();
    let mut spectral: Vec<Option<Spectral>> = vec![None; long.len()];
    for (ids, batch) in batches(&long) {
        for (i, s) in ids.into_iter().zip(engine.roughness(&batch)?) {
            spectral[i] = Some(s);
        }
    }
    let mut spectral = spectral.into_iter();
    let work: Vec<(Profile, Option<Spectral>)> = profiles
        .into_iter()
        .map(|p| {
            let s = if p.z_mm.len() >= FFT_N {
                spectral.next().flatten()
            } else {
                None
            };
            (p, s)
        })
        .collect();
    Ok(work
        .into_par_iter()
        .map(|(p, s)| {
            let (i, c) = match s {
                Some(s) => profile_indices_from(&p, s),
                None => profile_indices(&p),
            };
            (p, i, c)
        })
        .collect())
}

/// All indices and curves of one profile.
pub fn profile_indices(p: &Profile) -> (RoadIndices, RoadCurves) {
    profile_indices_from(p, spectral(p))
}

/// The engine part of a profile's indices on the CPU (f64): height moments,
/// Welch PSD and HDC — what the GPU engine's roughness kernels compute.
pub(crate) fn spectral(p: &Profile) -> Spectral {
    let (psd_q, psd_c) = psd(&p.z_mm, p.dx_mm);
    let (hdc_lag_mm, hdc_c) = hdc(&p.z_mm, p.dx_mm);
    Spectral {
        moments: height_moments(&p.z_mm),
        psd_q,
        psd_c,
        hdc_lag_mm,
        hdc_c,
    }
}

/// A profile's indices and curves from the engine part; the ISO 16610-21
/// split, λa and the Hurst fits are computed here, on the CPU.
pub(crate) fn profile_indices_from(p: &Profile, s: Spectral) -> (RoadIndices, RoadCurves) {
    let z = &p.z_mm;
    let dx = p.dx_mm;
    let (ra, rq, sk, ku) = s.moments;
    let low = gaussian_lowpass(z, dx, MACRO_MICRO_CUTOFF_MM);
    let high: Vec<f64> = z.iter().zip(&low).map(|(a, b)| a - b).collect();
    let (q, c) = (s.psd_q, s.psd_c);
    let (lag, h) = (s.hdc_lag_mm, s.hdc_c);
    let idx = RoadIndices {
        macro_wavelength_mm: average_wavelength(&low, dx),
        micro_wavelength_mm: average_wavelength(&high, dx),
        hurst: hurst_from_psd(&q, &c),
        hurst_hdc: hurst_from_hdc(&lag, &h),
        ra_macro_mm: height_moments(&low).0,
        ra_micro_mm: height_moments(&high).0,
        peakyness_mm: std::f64::consts::SQRT_2 * rq,
        skewness: sk,
        kurtosis: ku,
        rq_mm: rq,
        ra_mm: ra,
    };
    let (bq, bc) = log_bin(&q, &c, PSD_BINS);
    (
        idx,
        RoadCurves {
            psd_q: bq,
            psd_c: bc,
            hdc_lag_mm: lag,
            hdc_c: h,
        },
    )
}

/// Mean of every index over a track's locations.
pub(crate) fn mean_indices(all: &[RoadIndices]) -> RoadIndices {
    let n = all.len() as f64;
    let m = |f: fn(&RoadIndices) -> f64| all.iter().map(f).sum::<f64>() / n;
    RoadIndices {
        macro_wavelength_mm: m(|r| r.macro_wavelength_mm),
        micro_wavelength_mm: m(|r| r.micro_wavelength_mm),
        hurst: m(|r| r.hurst),
        hurst_hdc: m(|r| r.hurst_hdc),
        ra_macro_mm: m(|r| r.ra_macro_mm),
        ra_micro_mm: m(|r| r.ra_micro_mm),
        peakyness_mm: m(|r| r.peakyness_mm),
        skewness: m(|r| r.skewness),
        kurtosis: m(|r| r.kurtosis),
        rq_mm: m(|r| r.rq_mm),
        ra_mm: m(|r| r.ra_mm),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sinusoid_closed_forms() {
        // z = A sin(2πx/λ) over whole periods: Ra = 2A/π, Rq = A/√2, Sk = 0, Ku = 1.5,
        // mean |slope| = 4A/λ so λa = 2π·(2A/π)/(4A/λ) = λ.
        let (a, lam, dx) = (0.3, 2.0, 0.001);
        let n = (20.0 * lam / dx) as usize;
        let z: Vec<f64> = (0..n)
            .map(|i| a * (std::f64::consts::TAU * i as f64 * dx / lam).sin())
            .collect();
        let (ra, rq, sk, ku) = height_moments(&z);
        assert!((ra - 2.0 * a / std::f64::consts::PI).abs() < 1e-6);
        assert!((rq - a / 2f64.sqrt()).abs() < 1e-9);
        assert!(sk.abs() < 1e-9 && (ku - 1.5).abs() < 1e-6);
        assert!((average_wavelength(&z, dx) / lam - 1.0).abs() < 1e-4);
    }

    #[test]
    fn gaussian_lowpass_interior_equals_the_reflected_sum() {
        // Every output against the definition, sample by sample with the
        // reflection, on a random profile longer and shorter than the window.
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        for n in [3usize, 150, 2_000] {
            let z: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let (dx, cutoff) = (0.01, 0.5);
            let sigma = cutoff * (std::f64::consts::LN_2 / 2.0).sqrt() / std::f64::consts::PI / dx;
            let radius = (4.0 * sigma + 0.5) as isize;
            let w: Vec<f64> = (-radius..=radius)
                .map(|k| (-0.5 * (k as f64 / sigma).powi(2)).exp())
                .collect();
            let s: f64 = w.iter().sum();
            let low = gaussian_lowpass(&z, dx, cutoff);
            for (i, &got) in low.iter().enumerate() {
                let mut want = 0.0;
                for (k, wk) in (-radius..=radius).zip(&w) {
                    let mut j = (i as isize + k).rem_euclid(2 * n as isize);
                    if j >= n as isize {
                        j = 2 * n as isize - 1 - j;
                    }
                    want += wk / s * z[j as usize];
                }
                assert!((got - want).abs() <= 1e-13, "n {n}, i {i}: {got} vs {want}");
            }
        }
    }

    #[test]
    fn hdc_is_the_mean_squared_difference_at_each_lag() {
        // Every lag against the definition summed serially in the test, on
        // random profiles of lengths around the four-sum split; lags with no
        // pair of samples are NaN, not a panic.
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        for n in [16usize, 17, 18, 19, 101, 4_099] {
            let z: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let (lag, c) = hdc(&z, 0.02);
            let lags = hdc_lags(n);
            assert_eq!(lag.len(), lags.len());
            for ((&k, &l), &got) in lags.iter().zip(&lag).zip(&c) {
                assert_eq!(l, k as f64 * 0.02);
                let mut sum = 0.0;
                for i in 0..n - k {
                    sum += (z[i + k] - z[i]) * (z[i + k] - z[i]);
                }
                let want = sum / (n - k) as f64;
                assert!(
                    (got - want).abs() <= 1e-13 * want,
                    "n {n}, lag {k}: {got} vs {want}"
                );
            }
        }
        for n in [1usize, 2] {
            let (_, c) = hdc(&vec![0.5; n], 0.02);
            for (&k, v) in hdc_lags(n).iter().zip(&c) {
                assert_eq!(v.is_nan(), k >= n, "n {n}, lag {k}: {v}");
            }
        }
    }

    #[test]
    fn gaussian_filter_passes_long_waves_and_halves_at_cutoff() {
        // ISO 16610-21: transmission 50 % at the cut-off wavelength, ~1 far above it.
        let dx = 0.005;
        let n = 40_000;
        for (lam, expect) in [
            (0.5, 0.5),
            (
                5.0,
                (-std::f64::consts::PI * (0.4697 * 0.5 / 5.0f64).powi(2)).exp(),
            ),
        ] {
            let z: Vec<f64> = (0..n)
                .map(|i| (std::f64::consts::TAU * i as f64 * dx / lam).sin())
                .collect();
            let low = gaussian_lowpass(&z, dx, 0.5);
            let mid = &low[n / 4..3 * n / 4];
            let amp = (2.0 * mid.iter().map(|v| v * v).sum::<f64>() / mid.len() as f64).sqrt();
            assert!((amp - expect).abs() < 2e-3, "λ {lam}: {amp} vs {expect}");
        }
    }

    #[test]
    fn psd_integrates_to_the_variance() {
        // Parseval in this convention: (1/π)∫C dq = ⟨h²⟩ (white noise, Welch-averaged).
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let z: Vec<f64> = (0..1 << 16)
            .map(|_| StandardNormal.sample(&mut rng))
            .collect();
        let (q, c) = psd(&z, 0.01);
        let dq = q[1] - q[0];
        let var = c.iter().sum::<f64>() * dq / std::f64::consts::PI;
        assert!((var - 1.0).abs() < 0.02, "{var}");
    }

    #[test]
    fn unit_amplitude_profile_recovers_hurst() {
        use crate::sim::road::{Amplitudes, gaussian_profile};
        use crate::sim::track::RoadParams;
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        for h in [0.65, 0.8, 0.9] {
            let p = RoadParams {
                hurst: h,
                rms_mm: 0.4,
                rolloff_mm: 30.0,
                cutoff_mm: 0.02,
                skew_coef: 0.0,
                kurt_coef: 0.0,
            };
            let z = gaussian_profile(&p, 1 << 15, 0.005, Amplitudes::Unit, &mut rng);
            let prof = Profile {
                track: "t".into(),
                location: "l".into(),
                x0_mm: 0.0,
                dx_mm: 0.005,
                z_mm: z,
            };
            let (idx, _) = profile_indices(&prof);
            assert!(
                (idx.hurst - h).abs() < 0.02,
                "H {h}: PSD gives {}",
                idx.hurst
            );
            assert!(
                (idx.hurst_hdc - h).abs() < 0.1,
                "H {h}: HDC gives {}",
                idx.hurst_hdc
            );
        }
    }
}
