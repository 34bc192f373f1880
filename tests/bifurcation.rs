//! Bifurcation detection: a straight strip clamped at one end under a compressive dead edge
//! force on the other (Euler's column, no imperfection) follows its straight path through the
//! buckling load; the sign of the tangent's determinant changes there while the load factor
//! keeps rising, and the run reports one bifurcation between the two steps around the Euler
//! load, under load control and under arc-length control, on two grids.
//!
//! Euler load of a clamped–free column: `P_cr = π² E I / (4 L²)` (Timoshenko & Gere, *Theory of
//! Elastic Stability*, §2.1) with `I = b t³/12`. With `ν = 0` the plate modulus `E/(1 − ν²)` of
//! a strip in cylindrical bending equals `E`, so the strip's width does not enter and the
//! narrow-strip and wide-plate values coincide. Transverse shear lowers the load by the factor
//! `1/(1 + P_cr/(κ G b t))` (Timoshenko & Gere §2.17): `P_cr/(κ G b t) = 3.1e-4` here, far below
//! the step brackets checked.

use shelldsa::io::shell_build;
use shelldsa::io::shell_case::parse_shell_case;
use shelldsa::solver::*;
use std::path::Path;

const E: f64 = 1.2e6;
const T: f64 = 0.05;
const B: f64 = 0.25;
const L: f64 = 2.0;

fn euler_load() -> f64 {
    let i = B * T.powi(3) / 12.0;
    std::f64::consts::PI.powi(2) * E * i / (4.0 * L * L)
}

/// The strip with `grid` particles and the edge force `P_cr / b` per unit length (load factor 1
/// at the Euler load), with the `[steps]` table `steps`.
fn strip(grid: [usize; 2], steps: &str) -> String {
    let q = euler_load() / B;
    format!(
        r#"thickness = {T}
[problem]
kind = "shell"
title = "Euler column"
[surface]
type = "rectangle"
origin = [0.0, 0.0, 0.0]
edge_u = [{L}, 0.0, 0.0]
edge_v = [0.0, {B}, 0.0]
[particles]
grid = [{}, {}]
[kernel]
basis = "quadratic"
support = 3.0
[integration]
cells = "per-particle-spacing"
gauss = 2
thickness_points = 2
thickness_rule = "gauss"
[material]
young = {E}
poisson = 0.0
sigma0 = 1e30
hardening = 0.0
beta = 1.0
[[boundary]]
kind = "clamped"
edge = "u-min"
[[load]]
kind = "edge-force"
edge = "u-max"
per_length = [{:e}, 0.0, 0.0]
[steps]
{steps}
[[monitor]]
name = "tip"
at = [1.0, 0.5]
"#,
        grid[0], grid[1], -q
    )
}

/// Run the case; the critical points from results.json and the converged steps' (number, load
/// factor).
fn run(text: &str, tag: &str) -> (Vec<serde_json::Value>, Vec<(usize, f64)>) {
    let case = parse_shell_case(text, Path::new("column.toml")).unwrap();
    let mut built = shell_build::build(&case).unwrap();
    let out =
        std::env::temp_dir().join(format!("shelldsa-bifurcation-{tag}-{}", std::process::id()));
    let s = shell_build::run(&case, &mut built, &out, std::time::Instant::now(), |_| {}).unwrap();
    assert_eq!(s.status, shell_build::RunStatus::Complete, "{tag}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let _ = std::fs::remove_dir_all(&out);
    let loads = s.steps.iter().map(|st| (st.step, st.load_factor)).collect();
    (json["critical_points"].as_array().unwrap().clone(), loads)
}

#[test]
fn load_control_reports_one_bifurcation_at_the_euler_load_on_two_grids() {
    // Steps of 0.1 to 0.97, then every 0.0025 from 0.97 to 1.03 (`stops`), then to 1.2.
    let stops: Vec<String> = (0..=24)
        .map(|k| format!("{:.4}", 0.97 + 0.0025 * k as f64))
        .collect();
    let steps = format!(
        "final_load = 1.2\ninitial_step = 0.1\nmin_step = 0.001\nmax_step = 0.1\nstops = [{}]",
        stops.join(", ")
    );
    let mut brackets = Vec::new();
    for grid in [[17, 3], [33, 5]] {
        let (cps, loads) = run(&strip(grid, &steps), &format!("{}x{}", grid[0], grid[1]));
        assert_eq!(cps.len(), 1, "{grid:?}: {cps:?}");
        let c = &cps[0];
        assert_eq!(c["kind"], "bifurcation", "{c}");
        assert!(c["stiffness_parameter"].is_null(), "{c}");
        let sign = c["determinant_sign"].as_array().unwrap();
        assert_eq!(sign[0].as_f64().unwrap(), -sign[1].as_f64().unwrap(), "{c}");
        let between: Vec<usize> = c["between_steps"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as usize)
            .collect();
        let lf: Vec<f64> = c["load_factors"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        // Consecutive converged steps, with those loads; none below.
        assert_eq!(between[1], between[0] + 1, "{c}");
        let load_of = |k: usize| loads.iter().find(|s| s.0 == k).map(|s| s.1);
        assert_eq!(load_of(between[0]), Some(lf[0]), "{c}");
        assert_eq!(load_of(between[1]), Some(lf[1]), "{c}");
        assert!(lf[1] - lf[0] <= 0.0025 + 1e-12, "{c}");
        brackets.push((grid, lf[0], lf[1]));
    }
    println!("bifurcation brackets (load factor / Euler): {brackets:?}");
    // The two grids' brackets differ by at most one step of 0.0025 (the discretisation error
    // of the buckling load is below the bracket width), and each brackets the Euler load
    // within that measured difference plus one step: 0.5 %.
    let (a, b) = (brackets[0], brackets[1]);
    assert!((a.1 - b.1).abs() <= 0.0025 + 1e-12, "{brackets:?}");
    for (grid, lo, hi) in brackets {
        assert!(lo <= 1.005 && hi >= 0.995, "{grid:?}: [{lo}, {hi}]");
    }
}

#[test]
fn arc_length_reports_a_bifurcation_not_a_limit_point() {
    // On the straight path q·K⁻¹q keeps its sign (the buckling mode is orthogonal to the axial
    // load) while det K changes sign: a bifurcation, with the load factor still rising.
    let steps = "final_load = 1.2\ninitial_step = 0.1\nmin_step = 0.001\nmax_step = 0.1\n\
                 control = \"arc-length\"\narc_length = 1e-4";
    let text = strip([17, 3], steps);
    let case = parse_shell_case(&text, Path::new("column.toml")).unwrap();
    let mut built = shell_build::build(&case).unwrap();
    let pattern = built.problem.pattern().clone();
    let mut solver =
        LinearSolver::new(&pattern, Method::auto(&pattern), SolverOptions::default()).unwrap();
    let n = built.problem.n_dofs();
    let arc = ArcLength {
        end: 1.2,
        initial_length: 1e-4,
        max_length: 1e-4,
        ..ArcLength::default()
    };
    let mut seen = Vec::new();
    let out = built
        .newton
        .run_arc_length(
            &mut built.problem,
            &pattern,
            &mut solver,
            &vec![0.0; n],
            &arc,
            |c| seen.push(c.clone()),
        )
        .unwrap();
    assert_eq!(out.critical, seen);
    assert_eq!(seen.len(), 1, "{seen:?}");
    let c = &seen[0];
    assert_eq!(c.kind, CriticalKind::Bifurcation, "{c}");
    let [s0, s1] = c.stiffness.unwrap();
    assert!(s0 > 0.0 && s1 > 0.0, "{c}");
    assert_eq!(
        c.determinant_sign[0],
        c.determinant_sign[1].map(|d| -d),
        "{c}"
    );
    assert!(c.loads[0] < c.loads[1], "{c}");
    // The bracket holds the Euler load (the grid's buckling load is within 0.5 % of it, test
    // above; an arc-length step here is about 0.1 in λ).
    assert!(c.loads[0] <= 1.005 && c.loads[1] >= 0.995, "{c}");
    let loads: Vec<f64> = out.report.converged_steps().map(|s| s.load).collect();
    assert!(loads.windows(2).all(|w| w[1] > w[0]), "{loads:?}");
    assert!(
        c.to_string()
            .starts_with("bifurcation between converged steps"),
        "{c}"
    );
}
