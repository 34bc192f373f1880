//! Shell case files: `[problem] kind = "shell"`.
//!
//! The TOML is read into loose `serde` structs (`deny_unknown_fields` everywhere, so a typo is
//! an error naming the key, line and column), then validated into a typed, checked
//! [`ShellCase`]. Every validation error is a [`CaseError::Invalid`] naming the dotted key
//! (`boundary[2].edge`, `steps.min_step`, ...), the value as written and what was expected.
//! The format is documented, with an annotated complete example (the MacNeal–Harder pinched
//! hemisphere), in `docs/case-format.md`.
//!
//! Nothing here builds the model: [`crate::io::shell_build`] does that from a [`ShellCase`].

pub use super::Monitor;
use super::{exact, exact_opt, fmt_num, material_from_spec, CaseError, MaterialSpec};
use crate::contact::{PathKey, RigidTool, Side, ToolPath};
use crate::geometry::{Surface, SurfaceSpec};
use crate::material::MaterialParams;
use crate::meshfree::quadrature::{ThicknessRule, MAX_GAUSS_POINTS, MAX_LOBATTO_POINTS};
use crate::meshfree::vci::VciOrder;
use crate::meshfree::Edge;
use crate::meshfree::{Basis, KernelFunction, ParamBox};
use crate::shell::contact::{ContactFaces, DEFAULT_PENALTY_FACTOR};
use crate::shell::stabilisation::FilterStrength;
use nalgebra::Vector3;
use serde::Deserialize;
use std::path::{Path, PathBuf};

// ---------------------------------------------------------------------------------------------
// The file as written (loose; checked below).

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ShellFile {
    thickness: Option<f64>,
    problem: ProblemFile,
    surface: SurfaceSpec,
    particles: ParticlesFile,
    kernel: KernelFile,
    integration: IntegrationFile,
    material: MaterialSpec,
    #[serde(default)]
    boundary: Vec<BoundaryFile>,
    #[serde(default)]
    load: Vec<LoadFile>,
    steps: StepsFile,
    #[serde(default)]
    monitor: Vec<MonitorFile>,
    #[serde(default)]
    output: Option<OutputFile>,
    #[serde(default)]
    tool: Vec<ToolFile>,
    #[serde(default)]
    contact: Option<ContactFile>,
    #[serde(default)]
    design: Vec<super::dsa_case::DesignFile>,
    #[serde(default)]
    dsa: Option<super::dsa_case::DsaFile>,
    #[serde(default)]
    limits: Option<LimitsFile>,
}

/// `[limits]`: raise the resource limits of [`Limits`] for a case that needs more.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct LimitsFile {
    #[serde(default)]
    max_unknowns: Option<i64>,
    #[serde(default)]
    max_layer_points: Option<i64>,
    #[serde(default)]
    max_memory_gb: Option<f64>,
    #[serde(default)]
    max_support: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ProblemFile {
    #[allow(dead_code)] // dispatched on before this struct is parsed
    kind: String,
    #[serde(default)]
    title: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ParticlesFile {
    #[serde(deserialize_with = "exact")]
    grid: [i64; 2],
    #[serde(default)]
    jitter: f64,
    #[serde(default)]
    seed: u64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct KernelFile {
    basis: String,
    support: f64,
    function: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct IntegrationFile {
    /// `"per-particle-spacing"` or `[n_u, n_v]` (checked by hand for a clear message).
    cells: toml::Value,
    #[serde(default)]
    subdivide: Option<i64>,
    gauss: i64,
    thickness_points: i64,
    thickness_rule: String,
    #[serde(default)]
    vci: Option<String>,
    #[serde(default)]
    director_stabilisation: Option<f64>,
    #[serde(default)]
    director_stabilisation_strength: Option<String>,
    #[serde(default)]
    director_stabilisation_floor: Option<f64>,
    #[serde(default)]
    director_stabilisation_support: Option<f64>,
    #[serde(default)]
    director: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct BoundaryFile {
    kind: String,
    edge: Option<String>,
    #[serde(default, deserialize_with = "exact_opt")]
    at: Option<[f64; 2]>,
    #[serde(default, deserialize_with = "exact_opt")]
    normal: Option<[f64; 3]>,
    #[serde(default, deserialize_with = "exact_opt")]
    point: Option<[f64; 3]>,
    components: Option<Vec<String>>,
    component: Option<String>,
    value: Option<f64>,
    everywhere: Option<bool>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct LoadFile {
    kind: String,
    #[serde(default, deserialize_with = "exact_opt")]
    at: Option<[f64; 2]>,
    #[serde(default, deserialize_with = "exact_opt")]
    force: Option<[f64; 3]>,
    value: Option<f64>,
    #[serde(default, deserialize_with = "exact_opt")]
    per_area: Option<[f64; 3]>,
    #[serde(default, deserialize_with = "exact_opt")]
    per_volume: Option<[f64; 3]>,
    edge: Option<String>,
    #[serde(default, deserialize_with = "exact_opt")]
    per_length: Option<[f64; 3]>,
    #[serde(default)]
    follower: Option<bool>,
    #[serde(default)]
    scaling: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ToolFile {
    name: String,
    surface: SurfaceSpec,
    side: String,
    path: ToolPathFile,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ToolPathFile {
    #[serde(default, deserialize_with = "exact_opt")]
    pivot: Option<[f64; 3]>,
    #[serde(default)]
    keys: Option<Vec<PathKeyFile>>,
    #[serde(default, deserialize_with = "exact_opt")]
    stroke: Option<[f64; 3]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PathKeyFile {
    t: f64,
    #[serde(deserialize_with = "exact")]
    translation: [f64; 3],
    #[serde(default, deserialize_with = "exact_opt")]
    rotation: Option<[f64; 3]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ContactFile {
    #[serde(default)]
    faces: Option<String>,
    #[serde(default)]
    penalty: Option<f64>,
    #[serde(default)]
    penalty_factor: Option<f64>,
    #[serde(default)]
    release: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct StepsFile {
    #[serde(default)]
    initial_step: Option<f64>,
    #[serde(default)]
    min_step: Option<f64>,
    #[serde(default)]
    max_step: Option<f64>,
    #[serde(default = "one")]
    final_load: f64,
    #[serde(default = "default_max_iterations")]
    max_iterations: i64,
    #[serde(default = "default_max_iterations")]
    max_active_set_iterations: i64,
    #[serde(default = "default_residual_rtol")]
    residual_rtol: f64,
    #[serde(default)]
    residual_atol: f64,
    #[serde(default = "default_energy_rtol")]
    energy_rtol: f64,
    #[serde(default)]
    energy_atol: f64,
    #[serde(default = "default_cut")]
    cut_factor: f64,
    #[serde(default = "default_grow")]
    grow_factor: f64,
    #[serde(default = "default_easy")]
    easy_iterations: i64,
    #[serde(default)]
    predictor: Option<String>,
    #[serde(default)]
    linear_updates: Option<String>,
    #[serde(default)]
    preconditioner: Option<String>,
    #[serde(default)]
    line_search: Option<String>,
    #[serde(default)]
    stop_failure: Option<String>,
    #[serde(default)]
    stops: Vec<f64>,
    #[serde(default = "default_max_attempts")]
    max_attempts: i64,
    #[serde(default)]
    control: Option<String>,
    #[serde(default)]
    arc_length: Option<f64>,
    #[serde(default)]
    min_arc_length: Option<f64>,
    #[serde(default)]
    max_arc_length: Option<f64>,
}

fn default_max_attempts() -> i64 {
    DEFAULT_MAX_ATTEMPTS as i64
}

/// Default `steps.max_attempts`: step attempts (converged or cut) before a run stops.
pub const DEFAULT_MAX_ATTEMPTS: usize = 10_000;

fn one() -> f64 {
    1.0
}
fn default_max_iterations() -> i64 {
    20
}
fn default_residual_rtol() -> f64 {
    1e-8
}
fn default_energy_rtol() -> f64 {
    1e-14
}
fn default_cut() -> f64 {
    0.5
}
fn default_easy() -> i64 {
    4
}

fn default_grow() -> f64 {
    1.5
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MonitorFile {
    name: String,
    #[serde(deserialize_with = "exact")]
    at: [f64; 2],
    #[serde(default)]
    direction: Option<DirectionFile>,
}

/// `[[monitor]] direction`: a vector or the word `"normal"`.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum DirectionFile {
    Vector([f64; 3]),
    Word(String),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct OutputFile {
    #[serde(default = "yes")]
    vtu: bool,
    #[serde(default = "one_i")]
    every: i64,
    #[serde(default = "one_i")]
    subdivide: i64,
    #[serde(default = "yes")]
    plot: bool,
}

fn yes() -> bool {
    true
}
fn one_i() -> i64 {
    1
}

// ---------------------------------------------------------------------------------------------
// The checked case.

/// Particle layout on the surface's parameter box: a regular grid, optionally jittered
/// ([`crate::meshfree::jittered_grid`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParticleLayout {
    /// `(n_u, n_v)`, each ≥ 2.
    pub counts: [usize; 2],
    /// Jitter as a fraction of the spacing, in `[0, 0.5)` (0: regular grid).
    pub jitter: f64,
    /// Seed of the jitter.
    pub seed: u64,
}

/// The smallest support of the director filter's RK functions, in particle spacings
/// (`integration.director_stabilisation_support`): from 2 on a particle's neighbours on the
/// lattice (offsets ±1 in both directions) carry weight, the fewest that a quadratic basis needs.
pub const MIN_FILTER_SUPPORT: f64 = 2.0;

/// RK kernel: basis, support half-width as a multiple of the particle spacing, and the kernel
/// function.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KernelSpec {
    /// Polynomial basis.
    pub basis: Basis,
    /// Support half-width in particle spacings (per direction), > 0.
    pub support: f64,
    /// `kernel.function`; by default [`KernelFunction::default_for`] the support: the cubic
    /// B-spline, or the quartic spline where the cubic is blind to alternating patterns.
    pub function: KernelFunction,
}

/// Background cells of the in-plane quadrature.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CellLayout {
    /// One cell between neighbouring nominal particle grid lines, each split `subdivide` times
    /// per direction ([`crate::meshfree::quadrature::CellQuadrature::for_particle_grid`]).
    PerParticleSpacing {
        /// Subdivisions per direction (≥ 1).
        subdivide: usize,
    },
    /// `n_u × n_v` equal cells on the parameter box.
    Counts([usize; 2]),
}

/// `[integration]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IntegrationSpec {
    /// Background cells.
    pub cells: CellLayout,
    /// Gauss–Legendre points per cell and direction (`1..=10`).
    pub gauss: usize,
    /// Through-thickness rule.
    pub thickness_rule: ThicknessRule,
    /// Variationally consistent correction of the test gradients (docs/integration.md).
    pub vci: VciOrder,
    /// Factor `ε` of the director-filter stabilisation (docs/stability.md; 0: off).
    pub director_stabilisation: f64,
    /// How the stabilisation's stiffness is set from `ε` (docs/stability.md).
    pub director_stabilisation_strength: FilterStrength,
    /// The floor `φ` of the per-particle strength, a fraction of `E t³ / (12 (1 − ν²))`
    /// (docs/stability.md; 0: none).
    pub director_stabilisation_floor: f64,
    /// Support half-width, in particle spacings, of the RK functions that define the
    /// stabilisation's filter (docs/stability.md §8); by default `kernel.support` (the model's
    /// own functions).
    pub director_stabilisation_support: f64,
    /// The director field at the quadrature points (docs/stability.md §9).
    pub director: crate::shell::point::DirectorField,
}

/// A displacement or rotation component of a particle's 5 DOFs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Component {
    /// Displacement along global x.
    Ux,
    /// Displacement along global y.
    Uy,
    /// Displacement along global z.
    Uz,
    /// Director rotation about the particle's first lamina vector `e1`.
    Rot1,
    /// Director rotation about the particle's second lamina vector `e2`.
    Rot2,
}

impl Component {
    /// All five, in DOF order.
    pub const ALL: [Component; 5] = [
        Component::Ux,
        Component::Uy,
        Component::Uz,
        Component::Rot1,
        Component::Rot2,
    ];
    /// The names used in case files.
    pub const NAMES: [&'static str; 5] = ["ux", "uy", "uz", "rot1", "rot2"];
    /// Index of the component within a particle's 5 DOFs `[Δu(3), α1, α2]`.
    pub fn index(self) -> usize {
        self as usize
    }
    /// Name as written in case files.
    pub fn name(self) -> &'static str {
        Self::NAMES[self.index()]
    }
    fn parse(s: &str) -> Option<Self> {
        Self::NAMES
            .iter()
            .position(|n| *n == s)
            .map(|k| Self::ALL[k])
    }
}

/// Where a `fixed` condition applies.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Location {
    /// Every point of a parametric edge.
    Edge(Edge),
    /// One parameter point.
    Point([f64; 2]),
    /// Every real particle (`everywhere = true`): the listed generalised DOFs of each particle
    /// are held, so the interpolated component is zero everywhere. For `rot1`/`rot2` these
    /// are the rotations about each particle's own lamina vectors.
    Everywhere,
}

/// One `[[boundary]]` entry.
#[derive(Clone, Debug, PartialEq)]
pub enum Boundary {
    /// Symmetry plane through `point` with unit `normal`, on parametric `edge` (the edge lies in
    /// the plane and the surface normal along it is in the plane: checked).
    Symmetry {
        /// The edge.
        edge: Edge,
        /// A point of the plane.
        point: [f64; 3],
        /// Unit plane normal.
        normal: [f64; 3],
    },
    /// All five components held on the edge.
    Clamped {
        /// The edge.
        edge: Edge,
    },
    /// The three displacements held on the edge, rotations free (hard simple support).
    SimplySupported {
        /// The edge.
        edge: Edge,
    },
    /// The listed components held at zero on an edge or at a point.
    Fixed {
        /// Where.
        location: Location,
        /// Which components (distinct, sorted).
        components: Vec<Component>,
    },
    /// Displacement control: `component` at `at` equals `λ · value` (ramps with the load factor).
    Prescribed {
        /// Parameter point.
        at: [f64; 2],
        /// A displacement component (`ux`, `uy` or `uz`).
        component: Component,
        /// Value at load factor 1.
        value: f64,
    },
}

/// One `[[load]]` entry, at load factor 1.
#[derive(Clone, Debug, PartialEq)]
pub enum Load {
    /// Dead force at a parameter point.
    PointForce {
        /// Parameter point.
        at: [f64; 2],
        /// Force (global axes).
        force: [f64; 3],
    },
    /// Follower pressure `value` (force per current area) along the current mid-surface normal.
    Pressure {
        /// Pressure.
        value: f64,
    },
    /// Dead load per unit (initial) area, e.g. self weight.
    Gravity {
        /// Force per unit area (global axes).
        per_area: [f64; 3],
    },
    /// Dead load per unit (initial) volume, `ρ g`: per unit area it is `ρ g t`, so it follows
    /// the thickness (and its design derivative).
    GravityPerVolume {
        /// Force per unit volume (global axes).
        per_volume: [f64; 3],
    },
    /// Moment per unit length about a fixed axis, along a parametric edge.
    Moment {
        /// The edge.
        edge: Edge,
        /// Moment per unit length (global axes).
        per_length: [f64; 3],
    },
    /// Force per unit initial length along a parametric edge: dead (fixed global vector) or
    /// follower (components in the current edge frame: along the edge's outward normal in the
    /// surface, along the current mid-surface normal, along the edge tangent).
    EdgeForce {
        /// The edge.
        edge: Edge,
        /// Force per unit length: global `[fx, fy, fz]` (dead) or `[f_out, f_normal, f_tangent]`
        /// (follower).
        per_length: [f64; 3],
        /// Whether it follows the deforming edge.
        follower: bool,
    },
}

/// Driver choice of the first iterate of a step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PredictorKind {
    /// Start every step from the converged state.
    Zero,
    /// Start from the previous step's increment scaled by the step ratio.
    Secant,
    /// Extrapolate quadratically through the last three converged states.
    Quadratic,
}

/// `[steps]`: load stepping from 0 to `final_load` and Newton tolerances.
#[derive(Clone, Debug, PartialEq)]
pub struct StepsSpec {
    /// First load-factor step.
    pub initial_step: f64,
    /// Smallest step before giving up.
    pub min_step: f64,
    /// Largest step.
    pub max_step: f64,
    /// Final load factor (> 0).
    pub final_load: f64,
    /// Newton iterations per step, not counting those whose iterate changed the contact
    /// active set.
    pub max_iterations: usize,
    /// Newton iterations per step whose iterate changed the contact active set.
    pub max_active_set_iterations: usize,
    /// Relative residual tolerance.
    pub residual_rtol: f64,
    /// Absolute residual floor.
    pub residual_atol: f64,
    /// Relative energy tolerance.
    pub energy_rtol: f64,
    /// Absolute energy floor.
    pub energy_atol: f64,
    /// Step factor after a failure, in (0, 1).
    pub cut_factor: f64,
    /// Step factor after an easy step, ≥ 1.
    pub grow_factor: f64,
    /// A step converging in at most this many iterations is easy (the step then grows).
    pub easy_iterations: usize,
    /// Predictor (`None`: the driver's default).
    pub predictor: Option<PredictorKind>,
    /// How Newton updates are solved (`steps.linear_updates`): `"direct"` (the default: a
    /// factorisation per update), `"auto"` (GMRES preconditioned by the held factorisation
    /// with the sparse solvers, a factorisation per update with the dense one), `"krylov"`
    /// (near convergence, preconditioned by the step's last factorisation) or `"krylov-held"`.
    /// Measured on the plastic hemisphere at 17², 25², 33²: `"auto"` and `"krylov"` take the
    /// same CPU time within the machine's noise, so the simplest is the default.
    pub linear_updates: crate::solver::LinearUpdates,
    /// The precision of the triangular solves that apply a held factorisation as GMRES's
    /// preconditioner (`steps.preconditioner`): `"single"` (the default: the factors rounded
    /// to single precision, half the memory traffic) or `"double"`
    /// ([`crate::solver::PreconditionerPrecision`]). Only the supernodal LU of large systems
    /// has a single-precision copy; every solution is accepted on its double-precision
    /// residual either way.
    pub preconditioner: crate::solver::PreconditionerPrecision,
    /// What an unusable Newton iterate (an inverted cell, a failed return map, a diverged
    /// residual, a singular tangent) leads to (`steps.line_search`): `"on-failure"` (the
    /// default: backtrack along the update, `s` = 1/2 … 1/16, before the step is cut; steps
    /// that converge without it take the same iterates) or `"off"` (cut the step).
    pub line_search: crate::solver::LineSearch,
    /// What a failed attempt to land on a stop leads to (`steps.stop_failure`): `"cut"` (the
    /// default: a shorter step is committed) or `"continuation"` (the stop is reached from the
    /// committed state through intermediate solutions that are not committed; the design
    /// sensitivity's re-runs use it to land on the nominal run's levels).
    pub stop_failure: crate::solver::StopFailure,
    /// Load levels the stepping lands on exactly (strictly ascending, finite, in
    /// `(0, final_load]`; possibly empty).
    pub stops: Vec<f64>,
    /// Step attempts (converged or cut) before the run stops (default
    /// [`DEFAULT_MAX_ATTEMPTS`]).
    pub max_attempts: usize,
    /// Arc-length continuation (`control = "arc-length"`): `[initial, min, max]` arc length;
    /// `None` for load stepping (`control = "load"`, the default).
    pub arc_length: Option<[f64; 3]>,
}

/// A monitor's scalar: the displacement along a fixed unit vector, or along the initial unit
/// normal of the mid-surface at the monitor's point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MonitorDirection {
    /// A fixed unit vector (global axes).
    Fixed([f64; 3]),
    /// The initial mid-surface normal `x̄,u × x̄,v / |x̄,u × x̄,v|` at the point.
    Normal,
}

/// `[output]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OutputSpec {
    /// Write a VTU per converged step (and the PVD collection).
    pub vtu: bool,
    /// Write every `every`-th converged step (the last converged step is always written).
    pub every: usize,
    /// Visualisation quads per integration cell and direction.
    pub subdivide: usize,
    /// Write the load–displacement plot of the monitors at the end.
    pub plot: bool,
}

impl Default for OutputSpec {
    fn default() -> Self {
        OutputSpec {
            vtu: true,
            every: 1,
            subdivide: 1,
            plot: true,
        }
    }
}

/// How a `[[load]]` entry depends on the load factor `λ` (`scaling` key).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum LoadScalingSpec {
    /// `λ · f` (default): the load grows with the load factor.
    #[default]
    Proportional,
    /// `f` at every load factor, from the first step on (e.g. the self-weight that keeps a
    /// sheet on a die while tools move with `λ`; docs/case-format.md, `[contact]`).
    Constant,
}

/// The contact penalty `ω` of `[contact]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PenaltySpec {
    /// `penalty_factor = c`: `ω = c E / t` (default `c` =
    /// [`crate::shell::contact::DEFAULT_PENALTY_FACTOR`]).
    Factor(f64),
    /// `penalty = ω` (force per length³).
    Value(f64),
}

impl PenaltySpec {
    /// `ω` for Young's modulus `young` and thickness `thickness`.
    pub fn omega(&self, young: f64, thickness: f64) -> f64 {
        match *self {
            PenaltySpec::Factor(c) => c * young / thickness,
            PenaltySpec::Value(w) => w,
        }
    }

    /// The `[contact]` key and value this penalty was given by, e.g. `penalty = 1e3`.
    pub fn as_key(&self) -> String {
        match *self {
            PenaltySpec::Factor(c) => format!("penalty_factor = {c:e}"),
            PenaltySpec::Value(w) => format!("penalty = {w:e}"),
        }
    }
}

/// `[contact]`: settings of the frictionless penalty contact with the `[[tool]]`s
/// (docs/contact.md).
#[derive(Clone, Debug, PartialEq)]
pub struct ContactSpec {
    /// Faces of the sheet that carry slave points.
    pub faces: ContactFaces,
    /// Penalty.
    pub penalty: PenaltySpec,
    /// A tool whose separation from the sheet is detected and reported (the punch on the way
    /// up), by name (checked to exist).
    pub release: Option<String>,
}

/// A checked shell case.
#[derive(Clone, Debug)]
pub struct ShellCase {
    /// The case file.
    pub path: PathBuf,
    /// Title for reports.
    pub title: String,
    /// The surface as written.
    pub surface_spec: SurfaceSpec,
    /// The validated surface.
    pub surface: Surface<f64>,
    /// Its parameter box.
    pub param_box: ParamBox,
    /// Shell thickness.
    pub thickness: f64,
    /// Particles.
    pub particles: ParticleLayout,
    /// RK kernel.
    pub kernel: KernelSpec,
    /// Quadrature.
    pub integration: IntegrationSpec,
    /// Material.
    pub material: MaterialParams<f64>,
    /// Essential conditions, in file order (`boundary[i]`).
    pub boundary: Vec<Boundary>,
    /// Loads, in file order (`load[i]`).
    pub loads: Vec<Load>,
    /// How each load depends on the load factor (same order as `loads`).
    pub load_scaling: Vec<LoadScalingSpec>,
    /// Rigid tools (`[[tool]]`), in file order; their motion is driven by the load factor.
    pub tools: Vec<RigidTool>,
    /// Contact settings: `Some` exactly when there are tools (defaults when `[contact]` is
    /// absent).
    pub contact: Option<ContactSpec>,
    /// Load stepping and Newton settings.
    pub steps: StepsSpec,
    /// Monitors, in file order.
    pub monitors: Vec<Monitor>,
    /// Per monitor (same order): the direction whose displacement component is also recorded
    /// (`[[monitor]] direction`), if any.
    pub monitor_directions: Vec<Option<MonitorDirection>>,
    /// Output settings.
    pub output: OutputSpec,
    /// `[[design]]` and `[dsa]` (`None` without `[[design]]` tables; [`super::dsa_case`]).
    pub dsa: Option<super::dsa_case::DsaSpec>,
    /// Resource limits (defaults raised by `[limits]`).
    pub limits: Limits,
    /// Warnings about a valid but doubtful case (geometry outside the shell regime, ...): the
    /// case runs; `check`, `run` and `dsa` print them.
    pub warnings: Vec<String>,
}

/// Resource limits a case is checked against before any work (`[limits]` raises them).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    /// Largest number of unknowns (5 per particle); `limits.max_unknowns`.
    pub max_unknowns: usize,
    /// Largest number of layer points (in-plane quadrature points × thickness points);
    /// `limits.max_layer_points`.
    pub max_layer_points: usize,
    /// Largest estimated memory in bytes; `limits.max_memory_gb` (default: 3/4 of the machine's
    /// memory, or [`Limits::DEFAULT_MEMORY_GB`] where that is unknown).
    pub max_memory_bytes: f64,
    /// Largest kernel support in particle spacings; `limits.max_support`.
    pub max_support: f64,
}

impl Limits {
    /// Default `max_unknowns`: 40,000 particles (a 200 × 200 grid).
    pub const DEFAULT_MAX_UNKNOWNS: usize = 200_000;
    /// Default `max_layer_points`.
    pub const DEFAULT_MAX_LAYER_POINTS: usize = 20_000_000;
    /// Default memory bound where the machine's memory cannot be read.
    pub const DEFAULT_MEMORY_GB: f64 = 8.0;
    /// Default `max_support`: supports wider than 10 spacings couple every particle with
    /// hundreds of others and are no longer a local approximation.
    pub const DEFAULT_MAX_SUPPORT: f64 = 10.0;

    /// The defaults of this machine.
    pub fn machine_default() -> Self {
        let memory = machine_memory_bytes()
            .map(|m| 0.75 * m)
            .unwrap_or(Self::DEFAULT_MEMORY_GB * 1e9);
        Limits {
            max_unknowns: Self::DEFAULT_MAX_UNKNOWNS,
            max_layer_points: Self::DEFAULT_MAX_LAYER_POINTS,
            max_memory_bytes: memory,
            max_support: Self::DEFAULT_MAX_SUPPORT,
        }
    }
}

/// Total memory of the machine (`MemTotal` of `/proc/meminfo`), where readable.
fn machine_memory_bytes() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024.0)
}

/// What a case will need, estimated before anything is built (printed by `check`, `run` and
/// `dsa`; checked against [`Limits`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResourceEstimate {
    /// Particles.
    pub particles: usize,
    /// Unknowns (5 per particle).
    pub unknowns: usize,
    /// In-plane quadrature points.
    pub quadrature_points: usize,
    /// Layer points (quadrature points × thickness points), each with a material history.
    pub layer_points: usize,
    /// Particles in a quadrature point's kernel supports (at most all).
    pub neighbours: usize,
    /// Stored entries of the tangent (particles coupled through overlapping supports).
    pub tangent_entries: f64,
    /// Memory estimate in bytes: shape functions, histories, tangent and its factorisation.
    pub memory_bytes: f64,
    /// Fewest load steps that reach `final_load` (`final_load / max_step`, plus the stops).
    pub min_steps: f64,
    /// The step-attempt cap (`steps.max_attempts`).
    pub max_attempts: usize,
}

impl std::fmt::Display for ResourceEstimate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "estimate: {} particles, {} unknowns, {} quadrature points × layers = {} layer \
             points, {} particles per support, ~{:.3e} tangent entries, memory ~{}; at least \
             {} load step(s) of at most {} attempts",
            self.particles,
            self.unknowns,
            self.quadrature_points,
            self.layer_points,
            self.neighbours,
            self.tangent_entries,
            fmt_bytes(self.memory_bytes),
            self.min_steps,
            self.max_attempts
        )
    }
}

/// Bytes with a binary prefix.
pub fn fmt_bytes(b: f64) -> String {
    const UNITS: [&str; 6] = ["B", "KiB", "MiB", "GiB", "TiB", "PiB"];
    let mut v = b;
    let mut k = 0;
    while v >= 1024.0 && k + 1 < UNITS.len() {
        v /= 1024.0;
        k += 1;
    }
    if v >= 1024.0 {
        format!("{b:.2e} B")
    } else {
        format!("{v:.1} {}", UNITS[k])
    }
}

/// Memory of a run before the model: program, thread pools, output buffers (the measured peak
/// of the smallest shipped case less its model).
const BASE_MEMORY: f64 = 64.0 * 1024.0 * 1024.0;

/// Estimate a case's resources from the checked settings (all arithmetic in `f64`, so that no
/// setting can overflow it). Memory: per quadrature point and particle of its supports the
/// shape data and indices (64 bytes); per layer point three histories (committed, trial and a
/// sensitivity, 480 bytes); the tangent's entries (16 bytes with their index) twice (matrix
/// and values in the assembly), and its LU: dense (`8 n²`) where the solver picks the dense
/// LU ([`crate::solver::linear::Method`]), else 8 times the tangent (fill-in of the sparse LU
/// of a two-dimensional coupling pattern), plus [`BASE_MEMORY`]. Against the measured peak
/// resident memory of `run` on the linear hemisphere at 17², 33² and 49² particles (119, 647 and
/// 1765 MiB): 121, 782 and 1600 MiB, within 21 %.
fn estimate(
    particles: &ParticleLayout,
    kernel: &KernelSpec,
    integration: &IntegrationSpec,
    steps: &StepsSpec,
) -> ResourceEstimate {
    let (nu, nv) = (particles.counts[0] as f64, particles.counts[1] as f64);
    let n = nu * nv;
    let cells = match integration.cells {
        CellLayout::PerParticleSpacing { subdivide } => {
            (nu - 1.0) * (nv - 1.0) * (subdivide as f64).powi(2)
        }
        CellLayout::Counts(c) => c[0] as f64 * c[1] as f64,
    };
    let q = cells * (integration.gauss as f64).powi(2);
    let layers = match integration.thickness_rule {
        ThicknessRule::Gauss(k) | ThicknessRule::Lobatto(k) => k as f64,
    };
    let s = kernel.support;
    let support_width = |m: f64| (2.0 * s + 1.0).min(m);
    let coupled_width = |m: f64| (4.0 * s + 1.0).min(m);
    let neighbours = support_width(nu) * support_width(nv);
    let coupled = coupled_width(nu) * coupled_width(nv);
    let unknowns = 5.0 * n;
    let entries = unknowns * 5.0 * coupled;
    let dense = unknowns <= crate::solver::linear::Method::DENSE_MAX_N as f64
        && entries >= crate::solver::linear::Method::DENSE_FILL * unknowns * unknowns;
    let lu = if dense {
        8.0 * unknowns * unknowns
    } else {
        8.0 * 16.0 * entries
    };
    let memory =
        BASE_MEMORY + q * neighbours * 64.0 + q * layers * 480.0 + 2.0 * 16.0 * entries + lu;
    let to_usize = |x: f64| {
        if x >= usize::MAX as f64 {
            usize::MAX
        } else {
            x as usize
        }
    };
    let min_steps = (steps.final_load / steps.max_step).ceil() + steps.stops.len() as f64;
    ResourceEstimate {
        particles: to_usize(n),
        unknowns: to_usize(unknowns),
        quadrature_points: to_usize(q),
        layer_points: to_usize(q * layers),
        neighbours: to_usize(neighbours),
        tangent_entries: entries,
        memory_bytes: memory,
        min_steps,
        max_attempts: steps.max_attempts,
    }
}

impl ShellCase {
    /// The resources this case needs (estimated from the settings, nothing built).
    pub fn estimate(&self) -> ResourceEstimate {
        estimate(
            &self.particles,
            &self.kernel,
            &self.integration,
            &self.steps,
        )
    }
}

/// Edge names as written in case files.
pub const EDGE_NAMES: [&str; 4] = ["u-min", "u-max", "v-min", "v-max"];

/// The case-file name of an edge.
pub fn edge_name(e: Edge) -> &'static str {
    match e {
        Edge::UMin => EDGE_NAMES[0],
        Edge::UMax => EDGE_NAMES[1],
        Edge::VMin => EDGE_NAMES[2],
        Edge::VMax => EDGE_NAMES[3],
    }
}

/// Parse and validate the text of a `kind = "shell"` case file (`path` names it in messages).
pub fn parse_shell_case(text: &str, path: &Path) -> Result<ShellCase, CaseError> {
    let f: ShellFile = toml::from_str(text).map_err(|e| CaseError::Parse {
        path: path.into(),
        message: e.to_string(),
    })?;
    Checker { path }.case(f)
}

/// Read and validate a shell case file.
pub fn read_shell_case(path: &Path) -> Result<ShellCase, CaseError> {
    let text = std::fs::read_to_string(path).map_err(|source| CaseError::Read {
        path: path.into(),
        source,
    })?;
    parse_shell_case(&text, path)
}

struct Checker<'a> {
    path: &'a Path,
}

/// The cubic B-spline named at a support of `4 − RESONANT_SUPPORT_BAND` spacings or more,
/// where its transform's first zero (`ω a = 4π`) lies in the band the particles resolve
/// ([`KernelFunction::default_for`]) and away from the multiples of 4 ([`resonance_warning`]):
/// coefficient patterns of wavelength near `a/2` pass almost nothing. Measured (clamped plate,
/// 31 × 31 particles, quadratic basis, 2 × 2 Gauss points): the cubic B-spline's tangent is
/// singular at supports 4, 4.5 and 5 (probe forward errors 19.6, 2.4e-2, 1.7e-2), the quartic
/// spline's solves at all three (w +0.68 %, +0.57 %, +0.61 % against the reference).
fn wide_cubic_warning(kernel: &KernelSpec) -> Option<String> {
    let wide = kernel.function == KernelFunction::CubicSpline
        && kernel.support >= 4.0 - crate::meshfree::kernel::RESONANT_SUPPORT_BAND
        && !kernel.function.blind_at(kernel.support);
    wide.then(|| {
        format!(
            "`kernel.support` = {} spacings with `kernel.function` = \"cubic-spline\": from \
             about 4 spacings on the cubic B-spline passes almost nothing of coefficient \
             patterns of wavelength near half the support, and the tangent can be singular \
             (docs/stability.md §6); the quartic spline (`kernel.function` = \
             \"quartic-spline\", the default at this support) avoids it",
            kernel.support
        )
    })
}

/// The cubic B-spline chosen at a support within [`crate::meshfree::kernel::RESONANT_SUPPORT_BAND`]
/// spacings of a multiple of 4 (where the default is the quartic spline): the cubic B-spline
/// kernel of half-width `a` has knots `a/2` apart, so its Fourier transform (`sinc⁴`) vanishes
/// at the two-spacing wavelength when `a` is a multiple of 4 spacings. A coefficient field
/// alternating from particle to particle then passes (almost) nothing to the RK approximation:
/// measured with [`crate::shell::model::ShellModel::coefficient_transfer`] on the hemisphere
/// (33 × 33, quadratic basis), the h·gradient transfer is 0.39 at support 3, 0.0081 at 3.8,
/// 0.0019 at 3.9, 0 at 4, 0.0014 at 4.1, 0.0041 at 4.2, 0.012 at 4.5, 0 at 8. Only edges resist
/// such a field, and symmetry planes on opposite edges mirror it into a complete alternating sum:
/// [`crate::shell::gauge`] finds such coefficient modes and the problem fixes them by rows
/// (docs/stability.md §6).
fn resonance_warning(kernel: &KernelSpec) -> Option<String> {
    let k = (kernel.support / 4.0).round();
    kernel.function.blind_at(kernel.support).then(|| {
        format!(
            "`kernel.support` = {} spacings is within {} of {} with `kernel.function` = \
             \"cubic-spline\": there the cubic B-spline kernel passes (almost) no field that \
             alternates from particle to particle, a mode only edges resist; between symmetry \
             planes on opposite edges the run fixes such coefficient modes by constraint rows, \
             and any it does not find leave the tangent singular (docs/stability.md); the \
             quartic spline (`kernel.function` = \"quartic-spline\", the default at this \
             support) or a support away from multiples of 4 spacings, e.g. 3.5 or 4.5, avoids \
             both",
            kernel.support,
            crate::meshfree::kernel::RESONANT_SUPPORT_BAND,
            4.0 * k
        )
    })
}

/// Smallest radius of curvature over thickness from which the case check warns of membrane
/// locking on jittered particles with a basis below cubic (`ShellCase::warnings`): a thin curved
/// shell, whose inextensional bending the discrete membrane constraints hold back.
pub const JITTER_LOCKING_RADIUS_OVER_T: f64 = 50.0;

/// Warnings about geometry outside the regime of the shell model: a thickness not small
/// against the smallest radius of curvature (sampled on a 9 × 9 grid of the parameter box) or
/// the surface's size, particle spacings of very different lengths along `u` and `v`, or
/// jittered particles on a thin curved shell with a basis that locks there.
fn geometry_warnings(
    thickness: f64,
    surface: &Surface<f64>,
    pb: &ParamBox,
    particles: &ParticleLayout,
    basis: Basis,
) -> Vec<String> {
    let mut out = Vec::new();
    let mut kappa_max: f64 = 0.0;
    let mut at = [0.0; 2];
    let (mut len_u, mut len_v) = (0.0, 0.0);
    for i in 0..=8 {
        for j in 0..=8 {
            let u = pb.lo[0] + (pb.hi[0] - pb.lo[0]) * i as f64 / 8.0;
            let v = pb.lo[1] + (pb.hi[1] - pb.lo[1]) * j as f64 / 8.0;
            let d = surface.eval(u, v);
            if let (Ok(h), Ok(k)) = (d.mean_curvature(), d.gaussian_curvature()) {
                let kappa = h.abs() + (h * h - k).max(0.0).sqrt();
                if kappa.is_finite() && kappa > kappa_max {
                    kappa_max = kappa;
                    at = [u, v];
                }
            }
            // Mean lengths of the u and v parameter lines (trapezoid-free sampling mean).
            len_u += d.xu.norm() * (pb.hi[0] - pb.lo[0]) / 81.0;
            len_v += d.xv.norm() * (pb.hi[1] - pb.lo[1]) / 81.0;
        }
    }
    if kappa_max > 0.0 && thickness * kappa_max >= 1.0 {
        out.push(format!(
            "`thickness` = {thickness} is not smaller than the smallest radius of curvature \
             {:.4e} (at (u, v) = ({}, {})): the shell model assumes t much smaller than it",
            1.0 / kappa_max,
            at[0],
            at[1]
        ));
    }
    // Membrane locking of jittered sets (verification/hemisphere-linear/README.md: the linear
    // hemisphere, R/t = 250, 2 × 2 Gauss points per cell, jitter 0.2 on 17 × 17: quadratic
    // −29 %, cubic with supports of 3.5 spacings −1.7 %).
    let radius_over_t = 1.0 / (kappa_max * thickness);
    // The linear basis on a thin curved shell locks on any particle set: it cannot bend the
    // surface without stretching it (the linear hemisphere, R/t = 250, supports of 2
    // spacings: δ_A/P −66 % on 17 × 17 particles, −19 % on 33 × 33).
    if basis == Basis::Linear && kappa_max > 0.0 && radius_over_t >= JITTER_LOCKING_RADIUS_OVER_T {
        out.push(format!(
            "`kernel.basis` = \"linear\" on a curved shell of radius over thickness \
             {radius_over_t:.0}: the linear basis locks in membrane on thin curved shells (the \
             linear hemisphere at R/t = 250 is 66 % too stiff on 17 × 17 particles, 19 % on \
             33 × 33; verification/hemisphere-linear/README.md); use `kernel.basis` = \
             \"quadratic\" (supports of 3 spacings)"
        ));
    }
    if particles.jitter > 0.0
        && basis != Basis::Cubic
        && kappa_max > 0.0
        && radius_over_t >= JITTER_LOCKING_RADIUS_OVER_T
    {
        out.push(format!(
            "`particles.jitter` = {} with `kernel.basis` = \"{basis}\" on a curved shell of \
             radius over thickness {radius_over_t:.0}: on jittered particles this basis locks \
             in membrane under the cell quadrature (the linear hemisphere at R/t = 250 is 29 % \
             too stiff on 17 × 17 particles jittered by 0.2, 7.5 % on 25 × 25, 2.7 % on 33 × 33; \
             verification/hemisphere-linear/README.md); `kernel.basis` = \"cubic\" with \
             `kernel.support` = 3.5 is within 1.7 % there",
            particles.jitter
        ));
    }
    let size = len_u.max(len_v);
    if size.is_finite() && size > 0.0 {
        let ratio = size / thickness;
        if ratio < 4.0 {
            out.push(format!(
                "`thickness` = {thickness} is more than a quarter of the surface's size \
                 {size:.4e}: a solid, not a shell"
            ));
        } else if ratio > 1e5 {
            out.push(format!(
                "`thickness` = {thickness} is below 1e-5 of the surface's size {size:.4e}: the \
                 stiffness matrix is ill-conditioned (bending against membrane stiffness as \
                 (t/L)² = {:.1e})",
                (thickness / size).powi(2)
            ));
        }
    }
    let hu = len_u / (particles.counts[0] as f64 - 1.0);
    let hv = len_v / (particles.counts[1] as f64 - 1.0);
    let aspect = hu.max(hv) / hu.min(hv);
    if aspect.is_finite() && aspect > 20.0 {
        out.push(format!(
            "particle spacings of {hu:.3e} along u and {hv:.3e} along v (ratio {aspect:.1}): \
             `particles.grid` with spacings within a factor 20 of each other keeps the \
             rectangular kernel supports balanced"
        ));
    }
    out
}

fn fmt_arr(a: &[f64]) -> String {
    let parts: Vec<String> = a.iter().map(|v| format!("{v}")).collect();
    format!("[{}]", parts.join(", "))
}

impl Checker<'_> {
    /// The value of a keyword key: `default` when absent, else the option named `value`; an
    /// error naming the key, the value and the options otherwise.
    fn keyword<T: Copy>(
        &self,
        key: &str,
        value: Option<&str>,
        default: T,
        options: &[(&str, T)],
    ) -> Result<T, CaseError> {
        let Some(v) = value else {
            return Ok(default);
        };
        if let Some(&(_, t)) = options.iter().find(|(name, _)| *name == v) {
            return Ok(t);
        }
        let names: Vec<String> = options.iter().map(|(n, _)| format!("{n:?}")).collect();
        let expected = match names.split_last() {
            Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
            _ => names.join(""),
        };
        Err(self.err(key, format!("{v:?}"), expected))
    }

    fn err(
        &self,
        key: impl Into<String>,
        value: impl Into<String>,
        expected: impl Into<String>,
    ) -> CaseError {
        CaseError::Invalid {
            path: self.path.into(),
            key: key.into(),
            value: value.into(),
            expected: expected.into(),
        }
    }

    fn positive(&self, key: &str, v: f64) -> Result<f64, CaseError> {
        if v > 0.0 && v.is_finite() {
            Ok(v)
        } else {
            Err(self.err(key, fmt_num(v), "a finite number > 0"))
        }
    }

    /// A relative tolerance: finite, in `(0, 1)`.
    fn fraction(&self, key: &str, v: f64) -> Result<f64, CaseError> {
        if v > 0.0 && v < 1.0 {
            Ok(v)
        } else {
            Err(self.err(key, fmt_num(v), "a relative tolerance in (0, 1)"))
        }
    }

    fn finite_vec(&self, key: &str, v: &[f64]) -> Result<(), CaseError> {
        if v.iter().all(|x| x.is_finite()) {
            Ok(())
        } else {
            Err(self.err(key, fmt_arr(v), "finite numbers"))
        }
    }

    fn count(&self, key: &str, v: i64, min: i64, max: Option<i64>) -> Result<usize, CaseError> {
        let ok = v >= min && max.is_none_or(|m| v <= m);
        if ok {
            Ok(v as usize)
        } else {
            let expected = match max {
                Some(m) => format!("an integer in {min}..={m}"),
                None => format!("an integer >= {min}"),
            };
            Err(self.err(key, v.to_string(), expected))
        }
    }

    fn edge(&self, key: &str, s: &str) -> Result<Edge, CaseError> {
        match EDGE_NAMES.iter().position(|n| *n == s) {
            Some(k) => Ok([Edge::UMin, Edge::UMax, Edge::VMin, Edge::VMax][k]),
            None => Err(self.err(key, format!("{s:?}"), format!("one of {EDGE_NAMES:?}"))),
        }
    }

    fn param_point(&self, key: &str, at: [f64; 2], b: &ParamBox) -> Result<[f64; 2], CaseError> {
        if b.contains(at) {
            Ok(at)
        } else {
            Err(self.err(
                key,
                fmt_arr(&at),
                format!(
                    "a parameter point (u, v) in the surface's domain [{}, {}] × [{}, {}]",
                    b.lo[0], b.hi[0], b.lo[1], b.hi[1]
                ),
            ))
        }
    }

    fn case(&self, f: ShellFile) -> Result<ShellCase, CaseError> {
        let thickness = match f.thickness {
            Some(t) => self.positive("thickness", t)?,
            None => {
                return Err(self.err(
                    "thickness",
                    "(missing)",
                    "a top-level `thickness = <value > 0>` before the first [table]",
                ))
            }
        };
        let limits = self.limits(f.limits.as_ref())?;
        self.check_degrees("surface", &f.surface)?;
        let surface = f.surface.build().map_err(|source| CaseError::Surface {
            path: self.path.into(),
            source,
        })?;
        let d = surface.domain();
        let param_box = ParamBox::new(d[0], d[1]);

        // [particles]
        let p = &f.particles;
        let counts = [
            self.count("particles.grid[0]", p.grid[0], 2, None)?,
            self.count("particles.grid[1]", p.grid[1], 2, None)?,
        ];
        if !(0.0..0.5).contains(&p.jitter) {
            return Err(self.err(
                "particles.jitter",
                p.jitter.to_string(),
                "a fraction of the particle spacing in [0, 0.5)",
            ));
        }
        let particles = ParticleLayout {
            counts,
            jitter: p.jitter,
            seed: p.seed,
        };

        // [kernel]
        let basis = match f.kernel.basis.as_str() {
            "linear" => Basis::Linear,
            "quadratic" => Basis::Quadratic,
            "cubic" => Basis::Cubic,
            other => {
                return Err(self.err(
                    "kernel.basis",
                    format!("{other:?}"),
                    "\"linear\", \"quadratic\" or \"cubic\"",
                ))
            }
        };
        let support = self.positive("kernel.support", f.kernel.support)?;
        if support > limits.max_support {
            return Err(self.err(
                "kernel.support",
                support.to_string(),
                format!(
                    "a support of at most limits.max_support = {} particle spacings (raise \
                     `max_support` in a [limits] table to use a wider one)",
                    limits.max_support
                ),
            ));
        }
        let function = self.keyword(
            "kernel.function",
            f.kernel.function.as_deref(),
            KernelFunction::default_for(support),
            &[
                ("cubic-spline", KernelFunction::CubicSpline),
                ("quartic-spline", KernelFunction::QuarticSpline),
            ],
        )?;
        let kernel = KernelSpec {
            basis,
            support,
            function,
        };

        // [integration]
        let i = &f.integration;
        let counts = match &i.cells {
            toml::Value::Array(a) => match a.as_slice() {
                [toml::Value::Integer(u), toml::Value::Integer(v)] => Some([*u, *v]),
                _ => None,
            },
            _ => None,
        };
        let cells = match (&i.cells, counts) {
            (toml::Value::String(s), _) if s == "per-particle-spacing" => {
                CellLayout::PerParticleSpacing {
                    subdivide: self.count(
                        "integration.subdivide",
                        i.subdivide.unwrap_or(1),
                        1,
                        None,
                    )?,
                }
            }
            (_, Some(c)) => {
                let counts = [
                    self.count("integration.cells[0]", c[0], 1, None)?,
                    self.count("integration.cells[1]", c[1], 1, None)?,
                ];
                if let Some(s) = i.subdivide {
                    return Err(self.err(
                        "integration.subdivide",
                        s.to_string(),
                        "no `subdivide` with explicit cell counts (it applies to \
                         cells = \"per-particle-spacing\")",
                    ));
                }
                CellLayout::Counts(counts)
            }
            (other, None) => {
                return Err(self.err(
                    "integration.cells",
                    other.to_string(),
                    "\"per-particle-spacing\" or [n_u, n_v] (two integers)",
                ))
            }
        };
        let gauss = self.count(
            "integration.gauss",
            i.gauss,
            1,
            Some(MAX_GAUSS_POINTS as i64),
        )?;
        let thickness_rule = match i.thickness_rule.as_str() {
            // One point at the mid-surface integrates no bending stiffness (the strain's
            // linear part in ζ vanishes there): at least two.
            "gauss" if i.thickness_points == 1 => {
                return Err(self.err(
                    "integration.thickness_points",
                    "1".to_string(),
                    format!(
                        "an integer in 2..={MAX_GAUSS_POINTS} (one point through the thickness \
                         sits on the mid-surface and integrates no bending stiffness)"
                    ),
                ))
            }
            "gauss" => ThicknessRule::Gauss(self.count(
                "integration.thickness_points",
                i.thickness_points,
                2,
                Some(MAX_GAUSS_POINTS as i64),
            )?),
            "lobatto" => ThicknessRule::Lobatto(self.count(
                "integration.thickness_points",
                i.thickness_points,
                2,
                Some(MAX_LOBATTO_POINTS as i64),
            )?),
            other => {
                return Err(self.err(
                    "integration.thickness_rule",
                    format!("{other:?}"),
                    "\"gauss\" or \"lobatto\"",
                ))
            }
        };
        let vci = match i.vci.as_deref().unwrap_or("second") {
            "off" => VciOrder::Off,
            "first" => VciOrder::First,
            "second" => VciOrder::Second,
            other => {
                return Err(self.err(
                    "integration.vci",
                    format!("{other:?}"),
                    "\"off\", \"first\" or \"second\" (default \"second\")",
                ))
            }
        };
        let director_stabilisation = match i.director_stabilisation {
            None => 0.0,
            Some(x) if x.is_finite() && x >= 0.0 => x,
            Some(x) => {
                return Err(self.err(
                    "integration.director_stabilisation",
                    format!("{x}"),
                    "a finite number >= 0 (0: off)",
                ))
            }
        };
        let director_stabilisation_strength = match i.director_stabilisation_strength.as_deref() {
            None | Some("bending") => FilterStrength::Bending,
            Some("director-force") => FilterStrength::DirectorForce,
            Some(other) => {
                return Err(self.err(
                    "integration.director_stabilisation_strength",
                    format!("{other:?}"),
                    "\"bending\" or \"director-force\" (default \"bending\")",
                ))
            }
        };
        let director_stabilisation_floor = match i.director_stabilisation_floor {
            None => 0.0,
            Some(x)
                if x.is_finite()
                    && x >= 0.0
                    && director_stabilisation_strength == FilterStrength::DirectorForce =>
            {
                x
            }
            Some(x) => {
                return Err(self.err(
                    "integration.director_stabilisation_floor",
                    format!("{x}"),
                    "a finite number >= 0, with director_stabilisation_strength = \
                     \"director-force\" (the floor of the per-particle strength)",
                ))
            }
        };
        let director_stabilisation_support = match i.director_stabilisation_support {
            None => kernel.support,
            Some(x) if x.is_finite() && (MIN_FILTER_SUPPORT..=kernel.support).contains(&x) => x,
            Some(x) => {
                return Err(self.err(
                    "integration.director_stabilisation_support",
                    format!("{x}"),
                    format!(
                        "a support half-width in particle spacings from {MIN_FILTER_SUPPORT} to \
                         kernel.support = {} (default kernel.support)",
                        kernel.support
                    ),
                ))
            }
        };
        let director = match i.director.as_deref() {
            Some("interpolated") => crate::shell::point::DirectorField::Interpolated,
            None | Some("normalised") => crate::shell::point::DirectorField::Normalised,
            Some(other) => {
                return Err(self.err(
                    "integration.director",
                    format!("{other:?}"),
                    "\"interpolated\" or \"normalised\" (default \"normalised\")",
                ))
            }
        };
        let integration = IntegrationSpec {
            cells,
            gauss,
            thickness_rule,
            vci,
            director_stabilisation,
            director_stabilisation_strength,
            director_stabilisation_floor,
            director_stabilisation_support,
            director,
        };

        let material = material_from_spec(&f.material, self.path)?;

        let boundary = f
            .boundary
            .iter()
            .enumerate()
            .map(|(k, b)| self.boundary(k, b, &surface, &param_box))
            .collect::<Result<Vec<_>, _>>()?;
        let loads = f
            .load
            .iter()
            .enumerate()
            .map(|(k, l)| self.load(k, l, &param_box))
            .collect::<Result<Vec<_>, _>>()?;
        let load_scaling = f
            .load
            .iter()
            .enumerate()
            .map(|(k, l)| match l.scaling.as_deref() {
                None | Some("proportional") => Ok(LoadScalingSpec::Proportional),
                Some("constant") => Ok(LoadScalingSpec::Constant),
                Some(other) => Err(self.err(
                    format!("load[{k}].scaling"),
                    format!("{other:?}"),
                    "\"proportional\" (default) or \"constant\"",
                )),
            })
            .collect::<Result<Vec<_>, _>>()?;
        self.check_everywhere(&boundary)?;
        let steps = self.steps(&f.steps)?;
        self.check_resources(
            &estimate(&particles, &kernel, &integration, &steps),
            &limits,
            &particles,
            &integration,
            &steps,
        )?;
        let tools = f
            .tool
            .iter()
            .enumerate()
            .map(|(k, t)| self.tool(k, t, &f.tool[..k]))
            .collect::<Result<Vec<_>, _>>()?;
        let contact = self.contact(f.contact.as_ref(), &tools)?;
        if steps.arc_length.is_some() && !tools.is_empty() {
            return Err(self.err(
                "steps.control",
                "\"arc-length\"",
                "\"load\" with [[tool]] entries (the tools move with the load factor, which \
                 arc-length continuation makes an unknown)",
            ));
        }

        let mut monitors: Vec<Monitor> = Vec::with_capacity(f.monitor.len());
        let mut monitor_directions = Vec::with_capacity(f.monitor.len());
        for (k, m) in f.monitor.iter().enumerate() {
            let dk = format!("monitor[{k}].direction");
            monitor_directions.push(match &m.direction {
                None => None,
                Some(DirectionFile::Word(w)) if w == "normal" => Some(MonitorDirection::Normal),
                Some(DirectionFile::Word(w)) => {
                    return Err(self.err(dk, format!("{w:?}"), "\"normal\" or a vector [x, y, z]"))
                }
                Some(DirectionFile::Vector(v)) => {
                    self.finite_vec(&dk, v)?;
                    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                    if !(n > 0.0 && n.is_finite()) {
                        return Err(self.err(dk, fmt_arr(v), "a non-zero vector [x, y, z]"));
                    }
                    Some(MonitorDirection::Fixed([v[0] / n, v[1] / n, v[2] / n]))
                }
            });
            let key = format!("monitor[{k}]");
            if !super::is_name(&m.name) {
                return Err(self.err(
                    format!("{key}.name"),
                    format!("{:?}", m.name),
                    super::NAME_EXPECTED,
                ));
            }
            if monitors.iter().any(|o| o.name == m.name) {
                return Err(self.err(
                    format!("{key}.name"),
                    format!("{:?}", m.name),
                    "a name not used by an earlier monitor",
                ));
            }
            monitors.push(Monitor {
                name: m.name.clone(),
                at: self.param_point(&format!("{key}.at"), m.at, &param_box)?,
            });
        }

        let output = match &f.output {
            None => OutputSpec::default(),
            Some(o) => OutputSpec {
                vtu: o.vtu,
                every: self.count("output.every", o.every, 1, None)?,
                subdivide: self.count("output.subdivide", o.subdivide, 1, Some(16))?,
                plot: o.plot,
            },
        };

        if let Some(t) = f.problem.title.as_ref().filter(|t| !super::is_name(t)) {
            return Err(self.err("problem.title", format!("{t:?}"), super::NAME_EXPECTED));
        }
        let dsa = super::dsa_case::check(
            self.path,
            f.design,
            f.dsa,
            thickness,
            &material,
            &monitors,
            &super::dsa_case::CaseGeometry {
                surface: &surface,
                tools: &tools,
            },
        )?;
        if let Some(spec) = &dsa {
            super::dsa_case::check_tool_names(self.path, &tools, spec)?;
        }

        let mut warnings =
            geometry_warnings(thickness, &surface, &param_box, &particles, kernel.basis);
        warnings.extend(wide_cubic_warning(&kernel));
        warnings.extend(resonance_warning(&kernel));
        if boundary.is_empty() {
            warnings.push(
                "no `[[boundary]]` entry: nothing holds the shell against rigid-body motion, \
                 so its tangent is singular (the run stops at its first factorisation) unless \
                 tools or loads stiffen every such motion; fix or support at least one edge or \
                 point"
                    .into(),
            );
        }
        Ok(ShellCase {
            limits,
            warnings,
            dsa,
            path: self.path.into(),
            title: f.problem.title.clone().unwrap_or_else(|| "shell".into()),
            surface_spec: f.surface,
            surface,
            param_box,
            thickness,
            particles,
            kernel,
            integration,
            material,
            boundary,
            loads,
            load_scaling,
            tools,
            contact,
            steps,
            monitors,
            monitor_directions,
            output,
        })
    }

    /// `[limits]`: each given limit a positive finite number.
    fn limits(&self, l: Option<&LimitsFile>) -> Result<Limits, CaseError> {
        let mut out = Limits::machine_default();
        let Some(l) = l else { return Ok(out) };
        if let Some(v) = l.max_unknowns {
            out.max_unknowns = self.count("limits.max_unknowns", v, 1, None)?;
        }
        if let Some(v) = l.max_layer_points {
            out.max_layer_points = self.count("limits.max_layer_points", v, 1, None)?;
        }
        if let Some(v) = l.max_memory_gb {
            out.max_memory_bytes = self.positive("limits.max_memory_gb", v)? * 1e9;
        }
        if let Some(v) = l.max_support {
            out.max_support = self.positive("limits.max_support", v)?;
        }
        Ok(out)
    }

    /// Refuse a case beyond a limit, naming the key that sets the size, the estimate and the
    /// `[limits]` key that raises the limit.
    fn check_resources(
        &self,
        e: &ResourceEstimate,
        limits: &Limits,
        particles: &ParticleLayout,
        integration: &IntegrationSpec,
        steps: &StepsSpec,
    ) -> Result<(), CaseError> {
        let grid = format!("[{}, {}]", particles.counts[0], particles.counts[1]);
        if e.unknowns > limits.max_unknowns {
            return Err(self.err(
                "particles.grid",
                grid,
                format!(
                    "at most limits.max_unknowns = {} unknowns (5 per particle; this grid has \
                     {}): use fewer particles, or raise `max_unknowns` in a [limits] table",
                    limits.max_unknowns, e.unknowns
                ),
            ));
        }
        if e.layer_points > limits.max_layer_points {
            let (key, value) = match integration.cells {
                CellLayout::PerParticleSpacing { subdivide } if subdivide > 1 => {
                    ("integration.subdivide", subdivide.to_string())
                }
                CellLayout::Counts(c) => ("integration.cells", format!("[{}, {}]", c[0], c[1])),
                _ => ("particles.grid", grid.clone()),
            };
            return Err(self.err(
                key,
                value,
                format!(
                    "at most limits.max_layer_points = {} layer points (this case has {} \
                     quadrature points × {} thickness points = {}): use fewer cells or points, \
                     or raise `max_layer_points` in a [limits] table",
                    limits.max_layer_points,
                    e.quadrature_points,
                    e.layer_points / e.quadrature_points.max(1),
                    e.layer_points
                ),
            ));
        }
        if e.memory_bytes > limits.max_memory_bytes {
            return Err(self.err(
                "particles.grid",
                grid,
                format!(
                    "a case within the memory limit {} (limits.max_memory_gb; default 3/4 of \
                     this machine's memory): this one needs ~{} ({}); use fewer particles, \
                     cells or a smaller kernel.support, or raise `max_memory_gb` in a [limits] \
                     table",
                    fmt_bytes(limits.max_memory_bytes),
                    fmt_bytes(e.memory_bytes),
                    e
                ),
            ));
        }
        if e.min_steps > e.max_attempts as f64 {
            return Err(self.err(
                "steps.max_step",
                fmt_num(steps.max_step),
                format!(
                    "a step that reaches steps.final_load = {} within steps.max_attempts = {} \
                     step attempts (final_load / max_step + {} stops = {} steps): raise \
                     `max_step` or `steps.max_attempts`, or lower `final_load`",
                    fmt_num(steps.final_load),
                    e.max_attempts,
                    steps.stops.len(),
                    fmt_num(e.min_steps)
                ),
            ));
        }
        Ok(())
    }

    /// One `[[tool]]`: name (non-empty, unique), side, surface and path, validated as a
    /// [`RigidTool`] (a normal at every sample of its coarse grid).
    fn tool(&self, k: usize, t: &ToolFile, earlier: &[ToolFile]) -> Result<RigidTool, CaseError> {
        let key = format!("tool[{k}]");
        if !super::is_name(&t.name) {
            return Err(self.err(
                format!("{key}.name"),
                format!("{:?}", t.name),
                super::NAME_EXPECTED,
            ));
        }
        if let Some(j) = earlier.iter().position(|o| o.name == t.name) {
            return Err(self.err(
                format!("{key}.name"),
                format!("{:?}", t.name),
                format!("a name not used by an earlier tool (tool[{j}])"),
            ));
        }
        let side = match t.side.as_str() {
            "positive" => Side::Positive,
            "negative" => Side::Negative,
            other => {
                return Err(self.err(
                    format!("{key}.side"),
                    format!("{other:?}"),
                    "\"positive\" (the solid lies behind the surface normal x_u × x_v, \
                     which is then the tool's outward normal) or \"negative\"",
                ))
            }
        };
        self.check_degrees(&format!("{key}.surface"), &t.surface)?;
        let surface = t.surface.build().map_err(|e| {
            self.err(
                format!("{key}.surface"),
                "(table)",
                format!("a valid surface: {e}"),
            )
        })?;
        let path = self.tool_path(&key, &t.path)?;
        let kind = surface.kind();
        RigidTool::new(t.name.clone(), surface, side, path).map_err(|e| {
            self.err(
                format!("{key}.surface"),
                format!("(type = {kind:?})"),
                format!(
                    "a regular surface with a normal everywhere (a sphere zone may not reach \
                     a pole): {e}"
                ),
            )
        })
    }

    /// `[tool.path]`: `stroke = [dx, dy, dz]` (0 at t = 0 to the stroke at t = 1), or `keys`
    /// (strictly increasing `t`, finite translations and rotations) with an optional `pivot`.
    fn tool_path(&self, key: &str, p: &ToolPathFile) -> Result<ToolPath, CaseError> {
        let pk = format!("{key}.path");
        match (&p.stroke, &p.keys) {
            (Some(stroke), None) => {
                if let Some(pv) = p.pivot {
                    return Err(self.err(
                        format!("{pk}.pivot"),
                        fmt_arr(&pv),
                        "no `pivot` with `stroke` (a pure translation; use `keys` with \
                         `rotation` to rotate about a pivot)",
                    ));
                }
                self.finite_vec(&format!("{pk}.stroke"), stroke)?;
                ToolPath::linear_stroke(*stroke)
                    .map_err(|e| self.err(format!("{pk}.stroke"), fmt_arr(stroke), e.to_string()))
            }
            (None, Some(keys)) => {
                let pivot = p.pivot.unwrap_or([0.0; 3]);
                self.finite_vec(&format!("{pk}.pivot"), &pivot)?;
                if keys.is_empty() {
                    return Err(self.err(
                        format!("{pk}.keys"),
                        "[]",
                        "at least one key {t, translation, rotation?}",
                    ));
                }
                let mut out = Vec::with_capacity(keys.len());
                for (i, kf) in keys.iter().enumerate() {
                    let kk = format!("{pk}.keys[{i}]");
                    if !kf.t.is_finite() {
                        return Err(self.err(format!("{kk}.t"), kf.t.to_string(), "a finite time"));
                    }
                    if i > 0 && kf.t <= keys[i - 1].t {
                        return Err(self.err(
                            format!("{kk}.t"),
                            kf.t.to_string(),
                            format!(
                                "a time greater than {pk}.keys[{}].t = {} (strictly increasing)",
                                i - 1,
                                keys[i - 1].t
                            ),
                        ));
                    }
                    self.finite_vec(&format!("{kk}.translation"), &kf.translation)?;
                    let rotation = kf.rotation.unwrap_or([0.0; 3]);
                    self.finite_vec(&format!("{kk}.rotation"), &rotation)?;
                    out.push(PathKey {
                        t: kf.t,
                        translation: kf.translation,
                        rotation,
                    });
                }
                ToolPath::new(pivot, out)
                    .map_err(|e| self.err(format!("{pk}.keys"), "(table)", e.to_string()))
            }
            (Some(_), Some(_)) => Err(self.err(
                format!("{pk}.stroke"),
                "(given with `keys`)",
                "either `stroke` or `keys`, not both",
            )),
            (None, None) => Err(self.err(
                pk,
                "(no `stroke` or `keys`)",
                "`stroke = [dx, dy, dz]` or `keys = [{t, translation, rotation?}, ...]`",
            )),
        }
    }

    /// `[contact]`: only with tools; faces, one of `penalty` / `penalty_factor` (> 0), and a
    /// `release` tool that exists.
    fn contact(
        &self,
        c: Option<&ContactFile>,
        tools: &[RigidTool],
    ) -> Result<Option<ContactSpec>, CaseError> {
        if tools.is_empty() {
            return match c {
                Some(_) => Err(self.err(
                    "contact",
                    "(given)",
                    "at least one [[tool]] table (contact is with rigid tools)",
                )),
                None => Ok(None),
            };
        }
        let default = ContactFile {
            faces: None,
            penalty: None,
            penalty_factor: None,
            release: None,
        };
        let c = c.unwrap_or(&default);
        let faces = match c.faces.as_deref().unwrap_or("both") {
            "top" => ContactFaces::Top,
            "bottom" => ContactFaces::Bottom,
            "both" => ContactFaces::Both,
            other => {
                return Err(self.err(
                    "contact.faces",
                    format!("{other:?}"),
                    "\"top\", \"bottom\" or \"both\" (default \"both\")",
                ))
            }
        };
        let penalty = match (c.penalty, c.penalty_factor) {
            (Some(_), Some(_)) => return Err(self.err(
                "contact.penalty",
                "(given with `penalty_factor`)",
                "either `penalty` (ω, force per length³) or `penalty_factor` (c of ω = c E/t), \
                     not both",
            )),
            (Some(w), None) => PenaltySpec::Value(self.positive("contact.penalty", w)?),
            (None, Some(f)) => PenaltySpec::Factor(self.positive("contact.penalty_factor", f)?),
            (None, None) => PenaltySpec::Factor(DEFAULT_PENALTY_FACTOR),
        };
        if let Some(r) = &c.release {
            if !tools.iter().any(|t| &t.name == r) {
                let names: Vec<&str> = tools.iter().map(|t| t.name.as_str()).collect();
                return Err(self.err(
                    "contact.release",
                    format!("{r:?}"),
                    format!("the name of a [[tool]]: one of {names:?}"),
                ));
            }
        }
        Ok(Some(ContactSpec {
            faces,
            penalty,
            release: c.release.clone(),
        }))
    }

    /// Reject keys that do not belong to an entry of this kind.
    fn only(
        &self,
        key: &str,
        kind: &str,
        present: &[(&str, bool)],
        allowed: &[&str],
    ) -> Result<(), CaseError> {
        for (name, is_present) in present {
            if *is_present && !allowed.contains(name) {
                return Err(self.err(
                    format!("{key}.{name}"),
                    "(given)",
                    format!("no `{name}` for kind = {kind:?} (its keys: {allowed:?})"),
                ));
            }
        }
        Ok(())
    }

    fn required<T: Copy>(
        &self,
        key: &str,
        kind: &str,
        v: Option<T>,
        what: &str,
    ) -> Result<T, CaseError> {
        v.ok_or_else(|| {
            self.err(
                key,
                "(missing)",
                format!("{what} (required for kind = {kind:?})"),
            )
        })
    }

    fn boundary(
        &self,
        k: usize,
        b: &BoundaryFile,
        surface: &Surface<f64>,
        pb: &ParamBox,
    ) -> Result<Boundary, CaseError> {
        let key = format!("boundary[{k}]");
        let present = [
            ("edge", b.edge.is_some()),
            ("at", b.at.is_some()),
            ("normal", b.normal.is_some()),
            ("point", b.point.is_some()),
            ("components", b.components.is_some()),
            ("component", b.component.is_some()),
            ("value", b.value.is_some()),
            ("everywhere", b.everywhere.is_some()),
        ];
        let kind = b.kind.as_str();
        let edge = |this: &Self| -> Result<Edge, CaseError> {
            let s = b.edge.as_deref().ok_or_else(|| {
                this.err(
                    format!("{key}.edge"),
                    "(missing)",
                    format!("one of {EDGE_NAMES:?} (required for kind = {kind:?})"),
                )
            })?;
            this.edge(&format!("{key}.edge"), s)
        };
        match kind {
            "symmetry" => {
                self.only(&key, kind, &present, &["edge", "normal", "point"])?;
                let e = edge(self)?;
                let nk = format!("{key}.normal");
                let n = self.required(&nk, kind, b.normal, "the plane's normal [nx, ny, nz]")?;
                self.finite_vec(&nk, &n)?;
                let nv = Vector3::from(n);
                let len = nv.norm();
                if len == 0.0 {
                    return Err(self.err(nk, fmt_arr(&n), "a non-zero plane normal"));
                }
                let nv = nv / len;
                let pk = format!("{key}.point");
                let point = match b.point {
                    Some(p) => {
                        self.finite_vec(&pk, &p)?;
                        Vector3::from(p)
                    }
                    None => {
                        let mid = edge_point(pb, e, 0.5);
                        surface.eval(mid[0], mid[1]).x
                    }
                };
                self.check_symmetry_plane(&key, e, &point, &nv, surface, pb)?;
                Ok(Boundary::Symmetry {
                    edge: e,
                    point: point.into(),
                    normal: nv.into(),
                })
            }
            "clamped" | "simply-supported" => {
                self.only(&key, kind, &present, &["edge"])?;
                let e = edge(self)?;
                Ok(if kind == "clamped" {
                    Boundary::Clamped { edge: e }
                } else {
                    Boundary::SimplySupported { edge: e }
                })
            }
            "fixed" => {
                self.only(&key, kind, &present, &["edge", "at", "components", "everywhere"])?;
                let everywhere = b.everywhere == Some(true);
                let location = match (&b.edge, b.at, everywhere) {
                    (Some(_), None, false) => Location::Edge(edge(self)?),
                    (None, Some(at), false) => Location::Point(self.param_point(&format!("{key}.at"), at, pb)?),
                    (None, None, true) => Location::Everywhere,
                    (Some(_), Some(_), _) => {
                        return Err(self.err(
                            format!("{key}.at"),
                            "(given with `edge`)",
                            "either `edge`, `at` or `everywhere = true`, not two of them",
                        ))
                    }
                    (e, _, true) => {
                        let other = if e.is_some() { "edge" } else { "at" };
                        return Err(self.err(
                            format!("{key}.everywhere"),
                            format!("true (given with `{other}`)"),
                            "either `edge`, `at` or `everywhere = true`, not two of them",
                        ));
                    }
                    (None, None, false) => {
                        let value = if b.everywhere.is_some() { "false" } else { "(missing)" };
                        return Err(self.err(
                            format!("{key}.edge"),
                            value,
                            "`edge`, `at = [u, v]` or `everywhere = true` (one is required for \
                             kind = \"fixed\")",
                        ));
                    }
                };
                let ck = format!("{key}.components");
                let names = b.components.as_ref().ok_or_else(|| {
                    self.err(
                        ck.clone(),
                        "(missing)",
                        format!("a non-empty list of {:?} (required for kind = \"fixed\")", Component::NAMES),
                    )
                })?;
                if names.is_empty() {
                    return Err(self.err(ck, "[]", format!("a non-empty list of {:?}", Component::NAMES)));
                }
                let mut components = Vec::with_capacity(names.len());
                for (j, s) in names.iter().enumerate() {
                    let c = Component::parse(s).ok_or_else(|| {
                        self.err(format!("{ck}[{j}]"), format!("{s:?}"), format!("one of {:?}", Component::NAMES))
                    })?;
                    if components.contains(&c) {
                        return Err(self.err(format!("{ck}[{j}]"), format!("{s:?}"), "each component once"));
                    }
                    components.push(c);
                }
                components.sort();
                Ok(Boundary::Fixed { location, components })
            }
            "prescribed" => {
                self.only(&key, kind, &present, &["at", "component", "value"])?;
                let at = self.required(&format!("{key}.at"), kind, b.at, "a parameter point [u, v]")?;
                let at = self.param_point(&format!("{key}.at"), at, pb)?;
                let ck = format!("{key}.component");
                let s = b.component.as_deref().ok_or_else(|| {
                    self.err(ck.clone(), "(missing)", "\"ux\", \"uy\" or \"uz\" (required for kind = \"prescribed\")")
                })?;
                let component = match Component::parse(s) {
                    Some(c @ (Component::Ux | Component::Uy | Component::Uz)) => c,
                    _ => return Err(self.err(ck, format!("{s:?}"), "\"ux\", \"uy\" or \"uz\" (a displacement)")),
                };
                let vk = format!("{key}.value");
                let value = self.required(&vk, kind, b.value, "the displacement at load factor 1")?;
                if !value.is_finite() {
                    return Err(self.err(vk, value.to_string(), "a finite number"));
                }
                Ok(Boundary::Prescribed { at, component, value })
            }
            other => Err(self.err(
                format!("{key}.kind"),
                format!("{other:?}"),
                "one of [\"symmetry\", \"clamped\", \"simply-supported\", \"fixed\", \"prescribed\"]",
            )),
        }
    }

    /// Components held on every particle (`fixed`, `everywhere = true`) must not be held again
    /// by another entry: the rows would repeat the particle rows (a singular constraint
    /// system). A symmetry plane is fine (its conditions on the plane's particles are
    /// eliminated DOFs, and the repeated rows are dropped), except a plane whose normal is not
    /// a coordinate axis with every component of the normal held: its multiplier row would
    /// repeat them.
    fn check_everywhere(&self, boundary: &[Boundary]) -> Result<(), CaseError> {
        let mut held: Vec<(usize, Component)> = Vec::new();
        for (k, b) in boundary.iter().enumerate() {
            if let Boundary::Fixed {
                location: Location::Everywhere,
                components,
            } = b
            {
                held.extend(components.iter().map(|&c| (k, c)));
            }
        }
        if held.is_empty() {
            return Ok(());
        }
        let is_held = |c: Component| held.iter().find(|h| h.1 == c).map(|h| h.0);
        let displacements = [Component::Ux, Component::Uy, Component::Uz];
        for (k, b) in boundary.iter().enumerate() {
            let (holds, what): (Vec<Component>, &str) = match b {
                Boundary::Clamped { .. } => (Component::ALL.to_vec(), "kind"),
                Boundary::SimplySupported { .. } => (displacements.to_vec(), "kind"),
                Boundary::Fixed { components, .. } => (components.clone(), "components"),
                Boundary::Prescribed { component, .. } => (vec![*component], "component"),
                Boundary::Symmetry { normal, .. } => {
                    let nonzero: Vec<Component> = (0..3)
                        .filter(|&i| normal[i] != 0.0)
                        .map(|i| displacements[i])
                        .collect();
                    if nonzero.len() > 1 && nonzero.iter().all(|&c| is_held(c).is_some()) {
                        return Err(self.err(
                            format!("boundary[{k}].normal"),
                            fmt_arr(normal),
                            "a plane whose normal has a component not held on every particle \
                             (the symmetry row would repeat those of `everywhere = true`)",
                        ));
                    }
                    continue;
                }
            };
            for c in holds {
                match is_held(c) {
                    Some(j) if j != k => {
                        let which = match b {
                            Boundary::Clamped { .. } => "clamped",
                            Boundary::SimplySupported { .. } => "simply-supported",
                            Boundary::Fixed { .. } => "fixed",
                            _ => "prescribed",
                        };
                        return Err(self.err(
                            format!("boundary[{k}].{what}"),
                            format!("{which:?} (holds {:?})", c.name()),
                            format!(
                                "no component held on every particle by boundary[{j}] \
                                 (everywhere = true): list only the other components here, \
                                 e.g. kind = \"fixed\" with `components`"
                            ),
                        ));
                    }
                    _ => {}
                }
            }
        }
        Ok(())
    }

    /// The edge must lie in the plane, and the surface normal along it must lie in the plane
    /// (so the mirrored surface continues smoothly). Checked at 9 points along the edge; the
    /// tolerance is 1e-8 of the surface's size (bounding box of the sampled points), which
    /// accepts round-off of the geometry evaluation and rejects any real misplacement.
    fn check_symmetry_plane(
        &self,
        key: &str,
        e: Edge,
        point: &Vector3<f64>,
        n: &Vector3<f64>,
        surface: &Surface<f64>,
        pb: &ParamBox,
    ) -> Result<(), CaseError> {
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        for i in 0..=8 {
            for j in 0..=8 {
                let u = pb.lo[0] + (pb.hi[0] - pb.lo[0]) * i as f64 / 8.0;
                let v = pb.lo[1] + (pb.hi[1] - pb.lo[1]) * j as f64 / 8.0;
                let x = surface.eval(u, v).x;
                lo = lo.inf(&x);
                hi = hi.sup(&x);
            }
        }
        let size = (hi - lo).norm().max(f64::MIN_POSITIVE);
        let tol = 1e-8;
        for s in 0..=8 {
            let uv = edge_point(pb, e, s as f64 / 8.0);
            let sd = surface.eval(uv[0], uv[1]);
            let dist = (sd.x - point).dot(n);
            if dist.abs() > tol * size {
                return Err(self.err(
                    format!("{key}.normal"),
                    fmt_arr(n.as_slice()),
                    format!(
                        "a plane containing edge {}: the surface point at (u, v) = ({}, {}) is {:.3e} \
                         from the plane through {} (tolerance {:.1e})",
                        edge_name(e),
                        uv[0],
                        uv[1],
                        dist,
                        fmt_arr(point.as_slice()),
                        tol * size
                    ),
                ));
            }
            if let Ok(sn) = sd.normal() {
                let c = sn.dot(n);
                if c.abs() > tol.sqrt() {
                    return Err(self.err(
                        format!("{key}.normal"),
                        fmt_arr(n.as_slice()),
                        format!(
                            "a plane that contains the surface normal along edge {}: at (u, v) = \
                             ({}, {}) the normal's component along the plane normal is {:.3e}",
                            edge_name(e),
                            uv[0],
                            uv[1],
                            c
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    fn load(&self, k: usize, l: &LoadFile, pb: &ParamBox) -> Result<Load, CaseError> {
        let key = format!("load[{k}]");
        let present = [
            ("at", l.at.is_some()),
            ("force", l.force.is_some()),
            ("value", l.value.is_some()),
            ("per_area", l.per_area.is_some()),
            ("per_volume", l.per_volume.is_some()),
            ("edge", l.edge.is_some()),
            ("per_length", l.per_length.is_some()),
            ("follower", l.follower.is_some()),
        ];
        let kind = l.kind.as_str();
        let vec3 = |this: &Self,
                    name: &str,
                    v: Option<[f64; 3]>,
                    what: &str|
         -> Result<[f64; 3], CaseError> {
            let k2 = format!("{key}.{name}");
            let v = this.required(&k2, kind, v, what)?;
            this.finite_vec(&k2, &v)?;
            Ok(v)
        };
        match kind {
            "point-force" => {
                self.only(&key, kind, &present, &["at", "force"])?;
                let at =
                    self.required(&format!("{key}.at"), kind, l.at, "a parameter point [u, v]")?;
                Ok(Load::PointForce {
                    at: self.param_point(&format!("{key}.at"), at, pb)?,
                    force: vec3(self, "force", l.force, "a force [fx, fy, fz]")?,
                })
            }
            "pressure" => {
                self.only(&key, kind, &present, &["value"])?;
                let vk = format!("{key}.value");
                let value = self.required(&vk, kind, l.value, "the pressure")?;
                if !value.is_finite() {
                    return Err(self.err(vk, value.to_string(), "a finite number"));
                }
                Ok(Load::Pressure { value })
            }
            "gravity" => {
                self.only(&key, kind, &present, &["per_area", "per_volume"])?;
                match (l.per_area, l.per_volume) {
                    (Some(_), Some(_)) => Err(self.err(
                        format!("{key}.per_volume"),
                        "(given)",
                        "either `per_area` (force per unit area) or `per_volume` (force per \
                         unit volume, scaled by the thickness), not both",
                    )),
                    (None, Some(_)) => Ok(Load::GravityPerVolume {
                        per_volume: vec3(
                            self,
                            "per_volume",
                            l.per_volume,
                            "a force per unit volume [ρgx, ρgy, ρgz]",
                        )?,
                    }),
                    _ => Ok(Load::Gravity {
                        per_area: vec3(
                            self,
                            "per_area",
                            l.per_area,
                            "a force per unit area [bx, by, bz] (or `per_volume`)",
                        )?,
                    }),
                }
            }
            "moment" => {
                self.only(&key, kind, &present, &["edge", "per_length"])?;
                let ek = format!("{key}.edge");
                let s = l.edge.as_deref().ok_or_else(|| {
                    self.err(
                        ek.clone(),
                        "(missing)",
                        format!("one of {EDGE_NAMES:?} (required for kind = \"moment\")"),
                    )
                })?;
                Ok(Load::Moment {
                    edge: self.edge(&ek, s)?,
                    per_length: vec3(
                        self,
                        "per_length",
                        l.per_length,
                        "a moment per unit length [mx, my, mz]",
                    )?,
                })
            }
            "edge-force" => {
                self.only(&key, kind, &present, &["edge", "per_length", "follower"])?;
                let ek = format!("{key}.edge");
                let s = l.edge.as_deref().ok_or_else(|| {
                    self.err(
                        ek.clone(),
                        "(missing)",
                        format!("one of {EDGE_NAMES:?} (required for kind = \"edge-force\")"),
                    )
                })?;
                let follower = l.follower.unwrap_or(false);
                Ok(Load::EdgeForce {
                    edge: self.edge(&ek, s)?,
                    per_length: vec3(
                        self,
                        "per_length",
                        l.per_length,
                        if follower {
                            "a force per unit length [f_out, f_normal, f_tangent]"
                        } else {
                            "a force per unit length [fx, fy, fz]"
                        },
                    )?,
                    follower,
                })
            }
            other => Err(self.err(
                format!("{key}.kind"),
                format!("{other:?}"),
                "one of [\"point-force\", \"pressure\", \"gravity\", \"moment\", \"edge-force\"]",
            )),
        }
    }

    /// The angle ranges of a surface in the degrees they are written in (`*_deg` keys):
    /// finite, ascending, a span of at most 360°, latitudes within [−90°, 90°].
    fn check_degrees(&self, key: &str, spec: &SurfaceSpec) -> Result<(), CaseError> {
        let range = |name: &str, a: &[f64; 2], lat: bool| -> Result<(), CaseError> {
            let k = format!("{key}.{name}");
            self.finite_vec(&k, a)?;
            if a[0] >= a[1] {
                return Err(self.err(k, fmt_arr(a), "an ascending range [start, end] in degrees"));
            }
            if lat && !(a[0] >= -90.0 && a[1] <= 90.0) {
                return Err(self.err(k, fmt_arr(a), "latitudes in degrees within [-90, 90]"));
            }
            if a[1] - a[0] > 360.0 {
                return Err(self.err(
                    k,
                    fmt_arr(a),
                    format!(
                        "a span of at most 360 degrees (this one spans {} degrees)",
                        a[1] - a[0]
                    ),
                ));
            }
            Ok(())
        };
        match spec {
            SurfaceSpec::AnnulusSector { angle_deg, .. }
            | SurfaceSpec::CylinderSector { angle_deg, .. } => range("angle_deg", angle_deg, false),
            SurfaceSpec::SphereZone {
                latitude_deg,
                longitude_deg,
                ..
            } => {
                range("latitude_deg", latitude_deg, true)?;
                range("longitude_deg", longitude_deg, false)
            }
            _ => Ok(()),
        }
    }

    fn steps(&self, s: &StepsFile) -> Result<StepsSpec, CaseError> {
        let final_load = self.positive("steps.final_load", s.final_load)?;
        // The load steps: required with load stepping; arc-length continuation does not use
        // them (one step to `final_load` where they are left out).
        let arc = s.control.as_deref() == Some("arc-length");
        let step = |key: &str, v: Option<f64>, what: &str| match v {
            Some(v) => self.positive(key, v),
            None if arc => Ok(final_load),
            None => Err(self.err(
                key,
                "(missing)",
                format!("{what} (> 0; required with control = \"load\", the default)"),
            )),
        };
        let min_step = step(
            "steps.min_step",
            s.min_step,
            "the smallest load-factor step",
        )?;
        let initial_step = step(
            "steps.initial_step",
            s.initial_step,
            "the first load-factor step",
        )?;
        let max_step = step("steps.max_step", s.max_step, "the largest load-factor step")?;
        if initial_step < min_step {
            return Err(self.err(
                "steps.initial_step",
                initial_step.to_string(),
                format!("a step >= steps.min_step = {min_step}"),
            ));
        }
        if max_step < initial_step {
            return Err(self.err(
                "steps.max_step",
                max_step.to_string(),
                format!("a step >= steps.initial_step = {initial_step}"),
            ));
        }
        let max_iterations = self.count("steps.max_iterations", s.max_iterations, 1, Some(1000))?;
        let max_active_set_iterations = self.count(
            "steps.max_active_set_iterations",
            s.max_active_set_iterations,
            0,
            Some(1000),
        )?;
        let residual_rtol = self.fraction("steps.residual_rtol", s.residual_rtol)?;
        let energy_rtol = self.fraction("steps.energy_rtol", s.energy_rtol)?;
        let max_attempts = self.count("steps.max_attempts", s.max_attempts, 1, None)?;
        for (k, v) in [
            ("steps.residual_atol", s.residual_atol),
            ("steps.energy_atol", s.energy_atol),
        ] {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(self.err(k, v.to_string(), "a finite number >= 0"));
            }
        }
        if !(s.cut_factor > 0.0 && s.cut_factor < 1.0) {
            return Err(self.err(
                "steps.cut_factor",
                s.cut_factor.to_string(),
                "a factor in (0, 1)",
            ));
        }
        if !(s.grow_factor >= 1.0 && s.grow_factor.is_finite()) {
            return Err(self.err(
                "steps.grow_factor",
                s.grow_factor.to_string(),
                "a finite factor >= 1",
            ));
        }
        let easy_iterations = self.count("steps.easy_iterations", s.easy_iterations, 0, None)?;
        let predictor = self.keyword(
            "steps.predictor",
            s.predictor.as_deref(),
            None,
            &[
                ("zero", Some(PredictorKind::Zero)),
                ("secant", Some(PredictorKind::Secant)),
                ("quadratic", Some(PredictorKind::Quadratic)),
            ],
        )?;
        use crate::solver::{LineSearch, LinearUpdates, StopFailure};
        let linear_updates = self.keyword(
            "steps.linear_updates",
            s.linear_updates.as_deref(),
            LinearUpdates::Direct,
            &[
                ("auto", LinearUpdates::Auto),
                ("direct", LinearUpdates::Direct),
                ("krylov", LinearUpdates::KrylovNearConvergence),
                ("krylov-held", LinearUpdates::KrylovHeld),
            ],
        )?;
        let preconditioner = self.keyword(
            "steps.preconditioner",
            s.preconditioner.as_deref(),
            crate::solver::PreconditionerPrecision::Single,
            &[
                ("single", crate::solver::PreconditionerPrecision::Single),
                ("double", crate::solver::PreconditionerPrecision::Double),
            ],
        )?;
        let line_search = self.keyword(
            "steps.line_search",
            s.line_search.as_deref(),
            LineSearch::OnFailure,
            &[
                ("on-failure", LineSearch::OnFailure),
                ("off", LineSearch::Off),
            ],
        )?;
        let stop_failure = self.keyword(
            "steps.stop_failure",
            s.stop_failure.as_deref(),
            StopFailure::Cut,
            &[
                ("cut", StopFailure::Cut),
                ("continuation", StopFailure::Continuation),
            ],
        )?;
        let arc_length = match s.control.as_deref() {
            None | Some("load") => {
                for (k, given) in [
                    ("arc_length", s.arc_length.is_some()),
                    ("min_arc_length", s.min_arc_length.is_some()),
                    ("max_arc_length", s.max_arc_length.is_some()),
                ] {
                    if given {
                        return Err(self.err(
                            format!("steps.{k}"),
                            "(given)",
                            "no arc length with load stepping (set control = \"arc-length\")",
                        ));
                    }
                }
                None
            }
            Some("arc-length") => {
                let initial = self.positive(
                    "steps.arc_length",
                    s.arc_length.ok_or_else(|| {
                        self.err(
                            "steps.arc_length",
                            "(missing)",
                            "the first arc length (> 0; required with control = \"arc-length\")",
                        )
                    })?,
                )?;
                let min = self.positive(
                    "steps.min_arc_length",
                    s.min_arc_length.unwrap_or(1e-4 * initial),
                )?;
                let max =
                    self.positive("steps.max_arc_length", s.max_arc_length.unwrap_or(initial))?;
                if !(min <= initial && initial <= max) {
                    return Err(self.err(
                        "steps.arc_length",
                        initial.to_string(),
                        format!(
                            "an arc length within [steps.min_arc_length, steps.max_arc_length] \
                             = [{min}, {max}]"
                        ),
                    ));
                }
                if !s.stops.is_empty() {
                    return Err(self.err(
                        "steps.stops",
                        fmt_arr(&s.stops),
                        "no stops with control = \"arc-length\" (the load factor is an unknown)",
                    ));
                }
                Some([initial, min, max])
            }
            Some(other) => {
                return Err(self.err(
                    "steps.control",
                    format!("{other:?}"),
                    "\"load\" or \"arc-length\"",
                ))
            }
        };
        let mut prev = 0.0;
        for (k, &v) in s.stops.iter().enumerate() {
            if !(v.is_finite() && v > prev && v <= final_load) {
                return Err(self.err(
                    format!("steps.stops[{k}]"),
                    v.to_string(),
                    format!(
                        "a finite load factor in ({prev}, steps.final_load = {final_load}] \
                         (stops strictly ascending, after 0)"
                    ),
                ));
            }
            prev = v;
        }
        Ok(StepsSpec {
            initial_step,
            min_step,
            max_step,
            final_load,
            max_iterations,
            max_active_set_iterations,
            residual_rtol,
            residual_atol: s.residual_atol,
            energy_rtol,
            energy_atol: s.energy_atol,
            cut_factor: s.cut_factor,
            grow_factor: s.grow_factor,
            easy_iterations,
            predictor,
            linear_updates,
            preconditioner,
            line_search,
            stop_failure,
            stops: s.stops.clone(),
            max_attempts,
            arc_length,
        })
    }
}

/// The parameter point at fraction `s ∈ [0, 1]` along edge `e` of box `b` (from the edge's
/// lower end).
pub fn edge_point(b: &ParamBox, e: Edge, s: f64) -> [f64; 2] {
    let lerp = |k: usize| b.lo[k] + (b.hi[k] - b.lo[k]) * s;
    match e {
        Edge::UMin => [b.lo[0], lerp(1)],
        Edge::UMax => [b.hi[0], lerp(1)],
        Edge::VMin => [lerp(0), b.lo[1]],
        Edge::VMax => [lerp(0), b.hi[1]],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A clamped strip (12 × 1, t = 0.1) with one design variable.
    const GOOD: &str = r#"
thickness = 0.1

[problem]
kind = "shell"

[surface]
type = "rectangle"
origin = [0.0, 0.0, 0.0]
edge_u = [12.0, 0.0, 0.0]
edge_v = [0.0, 1.0, 0.0]

[particles]
grid = [13, 3]

[kernel]
basis = "quadratic"
support = 3.0

[integration]
cells = "per-particle-spacing"
subdivide = 2
gauss = 4
thickness_points = 5
thickness_rule = "lobatto"

[material]
young = 1.2e6
poisson = 0.0
sigma0 = 100.0
hardening = 10.0
beta = 1.0

[[boundary]]
kind = "clamped"
edge = "u-min"

[[load]]
kind = "point-force"
at = [1.0, 0.5]
force = [0.0, 0.0, 1.0]

[steps]
initial_step = 0.1
min_step = 0.001
max_step = 0.2

[[monitor]]
name = "tip"
at = [1.0, 0.5]

[[design]]
name = "t"
kind = "thickness"
fd_steps = [1e-3]
"#;

    fn parse(text: &str) -> Result<ShellCase, CaseError> {
        parse_shell_case(text, Path::new("case.toml"))
    }

    fn err(text: &str) -> String {
        match parse(text) {
            Ok(_) => panic!("accepted:\n{text}"),
            Err(e) => e.to_string(),
        }
    }

    fn with(a: &str, b: &str) -> String {
        assert!(GOOD.contains(a), "{a}");
        GOOD.replacen(a, b, 1)
    }

    #[test]
    fn good_case_has_no_warning_and_a_small_estimate() {
        let c = parse(GOOD).unwrap();
        assert!(c.warnings.is_empty(), "{:?}", c.warnings);
        let e = c.estimate();
        assert_eq!((e.particles, e.unknowns), (39, 195));
        // 12 × 2 spacings, subdivided twice, 4 × 4 Gauss points, 5 layers.
        assert_eq!(e.quadrature_points, 24 * 4 * 16);
        assert_eq!(e.layer_points, 24 * 4 * 16 * 5);
        // Supports of 3 spacings: 7 particles along u, all 3 along v.
        assert_eq!(e.neighbours, 21);
        assert_eq!(e.min_steps, 5.0);
        assert_eq!(e.max_attempts, DEFAULT_MAX_ATTEMPTS);
    }

    /// serde would read the first entries of a longer array and drop the rest: every
    /// fixed-length array is read whole, the surface's included.
    #[test]
    fn arrays_of_the_wrong_length_are_errors() {
        for (a, b, key) in [
            ("grid = [13, 3]", "grid = [13, 3, 3]", "grid"),
            ("grid = [13, 3]", "grid = [13]", "grid"),
            (
                "force = [0.0, 0.0, 1.0]",
                "force = [1e-3, 0, 0, 1e6]",
                "force",
            ),
            (
                "at = [1.0, 0.5]\nforce",
                "at = [1.0, 0.5, 0.0]\nforce",
                "at",
            ),
            // The surface's arrays (a tagged enum, read through serde's buffered content)
            // get serde's own length message.
            (
                "edge_u = [12.0, 0.0, 0.0]",
                "edge_u = [12.0, 0.0, 0.0, 5.0]",
                "invalid length 4",
            ),
        ] {
            let e = err(&with(a, b));
            assert!(e.contains(key) && e.contains("length"), "{b}: {e}");
        }
    }

    #[test]
    fn tolerances_and_counts_are_range_checked() {
        for (key, bad) in [
            ("residual_rtol", "-1e-8"),
            ("residual_rtol", "nan"),
            ("residual_rtol", "1.5"),
            ("energy_rtol", "-1e-14"),
            ("residual_atol", "-1.0"),
            ("energy_atol", "inf"),
            ("max_attempts", "0"),
        ] {
            let e = err(&with(
                "max_step = 0.2",
                &format!("max_step = 0.2\n{key} = {bad}"),
            ));
            assert!(e.contains(&format!("steps.{key}")), "{key} = {bad}: {e}");
        }
    }

    /// The cases that were accepted and then ran out of memory or time are refused with the
    /// estimate and the `[limits]` key; an explicit `[limits]` lets them through.
    #[test]
    fn cases_beyond_the_limits_are_refused_unless_raised() {
        let e = err(&with("grid = [13, 3]", "grid = [5000, 5000]"));
        assert!(
            e.contains("particles.grid") && e.contains("125000000") && e.contains("max_unknowns"),
            "{e}"
        );
        let e = err(&with("subdivide = 2", "subdivide = 1000"));
        assert!(
            e.contains("integration.subdivide") && e.contains("max_layer_points"),
            "{e}"
        );
        let e = err(&with("support = 3.0", "support = 1e6"));
        assert!(
            e.contains("kernel.support") && e.contains("max_support"),
            "{e}"
        );
        let e = err(&with(
            "max_step = 0.2",
            "max_step = 0.2\nfinal_load = 1e308",
        ));
        assert!(
            e.contains("steps.max_step") && e.contains("max_attempts"),
            "{e}"
        );
        let stops: Vec<String> = (1..=10_000)
            .map(|k| format!("{}", k as f64 * 1e-4))
            .collect();
        let e = err(&with(
            "max_step = 0.2",
            &format!("max_step = 0.2\nstops = [{}]", stops.join(", ")),
        ));
        assert!(
            e.contains("max_attempts") && e.contains("10000 stops"),
            "{e}"
        );
        // Raised explicitly: accepted (nothing is built by `check`).
        let raised = with("support = 3.0", "support = 12.0") + "\n[limits]\nmax_support = 20.0\n";
        assert_eq!(parse(&raised).unwrap().kernel.support, 12.0);
        let raised = with(
            "max_step = 0.2",
            "max_step = 0.2\nfinal_load = 1e4\nmax_attempts = 100000",
        );
        assert_eq!(parse(&raised).unwrap().steps.max_attempts, 100_000);
        let e = err(&(GOOD.to_string() + "\n[limits]\nmax_memory_gb = -1.0\n"));
        assert!(e.contains("limits.max_memory_gb"), "{e}");
        let e = err(&(GOOD.to_string() + "\n[limits]\nmax_memory_gb = 1e-9\n"));
        assert!(e.contains("memory") && e.contains("max_memory_gb"), "{e}");
    }

    /// The good case on a quarter cylinder of radius 1 and length 12 with the thickness given.
    fn cylinder_case(thickness: &str) -> String {
        with(
            "type = \"rectangle\"\norigin = [0.0, 0.0, 0.0]\nedge_u = [12.0, 0.0, 0.0]\n\
         edge_v = [0.0, 1.0, 0.0]",
            "type = \"cylinder-sector\"\norigin = [0.0, 0.0, 0.0]\naxis = [0.0, 0.0, 1.0]\n\
         reference = [1.0, 0.0, 0.0]\nradius = 1.0\nangle_deg = [0.0, 90.0]\n\
         length = [0.0, 12.0]",
        )
        .replacen("thickness = 0.1", &format!("thickness = {thickness}"), 1)
    }

    #[test]
    fn no_boundary_entry_is_a_warning() {
        let free = with("[[boundary]]\nkind = \"clamped\"\nedge = \"u-min\"\n", "");
        let c = parse(&free).unwrap();
        assert!(c.boundary.is_empty());
        assert!(
            c.warnings
                .iter()
                .any(|w| w.contains("no `[[boundary]]` entry") && w.contains("singular")),
            "{:?}",
            c.warnings
        );
    }

    #[test]
    fn linear_basis_on_a_thin_curved_shell_is_a_warning() {
        // A cylinder of radius 1 with t = 0.01 (R/t = 100).
        let linear = cylinder_case("0.01")
            .replacen("basis = \"quadratic\"", "basis = \"linear\"", 1)
            .replacen("support = 3.0", "support = 2.0", 1);
        assert!(linear.contains("\"linear\""));
        let locks = |text: &str| {
            parse(text)
                .unwrap()
                .warnings
                .iter()
                .any(|w| w.contains("the linear basis locks"))
        };
        assert!(locks(&linear));
        // Not with the quadratic basis, not on a plate, not at R/t = 20.
        assert!(!locks(&cylinder_case("0.01")));
        assert!(!locks(&linear.replacen(
            "thickness = 0.01",
            "thickness = 0.05",
            1
        )));
        let plate = GOOD
            .replacen("basis = \"quadratic\"", "basis = \"linear\"", 1)
            .replacen("support = 3.0", "support = 2.0", 1);
        assert!(plate.contains("\"linear\""));
        assert!(!locks(&plate));
    }

    #[test]
    fn jittered_thin_curved_shell_with_a_quadratic_basis_is_a_warning() {
        // A cylinder of radius 1 with t = 0.01 (R/t = 100).
        let cyl = cylinder_case("0.01");
        let locks = |text: &str| {
            parse(text)
                .unwrap()
                .warnings
                .iter()
                .any(|w| w.contains("locks in membrane") && w.contains("particles.jitter"))
        };
        assert!(!cyl.contains("jitter"));
        let jittered = cyl.replacen("grid = [", "jitter = 0.2\ngrid = [", 1);
        assert!(jittered.contains("jitter = 0.2"));
        assert!(locks(&jittered));
        // Not on the regular grid, not with the cubic basis, not on a plate, not at R/t = 20.
        assert!(!locks(&cyl));
        let cubic = jittered
            .replacen("basis = \"quadratic\"", "basis = \"cubic\"", 1)
            .replacen("support = 3.0", "support = 3.5", 1);
        assert!(cubic.contains("\"cubic\""));
        assert!(!locks(&cubic));
        assert!(!locks(&GOOD.replacen(
            "grid = [",
            "jitter = 0.2\ngrid = [",
            1
        )));
        assert!(!locks(&jittered.replacen(
            "thickness = 0.01",
            "thickness = 0.05",
            1
        )));
    }

    #[test]
    fn implausible_geometry_is_a_warning() {
        // A cylinder of radius 1 with t = 1.5: thicker than its radius of curvature.
        let cyl = cylinder_case("1.5");
        let c = parse(&cyl).unwrap();
        assert!(
            c.warnings.iter().any(|w| w.contains("radius of curvature")),
            "{:?}",
            c.warnings
        );
        let thick = with("thickness = 0.1", "thickness = 5.0");
        let c = parse(&thick).unwrap();
        assert!(
            c.warnings.iter().any(|w| w.contains("solid")),
            "{:?}",
            c.warnings
        );
        // The cubic B-spline named at wide supports: the two-spacing blind spot near
        // multiples of 4, the wavelength of half the support elsewhere from 4 on; the default
        // kernel there (the quartic spline) draws neither warning.
        for (support, blind, wide) in [
            ("3.5", false, false),
            ("4.0", true, false),
            ("4.1", true, false),
            ("4.5", false, true),
            ("8.0", true, false),
        ] {
            let named = with("support = 3.0", &format!("support = {support}")).replacen(
                "[kernel]",
                "[kernel]\nfunction = \"cubic-spline\"",
                1,
            );
            let c = parse(&named).unwrap();
            let has = |what: &str| c.warnings.iter().any(|w| w.contains(what));
            assert_eq!(
                has("alternates from particle"),
                blind,
                "{support}: {:?}",
                c.warnings
            );
            assert_eq!(has("half the support"), wide, "{support}: {:?}", c.warnings);
            let c = parse(&with("support = 3.0", &format!("support = {support}"))).unwrap();
            assert!(
                !c.warnings.iter().any(|w| w.contains("cubic-spline")),
                "{support}: {:?}",
                c.warnings
            );
        }
        let stretched = with("grid = [13, 3]", "grid = [3, 60]");
        let c = parse(&stretched).unwrap();
        assert!(
            c.warnings.iter().any(|w| w.contains("spacings")),
            "{:?}",
            c.warnings
        );
    }

    /// A finite-difference step that vanishes against the variable's value: an error naming
    /// the step.
    #[test]
    fn fd_steps_that_underflow_are_errors() {
        for bad in ["5e-324", "1e-300", "1e-17"] {
            let e = err(&with("fd_steps = [1e-3]", &format!("fd_steps = [{bad}]")));
            assert!(
                e.contains("design[0].fd_steps[0]") && e.contains("floating point"),
                "{bad}: {e}"
            );
        }
        assert!(parse(&with("fd_steps = [1e-3]", "fd_steps = [1e-10]")).is_ok());
    }
}
