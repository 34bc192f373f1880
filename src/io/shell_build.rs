//! From a checked [`ShellCase`] to a running shell analysis: particles, supports, quadrature,
//! model, boundary conditions, loads, the Newton driver, and the run loop that writes results
//! after every converged step ([`crate::io::shell_output`]).
//!
//! The file has two halves:
//! - **stable**: particle grid, cell quadrature, the [`Discretisation`], driver options and the
//!   run loop. They use APIs that are settled (meshfree, quadrature, solver, model output).
//! - **the problem seam** (section "API seam" below): [`connect`], [`driver`] and
//!   [`problem_model`]. Only these know how boundary conditions (exact linear constraints with
//!   multipliers), symmetry planes (image particles) and loads reach [`ShellProblem`], and which
//!   driver options exist. A condition or load they cannot build is an error naming its key in
//!   the case file, before any computation.

use super::shell_case::{
    edge_name, Boundary, CellLayout, Component, Load, LoadScalingSpec, Location, MonitorDirection,
    PenaltySpec, PredictorKind, ShellCase,
};
use super::shell_output::{OutputError, OutputGrid, PvdTime, Separation, ShellOutput, StepSummary};
use crate::meshfree::quadrature::{CellQuadrature, QuadratureError};
use crate::meshfree::vci::VciOrder;
use crate::meshfree::Edge;
use crate::meshfree::{jittered_grid, ParticleGrid};
use crate::shell::constraints::{
    assemble, edge_constraints, ConstraintError, ConstraintSet, EdgeCondition, LinearConstraint,
    RowKind, SymmetryRows,
};
use crate::shell::contact::ShellContact;
use crate::shell::integration::{apply_vci, boundary_rule};
use crate::shell::load;
use crate::shell::model::{Discretisation, ShellModel};
use crate::shell::point::DOFS_PER_PARTICLE;
use crate::shell::problem::ShellProblem;
use crate::shell::stabilisation::{
    DirectorResolution, NEGLIGIBLE_DIRECTOR_CHANGE, NEGLIGIBLE_STEP_CHANGE,
};
use crate::shell::symmetry::SymmetryPlane;
use crate::shell::ShellError;
use crate::solver::observe::{Observed, StepObserver};
use crate::solver::Failure;
use crate::solver::{
    ArcLength, ConvergedStep, LinearSolver, LoadStepping, Method, NewtonOptions, NewtonSolver,
    NonlinearProblem, Parallelism, Predictor, ProblemError, SolverError, SolverOptions,
    SparsityPattern, StepRecord,
};
use nalgebra::Vector3;
use serde_json::json;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;
use thiserror::Error;

/// Errors assembling or running a shell case. Each names the case-file key concerned.
#[derive(Debug, Error)]
pub enum BuildError {
    /// The case is valid but the model cannot be built from it (e.g. too few particles in a
    /// support).
    #[error("`{key}`: {message}")]
    Model {
        /// Case-file key most directly responsible.
        key: String,
        /// What failed.
        message: String,
    },
    /// Sparse solver set-up.
    #[error("linear solver: {0}")]
    Solver(#[from] SolverError),
    /// Writing results.
    #[error(transparent)]
    Output(#[from] OutputError),
}

fn model_err(key: &str, e: impl std::fmt::Display) -> BuildError {
    BuildError::Model {
        key: key.into(),
        message: e.to_string(),
    }
}

/// A model error of `key`, unless the shape functions failed (too few particles cover a
/// point): that names `kernel.support` and its value, whatever step of the build met it.
fn shell_err(case: &ShellCase, key: &str, e: ShellError) -> BuildError {
    match e {
        e @ ShellError::Shape { .. } => BuildError::Model {
            key: "kernel.support".into(),
            message: format!("{} (particle spacings): {e}", case.kernel.support),
        },
        other => model_err(key, other),
    }
}

// ---------------------------------------------------------------------------------------------
// Stable half.

/// The particle grid of the case on the surface's parameter box.
pub fn particle_grid(case: &ShellCase) -> ParticleGrid {
    let p = &case.particles;
    // Ranges were checked with the case (counts >= 2, jitter in [0, 0.5)), so this cannot panic.
    jittered_grid(case.param_box, p.counts[0], p.counts[1], p.jitter, p.seed)
}

/// The background-cell quadrature of the case.
pub fn cell_quadrature(
    case: &ShellCase,
    grid: &ParticleGrid,
) -> Result<CellQuadrature, BuildError> {
    let i = &case.integration;
    let e = |e: QuadratureError| model_err("integration", e);
    match i.cells {
        CellLayout::PerParticleSpacing { subdivide } => {
            CellQuadrature::for_particle_grid(grid, subdivide, i.gauss).map_err(e)
        }
        CellLayout::Counts([nu, nv]) => {
            CellQuadrature::new(case.param_box, nu, nv, i.gauss).map_err(e)
        }
    }
}

/// The discretisation (particles, supports, basis, quadrature, thickness rule).
pub fn discretisation(
    case: &ShellCase,
    grid: &ParticleGrid,
    cq: &CellQuadrature,
) -> Result<Discretisation, BuildError> {
    Ok(Discretisation {
        particle_uv: grid.positions.clone(),
        supports: grid.supports(case.kernel.support),
        basis: case.kernel.basis,
        kernel: case.kernel.function,
        quadrature: cq.iter().map(|(p, w, _)| (p, w)).collect(),
        thickness_rule: thickness_rule(case)?,
        thickness: case.thickness,
        symmetry: Vec::new(),
    })
}

/// The rule through the thickness: `(ζ, weight)` pairs.
fn thickness_rule(case: &ShellCase) -> Result<Vec<(f64, f64)>, BuildError> {
    let rule = case
        .integration
        .thickness_rule
        .rule()
        .map_err(|e| model_err("integration.thickness_points", e))?;
    Ok(rule
        .nodes
        .iter()
        .copied()
        .zip(rule.weights.iter().copied())
        .collect())
}

/// Load stepping and Newton tolerances of `[steps]` (everything but the predictor, which
/// [`driver`] maps).
pub fn newton_settings(case: &ShellCase) -> (NewtonOptions, LoadStepping) {
    let s = &case.steps;
    (
        NewtonOptions {
            residual_rtol: s.residual_rtol,
            residual_atol: s.residual_atol,
            energy_rtol: s.energy_rtol,
            energy_atol: s.energy_atol,
            max_iterations: s.max_iterations,
            max_active_set_iterations: s.max_active_set_iterations,
            linear_updates: s.linear_updates,
            line_search: s.line_search,
            ..NewtonOptions::default()
        },
        LoadStepping {
            start: 0.0,
            end: s.final_load,
            initial_step: s.initial_step,
            min_step: s.min_step,
            max_step: s.max_step,
            cut_factor: s.cut_factor,
            grow_factor: s.grow_factor,
            easy_iterations: s.easy_iterations,
            stops: s.stops.clone(),
            stop_failure: s.stop_failure,
            max_attempts: s.max_attempts,
            ..LoadStepping::default()
        },
    )
}

// ---------------------------------------------------------------------------------------------
// API seam: the only code that knows how conditions and loads reach `ShellProblem`, and which
// options the driver has.

/// The reaction of every `prescribed` entry of the case, in case order: `(boundary[k], the
/// force (or moment) the support exerts on the shell along the prescribed component)`, from
/// the committed multipliers. An entry whose row was dropped as redundant has none.
pub fn prescribed_reactions(case: &ShellCase, problem: &ShellProblem) -> Vec<(String, f64)> {
    let reactions = problem.reactions();
    case.boundary
        .iter()
        .enumerate()
        .filter_map(|(k, b)| match b {
            Boundary::Prescribed { .. } => {
                // The entry's one row, labelled by `boundary_constraints`.
                let prefix = format!("{}: ", entry_name(k, b));
                problem
                    .constraints()
                    .iter()
                    .position(|c| c.label.starts_with(&prefix))
                    .map(|i| (format!("boundary[{k}]"), reactions[i]))
            }
            _ => None,
        })
        .collect()
}

/// The unit direction of each monitor with a `direction` (the initial surface normal at the
/// monitor's point for `"normal"`), in monitor order.
pub fn monitor_directions(case: &ShellCase) -> Result<Vec<Option<[f64; 3]>>, BuildError> {
    case.monitors
        .iter()
        .enumerate()
        .map(
            |(k, m)| match case.monitor_directions.get(k).copied().flatten() {
                None => Ok(None),
                Some(MonitorDirection::Fixed(d)) => Ok(Some(d)),
                Some(MonitorDirection::Normal) => {
                    let n = case
                        .surface
                        .eval(m.at[0], m.at[1])
                        .normal()
                        .map_err(|e| model_err(&format!("monitor[{k}].direction"), e))?;
                    Ok(Some([n[0], n[1], n[2]]))
                }
            },
        )
        .collect()
}

/// The global axis of a displacement component, or the rotation index of a rotation one.
fn component_target(c: Component) -> Result<Vector3<f64>, usize> {
    match c {
        Component::Ux => Ok(Vector3::x()),
        Component::Uy => Ok(Vector3::y()),
        Component::Uz => Ok(Vector3::z()),
        Component::Rot1 => Err(0),
        Component::Rot2 => Err(1),
    }
}

/// The symmetry planes of the case (checked against the surface when the model is built).
fn symmetry_planes(case: &ShellCase) -> Result<Vec<SymmetryPlane>, BuildError> {
    case.boundary
        .iter()
        .enumerate()
        .filter_map(|(k, b)| match b {
            Boundary::Symmetry {
                edge,
                point,
                normal,
            } => Some(
                SymmetryPlane::new(*edge, Vector3::from(*point), Vector3::from(*normal))
                    .map(|p| p.labelled(entry_name(k, b)))
                    .map_err(|e| model_err(&format!("boundary[{k}]"), e)),
            ),
            _ => None,
        })
        .collect()
}

/// A boundary entry as the case file names it, e.g. `boundary[2] (clamped, edge v-min)`.
fn entry_name(k: usize, b: &Boundary) -> String {
    let what = match b {
        Boundary::Symmetry { edge, .. } => format!("symmetry, edge {}", edge_name(*edge)),
        Boundary::Clamped { edge } => format!("clamped, edge {}", edge_name(*edge)),
        Boundary::SimplySupported { edge } => {
            format!("simply-supported, edge {}", edge_name(*edge))
        }
        Boundary::Fixed {
            location,
            components,
        } => {
            let names: Vec<&str> = components.iter().map(|c| c.name()).collect();
            let at = match location {
                Location::Edge(e) => format!("edge {}", edge_name(*e)),
                Location::Point(at) => format!("at {at:?}"),
                Location::Everywhere => "everywhere".to_string(),
            };
            format!("fixed {}, {at}", names.join(" "))
        }
        Boundary::Prescribed {
            at,
            component,
            value,
        } => format!("prescribed {} = {value} at {at:?}", component.name()),
    };
    format!("boundary[{k}] ({what})")
}

/// The rows of the case's `[[boundary]]` entries other than symmetry planes (which are in the
/// model), in entry order, each labelled with its entry (`entry_name`). They may overlap:
/// the problem merges rows that repeat others ([`crate::shell::constraints::assemble`]).
pub fn boundary_constraints(
    case: &ShellCase,
    model: &ShellModel,
) -> Result<Vec<LinearConstraint>, BuildError> {
    let mut constraints: Vec<LinearConstraint> = Vec::new();
    for (k, b) in case.boundary.iter().enumerate() {
        let key = format!("boundary[{k}]");
        let err = |e: ConstraintError| model_err(&key, e);
        let entry = entry_name(k, b);
        let from = constraints.len();
        match b {
            Boundary::Symmetry { .. } => {} // in the model (image particles)
            Boundary::Clamped { edge } => constraints
                .extend(edge_constraints(model, *edge, &EdgeCondition::Clamped).map_err(err)?),
            Boundary::SimplySupported { edge } => constraints.extend(
                edge_constraints(model, *edge, &EdgeCondition::SimplySupported).map_err(err)?,
            ),
            Boundary::Fixed {
                location,
                components,
            } => {
                let (directions, rotations): (Vec<_>, Vec<_>) = components
                    .iter()
                    .map(|&c| component_target(c))
                    .partition(Result::is_ok);
                let directions: Vec<Vector3<f64>> =
                    directions.into_iter().filter_map(Result::ok).collect();
                let rotations: Vec<usize> = rotations.into_iter().filter_map(Result::err).collect();
                match location {
                    Location::Edge(e) => constraints.extend(
                        edge_constraints(
                            model,
                            *e,
                            &EdgeCondition::Fixed {
                                directions,
                                rotations,
                            },
                        )
                        .map_err(err)?,
                    ),
                    Location::Point(at) => {
                        for d in directions {
                            constraints.push(
                                LinearConstraint::displacement(model, *at, d, 0.0).map_err(err)?,
                            );
                        }
                        for r in rotations {
                            constraints
                                .push(LinearConstraint::rotation(model, *at, r, 0.0).map_err(err)?);
                        }
                    }
                    // The generalised DOFs of every real particle (images follow their
                    // sources); those the symmetry planes eliminate are dropped by the problem.
                    Location::Everywhere => {
                        for i in 0..model.n_particles() {
                            for &c in components {
                                let kind = match c {
                                    Component::Rot1 | Component::Rot2 => RowKind::Rotation,
                                    _ => RowKind::Displacement,
                                };
                                constraints.push(
                                    LinearConstraint::generalised(
                                        DOFS_PER_PARTICLE * i + c.index(),
                                        0.0,
                                        kind,
                                    )
                                    .labelled(format!("particle {i}, {}", c.name())),
                                );
                            }
                        }
                    }
                }
            }
            Boundary::Prescribed {
                at,
                component,
                value,
            } => match component_target(*component) {
                Ok(d) => constraints
                    .push(LinearConstraint::displacement(model, *at, d, *value).map_err(err)?),
                Err(r) => constraints
                    .push(LinearConstraint::rotation(model, *at, r, *value).map_err(err)?),
            },
        }
        for c in &mut constraints[from..] {
            c.label = format!("{entry}: {}", c.label);
        }
    }
    Ok(constraints)
}

/// The boundary entries as the problem will impose them, without building the analysis: the
/// model is made on the particles alone (no quadrature points, no VCI: the constraint rows need
/// only the shape functions at the particles and the symmetry images), and the rows are
/// assembled as [`ShellProblem`] does. So `shelldsa check` refuses an inconsistent set (the
/// same component held at two values: [`ConstraintError::Conflict`], naming both entries)
/// before any analysis, and reports the rows merged.
pub fn check_boundary(case: &ShellCase) -> Result<ConstraintSet, BuildError> {
    let grid = particle_grid(case);
    let disc = Discretisation {
        particle_uv: grid.positions.clone(),
        supports: grid.supports(case.kernel.support),
        basis: case.kernel.basis,
        kernel: case.kernel.function,
        quadrature: Vec::new(),
        thickness_rule: thickness_rule(case)?,
        thickness: case.thickness,
        symmetry: symmetry_planes(case)?,
    };
    let model = ShellModel::new(&case.surface, disc, case.material)
        .map_err(|e| shell_err(case, "kernel.support", e))?;
    let rows = boundary_constraints(case, &model)?;
    assemble(&model, rows, SymmetryRows::Eliminate).map_err(|e| model_err("boundary", e))
}

/// Build the model and the shell problem: surface, discretisation (symmetry planes, VCI),
/// essential conditions (exact linear constraints) and loads.
pub fn connect(case: &ShellCase, disc: Discretisation) -> Result<ShellProblem, BuildError> {
    connect_with_contact(case, disc).map(|(p, _)| p)
}

/// The loads of `case` on `model`, at load factor 1, in case order: the `[[load]]` tables
/// (a load with `scaling = "constant"` held at its full value), the director filter, and the
/// contact with the case's tools (also returned: a handle for the per-step reports).
pub fn case_loads(
    case: &ShellCase,
    model: &ShellModel,
) -> Result<(Vec<load::Load>, Option<Arc<ShellContact>>), BuildError> {
    let mut loads = Vec::new();
    for (k, l) in case.loads.iter().enumerate() {
        let key = format!("load[{k}]");
        let err = |e: ShellError| model_err(&key, e);
        // The edge rule of edge loads: one interval per particle spacing along the edge (the
        // kernels are piecewise cubic there), 4 Gauss points each.
        let intervals = |edge: &Edge| match edge {
            Edge::UMin | Edge::UMax => case.particles.counts[1] - 1,
            Edge::VMin | Edge::VMax => case.particles.counts[0] - 1,
        };
        let load: load::Load = match l {
            Load::PointForce { at, force } => load::PointForce {
                uv: *at,
                force: *force,
            }
            .into(),
            Load::Gravity { per_area } => load::Gravity::new(*per_area).map_err(err)?.into(),
            Load::GravityPerVolume { per_volume } => {
                load::Gravity::per_volume(*per_volume).map_err(err)?.into()
            }
            Load::Pressure { value } => load::Pressure::new(*value).map_err(err)?.into(),
            Load::Moment { edge, per_length } => {
                load::Moment::on_edge(model, &case.surface, *edge, *per_length, intervals(edge), 4)
                    .map_err(err)?
                    .into()
            }
            Load::EdgeForce {
                edge,
                per_length,
                follower,
            } => {
                let build = if *follower {
                    load::EdgeForce::follower_on_edge
                } else {
                    load::EdgeForce::on_edge
                };
                build(model, &case.surface, *edge, *per_length, intervals(edge), 4)
                    .map_err(err)?
                    .into()
            }
        };
        loads.push(
            match case.load_scaling.get(k).copied().unwrap_or_default() {
                LoadScalingSpec::Proportional => load,
                LoadScalingSpec::Constant => load::Load::Constant(Box::new(load)),
            },
        );
    }
    if case.integration.director_stabilisation > 0.0 {
        loads.push(load::Load::DirectorFilter(
            crate::shell::stabilisation::DirectorFilter::with_strength(
                model,
                case.integration.director_stabilisation,
                case.integration.director_stabilisation_strength,
                case.integration.director_stabilisation_floor,
            )
            .and_then(|f| {
                f.with_filter_support(
                    model,
                    case.integration.director_stabilisation_support / case.kernel.support,
                )
            })
            .map_err(|e| model_err("integration.director_stabilisation", e))?,
        ));
    }
    let contact = match &case.contact {
        Some(spec) if !case.tools.is_empty() => {
            let omega = spec.penalty.omega(case.material.young, case.thickness);
            let c = ShellContact::new(model, &case.surface, case.tools.clone(), spec.faces, omega)
                .map_err(|e| model_err("contact", e))?;
            let c = Arc::new(c);
            let penalty_factor = match spec.penalty {
                PenaltySpec::Factor(c) => Some(c),
                _ => None,
            };
            loads.push(load::Load::Contact(load::ContactLoad {
                contact: c.clone(),
                penalty_factor,
            }));
            Some(c)
        }
        _ => None,
    };
    Ok((loads, contact))
}

/// As [`connect`], also returning a handle on the contact with the case's tools (a
/// [`ShellContact`] owned by the problem as a prescribed load, `docs/contact.md` §4), for the
/// per-step reports. Its gap tracking is reset after the problem's set-up evaluations.
pub fn connect_with_contact(
    case: &ShellCase,
    mut disc: Discretisation,
) -> Result<(ShellProblem, Option<Arc<ShellContact>>), BuildError> {
    disc.symmetry = symmetry_planes(case)?;
    let mut model = ShellModel::new(&case.surface, disc, case.material)
        .map_err(|e| shell_err(case, "kernel.support", e))?;
    model.director = case.integration.director;
    if case.integration.vci != VciOrder::Off {
        let rule = boundary_rule(&model, case.param_box)
            .map_err(|e| shell_err(case, "integration.vci", e))?;
        apply_vci(&mut model, case.integration.vci, &rule)
            .map_err(|e| shell_err(case, "integration.vci", e))?;
    }

    let constraints = boundary_constraints(case, &model)?;

    let (loads, contact) = case_loads(case, &model)?;
    let problem =
        ShellProblem::new(model, loads, constraints).map_err(|e| model_err("boundary", e))?;
    if let Some(c) = &contact {
        c.reset_tracking();
    }
    Ok((problem, contact))
}

/// The Newton driver of `[steps]`.
pub fn driver(case: &ShellCase) -> Result<NewtonSolver, BuildError> {
    let (options, mut stepping) = newton_settings(case);
    if let Some(p) = case.steps.predictor {
        stepping.predictor = match p {
            PredictorKind::Zero => Predictor::Zero,
            PredictorKind::Secant => Predictor::Secant,
            PredictorKind::Quadratic => Predictor::Quadratic,
        };
    }
    Ok(NewtonSolver { options, stepping })
}

/// The committed shell model inside the problem.
pub fn problem_model(p: &ShellProblem) -> &ShellModel {
    &p.model
}

/// The sparse pattern of the problem's tangent.
pub fn problem_pattern(p: &ShellProblem) -> &SparsityPattern {
    p.pattern()
}

// ---------------------------------------------------------------------------------------------
// Run.

/// A shell case ready to run.
#[derive(Debug)]
pub struct BuiltShell {
    /// The problem (model inside).
    pub problem: ShellProblem,
    /// The background cells (the output grid's cells).
    pub quadrature: CellQuadrature,
    /// The driver.
    pub newton: NewtonSolver,
    /// Number of particles.
    pub n_particles: usize,
    /// The contact with the case's tools (shared with the problem, which owns it as a load).
    pub contact: Option<Arc<ShellContact>>,
}

/// Build everything for `case` (no output written).
/// Before an analysis: no tool of `built` lies through its undeformed sheet
/// ([`ShellContact::initial_penetration`]; a die set flush with the sheet passes). Not part of
/// [`build`], whose models also serve evaluations at states no analysis reaches.
pub fn tools_clear_of_the_sheet(built: &BuiltShell) -> Result<(), BuildError> {
    match &built.contact {
        Some(c) => c
            .initial_penetration(problem_model(&built.problem))
            .map_err(|e| model_err("tool", e)),
        None => Ok(()),
    }
}

pub fn build(case: &ShellCase) -> Result<BuiltShell, BuildError> {
    let grid = particle_grid(case);
    let cq = cell_quadrature(case, &grid)?;
    let disc = discretisation(case, &grid, &cq)?;
    let newton = driver(case)?;
    let (problem, contact) = connect_with_contact(case, disc)?;
    Ok(BuiltShell {
        problem,
        quadrature: cq,
        newton,
        n_particles: grid.len(),
        contact,
    })
}

/// How a run ended.
#[derive(Clone, Debug, PartialEq)]
pub enum RunStatus {
    /// Reached the final load factor.
    Complete,
    /// Stopped before it (the reason); every converged step was written.
    Failed(String),
}

impl RunStatus {
    /// `"complete"` or `"failed: <reason>"` (as in results.json).
    pub fn label(&self) -> String {
        match self {
            RunStatus::Complete => "complete".into(),
            RunStatus::Failed(r) => format!("failed: {r}"),
        }
    }
}

/// The result of [`run`].
#[derive(Clone, Debug)]
pub struct RunSummary {
    /// How it ended.
    pub status: RunStatus,
    /// The converged steps.
    pub steps: Vec<StepSummary>,
    /// Step attempts (converged or cut).
    pub attempts: usize,
    /// Wall time of the whole run, model building included.
    pub wall_time_s: f64,
    /// Separation of the `[contact] release` tool, if detected.
    pub separation: Option<Separation>,
    /// Warnings (tools that never touched the sheet), also in results.json.
    pub warnings: Vec<String>,
    /// A stopped run whose every attempt after its last converged step changed the contact
    /// active set: `Some((attempts, smallest step size))`.
    pub stopped_switching: Option<(usize, f64)>,
}

/// The commit hook of a run: `on_commit` sees the committed problem and the step's record
/// (kept from the converged step). An error of the hook stops the run at the next evaluation
/// (as a fatal problem error).
struct CommitHook<F, E> {
    record: Option<StepRecord>,
    error: Option<E>,
    on_commit: F,
}

impl<F, E> StepObserver<&mut ShellProblem> for CommitHook<F, E>
where
    F: FnMut(&ShellProblem, &StepRecord) -> Result<(), E>,
    E: std::fmt::Display,
{
    fn on_converged(
        &mut self,
        _problem: &&mut ShellProblem,
        step: &ConvergedStep<'_>,
    ) -> Result<(), ProblemError> {
        self.record = Some(step.record.clone());
        Ok(())
    }
    fn after_commit(&mut self, problem: &&mut ShellProblem, _u: &[f64], _load: f64) {
        if let Some(rec) = self.record.take() {
            if self.error.is_none() {
                if let Err(e) = (self.on_commit)(problem, &rec) {
                    self.error = Some(e);
                }
            }
        }
    }
    fn on_restore(&mut self) {
        self.record = None;
    }
    fn failure(&self) -> Option<Failure> {
        self.error
            .as_ref()
            .map(|e| Failure::new("writing results", e.to_string()))
    }
}

/// Run a built case: write the initial state, drive Newton to the final load factor writing
/// results after every converged step (`progress` sees each step's summary), then the final
/// results.json and plot. A Newton failure is a [`RunStatus::Failed`] (results kept), not an
/// error; errors are output failures.
pub fn run(
    case: &ShellCase,
    built: &mut BuiltShell,
    out: &Path,
    start: Instant,
    mut progress: impl FnMut(&StepSummary),
) -> Result<RunSummary, BuildError> {
    let grid = OutputGrid::new(&built.quadrature, case.output.subdivide)?;
    let mut output = ShellOutput::new(
        out,
        &case.path.display().to_string(),
        &case.title,
        &case.monitors,
        case.output,
        grid,
        case.steps.final_load,
        start,
    )?;
    let n = built.problem.n_dofs();
    output.set_info("n_particles", json!(built.n_particles));
    output.set_info("n_unknowns", json!(n));
    output.set_info("final_load", json!(case.steps.final_load));
    if let Some(c) = &built.contact {
        let names: Vec<String> = c.tools().iter().map(|t| t.name.clone()).collect();
        output.set_contact(
            &names,
            case.contact.as_ref().and_then(|s| s.release.clone()),
        );
        output.set_info("penalty", json!(c.penalty()));
    }
    output.set_monitor_directions(monitor_directions(case)?);
    let controlled = case.boundary.iter().find_map(|b| match b {
        Boundary::Prescribed { value, .. } => Some(if *value < 0.0 { -1.0 } else { 1.0 }),
        _ => None,
    });
    output.set_displacement_control(controlled);
    output.set_pvd_time(if case.steps.arc_length.is_some() {
        PvdTime::Step
    } else {
        PvdTime::LoadFactor
    });
    output.initial(problem_model(&built.problem), &case.surface)?;

    let pattern = problem_pattern(&built.problem).clone();
    let method = Method::auto(&pattern);
    let parallelism = match (method, std::env::var("SHELLDSA_LU_THREADS").ok()) {
        (_, Some(t)) => match t.trim().parse::<usize>() {
            Ok(1) => Parallelism::Sequential,
            Ok(n) => Parallelism::Rayon(n),
            Err(_) => Parallelism::Sequential,
        },
        // The blocked dense kernel scales on 2 cores; the sparse one did not (linear.rs).
        (Method::DenseLu, None) => Parallelism::Rayon(0),
        (_, None) => Parallelism::Sequential,
    };
    let mut solver = LinearSolver::new(
        &pattern,
        method,
        SolverOptions {
            parallelism,
            preconditioner: case.steps.preconditioner,
            ..SolverOptions::default()
        },
    )?;
    output.set_info(
        "linear_solver",
        json!(match solver.structure() {
            Some(s) => format!("{method:?} ({parallelism:?}): {s}"),
            None => format!("{method:?} ({parallelism:?})"),
        }),
    );
    let surface = &case.surface;
    let contact = built.contact.clone();
    let mut resolution = DirectorResolution::new(problem_model(&built.problem))
        .map_err(|e| shell_err(case, "kernel.support", e))?;
    let hook = CommitHook {
        record: None,
        error: None,
        on_commit: |p: &ShellProblem, rec: &StepRecord| {
            let model = problem_model(p);
            // The committed state: a zero increment at the step's tool time.
            let report = match &contact {
                Some(c) => Some(
                    c.report(model, &vec![0.0; model.n_dofs()], rec.load)
                        .map_err(OutputError::Model)?,
                ),
                None => None,
            };
            output.set_step_reactions(prescribed_reactions(case, p));
            // Directors that moved only by round-off (in all) or by the states' convergence
            // noise (in the step) have no meaningful share.
            let changed = resolution.change_rms(model) > NEGLIGIBLE_DIRECTOR_CHANGE;
            let moved = changed && resolution.step_change_ratio(model) > NEGLIGIBLE_STEP_CHANGE;
            output.set_step_director_unresolved(
                changed.then(|| resolution.unresolved_share(model)),
                moved.then(|| resolution.step_share(model)),
            );
            resolution.advance(model);
            let s = output.converged_with_contact(model, surface, rec, report.as_ref())?;
            progress(s);
            Ok::<(), OutputError>(())
        },
    };
    let mut obs = Observed::new(&mut built.problem, hook);
    let mut critical = Vec::new();
    let result = match case.steps.arc_length {
        None => built.newton.run_with_callbacks(
            &mut obs,
            &pattern,
            &mut solver,
            &vec![0.0; n],
            |_| {},
            |cp| {
                println!("{cp}");
                critical.push(cp.clone());
            },
        ),
        Some([initial, min, max]) => {
            let s = &case.steps;
            let arc = ArcLength {
                start: 0.0,
                end: s.final_load,
                initial_length: initial,
                min_length: min,
                max_length: max,
                cut_factor: s.cut_factor,
                grow_factor: s.grow_factor,
                easy_iterations: s.easy_iterations,
                ..ArcLength::default()
            };
            built
                .newton
                .run_arc_length(&mut obs, &pattern, &mut solver, &vec![0.0; n], &arc, |cp| {
                    println!("{cp}");
                    critical.push(cp.clone());
                })
                .map(|r| r.report)
        }
    };
    let hook_error = obs.observer.error.take();
    drop(obs);
    let (status, attempts) = match result {
        Ok(report) => (RunStatus::Complete, report.attempts),
        Err(f) => (RunStatus::Failed(f.to_string()), f.report.attempts.clone()),
    };
    let cps: Vec<serde_json::Value> = critical
        .iter()
        .map(|c| {
            json!({
                "kind": c.kind.label(),
                "between_steps": [c.before_step + 1, c.after_step + 1],
                "load_factors": c.loads,
                "stiffness_parameter": c.stiffness,
                "determinant_sign": c.determinant_sign,
            })
        })
        .collect();
    output.set_info("critical_points", json!(cps));
    output.set_critical_points(
        critical
            .iter()
            .map(|c| (c.kind, c.after_step + 1))
            .collect(),
    );
    output.set_info(
        "factorisations",
        json!({
            "count": solver.n_factorizations(),
            "redone_by_the_sparse_lu": solver.n_fallbacks(),
        }),
    );
    if solver.n_fallbacks() > 0 {
        println!(
            "note: {} of {} factorisations failed the supernodal LU's probe and were redone by \
             the sparse LU (pivots too small within its supernodes)",
            solver.n_fallbacks(),
            solver.n_factorizations()
        );
    }
    let model = problem_model(&built.problem);
    if let Some(e) = hook_error {
        // Writing a step's results failed and stopped the run: that is the error to report.
        // Leave a final status in results.json if the disk still takes it.
        let _ = output.finish(
            model,
            &case.surface,
            &format!("failed: writing results: {e}"),
            &attempts,
        );
        return Err(BuildError::Output(e));
    }
    output.finish(model, &case.surface, &status.label(), &attempts)?;
    let failing = attempts
        .iter()
        .rposition(|a| a.converged)
        .map_or(&attempts[..], |i| &attempts[i + 1..]);
    let stopped_switching = (matches!(status, RunStatus::Failed(_))
        && !failing.is_empty()
        && failing.iter().all(|a| a.active_set_iterations > 0))
    .then(|| {
        let smallest = failing
            .iter()
            .map(|a| a.step_size.abs())
            .fold(f64::INFINITY, f64::min);
        (failing.len(), smallest)
    });
    Ok(RunSummary {
        status,
        steps: output.steps().to_vec(),
        attempts: attempts.len(),
        wall_time_s: start.elapsed().as_secs_f64(),
        separation: output.separation().cloned(),
        warnings: output.warnings().to_vec(),
        stopped_switching,
    })
}
