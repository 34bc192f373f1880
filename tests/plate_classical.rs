//! Square plates clamped and simply supported on all four edges (`verification/plate-clamped`,
//! `verification/plate-simply-supported`), run through `shelldsa run` as shipped, against the
//! classical central deflections of Timoshenko & Woinowsky-Krieger, Theory of Plates and Shells
//! (2nd ed., 1959): uniform load q, w = α q a⁴/D with α = 0.00126 (clamped) and 0.00406 (simply
//! supported); central point load P, w = β P a²/D with β = 0.00560 (clamped) and 0.01160
//! (simply supported). The uniform-load values are also checked against their four-digit values
//! (simply supported: the Navier series, 0.0040624; clamped: 0.0012653, Taylor & Govindjee
//! 2004, Comm. Numer. Meth. Eng. 20:757), which the printed three-digit ones round.
//!
//! The plates are thin (a/t = 100). The shell deforms in transverse shear: that adds
//! `M_c / (κ G t)` to the central deflection of the (hard) simply supported plate under a
//! uniform load (Marcus moment `M_c = 0.0736714 q a²`, Navier series): +0.052 % here; under a
//! point load the shear part grows with ln(a/h) (+0.03 % per halving of the spacing). Target:
//! 1 % of the reference; measured values and refinement in the READMEs.
//!
//! Each case has D = 1 (E = 1.092e7, ν = 0.3, t = 0.01, a = 1) and a load small enough for the
//! linear response (w/t ~ 1e-4).

use std::path::PathBuf;

#[path = "common/cli.rs"]
mod cli;
use cli::{last_monitor, run_case_text};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Run the case text `text` (written as `target/plate-classical/NAME/case.toml`) with the CLI;
/// the centre deflection `−u_z` of the last converged step.
fn centre_deflection(name: &str, text: &str) -> f64 {
    let dir = root().join("target").join("plate-classical").join(name);
    let r = run_case_text(&dir, text, &["--quiet"]);
    assert_eq!(r["status"], "complete", "{name}");
    -last_monitor(&r, "centre")[2]
}

/// The shipped case `verification/NAME/case.toml`, with the `(from, to)` line replacements.
fn shipped(name: &str, edits: &[(&str, &str)]) -> String {
    let mut text =
        std::fs::read_to_string(root().join("verification").join(name).join("case.toml")).unwrap();
    for (from, to) in edits {
        assert!(text.contains(from), "{name}: no `{from}`");
        text = text.replacen(from, to, 1);
    }
    // No VTU in the test runs.
    text.replacen("vtu = true", "vtu = false", 1)
}

/// Check `w` (per unit load: coefficient × load × a^k / D with D = a = 1) against the
/// references, 1 % each.
fn assert_within_1_percent(what: &str, w: f64, references: &[(&str, f64)]) {
    for (source, c) in references {
        let e = w / c - 1.0;
        println!("{what}: {w:.6e} against {source} {c}: {:+.3} %", 100.0 * e);
        assert!(e.abs() <= 0.01, "{what}: {w} against {source} {c}");
    }
}

const Q: f64 = 1e-3;
const P: f64 = 1e-3;

/// The shipped cases as they are (31 × 31 particles, uniform load). Measured: clamped +0.72 %
/// against 0.00126 (+0.30 % against 0.0012653), simply supported +0.18 % (+0.12 %; README).
#[test]
fn uniform_load_on_clamped_and_simply_supported_square_plates() {
    let w = centre_deflection("clamped-uniform", &shipped("plate-clamped", &[])) / Q;
    assert_within_1_percent(
        "clamped, uniform load",
        w,
        &[
            ("Timoshenko & Woinowsky-Krieger", 0.00126),
            ("Taylor & Govindjee", 0.0012653),
        ],
    );
    let w = centre_deflection("ss-uniform", &shipped("plate-simply-supported", &[])) / Q;
    assert_within_1_percent(
        "simply supported, uniform load",
        w,
        &[
            ("Timoshenko & Woinowsky-Krieger", 0.00406),
            ("Navier series", 0.0040624),
        ],
    );
}

/// The same plates under a central point load, on 21 × 21 particles (reduced for CI time; the
/// READMEs give 31 × 31 and 41 × 41). Measured: clamped +0.61 %, simply supported +0.21 %.
#[test]
fn central_point_load_on_clamped_and_simply_supported_square_plates() {
    let point = "kind = \"point-force\"\nat = [0.5, 0.5]\nforce = [0.0, 0.0, -1e-3]";
    let edits = [
        ("grid = [31, 31]", "grid = [21, 21]"),
        ("kind = \"gravity\"\nper_area = [0.0, 0.0, -1e-3]", point),
    ];
    let w = centre_deflection("clamped-point", &shipped("plate-clamped", &edits)) / P;
    assert_within_1_percent(
        "clamped, central point load",
        w,
        &[("Timoshenko & Woinowsky-Krieger", 0.00560)],
    );
    let w = centre_deflection("ss-point", &shipped("plate-simply-supported", &edits)) / P;
    assert_within_1_percent(
        "simply supported, central point load",
        w,
        &[("Timoshenko & Woinowsky-Krieger", 0.01160)],
    );
}

/// The clamped plate in the thin limit, a/t = 1000 (t = 0.001, E scaled by 1000 to keep D = 1),
/// 31 × 31 particles as shipped: no shear locking. Measured +1.52 % over the thin-plate value
/// (from above, converging: +3.73 / +0.80 % on 21² / 41²; README); 3 × 3 Gauss points lock at
/// −22 %, which the 2 % bound rejects.
#[test]
fn clamped_plate_at_a_over_t_1000_does_not_lock() {
    let edits = [
        ("thickness = 0.01 ", "thickness = 0.001 "),
        ("young = 1.092e7", "young = 1.092e10"),
    ];
    let w = centre_deflection("clamped-thin", &shipped("plate-clamped", &edits)) / Q;
    let e = w / 0.0012653 - 1.0;
    println!(
        "clamped, a/t = 1000: {w:.6e}, {:+.3} % against Taylor & Govindjee",
        100.0 * e
    );
    assert!(e.abs() <= 0.02, "{w}");
}
