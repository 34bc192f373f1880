//! Lamina frames and stress/strain rotations (eqs 22, 26, 27, 30) and their material derivatives
//! (eqs 42, 50, 51). A frame `Q` has the lamina basis vectors as rows: `v_local = Q v_global`.

use super::M3;
use crate::scalar::Real;

/// Strain increment in the lamina frame (eq 30, with the transpose the transcription lost; eq 50
/// has it): `Δεˡ = ⁿQ ½Rᵀ Δεᵍ`, i.e. `Qₙ ½rᵀ Δε ½r Qₙᵀ`.
///
/// `Δε` is computed at the mid-step configuration; `½rᵀ` rotates it back to the step-start
/// orientation, where `Qₙ` resolves it in the lamina frame. Equivalently it is `Δε` resolved in
/// the mid-step frame `Qₙ ½rᵀ`.
pub fn local_strain_increment<T: Real>(q_n: &M3<T>, r_half: &M3<T>, deps: &M3<T>) -> M3<T> {
    let a = q_n * r_half.transpose();
    a * deps * a.transpose()
}

/// Material derivative of [`local_strain_increment`] (eq 50, in 3×3 form): with `A = Qₙ ½rᵀ`,
/// `Ȧ = Q̇ₙ ½rᵀ + Qₙ ½ṙᵀ` and `Δε̇ˡ = Ȧ Δε Aᵀ + A Δε̇ Aᵀ + A Δε Ȧᵀ`.
pub fn local_strain_increment_dot(
    q_n: &M3<f64>,
    q_n_dot: &M3<f64>,
    r_half: &M3<f64>,
    r_half_dot: &M3<f64>,
    deps: &M3<f64>,
    deps_dot: &M3<f64>,
) -> M3<f64> {
    let a = q_n * r_half.transpose();
    let a_dot = q_n_dot * r_half.transpose() + q_n * r_half_dot.transpose();
    let a_deps = a * deps;
    a_dot * deps * a.transpose() + a * deps_dot * a.transpose() + a_deps * a_dot.transpose()
}

/// Lamina frame update (eq 27): `ⁿ⁺¹Qᵀ = R ⁿQᵀ`, i.e. `Qₙ₊₁ = Qₙ rᵀ` (each basis vector
/// rotated by `r`).
pub fn frame_update<T: Real>(q_n: &M3<T>, r: &M3<T>) -> M3<T> {
    q_n * r.transpose()
}

/// Material derivative of [`frame_update`] (eq 51): `Q̇ₙ₊₁ = Q̇ₙ rᵀ + Qₙ ṙᵀ`.
pub fn frame_update_dot(q_n: &M3<f64>, q_n_dot: &M3<f64>, r: &M3<f64>, r_dot: &M3<f64>) -> M3<f64> {
    q_n_dot * r.transpose() + q_n * r_dot.transpose()
}

/// Objective rotation of a global stress (first term of eq 22): `r σ rᵀ`.
pub fn rotate_stress<T: Real>(r: &M3<T>, sigma: &M3<T>) -> M3<T> {
    r * sigma * r.transpose()
}

/// Material derivative of [`rotate_stress`] (the `A^σ B^σ` term of eqs 52–55 when `ṙ` comes from
/// [`super::hughes_winget_dot`]): `ṙ σ rᵀ + r σ̇ rᵀ + r σ ṙᵀ`.
pub fn rotate_stress_dot(
    r: &M3<f64>,
    r_dot: &M3<f64>,
    sigma: &M3<f64>,
    sigma_dot: &M3<f64>,
) -> M3<f64> {
    let r_sigma = r * sigma;
    r_dot * sigma * r.transpose() + r * sigma_dot * r.transpose() + r_sigma * r_dot.transpose()
}

/// Global stress from lamina-frame stress (eq 26): `σᵍ = Qᵀ σˡ Q`.
pub fn global_stress<T: Real>(q: &M3<T>, sigma_local: &M3<T>) -> M3<T> {
    q.transpose() * sigma_local * q
}

/// Lamina-frame stress from global stress (eq 26): `σˡ = Q σᵍ Qᵀ`.
pub fn local_stress<T: Real>(q: &M3<T>, sigma_global: &M3<T>) -> M3<T> {
    q * sigma_global * q.transpose()
}

/// Material derivative of [`global_stress`] (eq 42; the 9×9 `Qᵀ` is quadratic in the entries of
/// the 3×3 `Q`, hence three terms): `σ̇ᵍ = Q̇ᵀ σˡ Q + Qᵀ σ̇ˡ Q + Qᵀ σˡ Q̇`.
pub fn global_stress_dot(
    q: &M3<f64>,
    q_dot: &M3<f64>,
    sigma_l: &M3<f64>,
    sigma_l_dot: &M3<f64>,
) -> M3<f64> {
    let qt_sigma = q.transpose() * sigma_l;
    q_dot.transpose() * sigma_l * q + q.transpose() * sigma_l_dot * q + qt_sigma * q_dot
}
