//! Return-map throughput (points per second), f64 and dual numbers, plus the hand-derived tangent
//! and sensitivity update. Run: `cargo bench --bench return_map`.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use shelldsa::material::{
    consistent_tangent, material_sensitivity, return_map, MaterialParams, MaterialState, ReturnMap,
    Vec5,
};
use shelldsa::scalar::{seed, Dual, DualN};
use std::hint::black_box;

const N: usize = 1000;

/// N material points: a loaded history and a strain increment each, half of them plastic.
type Points = Vec<(MaterialState<f64>, Vec5<f64>)>;

fn points() -> (MaterialParams<f64>, Points) {
    let m = MaterialParams::new(210_000.0, 0.3, 250.0, 1000.0, 0.5).unwrap();
    let pts = (0..N)
        .map(|k| {
            let t = k as f64 * 0.618;
            let dir = Vec5::new(
                t.cos(),
                (1.3 * t).sin(),
                0.5 * (0.7 * t).cos(),
                0.2 * t.sin(),
                -0.1,
            );
            let n = return_map(&m, &MaterialState::virgin(), &(dir * 2e-3))
                .unwrap()
                .state;
            let sign = if k % 2 == 0 { 1.0 } else { -0.3 };
            (n, dir * (4e-4 * sign))
        })
        .collect();
    (m, pts)
}

fn bench(c: &mut Criterion) {
    let (m, pts) = points();
    let mut g = c.benchmark_group("return_map");
    g.throughput(Throughput::Elements(N as u64));
    g.bench_function(BenchmarkId::new("f64", N), |b| {
        b.iter(|| {
            for (n, e) in &pts {
                black_box(return_map(&m, black_box(n), black_box(e)).unwrap());
            }
        })
    });
    let md: MaterialParams<Dual> = MaterialParams {
        young: Dual::from_re(m.young).derivative(),
        ..m.lift()
    };
    let ptsd: Vec<(MaterialState<Dual>, Vec5<Dual>)> = pts
        .iter()
        .map(|(n, e)| (n.lift(), e.map(Dual::from_re)))
        .collect();
    g.bench_function(BenchmarkId::new("Dual64", N), |b| {
        b.iter(|| {
            for (n, e) in &ptsd {
                black_box(return_map(&md, black_box(n), black_box(e)).unwrap());
            }
        })
    });
    let mv: MaterialParams<DualN<4>> = MaterialParams {
        young: seed(m.young, 0),
        sigma0: seed(m.sigma0, 1),
        hardening: seed(m.hardening, 2),
        beta: seed(m.beta, 3),
        ..m.lift()
    };
    let ptsv: Vec<(MaterialState<DualN<4>>, Vec5<DualN<4>>)> = pts
        .iter()
        .map(|(n, e)| (n.lift(), e.map(DualN::<4>::from_re)))
        .collect();
    g.bench_function(BenchmarkId::new("DualSVec64<4>", N), |b| {
        b.iter(|| {
            for (n, e) in &ptsv {
                black_box(return_map(&mv, black_box(n), black_box(e)).unwrap());
            }
        })
    });
    let outs: Vec<ReturnMap<f64>> = pts
        .iter()
        .map(|(n, e)| return_map(&m, n, e).unwrap())
        .collect();
    g.bench_function(BenchmarkId::new("consistent_tangent", N), |b| {
        b.iter(|| {
            for o in &outs {
                black_box(consistent_tangent(&m, black_box(o)));
            }
        })
    });
    let dm = MaterialParams::from_array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    let dn = MaterialState {
        stress: Vec5::repeat(1.0),
        back_stress: Vec5::repeat(0.1),
        eps_p: 1e-3,
    };
    g.bench_function(BenchmarkId::new("material_sensitivity", N), |b| {
        b.iter(|| {
            for ((_, e), o) in pts.iter().zip(&outs) {
                black_box(material_sensitivity(
                    &m,
                    e,
                    o,
                    &dm,
                    &dn,
                    &Vec5::repeat(1e-4),
                ));
            }
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
