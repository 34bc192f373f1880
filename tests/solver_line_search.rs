//! The Newton driver's line search on failure and its continuation to prescribed load levels
//! (`src/solver/newton.rs`, module documentation), on a one-unknown problem whose Newton
//! iterates leave the domain where it can be evaluated.

use shelldsa::solver::{
    FailureReason, LineSearch, LinearSolver, LoadStepping, Method, NewtonOptions, NewtonReport,
    NewtonSolver, NonlinearProblem, ProblemError, SolverOptions, SparsityPattern, StopFailure,
};

/// `r(u, λ) = u + u³ − λ`, evaluable only for `u < u_max` (beyond it the evaluation fails
/// recoverably, as an inverted cell does). From `u = 0` the first Newton iterate is `u = λ`
/// (the tangent there is 1), beyond `u_max` when `λ ≥ u_max`, while the root is `u ≈ λ^{1/3}`.
/// The cubic is convex, so after the first iterate Newton approaches the root from above.
struct Cubic {
    u_max: f64,
    evaluations: usize,
}

impl NonlinearProblem for Cubic {
    fn n_dofs(&self) -> usize {
        1
    }
    fn residual(&mut self, u: &[f64], load: f64, r: &mut [f64]) -> Result<(), ProblemError> {
        self.evaluations += 1;
        if u[0] >= self.u_max || u[0].is_nan() {
            return Err(ProblemError::Recoverable(format!(
                "u = {} beyond {}",
                u[0], self.u_max
            )));
        }
        r[0] = u[0] + u[0].powi(3) - load;
        Ok(())
    }
    fn tangent(&mut self, u: &[f64], _load: f64, values: &mut [f64]) -> Result<(), ProblemError> {
        values[0] = 1.0 + 3.0 * u[0] * u[0];
        Ok(())
    }
    fn force_norm(&self, load: f64) -> f64 {
        load.abs()
    }
    fn commit(&mut self, _u: &[f64], _load: f64) {}
    fn restore(&mut self) {}
}

fn run(
    u_max: f64,
    line_search: LineSearch,
    stepping: LoadStepping,
) -> Result<NewtonReport, Box<shelldsa::solver::NewtonFailure>> {
    let pattern = SparsityPattern::from_cells(1, &[vec![0]]).unwrap();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    let newton = NewtonSolver {
        options: NewtonOptions {
            residual_rtol: 1e-12,
            line_search,
            ..Default::default()
        },
        stepping,
    };
    let mut problem = Cubic {
        u_max,
        evaluations: 0,
    };
    newton.run(&mut problem, &pattern, &mut solver, &[0.0])
}

/// One step to λ = 10 (root u = 2): the first iterate u = 10 is beyond u_max = 6.
fn one_step() -> LoadStepping {
    LoadStepping {
        end: 10.0,
        initial_step: 10.0,
        max_step: 10.0,
        ..Default::default()
    }
}

fn levels(r: &NewtonReport) -> Vec<f64> {
    r.converged_steps().map(|s| s.load).collect()
}

#[test]
fn line_search_backtracks_where_the_step_was_cut() {
    // Without the line search the failed evaluation cuts the step: λ = 5 is committed first.
    let off = run(6.0, LineSearch::Off, one_step()).unwrap();
    assert_eq!(levels(&off), vec![5.0, 10.0]);
    assert!(matches!(
        off.attempts[0].failure,
        Some(FailureReason::Problem(ProblemError::Recoverable(_)))
    ));
    // With it, u = 0 + ½·10 = 5 is evaluable: the step converges at λ = 10 in one attempt.
    let on = run(6.0, LineSearch::OnFailure, one_step()).unwrap();
    assert_eq!(levels(&on), vec![10.0]);
    assert_eq!(on.attempts.len(), 1);
    let b = &on.attempts[0].backtracks;
    assert_eq!(b.len(), 1, "{b:?}");
    assert_eq!((b[0].iteration, b[0].length), (1, 0.5));
    // The root of 2 + 8 = 10, to the tolerance (1e-12 of the force 10; the tangent there
    // is 13, so |u − 2| ≤ 1e-11 / 13).
    assert!((on.u[0] - 2.0).abs() <= 1e-11, "{}", on.u[0]);
}

#[test]
fn line_search_leaves_converging_steps_unchanged() {
    // u_max = 100: no iterate is rejected, so both policies take the same iterates.
    let stepping = LoadStepping {
        end: 10.0,
        initial_step: 2.5,
        max_step: 2.5,
        ..Default::default()
    };
    let off = run(100.0, LineSearch::Off, stepping.clone()).unwrap();
    let on = run(100.0, LineSearch::OnFailure, stepping).unwrap();
    assert_eq!(off.u, on.u);
    assert_eq!(off.attempts.len(), on.attempts.len());
    for (a, b) in off.attempts.iter().zip(&on.attempts) {
        assert_eq!(a.load, b.load);
        assert_eq!(a.residual_norms, b.residual_norms);
        assert_eq!(a.energy_norms, b.energy_norms);
        assert!(b.backtracks.is_empty());
    }
}

#[test]
fn continuation_lands_on_the_stop_without_committing_the_shorter_step() {
    // Line search off, so that the attempt at λ = 10 fails as before; with continuation the
    // shorter step λ = 5 is solved (not committed) and starts the attempt at the stop.
    let stepping = LoadStepping {
        stops: vec![10.0],
        stop_failure: StopFailure::Continuation,
        ..one_step()
    };
    let r = run(6.0, LineSearch::Off, stepping).unwrap();
    assert_eq!(levels(&r), vec![10.0]);
    let last = r.attempts.last().unwrap();
    assert!(last.converged);
    assert_eq!(last.load_start, 0.0);
    assert_eq!(last.continuation, vec![5.0]);
    // The committed state solves the same equation as a direct attempt (root 2, to the
    // tolerance as above).
    assert!((r.u[0] - 2.0).abs() <= 1e-11, "{}", r.u[0]);
    // With the default (cut), λ = 5 is committed instead.
    let cut = run(
        6.0,
        LineSearch::Off,
        LoadStepping {
            stops: vec![10.0],
            ..one_step()
        },
    )
    .unwrap();
    assert_eq!(levels(&cut), vec![5.0, 10.0]);
}
