//! Material parameters (eqs 9–13) and their validation.

use crate::scalar::Real;
use thiserror::Error;

/// Errors of the material point.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum MaterialError {
    /// A parameter outside its admissible range.
    #[error("material parameter `{name}` = {value} is invalid: expected {expected}")]
    InvalidParameter {
        /// Parameter name as in the case file.
        name: &'static str,
        /// The value given.
        value: f64,
        /// What was expected.
        expected: &'static str,
    },
    /// A strain-increment component that is NaN or infinite.
    #[error("strain increment component {index} is not finite ({value})")]
    NonFiniteStrain {
        /// Component index in `[ε11, ε22, 2ε12, 2ε23, 2ε31]`.
        index: usize,
        /// The value given.
        value: f64,
    },
    /// The consistency condition (eq 21) was not solved.
    #[error("return mapping did not converge in {iterations} iterations (scaled residual {residual:.3e})")]
    ReturnMapNotConverged {
        /// Iterations spent.
        iterations: usize,
        /// Last residual of the consistency condition divided by ⅓κ².
        residual: f64,
    },
}

/// Elastoplastic shell material: elasticity (eq 9) with transverse shear, von Mises yield (eq 10),
/// linear combined hardening (eqs 12–13).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaterialParams<T> {
    /// Young's modulus `E` > 0.
    pub young: T,
    /// Poisson's ratio `ν` in (−1, 0.5).
    pub poisson: T,
    /// Transverse shear correction factor `k` > 0 (default 5/6): transverse shear modulus `kG`.
    pub shear_factor: T,
    /// Initial yield stress `σ0` > 0.
    pub sigma0: T,
    /// Hardening modulus `H` ≥ 0.
    pub hardening: T,
    /// Hardening mix `β` in [0, 1]: 1 isotropic, 0 kinematic (eq 12).
    pub beta: T,
}

/// Number of material parameters.
pub const N_PARAMS: usize = 6;
/// Parameter names in the order of [`MaterialParams::to_array`].
pub const PARAM_NAMES: [&str; N_PARAMS] = [
    "young",
    "poisson",
    "shear_factor",
    "sigma0",
    "hardening",
    "beta",
];

impl MaterialParams<f64> {
    /// Validated parameters with the default shear correction factor 5/6.
    pub fn new(
        young: f64,
        poisson: f64,
        sigma0: f64,
        hardening: f64,
        beta: f64,
    ) -> Result<Self, MaterialError> {
        let m = MaterialParams {
            young,
            poisson,
            shear_factor: 5.0 / 6.0,
            sigma0,
            hardening,
            beta,
        };
        m.validate()?;
        Ok(m)
    }
    /// Same parameters with another shear correction factor.
    pub fn with_shear_factor(mut self, k: f64) -> Result<Self, MaterialError> {
        self.shear_factor = k;
        self.validate()?;
        Ok(self)
    }
    /// Lift to scalar `T` (derivative parts zero).
    pub fn lift<T: Real>(&self) -> MaterialParams<T> {
        MaterialParams::from_array(self.to_array().map(T::cst))
    }
    /// All-zero parameter sensitivities.
    pub fn zero() -> Self {
        MaterialParams::from_array([0.0; N_PARAMS])
    }
}

impl<T: Real> MaterialParams<T> {
    /// `[E, ν, k, σ0, H, β]`.
    pub fn to_array(&self) -> [T; N_PARAMS] {
        [
            self.young,
            self.poisson,
            self.shear_factor,
            self.sigma0,
            self.hardening,
            self.beta,
        ]
    }
    /// From `[E, ν, k, σ0, H, β]`.
    pub fn from_array(a: [T; N_PARAMS]) -> Self {
        MaterialParams {
            young: a[0],
            poisson: a[1],
            shear_factor: a[2],
            sigma0: a[3],
            hardening: a[4],
            beta: a[5],
        }
    }
    /// Real parts.
    pub fn value(&self) -> MaterialParams<f64> {
        MaterialParams::from_array(self.to_array().map(|v| v.value()))
    }
    /// Kinematic hardening modulus `c = ⅔H(1 − β)` of eq (13).
    pub fn kinematic_modulus(&self) -> T {
        self.hardening * (T::one() - self.beta) * (2.0 / 3.0)
    }
    /// Check every parameter's range (on the real parts): an error names the parameter, its
    /// value and the admissible range.
    pub fn validate(&self) -> Result<(), MaterialError> {
        let v = self.value();
        let check = |name, value: f64, ok: bool, expected| {
            if ok && value.is_finite() {
                Ok(())
            } else {
                Err(MaterialError::InvalidParameter {
                    name,
                    value,
                    expected,
                })
            }
        };
        check("young", v.young, v.young > 0.0, "a finite value > 0")?;
        check(
            "poisson",
            v.poisson,
            v.poisson > -1.0 && v.poisson < 0.5,
            "a value in (-1, 0.5)",
        )?;
        check(
            "shear_factor",
            v.shear_factor,
            v.shear_factor > 0.0,
            "a finite value > 0 (default 5/6)",
        )?;
        check(
            "sigma0",
            v.sigma0,
            v.sigma0 > 0.0,
            "a finite initial yield stress > 0",
        )?;
        check(
            "hardening",
            v.hardening,
            v.hardening >= 0.0,
            "a finite hardening modulus >= 0",
        )?;
        check(
            "beta",
            v.beta,
            (0.0..=1.0).contains(&v.beta),
            "a value in [0, 1] (1 isotropic, 0 kinematic)",
        )?;
        Ok(())
    }
}
