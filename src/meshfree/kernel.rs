//! The kernel functions (cubic B-spline, quartic spline) and their tensor-product 2-D form.

use crate::scalar::Real;

/// The window function `φ` of the RK approximation.
///
/// The two differ in what a particle lattice of spacing `h` hides from them. The cubic B-spline
/// of half-width `a` has knots `a/2` apart, so its Fourier transform is `∝ sinc⁴(ω a/4)`, with
/// fourth-order zeros at `ω a = 4πk`. From `a = 4h` on the first lies in the band the particles
/// resolve (`ω ≤ π/h`): coefficient patterns of wavelength near `a/2` pass almost nothing, and
/// at multiples of `4h` the zero meets the two-spacing wavelength, where a pattern alternating
/// from particle to particle passes nothing at all (on a complete lattice the tangent is
/// singular; docs/stability.md §6). The quartic spline's transform has no zero: its smallest
/// local minima are `|φ̂|/φ̂(0)` = 7.6e-3 at `ω a` = 9.6 and 9.8e-4 at 15.8. The largest
/// alternating sum `|Σ_i (−1)^i φ((x − i h)/a)| / Σ_i φ((x − i h)/a)` over `x` is
/// 1.5e-2 / 1.5e-2 / 2.0e-3 / 2.9e-3 at `a/h` = 3 / 4 / 5 / 6 (cubic B-spline: 1.6e-2 / 0 /
/// 2.1e-3 / 4.1e-3, and 0 at 8).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum KernelFunction {
    /// [`cubic_bspline`].
    #[default]
    CubicSpline,
    /// [`quartic_spline`].
    QuarticSpline,
}

/// Supports within this many spacings of a multiple of 4 are near the cubic B-spline's blind
/// spot ([`KernelFunction`]). Measured with the cubic B-spline on a complete lattice between
/// symmetry planes: 4 ± 0.1 spacings gave a singular tangent, 3.8 and 4.2 did not.
pub const RESONANT_SUPPORT_BAND: f64 = 0.15;

impl KernelFunction {
    /// `[φ, φ', φ'']` at `z = |d|/a ≥ 0`.
    #[inline]
    pub fn eval<T: Real>(self, z: T) -> [T; 3] {
        match self {
            KernelFunction::CubicSpline => cubic_bspline(z),
            KernelFunction::QuarticSpline => quartic_spline(z),
        }
    }

    /// Whether this kernel is (nearly) blind, on a regular lattice, to coefficient patterns
    /// alternating from particle to particle at a support of `spacings` particle spacings: the
    /// cubic B-spline within [`RESONANT_SUPPORT_BAND`] of a non-zero multiple of 4; the quartic
    /// spline never.
    pub fn blind_at(self, spacings: f64) -> bool {
        match self {
            KernelFunction::CubicSpline => {
                let k = (spacings / 4.0).round();
                k >= 1.0 && (spacings - 4.0 * k).abs() <= RESONANT_SUPPORT_BAND
            }
            KernelFunction::QuarticSpline => false,
        }
    }

    /// The kernel used when a case does not name one: the cubic B-spline below
    /// `4 − RESONANT_SUPPORT_BAND` spacings, the quartic spline from there on, where the cubic's
    /// first transform zero is in (or at the edge of) the resolved band.
    pub fn default_for(spacings: f64) -> Self {
        if spacings >= 4.0 - RESONANT_SUPPORT_BAND {
            KernelFunction::QuarticSpline
        } else {
            KernelFunction::CubicSpline
        }
    }

    /// The name used in case files and output.
    pub fn name(self) -> &'static str {
        match self {
            KernelFunction::CubicSpline => "cubic-spline",
            KernelFunction::QuarticSpline => "quartic-spline",
        }
    }
}

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

/// Quartic spline `φ(z)` and its first two derivatives `[φ, φ', φ'']` at `z ≥ 0`, scaled to the
/// cubic B-spline's value at the centre:
///
/// ```text
/// φ(z) = (2/3) (1 − 6z² + 8z³ − 3z⁴)     0 ≤ z ≤ 1
///        0                               z > 1
/// ```
///
/// `φ` is C² (`φ(1) = φ'(1) = φ''(1) = 0`, `φ'(0) = 0`); one polynomial piece inside the
/// support. The scale does not change the RK functions (they are invariant under a constant
/// factor of the kernel); it keeps the moment matrices of the same size as the cubic's.
#[inline]
pub fn quartic_spline<T: Real>(z: T) -> [T; 3] {
    if z.value() <= 1.0 {
        let c = 2.0 / 3.0;
        // 1 − 6z² + 8z³ − 3z⁴, −12z + 24z² − 12z³, −12 + 48z − 36z²
        [
            (((z * -3.0 + 8.0) * z - 6.0) * z * z + 1.0) * c,
            ((z * -12.0 + 24.0) * z - 12.0) * z * c,
            ((z * -36.0 + 48.0) * z - 12.0) * c,
        ]
    } else {
        [T::zero(), T::zero(), T::zero()]
    }
}

/// One-dimensional scaled cubic B-spline `φ(|d|/a)` and its derivative with respect to `d`.
#[inline]
pub fn kernel_1d<T: Real>(d: T, a: T) -> [T; 2] {
    kernel_1d_with(KernelFunction::CubicSpline, d, a)
}

/// One-dimensional scaled kernel `φ(|d|/a)` of `kernel` and its derivative with respect to `d`.
#[inline]
pub fn kernel_1d_with<T: Real>(kernel: KernelFunction, d: T, a: T) -> [T; 2] {
    let (z, sign) = if d.value() < 0.0 {
        (-d / a, -1.0)
    } else {
        (d / a, 1.0)
    };
    let [p, dp, _] = kernel.eval(z);
    [p, dp / a * sign]
}

/// Tensor-product cubic B-spline kernel `φ_a(d) = φ(|d_u|/a_u) φ(|d_v|/a_v)` with `d = x − x_I`,
/// and its gradient with respect to `x`: `[φ_a, ∂φ_a/∂u, ∂φ_a/∂v]`.
#[inline]
pub fn tensor_kernel<T: Real>(d: [T; 2], a: [T; 2]) -> [T; 3] {
    tensor_kernel_with(KernelFunction::CubicSpline, d, a)
}

/// Tensor-product kernel of `kernel` ([`tensor_kernel`]).
#[inline]
pub fn tensor_kernel_with<T: Real>(kernel: KernelFunction, d: [T; 2], a: [T; 2]) -> [T; 3] {
    let [pu, dpu] = kernel_1d_with(kernel, d[0], a[0]);
    let [pv, dpv] = kernel_1d_with(kernel, d[1], a[1]);
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
