//! Shell assembly cost on the paper's hemisphere discretisation: quarter model, 17 × 17
//! particles (1445 DOFs), quadratic basis, support 3 spacings, 16 × 16 background cells with
//! 3 × 3 Gauss points, 5 Lobatto points through the thickness (11,520 material points).
//! Run: `cargo bench --bench shell`.

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::Vector3;
use shelldsa::geometry::{SphereZone, Surface};
use shelldsa::material::MaterialParams;
use shelldsa::meshfree::quadrature::{gauss_lobatto, CellQuadrature};
use shelldsa::meshfree::{regular_grid, Basis, ParamBox};
use shelldsa::shell::model::{Discretisation, ShellModel};
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

fn bench(c: &mut Criterion) {
    let m = hemisphere();
    let x: Vec<f64> = (0..m.n_dofs())
        .map(|j| 1e-4 * ((j as f64) * 0.37).sin())
        .collect();
    let nb: usize = m.points.iter().map(|p| p.neighbours.len()).sum();
    println!(
        "hemisphere: {} DOFs, {} in-plane points × {} layers, {:.1} neighbours per point on average",
        m.n_dofs(),
        m.points.len(),
        m.thickness_rule.len(),
        nb as f64 / m.points.len() as f64
    );
    let mut g = c.benchmark_group("shell_hemisphere_17x17");
    g.sample_size(10);
    g.bench_function("residual", |b| {
        b.iter(|| black_box(m.contributions(black_box(&x), false).unwrap()))
    });
    g.bench_function("residual_and_tangent", |b| {
        b.iter(|| black_box(m.contributions(black_box(&x), true).unwrap()))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
