//! Essential (Dirichlet) conditions by elimination, keeping the sparsity pattern unchanged.

use super::{check_len, SolverError, SparsityPattern};

const FREE: usize = usize::MAX;

/// A set of constrained DOFs with prescribed values.
///
/// [`EssentialBc::apply`] turns `K u = f` into an equivalent system with the same pattern:
/// the prescribed values' column contributions move to the right-hand side
/// (`f_i ← f_i − K_ic g_c` for free `i`), rows and columns of constrained DOFs are zeroed, their
/// diagonal set to one and their right-hand side to `g_c`. The matrix stays symmetric if it was,
/// so Cholesky remains applicable, and the symbolic factorisation stays valid.
#[derive(Debug, Clone, PartialEq)]
pub struct EssentialBc {
    n: usize,
    dofs: Vec<usize>,
    values: Vec<f64>,
    index: Vec<usize>,
}

impl EssentialBc {
    /// No constraints on `n_dofs` unknowns.
    pub fn none(n_dofs: usize) -> Self {
        Self {
            n: n_dofs,
            dofs: Vec::new(),
            values: Vec::new(),
            index: vec![FREE; n_dofs],
        }
    }

    /// Constraints `u[dof] = value`. A DOF listed twice must have the same value both times.
    pub fn new(n_dofs: usize, prescribed: &[(usize, f64)]) -> Result<Self, SolverError> {
        let mut list = prescribed.to_vec();
        list.sort_by_key(|p| p.0);
        let mut bc = Self::none(n_dofs);
        for (dof, value) in list {
            if dof >= n_dofs {
                return Err(SolverError::Constraint(format!(
                    "DOF {dof} out of range (n_dofs = {n_dofs})"
                )));
            }
            if !value.is_finite() {
                return Err(SolverError::Constraint(format!(
                    "DOF {dof}: prescribed value {value} is not finite"
                )));
            }
            if let Some(&last) = bc.dofs.last() {
                if last == dof {
                    let prev = *bc.values.last().expect("same length");
                    if prev != value {
                        return Err(SolverError::Constraint(format!(
                            "DOF {dof} prescribed twice with different values {prev} and {value}"
                        )));
                    }
                    continue;
                }
            }
            bc.index[dof] = bc.dofs.len();
            bc.dofs.push(dof);
            bc.values.push(value);
        }
        Ok(bc)
    }

    /// Constrained DOFs, ascending.
    pub fn dofs(&self) -> &[usize] {
        &self.dofs
    }

    /// Prescribed values, aligned with [`EssentialBc::dofs`].
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// Number of DOFs of the system.
    pub fn n_dofs(&self) -> usize {
        self.n
    }

    /// Whether `dof` is constrained.
    pub fn is_constrained(&self, dof: usize) -> bool {
        self.index[dof] != FREE
    }

    /// Eliminate with the stored prescribed values.
    pub fn apply(
        &self,
        pattern: &SparsityPattern,
        values: &mut [f64],
        rhs: &mut [f64],
    ) -> Result<(), SolverError> {
        self.apply_with(pattern, values, rhs, &self.values)
    }

    /// The increments `g − u_c` that take the unknowns `u` to the prescribed values, aligned
    /// with [`EssentialBc::dofs`], written into `g` (its contents replaced): what
    /// [`EssentialBc::apply_with`] eliminates at a Newton iterate `u`.
    pub fn increments_into(&self, u: &[f64], g: &mut Vec<f64>) {
        g.clear();
        g.extend(self.dofs.iter().zip(&self.values).map(|(&d, &v)| v - u[d]));
    }

    /// Eliminate with other prescribed values `g` (aligned with [`EssentialBc::dofs`]), e.g. the
    /// increments `g − u_c` of a Newton iteration, or zeros for a homogeneous system.
    pub fn apply_with(
        &self,
        pattern: &SparsityPattern,
        values: &mut [f64],
        rhs: &mut [f64],
        g: &[f64],
    ) -> Result<(), SolverError> {
        check_len("essential: pattern n_dofs", pattern.n_dofs(), self.n)?;
        check_len("essential: values", values.len(), pattern.nnz())?;
        check_len("essential: rhs", rhs.len(), self.n)?;
        check_len("essential: prescribed", g.len(), self.dofs.len())?;
        let (cp, ri) = (pattern.col_ptr(), pattern.row_idx());
        for j in 0..self.n {
            let cj = self.index[j];
            for p in cp[j]..cp[j + 1] {
                let i = ri[p];
                let ci = self.index[i];
                if cj != FREE && ci == FREE {
                    rhs[i] -= values[p] * g[cj];
                }
                if cj != FREE || ci != FREE {
                    values[p] = if i == j { 1.0 } else { 0.0 };
                }
            }
        }
        for (&d, &v) in self.dofs.iter().zip(g) {
            rhs[d] = v;
        }
        Ok(())
    }

    /// Set the constrained entries of a vector to zero (homogeneous right-hand sides, e.g. the
    /// design sensitivity loads, or residual norms over free DOFs).
    pub fn zero_constrained(&self, v: &mut [f64]) {
        for &d in &self.dofs {
            v[d] = 0.0;
        }
    }
}
