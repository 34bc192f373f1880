//! The continuum (hand-derived) design sensitivity analysis, path 2 of `docs/sensitivity.md`:
//! the paper's §3 (eqs 37–65) on the discretised shell, at every converged load step, with the
//! tangent factorised at the converged state and no iteration. Where it runs
//! ([`ContinuumSchedule`]): in the analysis' convergence hook, with the tangent the Newton
//! driver factorises there for it, or on a thread of its own beside the analysis, which hands
//! it each committed step; it then replays the commits on a copy of the problem and factorises
//! the same tangent itself, while the analysis goes on as the plain one.
//!
//! At the converged step `n → n+1` (increment `Δu`, unknowns `u = [q, μ]`), for every design
//! variable `τ` at once (the columns of one multi-right-hand-side solve):
//!
//! 1. **Fictitious load** (eq 65's right-hand side): the derivative of the step's residual
//!    `R(Δu; ⁿs, τ)` at fixed `Δu`, from the hand-derived point kernel
//!    ([`crate::shell::point_sensitivity`]) seeded with the committed sensitivities
//!    `ⁿṡ = (ⁿū̇, ⁿḋ, ⁿė; ⁿQ̇, ⁿσ̇, ⁿα̇, ⁿė^p; ⁿμ̇)` and the design's own terms
//!    (`ṫ`, `Ė, ν̇, …`, the design velocity of the surface for shape variables). This is
//!    `a'_V` of eq (64) with `σ^fic` of eqs (49, 61) and the rotation terms (50–58), minus the
//!    load term `l'_V` of eq (37) (a follower pressure's dependence on `ⁿū̇`), plus the
//!    constraint rows' terms `k_c a_c · ⁿq̇` and `k_c μ̇_c`.
//! 2. **Solve** `K Δu̇ = −(fictitious load)` with the factorised tangent (eq 65); the essential
//!    rows are zero.
//! 3. **History update**: the point kernel's derivative seeded with `Δu̇` as well gives the
//!    sensitivities of the trial histories `ⁿ⁺¹(Q̇, σ̇, α̇, ė^p)` (eqs 44–51); the particle update
//!    (Rodrigues' rotation of the director and the lamina vectors) differentiated by hand gives
//!    `ⁿ⁺¹(ū̇, ḋ, ė)`. They become the committed sensitivities when the analysis commits.
//!
//! The geometry of the discretisation is the CAD surface's parameter domain: shape functions
//! and quadrature are design-free, and the current configuration is `x⁰(ξ; τ) + ū(ξ)`. The
//! paper's design-velocity update (eq 74, the updated reference configuration
//! `ⁿV = V⁰ + ⁿu̇`) is therefore carried by the committed `ⁿū̇` and `ⁿḋ`: the current
//! configuration's sensitivity is `V⁰ + Σ Ψ_I ⁿū̇_I`.
//!
//! **Term groups** (the `--terms` breakdown): the fictitious load splits, by linearity, into
//! [`TermGroup::History`] (the committed state's sensitivities), [`TermGroup::Design`] (the
//! explicit dependence on the thickness and the design velocity of the geometry),
//! [`TermGroup::Material`] (the material parameters), [`TermGroup::Load`] (the loads'
//! explicit design dependence), [`TermGroup::Tool`] (the tools' design velocity) and
//! [`TermGroup::Filter`] (the director-filter stabilisation's whole derivative). Each can be
//! compared with the dual-number reference seeded with that group only ([`super::terms`]).

use super::contact_tools;
use super::dual::SensitivityError;
use super::shape::ShapeVelocity;
use super::{record_monitors, DesignError, DesignKind, DesignVariable, Monitor, SensitivityFields};
use crate::geometry::Surface;
use crate::material::MaterialParams;
use crate::shell::contact_sensitivity::ContactSeeds;
use crate::shell::load::{EdgeVelocity, Load};
use crate::shell::model::ShellModel;
use crate::shell::point::{ParticleState, PointHistory, SurfacePoint, DOFS_PER_PARTICLE};
use crate::shell::point_sensitivity::{commit_particle_dot, ModelSeeds, StepLinearisation};
use crate::shell::problem::ShellProblem;
use crate::solver::krylov::{csc_abs_mul_columns, gmres_columns_to};
use crate::solver::newton::{FailureReason, NewtonFailure};
use crate::solver::observe::{Observed, StepObserver};
use crate::solver::Failure;
use crate::solver::NonlinearProblem;
use crate::solver::{
    ConvergedStep, ConvergedTangent, EssentialBc, FactorisedAt, LinearSolver, Method, NewtonReport,
    ProblemError, SolverOptions, SparsityPattern,
};
use nalgebra::Vector3;
use std::sync::mpsc::{sync_channel, SyncSender};
use std::time::{Duration, Instant};

/// A named group of terms of the fictitious load.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TermGroup {
    /// The committed state's sensitivities `ⁿṡ` (history terms of eq 49, the particles'
    /// `ⁿū̇, ⁿḋ, ⁿė`, the multipliers' `ⁿμ̇`, a follower load's dependence on `ⁿū̇`).
    History,
    /// The explicit dependence on the geometry: thickness and the design velocity of the
    /// surface (eqs 37–43, 50–58).
    Design,
    /// The material parameters (the `Ḋ` and yield-radius terms of `σ^fic`).
    Material,
    /// The loads' explicit design dependence (eq 37's `l'_V` for a shape variable; the
    /// contact's dependence on the thickness through its faces and penalty).
    Load,
    /// The rigid tools' design velocity `V^c` in the contact force (`b'_N`, eqs 76–83).
    Tool,
    /// The director-filter stabilisation's derivative at fixed `Δu` (`docs/stability.md` §3):
    /// through its stiffness `κ(E, ν, t)` and the committed directors and lamina vectors
    /// `ⁿd_J, ⁿe_J` (all seeds; its coefficients live on the parameter domain). The other
    /// groups leave it out.
    Filter,
}

impl TermGroup {
    /// All groups, in output order.
    pub const ALL: [TermGroup; 6] = [
        TermGroup::History,
        TermGroup::Design,
        TermGroup::Material,
        TermGroup::Load,
        TermGroup::Tool,
        TermGroup::Filter,
    ];
    /// Name in tables and JSON.
    pub fn name(self) -> &'static str {
        match self {
            TermGroup::History => "history",
            TermGroup::Design => "design",
            TermGroup::Material => "material",
            TermGroup::Load => "load",
            TermGroup::Tool => "tool",
            TermGroup::Filter => "filter",
        }
    }
}

/// The committed sensitivities of one design variable, parallel to the model's state.
#[derive(Clone, Debug, PartialEq)]
pub struct SensitivityState {
    /// `ⁿ(ū̇, ḋ, ḋ⁰, ė)` of the real particles.
    pub particles: Vec<ParticleState<f64>>,
    /// `ⁿ(Q̇, σ̇, α̇, ė^p)`, point-major as `ShellModel::history`.
    pub history: Vec<PointHistory<f64>>,
    /// `ⁿ(q̇, μ̇)`.
    pub unknowns: Vec<f64>,
    /// Design velocity of the initial geometry at every in-plane point (shape variables).
    pub surface: Option<Vec<SurfacePoint<f64>>>,
    /// Design velocity `V⁰ = ẋ̄⁰` of the mid-surface point at every in-plane point (shape
    /// variables, with [`Self::surface`]): where the contact's slave points sit (eq 74).
    pub position: Option<Vec<Vector3<f64>>>,
    /// Per load of the problem (its order; empty for every load when the variable is not a
    /// shape variable): for a load on an edge (an edge force or moment), the design velocity of
    /// the initial geometry `ẋ̄⁰,u, ẋ̄⁰,v, ṅ⁰` at each of its edge points
    /// (`Load::edge_velocities`); empty for other loads.
    pub edge_velocities: Vec<Vec<EdgeVelocity>>,
    /// `ṫ`.
    pub thickness: f64,
    /// `Ė, ν̇, k̇, σ̇0, Ḣ, β̇`.
    pub material: MaterialParams<f64>,
    /// Per tool of the contact (its order; empty without contact): the rates of its
    /// translation and rotation (`V^c`, eq 76), a unit vector for a tool variable.
    pub tools: Vec<crate::shell::contact_sensitivity::ToolRate>,
}

/// A zero particle-state sensitivity.
pub fn zero_particle() -> ParticleState<f64> {
    let z = Vector3::zeros();
    ParticleState {
        u: z,
        d: z,
        d0: z,
        e: [z, z],
    }
}

/// A zero history sensitivity.
pub fn zero_history() -> PointHistory<f64> {
    PointHistory::ZERO
}

impl SensitivityState {
    /// The initial sensitivities of `var` for `problem` (at its unloaded state, built on
    /// `surface`): the variable's unit seed; for a shape variable the design velocity of the
    /// initial geometry (eqs 37–43, [`ShapeVelocity`]): `ẋ⁰,α, ṅ⁰, ṅ⁰,α` at the points, the
    /// particles' initial directors and lamina vectors, the initial lamina frames.
    pub fn initial(
        problem: &ShellProblem,
        var: &DesignVariable,
        surface: Option<&Surface<f64>>,
    ) -> Result<Self, SensitivityError> {
        let mut s = Self::zero(problem);
        match &var.kind {
            DesignKind::Thickness => s.thickness = 1.0,
            DesignKind::Material(p) => {
                let mut a = [0.0; 6];
                a[p.index()] = 1.0;
                s.material = MaterialParams::from_array(a);
            }
            DesignKind::Shape { parameter, name } => {
                let surface = surface
                    .ok_or_else(|| DesignError::ShapeWithoutSurface { name: name.clone() })?;
                let v =
                    ShapeVelocity::new(&problem.model, surface, *parameter).map_err(|source| {
                        SensitivityError::Geometry {
                            what: format!("design velocity of `{}`", var.name),
                            source,
                        }
                    })?;
                s.particles = v.particles;
                s.history = v.history;
                s.surface = Some(v.points);
                s.position = Some(v.positions);
                s.edge_velocities = problem
                    .loads()
                    .iter()
                    .map(|l| l.edge_velocities(surface, *parameter))
                    .collect::<Result<_, _>>()
                    .map_err(SensitivityError::from)?;
            }
            // The one check (`check_method_inputs`) found the tool.
            DesignKind::Tool { tool, axis } | DesignKind::ToolRotation { tool, axis } => {
                if let Some(t) = tool_index(problem, tool).and_then(|i| s.tools.get_mut(i)) {
                    match var.kind {
                        DesignKind::Tool { .. } => t.translation[*axis] = 1.0,
                        _ => t.rotation[*axis] = 1.0,
                    }
                }
            }
            DesignKind::ToolShape {
                tool, parameter, ..
            } => {
                if let Some(t) = tool_index(problem, tool).and_then(|i| s.tools.get_mut(i)) {
                    t.shape = Some((*parameter, 1.0));
                }
            }
        }
        Ok(s)
    }

    /// The seeds of the point kernel for `group` (all groups: `None`), with the increment
    /// sensitivity `dofs`; `zero` supplies the zero state of the groups left out.
    fn seeds<'a>(
        &'a self,
        group: Option<TermGroup>,
        dofs: &'a [f64],
        zero: &'a SensitivityState,
    ) -> ModelSeeds<'a> {
        let on = |g: TermGroup| group.is_none_or(|x| x == g);
        let state = if on(TermGroup::History) { self } else { zero };
        ModelSeeds {
            surface: if on(TermGroup::Design) {
                self.surface.as_deref()
            } else {
                None
            },
            thickness: if on(TermGroup::Design) {
                self.thickness
            } else {
                0.0
            },
            material: if on(TermGroup::Material) {
                self.material
            } else {
                MaterialParams::zero()
            },
            particles: &state.particles,
            history: &state.history,
            dofs,
        }
    }

    /// All sensitivities zero (the seeds of a group left out), for `problem`.
    pub fn zero(problem: &ShellProblem) -> Self {
        let model = &problem.model;
        SensitivityState {
            particles: vec![zero_particle(); model.particles.len()],
            history: vec![zero_history(); model.history.len()],
            unknowns: vec![0.0; problem.n_dofs()],
            surface: None,
            position: None,
            edge_velocities: Vec::new(),
            thickness: 0.0,
            material: MaterialParams::zero(),
            tools: vec![Default::default(); contact_tools(problem).len()],
        }
    }
}

/// The index of the tool `name` among the tools of the problem's contact.
fn tool_index(problem: &ShellProblem, name: &str) -> Option<usize> {
    contact_tools(problem).iter().position(|t| t.name == name)
}

/// The sensitivities recorded at one converged step.
#[derive(Clone, Debug, PartialEq)]
pub struct ContinuumStepRecord {
    /// Converged step index (0-based).
    pub step: usize,
    /// Load factor.
    pub load: f64,
    /// Monitor values (f64 analysis).
    pub values: Vec<f64>,
    /// `derivatives[m][v]`: d(monitor m)/d(variable v).
    pub derivatives: Vec<Vec<f64>>,
}

/// Where the continuum DSA spends its time (s, summed over the steps).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContinuumTiming {
    /// Fictitious loads (eq 65's right-hand sides).
    pub rhs: f64,
    /// The multi-RHS solve with the factorised tangent.
    pub solve: f64,
    /// History and particle updates (eqs 44–51).
    pub update: f64,
    /// Monitor derivatives after the commit.
    pub record: f64,
    /// The converged tangents assembled and factorised on the DSA's own thread, with the
    /// replayed commits ([`ContinuumSchedule::Concurrent`]; 0 in the synchronous hook, whose
    /// tangent the analysis' driver factorises). Not part of the DSA's own time.
    pub tangent: f64,
    /// Preconditioned iterations of the sensitivity solves ([`SensitivitySolve::Krylov`]:
    /// Arnoldi steps), over all steps and right-hand sides.
    pub krylov_iterations: usize,
    /// Steps whose sensitivity systems GMRES did not solve within its budget
    /// ([`SensitivitySolve::Krylov`]): the DSA factorised the tangent itself there.
    pub krylov_fallbacks: usize,
}

/// How the continuum DSA in the analysis' hook solves the sensitivity systems (eq 65) of a
/// converged step.
///
/// The default is [`SensitivitySolve::Krylov`]: measured with 2 cores on an otherwise idle
/// machine (2026-11-27, the two alternated in one sitting), the whole hooked run over the
/// plain run per design variable was 3.80 / 3.90 % against 4.48 / 4.29 % on the 17 × 17 plastic
/// hemisphere (`benches/dsa.rs`, medians of three pairs) and 1.69 / 1.51 % against 4.27 /
/// 2.93 % on the same case at 33 × 33 (`shelldsa dsa --methods continuum`, single runs, which
/// spread by about 1.5 points) and 0.94 % against 4.78 % at 65 × 65, where one factorisation
/// costs far more than a few preconditioned iterations; on the bending case the two were
/// within the pairs' spread.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SensitivitySolve {
    /// With the tangent factorised at the converged state: the driver factorises it once more
    /// per step (`ConvergedTangent::Required`), and one multi-right-hand-side solve follows.
    Factorised,
    /// Iteratively on the converged tangent, which the driver assembles where it tests
    /// convergence but does not factorise (`ConvergedTangent::Assembled`), preconditioned by
    /// the factorisation the driver holds (an earlier iterate's), to a residual of
    /// [`KRYLOV_RTOL`] of each right-hand side: from the preconditioner's solution of all
    /// right-hand sides, GMRES on the columns above the tolerance in lock step
    /// ([`gmres_columns_to`]: each Arnoldi step reads the factors and the tangent once for all
    /// of them). A step whose systems GMRES does not solve within [`KRYLOV_MAX_ITERATIONS`] is
    /// solved with a factorisation of the DSA's own.
    #[default]
    Krylov,
}

/// Relative residual `‖b − K u̇‖ / ‖b‖` to which [`SensitivitySolve::Krylov`] solves, or the
/// round-off of the residual's own evaluation, `16 ε ‖ |K| |u̇| ‖`, where that is larger: what
/// a backward-stable direct solve leaves, so that the continuum DSA keeps its agreement with
/// the dual reference far below the 1e-8 its checks ask (`tests/dsa_krylov_solve.rs`: within
/// 6.7e-11 and 2.6e-11 of each variable's largest derivative from the factorised solve on the
/// reduced hemisphere and bending examples).
pub const KRYLOV_RTOL: f64 = 1e-14;

/// Arnoldi steps per right-hand side before [`SensitivitySolve::Krylov`] gives up on a step.
pub const KRYLOV_MAX_ITERATIONS: usize = 30;

/// The tangent a sensitivity solve uses.
enum StepSolver<'a> {
    /// Factorised at the converged state.
    Factorised(&'a LinearSolver),
    /// The converged tangent's values over `pattern`, and a factorisation of an earlier
    /// iterate's as the preconditioner.
    Krylov {
        pattern: &'a SparsityPattern,
        values: &'a [f64],
        preconditioner: &'a LinearSolver,
    },
}

/// Where the continuum DSA runs.
///
/// The default is [`ContinuumSchedule::Synchronous`]: measured on both paper examples with 2
/// cores (`benches/dsa.rs`, machine otherwise idle, 2026-11-27), the whole run over the plain
/// run per design variable was 4.65 % in the hook against 5.39 % on the DSA's own thread
/// (hemisphere, median of three pairs) and 3.55 % against 3.45 % (bending), with less CPU time
/// in the hook on both (4.1–4.7 % against 7.9–9.1 %, and 3.4–7.5 % against 5.3–11.7 %): the
/// analysis keeps both cores busy, so a thread of the DSA's own takes its time from it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ContinuumSchedule {
    /// [`ContinuumSchedule::Concurrent`] when rayon's pool has two threads or more (a core for
    /// the DSA beside the analysis) and the problem has at most [`CONCURRENT_MAX_UNKNOWNS`]
    /// unknowns, else [`ContinuumSchedule::Synchronous`] ([`ContinuumSchedule::resolve`]).
    Auto,
    /// In the analysis' convergence hook: the driver evaluates the tangent at every converged
    /// iterate for it, factorised or for GMRES ([`SensitivitySolve`]), and the analysis waits
    /// for the DSA.
    #[default]
    Synchronous,
    /// On a thread of its own, behind the analysis by the step it is on and at most
    /// `QUEUED_STEPS` more: the analysis runs as the plain one (residual-first acceptance, no
    /// converged tangent) and hands each committed step's unknowns and load level through a
    /// bounded queue; the DSA's thread replays them on its own copy of the problem,
    /// assembles and factorises the converged tangent there and runs the same code, so the
    /// records are bit-identical to [`ContinuumSchedule::Synchronous`]'s whenever the
    /// analysis accepts the same iterates with and without the converged tangent (always
    /// with `direct` linear updates).
    Concurrent,
}

/// Largest problem (unknowns) that [`ContinuumSchedule::Auto`] gives a thread of its own.
/// The concurrent DSA keeps a second copy of the problem and needs a core the analysis leaves
/// free: at 33 × 33 (5,446 unknowns) the hemisphere's analysis keeps about 1.5 cores busy, the
/// own thread gave 6.25 % per variable against 3.25 % in the hook, and the copy adds the
/// model's 0.6 GB.
pub const CONCURRENT_MAX_UNKNOWNS: usize = 4_000;

impl ContinuumSchedule {
    /// The schedule for a problem of `n_unknowns` unknowns ([`ContinuumSchedule::Auto`]
    /// decided; the others as they are).
    pub fn resolve(self, n_unknowns: usize) -> Self {
        match self {
            ContinuumSchedule::Auto
                if rayon::current_num_threads() >= 2 && n_unknowns <= CONCURRENT_MAX_UNKNOWNS =>
            {
                ContinuumSchedule::Concurrent
            }
            ContinuumSchedule::Auto => ContinuumSchedule::Synchronous,
            other => other,
        }
    }
}

/// The continuum DSA as an observer of the analysis' converged steps.
#[derive(Debug)]
pub struct ContinuumDsa {
    variables: Vec<DesignVariable>,
    monitors: Vec<Monitor>,
    states: Vec<SensitivityState>,
    zero: SensitivityState,
    pending: Option<Vec<SensitivityState>>,
    /// History buffers of replaced states, handed back to the next step's fictitious-load
    /// pass (`ShellModel::internal_force_dots_linearised_into`): no allocation or zero-fill
    /// of the trial-history derivatives per step.
    spare: Vec<Vec<PointHistory<f64>>>,
    /// The previous step's layer data, whose storage the next step's pass reuses.
    spare_lin: Option<StepLinearisation>,
    records: Vec<ContinuumStepRecord>,
    time: Duration,
    timing: ContinuumTiming,
    failure: Option<Failure>,
    solve: SensitivitySolve,
    /// The DSA's own factorisation where GMRES gave up ([`SensitivitySolve::Krylov`]), made on
    /// first use.
    own_solver: Option<LinearSolver>,
}

/// What the continuum DSA's failures are reported as.
const CONTEXT: &str = "continuum sensitivity";

fn fatal(e: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> ProblemError {
    ProblemError::Failed(Failure::new(CONTEXT, e))
}

impl ContinuumDsa {
    /// The continuum DSA of `variables` for `problem` (at its initial state, built on
    /// `surface`: needed by shape variables), with `monitors` recorded at every converged
    /// step.
    pub fn new(
        problem: &ShellProblem,
        surface: Option<&Surface<f64>>,
        variables: Vec<DesignVariable>,
        monitors: Vec<Monitor>,
    ) -> Result<Self, SensitivityError> {
        super::dual::check_method_inputs(problem, surface, &variables, &monitors)?;
        let states = variables
            .iter()
            .map(|v| SensitivityState::initial(problem, v, surface))
            .collect::<Result<Vec<_>, _>>()?;
        let zero = SensitivityState::zero(problem);
        Ok(ContinuumDsa {
            variables,
            monitors,
            states,
            zero,
            pending: None,
            spare: Vec::new(),
            spare_lin: None,
            records: Vec::new(),
            time: Duration::ZERO,
            timing: ContinuumTiming::default(),
            failure: None,
            solve: SensitivitySolve::default(),
            own_solver: None,
        })
    }

    /// Solve the sensitivity systems in the hook as `solve` says (default
    /// [`SensitivitySolve::Krylov`]).
    pub fn with_solve(mut self, solve: SensitivitySolve) -> Self {
        self.solve = solve;
        self
    }

    /// The design variables.
    pub fn variables(&self) -> &[DesignVariable] {
        &self.variables
    }
    /// The records of the converged steps.
    pub fn records(&self) -> &[ContinuumStepRecord] {
        &self.records
    }
    /// The committed sensitivities, one per variable.
    pub fn states(&self) -> &[SensitivityState] {
        &self.states
    }
    /// Wall time spent in the continuum DSA.
    pub fn time(&self) -> Duration {
        self.time
    }
    /// The run's result, once the analysis it observed in its hooks
    /// ([`ContinuumSchedule::Synchronous`]) has ended with `report` after `total`.
    pub fn into_run(self, report: NewtonReport, total: Duration) -> ContinuumRun {
        let analysis = total.saturating_sub(self.time);
        self.into_run_timed(report, total, analysis, ContinuumSchedule::Synchronous)
    }

    fn into_run_timed(
        self,
        report: NewtonReport,
        total: Duration,
        analysis: Duration,
        schedule: ContinuumSchedule,
    ) -> ContinuumRun {
        ContinuumRun {
            variables: self.variables,
            records: self.records,
            states: self.states,
            report,
            total,
            analysis,
            dsa: self.time,
            timing: self.timing,
            schedule,
        }
    }
    /// The same, by stage.
    pub fn timing(&self) -> ContinuumTiming {
        self.timing
    }

    /// The fictitious load (eq 65's right-hand side, the derivative of the residual at fixed
    /// `Δu`) of every variable restricted to `group` (`None`: all groups), all unknowns' rows.
    pub fn fictitious_loads(
        &self,
        problem: &ShellProblem,
        at: StepState<'_>,
        group: Option<TermGroup>,
    ) -> Result<Vec<Vec<f64>>, SensitivityError> {
        fictitious_loads(problem, &self.states, &self.zero, at, group)
    }

    fn hook(
        &mut self,
        problem: &ShellProblem,
        step: &ConvergedStep<'_>,
    ) -> Result<(), ProblemError> {
        let solver = match (step.factorised_at, step.tangent) {
            (FactorisedAt::Converged, _) => StepSolver::Factorised(step.solver),
            (FactorisedAt::PreviousIterate, Some((pattern, values))) => StepSolver::Krylov {
                pattern,
                values,
                preconditioner: step.solver,
            },
            (FactorisedAt::PreviousIterate, None) => {
                return Err(fatal(
                    "the solver's tangent is not the converged one and the converged tangent \
                     was not assembled (the observer must ask for ConvergedTangent::Required \
                     or ConvergedTangent::Assembled)",
                ))
            }
        };
        self.solve_step(problem, step.u, step.load, solver, step.essential)
    }

    /// Solve the `nv` systems in the columns of `b` in place.
    fn solve_columns(
        &mut self,
        solver: StepSolver<'_>,
        b: &mut [f64],
        nv: usize,
    ) -> Result<(), ProblemError> {
        let (pattern, values, preconditioner) = match solver {
            StepSolver::Factorised(s) => return s.solve_columns_in_place(b, nv).map_err(fatal),
            StepSolver::Krylov {
                pattern,
                values,
                preconditioner,
            } => (pattern, values, preconditioner),
        };
        let n = pattern.n_dofs();
        let norm = |a: &[f64]| a.iter().map(|t| t * t).sum::<f64>().sqrt();
        // The preconditioner's solutions of all columns in one pass (the factors are read
        // once): GMRES's initial guesses.
        let mut x = b[..n * nv].to_vec();
        preconditioner
            .solve_columns_in_place(&mut x, nv)
            .map_err(fatal)?;
        // Each column's tolerance: KRYLOV_RTOL of its right-hand side or the round-off of its
        // residual's own evaluation, `16 ε ‖ |K| |x| ‖` (the size of the terms that cancel in
        // `b − K x`), which a backward-stable direct solve leaves too; `|K| |x|` of all
        // columns in one pass over the matrix.
        let mut scale = vec![0.0; n * nv];
        csc_abs_mul_columns(pattern, values, &x, nv, &mut scale);
        let tols: Vec<f64> = (0..nv)
            .map(|v| {
                (KRYLOV_RTOL * norm(&b[v * n..(v + 1) * n]))
                    .max(16.0 * f64::EPSILON * norm(&scale[v * n..(v + 1) * n]))
            })
            .collect();
        // GMRES on the columns whose residual with the converged tangent is above their
        // tolerance, in lock step (one pass over the factors and the matrix per Arnoldi step
        // for all of them).
        let outcome = gmres_columns_to(
            pattern,
            values,
            preconditioner,
            &b[..n * nv],
            &mut x,
            nv,
            &tols,
            KRYLOV_MAX_ITERATIONS,
        )
        .map_err(fatal)?;
        self.timing.krylov_iterations += outcome
            .iter()
            .flatten()
            .map(|i| i.iterations)
            .sum::<usize>();
        let solved: Vec<bool> = outcome.iter().map(Option::is_some).collect();
        for (v, col) in b.chunks_mut(n).enumerate().take(nv) {
            if solved[v] {
                col.copy_from_slice(&x[v * n..(v + 1) * n]);
            }
        }
        if solved.iter().all(|&s| s) {
            return Ok(());
        }
        // GMRES gave up: factorise the converged tangent here and solve the rest directly.
        self.timing.krylov_fallbacks += 1;
        if self.own_solver.is_none() {
            self.own_solver = Some(
                LinearSolver::new(pattern, Method::auto(pattern), SolverOptions::default())
                    .map_err(fatal)?,
            );
        }
        let own = self.own_solver.as_mut().expect("made above");
        own.factorize(values).map_err(fatal)?;
        for (col, _) in b.chunks_mut(n).zip(&solved).filter(|(_, s)| !**s) {
            own.solve_in_place(col).map_err(fatal)?;
        }
        Ok(())
    }

    /// The sensitivities of the converged step to `u` at `load` (eq 65 and the history
    /// update), kept pending until the commit: `problem` holds the step's start (committed)
    /// state and `solver` the tangent factorised at `u` with the essential conditions
    /// `essential` eliminated.
    fn solve_step(
        &mut self,
        problem: &ShellProblem,
        u: &[f64],
        load: f64,
        solver: StepSolver<'_>,
        essential: &EssentialBc,
    ) -> Result<(), ProblemError> {
        let n = u.len();
        let n_q = problem.n_generalised();
        let du: Vec<f64> = u.iter().zip(problem.state()).map(|(a, b)| a - b).collect();
        // 1. Fictitious loads of all variables (eq 65's right-hand side).
        let t0 = Instant::now();
        let (rhs, kept) = fictitious_loads_kept(
            problem,
            &self.states,
            &self.zero,
            StepState { du: &du, u, load },
            None,
            Some((std::mem::take(&mut self.spare), self.spare_lin.take())),
        )
        .map_err(fatal)?;
        let (mut histories, lin) = kept.ok_or_else(|| fatal("no linearisation kept"))?;
        let nv = self.variables.len();
        let mut b = vec![0.0; n * nv];
        for (v, r) in rhs.iter().enumerate() {
            let col = &mut b[v * n..(v + 1) * n];
            for (c, ri) in col.iter_mut().zip(r) {
                *c = -ri;
            }
            essential.zero_constrained(col);
        }
        // 2. One multi-RHS solve with the converged tangent (eq 65).
        self.timing.rhs += t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        self.solve_columns(solver, &mut b, nv)?;
        self.timing.solve += t0.elapsed().as_secs_f64();
        // 3. History and particle updates with Δu̇ (eqs 44–51): the trial histories'
        // derivative is linear in the seeds, so the fictitious loads' pass (Δq̇ = 0) gave its
        // seed part and the Δq̇ part is added from the layer data that pass kept.
        let t0 = Instant::now();
        let model = &problem.model;
        let dofs_dot: Vec<&[f64]> = (0..nv).map(|v| &b[v * n..v * n + n_q]).collect();
        model
            .add_increment_history_dots(&lin, &dofs_dot, &mut histories)
            .map_err(fatal)?;
        self.spare_lin = Some(lin);
        let next = self
            .states
            .iter()
            .zip(histories)
            .enumerate()
            .map(|(v, (s, history))| {
                let dq = &b[v * n..(v + 1) * n];
                let particles = model
                    .particles
                    .iter()
                    .zip(&s.particles)
                    .enumerate()
                    .map(|(i, (p, pd))| {
                        let r = DOFS_PER_PARTICLE * i..DOFS_PER_PARTICLE * (i + 1);
                        commit_particle_dot(p, pd, &du[r.clone()], &dq[r])
                    })
                    .collect();
                SensitivityState {
                    particles,
                    history,
                    unknowns: s.unknowns.iter().zip(dq).map(|(a, d)| a + d).collect(),
                    surface: s.surface.clone(),
                    position: s.position.clone(),
                    edge_velocities: s.edge_velocities.clone(),
                    thickness: s.thickness,
                    material: s.material,
                    tools: s.tools.clone(),
                }
            })
            .collect();
        self.timing.update += t0.elapsed().as_secs_f64();
        self.pending = Some(next);
        Ok(())
    }

    /// After the analysis' commit: adopt the pending sensitivities and record the monitors.
    fn record(&mut self, problem: &ShellProblem, load: f64) -> Result<(), Failure> {
        let next = self
            .pending
            .take()
            .ok_or_else(|| Failure::new(CONTEXT, "commit without a converged-step hook"))?;
        let old = std::mem::replace(&mut self.states, next);
        self.spare = old.into_iter().map(|s| s.history).collect();
        let (values, derivatives) = record_monitors(problem, load, &self.monitors, &*self)
            .map_err(|e| Failure::new(CONTEXT, e))?;
        self.records.push(ContinuumStepRecord {
            step: self.records.len(),
            load,
            values,
            derivatives,
        });
        Ok(())
    }
}

impl SensitivityFields for ContinuumDsa {
    fn n_variables(&self) -> usize {
        self.states.len()
    }
    fn translations(&self, model: &ShellModel, v: usize) -> Vec<f64> {
        let mut q = vec![0.0; model.n_dofs()];
        for (i, p) in self.states[v].particles.iter().enumerate() {
            for c in 0..3 {
                q[DOFS_PER_PARTICLE * i + c] = p.u[c];
            }
        }
        q
    }
    fn plastic_strain(&self, v: usize) -> Vec<f64> {
        let history = &self.states[v].history;
        history.iter().map(|h| h.material.eps_p).collect()
    }
    fn tool_force_dots(
        &self,
        problem: &ShellProblem,
        load: f64,
    ) -> Result<Vec<Vec<[f64; 3]>>, SensitivityError> {
        tool_force_dots(problem, &self.states, &self.zero, load)
    }
}

/// The contact force's derivative (`b'_N`, eqs 78–83, `ShellContact::force_dots`: the slave
/// projections evaluated once for all variables) for every state's seeds restricted to `group`:
/// the committed particle dots (group `history`), the tool translations (group `tool`), the
/// thickness (the contact faces at `±t/2`: group `load`), the penalty's `ω = c E/t`
/// dependence (`Ė`: group `material`, `ṫ`: group `load`) and a shape variable's design
/// velocity of the slave sites' initial geometry (`V⁰`, `ẋ⁰,α, ṅ⁰, ṅ⁰,α`: group `load`, the
/// loads' share of the geometry seeds, as [`super::terms`] splits the dual residual:
/// `design` is the internal force's share, `load` the external force's). `None` without
/// contact.
fn contact_dots(
    model: &ShellModel,
    loads: &[Load],
    states: &[SensitivityState],
    zero: &SensitivityState,
    group: Option<TermGroup>,
    dq: &[f64],
    factor: f64,
) -> Result<Option<Vec<Vec<f64>>>, SensitivityError> {
    let Some(c) = loads.iter().find_map(|l| match l {
        Load::Contact(c) => Some(c),
        _ => None,
    }) else {
        return Ok(None);
    };
    let increment = vec![0.0; dq.len()];
    let seeds = contact_seeds(model, c, states, zero, group, &increment)?;
    Ok(Some(c.contact.force_dots(model, dq, factor, &seeds)?))
}

/// The contact's input derivatives ([`ContactSeeds`]) of every state's seeds restricted to
/// `group` (`None`: all), with the increment's derivative `increment`.
fn contact_seeds<'a>(
    model: &ShellModel,
    c: &crate::shell::load::ContactLoad,
    states: &'a [SensitivityState],
    zero: &'a SensitivityState,
    group: Option<TermGroup>,
    increment: &'a [f64],
) -> Result<Vec<ContactSeeds<'a>>, SensitivityError> {
    let on = |g: TermGroup| group.is_none_or(|x| x == g);
    if states
        .iter()
        .any(|s| s.surface.is_some() != s.position.is_some())
    {
        return Err(SensitivityError::Shell(
            crate::shell::ShellError::InvalidInput(
                "continuum sensitivity with contact: a shape design velocity needs both the \
                 surface dots (`SensitivityState::surface`) and the mid-surface points' \
                 (`SensitivityState::position`), one of them is missing"
                    .into(),
            ),
        ));
    }
    Ok(states
        .iter()
        .map(|s| {
            let t_dot = if on(TermGroup::Load) {
                s.thickness
            } else {
                0.0
            };
            let e_dot = if on(TermGroup::Material) {
                s.material.young
            } else {
                0.0
            };
            ContactSeeds {
                tools: if on(TermGroup::Tool) {
                    &s.tools
                } else {
                    &zero.tools
                },
                thickness: t_dot,
                penalty: match c.penalty_factor {
                    Some(k) => {
                        k * (e_dot * model.thickness - model.material.young * t_dot)
                            / (model.thickness * model.thickness)
                    }
                    None => 0.0,
                },
                particles: if on(TermGroup::History) {
                    &s.particles
                } else {
                    &zero.particles
                },
                increment,
                initial: match (on(TermGroup::Load), &s.surface, &s.position) {
                    (true, Some(surfaces), Some(positions)) => {
                        Some(crate::shell::contact::InitialGeometry {
                            positions,
                            surfaces,
                        })
                    }
                    _ => None,
                },
            }
        })
        .collect())
}

/// The total derivatives of the forces on the tools at the committed state of `problem`
/// (pseudo-time `load`, increment zero) for the carried sensitivities `states`
/// ([`crate::shell::contact::ShellContact::tool_force_dots`]): `[variable][tool]`.
fn tool_force_dots(
    problem: &ShellProblem,
    states: &[SensitivityState],
    zero: &SensitivityState,
    load: f64,
) -> Result<Vec<Vec<[f64; 3]>>, SensitivityError> {
    let model = &problem.model;
    let Some(c) = super::contact_load(problem) else {
        return Ok(vec![Vec::new(); states.len()]);
    };
    let q = vec![0.0; model.n_dofs()];
    let seeds = contact_seeds(model, c, states, zero, None, &q)?;
    Ok(c.contact.tool_force_dots(model, &q, load, &seeds)?)
}

/// Add the derivative of load `l` (position `k` in the problem's loads) at the increment `dq`
/// and factor `factor` for the seeds of `s` restricted to `group` (`None`: all) into `f`,
/// hand-derived:
/// - a follower pressure depends on `ⁿū + Δū` only: its history term is its load stiffness at
///   `Δu` applied to `ⁿū̇` (eq 37's `l'_V`); for a shape variable its explicit dependence on the
///   initial tangents `x̄⁰,α` (`Pressure::add_design_derivative`, group `load`);
/// - gravity per unit initial area: the area element's shape derivative (group `load`);
/// - an edge force: a follower's history term as the pressure's (its load stiffness applied
///   to `ⁿū̇`); for a shape variable the derivative through its edge points' initial geometry,
///   a dead one's length element or a follower's initial tangents
///   (`EdgeForce::add_design_derivative`, group `load`);
/// - an edge moment: through the committed directors and lamina vectors (group `history`) and,
///   for a shape variable, the edge points' initial normals and length elements (group
///   `load`), `Moment::add_design_derivative`;
/// - a constant load: the inner load at factor 1;
/// - the director filter (group `filter` alone, with all seeds):
///   `−κ̇ Bᵀ B α − κ (Ḃᵀ B α + Bᵀ Ḃ α)` with `κ̇` from `Ė, ν̇, ṫ` and `Ḃ` from the committed
///   `ⁿḋ, ⁿė` (`DirectorFilter::add_design_derivative`);
/// - the contact: [`contact_dots`], for all variables at once.
fn add_load_dot(
    model: &ShellModel,
    (k, l): (usize, &Load),
    s: &SensitivityState,
    group: Option<TermGroup>,
    dq: &[f64],
    factor: f64,
    f: &mut [f64],
) -> Result<(), SensitivityError> {
    let on = |g: TermGroup| group.is_none_or(|x| x == g);
    match l {
        Load::Pressure(p) => {
            if on(TermGroup::History) {
                let mut trip = Vec::new();
                p.add_stiffness(model, dq, factor, &mut trip)?;
                add_times_committed_u(&trip, s, f);
            }
            if let (true, Some(v)) = (on(TermGroup::Load), &s.surface) {
                p.add_design_derivative(model, v, dq, factor, f)?;
            }
        }
        Load::Gravity(g) => {
            if on(TermGroup::Load) {
                if let Some(v) = &s.surface {
                    g.add_design_derivative(model, v, factor, f)?;
                }
                g.add_thickness_derivative(model, s.thickness, factor, f)?;
            }
        }
        Load::PointForce(_) => {}
        Load::Constant(inner) => add_load_dot(model, (k, inner), s, group, dq, 1.0, f)?,
        // The contact is evaluated for all variables at once (`contact_dots`).
        Load::Contact(_) => {
            return Err(SensitivityError::LoadNotCarried {
                load: "a contact inside a constant load".into(),
                expected: "the contact as a load of its own",
            })
        }
        Load::DirectorFilter(l) => {
            if on(TermGroup::Filter) {
                let mp = &model.material;
                let kappa_dot = l.kappa_dot(
                    [mp.young, mp.poisson, model.thickness],
                    [s.material.young, s.material.poisson, s.thickness],
                );
                l.add_design_derivative(model, &s.particles, kappa_dot, dq, f)?;
            }
        }
        // A follower depends on `ⁿū + Δū` as the pressure does; a shape variable changes the
        // arc-length element (dead) or the initial tangents under the current frame (follower).
        Load::EdgeForce(e) => {
            if e.is_follower() && on(TermGroup::History) {
                let mut trip = Vec::new();
                e.add_stiffness(model, dq, factor, &mut trip)?;
                add_times_committed_u(&trip, s, f);
            }
            if let (true, Some(v)) = (on(TermGroup::Load), s.edge_velocities.get(k)) {
                e.add_design_derivative(model, v, dq, factor, f)?;
            }
        }
        // Through the committed directors and lamina vectors (history) and, for a shape
        // variable, the edge's initial normals and length element (load).
        Load::Moment(mo) => {
            let particles = on(TermGroup::History).then_some(s.particles.as_slice());
            let velocities = s
                .edge_velocities
                .get(k)
                .filter(|_| on(TermGroup::Load))
                .map(|v| v.as_slice());
            if particles.is_some() || velocities.is_some() {
                mo.add_design_derivative(model, particles, velocities, dq, factor, f)?;
            }
        }
    }
    Ok(())
}

/// Add the load stiffness entries `trip` (global `(row, column, value)`) applied to the
/// committed displacement sensitivities `ⁿū̇` of `s` into `f` (a follower load's history term,
/// eq 37's `l'_V`): only the translation columns carry `ⁿū̇`.
fn add_times_committed_u(trip: &[(usize, usize, f64)], s: &SensitivityState, f: &mut [f64]) {
    for &(i, j, k) in trip {
        let (pj, c) = (j / DOFS_PER_PARTICLE, j % DOFS_PER_PARTICLE);
        if c < 3 {
            f[i] += k * s.particles[pj].u[c];
        }
    }
}

/// A converged step as the sensitivity methods see it.
#[derive(Clone, Copy, Debug)]
pub struct StepState<'a> {
    /// The converged increment `Δu` from the committed state.
    pub du: &'a [f64],
    /// The converged unknowns `u`.
    pub u: &'a [f64],
    /// The load level.
    pub load: f64,
}

/// The fictitious loads of `states` (one per variable) at the converged step `at` of
/// `problem`, restricted to `group` (`None`: all groups):
/// internal force terms from the hand-derived point kernel, the follower loads' dependence
/// on `ⁿū̇`, and the constraint rows.
pub fn fictitious_loads(
    problem: &ShellProblem,
    states: &[SensitivityState],
    zero: &SensitivityState,
    at: StepState<'_>,
    group: Option<TermGroup>,
) -> Result<Vec<Vec<f64>>, SensitivityError> {
    Ok(fictitious_loads_kept(problem, states, zero, at, group, None)?.0)
}

/// The trial histories' seed part (one per variable) and the layer data of the step, kept by
/// [`fictitious_loads_kept`] for the history update.
type Kept = (Vec<Vec<PointHistory<f64>>>, StepLinearisation);

/// Storage handed back to [`fictitious_loads_kept`]: the replaced states' history buffers and
/// the previous step's layer data.
type Recycled = (Vec<Vec<PointHistory<f64>>>, Option<StepLinearisation>);

/// [`fictitious_loads`], with `keep` (`Some`): also the trial histories' seed part, written
/// into the given buffers where they fit, and the layer data of the step
/// ([`ShellModel::internal_force_dots_linearised_into`]).
fn fictitious_loads_kept(
    problem: &ShellProblem,
    states: &[SensitivityState],
    zero: &SensitivityState,
    at: StepState<'_>,
    group: Option<TermGroup>,
    keep: Option<Recycled>,
) -> Result<(Vec<Vec<f64>>, Option<Kept>), SensitivityError> {
    let StepState { du, u, load } = at;
    let model = &problem.model;
    let loads = problem.loads();
    let n = u.len();
    let n_q = problem.n_generalised();
    let zero_dofs = vec![0.0; n_q];
    let seeds: Vec<ModelSeeds> = states
        .iter()
        .map(|s| s.seeds(group, &zero_dofs, zero))
        .collect();
    let history_terms = group.is_none_or(|g| g == TermGroup::History);
    let keep_histories = keep.is_some();
    let (dots, lin) = match keep {
        Some((buffers, previous)) => {
            let (d, l) =
                model.internal_force_dots_linearised_into(&du[..n_q], &seeds, buffers, previous)?;
            (d, Some(l))
        }
        None => (model.internal_force_dots(&du[..n_q], &seeds)?, None),
    };
    let mut contact =
        contact_dots(model, loads, states, zero, group, &du[..n_q], load)?.map(|v| v.into_iter());
    let mut out = Vec::with_capacity(states.len());
    let mut histories = Vec::with_capacity(if keep_histories { states.len() } else { 0 });
    for (s, (f_int, h)) in states.iter().zip(dots) {
        if keep_histories {
            histories.push(h);
        }
        let mut r = f_int;
        r.resize(n, 0.0);
        // The loads' derivative at fixed Δu (eqs 37, 83), subtracted: R = f_int − f_ext.
        let mut f = match contact.as_mut().and_then(|c| c.next()) {
            Some(c) => c,
            None => vec![0.0; n_q],
        };
        for (k, l) in loads
            .iter()
            .enumerate()
            .filter(|(_, l)| !matches!(l, Load::Contact(_)))
        {
            add_load_dot(model, (k, l), s, group, &du[..n_q], load, &mut f)?;
        }
        for (ri, fi) in r.iter_mut().zip(&f) {
            *ri -= fi;
        }
        if history_terms {
            // Constraint rows: k_c a_c · ⁿq̇ and k_c μ̇_c (the committed unknowns' sensitivities).
            for (c, (row, &k)) in problem
                .constraints()
                .iter()
                .zip(problem.constraint_scales())
                .enumerate()
            {
                let mu_dot = s.unknowns[n_q + c];
                let mut g = 0.0;
                for &(d, a) in &row.terms {
                    r[d] += mu_dot * k * a;
                    g += s.unknowns[d] * a;
                }
                r[n_q + c] = g * k;
            }
        }
        out.push(r);
    }
    Ok((out, lin.map(|l| (histories, l))))
}

impl StepObserver<ShellProblem> for ContinuumDsa {
    fn converged_tangent(&self, _problem: ConvergedTangent) -> ConvergedTangent {
        match self.solve {
            SensitivitySolve::Factorised => ConvergedTangent::Required,
            SensitivitySolve::Krylov => ConvergedTangent::Assembled,
        }
    }
    fn on_converged(
        &mut self,
        problem: &ShellProblem,
        step: &ConvergedStep<'_>,
    ) -> Result<(), ProblemError> {
        let t0 = Instant::now();
        let out = self.hook(problem, step);
        self.time += t0.elapsed();
        out
    }
    fn after_commit(&mut self, problem: &ShellProblem, _u: &[f64], load: f64) {
        let t0 = Instant::now();
        if let Err(e) = self.record(problem, load) {
            self.failure.get_or_insert(e);
        }
        self.time += t0.elapsed();
        self.timing.record += t0.elapsed().as_secs_f64();
    }
    fn on_restore(&mut self) {
        if let Some(p) = self.pending.take() {
            self.spare = p.into_iter().map(|s| s.history).collect();
        }
    }
    fn failure(&self) -> Option<Failure> {
        self.failure.clone()
    }
}

/// The result of [`run_continuum`].
#[derive(Clone, Debug)]
pub struct ContinuumRun {
    /// The design variables.
    pub variables: Vec<DesignVariable>,
    /// Per converged step.
    pub records: Vec<ContinuumStepRecord>,
    /// The committed sensitivities at the end, one per variable.
    pub states: Vec<SensitivityState>,
    /// The Newton report.
    pub report: NewtonReport,
    /// Wall time of the whole run (analysis and continuum DSA, until the last step's
    /// sensitivities are recorded).
    pub total: Duration,
    /// Wall time of the analysis: the run without the DSA's time
    /// ([`ContinuumSchedule::Synchronous`]), or the analysis thread's from its start to the
    /// driver's end ([`ContinuumSchedule::Concurrent`], overlapping the DSA).
    pub analysis: Duration,
    /// The continuum DSA's own time: its stages ([`ContinuumTiming`] without `tangent`), on
    /// the DSA's thread when it is concurrent (overlapping the analysis).
    pub dsa: Duration,
    /// The same, by stage.
    pub timing: ContinuumTiming,
    /// Where the DSA ran.
    pub schedule: ContinuumSchedule,
}

impl ContinuumRun {
    /// Cost of the continuum DSA's own time per design variable as a fraction of the
    /// analysis' ([`ContinuumRun::analysis`]).
    pub fn cost_per_variable(&self) -> f64 {
        self.dsa.as_secs_f64() / self.analysis.as_secs_f64() / self.variables.len() as f64
    }
}

/// How many committed steps may wait for the DSA's thread ([`ContinuumSchedule::Concurrent`])
/// before the analysis blocks at its next commit. Each is the step's unknowns and load level:
/// 8 bytes per unknown (11.6 kB on the hemisphere at 17 × 17).
const QUEUED_STEPS: usize = 2;

/// A committed step of the analysis, as the DSA's thread receives it.
struct Committed {
    u: Vec<f64>,
    load: f64,
}

/// The analysis thread's observer ([`ContinuumSchedule::Concurrent`]): hands every committed
/// step to the DSA's thread. Once that thread has stopped (a failed step), the analysis stops
/// at its next evaluation.
struct Feed {
    queue: SyncSender<Committed>,
    stopped: Option<Failure>,
}

impl StepObserver<ShellProblem> for Feed {
    fn after_commit(&mut self, _problem: &ShellProblem, u: &[f64], load: f64) {
        if self.stopped.is_none() {
            let step = Committed {
                u: u.to_vec(),
                load,
            };
            if self.queue.send(step).is_err() {
                self.stopped = Some(Failure::new(CONTEXT, "the sensitivity thread stopped"));
            }
        }
    }
    fn failure(&self) -> Option<Failure> {
        self.stopped.clone()
    }
}

/// The DSA thread's copy of the problem, following the analysis' commits, with its own solver
/// for the converged tangents.
struct Replica {
    problem: ShellProblem,
    solver: LinearSolver,
    r: Vec<f64>,
    values: Vec<f64>,
}

impl Replica {
    /// The tangent at the committed step's unknowns, evaluated from the replica's committed
    /// state (the step's start) and factorised as the driver does at a converged iterate:
    /// residual and tangent in one evaluation, the essential conditions eliminated.
    fn factorise(&mut self, step: &Committed) -> Result<EssentialBc, ProblemError> {
        let p = &mut self.problem;
        p.residual_and_tangent(&step.u, step.load, &mut self.r, &mut self.values)?;
        let bc = EssentialBc::new(p.n_dofs(), &p.essential(step.load)).map_err(fatal)?;
        let mut g = Vec::new();
        bc.increments_into(&step.u, &mut g);
        bc.apply_with(p.pattern(), &mut self.values, &mut self.r, &g)
            .map_err(fatal)?;
        self.solver.factorize(&self.values).map_err(fatal)?;
        Ok(bc)
    }
}

/// Where a step failed on the DSA's thread, as the synchronous path would meet it.
#[derive(Debug)]
enum StepFailure {
    /// Before the commit (the converged tangent or the sensitivities): the convergence hook's
    /// failure in the synchronous path.
    Hook(ProblemError),
    /// After the commit (the records): the synchronous path stops at the next evaluation.
    Record(Failure),
}

impl ContinuumDsa {
    /// One committed step on the DSA's thread: the converged tangent, the sensitivities
    /// ([`ContinuumDsa::solve_step`]), the replica's commit and the records.
    fn replay(&mut self, replica: &mut Replica, step: &Committed) -> Result<(), StepFailure> {
        let t0 = Instant::now();
        let bc = replica.factorise(step).map_err(StepFailure::Hook)?;
        self.timing.tangent += t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let solved = self.solve_step(
            &replica.problem,
            &step.u,
            step.load,
            StepSolver::Factorised(&replica.solver),
            &bc,
        );
        self.time += t0.elapsed();
        solved.map_err(StepFailure::Hook)?;
        let t0 = Instant::now();
        replica.problem.commit(&step.u, step.load);
        self.timing.tangent += t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let recorded = self.record(&replica.problem, step.load);
        self.time += t0.elapsed();
        self.timing.record += t0.elapsed().as_secs_f64();
        recorded.map_err(StepFailure::Record)
    }
}

/// The error of a run whose DSA failed at converged step `k` of the analysis' `report`, as the
/// synchronous path reports it, with the replica's committed state `u` at `load`: a failure
/// before the commit as the driver reports a failed convergence hook (`on_converged`: the
/// step's attempt failed, the state before it committed); a failure of the records after the
/// commit as the failure of the next attempt at its first evaluation (after the last step: as
/// the observer's failure). The attempts after the failed one are dropped: the analysis ran
/// on while the DSA's thread was behind.
fn failure_at_step(
    mut report: NewtonReport,
    k: usize,
    (u, load): (&[f64], f64),
    failure: StepFailure,
) -> SensitivityError {
    let converged_at = report
        .attempts
        .iter()
        .enumerate()
        .filter(|(_, a)| a.converged)
        .nth(k)
        .map(|(i, _)| i);
    // The attempt that fails in the synchronous path, why, and its residuals.
    let (failed, reason, residuals) = match failure {
        StepFailure::Hook(e) => {
            let reason =
                FailureReason::Problem(ProblemError::Failed(Failure::new("on_converged", e)));
            let residuals = converged_at
                .map(|i| report.attempts[i].residual_norms.clone())
                .unwrap_or_default();
            (converged_at, reason, residuals)
        }
        StepFailure::Record(f) => {
            let next = converged_at
                .map(|i| i + 1)
                .filter(|&i| i < report.attempts.len());
            match next {
                Some(i) => (
                    Some(i),
                    FailureReason::Problem(ProblemError::Failed(f)),
                    Vec::new(),
                ),
                None => return SensitivityError::Observer(f),
            }
        }
    };
    let (attempted, step_size) = match failed {
        Some(i) => {
            report.attempts.truncate(i + 1);
            let rec = &mut report.attempts[i];
            rec.converged = false;
            rec.failure = Some(reason.clone());
            rec.residual_norms.clone_from(&residuals);
            (rec.load, rec.step_size)
        }
        None => (load, 0.0),
    };
    report.u = u.to_vec();
    report.load = load;
    SensitivityError::Newton(Box::new(NewtonFailure {
        converged_load: load,
        attempted_load: attempted,
        step_size,
        reason,
        last_residuals: residuals,
        report,
    }))
}

/// What a thread's panic carried, as text.
fn panic_text(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic without a message".into())
}

/// [`ContinuumSchedule::Concurrent`]: the analysis of `problem` on a thread of its own (as the
/// plain analysis), the continuum DSA of `variables` on this one, step by step behind it on a
/// replica of the problem; `on_step` sees the replica (at the recorded step's committed
/// state) and the DSA after every recorded step. A failed step stops the analysis and is
/// reported as the driver reports a failed convergence hook
/// ([`SensitivityError::Newton`], with the steps before it); a failed analysis is reported
/// once every step it committed is recorded.
pub(super) fn run_concurrent(
    analysis: super::DsaAnalysis<'_>,
    on_step: &mut dyn FnMut(&ShellProblem, &ContinuumDsa),
) -> Result<ContinuumRun, SensitivityError> {
    let t0 = Instant::now();
    let (pattern, mut linear) = analysis.linear_solver()?;
    let (_, replica_solver) = analysis.linear_solver()?;
    let (problem, newton) = (analysis.problem, analysis.newton);
    let mut dsa = ContinuumDsa::new(
        &problem,
        analysis.surface,
        analysis.variables,
        analysis.monitors,
    )?;
    let mut replica = Replica {
        problem: problem.clone(),
        solver: replica_solver,
        r: vec![0.0; pattern.n_dofs()],
        values: vec![0.0; pattern.nnz()],
    };
    let (queue, steps) = sync_channel(QUEUED_STEPS);
    std::thread::scope(|scope| {
        let analysis = scope.spawn(move || {
            let started = Instant::now();
            let feed = Feed {
                queue,
                stopped: None,
            };
            let mut obs = Observed::new(problem, feed);
            let u0 = obs.problem.state().to_vec();
            let out = newton.run(&mut obs, &pattern, &mut linear, &u0);
            (out, started.elapsed())
        });
        // A failed step: its index, the replica's committed unknowns and load level, why.
        let mut stop: Option<(usize, Vec<f64>, f64, StepFailure)> = None;
        let mut load = newton.stepping.start;
        for (k, step) in steps.iter().enumerate() {
            if let Err(e) = dsa.replay(&mut replica, &step) {
                if matches!(e, StepFailure::Record(_)) {
                    load = step.load;
                }
                stop = Some((k, replica.problem.state().to_vec(), load, e));
                break;
            }
            load = step.load;
            on_step(&replica.problem, &dsa);
        }
        // Unblocks the analysis at its next commit if the DSA stopped.
        drop(steps);
        let (outcome, analysis_time) = analysis.join().map_err(|p| {
            SensitivityError::Observer(Failure::new("analysis thread", panic_text(&*p)))
        })?;
        if let Some((k, u, load, e)) = stop {
            let report = match outcome {
                Ok(r) => r,
                Err(f) => f.report,
            };
            return Err(failure_at_step(report, k, (&u, load), e));
        }
        let report = outcome.map_err(SensitivityError::Newton)?;
        let total = t0.elapsed();
        Ok(dsa.into_run_timed(report, total, analysis_time, ContinuumSchedule::Concurrent))
    })
}

/// Run `analysis` with the continuum DSA of its variables at every converged step.
pub fn run_continuum(analysis: super::DsaAnalysis<'_>) -> Result<ContinuumRun, SensitivityError> {
    let methods = super::HookedMethods {
        continuum: true,
        dual: None,
        schedule: ContinuumSchedule::default(),
        solve: SensitivitySolve::default(),
    };
    let (run, _) = super::run_hooked(analysis, methods, &mut |_| {})?;
    Ok(run.unwrap_or_else(|| unreachable!("run_hooked returns a run per method asked for")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::{Predictor, StepRecord};

    /// Attempts 0 → 1 (converged), 1 → 2 (cut), 1 → 1.5, 1.5 → 2 (converged), each with its
    /// residual norms.
    fn report() -> NewtonReport {
        let attempt = |from: f64, to: f64, converged: bool| {
            let mut r = StepRecord::new(from, to, to - from, Predictor::Zero);
            r.converged = converged;
            r.residual_norms = vec![to, 1e-9 * to];
            r
        };
        NewtonReport {
            u: vec![3.0; 2],
            load: 2.0,
            attempts: vec![
                attempt(0.0, 1.0, true),
                attempt(1.0, 2.0, false),
                attempt(1.0, 1.5, true),
                attempt(1.5, 2.0, true),
            ],
        }
    }

    fn newton(e: SensitivityError) -> NewtonFailure {
        match e {
            SensitivityError::Newton(f) => *f,
            other => panic!("expected the analysis' failure, got {other}"),
        }
    }

    #[test]
    fn a_failed_hook_is_the_failure_of_its_step() {
        let e = StepFailure::Hook(ProblemError::Fatal("singular".into()));
        let f = newton(failure_at_step(report(), 1, (&[1.0, 1.0], 1.0), e));
        assert_eq!(
            (f.converged_load, f.attempted_load, f.step_size),
            (1.0, 1.5, 0.5)
        );
        assert_eq!(
            f.last_residuals,
            vec![1.5, 1e-9 * 1.5],
            "the step's attempt"
        );
        assert!(f.reason.to_string().contains("singular"), "{}", f.reason);
        assert_eq!(f.report.attempts.len(), 3, "the attempts after it dropped");
        assert_eq!(f.report.converged_steps().count(), 1);
        assert!(f.report.attempts[2].failure.is_some());
        assert_eq!(
            (f.report.u.as_slice(), f.report.load),
            (&[1.0, 1.0][..], 1.0)
        );
    }

    #[test]
    fn a_failed_record_is_the_failure_of_the_next_attempt() {
        let e = StepFailure::Record(Failure::new(CONTEXT, "monitor"));
        let f = newton(failure_at_step(report(), 0, (&[2.0, 2.0], 1.0), e));
        assert_eq!((f.converged_load, f.attempted_load), (1.0, 2.0));
        assert!(
            f.last_residuals.is_empty(),
            "failed at its first evaluation"
        );
        assert_eq!(f.report.attempts.len(), 2);
        assert_eq!(f.report.converged_steps().count(), 1);
        // After the last step: the observer's failure.
        let e = StepFailure::Record(Failure::new(CONTEXT, "monitor"));
        let last = failure_at_step(report(), 2, (&[3.0, 3.0], 2.0), e);
        assert!(matches!(last, SensitivityError::Observer(_)), "{last}");
    }
}
