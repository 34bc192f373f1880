//! A problem with an observer of its converged steps: the one wrapper through which analysis
//! output, finite-difference recording and the design-sensitivity methods see the Newton
//! driver's converged steps, without each re-implementing [`NonlinearProblem`].
//!
//! [`Observed`] delegates every evaluation to the problem and calls the [`StepObserver`] at the
//! three points of a converged step's life: [`StepObserver::on_converged`] (the tangent at the
//! converged state is factorised in the step's solver when the observer asks for it,
//! [`StepObserver::converged_tangent`]), [`StepObserver::after_commit`] (the problem holds the
//! committed state) and [`StepObserver::on_restore`] (the trial state was rejected). An observer
//! that fails after a commit (which cannot return an error) reports it through
//! [`StepObserver::failure`]; the next evaluation stops the run with it.

use super::newton::{ConvergedStep, ConvergedTangent, Failure, NonlinearProblem, ProblemError};

/// What an observer of converged steps does (all hooks default to nothing).
pub trait StepObserver<P: ?Sized> {
    /// The tangent policy the observer needs, given the problem's own (default: the problem's).
    fn converged_tangent(&self, problem: ConvergedTangent) -> ConvergedTangent {
        problem
    }
    /// A step converged (before the commit): `problem` holds the trial state at `step.u`.
    fn on_converged(
        &mut self,
        _problem: &P,
        _step: &ConvergedStep<'_>,
    ) -> Result<(), ProblemError> {
        Ok(())
    }
    /// Called just before the problem commits `u` at `load` (e.g. to keep the step-start state).
    fn before_commit(&mut self, _problem: &P, _u: &[f64], _load: f64) {}
    /// The problem committed `u` at `load`. A failure is kept and reported by
    /// [`StepObserver::failure`].
    fn after_commit(&mut self, _problem: &P, _u: &[f64], _load: f64) {}
    /// The trial state was rejected.
    fn on_restore(&mut self) {}
    /// A failure recorded after a commit (what failed and why): stops the run at the next
    /// evaluation.
    fn failure(&self) -> Option<Failure> {
        None
    }
}

/// Two observers, called in order (the tangent policy is the stricter of the two,
/// [`ConvergedTangent::stricter`]).
impl<P: ?Sized, A: StepObserver<P>, B: StepObserver<P>> StepObserver<P> for (A, B) {
    fn converged_tangent(&self, problem: ConvergedTangent) -> ConvergedTangent {
        self.0
            .converged_tangent(problem)
            .stricter(self.1.converged_tangent(problem))
    }
    fn on_converged(&mut self, problem: &P, step: &ConvergedStep<'_>) -> Result<(), ProblemError> {
        self.0.on_converged(problem, step)?;
        self.1.on_converged(problem, step)
    }
    fn before_commit(&mut self, problem: &P, u: &[f64], load: f64) {
        self.0.before_commit(problem, u, load);
        self.1.before_commit(problem, u, load);
    }
    fn after_commit(&mut self, problem: &P, u: &[f64], load: f64) {
        self.0.after_commit(problem, u, load);
        self.1.after_commit(problem, u, load);
    }
    fn on_restore(&mut self) {
        self.0.on_restore();
        self.1.on_restore();
    }
    fn failure(&self) -> Option<Failure> {
        self.0.failure().or_else(|| self.1.failure())
    }
}

/// An observer that may be absent (then it does nothing and leaves the problem's tangent
/// policy as it is).
impl<P: ?Sized, A: StepObserver<P>> StepObserver<P> for Option<A> {
    fn converged_tangent(&self, problem: ConvergedTangent) -> ConvergedTangent {
        self.as_ref()
            .map_or(problem, |a| a.converged_tangent(problem))
    }
    fn on_converged(&mut self, problem: &P, step: &ConvergedStep<'_>) -> Result<(), ProblemError> {
        self.as_mut()
            .map_or(Ok(()), |a| a.on_converged(problem, step))
    }
    fn before_commit(&mut self, problem: &P, u: &[f64], load: f64) {
        if let Some(a) = self {
            a.before_commit(problem, u, load);
        }
    }
    fn after_commit(&mut self, problem: &P, u: &[f64], load: f64) {
        if let Some(a) = self {
            a.after_commit(problem, u, load);
        }
    }
    fn on_restore(&mut self) {
        if let Some(a) = self {
            a.on_restore();
        }
    }
    fn failure(&self) -> Option<Failure> {
        self.as_ref().and_then(|a| a.failure())
    }
}

/// An observer and a callback that sees the committed problem and the observer after every
/// commit, once the observer has recorded the step (e.g. to write the results so far while the
/// run goes on).
pub struct Tapped<'f, P: ?Sized, O> {
    /// The observer.
    pub observer: O,
    tap: &'f mut dyn FnMut(&P, &O),
}

impl<'f, P: ?Sized, O> Tapped<'f, P, O> {
    /// `observer`, with `tap` called after each of its commits.
    pub fn new(observer: O, tap: &'f mut dyn FnMut(&P, &O)) -> Self {
        Self { observer, tap }
    }
}

impl<P: ?Sized, O: std::fmt::Debug> std::fmt::Debug for Tapped<'_, P, O> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Tapped")
            .field("observer", &self.observer)
            .finish_non_exhaustive()
    }
}

impl<P: ?Sized, O: StepObserver<P>> StepObserver<P> for Tapped<'_, P, O> {
    fn converged_tangent(&self, problem: ConvergedTangent) -> ConvergedTangent {
        self.observer.converged_tangent(problem)
    }
    fn on_converged(&mut self, problem: &P, step: &ConvergedStep<'_>) -> Result<(), ProblemError> {
        self.observer.on_converged(problem, step)
    }
    fn before_commit(&mut self, problem: &P, u: &[f64], load: f64) {
        self.observer.before_commit(problem, u, load);
    }
    fn after_commit(&mut self, problem: &P, u: &[f64], load: f64) {
        self.observer.after_commit(problem, u, load);
        (self.tap)(problem, &self.observer);
    }
    fn on_restore(&mut self) {
        self.observer.on_restore();
    }
    fn failure(&self) -> Option<Failure> {
        self.observer.failure()
    }
}

/// A problem (owned or `&mut`) and its observer.
#[derive(Debug)]
pub struct Observed<P, O> {
    /// The observed problem.
    pub problem: P,
    /// The observer.
    pub observer: O,
}

impl<P, O> Observed<P, O> {
    /// Wrap `problem`.
    pub fn new(problem: P, observer: O) -> Self {
        Observed { problem, observer }
    }
}

impl<P: NonlinearProblem, O: StepObserver<P>> Observed<P, O> {
    fn check(&self) -> Result<(), ProblemError> {
        match self.observer.failure() {
            Some(f) => Err(ProblemError::Failed(f)),
            None => Ok(()),
        }
    }
}

impl<P: NonlinearProblem, O: StepObserver<P>> NonlinearProblem for Observed<P, O> {
    fn n_dofs(&self) -> usize {
        self.problem.n_dofs()
    }
    fn residual(&mut self, u: &[f64], load: f64, r: &mut [f64]) -> Result<(), ProblemError> {
        self.check()?;
        self.problem.residual(u, load, r)
    }
    fn tangent(&mut self, u: &[f64], load: f64, values: &mut [f64]) -> Result<(), ProblemError> {
        self.check()?;
        self.problem.tangent(u, load, values)
    }
    fn residual_and_tangent(
        &mut self,
        u: &[f64],
        load: f64,
        r: &mut [f64],
        values: &mut [f64],
    ) -> Result<(), ProblemError> {
        self.check()?;
        self.problem.residual_and_tangent(u, load, r, values)
    }
    fn essential(&self, load: f64) -> Vec<(usize, f64)> {
        self.problem.essential(load)
    }
    fn load_derivative(
        &mut self,
        u: &[f64],
        load: f64,
        out: &mut [f64],
    ) -> Result<bool, ProblemError> {
        self.problem.load_derivative(u, load, out)
    }
    fn path_dofs(&self) -> usize {
        self.problem.path_dofs()
    }
    fn force_norm(&self, load: f64) -> f64 {
        self.problem.force_norm(load)
    }
    fn residual_scale(&self) -> f64 {
        self.problem.residual_scale()
    }
    fn describe_unknown(&self, dof: usize) -> Option<String> {
        self.problem.describe_unknown(dof)
    }
    fn active_set_changes(&self) -> u64 {
        self.problem.active_set_changes()
    }
    fn on_converged(&mut self, step: &ConvergedStep<'_>) -> Result<(), ProblemError> {
        self.check()?;
        self.problem.on_converged(step)?;
        self.observer.on_converged(&self.problem, step)
    }
    fn converged_tangent(&self) -> ConvergedTangent {
        self.observer
            .converged_tangent(self.problem.converged_tangent())
    }
    fn commit(&mut self, u: &[f64], load: f64) {
        self.observer.before_commit(&self.problem, u, load);
        self.problem.commit(u, load);
        self.observer.after_commit(&self.problem, u, load);
    }
    fn restore(&mut self) {
        self.observer.on_restore();
        self.problem.restore();
    }
}

/// A borrowed problem is a problem: `Observed::new(&mut problem, observer)` observes a problem
/// its owner keeps.
impl<P: NonlinearProblem + ?Sized> NonlinearProblem for &mut P {
    fn n_dofs(&self) -> usize {
        (**self).n_dofs()
    }
    fn residual(&mut self, u: &[f64], load: f64, r: &mut [f64]) -> Result<(), ProblemError> {
        (**self).residual(u, load, r)
    }
    fn tangent(&mut self, u: &[f64], load: f64, values: &mut [f64]) -> Result<(), ProblemError> {
        (**self).tangent(u, load, values)
    }
    fn residual_and_tangent(
        &mut self,
        u: &[f64],
        load: f64,
        r: &mut [f64],
        values: &mut [f64],
    ) -> Result<(), ProblemError> {
        (**self).residual_and_tangent(u, load, r, values)
    }
    fn essential(&self, load: f64) -> Vec<(usize, f64)> {
        (**self).essential(load)
    }
    fn load_derivative(
        &mut self,
        u: &[f64],
        load: f64,
        out: &mut [f64],
    ) -> Result<bool, ProblemError> {
        (**self).load_derivative(u, load, out)
    }
    fn path_dofs(&self) -> usize {
        (**self).path_dofs()
    }
    fn force_norm(&self, load: f64) -> f64 {
        (**self).force_norm(load)
    }
    fn residual_scale(&self) -> f64 {
        (**self).residual_scale()
    }
    fn describe_unknown(&self, dof: usize) -> Option<String> {
        (**self).describe_unknown(dof)
    }
    fn active_set_changes(&self) -> u64 {
        (**self).active_set_changes()
    }
    fn on_converged(&mut self, step: &ConvergedStep<'_>) -> Result<(), ProblemError> {
        (**self).on_converged(step)
    }
    fn converged_tangent(&self) -> ConvergedTangent {
        (**self).converged_tangent()
    }
    fn commit(&mut self, u: &[f64], load: f64) {
        (**self).commit(u, load)
    }
    fn restore(&mut self) {
        (**self).restore()
    }
}

/// When a results file (`results.json` with its PVD, `sensitivity.json`) is rewritten whole
/// while a run goes on: after every converged step up to [`RewriteSchedule::EVERY_STEP_UP_TO`],
/// then once the number of steps has grown by a sixteenth since the last rewrite, or once the
/// last rewrite is older than [`RewriteSchedule::MIN_INTERVAL_S`] and 100 times its own
/// duration. Each step record is then written about 17 times in all (a geometric series), and
/// rewrites take at most about 1 % of the wall time, so the cost per step stays bounded however
/// long the run. (`steps.jsonl` has every converged step as soon as it converges.)
#[derive(Debug, Clone, Copy)]
pub(crate) struct RewriteSchedule {
    /// Steps in the last rewrite.
    steps: usize,
    /// When it ended.
    at: std::time::Instant,
    /// How long it took.
    took: std::time::Duration,
}

impl RewriteSchedule {
    pub(crate) const EVERY_STEP_UP_TO: usize = 32;
    const GROWTH: usize = 16;
    pub(crate) const MIN_INTERVAL_S: f64 = 10.0;

    /// Nothing written yet, at `start`.
    pub(crate) fn starting(start: std::time::Instant) -> Self {
        Self {
            steps: 0,
            at: start,
            took: std::time::Duration::ZERO,
        }
    }

    /// Whether a rewrite with `steps` converged steps is due.
    pub(crate) fn due(&self, steps: usize) -> bool {
        let since = self.at.elapsed().as_secs_f64();
        steps <= Self::EVERY_STEP_UP_TO
            || steps >= self.steps + (self.steps / Self::GROWTH).max(1)
            || since >= Self::MIN_INTERVAL_S.max(100.0 * self.took.as_secs_f64())
    }

    /// A rewrite with `steps` steps has just ended; it took `took`.
    pub(crate) fn wrote(&mut self, steps: usize, took: std::time::Duration) {
        *self = Self {
            steps,
            at: std::time::Instant::now(),
            took,
        };
    }
}
