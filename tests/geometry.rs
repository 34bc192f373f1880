//! Tests of `shelldsa::geometry`: parametric derivatives three ways, exactness of NURBS conics,
//! B-spline basis properties, design-parameter derivatives, validation and case-file specs.
//!
//! Tolerances are relative to the magnitude of the compared quantity (or, for components much
//! smaller than the largest one, relative to the largest: the floor of `verification::check`).
//! The reasons for each bound are given where it is set. Run with `--nocapture` to see the worst
//! errors measured.

use nalgebra::{DMatrix, Vector3};
use shelldsa::geometry::{
    basis_function_derivatives, find_span, AnnulusSector, CylinderSector, GeometryError,
    NurbsSurface, Rectangle, SphereZone, Surface, SurfaceDerivs, SurfaceSpec,
};
use shelldsa::scalar::{Dual, Real};
use shelldsa::verification::{check, CheckOptions, Differentiable};
use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, SQRT_2};

// ---------------------------------------------------------------------------------------------
// Test surfaces.

fn rectangle() -> Surface<f64> {
    Surface::Rectangle(
        Rectangle::new(
            Vector3::new(1.0, -2.0, 0.5),
            Vector3::new(3.0, 0.5, 0.2),
            Vector3::new(-0.4, 2.0, 0.7),
        )
        .unwrap(),
    )
}

fn annulus() -> Surface<f64> {
    Surface::AnnulusSector(
        AnnulusSector::new(
            Vector3::new(0.3, 0.1, -1.0),
            Vector3::new(0.2, -0.3, 1.0),
            Vector3::new(1.0, 0.4, 0.0),
            0.5,
            2.5,
            [0.3, 2.1],
        )
        .unwrap(),
    )
}

fn cylinder() -> Surface<f64> {
    Surface::CylinderSector(
        CylinderSector::new(
            Vector3::new(0.5, -1.0, 2.0),
            Vector3::new(0.3, 1.0, 0.2),
            Vector3::new(0.0, 0.0, 1.0),
            3.0,
            [-0.4, 1.9],
            [-1.0, 4.0],
        )
        .unwrap(),
    )
}

/// A quadrant of the pinched hemisphere (R = 10, 18° hole): latitude 0°–72°, longitude 0°–90°.
fn hemisphere_quadrant() -> Surface<f64> {
    Surface::SphereZone(
        SphereZone::new(
            Vector3::new(0.2, -0.1, 0.3),
            10.0,
            [0.0, 72f64.to_radians()],
            [0.0, FRAC_PI_2],
        )
        .unwrap(),
    )
}

/// Degree 3 × 2, non-uniform knots (a double interior knot along u), skewed net, varied weights.
fn nurbs_general() -> NurbsSurface<f64> {
    let (nu, nv) = (7, 5);
    let knots_u = vec![0.0, 0.0, 0.0, 0.0, 0.3, 0.45, 0.45, 1.0, 1.0, 1.0, 1.0];
    let knots_v = vec![0.0, 0.0, 0.0, 0.25, 0.6, 1.0, 1.0, 1.0];
    let mut pts = vec![];
    let mut ws = vec![];
    for i in 0..nu {
        let (fi, mut row, mut wrow) = (i as f64, vec![], vec![]);
        for j in 0..nv {
            let fj = j as f64;
            row.push(Vector3::new(
                fi + 0.1 * fj.sin(),
                fj * 0.8 + 0.1 * fi.cos(),
                0.3 * (fi + fj).sin() + 0.05 * fi * fj,
            ));
            wrow.push(0.6 + 0.5 * (1.3 * fi + 0.7 * fj).sin().abs());
        }
        pts.push(row);
        ws.push(wrow);
    }
    NurbsSurface::new([3, 2], [knots_u, knots_v], pts, ws).unwrap()
}

/// Degree 1 × 3 on a non-unit domain [−1, 2] × [0, 5].
fn nurbs_linear_cubic() -> NurbsSurface<f64> {
    let pts = vec![
        (0..4)
            .map(|j| Vector3::new(0.0, j as f64, (j as f64 * 0.9).sin()))
            .collect(),
        (0..4)
            .map(|j| Vector3::new(2.0 + 0.2 * j as f64, j as f64, 1.0 - 0.1 * j as f64))
            .collect(),
    ];
    let ws = vec![vec![1.0, 0.8, 1.3, 1.0], vec![0.9, 1.0, 0.7, 1.2]];
    NurbsSurface::new(
        [1, 3],
        [
            vec![-1.0, -1.0, 2.0, 2.0],
            vec![0.0, 0.0, 0.0, 0.0, 5.0, 5.0, 5.0, 5.0],
        ],
        pts,
        ws,
    )
    .unwrap()
}

const R_CYL: f64 = 2.5;
const L_CYL: f64 = 4.0;

/// Quarter cylinder, axis z, radius 2.5, angle 0°–90° (u: degree 2, middle weight √2/2),
/// length 0–4 (v: degree 1). u runs counter-clockwise and v along +z, so x_u × x_v is outward.
fn nurbs_quarter_cylinder() -> NurbsSurface<f64> {
    let arc = [
        (R_CYL, 0.0, 1.0),
        (R_CYL, R_CYL, SQRT_2 / 2.0),
        (0.0, R_CYL, 1.0),
    ];
    let pts = arc
        .iter()
        .map(|&(x, y, _)| vec![Vector3::new(x, y, 0.0), Vector3::new(x, y, L_CYL)])
        .collect();
    let ws = arc.iter().map(|&(_, _, w)| vec![w, w]).collect();
    NurbsSurface::new(
        [2, 1],
        [vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0], vec![0.0, 0.0, 1.0, 1.0]],
        pts,
        ws,
    )
    .unwrap()
}

const R_SPH: f64 = 10.0;
fn sphere_centre() -> Vector3<f64> {
    Vector3::new(0.2, -0.1, 0.3)
}

/// Control points (in the plane of the arc, unit radius) and weights of a single rational
/// quadratic arc from angle `a0` to `a1` (`a1 − a0 < π`): the middle point is the intersection of
/// the end tangents, at distance `1/cos(Δ/2)`, with weight `cos(Δ/2)`.
fn arc(a0: f64, a1: f64) -> [(f64, f64, f64); 3] {
    let h = 0.5 * (a1 - a0);
    let m = 0.5 * (a0 + a1);
    [
        (a0.cos(), a0.sin(), 1.0),
        (m.cos() / h.cos(), m.sin() / h.cos(), h.cos()),
        (a1.cos(), a1.sin(), 1.0),
    ]
}

/// The hemisphere quadrant as a degree 2 × 2 NURBS surface of revolution: u along longitude
/// 0°–90°, v along latitude 0°–72°, `P_ij = c + R (ρ_j cx_i, ρ_j cy_i, z_j)`, `w_ij = w_i w_j`.
fn nurbs_sphere_patch() -> NurbsSurface<f64> {
    let lon = arc(0.0, FRAC_PI_2);
    let lat = arc(0.0, 72f64.to_radians());
    let c = sphere_centre();
    let pts = lon
        .iter()
        .map(|&(cx, cy, _)| {
            lat.iter()
                .map(|&(r, z, _)| c + Vector3::new(r * cx, r * cy, z) * R_SPH)
                .collect()
        })
        .collect();
    let ws = lon
        .iter()
        .map(|&(_, _, wi)| lat.iter().map(|&(_, _, wj)| wi * wj).collect())
        .collect();
    let k = vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
    NurbsSurface::new([2, 2], [k.clone(), k], pts, ws).unwrap()
}

fn all_surfaces() -> Vec<(&'static str, Surface<f64>)> {
    vec![
        ("rectangle", rectangle()),
        ("annulus sector", annulus()),
        ("cylinder sector", cylinder()),
        ("sphere zone", hemisphere_quadrant()),
        ("nurbs 3x2 non-uniform", Surface::Nurbs(nurbs_general())),
        (
            "nurbs 1x3 domain [-1,2]x[0,5]",
            Surface::Nurbs(nurbs_linear_cubic()),
        ),
        (
            "nurbs quarter cylinder",
            Surface::Nurbs(nurbs_quarter_cylinder()),
        ),
        ("nurbs sphere patch", Surface::Nurbs(nurbs_sphere_patch())),
    ]
}

// ---------------------------------------------------------------------------------------------
// 1. Parametric derivatives: hand-derived against dual numbers and central differences.

/// `(u, v) ↦ (x, x_u, x_v)`: its Jacobian is `[[x_u, x_v], [x_uu, x_uv], [x_uv, x_vv]]`.
struct ByParameter<'a>(&'a Surface<f64>);

impl Differentiable for ByParameter<'_> {
    fn n_inputs(&self) -> usize {
        2
    }
    fn eval<T: Real>(&self, x: &[T]) -> Vec<T> {
        let d = self.0.lift::<T>().eval(x[0], x[1]);
        d.x.iter()
            .chain(d.xu.iter())
            .chain(d.xv.iter())
            .copied()
            .collect()
    }
    fn input_label(&self, j: usize) -> String {
        ["u", "v"][j].to_string()
    }
    fn output_label(&self, i: usize) -> String {
        format!("{}.{}", ["x", "x_u", "x_v"][i / 3], ["x", "y", "z"][i % 3])
    }
}

fn hand_jacobian(d: &SurfaceDerivs<f64>) -> DMatrix<f64> {
    let mut j = DMatrix::zeros(9, 2);
    for c in 0..3 {
        j[(c, 0)] = d.xu[c];
        j[(c, 1)] = d.xv[c];
        j[(3 + c, 0)] = d.xuu[c];
        j[(3 + c, 1)] = d.xuv[c];
        j[(6 + c, 0)] = d.xuv[c];
        j[(6 + c, 1)] = d.xvv[c];
    }
    j
}

#[test]
fn parametric_derivatives_three_ways() {
    // Hand vs dual: both are exact derivatives of the same closed form / the same A2.3+A4.4
    // arithmetic, so they differ by round-off only (measured ≤ ~1e-14); 1e-11 leaves three orders
    // of margin. Hand vs central differences with h = ε^(1/3)·max(1, |u|) ≈ 6e-6: truncation
    // h²/6·|x'''|/|x'| ≈ 1e-11 and round-off ε|x|/(h|x'|) ≈ 1e-10 for these unit-to-ten scale
    // surfaces; 1e-7 is three orders above either.
    //
    // Components far below the largest (exact zeros such as x_vv of a ruled surface, or the
    // z-part of x_uu of a cylinder that A4.4 produces as a round-off residue ≈ 1e-15) are
    // compared absolutely. For dual numbers the floor is 1e-3 of the largest component (absolute
    // bound 1e-14·max|J|, about 50 ulps). A central difference carries round-off ε|x|/h ≈ 4e-10
    // for |x| ≈ 10, so for finite differences the floor is 1e-2 (absolute bound 1e-9·max|J|,
    // ≥ 5e-9 here).
    let mut opts = CheckOptions::new(1e-11, 1e-7);
    opts.dual.floor = 1e-3;
    opts.fd.floor = 1e-2;
    // Fractions of the domain, all at least 1e-3 away from every knot so the differences never
    // straddle a knot (where x_uu may jump).
    let fractions = [
        (0.13, 0.71),
        (0.37, 0.12),
        (0.52, 0.88),
        (0.71, 0.33),
        (0.88, 0.52),
        (0.5, 0.5),
    ];
    let (mut worst_dual, mut worst_fd) = (0.0_f64, 0.0_f64);
    for (name, s) in all_surfaces() {
        let dom = s.domain();
        for &(fu, fv) in &fractions {
            let u = dom[0][0] + fu * (dom[0][1] - dom[0][0]);
            let v = dom[1][0] + fv * (dom[1][1] - dom[1][0]);
            let d = s.eval(u, v);
            let r = check(
                &ByParameter(&s),
                &format!("{name} at ({u}, {v})"),
                &[u, v],
                &hand_jacobian(&d),
                opts,
            );
            assert!(r.passed(), "{r}");
            worst_dual = worst_dual.max(r.vs_dual.max_error());
            worst_fd = worst_fd.max(r.vs_fd.max_error());
        }
    }
    println!("parametric derivatives: worst scaled error vs dual {worst_dual:.2e}, vs central differences {worst_fd:.2e}");
}

/// At an interior knot the span on the right is used; the derivatives stay consistent with the
/// dual-number derivative of the position there.
#[test]
fn derivatives_at_a_knot_match_dual_numbers() {
    let s = Surface::Nurbs(nurbs_general());
    for (u, v) in [(0.45, 0.25), (0.3, 0.6), (0.0, 0.0), (1.0, 1.0)] {
        let d = s.eval(u, v);
        let j = shelldsa::verification::dual_jacobian(&ByParameter(&s), &[u, v]);
        let h = hand_jacobian(&d);
        let scale = h.amax();
        assert!((j - &h).amax() <= 1e-12 * scale, "at ({u}, {v})");
    }
}

// ---------------------------------------------------------------------------------------------
// 2. NURBS conics reproduce the analytic cylinder and sphere.

#[test]
fn nurbs_quarter_cylinder_is_exact() {
    let nurbs = Surface::Nurbs(nurbs_quarter_cylinder());
    let exact = Surface::CylinderSector(
        CylinderSector::new(
            Vector3::zeros(),
            Vector3::z(),
            Vector3::x(),
            R_CYL,
            [0.0, FRAC_PI_2],
            [0.0, L_CYL],
        )
        .unwrap(),
    );
    let (mut e_pos, mut e_rad, mut e_n, mut e_h) = (0.0_f64, 0.0_f64, 0.0_f64, 0.0_f64);
    for a in 0..=20 {
        for b in 0..=20 {
            let (u, v) = (a as f64 / 20.0, b as f64 / 20.0);
            let d = nurbs.eval(u, v);
            // Distance from the axis must be R (the NURBS parametrisation differs from the
            // angular one; the point is mapped back by its angle and height).
            e_rad = e_rad.max(((d.x.x.hypot(d.x.y)) - R_CYL).abs() / R_CYL);
            let theta = d.x.y.atan2(d.x.x);
            let e = exact.eval(theta / FRAC_PI_2, d.x.z / L_CYL);
            e_pos = e_pos.max((e.x - d.x).norm() / R_CYL);
            e_n = e_n.max((e.normal().unwrap() - d.normal().unwrap()).norm());
            e_h = e_h.max((d.mean_curvature().unwrap() * 2.0 * R_CYL + 1.0).abs());
        }
    }
    println!("quarter cylinder: radius {e_rad:.2e}, position {e_pos:.2e}, normal {e_n:.2e}, 2RH+1 {e_h:.2e}");
    // Positions are exact up to a few round-offs of |x| ≈ R: 1e-14 relative is ~45 ulps. Normals
    // are unit vectors built from x_u × x_v (a cancellation-free product of O(R) vectors),
    // compared absolutely at the same bound. Curvature involves second derivatives divided by
    // the metric: a looser 1e-12.
    assert!(
        e_rad <= 1e-14 && e_pos <= 1e-14,
        "radius {e_rad:e}, position {e_pos:e}"
    );
    assert!(e_n <= 1e-14, "normal {e_n:e}");
    assert!(e_h <= 1e-12, "mean curvature {e_h:e}");
}

#[test]
fn nurbs_sphere_patch_is_exact() {
    let nurbs = Surface::Nurbs(nurbs_sphere_patch());
    let exact = hemisphere_quadrant();
    let c = sphere_centre();
    let lat1 = 72f64.to_radians();
    let (mut e_rad, mut e_pos, mut e_n, mut e_h, mut e_k) =
        (0.0_f64, 0.0_f64, 0.0_f64, 0.0_f64, 0.0_f64);
    for a in 0..=20 {
        for b in 0..=20 {
            let (u, v) = (a as f64 / 20.0, b as f64 / 20.0);
            let d = nurbs.eval(u, v);
            let r = d.x - c;
            e_rad = e_rad.max((r.norm() - R_SPH).abs() / R_SPH);
            let lam = r.y.atan2(r.x);
            let phi = r.z.atan2(r.x.hypot(r.y));
            let e = exact.eval(lam / FRAC_PI_2, phi / lat1);
            e_pos = e_pos.max((e.x - d.x).norm() / R_SPH);
            e_n = e_n.max((e.normal().unwrap() - d.normal().unwrap()).norm());
            // Outward: the normal is the unit radial vector.
            e_n = e_n.max((d.normal().unwrap() - r / r.norm()).norm());
            e_h = e_h.max((d.mean_curvature().unwrap() * R_SPH + 1.0).abs());
            e_k = e_k.max((d.gaussian_curvature().unwrap() * R_SPH * R_SPH - 1.0).abs());
        }
    }
    println!(
        "sphere patch: radius {e_rad:.2e}, position {e_pos:.2e}, normal {e_n:.2e}, RH+1 {e_h:.2e}, R²K−1 {e_k:.2e}"
    );
    // As for the cylinder; the latitude is recovered by atan2 of O(R) numbers (a few ulps).
    assert!(
        e_rad <= 1e-14 && e_pos <= 1e-14,
        "radius {e_rad:e}, position {e_pos:e}"
    );
    assert!(e_n <= 1e-14, "normal {e_n:e}");
    assert!(e_h <= 1e-12 && e_k <= 1e-12, "curvature {e_h:e} {e_k:e}");
}

#[test]
fn analytic_orientation_and_curvature() {
    // Cylinder and sphere normals point away from the axis / centre; annulus normal is `normal`.
    let cyl = cylinder();
    let Surface::CylinderSector(c) = &cyl else {
        unreachable!()
    };
    let a = c.axis.normalize();
    let d = cyl.eval(0.3, 0.6);
    let radial = {
        let r = d.x - c.origin;
        let r = r - a * r.dot(&a);
        r / r.norm()
    };
    assert!((d.normal().unwrap() - radial).norm() < 1e-15 * 10.0);
    assert!((d.mean_curvature().unwrap() * 2.0 * c.radius + 1.0).abs() < 1e-14);
    let ann = annulus();
    let Surface::AnnulusSector(an) = &ann else {
        unreachable!()
    };
    let n = ann.eval(0.4, 0.7).normal().unwrap();
    assert!((n - an.normal.normalize()).norm() < 1e-15 * 10.0);
    assert!(ann.eval(0.4, 0.7).mean_curvature().unwrap().abs() < 1e-15);
    let sph = hemisphere_quadrant();
    let d = sph.eval(0.25, 0.4);
    let r = d.x - sphere_centre();
    assert!((d.normal().unwrap() - r / r.norm()).norm() < 1e-15 * 10.0);
    // Normal curvature of a sphere is −1/R in every direction.
    let k = d
        .normal_curvature(nalgebra::Vector2::new(0.3, -0.8))
        .unwrap();
    assert!((k * R_SPH + 1.0).abs() < 1e-14);
    // Eq (66) tangents are x_u, x_v.
    assert_eq!(d.tangents(), (d.xu, d.xv));
}

// ---------------------------------------------------------------------------------------------
// 3. B-spline basis functions.

/// Cox–de Boor recursion with the derivative formula (Piegl & Tiller eq 2.9), written
/// independently of the library: value, first and second derivative of `N_{i,p}(u)`, using the
/// half-open convention and, at the end of the range, the last non-empty span.
fn cox_de_boor(i: usize, p: usize, u: f64, k: &[f64]) -> [f64; 3] {
    if p == 0 {
        let last = k[k.len() - 1];
        let inside = if u >= last {
            // u at the end: the last non-empty span [k_i, k_{i+1}) takes it.
            k[i] < k[i + 1] && k[i + 1] == last
        } else {
            k[i] <= u && u < k[i + 1]
        };
        return [if inside { 1.0 } else { 0.0 }, 0.0, 0.0];
    }
    let a = cox_de_boor(i, p - 1, u, k);
    let b = cox_de_boor(i + 1, p - 1, u, k);
    let d1 = k[i + p] - k[i];
    let d2 = k[i + p + 1] - k[i + 1];
    let f1 = if d1 > 0.0 { 1.0 / d1 } else { 0.0 };
    let f2 = if d2 > 0.0 { 1.0 / d2 } else { 0.0 };
    let pf = p as f64;
    [
        (u - k[i]) * f1 * a[0] + (k[i + p + 1] - u) * f2 * b[0],
        pf * (f1 * a[0] - f2 * b[0]),
        pf * (f1 * a[1] - f2 * b[1]),
    ]
}

#[test]
#[allow(clippy::needless_range_loop)] // index notation mirrors the formulas
fn basis_functions_partition_of_unity_and_cox_de_boor() {
    let cases: Vec<(usize, Vec<f64>)> = vec![
        (1, vec![0.0, 0.0, 0.2, 0.5, 0.5, 1.0, 1.0]),
        (2, vec![-1.0, -1.0, -1.0, 0.0, 0.5, 0.5, 3.0, 3.0, 3.0]),
        // Degree 3, non-uniform, with a double interior knot.
        (
            3,
            vec![0.0, 0.0, 0.0, 0.0, 0.1, 0.35, 0.35, 0.8, 1.0, 1.0, 1.0, 1.0],
        ),
    ];
    let (mut e_sum, mut e_ref, mut e_dual) = (0.0_f64, 0.0_f64, 0.0_f64);
    for (p, k) in &cases {
        let p = *p;
        let n = k.len() - p - 1;
        let (a, b) = (k[p], k[n]);
        let mut us: Vec<f64> = (0..=400).map(|t| a + (b - a) * t as f64 / 400.0).collect();
        us.extend(k.iter().copied()); // every knot, including the ends
        for &u in &us {
            let span = find_span(n, p, u, k);
            assert!(
                span >= p && span < n && k[span] <= u && (u < k[span + 1] || u == b),
                "span {span} at {u}"
            );
            let ders = basis_function_derivatives(span, u, p, k).unwrap();
            let sum: f64 = ders[0][..=p].iter().sum();
            // Partition of unity: exact up to the round-off of a sum of p + 1 terms ≤ 1.
            e_sum = e_sum.max((sum - 1.0).abs());
            let dscale = ders[1][..=p].iter().fold(1.0_f64, |m, x| m.max(x.abs()));
            let ddscale = ders[2][..=p].iter().fold(1.0_f64, |m, x| m.max(x.abs()));
            // Derivatives of the partition of unity vanish: relative to the largest term.
            e_sum = e_sum.max(ders[1][..=p].iter().sum::<f64>().abs() / dscale);
            e_sum = e_sum.max(ders[2][..=p].iter().sum::<f64>().abs() / ddscale);
            for j in 0..=p {
                assert!(
                    ders[0][j] >= 0.0,
                    "N_{} = {} < 0 at {u}",
                    span - p + j,
                    ders[0][j]
                );
                let r = cox_de_boor(span - p + j, p, u, k);
                e_ref = e_ref.max((ders[0][j] - r[0]).abs());
                e_ref = e_ref.max((ders[1][j] - r[1]).abs() / dscale);
                e_ref = e_ref.max((ders[2][j] - r[2]).abs() / ddscale);
            }
            // Dual numbers through A2.3: d N/du from the values equals the first-derivative row.
            let dd = basis_function_derivatives(span, Dual::from_re(u).derivative(), p, k).unwrap();
            for j in 0..=p {
                e_dual = e_dual.max((dd[0][j].eps - ders[1][j]).abs() / dscale);
                e_dual = e_dual.max((dd[1][j].eps - ders[2][j]).abs() / ddscale);
            }
            // Functions outside the support span are zero: check all n against Cox–de Boor.
            let total: f64 = (0..n).map(|i| cox_de_boor(i, p, u, k)[0]).sum();
            assert!(
                (total - 1.0).abs() < 1e-14,
                "Cox–de Boor sum {total} at {u}"
            );
        }
    }
    println!(
        "basis: partition of unity {e_sum:.2e}, vs Cox–de Boor {e_ref:.2e}, vs dual {e_dual:.2e}"
    );
    // All three are round-off comparisons of O(1) quantities (values ≤ 1, derivatives scaled by
    // the largest): 1e-13 allows a few hundred ulps for the deepest (degree 3) recursions.
    assert!(
        e_sum <= 1e-13 && e_ref <= 1e-13 && e_dual <= 1e-13,
        "{e_sum:e} {e_ref:e} {e_dual:e}"
    );
}

#[test]
fn basis_function_input_errors_do_not_panic() {
    let k = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
    assert!(matches!(
        basis_function_derivatives(2, 0.5, 4, &k),
        Err(GeometryError::Degree { .. })
    ));
    assert!(basis_function_derivatives(9, 0.5, 2, &k).is_err());
    assert!(basis_function_derivatives(1, 0.5, 2, &k).is_err());
    // find_span never panics, whatever the input.
    assert_eq!(find_span(3, 2, f64::NAN, &k), 2);
    assert_eq!(find_span(3, 2, -5.0, &k), 2);
    assert_eq!(find_span(3, 2, 7.0, &k), 2);
    let _ = find_span(0, 2, 0.5, &[]);
    let _ = find_span(10, 2, 0.5, &k);
}

// ---------------------------------------------------------------------------------------------
// 4. Design-parameter derivatives through `with_design_parameters` seeded with Dual64.

/// The surface with parameter `name` seeded (derivative part 1), evaluated at `(u, v)`.
fn seeded(s: &Surface<f64>, name: &str, u: f64, v: f64) -> SurfaceDerivs<Dual> {
    let k = s
        .parameter_index(name)
        .unwrap_or_else(|| panic!("no parameter {name}"));
    let p: Vec<Dual> = s
        .design_parameters()
        .iter()
        .enumerate()
        .map(|(i, (_, x))| {
            if i == k {
                Dual::from_re(*x).derivative()
            } else {
                Dual::from_re(*x)
            }
        })
        .collect();
    s.with_design_parameters(&p)
        .unwrap()
        .eval(Dual::from_re(u), Dual::from_re(v))
}

fn eps(v: &Vector3<Dual>) -> Vector3<f64> {
    v.map(|c| c.eps)
}

#[test]
fn radius_derivatives_are_exact() {
    let sph = hemisphere_quadrant();
    let cyl = cylinder();
    let Surface::CylinderSector(c) = &cyl else {
        unreachable!()
    };
    let (e1, e2) = {
        let a = c.axis.normalize();
        let e1 = (c.reference - a * c.reference.dot(&a)).normalize();
        (e1, a.cross(&e1))
    };
    let mut worst = 0.0_f64;
    for &(u, v) in &[(0.1, 0.2), (0.5, 0.5), (0.9, 0.95), (0.0, 1.0)] {
        // Sphere: x = c + R r̂(λ, φ) ⇒ ∂x/∂R = r̂, and ∂x_α/∂R = x_α / R.
        let d = seeded(&sph, "radius", u, v);
        let (lam, phi) = (u * FRAC_PI_2, v * 72f64.to_radians());
        let rhat = Vector3::new(phi.cos() * lam.cos(), phi.cos() * lam.sin(), phi.sin());
        worst = worst.max((eps(&d.x) - rhat).norm());
        let f = d.value();
        worst = worst.max((eps(&d.xu) - f.xu / R_SPH).norm() / (f.xu.norm() / R_SPH));
        worst = worst.max((eps(&d.xvv) - f.xvv / R_SPH).norm() / (f.xvv.norm() / R_SPH));
        // Cylinder: ∂x/∂R = cos θ e₁ + sin θ e₂.
        let d = seeded(&cyl, "radius", u, v);
        let th = c.angle[0] + u * (c.angle[1] - c.angle[0]);
        worst = worst.max((eps(&d.x) - (e1 * th.cos() + e2 * th.sin())).norm());
    }
    println!("d x/d R (sphere, cylinder): worst error {worst:.2e}");
    // Unit vectors computed two ways (a few trigonometric round-offs): 1e-15 absolute.
    assert!(worst <= 1e-15, "{worst:e}");
}

#[test]
#[allow(clippy::needless_range_loop)] // index notation mirrors the formulas
fn control_point_and_weight_derivatives_equal_rational_basis() {
    let nurbs = nurbs_general();
    let s = Surface::Nurbs(nurbs.clone());
    let [nu, nv] = nurbs.n_points();
    let [ku, kv] = nurbs.knots().clone();
    let mut worst = 0.0_f64;
    for &(u, v) in &[(0.2, 0.4), (0.41, 0.7), (0.45, 0.1), (0.77, 0.93)] {
        // Independent: N_i(u) N_j(v) from Cox–de Boor, R_ij = N_i N_j w_ij / W.
        let bu: Vec<[f64; 3]> = (0..nu).map(|i| cox_de_boor(i, 3, u, &ku)).collect();
        let bv: Vec<[f64; 3]> = (0..nv).map(|j| cox_de_boor(j, 2, v, &kv)).collect();
        let w = |i, j| nurbs.weight(i, j).unwrap();
        let (mut big_w, mut big_wu) = (0.0, 0.0);
        for i in 0..nu {
            for j in 0..nv {
                big_w += bu[i][0] * bv[j][0] * w(i, j);
                big_wu += bu[i][1] * bv[j][0] * w(i, j);
            }
        }
        let x = s.eval(u, v).x;
        for (i, j) in [(0, 0), (3, 2), (2, 1), (4, 3), (5, 4)] {
            let r = bu[i][0] * bv[j][0] * w(i, j) / big_w;
            let ru = (bu[i][1] * bv[j][0] * w(i, j) * big_w
                - bu[i][0] * bv[j][0] * w(i, j) * big_wu)
                / (big_w * big_w);
            // ∂x/∂P_ij.z = R_ij e_z, ∂x_u/∂P_ij.z = R_ij,u e_z; ∂x/∂P_ij.x = R_ij e_x.
            let dz = seeded(&s, &format!("cp[{i}][{j}].z"), u, v);
            worst = worst.max((eps(&dz.x) - Vector3::new(0.0, 0.0, r)).norm());
            worst =
                worst.max((eps(&dz.xu) - Vector3::new(0.0, 0.0, ru)).norm() / ru.abs().max(1.0));
            let dx = seeded(&s, &format!("cp[{i}][{j}].x"), u, v);
            worst = worst.max((eps(&dx.x) - Vector3::new(r, 0.0, 0.0)).norm());
            // ∂x/∂w_ij = N_i N_j (P_ij − x) / W.
            let dw = seeded(&s, &format!("weight[{i}][{j}]"), u, v);
            let expect = (nurbs.point(i, j).unwrap() - x) * (bu[i][0] * bv[j][0] / big_w);
            worst = worst.max((eps(&dw.x) - expect).norm() / expect.norm().max(1.0));
        }
    }
    println!("d x/d (control point, weight): worst error vs rational basis {worst:.2e}");
    // R_ij ≤ 1 and the other quantities are O(1) (or scaled to it): round-off of two different
    // evaluation orders; 1e-14 absolute is ~50 ulps.
    assert!(worst <= 1e-14, "{worst:e}");
}

#[test]
fn design_parameter_names_values_and_lift() {
    let s = Surface::Nurbs(nurbs_general());
    let p = s.design_parameters();
    assert_eq!(p.len(), 7 * 5 * 4);
    assert_eq!(s.parameter_index("cp[3][2].z"), Some((3 * 5 + 2) * 4 + 2));
    assert_eq!(
        p[s.parameter_index("weight[1][1]").unwrap()].1,
        nurbs_general().weight(1, 1).unwrap()
    );
    let sph = hemisphere_quadrant();
    let names: Vec<String> = sph
        .design_parameters()
        .into_iter()
        .map(|(n, _)| n)
        .collect();
    assert_eq!(
        names,
        [
            "centre.x",
            "centre.y",
            "centre.z",
            "radius",
            "latitude_start",
            "latitude_end",
            "longitude_start",
            "longitude_end"
        ]
    );
    for (_, s) in all_surfaces() {
        // Round trips: parameters → same surface; lift → value → same surface.
        let vals: Vec<f64> = s.design_parameters().iter().map(|(_, x)| *x).collect();
        assert_eq!(s.with_design_parameters(&vals).unwrap(), s);
        assert_eq!(s.lift::<Dual>().value(), s);
        assert_eq!(s.n_design_parameters(), vals.len());
        // Dual and f64 evaluation agree to round-off (num-dual's trigonometric functions may
        // round differently in the last ulp).
        let d = s
            .lift::<Dual>()
            .eval(Dual::from_re(0.3), Dual::from_re(0.6))
            .value();
        let f = s.eval(0.3, 0.6);
        for (a, b) in [
            (d.x, f.x),
            (d.xu, f.xu),
            (d.xv, f.xv),
            (d.xuu, f.xuu),
            (d.xuv, f.xuv),
            (d.xvv, f.xvv),
        ] {
            assert!((a - b).norm() <= 1e-15 * f.x.norm().max(f.xuu.norm()).max(1.0));
        }
    }
}

// ---------------------------------------------------------------------------------------------
// 5. Validation: every error triggers and names its field.

fn expect_err<T: std::fmt::Debug>(r: Result<T, GeometryError>, field: &str) -> GeometryError {
    let e = r.expect_err("expected an error");
    let msg = e.to_string();
    assert!(
        msg.contains(&format!("`{field}`")),
        "message {msg:?} does not name `{field}`"
    );
    println!("  {msg}");
    e
}

fn nurbs_spec(degree_u: usize, knots_u: Vec<f64>, rows: usize, weight: f64) -> SurfaceSpec {
    SurfaceSpec::Nurbs {
        degree_u,
        degree_v: 1,
        knots_u,
        knots_v: vec![0.0, 0.0, 1.0, 1.0],
        control_points: (0..rows)
            .map(|i| vec![[i as f64, 0.0, 0.0, 1.0], [i as f64, 1.0, 0.0, weight]])
            .collect(),
    }
}

#[test]
fn validation_errors_name_their_field() {
    use GeometryError as E;
    let k2 = vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
    // NURBS structure.
    assert!(matches!(
        expect_err(
            nurbs_spec(0, vec![0.0, 1.0, 1.0], 2, 1.0).build(),
            "degree_u"
        ),
        E::Degree { .. }
    ));
    assert!(matches!(
        expect_err(nurbs_spec(4, vec![0.0; 10], 5, 1.0).build(), "degree_u"),
        E::Degree { value: 4, .. }
    ));
    assert!(matches!(
        expect_err(nurbs_spec(2, k2.clone(), 4, 1.0).build(), "knots_u"),
        E::KnotCount { .. }
    ));
    assert!(matches!(
        expect_err(
            nurbs_spec(2, vec![0.0, 0.0, 0.0, 0.7, 0.5, 1.0, 1.0, 1.0], 5, 1.0).build(),
            "knots_u"
        ),
        E::KnotsDecreasing { index: 4, .. }
    ));
    assert!(matches!(
        expect_err(
            nurbs_spec(2, vec![0.0, 0.0, 0.2, 0.6, 1.0, 1.0, 1.0], 4, 1.0).build(),
            "knots_u"
        ),
        E::KnotsNotClamped { .. }
    ));
    assert!(matches!(
        expect_err(
            nurbs_spec(2, vec![0.0, 0.0, 0.0, 0.5, 0.5, 0.5, 1.0, 1.0, 1.0], 6, 1.0).build(),
            "knots_u"
        ),
        E::KnotMultiplicity {
            multiplicity: 3,
            ..
        }
    ));
    assert!(matches!(
        expect_err(
            nurbs_spec(1, vec![0.0, 0.0, 1.0, 1.0, 1.0], 3, 1.0).build(),
            "knots_u"
        ),
        E::KnotMultiplicity {
            multiplicity: 3,
            ..
        }
    ));
    assert!(matches!(
        expect_err(
            nurbs_spec(1, vec![0.0, 0.0, 0.0, 0.0], 2, 1.0).build(),
            "knots_u"
        ),
        E::InvalidRange { .. } | E::KnotMultiplicity { .. }
    ));
    assert!(matches!(
        expect_err(
            nurbs_spec(1, vec![0.0, 0.0, f64::NAN, 1.0], 2, 1.0).build(),
            "knots_u[2]"
        ),
        E::NonFinite { .. }
    ));
    assert!(matches!(
        expect_err(nurbs_spec(2, k2.clone(), 3, 0.0).build(), "weight[0][1]"),
        E::NonPositiveWeight { .. }
    ));
    assert!(matches!(
        expect_err(nurbs_spec(2, k2.clone(), 3, -0.5).build(), "weight[0][1]"),
        E::NonPositiveWeight { .. }
    ));
    assert!(matches!(
        expect_err(
            nurbs_spec(2, vec![0.0, 0.0, 1.0, 1.0], 1, 1.0).build(),
            "control_points"
        ),
        E::ControlNet { .. }
    ));
    let ragged = SurfaceSpec::Nurbs {
        degree_u: 1,
        degree_v: 1,
        knots_u: vec![0.0, 0.0, 1.0, 1.0],
        knots_v: vec![0.0, 0.0, 1.0, 1.0],
        control_points: vec![
            vec![[0.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 1.0]],
            vec![[1.0, 0.0, 0.0, 1.0]],
        ],
    };
    assert!(matches!(
        expect_err(ragged.build(), "control_points[1]"),
        E::ControlNet { .. }
    ));
    let nan_cp = SurfaceSpec::Nurbs {
        degree_u: 1,
        degree_v: 1,
        knots_u: vec![0.0, 0.0, 1.0, 1.0],
        knots_v: vec![0.0, 0.0, 1.0, 1.0],
        control_points: vec![
            vec![[0.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 1.0]],
            vec![[1.0, 0.0, f64::INFINITY, 1.0], [1.0, 1.0, 0.0, 1.0]],
        ],
    };
    assert!(matches!(
        expect_err(nan_cp.build(), "cp[1][0].z"),
        E::NonFinite { .. }
    ));
    assert!(matches!(
        expect_err(
            NurbsSurface::new(
                [1, 1],
                [vec![0.0, 0.0, 1.0, 1.0], vec![0.0, 0.0, 1.0, 1.0]],
                vec![vec![Vector3::zeros(); 2]; 2],
                vec![vec![1.0; 2]]
            ),
            "weights"
        ),
        E::ControlNet { .. }
    ));

    // Analytic patches.
    let o = Vector3::zeros();
    assert!(matches!(
        expect_err(SphereZone::new(o, 0.0, [0.0, 1.0], [0.0, 1.0]), "radius"),
        E::InvalidRadius { .. }
    ));
    assert!(matches!(
        expect_err(
            CylinderSector::new(o, Vector3::z(), Vector3::x(), -1.0, [0.0, 1.0], [0.0, 1.0]),
            "radius"
        ),
        E::InvalidRadius { .. }
    ));
    assert!(matches!(
        expect_err(
            AnnulusSector::new(o, Vector3::z(), Vector3::x(), -0.1, 1.0, [0.0, 1.0]),
            "inner_radius"
        ),
        E::InvalidRadius { .. }
    ));
    assert!(matches!(
        expect_err(
            AnnulusSector::new(o, Vector3::z(), Vector3::x(), 1.0, 1.0, [0.0, 1.0]),
            "outer_radius"
        ),
        E::InvalidRadius { .. }
    ));
    assert!(matches!(
        expect_err(SphereZone::new(o, 1.0, [0.5, 0.5], [0.0, 1.0]), "latitude"),
        E::InvalidRange { .. }
    ));
    assert!(matches!(
        expect_err(SphereZone::new(o, 1.0, [0.0, 1.7], [0.0, 1.0]), "latitude"),
        E::InvalidRange { .. }
    ));
    assert!(matches!(
        expect_err(SphereZone::new(o, 1.0, [0.0, 1.0], [1.0, 0.0]), "longitude"),
        E::InvalidRange { .. }
    ));
    assert!(matches!(
        expect_err(
            CylinderSector::new(o, Vector3::z(), Vector3::x(), 1.0, [0.0, 7.0], [0.0, 1.0]),
            "angle"
        ),
        E::InvalidRange { .. }
    ));
    assert!(matches!(
        expect_err(
            CylinderSector::new(o, Vector3::z(), Vector3::x(), 1.0, [0.0, 1.0], [2.0, 2.0]),
            "length"
        ),
        E::InvalidRange { .. }
    ));
    assert!(matches!(
        expect_err(
            CylinderSector::new(
                o,
                Vector3::zeros(),
                Vector3::x(),
                1.0,
                [0.0, 1.0],
                [0.0, 1.0]
            ),
            "axis"
        ),
        E::DegenerateVector { .. }
    ));
    assert!(matches!(
        expect_err(
            CylinderSector::new(
                o,
                Vector3::z(),
                Vector3::z() * 3.0,
                1.0,
                [0.0, 1.0],
                [0.0, 1.0]
            ),
            "reference"
        ),
        E::DegenerateVector { .. }
    ));
    assert!(matches!(
        expect_err(
            Rectangle::new(o, Vector3::x(), Vector3::x() * -2.0),
            "edge_v"
        ),
        E::DegenerateVector { .. }
    ));
    assert!(matches!(
        expect_err(
            SphereZone::new(
                Vector3::new(0.0, f64::NAN, 0.0),
                1.0,
                [0.0, 1.0],
                [0.0, 1.0]
            ),
            "centre.y"
        ),
        E::NonFinite { .. }
    ));
    assert!(matches!(
        expect_err(
            SphereZone::new(o, f64::INFINITY, [0.0, 1.0], [0.0, 1.0]),
            "radius"
        ),
        E::NonFinite { .. }
    ));

    // Domain, parameter count, degenerate normal.
    let s = Surface::Nurbs(nurbs_linear_cubic());
    assert!(matches!(
        expect_err(s.eval_checked(2.5, 1.0), "u"),
        E::OutsideDomain { .. }
    ));
    assert!(matches!(
        expect_err(s.eval_checked(0.0, -0.1), "v"),
        E::OutsideDomain { .. }
    ));
    assert!(matches!(
        expect_err(s.eval_checked(f64::NAN, 1.0), "u"),
        E::OutsideDomain { .. }
    ));
    assert!(s.eval_checked(2.0, 5.0).is_ok());
    assert_eq!(s.clamp(2.5, -1.0), (2.0, 0.0));
    assert!(matches!(
        expect_err(s.with_design_parameters(&[1.0, 2.0]), "design parameters"),
        E::ParameterCount { got: 2, .. }
    ));
    let mut p: Vec<f64> = s.design_parameters().iter().map(|(_, x)| *x).collect();
    p[s.parameter_index("weight[1][2]").unwrap()] = -1.0;
    assert!(matches!(
        expect_err(s.with_design_parameters(&p), "weight[1][2]"),
        E::NonPositiveWeight { .. }
    ));
    let mut p: Vec<f64> = hemisphere_quadrant()
        .design_parameters()
        .iter()
        .map(|(_, x)| *x)
        .collect();
    p[3] = 0.0;
    expect_err(hemisphere_quadrant().with_design_parameters(&p), "radius");
    let pole = SphereZone::new(o, 1.0, [0.0, FRAC_PI_2], [0.0, FRAC_PI_4])
        .unwrap()
        .eval(0.5, 1.0);
    assert!(matches!(
        expect_err(pole.normal(), "normal"),
        E::DegenerateNormal { .. }
    ));
}

#[test]
fn evaluation_never_panics_on_bad_parameters() {
    for (_, s) in all_surfaces() {
        for (u, v) in [
            (f64::NAN, 0.5),
            (0.5, f64::INFINITY),
            (-3.0, 7.0),
            (1e300, -1e300),
        ] {
            let _ = s.eval(u, v);
        }
    }
    // Extrapolation outside the knot range continues the end polynomial pieces smoothly.
    let s = Surface::Nurbs(nurbs_general());
    let (a, b) = (s.eval(1.0 + 1e-9, 0.5), s.eval(1.0, 0.5));
    assert!((a.x - b.x).norm() < 1e-7 && a.x.iter().all(|c| c.is_finite()));
    // A hand-edited invalid analytic patch evaluates to NaN, not a panic.
    let bad = Surface::SphereZone(SphereZone {
        centre: Vector3::zeros(),
        radius: f64::NAN,
        latitude: [0.0, 1.0],
        longitude: [0.0, 1.0],
    });
    assert!(bad.eval(0.5, 0.5).x.x.is_nan());
    assert!(bad.validate().is_err());
}

// ---------------------------------------------------------------------------------------------
// Case-file descriptions.

#[test]
fn toml_specs_build_surfaces() {
    let text = r#"
        [rect]
        type = "rectangle"
        origin = [0.0, 0.0, 0.0]
        edge_u = [2.0, 0.0, 0.0]
        edge_v = [0.0, 3.0, 0.0]

        [ring]
        type = "annulus-sector"
        centre = [0.0, 0.0, 1.0]
        normal = [0.0, 0.0, 1.0]
        reference = [1.0, 0.0, 0.0]
        inner_radius = 1.0
        outer_radius = 2.0
        angle_deg = [0.0, 90.0]

        [die]
        type = "cylinder-sector"
        origin = [0.0, 0.0, 0.0]
        axis = [0.0, 1.0, 0.0]
        reference = [1.0, 0.0, 0.0]
        radius = 5.0
        angle_deg = [-90.0, 0.0]
        length = [0.0, 10.0]

        [shell]
        type = "sphere-zone"
        centre = [0.0, 0.0, 0.0]
        radius = 10.0
        latitude_deg = [0.0, 72.0]
        longitude_deg = [0.0, 90.0]

        [patch]
        type = "nurbs"
        degree_u = 2
        degree_v = 1
        knots_u = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0]
        knots_v = [0.0, 0.0, 1.0, 1.0]
        control_points = [
            [[2.5, 0.0, 0.0, 1.0], [2.5, 0.0, 4.0, 1.0]],
            [[2.5, 2.5, 0.0, 0.7071067811865476], [2.5, 2.5, 4.0, 0.7071067811865476]],
            [[0.0, 2.5, 0.0, 1.0], [0.0, 2.5, 4.0, 1.0]],
        ]
    "#;
    let specs: std::collections::BTreeMap<String, SurfaceSpec> = toml::from_str(text).unwrap();
    let built: std::collections::BTreeMap<&str, Surface<f64>> = specs
        .iter()
        .map(|(k, s)| (k.as_str(), Surface::try_from(s).unwrap()))
        .collect();
    assert_eq!(built["rect"].kind(), "rectangle");
    assert_eq!(built["ring"].kind(), "annulus-sector");
    assert_eq!(built["die"].kind(), "cylinder-sector");
    let Surface::SphereZone(z) = &built["shell"] else {
        panic!()
    };
    assert!((z.latitude[1] - 72f64.to_radians()).abs() < 1e-16);
    // The TOML NURBS is the quarter cylinder of the exactness test.
    assert_eq!(built["patch"], Surface::Nurbs(nurbs_quarter_cylinder()));
    // Unknown fields and types are rejected by serde; invalid values by `build`, naming the field.
    assert!(toml::from_str::<SurfaceSpec>("type = \"sphere-zone\"\ncentre = [0,0,0]\nradius = 1.0\nlatitude_deg = [0, 1]\nlongitude_deg = [0, 1]\ncolour = 3").is_err());
    assert!(toml::from_str::<SurfaceSpec>("type = \"torus\"").is_err());
    let bad: SurfaceSpec =
        toml::from_str("type = \"sphere-zone\"\ncentre = [0,0,0]\nradius = 0.0\nlatitude_deg = [0, 1]\nlongitude_deg = [0, 1]")
            .unwrap();
    expect_err(bad.build(), "radius");
}

// ---------------------------------------------------------------------------------------------
// Random parameters.

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig { cases: 64, rng_seed: proptest::test_runner::RngSeed::Fixed(0x9e0), ..proptest::prelude::ProptestConfig::default() })]

    /// Hand-derived derivatives equal dual-number derivatives anywhere in the domain (including
    /// next to knots, where finite differences would straddle), for every surface; and a
    /// two-direction dual seeds (u, v) at once.
    #[test]
    fn hand_derivatives_match_duals_anywhere(fu in 0.0..=1.0f64, fv in 0.0..=1.0f64) {
        for (name, s) in all_surfaces() {
            let dom = s.domain();
            let u = dom[0][0] + fu * (dom[0][1] - dom[0][0]);
            let v = dom[1][0] + fv * (dom[1][1] - dom[1][0]);
            let d = s.eval(u, v);
            let h = hand_jacobian(&d);
            let j = shelldsa::verification::dual_jacobian(&ByParameter(&s), &[u, v]);
            // Round-off against the largest component, as in `parametric_derivatives_three_ways`.
            proptest::prop_assert!((j - &h).amax() <= 1e-13 * h.amax(), "{} at ({}, {})", name, u, v);
            let dn = s.lift::<shelldsa::scalar::DualN<2>>().eval(
                shelldsa::scalar::seed::<2>(u, 0),
                shelldsa::scalar::seed::<2>(v, 1),
            );
            for c in 0..3 {
                let p = shelldsa::scalar::dual_parts(&dn.x[c]);
                proptest::prop_assert!((p[0] - d.xu[c]).abs() <= 1e-13 * h.amax());
                proptest::prop_assert!((p[1] - d.xv[c]).abs() <= 1e-13 * h.amax());
            }
        }
    }

    /// Partition of unity and non-negativity at random parameters of a degree-3 non-uniform
    /// knot vector with a double interior knot.
    #[test]
    fn partition_of_unity_random(t in 0.0..=1.0f64) {
        let k = [0.0, 0.0, 0.0, 0.0, 0.1, 0.35, 0.35, 0.8, 1.0, 1.0, 1.0, 1.0];
        let span = find_span(8, 3, t, &k);
        let n = basis_function_derivatives(span, t, 3, &k).unwrap();
        proptest::prop_assert!((n[0].iter().sum::<f64>() - 1.0).abs() <= 1e-15);
        proptest::prop_assert!(n[0].iter().all(|&x| x >= 0.0));
    }
}
