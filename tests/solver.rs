//! Global linear algebra and Newton driver (`shelldsa::solver`).

use nalgebra::{DMatrix, DVector};
use shelldsa::solver::*;
use std::convert::Infallible;

/// Small deterministic generator (xorshift64*), uniform in [-1, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let x = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
        (x >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
    fn below(&mut self, n: usize) -> usize {
        (((self.next() + 1.0) * 0.5 * n as f64) as usize).min(n - 1)
    }
}

/// Random cells of 2..=6 DOFs (some repeated DOFs inside a cell) plus a chain so the matrix is
/// irreducible.
fn random_cells(n: usize, n_cells: usize, rng: &mut Rng) -> Vec<Vec<usize>> {
    let mut cells: Vec<Vec<usize>> = (0..n - 1).map(|i| vec![i, i + 1]).collect();
    for _ in 0..n_cells {
        let m = 2 + rng.below(5);
        cells.push((0..m).map(|_| rng.below(n)).collect());
    }
    cells
}

/// Random values over the pattern: unsymmetric, or SPD (cell matrices `B Bᵀ`), plus a diagonal
/// shift `shift` that keeps the matrix safely nonsingular.
fn random_values(p: &SparsityPattern, rng: &mut Rng, spd: bool, shift: f64) -> Vec<f64> {
    let mut values = vec![0.0; p.nnz()];
    let mut rhs = vec![0.0; p.n_dofs()];
    let locals: Vec<DMatrix<f64>> = (0..p.n_cells())
        .map(|c| {
            let m = p.cell_dofs(c).len();
            let b = DMatrix::from_fn(m, m, |_, _| rng.next());
            if spd {
                &b * b.transpose()
            } else {
                b
            }
        })
        .collect();
    assemble(p, &mut values, &mut rhs, Execution::Serial, |c| {
        let m = locals[c].nrows();
        Ok::<_, Infallible>((locals[c].clone(), DVector::zeros(m)))
    })
    .unwrap();
    for i in 0..p.n_dofs() {
        values[p.diag_slot(i)] += shift;
    }
    values
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// Normwise relative residual ‖A x − b‖ / (‖A‖_F ‖x‖ + ‖b‖): the backward error of the solve.
fn backward_error(p: &SparsityPattern, values: &[f64], x: &[f64], b: &[f64]) -> f64 {
    let mut ax = vec![0.0; x.len()];
    p.mat_vec(values, x, &mut ax).unwrap();
    let r: Vec<f64> = ax.iter().zip(b).map(|(a, b)| a - b).collect();
    norm(&r) / (norm(values) * norm(x) + norm(b))
}

#[test]
fn pattern_is_sorted_csc_with_diagonal_and_cell_slots() {
    let cells = vec![vec![0, 3], vec![3, 1, 3], vec![]];
    let p = SparsityPattern::from_cells(5, &cells).unwrap();
    assert_eq!(p.n_dofs(), 5);
    assert_eq!(p.col_ptr(), &[0, 2, 4, 5, 8, 9]);
    assert_eq!(p.row_idx(), &[0, 3, 1, 3, 2, 0, 1, 3, 4]);
    // cell 1 local (i, j) at j*m + i: (row 3, col 1) is local (0, 1) -> slot of (3, 1) = 3.
    assert_eq!(p.cell_slots(1)[3] as usize, p.slot(3, 1).unwrap());
    assert_eq!(p.cell_slots(1).len(), 9);
    assert_eq!(p.slot(2, 0), None);
    assert_eq!(p.diag_slot(4), 8);
}

/// The runs of every cell column cover its local rows once, in order, and map each to the
/// slot of its entry (and `cell_slots` expands them to the same): on random cells (unsorted DOF lists), a cell with a repeated DOF,
/// and particle-like cells whose DOFs come in consecutive blocks (long runs).
#[test]
fn cell_column_runs_reproduce_the_cell_slots() {
    let mut rng = Rng(0x5EED);
    let n = 60;
    let mut cells = random_cells(n, 40, &mut rng);
    cells.push(vec![4, 9, 4, 5, 6]);
    cells.push((10..25).chain(40..50).collect());
    let p = SparsityPattern::from_cells(n, &cells).unwrap();
    let mut longest = 0;
    for (c, dofs) in cells.iter().enumerate() {
        let m = dofs.len();
        let slots = p.cell_slots(c);
        for jj in 0..m {
            let mut next = 0;
            for run in p.cell_column_runs(c, jj) {
                assert_eq!(
                    run.row as usize, next,
                    "cell {c} column {jj}: rows in order"
                );
                assert!(run.len >= 1);
                for t in 0..run.len as usize {
                    // Against the pattern's own look-up of the entry.
                    let slot = p.slot(dofs[next + t], dofs[jj]).unwrap();
                    assert_eq!((run.slot + t as u32) as usize, slot);
                    assert_eq!(slots[jj * m + next + t], run.slot + t as u32);
                }
                next += run.len as usize;
                longest = longest.max(run.len);
            }
            assert_eq!(next, m, "cell {c} column {jj}: every row once");
        }
    }
    // The block cell's columns 10..25 and 40..50 are contiguous in every column's rows.
    assert!(longest >= 10, "longest run {longest}");
}

/// The runs of every column cover its stored rows once, in order (so the `k`-th entry of a
/// column is the `k`-th row of its runs), and the products read through them give the
/// entry-by-entry sums bit for bit: on random cells (short runs), particle-like cells (long runs),
/// a pattern of entries, and with a zero entry in `x` (the products skip its column).
#[test]
fn column_runs_cover_the_rows_and_the_products_equal_the_entrywise_sums() {
    use shelldsa::solver::krylov::{csc_abs_mul_columns, csc_mul, csc_mul_columns};
    let mut rng = Rng(0xC0FFEE);
    let n = 80;
    let patterns = [
        SparsityPattern::from_cells(n, &random_cells(n, 60, &mut rng)).unwrap(),
        SparsityPattern::particle_grid(9, 5, 2).unwrap(),
        SparsityPattern::from_entries(n, &[(3, 7), (4, 7), (5, 7), (9, 7), (79, 0)]).unwrap(),
    ];
    for (k, p) in patterns.iter().enumerate() {
        let (cp, ri) = (p.col_ptr(), p.row_idx());
        let n = p.n_dofs();
        let mut longest = 0;
        for j in 0..n {
            let mut q = cp[j];
            for run in p.column_runs(j) {
                assert!(run.len >= 1, "pattern {k} column {j}: empty run");
                for t in 0..run.len as usize {
                    assert_eq!(ri[q], run.row as usize + t, "pattern {k} column {j}");
                    q += 1;
                }
                longest = longest.max(run.len);
            }
            assert_eq!(q, cp[j + 1], "pattern {k} column {j}: every entry once");
        }
        // The particle grid's columns hold its 5 × 5 particle blocks: runs of 25 rows.
        if k == 1 {
            assert!(longest >= 25, "longest run {longest}");
        }
        let values: Vec<f64> = (0..p.nnz()).map(|_| rng.next()).collect();
        let cols = 3;
        let mut x: Vec<f64> = (0..n * cols).map(|_| rng.next()).collect();
        x[n / 2] = 0.0;
        let abs_values: Vec<f64> = values.iter().map(|v| v.abs()).collect();
        let (mut y, mut ys, mut yabs) = (
            vec![0.0; n * cols],
            vec![0.0; n * cols],
            vec![0.0; n * cols],
        );
        csc_mul_columns(p, &values, &x, cols, &mut ys);
        csc_abs_mul_columns(p, &values, &x, cols, &mut yabs);
        for c in 0..cols {
            let xc = &x[c * n..(c + 1) * n];
            let mut reference = vec![0.0; n];
            p.mat_vec(&values, xc, &mut reference).unwrap();
            csc_mul(p, &values, xc, &mut y[c * n..(c + 1) * n]);
            // `mat_vec` reads the entries one by one in the same order; equal sums (`==`: a
            // skipped zero column and an added `0 · a` differ only in the sign of a zero).
            assert_eq!(
                &y[c * n..(c + 1) * n],
                &reference[..],
                "pattern {k} csc_mul"
            );
            assert_eq!(
                &ys[c * n..(c + 1) * n],
                &reference[..],
                "pattern {k} columns"
            );
            let xa: Vec<f64> = xc.iter().map(|v| v.abs()).collect();
            p.mat_vec(&abs_values, &xa, &mut reference).unwrap();
            assert_eq!(
                &yabs[c * n..(c + 1) * n],
                &reference[..],
                "pattern {k} |A||x|"
            );
        }
    }
}

#[test]
fn pattern_rejects_out_of_range_dof_naming_cell_and_index() {
    let err = SparsityPattern::from_cells(4, &[vec![0, 1], vec![2, 7, 1]]).unwrap_err();
    assert_eq!(
        err,
        SolverError::DofOutOfRange {
            cell: 1,
            local: 1,
            dof: 7,
            n_dofs: 4
        }
    );
    assert!(err.to_string().contains("cell 1") && err.to_string().contains('7'));
}

#[test]
fn lu_and_cholesky_match_dense_lu_on_random_sparse_matrices() {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let n = 80;
    let cells = random_cells(n, 60, &mut rng);
    let p = SparsityPattern::from_cells(n, &cells).unwrap();
    for (spd, method) in [
        (false, Method::Lu),
        (true, Method::Lu),
        (true, Method::Cholesky),
        (false, Method::DenseLu),
        (false, Method::SupernodalLu),
        (true, Method::SupernodalLu),
    ] {
        // The shift keeps cond(A) moderate (< 1e4 for these sizes), so the dense and sparse
        // solutions must agree to ~cond·ε ≈ 1e-12; the backward error of a stable factorisation
        // is a small multiple of ε independent of cond, hence the 1e-12 bound with margin.
        let values = random_values(&p, &mut rng, spd, 4.0);
        let b: Vec<f64> = (0..n).map(|_| rng.next()).collect();
        let mut solver = LinearSolver::new(&p, method, SolverOptions::default()).unwrap();
        solver.factorize(&values).unwrap();
        let mut x = b.clone();
        solver.solve_in_place(&mut x).unwrap();
        let dense = p.to_dense(&values);
        let xd = dense
            .clone()
            .lu()
            .solve(&DVector::from_vec(b.clone()))
            .unwrap();
        let diff = x
            .iter()
            .zip(xd.iter())
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        let be = backward_error(&p, &values, &x, &b);
        println!(
            "{method:?} spd={spd}: backward error {be:.2e}, |x - x_dense|/|x| {:.2e}",
            diff / norm(&x)
        );
        assert!(be < 1e-12, "{method:?}: backward error {be:e}");
        assert!(
            diff / norm(&x) < 1e-12,
            "{method:?}: differs from dense LU by {diff:e}"
        );
    }
}

#[test]
fn symbolic_reuse_equals_fresh_factorisation_bit_for_bit() {
    let mut rng = Rng(7);
    let n = 120;
    let p = SparsityPattern::from_cells(n, &random_cells(n, 100, &mut rng)).unwrap();
    let v1 = random_values(&p, &mut rng, false, 3.0);
    let v2 = random_values(&p, &mut rng, false, 3.0);
    let b: Vec<f64> = (0..n).map(|_| rng.next()).collect();
    for method in [
        Method::Lu,
        Method::Cholesky,
        Method::DenseLu,
        Method::SupernodalLu,
    ] {
        let (v1, v2) = if method == Method::Cholesky {
            (
                random_values(&p, &mut rng, true, 1.0),
                random_values(&p, &mut rng, true, 1.0),
            )
        } else {
            (v1.clone(), v2.clone())
        };
        let mut reused = LinearSolver::new(&p, method, SolverOptions::default()).unwrap();
        reused.factorize(&v1).unwrap();
        reused.factorize(&v2).unwrap();
        assert_eq!(reused.n_factorizations(), 2);
        let mut fresh = LinearSolver::new(&p, method, SolverOptions::default()).unwrap();
        fresh.factorize(&v2).unwrap();
        let (mut x1, mut x2) = (b.clone(), b.clone());
        reused.solve_in_place(&mut x1).unwrap();
        fresh.solve_in_place(&mut x2).unwrap();
        assert_eq!(x1, x2, "{method:?}");
    }
}

#[test]
fn auto_method_is_dense_only_for_nearly_full_patterns() {
    // A chain (3n − 2 of n² entries stored) stays sparse; 40 unknowns all coupled in one cell
    // are full (100 %); 40 unknowns in overlapping cells of 8 store
    // (n·(2·7+1) − 7·8) / n² ≈ 34 % ≥ DENSE_FILL (25 %), cells of 4 about 17 % < DENSE_FILL.
    let chain: Vec<Vec<usize>> = (0..39).map(|i| vec![i, i + 1]).collect();
    let p = SparsityPattern::from_cells(40, &chain).unwrap();
    assert_eq!(Method::auto(&p), Method::SupernodalLu);
    let full = SparsityPattern::from_cells(40, &[(0..40).collect::<Vec<_>>()]).unwrap();
    assert_eq!(Method::auto(&full), Method::DenseLu);
    let banded: Vec<Vec<usize>> = (0..33).map(|i| (i..i + 8).collect()).collect();
    let b = SparsityPattern::from_cells(40, &banded).unwrap();
    let fill = b.nnz() as f64 / 1600.0;
    assert!(fill >= Method::DENSE_FILL, "{fill}");
    assert_eq!(Method::auto(&b), Method::DenseLu);
    let narrow: Vec<Vec<usize>> = (0..37).map(|i| (i..i + 4).collect()).collect();
    let b = SparsityPattern::from_cells(40, &narrow).unwrap();
    let fill = b.nnz() as f64 / 1600.0;
    assert!(fill < Method::DENSE_FILL, "{fill}");
    assert_eq!(Method::auto(&b), Method::SupernodalLu);
}

#[test]
fn multi_rhs_equals_single_solves() {
    let mut rng = Rng(11);
    let n = 150;
    let p = SparsityPattern::from_cells(n, &random_cells(n, 150, &mut rng)).unwrap();
    let values = random_values(&p, &mut rng, false, 4.0);
    let k = 5;
    let b: Vec<f64> = (0..n * k).map(|_| rng.next()).collect();
    for (par, method) in [
        (Parallelism::Sequential, Method::Lu),
        (Parallelism::Rayon(0), Method::Lu),
        (Parallelism::Sequential, Method::DenseLu),
        (Parallelism::Rayon(0), Method::DenseLu),
    ] {
        let opts = SolverOptions {
            parallelism: par,
            ..Default::default()
        };
        let mut solver = LinearSolver::new(&p, method, opts).unwrap();
        solver.factorize(&values).unwrap();
        let mut multi = b.clone();
        solver.solve_columns_in_place(&mut multi, k).unwrap();
        let mut mat = faer::Mat::from_fn(n, k, |i, j| b[j * n + i]);
        solver.solve_multi_in_place(mat.as_mut()).unwrap();
        let mut worst = 0.0f64;
        for j in 0..k {
            let mut single = b[j * n..(j + 1) * n].to_vec();
            solver.solve_in_place(&mut single).unwrap();
            let s = norm(&single);
            for i in 0..n {
                worst = worst.max((single[i] - multi[j * n + i]).abs() / s);
                assert_eq!(mat[(i, j)], multi[j * n + i]);
            }
        }
        println!("{method:?} {par:?}: multi vs single max relative difference {worst:.2e}");
        // Blocked and single-column triangular solves may sum in a different order: allow a
        // few ulps relative to the solution norm.
        assert!(worst <= 1e-14, "{worst:e}");
    }
}

/// 1-D bar `−EA u'' = q` on [0, L], linear elements, `u(0) = 0`, `u(L) = uL`: linear elements
/// with consistent loads are nodally exact, so elimination must reproduce
/// `u(x) = q x (L − x) / (2 EA) + uL x / L` to round-off.
#[test]
fn dirichlet_elimination_gives_exact_bar_solution() {
    let (ne, len, ea, q, ul) = (6usize, 3.0, 2.5, 1.7, 0.3);
    let h = len / ne as f64;
    let cells: Vec<Vec<usize>> = (0..ne).map(|e| vec![e, e + 1]).collect();
    let p = SparsityPattern::from_cells(ne + 1, &cells).unwrap();
    let exact = |x: f64| q * x * (len - x) / (2.0 * ea) + ul * x / len;
    for method in [Method::Lu, Method::Cholesky] {
        let mut values = vec![0.0; p.nnz()];
        let mut f = vec![0.0; ne + 1];
        assemble(&p, &mut values, &mut f, Execution::Parallel, |_| {
            let k = DMatrix::from_row_slice(2, 2, &[1.0, -1.0, -1.0, 1.0]) * (ea / h);
            Ok::<_, Infallible>((k, DVector::from_element(2, q * h / 2.0)))
        })
        .unwrap();
        let bc = EssentialBc::new(ne + 1, &[(0, 0.0), (ne, ul)]).unwrap();
        bc.apply(&p, &mut values, &mut f).unwrap();
        // Symmetry is kept by the elimination.
        let d = p.to_dense(&values);
        assert_eq!(d, d.transpose());
        let mut solver = LinearSolver::new(&p, method, SolverOptions::default()).unwrap();
        solver.factorize(&values).unwrap();
        solver.solve_in_place(&mut f).unwrap();
        for (i, u) in f.iter().enumerate() {
            let ue = exact(i as f64 * h);
            // Round-off of a 7-unknown solve: a few ε relative to the largest value (~0.9).
            assert!((u - ue).abs() <= 1e-14, "{method:?} node {i}: {u} vs {ue}");
        }
        assert_eq!(f[ne], ul);
    }
}

#[test]
fn serial_and_parallel_assembly_are_bit_identical() {
    // 40×40 grid of 2-DOF nodes, cells = 3×3 node blocks (18 DOFs), 1444 cells: several batches.
    let nn = 40;
    let node = |i: usize, j: usize| i * nn + j;
    let mut cells = Vec::new();
    for i in 0..nn - 2 {
        for j in 0..nn - 2 {
            let mut dofs = Vec::new();
            for a in 0..3 {
                for b in 0..3 {
                    let nd = node(i + a, j + b);
                    dofs.extend([2 * nd, 2 * nd + 1]);
                }
            }
            cells.push(dofs);
        }
    }
    let p = SparsityPattern::from_cells(2 * nn * nn, &cells).unwrap();
    let local = |c: usize| {
        let m = p.cell_dofs(c).len();
        let x = c as f64 * 0.37;
        let k = DMatrix::from_fn(m, m, |i, j| {
            (x + i as f64 * 1.3 - j as f64 * 0.7).sin() / 3.0
        });
        let f = DVector::from_fn(m, |i, _| (x * 1.1 + i as f64).cos() / 7.0);
        Ok::<_, Infallible>((k, f))
    };
    let (mut v1, mut f1) = (vec![0.0; p.nnz()], vec![0.0; p.n_dofs()]);
    let (mut v2, mut f2) = (vec![1.0; p.nnz()], vec![1.0; p.n_dofs()]);
    assemble(&p, &mut v1, &mut f1, Execution::Serial, local).unwrap();
    assemble(&p, &mut v2, &mut f2, Execution::Parallel, local).unwrap();
    assert!(v1.iter().zip(&v2).all(|(a, b)| a.to_bits() == b.to_bits()));
    assert!(f1.iter().zip(&f2).all(|(a, b)| a.to_bits() == b.to_bits()));
    let mut r2 = vec![0.0; p.n_dofs()];
    assemble_vector(&p, &mut r2, Execution::Parallel, |c| {
        local(c).map(|(_, f)| f)
    })
    .unwrap();
    assert!(f1.iter().zip(&r2).all(|(a, b)| a.to_bits() == b.to_bits()));
}

#[test]
fn assembly_reports_lowest_failing_cell_and_bad_shapes() {
    let cells: Vec<Vec<usize>> = (0..500).map(|e| vec![e, e + 1]).collect();
    let p = SparsityPattern::from_cells(501, &cells).unwrap();
    let (mut v, mut f) = (vec![0.0; p.nnz()], vec![0.0; 501]);
    for exec in [Execution::Serial, Execution::Parallel] {
        let err = assemble(&p, &mut v, &mut f, exec, |c| {
            if c == 317 || c == 420 {
                Err(format!("inverted cell {c}"))
            } else {
                Ok((DMatrix::identity(2, 2), DVector::zeros(2)))
            }
        })
        .unwrap_err();
        assert_eq!(
            err,
            AssemblyError::Cell {
                cell: 317,
                source: "inverted cell 317".to_string()
            }
        );
        let err = assemble(&p, &mut v, &mut f, exec, |c| {
            Ok::<_, Infallible>((
                DMatrix::identity(2 + usize::from(c == 9), 2),
                DVector::zeros(2),
            ))
        })
        .unwrap_err();
        assert!(
            matches!(err, AssemblyError::Shape { cell: 9, .. }),
            "{err:?}"
        );
    }
}

#[test]
fn singular_and_non_finite_matrices_are_errors_not_panics() {
    let cells: Vec<Vec<usize>> = (0..5).map(|e| vec![e, e + 1]).collect();
    let p = SparsityPattern::from_cells(6, &cells).unwrap();
    let spring = |values: &mut Vec<f64>, skip: Option<usize>| {
        let mut f = vec![0.0; 6];
        assemble(&p, values, &mut f, Execution::Serial, |c| {
            let s = if Some(c) == skip { 0.0 } else { 1.0 };
            Ok::<_, Infallible>((
                DMatrix::from_row_slice(2, 2, &[s, -s, -s, s]),
                DVector::zeros(2),
            ))
        })
        .unwrap();
    };
    let mut solver = LinearSolver::new(&p, Method::Lu, SolverOptions::default()).unwrap();
    // Free-floating chain of springs: rank deficient (rigid translation), no zero row.
    let mut values = vec![0.0; p.nnz()];
    spring(&mut values, None);
    let err = solver.factorize(&values).unwrap_err();
    println!("{err}");
    assert!(
        matches!(err, SolverError::Singular { dof: Some(_), .. }),
        "{err:?}"
    );
    // The dense LU divides by the round-off pivot too: the probe catches it.
    let mut dense = LinearSolver::new(&p, Method::DenseLu, SolverOptions::default()).unwrap();
    let err = dense.factorize(&values).unwrap_err();
    println!("dense: {err}");
    assert!(matches!(err, SolverError::Singular { .. }), "{err:?}");
    assert!(!dense.is_factorized());
    assert!(!solver.is_factorized());
    assert_eq!(
        solver.solve_in_place(&mut [0.0; 6]),
        Err(SolverError::NotFactorized)
    );
    // Supported at DOF 0 but spring 5 missing: DOF 5 has an identically zero column.
    spring(&mut values, Some(4));
    values[p.diag_slot(0)] += 1.0;
    let err = solver.factorize(&values).unwrap_err();
    assert_eq!(
        err,
        SolverError::Singular {
            dof: Some(5),
            detail: "column 5 is identically zero".into()
        }
    );
    // NaN entry, named by position.
    spring(&mut values, None);
    values[p.slot(3, 2).unwrap()] = f64::NAN;
    let err = solver.factorize(&values).unwrap_err();
    assert!(
        matches!(err, SolverError::NonFiniteMatrix { row: 3, col: 2, .. }),
        "{err:?}"
    );
    // Cholesky of an indefinite matrix names the DOF with the non-positive pivot: supported
    // chain (SPD) with DOF 3 decoupled and given a negative diagonal (DOFs 4, 5 are then held
    // by an extra diagonal at 5). Whatever the fill-reducing order, the failing pivot is DOF 3,
    // which checks the mapping from the permuted elimination step back to the DOF.
    let mut solver = LinearSolver::new(&p, Method::Cholesky, SolverOptions::default()).unwrap();
    spring(&mut values, None);
    values[p.diag_slot(0)] += 1.0;
    solver.factorize(&values).unwrap();
    for (r, c) in [(2, 3), (3, 2), (3, 4), (4, 3)] {
        values[p.slot(r, c).unwrap()] = 0.0;
    }
    values[p.diag_slot(2)] -= 1.0;
    values[p.diag_slot(4)] -= 1.0;
    values[p.diag_slot(5)] += 1.0;
    values[p.diag_slot(3)] = -5.0;
    let err = solver.factorize(&values).unwrap_err();
    println!("{err}");
    assert!(
        matches!(err, SolverError::NotPositiveDefinite { dof: 3, .. }),
        "{err:?}"
    );
    // Non-finite right-hand side.
    let mut solver = LinearSolver::new(&p, Method::Lu, SolverOptions::default()).unwrap();
    spring(&mut values, None);
    values[p.diag_slot(0)] += 1.0;
    solver.factorize(&values).unwrap();
    let mut b = [0.0, 1.0, f64::INFINITY, 0.0, 0.0, 0.0];
    assert!(matches!(
        solver.solve_in_place(&mut b),
        Err(SolverError::NonFiniteRhs { rhs: 0, row: 2, .. })
    ));
}

// ---------------------------------------------------------------------------------------------
// Newton driver on a chain of nonlinear springs.

/// `n` springs in series, DOF 0 fixed, load `λ P` at the last DOF (or, with `displacement`,
/// the last DOF prescribed to `λ δ`). Spring `s` has force `f = k_s (a atan e + β e + c e³)` in
/// its elongation `e = u_{s+1} − u_s`, `k_s = 1 + 0.1 s`. With `a = 1, c = 0` it softens, with a
/// limit load `k_0 π/2 = π/2` when `β = 0`; with `a = 0, c > 0` it stiffens and a large load
/// step overshoots. An elongation beyond `e_limit` is reported as a recoverable error (like a
/// return map refusing a too large strain increment). History: the largest elongation of each
/// spring (explicit trial and committed copies) — it does not change the forces but tests
/// commit/restore.
struct SpringChain {
    n: usize,
    a: f64,
    beta: f64,
    c: f64,
    e_limit: f64,
    load: f64,
    displacement: Option<f64>,
    pattern: SparsityPattern,
    committed_max: Vec<f64>,
    trial_max: Vec<f64>,
    commits: usize,
    restores: usize,
}

impl SpringChain {
    fn new(n: usize, beta: f64, load: f64, displacement: Option<f64>) -> Self {
        let cells: Vec<Vec<usize>> = (0..n).map(|s| vec![s, s + 1]).collect();
        Self {
            n,
            a: 1.0,
            beta,
            c: 0.0,
            e_limit: f64::INFINITY,
            load,
            displacement,
            pattern: SparsityPattern::from_cells(n + 1, &cells).unwrap(),
            committed_max: vec![0.0; n],
            trial_max: vec![0.0; n],
            commits: 0,
            restores: 0,
        }
    }
    fn k(s: usize) -> f64 {
        1.0 + 0.1 * s as f64
    }
    fn eval(
        &mut self,
        u: &[f64],
        lam: f64,
        r: &mut [f64],
        values: Option<&mut [f64]>,
    ) -> Result<(), ProblemError> {
        let (a, beta, c) = (self.a, self.beta, self.c);
        if let Some(s) = (0..self.n).find(|&s| (u[s + 1] - u[s]).abs() > self.e_limit) {
            return Err(ProblemError::Recoverable(format!(
                "spring {s} overstretched: e = {:.3}",
                u[s + 1] - u[s]
            )));
        }
        let local = |s: usize| {
            let e = u[s + 1] - u[s];
            let f = Self::k(s) * (a * e.atan() + beta * e + c * e * e * e);
            let kt = Self::k(s) * (a / (1.0 + e * e) + beta + 3.0 * c * e * e);
            Ok::<_, Infallible>((
                DMatrix::from_row_slice(2, 2, &[kt, -kt, -kt, kt]),
                DVector::from_row_slice(&[-f, f]),
            ))
        };
        match values {
            Some(v) => assemble(&self.pattern, v, r, Execution::Parallel, local).unwrap(),
            None => assemble_vector(&self.pattern, r, Execution::Parallel, |s| {
                local(s).map(|(_, f)| f)
            })
            .unwrap(),
        }
        if self.displacement.is_none() {
            r[self.n] -= lam * self.load;
        }
        for s in 0..self.n {
            self.trial_max[s] = self.committed_max[s].max(u[s + 1] - u[s]);
        }
        Ok(())
    }
}

impl NonlinearProblem for SpringChain {
    fn n_dofs(&self) -> usize {
        self.n + 1
    }
    fn residual(&mut self, u: &[f64], lam: f64, r: &mut [f64]) -> Result<(), ProblemError> {
        self.eval(u, lam, r, None)
    }
    fn tangent(&mut self, u: &[f64], lam: f64, values: &mut [f64]) -> Result<(), ProblemError> {
        let mut r = vec![0.0; self.n + 1];
        self.eval(u, lam, &mut r, Some(values))
    }
    fn residual_and_tangent(
        &mut self,
        u: &[f64],
        lam: f64,
        r: &mut [f64],
        values: &mut [f64],
    ) -> Result<(), ProblemError> {
        self.eval(u, lam, r, Some(values))
    }
    fn essential(&self, lam: f64) -> Vec<(usize, f64)> {
        match self.displacement {
            Some(d) => vec![(0, 0.0), (self.n, lam * d)],
            None => vec![(0, 0.0)],
        }
    }
    fn force_norm(&self, lam: f64) -> f64 {
        lam.abs() * self.load
    }
    fn commit(&mut self, _u: &[f64], _lam: f64) {
        self.committed_max.clone_from(&self.trial_max);
        self.commits += 1;
    }
    fn restore(&mut self) {
        self.trial_max.clone_from(&self.committed_max);
        self.restores += 1;
    }
}

/// Observed order `ln(r_{k+1}/r_k) / ln(r_k/r_{k−1})` of the last triple above the round-off
/// floor.
fn last_rate(res: &[f64], floor: f64) -> Option<f64> {
    let r: Vec<f64> = res.iter().copied().filter(|&x| x > floor).collect();
    (r.len() >= 3).then(|| {
        let k = r.len() - 2;
        (r[k + 1] / r[k]).ln() / (r[k] / r[k - 1]).ln()
    })
}

#[test]
fn newton_converges_quadratically_under_load_and_displacement_control() {
    for displacement in [None, Some(12.0)] {
        let mut prob = SpringChain::new(10, 0.05, 2.0, displacement);
        let pattern = prob.pattern.clone();
        let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
        let newton = NewtonSolver {
            options: NewtonOptions {
                residual_rtol: 1e-12,
                ..Default::default()
            },
            stepping: LoadStepping {
                initial_step: 0.25,
                ..Default::default()
            },
        };
        let mut seen = 0;
        let report = newton
            .run_with_progress(&mut prob, &pattern, &mut solver, &[0.0; 11], |_| seen += 1)
            .unwrap();
        assert_eq!(report.load, 1.0);
        assert_eq!(seen, report.converged_steps().count());
        assert_eq!(prob.commits, seen);
        // Equilibrium: every spring carries the same force (the end load in load control).
        let u = &report.u;
        let forces: Vec<f64> = (0..10)
            .map(|s| {
                let e = u[s + 1] - u[s];
                SpringChain::k(s) * (e.atan() + 0.05 * e)
            })
            .collect();
        let fref = displacement.map_or(2.0, |_| forces[0]);
        for f in &forces {
            assert!((f - fref).abs() <= 1e-10 * fref, "{forces:?}");
        }
        let mut rates = Vec::new();
        for st in report.converged_steps() {
            // Residuals below ~1e-13 of the step's reference are round-off (ε times the
            // internal forces, O(1) here), where the order can no longer be observed.
            let floor = 1e-13 * st.residual_norms[0].max(2.0 * st.load);
            if let Some(p) = last_rate(&st.residual_norms, floor) {
                rates.push(p);
            }
            println!(
                "{displacement:?} λ={:.4} it={} r={:?}",
                st.load,
                st.iterations,
                st.residual_norms
                    .iter()
                    .map(|r| format!("{r:.2e}"))
                    .collect::<Vec<_>>()
            );
        }
        println!("observed rates {rates:.3?}");
        assert!(!rates.is_empty());
        assert!(rates.iter().all(|&p| p >= 1.8), "{rates:?}");
    }
}

#[test]
fn step_cutting_recovers_from_a_too_large_step() {
    // Stiffening springs f = k (e + e³), end load 20: the full step's linear predictor
    // stretches the first spring to e ≈ 19, beyond e_limit = 4 (recoverable error); the root is
    // e ≈ 2.6. Halved steps get there, then the step grows again after easy steps.
    let mut prob = SpringChain::new(10, 1.0, 20.0, None);
    prob.a = 0.0;
    prob.c = 1.0;
    prob.e_limit = 4.0;
    let pattern = prob.pattern.clone();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    // The cut is under test: without the line search (which backtracks instead of cutting).
    let newton = NewtonSolver {
        options: NewtonOptions {
            line_search: LineSearch::Off,
            ..Default::default()
        },
        stepping: LoadStepping {
            initial_step: 1.0,
            ..Default::default()
        },
    };
    let report = newton
        .run(&mut prob, &pattern, &mut solver, &[0.0; 11])
        .unwrap();
    let failed = report.attempts.iter().filter(|s| !s.converged).count();
    println!(
        "{} attempts, {failed} failed: {:?}",
        report.attempts.len(),
        report
            .attempts
            .iter()
            .map(|s| (s.load, s.converged, s.iterations))
            .collect::<Vec<_>>()
    );
    assert!(!report.attempts[0].converged, "the full step should fail");
    assert!(matches!(
        report.attempts[0].failure,
        Some(FailureReason::Problem(ProblemError::Recoverable(_)))
    ));
    // After the cuts the step grew again: some converged step is larger than the first one.
    let sizes: Vec<f64> = report.converged_steps().map(|s| s.step_size).collect();
    assert!(sizes.iter().any(|&h| h > sizes[0]), "{sizes:?}");
    assert_eq!(report.load, 1.0);
    assert_eq!(prob.restores, failed);
    assert_eq!(prob.commits, report.converged_steps().count());
    // History committed only from converged states: the largest elongation equals the final one
    // (monotonic loading), not an overshooting trial iterate.
    for s in 0..10 {
        let e = report.u[s + 1] - report.u[s];
        assert!(
            (prob.committed_max[s] - e).abs() <= 1e-12 * e.abs(),
            "spring {s}"
        );
    }
}

#[test]
fn failure_beyond_the_limit_load_reports_level_and_keeps_converged_steps() {
    // β = 0: the chain cannot carry more than π/2; the load 2λ fails at λ = π/4.
    let mut prob = SpringChain::new(10, 0.0, 2.0, None);
    let pattern = prob.pattern.clone();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    let newton = NewtonSolver {
        options: NewtonOptions::default(),
        stepping: LoadStepping {
            initial_step: 0.1,
            min_step: 1e-4,
            ..Default::default()
        },
    };
    let fail = newton
        .run(&mut prob, &pattern, &mut solver, &[0.0; 11])
        .unwrap_err();
    let msg = fail.to_string();
    println!("{msg}");
    let limit = std::f64::consts::FRAC_PI_4;
    assert!(fail.converged_load < limit && fail.converged_load > limit - 1e-3);
    assert!(fail.attempted_load > fail.converged_load);
    assert!(fail.step_size < 2e-4);
    assert!(!fail.last_residuals.is_empty());
    assert!(msg.contains("Newton stopped at load factor") && msg.contains("residual norms"));
    assert_eq!(fail.report.load, fail.converged_load);
    let steps: Vec<_> = fail.report.converged_steps().collect();
    assert!(steps.len() >= 7);
    assert_eq!(steps.last().unwrap().load, fail.converged_load);
    assert_eq!(prob.commits, steps.len());
    // The kept state is the converged one at that load.
    let e0 = fail.report.u[1] - fail.report.u[0];
    assert!((e0.atan() - 2.0 * fail.converged_load).abs() < 1e-9);
}

#[test]
fn converged_hook_sees_factorised_tangent_for_sensitivity_solves() {
    // d u / d λ at a converged state solves K u' = f_ext (= ∂r/∂λ with a sign): check it against
    // a finite difference of two converged states.
    struct Hooked(SpringChain, Vec<(f64, Vec<f64>, Vec<f64>)>);
    impl NonlinearProblem for Hooked {
        fn n_dofs(&self) -> usize {
            self.0.n_dofs()
        }
        fn residual(&mut self, u: &[f64], l: f64, r: &mut [f64]) -> Result<(), ProblemError> {
            self.0.residual(u, l, r)
        }
        fn tangent(&mut self, u: &[f64], l: f64, v: &mut [f64]) -> Result<(), ProblemError> {
            self.0.tangent(u, l, v)
        }
        fn essential(&self, l: f64) -> Vec<(usize, f64)> {
            self.0.essential(l)
        }
        fn force_norm(&self, l: f64) -> f64 {
            self.0.force_norm(l)
        }
        fn on_converged(&mut self, s: &ConvergedStep<'_>) -> Result<(), ProblemError> {
            let n = s.u.len();
            let mut rhs = vec![0.0; 2 * n];
            rhs[n - 1] = self.0.load; // column 0: ∂u/∂λ
            rhs[2 * n - 1] = 1.0; // column 1: ∂u/∂P / λ
            s.essential.zero_constrained(&mut rhs[..n]);
            s.solver.solve_columns_in_place(&mut rhs, 2).unwrap();
            self.1.push((s.load, s.u.to_vec(), rhs[..n].to_vec()));
            Ok(())
        }
        fn commit(&mut self, u: &[f64], l: f64) {
            self.0.commit(u, l)
        }
        fn restore(&mut self) {
            self.0.restore()
        }
    }
    let mut prob = Hooked(SpringChain::new(6, 0.05, 2.0, None), Vec::new());
    let pattern = prob.0.pattern.clone();
    let mut solver =
        LinearSolver::new(&pattern, Method::Cholesky, SolverOptions::default()).unwrap();
    let newton = NewtonSolver {
        options: NewtonOptions {
            residual_rtol: 1e-13,
            ..Default::default()
        },
        stepping: LoadStepping {
            initial_step: 0.01,
            max_step: 0.01,
            end: 0.5,
            ..Default::default()
        },
    };
    newton
        .run(&mut prob, &pattern, &mut solver, &[0.0; 7])
        .unwrap();
    let h = &prob.1;
    let (a, b, c) = (&h[h.len() - 3], &h[h.len() - 2], &h[h.len() - 1]);
    for i in 0..7 {
        // Central difference over Δλ = 0.01: truncation O(Δλ² u''') ≈ 1e-4 relative here.
        let fd = (c.1[i] - a.1[i]) / (c.0 - a.0);
        assert!(
            (fd - b.2[i]).abs() <= 1e-3 * b.2[6].abs(),
            "{i}: {fd} vs {}",
            b.2[i]
        );
    }
}

#[test]
fn cholesky_names_the_failing_dof_on_a_large_supernodal_sized_system() {
    // 25×25 nodes × 3 DOFs with 3×3-node cells: large and dense enough for faer's supernodal
    // Cholesky (the small test above runs the simplicial kernel; faer numbers the failing pivot
    // differently in the two, 1-based vs 0-based).
    let nn = 25;
    let mut cells = Vec::new();
    for i in 0..nn - 2 {
        for j in 0..nn - 2 {
            let mut dofs = Vec::new();
            for a in 0..3 {
                for b in 0..3 {
                    let nd = (i + a) * nn + j + b;
                    dofs.extend([3 * nd, 3 * nd + 1, 3 * nd + 2]);
                }
            }
            cells.push(dofs);
        }
    }
    let p = SparsityPattern::from_cells(3 * nn * nn, &cells).unwrap();
    let mut rng = Rng(3);
    let values = random_values(&p, &mut rng, true, 1.0);
    let mut solver = LinearSolver::new(&p, Method::Cholesky, SolverOptions::default()).unwrap();
    solver.factorize(&values).unwrap();
    // Decouple DOF k (the rest is a principal submatrix of an SPD matrix, still SPD) and make
    // its diagonal negative.
    for k in [0, 1000, 3 * nn * nn - 1] {
        let mut v = values.clone();
        for (j, w) in
            (0..p.n_dofs()).flat_map(|j| (p.col_ptr()[j]..p.col_ptr()[j + 1]).map(move |q| (j, q)))
        {
            let i = p.row_idx()[w];
            if (i == k || j == k) && i != j {
                v[w] = 0.0;
            }
        }
        v[p.diag_slot(k)] = -1.0;
        let err = solver.factorize(&v).unwrap_err();
        assert!(
            matches!(err, SolverError::NotPositiveDefinite { dof, .. } if dof == k),
            "{k}: {err:?}"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Predictor and stopping tests of the driver.

fn steps_summary(report: &NewtonReport) -> Vec<(f64, Predictor, usize, Option<Acceptance>)> {
    report
        .converged_steps()
        .map(|s| (s.load, s.predictor, s.iterations, s.acceptance))
        .collect()
}

#[test]
fn secant_predictor_is_exact_on_a_linear_path_even_when_steps_grow() {
    // Linear springs (a = 0, β = 1, c = 0): u(λ) is linear in λ, so the previous increment
    // scaled by Δλ/Δλ_prev is the exact solution of the next step (to round-off), whatever the
    // step sizes. The zero predictor needs one Newton update per step.
    for predictor in [Predictor::Secant, Predictor::Zero] {
        let mut prob = SpringChain::new(8, 1.0, 3.0, None);
        prob.a = 0.0;
        let pattern = prob.pattern.clone();
        let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
        let newton = NewtonSolver {
            options: NewtonOptions::default(),
            stepping: LoadStepping {
                initial_step: 0.05,
                grow_factor: 1.7,
                predictor,
                ..Default::default()
            },
        };
        let report = newton
            .run(&mut prob, &pattern, &mut solver, &[0.0; 9])
            .unwrap();
        let steps = steps_summary(&report);
        println!("{predictor:?}: {steps:?}");
        let sizes: Vec<f64> = report.converged_steps().map(|s| s.step_size).collect();
        assert!(sizes.windows(2).any(|w| w[1] > 1.5 * w[0]), "{sizes:?}");
        assert_eq!(steps[0].1, Predictor::Zero, "no previous increment");
        assert_eq!(steps[0].2, 1);
        for &(load, p, its, acc) in &steps[1..] {
            assert_eq!(p, predictor);
            match predictor {
                Predictor::Secant => {
                    assert_eq!(its, 0, "λ = {load}: the prediction is the solution");
                    assert!(acc.is_some());
                }
                Predictor::Zero => assert_eq!(its, 1, "λ = {load}"),
                Predictor::Quadratic => unreachable!("not in this loop"),
            }
        }
        // u_N = λ P / k_s summed: exact for linear springs.
        let exact: f64 = (0..8).map(|s| 3.0 / SpringChain::k(s)).sum();
        assert!((report.u[8] - exact).abs() <= 1e-13 * exact);
    }
}

/// Newton updates over 20 equal steps of the softening chain near its limit load (tolerance
/// 1e-12) with `predictor`.
fn softening_chain_iterations(predictor: Predictor) -> usize {
    let mut prob = SpringChain::new(10, 0.05, 2.0, None);
    let pattern = prob.pattern.clone();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    let newton = NewtonSolver {
        options: NewtonOptions {
            residual_rtol: 1e-12,
            ..Default::default()
        },
        stepping: LoadStepping {
            initial_step: 0.05,
            max_step: 0.05,
            predictor,
            ..Default::default()
        },
    };
    let report = newton
        .run(&mut prob, &pattern, &mut solver, &[0.0; 11])
        .unwrap();
    let total: usize = report.converged_steps().map(|s| s.iterations).sum();
    println!("{predictor:?}: {total} iterations in 20 steps");
    total
}

#[test]
fn secant_predictor_saves_iterations_on_a_softening_chain() {
    // Softening springs near their limit load: the path bends, the secant prediction is not
    // exact, but it starts each step closer than the committed state does.
    let totals = [Predictor::Zero, Predictor::Secant].map(softening_chain_iterations);
    assert!(totals[1] < totals[0], "{totals:?}");
}

/// Uncoupled linear springs under a load growing as `λ²`: `r_i = k_i u_i − λ² f_i`, so the
/// path `u(λ) = λ² f/k` is a parabola (the tangent is `k`, independent of `λ`).
struct ParabolicPath {
    pattern: SparsityPattern,
    tangents: usize,
    residuals: usize,
}

impl ParabolicPath {
    const N: usize = 3;
    fn new() -> Self {
        let cells: Vec<Vec<usize>> = (0..Self::N).map(|i| vec![i]).collect();
        ParabolicPath {
            pattern: SparsityPattern::from_cells(Self::N, &cells).unwrap(),
            tangents: 0,
            residuals: 0,
        }
    }
    fn k(i: usize) -> f64 {
        1.0 + i as f64
    }
    fn f(i: usize) -> f64 {
        2.0 - 0.5 * i as f64
    }
}

impl NonlinearProblem for ParabolicPath {
    fn n_dofs(&self) -> usize {
        Self::N
    }
    fn residual(&mut self, u: &[f64], lam: f64, r: &mut [f64]) -> Result<(), ProblemError> {
        self.residuals += 1;
        for (i, ri) in r.iter_mut().enumerate() {
            *ri = Self::k(i) * u[i] - lam * lam * Self::f(i);
        }
        Ok(())
    }
    fn tangent(&mut self, _u: &[f64], _lam: f64, values: &mut [f64]) -> Result<(), ProblemError> {
        self.tangents += 1;
        for (i, v) in values.iter_mut().enumerate() {
            *v = Self::k(i); // one entry per column: the diagonal
        }
        Ok(())
    }
    fn force_norm(&self, lam: f64) -> f64 {
        lam * lam * (0..Self::N).map(|i| Self::f(i).powi(2)).sum::<f64>().sqrt()
    }
    fn commit(&mut self, _u: &[f64], _lam: f64) {}
    fn restore(&mut self) {}
}

#[test]
fn quadratic_predictor_is_exact_on_a_parabolic_path() {
    // u(λ) = λ² f/k: three converged states determine the parabola, so from the third step on
    // the quadratic extrapolation is the solution to round-off (0 Newton updates), while the
    // secant's error is (Δλ)² f/k and needs one update per step. Unequal steps (growth 1.7).
    for predictor in [Predictor::Quadratic, Predictor::Secant] {
        let mut prob = ParabolicPath::new();
        let pattern = prob.pattern.clone();
        let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
        let newton = NewtonSolver {
            options: NewtonOptions::default(),
            stepping: LoadStepping {
                initial_step: 0.05,
                grow_factor: 1.7,
                predictor,
                ..Default::default()
            },
        };
        let report = newton
            .run(&mut prob, &pattern, &mut solver, &[0.0; 3])
            .unwrap();
        let steps = steps_summary(&report);
        println!("{predictor:?}: {steps:?}");
        assert!(steps.len() >= 4, "{steps:?}");
        assert_eq!(steps[0].1, Predictor::Zero, "no previous increment");
        assert_eq!(steps[1].1, Predictor::Secant, "one previous increment");
        for &(load, p, its, _) in &steps[2..] {
            assert_eq!(p, predictor, "λ = {load}");
            let expected = if predictor == Predictor::Quadratic {
                0
            } else {
                1
            };
            assert_eq!(its, expected, "λ = {load}");
        }
        for i in 0..3 {
            let exact = ParabolicPath::f(i) / ParabolicPath::k(i);
            assert!((report.u[i] - exact).abs() <= 1e-13 * exact, "{i}");
        }
    }
}

#[test]
fn quadratic_predictor_saves_iterations_on_a_softening_chain() {
    // The softening chain of the secant test, equal steps: the quadratic extrapolation's error
    // is third order in the step, the secant's second order.
    let totals = [Predictor::Secant, Predictor::Quadratic].map(softening_chain_iterations);
    assert!(totals[1] < totals[0], "{totals:?}");
}

/// [`SpringChain`] with a given converged-tangent policy, counting tangent assemblies and
/// recording what the convergence hook saw.
struct Counting {
    chain: SpringChain,
    policy: ConvergedTangent,
    tangents: usize,
    hooks: Vec<FactorisedAt>,
    /// Per hook that was handed the converged tangent's values (`ConvergedTangent::Assembled`):
    /// the largest difference from the tangent evaluated afresh at the step's unknowns, with
    /// the essential conditions eliminated.
    handed: Vec<f64>,
}

impl NonlinearProblem for Counting {
    fn n_dofs(&self) -> usize {
        self.chain.n_dofs()
    }
    fn residual(&mut self, u: &[f64], l: f64, r: &mut [f64]) -> Result<(), ProblemError> {
        self.chain.residual(u, l, r)
    }
    fn tangent(&mut self, u: &[f64], l: f64, v: &mut [f64]) -> Result<(), ProblemError> {
        self.tangents += 1;
        self.chain.tangent(u, l, v)
    }
    fn residual_and_tangent(
        &mut self,
        u: &[f64],
        l: f64,
        r: &mut [f64],
        v: &mut [f64],
    ) -> Result<(), ProblemError> {
        self.tangents += 1;
        self.chain.residual_and_tangent(u, l, r, v)
    }
    fn essential(&self, l: f64) -> Vec<(usize, f64)> {
        self.chain.essential(l)
    }
    fn force_norm(&self, l: f64) -> f64 {
        self.chain.force_norm(l)
    }
    fn converged_tangent(&self) -> ConvergedTangent {
        self.policy
    }
    fn on_converged(&mut self, s: &ConvergedStep<'_>) -> Result<(), ProblemError> {
        self.hooks.push(s.factorised_at);
        if let Some((pattern, values)) = s.tangent {
            let mut v = vec![0.0; pattern.nnz()];
            self.chain.tangent(s.u, s.load, &mut v)?;
            let mut rhs = vec![0.0; s.u.len()];
            let zeros = vec![0.0; s.essential.dofs().len()];
            s.essential
                .apply_with(pattern, &mut v, &mut rhs, &zeros)
                .unwrap();
            let diff = v
                .iter()
                .zip(values)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            self.handed.push(diff);
        }
        Ok(())
    }
    fn commit(&mut self, u: &[f64], l: f64) {
        self.chain.commit(u, l)
    }
    fn restore(&mut self) {
        self.chain.restore()
    }
}

/// The driver of the residual-first tests: default options, steps of 0.1.
fn steps_of_a_tenth() -> NewtonSolver {
    NewtonSolver {
        options: NewtonOptions::default(),
        stepping: LoadStepping {
            initial_step: 0.1,
            max_step: 0.1,
            ..Default::default()
        },
    }
}

/// The softening chain run by `newton` under the converged-tangent `policy`: the report, the
/// problem (its counts and what its hook saw) and the number of factorisations.
fn run_counting(
    policy: ConvergedTangent,
    newton: &NewtonSolver,
) -> (NewtonReport, Counting, usize) {
    let chain = SpringChain::new(10, 0.05, 2.0, None);
    let pattern = chain.pattern.clone();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    let mut prob = Counting {
        chain,
        policy,
        tangents: 0,
        hooks: Vec::new(),
        handed: Vec::new(),
    };
    let report = newton
        .run(&mut prob, &pattern, &mut solver, &[0.0; 11])
        .unwrap();
    (report, prob, solver.n_factorizations())
}

#[test]
fn residual_first_acceptance_saves_tangents_and_keeps_the_converged_states() {
    // The same softening chain twice: with the default (converged tangent required) every
    // accepted iterate has its tangent assembled and factorised; declaring `NotNeeded` lets the
    // driver accept from the residual alone once quadratic contraction predicts convergence.
    // Both must accept the same iterates (the same Newton sequence, so the same unknowns to
    // the bit), with fewer tangents in the second run.
    let run = |not_needed: bool| {
        let policy = if not_needed {
            ConvergedTangent::NotNeeded
        } else {
            ConvergedTangent::Required
        };
        let (report, prob, _) = run_counting(policy, &steps_of_a_tenth());
        (report, prob.tangents, prob.hooks)
    };
    let (full, t_full, h_full) = run(false);
    let (first, t_first, h_first) = run(true);
    println!("tangents: {t_full} (required) vs {t_first} (not needed); hooks {h_first:?}");
    assert!(h_full.iter().all(|&f| f == FactorisedAt::Converged));
    let saved = h_first
        .iter()
        .filter(|&&f| f == FactorisedAt::PreviousIterate)
        .count();
    assert!(saved > 0, "{h_first:?}");
    assert_eq!(
        t_full - t_first,
        saved,
        "one tangent saved per residual-first step"
    );
    assert_eq!(full.u, first.u, "the same accepted iterates");
    let its = |r: &NewtonReport| {
        r.converged_steps()
            .map(|s| s.iterations)
            .collect::<Vec<_>>()
    };
    assert_eq!(its(&full), its(&first));
    for s in first.converged_steps() {
        let accepted_only = s.factorised_at == Some(FactorisedAt::PreviousIterate);
        assert_eq!(
            accepted_only,
            s.residual_only.last().map(|&(k, _)| k) == Some(s.residual_norms.len() - 1),
            "{s:?}"
        );
    }
}

#[test]
fn assembled_tangent_acceptance_hands_the_hook_the_converged_tangent() {
    // The softening chain of the residual-first test under the three policies. `Assembled`
    // tests convergence as `NotNeeded` does (the same accepted iterates, to the bit) but
    // evaluates the tangent with the residual there: as many tangents as `Required`, and one
    // factorisation fewer per step accepted on the previous iterate's, whose hook receives the
    // converged tangent's values (equal to a fresh evaluation at the accepted unknowns).
    let newton = steps_of_a_tenth();
    let (full, p_full, f_full) = run_counting(ConvergedTangent::Required, &newton);
    let (plain, _, _) = run_counting(ConvergedTangent::NotNeeded, &newton);
    let (asm, p_asm, f_asm) = run_counting(ConvergedTangent::Assembled, &newton);
    let saved = p_asm
        .hooks
        .iter()
        .filter(|&&f| f == FactorisedAt::PreviousIterate)
        .count();
    println!(
        "tangents {} / {} (required / assembled); factorisations {f_full} / {f_asm}; {saved} \
         steps handed the converged tangent, largest difference {:e}",
        p_full.tangents,
        p_asm.tangents,
        p_asm.handed.iter().fold(0.0f64, |m, &d| m.max(d))
    );
    assert!(saved > 0);
    assert_eq!(
        asm.u, plain.u,
        "the same accepted iterates as residual-first"
    );
    assert_eq!(asm.u, full.u);
    assert_eq!(
        p_asm.tangents, p_full.tangents,
        "no evaluation twice, none saved"
    );
    assert_eq!(
        f_full - f_asm,
        saved,
        "one factorisation saved per such step"
    );
    assert_eq!(p_asm.handed.len(), saved, "the values with every such step");
    // The same evaluation and elimination: bit for bit.
    assert!(p_asm.handed.iter().all(|&d| d == 0.0), "{:?}", p_asm.handed);
    assert!(p_full.handed.is_empty());
}

/// A spring chain whose residual carries deterministic noise of size `noise` (a stand-in for
/// round-off far above `ε ‖|K||u|‖`), optionally reported as its residual scale.
struct Noisy {
    chain: SpringChain,
    noise: f64,
    report_scale: bool,
    rng: Rng,
}

impl NonlinearProblem for Noisy {
    fn n_dofs(&self) -> usize {
        self.chain.n_dofs()
    }
    fn residual(&mut self, u: &[f64], l: f64, r: &mut [f64]) -> Result<(), ProblemError> {
        self.chain.residual(u, l, r)?;
        for x in r.iter_mut() {
            *x += self.noise * self.rng.next();
        }
        Ok(())
    }
    fn tangent(&mut self, u: &[f64], l: f64, v: &mut [f64]) -> Result<(), ProblemError> {
        self.chain.tangent(u, l, v)
    }
    fn residual_and_tangent(
        &mut self,
        u: &[f64],
        l: f64,
        r: &mut [f64],
        v: &mut [f64],
    ) -> Result<(), ProblemError> {
        self.residual(u, l, r)?;
        self.tangent(u, l, v)
    }
    fn essential(&self, l: f64) -> Vec<(usize, f64)> {
        self.chain.essential(l)
    }
    fn force_norm(&self, l: f64) -> f64 {
        self.chain.force_norm(l)
    }
    fn residual_scale(&self) -> f64 {
        if self.report_scale {
            // ‖noise‖ ≤ √n · noise; the driver multiplies by roundoff_factor · ε.
            self.noise * (self.n_dofs() as f64).sqrt() / f64::EPSILON
        } else {
            0.0
        }
    }
    fn commit(&mut self, u: &[f64], l: f64) {
        self.chain.commit(u, l)
    }
    fn restore(&mut self) {
        self.chain.restore()
    }
}

fn noisy_run(
    noise: f64,
    report_scale: bool,
    options: NewtonOptions,
) -> Result<NewtonReport, Box<NewtonFailure>> {
    let mut prob = Noisy {
        chain: SpringChain::new(10, 0.05, 2.0, None),
        noise,
        report_scale,
        rng: Rng(0xF100),
    };
    let pattern = prob.chain.pattern.clone();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    let newton = NewtonSolver {
        options,
        stepping: LoadStepping {
            initial_step: 0.25,
            max_step: 0.25,
            ..Default::default()
        },
    };
    newton.run(&mut prob, &pattern, &mut solver, &[0.0; 11])
}

#[test]
fn unattainable_tolerance_is_met_at_the_roundoff_floor() {
    // rtol = 1e-18 asks for less than round-off (the internal forces are O(1)): the driver stops
    // at the first residual below ε ‖|K||u|‖, after the iterations quadratic convergence needs,
    // where the bare tolerance test runs into max_iterations.
    let tight = NewtonOptions {
        residual_rtol: 1e-18,
        energy_rtol: 0.0,
        ..Default::default()
    };
    let report = noisy_run(0.0, false, tight).unwrap();
    let reference = noisy_run(
        0.0,
        false,
        NewtonOptions {
            residual_rtol: 1e-12,
            ..Default::default()
        },
    )
    .unwrap();
    for (st, rf) in report.converged_steps().zip(reference.converged_steps()) {
        println!(
            "λ {}: {:?} after {} (rtol 1e-12: {}), r {:?}, floor {:.2e}",
            st.load,
            st.acceptance,
            st.iterations,
            rf.iterations,
            st.residual_norms,
            st.roundoff_floors.last().unwrap()
        );
        assert_eq!(st.acceptance, Some(Acceptance::RoundoffFloor));
        assert!(st.residual_norms.last() <= st.roundoff_floors.last());
        // At most one update beyond the 1e-12 tolerance (whose last residual is already within
        // a few orders of the floor).
        assert!(st.iterations <= rf.iterations + 1, "λ {}", st.load);
    }
    // Without the floor (and the stagnation fallback) the same tolerance is never met.
    let fail = noisy_run(
        0.0,
        false,
        NewtonOptions {
            roundoff_factor: 0.0,
            stagnation_ratio: 0.0,
            ..tight
        },
    )
    .unwrap_err();
    assert!(
        matches!(fail.reason, FailureReason::MaxIterations(20)),
        "{fail}"
    );
}

#[test]
fn noise_above_the_estimated_floor_is_caught_by_the_scale_or_by_stagnation() {
    // Noise of 1e-9 in every residual entry, far above ε ‖|K||u|‖ ≈ 1e-15, below the tolerance
    // rtol·r_ref only for rtol > ~1e-9. With rtol = 1e-12:
    let opts = NewtonOptions {
        residual_rtol: 1e-12,
        ..Default::default()
    };
    // the problem reports its scale: the floor test accepts at the first noisy residual;
    let with_scale = noisy_run(1e-9, true, opts).unwrap();
    // it does not: the residual stalls twice and the stagnation test accepts, two updates later;
    let without = noisy_run(1e-9, false, opts).unwrap();
    for (a, b) in with_scale.converged_steps().zip(without.converged_steps()) {
        println!(
            "λ {}: scale reported {:?} after {} {:?}; not reported {:?} after {} {:?}",
            a.load,
            a.acceptance,
            a.iterations,
            a.residual_norms,
            b.acceptance,
            b.iterations,
            b.residual_norms
        );
        assert_eq!(a.acceptance, Some(Acceptance::RoundoffFloor));
        assert_eq!(b.acceptance, Some(Acceptance::Stagnation));
        assert_eq!(b.iterations, a.iterations + 2);
        assert!(*b.residual_norms.last().unwrap() <= 1e-12f64.sqrt() * 2.0 * b.load);
    }
    // A stall far above the tolerance is a failure, not round-off: noise 1e-4 > √rtol · r_ref.
    let fail = noisy_run(1e-4, false, opts).unwrap_err();
    assert!(
        matches!(fail.reason, FailureReason::MaxIterations(_)),
        "{fail}"
    );
}

/// Run the softening chain (β = 0.05, end load 2λ) with `stepping`; return the report.
fn chain_with_stepping(stepping: LoadStepping) -> Result<NewtonReport, Box<NewtonFailure>> {
    let mut prob = SpringChain::new(10, 0.05, 2.0, None);
    let pattern = prob.pattern.clone();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    let newton = NewtonSolver {
        options: NewtonOptions::default(),
        stepping,
    };
    newton.run(&mut prob, &pattern, &mut solver, &[0.0; 11])
}

#[test]
fn load_stepping_lands_exactly_on_the_stops() {
    // Constant step 0.3 (no growth): every step is 0.3 or is clipped to the next stop, and the
    // step after a clipped one is 0.3 again (not the clipped size).
    let report = chain_with_stepping(LoadStepping {
        initial_step: 0.3,
        grow_factor: 1.0,
        stops: vec![0.1, 0.25, 0.5, 0.55, 1.0],
        ..Default::default()
    })
    .unwrap();
    let loads: Vec<f64> = report.converged_steps().map(|s| s.load).collect();
    let sizes: Vec<f64> = report.converged_steps().map(|s| s.step_size).collect();
    println!("loads {loads:?}, step sizes {sizes:?}");
    // The stops are met bit for bit (the load factor is the stop itself, not a sum of steps);
    // the one unclipped step 0.55 + 0.3 is a sum, exact to round-off of the addition.
    assert_eq!(loads.len(), 6, "{loads:?}");
    for (k, stop) in [(0, 0.1), (1, 0.25), (2, 0.5), (3, 0.55), (5, 1.0)] {
        assert_eq!(loads[k], stop, "{loads:?}");
    }
    assert!((loads[4] - 0.85).abs() <= 1e-15, "{loads:?}");
    assert!((sizes[4] - 0.3).abs() <= 1e-15, "{sizes:?}");
    assert_eq!(report.load, 1.0);
    assert_eq!(report.attempts.len(), 6, "no step was cut");

    // With growth (every step easy, factor 2): a clipped step neither grows the step size nor
    // shrinks it; an unclipped one doubles it.
    let report = chain_with_stepping(LoadStepping {
        initial_step: 0.1,
        grow_factor: 2.0,
        easy_iterations: 100,
        stops: vec![0.15, 0.6],
        ..Default::default()
    })
    .unwrap();
    let loads: Vec<f64> = report.converged_steps().map(|s| s.load).collect();
    let sizes: Vec<f64> = report.converged_steps().map(|s| s.step_size).collect();
    println!("loads {loads:?}, step sizes {sizes:?}");
    // 0.1 (grows to 0.2) → 0.15 clipped (stays 0.2) → 0.35 (grows to 0.4) → 0.6 clipped
    // (stays 0.4) → 1.0 (a full step of 0.4).
    let expected = [
        (0.1, 0.1),
        (0.15, 0.05),
        (0.35, 0.2),
        (0.6, 0.25),
        (1.0, 0.4),
    ];
    assert_eq!(loads.len(), expected.len(), "{loads:?}");
    for (k, (l, h)) in expected.iter().enumerate() {
        // Sums of a few steps: round-off of the additions (≤ 1e-15 at these magnitudes).
        assert!((loads[k] - l).abs() <= 1e-15, "{loads:?}");
        assert!((sizes[k] - h).abs() <= 1e-15, "{sizes:?}");
    }
    assert_eq!(loads[1], 0.15);
    assert_eq!(loads[3], 0.6);

    // The converged state at a stop does not depend on the path to it: the same chain with
    // one step to 0.25 and with the clipped steps above (tolerance: both solves converge to
    // rtol 1e-8 of the load, so the end displacement agrees to about that).
    let one = chain_with_stepping(LoadStepping {
        initial_step: 0.25,
        end: 0.25,
        ..Default::default()
    })
    .unwrap();
    let stopped = chain_with_stepping(LoadStepping {
        initial_step: 0.3,
        grow_factor: 1.0,
        end: 0.25,
        stops: vec![0.1, 0.25],
        ..Default::default()
    })
    .unwrap();
    let (a, b) = (one.u[10], stopped.u[10]);
    assert!((a - b).abs() <= 1e-7 * a.abs(), "{a} vs {b}");
}

#[test]
fn a_failed_clipped_step_is_cut_from_its_clipped_size() {
    // Stiffening chain (f = k (e + e³), end load 20λ, overstretch above e = 4): the step to
    // the stop 0.9 overstretches (linear predictor e ≈ 17); the retry is 0.45, half the
    // clipped step (not half the step size 1), and the stop is still met exactly.
    let mut prob = SpringChain::new(10, 1.0, 20.0, None);
    prob.a = 0.0;
    prob.c = 1.0;
    prob.e_limit = 4.0;
    let pattern = prob.pattern.clone();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    // The cut is under test: without the line search (which backtracks instead of cutting).
    let newton = NewtonSolver {
        options: NewtonOptions {
            line_search: LineSearch::Off,
            ..Default::default()
        },
        stepping: LoadStepping {
            initial_step: 1.0,
            stops: vec![0.9],
            ..Default::default()
        },
    };
    let report = newton
        .run(&mut prob, &pattern, &mut solver, &[0.0; 11])
        .unwrap();
    let first = &report.attempts[0];
    assert!(!first.converged);
    assert_eq!((first.load, first.step_size), (0.9, 0.9));
    assert_eq!(report.attempts[1].step_size, 0.45);
    assert!(report.converged_steps().any(|s| s.load == 0.9));
    assert_eq!(report.load, 1.0);
}

#[test]
fn invalid_stops_are_a_setup_failure() {
    for stops in [
        vec![0.5, 0.4],
        vec![0.0],
        vec![0.3, 0.3],
        vec![1.5],
        vec![f64::NAN],
    ] {
        let fail = chain_with_stepping(LoadStepping {
            stops: stops.clone(),
            ..Default::default()
        })
        .unwrap_err();
        assert!(
            matches!(&fail.reason, FailureReason::Setup(m) if m.contains("stops[")),
            "{stops:?}: {fail}"
        );
        assert!(fail.report.attempts.is_empty());
    }
}

#[test]
fn gmres_preconditioned_by_a_nearby_factorisation_matches_the_direct_solve() {
    // A random unsymmetric sparse matrix A and a perturbation A + δB of it (the tangent of
    // the next Newton iterate): GMRES on A + δB preconditioned by the LU of A must give the
    // direct solution of A + δB to the requested 1e-12 (relative residual; the solution
    // differs by at most cond · 1e-12 with cond < 1e4 for these shifted matrices), in few
    // steps for small δ and more as δ grows; a preconditioner far from the matrix with too
    // few steps allowed is reported (None), not returned as a solution.
    let mut rng = Rng(0xC0FFEE);
    let n = 120;
    let p = SparsityPattern::from_cells(n, &random_cells(n, 100, &mut rng)).unwrap();
    let a = random_values(&p, &mut rng, false, 4.0);
    let bvals = random_values(&p, &mut rng, false, 0.0);
    let rhs: Vec<f64> = (0..n).map(|_| rng.next()).collect();
    let mut m = LinearSolver::new(&p, Method::Lu, SolverOptions::default()).unwrap();
    m.factorize(&a).unwrap();
    let mut steps = Vec::new();
    for delta in [1e-6, 1e-3, 1e-1] {
        let ad: Vec<f64> = a.iter().zip(&bvals).map(|(x, y)| x + delta * y).collect();
        let mut direct = LinearSolver::new(&p, Method::Lu, SolverOptions::default()).unwrap();
        direct.factorize(&ad).unwrap();
        let mut xd = rhs.clone();
        direct.solve_in_place(&mut xd).unwrap();
        let mut x = vec![0.0; n];
        let info = shelldsa::solver::krylov::gmres(&p, &ad, &m, &rhs, &mut x, 1e-12, 60)
            .unwrap()
            .expect("converges");
        let diff = x
            .iter()
            .zip(&xd)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        println!(
            "δ = {delta:e}: {info:?}, |x − x_direct|/|x| = {:.2e}",
            diff / norm(&xd)
        );
        assert!(info.relative_residual <= 1e-11, "{info:?}");
        assert!(diff / norm(&xd) <= 1e-8, "δ = {delta}: {diff:e}");
        steps.push(info.iterations);
    }
    assert!(steps[0] <= steps[1] && steps[1] <= steps[2], "{steps:?}");
    assert!(steps[0] <= 3, "{steps:?}");
    // A preconditioner far from the matrix (A against A + 5B) with 2 steps allowed: not
    // reached, reported as None.
    let far: Vec<f64> = bvals.iter().map(|y| 5.0 * y).collect();
    let sum: Vec<f64> = a.iter().zip(&far).map(|(x, y)| x + y).collect();
    let mut x = vec![0.0; n];
    let out = shelldsa::solver::krylov::gmres(&p, &sum, &m, &rhs, &mut x, 1e-12, 2).unwrap();
    assert!(out.is_none(), "{out:?}");
}

#[test]
fn gmres_on_several_columns_in_lock_step_matches_gmres_column_by_column() {
    // Five right-hand sides of A + δB, preconditioned by the LU of A: a zero column (done
    // at once), columns at δ = 1e-3 scales (a few steps) and one with a tolerance the chord
    // step already meets. Run together by `gmres_columns_to` (from the chord steps M⁻¹ b),
    // each column takes the Arnoldi steps `gmres_to` takes on it alone, to the same tolerance,
    // and the two solutions agree to what cond(A + δB) < 1e4 makes of residuals of 1e-12
    // (1e-8 relative, with margin). Five columns also cover a product group left part-filled.
    use shelldsa::solver::krylov::{
        csc_abs_mul_columns, csc_mul, csc_mul_columns, gmres_columns_to, gmres_to,
    };
    let mut rng = Rng(0xBA7C4);
    let n = 150;
    let p = SparsityPattern::from_cells(n, &random_cells(n, 120, &mut rng)).unwrap();
    let a = random_values(&p, &mut rng, false, 4.0);
    let bvals = random_values(&p, &mut rng, false, 0.0);
    let ad: Vec<f64> = a.iter().zip(&bvals).map(|(x, y)| x + 1e-3 * y).collect();
    let mut m = LinearSolver::new(&p, Method::Lu, SolverOptions::default()).unwrap();
    m.factorize(&a).unwrap();
    let k = 5;
    let mut b: Vec<f64> = (0..n * k).map(|_| rng.next()).collect();
    b[n..2 * n].fill(0.0);
    // The products of several columns against the single-column product: the same bits
    // below the size at which a product is split; |A||x| against the product of the
    // absolute values.
    let mut y = vec![0.0; n * k];
    csc_mul_columns(&p, &ad, &b, k, &mut y);
    let mut yabs = vec![0.0; n * k];
    csc_abs_mul_columns(&p, &ad, &b, k, &mut yabs);
    let abs_vals: Vec<f64> = ad.iter().map(|v| v.abs()).collect();
    for c in 0..k {
        let mut yc = vec![0.0; n];
        csc_mul(&p, &ad, &b[c * n..(c + 1) * n], &mut yc);
        assert_eq!(&y[c * n..(c + 1) * n], &yc[..], "column {c}");
        let xa: Vec<f64> = b[c * n..(c + 1) * n].iter().map(|v| v.abs()).collect();
        csc_mul(&p, &abs_vals, &xa, &mut yc);
        assert_eq!(&yabs[c * n..(c + 1) * n], &yc[..], "|A||x|, column {c}");
    }
    let tols: Vec<f64> = (0..k)
        .map(|c| {
            let bn = norm(&b[c * n..(c + 1) * n]);
            if c == 3 {
                1e-1 * bn
            } else {
                1e-12 * bn
            }
        })
        .collect();
    let mut x = b.clone();
    m.solve_columns_in_place(&mut x, k).unwrap();
    let out = gmres_columns_to(&p, &ad, &m, &b, &mut x, k, &tols, 40).unwrap();
    for c in 0..k {
        let info = out[c].expect("converges");
        let mut xc = vec![0.0; n];
        let alone = gmres_to(
            &p,
            &ad,
            &m,
            &b[c * n..(c + 1) * n],
            &mut xc,
            tols[c],
            40,
            false,
        )
        .unwrap()
        .expect("converges alone");
        println!("column {c}: together {info:?}, alone {alone:?}");
        assert_eq!(info.iterations, alone.iterations, "column {c}");
        let bn = norm(&b[c * n..(c + 1) * n]);
        assert!(
            info.relative_residual * bn <= 10.0 * tols[c],
            "column {c}: {info:?}"
        );
        let d = xc
            .iter()
            .zip(&x[c * n..(c + 1) * n])
            .map(|(u, v)| (u - v).powi(2))
            .sum::<f64>()
            .sqrt();
        let xn = norm(&xc).max(f64::MIN_POSITIVE);
        assert!(c == 3 || d <= 1e-8 * xn, "column {c}: {d:e} of {xn:e}");
    }
    assert_eq!(out[1].unwrap().iterations, 0);
    assert_eq!(out[3].unwrap().iterations, 0);
    assert!(out[0].unwrap().iterations >= 2, "{out:?}");
    // Too few steps allowed: reported per column, not returned as solutions.
    let mut x = b.clone();
    m.solve_columns_in_place(&mut x, k).unwrap();
    let out = gmres_columns_to(&p, &ad, &m, &b, &mut x, k, &tols, 1).unwrap();
    assert!(out[0].is_none() && out[2].is_none(), "{out:?}");
    assert!(out[1].is_some() && out[3].is_some(), "{out:?}");
}

#[test]
fn a_large_sparse_product_is_split_over_two_tasks_with_the_same_result_on_any_pool() {
    // 40 000 unknowns in overlapping cells of 16: 1.24 M stored entries, above the size at which
    // the product runs as two tasks (2^20). Against a row-by-row sum of the same products: the
    // two halves change only the order of the additions into a row, so they agree to a few
    // units of round-off of the row's magnitude (1e-13 relative with margin); and the split is
    // fixed by the pattern, so one and two threads give the same bits.
    let n = 40_000;
    let cells: Vec<Vec<usize>> = (0..n - 15).map(|i| (i..i + 16).collect()).collect();
    let p = SparsityPattern::from_cells(n, &cells).unwrap();
    assert!(p.nnz() > 1 << 20, "{}", p.nnz());
    let mut rng = Rng(0x5EED);
    let values = random_values(&p, &mut rng, false, 1.0);
    let x: Vec<f64> = (0..n).map(|_| rng.next()).collect();
    let (cp, ri) = (p.col_ptr(), p.row_idx());
    let mut rows = vec![Vec::new(); n];
    for j in 0..n {
        for q in cp[j]..cp[j + 1] {
            rows[ri[q]].push(values[q] * x[j]);
        }
    }
    let product = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let mut y = vec![0.0; n];
        pool.install(|| shelldsa::solver::krylov::csc_mul(&p, &values, &x, &mut y));
        y
    };
    let y1 = product(1);
    for (i, terms) in rows.iter().enumerate() {
        let exact: f64 = terms.iter().sum();
        let scale: f64 = terms.iter().map(|t| t.abs()).sum();
        assert!(
            (y1[i] - exact).abs() <= 1e-13 * scale,
            "row {i}: {} against {exact}",
            y1[i]
        );
    }
    let y2 = product(2);
    assert!(y1.iter().zip(&y2).all(|(a, b)| a.to_bits() == b.to_bits()));
}

/// The driver of the softening-chain comparisons of linear-update policies: residual to 1e-12,
/// five equal load steps of 0.2, updates by `updates`.
fn chain_newton(updates: LinearUpdates) -> NewtonSolver {
    NewtonSolver {
        options: NewtonOptions {
            residual_rtol: 1e-12,
            linear_updates: updates,
            ..Default::default()
        },
        stepping: LoadStepping {
            initial_step: 0.2,
            max_step: 0.2,
            ..Default::default()
        },
    }
}

#[test]
fn krylov_updates_near_convergence_keep_the_newton_iterates() {
    // The softening chain with direct updates and with GMRES updates near convergence: the
    // same iteration counts, the same converged unknowns to far below the tolerance, fewer
    // factorisations, and with the default hook policy (converged tangent required) the
    // solver holds the converged tangent at every step.
    let run = |updates: LinearUpdates| {
        let mut chain = SpringChain::new(10, 0.05, 2.0, None);
        let pattern = chain.pattern.clone();
        let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
        let newton = chain_newton(updates);
        let report = newton
            .run(&mut chain, &pattern, &mut solver, &[0.0; 11])
            .unwrap();
        (report, solver.n_factorizations())
    };
    let (direct, f_direct) = run(LinearUpdates::Direct);
    let (krylov, f_krylov) = run(LinearUpdates::KrylovNearConvergence);
    let used: usize = krylov.converged_steps().map(|s| s.krylov.len()).sum();
    println!("factorisations {f_direct} direct, {f_krylov} with {used} GMRES updates");
    assert!(used > 0);
    assert!(f_krylov < f_direct);
    let its = |r: &NewtonReport| {
        r.converged_steps()
            .map(|s| s.iterations)
            .collect::<Vec<_>>()
    };
    assert_eq!(its(&direct), its(&krylov));
    let scale = norm(&direct.u);
    let diff = direct
        .u
        .iter()
        .zip(&krylov.u)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        .sqrt();
    // Both stop below 1e-12 of the force; the chain's compliance is O(1).
    assert!(diff <= 1e-10 * scale, "{diff:e}");
    assert!(krylov
        .converged_steps()
        .all(|s| s.factorised_at == Some(FactorisedAt::Converged)));
}

#[test]
fn held_factorisation_updates_keep_the_newton_iterates_across_steps() {
    // The softening chain with direct updates and with every update by GMRES preconditioned by
    // the held factorisation (`KrylovHeld`), for the three converged-tangent policies: the same
    // iteration counts and converged unknowns to far below the tolerance, fewer
    // factorisations, factors reused across steps (GMRES at the first iteration of a step),
    // and with the converged tangent required, the solver holds it at every hook.
    let run = |updates: LinearUpdates, policy: ConvergedTangent| {
        let (report, prob, factorisations) = run_counting(policy, &chain_newton(updates));
        (report, factorisations, prob.hooks)
    };
    let its = |r: &NewtonReport| {
        r.converged_steps()
            .map(|s| s.iterations)
            .collect::<Vec<_>>()
    };
    for policy in [
        ConvergedTangent::Required,
        ConvergedTangent::Assembled,
        ConvergedTangent::NotNeeded,
    ] {
        let (direct, f_direct, _) = run(LinearUpdates::Direct, policy);
        let (held, f_held, hooks) = run(LinearUpdates::KrylovHeld, policy);
        let used: usize = held.converged_steps().map(|s| s.krylov.len()).sum();
        let at_start = held
            .converged_steps()
            .filter(|s| s.krylov.iter().any(|&(k, _)| k == 0))
            .count();
        println!(
            "{policy:?}: factorisations {f_direct} direct, {f_held} held with {used} GMRES \
             updates ({at_start} steps started on an earlier step's factors)"
        );
        assert!(f_held < f_direct, "{f_held} vs {f_direct}");
        assert!(at_start > 0);
        // GMRES is skipped (the tangent factorised without a try) only at an iteration where
        // it gave up, or was skipped, in each of the two attempts before.
        for (i, s) in held.attempts.iter().enumerate() {
            for &k in &s.krylov_skipped {
                assert!(
                    i >= 2,
                    "attempt {i} skipped {k} without two attempts before"
                );
                assert!(
                    held.attempts[i - 1].gmres_gave_up_at(k)
                        && held.attempts[i - 2].gmres_gave_up_at(k)
                );
            }
        }
        assert_eq!(its(&direct), its(&held));
        let scale = norm(&direct.u);
        let diff = direct
            .u
            .iter()
            .zip(&held.u)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        // Both stop below 1e-12 of the force and GMRES solves to 1e-12 of the force scale;
        // the chain's compliance is O(1).
        assert!(diff <= 1e-10 * scale, "{diff:e}");
        if policy == ConvergedTangent::Required {
            assert!(hooks.iter().all(|&f| f == FactorisedAt::Converged));
        }
    }
}

#[test]
fn auto_linear_updates_follow_the_factorisation() {
    // Dense LU: a factorisation per update; the sparse factorisations: the held one.
    let chain = SpringChain::new(10, 0.05, 2.0, None);
    let dense =
        LinearSolver::new(&chain.pattern, Method::DenseLu, SolverOptions::default()).unwrap();
    let sparse = LinearSolver::new(
        &chain.pattern,
        Method::SupernodalLu,
        SolverOptions::default(),
    )
    .unwrap();
    assert_eq!(LinearUpdates::Auto.resolve(&dense), LinearUpdates::Direct);
    assert_eq!(
        LinearUpdates::Auto.resolve(&sparse),
        LinearUpdates::KrylovHeld
    );
    assert_eq!(
        LinearUpdates::KrylovNearConvergence.resolve(&sparse),
        LinearUpdates::KrylovNearConvergence
    );
    // At least the singularity probe's solve and product, one GMRES step's work.
    assert!(sparse.refactorisation_cost() >= 1.0);
    assert!(dense.refactorisation_cost() >= 1.0);
}

#[test]
fn a_particle_grid_couples_each_particle_with_its_square_support() {
    // 4 × 4 particles, 2 DOFs each, reach 1. Two DOFs are coupled when their particles share a
    // cell, i.e. both lie within one spacing of a cell's particle: within two spacings of each
    // other in each direction, clipped to the grid. Particle 0 (a corner) couples 3 × 3
    // particles, particle 1 (on an edge) 4 × 3, particle 5 (inside) 4 × 4.
    let p = SparsityPattern::particle_grid(4, 2, 1).unwrap();
    assert_eq!(p.n_dofs(), 32);
    let rows = |particle: usize| {
        let j = 2 * particle;
        p.col_ptr()[j + 1] - p.col_ptr()[j]
    };
    assert_eq!(rows(0), 2 * 3 * 3);
    assert_eq!(rows(1), 2 * 4 * 3);
    assert_eq!(rows(5), 2 * 4 * 4);
    assert!(p.slot(0, 1).is_some() && p.slot(0, 2 * 15).is_none());
}
