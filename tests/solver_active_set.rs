//! Iterations whose iterate changed the problem's active set (a contact switching on or off)
//! are not counted against `max_iterations`: their update was solved with another active set,
//! and a shorter step does not remove them. They have their own limit,
//! `max_active_set_iterations`, beyond which the attempt fails with its own reason.

use shelldsa::solver::*;

/// One unknown, `r(u, λ) = a (u − λ) + s_k`: in an attempt's first `switching` iterates after
/// its start (`k = 1..=switching`) the active set changes and the residual carries the jump
/// `s_k = ±1` of the switching terms (whatever the step size); afterwards `s_k = 0` and the
/// residual is linear, which Newton solves in two more updates.
struct Switching {
    a: f64,
    switching: usize,
    /// Evaluations since the last commit or restore (the attempt's `k`).
    k: usize,
    changes: u64,
}

impl Switching {
    fn new(switching: usize) -> Self {
        Switching {
            a: 2.0,
            switching,
            k: 0,
            changes: 0,
        }
    }
}

impl NonlinearProblem for Switching {
    fn n_dofs(&self) -> usize {
        1
    }
    fn residual(&mut self, u: &[f64], load: f64, r: &mut [f64]) -> Result<(), ProblemError> {
        let k = self.k;
        self.k += 1;
        let jump = if (1..=self.switching).contains(&k) {
            self.changes += 1;
            if k % 2 == 0 {
                1.0
            } else {
                -1.0
            }
        } else {
            0.0
        };
        r[0] = self.a * (u[0] - load) + jump;
        Ok(())
    }
    fn tangent(&mut self, _u: &[f64], _load: f64, k: &mut [f64]) -> Result<(), ProblemError> {
        k[0] = self.a;
        Ok(())
    }
    fn active_set_changes(&self) -> u64 {
        self.changes
    }
    fn commit(&mut self, _u: &[f64], _load: f64) {
        self.k = 0;
    }
    fn restore(&mut self) {
        self.k = 0;
    }
}

fn run(
    switching: usize,
    max_active_set_iterations: usize,
) -> Result<NewtonReport, Box<NewtonFailure>> {
    let mut p = Switching::new(switching);
    let pattern = SparsityPattern::from_cells(1, &[vec![0]]).unwrap();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    let newton = NewtonSolver {
        options: NewtonOptions {
            max_iterations: 3,
            max_active_set_iterations,
            ..Default::default()
        },
        stepping: LoadStepping {
            initial_step: 1.0,
            max_step: 1.0,
            // The switching does not depend on the step size: cuts cannot help, so a few
            // suffice to show it.
            min_step: 0.1,
            ..Default::default()
        },
    };
    newton.run(&mut p, &pattern, &mut solver, &[0.0])
}

#[test]
fn iterations_that_change_the_active_set_are_not_counted_against_max_iterations() {
    // Four switching iterates, then two updates on the linear residual: six in all, two of
    // them counted against max_iterations = 3. Counted together (the old rule) every attempt
    // fails at k = 3, at every step size.
    let report = run(4, 20).expect("converged");
    let st: Vec<&StepRecord> = report.converged_steps().collect();
    assert_eq!(st.len(), 1);
    assert_eq!(st[0].iterations, 6);
    assert_eq!(st[0].active_set_iterations, 4);
    assert!((report.u[0] - 1.0).abs() <= 1e-14, "u = {}", report.u[0]);
    assert!(
        report.attempts.iter().all(|s| s.converged),
        "no attempt was cut"
    );
}

#[test]
fn an_active_set_that_keeps_changing_fails_with_its_own_reason() {
    // More switching iterates than max_active_set_iterations = 5: the attempt fails naming
    // the active set, not max_iterations, and so does every cut attempt.
    let fail = run(100, 5).unwrap_err();
    let attempts = &fail.report.attempts;
    assert!(!attempts.is_empty());
    for a in attempts {
        assert_eq!(
            a.failure,
            Some(FailureReason::ActiveSetIterations(5)),
            "{:?}",
            a.failure
        );
        assert_eq!(a.active_set_iterations, 6);
    }
    let message = FailureReason::ActiveSetIterations(5).to_string();
    assert!(message.contains("active set"), "{message}");
}
