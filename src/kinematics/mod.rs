//! Finite-deformation shell kinematics: the Hughes–Winget incrementally objective update of the
//! paper's §2.3 (eqs 22–31) and its hand-derived material derivatives of §3 (eqs 42, 50–58).
//!
//! Everything is written with 3×3 tensors ([`M3`]); the paper's 9×9 matrices are notation for
//! the same maps (`R_ijkl = r_ik r_jl` acting on a tensor `A` is `r A rᵀ`, `Q_ijkl` acting on a
//! global tensor is `Q A Qᵀ`).
//!
//! Conventions:
//! - `H = ∂Δz/∂ⁿx`, the gradient of the displacement increment with respect to the step-start
//!   configuration; `L = ∂Δz/∂ⁿ⁺½x` the gradient at the mid-step configuration
//!   ([`mid_step_gradient`]).
//! - The rows of a lamina frame `Q` are the lamina basis vectors: `v_local = Q v_global`, so a
//!   global tensor `A` has local components `Q A Qᵀ` and `A = Qᵀ A_local Q` (eq 26).
//! - Shell 5-vectors follow the material module: stresses `[σ11, σ22, σ12, σ23, σ31]`, strains
//!   `[ε11, ε22, 2ε12, 2ε23, 2ε31]` ([`strain_to_vec5`], [`stress_to_vec5`]).
//!
//! One step of the update, for a material point with lamina frame `Qₙ` and global stress `ⁿσ`:
//! 1. `L = H (I + ½H)⁻¹` ([`mid_step_gradient`]);
//! 2. `Δε = sym L`, `Δω = skew L`, `r = (I − ½Δω)⁻¹(I + ½Δω)`,
//!    `½r = (I − ¼Δω)⁻¹(I + ¼Δω)` ([`hughes_winget`], eqs 23, 28, 29, 31);
//! 3. the strain increment in the lamina frame `Qₙ ½rᵀ Δε ½r Qₙᵀ` ([`local_strain_increment`],
//!    eq 30), handed to the plane-stress return map;
//! 4. `Qₙ₊₁ = Qₙ rᵀ` ([`frame_update`], eq 27), `ⁿ⁺¹σ = r ⁿσ rᵀ + Δσ` ([`rotate_stress`], eq 22),
//!    or equivalently `ⁿ⁺¹σ = Qₙ₊₁ᵀ ⁿ⁺¹σˡ Qₙ₊₁` ([`global_stress`], eq 26).
//!
//! Every kernel is generic over [`Real`], so the dual-number reference differentiates the same
//! code; the hand-derived derivatives (`*_dot`, in f64) are checked against it in
//! `tests/kinematics.rs`.
//!
//! Corrections to the transcribed paper, each decided by the dual-number reference:
//! - eq 30 lost a transpose: `Δεˡ = ⁿQ ½Rᵀ Δεᵍ` (as eq 50 writes it), i.e. `Qₙ ½rᵀ Δε ½r Qₙᵀ`;
//! - eq 55: `B^ε` must carry `½r`, not `r`: `½ṙ = (4I − Δω)⁻¹ Δω̇ (I + ½r)`;
//! - eq 56: the first line's `ⁿx_{p,ⁿ⁺½x_l}` must be `ⁿx_{p,ⁿ⁺¹x_l}`: the bracket `M` acts on
//!   is the rate of the gradient with respect to `ⁿ⁺¹x`, as the second line writes it
//!   ([`mid_step_gradient_dot_from_spatial`]).

mod frames;
mod hughes_winget;
mod midstep;
pub mod rotation;
pub mod unit_director;
mod voigt;

pub use frames::{
    frame_update, frame_update_dot, global_stress, global_stress_dot, local_strain_increment,
    local_strain_increment_dot, local_stress, rotate_stress, rotate_stress_dot,
};
pub use hughes_winget::{hughes_winget, hughes_winget_dot, HwIncrement, HwIncrementDot};
pub use midstep::{mid_step_gradient, mid_step_gradient_dot, mid_step_gradient_dot_from_spatial};
pub use voigt::{strain_from_vec5, strain_to_vec5, stress_from_vec5, stress_to_vec5};

use crate::scalar::Real;
use thiserror::Error;

/// 3×3 matrix (tensor components in one frame).
pub type M3<T> = nalgebra::Matrix3<T>;

/// Smallest determinant accepted for a matrix that is inverted (`I + ½H`, `I − ½Δω`). The
/// matrices inverted here are of unit scale (they equal `I` for a zero increment), so a
/// determinant below this means a collapsed or inverted mid-step configuration, whose inverse
/// would carry no correct digits.
pub const MIN_DET: f64 = 1e-12;

/// Errors of the kinematic kernels. They never panic: a bad input is named and returned.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum KinematicsError {
    /// An input entry that is NaN or infinite.
    #[error("{what}: entry ({row}, {col}) is not finite ({value})")]
    NonFinite {
        /// Which input.
        what: &'static str,
        /// Row of the entry.
        row: usize,
        /// Column of the entry.
        col: usize,
        /// The value given.
        value: f64,
    },
    /// A matrix to invert that is singular, inverted (non-positive determinant) or overflowed.
    #[error(
        "{what} is singular or inverted: det = {det:e} (must be finite and exceed {min_det:e})"
    )]
    Singular {
        /// Which matrix.
        what: &'static str,
        /// Its determinant.
        det: f64,
        /// The smallest accepted determinant.
        min_det: f64,
    },
}

/// Reject a matrix with a non-finite (real-part) entry.
pub(crate) fn check_finite<T: Real>(what: &'static str, m: &M3<T>) -> Result<(), KinematicsError> {
    for col in 0..3 {
        for row in 0..3 {
            let value = m[(row, col)].value();
            if !value.is_finite() {
                return Err(KinematicsError::NonFinite {
                    what,
                    row,
                    col,
                    value,
                });
            }
        }
    }
    Ok(())
}

/// Reject a determinant that is not finite or not above [`MIN_DET`].
pub(crate) fn check_det(what: &'static str, det: f64) -> Result<(), KinematicsError> {
    if det.is_finite() && det > MIN_DET {
        Ok(())
    } else {
        Err(KinematicsError::Singular {
            what,
            det,
            min_det: MIN_DET,
        })
    }
}

/// Symmetric part `½(A + Aᵀ)`.
pub fn sym<T: Real>(a: &M3<T>) -> M3<T> {
    (a + a.transpose()) * T::cst(0.5)
}

/// Skew-symmetric part `½(A − Aᵀ)` (exactly antisymmetric in floating point).
pub fn skew<T: Real>(a: &M3<T>) -> M3<T> {
    (a - a.transpose()) * T::cst(0.5)
}

/// Real parts of a matrix of dual numbers.
pub fn value_of<T: Real>(a: &M3<T>) -> M3<f64> {
    a.map(|v| v.value())
}

/// Lift an f64 matrix to scalar `T` (derivative parts zero).
pub fn lift<T: Real>(a: &M3<f64>) -> M3<T> {
    a.map(T::cst)
}
