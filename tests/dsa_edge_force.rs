//! The shape design derivative of an edge force (`[[load]] kind = "edge-force"`, a dead force
//! per unit initial length): only the arc-length element `|x̄⁰,t|` of the edge depends on the
//! design. Checked three ways on the load itself (hand-derived = dual on the seeded surface =
//! central differences of the load rebuilt on perturbed surfaces, for every design parameter
//! of a cylindrical panel and both edge directions), then through whole design sensitivity
//! runs of a cantilever strip against beam theory.

use nalgebra::Vector3;
use num_dual::Dual64;
use shelldsa::geometry::Surface;
use shelldsa::io::dsa_case::DsaMethod;
use shelldsa::io::dsa_study::{self, base_design, CaseAnalysis};
use shelldsa::io::shell_build;
use shelldsa::io::shell_case::{parse_shell_case, ShellCase};
use shelldsa::sensitivity::fd::Analysis;
use shelldsa::sensitivity::study;
use shelldsa::sensitivity::DesignVariable;
use shelldsa::shell::load::LoadState;
use std::path::Path;

/// A cylindrical panel (R = 3, 80° of arc, length 2), 7 × 5 particles, with edge forces on an
/// edge along the arc (`v-min`, running in `u`) and on one along the generators (`u-max`,
/// running in `v`).
const PANEL: &str = r#"
thickness = 0.05
[problem]
kind = "shell"
title = "panel with edge forces"
[surface]
type = "cylinder-sector"
origin = [0.0, 0.0, 0.0]
axis = [0.0, 1.0, 0.0]
reference = [0.0, 0.0, 1.0]
radius = 3.0
angle_deg = [10.0, 90.0]
length = [0.0, 2.0]
[particles]
grid = [7, 5]
[kernel]
basis = "quadratic"
support = 3.0
[integration]
cells = "per-particle-spacing"
gauss = 2
thickness_points = 2
thickness_rule = "gauss"
[material]
young = 1.0e6
poisson = 0.3
sigma0 = 1e30
hardening = 0.0
beta = 1.0
[[boundary]]
kind = "clamped"
edge = "u-min"
[[load]]
kind = "edge-force"
edge = "v-min"
per_length = [0.3, -1.0, 0.7]
[[load]]
kind = "edge-force"
edge = "u-max"
per_length = [-0.5, 0.2, 1.0]
[steps]
initial_step = 1.0
min_step = 1.0
max_step = 1.0
"#;

/// The edge forces of the case rebuilt with surface parameter `name` moved by `delta` (as the
/// finite-difference re-runs build it).
fn moved(case: &ShellCase, surface: &Surface<f64>, name: &str, delta: f64) -> Vec<f64> {
    let design = DesignVariable::shape(surface, name)
        .unwrap()
        .perturbed(&base_design(case), delta)
        .unwrap();
    let (problem, _) = CaseAnalysis { case }.build(&design).unwrap();
    edge_forces(&problem)
}

/// The external force of the problem's edge forces at load factor 1 (generalised rows).
fn edge_forces(problem: &shelldsa::shell::problem::ShellProblem) -> Vec<f64> {
    let n = problem.n_generalised();
    let mut f = vec![0.0; n];
    let q = vec![0.0; n];
    for l in problem.loads() {
        assert!(l.edge_force().is_some());
        l.force(&problem.model, None, &q, 1.0, &mut f).unwrap();
    }
    f
}

fn max_abs(a: &[f64]) -> f64 {
    a.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

/// For every design parameter of the panel's surface (origin, axis, reference direction,
/// radius, angles, length): the hand-derived derivative of the edge forces
/// (`EdgeForce::add_design_derivative` with `tangent_velocities`) equals the dual one (the
/// force evaluated on the surface seeded with that parameter, through `Load::force` with a
/// `LoadState`) to round-off, and the central difference of the load rebuilt on the perturbed
/// surface to truncation.
#[test]
fn edge_force_design_derivative_three_ways_for_every_surface_parameter() {
    let case = parse_shell_case(PANEL, Path::new("panel.toml")).unwrap();
    let surface = case.surface.clone();
    let built = shell_build::build(&case).unwrap();
    let problem = &built.problem;
    let model = &problem.model;
    let n = problem.n_generalised();
    let f0 = edge_forces(problem);
    let names = surface.parameter_names();
    let values = surface.parameter_values();
    let mut acting = Vec::new();
    for (k, name) in names.iter().enumerate() {
        // Hand-derived.
        let mut cont = vec![0.0; n];
        for l in problem.loads() {
            let e = l.edge_force().unwrap();
            let td = e.tangent_velocities(&surface, k).unwrap();
            e.add_design_derivative(model, &td, 1.0, &mut cont).unwrap();
        }
        // Dual: the loads on the seeded surface.
        let p: Vec<Dual64> = values
            .iter()
            .enumerate()
            .map(|(i, &x)| Dual64::new(x, if i == k { 1.0 } else { 0.0 }))
            .collect();
        let seeded = surface.with_design_parameters(&p).unwrap();
        let particles: Vec<_> = model.particles.iter().map(|s| s.lift()).collect();
        let surfaces: Vec<_> = model.points.iter().map(|s| s.surface.lift()).collect();
        let none: [Vector3<Dual64>; 0] = [];
        let state = LoadState {
            particles: &particles,
            surfaces: &surfaces,
            positions: None,
            surface: Some(&seeded),
            thickness: Dual64::from(model.thickness),
            young: Dual64::from(model.material.young),
            poisson: Dual64::from(model.material.poisson),
            tool_offsets: &none,
            tool_rotations: &none,
            tool_surfaces: None,
        };
        let q = vec![Dual64::from(0.0); n];
        let mut fd_dual = vec![Dual64::from(0.0); n];
        for l in problem.loads() {
            l.force(model, Some(&state), &q, 1.0, &mut fd_dual).unwrap();
        }
        let dual: Vec<f64> = fd_dual.iter().map(|x| x.eps).collect();
        // The dual force's value is the f64 force as built, to round-off.
        let values_f: Vec<f64> = fd_dual.iter().map(|x| x.re).collect();
        let scale = max_abs(&f0);
        let diff_value: Vec<f64> = values_f.iter().zip(&f0).map(|(a, b)| a - b).collect();
        assert!(max_abs(&diff_value) <= 1e-14 * scale, "{name}: value");
        // Central difference with h relative to the parameter (1e-5, absolute for a zero one).
        let h = 1e-5 * values[k].abs().max(1.0);
        let fp = moved(&case, &surface, name, h);
        let fm = moved(&case, &surface, name, -h);
        let fd: Vec<f64> = fp
            .iter()
            .zip(&fm)
            .map(|(a, b)| (a - b) / (2.0 * h))
            .collect();
        let d_cd: Vec<f64> = cont.iter().zip(&dual).map(|(a, b)| a - b).collect();
        let d_cf: Vec<f64> = cont.iter().zip(&fd).map(|(a, b)| a - b).collect();
        let size = max_abs(&dual);
        println!(
            "{name}: |df| {size:.3e}, continuum−dual {:.1e}, continuum−fd {:.1e}",
            max_abs(&d_cd),
            max_abs(&d_cf)
        );
        if size > 1e-12 * scale {
            acting.push(name.as_str());
        }
        // Round-off of a sum of O(100) terms of the force's size.
        assert!(max_abs(&d_cd) <= 1e-13 * scale.max(size), "{name}: dual");
        // Truncation h²|f'''| ~ 1e-10 of the force plus cancellation ε|f|/h ~ 1e-11: 1e-8.
        assert!(max_abs(&d_cf) <= 1e-8 * scale.max(size), "{name}: fd");
    }
    // The radius and both angles change the arc edge's length, the two ends of the length
    // the generator edge's; the origin, the axis and the reference direction move or turn
    // the panel without stretching it.
    assert_eq!(
        acting,
        [
            "radius",
            "angle_start",
            "angle_end",
            "length_start",
            "length_end"
        ]
    );
}

/// A clamped cantilever strip (L = 2, b = 0.5, t = 0.05, E = 1.2e6, ν = 0, 13 × 3 particles)
/// under a transverse edge force `q` per unit length on its free end, one load step of a
/// linear-size load (w/t ≈ 0.14), with the width and the length as shape design variables.
fn strip() -> ShellCase {
    let text = r#"
thickness = 0.05
[problem]
kind = "shell"
title = "cantilever strip under an end edge force"
[surface]
type = "rectangle"
origin = [0.0, 0.0, 0.0]
edge_u = [2.0, 0.0, 0.0]
edge_v = [0.0, 0.5, 0.0]
[particles]
grid = [13, 3]
[kernel]
basis = "quadratic"
support = 3.0
[integration]
cells = "per-particle-spacing"
gauss = 3
thickness_points = 3
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
[[load]]
kind = "edge-force"
edge = "u-max"
per_length = [0.0, 0.0, -0.2]
[steps]
initial_step = 1.0
min_step = 1.0
max_step = 1.0
[[monitor]]
name = "tip"
at = [1.0, 0.5]
[[design]]
name = "b"
kind = "shape.edge_v.y"
fd_steps = [1e-4]
[[design]]
name = "L"
kind = "shape.edge_u.x"
fd_steps = [1e-4]
[dsa]
monitors = ["tip.uz"]
"#;
    parse_shell_case(text, Path::new("strip.toml")).unwrap()
}

/// Through whole runs: the tip deflection's derivatives with respect to the strip's width and
/// length, continuum = dual (round-off) = central differences of re-runs (truncation). Beam
/// theory: the end force is `q b`, the stiffness `E b t³/4L³`, so `w = 4 q L³/(E t³)` does not
/// depend on `b` (ν = 0) and goes as `L³`. A derivative that left out the edge force's
/// length element would give `(b/w) dw/db = −1` instead of 0.
#[test]
fn edge_force_width_and_length_sensitivities_three_ways_match_beam_theory() {
    let case = strip();
    let methods = [DsaMethod::Continuum, DsaMethod::Dual, DsaMethod::Fd];
    let spec = dsa_study::validate(&case, &methods).unwrap();
    let out = study::run(
        &CaseAnalysis { case: &case },
        &base_design(&case),
        &spec,
        &mut |_| {},
    )
    .unwrap();
    let w = out.nominal.values[0][0];
    let (b, l) = (0.5f64, 2.0f64);
    let beam = -4.0 * 0.2 * l.powi(3) / (1.2e6 * 0.05f64.powi(3));
    println!("w = {w:e}, beam {beam:e}");
    // The discrete strip within 2 % of Euler–Bernoulli (shear and the geometric
    // nonlinearity at w/L = 0.02 stay below 0.1 %; the rest is the 13 × 3 discretisation,
    // within 1 % in tests/path_following.rs on a similar strip).
    assert!((w / beam - 1.0).abs() <= 0.02, "{w} vs {beam}");
    let mut exponents = Vec::new();
    for (var, size) in out.variables.iter().zip([b, l]) {
        let cont = var.continuum.as_ref().unwrap()[0][0];
        let dual = var.dual.as_ref().unwrap()[0][0];
        let fd = var.fd[0].derivatives[0][0];
        println!(
            "{}: continuum {cont:e}, dual {dual:e}, fd {fd:e}, (τ/w) dw/dτ {}",
            var.entry.variable.name,
            size * cont / w
        );
        // The same equation with right-hand sides equal to round-off: 1e-10 leaves decades
        // (1e-13 measured on the shipped cases). The scale is w/τ: the width's derivative
        // is nearly zero by itself.
        let scale = (w / size).abs();
        assert!(
            (cont - dual).abs() <= 1e-10 * scale,
            "{}: {cont} vs {dual}",
            var.entry.variable.name
        );
        // Central difference at h/τ = 1e-4: truncation (h/τ)² = 1e-8 of w/τ, re-runs'
        // round-off well below; bound 1e-6 of w/τ.
        assert!(
            (fd - cont).abs() <= 1e-6 * scale,
            "{}: {fd} vs {cont}",
            var.entry.variable.name
        );
        exponents.push(size * cont / w);
    }
    // Width: 0 for the beam, and for the plate strip at ν = 0 up to the geometric
    // nonlinearity's coupling (measured −6e-6); bound 1e-3, against −1 without the edge
    // force's term.
    assert!(exponents[0].abs() <= 1e-3, "(b/w) dw/db = {}", exponents[0]);
    // Length: 3 for the beam; the shear part and the discretisation's own dependence on the
    // length (the particle spacing scales with L) move it (measured 2.993): within 0.05.
    assert!(
        (exponents[1] - 3.0).abs() <= 0.05,
        "(L/w) dw/dL = {}",
        exponents[1]
    );
}

/// The panel with both edge forces, elastoplastic (σ0 = 400, H = 1e4), clamped on its
/// straight edge, five steps into yielding; the radius (which lengthens the loaded
/// arc edge) and the thickness as design variables, the free corner's displacement as
/// response.
fn plastic_panel() -> ShellCase {
    let text = PANEL
        .replace(
            "sigma0 = 1e30\nhardening = 0.0",
            "sigma0 = 400.0\nhardening = 1.0e4",
        )
        .replace("[0.3, -1.0, 0.7]", "[0.0, 0.0, -0.15]")
        .replace("[-0.5, 0.2, 1.0]", "[0.0, 0.06, -0.09]")
        .replace(
            "initial_step = 1.0\nmin_step = 1.0\nmax_step = 1.0",
            "initial_step = 0.125\nmin_step = 0.125\nmax_step = 0.125\nfinal_load = 0.625",
        )
        + r#"
[[monitor]]
name = "corner"
at = [1.0, 0.0]
[[design]]
name = "R"
kind = "shape.radius"
fd_steps = [1e-4]
[[design]]
name = "t"
kind = "thickness"
fd_steps = [1e-4]
[dsa]
monitors = ["corner.ux", "corner.uz"]
"#;
    parse_shell_case(&text, Path::new("panel.toml")).unwrap()
}

/// Curved edges under plasticity, through whole runs: continuum = dual (round-off) = central
/// differences (truncation) at every step the re-runs do not flag for a changed yield set;
/// points yield in the last two steps, so the plastic history terms are exercised.
#[test]
fn edge_forces_on_a_yielding_panel_three_ways() {
    let case = plastic_panel();
    let methods = [DsaMethod::Continuum, DsaMethod::Dual, DsaMethod::Fd];
    let spec = dsa_study::validate(&case, &methods).unwrap();
    let out = study::run(
        &CaseAnalysis { case: &case },
        &base_design(&case),
        &spec,
        &mut |_| {},
    )
    .unwrap();
    assert_eq!(out.nominal.values.len(), 5);
    let yielding: Vec<usize> = out
        .nominal
        .yielding
        .iter()
        .map(|y| y.iter().filter(|&&b| b).count())
        .collect();
    println!("yielding layer points per step: {yielding:?}");
    // Elastic for three steps, then yielding (3 and 20 layer points measured).
    assert!(yielding[..3].iter().all(|&n| n == 0) && yielding[3..].iter().all(|&n| n > 0));
    for var in &out.variables {
        let name = &var.entry.variable.name;
        let cont = var.continuum.as_ref().unwrap();
        let dual = var.dual.as_ref().unwrap();
        let fd = &var.fd[0];
        let scale = dual.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        let mut compared = 0;
        for (s, ((c, d), f)) in cont.iter().zip(dual).zip(&fd.derivatives).enumerate() {
            for ((c, d), f) in c.iter().zip(d).zip(f) {
                // The same equations with right-hand sides equal to round-off (2.3e-13 of
                // the largest derivative measured): 1e-10 leaves decades.
                assert!(
                    (c - d).abs() <= 1e-10 * scale,
                    "{name} step {s}: {c} vs {d}"
                );
                if !fd.flagged[s] {
                    // h/τ = 1e-4: truncation (h/τ)² = 1e-8 relative (measured 3.8e-8 of the
                    // derivative); bound 1e-6 of the largest derivative.
                    assert!((f - c).abs() <= 1e-6 * scale, "{name} step {s}: {f} vs {c}");
                    compared += 1;
                }
            }
        }
        // The yield set does not change within ±h at this step size (measured): every step
        // compared, the yielding one included.
        assert_eq!(compared, 10, "{name}: flags {:?}", fd.flagged);
    }
}
