//! The shell as a [`NonlinearProblem`] for the Newton driver: essential conditions through the
//! transformation method, the transformed tangent `K̃ = Λ⁻ᵀ K Λ⁻¹` in a sparse pattern built once,
//! committed and trial state.
//!
//! Unknowns of the driver are the transformed (nodal) values `ũ = Λ d`, 5 per particle; the
//! constrained particles' nodal values can be prescribed component by component. Within a step
//! the model's increment is `d = Λ⁻¹ (ũ − ũ_committed)`.

use super::model::{LocalContribution, ShellModel};
use super::point::DOFS_PER_PARTICLE;
use super::ShellError;
use crate::meshfree::transform::{CsrMatrix, Transformation};
use crate::solver::{NonlinearProblem, ProblemError, SolverError, SparsityPattern};

/// The shell problem.
#[derive(Debug)]
pub struct ShellProblem {
    /// The discrete shell (committed state).
    pub model: ShellModel,
    transform: Transformation,
    /// External load at load factor 1, on the generalised DOFs.
    pub load: Vec<f64>,
    fixed: Vec<(usize, f64)>,
    pattern: SparsityPattern,
    committed: Vec<f64>,
    cache: Option<(Vec<f64>, Vec<LocalContribution>)>,
}

fn fatal<E: std::fmt::Display>(e: E) -> ProblemError {
    ProblemError::Fatal(e.to_string())
}

impl ShellProblem {
    /// `constrained`: particles whose nodal values are the unknowns of the transformation;
    /// `fixed`: `(particle, component)` nodal values held at zero (each particle must be in
    /// `constrained`); `load`: the external load vector at load factor 1.
    pub fn new(
        model: ShellModel,
        constrained: &[usize],
        fixed: &[(usize, usize)],
        load: Vec<f64>,
    ) -> Result<Self, ShellError> {
        let n = model.n_dofs();
        if load.len() != n {
            return Err(ShellError::Dimension {
                expected: n,
                got: load.len(),
            });
        }
        for &(p, c) in fixed {
            if !constrained.contains(&p) || c >= DOFS_PER_PARTICLE {
                return Err(ShellError::InvalidInput(format!(
                    "fixed nodal value (particle {p}, component {c}): expected a constrained particle and a component < 5"
                )));
            }
        }
        let transform = Transformation::new(&model.shape_functions, constrained)
            .map_err(|e| ShellError::InvalidInput(e.to_string()))?;
        // Structural pattern of K̃ from a structurally full K (every coupled pair = 1).
        let ones: Vec<(usize, usize, f64)> = model
            .points
            .iter()
            .flat_map(|p| {
                let dofs: Vec<usize> = p
                    .neighbours
                    .iter()
                    .flat_map(|&i| (0..5).map(move |c| 5 * i + c))
                    .collect();
                dofs.iter()
                    .flat_map(|&a| dofs.iter().map(move |&b| (a, b, 1.0)))
                    .collect::<Vec<_>>()
            })
            .collect();
        let kt = transform
            .transform_matrix(&CsrMatrix::from_triplets(n, n, &ones), DOFS_PER_PARTICLE)
            .map_err(|e| ShellError::InvalidInput(e.to_string()))?;
        let entries: Vec<(usize, usize)> = (0..n)
            .flat_map(|i| kt.row(i).map(move |(j, _)| (i, j)).collect::<Vec<_>>())
            .collect();
        let pattern = SparsityPattern::from_entries(n, &entries)
            .map_err(|e| ShellError::InvalidInput(e.to_string()))?;
        let fixed = fixed
            .iter()
            .map(|&(p, c)| (DOFS_PER_PARTICLE * p + c, 0.0))
            .collect();
        Ok(ShellProblem {
            model,
            transform,
            load,
            fixed,
            pattern,
            committed: vec![0.0; n],
            cache: None,
        })
    }

    /// The sparse pattern of the transformed tangent (give it to the driver and its solver).
    pub fn pattern(&self) -> &SparsityPattern {
        &self.pattern
    }

    /// Generalised increment `Λ⁻¹ (ũ − ũ_committed)`.
    fn increment(&self, u: &[f64]) -> Result<Vec<f64>, ProblemError> {
        let du: Vec<f64> = u.iter().zip(&self.committed).map(|(a, b)| a - b).collect();
        self.transform
            .to_generalised(&du, DOFS_PER_PARTICLE)
            .map_err(fatal)
    }

    fn contributions(
        &mut self,
        u: &[f64],
        tangent: bool,
    ) -> Result<Vec<LocalContribution>, ProblemError> {
        let q = self.increment(u)?;
        // An inverted cell or a failed return map: a smaller step may succeed.
        self.model
            .contributions(&q, tangent)
            .map_err(|e| ProblemError::Recoverable(e.to_string()))
    }

    fn transformed_residual(
        &self,
        c: &[LocalContribution],
        load: f64,
        r: &mut [f64],
    ) -> Result<(), ProblemError> {
        let f = self.model.internal_force(c);
        let g: Vec<f64> = f
            .iter()
            .zip(&self.load)
            .map(|(a, b)| a - load * b)
            .collect();
        let rt = self
            .transform
            .transform_vector(&g, DOFS_PER_PARTICLE)
            .map_err(fatal)?;
        r.copy_from_slice(&rt);
        Ok(())
    }

    fn transformed_tangent(
        &self,
        c: &[LocalContribution],
        values: &mut [f64],
    ) -> Result<(), ProblemError> {
        let n = self.model.n_dofs();
        let mut trip = Vec::new();
        for lc in c {
            let k = lc
                .tangent
                .as_ref()
                .ok_or_else(|| fatal("tangent not computed"))?;
            for (b, &j) in lc.dofs.iter().enumerate() {
                for (a, &i) in lc.dofs.iter().enumerate() {
                    trip.push((i, j, k[(a, b)]));
                }
            }
        }
        let kt = self
            .transform
            .transform_matrix(&CsrMatrix::from_triplets(n, n, &trip), DOFS_PER_PARTICLE)
            .map_err(fatal)?;
        values.fill(0.0);
        for i in 0..n {
            for (j, v) in kt.row(i) {
                let slot = self.pattern.slot(i, j).ok_or_else(|| {
                    fatal(SolverError::DofOutOfRange {
                        cell: 0,
                        local: i,
                        dof: j,
                        n_dofs: n,
                    })
                })?;
                values[slot] += v;
            }
        }
        Ok(())
    }
}

impl NonlinearProblem for ShellProblem {
    fn n_dofs(&self) -> usize {
        self.model.n_dofs()
    }
    fn residual(&mut self, u: &[f64], load: f64, r: &mut [f64]) -> Result<(), ProblemError> {
        let c = self.contributions(u, false)?;
        self.transformed_residual(&c, load, r)?;
        self.cache = Some((u.to_vec(), c));
        Ok(())
    }
    fn tangent(&mut self, u: &[f64], _load: f64, values: &mut [f64]) -> Result<(), ProblemError> {
        let c = self.contributions(u, true)?;
        self.transformed_tangent(&c, values)
    }
    fn residual_and_tangent(
        &mut self,
        u: &[f64],
        load: f64,
        r: &mut [f64],
        values: &mut [f64],
    ) -> Result<(), ProblemError> {
        let c = self.contributions(u, true)?;
        self.transformed_residual(&c, load, r)?;
        self.transformed_tangent(&c, values)?;
        self.cache = Some((u.to_vec(), c));
        Ok(())
    }
    fn essential(&self, _load: f64) -> Vec<(usize, f64)> {
        self.fixed.clone()
    }
    fn force_norm(&self, load: f64) -> f64 {
        load.abs() * self.load.iter().map(|v| v * v).sum::<f64>().sqrt()
    }
    fn commit(&mut self, u: &[f64], _load: f64) {
        let q = match self.increment(u) {
            Ok(q) => q,
            Err(_) => return, // unreachable for a state the driver evaluated
        };
        let c = match self.cache.take() {
            Some((uc, c)) if uc == u => c,
            _ => match self.model.contributions(&q, false) {
                Ok(c) => c,
                Err(_) => return,
            },
        };
        self.model.commit(&q, c);
        self.committed = u.to_vec();
    }
    fn restore(&mut self) {
        self.cache = None;
    }
}
