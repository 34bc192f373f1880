//! The cubic B-spline kernel and its tensor-product 2-D form.

use crate::scalar::Real;

/// Cubic B-spline `φ(z)` and its first two derivatives `[φ, φ', φ'']` at `z ≥ 0`:
///
/// ```text
/// φ(z) = 2/3 − 4z² + 4z³                 0 ≤ z ≤ ½
///        4/3 − 4z + 4z² − (4/3)z³        ½ < z ≤ 1
///        0                               z > 1
/// ```
///
/// `φ` is C² (the second derivative is continuous and piecewise linear); `φ(0) = 2/3`, `φ(1) = 0`.
/// The branch is chosen on the real part of `z`, so dual numbers differentiate the active piece.
#[inline]
pub fn cubic_bspline<T: Real>(z: T) -> [T; 3] {
    let zv = z.value();
    if zv <= 0.5 {
        // 2/3 + z²(−4 + 4z), −8z + 12z², −8 + 24z
        [
            (z * 4.0 - 4.0) * z * z + 2.0 / 3.0,
            (z * 12.0 - 8.0) * z,
            z * 24.0 - 8.0,
        ]
    } else if zv <= 1.0 {
        // 4/3 − 4z + 4z² − (4/3)z³ = (4/3)(1 − z)³, −4(1 − z)², 8(1 − z)
        let w = -z + 1.0;
        [w * w * w * (4.0 / 3.0), -(w * w * 4.0), w * 8.0]
    } else {
        [T::zero(), T::zero(), T::zero()]
    }
}

/// One-dimensional scaled kernel `φ(|d|/a)` and its derivative with respect to `d`.
#[inline]
pub fn kernel_1d<T: Real>(d: T, a: T) -> [T; 2] {
    let (z, sign) = if d.value() < 0.0 {
        (-d / a, -1.0)
    } else {
        (d / a, 1.0)
    };
    let [p, dp, _] = cubic_bspline(z);
    [p, dp / a * sign]
}

/// Tensor-product kernel `φ_a(d) = φ(|d_u|/a_u) φ(|d_v|/a_v)` with `d = x − x_I`, and its gradient
/// with respect to `x`: `[φ_a, ∂φ_a/∂u, ∂φ_a/∂v]`.
#[inline]
pub fn tensor_kernel<T: Real>(d: [T; 2], a: [T; 2]) -> [T; 3] {
    let [pu, dpu] = kernel_1d(d[0], a[0]);
    let [pv, dpv] = kernel_1d(d[1], a[1]);
    [pu * pv, dpu * pv, pu * dpv]
}

/// Whether the (open) rectangular support of half-widths `a` centred at `p` covers `x`:
/// `|x_u − p_u| < a_u` and `|x_v − p_v| < a_v`. On the support boundary the kernel is zero, so
/// that particle contributes nothing and is not counted as a neighbour. This one predicate is used
/// by the neighbour search, the brute-force reference and the generic shape functions.
#[inline]
pub fn covers(p: [f64; 2], a: [f64; 2], x: [f64; 2]) -> bool {
    (x[0] - p[0]).abs() < a[0] && (x[1] - p[1]).abs() < a[1]
}
