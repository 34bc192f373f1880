//! Rigid parametric tools and the point-level frictionless penalty contact with them (the paper's
//! §4.1, eqs 66–72; what the design sensitivity of §4.2, eqs 73–83, needs is exposed generically).
//!
//! - [`tool`]: rigid tools ([`RigidTool`]): a [`crate::geometry::Surface`] (die, punch, blank
//!   holder) moved rigidly along a [`ToolPath`] driven by the pseudo-time `t` (the solver's load
//!   factor), `x^c(ξ; t) = c + R(t)(X(ξ) − c) + a(t)`, with the side of the surface that is
//!   solid and a coarse sample grid of the parameter domain for the projection's initial guess.
//! - [`projection`]: the closest-point projection (eq 67) and the normal gap (eq 68), generic
//!   over the scalar: Newton in f64 on `ξ`, then one Newton correction in the scalar type, which
//!   carries the exact implicit derivative `ξ̇ = A⁻¹(…)` (eq 80) into the gap and the normal.
//! - [`penalty`]: the penalty force of one slave point (eqs 69–70) and its hand-derived
//!   consistent 3×3 tangent (eq 72, with the curvature term of the normal's rotation).
//!
//! The sheet's side of the contact (slave points on its faces, the generalised force and
//! stiffness, their design derivative) is in the shell module: `crate::shell::contact` and
//! `crate::shell::contact_sensitivity`.
//!
//! Formulas, conventions and the measured checks: `docs/contact.md`.

pub mod penalty;
pub mod projection;
pub mod tool;

pub use penalty::{penalty_force, penalty_tangent};
pub use projection::{closest_point, nearest_tool, Bound, ContactPoint};
pub use tool::{CoarseGrid, PathKey, RigidMotion, RigidTool, Side, ToolPath};

use crate::geometry::GeometryError;
use thiserror::Error;

/// Errors of the contact module, naming the field or the point, the value found and what was
/// expected.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ContactError {
    /// Invalid input data.
    #[error("`{field}` = {value}: expected {expected}")]
    InvalidInput {
        /// The field (`penalty`, `path.keys[2].t`, …).
        field: String,
        /// The value given.
        value: String,
        /// What was expected.
        expected: String,
    },
    /// Invalid tool geometry.
    #[error("tool `{tool}`: {source}")]
    Geometry {
        /// Tool name.
        tool: String,
        /// The geometry error.
        source: GeometryError,
    },
    /// The closest-point projection did not converge.
    #[error(
        "closest-point projection of {point:?} onto tool `{tool}` did not converge in \
         {iterations} iterations: last step {step:e} (expected ≤ {tolerance:e}) at ξ = {xi:?}"
    )]
    ProjectionNotConverged {
        /// Tool name.
        tool: String,
        /// The slave point (real part).
        point: [f64; 3],
        /// Iterations done.
        iterations: usize,
        /// Length of the last step on the tool.
        step: f64,
        /// The convergence tolerance on the step.
        tolerance: f64,
        /// Last parameter pair.
        xi: [f64; 2],
    },
    /// A slave point went from outside a tool to deeper inside it than the sheet thickness in
    /// one step: the tool path moves too far per step (or the penalty is far too small).
    #[error(
        "tool `{tool}` crosses the sheet in one step: slave point of quadrature point {point} \
         (ζ = {zeta}, (u, v) = {uv:?}) had the gap {gap_before:e} at t = {t_before} and \
         {gap_after:e} at t = {t_after}: expected a gap ≥ −{thickness:e} (minus the sheet \
         thickness); take smaller steps"
    )]
    PathCrossesSheet {
        /// Tool name.
        tool: String,
        /// Quadrature point index.
        point: usize,
        /// Face (`+1` top, `−1` bottom).
        zeta: f64,
        /// Parameter coordinates of the point.
        uv: [f64; 2],
        /// Gap at the previous pseudo-time.
        gap_before: f64,
        /// Gap now.
        gap_after: f64,
        /// Previous pseudo-time.
        t_before: f64,
        /// Current pseudo-time.
        t_after: f64,
        /// Sheet thickness.
        thickness: f64,
    },
    /// A tool that penetrates the undeformed sheet at `t = 0` deeper than the sheet thickness
    /// ([`crate::shell::contact::ShellContact::initial_penetration`]): placed through the
    /// sheet, or facing it with the wrong side.
    #[error(
        "tool `{tool}` already penetrates the undeformed sheet at t = 0: a slave point of \
         quadrature point {point} (ζ = {zeta}, (u, v) = {uv:?}) has the gap {gap:e}, expected \
         a gap ≥ −{thickness:e} (minus the sheet thickness); move the tool off the sheet (its \
         surface's position) or check its `side`"
    )]
    InitialPenetration {
        /// Tool name.
        tool: String,
        /// Quadrature point index.
        point: usize,
        /// Face (`+1` top, `−1` bottom).
        zeta: f64,
        /// Parameter coordinates of the point.
        uv: [f64; 2],
        /// The deepest gap of the tool.
        gap: f64,
        /// Sheet thickness.
        thickness: f64,
    },
    /// Tools that had no active slave point in any evaluation since the tracking started
    /// ([`crate::shell::contact::ShellContact::check_engaged`]).
    #[error("tools {tools:?} never touched the sheet: expected every tool to make contact")]
    ToolsNeverTouched {
        /// Tool names.
        tools: Vec<String>,
    },
}

/// `InvalidInput` with a formatted value.
pub(crate) fn invalid(
    field: impl Into<String>,
    value: impl std::fmt::Debug,
    expected: &str,
) -> ContactError {
    ContactError::InvalidInput {
        field: field.into(),
        value: format!("{value:?}"),
        expected: expected.to_string(),
    }
}
