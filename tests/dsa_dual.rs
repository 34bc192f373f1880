//! Design sensitivity groundwork: the dual-number reference against finite
//! differences of complete re-runs, the Taylor remainder rate, repeatability, and a linear
//! elastic cantilever against beam theory.
//!
//! Case: a flat 1 × 1 plate, t = 0.05, clamped on its four edges (rows on the RK-interpolated
//! displacements and rotations at the edge particles), 7 × 7 particles (quadratic basis,
//! support 3 spacings), 2 × 2 Gauss points per cell, 5 Lobatto points through the thickness,
//! E = 1000, ν = 0.3, σ0 = 1, H = 100, β = 0.5, follower pressure p = 0.02 in 5 equal steps.
//! Elastic plate theory puts first yield (edge midpoint, surface) at p ≈ 0.008 (M = 0.0513 p a²,
//! σ = 6M/t²); the discrete plate first yields in step 4 (p = 0.016: 32 layer points, 92 in
//! step 5), so steps 1–3 are elastic. The collapse load of the clamped plate
//! (≈ 42.8 M_p/a², M_p = σ0 t²/4) is ≈ 0.027, above the last step.

use shelldsa::geometry::{Rectangle, Surface};
use shelldsa::material::MaterialParams;
use shelldsa::meshfree::quadrature::{gauss_legendre, CellQuadrature};
use shelldsa::meshfree::Edge;
use shelldsa::meshfree::{regular_grid, Basis, ParamBox};
use shelldsa::sensitivity::dual::{run_dual, DualMode, DualRun, SensitivityError};
use shelldsa::sensitivity::fd::{central_differences, fit_rate, response, taylor_remainders};
use shelldsa::sensitivity::{
    check_design, Design, DesignError, DesignKind, DesignScope, DesignVariable, MaterialParameter,
    Monitor,
};
use shelldsa::shell::constraints::{edge_constraints, EdgeCondition};
use shelldsa::shell::load::{Load, PointForce};
use shelldsa::shell::model::{Discretisation, ShellModel};
use shelldsa::shell::problem::ShellProblem;
use shelldsa::solver::SolverOptions;
use std::time::Instant;

#[path = "common/plate.rs"]
mod plate;
use plate::*;

fn dual_run(mode: DualMode) -> DualRun {
    let d = nominal_design();
    run_dual(
        Plate::problem(&d),
        variables(),
        Plate::monitors(),
        &driver(STEPS),
        SolverOptions::default(),
        mode,
    )
    .unwrap()
}

/// Dual reference = central differences (relative step 1e-4) within 1e-5 at every unflagged step
/// and every monitor with |ψ'| ≥ 1e-6 max|ψ'|; Taylor rate 2.0 ± 0.1; the dual state follows
/// the analysis to round-off; vector and per-variable duals agree; the run is repeatable.
#[test]
fn dual_reference_matches_finite_differences_on_a_yielding_clamped_plate() {
    let t0 = Instant::now();
    let dual = dual_run(DualMode::Vector);
    let total_dual = t0.elapsed();
    let steps = dual.records.len();
    assert_eq!(steps, STEPS, "steps: {:?}", dual.report.attempts.len());
    let plastic: Vec<usize> = dual.records.iter().map(|r| r.plastic_points).collect();
    println!(
        "yielding layer points per step: {plastic:?}; dual state vs analysis (relative): {:?}",
        dual.records
            .iter()
            .map(|r| format!("{:.1e}", r.value_mismatch))
            .collect::<Vec<_>>()
    );
    assert_eq!(plastic[0], 0, "step 1 must be elastic");
    assert!(
        plastic[STEPS - 2] > 0 && plastic[STEPS - 1] > 0,
        "yielding must be reached in the last two steps"
    );
    // The dual state's value parts are the analysis state: same kernels on the same values.
    // 1e-13 relative allows for the different summation order of the per-point residuals.
    for r in &dual.records {
        assert!(
            r.value_mismatch <= 1e-13,
            "step {}: dual state off the analysis by {:e}",
            r.step,
            r.value_mismatch
        );
    }

    // Repeatable: bit-identical records.
    let again = dual_run(DualMode::Vector);
    assert_eq!(dual.records, again.records, "two runs differ");

    // Vector and scalar duals: the same arithmetic per direction, so equal to round-off
    // (1e-12 of the largest derivative of the monitor).
    let t1 = Instant::now();
    let scalar = dual_run(DualMode::PerVariable);
    let total_scalar = t1.elapsed();
    for (a, b) in dual.records.iter().zip(&scalar.records) {
        for (da, db) in a.derivatives.iter().zip(&b.derivatives) {
            let scale = da.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
            for (x, y) in da.iter().zip(db) {
                assert!((x - y).abs() <= 1e-12 * scale, "vector {x} vs scalar {y}");
            }
        }
    }

    // Cost: the analysis alone (no hook: residual-first acceptance) against the reference.
    let d = nominal_design();
    let t2 = Instant::now();
    let plain = response(
        Plate::problem(&d),
        &driver(STEPS),
        SolverOptions::default(),
        &Plate::monitors(),
    )
    .unwrap();
    let analysis = t2.elapsed().as_secs_f64();
    let nv = variables().len() as f64;
    println!(
        "analysis alone {analysis:.3} s; with the vector dual ({} variables) {:.3} s, of which \
         the reference {:.3} s = {:.1} % of the analysis per variable; per-variable Dual64: \
         total {:.3} s, reference {:.3} s = {:.1} % per variable",
        nv,
        total_dual.as_secs_f64(),
        dual.reference.as_secs_f64(),
        100.0 * dual.reference.as_secs_f64() / analysis / nv,
        total_scalar.as_secs_f64(),
        scalar.reference.as_secs_f64(),
        100.0 * scalar.reference.as_secs_f64() / analysis / nv,
    );
    // The analysis with the hook follows the same path.
    for (a, b) in plain.values.iter().zip(&dual.records) {
        for (x, y) in a.iter().zip(&b.values) {
            assert!((x - y).abs() <= 1e-12 * x.abs().max(1e-12), "{x} vs {y}");
        }
    }

    let monitors = Plate::monitors();
    let base = nominal_design();
    for (v, var) in variables().iter().enumerate().take(4) {
        let tau = var.value(&base);
        // Step-size study: relative steps 1e-3, 1e-4, 1e-5. Truncation error of the central
        // difference ~ (h/τ)² ψ'''τ²/6ψ' ≈ 1e-8 at 1e-4 for responses smooth on the scale of τ;
        // the responses are converged to the round-off floor (~1e-14 relative), so the noise
        // is ~1e-14/1e-4 = 1e-10. 1e-5 relative leaves margin for both, and is what the
        // assertion uses at h = 1e-4 τ.
        let hs = [1e-3 * tau, 1e-4 * tau, 1e-5 * tau];
        let (nominal, fds) = central_differences(&Plate, &base, var, &hs, &monitors).unwrap();
        println!(
            "\n{}: step-size study (max relative difference per step; * flagged)",
            var.name
        );
        let mut checked = 0;
        for fd in &fds {
            let mut line = format!("  h/τ = {:.0e}:", fd.h / tau);
            for s in 0..steps {
                let dd = &dual.records[s].derivatives;
                let col: Vec<f64> = dd.iter().map(|m| m[v]).collect();
                let max = col.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
                let mut worst = 0.0_f64;
                for (m, &g) in col.iter().enumerate() {
                    if g.abs() < 1e-6 * max {
                        continue;
                    }
                    worst = worst.max((fd.derivatives[s][m] - g).abs() / g.abs());
                }
                line += &format!(" {:.1e}{}", worst, if fd.flagged[s] { "*" } else { "" });
                if (fd.h / tau - 1e-4).abs() < 1e-12 && !fd.flagged[s] {
                    checked += 1;
                    assert!(
                        worst <= 1e-5,
                        "{}: step {s}: dual vs central difference {worst:e}",
                        var.name
                    );
                }
            }
            println!("{line}");
        }
        // The elastic first step can never be flagged; at least it is compared.
        assert!(checked >= 1, "{}: no unflagged step", var.name);

        // Taylor remainder of the dual derivative: rate 2 where the active set is unchanged.
        let th = [8e-3 * tau, 4e-3 * tau, 2e-3 * tau, 1e-3 * tau, 5e-4 * tau];
        let deriv: Vec<Vec<f64>> = dual
            .records
            .iter()
            .map(|r| r.derivatives.iter().map(|m| m[v]).collect())
            .collect();
        let rows = taylor_remainders(&Plate, &base, var, &th, &monitors, &nominal, &deriv).unwrap();
        let mut fitted = 0;
        for s in 0..steps {
            let fit = fit_rate(&rows, s);
            println!(
                "  Taylor step {s}: rate {:?} from h/τ = {:?}, excluded (active set changed) {:?}, \
                 remainder exactly 0 {:?}",
                fit.rate,
                fit.used.iter().map(|h| h / tau).collect::<Vec<_>>(),
                fit.excluded.iter().map(|h| h / tau).collect::<Vec<_>>(),
                fit.exact.iter().map(|h| h / tau).collect::<Vec<_>>()
            );
            if fit.used.len() >= 3 {
                let rate = fit.rate.unwrap();
                assert!(
                    (rate - 2.0).abs() <= 0.1,
                    "{}: step {s}: Taylor rate {rate}",
                    var.name
                );
                fitted += 1;
            }
        }
        assert!(
            fitted >= 1,
            "{}: no step with three unflagged sizes",
            var.name
        );
    }
}

/// Linear elastic cantilever strip (L = 12, b = 1, t = 0.1, E = 1.2e6, ν = 0, tip load spread
/// over the tip edge; Sze, Liu & Lo 2004 §3.2) at a load small enough for a linear response:
/// - `E dδ/dE = −δ`: the discrete stiffness is proportional to E (membrane, bending and shear),
///   so this holds to the geometric nonlinearity of the step, O(δ/L) ≈ 5e-8 here;
/// - `t dδ/dt` against Timoshenko beam theory, `δ = PL³/(3EI) + PL/(kGA)`,
///   `t dδ/dt = −3 δ_b − δ_s`.
#[test]
fn elastic_cantilever_sensitivities_follow_beam_theory() {
    const L: f64 = 12.0;
    const E: f64 = 1.2e6;
    const T: f64 = 0.1;
    const P: f64 = 1e-6;
    let design = Design {
        thickness: T,
        material: MaterialParams::new(E, 0.0, 1e30, 0.0, 1.0).unwrap(),
        surface: None,
        tool_offsets: Default::default(),
    };
    let grid = regular_grid(ParamBox::unit(), 25, 3);
    let cq = CellQuadrature::for_particle_grid(&grid, 2, 4).unwrap();
    let g2 = gauss_legendre(2).unwrap();
    let disc = Discretisation {
        supports: grid.supports(3.0),
        particle_uv: grid.positions,
        basis: Basis::Quadratic,
        kernel: Default::default(),
        quadrature: cq.iter().map(|(p, w, _)| (p, w)).collect(),
        thickness_rule: g2.nodes.iter().copied().zip(g2.weights).collect(),
        thickness: T,
        symmetry: Vec::new(),
    };
    let surface = Surface::Rectangle(Rectangle::new(V3::zeros(), L * V3::x(), V3::y()).unwrap());
    let model = ShellModel::new(&surface, disc, design.material).unwrap();
    let rows = edge_constraints(&model, Edge::UMin, &EdgeCondition::Clamped).unwrap();
    // The tip load P spread over the edge u = 1 with 4-point Gauss–Legendre weights.
    let g4 = gauss_legendre(4).unwrap();
    let forces: Vec<PointForce> = g4
        .nodes
        .iter()
        .zip(&g4.weights)
        .map(|(&x, &w)| PointForce {
            uv: [1.0, 0.5 + 0.5 * x],
            force: [0.0, 0.0, P * w / 2.0],
        })
        .collect();
    let loads = forces.into_iter().map(Into::into).collect();
    let problem = ShellProblem::new(model, loads, rows).unwrap();
    let run = run_dual(
        problem,
        vec![
            DesignVariable::thickness(),
            DesignVariable::material(MaterialParameter::Young),
        ],
        vec![Monitor::new("tip deflection", [1.0, 0.5], 2).unwrap()],
        &driver(1),
        SolverOptions::default(),
        DualMode::Vector,
    )
    .unwrap();
    let r = &run.records[0];
    let delta = r.values[0];
    let (dt, de) = (r.derivatives[0][0], r.derivatives[0][1]);
    let i = T.powi(3) / 12.0;
    let db = P * L.powi(3) / (3.0 * E * i);
    let ds = P * L / (5.0 / 6.0 * E / 2.0 * T);
    let exact_t = -3.0 * db - ds;
    println!(
        "δ = {delta:e} (beam {:e}, {:+.3} %); E dδ/dE = {:e} (−δ: {:+.2e} rel.); t dδ/dt = {:e} \
         (beam {exact_t:e}, {:+.3} %)",
        db + ds,
        100.0 * (delta / (db + ds) - 1.0),
        E * de,
        E * de / -delta - 1.0,
        T * dt,
        100.0 * (T * dt / exact_t - 1.0)
    );
    // E dδ/dE = −δ up to the step's geometric nonlinearity, δ/L ≈ 5e-8 relative: 1e-6.
    assert!((E * de / -delta - 1.0).abs() <= 1e-6);
    // Discretisation: tests/shell_cantilever.rs measures δ within 0.1 % of beam theory on this
    // grid (−0.094 %). The thickness derivative has the discretisation error of δ at two
    // nearby thicknesses; 0.5 % allows for its h-dependence on t (L/t = 120, no locking
    // measured there).
    assert!((delta / (db + ds) - 1.0).abs() <= 2e-3, "δ = {delta}");
    assert!(
        (T * dt / exact_t - 1.0).abs() <= 5e-3,
        "t dδ/dt = {}",
        T * dt
    );
}

/// Design variables are checked before any analysis: unknown kinds and parameters, duplicate
/// variables, perturbations that make the design inadmissible.
#[test]
fn design_variables_are_validated() {
    let d = nominal_design();
    let model = Plate::model(&d);
    assert!(matches!(
        DesignKind::parse("material.yield"),
        Err(DesignError::UnknownParameter { ref name, .. }) if name == "yield"
    ));
    assert!(matches!(
        DesignKind::parse("radius"),
        Err(DesignError::UnknownKind { ref key }) if key == "radius"
    ));
    assert_eq!(
        DesignKind::parse("material.sigma0").unwrap(),
        DesignKind::Material(MaterialParameter::Sigma0)
    );
    assert_eq!(
        DesignKind::parse("thickness").unwrap(),
        DesignKind::Thickness
    );
    // The one check of a design variable, at the model's design with the steps 0, ±h.
    let base = Design::of(&model);
    let scope = DesignScope {
        base: Some(&base),
        model: Some(&model),
        tools: None,
    };
    let check = |v: &DesignVariable, h: f64| v.check(&[0.0, h, -h], &scope);
    // t = 0.05 perturbed by ±0.06 reaches −0.01.
    let e = check(&DesignVariable::thickness(), 0.06).unwrap_err();
    assert!(matches!(e, DesignError::InvalidPerturbation { ref variable, .. } if variable == "t"));
    // ν = 0.3 + 0.25 leaves (−1, 0.5).
    let nu = DesignVariable::material(MaterialParameter::Poisson);
    let e = check(&nu, 0.25).unwrap_err();
    assert!(e.to_string().contains("poisson"), "{e}");
    assert!(check(&nu, 0.1).is_ok());
    let dup = vec![
        DesignVariable::thickness(),
        DesignVariable::new("t2", DesignKind::Thickness),
    ];
    assert!(matches!(
        check_design(&dup, &|_| vec![0.0], &scope),
        Err(DesignError::Duplicate { .. })
    ));
    assert!(matches!(
        check_design(&[], &|_| vec![0.0], &scope),
        Err(DesignError::NoVariables)
    ));
    assert!(Monitor::new("bad", [0.5, 0.5], 3).is_err());
    // The dual reference refuses, before the analysis, a load it does not carry: the director
    // filter with its per-particle strength.
    let filter = shelldsa::shell::stabilisation::DirectorFilter::with_strength(
        &model,
        1.0,
        shelldsa::shell::stabilisation::FilterStrength::DirectorForce,
        0.0,
    )
    .unwrap();
    let problem = ShellProblem::new(model, vec![Load::DirectorFilter(filter)], Vec::new()).unwrap();
    let err = run_dual(
        problem,
        vec![DesignVariable::thickness()],
        Plate::monitors(),
        &driver(STEPS),
        SolverOptions::default(),
        DualMode::Vector,
    )
    .unwrap_err();
    assert!(
        matches!(
            err,
            SensitivityError::UnsupportedLoad {
                index: 0,
                kind: "director-stabilisation"
            }
        ),
        "{err}"
    );
}
