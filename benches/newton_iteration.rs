//! One Newton iteration of the elastoplastic hemisphere (`verification/hemisphere-plastic`)
//! refined from 17 × 17 to 65 × 65 particles: residual and tangent assembly, elimination of the
//! essential conditions, numeric factorisation with the solver `Method::auto` picks (symbolic
//! analysis done once, outside the timing) and one solve.
//!
//! `cargo bench --bench newton_iteration -- --sample-size 10` (`NEWTON_BENCH_GRIDS=17,33`
//! restricts the grids).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use shelldsa::io::shell_build::build;
use shelldsa::io::shell_case::read_shell_case;
use shelldsa::solver::{EssentialBc, LinearSolver, Method, NonlinearProblem, SolverOptions};
use std::hint::black_box;
use std::time::Duration;

fn newton_iteration(c: &mut Criterion) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("verification/hemisphere-plastic/case.toml");
    let grids: Vec<usize> = std::env::var("NEWTON_BENCH_GRIDS")
        .ok()
        .map(|s| s.split(',').filter_map(|g| g.trim().parse().ok()).collect())
        .unwrap_or_else(|| vec![17, 33, 49, 65]);
    let mut group = c.benchmark_group("hemisphere_plastic_newton_iteration");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(500));
    group.measurement_time(Duration::from_secs(10));
    for g in grids {
        let mut case = read_shell_case(&path).expect("shipped case");
        case.particles.counts = [g, g];
        let mut built = build(&case).expect("hemisphere builds");
        let pattern = built.problem.pattern().clone();
        let n = pattern.n_dofs();
        // A smooth deformed state (not an equilibrium): the tangent's values are generic.
        let u = built.problem.generic_state();
        let load = 10.0;
        let bc = EssentialBc::new(n, &built.problem.essential(load)).expect("constraints");
        let g0 = vec![0.0; bc.dofs().len()];
        let method = Method::auto(&pattern);
        let mut solver =
            LinearSolver::new(&pattern, method, SolverOptions::default()).expect("symbolic");
        let mut r = vec![0.0; n];
        let mut values = vec![0.0; pattern.nnz()];
        println!(
            "{g} × {g}: {n} unknowns, {} stored, {method:?}",
            pattern.nnz()
        );
        group.bench_with_input(BenchmarkId::new(format!("{method:?}"), g), &g, |b, _| {
            b.iter(|| {
                built
                    .problem
                    .residual_and_tangent(&u, load, &mut r, &mut values)
                    .expect("assembly");
                let mut rhs: Vec<f64> = r.iter().map(|x| -x).collect();
                bc.apply_with(&pattern, &mut values, &mut rhs, &g0)
                    .expect("elimination");
                solver.factorize(&values).expect("factorisation");
                solver.solve_in_place(&mut rhs).expect("solve");
                black_box(rhs)
            })
        });
    }
    group.finish();
}

criterion_group!(benches, newton_iteration);
criterion_main!(benches);
