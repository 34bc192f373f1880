//! Finite-difference re-runs that must reach a load level their direct attempt cannot: the
//! thickness of the reduced bending case (`verification/cylindrical-bending-dsa/ci.toml`) at
//! h/τ = 2e-4. The `t + h` re-run meets a singular tangent at the separation level (the sheet
//! resting on the die alone, its free end's `u_z` unrestrained once the predictor lifts it
//! off); the re-runs replay the nominal run's levels and reach that one by continuation
//! (`steps.stop_failure`), so the study completes and compares equal levels.

//!
//! Without contact too: the nonlinear hemisphere stepped adaptively between `stops` (its own
//! case file, reduced), whose finite-difference runs converge to tighter tolerances than the
//! plain run and would otherwise cut and grow their steps elsewhere.

#[path = "common/cli.rs"]
mod cli;
use cli::dsa_case_text;
use serde_json::Value;
use std::path::PathBuf;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `shelldsa dsa` on `case` (written to `target/dsa-replay-tests/NAME.toml`, output in
/// `target/dsa-replay-tests/NAME`), which must complete without a failure: its
/// sensitivity.json.
fn dsa_complete(name: &str, case: &str) -> Value {
    let (code, out) = dsa_case_text(&root().join("target/dsa-replay-tests"), name, case, &[]);
    let s: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("sensitivity.json")).unwrap())
            .unwrap();
    assert_eq!(
        s["failures"].as_array().unwrap().len(),
        0,
        "{}",
        s["failures"]
    );
    assert_eq!(code, 0);
    s
}

/// Over the steps not flagged by the active-set test: the largest `|FD / continuum − 1|` of
/// the components above 1e-3 of the step's largest, the components compared, and the flagged
/// steps.
fn continuum_vs_fd(steps: &[Value]) -> (f64, usize, usize) {
    let (mut worst, mut compared, mut flagged) = (0.0f64, 0, 0);
    for st in steps {
        if st["fd_flagged"][0].as_bool().unwrap() {
            flagged += 1;
            continue;
        }
        let m = st["monitors"].as_object().unwrap();
        let big = m
            .values()
            .map(|c| c["continuum"].as_f64().unwrap().abs())
            .fold(0.0, f64::max);
        for c in m.values() {
            let g = c["continuum"].as_f64().unwrap();
            if g.abs() < 1e-3 * big {
                continue;
            }
            worst = worst.max((c["fd_central"][0].as_f64().unwrap() / g - 1.0).abs());
            compared += 1;
        }
    }
    (worst, compared, flagged)
}

#[test]
fn thickness_re_runs_reach_the_separation_level() {
    let ci = std::fs::read_to_string(root().join("verification/cylindrical-bending-dsa/ci.toml"))
        .unwrap();
    // The die variables' tables and the [dsa] table replaced by the thickness alone, with the
    // continuum method (the finite differences' reference) and one step size.
    let head = &ci[..ci
        .find("\n[[design]]\n")
        .expect("ci.toml has [[design]] tables")
        + 1];
    let case = format!(
        "{head}[[design]]\nname = \"t\"\nkind = \"thickness\"\nfd_steps = [2e-4]\n\n\
         [dsa]\nmethods = [\"continuum\", \"fd\"]\n\
         monitors = [\"center.uz\", \"mid.uz\", \"arm.uz\", \"edge.uz\", \"edge.ux\"]\n"
    );
    let s = dsa_complete("ci_thickness", &case);
    let v = &s["variables"][0];
    let steps = v["steps"].as_array().unwrap();
    // Every level of the nominal run, the separation (t ≈ 1.2467) and the end included.
    let loads = s["loads"].as_array().unwrap();
    assert_eq!(steps.len(), loads.len());
    assert_eq!(loads.last().unwrap().as_f64(), Some(1.4));
    let (worst, compared, _) = continuum_vs_fd(steps);
    println!("t: continuum vs FD {worst:.2e} over {compared} unflagged components");
    assert!(compared > 0);
    // Measured 8.4e-6 at h/τ = 2e-4 (the truncation error of the central difference, O(h²),
    // plus the re-runs' convergence noise): bound 5e-5, six times that.
    assert!(worst <= 5e-5, "continuum vs FD {worst:e}");
}

/// The nonlinear hemisphere (`verification/hemisphere-nonlinear/case.toml`) at 7 × 7 to
/// P = 60, adaptive steps between the stops at 10, 20, …, 60, thickness by the continuum method
/// and central differences: the re-runs replay the plain run's levels (15 steps of the
/// finite-difference runs against the plain run's 13 without the replay, the first differing
/// level 48.44 against 50).
#[test]
fn adaptive_steps_without_contact_are_replayed() {
    let mut case =
        std::fs::read_to_string(root().join("verification/hemisphere-nonlinear/case.toml"))
            .unwrap();
    let mut set = |from: &str, to: &str| {
        assert!(case.contains(from), "case file lacks {from:?}");
        case = case.replacen(from, to, 1);
    };
    set("grid = [25, 25]", "grid = [7, 7]");
    set("final_load = 200.0", "final_load = 60.0");
    set("plot = true", "plot = false");
    let (i, j) = (
        case.find("stops = [").unwrap(),
        case.find("190.0, 200.0]").unwrap() + "190.0, 200.0]".len(),
    );
    case.replace_range(i..j, "stops = [10.0, 20.0, 30.0, 40.0, 50.0, 60.0]");
    case.push_str(
        "\n[[design]]\nname = \"t\"\nkind = \"thickness\"\nfd_steps = [1e-4]\n\n\
         [dsa]\nmethods = [\"continuum\", \"fd\"]\n",
    );
    assert!(!case.contains("initial_step = max_step"));
    let s = dsa_complete("hemisphere_adaptive", &case);
    let loads: Vec<f64> = s["loads"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l.as_f64().unwrap())
        .collect();
    // Adaptive: more levels than the stops, and every stop among them.
    assert!(loads.len() > 6, "{loads:?}");
    for stop in [10.0, 20.0, 30.0, 40.0, 50.0, 60.0] {
        assert!(loads.contains(&stop), "{stop} not in {loads:?}");
    }
    let steps = s["variables"][0]["steps"].as_array().unwrap();
    assert_eq!(steps.len(), loads.len());
    let (worst, compared, flagged) = continuum_vs_fd(steps);
    assert_eq!(flagged, 0);
    assert!(compared > 0);
    println!("t: continuum vs FD {worst:.2e} over {} steps", steps.len());
    // Measured 1.5e-8 at h/τ = 1e-4: the central difference's O(h²) truncation and the
    // re-runs' convergence noise (1e-12 of the force over h = 1e-4 τ, about 1e-8 relative).
    // Bound 1e-6; a re-run on other levels than the plain run's is off by far more.
    assert!(worst <= 1e-6, "continuum vs FD {worst:e}");
}
