//! Design sensitivity analysis (the paper's §3, eqs 37–65): design variables, the
//! dual-number reference ([`dual`]) and finite differences of complete re-runs ([`fd`]).
//!
//! The **non-shape** design variables: the thickness `t` and the material parameters
//! `E, ν, k, σ0, H, β` (eqs 9–13), and the **tool placements** ([`DesignKind::Tool`], the
//! translation of a rigid tool's whole path, and [`DesignKind::ToolRotation`], a rotation of
//! the tool as built about its pivot, which enter through the contact force only:
//! `b'_N` of eq 83, `crate::shell::contact_sensitivity`). The first ones enter the
//! residual (eq 32) only through the point kernel's `PointInput::thickness` and
//! `PointInput::material`; the design velocity of eqs 37–43 is zero for them (the geometry does
//! not move), so the structural fictitious load `a'_V` of eq (64) reduces to the material and
//! history terms of eq (49). Shape design variables ([`DesignKind::Shape`]: a parameter of the
//! mid-surface, `Surface::design_parameters`) move the initial geometry at fixed parameter
//! coordinates; their design velocity field (eqs 37–43) is hand-derived in [`shape`], and the
//! dual reference seeds the surface parameter ([`shape::dual_geometry`]). Tool placements
//! ([`DesignKind::Tool`], [`DesignKind::ToolRotation`]) translate a rigid tool's path or turn
//! the tool as built, and tool shapes ([`DesignKind::ToolShape`]) change a design parameter of
//! a tool's surface (`b'_N`, eq 83, with the design velocity `V^c` of eq 76).
//!
//! Layout: `docs/sensitivity.md`.

pub mod continuum;
pub mod dual;
pub mod fd;
pub mod shape;
pub mod study;
pub mod terms;

use crate::contact::RigidTool;
use crate::geometry::Surface;
use crate::material::{MaterialError, MaterialParams, PARAM_NAMES};
use crate::shell::load::ContactLoad;
use crate::shell::model::ShellModel;
use crate::shell::problem::ShellProblem;
use crate::shell::ShellError;
use nalgebra::Vector3;
use std::collections::BTreeMap;
use thiserror::Error;

/// A material parameter as a design variable (the fields of [`MaterialParams`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MaterialParameter {
    /// Young's modulus `E` (eq 9).
    Young,
    /// Poisson's ratio `ν` (eq 9).
    Poisson,
    /// Transverse shear correction factor `k`.
    ShearFactor,
    /// Initial yield stress `σ0` (eq 10).
    Sigma0,
    /// Hardening modulus `H` (eqs 12–13).
    Hardening,
    /// Hardening mix `β` (eq 12).
    Beta,
}

impl MaterialParameter {
    /// All parameters in the order of [`MaterialParams::to_array`].
    pub const ALL: [MaterialParameter; 6] = [
        MaterialParameter::Young,
        MaterialParameter::Poisson,
        MaterialParameter::ShearFactor,
        MaterialParameter::Sigma0,
        MaterialParameter::Hardening,
        MaterialParameter::Beta,
    ];

    /// Position in [`MaterialParams::to_array`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// The case-file name (as [`PARAM_NAMES`]).
    pub fn name(self) -> &'static str {
        PARAM_NAMES[self.index()]
    }

    /// From its case-file name (`young`, `poisson`, `shear_factor`, `sigma0`, `hardening`,
    /// `beta`).
    pub fn from_name(name: &str) -> Result<Self, DesignError> {
        Self::ALL
            .into_iter()
            .find(|p| p.name() == name)
            .ok_or_else(|| DesignError::UnknownParameter {
                name: name.to_string(),
                expected: PARAM_NAMES.join(", "),
            })
    }
}

/// What a design variable changes. Non-exhaustive: shape (surface parameters, control-point
/// What a design variable changes: thickness, a material parameter, a surface parameter
/// (shape) or the position of a rigid tool.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum DesignKind {
    /// The shell thickness `t` (uniform).
    Thickness,
    /// A material parameter.
    Material(MaterialParameter),
    /// A design parameter of the shell's mid-surface (`Surface::design_parameters`: the
    /// radius, a centre coordinate, a NURBS control-point coordinate or weight): a shape
    /// design variable, whose design velocity field (eqs 37–43) is the surface's
    /// `Surface::design_velocity` on the fixed parametric discretisation.
    Shape {
        /// Index in `Surface::design_parameters`.
        parameter: usize,
        /// Its name there (`radius`, `cp[2][3].z`, …).
        name: String,
    },
    /// The translation of the named rigid tool's whole path by `τ` along axis `axis` (0, 1, 2 =
    /// x, y, z): the tool position of the paper's §4.2, whose design velocity on the tool is
    /// the constant `V^c = e_axis` (eq 76) and whose fictitious load is `b'_N` (eq 83). The
    /// variable's value is the offset from the case's path (0 at the nominal design).
    Tool {
        /// Tool name (`[[tool]] name`).
        tool: String,
        /// Axis 0, 1, 2.
        axis: usize,
    },
    /// The rotation of the named rigid tool **as built** by `τ` radians about the global axis
    /// `axis` (0, 1, 2 = x, y, z) through its pivot `c` (`path.pivot`), before its motion:
    /// `x^c = c + R(θ(t)) R_φ (X − c) + a(t)` with `φ = τ e_axis`
    /// ([`crate::contact::ToolPath::rotated`]). Its design velocity on the tool is
    /// `V^c = Ω (x^c − p)`, `Ω = [R(θ(t)) e_axis]×`, `p = c + a(t)` (eq 76), with the tangents'
    /// `V^c,α = Ω x^c,α` in the projection sensitivity (eq 80) and the fictitious load `b'_N`
    /// (eq 83). The variable's value is the rotation from the case's tool (0 at the nominal
    /// design); the derivatives are taken there.
    ToolRotation {
        /// Tool name (`[[tool]] name`).
        tool: String,
        /// Axis 0, 1, 2.
        axis: usize,
    },
    /// A design parameter of the named rigid tool's surface (`Surface::design_parameters` of
    /// the tool as built: the radius of a cylinder die, a NURBS control-point coordinate or
    /// weight, …): the tool's shape. Its design velocity on the tool is the surface's
    /// `Surface::design_velocity` at fixed surface parameters `ξ`, moved with the tool:
    /// `V^c = R ∂X/∂p`, `V^c,α = R ∂X,α/∂p` (eq 76; `R` the tool's rotation at the step), which
    /// enter the projection sensitivity (eq 80), the gap (eq 78) and the normal's turn (the
    /// curvature terms of eqs 77 and 83). The variable's value is the offset of the
    /// parameter from the case's tool (0 at the nominal design), so its finite-difference
    /// steps are absolute; the perturbed tool is built by
    /// [`crate::contact::RigidTool::reshaped`].
    ToolShape {
        /// Tool name (`[[tool]] name`).
        tool: String,
        /// Index in the tool surface's `Surface::design_parameters`.
        parameter: usize,
        /// Its name there (`radius`, `cp[2][3].z`, …).
        name: String,
    },
}

/// The axis names of [`DesignKind::Tool`] in case keys (`tool.<name>.x`).
pub const TOOL_AXES: [&str; 3] = ["x", "y", "z"];

/// The axis names of [`DesignKind::ToolRotation`] in case keys (`tool.<name>.rx`).
pub const TOOL_ROTATION_AXES: [&str; 3] = ["rx", "ry", "rz"];

impl DesignKind {
    /// From a case-file key: `thickness`, `material.<name>` with `<name>` one of
    /// [`PARAM_NAMES`], `tool.<name>.<x|y|z>` (translation) or `tool.<name>.<rx|ry|rz>`
    /// (rotation; the tool name is checked against the case's tools by
    /// [`DesignVariable::check`]).
    /// A `shape.<parameter>` or `tool.<name>.shape.<parameter>` key needs its surface
    /// ([`DesignKind::parse_on`], [`DesignKind::parse_with_tools`]).
    pub fn parse(key: &str) -> Result<Self, DesignError> {
        if key == "thickness" {
            return Ok(DesignKind::Thickness);
        }
        if let Some((tool, name)) = split_tool_shape(key) {
            return Err(DesignError::ToolShapeWithoutTool {
                tool: tool.to_string(),
                name: name.to_string(),
            });
        }
        if let Some(rest) = key.strip_prefix("tool.") {
            let parsed = rest.rsplit_once('.').and_then(|(name, ax)| {
                if name.trim().is_empty() {
                    return None;
                }
                let tool = name.to_string();
                if let Some(axis) = TOOL_AXES.iter().position(|a| *a == ax) {
                    return Some(DesignKind::Tool { tool, axis });
                }
                let axis = TOOL_ROTATION_AXES.iter().position(|a| *a == ax)?;
                Some(DesignKind::ToolRotation { tool, axis })
            });
            return parsed.ok_or_else(|| DesignError::UnknownKind {
                key: key.to_string(),
            });
        }
        match key.strip_prefix("material.") {
            Some(name) => Ok(DesignKind::Material(MaterialParameter::from_name(name)?)),
            None => match key.strip_prefix("shape.") {
                Some(name) => Err(DesignError::ShapeWithoutSurface {
                    name: name.to_string(),
                }),
                None => Err(DesignError::UnknownKind {
                    key: key.to_string(),
                }),
            },
        }
    }

    /// As [`DesignKind::parse`], with `shape.<parameter name>` resolved on `surface`
    /// ([`DesignKind::shape`]).
    pub fn parse_on(key: &str, surface: &Surface<f64>) -> Result<Self, DesignError> {
        match key.strip_prefix("shape.") {
            Some(name) => Self::shape(surface, name),
            None => Self::parse(key),
        }
    }

    /// As [`DesignKind::parse_on`], with `tool.<name>.shape.<parameter>` resolved on the
    /// surface of the tool `<name>` among `tools` ([`DesignKind::tool_shape`]).
    pub fn parse_with_tools(
        key: &str,
        surface: &Surface<f64>,
        tools: &[RigidTool],
    ) -> Result<Self, DesignError> {
        match split_tool_shape(key) {
            Some((tool, name)) => {
                let Some(t) = tools.iter().find(|t| t.name == tool) else {
                    return Err(DesignError::UnknownTool {
                        variable: key.to_string(),
                        tool: tool.to_string(),
                        expected: format!(
                            "{:?}",
                            tools.iter().map(|t| t.name.as_str()).collect::<Vec<_>>()
                        ),
                    });
                };
                Self::tool_shape(t, name)
            }
            None => Self::parse_on(key, surface),
        }
    }

    /// The tool-shape design variable of `tool`'s surface parameter `name` (`radius`,
    /// `cp[1][2].z`, …); an unknown name is an error listing the valid ones.
    pub fn tool_shape(tool: &RigidTool, name: &str) -> Result<Self, DesignError> {
        match tool.surface.parameter_index(name) {
            Some(parameter) => Ok(DesignKind::ToolShape {
                tool: tool.name.clone(),
                parameter,
                name: name.to_string(),
            }),
            None => Err(DesignError::UnknownToolShapeParameter {
                tool: tool.name.clone(),
                name: name.to_string(),
                kind: tool.surface.kind(),
                expected: tool.surface.parameter_names().join(", "),
            }),
        }
    }

    /// The shape design variable of `surface`'s design parameter `name` (`radius`,
    /// `centre.z`, `cp[2][3].z`, …); an unknown name is an error listing the valid ones.
    pub fn shape(surface: &Surface<f64>, name: &str) -> Result<Self, DesignError> {
        match surface.parameter_index(name) {
            Some(parameter) => Ok(DesignKind::Shape {
                parameter,
                name: name.to_string(),
            }),
            None => Err(DesignError::UnknownShapeParameter {
                name: name.to_string(),
                kind: surface.kind(),
                expected: surface.parameter_names().join(", "),
            }),
        }
    }

    /// The case-file key of the kind (the inverse of [`DesignKind::parse_on`]): `thickness`,
    /// `material.<name>`, `shape.<surface parameter>`, `tool.<name>.<x|y|z>`,
    /// `tool.<name>.<rx|ry|rz>` or `tool.<name>.shape.<tool surface parameter>`.
    pub fn key(&self) -> String {
        match self {
            DesignKind::Thickness => "thickness".into(),
            DesignKind::Material(p) => format!("material.{}", p.name()),
            DesignKind::Shape { name, .. } => format!("shape.{name}"),
            DesignKind::Tool { tool, axis } => format!("tool.{tool}.{}", TOOL_AXES[*axis.min(&2)]),
            DesignKind::ToolRotation { tool, axis } => {
                format!("tool.{tool}.{}", TOOL_ROTATION_AXES[*axis.min(&2)])
            }
            DesignKind::ToolShape { tool, name, .. } => format!("tool.{tool}.shape.{name}"),
        }
    }

    /// Whether the variable's value is an offset from the case (0 at the nominal design: a
    /// tool translation, rotation or shape parameter), so that its finite-difference steps are
    /// absolute.
    pub fn is_offset(&self) -> bool {
        match self {
            DesignKind::Thickness | DesignKind::Material(_) | DesignKind::Shape { .. } => false,
            DesignKind::Tool { .. }
            | DesignKind::ToolRotation { .. }
            | DesignKind::ToolShape { .. } => true,
        }
    }
}

/// `tool.<name>.shape.<parameter>` split into the tool name and the parameter name (`None`
/// for any other key, or an empty part).
fn split_tool_shape(key: &str) -> Option<(&str, &str)> {
    let (tool, name) = key.strip_prefix("tool.")?.split_once(".shape.")?;
    (!tool.trim().is_empty() && !name.trim().is_empty()).then_some((tool, name))
}

/// A named design variable.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct DesignVariable {
    /// Name (for tables and output).
    pub name: String,
    /// What it changes.
    pub kind: DesignKind,
}

impl DesignVariable {
    /// A design variable.
    pub fn new(name: impl Into<String>, kind: DesignKind) -> Self {
        DesignVariable {
            name: name.into(),
            kind,
        }
    }

    /// The thickness, named `t`.
    pub fn thickness() -> Self {
        Self::new("t", DesignKind::Thickness)
    }

    /// A material parameter, named after it.
    pub fn material(p: MaterialParameter) -> Self {
        Self::new(p.name(), DesignKind::Material(p))
    }

    /// A shape design variable: `surface`'s design parameter `name`, named after it.
    pub fn shape(surface: &Surface<f64>, name: &str) -> Result<Self, DesignError> {
        Ok(Self::new(name, DesignKind::shape(surface, name)?))
    }

    /// A tool translation along `axis` (0, 1, 2), named `<tool>.<x|y|z>`.
    pub fn tool(tool: impl Into<String>, axis: usize) -> Result<Self, DesignError> {
        let tool = tool.into();
        let Some(a) = TOOL_AXES.get(axis) else {
            return Err(DesignError::UnknownKind {
                key: format!("tool.{tool}.<axis {axis}>"),
            });
        };
        let name = format!("{tool}.{a}");
        Ok(Self::new(name, DesignKind::Tool { tool, axis }))
    }

    /// A tool rotation about the global axis `axis` (0, 1, 2) through its pivot, named
    /// `<tool>.<rx|ry|rz>`.
    pub fn tool_rotation(tool: impl Into<String>, axis: usize) -> Result<Self, DesignError> {
        let tool = tool.into();
        let Some(a) = TOOL_ROTATION_AXES.get(axis) else {
            return Err(DesignError::UnknownKind {
                key: format!("tool.{tool}.<rotation axis {axis}>"),
            });
        };
        let name = format!("{tool}.{a}");
        Ok(Self::new(name, DesignKind::ToolRotation { tool, axis }))
    }

    /// A tool-shape design variable: `tool`'s surface parameter `name`, named
    /// `<tool>.<name>` (`die.radius`).
    pub fn tool_shape(tool: &RigidTool, name: &str) -> Result<Self, DesignError> {
        Ok(Self::new(
            format!("{}.{name}", tool.name),
            DesignKind::tool_shape(tool, name)?,
        ))
    }

    /// Its value at `design` (a shape variable of a design without a surface, or with an
    /// index beyond its parameters, is NaN: [`DesignVariable::perturbed`] and
    /// [`DesignVariable::check`] report it as an error).
    pub fn value(&self, design: &Design) -> f64 {
        match &self.kind {
            DesignKind::Thickness => design.thickness,
            DesignKind::Material(p) => design.material.to_array()[p.index()],
            DesignKind::Shape { parameter, .. } => design
                .surface
                .as_ref()
                .and_then(|s| s.parameter_values().get(*parameter).copied())
                .unwrap_or(f64::NAN),
            DesignKind::Tool { tool, axis } => design.tool_offset(tool)[*axis],
            DesignKind::ToolRotation { tool, axis } => design
                .tool_rotation(tool)
                .get(*axis)
                .copied()
                .unwrap_or(f64::NAN),
            DesignKind::ToolShape {
                tool, parameter, ..
            } => design.tool_shape_offset(tool, *parameter),
        }
    }

    /// `design` with this variable moved by `delta`, checked: a thickness must stay > 0 and a
    /// material parameter in its admissible range ([`MaterialParams::validate`]).
    pub fn perturbed(&self, design: &Design, delta: f64) -> Result<Design, DesignError> {
        if !delta.is_finite() {
            return Err(DesignError::InvalidPerturbation {
                variable: self.name.clone(),
                delta,
                detail: "expected a finite perturbation".into(),
            });
        }
        let mut d = design.clone();
        match &self.kind {
            DesignKind::Thickness => {
                d.thickness += delta;
                if !(d.thickness > 0.0 && d.thickness.is_finite()) {
                    return Err(DesignError::InvalidPerturbation {
                        variable: self.name.clone(),
                        delta,
                        detail: format!(
                            "thickness {} + {delta} = {}: expected a finite value > 0",
                            design.thickness, d.thickness
                        ),
                    });
                }
            }
            DesignKind::Material(p) => {
                let mut a = d.material.to_array();
                a[p.index()] += delta;
                d.material = MaterialParams::from_array(a);
                d.material
                    .validate()
                    .map_err(|e| DesignError::InvalidPerturbation {
                        variable: self.name.clone(),
                        delta,
                        detail: e.to_string(),
                    })?;
            }
            DesignKind::Shape { parameter, .. } => {
                let err = |detail: String| DesignError::InvalidPerturbation {
                    variable: self.name.clone(),
                    delta,
                    detail,
                };
                let surface = design.surface.as_ref().ok_or_else(|| {
                    err(
                        "a shape design variable needs the design's surface (Design::surface \
                         is None)"
                            .into(),
                    )
                })?;
                let mut p = surface.parameter_values();
                let count = p.len();
                let slot = p.get_mut(*parameter).ok_or_else(|| {
                    err(format!(
                        "surface parameter index {parameter}: expected an index below {count} \
                         (the {} surface's parameters)",
                        surface.kind()
                    ))
                })?;
                *slot += delta;
                let moved = surface
                    .with_design_parameters::<f64>(&p)
                    .map_err(|e| err(format!("the perturbed surface is invalid: {e}")))?;
                d.surface = Some(moved);
            }
            DesignKind::Tool { tool, axis } => {
                if *axis > 2 {
                    return Err(DesignError::InvalidPerturbation {
                        variable: self.name.clone(),
                        delta,
                        detail: format!("tool axis {axis}: expected 0, 1 or 2 (x, y, z)"),
                    });
                }
                d.tool_offsets.entry(tool.clone()).or_default().translation[*axis] += delta;
            }
            DesignKind::ToolRotation { tool, axis } => {
                if *axis > 2 {
                    return Err(DesignError::InvalidPerturbation {
                        variable: self.name.clone(),
                        delta,
                        detail: format!(
                            "tool rotation axis {axis}: expected 0, 1 or 2 (rx, ry, rz)"
                        ),
                    });
                }
                d.tool_offsets.entry(tool.clone()).or_default().rotation[*axis] += delta;
            }
            DesignKind::ToolShape {
                tool, parameter, ..
            } => {
                // The perturbed tool is checked where it is rebuilt (`RigidTool::reshaped`,
                // before any analysis: `DesignVariable::check` with the tools).
                *d.tool_offsets
                    .entry(tool.clone())
                    .or_default()
                    .shape
                    .entry(*parameter)
                    .or_default() += delta;
            }
        }
        Ok(d)
    }

    /// The one check of a design variable, against what `scope` gives: a tool variable must
    /// name one of `scope.tools`; a shape variable needs the surface of `scope.base`; each
    /// perturbation in `deltas` must give an admissible design at `scope.base`
    /// ([`DesignVariable::perturbed`]), with `scope.model` (built on `scope.base`) a shape
    /// variable's perturbed surface a regular normal at every particle and quadrature point of
    /// the model, and a tool shape's perturbed tool a valid tool
    /// ([`crate::contact::RigidTool::reshaped`]): checked before any analysis, so that no
    /// re-run can fail on a degenerate geometry or tool.
    pub fn check(&self, deltas: &[f64], scope: &DesignScope<'_>) -> Result<(), DesignError> {
        let mut tool = None;
        match &self.kind {
            DesignKind::Tool { tool: name, .. }
            | DesignKind::ToolRotation { tool: name, .. }
            | DesignKind::ToolShape { tool: name, .. } => {
                if let Some(tools) = scope.tools {
                    tool = tools.iter().find(|t| &t.name == name);
                    if tool.is_none() {
                        let names: Vec<&str> = tools.iter().map(|t| t.name.as_str()).collect();
                        return Err(DesignError::UnknownTool {
                            variable: self.name.clone(),
                            tool: name.clone(),
                            expected: format!("{names:?}"),
                        });
                    }
                }
            }
            DesignKind::Shape { name, .. } => {
                if scope.base.is_some_and(|b| b.surface.is_none()) {
                    return Err(DesignError::ShapeWithoutSurface { name: name.clone() });
                }
            }
            DesignKind::Thickness | DesignKind::Material(_) => {}
        }
        let variable = || self.name.clone();
        for &delta in deltas {
            if let Some(base) = scope.base {
                let p = self.perturbed(base, delta)?;
                if let (DesignKind::Shape { .. }, Some(s), Some(model)) =
                    (&self.kind, &p.surface, scope.model)
                {
                    let points = model.points.iter().map(|p| &p.uv);
                    for uv in model.particle_uv.iter().chain(points) {
                        s.eval(uv[0], uv[1]).normal().map_err(|source| {
                            DesignError::DegenerateSurface {
                                variable: variable(),
                                delta,
                                uv: *uv,
                                source: Box::new(source),
                            }
                        })?;
                    }
                }
            }
            if let (DesignKind::ToolShape { parameter, .. }, Some(t)) = (&self.kind, tool) {
                t.reshaped(&[(*parameter, delta)])
                    .map_err(|source| DesignError::InvalidTool {
                        variable: variable(),
                        delta,
                        source: Box::new(source),
                    })?;
            }
        }
        Ok(())
    }
}

/// What design variables are checked against ([`DesignVariable::check`], [`check_design`]);
/// each part given is checked.
#[derive(Clone, Copy, Debug, Default)]
pub struct DesignScope<'a> {
    /// The nominal design, at which the perturbations are checked.
    pub base: Option<&'a Design>,
    /// The model built on `base` (shape variables: the perturbed surface's normals).
    pub model: Option<&'a ShellModel>,
    /// The tools a tool variable may name, as built at `base` (the case's `[[tool]]` tables
    /// or the problem's contact; tool shapes: the perturbed tools).
    pub tools: Option<&'a [RigidTool]>,
}

/// The one check of a list of design variables: at least one, names not empty and unique, no
/// kind listed twice (two columns of the same derivative), and each variable
/// [`DesignVariable::check`]ed with its perturbations `deltas(index)` against `scope`.
pub fn check_design(
    variables: &[DesignVariable],
    deltas: &dyn Fn(usize) -> Vec<f64>,
    scope: &DesignScope<'_>,
) -> Result<(), DesignError> {
    if variables.is_empty() {
        return Err(DesignError::NoVariables);
    }
    for (i, v) in variables.iter().enumerate() {
        if v.name.trim().is_empty() {
            return Err(DesignError::EmptyName { index: i });
        }
        if let Some(w) = variables[..i]
            .iter()
            .find(|w| w.name == v.name || w.kind == v.kind)
        {
            return Err(DesignError::Duplicate {
                first: w.name.clone(),
                second: v.name.clone(),
            });
        }
        v.check(&deltas(i), scope)?;
    }
    Ok(())
}

/// The placement and shape of one rigid tool relative to the case's
/// ([`Design::tool_offsets`]): a translation of its whole path, a rotation of the tool as
/// built about its pivot (`crate::contact::ToolPath::translated`,
/// `crate::contact::ToolPath::rotated`) and offsets of its surface's design parameters
/// (`crate::contact::RigidTool::reshaped`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ToolOffset {
    /// Translation added to the path at every key ([`DesignKind::Tool`]).
    pub translation: [f64; 3],
    /// Rotation vector `φ` (radians, global axes) of the tool as built about its pivot,
    /// before its motion ([`DesignKind::ToolRotation`]).
    pub rotation: [f64; 3],
    /// Offsets added to the tool surface's design parameters, by index in
    /// `Surface::design_parameters` ([`DesignKind::ToolShape`]; absent: zero).
    pub shape: BTreeMap<usize, f64>,
}

/// The design of a shell: thickness, material, (for shape variables) the mid-surface,
/// whose design parameters are `Surface::design_parameters`, and the rigid tools' offsets.
#[derive(Clone, Debug, PartialEq)]
pub struct Design {
    /// Thickness `t`.
    pub thickness: f64,
    /// Material parameters.
    pub material: MaterialParams<f64>,
    /// The mid-surface with its design parameter values (`None`: not a design variable; shape
    /// variables need it).
    pub surface: Option<Surface<f64>>,
    /// Placement of each named tool from the case's: translation of its whole path and
    /// rotation of the tool as built (absent: zero).
    pub tool_offsets: BTreeMap<String, ToolOffset>,
}

impl Design {
    /// The design of `model` (no surface, no tool offsets: the model keeps neither).
    pub fn of(model: &ShellModel) -> Self {
        Design {
            thickness: model.thickness,
            material: model.material,
            surface: None,
            tool_offsets: BTreeMap::new(),
        }
    }

    /// The design of `model` built on `surface`.
    pub fn of_shell(model: &ShellModel, surface: &Surface<f64>) -> Self {
        Design {
            surface: Some(surface.clone()),
            ..Self::of(model)
        }
    }

    /// The translation offset of tool `name` (zero when not set).
    pub fn tool_offset(&self, name: &str) -> [f64; 3] {
        self.tool_offsets
            .get(name)
            .map_or([0.0; 3], |o| o.translation)
    }

    /// The rotation vector of tool `name` as built (zero when not set).
    pub fn tool_rotation(&self, name: &str) -> [f64; 3] {
        self.tool_offsets.get(name).map_or([0.0; 3], |o| o.rotation)
    }

    /// The offset of tool `name`'s surface design parameter `parameter` (zero when not set).
    pub fn tool_shape_offset(&self, name: &str, parameter: usize) -> f64 {
        self.tool_offsets
            .get(name)
            .and_then(|o| o.shape.get(&parameter).copied())
            .unwrap_or(0.0)
    }
}

/// The monitors' values at the committed state of `problem` (pseudo-time `load`) and their
/// derivatives from a method's committed sensitivities `fields`: a displacement or a position
/// functional from the displacement sensitivities `ū̇_J`, a plastic strain from `ė^p`, a tool
/// force from the method's derivative of the forces on the tools (asked for only when a
/// monitor needs it): `(values[m], derivatives[m][v])`.
pub fn record_monitors(
    problem: &ShellProblem,
    load: f64,
    monitors: &[Monitor],
    fields: &dyn SensitivityFields,
) -> Result<(Vec<f64>, Vec<Vec<f64>>), MonitorError> {
    let model = &problem.model;
    let nv = fields.n_variables();
    let udot: Vec<Vec<f64>> = (0..nv).map(|v| fields.translations(model, v)).collect();
    let mut values = Vec::with_capacity(monitors.len());
    let mut derivatives = vec![vec![0.0; nv]; monitors.len()];
    let mut tools: Option<Vec<Vec<[f64; 3]>>> = None;
    let mut plastic: Option<Vec<Vec<f64>>> = None;
    let mut forces = None;
    for (mi, m) in monitors.iter().enumerate() {
        values.push(m.value_with(problem, load, &mut forces)?);
        let model_err = |source| MonitorError::Model {
            label: m.label.clone(),
            source,
        };
        let missing = |what: &str, variable| MonitorError::NoDerivative {
            label: m.label.clone(),
            what: what.to_string(),
            variable,
        };
        match &m.quantity {
            Quantity::Displacement { uv, component } => {
                for (v, ud) in udot.iter().enumerate() {
                    derivatives[mi][v] =
                        model.interpolate_translation(*uv, ud).map_err(model_err)?[*component];
                }
            }
            q @ (Quantity::ChordAngle { .. } | Quantity::TargetDistance { .. }) => {
                let pts = q.functional_points();
                let u: Vec<Vector3<f64>> = pts
                    .iter()
                    .map(|uv| model.displacement_at(*uv))
                    .collect::<Result<_, _>>()
                    .map_err(model_err)?;
                for (v, ud) in udot.iter().enumerate() {
                    let seeded: Vec<Vector3<crate::scalar::Dual>> = pts
                        .iter()
                        .zip(&u)
                        .map(|(uv, ui)| {
                            let d = model.interpolate_translation(*uv, ud)?;
                            Ok(ui.zip_map(&d, crate::scalar::Dual::new))
                        })
                        .collect::<Result<_, ShellError>>()
                        .map_err(model_err)?;
                    derivatives[mi][v] = m.functional(&seeded)?.eps;
                }
            }
            Quantity::PlasticStrain {
                region,
                layers,
                rho,
            } => {
                let idx = layer_points(model, region, *layers);
                let dots = plastic
                    .get_or_insert_with(|| (0..nv).map(|v| fields.plastic_strain(v)).collect());
                for (v, d) in derivatives[mi].iter_mut().enumerate() {
                    let ev = dots
                        .get(v)
                        .ok_or_else(|| missing("plastic strain rates", v))?;
                    let x: Vec<crate::scalar::Dual> = idx
                        .iter()
                        .map(|&k| crate::scalar::Dual::new(model.history[k].material.eps_p, ev[k]))
                        .collect();
                    *d = smooth_max(&x, *rho).eps;
                }
            }
            Quantity::Thinning { region, rho } => {
                let idx = m.region_points(model, region)?;
                for (v, ud) in udot.iter().enumerate() {
                    let x: Vec<crate::scalar::Dual> = idx
                        .iter()
                        .map(|&i| {
                            thinning_strain(model, i, |j| {
                                let u = model.particle_state(j).u;
                                u.zip_map(&model.translation_in(j, ud), crate::scalar::Dual::new)
                            })
                        })
                        .collect();
                    derivatives[mi][v] = smooth_max(&x, *rho).eps;
                }
            }
            Quantity::ToolForce { tool, component } => {
                let i = m.tool_index(problem, tool)?;
                if tools.is_none() {
                    let dots = fields.tool_force_dots(problem, load).map_err(|e| {
                        MonitorError::ToolRates {
                            label: m.label.clone(),
                            source: Box::new(e),
                        }
                    })?;
                    tools = Some(dots);
                }
                let dots = tools.as_deref().unwrap_or_default();
                for (v, d) in derivatives[mi].iter_mut().enumerate() {
                    *d = dots
                        .get(v)
                        .and_then(|per_tool| per_tool.get(i))
                        .ok_or_else(|| missing(&format!("force derivative of tool `{tool}`"), v))?
                        [*component];
                }
            }
        }
    }
    Ok((values, derivatives))
}

/// What a monitor measures.
#[derive(Clone, Debug, PartialEq)]
pub enum Quantity {
    /// A component (0, 1, 2: x, y, z) of the RK-interpolated mid-surface displacement
    /// `Σ Ψ_J ū_J` at parameter coordinates `uv` ([`ShellModel::displacement_at`]).
    Displacement {
        /// Parameter coordinates.
        uv: [f64; 2],
        /// Component 0, 1, 2 (x, y, z).
        component: usize,
    },
    /// A component (0, 1, 2: x, y, z) of the force the sheet exerts on the named tool
    /// ([`crate::shell::contact::ShellContact::tool_forces_with`], eq 70 summed over the tool's
    /// active slave points): the punch or die force of a forming process.
    ToolForce {
        /// The tool's name.
        tool: String,
        /// Component 0, 1, 2 (x, y, z).
        component: usize,
    },
    /// The angle in degrees, in the plane of the global axes `plane = [i, j]`, of the chord
    /// from the sheet's point at `from` to its point at `to` (parameter coordinates) in the
    /// current configuration: `atan2(Δ_j, Δ_i)` with `Δ = (X⁰_to + u_to) − (X⁰_from + u_from)`
    /// ([`position_functional`]). The springback angle of a bent flange is its change from the
    /// loaded to the released state (two steps of the same monitor).
    ChordAngle {
        /// Parameter coordinates of the chord's start and end.
        points: [[f64; 2]; 2],
        /// Their initial positions `X⁰` (from the case's surface).
        initial: [[f64; 3]; 2],
        /// The plane's axes `[i, j]` (0, 1, 2: x, y, z), `i ≠ j`.
        plane: [usize; 2],
    },
    /// The mean squared distance of sheet points from their targets,
    /// `(1/n) Σ_k |X⁰_k + u_k − x*_k|²` (least squares; the shape deviation from a target
    /// surface sampled at the points) ([`position_functional`]).
    TargetDistance {
        /// Parameter coordinates of the points.
        points: Vec<[f64; 2]>,
        /// Their initial positions `X⁰` (from the case's surface).
        initial: Vec<[f64; 3]>,
        /// Their target positions `x*`.
        targets: Vec<[f64; 3]>,
    },
    /// A smooth maximum of the equivalent plastic strain `ē^p` over the layer points whose
    /// quadrature point lies in the parameter box `region` (on the selected `layers`):
    /// `(1/ρ) ln((1/N) Σ_k exp(ρ ē^p_k))` ([`smooth_max`]), between the mean (ρ → 0) and the
    /// maximum (ρ → ∞), below the maximum by at most `ln(N)/ρ`, zero while nothing yields,
    /// differentiable everywhere. A small box gives the strain at a point.
    PlasticStrain {
        /// `[[u_min, u_max], [v_min, v_max]]`.
        region: [[f64; 2]; 2],
        /// The layers read.
        layers: Layers,
        /// The aggregation parameter `ρ` (> 0, 1/strain).
        rho: f64,
    },
    /// The thinning strain of the mid-surface, `ln(da/dA) = ln(|x,1 × x,2| / |X,1 × X,2|)`
    /// with `x,α = X,α + Σ_J Ψ_J,α ū_J` ([`thinning_strain`]), at the quadrature points in a
    /// parameter box, aggregated by the smooth maximum `(1/ρ) ln((1/N) Σ_k exp(ρ x_k))`
    /// ([`smooth_max`]): the peak thinning of a formed sheet. Under plastic incompressibility
    /// with the elastic volume change neglected (the sheet-forming convention), `t/t⁰ = dA/da`,
    /// so the thinning strain is the negative thickness strain `−ln(t/t⁰)`; positive where
    /// the sheet thins. It reads the initial geometry `X,α`, which a shape variable moves.
    Thinning {
        /// Parameter box `[[u_min, u_max], [v_min, v_max]]`.
        region: [[f64; 2]; 2],
        /// Aggregation parameter `ρ > 0`.
        rho: f64,
    },
}

/// The quadrature points (indices into `ShellModel::points`) in a parameter box.
pub fn region_points(model: &ShellModel, region: &[[f64; 2]; 2]) -> Vec<usize> {
    (0..model.points.len())
        .filter(|&i| {
            let uv = model.points[i].uv;
            (0..2).all(|k| uv[k] >= region[k][0] && uv[k] <= region[k][1])
        })
        .collect()
}

/// The thinning strain `ln(|x,1 × x,2| / |X,1 × X,2|)` of the mid-surface at quadrature point
/// `i` ([`Quantity::Thinning`]), with `x,α = X,α + Σ_J Ψ_J,α ū_J` from the translations
/// `u(J)` of its shape-function particles, generic over the scalar: f64 committed
/// translations give the value, `Dual64` ones `ū + ε ū̇` its derivative.
pub fn thinning_strain<T: crate::scalar::Real>(
    model: &ShellModel,
    i: usize,
    u: impl Fn(usize) -> Vector3<T>,
) -> T {
    let p = &model.points[i];
    let mut xa = p.surface.x_a.map(|x| x.map(T::cst));
    for (&j, s) in p.neighbours.iter().zip(&p.shape) {
        let uj = u(j);
        for (a, x) in xa.iter_mut().enumerate() {
            *x += uj * T::cst(s.dpsi[a]);
        }
    }
    let da0 = p.surface.x_a[0].cross(&p.surface.x_a[1]).norm();
    (xa[0].cross(&xa[1]).norm() / da0).ln()
}

/// `(1/ρ) ln((1/N) Σ_k exp(ρ x_k))`, evaluated with the largest value factored out, generic
/// over the scalar (its dual part is the softmax-weighted mean of the `x_k`'s).
pub fn smooth_max<T: crate::scalar::Real>(x: &[T], rho: f64) -> T {
    let m = x
        .iter()
        .map(|v| v.value())
        .fold(f64::NEG_INFINITY, f64::max);
    if x.is_empty() || !m.is_finite() {
        return T::zero();
    }
    let mut sum = T::zero();
    for v in x {
        sum += ((*v - m) * rho).exp();
    }
    (sum / (x.len() as f64)).ln() / rho + m
}

/// The layer points (indices into `ShellModel::history`) a [`Quantity::PlasticStrain`] reads.
pub fn layer_points(model: &ShellModel, region: &[[f64; 2]; 2], layers: Layers) -> Vec<usize> {
    let nl = model.thickness_rule.len();
    let zetas: Vec<f64> = model.thickness_rule.iter().map(|(z, _)| *z).collect();
    let top = zetas.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let bottom = zetas.iter().copied().fold(f64::INFINITY, f64::min);
    let keep = |l: usize| match layers {
        Layers::All => true,
        Layers::Top => zetas[l] == top,
        Layers::Bottom => zetas[l] == bottom,
    };
    region_points(model, region)
        .into_iter()
        .flat_map(|i| (0..nl).filter(|l| keep(*l)).map(move |l| i * nl + l))
        .collect()
}

/// Which layers through the thickness a [`Quantity::PlasticStrain`] reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layers {
    /// Every layer point.
    All,
    /// The layer of largest `ζ` (the side the normal `n⁰` points to).
    Top,
    /// The layer of smallest `ζ`.
    Bottom,
}

impl Quantity {
    /// The parameter points whose displacements a position functional reads (empty for a
    /// displacement or a tool force).
    pub fn functional_points(&self) -> &[[f64; 2]] {
        match self {
            Quantity::ChordAngle { points, .. } => points,
            Quantity::TargetDistance { points, .. } => points,
            Quantity::Displacement { .. }
            | Quantity::ToolForce { .. }
            | Quantity::PlasticStrain { .. }
            | Quantity::Thinning { .. } => &[],
        }
    }

    /// Whether the response reads the initial geometry (the initial positions of a position
    /// functional, the initial tangents of the thinning strain), which a shape design variable
    /// moves and whose design velocity these responses do not carry.
    pub fn reads_initial_geometry(&self) -> bool {
        matches!(
            self,
            Quantity::ChordAngle { .. }
                | Quantity::TargetDistance { .. }
                | Quantity::Thinning { .. }
        )
    }
}

/// A position functional's value from the displacements `u` at its
/// [`Quantity::functional_points`], generic over the scalar: in `f64` the response, with
/// `Dual64` displacements `u + ε u̇` its derivative (one formula for the value, the continuum
/// and dual derivatives, and the re-runs of the finite differences). `None` for a quantity
/// that is not a position functional.
pub fn position_functional<T: crate::scalar::Real>(q: &Quantity, u: &[Vector3<T>]) -> Option<T> {
    let pos = |x0: &[f64; 3], u: &Vector3<T>| {
        Vector3::new(T::cst(x0[0]), T::cst(x0[1]), T::cst(x0[2])) + u
    };
    match q {
        Quantity::ChordAngle { initial, plane, .. } => {
            let d = pos(&initial[1], &u[1]) - pos(&initial[0], &u[0]);
            Some(d[plane[1]].atan2(d[plane[0]]) * (180.0 / std::f64::consts::PI))
        }
        Quantity::TargetDistance {
            initial, targets, ..
        } => {
            let mut sum = T::zero();
            for ((x0, t), uk) in initial.iter().zip(targets).zip(u) {
                let r = pos(x0, uk) - Vector3::new(T::cst(t[0]), T::cst(t[1]), T::cst(t[2]));
                sum += r.dot(&r);
            }
            Some(sum / (initial.len().max(1) as f64))
        }
        Quantity::Displacement { .. }
        | Quantity::ToolForce { .. }
        | Quantity::PlasticStrain { .. }
        | Quantity::Thinning { .. } => None,
    }
}

/// A monitored response ([`Quantity`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Monitor {
    /// Label (for tables and output).
    pub label: String,
    /// What it measures.
    pub quantity: Quantity,
}

impl Monitor {
    /// A displacement monitor, checked: `component` in 0..3, `uv` finite.
    pub fn new(
        label: impl Into<String>,
        uv: [f64; 2],
        component: usize,
    ) -> Result<Self, DesignError> {
        let label = label.into();
        if component > 2 || !uv.iter().all(|v| v.is_finite()) {
            return Err(DesignError::InvalidMonitor {
                label,
                detail: format!(
                    "uv = {uv:?}, component = {component}: expected finite coordinates and a \
                     component in 0..3"
                ),
            });
        }
        Ok(Monitor {
            label,
            quantity: Quantity::Displacement { uv, component },
        })
    }

    /// A monitor of the force on the tool `tool`, checked: `component` in 0..3 (the tool's
    /// existence is checked against the problem by the methods).
    pub fn tool_force(
        label: impl Into<String>,
        tool: impl Into<String>,
        component: usize,
    ) -> Result<Self, DesignError> {
        let label = label.into();
        if component > 2 {
            return Err(DesignError::InvalidMonitor {
                label,
                detail: format!("component = {component}: expected a component in 0..3"),
            });
        }
        Ok(Monitor {
            label,
            quantity: Quantity::ToolForce {
                tool: tool.into(),
                component,
            },
        })
    }

    /// A chord-angle monitor ([`Quantity::ChordAngle`]), checked: finite coordinates, two
    /// different axes in 0..3, a chord of non-zero length in the plane at the initial state.
    pub fn chord_angle(
        label: impl Into<String>,
        points: [[f64; 2]; 2],
        initial: [[f64; 3]; 2],
        plane: [usize; 2],
    ) -> Result<Self, DesignError> {
        let label = label.into();
        let finite = points
            .iter()
            .flatten()
            .chain(initial.iter().flatten())
            .all(|v| v.is_finite());
        let d = [0, 1].map(|k| initial[1][plane[k].min(2)] - initial[0][plane[k].min(2)]);
        if !finite
            || plane[0] > 2
            || plane[1] > 2
            || plane[0] == plane[1]
            || d[0].hypot(d[1]) == 0.0
        {
            return Err(DesignError::InvalidMonitor {
                label,
                detail: format!(
                    "points {points:?} at {initial:?}, plane axes {plane:?}: expected finite \
                     coordinates, two different axes of x, y, z and two points apart in that \
                     plane"
                ),
            });
        }
        Ok(Monitor {
            label,
            quantity: Quantity::ChordAngle {
                points,
                initial,
                plane,
            },
        })
    }

    /// A target-distance monitor ([`Quantity::TargetDistance`]), checked: at least one point,
    /// as many targets as points, finite coordinates.
    pub fn target_distance(
        label: impl Into<String>,
        points: Vec<[f64; 2]>,
        initial: Vec<[f64; 3]>,
        targets: Vec<[f64; 3]>,
    ) -> Result<Self, DesignError> {
        let label = label.into();
        let finite = points.iter().flatten().all(|v| v.is_finite())
            && initial
                .iter()
                .chain(&targets)
                .flatten()
                .all(|v| v.is_finite());
        if points.is_empty()
            || points.len() != targets.len()
            || points.len() != initial.len()
            || !finite
        {
            return Err(DesignError::InvalidMonitor {
                label,
                detail: format!(
                    "{} point(s), {} target(s): expected at least one point, one target per \
                     point, finite coordinates",
                    points.len(),
                    targets.len()
                ),
            });
        }
        Ok(Monitor {
            label,
            quantity: Quantity::TargetDistance {
                points,
                initial,
                targets,
            },
        })
    }

    /// A plastic-strain monitor ([`Quantity::PlasticStrain`]), checked: a finite box with
    /// `min ≤ max` on both axes, `ρ` finite and > 0.
    pub fn plastic_strain(
        label: impl Into<String>,
        region: [[f64; 2]; 2],
        layers: Layers,
        rho: f64,
    ) -> Result<Self, DesignError> {
        Self::aggregate(
            label.into(),
            region,
            rho,
            Quantity::PlasticStrain {
                region,
                layers,
                rho,
            },
        )
    }

    /// A thinning-strain monitor ([`Quantity::Thinning`]), checked as
    /// [`Monitor::plastic_strain`].
    pub fn thinning(
        label: impl Into<String>,
        region: [[f64; 2]; 2],
        rho: f64,
    ) -> Result<Self, DesignError> {
        Self::aggregate(
            label.into(),
            region,
            rho,
            Quantity::Thinning { region, rho },
        )
    }

    /// A smooth maximum over a parameter box, checked: a finite box with `min ≤ max` on both
    /// axes, `ρ` finite and > 0.
    fn aggregate(
        label: String,
        region: [[f64; 2]; 2],
        rho: f64,
        quantity: Quantity,
    ) -> Result<Self, DesignError> {
        let ok = region
            .iter()
            .all(|r| r[0].is_finite() && r[1].is_finite() && r[0] <= r[1])
            && rho.is_finite()
            && rho > 0.0;
        if !ok {
            return Err(DesignError::InvalidMonitor {
                label,
                detail: format!(
                    "region {region:?}, rho = {rho}: expected finite [min, max] ranges with \
                     min <= max and rho > 0"
                ),
            });
        }
        Ok(Monitor { label, quantity })
    }

    /// The quadrature points in `region` ([`region_points`]), none an error.
    fn region_points(
        &self,
        model: &ShellModel,
        region: &[[f64; 2]; 2],
    ) -> Result<Vec<usize>, MonitorError> {
        let idx = region_points(model, region);
        if idx.is_empty() {
            return Err(self.empty_region(region));
        }
        Ok(idx)
    }

    /// The error of a region without quadrature points.
    fn empty_region(&self, region: &[[f64; 2]; 2]) -> MonitorError {
        MonitorError::EmptyRegion {
            label: self.label.clone(),
            region: *region,
        }
    }

    /// The index of the tool `name` in the problem's contact load.
    fn tool_index(&self, problem: &ShellProblem, name: &str) -> Result<usize, MonitorError> {
        let (label, tool) = (self.label.clone(), name.to_string());
        let Some(contact) = contact_load(problem) else {
            return Err(MonitorError::NoContact { label, tool });
        };
        let names = contact.contact.tools().iter().map(|t| t.name.as_str());
        names
            .clone()
            .position(|n| n == name)
            .ok_or_else(|| MonitorError::UnknownTool {
                label,
                tool,
                expected: names.map(str::to_string).collect(),
            })
    }

    /// The value of a position functional ([`position_functional`]) from the displacements
    /// `u` at its points.
    fn functional<T: crate::scalar::Real>(&self, u: &[Vector3<T>]) -> Result<T, MonitorError> {
        position_functional(&self.quantity, u).ok_or_else(|| MonitorError::NotAFunctional {
            label: self.label.clone(),
        })
    }

    /// Its committed value in `problem` at pseudo-time `load` (the load factor of the
    /// converged step: the tools' position along their paths). Several monitors:
    /// [`monitor_values`], which evaluates the contact once for all tool forces.
    pub fn value(&self, problem: &ShellProblem, load: f64) -> Result<f64, MonitorError> {
        self.value_with(problem, load, &mut None)
    }

    /// [`Self::value`], with the forces on the tools (`[tool][component]`) computed into
    /// `tools` when first needed and reused after.
    fn value_with(
        &self,
        problem: &ShellProblem,
        load: f64,
        tools: &mut Option<Vec<[f64; 3]>>,
    ) -> Result<f64, MonitorError> {
        let model = &problem.model;
        let model_err = |source| MonitorError::Model {
            label: self.label.clone(),
            source,
        };
        match &self.quantity {
            Quantity::Displacement { uv, component } => {
                Ok(model.displacement_at(*uv).map_err(model_err)?[*component])
            }
            q @ (Quantity::ChordAngle { .. } | Quantity::TargetDistance { .. }) => {
                let u: Vec<Vector3<f64>> = q
                    .functional_points()
                    .iter()
                    .map(|uv| model.displacement_at(*uv))
                    .collect::<Result<_, _>>()
                    .map_err(model_err)?;
                self.functional(&u)
            }
            Quantity::PlasticStrain {
                region,
                layers,
                rho,
            } => {
                let x: Vec<f64> = layer_points(model, region, *layers)
                    .into_iter()
                    .map(|k| model.history[k].material.eps_p)
                    .collect();
                if x.is_empty() {
                    return Err(self.empty_region(region));
                }
                Ok(smooth_max(&x, *rho))
            }
            Quantity::Thinning { region, rho } => {
                let x: Vec<f64> = self
                    .region_points(model, region)?
                    .into_iter()
                    .map(|i| thinning_strain(model, i, |j| model.particle_state(j).u))
                    .collect();
                Ok(smooth_max(&x, *rho))
            }
            Quantity::ToolForce { tool, component } => {
                let i = self.tool_index(problem, tool)?;
                if tools.is_none() {
                    *tools = Some(tool_forces(problem, load).map_err(model_err)?);
                }
                Ok(tools.as_deref().unwrap_or_default()[i][*component])
            }
        }
    }
}

/// The problem's (first) contact load, the one the methods carry.
pub(crate) fn contact_load(problem: &ShellProblem) -> Option<&ContactLoad> {
    problem.loads().iter().find_map(|l| l.contact())
}

/// The tools of [`contact_load`], none without one.
pub(crate) fn contact_tools(problem: &ShellProblem) -> &[RigidTool] {
    contact_load(problem).map_or(&[], |c| c.contact.tools())
}

/// The committed values of `monitors` in `problem` at pseudo-time `load` (the contact
/// evaluated once for all tool-force monitors).
pub fn monitor_values(
    problem: &ShellProblem,
    load: f64,
    monitors: &[Monitor],
) -> Result<Vec<f64>, MonitorError> {
    let mut tools = None;
    monitors
        .iter()
        .map(|m| m.value_with(problem, load, &mut tools))
        .collect()
}

/// The forces the sheet exerts on the tools of the problem's contact at its committed state
/// and pseudo-time `load` (`[tool][component]`, empty without contact).
fn tool_forces(problem: &ShellProblem, load: f64) -> Result<Vec<[f64; 3]>, ShellError> {
    let model = &problem.model;
    match contact_load(problem) {
        None => Ok(Vec::new()),
        Some(c) => Ok(c
            .contact
            .report(model, &vec![0.0; model.n_dofs()], load)?
            .tools
            .iter()
            .map(|t| t.force)
            .collect()),
    }
}

/// Why a monitor could not be evaluated or differentiated. Each names the monitor.
#[derive(Debug, Error)]
pub enum MonitorError {
    /// No quadrature point (or layer point) in the monitor's parameter box.
    #[error(
        "monitor `{label}`: no quadrature point in the region {region:?}: expected a parameter \
         box containing at least one"
    )]
    EmptyRegion {
        /// Monitor label.
        label: String,
        /// `[[u_min, u_max], [v_min, v_max]]`.
        region: [[f64; 2]; 2],
    },
    /// The force on a tool of a problem without contact.
    #[error(
        "monitor `{label}`: the force on tool `{tool}`: the problem has no contact (expected a \
         case with [[tool]] tables)"
    )]
    NoContact {
        /// Monitor label.
        label: String,
        /// The tool named.
        tool: String,
    },
    /// The force on a tool the contact does not have.
    #[error("monitor `{label}`: the force on tool `{tool}`: no such tool (expected one of {expected:?})")]
    UnknownTool {
        /// Monitor label.
        label: String,
        /// The tool named.
        tool: String,
        /// The contact's tools.
        expected: Vec<String>,
    },
    /// A position functional's formula asked of another quantity.
    #[error("monitor `{label}`: not a position functional")]
    NotAFunctional {
        /// Monitor label.
        label: String,
    },
    /// A method's sensitivities lack a rate the monitor's derivative needs.
    #[error("monitor `{label}`: no {what} for design variable {variable}")]
    NoDerivative {
        /// Monitor label.
        label: String,
        /// The rate missing.
        what: String,
        /// The design variable's index.
        variable: usize,
    },
    /// Evaluating the model (an interpolation, the contact's report).
    #[error("monitor `{label}`: {source}")]
    Model {
        /// Monitor label.
        label: String,
        /// Why.
        #[source]
        source: ShellError,
    },
    /// The method's derivatives of the forces on the tools.
    #[error("monitor `{label}`: the derivatives of the forces on the tools: {source}")]
    ToolRates {
        /// Monitor label.
        label: String,
        /// Why.
        #[source]
        source: Box<dual::SensitivityError>,
    },
}

/// Errors of design variables and sensitivity runs. Each names the variable or field concerned.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum DesignError {
    /// No design variable given.
    #[error("design variables: none given, expected at least one")]
    NoVariables,
    /// A variable without a name.
    #[error("design variable {index}: empty name")]
    EmptyName {
        /// Position in the list.
        index: usize,
    },
    /// Two variables with the same name or kind.
    #[error(
        "design variables `{first}` and `{second}`: same name or same kind, expected distinct"
    )]
    Duplicate {
        /// The first.
        first: String,
        /// The repeated one.
        second: String,
    },
    /// A key that is no design-variable kind.
    #[error(
        "design variable kind `{key}`: expected `thickness`, `material.<parameter>`, \
         `shape.<surface parameter>`, `tool.<name>.<x|y|z|rx|ry|rz>` (a tool's translation \
         or rotation) or `tool.<name>.shape.<surface parameter>` (a tool's shape)"
    )]
    UnknownKind {
        /// The key given.
        key: String,
    },
    /// A shape design variable of a surface that does not have the parameter.
    #[error("shape design variable `shape.{name}`: the {kind} surface has no parameter `{name}`, expected one of {expected}")]
    UnknownShapeParameter {
        /// The name given.
        name: String,
        /// Surface kind.
        kind: &'static str,
        /// The admissible names.
        expected: String,
    },
    /// A tool-shape design variable of a surface that does not have the parameter.
    #[error("tool-shape design variable `tool.{tool}.shape.{name}`: the tool's {kind} surface has no parameter `{name}`, expected one of {expected}")]
    UnknownToolShapeParameter {
        /// Tool name.
        tool: String,
        /// The name given.
        name: String,
        /// Surface kind.
        kind: &'static str,
        /// The admissible names.
        expected: String,
    },
    /// A tool-shape design variable parsed without the case's tools.
    #[error("tool-shape design variable `tool.{tool}.shape.{name}`: needs the case's tools (use DesignKind::parse_with_tools)")]
    ToolShapeWithoutTool {
        /// Tool name.
        tool: String,
        /// The parameter name.
        name: String,
    },
    /// A shape design variable checked without the surface it belongs to.
    #[error("shape design variable `shape.{name}`: needs the shell's surface (use DesignKind::parse_on, Design::of_shell)")]
    ShapeWithoutSurface {
        /// The parameter name.
        name: String,
    },
    /// A tool variable naming no tool of the case.
    #[error("design variable `{variable}`: tool `{tool}` is unknown, expected one of {expected}")]
    UnknownTool {
        /// Variable name.
        variable: String,
        /// The tool name given.
        tool: String,
        /// The case's tool names.
        expected: String,
    },
    /// An unknown material parameter.
    #[error("material parameter `{name}`: unknown, expected one of {expected}")]
    UnknownParameter {
        /// The name given.
        name: String,
        /// The admissible names.
        expected: String,
    },
    /// A perturbation that leaves the admissible design.
    #[error("design variable `{variable}` perturbed by {delta}: {detail}")]
    InvalidPerturbation {
        /// Variable name.
        variable: String,
        /// The perturbation.
        delta: f64,
        /// What is violated.
        detail: String,
    },
    /// A shape perturbation whose surface has no regular normal at a point of the model.
    #[error(
        "design variable `{variable}` perturbed by {delta}: the perturbed surface at (u, v) = \
         {uv:?}: {source}"
    )]
    DegenerateSurface {
        /// Variable name.
        variable: String,
        /// The perturbation.
        delta: f64,
        /// The point's parameter coordinates.
        uv: [f64; 2],
        /// Why the normal is undefined.
        #[source]
        source: Box<crate::geometry::GeometryError>,
    },
    /// A tool-shape perturbation that leaves no valid tool
    /// ([`crate::contact::RigidTool::reshaped`]).
    #[error("design variable `{variable}` perturbed by {delta}: {source}")]
    InvalidTool {
        /// Variable name.
        variable: String,
        /// The perturbation.
        delta: f64,
        /// Why the tool is invalid.
        #[source]
        source: Box<crate::contact::ContactError>,
    },
    /// A monitor that cannot be evaluated.
    #[error("monitor `{label}`: {detail}")]
    InvalidMonitor {
        /// Monitor label.
        label: String,
        /// What is wrong.
        detail: String,
    },
    /// Material validation.
    #[error(transparent)]
    Material(#[from] MaterialError),
    /// A method that does not support the variable's kind.
    #[error("design variable `{name}`: the {method} method does not support its kind yet")]
    Unsupported {
        /// Variable name.
        name: String,
        /// Method (`continuum`, `dual`, ...).
        method: &'static str,
    },
}

/// The analysis a derivative method observes: the problem, the surface its model was built
/// on (`None` admits no shape variables), the design variables, the monitored responses, and
/// the Newton driver with the linear solver's options.
#[derive(Debug)]
pub struct DsaAnalysis<'a> {
    /// The problem at its initial state.
    pub problem: crate::shell::problem::ShellProblem,
    /// The surface the model was built on (needed by shape variables).
    pub surface: Option<&'a Surface<f64>>,
    /// The design variables.
    pub variables: Vec<DesignVariable>,
    /// The responses whose derivatives are recorded.
    pub monitors: Vec<Monitor>,
    /// The driver of the analysis.
    pub newton: &'a crate::solver::NewtonSolver,
    /// The linear solver's options.
    pub solver: crate::solver::SolverOptions,
}

impl DsaAnalysis<'_> {
    /// The problem's sparsity pattern and a linear solver for it (the method for its size,
    /// [`crate::solver::Method::auto`], with the analysis' options; symbolic analysis done).
    pub(crate) fn linear_solver(
        &self,
    ) -> Result<
        (crate::solver::SparsityPattern, crate::solver::LinearSolver),
        crate::solver::SolverError,
    > {
        let pattern = self.problem.pattern().clone();
        let method = crate::solver::Method::auto(&pattern);
        let linear = crate::solver::LinearSolver::new(&pattern, method, self.solver)?;
        Ok((pattern, linear))
    }
}

/// Which derivative methods observe a hooked run ([`run_hooked`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HookedMethods {
    /// The continuum (hand-derived) DSA.
    pub continuum: bool,
    /// The dual-number reference, with its scalar ([`dual::DualMode`]).
    pub dual: Option<dual::DualMode>,
    /// Where the continuum DSA runs. With the dual reference in the same run it runs in the
    /// hook whatever this says ([`continuum::ContinuumSchedule::Synchronous`]): the dual
    /// reference needs the converged tangent factorised by the analysis' driver, which the
    /// continuum then uses as well.
    pub schedule: continuum::ContinuumSchedule,
    /// How the continuum DSA in the hook solves its sensitivity systems. With the dual
    /// reference in the same run it uses the factorised converged tangent whatever this says
    /// (the dual reference needs it).
    pub solve: continuum::SensitivitySolve,
}

/// The records of a hooked run so far, seen after every converged step.
#[derive(Clone, Copy, Debug)]
pub struct HookedRecords<'a> {
    /// The continuum DSA's steps, when it runs.
    pub continuum: Option<&'a [continuum::ContinuumStepRecord]>,
    /// The dual reference's steps, when it runs.
    pub dual: Option<&'a [dual::DualStepRecord]>,
    /// The analysis' model at the committed step.
    pub model: &'a ShellModel,
    /// The continuum DSA's committed sensitivities, when it runs.
    pub continuum_fields: Option<&'a dyn SensitivityFields>,
    /// The dual reference's committed sensitivities (derivative parts), when it runs.
    pub dual_fields: Option<&'a dyn SensitivityFields>,
}

/// A method's committed sensitivities at the last converged step, read per design variable as
/// f64 fields parallel to the model's state (for output: the VTU of a step).
pub trait SensitivityFields: std::fmt::Debug {
    /// Number of design variables.
    fn n_variables(&self) -> usize;
    /// `ⁿū̇_I` of the real particles for variable `v` as a generalised vector of `model`
    /// (translations set, the other DOFs 0): with
    /// [`ShellModel::interpolate_translation`] it gives the displacement sensitivity
    /// `Σ Ψ_J ū̇_J` at any parameter point, the derivative a [`Monitor`] records.
    fn translations(&self, model: &ShellModel, v: usize) -> Vec<f64>;
    /// `ⁿė^p` of every layer point for variable `v`, point-major as `ShellModel::history`.
    fn plastic_strain(&self, v: usize) -> Vec<f64>;
    /// The derivatives of the forces the sheet exerts on the tools of `problem`'s contact at
    /// its committed state and pseudo-time `load`, `[variable][tool]` (no tools without
    /// contact).
    fn tool_force_dots(
        &self,
        problem: &ShellProblem,
        load: f64,
    ) -> Result<Vec<Vec<[f64; 3]>>, dual::SensitivityError>;
}

/// One analysis of `problem` observed by the derivative methods of `methods`: the continuum
/// DSA and the dual-number reference (each optional; with both, one run instead of one each,
/// the continuum's hooks first). The methods share the analysis, its converged tangents and
/// its load levels, and each still times only its own work (`ContinuumRun::dsa`,
/// `DualRun::reference`); both results carry the one run's report and total time. `on_step`
/// sees the records after every converged step (to write the results as the run goes); with
/// the continuum DSA alone on its own thread
/// ([`continuum::ContinuumSchedule::Concurrent`]) after every step it has recorded, with the
/// model at that step's committed state, while the analysis may be a step or more ahead.
pub fn run_hooked(
    analysis: DsaAnalysis<'_>,
    methods: HookedMethods,
    on_step: &mut dyn FnMut(HookedRecords<'_>),
) -> Result<(Option<continuum::ContinuumRun>, Option<dual::DualRun>), dual::SensitivityError> {
    type Runs = (Option<continuum::ContinuumRun>, Option<dual::DualRun>);
    if methods.continuum
        && methods.dual.is_none()
        && methods
            .schedule
            .resolve(crate::solver::NonlinearProblem::n_dofs(&analysis.problem))
            == continuum::ContinuumSchedule::Concurrent
    {
        let run = continuum::run_concurrent(analysis, &mut |p, c| {
            on_step(HookedRecords {
                continuum: Some(c.records()),
                dual: None,
                model: &p.model,
                continuum_fields: Some(c),
                dual_fields: None,
            })
        })?;
        return Ok((Some(run), None));
    }
    fn drive<D: dual::DesignDual>(
        analysis: DsaAnalysis<'_>,
        methods: HookedMethods,
        on_step: &mut dyn FnMut(HookedRecords<'_>),
    ) -> Result<Runs, dual::SensitivityError> {
        use crate::solver::observe::{Observed, StepObserver, Tapped};
        let t0 = std::time::Instant::now();
        let (pattern, mut linear) = analysis.linear_solver()?;
        let (problem, surface, newton) = (analysis.problem, analysis.surface, analysis.newton);
        let (variables, monitors) = (analysis.variables, analysis.monitors);
        let c = methods
            .continuum
            .then(|| {
                continuum::ContinuumDsa::new(&problem, surface, variables.clone(), monitors.clone())
                    .map(|c| {
                        c.with_solve(match methods.dual {
                            None => methods.solve,
                            Some(_) => continuum::SensitivitySolve::Factorised,
                        })
                    })
            })
            .transpose()?;
        let d = methods
            .dual
            .map(|_| dual::DualDsa::<D>::new(&problem, surface, variables, monitors))
            .transpose()?;
        type Methods<D> = (Option<continuum::ContinuumDsa>, Option<dual::DualDsa<D>>);
        let mut tap = |p: &crate::shell::problem::ShellProblem, o: &Methods<D>| {
            on_step(HookedRecords {
                continuum: o.0.as_ref().map(|c| c.records()),
                dual: o.1.as_ref().map(|d| d.records()),
                model: &p.model,
                continuum_fields: o.0.as_ref().map(|c| c as &dyn SensitivityFields),
                dual_fields: o.1.as_ref().map(|d| d as &dyn SensitivityFields),
            })
        };
        let mut obs = Observed::new(problem, Tapped::new((c, d), &mut tap));
        let u0 = obs.problem.state().to_vec();
        let report = newton
            .run(&mut obs, &pattern, &mut linear, &u0)
            .map_err(dual::SensitivityError::Newton)?;
        if let Some(f) = obs.observer.failure() {
            return Err(dual::SensitivityError::Observer(f));
        }
        let total = t0.elapsed();
        let (c, d) = obs.observer.observer;
        Ok((
            c.map(|c| c.into_run(report.clone(), total)),
            d.map(|d| d.into_run(report, total)),
        ))
    }
    macro_rules! vector {
        ($($n:literal),*) => {
            match analysis.variables.len() {
                $($n => drive::<num_dual::DualSVec64<$n>>(analysis, methods, on_step),)*
                count => Err(dual::SensitivityError::TooManyVariables { count, max: 8 }),
            }
        };
    }
    match methods.dual {
        None | Some(dual::DualMode::PerVariable) => {
            drive::<num_dual::Dual64>(analysis, methods, on_step)
        }
        Some(dual::DualMode::Vector) => vector!(1, 2, 3, 4, 5, 6, 7, 8),
    }
}

/// The continuum DSA and the dual-number reference in one hooked run ([`run_hooked`] with
/// both methods; the dual scalar follows `mode` as in [`dual::run_dual_on`]).
pub fn run_continuum_and_dual(
    analysis: DsaAnalysis<'_>,
    mode: dual::DualMode,
) -> Result<(continuum::ContinuumRun, dual::DualRun), dual::SensitivityError> {
    let methods = HookedMethods {
        continuum: true,
        dual: Some(mode),
        schedule: continuum::ContinuumSchedule::Synchronous,
        solve: continuum::SensitivitySolve::Factorised,
    };
    let runs = run_hooked(analysis, methods, &mut |_| {})?;
    match runs {
        (Some(c), Some(d)) => Ok((c, d)),
        _ => unreachable!("run_hooked returns a run per method asked for"),
    }
}
