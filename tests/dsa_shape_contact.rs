//! Shape design variables in cases with contact (the paper's eqs 74, 78–83): the
//! contact's slave points sit on the initial mid-surface, `x = x̄⁰ + Σ Ψ (ū + Δū) + ζ t/2 d`,
//! `d = n⁰ + Σ Ψ (d_J − d⁰_J)`, weighed by the initial face areas `w |x⁰,1 × x⁰,2|`, so a
//! shape variable moves them by `V⁰ + ζ t/2 ṅ⁰` and changes the areas
//! (`shell::contact::InitialGeometry`, `ContactInputs::initial`, `ContactSeeds::initial`).
//!
//! 1. Kernel: the hand-derived `ShellContact::force_dot` seeded with a shape variable's design
//!    velocity (`ShapeVelocity`: `V⁰`, `ẋ⁰,α, ṅ⁰, ṅ⁰,α` and the particles' `ḋ = ḋ⁰ = ṅ(ξ_I)`,
//!    `ė`) against the `Dual64` evaluation of `force_with` on the dual geometry of
//!    `sensitivity::shape::dual_geometry`, and against central differences of the force of a
//!    contact *rebuilt* on the perturbed surface (`ShellContact::new`, which does not go
//!    through the new code path), on the plastically bent flat sheet of `tests/dsa_contact.rs`
//!    with both tools active, and on a curved sheet (a cylinder, where `n⁰,α ≠ 0` and its
//!    radius changes `ṅ⁰,α`) pressed into both tools.
//! 2. Whole runs of the small punch-bending case with the sheet's length and width as design
//!    variables (`shape.edge_u.x`, `shape.edge_v.y`): continuum = dual, both against central
//!    differences of complete re-runs on the perturbed surface, Taylor rates.
//! 3. `--terms`: the continuum's term groups equal the dual residual seeded with each group.
//!
//! Run: `cargo test --release --test dsa_shape_contact -- --nocapture`.

#[path = "common/small_bending.rs"]
mod small_bending;
use nalgebra::Vector3;
use num_dual::Dual64;
use shelldsa::geometry::Surface;
use shelldsa::io::dsa_case::DsaMethod;
use shelldsa::io::dsa_output;
use shelldsa::io::dsa_study::{self, base_design, CaseAnalysis};
use shelldsa::io::shell_build;
use shelldsa::io::shell_case::parse_shell_case;
use shelldsa::sensitivity::shape::{dual_geometry, ShapeVelocity};
use shelldsa::sensitivity::study;
use shelldsa::shell::contact::InitialGeometry;
use shelldsa::shell::contact::{ContactFaces, ContactInputs, ShellContact};
use shelldsa::shell::contact_sensitivity::ContactSeeds;
use shelldsa::shell::contact_sensitivity::ToolRate;
use shelldsa::shell::model::ShellModel;
use shelldsa::shell::point::{ParticleState, SurfacePoint};
use shelldsa::solver::{LinearSolver, Method, SolverOptions};
use small_bending::{
    assert_taylor_rates, case, max_abs, max_diff, run_case, zero_state, Lcg, CASE,
};
use std::path::Path;
use std::sync::Arc;

/// The force of `contact` at `(q, t)` with the model's committed state (`force_generic`: the
/// slave sites as built).
fn force(model: &ShellModel, contact: &ShellContact, q: &[f64], t: f64) -> Vec<f64> {
    let mut f = vec![0.0; q.len()];
    contact.force_generic(model, q, t, &mut f).unwrap();
    f
}

/// The model and contact with the surface parameter of `v` moved by `s` and the committed
/// particle states moved by `s` times the design velocity's particle dots: the quadrature
/// points' geometry from the perturbed surface, and a contact built anew on it
/// (`ShellContact::new`: slave sites and face areas of the perturbed sheet, the same tools and
/// penalty).
fn perturbed(
    model: &ShellModel,
    surface: &Surface<f64>,
    contact: &ShellContact,
    v: &ShapeVelocity,
    s: f64,
) -> (ShellModel, ShellContact) {
    let mut p = surface.parameter_values();
    p[v.parameter] += s;
    let sh = surface.with_design_parameters::<f64>(&p).unwrap();
    let mut m = model.clone();
    for pt in &mut m.points {
        pt.surface = SurfacePoint::from_derivs(&sh.eval(pt.uv[0], pt.uv[1]));
    }
    for (pm, pd) in m.particles.iter_mut().zip(&v.particles) {
        *pm = ParticleState {
            u: pm.u + pd.u * s,
            d: pm.d + pd.d * s,
            d0: pm.d0 + pd.d0 * s,
            e: [pm.e[0] + pd.e[0] * s, pm.e[1] + pd.e[1] * s],
        };
    }
    let c = ShellContact::new(
        &m,
        &sh,
        contact.tools().to_vec(),
        ContactFaces::Both,
        contact.penalty(),
    )
    .unwrap();
    (m, c)
}

/// `force_dot` for the design velocity `v` (no other seed).
fn hand(
    model: &ShellModel,
    contact: &ShellContact,
    v: &ShapeVelocity,
    q: &[f64],
    t: f64,
) -> Vec<f64> {
    hand_parts(model, contact, v, q, t, [true; 3])
}

/// `force_dot` for the design velocity `v` with only some of its initial-geometry parts:
/// `[V⁰, ṅ⁰, (ẋ⁰,α, ṅ⁰,α)]` (the slave point's translation, its director's turn, the face
/// areas' change).
fn hand_parts(
    model: &ShellModel,
    contact: &ShellContact,
    v: &ShapeVelocity,
    q: &[f64],
    t: f64,
    keep: [bool; 3],
) -> Vec<f64> {
    let positions: Vec<Vector3<f64>> = v
        .positions
        .iter()
        .map(|x| if keep[0] { *x } else { Vector3::zeros() })
        .collect();
    let points: Vec<SurfacePoint<f64>> = v
        .points
        .iter()
        .map(|p| SurfacePoint {
            n: if keep[1] { p.n } else { Vector3::zeros() },
            x_a: if keep[2] {
                p.x_a
            } else {
                [Vector3::zeros(); 2]
            },
            n_a: if keep[2] {
                p.n_a
            } else {
                [Vector3::zeros(); 2]
            },
        })
        .collect();
    let tools = vec![ToolRate::default(); contact.tools().len()];
    let increment = vec![0.0; q.len()];
    let seeds = ContactSeeds {
        tools: &tools,
        thickness: 0.0,
        penalty: 0.0,
        particles: &v.particles,
        increment: &increment,
        initial: Some(InitialGeometry {
            positions: &positions,
            surfaces: &points,
        }),
    };
    contact.force_dot(model, q, t, &seeds).unwrap()
}

/// The derivative part of `force_with` in `Dual64` with the site geometry of `dual_geometry`
/// (the parameter of `v` seeded) and the committed particle states seeded with `v`'s dots.
fn dual(
    model: &ShellModel,
    surface: &Surface<f64>,
    contact: &ShellContact,
    v: &ShapeVelocity,
    q: &[f64],
    t: f64,
) -> Vec<f64> {
    let mut seeds = vec![vec![0.0]; surface.n_design_parameters()];
    seeds[v.parameter] = vec![1.0];
    let g = dual_geometry::<Dual64>(model, surface, &seeds).unwrap();
    let dv = |a: &Vector3<f64>, b: &Vector3<f64>| a.zip_map(b, Dual64::new);
    let particles: Vec<ParticleState<Dual64>> = model
        .particles
        .iter()
        .zip(&v.particles)
        .map(|(p, d)| ParticleState {
            u: dv(&p.u, &d.u),
            d: dv(&p.d, &d.d),
            d0: dv(&p.d0, &d.d0),
            e: [dv(&p.e[0], &d.e[0]), dv(&p.e[1], &d.e[1])],
        })
        .collect();
    let zeros = vec![Vector3::<Dual64>::zeros(); contact.tools().len()];
    let inputs = ContactInputs {
        particles: &particles,
        thickness: Dual64::from(model.thickness),
        penalty: Dual64::from(contact.penalty()),
        offsets: &zeros,
        rotations: &zeros,
        surfaces: None,
        initial: Some(InitialGeometry {
            positions: &g.positions,
            surfaces: &g.points,
        }),
    };
    let qd: Vec<Dual64> = q.iter().map(|&x| Dual64::from(x)).collect();
    let mut f = vec![Dual64::from(0.0); q.len()];
    contact.force_with(model, &inputs, &qd, t, &mut f).unwrap();
    f.iter().map(|x| x.eps).collect()
}

/// `force_with` in f64 with the nominal geometry given as `ContactInputs::initial` (the new
/// code path) reproduces the contact as built; a wrong length is a typed error.
fn check_initial_path(
    model: &ShellModel,
    surface: &Surface<f64>,
    contact: &ShellContact,
    q: &[f64],
    t: f64,
) {
    let positions: Vec<Vector3<f64>> = model
        .points
        .iter()
        .map(|p| surface.eval(p.uv[0], p.uv[1]).x)
        .collect();
    let surfaces: Vec<SurfacePoint<f64>> = model.points.iter().map(|p| p.surface).collect();
    let zeros = vec![Vector3::zeros(); contact.tools().len()];
    let inputs = ContactInputs {
        particles: &model.particles,
        thickness: model.thickness,
        penalty: contact.penalty(),
        offsets: &zeros,
        rotations: &zeros,
        surfaces: None,
        initial: Some(InitialGeometry {
            positions: &positions,
            surfaces: &surfaces,
        }),
    };
    let mut f = vec![0.0; q.len()];
    contact.force_with(model, &inputs, q, t, &mut f).unwrap();
    let f0 = force(model, contact, q, t);
    let e = max_diff(&f, &f0) / max_abs(&f0);
    println!("  force with the nominal geometry given: {e:.1e} of max|f|");
    // The same geometry (the built sites take the normal from `SurfaceDerivs::normal`, the
    // model's points from `SurfacePoint::from_derivs`: the same formula up to round-off), so
    // round-off of the force: 1e-12 relative.
    assert!(e < 1e-12, "nominal geometry given: {e:e}");
    let bad = ContactInputs {
        initial: Some(InitialGeometry {
            positions: &positions[1..],
            surfaces: &surfaces,
        }),
        ..inputs
    };
    let err = contact.force_with(model, &bad, q, t, &mut f).unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains(&positions.len().to_string())
            && msg.contains(&(positions.len() - 1).to_string()),
        "{msg}"
    );
}

/// `force_dot` with the design velocity of each parameter in `names` (with its central
/// difference step) against the dual evaluation and central differences of rebuilt contacts;
/// returns the hand-derived `ḟ` per parameter and, per part of the initial geometry's velocity
/// (`V⁰`, `ṅ⁰`, the face areas), its largest share of `ḟ`.
fn check_kernel(
    label: &str,
    (model, surface, contact): (&ShellModel, &Surface<f64>, &ShellContact),
    q: &[f64],
    t: f64,
    names: &[(&str, f64)],
) -> (Vec<Vec<f64>>, [f64; 3]) {
    let mut shares = [0.0f64; 3];
    let report = contact.report(model, q, t).unwrap();
    let active: Vec<usize> = report.tools.iter().map(|r| r.active_points).collect();
    println!(
        "{label}: active points per tool {active:?} of {} slave points",
        report.slaves.len()
    );
    assert!(
        active.iter().all(|&a| a > 0),
        "{label}: active points {active:?}"
    );
    check_initial_path(model, surface, contact, q, t);
    let mut out = Vec::new();
    for &(name, h) in names {
        let k = surface.parameter_index(name).unwrap();
        let v = ShapeVelocity::new(model, surface, k).unwrap();
        let fh = hand(model, contact, &v, q, t);
        let fd = dual(model, surface, contact, &v, q, t);
        let (mp, cp) = perturbed(model, surface, contact, &v, h);
        let (mm, cm) = perturbed(model, surface, contact, &v, -h);
        let fp = force(&mp, &cp, q, t);
        let fm = force(&mm, &cm, q, t);
        let cd: Vec<f64> = fp
            .iter()
            .zip(&fm)
            .map(|(a, b)| (a - b) / (2.0 * h))
            .collect();
        let scale = max_abs(&fd);
        let e_dual = max_diff(&fh, &fd) / scale;
        let e_cd = max_diff(&fh, &cd) / scale;
        println!(
            "  {name:<12} max|ḟ| {scale:.4e}  |hand − dual| {e_dual:.2e}  |hand − central| \
             {e_cd:.2e} (h = {h:e})"
        );
        assert!(
            scale > 0.0,
            "{label} {name}: the design must move the contact force"
        );
        // The same formulas two ways (dual numbers through the projection's Newton correction
        // and the dual surface, against the hand-derived chain; the geometry seeds differ only
        // by the round-off between `ShapeVelocity` and `dual_geometry`, ≤ 1.3e-15 in
        // tests/dsa_shape.rs): round-off of sums of terms of size ~max|ḟ|, so 1e-10.
        assert!(e_dual < 1e-10, "{label} {name}: hand vs dual {e_dual:e}");
        // Central differences of contacts rebuilt on the surface moved by ±h: truncation
        // ~h² |f‴| and round-off ~ε |f| / h, relative to max|ḟ| (measured ≤ 2.5e-9 with the
        // steps chosen per parameter); 1e-6 still fails a missing term: each of V⁰,
        // ζ t/2 ṅ⁰ and the face areas is > 1e-3 of some ḟ (asserted by the caller).
        assert!(
            e_cd < 1e-6,
            "{label} {name}: hand vs central differences {e_cd:e}"
        );
        // The share of each part of the initial geometry's velocity in ḟ (the largest over
        // the parameters is asserted by the caller: every part must matter somewhere, so the
        // comparisons above would see it missing).
        let share: Vec<f64> = (0..3)
            .map(|i| {
                let mut keep = [true; 3];
                keep[i] = false;
                max_diff(&fh, &hand_parts(model, contact, &v, q, t, keep)) / scale
            })
            .collect();
        println!(
            "  {:<12} share of V⁰ {:.2e}, of ζ t/2 ṅ⁰ {:.2e}, of the face areas {:.2e}",
            "", share[0], share[1], share[2]
        );
        for (m, x) in shares.iter_mut().zip(&share) {
            *m = m.max(*x);
        }
        out.push(fh);
    }
    (out, shares)
}

/// The model bent to 3 mm of stroke (t = 0.5), its surface and contact.
fn bent_state() -> (ShellModel, Surface<f64>, Arc<ShellContact>) {
    let c = case(0.5, "");
    let mut b = shell_build::build(&c).unwrap();
    let pattern = b.problem.pattern().clone();
    let mut linear =
        LinearSolver::new(&pattern, Method::auto(&pattern), SolverOptions::default()).unwrap();
    let u0 = b.problem.state().to_vec();
    b.newton
        .run(&mut b.problem, &pattern, &mut linear, &u0)
        .unwrap();
    (
        b.problem.model.clone(),
        c.surface.clone(),
        b.contact.unwrap(),
    )
}

#[test]
fn contact_force_shape_sensitivity_matches_dual_and_rebuilt_contacts() {
    // (1) The plastically bent flat sheet, a random increment (translations ≤ 0.02 mm,
    // rotations ≤ 0.02 rad) at t = 0.505 (the punch 0.03 mm further down).
    let (model, surface, contact) = bent_state();
    let n = model.n_dofs();
    let mut rng = Lcg(0x5eed_5a9e);
    let q: Vec<f64> = (0..n).map(|_| rng.next() * 0.02).collect();
    let t = 0.505;
    // The sheet's length and width (a stretch: V⁰ and ẋ⁰,α, the face areas), the rise of its
    // long edge (ṅ⁰ ≠ 0: the directors tilt) and its height (V⁰ = e_z alone).
    let (f, flat_shares) = check_kernel(
        "bent flat sheet",
        (&model, &surface, &contact),
        &q,
        t,
        &[
            ("edge_u.x", 1e-6),
            ("edge_v.y", 1e-6),
            ("edge_u.z", 1e-6),
            ("origin.z", 1e-6),
        ],
    );
    // Independent of the dual: raising the sheet rigidly (V⁰ = e_z, no other dot) is lowering
    // both tools, `ḟ(origin.z) = −ḟ(punch z) − ḟ(die z)` (tool translations, checked in
    // tests/dsa_contact.rs), to round-off of the terms summed.
    let zeros = vec![zero_state(); model.particles.len()];
    let increment = vec![0.0; n];
    let lowered_tool = |i: usize| {
        let mut tools = vec![ToolRate::default(); 2];
        tools[i].translation = [0.0, 0.0, 1.0];
        let seeds = ContactSeeds {
            tools: &tools,
            thickness: 0.0,
            penalty: 0.0,
            particles: &zeros,
            increment: &increment,
            initial: None,
        };
        contact.force_dot(&model, &q, t, &seeds).unwrap()
    };
    let (punch, die) = (lowered_tool(0), lowered_tool(1));
    let lowered: Vec<f64> = punch.iter().zip(&die).map(|(a, b)| -a - b).collect();
    let e = max_diff(&f[3], &lowered) / max_abs(&lowered);
    println!("  origin.z = −(punch z + die z): {e:.1e} of max|ḟ|");
    assert!(e < 1e-12, "origin.z against the tools lowered: {e:e}");

    // (2) A curved sheet: a cylinder of radius 200 about an axis along y through
    // (0, ·, −200), its highest line at x = 0, 1.2 mm lower at the die (n⁰,α ≠ 0), not run:
    // its initial state with a random increment at t = 0.05, pressed into both tools (kernel
    // values need no equilibrium). The radius changes the curvature (ṅ⁰,α ≠ 0), the start angle slides the
    // sheet along its arc, origin.x moves it along x.
    let flat = "type = \"rectangle\"\norigin = [0.0, 0.0, 0.0]\nedge_u = [30.0, 0.0, 0.0]\n\
                edge_v = [0.0, 5.0, 0.0]";
    let text = CASE.replace("{final}", "0.5").replace("{design}", "");
    assert_eq!(text.matches(flat).count(), 1);
    let text = text.replace(
        flat,
        "type = \"cylinder-sector\"\norigin = [0.0, 0.0, -200.0]\naxis = [0.0, 1.0, 0.0]\n\
         reference = [0.0, 0.0, 1.0]\nradius = 200.0\nangle_deg = [0.0, 8.594]\n\
         length = [0.0, 5.0]",
    );
    let c = parse_shell_case(&text, Path::new("tests/dsa_shape_contact.rs")).unwrap();
    let b = shell_build::build(&c).unwrap();
    let model = b.problem.model.clone();
    let contact = b.contact.unwrap();
    let corners: Vec<_> = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]
        .iter()
        .map(|uv| c.surface.eval(uv[0], uv[1]).x)
        .collect();
    println!("curved sheet corners {corners:?}");
    let q: Vec<f64> = (0..model.n_dofs()).map(|_| rng.next() * 0.02).collect();
    let (_, curved_shares) = check_kernel(
        "curved sheet",
        (&model, &c.surface, &contact),
        &q,
        0.05,
        &[("radius", 1e-4), ("angle_start", 1e-7), ("origin.x", 1e-6)],
    );
    // Every part of the initial geometry's velocity is a visible share of some ḟ (1e-3, far
    // above the 1e-6 of the central differences): a missing or wrong part would fail there.
    for (i, part) in ["V⁰", "ζ t/2 ṅ⁰", "face areas"].iter().enumerate() {
        let m = flat_shares[i].max(curved_shares[i]);
        assert!(m > 1e-3, "{part}: largest share {m:e}");
    }
}

/// The continuum derivative equals the dual one: the three-way check asks 1e-8 relative on every
/// component with |ψ'| ≥ 1e-6 max|ψ'| (both solve eq 65 with the same tangent; their
/// right-hand sides differ by round-off). Returns the largest relative difference.
fn continuum_matches_dual(var: &study::VariableResult) -> f64 {
    let name = &var.entry.variable.name;
    let (c, d) = (var.continuum.as_ref().unwrap(), var.dual.as_ref().unwrap());
    let big = d.iter().flatten().fold(0.0f64, |a, x| a.max(x.abs()));
    let mut worst = 0.0f64;
    for (x, y) in c.iter().flatten().zip(d.iter().flatten()) {
        if y.abs() >= 1e-6 * big {
            worst = worst.max((x / y - 1.0).abs());
        }
    }
    println!("`{name}`: continuum vs dual {worst:.2e} (every step and monitor)");
    assert!(worst <= 1e-8, "`{name}`: continuum vs dual {worst:e}");
    worst
}

/// Whole runs of the small punch-bending case (1.5 mm of stroke in 14 steps, yielding from
/// step 9, 6 penetrating slave points throughout) with the sheet's length (`shape.edge_u.x`, 30 mm: the die's contact
/// line moves along the sheet, the face areas stretch) and width (`shape.edge_v.y`, 5 mm)
/// as shape design variables: continuum = dual, both against central differences of complete
/// re-runs on the perturbed surface (the contact rebuilt there), Taylor rates.
#[test]
fn shape_derivatives_with_contact_match_dual_and_re_runs() {
    let design = r#"
[[design]]
name = "length"
kind = "shape.edge_u.x"
fd_steps = [1e-4, 5e-5, 2.5e-5]
[[design]]
name = "width"
kind = "shape.edge_v.y"
fd_steps = [4e-4, 2e-4, 1e-4]
[dsa]
monitors = ["center.uz", "edge.ux", "edge.uz"]
"#;
    let c = case(0.25, design);
    let spec = dsa_study::validate(&c, &c.dsa.as_ref().unwrap().methods).unwrap();
    let t0 = std::time::Instant::now();
    let r = run_case(&c, &spec);
    println!(
        "{} steps; analysis {:.2} s, continuum {:.3} s, dual {:.2} s, fd {:.2} s (total {:.1} s); \
         dual state mismatch {:.1e}",
        r.nominal.loads.len(),
        r.time_analysis,
        r.time_continuum.unwrap(),
        r.time_dual.unwrap(),
        r.time_fd.unwrap(),
        t0.elapsed().as_secs_f64(),
        r.dual_state_mismatch.unwrap(),
    );
    let yielding: Vec<usize> = r
        .nominal
        .yielding
        .iter()
        .map(|s| s.iter().filter(|y| **y).count())
        .collect();
    let active: Vec<usize> = r
        .nominal
        .contact
        .iter()
        .map(|s| s.iter().filter(|c| **c).count())
        .collect();
    println!("yielding layer points per step {yielding:?}");
    println!("penetrating slave points per step {active:?}");
    // The dual state's value parts follow the analysis to round-off.
    assert!(r.dual_state_mismatch.unwrap() < 1e-10);
    for var in &r.variables {
        let name = &var.entry.variable.name;
        continuum_matches_dual(var);
        println!(
            "{}",
            dsa_output::table(
                &r,
                r.variables
                    .iter()
                    .position(|v| std::ptr::eq(v, var))
                    .unwrap()
            )
            .lines()
            .filter(|l| !l.starts_with(' '))
            .collect::<Vec<_>>()
            .join("\n")
        );
        let per_h: Vec<String> = var
            .fd
            .iter()
            .map(|col| {
                let unflagged = col.flagged.iter().filter(|f| !**f).count();
                format!(
                    "{:.2e} ({unflagged} of {} steps)",
                    study::max_rel_diff(var, col).unwrap_or(f64::NAN),
                    col.flagged.len()
                )
            })
            .collect();
        println!("`{name}`: continuum vs central differences per h {per_h:?}");
        let last = var.fd.last().unwrap();
        let unflagged = last.flagged.iter().filter(|f| !**f).count();
        // Measured: the length's yield status flips within ±h from step 10 (flagged, reported
        // and left out), the width's nowhere; the comparison covers the unflagged steps.
        assert!(
            unflagged >= 5,
            "{name}: {unflagged} of {} steps unflagged",
            last.flagged.len()
        );
        // The three-way check asks 0.1 % against complete re-runs. At the smallest h the central
        // difference's truncation falls as h² (measured 4.1e-5, 1.0e-5, 2.6e-6 for the length
        // at h/τ = 1e-4, 5e-5, 2.5e-5; the width ≤ 1.3e-7, at the re-runs' noise ~1e-14 of
        // the responses over h) : 1e-5 leaves a factor 4 and is 100 times the issue's 0.1 %.
        let e = study::max_rel_diff(var, last).expect("comparable components");
        assert!(e < 1e-5, "{name}: continuum vs central differences {e:e}");
        let fitted = assert_taylor_rates(var, name);
        println!("`{name}`: {fitted} steps with a Taylor rate");
        assert!(fitted >= 5, "{name}: {fitted} steps fitted");
        // The design moves the sheet.
        let d = var.continuum.as_ref().unwrap();
        assert!(
            d.last().unwrap().iter().any(|x| x.abs() > 1e-3),
            "{name}: {:?}",
            d.last()
        );
    }
}

/// `--terms`: with contact and a shape variable, every term group of the continuum fictitious
/// load equals the dual residual seeded with that group only (the contact's share of the
/// geometry's design velocity is in `load`, the external force's share, as the dual side
/// splits `R = f_int − f_ext`), to round-off of the terms summed (1e-12 of the largest group).
#[test]
fn term_groups_with_contact_and_shape_match_the_dual_reference() {
    let design = r#"
[[design]]
name = "length"
kind = "shape.edge_u.x"
[[design]]
name = "width"
kind = "shape.edge_v.y"
[dsa]
monitors = ["center.uz"]
"#;
    let c = case(0.25, design);
    let spec = dsa_study::validate(&c, &[DsaMethod::Continuum, DsaMethod::Dual]).unwrap();
    // Step 12: plastic (61 yielding layer points), the punch and the die active.
    let bs = study::terms(&CaseAnalysis { case: &c }, &base_design(&c), &spec, 12).unwrap();
    assert_eq!(bs.len(), 2);
    for b in &bs {
        check_groups(b);
    }
}

fn check_groups(b: &shelldsa::sensitivity::terms::TermBreakdown) {
    let scale = b.groups.iter().fold(0.0f64, |a, g| a.max(g.dual_max));
    for g in &b.groups {
        println!(
            "{} {:>8}: cont {:.3e} dual {:.3e} diff {:.1e}",
            b.variable.name,
            g.group.map_or("total", |t| t.name()),
            g.continuum_max,
            g.dual_max,
            g.max_difference
        );
        assert!(
            g.max_difference <= 1e-12 * scale,
            "{} {:?}: {:e} of {scale:e}",
            b.variable.name,
            g.group,
            g.max_difference
        );
    }
    for u in &b.update {
        println!("  update {:<12} {:.1e}", u.field, u.relative());
        // The continuum's own end-of-step sensitivities against the dual state's: the same
        // step from the same seeds, round-off (1e-10 relative).
        assert!(
            u.relative() < 1e-10,
            "{} update {}: {:e}",
            b.variable.name,
            u.field,
            u.relative()
        );
    }
    let group = |name: &str| {
        b.groups
            .iter()
            .find(|g| g.group.map_or("total", |t| t.name()) == name)
            .unwrap()
            .dual_max
    };
    // The internal force's share (design), the contact's and gravity's (load) and the
    // committed state's (history) all carry the shape variable; the tools do not move.
    for g in ["design", "load", "history"] {
        assert!(group(g) > 0.0, "{g}");
    }
    assert_eq!(group("tool"), 0.0);
}
