//! Conversions between 3×3 lamina-frame tensors and the shell 5-vectors of the material module
//! (eqs 3 and 8): stresses `[σ11, σ22, σ12, σ23, σ31]`, strains `[ε11, ε22, 2ε12, 2ε23, 2ε31]`.
//! The thickness components (`σ33`, `ε33`) are not part of the 5-vectors.

use super::M3;
use crate::material::Vec5;
use crate::scalar::Real;

/// Shell strain vector `[e11, e22, 2e12, 2e23, 2e31]` of a lamina-frame strain tensor. Shear
/// entries use both off-diagonal entries (`e12 + e21`, …), which is `2e12` for a symmetric
/// tensor and the symmetric part's engineering shear otherwise; `e33` is dropped.
pub fn strain_to_vec5<T: Real>(m: &M3<T>) -> Vec5<T> {
    Vec5::new(
        m[(0, 0)],
        m[(1, 1)],
        m[(0, 1)] + m[(1, 0)],
        m[(1, 2)] + m[(2, 1)],
        m[(2, 0)] + m[(0, 2)],
    )
}

/// Symmetric strain tensor from a shell strain vector; `ε33 = 0` (the thickness strain is not
/// carried by the 5-vector).
pub fn strain_from_vec5<T: Real>(v: &Vec5<T>) -> M3<T> {
    let h = T::cst(0.5);
    let (e12, e23, e31) = (v[2] * h, v[3] * h, v[4] * h);
    M3::new(v[0], e12, e31, e12, v[1], e23, e31, e23, T::zero())
}

/// Shell stress vector `[s11, s22, s12, s23, s31]` of a lamina-frame stress tensor (off-diagonal
/// entries averaged, exact for a symmetric tensor); `s33` is dropped.
pub fn stress_to_vec5<T: Real>(m: &M3<T>) -> Vec5<T> {
    let h = T::cst(0.5);
    Vec5::new(
        m[(0, 0)],
        m[(1, 1)],
        (m[(0, 1)] + m[(1, 0)]) * h,
        (m[(1, 2)] + m[(2, 1)]) * h,
        (m[(2, 0)] + m[(0, 2)]) * h,
    )
}

/// Symmetric lamina-frame stress tensor from a shell stress vector, with `σ33 = 0` (eq 1).
pub fn stress_from_vec5<T: Real>(v: &Vec5<T>) -> M3<T> {
    M3::new(v[0], v[2], v[4], v[2], v[1], v[3], v[4], v[3], T::zero())
}
