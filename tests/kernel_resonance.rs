//! The cubic B-spline kernel's two-spacing blind spot: at supports of 4 and 8 spacings its
//! Fourier transform (`sinc⁴` with knots half a support apart) vanishes at the wavelength of two
//! particle spacings, so a coefficient field alternating from particle to particle passes no
//! displacement and no strain to the RK approximation (docs/stability.md §6). With symmetry
//! planes on both `u` edges (the quarter hemisphere) that field is a zero-energy mode; the
//! problem finds such coefficient modes (`shell::gauge`) and fixes each by a constraint row.
//! The quartic spline has no such blind spot, and is the kernel at those supports unless a case
//! names the cubic B-spline.
use shelldsa::io::shell_build::build;
use shelldsa::io::shell_case::{parse_shell_case, ShellCase};
use shelldsa::meshfree::KernelFunction;
use shelldsa::solver::{LinearSolver, Method, NonlinearProblem, SolverOptions};
use std::path::Path;

#[path = "common/cli.rs"]
mod cli;
use cli::cli;

/// The cubic B-spline named in a case (`kernel.function`).
const CUBIC: Option<&str> = Some("cubic-spline");

/// The shipped linear hemisphere with `support` and the cubic B-spline (and, with `unfix`,
/// without its one `uz` restraint: a rigid translation left free).
fn hemisphere_case(support: &str, unfix: bool) -> ShellCase {
    hemisphere_case_with(support, CUBIC, unfix)
}

/// As [`hemisphere_case`] with `kernel.function = function` (`None`: the key left out).
fn hemisphere_case_with(support: &str, function: Option<&str>, unfix: bool) -> ShellCase {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("verification/hemisphere-linear/case.toml");
    let mut text = case_text("hemisphere-linear", support, function);
    if unfix {
        let from = text
            .find("[[boundary]]                        # remove the rigid")
            .unwrap();
        let to = text.find("# Loads at load factor 1").unwrap();
        text.replace_range(from..to, "");
    }
    parse_shell_case(&text, &path).unwrap()
}

/// The text of the shipped case `name` with `support` and `kernel.function = function`
/// (`None`: the key left out, the default for the support).
fn case_text(name: &str, support: &str, function: Option<&str>) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("verification/{name}/case.toml"));
    let text = std::fs::read_to_string(&path).unwrap();
    let old = "support = 3.0";
    assert_eq!(text.matches(old).count(), 1);
    let function = function.map_or(String::new(), |f| format!("function = \"{f}\"\n"));
    text.replace(old, &format!("{function}support = {support}"))
}

/// Run the case; `Ok((δ_A / P, gauge rows))` with the radial displacement at A per unit
/// load, or the driver's error text.
fn radial_at_a(case: &ShellCase) -> Result<(f64, usize), String> {
    // P = 1e-3 along +x at A = (R, 0, 0): the radial displacement is u_x.
    displacement_at(case, [0.0, 0.0]).map(|(u, g)| (u[0] / 1e-3, g))
}

/// Run the case; `Ok((displacement at uv, gauge rows))`, or the driver's error text.
fn displacement_at(case: &ShellCase, uv: [f64; 2]) -> Result<([f64; 3], usize), String> {
    let mut built = build(case).unwrap();
    let gauge = built.problem.gauge_modes().len();
    let pattern = built.problem.pattern().clone();
    let mut solver =
        LinearSolver::new(&pattern, Method::auto(&pattern), SolverOptions::default()).unwrap();
    let n = built.problem.n_dofs();
    built
        .newton
        .run(&mut built.problem, &pattern, &mut solver, &vec![0.0; n])
        .map_err(|e| e.to_string())?;
    let u = built.problem.model.displacement_at(uv).unwrap();
    Ok(([u[0], u[1], u[2]], gauge))
}

/// The h·gradient transfer (`ShellModel::coefficient_transfer`) of `u_z = (−1)^i` along `u`
/// (particle grid index `i`) on the shipped linear hemisphere with the support changed.
fn alternating_transfer(support: &str) -> f64 {
    alternating_transfer_with(support, CUBIC)
}

/// As [`alternating_transfer`] with `kernel.function = function`.
fn alternating_transfer_with(support: &str, function: Option<&str>) -> f64 {
    let case = hemisphere_case_with(support, function, false);
    let built = build(&case).unwrap();
    let model = &built.problem.model;
    let [nu, _] = case.particles.counts;
    let d = model.domain;
    let h = (d[0][1] - d[0][0]) / (nu - 1) as f64;
    let mut x = vec![0.0; 5 * model.n_particles()];
    for (p, uv) in model.particle_uv.iter().enumerate() {
        let i = ((uv[0] - d[0][0]) / h).round() as i64;
        x[5 * p + 2] = if i % 2 == 0 { 1.0 } else { -1.0 };
    }
    model.coefficient_transfer(&x, h)[2]
}

/// Measured on the 17 × 17 grid: 0.39 at support 3 (a smooth field passes 1); at 4 and 8 the
/// transfer is round-off (the alternating sum of the kernel's samples cancels exactly; the RK
/// correction's moments up to order 3 cancel with it, `sinc⁴` having a fourth-order zero).
/// 1e-8 is far above that round-off and far below the 1e-3 of the nearest supports that run.
#[test]
fn supports_of_four_and_eight_spacings_pass_no_alternating_field() {
    let t3 = alternating_transfer("3.0");
    let t4 = alternating_transfer("4.0");
    let t8 = alternating_transfer("8.0");
    let t45 = alternating_transfer("4.5");
    println!("h·gradient transfer of an alternating field: support 3 {t3:.3e}, 4 {t4:.3e}, 4.5 {t45:.3e}, 8 {t8:.3e}");
    assert!(t3 > 0.1, "support 3: {t3}");
    assert!(t45 > 1e-3, "support 4.5: {t45}");
    assert!(t4 < 1e-8, "support 4: {t4}");
    assert!(t8 < 1e-8, "support 8: {t8}");
}

/// Support 4 between the two symmetry planes: the alternating coefficient modes are fixed by
/// rows and the run converges to the field of the neighbouring supports. Measured (17 × 17,
/// 2 × 2 Gauss points, second-order VCI): δ_A/P = 0.090621 at support 3.8 (no rows), 0.091392
/// at 4 (70 rows), 0.091607 at 4.2 (no rows); MacNeal–Harder's 0.0935 (README) is −2.3 % away
/// at 4, as it is −3.1 % at 3.8: larger supports over-smooth on this grid. The bound 1 %
/// against support 3.8 is the task's requirement; the measured gap is 0.85 %, and 3.8 and
/// 4.2 differ by 1.1 % between themselves, so the bound checks that 4 lies with them, not
/// more.
#[test]
fn support_four_between_symmetry_planes_runs() {
    let (d38, g38) = radial_at_a(&hemisphere_case("3.8", false)).unwrap();
    let (d4, g4) = radial_at_a(&hemisphere_case("4.0", false)).unwrap();
    println!("δ_A/P: support 3.8 {d38:.6} ({g38} rows), 4 {d4:.6} ({g4} rows)");
    assert_eq!(g38, 0, "support 3.8 needs no rows");
    assert!(
        g4 >= 17,
        "support 4: {g4} rows, expected at least one per line along u (17)"
    );
    assert!(
        ((d4 - d38) / d38).abs() < 0.01,
        "support 4 gives {d4}, support 3.8 {d38}"
    );
}

/// A model that is singular for a reason other than the kernel (the rigid translation in z
/// left free) still fails at support 4, the rows notwithstanding, with a message naming the
/// particle and the component of the offending unknown.
#[test]
fn support_four_with_a_missing_support_still_fails_naming_the_dof() {
    let err = radial_at_a(&hemisphere_case("4.0", true)).unwrap_err();
    println!("{err}");
    assert!(err.contains("singular"), "{err}");
    assert!(err.contains("is particle "), "{err}");
    assert!(err.contains("component ū_z"), "{err}");
}

/// Design sensitivities of the support-4 hemisphere, whose gauge rows are design-independent
/// for the thickness and Poisson's ratio: the continuum DSA equals the dual reference (both
/// solve the bordered system with the rows); a shape variable, whose rows of the director
/// patterns would follow the initial directors, is refused before the analysis (exit 1). Measured
/// with `fd` as well (`shelldsa dsa`, h/τ = 1e-4): central differences within 3.4e-8 of the
/// dual derivatives, Taylor rates 1.999–2.002; continuum − dual 7.9e-11 (t) and 1.0e-9 (ν) of
/// the largest derivative, against ~1e-13 at support 3: the bordered tangent is less well
/// conditioned.
#[test]
fn support_four_design_sensitivities_continuum_equals_dual() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/kernel-resonance-tests");
    std::fs::create_dir_all(&dir).unwrap();
    // `shelldsa dsa` on the support-4 hemisphere with `extra` design tables before t and ν:
    // the exit code and sensitivity.json.
    let dsa = |name: &str, extra: &str, function: Option<&str>| {
        let text = format!(
            "{}\n{extra}[[design]]\nname = \"t\"\nkind = \"thickness\"\n\n[[design]]\n\
             name = \"nu\"\nkind = \"material.poisson\"\n\n[dsa]\n\
             methods = [\"continuum\", \"dual\"]\nmonitors = [\"A.ux\", \"B.uy\"]\n",
            case_text("hemisphere-linear", "4.0", function)
        );
        let case = dir.join(format!("{name}.toml"));
        std::fs::write(&case, text).unwrap();
        let out = dir.join(name);
        let code = cli(&[
            "dsa",
            case.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        let json = std::fs::read_to_string(out.join("sensitivity.json")).unwrap();
        (
            code,
            serde_json::from_str::<serde_json::Value>(&json).unwrap(),
        )
    };
    let (code, a) = dsa("support4", "", CUBIC);
    assert_eq!(code, 0);
    for v in a["variables"].as_array().unwrap() {
        let d = v["continuum_vs_dual"].as_f64().unwrap();
        // Both methods solve the same bordered system; 1e-8 is the agreement the methods
        // promise (measured 7.9e-11 and 1.0e-9: the rows' conditioning, 1e-13 without them).
        assert!(d <= 1e-8, "{}: continuum vs dual {d:e}", v["name"]);
    }
    let shape = "[[design]]\nname = \"R\"\nkind = \"shape.radius\"\n\n";
    // Refused before any analysis: a bad input (exit 1); sensitivity.json says why, with no
    // load level.
    let (code, r) = dsa("support4-shape", shape, CUBIC);
    assert_eq!(code, 1, "a shape variable with gauge rows must be refused");
    let status = r["status"].as_str().unwrap();
    assert!(
        status.contains("`R`") && status.contains("coefficient mode"),
        "{status}"
    );
    assert!(r["loads"].as_array().unwrap().is_empty());

    // The default kernel at support 4, the quartic spline, needs no rows: the shape variable
    // is carried by both methods like at any other support (measured: continuum − dual
    // 2.5e-12 (R), 1.0e-13 (t), 3.9e-13 (ν) of the largest derivative; same bound).
    let (code, q) = dsa("support4-quartic", shape, None);
    assert_eq!(code, 0);
    let vars = q["variables"].as_array().unwrap();
    assert_eq!(vars.len(), 3);
    for v in vars {
        let d = v["continuum_vs_dual"].as_f64().unwrap();
        println!(
            "quartic spline, support 4: {} continuum vs dual {d:.1e}",
            v["name"]
        );
        assert!(d <= 1e-8, "{}: continuum vs dual {d:e}", v["name"]);
    }
}

/// The quartic spline's transform has no zero at the two-spacing wavelength
/// (`meshfree::KernelFunction`): the alternating field that the cubic B-spline passes not at
/// all at supports 4 and 8 reaches the points. Measured on the 17 × 17 grid (h·gradient
/// transfer): 1.9e-2 at 4, about the cubic's 1.2e-2 at 4.5, where it runs; 4.4e-4 at 8, weaker
/// (the quartic's own alternating sum is smallest near 7 and 9 spacings, 5e-4 and 2e-4 of the
/// constant one in one dimension) but 13 orders above the cubic's round-off there. Bounds: 1e-3
/// at 4 (the cubic's nearest supports that run pass more), 1e-4 at 8.
#[test]
fn the_quartic_spline_passes_alternating_fields_at_four_and_eight_spacings() {
    let quartic = Some("quartic-spline");
    let t4 = alternating_transfer_with("4.0", quartic);
    let t8 = alternating_transfer_with("8.0", quartic);
    println!("quartic spline, h·gradient transfer of an alternating field: 4 {t4:.3e}, 8 {t8:.3e}");
    assert!(t4 > 1e-3, "support 4: {t4}");
    assert!(t8 > 1e-4, "support 8: {t8}");
}

/// A support of 4 spacings without a kernel named: the quartic spline, no gauge rows, and the
/// refined models that stop with the cubic B-spline (its rows fix the exactly invisible
/// patterns, not the band of nearly invisible ones around them, whose smallest singular values
/// reach 2e-15 of the mean diagonal on the 25 × 25 hemisphere) run. Measured: hemisphere
/// 25 × 25 δ_A/P = 0.093695 (+0.21 % against MacNeal–Harder's 0.0935; 17 × 17: −1.07 %),
/// pinched cylinder 25 × 25 w = 1.7962e-5 (−1.56 % against 1.8248e-5). The bounds are the
/// shipped cases' own targets (`tests/verification_cases.rs`): ±1 % and ±2 %. The cubic
/// B-spline on the same hemisphere is the control: it stops at the first step, singular.
#[test]
fn support_four_takes_the_quartic_spline_and_runs_refined() {
    let mut case = hemisphere_case_with("4.0", None, false);
    assert_eq!(case.kernel.function, KernelFunction::QuarticSpline);
    case.particles.counts = [25, 25];
    let (d, rows) = radial_at_a(&case).unwrap();
    println!("hemisphere 25 × 25, support 4, quartic spline: δ_A/P = {d:.6} ({rows} rows)");
    assert_eq!(rows, 0, "the quartic spline needs no gauge rows");
    assert!(((d - 0.0935) / 0.0935).abs() < 0.01, "δ_A/P = {d}");

    let mut cubic = hemisphere_case("4.0", false);
    cubic.particles.counts = [25, 25];
    let err = radial_at_a(&cubic).unwrap_err();
    assert!(err.contains("singular"), "{err}");

    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("verification/pinched-cylinder/case.toml");
    let pinched = parse_shell_case(&case_text("pinched-cylinder", "4.0", None), &path).unwrap();
    let (u, rows) = displacement_at(&pinched, [0.0, 0.0]).unwrap();
    let (w, reference) = (-u[2], 1.8248e-5);
    println!("pinched cylinder 25 × 25, support 4, quartic spline: w = {w:.5e} ({rows} rows)");
    assert!((w - reference).abs() <= 0.02 * reference, "w = {w}");
}

/// `kernel.function`: the default follows the support, a named kernel is kept, an unknown one
/// is refused naming the key, the value and the choices.
#[test]
fn kernel_function_key() {
    let function =
        |support: &str, f: Option<&str>| hemisphere_case_with(support, f, false).kernel.function;
    assert_eq!(function("3.0", None), KernelFunction::CubicSpline);
    assert_eq!(function("4.0", None), KernelFunction::QuarticSpline);
    assert_eq!(function("7.9", None), KernelFunction::QuarticSpline);
    assert_eq!(function("4.5", None), KernelFunction::QuarticSpline);
    assert_eq!(function("3.8", None), KernelFunction::CubicSpline);
    assert_eq!(function("4.0", CUBIC), KernelFunction::CubicSpline);
    assert_eq!(
        function("3.0", Some("quartic-spline")),
        KernelFunction::QuarticSpline
    );
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("verification/hemisphere-linear/case.toml");
    let err = parse_shell_case(&case_text("hemisphere-linear", "3.0", Some("gauss")), &path)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("kernel.function")
            && err.contains("\"gauss\"")
            && err.contains("quartic-spline"),
        "{err}"
    );
}
