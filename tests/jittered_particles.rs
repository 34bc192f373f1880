//! The cubic basis. The MacNeal–Harder hemisphere (`verification/hemisphere-linear`, R/t = 250,
//! 17 × 17) on particles jittered by 0.2 spacings. With the quadratic basis and 2 × 2 Gauss points per cell
//! the jittered set locks in membrane (−29 % with this seed, −22 % with another; the case's
//! README); the cubic basis with supports of 3.5 spacings follows the reference. Reference: the
//! radial displacement at the load point, 0.0935 per unit load (`../shared/reference-values.md`
//! §1), which the case's unit load and material give as 9.35e-5.

use serde_json::Value;
use std::path::PathBuf;

#[path = "common/cli.rs"]
mod cli;
use cli::{dsa_case_text, last_monitor, run_case_text};

#[path = "common/dsa_checks.rs"]
mod dsa_checks;
use dsa_checks::assert_three_ways;

const REFERENCE: f64 = 9.35e-5;

/// u_x at A of the shipped case with `edits` applied, on particles jittered by 0.2 spacings.
fn jittered_ux(name: &str, edits: &[(&str, &str)]) -> f64 {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut text =
        std::fs::read_to_string(root.join("verification/hemisphere-linear/case.toml")).unwrap();
    let jitter = ("grid = [17, 17]", "grid = [17, 17]\njitter = 0.2\nseed = 5");
    for (from, to) in std::iter::once(&jitter).chain(edits) {
        assert!(text.contains(from), "no `{from}`");
        text = text.replacen(from, to, 1);
    }
    let text = text.replacen("vtu = true", "vtu = false", 1);
    let dir = root.join("target").join("jittered-particles").join(name);
    let r = run_case_text(&dir, &text, &["--quiet"]);
    assert_eq!(r["status"], "complete");
    last_monitor(&r, "A")[0]
}

#[test]
fn the_cubic_basis_does_not_lock_on_jittered_particles() {
    let quadratic = jittered_ux("quadratic", &[]) / REFERENCE - 1.0;
    let cubic = jittered_ux(
        "cubic",
        &[
            ("basis = \"quadratic\"", "basis = \"cubic\""),
            ("support = 3.0", "support = 3.5"),
        ],
    ) / REFERENCE
        - 1.0;
    println!(
        "jittered hemisphere, 17 × 17: quadratic {:+.2} %, cubic {:+.2} %",
        100.0 * quadratic,
        100.0 * cubic
    );
    // Measured −1.74 % (another seed −0.73 %, 25 × 25 −0.01 %; the regular grid −0.68 %);
    // 2.5 % holds the seeds' spread and rejects the quadratic basis' −29 %.
    assert!(cubic.abs() <= 0.025, "cubic basis: {:+.2} %", 100.0 * cubic);
}

/// The cubic basis in the three derivative paths, on particles jittered by 0.2 spacings:
/// `shelldsa dsa` on the reduced elastoplastic hemisphere
/// (`verification/hemisphere-plastic-dsa/ci.toml`: 9 × 9, R, φ1, t, σ0) with the cubic basis on
/// supports of 3.5 spacings: continuum = dual, dual = central differences of complete re-runs,
/// Taylor rate 2 at every step with a rate. On this set σ0's derivative is exactly 0 at the
/// step before its first yield while Newton's intermediate iterates did yield; with the re-runs
/// converged only to the case's tolerance their iteration error, smooth in τ, made a remainder
/// of 2.5e-12 |ψ| that fell as h (a fitted rate of 1.005). Converged further it is at round-off
/// and is reported with no rate (`fd::RERUN_RESIDUAL_RTOL`, `TaylorFit::roundoff`).
#[test]
fn cubic_basis_three_ways_through_the_cli() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut text =
        std::fs::read_to_string(root.join("verification/hemisphere-plastic-dsa/ci.toml")).unwrap();
    for (from, to) in [
        ("basis = \"quadratic\"", "basis = \"cubic\""),
        ("support = 3.0", "support = 3.5"),
        ("# jitter = 0.2", "jitter = 0.2"),
        ("# seed = 7", "seed = 5"),
    ] {
        assert!(text.contains(from), "no `{from}`");
        text = text.replacen(from, to, 1);
    }
    let (code, out) = dsa_case_text(&root.join("target/jittered-particles"), "dsa", &text, &[]);
    assert_eq!(code, 0);
    let a: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("sensitivity.json")).unwrap())
            .unwrap();
    assert_eq!(assert_three_ways(&a), 4);
}
