//! The clamped strip of `tests/common` as a [`NonlinearProblem`] for the Newton driver, solved
//! through a dense pattern (tests only; the library's sparse shell problem is
//! `shell::problem`).
//!
//! Unknowns are the transformed (nodal) values `ũ = Λ d` of the clamping transformation, 5 per
//! particle; the clamped particles' 5 nodal values are held at zero through the driver's
//! essential conditions. Within a step the model's increment is `q = Λ⁻¹ (ũ − ũ_committed)`.
//! Residual `r̃ = Λ⁻ᵀ (f_int(q) − λ f_ext(q))` with `f_ext = dead + Σ loads(q)`, tangent
//! `K̃ = Λ⁻ᵀ (K − λ Σ ∂f_load/∂q) Λ⁻¹`. `Λ⁻¹` differs from the identity only in the rows of the
//! clamped particles, so `K̃` is formed from those rows (`O(n² m)` for `m` clamped DOFs) rather
//! than by two dense `n³` products.
#![allow(dead_code)] // each test file uses a subset

use crate::common::Strip;
use nalgebra::DMatrix;
use shelldsa::shell::load::ExternalLoad;
use shelldsa::shell::model::LocalContribution;
use shelldsa::solver::{
    LinearSolver, Method, NonlinearProblem, ProblemError, SolverOptions, SparsityPattern,
};

const C: usize = 5;

/// The strip under dead and configuration-dependent loads.
pub struct StripProblem {
    /// Model, shape functions, clamp (the model holds the committed state).
    pub strip: Strip,
    /// Dead generalised load at load factor 1.
    pub dead: Vec<f64>,
    /// Further loads (follower loads add their stiffness).
    pub loads: Vec<Box<dyn ExternalLoad>>,
    pattern: SparsityPattern,
    /// The clamped DOFs `J` and the rows `Λ⁻¹[J, :]`.
    fixed: Vec<usize>,
    t_rows: DMatrix<f64>,
    /// Further DOFs held at zero (unconstrained particles: their generalised coefficients).
    restrained: Vec<usize>,
    committed: Vec<f64>,
    cache: Option<(Vec<f64>, Vec<LocalContribution>)>,
    scale: f64,
    /// Residual evaluations so far.
    pub evaluations: usize,
}

fn fatal<E: std::fmt::Display>(e: E) -> ProblemError {
    ProblemError::Fatal(e.to_string())
}

impl StripProblem {
    /// The problem at the strip's committed state.
    pub fn new(strip: Strip, dead: Vec<f64>, loads: Vec<Box<dyn ExternalLoad>>) -> Self {
        let n = strip.model.n_dofs();
        let all: Vec<usize> = (0..n).collect();
        let pattern = SparsityPattern::from_cells(n, &[all]).unwrap();
        let fixed = strip.clamp.constrained_dofs(C);
        let inv = strip
            .clamp
            .lambda_dense(C)
            .try_inverse()
            .expect("the clamping transformation is regular");
        let t_rows = DMatrix::from_fn(fixed.len(), n, |a, j| inv[(fixed[a], j)]);
        StripProblem {
            strip,
            dead,
            loads,
            pattern,
            fixed,
            t_rows,
            restrained: Vec::new(),
            committed: vec![0.0; n],
            cache: None,
            scale: 0.0,
            evaluations: 0,
        }
    }

    /// Hold component `c` of every particle outside the clamp at zero (e.g. the out-of-plane
    /// displacement and rotation of a plane problem). The clamped particles' nodal values are
    /// all fixed already.
    pub fn restrain_component(&mut self, c: usize) {
        let clamped = self.strip.clamp.constrained().to_vec();
        for i in 0..self.strip.model.particles.len() {
            if !clamped.contains(&i) {
                self.restrained.push(C * i + c);
            }
        }
    }

    /// The dense pattern (give it to the driver).
    pub fn pattern(&self) -> &SparsityPattern {
        &self.pattern
    }

    /// A sparse LU solver on the pattern.
    pub fn solver(&self) -> LinearSolver {
        LinearSolver::new(&self.pattern, Method::Lu, SolverOptions::default()).unwrap()
    }

    /// Component `c` of the committed mid-surface displacement at `uv`.
    pub fn displacement(&self, c: usize, uv: [f64; 2]) -> f64 {
        self.strip.field(|i| self.strip.model.particles[i].u[c], uv)
    }

    fn increment(&self, u: &[f64]) -> Result<Vec<f64>, ProblemError> {
        let du: Vec<f64> = u.iter().zip(&self.committed).map(|(a, b)| a - b).collect();
        self.strip.clamp.to_generalised(&du, C).map_err(fatal)
    }

    /// `f_ext(q)` at load factor 1 (dead plus loads).
    fn external(&self, q: &[f64]) -> Result<Vec<f64>, ProblemError> {
        let mut f = self.dead.clone();
        for l in &self.loads {
            l.add_force(&self.strip.model, q, 1.0, &mut f)
                .map_err(fatal)?;
        }
        Ok(f)
    }

    /// `Λ⁻ᵀ K Λ⁻¹` from the clamped rows `T_J = Λ⁻¹[J, :]`: with `P` the identity on the free
    /// DOFs, `Λ⁻¹ = P + T_J` (rows `J`), so `K Λ⁻¹ = K P + K[:, J] T_J` and
    /// `Λ⁻ᵀ W = P W + T_Jᵀ W[J, :]`.
    pub fn transform(&self, k: &DMatrix<f64>) -> DMatrix<f64> {
        let n = k.nrows();
        let m = self.fixed.len();
        let kj = DMatrix::from_fn(n, m, |i, a| k[(i, self.fixed[a])]);
        let mut w = k.clone();
        for &j in &self.fixed {
            w.column_mut(j).fill(0.0);
        }
        w += &kj * &self.t_rows;
        let wj = DMatrix::from_fn(m, n, |a, j| w[(self.fixed[a], j)]);
        for &j in &self.fixed {
            w.row_mut(j).fill(0.0);
        }
        w += self.t_rows.transpose() * wj;
        w
    }

    fn evaluate(
        &mut self,
        u: &[f64],
        load: f64,
        r: &mut [f64],
        values: Option<&mut [f64]>,
    ) -> Result<(), ProblemError> {
        self.evaluations += 1;
        let q = self.increment(u)?;
        let model = &self.strip.model;
        let c = model
            .contributions(&q, values.is_some())
            .map_err(|e| ProblemError::Recoverable(e.to_string()))?;
        let f_ext = self.external(&q)?;
        let f_int = model.internal_force(&c);
        let g: Vec<f64> = f_int
            .iter()
            .zip(&f_ext)
            .map(|(a, b)| a - load * b)
            .collect();
        r.copy_from_slice(&self.strip.clamp.transform_vector(&g, C).map_err(fatal)?);
        // Size of the summed terms: Σ_points |r_point| + |λ f_ext|, carried through |Λ⁻ᵀ|.
        let mut s: Vec<f64> = f_ext.iter().map(|v| (load * v).abs()).collect();
        for lc in &c {
            for (&i, v) in lc.dofs.iter().zip(&lc.residual) {
                s[i] += v.abs();
            }
        }
        let sj: Vec<f64> = self.fixed.iter().map(|&j| s[j]).collect();
        for &j in &self.fixed {
            s[j] = 0.0;
        }
        for (a, row) in self.t_rows.row_iter().enumerate() {
            for (si, t) in s.iter_mut().zip(row.iter()) {
                *si += t.abs() * sj[a];
            }
        }
        self.scale = s.iter().map(|v| v * v).sum::<f64>().sqrt();
        if let Some(values) = values {
            let mut k = model.dense_tangent(&c);
            let mut trip = Vec::new();
            for l in self.loads.iter().filter(|l| l.is_follower()) {
                l.add_stiffness(model, &q, load, &mut trip).map_err(fatal)?;
            }
            for (i, j, v) in trip {
                k[(i, j)] -= v;
            }
            let kt = self.transform(&k);
            let n = kt.nrows();
            for (slot, &v) in self.pattern.cell_slots(0).iter().zip(kt.as_slice()) {
                values[*slot as usize] = v;
            }
            debug_assert_eq!(self.pattern.cell_slots(0).len(), n * n);
        }
        self.cache = Some((u.to_vec(), c));
        Ok(())
    }
}

impl NonlinearProblem for StripProblem {
    fn n_dofs(&self) -> usize {
        self.strip.model.n_dofs()
    }
    fn residual(&mut self, u: &[f64], load: f64, r: &mut [f64]) -> Result<(), ProblemError> {
        self.evaluate(u, load, r, None)
    }
    fn tangent(&mut self, u: &[f64], load: f64, values: &mut [f64]) -> Result<(), ProblemError> {
        let mut r = vec![0.0; self.n_dofs()];
        self.evaluate(u, load, &mut r, Some(values))
    }
    fn residual_and_tangent(
        &mut self,
        u: &[f64],
        load: f64,
        r: &mut [f64],
        values: &mut [f64],
    ) -> Result<(), ProblemError> {
        self.evaluate(u, load, r, Some(values))
    }
    fn essential(&self, _load: f64) -> Vec<(usize, f64)> {
        self.fixed
            .iter()
            .chain(&self.restrained)
            .map(|&d| (d, 0.0))
            .collect()
    }
    fn force_norm(&self, load: f64) -> f64 {
        let q = vec![0.0; self.n_dofs()];
        let f = self
            .external(&q)
            .expect("loads evaluate at the committed state");
        let mut ft = self.strip.clamp.transform_vector(&f, C).unwrap();
        for &d in self.fixed.iter().chain(&self.restrained) {
            ft[d] = 0.0;
        }
        load.abs() * ft.iter().map(|v| v * v).sum::<f64>().sqrt()
    }
    fn residual_scale(&self) -> f64 {
        self.scale
    }
    fn commit(&mut self, u: &[f64], _load: f64) {
        let q = self.increment(u).expect("a state the driver evaluated");
        let c = match self.cache.take() {
            Some((uc, c)) if uc == u => c,
            _ => self.strip.model.contributions(&q, false).unwrap(),
        };
        self.strip.model.commit(&q, c);
        self.committed = u.to_vec();
    }
    fn restore(&mut self) {
        self.cache = None;
    }
}
