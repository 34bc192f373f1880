//! Essential boundary conditions with non-interpolating RK shape functions: the (mixed)
//! transformation method.
//!
//! RK shape functions do not interpolate, `Ψ_I(ξ_J) ≠ δ_IJ`, so the generalised coefficients `d_I`
//! are not the field values at the particles. For a chosen set `J` of *constrained* particles
//! (e.g. those on an edge with an essential condition) the unknowns are replaced by the nodal
//! values `ũ_J = Σ_I Ψ_I(ξ_J) d_I`; every other particle keeps its generalised coefficient. With
//! the particles of `J` and the unconstrained ones `U`,
//!
//! ```text
//! ũ = Λ d,   Λ = ⎡ I     0    ⎤  (rows U)          Λ⁻¹ = ⎡ I              0      ⎤
//!                ⎣ Λ_JU  Λ_JJ ⎦  (rows J),               ⎣ −Λ_JJ⁻¹ Λ_JU   Λ_JJ⁻¹ ⎦
//! ```
//!
//! with `(Λ_J·)_I = Ψ_I(ξ_J)`. For a field with `k` components per particle the transformation is
//! `Λ ⊗ I_k` with the particle-major layout `dof = k · I + c` (the same `Λ` for every component).
//!
//! **Operations.**
//! - [`Transformation::to_nodal`]: `ũ = Λ d` (a sparse product on the `J` rows, identity elsewhere).
//! - [`Transformation::to_generalised`]: solve `Λ d = ũ`: `d_U = ũ_U`, then
//!   `Λ_JJ d_J = ũ_J − Λ_JU d_U` (one LU solve with the small constrained block).
//! - [`Transformation::transform_vector`]: `f̃ = Λ⁻ᵀ f`: `y = Λ_JJ⁻ᵀ f_J` (a transposed LU solve),
//!   `f̃_J = y`, `f̃_U = f_U − Λ_JUᵀ y`.
//! - [`Transformation::transform_matrix`]: `K̃ = Λ⁻ᵀ K Λ⁻¹` for a sparse [`CsrMatrix`]. `Λ⁻¹` is
//!   never formed as an `n × n` matrix: it is the identity except for its `|J|` constrained rows
//!   `T_J· = [−Λ_JJ⁻¹ Λ_JU, Λ_JJ⁻¹]`, which are nonzero only in the columns of `J` and of the
//!   unconstrained particles coupled to `J` (those whose supports cover a constrained particle).
//!   These rows are computed once (`|J|` LU solves). Then `W = K T` and `K̃ = Tᵀ W` are two sparse
//!   products with a sparse accumulator: row `r` of `W` is `K_r·` with every entry in a constrained
//!   column replaced by that entry times the corresponding row of `T`; row `i` of `K̃` is
//!   `[i ∈ U] W_i· + Σ_{a ∈ J} T_{a i} W_a·`, whose second term is nonzero only for `i` in
//!   `S = J ∪ near(J)` and is computed per component as one dense product
//!   `T_{J S}ᵀ W_{J ·}` (a GEMM of size `|S| × |J| × (columns of the J rows of W)`). The fill is
//!   confined to the `S` block and the cost is dominated by that product, `O(|S| |J| |S| k)`.
//!   `Λ_JJ⁻¹` is dense but its entries decay quickly away from the diagonal; a relative drop
//!   tolerance ([`Transformation::with_drop_tolerance`], default 0 = exact) can keep the fill
//!   small on large problems.
//! - [`Transformation::transform_matrix_dense`]: the dense reference (forms `Λ` and its inverse;
//!   small problems and tests only).
//!
//! After solving `K̃ ũ = f̃` with the essential values prescribed on the constrained entries of `ũ`,
//! the generalised coefficients are `d = Λ⁻¹ ũ` ([`Transformation::to_generalised`]).
//!
//! Note: the test functions `δu = Σ_I Ψ_I δd_I` with `δũ_J = 0` vanish *at* the constrained
//! particles, not along the edge between them, so the essential condition is imposed at the
//! particles (collocation), not on the whole edge.

// Dense LU and sparse-accumulator kernels read most clearly with index loops.
#![allow(clippy::needless_range_loop)]

use super::particles::ParamBox;
use super::shape::{ShapeFunctions, ShapeValues};
use super::MeshfreeError;
use nalgebra::DMatrix;

/// Relative pivot below which the constrained block `Λ_JJ` is declared singular: a pivot of the
/// partially pivoted LU smaller than this times the largest entry of `Λ_JJ`.
pub const SINGULAR_PIVOT_TOLERANCE: f64 = 1e-12;

const NOT_CONSTRAINED: usize = usize::MAX;

/// Errors of the transformation method.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TransformError {
    /// The shape-function rows of the constrained particles are linearly dependent.
    #[error(
        "transformation block Λ_JJ is singular (relative pivot {pivot:.3e}): the shape-function \
         rows of constrained particle(s) {dependent:?} are linear combinations of those of \
         constrained particle(s) {involved:?}; remove duplicate or coincident constrained particles"
    )]
    Singular {
        /// Constrained particles whose rows depend on earlier ones (particle indices).
        dependent: Vec<usize>,
        /// Constrained particles appearing in those dependencies (particle indices).
        involved: Vec<usize>,
        /// Smallest relative LU pivot.
        pivot: f64,
    },
    /// Shape functions could not be evaluated at a constrained particle.
    #[error("shape functions at constrained particle {particle}: {source}")]
    Shape {
        /// Particle index.
        particle: usize,
        /// The meshfree error.
        source: MeshfreeError,
    },
    /// A vector or matrix has the wrong size.
    #[error("{what}: expected size {expected}, got {got}")]
    DimensionMismatch {
        /// Which argument.
        what: &'static str,
        /// Expected size.
        expected: usize,
        /// Actual size.
        got: usize,
    },
    /// Invalid input (indices out of range, duplicates, zero components, …).
    #[error("invalid transformation input: {0}")]
    InvalidInput(String),
}

/// A parametric edge of a box.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Edge {
    /// `u = u_min`.
    UMin,
    /// `u = u_max`.
    UMax,
    /// `v = v_min`.
    VMin,
    /// `v = v_max`.
    VMax,
}

impl Edge {
    /// All four edges.
    pub const ALL: [Edge; 4] = [Edge::UMin, Edge::UMax, Edge::VMin, Edge::VMax];
}

/// Indices (ascending) of the particles lying on `edge` of `b`, within the absolute tolerance
/// `tol` of the edge coordinate.
pub fn edge_particles(positions: &[[f64; 2]], b: &ParamBox, edge: Edge, tol: f64) -> Vec<usize> {
    let (k, target) = match edge {
        Edge::UMin => (0, b.lo[0]),
        Edge::UMax => (0, b.hi[0]),
        Edge::VMin => (1, b.lo[1]),
        Edge::VMax => (1, b.hi[1]),
    };
    positions
        .iter()
        .enumerate()
        .filter(|(_, p)| (p[k] - target).abs() <= tol)
        .map(|(i, _)| i)
        .collect()
}

/// Indices (ascending, each once) of the particles on any of the given edges.
pub fn particles_on_edges(
    positions: &[[f64; 2]],
    b: &ParamBox,
    edges: &[Edge],
    tol: f64,
) -> Vec<usize> {
    let mut out: Vec<usize> = edges
        .iter()
        .flat_map(|&e| edge_particles(positions, b, e, tol))
        .collect();
    out.sort_unstable();
    out.dedup();
    out
}

/// A compressed-row sparse matrix (columns ascending within a row, no duplicates).
#[derive(Clone, Debug, PartialEq)]
pub struct CsrMatrix {
    /// Rows.
    pub nrows: usize,
    /// Columns.
    pub ncols: usize,
    /// Row `i` occupies `row_ptr[i]..row_ptr[i + 1]`.
    pub row_ptr: Vec<usize>,
    /// Column indices.
    pub col_idx: Vec<usize>,
    /// Values.
    pub values: Vec<f64>,
}

impl CsrMatrix {
    /// From `(row, col, value)` triplets; duplicates are summed.
    ///
    /// # Panics
    /// If an index is out of range.
    pub fn from_triplets(nrows: usize, ncols: usize, triplets: &[(usize, usize, f64)]) -> Self {
        let mut rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); nrows];
        for &(i, j, v) in triplets {
            assert!(
                i < nrows && j < ncols,
                "triplet ({i}, {j}) out of range {nrows} × {ncols}"
            );
            rows[i].push((j, v));
        }
        let mut row_ptr = Vec::with_capacity(nrows + 1);
        let mut col_idx = Vec::new();
        let mut values = Vec::new();
        row_ptr.push(0);
        for mut r in rows {
            r.sort_unstable_by_key(|e| e.0);
            for (j, v) in r {
                if col_idx.len() > *row_ptr.last().expect("non-empty") && col_idx.last() == Some(&j)
                {
                    *values.last_mut().expect("non-empty") += v;
                } else {
                    col_idx.push(j);
                    values.push(v);
                }
            }
            row_ptr.push(col_idx.len());
        }
        CsrMatrix {
            nrows,
            ncols,
            row_ptr,
            col_idx,
            values,
        }
    }
    /// From a dense matrix (exact zeros skipped).
    pub fn from_dense(m: &DMatrix<f64>) -> Self {
        let mut t = Vec::new();
        for i in 0..m.nrows() {
            for j in 0..m.ncols() {
                if m[(i, j)] != 0.0 {
                    t.push((i, j, m[(i, j)]));
                }
            }
        }
        Self::from_triplets(m.nrows(), m.ncols(), &t)
    }
    /// Stored entries.
    pub fn nnz(&self) -> usize {
        self.values.len()
    }
    /// `(column, value)` of row `i`.
    pub fn row(&self, i: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let r = self.row_ptr[i]..self.row_ptr[i + 1];
        self.col_idx[r.clone()]
            .iter()
            .copied()
            .zip(self.values[r].iter().copied())
    }
    /// Entry `(i, j)` (0 when not stored).
    pub fn get(&self, i: usize, j: usize) -> f64 {
        let r = self.row_ptr[i]..self.row_ptr[i + 1];
        match self.col_idx[r.clone()].binary_search(&j) {
            Ok(p) => self.values[r.start + p],
            Err(_) => 0.0,
        }
    }
    /// Dense copy.
    pub fn to_dense(&self) -> DMatrix<f64> {
        let mut m = DMatrix::zeros(self.nrows, self.ncols);
        for i in 0..self.nrows {
            for (j, v) in self.row(i) {
                m[(i, j)] += v;
            }
        }
        m
    }
    /// `A x`.
    ///
    /// # Panics
    /// If `x.len() != ncols`.
    pub fn mul_vec(&self, x: &[f64]) -> Vec<f64> {
        assert_eq!(x.len(), self.ncols, "CsrMatrix::mul_vec: length");
        (0..self.nrows)
            .map(|i| self.row(i).map(|(j, v)| v * x[j]).sum())
            .collect()
    }
}

/// Sparse accumulator: a dense scratch row with a list of touched columns.
struct Accumulator {
    vals: Vec<f64>,
    used: Vec<bool>,
    touched: Vec<usize>,
}

impl Accumulator {
    fn new(n: usize) -> Self {
        Accumulator {
            vals: vec![0.0; n],
            used: vec![false; n],
            touched: Vec::new(),
        }
    }
    #[inline]
    fn add(&mut self, j: usize, v: f64) {
        if !self.used[j] {
            self.used[j] = true;
            self.touched.push(j);
        }
        self.vals[j] += v;
    }
    /// Append the row (columns ascending) to CSR arrays and reset.
    fn flush(&mut self, col_idx: &mut Vec<usize>, values: &mut Vec<f64>) {
        self.touched.sort_unstable();
        for &j in &self.touched {
            col_idx.push(j);
            values.push(self.vals[j]);
            self.vals[j] = 0.0;
            self.used[j] = false;
        }
        self.touched.clear();
    }
}

/// Dense LU with partial pivoting of the constrained block (row-major).
#[derive(Clone, Debug)]
struct DenseLu {
    m: usize,
    lu: Vec<f64>,
    perm: Vec<usize>,
}

impl DenseLu {
    /// Factor `a` (row-major `m × m`). Returns the factor and the smallest pivot relative to the
    /// largest entry of `a`.
    fn new(mut a: Vec<f64>, m: usize) -> (Self, f64) {
        let amax = a.iter().fold(0.0_f64, |s, v| s.max(v.abs()));
        let mut perm: Vec<usize> = (0..m).collect();
        let mut min_piv = f64::INFINITY;
        for k in 0..m {
            let mut p = k;
            for i in k + 1..m {
                if a[i * m + k].abs() > a[p * m + k].abs() {
                    p = i;
                }
            }
            if p != k {
                for j in 0..m {
                    a.swap(k * m + j, p * m + j);
                }
                perm.swap(k, p);
            }
            let piv = a[k * m + k];
            min_piv = min_piv.min(piv.abs());
            if piv == 0.0 {
                continue;
            }
            for i in k + 1..m {
                let l = a[i * m + k] / piv;
                a[i * m + k] = l;
                if l != 0.0 {
                    for j in k + 1..m {
                        a[i * m + j] -= l * a[k * m + j];
                    }
                }
            }
        }
        let rel = if m == 0 {
            1.0
        } else if amax > 0.0 {
            min_piv / amax
        } else {
            0.0
        };
        (DenseLu { m, lu: a, perm }, rel)
    }
    /// Solve `A x = b` in place.
    fn solve(&self, b: &mut [f64]) {
        let m = self.m;
        let mut y: Vec<f64> = self.perm.iter().map(|&p| b[p]).collect();
        for i in 0..m {
            let mut s = y[i];
            for k in 0..i {
                s -= self.lu[i * m + k] * y[k];
            }
            y[i] = s;
        }
        for i in (0..m).rev() {
            let mut s = y[i];
            for k in i + 1..m {
                s -= self.lu[i * m + k] * y[k];
            }
            y[i] = s / self.lu[i * m + i];
        }
        b.copy_from_slice(&y);
    }
    /// Solve `Aᵀ x = b` in place (`Aᵀ = Uᵀ Lᵀ P`).
    fn solve_transpose(&self, b: &mut [f64]) {
        let m = self.m;
        let mut z = b.to_vec();
        for i in 0..m {
            let mut s = z[i];
            for k in 0..i {
                s -= self.lu[k * m + i] * z[k];
            }
            z[i] = s / self.lu[i * m + i];
        }
        for i in (0..m).rev() {
            let mut s = z[i];
            for k in i + 1..m {
                s -= self.lu[k * m + i] * z[k];
            }
            z[i] = s;
        }
        for (i, &p) in self.perm.iter().enumerate() {
            b[p] = z[i];
        }
    }
}

/// Which constrained rows of the dense block `a` (row-major `m × m`) are linear combinations of
/// earlier ones (modified Gram–Schmidt, twice, row by row), and which rows enter those
/// combinations. Returns positions in `0..m`.
fn dependent_rows(a: &[f64], m: usize, tol: f64) -> (Vec<usize>, Vec<usize>) {
    let mut q: Vec<Vec<f64>> = Vec::new(); // orthonormal rows
    let mut r: Vec<Vec<f64>> = Vec::new(); // r[t][j]: coefficient of q_j in independent row t
    let mut indep: Vec<usize> = Vec::new();
    let mut dependent = Vec::new();
    let mut involved = Vec::new();
    for i in 0..m {
        let row = &a[i * m..(i + 1) * m];
        let norm0 = row.iter().map(|v| v * v).sum::<f64>().sqrt();
        let mut v = row.to_vec();
        let mut coef = vec![0.0; q.len()];
        for _pass in 0..2 {
            for (j, qj) in q.iter().enumerate() {
                let s: f64 = v.iter().zip(qj).map(|(x, y)| x * y).sum();
                coef[j] += s;
                for (x, y) in v.iter_mut().zip(qj) {
                    *x -= s * y;
                }
            }
        }
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm <= tol * norm0.max(f64::MIN_POSITIVE) {
            dependent.push(i);
            // row_i ≈ Σ_j coef_j q_j and row_{indep[t]} = Σ_{j ≤ t} r[t][j] q_j: solve Rᵀ c = coef
            // (lower triangular in t) for the coefficients c_t on the independent rows.
            let s = q.len();
            let mut c = vec![0.0; s];
            for t in (0..s).rev() {
                let mut x = coef[t];
                for u in t + 1..s {
                    x -= r[u][t] * c[u];
                }
                c[t] = x / r[t][t];
            }
            let cmax = c.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
            for (t, &ct) in c.iter().enumerate() {
                if ct.abs() > 1e-8 * cmax {
                    involved.push(indep[t]);
                }
            }
        } else {
            for x in v.iter_mut() {
                *x /= norm;
            }
            coef.push(norm);
            q.push(v);
            r.push(coef);
            indep.push(i);
        }
    }
    involved.sort_unstable();
    involved.dedup();
    (dependent, involved)
}

/// The transformation `ũ = Λ d` for a set of constrained particles of an RK discretisation.
#[derive(Clone, Debug)]
pub struct Transformation {
    n_particles: usize,
    /// Constrained particles `J`, ascending.
    constrained: Vec<usize>,
    /// Position in `constrained` of each particle, or `NOT_CONSTRAINED`.
    slot: Vec<usize>,
    /// `(I, Ψ_I(ξ_J))` for each constrained `J` (the constrained rows of `Λ`).
    rows: Vec<Vec<(usize, f64)>>,
    lu: DenseLu,
    /// Constrained rows of `Λ⁻¹`: `(I, T_{J I})`.
    inv_rows: Vec<Vec<(usize, f64)>>,
    /// For each particle `I`: `(a, T_{J_a I})` (the columns of the constrained rows of `Λ⁻¹`).
    inv_cols: Vec<Vec<(usize, f64)>>,
    /// Largest `|T_{J I}|`.
    inv_max: f64,
    drop_tolerance: f64,
}

impl Transformation {
    /// Build `Λ` for the particles `constrained` (indices into `shape.particles()`, any order,
    /// no duplicates) of the RK shape functions `shape`: evaluates `Ψ_I(ξ_J)` at every constrained
    /// particle, factors `Λ_JJ` (dense LU, partial pivoting) and forms the constrained rows of
    /// `Λ⁻¹` (`|J|` solves).
    ///
    /// Errors: an index out of range or repeated ([`TransformError::InvalidInput`]); a shape
    /// function evaluation failure ([`TransformError::Shape`]); linearly dependent constrained
    /// rows ([`TransformError::Singular`], naming the particles).
    pub fn new(shape: &ShapeFunctions, constrained: &[usize]) -> Result<Self, TransformError> {
        let n = shape.len();
        let mut js = constrained.to_vec();
        js.sort_unstable();
        if let Some(&bad) = js.iter().find(|&&j| j >= n) {
            return Err(TransformError::InvalidInput(format!(
                "constrained particle {bad} out of range ({n} particles)"
            )));
        }
        if let Some(w) = js.windows(2).find(|w| w[0] == w[1]) {
            return Err(TransformError::InvalidInput(format!(
                "constrained particle {} listed more than once",
                w[0]
            )));
        }
        let m = js.len();
        let mut slot = vec![NOT_CONSTRAINED; n];
        for (a, &j) in js.iter().enumerate() {
            slot[j] = a;
        }
        let mut sv = ShapeValues::new();
        let mut rows = Vec::with_capacity(m);
        for &j in &js {
            shape
                .evaluate(shape.particles()[j], &mut sv)
                .map_err(|source| TransformError::Shape {
                    particle: j,
                    source,
                })?;
            rows.push(
                sv.neighbours()
                    .iter()
                    .copied()
                    .zip(sv.values().iter().copied())
                    .collect::<Vec<_>>(),
            );
        }
        let mut block = vec![0.0; m * m];
        for (a, row) in rows.iter().enumerate() {
            for &(i, v) in row {
                if slot[i] != NOT_CONSTRAINED {
                    block[a * m + slot[i]] = v;
                }
            }
        }
        let (lu, pivot) = DenseLu::new(block.clone(), m);
        if pivot.is_nan() || pivot <= SINGULAR_PIVOT_TOLERANCE {
            let (dep, inv) = dependent_rows(&block, m, 1e-8);
            let (dependent, involved) = if dep.is_empty() {
                // Gram–Schmidt did not single out a row: name the row of the smallest pivot.
                let mut k = 0;
                let mut best = f64::INFINITY;
                for i in 0..m {
                    let p = lu.lu[i * m + i].abs();
                    if p < best {
                        best = p;
                        k = i;
                    }
                }
                (vec![js[lu.perm[k]]], Vec::new())
            } else {
                (
                    dep.iter().map(|&a| js[a]).collect(),
                    inv.iter().map(|&a| js[a]).collect(),
                )
            };
            return Err(TransformError::Singular {
                dependent,
                involved,
                pivot,
            });
        }
        // Constrained rows of Λ⁻¹: T_{J·} = [−G Λ_JU, G], G = Λ_JJ⁻¹ (column by column).
        let mut g = vec![0.0; m * m]; // row-major G
        let mut col = vec![0.0; m];
        for b in 0..m {
            col.iter_mut().for_each(|x| *x = 0.0);
            col[b] = 1.0;
            lu.solve(&mut col);
            for a in 0..m {
                g[a * m + b] = col[a];
            }
        }
        // Unconstrained particles coupled to J, numbered locally.
        let mut near_slot = vec![NOT_CONSTRAINED; n];
        let mut near: Vec<usize> = Vec::new();
        for row in &rows {
            for &(i, _) in row {
                if slot[i] == NOT_CONSTRAINED && near_slot[i] == NOT_CONSTRAINED {
                    near_slot[i] = near.len();
                    near.push(i);
                }
            }
        }
        let nn = near.len();
        let mut tu = vec![0.0; m * nn]; // row-major −G Λ_JU
        for (b, row) in rows.iter().enumerate() {
            for &(i, v) in row {
                let s = near_slot[i];
                if s != NOT_CONSTRAINED {
                    for a in 0..m {
                        tu[a * nn + s] -= g[a * m + b] * v;
                    }
                }
            }
        }
        let mut inv_rows = Vec::with_capacity(m);
        let mut inv_cols: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
        let mut inv_max = 0.0_f64;
        for a in 0..m {
            let mut r: Vec<(usize, f64)> = Vec::with_capacity(m + nn);
            for b in 0..m {
                r.push((js[b], g[a * m + b]));
            }
            for s in 0..nn {
                r.push((near[s], tu[a * nn + s]));
            }
            r.retain(|e| e.1 != 0.0);
            r.sort_unstable_by_key(|e| e.0);
            for &(i, v) in &r {
                inv_cols[i].push((a, v));
                inv_max = inv_max.max(v.abs());
            }
            inv_rows.push(r);
        }
        Ok(Transformation {
            n_particles: n,
            constrained: js,
            slot,
            rows,
            lu,
            inv_rows,
            inv_cols,
            inv_max,
            drop_tolerance: 0.0,
        })
    }

    /// Drop entries of the constrained rows of `Λ⁻¹` smaller than `tol` times the largest one in
    /// [`transform_matrix`](Self::transform_matrix) (default 0: exact). Vectors are always
    /// transformed exactly.
    pub fn with_drop_tolerance(mut self, tol: f64) -> Self {
        self.drop_tolerance = tol.max(0.0);
        self
    }

    /// Number of particles.
    pub fn n_particles(&self) -> usize {
        self.n_particles
    }
    /// Constrained particles, ascending.
    pub fn constrained(&self) -> &[usize] {
        &self.constrained
    }
    /// Whether particle `i` is constrained.
    pub fn is_constrained(&self, i: usize) -> bool {
        self.slot.get(i).is_some_and(|&s| s != NOT_CONSTRAINED)
    }
    /// DOF indices `k · J + c` of the constrained particles for `comps` components, ascending.
    pub fn constrained_dofs(&self, comps: usize) -> Vec<usize> {
        self.constrained
            .iter()
            .flat_map(|&j| (0..comps).map(move |c| comps * j + c))
            .collect()
    }
    /// Row of `Λ` for the `a`-th constrained particle: `(I, Ψ_I(ξ_J))`.
    pub fn lambda_row(&self, a: usize) -> &[(usize, f64)] {
        &self.rows[a]
    }
    /// Nonzeros in the constrained rows of `Λ⁻¹` (the fill the transformation introduces).
    pub fn inverse_row_nnz(&self) -> usize {
        self.inv_rows.iter().map(Vec::len).sum()
    }

    fn check(&self, len: usize, comps: usize, what: &'static str) -> Result<(), TransformError> {
        if comps == 0 {
            return Err(TransformError::InvalidInput(
                "number of components must be at least 1".into(),
            ));
        }
        let expected = self.n_particles * comps;
        if len != expected {
            return Err(TransformError::DimensionMismatch {
                what,
                expected,
                got: len,
            });
        }
        Ok(())
    }

    /// `ũ = Λ d` for `comps` components per particle (layout `comps · I + c`).
    pub fn to_nodal(&self, d: &[f64], comps: usize) -> Result<Vec<f64>, TransformError> {
        self.check(d.len(), comps, "generalised coefficients d")?;
        let mut u = d.to_vec();
        for (a, row) in self.rows.iter().enumerate() {
            let j = self.constrained[a];
            for c in 0..comps {
                u[comps * j + c] = row.iter().map(|&(i, v)| v * d[comps * i + c]).sum();
            }
        }
        Ok(u)
    }

    /// Solve `Λ d = ũ`: `d_U = ũ_U` (untouched), `Λ_JJ d_J = ũ_J − Λ_JU d_U`.
    pub fn to_generalised(&self, nodal: &[f64], comps: usize) -> Result<Vec<f64>, TransformError> {
        self.check(nodal.len(), comps, "nodal values ũ")?;
        let m = self.constrained.len();
        let mut d = nodal.to_vec();
        let mut rhs = vec![0.0; m];
        for c in 0..comps {
            for (a, row) in self.rows.iter().enumerate() {
                let j = self.constrained[a];
                let mut s = nodal[comps * j + c];
                for &(i, v) in row {
                    if self.slot[i] == NOT_CONSTRAINED {
                        s -= v * nodal[comps * i + c];
                    }
                }
                rhs[a] = s;
            }
            self.lu.solve(&mut rhs);
            for (a, &j) in self.constrained.iter().enumerate() {
                d[comps * j + c] = rhs[a];
            }
        }
        Ok(d)
    }

    /// `f̃ = Λ⁻ᵀ f`: `y = Λ_JJ⁻ᵀ f_J`, `f̃_J = y`, `f̃_U = f_U − Λ_JUᵀ y`.
    pub fn transform_vector(&self, f: &[f64], comps: usize) -> Result<Vec<f64>, TransformError> {
        self.check(f.len(), comps, "vector f")?;
        let m = self.constrained.len();
        let mut out = f.to_vec();
        let mut y = vec![0.0; m];
        for c in 0..comps {
            for (a, &j) in self.constrained.iter().enumerate() {
                y[a] = f[comps * j + c];
            }
            self.lu.solve_transpose(&mut y);
            for (a, row) in self.rows.iter().enumerate() {
                out[comps * self.constrained[a] + c] = y[a];
                for &(i, v) in row {
                    if self.slot[i] == NOT_CONSTRAINED {
                        out[comps * i + c] -= v * y[a];
                    }
                }
            }
        }
        Ok(out)
    }

    /// `K̃ = Λ⁻ᵀ K Λ⁻¹` for a square sparse `K` of size `comps · n_particles` (see the module
    /// documentation for the two sparse products).
    pub fn transform_matrix(
        &self,
        k: &CsrMatrix,
        comps: usize,
    ) -> Result<CsrMatrix, TransformError> {
        self.check(k.nrows, comps, "matrix K rows")?;
        self.check(k.ncols, comps, "matrix K columns")?;
        let nd = k.nrows;
        let cut = self.drop_tolerance * self.inv_max;
        let keep = |v: f64| v != 0.0 && v.abs() > cut;
        let mut acc = Accumulator::new(nd);
        // W = K T.
        let mut w_ptr = Vec::with_capacity(nd + 1);
        let mut w_idx = Vec::new();
        let mut w_val = Vec::new();
        w_ptr.push(0);
        for r in 0..nd {
            for (s, v) in k.row(r) {
                let (p, c) = (s / comps, s % comps);
                let a = self.slot[p];
                if a == NOT_CONSTRAINED {
                    acc.add(s, v);
                } else {
                    for &(q, t) in &self.inv_rows[a] {
                        if keep(t) {
                            acc.add(comps * q + c, v * t);
                        }
                    }
                }
            }
            acc.flush(&mut w_idx, &mut w_val);
            w_ptr.push(w_idx.len());
        }
        let w = CsrMatrix {
            nrows: nd,
            ncols: nd,
            row_ptr: w_ptr,
            col_idx: w_idx,
            values: w_val,
        };
        // K̃ = Tᵀ W: row (i, c) = [i ∈ U] W_(i,c) + Σ_a T_{J_a i} W_(J_a, c). The second term is
        // nonzero only for particles i in S = J ∪ near(J); per component it is the dense product
        // P_c = T_S (|S| × |J|) · W_{J,c} (|J| × |columns of the J rows of W|), done with a GEMM.
        let m = self.constrained.len();
        let s_list: Vec<usize> = (0..self.n_particles)
            .filter(|&i| self.inv_cols[i].iter().any(|&(_, t)| keep(t)))
            .collect();
        let mut s_slot = vec![NOT_CONSTRAINED; self.n_particles];
        for (k, &i) in s_list.iter().enumerate() {
            s_slot[i] = k;
        }
        let mut col_slot = vec![NOT_CONSTRAINED; nd];
        let mut cols: Vec<usize> = Vec::new();
        for &j in &self.constrained {
            for c in 0..comps {
                for (q, _) in w.row(comps * j + c) {
                    if col_slot[q] == NOT_CONSTRAINED {
                        col_slot[q] = cols.len();
                        cols.push(q);
                    }
                }
            }
        }
        let mut ts = DMatrix::zeros(s_list.len(), m);
        for (k, &i) in s_list.iter().enumerate() {
            for &(a, t) in &self.inv_cols[i] {
                if keep(t) {
                    ts[(k, a)] = t;
                }
            }
        }
        let products: Vec<DMatrix<f64>> = (0..comps)
            .map(|c| {
                let mut wj = DMatrix::zeros(m, cols.len());
                for (a, &j) in self.constrained.iter().enumerate() {
                    for (q, v) in w.row(comps * j + c) {
                        wj[(a, col_slot[q])] = v;
                    }
                }
                &ts * wj
            })
            .collect();
        let mut row_ptr = Vec::with_capacity(nd + 1);
        let mut col_idx = Vec::new();
        let mut values = Vec::new();
        row_ptr.push(0);
        for r in 0..nd {
            let (i, c) = (r / comps, r % comps);
            if self.slot[i] == NOT_CONSTRAINED {
                for (q, v) in w.row(r) {
                    acc.add(q, v);
                }
            }
            let k = s_slot[i];
            if k != NOT_CONSTRAINED {
                let p = &products[c];
                for (l, &q) in cols.iter().enumerate() {
                    let v = p[(k, l)];
                    if v != 0.0 {
                        acc.add(q, v);
                    }
                }
            }
            acc.flush(&mut col_idx, &mut values);
            row_ptr.push(col_idx.len());
        }
        Ok(CsrMatrix {
            nrows: nd,
            ncols: nd,
            row_ptr,
            col_idx,
            values,
        })
    }

    /// `Λ ⊗ I_comps` as a dense matrix (small problems, tests).
    pub fn lambda_dense(&self, comps: usize) -> DMatrix<f64> {
        let nd = self.n_particles * comps;
        let mut l = DMatrix::identity(nd, nd);
        for (a, row) in self.rows.iter().enumerate() {
            let j = self.constrained[a];
            for c in 0..comps {
                l[(comps * j + c, comps * j + c)] = 0.0;
                for &(i, v) in row {
                    l[(comps * j + c, comps * i + c)] = v;
                }
            }
        }
        l
    }

    /// Dense reference `K̃ = Λ⁻ᵀ K Λ⁻¹`, with `Λ⁻¹` from a dense LU of `Λ ⊗ I_comps` (small
    /// problems, tests).
    pub fn transform_matrix_dense(
        &self,
        k: &DMatrix<f64>,
        comps: usize,
    ) -> Result<DMatrix<f64>, TransformError> {
        self.check(k.nrows(), comps, "matrix K rows")?;
        self.check(k.ncols(), comps, "matrix K columns")?;
        let inv = self
            .lambda_dense(comps)
            .try_inverse()
            .ok_or_else(|| TransformError::InvalidInput("dense Λ is not invertible".into()))?;
        Ok(inv.transpose() * k * inv)
    }
}
