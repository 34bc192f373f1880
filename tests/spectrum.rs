//! The smallest eigenpairs of a bordered (multiplier) system with eliminated DOFs
//! (`solver::spectrum`), against a dense eigen-decomposition of the constrained matrix.
use nalgebra::{DMatrix, DVector, SymmetricEigen};
use shelldsa::solver::spectrum::{smallest_eigenpairs, SpectrumOptions};
use shelldsa::solver::{EssentialBc, LinearSolver, Method, SolverOptions, SparsityPattern};

/// A symmetric matrix of size 40 with a spread spectrum (a 1D Laplacian plus a diagonal), two
/// constraint rows (the sum of the first ten unknowns, and u_20 − u_21), one eliminated DOF
/// (u_39). The smallest six eigenvalues of `Zᵀ K Z` (Z: orthonormal basis of the admissible
/// subspace) must be found to 1e-8 relative and the vectors must be admissible.
#[test]
fn bordered_system_gives_the_constrained_spectrum() {
    let n = 40;
    let mut k = DMatrix::<f64>::zeros(n, n);
    for i in 0..n {
        k[(i, i)] = 2.0 + 0.01 * i as f64;
        if i + 1 < n {
            k[(i, i + 1)] = -1.0;
            k[(i + 1, i)] = -1.0;
        }
    }
    let mut c = DMatrix::<f64>::zeros(2, n);
    for i in 0..10 {
        c[(0, i)] = 1.0;
    }
    c[(1, 20)] = 1.0;
    c[(1, 21)] = -1.0;
    let fixed = 39;
    let nt = n + 2;
    let mut a = DMatrix::<f64>::zeros(nt, nt);
    a.view_mut((0, 0), (n, n)).copy_from(&k);
    // Rows scaled as the shell problem does (the solution does not depend on it).
    a.view_mut((n, 0), (2, n)).copy_from(&(&c * 3.0));
    a.view_mut((0, n), (n, 2)).copy_from(&(c.transpose() * 3.0));
    let mut entries = Vec::new();
    for j in 0..nt {
        for i in 0..nt {
            if a[(i, j)] != 0.0 || i == j {
                entries.push((i, j));
            }
        }
    }
    let pattern = SparsityPattern::from_entries(nt, &entries).unwrap();
    let mut values = vec![0.0; pattern.nnz()];
    for &(i, j) in &entries {
        values[pattern.slot(i, j).unwrap()] = a[(i, j)];
    }
    let bc = EssentialBc::new(nt, &[(fixed, 0.0)]).unwrap();
    let mut rhs = vec![0.0; nt];
    bc.apply_with(&pattern, &mut values, &mut rhs, &[0.0])
        .unwrap();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    solver.factorize(&values).unwrap();
    let sp = smallest_eigenpairs(
        &solver,
        &bc,
        n,
        SpectrumOptions {
            count: 6,
            ..Default::default()
        },
    )
    .unwrap();

    // Reference: orthonormal basis of {C x = 0, x_39 = 0} from the SVD of the stacked rows.
    let mut rows = DMatrix::<f64>::zeros(3, n);
    rows.view_mut((0, 0), (2, n)).copy_from(&c);
    rows[(2, fixed)] = 1.0;
    let svd = nalgebra::SVD::new(rows.transpose() * &rows, true, true);
    let v = svd.v_t.unwrap().transpose();
    let z = DMatrix::from_fn(n, n - 3, |i, j| {
        // Columns of V with zero singular value (sorted descending: the last n − 3).
        let order: Vec<usize> = {
            let mut o: Vec<usize> = (0..n).collect();
            o.sort_by(|&p, &q| svd.singular_values[q].total_cmp(&svd.singular_values[p]));
            o
        };
        v[(i, order[3 + j])]
    });
    let kz = z.transpose() * &k * &z;
    let mut reference: Vec<f64> = SymmetricEigen::new(kz)
        .eigenvalues
        .iter()
        .copied()
        .collect();
    reference.sort_by(|p, q| p.abs().total_cmp(&q.abs()));
    for (pair, want) in sp.pairs.iter().zip(&reference) {
        // Subspace iteration converged to 1e-10 in the Ritz values; 1e-8 leaves a margin.
        assert!(
            (pair.value - want).abs() <= 1e-8 * want.abs(),
            "{} against {want}",
            pair.value
        );
        let x = DVector::from_column_slice(&pair.vector);
        // Admissible: constraint rows and the eliminated DOF vanish (round-off of unit vectors).
        assert!((&c * &x).amax() < 1e-10, "C x = {}", (&c * &x).amax());
        assert!(x[fixed].abs() < 1e-14);
        // An eigenvector of the constrained operator: K x − λ x lies in the span of the rows.
        let r = &k * &x - &x * pair.value;
        let rz = z.transpose() * r;
        // Ritz vectors converge like the square root of the Ritz values' tolerance (1e-10), so
        // their residual is about 1e-5 |λ| (4.4e-7 absolute measured here); 1e-4 |λ| leaves a
        // margin.
        assert!(
            rz.amax() < 1e-4 * pair.value.abs(),
            "residual {}",
            rz.amax()
        );
    }
    assert_eq!(sp.pairs.len(), 6);
    assert!(sp.skew < 1e-12, "symmetric input: skew {}", sp.skew);
}
