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
    /// The columns on the rows, for Xᵀy ([`BaseColumns`]: the tracks'
    /// scale columns are 0 off their track, and a dense pass over them
    /// for every threshold of every candidate's between-track test was a
    /// sixth of a diagnosis).
    columns: BaseColumns,
    rows: Vec<usize>,
}

impl Solver {
    pub fn new(cols: &[&[f64]], idx: &[usize]) -> Solver {
        let zeros = vec![0.0; cols.first().map_or(0, |c| c.len())];
        let (g, _) = normal_equations(cols, &zeros, idx);
        Solver {
            gram: Cholesky::new(&g, cols.len()),
            columns: BaseColumns::new(cols, idx),
            rows: idx.to_vec(),
        }
    }

    /// The coefficients of `y` on the columns over the rows (what
    /// [`lstsq`] gives). Xᵀy is summed over the rows where y is not 0, in
    /// row order: the plain sums' bits, but for the sign of a zero (tested).
    pub fn coefficients(&self, y: &[f64]) -> Vec<f64> {
        let nonzero: Vec<(usize, f64)> = self
            .rows
            .iter()
            .map(|&i| (i, y[i]))
            .filter(|&(_, v)| v != 0.0)
            .collect();
        let mut b = Vec::new();
        self.columns.cross_products_into(y, &nonzero, &mut b);
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
        let mut x = Vec::new();
        self.solve_into(b, &mut x);
        x
    }

    /// [`Cholesky::solve`] into `x` (its length set to p): the forward
    /// substitution's z, then the backward one over z in place — x_a reads
    /// z_a and the x_k after it, which are final by then, so the bits are
    /// those of a separate x.
    fn solve_into(&self, b: &[f64], x: &mut Vec<f64>) {
        let (p, l, dead) = (self.p, &self.l, &self.dead);
        x.clear();
        x.resize(p, 0.0);
        for a in 0..p {
            if dead[a] {
                continue;
            }
            let mut s = b[a];
            for k in 0..a {
                s -= l[a * p + k] * x[k];
            }
            x[a] = s / l[a * p + a];
        }
        for a in (0..p).rev() {
            if dead[a] {
                continue;
            }
            let mut s = x[a];
            for k in a + 1..p {
                s -= l[k * p + a] * x[k];
            }
            x[a] = s / l[a * p + a];
        }
    }
}

/// The least-squares fit of `y` on fixed base columns over fixed rows,
/// factored once, so that the fit with one more column (each threshold of
/// each candidate, in every cross-validation fold) costs one pass over the
/// rows, O(n·p), instead of a new fit, O(n·p²): with the tracks' scale
/// columns p is about 20, and these fits were two thirds of a diagnosis.
pub(crate) struct BaseFit {
    fit: FactoredFit,
    /// The rows of the fit, in order, with `y` on each.
    rows: Vec<(usize, f64)>,
    /// The base columns on those rows.
    columns: BaseColumns,
}

/// A base fit's normal equations, factored: what the fit with one more
/// column needs besides that column's products with the rows.
struct FactoredFit {
    gram: Cholesky,
    /// Coefficients of the base fit.
    k0: Vec<f64>,
    /// Its sum of squared residuals over the rows.
    sse0: f64,
    /// The largest squared column norm (the scale of `Cholesky`'s tests).
    scale: f64,
}

impl FactoredFit {
    fn new(cols: &[&[f64]], y: &[f64], idx: &[usize]) -> FactoredFit {
        let (g, b) = normal_equations(cols, y, idx);
        let p = cols.len();
        let scale = (0..p).map(|a| g[a * p + a]).fold(0.0, f64::max);
        let gram = Cholesky::new(&g, p);
        let k0 = gram.solve(&b);
        let sse0 = idx.iter().map(|&i| residual(cols, &k0, y, i).powi(2)).sum();
        FactoredFit {
            gram,
            k0,
            sse0,
            scale,
        }
    }

    /// Whether a column of squared norm `xx` gets a coefficient (`lstsq`
    /// pins it to 0 at most 1e-14 of the largest column's).
    fn takes(&self, xx: f64) -> bool {
        xx > 1e-14 * self.scale.max(xx)
    }

    /// The fit with a column x given by its products over the fit's rows,
    /// x·x, x·y and Xᵀx (`xb`): its coefficient c and the sum of squared
    /// residuals, β = G⁻¹Xᵀx left in `beta` ([`BaseFit::with_column_in`]
    /// has the algebra).
    fn with_products(
        &self,
        xx: f64,
        xy: f64,
        xb: &[f64],
        beta: &mut Vec<f64>,
    ) -> Option<(f64, f64)> {
        if !self.takes(xx) {
            return None;
        }
        self.gram.solve_into(xb, beta);
        let perp = (xx - dot(xb, beta)).max(0.0);
        // x⊥·r₀ = x·r₀ (r₀ ⟂ the base) = x·y − (Xᵀx)·k₀.
        let xr = xy - dot(xb, &self.k0);
        let c = xr / perp.max(1e-12 * xx);
        Some((c, self.sse0 - 2.0 * c * xr + c * c * perp))
    }

    /// The coefficients with the term (last, `c`), from its β: k₀ − c·β, then c.
    fn coefficients(&self, beta: &[f64], c: f64) -> Vec<f64> {
        let mut k: Vec<f64> = self.k0.iter().zip(beta).map(|(k, b)| k - c * b).collect();
        k.push(c);
        k
    }
}

impl BaseFit {
    pub fn new(cols: &[&[f64]], y: &[f64], idx: &[usize]) -> BaseFit {
        BaseFit {
            fit: FactoredFit::new(cols, y, idx),
            rows: idx.iter().map(|&i| (i, y[i])).collect(),
            columns: BaseColumns::new(cols, idx),
        }
    }

    /// Coefficients of the base fit.
    pub(crate) fn k0(&self) -> &[f64] {
        &self.fit.k0
    }

    /// [`BaseFit::with_column_in`] with the coefficients: the tests'
    /// reference, against [`lstsq`] on all the columns.
    #[cfg(test)]
    pub(crate) fn with_column(&self, x: &[f64]) -> Option<(Vec<f64>, f64)> {
        let mut scratch = Scratch::default();
        let (c, sse) = self.with_column_in(x, &mut scratch)?;
        Some((self.fit.coefficients(&scratch.beta, c), sse))
    }

    /// The fit of `y` on the base columns and `x` (the term last) over the
    /// fit's rows, as [`lstsq`] on all the columns gives it: the term's
    /// coefficient c and the sum of squared residuals, with β = G⁻¹Xᵀx left
    /// in `scratch.beta` for the coefficients (k₀ − c·β); None when `lstsq`
    /// would pin `x`'s coefficient to 0 (its squared norm at most 1e-14 of
    /// the largest column's). By the partitioned normal equations:
    /// x⊥ = x − Xβ, c = x⊥·r₀ / |x⊥|² (|x⊥|² floored at 1e-12·|x|²,
    /// `lstsq`'s jitter), SSE = SSE₀ − 2c·x⊥·r₀ + c²|x⊥|², base
    /// coefficients k₀ − c·β. The scans call it for every threshold, so it
    /// allocates nothing: five buffers per call were a third of the
    /// allocations of a one-thread diagnosis.
    pub(crate) fn with_column_in(&self, x: &[f64], scratch: &mut Scratch) -> Option<(f64, f64)> {
        let Scratch {
            nonzero,
            ys,
            xb,
            beta,
        } = scratch;
        let (xx, xy) = nonzero_rows(&self.rows, x, nonzero, ys);
        if !self.fit.takes(xx) {
            return None;
        }
        self.columns.cross_products_into(x, nonzero, xb);
        self.fit.with_products(xx, xy, xb, beta)
    }
}

/// The best of the columns offered to a fit in turn (each threshold of a
/// candidate): the smallest SSE, the first of equal ones, the coefficient
/// positive where `positive_only`.
#[derive(Default)]
pub(crate) struct BestColumn {
    /// (column, its coefficient, SSE).
    best: Option<(usize, f64, f64)>,
    /// The best one's β = G⁻¹Xᵀx.
    beta: Vec<f64>,
}

impl BestColumn {
    /// Offers column `t`'s fit (`c`, `sse`, β in `beta`); where it is the
    /// best so far, its β is kept (swapped with `beta`'s buffer).
    pub(crate) fn offer(
        &mut self,
        t: usize,
        fit: Option<(f64, f64)>,
        beta: &mut Vec<f64>,
        positive_only: bool,
    ) {
        let Some((c, sse)) = fit else {
            return;
        };
        if positive_only && c <= 0.0 {
            return;
        }
        if self.best.is_none_or(|b| sse < b.2) {
            self.best = Some((t, c, sse));
            std::mem::swap(&mut self.beta, beta);
        }
    }

    /// The best column and the coefficients of its fit (the term last).
    fn chosen(self, fit: &FactoredFit) -> Option<(usize, Vec<f64>)> {
        self.best
            .map(|(t, c, _)| (t, fit.coefficients(&self.beta, c)))
    }

    /// [`BestColumn::chosen`] for a [`BaseFit`].
    pub(crate) fn chosen_in(self, fit: &BaseFit) -> Option<(usize, Vec<f64>)> {
        self.chosen(&fit.fit)
    }
}

/// The base fits that each leave one group of rows out (the
/// cross-validation folds), scanned together for an added column. One pass
/// over the rows gives each group's products with x (x·x, x·y and every
/// column's), and a fold's products are the sums of the other groups'.
/// A fit per fold, each passing over its own rows, cost F passes for F
/// folds: with a season's twelve tracks that was a third of a diagnosis,
/// and it grew faster than the rows (docs/gap.md, "Time, by season
/// size"). The sums are taken in another order than a pass over the
/// fold's rows, so they agree with [`BaseFit::with_column_in`] to
/// rounding, not bit for bit (tested).
pub(crate) struct LeaveGroupOut {
    /// The groups' rows, in order (a partition of the rows).
    groups: Vec<Vec<usize>>,
    y: Vec<f64>,
    /// Each column's entries that are not 0, group by group in row order:
    /// column u's on group g at `ranges[u · groups + g]`.
    entries: Vec<(usize, f64)>,
    ranges: Vec<std::ops::Range<usize>>,
    /// Each fold (group g left out): its fit on the other groups' rows and
    /// the columns it takes, in its order, as indices of the columns given.
    folds: Vec<(FactoredFit, Vec<usize>)>,
}

impl LeaveGroupOut {
    /// The folds of `groups` (a partition of the rows of `columns` and `y`),
    /// the fold leaving group g out fitted on the columns `takes[g]`.
    pub(crate) fn new(
        columns: &[&[f64]],
        y: &[f64],
        groups: &[Vec<usize>],
        takes: &[Vec<usize>],
    ) -> LeaveGroupOut {
        let n = y.len();
        let mut entries = Vec::new();
        let mut ranges = Vec::with_capacity(columns.len() * groups.len());
        for c in columns {
            for g in groups {
                let start = entries.len();
                entries.extend(g.iter().map(|&i| (i, c[i])).filter(|&(_, v)| v != 0.0));
                ranges.push(start..entries.len());
            }
        }
        let folds = groups
            .iter()
            .zip(takes)
            .map(|(test, takes)| {
                let mut out = vec![false; n];
                test.iter().for_each(|&i| out[i] = true);
                let train: Vec<usize> = (0..n).filter(|&i| !out[i]).collect();
                let cols: Vec<&[f64]> = takes.iter().map(|&u| columns[u]).collect();
                (FactoredFit::new(&cols, y, &train), takes.clone())
            })
            .collect();
        LeaveGroupOut {
            groups: groups.to_vec(),
            y: y.to_vec(),
            entries,
            ranges,
            folds,
        }
    }

    /// The columns the fold leaving group `g` out takes.
    pub(crate) fn takes(&self, g: usize) -> &[usize] {
        &self.folds[g].1
    }

    /// The base coefficients of the fold leaving group `g` out.
    pub(crate) fn k0(&self, g: usize) -> &[f64] {
        &self.folds[g].0.k0
    }

    /// For each fold, the best of the columns `x` ([`BestColumn`]) and the
    /// coefficients of its fit (term last): what [`BaseFit::with_column_in`]
    /// on each fold's own fit would choose, to rounding.
    pub(crate) fn best_columns(
        &self,
        x: &[Vec<f64>],
        positive_only: bool,
    ) -> Vec<Option<(usize, Vec<f64>)>> {
        let ng = self.groups.len();
        let nu = self.ranges.len() / ng.max(1);
        // Per group: x·x, x·y, then each column's product with x.
        let mut by_group = vec![0.0; ng * (2 + nu)];
        let mut best: Vec<BestColumn> = (0..ng).map(|_| BestColumn::default()).collect();
        let (mut xb, mut beta) = (Vec::new(), Vec::new());
        for (t, xt) in x.iter().enumerate() {
            for (g, rows) in self.groups.iter().enumerate() {
                let (mut xx, mut xy) = (0.0, 0.0);
                for &i in rows {
                    xx += xt[i] * xt[i];
                    xy += xt[i] * self.y[i];
                }
                by_group[g * (2 + nu)] = xx;
                by_group[g * (2 + nu) + 1] = xy;
            }
            for u in 0..nu {
                for g in 0..ng {
                    let range = self.ranges[u * ng + g].clone();
                    let p: f64 = self.entries[range].iter().map(|&(i, v)| xt[i] * v).sum();
                    by_group[g * (2 + nu) + 2 + u] = p;
                }
            }
            // A fold's product k: the sum over the other groups.
            let others = |left_out: usize, k: usize| -> f64 {
                (0..ng)
                    .filter(|&g| g != left_out)
                    .map(|g| by_group[g * (2 + nu) + k])
                    .sum()
            };
            for (g, ((fit, takes), best)) in self.folds.iter().zip(&mut best).enumerate() {
                let (xx, xy) = (others(g, 0), others(g, 1));
                let chosen = if fit.takes(xx) {
                    xb.clear();
                    xb.extend(takes.iter().map(|&u| others(g, 2 + u)));
                    fit.with_products(xx, xy, &xb, &mut beta)
                } else {
                    None
                };
                best.offer(t, chosen, &mut beta, positive_only);
            }
        }
        best.into_iter()
            .zip(&self.folds)
            .map(|(b, (fit, _))| b.chosen(fit))
            .collect()
    }
}

/// Buffers [`BaseFit::with_column_in`] reuses from one call to the next.
#[derive(Default)]
pub(crate) struct Scratch {
    /// The rows where the term is not 0 ([`nonzero_rows`]), and their y.
    nonzero: Vec<(usize, f64)>,
    ys: Vec<f64>,
    /// Xᵀx.
    xb: Vec<f64>,
    /// G⁻¹Xᵀx.
    pub(crate) beta: Vec<f64>,
}

/// The rows (of `rows`, each with its y) where x is not 0, with x's value,
/// in their order, into `out` (their y into `ys`); and x·x, x·y over them.
/// The rows are gathered without a branch per row (each row is stored,
/// the count moves on where x is not 0): a scope's column is 0 on the
/// other tires, a pattern no branch predictor follows. The sums then run
/// over the rows gathered only: each is one chain of additions, one row
/// per addition's latency, and a term 0 on most rows (another car's
/// tires, a threshold few bins pass) need not wait on them.
fn nonzero_rows(
    rows: &[(usize, f64)],
    x: &[f64],
    out: &mut Vec<(usize, f64)>,
    ys: &mut Vec<f64>,
) -> (f64, f64) {
    out.clear();
    out.resize(rows.len(), (0, 0.0));
    ys.clear();
    ys.resize(rows.len(), 0.0);
    let mut kept = 0;
    for &(i, yi) in rows {
        let xi = x[i];
        // kept ≤ the rows before this one < out.len() = ys.len().
        out[kept] = (i, xi);
        ys[kept] = yi;
        kept += usize::from(xi != 0.0);
    }
    out.truncate(kept);
    ys.truncate(kept);
    let (mut xx, mut xy) = (0.0, 0.0);
    for (&(_, xi), &yi) in out.iter().zip(ys.iter()) {
        xx += xi * xi;
        xy += xi * yi;
    }
    (xx, xy)
}

/// A fit's base columns on its rows, for [`BaseFit::with_column_in`]'s Xᵀx.
/// A column that is not 0 on at least half the rows is read densely over
/// the rows where x is not 0. The others are lists of their entries that
/// are not 0: the baseline's per-group energy terms are 0 off their
/// compound and axle, the tracks' scale columns off their track, and
/// their products with x were most of a one-thread diagnosis. Either way
/// each sum adds the products in row order, and those it leaves out or
/// adds where x is 0 are ±0: the same bits as the plain loop over the rows
/// where x is not 0 (tested), the columns being finite on the fit's rows
/// (a NaN or an infinity there makes the base fit NaN).
struct BaseColumns {
    p: usize,
    /// Column index and values, by row.
    dense: Vec<(usize, Vec<f64>)>,
    /// Column index and its (row, value) entries that are not 0, in row
    /// order; the shortest lists first, so that groups of four have about
    /// the same length.
    sparse: Vec<(usize, Vec<(usize, f64)>)>,
}

impl BaseColumns {
    fn new(cols: &[&[f64]], idx: &[usize]) -> BaseColumns {
        let (mut dense, mut sparse) = (Vec::new(), Vec::new());
        for (a, c) in cols.iter().enumerate() {
            let entries: Vec<(usize, f64)> = idx
                .iter()
                .map(|&i| (i, c[i]))
                .filter(|&(_, v)| v != 0.0)
                .collect();
            if 2 * entries.len() >= idx.len() {
                dense.push((a, c.to_vec()));
            } else {
                sparse.push((a, entries));
            }
        }
        sparse.sort_by_key(|(_, e)| e.len());
        BaseColumns {
            p: cols.len(),
            dense,
            sparse,
        }
    }

    /// Xᵀx, given x's rows that are not 0 (from [`nonzero_rows`]). Four
    /// columns at a time, their sums in registers, so that four chains of
    /// additions run at once.
    #[inline(never)]
    #[cfg(test)]
    fn cross_products(&self, x: &[f64], nonzero: &[(usize, f64)]) -> Vec<f64> {
        let mut xb = Vec::new();
        self.cross_products_into(x, nonzero, &mut xb);
        xb
    }

    /// [`BaseColumns::cross_products`] into `xb` (its length set to p).
    fn cross_products_into(&self, x: &[f64], nonzero: &[(usize, f64)], xb: &mut Vec<f64>) {
        xb.clear();
        xb.resize(self.p, 0.0);
        for group in self.dense.chunks(4) {
            let mut s = [0.0f64; 4];
            if let [(_, c0), (_, c1), (_, c2), (_, c3)] = group {
                for &(i, xi) in nonzero {
                    s[0] += c0[i] * xi;
                    s[1] += c1[i] * xi;
                    s[2] += c2[i] * xi;
                    s[3] += c3[i] * xi;
                }
            } else {
                for &(i, xi) in nonzero {
                    for (sa, (_, c)) in s.iter_mut().zip(group) {
                        *sa += c[i] * xi;
                    }
                }
            }
            for ((a, _), sa) in group.iter().zip(s) {
                xb[*a] = sa;
            }
        }
        for group in self.sparse.chunks(4) {
            let mut s = [0.0f64; 4];
            if let [(_, e0), (_, e1), (_, e2), (_, e3)] = group {
                // Shortest first: `zip` stops at the end of e0, the
                // group's common length.
                let common = e0.len();
                let rows = e0.iter().zip(e1).zip(e2).zip(e3);
                for (((&(i0, v0), &(i1, v1)), &(i2, v2)), &(i3, v3)) in rows {
                    s[0] += x[i0] * v0;
                    s[1] += x[i1] * v1;
                    s[2] += x[i2] * v2;
                    s[3] += x[i3] * v3;
                }
                for (sa, e) in s.iter_mut().zip([e0, e1, e2, e3]) {
                    for &(i, v) in &e[common..] {
                        *sa += x[i] * v;
                    }
                }
            } else {
                for (sa, (_, e)) in s.iter_mut().zip(group) {
                    for &(i, v) in e {
                        *sa += x[i] * v;
                    }
                }
            }
            for ((a, _), sa) in group.iter().zip(s) {
                xb[*a] = sa;
            }
        }
    }
}

/// `y − Σ coef·col` at row i.
pub fn residual(cols: &[&[f64]], coef: &[f64], y: &[f64], i: usize) -> f64 {
    y[i] - cols.iter().zip(coef).map(|(c, k)| k * c[i]).sum::<f64>()
}

/// [`residual`] with one more column `x` after `cols` (its coefficient
/// `coef`'s last), without a new list of the columns: the same sum in the
/// same order.
pub(crate) fn residual_with(cols: &[&[f64]], x: &[f64], coef: &[f64], y: &[f64], i: usize) -> f64 {
    let terms = cols.iter().chain([&x]).zip(coef);
    y[i] - terms.map(|(c, k)| k * c[i]).sum::<f64>()
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

/// [`project_out`] of each of `vs`, four at a time: the four products
/// with each basis vector in one pass ([`dots`]), so four chains of
/// additions run at once where `dot` waits on one (the projections were
/// about a tenth of a one-thread diagnosis). Each vector goes through the
/// same operations in the same order as alone: the same bits (tested).
pub(crate) fn project_out_each(q: &[Vec<f64>], vs: &mut [Vec<f64>]) {
    for group in vs.chunks_mut(4) {
        if let [v0, v1, v2, v3] = group {
            for u in q {
                let d = dots([u, u, u, u], [v0, v1, v2, v3]);
                for (v, d) in [&mut *v0, &mut *v1, &mut *v2, &mut *v3].into_iter().zip(d) {
                    v.iter_mut().zip(u).for_each(|(a, b)| *a -= d * b);
                }
            }
        } else {
            for v in group {
                project_out(q, v);
            }
        }
    }
}

/// [`dot`] of four pairs in one pass, each sum in element order from the
/// value `dot`'s sum starts at: the same bits as four calls, in about the
/// time of one (the calls are bound by their additions' latency).
pub(crate) fn dots(a: [&[f64]; 4], b: [&[f64]; 4]) -> [f64; 4] {
    let n = a[0].len();
    if a.iter().zip(&b).any(|(a, b)| a.len() != n || b.len() != n) {
        return [0, 1, 2, 3].map(|k| dot(a[k], b[k]));
    }
    let start: f64 = std::iter::empty::<f64>().sum();
    let mut s = [start; 4];
    let (a0, a1, a2, a3) = (&a[0][..n], &a[1][..n], &a[2][..n], &a[3][..n]);
    let (b0, b1, b2, b3) = (&b[0][..n], &b[1][..n], &b[2][..n], &b[3][..n]);
    for i in 0..n {
        s[0] += a0[i] * b0[i];
        s[1] += a1[i] * b1[i];
        s[2] += a2[i] * b2[i];
        s[3] += a3[i] * b3[i];
    }
    s
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
        assert_eq!(solver.coefficients(&y), k);
        assert_eq!(
            solver.coefficients(&b)[2],
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
        // Against one running sum per column in row order over the rows
        // where x is not 0, bit for bit, for 1 to 11 columns (whole groups
        // of four and remainders) of different sparsity (dense, half, a
        // tenth and no entries: read densely or as lists, groups of four
        // with common parts and tails), x 0 and −0 on some rows, rows in a
        // scrambled order; and x's rows that are not 0, x·x and x·y as
        // `with_column` takes them.
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let n = 200;
        for p in 1..=11 {
            let cols: Vec<Vec<f64>> = (0..p)
                .map(|a| {
                    let every = [1, 2, 10, 0][a % 4];
                    (0..n)
                        .map(|i| {
                            let on = every != 0 && i % every == a % 3;
                            if on { rng.random_range(-3.0..3.0) } else { 0.0 }
                        })
                        .collect()
                })
                .collect();
            let mut x: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let y: Vec<f64> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
            for i in (0..n).step_by(3) {
                x[i] = if i % 2 == 0 { 0.0 } else { -0.0 };
            }
            let idx: Vec<usize> = (0..n).map(|k| (k * 37) % n).step_by(2).collect();
            let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
            let rows: Vec<(usize, f64)> = idx.iter().map(|&i| (i, y[i])).collect();
            let (mut nonzero, mut ys) = (Vec::new(), Vec::new());
            let (got_xx, got_xy) = nonzero_rows(&rows, &x, &mut nonzero, &mut ys);
            let got = BaseColumns::new(&refs, &idx).cross_products(&x, &nonzero);
            for (a, c) in cols.iter().enumerate() {
                let mut want = 0.0;
                for &i in &idx {
                    if x[i] != 0.0 {
                        want += c[i] * x[i];
                    }
                }
                assert!(want.is_finite(), "p {p}, column {a}");
                assert_eq!(got[a].to_bits(), want.to_bits(), "p {p}, column {a}");
            }
            let (mut xx, mut xy) = (0.0f64, 0.0f64);
            for &i in &idx {
                if x[i] != 0.0 {
                    xx += x[i] * x[i];
                    xy += x[i] * y[i];
                }
            }
            let want_rows: Vec<(usize, f64)> = idx
                .iter()
                .map(|&i| (i, x[i]))
                .filter(|&(_, xi)| xi != 0.0)
                .collect();
            assert_eq!(nonzero, want_rows);
            assert!(xy.is_finite());
            assert_eq!(
                (got_xx.to_bits(), got_xy.to_bits()),
                (xx.to_bits(), xy.to_bits())
            );
        }
    }

    #[test]
    fn dots_and_projections_four_at_a_time_are_one_at_a_times_bits() {
        // Against `dot` and `project_out` one vector at a time, bit for bit:
        // 1 to 9 vectors (groups of four and remainders), sums that cancel
        // to ±0, unequal lengths (dot's zip stops at the shorter), a basis
        // from Gram–Schmidt as the diagnosis builds it.
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(9);
        let n = 57;
        let mut r =
            |n: usize| -> Vec<f64> { (0..n).map(|_| rng.random_range(-1.0..1.0)).collect() };
        let basis_cols: Vec<Vec<f64>> = (0..5).map(|_| r(n)).collect();
        let refs: Vec<&[f64]> = basis_cols.iter().map(|c| c.as_slice()).collect();
        let all: Vec<usize> = (0..n).collect();
        let q = orthonormal_basis(&refs, &all);
        for count in 1..=9 {
            let vs: Vec<Vec<f64>> = (0..count).map(|_| r(n)).collect();
            let mut got = vs.clone();
            project_out_each(&q, &mut got);
            for (v, g) in vs.iter().zip(&got) {
                let mut want = v.clone();
                project_out(&q, &mut want);
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(g), bits(&want), "{count} vectors");
            }
        }
        let (a, b, c) = (r(n), r(n), r(n - 3));
        let neg: Vec<f64> = a.iter().map(|x| -x).collect();
        let zero = vec![-0.0; n];
        let pairs = [(&a, &b), (&a, &neg), (&zero, &a), (&b, &b)];
        let got = dots(pairs.map(|p| p.0.as_slice()), pairs.map(|p| p.1.as_slice()));
        for ((x, y), g) in pairs.iter().zip(got) {
            assert_eq!(g.to_bits(), dot(x, y).to_bits());
        }
        let uneven = [(&a, &c), (&b, &b), (&c, &a), (&a, &a)];
        let got = dots(
            uneven.map(|p| p.0.as_slice()),
            uneven.map(|p| p.1.as_slice()),
        );
        for ((x, y), g) in uneven.iter().zip(got) {
            assert_eq!(g.to_bits(), dot(x, y).to_bits());
        }
    }

    /// The substitutions in one buffer are the two-buffer ones bit for
    /// bit (z kept apart from x, as `solve` was written before), dead
    /// columns included; and `with_column_in` with a reused scratch gives
    /// every threshold's fit as a fresh `with_column` does.
    #[test]
    fn solve_in_place_and_reused_scratch_are_the_same_bits() {
        fn two_buffers(c: &Cholesky, b: &[f64]) -> Vec<f64> {
            let (p, l, dead) = (c.p, &c.l, &c.dead);
            let mut z = vec![0.0; p];
            for a in (0..p).filter(|&a| !dead[a]) {
                let mut s = b[a];
                for k in 0..a {
                    s -= l[a * p + k] * z[k];
                }
                z[a] = s / l[a * p + a];
            }
            let mut x = vec![0.0; p];
            for a in (0..p).rev().filter(|&a| !dead[a]) {
                let mut s = z[a];
                for k in a + 1..p {
                    s -= l[k * p + a] * x[k];
                }
                x[a] = s / l[a * p + a];
            }
            x
        }
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(9);
        let n = 60;
        for p in 1..=9 {
            // Column 1 all 0 (dead) where there is one.
            let cols: Vec<Vec<f64>> = (0..p)
                .map(|a| {
                    (0..n)
                        .map(|_| {
                            if a == 1 {
                                0.0
                            } else {
                                rng.random_range(-3.0..3.0)
                            }
                        })
                        .collect()
                })
                .collect();
            let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
            let y: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..5.0)).collect();
            let idx: Vec<usize> = (0..n).filter(|i| i % 7 != 3).collect();
            let (g, b) = normal_equations(&refs, &y, &idx);
            let chol = Cholesky::new(&g, p);
            assert_eq!(chol.dead.iter().any(|&d| d), p > 1);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            let mut x = vec![7.0; 2 * p];
            chol.solve_into(&b, &mut x);
            assert_eq!(bits(&x), bits(&two_buffers(&chol, &b)), "p = {p}");
            let fit = BaseFit::new(&refs, &y, &idx);
            let mut scratch = Scratch::default();
            for t in 0..6 {
                let term: Vec<f64> = (0..n)
                    .map(|i| {
                        if (i + t) % 3 == 0 {
                            0.0
                        } else {
                            rng.random_range(0.0..2.0)
                        }
                    })
                    .collect();
                let (k, sse) = fit.with_column(&term).unwrap();
                let (c, sse_in) = fit.with_column_in(&term, &mut scratch).unwrap();
                assert_eq!(sse.to_bits(), sse_in.to_bits());
                assert_eq!(bits(&k), bits(&fit.fit.coefficients(&scratch.beta, c)));
            }
        }
    }

    #[test]
    fn residual_with_one_more_column_is_residuals_bits() {
        let (a, b, x) = ([0.1, 0.7, -2.3], [1.0 / 3.0, 5.5, 1e-17], [3.0, 1e16, -0.2]);
        let (k, y) = ([0.3, -1.7, 2.9], [1.1, -4.0, 0.6]);
        for i in 0..3 {
            let want = residual(&[&a, &b, &x], &k, &y, i);
            assert_eq!(
                residual_with(&[&a, &b], &x, &k, &y, i).to_bits(),
                want.to_bits()
            );
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
        let (k, sse) = fit.with_column(&x).unwrap();
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
        assert!(fit.with_column(&tiny).is_none());
        assert_eq!(lstsq(&[&a, &b, &tiny], &y, &idx)[2], 0.0);
        let outside: Vec<f64> = (0..30).map(|i| if i >= 25 { 1.0 } else { 0.0 }).collect();
        assert!(fit.with_column(&outside).is_none());
    }

    #[test]
    fn folds_scanned_together_choose_as_each_folds_own_fit() {
        // Six groups of 40 rows, scattered; dense columns and cell-like
        // ones (0 off one group), each fold taking its own subset of them.
        // Each fold's choice among the thresholds, and its coefficients,
        // against each fold's own BaseFit scanned with `best_threshold`'s
        // rule and against lstsq on the fold's columns and the chosen
        // term. The thresholds include a column 0 on every row, one 0 off
        // one group (so 0 on that fold's rows: no fit there), and ones
        // whose coefficient is negative, which `positive_only` refuses.
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let (n, ng) = (240, 6);
        let group_of: Vec<usize> = (0..n).map(|i| (i * 7) % ng).collect();
        let groups: Vec<Vec<usize>> = (0..ng)
            .map(|g| (0..n).filter(|&i| group_of[i] == g).collect())
            .collect();
        let mut cols: Vec<Vec<f64>> = (0..3)
            .map(|_| (0..n).map(|_| rng.random_range(0.5..2.0)).collect())
            .collect();
        for g in 0..ng {
            let b: Vec<f64> = (0..n)
                .map(|i| {
                    if group_of[i] == g {
                        rng.random_range(0.8..1.2)
                    } else {
                        0.0
                    }
                })
                .collect();
            cols.push(b);
        }
        let y: Vec<f64> = (0..n)
            .map(|i| cols[0][i] + 0.5 * cols[1][i] + rng.random_range(-0.3..0.3))
            .collect();
        // Fold g takes the dense columns and every other group's cell but
        // the first of them (as the track cells do).
        let takes: Vec<Vec<usize>> = (0..ng)
            .map(|g| {
                let cells = (0..ng).filter(|&h| h != g).skip(1).map(|h| 3 + h);
                (0..3).chain(cells).collect()
            })
            .collect();
        let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
        let folds = LeaveGroupOut::new(&refs, &y, &groups, &takes);
        let mut x: Vec<Vec<f64>> = (0..5)
            .map(|t| {
                (0..n)
                    .map(|i| {
                        let v: f64 = rng.random_range(0.0..1.0);
                        if v < 0.2 * t as f64 {
                            0.0
                        } else {
                            v * cols[2][i]
                        }
                    })
                    .collect()
            })
            .collect();
        x.push(vec![0.0; n]);
        x.push(
            (0..n)
                .map(|i| if group_of[i] == 2 { 1.0 } else { 0.0 })
                .collect(),
        );
        x.push(y.iter().map(|v| -v).collect());
        for positive_only in [false, true] {
            let together = folds.best_columns(&x, positive_only);
            for (g, chosen) in together.iter().enumerate() {
                let train: Vec<usize> = (0..n).filter(|&i| group_of[i] != g).collect();
                let own: Vec<&[f64]> = takes[g].iter().map(|&u| refs[u]).collect();
                let fit = BaseFit::new(&own, &y, &train);
                let (mut best, mut scratch) = (BestColumn::default(), Scratch::default());
                for (t, xt) in x.iter().enumerate() {
                    let c = fit.with_column_in(xt, &mut scratch);
                    best.offer(t, c, &mut scratch.beta, positive_only);
                }
                let (t, k) = chosen.as_ref().expect("a threshold fits");
                let (t_own, k_own) = best.chosen_in(&fit).unwrap();
                assert_eq!(*t, t_own, "fold {g}");
                assert_ne!(*t, 5, "the zero column is never chosen");
                assert!(
                    !(g == 2 && *t == 6),
                    "a column 0 on the fold's rows has no fit"
                );
                let mut with: Vec<&[f64]> = own.clone();
                with.push(&x[*t]);
                let want = lstsq(&with, &y, &train);
                for ((a, b), w) in k.iter().zip(&k_own).zip(&want) {
                    assert!(
                        (a - b).abs() < 1e-10 * (1.0 + b.abs()),
                        "fold {g}: {k:?} vs {k_own:?}"
                    );
                    assert!(
                        (a - w).abs() < 1e-8 * (1.0 + w.abs()),
                        "fold {g}: {k:?} vs lstsq {want:?}"
                    );
                }
                if positive_only {
                    assert!(k[k.len() - 1] > 0.0);
                } else {
                    assert_eq!(*t, 7, "−y fits y exactly");
                }
            }
        }
    }
}
