//! Newton–Raphson driver with load stepping, a secant predictor and automatic step cutting.
//!
//! One step goes from the committed state at load factor `λ_n` to `λ = λ_n + Δλ`. It starts
//! from the committed unknowns, or, with [`Predictor::Secant`], from
//! `u_n + (Δλ/Δλ_prev) (u_n − u_{n−1})`: the previous converged increment scaled by the ratio of
//! the load steps, or, with [`Predictor::Quadratic`], from the parabola through the last three
//! converged states. Every iteration `k` evaluates the residual `r(u_k, λ)` and the tangent
//! `K = ∂r/∂u` (one call, [`NonlinearProblem::residual_and_tangent`]), eliminates the essential
//! conditions with the increments `g − u_c` (so a prescribed motion enters through the consistent
//! linear predictor `−K_fc Δg` at `k = 0` and is satisfied exactly afterwards), factorises and
//! solves `K Δu_k = −r_k`. The iterate is accepted ([`Acceptance`]) when
//! - **tolerances:** `‖r_k‖ ≤ max(residual_rtol · r_ref, residual_atol)` and
//!   `|Δu_kᵀ r_k| ≤ max(energy_rtol · e_ref, energy_atol)` (the energy test is not required
//!   at `k = 0`). The references are `r_ref = max(‖r_0‖, force_norm(λ))` over free DOFs (at
//!   `k = 0`, `r_0` includes `K_fc Δg`) and `e_ref = |Δu_0ᵀ r_0|`. After a secant prediction
//!   `r_0` measures the predictor's error, not the force level, so then
//!   `r_ref = force_norm(λ)` (or `‖r_0‖` when the problem reports no force scale) and `e_ref`
//!   is `|Δu_0ᵀ r_0|` scaled by `(r_ref/‖r_0‖)²` when `‖r_0‖ > r_ref` (the energy is quadratic in
//!   the residual): a poor prediction must not loosen the energy test; or
//! - **round-off floor:** `‖r_k‖ ≤ roundoff_factor · ε · S_k` with
//!   `S_k = max(r_ref, residual_scale, ‖ |K_k| |u_k| ‖, ‖ |K_k| |u_k − u_n| ‖)` (free rows,
//!   component-wise absolute values): no iteration can push the residual below its round-off.
//!   The unknowns themselves are known only to about `ε |u|`, and such a perturbation changes
//!   the residual by `K δu`, so `ε ‖ |K| |u| ‖` bounds the resolution of `r` (for a linear
//!   problem it is the round-off bound of `K u`); the step's increment covers problems whose
//!   unknowns are increments, and [`NonlinearProblem::residual_scale`] what the tangent does not
//!   show (e.g. large self-equilibrated internal forces). The sum of the residual's own terms
//!   is not enough: in a shell with large rotations the floor was measured at up to 10³ ε times
//!   it; or
//! - **stagnation** (the fallback when `S_k` underestimates the floor): the energy test holds,
//!   the residual did not fall in two consecutive iterations
//!   (`‖r_j‖ ≥ stagnation_ratio · ‖r_{j−1}‖` for `j = k, k−1`, which quadratic convergence above
//!   the floor never shows twice in a row) and `‖r_k‖ ≤ √residual_rtol · r_ref`. Without the
//!   energy test a slowly falling residual with no root below it (a load beyond a limit point,
//!   `tests/solver.rs`) would pass; or
//! - **residual at round-off** ([`Acceptance::ResidualRoundoff`]): from `k ≥ 1`, the residual
//!   tolerance holds and `‖r_k‖ ≤ 10³ ε r_ref`, whatever the energy product. Tested after the
//!   tolerances and before the energy's divergence test: a step whose residual fell from
//!   1.1e-3 to 6.3e-18 while `|Δu_kᵀ r_k|` grew (a nearly singular tangent) is converged, not
//!   diverged.
//!
//! The essential conditions must be met (`g = 0`) for any acceptance. The converged increment
//! `Δu_k` is *not* applied: the committed state is exactly the
//! one at which residual, history and tangent were last evaluated, and the solver then holds
//! the factorised tangent at the converged configuration, which is what the design sensitivity
//! equation needs (the paper's eq. 65 reuses the decomposed tangent without iteration).
//! [`NonlinearProblem::on_converged`] is called at that point, before
//! [`NonlinearProblem::commit`].
//!
//! **Residual-first acceptance.** A problem whose convergence hook does not use the converged
//! tangent ([`NonlinearProblem::converged_tangent`] = [`ConvergedTangent::NotNeeded`], the
//! plain analysis) lets the driver skip the tangent at the iterate it accepts: from `k ≥ 2`,
//! when the last two residuals predict convergence under quadratic contraction
//! (`‖r_{k−1}‖³/‖r_{k−2}‖² ≤ 100 · tol`), it evaluates the residual alone, and accepts if the
//! residual tolerance holds and either the energy test with `Δu = K_{k−1}⁻¹ r_k` (the previous
//! iterate's factorisation, one solve) or the round-off floor (with the previous `S`) does.
//! Otherwise it evaluates residual and tangent at the same iterate as usual (one residual
//! wasted). Accepted iterates and unknowns are the same as without it
//! (`tests/solver.rs`); one tangent assembly and one factorisation per step are saved. The
//! converged step then reports [`FactorisedAt::PreviousIterate`].
//!
//! A hook that solves with the converged tangent iteratively
//! ([`ConvergedTangent::Assembled`], the continuum DSA's default) gets the same acceptance with
//! the residual and the tangent evaluated together at the predicted iterate: accepted, the
//! hook sees the tangent's values there ([`ConvergedStep::tangent`]) and the earlier
//! factorisation as a preconditioner, so only the factorisation is saved; not accepted, the
//! evaluation serves the next Newton update and nothing is evaluated twice.
//!
//! **Active set.** An iterate whose evaluation changed the problem's active set
//! ([`NonlinearProblem::active_set_changes`]: a contact switched on or off) is not counted
//! against `max_iterations`: the update that led to it was solved with the other active set,
//! so it says nothing of Newton's convergence, and a shorter step does not remove such
//! iterations. They are counted in [`StepRecord::active_set_iterations`] and limited by
//! [`NewtonOptions::max_active_set_iterations`] ([`FailureReason::ActiveSetIterations`]).
//!
//! **Line search on failure** ([`LineSearch::OnFailure`], the default). An iterate at which
//! the iteration cannot go on (a recoverable [`ProblemError`] such as an inverted cell or a
//! return map that did not converge, a non-finite residual, a residual or energy beyond
//! `divergence_factor`, a tangent that cannot be factorised) is replaced by `u_{k−1} + s Δu_{k−1}`
//! for `s` = 1/2, 1/4, 1/8, 1/16 (at `k = 0`: along the predictor's increment, then the committed
//! unknowns), each evaluated afresh from the committed history; at most [`BACKTRACK_BUDGET`]
//! tries per attempt. It acts only where the attempt would otherwise fail, so every attempt
//! that converges without it takes the same iterates (bit for bit). Measured on the half-sheet
//! bending case (`verification/cylindrical-bending-dsa/half.toml`): after the punch separates,
//! the secant predictor lifts the sheet off the dies it rests on under its self-weight (the
//! contact holds it through a penetration of about 10⁻⁸ mm), the tangent there is singular
//! (the sheet's rigid motion), and the shortened predictor converges where the step was cut.
//!
//! A step fails on a non-finite or diverging residual (`‖r_k‖` growing by more than
//! `divergence_factor` over `r_ref`, or the energy over iteration 0 while the residual
//! tolerance is not met), too many iterations, a singular tangent, or a
//! recoverable [`ProblemError`] (with the line search: when no shortened update helped); it is
//! then restored ([`NonlinearProblem::restore`]) and retried
//! with `cut_factor · Δλ` (with the secant predictor scaled down accordingly). With
//! [`StopFailure::Continuation`] a failed attempt at a stop is not cut: the shorter step's
//! solution (not committed) is the start of a new attempt at the stop from the same committed
//! state, so that a run lands on prescribed levels (the design sensitivity's re-runs replay the
//! nominal run's levels). After a step that
//! converged in at most `easy_iterations`, `Δλ` grows by `grow_factor` up to `max_step`. A step
//! that would pass one of the load levels in [`LoadStepping::stops`] (or the end) is clipped to
//! land on it exactly; the next step resumes the unclipped `Δλ`. Below
//! `min_step` the run stops with a [`NewtonFailure`] naming the load level, the reason and the
//! residual norms, and keeping every converged step.

use super::krylov::{csc_abs_mul_columns, gmres, gmres_to};
use super::{EssentialBc, LinearSolver, SolverError, SparsityPattern};
use std::fmt;
use std::time::Instant;

/// Error reported by a problem's residual, tangent or convergence hook.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProblemError {
    /// The evaluation failed at this state but a smaller step may succeed (a return map that
    /// did not converge, an inverted cell, a contact search that lost the tool...).
    #[error("{0}")]
    Recoverable(String),
    /// No step size can help: stop the run.
    #[error("fatal: {0}")]
    Fatal(String),
    /// No step size can help: a part of the problem or an observer of its steps failed
    /// (what and why, the error kept as the source).
    #[error("fatal: {0}")]
    Failed(#[source] Failure),
}

/// A failure with its context: what failed (a sensitivity method, a monitor, the results
/// writer, a convergence hook) and the error itself, kept as the source (shared, so that a
/// recorded failure can be reported more than once).
#[derive(Debug, Clone)]
pub struct Failure {
    /// What failed.
    pub context: String,
    /// Why.
    pub source: std::sync::Arc<dyn std::error::Error + Send + Sync>,
}

impl Failure {
    /// `source` (an error, or a message) in `context`.
    pub fn new(
        context: impl Into<String>,
        source: impl Into<Box<dyn std::error::Error + Send + Sync>>,
    ) -> Self {
        Failure {
            context: context.into(),
            source: std::sync::Arc::from(source.into()),
        }
    }
}

impl fmt::Display for Failure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.context, self.source)
    }
}

impl std::error::Error for Failure {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        Some(&*self.source)
    }
}

/// Failures compare by context and message (the sources are shared trait objects).
impl PartialEq for Failure {
    fn eq(&self, other: &Self) -> bool {
        self.context == other.context && self.source.to_string() == other.source.to_string()
    }
}

/// A nonlinear system `r(u, λ) = 0` with explicit history (committed and trial state).
///
/// Residual and tangent are evaluated from the *committed* history and the trial `u`; the
/// trial history produced by the last evaluation becomes the committed one in
/// [`NonlinearProblem::commit`] and is discarded in [`NonlinearProblem::restore`].
pub trait NonlinearProblem {
    /// Number of unknowns.
    fn n_dofs(&self) -> usize;
    /// Residual `r = f_int(u) − λ f_ext` (any consistent sign; the tangent is `∂r/∂u`).
    fn residual(&mut self, u: &[f64], load: f64, r: &mut [f64]) -> Result<(), ProblemError>;
    /// Tangent `∂r/∂u` into `values`, aligned with the pattern given to the driver; every entry
    /// must be overwritten (the driver's buffer holds the eliminated previous tangent).
    fn tangent(&mut self, u: &[f64], load: f64, values: &mut [f64]) -> Result<(), ProblemError>;
    /// Both at once (override to share one assembly pass); the driver calls only this.
    fn residual_and_tangent(
        &mut self,
        u: &[f64],
        load: f64,
        r: &mut [f64],
        values: &mut [f64],
    ) -> Result<(), ProblemError> {
        self.residual(u, load, r)?;
        self.tangent(u, load, values)
    }
    /// Essential conditions `(dof, value)` at load level `load` (default: none).
    fn essential(&self, _load: f64) -> Vec<(usize, f64)> {
        Vec::new()
    }
    /// A force scale at `load` (e.g. `‖λ f_ext‖`), a floor of the residual reference so that the
    /// relative tolerance never asks for less than round-off in small steps (default 0).
    fn force_norm(&self, _load: f64) -> f64 {
        0.0
    }
    /// The size of the terms summed into the last evaluated residual, e.g. `‖Σ_cells |r_cell|‖`
    /// (component-wise absolute values of the cell contributions, internal and external), in
    /// the driver's unknowns. Round-off leaves `‖r‖` at about `ε` times this, however well the
    /// iteration converges: the driver accepts below `roundoff_factor · ε · residual_scale`
    /// ([`Acceptance::RoundoffFloor`]). Default 0: no estimate (the stagnation test remains).
    fn residual_scale(&self) -> f64 {
        0.0
    }
    /// Called at a converged step before `commit`, with the tangent at the converged state
    /// factorised in `step.solver` (the design sensitivity hook). An error stops the run
    /// (a recoverable one is reported like a fatal one: the step has converged).
    fn on_converged(&mut self, _step: &ConvergedStep<'_>) -> Result<(), ProblemError> {
        Ok(())
    }
    /// Whether [`NonlinearProblem::on_converged`] needs the tangent factorised at the converged
    /// state (default [`ConvergedTangent::Required`]: the design sensitivity equation does).
    /// With [`ConvergedTangent::NotNeeded`] the driver may accept an iterate from its residual
    /// alone, saving one tangent assembly and one factorisation per step (module
    /// documentation, "residual-first acceptance").
    fn converged_tangent(&self) -> ConvergedTangent {
        ConvergedTangent::Required
    }
    /// `∂r/∂λ` at `(u, load)` into `out` (for [`NonlinearProblem::residual`]'s sign convention,
    /// `−f_ext` of proportional loads); `Ok(false)` when the problem cannot give it (default),
    /// which arc-length continuation ([`NewtonSolver::run_arc_length`]) then refuses.
    fn load_derivative(
        &mut self,
        _u: &[f64],
        _load: f64,
        _out: &mut [f64],
    ) -> Result<bool, ProblemError> {
        Ok(false)
    }
    /// The number of leading unknowns measured by the arc length (default all; a problem
    /// with Lagrange multipliers after its displacements gives the displacements' count).
    fn path_dofs(&self) -> usize {
        self.n_dofs()
    }
    /// What unknown `dof` is, in the problem's terms (e.g. a node and component), for the
    /// messages of a failed solve (default: none, the index alone).
    fn describe_unknown(&self, _dof: usize) -> Option<String> {
        None
    }
    /// A count of the changes of an inequality's active set (e.g. which slave points penetrate
    /// which tool) from one evaluation to the next, accumulated over the run (default 0: no
    /// inequalities). An iteration whose iterate changed it is not counted against
    /// `max_iterations` ([`NewtonOptions::max_active_set_iterations`]).
    fn active_set_changes(&self) -> u64 {
        0
    }
    /// Accept the converged state `u` at `load` (trial history becomes committed).
    fn commit(&mut self, u: &[f64], load: f64);
    /// Reject the current trial state (back to the committed history).
    fn restore(&mut self);
}

/// Whether a problem's convergence hook needs the tangent at the converged state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ConvergedTangent {
    /// Factorise the tangent at the accepted iterate (design sensitivity).
    #[default]
    Required,
    /// Assemble the tangent at the accepted iterate, but do not factorise it: the hook solves
    /// with it iteratively, preconditioned by the factorisation the solver holds (an earlier
    /// iterate's). Residual-first acceptance is allowed, with the residual and the tangent
    /// evaluated together where the iteration predicts convergence ([`ConvergedStep::tangent`]).
    Assembled,
    /// The hook does not use the factorisation: residual-first acceptance is allowed.
    NotNeeded,
}

impl ConvergedTangent {
    /// The policy that serves both `self` and `other`: `Required` over `Assembled` over
    /// `NotNeeded`.
    pub fn stricter(self, other: ConvergedTangent) -> ConvergedTangent {
        use ConvergedTangent::*;
        match (self, other) {
            (Required, _) | (_, Required) => Required,
            (Assembled, _) | (_, Assembled) => Assembled,
            _ => NotNeeded,
        }
    }
}

/// Which tangent the solver of a [`ConvergedStep`] holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FactorisedAt {
    /// The tangent at the converged unknowns.
    Converged,
    /// An earlier tangent (residual-first acceptance): the previous iterate's, or after GMRES
    /// updates the factorisation held, possibly from an earlier step.
    PreviousIterate,
}

/// What [`NonlinearProblem::on_converged`] sees.
#[derive(Debug)]
pub struct ConvergedStep<'a> {
    /// Index of this converged step (0-based).
    pub step: usize,
    /// Load factor reached.
    pub load: f64,
    /// Converged unknowns.
    pub u: &'a [f64],
    /// Iteration record of the step.
    pub record: &'a StepRecord,
    /// Solver holding the factorised tangent, essential conditions eliminated: at `u` unless
    /// `factorised_at` says otherwise (only when the problem declared
    /// [`ConvergedTangent::NotNeeded`]).
    pub solver: &'a LinearSolver,
    /// Where the tangent in `solver` was evaluated.
    pub factorised_at: FactorisedAt,
    /// The essential conditions eliminated in `solver` (zero their entries in sensitivity
    /// right-hand sides).
    pub essential: &'a EssentialBc,
    /// The tangent at `u` (essential conditions eliminated) as values over the pattern, when
    /// `solver` holds an earlier iterate's and the problem asked for
    /// [`ConvergedTangent::Assembled`]; `None` otherwise.
    pub tangent: Option<(&'a SparsityPattern, &'a [f64])>,
}

/// Convergence and divergence settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NewtonOptions {
    /// Round-off floor factor: accept when `‖r_k‖ ≤ roundoff_factor · ε · S_k` (module
    /// documentation). Default 1: `ε S_k` bounds the floor from above; the residuals where
    /// the iteration stalled were 0.04–0.15 (once 0.56) times `ε S_k` on the large-deflection
    /// elastica and the end-moment cantilever (tests/shell_elastica.rs,
    /// tests/shell_cantilever_moment.rs), so factor 1 accepts within about an order of
    /// magnitude of the floor, and only when the tolerances ask for less.
    pub roundoff_factor: f64,
    /// Stagnation: accept, once the energy test holds, when `‖r_j‖ ≥ stagnation_ratio ·
    /// ‖r_{j−1}‖` for `j = k` and `k − 1` and `‖r_k‖ ≤ √residual_rtol · r_ref` (default 0.5; 0
    /// disables the test).
    pub stagnation_ratio: f64,
    /// Relative residual tolerance (default 1e-8).
    pub residual_rtol: f64,
    /// Absolute residual floor (default 0).
    pub residual_atol: f64,
    /// Relative energy tolerance on `|Δuᵀ r|` (default 1e-14: the energy scales like the
    /// residual squared, so this is about `residual_rtol²` with two digits of slack).
    pub energy_rtol: f64,
    /// Absolute energy floor (default 0).
    pub energy_atol: f64,
    /// Maximum iterations per step (default 20), not counting those whose iterate changed the
    /// problem's active set ([`NonlinearProblem::active_set_changes`]).
    pub max_iterations: usize,
    /// Maximum iterations per step whose iterate changed the active set (default 20). Such an
    /// iteration's update was solved with another active set (a contact switched on or off),
    /// so it says nothing of Newton's convergence on the current one, and a shorter step does
    /// not remove it: a sheet lifting off a die at the first touch of a punch changes its
    /// active set in the first iterations of every step size.
    pub max_active_set_iterations: usize,
    /// How the Newton updates are solved (default [`LinearUpdates::Direct`]).
    pub linear_updates: LinearUpdates,
    /// Divergence when `‖r_k‖ > factor · r_ref` or `|Δu_kᵀ r_k| > factor · |Δu_0ᵀ r_0|`
    /// (default 1e8).
    pub divergence_factor: f64,
    /// What an iterate that cannot be used leads to (default [`LineSearch::OnFailure`]).
    pub line_search: LineSearch,
}

impl Default for NewtonOptions {
    fn default() -> Self {
        Self {
            roundoff_factor: 1.0,
            stagnation_ratio: 0.5,
            residual_rtol: 1e-8,
            residual_atol: 0.0,
            energy_rtol: 1e-14,
            energy_atol: 0.0,
            max_iterations: 20,
            max_active_set_iterations: 20,
            divergence_factor: 1e8,
            linear_updates: LinearUpdates::Direct,
            line_search: LineSearch::OnFailure,
        }
    }
}

/// How the linear system of a Newton update is solved.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LinearUpdates {
    /// Factorise every tangent and solve directly.
    #[default]
    Direct,
    /// Near convergence (`k ≥ 1`, constraints met, `‖r_k‖ ≤ 10⁻² r_ref`, and a factorisation
    /// of an earlier iterate of the same step held), solve `K_k Δu = −r_k` by GMRES
    /// right-preconditioned with that factorisation ([`super::krylov::gmres`]) to 1e-12 of
    /// `‖r_k‖`, within 20 Arnoldi steps; otherwise (or if GMRES fails) factorise as
    /// [`LinearUpdates::Direct`]. The updates equal the direct ones to that tolerance, so the
    /// iteration stays Newton's (quadratic); an iterate accepted after a GMRES update is
    /// factorised before [`NonlinearProblem::on_converged`] when the problem requires the
    /// converged tangent.
    KrylovNearConvergence,
    /// Every update by GMRES right-preconditioned with the factorisation the solver holds,
    /// whichever tangent of the run it was computed for (an earlier iterate of this step, an
    /// earlier step, a rejected attempt: it is only a preconditioner), to 1e-12 of `‖r_k‖`, so
    /// the updates equal the direct ones to that tolerance and the iteration stays Newton's.
    /// The tangent is factorised (and the update solved directly) when no factorisation of
    /// this run is held, when GMRES does not converge within the budget (the estimated cost of
    /// a factorisation in Arnoldi steps, [`LinearSolver::refactorisation_cost`], between
    /// [`HELD_MIN_BUDGET`] and [`HELD_MAX_BUDGET`] steps), or when the preconditioner has gone
    /// stale: the last solve's Arnoldi steps reached the average cost per solve since the last
    /// factorisation (factorisation included), beyond which keeping the factors no longer
    /// lowers that average (the replacement rule of a cost that grows with age). It is
    /// factorised without trying GMRES at an iteration `k` where GMRES gave up in each of the
    /// two step attempts before ([`HELD_PROBE_EVERY`]: the attempt that gives up is pure loss,
    /// and the first iterations of a plastic step give up step after step). The
    /// residual-first energy test solves with the previous iterate's tangent by GMRES too, and
    /// an accepted iterate is factorised before [`NonlinearProblem::on_converged`] when the
    /// problem requires the converged tangent.
    KrylovHeld,
    /// [`LinearUpdates::KrylovHeld`] with the sparse factorisations, [`LinearUpdates::Direct`]
    /// with [`super::Method::DenseLu`] (small systems, where a factorisation costs a few
    /// solves).
    Auto,
}

/// What the driver does with an iterate at which the iteration cannot go on: the problem's
/// evaluation failed recoverably (an inverted cell, a return map that did not converge), the
/// residual is not finite or diverged (`divergence_factor`, residual or energy), or the tangent
/// could not be factorised or solved with (singular). Without a line search the attempt fails
/// and the step is cut.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LineSearch {
    /// Fail the attempt: the step is cut.
    Off,
    /// Backtrack along the update that led to the iterate: `u_{k−1} + s Δu_{k−1}` for
    /// `s` = 1/2, 1/4, 1/8, 1/16 ([`BACKTRACK_LENGTHS`]), each evaluated afresh from the
    /// committed history; the first usable one is the iterate `k` (at most
    /// [`BACKTRACK_BUDGET`] tries per attempt). At `k = 0` the update is the
    /// predictor's increment `u_pred − u_n`, and after the four lengths the committed unknowns
    /// themselves are tried (`s = 0`: the zero predictor). The attempt fails (and the step is
    /// cut) only when every length fails. An attempt that never meets such an iterate takes
    /// exactly the iterates it takes with [`LineSearch::Off`]: converged steps are unchanged
    /// bit for bit, only steps that would be cut can converge.
    #[default]
    OnFailure,
}

/// The step lengths [`LineSearch::OnFailure`] tries, in order.
pub const BACKTRACK_LENGTHS: [f64; 4] = [0.5, 0.25, 0.125, 0.0625];

/// Most backtracking tries in one step attempt (over all its iterates). Measured on the
/// half-sheet bending case: the attempts the line search rescued used at most 3 tries, those
/// that failed anyway up to 30 (each an evaluation of residual and tangent).
pub const BACKTRACK_BUDGET: usize = 5;

/// One backtracking try of [`LineSearch::OnFailure`].
#[derive(Debug, Clone, PartialEq)]
pub struct Backtrack {
    /// The iterate `k` whose update was shortened.
    pub iteration: usize,
    /// The step length `s` tried next (`u_{k−1} + s Δu_{k−1}`; at `k = 0`, `u_n + s (u_pred − u_n)`).
    pub length: f64,
    /// Why the iterate at the previous length was not usable.
    pub reason: FailureReason,
}

/// Tolerance of the GMRES updates of [`LinearUpdates::KrylovHeld`]: `‖K Δu + r_k‖ ≤ HELD_RTOL ·
/// max(‖r_k‖, r_ref)`. The iterate then differs from the direct update's by `K⁻¹` of a residual
/// four orders below the Newton tolerance's `10⁻⁸ r_ref` (the default `residual_rtol`), so the
/// acceptance tests see the same residuals. Relative to `‖r_k‖` alone, the late iterations
/// (residuals of `10⁻⁴ r_ref` and less) would spend Arnoldi steps on digits of `Δu` far below
/// `10⁻¹²` of the unknowns.
pub const HELD_RTOL: f64 = 1e-12;

/// Fewest Arnoldi steps GMRES may take under [`LinearUpdates::KrylovHeld`] before the tangent
/// is factorised instead.
pub const HELD_MIN_BUDGET: usize = 10;
/// Most Arnoldi steps GMRES may take under [`LinearUpdates::KrylovHeld`] (the Krylov basis holds
/// this many vectors of the system's size).
pub const HELD_MAX_BUDGET: usize = 60;

/// Under [`LinearUpdates::KrylovHeld`], an iteration `k` at which GMRES gave up in each of the
/// two step attempts before factorises at once, without trying (one give-up alone, as at the
/// third iteration of some steps, does not predict the next); every `HELD_PROBE_EVERY`-th
/// attempt, and an attempt whose load step is less than half the last one, tries again at
/// every iteration, so a change of regime (GMRES converging there again) is noticed within
/// that many attempts. Measured on the plastic hemisphere (2 cores, 2026-11-28): GMRES gave up
/// at the first two iterations of 18 of its 19 steps at 33², and at 45 updates of 18 steps at
/// 17², each after the first early-abort test (three Arnoldi steps); those attempts were
/// 3.1 % and 3.9 % of the run. With the rule 23 of the 38 at 33² and 25 of the 45 at 17² are
/// not tried, and both runs take the same iterates, bit for bit (GMRES would have given up at
/// every iteration skipped).
pub const HELD_PROBE_EVERY: usize = 4;

impl LinearUpdates {
    /// The mode used with `solver` ([`LinearUpdates::Auto`] resolved by its method).
    pub fn resolve(self, solver: &LinearSolver) -> LinearUpdates {
        match self {
            LinearUpdates::Auto if solver.method() == super::Method::DenseLu => {
                LinearUpdates::Direct
            }
            LinearUpdates::Auto => LinearUpdates::KrylovHeld,
            other => other,
        }
    }
}

/// The factorisation held across iterations and steps under [`LinearUpdates::KrylovHeld`], and
/// the cost of the solves made with it (in Arnoldi steps).
#[derive(Debug, Clone, Copy, Default)]
struct Held {
    /// The solver holds a factorisation computed in this run.
    valid: bool,
    /// The last solve reached the cycle's average cost: factorise at the next update.
    stale: bool,
    /// Estimated cost of one factorisation, in Arnoldi steps.
    cost: f64,
    /// Arnoldi steps (plus one per solve for the chord step) since the last factorisation.
    spent: f64,
    /// Solves since the last factorisation (the direct one included).
    solves: usize,
    /// Iterations `k < 64` (bit `k`) at which GMRES gave up in each of the two attempts
    /// before this one, or was not tried there for that reason.
    gave_up_twice: u64,
    /// The same for the last attempt alone.
    gave_up_before: u64,
    /// The same for this attempt.
    gave_up_now: u64,
    /// Attempts since GMRES was last tried at every iteration (a probe).
    since_probe: usize,
    /// This attempt tries GMRES wherever the factors allow it.
    probe: bool,
    /// The last attempt's load step `|Δλ|`.
    last_step: f64,
}

impl Held {
    /// A factorisation was just computed (and will serve one direct solve).
    fn refreshed(&mut self) {
        self.valid = true;
        self.stale = false;
        self.spent = 0.0;
        self.solves = 0;
    }

    /// A direct solve with the fresh factors.
    fn direct_solve(&mut self) {
        self.spent += 1.0;
        self.solves += 1;
    }

    /// A GMRES solve of `arnoldi` steps: stale when its cost reached the cycle's average.
    fn krylov_solve(&mut self, arnoldi: usize) {
        let c = arnoldi as f64 + 1.0;
        self.spent += c;
        self.solves += 1;
        self.stale = c >= (self.cost + self.spent) / self.solves as f64;
    }

    /// GMRES budget in Arnoldi steps.
    fn budget(&self) -> usize {
        (self.cost.ceil() as usize).clamp(HELD_MIN_BUDGET, HELD_MAX_BUDGET)
    }

    /// A step attempt of load step `step` starts: what the previous two met becomes the
    /// prediction, unless this step is less than half the last one (the tangent then moves
    /// less within the step, and GMRES converges where it gave up before: measured on the
    /// plastic hemisphere's last step, clipped to land on the end load); every
    /// [`HELD_PROBE_EVERY`]-th attempt tries GMRES everywhere again.
    fn begin_attempt(&mut self, step: f64) {
        let now = std::mem::take(&mut self.gave_up_now);
        self.gave_up_twice = now & self.gave_up_before;
        self.gave_up_before = now;
        let shorter = step.abs() < 0.5 * self.last_step;
        self.last_step = step.abs();
        self.since_probe += 1;
        self.probe = shorter || self.since_probe >= HELD_PROBE_EVERY;
        if self.probe {
            self.since_probe = 0;
        }
    }

    /// Whether GMRES at iteration `k` is predicted to give up (it did at the same iteration
    /// of each of the previous two attempts, and this attempt is no probe).
    fn predicts_giving_up(&self, k: usize) -> bool {
        !self.probe && k < 64 && self.gave_up_twice & (1 << k) != 0
    }

    /// GMRES gave up at iteration `k`, or was not tried there because it was predicted to.
    fn gave_up(&mut self, k: usize) {
        if k < 64 {
            self.gave_up_now |= 1 << k;
        }
    }
}

/// How a load step's iteration starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Predictor {
    /// From the committed unknowns (the first iteration is then the tangent predictor).
    Zero,
    /// From the committed unknowns plus the previous converged increment scaled by the ratio of
    /// the load steps, `u_n + (Δλ/Δλ_prev)(u_n − u_{n−1})` (a secant, i.e. linear extrapolation
    /// along the path); the first step, with no previous increment, starts from zero. Measured:
    /// on the large-deflection elastica 35 against 38 Newton updates (first step P/4) and 86
    /// against 92 (16 equal steps) for the same converged states (tests/shell_elastica.rs); on a
    /// softening spring chain 59 against 77 (tests/solver.rs). Hence the default.
    #[default]
    Secant,
    /// Quadratic extrapolation through the last three converged states `(λ, u)`:
    /// `u_n + s d₁/h₁ + s (s + h₁)(d₁/h₁ − d₂/h₂)/(h₁ + h₂)` with `s = Δλ`, `d₁ = u_n − u_{n−1}`,
    /// `h₁ = λ_n − λ_{n−1}`, `d₂ = u_{n−1} − u_{n−2}`, `h₂ = λ_{n−1} − λ_{n−2}` (Newton's
    /// divided differences). It falls back to the secant on the second step and to zero on the
    /// first. For paths that bend (an inextensional mode whose membrane strains are quadratic
    /// in the displacement) the secant's error is of order `s²` and the quadratic's `s³`.
    Quadratic,
}

/// Load stepping from `start` to `end` (load factors, `end ≥ start`), landing exactly on every
/// load level in `stops`.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadStepping {
    /// Initial load factor (the problem's committed state must be at this level).
    pub start: f64,
    /// Final load factor.
    pub end: f64,
    /// First step size.
    pub initial_step: f64,
    /// Smallest step tried before giving up.
    pub min_step: f64,
    /// Largest step.
    pub max_step: f64,
    /// Factor applied to the step after a failure (default 0.5).
    pub cut_factor: f64,
    /// Factor applied after an easy step (default 1.5).
    pub grow_factor: f64,
    /// A step converging in at most this many iterations is easy (default 4).
    pub easy_iterations: usize,
    /// Maximum number of step attempts, converged or not (default 10 000).
    pub max_attempts: usize,
    /// How a step's iteration starts (default [`Predictor::Secant`]).
    pub predictor: Predictor,
    /// Load levels the stepping must land on exactly (strictly ascending, finite, within
    /// `(start, end]`; default none). A step that would pass the next stop is clipped to it
    /// (the load factor is then the stop itself, bit for bit); the step after a clipped one
    /// uses the unclipped step size again, which a clipped step neither grows nor shrinks
    /// (an easy clipped step says little about the full step). A clipped step that fails is
    /// cut from its clipped size.
    pub stops: Vec<f64>,
    /// What a failed attempt at a stop leads to (default [`StopFailure::Cut`]).
    pub stop_failure: StopFailure,
}

/// What the driver does when an attempt to land on a stop of [`LoadStepping::stops`] fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StopFailure {
    /// Cut the step: a level short of the stop is committed (and the stop reached later).
    #[default]
    Cut,
    /// Reach the stop from the committed state by continuation: the step is cut as usual,
    /// but the shorter step's converged state is not committed; it is the start (extrapolated
    /// along its increment) of a new attempt at the stop, from the same committed state
    /// (history, committed unknowns). A level that fails is halved again towards the last
    /// intermediate solution, down to `min_step`. The committed state then solves the same
    /// equations `r(u; history_n, λ_stop) = 0` as an attempt that converged directly (the
    /// intermediate levels only change where Newton starts), so the converged levels are
    /// exactly the stops: the discrete response of a path-dependent analysis is the same
    /// function of the design as in a run that needed no continuation. The intermediate levels
    /// are recorded in [`StepRecord::continuation`].
    Continuation,
}

impl Default for LoadStepping {
    fn default() -> Self {
        Self {
            start: 0.0,
            end: 1.0,
            initial_step: 0.1,
            min_step: 1e-6,
            max_step: 1.0,
            cut_factor: 0.5,
            grow_factor: 1.5,
            easy_iterations: 4,
            max_attempts: 10_000,
            predictor: Predictor::default(),
            stops: Vec::new(),
            stop_failure: StopFailure::Cut,
        }
    }
}

/// Why a step attempt failed.
#[derive(Debug, Clone, PartialEq)]
pub enum FailureReason {
    /// No convergence within `max_iterations`.
    MaxIterations(usize),
    /// The active set changed in more than `max_active_set_iterations` iterations.
    ActiveSetIterations(usize),
    /// Residual or energy grew by more than `divergence_factor` (`ratio` observed).
    Diverged {
        /// Observed growth over iteration 0.
        ratio: f64,
    },
    /// The residual contained NaN or infinity.
    NonFiniteResidual,
    /// Factorisation or solve failed (e.g. singular tangent at a limit point).
    LinearSolver(SolverError),
    /// The problem reported an error.
    Problem(ProblemError),
    /// Invalid stepping or input (not retried).
    Setup(String),
    /// `max_attempts` step attempts used up.
    TooManyAttempts(usize),
    /// Arc-length continuation: after the first converged step, the arc lengths allowed would
    /// need far more steps to reach the end load than the attempts left (the first step's load
    /// increment per arc length, at the largest arc length, more than four times short).
    ArcLengthTooShort {
        /// The first step's load increment.
        first_step: f64,
        /// Its arc length.
        arc_length: f64,
        /// The largest arc length.
        max_length: f64,
        /// Steps that estimate needs.
        steps: f64,
        /// Attempts left.
        attempts_left: usize,
    },
    /// An arc-length step converged to a point behind the last one: its increment makes an
    /// obtuse angle with the previous step's (over the path unknowns), so the corrector went
    /// back along the path instead of on (a turn sharper than the arc length resolves, a cusp,
    /// or a branch point). Retried with a shorter arc length.
    PathReversed {
        /// Cosine of the angle between the two increments (negative).
        cosine: f64,
    },
}

impl fmt::Display for FailureReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FailureReason::MaxIterations(n) => write!(f, "no convergence in {n} iterations"),
            FailureReason::ActiveSetIterations(n) => write!(
                f,
                "the contact active set still changed after {n} iterations that changed it"
            ),
            FailureReason::Diverged { ratio } => {
                write!(f, "diverged (growth {ratio:.3e} over the first iteration)")
            }
            FailureReason::NonFiniteResidual => write!(f, "non-finite residual"),
            FailureReason::LinearSolver(e) => write!(f, "linear solver: {e}"),
            FailureReason::Problem(e) => write!(f, "problem: {e}"),
            FailureReason::Setup(s) => write!(f, "setup: {s}"),
            FailureReason::TooManyAttempts(n) => write!(f, "{n} step attempts used up"),
            FailureReason::ArcLengthTooShort {
                first_step,
                arc_length,
                max_length,
                steps,
                attempts_left,
            } => write!(
                f,
                "the arc lengths are too short for this path: the first step (arc length \
                 {arc_length:e}) advanced the load factor by {first_step:e}; at the largest arc \
                 length {max_length:e} the end load takes about {steps:.0} steps, more than four \
                 times the {attempts_left} attempts left; a longer arc length (or a larger \
                 maximum) reaches it"
            ),
            FailureReason::PathReversed { cosine } => write!(
                f,
                "the arc-length step went back along the path (cosine {cosine:.3} between its \
                 increment and the previous step's): the path turns more sharply than the arc \
                 length resolves, or it has a cusp or a branch point there"
            ),
        }
    }
}

impl FailureReason {
    /// A linear solver failure at a known unknown, with the problem's name for it appended.
    fn with_unknown_named(self, name: impl Fn(usize) -> Option<String>) -> Self {
        match self {
            FailureReason::LinearSolver(SolverError::Singular {
                dof: Some(d),
                detail,
            }) => {
                let detail = match name(d) {
                    Some(n) => format!("{detail}; DOF {d} is {n}"),
                    None => detail,
                };
                FailureReason::LinearSolver(SolverError::Singular {
                    dof: Some(d),
                    detail,
                })
            }
            other => other,
        }
    }

    /// An iterate's failure that a shorter update may avoid ([`LineSearch::OnFailure`]): a
    /// recoverable problem error, a non-finite or diverged residual, a tangent that could not
    /// be factorised or solved with.
    fn backtrackable(&self) -> bool {
        match self {
            FailureReason::Problem(ProblemError::Recoverable(_))
            | FailureReason::NonFiniteResidual
            | FailureReason::Diverged { .. } => true,
            FailureReason::LinearSolver(e) => matches!(
                e,
                SolverError::Singular { .. }
                    | SolverError::NotPositiveDefinite { .. }
                    | SolverError::NonFiniteMatrix { .. }
                    | SolverError::NonFiniteRhs { .. }
            ),
            _ => false,
        }
    }

    fn retryable(&self) -> bool {
        !matches!(
            self,
            FailureReason::Problem(ProblemError::Fatal(_) | ProblemError::Failed(_))
                | FailureReason::Setup(_)
                | FailureReason::TooManyAttempts(_)
                | FailureReason::ArcLengthTooShort { .. }
        )
    }
}

/// Which test accepted a converged iterate (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Acceptance {
    /// Residual and energy tolerances (or the residual tolerance with the residual at its
    /// round-off floor, where the energy product is round-off too).
    Tolerance,
    /// Residual at its round-off floor, above the residual tolerance.
    RoundoffFloor,
    /// Energy test met and the residual stopped falling for two iterations, within
    /// `√residual_rtol · r_ref`.
    Stagnation,
    /// Residual tolerance met with `‖r_k‖ ≤ 10³ ε r_ref` (at the round-off of its reference,
    /// `k ≥ 1`), the energy test not: the energy product of a round-off residual is not a
    /// measure of convergence (near a singular tangent it is large).
    ResidualRoundoff,
}

/// `‖r_k‖ ≤ ROUNDOFF_BAND · ε · r_ref` is a residual at the round-off of its reference
/// ([`Acceptance::ResidualRoundoff`]): 10³ is the largest ratio of the stalled residual to
/// The iteration limits after iterate `k` of an attempt: more than `max_active_set_iterations`
/// iterates that changed the active set, or `max_iterations` that did not (module
/// documentation, "Active set").
fn iteration_limits(o: &NewtonOptions, rec: &StepRecord, k: usize) -> Result<(), FailureReason> {
    if rec.active_set_iterations > o.max_active_set_iterations {
        return Err(FailureReason::ActiveSetIterations(
            o.max_active_set_iterations,
        ));
    }
    if k - rec.active_set_iterations == o.max_iterations {
        return Err(FailureReason::MaxIterations(o.max_iterations));
    }
    Ok(())
}

/// `ε` times the summed terms measured on the shells with large rotations (module
/// documentation, round-off floor).
const ROUNDOFF_BAND: f64 = 1e3;

/// Record of one step attempt.
#[derive(Debug, Clone, PartialEq)]
pub struct StepRecord {
    /// Load factor at the start of the attempt.
    pub load_start: f64,
    /// Load factor aimed at (reached if converged).
    pub load: f64,
    /// Step size `Δλ`.
    pub step_size: f64,
    /// Number of Newton updates applied (= residual evaluations − 1 when converged).
    pub iterations: usize,
    /// How many of the evaluated iterates changed the problem's active set (not counted
    /// against `max_iterations`).
    pub active_set_iterations: usize,
    /// `‖r_k‖` over free DOFs for every evaluation `k`.
    pub residual_norms: Vec<f64>,
    /// `|Δu_kᵀ r_k|` for every solve.
    pub energy_norms: Vec<f64>,
    /// Whether the attempt converged.
    pub converged: bool,
    /// The predictor the attempt started from ([`Predictor::Zero`] when there was no previous
    /// increment).
    pub predictor: Predictor,
    /// Which test accepted the converged iterate.
    pub acceptance: Option<Acceptance>,
    /// The round-off floor `roundoff_factor · ε · S_k` for every evaluation `k`.
    pub roundoff_floors: Vec<f64>,
    /// Residual-only evaluations (residual-first acceptance): `(k, ‖r_k‖)` for every one, also
    /// those that did not accept (the iterate was then re-evaluated with the tangent, and
    /// `residual_norms[k]` holds that evaluation).
    pub residual_only: Vec<(usize, f64)>,
    /// Where the converged step's factorised tangent was evaluated (`None` until converged).
    pub factorised_at: Option<FactorisedAt>,
    /// Wall time spent in the attempt's parts.
    pub timing: StepTiming,
    /// Updates solved by GMRES ([`LinearUpdates::KrylovNearConvergence`]): `(k, Arnoldi steps)`.
    pub krylov: Vec<(usize, usize)>,
    /// Iterations `k` whose GMRES update gave up (the tangent was then factorised).
    pub krylov_gave_up: Vec<usize>,
    /// Iterations `k` factorised without trying GMRES, because it gave up at the same
    /// iteration of each of the two attempts before ([`HELD_PROBE_EVERY`]).
    pub krylov_skipped: Vec<usize>,
    /// Why it failed, if it did.
    pub failure: Option<FailureReason>,
    /// Backtracking tries of the line search ([`LineSearch::OnFailure`]), in order.
    pub backtracks: Vec<Backtrack>,
    /// Intermediate levels solved (not committed) to start this attempt's iteration
    /// ([`StopFailure::Continuation`]), in order; empty when the attempt started from the
    /// predictor.
    pub continuation: Vec<f64>,
}

impl StepRecord {
    /// Whether GMRES gave up at iteration `k` of this attempt, or was not tried there because
    /// it had given up at `k` in the two attempts before ([`Self::krylov_gave_up`],
    /// [`Self::krylov_skipped`]).
    pub fn gmres_gave_up_at(&self, k: usize) -> bool {
        self.krylov_gave_up.contains(&k) || self.krylov_skipped.contains(&k)
    }

    /// A record of an attempt from `load_start` to `load` of step size `step_size`, started
    /// from `predictor`, with nothing evaluated yet.
    pub fn new(load_start: f64, load: f64, step_size: f64, predictor: Predictor) -> Self {
        StepRecord {
            load_start,
            load,
            step_size,
            iterations: 0,
            active_set_iterations: 0,
            residual_norms: Vec::new(),
            energy_norms: Vec::new(),
            converged: false,
            predictor,
            acceptance: None,
            roundoff_floors: Vec::new(),
            residual_only: Vec::new(),
            factorised_at: None,
            timing: StepTiming::default(),
            krylov: Vec::new(),
            krylov_gave_up: Vec::new(),
            krylov_skipped: Vec::new(),
            failure: None,
            backtracks: Vec::new(),
            continuation: Vec::new(),
        }
    }
}

/// Wall time of one step attempt by part, in seconds.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepTiming {
    /// Residual and tangent evaluations ([`NonlinearProblem::residual_and_tangent`]).
    pub residual_and_tangent_s: f64,
    /// Residual-only evaluations (residual-first acceptance).
    pub residual_s: f64,
    /// Numeric factorisations.
    pub factorise_s: f64,
    /// Solves.
    pub solve_s: f64,
}

/// Result of a run: the last converged state and every attempt.
#[derive(Debug, Clone, PartialEq)]
pub struct NewtonReport {
    /// Unknowns at the last converged step (the initial ones if none converged).
    pub u: Vec<f64>,
    /// Load factor of `u`.
    pub load: f64,
    /// Every attempt in order, converged or not.
    pub attempts: Vec<StepRecord>,
}

impl NewtonReport {
    /// The converged steps in order.
    pub fn converged_steps(&self) -> impl Iterator<Item = &StepRecord> {
        self.attempts.iter().filter(|s| s.converged)
    }
}

/// A run that stopped before reaching the end load.
#[derive(Debug, Clone, PartialEq)]
pub struct NewtonFailure {
    /// Load factor of the last converged state.
    pub converged_load: f64,
    /// Load factor of the last (failed) attempt.
    pub attempted_load: f64,
    /// Step size of the last attempt.
    pub step_size: f64,
    /// Why the last attempt failed.
    pub reason: FailureReason,
    /// Residual norms of the last attempt.
    pub last_residuals: Vec<f64>,
    /// Everything converged so far.
    pub report: NewtonReport,
}

impl fmt::Display for NewtonFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "Newton stopped at load factor {:.6e} (last converged {:.6e}, step {:.3e}): {}",
            self.attempted_load, self.converged_load, self.step_size, self.reason
        )?;
        if self.last_residuals.is_empty() {
            // No iteration was made (a cap or a set-up error before the attempt).
            return Ok(());
        }
        write!(f, "; residual norms of the last attempt: [")?;
        for (k, r) in self.last_residuals.iter().enumerate() {
            write!(f, "{}{r:.3e}", if k > 0 { ", " } else { "" })?;
        }
        write!(f, "]")
    }
}

impl std::error::Error for NewtonFailure {}

/// The driver: options plus load stepping.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct NewtonSolver {
    /// Convergence settings.
    pub options: NewtonOptions,
    /// Load stepping.
    pub stepping: LoadStepping,
}

struct Work {
    r: Vec<f64>,
    /// Scratch of [`unknowns_term_scale`] (`4 n`).
    s: Vec<f64>,
    rhs: Vec<f64>,
    du: Vec<f64>,
    values: Vec<f64>,
    g: Vec<f64>,
    /// The mode in use ([`LinearUpdates::Auto`] resolved).
    updates: LinearUpdates,
    held: Held,
    /// Line search: the iterate the last update started from, and that update.
    base: Vec<f64>,
    dir: Vec<f64>,
}

impl NewtonSolver {
    /// Run without a progress callback.
    pub fn run<P: NonlinearProblem>(
        &self,
        problem: &mut P,
        pattern: &SparsityPattern,
        solver: &mut LinearSolver,
        u0: &[f64],
    ) -> Result<NewtonReport, Box<NewtonFailure>> {
        self.run_with_progress(problem, pattern, solver, u0, |_| {})
    }

    /// Run from the committed state `u0` at `stepping.start` to `stepping.end`, calling
    /// `progress` after every converged (and committed) step.
    pub fn run_with_progress<P: NonlinearProblem, F: FnMut(&StepRecord)>(
        &self,
        problem: &mut P,
        pattern: &SparsityPattern,
        solver: &mut LinearSolver,
        u0: &[f64],
        progress: F,
    ) -> Result<NewtonReport, Box<NewtonFailure>> {
        self.run_with_callbacks(problem, pattern, solver, u0, progress, |_| {})
    }

    /// [`NewtonSolver::run_with_progress`], also reporting every [`CriticalPoint`] passed
    /// through `on_critical` (after the `progress` of the step that revealed it): the sign of
    /// the determinant of the tangent factorised in a converged step
    /// ([`LinearSolver::determinant_sign`], the last factorisation of the step's successful
    /// attempt, at or next to the converged state) differs from that of the last converged
    /// step that factorised. The load factor only rises here, so the tangent became singular on
    /// a rising path: a [`CriticalKind::Bifurcation`]. Steps that did not factorise (Krylov
    /// updates with a held factorisation) or whose method gives no sign are skipped: the
    /// bracket then spans them.
    pub fn run_with_callbacks<P, F, C>(
        &self,
        problem: &mut P,
        pattern: &SparsityPattern,
        solver: &mut LinearSolver,
        u0: &[f64],
        mut progress: F,
        mut on_critical: C,
    ) -> Result<NewtonReport, Box<NewtonFailure>>
    where
        P: NonlinearProblem,
        F: FnMut(&StepRecord),
        C: FnMut(&CriticalPoint),
    {
        let st = &self.stepping;
        let n = problem.n_dofs();
        let mut report = NewtonReport {
            u: u0.to_vec(),
            load: st.start,
            attempts: Vec::new(),
        };
        let fail = |report: NewtonReport, load: f64, step: f64, reason, res: Vec<f64>| {
            Box::new(NewtonFailure {
                converged_load: report.load,
                attempted_load: load,
                step_size: step,
                reason,
                last_residuals: res,
                report,
            })
        };
        let setup = if u0.len() != n || pattern.n_dofs() != n || solver.n_dofs() != n {
            Some(format!(
                "sizes differ: problem {n}, u0 {}, pattern {}, solver {}",
                u0.len(),
                pattern.n_dofs(),
                solver.n_dofs()
            ))
        } else if !(st.end >= st.start
            && st.min_step > 0.0
            && st.initial_step >= st.min_step
            && st.max_step >= st.min_step
            && st.cut_factor > 0.0
            && st.cut_factor < 1.0
            && st.grow_factor >= 1.0)
        {
            Some(format!("invalid load stepping {st:?}"))
        } else {
            stops_error(st)
        };
        if let Some(msg) = setup {
            return Err(fail(
                report,
                st.start,
                0.0,
                FailureReason::Setup(msg),
                vec![],
            ));
        }
        let mut work = Work {
            r: vec![0.0; n],
            s: vec![0.0; 4 * n],
            rhs: vec![0.0; n],
            du: vec![0.0; n],
            values: vec![0.0; pattern.nnz()],
            g: Vec::new(),
            base: vec![0.0; n],
            dir: vec![0.0; n],
            updates: self.options.linear_updates.resolve(solver),
            held: Held {
                cost: solver.refactorisation_cost(),
                ..Held::default()
            },
        };
        let mut step = st.initial_step.min(st.max_step);
        let mut n_converged = 0;
        // The last two converged increments and their load steps (most recent first), for the
        // secant and quadratic predictors.
        let mut last: Option<(Vec<f64>, f64)> = None;
        let mut before_last: Option<(Vec<f64>, f64)> = None;
        let scale = st.end.abs().max(st.start.abs()).max(1.0);
        // Converged step, load factor and determinant sign of the last converged step that
        // factorised a tangent with a known sign.
        let mut last_sign: Option<(usize, f64, f64)> = None;
        while st.end - report.load > 1e-12 * scale {
            if report.attempts.len() >= st.max_attempts {
                let reason = FailureReason::TooManyAttempts(st.max_attempts);
                let load = report.load;
                return Err(fail(report, load, step, reason, vec![]));
            }
            // The next level to land on: the first stop beyond the committed load, else the
            // end. A step reaching it (to round-off of the step) is clipped to it exactly.
            let stop = st
                .stops
                .iter()
                .copied()
                .find(|&s| s - report.load > 1e-12 * scale)
                .unwrap_or(st.end);
            let remaining = stop - report.load;
            let reach = remaining <= step * (1.0 + 1e-9);
            // Shorter than the step size by more than round-off.
            let clipped = reach && remaining < step * (1.0 - 1e-9);
            let (dl, target) = if reach {
                (remaining, stop)
            } else {
                (step, report.load + step)
            };
            let mut u = report.u.clone();
            let predictor = match (st.predictor, &last, &before_last) {
                (Predictor::Quadratic, Some((d1, h1)), Some((d2, h2))) => {
                    let (h1, h2) = (*h1, *h2);
                    let c = dl * (dl + h1) / (h1 + h2);
                    for ((x, a), b) in u.iter_mut().zip(d1).zip(d2) {
                        let (s1, s2) = (a / h1, b / h2);
                        *x += dl * s1 + c * (s1 - s2);
                    }
                    Predictor::Quadratic
                }
                (Predictor::Secant | Predictor::Quadratic, Some((du, dl_prev)), _) => {
                    let ratio = dl / dl_prev;
                    for (x, d) in u.iter_mut().zip(du) {
                        *x += ratio * d;
                    }
                    Predictor::Secant
                }
                _ => Predictor::Zero,
            };
            let mut rec = StepRecord::new(report.load, target, dl, predictor);
            let factorisations = solver.n_factorizations();
            let start = (st.stop_failure == StopFailure::Continuation && reach).then(|| u.clone());
            let mut outcome = self.attempt(
                problem, pattern, solver, &report.u, &mut u, target, &mut rec, &mut work,
            );
            if let (Some(start), Err(first)) = (start, &outcome) {
                if first.retryable() {
                    let first = first.clone();
                    problem.restore();
                    let u_n = report.u.clone();
                    outcome = self.continuation(
                        problem,
                        pattern,
                        solver,
                        (&u_n, report.load),
                        &start,
                        (&mut u, target),
                        first,
                        &mut rec,
                        &mut work,
                        &mut report.attempts,
                    );
                }
            }
            match outcome {
                Ok((bc, acceptance, factorised_at)) => {
                    rec.converged = true;
                    rec.acceptance = Some(acceptance);
                    rec.factorised_at = Some(factorised_at);
                    let assembled = factorised_at == FactorisedAt::PreviousIterate
                        && problem.converged_tangent() == ConvergedTangent::Assembled;
                    let hook = problem.on_converged(&ConvergedStep {
                        step: n_converged,
                        load: target,
                        u: &u,
                        record: &rec,
                        solver,
                        factorised_at,
                        essential: &bc,
                        tangent: assembled.then_some((pattern, work.values.as_slice())),
                    });
                    if let Err(e) = hook {
                        problem.restore();
                        rec.converged = false;
                        let reason = FailureReason::Problem(ProblemError::Failed(Failure::new(
                            "on_converged",
                            e,
                        )));
                        rec.failure = Some(reason.clone());
                        let res = rec.residual_norms.clone();
                        report.attempts.push(rec);
                        return Err(fail(report, target, dl, reason, res));
                    }
                    problem.commit(&u, target);
                    let sign = (solver.n_factorizations() > factorisations)
                        .then(|| solver.determinant_sign())
                        .flatten();
                    n_converged += 1;
                    let du = u.iter().zip(&report.u).map(|(a, b)| a - b).collect();
                    before_last = last.replace((du, dl));
                    report.u = u;
                    report.load = target;
                    progress(&rec);
                    if let Some(d) = sign.filter(|d| *d != 0.0) {
                        if let Some((step0, load0, d0)) = last_sign.filter(|l| l.2 != d) {
                            on_critical(&CriticalPoint {
                                before_step: step0,
                                after_step: n_converged - 1,
                                loads: [load0, target],
                                stiffness: None,
                                determinant_sign: [Some(d0), Some(d)],
                                kind: CriticalKind::Bifurcation,
                            });
                        }
                        last_sign = Some((n_converged - 1, target, d));
                    }
                    // A clipped step keeps the unclipped size for the next one.
                    if !clipped && rec.iterations <= st.easy_iterations {
                        step = (step * st.grow_factor).min(st.max_step);
                    }
                    report.attempts.push(rec);
                }
                Err(reason) => {
                    problem.restore();
                    let reason = reason.with_unknown_named(|d| problem.describe_unknown(d));
                    rec.failure = Some(reason.clone());
                    let res = rec.residual_norms.clone();
                    report.attempts.push(rec);
                    let cut = dl * st.cut_factor;
                    if !reason.retryable() || cut < st.min_step {
                        return Err(fail(report, target, dl, reason, res));
                    }
                    step = cut;
                }
            }
        }
        Ok(report)
    }

    /// One step attempt; on success returns the essential conditions eliminated in `solver` and
    /// the test that accepted the iterate.
    #[allow(clippy::too_many_arguments)]
    fn attempt<P: NonlinearProblem>(
        &self,
        problem: &mut P,
        pattern: &SparsityPattern,
        solver: &mut LinearSolver,
        u_n: &[f64],
        u: &mut [f64],
        load: f64,
        rec: &mut StepRecord,
        w: &mut Work,
    ) -> Result<(EssentialBc, Acceptance, FactorisedAt), FailureReason> {
        let o = self.options;
        let policy = problem.converged_tangent();
        let residual_first = policy != ConvergedTangent::Required;
        w.held.begin_attempt(rec.step_size);
        // Residual and tangent already evaluated at `u` by the residual-first test
        // (`ConvergedTangent::Assembled`), which did not accept the iterate.
        let mut evaluated_here = false;
        let mut unknowns_terms = 0.0;
        // Whether the solver holds the factorisation of an iterate of this attempt.
        let mut held_in_step = false;
        let bc = EssentialBc::new(u.len(), &problem.essential(load))
            .map_err(|e| FailureReason::Setup(e.to_string()))?;
        let mut predicted = rec.predictor != Predictor::Zero;
        let mut r_ref = 0.0;
        let mut e0 = 0.0;
        let mut r_prev = f64::INFINITY;
        let mut r_prev2 = f64::INFINITY;
        // Line search (`LineSearch::OnFailure`): the update that led to `u` (at k = 0 the
        // predictor's increment) and the lengths tried for the current iterate.
        let line_search = o.line_search == LineSearch::OnFailure;
        if line_search {
            w.base.copy_from_slice(u_n);
            for ((d, a), b) in w.dir.iter_mut().zip(&*u).zip(u_n) {
                *d = a - b;
            }
        }
        let mut tries = 0;
        let mut k = 0;
        let mut counted_at = None;
        loop {
            // The active set's count before this iterate's evaluations: a change shows against
            // the previous iterate's (or, at k = 0, the last state evaluated).
            let active_before = problem.active_set_changes();
            let marks = (
                rec.residual_norms.len(),
                rec.roundoff_floors.len(),
                rec.energy_norms.len(),
                rec.krylov.len(),
            );
            // An unusable iterate: backtrack along its update (`LineSearch::OnFailure`), or
            // fail the attempt.
            macro_rules! reject {
                ($reason:expr) => {{
                    let reason: FailureReason = $reason;
                    let lengths = BACKTRACK_LENGTHS.len() + usize::from(k == 0);
                    let usable = line_search
                        && reason.backtrackable()
                        && tries < lengths
                        && rec.backtracks.len() < BACKTRACK_BUDGET
                        && w.dir.iter().any(|&d| d != 0.0);
                    if !usable {
                        return Err(reason);
                    }
                    let length = BACKTRACK_LENGTHS.get(tries).copied().unwrap_or(0.0);
                    tries += 1;
                    for ((x, b), d) in u.iter_mut().zip(&w.base).zip(&w.dir) {
                        *x = b + length * d;
                    }
                    if length == 0.0 {
                        // The committed unknowns: the zero predictor.
                        rec.predictor = Predictor::Zero;
                        predicted = false;
                    }
                    rec.residual_norms.truncate(marks.0);
                    rec.roundoff_floors.truncate(marks.1);
                    rec.energy_norms.truncate(marks.2);
                    rec.krylov.truncate(marks.3);
                    rec.backtracks.push(Backtrack {
                        iteration: k,
                        length,
                        reason,
                    });
                    continue;
                }};
            }
            // Residual-first acceptance: when the last two residuals predict convergence under
            // quadratic contraction, try the residual alone and test it with the previous
            // iterate's factorisation (module documentation). Not after a backtrack: the
            // buffers then hold the rejected iterate's tangent.
            if residual_first && k >= 2 && tries == 0 {
                let predicted_next = r_prev.powi(3) / (r_prev2 * r_prev2);
                let tol = (o.residual_rtol * r_ref).max(o.residual_atol);
                if predicted_next.is_finite() && predicted_next <= 100.0 * tol {
                    let tried = self.residual_only(
                        problem,
                        pattern,
                        solver,
                        (u, load),
                        &bc,
                        (r_ref, e0, unknowns_terms),
                        (policy == ConvergedTangent::Assembled).then_some(&mut evaluated_here),
                        rec,
                        w,
                    );
                    match tried {
                        Ok(Some(how)) => return Ok((bc, how, FactorisedAt::PreviousIterate)),
                        Ok(None) => {}
                        // The full evaluation below meets the same failure and backtracks.
                        Err(e) if line_search && e.backtrackable() => {}
                        Err(e) => return Err(e),
                    }
                }
            }
            let evaluated = if std::mem::take(&mut evaluated_here) {
                Ok(())
            } else {
                let clock = Instant::now();
                let evaluated = problem.residual_and_tangent(u, load, &mut w.r, &mut w.values);
                rec.timing.residual_and_tangent_s += clock.elapsed().as_secs_f64();
                evaluated
            };
            // An iterate that changed the active set, counted once per k (also when its
            // evaluation fails: the failures of an attempt that switches are reported so).
            if k >= 1 && counted_at != Some(k) && problem.active_set_changes() != active_before {
                counted_at = Some(k);
                rec.active_set_iterations += 1;
            }
            if let Err(e) = evaluated {
                reject!(FailureReason::Problem(e));
            }
            unknowns_terms = unknowns_term_scale(pattern, &w.values, u, u_n, &bc, &mut w.s);
            bc.increments_into(u, &mut w.g);
            for (x, r) in w.rhs.iter_mut().zip(&w.r) {
                *x = -r;
            }
            if let Err(e) = bc.apply_with(pattern, &mut w.values, &mut w.rhs, &w.g) {
                reject!(FailureReason::LinearSolver(e));
            }
            let rnorm = free_dot(&bc, &w.rhs, &w.rhs).sqrt();
            rec.residual_norms.push(rnorm);
            if !rnorm.is_finite() {
                reject!(FailureReason::NonFiniteResidual);
            }
            if k == 0 {
                let f = problem.force_norm(load);
                r_ref = if predicted && f > 0.0 {
                    f
                } else {
                    rnorm.max(f)
                };
            } else if r_ref > 0.0 && rnorm > o.divergence_factor * r_ref {
                reject!(FailureReason::Diverged {
                    ratio: rnorm / r_ref,
                });
            }
            let constraints_met = w.g.iter().all(|&x| x == 0.0);
            let res_ok = constraints_met && rnorm <= (o.residual_rtol * r_ref).max(o.residual_atol);
            let floor = o.roundoff_factor
                * f64::EPSILON
                * r_ref.max(problem.residual_scale()).max(unknowns_terms);
            rec.roundoff_floors.push(floor);
            let floor_ok = constraints_met && rnorm <= floor;
            let krylov = match w.updates {
                LinearUpdates::KrylovNearConvergence => {
                    held_in_step && k >= 1 && constraints_met && rnorm <= 1e-2 * r_ref
                }
                LinearUpdates::KrylovHeld => {
                    let usable = w.held.valid && !w.held.stale && solver.is_factorized();
                    if usable && w.held.predicts_giving_up(k) {
                        w.held.gave_up(k);
                        rec.krylov_skipped.push(k);
                        false
                    } else {
                        usable
                    }
                }
                LinearUpdates::Direct | LinearUpdates::Auto => false,
            };
            let mut factorised_here = false;
            // Accept the iterate (`how`): the factorisation the problem's hooks see is the one
            // `accepted_at` settles.
            macro_rules! accept {
                ($how:expr) => {{
                    let at = accepted_at(
                        factorised_here,
                        residual_first,
                        solver,
                        &w.values,
                        rec,
                        &mut w.held,
                    )?;
                    return Ok((bc, $how, at));
                }};
            }
            if !krylov {
                if let Err(e) = factorise_held(solver, &w.values, rec, &mut w.held) {
                    reject!(e);
                }
                held_in_step = true;
                factorised_here = true;
            }
            if floor_ok {
                // At the floor the energy product is round-off too: the residual decides.
                let how = if res_ok {
                    Acceptance::Tolerance
                } else {
                    Acceptance::RoundoffFloor
                };
                accept!(how);
            }
            if res_ok && k == 0 {
                return Ok((bc, Acceptance::Tolerance, FactorisedAt::Converged));
            }
            let clock = Instant::now();
            let iterative = match (krylov, w.updates) {
                (false, _) => Ok(None),
                (true, LinearUpdates::KrylovHeld) => gmres_to(
                    pattern,
                    &w.values,
                    solver,
                    &w.rhs,
                    &mut w.du,
                    HELD_RTOL * rnorm.max(r_ref),
                    w.held.budget(),
                    true,
                ),
                (true, _) => gmres(pattern, &w.values, solver, &w.rhs, &mut w.du, 1e-12, 20),
            };
            rec.timing.solve_s += clock.elapsed().as_secs_f64();
            let iterative = match iterative {
                Ok(i) => i,
                Err(e) => reject!(FailureReason::LinearSolver(e)),
            };
            match iterative {
                Some(info) => {
                    rec.krylov.push((k, info.iterations));
                    w.held.krylov_solve(info.iterations);
                }
                None => {
                    if krylov {
                        w.held.gave_up(k);
                        rec.krylov_gave_up.push(k);
                    }
                    if !factorised_here {
                        if let Err(e) = factorise_held(solver, &w.values, rec, &mut w.held) {
                            reject!(e);
                        }
                        factorised_here = true;
                    }
                    w.held.direct_solve();
                    w.du.copy_from_slice(&w.rhs);
                    let clock = Instant::now();
                    let solved = solver.solve_in_place(&mut w.du);
                    rec.timing.solve_s += clock.elapsed().as_secs_f64();
                    if let Err(e) = solved {
                        reject!(FailureReason::LinearSolver(e));
                    }
                }
            }
            let e = free_dot(&bc, &w.du, &w.rhs).abs();
            rec.energy_norms.push(e);
            if k == 0 {
                // After a prediction, |Δu_0ᵀ r_0| measures the predictor's error; scaled to the
                // force level (the energy is quadratic in the residual) it is the reference.
                e0 = if predicted && rnorm > r_ref {
                    e * (r_ref / rnorm).powi(2)
                } else {
                    e
                };
            }
            let energy_ok = e <= (o.energy_rtol * e0).max(o.energy_atol);
            if res_ok && energy_ok {
                accept!(Acceptance::Tolerance);
            }
            // The residual tests come before the energy's divergence test: a residual at the
            // round-off of its reference is converged whatever `Δu_kᵀ r_k` says (near a
            // singular tangent the update of a round-off residual is large, and the energy
            // product with it).
            if k >= 1 && res_ok && rnorm <= ROUNDOFF_BAND * f64::EPSILON * r_ref {
                accept!(Acceptance::ResidualRoundoff);
            }
            if k >= 1 && !res_ok && e0 > 0.0 && e > o.divergence_factor * e0 {
                reject!(FailureReason::Diverged { ratio: e / e0 });
            }
            // Two consecutive iterations without progress: round-off, not a slow approach.
            let stalled = |a: f64, b: f64| a >= o.stagnation_ratio * b;
            let stagnated = k >= 2
                && constraints_met
                && energy_ok
                && o.stagnation_ratio > 0.0
                && stalled(rnorm, r_prev)
                && stalled(r_prev, r_prev2)
                && rnorm <= o.residual_rtol.sqrt() * r_ref;
            if stagnated {
                accept!(Acceptance::Stagnation);
            }
            iteration_limits(&o, rec, k)?;
            if line_search {
                w.base.copy_from_slice(u);
                w.dir.copy_from_slice(&w.du);
            }
            for (x, d) in u.iter_mut().zip(&w.du) {
                *x += d;
            }
            for (&d, &v) in bc.dofs().iter().zip(bc.values()) {
                u[d] = v;
            }
            rec.iterations = k + 1;
            r_prev2 = r_prev;
            r_prev = rnorm;
            k += 1;
            tries = 0;
        }
    }
}

impl NewtonSolver {
    /// [`StopFailure::Continuation`]: the attempt at the stop `target` from the committed
    /// `(u_n, l_n)`, started at `start`, failed with `first` (its record in `rec`). Halve the
    /// level towards the last intermediate solution (first the committed state) until an
    /// attempt converges there, then try the stop again from that solution extrapolated along
    /// the secant from `u_n`; every attempt evaluates from the committed history. On return
    /// `rec` holds the last attempt at the stop (converged, with its intermediate levels, or
    /// failed) and `u` its unknowns; the failed attempts before it are appended to `failed`.
    #[allow(clippy::too_many_arguments)]
    fn continuation<P: NonlinearProblem>(
        &self,
        problem: &mut P,
        pattern: &SparsityPattern,
        solver: &mut LinearSolver,
        (u_n, l_n): (&[f64], f64),
        start: &[f64],
        (u, target): (&mut [f64], f64),
        first: FailureReason,
        rec: &mut StepRecord,
        w: &mut Work,
        failed: &mut Vec<StepRecord>,
    ) -> Result<(EssentialBc, Acceptance, FactorisedAt), FailureReason> {
        let st = &self.stepping;
        let fresh =
            |load: f64, predictor: Predictor| StepRecord::new(l_n, load, load - l_n, predictor);
        let predictor = rec.predictor;
        rec.failure = Some(first);
        // Where the copy of the failed attempt at the stop in `rec` went in `failed` (the
        // attempts are listed in the order they were made).
        failed.push(rec.clone());
        let mut rec_at = Some(failed.len() - 1);
        // The last solution `(from_u, from_l)` (first the committed state) and the increment of
        // the unknowns per unit load along which the next start is extrapolated.
        let mut from_u = u_n.to_vec();
        let mut from_l = l_n;
        let mut rate: Vec<f64> = start
            .iter()
            .zip(u_n)
            .map(|(a, b)| (a - b) / (target - l_n))
            .collect();
        let mut levels = Vec::new();
        let mut sub = target;
        let starting = |from_u: &[f64], from_l: f64, rate: &[f64], load: f64, x: &mut [f64]| {
            for ((x, a), r) in x.iter_mut().zip(from_u).zip(rate) {
                *x = a + (load - from_l) * r;
            }
        };
        loop {
            sub = from_l + st.cut_factor * (sub - from_l);
            if sub - from_l < st.min_step {
                // `rec` holds the last attempt at the stop, failed (the caller lists it).
                if let Some(i) = rec_at {
                    failed.remove(i);
                }
                return Err(rec.failure.clone().expect("a failed attempt"));
            }
            let mut attempt = fresh(sub, predictor);
            attempt.continuation.clone_from(&levels);
            let mut v = vec![0.0; u.len()];
            starting(&from_u, from_l, &rate, sub, &mut v);
            match self.attempt(problem, pattern, solver, u_n, &mut v, sub, &mut attempt, w) {
                Ok(_) => {
                    problem.restore();
                    for ((r, a), b) in rate.iter_mut().zip(&v).zip(u_n) {
                        *r = (a - b) / (sub - l_n);
                    }
                    from_u = v;
                    from_l = sub;
                    levels.push(sub);
                    *rec = fresh(target, predictor);
                    rec.continuation.clone_from(&levels);
                    starting(&from_u, from_l, &rate, target, u);
                    match self.attempt(problem, pattern, solver, u_n, u, target, rec, w) {
                        Ok(done) => return Ok(done),
                        Err(e) if e.retryable() => {
                            problem.restore();
                            rec.failure = Some(e);
                            failed.push(rec.clone());
                            rec_at = Some(failed.len() - 1);
                            sub = target;
                        }
                        Err(e) => return Err(e),
                    }
                }
                Err(e) if e.retryable() => {
                    problem.restore();
                    attempt.failure = Some(e);
                    failed.push(attempt);
                }
                Err(e) => {
                    // Not retryable: the run stops with this attempt as its last.
                    if let Some(i) = rec_at {
                        failed.remove(i);
                    }
                    *rec = attempt;
                    rec.failure = Some(e.clone());
                    return Err(e);
                }
            }
        }
    }

    /// One residual-only evaluation at `u` tested with the factorisation of the previous
    /// iterate: accepted by the tolerances (residual, and energy with `Δu = K_prev⁻¹ r`) or the
    /// round-off floor (with the previous `S`). `None`: not accepted, or the essential
    /// conditions are not met; the caller then evaluates residual and tangent as usual.
    ///
    /// With `tangent` (`ConvergedTangent::Assembled`) the residual and the tangent are
    /// evaluated together, the tangent's essential conditions eliminated where the residual
    /// passes, and `*tangent` is set when they were evaluated (the caller then does not evaluate
    /// them again at `u` if the iterate is not accepted).
    #[allow(clippy::too_many_arguments)]
    fn residual_only<P: NonlinearProblem>(
        &self,
        problem: &mut P,
        pattern: &SparsityPattern,
        solver: &mut LinearSolver,
        (u, load): (&[f64], f64),
        bc: &EssentialBc,
        (r_ref, e0, unknowns_terms): (f64, f64, f64),
        tangent: Option<&mut bool>,
        rec: &mut StepRecord,
        w: &mut Work,
    ) -> Result<Option<Acceptance>, FailureReason> {
        let o = self.options;
        if bc.dofs().iter().zip(bc.values()).any(|(&d, &v)| v != u[d]) {
            return Ok(None);
        }
        let clock = Instant::now();
        let with_tangent = tangent.is_some();
        if let Some(flag) = tangent {
            let evaluated = problem.residual_and_tangent(u, load, &mut w.r, &mut w.values);
            rec.timing.residual_and_tangent_s += clock.elapsed().as_secs_f64();
            evaluated.map_err(FailureReason::Problem)?;
            *flag = true;
        } else {
            let evaluated = problem.residual(u, load, &mut w.r);
            rec.timing.residual_s += clock.elapsed().as_secs_f64();
            evaluated.map_err(FailureReason::Problem)?;
        }
        for (x, r) in w.rhs.iter_mut().zip(&w.r) {
            *x = -r;
        }
        bc.zero_constrained(&mut w.rhs);
        let rnorm = free_dot(bc, &w.rhs, &w.rhs).sqrt();
        let k = rec.residual_norms.len();
        rec.residual_only.push((k, rnorm));
        if !rnorm.is_finite() || rnorm > (o.residual_rtol * r_ref).max(o.residual_atol) {
            return Ok(None);
        }
        if with_tangent {
            // The conditions hold at `u` (checked above): the increments are zero and the
            // elimination leaves the right-hand side as it is.
            bc.increments_into(u, &mut w.g);
            bc.apply_with(pattern, &mut w.values, &mut w.rhs, &w.g)
                .map_err(FailureReason::LinearSolver)?;
        }
        let floor = o.roundoff_factor
            * f64::EPSILON
            * r_ref.max(problem.residual_scale()).max(unknowns_terms);
        let clock = Instant::now();
        if w.updates == LinearUpdates::KrylovHeld {
            // `values` still holds the previous iterate's eliminated tangent; the solver may
            // hold an older one.
            let solved = gmres_to(
                pattern,
                &w.values,
                solver,
                &w.rhs,
                &mut w.du,
                HELD_RTOL * rnorm.max(r_ref),
                w.held.budget(),
                true,
            );
            rec.timing.solve_s += clock.elapsed().as_secs_f64();
            match solved.map_err(FailureReason::LinearSolver)? {
                Some(info) => w.held.krylov_solve(info.iterations),
                None => return Ok(None),
            }
        } else {
            w.du.copy_from_slice(&w.rhs);
            let solved = solver.solve_in_place(&mut w.du);
            rec.timing.solve_s += clock.elapsed().as_secs_f64();
            solved.map_err(FailureReason::LinearSolver)?;
        }
        let e = free_dot(bc, &w.du, &w.rhs).abs();
        // As in the full path: the residual tolerance holds, and either the energy test, the
        // round-off floor (where the energy product is round-off too) or the residual at the
        // round-off of its reference.
        if e > (o.energy_rtol * e0).max(o.energy_atol)
            && rnorm > floor
            && rnorm > ROUNDOFF_BAND * f64::EPSILON * r_ref
        {
            return Ok(None);
        }
        rec.residual_norms.push(rnorm);
        rec.roundoff_floors.push(floor);
        rec.energy_norms.push(e);
        Ok(Some(Acceptance::Tolerance))
    }
}

/// The tangent the solver holds for an accepted iterate: factorised there, or (after an
/// iterative update) an earlier iterate's when the problem allows it, else factorised now.
fn accepted_at(
    factorised_here: bool,
    residual_first: bool,
    solver: &mut LinearSolver,
    values: &[f64],
    rec: &mut StepRecord,
    held: &mut Held,
) -> Result<FactorisedAt, FailureReason> {
    if factorised_here {
        Ok(FactorisedAt::Converged)
    } else if residual_first {
        Ok(FactorisedAt::PreviousIterate)
    } else {
        factorise_held(solver, values, rec, held)?;
        Ok(FactorisedAt::Converged)
    }
}

/// [`factorise`], recording the fresh factors in `held` (invalid after a failure).
fn factorise_held(
    solver: &mut LinearSolver,
    values: &[f64],
    rec: &mut StepRecord,
    held: &mut Held,
) -> Result<(), FailureReason> {
    held.valid = false;
    factorise(solver, values, rec)?;
    held.refreshed();
    Ok(())
}

/// Numeric factorisation of the tangent, timed into `rec`.
fn factorise(
    solver: &mut LinearSolver,
    values: &[f64],
    rec: &mut StepRecord,
) -> Result<(), FailureReason> {
    let clock = Instant::now();
    let factorised = solver.factorize(values);
    rec.timing.factorise_s += clock.elapsed().as_secs_f64();
    factorised.map_err(FailureReason::LinearSolver)
}

/// Why `st.stops` is invalid (strictly ascending, finite, within `(start, end]`), if it is.
fn stops_error(st: &LoadStepping) -> Option<String> {
    let mut prev = st.start;
    for (k, &s) in st.stops.iter().enumerate() {
        if !(s.is_finite() && s > prev && s <= st.end) {
            return Some(format!(
                "stops[{k}] = {s}: the stops must be finite, strictly ascending and within \
                 (start, end] = ({}, {}]",
                st.start, st.end
            ));
        }
        prev = s;
    }
    None
}

/// `max(‖ |K| |u| ‖, ‖ |K| |u − u_n| ‖)` over the free rows (the raw tangent, before
/// elimination): the change of the residual when the unknowns (or their increment in the step)
/// are perturbed by their own round-off, divided by `ε`. Both products in one pass over the
/// matrix ([`csc_abs_mul_columns`]); `s` is scratch of length `4 n`.
fn unknowns_term_scale(
    pattern: &SparsityPattern,
    values: &[f64],
    u: &[f64],
    u_n: &[f64],
    bc: &EssentialBc,
    s: &mut [f64],
) -> f64 {
    let n = u.len();
    let (x, y) = s[..4 * n].split_at_mut(2 * n);
    for (j, (a, b)) in u.iter().zip(u_n).enumerate() {
        x[j] = a.abs();
        x[n + j] = (a - b).abs();
    }
    csc_abs_mul_columns(pattern, values, x, 2, y);
    let norm = |col: &[f64]| {
        col.iter()
            .enumerate()
            .filter(|(i, _)| !bc.is_constrained(*i))
            .map(|(_, v)| v * v)
            .sum::<f64>()
            .sqrt()
    };
    norm(&y[..n]).max(norm(&y[n..]))
}

fn free_dot(bc: &EssentialBc, a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .enumerate()
        .filter(|(i, _)| !bc.is_constrained(*i))
        .map(|(_, (x, y))| x * y)
        .sum()
}

// ---------------------------------------------------------------------------------------------
// Arc-length continuation.

/// Settings of [`NewtonSolver::run_arc_length`]: Crisfield's cylindrical arc length, the load
/// factor an unknown of every step.
#[derive(Debug, Clone, PartialEq)]
pub struct ArcLength {
    /// Initial load factor (the problem's committed state must be at this level).
    pub start: f64,
    /// The run ends at the first converged step with `λ ≥ end` (`end > start`).
    pub end: f64,
    /// Arc length `Δs` of the first step (in the norm of the path unknowns,
    /// [`NonlinearProblem::path_dofs`]).
    pub initial_length: f64,
    /// Smallest arc length tried before giving up.
    pub min_length: f64,
    /// Largest arc length.
    pub max_length: f64,
    /// Factor applied to `Δs` after a failed step, in (0, 1).
    pub cut_factor: f64,
    /// Factor applied to `Δs` after an easy step, ≥ 1.
    pub grow_factor: f64,
    /// A step converging in at most this many iterations is easy.
    pub easy_iterations: usize,
    /// Largest number of step attempts (converged or not).
    pub max_attempts: usize,
}

impl Default for ArcLength {
    fn default() -> Self {
        ArcLength {
            start: 0.0,
            end: 1.0,
            initial_length: 0.1,
            min_length: 1e-6,
            max_length: 1.0,
            cut_factor: 0.5,
            grow_factor: 1.5,
            easy_iterations: 4,
            max_attempts: 10_000,
        }
    }
}

/// What kind of point a [`CriticalPoint`] is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CriticalKind {
    /// A limit point with the load factor at a maximum (it rose, then fell): `q·K⁻¹q` and the
    /// sign of `dλ/ds` changed, from rising.
    LoadMaximum,
    /// A limit point with the load factor at a minimum (it had been falling).
    LoadMinimum,
    /// The tangent became singular while the load factor kept its direction: the
    /// determinant's sign changed, the current stiffness parameter's did not.
    Bifurcation,
    /// A turning point of the displacement work-conjugate to the load, `qᵀu` (a snap-back: the
    /// deflection under a point load turns back while the load factor keeps its direction):
    /// `q·K⁻¹q = qᵀ du/dλ` passed through zero and `dλ/ds` kept its sign, so the tangent is
    /// regular there. Not a critical point of the tangent; reported with them because a load
    /// factor alone does not locate it on the path.
    SnapBack,
}

impl CriticalKind {
    /// The name written to results.json and printed: `"limit point (load maximum)"`,
    /// `"limit point (load minimum)"`, `"bifurcation"` or
    /// `"snap-back (turning point of the displacement)"`.
    pub fn label(self) -> &'static str {
        match self {
            CriticalKind::LoadMaximum => "limit point (load maximum)",
            CriticalKind::LoadMinimum => "limit point (load minimum)",
            CriticalKind::Bifurcation => "bifurcation",
            CriticalKind::SnapBack => "snap-back (turning point of the displacement)",
        }
    }
}

/// A converged arc-length step ([`NewtonSolver::run_arc_length`]).
struct ArcStep {
    /// The unknowns.
    u: Vec<f64>,
    /// The load factor.
    load: f64,
    /// `q·K⁻¹q` at the step's start and end.
    stiffness: [f64; 2],
    /// Whether the load factor rises along the path (`dλ/ds > 0`, the path oriented by the
    /// previous increment at the start and by this one at the end) at the start and the end.
    rising: [bool; 2],
}

/// A critical point passed between two converged steps, where the tangent `K` became singular:
/// - a **limit point** of the load factor (arc-length paths): the current stiffness parameter
///   `q·K⁻¹q` (`q = −∂r/∂λ`) changed sign through a pole, `det K` passing through zero with
///   the load factor at an extremum (`dλ/ds`, read at both steps as `Δuᵀ K⁻¹q` along the
///   path's increments, changed sign);
/// - a **bifurcation**: the sign of `det K` ([`LinearSolver::determinant_sign`]) changed and
///   that of `q·K⁻¹q` did not (arc length), or changed at all under load or displacement
///   control (the load factor only rises there);
/// - with them, a **snap-back** (arc length): `q·K⁻¹q` changed sign through zero, `dλ/ds`
///   kept its sign, `K` stayed regular and `qᵀu` turned back ([`CriticalKind::SnapBack`]).
///
/// The determinant is that of the factorised tangent with the essential conditions eliminated
/// (unit diagonal) and the constraint multipliers' rows included: the `m` multiplier rows of
/// the saddle point contribute the constant factor `(−1)^m`, so only changes are meaningful.
#[derive(Debug, Clone, PartialEq)]
pub struct CriticalPoint {
    /// The converged step (0-based) before the sign change.
    pub before_step: usize,
    /// The converged step after it.
    pub after_step: usize,
    /// Load factors of the two steps.
    pub loads: [f64; 2],
    /// `q·K⁻¹q` at the two steps (arc-length runs; `None` under load or displacement control).
    pub stiffness: Option<[f64; 2]>,
    /// Sign of `det K` at the two steps (`None` where the factorisation gives none).
    pub determinant_sign: [Option<f64>; 2],
    /// Limit point (load maximum or minimum), bifurcation or snap-back.
    pub kind: CriticalKind,
}

impl fmt::Display for CriticalPoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let sign = |d: Option<f64>| match d {
            Some(d) if d > 0.0 => "+",
            Some(d) if d < 0.0 => "−",
            Some(_) => "0",
            None => "?",
        };
        write!(
            f,
            "{} between converged steps {} and {}: λ = {:.6e} → {:.6e}",
            self.kind.label(),
            self.before_step + 1,
            self.after_step + 1,
            self.loads[0],
            self.loads[1],
        )?;
        if let Some([a, b]) = self.stiffness {
            write!(f, ", q·K⁻¹q = {a:.3e} → {b:.3e}")?;
        }
        if self.determinant_sign.iter().any(Option::is_some) {
            write!(
                f,
                ", sign det K = {} → {}",
                sign(self.determinant_sign[0]),
                sign(self.determinant_sign[1])
            )?;
        }
        Ok(())
    }
}

/// The result of an arc-length run: the steps and the critical points passed.
#[derive(Debug, Clone, PartialEq)]
pub struct ArcLengthReport {
    /// Converged state and every attempt (`load` of a record is its converged λ).
    pub report: NewtonReport,
    /// Limit points and bifurcations detected, in path order.
    pub critical: Vec<CriticalPoint>,
}

impl NewtonSolver {
    /// Arc-length continuation from the committed state `u0` at `arc.start` until `λ ≥ arc.end`
    /// (Crisfield's cylindrical method, docs/loads.md "Path following"). Every step solves the
    /// bordered system with the one factorised tangent and two right-hand sides,
    /// `K δu_r = −r` and `K δu_q = q` with `q = −∂r/∂λ` ([`NonlinearProblem::load_derivative`]),
    /// and picks `δλ` from `‖Δu + δu_r + δλ δu_q‖² = Δs²` over the path unknowns (the root
    /// closer to the previous increment). The predictor's direction follows the previous
    /// increment (`sign Δλ = sign(Δu_prevᵀ δu_q)`), which passes limit points. Convergence is
    /// the residual tolerance `‖r‖ ≤ max(rtol · force_norm(λ), atol)` or the round-off floor of
    /// [`NewtonSolver::run`]. A step failing (no real root, divergence, too many iterations, a
    /// recoverable problem error, a singular tangent, or a converged point behind the last one:
    /// [`FailureReason::PathReversed`]) is retried with `cut_factor · Δs`; easy
    /// steps grow `Δs` by `grow_factor` up to `max_length`. At every converged step the tangent
    /// there is factorised and `q·K⁻¹q` and the sign of `det K`
    /// ([`LinearSolver::determinant_sign`]) evaluated: a sign change of `q·K⁻¹q` is reported
    /// as a limit point, one of `det K` alone as a bifurcation ([`CriticalPoint`]), through
    /// `on_critical` (the essential conditions must not depend on λ).
    pub fn run_arc_length<P: NonlinearProblem, F: FnMut(&CriticalPoint)>(
        &self,
        problem: &mut P,
        pattern: &SparsityPattern,
        solver: &mut LinearSolver,
        u0: &[f64],
        arc: &ArcLength,
        mut on_critical: F,
    ) -> Result<ArcLengthReport, Box<NewtonFailure>> {
        let n = problem.n_dofs();
        let np = problem.path_dofs().min(n);
        let mut out = ArcLengthReport {
            report: NewtonReport {
                u: u0.to_vec(),
                load: arc.start,
                attempts: Vec::new(),
            },
            critical: Vec::new(),
        };
        let fail = |out: ArcLengthReport, load: f64, step: f64, reason, res: Vec<f64>| {
            Box::new(NewtonFailure {
                converged_load: out.report.load,
                attempted_load: load,
                step_size: step,
                reason,
                last_residuals: res,
                report: out.report,
            })
        };
        let setup = if u0.len() != n || pattern.n_dofs() != n || solver.n_dofs() != n {
            Some(format!(
                "sizes differ: problem {n}, u0 {}, pattern {}, solver {}",
                u0.len(),
                pattern.n_dofs(),
                solver.n_dofs()
            ))
        } else if !(arc.end > arc.start
            && arc.min_length > 0.0
            && arc.initial_length >= arc.min_length
            && arc.max_length >= arc.initial_length
            && arc.cut_factor > 0.0
            && arc.cut_factor < 1.0
            && arc.grow_factor >= 1.0)
        {
            Some(format!("invalid arc-length settings {arc:?}"))
        } else if problem.essential(arc.start) != problem.essential(arc.start + 1.0) {
            Some("arc-length continuation needs essential conditions independent of λ".into())
        } else {
            None
        };
        if let Some(msg) = setup {
            return Err(fail(out, arc.start, 0.0, FailureReason::Setup(msg), vec![]));
        }
        let bc = match EssentialBc::new(n, &problem.essential(arc.start)) {
            Ok(b) => b,
            Err(e) => {
                let r = FailureReason::Setup(e.to_string());
                return Err(fail(out, arc.start, 0.0, r, vec![]));
            }
        };
        let mut w = ArcWork {
            r: vec![0.0; n],
            q: vec![0.0; n],
            du_r: vec![0.0; n],
            du_q: vec![0.0; n],
            values: vec![0.0; pattern.nnz()],
            s: vec![0.0; 4 * n],
        };
        let mut ds = arc.initial_length.min(arc.max_length);
        let mut prev: Option<Vec<f64>> = None;
        // q·K⁻¹q at the last converged state (or the start).
        let mut last_stiffness: Option<f64> = None;
        // Determinant sign of the tangent at the last converged state.
        let mut last_sign: Option<f64> = None;
        let mut n_converged = 0;
        while out.report.load < arc.end {
            if out.report.attempts.len() >= arc.max_attempts {
                let reason = FailureReason::TooManyAttempts(arc.max_attempts);
                let load = out.report.load;
                return Err(fail(out, load, ds, reason, vec![]));
            }
            let u_n = out.report.u.clone();
            let l_n = out.report.load;
            let mut rec = StepRecord::new(l_n, l_n, ds, Predictor::Zero);
            let outcome = self.arc_attempt(
                problem,
                pattern,
                solver,
                &bc,
                &u_n,
                l_n,
                ds,
                np,
                prev.as_deref(),
                &mut rec,
                &mut w,
            );
            // A converged step whose increment turns back against the previous one has
            // found the path behind the last point (the corrector's cylinder meets the path
            // on both sides): taken, the next step's predictor (along the previous
            // increment) would turn back again and the run would shuttle between two points.
            let outcome = match (outcome, prev.as_deref()) {
                (Ok(done), Some(p)) => {
                    let cosine = increment_cosine(&done.u[..np], &u_n[..np], p);
                    if cosine < 0.0 {
                        Err(FailureReason::PathReversed { cosine })
                    } else {
                        Ok(done)
                    }
                }
                (other, _) => other,
            };
            match outcome {
                Ok(ArcStep {
                    u,
                    load,
                    stiffness: [start_stiffness, stiffness],
                    rising,
                }) => {
                    rec.converged = true;
                    rec.load = load;
                    rec.factorised_at = Some(FactorisedAt::Converged);
                    let hook = problem.on_converged(&ConvergedStep {
                        step: n_converged,
                        load,
                        u: &u,
                        record: &rec,
                        solver,
                        factorised_at: FactorisedAt::Converged,
                        essential: &bc,
                        tangent: None,
                    });
                    if let Err(e) = hook {
                        problem.restore();
                        rec.converged = false;
                        let reason = FailureReason::Problem(ProblemError::Failed(Failure::new(
                            "on_converged",
                            e,
                        )));
                        rec.failure = Some(reason.clone());
                        let res = rec.residual_norms.clone();
                        out.report.attempts.push(rec);
                        return Err(fail(out, load, ds, reason, res));
                    }
                    problem.commit(&u, load);
                    // The solver holds the tangent at the converged state (`arc_tangent` of
                    // the accepted iterate).
                    let sign = solver.determinant_sign().filter(|d| *d != 0.0);
                    let before = last_stiffness.unwrap_or(start_stiffness);
                    let sign_changed = matches!((last_sign, sign), (Some(a), Some(b)) if a != b);
                    let kind = if before.signum() != stiffness.signum() {
                        // `q·K⁻¹q = qᵀ(du/ds) / (dλ/ds)` changed sign: through a pole where
                        // `dλ/ds` did (a load extremum), through zero where `qᵀu` turned back.
                        Some(match rising {
                            [true, false] => CriticalKind::LoadMaximum,
                            [false, true] => CriticalKind::LoadMinimum,
                            _ => CriticalKind::SnapBack,
                        })
                    } else {
                        sign_changed.then_some(CriticalKind::Bifurcation)
                    };
                    if let (Some(kind), true) = (kind, n_converged > 0) {
                        let cp = CriticalPoint {
                            before_step: n_converged - 1,
                            after_step: n_converged,
                            loads: [l_n, load],
                            stiffness: Some([before, stiffness]),
                            determinant_sign: [last_sign, sign],
                            kind,
                        };
                        on_critical(&cp);
                        out.critical.push(cp);
                    }
                    last_stiffness = Some(stiffness);
                    last_sign = sign;
                    n_converged += 1;
                    let ds_taken = ds;
                    prev = Some(u[..np].iter().zip(&u_n[..np]).map(|(a, b)| a - b).collect());
                    if rec.iterations <= arc.easy_iterations {
                        ds = (ds * arc.grow_factor).min(arc.max_length);
                    }
                    out.report.u = u;
                    out.report.load = load;
                    out.report.attempts.push(rec);
                    // After the first step: the steps the end still takes at the largest arc
                    // length, if the load advances per arc length as in this step (it does
                    // less on a softening path), against the attempts left.
                    if n_converged == 1 {
                        let rate = (load - l_n).abs() / ds_taken;
                        let steps = (arc.end - load) / (rate * arc.max_length);
                        let left = arc.max_attempts.saturating_sub(out.report.attempts.len());
                        if steps > 4.0 * left as f64 {
                            let reason = FailureReason::ArcLengthTooShort {
                                first_step: load - l_n,
                                arc_length: ds_taken,
                                max_length: arc.max_length,
                                steps,
                                attempts_left: left,
                            };
                            return Err(fail(out, load, ds, reason, vec![]));
                        }
                    }
                }
                Err(reason) => {
                    problem.restore();
                    rec.failure = Some(reason.clone());
                    let res = rec.residual_norms.clone();
                    let load = rec.load;
                    out.report.attempts.push(rec);
                    let cut = ds * arc.cut_factor;
                    if !reason.retryable() || cut < arc.min_length {
                        return Err(fail(out, load, ds, reason, res));
                    }
                    ds = cut;
                }
            }
        }
        Ok(out)
    }

    /// One arc-length step of length `ds` from `(u_n, l_n)`.
    #[allow(clippy::too_many_arguments)]
    fn arc_attempt<P: NonlinearProblem>(
        &self,
        problem: &mut P,
        pattern: &SparsityPattern,
        solver: &mut LinearSolver,
        bc: &EssentialBc,
        u_n: &[f64],
        l_n: f64,
        ds: f64,
        np: usize,
        prev: Option<&[f64]>,
        rec: &mut StepRecord,
        w: &mut ArcWork,
    ) -> Result<ArcStep, FailureReason> {
        let o = self.options;
        let zeros = vec![0.0; bc.dofs().len()];
        let dot = |a: &[f64], b: &[f64]| -> f64 {
            a[..np].iter().zip(&b[..np]).map(|(x, y)| x * y).sum()
        };
        // Predictor: the tangent at the committed state.
        self.arc_tangent(problem, pattern, solver, bc, u_n, l_n, rec, w, &zeros)?;
        let start_stiffness = free_dot(bc, &w.q, &w.du_q);
        let norm_q = dot(&w.du_q, &w.du_q).sqrt();
        if !(norm_q > 0.0 && norm_q.is_finite()) {
            return Err(FailureReason::Setup(
                "arc length: the load derivative moves no path unknown".into(),
            ));
        }
        let sign = match prev {
            Some(p) if dot(p, &w.du_q) < 0.0 => -1.0,
            _ => 1.0,
        };
        let mut dl = sign * ds / norm_q;
        let mut du: Vec<f64> = w.du_q.iter().map(|x| dl * x).collect();
        let mut u: Vec<f64> = u_n.iter().zip(&du).map(|(a, b)| a + b).collect();
        rec.predictor = Predictor::Secant;
        for k in 0.. {
            let active_before = problem.active_set_changes();
            let load = l_n + dl;
            rec.load = load;
            self.arc_tangent(problem, pattern, solver, bc, &u, load, rec, w, &zeros)?;
            let rnorm = free_dot(bc, &w.r, &w.r).sqrt();
            rec.residual_norms.push(rnorm);
            if !rnorm.is_finite() {
                return Err(FailureReason::NonFiniteResidual);
            }
            let r_ref = problem.force_norm(load).max(o.residual_atol);
            let floor = o.roundoff_factor
                * f64::EPSILON
                * r_ref.max(problem.residual_scale()).max(unknowns_term_scale(
                    pattern, &w.values, &u, u_n, bc, &mut w.s,
                ));
            rec.roundoff_floors.push(floor);
            if k >= 1 && (rnorm <= (o.residual_rtol * r_ref).max(o.residual_atol) || rnorm <= floor)
            {
                rec.acceptance = Some(if rnorm <= floor {
                    Acceptance::RoundoffFloor
                } else {
                    Acceptance::Tolerance
                });
                let stiffness = free_dot(bc, &w.q, &w.du_q);
                // `dλ/ds` along the step's direction at its end: the path's tangent is
                // `(K⁻¹q, 1) dλ/ds`, oriented along the increment.
                let rising_end = u[..np]
                    .iter()
                    .zip(&u_n[..np])
                    .zip(&w.du_q[..np])
                    .map(|((a, b), q)| (a - b) * q)
                    .sum::<f64>()
                    > 0.0;
                return Ok(ArcStep {
                    u,
                    load,
                    stiffness: [start_stiffness, stiffness],
                    rising: [sign > 0.0, rising_end],
                });
            }
            let r_scale = r_ref.max(rec.residual_norms[0]);
            if k >= 1 && rnorm > o.divergence_factor * r_scale {
                return Err(FailureReason::Diverged {
                    ratio: rnorm / r_scale,
                });
            }
            if k >= 1 && problem.active_set_changes() != active_before {
                rec.active_set_iterations += 1;
            }
            iteration_limits(&o, rec, k)?;
            // Corrector: Δu + δu_r + δλ δu_q on the cylinder ‖·‖ = Δs.
            let base: Vec<f64> = du.iter().zip(&w.du_r).map(|(a, b)| a + b).collect();
            let a = dot(&w.du_q, &w.du_q);
            let b = 2.0 * dot(&w.du_q, &base);
            let c = dot(&base, &base) - ds * ds;
            let disc = b * b - 4.0 * a * c;
            if disc.is_nan() || disc < 0.0 {
                return Err(FailureReason::Problem(ProblemError::Recoverable(format!(
                    "arc length: no real root of the constraint (discriminant {disc:.3e})"
                ))));
            }
            let sq = disc.sqrt();
            // Roots without cancellation.
            let t = -0.5 * (b + b.signum() * sq);
            let roots = [t / a, if t != 0.0 { c / t } else { t / a }];
            let pick = roots
                .iter()
                .copied()
                .max_by(|x, y| {
                    let score = |s: f64| {
                        base.iter()
                            .zip(&w.du_q)
                            .zip(&du)
                            .take(np)
                            .map(|((bb, q), d)| (bb + s * q) * d)
                            .sum::<f64>()
                    };
                    score(*x).total_cmp(&score(*y))
                })
                .unwrap_or(roots[0]);
            dl += pick;
            for ((d, bb), q) in du.iter_mut().zip(&base).zip(&w.du_q) {
                *d = bb + pick * q;
            }
            for ((x, a0), d) in u.iter_mut().zip(u_n).zip(&du) {
                *x = a0 + d;
            }
            rec.iterations = k + 1;
        }
        unreachable!("the loop returns by max_iterations and max_active_set_iterations")
    }

    /// Residual, tangent and load derivative at `(u, load)`; the tangent factorised with the
    /// essential conditions eliminated; `du_r = −K⁻¹ r`, `du_q = K⁻¹ q` (free DOFs), `r` and
    /// `q` zeroed on the constrained ones.
    #[allow(clippy::too_many_arguments)]
    fn arc_tangent<P: NonlinearProblem>(
        &self,
        problem: &mut P,
        pattern: &SparsityPattern,
        solver: &mut LinearSolver,
        bc: &EssentialBc,
        u: &[f64],
        load: f64,
        rec: &mut StepRecord,
        w: &mut ArcWork,
        zeros: &[f64],
    ) -> Result<(), FailureReason> {
        let clock = Instant::now();
        let evaluated = problem.residual_and_tangent(u, load, &mut w.r, &mut w.values);
        rec.timing.residual_and_tangent_s += clock.elapsed().as_secs_f64();
        evaluated.map_err(FailureReason::Problem)?;
        let have = problem
            .load_derivative(u, load, &mut w.q)
            .map_err(FailureReason::Problem)?;
        if !have {
            return Err(FailureReason::Setup(
                "arc-length continuation needs the problem's load derivative ∂r/∂λ".into(),
            ));
        }
        for x in w.q.iter_mut() {
            *x = -*x;
        }
        for (x, r) in w.du_r.iter_mut().zip(&w.r) {
            *x = -r;
        }
        bc.apply_with(pattern, &mut w.values, &mut w.du_r, zeros)
            .map_err(FailureReason::LinearSolver)?;
        bc.zero_constrained(&mut w.q);
        bc.zero_constrained(&mut w.r);
        factorise(solver, &w.values, rec)?;
        w.du_q.copy_from_slice(&w.q);
        let clock = Instant::now();
        let solved = solver
            .solve_in_place(&mut w.du_r)
            .and_then(|()| solver.solve_in_place(&mut w.du_q));
        rec.timing.solve_s += clock.elapsed().as_secs_f64();
        solved.map_err(FailureReason::LinearSolver)
    }
}

/// Cosine of the angle between the increment `u − u_n` and `prev`; 1 where either is zero.
fn increment_cosine(u: &[f64], u_n: &[f64], prev: &[f64]) -> f64 {
    let (mut d, mut a, mut b) = (0.0, 0.0, 0.0);
    for ((x, x0), p) in u.iter().zip(u_n).zip(prev) {
        let du = x - x0;
        d += du * p;
        a += du * du;
        b += p * p;
    }
    if a > 0.0 && b > 0.0 {
        d / (a.sqrt() * b.sqrt())
    } else {
        1.0
    }
}

struct ArcWork {
    r: Vec<f64>,
    q: Vec<f64>,
    du_r: Vec<f64>,
    du_q: Vec<f64>,
    values: Vec<f64>,
    /// Scratch of [`unknowns_term_scale`] (`4 n`).
    s: Vec<f64>,
}

#[cfg(test)]
mod tests {
    use super::{Held, HELD_PROBE_EVERY};

    /// One attempt of load step `step` at which GMRES is tried where the policy lets it and
    /// gives up at the iterations in `gives_up`: the iterations it was not tried at.
    fn attempt(h: &mut Held, step: f64, gives_up: &[usize]) -> Vec<usize> {
        h.begin_attempt(step);
        let mut skipped = Vec::new();
        for k in 0..6 {
            if h.predicts_giving_up(k) {
                h.gave_up(k);
                skipped.push(k);
            } else if gives_up.contains(&k) {
                h.gave_up(k);
            }
        }
        skipped
    }

    #[test]
    fn held_factors_skip_gmres_where_it_gave_up_twice() {
        let mut h = Held::default();
        // Gave up at 0 and 1 in two attempts in a row, at 2 once: 0 and 1 are factorised at
        // once in the next attempts, 2 is tried.
        assert!(attempt(&mut h, 1.0, &[0, 1, 2]).is_empty());
        assert!(attempt(&mut h, 1.0, &[0, 1]).is_empty());
        assert_eq!(attempt(&mut h, 1.0, &[]), [0, 1]);
        // The probe: every HELD_PROBE_EVERY-th attempt tries everywhere (here the 4th).
        assert_eq!(HELD_PROBE_EVERY, 4);
        assert!(attempt(&mut h, 1.0, &[1]).is_empty());
        // Iteration 0 converged in the probe, 1 gave up again: only 1 is skipped.
        assert_eq!(attempt(&mut h, 1.0, &[]), [1]);
        assert_eq!(attempt(&mut h, 1.0, &[]), [1]);
        // A step shorter than half the last one tries everywhere (and counts as a probe).
        assert!(attempt(&mut h, 0.4, &[]).is_empty());
        // The next normal step: 1 gave up in the attempt before the short one but not in it.
        assert!(attempt(&mut h, 1.0, &[1]).is_empty());
        // Iterations beyond the memory's 64 are always tried.
        h.gave_up(70);
        assert!(!h.predicts_giving_up(70));
    }
}
