//! Small least squares for the gap's nested models: a handful of columns
//! (the baseline's per-group energy terms and the candidate terms) over a few
//! hundred rows, so normal equations and Gram–Schmidt are exact enough and
//! far cheaper than a general solver called thousands of times.

/// Least-squares coefficients of `y` on `cols` over the rows `idx`, no
/// intercept. A column that is zero on every row gets coefficient 0.
pub fn lstsq(cols: &[&[f64]], y: &[f64], idx: &[usize]) -> Vec<f64> {
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
    // Cholesky with empty columns pinned to zero and a relative jitter for
    // near-collinear ones (a threshold step that selects no rows, say).
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

/// `y − Σ coef·col` at row i.
pub fn residual(cols: &[&[f64]], coef: &[f64], y: &[f64], i: usize) -> f64 {
    y[i] - cols.iter().zip(coef).map(|(c, k)| k * c[i]).sum::<f64>()
}

/// An orthonormal basis (over the rows `idx`, as dense vectors of length
/// `idx.len()`) of the span of `cols`, by modified Gram–Schmidt; columns
/// that add nothing are dropped.
pub fn orthonormal_basis(cols: &[&[f64]], idx: &[usize]) -> Vec<Vec<f64>> {
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
pub fn project_out(q: &[Vec<f64>], v: &mut [f64]) {
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
pub fn weighted_fit(
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
        let q = orthonormal_basis(&[&a, &b, &a], &idx);
        assert_eq!(q.len(), 2);
        let mut v = y.clone();
        project_out(&q, &mut v);
        assert!(v.iter().all(|x| x.abs() < 1e-9));
    }
}
