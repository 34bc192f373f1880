//! The meshfree shell: thickness-degenerated, shear-deformable, 5 DOF per particle (3
//! translations, 2 director rotations), finite rotations, updated Lagrangian with the
//! Hughes–Winget update (paper §2.3–2.4; plan in docs/shell-formulation.md).
//!
//! The point kernel ([`point`]: kinematics, stress update and internal force at one
//! quadrature point, generic over the scalar) and its consistent tangent ([`tangent`]) and
//! design derivative ([`point_sensitivity`]); the assembled model ([`model`]) with symmetry
//! images ([`symmetry`]), exact linear constraints ([`constraints`]) and the loads ([`load`]),
//! among them the director stabilisation ([`stabilisation`]) and the contact with rigid tools
//! ([`contact`], its design derivative [`contact_sensitivity`]); the nonlinear problem the
//! solver drives ([`problem`]). The director rotation is `crate::kinematics::rotation`.

pub mod constraints;
pub mod contact;
pub mod contact_sensitivity;
pub mod gather;
pub mod gauge;
pub mod integration;
pub mod load;
pub mod model;
pub mod point;
pub mod point_sensitivity;
pub mod problem;
pub mod resultants;
pub mod stabilisation;
pub mod symmetry;
pub mod tangent;

use crate::kinematics::KinematicsError;
use crate::material::MaterialError;
use thiserror::Error;

/// Errors of the shell kernels.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ShellError {
    /// A configuration Jacobian with non-positive determinant (an inverted shell).
    #[error("{what} has determinant {det:e} <= 0: the shell is inverted or the step too large")]
    NonPositiveJacobian {
        /// Which Jacobian.
        what: &'static str,
        /// Its determinant.
        det: f64,
    },
    /// Inconsistent input sizes.
    #[error("expected {expected} degrees of freedom at the point, got {got}")]
    Dimension {
        /// Expected length.
        expected: usize,
        /// Given length.
        got: usize,
    },
    /// Invalid model input (geometry, particles, parameters).
    #[error("{0}")]
    InvalidInput(String),
    /// A load could not be evaluated at this state, but a smaller load step may succeed (a
    /// rigid tool that crossed the sheet in one step, a closest-point projection that did not
    /// converge): the nonlinear driver cuts the step.
    #[error("{0}")]
    StepTooLarge(String),
    /// Kinematics failure.
    #[error(transparent)]
    Kinematics(#[from] KinematicsError),
    /// Material failure.
    #[error(transparent)]
    Material(#[from] MaterialError),
    /// Invalid symmetry plane.
    #[error(transparent)]
    Symmetry(#[from] symmetry::SymmetryError),
    /// Invalid linear constraint.
    #[error(transparent)]
    Constraint(#[from] constraints::ConstraintError),
    /// The reproducing-kernel functions could not be evaluated (too few particles cover a
    /// point: the supports are too small for the basis); `context` says where.
    #[error("{context}{source}")]
    Shape {
        /// Where the evaluation was, with a trailing separator (empty at quadrature points).
        context: &'static str,
        /// The meshfree error.
        source: crate::meshfree::MeshfreeError,
    },
}
