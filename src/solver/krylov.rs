//! GMRES right-preconditioned by a held factorisation: `A x = b` for a matrix `A` over a
//! [`SparsityPattern`] when the [`LinearSolver`] holds the factorisation of a nearby matrix
//! (the tangent of an earlier Newton iterate of the same step). Near convergence the tangent
//! changes by `O(‖Δu‖)` from one iterate to the next, so `A M⁻¹` is a small perturbation of the
//! identity and a few Arnoldi steps reach round-off, at the cost of one sparse product and one
//! pair of triangular solves each, against a full refactorisation.
//!
//! The iteration (Saad, *Iterative Methods for Sparse Linear Systems*, 2nd ed., §9.3.2): start
//! from the chord step `x₀ = M⁻¹ b`, build an orthonormal basis `V` of the Krylov space of
//! `A M⁻¹` on `r₀ = b − A x₀` by modified Gram–Schmidt, keep the least-squares problem in upper
//! triangular form with Givens rotations, and stop when the estimated residual
//! `|g_{j+1}| ≤ rtol ‖b‖`; then `x = x₀ + M⁻¹ V y`, from the vectors `M⁻¹ v_j` the Arnoldi
//! steps formed. No restart: the iteration fails (and the
//! caller refactorises) when `max_iterations` is reached first.

use super::{LinearSolver, SolverError, SparsityPattern};

/// Outcome of [`gmres`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GmresInfo {
    /// Arnoldi steps taken (0 when the chord step already met the tolerance).
    pub iterations: usize,
    /// True residual `‖b − A x‖ / ‖b‖` at the returned `x`.
    pub relative_residual: f64,
}

/// Products with at least this many stored entries run as two rayon tasks.
const PAR_PRODUCT_NNZ: usize = 1 << 20;

/// `y = A x` for the CSC values `values` of `pattern`.
///
/// A large product is split into two halves of the columns (at the column that halves the
/// stored entries, fixed by the pattern): the second half sums into a buffer that is added
/// to `y` at the end, so the result does not depend on the number of threads.
pub fn csc_mul(pattern: &SparsityPattern, values: &[f64], x: &[f64], y: &mut [f64]) {
    let nnz = pattern.nnz();
    in_halves(pattern, nnz, y, |cols, y| {
        csc_mul_range(pattern, values, x, cols, y)
    });
}

/// `y = 0`, then `part(cols, y)` adds the product of the columns `cols` of a matrix over
/// `pattern` into `y`: over all columns at once when `work` (stored entries times columns) is
/// below `PAR_PRODUCT_NNZ`, else in two halves (split at the column that halves the stored entries, fixed by the pattern) on two
/// rayon tasks, the second into a buffer added to `y` at the end, so that the result does not
/// depend on the number of threads.
fn in_halves<F>(pattern: &SparsityPattern, work: usize, y: &mut [f64], part: F)
where
    F: Fn(std::ops::Range<usize>, &mut [f64]) + Sync,
{
    let n = pattern.n_dofs();
    let cp = pattern.col_ptr();
    let nnz = cp[cp.len() - 1];
    y.fill(0.0);
    if work < PAR_PRODUCT_NNZ {
        part(0..n, y);
        return;
    }
    let mid = cp.partition_point(|&p| p < nnz / 2).min(n);
    let mut upper = vec![0.0; y.len()];
    rayon::join(|| part(0..mid, y), || part(mid..n, &mut upper));
    for (yi, ui) in y.iter_mut().zip(&upper) {
        *yi += ui;
    }
}

wide_vectors! {
    /// `y += A[:, cols] x[cols]`, each column's values run by run
    /// ([`SparsityPattern::column_runs`]): slices of consecutive rows, no row index per entry read,
    /// the same sums in the same order as entry by entry. Compiled for wider vectors where the
    /// processor has them, as [`csc_mul_many`].
    fn csc_mul_range(
        pattern: &SparsityPattern,
        values: &[f64],
        x: &[f64],
        cols: std::ops::Range<usize>,
        y: &mut [f64],
    ) => csc_mul_range_generic, avx512 = csc_mul_range_avx512, avx = csc_mul_range_avx {
        let cp = pattern.col_ptr();
        for j in cols {
            let xj = x[j];
            if xj == 0.0 {
                continue;
            }
            let mut p = cp[j];
            for run in pattern.column_runs(j) {
                let (r, len) = (run.row as usize, run.len as usize);
                for (yi, a) in y[r..r + len].iter_mut().zip(&values[p..p + len]) {
                    *yi += a * xj;
                }
                p += len;
            }
        }
    }
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Solve `A x = b` (`A` given by `values` over `pattern`) with GMRES right-preconditioned by the
/// factorisation `m` holds, applied in the precision of its options
/// ([`LinearSolver::precondition_columns_in_place`]: single precision for the supernodal LU by
/// default); `x` receives the solution. `Ok(None)`: not converged within
/// `max_iterations` (or the true residual of the result missed `rtol` by more than a factor
/// 10), `x` is then unspecified; errors are the solver's.
pub fn gmres(
    pattern: &SparsityPattern,
    values: &[f64],
    m: &LinearSolver,
    b: &[f64],
    x: &mut [f64],
    rtol: f64,
    max_iterations: usize,
) -> Result<Option<GmresInfo>, SolverError> {
    let tol = rtol * norm(b);
    gmres_to(pattern, values, m, b, x, tol, max_iterations, false)
}

/// Check points of the early abort of [`gmres_to`]: every this many Arnoldi steps.
const ABORT_EVERY: usize = 3;

/// [`gmres`] to the absolute tolerance `‖b − A x‖ ≤ tol`. With `abort_early`, the iteration
/// also gives up (`Ok(None)`) at every `ABORT_EVERY`-th step `j` when the mean contraction so
/// far, `(‖r_j‖/‖r_0‖)^(1/j)`, would need more than `max_iterations` steps in all to reach
/// `tol`: GMRES contracts at a rate that does not fall much once the preconditioner's error is
/// resolved, so such a solve is very unlikely to end within the budget and the steps already
/// taken are the only ones wasted.
#[allow(clippy::too_many_arguments)]
pub fn gmres_to(
    pattern: &SparsityPattern,
    values: &[f64],
    m: &LinearSolver,
    b: &[f64],
    x: &mut [f64],
    tol: f64,
    max_iterations: usize,
    abort_early: bool,
) -> Result<Option<GmresInfo>, SolverError> {
    let n = b.len();
    let b_norm = norm(b);
    if b_norm == 0.0 {
        x.fill(0.0);
        return Ok(Some(GmresInfo {
            iterations: 0,
            relative_residual: 0.0,
        }));
    }
    x.copy_from_slice(b);
    m.precondition_columns_in_place(x, 1)?;
    let mut ax = vec![0.0; n];
    csc_mul(pattern, values, x, &mut ax);
    let r0: Vec<f64> = b.iter().zip(&ax).map(|(bi, ai)| bi - ai).collect();
    let beta = norm(&r0);
    if beta <= tol {
        return Ok(Some(GmresInfo {
            iterations: 0,
            relative_residual: beta / b_norm,
        }));
    }
    let mut col = ColumnArnoldi::new(0, tol, &r0, beta);
    let mut converged = false;
    for j in 0..max_iterations {
        let mut z = col.last().to_vec();
        m.precondition_columns_in_place(&mut z, 1)?;
        let mut w = vec![0.0; n];
        csc_mul(pattern, values, &z, &mut w);
        match col.step(z, w) {
            Some(true) => {
                converged = true;
                break;
            }
            Some(false) => return Ok(None),
            None => {}
        }
        if abort_early && (j + 1) % ABORT_EVERY == 0 {
            // Steps in all at the mean contraction so far.
            let rate = (col.residual_estimate() / beta).ln() / (j + 1) as f64;
            let needed = (tol / beta).ln() / rate;
            if rate >= 0.0 || needed > max_iterations as f64 {
                return Ok(None);
            }
        }
    }
    if !converged {
        return Ok(None);
    }
    col.update(x);
    csc_mul(pattern, values, x, &mut ax);
    Ok(col.accept(b, &ax))
}

/// `Y = A X` for the `k` columns of `x` (column-major, `n` rows each) into `y`, with the
/// matrix read once for all of them. Below `PAR_PRODUCT_NNZ` stored entries times `k` each
/// column's sums are formed in [`csc_mul`]'s order (the same bits as a product of that column
/// alone); above it the columns of `A` are split in two halves as in [`csc_mul`], so the
/// result does not depend on the number of threads.
pub fn csc_mul_columns(
    pattern: &SparsityPattern,
    values: &[f64],
    x: &[f64],
    k: usize,
    y: &mut [f64],
) {
    csc_mul_columns_with::<false>(pattern, values, x, k, y);
}

/// `Y = |A| |X|` (entrywise absolute values) for the `k` columns of `x`, as
/// [`csc_mul_columns`]: the size of the terms that cancel in a residual `b − A x`.
pub fn csc_abs_mul_columns(
    pattern: &SparsityPattern,
    values: &[f64],
    x: &[f64],
    k: usize,
    y: &mut [f64],
) {
    csc_mul_columns_with::<true>(pattern, values, x, k, y);
}

fn csc_mul_columns_with<const ABS: bool>(
    pattern: &SparsityPattern,
    values: &[f64],
    x: &[f64],
    k: usize,
    y: &mut [f64],
) {
    let n = pattern.n_dofs();
    in_halves(pattern, pattern.nnz() * k, &mut y[..n * k], |cols, y| {
        csc_mul_many::<ABS>(pattern, values, x, k, cols, y)
    });
}

/// Columns of a product formed together: each stored entry is read once and multiplies
/// this many interleaved values (two SIMD lanes of two, or one of four).
const PRODUCT_GROUP: usize = 4;

wide_vectors! {
    /// `Y += A[:, cols] X[cols, :]` for `k` column-major columns, in groups of
    /// [`PRODUCT_GROUP`] columns interleaved row by row (with `ABS`, of `|A|` and `|X|`). On
    /// x86-64 processors with AVX-512 or AVX the same code runs compiled for wider vectors (the
    /// same operations in the same order per entry: bitwise equal results).
    fn csc_mul_many[const ABS: bool](
        pattern: &SparsityPattern,
        values: &[f64],
        x: &[f64],
        k: usize,
        cols: std::ops::Range<usize>,
        y: &mut [f64],
    ) => csc_mul_many_generic[ABS], avx512 = csc_mul_many_avx512, avx = csc_mul_many_avx {
        const G: usize = PRODUCT_GROUP;
        let n = pattern.n_dofs();
        let cp = pattern.col_ptr();
        let mut xi = vec![[0.0f64; G]; n];
        let mut yi = vec![[0.0f64; G]; n];
        for g in (0..k).step_by(G) {
            let w = (k - g).min(G);
            for j in cols.clone() {
                let mut row = [0.0; G];
                for (c, r) in row.iter_mut().enumerate().take(w) {
                    let v = x[(g + c) * n + j];
                    *r = if ABS { v.abs() } else { v };
                }
                xi[j] = row;
            }
            yi.fill([0.0; G]);
            for j in cols.clone() {
                let xj = xi[j];
                let mut p = cp[j];
                for run in pattern.column_runs(j) {
                    let (r, len) = (run.row as usize, run.len as usize);
                    for (yr, &a) in yi[r..r + len].iter_mut().zip(&values[p..p + len]) {
                        let a = if ABS { a.abs() } else { a };
                        for c in 0..G {
                            yr[c] += a * xj[c];
                        }
                    }
                    p += len;
                }
            }
            for c in 0..w {
                for (yv, r) in y[(g + c) * n..(g + c + 1) * n].iter_mut().zip(&yi) {
                    *yv += r[c];
                }
            }
        }
    }
}

/// One right-hand side's Arnoldi process ([`gmres_to`], [`gmres_columns_to`]): the
/// orthonormal basis `V` of the Krylov space of `A M⁻¹` on `r₀` (modified Gram–Schmidt), the
/// preconditioned basis `M⁻¹ v_j` (kept so that the update costs no further solve), the
/// Hessenberg columns after the Givens rotations (upper triangular `R`), the rotations and the
/// rotated right-hand side `g`.
struct ColumnArnoldi {
    /// The column's index among the right-hand sides.
    col: usize,
    tol: f64,
    v: Vec<Vec<f64>>,
    zs: Vec<Vec<f64>>,
    r: Vec<Vec<f64>>,
    rot: Vec<(f64, f64)>,
    g: Vec<f64>,
}

impl ColumnArnoldi {
    /// The process of column `col` on the residual `r0` of norm `beta > 0`, to `‖r‖ ≤ tol`.
    fn new(col: usize, tol: f64, r0: &[f64], beta: f64) -> Self {
        Self {
            col,
            tol,
            v: vec![r0.iter().map(|r| r / beta).collect()],
            zs: Vec::new(),
            r: Vec::new(),
            rot: Vec::new(),
            g: vec![beta],
        }
    }

    /// The newest basis vector `v_j`, which step `j` applies `A M⁻¹` to.
    fn last(&self) -> &[f64] {
        self.v.last().expect("a basis vector")
    }

    /// The residual norm of the least-squares solution so far, `|g_{j+1}|`.
    fn residual_estimate(&self) -> f64 {
        self.g.last().expect("g starts with β").abs()
    }

    /// Takes the product `w = A M⁻¹ v_j` of step `j`: orthogonalises it, rotates the new
    /// Hessenberg column, and tells whether the column is done (`Some(true)`: converged or
    /// an invariant space, `Some(false)`: broken down) or goes on (`None`).
    fn step(&mut self, z: Vec<f64>, mut w: Vec<f64>) -> Option<bool> {
        let j = self.zs.len();
        self.zs.push(z);
        let mut h = Vec::with_capacity(j + 2);
        for vi in &self.v {
            let hij = dot(&w, vi);
            for (wk, vk) in w.iter_mut().zip(vi) {
                *wk -= hij * vk;
            }
            h.push(hij);
        }
        let h_next = norm(&w);
        h.push(h_next);
        for (i, &(c, s)) in self.rot.iter().enumerate() {
            let (a, bb) = (h[i], h[i + 1]);
            h[i] = c * a + s * bb;
            h[i + 1] = -s * a + c * bb;
        }
        let (a, bb) = (h[j], h[j + 1]);
        let d = a.hypot(bb);
        if d == 0.0 || !d.is_finite() {
            return Some(false);
        }
        let (c, s) = (a / d, bb / d);
        h[j] = d;
        h[j + 1] = 0.0;
        self.rot.push((c, s));
        let gj = self.g[j];
        self.g[j] = c * gj;
        self.g.push(-s * gj);
        h.truncate(j + 1);
        self.r.push(h);
        if self.g[j + 1].abs() <= self.tol || h_next == 0.0 {
            // Converged, or the Krylov space is invariant and the least-squares solution
            // exact.
            return Some(true);
        }
        w.iter_mut().for_each(|x| *x /= h_next);
        self.v.push(w);
        None
    }

    /// The outcome of a converged process from the true residual `b − A x` of its updated
    /// `x` (`ax = A x`): `None` where it missed the tolerance by more than a factor 10 (the
    /// estimate drifted from the true residual) or is NaN.
    fn accept(&self, b: &[f64], ax: &[f64]) -> Option<GmresInfo> {
        let res = b
            .iter()
            .zip(ax)
            .map(|(bi, ai)| (bi - ai).powi(2))
            .sum::<f64>()
            .sqrt();
        // A NaN residual fails too.
        if res.is_nan() || res > 10.0 * self.tol {
            return None;
        }
        Some(GmresInfo {
            iterations: self.r.len(),
            relative_residual: res / norm(b),
        })
    }

    /// `x += M⁻¹ V y` with `R y = g` (back substitution).
    fn update(&self, x: &mut [f64]) {
        let k = self.r.len();
        let mut y = vec![0.0; k];
        for i in (0..k).rev() {
            let mut s = self.g[i];
            for (l, yl) in y.iter().enumerate().take(k).skip(i + 1) {
                s -= self.r[l][i] * yl;
            }
            y[i] = s / self.r[i][i];
        }
        for (zi, yi) in self.zs.iter().zip(&y) {
            for (xk, zk) in x.iter_mut().zip(zi) {
                *xk += yi * zk;
            }
        }
    }
}

/// [`gmres_to`] for the `k` right-hand sides in the columns of `b` (column-major, `n` rows
/// each) at once, from the initial guesses in `x`, each column to its own absolute tolerance
/// `tols[c]` on `‖b_c − A x_c‖`. The columns run their own Arnoldi processes in lock step,
/// so that each step reads the factors once ([`LinearSolver::solve_columns_in_place`]) and the
/// matrix once ([`csc_mul_columns`]) for all columns still iterating; a column leaves when it
/// converges. Per column, the same iteration as [`gmres_to`] from the guess `x_c` (whose
/// chord step `M⁻¹ b` is the usual one), without the early abort, and with the factorisation
/// applied in double precision whatever the solver's preconditioner precision: these are the
/// continuum DSA's solves, to round-off, against a factorisation at or next to the matrix,
/// where single precision's rounding would bound each step's contraction (the plastic
/// hemisphere's 17² DSA: 129 Arnoldi steps in double precision, 261 in single).
///
/// Returns each column's outcome: `None` where it did not converge within `max_iterations`
/// or its true residual missed its tolerance by more than a factor 10 (that column of `x` is
/// then unspecified).
#[allow(clippy::too_many_arguments)]
pub fn gmres_columns_to(
    pattern: &SparsityPattern,
    values: &[f64],
    m: &LinearSolver,
    b: &[f64],
    x: &mut [f64],
    k: usize,
    tols: &[f64],
    max_iterations: usize,
) -> Result<Vec<Option<GmresInfo>>, SolverError> {
    let n = pattern.n_dofs();
    let mut ax = vec![0.0; n * k];
    csc_mul_columns(pattern, values, x, k, &mut ax);
    let mut out: Vec<Option<GmresInfo>> = vec![None; k];
    let mut active = Vec::new();
    for c in 0..k {
        let bc = &b[c * n..(c + 1) * n];
        let r0: Vec<f64> = bc
            .iter()
            .zip(&ax[c * n..(c + 1) * n])
            .map(|(bi, ai)| bi - ai)
            .collect();
        let beta = norm(&r0);
        let b_norm = norm(bc);

        if beta <= tols[c] {
            out[c] = Some(GmresInfo {
                iterations: 0,
                relative_residual: if b_norm > 0.0 { beta / b_norm } else { 0.0 },
            });
            continue;
        }
        active.push(ColumnArnoldi::new(c, tols[c], &r0, beta));
    }
    let mut done = Vec::new();
    let mut zbuf = Vec::new();
    let mut wbuf = Vec::new();
    for _ in 0..max_iterations {
        if active.is_empty() {
            break;
        }
        let na = active.len();
        zbuf.clear();
        for a in &active {
            zbuf.extend_from_slice(a.last());
        }
        m.solve_columns_in_place(&mut zbuf, na)?;
        wbuf.resize(n * na, 0.0);
        csc_mul_columns(pattern, values, &zbuf, na, &mut wbuf);
        let mut still = Vec::with_capacity(na);
        for (i, mut a) in active.drain(..).enumerate() {
            let z = zbuf[i * n..(i + 1) * n].to_vec();
            let w = wbuf[i * n..(i + 1) * n].to_vec();
            match a.step(z, w) {
                None => still.push(a),
                Some(true) => done.push(a),
                Some(false) => {}
            }
        }
        active = still;
    }
    // The converged columns' updates and their true residuals, in one product.
    for a in &done {
        a.update(&mut x[a.col * n..(a.col + 1) * n]);
    }
    if !done.is_empty() {
        let mut xs = Vec::with_capacity(n * done.len());
        for a in &done {
            xs.extend_from_slice(&x[a.col * n..(a.col + 1) * n]);
        }
        let mut axs = vec![0.0; n * done.len()];
        csc_mul_columns(pattern, values, &xs, done.len(), &mut axs);
        for (i, a) in done.iter().enumerate() {
            out[a.col] = a.accept(&b[a.col * n..(a.col + 1) * n], &axs[i * n..(i + 1) * n]);
        }
    }
    Ok(out)
}
