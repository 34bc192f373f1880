//! Tests of the RK meshfree shape functions (`shelldsa::meshfree`).

use nalgebra::DMatrix;
use shelldsa::meshfree::*;
use shelldsa::scalar::{Dual, Real};
use shelldsa::verification::{check, CheckOptions, Differentiable, Tolerance};

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
    for (kernel, basis, multiples) in [
        (KernelFunction::CubicSpline, Basis::Linear, [2.0, 2.5, 4.0]),
        (
            KernelFunction::CubicSpline,
            Basis::Quadratic,
            [3.0, 3.5, 4.0],
        ),
        (
            KernelFunction::QuarticSpline,
            Basis::Linear,
            [2.0, 2.5, 4.0],
        ),
        (
            KernelFunction::QuarticSpline,
            Basis::Quadratic,
            [3.0, 3.5, 4.0],
        ),
        (KernelFunction::CubicSpline, Basis::Cubic, [3.5, 4.0, 4.5]),
        (KernelFunction::QuarticSpline, Basis::Cubic, [3.5, 4.0, 4.5]),
    ] {
        let mut worst = [0.0_f64; 2];
        for (s, &mult) in multiples.iter().enumerate() {
            let grid = jittered_grid(b, 17, 23, 0.3, 11 + s as u64);
            let sf = ShapeFunctions::new(grid.positions.clone(), grid.supports(mult), basis)
                .unwrap()
                .with_kernel(kernel);
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
                            "{} {basis} basis, support {mult}h, x = {x:?}, x^{e:?}, component {k}: {} vs {exact} (scaled error {err:.2e})",
                            kernel.name(),
                            sum[k]
                        );
                    }
                }
            }
        }
        println!(
            "{} {basis} basis: worst scaled reproduction error: values {:.2e}, derivatives {:.2e}",
            kernel.name(),
            worst[0],
            worst[1]
        );
    }
}

/// Reproducing conditions on fully random (unstructured) particle sets with per-particle support
/// sizes from the local spacing, including particles outside the evaluation box (as mirror images
/// for symmetry planes are): values and first derivatives, linear and quadratic basis.
///
/// The particles are uniform random in a box 10 % larger than the evaluation box on every side, so
/// the box's edges and corners are covered from outside too; supports are `multiple ×` the mean
/// distance to the 8 nearest particles (per particle, isotropic), a multiple large enough that
/// every evaluation point has a non-degenerate neighbourhood in these fixed-seed sets. Tolerance
/// as in [`reproducing_conditions_on_jittered_sets`]: `1e-12 · max(1, Σ_I |terms|)`, the
/// round-off bound of the sums, not amplified by the conditioning of `M` (measured worst values
/// printed).
#[test]
fn reproducing_conditions_on_random_sets() {
    let b = ParamBox::new([0.5, 2.0], [-1.0, 1.5]);
    let pad = [0.1 * (b.hi[0] - b.lo[0]), 0.1 * (b.hi[1] - b.lo[1])];
    let outer = ParamBox::new(
        [b.lo[0] - pad[0], b.hi[0] + pad[0]],
        [b.lo[1] - pad[1], b.hi[1] + pad[1]],
    );
    let mut rng = XorShift64::new(23);
    let pts = test_points(&b, 300, &mut rng);
    let mut out = ShapeValues::new();
    for (basis, multiples) in [(Basis::Linear, [2.0, 3.0]), (Basis::Quadratic, [3.0, 4.0])] {
        let mut worst = [0.0_f64; 2];
        let mut outside = 0;
        for (s, &mult) in multiples.iter().enumerate() {
            let mut prng = XorShift64::new(100 + s as u64);
            let particles: Vec<[f64; 2]> = (0..500).map(|_| prng.point_in(&outer)).collect();
            outside += particles.iter().filter(|p| !b.contains(**p)).count();
            let h = local_spacing(&particles, 8);
            let supports =
                supports_from_spacing(&h.iter().map(|&h| [h, h]).collect::<Vec<_>>(), mult);
            let sf = ShapeFunctions::new(particles.clone(), supports, basis).unwrap();
            for &x in &pts {
                sf.evaluate(x, &mut out)
                    .unwrap_or_else(|e| panic!("{basis}, multiple {mult}: {e}"));
                for (e, val, grad) in monomials(basis.order(), x) {
                    let mut sum = [0.0; 3];
                    let mut mag = [0.0; 3];
                    for (i, psi, g) in out.iter() {
                        let p = particles[i];
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
                            "{basis} basis, multiple {mult}, x = {x:?}, x^{e:?}, component {k}: \
                             {} vs {exact} (scaled error {err:.2e})",
                            sum[k]
                        );
                    }
                }
            }
        }
        assert!(
            outside > 50,
            "the sets must include particles outside the box"
        );
        println!(
            "{basis} basis, random sets ({outside} particles outside the box in the two sets): worst \
             scaled reproduction error: values {:.2e}, derivatives {:.2e}",
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
    // The parallel batch gives the same numbers.
    let many = sf.evaluate_many(&[[5.3, 5.0], [2.25, 7.5]]).unwrap();
    assert_eq!(many[0].neighbours(), out.neighbours());
    assert_eq!(many[0].values(), out.values());
    assert_eq!(many[0].gradients(), out.gradients());
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

/// Ψ_I(x) of every particle, as a function of the evaluation point (inputs u, v).
struct ShapeOfPoint {
    particles: Vec<[f64; 2]>,
    supports: Vec<[f64; 2]>,
    basis: Basis,
}

impl Differentiable for ShapeOfPoint {
    fn n_inputs(&self) -> usize {
        2
    }
    fn eval<T: Real>(&self, x: &[T]) -> Vec<T> {
        let p: Vec<[T; 2]> = self
            .particles
            .iter()
            .map(|p| [T::cst(p[0]), T::cst(p[1])])
            .collect();
        let a: Vec<[T; 2]> = self
            .supports
            .iter()
            .map(|a| [T::cst(a[0]), T::cst(a[1])])
            .collect();
        rk_shape_functions([x[0], x[1]], &p, &a, self.basis)
            .expect("well-posed point")
            .0
    }
    fn input_label(&self, j: usize) -> String {
        ["u", "v"][j].to_string()
    }
    fn output_label(&self, i: usize) -> String {
        format!("Ψ_{i}")
    }
}

/// Tolerances of the derivative checks.
///
/// Hand vs dual: 1e-12 relative. Both are exact derivatives of the same floating-point computation
/// and differ only by round-off: the hand formula `−M⁻¹ (∂M) b` and the dual chain rule through the
/// Cholesky factorisation order the operations differently, and a gradient component built from
/// terms ~100× larger than itself loses two digits to cancellation (measured worst 5e-13 relative,
/// on a component of 0.16 with the largest 18). Components below 1e-6 of the largest are held to an
/// absolute bound (the verification module's default floor).
///
/// Hand vs central differences (step h = ε^(1/3) ≈ 6e-6): 1e-6 relative, with the floor raised to
/// 1e-2 of the largest component. The truncation error `h²/6 · max|∂³Ψ|` does not shrink with the
/// component: `∂³Ψ ~ Ψ/a³` is large everywhere in the support, and the cubic B-spline is only C²,
/// so its third derivative jumps at z = ½ and z = 1. With a = 0.2, h²/6 · 8/a³ ≈ 6e-9 absolute,
/// i.e. ≈ 1e-5 relative for a gradient component of 1e-3 near a support edge (measured 9.5e-6
/// there) but ≈ 1e-9 relative to the largest gradient (≈ 7). Round-off `ε/h ≈ 4e-11` is negligible.
fn check_options() -> CheckOptions {
    let mut o = CheckOptions::new(1e-12, 1e-6);
    o.fd = Tolerance {
        rel: 1e-6,
        floor: 1e-2,
    };
    o
}

/// Three-way check of the hand-derived gradient ∂Ψ_I/∂x (hot path) against dual numbers through
/// the generic kernel and central differences; tolerances in [`check_options`].
#[test]
fn gradient_three_way_check() {
    let b = ParamBox::unit();
    let mut rng = XorShift64::new(3);
    let mut worst = [0.0_f64; 2];
    for (basis, mult, seed) in [
        (Basis::Linear, 2.0, 1),
        (Basis::Linear, 3.0, 2),
        (Basis::Quadratic, 3.0, 3),
        (Basis::Quadratic, 3.5, 4),
        (Basis::Cubic, 3.5, 5),
        (Basis::Cubic, 4.0, 6),
    ] {
        let grid = jittered_grid(b, 9, 11, 0.3, seed);
        let f = ShapeOfPoint {
            particles: grid.positions.clone(),
            supports: grid.supports(mult),
            basis,
        };
        let sf = ShapeFunctions::new(grid.positions.clone(), grid.supports(mult), basis).unwrap();
        let mut out = ShapeValues::new();
        let mut pts: Vec<[f64; 2]> = (0..6).map(|_| rng.point_in(&b)).collect();
        pts.extend([[0.0, 0.0], [1.0, 0.37], [0.02, 0.999]]);
        for x in pts {
            sf.evaluate(x, &mut out).unwrap();
            let mut hand = DMatrix::zeros(grid.len(), 2);
            for (i, _, g) in out.iter() {
                hand[(i, 0)] = g[0];
                hand[(i, 1)] = g[1];
            }
            let r = check(
                &f,
                &format!("∂Ψ/∂x, {basis} basis, support {mult}h, x = {x:?}"),
                &x,
                &hand,
                check_options(),
            );
            worst[0] = worst[0].max(r.vs_dual.max_error());
            worst[1] = worst[1].max(r.vs_fd.max_error());
            assert!(r.passed(), "{r}");
        }
    }
    println!("gradient check: worst scaled error hand vs dual {:.2e}, hand vs central differences {:.2e}", worst[0], worst[1]);
}

/// Ψ_I at a fixed point as a function of one particle's coordinates (a design-type derivative).
struct ShapeOfParticle {
    particles: Vec<[f64; 2]>,
    supports: Vec<[f64; 2]>,
    moved: usize,
    x: [f64; 2],
}

impl Differentiable for ShapeOfParticle {
    fn n_inputs(&self) -> usize {
        2
    }
    fn eval<T: Real>(&self, y: &[T]) -> Vec<T> {
        let mut p: Vec<[T; 2]> = self
            .particles
            .iter()
            .map(|p| [T::cst(p[0]), T::cst(p[1])])
            .collect();
        p[self.moved] = [y[0], y[1]];
        let a: Vec<[T; 2]> = self
            .supports
            .iter()
            .map(|a| [T::cst(a[0]), T::cst(a[1])])
            .collect();
        let (v, g) = rk_shape_functions(
            [T::cst(self.x[0]), T::cst(self.x[1])],
            &p,
            &a,
            Basis::Quadratic,
        )
        .unwrap();
        v.into_iter()
            .chain(g.into_iter().flat_map(|g| g.into_iter()))
            .collect()
    }
}

/// The generic kernel is differentiable in the particle coordinates too: the dual-number
/// derivative of Ψ_I and ∇Ψ_I with respect to one particle's position agrees with central
/// differences (no hand derivative here: the dual Jacobian is the one checked; tolerance as above).
#[test]
fn particle_coordinate_derivatives_dual_vs_fd() {
    let grid = jittered_grid(ParamBox::unit(), 8, 8, 0.25, 9);
    let moved = 3 * 8 + 4;
    let f = ShapeOfParticle {
        particles: grid.positions.clone(),
        supports: grid.supports(3.0),
        moved,
        x: [0.55, 0.41],
    };
    let y = grid.positions[moved];
    let dual = shelldsa::verification::dual_jacobian(&f, &y);
    let r = check(
        &f,
        "∂(Ψ, ∇Ψ)/∂x_J by dual numbers",
        &y,
        &dual,
        check_options(),
    );
    println!("{r}");
    assert!(r.passed(), "{r}");
    assert!(
        dual.abs().max() > 0.1,
        "the moved particle must influence the point"
    );
}

/// The neighbour search returns exactly the brute-force set (same predicate, ascending order) on
/// jittered sets with per-particle support sizes, for random points, points outside the supports,
/// and points exactly on support edges.
#[test]
fn neighbour_search_equals_brute_force() {
    let mut rng = XorShift64::new(42);
    let mut total = 0usize;
    for seed in 0..6u64 {
        let b = ParamBox::new([-0.3, 1.7 + seed as f64], [2.0, 2.5]);
        let grid = jittered_grid(b, 12 + 5 * seed as usize, 7 + 3 * seed as usize, 0.45, seed);
        let supports: Vec<[f64; 2]> = (0..grid.len())
            .map(|_| {
                [
                    grid.spacing[0] * rng.uniform(0.7, 4.0),
                    grid.spacing[1] * rng.uniform(0.7, 4.0),
                ]
            })
            .collect();
        let sg = SupportGrid::new(&grid.positions, &supports).unwrap();
        let (mut a, mut bf) = (Vec::new(), Vec::new());
        let wide = ParamBox::new(
            [b.lo[0] - 1.0, b.hi[0] + 1.0],
            [b.lo[1] - 1.0, b.hi[1] + 1.0],
        );
        let mut queries: Vec<[f64; 2]> = (0..500).map(|_| rng.point_in(&wide)).collect();
        for i in (0..grid.len()).step_by(3) {
            let (p, s) = (grid.positions[i], supports[i]);
            queries.extend([
                [p[0] + s[0], p[1]],
                [p[0] - s[0], p[1]],
                [p[0], p[1] - s[1]],
                [p[0] + s[0] * 0.999_999_999_999, p[1]],
            ]);
        }
        queries.extend([[f64::NAN, 0.0], [f64::INFINITY, 2.2]]);
        for x in queries {
            sg.covering(x, &mut a);
            covering_brute_force(&grid.positions, &supports, x, &mut bf);
            assert_eq!(a, bf, "seed {seed}, x = {x:?}");
            total += a.len();
        }
    }
    assert!(total > 1000, "queries must find neighbours ({total})");
}

/// Too few particles in support, or degenerate (collinear) ones: an error naming the point and the
/// neighbour count, never a panic; the output buffer is left empty.
#[test]
fn too_few_neighbours_is_an_error_naming_the_point() {
    let grid = regular_grid(ParamBox::unit(), 5, 5);
    let sf =
        ShapeFunctions::new(grid.positions.clone(), grid.supports(0.6), Basis::Linear).unwrap();
    let mut out = ShapeValues::new();
    // Support 0.6 h: the point (0.1, 0.1) is covered by the corner particle only.
    let err = sf.evaluate([0.1, 0.1], &mut out).unwrap_err();
    assert!(
        matches!(
            err,
            MeshfreeError::TooFewNeighbours {
                neighbours: 1,
                required: 3,
                ..
            }
        ),
        "{err:?}"
    );
    let msg = err.to_string();
    println!("{msg}");
    assert!(
        msg.contains("(0.1, 0.1)") && msg.contains("only 1 particle"),
        "{msg}"
    );
    assert!(out.is_empty());
    // Far outside: zero neighbours.
    let err = sf.evaluate([7.0, -3.5], &mut out).unwrap_err();
    assert!(
        err.to_string().contains("(7, -3.5)") && err.to_string().contains("only 0 particle"),
        "{err}"
    );
    // The generic kernel reports the same.
    let err = rk_shape_functions(
        [0.1, 0.1],
        &grid.positions,
        &grid.supports(0.6),
        Basis::Linear,
    )
    .unwrap_err();
    assert!(
        matches!(
            err,
            MeshfreeError::TooFewNeighbours {
                point: [0.1, 0.1],
                neighbours: 1,
                ..
            }
        ),
        "{err:?}"
    );
    // Quadratic basis with a linear-basis support near a corner: 4 < 6 neighbours.
    let sf =
        ShapeFunctions::new(grid.positions.clone(), grid.supports(2.0), Basis::Quadratic).unwrap();
    let err = sf.evaluate([0.0, 0.0], &mut out).unwrap_err();
    assert!(
        matches!(
            err,
            MeshfreeError::TooFewNeighbours {
                neighbours: 4,
                required: 6,
                ..
            }
        ),
        "{err:?}"
    );
    // Enough particles but collinear: singular moment matrix.
    let line: Vec<[f64; 2]> = (0..6).map(|i| [i as f64 * 0.2, 0.5]).collect();
    let sf = ShapeFunctions::new(line, vec![[0.5, 0.5]; 6], Basis::Linear).unwrap();
    let err = sf.evaluate([0.5, 0.6], &mut out).unwrap_err();
    println!("{err}");
    assert!(
        matches!(err, MeshfreeError::IllConditioned { neighbours: 4, .. }),
        "{err:?}"
    );
    assert!(err.to_string().contains("(0.5, 0.6)"));
    // A 2-column tensor patch is singular for the quadratic basis (Δu² depends on 1 and Δu).
    let cols: Vec<[f64; 2]> = (0..8)
        .map(|i| [(i % 2) as f64 * 0.3, (i / 2) as f64 * 0.3])
        .collect();
    let err =
        rk_shape_functions([0.1, 0.4], &cols, &[[1.0, 1.0]; 8], Basis::Quadratic).unwrap_err();
    assert!(
        matches!(err, MeshfreeError::IllConditioned { neighbours: 8, .. }),
        "{err:?}"
    );
    // Invalid input is reported, not panicked on.
    assert!(matches!(
        ShapeFunctions::new(vec![[0.0, 0.0]], vec![[0.0, 1.0]], Basis::Linear),
        Err(MeshfreeError::InvalidInput(_))
    ));
    assert!(matches!(
        ShapeFunctions::new(vec![[0.0, 0.0]], vec![], Basis::Linear),
        Err(MeshfreeError::InvalidInput(_))
    ));
}

/// Kernel values at the knots and C² continuity at z = ½ and z = 1.
#[test]
fn cubic_bspline_knots_and_continuity() {
    assert_eq!(cubic_bspline(0.0), [2.0 / 3.0, 0.0, -8.0]);
    let (l, r) = (cubic_bspline(0.5_f64), cubic_bspline(0.5 + 1e-15));
    for k in 0..3 {
        assert!(
            (l[k] - r[k]).abs() < 1e-13,
            "derivative {k} at z = 1/2: {l:?} vs {r:?}"
        );
    }
    for (k, e) in [1.0 / 6.0, -1.0, 4.0].into_iter().enumerate() {
        assert!((l[k] - e).abs() < 1e-15, "{l:?}");
    }
    assert_eq!(cubic_bspline(1.0), [0.0, 0.0, 0.0]);
    assert_eq!(cubic_bspline(1.5), [0.0, 0.0, 0.0]);
    // Derivatives by dual numbers.
    for z in [0.1, 0.45, 0.7, 0.95] {
        let d = cubic_bspline(Dual::from_re(z).derivative());
        let v = cubic_bspline(z);
        assert!(
            (d[0].eps - v[1]).abs() < 1e-14 && (d[1].eps - v[2]).abs() < 1e-14,
            "z = {z}"
        );
    }
}

/// The quartic spline: `φ(0) = 2/3` (the cubic B-spline's), C² at `z = 1`, zero beyond, and its
/// hand-written derivatives against dual numbers (round-off, 1e-14) and central differences
/// (h = 1e-5: the truncation `h² φ‴ / 6` is below 1e-9 for this quartic, so 1e-8).
#[test]
fn quartic_spline_values_continuity_and_derivatives() {
    assert_eq!(quartic_spline(0.0), [2.0 / 3.0, 0.0, -8.0]);
    assert_eq!(quartic_spline(1.0), [0.0, 0.0, 0.0]);
    assert_eq!(quartic_spline(1.5), [0.0, 0.0, 0.0]);
    let l = quartic_spline(1.0 - 1e-9_f64);
    assert!(l.iter().all(|v| v.abs() < 1e-7), "C² at z = 1: {l:?}");
    for z in [0.1, 0.45, 0.7, 0.95] {
        let d = quartic_spline(Dual::from_re(z).derivative());
        let v = quartic_spline(z);
        let h = 1e-5;
        let fd = |k: usize| (quartic_spline(z + h)[k] - quartic_spline(z - h)[k]) / (2.0 * h);
        assert!(
            (d[0].eps - v[1]).abs() < 1e-14 && (d[1].eps - v[2]).abs() < 1e-14,
            "dual, z = {z}"
        );
        assert!(
            (fd(0) - v[1]).abs() < 1e-8 && (fd(1) - v[2]).abs() < 1e-8,
            "central differences, z = {z}"
        );
    }
    // The same through the kernel choice, and the choice's blind spots.
    assert_eq!(KernelFunction::QuarticSpline.eval(0.3), quartic_spline(0.3));
    assert_eq!(KernelFunction::CubicSpline.eval(0.3), cubic_bspline(0.3));
    assert!(KernelFunction::CubicSpline.blind_at(4.0) && KernelFunction::CubicSpline.blind_at(8.1));
    assert!(
        !KernelFunction::CubicSpline.blind_at(3.5) && !KernelFunction::CubicSpline.blind_at(4.2)
    );
    assert!(!KernelFunction::QuarticSpline.blind_at(4.0));
}

/// Particle generators: deterministic, corners and edges on the box, spacing estimate.
#[test]
fn particle_generators() {
    let b = ParamBox::new([1.0, 3.0], [0.0, 0.5]);
    let g1 = jittered_grid(b, 9, 6, 0.3, 5);
    assert_eq!(g1, jittered_grid(b, 9, 6, 0.3, 5));
    assert_ne!(g1.positions, jittered_grid(b, 9, 6, 0.3, 6).positions);
    assert!(g1.positions.iter().all(|&p| b.contains(p)));
    assert_eq!(g1.positions[0], [1.0, 0.0]);
    assert_eq!(g1.positions[9 * 6 - 1], [3.0, 0.5]);
    assert!(g1.positions[..9].iter().all(|p| p[1] == 0.0));
    let reg = regular_grid(ParamBox::unit(), 6, 6);
    let h = local_spacing(&reg.positions, 4);
    // Interior particles: 4 neighbours at h. Edges and corners: some at h√2, so between h and 1.5h.
    for (i, &hi) in h.iter().enumerate() {
        let (iu, iv) = (i % 6, i / 6);
        if (1..5).contains(&iu) && (1..5).contains(&iv) {
            assert!((hi - 0.2).abs() < 1e-12, "particle {i}: {hi}");
        } else {
            assert!((0.2 - 1e-12..0.3).contains(&hi), "particle {i}: {hi}");
        }
    }
    let s = supports_from_spacing(&h.iter().map(|&h| [h, h]).collect::<Vec<_>>(), 3.0);
    assert!((s[7][0] - 0.6).abs() < 1e-12);
}
