//! The design sensitivity study of `shelldsa dsa`: the design sensitivities of an analysis by
//! the hand-derived continuum DSA, the dual-number reference and central differences of
//! complete re-runs ([`fd`]), with the Taylor test, collected per design variable
//! ([`DsaResult`], written by `io::dsa_output` as the paper's Tables 1–2 and
//! `sensitivity.json`, `docs/sensitivity.md`). The analysis for any design is an
//! [`Analysis`] (for a case file: `io::dsa_study::CaseAnalysis`).
//!
//! Order of the runs: (1) the plain analysis (no hook; its wall time is `timing_s.analysis`,
//! and its monitors are the nominal responses `ψ(τ)` of the finite differences); (2a) the
//! analysis with the continuum DSA in its convergence hook (`timing_s.continuum` is the DSA's
//! own time inside it); (2b) the analysis with the dual reference in its convergence hook
//! (one run gives the responses and the derivatives of every design variable;
//! `timing_s.dual` is the reference's own time inside it); (3) per design variable and
//! relative step, the re-runs at `τ ± h` (`timing_s.fd`, all of them). The Taylor remainder
//! `|ψ(τ + h) − ψ(τ) − h ψ'|` of every step size reuses the `τ + h` re-run.

use super::dual::{DualMode, SensitivityError};
use super::fd::{self, fit_rate, Analysis, RunResponse, TaylorFit, TaylorRow};
use super::terms::{breakdown, TermBreakdown};
use super::{
    check_design, run_hooked, Design, DesignScope, DesignVariable, DsaAnalysis, HookedMethods,
    SensitivityFields,
};
use crate::shell::contact::ShellContact;
use crate::shell::model::ShellModel;
use crate::shell::problem::ShellProblem;
use crate::solver::observe::RewriteSchedule;
use crate::solver::{Failure, NewtonSolver};
use std::sync::Arc;
use std::time::{Duration, Instant};
use thiserror::Error;

/// A sensitivity method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DsaMethod {
    /// The hand-derived continuum DSA (`sensitivity::continuum`, eqs 37–65).
    Continuum,
    /// The dual-number reference (`sensitivity::dual`).
    Dual,
    /// Central differences of complete re-runs (`sensitivity::fd`).
    Fd,
}

impl DsaMethod {
    /// Every method, in the order of their names.
    pub const ALL: [DsaMethod; 3] = [DsaMethod::Continuum, DsaMethod::Dual, DsaMethod::Fd];

    /// The name used in case files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            DsaMethod::Continuum => "continuum",
            DsaMethod::Dual => "dual",
            DsaMethod::Fd => "fd",
        }
    }

    /// The method of a name ([`DsaMethod::name`]).
    pub fn from_name(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == s)
    }
}

/// One checked design variable with its finite-difference steps.
#[derive(Clone, Debug, PartialEq)]
pub struct DesignEntry {
    /// The variable.
    pub variable: DesignVariable,
    /// Relative steps `h/|τ|` (each finite, > 0), in the order written.
    pub fd_steps: Vec<f64>,
}

impl DesignEntry {
    /// The absolute steps `h = (h/|τ|)·|τ|` at `design`; for a variable whose value is an
    /// offset (0 at the nominal design, [`super::DesignKind::is_offset`]: a tool translation or
    /// rotation) `fd_steps` are absolute lengths or angles (radians).
    pub fn absolute_steps(&self, design: &Design) -> Vec<f64> {
        if self.variable.kind.is_offset() {
            return self.fd_steps.clone();
        }
        let tau = self.variable.value(design).abs();
        self.fd_steps.iter().map(|r| r * tau).collect()
    }
}

/// The checked design-sensitivity part of a shell case.
#[derive(Clone, Debug, PartialEq)]
pub struct DsaSpec {
    /// The design variables (at least one).
    pub design: Vec<DesignEntry>,
    /// The methods to run (default: continuum, dual and fd).
    pub methods: Vec<DsaMethod>,
    /// The monitored components (default: every case monitor, ux, uy, uz).
    pub monitors: Vec<super::Monitor>,
}

impl DsaSpec {
    /// The design variables, in the order of the case.
    pub fn variables(&self) -> Vec<DesignVariable> {
        self.design.iter().map(|d| d.variable.clone()).collect()
    }
}

/// Errors of a `dsa` run.
#[derive(Debug, Error)]
pub enum DsaError {
    /// The analysis or a method failed.
    #[error(transparent)]
    Sensitivity(#[from] SensitivityError),
    /// An analysis setting the continuum and dual methods do not carry (the message names
    /// the case key).
    #[error("{0}")]
    Unsupported(String),
    /// A hooked run took other load levels than the plain analysis.
    #[error("{}", fd::load_levels_differ(.levels, .nominal, "plain analysis"))]
    LoadLevels {
        /// The hooked run's converged load levels.
        levels: Vec<f64>,
        /// The plain analysis'.
        nominal: Vec<f64>,
    },
}

/// The analysis replaying given load levels: every level is a stop of the load stepping and
/// the step size starts at `max_step` (≥ every gap), so each step is clipped to the next level
/// and keeps its size (a clipped step neither grows nor shrinks); a level whose attempt fails
/// is reached by continuation ([`crate::solver::StopFailure::Continuation`]).
struct Replay<'a> {
    analysis: &'a dyn Analysis,
    levels: Vec<f64>,
}

impl Analysis for Replay<'_> {
    fn build(&self, design: &Design) -> Result<(ShellProblem, NewtonSolver), SensitivityError> {
        let (problem, mut newton) = self.analysis.build(design)?;
        newton.stepping.stops = self.levels.clone();
        newton.stepping.initial_step = newton.stepping.max_step;
        newton.stepping.stop_failure = crate::solver::StopFailure::Continuation;
        Ok((problem, newton))
    }
    fn solver(&self) -> crate::solver::SolverOptions {
        self.analysis.solver()
    }
}

/// The committed sensitivities of the methods at a step: `(method name, fields)`.
pub type MethodFields<'a> = [(&'a str, Option<&'a dyn SensitivityFields>)];

/// Writes the fields of the run that carries the derivative methods as it goes (the VTU
/// files of `shelldsa dsa`); a failure is kept and stops further writing, the run goes on.
pub trait StepWriter {
    /// Open for the hooked run: `contact` is its contact (for the contact pressure),
    /// `variables` the design variables' names.
    fn open(
        &mut self,
        contact: Option<Arc<ShellContact>>,
        variables: Vec<String>,
    ) -> Result<(), Failure>;
    /// Whether converged step `step` (1-based) at `load` is written.
    fn due(&self, step: usize, load: f64) -> bool;
    /// Write step `step` at `load` of `model` with the methods' committed sensitivities
    /// (`(method name, fields)`; `None` fields: zero, the initial state).
    fn write(&mut self, step: usize, load: f64, model: &ShellModel, methods: &MethodFields<'_>);
    /// Time spent writing so far.
    fn time(&self) -> Duration;
    /// The first error writing, if any.
    fn error(&self) -> Option<&Failure>;
    /// The files written so far.
    fn written(&self) -> &[VtuStep];
}

/// Per-step derivatives `[step][monitor][variable]` regrouped as `[variable][step][monitor]`.
fn by_variable<'a>(
    nv: usize,
    steps: impl Iterator<Item = &'a [Vec<f64>]> + Clone,
) -> Vec<Vec<Vec<f64>>> {
    (0..nv)
        .map(|v| {
            steps
                .clone()
                .map(|s| s.iter().map(|d| d[v]).collect())
                .collect()
        })
        .collect()
}

/// Central differences of one variable with one step size.
#[derive(Clone, Debug, PartialEq)]
pub struct FdColumn {
    /// Relative step `h/|τ|`.
    pub relative: f64,
    /// Absolute step `h`.
    pub h: f64,
    /// `derivatives[step][monitor] = (ψ(τ + h) − ψ(τ − h)) / 2h`.
    pub derivatives: Vec<Vec<f64>>,
    /// Per step: the yield status of some layer point differs among the three runs at this or
    /// an earlier step ([`fd::flags`]).
    pub flagged: Vec<bool>,
    /// The Taylor remainder of the dual derivative with this step (when the dual ran).
    pub taylor: Option<TaylorRow>,
}

/// The results of one design variable.
#[derive(Clone, Debug, PartialEq)]
pub struct VariableResult {
    /// The variable and its relative steps.
    pub entry: DesignEntry,
    /// Its value `τ`.
    pub value: f64,
    /// `continuum[step][monitor]` (when the continuum DSA ran).
    pub continuum: Option<Vec<Vec<f64>>>,
    /// `dual[step][monitor]` (when the dual reference ran).
    pub dual: Option<Vec<Vec<f64>>>,
    /// One column per step size (when finite differences ran).
    pub fd: Vec<FdColumn>,
    /// Per load step, the fitted Taylor rate (dual and fd both ran).
    pub taylor: Vec<TaylorFit>,
}

/// All results of a `dsa` run.
#[derive(Clone, Debug, PartialEq)]
pub struct DsaResult {
    /// The spec run (methods possibly overridden on the command line).
    pub spec: DsaSpec,
    /// The plain analysis: loads, monitors, yield status.
    pub nominal: RunResponse,
    /// Per design variable.
    pub variables: Vec<VariableResult>,
    /// Largest difference between the dual run's monitor values and the plain analysis',
    /// relative to the largest monitor magnitude (both converge to the Newton tolerance).
    pub dual_value_difference: Option<f64>,
    /// Largest [`crate::sensitivity::dual::DualStepRecord::value_mismatch`] over the steps:
    /// the value parts of the dual state against the f64 analysis state (round-off when the
    /// reference follows the analysis).
    pub dual_state_mismatch: Option<f64>,
    /// Largest difference between the continuum run's monitor values and the plain analysis',
    /// relative to the largest monitor magnitude.
    pub continuum_value_difference: Option<f64>,
    /// Wall time of the plain analysis (s).
    pub time_analysis: f64,
    /// The continuum DSA's own time inside its run (s).
    pub time_continuum: Option<f64>,
    /// Wall time of the whole run with the continuum hook (analysis + DSA, s).
    pub time_continuum_run: Option<f64>,
    /// The continuum DSA's time by stage.
    pub continuum_stages: Option<crate::sensitivity::continuum::ContinuumTiming>,
    /// The dual reference's own time inside its run (s).
    pub time_dual: Option<f64>,
    /// Wall time of the whole run with the dual hook (analysis + reference, s).
    pub time_dual_run: Option<f64>,
    /// Wall time of all finite-difference re-runs (s).
    pub time_fd: Option<f64>,
    /// Methods and re-runs that failed after the plain analysis (their results are missing,
    /// everything else is kept).
    pub failures: Vec<DsaFailure>,
    /// The VTU files of the run with the derivative methods
    /// ([`StepVtu`](crate::io::dsa_output::StepVtu)), relative to the output directory.
    pub vtu: Vec<VtuStep>,
    /// Wall time of writing them (s; left out of the hooked run's total).
    pub time_vtu: Option<f64>,
    /// The first error writing them (no further VTU is written after it).
    pub vtu_error: Option<String>,
}

/// A VTU file with the sensitivity fields of a converged step.
#[derive(Clone, Debug, PartialEq)]
pub struct VtuStep {
    /// Converged step (0: the initial state).
    pub step: usize,
    /// Its load factor.
    pub load: f64,
    /// The file, relative to the output directory (`steps/step_NNNN.vtu`).
    pub file: String,
}

/// The cost of the derivative methods per design variable, as fractions of the plain
/// analysis' wall time, measured both ways ([`DsaResult::cost`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DsaCost {
    /// The continuum DSA's own stages (fictitious loads, solves, history update, monitors)
    /// over the plain analysis, per variable.
    pub continuum_own: Option<f64>,
    /// The dual reference's own time over the plain analysis, per variable.
    pub dual_own: Option<f64>,
    /// `(hooked − plain) / plain / variables`: everything the hooked run costs more than the
    /// plain one, including the converged-state tangents the methods need and the plain run
    /// skips. With both methods the hooked run carries both.
    pub hooked_over_plain: Option<f64>,
}

impl DsaResult {
    /// The cost per design variable both ways (`None` entries for methods that did not run).
    pub fn cost(&self) -> DsaCost {
        let nv = self.variables.len().max(1) as f64;
        let plain = self.time_analysis;
        let per = |t: f64| (plain > 0.0).then(|| t / plain / nv);
        DsaCost {
            continuum_own: self.time_continuum.and_then(per),
            dual_own: self.time_dual.and_then(per),
            hooked_over_plain: self
                .time_continuum_run
                .or(self.time_dual_run)
                .and_then(|t| per(t - plain)),
        }
    }
}

/// A method or finite-difference re-run that failed.
#[derive(Clone, Debug, PartialEq)]
pub struct DsaFailure {
    /// `continuum`, `dual`, `continuum and dual` (one hooked run) or `fd`.
    pub method: String,
    /// The design variable of a re-run.
    pub variable: Option<String>,
    /// The perturbation of a re-run: `+h` or `−h` (absolute).
    pub h: Option<f64>,
    /// Its relative step `h/|τ|` as written in `fd_steps`.
    pub relative: Option<f64>,
    /// The error.
    pub message: String,
}

impl DsaFailure {
    /// A method's failure (no variable, no step).
    pub fn method(method: &str, e: impl std::fmt::Display) -> Self {
        DsaFailure {
            method: method.into(),
            variable: None,
            h: None,
            relative: None,
            message: e.to_string(),
        }
    }
}

impl std::fmt::Display for DsaFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (&self.variable, self.h) {
            (Some(v), Some(h)) => write!(
                f,
                "{}: re-run of `{v}` at τ {} h (h = {:e}{}): {}",
                self.method,
                if h > 0.0 { "+" } else { "−" },
                h.abs(),
                self.relative
                    .map_or(String::new(), |r| format!(", fd_steps entry {r:e}")),
                self.message
            ),
            _ => write!(f, "{}: {}", self.method, self.message),
        }
    }
}

/// Run the analysis (for any design: `analysis`; nominal design `base`) and the methods of
/// `spec`; `progress` receives one line per run ([`run_observed`] without the pre-check of a
/// step and without the updates).
pub fn run(
    analysis: &dyn Analysis,
    base: &Design,
    spec: &DsaSpec,
    progress: &mut dyn FnMut(&str),
) -> Result<DsaResult, DsaError> {
    run_observed(analysis, base, spec, None, progress, &mut |_| {})
}

/// Run the analysis and the methods of `spec`. `progress` receives one line per run;
/// `update` the results so far (to write `sensitivity.json` as the run goes): after converged
/// steps of the plain analysis and of the run with the derivative methods (on the schedule of
/// `RewriteSchedule`), after each of those runs, after every finite-difference step size of
/// every variable, and before an error of the plain analysis is returned (with its converged
/// steps). With `need_step`, a plain analysis with fewer converged steps is an error
/// before the methods run ([`SensitivityError::StepOutOfRange`]).
///
/// The checks and the plain analysis are all or nothing: an error there is returned. After it,
/// a failed method or re-run is recorded in [`DsaResult::failures`] (naming the method, the
/// variable and `h`) and everything else still runs and is kept.
pub fn run_observed(
    analysis: &dyn Analysis,
    base: &Design,
    spec: &DsaSpec,
    need_step: Option<usize>,
    progress: &mut dyn FnMut(&str),
    update: &mut dyn FnMut(&DsaResult),
) -> Result<DsaResult, DsaError> {
    run_with_output(analysis, base, spec, need_step, None, progress, update)
}

/// [`run_observed`], and with `writer` the fields of the run with the derivative methods
/// written as it goes ([`StepWriter`]; nothing when only finite differences run).
pub fn run_with_output(
    analysis: &dyn Analysis,
    base: &Design,
    spec: &DsaSpec,
    need_step: Option<usize>,
    writer: Option<&mut dyn StepWriter>,
    progress: &mut dyn FnMut(&str),
    update: &mut dyn FnMut(&DsaResult),
) -> Result<DsaResult, DsaError> {
    let vars = spec.variables();
    let monitors = &spec.monitors;
    let surface = base.surface.as_ref();

    // (1) The plain analysis.
    let t = Instant::now();
    let (problem, newton) = analysis.build(base)?;
    // The design variables at the nominal design and every finite-difference design (shape:
    // the perturbed surface with a regular normal at every particle and point of the model;
    // tool shape: a valid perturbed tool) are checked before the analysis.
    let fd = spec.methods.contains(&DsaMethod::Fd);
    let deltas = |i: usize| {
        let steps = match fd {
            true => spec.design[i].absolute_steps(base),
            false => Vec::new(),
        };
        std::iter::once(0.0)
            .chain(steps.into_iter().flat_map(|h| [h, -h]))
            .collect()
    };
    let scope = DesignScope {
        base: Some(base),
        model: Some(&problem.model),
        tools: Some(super::contact_tools(&problem)),
    };
    check_design(&vars, &deltas, &scope).map_err(SensitivityError::from)?;
    if spec.methods.contains(&DsaMethod::Continuum) || spec.methods.contains(&DsaMethod::Dual) {
        super::dual::check_gauge_rows(&problem, &vars)?;
        if problem.loads().iter().any(|l| {
            matches!(l, crate::shell::load::Load::DirectorFilter(f)
                if f.strength() == crate::shell::stabilisation::FilterStrength::DirectorForce)
        }) {
            return Err(DsaError::Unsupported(
                "integration.director_stabilisation_strength = \"director-force\": the \
                 continuum and dual methods do not carry its design derivative (that of the \
                 committed director forces); expected \"bending\" (the default), or the \
                 finite differences alone"
                    .into(),
            ));
        }
    }
    let mut result = DsaResult {
        spec: spec.clone(),
        variables: spec
            .design
            .iter()
            .map(|entry| VariableResult {
                entry: entry.clone(),
                value: entry.variable.value(base),
                continuum: None,
                dual: None,
                fd: Vec::new(),
                taylor: Vec::new(),
            })
            .collect(),
        nominal: RunResponse {
            loads: Vec::new(),
            values: Vec::new(),
            yielding: Vec::new(),
            contact: Vec::new(),
        },
        dual_value_difference: None,
        dual_state_mismatch: None,
        continuum_value_difference: None,
        time_analysis: 0.0,
        time_continuum: None,
        time_continuum_run: None,
        continuum_stages: None,
        time_dual: None,
        time_dual_run: None,
        time_fd: None,
        failures: Vec::new(),
        vtu: Vec::new(),
        time_vtu: None,
        vtu_error: None,
    };
    let mut schedule = RewriteSchedule::starting(Instant::now());
    let run = fd::response_observed(problem, &newton, analysis.solver(), monitors, &mut |r| {
        extend_response(&mut result.nominal, r);
        update_if_due(update, &mut schedule, &result, r.loads.len());
    });
    result.time_analysis = t.elapsed().as_secs_f64();
    match run {
        Ok(nominal) => result.nominal = nominal,
        Err(e) => {
            // The converged steps are kept in the last update before the error.
            update(&result);
            return Err(e.into());
        }
    }
    progress(&format!(
        "analysis: {} converged steps, {:.2} s",
        result.nominal.loads.len(),
        result.time_analysis
    ));
    if let Some(step) = need_step.filter(|&s| s == 0 || s > result.nominal.loads.len()) {
        let steps = Some(result.nominal.loads.len());
        return Err(SensitivityError::StepOutOfRange { step, steps }.into());
    }
    update(&result);
    let nominal = result.nominal.clone();

    // The later runs replay the plain run's load levels: every converged level becomes a
    // `stops` entry and the step size starts at `max_step` (≥ every gap), so each step is
    // clipped to the next level and keeps its size (a clipped step neither grows nor
    // shrinks): the runs land on the same levels whatever their iteration counts (the hooked
    // run needs the converged tangent, the re-runs converge to tighter tolerances, and near a
    // change of the contact set or of the plastic zone an iteration more or less changes the
    // adaptive growth; the discrete response depends on the levels). Prescribed steps are
    // replayed as they were (the levels are the plain run's own numbers, bit for bit). A
    // re-run whose attempt at a level fails reaches it by continuation (`StopFailure`: a
    // shorter step solved from the same committed state, not committed, starts a new attempt
    // at the level), so it solves the same equations at the same levels; a re-run that still
    // has to cut a step differs and is reported (`StepSequence`).
    let replay = Replay {
        analysis,
        levels: nominal.loads.clone(),
    };
    let analysis: &dyn Analysis = &replay;

    // (2) The continuum DSA and the dual reference: both observe one hooked run when both are
    // asked for (they share the analysis and its converged tangents), else each its own.
    let dual_mode = if vars.len() <= 8 {
        DualMode::Vector
    } else {
        DualMode::PerVariable
    };
    let (want_continuum, want_dual) = (
        spec.methods.contains(&DsaMethod::Continuum),
        spec.methods.contains(&DsaMethod::Dual),
    );
    let methods_name = match (want_continuum, want_dual) {
        (true, true) => "continuum and dual",
        (true, false) => "continuum",
        _ => "dual",
    };
    let methods = HookedMethods {
        continuum: want_continuum,
        dual: want_dual.then_some(dual_mode),
        schedule: crate::sensitivity::continuum::ContinuumSchedule::default(),
        solve: crate::sensitivity::continuum::SensitivitySolve::default(),
    };
    let method_names: Vec<&str> = [(want_continuum, "continuum"), (want_dual, "dual")]
        .into_iter()
        .filter_map(|(w, n)| w.then_some(n))
        .collect();
    let mut vtu: Option<&mut dyn StepWriter> = None;
    let mut vtu_before_run = 0.0;
    let (continuum_run, dual_run) = if want_continuum || want_dual {
        let mut schedule = RewriteSchedule::starting(Instant::now());
        let built = analysis.build(base).map_err(DsaError::from);
        if let (Some(w), Ok((problem, _))) = (writer, &built) {
            let names = vars.iter().map(|v| v.name.clone()).collect();
            let contact = super::contact_load(problem).map(|c| c.contact.clone());
            match w.open(contact, names) {
                Ok(()) => {
                    let zero: Vec<_> = method_names.iter().map(|m| (*m, None)).collect();
                    w.write(0, 0.0, &problem.model, &zero);
                    // Only the writes inside the hooked run leave its total.
                    vtu_before_run = w.time().as_secs_f64();
                    vtu = Some(w);
                }
                Err(e) => result.vtu_error = Some(e.to_string()),
            }
        }
        let runs = built.and_then(|(problem, newton)| {
            run_hooked(
                DsaAnalysis {
                    problem,
                    surface,
                    variables: vars.clone(),
                    monitors: monitors.clone(),
                    newton: &newton,
                    solver: analysis.solver(),
                },
                methods,
                &mut |records| {
                    if let Some(w) = vtu.as_mut() {
                        let last = records
                            .continuum
                            .and_then(|r| r.last().map(|r| (r.step, r.load)))
                            .or_else(|| {
                                records
                                    .dual
                                    .and_then(|r| r.last().map(|r| (r.step, r.load)))
                            });
                        if let Some((step, load)) = last.filter(|&(s, l)| w.due(s + 1, l)) {
                            let mut fields = Vec::new();
                            if want_continuum {
                                fields.push(("continuum", records.continuum_fields));
                            }
                            if want_dual {
                                fields.push(("dual", records.dual_fields));
                            }
                            w.write(step + 1, load, records.model, &fields);
                        }
                    }
                    let mut steps = 0;
                    if let Some(recs) = records.continuum {
                        for (v, vr) in result.variables.iter_mut().enumerate() {
                            let steps_of = recs.iter().map(|r| (r.load, r.derivatives.as_slice()));
                            extend_column(&mut vr.continuum, &nominal.loads, steps_of, v);
                        }
                        steps = recs.len();
                    }
                    if let Some(recs) = records.dual {
                        for (v, vr) in result.variables.iter_mut().enumerate() {
                            let steps_of = recs.iter().map(|r| (r.load, r.derivatives.as_slice()));
                            extend_column(&mut vr.dual, &nominal.loads, steps_of, v);
                        }
                        steps = steps.max(recs.len());
                    }
                    update_if_due(update, &mut schedule, &result, steps);
                },
            )
            .map_err(DsaError::from)
        });
        match runs {
            Ok(runs) => runs,
            Err(e) => {
                // The derivatives of the steps that converged before the failure are kept.
                fail(&mut result, progress, DsaFailure::method(methods_name, e));
                (None, None)
            }
        }
    } else {
        (None, None)
    };

    let vtu_time = vtu
        .as_ref()
        .map_or(0.0, |w| w.time().as_secs_f64() - vtu_before_run);
    if let Some(w) = vtu {
        result.time_vtu = Some(w.time().as_secs_f64());
        result.vtu_error = w.error().map(Failure::to_string);
        result.vtu = w.written().to_vec();
    }

    // (2a) The continuum DSA.
    if let Some(r) = continuum_run {
        let loads: Vec<f64> = r.records.iter().map(|s| s.load).collect();
        if loads != nominal.loads {
            let e = DsaError::LoadLevels {
                levels: loads,
                nominal: nominal.loads.clone(),
            };
            fail(&mut result, progress, DsaFailure::method("continuum", e));
            for v in &mut result.variables {
                v.continuum = None;
            }
        } else {
            result.continuum_value_difference = Some(value_difference(
                &nominal.values,
                r.records.iter().map(|s| s.values.as_slice()),
            ));
            result.time_continuum = Some(r.dsa.as_secs_f64());
            result.time_continuum_run = Some(r.total.as_secs_f64() - vtu_time);
            result.continuum_stages = Some(r.timing);
            progress(&format!(
                "continuum: {} variable(s), DSA {:.3} s in a run of {:.2} s",
                vars.len(),
                r.dsa.as_secs_f64(),
                r.total.as_secs_f64()
            ));
            let d = by_variable(
                vars.len(),
                r.records.iter().map(|s| s.derivatives.as_slice()),
            );
            for (v, d) in result.variables.iter_mut().zip(d) {
                v.continuum = Some(d);
            }
        }
    }

    // (2b) The dual reference.
    if let Some(r) = dual_run {
        let loads: Vec<f64> = r.records.iter().map(|s| s.load).collect();
        if loads != nominal.loads {
            let e = DsaError::LoadLevels {
                levels: loads,
                nominal: nominal.loads.clone(),
            };
            fail(&mut result, progress, DsaFailure::method("dual", e));
            for v in &mut result.variables {
                v.dual = None;
            }
        } else {
            result.dual_value_difference = Some(value_difference(
                &nominal.values,
                r.records.iter().map(|s| s.values.as_slice()),
            ));
            result.dual_state_mismatch = Some(
                r.records
                    .iter()
                    .map(|s| s.value_mismatch)
                    .fold(0.0f64, f64::max),
            );
            result.time_dual = Some(r.reference.as_secs_f64());
            result.time_dual_run = Some(r.total.as_secs_f64() - vtu_time);
            progress(&format!(
                "dual: {} variable(s), reference {:.2} s in a run of {:.2} s",
                vars.len(),
                r.reference.as_secs_f64(),
                r.total.as_secs_f64()
            ));
            let d = by_variable(
                vars.len(),
                r.records.iter().map(|s| s.derivatives.as_slice()),
            );
            for (v, d) in result.variables.iter_mut().zip(d) {
                v.dual = Some(d);
            }
        }
    }
    if want_continuum || want_dual {
        update(&result);
    }

    // (3) Finite differences: per variable and step size, the re-runs at τ ± h. A failed
    // re-run is recorded (variable, h) and the other step sizes and variables still run.
    let run_fd = spec.methods.contains(&DsaMethod::Fd);
    let total_runs: usize = if run_fd {
        spec.design.iter().map(|d| 2 * d.fd_steps.len()).sum()
    } else {
        0
    };
    let t_fd = Instant::now();
    let mut done = 0;
    // The re-runs converge to `fd::RERUN_RESIDUAL_RTOL`, so they are compared with a nominal
    // run converged as far (the Taylor remainders and the active-set flags), not with the
    // plain analysis converged to the case's tolerance.
    let fd_nominal = if run_fd {
        let t = Instant::now();
        let r = fd::run_at(analysis, base, monitors)
            .map_err(DsaError::from)
            .and_then(|r| {
                if r.loads == nominal.loads {
                    Ok(r)
                } else {
                    Err(DsaError::LoadLevels {
                        levels: r.loads.clone(),
                        nominal: nominal.loads.clone(),
                    })
                }
            });
        match r {
            Ok(r) => {
                progress(&format!(
                    "fd: nominal design converged to {:e} in {:.2} s",
                    fd::RERUN_RESIDUAL_RTOL,
                    t.elapsed().as_secs_f64()
                ));
                Some(r)
            }
            Err(e) => {
                let f = DsaFailure {
                    method: "fd".into(),
                    variable: None,
                    h: None,
                    relative: None,
                    message: format!("the nominal run of the finite differences: {e}"),
                };
                fail(&mut result, progress, f);
                update(&result);
                None
            }
        }
    } else {
        None
    };
    for (v, entry) in spec.design.iter().enumerate() {
        let Some(nominal) = fd_nominal.as_ref() else {
            break;
        };
        let var = &entry.variable;
        for (&relative, h) in entry.fd_steps.iter().zip(entry.absolute_steps(base)) {
            let mut one = |delta: f64| -> Result<RunResponse, DsaError> {
                let t = Instant::now();
                done += 1;
                let design = var.perturbed(base, delta).map_err(SensitivityError::from)?;
                let r = fd::run_at(analysis, &design, monitors)?;
                fd::same_steps(var, delta, nominal, &r)?;
                progress(&format!(
                    "fd {done}/{total_runs}: `{}` {} h (h/|τ| = {relative:e}, h = {delta:.4e}) \
                     in {:.2} s",
                    var.name,
                    if delta > 0.0 { "+" } else { "−" },
                    t.elapsed().as_secs_f64()
                ));
                Ok(r)
            };
            let runs = one(h)
                .map_err(|e| (h, e))
                .and_then(|plus| one(-h).map(|minus| (plus, minus)).map_err(|e| (-h, e)));
            let (plus, minus) = match runs {
                Ok(r) => r,
                Err((delta, e)) => {
                    let f = DsaFailure {
                        method: "fd".into(),
                        variable: Some(var.name.clone()),
                        h: Some(delta),
                        relative: Some(relative),
                        message: e.to_string(),
                    };
                    fail(&mut result, progress, f);
                    if delta > 0.0 {
                        // The pair's τ − h run is not made.
                        done += 1;
                    }
                    update(&result);
                    continue;
                }
            };
            let derivatives = fd::central(&plus, &minus, h);
            // The Taylor test checks the continuum derivative when it ran, else the dual one.
            let vr = &mut result.variables[v];
            let taylor = vr
                .continuum
                .as_ref()
                .or(vr.dual.as_ref())
                .map(|d| fd::taylor_row(&plus, nominal, d, h));
            vr.fd.push(FdColumn {
                relative,
                h,
                derivatives,
                flagged: fd::flags(&[&minus, nominal, &plus]),
                taylor,
            });
            let rows: Vec<TaylorRow> = vr.fd.iter().filter_map(|c| c.taylor.clone()).collect();
            vr.taylor = if rows.is_empty() {
                Vec::new()
            } else {
                // Steps past a derivative column cut short by a failed method have no
                // remainder.
                (0..nominal.loads.len())
                    .take_while(|&s| rows.iter().all(|r| s < r.remainder.len()))
                    .map(|s| fit_rate(&rows, s))
                    .collect()
            };
            result.time_fd = Some(t_fd.elapsed().as_secs_f64());
            update(&result);
        }
    }
    result.time_fd = run_fd.then(|| t_fd.elapsed().as_secs_f64());
    Ok(result)
}

/// `update(result)` when `schedule` has a rewrite due at `steps` converged steps.
fn update_if_due(
    update: &mut dyn FnMut(&DsaResult),
    schedule: &mut RewriteSchedule,
    result: &DsaResult,
    steps: usize,
) {
    if schedule.due(steps) {
        let t = Instant::now();
        update(result);
        schedule.wrote(steps, t.elapsed());
    }
}

/// Append to `to` the steps of `from` it does not have yet.
fn extend_response(to: &mut RunResponse, from: &RunResponse) {
    let have = to.loads.len();
    to.loads
        .extend_from_slice(&from.loads[have.min(from.loads.len())..]);
    to.values.extend(from.values.iter().skip(have).cloned());
    to.yielding.extend(from.yielding.iter().skip(have).cloned());
    to.contact.extend(from.contact.iter().skip(have).cloned());
}

/// Append to the column of variable `v` (`column[step][monitor]`) the derivatives of the hooked
/// run's steps (`(load, derivatives[monitor][variable])`) it does not have yet, as long as each
/// step's load is the plain analysis' load of the same step (a column only holds steps
/// comparable with the plain run's).
fn extend_column<'a>(
    column: &mut Option<Vec<Vec<f64>>>,
    loads: &[f64],
    steps: impl Iterator<Item = (f64, &'a [Vec<f64>])>,
    v: usize,
) {
    let column = column.get_or_insert_with(Vec::new);
    for (s, (load, d)) in steps.enumerate().skip(column.len()) {
        if loads.get(s) != Some(&load) {
            break;
        }
        column.push(d.iter().map(|m| m[v]).collect());
    }
}

/// Record a failure and report it on the progress lines.
fn fail(result: &mut DsaResult, progress: &mut dyn FnMut(&str), f: DsaFailure) {
    progress(&format!("failed: {f}"));
    result.failures.push(f);
}

/// Largest difference of a hooked run's monitor values from the plain analysis', relative to
/// the largest monitor magnitude.
fn value_difference<'a>(nominal: &[Vec<f64>], run: impl Iterator<Item = &'a [f64]>) -> f64 {
    let scale = nominal.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
    let diff = run
        .zip(nominal)
        .flat_map(|(s, n)| s.iter().zip(n).map(|(a, b)| (a - b).abs()))
        .fold(0.0f64, f64::max);
    if scale > 0.0 {
        diff / scale
    } else {
        diff
    }
}

/// The largest `|continuum − dual|` over the steps and monitors, relative to the largest
/// `|dual|` (`None` unless both ran).
pub fn continuum_vs_dual(v: &VariableResult) -> Option<f64> {
    let (c, d) = (v.continuum.as_ref()?, v.dual.as_ref()?);
    let big = d.iter().flatten().fold(0.0f64, |a, x| a.max(x.abs()));
    let diff = c
        .iter()
        .flatten()
        .zip(d.iter().flatten())
        .fold(0.0f64, |a, (x, y)| a.max((x - y).abs()));
    Some(if big > 0.0 { diff / big } else { diff })
}

/// The largest `|fd/ψ' − 1|` of one step size (`ψ'` continuum when it ran, else dual) over the
/// unflagged steps and the components with `|ψ'| ≥ 1e-6 · max|ψ'|` (the variable's largest
/// over all steps and monitors); `None` without a derivative method or without an unflagged
/// non-zero component.
pub fn max_rel_diff(v: &VariableResult, c: &FdColumn) -> Option<f64> {
    let d = v.continuum.as_ref().or(v.dual.as_ref())?;
    let big = d.iter().flatten().fold(0.0f64, |a, x| a.max(x.abs()));
    let mut out: Option<f64> = None;
    for (s, row) in d.iter().enumerate() {
        if c.flagged[s] {
            continue;
        }
        for (m, g) in row.iter().enumerate() {
            if big > 0.0 && g.abs() >= 1e-6 * big {
                let e = (c.derivatives[s][m] / g - 1.0).abs();
                out = Some(out.map_or(e, |o: f64| o.max(e)));
            }
        }
    }
    out
}

/// `--terms STEP`: the term-by-term breakdown of the continuum fictitious load against the dual
/// reference at converged step `step` (1-based), one entry per design variable
/// ([`crate::sensitivity::terms`]).
pub fn terms(
    analysis: &dyn Analysis,
    base: &Design,
    spec: &DsaSpec,
    step: usize,
) -> Result<Vec<TermBreakdown>, DsaError> {
    let (problem, newton) = analysis.build(base)?;
    let vars = spec.variables();
    Ok(breakdown(
        problem,
        base.surface.as_ref(),
        vars,
        &newton,
        analysis.solver(),
        step,
    )?)
}
