//! One numeric LU of a shell case's tangent, sparse (faer, COLAMD) against dense (partial
//! pivoting, serial and 2 threads): the measurement behind `Method::DENSE_FILL`.
//!
//! `cargo run --release --example lu_probe -- verification/hemisphere-plastic/case.toml`
use shelldsa::io::shell_build::build;
use shelldsa::io::shell_case::read_shell_case;
use shelldsa::solver::{
    EssentialBc, LinearSolver, Method, NonlinearProblem, Parallelism, SolverOptions,
};
use std::time::Instant;

fn main() {
    let path = std::path::PathBuf::from(std::env::args().nth(1).expect("case path"));
    let case = read_shell_case(&path).unwrap();
    let mut built = build(&case).unwrap();
    let pattern = built.problem.pattern().clone();
    let n = pattern.n_dofs();
    let u = built.problem.generic_state();
    let mut r = vec![0.0; n];
    let mut values = vec![0.0; pattern.nnz()];
    let p = &mut built.problem;
    p.residual_and_tangent(&u, 10.0, &mut r, &mut values)
        .unwrap();
    let bc = EssentialBc::new(n, &p.essential(10.0)).unwrap();
    let mut rhs: Vec<f64> = r.iter().map(|x| -x).collect();
    let g0 = vec![0.0; bc.dofs().len()];
    bc.apply_with(&pattern, &mut values, &mut rhs, &g0).unwrap();
    println!(
        "n = {n}, nnz = {}, fill {:.3}",
        pattern.nnz(),
        pattern.nnz() as f64 / (n * n) as f64
    );
    let reps = 8;
    let mut solver = LinearSolver::new(
        &pattern,
        Method::Lu,
        SolverOptions {
            singularity_probe: None,
            ..Default::default()
        },
    )
    .unwrap();
    solver.factorize(&values).unwrap();
    let t = Instant::now();
    for _ in 0..reps {
        solver.factorize(&values).unwrap();
    }
    println!(
        "sparse LU (current): {:.1} ms",
        t.elapsed().as_secs_f64() * 1e3 / reps as f64
    );
    for (probe, par) in [
        (None, Parallelism::Sequential),
        (Some(1e-2), Parallelism::Sequential),
        (None, Parallelism::Rayon(2)),
        (Some(1e-2), Parallelism::Rayon(2)),
    ] {
        let mut dense = LinearSolver::new(
            &pattern,
            Method::DenseLu,
            SolverOptions {
                singularity_probe: probe,
                parallelism: par,
                ..SolverOptions::default()
            },
        )
        .unwrap();
        dense.factorize(&values).unwrap();
        let t = Instant::now();
        for _ in 0..reps {
            dense.factorize(&values).unwrap();
        }
        println!(
            "LinearSolver DenseLu (probe {probe:?}, {par:?}): {:.1} ms",
            t.elapsed().as_secs_f64() * 1e3 / reps as f64
        );
    }
    // dense
    let (cp, ri) = (pattern.col_ptr(), pattern.row_idx());
    let mut a = faer::Mat::<f64>::zeros(n, n);
    for j in 0..n {
        for q in cp[j]..cp[j + 1] {
            a[(ri[q], j)] = values[q];
        }
    }
    for par in [faer::Par::Seq, faer::Par::rayon(2)] {
        use faer::dyn_stack::{MemBuffer, MemStack};
        let mut fwd = vec![0usize; n];
        let mut bwd = vec![0usize; n];
        let mut buf = MemBuffer::new(
            faer::linalg::lu::partial_pivoting::factor::lu_in_place_scratch::<usize, f64>(
                n,
                n,
                par,
                Default::default(),
            ),
        );
        let mut lu = a.clone();
        let t = Instant::now();
        for _ in 0..reps {
            lu.copy_from(&a);
            faer::linalg::lu::partial_pivoting::factor::lu_in_place(
                lu.as_mut(),
                &mut fwd,
                &mut bwd,
                par,
                MemStack::new(&mut buf),
                Default::default(),
            );
            std::hint::black_box(&lu);
        }
        println!(
            "dense partial-piv LU {par:?}: {:.1} ms",
            t.elapsed().as_secs_f64() * 1e3 / reps as f64
        );
        if std::env::var("LU_TUNE").is_ok() {
            use faer::linalg::lu::partial_pivoting::factor::PartialPivLuParams;
            for (rt, bs) in [
                (16, 64),
                (32, 64),
                (16, 128),
                (32, 128),
                (64, 128),
                (16, 256),
                (8, 32),
            ] {
                let mut prm: PartialPivLuParams = faer::Auto::<f64>::auto();
                prm.recursion_threshold = rt;
                prm.block_size = bs;
                let t = Instant::now();
                for _ in 0..reps {
                    lu.copy_from(&a);
                    faer::linalg::lu::partial_pivoting::factor::lu_in_place(
                        lu.as_mut(),
                        &mut fwd,
                        &mut bwd,
                        par,
                        MemStack::new(&mut buf),
                        prm.into(),
                    );
                }
                println!(
                    "  rt {rt} bs {bs}: {:.1} ms",
                    t.elapsed().as_secs_f64() * 1e3 / reps as f64
                );
            }
        }
    }
}
