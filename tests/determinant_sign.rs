//! `LinearSolver::determinant_sign` against determinants known independently: matrices built as
//! `L D U` (the sign is that of `Π D_i`), strictly diagonally dominant matrices (the sign is
//! that of `Π a_ii`), saddle points `[K Cᵀ; C 0]` with `K` positive definite (`(−1)^m`), and
//! random indefinite matrices checked against a Gaussian elimination with partial pivoting
//! written here, for the dense and the supernodal LU on 1 and 2 threads.

use shelldsa::solver::*;

/// xorshift64*: reproducible uniform numbers in [−1, 1).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let x = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d);
        (x >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// Sign of `det a` (row-major `n × n`) by Gaussian elimination with partial pivoting, and the
/// smallest pivot relative to the largest entry (to keep away from numerically singular cases).
fn reference_sign(n: usize, a: &[f64]) -> (f64, f64) {
    let mut a = a.to_vec();
    let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut sign = 1.0;
    let mut smallest = f64::INFINITY;
    for k in 0..n {
        let p = (k..n)
            .max_by(|&i, &j| a[i * n + k].abs().total_cmp(&a[j * n + k].abs()))
            .unwrap();
        if p != k {
            for j in 0..n {
                a.swap(k * n + j, p * n + j);
            }
            sign = -sign;
        }
        let d = a[k * n + k];
        smallest = smallest.min(d.abs() / scale);
        if d < 0.0 {
            sign = -sign;
        }
        for i in k + 1..n {
            let f = a[i * n + k] / d;
            for j in k..n {
                a[i * n + j] -= f * a[k * n + j];
            }
        }
    }
    (sign, smallest)
}

/// The pattern of all `n²` entries, and `values` of the row-major `a` in its slots.
fn full(n: usize) -> SparsityPattern {
    SparsityPattern::from_cells(n, &[(0..n).collect()]).unwrap()
}

fn values_of(p: &SparsityPattern, n: usize, a: &[f64]) -> Vec<f64> {
    let (cp, ri) = (p.col_ptr(), p.row_idx());
    let mut v = vec![0.0; p.nnz()];
    for j in 0..n {
        for q in cp[j]..cp[j + 1] {
            v[q] = a[ri[q] * n + j];
        }
    }
    v
}

/// A banded shell-like pattern: `nx × nx` particles with 3 DOFs, each coupled to the particles
/// within one spacing.
fn banded(nx: usize) -> SparsityPattern {
    SparsityPattern::particle_grid(nx, 3, 1).unwrap()
}

/// The sign from a fresh factorisation with `method` on `threads` rayon threads (the
/// supernodal LU's tasks, and faer's kernels through `Parallelism::Rayon`).
fn sign_with(p: &SparsityPattern, values: &[f64], method: Method, threads: usize) -> Option<f64> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let parallelism = if threads == 1 {
            Parallelism::Sequential
        } else {
            Parallelism::Rayon(threads)
        };
        let options = SolverOptions {
            parallelism,
            ..SolverOptions::default()
        };
        let mut s = LinearSolver::new(p, method, options).unwrap();
        assert_eq!(s.determinant_sign(), None, "no factorisation yet");
        s.factorize(values).unwrap();
        s.determinant_sign()
    })
}

const PIVOTED: [Method; 2] = [Method::DenseLu, Method::SupernodalLu];

#[test]
fn sign_of_l_d_u_products_is_the_sign_of_d() {
    // A = P L D U with unit triangular L, U and a row permutation P: det A = sign(P) Π D_i
    // exactly, whatever pivoting the factorisation does.
    let n = 24;
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let p = full(n);
    let mut seen = [0usize; 2];
    for trial in 0..12 {
        let mut l = vec![0.0; n * n];
        let mut u = vec![0.0; n * n];
        let mut d = vec![0.0; n];
        for i in 0..n {
            l[i * n + i] = 1.0;
            u[i * n + i] = 1.0;
            for j in 0..i {
                l[i * n + j] = rng.next();
                u[j * n + i] = rng.next();
            }
            // |D_i| in [0.5, 1.5], random sign (trial 0: all positive).
            let mag = 1.0 + 0.5 * rng.next();
            d[i] = if trial > 0 && rng.next() < 0.0 {
                -mag
            } else {
                mag
            };
        }
        let mut a = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                a[i * n + j] = (0..=i.min(j))
                    .map(|k| l[i * n + k] * d[k] * u[k * n + j])
                    .sum();
            }
        }
        // Rows swapped at random (|L| ≤ 1 alone would need no pivoting): each swap flips the sign.
        let mut exact = d.iter().map(|v| v.signum()).product::<f64>();
        for _ in 0..trial {
            let i = ((rng.next() + 1.0) * 0.5 * n as f64) as usize % n;
            let j = ((rng.next() + 1.0) * 0.5 * n as f64) as usize % n;
            if i != j {
                for c in 0..n {
                    a.swap(i * n + c, j * n + c);
                }
                exact = -exact;
            }
        }
        seen[(exact < 0.0) as usize] += 1;
        let values = values_of(&p, n, &a);
        assert_sign_everywhere(&p, &values, exact, trial);
    }
    assert!(seen[0] > 0 && seen[1] > 0, "both signs tested: {seen:?}");
}

/// Every pivoted method, with 1 and 2 threads, gives the sign `exact` of the matrix `values`.
fn assert_sign_everywhere(p: &SparsityPattern, values: &[f64], exact: f64, trial: usize) {
    for method in PIVOTED {
        for threads in [1, 2] {
            let got = sign_with(p, values, method, threads);
            assert_eq!(
                got,
                Some(exact),
                "trial {trial}, {method:?}, {threads} threads"
            );
        }
    }
}

#[test]
fn sign_of_diagonally_dominant_matrices_is_the_sign_of_the_diagonal_product() {
    // Strictly diagonally dominant rows: A(t) = D + t (A − D) is nonsingular for t ∈ [0, 1], so
    // det A has the sign of Π a_ii. Sparse banded pattern, unsymmetric values.
    let p = banded(7);
    let n = p.n_dofs();
    let (cp, ri) = (p.col_ptr().to_vec(), p.row_idx().to_vec());
    let mut rng = Rng(42);
    let mut seen = [0usize; 2];
    for trial in 0..10 {
        let mut values: Vec<f64> = (0..p.nnz()).map(|_| rng.next()).collect();
        let mut row_sum = vec![0.0; n];
        for j in 0..n {
            for q in cp[j]..cp[j + 1] {
                if ri[q] != j {
                    row_sum[ri[q]] += values[q].abs();
                }
            }
        }
        // A few negative diagonal entries (0, 1, ... per trial).
        let mut exact = 1.0;
        for (i, s) in row_sum.iter().enumerate() {
            let neg = (i * 7 + trial * 13) % 29 < trial;
            let d = (1.1 + 0.2 * rng.next().abs()) * s;
            values[p.diag_slot(i)] = if neg { -d } else { d };
            if neg {
                exact = -exact;
            }
        }
        seen[(exact < 0.0) as usize] += 1;
        assert_sign_everywhere(&p, &values, exact, trial);
    }
    assert!(seen[0] > 0 && seen[1] > 0, "both signs tested: {seen:?}");
}

#[test]
fn sign_of_random_indefinite_matrices_matches_gaussian_elimination() {
    // Random unsymmetric values on the banded pattern with a weak diagonal of random sign:
    // indefinite, and the factorisations pivot. The reference is the elimination above;
    // matrices whose reference pivots fall below 1e-6 of the largest entry are skipped (none
    // was in these seeds: the assertion on `tested` catches a change).
    let p = banded(6);
    let n = p.n_dofs();
    let (cp, ri) = (p.col_ptr().to_vec(), p.row_idx().to_vec());
    let mut rng = Rng(7);
    let mut tested = 0;
    let mut supernodal_signs = 0;
    let mut seen = [0usize; 2];
    for trial in 0..16 {
        let mut values: Vec<f64> = (0..p.nnz()).map(|_| rng.next()).collect();
        for i in 0..n {
            values[p.diag_slot(i)] = 0.3 * rng.next();
        }
        let mut dense = vec![0.0; n * n];
        for j in 0..n {
            for q in cp[j]..cp[j + 1] {
                dense[ri[q] * n + j] = values[q];
            }
        }
        let (exact, smallest) = reference_sign(n, &dense);
        if smallest < 1e-6 {
            continue;
        }
        tested += 1;
        seen[(exact < 0.0) as usize] += 1;
        for threads in [1, 2] {
            let got = sign_with(&p, &values, Method::DenseLu, threads);
            assert_eq!(got, Some(exact), "trial {trial}, dense, {threads} threads");
            // The supernodal LU pivots only inside its supernodes; where that fails the probe
            // it hands over to faer's sparse LU, which gives no sign (None).
            let got = sign_with(&p, &values, Method::SupernodalLu, threads);
            if let Some(s) = got {
                assert_eq!(s, exact, "trial {trial}, supernodal, {threads} threads");
                supernodal_signs += 1;
            }
        }
    }
    assert!(tested >= 12, "{tested} matrices tested");
    assert!(seen[0] > 0 && seen[1] > 0, "both signs tested: {seen:?}");
    assert!(
        supernodal_signs >= tested,
        "the supernodal LU gave a sign for {supernodal_signs} of {} factorisations",
        2 * tested
    );
}

#[test]
fn saddle_points_with_a_positive_definite_block_have_sign_minus_one_to_the_m() {
    // [K Cᵀ; C 0] with K symmetric positive definite and C of full row rank m has m negative
    // and n positive eigenvalues: sign det = (−1)^m (the constant factor the multiplier rows
    // of a constrained tangent contribute).
    let nk = 20;
    let mut rng = Rng(2024);
    for m in 1..=4 {
        let n = nk + m;
        let mut a = vec![0.0; n * n];
        // K = B Bᵀ + I.
        let b: Vec<f64> = (0..nk * nk).map(|_| rng.next()).collect();
        for i in 0..nk {
            for j in 0..nk {
                let mut s: f64 = (0..nk).map(|k| b[i * nk + k] * b[j * nk + k]).sum();
                if i == j {
                    s += 1.0;
                }
                a[i * n + j] = s;
            }
        }
        for r in 0..m {
            for j in 0..nk {
                let c = rng.next();
                a[(nk + r) * n + j] = c;
                a[j * n + nk + r] = c;
            }
        }
        let p = full(n);
        let values = values_of(&p, n, &a);
        let exact = if m % 2 == 0 { 1.0 } else { -1.0 };
        assert_eq!(reference_sign(n, &a).0, exact, "m = {m}: reference");
        for threads in [1, 2] {
            assert_eq!(
                sign_with(&p, &values, Method::DenseLu, threads),
                Some(exact),
                "m = {m}, {threads} threads"
            );
            if let Some(s) = sign_with(&p, &values, Method::SupernodalLu, threads) {
                assert_eq!(s, exact, "m = {m}, supernodal, {threads} threads");
            }
        }
    }
}

#[test]
fn cholesky_gives_plus_one_and_the_sparse_lu_gives_no_sign() {
    let p = banded(4);
    let n = p.n_dofs();
    let (cp, ri) = (p.col_ptr().to_vec(), p.row_idx().to_vec());
    // A symmetric diagonally dominant matrix with a positive diagonal: positive definite.
    let mut values = p.values_from(|i, j| -1.0 / (1.0 + (i + j) as f64 % 5.0));
    for j in 0..n {
        let s: f64 = (cp[j]..cp[j + 1])
            .filter(|&q| ri[q] != j)
            .map(|q| values[q].abs())
            .sum();
        values[p.diag_slot(j)] = s + 1.0;
    }
    let mut chol = LinearSolver::new(&p, Method::Cholesky, SolverOptions::default()).unwrap();
    chol.factorize(&values).unwrap();
    assert_eq!(chol.determinant_sign(), Some(1.0));
    let mut lu = LinearSolver::new(&p, Method::Lu, SolverOptions::default()).unwrap();
    lu.factorize(&values).unwrap();
    assert_eq!(lu.determinant_sign(), None);
    // A failed factorisation leaves no sign.
    let mut dense = LinearSolver::new(&p, Method::DenseLu, SolverOptions::default()).unwrap();
    dense.factorize(&values).unwrap();
    assert_eq!(dense.determinant_sign(), Some(1.0));
    let mut singular = values.clone();
    singular[cp[0]..cp[1]].fill(0.0);
    assert!(dense.factorize(&singular).is_err());
    assert_eq!(dense.determinant_sign(), None);
}
