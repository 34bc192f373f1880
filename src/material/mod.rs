//! Shell material point: plane-stress J2 plasticity with linear combined isotropic–kinematic
//! hardening, in the 5-component shell stress space of the paper (eqs 1–21), its consistent
//! tangent (eq 48) and its hand-derived design sensitivity (eqs 44–49).
//!
//! Vectors are ordered as the paper's eqs (3) and (8):
//! `σ = [σ11, σ22, σ12, σ23, σ31]`, `ε = [ε11, ε22, 2ε12, 2ε23, 2ε31]`, σ33 = 0.
//!
//! The return mapping is Simo and Taylor's projection onto the plane-stress subspace: with
//! `η = σ − α` and `Ξ = [f1 I + λ D P]⁻¹`, `f1 = 1 + ⅔λH(1 − β)`, backward Euler gives
//! `η = Ξ η_tr` (eq 20), and λ is fixed by the consistency condition (eq 21). D and P share their
//! eigenvectors, so `Ξ` is diagonal in that basis and the consistency condition is a scalar
//! equation in λ with a closed form for every term.

mod params;
mod sensitivity;

pub use params::{MaterialError, MaterialParams};
pub use params::{N_PARAMS, PARAM_NAMES};
pub use sensitivity::{
    elastic_matrix_derivative, material_sensitivity, material_sensitivity_terms,
    MaterialSensitivity, MaterialSensitivityTerms, StrainMap,
};

use crate::scalar::Real;
use nalgebra::{SMatrix, SVector};

/// 5-vector of shell stress or strain components.
pub type Vec5<T> = SVector<T, 5>;
/// 5×5 matrix on shell stress/strain vectors.
pub type Mat5<T> = SMatrix<T, 5, 5>;

/// `√(2/3)`.
pub const SQRT_2_3: f64 = 0.816_496_580_927_726;

/// History of a material point (eq 17): stress, back stress and effective plastic strain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaterialState<T> {
    /// Local Cauchy stress `σ` (eq 3).
    pub stress: Vec5<T>,
    /// Back stress `α` (eq 6).
    pub back_stress: Vec5<T>,
    /// Effective plastic strain `ē^p` (eq 15).
    pub eps_p: T,
}

impl<T: Real> MaterialState<T> {
    /// Virgin state: no stress, no back stress, no plastic strain.
    pub fn virgin() -> Self {
        MaterialState {
            stress: Vec5::zeros(),
            back_stress: Vec5::zeros(),
            eps_p: T::zero(),
        }
    }
    /// Real parts.
    pub fn value(&self) -> MaterialState<f64> {
        MaterialState {
            stress: self.stress.map(|v| v.value()),
            back_stress: self.back_stress.map(|v| v.value()),
            eps_p: self.eps_p.value(),
        }
    }
}

impl MaterialState<f64> {
    /// Lift an f64 state to scalar `T` (derivative parts zero).
    pub fn lift<T: Real>(&self) -> MaterialState<T> {
        MaterialState {
            stress: self.stress.map(T::cst),
            back_stress: self.back_stress.map(T::cst),
            eps_p: T::cst(self.eps_p),
        }
    }
    /// All 11 entries in one array: σ (5), α (5), ē^p.
    pub fn to_array(&self) -> [f64; 11] {
        let mut a = [0.0; 11];
        a[..5].copy_from_slice(self.stress.as_slice());
        a[5..10].copy_from_slice(self.back_stress.as_slice());
        a[10] = self.eps_p;
        a
    }
    /// Sum of two states (used for sensitivity term groups).
    pub fn add(&self, o: &Self) -> Self {
        MaterialState {
            stress: self.stress + o.stress,
            back_stress: self.back_stress + o.back_stress,
            eps_p: self.eps_p + o.eps_p,
        }
    }
    /// The zero state.
    pub fn zero() -> Self {
        MaterialState {
            stress: Vec5::zeros(),
            back_stress: Vec5::zeros(),
            eps_p: 0.0,
        }
    }
}

/// Names of the 11 state entries, for reports.
pub const STATE_LABELS: [&str; 11] = [
    "σ11", "σ22", "σ12", "σ23", "σ31", "α11", "α22", "α12", "α23", "α31", "ē^p",
];

/// Outcome of one return mapping.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReturnMap<T> {
    /// State at step n+1.
    pub state: MaterialState<T>,
    /// Plastic consistency parameter `λ_{n+1}` (zero when elastic).
    pub lambda: T,
    /// True when the trial state lay outside the yield surface.
    pub plastic: bool,
    /// Newton iterations spent on the consistency condition.
    pub iterations: usize,
}

/// The mapping matrix `P` of eq (11) (deviatoric projection with the shear factor of two).
pub fn p_matrix<T: Real>() -> Mat5<T> {
    let mut p = Mat5::zeros();
    p[(0, 0)] = T::cst(2.0 / 3.0);
    p[(1, 1)] = T::cst(2.0 / 3.0);
    p[(0, 1)] = T::cst(-1.0 / 3.0);
    p[(1, 0)] = T::cst(-1.0 / 3.0);
    p[(2, 2)] = T::cst(2.0);
    p[(3, 3)] = T::cst(2.0);
    p[(4, 4)] = T::cst(2.0);
    p
}

/// The plane-stress elastic matrix `D` of eq (9), with transverse shear `k G`.
pub fn elastic_matrix<T: Real>(m: &MaterialParams<T>) -> Mat5<T> {
    let e = m.young;
    let nu = m.poisson;
    let c = e / (T::one() - nu * nu);
    let g = e / ((T::one() + nu) * 2.0);
    let mut d = Mat5::zeros();
    d[(0, 0)] = c;
    d[(1, 1)] = c;
    d[(0, 1)] = c * nu;
    d[(1, 0)] = c * nu;
    d[(2, 2)] = g;
    d[(3, 3)] = g * m.shear_factor;
    d[(4, 4)] = g * m.shear_factor;
    d
}

/// `ηᵀ P η` (eq 10 without the factor ½): the squared `φ` of eq (15).
pub fn eta_p_eta<T: Real>(eta: &Vec5<T>) -> T {
    let (a, b) = (eta[0], eta[1]);
    (a * a + b * b - a * b) * (2.0 / 3.0)
        + (eta[2] * eta[2] + eta[3] * eta[3] + eta[4] * eta[4]) * 2.0
}

/// Yield function of eq (10): `f = ½ ηᵀPη − ⅓ κ²`, κ of eq (12).
pub fn yield_function<T: Real>(m: &MaterialParams<T>, state: &MaterialState<T>) -> T {
    let eta = state.stress - state.back_stress;
    let kappa = m.sigma0 + m.beta * m.hardening * state.eps_p;
    eta_p_eta(&eta) * 0.5 - kappa * kappa / 3.0
}

/// Von Mises equivalent stress of a shell stress vector: `√(3/2 · σᵀPσ)`.
pub fn von_mises<T: Real>(s: &Vec5<T>) -> T {
    (eta_p_eta(s) * 1.5).sqrt()
}

/// The common eigenbasis of `D` and `P`: coordinates `a = Vᵀ x` and eigenvalues `(d_i, p_i)`.
///
/// Membrane: `(x11 ± x22)/√2` with `P` eigenvalues 1/3 and 1 and `D` eigenvalues `E/(1−ν)` and
/// `E/(1+ν)`; the three shears with `P` eigenvalue 2 and `D` eigenvalues `G`, `kG`, `kG`.
struct Spectral<T> {
    d: [T; 5],
    p: [f64; 5],
}

impl<T: Real> Spectral<T> {
    fn new(m: &MaterialParams<T>) -> Self {
        let g = m.young / ((T::one() + m.poisson) * 2.0);
        Spectral {
            d: [
                m.young / (T::one() - m.poisson),
                m.young / (T::one() + m.poisson),
                g,
                g * m.shear_factor,
                g * m.shear_factor,
            ],
            p: [1.0 / 3.0, 1.0, 2.0, 2.0, 2.0],
        }
    }
    fn to_basis(x: &Vec5<T>) -> [T; 5] {
        let s = std::f64::consts::FRAC_1_SQRT_2;
        [(x[0] + x[1]) * s, (x[0] - x[1]) * s, x[2], x[3], x[4]]
    }
    fn from_basis(a: &[T; 5]) -> Vec5<T> {
        let s = std::f64::consts::FRAC_1_SQRT_2;
        Vec5::new((a[0] + a[1]) * s, (a[0] - a[1]) * s, a[2], a[3], a[4])
    }
}

/// The matrix `Ξ = [f1 I + λ D P]⁻¹` of eqs (46)–(48), built in the common eigenbasis.
pub fn xi_matrix<T: Real>(m: &MaterialParams<T>, lambda: T) -> Mat5<T> {
    let sp = Spectral::new(m);
    let c = m.kinematic_modulus();
    let f1 = T::one() + lambda * c;
    let mut cols = Mat5::zeros();
    for j in 0..5 {
        let mut e = Vec5::zeros();
        e[j] = T::one();
        let a = Spectral::to_basis(&e);
        let mut b = a;
        for i in 0..5 {
            b[i] = a[i] / (f1 + lambda * sp.d[i] * sp.p[i]);
        }
        cols.set_column(j, &Spectral::from_basis(&b));
    }
    cols
}

/// Consistency function `F(λ) = ½φ²(λ) − ⅓κ²(λ)` (the squared form of eq 21) and `dF/dλ`, with
/// `φ²(λ) = Σ p_i a_i² / (1 + λ e_i)²`, `e_i = c + d_i p_i`, `κ = σ0 + βH(ē^p_n + √⅔ λ φ)`.
fn consistency<T: Real>(
    m: &MaterialParams<T>,
    sp: &Spectral<T>,
    a: &[T; 5],
    eps_p_n: T,
    lambda: T,
) -> (T, T) {
    let c = m.kinematic_modulus();
    let mut phi2 = T::zero();
    let mut dphi2 = T::zero();
    for ((ai, di), pi) in a.iter().zip(&sp.d).zip(&sp.p) {
        let e = c + *di * *pi;
        let den = T::one() + lambda * e;
        let t = *ai * *ai * *pi / (den * den);
        phi2 += t;
        dphi2 -= t * e * 2.0 / den;
    }
    let phi = phi2.sqrt();
    let bh = m.beta * m.hardening;
    let kappa = m.sigma0 + bh * (eps_p_n + lambda * phi * SQRT_2_3);
    let dphi = if phi > T::zero() {
        dphi2 / (phi * 2.0)
    } else {
        T::zero()
    };
    let dkappa = bh * (phi + lambda * dphi) * SQRT_2_3;
    (
        phi2 * 0.5 - kappa * kappa / 3.0,
        dphi2 * 0.5 - kappa * dkappa * (2.0 / 3.0),
    )
}

/// Maximum Newton iterations on the consistency condition.
pub const MAX_RETURN_ITERATIONS: usize = 100;

/// Relative tolerance on the trial yield function below which a step is taken as elastic:
/// `f_tr ≤ TRIAL_TOL · ⅓κ²`. The quadratic forms carry round-off of a few 1e-16 relative; a state
/// left on the yield surface by the previous plastic step and loaded neutrally stays elastic.
pub const TRIAL_TOL: f64 = 1e-12;

/// Backward-Euler return mapping (eqs 19–21) for strain increment `Δε` from state `ⁿ(σ, α, ē^p)`.
///
/// Trial: `σ_tr = ⁿσ + D Δε` (eq 19). Plastic: `η = Ξ(λ) η_tr`, `α = ⁿα + ⅔(1 − β)Hλη`,
/// `σ = η + α`, `ē^p = ⁿē^p + √⅔ λ φ` (eq 20), with λ from the consistency condition (eq 21)
/// solved by Newton's method safeguarded by bisection on a bracket, in f64; one final Newton step
/// in the scalar type `T` carries the exact first derivative of λ into dual numbers (implicit
/// function theorem), so the same routine is the dual-number reference.
pub fn return_map<T: Real>(
    m: &MaterialParams<T>,
    n: &MaterialState<T>,
    deps: &Vec5<T>,
) -> Result<ReturnMap<T>, MaterialError> {
    m.validate()?;
    for (index, v) in deps.iter().enumerate() {
        if !v.value().is_finite() {
            return Err(MaterialError::NonFiniteStrain {
                index,
                value: v.value(),
            });
        }
    }
    let d = elastic_matrix(m);
    let sigma_tr = n.stress + d * deps;
    let eta_tr = sigma_tr - n.back_stress;
    let kappa_n = m.sigma0 + m.beta * m.hardening * n.eps_p;
    let f_tr = eta_p_eta(&eta_tr) * 0.5 - kappa_n * kappa_n / 3.0;
    let scale = (kappa_n * kappa_n / 3.0).value();
    if f_tr.value() <= TRIAL_TOL * scale {
        let state = MaterialState {
            stress: sigma_tr,
            back_stress: n.back_stress,
            eps_p: n.eps_p,
        };
        return Ok(ReturnMap {
            state,
            lambda: T::zero(),
            plastic: false,
            iterations: 0,
        });
    }

    let sp = Spectral::new(m);
    let a = Spectral::to_basis(&eta_tr);
    // Solve F(λ) = 0 in f64 on the real parts.
    let m0 = m.value();
    let sp0 = Spectral::new(&m0);
    let a0 = a.map(|v| v.value());
    let epn0 = n.eps_p.value();
    let f = |l: f64| consistency(&m0, &sp0, &a0, epn0, l);
    let (lambda0, iterations) = solve_consistency(&f, scale)?;

    // One Newton step in T: exact first derivatives of λ (F(λ0) = 0 to round-off).
    let l0 = T::cst(lambda0);
    let (fv, df) = consistency(m, &sp, &a, n.eps_p, l0);
    let lambda = l0 - fv / df;

    let c = m.kinematic_modulus();
    let f1 = T::one() + lambda * c;
    let mut b = a;
    for i in 0..5 {
        b[i] = a[i] / (f1 + lambda * sp.d[i] * sp.p[i]);
    }
    let eta = Spectral::from_basis(&b);
    let phi = eta_p_eta(&eta).sqrt();
    let back_stress = n.back_stress + eta * (lambda * c);
    let state = MaterialState {
        stress: eta + back_stress,
        back_stress,
        eps_p: n.eps_p + lambda * phi * SQRT_2_3,
    };
    Ok(ReturnMap {
        state,
        lambda,
        plastic: true,
        iterations,
    })
}

/// Safeguarded Newton on `F(λ) = 0`, `F(0) > 0`, `F(λ) < 0` for large λ: returns λ and the
/// iteration count.
fn solve_consistency(
    f: &dyn Fn(f64) -> (f64, f64),
    scale: f64,
) -> Result<(f64, usize), MaterialError> {
    let tol = 1e-15 * scale;
    let (f0, df0) = f(0.0);
    // Bracket [lo, hi] with F(lo) > 0 > F(hi).
    let mut lo = 0.0;
    let mut hi = if df0 < 0.0 { -2.0 * f0 / df0 } else { 1.0 };
    let mut grow = 0;
    while f(hi).0 > 0.0 {
        lo = hi;
        hi *= 2.0;
        grow += 1;
        if grow > 200 || !hi.is_finite() {
            return Err(MaterialError::ReturnMapNotConverged {
                iterations: grow,
                residual: f(hi).0 / scale,
            });
        }
    }
    let mut lambda = 0.0;
    let (mut fv, mut dfv) = (f0, df0);
    for it in 1..=MAX_RETURN_ITERATIONS {
        let mut next = if dfv < 0.0 {
            lambda - fv / dfv
        } else {
            f64::NAN
        };
        if !(next > lo && next < hi) {
            next = 0.5 * (lo + hi);
        }
        let step = (next - lambda).abs();
        lambda = next;
        (fv, dfv) = f(lambda);
        if fv > 0.0 {
            lo = lambda;
        } else {
            hi = lambda;
        }
        if fv.abs() <= tol || step <= 1e-16 * lambda.abs() || hi - lo <= 4.0 * f64::EPSILON * hi {
            return Ok((lambda, it));
        }
    }
    Err(MaterialError::ReturnMapNotConverged {
        iterations: MAX_RETURN_ITERATIONS,
        residual: fv / scale,
    })
}

/// Consistent (algorithmic) tangent `D^ep = ∂ⁿ⁺¹σ/∂Δε` of eq (48), derived by hand.
///
/// Elastic: `D`. Plastic, with `u = Ξ D P η`, `w = Ξ(cI + DP)η`, `c = ⅔H(1 − β)`,
/// `θ = 1 − ⅔βHλ` and `f2 = ⅔βHφ² + θ ηᵀPw`:
/// `D^ep = f1 Ξ D − (θ / f2) u uᵀ` (symmetric).
///
/// This is the transcribed eq (48) with its `f2 = ⅔Hφ² + θ ηᵀPΞDPη` and `f3 = f1 θ / f2`
/// written as `f3 = θ / (f2 / f1)`: the two forms agree to round-off for every β
/// (tests/material_transcription.rs), and the dual-number derivative of [`return_map`] confirms
/// them (tests `consistent_tangent_*`).
pub fn consistent_tangent(m: &MaterialParams<f64>, out: &ReturnMap<f64>) -> Mat5<f64> {
    let d = elastic_matrix(m);
    if !out.plastic {
        return d;
    }
    let lambda = out.lambda;
    let p = p_matrix::<f64>();
    let c = m.kinematic_modulus();
    let f1 = 1.0 + lambda * c;
    let xi = xi_matrix(m, lambda);
    let eta = out.state.stress - out.state.back_stress;
    let phi2 = eta_p_eta(&eta);
    let theta = 1.0 - 2.0 / 3.0 * m.beta * m.hardening * lambda;
    let u = xi * d * p * eta;
    let w = xi * (eta * c + d * p * eta);
    let f2 = 2.0 / 3.0 * m.beta * m.hardening * phi2 + theta * eta.dot(&(p * w));
    xi * d * f1 - u * u.transpose() * (theta / f2)
}
