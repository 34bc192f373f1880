//! Tests of the RK meshfree shape functions (`shelldsa::meshfree`).

use nalgebra::DMatrix;
use shelldsa::meshfree::*;
use shelldsa::scalar::{Dual, Real};
use shelldsa::verification::{check, CheckOptions, Differentiable};

/// Monomials `x^α`, |α| ≤ 2, as (exponent pair, value, gradient).
fn monomials(order: usize, x: [f64; 2]) -> Vec<([u32; 2], f64, [f64; 2])> {
    let mut out = Vec::new();
    for total in 0..=order as u32 {
        for i in 0..=total {
            let e = [i, total - i];
            let val = x[0].powi(e[0] as i32) * x[1].powi(e[1] as i32);
            let du = if e[0] == 0 {
                0.0
            } else {
                e[0] as f64 * x[0].powi(e[0] as i32 - 1) * x[1].powi(e[1] as i32)
            };
            let dv = if e[1] == 0 {
                0.0
            } else {
                e[1] as f64 * x[0].powi(e[0] as i32) * x[1].powi(e[1] as i32 - 1)
            };
            out.push((e, val, [du, dv]));
        }
    }
    out
}

/// Evaluation points: random interior points, random points on the four edges, the corners, and
/// points within 1e-3 of the boundary.
fn test_points(b: &ParamBox, n: usize, rng: &mut XorShift64) -> Vec<[f64; 2]> {
    let mut pts: Vec<[f64; 2]> = (0..n).map(|_| rng.point_in(b)).collect();
    let (lo, hi) = (b.lo, b.hi);
    pts.extend([lo, hi, [lo[0], hi[1]], [hi[0], lo[1]]]);
    for _ in 0..n / 4 {
        let u = rng.uniform(lo[0], hi[0]);
        let v = rng.uniform(lo[1], hi[1]);
        let eps = 1e-3 * rng.next_f64();
        pts.extend([[u, lo[1]], [u, hi[1]], [lo[0], v], [hi[0], v]]);
        pts.extend([[u, lo[1] + eps], [hi[0] - eps, v]]);
    }
    pts
}

/// Reproducing conditions on jittered particle sets.
///
/// Tolerance: `Σ_I Ψ_I p(x_I) − p(x)` is a sum of terms `Ψ_I p(x_I)`; its round-off is bounded by a
/// small multiple of `ε · Σ_I |Ψ_I p(x_I)|` (the magnitude of the terms, not of the result, which
/// may be zero), and likewise for the derivatives. The reproduction error equals the residual of the
/// backward-stable Cholesky solve `M b = H(0)`, so it is not amplified by the condition of `M`. We
/// require `|error| ≤ 1e-12 · max(1, Σ_I |terms|)`; measured worst values are printed (run with
/// `--nocapture`).
#[test]
fn reproducing_conditions_on_jittered_sets() {
    // A box away from the origin with unequal spacings exercises the basis scaling.
    let b = ParamBox::new([0.5, 2.0], [-1.0, 1.5]);
    let mut rng = XorShift64::new(7);
    let pts = test_points(&b, 300, &mut rng);
    let mut out = ShapeValues::new();
    for (basis, multiples) in [
        (Basis::Linear, [2.0, 2.5, 4.0]),
        (Basis::Quadratic, [3.0, 3.5, 4.0]),
    ] {
        let mut worst = [0.0_f64; 2];
        for (s, &mult) in multiples.iter().enumerate() {
            let grid = jittered_grid(b, 17, 23, 0.3, 11 + s as u64);
            let sf =
                ShapeFunctions::new(grid.positions.clone(), grid.supports(mult), basis).unwrap();
            for &x in &pts {
                sf.evaluate(x, &mut out).unwrap_or_else(|e| panic!("{e}"));
                for (e, val, grad) in monomials(basis.order(), x) {
                    let mut sum = [0.0; 3];
                    let mut mag = [0.0; 3];
                    for (i, psi, g) in out.iter() {
                        let p = grid.positions[i];
                        let pv = p[0].powi(e[0] as i32) * p[1].powi(e[1] as i32);
                        for (k, f) in [psi, g[0], g[1]].into_iter().enumerate() {
                            sum[k] += f * pv;
                            mag[k] += (f * pv).abs();
                        }
                    }
                    for (k, exact) in [val, grad[0], grad[1]].into_iter().enumerate() {
                        let err = (sum[k] - exact).abs() / mag[k].max(1.0);
                        worst[k.min(1)] = worst[k.min(1)].max(err);
                        assert!(
                            err <= 1e-12,
                            "{basis} basis, support {mult}h, x = {x:?}, x^{e:?}, component {k}: {} vs {exact} (scaled error {err:.2e})",
                            sum[k]
                        );
                    }
                }
            }
        }
        println!(
            "{basis} basis: worst scaled reproduction error: values {:.2e}, derivatives {:.2e}",
            worst[0], worst[1]
        );
    }
}

/// Regression value, reference-values §5: unit grid, tensor-product cubic B-spline with a = 2h,
/// linear basis, x = (5.3, 5.0): Ψ(5,5) = 0.393444444444, Ψ(6,5) = 0.232111111111. The reference is
/// given to 12 decimals, so 1e-11 is the tightest meaningful tolerance.
#[test]
fn regression_value_unit_grid() {
    let grid = regular_grid(ParamBox::new([0.0, 10.0], [0.0, 10.0]), 11, 11);
    assert_eq!(grid.spacing, [1.0, 1.0]);
    let sf =
        ShapeFunctions::new(grid.positions.clone(), grid.supports(2.0), Basis::Linear).unwrap();
    let mut out = ShapeValues::new();
    sf.evaluate([5.3, 5.0], &mut out).unwrap();
    let psi = |node: [f64; 2]| {
        let i = grid.positions.iter().position(|p| *p == node).unwrap();
        let k = out.neighbours().iter().position(|&j| j == i).unwrap();
        out.values()[k]
    };
    let (a, b) = (psi([5.0, 5.0]), psi([6.0, 5.0]));
    println!("Ψ(5,5) = {a:.15}, Ψ(6,5) = {b:.15}");
    assert!((a - 0.393444444444).abs() < 1e-11, "Ψ(5,5) = {a}");
    assert!((b - 0.232111111111).abs() < 1e-11, "Ψ(6,5) = {b}");
    // The generic kernel gives the same numbers.
    let (v, _) = rk_shape_functions(
        [5.3, 5.0],
        &grid.positions,
        &grid.supports(2.0),
        Basis::Linear,
    )
    .unwrap();
    for (i, (p, &vi)) in grid.positions.iter().zip(&v).enumerate() {
        let k = out.neighbours().iter().position(|&j| j == i);
        let hot = k.map_or(0.0, |k| out.values()[k]);
        assert!(
            (vi - hot).abs() <= 1e-15,
            "particle {p:?}: generic {vi} vs hot path {hot}"
        );
    }
}
