//! Continuum DSA point and model kernels (issue 5, path 2): the hand-derived directional
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
use shelldsa::sensitivity::dual::commit_particle;
use shelldsa::shell::model::ShellModel;
use shelldsa::shell::point::{
    point_residual, point_residual_with, point_tangent, ParticleState, PointHistory,
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

fn three_way(plastic: bool) {
    let f = Fixture::new(11, plastic);
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
    three_way(true);
}

#[test]
fn point_residual_dot_three_ways_elastic_step() {
    three_way(false);
}
