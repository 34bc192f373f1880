//! The supernodal LU (`Method::SupernodalLu`) on shell-like patterns: agreement with the
//! unrestricted sparse LU, both fill-reducing orderings, many right-hand sides, and results that
//! do not depend on the number of threads (in-process thread pools for the factorisation, and
//! `shelldsa run` in subprocesses with `RAYON_NUM_THREADS` and `SHELLDSA_LU_THREADS` for a whole
//! analysis).

use serde_json::Value;
use shelldsa::solver::*;
use std::path::PathBuf;

/// A meshfree-shell-like pattern: `nx × nx` particles with 5 DOFs, each particle's cell coupling
/// the particles within 2 spacings (as `benches/solver.rs`), and unsymmetric values: a
/// diagonally weighted graph Laplacian plus a skew part of relative size `skew`.
fn shell_like(nx: usize, skew: f64) -> (SparsityPattern, Vec<f64>) {
    let p = SparsityPattern::particle_grid(nx, 5, 2).unwrap();
    let n = p.n_dofs();
    let (cp, ri) = (p.col_ptr().to_vec(), p.row_idx().to_vec());
    let mut values = p.values_from(|i, j| {
        if i == j {
            0.0
        } else {
            // Symmetric coupling −1/(1 + |i − j| mod 7) plus a skew part.
            let sym = -1.0 / (1.0 + ((i.abs_diff(j)) % 7) as f64);
            let sk = if i < j { skew } else { -skew } * ((i + 2 * j) % 5) as f64 / 5.0;
            sym + sk
        }
    });
    // Diagonal: the row sum of the symmetric part's magnitudes plus one (diagonally dominant
    // symmetric part: nonsingular, moderately conditioned).
    for j in 0..n {
        let mut s = 1.0;
        for q in cp[j]..cp[j + 1] {
            if ri[q] != j {
                s += values[q].abs();
            }
        }
        values[p.diag_slot(j)] = s;
    }
    (p, values)
}

fn rhs(n: usize, k: usize) -> Vec<f64> {
    (0..n * k)
        .map(|i| ((i as f64 + 1.0) * 0.754_877_666).fract() - 0.5)
        .collect()
}

fn relative_residual(p: &SparsityPattern, values: &[f64], x: &[f64], b: &[f64]) -> f64 {
    let mut ax = vec![0.0; b.len()];
    p.mat_vec(values, x, &mut ax).unwrap();
    let r: f64 = ax.iter().zip(b).map(|(a, b)| (a - b).powi(2)).sum();
    (r / b.iter().map(|v| v * v).sum::<f64>()).sqrt()
}

#[test]
fn supernodal_lu_matches_the_sparse_lu_for_every_ordering() {
    let (p, values) = shell_like(14, 0.2);
    let n = p.n_dofs();
    let b = rhs(n, 1);
    let mut reference = LinearSolver::new(&p, Method::Lu, SolverOptions::default()).unwrap();
    reference.factorize(&values).unwrap();
    let mut x_ref = b.clone();
    reference.solve_in_place(&mut x_ref).unwrap();
    for ordering in [
        FillOrdering::NestedDissection,
        FillOrdering::Amd,
        FillOrdering::Metis,
    ] {
        let mut s = LinearSolver::supernodal(&p, ordering, SolverOptions::default()).unwrap();
        assert_eq!(s.method(), Method::SupernodalLu);
        s.factorize(&values).unwrap();
        let mut x = b.clone();
        s.solve_in_place(&mut x).unwrap();
        // Both are backward stable: residuals at a small multiple of ε, and solutions equal to
        // cond(A)·ε (the diagonally dominant symmetric part keeps cond(A) below ~1e2).
        let res = relative_residual(&p, &values, &x, &b);
        assert!(res < 1e-14, "{ordering:?}: relative residual {res:.2e}");
        let diff = x
            .iter()
            .zip(&x_ref)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max)
            / x_ref.iter().map(|v| v.abs()).fold(0.0, f64::max);
        assert!(
            diff < 1e-12,
            "{ordering:?}: differs from the sparse LU by {diff:.2e}"
        );
        assert!(s.structure().is_some_and(|t| t.contains("supernodes")));
    }
}

#[test]
fn the_default_ordering_is_nested_dissection_unless_another_costs_clearly_less() {
    for (size, skew) in [(14, 0.2), (9, 0.0), (20, 0.1)] {
        let (p, _) = shell_like(size, skew);
        let cost = |o: FillOrdering| {
            LinearSolver::supernodal(&p, o, SolverOptions::default())
                .unwrap()
                .ordering_and_cost()
                .unwrap()
        };
        let named = [
            FillOrdering::NestedDissection,
            FillOrdering::Metis,
            FillOrdering::Amd,
        ];
        let candidates = named.map(cost);
        // An explicit ordering is used as named.
        for (c, o) in candidates.iter().zip(named) {
            assert_eq!(c.0, o);
        }
        let nd = candidates[0].1;
        let other = candidates[1..]
            .iter()
            .copied()
            .fold(None, |b: Option<(FillOrdering, f64)>, c| match b {
                Some(b) if b.1 <= c.1 => Some(b),
                _ => Some(c),
            })
            .unwrap();
        let expected = if other.1 <= ORDERING_MARGIN * nd {
            other
        } else {
            candidates[0]
        };
        // The same symbolic analyses are repeated, so the costs are equal exactly.
        let chosen = cost(FillOrdering::Cheapest);
        assert_eq!(chosen, expected, "{size}: {candidates:?}");
        // Through the solver's default construction as well.
        let default = LinearSolver::new(&p, Method::SupernodalLu, SolverOptions::default())
            .unwrap()
            .ordering_and_cost()
            .unwrap();
        assert_eq!(default, chosen);
        println!("{size} × {size}: {candidates:?} → {chosen:?}");
    }
}

#[test]
fn supernodal_lu_solves_many_right_hand_sides_as_single_ones() {
    let (p, values) = shell_like(10, 0.3);
    let n = p.n_dofs();
    let k = 5;
    let b = rhs(n, k);
    let mut s = LinearSolver::new(&p, Method::SupernodalLu, SolverOptions::default()).unwrap();
    s.factorize(&values).unwrap();
    let mut multi = b.clone();
    s.solve_columns_in_place(&mut multi, k).unwrap();
    for c in 0..k {
        let mut single = b[c * n..(c + 1) * n].to_vec();
        s.solve_in_place(&mut single).unwrap();
        // The same factors; the dense kernels may block k columns differently from one, so
        // the two agree to round-off (cond(A) < 1e2 here: 1e-13 relative with margin).
        let scale = single.iter().map(|v| v.abs()).fold(0.0, f64::max);
        let diff = multi[c * n..(c + 1) * n]
            .iter()
            .zip(&single)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(
            diff <= 1e-13 * scale,
            "column {c}: {diff:.2e} of {scale:.2e}"
        );
    }
}

#[test]
fn supernodal_factors_do_not_depend_on_the_number_of_threads() {
    // 20 × 20 particles, 2000 unknowns: fronts large enough for parallel subtrees and cut
    // trailing updates.
    let (p, values) = shell_like(20, 0.2);
    let n = p.n_dofs();
    let k = 3;
    let solve_with = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut s =
                LinearSolver::new(&p, Method::SupernodalLu, SolverOptions::default()).unwrap();
            s.factorize(&values).unwrap();
            let mut x = rhs(n, k);
            s.solve_columns_in_place(&mut x, k).unwrap();
            x
        })
    };
    let x1 = solve_with(1);
    assert!(relative_residual(&p, &values, &x1[..n], &rhs(n, 1)) < 1e-14);
    for threads in [2, 3, 4] {
        let x = solve_with(threads);
        let differ = x
            .iter()
            .zip(&x1)
            .filter(|(a, b)| a.to_bits() != b.to_bits())
            .count();
        assert_eq!(
            differ,
            0,
            "{threads} threads: {differ} of {} values differ",
            x.len()
        );
    }
}

/// Numbers of a results.json, by path, without the timings.
fn numbers(v: &Value, path: &str, out: &mut Vec<(String, u64)>) {
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                if !(k.contains("tim") || k.contains("wall")) {
                    numbers(x, &format!("{path}/{k}"), out);
                }
            }
        }
        Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                numbers(x, &format!("{path}/{i}"), out);
            }
        }
        Value::Number(x) => out.push((path.to_string(), x.as_f64().unwrap().to_bits())),
        _ => {}
    }
}

#[test]
fn a_whole_run_is_bit_identical_for_any_number_of_threads() {
    // The elastoplastic hemisphere reduced to 15 × 15 particles (1126 unknowns, above the
    // dense limit: the supernodal LU) and P = 20, yielding from P ≈ 18 with the CI case's σ0.
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let text =
        std::fs::read_to_string(root.join("verification/hemisphere-plastic-dsa/ci.toml")).unwrap();
    let text: String = text
        .lines()
        .map(|l| {
            if l.starts_with("grid =") {
                "grid = [15, 15]".to_string()
            } else if l.starts_with("final_load =") {
                "final_load = 20.0".to_string()
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    let dir = std::env::temp_dir().join(format!("shelldsa-threads-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let case = dir.join("case.toml");
    std::fs::write(&case, text).unwrap();
    let run = |name: &str, env: &[(&str, &str)]| {
        let out = dir.join(name);
        let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_shelldsa"));
        cmd.arg("run").arg(&case).arg("--out").arg(&out);
        cmd.env_remove("RAYON_NUM_THREADS")
            .env_remove("SHELLDSA_LU_THREADS");
        for (k, v) in env {
            cmd.env(k, v);
        }
        let status = cmd.output().unwrap();
        assert!(status.status.success(), "{name}: {status:?}");
        let json: Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap())
                .unwrap();
        assert!(json["linear_solver"]
            .as_str()
            .is_some_and(|s| s.starts_with("SupernodalLu") && s.contains("ordering")));
        // The case holds a point by a constraint row: its multiplier must not make the
        // supernodal LU fall back.
        assert!(json["factorisations"]["count"]
            .as_u64()
            .is_some_and(|c| c > 0));
        assert_eq!(
            json["factorisations"]["redone_by_the_sparse_lu"], 0,
            "{name}"
        );
        let mut v = Vec::new();
        numbers(&json, "", &mut v);
        v
    };
    let two = run("t2", &[("RAYON_NUM_THREADS", "2")]);
    assert!(two.len() > 100, "{} numbers", two.len());
    for (name, env) in [
        ("t1", vec![("RAYON_NUM_THREADS", "1")]),
        ("t3", vec![("RAYON_NUM_THREADS", "3")]),
        ("lu1", vec![("SHELLDSA_LU_THREADS", "1")]),
    ] {
        let other = run(name, &env);
        assert_eq!(other.len(), two.len(), "{name}");
        let differ: Vec<&String> = two
            .iter()
            .zip(&other)
            .filter(|(a, b)| a != b)
            .map(|(a, _)| &a.0)
            .collect();
        assert!(
            differ.is_empty(),
            "{name}: {} numbers differ, first {:?}",
            differ.len(),
            differ.first()
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_bordered_tangent_is_factorised_by_the_supernodal_lu_itself() {
    // The elastoplastic hemisphere (17 × 17) holds u_z at an interpolated point of the hole's
    // rim by a constraint row: its multiplier has a zero diagonal. Pivoting only inside the
    // supernodes, a multiplier ordered before the DOFs it couples meets that zero as its
    // pivot, and the solver falls back to the unrestricted sparse LU (whose determinant sign
    // it does not track: `determinant_sign` is `None` then). Ordered after them, its pivot is
    // the Schur complement of its row, and the supernodal factors are used.
    use shelldsa::io::shell_build::build;
    use shelldsa::io::shell_case::read_shell_case;
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let case = read_shell_case(&root.join("verification/hemisphere-plastic/case.toml")).unwrap();
    let mut built = build(&case).unwrap();
    let problem = &mut built.problem;
    let pattern = problem.pattern().clone();
    let n = pattern.n_dofs();
    let nq = problem.n_generalised();
    assert!(nq < n, "the case has a constraint row");
    assert_eq!(pattern.multipliers_from(), nq);
    let u = problem.generic_state();
    let load = 10.0;
    let mut r = vec![0.0; n];
    let mut values = vec![0.0; pattern.nnz()];
    problem
        .residual_and_tangent(&u, load, &mut r, &mut values)
        .unwrap();
    let bc = EssentialBc::new(n, &problem.essential(load)).unwrap();
    let mut rhs: Vec<f64> = r.iter().map(|x| -x).collect();
    bc.apply_with(&pattern, &mut values, &mut rhs, &vec![0.0; bc.dofs().len()])
        .unwrap();
    let factorise = |p: &SparsityPattern| {
        let mut s = LinearSolver::new(p, Method::SupernodalLu, SolverOptions::default()).unwrap();
        s.factorize(&values).unwrap();
        s
    };
    let s = factorise(&pattern);
    assert_eq!(s.n_fallbacks(), 0);
    assert!(
        s.determinant_sign().is_some(),
        "the supernodal factors were replaced by the fallback LU"
    );
    let mut x = rhs.clone();
    s.solve_in_place(&mut x).unwrap();
    // A pivot from a near-cancellation would show as a large backward error (the probe's
    // tolerance is far looser): 1e-12 bounds a stable factorisation's with margin.
    let res = relative_residual(&pattern, &values, &x, &rhs);
    assert!(res < 1e-12, "relative residual {res:e}");
    // For comparison, the same matrix with the multiplier left where the ordering puts it.
    let unmarked = factorise(&pattern.clone().with_multipliers_from(n));
    println!(
        "determinant sign with the multiplier ordered last: {:?}, unmarked: {:?} ({} fallback)",
        s.determinant_sign(),
        unmarked.determinant_sign(),
        unmarked.n_fallbacks()
    );
}

#[test]
fn a_singular_matrix_counts_no_factorisation_and_no_fallback() {
    // Two rows of one particle made equal: singular. The supernodal LU's probe fails, the
    // sparse LU redoes it, its probe fails too, and the error stands: neither the
    // factorisation nor the fallback is counted (the run's note reads "k of n factorisations
    // were redone", so k ≤ n).
    let (p, mut values) = shell_like(6, 0.1);
    let (cp, ri) = (p.col_ptr().to_vec(), p.row_idx().to_vec());
    let (r0, r1) = (10, 11);
    for c in 0..p.n_dofs() {
        let rows = &ri[cp[c]..cp[c + 1]];
        let a = rows.iter().position(|&r| r == r0).map(|k| cp[c] + k);
        let b = rows.iter().position(|&r| r == r1).map(|k| cp[c] + k);
        assert_eq!(a.is_some(), b.is_some(), "the rows share a pattern");
        if let (Some(a), Some(b)) = (a, b) {
            values[b] = values[a];
        }
    }
    let mut s = LinearSolver::new(&p, Method::SupernodalLu, SolverOptions::default()).unwrap();
    assert!(s.factorize(&values).is_err());
    assert_eq!((s.n_factorizations(), s.n_fallbacks()), (0, 0));
    assert!(!s.is_factorized());
}

#[test]
fn the_single_precision_preconditioner_solves_to_single_precision_and_gmres_to_double() {
    // The same factorisation applied as a preconditioner in single precision
    // (`PreconditionerPrecision::Single`, the default) and in double: on this moderately
    // conditioned matrix (cond < 1e2) the two differ by single precision's rounding of the
    // factors and of the substitutions, a relative 6e-8 amplified by the conditioning and the
    // solve's length, so below 1e-5 of the solution's size and above double precision's
    // 1e-12 (the single path is really taken). With `Double` the preconditioner is the solve
    // itself, bit for bit. GMRES with the single-precision preconditioner on the matrix it
    // factorised still reaches a double-precision tolerance (1e-13), in a few steps.
    // Factorised again, the preconditioner reads the new factors' copies.
    use shelldsa::solver::krylov::gmres_to;
    let (p, values) = shell_like(10, 0.3);
    let n = p.n_dofs();
    let k = 3;
    let b = rhs(n, k);
    let solver = |preconditioner| {
        let options = SolverOptions {
            preconditioner,
            ..SolverOptions::default()
        };
        let mut s = LinearSolver::new(&p, Method::SupernodalLu, options).unwrap();
        s.factorize(&values).unwrap();
        s
    };
    let single = solver(PreconditionerPrecision::Single);
    let double = solver(PreconditionerPrecision::Double);
    let mut exact = b.clone();
    double.solve_columns_in_place(&mut exact, k).unwrap();
    let mut same = b.clone();
    double.precondition_columns_in_place(&mut same, k).unwrap();
    assert_eq!(same, exact, "Double: the preconditioner is the solve");
    let mut rounded = b.clone();
    single
        .precondition_columns_in_place(&mut rounded, k)
        .unwrap();
    let scale = exact.iter().map(|v| v.abs()).fold(0.0, f64::max);
    let diff = rounded
        .iter()
        .zip(&exact)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(
        diff <= 1e-5 * scale && diff >= 1e-12 * scale,
        "single against double: {diff:.2e} of {scale:.2e}"
    );
    // A non-finite entry is named as by the solve.
    let mut bad = b.clone();
    bad[n + 7] = f64::NAN;
    match single.precondition_columns_in_place(&mut bad, k) {
        Err(SolverError::NonFiniteRhs { rhs: 1, row: 7, .. }) => {}
        other => panic!("expected NonFiniteRhs at column 1, row 7: {other:?}"),
    }
    // The single-precision copies follow a new factorisation (they are made on first use
    // after it): the matrix doubled halves the result, exactly (a power of two scales every
    // rounding alike).
    let mut refactorised = solver(PreconditionerPrecision::Single);
    let doubled: Vec<f64> = values.iter().map(|v| 2.0 * v).collect();
    refactorised
        .precondition_columns_in_place(&mut b.clone(), k)
        .unwrap();
    refactorised.factorize(&doubled).unwrap();
    let mut halved = b.clone();
    refactorised
        .precondition_columns_in_place(&mut halved, k)
        .unwrap();
    for (h, r) in halved.iter().zip(&rounded) {
        assert_eq!(2.0 * h, *r, "the copies of the new factorisation are used");
    }
    for c in 0..k {
        let bc = &b[c * n..(c + 1) * n];
        let mut x = vec![0.0; n];
        let info = gmres_to(
            &p,
            &values,
            &single,
            bc,
            &mut x,
            1e-13 * norm(bc),
            20,
            false,
        )
        .unwrap()
        .expect("converges");
        assert!(
            info.iterations <= 3,
            "column {c}: {} steps",
            info.iterations
        );
        let rel = relative_residual(&p, &values, &x, bc);
        assert!(rel <= 1e-13, "column {c}: residual {rel:.2e}");
    }
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}
