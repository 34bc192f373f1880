//! Assembled meshfree shell: the assembled consistent tangent equals the
//! dual-number Jacobian of the assembled internal force, before and after a committed plastic
//! step with finite rotations (which moves particles, rotates directors and lamina frames, and
//! leaves plastic history); and parallel assembly is bit-identical to serial.

use nalgebra::Vector3;
use shelldsa::geometry::{CylinderSector, Surface};
use shelldsa::material::MaterialParams;
use shelldsa::meshfree::{regular_grid, Basis, ParamBox, XorShift64};
use shelldsa::scalar::Real;
use shelldsa::shell::model::{Discretisation, ShellModel};
use shelldsa::verification::{compare_matrices, dual_jacobian, Differentiable, Tolerance};

/// A cylinder sector (R = 5, 60°, length 4, t = 0.1) with 5×5 particles, quadratic basis,
/// support 3 spacings, 4×4 cells of 2×2 Gauss points, 3 Gauss points through the thickness.
fn model() -> ShellModel {
    let cyl = CylinderSector::new(
        Vector3::zeros(),
        Vector3::z(),
        Vector3::x(),
        5.0,
        [0.0, 60f64.to_radians()],
        [0.0, 4.0],
    )
    .unwrap();
    let surface = Surface::CylinderSector(cyl);
    let grid = regular_grid(ParamBox::unit(), 5, 5);
    let supports = grid.supports(3.0);
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
    let s3 = (0.6f64).sqrt();
    let thick = vec![(-s3, 5.0 / 9.0), (0.0, 8.0 / 9.0), (s3, 5.0 / 9.0)];
    let material = MaterialParams::new(7.0e4, 0.34, 184.3, 70.0, 0.5).unwrap();
    let disc = Discretisation {
        particle_uv: grid.positions,
        supports,
        basis: Basis::Quadratic,
        kernel: Default::default(),
        quadrature: quad,
        thickness_rule: thick,
        thickness: 0.1,
        symmetry: Vec::new(),
    };
    ShellModel::new(&surface, disc, material).unwrap()
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

fn increment(m: &ShellModel, seed: u64, u: f64, a: f64) -> Vec<f64> {
    let mut rng = XorShift64::new(seed);
    (0..m.n_dofs())
        .map(|j| (2.0 * rng.next_f64() - 1.0) * if j % 5 < 3 { u } else { a })
        .collect()
}

/// 1e-10: the assembled tangent is a sum of point tangents, each equal to its dual Jacobian to
/// ~1e-12 (tests/shell_point.rs); assembly adds round-off of the same order.
fn check_tangent(m: &ShellModel, x: &[f64], title: &str) -> usize {
    let c = m.contributions(x, true).unwrap();
    let k = m.dense_tangent(&c);
    let dual = dual_jacobian(&Residual(m), x);
    let cmp = compare_matrices(title, &k, &dual, Tolerance::rel(1e-10), &[], &|i, j| {
        (format!("r{i}"), format!("q{j}"))
    });
    println!("{cmp}");
    assert!(cmp.passed(), "{cmp}");
    // The f64 assembly and the generic assembly agree on the residual itself.
    let f = m.internal_force(&c);
    let g = m.internal_force_generic(x).unwrap();
    let scale = g.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    for (a, b) in f.iter().zip(&g) {
        assert!((a - b).abs() <= 1e-13 * scale);
    }
    c.iter().map(|c| c.plastic_layers).sum()
}

#[test]
fn assembled_tangent_equals_dual_jacobian_across_a_committed_plastic_step() {
    let mut m = model();
    // Step 1: a finite step (rotations up to 0.2 rad, translations 5e-3 on a 5-unit shell).
    let x1 = increment(&m, 3, 5e-3, 0.2);
    let plastic1 = check_tangent(&m, &x1, "assembled tangent, step 1");
    assert!(plastic1 > 0, "step 1 must yield somewhere");
    let c = m.contributions(&x1, false).unwrap();
    m.commit(&x1, c);
    assert!(m.history.iter().any(|h| h.material.eps_p > 0.0));
    // Step 2 from the moved, rotated, plastically deformed state.
    let x2 = increment(&m, 4, 2e-3, 0.05);
    check_tangent(&m, &x2, "assembled tangent, step 2 (after commit)");
    // Directors stay unit and the lamina vectors orthonormal to them after the commit.
    for p in &m.particles {
        assert!((p.d.norm() - 1.0).abs() < 1e-14);
        assert!(p.e[0].dot(&p.d).abs() < 1e-14 && p.e[1].dot(&p.d).abs() < 1e-14);
    }
}

#[test]
fn parallel_assembly_is_bit_identical_to_serial() {
    let m = model();
    let x = increment(&m, 5, 5e-3, 0.1);
    let par = m.contributions(&x, true).unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let ser = pool.install(|| m.contributions(&x, true).unwrap());
    assert_eq!(m.internal_force(&par), m.internal_force(&ser));
    assert_eq!(m.dense_tangent(&par), m.dense_tangent(&ser));
}

#[test]
fn rigid_translation_gives_zero_internal_force() {
    let m = model();
    let mut x = vec![0.0; m.n_dofs()];
    for i in 0..m.particles.len() {
        x[5 * i] = 0.3;
        x[5 * i + 1] = -0.2;
        x[5 * i + 2] = 0.1;
    }
    let f = m.internal_force(&m.contributions(&x, false).unwrap());
    // RK shape functions reproduce constants, so a uniform coefficient shift is a rigid
    // translation: zero strain and zero force, to round-off of Σ Ψ_I,α (~1e-15).
    assert!(
        f.iter().all(|v| v.abs() < 1e-9),
        "max |f| = {}",
        f.iter().fold(0.0f64, |a, v| a.max(v.abs()))
    );
}
