//! Contact kernels: tool paths, closest-point projection (eq 67), gap and normal (eq 68) with
//! their dual-number derivatives, and the penalty force and consistent tangent at one slave
//! point (eqs 69–72) on curved tools (cylinder sector, sphere zone, rational NURBS patch).

use nalgebra::{DMatrix, Vector3};
use shelldsa::contact::{
    closest_point, nearest_tool, penalty_force, penalty_tangent, Bound, ContactError, PathKey,
    RigidMotion, RigidTool, Side, ToolPath,
};
use shelldsa::geometry::{CylinderSector, NurbsSurface, Rectangle, SphereZone, Surface};
use shelldsa::scalar::{Dual, Real};
use shelldsa::verification::{check, CheckOptions, Differentiable};
use std::f64::consts::PI;

type V3<T> = Vector3<T>;

fn key(t: f64, a: [f64; 3], th: [f64; 3]) -> PathKey {
    PathKey {
        t,
        translation: a,
        rotation: th,
    }
}

/// A sphere zone of radius 2 centred at the origin, latitudes ±60°, longitudes 0–180°.
fn sphere() -> Surface<f64> {
    Surface::SphereZone(
        SphereZone::new(V3::zeros(), 2.0, [-PI / 3.0, PI / 3.0], [0.0, PI]).unwrap(),
    )
}

/// A cylinder sector of radius 1.5 about the line through (0, −2, 3) along y, angles 200°–340°
/// (`e₂ = ŷ × x̂ = −ẑ`, so the sector is the upper part, around +z), length 0–4.
fn cylinder() -> Surface<f64> {
    Surface::CylinderSector(
        CylinderSector::new(
            V3::new(0.0, -2.0, 3.0),
            V3::new(0.0, 1.0, 0.0),
            V3::new(1.0, 0.0, 0.0),
            1.5,
            [200f64.to_radians(), 340f64.to_radians()],
            [0.0, 4.0],
        )
        .unwrap(),
    )
}

/// A rational biquadratic NURBS bump over [0, 2]² (no closed-form projection).
fn nurbs() -> Surface<f64> {
    let pts: Vec<Vec<V3<f64>>> = (0..3)
        .map(|i| {
            (0..3)
                .map(|j| {
                    let z = if i == 1 && j == 1 {
                        0.8
                    } else {
                        0.1 * (i + j) as f64
                    };
                    V3::new(i as f64, j as f64, z)
                })
                .collect()
        })
        .collect();
    let w = vec![
        vec![1.0, 1.0, 1.0],
        vec![1.0, 1.6, 1.0],
        vec![1.0, 1.0, 1.0],
    ];
    let k = vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
    Surface::Nurbs(NurbsSurface::new([2, 2], [k.clone(), k], pts, w).unwrap())
}

fn motion() -> RigidMotion<f64> {
    RigidMotion::new(
        V3::new(0.3, -0.2, 0.1),
        V3::new(0.2, -0.1, 0.15),
        V3::new(0.05, 0.1, -0.2),
    )
}

fn tool(name: &str, s: Surface<f64>, side: Side) -> RigidTool {
    RigidTool::new(name, s, side, ToolPath::fixed()).unwrap()
}

#[test]
fn path_validation_names_the_field() {
    let e = ToolPath::new([0.0; 3], vec![]).unwrap_err();
    assert!(matches!(&e, ContactError::InvalidInput { field, .. } if field == "path.keys"));
    let e = ToolPath::new(
        [0.0; 3],
        vec![key(0.0, [0.0; 3], [0.0; 3]), key(0.0, [1.0; 3], [0.0; 3])],
    )
    .unwrap_err();
    assert!(
        matches!(&e, ContactError::InvalidInput { field, .. } if field == "path.keys[1].t"),
        "{e}"
    );
    let e = ToolPath::new([0.0; 3], vec![key(0.0, [0.0, f64::NAN, 0.0], [0.0; 3])]).unwrap_err();
    assert!(
        matches!(&e, ContactError::InvalidInput { field, .. } if field == "path.keys[0].translation[1]"),
        "{e}"
    );
    let e = ToolPath::new(
        [f64::INFINITY, 0.0, 0.0],
        vec![key(0.0, [0.0; 3], [0.0; 3])],
    )
    .unwrap_err();
    assert!(matches!(&e, ContactError::InvalidInput { field, .. } if field == "path.pivot[0]"));
    // A tool whose parametrisation is singular (sphere zone up to the pole) is refused.
    let pole = Surface::SphereZone(
        SphereZone::new(V3::zeros(), 1.0, [0.0, PI / 2.0], [0.0, 1.0]).unwrap(),
    );
    let e = RigidTool::new("cap", pole, Side::Positive, ToolPath::fixed()).unwrap_err();
    assert!(
        matches!(&e, ContactError::Geometry { tool, .. } if tool == "cap"),
        "{e}"
    );
    let e = RigidTool::new(" ", sphere(), Side::Positive, ToolPath::fixed()).unwrap_err();
    assert!(matches!(&e, ContactError::InvalidInput { field, .. } if field == "tool.name"));
}

#[test]
fn path_interpolates_linearly_and_rests_outside() {
    let p = ToolPath::new(
        [1.0, 0.0, 0.0],
        vec![
            key(0.0, [0.0; 3], [0.0; 3]),
            key(0.5, [0.0, 0.0, -1.0], [0.0, 0.0, 0.4]),
            key(1.0, [1.0, 0.0, -1.0], [0.0, 0.0, 0.4]),
        ],
    )
    .unwrap();
    let (a, th) = p.position(0.25);
    assert_eq!(a, [0.0, 0.0, -0.5]);
    assert_eq!(th, [0.0, 0.0, 0.2]);
    assert_eq!(p.position(-1.0).0, [0.0; 3]);
    assert_eq!(p.position(7.0).0, [1.0, 0.0, -1.0]);
    // Rotation by 0.2 rad about z through the pivot (1, 0, 0), then the translation.
    let m = p.motion(0.25);
    let x = m.apply(&V3::new(2.0, 0.0, 0.0));
    let expect = V3::new(1.0 + 0.2f64.cos(), 0.2f64.sin(), -0.5);
    assert!((x - expect).norm() < 1e-15, "{x:?}");
    assert!((m.to_reference(&x) - V3::new(2.0, 0.0, 0.0)).norm() < 1e-15);
}

/// Sphere (solid inside: outward normal): `g = |X − c| − R`, `n = R_m (X − c)/|X − c|` in the
/// built frame, for a point inside the zone's angular range; derivatives by dual numbers against
/// the closed forms `∂g/∂x = n`, `∂n/∂x = (I − n nᵀ)/|x − c_moved|`.
#[test]
fn sphere_projection_matches_closed_form_with_derivatives() {
    let s = sphere();
    let m = motion();
    let tl = tool("ball", s.clone(), Side::Positive);
    let centre = m.apply(&V3::zeros());
    for (dir, dist) in [
        (V3::new(0.3, 0.9, 0.2), 2.3),   // outside
        (V3::new(-0.5, 0.6, -0.4), 1.7), // inside (penetrating)
    ] {
        let x = centre + m.rotation * dir.normalize() * dist;
        let cp = closest_point(&s, &m, Side::Positive, &tl.grid, &x, "ball").unwrap();
        assert!(cp.is_interior());
        let n_exact = (x - centre).normalize();
        // Round-off of a converged Newton on unit-size data: 1e-14 with margin.
        assert!(
            (cp.gap - (dist - 2.0)).abs() < 1e-14,
            "{} vs {}",
            cp.gap,
            dist - 2.0
        );
        assert!((cp.normal - n_exact).norm() < 1e-14);
        assert!((cp.surface.x - (centre + n_exact * 2.0)).norm() < 1e-14);
        // Dual derivative w.r.t. each component of x.
        for k in 0..3 {
            let mut xd = x.map(Dual::from_re);
            xd[k] = xd[k].derivative();
            let sd = s.lift::<Dual>();
            let cpd = closest_point(&sd, &m.lift(), Side::Positive, &tl.grid, &xd, "ball").unwrap();
            let r = (x - centre).norm();
            let dn: V3<f64> = (V3::ith(k, 1.0) - n_exact * n_exact[k]) / r;
            // Exact derivatives through one Newton correction: agreement to round-off.
            assert!((cpd.gap.eps - n_exact[k]).abs() < 1e-13, "dg/dx{k}");
            for c in 0..3 {
                assert!((cpd.normal[c].eps - dn[c]).abs() < 1e-13, "dn{c}/dx{k}");
            }
        }
        // Tool parameters: ∂g/∂R = −1; tool translation ∂g/∂a = −n.
        let p: Vec<Dual> = s
            .parameter_values()
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                if Some(i) == s.parameter_index("radius") {
                    Dual::from_re(v).derivative()
                } else {
                    Dual::from_re(v)
                }
            })
            .collect();
        let sr = s.with_design_parameters(&p).unwrap();
        let xd = x.map(Dual::from_re);
        let cpd = closest_point(&sr, &m.lift(), Side::Positive, &tl.grid, &xd, "ball").unwrap();
        assert!((cpd.gap.eps + 1.0).abs() < 1e-13, "dg/dR = {}", cpd.gap.eps);
        for k in 0..3 {
            let mut md = m.lift::<Dual>();
            md.translation[k] = md.translation[k].derivative();
            let cpd = closest_point(&s.lift(), &md, Side::Positive, &tl.grid, &xd, "ball").unwrap();
            assert!((cpd.gap.eps + n_exact[k]).abs() < 1e-13, "dg/da{k}");
        }
    }
}

/// Projection onto the boundary: beyond the rectangle's edge the closest point is on the edge
/// (constrained projection), beyond a corner it is the corner; neither is interior.
#[test]
fn projection_clamps_to_edges_and_corners() {
    let r = Surface::Rectangle(
        Rectangle::new(V3::zeros(), V3::new(2.0, 0.0, 0.0), V3::new(0.0, 1.0, 0.0)).unwrap(),
    );
    let tl = tool("die", r.clone(), Side::Positive);
    let id = RigidMotion::identity();
    let cp = closest_point(
        &r,
        &id,
        Side::Positive,
        &tl.grid,
        &V3::new(2.5, 0.4, -0.1),
        "die",
    )
    .unwrap();
    assert_eq!(cp.bounds, [Bound::Upper, Bound::Interior]);
    assert!((cp.surface.x - V3::new(2.0, 0.4, 0.0)).norm() < 1e-14);
    assert!(!cp.is_active());
    let cp = closest_point(
        &r,
        &id,
        Side::Positive,
        &tl.grid,
        &V3::new(-0.5, 1.4, 0.3),
        "die",
    )
    .unwrap();
    assert_eq!(cp.bounds, [Bound::Lower, Bound::Upper]);
    assert!((cp.surface.x - V3::new(0.0, 1.0, 0.0)).norm() < 1e-15);
    let cp = closest_point(
        &r,
        &id,
        Side::Positive,
        &tl.grid,
        &V3::new(1.2, 0.3, -0.01),
        "die",
    )
    .unwrap();
    assert!(cp.is_active());
    assert!((cp.gap + 0.01).abs() < 1e-15);
}

/// The nearest of two tools is the one with the smallest gap; a tool with only a boundary
/// projection does not count.
#[test]
fn nearest_tool_is_the_most_penetrated() {
    let die = tool(
        "die",
        Surface::Rectangle(
            Rectangle::new(
                V3::new(-1.0, -1.0, 0.0),
                V3::new(2.0, 0.0, 0.0),
                V3::new(0.0, 2.0, 0.0),
            )
            .unwrap(),
        ),
        Side::Positive,
    );
    // Punch above: a rectangle at z = 0.1 with its solid above (normal −z after the side flip).
    let punch = tool(
        "punch",
        Surface::Rectangle(
            Rectangle::new(
                V3::new(-1.0, -1.0, 0.1),
                V3::new(2.0, 0.0, 0.0),
                V3::new(0.0, 2.0, 0.0),
            )
            .unwrap(),
        ),
        Side::Negative,
    );
    let tools = vec![die, punch];
    let surfaces: Vec<Surface<f64>> = tools.iter().map(|t| t.surface.clone()).collect();
    let (i, cp) = nearest_tool(&tools, &surfaces, 0.0, &V3::new(0.0, 0.0, 0.12))
        .unwrap()
        .unwrap();
    assert_eq!(i, 1);
    assert!((cp.gap + 0.02).abs() < 1e-15);
    assert!((cp.normal - V3::new(0.0, 0.0, -1.0)).norm() < 1e-15);
    let (i, cp) = nearest_tool(&tools, &surfaces, 0.0, &V3::new(0.0, 0.0, 0.03))
        .unwrap()
        .unwrap();
    assert_eq!(i, 0);
    assert!((cp.gap - 0.03).abs() < 1e-15);
    assert!(
        nearest_tool(&tools, &surfaces, 0.0, &V3::new(3.0, 0.0, 0.03))
            .unwrap()
            .is_none()
    );
}

/// The penalty force of one slave point through the generic projection, as a function of the
/// slave point's position.
struct PointForce {
    surface: Surface<f64>,
    motion: RigidMotion<f64>,
    tool: RigidTool,
    omega: f64,
    area: f64,
}

impl Differentiable for PointForce {
    fn n_inputs(&self) -> usize {
        3
    }
    fn eval<T: Real>(&self, x: &[T]) -> Vec<T> {
        let xs = V3::new(x[0], x[1], x[2]);
        let cp = closest_point(
            &self.surface.lift::<T>(),
            &self.motion.lift(),
            self.tool.side,
            &self.tool.grid,
            &xs,
            &self.tool.name,
        )
        .unwrap();
        penalty_force(&cp, self.omega, self.area)
            .iter()
            .copied()
            .collect()
    }
    fn active_set(&self, x: &[f64]) -> Vec<u8> {
        let cp = closest_point(
            &self.surface,
            &self.motion,
            self.tool.side,
            &self.tool.grid,
            &V3::new(x[0], x[1], x[2]),
            "",
        )
        .unwrap();
        vec![u8::from(cp.is_active())]
    }
}

/// Hand-derived 3×3 tangent against the dual Jacobian (≤ 1e-12) and central differences
/// (≤ 1e-8: the truncation error `h² |f'''|/6` with `h ≈ 6e-6` relative is ~1e-10 here;
/// round-off ε/h ≈ 4e-11 of the force scale), on penetrating points whose projection slides
/// over curved tools from both sides (convex punch, concave cavity).
#[test]
fn penalty_tangent_matches_dual_and_central_differences_on_curved_tools() {
    let m = motion();
    let cases: Vec<(&str, Surface<f64>, Side, V3<f64>)> = vec![
        // Cylinder punch (solid inside): a point 0.05 inside, off the lowest line.
        ("cylinder punch", cylinder(), Side::Positive, {
            let c = V3::new(0.0, 0.7, 3.0);
            let d = V3::new(0.4, 0.0, 1.0).normalize();
            m.apply(&(c + d * 1.45))
        }),
        // Cylinder cavity (solid outside the cylinder): the point 0.04 beyond the surface.
        ("cylinder cavity", cylinder(), Side::Negative, {
            let c = V3::new(0.0, 1.3, 3.0);
            let d = V3::new(-0.3, 0.0, 1.0).normalize();
            m.apply(&(c + d * 1.54))
        }),
        ("sphere punch", sphere(), Side::Positive, {
            m.apply(&(V3::new(0.4, 0.8, 0.3).normalize() * 1.93))
        }),
        ("sphere cavity", sphere(), Side::Negative, {
            m.apply(&(V3::new(-0.2, 0.9, -0.35).normalize() * 2.06))
        }),
        // NURBS die (solid below its upward normal): a point 0.03 below the surface.
        ("nurbs die", nurbs(), Side::Positive, {
            let s = nurbs().eval(0.37, 0.58);
            m.apply(&(s.x - s.normal().unwrap() * 0.03))
        }),
    ];
    let omega = 1e4;
    let area = 0.02;
    for (name, s, side, x) in cases {
        let f = PointForce {
            surface: s.clone(),
            motion: m,
            tool: tool(name, s.clone(), side),
            omega,
            area,
        };
        let cp = closest_point(&s, &m, side, &f.tool.grid, &x, name).unwrap();
        assert!(cp.is_active(), "{name}: gap {}", cp.gap);
        // Curvature enters: the g-term is a visible part of the tangent.
        let hand = penalty_tangent(&cp, omega, area);
        let normal_only = cp.normal * cp.normal.transpose() * (-omega * area);
        assert!(
            (hand - normal_only).norm() > 1e-3 * hand.norm(),
            "{name}: no curvature term"
        );
        let hand = DMatrix::from_column_slice(3, 3, hand.as_slice());
        let rep = check(
            &f,
            name,
            &[x[0], x[1], x[2]],
            &hand,
            CheckOptions::new(1e-12, 1e-8),
        );
        println!("{rep}");
        assert!(
            rep.fd.flips.is_empty(),
            "{name}: contact status flips within ±h"
        );
        assert!(rep.passed(), "{name}");
        // Symmetric (conservative penalty): to round-off of the entries.
        assert!(
            (&hand - hand.transpose()).norm() < 1e-13 * hand.norm(),
            "{name}"
        );
    }
}

/// The force is zero for a separated point and for a point over the boundary, and equals
/// `−ω w g n` (eq 70) when penetrating.
#[test]
fn penalty_force_is_eq_70() {
    let s = sphere();
    let m = RigidMotion::identity();
    let tl = tool("ball", s.clone(), Side::Positive);
    let x = V3::new(0.0, 1.99, 0.0);
    let cp = closest_point(&s, &m, Side::Positive, &tl.grid, &x, "ball").unwrap();
    let f = penalty_force(&cp, 100.0, 0.5);
    assert!((f - V3::new(0.0, 0.5, 0.0)).norm() < 1e-12, "{f:?}");
    let cp = closest_point(
        &s,
        &m,
        Side::Positive,
        &tl.grid,
        &V3::new(0.0, 2.01, 0.0),
        "ball",
    )
    .unwrap();
    assert_eq!(penalty_force(&cp, 100.0, 0.5), V3::zeros());
    // Behind the zone (longitude range 0–180°: y < 0 projects onto its boundary).
    let cp = closest_point(
        &s,
        &m,
        Side::Positive,
        &tl.grid,
        &V3::new(0.1, -1.9, 0.0),
        "ball",
    )
    .unwrap();
    assert!(!cp.is_interior());
    assert_eq!(penalty_force(&cp, 100.0, 0.5), V3::zeros());
}
