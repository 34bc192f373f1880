//! Boundary entries that overlap at corners and edges (the same component held twice) on a
//! square plate: every combination of clamped, simply supported, fixed, prescribed and
//! symmetry entries builds a non-singular system, with the repeated rows merged, and runs
//! through `shelldsa run`; a component held at two different values is refused by
//! `shelldsa check` and `shelldsa run` before any analysis, with an error naming both entries.
//!
//! The plate: a = 1, t = 0.01, E = 1.092e7, ν = 0.3 (D = 1), 9 × 9 particles, uniform load
//! 1e-3 per unit area (one linear step).

use shelldsa::io::shell_build::check_boundary;
use shelldsa::io::shell_case::parse_shell_case;
use std::path::{Path, PathBuf};

#[path = "common/cli.rs"]
mod cli;
use cli::{cli, last_monitor};

/// A plate case with the given `[[boundary]]` tables, on `[0, side]²` (a quarter plate has
/// side 0.5), monitoring the point `centre` (parameter coordinates).
fn plate(boundary: &str, side: f64, centre: [f64; 2]) -> String {
    format!(
        r#"thickness = 0.01

[problem]
kind = "shell"
title = "square plate, overlapping boundary entries"

[surface]
type = "rectangle"
origin = [0.0, 0.0, 0.0]
edge_u = [{side}, 0.0, 0.0]
edge_v = [0.0, {side}, 0.0]

[particles]
grid = [9, 9]

[kernel]
basis = "quadratic"
support = 3.0

[integration]
cells = "per-particle-spacing"
gauss = 2
thickness_points = 2
thickness_rule = "gauss"
vci = "second"

[material]
young = 1.092e7
poisson = 0.3
sigma0 = 1e30
hardening = 0.0
beta = 1.0

{boundary}
[[load]]
kind = "gravity"
per_area = [0.0, 0.0, -1e-3]

[steps]
initial_step = 1.0
min_step = 0.1
max_step = 1.0
final_load = 1.0

[[monitor]]
name = "centre"
at = [{}, {}]

[output]
vtu = false
subdivide = 1
"#,
        centre[0], centre[1]
    )
}

fn entry(kind: &str, edge: &str) -> String {
    format!("[[boundary]]\nkind = \"{kind}\"\nedge = \"{edge}\"\n\n")
}

/// Write `text` as `target/plate-constraints/NAME/case.toml`; its path and output directory.
fn write_case(name: &str, text: &str) -> (PathBuf, PathBuf) {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("target")
        .join("plate-constraints")
        .join(name);
    let out = dir.join("out");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let case = dir.join("case.toml");
    std::fs::write(&case, text).unwrap();
    (case, out)
}

/// The centre deflection `−u_z` of the last converged step of `out/results.json`.
fn centre_deflection(out: &Path) -> f64 {
    let text = std::fs::read_to_string(out.join("results.json")).unwrap();
    let r: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(r["status"], "complete", "{}", out.display());
    -last_monitor(&r, "centre")[2]
}

/// Check and run the case `text`; the number of rows merged, and the centre deflection.
fn check_and_run(name: &str, text: &str) -> (usize, f64) {
    let (case, out) = write_case(name, text);
    let parsed = parse_shell_case(text, &case).unwrap();
    let set = check_boundary(&parsed).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(cli(&["check", case.to_str().unwrap()]), 0, "{name}: check");
    let code = cli(&[
        "run",
        case.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{name}: run");
    let w = centre_deflection(&out);
    println!(
        "{name}: {} rows, {} merged, w_centre = {w:.6e}",
        set.rows.len(),
        set.merged.len()
    );
    (set.merged.len(), w)
}

/// Four clamped edges: the two edges meeting at each corner hold all five components of the
/// corner particle, so 4 × 5 rows repeat and are merged; the same for four simply supported
/// edges with the three displacements (4 × 3). Both run, and the clamped plate is stiffer.
#[test]
fn four_clamped_and_four_simply_supported_edges_merge_their_corners() {
    let edges = ["u-min", "u-max", "v-min", "v-max"];
    let clamped: String = edges.iter().map(|e| entry("clamped", e)).collect();
    let (merged, w_c) = check_and_run("clamped4", &plate(&clamped, 1.0, [0.5, 0.5]));
    assert_eq!(merged, 20);
    let ss: String = edges.iter().map(|e| entry("simply-supported", e)).collect();
    let (merged, w_s) = check_and_run("ss4", &plate(&ss, 1.0, [0.5, 0.5]));
    assert_eq!(merged, 12);
    // Classical ratio 0.00126 / 0.00406 ≈ 0.31 (Timoshenko & Woinowsky-Krieger); the
    // verification cases check each value to 1 %, here only the order.
    assert!(w_c > 0.0 && w_s > 2.0 * w_c, "w_c = {w_c}, w_s = {w_s}");
}

/// Two edges meeting at a corner, in every pairing of clamped, simply supported and a `fixed`
/// edge, plus a `fixed` point and a consistent `prescribed` point at the corner particle: each
/// component held twice is one row.
#[test]
fn pairs_of_entries_meeting_at_a_corner_merge_the_shared_components() {
    let fixed_uz = "[[boundary]]\nkind = \"fixed\"\nedge = \"v-min\"\ncomponents = [\"uz\"]\n\n";
    let fixed_point = "[[boundary]]\nkind = \"fixed\"\nat = [0.0, 0.0]\ncomponents = [\"ux\", \"uz\", \"rot2\"]\n\n";
    let prescribed_zero =
        "[[boundary]]\nkind = \"prescribed\"\nat = [0.0, 0.0]\ncomponent = \"uz\"\nvalue = 0.0\n\n";
    let cases: [(&str, String, usize); 6] = [
        (
            "clamped-clamped",
            entry("clamped", "u-min") + &entry("clamped", "v-min"),
            5,
        ),
        (
            "clamped-ss",
            entry("clamped", "u-min") + &entry("simply-supported", "v-min"),
            3,
        ),
        (
            "ss-ss",
            entry("simply-supported", "u-min") + &entry("simply-supported", "v-min"),
            3,
        ),
        ("clamped-fixed-uz", entry("clamped", "u-min") + fixed_uz, 1),
        (
            "clamped-fixed-point",
            entry("clamped", "u-min") + &entry("clamped", "v-min") + fixed_point,
            5 + 3,
        ),
        (
            "clamped-prescribed-zero",
            entry("clamped", "u-min") + prescribed_zero,
            1,
        ),
    ];
    for (name, boundary, want) in cases {
        let (merged, w) = check_and_run(name, &plate(&boundary, 1.0, [1.0, 1.0]));
        assert_eq!(merged, want, "{name}");
        assert!(w > 0.0, "{name}: w = {w}");
    }
}

/// A quarter plate (the full plate's quarter [0, 1/2]², the centre at the corner (1, 1)) with
/// two clamped edges and two symmetry planes: the clamped edges' rows at the particles on the
/// planes that the symmetry already meets (`ū·n_s`, the rotation about the in-plane axis
/// normal to the plane) are merged, and the centre deflection equals the full plate's with the
/// same particle spacing (9 × 9 on the quarter, 17 × 17 on the full plate): the images are the
/// full plate's particles mirrored and the quadrature points mirror each other, so the two
/// discretisations are the same up to the order of sums. Without VCI (whose boundary rule
/// treats the symmetry edges as edges of the domain: 2e-4 apart with it, README of
/// `verification/plate-clamped`) measured equal to the last bit on 21 × 21; asserted to 1e-10
/// (round-off of the solves, ~1e-15, with margin).
#[test]
fn quarter_plate_with_two_clamped_edges_and_two_symmetry_planes_runs_as_the_full_plate() {
    let sym = |edge: &str, normal: [f64; 3]| {
        format!(
            "[[boundary]]\nkind = \"symmetry\"\nedge = \"{edge}\"\nnormal = {normal:?}\n\
             point = [0.5, 0.5, 0.0]\n\n"
        )
    };
    let no_vci = |t: String| t.replacen("vci = \"second\"", "vci = \"off\"", 1);
    let quarter = entry("clamped", "u-min")
        + &entry("clamped", "v-min")
        + &sym("u-max", [1.0, 0.0, 0.0])
        + &sym("v-max", [0.0, 1.0, 0.0]);
    let text = no_vci(plate(&quarter, 0.5, [1.0, 1.0]));
    let (merged, w_q) = check_and_run("quarter-clamped", &text);
    // The corner of the two clamped edges: 5 rows. At each of the two corners where a clamped
    // edge meets a plane, the particle is on the plane: its clamped rows `ū·n_s` and the
    // rotation about the in-plane axis normal to the plane fold to zero (antisymmetric across
    // the plane): 2 + 2.
    assert_eq!(merged, 9);
    let full: String = ["u-min", "u-max", "v-min", "v-max"]
        .iter()
        .map(|e| entry("clamped", e))
        .collect();
    let text = no_vci(plate(&full, 1.0, [0.5, 0.5]).replace("grid = [9, 9]", "grid = [17, 17]"));
    let (_, w_f) = check_and_run("full-clamped-17", &text);
    println!(
        "quarter {w_q:.15e}, full {w_f:.15e}, {:+.3e}",
        w_q / w_f - 1.0
    );
    assert!(
        (w_q / w_f - 1.0).abs() <= 1e-10,
        "quarter {w_q}, full {w_f}"
    );
}

/// A component held at two values: a clamped edge and a prescribed `u_z = 0.01` at its corner
/// particle; a symmetry plane with normal x and a prescribed `u_x` on it. `check` refuses both
/// (exit 1) and so does `run`, before any analysis (no results.json); the error names both
/// entries.
#[test]
fn a_component_held_at_two_values_is_refused_up_front_naming_both_entries() {
    let clash = entry("clamped", "u-min")
        + "[[boundary]]\nkind = \"prescribed\"\nat = [0.0, 0.5]\ncomponent = \"uz\"\nvalue = 0.01\n\n";
    let sym_clash = "[[boundary]]\nkind = \"symmetry\"\nedge = \"u-max\"\nnormal = [1.0, 0.0, 0.0]\n\
                     point = [1.0, 0.0, 0.0]\n\n"
        .to_string()
        + &entry("clamped", "u-min")
        + "[[boundary]]\nkind = \"prescribed\"\nat = [1.0, 0.5]\ncomponent = \"ux\"\nvalue = 0.01\n\n";
    for (name, boundary, first, second) in [
        (
            "clash-prescribed",
            clash,
            "boundary[0] (clamped, edge u-min)",
            "boundary[1] (prescribed uz = 0.01 at [0.0, 0.5])",
        ),
        (
            "clash-symmetry",
            sym_clash,
            "boundary[0] (symmetry, edge u-max)",
            "boundary[2] (prescribed ux = 0.01 at [1.0, 0.5])",
        ),
    ] {
        let text = plate(&boundary, 1.0, [0.5, 0.5]);
        let (case, out) = write_case(name, &text);
        let parsed = parse_shell_case(&text, &case).unwrap();
        let e = check_boundary(&parsed).unwrap_err().to_string();
        println!("{name}: {e}");
        assert!(e.contains(first) && e.contains(second), "{name}: {e}");
        assert_eq!(cli(&["check", case.to_str().unwrap()]), 1, "{name}: check");
        let code = cli(&[
            "run",
            case.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(code, 1, "{name}: run");
        assert!(
            !out.join("results.json").exists(),
            "{name}: analysis started"
        );
    }
}

/// A singular tangent names the unknown: a plate held only at its centre in z (free to slide
/// and turn in its plane) stops at the first step (exit 3) with the linear solver's message
/// extended by the particle, its parameter coordinates and the component of the offending DOF;
/// a multiplier is named by its constraint row.
#[test]
fn a_singular_tangent_names_the_particle_and_component_of_the_dof() {
    let held =
        "[[boundary]]\nkind = \"fixed\"\nat = [0.5, 0.5]\ncomponents = [\"uz\"]\n\n".to_string();
    let text = plate(&held, 1.0, [0.5, 0.5]);
    let (case, out) = write_case("singular", &text);
    let code = cli(&[
        "run",
        case.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 3, "the analysis should stop");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let status = r["status"].as_str().unwrap();
    println!("{status}");
    assert!(status.contains("singular matrix"), "{status}");
    assert!(
        status.contains(" is particle ")
            && status.contains("(u, v) = [")
            && status.contains(", component "),
        "{status}"
    );

    let clamped = plate(&entry("clamped", "u-min"), 1.0, [0.5, 0.5]);
    let parsed = parse_shell_case(&clamped, &case).unwrap();
    let built = shelldsa::io::shell_build::build(&parsed).unwrap();
    let n_q = built.problem.n_generalised();
    let d = built.problem.describe_dof(n_q);
    assert!(
        d.starts_with("the multiplier of constraint `boundary[0] (clamped, edge u-min)"),
        "{d}"
    );
    let d = built.problem.describe_dof(5 * 10 + 2);
    assert_eq!(d, "particle 10 at (u, v) = [0.125, 0.125], component ū_z");
}
