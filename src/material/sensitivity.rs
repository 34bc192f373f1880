//! Hand-derived design sensitivity of the material point (eqs 44–49), extended to material
//! parameters as design variables.
//!
//! Differentiating the backward-Euler equations (eq 20) and the consistency condition (eq 21)
//! with respect to a design parameter τ, with `η = σ − α`, `c = ⅔H(1 − β)`, `f1 = 1 + λc`,
//! `Ξ = [f1 I + λDP]⁻¹`, `θ = 1 − ⅔βHλ`, `w = Ξ(cI + DP)η` and `f2 = ⅔βHφ² + θ ηᵀPw`:
//!
//! ```text
//! r      = ⁿσ̇ − ⁿα̇ + Ḋ Δε + D Δε̇ − λ ċ η − λ Ḋ P η          (explicit driving term)
//! q      = σ̇0 + (βH)˙ ⁿ⁺¹ē^p + βH ⁿė^p                          (yield-radius term, eq 12)
//! λ̇      = (θ ηᵀPΞ r − √⅔ φ q) / f2                            (eq 46)
//! η̇      = Ξ r − λ̇ w
//! ⁿ⁺¹σ̇   = f1 η̇ + ⁿα̇ + (c λ̇ + λ ċ) η                          (eqs 44, 47)
//! ⁿ⁺¹α̇   = ⁿα̇ + (c λ̇ + λ ċ) η + λ c η̇                         (eq 45)
//! ⁿ⁺¹ė^p = ⁿė^p + √⅔ (λ̇ φ + λ ηᵀPη̇ / φ)
//! ```
//!
//! The stress sensitivity is linear in `Δε̇`: `ⁿ⁺¹σ̇ = D^ep Δε̇ + σ^fic` (eq 47), where σ^fic
//! collects the history terms (`ⁿσ̇, ⁿα̇, ⁿė^p`, eq 49) and the material-parameter terms.
//! This `f2` is the transcription's divided by `f1`, so `D^ep` is eq (48) as transcribed. Eq
//! (49)'s coefficient of `ⁿα̇` as transcribed is not the derivative: this form gives
//! `λΞDP + f3 ΞDPη ηᵀPΞ` (`f3 = θ/f2` here), the one the dual-number derivative of
//! [`super::return_map`] confirms (tests/material_transcription.rs).

use super::{
    elastic_matrix, eta_p_eta, p_matrix, xi_matrix, Mat5, MaterialParams, MaterialState, ReturnMap,
    Vec5, SQRT_2_3,
};

/// Material-point sensitivity split into the named groups of the design-sensitivity equation:
/// the three parts add up to the total.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaterialSensitivityTerms {
    /// Strain terms: the response to `Δε̇` (for the stress, `D^ep Δε̇`).
    pub strain: MaterialState<f64>,
    /// History terms: the response to `ⁿσ̇, ⁿα̇, ⁿė^p` (eq 49).
    pub history: MaterialState<f64>,
    /// Material-parameter terms: the response to `Ė, ν̇, k̇, σ̇0, Ḣ, β̇`.
    pub material: MaterialState<f64>,
}

impl MaterialSensitivityTerms {
    /// The whole sensitivity `ⁿ⁺¹(σ̇, α̇, ė^p)`.
    pub fn total(&self) -> MaterialState<f64> {
        self.strain.add(&self.history).add(&self.material)
    }
    /// The fictitious stress `σ^fic` of eq (47): history and material terms of the stress.
    pub fn sigma_fic(&self) -> Vec5<f64> {
        self.history.stress + self.material.stress
    }
}

/// `Ḋ` for parameter sensitivities `dm`, from `D11 = E/(1−ν²)`, `D12 = νD11`, `G = E/(2(1+ν))`,
/// transverse shear `kG`.
pub fn elastic_matrix_derivative(m: &MaterialParams<f64>, dm: &MaterialParams<f64>) -> Mat5<f64> {
    let (e, nu, k) = (m.young, m.poisson, m.shear_factor);
    let one_m = 1.0 - nu * nu;
    let c = e / one_m;
    let dc = dm.young / one_m + e * 2.0 * nu * dm.poisson / (one_m * one_m);
    let g = e / (2.0 * (1.0 + nu));
    let dg = dm.young / (2.0 * (1.0 + nu)) - e * dm.poisson / (2.0 * (1.0 + nu) * (1.0 + nu));
    let mut d = Mat5::zeros();
    d[(0, 0)] = dc;
    d[(1, 1)] = dc;
    d[(0, 1)] = dc * nu + c * dm.poisson;
    d[(1, 0)] = d[(0, 1)];
    d[(2, 2)] = dg;
    d[(3, 3)] = dm.shear_factor * g + k * dg;
    d[(4, 4)] = d[(3, 3)];
    d
}

/// `D v` for a `D` of [`elastic_matrix`]'s pattern (the in-plane 2 × 2 block and the
/// diagonal), with only its 7 non-zero entries.
fn elastic_times(d: &Mat5<f64>, v: &Vec5<f64>) -> Vec5<f64> {
    Vec5::new(
        d[(0, 0)] * v[0] + d[(0, 1)] * v[1],
        d[(1, 0)] * v[0] + d[(1, 1)] * v[1],
        d[(2, 2)] * v[2],
        d[(3, 3)] * v[3],
        d[(4, 4)] * v[4],
    )
}

/// Sensitivity of one return mapping, linear in its three inputs:
/// `dm` (parameter sensitivities), `dn` (history sensitivities `ⁿ(σ̇, α̇, ė^p)`) and `ddeps` (`Δε̇`).
///
/// `m`, `deps` and `out` are the analysis data of the step: parameters, the strain increment and the outcome of [`super::return_map`] (its branch decides elastic/plastic).
pub fn material_sensitivity(
    m: &MaterialParams<f64>,
    deps: &Vec5<f64>,
    out: &ReturnMap<f64>,
    dm: &MaterialParams<f64>,
    dn: &MaterialState<f64>,
    ddeps: &Vec5<f64>,
) -> MaterialState<f64> {
    MaterialSensitivity::new(m, deps, out).apply(dm, dn, ddeps)
}

/// [`material_sensitivity`] with the factors that do not depend on the seeds (`D`, and on the
/// plastic branch `Ξ`, `η`, `φ`, `θ`, `Pη`, `w`, `f2`) formed once, for several seed sets at
/// one material point; [`MaterialSensitivity::apply`] gives the same result.
#[derive(Clone, Copy, Debug)]
pub struct MaterialSensitivity {
    m: MaterialParams<f64>,
    deps: Vec5<f64>,
    out: ReturnMap<f64>,
    d: Mat5<f64>,
    plastic: Option<Plastic>,
}

/// The seed-independent factors of the plastic branch (module docs).
#[derive(Clone, Copy, Debug)]
struct Plastic {
    c: f64,
    f1: f64,
    xi: Mat5<f64>,
    eta: Vec5<f64>,
    phi: f64,
    theta: f64,
    p_eta: Vec5<f64>,
    w: Vec5<f64>,
    f2: f64,
}

impl MaterialSensitivity {
    /// The factors at the analysis data `m`, `deps`, `out` (as [`material_sensitivity`]).
    pub fn new(m: &MaterialParams<f64>, deps: &Vec5<f64>, out: &ReturnMap<f64>) -> Self {
        let d = elastic_matrix(m);
        let plastic = out.plastic.then(|| {
            let p = p_matrix::<f64>();
            let lambda = out.lambda;
            let (h, beta) = (m.hardening, m.beta);
            let c = m.kinematic_modulus();
            let f1 = 1.0 + lambda * c;
            let xi = xi_matrix(m, lambda);
            let eta = out.state.stress - out.state.back_stress;
            let phi = eta_p_eta(&eta).sqrt();
            let theta = 1.0 - 2.0 / 3.0 * beta * h * lambda;
            let p_eta = p * eta;
            let w = xi * (eta * c + d * p_eta);
            let f2 = 2.0 / 3.0 * beta * h * phi * phi + theta * p_eta.dot(&w);
            Plastic {
                c,
                f1,
                xi,
                eta,
                phi,
                theta,
                p_eta,
                w,
                f2,
            }
        });
        MaterialSensitivity {
            m: *m,
            deps: *deps,
            out: *out,
            d,
            plastic,
        }
    }

    /// The strain part alone: [`Self::apply`] with `dm = 0`, `dn = 0` (the same result; for
    /// the plastic branch `D^ep Δε̇` of eq 48 and its back-stress and `ē^p` companions).
    pub fn strain(&self, ddeps: &Vec5<f64>) -> MaterialState<f64> {
        let dsigma_tr = self.d * ddeps;
        let Some(pl) = &self.plastic else {
            return MaterialState {
                stress: dsigma_tr,
                back_stress: Vec5::zeros(),
                eps_p: 0.0,
            };
        };
        let lambda = self.out.lambda;
        let xi_r = pl.xi * dsigma_tr;
        let dlambda = pl.theta * pl.p_eta.dot(&xi_r) / pl.f2;
        let deta = xi_r - pl.w * dlambda;
        let dshift = pl.eta * (pl.c * dlambda);
        MaterialState {
            stress: deta * pl.f1 + dshift,
            back_stress: dshift + deta * (lambda * pl.c),
            eps_p: SQRT_2_3 * (dlambda * pl.phi + lambda * (pl.p_eta.dot(&deta) / pl.phi)),
        }
    }

    /// The strain part ([`Self::strain`]) in compact form, for storing per material point:
    /// [`StrainMap`].
    pub fn strain_map(&self) -> StrainMap {
        let Some(pl) = &self.plastic else {
            return StrainMap { plastic: None };
        };
        let lambda = self.out.lambda;
        let xi_d = pl.xi * self.d;
        StrainMap {
            plastic: Some(PlasticStrain {
                xi_d,
                g: xi_d.tr_mul(&pl.p_eta) * (pl.theta / pl.f2),
                w: pl.w,
                eta_c: pl.eta * pl.c,
                p_eta: pl.p_eta,
                f1: pl.f1,
                lambda_c: lambda * pl.c,
                phi: pl.phi,
                lambda_over_phi: lambda / pl.phi,
            }),
        }
    }

    /// The sensitivity for the seeds `dm`, `dn`, `ddeps` (eqs 44–49, module docs).
    pub fn apply(
        &self,
        dm: &MaterialParams<f64>,
        dn: &MaterialState<f64>,
        ddeps: &Vec5<f64>,
    ) -> MaterialState<f64> {
        let (m, deps, out, d) = (&self.m, &self.deps, &self.out, &self.d);
        // Ḋ only for a seed of E, ν or k, the parameters D depends on (the other seed sets skip
        // its 5 × 5 products; adding the zero vectors instead gives the same floating-point
        // result).
        let elastic_seed = dm.young != 0.0 || dm.poisson != 0.0 || dm.shear_factor != 0.0;
        let dd = elastic_seed.then(|| elastic_matrix_derivative(m, dm));
        let dd_times = |v: &Vec5<f64>| dd.map_or_else(Vec5::zeros, |dd| dd * v);
        let dsigma_tr = dn.stress + dd_times(deps) + elastic_times(d, ddeps);
        let Some(pl) = &self.plastic else {
            // Elastic branch: σ = ⁿσ + D Δε, α and ē^p unchanged.
            return MaterialState {
                stress: dsigma_tr,
                back_stress: dn.back_stress,
                eps_p: dn.eps_p,
            };
        };
        let lambda = out.lambda;
        let (h, beta) = (m.hardening, m.beta);
        let (c, f1, xi, eta, phi) = (pl.c, pl.f1, &pl.xi, pl.eta, pl.phi);
        let (theta, p_eta, w, f2) = (pl.theta, pl.p_eta, pl.w, pl.f2);
        let dc = 2.0 / 3.0 * ((1.0 - beta) * dm.hardening - h * dm.beta);

        let r = dsigma_tr - dn.back_stress - eta * (lambda * dc) - dd_times(&p_eta) * lambda;
        let q =
            dm.sigma0 + (dm.beta * h + beta * dm.hardening) * out.state.eps_p + beta * h * dn.eps_p;
        let xi_r = xi * r;
        let dlambda = (theta * p_eta.dot(&xi_r) - SQRT_2_3 * phi * q) / f2;
        let deta = xi_r - w * dlambda;
        let dshift = eta * (c * dlambda + lambda * dc);
        let dback = dn.back_stress + dshift + deta * (lambda * c);
        let dstress = deta * f1 + dn.back_stress + dshift;
        let dphi = p_eta.dot(&deta) / phi;
        let deps_p = dn.eps_p + SQRT_2_3 * (dlambda * phi + lambda * dphi);
        MaterialState {
            stress: dstress,
            back_stress: dback,
            eps_p: deps_p,
        }
    }
}

/// The strain part of a material point's sensitivity ([`MaterialSensitivity::strain`], the
/// `D^ep Δε̇` of eq 48 and its back-stress and `ē^p` companions) in compact form: nothing for
/// an elastic point (`σ̇ = D Δε̇`, with `D` the model's, given to [`Self::apply`]), and for a
/// plastic one `ΞD`, `g = (θ/f2) (ΞD)ᵀ Pη` (so `λ̇ = g·Δε̇`) and the vectors and scalars of the
/// update (module docs): ≈ 390 bytes instead of the ≈ 770 of a [`MaterialSensitivity`].
#[derive(Clone, Copy, Debug, Default)]
pub struct StrainMap {
    plastic: Option<PlasticStrain>,
}

#[derive(Clone, Copy, Debug)]
struct PlasticStrain {
    xi_d: Mat5<f64>,
    g: Vec5<f64>,
    w: Vec5<f64>,
    eta_c: Vec5<f64>,
    p_eta: Vec5<f64>,
    f1: f64,
    lambda_c: f64,
    phi: f64,
    lambda_over_phi: f64,
}

impl StrainMap {
    /// `ⁿ⁺¹(σ̇, α̇, ė^p)` for the strain-increment rate `ddeps` alone; `d` is the elastic matrix
    /// of the point's material (used on the elastic branch only). Equal to
    /// [`MaterialSensitivity::strain`] to round-off.
    pub fn apply(&self, d: &Mat5<f64>, ddeps: &Vec5<f64>) -> MaterialState<f64> {
        let Some(pl) = &self.plastic else {
            return MaterialState {
                stress: d * ddeps,
                back_stress: Vec5::zeros(),
                eps_p: 0.0,
            };
        };
        let xi_r = pl.xi_d * ddeps;
        let dlambda = pl.g.dot(ddeps);
        let deta = xi_r - pl.w * dlambda;
        let dshift = pl.eta_c * dlambda;
        MaterialState {
            stress: deta * pl.f1 + dshift,
            back_stress: dshift + deta * pl.lambda_c,
            eps_p: SQRT_2_3 * (dlambda * pl.phi + pl.lambda_over_phi * pl.p_eta.dot(&deta)),
        }
    }
}

/// [`material_sensitivity`] split into its strain, history and material-parameter groups.
pub fn material_sensitivity_terms(
    m: &MaterialParams<f64>,
    deps: &Vec5<f64>,
    out: &ReturnMap<f64>,
    dm: &MaterialParams<f64>,
    dn: &MaterialState<f64>,
    ddeps: &Vec5<f64>,
) -> MaterialSensitivityTerms {
    let z_m = MaterialParams::zero();
    let z_n = MaterialState::zero();
    let z_e = Vec5::zeros();
    MaterialSensitivityTerms {
        strain: material_sensitivity(m, deps, out, &z_m, &z_n, ddeps),
        history: material_sensitivity(m, deps, out, &z_m, dn, &z_e),
        material: material_sensitivity(m, deps, out, dm, &z_n, &z_e),
    }
}
