//! The transcribed eqs 48 and 49 of Choi, Yi, Kim & Botkin (2003) against the dual-number
//! derivative of the return map (`material::return_map` in dual numbers: the reference).
//!
//! - Eq 48 as transcribed (`f2 = ⅔Hφ² + θ ηᵀPΞDPη`, `f3 = f1 θ / f2`,
//!   `D^ep = f1 ΞD − f3 ΞDPη ηᵀPDΞ`, `θ = 1 − ⅔βHλ`) is the consistent tangent for every β.
//! - Eq 49's coefficient of `ⁿα̇` as transcribed (`λΞDP − f3 λ ΞDPη ηᵀPΞDP + f3 λ ΞDPη ηᵀP`)
//!   is not `∂ⁿ⁺¹σ/∂ⁿα`; the derivation's `λΞDP + f3 ΞDPη ηᵀPΞ` is, and so are the
//!   hand-derived history terms of `material::material_sensitivity` (the code follows the
//!   derivation).

use shelldsa::material::{
    consistent_tangent, elastic_matrix, eta_p_eta, material_sensitivity, p_matrix, return_map,
    xi_matrix, Mat5, MaterialParams, MaterialState, Vec5,
};
use shelldsa::scalar::Dual;

fn steel(beta: f64) -> MaterialParams<f64> {
    MaterialParams::new(210_000.0, 0.3, 250.0, 1000.0, beta).unwrap()
}

/// A history with back stress and plastic strain: loading along a shear-rich path.
fn loaded_state(m: &MaterialParams<f64>) -> MaterialState<f64> {
    let mut s = MaterialState::virgin();
    for _ in 0..6 {
        s = return_map(m, &s, &Vec5::new(6e-4, -2e-4, 5e-4, 3e-4, -2e-4))
            .unwrap()
            .state;
    }
    s
}

const DEPS: [f64; 5] = [4e-4, -1e-4, 3e-4, 2e-4, -1e-4];

/// The factors of eqs 46–49 at a converged plastic step: `(D, P, Ξ, η, f1, θ, f3, λ)` with
/// the transcription's `f2` and `f3`.
struct Factors {
    d: Mat5<f64>,
    p: Mat5<f64>,
    xi: Mat5<f64>,
    eta: Vec5<f64>,
    f1: f64,
    f3: f64,
    lambda: f64,
}

fn factors(m: &MaterialParams<f64>, n: &MaterialState<f64>) -> Factors {
    let out = return_map(m, n, &Vec5::from_column_slice(&DEPS)).unwrap();
    assert!(out.plastic);
    let lambda = out.lambda;
    let d = elastic_matrix(m);
    let p = p_matrix::<f64>();
    let xi = xi_matrix(m, lambda);
    let eta = out.state.stress - out.state.back_stress;
    let f1 = 1.0 + 2.0 / 3.0 * lambda * m.hardening * (1.0 - m.beta);
    let theta = 1.0 - 2.0 / 3.0 * m.beta * m.hardening * lambda;
    let f2 = 2.0 / 3.0 * m.hardening * eta_p_eta(&eta) + theta * eta.dot(&(p * xi * d * p * eta));
    Factors {
        d,
        p,
        xi,
        eta,
        f1,
        f3: f1 * theta / f2,
        lambda,
    }
}

fn rel(a: &Mat5<f64>, b: &Mat5<f64>) -> f64 {
    (a - b).abs().max() / b.abs().max()
}

/// Eq 48 as transcribed equals the consistent tangent (itself checked against the dual
/// derivative in tests/material.rs) for β = 0, 0.3, 0.5, 1. Tolerance 1e-12 relative: the two
/// forms associate the products differently; a wrong factor anywhere changes entries by far
/// more (the eq 49 test below finds 1e-1).
#[test]
fn transcribed_eq_48_is_the_consistent_tangent() {
    for beta in [0.0, 0.3, 0.5, 1.0] {
        let m = steel(beta);
        let n = loaded_state(&m);
        let f = factors(&m, &n);
        let u = f.xi * f.d * f.p * f.eta;
        let v = f.eta.transpose() * f.p * f.d * f.xi;
        let transcribed = f.xi * f.d * f.f1 - u * v * f.f3;
        let out = return_map(&m, &n, &Vec5::from_column_slice(&DEPS)).unwrap();
        let e = rel(&transcribed, &consistent_tangent(&m, &out));
        println!("eq 48, β = {beta}: transcribed vs consistent tangent {e:.2e}");
        assert!(e <= 1e-12, "β = {beta}: {e:e}");
    }
}

/// `∂ⁿ⁺¹σ/∂ⁿα` by dual numbers (one seed per component of the back stress).
fn dual_alpha_jacobian(m: &MaterialParams<f64>, n: &MaterialState<f64>) -> Mat5<f64> {
    let mut j = Mat5::zeros();
    for k in 0..5 {
        let mut nd: MaterialState<Dual> = n.lift();
        nd.back_stress[k] = Dual::from_re(n.back_stress[k]).derivative();
        let deps = Vec5::from_column_slice(&DEPS).map(Dual::from_re);
        let out = return_map(&m.lift::<Dual>(), &nd, &deps).unwrap();
        for i in 0..5 {
            j[(i, k)] = out.state.stress[i].eps;
        }
    }
    j
}

/// The hand-derived history terms (`material_sensitivity` with only `ⁿα̇` seeded) and the
/// derivation's closed form `λΞDP + f3 ΞDPη ηᵀPΞ` equal the dual derivative to round-off for
/// every β; the transcribed coefficient of `ⁿα̇` in eq 49
/// (`λΞDP − f3 λ ΞDPη ηᵀPΞDP + f3 λ ΞDPη ηᵀP`) does not (measured: 0.93 of the largest entry at
/// every β). Tolerances: 1e-10 relative for the derived forms (round-off of the dual return
/// map's final Newton step, a few 1e-16 measured, with margin); "more than 10 %" for the
/// transcription.
#[test]
fn transcribed_eq_49_back_stress_coefficient_is_not_the_derivative() {
    for beta in [0.0, 0.3, 0.5, 1.0] {
        let m = steel(beta);
        let n = loaded_state(&m);
        let f = factors(&m, &n);
        let reference = dual_alpha_jacobian(&m, &n);
        // Hand-derived history terms, one column per seeded component of ⁿα̇.
        let out = return_map(&m, &n, &Vec5::from_column_slice(&DEPS)).unwrap();
        let mut hand = Mat5::zeros();
        for k in 0..5 {
            let mut dn = MaterialState::zero();
            dn.back_stress[k] = 1.0;
            let s = material_sensitivity(
                &m,
                &Vec5::from_column_slice(&DEPS),
                &out,
                &MaterialParams::zero(),
                &dn,
                &Vec5::zeros(),
            );
            hand.set_column(k, &s.stress);
        }
        let e_hand = rel(&hand, &reference);
        let u = f.xi * f.d * f.p * f.eta;
        let pe = f.eta.transpose() * f.p;
        let transcribed = f.xi * f.d * f.p * f.lambda
            - u * pe * f.xi * f.d * f.p * (f.f3 * f.lambda)
            + u * pe * (f.f3 * f.lambda);
        let e_tr = rel(&transcribed, &reference);
        // The derivation's coefficient: λΞDP + f3 ΞDPη ηᵀPΞ.
        let derived = f.xi * f.d * f.p * f.lambda + u * pe * f.xi * f.f3;
        let e_der = rel(&derived, &reference);
        println!(
            "eq 49 ⁿα̇ coefficient, β = {beta}: hand-derived kernel vs dual {e_hand:.2e}, \
             λΞDP + f3 ΞDPη ηᵀPΞ vs dual {e_der:.2e}, transcribed vs dual {e_tr:.2e}"
        );
        assert!(e_hand <= 1e-10, "β = {beta}: {e_hand:e}");
        assert!(e_der <= 1e-10, "β = {beta}: {e_der:e}");
        assert!(e_tr > 0.1, "β = {beta}: {e_tr:e}");
    }
}
