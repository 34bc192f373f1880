//! The eigenvalues of a factorised tangent nearest to zero, with their eigenvectors: the
//! stability diagnosis of a converged state (a spurious mode of the discretisation, a
//! bifurcation, a limit point).
//!
//! The operator is the inverse of the tangent restricted to the admissible unknowns: for the
//! bordered (multiplier) system `A = [K  Cᵀ; C  0]` factorised in a [`LinearSolver`], with the
//! eliminated DOFs of an [`EssentialBc`] and the multiplier rows `n_primary..n` masked,
//! `x ↦ P (A⁻¹ [P x; 0])` is `Z (Zᵀ K Z)⁻¹ Zᵀ x` for an orthonormal basis `Z` of the admissible
//! subspace (`C q = 0`, eliminated DOFs zero). Its largest eigenvalues are the inverses of the
//! smallest eigenvalues of `K` on that subspace, so rigid-body motions that the conditions
//! remove and the constraint rows themselves never appear: every eigenvalue returned is a
//! mode of the constrained structure.
//!
//! Method: block inverse (subspace) iteration with Rayleigh–Ritz on the symmetric part of the
//! projected inverse (the shell tangent is unsymmetric only through non-conservative terms and
//! the Petrov–Galerkin test gradients; the skew part of the projected matrix is reported so the
//! caller can judge). Each iteration costs one multi-right-hand-side solve with the existing
//! factorisation.

use super::{EssentialBc, LinearSolver, SolverError};
use nalgebra::{DMatrix, SymmetricEigen};

/// Settings of [`smallest_eigenpairs`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpectrumOptions {
    /// Eigenpairs wanted (the ones nearest to zero).
    pub count: usize,
    /// Extra subspace vectors (guard vectors speed convergence of the last wanted pair).
    pub guard: usize,
    /// Most iterations.
    pub max_iterations: usize,
    /// Stop when every wanted Ritz value changes by less than this, relative, in one iteration.
    pub tolerance: f64,
}

impl Default for SpectrumOptions {
    fn default() -> Self {
        SpectrumOptions {
            count: 8,
            guard: 8,
            max_iterations: 200,
            tolerance: 1e-10,
        }
    }
}

/// One eigenpair of the constrained tangent.
#[derive(Clone, Debug, PartialEq)]
pub struct Eigenpair {
    /// The eigenvalue (signed; negative: the state is unstable along `vector`).
    pub value: f64,
    /// The unit eigenvector on the first `n_primary` unknowns (zero on eliminated DOFs).
    pub vector: Vec<f64>,
    /// `‖A⁻¹x − x/λ‖·|λ|` for the returned `x`: the residual of the inverse eigen-equation,
    /// relative (0 for an exact pair).
    pub residual: f64,
}

/// The result of [`smallest_eigenpairs`].
#[derive(Clone, Debug, PartialEq)]
pub struct Spectrum {
    /// The eigenpairs, in increasing `|value|`.
    pub pairs: Vec<Eigenpair>,
    /// Iterations used.
    pub iterations: usize,
    /// `‖H − Hᵀ‖ / ‖H‖` of the projected inverse on the final subspace: the unsymmetry that
    /// the symmetric Rayleigh–Ritz step ignored.
    pub skew: f64,
}

fn mask(v: &mut [f64], n_primary: usize, essential: &EssentialBc) {
    for x in v[n_primary..].iter_mut() {
        *x = 0.0;
    }
    essential.zero_constrained(v);
}

/// Orthonormalise the columns of `v` (`n × m`, column-major) in place by twice-repeated
/// modified Gram–Schmidt; returns the number of independent columns kept at the front.
fn orthonormalise(v: &mut [f64], n: usize, m: usize) -> usize {
    let mut kept = 0;
    for j in 0..m {
        let (head, tail) = v.split_at_mut(j * n);
        let col = &mut tail[..n];
        let norm0 = col.iter().map(|x| x * x).sum::<f64>().sqrt();
        for _ in 0..2 {
            for k in 0..kept {
                let q = &head[k * n..(k + 1) * n];
                let d: f64 = q.iter().zip(col.iter()).map(|(a, b)| a * b).sum();
                for (c, a) in col.iter_mut().zip(q) {
                    *c -= d * a;
                }
            }
        }
        let norm = col.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm > 1e-12 * norm0.max(f64::MIN_POSITIVE) && norm > 0.0 {
            let col: Vec<f64> = col.iter().map(|x| x / norm).collect();
            v[kept * n..(kept + 1) * n].copy_from_slice(&col);
            kept += 1;
        }
    }
    kept
}

/// The `options.count` eigenpairs of the constrained tangent nearest to zero (module
/// documentation). `solver` holds the factorised system of `n = solver.n_dofs()` unknowns, the
/// first `n_primary` of which are the generalised DOFs (the rest multipliers); `essential`
/// lists the eliminated DOFs.
pub fn smallest_eigenpairs(
    solver: &LinearSolver,
    essential: &EssentialBc,
    n_primary: usize,
    options: SpectrumOptions,
) -> Result<Spectrum, SolverError> {
    let n = solver.n_dofs();
    if n_primary > n {
        return Err(SolverError::Length {
            what: "n_primary (at most the solver's unknowns)",
            expected: n,
            got: n_primary,
        });
    }
    let free = (0..n_primary)
        .filter(|&i| !essential.is_constrained(i))
        .count();
    let m = (options.count + options.guard).min(free).max(1);
    let want = options.count.min(m);
    // Deterministic start: smooth and oscillating columns mixed by a fixed hash, so that no
    // start vector is orthogonal to a mode by symmetry.
    let mut v = vec![0.0; n * m];
    for j in 0..m {
        for i in 0..n {
            let h = (i as u64 + 1)
                .wrapping_mul(0x9E37_79B9_7F4A_7C15)
                .wrapping_add((j as u64 + 1).wrapping_mul(0xBF58_476D_1CE4_E5B9));
            let h = (h ^ (h >> 31)).wrapping_mul(0x94D0_49BB_1331_11EB);
            v[j * n + i] = (h >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
        }
        mask(&mut v[j * n..(j + 1) * n], n_primary, essential);
    }
    let mut m = orthonormalise(&mut v, n, m);
    let mut previous: Vec<f64> = Vec::new();
    let mut iterations = 0;
    let mut skew;
    let mut theta: Vec<f64>;
    let mut ritz_vectors: DMatrix<f64>;
    let mut y = vec![0.0; n * m];
    loop {
        iterations += 1;
        y.resize(n * m, 0.0);
        y.copy_from_slice(&v[..n * m]);
        solver.solve_columns_in_place(&mut y, m)?;
        for j in 0..m {
            mask(&mut y[j * n..(j + 1) * n], n_primary, essential);
        }
        // Projected inverse H = Vᵀ Y.
        let h = DMatrix::from_fn(m, m, |a, b| {
            v[a * n..(a + 1) * n]
                .iter()
                .zip(&y[b * n..(b + 1) * n])
                .map(|(p, q)| p * q)
                .sum::<f64>()
        });
        let hs = (&h + h.transpose()) * 0.5;
        skew = (&h - h.transpose()).norm() / h.norm().max(f64::MIN_POSITIVE) * 0.5;
        let eig = SymmetricEigen::new(hs);
        // Order by decreasing |θ| (smallest |λ| first).
        let mut order: Vec<usize> = (0..m).collect();
        order.sort_by(|&a, &b| {
            eig.eigenvalues[b]
                .abs()
                .partial_cmp(&eig.eigenvalues[a].abs())
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        theta = order.iter().map(|&k| eig.eigenvalues[k]).collect();
        ritz_vectors = DMatrix::from_fn(m, m, |a, b| eig.eigenvectors[(a, order[b])]);
        let converged = previous.len() == theta.len()
            && theta
                .iter()
                .zip(&previous)
                .take(want)
                .all(|(t, p)| (t - p).abs() <= options.tolerance * t.abs());
        if converged || iterations >= options.max_iterations {
            break;
        }
        previous = theta.clone();
        // Next subspace: Y S, orthonormalised.
        let mut next = vec![0.0; n * m];
        for b in 0..m {
            let col = &mut next[b * n..(b + 1) * n];
            for a in 0..m {
                let s = ritz_vectors[(a, b)];
                if s != 0.0 {
                    for (c, q) in col.iter_mut().zip(&y[a * n..(a + 1) * n]) {
                        *c += s * q;
                    }
                }
            }
        }
        m = orthonormalise(&mut next, n, m);
        v = next;
        v.truncate(n * m);
    }
    let mut pairs = Vec::with_capacity(want);
    for b in 0..want.min(m) {
        let mut x = vec![0.0; n];
        let mut ax = vec![0.0; n];
        for a in 0..m {
            let s = ritz_vectors[(a, b)];
            for i in 0..n {
                x[i] += s * v[a * n + i];
                ax[i] += s * y[a * n + i];
            }
        }
        let t = theta[b];
        let nx = x.iter().map(|q| q * q).sum::<f64>().sqrt();
        let r = ax
            .iter()
            .zip(&x)
            .map(|(p, q)| (p - t * q).powi(2))
            .sum::<f64>()
            .sqrt();
        x.truncate(n_primary);
        for q in x.iter_mut() {
            *q /= nx;
        }
        pairs.push(Eigenpair {
            value: 1.0 / t,
            vector: x,
            residual: r / (t.abs() * nx).max(f64::MIN_POSITIVE),
        });
    }
    Ok(Spectrum {
        pairs,
        iterations,
        skew,
    })
}
