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

use super::{material_from_spec, CaseError, MaterialSpec};
use crate::contact::{ContactFaces, PathKey, RigidTool, Side, ToolPath, DEFAULT_PENALTY_FACTOR};
use crate::geometry::{Surface, SurfaceSpec};
use crate::material::MaterialParams;
use crate::meshfree::quadrature::{ThicknessRule, MAX_GAUSS_POINTS, MAX_LOBATTO_POINTS};
use crate::meshfree::transform::Edge;
use crate::meshfree::vci::VciOrder;
use crate::meshfree::{Basis, ParamBox};
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
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct BoundaryFile {
    kind: String,
    edge: Option<String>,
    at: Option<[f64; 2]>,
    normal: Option<[f64; 3]>,
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
    at: Option<[f64; 2]>,
    force: Option<[f64; 3]>,
    value: Option<f64>,
    per_area: Option<[f64; 3]>,
    edge: Option<String>,
    per_length: Option<[f64; 3]>,
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
    #[serde(default)]
    pivot: Option<[f64; 3]>,
    #[serde(default)]
    keys: Option<Vec<PathKeyFile>>,
    #[serde(default)]
    stroke: Option<[f64; 3]>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PathKeyFile {
    t: f64,
    translation: [f64; 3],
    #[serde(default)]
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
    initial_step: f64,
    min_step: f64,
    max_step: f64,
    #[serde(default = "one")]
    final_load: f64,
    #[serde(default = "default_max_iterations")]
    max_iterations: i64,
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
    stops: Vec<f64>,
}

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
    at: [f64; 2],
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

/// RK kernel: basis and support half-width as a multiple of the particle spacing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KernelSpec {
    /// Polynomial basis.
    pub basis: Basis,
    /// Support half-width in particle spacings (per direction), > 0.
    pub support: f64,
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
    /// Moment per unit length about a fixed axis, along a parametric edge.
    Moment {
        /// The edge.
        edge: Edge,
        /// Moment per unit length (global axes).
        per_length: [f64; 3],
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
    /// Newton iterations per step.
    pub max_iterations: usize,
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
    /// How Newton updates are solved near convergence (`false`: always a fresh factorisation,
    /// the default; `true`: GMRES preconditioned by the step's last factorisation).
    pub krylov_updates: bool,
    /// Load levels the stepping lands on exactly (strictly ascending, finite, in
    /// `(0, final_load]`; possibly empty).
    pub stops: Vec<f64>,
}

/// A named point whose displacement is recorded at every converged step.
#[derive(Clone, Debug, PartialEq)]
pub struct Monitor {
    /// Name (unique).
    pub name: String,
    /// Parameter point.
    pub at: [f64; 2],
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
    /// [`crate::contact::DEFAULT_PENALTY_FACTOR`]).
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
    /// Output settings.
    pub output: OutputSpec,
    /// `[[design]]` and `[dsa]` (`None` without `[[design]]` tables; [`super::dsa_case`]).
    pub dsa: Option<super::dsa_case::DsaSpec>,
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

fn fmt_arr(a: &[f64]) -> String {
    let parts: Vec<String> = a.iter().map(|v| format!("{v}")).collect();
    format!("[{}]", parts.join(", "))
}

impl Checker<'_> {
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
            Err(self.err(key, v.to_string(), "a finite number > 0"))
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
            other => {
                return Err(self.err(
                    "kernel.basis",
                    format!("{other:?}"),
                    "\"linear\" or \"quadratic\"",
                ))
            }
        };
        let support = self.positive("kernel.support", f.kernel.support)?;
        let kernel = KernelSpec { basis, support };

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
            "gauss" => ThicknessRule::Gauss(self.count(
                "integration.thickness_points",
                i.thickness_points,
                1,
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
        let integration = IntegrationSpec {
            cells,
            gauss,
            thickness_rule,
            vci,
            director_stabilisation,
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
        let tools = f
            .tool
            .iter()
            .enumerate()
            .map(|(k, t)| self.tool(k, t, &f.tool[..k]))
            .collect::<Result<Vec<_>, _>>()?;
        let contact = self.contact(f.contact.as_ref(), &tools)?;

        let mut monitors: Vec<Monitor> = Vec::with_capacity(f.monitor.len());
        for (k, m) in f.monitor.iter().enumerate() {
            let key = format!("monitor[{k}]");
            if m.name.trim().is_empty() {
                return Err(self.err(
                    format!("{key}.name"),
                    format!("{:?}", m.name),
                    "a non-empty name",
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

        let dsa = super::dsa_case::check(
            self.path, f.design, f.dsa, thickness, &material, &monitors, &surface,
        )?;
        if let Some(spec) = &dsa {
            super::dsa_case::check_tool_names(self.path, &tools, spec)?;
        }

        Ok(ShellCase {
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
            output,
        })
    }

    /// One `[[tool]]`: name (non-empty, unique), side, surface and path, validated as a
    /// [`RigidTool`] (a normal at every sample of its coarse grid).
    fn tool(&self, k: usize, t: &ToolFile, earlier: &[ToolFile]) -> Result<RigidTool, CaseError> {
        let key = format!("tool[{k}]");
        if t.name.trim().is_empty() {
            return Err(self.err(
                format!("{key}.name"),
                format!("{:?}", t.name),
                "a non-empty name",
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
            ("edge", l.edge.is_some()),
            ("per_length", l.per_length.is_some()),
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
                self.only(&key, kind, &present, &["per_area"])?;
                Ok(Load::Gravity {
                    per_area: vec3(
                        self,
                        "per_area",
                        l.per_area,
                        "a force per unit area [bx, by, bz]",
                    )?,
                })
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
            other => Err(self.err(
                format!("{key}.kind"),
                format!("{other:?}"),
                "one of [\"point-force\", \"pressure\", \"gravity\", \"moment\"]",
            )),
        }
    }

    fn steps(&self, s: &StepsFile) -> Result<StepsSpec, CaseError> {
        let final_load = self.positive("steps.final_load", s.final_load)?;
        let min_step = self.positive("steps.min_step", s.min_step)?;
        let initial_step = self.positive("steps.initial_step", s.initial_step)?;
        let max_step = self.positive("steps.max_step", s.max_step)?;
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
        let residual_rtol = self.positive("steps.residual_rtol", s.residual_rtol)?;
        let energy_rtol = self.positive("steps.energy_rtol", s.energy_rtol)?;
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
        let predictor = match s.predictor.as_deref() {
            None => None,
            Some("zero") => Some(PredictorKind::Zero),
            Some("secant") => Some(PredictorKind::Secant),
            Some("quadratic") => Some(PredictorKind::Quadratic),
            Some(other) => {
                return Err(self.err(
                    "steps.predictor",
                    format!("{other:?}"),
                    "\"zero\", \"secant\" or \"quadratic\"",
                ))
            }
        };
        let krylov_updates = match s.linear_updates.as_deref() {
            None | Some("direct") => false,
            Some("krylov") => true,
            Some(other) => {
                return Err(self.err(
                    "steps.linear_updates",
                    format!("{other:?}"),
                    "\"direct\" or \"krylov\"",
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
            residual_rtol,
            residual_atol: s.residual_atol,
            energy_rtol,
            energy_atol: s.energy_atol,
            cut_factor: s.cut_factor,
            grow_factor: s.grow_factor,
            easy_iterations,
            predictor,
            krylov_updates,
            stops: s.stops.clone(),
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
