//! Global linear algebra on a pattern resembling a meshfree shell: 30×30 particles, 5 DOFs each
//! (3 displacements, 2 director rotations), every particle's support coupling the particles
//! within 2 spacings (13 particles, 65 DOFs per cell); 4500 unknowns, one edge clamped.
//! Symbolic analysis once; measured: assembly (serial / parallel), numeric factorisation (LU and
//! Cholesky, faer sequential / rayon), solves with 1, 4, 16 right-hand sides, and one full
//! Newton iteration (assemble + eliminate + factorise + solve). Also the sparse products of the
//! Krylov solves (`csc_mul`, and `csc_mul_columns` with 4 columns) on the plastic hemisphere's
//! pattern shape at 33 × 33 and 65 × 65 particles (each column coupling the 11 × 11
//! particles around its own, as the cells of 6 × 6 neighbours do).
//! Run: `cargo bench --bench solver` (products alone: `cargo bench --bench solver -- product`).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use nalgebra::{DMatrix, DVector};
use shelldsa::solver::{
    assemble, krylov, EssentialBc, Execution, LinearSolver, Method, Parallelism, SolverOptions,
    SparsityPattern,
};
use std::convert::Infallible;
use std::hint::black_box;
use std::time::Duration;

const NX: usize = 30;
const DOF: usize = 5;

struct Model {
    pattern: SparsityPattern,
    centres: Vec<usize>,
    bc: EssentialBc,
}

fn model() -> Model {
    let mut cells = Vec::new();
    let mut centres = Vec::new();
    for i in 0..NX {
        for j in 0..NX {
            let mut dofs = Vec::new();
            for a in i.saturating_sub(2)..(i + 3).min(NX) {
                for b in j.saturating_sub(2)..(j + 3).min(NX) {
                    let (di, dj) = (a as f64 - i as f64, b as f64 - j as f64);
                    if di * di + dj * dj <= 4.0 {
                        let p = a * NX + b;
                        dofs.extend((0..DOF).map(|d| p * DOF + d));
                    }
                }
            }
            cells.push(dofs);
            centres.push(i * NX + j);
        }
    }
    let n = NX * NX * DOF;
    let pattern = SparsityPattern::from_cells(n, &cells).unwrap();
    let clamped: Vec<(usize, f64)> = (0..NX * DOF).map(|d| (d, 0.0)).collect();
    Model {
        pattern,
        centres,
        bc: EssentialBc::new(n, &clamped).unwrap(),
    }
}

/// Cell matrix: a weighted graph Laplacian of the support (SPD after clamping) with a DOF
/// coupling block, plus `skew` times an antisymmetric part (unsymmetric tangent for LU).
fn local(m: &Model, c: usize, skew: f64) -> (DMatrix<f64>, DVector<f64>) {
    let dofs = m.pattern.cell_dofs(c);
    let nodes: Vec<usize> = dofs.iter().step_by(DOF).map(|d| d / DOF).collect();
    let pos = |p: usize| ((p / NX) as f64, (p % NX) as f64);
    let (ci, cj) = pos(m.centres[c]);
    let nn = nodes.len();
    let mut k = DMatrix::zeros(nn * DOF, nn * DOF);
    for a in 0..nn {
        let (ai, aj) = pos(nodes[a]);
        let wa = (-((ai - ci).powi(2) + (aj - cj).powi(2)) / 4.0).exp();
        for b in 0..nn {
            let (bi, bj) = pos(nodes[b]);
            let wb = (-((bi - ci).powi(2) + (bj - cj).powi(2)) / 4.0).exp();
            let lap = if a == b { wa * (1.0 + 1e-3) } else { 0.0 } - wa * wb / nn as f64;
            for d in 0..DOF {
                for e in 0..DOF {
                    let block = if d == e {
                        1.0
                    } else {
                        0.1 / (1.0 + (d + e) as f64)
                    };
                    let asym = skew * (d as f64 - e as f64 + (a as f64 - b as f64) * 0.1);
                    k[(a * DOF + d, b * DOF + e)] = lap * block + lap.abs() * asym;
                }
            }
        }
    }
    let f = DVector::from_fn(nn * DOF, |r, _| ((c + r) as f64 * 0.37).sin());
    (k, f)
}

fn system(m: &Model, skew: f64, exec: Execution) -> (Vec<f64>, Vec<f64>) {
    let mut values = vec![0.0; m.pattern.nnz()];
    let mut rhs = vec![0.0; m.pattern.n_dofs()];
    assemble(&m.pattern, &mut values, &mut rhs, exec, |c| {
        Ok::<_, Infallible>(local(m, c, skew))
    })
    .unwrap();
    m.bc.apply(&m.pattern, &mut values, &mut rhs).unwrap();
    (values, rhs)
}

fn bench(c: &mut Criterion) {
    let m = model();
    let n = m.pattern.n_dofs();
    eprintln!(
        "pattern: {n} DOFs, {} cells, {} stored entries ({:.1} per row)",
        m.pattern.n_cells(),
        m.pattern.nnz(),
        m.pattern.nnz() as f64 / n as f64
    );
    let mut g = c.benchmark_group("solver");
    g.sample_size(10).warm_up_time(Duration::from_millis(500));
    g.measurement_time(Duration::from_secs(3));

    for exec in [Execution::Serial, Execution::Parallel] {
        g.bench_function(BenchmarkId::new("assemble", format!("{exec:?}")), |b| {
            let mut values = vec![0.0; m.pattern.nnz()];
            let mut rhs = vec![0.0; n];
            b.iter(|| {
                assemble(&m.pattern, &mut values, &mut rhs, exec, |c| {
                    Ok::<_, Infallible>(local(&m, c, 0.05))
                })
                .unwrap();
                black_box(&values);
            })
        });
    }

    let (lu_values, _) = system(&m, 0.05, Execution::Parallel);
    let (spd_values, _) = system(&m, 0.0, Execution::Parallel);
    for (method, values) in [(Method::Lu, &lu_values), (Method::Cholesky, &spd_values)] {
        for par in [Parallelism::Sequential, Parallelism::Rayon(0)] {
            let opts = SolverOptions {
                parallelism: par,
                ..Default::default()
            };
            let mut solver = LinearSolver::new(&m.pattern, method, opts).unwrap();
            solver.factorize(values).unwrap();
            g.bench_function(
                BenchmarkId::new(format!("factorize/{method:?}"), format!("{par:?}")),
                |b| b.iter(|| solver.factorize(black_box(values)).unwrap()),
            );
            if method == Method::Lu && par == Parallelism::Sequential {
                let mut probe_off = LinearSolver::new(
                    &m.pattern,
                    method,
                    SolverOptions {
                        singularity_probe: None,
                        ..opts
                    },
                )
                .unwrap();
                g.bench_function(
                    BenchmarkId::new("factorize/Lu-no-probe", format!("{par:?}")),
                    |b| b.iter(|| probe_off.factorize(black_box(values)).unwrap()),
                );
            }
            for k in [1usize, 4, 16] {
                let rhs: Vec<f64> = (0..n * k).map(|i| (i as f64 * 0.1).sin()).collect();
                let mut x = rhs.clone();
                g.bench_function(
                    BenchmarkId::new(format!("solve/{method:?}/{par:?}"), format!("k={k}")),
                    |b| {
                        b.iter(|| {
                            x.copy_from_slice(&rhs);
                            solver.solve_columns_in_place(&mut x, k).unwrap();
                            black_box(&x);
                        })
                    },
                );
            }
        }
    }

    for nx in [33usize, 65] {
        let p = SparsityPattern::particle_grid(nx, DOF, 5).unwrap();
        let values = p.values_from(|i, j| 1.0 / (1.0 + i.abs_diff(j) as f64));
        let np = p.n_dofs();
        let x: Vec<f64> = (0..4 * np).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut y = vec![0.0; 4 * np];
        g.bench_function(
            BenchmarkId::new("product/csc_mul", format!("{nx}x{nx}")),
            |b| {
                b.iter(|| {
                    krylov::csc_mul(&p, &values, black_box(&x[..np]), &mut y[..np]);
                    black_box(&y);
                })
            },
        );
        g.bench_function(
            BenchmarkId::new("product/csc_mul_columns/k=4", format!("{nx}x{nx}")),
            |b| {
                b.iter(|| {
                    krylov::csc_mul_columns(&p, &values, black_box(&x), 4, &mut y);
                    black_box(&y);
                })
            },
        );
    }

    let mut solver = LinearSolver::new(&m.pattern, Method::Lu, SolverOptions::default()).unwrap();
    g.bench_function("newton_iteration/Lu", |b| {
        b.iter(|| {
            let (values, mut rhs) = system(&m, 0.05, Execution::Parallel);
            solver.factorize(&values).unwrap();
            solver.solve_in_place(&mut rhs).unwrap();
            black_box(&rhs);
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
