//! Finite rotation of a particle's director by two rotation parameters (the shell's 4th and 5th
//! degrees of freedom), with hand-derived first and second derivatives for the tangent.
//!
//! `d(α) = exp([θ]×) dⁿ`, `θ = α1 e1 + α2 e2` with `e1, e2 ⟂ dⁿ` the particle's lamina vectors.
//! Rodrigues' formula in terms of `x = θ·θ = s²`:
//! `d = dⁿ + f1(x) θ×dⁿ + f2(x) θ×(θ×dⁿ)`, `f1 = sin s / s`, `f2 = (1 − cos s)/s²`.
//! Both coefficients are entire functions of `x`. They are evaluated by their power series for
//! `x < 4` (no square root, so dual numbers stay finite at θ = 0) and in closed form beyond.

use crate::scalar::Real;
use nalgebra::Vector3;

type V3<T> = Vector3<T>;

/// Number of series terms: `x^k/(2k+1)!` at `x = 4`, `k = 16` is below 1e-21.
const TERMS: usize = 17;
/// Series below this `x = s²`, closed forms above.
const SERIES_LIMIT: f64 = 4.0;

/// `(2k+1)!` and `(2k+2)!` as f64 for k < TERMS.
fn factorials() -> ([f64; TERMS], [f64; TERMS]) {
    let mut odd = [0.0; TERMS];
    let mut even = [0.0; TERMS];
    let mut f = 1.0; // 1!
    for k in 0..TERMS {
        odd[k] = f; // (2k+1)!
        f *= (2 * k + 2) as f64;
        even[k] = f; // (2k+2)!
        f *= (2 * k + 3) as f64;
    }
    (odd, even)
}

/// `(f1, f2)` of Rodrigues' formula as functions of `x = s²`.
pub fn rodrigues_coefficients<T: Real>(x: T) -> (T, T) {
    if x.value() < SERIES_LIMIT {
        let (odd, even) = factorials();
        let mut f1 = T::zero();
        let mut f2 = T::zero();
        let mut p = T::one();
        for k in 0..TERMS {
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            f1 += p * (sign / odd[k]);
            f2 += p * (sign / even[k]);
            p *= x;
        }
        (f1, f2)
    } else {
        let s = x.sqrt();
        (s.sin() / s, (T::one() - s.cos()) / x)
    }
}

/// `(f1, f2, f1', f2')` with `' = d/dx`, generic (the virtual director of the residual needs the
/// first derivatives in the scalar type).
pub fn rodrigues_with_first_derivatives<T: Real>(x: T) -> (T, T, T, T) {
    if x.value() < SERIES_LIMIT {
        let (odd, even) = factorials();
        let (mut f1, mut f2, mut f1p, mut f2p) = (T::zero(), T::zero(), T::zero(), T::zero());
        let mut p = T::one(); // x^k
        let mut q = T::zero(); // k x^(k−1)
        for k in 0..TERMS {
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            f1 += p * (sign / odd[k]);
            f2 += p * (sign / even[k]);
            f1p += q * (sign / odd[k]);
            f2p += q * (sign / even[k]);
            q = q * x + p;
            p *= x;
        }
        (f1, f2, f1p, f2p)
    } else {
        let s = x.sqrt();
        let (sn, cs) = (s.sin(), s.cos());
        let f1 = sn / s;
        let f1p = (s * cs - sn) / (s * s * s * 2.0);
        let f2 = (T::one() - cs) / x;
        let f2p = (s * sn - cs * (-2.0) - T::cst(2.0)) / (x * x * 2.0);
        (f1, f2, f1p, f2p)
    }
}

/// `[f, f', f'']` (derivatives with respect to `x = s²`) of `f1` and of `f2`, in f64.
pub fn rodrigues_coefficient_derivatives(x: f64) -> ([f64; 3], [f64; 3]) {
    if x < SERIES_LIMIT {
        let (odd, even) = factorials();
        let mut a = [0.0; 3];
        let mut b = [0.0; 3];
        // Running powers x^k, x^(k−1), x^(k−2) (the negative powers enter with factor 0).
        let (mut pk, mut pk1, mut pk2) = (1.0, 0.0, 0.0);
        for k in 0..TERMS {
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            let kf = k as f64;
            let (co, ce) = (sign / odd[k], sign / even[k]);
            let t = [pk, kf * pk1, kf * (kf - 1.0) * pk2];
            for m in 0..3 {
                a[m] += t[m] * co;
                b[m] += t[m] * ce;
            }
            (pk2, pk1, pk) = (pk1, pk, pk * x);
        }
        (a, b)
    } else {
        let s = x.sqrt();
        let (sn, cs) = s.sin_cos();
        let f1 = sn / s;
        let f1p = (s * cs - sn) / (2.0 * s * s * s);
        let f1pp = (3.0 * sn - 3.0 * s * cs - s * s * sn) / (4.0 * s.powi(5));
        let f2 = (1.0 - cs) / x;
        let f2p = (s * sn - 2.0 + 2.0 * cs) / (2.0 * x * x);
        let f2pp = (x * cs - 5.0 * s * sn + 8.0 - 8.0 * cs) / (4.0 * x * x * x);
        ([f1, f1p, f1pp], [f2, f2p, f2pp])
    }
}

/// The rotated director `d(α) = exp([α1 e1 + α2 e2]×) dⁿ`.
pub fn rotate_director<T: Real>(dn: &V3<T>, e1: &V3<T>, e2: &V3<T>, alpha: [T; 2]) -> V3<T> {
    let theta = e1 * alpha[0] + e2 * alpha[1];
    let (f1, f2) = rodrigues_coefficients(theta.dot(&theta));
    let c = theta.cross(dn);
    dn + c * f1 + theta.cross(&c) * f2
}

/// The director and its first and second derivatives with respect to `(α1, α2)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DirectorDerivatives {
    /// `d(α)`.
    pub d: V3<f64>,
    /// `∂d/∂α_β`.
    pub d_a: [V3<f64>; 2],
    /// `∂²d/∂α_β∂α_γ` (symmetric).
    pub d_ab: [[V3<f64>; 2]; 2],
}

/// Hand-derived derivatives of [`rotate_director`]. With `c = θ×dⁿ`, `x = θ·θ`,
/// `x_β = 2 θ·e_β`, `c_β = e_β×dⁿ`, `w_β = e_β×c + θ×c_β`:
/// `∂d/∂α_β = f1' x_β c + f1 c_β + f2' x_β θ×c + f2 w_β`, and the second derivatives follow by the
/// product rule with `∂x_β/∂α_γ = 2 e_β·e_γ`, `∂w_β/∂α_γ = e_β×c_γ + e_γ×c_β`.
pub fn director_derivatives(
    dn: &V3<f64>,
    e1: &V3<f64>,
    e2: &V3<f64>,
    alpha: [f64; 2],
) -> DirectorDerivatives {
    let e = [*e1, *e2];
    let theta = e1 * alpha[0] + e2 * alpha[1];
    let x = theta.dot(&theta);
    let ([f1, f1p, f1pp], [f2, f2p, f2pp]) = rodrigues_coefficient_derivatives(x);
    let c = theta.cross(dn);
    let tc = theta.cross(&c);
    let xb = [2.0 * theta.dot(&e[0]), 2.0 * theta.dot(&e[1])];
    let cb = [e[0].cross(dn), e[1].cross(dn)];
    let wb = [
        e[0].cross(&c) + theta.cross(&cb[0]),
        e[1].cross(&c) + theta.cross(&cb[1]),
    ];
    let d = dn + c * f1 + tc * f2;
    let d_a =
        std::array::from_fn(|b| c * (f1p * xb[b]) + cb[b] * f1 + tc * (f2p * xb[b]) + wb[b] * f2);
    let d_ab = std::array::from_fn(|b| {
        std::array::from_fn(|g| {
            let xbg = 2.0 * e[b].dot(&e[g]);
            let wbg = e[b].cross(&cb[g]) + e[g].cross(&cb[b]);
            c * (f1pp * xb[g] * xb[b] + f1p * xbg)
                + cb[g] * (f1p * xb[b])
                + cb[b] * (f1p * xb[g])
                + tc * (f2pp * xb[g] * xb[b] + f2p * xbg)
                + wb[g] * (f2p * xb[b])
                + wb[b] * (f2p * xb[g])
                + wbg * f2
        })
    });
    DirectorDerivatives { d, d_a, d_ab }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scalar::Dual;

    #[test]
    fn coefficients_match_closed_forms_and_are_continuous_at_the_switch() {
        for &x in &[1e-8f64, 0.01, 0.5, 2.0, 3.999_999, 4.0, 9.0] {
            let s: f64 = x.sqrt();
            let (f1, f2) = rodrigues_coefficients(x);
            // Closed forms lose ~ε/x relative accuracy to cancellation for small x.
            let tol = 1e-15 + 1e-16 / x;
            assert!((f1 - s.sin() / s).abs() <= tol, "f1 at {x}");
            assert!((f2 - (1.0 - s.cos()) / x).abs() <= tol, "f2 at {x}");
        }
        // Derivatives: series and closed forms agree across the switch at x = 4.
        let (a, b) = rodrigues_coefficient_derivatives(4.0 - 1e-12);
        let (c, d) = rodrigues_coefficient_derivatives(4.0);
        for k in 0..3 {
            assert!(
                (a[k] - c[k]).abs() <= 1e-12 * c[k].abs().max(1e-3),
                "f1^({k})"
            );
            assert!(
                (b[k] - d[k]).abs() <= 1e-12 * d[k].abs().max(1e-3),
                "f2^({k})"
            );
        }
    }

    #[test]
    fn director_stays_unit_and_derivatives_match_duals() {
        let dn = V3::new(0.2, -0.3, 0.9).normalize();
        let e1 = V3::new(1.0, 0.0, 0.0).cross(&dn).normalize();
        let e2 = dn.cross(&e1);
        for alpha in [[0.0, 0.0], [0.3, -0.2], [1.5, 1.2], [-2.0, 0.4]] {
            let h = director_derivatives(&dn, &e1, &e2, alpha);
            assert!((h.d.norm() - 1.0).abs() < 1e-15);
            for b in 0..2 {
                let ad: [Dual; 2] = std::array::from_fn(|i| {
                    if i == b {
                        Dual::from_re(alpha[i]).derivative()
                    } else {
                        Dual::from_re(alpha[i])
                    }
                });
                let dd = rotate_director(
                    &dn.map(Dual::from_re),
                    &e1.map(Dual::from_re),
                    &e2.map(Dual::from_re),
                    ad,
                );
                let first = dd.map(|v| v.eps);
                assert!((first - h.d_a[b]).norm() < 1e-14, "∂d/∂α{b} at {alpha:?}");
                // Second derivatives against a dual derivative of the hand first derivative.
                for g in 0..2 {
                    let step = 1e-6;
                    let mut ap = alpha;
                    let mut am = alpha;
                    ap[g] += step;
                    am[g] -= step;
                    let fd = (director_derivatives(&dn, &e1, &e2, ap).d_a[b]
                        - director_derivatives(&dn, &e1, &e2, am).d_a[b])
                        / (2.0 * step);
                    // Central difference: truncation ~h² = 1e-12, round-off ~ε/h = 2e-10.
                    assert!(
                        (fd - h.d_ab[b][g]).norm() < 1e-9,
                        "∂²d/∂α{b}∂α{g} at {alpha:?}"
                    );
                }
            }
        }
    }
}
