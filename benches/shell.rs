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

criterion_group!(benches, bench);
criterion_main!(benches);
