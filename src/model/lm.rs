//! Levenberg–Marquardt for nonlinear least squares, as used to train the
//! feed-forward network (paper table 6): solve (JᵀJ + μI) δ = −Jᵀr with a
//! Cholesky factorisation (faer; in the residuals' space when they are
//! fewer than the parameters); accept the step and lower μ when the sum of
//! squares falls, otherwise raise μ and try again.

use super::ModelError;
use faer::linalg::matmul::triangular::BlockStructure;
use faer::linalg::solvers::Solve;
use faer::{Accum, Mat, Side};

/// A least-squares problem: residuals r(p) and their Jacobian ∂r/∂p.
pub trait LeastSquares {
    fn n_residuals(&self) -> usize;
    fn n_params(&self) -> usize;
    fn residuals(&self, p: &[f64], r: &mut [f64]);
    /// Fills `jac` (n_residuals × n_params).
    fn jacobian(&self, p: &[f64], jac: &mut Mat<f64>);
}

/// Settings (MATLAB trainlm's defaults for μ).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LmSettings {
    pub max_iterations: usize,
    pub mu: f64,
    pub mu_decrease: f64,
    pub mu_increase: f64,
    pub mu_max: f64,
    /// Stop when the relative decrease of the sum of squares is below this.
    pub tolerance: f64,
}

impl Default for LmSettings {
    fn default() -> Self {
        LmSettings {
            max_iterations: 100,
            mu: 1e-3,
            mu_decrease: 0.1,
            mu_increase: 10.0,
            mu_max: 1e10,
            tolerance: 1e-12,
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct LmResult {
    pub params: Vec<f64>,
    /// Sum of squared residuals at `params`.
    pub sse: f64,
    pub iterations: usize,
    /// Sum of squares after each accepted iteration.
    pub history: Vec<f64>,
}

fn sse(r: &[f64]) -> f64 {
    r.iter().map(|v| v * v).sum()
}

/// Where a step's damped normal equations are solved: the parameters'
/// space, (JᵀJ + μI)δ = Jᵀr (m × m), or the residuals', (JJᵀ + μI)u = r
/// then δ = Jᵀu (n × n): the same step for μ > 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum StepSpace {
    Parameters,
    Residuals,
}

impl StepSpace {
    /// The smaller of the two systems.
    pub(crate) fn for_shape(residuals: usize, params: usize) -> StepSpace {
        if residuals < params {
            StepSpace::Residuals
        } else {
            StepSpace::Parameters
        }
    }
}

/// One solver in progress: call [`LmSolver::step`] once per epoch (so a
/// caller can stop early on validation error), or [`levenberg_marquardt`].
pub(crate) struct LmSolver {
    pub params: Vec<f64>,
    /// Sum of squared residuals at `params`.
    pub sse: f64,
    pub mu: f64,
    settings: LmSettings,
    r: Vec<f64>,
    trial_r: Vec<f64>,
    jac: Mat<f64>,
}

impl LmSolver {
    pub fn new(
        problem: &impl LeastSquares,
        p0: &[f64],
        settings: LmSettings,
    ) -> Result<Self, ModelError> {
        let (n, m) = (problem.n_residuals(), problem.n_params());
        if p0.len() != m {
            return Err(ModelError::LengthMismatch(
                "Levenberg-Marquardt start point".into(),
            ));
        }
        let mut r = vec![0.0; n];
        problem.residuals(p0, &mut r);
        Ok(LmSolver {
            params: p0.to_vec(),
            sse: sse(&r),
            mu: settings.mu,
            settings,
            r,
            trial_r: vec![0.0; n],
            jac: Mat::zeros(n, m),
        })
    }

    /// One iteration. Returns false when no step improves the sum of squares
    /// by more than the tolerance (μ has reached its maximum or the fit converged).
    ///
    /// With fewer residuals than parameters (a network on a few hundred
    /// tires: 177 residuals, up to 1 131 weights on the demo) the step is
    /// solved in the residuals' space: (JᵀJ + μI)⁻¹Jᵀr = Jᵀ(JJᵀ + μI)⁻¹r
    /// for μ > 0, an n × n Cholesky instead of an m × m one, the same step
    /// up to rounding (unit test `the_dual_step_is_the_primal_one`).
    pub fn step(&mut self, problem: &impl LeastSquares) -> bool {
        let space = StepSpace::for_shape(self.r.len(), self.params.len());
        self.step_in(problem, space)
    }

    /// [`LmSolver::step`] solved in the given space (`tirewear bench --only
    /// fit` times both on one problem).
    pub(crate) fn step_in(&mut self, problem: &impl LeastSquares, space: StepSpace) -> bool {
        let m = self.params.len();
        problem.jacobian(&self.params, &mut self.jac);
        let dual = space == StepSpace::Residuals;
        let (gram, rhs) = self.gram_and_rhs(dual);
        let k = gram.nrows();
        while self.mu <= self.settings.mu_max {
            let a = Mat::from_fn(k, k, |i, j| {
                gram[(i, j)] + if i == j { self.mu } else { 0.0 }
            });
            let Ok(llt) = a.llt(Side::Lower) else {
                self.mu *= self.settings.mu_increase;
                continue;
            };
            let solved = llt.solve(&rhs);
            let delta = if dual {
                self.jac.transpose() * &solved
            } else {
                solved
            };
            let trial: Vec<f64> = (0..m).map(|i| self.params[i] - delta[(i, 0)]).collect();
            problem.residuals(&trial, &mut self.trial_r);
            let trial_sse = sse(&self.trial_r);
            if trial_sse.is_finite() && trial_sse < self.sse {
                let rel = (self.sse - trial_sse) / self.sse.max(f64::MIN_POSITIVE);
                self.params = trial;
                std::mem::swap(&mut self.r, &mut self.trial_r);
                self.sse = trial_sse;
                self.mu *= self.settings.mu_decrease;
                return rel > self.settings.tolerance;
            }
            self.mu *= self.settings.mu_increase;
        }
        false
    }

    /// The Gram matrix the step factorises, lower triangle only (all the
    /// Cholesky reads, Side::Lower: half the flops of the full product,
    /// which was three quarters of a network's training, docs/models.md),
    /// and the right-hand side: JᵀJ and Jᵀr, or, `dual`, JJᵀ and r.
    fn gram_and_rhs(&self, dual: bool) -> (Mat<f64>, Mat<f64>) {
        let n = self.r.len();
        let r = Mat::from_fn(n, 1, |i, _| self.r[i]);
        let (left, right) = if dual {
            (self.jac.as_ref(), self.jac.transpose())
        } else {
            (self.jac.transpose(), self.jac.as_ref())
        };
        let k = left.nrows();
        let mut gram = Mat::<f64>::zeros(k, k);
        faer::linalg::matmul::triangular::matmul(
            gram.as_mut(),
            BlockStructure::TriangularLower,
            Accum::Replace,
            left,
            BlockStructure::Rectangular,
            right,
            BlockStructure::Rectangular,
            1.0,
            faer::get_global_parallelism(),
        );
        let rhs = if dual { r } else { self.jac.transpose() * &r };
        (gram, rhs)
    }
}

/// r(p) = A p − b with A uniform in ±1 and b in ±3 (seeded): a problem of
/// any shape whose Jacobian costs only a copy, so a step's time is its
/// linear algebra (the unit tests, and `tirewear bench --only fit`).
pub(crate) struct RandomLinear {
    pub a: Mat<f64>,
    pub b: Vec<f64>,
}

impl RandomLinear {
    pub(crate) fn new(seed: u64, residuals: usize, params: usize) -> Self {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        RandomLinear {
            a: Mat::from_fn(residuals, params, |_, _| rng.random_range(-1.0..1.0)),
            b: (0..residuals)
                .map(|_| rng.random_range(-3.0..3.0))
                .collect(),
        }
    }
}

impl LeastSquares for RandomLinear {
    fn n_residuals(&self) -> usize {
        self.a.nrows()
    }
    fn n_params(&self) -> usize {
        self.a.ncols()
    }
    fn residuals(&self, p: &[f64], r: &mut [f64]) {
        for (i, ri) in r.iter_mut().enumerate() {
            *ri = (0..p.len()).map(|j| self.a[(i, j)] * p[j]).sum::<f64>() - self.b[i];
        }
    }
    fn jacobian(&self, _: &[f64], j: &mut Mat<f64>) {
        j.copy_from(&self.a);
    }
}

/// Minimises Σ r(p)² from `p0`.
pub fn levenberg_marquardt(
    problem: &impl LeastSquares,
    p0: &[f64],
    s: &LmSettings,
) -> Result<LmResult, ModelError> {
    let mut solver = LmSolver::new(problem, p0, *s)?;
    let mut history = vec![solver.sse];
    let mut iterations = 0;
    while iterations < s.max_iterations {
        iterations += 1;
        let improved = solver.step(problem);
        if history.last() != Some(&solver.sse) {
            history.push(solver.sse);
        }
        if !improved {
            break;
        }
    }
    Ok(LmResult {
        params: solver.params,
        sse: solver.sse,
        iterations,
        history,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rosenbrock as least squares: r = (10(p1 − p0²), 1 − p0); minimum at (1, 1).
    struct Rosenbrock;
    impl LeastSquares for Rosenbrock {
        fn n_residuals(&self) -> usize {
            2
        }
        fn n_params(&self) -> usize {
            2
        }
        fn residuals(&self, p: &[f64], r: &mut [f64]) {
            r[0] = 10.0 * (p[1] - p[0] * p[0]);
            r[1] = 1.0 - p[0];
        }
        fn jacobian(&self, p: &[f64], j: &mut Mat<f64>) {
            j[(0, 0)] = -20.0 * p[0];
            j[(0, 1)] = 10.0;
            j[(1, 0)] = -1.0;
            j[(1, 1)] = 0.0;
        }
    }

    #[test]
    fn finds_the_rosenbrock_minimum() {
        let res = levenberg_marquardt(&Rosenbrock, &[-1.2, 1.0], &LmSettings::default()).unwrap();
        assert!(
            (res.params[0] - 1.0).abs() < 1e-8 && (res.params[1] - 1.0).abs() < 1e-8,
            "{:?}",
            res.params
        );
        assert!(res.history.windows(2).all(|w| w[1] < w[0]));
    }

    /// The step from p = 0 with damping μ by another route: AᵀA formed in
    /// full (not its lower triangle alone) and solved by LU, so the new p
    /// is −δ with (AᵀA + μI) δ = Aᵀr, r = −b.
    fn step_by_lu(problem: &RandomLinear, mu: f64) -> Vec<f64> {
        use faer::linalg::solvers::Solve;
        let (a, m) = (&problem.a, problem.a.ncols());
        let damped = a.transpose() * a + Mat::<f64>::identity(m, m) * mu;
        let atr = a.transpose() * Mat::from_fn(a.nrows(), 1, |i, _| -problem.b[i]);
        let delta = damped.partial_piv_lu().solve(&atr);
        (0..m).map(|j| -delta[(j, 0)]).collect()
    }

    #[test]
    fn a_step_solves_the_damped_normal_equations() {
        // A Jacobian of 300 × 40: large enough for faer's blocked products.
        let (n, m) = (300, 40);
        let problem = RandomLinear::new(5, n, m);
        let settings = LmSettings {
            mu: 0.7,
            ..LmSettings::default()
        };
        let mut solver = LmSolver::new(&problem, &vec![0.0; m], settings).unwrap();
        assert!(solver.step(&problem));
        let lu = step_by_lu(&problem, 0.7);
        for (j, &expected) in lu.iter().enumerate() {
            assert!(
                (solver.params[j] - expected).abs() <= 1e-12 * expected.abs().max(1.0),
                "{j}: {} vs {expected}",
                solver.params[j]
            );
        }
    }

    /// More parameters than residuals (a network on few tires): the step,
    /// solved in the residuals' space, is the primal one, (JᵀJ + μI)δ = Jᵀr
    /// formed in full and solved by LU, to 1e-9 relative. With μ = 0.7 the
    /// m × m system is well conditioned, so the LU route is exact enough
    /// to judge by.
    #[test]
    fn the_dual_step_is_the_primal_one() {
        let (n, m) = (40, 300);
        let problem = RandomLinear::new(6, n, m);
        let settings = LmSettings {
            mu: 0.7,
            ..LmSettings::default()
        };
        assert_eq!(StepSpace::for_shape(n, m), StepSpace::Residuals);
        let lu = step_by_lu(&problem, 0.7);
        let scale = lu.iter().fold(0.0, |s: f64, v| s.max(v.abs()));
        // The chosen space (the residuals'), and the parameters' forced.
        for space in [None, Some(StepSpace::Parameters)] {
            let mut solver = LmSolver::new(&problem, &vec![0.0; m], settings).unwrap();
            assert!(match space {
                None => solver.step(&problem),
                Some(s) => solver.step_in(&problem, s),
            });
            assert_eq!(solver.mu, 0.7 * 0.1, "the first trial was accepted");
            for (j, &expected) in lu.iter().enumerate() {
                assert!(
                    (solver.params[j] - expected).abs() <= 1e-9 * scale,
                    "{space:?} {j}: {} vs {expected}",
                    solver.params[j]
                );
            }
        }
    }
}
