//! The continuum DSA's sensitivity systems solved by GMRES on the converged tangent,
//! preconditioned by the driver's factorisation of an earlier iterate
//! (`SensitivitySolve::Krylov`: the driver assembles the converged tangent where it tests
//! convergence but does not factorise it), against the factorised converged tangent
//! (`SensitivitySolve::Factorised`) and against the dual-number reference run on its own, on
//! the reduced elastoplastic hemisphere (`verification/hemisphere-plastic-dsa/ci.toml`: shape,
//! thickness and material variables) and the reduced bending case with contact
//! (`verification/cylindrical-bending-dsa/ci.toml`: tool variables).
//!
//! Run: `cargo test --release --test dsa_krylov_solve -- --nocapture`.

use shelldsa::io::dsa_study::{base_design, CaseAnalysis};
use shelldsa::io::shell_case::{read_shell_case, ShellCase};
use shelldsa::sensitivity::continuum::{ContinuumRun, ContinuumSchedule, SensitivitySolve};
use shelldsa::sensitivity::dual::{run_dual_on, DualMode};
use shelldsa::sensitivity::fd::Analysis;
use shelldsa::sensitivity::{run_hooked, DsaAnalysis, HookedMethods};
use shelldsa::solver::FactorisedAt;
use std::path::Path;

fn case(rel: &str) -> ShellCase {
    read_shell_case(&Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)).unwrap()
}

fn analysis<'a>(
    case: &'a ShellCase,
    a: &CaseAnalysis<'a>,
    newton: &'a shelldsa::solver::NewtonSolver,
    problem: shelldsa::shell::problem::ShellProblem,
) -> DsaAnalysis<'a> {
    let dsa = case.dsa.as_ref().unwrap();
    DsaAnalysis {
        problem,
        surface: Some(&case.surface),
        variables: dsa.variables(),
        monitors: dsa.monitors.clone(),
        newton,
        solver: a.solver(),
    }
}

fn continuum(case: &ShellCase, solve: SensitivitySolve) -> ContinuumRun {
    let a = CaseAnalysis { case };
    let (problem, newton) = a.build(&base_design(case)).unwrap();
    let methods = HookedMethods {
        continuum: true,
        dual: None,
        schedule: ContinuumSchedule::Synchronous,
        solve,
    };
    let (c, _) = run_hooked(analysis(case, &a, &newton, problem), methods, &mut |_| {}).unwrap();
    c.unwrap()
}

/// Largest `|a − b|` over steps and monitors per variable, relative to the largest `|b|` of
/// that variable, over components with `|b| ≥ 1e-6 max|b|` (as the three-way checks).
fn worst(a: &[Vec<Vec<f64>>], b: &[Vec<Vec<f64>>]) -> f64 {
    let nv = b[0][0].len();
    let mut out = 0.0f64;
    for v in 0..nv {
        let big = b.iter().flatten().map(|m| m[v].abs()).fold(0.0, f64::max);
        for (sa, sb) in a.iter().zip(b) {
            for (ma, mb) in sa.iter().zip(sb) {
                if mb[v].abs() >= 1e-6 * big {
                    out = out.max((ma[v] - mb[v]).abs() / big);
                }
            }
        }
    }
    out
}

fn check(rel: &str) {
    let c = case(rel);
    let direct = continuum(&c, SensitivitySolve::Factorised);
    let krylov = continuum(&c, SensitivitySolve::Krylov);
    let dual = {
        let a = CaseAnalysis { case: &c };
        let (problem, newton) = a.build(&base_design(&c)).unwrap();
        run_dual_on(analysis(&c, &a, &newton, problem), DualMode::Vector).unwrap()
    };
    let steps = direct.records.len();
    assert!(steps > 0);
    // The same analysis: the same converged steps at the same loads (the acceptance tests
    // see the same residuals; only where the tangent is factorised differs).
    assert_eq!(krylov.records.len(), steps, "{rel}");
    for (a, b) in krylov.records.iter().zip(&direct.records) {
        assert_eq!(a.load, b.load, "{rel}: step {}", a.step);
    }
    let d = |r: &ContinuumRun| -> Vec<Vec<Vec<f64>>> {
        r.records.iter().map(|s| s.derivatives.clone()).collect()
    };
    let dd: Vec<Vec<Vec<f64>>> = dual.records.iter().map(|s| s.derivatives.clone()).collect();
    let (kd, kr, dr) = (
        worst(&d(&krylov), &d(&direct)),
        worst(&d(&krylov), &dd),
        worst(&d(&direct), &dd),
    );
    // Steps whose solves took GMRES: accepted on an earlier iterate's factorisation.
    let unfactorised = |r: &ContinuumRun| -> usize {
        r.report
            .converged_steps()
            .filter(|s| s.factorised_at == Some(FactorisedAt::PreviousIterate))
            .count()
    };
    println!(
        "{rel}: {steps} steps; Krylov − factorised {kd:.2e}, Krylov − dual {kr:.2e}, factorised \
         − dual {dr:.2e} (of each variable's largest derivative); {} Arnoldi steps, {} steps \
         factorised by the DSA; steps without the converged factorisation {} (Krylov run) and {} \
         (factorised run); whole runs {:.3} s and {:.3} s",
        krylov.timing.krylov_iterations,
        krylov.timing.krylov_fallbacks,
        unfactorised(&krylov),
        unfactorised(&direct),
        krylov.total.as_secs_f64(),
        direct.total.as_secs_f64()
    );
    // GMRES stops at a residual of 1e-14 of each right-hand side, the level a direct solve
    // reaches: the two solutions agree to what the tangent's conditioning makes of such
    // residuals; 1e-9 of the largest derivative is the agreement the three-way checks ask of
    // the continuum and the dual reference (1e-8), with a margin of 10.
    assert!(kd <= 1e-9, "{rel}: {kd:e}");
    assert!(kr <= 1e-8, "{rel}: {kr:e}");
    assert!(krylov.timing.krylov_iterations > 0, "{rel}");
    // The converged tangent is not factorised for the DSA where the driver accepted an iterate
    // on an earlier factorisation; the factorised run never does.
    assert!(unfactorised(&krylov) > 0, "{rel}");
    assert_eq!(unfactorised(&direct), 0, "{rel}");
}

#[test]
fn krylov_sensitivity_solves_on_the_hemisphere() {
    check("verification/hemisphere-plastic-dsa/ci.toml");
}

#[test]
fn krylov_sensitivity_solves_on_the_bending_case() {
    check("verification/cylindrical-bending-dsa/ci.toml");
}
