//! The displacement-increment gradient at the mid-step configuration (used by eqs 28–29) and its
//! material derivative (eqs 56–57).

use super::{check_det, check_finite, KinematicsError, M3};
use crate::scalar::Real;

/// `F½ = ∂ⁿ⁺½x/∂ⁿx = I + ½H` and its inverse, rejecting a singular or inverted mid-step
/// configuration.
fn half_step_deformation_inverse<T: Real>(h: &M3<T>) -> Result<M3<T>, KinematicsError> {
    check_finite("H = ∂Δz/∂ⁿx", h)?;
    let f_half = M3::<T>::identity() + h * T::cst(0.5);
    let det = f_half.determinant();
    check_det("I + ½H", det.value())?;
    f_half.try_inverse().ok_or(KinematicsError::Singular {
        what: "I + ½H",
        det: det.value(),
        min_det: super::MIN_DET,
    })
}

/// Mid-step gradient `L = ∂Δz/∂ⁿ⁺½x = H (I + ½H)⁻¹` from `H = ∂Δz/∂ⁿx`.
///
/// The mid-step configuration is `ⁿ⁺½x = ⁿx + ½Δz`, so `∂ⁿ⁺½x/∂ⁿx = F½ = I + ½H` and
/// `L = H F½⁻¹` (`H` and `F½` commute). Its symmetric and skew parts are the strain and rotation
/// increments of eqs 28–29. For a rigid step `ⁿ⁺¹x = R ⁿx`, `L = 2(R − I)(R + I)⁻¹` is exactly
/// skew, so the strain increment vanishes; the gradient at the step start (`L = H`) would not.
///
/// Errors: a non-finite entry of `H`, or `det(I + ½H) ≤` [`super::MIN_DET`] (collapsed or
/// inverted mid-step configuration, for example a rigid half-turn).
pub fn mid_step_gradient<T: Real>(h: &M3<T>) -> Result<M3<T>, KinematicsError> {
    let f_half_inv = half_step_deformation_inverse(h)?;
    Ok(h * f_half_inv)
}

/// Material derivative of [`mid_step_gradient`]: `L̇ = F½⁻¹ Ḣ F½⁻¹`, `F½ = I + ½H`.
///
/// Derivation: `L̇ = Ḣ F½⁻¹ − H F½⁻¹ (½Ḣ) F½⁻¹ = (I − ½H F½⁻¹) Ḣ F½⁻¹`, and
/// `I − ½H F½⁻¹ = (F½ − ½H) F½⁻¹ = F½⁻¹`. Checked against dual numbers in the tests.
///
/// `ḣ` is the full material derivative of `H = ∂Δz/∂ⁿx` (with the design-velocity term
/// `−H ∇V` of eq 39 included by the caller). Returns a `Result` (unlike the other `*_dot`
/// functions) because it needs `F½⁻¹`, which may not exist.
pub fn mid_step_gradient_dot(h: &M3<f64>, h_dot: &M3<f64>) -> Result<M3<f64>, KinematicsError> {
    check_finite("Ḣ", h_dot)?;
    let f_half_inv = half_step_deformation_inverse(h)?;
    Ok(f_half_inv * h_dot * f_half_inv)
}

/// The paper's form of the same derivative (eqs 56–57): `L̇_ij = M_ijkl Ġ_kl` with
/// `M_ijkl = (∂ⁿx_i/∂ⁿ⁺½x_k)(∂ⁿ⁺¹x_l/∂ⁿ⁺½x_j)`, i.e. `L̇ = F½⁻¹ Ġ (F F½⁻¹)`, `F = I + H`.
///
/// `Ġ = Ḣ F⁻¹ = Δż_{,ⁿ⁺¹x} + ε^V(Δz)` is the bracket of eq 56's second line: the rate of the
/// gradient taken with respect to the end-of-step configuration `ⁿ⁺¹x`. With it, eq 57's `M` is
/// confirmed (the tests check this equals [`mid_step_gradient_dot`] with `Ḣ = Ġ F`); the first
/// line of eq 56, which contracts with `ⁿx_{p,ⁿ⁺½x_l}`, is a transcription error for
/// `ⁿx_{p,ⁿ⁺¹x_l}`.
pub fn mid_step_gradient_dot_from_spatial(
    h: &M3<f64>,
    g_dot: &M3<f64>,
) -> Result<M3<f64>, KinematicsError> {
    check_finite("Ġ", g_dot)?;
    let f_half_inv = half_step_deformation_inverse(h)?;
    let f = M3::identity() + h;
    Ok(f_half_inv * g_dot * (f * f_half_inv))
}
