//! Path following: arc-length continuation through limit points (a one-unknown snap-through
//! with a closed-form equilibrium path), the edge-force load, reactions and directional monitors
//! of a displacement-controlled shell run.

use shelldsa::io::shell_build;
use shelldsa::io::shell_case::parse_shell_case;
use shelldsa::solver::*;
use std::path::Path;

/// `r(u, λ) = f(u) − λ` with `f(u) = u − 1.5 u² + 0.6 u³`: a snap-through path with a load
/// maximum at `u₁ = (3 − √1.8)/3.6` and a minimum at `u₂ = (3 + √1.8)/3.6` (`f′ = 0`).
struct Snap;

fn f(u: f64) -> f64 {
    u - 1.5 * u * u + 0.6 * u * u * u
}

/// `f′`.
fn df(u: f64) -> f64 {
    1.0 - 3.0 * u + 1.8 * u * u
}

impl NonlinearProblem for Snap {
    fn n_dofs(&self) -> usize {
        1
    }
    fn residual(&mut self, u: &[f64], load: f64, r: &mut [f64]) -> Result<(), ProblemError> {
        r[0] = f(u[0]) - load;
        Ok(())
    }
    fn tangent(&mut self, u: &[f64], _load: f64, k: &mut [f64]) -> Result<(), ProblemError> {
        k[0] = df(u[0]);
        Ok(())
    }
    fn force_norm(&self, load: f64) -> f64 {
        load.abs()
    }
    fn load_derivative(
        &mut self,
        _u: &[f64],
        _load: f64,
        out: &mut [f64],
    ) -> Result<bool, ProblemError> {
        out[0] = -1.0;
        Ok(true)
    }
    fn commit(&mut self, _u: &[f64], _load: f64) {}
    fn restore(&mut self) {}
}

#[test]
fn arc_length_passes_a_load_maximum_and_minimum_and_reports_both() {
    let pattern = SparsityPattern::from_cells(1, &[vec![0]]).unwrap();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    let newton = NewtonSolver::default();
    let arc = ArcLength {
        end: 1.0,
        initial_length: 0.05,
        max_length: 0.05,
        ..ArcLength::default()
    };
    let mut seen = Vec::new();
    let out = newton
        .run_arc_length(&mut Snap, &pattern, &mut solver, &[0.0], &arc, |c| {
            seen.push(c.clone())
        })
        .expect("the path to λ = 1");
    let steps: Vec<&StepRecord> = out.report.converged_steps().collect();
    // Every converged point is on the path: f(u) = λ to the tolerance 1e-8 λ.
    // (The unknowns are not kept per step by the driver; the last one is checked exactly and
    // the path through the load factors below.)
    let u = out.report.u[0];
    assert!(
        (f(u) - out.report.load).abs() <= 1e-8 * out.report.load,
        "u {u}"
    );
    assert!(out.report.load >= 1.0);
    // The load factors rise, fall and rise again: two extrema, found by the sign of q·K⁻¹q.
    assert_eq!(out.critical, seen);
    assert_eq!(out.critical.len(), 2, "{:?}", out.critical);
    let (u1, u2) = ((3.0 - 1.8f64.sqrt()) / 3.6, (3.0 + 1.8f64.sqrt()) / 3.6);
    let (max, min) = (&out.critical[0], &out.critical[1]);
    assert_eq!(max.kind, CriticalKind::LoadMaximum);
    assert_eq!(min.kind, CriticalKind::LoadMinimum);
    // Each bracket lies within one step of the extremum: a step moves u by at most Δs = 0.05,
    // and f is within f″·Δs²/2 ≤ 0.0045 of its extremum there (|f″| ≤ 1.8 near u₁, u₂).
    for (c, ue) in [(max, u1), (min, u2)] {
        for l in c.loads {
            assert!((l - f(ue)).abs() <= 0.0045, "{c}: λ {l} against {}", f(ue));
        }
    }
    // Between the brackets the load factor fell: the path went through the unstable branch.
    let falling = steps.windows(2).filter(|w| w[1].load < w[0].load).count();
    assert!(falling >= 3, "{falling} falling steps");
}

/// `r(u, λ) = (u₂ − λ, u₁ − f(u₂))` with the load on the first row (`q = e₁`): the load factor
/// rises with `u₂`, and the displacement the load works on, `u₁ = f(u₂)`, turns back twice, at
/// `u₂ = u₁`, `u₂` of [`Snap`] (a snap-back). `det K = −1` everywhere, and `q·K⁻¹q = f′(u₂)`.
struct SnapBack;

impl NonlinearProblem for SnapBack {
    fn n_dofs(&self) -> usize {
        2
    }
    fn residual(&mut self, u: &[f64], load: f64, r: &mut [f64]) -> Result<(), ProblemError> {
        r[0] = u[1] - load;
        r[1] = u[0] - f(u[1]);
        Ok(())
    }
    fn tangent(&mut self, u: &[f64], _load: f64, k: &mut [f64]) -> Result<(), ProblemError> {
        // [[0, 1], [1, −f′(u₂)]]: symmetric, so the storage order does not matter.
        k.copy_from_slice(&[0.0, 1.0, 1.0, -df(u[1])]);
        Ok(())
    }
    fn force_norm(&self, load: f64) -> f64 {
        load.abs()
    }
    fn load_derivative(
        &mut self,
        _u: &[f64],
        _load: f64,
        out: &mut [f64],
    ) -> Result<bool, ProblemError> {
        out[0] = -1.0;
        out[1] = 0.0;
        Ok(true)
    }
    fn commit(&mut self, _u: &[f64], _load: f64) {}
    fn restore(&mut self) {}
}

#[test]
fn arc_length_reports_a_snap_back_as_such_not_as_a_limit_point() {
    let pattern = SparsityPattern::from_cells(2, &[vec![0, 1]]).unwrap();
    // Both factorisations: the dense LU gives the determinant's sign, faer's sparse LU none;
    // the kind follows from the direction of the load along the path in both.
    for method in [Method::DenseLu, Method::Lu] {
        snap_back_with(&pattern, method);
    }
}

fn snap_back_with(pattern: &SparsityPattern, method: Method) {
    let mut solver = LinearSolver::new(pattern, method, SolverOptions::default()).unwrap();
    let arc = ArcLength {
        end: 1.5,
        initial_length: 0.05,
        max_length: 0.05,
        ..ArcLength::default()
    };
    let out = NewtonSolver::default()
        .run_arc_length(
            &mut SnapBack,
            pattern,
            &mut solver,
            &[0.0, 0.0],
            &arc,
            |_| {},
        )
        .expect("the path to λ = 1.5");
    // q·K⁻¹q changes sign twice and the determinant never: two snap-backs, no limit point
    // (the load factor rises all the way) and no bifurcation.
    let kinds: Vec<CriticalKind> = out.critical.iter().map(|c| c.kind).collect();
    assert_eq!(
        kinds,
        [CriticalKind::SnapBack; 2],
        "{method:?}: {:?}",
        out.critical
    );
    let steps: Vec<&StepRecord> = out.report.converged_steps().collect();
    assert!(steps.windows(2).all(|w| w[1].load > w[0].load));
    // Each bracket holds its turning point (λ = u₂ there): a step moves λ by at most Δs.
    let turns = [(3.0 - 1.8f64.sqrt()) / 3.6, (3.0 + 1.8f64.sqrt()) / 3.6];
    for (c, t) in out.critical.iter().zip(turns) {
        assert!(c.loads[0] <= t && t <= c.loads[1], "{c}: turn at λ = {t}");
    }
}

/// `r(u, λ) = u − g(λ)` with `g(λ) = (1 − (λ − 1)², ε λ)`: a path whose trace in the unknowns
/// is a hairpin, out along `u₁` and back, turning at `λ = 1` with a radius of curvature `ε²/2`
/// (0.005 at ε = 0.1). Committed states are kept, to read the steps' increments.
struct Hairpin {
    committed: Vec<([f64; 2], f64)>,
}

const HAIRPIN_EPS: f64 = 0.1;

fn hairpin(l: f64) -> [f64; 2] {
    [1.0 - (l - 1.0) * (l - 1.0), HAIRPIN_EPS * l]
}

impl NonlinearProblem for Hairpin {
    fn n_dofs(&self) -> usize {
        2
    }
    fn residual(&mut self, u: &[f64], load: f64, r: &mut [f64]) -> Result<(), ProblemError> {
        let g = hairpin(load);
        r[0] = u[0] - g[0];
        r[1] = u[1] - g[1];
        Ok(())
    }
    fn tangent(&mut self, _u: &[f64], _load: f64, k: &mut [f64]) -> Result<(), ProblemError> {
        // The pattern of one 2 × 2 cell: identity.
        k.copy_from_slice(&[1.0, 0.0, 0.0, 1.0]);
        Ok(())
    }
    fn force_norm(&self, _load: f64) -> f64 {
        1.0
    }
    fn load_derivative(
        &mut self,
        _u: &[f64],
        load: f64,
        out: &mut [f64],
    ) -> Result<bool, ProblemError> {
        out[0] = 2.0 * (load - 1.0);
        out[1] = -HAIRPIN_EPS;
        Ok(true)
    }
    fn commit(&mut self, u: &[f64], load: f64) {
        self.committed.push(([u[0], u[1]], load));
    }
    fn restore(&mut self) {}
}

#[test]
fn arc_length_goes_round_a_turn_sharper_than_its_arc_length_without_turning_back() {
    let pattern = SparsityPattern::from_cells(2, &[vec![0, 1]]).unwrap();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    // Δs = 0.05 is ten times the turn's radius of curvature: a step from just before the turn
    // meets the path on both legs.
    let arc = ArcLength {
        end: 1.9,
        initial_length: 0.05,
        max_length: 0.05,
        ..ArcLength::default()
    };
    let mut problem = Hairpin {
        committed: vec![([0.0, 0.0], 0.0)],
    };
    let out = NewtonSolver::default()
        .run_arc_length(
            &mut problem,
            &pattern,
            &mut solver,
            &[0.0, 0.0],
            &arc,
            |_| {},
        )
        .expect("the path round the turn to λ = 1.9");
    assert!(out.report.load >= 1.9);
    let states = &problem.committed;
    // Every committed state is on the path: the residual within the driver's tolerance,
    // `residual_rtol` (1e-8) times the force norm (1).
    for (u, l) in states {
        let g = hairpin(*l);
        assert!((u[0] - g[0]).hypot(u[1] - g[1]) <= 1e-8, "{u:?} at λ {l}");
    }
    // The load factor only rises along this path: no step went back to an earlier point.
    assert!(
        states.windows(2).all(|w| w[1].1 > w[0].1),
        "{:?}",
        states.iter().map(|s| s.1).collect::<Vec<_>>()
    );
    // Consecutive increments make acute angles: the steps went round the turn, which the
    // shortened arc lengths resolved.
    let inc = |a: &([f64; 2], f64), b: &([f64; 2], f64)| [b.0[0] - a.0[0], b.0[1] - a.0[1]];
    for w in states.windows(3) {
        let (p, d) = (inc(&w[0], &w[1]), inc(&w[1], &w[2]));
        assert!(p[0] * d[0] + p[1] * d[1] >= 0.0, "{w:?}");
    }
    // The steps that met the path on the leg behind were refused as such.
    let reversed = out
        .report
        .attempts
        .iter()
        .filter(|a| matches!(a.failure, Some(FailureReason::PathReversed { .. })))
        .count();
    assert!(reversed >= 1, "no step was refused as reversed");
}

#[test]
fn arc_length_refuses_a_problem_without_load_derivative() {
    struct NoDerivative;
    impl NonlinearProblem for NoDerivative {
        fn n_dofs(&self) -> usize {
            1
        }
        fn residual(&mut self, u: &[f64], load: f64, r: &mut [f64]) -> Result<(), ProblemError> {
            r[0] = u[0] - load;
            Ok(())
        }
        fn tangent(&mut self, _u: &[f64], _l: f64, k: &mut [f64]) -> Result<(), ProblemError> {
            k[0] = 1.0;
            Ok(())
        }
        fn commit(&mut self, _u: &[f64], _load: f64) {}
        fn restore(&mut self) {}
    }
    let pattern = SparsityPattern::from_cells(1, &[vec![0]]).unwrap();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    let fail = NewtonSolver::default()
        .run_arc_length(
            &mut NoDerivative,
            &pattern,
            &mut solver,
            &[0.0],
            &ArcLength::default(),
            |_| {},
        )
        .unwrap_err();
    assert!(
        matches!(&fail.reason, FailureReason::Setup(m) if m.contains("load derivative")),
        "{}",
        fail.reason
    );
}

const PLATE: &str = r#"
thickness = 0.1
[problem]
kind = "shell"
title = "strip"
[surface]
type = "rectangle"
origin = [0.0, 0.0, 0.0]
edge_u = [2.0, 0.0, 0.0]
edge_v = [0.0, 1.0, 0.0]
[particles]
grid = [9, 5]
[kernel]
basis = "quadratic"
support = 3.0
[integration]
cells = "per-particle-spacing"
gauss = 2
thickness_points = 2
thickness_rule = "gauss"
[material]
young = 1.2e6
poisson = 0.0
sigma0 = 1e30
hardening = 0.0
beta = 1.0
[[boundary]]
kind = "clamped"
edge = "u-min"
LOAD
[steps]
initial_step = 1.0
min_step = 0.01
max_step = 1.0
[[monitor]]
name = "tip"
at = [1.0, 0.5]
direction = [0.0, 0.0, 2.0]
[[monitor]]
name = "tip-normal"
at = [1.0, 0.5]
direction = "normal"
"#;

#[test]
fn edge_force_integrates_to_the_force_times_the_edge_length() {
    // A dead force per unit length on the tip edge (u-max, length 1): by the partition of unity
    // Σ_I Ψ_I = 1 the generalised forces sum to ∫ p ds = p · 1, to round-off.
    let text = PLATE.replace(
        "LOAD",
        "[[load]]\nkind = \"edge-force\"\nedge = \"u-max\"\nper_length = [0.5, -0.25, 3.0]",
    );
    let case = parse_shell_case(&text, Path::new("strip.toml")).unwrap();
    let built = shell_build::build(&case).unwrap();
    let p = &built.problem;
    let f = p
        .external_force(&vec![0.0; p.n_generalised()], 1.0)
        .unwrap();
    let mut sum = [0.0; 3];
    for (k, v) in f.iter().enumerate() {
        if k % 5 < 3 {
            sum[k % 5] += v;
        }
    }
    for (s, e) in sum.iter().zip([0.5, -0.25, 3.0]) {
        // Round-off of ~45 summed terms of order 1 (1e-13 leaves a margin of ~10²).
        assert!((s - e).abs() <= 1e-13, "{sum:?}");
    }
    // Moments: none (translations only).
    assert!(f.iter().enumerate().all(|(k, v)| k % 5 < 3 || *v == 0.0));
}

#[test]
fn edge_force_equals_the_point_forces_of_a_uniform_load_on_a_linear_strip() {
    // A strip clamped at u = 0 under a uniform transverse edge force q on its tip: linear
    // cantilever, tip deflection q b L³/(3 E I) with I = b t³/12 (Euler–Bernoulli; the shear
    // part q L/(κ G t) adds 1.3e-5 relative at L/t = 20). Checked within 1 % (the RK strip's
    // measured bending error at this grid is well below that, tests/shell_cantilever.rs).
    let q = 1e-4;
    let text = PLATE.replace(
        "LOAD",
        &format!("[[load]]\nkind = \"edge-force\"\nedge = \"u-max\"\nper_length = [0.0, 0.0, {q}]"),
    );
    let case = parse_shell_case(&text, Path::new("strip.toml")).unwrap();
    let mut built = shell_build::build(&case).unwrap();
    let out = std::env::temp_dir().join(format!("shelldsa-edge-force-{}", std::process::id()));
    let summary =
        shell_build::run(&case, &mut built, &out, std::time::Instant::now(), |_| {}).unwrap();
    assert_eq!(summary.status, shell_build::RunStatus::Complete);
    let (l, t, e): (f64, f64, f64) = (2.0, 0.1, 1.2e6);
    let exact = q * l.powi(3) / (3.0 * e * t.powi(3) / 12.0);
    let w = summary.steps.last().unwrap().monitors[0][2];
    assert!((w / exact - 1.0).abs() < 0.01, "w {w} against {exact}");
    // The directional monitors: along (0, 0, 2)/2 and along the initial normal (+z).
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let last = json["steps"].as_array().unwrap().last().unwrap().clone();
    assert_eq!(last["monitors"]["tip"]["along"].as_f64().unwrap(), w);
    let normal = last["monitors"]["tip-normal"]["along"].as_f64().unwrap();
    assert!((normal - w).abs() <= 1e-15 * w.abs(), "{normal} {w}");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn displacement_control_reports_the_reaction_that_equals_the_applied_load() {
    // The same strip with its tip deflection prescribed to the value the edge force gives: the
    // reaction of the prescribed point is the force that holds it there. Linear, so the
    // reaction equals the total edge force that produced that deflection at its own point
    // only up to the load's distribution; instead, compare with a point force at the same
    // point: prescribe the deflection w_P of a point force P and read back P.
    let p = 1e-4;
    let load =
        format!("[[load]]\nkind = \"point-force\"\nat = [1.0, 0.5]\nforce = [0.0, 0.0, {p}]");
    let case = parse_shell_case(&PLATE.replace("LOAD", &load), Path::new("s.toml")).unwrap();
    let mut built = shell_build::build(&case).unwrap();
    let out = std::env::temp_dir().join(format!("shelldsa-reaction-a-{}", std::process::id()));
    let s = shell_build::run(&case, &mut built, &out, std::time::Instant::now(), |_| {}).unwrap();
    let w = s.steps.last().unwrap().monitors[0][2];
    let _ = std::fs::remove_dir_all(&out);

    let control = format!(
        "[[boundary]]\nkind = \"prescribed\"\nat = [1.0, 0.5]\ncomponent = \"uz\"\nvalue = {w:e}"
    );
    let case = parse_shell_case(&PLATE.replace("LOAD", &control), Path::new("s.toml")).unwrap();
    let mut built = shell_build::build(&case).unwrap();
    let out = std::env::temp_dir().join(format!("shelldsa-reaction-b-{}", std::process::id()));
    let s = shell_build::run(&case, &mut built, &out, std::time::Instant::now(), |_| {}).unwrap();
    let last = s.steps.last().unwrap();
    assert_eq!(last.reactions.len(), 1);
    assert_eq!(last.reactions[0].0, "boundary[1]");
    // The support pushes the point up with P; linear problem solved to rtol 1e-8: 1e-6.
    let r = last.reactions[0].1;
    assert!((r / p - 1.0).abs() < 1e-6, "reaction {r} against {p}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let steps = json["steps"].as_array().unwrap();
    assert_eq!(
        steps.last().unwrap()["reactions"]["boundary[1]"].as_f64(),
        Some(r)
    );
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn degree_keys_and_arc_length_with_dsa_are_refused_up_front() {
    // A degree key names degrees.
    let start = PLATE.find("[surface]").unwrap();
    let end = PLATE.find("[particles]").unwrap();
    let bad = format!(
        "{}[surface]\ntype = \"cylinder-sector\"\norigin = [0.0, 0.0, 0.0]\n\
         axis = [1.0, 0.0, 0.0]\nreference = [0.0, 0.0, 1.0]\nradius = 10.0\n\
         angle_deg = [0.0, 400.0]\nlength = [0.0, 1.0]\n{}",
        &PLATE[..start],
        &PLATE[end..]
    )
    .replace("LOAD", "");
    let e = parse_shell_case(&bad, Path::new("c.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("angle_deg") && e.contains("400"), "{e}");
    // shelldsa dsa refuses an arc-length case before any analysis.
    let text = PLATE.replace("LOAD", "").replace(
        "[steps]\n",
        "[steps]\ncontrol = \"arc-length\"\narc_length = 0.1\n",
    );
    let case = parse_shell_case(&text, Path::new("arc.toml")).unwrap();
    let e = shelldsa::io::dsa_study::check_load_control(&case)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("steps.control") && e.contains("arc-length"),
        "{e}"
    );
}

/// Arc lengths far too short for the path to the end load: the run stops after its first
/// step, saying so, instead of using up every attempt; a short first arc length that may grow
/// runs to the end.
#[test]
fn arc_lengths_far_too_short_stop_after_the_first_step() {
    let pattern = SparsityPattern::from_cells(1, &[vec![0]]).unwrap();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    let newton = NewtonSolver::default();
    // dλ/du = 1 at the start: about 1e6 steps of 1e-6 to λ = 1, against 10 000 attempts.
    let short = ArcLength {
        end: 1.0,
        initial_length: 1e-6,
        max_length: 1e-6,
        ..ArcLength::default()
    };
    let e = newton
        .run_arc_length(&mut Snap, &pattern, &mut solver, &[0.0], &short, |_| {})
        .expect_err("arc lengths of 1e-6 to λ = 1");
    assert!(
        matches!(e.reason, FailureReason::ArcLengthTooShort { steps, .. } if steps > 4e5),
        "{e}"
    );
    assert_eq!(e.report.converged_steps().count(), 1);
    assert!(e.to_string().contains("too short for this path"), "{e}");
    // The same first step with room to grow (easy steps grow 1.5 times up to 0.05).
    let growing = ArcLength {
        max_length: 0.05,
        ..short
    };
    let out = newton
        .run_arc_length(&mut Snap, &pattern, &mut solver, &[0.0], &growing, |_| {})
        .expect("the path to λ = 1 with growing arc lengths");
    assert!(out.report.load >= 1.0);
}
