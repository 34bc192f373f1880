//! Patch test of RK Galerkin with cell quadrature and essential conditions at the boundary
//! particles (the Poisson problem on the unit square).

mod common;

use nalgebra::DMatrix;
use shelldsa::meshfree::quadrature::{gauss_legendre, CellQuadrature};
use shelldsa::meshfree::*;

/// `Σ_I Ψ_I(x) d_I`.
fn approx_at(sf: &ShapeFunctions, x: [f64; 2], d: &[f64]) -> f64 {
    let mut sv = ShapeValues::new();
    sf.evaluate(x, &mut sv).unwrap();
    sv.iter().map(|(i, v, _)| v * d[i]).sum()
}

/// Assemble the RK Galerkin system of `−Δu = s` on the box: `K_IJ = ∫ ∇Ψ_I·∇Ψ_J`,
/// `f_I = ∫ s Ψ_I + ∮ Ψ_I ∂u/∂n`. The boundary flux term is included because the test functions
/// vanish only *at* the constrained particles, not along the edge between them.
fn assemble_poisson(
    sf: &ShapeFunctions,
    q: &CellQuadrature,
    edge_rule_cells: usize,
    source: f64,
    grad_exact: impl Fn([f64; 2]) -> [f64; 2],
) -> (DMatrix<f64>, Vec<f64>) {
    let n = sf.len();
    let mut k = DMatrix::zeros(n, n);
    let mut f = vec![0.0; n];
    let mut sv = ShapeValues::new();
    for (x, w, _) in q.iter() {
        sf.evaluate(x, &mut sv).unwrap();
        for (a, va, ga) in sv.iter() {
            f[a] += w * source * va;
            for (bb, _, gb) in sv.iter() {
                k[(a, bb)] += w * (ga[0] * gb[0] + ga[1] * gb[1]);
            }
        }
    }
    let b = q.param_box();
    let r = gauss_legendre(q.points_per_axis()).unwrap();
    for edge in Edge::ALL {
        let (axis, fixed, normal) = match edge {
            Edge::UMin => (1, b.lo[0], [-1.0, 0.0]),
            Edge::UMax => (1, b.hi[0], [1.0, 0.0]),
            Edge::VMin => (0, b.lo[1], [0.0, -1.0]),
            Edge::VMax => (0, b.hi[1], [0.0, 1.0]),
        };
        for c in 0..edge_rule_cells {
            let lo = b.lo[axis] + (b.hi[axis] - b.lo[axis]) * c as f64 / edge_rule_cells as f64;
            let hi =
                b.lo[axis] + (b.hi[axis] - b.lo[axis]) * (c + 1) as f64 / edge_rule_cells as f64;
            let (s, ws) = r.mapped(lo, hi);
            for (&y, &w) in s.iter().zip(&ws) {
                let x = if axis == 0 { [y, fixed] } else { [fixed, y] };
                let g = grad_exact(x);
                let flux = g[0] * normal[0] + g[1] * normal[1];
                sf.evaluate(x, &mut sv).unwrap();
                for (a, va, _) in sv.iter() {
                    f[a] += w * flux * va;
                }
            }
        }
    }
    (k, f)
}

/// Patch test of RK Galerkin + cell quadrature + essential conditions: `−Δu = s` on the unit
/// square with a quadratic exact solution and Dirichlet data on the whole boundary imposed at the
/// boundary particles as constraint rows `Σ_I Ψ_I(ξ_J) d_I = u(ξ_J)`. With the quadratic basis
/// the exact solution lies in the trial space (`d_I = u(ξ_I)` by reproduction), so the only error
/// is quadrature error. On a regular grid with support half-width 3h, the kernel breakpoints (±1.5h, ±3h from each particle)
/// lie on the lines of cells of size h/2, inside which the shape functions are smooth rational
/// functions, and a 10×10 Gauss rule per cell brings the quadrature error to round-off.
///
/// Measured (9×9 particles): coefficient error 4e-13 with 10×10 points per h/2 cell; 1.4e-8 with
/// 6×6 points; 8e-7 with 10×10 points on cells of size h (breakpoints inside the cells). On a
/// jittered grid (jitter 0.3) the breakpoints cannot be aligned and the patch test is passed only
/// to the quadrature error: field error 6e-6 (h/2 cells) and 4e-7 (h/4 cells) with 10×10 points.
#[test]
fn poisson_patch_test_with_quadratic_basis() {
    let u_exact =
        |x: [f64; 2]| 1.0 + 2.0 * x[0] - x[1] + x[0] * x[0] + 0.5 * x[0] * x[1] - 2.0 * x[1] * x[1];
    let grad = |x: [f64; 2]| {
        [
            2.0 + 2.0 * x[0] + 0.5 * x[1],
            -1.0 + 0.5 * x[0] - 4.0 * x[1],
        ]
    };
    let source = -(2.0 - 4.0); // −Δu
    let b = ParamBox::unit();
    let np = 9;
    // Support 3h, cells of h/2 (breakpoint-aligned), 10×10 Gauss points per cell.
    let (mult, sub, ng) = (3.0, 2, 10);
    let grid = regular_grid(b, np, np);
    let sf = ShapeFunctions::new(
        grid.positions.clone(),
        grid.supports(mult),
        Basis::Quadratic,
    )
    .unwrap();
    let q = CellQuadrature::for_particle_grid(&grid, sub, ng).unwrap();
    let (k, f) = assemble_poisson(&sf, &q, sub * (np - 1), source, grad);
    let j = common::particles_on_edges(&grid.positions, &Edge::ALL);
    let xj: Vec<[f64; 2]> = j.iter().map(|&p| grid.positions[p]).collect();
    let gj: Vec<f64> = xj.iter().map(|&x| u_exact(x)).collect();
    let d = common::solve_constrained(&k, &f, &common::nodal_rows(&sf, &xj, 1, 0, &gj));
    // Coefficients are the nodal values of the exact solution; the field is exact everywhere.
    let coef_err = (0..grid.len())
        .map(|i| (d[i] - u_exact(grid.positions[i])).abs())
        .fold(0.0_f64, f64::max);
    let mut rng = XorShift64::new(1);
    let mut field_err: f64 = 0.0;
    for _ in 0..200 {
        let x = rng.point_in(&b);
        field_err = field_err.max((approx_at(&sf, x, &d) - u_exact(x)).abs());
    }
    println!(
        "Poisson patch test ({np}×{np} particles, {} points): coefficient error {coef_err:.2e}, \
         field error {field_err:.2e}",
        q.len()
    );
    assert!(coef_err < 1e-10, "coefficient error {coef_err:e}");
    assert!(field_err < 1e-10, "field error {field_err:e}");
}
