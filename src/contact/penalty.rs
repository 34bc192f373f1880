//! Penalty contact at one slave point (eqs 69–72).
//!
//! With the penalty `ω` (force per length³: pressure per penetration) and the slave point's area
//! weight `w`, the penalty energy of the point is `P = ½ ω w g²` where `g < 0` (eq 69), and the
//! force on the slave body is
//!
//! `f = −∂P/∂x = −ω w g n` (traction `t = −ω g n`, along `+n`: out of the tool),
//!
//! since `∂g/∂x = n` at an interior projection (`x − x^c = g n`, `n·∂n = 0`, `n·x^c,α = 0`; the
//! paper's `ḡ = n·z̄` below eq 70). Its consistent tangent (eq 72, hand-derived) is
//!
//! `K = ∂f/∂x = −ω w (n ⊗ n + g ∂n/∂x)`, `∂n/∂x = −Σ_γα (m⁻¹ b A⁻¹)_γα x^c,γ ⊗ x^c,α`,
//!
//! from Weingarten's `n,β = −(b m⁻¹)_βγ x^c,γ` and the linearised eq (67),
//! `A ∂ξ/∂x = [x^c,1 x^c,2]ᵀ` with `A = m − g b`, `b_αβ = n·x^c,αβ`. The matrix `m⁻¹ b A⁻¹` is
//! symmetric (its inverse `m b⁻¹ m − g m` is), so `K` is symmetric: the penalty is conservative.
//! Points without an interior projection, or with `g ≥ 0`, carry nothing.

use super::projection::ContactPoint;
use crate::scalar::Real;
use nalgebra::{Matrix3, Vector3};

/// Penalty force `f = −ω w g n` on the slave point for `g < 0` at an interior projection, zero
/// otherwise (eqs 69–70). Generic: with dual numbers through [`super::closest_point`] its
/// Jacobian is the reference of [`penalty_tangent`].
pub fn penalty_force<T: Real>(cp: &ContactPoint<T>, omega: f64, area: f64) -> Vector3<T> {
    if cp.is_active() {
        cp.normal * (cp.gap * (-omega * area))
    } else {
        Vector3::zeros()
    }
}

/// Consistent tangent `∂f/∂x` (3×3) of [`penalty_force`] with respect to the slave point
/// (module documentation), including the curvature term `g ∂n/∂x`.
pub fn penalty_tangent(cp: &ContactPoint<f64>, omega: f64, area: f64) -> Matrix3<f64> {
    if !cp.is_active() {
        return Matrix3::zeros();
    }
    let n = cp.normal;
    let g = cp.gap;
    let m = cp.metric();
    let b = cp.curvature();
    let a = cp.a_matrix();
    let (Some(m_inv), Some(a_inv)) = (m.try_inverse(), a.try_inverse()) else {
        // A singular metric cannot occur at a regular tool point (the tool was validated), and
        // `A` is positive definite at a converged interior projection unless the point lies at
        // a centre of curvature: keep the normal term.
        return n * n.transpose() * (-omega * area);
    };
    let c = m_inv * b * a_inv;
    let t = [cp.surface.xu, cp.surface.xv];
    let mut dn = Matrix3::zeros();
    for (gi, tg) in t.iter().enumerate() {
        for (ai, ta) in t.iter().enumerate() {
            dn -= tg * ta.transpose() * c[(gi, ai)];
        }
    }
    (n * n.transpose() + dn * g) * (-omega * area)
}
