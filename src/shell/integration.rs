//! In-plane integration of the shell: variationally consistent test gradients
//! ([`crate::meshfree::vci`]) for a [`ShellModel`].
//!
//! The internal virtual work of the shell is an integral over the parameter domain (eq 32 with
//! `dV = det J dξ1 dξ2 dζ`): the translation rows of particle `I` are `Σ_q Σ_ζ Ψ_I,α P:α` with
//! `P = w det(J) σᵍ J⁻ᵀ` (see [`super::point`]), so the divergence theorem that VCI restores is the
//! one in the parameter plane, `∫ (Ψ_I P:α),α dξ = ∮ Ψ_I P:α n_α ds`, with parameter-domain
//! weights and arc length. The correction is coupled so that the partition of nullity
//! `Σ_I Ψ̃_I,α = 0` also holds at every point ([`VciCoupling::PartitionOfNullity`]; without it the
//! pinched hemisphere was 4-6 % too flexible, docs/integration.md §4.8). [`apply_vci`] writes the
//! corrected gradients into
//! `ShapeData::dpsi_test` of every quadrature point; the trial gradients `dpsi` are untouched
//! (Petrov–Galerkin: the internal force is no longer the gradient of the stored energy and the
//! tangent is not symmetric, but the patch tests pass; see `docs/integration.md`).

use super::model::ShellModel;
use super::ShellError;
use crate::meshfree::vci::{
    BoundaryRule, QuadratureShapes, VciCorrection, VciCoupling, VciError, VciOrder,
};
use crate::meshfree::ParamBox;

/// Points per segment of the default boundary rule: the contour integrals of the RK functions to
/// about 4e-14 relative (measured in `tests/vci.rs`).
pub const BOUNDARY_POINTS_PER_SEGMENT: usize = 8;

/// The model's quadrature points with their RK (trial) functions, as VCI sees them.
struct ModelPoints<'a>(&'a ShellModel);

impl QuadratureShapes for ModelPoints<'_> {
    fn n_points(&self) -> usize {
        self.0.points.len()
    }
    fn point(&self, k: usize) -> ([f64; 2], f64) {
        let p = &self.0.points[k];
        (p.uv, p.weight)
    }
    fn for_each_shape(&self, k: usize, f: &mut dyn FnMut(usize, f64, [f64; 2])) {
        let p = &self.0.points[k];
        for (&i, s) in p.neighbours.iter().zip(&p.shape) {
            f(i, s.psi, s.dpsi);
        }
    }
}

/// What [`apply_vci`] did.
#[derive(Clone, Debug)]
pub struct VciReport {
    /// The correction (coefficients, achieved order per shape-function particle).
    pub correction: VciCorrection,
    /// Particles corrected to a lower order than requested (too few quadrature points in their
    /// support, e.g. mirror images reaching only a thin strip of the domain).
    pub degraded: Vec<(usize, VciOrder)>,
    /// Largest relative defect of the integration constraints (of the requested order, over the
    /// particles that achieved it) with the RK gradients: the quadrature error VCI removes.
    pub defect_before: f64,
    /// The same with the corrected gradients (round-off when the correction succeeded).
    pub defect_after: f64,
    /// Conjugate-gradient iterations of the coupled correction
    /// ([`VciCoupling::PartitionOfNullity`]).
    pub iterations: usize,
}

/// The default boundary rule for `model` on `domain`: 8 Gauss points on every segment between
/// the kernel breakpoints of the model's shape-function particles (images included).
pub fn boundary_rule(model: &ShellModel, domain: ParamBox) -> Result<BoundaryRule, ShellError> {
    let sf = &model.shape_functions;
    BoundaryRule::breakpoint_aligned(
        domain,
        sf.particles(),
        sf.supports(),
        BOUNDARY_POINTS_PER_SEGMENT,
    )
    .map_err(vci_error)
}

/// Replace the test gradients `points[k].shape[i].dpsi_test` of `model` by the variationally
/// consistent ones of `order` (coupled by [`VciCoupling::PartitionOfNullity`]), computed from the
/// trial gradients `dpsi`, the model's quadrature
/// (which must cover exactly the rectangular parameter `domain`) and the contour integrals by
/// `boundary` (e.g. [`boundary_rule`]). [`VciOrder::Off`] restores `dpsi_test = dpsi`. Repeated
/// calls do not accumulate: each starts from `dpsi`.
pub fn apply_vci(
    model: &mut ShellModel,
    order: VciOrder,
    boundary: &BoundaryRule,
) -> Result<VciReport, ShellError> {
    let pts = ModelPoints(model);
    let correction = VciCorrection::with_coupling(
        &model.shape_functions,
        boundary,
        &pts,
        order,
        VciCoupling::PartitionOfNullity,
    )
    .map_err(vci_error)?;
    let worst = |corrected: bool| {
        correction
            .defects(&pts, corrected)
            .iter()
            .enumerate()
            .filter(|(i, _)| correction.achieved(*i) == order)
            .fold(0.0_f64, |m, (_, d)| m.max(d.rel))
    };
    let defect_before = worst(false);
    let defect_after = worst(true);
    for (k, p) in model.points.iter_mut().enumerate() {
        for (&i, s) in p.neighbours.iter().zip(p.shape.iter_mut()) {
            s.dpsi_test = correction.corrected_gradient_at(i, k, p.uv, s.dpsi);
        }
    }
    Ok(VciReport {
        degraded: correction.degraded(),
        iterations: correction.iterations(),
        correction,
        defect_before,
        defect_after,
    })
}

fn vci_error(e: VciError) -> ShellError {
    match e {
        VciError::Shape(source) => ShellError::Shape {
            context: "at a boundary point of the VCI contour integrals: ",
            source,
        },
        other => ShellError::InvalidInput(other.to_string()),
    }
}
