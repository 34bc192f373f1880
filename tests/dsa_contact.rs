//! Design sensitivity with contact (tool-position variables; the paper's §4.2,
//! eqs 73–83) on a small punch-bending case: a quarter sheet 30 × 5 × 1 mm (13 × 3 particles,
//! elastoplastic aluminium as in `verification/cylindrical-bending/`), a cylinder punch
//! (R = 10) pushed down at x = 0, a cylinder die (R = 10) at x = 22, a constant self-weight.
//!
//! 1. The hand-derived contact-force sensitivity `ShellContact::force_dot` (eqs 78–83) against
//!    the dual-number evaluation `ShellContact::force_with` and against central differences,
//!    seed by seed (die x, die z, punch z, thickness with penalty, committed state and
//!    increment), at a deformed, plastically bent state with both tools active.
//! 2. The dual reference (`sensitivity::dual` on the problem's `Load::Contact`) for the die's
//!    horizontal and vertical position and the thickness against central differences of complete re-runs
//!    (`shelldsa dsa`'s run), and the Taylor remainder's rate.
//! 3. Tool **rotations** (`tool.<name>.<rx|ry|rz>`): `force_dot` with rotation rates against
//!    the dual evaluation and central differences of the force with the tool rotated
//!    (`ToolPath::rotated`), with pivots off the origin and paths that rotate (`R(t) ≠ I`);
//!    whole runs (continuum = dual, central differences of re-runs, Taylor rates) for the
//!    die and the punch turned about z; and `die.ry` = a translation of the die over a run.
//! 4. Tool **shapes** (`tool.<name>.shape.<parameter>`): `force_dot` with the rate of a tool
//!    surface's design parameter (cylinder radius and axis point; the die as a NURBS patch of
//!    the same cylinder: control-point coordinates and a weight) against the dual evaluation on
//!    the seeded surface and central differences; whole runs for the radii of both tools and
//!    a NURBS control point and weight of the die (continuum = dual, re-runs on the rebuilt
//!    tool, Taylor rates); the variables' parsing and errors.
//!
//! Run: `cargo test --release --test dsa_contact -- --nocapture`.

#[path = "common/small_bending.rs"]
mod small_bending;
use nalgebra::Vector3;
use num_dual::Dual64;
use shelldsa::contact::{PathKey, RigidTool, ToolPath};
use shelldsa::geometry::Surface;
use shelldsa::io::dsa_case::DsaMethod;
use shelldsa::io::dsa_output;
use shelldsa::io::dsa_study::{self, base_design, CaseAnalysis};
use shelldsa::io::shell_build;
use shelldsa::io::shell_case::{parse_shell_case, ShellCase};
use shelldsa::sensitivity::study;
use shelldsa::shell::contact::{ContactFaces, ContactInputs, ShellContact};
use shelldsa::shell::contact_sensitivity::ContactSeeds;
use shelldsa::shell::contact_sensitivity::ToolRate;
use shelldsa::shell::model::ShellModel;
use shelldsa::shell::point::ParticleState;
use shelldsa::solver::{LinearSolver, Method, SolverOptions};
use small_bending::{
    assert_taylor_rates, case, max_abs, max_diff, run_case, zero_state, Lcg, CASE,
};
use std::path::Path;
use std::sync::Arc;

/// The model bent to 3 mm of stroke (t = 0.5) and its contact.
fn bent_state() -> (ShellModel, Arc<ShellContact>) {
    let c = case(0.5, "");
    let mut b = shell_build::build(&c).unwrap();
    let pattern = b.problem.pattern().clone();
    let mut linear =
        LinearSolver::new(&pattern, Method::auto(&pattern), SolverOptions::default()).unwrap();
    let u0 = b.problem.state().to_vec();
    b.newton
        .run(&mut b.problem, &pattern, &mut linear, &u0)
        .unwrap();
    (b.problem.model.clone(), b.contact.unwrap())
}

/// Input derivatives of one test seed.
struct Seed {
    name: &'static str,
    tools: Vec<ToolRate>,
    thickness: f64,
    penalty: f64,
    particles: Vec<ParticleState<f64>>,
    increment: Vec<f64>,
}

impl Seed {
    /// No input moves (`np` particles, `n` generalised DOFs, the two tools).
    fn none(np: usize, n: usize) -> Self {
        Seed {
            name: "none",
            tools: vec![ToolRate::default(); 2],
            thickness: 0.0,
            penalty: 0.0,
            particles: vec![zero_state(); np],
            increment: vec![0.0; n],
        }
    }

    /// Only the tools move, at `tools`.
    fn tools(name: &'static str, tools: Vec<ToolRate>, np: usize, n: usize) -> Self {
        Seed {
            name,
            tools,
            ..Seed::none(np, n)
        }
    }
}

/// The kernel tests' evaluation point: a random increment from the bent state's committed
/// state (translations ≤ 0.02 mm, rotations ≤ 0.02 rad) at t = 0.505 (the punch 0.03 mm further
/// down than at the commit).
fn kernel_point(n: usize, rng: &mut Lcg) -> (Vec<f64>, f64) {
    ((0..n).map(|_| rng.next() * 0.02).collect(), 0.505)
}

/// `x + s ẋ` for every input.
fn shifted(model: &ShellModel, seed: &Seed, s: f64) -> Vec<ParticleState<f64>> {
    model
        .particles
        .iter()
        .zip(&seed.particles)
        .map(|(p, d)| ParticleState {
            u: p.u + d.u * s,
            d: p.d + d.d * s,
            d0: p.d0 + d.d0 * s,
            e: [p.e[0] + d.e[0] * s, p.e[1] + d.e[1] * s],
        })
        .collect()
}

/// The contact's inputs with every input shifted by `s` times the seed, in f64, and the
/// shifted increment, handed to `f`.
fn with_inputs_f64<R>(
    model: &ShellModel,
    contact: &ShellContact,
    q: &[f64],
    seed: &Seed,
    s: f64,
    f: impl FnOnce(&ContactInputs<'_, f64>, &[f64]) -> R,
) -> R {
    let particles = shifted(model, seed, s);
    let offsets: Vec<Vector3<f64>> = seed
        .tools
        .iter()
        .map(|a| Vector3::from(a.translation) * s)
        .collect();
    let rotations: Vec<Vector3<f64>> = seed
        .tools
        .iter()
        .map(|a| Vector3::from(a.rotation) * s)
        .collect();
    // A tool-shape rate moves the surface's design parameter by s ṗ.
    let surfaces: Vec<Surface<f64>> = contact
        .tools()
        .iter()
        .zip(&seed.tools)
        .map(|(tl, rate)| {
            let mut p = tl.surface.parameter_values();
            if let Some((k, r)) = rate.shape {
                p[k] += s * r;
            }
            tl.surface.with_design_parameters::<f64>(&p).unwrap()
        })
        .collect();
    let inputs = ContactInputs {
        particles: &particles,
        thickness: model.thickness + s * seed.thickness,
        penalty: contact.penalty() + s * seed.penalty,
        offsets: &offsets,
        rotations: &rotations,
        surfaces: Some(&surfaces),
        initial: None,
    };
    let qs: Vec<f64> = q
        .iter()
        .zip(&seed.increment)
        .map(|(a, b)| a + s * b)
        .collect();
    f(&inputs, &qs)
}

/// The contact's inputs as `Dual64` numbers seeded by `seed`, and the seeded increment, handed
/// to `f`.
fn with_inputs_dual<R>(
    model: &ShellModel,
    contact: &ShellContact,
    q: &[f64],
    seed: &Seed,
    f: impl FnOnce(&ContactInputs<'_, Dual64>, &[Dual64]) -> R,
) -> R {
    let dv = |a: &Vector3<f64>, b: &Vector3<f64>| a.zip_map(b, Dual64::new);
    let particles: Vec<ParticleState<Dual64>> = model
        .particles
        .iter()
        .zip(&seed.particles)
        .map(|(p, d)| ParticleState {
            u: dv(&p.u, &d.u),
            d: dv(&p.d, &d.d),
            d0: dv(&p.d0, &d.d0),
            e: [dv(&p.e[0], &d.e[0]), dv(&p.e[1], &d.e[1])],
        })
        .collect();
    let seeded = |v: [f64; 3]| Vector3::from(v).map(|x| Dual64::new(0.0, x));
    let offsets: Vec<Vector3<Dual64>> = seed.tools.iter().map(|a| seeded(a.translation)).collect();
    let rotations: Vec<Vector3<Dual64>> = seed.tools.iter().map(|a| seeded(a.rotation)).collect();
    // A tool-shape rate seeds the surface's design parameter with ṗ.
    let surfaces: Vec<Surface<Dual64>> = contact
        .tools()
        .iter()
        .zip(&seed.tools)
        .map(|(tl, rate)| {
            let mut p: Vec<Dual64> = tl
                .surface
                .parameter_values()
                .iter()
                .map(|&v| Dual64::from(v))
                .collect();
            if let Some((k, r)) = rate.shape {
                p[k].eps = r;
            }
            tl.surface.with_design_parameters::<Dual64>(&p).unwrap()
        })
        .collect();
    let inputs = ContactInputs {
        particles: &particles,
        thickness: Dual64::new(model.thickness, seed.thickness),
        penalty: Dual64::new(contact.penalty(), seed.penalty),
        offsets: &offsets,
        rotations: &rotations,
        surfaces: Some(&surfaces),
        initial: None,
    };
    let qd: Vec<Dual64> = q
        .iter()
        .zip(&seed.increment)
        .map(|(a, b)| Dual64::new(*a, *b))
        .collect();
    f(&inputs, &qd)
}

fn force_f64(
    model: &ShellModel,
    contact: &ShellContact,
    q: &[f64],
    t: f64,
    seed: &Seed,
    s: f64,
) -> Vec<f64> {
    with_inputs_f64(model, contact, q, seed, s, |inputs, qs| {
        let mut f = vec![0.0; q.len()];
        contact.force_with(model, inputs, qs, t, &mut f).unwrap();
        f
    })
}

fn force_dual(
    model: &ShellModel,
    contact: &ShellContact,
    q: &[f64],
    t: f64,
    seed: &Seed,
) -> Vec<f64> {
    with_inputs_dual(model, contact, q, seed, |inputs, qd| {
        let mut f = vec![Dual64::from(0.0); q.len()];
        contact.force_with(model, inputs, qd, t, &mut f).unwrap();
        f.iter().map(|v| v.eps).collect()
    })
}

/// A translation rate `ȧ`.
fn translation(a: [f64; 3]) -> ToolRate {
    ToolRate {
        translation: a,
        ..Default::default()
    }
}

/// A rotation rate `φ̇`.
fn rotation(phi: [f64; 3]) -> ToolRate {
    ToolRate {
        rotation: phi,
        ..Default::default()
    }
}

#[test]
fn hand_derived_contact_force_sensitivity_matches_dual_and_central_differences() {
    let (model, contact) = bent_state();
    let n = model.n_dofs();
    let np = model.particles.len();
    let mut rng = Lcg(0x5eed_c0de);
    let (q, t) = kernel_point(n, &mut rng);
    let report = contact.report(&model, &q, t).unwrap();
    let active: Vec<usize> = report.tools.iter().map(|r| r.active_points).collect();
    let off_tool = report.slaves.iter().filter(|s| s.tool.is_none()).count();
    println!(
        "active points per tool {active:?}, slave points without an interior projection \
         {off_tool} of {}",
        report.slaves.len()
    );
    // Both tools carry force. (Both cylinders span every slave point's projection here, so no
    // point projects onto a tool boundary: that branch carries no force in either method.)
    assert!(active.iter().all(|&a| a > 0), "active points {active:?}");

    let state_dots: Vec<ParticleState<f64>> = (0..np)
        .map(|_| ParticleState {
            u: rng.v3(0.1),
            d: rng.v3(0.01),
            d0: rng.v3(0.01),
            e: [rng.v3(0.01), rng.v3(0.01)],
        })
        .collect();
    let inc_dot: Vec<f64> = (0..n).map(|_| rng.next() * 0.05).collect();
    let seeds = vec![
        Seed::tools(
            "die x",
            vec![ToolRate::default(), translation([1.0, 0.0, 0.0])],
            np,
            n,
        ),
        Seed::tools(
            "die z",
            vec![ToolRate::default(), translation([0.0, 0.0, 1.0])],
            np,
            n,
        ),
        Seed::tools(
            "punch z",
            vec![translation([0.0, 0.0, 1.0]), ToolRate::default()],
            np,
            n,
        ),
        Seed {
            name: "thickness, penalty",
            thickness: 1.0,
            penalty: -1000.0, // ω = c E/t: ω̇ = −ω/t
            ..Seed::none(np, n)
        },
        Seed {
            name: "state, increment",
            particles: state_dots,
            increment: inc_dot,
            ..Seed::none(np, n)
        },
    ];
    for seed in &seeds {
        let h = 1e-6;
        let rates = ContactRates::new(&model, &contact, &q, t, seed, h);
        let (scale, e_dual, e_cd) = rates.force;
        println!(
            "{:<20} max|ḟ| {scale:.4e}  |hand − dual| {e_dual:.2e}  |hand − central| {e_cd:.2e}",
            seed.name
        );
        // Central differences with h = 1e-6 (inputs of size 1…30 mm): truncation ~h²·|f'''|
        // ≲ 1e-11 and round-off ~ε|f|/h ≈ 1e-10 of the force; 1e-7 leaves room for the
        // curvature of the cylinder (R = 10) along a slave point's path.
        assert_three_way(seed.name, "force", rates.force);

        // The forces on the tools (the punch force): the same three ways.
        let (scale, e_dual, e_cd) = rates.tool_forces;
        println!(
            "{:<20} tool forces: max|Ḟ| {scale:.4e}  |hand − dual| {e_dual:.2e}  \
             |hand − central| {e_cd:.2e}",
            seed.name
        );
        // Sums of the same per-point terms as above (no shape-function weights): the same
        // round-off and truncation bounds, relative to the largest tool-force rate.
        assert_three_way(seed.name, "tool forces", rates.tool_forces);
    }
    // The generic tool forces in f64 are the contact report's.
    let none = Seed::none(np, n);
    let generic = tool_forces_f64(&model, &contact, &q, t, &none, 0.0);
    let reported: Vec<f64> = report.tools.iter().flat_map(|r| r.force).collect();
    // The same sum in the same order: bit-identical up to the order of one addition.
    assert!(max_diff(&generic, &reported) <= 1e-12 * max_abs(&reported));
}

/// The largest dual value and the hand-derived derivative's largest differences from the
/// dual one and from the central difference `(f(+h) − f(−h))/2h`, relative to it.
fn three_way(hand: &[f64], dual: &[f64], fp: &[f64], fm: &[f64], h: f64) -> (f64, f64, f64) {
    let cd: Vec<f64> = fp
        .iter()
        .zip(fm)
        .map(|(a, b)| (a - b) / (2.0 * h))
        .collect();
    let scale = max_abs(dual);
    (
        scale,
        max_diff(hand, dual) / scale,
        max_diff(hand, &cd) / scale,
    )
}

/// The bounds every contact kernel seed meets, on `(max rate, |hand − dual|, |hand − central|)`
/// ([`three_way`]) of quantity `what`: the seed moves it; hand = dual to 1e-10 of the largest
/// rate (the same formulas two ways, dual numbers through the projection's Newton correction
/// and the hand-derived chain: round-off of sums of terms of size ~max rate, the penalty
/// ω = 1000 amplifying gaps of ~1e-3 mm); hand = central differences to 1e-7 (truncation and
/// round-off of the calling test's step, justified there).
fn assert_three_way(name: &str, what: &str, (scale, e_dual, e_cd): (f64, f64, f64)) {
    assert!(scale > 0.0, "{name}: the seed must move the {what}");
    assert!(e_dual < 1e-10, "{name}: {what} hand vs dual {e_dual:e}");
    assert!(
        e_cd < 1e-7,
        "{name}: {what} hand vs central differences {e_cd:e}"
    );
}

/// The contact force rate and the tool-force rates of `seed` at `(q, t)` three ways
/// ([`three_way`] with the central step `h`): hand-derived (`ShellContact::force_dot`,
/// `tool_force_dots`), dual, and central differences of the f64 evaluations.
struct ContactRates {
    /// `(max|ḟ|, |hand − dual|, |hand − central|)` of the generalised contact force.
    force: (f64, f64, f64),
    /// The same for the forces on the tools.
    tool_forces: (f64, f64, f64),
    /// The force at `+h`.
    force_plus: Vec<f64>,
}

impl ContactRates {
    fn new(
        model: &ShellModel,
        contact: &ShellContact,
        q: &[f64],
        t: f64,
        seed: &Seed,
        h: f64,
    ) -> Self {
        let cs = ContactSeeds {
            tools: &seed.tools,
            thickness: seed.thickness,
            penalty: seed.penalty,
            particles: &seed.particles,
            increment: &seed.increment,
            initial: None,
        };
        let hand = contact.force_dot(model, q, t, &cs).unwrap();
        let dual = force_dual(model, contact, q, t, seed);
        let fp = force_f64(model, contact, q, t, seed, h);
        let fm = force_f64(model, contact, q, t, seed, -h);
        let force = three_way(&hand, &dual, &fp, &fm, h);
        let hand = contact
            .tool_force_dots(model, q, t, std::slice::from_ref(&cs))
            .unwrap()
            .pop()
            .unwrap();
        let hand: Vec<f64> = hand.iter().flatten().copied().collect();
        let dual = tool_forces_dual(model, contact, q, t, seed);
        let tp = tool_forces_f64(model, contact, q, t, seed, h);
        let tm = tool_forces_f64(model, contact, q, t, seed, -h);
        ContactRates {
            force,
            tool_forces: three_way(&hand, &dual, &tp, &tm, h),
            force_plus: fp,
        }
    }
}

/// The forces on the tools, flattened `[tool][component]`, with every input shifted by
/// `s` times the seed (`ShellContact::tool_forces_with` in f64).
fn tool_forces_f64(
    model: &ShellModel,
    contact: &ShellContact,
    q: &[f64],
    t: f64,
    seed: &Seed,
    s: f64,
) -> Vec<f64> {
    with_inputs_f64(model, contact, q, seed, s, |inputs, qs| {
        let f = contact.tool_forces_with(model, inputs, qs, t).unwrap();
        f.iter().flat_map(|v| [v[0], v[1], v[2]]).collect()
    })
}

/// The derivative parts of the forces on the tools evaluated with dual inputs seeded by `seed`.
fn tool_forces_dual(
    model: &ShellModel,
    contact: &ShellContact,
    q: &[f64],
    t: f64,
    seed: &Seed,
) -> Vec<f64> {
    with_inputs_dual(model, contact, q, seed, |inputs, qd| {
        let f = contact.tool_forces_with(model, inputs, qd, t).unwrap();
        f.iter()
            .flat_map(|v| [v[0].eps, v[1].eps, v[2].eps])
            .collect()
    })
}

/// The contact of `model` with `contact`'s tools on new paths (`path(i, tool)`), on both faces
/// with the same penalty.
fn with_paths(
    model: &ShellModel,
    contact: &ShellContact,
    path: impl Fn(usize, &RigidTool) -> ToolPath,
) -> ShellContact {
    let surface = case(0.5, "").surface;
    let tools: Vec<RigidTool> = contact
        .tools()
        .iter()
        .enumerate()
        .map(|(i, tl)| RigidTool {
            path: path(i, tl),
            ..tl.clone()
        })
        .collect();
    ShellContact::new(
        model,
        &surface,
        tools,
        ContactFaces::Both,
        contact.penalty(),
    )
    .unwrap()
}

/// The force with every input at `x + s ẋ`, the tools' design placements applied to their
/// paths (`ToolPath::translated`, `ToolPath::rotated`: what a finite-difference re-run
/// builds) instead of being passed as `ContactInputs` offsets.
fn force_rotated_tools(
    model: &ShellModel,
    contact: &ShellContact,
    q: &[f64],
    t: f64,
    seed: &Seed,
    s: f64,
) -> Vec<f64> {
    let moved = with_paths(model, contact, |i, tl| {
        let r = &seed.tools[i];
        tl.path
            .translated(r.translation.map(|v| v * s))
            .and_then(|p| p.rotated(r.rotation.map(|v| v * s)))
            .unwrap()
    });
    let still = Seed {
        name: seed.name,
        tools: vec![ToolRate::default(); seed.tools.len()],
        thickness: seed.thickness,
        penalty: seed.penalty,
        particles: seed.particles.clone(),
        increment: seed.increment.clone(),
    };
    force_f64(model, &moved, q, t, &still, s)
}

/// Tool rotations (`tool.<name>.<rx|ry|rz>`): `force_dot` with rotation rates `φ̇` (module
/// documentation of `shell::contact_sensitivity`: `V^c = ȧ + Ω (x^c − p)`, eq 80's `g n·(Ω x^c,α)`,
/// `ṅ = Ω n + n,β ξ̇_β`) against the `Dual64` evaluation of `force_with` (the dual `R(φ)`
/// composed into the motion) and central differences of the force with the tools rotated as a
/// re-run rotates them. Both tools have pivots off the origin on their axes and paths that
/// rotate about their axes (`R(t) ≠ I`; the cylinders map onto themselves, so the contact
/// state is the bent one), the punch's pivot moving with its stroke (`p = c + a(t)`).
#[test]
fn tool_rotation_sensitivity_matches_dual_and_central_differences() {
    let (model, base) = bent_state();
    let n = model.n_dofs();
    let np = model.particles.len();
    // Punch axis through (0, y, 10.51), die axis through (22, y, −10.49), both along y.
    let contact = with_paths(&model, &base, |i, _| {
        let (pivot, a1, th1) = if i == 0 {
            ([0.0, 2.5, 10.51], [0.0, 0.0, -6.0], [0.0, -0.2, 0.0])
        } else {
            ([22.0, 2.5, -10.49], [0.0; 3], [0.0, 0.3, 0.0])
        };
        let key = |t: f64, translation, rotation| PathKey {
            t,
            translation,
            rotation,
        };
        ToolPath::new(pivot, vec![key(0.0, [0.0; 3], [0.0; 3]), key(1.0, a1, th1)]).unwrap()
    });
    let (q, t) = kernel_point(n, &mut Lcg(0x0dd_ba11));
    // The rotating paths give the bent case's geometry (each cylinder turned about its own
    // axis): the same force to round-off of positions ~30 mm (ε·30·ω·w ≪ 1e-9 max|f|).
    let zero = Seed::none(np, n);
    let f_base = force_f64(&model, &base, &q, t, &zero, 0.0);
    let f_rot = force_f64(&model, &contact, &q, t, &zero, 0.0);
    let e_geom = max_diff(&f_base, &f_rot) / max_abs(&f_base);
    println!(
        "force with rotating paths vs fixed: {e_geom:.2e} of max|f| {:.3e}",
        max_abs(&f_base)
    );
    assert!(
        e_geom < 1e-9,
        "rotating paths change the force by {e_geom:e}"
    );
    let report = contact.report(&model, &q, t).unwrap();
    let active: Vec<usize> = report.tools.iter().map(|r| r.active_points).collect();
    assert!(active.iter().all(|&a| a > 0), "active points {active:?}");
    for tl in contact.tools() {
        assert!(
            (tl.path.path_rotation(t) - nalgebra::Matrix3::identity()).norm() > 0.05,
            "R(t) = I for `{}`",
            tl.name
        );
    }

    let none = ToolRate::default();
    let seed = |name, tools| Seed::tools(name, tools, np, n);
    let seeds = vec![
        seed("die rx", vec![none, rotation([1.0, 0.0, 0.0])]),
        seed("die rz", vec![none, rotation([0.0, 0.0, 1.0])]),
        seed("punch rx", vec![rotation([1.0, 0.0, 0.0]), none]),
        seed("punch rz", vec![rotation([0.0, 0.0, 1.0]), none]),
        seed(
            "both, mixed",
            vec![
                ToolRate {
                    translation: [0.1, -0.2, 0.3],
                    rotation: [0.4, 0.1, -0.3],
                    shape: None,
                },
                ToolRate {
                    translation: [0.3, 0.0, -0.2],
                    rotation: [0.2, -0.5, 0.7],
                    shape: None,
                },
            ],
        ),
    ];
    let mut scale_rx = 0.0;
    for seed in &seeds {
        let cs = ContactSeeds {
            tools: &seed.tools,
            thickness: 0.0,
            penalty: 0.0,
            particles: &seed.particles,
            increment: &seed.increment,
            initial: None,
        };
        let hand = contact.force_dot(&model, &q, t, &cs).unwrap();
        let dual = force_dual(&model, &contact, &q, t, seed);
        // h = 1e-6 rad moves tool points ≤ 30 mm away from the pivot by ≤ 3e-5 mm.
        let h = 1e-6;
        let fp = force_rotated_tools(&model, &contact, &q, t, seed, h);
        let fm = force_rotated_tools(&model, &contact, &q, t, seed, -h);
        // The re-run's rotated path and the dual's composition R(θ(t)) R(φ) are the same
        // motion: the forces agree to round-off (1e-12 of max|f|).
        let fi = force_f64(&model, &contact, &q, t, seed, h);
        let e_repr = max_diff(&fp, &fi) / max_abs(&fi);
        let rates = three_way(&hand, &dual, &fp, &fm, h);
        let (scale, e_dual, e_cd) = rates;
        println!(
            "{:<12} max|ḟ| {scale:.4e}  |hand − dual| {e_dual:.2e}  |hand − central| {e_cd:.2e}  \
             rotated path vs inputs {e_repr:.1e}",
            seed.name
        );
        if seed.name == "die rx" {
            scale_rx = scale;
        }
        assert!(
            e_repr < 1e-12,
            "{}: rotated path vs inputs {e_repr:e}",
            seed.name
        );
        // Central differences: truncation ~h²|f'''| and round-off ~ε|f|/h ≈ 1e-10 of the
        // force, as for the translations.
        assert_three_way(seed.name, "force", rates);
    }
    // A rotation about a tool's own axis (pivot on it, R(t) keeps it along y) maps the cylinder
    // onto itself: the tool point slides along the surface (V^c tangential, ġ = 0) and the
    // normal's turn Ω n is cancelled by its slide n,β ξ̇_β, so ḟ = 0. Independent of the dual:
    // it checks the eq-80 term g n·(Ω x^c,α) and the pivot p = c + a(t) of the moving punch.
    // Round-off of the cancelling terms, ~1e-15 of the punch-lever terms, allows 1e-12 of
    // max|ḟ| of a genuine tilt.
    for (name, tools) in [
        ("die ry", vec![none, rotation([0.0, 1.0, 0.0])]),
        ("punch ry", vec![rotation([0.0, 1.0, 0.0]), none]),
    ] {
        let particles = vec![zero_state(); np];
        let increment = vec![0.0; n];
        let cs = ContactSeeds {
            tools: &tools,
            thickness: 0.0,
            penalty: 0.0,
            particles: &particles,
            increment: &increment,
            initial: None,
        };
        let hand = contact.force_dot(&model, &q, t, &cs).unwrap();
        let e = max_abs(&hand) / scale_rx;
        println!(
            "{name:<12} max|ḟ| {:.2e} = {e:.1e} of die rx's",
            max_abs(&hand)
        );
        assert!(
            e < 1e-12,
            "{name}: a rotation about the axis gives ḟ = {e:e}"
        );
    }
}

/// One variable's results of the `shelldsa dsa` run: dual against central differences at the
/// smallest step, and the Taylor rates.
/// The continuum (hand-derived, with `ShellContact::force_dot` for `b'_N`) derivative equals the
/// dual one: the three-way check asks 1e-8 relative on every component with |ψ'| ≥ 1e-6 max|ψ'| (both solve
/// eq 65 with the same tangent; their right-hand sides differ by round-off).
fn continuum_matches_dual(var: &study::VariableResult) {
    let name = &var.entry.variable.name;
    let (c, d) = (var.continuum.as_ref().unwrap(), var.dual.as_ref().unwrap());
    let big = d.iter().flatten().fold(0.0f64, |a, x| a.max(x.abs()));
    let mut worst = 0.0f64;
    for (x, y) in c.iter().flatten().zip(d.iter().flatten()) {
        if y.abs() >= 1e-6 * big {
            worst = worst.max((x / y - 1.0).abs());
        }
    }
    println!("`{name}`: continuum vs dual {worst:.2e}");
    assert!(worst <= 1e-8, "`{name}`: continuum vs dual {worst:e}");
}

fn check_variable(r: &study::DsaResult, v: usize) {
    let var = &r.variables[v];
    let name = &var.entry.variable.name;
    continuum_matches_dual(var);
    println!(
        "{}",
        dsa_output::table(r, v)
            .lines()
            .filter(|l| !l.starts_with(' '))
            .collect::<Vec<_>>()
            .join("\n")
    );
    let last = var.fd.last().unwrap();
    let unflagged = last.flagged.iter().filter(|f| !**f).count();
    // The first steps keep their active set (contact and yield status) within the smallest
    // ±h. Measured: the first flagged step is 9 or 10 of 27 for every h from 4e-3 down to 5e-4
    // (a status at the nominal design that flips on one side); flagged steps are reported and
    // left out, the comparison below covers the others.
    assert!(
        unflagged >= 5,
        "{name}: {unflagged} of {} steps unflagged",
        last.flagged.len()
    );
    // The step-size study's best h: where truncation (falling as h²) meets the re-runs'
    // noise (growing as 1/h). Measured on the cylinder dies, truncation-bound down to the
    // smallest h: 1.6e-5, 4.1e-6, 1.0e-6, 2.6e-7 for die x at h = 4, 2, 1, 0.5 ·1e-3 (die z
    // ≤ 2.9e-7, t ≤ 5.5e-6, radii 1.2e-8). On the NURBS die's control point the re-runs'
    // noise (independent of the Newton tolerance: the same at residual_rtol 1e-12, and the
    // Taylor rates are 2.00 ± 0.05 at every step) sets in from h = 2e-3: 3.8e-6, 2.2e-6,
    // 6.6e-6, 1.8e-5 with the normalised director field, 3.3e-6, 1.7e-6, 4.3e-6, 5.2e-6 with
    // the interpolated one. 1e-5 at the best h leaves a factor ≥ 4 and still fails a wrong
    // derivative term.
    let e = var
        .fd
        .iter()
        .filter_map(|c| study::max_rel_diff(var, c))
        .fold(f64::INFINITY, f64::min);
    assert!(e < 1e-5, "{name}: dual vs FD {e:e} at the best step size");
    // The Taylor remainder of the dual derivative falls as h² (the derivative of the discrete
    // response) at every step with at least three unflagged step sizes.
    let fitted = assert_taylor_rates(var, name);
    assert!(fitted >= 5, "{name}: {fitted} steps fitted");
}

/// Tool position and thickness variables on the small bending case, three ways, for the
/// displacements and the other responses: the forces on the tools
/// (`dsa.monitors = ["tool.<name>.<fx|fy|fz>"]`, the punch force; continuum through
/// `ShellContact::tool_force_dots` with the carried sensitivities at every converged state,
/// dual through the tool forces on the dual state), a chord angle (`[[dsa.angle]]`), a smooth
/// maximum of the equivalent plastic strain (`[[dsa.plastic]]`), a smooth maximum of the
/// thinning strain (`[[dsa.thinning]]`) and the mean squared distance of points from targets
/// (`[[dsa.distance]]`).
#[test]
fn dual_tool_position_and_thickness_derivatives_match_re_runs() {
    let design = r#"
[[design]]
name = "die.x"
kind = "tool.die.x"
fd_steps = [4e-3, 2e-3, 1e-3, 5e-4]
[[design]]
name = "die.z"
kind = "tool.die.z"
fd_steps = [4e-3, 2e-3, 1e-3, 5e-4]
[[design]]
name = "t"
kind = "thickness"
fd_steps = [4e-3, 2e-3, 1e-3, 5e-4]
[dsa]
monitors = ["center.uz", "edge.ux", "edge.uz", "tool.punch.fz", "tool.die.fx", "tool.die.fz"]
[[dsa.angle]]
name = "arm angle"
from = [0.5, 0.0]
to = [1.0, 0.5]
plane = ["x", "z"]
[[dsa.distance]]
name = "from target"
at = [[0.0, 0.0], [0.5, 0.5], [1.0, 1.0]]
target = [[0.0, 0.0, -3.0], [15.0, 2.5, -1.0], [30.0, 5.0, 1.0]]
[[dsa.plastic]]
name = "peak strain"
region = [[0.0, 0.3], [0.0, 1.0]]
layers = "top"
rho = 300.0
[[dsa.thinning]]
name = "peak thinning"
region = [[0.0, 0.3], [0.0, 1.0]]
rho = 1e5
"#;
    let c = case(0.5, design);
    let spec = dsa_study::validate(&c, &c.dsa.as_ref().unwrap().methods).unwrap();
    let t0 = std::time::Instant::now();
    let r = run_case(&c, &spec);
    println!(
        "{} steps; analysis {:.2} s, dual reference {:.2} s, fd {:.2} s (total {:.1} s); \
         dual state mismatch {:.1e}, dual value difference {:.1e}",
        r.nominal.loads.len(),
        r.time_analysis,
        r.time_dual.unwrap(),
        r.time_fd.unwrap(),
        t0.elapsed().as_secs_f64(),
        r.dual_state_mismatch.unwrap(),
        r.dual_value_difference.unwrap()
    );
    // The dual state's value parts follow the analysis to round-off.
    assert!(r.dual_state_mismatch.unwrap() < 1e-10);
    for v in 0..r.variables.len() {
        check_variable(&r, v);
    }
    // The die's horizontal position moves the sheet: non-zero derivatives.
    let d = r.variables[0].dual.as_ref().unwrap();
    assert!(d.last().unwrap().iter().any(|x| x.abs() > 1e-3));
    // The responses besides the displacements are evaluated at every step (values and both
    // methods' derivatives, checked above with the displacements).
    let labels: Vec<&str> = r.spec.monitors.iter().map(|m| m.label.as_str()).collect();
    assert_eq!(
        labels[3..],
        [
            "tool.punch.fz",
            "tool.die.fx",
            "tool.die.fz",
            "arm angle",
            "peak strain",
            "peak thinning",
            "from target"
        ]
    );
    // The punch pushes down on the sheet, so the sheet pushes the punch up: fz > 0 at the end.
    let (first, last) = (&r.nominal.values[0], r.nominal.values.last().unwrap());
    assert!(last[3] > 0.0 && last[5] < 0.0, "tool forces {last:?}");
    // The arm rises as the centre goes down: a positive chord angle (degrees) at the end;
    // flat at the start the chord from (15, 0, 0) to (30, 2.5, 0) has angle 0.
    assert!(last[6] > 1.0, "arm angle {}", last[6]);
    // The sheet yields under the punch: a smooth maximum of ē^p above zero at the end, zero
    // while it is elastic.
    assert!(
        first[7] == 0.0 && last[7] > 1e-4,
        "peak strain {first:?} {last:?}"
    );
    // The bent sheet is stretched under the punch: the smooth maximum of the thinning strain
    // ln(da/dA) is above its first-step value (the flat sheet under self-weight, where the
    // area changes by round-off of the sag's square, ~1e-9) by orders of magnitude at the end.
    assert!(
        first[8].abs() < 1e-6 && last[8] > 1e-5,
        "peak thinning {first:?} {last:?}"
    );
    // Its derivatives are ~1e-6 of the displacements', below the cut of the all-component
    // comparisons above: compared on their own scale, per variable.
    for var in &r.variables {
        let name = &var.entry.variable.name;
        let (cont, dual) = (var.continuum.as_ref().unwrap(), var.dual.as_ref().unwrap());
        let col = |d: &Vec<Vec<f64>>| d.iter().map(|s| s[8]).collect::<Vec<f64>>();
        let (c, d) = (col(cont), col(dual));
        let scale = d.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(scale > 0.0, "{name}: thinning derivative identically zero");
        // Both methods push the same carried displacement sensitivities through one generic
        // formula: round-off of the sensitivities (1e-12 relative above) is the bound.
        let e_cd = c
            .iter()
            .zip(&d)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()))
            / scale;
        assert!(e_cd < 1e-9, "{name}: thinning continuum vs dual {e_cd:e}");
        // Central differences at the smallest h on the unflagged steps, on the component's
        // own scale: measured 2.7e-9 (die x), 1.7e-8 (die z), 1.1e-8 (t); 1e-6 leaves a factor
        // ~60 for the truncation, and a wrong derivative (a missing image map, a wrong
        // gradient) is off by O(1).
        let fd = var.fd.last().unwrap();
        let e_fd = fd
            .derivatives
            .iter()
            .zip(&fd.flagged)
            .zip(&d)
            .filter(|((_, f), _)| !**f)
            .fold(0.0f64, |m, ((row, _), b)| m.max((row[8] - b).abs()))
            / scale;
        println!("`{name}`: thinning continuum vs dual {e_cd:.1e}, FD vs dual {e_fd:.1e}");
        assert!(e_fd < 1e-6, "{name}: thinning FD vs dual {e_fd:e}");
    }
    // The initial mean squared distance of the three points from their targets is
    // (9 + 1 + 1)/3; the bent sheet moves the centre towards its target z = −3.
    assert!(
        first[9] < 11.0 / 3.0 && last[9] < first[9],
        "distance {first:?} {last:?}"
    );
}

/// Whole runs for tool rotations: the die and the punch turn about their own axes along the
/// stroke (pivots on the axes at mid-width, the punch's moving with it; `R(t) ≠ I`, and
/// `R(t) e_z ≠ e_z`, while the geometry is the base case's) and are turned as built about the
/// vertical through their pivots (`tool.<name>.rz`: the contact line turns in plan). The
/// continuum derivative (hand-derived `b'_N` with the rotation terms) equals the dual one;
/// both match central differences of complete re-runs with the tool rotated
/// (`ToolPath::rotated`), whose Taylor remainder falls as h².
///
/// (A tilt about x, `tool.die.rx`, is not used here: it raises one end of the die's contact
/// line, on which the sheet rests under its self-weight with a penetration of ~1e-8 mm, so
/// the sheet rocks and the contact set changes within ±h from the first step: every step is
/// flagged. Its force derivative is checked in the test above.)
#[test]
fn tool_rotation_derivatives_match_dual_and_re_runs() {
    let design = r#"
[[design]]
name = "die.rz"
kind = "tool.die.rz"
fd_steps = [1.6e-3, 8e-4, 4e-4, 2e-4]
[[design]]
name = "punch.rz"
kind = "tool.punch.rz"
fd_steps = [1.6e-3, 8e-4, 4e-4, 2e-4]
[dsa]
monitors = ["center.uz", "edge.ux", "edge.uz"]
"#;
    let die_path = "keys = [{ t = 0.0, translation = [0.0, 0.0, 0.0] }]";
    let punch_end = "{ t = 1.0, translation = [0.0, 0.0, -6.0] },\n]";
    let text = CASE.replace("{final}", "0.5").replace("{design}", design);
    assert_eq!(text.matches(die_path).count(), 1);
    assert_eq!(text.matches(punch_end).count(), 1);
    let text = text
        .replace(
            die_path,
            "pivot = [22.0, 2.5, -10.49]\nkeys = [\n    \
             { t = 0.0, translation = [0.0, 0.0, 0.0] },\n    \
             { t = 1.0, translation = [0.0, 0.0, 0.0], rotation = [0.0, 0.2, 0.0] },\n]",
        )
        .replace(
            punch_end,
            "{ t = 1.0, translation = [0.0, 0.0, -6.0], rotation = [0.0, -0.2, 0.0] },\n]\n\
             pivot = [0.0, 2.5, 10.51]",
        );
    let c = parse_shell_case(&text, Path::new("tests/dsa_contact.rs")).unwrap();
    let spec = dsa_study::validate(&c, &c.dsa.as_ref().unwrap().methods).unwrap();
    let t0 = std::time::Instant::now();
    let r = run_case(&c, &spec);
    println!(
        "rotations: {} steps; analysis {:.2} s, continuum {:.3} s, dual {:.2} s, fd {:.2} s \
         (total {:.1} s)",
        r.nominal.loads.len(),
        r.time_analysis,
        r.time_continuum.unwrap(),
        r.time_dual.unwrap(),
        r.time_fd.unwrap(),
        t0.elapsed().as_secs_f64(),
    );
    assert!(r.dual_state_mismatch.unwrap() < 1e-10);
    for v in 0..r.variables.len() {
        let var = &r.variables[v];
        let all: Vec<String> = var
            .fd
            .iter()
            .map(|c| format!("{:.2e}", study::max_rel_diff(var, c).unwrap_or(f64::NAN)))
            .collect();
        println!(
            "`{}`: continuum vs FD per h {all:?}",
            var.entry.variable.name
        );
        check_variable(&r, v);
        // The tilt moves the sheet.
        let d = var.continuum.as_ref().unwrap();
        assert!(
            d.last().unwrap().iter().any(|x| x.abs() > 1e-3),
            "`{}`: {:?}",
            var.entry.variable.name,
            d.last()
        );
    }
}

/// A rotation of the die about the global y axis through its pivot (the origin here) turns
/// its cylinder about a line parallel to its axis: a translation of the axis, through
/// A = (22, ·, −10.49), by `e_y × (A − c)` = (−10.49, 0, −22) per radian, plus a
/// re-parametrisation that leaves the force unchanged. So over a whole run
/// `ψ'(die.ry) = −10.49 ψ'(die.x) − 22 ψ'(die.z)`, for the continuum and the dual method:
/// both are linear in the design velocity `V^c`, so the identity holds to round-off of the
/// terms summed (1e-10 of max|ψ'(die.ry)|). Independent of finite differences.
#[test]
fn die_rotation_about_its_axis_direction_equals_a_translation_over_the_run() {
    let design = r#"
[[design]]
name = "die.x"
kind = "tool.die.x"
[[design]]
name = "die.z"
kind = "tool.die.z"
[[design]]
name = "die.ry"
kind = "tool.die.ry"
[dsa]
monitors = ["center.uz", "edge.ux", "edge.uz"]
"#;
    let c = case(0.5, design);
    let spec = dsa_study::validate(&c, &[DsaMethod::Continuum, DsaMethod::Dual]).unwrap();
    let r = run_case(&c, &spec);
    for method in ["continuum", "dual"] {
        let d = |v: &study::VariableResult| match method {
            "continuum" => v.continuum.clone(),
            _ => v.dual.clone(),
        };
        let (x, z, ry) = (
            d(&r.variables[0]).unwrap(),
            d(&r.variables[1]).unwrap(),
            d(&r.variables[2]).unwrap(),
        );
        let big = ry.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
        let worst = x
            .iter()
            .flatten()
            .zip(z.iter().flatten())
            .zip(ry.iter().flatten())
            .fold(0.0f64, |a, ((x, z), ry)| {
                a.max((ry - (-10.49 * x - 22.0 * z)).abs())
            });
        println!(
            "{method}: |ψ'(ry) − (−10.49 ψ'(x) − 22 ψ'(z))| = {:.1e} of max|ψ'(ry)| {big:.3e}",
            worst / big
        );
        assert!(big > 1e-2, "{method}: max|ψ'(die.ry)| = {big:e}");
        assert!(worst <= 1e-10 * big, "{method}: {:e}", worst / big);
    }
}

#[test]
fn tool_design_variables_are_checked() {
    use shelldsa::io::CaseError;
    use shelldsa::sensitivity::{DesignKind, DesignVariable};
    assert_eq!(
        DesignKind::parse("tool.die.z").unwrap(),
        DesignKind::Tool {
            tool: "die".into(),
            axis: 2
        }
    );
    // A tool name may contain dots: the axis is the last component.
    assert_eq!(
        DesignKind::parse("tool.a.b.x").unwrap(),
        DesignKind::Tool {
            tool: "a.b".into(),
            axis: 0
        }
    );
    // Rotations: `rx|ry|rz`, a kind of their own (translation behaviour unchanged).
    assert_eq!(
        DesignKind::parse("tool.die.ry").unwrap(),
        DesignKind::ToolRotation {
            tool: "die".into(),
            axis: 1
        }
    );
    assert_eq!(
        DesignKind::parse("tool.a.rx.rz").unwrap(),
        DesignKind::ToolRotation {
            tool: "a.rx".into(),
            axis: 2
        }
    );
    for bad in [
        "tool.die.w",
        "tool.die",
        "tool..x",
        "tool.",
        "tool.die.r",
        "tool.die.rw",
    ] {
        let e = DesignKind::parse(bad).unwrap_err().to_string();
        assert!(
            e.contains(bad) && e.contains("tool.<name>.<x|y|z|rx|ry|rz>"),
            "{e}"
        );
    }
    assert!(DesignVariable::tool("die", 3).is_err());
    assert_eq!(DesignVariable::tool("die", 1).unwrap().name, "die.y");
    assert!(DesignVariable::tool_rotation("die", 3).is_err());
    assert_eq!(
        DesignVariable::tool_rotation("die", 2).unwrap().name,
        "die.rz"
    );
    // A non-finite orientation is a typed error naming the component.
    let e = ToolPath::fixed()
        .rotated([0.0, f64::NAN, 0.0])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("path.orientation[1]") && e.contains("finite"),
        "{e}"
    );
    // An unknown tool in a case: a typed error at the key, listing the case's tools.
    let text = CASE.replace("{final}", "0.5").replace(
        "{design}",
        "[[design]]\nname = \"h\"\nkind = \"tool.holder.x\"\nfd_steps = [1e-3]\n",
    );
    match parse_shell_case(&text, Path::new("x.toml")) {
        Err(CaseError::Invalid {
            key,
            value,
            expected,
            ..
        }) => {
            assert_eq!(key, "design[0].kind");
            assert!(value.contains("tool.holder.x"), "{value}");
            assert!(
                expected.contains("\"punch\"") && expected.contains("\"die\""),
                "{expected}"
            );
        }
        other => panic!("expected an Invalid error, got {other:?}"),
    }
    // Tool variables take absolute finite-difference steps (τ = 0 at the nominal design).
    let c = case(
        0.5,
        "[[design]]\nname = \"x\"\nkind = \"tool.die.x\"\nfd_steps = [2e-3]\n",
    );
    let base = base_design(&c);
    let spec = c.dsa.unwrap();
    assert_eq!(spec.design[0].absolute_steps(&base), vec![2e-3]);
    let moved = spec.design[0].variable.perturbed(&base, 2e-3).unwrap();
    assert_eq!(moved.tool_offset("die"), [2e-3, 0.0, 0.0]);
    assert_eq!(moved.tool_rotation("die"), [0.0; 3]);
    assert_eq!(spec.design[0].variable.value(&moved), 2e-3);
    // Rotations likewise (absolute angles), and an unknown tool is reported as for
    // translations.
    let c = case(
        0.5,
        "[[design]]\nname = \"r\"\nkind = \"tool.die.ry\"\nfd_steps = [1e-3]\n",
    );
    let spec = c.dsa.clone().unwrap();
    assert_eq!(spec.design[0].absolute_steps(&base), vec![1e-3]);
    let turned = spec.design[0].variable.perturbed(&base, -1e-3).unwrap();
    assert_eq!(turned.tool_rotation("die"), [0.0, -1e-3, 0.0]);
    assert_eq!(turned.tool_offset("die"), [0.0; 3]);
    assert_eq!(spec.design[0].variable.value(&turned), -1e-3);
    // The re-run's die is the case's rotated as built about its pivot: R(θ(t)) R_φ.
    let analysis = CaseAnalysis { case: &c };
    let (problem, _) = shelldsa::sensitivity::fd::Analysis::build(&analysis, &turned).unwrap();
    let contact = problem.loads().iter().find_map(|l| l.contact()).unwrap();
    let die = &contact.contact.tools()[1];
    let expected = ToolPath::fixed().rotated([0.0, -1e-3, 0.0]).unwrap();
    assert_eq!(die.path.orientation(), expected.orientation());
    assert!((die.path.orientation()[(0, 2)] + (1e-3f64).sin()).abs() < 1e-15);
    let text = CASE.replace("{final}", "0.5").replace(
        "{design}",
        "[[design]]\nname = \"h\"\nkind = \"tool.holder.rz\"\nfd_steps = [1e-3]\n",
    );
    match parse_shell_case(&text, Path::new("x.toml")) {
        Err(CaseError::Invalid { key, expected, .. }) => {
            assert_eq!(key, "design[0].kind");
            assert!(
                expected.contains("\"punch\"") && expected.contains("\"die\""),
                "{expected}"
            );
        }
        other => panic!("expected an Invalid error, got {other:?}"),
    }
}

#[test]
fn penalty_from_factor_is_differentiated_with_e_and_t() {
    // ω = c E/t (`penalty_factor`): a re-run with another E or t has another penalty, and the
    // reference differentiates it (c = 1000/70000 gives the ω = 1000 of the other tests).
    let design = r#"
[[design]]
name = "t"
kind = "thickness"
fd_steps = [1e-3, 1e-4]
[[design]]
name = "E"
kind = "material.young"
fd_steps = [1e-3, 1e-4]
[dsa]
monitors = ["center.uz", "edge.ux", "edge.uz"]
"#;
    let text = CASE
        .replace("{final}", "0.25")
        .replace("{design}", design)
        .replace("penalty = 1000.0", "penalty_factor = 0.014285714285714285");
    let c = parse_shell_case(&text, Path::new("tests/dsa_contact.rs")).unwrap();
    let spec = dsa_study::validate(&c, &c.dsa.as_ref().unwrap().methods).unwrap();
    let r = run_case(&c, &spec);
    for var in &r.variables {
        continuum_matches_dual(var);
        let last = var.fd.last().unwrap();
        let unflagged = last.flagged.iter().filter(|f| !**f).count();
        let e = study::max_rel_diff(var, last).expect("comparable components");
        let all: Vec<String> = var
            .fd
            .iter()
            .map(|c| format!("{:.2e}", study::max_rel_diff(var, c).unwrap_or(f64::NAN)))
            .collect();
        println!(
            "penalty_factor, `{}`: {unflagged} of {} steps unflagged, dual vs FD per h {all:?}, \
             smallest {e:.2e}",
            var.entry.variable.name,
            last.flagged.len()
        );
        assert!(unflagged >= 5);
        // The better of the two step sizes: the truncation falls as h² and the re-runs' noise
        // grows as 1/h (measured for E: 2.0e-6 at h/τ = 1e-3, 1.9e-5 at 1e-4, where the
        // response's small E-derivative meets the convergence noise; for t 4.4e-7, 4.5e-9). A
        // penalty held fixed in the reference would be off by the penalty's share of the
        // derivative, orders of magnitude above 1e-5.
        let best = var
            .fd
            .iter()
            .filter_map(|c| study::max_rel_diff(var, c))
            .fold(f64::INFINITY, f64::min);
        assert!(
            best < 1e-5,
            "`{}`: dual vs FD {best:e}",
            var.entry.variable.name
        );
    }
}

/// `--terms`: with contact, every term group of the continuum fictitious load (history, tool,
/// the thickness through the contact faces in `load`, …) equals the dual residual seeded with
/// that group only, to round-off of the terms summed (1e-12 of the largest group entry).
#[test]
fn term_groups_with_contact_match_the_dual_reference() {
    let design = r#"
[[design]]
name = "die.x"
kind = "tool.die.x"
[[design]]
name = "t"
kind = "thickness"
[[design]]
name = "die.rz"
kind = "tool.die.rz"
[dsa]
monitors = ["center.uz"]
"#;
    let c = case(0.25, design);
    let spec = dsa_study::validate(&c, &[DsaMethod::Continuum, DsaMethod::Dual]).unwrap();
    let bs = study::terms(&CaseAnalysis { case: &c }, &base_design(&c), &spec, 8).unwrap();
    assert_eq!(bs.len(), 3);
    for b in &bs {
        let scale = b.groups.iter().fold(0.0f64, |a, g| a.max(g.dual_max));
        for g in &b.groups {
            println!(
                "{} {:>8}: cont {:.3e} dual {:.3e} diff {:.1e}",
                b.variable.name,
                g.group.map_or("total", |t| t.name()),
                g.continuum_max,
                g.dual_max,
                g.max_difference
            );
            assert!(
                g.max_difference <= 1e-12 * scale,
                "{} {:?}: {:e} of {scale:e}",
                b.variable.name,
                g.group,
                g.max_difference
            );
        }
    }
    // The tool group carries die.x, the load group the thickness through the contact.
    let group = |b: &shelldsa::sensitivity::terms::TermBreakdown, name: &str| {
        b.groups
            .iter()
            .find(|g| g.group.map_or("total", |t| t.name()) == name)
            .unwrap()
            .dual_max
    };
    assert!(group(&bs[0], "tool") > 0.0);
    assert!(group(&bs[1], "load") > 0.0);
    // A tool rotation is filed under `tool` too, and under nothing explicit besides.
    assert!(group(&bs[2], "tool") > 0.0);
    for g in ["design", "material", "load"] {
        assert_eq!(group(&bs[2], g), 0.0, "die.rz in {g}");
    }
}

/// The small case's die (R = 10, axis along y through (22, ·, −10.49)) as a NURBS surface:
/// two rational quadratic arcs, 0°–80° and 80°–180° (angle 0 towards the punch, 90° the top;
/// knot 0.45 between them, off the top where the sheet rests at the start: the design
/// velocity of a control point is only C⁰ across a knot), linear along y over [−5, 10]: the
/// same cylinder, parametrised differently. `x_u × x_v` points out of the die
/// (`side = "positive"`).
const NURBS_DIE: &str = r#"type = "nurbs"
degree_u = 2
degree_v = 1
knots_u = [0.0, 0.0, 0.0, 0.45, 0.45, 1.0, 1.0, 1.0]
knots_v = [0.0, 0.0, 1.0, 1.0]
control_points = [
    [[12.0, -5.0, -10.49, 1.0], [12.0, 10.0, -10.49, 1.0]],
    [[12.0, -5.0, -2.099003688227201, 0.766044443118978], [12.0, 10.0, -2.099003688227201, 0.766044443118978]],
    [[20.263518223330696, -5.0, -0.6419224698779207, 1.0], [20.263518223330696, 10.0, -0.6419224698779207, 1.0]],
    [[32.0, -5.0, 1.4275359259420988, 0.6427876096865394], [32.0, 10.0, 1.4275359259420988, 0.6427876096865394]],
    [[32.0, -5.0, -10.489999999999998, 1.0], [32.0, 10.0, -10.489999999999998, 1.0]],
]"#;

/// The small case's text with the die's cylinder replaced by [`NURBS_DIE`].
fn nurbs_die_case_text(final_load: f64, design: &str) -> String {
    let cylinder = r#"type = "cylinder-sector"
origin = [22.0, -5.0, -10.49]
axis = [0.0, 1.0, 0.0]
reference = [-1.0, 0.0, 0.0]
radius = 10.0
angle_deg = [-30.0, 150.0]
length = [0.0, 15.0]"#;
    let text = CASE
        .replace("{final}", &format!("{final_load:?}"))
        .replace("{design}", design);
    assert_eq!(text.matches(cylinder).count(), 1);
    text.replace(cylinder, NURBS_DIE)
}

/// A tool-shape rate: surface parameter `name` of `tool` at unit rate.
fn shape_rate(tool: &RigidTool, name: &str) -> ToolRate {
    ToolRate {
        shape: Some((tool.surface.parameter_index(name).unwrap(), 1.0)),
        ..Default::default()
    }
}

/// Tool shapes (`tool.<name>.shape.<parameter>`): `force_dot` with the rate of a tool
/// surface's design parameter (`V^c = R ∂X/∂p`, `V^c,α = R ∂X,α/∂p` at fixed `ξ`, the normal's
/// turn `(I − n nᵀ) ċ/(n·c)`; `shell::contact_sensitivity`) against the `Dual64` evaluation of
/// `force_with` on the tool surface rebuilt with the seeded parameter and against central
/// differences, for the cylinders' radii and axis points and, with the die as a NURBS patch of
/// the same cylinder, control-point coordinates and a weight. The forces with the tool
/// rebuilt as a re-run rebuilds it (`RigidTool::reshaped`) equal those with the perturbed
/// surface passed as input.
#[test]
fn tool_shape_sensitivity_matches_dual_and_central_differences() {
    let (model, contact) = bent_state();
    let n = model.n_dofs();
    let np = model.particles.len();
    let surface = case(0.5, "").surface;
    let nurbs_case = parse_shell_case(
        &nurbs_die_case_text(0.5, ""),
        Path::new("tests/dsa_contact.rs"),
    )
    .unwrap();
    let nurbs = ShellContact::new(
        &model,
        &surface,
        nurbs_case.tools.clone(),
        ContactFaces::Both,
        contact.penalty(),
    )
    .unwrap();
    let (q, t) = kernel_point(n, &mut Lcg(0x7001_5ba9e));
    // The NURBS die is the cylinder: the same force to round-off of the projection
    // (positions ~30 mm, Newton to ~1e-14 in ξ): 1e-9 of max|f|.
    let zero = Seed::none(np, n);
    let f_cyl = force_f64(&model, &contact, &q, t, &zero, 0.0);
    let f_nurbs = force_f64(&model, &nurbs, &q, t, &zero, 0.0);
    let e_geom = max_diff(&f_cyl, &f_nurbs) / max_abs(&f_cyl);
    println!("NURBS die vs cylinder die: force differs by {e_geom:.1e} of max|f|");
    assert!(e_geom < 1e-9, "NURBS die vs cylinder: {e_geom:e}");

    let none = ToolRate::default();
    let seed = |name, tools| Seed::tools(name, tools, np, n);
    let (punch, die) = (&contact.tools()[0], &contact.tools()[1]);
    let ndie = &nurbs.tools()[1];
    let cases: Vec<(&ShellContact, Seed)> = vec![
        (
            &contact,
            seed("die radius", vec![none, shape_rate(die, "radius")]),
        ),
        (
            &contact,
            seed("die origin.z", vec![none, shape_rate(die, "origin.z")]),
        ),
        (
            &contact,
            seed("punch radius", vec![shape_rate(punch, "radius"), none]),
        ),
        (
            &contact,
            seed(
                "both radii",
                vec![shape_rate(punch, "radius"), shape_rate(die, "radius")],
            ),
        ),
        (
            &nurbs,
            seed(
                "nurbs cp[2][0].z",
                vec![none, shape_rate(ndie, "cp[2][0].z")],
            ),
        ),
        (
            &nurbs,
            seed(
                "nurbs cp[3][0].x",
                vec![none, shape_rate(ndie, "cp[3][0].x")],
            ),
        ),
        (
            &nurbs,
            seed(
                "nurbs cp[3][1].z",
                vec![none, shape_rate(ndie, "cp[3][1].z")],
            ),
        ),
        (
            &nurbs,
            seed(
                "nurbs weight[3][0]",
                vec![none, shape_rate(ndie, "weight[3][0]")],
            ),
        ),
    ];
    for (contact, seed) in &cases {
        let h = 1e-4;
        let rates = ContactRates::new(&model, contact, &q, t, seed, h);
        let (scale, e_dual, e_cd) = rates.force;
        let fp = &rates.force_plus;
        // The tool rebuilt as a re-run rebuilds it (RigidTool::reshaped): the same surface,
        // so the same force to round-off (1e-12 of max|f|).
        let tools: Vec<RigidTool> = contact
            .tools()
            .iter()
            .zip(&seed.tools)
            .map(|(tl, r)| match r.shape {
                Some((k, rate)) => tl.reshaped(&[(k, h * rate)]).unwrap(),
                None => tl.clone(),
            })
            .collect();
        let rebuilt = ShellContact::new(
            &model,
            &surface,
            tools,
            ContactFaces::Both,
            contact.penalty(),
        )
        .unwrap();
        let fr = force_f64(&model, &rebuilt, &q, t, &zero, 0.0);
        let e_rebuilt = max_diff(&fr, fp) / max_abs(fp);
        println!(
            "{:<20} max|ḟ| {scale:.4e}  |hand − dual| {e_dual:.2e}  |hand − central| {e_cd:.2e}  \
             rebuilt tool vs inputs {e_rebuilt:.1e}",
            seed.name
        );
        assert!(
            e_rebuilt < 1e-12,
            "{}: rebuilt tool vs inputs {e_rebuilt:e}",
            seed.name
        );
        // Central differences with h = 1e-4 (parameters of size 0.6…30): the projection's
        // convergence noise in the force (~1e-13 of max|f| ~ 1e3) over h dominates smaller
        // steps for the seeds that move the force little (a control point off the die's top,
        // max|ḟ| ~ 2: measured 1.9e-7, 3.4e-8, 2.3e-9 at h = 1e-6, 1e-5, 1e-4), while the
        // truncation ~h²|f'''| stays below 2e-8 (the weight): 1e-7 of max|ḟ|.
        assert_three_way(seed.name, "force", rates.force);
        // The forces on the tools, the same three ways.
        assert_three_way(seed.name, "tool forces", rates.tool_forces);
    }
    // A cylinder's radius with its axis fixed moves every tool point along its normal by one
    // (V^c = n, V^c,α = x^c,α / R). The die's contact points lie within a few degrees of its
    // top, where n ≈ e_z, so the force rate is nearly that of raising the die (die.z: V^c =
    // e_z, V^c,α = 0): a check independent of the dual (measured cosine 1.0000; 0.99 allows
    // the points off the top).
    let fr = contact
        .force_dot(
            &model,
            &q,
            t,
            &ContactSeeds {
                tools: &[none, shape_rate(die, "radius")],
                thickness: 0.0,
                penalty: 0.0,
                particles: &zero.particles,
                increment: &zero.increment,
                initial: None,
            },
        )
        .unwrap();
    let fz = contact
        .force_dot(
            &model,
            &q,
            t,
            &ContactSeeds {
                tools: &[none, translation([0.0, 0.0, 1.0])],
                thickness: 0.0,
                penalty: 0.0,
                particles: &zero.particles,
                increment: &zero.increment,
                initial: None,
            },
        )
        .unwrap();
    let dot: f64 = fr.iter().zip(&fz).map(|(a, b)| a * b).sum();
    let cos = dot
        / (fr.iter().map(|a| a * a).sum::<f64>() * fz.iter().map(|a| a * a).sum::<f64>()).sqrt();
    println!("die radius vs die z force rates: cosine {cos:.4}");
    assert!(cos > 0.99, "die radius vs die z: cosine {cos}");
}

/// Whole runs for tool shapes on the small bending case: the radii of the die and the punch
/// (axes fixed: the die's top rises with its radius) and, with the die as a NURBS patch of
/// the same cylinder ([`NURBS_DIE`]), the horizontal position of the middle control point of
/// the arc that holds the die's top (`cp[3][0].x`, one end of the die) and that arc's weight:
/// continuum = dual, central differences of complete re-runs with the tools rebuilt
/// (`RigidTool::reshaped`), Taylor rates 2.
#[test]
fn tool_shape_derivatives_match_dual_and_re_runs() {
    let design = r#"
[[design]]
name = "die.radius"
kind = "tool.die.shape.radius"
fd_steps = [4e-3, 2e-3, 1e-3, 5e-4]
[[design]]
name = "punch.radius"
kind = "tool.punch.shape.radius"
fd_steps = [4e-3, 2e-3, 1e-3, 5e-4]
[dsa]
monitors = ["center.uz", "edge.ux", "edge.uz", "tool.punch.fz"]
"#;
    // The study three ways on `c`, every variable checked.
    let run_and_check = |label: &str, c: &ShellCase| {
        let spec = dsa_study::validate(c, &c.dsa.as_ref().unwrap().methods).unwrap();
        let t0 = std::time::Instant::now();
        let r = run_case(c, &spec);
        println!(
            "{label}: {} steps, total {:.1} s",
            r.nominal.loads.len(),
            t0.elapsed().as_secs_f64()
        );
        assert!(r.dual_state_mismatch.unwrap() < 1e-10);
        for v in 0..r.variables.len() {
            check_variable(&r, v);
        }
    };
    run_and_check("radii", &case(0.5, design));

    let design = r#"
[[design]]
name = "die.cp.x"
kind = "tool.die.shape.cp[3][0].x"
fd_steps = [4e-3, 2e-3, 1e-3, 5e-4]
[[design]]
name = "die.w"
kind = "tool.die.shape.weight[3][0]"
fd_steps = [4e-3, 2e-3, 1e-3, 5e-4]
[dsa]
monitors = ["center.uz", "edge.ux", "edge.uz", "tool.punch.fz"]
"#;
    let c = parse_shell_case(
        &nurbs_die_case_text(0.5, design),
        Path::new("tests/dsa_contact.rs"),
    )
    .unwrap();
    run_and_check("NURBS die", &c);
}

/// `tool.<name>.shape.<parameter>`: parsed on the case's tools; an unknown parameter lists
/// the valid ones, an unknown tool the case's tools; a step that makes the tool invalid (a
/// radius ≤ 0) is an error naming the key, before any analysis.
#[test]
fn tool_shape_design_variables_are_checked() {
    use shelldsa::sensitivity::{DesignError, DesignKind};
    let c = case(0.5, "");
    let kind = DesignKind::parse_with_tools("tool.die.shape.radius", &c.surface, &c.tools).unwrap();
    let DesignKind::ToolShape {
        tool,
        parameter,
        name,
    } = &kind
    else {
        panic!("{kind:?}");
    };
    assert_eq!((tool.as_str(), name.as_str()), ("die", "radius"));
    assert_eq!(c.tools[1].surface.parameter_names()[*parameter], "radius");
    // Without the tools the key is refused with a message naming what it needs.
    let e = DesignKind::parse("tool.die.shape.radius").unwrap_err();
    assert!(matches!(e, DesignError::ToolShapeWithoutTool { .. }), "{e}");
    // Unknown parameter: the valid names are listed.
    let e = DesignKind::parse_with_tools("tool.die.shape.raduis", &c.surface, &c.tools)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("raduis") && e.contains("radius") && e.contains("origin.x"),
        "{e}"
    );
    // Unknown tool: the case's tools are listed.
    let e = DesignKind::parse_with_tools("tool.blank.shape.radius", &c.surface, &c.tools)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("blank") && e.contains("die") && e.contains("punch"),
        "{e}"
    );
    // A reshaped tool that is no valid tool: an error naming the parameter.
    let e = c.tools[1]
        .reshaped(&[(*parameter, -20.0)])
        .unwrap_err()
        .to_string();
    assert!(e.contains("die") && e.contains("radius"), "{e}");
    // In a case file: the step that would make the radius negative is refused at its key.
    let design = r#"
[[design]]
name = "die.radius"
kind = "tool.die.shape.radius"
fd_steps = [1e-3, 20.0]
"#;
    let text = CASE.replace("{final}", "0.5").replace("{design}", design);
    let e = parse_shell_case(&text, Path::new("tests/dsa_contact.rs"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("design[0].fd_steps[1]") && e.contains("radius"),
        "{e}"
    );
    let design = r#"
[[design]]
name = "die.r"
kind = "tool.die.shape.r"
"#;
    let text = CASE.replace("{final}", "0.5").replace("{design}", design);
    let e = parse_shell_case(&text, Path::new("tests/dsa_contact.rs"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("design[0].kind") && e.contains("radius"), "{e}");
}
