//! External loads on the shell (`shell::load`): totals against closed-form integrals, the
//! follower pressure under a rigid rotation, the end moment's work in a uniform rotation, and
//! every load stiffness against the dual-number Jacobian of its (generic) force and against
//! central differences, at committed and trial states with finite rotations. The moment's
//! conservativeness is measured by the symmetry of its stiffness (docs/loads.md).

mod common;

use nalgebra::{DMatrix, Rotation3, Vector3};
use shelldsa::geometry::{CylinderSector, Rectangle, SphereZone, Surface};
use shelldsa::meshfree::Edge;
use shelldsa::meshfree::{ParamBox, XorShift64};
use shelldsa::scalar::Real;
use shelldsa::shell::gather::GatherMap;
use shelldsa::shell::load::{Gravity, Load, Moment, PointForce, Pressure};
use shelldsa::shell::model::ShellModel;
use shelldsa::shell::ShellError;
use shelldsa::verification::{check, CheckOptions, Differentiable, StepSize, Tolerance};

fn spec(n_u: usize, n_v: usize) -> common::ModelSpec {
    common::ModelSpec {
        thickness: 0.1,
        young: 1.0e5,
        n_u,
        n_v,
        support: 3.0,
        sub: 1,
        ppc: 4,
    }
}

/// Cylinder sector R = 5, θ ∈ [0, 60°], length 4 along z (outward normal).
fn cylinder() -> Surface<f64> {
    Surface::CylinderSector(
        CylinderSector::new(
            Vector3::zeros(),
            Vector3::z(),
            Vector3::x(),
            5.0,
            [0.0, 60f64.to_radians()],
            [0.0, 4.0],
        )
        .unwrap(),
    )
}

/// Flat strip of length 3 along x, width 1 along y, normal +z.
fn strip() -> Surface<f64> {
    Surface::Rectangle(
        Rectangle::new(
            Vector3::zeros(),
            Vector3::new(3.0, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
        )
        .unwrap(),
    )
}

fn sum_components(model: &ShellModel, f: &[f64]) -> [f64; 5] {
    let mut s = [0.0; 5];
    for i in 0..model.particles.len() {
        for (c, v) in s.iter_mut().enumerate() {
            *v += f[5 * i + c];
        }
    }
    s
}

fn dense(n: usize, trip: &[(usize, usize, f64)]) -> DMatrix<f64> {
    let mut k = DMatrix::zeros(n, n);
    for &(i, j, v) in trip {
        k[(i, j)] += v;
    }
    k
}

/// A random state: commit a random increment (translations up to `du`, rotations up to
/// `rot` rad), so the committed displacements, directors and lamina vectors are all non-trivial.
fn commit_random(model: &mut ShellModel, rng: &mut XorShift64, du: f64, rot: f64) {
    let q = random_increment(model.n_dofs(), rng, du, rot, true);
    let c = model.contributions(&q, false).unwrap();
    model.commit(&q, c);
}

fn random_increment(
    n: usize,
    rng: &mut XorShift64,
    du: f64,
    rot: f64,
    both_rotations: bool,
) -> Vec<f64> {
    (0..n)
        .map(|i| match i % 5 {
            0..=2 => rng.uniform(-du, du),
            3 if !both_rotations => 0.0,
            _ => rng.uniform(-rot, rot),
        })
        .collect()
}

struct LoadForce<'a>(&'a ShellModel, &'a Load);

impl Differentiable for LoadForce<'_> {
    fn n_inputs(&self) -> usize {
        self.0.n_dofs()
    }
    fn eval<T: Real>(&self, x: &[T]) -> Vec<T> {
        let mut f = vec![T::zero(); self.0.n_dofs()];
        self.1.force(self.0, None, x, 1.0, &mut f).unwrap();
        f
    }
}

/// Hand-derived stiffness against dual numbers (round-off: the force is a sum of a few hundred
/// products, so 1e-11 relative with the default floor of 100 ε·max) and central differences
/// (step ε^(1/3) ≈ 6e-6). The difference error is absolute, not relative to each entry:
/// truncation h²|f'''|/6 plus round-off ε|f|/h, measured ≤ 5e-10 of the largest entry here. So
/// entries are compared to 1e-6 relative above 1 % of the largest entry and to 1e-8 of the
/// largest entry below (floor 1e-2): a missing term of any visible size still fails.
fn check_stiffness(title: &str, model: &ShellModel, load: Load, q: &[f64]) -> DMatrix<f64> {
    let mut trip = Vec::new();
    load.add_stiffness(model, q, 1.0, &mut trip).unwrap();
    let k = dense(model.n_dofs(), &trip);
    let rep = check(
        &LoadForce(model, &load),
        title,
        q,
        &k,
        CheckOptions {
            dual: Tolerance::rel(1e-11),
            fd: Tolerance {
                rel: 1e-6,
                floor: 1e-2,
            },
            step: StepSize::default(),
        },
    );
    println!("{rep}");
    assert!(rep.passed(), "{rep}");
    assert!(k.norm() > 0.0, "{title}: empty stiffness");
    k
}

#[test]
fn gravity_total_is_load_times_area_on_a_sphere_zone() {
    // Sphere zone R = 10, latitude 0–72°, longitude 0–90°: area R² Δλ (sin φ1 − sin φ0).
    let (phi1, lam1) = (72f64.to_radians(), 90f64.to_radians());
    let zone = Surface::SphereZone(
        SphereZone::new(Vector3::zeros(), 10.0, [0.0, phi1], [0.0, lam1]).unwrap(),
    );
    let model = common::elastic_model(&zone, &spec(7, 7));
    let area = 100.0 * lam1 * phi1.sin();
    let b = [0.5, -1.0, -90.0];
    let g = Load::from(Gravity::new(b).unwrap());
    let mut f = vec![0.0; model.n_dofs()];
    let q = vec![0.0; model.n_dofs()];
    g.add_force(&model, &q, 2.0, &mut f).unwrap();
    let s = sum_components(&model, &f);
    // Partition of unity: Σ_I f_I = 2 b A. The area element R² cos φ is integrated by 4 Gauss
    // points on cells of 12° in φ: error ~ (0.21)^8/8! ≈ 9e-11 relative.
    for c in 0..3 {
        let exact = 2.0 * b[c] * area;
        assert!(
            (s[c] - exact).abs() <= 1e-9 * exact.abs(),
            "component {c}: {} vs {exact}",
            s[c]
        );
    }
    assert_eq!((s[3], s[4]), (0.0, 0.0), "gravity has no moments");
    // Dead load: no stiffness, and the force does not depend on the increment.
    assert!(!g.is_follower());
    let mut trip = Vec::new();
    g.add_stiffness(&model, &q, 1.0, &mut trip).unwrap();
    assert!(trip.is_empty());
    let mut f2 = vec![0.0; model.n_dofs()];
    let mut rng = XorShift64::new(3);
    let q2 = random_increment(model.n_dofs(), &mut rng, 0.1, 0.1, true);
    g.add_force(&model, &q2, 2.0, &mut f2).unwrap();
    assert_eq!(f, f2);
}

#[test]
fn gravity_in_a_region_integrates_that_region_only() {
    // Cylinder: |x_u × x_v| = R Δθ L is constant, so cell-aligned halves are exact to
    // round-off.
    let model = common::elastic_model(&cylinder(), &spec(5, 5));
    let area = 5.0 * 60f64.to_radians() * 4.0;
    let g = Gravity::new([0.0, 0.0, -1.0])
        .unwrap()
        .within(ParamBox::new([0.0, 1.0], [0.0, 0.5]))
        .unwrap();
    let g = Load::from(g);
    let mut f = vec![0.0; model.n_dofs()];
    g.add_force(&model, &vec![0.0; model.n_dofs()], 1.0, &mut f)
        .unwrap();
    let s = sum_components(&model, &f);
    assert!((s[2] + 0.5 * area).abs() <= 1e-13 * area, "{}", s[2]);
}

#[test]
fn pressure_total_on_a_cylinder_sector_matches_the_closed_form() {
    let model = common::elastic_model(&cylinder(), &spec(5, 5));
    let (r, len, th1) = (5.0, 4.0, 60f64.to_radians());
    let p = 3.0;
    let load = Load::from(Pressure::new(p).unwrap());
    let mut f = vec![0.0; model.n_dofs()];
    load.add_force(&model, &vec![0.0; model.n_dofs()], 1.0, &mut f)
        .unwrap();
    let s = sum_components(&model, &f);
    // ∫ p n dA with the outward normal ρ(θ) = (cos θ, sin θ, 0): p R L (sin θ1, 1 − cos θ1, 0).
    let exact = [
        p * r * len * th1.sin(),
        p * r * len * (1.0 - th1.cos()),
        0.0,
    ];
    // 4 Gauss points per 15° cell integrate cos θ to ~ (0.26)^8/8! ≈ 1e-10 relative.
    for c in 0..3 {
        assert!(
            (s[c] - exact[c]).abs() <= 1e-9 * p * r * len,
            "component {c}: {} vs {}",
            s[c],
            exact[c]
        );
    }
    assert!(load.is_follower());
}

#[test]
fn pressure_follows_a_rigid_rotation_of_a_flat_plate() {
    // Translations (R − I) x⁰_I rotate the plate rigidly: the quadratic RK basis reproduces the
    // linear map x⁰(ξ) exactly, so x̄,α = R x̄⁰,α and the total force is R (p A n⁰) to round-off.
    let surface = strip();
    let model = common::elastic_model(&surface, &spec(7, 4));
    let rot = Rotation3::from_scaled_axis(Vector3::new(0.4, -0.7, 0.9));
    let mut q = vec![0.0; model.n_dofs()];
    for (i, uv) in model.particle_uv.iter().enumerate() {
        let x0 = surface.eval(uv[0], uv[1]).x;
        let u = rot * x0 - x0;
        q[5 * i..5 * i + 3].copy_from_slice(u.as_slice());
    }
    let p = -2.5;
    let mut f = vec![0.0; model.n_dofs()];
    Load::from(Pressure::new(p).unwrap())
        .add_force(&model, &q, 1.0, &mut f)
        .unwrap();
    let s = sum_components(&model, &f);
    let exact = rot * Vector3::new(0.0, 0.0, p * 3.0);
    let got = Vector3::new(s[0], s[1], s[2]);
    println!("rotated total {got:?}, exact {exact:?}");
    assert!((got - exact).norm() <= 1e-12 * exact.norm());
}

#[test]
fn pressure_stiffness_matches_dual_numbers_and_central_differences() {
    let mut model = common::elastic_model(&cylinder(), &spec(5, 4));
    let mut rng = XorShift64::new(0x5EED);
    commit_random(&mut model, &mut rng, 0.05, 0.1);
    let q = random_increment(model.n_dofs(), &mut rng, 0.1, 0.2, true);
    let load = Pressure::new(7.0).unwrap();
    let k = check_stiffness("pressure on a cylinder sector", &model, load.into(), &q);
    // Rotation columns and rows are empty (a mid-surface load).
    for i in 0..model.n_dofs() {
        if i % 5 >= 3 {
            assert!(k.row(i).iter().chain(k.column(i).iter()).all(|&v| v == 0.0));
        }
    }
    // The same in a region, with a load factor.
    let part = Pressure::new(-4.0)
        .unwrap()
        .within(ParamBox::new([0.25, 0.75], [0.0, 0.5]))
        .unwrap();
    check_stiffness("pressure in a region", &model, part.clone().into(), &q);
    let mut t1 = Vec::new();
    let mut t2 = Vec::new();
    part.add_stiffness(&model, &q, 1.0, &mut t1).unwrap();
    part.add_stiffness(&model, &q, 2.5, &mut t2).unwrap();
    let (k1, k2) = (dense(model.n_dofs(), &t1), dense(model.n_dofs(), &t2));
    assert!((&k2 - k1 * 2.5).norm() <= 1e-14 * k2.norm());
}

#[test]
fn moment_does_the_work_of_a_uniform_rotation_on_a_flat_strip() {
    // Flat strip: every particle has e1 = x, e2 = y and d = n⁰ = z, so the interpolated
    // director is Σ Ψ_J d_J and a uniform virtual rotation about a ⟂ d gives δθ = a exactly:
    // the generalised moments summed over the particles equal m·a times the edge length.
    let surface = strip();
    let model = common::elastic_model(&surface, &spec(7, 4));
    let m = [0.3, -2.0, 0.7];
    let load = Moment::on_edge(&model, &surface, Edge::UMax, m, 3, 4).unwrap();
    assert!((load.rule().edge_length() - 1.0).abs() < 1e-15);
    let mut f = vec![0.0; model.n_dofs()];
    load.force(&model, &vec![0.0; model.n_dofs()], 1.5, &mut f)
        .unwrap();
    let s = sum_components(&model, &f);
    assert_eq!((s[0], s[1], s[2]), (0.0, 0.0, 0.0));
    // α1 rotates about e1 = x, α2 about e2 = y; the component along d = z does no work.
    assert!((s[3] - 1.5 * m[0]).abs() <= 1e-14, "{}", s[3]);
    assert!((s[4] - 1.5 * m[1]).abs() <= 1e-14, "{}", s[4]);
    // Only particles whose supports reach the edge u = 1 are loaded.
    for (i, uv) in model.particle_uv.iter().enumerate() {
        if uv[0] < 1.0 - 3.0 / 6.0 - 1e-12 {
            assert!(f[5 * i..5 * i + 5].iter().all(|&v| v == 0.0), "{i}");
        }
    }
}

#[test]
fn moment_stiffness_matches_duals_and_is_symmetric_exactly_for_planar_bending() {
    let surface = strip();
    let mut model = common::elastic_model(&surface, &spec(7, 4));
    // Moment about −y: bending in the x–z plane.
    let load = Moment::on_edge(&model, &surface, Edge::UMax, [0.0, -3.0, 0.0], 3, 4).unwrap();
    let mut rng = XorShift64::new(0xD1CE);

    // Planar state: rotations about e2 = y only, with finite rotations committed first.
    let q = random_increment(model.n_dofs(), &mut rng, 0.0, 0.6, false);
    let c = model.contributions(&q, false).unwrap();
    model.commit(&q, c);
    let q = random_increment(model.n_dofs(), &mut rng, 0.0, 0.4, false);
    let k = check_stiffness("moment, planar state", &model, load.clone().into(), &q);
    let skew = (&k - k.transpose()).norm() / k.norm();
    println!("planar bending: |K − Kᵀ|/|K| = {skew:.2e}");
    // Conservative: the stiffness is the Hessian of −|m| ∫ φ ds, symmetric to round-off.
    assert!(skew < 1e-13, "{skew:e}");

    // Out-of-plane state: rotations about both lamina vectors. Still the exact derivative of
    // the force, but no longer symmetric: the load is not conservative there.
    let mut model3 = common::elastic_model(&surface, &spec(7, 4));
    commit_random(&mut model3, &mut rng, 0.0, 0.3);
    let q3 = random_increment(model3.n_dofs(), &mut rng, 0.0, 0.3, true);
    let k3 = check_stiffness("moment, out-of-plane state", &model3, load.into(), &q3);
    let skew3 = (&k3 - k3.transpose()).norm() / k3.norm();
    println!("out-of-plane director: |K − Kᵀ|/|K| = {skew3:.2e}");
    assert!(skew3 > 1e-3, "{skew3:e}");
}

#[test]
fn moment_on_a_curved_edge_matches_dual_numbers() {
    // The v = 1 edge of the cylinder sector (a circular arc of length R·60°), at a random
    // committed and trial state.
    let surface = cylinder();
    let mut model = common::elastic_model(&surface, &spec(5, 4));
    let load = Moment::on_edge(&model, &surface, Edge::VMax, [1.0, -0.5, 2.0], 4, 3).unwrap();
    let arc = 5.0 * 60f64.to_radians();
    assert!((load.rule().edge_length() - arc).abs() <= 1e-13 * arc);
    let mut rng = XorShift64::new(42);
    commit_random(&mut model, &mut rng, 0.05, 0.2);
    let q = random_increment(model.n_dofs(), &mut rng, 0.05, 0.3, true);
    check_stiffness("moment on a curved edge", &model, load.into(), &q);
}

#[test]
fn gather_map_is_the_identity_for_real_particles() {
    let model = common::elastic_model(&strip(), &spec(4, 3));
    let mut map = GatherMap::new(&model);
    for j in 0..model.particles.len() {
        let rows = map.rows(&model, j).clone();
        for (c, row) in rows.iter().enumerate() {
            assert_eq!(row, &vec![(5 * j + c, 1.0)]);
        }
    }
}

#[test]
fn bad_load_input_is_a_typed_error_naming_the_field() {
    let surface = strip();
    let model = common::elastic_model(&surface, &spec(4, 3));
    let msg = |e: ShellError| e.to_string();
    assert!(msg(Pressure::new(f64::NAN).unwrap_err()).contains("pressure"));
    assert!(msg(Gravity::new([0.0, f64::INFINITY, 0.0]).unwrap_err()).contains("gravity"));
    let e = Pressure::new(1.0)
        .unwrap()
        .within(ParamBox::new([0.6, 0.4], [0.0, 1.0]))
        .unwrap_err();
    assert!(msg(e).contains("lo <= hi"));
    // A region between the quadrature points selects nothing.
    let empty = Pressure::new(1.0)
        .unwrap()
        .within(ParamBox::new([0.5, 0.5], [0.5, 0.5]))
        .unwrap();
    let n = model.n_dofs();
    let e = Load::from(empty)
        .add_force(&model, &vec![0.0; n], 1.0, &mut vec![0.0; n])
        .unwrap_err();
    assert!(msg(e).contains("contains no quadrature point"));
    let e = Load::from(Pressure::new(1.0).unwrap())
        .add_force(&model, &vec![0.0; n - 1], 1.0, &mut vec![0.0; n])
        .unwrap_err();
    assert_eq!(
        e,
        ShellError::Dimension {
            expected: n,
            got: n - 1
        }
    );
    let e = Moment::on_edge(&model, &surface, Edge::UMax, [0.0; 3], 0, 2).unwrap_err();
    assert!(msg(e).contains("intervals = 0"));
    let e = Moment::on_edge(&model, &surface, Edge::UMax, [0.0; 3], 2, 11).unwrap_err();
    assert!(msg(e).contains("moment edge rule"));
    let e = Moment::on_edge(&model, &surface, Edge::UMax, [f64::NAN, 0.0, 0.0], 2, 2).unwrap_err();
    assert!(msg(e).contains("moment per unit length"));
    // A moment built for another model.
    let other = common::elastic_model(&surface, &spec(5, 3));
    let load = Moment::on_edge(&other, &surface, Edge::UMax, [0.0, 1.0, 0.0], 2, 2).unwrap();
    let e = Load::from(load)
        .add_force(&model, &vec![0.0; n], 1.0, &mut vec![0.0; n])
        .unwrap_err();
    assert!(msg(e).contains("built for a model"));
    // The dead point force still works through the same seam.
    let mut f = vec![0.0; n];
    Load::from(PointForce {
        uv: [0.5, 0.5],
        force: [0.0, 0.0, 1.0],
    })
    .add_force(&model, &vec![0.0; n], 1.0, &mut f)
    .unwrap();
    assert!((sum_components(&model, &f)[2] - 1.0).abs() < 1e-14);
}
