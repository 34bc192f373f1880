//! Structure and cost of a shell case's tangent for the sparse direct solvers: stored entries per
//! row, numerical asymmetry, the symmetric-structure factor (fill, flops, supernodes, largest
//! front) under the orderings on offer, and the time of one numeric factorisation with each
//! method.
//!
//! `cargo run --release --example solver_probe -- CASE.toml [GRID] [--methods sn,nd,metis,amd,lu,dense]`
//! (`GRID` overrides `particles.grid` with `GRID × GRID`; `sn` is the supernodal LU with its
//! default ordering, the cheapest of `nd`, `metis` and `amd` by estimate; `lu` faer's sparse LU,
//! `dense` the dense LU).
use shelldsa::io::shell_build::build;
use shelldsa::io::shell_case::read_shell_case;
use shelldsa::solver::{
    EssentialBc, FillOrdering, LinearSolver, Method, NonlinearProblem, Parallelism, SolverOptions,
};
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = std::path::PathBuf::from(&args[1]);
    let mut case = read_shell_case(&path).unwrap();
    if let Some(g) = args.get(2).and_then(|s| s.parse::<usize>().ok()) {
        case.particles.counts = [g, g];
    }
    let methods = args
        .iter()
        .position(|a| a == "--methods")
        .map(|i| args[i + 1].clone())
        .unwrap_or_else(|| "sn".into());
    let mut built = build(&case).unwrap();
    let pattern = built.problem.pattern().clone();
    let n = pattern.n_dofs();
    let u = built.problem.generic_state();
    let mut r = vec![0.0; n];
    let mut values = vec![0.0; pattern.nnz()];
    let p = &mut built.problem;
    let t = Instant::now();
    p.residual_and_tangent(&u, 10.0, &mut r, &mut values)
        .unwrap();
    let t_asm = t.elapsed().as_secs_f64();
    let bc = EssentialBc::new(n, &p.essential(10.0)).unwrap();
    let mut rhs: Vec<f64> = r.iter().map(|x| -x).collect();
    let g0 = vec![0.0; bc.dofs().len()];
    bc.apply_with(&pattern, &mut values, &mut rhs, &g0).unwrap();
    // Numerical asymmetry ‖A − Aᵀ‖_F / ‖A‖_F over the stored entries.
    let (cp, ri) = (pattern.col_ptr(), pattern.row_idx());
    let (mut skew, mut all) = (0.0f64, 0.0f64);
    let mut structurally_symmetric = true;
    for j in 0..n {
        for q in cp[j]..cp[j + 1] {
            let i = ri[q];
            all += values[q] * values[q];
            match pattern.slot(j, i) {
                Some(s) => skew += (values[q] - values[s]).powi(2),
                None => structurally_symmetric = false,
            }
        }
    }
    let runs: usize = (0..n).map(|j| pattern.column_runs(j).len()).sum();
    println!(
        "grid {:?}: n = {n}, nnz = {} ({:.1} per row, {:.1} % of n², {:.1} rows per run of \
         consecutive rows), structurally symmetric: {structurally_symmetric}, ‖A−Aᵀ‖/‖A‖ = \
         {:.2e}, assembly {:.3} s",
        case.particles.counts,
        pattern.nnz(),
        pattern.nnz() as f64 / n as f64,
        100.0 * pattern.nnz() as f64 / (n * n) as f64,
        pattern.nnz() as f64 / runs as f64,
        (skew / 2.0).sqrt() / all.sqrt(),
        t_asm
    );
    let reps = std::env::var("PROBE_REPS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3usize);
    for m in methods.split(',') {
        let (method, par) = match m {
            "lu" => (Method::Lu, Parallelism::Sequential),
            "dense" => (Method::DenseLu, Parallelism::Rayon(0)),
            "sn" | "nd" | "amd" | "metis" => (Method::SupernodalLu, Parallelism::Sequential),
            _ => {
                eprintln!(
                    "--methods: unknown method `{m}`; expected sn, nd, metis, amd, lu or dense"
                );
                std::process::exit(1);
            }
        };
        let t = Instant::now();
        let options = SolverOptions {
            parallelism: par,
            ..Default::default()
        };
        let mut solver = match m {
            "amd" => LinearSolver::supernodal(&pattern, FillOrdering::Amd, options),
            "metis" => LinearSolver::supernodal(&pattern, FillOrdering::Metis, options),
            "nd" => LinearSolver::supernodal(&pattern, FillOrdering::NestedDissection, options),
            _ => LinearSolver::new(&pattern, method, options),
        }
        .unwrap();
        let t_sym = t.elapsed().as_secs_f64();
        if let Some(s) = solver.structure() {
            println!("  {m}: {s}");
        }
        solver.factorize(&values).unwrap();
        let t = Instant::now();
        let c = cpu_seconds();
        for _ in 0..reps {
            solver.factorize(&values).unwrap();
        }
        let t_num = t.elapsed().as_secs_f64() / reps as f64;
        let c_num = (cpu_seconds() - c) / reps as f64;
        let mut x = rhs.clone();
        solver.solve_in_place(&mut x).unwrap();
        let t = Instant::now();
        for _ in 0..reps {
            x.copy_from_slice(&rhs);
            solver.solve_in_place(&mut x).unwrap();
        }
        let t_solve = t.elapsed().as_secs_f64() / reps as f64;
        let mut ax = vec![0.0; n];
        let t = Instant::now();
        for _ in 0..reps {
            pattern.mat_vec(&values, &x, &mut ax).unwrap();
        }
        let t_mv = t.elapsed().as_secs_f64() / reps as f64;
        let res = ax
            .iter()
            .zip(&rhs)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt()
            / rhs.iter().map(|b| b * b).sum::<f64>().sqrt();
        println!(
            "  {m} ({par:?}): symbolic {t_sym:.3} s, numeric {t_num:.5} s wall, {c_num:.3} s CPU (incl. probe), \
             solve {t_solve:.4} s, product {t_mv:.4} s, relative residual {res:.1e}, \
             {} of {} factorisations redone by the sparse LU",
            solver.n_fallbacks(),
            solver.n_factorizations()
        );
        println!(
            "  {m}: one factorisation = {:.1} (solve + product) measured, {:.1} estimated \
             (LinearSolver::refactorisation_cost)",
            t_num / (t_solve + t_mv),
            solver.refactorisation_cost()
        );
    }
}

/// User + system CPU time of the process (all threads), from `/proc/self/stat`.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let fields: Vec<&str> = stat
        .rsplit_once(')')
        .map(|(_, r)| r.split_whitespace().collect())
        .unwrap_or_default();
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    // utime and stime are fields 14 and 15 of the line, 11 and 12 after the command name.
    (ticks(11) + ticks(12)) / 100.0
}
