//! Shell output (`shelldsa::io::shell_output`) and the shell `run` command.
//!
//! Small flat shells are put into known committed states (a uniform stretch, a pure bending
//! state, a plastic stretch) by committing chosen DOF increments with `ShellModel::commit`; their
//! VTU, PVD, results.json and plot are written and the VTU/PVD files read back by an independent
//! reader (meshio, through `tests/read_vtu.py --dump`). Field names, sizes and values are checked
//! against `ShellModel::sample` (bit for bit: same numbers, written and read back) and against
//! closed forms (stress resultants of the stretch and bending states). Then the CLI runs a
//! cantilever case file end to end and a case that stops at plastic collapse.
//!
//! meshio must be installed (`pip install meshio`); the tests fail, rather than skip, without it.

mod common;

use serde_json::Value;
use shelldsa::io::shell_build::{cell_quadrature, discretisation, particle_grid};
use shelldsa::io::shell_case::{parse_shell_case, Monitor, OutputSpec, ShellCase};
use shelldsa::io::shell_output::{
    cell_resultants, shell_vtu, OutputGrid, ShellOutput, PLOT_FILE, PVD_FILE, RESULTS_FILE,
};
use shelldsa::meshfree::quadrature::CellQuadrature;
use shelldsa::shell::model::ShellModel;
use shelldsa::solver::{FailureReason, StepRecord};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

#[path = "common/meshio.rs"]
mod meshio;
use meshio::{meshio_dump, num};

fn unique_dir(tag: &str) -> PathBuf {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos();
    let dir = std::env::temp_dir().join(format!(
        "shelldsa-shell-output-{tag}-{}-{nanos}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn cleanup(dir: &Path) {
    // SHELLDSA_KEEP_TEST_OUTPUT=1 keeps the files (to open them in ParaView).
    if std::env::var_os("SHELLDSA_KEEP_TEST_OUTPUT").is_some() {
        println!("kept {}", dir.display());
    } else {
        let _ = std::fs::remove_dir_all(dir);
    }
}

fn table(v: &Value) -> Vec<Vec<f64>> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|r| r.as_array().unwrap().iter().map(num).collect())
        .collect()
}

/// A flat 2 × 1 plate on z = 0 (u along x, v along y), 5 × 4 particles, quadratic basis,
/// supports of 3 spacings, one cell per particle spacing with 2 × 2 Gauss points, thickness 0.1.
fn plate_case(material: &str, thickness_rule: &str, points: usize) -> ShellCase {
    let text = format!(
        r#"
thickness = 0.1
[problem]
kind = "shell"
title = "plate"
[surface]
type = "rectangle"
origin = [0.0, 0.0, 0.0]
edge_u = [2.0, 0.0, 0.0]
edge_v = [0.0, 1.0, 0.0]
[particles]
grid = [5, 4]
[kernel]
basis = "quadratic"
support = 3.0
[integration]
cells = "per-particle-spacing"
gauss = 2
thickness_points = {points}
thickness_rule = "{thickness_rule}"
[material]
{material}
[steps]
initial_step = 1.0
min_step = 1.0
max_step = 1.0
[[monitor]]
name = "corner"
at = [1.0, 1.0]
"#
    );
    parse_shell_case(&text, Path::new("plate.toml")).unwrap()
}

const ELASTIC: &str = "young = 1000.0\npoisson = 0.3\nsigma0 = 1e30\nhardening = 0.0\nbeta = 1.0";

fn plate_model(case: &ShellCase) -> (ShellModel, CellQuadrature) {
    let grid = particle_grid(case);
    let cq = cell_quadrature(case, &grid).unwrap();
    let disc = discretisation(case, &grid, &cq).unwrap();
    (
        ShellModel::new(&case.surface, disc, case.material).unwrap(),
        cq,
    )
}

/// Commit the generalised increment `q` (one converged step).
fn commit(m: &mut ShellModel, q: &[f64]) {
    let c = m.contributions(q, false).unwrap();
    m.commit(q, c);
}

/// Initial position of particle `i` of the 2 × 1 plate.
fn x0(m: &ShellModel, i: usize) -> [f64; 2] {
    [2.0 * m.particle_uv[i][0], m.particle_uv[i][1]]
}

fn record(load_start: f64, load: f64, converged: bool) -> StepRecord {
    StepRecord {
        load_start,
        load,
        step_size: load - load_start,
        iterations: 2,
        active_set_iterations: 0,
        residual_norms: vec![1.0, 1e-3, 1e-12],
        energy_norms: vec![1.0, 1e-20],
        converged,
        predictor: shelldsa::solver::Predictor::Zero,
        acceptance: converged.then_some(shelldsa::solver::Acceptance::Tolerance),
        roundoff_floors: vec![0.0; 3],
        residual_only: vec![(2, 1e-12)],
        factorised_at: converged.then_some(shelldsa::solver::FactorisedAt::PreviousIterate),
        timing: Default::default(),
        krylov: Vec::new(),
        krylov_gave_up: Vec::new(),
        krylov_skipped: Vec::new(),
        backtracks: Vec::new(),
        continuation: Vec::new(),
        failure: (!converged).then_some(FailureReason::MaxIterations(2)),
    }
}

/// Uniform stretch `u = s X` in x, applied in three equal increments `Δu_I = (s X_I, 0, 0)`.
/// Step k starts from `x = (1 + (k−1)s) X`, so `H11 = h_k = s/(1 + (k−1)s)`; the mid-step
/// gradient gives `Δε11 = h_k/(1 + h_k/2)` (eqs 28–29) with no spin, and the hypoelastic
/// update adds `D Δε` (plane stress, eq 9): `σ11 = E/(1−ν²) Σ Δε11`, `σ22 = ν σ11`. The
/// resultants are `N = t σ` (Gauss weights sum to 2), `M = Q = 0`.
///
/// Written with `every = 2`, `subdivide = 2`: steps 0 (initial), 2 and 3 (the last) have VTUs.
#[test]
fn stretch_steps_are_written_and_read_back_by_meshio() {
    let case = plate_case(ELASTIC, "gauss", 2);
    let (mut m, cq) = plate_model(&case);
    let dir = unique_dir("stretch");
    let grid = OutputGrid::new(&cq, 2).unwrap();
    let spec = OutputSpec {
        vtu: true,
        every: 2,
        subdivide: 2,
        plot: true,
    };
    let monitors = vec![Monitor {
        name: "corner".into(),
        at: [1.0, 1.0],
    }];
    let mut out = ShellOutput::new(
        &dir,
        "plate.toml",
        "stretch",
        &monitors,
        spec,
        grid.clone(),
        1.0,
        Instant::now(),
    )
    .unwrap();
    out.initial(&m, &case.surface).unwrap();

    let s = 1e-3;
    let mut q = vec![0.0; m.n_dofs()];
    for i in 0..m.particles.len() {
        q[5 * i] = s * x0(&m, i)[0];
    }
    let mut attempts = Vec::new();
    let mut eps = 0.0;
    for k in 1..=3 {
        if k == 2 {
            attempts.push(record(1.0 / 3.0, 1.0, false)); // a cut attempt in between
        }
        commit(&mut m, &q);
        let h = s / (1.0 + (k - 1) as f64 * s);
        eps += h / (1.0 + h / 2.0);
        let rec = record((k - 1) as f64 / 3.0, k as f64 / 3.0, true);
        let summary = out.converged(&m, &case.surface, &rec).unwrap().clone();
        assert_eq!(summary.step, k);
        // The monitor is the sampled displacement: at X = (2, 1), u = (2 k s, 0, 0) (RK
        // reproduces linear fields to round-off: 1e-12 relative).
        let want = m.sample(&case.surface, [1.0, 1.0]).unwrap().displacement;
        assert_eq!(summary.monitors[0], [want[0], want[1], want[2]]);
        assert!((want[0] - 2.0 * k as f64 * s).abs() <= 1e-12 * 2.0 * k as f64 * s);
        assert_eq!(summary.vtu.is_some(), k != 1, "every = 2 and the last step");
        attempts.push(rec);
    }
    out.finish(&m, &case.surface, "complete", &attempts)
        .unwrap();

    // Files on disk.
    let steps = dir.join("steps");
    for (k, present) in [(0, true), (1, false), (2, true), (3, true)] {
        assert_eq!(
            steps.join(format!("step_{k:04}.vtu")).exists(),
            present,
            "step {k}"
        );
    }
    let png = std::fs::read(dir.join(PLOT_FILE)).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "the plot is a PNG");

    // meshio's view.
    let pvd = dir.join(PVD_FILE);
    let last = steps.join("step_0003.vtu");
    let first = steps.join("step_0000.vtu");
    let d = meshio_dump(&[pvd.clone(), last.clone(), first.clone()]);
    let entries = d[pvd.to_str().unwrap()]["entries"].as_array().unwrap();
    let got: Vec<(f64, &str)> = entries
        .iter()
        .map(|e| (num(&e["time"]), e["file"].as_str().unwrap()))
        .collect();
    assert_eq!(
        got,
        vec![
            (0.0, "steps/step_0000.vtu"),
            (2.0 / 3.0, "steps/step_0002.vtu"),
            (1.0, "steps/step_0003.vtu"),
        ]
    );

    let v = &d[last.to_str().unwrap()];
    // 4 × 3 integration cells, split twice: 9 × 7 nodes, 8 × 6 quads.
    let points = table(&v["points"]);
    assert_eq!(points.len(), 63);
    let cells = v["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 1);
    assert_eq!(cells[0]["type"], "quad");
    assert_eq!(cells[0]["connectivity"].as_array().unwrap().len(), 48);
    let names = |k: &str| {
        let mut n: Vec<String> = v[k].as_object().unwrap().keys().cloned().collect();
        n.sort();
        n
    };
    assert_eq!(
        names("point_data"),
        ["director", "director_rotation", "displacement"]
    );
    assert_eq!(
        names("cell_data"),
        [
            "M",
            "N",
            "Q",
            "eps_p_bottom",
            "eps_p_mid",
            "eps_p_top",
            "von_mises_bottom",
            "von_mises_top"
        ]
    );
    for (name, comps) in [
        ("displacement", 3),
        ("director", 3),
        ("director_rotation", 3),
    ] {
        let t = table(&v["point_data"][name]);
        assert_eq!((t.len(), t[0].len()), (63, comps), "{name}");
    }
    for (name, comps) in [
        ("N", 3),
        ("M", 3),
        ("Q", 2),
        ("eps_p_top", 1),
        ("von_mises_top", 1),
    ] {
        let t = table(&v["cell_data"][name]);
        assert_eq!((t.len(), t[0].len()), (48, comps), "{name}");
    }

    // Point values are ShellModel::sample at the grid nodes, bit for bit, in VTU order
    // (node (i, j) at index i·n_v + j, v fastest).
    let disp = table(&v["point_data"]["displacement"]);
    let dirs = table(&v["point_data"]["director"]);
    let rot = table(&v["point_data"]["director_rotation"]);
    for (p, uv) in grid.nodes().iter().enumerate() {
        let smp = m.sample(&case.surface, *uv).unwrap();
        assert_eq!(points[p], smp.x0.as_slice(), "node {p} at {uv:?}");
        assert_eq!(disp[p], smp.displacement.as_slice(), "node {p}");
        // Analytic: u = 3 s X (RK linear reproduction, 1e-12 relative); the director does not
        // turn (|rotation| and |d − e3| at round-off, 1e-12).
        assert!((disp[p][0] - 3.0 * s * 2.0 * uv[0]).abs() <= 1e-12 * 6.0 * s);
        assert!(disp[p][1].abs() + disp[p][2].abs() <= 1e-12 * 6.0 * s);
        assert!(rot[p].iter().all(|r| r.abs() <= 1e-12), "{:?}", rot[p]);
        assert!((dirs[p][2] - 1.0).abs() <= 1e-12 && dirs[p][0].abs() <= 1e-12);
    }
    // A node inside a cell (subdivide = 2 puts nodes at cell centres): (i, j) = (3, 1).
    assert_eq!(grid.nodes()[3 * 7 + 1], [3.0 / 8.0, 1.0 / 6.0]);

    // Resultants: closed form, uniform over the plate. Tolerance 1e-9 relative to N11: the
    // strains come from RK derivatives that reproduce linear fields to ~1e-13 (reference
    // values §5) of a strain of 3e-3, i.e. a relative error ~1e-10 at worst.
    let (e, nu, t) = (1000.0, 0.3, 0.1);
    let n11 = t * e / (1.0 - nu * nu) * eps;
    let tol = 1e-9 * n11;
    for name in ["N", "M", "Q"] {
        for row in table(&v["cell_data"][name]) {
            let want: &[f64] = match name {
                "N" => &[n11, nu * n11, 0.0],
                "M" => &[0.0, 0.0, 0.0],
                _ => &[0.0, 0.0],
            };
            for (g, w) in row.iter().zip(want) {
                assert!((g - w).abs() <= tol, "{name}: {row:?} vs {want:?}");
            }
        }
    }
    for name in ["eps_p_top", "eps_p_mid", "eps_p_bottom"] {
        assert!(table(&v["cell_data"][name]).iter().all(|r| r[0] == 0.0));
    }
    // Von Mises of the plane stress (σ11, ν σ11): σ11 √(1 − ν + ν²).
    let vm = n11 / t * (1.0 - nu + nu * nu).sqrt();
    for name in ["von_mises_top", "von_mises_bottom"] {
        for r in table(&v["cell_data"][name]) {
            assert!((r[0] - vm).abs() <= 1e-9 * vm, "{name} {} vs {vm}", r[0]);
        }
    }
    // The initial state: zero displacement and resultants.
    let v0 = &d[first.to_str().unwrap()];
    assert!(table(&v0["point_data"]["displacement"])
        .iter()
        .all(|r| r.iter().all(|x| *x == 0.0)));
    assert!(table(&v0["cell_data"]["N"])
        .iter()
        .all(|r| r.iter().all(|x| *x == 0.0)));

    // results.json: every attempt in order, the cut one without monitors.
    let res: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join(RESULTS_FILE)).unwrap()).unwrap();
    assert_eq!(res["status"], "complete");
    assert_eq!(res["case"], "plate.toml");
    assert!(res["wall_time_s"].as_f64().unwrap() >= 0.0);
    let st = res["steps"].as_array().unwrap();
    assert_eq!(st.len(), 4);
    let conv: Vec<bool> = st
        .iter()
        .map(|x| x["converged"].as_bool().unwrap())
        .collect();
    assert_eq!(conv, [true, false, true, true]);
    assert_eq!(
        st.iter()
            .map(|x| x["step"].as_u64().unwrap())
            .collect::<Vec<_>>(),
        [1, 2, 2, 3]
    );
    assert!(st[1]["monitors"].is_null());
    assert_eq!(st[1]["failure"], "no convergence in 2 iterations");
    assert!(st[0]["vtu"].is_null());
    assert_eq!(st[3]["vtu"], "steps/step_0003.vtu");
    assert_eq!(st[3]["iterations"], 2);
    assert_eq!(st[3]["residual_norms"].as_array().unwrap().len(), 3);
    let ux = st[3]["monitors"]["corner"]["displacement"][0]
        .as_f64()
        .unwrap();
    assert!((ux - 6.0 * s).abs() <= 1e-12 * 6.0 * s, "{ux}");
    assert!(!dir.join("results.json.tmp").exists());
    cleanup(&dir);
}

/// Pure bending: directors turned about e2 = y by `β = κ X` (the rotation DOF α2 of every
/// particle) with the shear-free deflection `w = −κ X²/2` (so `x̄,1 ⟂ d` to O((κX)³)). Plate
/// theory: `M11 = E t³ κ / (12 (1 − ν²))`, `M22 = ν M11`, `M12 = 0`.
/// Tolerances: the mid-step gradient makes the rigid part of the motion strain-free and the
/// terms even in ζ drop out of `M`, so the shell kinematics differ from plate theory only at
/// second order in the rotation `κX ≤ 2e-4` (≤ 4e-8; measured 7.5e-9): `M` to 1e-6, which
/// any wrong sign, factor, frame or node ordering exceeds by orders of magnitude. The
/// membrane strain `w'²/2 ≤ 2κ²` bounds `|N| ≤ E t 2κ²/(1−ν²)` (measured 1.7e-6 against
/// 2.2e-6); the shear strain `x̄,1·d = O((κX)³)` bounds `|Q| ≤ k G t (2κ)³` (measured 5.8e-11
/// against 2.6e-10). The director rotation vector at a node is `(0, κ X, 0)` up to O((κX)³)
/// and the RK interpolation of the directors (exact for quadratics; sin κX is quadratic to
/// O((κX)³) ≈ 8e-12): checked to 1e-9 of κ.
#[test]
fn bending_state_gives_plate_moments_and_director_rotations() {
    let case = plate_case(
        "young = 1000.0\npoisson = 0.3\nsigma0 = 1e30\nhardening = 0.0\nbeta = 1.0",
        "gauss",
        2,
    );
    let (mut m, cq) = plate_model(&case);
    let kappa = 1e-4;
    let mut q = vec![0.0; m.n_dofs()];
    for i in 0..m.particles.len() {
        let x = x0(&m, i)[0];
        // Lamina vectors of a flat plate: e1 = x, e2 = z × x = y.
        assert!((m.particles[i].e[1] - nalgebra::Vector3::y()).norm() < 1e-15);
        q[5 * i + 2] = -kappa * x * x / 2.0;
        q[5 * i + 4] = kappa * x;
    }
    commit(&mut m, &q);
    let grid = OutputGrid::new(&cq, 1).unwrap();
    let dir = unique_dir("bending");
    let file = dir.join("bending.vtu");
    shell_vtu(&m, &case.surface, &grid)
        .unwrap()
        .write(&file)
        .unwrap();
    let d = meshio_dump(std::slice::from_ref(&file));
    let v = &d[file.to_str().unwrap()];

    let (e, nu, t): (f64, f64, f64) = (1000.0, 0.3, 0.1);
    let m11 = e * t.powi(3) * kappa / (12.0 * (1.0 - nu * nu));
    let mm = table(&v["cell_data"]["M"]);
    let nn = table(&v["cell_data"]["N"]);
    let qq = table(&v["cell_data"]["Q"]);
    let (mut worst_m, mut worst_n, mut worst_q) = (0.0f64, 0.0f64, 0.0f64);
    for c in 0..mm.len() {
        worst_m = worst_m
            .max((mm[c][0] / m11 - 1.0).abs())
            .max((mm[c][1] / (nu * m11) - 1.0).abs())
            .max((mm[c][2] / m11).abs());
        worst_n = worst_n.max(nn[c].iter().fold(0.0, |a, x| a.max(x.abs())));
        worst_q = worst_q.max(qq[c].iter().fold(0.0, |a, x| a.max(x.abs())));
    }
    println!(
        "bending: M11 = {m11:e} expected; worst relative M error {worst_m:.2e}, max |N| {worst_n:.2e}, max |Q| {worst_q:.2e}"
    );
    assert!(worst_m < 1e-6, "{worst_m}");
    let n_bound = e * t * 2.0 * kappa * kappa / (1.0 - nu * nu);
    assert!(worst_n <= n_bound, "{worst_n} > {n_bound}");
    let q_bound = 5.0 / 6.0 * e / (2.0 * (1.0 + nu)) * t * (2.0 * kappa).powi(3);
    assert!(worst_q <= q_bound, "{worst_q} > {q_bound}");

    let rot = table(&v["point_data"]["director_rotation"]);
    for (p, uv) in grid.nodes().iter().enumerate() {
        let want = [0.0, kappa * 2.0 * uv[0], 0.0];
        for c in 0..3 {
            assert!(
                (rot[p][c] - want[c]).abs() <= 1e-9 * kappa,
                "node {p}: {:?} vs {want:?}",
                rot[p]
            );
        }
    }
    cleanup(&dir);
}

/// A plastic stretch through a 3-point Lobatto rule: every layer yields equally, so the
/// plastic strain is the same at top, middle and bottom, and with isotropic hardening
/// (β = 1) the von Mises stress equals the current yield stress `σ0 + H ē^p` exactly
/// (reference values §3: "in every plastic case σ_vm = σ_y0 + H ē^p"); checked to 1e-10
/// (the return map's consistency tolerance is 1e-12 of κ², reference §3's cross-check 3e-12).
#[test]
fn plastic_layers_report_equivalent_strain_and_yield_stress() {
    let case = plate_case(
        "young = 1000.0\npoisson = 0.3\nsigma0 = 0.5\nhardening = 100.0\nbeta = 1.0",
        "lobatto",
        3,
    );
    let (mut m, cq) = plate_model(&case);
    let s = 1e-3; // elastic trial σ11 = 1.1 > σ0 = 0.5
    let mut q = vec![0.0; m.n_dofs()];
    for i in 0..m.particles.len() {
        q[5 * i] = s * x0(&m, i)[0];
    }
    commit(&mut m, &q);
    let r = cell_resultants(&m, &OutputGrid::new(&cq, 1).unwrap()).unwrap();
    assert_eq!(r.len(), 12);
    for c in &r {
        let ep = c.eps_p[0];
        assert!(ep > 1e-4, "the stretch must yield: ē^p = {ep}");
        for k in 1..3 {
            assert!((c.eps_p[k] - ep).abs() <= 1e-10 * ep, "{:?}", c.eps_p);
        }
        let yield_stress = 0.5 + 100.0 * ep;
        for vm in c.von_mises {
            assert!(
                (vm - yield_stress).abs() <= 1e-10 * yield_stress,
                "σ_vm {vm} vs σ0 + H ē^p = {yield_stress}"
            );
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The command line.

/// A clamped cantilever strip (Sze, Liu & Lo 2004 §3.2's data: L = 12, b = 1, t = 0.1,
/// E = 1.2e6, ν = 0) with a tip force at the middle of the free edge.
fn cantilever_toml(force: f64, sigma0: f64, thickness: &str, steps: &str) -> String {
    format!(
        r#"
thickness = 0.1
[problem]
kind = "shell"
title = "cantilever"
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
gauss = 3
{thickness}
[material]
young = 1.2e6
poisson = 0.0
sigma0 = {sigma0:e}
hardening = 0.0
beta = 1.0
[[boundary]]
kind = "clamped"
edge = "u-min"
[[load]]
kind = "point-force"
at = [1.0, 0.5]
force = [0.0, 0.0, {force:e}]
[steps]
{steps}
[[monitor]]
name = "tip"
at = [1.0, 0.5]
"#
    )
}

const GAUSS2: &str = "thickness_points = 2\nthickness_rule = \"gauss\"";

fn run_cli(args: &[&str]) -> i32 {
    let mut v = vec!["shelldsa".to_string()];
    v.extend(args.iter().map(|s| s.to_string()));
    shelldsa::cli::main_with_args(v)
}

/// Tip deflection per unit load of the same discretisation, linear, by an independent path:
/// the model assembled directly into a dense tangent, the clamp as rows formed here from the
/// shape functions (every component of `Σ_I Ψ_I(ξ_J) q_I` held at zero at the particles J on
/// u = 0), the point force spread as `Ψ_I(ξ_P) P`, one dense solve with Lagrange multipliers.
fn independent_linear_tip_deflection() -> f64 {
    use nalgebra::Vector3;
    use shelldsa::geometry::{Rectangle, Surface};
    use shelldsa::material::MaterialParams;
    use shelldsa::meshfree::quadrature::gauss_legendre;
    use shelldsa::meshfree::{regular_grid, Basis, Edge, ParamBox, ShapeValues};
    use shelldsa::shell::model::Discretisation;

    let surface = Surface::Rectangle(
        Rectangle::new(
            Vector3::zeros(),
            Vector3::new(12.0, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
        )
        .unwrap(),
    );
    let grid = regular_grid(ParamBox::unit(), 13, 3);
    let cq = CellQuadrature::new(ParamBox::unit(), 12, 2, 3).unwrap();
    let g2 = gauss_legendre(2).unwrap();
    let disc = Discretisation {
        particle_uv: grid.positions.clone(),
        supports: vec![[3.0 / 12.0, 3.0 / 2.0]; grid.positions.len()],
        basis: Basis::Quadratic,
        kernel: Default::default(),
        quadrature: cq.iter().map(|(p, w, _)| (p, w)).collect(),
        thickness_rule: g2.nodes.iter().copied().zip(g2.weights.clone()).collect(),
        thickness: 0.1,
        symmetry: Vec::new(),
    };
    let material = MaterialParams::new(1.2e6, 0.0, 1e30, 0.0, 1.0).unwrap();
    let mut m = ShellModel::new(&surface, disc, material).unwrap();
    // The case file takes the default integration (second-order VCI): the same here.
    let rule = shelldsa::shell::integration::boundary_rule(&m, ParamBox::unit()).unwrap();
    shelldsa::shell::integration::apply_vci(
        &mut m,
        shelldsa::meshfree::vci::VciOrder::Second,
        &rule,
    )
    .unwrap();
    let n = m.n_dofs();
    let c = m.contributions(&vec![0.0; n], true).unwrap();
    let k = m.dense_tangent(&c);
    let mut f = vec![0.0; n];
    let mut sv = ShapeValues::new();
    m.shape_functions.evaluate([1.0, 0.5], &mut sv).unwrap();
    for (i, psi, _) in sv.iter() {
        f[5 * i + 2] += psi;
    }
    let clamped = common::particles_on_edges(&m.particle_uv, &[Edge::UMin]);
    let xj: Vec<[f64; 2]> = clamped.iter().map(|&j| m.particle_uv[j]).collect();
    let zeros = vec![0.0; xj.len()];
    let rows: Vec<common::Row> = (0..5)
        .flat_map(|c| common::nodal_rows(&m.shape_functions, &xj, 5, c, &zeros))
        .collect();
    let q = common::solve_constrained(&k, &f, &rows);
    m.shape_functions.evaluate([1.0, 0.5], &mut sv).unwrap();
    sv.iter().map(|(i, psi, _)| psi * q[5 * i + 2]).sum()
}

/// `shelldsa run` on a cantilever case file: exit 0, the output files, and the tip deflection
/// (i) equal to an independent linear solve of the same discretisation: at P = 1e-4 the
/// response is linear to (δ/L)² ≈ 2e-9, so 1e-7 relative; (ii) near Timoshenko beam theory,
/// δ = PL³/(3EI) + PL/(kGA) = 5.76024 P: tests/shell_cantilever.rs measured −1.2 % for 13
/// particles along the length (4 × 4 Gauss points in h/2 cells, load spread over the edge),
/// so within 3 % here (3 × 3 points in h cells, load at one point; measured −1.64 %).
#[test]
fn cli_runs_a_cantilever_case() {
    let dir = unique_dir("cli-cantilever");
    let case = dir.join("cantilever.toml");
    let p = 1e-4;
    std::fs::write(
        &case,
        cantilever_toml(
            p,
            1e30,
            GAUSS2,
            "initial_step = 0.5\nmin_step = 0.1\nmax_step = 0.5\nresidual_rtol = 1e-10",
        ),
    )
    .unwrap();
    let out = dir.join("out");
    assert_eq!(run_cli(&["check", case.to_str().unwrap()]), 0);
    let code = run_cli(&[
        "run",
        case.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ]);
    assert_eq!(code, 0);
    let res: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join(RESULTS_FILE)).unwrap()).unwrap();
    assert_eq!(res["status"], "complete");
    let st = res["steps"].as_array().unwrap();
    assert_eq!(st.len(), 2, "two steps of 0.5, both converged: {st:?}");
    let tip = |k: usize| {
        st[k]["monitors"]["tip"]["displacement"][2]
            .as_f64()
            .unwrap()
    };
    let dense = independent_linear_tip_deflection();
    let cli = tip(1) / p;
    let timoshenko =
        12f64.powi(3) / (3.0 * 1.2e6 * 0.1f64.powi(3) / 12.0) + 12.0 / (5.0 / 6.0 * 0.6e6 * 0.1);
    println!(
        "cantilever via the CLI: δ/P = {cli:.8}, independent dense solve {dense:.8}, Timoshenko {timoshenko:.6} ({:+.3} %)",
        100.0 * (cli / timoshenko - 1.0)
    );
    assert!((cli / dense - 1.0).abs() < 1e-7, "{cli} vs {dense}");
    assert!((cli / timoshenko - 1.0).abs() < 0.03);
    // Half the load, half the deflection (linear).
    assert!((tip(0) / tip(1) - 0.5).abs() < 1e-7);
    for f in [
        "steps/step_0000.vtu",
        "steps/step_0001.vtu",
        "steps/step_0002.vtu",
        PVD_FILE,
        PLOT_FILE,
    ] {
        assert!(out.join(f).exists(), "{f}");
    }
    cleanup(&dir);
}

/// Elastic–perfectly plastic cantilever loaded to about twice its limit load: the run must
/// stop (exit code 3), keep every converged step in results.json and the PVD, and name the
/// failure. With 5 Lobatto points through the thickness (ζ = 0, ±0.6547, ±1; weights 0.711,
/// 0.544, 0.1) the surface layers yield at the root when P L = σ0 b t²/6, i.e. P_y = 0.0139
/// for σ0 = 100, and the section's plastic moment is σ0 b (t²/4) Σ w|ζ| = 0.2282 σ0 b t², so
/// beam theory's limit load is P_lim = 0.0190. The case asks for P = 0.04 in steps of 0.01.
/// Measured: the last converged step is at P = 0.025 (a smooth RK field cannot localise a
/// hinge at the clamp, so the discrete limit load lies above beam theory's, as that of any
/// kinematically admissible field space must), and the next attempts invert the shell.
#[test]
fn cli_reports_a_run_that_stops_at_plastic_collapse() {
    let dir = unique_dir("cli-collapse");
    let case = dir.join("collapse.toml");
    std::fs::write(
        &case,
        cantilever_toml(
            0.04,
            100.0,
            "thickness_points = 5\nthickness_rule = \"lobatto\"",
            "initial_step = 0.25\nmin_step = 0.05\nmax_step = 0.25\nmax_iterations = 12",
        ),
    )
    .unwrap();
    let out = dir.join("out");
    let code = run_cli(&[
        "run",
        case.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(
        code, 3,
        "a run that stops before the final load exits with 3"
    );
    let res: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join(RESULTS_FILE)).unwrap()).unwrap();
    let status = res["status"].as_str().unwrap();
    assert!(status.starts_with("failed: "), "{status}");
    let st = res["steps"].as_array().unwrap();
    let converged: Vec<&Value> = st.iter().filter(|s| s["converged"] == true).collect();
    assert!(!converged.is_empty(), "the elastic first step converges");
    let last_load = converged.last().unwrap()["load_factor"].as_f64().unwrap();
    assert!(last_load < 1.0, "{last_load}");
    assert_eq!(st.last().unwrap()["converged"], false);
    assert!(st.last().unwrap()["failure"].is_string());
    // The PVD lists the initial state and every converged step, all readable.
    let pvd = out.join(PVD_FILE);
    let d = meshio_dump(std::slice::from_ref(&pvd));
    let entries = d[pvd.to_str().unwrap()]["entries"].as_array().unwrap();
    assert_eq!(entries.len(), converged.len() + 1);
    // The plastic strain reached the VTU of the last converged step.
    let last_vtu = out.join(converged.last().unwrap()["vtu"].as_str().unwrap());
    let v = meshio_dump(std::slice::from_ref(&last_vtu));
    let eps = table(&v[last_vtu.to_str().unwrap()]["cell_data"]["eps_p_top"]);
    let max_eps = eps.iter().fold(0.0f64, |a, r| a.max(r[0]));
    println!(
        "collapse: status {status}; {} converged step(s), last load factor {last_load}, max ē^p (top) {max_eps:e}",
        converged.len()
    );
    assert!(max_eps > 0.0, "the root yields before collapse");
    cleanup(&dir);
}

/// `shelldsa check` on a bad case exits with 1 (and names the key on stderr).
#[test]
fn cli_check_rejects_a_bad_case() {
    let dir = unique_dir("cli-check");
    let case = dir.join("bad.toml");
    std::fs::write(
        &case,
        cantilever_toml(
            1.0,
            1e30,
            GAUSS2,
            "initial_step = 0.5\nmin_step = 0.1\nmax_step = 0.5",
        )
        .replace("edge = \"u-min\"", "edge = \"left\""),
    )
    .unwrap();
    assert_eq!(run_cli(&["check", case.to_str().unwrap()]), 1);
    cleanup(&dir);
}

/// A failure to write a step's results stops the run with that error (not a Newton failure),
/// and results.json still gets a final status naming it. The output is sabotaged from the
/// progress callback: after step 1 the `steps/` directory is removed, so step 2's VTU cannot
/// be written.
#[test]
fn an_output_failure_stops_the_run_and_is_reported() {
    use shelldsa::io::shell_build::{build, run, BuildError};
    let dir = unique_dir("output-failure");
    let case = parse_shell_case(
        &cantilever_toml(
            1e-4,
            1e30,
            GAUSS2,
            "initial_step = 0.5\nmin_step = 0.1\nmax_step = 0.5",
        ),
        Path::new("cantilever.toml"),
    )
    .unwrap();
    let mut built = build(&case).unwrap();
    let out = dir.join("out");
    let mut seen = Vec::new();
    let r = run(&case, &mut built, &out, Instant::now(), |s| {
        seen.push(s.step);
        std::fs::remove_dir_all(out.join("steps")).unwrap();
    });
    match r {
        Err(BuildError::Output(e)) => println!("output failure reported: {e}"),
        other => panic!("expected an output error, got {other:?}"),
    }
    assert_eq!(seen, [1], "the run stops at the step whose output failed");
    let res: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join(RESULTS_FILE)).unwrap()).unwrap();
    let status = res["status"].as_str().unwrap();
    assert!(status.starts_with("failed: writing results: "), "{status}");
    cleanup(&dir);
}
