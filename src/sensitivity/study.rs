//! `shelldsa dsa`: the design sensitivities of a shell case by the hand-derived continuum DSA,
//! the dual-number reference and central differences of complete re-runs, the table in the
//! format of the paper's Tables 1–2, and `sensitivity.json` (`docs/sensitivity.md`).
//!
//! Order of the runs: (1) the plain analysis (no hook; its wall time is `timing_s.analysis`,
//! and its monitors are the nominal responses `ψ(τ)` of the finite differences); (2a) the
//! analysis with the continuum DSA in its convergence hook (`timing_s.continuum` is the DSA's
//! own time inside it); (2b) the analysis with the dual reference in its convergence hook
//! (one run gives the responses and the derivatives of every design variable;
//! `timing_s.dual` is the reference's own time inside it); (3) per design variable and
//! relative step, the re-runs at `τ ± h` (`timing_s.fd`, all of them). The Taylor remainder
//! `|ψ(τ + h) − ψ(τ) − h ψ'|` of every step size reuses the `τ + h` re-run.

use super::dsa_case::{
    check_dsa_loads, check_load_control, check_tool_names, DesignEntry, DsaMethod, DsaSpec,
};
use super::shell_build;
use super::shell_case::ShellCase;
use super::shell_output::{
    add_sensitivity_fields, shell_vtu_with_contact, OutputGrid, SensitivityField, PVD_FILE,
};
use super::vtu::PvdCollection;
use super::CaseError;
use super::RewriteSchedule;
use crate::sensitivity::dual::{DualMode, SensitivityError};
use crate::sensitivity::fd::{self, fit_rate, Analysis, RunResponse, TaylorFit, TaylorRow};
use crate::sensitivity::terms::{breakdown, TermBreakdown};
use crate::sensitivity::{
    run_hooked, validate_design_on, Design, DesignVariable, HookedMethods, Quantity,
    SensitivityFields,
};
use crate::shell::contact::ShellContact;
use crate::shell::model::ShellModel;
use crate::shell::problem::ShellProblem;
use crate::shell::ShellError;
use crate::solver::NewtonSolver;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;
use thiserror::Error;

/// Errors of a `dsa` run.
#[derive(Debug, Error)]
pub enum DsaError {
    /// The case has no `[[design]]` table.
    #[error(
        "case file {0}: no [[design]] table: `shelldsa dsa` needs at least one design variable"
    )]
    NoDesign(String),
    /// Invalid case input (design variables, loads the reference cannot carry).
    #[error(transparent)]
    Case(#[from] CaseError),
    /// The analysis or a method failed.
    #[error(transparent)]
    Sensitivity(#[from] SensitivityError),
    /// A hooked run took other load steps than the plain analysis.
    #[error("{0}")]
    Inconsistent(String),
    /// `--terms STEP` beyond the converged steps of the plain analysis.
    #[error("--terms {step}: expected a converged load step in 1..={steps}")]
    StepOutOfRange {
        /// The step asked for.
        step: usize,
        /// Converged steps of the plain analysis.
        steps: usize,
    },
    /// A feature of the analysis that the sensitivity methods do not carry.
    #[error("case file {path}: `{key}` = {value}: {why}")]
    Unsupported {
        /// The case file.
        path: String,
        /// The key.
        key: &'static str,
        /// Its value.
        value: String,
        /// What is missing.
        why: &'static str,
    },
}

/// The case's analysis for any design: the case with `thickness` and `material` replaced.
pub struct CaseAnalysis<'a> {
    /// The case.
    pub case: &'a ShellCase,
}

impl Analysis for CaseAnalysis<'_> {
    fn build(&self, design: &Design) -> Result<(ShellProblem, NewtonSolver), SensitivityError> {
        self.build_with_contact(design).map(|(p, n, _)| (p, n))
    }

    /// The case with the design's thickness, material and tool offsets (each tool's whole path
    /// translated, [`crate::contact::ToolPath::translated`], and the tool as built rotated
    /// about its pivot, [`crate::contact::ToolPath::rotated`]), and its contact.
    fn build_with_contact(
        &self,
        design: &Design,
    ) -> Result<(ShellProblem, NewtonSolver, Option<Arc<ShellContact>>), SensitivityError> {
        let mut c = self.case.clone();
        c.thickness = design.thickness;
        c.material = design.material;
        if let Some(surface) = &design.surface {
            // A shape design: the same case on the perturbed surface (the discretisation,
            // boundaries, loads and monitors live on the parameter domain and stay).
            c.surface = surface.clone();
        }
        for (name, offset) in &design.tool_offsets {
            let tool = c
                .tools
                .iter_mut()
                .find(|t| &t.name == name)
                .ok_or_else(|| {
                    SensitivityError::Design(crate::sensitivity::DesignError::UnknownTool {
                        variable: name.clone(),
                        tool: name.clone(),
                        expected: format!(
                            "{:?}",
                            self.case.tools.iter().map(|t| &t.name).collect::<Vec<_>>()
                        ),
                    })
                })?;
            tool.path = tool
                .path
                .translated(offset.translation)
                .and_then(|p| p.rotated(offset.rotation))
                .map_err(|e| {
                    SensitivityError::Shell(ShellError::InvalidInput(format!(
                        "tool `{name}` moved by {:?} and rotated by {:?}: {e}",
                        offset.translation, offset.rotation
                    )))
                })?;
        }
        let b = shell_build::build(&c).map_err(|e| {
            SensitivityError::Shell(ShellError::InvalidInput(format!(
                "{}: {e}",
                self.case.path.display()
            )))
        })?;
        Ok((b.problem, b.newton, b.contact))
    }
}

/// A sensitivity method's problem for `design`: the problem (which owns its loads) and its
/// driver.
fn method_problem(
    analysis: &CaseAnalysis<'_>,
    design: &Design,
) -> Result<(ShellProblem, NewtonSolver), DsaError> {
    let (problem, newton, _) = analysis.build_with_contact(design)?;
    Ok((problem, newton))
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

/// The case's nominal design: thickness, material and surface.
pub fn base_design(case: &ShellCase) -> Design {
    Design {
        thickness: case.thickness,
        material: case.material,
        surface: Some(case.surface.clone()),
        tool_offsets: Default::default(),
    }
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
    /// The VTU files of the run with the derivative methods ([`StepVtu`]), relative to the
    /// output directory.
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

/// The VTU files of the run that carries the derivative methods, in the plain run's layout
/// (`[output] vtu`, `every`, `subdivide`; `shell.pvd` and `steps/step_NNNN.vtu`, step 0 the
/// initial state, every `every`-th converged step and the one reaching `final_load`): every
/// array of the plain run's VTU ([`shell_vtu_with_contact`]) and, per design variable and
/// method, the sensitivity fields of [`add_sensitivity_fields`], named
/// `d_u/d_<variable> (<method>)` and `d_eps_p_<top|mid|bottom>/d_<variable> (<method>)`.
pub struct StepVtu<'a> {
    dir: PathBuf,
    case: &'a ShellCase,
    grid: OutputGrid,
    contact: Option<Arc<ShellContact>>,
    variables: Vec<String>,
    pvd: PvdCollection,
    time: std::time::Duration,
    written: Vec<VtuStep>,
    error: Option<String>,
}

impl<'a> StepVtu<'a> {
    /// The writer into `dir` for `case`'s output grid, with the hooked run's `contact` (for
    /// the contact pressure) and the names of its design variables.
    pub fn new(
        dir: &Path,
        case: &'a ShellCase,
        contact: Option<Arc<ShellContact>>,
        variables: Vec<String>,
    ) -> Result<Self, String> {
        let cq = shell_build::particle_grid(case);
        let cq = shell_build::cell_quadrature(case, &cq).map_err(|e| e.to_string())?;
        let grid = OutputGrid::new(&cq, case.output.subdivide).map_err(|e| e.to_string())?;
        let steps = dir.join("steps");
        std::fs::create_dir_all(&steps)
            .map_err(|e| format!("cannot create {}: {e}", steps.display()))?;
        Ok(StepVtu {
            dir: dir.to_owned(),
            case,
            grid,
            contact,
            variables,
            pvd: PvdCollection::new(dir.join(PVD_FILE)),
            time: std::time::Duration::ZERO,
            written: Vec::new(),
            error: None,
        })
    }

    /// Whether converged step `step` (1-based) at `load` is written: every `every`-th and the
    /// one reaching `final_load` (as the plain run).
    pub fn due(&self, step: usize, load: f64) -> bool {
        let s = &self.case.steps;
        let last = (s.final_load - load).abs() <= 1e-12 * s.final_load.abs().max(1.0);
        self.error.is_none() && (step % self.case.output.every == 0 || last)
    }

    /// Write step `step` at `load` of `model` with the methods' committed sensitivities
    /// (`(method name, fields)`; `None` fields: zero, the initial state). A failure is kept
    /// ([`Self::error`]) and stops further writing.
    pub fn write(
        &mut self,
        step: usize,
        load: f64,
        model: &ShellModel,
        methods: &[(&str, Option<&dyn SensitivityFields>)],
    ) {
        if self.error.is_some() {
            return;
        }
        let t = Instant::now();
        if let Err(e) = self.write_files(step, load, model, methods) {
            self.error = Some(e);
        }
        self.time += t.elapsed();
    }

    fn write_files(
        &mut self,
        step: usize,
        load: f64,
        model: &ShellModel,
        methods: &[(&str, Option<&dyn SensitivityFields>)],
    ) -> Result<(), String> {
        let pressure = match &self.contact {
            Some(c) => Some(
                c.report(model, &vec![0.0; model.n_dofs()], load)
                    .map_err(|e| format!("contact at step {step}: {e}"))?
                    .pressure,
            ),
            None => None,
        };
        let n_layer_points = model.points.len() * model.thickness_rule.len();
        let mut fields = Vec::new();
        for (method, f) in methods {
            for (v, name) in self.variables.iter().enumerate() {
                let (translations, plastic_strain) = match f {
                    Some(f) => (f.translations(model, v), f.plastic_strain(v)),
                    None => (vec![0.0; model.n_dofs()], vec![0.0; n_layer_points]),
                };
                fields.push(SensitivityField {
                    label: format!("{name} ({method})"),
                    translations,
                    plastic_strain,
                });
            }
        }
        let rel = format!("steps/step_{step:04}.vtu");
        let path = self.dir.join(&rel);
        let w = shell_vtu_with_contact(model, &self.case.surface, &self.grid, pressure.as_deref())
            .and_then(|w| add_sensitivity_fields(w, model, &self.grid, &fields))
            .map_err(|e| format!("{}: {e}", path.display()))?;
        w.write(&path).map_err(|e| e.to_string())?;
        self.pvd
            .add_and_write(load, &rel)
            .map_err(|e| e.to_string())?;
        self.written.push(VtuStep {
            step,
            load,
            file: rel,
        });
        Ok(())
    }

    /// The first error writing the files.
    pub fn error(&self) -> Option<&str> {
        self.error.as_deref()
    }
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

/// Check everything a `dsa` run of `case` with `methods` needs, before any analysis: design
/// variables present and admissible, loads the dual reference can carry, and, on the built
/// model, [`validate_design`](crate::sensitivity::validate_design).
pub fn validate(case: &ShellCase, methods: &[DsaMethod]) -> Result<DsaSpec, DsaError> {
    let mut spec = case
        .dsa
        .clone()
        .ok_or_else(|| DsaError::NoDesign(case.path.display().to_string()))?;
    spec.methods = methods.to_vec();
    check_load_control(case)?;
    check_tool_names(&case.path, &case.tools, &spec)?;
    if methods.contains(&DsaMethod::Dual) || methods.contains(&DsaMethod::Continuum) {
        // Shape variables with contact are carried by both methods: the slave sites take the
        // design velocity of the initial geometry (`shell::contact::InitialGeometry`).
        check_dsa_loads(case)?;
    }
    Ok(spec)
}

/// Run the analysis and the methods of `spec` on `case`; `progress` receives one line per
/// run ([`run_observed`] without the pre-check of a step and without the updates).
pub fn run(
    case: &ShellCase,
    spec: &DsaSpec,
    progress: &mut dyn FnMut(&str),
) -> Result<DsaResult, DsaError> {
    run_observed(case, spec, None, progress, &mut |_| {})
}

/// Run the analysis and the methods of `spec` on `case`. `progress` receives one line per run;
/// `update` the results so far (to write `sensitivity.json` as the run goes): after converged
/// steps of the plain analysis and of the run with the derivative methods (on the schedule of
/// [`RewriteSchedule`]), after each of those runs, after every finite-difference step size of
/// every variable, and before an error of the plain analysis is returned (with its converged
/// steps). With `need_step`, a plain analysis with fewer converged steps is an error
/// before the methods run ([`DsaError::StepOutOfRange`]).
///
/// The checks and the plain analysis are all or nothing: an error there is returned. After it,
/// a failed method or re-run is recorded in [`DsaResult::failures`] (naming the method, the
/// variable and `h`) and everything else still runs and is kept.
pub fn run_observed(
    case: &ShellCase,
    spec: &DsaSpec,
    need_step: Option<usize>,
    progress: &mut dyn FnMut(&str),
    update: &mut dyn FnMut(&DsaResult),
) -> Result<DsaResult, DsaError> {
    run_with_output(case, spec, need_step, None, progress, update)
}

/// [`run_observed`], and with `out` (and `[output] vtu = true`) the VTU files of the run with
/// the derivative methods in `out` ([`StepVtu`]; none when only finite differences run).
pub fn run_with_output(
    case: &ShellCase,
    spec: &DsaSpec,
    need_step: Option<usize>,
    out: Option<&Path>,
    progress: &mut dyn FnMut(&str),
    update: &mut dyn FnMut(&DsaResult),
) -> Result<DsaResult, DsaError> {
    let analysis = CaseAnalysis { case };
    let base = base_design(case);
    let vars: Vec<DesignVariable> = spec.design.iter().map(|d| d.variable.clone()).collect();
    let monitors = &spec.monitors;

    // (1) The plain analysis.
    let t = Instant::now();
    let (problem, newton, contact) = analysis.build_with_contact(&base)?;
    validate_design_on(&vars, &problem.model, &case.surface, 0.0)
        .map_err(SensitivityError::from)?;
    // Every finite-difference design (shape: the perturbed surface with a regular normal at
    // every particle and point of the model) is checked before the analysis.
    if spec.methods.contains(&DsaMethod::Fd) {
        for d in &spec.design {
            for h in d.absolute_steps(&base) {
                d.variable
                    .validate_on(&problem.model, &case.surface, h)
                    .map_err(SensitivityError::from)?;
            }
        }
    }
    let mut result = DsaResult {
        spec: spec.clone(),
        variables: spec
            .design
            .iter()
            .map(|entry| VariableResult {
                entry: entry.clone(),
                value: entry.variable.value(&base),
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
    let run = fd::response_observed(
        problem,
        contact,
        &newton,
        analysis.solver(),
        monitors,
        &mut |r| {
            extend_response(&mut result.nominal, r);
            update_if_due(update, &mut schedule, &result, r.loads.len());
        },
    );
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
        return Err(DsaError::StepOutOfRange {
            step,
            steps: result.nominal.loads.len(),
        });
    }
    update(&result);
    let nominal = result.nominal.clone();

    // With contact, the later runs replay the plain run's load levels: every converged level
    // becomes a `stops` entry and the step size starts at `max_step` (≥ every gap), so each
    // step is clipped to the next level and keeps its size (a clipped step neither grows nor
    // shrinks): the runs land on the same levels whatever their iteration counts (the hooked
    // run needs the converged tangent, and near a change of the contact set an iteration more
    // or less changes the adaptive growth; the discrete response depends on the levels). A
    // re-run that has to cut a step still differs and is reported (`StepSequence`).
    let replay_case;
    let analysis = if case.tools.is_empty() {
        analysis
    } else {
        let mut c = case.clone();
        c.steps.stops = nominal.loads.clone();
        c.steps.initial_step = c.steps.max_step;
        replay_case = c;
        CaseAnalysis { case: &replay_case }
    };

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
    };
    let method_names: Vec<&str> = [(want_continuum, "continuum"), (want_dual, "dual")]
        .into_iter()
        .filter_map(|(w, n)| w.then_some(n))
        .collect();
    let mut vtu: Option<StepVtu> = None;
    let mut vtu_before_run = 0.0;
    let (continuum_run, dual_run) = if want_continuum || want_dual {
        let mut schedule = RewriteSchedule::starting(Instant::now());
        let built = analysis.build_with_contact(&base).map_err(DsaError::from);
        if let (Some(dir), true, Ok((problem, _, contact))) = (out, case.output.vtu, &built) {
            let names = vars.iter().map(|v| v.name.clone()).collect();
            match StepVtu::new(dir, case, contact.clone(), names) {
                Ok(mut w) => {
                    let zero: Vec<_> = method_names.iter().map(|m| (*m, None)).collect();
                    w.write(0, 0.0, &problem.model, &zero);
                    // Only the writes inside the hooked run leave its total.
                    vtu_before_run = w.time.as_secs_f64();
                    vtu = Some(w);
                }
                Err(e) => result.vtu_error = Some(e),
            }
        }
        let runs = built.and_then(|(problem, newton, _)| {
            run_hooked(
                problem,
                Some(&case.surface),
                vars.clone(),
                monitors.clone(),
                &newton,
                analysis.solver(),
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
        .map_or(0.0, |w| w.time.as_secs_f64() - vtu_before_run);
    if let Some(w) = vtu {
        result.time_vtu = Some(w.time.as_secs_f64());
        result.vtu_error = w.error;
        result.vtu = w.written;
    }

    // (2a) The continuum DSA.
    if let Some(r) = continuum_run {
        let loads: Vec<f64> = r.records.iter().map(|s| s.load).collect();
        if loads != nominal.loads {
            let e = DsaError::Inconsistent(fd::load_levels_differ(
                &loads,
                &nominal.loads,
                "plain analysis",
            ));
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
            let e = DsaError::Inconsistent(fd::load_levels_differ(
                &loads,
                &nominal.loads,
                "plain analysis",
            ));
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
    for (v, entry) in spec.design.iter().enumerate() {
        if !run_fd {
            break;
        }
        let var = &entry.variable;
        for (&relative, h) in entry.fd_steps.iter().zip(entry.absolute_steps(&base)) {
            let mut one = |delta: f64| -> Result<RunResponse, DsaError> {
                let t = Instant::now();
                done += 1;
                let (problem, newton, contact) = analysis.build_with_contact(
                    &var.perturbed(&base, delta)
                        .map_err(SensitivityError::from)?,
                )?;
                let r = fd::response_with_contact(
                    problem,
                    contact,
                    &newton,
                    analysis.solver(),
                    monitors,
                )?;
                fd::same_steps(var, delta, &nominal, &r)?;
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
            let derivatives = plus
                .values
                .iter()
                .zip(&minus.values)
                .map(|(p, m)| p.iter().zip(m).map(|(a, b)| (a - b) / (2.0 * h)).collect())
                .collect();
            // The Taylor test checks the continuum derivative when it ran, else the dual one.
            let vr = &mut result.variables[v];
            let taylor = vr
                .continuum
                .as_ref()
                .or(vr.dual.as_ref())
                .map(|d| TaylorRow {
                    h,
                    remainder: plus
                        .values
                        .iter()
                        .zip(&nominal.values)
                        .zip(d)
                        .map(|((p, n), g)| {
                            p.iter()
                                .zip(n)
                                .zip(g)
                                .map(|((a, b), g)| (a - b - h * g).abs())
                                .fold(0.0, f64::max)
                        })
                        .collect(),
                    flagged: fd::flags(&[&nominal, &plus]),
                });
            vr.fd.push(FdColumn {
                relative,
                h,
                derivatives,
                flagged: fd::flags(&[&minus, &nominal, &plus]),
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

/// A number for JSON: `null` when not finite (JSON has no NaN).
fn num(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

/// `sensitivity.json` before any analysis (`status` `"running"`, no steps yet) or after a plain
/// analysis that failed (`status` `"failed: ..."`).
pub fn empty_json(case: &ShellCase, spec: &DsaSpec, status: &str) -> Value {
    json!({
        "kind": "shell-dsa",
        "case": case.path.display().to_string(),
        "title": case.title,
        "status": status,
        "failures": [],
        "methods": spec.methods.iter().map(|m| m.name()).collect::<Vec<_>>(),
        "design_variables": spec.design.iter().map(|d| d.variable.name.clone()).collect::<Vec<_>>(),
        "variables": [],
        "loads": [],
    })
}

/// Write `doc` as `DIR/sensitivity.json` (pretty, replaced whole: a reader or a killed run
/// sees the previous or the new file).
pub fn write_json(path: &std::path::Path, doc: &Value) -> Result<(), String> {
    let text = serde_json::to_string_pretty(doc).map_err(|e| format!("{}: {e}", path.display()))?;
    super::vtu::replace_file(path, text.as_bytes())
        .map_err(|e| format!("cannot write {}: {e}", path.display()))
}

/// The notes written at the top of `sensitivity.json`.
pub const NOTES: [&str; 6] = [
    "continuum: the hand-derived continuum DSA (eqs 37-65: fictitious loads solved with the \
     converged, factorised tangent at every step); dual: the dual-number reference through \
     the same kernels; continuum_vs_dual: per variable, the largest |continuum - dual| \
     relative to max |dual| over the steps and monitors",
    "timing_s.analysis: wall time of a separate plain run of the analysis (no sensitivity \
     hook), the nominal run of the finite differences; timing_s.continuum and timing_s.dual: \
     each method's own time inside its analysis run with the hook (the whole hooked runs: \
     continuum_run_total_s, dual_run_total_s; with both methods asked for, one run observed \
     by both, so the two totals are the same run's); timing_s.continuum_stages: the continuum DSA by stage (fictitious loads, solve, history update, monitors; s); timing_s.fd: all finite-difference re-runs",
    "fd_central and fd_step are lists, one entry per step size of the variable's fd_steps \
     (relative steps h/|tau|; fd_step holds the absolute h); fd_flagged[k] marks load steps \
     where the yield status of some layer point differs among the runs at tau-h, tau, tau+h \
     (at that step or an earlier one): such differences straddle a kink and are not \
     comparable",
    "taylor: per load step, the least-squares slope of log |psi(tau+h) - psi(tau) - h psi'| \
     (max over the monitors; psi' the continuum derivative when it ran, else the dual one) \
     against log h over the unflagged step sizes; 2 when psi' is the derivative of the \
     discrete response",
    "cost_per_variable: fractions of the plain analysis' wall time per design variable; \
     continuum_own and dual_own: each method's own time in the hooked run; hooked_over_plain: \
     (hooked run - plain run) / plain run / variables, everything the methods add including \
     the tangents at converged states (with both methods, one run carries both)",
    "vtu: the files of the run with the derivative methods (the plain run's VTU layout and \
     arrays, plus point data uv, d_u/d_<variable> (<method>) = sum_J Psi_J du_J/dtau at the \
     node, the derivative a displacement monitor there records, and cell data \
     d_eps_p_<top|mid|bottom>/d_<variable> (<method>), the cell means of the layer points' \
     deps_p/dtau with the nominal weights); timing_s.vtu: writing them, left out of the \
     hooked run totals",
];

/// `sensitivity.json`. Everything but `timing_s` and `dual_run_total_s` is a deterministic
/// function of the case. `status` is `"running"` while the methods run (the file is rewritten
/// after each), then `"complete"`, or `"incomplete"` when some method or re-run failed
/// (`failures` names each: method, variable, h, error).
pub fn to_json(case: &ShellCase, r: &DsaResult, status: &str) -> Value {
    let monitors: Vec<Value> = r
        .spec
        .monitors
        .iter()
        .map(|m| match &m.quantity {
            Quantity::Displacement { uv, component } => {
                json!({"label": m.label, "quantity": "displacement", "uv": uv, "component": component})
            }
            Quantity::ToolForce { tool, component } => {
                json!({"label": m.label, "quantity": "tool-force", "tool": tool, "component": component})
            }
            Quantity::ChordAngle { points, plane, .. } => {
                json!({"label": m.label, "quantity": "chord-angle", "points": points, "plane": plane})
            }
            Quantity::TargetDistance {
                points, targets, ..
            } => {
                json!({"label": m.label, "quantity": "target-distance", "points": points, "targets": targets})
            }
            Quantity::PlasticStrain {
                region,
                layers,
                rho,
            } => {
                json!({"label": m.label, "quantity": "plastic-strain", "region": region,
                       "layers": format!("{layers:?}").to_lowercase(), "rho": rho})
            }
        })
        .collect();
    let variables: Vec<Value> = r
        .variables
        .iter()
        .map(|v| {
            let steps: Vec<Value> = (0..r.nominal.loads.len())
                .map(|s| {
                    let mut comps = serde_json::Map::new();
                    for (m, mon) in r.spec.monitors.iter().enumerate() {
                        comps.insert(
                            mon.label.clone(),
                            json!({
                                "value": num(r.nominal.values[s][m]),
                                "continuum": v.continuum.as_ref().and_then(|d| d.get(s)).map_or(Value::Null, |d| num(d[m])),
                                "dual": v.dual.as_ref().and_then(|d| d.get(s)).map_or(Value::Null, |d| num(d[m])),
                                "fd_central": v.fd.iter().map(|c| num(c.derivatives[s][m])).collect::<Vec<_>>(),
                                "fd_step": v.fd.iter().map(|c| num(c.h)).collect::<Vec<_>>(),
                            }),
                        );
                    }
                    json!({
                        "step": s + 1,
                        "load": r.nominal.loads[s],
                        "plastic_points": r.nominal.yielding[s].iter().filter(|y| **y).count(),
                        "fd_flagged": v.fd.iter().map(|c| c.flagged[s]).collect::<Vec<_>>(),
                        "taylor_remainder": v.fd.iter().map(|c| c.taylor.as_ref().and_then(|t| t.remainder.get(s)).map_or(Value::Null, |t| num(*t))).collect::<Vec<_>>(),
                        "monitors": comps,
                    })
                })
                .collect();
            let fits: Vec<Value> = v
                .taylor
                .iter()
                .map(|f| {
                    json!({
                        "step": f.step + 1,
                        "rate": f.rate.map_or(Value::Null, num),
                        "used_h": f.used,
                        "excluded_h_active_set": f.excluded,
                        "exact_h": f.exact,
                    })
                })
                .collect();
            let rates: Vec<f64> = v.taylor.iter().filter_map(|f| f.rate).collect();
            json!({
                "name": v.entry.variable.name,
                "kind": kind_name(&v.entry.variable),
                "value": v.value,
                "fd_steps_relative": v.entry.fd_steps,
                "fd_steps": v.fd.iter().map(|c| c.h).collect::<Vec<_>>(),
                "flagged_steps": flagged_steps(v),
                "continuum_vs_dual": continuum_vs_dual(v).map_or(Value::Null, num),
                "taylor": {
                    "rate_min": rates.iter().copied().reduce(f64::min),
                    "rate_max": rates.iter().copied().reduce(f64::max),
                    "per_step": fits,
                },
                "steps": steps,
            })
        })
        .collect();
    let failures: Vec<Value> = r
        .failures
        .iter()
        .map(|f| {
            json!({
                "method": f.method,
                "variable": f.variable,
                "h": f.h,
                "fd_step_relative": f.relative,
                "error": f.message,
            })
        })
        .collect();
    json!({
        "kind": "shell-dsa",
        "case": case.path.display().to_string(),
        "title": case.title,
        "status": status,
        "failures": failures,
        "notes": NOTES,
        "methods": r.spec.methods.iter().map(|m| m.name()).collect::<Vec<_>>(),
        "monitors": monitors,
        "loads": r.nominal.loads,
        "dual_value_difference": r.dual_value_difference.map_or(Value::Null, num),
        "dual_state_mismatch": r.dual_state_mismatch.map_or(Value::Null, num),
        "continuum_value_difference": r.continuum_value_difference.map_or(Value::Null, num),
        "timing_s": {
            "analysis": r.time_analysis,
            "continuum": r.time_continuum,
            "dual": r.time_dual,
            "fd": r.time_fd,
            "vtu": r.time_vtu,
            "continuum_stages": r.continuum_stages.map_or(Value::Null, |t| json!({
                "rhs": t.rhs,
                "solve": t.solve,
                "update": t.update,
                "record": t.record,
            })),
        },
        "cost_per_variable": {
            "continuum_own": r.cost().continuum_own.map_or(Value::Null, num),
            "dual_own": r.cost().dual_own.map_or(Value::Null, num),
            "hooked_over_plain": r.cost().hooked_over_plain.map_or(Value::Null, num),
        },
        "dual_run_total_s": r.time_dual_run,
        "continuum_run_total_s": r.time_continuum_run,
        "vtu": {
            "collection": (!r.vtu.is_empty()).then_some(super::shell_output::PVD_FILE),
            "steps": r.vtu.iter().map(|v| json!({"step": v.step, "load": v.load, "file": v.file})).collect::<Vec<_>>(),
            "error": r.vtu_error,
        },
        "variables": variables,
    })
}

/// `thickness`, `material.<name>`, `shape.<surface parameter>`, `tool.<name>.<x|y|z>` or
/// `tool.<name>.<rx|ry|rz>`.
pub fn kind_name(v: &DesignVariable) -> String {
    match &v.kind {
        crate::sensitivity::DesignKind::Material(p) => format!("material.{}", p.name()),
        crate::sensitivity::DesignKind::Shape { name, .. } => format!("shape.{name}"),
        crate::sensitivity::DesignKind::Tool { tool, axis } => {
            format!(
                "tool.{tool}.{}",
                crate::sensitivity::TOOL_AXES[*axis.min(&2)]
            )
        }
        crate::sensitivity::DesignKind::ToolRotation { tool, axis } => {
            format!(
                "tool.{tool}.{}",
                crate::sensitivity::TOOL_ROTATION_AXES[*axis.min(&2)]
            )
        }
        _ => "thickness".into(),
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

/// Per step size, the 1-based load steps flagged by the active-set test.
fn flagged_steps(v: &VariableResult) -> Vec<Value> {
    v.fd
        .iter()
        .map(|c| {
            json!({
                "fd_step_relative": c.relative,
                "steps": c.flagged.iter().enumerate().filter(|(_, f)| **f).map(|(s, _)| s + 1).collect::<Vec<_>>(),
            })
        })
        .collect()
}

fn cell(v: Option<f64>) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:>13.5e}"),
        _ => format!("{:>13}", "—"),
    }
}

/// The table of one design variable in the format of the paper's Tables 1–2, at its first
/// step size `h` (`Δτ`): per load step and monitor component ψ, `Δψ = (ψ(τ+h) − ψ(τ−h))/2`
/// (central differences), `ψ'Δτ` per method, and `Δψ / ψ'Δτ × 100` (finite differences
/// against the continuum derivative when it ran, else the dual one: the paper's ratio).
/// `*` marks a step flagged by the active-set test.
pub fn table(r: &DsaResult, v: usize) -> String {
    let var = &r.variables[v];
    let col = var.fd.first();
    let mut s = format!(
        "design variable `{}` ({}), τ = {:e}{}\n",
        var.entry.variable.name,
        kind_name(&var.entry.variable),
        var.value,
        col.map_or(String::from(", no finite differences"), |c| {
            if matches!(
                var.entry.variable.kind,
                crate::sensitivity::DesignKind::Tool { .. }
                    | crate::sensitivity::DesignKind::ToolRotation { .. }
            ) {
                // τ is the tool's offset or rotation (0): fd_steps are absolute.
                format!(", Δτ = {:e} (absolute: τ is the tool's offset)", c.h)
            } else {
                format!(", Δτ = {:e} (h/|τ| = {:e})", c.h, c.relative)
            }
        })
    );
    let (dual_head, cont_head) = if col.is_some() {
        ("ψ'Δτ dual", "ψ'Δτ cont.")
    } else {
        ("ψ' dual", "ψ' cont.")
    };
    s.push_str(&format!(
        "{:>4} {:>11} {:<10} {:>13} {:>13} {:>13} {:>13} {:>10}\n",
        "step", "λ", "monitor", "ψ", "Δψ (FD)", dual_head, cont_head, "ratio×100"
    ));
    for st in 0..r.nominal.loads.len() {
        let flag = col.is_some_and(|c| c.flagged[st]);
        for (m, mon) in r.spec.monitors.iter().enumerate() {
            let fd = col.map(|c| c.derivatives[st][m] * c.h);
            let scaled = |d: &Vec<Vec<f64>>| {
                let g = d.get(st)?[m];
                col.map(|c| g * c.h).or(Some(g))
            };
            let dual = var.dual.as_ref().and_then(scaled);
            let cont = var.continuum.as_ref().and_then(scaled);
            let ratio = match (fd, cont.or(dual)) {
                (Some(a), Some(b)) if b != 0.0 => format!("{:>10.4}", 100.0 * a / b),
                (Some(0.0), Some(_)) => format!("{:>10}", "0 = 0"),
                _ => format!("{:>10}", "—"),
            };
            s.push_str(&format!(
                "{:>4} {:>11} {:<10} {} {} {} {} {}{}\n",
                st + 1,
                super::plot::plain_tick(r.nominal.loads[st]),
                mon.label,
                cell(Some(r.nominal.values[st][m])),
                cell(fd),
                cell(dual),
                cell(cont),
                ratio,
                if flag { " *" } else { "" }
            ));
        }
    }
    for c in &var.fd {
        s.push_str(&format!(
            "h/|τ| = {:e}: max |Δψ/ψ'Δτ − 1| over unflagged components with |ψ'| ≥ 1e-6 max|ψ'|: {}\n",
            c.relative,
            max_rel_diff(var, c).map_or("—".into(), |e| format!("{e:.3e}"))
        ));
    }
    if let Some(e) = continuum_vs_dual(var) {
        s.push_str(&format!(
            "continuum vs dual: max |ψ'_cont − ψ'_dual| / max |ψ'_dual| = {e:.3e}\n"
        ));
    }
    let rates: Vec<String> = var
        .taylor
        .iter()
        .filter_map(|f| f.rate.map(|r| format!("{}: {r:.3}", f.step + 1)))
        .collect();
    if !rates.is_empty() {
        s.push_str(&format!("Taylor rate per step: {}\n", rates.join(", ")));
    }
    let flagged: Vec<String> = var
        .fd
        .iter()
        .filter(|c| c.flagged.iter().any(|f| *f))
        .map(|c| {
            let first = c.flagged.iter().position(|f| *f).map_or(0, |p| p + 1);
            format!("h/|τ| = {:e} from step {first}", c.relative)
        })
        .collect();
    if !flagged.is_empty() {
        s.push_str(&format!(
            "* active set changed within ±h (not comparable): {}\n",
            flagged.join("; ")
        ));
    }
    s
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
    case: &ShellCase,
    spec: &DsaSpec,
    step: usize,
) -> Result<Vec<TermBreakdown>, DsaError> {
    let analysis = CaseAnalysis { case };
    let base = base_design(case);
    let (problem, newton) = method_problem(&analysis, &base)?;
    let vars: Vec<DesignVariable> = spec.design.iter().map(|d| d.variable.clone()).collect();
    Ok(breakdown(
        problem,
        Some(&case.surface),
        vars,
        &newton,
        analysis.solver(),
        step,
    )?)
}

/// The breakdown of one variable as a table: per group the largest continuum and dual entries
/// and their largest difference with its row (particle, DOF); then the end-of-step
/// sensitivities field by field with the worst integration point or particle.
pub fn terms_table(b: &TermBreakdown) -> String {
    let mut s = format!(
        "terms at step {} (λ = {:e}), design variable `{}` ({}):\n",
        b.step,
        b.load,
        b.variable.name,
        kind_name(&b.variable)
    );
    s.push_str(&format!(
        "{:<10} {:>13} {:>13} {:>13} {:>10}  worst row\n",
        "group", "max|cont.|", "max|dual|", "max|diff|", "rel."
    ));
    for g in &b.groups {
        let worst = match g.worst_dof {
            _ if g.max_difference == 0.0 => "—".to_string(),
            Some((p, c)) => format!("particle {p} dof {c}"),
            None => format!("constraint row {}", g.worst_row),
        };
        s.push_str(&format!(
            "{:<10} {:>13.5e} {:>13.5e} {:>13.5e} {:>10.2e}  {}\n",
            g.group.map_or("total", |t| t.name()),
            g.continuum_max,
            g.dual_max,
            g.max_difference,
            g.relative(),
            worst
        ));
    }
    s.push_str(&format!(
        "{:<12} {:>13} {:>13} {:>10}  worst point\n",
        "n+1 field", "max|dual|", "max|diff|", "rel."
    ));
    for f in &b.update {
        let at = match f.worst.1 {
            _ if f.max_difference == 0.0 => "—".to_string(),
            Some(l) => format!(
                "point {} layer {l} at ({:.4}, {:.4})",
                f.worst.0, f.worst_uv[0], f.worst_uv[1]
            ),
            None => format!(
                "particle {} at ({:.4}, {:.4})",
                f.worst.0, f.worst_uv[0], f.worst_uv[1]
            ),
        };
        s.push_str(&format!(
            "{:<12} {:>13.5e} {:>13.5e} {:>10.2e}  {}\n",
            f.field,
            f.dual_max,
            f.max_difference,
            f.relative(),
            at
        ));
    }
    s
}

/// `terms.json`: the breakdowns of all variables.
pub fn terms_json(bs: &[TermBreakdown]) -> Value {
    let one = |b: &TermBreakdown| {
        json!({
            "step": b.step,
            "load": b.load,
            "variable": b.variable.name,
            "kind": kind_name(&b.variable),
            "groups": b.groups.iter().map(|g| json!({
                "group": g.group.map_or("total", |t| t.name()),
                "continuum_max": num(g.continuum_max),
                "dual_max": num(g.dual_max),
                "max_difference": num(g.max_difference),
                "relative": num(g.relative()),
                "worst_row": g.worst_row,
                "worst_particle_dof": g.worst_dof,
            })).collect::<Vec<_>>(),
            "update": b.update.iter().map(|f| json!({
                "field": f.field,
                "dual_max": num(f.dual_max),
                "max_difference": num(f.max_difference),
                "relative": num(f.relative()),
                "worst_index": f.worst.0,
                "worst_layer": f.worst.1,
                "worst_uv": f.worst_uv,
            })).collect::<Vec<_>>(),
        })
    };
    json!({
        "kind": "shell-dsa-terms",
        "notes": [
            "groups: the continuum fictitious load (eq 65's right-hand side) of each term group, \
             seeded with the dual reference's committed sensitivities at the step start, against \
             the dual residual's derivative part with only that group seeded; total = all groups",
            "update: the continuum end-of-step sensitivities (its own solve of eq 65 with the \
             converged tangent, history update eqs 44-51, particle update) against the dual \
             reference's committed dual state",
        ],
        "breakdowns": bs.iter().map(one).collect::<Vec<_>>(),
    })
}
