//! Continuum DSA point and model kernels (path 2): the hand-derived directional
//! derivative of the point residual and trial history (`point_residual_dot`) equals the
//! dual-number derivative of the generic kernel (`point_residual` in `Dual64`, round-off) and
//! central differences (truncation), per seed group (surface, thickness, each material
//! parameter, particles, history, DOFs) and all together, at a plastic and an elastic step from
//! a plastic history. The DOF seed reproduces `point_tangent`; `commit_particle_dot` equals the
//! dual derivative of `commit_particle`; the model-level `internal_force_dots` (several seed sets
//! at once, image particles of two symmetry planes) equals `internal_force_with` in `Dual64`.

use nalgebra::{DMatrix, Matrix3, Rotation3, Vector3};
use num_dual::Dual64;
use shelldsa::geometry::{SphereZone, Surface};
use shelldsa::io::shell_build::{build, problem_model};
use shelldsa::io::shell_case::parse_shell_case;
use shelldsa::material::{return_map, MaterialParams, MaterialState, Vec5, N_PARAMS, PARAM_NAMES};
use shelldsa::meshfree::XorShift64;
use shelldsa::scalar::Real;
use shelldsa::shell::model::commit_particle;
use shelldsa::shell::model::ShellModel;
use shelldsa::shell::point::{
    point_residual, point_residual_with, point_tangent, DirectorField, ParticleState, PointHistory,
    PointIncrement, PointInput, ShapeData, SurfacePoint,
};
use shelldsa::shell::point_sensitivity::{
    commit_particle_dot, point_residual_dot, ModelSeeds, PointIncrementDot, PointSeeds,
};
use shelldsa::shell::ShellError;
use shelldsa::verification::{
    central_jacobian, compare_matrices, dual_jacobian, Differentiable, StepSize, Tolerance,
};

type V3 = Vector3<f64>;
type M3 = Matrix3<f64>;

struct Rng(XorShift64);

impl Rng {
    fn new(seed: u64) -> Self {
        Rng(XorShift64::new(seed))
    }
    /// Uniform in `[−s, s]`.
    fn r(&mut self, s: f64) -> f64 {
        s * (2.0 * self.0.next_f64() - 1.0)
    }
    fn v(&mut self, s: f64) -> V3 {
        V3::new(self.r(s), self.r(s), self.r(s))
    }
    /// `W Q` with `W` skew of size `s`: a frame rate tangent to the rotations.
    fn frame_rate(&mut self, q: &M3, s: f64) -> M3 {
        self.v(s).cross_matrix() * q
    }
}

fn perp(d: &V3) -> [V3; 2] {
    let a = if d.x.abs() < 0.9 { V3::x() } else { V3::y() };
    let e1 = a.cross(d).normalize();
    [e1, d.cross(&e1)]
}

// ---------------------------------------------------------------------------------------------
// Point fixture
// ---------------------------------------------------------------------------------------------

/// A point on a sphere R = 10 (thickness 0.2, so the thickness terms matter) with 5 neighbours
/// (test gradients differing from the trial ones), committed states with rotated directors and
/// non-zero ū, a rotated lamina frame and a plastic history (ē^p > 0, back stress: β = 0.5),
/// material of the paper's hemisphere (E = 6.825e7, ν = 0.3, σ0 = 2.43e5, H = 3e5).
struct Fixture {
    surface: SurfacePoint<f64>,
    shape: Vec<ShapeData>,
    particles: Vec<ParticleState<f64>>,
    material: MaterialParams<f64>,
    history: PointHistory<f64>,
    dofs: Vec<f64>,
    zeta: f64,
    thickness: f64,
    weight: f64,
    director: DirectorField,
}

/// The seeds of one directional derivative.
#[derive(Clone)]
struct Seeds {
    surface: Option<SurfacePoint<f64>>,
    thickness: f64,
    material: MaterialParams<f64>,
    particles: Vec<ParticleState<f64>>,
    history: PointHistory<f64>,
    dofs: Vec<f64>,
}

const N_NB: usize = 5;

fn zero_state() -> ParticleState<f64> {
    ParticleState {
        u: V3::zeros(),
        d: V3::zeros(),
        d0: V3::zeros(),
        e: [V3::zeros(); 2],
    }
}

fn zero_history() -> PointHistory<f64> {
    PointHistory {
        frame: M3::zeros(),
        material: MaterialState::zero(),
    }
}

impl Seeds {
    fn zero(n: usize) -> Self {
        Seeds {
            surface: None,
            thickness: 0.0,
            material: MaterialParams::zero(),
            particles: vec![zero_state(); n],
            history: zero_history(),
            dofs: vec![0.0; 5 * n],
        }
    }
}

impl Fixture {
    /// `plastic`: a loading step that yields; otherwise an elastic step from a state inside the
    /// yield surface (the plastic history with its relative stress scaled by 0.3).
    fn new(seed: u64, plastic: bool) -> Self {
        let mut rng = Rng::new(seed);
        let sphere = SphereZone::new(
            V3::zeros(),
            10.0,
            [0.0, 72f64.to_radians()],
            [0.0, 90f64.to_radians()],
        )
        .unwrap();
        let surface = SurfacePoint::from_derivs(&Surface::SphereZone(sphere).eval(0.4, 0.3));
        let shape = (0..N_NB)
            .map(|_| {
                let dpsi = [rng.r(0.8), rng.r(0.8)];
                ShapeData {
                    psi: 0.2 + rng.r(0.05),
                    dpsi,
                    dpsi_test: [dpsi[0] + rng.r(0.05), dpsi[1] + rng.r(0.05)],
                }
            })
            .collect();
        let particles = (0..N_NB)
            .map(|_| {
                let d0 = (surface.n + rng.v(0.02)).normalize();
                let d = (d0 + rng.v(0.1)).normalize();
                ParticleState {
                    u: rng.v(0.05),
                    d,
                    d0,
                    e: perp(&d),
                }
            })
            .collect();
        let material = MaterialParams::new(6.825e7, 0.3, 2.43e5, 3.0e5, 0.5).unwrap();
        let mut m = MaterialState::virgin();
        for _ in 0..3 {
            m = return_map(&material, &m, &Vec5::new(4e-3, -1.2e-3, 2e-3, 4e-4, -3e-4))
                .unwrap()
                .state;
        }
        assert!(m.eps_p > 0.0 && m.back_stress.norm() > 0.0);
        if !plastic {
            m.stress = m.back_stress + (m.stress - m.back_stress) * 0.3;
        }
        let frame = surface.initial_frame()
            * Rotation3::from_scaled_axis(V3::new(0.1, -0.05, 0.2)).into_inner();
        let (su, sa) = if plastic { (0.1, 0.05) } else { (2e-4, 1e-5) };
        let dofs = (0..5 * N_NB)
            .map(|i| if i % 5 < 3 { rng.r(su) } else { rng.r(sa) })
            .collect();
        Fixture {
            surface,
            shape,
            particles,
            material,
            history: PointHistory { frame, material: m },
            dofs,
            zeta: 0.6,
            thickness: 0.2,
            weight: 0.37,
            director: DirectorField::Interpolated,
        }
    }

    fn input(&self) -> PointInput<'_, f64> {
        PointInput {
            surface: &self.surface,
            zeta: self.zeta,
            thickness: self.thickness,
            weight: self.weight,
            shape: &self.shape,
            particles: &self.particles,
            material: &self.material,
            history: &self.history,
            director: self.director,
        }
    }

    /// Seeds of one group, sized on the quantities they perturb.
    fn seeds(&self, group: &str, rng: &mut Rng) -> Seeds {
        let n = N_NB;
        let mut s = Seeds::zero(n);
        let all = group == "all";
        if all || group == "surface" {
            let xs = self.surface.x_a[0].norm();
            let ns = self.surface.n_a[0].norm();
            s.surface = Some(SurfacePoint {
                x_a: [rng.v(0.1 * xs), rng.v(0.1 * xs)],
                n: rng.v(0.05),
                n_a: [rng.v(0.1 * ns), rng.v(0.1 * ns)],
            });
        }
        if all || group == "thickness" {
            s.thickness = 0.3 * self.thickness;
        }
        let m = self.material.to_array();
        let mut md = [0.0; N_PARAMS];
        for (i, name) in PARAM_NAMES.iter().enumerate() {
            if all || group == *name {
                md[i] = (0.5 + rng.r(0.3)) * m[i];
            }
        }
        s.material = MaterialParams::from_array(md);
        if all || group == "particles" {
            s.particles = (0..n)
                .map(|_| ParticleState {
                    u: rng.v(0.05),
                    d: rng.v(0.05),
                    d0: rng.v(0.02),
                    e: [rng.v(0.05), rng.v(0.05)],
                })
                .collect();
        }
        if all || group == "history" {
            let sig = self.history.material.stress.norm();
            s.history = PointHistory {
                frame: rng.frame_rate(&self.history.frame, 0.1),
                material: MaterialState {
                    stress: Vec5::from_fn(|_, _| rng.r(0.1 * sig)),
                    back_stress: Vec5::from_fn(|_, _| rng.r(0.1 * sig)),
                    eps_p: 0.2 * self.history.material.eps_p,
                },
            };
        }
        if all || group == "dofs" {
            s.dofs = self
                .dofs
                .iter()
                .map(|q| rng.r(0.5 * q.abs().max(1e-6)))
                .collect();
        }
        s
    }

    /// Hand-derived: residual dot ++ frame dot (column-major) ++ σ̇ ++ α̇ ++ ė^p.
    fn hand(&self, s: &Seeds) -> Vec<f64> {
        let inp = self.input();
        let incr = PointIncrement::new(&self.particles, &self.dofs).unwrap();
        let res = point_residual_with(&inp, &incr).unwrap();
        let incr_dot =
            PointIncrementDot::new(&self.particles, &s.particles, &self.dofs, &s.dofs).unwrap();
        let seeds = PointSeeds {
            surface: s.surface.as_ref(),
            thickness: s.thickness,
            material: s.material,
            particles: &s.particles,
            history: &s.history,
            dofs: &s.dofs,
        };
        let d = point_residual_dot(&inp, &incr, &incr_dot, &res, &seeds).unwrap();
        let mut out = d.residual;
        out.extend_from_slice(d.history.frame.as_slice());
        out.extend_from_slice(&d.history.material.to_array());
        out
    }

    fn plastic(&self) -> bool {
        point_residual(&self.input(), &self.dofs)
            .unwrap()
            .return_map
            .plastic
    }
}

fn lv<T: Real>(v: &V3, dv: &V3, t: T) -> Vector3<T> {
    Vector3::from_fn(|i, _| T::cst(v[i]) + t * dv[i])
}

/// The point along the seed direction, `x(τ) = x + τ ẋ`, as a function of the one input τ.
struct Along<'a> {
    f: &'a Fixture,
    s: &'a Seeds,
}

impl Along<'_> {
    fn result<T: Real>(&self, t: T) -> shelldsa::shell::point::PointResult<T> {
        let (f, s) = (self.f, self.s);
        let zs = SurfacePoint {
            x_a: [V3::zeros(); 2],
            n: V3::zeros(),
            n_a: [V3::zeros(); 2],
        };
        let ds = s.surface.unwrap_or(zs);
        let surface = SurfacePoint {
            x_a: [0, 1].map(|a| lv(&f.surface.x_a[a], &ds.x_a[a], t)),
            n: lv(&f.surface.n, &ds.n, t),
            n_a: [0, 1].map(|a| lv(&f.surface.n_a[a], &ds.n_a[a], t)),
        };
        let particles: Vec<ParticleState<T>> = f
            .particles
            .iter()
            .zip(&s.particles)
            .map(|(p, d)| ParticleState {
                u: lv(&p.u, &d.u, t),
                d: lv(&p.d, &d.d, t),
                d0: lv(&p.d0, &d.d0, t),
                e: [lv(&p.e[0], &d.e[0], t), lv(&p.e[1], &d.e[1], t)],
            })
            .collect();
        let (m, dm) = (f.material.to_array(), s.material.to_array());
        let material =
            MaterialParams::from_array(std::array::from_fn(|i| T::cst(m[i]) + t * dm[i]));
        let (h, dh) = (&f.history, &s.history);
        let history = PointHistory {
            frame: Matrix3::from_fn(|i, j| T::cst(h.frame[(i, j)]) + t * dh.frame[(i, j)]),
            material: MaterialState {
                stress: Vec5::from_fn(|i, _| {
                    T::cst(h.material.stress[i]) + t * dh.material.stress[i]
                }),
                back_stress: Vec5::from_fn(|i, _| {
                    T::cst(h.material.back_stress[i]) + t * dh.material.back_stress[i]
                }),
                eps_p: T::cst(h.material.eps_p) + t * dh.material.eps_p,
            },
        };
        let dofs: Vec<T> = f
            .dofs
            .iter()
            .zip(&s.dofs)
            .map(|(q, dq)| T::cst(*q) + t * *dq)
            .collect();
        let inp = PointInput {
            surface: &surface,
            zeta: f.zeta,
            thickness: T::cst(f.thickness) + t * s.thickness,
            weight: f.weight,
            shape: &f.shape,
            particles: &particles,
            material: &material,
            history: &history,
            director: f.director,
        };
        point_residual(&inp, &dofs).unwrap()
    }
}

impl Differentiable for Along<'_> {
    fn n_inputs(&self) -> usize {
        1
    }
    fn eval<T: Real>(&self, x: &[T]) -> Vec<T> {
        let r = self.result(x[0]);
        let mut out = r.residual;
        out.extend_from_slice(r.history.frame.as_slice());
        out.extend(r.history.material.stress.iter().copied());
        out.extend(r.history.material.back_stress.iter().copied());
        out.push(r.history.material.eps_p);
        out
    }
    fn active_set(&self, x: &[f64]) -> Vec<u8> {
        // The return map's branch: a flip within ±h would make the FD meaningless.
        vec![u8::from(self.result(x[0]).return_map.plastic)]
    }
}

/// Output blocks compared separately, each against its own largest entry: residual, frame,
/// stress and back stress, effective plastic strain.
fn blocks(n: usize) -> [(&'static str, std::ops::Range<usize>); 4] {
    let r = 5 * n;
    [
        ("residual", 0..r),
        ("frame", r..r + 9),
        ("stress, back stress", r + 9..r + 19),
        ("ē^p", r + 19..r + 20),
    ]
}

fn column(v: &[f64], rows: &std::ops::Range<usize>) -> DMatrix<f64> {
    DMatrix::from_column_slice(rows.len(), 1, &v[rows.clone()])
}

/// Tolerances.
/// Dual: the same f64 point differentiated two ways through ~12 hand-derived stages, each exact
/// to round-off, so agreement to 1e-10 relative to each block's largest entry (entries below
/// 2.2e-4 of it held to the absolute floor of `Tolerance::rel`).
/// FD: the seeds change their quantities by 5–50 % per unit τ, so an absolute step h in τ is a
/// relative perturbation of ~h. Round-off ~ε|y|/h against derivatives ~|y|: ~2e-10 at h = 1e-6;
/// truncation ~h² times the third derivative, on the strain-increment scale (1e-2 per unit
/// perturbation) ~1e-8. 1e-6 relative (floor 1e-4 of the block's largest entry) leaves a margin
/// of ~100; the measured worst cases are printed.
/// Blocks whose values are much larger than their derivatives (the frame, ~1, moves by ~1e-5
/// per unit τ for a surface seed) are dominated by the round-off of the differenced values:
/// `ε max|y| / h` absolute. The floor is raised to 50 times that where it exceeds 1e-4 of the
/// block's largest derivative.
const FD_STEP: f64 = 1e-6;
fn fd_tol(value_scale: f64, derivative_scale: f64) -> Tolerance {
    let rel = 1e-6;
    let roundoff = 50.0 * f64::EPSILON * value_scale / FD_STEP;
    Tolerance {
        rel,
        floor: (roundoff / (rel * derivative_scale.max(f64::MIN_POSITIVE))).max(1e-4),
    }
}

const GROUPS: [&str; 12] = [
    "surface",
    "thickness",
    "young",
    "poisson",
    "shear_factor",
    "sigma0",
    "hardening",
    "beta",
    "particles",
    "history",
    "dofs",
    "all",
];

fn three_way(plastic: bool, director: DirectorField) {
    let mut f = Fixture::new(11, plastic);
    f.director = director;
    assert_eq!(
        f.plastic(),
        plastic,
        "the fixture's step is plastic = {plastic}"
    );
    let mut rng = Rng::new(99);
    let mut worst = (0.0_f64, 0.0_f64);
    for group in GROUPS {
        let s = f.seeds(group, &mut rng);
        let hand = f.hand(&s);
        let along = Along { f: &f, s: &s };
        let dual = dual_jacobian(&along, &[0.0]);
        let fd = central_jacobian(&along, &[0.0], StepSize::Absolute(FD_STEP));
        let y0 = along.eval(&[0.0]);
        // The branch must not flip within ±h (both steps are well inside their branch).
        assert!(
            fd.flips.is_empty(),
            "{group}: return-map branch flips within ±h"
        );
        for (name, rows) in blocks(N_NB) {
            let h = column(&hand, &rows);
            let d = DMatrix::from_fn(rows.len(), 1, |i, _| dual[(rows.start + i, 0)]);
            let c = DMatrix::from_fn(rows.len(), 1, |i, _| fd.jacobian[(rows.start + i, 0)]);
            let labels = |i: usize, _: usize| (format!("{name}[{i}]"), group.to_string());
            let vd = compare_matrices("hand vs dual", &h, &d, Tolerance::rel(1e-10), &[], &labels);
            let value_scale = y0[rows.clone()]
                .iter()
                .fold(0.0_f64, |m, v: &f64| m.max(v.abs()));
            let dscale = c.amax();
            let vf = compare_matrices(
                "hand vs FD",
                &h,
                &c,
                fd_tol(value_scale, dscale),
                &[],
                &labels,
            );
            println!(
                "plastic={plastic} {group:>12} {name:>20}: scale {:.3e}, dual {:.2e}, fd {:.2e}",
                vd.scale,
                vd.max_error(),
                vf.max_error()
            );
            worst = (worst.0.max(vd.max_error()), worst.1.max(vf.max_error()));
            assert!(vd.passed(), "{group} {name}: {vd}");
            assert!(vf.passed(), "{group} {name}: {vf}");
        }
    }
    println!(
        "plastic={plastic}: worst dual {:.2e}, worst fd {:.2e}",
        worst.0, worst.1
    );
}

#[test]
fn point_residual_dot_three_ways_plastic_step() {
    three_way(true, DirectorField::Interpolated);
}

#[test]
fn point_residual_dot_three_ways_elastic_step() {
    three_way(false, DirectorField::Interpolated);
}

/// The unit director's terms (its maps `N′`, `N″`, `N‴` in the seeds' sums and the rows) under
/// the same tolerances: the same chain with a few more closed-form stages.
#[test]
fn point_residual_dot_three_ways_normalised_director() {
    three_way(true, DirectorField::Normalised);
    three_way(false, DirectorField::Normalised);
}

/// With only `Δq̇ = e_j` seeded, the residual derivative is column j of the consistent tangent
/// (both hand-derived, by different compositions of the same stages: round-off, 1e-10).
#[test]
fn dofs_seed_reproduces_point_tangent() {
    for plastic in [true, false] {
        let f = Fixture::new(11, plastic);
        let inp = f.input();
        let res = point_residual(&inp, &f.dofs).unwrap();
        let k = point_tangent(&inp, &f.dofs, &res).unwrap();
        let nd = 5 * N_NB;
        let mut cols = DMatrix::zeros(nd, nd);
        for j in 0..nd {
            let mut s = Seeds::zero(N_NB);
            s.dofs[j] = 1.0;
            let h = f.hand(&s);
            cols.set_column(j, &nalgebra::DVector::from_column_slice(&h[..nd]));
        }
        let c = compare_matrices(
            "point_residual_dot vs point_tangent",
            &cols,
            &k,
            Tolerance::rel(1e-10),
            &[],
            &|i, j| (format!("r[{i}]"), format!("q[{j}]")),
        );
        println!("plastic={plastic}: {c}");
        assert!(c.passed(), "{c}");
    }
}

fn dual_state(p: &ParticleState<f64>, d: &ParticleState<f64>) -> ParticleState<Dual64> {
    let l = |a: &V3, b: &V3| Vector3::from_fn(|i, _| Dual64::new(a[i], b[i]));
    ParticleState {
        u: l(&p.u, &d.u),
        d: l(&p.d, &d.d),
        d0: l(&p.d0, &d.d0),
        e: [l(&p.e[0], &d.e[0]), l(&p.e[1], &d.e[1])],
    }
}

fn state_parts(p: &ParticleState<f64>) -> Vec<f64> {
    [p.u, p.d, p.d0, p.e[0], p.e[1]]
        .iter()
        .flat_map(|v| v.iter().copied().collect::<Vec<_>>())
        .collect()
}

/// `commit_particle_dot` = dual derivative of `commit_particle`, for rotations on both sides of
/// the series/closed-form switch of Rodrigues' coefficients (|θ| = 2) and at θ = 0. Round-off:
/// 1e-12 relative to the largest entry (a handful of products of unit vectors).
#[test]
fn commit_particle_dot_matches_dual() {
    let mut rng = Rng::new(5);
    for alpha_scale in [0.0, 0.3, 1.2, 2.5] {
        for _ in 0..4 {
            let d = (V3::new(0.2, -0.3, 0.9) + rng.v(0.3)).normalize();
            let p = ParticleState {
                u: rng.v(0.1),
                d,
                d0: (d + rng.v(0.1)).normalize(),
                e: perp(&d),
            };
            let pd = ParticleState {
                u: rng.v(1.0),
                d: rng.v(1.0),
                d0: rng.v(1.0),
                e: [rng.v(1.0), rng.v(1.0)],
            };
            let q = [
                rng.r(0.1),
                rng.r(0.1),
                rng.r(0.1),
                rng.r(alpha_scale),
                rng.r(alpha_scale),
            ];
            let qd: Vec<f64> = (0..5).map(|_| rng.r(1.0)).collect();
            let hand = commit_particle_dot(&p, &pd, &q, &qd);
            let qdual: Vec<Dual64> = q
                .iter()
                .zip(&qd)
                .map(|(a, b)| Dual64::new(*a, *b))
                .collect();
            let dual = commit_particle(&dual_state(&p, &pd), &qdual);
            let dual_eps = ParticleState {
                u: dual.u.map(|x| x.eps),
                d: dual.d.map(|x| x.eps),
                d0: dual.d0.map(|x| x.eps),
                e: [dual.e[0].map(|x| x.eps), dual.e[1].map(|x| x.eps)],
            };
            let (a, b) = (state_parts(&hand), state_parts(&dual_eps));
            let scale = b.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
            let err = a
                .iter()
                .zip(&b)
                .fold(0.0_f64, |m, (x, y)| m.max((x - y).abs()));
            assert!(
                err <= 1e-12 * scale,
                "α scale {alpha_scale}: |hand − dual| = {err:e}, scale {scale:e}"
            );
        }
    }
}

/// Point-level input errors are typed and name the field.
#[test]
fn point_level_bad_sizes_are_named_errors() {
    let f = Fixture::new(11, true);
    let mut s = Seeds::zero(N_NB);
    s.particles.pop();
    let err = PointIncrementDot::new(&f.particles, &s.particles, &f.dofs, &s.dofs).unwrap_err();
    assert!(
        matches!(&err, ShellError::InvalidInput(m) if m.contains("particles_dot")),
        "{err}"
    );
    let inp = f.input();
    let incr = PointIncrement::new(&f.particles, &f.dofs).unwrap();
    let res = point_residual_with(&inp, &incr).unwrap();
    let full = Seeds::zero(N_NB);
    let incr_dot =
        PointIncrementDot::new(&f.particles, &full.particles, &f.dofs, &full.dofs).unwrap();
    let short_dofs = vec![0.0; 5 * N_NB - 1];
    let seeds = PointSeeds {
        surface: None,
        thickness: 0.0,
        material: MaterialParams::zero(),
        particles: &full.particles,
        history: &full.history,
        dofs: &short_dofs,
    };
    let err = point_residual_dot(&inp, &incr, &incr_dot, &res, &seeds).unwrap_err();
    assert!(
        matches!(&err, ShellError::InvalidInput(m) if m.contains("seeds.dofs")),
        "{err}"
    );
}

// ---------------------------------------------------------------------------------------------
// Model level
// ---------------------------------------------------------------------------------------------

/// The shipped plastic hemisphere (quarter model, two symmetry planes, so image particles) on
/// 7 × 7 particles, after one committed plastic step: an equibiaxial stretch `Δū = ε x⁰`
/// (ε = 6e-3, above the yield strain σ0(1 − ν)/E ≈ 2.5e-3) with random rotations of 0.01 rad.
/// The returned increment of the next step stretches by `8e-3 (x − y)/R`: part of the layer
/// points yield further, part unload elastically.
fn committed_model(director: DirectorField) -> (ShellModel, Vec<f64>) {
    let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let path = root.join("verification/hemisphere-plastic/case.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let text: String = text
        .lines()
        .map(|l| {
            if l.starts_with("grid =") {
                "grid = [7, 7]\n".to_string()
            } else {
                format!("{l}\n")
            }
        })
        .collect();
    let case = parse_shell_case(&text, &path).unwrap();
    let built = build(&case).unwrap();
    let mut model = problem_model(&built.problem).clone();
    assert!(
        !model.symmetry.images.is_empty(),
        "the quarter model has images"
    );
    // Beta = 0.5 so the back stress is non-zero.
    model.material.beta = 0.5;
    model.director = director;
    let mut rng = Rng::new(21);
    // On the sphere centred at the origin x⁰ = R d⁰ (R = 10).
    let field = |m: &ShellModel, eps: f64, rot: f64, rng: &mut Rng| -> Vec<f64> {
        m.particles
            .iter()
            .flat_map(|p| {
                // eps < 0: a stretch varying as (x − y)/R, loading on one side of x = y and
                // unloading on the other.
                let e = if eps < 0.0 {
                    -eps * (p.d0.x - p.d0.y)
                } else {
                    eps
                };
                let u = p.d0 * (10.0 * e) + rng.v(1e-3);
                [u.x, u.y, u.z, rng.r(rot), rng.r(rot)]
            })
            .collect()
    };
    let q1 = field(&model, 6e-3, 1e-2, &mut rng);
    let (_, trial) = model
        .internal_force_with(
            &model.particles.clone(),
            &model.history.clone(),
            &model.material.clone(),
            model.thickness,
            &q1,
        )
        .unwrap();
    let nl = model.thickness_rule.len();
    model.commit_histories(&q1, trial.chunks(nl).map(|c| c.to_vec()).collect());
    let q2 = field(&model, -8e-3, 1e-2, &mut rng);
    (model, q2)
}

/// Owned seeds of one model-level group.
struct OwnedModelSeeds {
    surface: Option<Vec<SurfacePoint<f64>>>,
    thickness: f64,
    material: MaterialParams<f64>,
    particles: Vec<ParticleState<f64>>,
    history: Vec<PointHistory<f64>>,
    dofs: Vec<f64>,
}

impl OwnedModelSeeds {
    fn view(&self) -> ModelSeeds<'_> {
        ModelSeeds {
            surface: self.surface.as_deref(),
            thickness: self.thickness,
            material: self.material,
            particles: &self.particles,
            history: &self.history,
            dofs: &self.dofs,
        }
    }
}

fn model_seeds(m: &ShellModel, group: &str, q: &[f64], rng: &mut Rng) -> OwnedModelSeeds {
    let all = group == "all";
    let surface = (group == "surface").then(|| {
        m.points
            .iter()
            .map(|p| {
                let xs = p.surface.x_a[0].norm();
                let ns = p.surface.n_a[0].norm();
                SurfacePoint {
                    x_a: [rng.v(0.05 * xs), rng.v(0.05 * xs)],
                    n: rng.v(0.02),
                    n_a: [rng.v(0.05 * ns), rng.v(0.05 * ns)],
                }
            })
            .collect()
    });
    let mat = m.material.to_array();
    let material = MaterialParams::from_array(std::array::from_fn(|i| {
        if all || group == PARAM_NAMES[i] {
            (0.5 + rng.r(0.3)) * mat[i]
        } else {
            0.0
        }
    }));
    let particles = m
        .particles
        .iter()
        .map(|_| {
            if all || group == "particles" {
                ParticleState {
                    u: rng.v(0.01),
                    d: rng.v(0.01),
                    d0: rng.v(0.005),
                    e: [rng.v(0.01), rng.v(0.01)],
                }
            } else {
                zero_state()
            }
        })
        .collect();
    let sig = m
        .history
        .iter()
        .fold(0.0_f64, |a, h| a.max(h.material.stress.norm()));
    let history = m
        .history
        .iter()
        .map(|h| {
            if all || group == "history" {
                PointHistory {
                    frame: rng.frame_rate(&h.frame, 0.05),
                    material: MaterialState {
                        stress: Vec5::from_fn(|_, _| rng.r(0.05 * sig)),
                        back_stress: Vec5::from_fn(|_, _| rng.r(0.05 * sig)),
                        eps_p: 0.1 * h.material.eps_p,
                    },
                }
            } else {
                zero_history()
            }
        })
        .collect();
    let dofs = q
        .iter()
        .map(|v| {
            if all || group == "dofs" {
                rng.r(0.5 * v.abs().max(1e-6))
            } else {
                0.0
            }
        })
        .collect();
    OwnedModelSeeds {
        surface,
        thickness: if all || group == "thickness" {
            0.3 * m.thickness
        } else {
            0.0
        },
        material,
        particles,
        history,
        dofs,
    }
}

/// Flatten (f, histories) into blocks: force, frames, stresses and back stresses, ē^p.
fn model_blocks(f: &[f64], h: &[PointHistory<f64>]) -> [(&'static str, Vec<f64>); 4] {
    [
        ("force", f.to_vec()),
        (
            "frame",
            h.iter().flat_map(|x| x.frame.as_slice().to_vec()).collect(),
        ),
        (
            "stress, back stress",
            h.iter()
                .flat_map(|x| x.material.to_array()[..10].to_vec())
                .collect(),
        ),
        ("ē^p", h.iter().map(|x| x.material.eps_p).collect()),
    ]
}

fn dual_reference(
    m: &ShellModel,
    q: &[f64],
    s: &OwnedModelSeeds,
) -> (Vec<f64>, Vec<PointHistory<f64>>) {
    let particles: Vec<ParticleState<Dual64>> = m
        .particles
        .iter()
        .zip(&s.particles)
        .map(|(p, d)| dual_state(p, d))
        .collect();
    let history: Vec<PointHistory<Dual64>> = m
        .history
        .iter()
        .zip(&s.history)
        .map(|(h, d)| PointHistory {
            frame: Matrix3::from_fn(|i, j| Dual64::new(h.frame[(i, j)], d.frame[(i, j)])),
            material: MaterialState {
                stress: Vec5::from_fn(|i, _| {
                    Dual64::new(h.material.stress[i], d.material.stress[i])
                }),
                back_stress: Vec5::from_fn(|i, _| {
                    Dual64::new(h.material.back_stress[i], d.material.back_stress[i])
                }),
                eps_p: Dual64::new(h.material.eps_p, d.material.eps_p),
            },
        })
        .collect();
    let (mv, md) = (m.material.to_array(), s.material.to_array());
    let material = MaterialParams::from_array(std::array::from_fn(|i| Dual64::new(mv[i], md[i])));
    let dofs: Vec<Dual64> = q
        .iter()
        .zip(&s.dofs)
        .map(|(a, b)| Dual64::new(*a, *b))
        .collect();
    let (f, h) = m
        .internal_force_with(
            &particles,
            &history,
            &material,
            Dual64::new(m.thickness, s.thickness),
            &dofs,
        )
        .unwrap();
    let hist = h
        .iter()
        .map(|x| PointHistory {
            frame: x.frame.map(|v| v.eps),
            material: MaterialState {
                stress: x.material.stress.map(|v| v.eps),
                back_stress: x.material.back_stress.map(|v| v.eps),
                eps_p: x.material.eps_p.eps,
            },
        })
        .collect();
    (f.iter().map(|v| v.eps).collect(), hist)
}

/// The surface seed has no dual path through `internal_force_with` (the initial geometry is
/// the model's f64 data): central differences of the model with its points' geometry moved.
fn surface_fd(
    m: &ShellModel,
    q: &[f64],
    ds: &[SurfacePoint<f64>],
    h: f64,
) -> (Vec<f64>, Vec<PointHistory<f64>>, [Vec<bool>; 2]) {
    let eval = |sign: f64| {
        let mut mm = m.clone();
        for (p, d) in mm.points.iter_mut().zip(ds) {
            let s = &mut p.surface;
            for a in 0..2 {
                s.x_a[a] += d.x_a[a] * (sign * h);
                s.n_a[a] += d.n_a[a] * (sign * h);
            }
            s.n += d.n * (sign * h);
        }
        let (f, hist) = mm
            .internal_force_with(&m.particles, &m.history, &m.material, m.thickness, q)
            .unwrap();
        let yielded: Vec<bool> = hist
            .iter()
            .zip(&m.history)
            .map(|(t, c)| t.material.eps_p > c.material.eps_p)
            .collect();
        (f, hist, yielded)
    };
    let (fp, hp, yp) = eval(1.0);
    let (fm, hm, ym) = eval(-1.0);
    let f = fp
        .iter()
        .zip(&fm)
        .map(|(a, b)| (a - b) / (2.0 * h))
        .collect();
    let hist = hp
        .iter()
        .zip(&hm)
        .map(|(a, b)| PointHistory {
            frame: (a.frame - b.frame) / (2.0 * h),
            material: MaterialState {
                stress: (a.material.stress - b.material.stress) / (2.0 * h),
                back_stress: (a.material.back_stress - b.material.back_stress) / (2.0 * h),
                eps_p: (a.material.eps_p - b.material.eps_p) / (2.0 * h),
            },
        })
        .collect();
    (f, hist, [yp, ym])
}

/// Hand vs dual at model level: 1e-10 relative for entries above 1 % of the block's largest,
/// 1e-12 of the largest below. Small entries are not small terms: e.g. the thickness derivative
/// of the frames (~1e-5) is formed from products like `H J̇ⁿ`, `Qₙ ṙᵀ` whose terms are ~1e-3 and
/// cancel, so their round-off is ~ε·1e-3 absolute; over 6480 frame entries the worst measured
/// was 5e-14 of the largest (1e-18 on a 1e-19 entry), which the point tests' floor (2.2e-14 of
/// the largest) would flag as a failure.
fn model_dual_tol() -> Tolerance {
    Tolerance {
        rel: 1e-10,
        floor: 1e-2,
    }
}

/// `internal_force_dots` with every seed group as one seed set of a single multi-RHS call equals
/// the dual-number `internal_force_with` with the same seeds (force and trial histories), 1e-10
/// relative to each block's largest entry (the point kernel agrees to ~1e-13; the assembly adds
/// the same contributions in the same order); the surface group, which has no dual path, equals
/// central differences (the point test's tolerance). Deterministic: a second call is
/// bit-identical.
#[test]
fn internal_force_dots_match_dual_model() {
    internal_force_dots_match_dual(DirectorField::Interpolated);
}

#[test]
fn internal_force_dots_match_dual_model_normalised_director() {
    internal_force_dots_match_dual(DirectorField::Normalised);
}

fn internal_force_dots_match_dual(director: DirectorField) {
    let (model, q) = committed_model(director);
    let mut rng = Rng::new(77);
    let (f0, h0) = model
        .internal_force_with(
            &model.particles,
            &model.history,
            &model.material,
            model.thickness,
            &q,
        )
        .unwrap();
    let yielded = h0
        .iter()
        .zip(&model.history)
        .filter(|(t, c)| t.material.eps_p > c.material.eps_p)
        .count();
    println!("{yielded} of {} layer points yield in the step", h0.len());
    assert!(
        yielded > 0 && yielded < h0.len(),
        "a mixed plastic/elastic step"
    );
    assert!(model.history.iter().any(|h| h.material.eps_p > 0.0));
    let owned: Vec<OwnedModelSeeds> = GROUPS
        .iter()
        .map(|g| model_seeds(&model, g, &q, &mut rng))
        .collect();
    let views: Vec<ModelSeeds> = owned.iter().map(|s| s.view()).collect();
    let dots = model.internal_force_dots(&q, &views).unwrap();
    let again = model.internal_force_dots(&q, &views).unwrap();
    assert!(
        dots.iter()
            .zip(&again)
            .all(|(a, b)| a.0 == b.0 && a.1 == b.1),
        "bit-identical run to run"
    );
    for ((group, s), (f, h)) in GROUPS.iter().zip(&owned).zip(&dots) {
        let hand = model_blocks(f, h);
        if *group == "surface" {
            let (ff, hf, [yp, ym]) = surface_fd(&model, &q, s.surface.as_ref().unwrap(), FD_STEP);
            assert_eq!(yp, ym, "a return-map branch flips within ±h");
            let values = model_blocks(&f0, &h0);
            for (((name, a), (_, b)), (_, v)) in hand.iter().zip(model_blocks(&ff, &hf)).zip(values)
            {
                let vs = v.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
                let (a, b) = (
                    DMatrix::from_column_slice(a.len(), 1, a),
                    DMatrix::from_column_slice(b.len(), 1, &b),
                );
                let c =
                    compare_matrices("hand vs FD", &a, &b, fd_tol(vs, b.amax()), &[], &|i, _| {
                        (format!("{name}[{i}]"), group.to_string())
                    });
                println!(
                    "model {group:>12} {name:>20}: scale {:.3e}, fd {:.2e}",
                    c.scale,
                    c.max_error()
                );
                assert!(c.passed(), "{group} {name}: {c}");
            }
            continue;
        }
        let (fr, hr) = dual_reference(&model, &q, s);
        for ((name, a), (_, b)) in hand.iter().zip(model_blocks(&fr, &hr)) {
            let (a, b) = (
                DMatrix::from_column_slice(a.len(), 1, a),
                DMatrix::from_column_slice(b.len(), 1, &b),
            );
            let c = compare_matrices("hand vs dual", &a, &b, model_dual_tol(), &[], &|i, _| {
                (format!("{name}[{i}]"), group.to_string())
            });
            println!(
                "model {group:>12} {name:>20}: scale {:.3e}, dual {:.2e}",
                c.scale,
                c.max_error()
            );
            assert!(c.passed(), "{group} {name}: {c}");
        }
    }
}

/// Model-level input errors are typed and name the seed set and field.
#[test]
fn model_level_bad_seeds_are_named_errors() {
    let (model, q) = committed_model(DirectorField::Interpolated);
    let mut rng = Rng::new(3);
    let mut s = model_seeds(&model, "all", &q, &mut rng);
    s.history.pop();
    let err = model.internal_force_dots(&q, &[s.view()]).unwrap_err();
    assert!(
        matches!(&err, ShellError::InvalidInput(m) if m.contains("seeds[0].history")),
        "{err}"
    );
    let mut s = model_seeds(&model, "all", &q, &mut rng);
    s.material.young = f64::NAN;
    let err = model.internal_force_dots(&q, &[s.view()]).unwrap_err();
    assert!(
        matches!(&err, ShellError::InvalidInput(m) if m.contains("seeds[0].young")),
        "{err}"
    );
    let err = model.internal_force_dots(&q[1..], &[]).unwrap_err();
    assert!(
        matches!(&err, ShellError::InvalidInput(m) if m.contains("dofs")),
        "{err}"
    );
}

/// `internal_force_dots_linearised_into` with recycled storage (history buffers filled with
/// unrelated values, one of the wrong length, one missing, one too many; the layer data of a
/// linearisation at another increment) gives bit for bit what the fresh call gives, and so
/// does the history update from its linearisation: every entry of fitting storage is
/// overwritten, the rest is replaced.
#[test]
fn recycled_storage_changes_nothing() {
    let (model, q) = committed_model(DirectorField::Interpolated);
    let owned = all_groups(&model, &q, 11);
    let zero_dofs = vec![0.0; q.len()];
    let views = fictitious(&owned, &zero_dofs);
    let (fresh, lin) = model.internal_force_dots_linearised(&q, &views).unwrap();
    let dofs_dot: Vec<&[f64]> = owned.iter().map(|s| &s.dofs[..]).collect();
    let updated =
        |lin: &shelldsa::shell::point_sensitivity::StepLinearisation,
         dots: &[shelldsa::shell::point_sensitivity::InternalForceDot]| {
            let mut h: Vec<_> = dots.iter().map(|d| d.1.clone()).collect();
            model
                .add_increment_history_dots(lin, &dofs_dot, &mut h)
                .unwrap();
            h
        };
    let fresh_updated = updated(&lin, &fresh);
    // Layer data of another increment, to be overwritten.
    let q_other: Vec<f64> = q.iter().map(|x| 0.5 * x).collect();
    let (_, other) = model
        .internal_force_dots_linearised(&q_other, &views)
        .unwrap();
    let n = model.history.len();
    let junk = |k: usize| -> Vec<PointHistory<f64>> { owned[k % owned.len()].history.clone() };
    // Case 0: one buffer per seed set, one of them one entry short; case 1: one buffer too
    // few; case 2: one too many.
    let mut short: Vec<_> = (0..views.len()).map(junk).collect();
    short[1].pop();
    let cases = [
        short,
        (0..views.len() - 1).map(junk).collect(),
        (0..views.len() + 1).map(junk).collect(),
    ];
    for (c, buffers) in cases.into_iter().enumerate() {
        assert!(
            buffers.iter().any(|b| b.len() == n),
            "case {c}: some buffer fits"
        );
        let previous = (c != 1).then(|| other.clone());
        let (got, got_lin) = model
            .internal_force_dots_linearised_into(&q, &views, buffers, previous)
            .unwrap();
        assert_eq!(got.len(), fresh.len(), "case {c}");
        for (s, (a, b)) in got.iter().zip(&fresh).enumerate() {
            assert!(a.0 == b.0 && a.1 == b.1, "case {c}, seed set {s}");
        }
        assert!(
            updated(&got_lin, &got) == fresh_updated,
            "case {c}: history update"
        );
    }
}

/// Seeds of every group of [`GROUPS`] (random, from `seed`).
fn all_groups(model: &ShellModel, q: &[f64], seed: u64) -> Vec<OwnedModelSeeds> {
    let mut rng = Rng::new(seed);
    GROUPS
        .iter()
        .map(|g| model_seeds(model, g, q, &mut rng))
        .collect()
}

/// The seeds' views with `Δq̇ = 0` (the fictitious loads' seeds).
fn fictitious<'a>(owned: &'a [OwnedModelSeeds], zero_dofs: &'a [f64]) -> Vec<ModelSeeds<'a>> {
    owned
        .iter()
        .map(|s| ModelSeeds {
            dofs: zero_dofs,
            ..s.view()
        })
        .collect()
}

/// The increment-only history update from a kept linearisation
/// (`add_increment_history_dots`) plus the fictitious loads' histories equals the trial
/// histories of `internal_force_dots` seeded with `Δq̇` as well, for both director fields
/// (linearity; the two compose the same stages in another order, so 1e-10 relative to each
/// block's largest entry, the model-level dual tolerance).
#[test]
fn linearised_history_update_equals_full_dots() {
    for director in [DirectorField::Interpolated, DirectorField::Normalised] {
        let (model, q) = committed_model(director);
        let owned = all_groups(&model, &q, 13);
        let full: Vec<ModelSeeds> = owned.iter().map(|s| s.view()).collect();
        let zero_dofs = vec![0.0; q.len()];
        let fictitious = fictitious(&owned, &zero_dofs);
        let reference = model.internal_force_dots(&q, &full).unwrap();
        let (dots, lin) = model
            .internal_force_dots_linearised(&q, &fictitious)
            .unwrap();
        let dofs_dot: Vec<&[f64]> = owned.iter().map(|s| &s.dofs[..]).collect();
        let mut h: Vec<_> = dots.iter().map(|d| d.1.clone()).collect();
        model
            .add_increment_history_dots(&lin, &dofs_dot, &mut h)
            .unwrap();
        for ((group, r), got) in GROUPS.iter().zip(&reference).zip(&h) {
            for ((name, a), (_, b)) in model_blocks(&r.0, got).iter().zip(model_blocks(&r.0, &r.1))
            {
                if *name == "force" {
                    continue;
                }
                let (a, b) = (
                    DMatrix::from_column_slice(a.len(), 1, a),
                    DMatrix::from_column_slice(b.len(), 1, &b),
                );
                let c =
                    compare_matrices("update vs full", &a, &b, model_dual_tol(), &[], &|i, _| {
                        (format!("{name}[{i}]"), group.to_string())
                    });
                println!("{director:?} {group:>12} {name:>20}: {:.2e}", c.max_error());
                assert!(c.passed(), "{director:?} {group} {name}: {c}");
            }
        }
    }
}
