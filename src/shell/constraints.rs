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
    /// A row without a non-zero coefficient and a non-zero value: it cannot be met.
    #[error(
        "constraint `{label}` has no non-zero coefficient but the value {value}: expected a row \
         that constrains something"
    )]
    EmptyRow {
        /// The constraint.
        label: String,
        /// Its value.
        value: f64,
    },
    /// A row that other rows (or symmetry planes) already impose, at a different value: the
    /// same component is held at two values, and no displacement can meet both.
    #[error(
        "constraint `{label}` holds, at value {value}, a component that `{other}` already \
         holds at {implied}: expected one value per component (remove one of the two \
         entries, or give them the same value)"
    )]
    Conflict {
        /// The dependent row.
        label: String,
        /// Its value `g` (at load factor 1).
        value: f64,
        /// The row (or symmetry plane) it repeats.
        other: String,
        /// The value the other rows imply for it.
        implied: f64,
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

/// `Σ_J Ψ_J(uv) local_J` scattered through the model's seam (images to their sources);
/// `local(j, Ψ_J)` for shape-function particle `j`.
fn interpolated_row(
    model: &ShellModel,
    uv: [f64; 2],
    label: &str,
    local: impl Fn(usize, f64) -> [f64; DOFS_PER_PARTICLE],
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
        model.scatter_particle(j, &local(j, psi), &mut dense);
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
        let terms = interpolated_row(model, uv, &label, |_, psi| {
            [psi * n[0], psi * n[1], psi * n[2], 0.0, 0.0]
        })?;
        Ok(LinearConstraint {
            label,
            terms,
            value,
            kind: RowKind::Displacement,
        })
    }

    /// The RK-interpolated rotation about the lamina vector `e_β` (`component` 0 or 1) of the
    /// real particle nearest to `uv` (in the parameter domain; the particle's own at a
    /// particle): `Σ_J Ψ_J(uv) Σ_γ P_Jγβ α_Jγ = λ value` (`rotation_matching`).
    pub fn rotation(
        model: &ShellModel,
        uv: [f64; 2],
        component: usize,
        value: f64,
    ) -> Result<Self, ConstraintError> {
        let [w0, w1] = [0, 1].map(|k| model.domain[k][1] - model.domain[k][0]);
        let nearest = (0..model.n_particles())
            .min_by(|&a, &b| {
                let d = |i: usize| {
                    let p = model.particle_uv[i];
                    ((p[0] - uv[0]) / w0).powi(2) + ((p[1] - uv[1]) / w1).powi(2)
                };
                d(a).total_cmp(&d(b))
            })
            .unwrap_or(0);
        Self::rotation_at_particle_axes(model, uv, nearest, component, value)
    }

    /// As [`Self::rotation`] about the lamina vector of real particle `axes_of`.
    fn rotation_at_particle_axes(
        model: &ShellModel,
        uv: [f64; 2],
        axes_of: usize,
        component: usize,
        value: f64,
    ) -> Result<Self, ConstraintError> {
        let label = format!("rotation α{} at {uv:?}", component + 1);
        if component > 1 {
            return Err(ConstraintError::InvalidComponent { label, component });
        }
        check_value(&label, value)?;
        let axis = model
            .particles
            .get(axes_of)
            .map(|p| p.e[component])
            .unwrap_or_else(Vector3::zeros);
        let terms = interpolated_row(model, uv, &label, |j, psi| {
            let p = rotation_matching(&model.particle_state(j).e, &axis);
            [0.0, 0.0, 0.0, psi * p[0], psi * p[1]]
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

/// How the rotation parameters `α_Jγ` of a particle with lamina vectors `e` (an image's are
/// `Q e` of its source's, its parameters `det Q α`) enter a row about `axis`: the lamina vector
/// more nearly along the axis enters with the sign of its component, the other not (`P_Jγβ`
/// ∈ {−1, 0, 1}), so that a row about `e_β` of one particle reads each neighbour's rotation
/// about the matching axis of its own frame, with its sign.
///
/// The lamina frames of neighbouring particles differ by a signed permutation exactly where it
/// matters most and the rows would otherwise be wrong: the images across a symmetry plane
/// (`e_img = S e`, `α_img = −α`: the rotation about the plane's normal is symmetric, the one
/// about an in-plane axis antisymmetric) and the particles on a plane (`e1 = n_s`, turned by 90°
/// from their neighbours' `e1 = x̄,u` on a `v` edge) — exact on a flat plate. Elsewhere (curved
/// shells) the frames differ by small angles (up to 45° the matching is the identity) and this
/// is the first-order reading of `Σ_J Ψ_J α_Jβ` (docs/shell-formulation.md §6.2). The factors
/// do not change under a small design perturbation, so the rows stay independent of the design.
fn rotation_matching(e: &[Vector3<f64>; 2], axis: &Vector3<f64>) -> [f64; 2] {
    let c = [e[0].dot(axis), e[1].dot(axis)];
    let g = usize::from(c[1].abs() > c[0].abs());
    let mut p = [0.0; 2];
    if c[g] != 0.0 {
        p[g] = c[g].signum();
    }
    p
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
            let c = LinearConstraint::rotation_at_particle_axes(model, uv, i, b, 0.0)?;
            let label = format!("{edge:?} particle {i}: {}", c.label);
            rows.push(c.labelled(label));
        }
    }
    Ok(rows)
}

/// A row left out of the system because other rows (or the symmetry planes) already impose it
/// with the same value, e.g. a corner particle held by both edges that meet there.
#[derive(Clone, Debug, PartialEq)]
pub struct MergedRow {
    /// The row left out.
    pub label: String,
    /// What imposes it: the label of the row it repeats (the kept row most nearly parallel to
    /// it), or of the symmetry plane that meets it.
    pub by: String,
}

/// The constraint system the problem imposes ([`assemble`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ConstraintSet {
    /// Linearly independent rows on the free generalised DOFs: the symmetry rows, then the given
    /// rows, each in its order, without the merged ones.
    pub rows: Vec<LinearConstraint>,
    /// Generalised DOFs eliminated as symmetry conditions (held at zero), sorted.
    pub fixed: Vec<usize>,
    /// For each eliminated DOF of [`Self::fixed`], the label of the symmetry plane holding it.
    pub fixed_by: Vec<String>,
    /// Rows left out as already imposed.
    pub merged: Vec<MergedRow>,
}

/// A row is dependent on the rows kept before it when its residual after projection on their
/// span is below this, relative to its own norm: far above the round-off of the explicit
/// residual (~1e-15 times the size of the combination) and far below the separation of rows
/// held at distinct points (the RK functions of particles one spacing apart differ by O(1) of
/// their size).
const DEPENDENT_TOL: f64 = 1e-8;
/// Rows whose squared residual by the Gram matrix is above this (a residual above 1e-3 of the
/// row) are independent without further test: the round-off of that estimate is ~1e-16 times
/// the squared condition number of the kept rows, far below for any usable set.
const SCREEN_TOL: f64 = 1e-6;
/// A dependent row's value conflicts with the value its span implies when they differ by more
/// than this relative to the largest normalised value of its component: round-off of the
/// projection is ~1e-15, and a row below [`DEPENDENT_TOL`] can shift the implied value by that
/// much relative; values meant to be equal agree far better, values meant to differ differ by O(1).
const VALUE_TOL: f64 = 1e-6;
/// Coefficients below this fraction of a row's largest are dropped after the row is folded onto
/// the free DOFs (round-off of the RK evaluation, ~1e-15 relative, with margin): a row at a point
/// of a symmetry plane along the plane's normal folds to `Ψ_I − Ψ_image ≈ 0`.
const FOLD_TOL: f64 = 1e-10;

/// How the symmetry conditions of the particles on the planes enter [`assemble`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SymmetryRows {
    /// `α2` (both rotations on two planes), and `ū·n_s` when `n_s` is a coordinate axis,
    /// eliminated as fixed DOFs; the other conditions become rows.
    Eliminate,
    /// Every symmetry condition a row.
    Rows,
}

/// Whether the unit vector `n` is a coordinate axis (to round-off); its axis if so.
fn axis_of(n: &Vector3<f64>) -> Option<usize> {
    (0..3).find(|&k| (n[k].abs() - 1.0).abs() <= 1e-12)
}

/// The constraint system of `model` with the rows `given` (any number, in any overlap): the
/// symmetry conditions of the particles on the model's planes (eliminated DOFs or rows, as
/// `symmetry` says), then `given` folded onto the free DOFs (terms on eliminated DOFs dropped,
/// repeated DOFs summed), checked, and reduced to a linearly independent set.
///
/// Two rows hold the same thing whenever they are linearly dependent: the same component of a
/// particle held by two edges meeting at a corner (identical rows), or by an edge and a `fixed`
/// entry, a row parallel to another, or a row the symmetry already meets (it folds to zero, or
/// to a combination of the others). The rank is found per connected set of rows (rows sharing a
/// DOF, transitively), in the given order, so the first row of a repeated pair is kept: each
/// unit row's residual after projection on the kept rows, from the Cholesky factor of their Gram
/// matrix, confirmed by the explicit residual when it is small; a dependent row is left out ([`ConstraintSet::merged`]) if its
/// value is the one the kept rows imply, and is an error naming both rows if not
/// ([`ConstraintError::Conflict`]), before any analysis.
pub fn assemble(
    model: &ShellModel,
    given: Vec<LinearConstraint>,
    symmetry: SymmetryRows,
) -> Result<ConstraintSet, ConstraintError> {
    let n_q = model.n_dofs();
    let layout = &model.symmetry;
    let mut fixed: Vec<(usize, String)> = Vec::new();
    let mut rows = Vec::new();
    for sc in layout.self_conditions() {
        let base = DOFS_PER_PARTICLE * sc.particle;
        let planes = &layout.on_planes[sc.particle];
        let plane_label = |k: usize| layout.planes[planes[k]].label.clone();
        let both = planes
            .iter()
            .map(|&p| layout.planes[p].label.as_str())
            .collect::<Vec<_>>()
            .join(" and ");
        for &b in &sc.rotations {
            // One plane: α2 (no rotation about d × n_s); two planes: both rotations.
            let by = if planes.len() == 1 {
                plane_label(0)
            } else {
                both.clone()
            };
            match symmetry {
                SymmetryRows::Eliminate => fixed.push((base + 3 + b, by)),
                SymmetryRows::Rows => rows.push(
                    LinearConstraint::generalised(base + 3 + b, 0.0, RowKind::Rotation)
                        .labelled(format!("{by}: particle {}, α{}", sc.particle, b + 1)),
                ),
            }
        }
        for (k, n) in sc.normals.iter().enumerate() {
            match (symmetry, axis_of(n)) {
                (SymmetryRows::Eliminate, Some(a)) => fixed.push((base + a, plane_label(k))),
                _ => rows.push(LinearConstraint {
                    label: format!(
                        "{}: particle {}, ū·({}, {}, {})",
                        plane_label(k),
                        sc.particle,
                        n[0],
                        n[1],
                        n[2]
                    ),
                    terms: (0..3)
                        .filter(|&c| n[c] != 0.0)
                        .map(|c| (base + c, n[c]))
                        .collect(),
                    value: 0.0,
                    kind: RowKind::Displacement,
                }),
            }
        }
    }
    fixed.sort_by_key(|f| f.0);
    fixed.dedup_by_key(|f| f.0);
    let is_fixed = |d: usize| fixed.binary_search_by_key(&d, |f| f.0).ok();
    let mut merged = Vec::new();
    for c in given {
        if !c.value.is_finite() {
            return Err(ConstraintError::InvalidValue {
                label: c.label,
                value: c.value,
            });
        }
        let mut folded: Vec<(usize, f64)> = Vec::with_capacity(c.terms.len());
        let mut held_by: Option<&str> = None;
        for &(d, a) in &c.terms {
            if d >= n_q {
                return Err(ConstraintError::DofOutOfRange {
                    label: c.label,
                    dof: d,
                    n_dofs: n_q,
                });
            }
            if !a.is_finite() {
                return Err(ConstraintError::NonFiniteCoefficient {
                    label: c.label,
                    dof: d,
                    value: a,
                });
            }
            if let Some(f) = is_fixed(d) {
                held_by = held_by.or(Some(&fixed[f].1));
                continue;
            }
            match folded.iter_mut().find(|(e, _)| *e == d) {
                Some(t) => t.1 += a,
                None => folded.push((d, a)),
            }
        }
        let scale = c.terms.iter().fold(0.0_f64, |m, t| m.max(t.1.abs()));
        folded.retain(|t| t.1.abs() > FOLD_TOL * scale);
        if folded.is_empty() {
            // Nothing left on the free DOFs: the symmetry (or nothing) already holds the row at 0.
            let by = match (held_by, c.terms.is_empty()) {
                (_, true) => "nothing (a row without coefficients)".to_string(),
                (Some(p), false) => p.to_string(),
                (None, false) => layout
                    .planes
                    .iter()
                    .map(|p| p.label.as_str())
                    .collect::<Vec<_>>()
                    .join(" and "),
            };
            if c.value != 0.0 {
                if c.terms.is_empty() {
                    return Err(ConstraintError::EmptyRow {
                        label: c.label,
                        value: c.value,
                    });
                }
                return Err(ConstraintError::Conflict {
                    label: c.label,
                    value: c.value,
                    other: by,
                    implied: 0.0,
                });
            }
            merged.push(MergedRow { label: c.label, by });
            continue;
        }
        rows.push(LinearConstraint { terms: folded, ..c });
    }
    let (rows, dependent) = independent_rows(rows, n_q)?;
    merged.extend(dependent);
    let (fixed, fixed_by) = fixed.into_iter().unzip();
    Ok(ConstraintSet {
        rows,
        fixed,
        fixed_by,
        merged,
    })
}

/// Representative of `i` in the union-find forest `parent` (with path halving).
fn root(parent: &mut [usize], mut i: usize) -> usize {
    while parent[i] != i {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    i
}

/// The linearly independent subset of `rows` (each on DOFs `< n_q`, each DOF once, not empty),
/// keeping the first of dependent rows, and the rows left out; an error if a dependent row's
/// value differs from the one the kept rows imply.
fn independent_rows(
    rows: Vec<LinearConstraint>,
    n_q: usize,
) -> Result<(Vec<LinearConstraint>, Vec<MergedRow>), ConstraintError> {
    let m = rows.len();
    // Connected sets: rows sharing a DOF, transitively.
    let mut parent: Vec<usize> = (0..m).collect();
    let mut owner = vec![usize::MAX; n_q];
    for (c, r) in rows.iter().enumerate() {
        for &(d, _) in &r.terms {
            if owner[d] == usize::MAX {
                owner[d] = c;
            } else {
                let (a, b) = (root(&mut parent, owner[d]), root(&mut parent, c));
                if a != b {
                    parent[a.max(b)] = a.min(b);
                }
            }
        }
    }
    let mut sets: Vec<Vec<usize>> = Vec::new();
    let mut set_of = vec![usize::MAX; m];
    for c in 0..m {
        let r = root(&mut parent, c);
        if set_of[r] == usize::MAX {
            set_of[r] = sets.len();
            sets.push(Vec::new());
        }
        sets[set_of[r]].push(c);
    }
    let norms: Vec<f64> = rows
        .iter()
        .map(|r| r.terms.iter().map(|t| t.1 * t.1).sum::<f64>().sqrt())
        .collect();
    // `â_c · v` for the unit row `c` and a dense vector `v`.
    let dot_unit =
        |c: usize, v: &[f64]| rows[c].terms.iter().map(|&(d, a)| a * v[d]).sum::<f64>() / norms[c];
    let mut keep = vec![true; m];
    let mut merged = Vec::new();
    let mut unit = vec![0.0; n_q];
    let mut residual = vec![0.0; n_q];
    for set in sets.iter().filter(|s| s.len() > 1) {
        let g_max = set
            .iter()
            .map(|&c| (rows[c].value / norms[c]).abs())
            .fold(0.0_f64, f64::max);
        // The kept rows and the Cholesky factor `L` of their Gram matrix (row i: i + 1 entries).
        let mut kept: Vec<usize> = Vec::new();
        let mut l: Vec<Vec<f64>> = Vec::new();
        for &c in set {
            for &(d, a) in &rows[c].terms {
                unit[d] = a / norms[c];
            }
            // y = L⁻¹ b with b_j = â_j · â_c: the coordinates of the projection of â_c on the
            // kept rows' span, ‖y‖² its squared length.
            let mut y: Vec<f64> = kept.iter().map(|&j| dot_unit(j, &unit)).collect();
            for i in 0..y.len() {
                let s: f64 = (0..i).map(|k| l[i][k] * y[k]).sum();
                y[i] = (y[i] - s) / l[i][i];
            }
            let d = 1.0 - y.iter().map(|v| v * v).sum::<f64>();
            // Squared residual by the Gram matrix: fast, but with the round-off of the squared
            // condition number. Rows well away from the span are independent; the others are
            // decided by their explicit residual `â_c − Σ_j x_j â_j`, with `Lᵀ x = y`.
            let mut diagonal = d.max(0.0).sqrt();
            let mut dependent = None;
            if d <= SCREEN_TOL {
                let mut x = y.clone();
                for i in (0..x.len()).rev() {
                    let s: f64 = (i + 1..x.len()).map(|k| l[k][i] * x[k]).sum();
                    x[i] = (x[i] - s) / l[i][i];
                }
                let mut touched: Vec<usize> = rows[c].terms.iter().map(|t| t.0).collect();
                for &d in &touched {
                    residual[d] = unit[d];
                }
                for (&j, &xj) in kept.iter().zip(&x) {
                    for &(d, a) in &rows[j].terms {
                        if residual[d] == 0.0 {
                            touched.push(d);
                        }
                        residual[d] -= xj * a / norms[j];
                    }
                }
                touched.sort_unstable();
                touched.dedup();
                let norm = touched
                    .iter()
                    .map(|&d| residual[d] * residual[d])
                    .sum::<f64>()
                    .sqrt();
                for &d in &touched {
                    residual[d] = 0.0;
                }
                if norm <= DEPENDENT_TOL {
                    dependent = Some(x);
                } else {
                    diagonal = norm;
                }
            }
            for &(d, _) in &rows[c].terms {
                unit[d] = 0.0;
            }
            let Some(x) = dependent else {
                y.push(diagonal);
                l.push(y);
                kept.push(c);
                continue;
            };
            // Dependent: the value the kept rows imply is the same combination of theirs.
            let implied: f64 = kept
                .iter()
                .zip(&x)
                .map(|(&j, xj)| xj * rows[j].value / norms[j])
                .sum();
            let other = kept
                .iter()
                .zip(&x)
                .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
                .map(|k| *k.0)
                .unwrap_or(c);
            if (rows[c].value / norms[c] - implied).abs() > VALUE_TOL * g_max {
                return Err(ConstraintError::Conflict {
                    label: rows[c].label.clone(),
                    value: rows[c].value,
                    other: rows[other].label.clone(),
                    implied: implied * norms[c],
                });
            }
            keep[c] = false;
            merged.push(MergedRow {
                label: rows[c].label.clone(),
                by: rows[other].label.clone(),
            });
        }
    }
    let rows = rows
        .into_iter()
        .zip(keep)
        .filter_map(|(r, k)| k.then_some(r))
        .collect();
    Ok((rows, merged))
}
