//! The Hughes–Winget incremental rotation (eqs 23, 28, 29, 31) and its material derivatives
//! (eqs 54, 55, 58).

use super::{check_det, check_finite, skew, sym, KinematicsError, M3};
use crate::scalar::Real;

/// Increments of one step from the mid-step gradient `L` ([`hughes_winget`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HwIncrement<T> {
    /// Strain increment `Δε = sym L` (eq 28), global components at the mid-step configuration.
    pub deps: M3<T>,
    /// Rotation increment `Δω = skew L` (eq 29).
    pub domega: M3<T>,
    /// Incremental rotation `r = (I − ½Δω)⁻¹(I + ½Δω) = I + (I − ½Δω)⁻¹Δω` (eq 23).
    pub r: M3<T>,
    /// Half-step rotation `½r = (I − ¼Δω)⁻¹(I + ¼Δω) = I + ½(I − ¼Δω)⁻¹Δω` (eq 31). It is
    /// orthogonal, but `½r ½r ≠ r` (a second-order difference, as the paper notes).
    pub r_half: M3<T>,
}

impl<T: Real> HwIncrement<T> {
    /// Real parts.
    pub fn value(&self) -> HwIncrement<f64> {
        HwIncrement {
            deps: super::value_of(&self.deps),
            domega: super::value_of(&self.domega),
            r: super::value_of(&self.r),
            r_half: super::value_of(&self.r_half),
        }
    }
}

/// Material derivatives of an [`HwIncrement`] ([`hughes_winget_dot`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HwIncrementDot {
    /// `Δε̇ = sym L̇` (eq 58).
    pub deps_dot: M3<f64>,
    /// `Δω̇ = skew L̇` (eq 58).
    pub domega_dot: M3<f64>,
    /// `ṙ = (2I − Δω)⁻¹ Δω̇ (I + r)` (eqs 54–55, `B^σ`, confirmed).
    pub r_dot: M3<f64>,
    /// `½ṙ = (4I − Δω)⁻¹ Δω̇ (I + ½r)` (eqs 54–55, `B^ε` corrected: the transcription has `r`).
    pub r_half_dot: M3<f64>,
}

/// `(I − aW)⁻¹` for a skew `W = [w]×` in closed form: `I + (aW + a²W²)/(1 + a²|w|²)`, with
/// `det(I − aW) = 1 + a²|w|²`. (Check: `W³ = −|w|²W`.) Returns the inverse and the determinant.
fn skew_resolvent<T: Real>(w: &M3<T>, a: f64) -> (M3<T>, T) {
    let w2 = w[(2, 1)] * w[(2, 1)] + w[(0, 2)] * w[(0, 2)] + w[(1, 0)] * w[(1, 0)];
    let det = w2 * (a * a) + T::one();
    let aw = w * T::cst(a);
    let inv = M3::<T>::identity() + (aw + aw * aw) / det;
    (inv, det)
}

/// The Cayley transform `(I − aW)⁻¹(I + aW) = 2(I − aW)⁻¹ − I` of a skew `W`: orthogonal with
/// determinant 1 for every finite `W`.
fn cayley<T: Real>(w: &M3<T>, a: f64, what: &'static str) -> Result<M3<T>, KinematicsError> {
    let (inv, det) = skew_resolvent(w, a);
    check_det(what, det.value())?;
    Ok(inv * T::cst(2.0) - M3::<T>::identity())
}

/// Strain increment, rotation increment and the incremental rotations of one step (eqs 23,
/// 28, 29, 31) from the mid-step gradient `L = ∂Δz/∂ⁿ⁺½x` ([`super::mid_step_gradient`]).
///
/// `Δω` is exactly antisymmetric in floating point, so `det(I − ½Δω) = 1 + ¼|ω|² ≥ 1` and the
/// inverses exist for every finite `L`; the only failures are a non-finite entry of `L` and an
/// overflow of `|ω|²`.
pub fn hughes_winget<T: Real>(l: &M3<T>) -> Result<HwIncrement<T>, KinematicsError> {
    check_finite("L = ∂Δz/∂ⁿ⁺½x", l)?;
    let deps = sym(l);
    let domega = skew(l);
    let r = cayley(&domega, 0.5, "I − ½Δω")?;
    let r_half = cayley(&domega, 0.25, "I − ¼Δω")?;
    Ok(HwIncrement {
        deps,
        domega,
        r,
        r_half,
    })
}

/// Hand-derived material derivatives of [`hughes_winget`] for a given `L̇` (eqs 54, 55, 58).
///
/// With `r = (I − ½Δω)⁻¹(I + ½Δω)`:
/// `ṙ = (I − ½Δω)⁻¹ ½Δω̇ r + (I − ½Δω)⁻¹ ½Δω̇ = (2I − Δω)⁻¹ Δω̇ (I + r)`, which is eq 55's
/// `B^σ_ijkl = (2δ_ik − Δω_ik)⁻¹(δ_lj + r_lj)` (confirmed). The same steps with ¼ give
/// `½ṙ = (4I − Δω)⁻¹ Δω̇ (I + ½r)`: eq 55's `B^ε` as transcribed, with `r` in place of `½r`, is
/// wrong; the dual-number reference agrees with `½r` (to round-off) and not with `r` (see
/// `tests/kinematics.rs`).
pub fn hughes_winget_dot(inc: &HwIncrement<f64>, l_dot: &M3<f64>) -> HwIncrementDot {
    let deps_dot = sym(l_dot);
    let domega_dot = skew(l_dot);
    let id = M3::<f64>::identity();
    // (2I − Δω)⁻¹ = ½(I − ½Δω)⁻¹ and (4I − Δω)⁻¹ = ¼(I − ¼Δω)⁻¹; both exist (det ≥ 1).
    let (inv_half, _) = skew_resolvent(&inc.domega, 0.5);
    let (inv_quarter, _) = skew_resolvent(&inc.domega, 0.25);
    let r_dot = inv_half * domega_dot * (id + inc.r) * 0.5;
    let r_half_dot = inv_quarter * domega_dot * (id + inc.r_half) * 0.25;
    HwIncrementDot {
        deps_dot,
        domega_dot,
        r_dot,
        r_half_dot,
    }
}
