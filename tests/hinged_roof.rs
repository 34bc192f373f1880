//! Reduced `verification/hinged-roof` (Sze, Liu & Lo 2004 §3.8, h = 12.7): 9 × 9 particles up to
//! the deflection 13.5, past the limit point, by displacement control (the reaction is the
//! load) and by arc-length continuation (the limit point reported). Full path, refinement and
//! figures: `verification/hinged-roof/README.md`.

use shelldsa::io::shell_build;
use shelldsa::io::shell_case::parse_shell_case;
use shelldsa::solver::{
    ArcLength, CriticalKind, CriticalPoint, FailureReason, LinearSolver, Method,
};
use shelldsa::solver::{NonlinearProblem, SolverOptions};
use std::path::Path;

#[path = "common/case_run.rs"]
mod case_run;
use case_run::{run_complete, shipped_case};

#[path = "common/load_path.rs"]
mod load_path;
use load_path::{extreme_points, load_maximum, vertex};

const SZE_LIMIT: f64 = 0.7421; // P/P_max at the limit point (Sze 2004 §3.8 table)
const P_MAX: f64 = 3000.0;

fn case_text() -> String {
    let text = shipped_case("hinged-roof");
    let start = text.find("stops = [").unwrap();
    let end = start + text[start..].find(']').unwrap() + 1;
    // Sze's deflections 9.339, 10.358, 11.293, 12.141, 12.903 (÷ 30) and the end at 13.5.
    let stops = "stops = [0.3113, 0.3452666667, 0.3764333333, 0.4047, 0.4301, 0.45]";
    let text = format!("{}{}{}", &text[..start], stops, &text[end..]);
    text.replace("grid = [17, 17]", "grid = [9, 9]")
        .replace("final_load = 1.0", "final_load = 0.45")
}

#[test]
fn displacement_control_passes_the_limit_point_with_sze_limit_load() {
    let s = run_complete(&case_text(), "hinged-roof.toml");
    // (−W, P/P_max) per converged step; the reaction pushes down (negative), P = −4 R.
    let pts: Vec<(f64, f64)> = s
        .steps
        .iter()
        .map(|st| {
            assert_eq!(st.reactions.len(), 1);
            (-st.monitors[0][2], -4.0 * st.reactions[0].1 / P_MAX)
        })
        .collect();
    // The load rose and fell: the path went through the limit point.
    let i = load_maximum(&pts);
    // Its value: the vertex of the parabola through the extreme step and its neighbours.
    let (w_limit, limit) = vertex(&pts, i);
    println!("limit load {limit:.5} (Sze {SZE_LIMIT}) at W {w_limit:.3}");
    // Measured −0.27 % here, −0.12 to −0.17 % on 13², 17², 25² (README); 1 % is the margin.
    assert!((limit / SZE_LIMIT - 1.0).abs() < 0.01, "limit load {limit}");
    // At Sze's deflections 9.339 and 12.141 on either side (0.7246, 0.7286): measured −0.21 and
    // −0.46 % of P_max; within 1 % of P_max.
    for (w, p) in [(9.339, 0.7246), (12.141, 0.7286)] {
        let got = pts
            .iter()
            .find(|q| (q.0 - w).abs() < 1e-9)
            .expect("a stop at Sze's deflection")
            .1;
        assert!((got - p).abs() < 0.01, "W {w}: {got} against {p}");
    }
}

/// Limit load and minimum (P/P_max) of a 3-D continuum with the shell's hinge: CalculiX 2.20,
/// 16 × 16 × 6 C3D20R bricks, compressible neo-Hooke with the case's E and ν, each section's
/// thickness-average displacement held on the hinged edge
/// (`verification/hinged-roof/calculix/roof_ccx.py --grid 16 --edge d --layers 6
/// --material neo-hooke`; README, "Where the minimum's difference comes from").
const CONTINUUM_LIMIT: f64 = 0.7422;
const CONTINUUM_MINIMUM: f64 = 0.1683;

#[test]
fn displacement_control_through_the_minimum_matches_the_continuum_with_the_shells_hinge() {
    // 9 × 9 particles to −W = 21 (the minimum is at 19.5), with Sze's deflections around the
    // two extremes as stops.
    let text = case_text()
        .replace(
            "stops = [0.3113, 0.3452666667, 0.3764333333, 0.4047, 0.4301, 0.45]",
            "stops = [0.3113, 0.3452666667, 0.3764333333, 0.6099666667, 0.6342666667, \
             0.6617333333, 0.6923666667]",
        )
        .replace("final_load = 0.45", "final_load = 0.7");
    let s = run_complete(&text, "hinged-roof-min.toml");
    let pts: Vec<(f64, f64)> = std::iter::once((0.0, 0.0))
        .chain(
            s.steps
                .iter()
                .map(|st| (-st.monitors[0][2], -4.0 * st.reactions[0].1 / P_MAX)),
        )
        .collect();
    let (i_max, i_min) = extreme_points(&pts);
    let (limit, minimum) = (vertex(&pts, i_max).1, vertex(&pts, i_min).1);
    println!("limit {limit:.5}, minimum {minimum:.5}");
    // Measured on 9 × 9: −0.28 % and −0.00 % (17 × 17: −0.15 % and −0.12 %). The continuum's
    // own through-thickness error: its minimum 0.1685 with 4 bricks, 0.1683 with 6 (0.1 %).
    // Sze's tabulated minimum, 0.1729, is 2.7 % above both: 1 % separates the two readings.
    assert!(
        (limit / CONTINUUM_LIMIT - 1.0).abs() < 0.005,
        "limit {limit}"
    );
    assert!(
        (minimum / CONTINUUM_MINIMUM - 1.0).abs() < 0.01,
        "minimum {minimum}"
    );
}

#[test]
fn arc_length_passes_the_limit_point_under_the_point_load_and_reports_it() {
    // The same roof under a point force −750 λ (P/4, λ = P/P_max) instead of the prescribed
    // deflection.
    let text = case_text();
    let start = text.find("[[boundary]]\nkind = \"prescribed\"").unwrap();
    let end = start + text[start..].find("value = -30.0").unwrap() + "value = -30.0".len();
    let text = format!(
        "{}[[load]]\nkind = \"point-force\"\nat = [0.0, 0.0]\nforce = [0.0, 0.0, -750.0]{}",
        &text[..start],
        &text[end..]
    );
    let start = text.find("stops = [").unwrap();
    let end = start + text[start..].find(']').unwrap() + 1;
    let text = format!(
        "{}control = \"arc-length\"\narc_length = 1.0\nmax_arc_length = 2.0{}",
        &text[..start],
        &text[end..]
    )
    .replace("final_load = 0.45", "final_load = 1.0");
    let case = parse_shell_case(&text, Path::new("hinged-roof-arc.toml")).unwrap();
    let mut built = shell_build::build(&case).unwrap();
    let pattern = built.problem.pattern().clone();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    let n = built.problem.n_dofs();
    // Stop after 36 attempts, beyond the limit point (measured: 24 steps reach λ = 0.7393,
    // 0.0008 below it).
    let arc = ArcLength {
        end: 1.0,
        initial_length: 1.0,
        max_length: 2.0,
        max_attempts: 36,
        ..ArcLength::default()
    };
    let mut seen: Vec<CriticalPoint> = Vec::new();
    let run = built.newton.run_arc_length(
        &mut built.problem,
        &pattern,
        &mut solver,
        &vec![0.0; n],
        &arc,
        |c| seen.push(c.clone()),
    );
    let report = match run {
        Ok(r) => r.report,
        Err(f) => {
            assert!(
                matches!(f.reason, FailureReason::TooManyAttempts(36)),
                "{}",
                f.reason
            );
            f.report
        }
    };
    let loads: Vec<f64> = report.converged_steps().map(|s| s.load).collect();
    println!("{seen:?}\n{loads:?}");
    assert_eq!(seen.len(), 1, "{seen:?}");
    let c = &seen[0];
    assert_eq!(c.kind, CriticalKind::LoadMaximum);
    // Both steps around the sign change carry loads within 1 % of Sze's limit load (the
    // displacement-controlled limit of the same model is 0.27 % below it).
    for l in c.loads {
        assert!((l / SZE_LIMIT - 1.0).abs() < 0.01, "{c}");
    }
    // The path then descends.
    assert!(*loads.last().unwrap() < c.loads[1]);
}
