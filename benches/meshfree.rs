//! RK shape functions and first derivatives per evaluation point (f64 hot path), plus the
//! neighbour query alone and the generic kernel with dual numbers for comparison.

use criterion::{criterion_group, criterion_main, Criterion};
use shelldsa::meshfree::{
    jittered_grid, rk_shape_functions_sparse, Basis, ParamBox, ShapeFunctions, ShapeValues,
    XorShift64,
};
use shelldsa::scalar::Dual;
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    // 60 × 60 jittered particles on the unit square, support 3 spacings.
    let grid = jittered_grid(ParamBox::unit(), 60, 60, 0.3, 1);
    let supports = grid.supports(3.0);
    let mut rng = XorShift64::new(2);
    let points: Vec<[f64; 2]> = (0..1024).map(|_| rng.point_in(&ParamBox::unit())).collect();

    for basis in [Basis::Quadratic, Basis::Linear] {
        let sf = ShapeFunctions::new(grid.positions.clone(), supports.clone(), basis).unwrap();
        let mut out = ShapeValues::with_capacity(64);
        let mut k = 0;
        c.bench_function(
            &format!("rk {basis} support 3h f64: values + gradients per point"),
            |b| {
                b.iter(|| {
                    k = (k + 1) % points.len();
                    sf.evaluate(black_box(points[k]), &mut out).unwrap();
                    black_box(out.values()[0])
                })
            },
        );
    }

    let sf =
        ShapeFunctions::new(grid.positions.clone(), supports.clone(), Basis::Quadratic).unwrap();
    let mut nbrs = Vec::with_capacity(64);
    let mut k = 0;
    c.bench_function("support grid query (support 3h)", |b| {
        b.iter(|| {
            k = (k + 1) % points.len();
            sf.grid().covering(black_box(points[k]), &mut nbrs);
            black_box(nbrs.len())
        })
    });

    // Generic kernel, one dual direction (seeded in u), allocating its outputs.
    let pd: Vec<[Dual; 2]> = grid
        .positions
        .iter()
        .map(|p| [Dual::from_re(p[0]), Dual::from_re(p[1])])
        .collect();
    let ad: Vec<[Dual; 2]> = supports
        .iter()
        .map(|a| [Dual::from_re(a[0]), Dual::from_re(a[1])])
        .collect();
    let mut k = 0;
    c.bench_function("rk quadratic support 3h Dual64 (generic, sparse)", |b| {
        b.iter(|| {
            k = (k + 1) % points.len();
            let x = points[k];
            sf.grid().covering(x, &mut nbrs);
            let xd = [Dual::from_re(x[0]).derivative(), Dual::from_re(x[1])];
            let (v, _) = rk_shape_functions_sparse(xd, &pd, &ad, Basis::Quadratic, &nbrs).unwrap();
            black_box(v[0])
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
