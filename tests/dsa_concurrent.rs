//! The continuum DSA on its own thread (`ContinuumSchedule::Concurrent`: the analysis runs as
//! the plain one and hands each committed step to the DSA's thread, which replays it on a copy
//! of the problem and factorises the converged tangent itself) against the DSA in the
//! analysis' hook (`ContinuumSchedule::Synchronous`), on the reduced elastoplastic hemisphere
//! (`verification/hemisphere-plastic-dsa/ci.toml`: shape, thickness and material variables)
//! and the reduced bending case with contact (`verification/cylindrical-bending-dsa/ci.toml`:
//! tool variables). Both run the same arithmetic on the same converged states, so every
//! record, the final sensitivities and what the per-step callback sees must be equal bit for
//! bit (no tolerance).

use shelldsa::io::dsa_study::{base_design, CaseAnalysis};
use shelldsa::io::shell_case::{read_shell_case, ShellCase};
use shelldsa::sensitivity::continuum::{ContinuumRun, ContinuumSchedule, SensitivitySolve};
use shelldsa::sensitivity::dual::DualMode;
use shelldsa::sensitivity::fd::Analysis;
use shelldsa::sensitivity::{run_hooked, DesignVariable, DsaAnalysis, HookedMethods};
use std::path::Path;

fn case(rel: &str) -> (ShellCase, Vec<DesignVariable>) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(rel);
    let case = read_shell_case(&path).unwrap();
    let vars = case.dsa.as_ref().unwrap().variables();
    (case, vars)
}

/// What the per-step callback saw at one call: the number of records, the last one's step and
/// load, the model's particle displacements and the continuum's displacement sensitivity
/// fields of every variable.
type Seen = (usize, usize, f64, Vec<[f64; 3]>, Vec<Vec<f64>>);

/// The continuum run of `case` with `schedule` (and the dual reference in the same run when
/// `dual`), and what the per-step callback saw.
fn run(
    case: &ShellCase,
    vars: &[DesignVariable],
    schedule: ContinuumSchedule,
    dual: bool,
) -> (ContinuumRun, Vec<Seen>) {
    let a = CaseAnalysis { case };
    let (problem, newton) = a.build(&base_design(case)).unwrap();
    let monitors = case.dsa.as_ref().unwrap().monitors.clone();
    let mut seen = Vec::new();
    let methods = HookedMethods {
        continuum: true,
        dual: dual.then_some(DualMode::Vector),
        schedule,
        // The concurrent DSA factorises the converged tangent on its thread; the synchronous
        // one compared with it bit for bit must factorise it too.
        solve: SensitivitySolve::Factorised,
    };
    let (c, _) = run_hooked(
        DsaAnalysis {
            problem,
            surface: Some(&case.surface),
            variables: vars.to_vec(),
            monitors,
            newton: &newton,
            solver: a.solver(),
        },
        methods,
        &mut |r| {
            let recs = r.continuum.unwrap();
            let last = recs.last().unwrap();
            let fields = r.continuum_fields.unwrap();
            seen.push((
                recs.len(),
                last.step,
                last.load,
                r.model.particles.iter().map(|p| p.u.into()).collect(),
                (0..fields.n_variables())
                    .map(|v| fields.translations(r.model, v))
                    .collect(),
            ));
        },
    )
    .unwrap();
    let c = c.unwrap();
    assert_eq!(
        c.schedule,
        if dual {
            ContinuumSchedule::Synchronous
        } else {
            schedule
        }
    );
    (c, seen)
}

fn assert_identical(rel: &str) {
    let (case, vars) = case(rel);
    let (sync, seen_sync) = run(&case, &vars, ContinuumSchedule::Synchronous, false);
    let (conc, seen_conc) = run(&case, &vars, ContinuumSchedule::Concurrent, false);
    let steps = sync.records.len();
    assert!(steps > 0);
    assert_eq!(conc.records.len(), steps, "{rel}: every step recorded");
    for (a, b) in sync.records.iter().zip(&conc.records) {
        // Loads, monitor values and every derivative, exactly.
        assert_eq!(a, b, "{rel}: step {}", a.step);
    }
    assert_eq!(sync.states, conc.states, "{rel}: the final sensitivities");
    assert_eq!(
        sync.report.u, conc.report.u,
        "{rel}: the same converged analysis"
    );
    // The callback saw every step once, in order, with the model at that step.
    assert_eq!(seen_conc.len(), steps);
    for (k, s) in seen_conc.iter().enumerate() {
        assert_eq!((s.0, s.1), (k + 1, k), "{rel}: callback {k}");
    }
    assert_eq!(seen_sync, seen_conc, "{rel}: what the callback saw");
    // The converged tangent is the DSA thread's work, not the hook's.
    assert_eq!(sync.timing.tangent, 0.0);
    assert!(conc.timing.tangent > 0.0);
    println!(
        "{rel}: {steps} steps; whole run synchronous {:.3} s, concurrent {:.3} s (analysis \
         thread {:.3} s, DSA stages {:.3} s, converged tangents {:.3} s)",
        sync.total.as_secs_f64(),
        conc.total.as_secs_f64(),
        conc.analysis.as_secs_f64(),
        conc.dsa.as_secs_f64(),
        conc.timing.tangent
    );
}

#[test]
fn concurrent_dsa_is_bit_identical_on_the_plastic_hemisphere() {
    assert_identical("verification/hemisphere-plastic-dsa/ci.toml");
}

#[test]
fn concurrent_dsa_is_bit_identical_on_the_bending_case_with_contact() {
    assert_identical("verification/cylindrical-bending-dsa/ci.toml");
}

/// With the dual reference in the same run, the continuum runs in the hook (the dual needs the
/// converged tangent factorised by the driver): the same records as alone.
#[test]
fn with_the_dual_reference_the_continuum_stays_in_the_hook() {
    let (case, vars) = case("verification/hemisphere-plastic-dsa/ci.toml");
    let (alone, _) = run(&case, &vars, ContinuumSchedule::Concurrent, false);
    let (both, _) = run(&case, &vars, ContinuumSchedule::Concurrent, true);
    assert_eq!(alone.records, both.records);
    assert_eq!(both.timing.tangent, 0.0);
}
