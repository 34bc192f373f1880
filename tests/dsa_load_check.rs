//! The sensitivity methods' load check (`sensitivity::dual::check_loads`): at every converged
//! step the loads given to the continuum DSA (and the dual reference) must give the problem's
//! external force. A contact given as the problem's own object (the same `Arc`) is recognised
//! by identity and not evaluated; these tests show that the check still fails when the contact
//! is missing from the method's loads, and still evaluates (and accepts) a contact that is an
//! equal but separate object.
//!
//! Case: the reduced punch bending of `verification/cylindrical-bending-dsa/ci.toml`, stopped
//! at 10 % of the stroke (the punch is in contact from the first steps).
//!
//! Run: `cargo test --release --test dsa_load_check`.

use shelldsa::io::dsa_case::{dual_contact, dual_loads};
use shelldsa::io::dsa_run::{base_design, CaseAnalysis};
use shelldsa::io::shell_case::{read_shell_case, ShellCase};
use shelldsa::sensitivity::continuum::run_continuum;
use shelldsa::sensitivity::dual::{DualLoad, SensitivityError};
use shelldsa::sensitivity::fd::Analysis;
use shelldsa::sensitivity::{DesignKind, DesignVariable};

fn case() -> ShellCase {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("verification/cylindrical-bending-dsa/ci.toml");
    let mut c = read_shell_case(&path).unwrap();
    c.steps.final_load = 0.1;
    c.steps.stops.clear();
    c
}

fn vars(c: &ShellCase) -> Vec<DesignVariable> {
    c.dsa
        .as_ref()
        .unwrap()
        .design
        .iter()
        .map(|d| d.variable.clone())
        .collect()
}

/// Runs the continuum DSA of `c` with the loads `make(case loads, the problem's contact)`.
fn run(
    c: &ShellCase,
    vars: Vec<DesignVariable>,
    make: impl FnOnce(Vec<DualLoad>, DualLoad) -> Vec<DualLoad>,
) -> Result<usize, SensitivityError> {
    let a = CaseAnalysis { case: c };
    let (p, n, contact) = a.build_with_contact(&base_design(c)).unwrap();
    let loads = make(dual_loads(c).unwrap(), dual_contact(c, contact.unwrap()));
    let monitors = c.dsa.as_ref().unwrap().monitors.clone();
    run_continuum(p, Some(&c.surface), vars, loads, monitors, &n, a.solver())
        .map(|r| r.records.len())
}

#[test]
fn the_problems_own_contact_passes_the_check() {
    let c = case();
    let steps = run(&c, vars(&c), |mut l, contact| {
        l.push(contact);
        l
    })
    .unwrap();
    assert!(steps >= 5, "{steps} converged steps");
}

#[test]
fn a_missing_contact_fails_the_check() {
    let c = case();
    // A thickness variable (a tool variable would be refused before the analysis: its tool
    // is not in the method's loads).
    let t = DesignVariable::new("t", DesignKind::Thickness);
    let err = run(&c, vec![t], |l, _| l).unwrap_err().to_string();
    assert!(
        err.contains("differ from the problem's"),
        "unexpected error: {err}"
    );
}

#[test]
fn an_equal_contact_of_another_object_is_evaluated_and_passes() {
    // A second build of the same case gives a contact equal in every input but another object:
    // it is not recognised by identity, so both forces are evaluated and compared. Its
    // tracking state is its own, so it is only evaluated, never stepped: the check's forces
    // at each converged increment are equal (the same inputs).
    let c = case();
    let a = CaseAnalysis { case: &c };
    let (_, _, other) = a.build_with_contact(&base_design(&c)).unwrap();
    let steps = run(&c, vars(&c), |mut l, _| {
        l.push(dual_contact(&c, other.unwrap()));
        l
    });
    match steps {
        Ok(n) => assert!(n >= 5, "{n} converged steps"),
        Err(e) => panic!("an equal contact object failed the check: {e}"),
    }
}
