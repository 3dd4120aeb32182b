//! Small least squares for the gap's nested models: a handful of columns
//! (the baseline's per-group energy terms and the candidate terms) over a few
//! hundred rows, so normal equations and Gram–Schmidt are exact enough and
//! far cheaper than a general solver called thousands of times.

/// Least-squares coefficients of `y` on `cols` over the rows `idx`, no
/// intercept. A column that is zero on every row gets coefficient 0.
pub(crate) fn lstsq(cols: &[&[f64]], y: &[f64], idx: &[usize]) -> Vec<f64> {
    let (g, b) = normal_equations(cols, y, idx);
    Cholesky::new(&g, cols.len()).solve(&b)
}

/// Least squares on fixed columns over fixed rows, factored once for many
/// right-hand sides (every threshold and scope of a candidate, say).
pub(crate) struct Solver {
    gram: Cholesky,
}

impl Solver {
    pub fn new(cols: &[&[f64]], idx: &[usize]) -> Solver {
        let zeros = vec![0.0; cols.first().map_or(0, |c| c.len())];
        let (g, _) = normal_equations(cols, &zeros, idx);
        Solver {
            gram: Cholesky::new(&g, cols.len()),
        }
    }

    /// The coefficients of `y` on the columns (what [`lstsq`] gives).
    pub fn coefficients(&self, cols: &[&[f64]], y: &[f64], idx: &[usize]) -> Vec<f64> {
        let b: Vec<f64> = cols
            .iter()
            .map(|c| idx.iter().map(|&i| c[i] * y[i]).sum())
            .collect();
        self.gram.solve(&b)
    }
}

/// XᵀX (p × p, row-major) and Xᵀy over the rows `idx`.
fn normal_equations(cols: &[&[f64]], y: &[f64], idx: &[usize]) -> (Vec<f64>, Vec<f64>) {
    let p = cols.len();
    let mut g = vec![0.0; p * p];
    let mut b = vec![0.0; p];
    for &i in idx {
        for a in 0..p {
            let xa = cols[a][i];
            if xa == 0.0 {
                continue;
            }
            b[a] += xa * y[i];
            for c in 0..=a {
                g[a * p + c] += xa * cols[c][i];
            }
        }
    }
    for a in 0..p {
        for c in 0..a {
            g[c * p + a] = g[a * p + c];
        }
    }
    (g, b)
}

/// Cholesky factor of a Gram matrix with empty columns pinned to zero and
/// a relative jitter for near-collinear ones (a threshold step that selects
/// no rows, say).
struct Cholesky {
    p: usize,
    l: Vec<f64>,
    dead: Vec<bool>,
}

impl Cholesky {
    /// `g`: the p × p Gram matrix, row-major, both triangles filled.
    fn new(g: &[f64], p: usize) -> Cholesky {
        let scale = (0..p).map(|a| g[a * p + a]).fold(0.0, f64::max).max(1e-300);
        let mut l = vec![0.0; p * p];
        let mut dead = vec![false; p];
        for a in 0..p {
            if g[a * p + a] <= 1e-14 * scale {
                dead[a] = true;
                continue;
            }
            for c in 0..=a {
                if dead[c] {
                    continue;
                }
                let mut s = g[a * p + c];
                for k in 0..c {
                    s -= l[a * p + k] * l[c * p + k];
                }
                if a == c {
                    l[a * p + a] = s.max(1e-12 * g[a * p + a]).sqrt();
                } else {
                    l[a * p + c] = s / l[c * p + c];
                }
            }
        }
        Cholesky { p, l, dead }
    }

    /// G⁻¹ b (0 for the dead columns).
    fn solve(&self, b: &[f64]) -> Vec<f64> {
        let (p, l, dead) = (self.p, &self.l, &self.dead);
        let mut z = vec![0.0; p];
        for a in 0..p {
            if dead[a] {
                continue;
            }
            let mut s = b[a];
            for k in 0..a {
                s -= l[a * p + k] * z[k];
            }
            z[a] = s / l[a * p + a];
        }
        let mut x = vec![0.0; p];
        for a in (0..p).rev() {
            if dead[a] {
                continue;
            }
            let mut s = z[a];
            for k in a + 1..p {
                s -= l[k * p + a] * x[k];
            }
            x[a] = s / l[a * p + a];
        }
        x
    }
}

/// The least-squares fit of `y` on fixed base columns over fixed rows,
/// factored once, so that the fit with one more column (each threshold of
/// each candidate, in every cross-validation fold) costs one pass over the
/// rows, O(n·p), instead of a new fit, O(n·p²): with the tracks' scale
/// columns p is about 20, and these fits were two thirds of a diagnosis.
pub(crate) struct BaseFit {
    gram: Cholesky,
    /// Coefficients of the base fit.
    k0: Vec<f64>,
    /// Its sum of squared residuals over the rows.
    sse0: f64,
    /// The largest squared column norm (the scale of `Cholesky`'s tests).
    scale: f64,
}

impl BaseFit {
    pub fn new(cols: &[&[f64]], y: &[f64], idx: &[usize]) -> BaseFit {
        let (g, b) = normal_equations(cols, y, idx);
        let p = cols.len();
        let scale = (0..p).map(|a| g[a * p + a]).fold(0.0, f64::max);
        let gram = Cholesky::new(&g, p);
        let k0 = gram.solve(&b);
        let sse0 = idx.iter().map(|&i| residual(cols, &k0, y, i).powi(2)).sum();
        BaseFit {
            gram,
            k0,
            sse0,
            scale,
        }
    }

    /// Coefficients of the base fit.
    pub(crate) fn k0(&self) -> &[f64] {
        &self.k0
    }

    /// Coefficients of `y` on the base columns and `x` (the term last) over
    /// the same rows, and the sum of squared residuals, as [`lstsq`] on all
    /// the columns gives them; None when `lstsq` would pin `x`'s coefficient
    /// to 0 (its squared norm at most 1e-14 of the largest column's). By the
    /// partitioned normal equations: β = G⁻¹Xᵀx, x⊥ = x − Xβ,
    /// c = x⊥·r₀ / |x⊥|² (|x⊥|² floored at 1e-12·|x|², `lstsq`'s jitter),
    /// SSE = SSE₀ − 2c·x⊥·r₀ + c²|x⊥|², base coefficients k₀ − c·β.
    pub(crate) fn with_column(
        &self,
        cols: &[&[f64]],
        x: &[f64],
        y: &[f64],
        idx: &[usize],
    ) -> Option<(Vec<f64>, f64)> {
        let rows = nonzero_rows(x, idx);
        let (mut xx, mut xy) = (0.0, 0.0);
        for &(i, xi) in &rows {
            xx += xi * xi;
            xy += xi * y[i];
        }
        if xx <= 1e-14 * self.scale.max(xx) {
            return None;
        }
        let xb = cross_products(cols, &rows);
        let beta = self.gram.solve(&xb);
        let perp = (xx - dot(&xb, &beta)).max(0.0);
        // x⊥·r₀ = x·r₀ (r₀ ⟂ the base) = x·y − (Xᵀx)·k₀.
        let xr = xy - dot(&xb, &self.k0);
        let c = xr / perp.max(1e-12 * xx);
        let mut k: Vec<f64> = self.k0.iter().zip(&beta).map(|(k, b)| k - c * b).collect();
        k.push(c);
        Some((k, self.sse0 - 2.0 * c * xr + c * c * perp))
    }
}

/// The rows of `idx` where x is not 0, with x's value, in `idx`'s order:
/// a scope's column is 0 on the other tires' rows, and the passes of
/// [`cross_products`] then run without a branch per row.
fn nonzero_rows(x: &[f64], idx: &[usize]) -> Vec<(usize, f64)> {
    idx.iter()
        .map(|&i| (i, x[i]))
        .filter(|&(_, xi)| xi != 0.0)
        .collect()
}

/// Xᵀx over `rows` (from [`nonzero_rows`]), each column's sum taken in
/// row order. Four columns at a time, their sums in registers: one sum per
/// column in memory waited on a store and a load per row, and these sums
/// are the largest part of a one-thread diagnosis. Each sum adds the same
/// products in the same order as a plain loop over the rows, skipping
/// those where x is 0, so the results are the same bits.
fn cross_products(cols: &[&[f64]], rows: &[(usize, f64)]) -> Vec<f64> {
    let mut xb = vec![0.0; cols.len()];
    for (group, out) in cols.chunks(4).zip(xb.chunks_mut(4)) {
        let mut s = [0.0f64; 4];
        if let [c0, c1, c2, c3] = group {
            for &(i, xi) in rows {
                s[0] += c0[i] * xi;
                s[1] += c1[i] * xi;
                s[2] += c2[i] * xi;
                s[3] += c3[i] * xi;
            }
        } else {
            for &(i, xi) in rows {
                for (sa, c) in s.iter_mut().zip(group) {
                    *sa += c[i] * xi;
                }
            }
        }
        out.copy_from_slice(&s[..out.len()]);
    }
    xb
}

/// `y − Σ coef·col` at row i.
pub fn residual(cols: &[&[f64]], coef: &[f64], y: &[f64], i: usize) -> f64 {
    y[i] - cols.iter().zip(coef).map(|(c, k)| k * c[i]).sum::<f64>()
}

/// An orthonormal basis (over the rows `idx`, as dense vectors of length
/// `idx.len()`) of the span of `cols`, by modified Gram–Schmidt; columns
/// that add nothing are dropped.
pub(crate) fn orthonormal_basis(cols: &[&[f64]], idx: &[usize]) -> Vec<Vec<f64>> {
    let mut q: Vec<Vec<f64>> = Vec::new();
    for c in cols {
        let mut v: Vec<f64> = idx.iter().map(|&i| c[i]).collect();
        let norm0 = dot(&v, &v).sqrt();
        for u in &q {
            let d = dot(u, &v);
            v.iter_mut().zip(u).for_each(|(a, b)| *a -= d * b);
        }
        let norm = dot(&v, &v).sqrt();
        if norm > 1e-9 * norm0.max(1e-300) && norm > 0.0 {
            v.iter_mut().for_each(|a| *a /= norm);
            q.push(v);
        }
    }
    q
}

/// `v` minus its projection on the orthonormal basis `q`.
pub(crate) fn project_out(q: &[Vec<f64>], v: &mut [f64]) {
    for u in q {
        let d = dot(u, v);
        v.iter_mut().zip(u).for_each(|(a, b)| *a -= d * b);
    }
}

/// `v` times the row weights `w`, element by element (over `w`'s length).
pub fn weighted(v: &[f64], w: &[f64]) -> Vec<f64> {
    v.iter().zip(w).map(|(a, b)| a * b).collect()
}

pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Coefficients of `y` on `cols` fitted on the rows `train` with the row
/// weights `w` (the relative scale for the physics law), and the fitted
/// values on every row (unweighted).
pub(crate) fn weighted_fit(
    cols: &[Vec<f64>],
    w: &[f64],
    y: &[f64],
    train: &[usize],
) -> (Vec<f64>, Vec<f64>) {
    let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
    let scaled: Vec<Vec<f64>> = cols.iter().map(|c| weighted(c, w)).collect();
    let scaled_refs: Vec<&[f64]> = scaled.iter().map(|c| c.as_slice()).collect();
    let k = lstsq(&scaled_refs, &weighted(y, w), train);
    let fitted = (0..y.len())
        .map(|i| y[i] - residual(&refs, &k, y, i))
        .collect();
    (k, fitted)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_fit_and_projection() {
        // y = 2·a − 3·b exactly; an all-zero column gets 0.
        let a: Vec<f64> = (0..10).map(|i| i as f64).collect();
        let b: Vec<f64> = (0..10).map(|i| ((i * 7) % 5) as f64 + 1.0).collect();
        let z = vec![0.0; 10];
        let y: Vec<f64> = a.iter().zip(&b).map(|(a, b)| 2.0 * a - 3.0 * b).collect();
        let idx: Vec<usize> = (0..10).collect();
        let k = lstsq(&[&a, &z, &b], &y, &idx);
        assert!((k[0] - 2.0).abs() < 1e-10 && k[1] == 0.0 && (k[2] + 3.0).abs() < 1e-10);
        // Factored once, the same coefficients for any right-hand side.
        let solver = Solver::new(&[&a, &z, &b], &idx);
        assert_eq!(solver.coefficients(&[&a, &z, &b], &y, &idx), k);
        assert_eq!(
            solver.coefficients(&[&a, &z, &b], &b, &idx)[2],
            lstsq(&[&a, &z, &b], &b, &idx)[2]
        );
        let q = orthonormal_basis(&[&a, &b, &a], &idx);
        assert_eq!(q.len(), 2);
        let mut v = y.clone();
        project_out(&q, &mut v);
        assert!(v.iter().all(|x| x.abs() < 1e-9));
    }

    #[test]
    fn cross_products_are_the_plain_loops_bits() {
        // Against one running sum per column in row order, bit for bit, for
        // 1 to 9 columns (whole groups of four and remainders), rows where x
        // is 0 skipped (a NaN there would show), rows in a scrambled order.
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let n = 200;
        for p in 1..=9 {
            let cols: Vec<Vec<f64>> = (0..p)
                .map(|_| (0..n).map(|_| rng.random_range(-3.0..3.0)).collect())
                .collect();
            let mut x: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let mut cols = cols;
            for i in (0..n).step_by(3) {
                x[i] = 0.0;
                cols[p - 1][i] = f64::NAN;
            }
            let idx: Vec<usize> = (0..n).map(|k| (k * 37) % n).step_by(2).collect();
            let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
            let got = cross_products(&refs, &nonzero_rows(&x, &idx));
            for (a, c) in cols.iter().enumerate() {
                let mut want = 0.0;
                for &i in &idx {
                    if x[i] != 0.0 {
                        want += c[i] * x[i];
                    }
                }
                assert_eq!(got[a].to_bits(), want.to_bits(), "p {p}, column {a}");
            }
        }
    }

    #[test]
    fn one_more_column_matches_a_new_fit() {
        // The partitioned update against lstsq on all the columns and a
        // direct sum of squares, on rows 0..25 of 30; a column zero on those
        // rows, or tiny, is pinned as lstsq pins it.
        let f = |k: usize| -> Vec<f64> {
            (0..30)
                .map(|i| ((i * (k + 3) * 7919) % 101) as f64 / 10.0 - 4.0)
                .collect()
        };
        let (a, b, x, y) = (f(1), f(2), f(3), f(4));
        let idx: Vec<usize> = (0..25).collect();
        let fit = BaseFit::new(&[&a, &b], &y, &idx);
        let (k, sse) = fit.with_column(&[&a, &b], &x, &y, &idx).unwrap();
        let want = lstsq(&[&a, &b, &x], &y, &idx);
        let want_sse: f64 = idx
            .iter()
            .map(|&i| residual(&[&a, &b, &x], &want, &y, i).powi(2))
            .sum();
        for (g, w) in k.iter().zip(&want) {
            assert!((g - w).abs() < 1e-10 * (1.0 + w.abs()), "{k:?} vs {want:?}");
        }
        assert!(
            (sse - want_sse).abs() < 1e-9 * want_sse,
            "{sse} vs {want_sse}"
        );
        let tiny: Vec<f64> = x.iter().map(|v| v * 1e-9).collect();
        assert!(fit.with_column(&[&a, &b], &tiny, &y, &idx).is_none());
        assert_eq!(lstsq(&[&a, &b, &tiny], &y, &idx)[2], 0.0);
        let outside: Vec<f64> = (0..30).map(|i| if i >= 25 { 1.0 } else { 0.0 }).collect();
        assert!(fit.with_column(&[&a, &b], &outside, &y, &idx).is_none());
    }
}
