//! The normalised director field (`integration.director = "normalised"`, docs/stability.md §9)
//! through the case file and the command line: a bad value names the key; the reduced plastic
//! hemisphere's derivatives three ways through `shelldsa dsa` (the kernels' and the model's
//! checks: tests/unit_director.rs, tests/shell_tangent_fast.rs, tests/point_sensitivity.rs).

use serde_json::Value;
use shelldsa::io::shell_case::parse_shell_case;
use shelldsa::shell::point::DirectorField;
use std::path::{Path, PathBuf};

#[path = "common/cli.rs"]
mod cli;
use cli::dsa_case_text;

#[path = "common/dsa_checks.rs"]
mod dsa_checks;
use dsa_checks::assert_three_ways;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The reduced plastic hemisphere (9 × 9, 14 steps to P = 35) with `lines` added to its
/// `[integration]` table.
fn hemisphere(lines: &str) -> String {
    let t = std::fs::read_to_string(root().join("verification/hemisphere-plastic-dsa/ci.toml"))
        .unwrap();
    // The case names the interpolated field (its README's tables); `lines` replace that.
    let named =
        "director = \"interpolated\"   # the field this case's README tables were measured with\n";
    assert!(t.contains(&format!("[integration]\n{named}")));
    t.replacen(named, &format!("{lines}\n"), 1)
}

#[test]
fn the_key_selects_the_field_and_a_bad_value_is_named() {
    let path = Path::new("case.toml");
    let default = parse_shell_case(&hemisphere(""), path).unwrap();
    assert_eq!(default.integration.director, DirectorField::Normalised);
    let n = parse_shell_case(&hemisphere("director = \"normalised\""), path).unwrap();
    assert_eq!(n.integration.director, DirectorField::Normalised);
    let i = parse_shell_case(&hemisphere("director = \"interpolated\""), path).unwrap();
    assert_eq!(i.integration.director, DirectorField::Interpolated);
    let e = parse_shell_case(&hemisphere("director = \"unit\""), path)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("integration.director") && e.contains("\"unit\"") && e.contains("normalised"),
        "{e}"
    );
}

/// `shelldsa dsa` on the reduced hemisphere with the normalised field, its four design
/// variables (R, φ1 shape, t, σ0 after first yield in step 11): continuum = dual, dual =
/// central differences of complete re-runs, Taylor rate 2.
#[test]
fn normalised_hemisphere_three_ways_through_the_cli() {
    let (code, out) = dsa_case_text(
        &root().join("target/normalised-director-tests"),
        "case",
        &hemisphere("director = \"normalised\""),
        &[],
    );
    assert_eq!(code, 0);
    let a: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("sensitivity.json")).unwrap())
            .unwrap();
    assert!(a["dual_state_mismatch"].as_f64().unwrap() < 1e-12);
    assert_eq!(assert_three_ways(&a), 4);
}

/// A run that stops under load control with the interpolated field and no stabilisation says
/// that the normalised field exists (the semi-cylinder on 9 × 17 without its stabilisation stops
/// at the checkerboard's false limit point at P/P_max = 0.12, docs/stability.md §2); with
/// the stabilisation on it completes, and a completed run prints no such note. The stopped run
/// also warns of the checkerboard from the director changes it left unresolved (84 % there,
/// 90 % of a step's, against at most 13 % with the stabilisation: `DirectorResolution`).
#[test]
fn a_stopped_interpolated_run_points_to_the_normalised_field() {
    let text = std::fs::read_to_string(root().join("verification/semi-cylinder/case.toml"))
        .unwrap()
        .replace("grid = [17, 33]", "grid = [9, 17]")
        .replace("final_load = 1000.0", "final_load = 150.0")
        .replace("plot = true", "plot = false");
    let start = text.find("stops = [").unwrap();
    let end = start + text[start..].find(']').unwrap() + 1;
    let text = format!("{}stops = [50.0, 100.0]{}", &text[..start], &text[end..]);
    let line = text
        .lines()
        .find(|l| l.starts_with("director_stabilisation = "))
        .unwrap()
        .to_string();
    let dir = root().join("target/normalised-director-note");
    std::fs::create_dir_all(&dir).unwrap();
    let run = |name: &str, text: &str| {
        let case = dir.join(format!("{name}.toml"));
        std::fs::write(&case, text).unwrap();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_shelldsa"))
            .args(["run", case.to_str().unwrap(), "--out"])
            .arg(dir.join(name))
            .output()
            .unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
        )
    };
    let shares = |name: &str, key: &str| -> Vec<f64> {
        let json: Value = serde_json::from_str(
            &std::fs::read_to_string(dir.join(name).join("results.json")).unwrap(),
        )
        .unwrap();
        json["steps"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|s| s["converged"] == true)
            .map(|s| s[key].as_f64().unwrap())
            .collect()
    };
    let (code, stdout) = run("stopped", &text.replace(&line, ""));
    assert_eq!(code, Some(3), "{stdout}");
    assert!(
        stdout.contains("note: ") && stdout.contains("integration.director = \"normalised\""),
        "{stdout}"
    );
    let s = shares("stopped", "director_unresolved");
    let threshold = shelldsa::shell::stabilisation::UNRESOLVED_SHARE_WARNING;
    let step_threshold = shelldsa::shell::stabilisation::UNRESOLVED_STEP_SHARE_WARNING;
    assert!(
        s.last().is_some_and(|&v| v > threshold),
        "the stopped run's last converged step: {s:?}"
    );
    assert!(
        stdout.contains("warning: at converged step") && stdout.contains("checkerboard"),
        "{stdout}"
    );
    let (code, stdout) = run("complete", &text);
    assert_eq!(code, Some(0), "{stdout}");
    assert!(!stdout.contains("note: "), "{stdout}");
    assert!(!stdout.contains("warning: "), "{stdout}");
    let s = shares("complete", "director_unresolved");
    assert!(
        !s.is_empty() && s.iter().all(|&v| v < threshold),
        "the stabilised run: {s:?}"
    );
    let s = shares("complete", "director_unresolved_step");
    assert!(
        !s.is_empty() && s.iter().all(|&v| v < step_threshold),
        "the stabilised run's steps: {s:?}"
    );
}
