//! Tests of the transformation method for essential conditions (`shelldsa::meshfree::transform`).

use nalgebra::{DMatrix, DVector};
use shelldsa::meshfree::quadrature::{gauss_legendre, CellQuadrature};
use shelldsa::meshfree::transform::*;
use shelldsa::meshfree::*;

/// Tolerance for "on the edge": jittered grids keep edge particles exactly on the edge.
const EDGE_TOL: f64 = 1e-12;

fn boundary(grid: &ParticleGrid, b: &ParamBox) -> Vec<usize> {
    particles_on_edges(&grid.positions, b, &Edge::ALL, EDGE_TOL)
}

/// `Σ_I Ψ_I(x) d_I` (component `c` of `comps`).
fn approx_at(sf: &ShapeFunctions, x: [f64; 2], d: &[f64], comps: usize, c: usize) -> f64 {
    let mut sv = ShapeValues::new();
    sf.evaluate(x, &mut sv).unwrap();
    sv.iter().map(|(i, v, _)| v * d[comps * i + c]).sum()
}

#[test]
fn edge_particle_listing() {
    let b = ParamBox::new([0.0, 2.0], [1.0, 2.0]);
    let g = jittered_grid(b, 5, 4, 0.3, 11);
    let left = edge_particles(&g.positions, &b, Edge::UMin, EDGE_TOL);
    assert_eq!(left, vec![0, 5, 10, 15]);
    let top = edge_particles(&g.positions, &b, Edge::VMax, EDGE_TOL);
    assert_eq!(top, vec![15, 16, 17, 18, 19]);
    let all = boundary(&g, &b);
    assert_eq!(all.len(), 2 * 5 + 2 * 4 - 4);
    assert!(all.windows(2).all(|w| w[0] < w[1]));
}

/// Impose `g` on all boundary particles of a jittered set (linear and quadratic basis): the RK
/// approximation equals `g` at every constrained particle to 1e-12; unconstrained coefficients are
/// untouched; `to_nodal` inverts `to_generalised`.
#[test]
fn imposed_values_are_reproduced_at_constrained_particles() {
    let b = ParamBox::new([0.0, 1.0], [0.0, 1.5]);
    let gfun = |x: [f64; 2]| (3.0 * x[0]).sin() + x[1] * x[1] - 0.5 * x[0] * x[1];
    for (basis, mult) in [(Basis::Linear, 2.0), (Basis::Quadratic, 3.0)] {
        let grid = jittered_grid(b, 11, 13, 0.3, 5);
        let sf = ShapeFunctions::new(grid.positions.clone(), grid.supports(mult), basis).unwrap();
        let j = boundary(&grid, &b);
        let tr = Transformation::new(&sf, &j).unwrap();
        assert_eq!(tr.constrained(), &j[..]);
        let comps = 2;
        let mut rng = XorShift64::new(99);
        let mut nodal: Vec<f64> = (0..comps * grid.len())
            .map(|_| rng.uniform(-1.0, 1.0))
            .collect();
        for &p in &j {
            nodal[comps * p] = gfun(grid.positions[p]);
            nodal[comps * p + 1] = -2.0 * gfun(grid.positions[p]) + 1.0;
        }
        let d = tr.to_generalised(&nodal, comps).unwrap();
        let mut worst: f64 = 0.0;
        for &p in &j {
            let x = grid.positions[p];
            let e0 = (approx_at(&sf, x, &d, comps, 0) - gfun(x)).abs();
            let e1 = (approx_at(&sf, x, &d, comps, 1) - (-2.0 * gfun(x) + 1.0)).abs();
            worst = worst.max(e0).max(e1);
        }
        assert!(worst < 1e-12, "{basis}: worst {worst:e}");
        for i in 0..grid.len() {
            if !tr.is_constrained(i) {
                for c in 0..comps {
                    assert_eq!(d[comps * i + c], nodal[comps * i + c]);
                }
            }
        }
        let back = tr.to_nodal(&d, comps).unwrap();
        let rt = back
            .iter()
            .zip(&nodal)
            .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(rt < 1e-13, "{basis}: round trip {rt:e}");
        println!(
            "{basis} basis, {} particles, {} constrained: max |u_h(ξ_J) − g(ξ_J)| = {worst:.2e}, \
             round trip {rt:.2e}",
            grid.len(),
            j.len()
        );
    }
}

/// Sparse and dense transformed systems agree, for 1 and 3 components; `f̃ = Λ⁻ᵀ f` likewise; and
/// the transformed system gives the same solution as the original one.
#[test]
fn sparse_and_dense_transformations_agree() {
    let b = ParamBox::unit();
    let grid = jittered_grid(b, 8, 7, 0.3, 21);
    let sf =
        ShapeFunctions::new(grid.positions.clone(), grid.supports(3.0), Basis::Quadratic).unwrap();
    let j: Vec<usize> = particles_on_edges(&grid.positions, &b, &[Edge::UMin, Edge::VMax], 1e-12);
    let tr = Transformation::new(&sf, &j).unwrap();
    let n = grid.len();
    let mut rng = XorShift64::new(4);
    for comps in [1usize, 3] {
        let nd = comps * n;
        // A nonsymmetric sparse matrix with the particle-coupling pattern of K.
        let mut t = Vec::new();
        for p in 0..n {
            for q in 0..n {
                let dx = grid.positions[p];
                let dy = grid.positions[q];
                if (dx[0] - dy[0]).abs() < 0.3 && (dx[1] - dy[1]).abs() < 0.3 {
                    for c in 0..comps {
                        for e in 0..comps {
                            let v =
                                rng.uniform(-1.0, 1.0) + if p == q && c == e { 8.0 } else { 0.0 };
                            t.push((comps * p + c, comps * q + e, v));
                        }
                    }
                }
            }
        }
        let k = CsrMatrix::from_triplets(nd, nd, &t);
        let kd = k.to_dense();
        let ks = tr.transform_matrix(&k, comps).unwrap().to_dense();
        let kr = tr.transform_matrix_dense(&kd, comps).unwrap();
        let scale = kr.amax();
        let diff = (&ks - &kr).amax() / scale;
        assert!(diff < 1e-13, "comps {comps}: relative difference {diff:e}");
        // f̃.
        let f: Vec<f64> = (0..nd).map(|_| rng.uniform(-1.0, 1.0)).collect();
        let ft = tr.transform_vector(&f, comps).unwrap();
        let l = tr.lambda_dense(comps);
        let fr = l
            .transpose()
            .lu()
            .solve(&DVector::from_vec(f.clone()))
            .unwrap();
        let fd = ft
            .iter()
            .zip(fr.iter())
            .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(fd < 1e-13 * fr.amax(), "comps {comps}: f̃ difference {fd:e}");
        // K d = f  ⇔  K̃ ũ = f̃ with ũ = Λ d.
        let d = kd
            .clone()
            .lu()
            .solve(&DVector::from_vec(f.clone()))
            .unwrap();
        let ut = DMatrix::from_row_slice(nd, nd, ks.transpose().as_slice())
            .lu()
            .solve(&DVector::from_vec(ft.clone()))
            .unwrap();
        let d2 = tr.to_generalised(ut.as_slice(), comps).unwrap();
        let sd = d
            .iter()
            .zip(&d2)
            .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(
            sd < 1e-10 * d.amax(),
            "comps {comps}: solutions differ by {sd:e}"
        );
        // Drop tolerance: fewer entries, result still close.
        let exact_nnz = tr.transform_matrix(&k, comps).unwrap().nnz();
        let trd = tr.clone().with_drop_tolerance(1e-12);
        let kdrop = trd.transform_matrix(&k, comps).unwrap();
        let dd = (&kdrop.to_dense() - &kr).amax() / scale;
        assert!(dd < 1e-10, "drop tolerance error {dd:e}");
        println!(
            "comps {comps}: nnz K {} → K̃ {} (drop 1e-12: {}); sparse vs dense {diff:.2e}, \
             f̃ {fd:.2e}, solutions {sd:.2e}, dropped {dd:.2e}",
            k.nnz(),
            exact_nnz,
            kdrop.nnz()
        );
    }
}

/// Coincident constrained particles make Λ_JJ singular: an error naming them, not a panic.
#[test]
fn singular_block_is_an_error_naming_the_particles() {
    let b = ParamBox::unit();
    let grid = regular_grid(b, 6, 6);
    let mut pts = grid.positions.clone();
    pts.push(pts[2]); // a duplicate of boundary particle 2 (index 36)
    let sup = vec![[0.6, 0.6]; pts.len()];
    let sf = ShapeFunctions::new(pts.clone(), sup, Basis::Linear).unwrap();
    let mut j = particles_on_edges(&pts, &b, &[Edge::VMin], 1e-12);
    assert!(j.contains(&2) && j.contains(&36));
    let e = Transformation::new(&sf, &j).unwrap_err();
    match &e {
        TransformError::Singular {
            dependent,
            involved,
            ..
        } => {
            assert_eq!(dependent, &vec![36]);
            assert_eq!(involved, &vec![2]);
        }
        other => panic!("unexpected {other:?}"),
    }
    let msg = e.to_string();
    assert!(msg.contains("[36]") && msg.contains("[2]"), "{msg}");
    println!("{msg}");
    // Without the duplicate it works; bad input is an error too.
    j.retain(|&p| p != 36);
    assert!(Transformation::new(&sf, &j).is_ok());
    assert!(matches!(
        Transformation::new(&sf, &[3, 3]),
        Err(TransformError::InvalidInput(_))
    ));
    assert!(matches!(
        Transformation::new(&sf, &[99]),
        Err(TransformError::InvalidInput(_))
    ));
    let tr = Transformation::new(&sf, &j).unwrap();
    assert!(matches!(
        tr.to_generalised(&[0.0; 5], 1),
        Err(TransformError::DimensionMismatch { .. })
    ));
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
) -> (CsrMatrix, Vec<f64>) {
    let n = sf.len();
    let mut t = Vec::new();
    let mut f = vec![0.0; n];
    let mut sv = ShapeValues::new();
    for (x, w, _) in q.iter() {
        sf.evaluate(x, &mut sv).unwrap();
        for (a, va, ga) in sv.iter() {
            f[a] += w * source * va;
            for (bb, _, gb) in sv.iter() {
                t.push((a, bb, w * (ga[0] * gb[0] + ga[1] * gb[1])));
            }
        }
    }
    let b = q.param_box();
    let r = gauss_legendre(q.points_per_axis()).unwrap();
    for edge in Edge::ALL {
        let (k, fixed, normal) = match edge {
            Edge::UMin => (1, b.lo[0], [-1.0, 0.0]),
            Edge::UMax => (1, b.hi[0], [1.0, 0.0]),
            Edge::VMin => (0, b.lo[1], [0.0, -1.0]),
            Edge::VMax => (0, b.hi[1], [0.0, 1.0]),
        };
        for c in 0..edge_rule_cells {
            let lo = b.lo[k] + (b.hi[k] - b.lo[k]) * c as f64 / edge_rule_cells as f64;
            let hi = b.lo[k] + (b.hi[k] - b.lo[k]) * (c + 1) as f64 / edge_rule_cells as f64;
            let (s, ws) = r.mapped(lo, hi);
            for (&y, &w) in s.iter().zip(&ws) {
                let x = if k == 0 { [y, fixed] } else { [fixed, y] };
                let g = grad_exact(x);
                let flux = g[0] * normal[0] + g[1] * normal[1];
                sf.evaluate(x, &mut sv).unwrap();
                for (a, va, _) in sv.iter() {
                    f[a] += w * flux * va;
                }
            }
        }
    }
    (CsrMatrix::from_triplets(n, n, &t), f)
}

/// Solve `K̃ ũ = f̃` with `ũ_J = g(ξ_J)` prescribed (dense, free rows only).
fn solve_with_prescribed(kt: &DMatrix<f64>, ft: &[f64], fixed: &[usize], g: &[f64]) -> Vec<f64> {
    let n = ft.len();
    let mut is_fixed = vec![false; n];
    for &i in fixed {
        is_fixed[i] = true;
    }
    let free: Vec<usize> = (0..n).filter(|&i| !is_fixed[i]).collect();
    let mut u = vec![0.0; n];
    for (&i, &v) in fixed.iter().zip(g) {
        u[i] = v;
    }
    let nf = free.len();
    let kff = DMatrix::from_fn(nf, nf, |a, b| kt[(free[a], free[b])]);
    let rhs = DVector::from_fn(nf, |a, _| {
        ft[free[a]] - fixed.iter().map(|&j| kt[(free[a], j)] * u[j]).sum::<f64>()
    });
    let sol = kff.cholesky().expect("K̃_FF SPD").solve(&rhs);
    for (a, &i) in free.iter().enumerate() {
        u[i] = sol[a];
    }
    u
}

/// Patch test of RK Galerkin + cell quadrature + transformation: `−Δu = s` on the unit square with
/// a quadratic exact solution and Dirichlet data on the whole boundary imposed at the boundary
/// particles through the transformation. With the quadratic basis the exact solution lies in the
/// trial space (`d_I = u(ξ_I)` by reproduction), so the only error is quadrature error. On a
/// regular grid with support half-width 3h, the kernel breakpoints (±1.5h, ±3h from each particle)
/// lie on the lines of cells of size h/2, inside which the shape functions are smooth rational
/// functions, and a 10×10 Gauss rule per cell brings the quadrature error to round-off.
///
/// Measured (9×9 particles): coefficient error 4e-13 with 10×10 points per h/2 cell; 1.4e-8 with
/// 6×6 points; 8e-7 with 10×10 points on cells of size h (breakpoints inside the cells). On a
/// jittered grid (jitter 0.3) the breakpoints cannot be aligned and the patch test is passed only
/// to the quadrature error: field error 6e-6 (h/2 cells) and 4e-7 (h/4 cells) with 10×10 points,
/// with the sparse and dense transformation paths still agreeing to 2e-14.
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
    let j = boundary(&grid, &b);
    let tr = Transformation::new(&sf, &j).unwrap();
    let kt = tr.transform_matrix(&k, 1).unwrap();
    let ft = tr.transform_vector(&f, 1).unwrap();
    let gj: Vec<f64> = j.iter().map(|&p| u_exact(grid.positions[p])).collect();
    let ut = solve_with_prescribed(&kt.to_dense(), &ft, &j, &gj);
    let d = tr.to_generalised(&ut, 1).unwrap();
    // Coefficients are the nodal values of the exact solution; the field is exact everywhere.
    let coef_err = (0..grid.len())
        .map(|i| (d[i] - u_exact(grid.positions[i])).abs())
        .fold(0.0_f64, f64::max);
    let mut rng = XorShift64::new(1);
    let mut field_err: f64 = 0.0;
    for _ in 0..200 {
        let x = rng.point_in(&b);
        field_err = field_err.max((approx_at(&sf, x, &d, 1, 0) - u_exact(x)).abs());
    }
    // Dense transformation path gives the same solution.
    let ktd = tr.transform_matrix_dense(&k.to_dense(), 1).unwrap();
    let ut_dense = solve_with_prescribed(&ktd, &ft, &j, &gj);
    let path = ut
        .iter()
        .zip(&ut_dense)
        .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
    println!(
        "Poisson patch test ({np}×{np} particles, {} points): coefficient error {coef_err:.2e}, \
         field error {field_err:.2e}, sparse vs dense path {path:.2e}",
        q.len()
    );
    assert!(coef_err < 1e-10, "coefficient error {coef_err:e}");
    assert!(field_err < 1e-10, "field error {field_err:e}");
    assert!(path < 1e-11, "paths differ by {path:e}");
}
