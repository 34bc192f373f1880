//! Exact linear constraints on the generalised DOFs, enforced with Lagrange multipliers by
//! [`super::problem::ShellProblem`] (docs/shell-formulation.md §6.2).
//!
//! A constraint is a row `Σ_k c_k q_k = λ g` on the driver's generalised DOFs `q` (accumulated
//! over the steps, so for translations `q` is the displacement coefficient `ū_I` itself), with
//! `λ` the load factor: a prescribed value ramps with the load (displacement control), a zero
//! value holds. Reproducing-kernel functions do not interpolate, so conditions at a point are
//! written on the RK-interpolated field, e.g. `Σ_I Ψ_I(ξ_J) ū_I · n = λ g` — exact for the
//! translations, with images mapped to their sources (`Ψ_J Qᵀ n` on the source's `ū`).
//! Rotation conditions `Σ_I Ψ_I(ξ_J) α_Iβ` are exact only where the particles around `ξ_J`
//! share their lamina vectors (a flat plate in its first step); elsewhere they constrain an
//! average of rotation parameters about different axes (docs/shell-formulation.md §6.2).
//!
//! Edge conditions ([`edge_constraints`]) put rows at the real particles lying on the edge (their
//! parameter coordinates), as the transformation method did.

use super::model::ShellModel;
use super::point::DOFS_PER_PARTICLE;
use super::symmetry::on_edge;
use crate::meshfree::Edge;
use crate::meshfree::ShapeValues;
use nalgebra::Vector3;
use thiserror::Error;

/// Errors of constraint construction. Each names the constraint and the offending value.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ConstraintError {
    /// A direction that is zero or not finite.
    #[error("constraint `{label}`: direction {direction:?}: expected a finite non-zero vector")]
    InvalidDirection {
        /// The constraint.
        label: String,
        /// The given direction.
        direction: [f64; 3],
    },
    /// A rotation component other than 0 or 1.
    #[error("constraint `{label}`: rotation component {component}: expected 0 (α1) or 1 (α2)")]
    InvalidComponent {
        /// The constraint.
        label: String,
        /// The given component.
        component: usize,
    },
    /// A prescribed value that is not finite.
    #[error("constraint `{label}`: value {value}: expected a finite number")]
    InvalidValue {
        /// The constraint.
        label: String,
        /// The value.
        value: f64,
    },
    /// The shape functions cannot be evaluated at the constraint point.
    #[error("constraint `{label}`: {message}")]
    Evaluation {
        /// The constraint.
        label: String,
        /// The meshfree error.
        message: String,
    },
    /// No real particle lies on a constrained edge.
    #[error("edge {edge:?}: no particle lies on it; expected particles on a constrained edge")]
    NoParticlesOnEdge {
        /// The edge.
        edge: Edge,
    },
    /// A generalised DOF out of range.
    #[error("constraint `{label}`: generalised DOF {dof}: expected < {n_dofs}")]
    DofOutOfRange {
        /// The constraint.
        label: String,
        /// The DOF.
        dof: usize,
        /// Number of generalised DOFs.
        n_dofs: usize,
    },
    /// A coefficient that is not finite.
    #[error("constraint `{label}`: coefficient {value} of DOF {dof}: expected a finite number")]
    NonFiniteCoefficient {
        /// The constraint.
        label: String,
        /// The DOF.
        dof: usize,
        /// The coefficient.
        value: f64,
    },
    /// A row without a non-zero coefficient on a free DOF: the system would be singular.
    #[error(
        "constraint `{label}` has no non-zero coefficient on a free DOF (none, or only on DOFs \
         eliminated as symmetry conditions): expected a row that constrains something"
    )]
    EmptyRow {
        /// The constraint.
        label: String,
    },
}

/// What a row constrains: it sets the row's scale in the problem (a stiffness that makes the
/// constraint residual a force or a moment, [`super::problem::ShellProblem`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RowKind {
    /// A displacement (length).
    Displacement,
    /// A rotation parameter (dimensionless).
    Rotation,
}

/// One row `Σ_k c_k q_k = λ g`.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearConstraint {
    /// A name for reports and errors (e.g. `"clamped UMin, particle 3, ū·(0, 0, 1)"`).
    pub label: String,
    /// `(generalised DOF, coefficient)`, each DOF once.
    pub terms: Vec<(usize, f64)>,
    /// `g`: the value at load factor 1.
    pub value: f64,
    /// Displacement or rotation row.
    pub kind: RowKind,
}

/// Collect the non-zero entries of a dense row.
fn sparse_row(dense: &[f64]) -> Vec<(usize, f64)> {
    dense
        .iter()
        .enumerate()
        .filter(|(_, v)| **v != 0.0)
        .map(|(i, &v)| (i, v))
        .collect()
}

fn check_value(label: &str, value: f64) -> Result<(), ConstraintError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(ConstraintError::InvalidValue {
            label: label.to_string(),
            value,
        })
    }
}

/// `Σ_J Ψ_J(uv) local_J` scattered through the model's seam (images to their sources).
fn interpolated_row(
    model: &ShellModel,
    uv: [f64; 2],
    label: &str,
    local: impl Fn(f64) -> [f64; DOFS_PER_PARTICLE],
) -> Result<Vec<(usize, f64)>, ConstraintError> {
    let mut sv = ShapeValues::new();
    model
        .shape_functions
        .evaluate(uv, &mut sv)
        .map_err(|e| ConstraintError::Evaluation {
            label: label.to_string(),
            message: e.to_string(),
        })?;
    let mut dense = vec![0.0; model.n_dofs()];
    for (j, psi, _) in sv.iter() {
        model.scatter_particle(j, &local(psi), &mut dense);
    }
    Ok(sparse_row(&dense))
}

impl LinearConstraint {
    /// The RK-interpolated displacement at `uv` along `direction` (normalised):
    /// `Σ_J Ψ_J(uv) ū_J · n = λ value`.
    pub fn displacement(
        model: &ShellModel,
        uv: [f64; 2],
        direction: Vector3<f64>,
        value: f64,
    ) -> Result<Self, ConstraintError> {
        let label = format!(
            "displacement at {uv:?} along ({}, {}, {})",
            direction[0], direction[1], direction[2]
        );
        let len = direction.norm();
        if !(len.is_finite() && len > 0.0) {
            return Err(ConstraintError::InvalidDirection {
                label,
                direction: direction.into(),
            });
        }
        check_value(&label, value)?;
        let n = direction / len;
        let terms = interpolated_row(model, uv, &label, |psi| {
            [psi * n[0], psi * n[1], psi * n[2], 0.0, 0.0]
        })?;
        Ok(LinearConstraint {
            label,
            terms,
            value,
            kind: RowKind::Displacement,
        })
    }

    /// The RK-interpolated rotation parameter `α_β` (`component` 0 or 1) at `uv`:
    /// `Σ_J Ψ_J(uv) α_Jβ = λ value` (exact where the particles share lamina vectors).
    pub fn rotation(
        model: &ShellModel,
        uv: [f64; 2],
        component: usize,
        value: f64,
    ) -> Result<Self, ConstraintError> {
        let label = format!("rotation α{} at {uv:?}", component + 1);
        if component > 1 {
            return Err(ConstraintError::InvalidComponent { label, component });
        }
        check_value(&label, value)?;
        let terms = interpolated_row(model, uv, &label, |psi| {
            let mut l = [0.0; DOFS_PER_PARTICLE];
            l[3 + component] = psi;
            l
        })?;
        Ok(LinearConstraint {
            label,
            terms,
            value,
            kind: RowKind::Rotation,
        })
    }

    /// One generalised DOF: `q_dof = λ value`.
    pub fn generalised(dof: usize, value: f64, kind: RowKind) -> Self {
        LinearConstraint {
            label: format!("generalised DOF {dof}"),
            terms: vec![(dof, 1.0)],
            value,
            kind,
        }
    }

    /// With a new label.
    pub fn labelled(mut self, label: impl Into<String>) -> Self {
        self.label = label.into();
        self
    }
}

/// A condition on a parametric edge, imposed at the real particles lying on it.
#[derive(Clone, Debug, PartialEq)]
pub enum EdgeCondition {
    /// All three displacement components and both rotations held.
    Clamped,
    /// All three displacement components held, rotations free ("hard" simple support).
    SimplySupported,
    /// A rigid diaphragm in the plane with this normal: the two displacement components in the
    /// plane held, the one along the normal and the rotations free.
    Diaphragm {
        /// Normal of the diaphragm plane.
        normal: Vector3<f64>,
    },
    /// The displacement along each given direction and the given rotation components.
    Fixed {
        /// Displacement directions held.
        directions: Vec<Vector3<f64>>,
        /// Rotation components held (0: α1, 1: α2).
        rotations: Vec<usize>,
    },
}

/// Two unit vectors spanning the plane normal to `n` (the coordinate axes when `n` is one).
fn in_plane_basis(n: &Vector3<f64>) -> [Vector3<f64>; 2] {
    let n = n.normalize();
    // The axis least aligned with n seeds the first vector.
    let k = (0..3)
        .min_by(|&a, &b| n[a].abs().total_cmp(&n[b].abs()))
        .unwrap_or(0);
    let mut seed = Vector3::zeros();
    seed[k] = 1.0;
    let t1 = (seed - n * n.dot(&seed)).normalize();
    [t1, n.cross(&t1)]
}

/// The rows of `condition` on `edge`: one per held component at every real particle on the edge
/// (value 0: held at its initial position/rotation).
pub fn edge_constraints(
    model: &ShellModel,
    edge: Edge,
    condition: &EdgeCondition,
) -> Result<Vec<LinearConstraint>, ConstraintError> {
    let axes = [Vector3::x(), Vector3::y(), Vector3::z()];
    let (directions, rotations): (Vec<Vector3<f64>>, Vec<usize>) = match condition {
        EdgeCondition::Clamped => (axes.to_vec(), vec![0, 1]),
        EdgeCondition::SimplySupported => (axes.to_vec(), vec![]),
        EdgeCondition::Diaphragm { normal } => {
            let len = normal.norm();
            if !(len.is_finite() && len > 0.0) {
                return Err(ConstraintError::InvalidDirection {
                    label: format!("diaphragm on edge {edge:?}"),
                    direction: (*normal).into(),
                });
            }
            (in_plane_basis(normal).to_vec(), vec![])
        }
        EdgeCondition::Fixed {
            directions,
            rotations,
        } => (directions.clone(), rotations.clone()),
    };
    let on: Vec<usize> = (0..model.n_particles())
        .filter(|&i| on_edge(model.particle_uv[i], edge, model.domain))
        .collect();
    if on.is_empty() {
        return Err(ConstraintError::NoParticlesOnEdge { edge });
    }
    let mut rows = Vec::new();
    for &i in &on {
        let uv = model.particle_uv[i];
        for d in &directions {
            let c = LinearConstraint::displacement(model, uv, *d, 0.0)?;
            let label = format!("{edge:?} particle {i}: {}", c.label);
            rows.push(c.labelled(label));
        }
        for &b in &rotations {
            let c = LinearConstraint::rotation(model, uv, b, 0.0)?;
            let label = format!("{edge:?} particle {i}: {}", c.label);
            rows.push(c.labelled(label));
        }
    }
    Ok(rows)
}
