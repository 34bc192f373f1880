//! Shell–tool contact (`shell::contact::ShellContact`): the hand-derived contact stiffness against the
//! dual Jacobian of the generic force and central differences, the report, the error checks,
//! and full solves with `ShellProblem` (contact patch test with a penalty study; a rigid cylinder
//! pressed into a clamped plate with the tool force balancing the support reactions).

mod common;

use nalgebra::{DMatrix, Vector3};
use shelldsa::contact::{ContactError, PathKey, RigidTool, Side, ToolPath};
use shelldsa::geometry::{CylinderSector, Rectangle, SphereZone, Surface};
use shelldsa::meshfree::Edge;
use shelldsa::scalar::Real;
use shelldsa::shell::constraints::{edge_constraints, EdgeCondition, LinearConstraint};
use shelldsa::shell::contact::{ContactFaces, ShellContact};
use shelldsa::shell::load::{ContactLoad, Gravity, Load, LoadScaling};
use shelldsa::shell::model::ShellModel;
use shelldsa::shell::problem::ShellProblem;
use shelldsa::solver::{
    LinearSolver, LoadStepping, Method, NewtonOptions, NewtonSolver, Predictor, SolverOptions,
};
use shelldsa::verification::{check, CheckOptions, Differentiable, Tolerance};
use std::f64::consts::PI;
use std::sync::Arc;

type V3 = Vector3<f64>;

const E: f64 = 1.0e5;
const T: f64 = 0.02;

fn plate() -> Surface<f64> {
    Surface::Rectangle(Rectangle::new(V3::zeros(), V3::x(), V3::y()).unwrap())
}

fn plate_model(n: usize) -> ShellModel {
    common::elastic_model(
        &plate(),
        &common::ModelSpec {
            thickness: T,
            young: E,
            n_u: n,
            n_v: n,
            support: 3.0,
            sub: 1,
            ppc: 2,
        },
    )
}

/// A cylinder punch of radius `r` with its axis along y at x = `x_axis`, lowest line at height
/// `z_low`, spanning y ∈ [−0.2, 1.2] and the lower half (angles 20°–160° from x about y; with
/// `e₂ = ŷ × x̂ = −ẑ` that is the part facing down). Solid inside: Side::Positive.
fn cylinder_punch(r: f64, x_axis: f64, z_low: f64, path: ToolPath) -> RigidTool {
    let s = Surface::CylinderSector(
        CylinderSector::new(
            V3::new(x_axis, -0.2, z_low + r),
            V3::y(),
            V3::x(),
            r,
            [20f64.to_radians(), 160f64.to_radians()],
            [0.0, 1.4],
        )
        .unwrap(),
    );
    RigidTool::new("cylinder", s, Side::Positive, path).unwrap()
}

/// A spherical die below the plate: a ball of radius `r` whose top is at height `z_top`
/// under (x, y) = (0.35, 0.6); the zone covers latitudes 20°–85°. Solid inside.
fn ball_die(r: f64, z_top: f64) -> RigidTool {
    let s = Surface::SphereZone(
        SphereZone::new(
            V3::new(0.35, 0.6, z_top - r),
            r,
            [20f64.to_radians(), 85f64.to_radians()],
            [0.0, 2.0 * PI],
        )
        .unwrap(),
    );
    RigidTool::new("ball", s, Side::Positive, ToolPath::fixed()).unwrap()
}

/// A deterministic pseudo-random increment: translations up to `du`, rotations up to `da`.
fn increment(model: &ShellModel, du: f64, da: f64) -> Vec<f64> {
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    (0..model.n_dofs())
        .map(|i| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let r = (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0;
            if i % 5 < 3 {
                r * du
            } else {
                r * da
            }
        })
        .collect()
}

/// The generic contact force as a function of the generalised increment.
struct ContactForce<'a> {
    contact: &'a ShellContact,
    model: &'a ShellModel,
    t: f64,
}

impl Differentiable for ContactForce<'_> {
    fn n_inputs(&self) -> usize {
        self.model.n_dofs()
    }
    fn eval<U: Real>(&self, x: &[U]) -> Vec<U> {
        let mut f = vec![U::zero(); x.len()];
        self.contact
            .force_generic(self.model, x, self.t, &mut f)
            .unwrap();
        f
    }
    fn active_set(&self, x: &[f64]) -> Vec<u8> {
        let r = self.contact.report(self.model, x, self.t).unwrap();
        r.slaves
            .iter()
            .map(|s| u8::from(s.pressure > 0.0))
            .collect()
    }
}

fn dense_stiffness(
    contact: &ShellContact,
    model: &ShellModel,
    q: &[f64],
    factor: f64,
) -> DMatrix<f64> {
    let mut trip = Vec::new();
    contact.add_stiffness(model, q, factor, &mut trip).unwrap();
    let n = model.n_dofs();
    let mut k = DMatrix::zeros(n, n);
    for (i, j, v) in trip {
        k[(i, j)] += v;
    }
    k
}

/// Several slave points slide on a cylinder punch (top face, moving with the pseudo-time) and on
/// a spherical die (bottom face) at a state with finite rotations: the hand-derived stiffness
/// equals the dual Jacobian of `force_generic` (≤ 1e-9 relative) and central differences to
/// truncation (≤ 1e-6 relative, absolute floor explained below; the force is smooth within ±h
/// unless a point's status flips, and such columns are reported and left out).
#[test]
fn contact_stiffness_matches_dual_jacobian_and_central_differences() {
    let model = plate_model(6);
    let path = ToolPath::new(
        [0.0; 3],
        vec![
            PathKey {
                t: 0.0,
                translation: [0.0; 3],
                rotation: [0.0; 3],
            },
            PathKey {
                t: 1.0,
                translation: [0.05, 0.0, -0.02],
                rotation: [0.0, 0.0, 0.1],
            },
        ],
    )
    .unwrap();
    let tools = vec![
        cylinder_punch(0.3, 0.45, T / 2.0 + 0.01, path),
        ball_die(0.6, -T / 2.0 + 0.02),
    ];
    let contact =
        ShellContact::new(&model, &plate(), tools, ContactFaces::Both, 50.0 * E / T).unwrap();
    let q = increment(&model, 2e-3, 0.08);
    let t = 0.8;
    let rep = contact.report(&model, &q, t).unwrap();
    let active: Vec<usize> = rep.tools.iter().map(|r| r.active_points).collect();
    println!("active points per tool {active:?}");
    assert!(
        active[0] >= 4 && active[1] >= 4,
        "several points on each tool: {active:?}"
    );
    let k = dense_stiffness(&contact, &model, &q, t);
    let f = ContactForce {
        contact: &contact,
        model: &model,
        t,
    };
    // Central differences carry an absolute truncation error ~(h κ)² max|K| with h ≈ 6e-6 and
    // the tool curvatures κ ≤ 1/0.3: ≤ 4e-10 of the largest entry. Entries below 1e-3 of the
    // largest are therefore compared absolutely against 1e-6 · 1e-3 · max|K| = 1e-9 max|K|.
    let opts = CheckOptions {
        fd: Tolerance {
            rel: 1e-6,
            floor: 1e-3,
        },
        ..CheckOptions::new(1e-9, 1e-6)
    };
    let report = check(&f, "contact stiffness", &q, &k, opts);
    println!("{report}");
    assert!(report.passed());
    // A prescribed load: the shell problem subtracts it as given, at factor = λ = t.
    let load = Load::Contact(ContactLoad {
        contact: Arc::new(contact),
        penalty_factor: None,
    });
    assert_eq!(load.scaling(), LoadScaling::Prescribed);
    let mut fp = vec![0.0; q.len()];
    load.add_force(&model, &q, t, &mut fp).unwrap();
    assert!(fp.iter().any(|v| *v != 0.0));
}

/// The report's tool forces are the negated sum of the contact forces on the particles'
/// translations (RK functions are a partition of unity), and its pressures are `−ω g`.
#[test]
fn report_balances_the_scattered_forces() {
    let model = plate_model(6);
    let tools = vec![ball_die(0.4, -T / 2.0 + 0.004)];
    let omega = 50.0 * E / T;
    let contact = ShellContact::new(&model, &plate(), tools, ContactFaces::Bottom, omega).unwrap();
    let q = increment(&model, 1e-3, 0.02);
    let rep = contact.report(&model, &q, 0.0).unwrap();
    let mut f = vec![0.0; q.len()];
    contact.force_tracked(&model, &q, 0.0, &mut f).unwrap();
    let sum: V3 = (0..model.n_particles())
        .map(|i| V3::new(f[5 * i], f[5 * i + 1], f[5 * i + 2]))
        .sum();
    let tool = V3::from(rep.tools[0].force);
    println!("tool force {tool:?}, Σ particle forces {sum:?}");
    assert!(tool.norm() > 0.0);
    // Round-off of sums of ~100 terms of the size of the total: 1e-13 relative.
    assert!((tool + sum).norm() <= 1e-13 * tool.norm());
    for s in rep.slaves.iter().filter(|s| s.pressure > 0.0) {
        assert_eq!(s.pressure, -omega * s.gap.unwrap());
        assert_eq!(rep.pressure[s.point][1], s.pressure);
    }
}

#[test]
fn invalid_input_and_path_errors_are_typed() {
    let model = plate_model(4);
    let die = || {
        RigidTool::new(
            "die",
            Surface::Rectangle(
                Rectangle::new(V3::new(-1.0, -1.0, -T / 2.0), 3.0 * V3::x(), 3.0 * V3::y())
                    .unwrap(),
            ),
            Side::Positive,
            ToolPath::fixed(),
        )
        .unwrap()
    };
    for bad in [0.0, -1.0, f64::NAN] {
        let e = ShellContact::new(&model, &plate(), vec![die()], ContactFaces::Bottom, bad)
            .unwrap_err();
        assert!(
            matches!(&e, ContactError::InvalidInput { field, .. } if field == "penalty"),
            "{e}"
        );
    }
    let e = ShellContact::new(&model, &plate(), vec![], ContactFaces::Bottom, 1.0).unwrap_err();
    assert!(matches!(&e, ContactError::InvalidInput { field, .. } if field == "tools"));
    let e = ShellContact::new(
        &model,
        &plate(),
        vec![die(), die()],
        ContactFaces::Bottom,
        1.0,
    )
    .unwrap_err();
    assert!(matches!(&e, ContactError::InvalidInput { field, .. } if field == "tools[1].name"));

    // A flat punch above the plate (solid above: Side::Negative) that jumps from 0.5 t above
    // the top face to 3 t below it between t = 0.5 and t = 0.6.
    let punch_path = ToolPath::new(
        [0.0; 3],
        vec![
            PathKey {
                t: 0.5,
                translation: [0.0; 3],
                rotation: [0.0; 3],
            },
            PathKey {
                t: 0.6,
                translation: [0.0, 0.0, -3.5 * T],
                rotation: [0.0; 3],
            },
        ],
    )
    .unwrap();
    let punch = RigidTool::new(
        "punch",
        Surface::Rectangle(
            Rectangle::new(V3::new(-1.0, -1.0, T), 3.0 * V3::x(), 3.0 * V3::y()).unwrap(),
        ),
        Side::Negative,
        punch_path,
    )
    .unwrap();
    let contact = ShellContact::new(
        &model,
        &plate(),
        vec![punch],
        ContactFaces::Top,
        10.0 * E / T,
    )
    .unwrap();
    let q = vec![0.0; model.n_dofs()];
    let mut f = vec![0.0; q.len()];
    contact.force_tracked(&model, &q, 0.5, &mut f).unwrap();
    assert!(f.iter().all(|v| *v == 0.0), "no contact at t = 0.5");
    assert!(matches!(
        contact.check_engaged(),
        Err(ContactError::ToolsNeverTouched { tools }) if tools == ["punch"]
    ));
    let e: shelldsa::shell::ShellError =
        contact.force_tracked(&model, &q, 0.6, &mut f).unwrap_err();
    let msg = e.to_string();
    println!("{msg}");
    assert!(
        msg.contains("crosses the sheet") && msg.contains("punch"),
        "{msg}"
    );
    // The gaps of a failed evaluation are not recorded: a retry with a smaller step is
    // compared with the last good pseudo-time, and fails again at t = 0.6 ...
    assert!(contact.force_tracked(&model, &q, 0.6, &mut f).is_err());
    // ... but passes at t = 0.52 (the punch 0.2 t into the top face, gap > −t), where the
    // punch has touched the sheet.
    contact.force_tracked(&model, &q, 0.52, &mut f).unwrap();
    contact.check_engaged().unwrap();
    // After a reset nothing is remembered.
    contact.reset_tracking();
    assert!(contact.check_engaged().is_err());
}

fn newton(rtol: f64, initial_step: f64, predictor: Predictor) -> NewtonSolver {
    NewtonSolver {
        options: NewtonOptions {
            residual_rtol: rtol,
            ..NewtonOptions::default()
        },
        stepping: LoadStepping {
            initial_step,
            predictor,
            ..LoadStepping::default()
        },
    }
}

/// Contact patch test: a free flat plate on a flat rigid die under a uniform dead load `p` per
/// unit area (Gravity, down). In-plane rigid modes held at two points (zero reactions). The
/// exact penalty solution is a rigid translation with the uniform penetration `p/ω`: the
/// contact pressure at every slave point equals `p` (to 1e-6 relative: measured at round-off),
/// and the penetration is `p/ω`. The die overlaps the bottom face by 1e-3 t at the start so
/// that the contact (the only support in z) is active from the first iteration; the steps start
/// from the committed state (a secant predictor would extrapolate the first step's lift-off of
/// that overlap and leave the die: a singular tangent). The residual tolerance asks for the
/// round-off floor: the set-up's load scale includes the overlap force `ω · 1e-3 t`, which
/// would make a relative 1e-10 loose against `p`.
#[test]
fn patch_test_uniform_pressure_and_penalty_study() {
    let p = 1.0;
    println!("| c (ω = c E/t) | penetration | ω·penetration/p − 1 | max |pressure/p − 1| | Newton iterations |");
    println!("|---|---|---|---|---|");
    for c in [1.0, 10.0, 100.0, 1e3] {
        let model = plate_model(6);
        let omega = c * E / T;
        let die = RigidTool::new(
            "die",
            Surface::Rectangle(
                Rectangle::new(
                    V3::new(-0.5, -0.5, -T / 2.0 + 1e-3 * T),
                    2.0 * V3::x(),
                    2.0 * V3::y(),
                )
                .unwrap(),
            ),
            Side::Positive,
            ToolPath::fixed(),
        )
        .unwrap();
        let contact = Arc::new(
            ShellContact::new(&model, &plate(), vec![die], ContactFaces::Bottom, omega).unwrap(),
        );
        let holds = vec![
            LinearConstraint::displacement(&model, [0.5, 0.5], V3::x(), 0.0).unwrap(),
            LinearConstraint::displacement(&model, [0.5, 0.5], V3::y(), 0.0).unwrap(),
            LinearConstraint::displacement(&model, [1.0, 0.5], V3::y(), 0.0).unwrap(),
        ];
        let loads = vec![
            Gravity::new([0.0, 0.0, -p]).unwrap().into(),
            Load::Contact(ContactLoad {
                contact: Arc::clone(&contact),
                penalty_factor: None,
            }),
        ];
        let mut problem = ShellProblem::new(model, loads, holds).unwrap();
        contact.reset_tracking();
        let pattern = problem.pattern().clone();
        let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
        let u0 = problem.state().to_vec();
        let report = newton(1e-14, 0.5, Predictor::Zero)
            .run(&mut problem, &pattern, &mut solver, &u0)
            .unwrap();
        let its: usize = report.converged_steps().map(|r| r.iterations).sum();
        let q0 = vec![0.0; problem.n_generalised()];
        let rep = contact.report(&problem.model, &q0, 1.0).unwrap();
        let n_slaves = rep.slaves.len();
        assert_eq!(
            rep.tools[0].active_points, n_slaves,
            "every slave point in contact"
        );
        let worst = rep
            .slaves
            .iter()
            .map(|s| (s.pressure / p - 1.0).abs())
            .fold(0.0, f64::max);
        let pen = -rep.slaves[0].gap.unwrap();
        println!(
            "| {c:e} | {pen:.6e} | {:+.2e} | {worst:.2e} | {its} |",
            pen * omega / p - 1.0
        );
        assert!(worst < 1e-6, "c = {c}: pressure error {worst}");
        assert!(
            (pen * omega / p - 1.0).abs() < 1e-6,
            "c = {c}: penetration {pen}"
        );
        // The tool force is the applied load p·A (A = 1).
        assert!(
            (rep.tools[0].force[2] + p).abs() < 1e-6 * p,
            "{:?}",
            rep.tools[0].force
        );
        contact.check_engaged().unwrap();
    }
}

/// A rigid cylinder (R = 0.2) pressed 1.5 t into a plate clamped on u = 0 and u = 1, its axis
/// across the plate: at every converged step the force the sheet exerts on the tool equals the
/// sum of the z-reactions of the clamps to 1e-8 relative (equilibrium of the whole sheet: the
/// internal forces sum to zero, each clamp row's coefficients Σ Ψ_I = 1).
#[test]
fn cylinder_pressed_into_clamped_plate_balances_the_reactions() {
    let n: usize = std::env::var("CONTACT_PARTICLES")
        .map(|v| v.parse().unwrap())
        .unwrap_or(9);
    let model = plate_model(n);
    let stroke = 1.5 * T;
    let path = ToolPath::linear_stroke([0.0, 0.0, -stroke - 0.2 * T]).unwrap();
    // Lowest line 0.2 t above the top face at t = 0: first contact at t ≈ 0.12.
    let tool = cylinder_punch(0.2, 0.5, T / 2.0 + 0.2 * T, path);
    // Penalty study: CONTACT_PENALTY_FACTOR=c runs with ω = c E/t (default: the library's).
    let omega = std::env::var("CONTACT_PENALTY_FACTOR")
        .map(|v| v.parse::<f64>().unwrap() * E / T)
        .unwrap_or_else(|_| ShellContact::default_penalty(&model));
    let contact = Arc::new(
        ShellContact::new(&model, &plate(), vec![tool], ContactFaces::Top, omega).unwrap(),
    );
    let mut clamps = edge_constraints(&model, Edge::UMin, &EdgeCondition::Clamped).unwrap();
    clamps.extend(edge_constraints(&model, Edge::UMax, &EdgeCondition::Clamped).unwrap());
    let loads = vec![Load::Contact(ContactLoad {
        contact: Arc::clone(&contact),
        penalty_factor: None,
    })];
    let mut problem = ShellProblem::new(model, loads, clamps).unwrap();
    contact.reset_tracking();
    let pattern = problem.pattern().clone();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    let n_steps = 10;
    println!("| t | tool force z | Σ R_z | relative difference | active points | iterations |");
    println!("|---|---|---|---|---|---|");
    let mut max_force: f64 = 0.0;
    for s in 0..n_steps {
        let (a, b) = (s as f64 / n_steps as f64, (s + 1) as f64 / n_steps as f64);
        let mut nw = newton(1e-12, b - a, Predictor::Secant);
        nw.stepping.start = a;
        nw.stepping.end = b;
        let u0 = problem.state().to_vec();
        let rep = nw
            .run(&mut problem, &pattern, &mut solver, &u0)
            .unwrap_or_else(|e| panic!("step to t = {b}: {e}"));
        let its: Vec<usize> = rep.converged_steps().map(|r| r.iterations).collect();
        let q0 = vec![0.0; problem.n_generalised()];
        let cr = contact.report(&problem.model, &q0, b).unwrap();
        let rz: f64 = problem
            .constraints()
            .iter()
            .zip(problem.reactions())
            .filter(|(c, _)| c.label.ends_with("along (0, 0, 1)"))
            .map(|(_, r)| r)
            .sum();
        let fz = cr.tools[0].force[2];
        max_force = max_force.max(fz.abs());
        let rel = (fz - rz).abs() / fz.abs().max(1e-300);
        println!(
            "| {b:.1} | {fz:.10e} | {rz:.10e} | {rel:.2e} | {} | {its:?} |",
            cr.tools[0].active_points
        );
        if cr.tools[0].active_points > 0 {
            assert!(rel < 1e-8, "t = {b}: tool {fz} vs reactions {rz}");
        } else {
            assert!(
                rz.abs() < 1e-8 * max_force.max(1e-12),
                "t = {b}: Σ R_z = {rz} without contact"
            );
        }
    }
    assert!(max_force > 0.0, "the cylinder pressed the plate");
    contact.check_engaged().unwrap();
}
