//! The fast consistent tangent (`shell::tangent`: per-layer 9×9 maps `Ġ ↦ Ṗ`, thickness moments,
//! contraction with the neighbours' dyads) equals the reference directional sweep
//! `shell::point::point_tangent` summed over the layers, to round-off, and the dual-number
//! Jacobian of the layer-summed `point_residual`; at elastic, plastic and mixed through-thickness
//! states, with finite director rotations in the step and test gradients distinct from the trial
//! ones (Petrov–Galerkin rows).

use nalgebra::{DMatrix, Vector3};
use shelldsa::geometry::{SphereZone, Surface};
use shelldsa::material::{return_map, MaterialParams, MaterialState, Vec5};
use shelldsa::meshfree::quadrature::{gauss_lobatto, CellQuadrature};
use shelldsa::meshfree::XorShift64;
use shelldsa::meshfree::{regular_grid, Basis, ParamBox};
use shelldsa::scalar::Real;
use shelldsa::shell::model::{Discretisation, ShellModel};
use shelldsa::shell::point::{
    point_residual, point_residual_with, point_tangent, DirectorField, ParticleState, PointHistory,
    PointIncrement, PointInput, ShapeData, SurfacePoint,
};
use shelldsa::shell::tangent::{point_tangent_fast, ThicknessTangent};
use shelldsa::shell::ShellError;
use shelldsa::verification::{compare_matrices, dual_jacobian, Differentiable, Tolerance};

/// Five Gauss–Lobatto points through the thickness (nodes 0, ±√(3/7), ±1; weights 32/45,
/// 49/90, 1/10): the plastic rule of docs/shell-formulation.md §2, with surface layers.
fn lobatto5() -> Vec<(f64, f64)> {
    let a = (3.0f64 / 7.0).sqrt();
    vec![
        (-1.0, 0.1),
        (-a, 49.0 / 90.0),
        (0.0, 32.0 / 45.0),
        (a, 49.0 / 90.0),
        (1.0, 0.1),
    ]
}

/// A point on the pinched hemisphere (R = 10, thickness raised from 0.04 to 0.2 so that the
/// thickness terms are not negligible) with 9 neighbours with random shape data, distinct test
/// gradients, committed rotated directors, and a committed history per layer.
struct Fixture {
    surface: SurfacePoint<f64>,
    shape: Vec<ShapeData>,
    particles: Vec<ParticleState<f64>>,
    material: MaterialParams<f64>,
    layers: Vec<(f64, f64)>,
    history: Vec<PointHistory<f64>>,
    thickness: f64,
    weight: f64,
    director: DirectorField,
}

fn unit_perp(d: &Vector3<f64>) -> [Vector3<f64>; 2] {
    let a = if d.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = a.cross(d).normalize();
    [e1, d.cross(&e1)]
}

const N: usize = 9;
const ND: usize = 5 * N;

impl Fixture {
    /// `preload`: committed strain history of size `preload · ζ` per layer (a bending
    /// preload: plastic at the surfaces first when large enough).
    fn new(seed: u64, preload: f64, sigma0: f64, layers: Vec<(f64, f64)>) -> Self {
        let mut rng = XorShift64::new(seed);
        let mut r = |s: f64| s * (2.0 * rng.next_f64() - 1.0);
        let sphere = SphereZone::new(
            Vector3::zeros(),
            10.0,
            [0.0, 72f64.to_radians()],
            [0.0, 90f64.to_radians()],
        )
        .unwrap();
        let sd = Surface::SphereZone(sphere).eval(0.4, 0.3);
        let surface = SurfacePoint::from_derivs(&sd);
        let shape: Vec<ShapeData> = (0..N)
            .map(|_| {
                let dpsi = [r(0.8), r(0.8)];
                ShapeData {
                    psi: 0.11 + r(0.05),
                    dpsi,
                    dpsi_test: [dpsi[0] + r(0.05), dpsi[1] + r(0.05)],
                }
            })
            .collect();
        let particles = (0..N)
            .map(|_| {
                let d0 = (surface.n + Vector3::new(r(0.02), r(0.02), r(0.02))).normalize();
                let d = (d0 + Vector3::new(r(0.1), r(0.1), r(0.1))).normalize();
                ParticleState {
                    u: Vector3::new(r(0.05), r(0.05), r(0.05)),
                    d,
                    d0,
                    e: unit_perp(&d),
                }
            })
            .collect();
        let material = MaterialParams::new(6.825e7, 0.3, sigma0, 3.0e5, 0.5).unwrap();
        let frame = surface.initial_frame();
        let history = layers
            .iter()
            .map(|&(zeta, _)| {
                let e = preload * zeta;
                let mut m = MaterialState::virgin();
                for _ in 0..3 {
                    m = return_map(
                        &material,
                        &m,
                        &Vec5::new(e, -0.3 * e, 0.5 * e, 0.1 * e, 0.0),
                    )
                    .unwrap()
                    .state;
                }
                PointHistory { frame, material: m }
            })
            .collect();
        Fixture {
            surface,
            shape,
            particles,
            material,
            layers,
            history,
            thickness: 0.2,
            weight: 0.37,
            director: DirectorField::Interpolated,
        }
    }

    fn input(&self, l: usize) -> PointInput<'_, f64> {
        let (zeta, wz) = self.layers[l];
        PointInput {
            surface: &self.surface,
            zeta,
            thickness: self.thickness,
            weight: self.weight * wz,
            shape: &self.shape,
            particles: &self.particles,
            material: &self.material,
            history: &self.history[l],
            director: self.director,
        }
    }

    /// Σ over layers of the reference sweep, the fast layer sum, and the plastic flags.
    fn tangents(&self, x: &[f64]) -> (DMatrix<f64>, DMatrix<f64>, Vec<bool>) {
        let mut reference = DMatrix::zeros(ND, ND);
        let mut sum = ThicknessTangent::new(&self.shape, &self.particles, x).unwrap();
        let mut plastic = Vec::new();
        for l in 0..self.layers.len() {
            let inp = self.input(l);
            let res = point_residual(&inp, x).unwrap();
            reference += point_tangent(&inp, x, &res).unwrap();
            sum.add_layer(&inp, &res).unwrap();
            plastic.push(res.return_map.plastic);
        }
        assert_eq!(sum.layers(), self.layers.len());
        let mut fast = DMatrix::zeros(ND, ND);
        sum.add_to(&mut fast).unwrap();
        (reference, fast, plastic)
    }
}

/// The layer-summed residual as a function of the 45 DOF increments (dual reference).
impl Differentiable for Fixture {
    fn n_inputs(&self) -> usize {
        ND
    }
    fn eval<T: Real>(&self, x: &[T]) -> Vec<T> {
        let s = self.surface.lift::<T>();
        let ps: Vec<ParticleState<T>> = self.particles.iter().map(|p| p.lift()).collect();
        let m = self.material.lift();
        let mut out = vec![T::zero(); ND];
        for (l, &(zeta, wz)) in self.layers.iter().enumerate() {
            let h = self.history[l].lift::<T>();
            let inp = PointInput {
                surface: &s,
                zeta,
                thickness: T::cst(self.thickness),
                weight: self.weight * wz,
                shape: &self.shape,
                particles: &ps,
                material: &m,
                history: &h,
                director: self.director,
            };
            for (o, r) in out
                .iter_mut()
                .zip(point_residual(&inp, x).unwrap().residual)
            {
                *o += r;
            }
        }
        out
    }
}

/// DOF increments: translations of size `u`, rotations of size `a` (radians).
fn dofs(seed: u64, u: f64, a: f64) -> Vec<f64> {
    let mut rng = XorShift64::new(seed);
    (0..ND)
        .map(|j| (2.0 * rng.next_f64() - 1.0) * if j % 5 < 3 { u } else { a })
        .collect()
}

/// Largest block-scaled difference: each entry's difference divided by the largest reference
/// entry of its block (translation or rotation rows × translation or rotation columns). The
/// blocks have their own scales (the rotation fields carry a factor t/2 and ∂d/∂α), and every
/// entry of a block is a sum of terms of up to that block's scale, so its round-off is a few ε
/// times the block's largest entry however much the terms cancel.
fn block_scaled_difference(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    let rot = |i: usize| usize::from(i % 5 >= 3);
    let mut scale = [[0.0f64; 2]; 2];
    for j in 0..b.ncols() {
        for i in 0..b.nrows() {
            let s = &mut scale[rot(i)][rot(j)];
            *s = s.max(b[(i, j)].abs());
        }
    }
    let mut worst = 0.0f64;
    for j in 0..b.ncols() {
        for i in 0..b.nrows() {
            let e = (a[(i, j)] - b[(i, j)]).abs() / scale[rot(i)][rot(j)];
            assert!(
                e.is_finite(),
                "entry ({i}, {j}): {} vs {}",
                a[(i, j)],
                b[(i, j)]
            );
            worst = worst.max(e);
        }
    }
    worst
}

/// Fast against reference: both evaluate the same linear chain at the same converged state,
/// in a different order (per unit direction then contracted, per DOF direction in the
/// reference; thickness moments instead of a layer sum). Each of the ~10 stages rounds to
/// ε ≈ 1.1e-16 relative to its largest term, and sums run over ≤ 45 columns and 5 layers, so
/// the differences should be ~1e-15 of the block scale; measured ≤ 1e-15 (printed by the
/// tests). 1e-13 leaves a margin of ~100, while a wrong or missing term shows at 1e-4 or more
/// (measured by breaking the fast tangent on purpose: without the ∂²d/∂α² term the smallest
/// difference over these cases is 2.2e-4, with trial instead of test gradients in the rows 5e-2).
const ROUND_OFF: f64 = 1e-13;

/// Dual reference: as tests/shell_point.rs, the tangent chains ~10 hand-derived stages, each exact
/// to round-off, so 1e-10 relative with the default floor.
fn dual_tol() -> Tolerance {
    Tolerance::rel(1e-10)
}

fn check_case(f: &Fixture, x: &[f64], title: &str, expect: &dyn Fn(&[bool]) -> bool) {
    let (reference, fast, plastic) = f.tangents(x);
    assert!(
        expect(&plastic),
        "{title}: unexpected layer branches {plastic:?}"
    );
    let e = block_scaled_difference(&fast, &reference);
    println!("{title}: fast vs reference sweep, block-scaled max difference {e:.3e}; plastic layers {plastic:?}");
    assert!(
        e <= ROUND_OFF,
        "{title}: fast differs from the sweep by {e:e}"
    );
    let dual = dual_jacobian(f, x);
    let c = compare_matrices(title, &fast, &dual, dual_tol(), &[], &|i, j| {
        (format!("r{i}"), format!("q{j}"))
    });
    println!("{c}");
    assert!(c.passed(), "{c}");
}

#[test]
fn single_layer_drop_in_equals_point_tangent() {
    // One layer at ζ = 0.7 (the fixture of tests/shell_point.rs), elastic and plastic, small and
    // finite rotations.
    for (seed, preload, sigma0, u, a) in [
        (7, 0.0, 2.43e5, 1e-4, 1e-3),
        (8, 0.0, 1e9, 2e-4, 0.3),
        (14, 3e-3 / 0.7, 2.43e5, 1e-3, 0.3),
        (9, 3e-3 / 0.7, 2.43e5, 3e-3, 0.05),
    ] {
        let f = Fixture::new(seed, preload, sigma0, vec![(0.7, 1.0)]);
        let x = dofs(seed + 4, u, a);
        let inp = f.input(0);
        let res = point_residual(&inp, &x).unwrap();
        let reference = point_tangent(&inp, &x, &res).unwrap();
        let fast = point_tangent_fast(&inp, &x, &res).unwrap();
        let e = block_scaled_difference(&fast, &reference);
        println!(
            "seed {seed}: plastic {}, block-scaled max difference {e:.3e}",
            res.return_map.plastic
        );
        assert_eq!(res.return_map.plastic, preload > 0.0, "seed {seed}: branch");
        assert!(e <= ROUND_OFF, "seed {seed}: {e:e}");
    }
}

#[test]
fn elastic_layers_small_step() {
    let f = Fixture::new(21, 0.0, 2.43e5, lobatto5());
    check_case(
        &f,
        &dofs(22, 1e-4, 1e-3),
        "5 layers, elastic, small step",
        &|p| p.iter().all(|&b| !b),
    );
}

#[test]
fn elastic_layers_finite_rotations() {
    // Rotations up to 0.3 rad: a yield stress far above the paper's keeps every layer elastic.
    let f = Fixture::new(23, 0.0, 1e9, lobatto5());
    check_case(
        &f,
        &dofs(24, 2e-4, 0.3),
        "5 layers, elastic, finite rotations",
        &|p| p.iter().all(|&b| !b),
    );
}

#[test]
fn mixed_plastic_and_elastic_layers() {
    // A bending preload: the surface layers are plastic, the mid-surface layer elastic (rotation
    // increments of 0.01 rad: larger ones shear the mid-surface layer into yield too).
    let f = Fixture::new(25, 3e-3, 2.43e5, lobatto5());
    check_case(&f, &dofs(26, 1e-4, 0.01), "5 layers, mixed plastic", &|p| {
        p.iter().any(|&b| b) && p.iter().any(|&b| !b)
    });
}

#[test]
fn plastic_layers_finite_rotations() {
    let f = Fixture::new(33, 3e-3, 2.43e5, lobatto5());
    check_case(
        &f,
        &dofs(34, 1e-3, 0.3),
        "5 layers, plastic, finite rotations",
        &|p| p.iter().all(|&b| b),
    );
}

#[test]
fn plastic_layers_gauss_rule() {
    // Three Gauss points (no surface layer): ζ = ±√(3/5), 0, weights 5/9, 8/9, 5/9.
    let s = 0.6f64.sqrt();
    let f = Fixture::new(
        27,
        3e-3 / s,
        2.43e5,
        vec![(-s, 5.0 / 9.0), (0.0, 8.0 / 9.0), (s, 5.0 / 9.0)],
    );
    check_case(&f, &dofs(28, 3e-3, 0.05), "3 Gauss layers, plastic", &|p| {
        p.iter().any(|&b| b)
    });
}

/// The normalised director field (no reference sweep): the fast tangent against the dual
/// Jacobian, with the same tolerance as the interpolated field's (the added maps `N′`, `N″`,
/// `N‴` are closed forms evaluated once per point: a few more rounded stages).
fn check_normalised(f: &mut Fixture, x: &[f64], title: &str) {
    f.director = DirectorField::Normalised;
    let mut sum = ThicknessTangent::new(&f.shape, &f.particles, x).unwrap();
    let cached = PointIncrement::new(&f.particles, x)
        .unwrap()
        .with_unit_director(&f.input(0));
    assert!(cached.unit.is_some());
    for l in 0..f.layers.len() {
        let inp = f.input(l);
        let res = point_residual(&inp, x).unwrap();
        assert!(res.kinematics.unit_director.is_some());
        // The unit director's step formed once for the point: the same layer, bit for bit.
        let again = point_residual_with(&inp, &cached).unwrap();
        assert_eq!(res.residual, again.residual);
        sum.add_layer(&inp, &res).unwrap();
    }
    let mut fast = DMatrix::zeros(ND, ND);
    sum.add_to(&mut fast).unwrap();
    let dual = dual_jacobian(&*f, x);
    let c = compare_matrices(title, &fast, &dual, dual_tol(), &[], &|i, j| {
        (format!("r{i}"), format!("q{j}"))
    });
    println!("{c}");
    assert!(c.passed(), "{c}");
    // The field differs from the interpolated one here (rotated, unequal directors): the
    // comparison is not vacuous.
    f.director = DirectorField::Interpolated;
    let (_, interpolated, _) = f.tangents(x);
    let e = block_scaled_difference(&interpolated, &fast);
    println!("{title}: normalised vs interpolated tangent, block-scaled difference {e:.3e}");
    assert!(e > 1e-6, "{title}: {e:e}");
}

#[test]
fn normalised_director_field_tangents_equal_the_dual_jacobian() {
    let s = 0.6f64.sqrt();
    for (seed, preload, sigma0, layers, u, a) in [
        (21, 0.0, 2.43e5, lobatto5(), 1e-4, 1e-3),
        (23, 0.0, 1e9, lobatto5(), 2e-4, 0.3),
        (25, 3e-3, 2.43e5, lobatto5(), 1e-4, 0.01),
        (33, 3e-3, 2.43e5, lobatto5(), 1e-3, 0.3),
        (
            27,
            3e-3 / s,
            2.43e5,
            vec![(-s, 5.0 / 9.0), (0.0, 8.0 / 9.0), (s, 5.0 / 9.0)],
            3e-3,
            0.05,
        ),
    ] {
        let mut f = Fixture::new(seed, preload, sigma0, layers);
        let x = dofs(seed + 1, u, a);
        check_normalised(&mut f, &x, &format!("normalised, seed {seed}"));
    }
}

#[test]
fn no_layer_adds_nothing() {
    let f = Fixture::new(29, 0.0, 2.43e5, lobatto5());
    let x = dofs(30, 1e-4, 1e-3);
    let sum = ThicknessTangent::new(&f.shape, &f.particles, &x).unwrap();
    let mut k = DMatrix::from_element(ND, ND, 1.5);
    sum.add_to(&mut k).unwrap();
    assert!(k.iter().all(|&v| v == 1.5));
}

#[test]
fn bad_input_is_a_typed_error() {
    let f = Fixture::new(31, 0.0, 2.43e5, lobatto5());
    let x = dofs(32, 1e-4, 1e-3);
    // DOF vector of the wrong length.
    assert_eq!(
        ThicknessTangent::new(&f.shape, &f.particles, &x[..ND - 1]).unwrap_err(),
        ShellError::Dimension {
            expected: ND,
            got: ND - 1
        }
    );
    // Fewer particle states than shape functions.
    assert_eq!(
        ThicknessTangent::new(&f.shape, &f.particles[..N - 1], &x).unwrap_err(),
        ShellError::Dimension {
            expected: N,
            got: N - 1
        }
    );
    let mut sum = ThicknessTangent::new(&f.shape, &f.particles, &x).unwrap();
    let inp = f.input(0);
    let res = point_residual(&inp, &x).unwrap();
    sum.add_layer(&inp, &res).unwrap();
    // A layer of another thickness.
    let mut other = f.input(1);
    other.thickness = 0.3;
    let res1 = point_residual(&other, &x).unwrap();
    let e = sum.add_layer(&other, &res1).unwrap_err();
    assert!(
        matches!(&e, ShellError::InvalidInput(s) if s.contains("thickness = 0.3") && s.contains("expected 0.2")),
        "{e}"
    );
    // A layer of another in-plane point (different shape functions).
    let mut shape2 = f.shape.clone();
    shape2[3].dpsi_test[1] += 0.01;
    let mut other = f.input(1);
    other.shape = &shape2;
    let res2 = point_residual(&other, &x).unwrap();
    let e = sum.add_layer(&other, &res2).unwrap_err();
    assert!(
        matches!(&e, ShellError::InvalidInput(s) if s.contains("shape functions")),
        "{e}"
    );
    assert_eq!(sum.layers(), 1, "failed layers are not added");
    // A local matrix of the wrong size.
    let mut k = DMatrix::zeros(ND, ND - 5);
    assert_eq!(
        sum.add_to(&mut k).unwrap_err(),
        ShellError::Dimension {
            expected: ND,
            got: ND - 5
        }
    );
}

#[test]
fn shared_increment_gives_the_same_residual_bitwise() {
    let f = Fixture::new(35, 3e-3, 2.43e5, lobatto5());
    let x = dofs(36, 1e-3, 0.3);
    let inc = PointIncrement::new(&f.particles, &x).unwrap();
    for l in 0..f.layers.len() {
        let inp = f.input(l);
        let a = point_residual(&inp, &x).unwrap();
        let b = point_residual_with(&inp, &inc).unwrap();
        assert_eq!(a.residual, b.residual, "layer {l}");
        assert_eq!(a.history, b.history, "layer {l}");
    }
    assert_eq!(
        PointIncrement::new(&f.particles, &x[..ND - 2]).unwrap_err(),
        ShellError::Dimension {
            expected: ND,
            got: ND - 2
        }
    );
    let short = PointIncrement::new(&f.particles[..N - 1], &x[..ND - 5]).unwrap();
    assert_eq!(
        point_residual_with(&f.input(0), &short).unwrap_err(),
        ShellError::Dimension {
            expected: N,
            got: N - 1
        }
    );
}

/// The model's local tangents (the fast path, `ShellModel::local`) against the reference sweep
/// summed over the layers of every in-plane point, on a coarse pinched-hemisphere patch (7 × 7
/// particles, quadratic basis, 4 × 4 cells of 2 × 2 Gauss points, 5 Lobatto layers, the paper's
/// thickness 0.04 and material) at an increment that yields part of the layers (185 of 720).
#[test]
fn model_local_tangents_equal_the_reference_sweep() {
    let sphere = SphereZone::new(
        Vector3::zeros(),
        10.0,
        [0.0, 72f64.to_radians()],
        [0.0, 90f64.to_radians()],
    )
    .unwrap();
    let grid = regular_grid(ParamBox::unit(), 7, 7);
    let cq = CellQuadrature::for_particle_grid(&grid, 1, 2).unwrap();
    let lob = gauss_lobatto(5).unwrap();
    let disc = Discretisation {
        particle_uv: grid.positions.clone(),
        supports: grid.supports(3.0),
        basis: Basis::Quadratic,
        kernel: Default::default(),
        quadrature: cq.iter().map(|(p, w, _)| (p, w)).collect(),
        thickness_rule: lob
            .nodes
            .iter()
            .copied()
            .zip(lob.weights.iter().copied())
            .collect(),
        thickness: 0.04,
        symmetry: Vec::new(),
    };
    let material = MaterialParams::new(6.825e7, 0.3, 2.43e5, 3.0e5, 1.0).unwrap();
    let mut m = ShellModel::new(&Surface::SphereZone(sphere), disc, material).unwrap();
    // The reference sweep (`point_tangent`) is written for the interpolated field; the
    // normalised field's fast tangent is checked against dual numbers below.
    m.director = DirectorField::Interpolated;
    let mut rng = XorShift64::new(37);
    let x: Vec<f64> = (0..m.n_dofs())
        .map(|j| (2.0 * rng.next_f64() - 1.0) * if j % 5 < 3 { 3e-4 } else { 0.01 })
        .collect();
    let c = m.contributions(&x, true).unwrap();
    let plastic: usize = c.iter().map(|c| c.plastic_layers).sum();
    let layers = c.len() * m.thickness_rule.len();
    assert!(
        plastic > 0 && plastic < layers,
        "the increment should yield some layers, not all: {plastic} of {layers}"
    );
    let nl = m.thickness_rule.len();
    let mut worst = 0.0f64;
    for (k, ck) in c.iter().enumerate() {
        let p = &m.points[k];
        let (parts, xl) = m.gather_local(k, &x);
        let nd = xl.len();
        let mut reference = DMatrix::zeros(nd, nd);
        for (l, &(zeta, wz)) in m.thickness_rule.iter().enumerate() {
            let inp = PointInput {
                surface: &p.surface,
                zeta,
                thickness: m.thickness,
                weight: p.weight * wz,
                shape: &p.shape,
                particles: &parts,
                material: &m.material,
                history: &m.history[k * nl + l],
                director: m.director,
            };
            let res = point_residual(&inp, &xl).unwrap();
            reference += point_tangent(&inp, &xl, &res).unwrap();
        }
        worst = worst.max(block_scaled_difference(
            ck.tangent.as_ref().unwrap(),
            &reference,
        ));
    }
    println!(
        "model: {} points, {plastic} plastic layers, worst block-scaled difference {worst:.3e}",
        c.len()
    );
    assert!(worst <= ROUND_OFF, "{worst:e}");
}
