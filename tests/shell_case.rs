//! Shell case files (`shelldsa::io::shell_case`): a good file reads into the expected typed
//! case, the documented example (docs/case-format.md) stays valid, and wrong files are
//! rejected with errors that name the key, the value and what was expected.

use shelldsa::io::shell_case::{
    parse_shell_case, Boundary, CellLayout, Component, Load, Location, OutputSpec, PredictorKind,
    ShellCase,
};
use shelldsa::io::{parse_case, Case, CaseError};
use shelldsa::meshfree::quadrature::ThicknessRule;
use shelldsa::meshfree::Basis;
use shelldsa::meshfree::Edge;
use std::path::Path;

/// A clamped strip with every kind of entry the current build can also run.
const GOOD: &str = r#"
thickness = 0.1

[problem]
kind = "shell"
title = "strip"

[surface]
type = "rectangle"
origin = [0.0, 0.0, 0.0]
edge_u = [12.0, 0.0, 0.0]
edge_v = [0.0, 1.0, 0.0]

[particles]
grid = [13, 3]

[kernel]
basis = "quadratic"
support = 3.0

[integration]
cells = "per-particle-spacing"
subdivide = 2
gauss = 4
thickness_points = 5
thickness_rule = "lobatto"

[material]
young = 1.2e6
poisson = 0.0
sigma0 = 100.0
hardening = 10.0
beta = 1.0

[[boundary]]
kind = "clamped"
edge = "u-min"

[[boundary]]
kind = "fixed"
at = [1.0, 0.0]
components = ["uy", "ux"]

[[load]]
kind = "point-force"
at = [1.0, 0.5]
force = [0.0, 0.0, 1.0]

[steps]
initial_step = 0.1
min_step = 0.001
max_step = 0.2

[[monitor]]
name = "tip"
at = [1.0, 0.5]
"#;

fn parse(text: &str) -> Result<ShellCase, CaseError> {
    parse_shell_case(text, Path::new("case.toml"))
}

/// The error message of `text` (which must be rejected).
fn err(text: &str) -> String {
    match parse(text) {
        Ok(_) => panic!("accepted a wrong case:\n{text}"),
        Err(e) => e.to_string(),
    }
}

/// `GOOD` with `from` replaced by `to` must be rejected with a message containing every one of
/// `want` (the key, the value, the expectation).
fn rejects(from: &str, to: &str, want: &[&str]) {
    assert!(GOOD.contains(from), "test set-up: {from:?} not in GOOD");
    let e = err(&GOOD.replacen(from, to, 1));
    println!("{e}");
    for w in want {
        assert!(e.contains(w), "error lacks {w:?}: {e}");
    }
}

#[test]
fn good_case_reads_into_the_typed_case_with_defaults() {
    let c = parse(GOOD).unwrap();
    assert_eq!(c.title, "strip");
    assert_eq!(c.thickness, 0.1);
    assert_eq!(c.surface.kind(), "rectangle");
    assert_eq!(c.particles.counts, [13, 3]);
    assert_eq!(c.particles.jitter, 0.0);
    assert_eq!(c.kernel.basis, Basis::Quadratic);
    assert_eq!(c.kernel.support, 3.0);
    assert_eq!(
        c.integration.cells,
        CellLayout::PerParticleSpacing { subdivide: 2 }
    );
    assert_eq!(c.integration.gauss, 4);
    assert_eq!(c.integration.thickness_rule, ThicknessRule::Lobatto(5));
    assert_eq!(c.material.shear_factor, 5.0 / 6.0);
    let c2 = parse(&GOOD.replacen(
        "cells = \"per-particle-spacing\"\nsubdivide = 2",
        "cells = [24, 4]",
        1,
    ))
    .unwrap();
    assert_eq!(c2.integration.cells, CellLayout::Counts([24, 4]));
    assert_eq!(
        c.boundary,
        vec![
            Boundary::Clamped { edge: Edge::UMin },
            Boundary::Fixed {
                location: Location::Point([1.0, 0.0]),
                components: vec![Component::Ux, Component::Uy],
            }
        ]
    );
    assert_eq!(
        c.loads,
        vec![Load::PointForce {
            at: [1.0, 0.5],
            force: [0.0, 0.0, 1.0]
        }]
    );
    // [steps] defaults.
    let s = c.steps;
    assert_eq!(
        (
            s.final_load,
            s.max_iterations,
            s.residual_rtol,
            s.energy_rtol
        ),
        (1.0, 20, 1e-8, 1e-14)
    );
    assert_eq!((s.cut_factor, s.grow_factor, s.predictor), (0.5, 1.5, None));
    assert_eq!(c.monitors.len(), 1);
    assert_eq!(c.output, OutputSpec::default());
    // The generic entry point dispatches on [problem] kind.
    match parse_case(GOOD, Path::new("case.toml")).unwrap() {
        Case::Shell(s) => assert_eq!(s.particles.counts, [13, 3]),
        other => panic!("{other:?}"),
    }
}

/// The annotated example of docs/case-format.md (the MacNeal–Harder hemisphere, reference
/// values §1) is a valid case: its symmetry planes pass the geometric check.
#[test]
fn documented_hemisphere_example_is_valid() {
    let doc =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/case-format.md"))
            .unwrap();
    let begin = doc
        .find("<!-- case-example: begin -->")
        .expect("begin marker");
    let end = doc.find("<!-- case-example: end -->").expect("end marker");
    let block = &doc[begin..end];
    let text = block
        .split_once("```toml\n")
        .and_then(|(_, rest)| rest.split_once("```"))
        .map(|(t, _)| t)
        .expect("a toml block between the markers");
    let c = parse(text).unwrap();
    assert_eq!(c.surface.kind(), "sphere-zone");
    assert_eq!(c.thickness, 0.04);
    assert_eq!(c.material.young, 6.825e7);
    assert_eq!(c.particles.counts, [17, 17]);
    let planes: Vec<(Edge, [f64; 3])> = c
        .boundary
        .iter()
        .filter_map(|b| match b {
            Boundary::Symmetry { edge, normal, .. } => Some((*edge, *normal)),
            _ => None,
        })
        .collect();
    assert_eq!(
        planes,
        vec![(Edge::UMin, [0.0, 1.0, 0.0]), (Edge::UMax, [1.0, 0.0, 0.0])]
    );
    assert_eq!(c.loads.len(), 2);
    assert_eq!(
        c.monitors
            .iter()
            .map(|m| m.name.as_str())
            .collect::<Vec<_>>(),
        ["A", "B"]
    );
    assert_eq!(c.output.subdivide, 2);
}

#[test]
fn symmetry_plane_point_defaults_to_the_edge_middle_and_normal_is_normalised() {
    let c = parse(&GOOD.replacen(
        "kind = \"clamped\"\nedge = \"u-min\"",
        "kind = \"symmetry\"\nedge = \"u-min\"\nnormal = [-2.0, 0.0, 0.0]",
        1,
    ))
    .unwrap();
    assert_eq!(
        c.boundary[0],
        Boundary::Symmetry {
            edge: Edge::UMin,
            point: [0.0, 0.5, 0.0],
            normal: [-1.0, 0.0, 0.0]
        }
    );
}

#[test]
fn wrong_top_level_and_discretisation_values_are_named() {
    rejects(
        "thickness = 0.1\n",
        "",
        &["`thickness`", "(missing)", "top-level"],
    );
    rejects(
        "thickness = 0.1",
        "thickness = -0.1",
        &["`thickness`", "-0.1", "> 0"],
    );
    rejects(
        "grid = [13, 3]",
        "grid = [1, 3]",
        &["`particles.grid[0]`", "= 1 ", ">= 2"],
    );
    rejects(
        "grid = [13, 3]",
        "grid = [13, 3]\njitter = 0.5",
        &["`particles.jitter`", "0.5", "[0, 0.5)"],
    );
    rejects(
        "basis = \"quadratic\"",
        "basis = \"quartic\"",
        &[
            "`kernel.basis`",
            "\"quartic\"",
            "\"quadratic\" or \"cubic\"",
        ],
    );
    rejects(
        "support = 3.0",
        "support = 0.0",
        &["`kernel.support`", "= 0 ", "> 0"],
    );
    rejects(
        "gauss = 4",
        "gauss = 11",
        &["`integration.gauss`", "11", "1..=10"],
    );
    rejects(
        "thickness_points = 5",
        "thickness_points = 1",
        &["`integration.thickness_points`", "= 1 ", "2..=7"],
    );
    // One Gauss point through the thickness: no bending stiffness (the plate's deflection
    // came out 146 times too large without a word).
    rejects(
        "thickness_points = 5\nthickness_rule = \"lobatto\"",
        "thickness_points = 1\nthickness_rule = \"gauss\"",
        &[
            "`integration.thickness_points`",
            "= 1 ",
            "2..=10",
            "no bending stiffness",
        ],
    );
    rejects(
        "thickness_rule = \"lobatto\"",
        "thickness_rule = \"simpson\"",
        &[
            "`integration.thickness_rule`",
            "simpson",
            "\"gauss\" or \"lobatto\"",
        ],
    );
    rejects(
        "cells = \"per-particle-spacing\"",
        "cells = \"per-cell\"",
        &["`integration.cells`", "per-cell", "per-particle-spacing"],
    );
    rejects(
        "cells = \"per-particle-spacing\"",
        "cells = 8",
        &["`integration.cells`", "= 8 ", "two integers"],
    );
    rejects(
        "cells = \"per-particle-spacing\"",
        "cells = [8, 0]",
        &["`integration.cells[1]`", "= 0 ", ">= 1"],
    );
    rejects(
        "cells = \"per-particle-spacing\"",
        "cells = [8, 2]",
        &["`integration.subdivide`", "per-particle-spacing"],
    );
    rejects(
        "poisson = 0.0",
        "poisson = 0.5",
        &["`material.poisson`", "0.5", "(-1, 0.5)"],
    );
}

#[test]
fn wrong_boundary_entries_are_named() {
    rejects(
        "edge = \"u-min\"",
        "edge = \"left\"",
        &["`boundary[0].edge`", "\"left\"", "\"u-min\""],
    );
    rejects(
        "kind = \"clamped\"",
        "kind = \"pinned\"",
        &["`boundary[0].kind`", "\"pinned\"", "simply-supported"],
    );
    rejects(
        "components = [\"uy\", \"ux\"]",
        "",
        &["`boundary[1].components`", "(missing)", "\"rot1\""],
    );
    rejects(
        "components = [\"uy\", \"ux\"]",
        "components = [\"uy\", \"uw\"]",
        &["`boundary[1].components[1]`", "\"uw\"", "\"uz\""],
    );
    rejects(
        "components = [\"uy\", \"ux\"]",
        "components = [\"uy\", \"uy\"]",
        &["`boundary[1].components[1]`", "each component once"],
    );
    rejects(
        "at = [1.0, 0.0]\ncomponents",
        "at = [1.0, 0.0]\nedge = \"v-min\"\ncomponents",
        &["`boundary[1].at`", "either `edge`, `at`"],
    );
    rejects(
        "kind = \"clamped\"\nedge = \"u-min\"",
        "kind = \"clamped\"\nedge = \"u-min\"\nnormal = [1.0, 0.0, 0.0]",
        &["`boundary[0].normal`", "no `normal` for kind = \"clamped\""],
    );
    // The plane y = 0 does not contain the edge u = 0 of the strip (which runs along y).
    rejects(
        "kind = \"clamped\"\nedge = \"u-min\"",
        "kind = \"symmetry\"\nedge = \"u-min\"\nnormal = [0.0, 1.0, 0.0]\npoint = [0.0, 0.0, 0.0]",
        &[
            "`boundary[0].normal`",
            "[0, 1, 0]",
            "containing edge u-min",
            "from the plane",
        ],
    );
    // The plane through the edge u = 0 tilted about it: contains the edge, not the normal.
    rejects(
        "kind = \"clamped\"\nedge = \"u-min\"",
        "kind = \"symmetry\"\nedge = \"u-min\"\nnormal = [1.0, 0.0, 1.0]\npoint = [0.0, 0.0, 0.0]",
        &[
            "`boundary[0].normal`",
            "contains the surface normal",
            "u-min",
        ],
    );
    rejects(
        "kind = \"fixed\"\nat = [1.0, 0.0]\ncomponents = [\"uy\", \"ux\"]",
        "kind = \"prescribed\"\nat = [1.0, 0.0]\ncomponent = \"rot1\"\nvalue = 0.1",
        &["`boundary[1].component`", "\"rot1\"", "a displacement"],
    );
    rejects(
        "kind = \"fixed\"\nat = [1.0, 0.0]\ncomponents = [\"uy\", \"ux\"]",
        "kind = \"prescribed\"\nat = [1.0, 0.0]\ncomponent = \"uz\"",
        &["`boundary[1].value`", "(missing)"],
    );
}

#[test]
fn wrong_loads_steps_monitors_and_output_are_named() {
    rejects(
        "at = [1.0, 0.5]\nforce",
        "at = [1.5, 0.5]\nforce",
        &["`load[0].at`", "[1.5, 0.5]", "domain [0, 1] × [0, 1]"],
    );
    rejects(
        "kind = \"point-force\"",
        "kind = \"pressure\"",
        &["`load[0].at`", "no `at` for kind = \"pressure\""],
    );
    rejects(
        "kind = \"point-force\"\nat = [1.0, 0.5]\nforce = [0.0, 0.0, 1.0]",
        "kind = \"moment\"\nedge = \"u-max\"",
        &["`load[0].per_length`", "(missing)"],
    );
    rejects(
        "kind = \"point-force\"",
        "kind = \"traction\"",
        &["`load[0].kind`", "\"traction\"", "\"gravity\""],
    );
    rejects(
        "min_step = 0.001",
        "min_step = 0.5",
        &["`steps.initial_step`", "0.1", ">= steps.min_step = 0.5"],
    );
    rejects(
        "max_step = 0.2",
        "max_step = 0.2\npredictor = \"linear\"",
        &["`steps.predictor`", "\"linear\"", "\"secant\""],
    );
    rejects(
        "max_step = 0.2",
        "max_step = 0.2\ncut_factor = 1.0",
        &["`steps.cut_factor`", "(0, 1)"],
    );
    rejects(
        "max_step = 0.2",
        "max_step = 0.2\nfinal_load = -1.0",
        &["`steps.final_load`", "-1", "> 0"],
    );
    rejects(
        "[[monitor]]\nname = \"tip\"",
        "[[monitor]]\nname = \"root\"\nat = [0.0, 0.5]\n[[monitor]]\nname = \"root\"",
        &[
            "`monitor[1].name`",
            "\"root\"",
            "not used by an earlier monitor",
        ],
    );
    rejects(
        "[[monitor]]",
        "[output]\nevery = 0\n[[monitor]]",
        &["`output.every`", "= 0 ", ">= 1"],
    );
    let c = parse(&GOOD.replacen(
        "max_step = 0.2",
        "max_step = 0.2\npredictor = \"secant\"",
        1,
    ))
    .unwrap();
    assert_eq!(c.steps.predictor, Some(PredictorKind::Secant));
}

#[test]
fn syntax_unknown_keys_and_surfaces_are_reported_by_name() {
    // A typo: the TOML layer names the unknown key (and the keys it expected).
    rejects("support = 3.0", "suport = 3.0", &["suport", "support"]);
    // An unknown table.
    rejects("[steps]", "[solver]\nmethod = \"lu\"\n[steps]", &["solver"]);
    // A wrong type.
    rejects("young = 1.2e6", "young = \"steel\"", &["steel"]);
    // A wrong array length.
    rejects("at = [1.0, 0.5]\nforce", "at = [1.0]\nforce", &["at"]);
    // The surface's own validation names its field.
    rejects(
        "edge_v = [0.0, 1.0, 0.0]",
        "edge_v = [24.0, 0.0, 0.0]",
        &["`surface`", "edge_v"],
    );
    // A boundary entry with a key of no kind at all.
    rejects("edge = \"u-min\"", "edge = \"u-min\"\nside = 1", &["side"]);
}

#[test]
fn stops_are_read_and_checked() {
    assert!(parse(GOOD).unwrap().steps.stops.is_empty(), "default: none");
    let c = parse(&GOOD.replacen(
        "max_step = 0.2",
        "max_step = 0.2\nfinal_load = 2.0\nstops = [0.25, 0.5, 2.0]",
        1,
    ))
    .unwrap();
    assert_eq!(c.steps.stops, vec![0.25, 0.5, 2.0]);
    rejects(
        "max_step = 0.2",
        "max_step = 0.2\nstops = [0.5, 0.4]",
        &["`steps.stops[1]`", "0.4", "(0.5, steps.final_load = 1]"],
    );
    rejects(
        "max_step = 0.2",
        "max_step = 0.2\nstops = [0.0]",
        &["`steps.stops[0]`", "(0, steps.final_load = 1]"],
    );
    rejects(
        "max_step = 0.2",
        "max_step = 0.2\nstops = [0.5, 1.5]",
        &["`steps.stops[1]`", "1.5", "steps.final_load = 1]"],
    );
    rejects(
        "max_step = 0.2",
        "max_step = 0.2\nstops = [nan]",
        &["`steps.stops[0]`", "NaN", "a finite load factor"],
    );
    rejects(
        "max_step = 0.2",
        "max_step = 0.2\nstops = 0.5",
        &["stops", "sequence"],
    );
}

/// `GOOD` as a plane problem: `uy` and `rot1` held on every particle, the clamp holding the
/// other three components, the point condition only `ux`.
fn plane_strip() -> String {
    GOOD.replacen(
        "kind = \"clamped\"\nedge = \"u-min\"",
        "kind = \"fixed\"\neverywhere = true\ncomponents = [\"rot1\", \"uy\"]\n\n\
         [[boundary]]\nkind = \"fixed\"\nedge = \"u-min\"\ncomponents = [\"ux\", \"uz\", \"rot2\"]",
        1,
    )
    .replacen("components = [\"uy\", \"ux\"]", "components = [\"ux\"]", 1)
}

#[test]
fn components_held_everywhere_are_read_and_not_held_twice() {
    let c = parse(&plane_strip()).unwrap();
    assert_eq!(
        c.boundary[0],
        Boundary::Fixed {
            location: Location::Everywhere,
            components: vec![Component::Uy, Component::Rot1],
        }
    );
    let key_err = |text: String, want: &[&str]| {
        let e = err(&text);
        println!("{e}");
        for w in want {
            assert!(e.contains(w), "error lacks {w:?}: {e}");
        }
    };
    // A clamped edge holds uy again.
    key_err(
        GOOD.replacen(
            "[[boundary]]\nkind = \"clamped\"",
            "[[boundary]]\nkind = \"fixed\"\neverywhere = true\ncomponents = [\"uy\"]\n\n\
             [[boundary]]\nkind = \"clamped\"",
            1,
        ),
        &[
            "`boundary[1].kind`",
            "\"clamped\" (holds \"uy\")",
            "boundary[0] (everywhere = true)",
        ],
    );
    // The point condition holds uy again.
    key_err(
        plane_strip().replacen("components = [\"ux\"]", "components = [\"ux\", \"uy\"]", 1),
        &["`boundary[2].components`", "\"fixed\" (holds \"uy\")"],
    );
    // A prescribed rotation is not a displacement; a prescribed uy is held twice.
    key_err(
        plane_strip()
            .replacen(
                "at = [1.0, 0.0]\ncomponents = [\"ux\"]",
                "at = [1.0, 0.0]\ncomponent = \"uy\"\nvalue = 0.1",
                1,
            )
            .replacen(
                "kind = \"fixed\"\nat = [1.0, 0.0]",
                "kind = \"prescribed\"\nat = [1.0, 0.0]",
                1,
            ),
        &["`boundary[2].component`", "\"prescribed\" (holds \"uy\")"],
    );
    // Where: exactly one of edge, at, everywhere = true.
    key_err(
        plane_strip().replacen(
            "everywhere = true",
            "everywhere = true\nedge = \"u-max\"",
            1,
        ),
        &[
            "`boundary[0].everywhere`",
            "given with `edge`",
            "not two of them",
        ],
    );
    key_err(
        plane_strip().replacen("everywhere = true", "everywhere = false", 1),
        &["`boundary[0].edge`", "false", "`everywhere = true`"],
    );
    key_err(
        GOOD.replacen(
            "kind = \"clamped\"\nedge = \"u-min\"",
            "kind = \"clamped\"\nedge = \"u-min\"\neverywhere = true",
            1,
        ),
        &[
            "`boundary[0].everywhere`",
            "no `everywhere` for kind = \"clamped\"",
        ],
    );
}

#[test]
fn a_symmetry_row_made_only_of_held_components_is_rejected() {
    // A square rotated by 45° about z: its edge u-min runs along (1, 1, 0), so the symmetry
    // plane through it has the normal (1, −1, 0) (not a coordinate axis: a multiplier row
    // ux − uy = 0 on its particles). With ux and uy held everywhere that row repeats theirs.
    let square = GOOD
        .replacen("edge_u = [12.0, 0.0, 0.0]", "edge_u = [1.0, -1.0, 0.0]", 1)
        .replacen("edge_v = [0.0, 1.0, 0.0]", "edge_v = [1.0, 1.0, 0.0]", 1)
        .replacen(
            "kind = \"clamped\"\nedge = \"u-min\"",
            "kind = \"symmetry\"\nedge = \"u-min\"\nnormal = [1.0, -1.0, 0.0]\n\
             point = [0.0, 0.0, 0.0]\n\n[[boundary]]\nkind = \"fixed\"\neverywhere = true\n\
             components = [\"ux\", \"uy\"]",
            1,
        )
        .replacen("components = [\"uy\", \"ux\"]", "components = [\"uz\"]", 1);
    let e = err(&square);
    println!("{e}");
    assert!(e.contains("`boundary[0].normal`") && e.contains("not held on every particle"));
    // With only ux held the row reduces to −uy = 0 on those particles, independent of the
    // held rows: accepted.
    parse(&square.replacen("components = [\"ux\", \"uy\"]", "components = [\"ux\"]", 1)).unwrap();
}

#[test]
fn load_steps_are_required_with_load_stepping_and_not_with_arc_length() {
    for key in ["initial_step", "min_step", "max_step"] {
        let line = GOOD
            .lines()
            .find(|l| l.starts_with(key))
            .expect("test set-up: the key in GOOD");
        rejects(
            &format!("{line}\n"),
            "",
            &[
                &format!("`steps.{key}`"),
                "(missing)",
                "required with control = \"load\"",
            ],
        );
    }
    // Arc-length continuation does not use them: left out, the case reads.
    let steps = "[steps]\ninitial_step = 0.1\nmin_step = 0.001\nmax_step = 0.2\n";
    assert!(GOOD.contains(steps), "test set-up");
    let arc = GOOD.replace(
        steps,
        "[steps]\ncontrol = \"arc-length\"\narc_length = 0.1\n",
    );
    let c = parse(&arc).unwrap();
    assert_eq!(c.steps.arc_length, Some([0.1, 1e-5, 0.1]));
}

/// Supports too small for the basis: the build's error names `kernel.support` and its value,
/// wherever the shape functions fail (here at a boundary point of the VCI contour integrals,
/// with linear supports of one spacing: two particles cover a point of the edge).
#[test]
fn supports_too_small_name_the_support_and_its_value() {
    let text = GOOD.replacen(
        "basis = \"quadratic\"\nsupport = 3.0",
        "basis = \"linear\"\nsupport = 1.0",
        1,
    );
    assert_ne!(text, GOOD, "test set-up: the kernel lines moved");
    let case = parse(&text).expect("a valid case file");
    let e = match shelldsa::io::shell_build::build(&case) {
        Ok(_) => panic!("built a model whose supports do not cover the basis"),
        Err(e) => e.to_string(),
    };
    println!("{e}");
    for want in [
        "`kernel.support`",
        "1 (particle spacings)",
        "VCI",
        "the linear basis needs at least 3",
    ] {
        assert!(e.contains(want), "error lacks {want:?}: {e}");
    }
}
