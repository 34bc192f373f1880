//! The dual-number reference of the design sensitivities (path 3 of `docs/sensitivity.md`):
//! the discrete, path-dependent solution differentiated step by step through the analysis'
//! own generic kernels, with no hand-derived sensitivity code.
//!
//! At every converged step `n → n+1` with increment `Δu` (unknowns `u = [q, μ]`, generalised
//! DOFs and scaled multipliers):
//! 1. the residual `R(Δu; ⁿs, τ)` (eq 32 with the loads and the constraint rows) is evaluated in
//!    a dual scalar `D`, with `Δu` constant (zero derivative part), the committed dual state
//!    `ⁿs` (particle coefficients `ū, d, e`, histories `Q, σ, α, ē^p`, unknowns `u`, whose
//!    derivative parts are the carried sensitivities) and the design `τ` seeded (thickness or
//!    material parameter with unit derivative in its direction). Its derivative part is
//!    `∂R/∂ⁿs · ⁿṡ + ∂R/∂τ`: the right-hand side of the sensitivity equation (eq 65) with the
//!    history terms of eq (49) and the material terms, computed rather than derived;
//! 2. `K Δu̇ = −(∂R/∂ⁿs · ⁿṡ + ∂R/∂τ)` is solved for all design variables at once with the
//!    tangent the Newton driver holds factorised at the converged state (multi-RHS, the
//!    essential conditions eliminated: their rows are zero);
//! 3. `Δu̇` becomes the derivative part of the increment, and the point updates (return map,
//!    frame update, eqs 19–27) and the particle update (Rodrigues' rotation of the director and
//!    lamina vectors) are re-evaluated in `D`: their derivative parts are the sensitivities of
//!    the trial histories `ⁿ⁺¹(Q̇, σ̇, α̇, ė^p)` and of the particle states, committed with the
//!    analysis' commit.
//!
//! **Dual type.** [`DesignDual`] is implemented for `DualSVec64<N>` (N directions in one pass)
//! and for `Dual64` (one direction per pass; several passes for several variables). A
//! [`DualDsa<D>`] (the reference as an observer of the analysis' converged steps, so that it
//! runs in the same hooked run as any other observer: [`DualShellProblem<D>`] is the problem
//! with it in its hook) holds `⌈n_variables / D::DIRECTIONS⌉` dual states ("groups"): one for
//! `DualSVec64<N>` with `N` = the number of variables ([`run_dual`] dispatches `N` = 1..=8),
//! one per variable for `Dual64`. The vector dual is the default: it shares the value part
//! (gathers, rotations, inverses, the return map's branch and its local Newton) between the
//! directions; `Dual64` repeats all of that per variable. Both give the same derivatives to
//! round-off; their cost is measured in `tests/dsa_dual.rs` and `docs/sensitivity.md`.
//!
//! **Loads.** The reference evaluates the problem's own loads ([`ShellProblem::loads`], the
//! closed [`crate::shell::load::Load`] type) with its `force` on the group's dual state ([`LoadState`]). For
//! non-shape design variables the loads have no explicit design dependence (a pressure per
//! unit area, a point force, a gravity load per unit area as given). A follower pressure
//! depends on the committed displacement `ⁿū`, which carries a sensitivity: it is evaluated with
//! the increment's derivative part set to `ⁿū̇` (it depends on `ⁿū` and `Δū` only through their
//! sum, `docs/loads.md`), which gives `∂f_ext/∂ⁿū · ⁿū̇` exactly. A load held constant is its
//! inner load at factor 1. The director-filter stabilisation (`docs/stability.md` §3) is
//! evaluated on the group's committed dual directors and lamina vectors with its stiffness
//! `κ(E, ν, t)` in `D` ([`crate::shell::stabilisation::DirectorFilter::force_with`]); its
//! coefficients `δ_IJ − Ψ_J(ξ_I)` live on the parameter domain and carry no design
//! derivative. Edge moments and edge forces are refused (`Load::takes_state`).
//!
//! **Contact** (`Load::Contact`, eqs 68–70). The penalty force of the slave points
//! against the rigid tools is evaluated in `D` by [`crate::shell::contact::ShellContact::force_with`] with the
//! group's committed dual particle states (`ū, d, e`: the slave point `x̄ + ζ t/2 d` and the
//! rotated director depend on them, so the history dependence of the contact force is carried
//! exactly, as for the pressure), the converged increment (constant), the dual thickness, the
//! penalty (`c E/t` in `D` when the case gives `penalty_factor`) and, per tool, a translation
//! offset of value 0 seeded with unit derivative along the axis of a tool variable
//! ([`crate::sensitivity::DesignKind::Tool`]) and a rotation vector `φ` of value 0 seeded
//! along the axis of a tool-rotation variable ([`crate::sensitivity::DesignKind::ToolRotation`]:
//! `R(φ)` in `D` is composed into the tool's motion, `R(θ(t)) R(φ)`, so the moved point, its
//! tangents, curvatures and normal carry the rotation) and, for a tool-shape variable
//! ([`crate::sensitivity::DesignKind::ToolShape`]), the tool's surface rebuilt in `D` with its
//! design parameter seeded (`Surface::with_design_parameters`, [`DualState::tool_surfaces`]),
//! so the tool point, tangents and normal carry `V^c = R ∂X/∂p` at fixed `ξ`. The closest-point projection's final Newton
//! correction in `D` carries the projection sensitivity (eq 80) into the gap and the normal, so
//! the derivative part of the contact force is the fictitious load `b'_N` of eq (83) plus its
//! history terms, computed rather than derived. The contact's tangent is in the tangent the
//! driver holds, so the solve is unchanged.
//!
//! **Shape design variables** ([`DesignKind::Shape`], [`DualDsa::new`],
//! [`run_dual_on`]): the surface parameter is seeded and the initial geometry of the group is
//! built in `D` as `ShellModel::new` builds it in `f64` ([`super::shape::dual_geometry`]):
//! the quadrature points' `x̄⁰,α, n⁰, n⁰,α` ([`DualState::surfaces`], passed to
//! `ShellModel::internal_force_with_surfaces`), the particles' `d = d⁰ = n(ξ_I)` and lamina
//! vectors, the initial frames. The follower pressure (`x̄⁰,α`) and gravity (the initial area
//! element) are evaluated on the dual surfaces (`Pressure::force_with_surfaces`,
//! `Gravity::force_with_surfaces`); point forces, monitors, essential conditions, shape
//! functions and quadrature weights live on the parameter domain and do not move. With
//! contact, the group's dual mid-surface points `x̄⁰` ([`DualState::positions`]) and its
//! surfaces are the initial geometry of the slave points
//! ([`crate::shell::contact::InitialGeometry`] in [`crate::shell::contact::ContactInputs::initial`]): the slave
//! point `x̄⁰ + Σ Ψ (ū + Δū) + ζ t/2 (n⁰ + Σ Ψ (d − d⁰))` and the initial face areas carry
//! the design velocity (eq 74's `V⁰` in eqs 78–83).
//!
//! **Constraint scales.** The rows' scales `k_c` (`E t`, `E t³/12`) are a numerical balance
//! set when the problem is built; they are held fixed here. The generalised DOFs do not depend
//! on them, and the physical reactions `−k_c μ_c` differentiate correctly with `k_c` fixed
//! (a re-run with another `E` changes `k_c` and `μ_c` with the same product).

use super::shape::dual_geometry;
use super::{
    check_design, Design, DesignError, DesignKind, DesignScope, DesignVariable, Monitor,
    MonitorError, SensitivityFields,
};
use crate::geometry::Surface;
use crate::material::MaterialParams;
use crate::shell::load::{Load, LoadState};
use crate::shell::model::commit_particle;
use crate::shell::point::{ParticleState, PointHistory, SurfacePoint, DOFS_PER_PARTICLE};
use crate::shell::problem::ShellProblem;
use crate::shell::ShellError;
use crate::solver::observe::{Observed, StepObserver};
use crate::solver::Failure;
use crate::solver::{
    ConvergedStep, ConvergedTangent, FactorisedAt, NewtonFailure, NewtonReport, NewtonSolver,
    ProblemError, SolverOptions,
};
use nalgebra::Vector3;
use std::time::{Duration, Instant};
use thiserror::Error;

pub use crate::scalar::DesignDual;

/// The dual state of one group of design variables, parallel to the model's f64 state.
#[derive(Clone, Debug)]
pub struct DualState<D> {
    /// Index of the first design variable of the group (its direction 0).
    pub first: usize,
    /// Number of variables in the group (≤ `D::DIRECTIONS`).
    pub count: usize,
    /// Committed particle states (real particles, as `ShellModel::particles`).
    pub particles: Vec<ParticleState<D>>,
    /// Committed histories (point-major, as `ShellModel::history`).
    pub history: Vec<PointHistory<D>>,
    /// Material, seeded.
    pub material: MaterialParams<D>,
    /// Thickness, seeded.
    pub thickness: D,
    /// Committed unknowns `[q, μ]` and their sensitivities.
    pub unknowns: Vec<D>,
    /// Initial geometry per quadrature point (as `ShellModel::points`), seeded with the
    /// group's shape design variables (constants without any).
    pub surfaces: Vec<SurfacePoint<D>>,
    /// The mid-surface position `x̄⁰` per quadrature point, seeded with the group's shape
    /// design variables (`None` without any: the contact's slave sites as built). With
    /// [`Self::surfaces`] it is the initial geometry of the contact's slave points
    /// ([`crate::shell::contact::InitialGeometry`]).
    pub positions: Option<Vec<Vector3<D>>>,
    /// The initial mid-surface with the group's shape design variables seeded on its design
    /// parameters (`None` without any): where an edge force takes its arc-length element.
    pub surface: Option<Surface<D>>,
    /// Per tool of the contact load (empty without one): the translation added to its path,
    /// value 0 (the problem's tools are at the design's position), seeded for tool variables.
    pub tool_offsets: Vec<Vector3<D>>,
    /// Per tool of the contact load (empty without one): the rotation vector of the tool as
    /// built about its pivot, value 0 (the problem's tools are at the design's orientation),
    /// seeded for tool-rotation variables.
    pub tool_rotations: Vec<Vector3<D>>,
    /// Per tool of the contact load: its surface in `D` with the group's tool-shape variables
    /// seeded on their design parameters (`None` without any: the tools' own surfaces).
    pub tool_surfaces: Option<Vec<Surface<D>>>,
}

impl<D: DesignDual> DualState<D> {
    /// The state as the loads see it ([`crate::shell::load::Load::force`]).
    pub fn load_state(&self) -> LoadState<'_, D> {
        LoadState {
            particles: &self.particles,
            surfaces: &self.surfaces,
            positions: self.positions.as_deref(),
            surface: self.surface.as_ref(),
            thickness: self.thickness,
            young: self.material.young,
            poisson: self.material.poisson,
            tool_offsets: &self.tool_offsets,
            tool_rotations: &self.tool_rotations,
            tool_surfaces: self.tool_surfaces.as_deref(),
        }
    }
}

/// The sensitivities recorded at one converged step.
#[derive(Clone, Debug, PartialEq)]
pub struct DualStepRecord {
    /// Converged step index (0-based).
    pub step: usize,
    /// Load factor.
    pub load: f64,
    /// Monitor values (f64 analysis).
    pub values: Vec<f64>,
    /// `derivatives[m][v]`: d(monitor m)/d(variable v).
    pub derivatives: Vec<Vec<f64>>,
    /// Largest difference between the value parts of the committed dual state (particles,
    /// histories) and the f64 analysis state, relative to the largest entry of each field:
    /// round-off if the dual state follows the analysis.
    pub value_mismatch: f64,
    /// Number of yielding layer points in this step (from the f64 analysis: `ē^p` increased).
    pub plastic_points: usize,
}

/// Errors of the dual reference.
#[derive(Debug, Error)]
pub enum SensitivityError {
    /// Invalid design variables or monitors.
    #[error(transparent)]
    Design(#[from] DesignError),
    /// The problem is not at its initial (unloaded, virgin) state.
    #[error(
        "problem: committed unknowns are not zero (entry {index} = {value}); the dual \
             reference must start with the analysis"
    )]
    NotInitial {
        /// First non-zero unknown.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// A shape variable on a model whose coefficient modes invisible to the field are held by
    /// rows ([`crate::shell::gauge`]): the rows of the director patterns follow the initial
    /// directors, whose design derivative the methods do not carry into them.
    #[error(
        "design variable `{name}`: a shape variable, and the model holds {rows} coefficient \
         mode(s) invisible to the field by constraint rows (the cubic B-spline kernel at a \
         support near a multiple of 4 spacings between symmetry planes), whose design \
         derivative the continuum and dual methods do not carry; take the quartic spline \
         (`kernel.function` = \"quartic-spline\", the default at such supports), a support \
         away from multiples of 4 spacings (e.g. 3.5 or 4.5), or the finite differences alone"
    )]
    ShapeWithGaugeRows {
        /// The shape variable.
        name: String,
        /// The number of gauge rows.
        rows: usize,
    },
    /// More variables than the vector dual dispatch supports.
    #[error("design variables: {count} given, the vector dual supports 1..={max}")]
    TooManyVariables {
        /// Given.
        count: usize,
        /// Supported.
        max: usize,
    },
    /// A load of the problem the sensitivity methods do not carry
    /// ([`crate::shell::load::Load::takes_state`]).
    #[error(
        "load {index} of the problem ({kind}): not carried by the design sensitivity methods \
         (expected point forces, gravity, pressure, edge forces, contact or the director \
         filter, any of them held constant)"
    )]
    UnsupportedLoad {
        /// Position in [`ShellProblem::loads`].
        index: usize,
        /// Its kind.
        kind: &'static str,
    },
    /// More than one contact load (the dual reference seeds the tools of one).
    #[error("dual sensitivity reference: {count} contact loads given, expected at most one")]
    ContactLoads {
        /// Contact loads of the problem.
        count: usize,
    },
    /// A geometry the methods build could not be built (the initial geometry or a tool's
    /// surface in the dual scalar, a shape variable's design velocity).
    #[error("{what}: {source}")]
    Geometry {
        /// What was built.
        what: String,
        /// Why it failed.
        #[source]
        source: crate::geometry::GeometryError,
    },
    /// A load met during the run that the continuum DSA does not carry (the kinds refused
    /// before the analysis, [`crate::shell::load::Load::takes_state`], or a contact held
    /// constant).
    #[error("continuum sensitivity: {load}: expected {expected}")]
    LoadNotCarried {
        /// The load.
        load: String,
        /// What the method carries.
        expected: &'static str,
    },
    /// A converged step asked for (`--terms`, 1-based) that the analysis does not have.
    #[error("--terms {step}: expected a converged load step {}", step_range(*.steps))]
    StepOutOfRange {
        /// The step asked for.
        step: usize,
        /// The analysis' converged steps (`None`: not run yet).
        steps: Option<usize>,
    },
    /// A monitor.
    #[error(transparent)]
    Monitor(#[from] MonitorError),
    /// Shell evaluation.
    #[error(transparent)]
    Shell(#[from] ShellError),
    /// An observer of the analysis' steps (a method's recording, a monitor) failed after a
    /// commit.
    #[error(transparent)]
    Observer(Failure),
    /// The analysis could not be built for a design (`context` names what was built: the case
    /// file, a moved tool).
    #[error("{context}: {source}")]
    Build {
        /// What was built.
        context: String,
        /// Why it failed.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// Linear solver set-up.
    #[error(transparent)]
    Solver(#[from] crate::solver::SolverError),
    /// The analysis stopped.
    #[error("analysis: {0}")]
    Newton(Box<NewtonFailure>),
    /// A finite-difference re-run took other load steps than the nominal run, so its
    /// responses are not the same discrete functions of the design.
    #[error("finite differences of `{variable}` with step {h}: {detail}")]
    StepSequence {
        /// Design variable.
        variable: String,
        /// Perturbation.
        h: f64,
        /// What differs.
        detail: String,
    },
}

/// The converged steps a step number must lie in: `in 1..=N`, `≥ 1` before the run.
fn step_range(steps: Option<usize>) -> String {
    steps.map_or("≥ 1".into(), |n| format!("in 1..={n}"))
}

/// The dual-number sensitivity reference as an observer of the analysis' converged steps
/// ([`StepObserver`]): at each converged step it forms the dual residual's right-hand sides,
/// solves them with the converged tangent and carries its dual states to the next step.
#[derive(Debug)]
pub struct DualDsa<D: DesignDual> {
    variables: Vec<DesignVariable>,
    monitors: Vec<Monitor>,
    groups: Vec<DualState<D>>,
    pending: Option<Vec<DualState<D>>>,
    records: Vec<DualStepRecord>,
    time: Duration,
    failure: Option<Failure>,
    /// The model's histories at the start of the step being committed (the yielding count).
    before: Option<Vec<PointHistory<f64>>>,
}

/// The shell problem with the dual-number reference in its convergence hook.
pub type DualShellProblem<D> = Observed<ShellProblem, DualDsa<D>>;

/// What the dual reference's failures are reported as.
const CONTEXT: &str = "dual sensitivity reference";

fn fatal(e: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> ProblemError {
    ProblemError::Failed(Failure::new(CONTEXT, e))
}

impl<D: DesignDual> DualDsa<D> {
    /// The reference for `problem` (at its initial state, its model built on `surface`;
    /// `None`: no shape design variables allowed): `variables` are validated against its
    /// model, the problem's loads are evaluated with the dual states, `monitors` are recorded
    /// at every converged step. A shape design variable seeds its surface
    /// parameter: the group's initial geometry (quadrature-point surfaces, particle directors
    /// and lamina vectors, initial frames) is built in `D` from the seeded surface
    /// ([`dual_geometry`]), exactly as `ShellModel::new` builds it in `f64`.
    pub fn new(
        problem: &ShellProblem,
        surface: Option<&Surface<f64>>,
        variables: Vec<DesignVariable>,
        monitors: Vec<Monitor>,
    ) -> Result<Self, SensitivityError> {
        check_method_inputs(problem, surface, &variables, &monitors)?;
        let contacts = problem.loads().iter().filter_map(|l| l.contact()).count();
        if contacts > 1 {
            return Err(SensitivityError::ContactLoads { count: contacts });
        }
        let tool_list = super::contact_tools(problem);
        let tool_names: Vec<&str> = tool_list.iter().map(|t| t.name.as_str()).collect();
        let model = &problem.model;
        let design = Design::of(model);
        let nd = D::DIRECTIONS;
        let groups = (0..variables.len().div_ceil(nd))
            .map(|g| {
                let first = g * nd;
                let count = nd.min(variables.len() - first);
                let mut t_parts = vec![0.0; nd];
                let mut m_parts = vec![vec![0.0; nd]; 6];
                let n_shape = surface.map_or(0, |s| s.n_design_parameters());
                let mut s_parts = vec![vec![0.0; nd]; n_shape];
                let mut shape = false;
                let mut tool_parts =
                    vec![[vec![0.0; nd], vec![0.0; nd], vec![0.0; nd]]; tool_names.len()];
                let mut rotation_parts = tool_parts.clone();
                // Per tool, per surface design parameter, the seed of each direction.
                let mut tool_shape_parts: Vec<Vec<Vec<f64>>> = tool_list
                    .iter()
                    .map(|t| vec![vec![0.0; nd]; t.surface.n_design_parameters()])
                    .collect();
                let mut tool_shape = false;
                for (k, v) in variables[first..first + count].iter().enumerate() {
                    match &v.kind {
                        DesignKind::Thickness => t_parts[k] = 1.0,
                        DesignKind::Material(p) => m_parts[p.index()][k] = 1.0,
                        // The one check (`check_method_inputs`) found the surface
                        // parameter, the tool and the tool's surface parameter.
                        DesignKind::Shape { parameter, .. } => {
                            s_parts[*parameter][k] = 1.0;
                            shape = true;
                        }
                        DesignKind::Tool { tool, axis } => {
                            if let Some(i) = tool_names.iter().position(|n| n == tool) {
                                tool_parts[i][*axis][k] = 1.0;
                            }
                        }
                        DesignKind::ToolRotation { tool, axis } => {
                            if let Some(i) = tool_names.iter().position(|n| n == tool) {
                                rotation_parts[i][*axis][k] = 1.0;
                            }
                        }
                        DesignKind::ToolShape {
                            tool, parameter, ..
                        } => {
                            let i = tool_names.iter().position(|n| n == tool);
                            if let Some(slot) =
                                i.and_then(|i| tool_shape_parts[i].get_mut(*parameter))
                            {
                                slot[k] = 1.0;
                                tool_shape = true;
                            }
                        }
                    }
                }
                let tool_surfaces = if tool_shape {
                    let built = tool_list
                        .iter()
                        .zip(&tool_shape_parts)
                        .map(|(t, parts)| {
                            let p: Vec<D> = t
                                .surface
                                .parameter_values()
                                .iter()
                                .zip(parts)
                                .map(|(&v, e)| D::from_parts(v, e))
                                .collect();
                            t.surface.with_design_parameters::<D>(&p).map_err(|source| {
                                SensitivityError::Geometry {
                                    what: format!("dual surface of tool `{}`", t.name),
                                    source,
                                }
                            })
                        })
                        .collect::<Result<Vec<_>, _>>()?;
                    Some(built)
                } else {
                    None
                };
                let m = design.material.to_array();
                let (particles, history, surfaces, positions, seeded) = match surface {
                    Some(s) if shape => {
                        let g = dual_geometry::<D>(model, s, &s_parts).map_err(|source| {
                            SensitivityError::Geometry {
                                what: "dual geometry of the shape design variables".into(),
                                source,
                            }
                        })?;
                        (
                            g.particles,
                            g.history,
                            g.points,
                            Some(g.positions),
                            Some(g.surface),
                        )
                    }
                    _ => (
                        model.particles.iter().map(|p| p.lift()).collect(),
                        model.history.iter().map(|h| h.lift()).collect(),
                        model.points.iter().map(|p| p.surface.lift()).collect(),
                        None,
                        None,
                    ),
                };
                Ok(DualState {
                    first,
                    count,
                    particles,
                    history,
                    material: MaterialParams::from_array(std::array::from_fn(|i| {
                        D::from_parts(m[i], &m_parts[i])
                    })),
                    thickness: D::from_parts(design.thickness, &t_parts),
                    unknowns: problem.state().iter().map(|&v| D::cst(v)).collect(),
                    surfaces,
                    positions,
                    surface: seeded,
                    tool_offsets: tool_parts
                        .iter()
                        .map(|p| Vector3::from_fn(|c, _| D::from_parts(0.0, &p[c])))
                        .collect(),
                    tool_rotations: rotation_parts
                        .iter()
                        .map(|p| Vector3::from_fn(|c, _| D::from_parts(0.0, &p[c])))
                        .collect(),
                    tool_surfaces,
                })
            })
            .collect::<Result<Vec<_>, SensitivityError>>()?;
        Ok(DualDsa {
            variables,
            monitors,
            groups,
            pending: None,
            records: Vec::new(),
            time: Duration::ZERO,
            failure: None,
            before: None,
        })
    }

    /// The design variables.
    pub fn variables(&self) -> &[DesignVariable] {
        &self.variables
    }

    /// The records of the converged steps.
    pub fn records(&self) -> &[DualStepRecord] {
        &self.records
    }

    /// The committed dual states (one per group of variables).
    pub fn groups(&self) -> &[DualState<D>] {
        &self.groups
    }

    /// Wall time spent in the reference (right-hand sides, solve, dual updates).
    pub fn time(&self) -> Duration {
        self.time
    }

    /// The run's result, once the analysis it observed has ended with `report` after `total`.
    pub fn into_run(self, report: NewtonReport, total: Duration) -> DualRun {
        DualRun {
            variables: self.variables,
            records: self.records,
            report,
            total,
            reference: self.time,
        }
    }

    /// The dual external force of group `g` (generalised rows) at the increment `dq` and load
    /// `load`: every load of the problem on the group's state
    /// ([`crate::shell::load::Load::force`]).
    pub(crate) fn dual_external(
        &self,
        problem: &ShellProblem,
        g: &DualState<D>,
        dq: &[D],
        load: f64,
    ) -> Result<Vec<D>, ShellError> {
        self.dual_loads(problem, g, dq, load, |_| true)
    }

    /// The share of the director filter in [`Self::dual_external`].
    pub(crate) fn dual_filter(
        &self,
        problem: &ShellProblem,
        g: &DualState<D>,
        dq: &[D],
        load: f64,
    ) -> Result<Vec<D>, ShellError> {
        self.dual_loads(problem, g, dq, load, |l| {
            matches!(l, Load::DirectorFilter(_))
        })
    }

    /// The loads of the problem for which `which` holds, on the group's state.
    fn dual_loads(
        &self,
        problem: &ShellProblem,
        g: &DualState<D>,
        dq: &[D],
        load: f64,
        which: impl Fn(&Load) -> bool,
    ) -> Result<Vec<D>, ShellError> {
        let state = g.load_state();
        let mut f_ext = vec![D::zero(); problem.n_generalised()];
        for l in problem.loads().iter().filter(|l| which(l)) {
            l.force(&problem.model, Some(&state), dq, load, &mut f_ext)?;
        }
        Ok(f_ext)
    }

    /// The dual residual `R(Δu; ⁿs, τ)` of group `g` (all unknowns' rows) at the converged
    /// unknowns `u` and load `load`.
    pub(crate) fn dual_residual(
        &self,
        problem: &ShellProblem,
        g: &DualState<D>,
        dq: &[D],
        u: &[f64],
        load: f64,
    ) -> Result<Vec<D>, ShellError> {
        let model = &problem.model;
        let (f_int, _) = model.internal_force_with_surfaces(
            &g.particles,
            &g.history,
            &g.material,
            g.thickness,
            dq,
            Some(&g.surfaces),
        )?;
        let mut r = f_int;
        r.resize(u.len(), D::zero());
        let f_ext = self.dual_external(problem, g, dq, load)?;
        for (ri, fi) in r.iter_mut().zip(&f_ext) {
            *ri -= *fi;
        }
        // Constraint rows with the committed unknowns' sensitivities (Δu has none).
        let ud: Vec<D> = u
            .iter()
            .zip(&g.unknowns)
            .map(|(&v, c)| *c + D::cst(v - c.value()))
            .collect();
        problem.add_constraint_rows(&ud, load, &mut r);
        Ok(r)
    }

    fn hook(
        &mut self,
        problem: &ShellProblem,
        step: &ConvergedStep<'_>,
    ) -> Result<(), ProblemError> {
        if step.factorised_at != FactorisedAt::Converged {
            return Err(fatal(
                "the solver's tangent is not the converged one (the observer must ask for \
                 ConvergedTangent::Required)",
            ));
        }
        let n = step.u.len();
        let n_q = problem.n_generalised();
        let committed = problem.state();
        let du: Vec<f64> = step.u.iter().zip(committed).map(|(a, b)| a - b).collect();
        let dq_const: Vec<D> = du[..n_q].iter().map(|&v| D::cst(v)).collect();
        // 1. Right-hand sides of all variables, column-major n × n_variables.
        let nv = self.variables.len();
        let mut b = vec![0.0; n * nv];
        for g in &self.groups {
            let r = self
                .dual_residual(problem, g, &dq_const, step.u, step.load)
                .map_err(fatal)?;
            for k in 0..g.count {
                let col = &mut b[(g.first + k) * n..(g.first + k + 1) * n];
                for (c, ri) in col.iter_mut().zip(&r) {
                    *c = -ri.part(k);
                }
                step.essential.zero_constrained(col);
            }
        }
        // 2. One multi-RHS solve with the converged tangent (eq 65).
        step.solver
            .solve_columns_in_place(&mut b, nv)
            .map_err(fatal)?;
        // 3. The dual increment, the dual point and particle updates.
        let mut next = Vec::with_capacity(self.groups.len());
        for g in &self.groups {
            let mut parts = vec![0.0; D::DIRECTIONS];
            let inc: Vec<D> = (0..n)
                .map(|i| {
                    for (k, p) in parts.iter_mut().enumerate().take(g.count) {
                        *p = b[(g.first + k) * n + i];
                    }
                    D::from_parts(du[i], &parts)
                })
                .collect();
            let model = &problem.model;
            let (_, history) = model
                .internal_force_with_surfaces(
                    &g.particles,
                    &g.history,
                    &g.material,
                    g.thickness,
                    &inc[..n_q],
                    Some(&g.surfaces),
                )
                .map_err(fatal)?;
            let particles = g
                .particles
                .iter()
                .zip(inc[..n_q].chunks_exact(DOFS_PER_PARTICLE))
                .map(|(p, q)| commit_particle(p, q))
                .collect();
            let unknowns = g.unknowns.iter().zip(&inc).map(|(a, d)| *a + *d).collect();
            next.push(DualState {
                first: g.first,
                count: g.count,
                particles,
                history,
                material: g.material,
                thickness: g.thickness,
                unknowns,
                surfaces: g.surfaces.clone(),
                positions: g.positions.clone(),
                surface: g.surface.clone(),
                tool_offsets: g.tool_offsets.clone(),
                tool_rotations: g.tool_rotations.clone(),
                tool_surfaces: g.tool_surfaces.clone(),
            });
        }
        self.pending = Some(next);
        Ok(())
    }

    /// After the analysis' commit: adopt the pending dual state and record the monitors.
    fn record(
        &mut self,
        problem: &ShellProblem,
        load: f64,
        plastic_points: usize,
    ) -> Result<(), Failure> {
        let next = self
            .pending
            .take()
            .ok_or_else(|| Failure::new(CONTEXT, "commit without a converged-step hook"))?;
        self.groups = next;
        let model = &problem.model;
        let mut mismatch = 0.0_f64;
        for g in &self.groups {
            mismatch = mismatch.max(value_mismatch(model, g));
        }
        let (values, derivatives) = super::record_monitors(problem, load, &self.monitors, &*self)
            .map_err(|e| Failure::new(CONTEXT, e))?;
        self.records.push(DualStepRecord {
            step: self.records.len(),
            load,
            values,
            derivatives,
            value_mismatch: mismatch,
            plastic_points,
        });
        Ok(())
    }

    /// The group that carries design variable `v`.
    fn group_of(&self, v: usize) -> Option<&DualState<D>> {
        let mut groups = self.groups.iter();
        groups.find(|g| (g.first..g.first + g.count).contains(&v))
    }
}

impl<D: DesignDual> SensitivityFields for DualDsa<D> {
    fn n_variables(&self) -> usize {
        self.variables.len()
    }
    fn translations(&self, model: &crate::shell::model::ShellModel, v: usize) -> Vec<f64> {
        let mut q = vec![0.0; model.n_dofs()];
        if let Some(g) = self.group_of(v) {
            for (i, p) in g.particles.iter().enumerate() {
                for c in 0..3 {
                    q[DOFS_PER_PARTICLE * i + c] = p.u[c].part(v - g.first);
                }
            }
        }
        q
    }
    fn plastic_strain(&self, v: usize) -> Vec<f64> {
        self.group_of(v).map_or_else(Vec::new, |g| {
            let history = g.history.iter();
            history
                .map(|h| h.material.eps_p.part(v - g.first))
                .collect()
        })
    }
    /// The contact's tool forces evaluated on every group's dual state
    /// ([`crate::shell::load::ContactLoad::tool_forces`]), their derivative parts.
    fn tool_force_dots(
        &self,
        problem: &ShellProblem,
        load: f64,
    ) -> Result<Vec<Vec<[f64; 3]>>, SensitivityError> {
        let mut out = vec![Vec::new(); self.variables.len()];
        let Some(c) = super::contact_load(problem) else {
            return Ok(out);
        };
        let q = vec![D::zero(); problem.model.n_dofs()];
        for g in &self.groups {
            let forces = c.tool_forces(&problem.model, &g.load_state(), &q, load)?;
            for k in 0..g.count {
                out[g.first + k] = forces
                    .iter()
                    .map(|f| [f[0].part(k), f[1].part(k), f[2].part(k)])
                    .collect();
            }
        }
        Ok(out)
    }
}

/// Shape variables are refused on a model with gauge rows ([`crate::shell::gauge`]): the rows
/// of the director patterns follow the initial directors, which the methods do not carry into
/// them ([`SensitivityError::ShapeWithGaugeRows`]).
pub fn check_gauge_rows(
    problem: &ShellProblem,
    variables: &[DesignVariable],
) -> Result<(), SensitivityError> {
    let rows = problem.gauge_modes().len();
    match variables
        .iter()
        .find(|v| rows > 0 && matches!(v.kind, DesignKind::Shape { .. }))
    {
        Some(v) => Err(SensitivityError::ShapeWithGaugeRows {
            name: v.name.clone(),
            rows,
        }),
        None => Ok(()),
    }
}

/// What both sensitivity methods check before the analysis: the design variables are
/// admissible for the model (and for `surface`, which shape variables need), the problem is at
/// its initial state, its loads are of the kinds the methods carry, and every monitor can be
/// evaluated.
pub(crate) fn check_method_inputs(
    problem: &ShellProblem,
    surface: Option<&Surface<f64>>,
    variables: &[DesignVariable],
    monitors: &[Monitor],
) -> Result<(), SensitivityError> {
    let model = &problem.model;
    let base = match surface {
        Some(s) => Design::of_shell(model, s),
        None => Design::of(model),
    };
    let scope = DesignScope {
        base: Some(&base),
        model: Some(model),
        tools: Some(super::contact_tools(problem)),
    };
    check_design(variables, &|_| vec![0.0], &scope)?;
    check_gauge_rows(problem, variables)?;
    if let Some((index, &value)) = problem.state().iter().enumerate().find(|(_, v)| **v != 0.0) {
        return Err(SensitivityError::NotInitial { index, value });
    }
    if let Some((index, l)) = problem
        .loads()
        .iter()
        .enumerate()
        .find(|(_, l)| !l.takes_state())
    {
        let kind = l.kind();
        return Err(SensitivityError::UnsupportedLoad { index, kind });
    }
    for m in monitors {
        m.value(problem, 0.0)?;
    }
    Ok(())
}

/// Largest difference between the value parts of a dual state and the model, relative to the
/// largest entry of each field (displacements, directors, lamina vectors, frames, stresses,
/// back stresses, plastic strains).
pub fn value_mismatch<D: DesignDual>(
    model: &crate::shell::model::ShellModel,
    g: &DualState<D>,
) -> f64 {
    let mut fields = [(0.0_f64, 0.0_f64); 7];
    let mut acc = |f: usize, dual: &D, val: f64| {
        fields[f].0 = fields[f].0.max((dual.value() - val).abs());
        fields[f].1 = fields[f].1.max(val.abs());
    };
    for (pd, pm) in g.particles.iter().zip(&model.particles) {
        for c in 0..3 {
            acc(0, &pd.u[c], pm.u[c]);
            acc(1, &pd.d[c], pm.d[c]);
            acc(2, &pd.e[0][c], pm.e[0][c]);
            acc(2, &pd.e[1][c], pm.e[1][c]);
        }
    }
    for (hd, hm) in g.history.iter().zip(&model.history) {
        for (a, b) in hd.frame.iter().zip(hm.frame.iter()) {
            acc(3, a, *b);
        }
        for c in 0..5 {
            acc(4, &hd.material.stress[c], hm.material.stress[c]);
            acc(5, &hd.material.back_stress[c], hm.material.back_stress[c]);
        }
        acc(6, &hd.material.eps_p, hm.material.eps_p);
    }
    fields
        .iter()
        .map(|&(d, s)| if s > 0.0 { d / s } else { d })
        .fold(0.0, f64::max)
}

/// Number of layer points whose effective plastic strain grew from `before` to `after`.
pub fn yielding_points(before: &[PointHistory<f64>], after: &[PointHistory<f64>]) -> usize {
    before
        .iter()
        .zip(after)
        .filter(|(a, b)| b.material.eps_p > a.material.eps_p)
        .count()
}

impl<D: DesignDual> StepObserver<ShellProblem> for DualDsa<D> {
    /// The reference solves with the tangent at the converged state.
    fn converged_tangent(&self, _problem: ConvergedTangent) -> ConvergedTangent {
        ConvergedTangent::Required
    }
    fn on_converged(
        &mut self,
        problem: &ShellProblem,
        step: &ConvergedStep<'_>,
    ) -> Result<(), ProblemError> {
        if let Some(f) = &self.failure {
            return Err(ProblemError::Failed(f.clone()));
        }
        let t0 = Instant::now();
        let out = self.hook(problem, step);
        self.time += t0.elapsed();
        out
    }
    fn before_commit(&mut self, problem: &ShellProblem, _u: &[f64], _load: f64) {
        self.before = Some(problem.model.history.clone());
    }
    fn after_commit(&mut self, problem: &ShellProblem, _u: &[f64], load: f64) {
        let plastic = self
            .before
            .take()
            .map_or(0, |before| yielding_points(&before, &problem.model.history));
        let t0 = Instant::now();
        if let Err(e) = self.record(problem, load, plastic) {
            // A commit cannot fail: the next hook (or the caller, `failure()`) reports it.
            self.failure.get_or_insert(e);
        }
        self.time += t0.elapsed();
    }
    fn on_restore(&mut self) {
        self.pending = None;
    }
    fn failure(&self) -> Option<Failure> {
        self.failure.clone()
    }
}

/// Which dual scalar the reference uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum DualMode {
    /// `DualSVec64<N>`, all variables in one pass (N = number of variables, 1..=8).
    #[default]
    Vector,
    /// `Dual64`, one pass per variable.
    PerVariable,
}

/// The result of [`run_dual`].
#[derive(Clone, Debug)]
pub struct DualRun {
    /// The design variables.
    pub variables: Vec<DesignVariable>,
    /// Per converged step.
    pub records: Vec<DualStepRecord>,
    /// The Newton report.
    pub report: NewtonReport,
    /// Wall time of the whole run (analysis and reference).
    pub total: Duration,
    /// Wall time of the reference alone.
    pub reference: Duration,
}

impl DualRun {
    /// Cost of the reference per design variable as a fraction of the analysis (the run's time
    /// without the reference).
    pub fn cost_per_variable(&self) -> f64 {
        let analysis = (self.total - self.reference).as_secs_f64();
        self.reference.as_secs_f64() / analysis / self.variables.len() as f64
    }
}

/// Run the analysis of `problem` with the dual reference of `variables` in its convergence
/// hook (`mode` picks the dual scalar), recording `monitors` and their derivatives at every
/// converged step.
pub fn run_dual(
    problem: ShellProblem,
    variables: Vec<DesignVariable>,
    monitors: Vec<Monitor>,
    newton: &NewtonSolver,
    solver: SolverOptions,
    mode: DualMode,
) -> Result<DualRun, SensitivityError> {
    run_dual_on(
        super::DsaAnalysis {
            problem,
            surface: None,
            variables,
            monitors,
            newton,
            solver,
        },
        mode,
    )
}

/// [`run_dual`] for an analysis whose model was built on a surface, which admits shape design
/// variables ([`DualDsa::new`]).
pub fn run_dual_on(
    analysis: super::DsaAnalysis<'_>,
    mode: DualMode,
) -> Result<DualRun, SensitivityError> {
    let methods = super::HookedMethods {
        continuum: false,
        dual: Some(mode),
        schedule: super::continuum::ContinuumSchedule::Synchronous,
        solve: super::continuum::SensitivitySolve::Factorised,
    };
    let (_, run) = super::run_hooked(analysis, methods, &mut |_| {})?;
    Ok(run.unwrap_or_else(|| unreachable!("run_hooked returns a run per method asked for")))
}
