//! Symmetry planes by image particles (docs/shell-formulation.md §6.1).
//!
//! - the rotation identity behind the image map of the rotation DOFs,
//!   `Q exp([θ]×) v = exp([det(Q) Q θ]×) Q v` for reflections and products of two;
//! - the plane checks (typed errors naming the edge and the deviation) and the image layout;
//! - an exactly symmetric response: a quarter model of a cylinder panel (planes y = 0 and z = 0,
//!   corner images included) against the full panel built independently with the mirrored
//!   particles and quadrature points and the mirrored state: internal forces and committed
//!   fields (at the original and the mirrored points) agree to round-off;
//! - the assembled tangent with images equals the dual-number Jacobian of the assembled
//!   residual, before and after a committed plastic step;
//! - a plane whose normal is not a coordinate axis (its `ū·n_s = 0` becomes a multiplier row)
//!   gives the rotated solution of the axis-aligned model, and eliminating versus multiplier rows
//!   give the same solution.

mod common;

use nalgebra::{Matrix3, Vector3};
use shelldsa::geometry::{CylinderSector, Rectangle, SphereZone, Surface};
use shelldsa::kinematics::rotation::rotate_director;
use shelldsa::material::MaterialParams;
use shelldsa::meshfree::Edge;
use shelldsa::meshfree::{regular_grid, Basis, ParamBox, XorShift64};
use shelldsa::scalar::Real;
use shelldsa::shell::constraints::{edge_constraints, EdgeCondition};
use shelldsa::shell::load::{PointForce, Pressure};
use shelldsa::shell::model::{Discretisation, ShellModel};
use shelldsa::shell::problem::{ProblemOptions, ShellProblem, SymmetryTreatment};
use shelldsa::shell::symmetry::{SymmetryError, SymmetryPlane};
use shelldsa::shell::ShellError;
use shelldsa::solver::{LinearSolver, LoadStepping, Method, NewtonSolver, SolverOptions};
use shelldsa::verification::{compare_matrices, dual_jacobian, Differentiable, Tolerance};

const R: f64 = 5.0;

fn cylinder(angle_deg: [f64; 2], length: [f64; 2]) -> Surface<f64> {
    Surface::CylinderSector(
        CylinderSector::new(
            Vector3::zeros(),
            Vector3::z(),
            Vector3::x(),
            R,
            [angle_deg[0].to_radians(), angle_deg[1].to_radians()],
            length,
        )
        .unwrap(),
    )
}

fn material() -> MaterialParams<f64> {
    MaterialParams::new(7.0e4, 0.34, 184.3, 70.0, 0.5).unwrap()
}

fn thickness_rule() -> Vec<(f64, f64)> {
    let s3 = 0.6f64.sqrt();
    vec![(-s3, 5.0 / 9.0), (0.0, 8.0 / 9.0), (s3, 5.0 / 9.0)]
}

/// 4 × 4 cells of 2 × 2 Gauss points on the unit square.
fn quadrature() -> Vec<([f64; 2], f64)> {
    let g = 1.0 / 3f64.sqrt();
    let mut quad = Vec::new();
    for cu in 0..4 {
        for cv in 0..4 {
            for (a, b) in [(-g, -g), (g, -g), (-g, g), (g, g)] {
                let u = (cu as f64 + 0.5 + 0.5 * a) / 4.0;
                let v = (cv as f64 + 0.5 + 0.5 * b) / 4.0;
                quad.push(([u, v], 1.0 / 64.0));
            }
        }
    }
    quad
}

fn plane_y() -> SymmetryPlane {
    SymmetryPlane::new(Edge::UMin, Vector3::zeros(), Vector3::y()).unwrap()
}

fn plane_z() -> SymmetryPlane {
    SymmetryPlane::new(Edge::VMin, Vector3::zeros(), Vector3::z()).unwrap()
}

/// The quarter panel: R = 5, 0–60°, s in [0, 4], planes y = 0 (u = 0) and z = 0 (v = 0),
/// 5 × 5 particles, quadratic basis, support 3 spacings, t = 0.1.
fn quarter() -> (Surface<f64>, ShellModel) {
    let surface = cylinder([0.0, 60.0], [0.0, 4.0]);
    let grid = regular_grid(ParamBox::unit(), 5, 5);
    let disc = Discretisation {
        supports: grid.supports(3.0),
        particle_uv: grid.positions,
        basis: Basis::Quadratic,
        kernel: Default::default(),
        quadrature: quadrature(),
        thickness_rule: thickness_rule(),
        thickness: 0.1,
        symmetry: vec![plane_y(), plane_z()],
    };
    let m = ShellModel::new(&surface, disc, material()).unwrap();
    (surface, m)
}

/// The full panel −60–60°, s in [−4, 4], without planes: 9 × 9 particles (the quarter's
/// particles and their mirrors, at half the parameter spacing and support), and the quarter's
/// quadrature points mirrored into the four quadrants (weights / 4).
fn full() -> (Surface<f64>, ShellModel) {
    let surface = cylinder([-60.0, 60.0], [-4.0, 4.0]);
    let grid = regular_grid(ParamBox::unit(), 9, 9);
    let mut quad = Vec::new();
    for (uv, w) in quadrature() {
        for su in [-1.0, 1.0] {
            for sv in [-1.0, 1.0] {
                quad.push((
                    [0.5 * (1.0 + su * uv[0]), 0.5 * (1.0 + sv * uv[1])],
                    w / 4.0,
                ));
            }
        }
    }
    let disc = Discretisation {
        supports: grid.supports(3.0),
        particle_uv: grid.positions,
        basis: Basis::Quadratic,
        kernel: Default::default(),
        quadrature: quad,
        thickness_rule: thickness_rule(),
        thickness: 0.1,
        symmetry: Vec::new(),
    };
    let m = ShellModel::new(&surface, disc, material()).unwrap();
    (surface, m)
}

fn reflection(n: Vector3<f64>) -> Matrix3<f64> {
    Matrix3::identity() - n * n.transpose() * 2.0
}

/// Full-panel parameter point of quarter point `uv` mirrored by `(su, sv)` = ±1, and the
/// physical map of that mirror.
fn to_full(uv: [f64; 2], su: f64, sv: f64) -> ([f64; 2], Matrix3<f64>) {
    let mut q = Matrix3::identity();
    if su < 0.0 {
        q = reflection(Vector3::y()) * q;
    }
    if sv < 0.0 {
        q = reflection(Vector3::z()) * q;
    }
    ([0.5 * (1.0 + su * uv[0]), 0.5 * (1.0 + sv * uv[1])], q)
}

fn random_state(m: &ShellModel, seed: u64, u: f64, a: f64) -> Vec<f64> {
    let mut rng = XorShift64::new(seed);
    (0..m.n_dofs())
        .map(|j| (2.0 * rng.next_f64() - 1.0) * if j % 5 < 3 { u } else { a })
        .collect()
}

/// Zero the symmetry conditions of the particles on the planes (ū·n_s and the rotations).
fn symmetrise(m: &ShellModel, q: &mut [f64]) {
    for sc in m.symmetry.self_conditions() {
        let b = 5 * sc.particle;
        for n in &sc.normals {
            let un = Vector3::new(q[b], q[b + 1], q[b + 2]);
            let v = un - n * n.dot(&un);
            q[b..b + 3].copy_from_slice(v.as_slice());
        }
        for &r in &sc.rotations {
            q[b + 3 + r] = 0.0;
        }
    }
}

#[test]
fn reflected_rotation_identity_with_rodrigues() {
    // Q R(θ) v = R(det(Q) Q θ) Q v for reflections and products of two, θ up to 2.5 rad
    // (beyond the series switch of rotate_director), each side through Rodrigues' formula.
    let mut rng = XorShift64::new(11);
    let mut rand_vec = |s: f64| {
        Vector3::new(
            rng.uniform(-1.0, 1.0),
            rng.uniform(-1.0, 1.0),
            rng.uniform(-1.0, 1.0),
        ) * s
    };
    let mut worst = 0.0f64;
    for _ in 0..50 {
        let n1 = rand_vec(1.0).normalize();
        let n2 = rand_vec(1.0).normalize();
        let theta = rand_vec(1.4);
        let v = rand_vec(1.0);
        for q in [reflection(n1), reflection(n1) * reflection(n2)] {
            let det = q.determinant();
            // R(θ) v with θ = |θ| θ̂: rotate_director with e1 = θ̂, α = (|θ|, 0).
            let rot = |axis: Vector3<f64>, x: Vector3<f64>| {
                let s = axis.norm();
                let e1 = axis / s;
                let e2 = e1.cross(&Vector3::x()).normalize();
                rotate_director(&x, &e1, &e2, [s, 0.0])
            };
            let lhs = q * rot(theta, v);
            let rhs = rot(q * theta * det, q * v);
            worst = worst.max((lhs - rhs).norm());
            // The image map of the shell DOFs: lamina vectors e ⟂ v map by Q, α by det(Q).
            let d = v.normalize();
            let e1 = (n2 - d * d.dot(&n2)).normalize();
            let e2 = d.cross(&e1);
            let alpha = [theta[0], theta[1]];
            let lhs = q * rotate_director(&d, &e1, &e2, alpha);
            let rhs = rotate_director(&(q * d), &(q * e1), &(q * e2), alpha.map(|a| a * det));
            worst = worst.max((lhs - rhs).norm());
        }
    }
    // Unit-size vectors, a few dozen flops each side: round-off ~1e-15.
    assert!(worst < 1e-13, "largest mismatch {worst:e}");
}

#[test]
fn plane_checks_name_the_edge_and_the_deviation() {
    let cyl = cylinder([0.0, 60.0], [0.0, 4.0]);
    // The edge u = 0 is the generator y = 0: a plane y = 0.5 misses it by 0.5.
    let off = SymmetryPlane::new(Edge::UMin, Vector3::new(0.0, 0.5, 0.0), Vector3::y()).unwrap();
    match off.validate(&cyl) {
        Err(SymmetryError::EdgeOffPlane { edge, distance, .. }) => {
            assert_eq!(edge, Edge::UMin);
            assert!((distance - 0.5).abs() < 1e-12, "distance {distance}");
        }
        other => panic!("expected EdgeOffPlane, got {other:?}"),
    }
    assert!(plane_y().validate(&cyl).is_ok());
    assert!(plane_z().validate(&cyl).is_ok());
    // The hole edge of the hemisphere (latitude 72°) lies in the plane z = R sin 72°, but the
    // normal there has component sin 72° = 0.951 along z: not a symmetry plane.
    let sphere = Surface::SphereZone(
        SphereZone::new(
            Vector3::zeros(),
            10.0,
            [0.0, 72f64.to_radians()],
            [0.0, 90f64.to_radians()],
        )
        .unwrap(),
    );
    let top = SymmetryPlane::new(
        Edge::VMax,
        Vector3::new(0.0, 0.0, 10.0 * 72f64.to_radians().sin()),
        Vector3::z(),
    )
    .unwrap();
    match top.validate(&sphere) {
        Err(SymmetryError::NormalOffPlane {
            edge, deviation, ..
        }) => {
            assert_eq!(edge, Edge::VMax);
            assert!((deviation - 72f64.to_radians().sin()).abs() < 1e-12);
        }
        other => panic!("expected NormalOffPlane, got {other:?}"),
    }
    // A skewed rectangle: the edge u = 0 and the normal lie in the plane x = 0, but the
    // parameter lines crossing it are not normal to the plane.
    let skew = Surface::Rectangle(
        Rectangle::new(
            Vector3::zeros(),
            Vector3::new(1.0, 0.3, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
        )
        .unwrap(),
    );
    let px = SymmetryPlane::new(Edge::UMin, Vector3::zeros(), Vector3::x()).unwrap();
    match px.validate(&skew) {
        Err(SymmetryError::NotMirrorParameterised {
            edge, deviation, ..
        }) => {
            assert_eq!(edge, Edge::UMin);
            let expected = 0.3 / (1.0f64 + 0.09).sqrt();
            assert!((deviation - expected).abs() < 1e-12, "{deviation}");
        }
        other => panic!("expected NotMirrorParameterised, got {other:?}"),
    }
    assert!(matches!(
        SymmetryPlane::new(Edge::VMax, Vector3::zeros(), Vector3::zeros()),
        Err(SymmetryError::InvalidNormal {
            edge: Edge::VMax,
            ..
        })
    ));
    // Through the model: the typed error reaches ShellModel::new, and two planes on one edge
    // are refused.
    let grid = regular_grid(ParamBox::unit(), 5, 5);
    let disc = |planes| Discretisation {
        supports: grid.supports(3.0),
        particle_uv: grid.positions.clone(),
        basis: Basis::Quadratic,
        kernel: Default::default(),
        quadrature: quadrature(),
        thickness_rule: thickness_rule(),
        thickness: 0.1,
        symmetry: planes,
    };
    assert!(matches!(
        ShellModel::new(&cyl, disc(vec![off]), material()),
        Err(ShellError::Symmetry(SymmetryError::EdgeOffPlane { .. }))
    ));
    assert!(matches!(
        ShellModel::new(&cyl, disc(vec![plane_y(), plane_y()]), material()),
        Err(ShellError::Symmetry(SymmetryError::DuplicateEdge {
            edge: Edge::UMin
        }))
    ));
}

#[test]
fn image_layout_of_two_planes_with_a_corner() {
    let (_, m) = quarter();
    // Spacing 1/4, support 3/4: the columns u = 1/4 and 1/2 (distance < 3/4) are mirrored, the
    // column u = 3/4 is not (its support ends on the edge). Per plane 2 × 5 images, plus the
    // 2 × 2 corner images of images.
    let imgs = &m.symmetry.images;
    assert_eq!(imgs.len(), 2 * 5 + 2 * 5 + 4);
    let corner: Vec<_> = imgs.iter().filter(|i| i.planes.len() == 2).collect();
    assert_eq!(corner.len(), 4);
    for im in imgs {
        let src = m.particle_uv[im.source];
        let mirrored_u = im.planes.contains(&0);
        let mirrored_v = im.planes.contains(&1);
        let expect = [
            if mirrored_u { -src[0] } else { src[0] },
            if mirrored_v { -src[1] } else { src[1] },
        ];
        assert!((im.uv[0] - expect[0]).abs() < 1e-15 && (im.uv[1] - expect[1]).abs() < 1e-15);
        assert_eq!(im.det, if im.planes.len() == 2 { 1.0 } else { -1.0 });
    }
    // Particles on the planes: 5 on each edge, the corner on both; e1 = n_s there.
    let on: Vec<_> = m.symmetry.self_conditions();
    assert_eq!(on.len(), 9);
    for sc in &on {
        let e1 = m.particles[sc.particle].e[0];
        assert!((e1 - sc.normals[0]).norm() < 1e-15);
        assert_eq!(sc.rotations.len(), sc.normals.len());
    }
    // Image states follow their sources through Q (after a commit too).
    let mut m = m;
    let mut q = random_state(&m, 2, 1e-2, 0.2);
    symmetrise(&m, &mut q);
    let c = m.contributions(&q, false).unwrap();
    m.commit(&q, c);
    let n = m.n_particles();
    for (k, im) in m.symmetry.images.iter().enumerate() {
        let s = m.particles[im.source];
        let p = m.particle_state(n + k);
        assert!((p.u - im.map * s.u).norm() < 1e-15);
        assert!((p.d - im.map * s.d).norm() < 1e-15);
        assert!((p.e[1] - im.map * s.e[1]).norm() < 1e-15);
    }
}

/// The mirrored full-panel state of the quarter's generalised DOFs `q`.
fn mirrored_state(quarter: &ShellModel, full: &ShellModel, q: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; full.n_dofs()];
    for (pf, uv) in full.particle_uv.iter().enumerate() {
        let ru = [(2.0 * uv[0] - 1.0).abs(), (2.0 * uv[1] - 1.0).abs()];
        let (su, sv) = (
            if 2.0 * uv[0] - 1.0 < -1e-12 {
                -1.0
            } else {
                1.0
            },
            if 2.0 * uv[1] - 1.0 < -1e-12 {
                -1.0
            } else {
                1.0
            },
        );
        let i = quarter
            .particle_uv
            .iter()
            .position(|x| (x[0] - ru[0]).abs() < 1e-12 && (x[1] - ru[1]).abs() < 1e-12)
            .expect("every full particle mirrors a quarter particle");
        let (_, qm) = to_full(ru, su, sv);
        let det = qm.determinant();
        let s = &q[5 * i..5 * i + 5];
        let u = qm * Vector3::new(s[0], s[1], s[2]);
        let e = quarter.particles[i].e;
        let theta = (e[0] * s[3] + e[1] * s[4]) * det;
        let th = qm * theta;
        let ef = full.particles[pf].e;
        // Both lamina pairs span the plane normal to the same (mirrored) director.
        assert!((full.particles[pf].d - qm * quarter.particles[i].d).norm() < 1e-14);
        out[5 * pf..5 * pf + 5].copy_from_slice(&[
            u[0],
            u[1],
            u[2],
            th.dot(&ef[0]),
            th.dot(&ef[1]),
        ]);
    }
    out
}

#[test]
fn quarter_model_with_images_reproduces_the_full_model_exactly() {
    let (sq, mut mq) = quarter();
    let (sf, mut mf) = full();
    assert_eq!(mf.n_particles(), 81);
    // A finite step: translations 1e-2 on a 5-unit shell, rotations up to 0.2 rad, plastic.
    let mut q = random_state(&mq, 7, 1e-2, 0.2);
    symmetrise(&mq, &mut q);
    let qf = mirrored_state(&mq, &mf, &q);
    let cq = mq.contributions(&q, false).unwrap();
    let cf = mf.contributions(&qf, false).unwrap();
    let plastic: usize = cq.iter().map(|c| c.plastic_layers).sum();
    assert!(plastic > 0, "the step should yield somewhere");
    let rq = mq.internal_force(&cq);
    let rf = mf.internal_force(&cf);
    let scale = rf.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    // Internal forces. Off the planes: equal (the full model's other quadrants act on the
    // quarter particle exactly as the quarter's points act on its images). On a plane the
    // particle is its own mirror: the full force is Σ_{Q fixing it} Q f_quarter (translations;
    // the rotation DOFs use different lamina vectors there and are not compared).
    let mut worst = 0.0f64;
    for (pf, uv) in mf.particle_uv.iter().enumerate() {
        if uv[0] < 0.5 - 1e-12 || uv[1] < 0.5 - 1e-12 {
            continue;
        }
        let ru = [2.0 * uv[0] - 1.0, 2.0 * uv[1] - 1.0];
        let i = mq
            .particle_uv
            .iter()
            .position(|x| (x[0] - ru[0]).abs() < 1e-12 && (x[1] - ru[1]).abs() < 1e-12)
            .unwrap();
        let fq = Vector3::new(rq[5 * i], rq[5 * i + 1], rq[5 * i + 2]);
        let ff = Vector3::new(rf[5 * pf], rf[5 * pf + 1], rf[5 * pf + 2]);
        let on = &mq.symmetry.on_planes[i];
        let mut expect = fq;
        let (sy, sz) = (reflection(Vector3::y()), reflection(Vector3::z()));
        if on.contains(&0) {
            expect += sy * fq;
        }
        if on.contains(&1) {
            expect += sz * fq;
        }
        if on.len() == 2 {
            expect += sy * sz * fq;
        }
        worst = worst.max((ff - expect).norm());
        if on.is_empty() {
            for c in 3..5 {
                worst = worst.max((rf[5 * pf + c] - rq[5 * i + c]).abs());
            }
        }
    }
    println!("internal force: largest mismatch {worst:.3e} (scale {scale:.3e})");
    // Both assemble the same point terms; the RK functions differ by round-off only (the full
    // model's parameters are scaled by 1/2), and each entry sums ~100 point contributions of
    // size ≤ scale: 1e-11 relative leaves a factor ~10 over the observed.
    assert!(worst <= 1e-11 * scale, "{worst:e} vs scale {scale:e}");

    // Committed fields at the original and the three mirrored points.
    mq.commit(&q, cq);
    mf.commit(&qf, cf);
    let mut rng = XorShift64::new(5);
    let mut worst_u = 0.0f64;
    let mut worst_d = 0.0f64;
    let mut umax = 0.0f64;
    for _ in 0..20 {
        let uv = [rng.next_f64(), rng.next_f64()];
        let sq_ = mq.sample(&sq, uv).unwrap();
        umax = umax.max(sq_.displacement.norm());
        for su in [-1.0, 1.0] {
            for sv in [-1.0, 1.0] {
                let (x, qm) = to_full(uv, su, sv);
                let sf_ = mf.sample(&sf, x).unwrap();
                assert!((sf_.x0 - qm * sq_.x0).norm() < 1e-13);
                worst_u = worst_u.max((sf_.displacement - qm * sq_.displacement).norm());
                worst_d = worst_d.max((sf_.director - qm * sq_.director).norm());
            }
        }
    }
    println!(
        "fields: displacement mismatch {worst_u:.3e} (max |u| {umax:.3e}), director {worst_d:.3e}"
    );
    // Sums of ~30 products Ψ_J u_J with |Ψ_J| ≤ 1: round-off ~1e-16 of max |u| per term.
    assert!(worst_u <= 1e-13 * umax.max(1e-2), "{worst_u:e}");
    assert!(worst_d <= 1e-13, "{worst_d:e}");
}

struct Residual<'a>(&'a ShellModel);

impl Differentiable for Residual<'_> {
    fn n_inputs(&self) -> usize {
        self.0.n_dofs()
    }
    fn eval<T: Real>(&self, x: &[T]) -> Vec<T> {
        self.0.internal_force_generic(x).unwrap()
    }
}

/// 1e-10 as in tests/shell_model.rs: point tangents equal their dual Jacobians to ~1e-12; the
/// image maps are orthogonal, so they add round-off of the same order.
fn check_tangent(m: &ShellModel, x: &[f64], title: &str) {
    let c = m.contributions(x, true).unwrap();
    let k = m.dense_tangent(&c);
    let dual = dual_jacobian(&Residual(m), x);
    let cmp = compare_matrices(title, &k, &dual, Tolerance::rel(1e-10), &[], &|i, j| {
        (format!("r{i}"), format!("q{j}"))
    });
    println!("{cmp}");
    assert!(cmp.passed(), "{cmp}");
    let f = m.internal_force(&c);
    let g = m.internal_force_generic(x).unwrap();
    let scale = g.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    for (a, b) in f.iter().zip(&g) {
        assert!((a - b).abs() <= 1e-13 * scale);
    }
}

#[test]
fn tangent_with_images_equals_dual_jacobian_across_a_plastic_step() {
    let (_, mut m) = quarter();
    // Any state (the identity holds off the symmetric subspace too).
    let x1 = random_state(&m, 3, 5e-3, 0.2);
    check_tangent(&m, &x1, "tangent with images, step 1");
    let mut xs = x1.clone();
    symmetrise(&m, &mut xs);
    let c = m.contributions(&xs, false).unwrap();
    assert!(c.iter().any(|c| c.plastic_layers > 0));
    m.commit(&xs, c);
    let x2 = random_state(&m, 4, 2e-3, 0.05);
    check_tangent(&m, &x2, "tangent with images, step 2 (after commit)");
    // On-plane particles keep e1 = n_s through the committed finite rotation about it.
    for sc in m.symmetry.self_conditions() {
        assert!((m.particles[sc.particle].e[0] - sc.normals[0]).norm() < 1e-14);
    }
}

/// A cylinder panel (R = 5, 60° wide, length 4, t = 0.05, elastic): symmetry plane on u = 0,
/// clamped on u = 1, a small radial point force at (0, 0.5) (linear range). The panel starts at
/// angle `start`, so the plane's normal is (−sin, cos, 0). Returns the displacement at three
/// points, rotated back by −start about z.
fn rotated_panel(start_deg: f64, treatment: SymmetryTreatment) -> Vec<Vector3<f64>> {
    let surface = cylinder([start_deg, start_deg + 60.0], [0.0, 4.0]);
    let a = start_deg.to_radians();
    let n = Vector3::new(-a.sin(), a.cos(), 0.0);
    let grid = regular_grid(ParamBox::unit(), 7, 7);
    let disc = Discretisation {
        supports: grid.supports(3.0),
        particle_uv: grid.positions,
        basis: Basis::Quadratic,
        kernel: Default::default(),
        quadrature: shelldsa::meshfree::quadrature::CellQuadrature::new(ParamBox::unit(), 6, 6, 2)
            .unwrap()
            .iter()
            .map(|(p, w, _)| (p, w))
            .collect(),
        thickness_rule: thickness_rule(),
        thickness: 0.05,
        symmetry: vec![SymmetryPlane::new(Edge::UMin, Vector3::zeros(), n).unwrap()],
    };
    let mat = MaterialParams::new(7.0e4, 0.3, 1e30, 0.0, 1.0).unwrap();
    let m = ShellModel::new(&surface, disc, mat).unwrap();
    let clamp = edge_constraints(&m, Edge::UMax, &EdgeCondition::Clamped).unwrap();
    let p = 1e-3;
    let radial = Vector3::new(a.cos(), a.sin(), 0.0) * p;
    let mut problem = ShellProblem::with_options(
        m,
        vec![PointForce {
            uv: [0.0, 0.5],
            force: radial.into(),
        }
        .into()],
        clamp,
        ProblemOptions {
            symmetry: treatment,
            ..ProblemOptions::default()
        },
    )
    .unwrap();
    let pattern = problem.pattern().clone();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    let newton = NewtonSolver {
        stepping: LoadStepping {
            initial_step: 1.0,
            ..LoadStepping::default()
        },
        ..NewtonSolver::default()
    };
    let u0 = problem.state().to_vec();
    newton
        .run(&mut problem, &pattern, &mut solver, &u0)
        .expect("linear step");
    let back = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), -a);
    [[0.0, 0.5], [0.0, 1.0], [0.5, 0.25]]
        .iter()
        .map(|&uv| back * problem.model.displacement_at(uv).unwrap() / p)
        .collect()
}

#[test]
fn a_plane_off_the_axes_gives_the_rotated_solution() {
    // start 0°: n_s = y, eliminated; start 30°: n_s = (−1/2, √3/2, 0), a multiplier row.
    let axis = rotated_panel(0.0, SymmetryTreatment::Eliminate);
    let rows = rotated_panel(0.0, SymmetryTreatment::Multipliers);
    let turned = rotated_panel(30.0, SymmetryTreatment::Eliminate);
    let scale = axis.iter().fold(0.0f64, |a, v| a.max(v.norm()));
    println!("|u|/P up to {scale:.4e}");
    for ((a, b), c) in axis.iter().zip(&rows).zip(&turned) {
        println!("eliminated {a:?}\nmultiplier {b:?}\nrotated    {c:?}");
        // The same equations up to the elimination and a rotation of the geometry, so the
        // three agree up to where the driver stops: its energy test |Δuᵀr| ≤ 1e-14 |Δu₀ᵀr₀|
        // bounds the remaining correction by √1e-14 = 1e-7 of the solution in the energy norm
        // (observed: ~1e-12).
        assert!((a - b).norm() <= 1e-7 * scale);
        assert!((a - c).norm() <= 1e-7 * scale);
    }
    // The symmetry condition holds at the plane: no displacement normal to it.
    assert!(axis[0][1].abs() <= 1e-9 * scale && axis[1][1].abs() <= 1e-9 * scale);
}

#[test]
fn problem_tangent_with_images_multipliers_and_follower_load_matches_central_differences() {
    use shelldsa::shell::constraints::LinearConstraint;
    use shelldsa::solver::NonlinearProblem;
    let (_, m) = quarter();
    // Rows: a point displacement near the corner (its neighbours include images), a rotation
    // row and the clamp of the free edge u = 1; the symmetry conditions as multiplier rows;
    // a point force near the plane and a follower pressure on the corner between the planes
    // (its stiffness mapped through the images).
    let mut rows = vec![
        LinearConstraint::displacement(&m, [0.1, 0.05], Vector3::new(1.0, 2.0, 0.5), 1e-3).unwrap(),
        LinearConstraint::rotation(&m, [0.3, 0.6], 0, 0.0).unwrap(),
    ];
    rows.extend(edge_constraints(&m, Edge::UMax, &EdgeCondition::SimplySupported).unwrap());
    let mut problem = ShellProblem::with_options(
        m,
        vec![
            PointForce {
                uv: [0.05, 0.5],
                force: [3.0, -1.0, 2.0],
            }
            .into(),
            Pressure::new(5e2)
                .unwrap()
                .within(ParamBox::new([0.0, 0.4], [0.0, 0.4]))
                .unwrap()
                .into(),
        ],
        rows,
        ProblemOptions {
            symmetry: SymmetryTreatment::Multipliers,
            ..ProblemOptions::default()
        },
    )
    .unwrap();
    let n = problem.n_dofs();
    let nq = problem.n_generalised();
    // 2 point rows, 5 × 3 on the supported edge, symmetry: 8 particles on one plane (ū·n_s,
    // α2) and the corner (two normals, both rotations); the supported edge's row along the
    // normal of the plane it meets, at the particle on that plane, repeats the symmetry row
    // `ū·n_s` there and is merged.
    assert_eq!(n - nq, 2 + 5 * 3 + 8 * 2 + 4 - 1);
    assert_eq!(problem.redundant_constraints().len(), 1);
    // A state: generalised DOFs at a small finite step (elastic-plastic material, stays
    // elastic at this size), multipliers of order 1e-3.
    let mut rng = XorShift64::new(17);
    let u: Vec<f64> = (0..n)
        .map(|j| {
            let s = if j >= nq {
                1e-3
            } else if j % 5 < 3 {
                1e-4
            } else {
                1e-3
            };
            (2.0 * rng.next_f64() - 1.0) * s
        })
        .collect();
    let load = 0.7;
    let pattern = problem.pattern().clone();
    let mut r = vec![0.0; n];
    let mut values = vec![0.0; pattern.nnz()];
    problem
        .residual_and_tangent(&u, load, &mut r, &mut values)
        .unwrap();
    let k = pattern.to_dense(&values);
    // Central differences column by column, steps 1e-6 of each DOF's scale: truncation
    // ~(h/scale)² = 1e-12 and round-off ~ε |r| / (h |∂r/∂q|) ~ ε · 1e6 = 2e-10 of the column,
    // amplified by cancellation in the sums of point forces (observed 2e-8): compare at 1e-6.
    let mut worst = 0.0f64;
    for j in 0..n {
        let h = if j >= nq {
            1e-9
        } else if j % 5 < 3 {
            1e-10
        } else {
            1e-9
        };
        let mut up = u.clone();
        let mut um = u.clone();
        up[j] += h;
        um[j] -= h;
        let (mut rp, mut rm) = (vec![0.0; n], vec![0.0; n]);
        problem.residual(&up, load, &mut rp).unwrap();
        problem.residual(&um, load, &mut rm).unwrap();
        let col = k.column(j);
        let scale = col.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        for i in 0..n {
            let fd = (rp[i] - rm[i]) / (2.0 * h);
            worst = worst.max((fd - col[i]).abs() / scale);
        }
    }
    println!("problem tangent vs central differences: worst relative error {worst:.3e}");
    assert!(worst < 1e-6, "{worst:e}");
    // Structural checks: the constraint block is k C and its transpose.
    let scales = problem.constraint_scales().to_vec();
    for (c, row) in problem.constraints().iter().enumerate() {
        for &(d, a) in &row.terms {
            assert_eq!(k[(nq + c, d)], scales[c] * a);
            assert_eq!(k[(d, nq + c)], scales[c] * a);
        }
    }
}

#[test]
fn particle_cache_gives_bit_identical_cell_contributions_with_images() {
    // The assembly path computes each shape-function particle's state, local DOFs and
    // director terms once (`ShellModel::particle_cache`) instead of once per point: the same
    // arithmetic on the same inputs, so every residual and tangent entry must be equal to the
    // bit, for points with image neighbours (two planes and a corner) and large rotations.
    let (_, m) = quarter();
    let mut q = random_state(&m, 11, 0.05, 0.3);
    symmetrise(&m, &mut q);
    let cache = m.particle_cache(&q, true).unwrap();
    let residual_only = m.particle_cache(&q, false).unwrap();
    let mut with_images = 0;
    for k in 0..m.points.len() {
        let nc = 5 * m.points[k].sources.len();
        if m.points[k].neighbours.len() != m.points[k].sources.len() {
            with_images += 1;
        }
        let (mut r1, mut k1) = (vec![0.0; nc], vec![0.0; nc * nc]);
        let (mut r2, mut k2) = (vec![0.0; nc], vec![0.0; nc * nc]);
        let (h1, p1) = m.add_to_cell(k, &q, &mut r1, Some(&mut k1)).unwrap();
        let (h2, p2) = m
            .add_to_cell_cached(k, &q, Some(&cache), &mut r2, Some(&mut k2))
            .unwrap();
        assert_eq!(r1, r2, "residual of point {k}");
        assert_eq!(k1, k2, "tangent of point {k}");
        assert_eq!((h1, p1), (h2, p2), "histories of point {k}");
        let mut r3 = vec![0.0; nc];
        m.add_to_cell_cached(k, &q, Some(&residual_only), &mut r3, None)
            .unwrap();
        assert_eq!(r1, r3, "residual-only cache, point {k}");
    }
    assert!(
        with_images > 0,
        "the quarter has points with image neighbours"
    );
}
