//! Contact in shell case files (`[[tool]]`, `[contact]`, `[[load]] scaling`): a good file reads
//! into the expected tools and settings, every wrong entry is rejected naming the dotted key,
//! the value and the expectation, and a run with a tool that never touches the sheet completes
//! with a warning in results.json.

use shelldsa::contact::Side;
use shelldsa::io::shell_case::{parse_shell_case, LoadScalingSpec, PenaltySpec, ShellCase};
use shelldsa::io::CaseError;
use shelldsa::shell::contact::{ContactFaces, DEFAULT_PENALTY_FACTOR};
use std::path::{Path, PathBuf};

/// A 4 × 1 elastic plate on z = 0 (u along x, v along y), a cylinder punch above it and a flat
/// die under it; `CONTACT` and `TOOLS` are replaced by the tests.
const BASE: &str = r#"
thickness = 0.1
[problem]
kind = "shell"
title = "plate and tools"
[surface]
type = "rectangle"
origin = [0.0, 0.0, 0.0]
edge_u = [4.0, 0.0, 0.0]
edge_v = [0.0, 1.0, 0.0]
[particles]
grid = [9, 3]
[kernel]
basis = "quadratic"
support = 3.0
[integration]
cells = "per-particle-spacing"
gauss = 2
thickness_points = 3
thickness_rule = "lobatto"
[material]
young = 1000.0
poisson = 0.3
sigma0 = 1e30
hardening = 0.0
beta = 1.0
[[boundary]]
kind = "fixed"
everywhere = true
components = ["ux", "uy"]
[[load]]
kind = "gravity"
per_area = [0.0, 0.0, -1e-3]
scaling = "constant"
[steps]
initial_step = 0.25
min_step = 0.01
max_step = 0.25
predictor = "zero"
residual_atol = 1e-12  # 2.5e-10 of the weight 4e-3: the steps after the first change nothing
[[monitor]]
name = "mid"
at = [0.5, 0.5]
CONTACT
[[tool]]
name = "punch"
side = "positive"
[tool.surface]
type = "cylinder-sector"
origin = [2.0, -1.0, 1.05]
axis = [0.0, 1.0, 0.0]
reference = [1.0, 0.0, 0.0]
radius = 1.0
angle_deg = [0.0, 180.0]
length = [0.0, 3.0]
[tool.path]
PUNCH_PATH
[[tool]]
name = "die"
side = "positive"
[tool.surface]
type = "rectangle"
origin = [-1.0, -1.0, -0.0499]
edge_u = [6.0, 0.0, 0.0]
edge_v = [0.0, 3.0, 0.0]
[tool.path]
keys = [{ t = 0.0, translation = [0.0, 0.0, 0.0] }]
"#;

const GOOD_CONTACT: &str = r#"[contact]
faces = "bottom"
penalty = 5e4
release = "punch""#;

const GOOD_PATH: &str = "keys = [{ t = 0.0, translation = [0.0, 0.0, 0.0] }, \
     { t = 1.0, translation = [0.0, 0.0, -0.2], rotation = [0.0, 0.1, 0.0] }]\npivot = [2.0, 0.0, 1.05]";

fn text(contact: &str, punch_path: &str) -> String {
    BASE.replace("CONTACT", contact)
        .replace("PUNCH_PATH", punch_path)
}

fn parse(t: &str) -> Result<ShellCase, CaseError> {
    parse_shell_case(t, Path::new("tools.toml"))
}

/// The good file: tools in order with their side, path keys, pivot; contact settings; the
/// load's constant scaling.
#[test]
fn good_file_reads_tools_and_contact() {
    let c = parse(&text(GOOD_CONTACT, GOOD_PATH)).unwrap();
    assert_eq!(c.tools.len(), 2);
    assert_eq!(c.tools[0].name, "punch");
    assert_eq!(c.tools[0].side, Side::Positive);
    assert_eq!(c.tools[0].path.pivot(), [2.0, 0.0, 1.05]);
    let keys = c.tools[0].path.keys();
    assert_eq!(keys.len(), 2);
    assert_eq!(keys[1].translation, [0.0, 0.0, -0.2]);
    assert_eq!(keys[1].rotation, [0.0, 0.1, 0.0]);
    assert_eq!(keys[0].rotation, [0.0; 3], "rotation defaults to zero");
    assert_eq!(c.tools[1].surface.kind(), "rectangle");
    let s = c.contact.as_ref().unwrap();
    assert_eq!(s.faces, ContactFaces::Bottom);
    assert_eq!(s.penalty, PenaltySpec::Value(5e4));
    assert_eq!(s.release.as_deref(), Some("punch"));
    assert_eq!(c.load_scaling, vec![LoadScalingSpec::Constant]);

    // Defaults without [contact]: both faces, ω = DEFAULT_PENALTY_FACTOR · E / t.
    let c = parse(&text("", "stroke = [0.0, 0.0, -0.2]")).unwrap();
    let s = c.contact.unwrap();
    assert_eq!(s.faces, ContactFaces::Both);
    assert_eq!(s.penalty, PenaltySpec::Factor(DEFAULT_PENALTY_FACTOR));
    assert_eq!(
        s.penalty.omega(1000.0, 0.1),
        DEFAULT_PENALTY_FACTOR * 1000.0 / 0.1
    );
    assert_eq!(s.release, None);
    // The stroke shorthand: 0 at t = 0, the stroke at t = 1, rest outside.
    assert_eq!(c.tools[0].path.position(0.5).0, [0.0, 0.0, -0.1]);
    assert_eq!(c.tools[0].path.position(3.0).0, [0.0, 0.0, -0.2]);
}

/// `(key, value, expectation fragment)` of the `Invalid` error of `t`.
fn invalid(t: &str) -> (String, String, String) {
    match parse(t) {
        Err(CaseError::Invalid {
            key,
            value,
            expected,
            ..
        }) => (key, value, expected),
        other => panic!("expected an Invalid error, got {other:?}"),
    }
}

fn assert_invalid(t: &str, key: &str, value: &str, expected: &str) {
    let (k, v, e) = invalid(t);
    assert_eq!(k, key, "key (value {v}, expected {e})");
    assert_eq!(v, value, "value of {k}");
    assert!(
        e.contains(expected),
        "`{k}`: expected {e:?} to contain {expected:?}"
    );
    // The message names all three.
    let msg = parse(t).unwrap_err().to_string();
    assert!(msg.contains(key) && msg.contains(value), "{msg}");
}

#[test]
fn penalty_must_be_positive() {
    for (line, key) in [
        ("penalty = 0.0", "contact.penalty"),
        ("penalty = -3.0", "contact.penalty"),
        ("penalty_factor = 0.0", "contact.penalty_factor"),
        ("penalty_factor = -1.0", "contact.penalty_factor"),
    ] {
        let v = line.split(" = ").nth(1).unwrap().trim_end_matches(".0");
        let t = text(&format!("[contact]\n{line}"), GOOD_PATH);
        assert_invalid(&t, key, v, "a finite number > 0");
    }
    let t = text("[contact]\npenalty = 1.0\npenalty_factor = 2.0", GOOD_PATH);
    assert_invalid(
        &t,
        "contact.penalty",
        "(given with `penalty_factor`)",
        "not both",
    );
}

#[test]
fn unknown_release_tool_and_faces() {
    let t = text("[contact]\nrelease = \"ram\"", GOOD_PATH);
    assert_invalid(&t, "contact.release", "\"ram\"", "[\"punch\", \"die\"]");
    let t = text("[contact]\nfaces = \"upper\"", GOOD_PATH);
    assert_invalid(
        &t,
        "contact.faces",
        "\"upper\"",
        "\"top\", \"bottom\" or \"both\"",
    );
}

#[test]
fn duplicate_and_empty_tool_names() {
    let t = text("", GOOD_PATH).replace("name = \"die\"", "name = \"punch\"");
    assert_invalid(
        &t,
        "tool[1].name",
        "\"punch\"",
        "not used by an earlier tool (tool[0])",
    );
    let t = text("", GOOD_PATH).replace("name = \"die\"", "name = \" \"");
    assert_invalid(&t, "tool[1].name", "\" \"", "a non-empty name");
}

#[test]
fn path_times_must_increase() {
    let p = "keys = [{ t = 0.0, translation = [0.0, 0.0, 0.0] }, \
             { t = 1.0, translation = [0.0, 0.0, -0.2] }, { t = 1.0, translation = [0.0, 0.0, 0.0] }]";
    assert_invalid(
        &text("", p),
        "tool[0].path.keys[2].t",
        "1",
        "a time greater than tool[0].path.keys[1].t = 1",
    );
    let p = "keys = [{ t = 0.5, translation = [0.0, 0.0, 0.0] }, { t = 0.2, translation = [0.0, 0.0, -0.2] }]";
    assert_invalid(
        &text("", p),
        "tool[0].path.keys[1].t",
        "0.2",
        "strictly increasing",
    );
    assert_invalid(
        &text("", "keys = []"),
        "tool[0].path.keys",
        "[]",
        "at least one key",
    );
    let p = "stroke = [0.0, 0.0, -1.0]\nkeys = [{ t = 0.0, translation = [0.0, 0.0, 0.0] }]";
    assert_invalid(
        &text("", p),
        "tool[0].path.stroke",
        "(given with `keys`)",
        "not both",
    );
    assert_invalid(
        &text("", "pivot = [0.0, 0.0, 0.0]"),
        "tool[0].path",
        "(no `stroke` or `keys`)",
        "`stroke = [dx, dy, dz]`",
    );
    let p = "stroke = [0.0, 0.0, -1.0]\npivot = [1.0, 0.0, 0.0]";
    assert_invalid(
        &text("", p),
        "tool[0].path.pivot",
        "[1, 0, 0]",
        "no `pivot` with `stroke`",
    );
}

#[test]
fn side_surface_contact_without_tools_and_load_scaling() {
    let t = text("", GOOD_PATH).replacen("side = \"positive\"", "side = \"inside\"", 1);
    assert_invalid(&t, "tool[0].side", "\"inside\"", "\"positive\"");
    let t = text("", GOOD_PATH).replace("radius = 1.0", "radius = -1.0");
    assert_invalid(&t, "tool[0].surface", "(table)", "a valid surface");
    // [contact] with no tool: cut the file before the first [[tool]].
    let full = text(GOOD_CONTACT, GOOD_PATH);
    let t = &full[..full.find("[[tool]]").unwrap()];
    assert_invalid(t, "contact", "(given)", "at least one [[tool]]");
    let t = text("", GOOD_PATH).replace("scaling = \"constant\"", "scaling = \"fixed\"");
    assert_invalid(
        &t,
        "load[0].scaling",
        "\"fixed\"",
        "\"proportional\" (default) or \"constant\"",
    );
    // Unknown keys in the new tables are TOML errors naming the key.
    let t = text("", GOOD_PATH).replace("side = \"positive\"", "side = \"positive\"\nsid = 1");
    let msg = parse(&t).unwrap_err().to_string();
    assert!(msg.contains("sid"), "{msg}");
}

/// A run whose punch stays far above the sheet: it completes (the die and the constant
/// weight hold the plate), the punch never touches the sheet, and results.json says so in
/// `"warnings"`; every converged step lists both tools and the active points, and the die
/// carries the whole weight (the only vertical force: 4 × 1 × 1e-3 = 4e-3) to the residual
/// tolerance (rtol 1e-8 of the force scale, checked to 1e-6 relative).
#[test]
fn tool_that_never_touches_is_a_warning() {
    let p = "stroke = [0.0, 0.0, 0.5]"; // upwards, away from the sheet
    let t = text("[contact]\npenalty = 1e4\nrelease = \"punch\"", p);
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let dir = root.join("target/contact-case-tests/never-touches");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let case_path = dir.join("case.toml");
    std::fs::write(&case_path, t.replace("[output]", "")).unwrap();
    let out = dir.join("out");
    let code = shelldsa::cli::main_with_args(
        [
            "shelldsa",
            "run",
            case_path.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]
        .map(String::from),
    );
    assert_eq!(code, 0);
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let w = r["warnings"].as_array().unwrap();
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(w[0].as_str().unwrap().contains("\"punch\""), "{w:?}");
    assert!(r["separation"].is_null());
    let steps = r["steps"].as_array().unwrap();
    assert_eq!(steps.last().unwrap()["load_factor"].as_f64(), Some(1.0));
    for s in steps.iter().filter(|s| s["converged"] == true) {
        assert_eq!(s["tools"]["punch"]["active_points"].as_u64(), Some(0));
        let die = s["tools"]["die"]["active_points"].as_u64().unwrap();
        assert!(die > 0);
        assert_eq!(s["active_contact_points"].as_u64(), Some(die));
        let fz = s["tools"]["die"]["force"][2].as_f64().unwrap();
        assert!((fz + 4e-3).abs() <= 1e-6 * 4e-3, "die force {fz}");
        // The plate settles onto the die without rotating: its directors change by round-off
        // only (rms 7e-16), which has no unresolved share (it read 0.92 and warned of a
        // checkerboard).
        assert!(s["director_unresolved"].is_null(), "{s}");
        assert!(s["director_unresolved_step"].is_null(), "{s}");
    }
    let csv = std::fs::read_to_string(out.join("tool_forces.csv")).unwrap();
    assert!(csv.starts_with("step,t,stroke,punch_x,"), "{csv}");
    assert_eq!(csv.lines().count(), 1 + steps.len());
    assert!(out.join("force_stroke.png").exists());
}

/// A penalty too stiff for the sheet's bending stiffness: the bending case
/// (`verification/cylindrical-bending`) with the default penalty (`ω = 10 E/t`, 7e5 N/mm³,
/// instead of the case's 1000) stops in its second step, where every attempt, down to a step of
/// 2e-5, changes the contact active set and fails. The run says so and names the penalty key
/// (and not the director-field note of a stopped run without contact, which would mislead
/// here). About 2 s.
#[test]
fn a_stop_where_every_attempt_switches_contact_names_the_penalty() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let text =
        std::fs::read_to_string(root.join("verification/cylindrical-bending/case.toml")).unwrap();
    assert!(
        text.contains("\npenalty = 1000.0"),
        "the case's penalty line"
    );
    let text = text
        .replace("\npenalty = 1000.0", "\n")
        .replace("vtu = true", "vtu = false");
    let dir = root.join("target/contact-case-stiff-penalty");
    std::fs::create_dir_all(&dir).unwrap();
    let case = dir.join("case.toml");
    std::fs::write(&case, text).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_shelldsa"))
        .args(["run", case.to_str().unwrap(), "--quiet", "--out"])
        .arg(dir.join("out"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(3), "{stdout}");
    assert!(
        stdout.contains("changed the contact active set")
            && stdout.contains("penalty_factor = 1e1"),
        "{stdout}"
    );
    assert!(!stdout.contains("director field"), "{stdout}");
    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/results.json")).unwrap())
            .unwrap();
    let failed: Vec<&serde_json::Value> = results["steps"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|s| s["converged"] == false)
        .collect();
    assert!(failed.len() >= 5, "{} failed attempts", failed.len());
    for a in failed.iter().rev().take(5) {
        assert!(a["active_set_iterations"].as_u64().unwrap() >= 1, "{a}");
    }
}

/// A tool placed through the sheet is refused before an analysis, naming the tool and its
/// deepest gap; the die set flush with the sheet (overlapping it by 1e-4 of the 0.1
/// thickness) is the penalty's to resolve and passes.
#[test]
fn tool_through_the_undeformed_sheet_is_refused_before_an_analysis() {
    use shelldsa::io::shell_build::{build, tools_clear_of_the_sheet};
    let good = parse(&text(GOOD_CONTACT, GOOD_PATH)).unwrap();
    assert!(tools_clear_of_the_sheet(&build(&good).unwrap()).is_ok());
    // The punch's axis at z = 0.5, radius 1: its lowest line at z = −0.5, through the plate.
    let through = text(GOOD_CONTACT, GOOD_PATH).replacen(
        "origin = [2.0, -1.0, 1.05]",
        "origin = [2.0, -1.0, 0.5]",
        1,
    );
    let case = parse(&through).unwrap();
    let e = match tools_clear_of_the_sheet(&build(&case).unwrap()) {
        Ok(()) => panic!("passed a sheet with a tool through it"),
        Err(e) => e.to_string(),
    };
    println!("{e}");
    for want in [
        "tool `punch`",
        "already penetrates the undeformed sheet at t = 0",
        "expected a gap ≥ −1e-1",
    ] {
        assert!(e.contains(want), "error lacks {want:?}: {e}");
    }
}
