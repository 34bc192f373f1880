//! The unit director of a point from the RK interpolant of the particles' directors
//! (docs/stability.md §9): `d = N(r) = r/|r|`, `r = n⁰ + Σ Ψ_I (d_I − d_I⁰)`, and
//! `d,α = N′(r) r,α`.
//!
//! `N = ∇ℓ` with `ℓ(r) = |r|`, so its derivatives are those of `ℓ` and fully symmetric:
//! - `N′ = ∇²ℓ = (I − d dᵀ)/ℓ` ([`n_prime`]);
//! - `y · N″[a, b] = aᵀ H(y) b` with `H(y) = ∇³ℓ · y`
//!   `= −(y rᵀ + r yᵀ + (y·r) I)/ℓ³ + 3 (y·r) r rᵀ/ℓ⁵` ([`n_second`]); by the symmetry
//!   `N″[a, b] = H(b) a`;
//! - `y · N‴[a, v, b] = aᵀ T(y, b) v` with `T(y, b) = ∇⁴ℓ · y · b` ([`n_third`]).
//!
//! Normalising at the point makes the director's length independent of how the particles'
//! directors vary between them: a rotation pattern that the RK functions filter out can no
//! longer shorten `d` (`Σ Ψ_I R(±α) d = cos α d` for a sign that alternates from particle to
//! particle), which with the interpolant alone releases bending energy at second order in `α`
//! and leaves that pattern without stiffness under load.
//!
//! The value kernels are generic over [`Real`]; the derivative kernels are f64, checked against
//! dual numbers in `tests/unit_director.rs`.

use super::M3;
use crate::scalar::Real;
use nalgebra::Vector3;

type V3<T> = Vector3<T>;

/// `N(r) = r/|r|`, `N′(r) r,α` and `|r|`.
pub fn normalise<T: Real>(r: &V3<T>, r_a: &[V3<T>; 2]) -> (V3<T>, [V3<T>; 2], T) {
    let l = r.norm();
    let d = r / l;
    let d_a = r_a.map(|v| (v - d * d.dot(&v)) / l);
    (d, d_a, l)
}

/// `N′ y = (y − d (d·y))/ℓ` without forming `N′` ([`n_prime`]), generic.
pub fn n_prime_apply<T: Real>(d: &V3<T>, l: T, y: &V3<T>) -> V3<T> {
    (y - d * d.dot(y)) / l
}

/// `H(y) b = (y·N″[·, b])` without forming `H(y)` ([`n_second`]), generic:
/// `[3 (y·d)(b·d) d − (b·d) y − (y·b) d − (y·d) b]/ℓ²`.
pub fn n_second_apply<T: Real>(d: &V3<T>, l: T, y: &V3<T>, b: &V3<T>) -> V3<T> {
    let (yd, bd) = (y.dot(d), b.dot(d));
    (d * (yd * bd * 3.0) - y * bd - d * y.dot(b) - b * yd) / (l * l)
}

/// The change of the unit director and its derivatives over a step, `(d₁ − dₙ, d₁,α − dₙ,α)`,
/// for `r₁ = rₙ + δ`, `r₁,α = rₙ,α + δ,α`, formed without cancellation (its absolute error is
/// of the order of ε |δ|, not ε: the transverse shear stiffness would turn the latter into a
/// residual floor). Also returns `d₁`, `d₁,α`, `dₙ`, `dₙ,α` and `ℓ₁ = |r₁|`.
pub fn step_change<T: Real>(
    rn: &V3<T>,
    rn_a: &[V3<T>; 2],
    delta: &V3<T>,
    delta_a: &[V3<T>; 2],
) -> UnitDirectorStep<T> {
    let ln2 = rn.dot(rn);
    let ln = ln2.sqrt();
    let r1 = rn + delta;
    let r1_a = [rn_a[0] + delta_a[0], rn_a[1] + delta_a[1]];
    let l1 = r1.norm();
    // ℓ₁² − ℓₙ² = 2 rₙ·δ + δ·δ.
    let dl2 = rn.dot(delta) * 2.0 + delta.dot(delta);
    // 1/ℓ₁ − 1/ℓₙ = (ℓₙ − ℓ₁)/(ℓ₁ℓₙ) = −(ℓ₁² − ℓₙ²)/(ℓ₁ℓₙ(ℓ₁ + ℓₙ)).
    let inv_diff = -dl2 / (l1 * ln * (l1 + ln));
    let dn = rn / ln;
    let d1 = r1 / l1;
    let dd = delta / l1 + rn * inv_diff;
    // 1/ℓ₁² − 1/ℓₙ² = −(ℓ₁² − ℓₙ²)/(ℓ₁²ℓₙ²).
    let inv2_diff = -dl2 / (l1 * l1 * ln2);
    let mut dd_a = [V3::zeros(), V3::zeros()];
    let mut dn_a = [V3::zeros(), V3::zeros()];
    let mut d1_a = [V3::zeros(), V3::zeros()];
    for a in 0..2 {
        // d,α = r,α/ℓ − d c with c = (r·r,α)/ℓ² (= (d·r,α)/ℓ).
        let cn = rn.dot(&rn_a[a]) / ln2;
        let e = delta.dot(&rn_a[a]) + rn.dot(&delta_a[a]) + delta.dot(&delta_a[a]);
        let c1 = cn + rn.dot(&rn_a[a]) * inv2_diff + e / (l1 * l1);
        dn_a[a] = rn_a[a] / ln - dn * cn;
        d1_a[a] = r1_a[a] / l1 - d1 * c1;
        // d₁c₁ − dₙcₙ = (d₁ − dₙ) c₁ + dₙ (c₁ − cₙ).
        dd_a[a] = delta_a[a] / l1 + rn_a[a] * inv_diff
            - (dd * c1 + dn * (rn.dot(&rn_a[a]) * inv2_diff + e / (l1 * l1)));
    }
    UnitDirectorStep {
        dn,
        dn_a,
        d1,
        d1_a,
        dd,
        dd_a,
        l1,
        r1_a,
        ln,
        inv_diff,
        inv2_diff,
        delta_a: *delta_a,
    }
}

/// The unit director at the start and end of a step ([`step_change`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnitDirectorStep<T> {
    /// `dₙ`, `dₙ,α`.
    pub dn: V3<T>,
    /// `dₙ,α`.
    pub dn_a: [V3<T>; 2],
    /// `d₁`.
    pub d1: V3<T>,
    /// `d₁,α`.
    pub d1_a: [V3<T>; 2],
    /// `d₁ − dₙ`.
    pub dd: V3<T>,
    /// `d₁,α − dₙ,α`.
    pub dd_a: [V3<T>; 2],
    /// `ℓ₁ = |r₁|`.
    pub l1: T,
    /// `r₁,α`.
    pub r1_a: [V3<T>; 2],
    /// `ℓₙ = |rₙ|`.
    pub ln: T,
    /// `1/ℓ₁ − 1/ℓₙ`.
    pub inv_diff: T,
    /// `1/ℓ₁² − 1/ℓₙ²`.
    pub inv2_diff: T,
    /// `δ,α = r₁,α − rₙ,α` as given.
    pub delta_a: [V3<T>; 2],
}

impl UnitDirectorStep<f64> {
    /// `N′(r₁) − N′(rₙ)`, formed from the differences of the step (no cancellation):
    /// `(1/ℓ₁ − 1/ℓₙ)(I − dₙdₙᵀ) − (δd d₁ᵀ + dₙ δdᵀ)/ℓ₁`, `δd = d₁ − dₙ`.
    pub fn n_prime_change(&self) -> M3<f64> {
        let (dn, d1, dd) = (&self.dn, &self.d1, &self.dd);
        (M3::identity() - dn * dn.transpose()) * self.inv_diff
            - (dd * d1.transpose() + dn * dd.transpose()) / self.l1
    }

    /// `H(r₁,α)|₁ − H(rₙ,α)|ₙ` ([`n_second`] at the two ends with `y = r,α`), formed from the
    /// differences of the step: with `A(y, d) = 3 (y·d) ddᵀ − y dᵀ − d yᵀ − (y·d) I`,
    /// `H = A/ℓ²`, the change is `ΔA/ℓ₁² + Aₙ (1/ℓ₁² − 1/ℓₙ²)` and `ΔA` follows by the
    /// product rule on the accurate changes `δy = r₁,α − rₙ,α`, `δd`, `δ(y·d) = δy·d₁ + yₙ·δd`.
    pub fn n_second_change(&self, a: usize, rn_a: &V3<f64>) -> M3<f64> {
        let (dn, d1, dd) = (&self.dn, &self.d1, &self.dd);
        let (yn, y1) = (rn_a, &self.r1_a[a]);
        let dy = self.delta_a[a];
        let (sn, ds) = (yn.dot(dn), dy.dot(d1) + yn.dot(dd));
        let id = M3::identity();
        let dn2 = dn * dn.transpose();
        let d12 = d1 * d1.transpose();
        let dd2 = dd * d1.transpose() + dn * dd.transpose();
        let a_n = dn2 * (3.0 * sn) - yn * dn.transpose() - dn * yn.transpose() - id * sn;
        let da = (d12 * ds + dd2 * sn) * 3.0
            - (dy * d1.transpose() + yn * dd.transpose())
            - (dd * y1.transpose() + dn * dy.transpose())
            - id * ds;
        da / (self.l1 * self.l1) + a_n * self.inv2_diff
    }
}

/// `N′(r) = (I − d dᵀ)/ℓ`, from `d = r/ℓ` and `ℓ`.
pub fn n_prime(d: &V3<f64>, l: f64) -> M3<f64> {
    (M3::identity() - d * d.transpose()) / l
}

/// `H(y) = ∇³ℓ · y = −(y rᵀ + r yᵀ + (y·r) I)/ℓ³ + 3 (y·r) r rᵀ/ℓ⁵`, written with `d = r/ℓ`:
/// `−(y dᵀ + d yᵀ + (y·d) I)/ℓ² + 3 (y·d) d dᵀ/ℓ²`.
pub fn n_second(d: &V3<f64>, l: f64, y: &V3<f64>) -> M3<f64> {
    let yd = y.dot(d);
    let ddt = d * d.transpose();
    (ddt * (3.0 * yd) - y * d.transpose() - d * y.transpose() - M3::identity() * yd) / (l * l)
}

/// `T(y, b) = ∇⁴ℓ · y · b`, written with `d = r/ℓ`:
/// `[−(y·b)(I − 3ddᵀ) − (y bᵀ + b yᵀ) + 3 (b·d)(y dᵀ + d yᵀ) + 3 (y·d)(b dᵀ + d bᵀ)
///   + 3 (y·d)(b·d)(I − 5 d dᵀ)]/ℓ³`.
pub fn n_third(d: &V3<f64>, l: f64, y: &V3<f64>, b: &V3<f64>) -> M3<f64> {
    let (yb, yd, bd) = (y.dot(b), y.dot(d), b.dot(d));
    let id = M3::identity();
    let ddt = d * d.transpose();
    let m = (id - ddt * 3.0) * (-yb) - (y * b.transpose() + b * y.transpose())
        + (y * d.transpose() + d * y.transpose()) * (3.0 * bd)
        + (b * d.transpose() + d * b.transpose()) * (3.0 * yd)
        + (id - ddt * 5.0) * (3.0 * yd * bd);
    m / (l * l * l)
}
