//! Self-affine road texture profiles by Fourier synthesis: PSD
//! `C(q) ∝ q^−(1+2H)` between the roll-off and cut-off wavenumbers (flat
//! below the roll-off), random phases, then a polynomial height transform
//! that makes the height distribution skewed and heavy-tailed per track.

use super::track::RoadParams;
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use realfft::RealFftPlanner;

/// How Fourier amplitudes are drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Amplitudes {
    /// Rayleigh-distributed (complex Gaussian), as a random surface.
    Random,
    /// Exactly `sqrt(C(q))`: the periodogram equals the target PSD (tests).
    Unit,
}

/// Target 1-D PSD shape (arbitrary scale) at wavenumber q (rad/mm).
pub(crate) fn psd_shape(q: f64, p: &RoadParams) -> f64 {
    let q_r = 2.0 * std::f64::consts::PI / p.rolloff_mm;
    let q_s = 2.0 * std::f64::consts::PI / p.cutoff_mm;
    if q > q_s {
        0.0
    } else {
        (q.max(q_r) / q_r).powf(-(1.0 + 2.0 * p.hurst))
    }
}

/// Gaussian self-affine profile with `n` samples at spacing `dx_mm`, zero mean and rms `p.rms_mm`.
pub fn gaussian_profile(
    p: &RoadParams,
    n: usize,
    dx_mm: f64,
    amps: Amplitudes,
    rng: &mut impl Rng,
) -> Vec<f64> {
    let len = n as f64 * dx_mm;
    let mut planner = RealFftPlanner::<f64>::new();
    let c2r = planner.plan_fft_inverse(n);
    let mut spec = c2r.make_input_vec();
    for (k, s) in spec.iter_mut().enumerate().skip(1) {
        let q = 2.0 * std::f64::consts::PI * k as f64 / len;
        let a = psd_shape(q, p).sqrt();
        let phase = rng.random_range(0.0..std::f64::consts::TAU);
        let mag = match amps {
            Amplitudes::Unit => a,
            Amplitudes::Random => {
                let re: f64 = StandardNormal.sample(rng);
                let im: f64 = StandardNormal.sample(rng);
                a * re.hypot(im) / std::f64::consts::SQRT_2
            }
        };
        *s = realfft::num_complex::Complex::from_polar(mag, phase);
    }
    spec[0] = Default::default();
    if n.is_multiple_of(2) {
        spec[n / 2].im = 0.0; // Nyquist bin must be real
    }
    let mut z = c2r.make_output_vec();
    c2r.process(&mut spec, &mut z).expect("sizes from the plan");
    let rms = (z.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    z.iter_mut().for_each(|v| *v *= p.rms_mm / rms);
    z
}

/// Applies the height transform `y = z + a(z² − 1) + b(z³ − 3z)` (z in rms
/// units) and rescales to zero mean and the original rms.
pub fn shape_heights(z: &mut [f64], p: &RoadParams) {
    let n = z.len() as f64;
    let rms = (z.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
    for v in z.iter_mut() {
        let s = *v / rms;
        *v = s + p.skew_coef * (s * s - 1.0) + p.kurt_coef * (s * s * s - 3.0 * s);
    }
    let mean = z.iter().sum::<f64>() / n;
    let rms2 = (z.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n).sqrt();
    z.iter_mut().for_each(|v| *v = (*v - mean) / rms2 * rms);
}

/// Fraction of the profile variance at wavelengths shorter than `lambda_mm`
/// (from the target PSD): the micro-texture share of the height variance.
pub(crate) fn variance_fraction_below(p: &RoadParams, n: usize, dx_mm: f64, lambda_mm: f64) -> f64 {
    let len = n as f64 * dx_mm;
    let q_split = 2.0 * std::f64::consts::PI / lambda_mm;
    let (mut below, mut total) = (0.0, 0.0);
    for k in 1..=n / 2 {
        let q = 2.0 * std::f64::consts::PI * k as f64 / len;
        let c = psd_shape(q, p);
        total += c;
        if q > q_split {
            below += c;
        }
    }
    below / total
}

/// Height moments of a profile: (Rq, Sk, Ku) about the mean, 1/N.
pub fn moments(z: &[f64]) -> (f64, f64, f64) {
    let n = z.len() as f64;
    let m = z.iter().sum::<f64>() / n;
    let (mut m2, mut m3, mut m4) = (0.0, 0.0, 0.0);
    for v in z {
        let d = v - m;
        m2 += d * d;
        m3 += d * d * d;
        m4 += d * d * d * d;
    }
    let (m2, m3, m4) = (m2 / n, m3 / n, m4 / n);
    (m2.sqrt(), m3 / m2.powf(1.5), m4 / (m2 * m2))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn params(h: f64) -> RoadParams {
        RoadParams {
            hurst: h,
            rms_mm: 0.4,
            rolloff_mm: 20.0,
            cutoff_mm: 0.05,
            skew_coef: 0.0,
            kurt_coef: 0.0,
        }
    }

    /// Least-squares slope of log C vs log q over the self-affine band.
    fn psd_slope(z: &[f64], dx: f64, p: &RoadParams) -> f64 {
        let n = z.len();
        let mut planner = RealFftPlanner::<f64>::new();
        let r2c = planner.plan_fft_forward(n);
        let mut input = z.to_vec();
        let mut out = r2c.make_output_vec();
        r2c.process(&mut input, &mut out).unwrap();
        let len = n as f64 * dx;
        let (q_lo, q_hi) = (
            2.0 * 2.0 * std::f64::consts::PI / p.rolloff_mm,
            0.5 * 2.0 * std::f64::consts::PI / p.cutoff_mm,
        );
        let pts: Vec<(f64, f64)> = out
            .iter()
            .enumerate()
            .skip(1)
            .map(|(k, c)| (2.0 * std::f64::consts::PI * k as f64 / len, c.norm_sqr()))
            .filter(|(q, _)| *q > q_lo && *q < q_hi)
            .map(|(q, c)| (q.ln(), c.ln()))
            .collect();
        let m = pts.len() as f64;
        let (sx, sy) = pts.iter().fold((0.0, 0.0), |a, p| (a.0 + p.0, a.1 + p.1));
        let (mx, my) = (sx / m, sy / m);
        let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
        let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
        sxy / sxx
    }

    #[test]
    fn unit_amplitudes_give_the_exact_hurst_exponent_and_rms() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        for h in [0.6, 0.8, 0.9] {
            let p = params(h);
            let z = gaussian_profile(&p, 1 << 14, 0.01, Amplitudes::Unit, &mut rng);
            let (rq, _, _) = moments(&z);
            assert!((rq - 0.4).abs() < 1e-12);
            // 1-D PSD slope is −(1+2H) (domain notes), so H = (−slope − 1)/2.
            let h_est = (-psd_slope(&z, 0.01, &p) - 1.0) / 2.0;
            assert!((h_est - h).abs() < 1e-6, "H {h} -> {h_est}");
        }
    }

    #[test]
    fn random_amplitudes_recover_hurst_within_tolerance() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let p = params(0.75);
        let z = gaussian_profile(&p, 1 << 16, 0.01, Amplitudes::Random, &mut rng);
        // Rayleigh amplitudes scatter the periodogram; a log-log fit over ~3 decades is good to ±0.03.
        let h_est = (-psd_slope(&z, 0.01, &p) - 1.0) / 2.0;
        assert!((h_est - 0.75).abs() < 0.03, "{h_est}");
    }

    #[test]
    fn height_transform_sets_skew_and_kurtosis_keeps_rms() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut p = params(0.8);
        p.skew_coef = -0.15;
        p.kurt_coef = 0.05;
        let mut z = gaussian_profile(&p, 1 << 16, 0.01, Amplitudes::Random, &mut rng);
        shape_heights(&mut z, &p);
        let (rq, sk, ku) = moments(&z);
        assert!((rq - 0.4).abs() < 1e-12);
        assert!(sk < -0.4, "skewness {sk}");
        assert!(ku > 3.3, "kurtosis {ku}");
    }

    #[test]
    fn non_gaussian_catalogue_profiles_keep_rms_and_hurst() {
        // Every catalogue track as the simulator writes it: rms exact, H from the
        // PSD slope within ±0.06 (random amplitudes ±0.03 plus the height transform's
        // harmonics, which flatten the spectrum slightly).
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        for t in crate::sim::preset::track_catalogue() {
            let mut z = gaussian_profile(&t.road, 1 << 16, 0.01, Amplitudes::Random, &mut rng);
            shape_heights(&mut z, &t.road);
            let (rq, _, _) = moments(&z);
            assert!((rq - t.road.rms_mm).abs() < 1e-12);
            let h = (-psd_slope(&z, 0.01, &t.road) - 1.0) / 2.0;
            assert!(
                (h - t.road.hurst).abs() < 0.06,
                "{}: H {} -> {h}",
                t.id,
                t.road.hurst
            );
        }
    }
}
