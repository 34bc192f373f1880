//! Shell assembly cost on the paper's hemisphere discretisation: quarter model, 17 × 17
//! particles (1445 DOFs), quadratic basis, support 3 spacings, 16 × 16 background cells with
//! 3 × 3 Gauss points, 5 Lobatto points through the thickness (11,520 material points).
//! Run: `cargo bench --bench shell` (threads: `RAYON_NUM_THREADS`).
//!
//! Groups: the residual alone; residual and tangent as `ShellModel::contributions` computes them
//! (the fast tangent of `shell::tangent`, all layers of an in-plane point at once); and the same
//! with the reference tangent `shell::point::point_tangent` (one directional sweep per DOF and
//! layer), assembled here the way the model did before, so that the ratio is visible.

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{DMatrix, Vector3};
use rayon::prelude::*;
use shelldsa::geometry::{SphereZone, Surface};
use shelldsa::material::MaterialParams;
use shelldsa::meshfree::quadrature::{gauss_lobatto, CellQuadrature};
use shelldsa::meshfree::{regular_grid, Basis, ParamBox};
use shelldsa::shell::model::{Discretisation, ShellModel};
use shelldsa::shell::point::{point_residual, point_tangent, PointInput};
use shelldsa::shell::tangent::ThicknessTangent;
use std::hint::black_box;

fn hemisphere() -> ShellModel {
    let sphere = SphereZone::new(
        Vector3::zeros(),
        10.0,
        [0.0, 72f64.to_radians()],
        [0.0, 90f64.to_radians()],
    )
    .unwrap();
    let grid = regular_grid(ParamBox::unit(), 17, 17);
    let cq = CellQuadrature::for_particle_grid(&grid, 1, 3).unwrap();
    let lob = gauss_lobatto(5).unwrap();
    let disc = Discretisation {
        particle_uv: grid.positions.clone(),
        supports: grid.supports(3.0),
        basis: Basis::Quadratic,
        kernel: Default::default(),
        quadrature: cq.iter().map(|(p, w, _)| (p, w)).collect(),
        thickness_rule: lob
            .nodes
            .iter()
            .copied()
            .zip(lob.weights.iter().copied())
            .collect(),
        thickness: 0.04,
        symmetry: Vec::new(),
    };
    let material = MaterialParams::new(6.825e7, 0.3, 2.43e5, 3.0e5, 1.0).unwrap();
    ShellModel::new(&Surface::SphereZone(sphere), disc, material).unwrap()
}

/// Residual and tangent of in-plane point `k` into `r` and `km` (zeroed here), with the reference
/// sweep layer by layer (`fast = false`) or the fast layer sum.
fn point_kernels(
    m: &ShellModel,
    k: usize,
    x: &[f64],
    fast: bool,
    r: &mut Vec<f64>,
    km: &mut DMatrix<f64>,
) {
    let nl = m.thickness_rule.len();
    let p = &m.points[k];
    let (parts, xl) = m.gather_local(k, x);
    let nd = xl.len();
    r.clear();
    r.resize(nd, 0.0);
    if km.nrows() != nd {
        *km = DMatrix::zeros(nd, nd);
    } else {
        km.as_mut_slice().fill(0.0);
    }
    let mut sum = ThicknessTangent::new(&p.shape, &parts, &xl).unwrap();
    for (l, &(zeta, wz)) in m.thickness_rule.iter().enumerate() {
        let inp = PointInput {
            surface: &p.surface,
            zeta,
            thickness: m.thickness,
            weight: p.weight * wz,
            shape: &p.shape,
            particles: &parts,
            material: &m.material,
            history: &m.history[k * nl + l],
            director: m.director,
        };
        let res = point_residual(&inp, &xl).unwrap();
        for (a, b) in r.iter_mut().zip(&res.residual) {
            *a += b;
        }
        if fast {
            sum.add_layer(&inp, &res).unwrap();
        } else {
            *km += point_tangent(&inp, &xl, &res).unwrap();
        }
    }
    if fast {
        sum.add_to(km).unwrap();
    }
}

/// Residual and tangent of every in-plane point with the reference sweep, kept per point as
/// `ShellModel::contributions` keeps them.
fn reference_contributions(m: &ShellModel, x: &[f64]) -> Vec<(Vec<f64>, DMatrix<f64>)> {
    (0..m.points.len())
        .into_par_iter()
        .map(|k| {
            let mut r = Vec::new();
            let mut km = DMatrix::zeros(0, 0);
            point_kernels(m, k, x, false, &mut r, &mut km);
            (r, km)
        })
        .collect()
}

/// The point kernels alone: every in-plane point's residual and tangent into one reused buffer
/// per thread (no per-point matrix is kept, so memory allocation and first-touch page faults
/// drop out). Returns a checksum.
fn kernels_only(m: &ShellModel, x: &[f64], fast: bool) -> f64 {
    (0..m.points.len())
        .into_par_iter()
        .map_init(
            || (Vec::new(), DMatrix::zeros(0, 0)),
            |(r, km), k| {
                point_kernels(m, k, x, fast, r, km);
                km[(0, 0)] + r[0]
            },
        )
        .sum()
}

fn bench(c: &mut Criterion) {
    let m = hemisphere();
    let x: Vec<f64> = (0..m.n_dofs())
        .map(|j| 1e-4 * ((j as f64) * 0.37).sin())
        .collect();
    let nb: usize = m.points.iter().map(|p| p.neighbours.len()).sum();
    println!(
        "hemisphere: {} DOFs, {} in-plane points × {} layers, {:.1} neighbours per point on average, {} threads",
        m.n_dofs(),
        m.points.len(),
        m.thickness_rule.len(),
        nb as f64 / m.points.len() as f64,
        rayon::current_num_threads()
    );
    let mut g = c.benchmark_group("shell_hemisphere_17x17");
    g.sample_size(10);
    g.bench_function("residual", |b| {
        b.iter(|| black_box(m.contributions(black_box(&x), false).unwrap()))
    });
    g.bench_function("residual_and_tangent", |b| {
        b.iter(|| black_box(m.contributions(black_box(&x), true).unwrap()))
    });
    g.bench_function("residual_and_tangent_reference_sweep", |b| {
        b.iter(|| black_box(reference_contributions(&m, black_box(&x))))
    });
    g.bench_function("point_kernels_fast", |b| {
        b.iter(|| black_box(kernels_only(&m, black_box(&x), true)))
    });
    g.bench_function("point_kernels_reference_sweep", |b| {
        b.iter(|| black_box(kernels_only(&m, black_box(&x), false)))
    });
    g.finish();
}

/// The elastoplastic hemisphere of `verification/hemisphere-plastic/case.toml` as the CLI builds
/// it (quarter model, 17 × 17 particles, 2 × 2 Gauss points per cell, image particles), on 1 and
/// on 2 threads (a local rayon pool; faer's LU runs serial on 1 thread and on the pool on 2):
/// assembly of the residual and of residual + tangent (throughput per particle), the point
/// kernels of that assembly alone (`point_kernels_into_cells`), numeric LU,
/// one solve, and the whole run to P = 100 without output (sample size 10: about 10–25 s per
/// sample). Run: `cargo bench --bench shell -- hemisphere_plastic` (the whole run alone:
/// `-- hemisphere_plastic/run`).
fn bench_plastic(c: &mut Criterion) {
    use criterion::{BenchmarkId, Throughput};
    use shelldsa::io::shell_build::build;
    use shelldsa::io::shell_case::read_shell_case;
    use shelldsa::solver::{LinearSolver, Method, NonlinearProblem, Parallelism, SolverOptions};
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("verification/hemisphere-plastic/case.toml");
    let case = read_shell_case(&path).unwrap();
    let mut built = build(&case).unwrap();
    let pattern = built.problem.pattern().clone();
    let n = pattern.n_dofs();
    let nq = built.problem.n_generalised();
    // A state with a strain level of the run (displacements ~ 1e-2, rotations ~ 1e-3).
    let u = built.problem.generic_state();
    let mut r = vec![0.0; n];
    let mut values = vec![0.0; pattern.nnz()];
    println!(
        "hemisphere-plastic: {} particles, {n} unknowns, {} stored entries",
        built.n_particles,
        pattern.nnz()
    );
    let mut g = c.benchmark_group("hemisphere_plastic");
    g.sample_size(10);
    for threads in [1usize, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let par = if threads == 1 {
            Parallelism::Sequential
        } else {
            Parallelism::Rayon(0)
        };
        let t = format!("{threads}_threads");
        g.throughput(Throughput::Elements(built.n_particles as u64));
        let p = &mut built.problem;
        // The tangent the factorisation benchmarks below use, also when a filter skips the
        // assembly's own benchmark.
        p.residual_and_tangent(&u, 10.0, &mut r, &mut values)
            .unwrap();
        g.bench_function(BenchmarkId::new("residual", &t), |b| {
            b.iter(|| pool.install(|| p.residual(black_box(&u), 10.0, &mut r).unwrap()))
        });
        g.bench_function(BenchmarkId::new("residual_and_tangent", &t), |b| {
            b.iter(|| {
                pool.install(|| {
                    p.residual_and_tangent(black_box(&u), 10.0, &mut r, &mut values)
                        .unwrap()
                })
            })
        });
        // The point kernels alone (`ShellModel::add_to_cell`, residual + tangent of every
        // in-plane point into a per-thread cell buffer reused from point to point): the part of
        // `residual_and_tangent` before the solver's zeroing and scatter of the cell buffers.
        let model = &p.model;
        let q: Vec<f64> = u[..nq].to_vec();
        g.bench_function(BenchmarkId::new("point_kernels_into_cells", &t), |b| {
            b.iter(|| {
                pool.install(|| {
                    (0..model.points.len())
                        .into_par_iter()
                        .map_init(
                            || (Vec::new(), Vec::new()),
                            |(kb, fb): &mut (Vec<f64>, Vec<f64>), k| {
                                let nc = 5 * model.points[k].sources.len();
                                kb.clear();
                                kb.resize(nc * nc, 0.0);
                                fb.clear();
                                fb.resize(nc, 0.0);
                                model.add_to_cell(k, black_box(&q), fb, Some(kb)).unwrap();
                                kb[0] + fb[0]
                            },
                        )
                        .sum::<f64>()
                })
            })
        });
        g.throughput(Throughput::Elements(1));
        let opts = SolverOptions {
            parallelism: par,
            singularity_probe: None,
            ..SolverOptions::default()
        };
        let mut solver = LinearSolver::new(&pattern, Method::Lu, opts).unwrap();
        let mut dense = LinearSolver::new(&pattern, Method::auto(&pattern), opts).unwrap();
        // The essential DOFs of the symmetry planes as the driver eliminates them.
        let bc = shelldsa::solver::EssentialBc::new(n, &p.essential(10.0)).unwrap();
        let mut rhs: Vec<f64> = r.iter().map(|x| -x).collect();
        let g0 = vec![0.0; bc.dofs().len()];
        bc.apply_with(&pattern, &mut values, &mut rhs, &g0).unwrap();
        g.bench_function(BenchmarkId::new("factorize_lu", &t), |b| {
            b.iter(|| pool.install(|| solver.factorize(black_box(&values)).unwrap()))
        });
        // The method `shelldsa run` picks for this pattern (dense: 29.5 % of the entries stored).
        g.bench_function(BenchmarkId::new("factorize_auto", &t), |b| {
            b.iter(|| pool.install(|| dense.factorize(black_box(&values)).unwrap()))
        });
        solver.factorize(&values).unwrap();
        let mut x = rhs.clone();
        g.bench_function(BenchmarkId::new("solve", &t), |b| {
            b.iter(|| {
                x.copy_from_slice(&rhs);
                pool.install(|| solver.solve_in_place(black_box(&mut x)).unwrap())
            })
        });
        g.bench_function(BenchmarkId::new("run", &t), |b| {
            b.iter(|| {
                pool.install(|| {
                    let mut fresh = build(&case).unwrap();
                    let pat = fresh.problem.pattern().clone();
                    let mut s = LinearSolver::new(
                        &pat,
                        Method::auto(&pat),
                        SolverOptions {
                            parallelism: par,
                            ..SolverOptions::default()
                        },
                    )
                    .unwrap();
                    let u0 = vec![0.0; pat.n_dofs()];
                    let report = fresh
                        .newton
                        .run(&mut fresh.problem, &pat, &mut s, &u0)
                        .unwrap();
                    black_box(report.attempts.len())
                })
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench, bench_plastic);
criterion_main!(benches);
