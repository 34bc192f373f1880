//! Finite differences of complete re-runs (path 4 of `docs/sensitivity.md`): central
//! differences for a list of step sizes (the step-size study) and the Taylor remainder test
//! `|ψ(τ + h) − ψ(τ) − h ψ'|`, which falls as `h²` when `ψ'` is the derivative of the discrete
//! response, with its observed rate fitted over the step sizes.
//!
//! **Same discrete function.** The response of a path-dependent analysis depends on its load
//! steps, so every re-run must take the nominal run's steps: a re-run whose converged load
//! levels differ (bit for bit) is an error ([`SensitivityError::StepSequence`]). Cases for
//! finite differences therefore prescribe their steps (equal steps, no growth, or `stops` at
//! every level); with `stops` at every level a re-run reaches a level whose direct attempt
//! fails by continuation ([`crate::solver::StopFailure::Continuation`]: the committed state
//! solves the same equations from the same committed history, only Newton's start differs).
//!
//! **Active set.** The response is only piecewise smooth in the design: a layer point that
//! yields at a step in one run and not in another (the yield status changes within `±h`) puts
//! a kink between them; so does a contact slave point that penetrates a tool at a converged
//! step in one run and not in another (the penalty force switches on at `g = 0`, eq 69;
//! recorded for the problem's contact load, [`response`]). Such a step, and every later one
//! (the history carries the kink), is *flagged*: its difference is reported but left out of
//! comparisons and of the rate fit, never silently ([`CentralDifference::flagged`], [`TaylorFit::excluded`]).
//!
//! **Converged below the differences.** A run converged to the case's Newton tolerance carries
//! an iteration error that depends smoothly on the design (the iterates, not only the
//! solution, move with `τ`), so `ψ(τ + h) − ψ(τ)` carries an error proportional to `h`: on the
//! jittered plastic hemisphere at `residual_rtol = 1e-8`, 2.5e-12 · |ψ| at `h = 10⁻³ τ` where
//! the converged state does not depend on `σ0` at all, which the Taylor fit read as a rate
//! of 1. Every run of this module ([`run_at`]), the nominal one included, therefore converges
//! to at least [`RERUN_RESIDUAL_RTOL`]; that remainder fell to 3 ε |ψ|, and a remainder at the
//! responses' round-off is reported apart ([`TaylorFit::roundoff`]), not fitted.

use super::dual::SensitivityError;
use super::{Design, DesignVariable, Monitor};
use crate::shell::problem::ShellProblem;
use crate::solver::observe::{Observed, StepObserver, Tapped};
use crate::solver::Failure;
use crate::solver::{LinearSolver, Method, NewtonSolver, SolverOptions};

/// The monitored responses of one complete run.
#[derive(Clone, Debug, PartialEq)]
pub struct RunResponse {
    /// Load factor of every converged step.
    pub loads: Vec<f64>,
    /// `values[step][monitor]`.
    pub values: Vec<Vec<f64>>,
    /// `yielding[step][layer point]`: whether the point's `ē^p` grew in the step.
    pub yielding: Vec<Vec<bool>>,
    /// `contact[step][slave point]`: whether the slave point penetrates a tool at the
    /// converged state (empty without contact): the contact part of the active set.
    pub contact: Vec<Vec<bool>>,
}

/// The recorder of the monitors, yield and contact status after every commit (an observer of
/// the problem's converged steps).
struct Recording<'a> {
    monitors: &'a [Monitor],
    out: RunResponse,
    /// `ē^p` of every layer point at the step start.
    before: Vec<f64>,
    failure: Option<Failure>,
}

impl StepObserver<ShellProblem> for Recording<'_> {
    fn before_commit(&mut self, problem: &ShellProblem, _u: &[f64], _load: f64) {
        self.before.clear();
        self.before
            .extend(problem.model.history.iter().map(|h| h.material.eps_p));
    }
    fn after_commit(&mut self, problem: &ShellProblem, _u: &[f64], load: f64) {
        let model = &problem.model;
        let yielding = self
            .before
            .iter()
            .zip(&model.history)
            .map(|(a, h)| h.material.eps_p > *a)
            .collect();
        let values = super::monitor_values(problem, load, self.monitors);
        let contact = match super::contact_load(problem) {
            None => Ok(Vec::new()),
            Some(c) => c
                .contact
                .report(model, &vec![0.0; model.n_dofs()], load)
                .map(|r| r.slaves.iter().map(|s| s.pressure > 0.0).collect()),
        };
        type Error = Box<dyn std::error::Error + Send + Sync>;
        match (|| -> Result<_, Error> { Ok((values?, contact?)) })() {
            Ok((v, c)) => {
                self.out.loads.push(load);
                self.out.values.push(v);
                self.out.yielding.push(yielding);
                self.out.contact.push(c);
            }
            Err(e) => {
                self.failure.get_or_insert(Failure::new("monitor", e));
            }
        }
    }
    fn failure(&self) -> Option<Failure> {
        self.failure.clone()
    }
}

/// Run `problem` with `newton` and record `monitors` (and the contact status of every slave
/// point of the problem's contact) at every converged step.
pub fn response(
    problem: ShellProblem,
    newton: &NewtonSolver,
    solver: SolverOptions,
    monitors: &[Monitor],
) -> Result<RunResponse, SensitivityError> {
    response_observed(problem, newton, solver, monitors, &mut |_| {})
}

/// As [`response`]; `on_step` sees the responses so far after every converged step (to write
/// them as the run goes).
pub fn response_observed(
    problem: ShellProblem,
    newton: &NewtonSolver,
    solver: SolverOptions,
    monitors: &[Monitor],
    on_step: &mut dyn FnMut(&RunResponse),
) -> Result<RunResponse, SensitivityError> {
    let pattern = problem.pattern().clone();
    let mut linear = LinearSolver::new(&pattern, Method::auto(&pattern), solver)?;
    let u0 = problem.state().to_vec();
    let rec = Recording {
        monitors,
        out: RunResponse {
            loads: Vec::new(),
            values: Vec::new(),
            yielding: Vec::new(),
            contact: Vec::new(),
        },
        before: Vec::new(),
        failure: None,
    };
    let mut tap = |_: &ShellProblem, r: &Recording<'_>| on_step(&r.out);
    let mut p = Observed::new(problem, Tapped::new(rec, &mut tap));
    newton
        .run(&mut p, &pattern, &mut linear, &u0)
        .map_err(SensitivityError::Newton)?;
    if let Some(f) = p.observer.failure() {
        return Err(SensitivityError::Observer(f));
    }
    Ok(p.observer.observer.out)
}

/// Builds the analysis for a design: the problem and its driver.
pub trait Analysis {
    /// The problem (at its initial state) and the driver for `design`.
    fn build(&self, design: &Design) -> Result<(ShellProblem, NewtonSolver), SensitivityError>;
    /// Linear solver options.
    fn solver(&self) -> SolverOptions {
        SolverOptions::default()
    }
}

/// The relative residual tolerance every finite-difference run converges to when its case
/// asks for less (module documentation). With it the Newton iteration's error is below the
/// smallest Taylor remainders a study resolves (about 1e-9 |ψ| on the shipped cases); the
/// acceptance at the residual's round-off floor still ends a step whose residual cannot fall
/// that far.
pub const RERUN_RESIDUAL_RTOL: f64 = 1e-12;

/// A remainder at most `ROUNDOFF_FACTOR · ε · max_m |ψ_m(τ)|` is at the responses' round-off
/// ([`TaylorFit::roundoff`]): the unknowns of a converged run are known to about `ε |u|`, and
/// the Newton driver's round-off floor was measured at up to 10³ `ε` times its estimate
/// (`crate::solver::newton`).
pub const ROUNDOFF_FACTOR: f64 = 1e3;

/// One complete run of `analysis` at `design`, recording `monitors` (and the contact status),
/// converged to at least [`RERUN_RESIDUAL_RTOL`].
pub fn run_at(
    analysis: &dyn Analysis,
    design: &Design,
    monitors: &[Monitor],
) -> Result<RunResponse, SensitivityError> {
    let (problem, mut newton) = analysis.build(design)?;
    newton.options.residual_rtol = newton.options.residual_rtol.min(RERUN_RESIDUAL_RTOL);
    response(problem, &newton, analysis.solver(), monitors)
}

/// A re-run at `τ + h` is comparable with the nominal run only on the same load levels
/// ([`SensitivityError::StepSequence`] otherwise, naming where they part).
pub fn same_steps(
    variable: &DesignVariable,
    h: f64,
    nominal: &RunResponse,
    other: &RunResponse,
) -> Result<(), SensitivityError> {
    if nominal.loads != other.loads {
        return Err(SensitivityError::StepSequence {
            variable: variable.name.clone(),
            h,
            detail: load_levels_differ(&other.loads, &nominal.loads, "nominal run"),
        });
    }
    Ok(())
}

/// How the converged load levels `run` differ from those of `reference` (named
/// `reference_name`), for an error message: the first step where they part, or the step
/// counts.
pub fn load_levels_differ(run: &[f64], reference: &[f64], reference_name: &str) -> String {
    match run.iter().zip(reference).position(|(a, b)| a != b) {
        Some(k) => format!(
            "the converged load level of step {} is {} where the {reference_name} has {} \
             ({} steps against {}: a step was cut or grown differently); prescribe the steps \
             or take a smaller step size",
            k + 1,
            run[k],
            reference[k],
            run.len(),
            reference.len()
        ),
        None => format!(
            "{} converged steps where the {reference_name} has {} (the same levels up to \
             there); prescribe the steps",
            run.len(),
            reference.len()
        ),
    }
}

/// Per step, whether the yield status of any layer point, or the contact status of any slave
/// point, differs between the runs at this or an earlier step.
pub fn flags(runs: &[&RunResponse]) -> Vec<bool> {
    let n = runs[0].yielding.len();
    let mut flagged = false;
    (0..n)
        .map(|s| {
            flagged |= runs.windows(2).any(|w| {
                w[0].yielding[s] != w[1].yielding[s] || w[0].contact.get(s) != w[1].contact.get(s)
            });
            flagged
        })
        .collect()
}

/// Central differences of one design variable with one step size.
#[derive(Clone, Debug, PartialEq)]
pub struct CentralDifference {
    /// Step size (absolute, in the variable's units).
    pub h: f64,
    /// `derivatives[step][monitor] = (ψ(τ + h) − ψ(τ − h)) / 2h`.
    pub derivatives: Vec<Vec<f64>>,
    /// Per step: the yield status of some layer point differs among the runs at `τ − h`, `τ`,
    /// `τ + h` at this step or an earlier one (the difference straddles a kink).
    pub flagged: Vec<bool>,
}

/// The nominal run and central differences of `variable` for every step size in `hs`
/// (absolute): two complete re-runs per step size.
pub fn central_differences(
    analysis: &dyn Analysis,
    base: &Design,
    variable: &DesignVariable,
    hs: &[f64],
    monitors: &[Monitor],
) -> Result<(RunResponse, Vec<CentralDifference>), SensitivityError> {
    let nominal = run_at(analysis, base, monitors)?;
    let mut out = Vec::with_capacity(hs.len());
    for &h in hs {
        let plus = run_at(analysis, &variable.perturbed(base, h)?, monitors)?;
        let minus = run_at(analysis, &variable.perturbed(base, -h)?, monitors)?;
        same_steps(variable, h, &nominal, &plus)?;
        same_steps(variable, -h, &nominal, &minus)?;
        out.push(CentralDifference {
            h,
            derivatives: central(&plus, &minus, h),
            flagged: flags(&[&minus, &nominal, &plus]),
        });
    }
    Ok((nominal, out))
}

/// The central differences `(ψ(τ + h) − ψ(τ − h)) / 2h` of the runs at `τ ± h`, per step and
/// monitor.
pub fn central(plus: &RunResponse, minus: &RunResponse, h: f64) -> Vec<Vec<f64>> {
    plus.values
        .iter()
        .zip(&minus.values)
        .map(|(p, m)| p.iter().zip(m).map(|(a, b)| (a - b) / (2.0 * h)).collect())
        .collect()
}

/// The Taylor remainder for one step size.
#[derive(Clone, Debug, PartialEq)]
pub struct TaylorRow {
    /// Step size.
    pub h: f64,
    /// Per step: `max_m |ψ_m(τ + h) − ψ_m(τ) − h ψ'_m|` over the monitors.
    pub remainder: Vec<f64>,
    /// Per step: the yield status differs between `τ` and `τ + h` (at this or an earlier step).
    pub flagged: Vec<bool>,
    /// Per step: `max_m |ψ_m(τ)|`, the scale of the responses' round-off.
    pub scale: Vec<f64>,
}

/// The Taylor remainder of `derivatives[step][monitor]` (the sensitivity under test, e.g. the
/// dual reference) for every step size in `hs`: one re-run per step size.
pub fn taylor_remainders(
    analysis: &dyn Analysis,
    base: &Design,
    variable: &DesignVariable,
    hs: &[f64],
    monitors: &[Monitor],
    nominal: &RunResponse,
    derivatives: &[Vec<f64>],
) -> Result<Vec<TaylorRow>, SensitivityError> {
    let mut rows = Vec::with_capacity(hs.len());
    for &h in hs {
        let plus = run_at(analysis, &variable.perturbed(base, h)?, monitors)?;
        same_steps(variable, h, nominal, &plus)?;
        rows.push(taylor_row(&plus, nominal, derivatives, h));
    }
    Ok(rows)
}

/// The Taylor remainder `max_m |ψ_m(τ + h) − ψ_m(τ) − h ψ'_m|` per step of the run `plus` at
/// `τ + h` against the `nominal` run and `derivatives[step][monitor]` (`ψ'`); flagged where
/// the active set differs between the two runs.
pub fn taylor_row(
    plus: &RunResponse,
    nominal: &RunResponse,
    derivatives: &[Vec<f64>],
    h: f64,
) -> TaylorRow {
    let remainder = plus
        .values
        .iter()
        .zip(&nominal.values)
        .zip(derivatives)
        .map(|((p, n), d)| {
            p.iter()
                .zip(n)
                .zip(d)
                .map(|((a, b), g)| (a - b - h * g).abs())
                .fold(0.0, f64::max)
        })
        .collect();
    TaylorRow {
        h,
        remainder,
        flagged: flags(&[nominal, plus]),
        scale: nominal
            .values
            .iter()
            .map(|v| v.iter().fold(0.0f64, |a, x| a.max(x.abs())))
            .collect(),
    }
}

/// The observed rate of the Taylor remainder at one step.
#[derive(Clone, Debug, PartialEq)]
pub struct TaylorFit {
    /// Step index.
    pub step: usize,
    /// Least-squares slope of `ln remainder` against `ln h` over the used rows (`None` with
    /// fewer than two).
    pub rate: Option<f64>,
    /// Step sizes used.
    pub used: Vec<f64>,
    /// Step sizes left out because the active set changed within `h` (reported, not used).
    pub excluded: Vec<f64>,
    /// Step sizes left out because the remainder is exactly zero (a response that does not
    /// depend on the variable at this step, e.g. σ0 before first yield).
    pub exact: Vec<f64>,
    /// Step sizes left out because the remainder is positive but at most
    /// [`ROUNDOFF_FACTOR`]` · ε · max_m |ψ_m(τ)|`: the responses' round-off, which has no rate
    /// (e.g. σ0 at a step whose converged state no yielding point reaches, where Newton's
    /// intermediate iterates did yield).
    pub roundoff: Vec<f64>,
}

/// Fit the rate of the remainders at `step` over the unflagged rows with a remainder above the
/// responses' round-off.
pub fn fit_rate(rows: &[TaylorRow], step: usize) -> TaylorFit {
    let (mut used, mut excluded, mut exact, mut roundoff) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut pts = Vec::new();
    for r in rows {
        if r.flagged[step] {
            excluded.push(r.h);
        } else if r.remainder[step] <= 0.0 {
            exact.push(r.h);
        } else if r.remainder[step] <= ROUNDOFF_FACTOR * f64::EPSILON * r.scale[step] {
            roundoff.push(r.h);
        } else {
            used.push(r.h);
            pts.push((r.h.abs().ln(), r.remainder[step].ln()));
        }
    }
    let rate = (pts.len() >= 2).then(|| {
        let n = pts.len() as f64;
        let mx = pts.iter().map(|p| p.0).sum::<f64>() / n;
        let my = pts.iter().map(|p| p.1).sum::<f64>() / n;
        let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
        let sxx: f64 = pts.iter().map(|p| (p.0 - mx) * (p.0 - mx)).sum();
        sxy / sxx
    });
    TaylorFit {
        step,
        rate,
        used,
        excluded,
        exact,
        roundoff,
    }
}
