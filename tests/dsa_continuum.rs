//! The continuum (hand-derived) DSA, path 2 of `docs/sensitivity.md` (paper eqs 37–65):
//! against the dual-number reference on the yielding clamped plate (`tests/common/plate.rs`:
//! follower pressure, clamped edges, 5 steps, plastic in steps 4–5) for thickness and five
//! material parameters, term group by term group at a plastic step, bit-identical on a
//! re-run, equal with serial and parallel assembly, and bit-identical when both methods
//! observe one analysis.
//!
//! Tolerances. Both methods solve eq (65) with the same factorised tangent; their right-hand
//! sides are the same derivative computed two ways (hand-derived chain against dual-number
//! arithmetic through the analysis kernels), so they differ by round-off of the terms summed:
//! ~1e-15 of the largest fictitious-load entry per step. The solve amplifies that by the
//! condition number of the tangent seen by the right-hand side, and the error is carried over
//! the steps. The issue asks for 1e-8 relative on every component with |ψ'| ≥ 1e-6 max|ψ'|;
//! that is what is asserted (the measured figures are printed with `--nocapture`).

#[path = "common/plate.rs"]
mod plate;
use plate::*;

use shelldsa::sensitivity::continuum::{run_continuum, ContinuumRun, TermGroup};
use shelldsa::sensitivity::dual::{run_dual, DualMode, DualRun};
use shelldsa::sensitivity::terms::breakdown;
use shelldsa::sensitivity::{Design, DsaAnalysis};
use shelldsa::solver::{NewtonSolver, SolverOptions};

/// The plate of design `d` with the test's variables and monitors, driven by `newton`.
fn plate_analysis<'a>(d: &Design, newton: &'a NewtonSolver) -> DsaAnalysis<'a> {
    DsaAnalysis {
        problem: Plate::problem(d),
        surface: None,
        variables: variables(),
        monitors: Plate::monitors(),
        newton,
        solver: SolverOptions::default(),
    }
}

fn continuum() -> ContinuumRun {
    let d = nominal_design();
    run_continuum(plate_analysis(&d, &driver(STEPS))).unwrap()
}

/// The continuum DSA in its own run with the converged tangent factorised by the driver, as in
/// a run shared with the dual reference (the default solves by GMRES on it:
/// `tests/dsa_krylov_solve.rs`).
fn continuum_factorised() -> ContinuumRun {
    use shelldsa::sensitivity::continuum::{ContinuumSchedule, SensitivitySolve};
    use shelldsa::sensitivity::{run_hooked, HookedMethods};
    let d = nominal_design();
    let methods = HookedMethods {
        continuum: true,
        dual: None,
        schedule: ContinuumSchedule::Synchronous,
        solve: SensitivitySolve::Factorised,
    };
    let (c, _) = run_hooked(plate_analysis(&d, &driver(STEPS)), methods, &mut |_| {}).unwrap();
    c.unwrap()
}

fn dual() -> DualRun {
    let d = nominal_design();
    run_dual(
        Plate::problem(&d),
        variables(),
        Plate::monitors(),
        &driver(STEPS),
        SolverOptions::default(),
        DualMode::Vector,
    )
    .unwrap()
}

/// Largest relative difference per variable over steps and monitors with
/// |ψ'| ≥ 1e-6 max|ψ'| (the variable's largest over all steps and monitors).
fn relative_differences(c: &ContinuumRun, d: &DualRun) -> Vec<f64> {
    let nv = c.variables.len();
    (0..nv)
        .map(|v| {
            let big = d
                .records
                .iter()
                .flat_map(|r| r.derivatives.iter().map(move |m| m[v].abs()))
                .fold(0.0f64, f64::max);
            let mut worst = 0.0f64;
            for (rc, rd) in c.records.iter().zip(&d.records) {
                for (mc, md) in rc.derivatives.iter().zip(&rd.derivatives) {
                    if md[v].abs() >= 1e-6 * big {
                        worst = worst.max((mc[v] - md[v]).abs() / md[v].abs());
                    }
                }
            }
            worst
        })
        .collect()
}

#[test]
fn continuum_matches_the_dual_reference_on_a_yielding_plate() {
    let c = continuum();
    let d = dual();
    assert_eq!(c.records.len(), STEPS);
    assert_eq!(d.records.len(), STEPS);
    for (rc, rd) in c.records.iter().zip(&d.records) {
        assert_eq!(rc.load, rd.load);
        assert_eq!(rc.values, rd.values, "the same analysis");
    }
    let rel = relative_differences(&c, &d);
    for (v, e) in c.variables.iter().zip(&rel) {
        println!("{:>8}: max |cont − dual| / |dual| = {e:.3e}", v.name);
    }
    println!(
        "cost per variable: continuum {:.2} % ({:.3} s in {:.3} s), dual {:.2} % ({:.3} s in {:.3} s)",
        100.0 * c.cost_per_variable(),
        c.dsa.as_secs_f64(),
        c.total.as_secs_f64(),
        100.0 * d.cost_per_variable(),
        d.reference.as_secs_f64(),
        d.total.as_secs_f64()
    );
    for (v, e) in c.variables.iter().zip(&rel) {
        assert!(*e <= 1e-8, "`{}`: continuum vs dual {e:e} > 1e-8", v.name);
    }
    // A derivative that is zero is zero in both (σ0, H, β before first yield: steps 1–3).
    for (rc, rd) in c.records.iter().zip(&d.records).take(3) {
        for (mc, md) in rc.derivatives.iter().zip(&rd.derivatives) {
            for v in 2..4 {
                assert_eq!(md[v], 0.0, "dual: no plastic dependence before yield");
                assert_eq!(mc[v], 0.0, "continuum: no plastic dependence before yield");
            }
        }
    }
}

/// Every term group of the fictitious load at the last (plastic) step, seeded with the dual
/// reference's state, equals the dual residual seeded with that group only; so does the end-of-
/// step update. The groups add up to the total.
#[test]
fn term_groups_match_the_dual_reference_at_a_plastic_step() {
    let d = nominal_design();
    let bs = breakdown(
        Plate::problem(&d),
        None,
        variables(),
        &driver(STEPS),
        SolverOptions::default(),
        STEPS,
    )
    .unwrap();
    assert_eq!(bs.len(), variables().len());
    for b in &bs {
        assert_eq!(b.step, STEPS);
        // The largest term of any group: the total sums the groups, and for β their history
        // and material terms cancel to 3e-3 of either, so its round-off scales with them.
        let terms = b.groups.iter().fold(0.0f64, |a, g| a.max(g.dual_max));
        for g in &b.groups {
            println!(
                "{:>8} {:>9}: max|cont| {:.3e} max|dual| {:.3e} rel {:.2e}",
                b.variable.name,
                g.group.map_or("total", |t| t.name()),
                g.continuum_max,
                g.dual_max,
                g.relative()
            );
            // The same derivative, two ways: round-off of sums of terms as large as the
            // largest entry (1e-16 each, thousands of terms per row): 1e-12 of the group's
            // largest entry (of the largest group's for the total). Measured ≤ 1e-14.
            let scale = match g.group {
                Some(_) => g.dual_max.max(g.continuum_max),
                None => terms,
            };
            assert!(
                g.max_difference <= 1e-12 * scale,
                "`{}` group {:?}: {:e} of {:e}",
                b.variable.name,
                g.group,
                g.max_difference,
                g.dual_max
            );
        }
        let history = &b.groups[0];
        assert_eq!(history.group, Some(TermGroup::History));
        assert!(history.dual_max > 0.0, "history terms are active at step 5");
        for f in &b.update {
            println!(
                "{:>8} {:>12}: max|dual| {:.3e} rel {:.2e}",
                b.variable.name,
                f.field,
                f.dual_max,
                f.relative()
            );
            // After one solve with the same tangent (condition number of the plate's tangent
            // ~1e8): 1e-7 of the field's largest entry.
            assert!(
                f.max_difference <= 1e-7 * f.dual_max,
                "`{}` {}: {:e} of {:e}",
                b.variable.name,
                f.field,
                f.max_difference,
                f.dual_max
            );
        }
    }
}

/// Two runs give bit-identical derivatives; a one-thread run agrees with the parallel one to
/// round-off (the point evaluations are summed in point order either way, so bit-identical
/// is expected, and the solver's threads may only reorder floating-point sums).
#[test]
fn continuum_is_repeatable_and_thread_independent() {
    let a = continuum();
    let b = continuum();
    for (ra, rb) in a.records.iter().zip(&b.records) {
        assert_eq!(ra.derivatives, rb.derivatives, "bit-identical re-run");
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let s = pool.install(continuum);
    let mut worst = 0.0f64;
    let mut big = 0.0f64;
    for (ra, rs) in a.records.iter().zip(&s.records) {
        for (ma, ms) in ra.derivatives.iter().zip(&rs.derivatives) {
            for (x, y) in ma.iter().zip(ms) {
                worst = worst.max((x - y).abs());
                big = big.max(x.abs());
            }
        }
    }
    println!("serial vs parallel: {:.3e} of {:.3e}", worst, big);
    assert!(
        worst <= 1e-10 * big,
        "serial vs parallel {worst:e} of {big:e}"
    );
}

/// Both methods observing one hooked run (`run_continuum_and_dual`, what `shelldsa dsa` runs
/// when both are asked for) give the same derivatives, bit for bit, as each method in its own
/// run (the continuum with the converged tangent factorised, as the shared run does): the
/// observers share the analysis and its converged tangent and do not touch each other's state,
/// and each run follows the same Newton path.
#[test]
fn one_run_for_both_methods_equals_a_run_each() {
    let d = nominal_design();
    let (c, du) = shelldsa::sensitivity::run_continuum_and_dual(
        plate_analysis(&d, &driver(STEPS)),
        DualMode::Vector,
    )
    .unwrap();
    let (c1, d1) = (continuum_factorised(), dual());
    assert_eq!(c.records.len(), c1.records.len());
    assert_eq!(du.records.len(), d1.records.len());
    for (a, b) in c.records.iter().zip(&c1.records) {
        assert_eq!(a.load, b.load);
        assert_eq!(a.values, b.values, "continuum monitors, step {}", a.step);
        assert_eq!(
            a.derivatives, b.derivatives,
            "continuum derivatives, step {}",
            a.step
        );
    }
    for (a, b) in du.records.iter().zip(&d1.records) {
        assert_eq!(
            a.derivatives, b.derivatives,
            "dual derivatives, step {}",
            a.step
        );
    }
    assert_eq!(c.report.attempts.len(), c1.report.attempts.len());
}
