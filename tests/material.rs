//! Material point: plane-stress J2 return mapping (paper eqs 1–21), consistent tangent (eq 48)
//! and parameter validation (foundation issue, items 1, 2 and 5).

use approx::assert_relative_eq;
use nalgebra::DMatrix;
use proptest::prelude::*;
use shelldsa::material::{
    consistent_tangent, elastic_matrix, material_sensitivity, return_map, von_mises,
    yield_function, MaterialError, MaterialParams, MaterialSensitivity, MaterialState, Vec5,
};
use shelldsa::scalar::Real;
use shelldsa::verification::{check, CheckOptions, Differentiable, StepSize, Tolerance};

fn steel(beta: f64) -> MaterialParams<f64> {
    MaterialParams::new(210_000.0, 0.3, 250.0, 1000.0, beta).unwrap()
}

/// Simo & Taylor (1986); de Souza Neto, Perić & Owen (2008) §9.4: one step from the virgin state,
/// E = 210000, ν = 0.3, σ_y0 = 250, H = 1000, isotropic. Values from ../shared/reference-values.md
/// §3 (two independent algorithms agreeing to 3e-12), compared to 1e-9 relative as the issue asks.
#[test]
fn simo_taylor_cross_check_states() {
    let cases: [([f64; 3], [f64; 4]); 4] = [
        (
            [0.005, 0.005, 0.0],
            [258.2781456954, 258.2781456954, 0.0, 8.2781456954e-03],
        ),
        (
            [0.01, 0.0, 0.0],
            [300.1131158442, 143.4381405764, 0.0, 9.9898366753e-03],
        ),
        (
            [0.0, 0.0, 0.01],
            [0.0, 0.0, 147.0639699611, 4.7222679353e-03],
        ),
        (
            [0.004, -0.001, 0.006],
            [
                210.3814148891,
                48.7109950871,
                97.0022518812,
                4.1919025384e-03,
            ],
        ),
    ];
    let m = steel(1.0);
    let mut worst = 0.0f64;
    for (e, r) in cases {
        let out = return_map(
            &m,
            &MaterialState::virgin(),
            &Vec5::new(e[0], e[1], e[2], 0.0, 0.0),
        )
        .unwrap();
        assert!(out.plastic);
        let s = out.state.stress;
        // The reference values carry 10 decimals: the absolute floor 1e-9 · 300 covers a zero entry.
        for (k, (got, want)) in [s[0], s[1], s[2], out.state.eps_p]
            .iter()
            .zip(&r[..])
            .enumerate()
        {
            let scale = if k < 3 { 300.0 } else { 1e-2 };
            let dev = (got - want).abs() / want.abs().max(scale);
            worst = worst.max(dev);
            assert!(dev <= 1e-9, "strain {e:?}, entry {k}: {got} vs {want}");
        }
        assert_eq!((s[3], s[4]), (0.0, 0.0));
    }
    println!("worst scaled deviation from the reference values: {worst:.2e}");
}

/// At a converged plastic point the yield function vanishes (to round-off of ⅓κ² ≈ 2e4: 1e-12
/// relative), and for isotropic hardening σ_vm = σ0 + H ē^p (eq 12 with β = 1).
#[test]
fn converged_plastic_points_lie_on_the_yield_surface() {
    for beta in [0.0, 0.3, 1.0] {
        let m = steel(beta);
        let mut state = MaterialState::virgin();
        for k in 0..40 {
            let t = k as f64 * 0.37;
            let deps = Vec5::new(
                3e-4 * t.cos(),
                2e-4 * t.sin(),
                4e-4,
                1e-4 * (2.0 * t).cos(),
                -1e-4,
            );
            let out = return_map(&m, &state, &deps).unwrap();
            if out.plastic {
                let kappa = m.sigma0 + beta * m.hardening * out.state.eps_p;
                let f = yield_function(&m, &out.state);
                assert!(
                    f.abs() <= 1e-12 * kappa * kappa / 3.0,
                    "β={beta} step {k}: f = {f}"
                );
                assert!(out.lambda > 0.0);
                if beta == 1.0 {
                    assert_relative_eq!(
                        von_mises(&out.state.stress),
                        250.0 + 1000.0 * out.state.eps_p,
                        max_relative = 1e-13
                    );
                }
            } else {
                assert!(yield_function(&m, &out.state) <= 1e-12 * 250.0f64.powi(2));
            }
            state = out.state;
        }
        assert!(state.eps_p > 1e-3, "the path must yield (β={beta})");
    }
}

/// Perfect plasticity (H = 0): an equibiaxial trial stress returns to σ11 = σ22 = σ_y; a pure
/// in-plane or transverse shear trial stress returns to σ_y/√3 (../shared/reference-values.md §3).
#[test]
fn perfect_plasticity_closed_forms() {
    let m = MaterialParams::new(210_000.0, 0.3, 250.0, 0.0, 1.0).unwrap();
    let v = MaterialState::virgin();
    let out = return_map(&m, &v, &Vec5::new(0.01, 0.01, 0.0, 0.0, 0.0)).unwrap();
    assert_relative_eq!(out.state.stress[0], 250.0, max_relative = 1e-13);
    assert_relative_eq!(out.state.stress[1], 250.0, max_relative = 1e-13);
    let tau_y = 250.0 / 3f64.sqrt();
    for comp in [2, 3, 4] {
        let mut e = Vec5::zeros();
        e[comp] = 0.02;
        let out = return_map(&m, &v, &e).unwrap();
        assert_relative_eq!(out.state.stress[comp], tau_y, max_relative = 1e-13);
        assert!(out
            .state
            .stress
            .iter()
            .enumerate()
            .all(|(i, s)| i == comp || *s == 0.0));
    }
}

/// Pure kinematic hardening (β = 0) shows the Bauschinger effect: after forward shear yielding,
/// the elastic range on reversal is exactly the diameter 2σ0/√3 of the *translated* yield surface;
/// with isotropic hardening (β = 1) it is the grown diameter 2κ/√3 > 2σ0/√3.
#[test]
fn kinematic_hardening_bauschinger_effect() {
    let tau0 = 250.0 / 3f64.sqrt();
    for beta in [0.0, 1.0] {
        let m = steel(beta);
        let g = m.young / (2.0 * (1.0 + m.poisson));
        // Forward: γ12 = 0.01 in 10 steps.
        let mut s = MaterialState::virgin();
        for _ in 0..10 {
            s = return_map(&m, &s, &Vec5::new(0.0, 0.0, 1e-3, 0.0, 0.0))
                .unwrap()
                .state;
        }
        let kappa = 250.0 + beta * 1000.0 * s.eps_p;
        let range = 2.0 * kappa / 3f64.sqrt(); // predicted elastic range in σ12
                                               // Reverse elastically just short of the far side of the yield surface ...
        let dg = -range / g;
        let inside = return_map(&m, &s, &Vec5::new(0.0, 0.0, dg * (1.0 - 1e-9), 0.0, 0.0)).unwrap();
        assert!(!inside.plastic, "β={beta}: still elastic just inside");
        let outside =
            return_map(&m, &s, &Vec5::new(0.0, 0.0, dg * (1.0 + 1e-6), 0.0, 0.0)).unwrap();
        assert!(outside.plastic, "β={beta}: yields just beyond");
        let reverse_yield = s.stress[2] - range;
        if beta == 0.0 {
            // Back stress carries the centre of the surface; its radius stays σ0.
            assert!(s.back_stress[2] > 0.0);
            assert_relative_eq!(s.stress[2] - s.back_stress[2], tau0, max_relative = 1e-12);
            assert_relative_eq!(range, 2.0 * tau0, max_relative = 1e-15);
            // Reversed yielding starts at a stress smaller in magnitude than the initial yield.
            assert!(
                reverse_yield.abs() < tau0,
                "Bauschinger: |{reverse_yield}| < {tau0}"
            );
        } else {
            assert_eq!(s.back_stress[2], 0.0);
            assert!(reverse_yield.abs() > tau0);
        }
    }
}

/// σ_{n+1}(Δε) from a fixed history: the function whose Jacobian is D^ep.
struct StressOfStrain {
    m: MaterialParams<f64>,
    n: MaterialState<f64>,
}

impl Differentiable for StressOfStrain {
    fn n_inputs(&self) -> usize {
        5
    }
    fn eval<T: Real>(&self, x: &[T]) -> Vec<T> {
        let deps = Vec5::from_column_slice(x);
        let out = return_map(&self.m.lift(), &self.n.lift(), &deps).unwrap();
        out.state.stress.iter().copied().collect()
    }
    fn input_label(&self, j: usize) -> String {
        ["ε11", "ε22", "γ12", "γ23", "γ31"][j].into()
    }
    fn output_label(&self, i: usize) -> String {
        ["σ11", "σ22", "σ12", "σ23", "σ31"][i].into()
    }
    fn active_set(&self, x: &[f64]) -> Vec<u8> {
        let out = return_map(&self.m, &self.n, &Vec5::from_column_slice(x)).unwrap();
        vec![u8::from(out.plastic)]
    }
}

/// Tolerances of the D^ep checks.
/// - Dual: 1e-10 relative, as the issue asks (the same converged state is differentiated two
///   ways; round-off of the 5×5 algebra is ~1e-14).
/// - FD: 1e-6 relative, absolute strain step h = 1e-7. The response σ(Δε) bends on the scale of
///   the yield strain (~1e-3), so the truncation error is ~(h/1e-3)²/6 ≈ 2e-9 relative; the
///   round-off is ε·|σ|/h ≈ 2.2e-16 · 1e3 / 1e-7 ≈ 2e-6 absolute. Entries of D^ep (up to ~1e5)
///   smaller than 1e-4 of the largest (~10) are therefore compared absolutely, at
///   1e-6 · 1e-4 · max|D^ep| ≈ 1e-5, the level of that round-off; all others relatively.
fn dep_options() -> CheckOptions {
    CheckOptions {
        dual: Tolerance::rel(1e-10),
        fd: Tolerance {
            rel: 1e-6,
            floor: 1e-4,
        },
        step: StepSize::Absolute(1e-7),
    }
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

#[test]
fn consistent_tangent_equals_dual_and_fd_plastic() {
    for beta in [0.0, 0.5, 1.0] {
        let m = steel(beta);
        let n = loaded_state(&m);
        assert!(n.eps_p > 0.0);
        let deps = [4e-4, -1e-4, 3e-4, 2e-4, -1e-4];
        let out = return_map(&m, &n, &Vec5::from_column_slice(&deps)).unwrap();
        assert!(out.plastic);
        let dep = consistent_tangent(&m, &out);
        let hand = DMatrix::from_fn(5, 5, |i, j| dep[(i, j)]);
        let f = StressOfStrain { m, n };
        let r = check(
            &f,
            &format!("D^ep plastic, β = {beta}"),
            &deps,
            &hand,
            dep_options(),
        );
        println!("{r}");
        assert!(r.passed(), "{r}");
        assert!(r.fd.flips.is_empty(), "{r}");
        // Associative plasticity: D^ep is symmetric.
        assert_relative_eq!(dep, dep.transpose(), max_relative = 1e-13);
        // A plastic tangent is softer than the elastic one along the flow direction.
        let d = elastic_matrix(&m);
        let eta = out.state.stress - out.state.back_stress;
        assert!(eta.dot(&(dep * eta)) < eta.dot(&(d * eta)));
    }
}

/// The compact strain map kept per layer point by the continuum DSA's history update
/// (`MaterialSensitivity::strain_map`) gives the strain part of `material_sensitivity` (history
/// and parameter seeds zero), on both branches, and its stress part is `D^ep Δε̇` (eq 48).
/// Tolerance: the two forms associate the products differently (`(ΞD)Δε̇` against
/// `Ξ(DΔε̇)`), a few ulps of the largest entry; 1e-13 relative leaves room for that only.
#[test]
fn strain_map_equals_the_strain_part_of_the_sensitivity() {
    let ddeps = Vec5::new(3e-5, -2e-5, 1e-5, 4e-6, -7e-6);
    for beta in [0.0, 0.5, 1.0] {
        let m = steel(beta);
        let n = loaded_state(&m);
        for (deps, plastic) in [
            (Vec5::new(4e-4, -1e-4, 3e-4, 2e-4, -1e-4), true),
            (Vec5::new(-1e-5, 1e-5, 0.0, 0.0, 0.0), false),
        ] {
            let out = return_map(&m, &n, &deps).unwrap();
            assert_eq!(out.plastic, plastic);
            let map = MaterialSensitivity::new(&m, &deps, &out).strain_map();
            let got = map.apply(&elastic_matrix(&m), &ddeps);
            let want = material_sensitivity(
                &m,
                &deps,
                &out,
                &MaterialParams::zero(),
                &MaterialState::zero(),
                &ddeps,
            );
            let scale = want.stress.amax();
            assert!((got.stress - want.stress).amax() <= 1e-13 * scale);
            assert!((got.stress - consistent_tangent(&m, &out) * ddeps).amax() <= 1e-12 * scale);
            assert!(
                (got.back_stress - want.back_stress).amax()
                    <= 1e-13 * scale.max(want.back_stress.amax())
            );
            assert!((got.eps_p - want.eps_p).abs() <= 1e-13 * want.eps_p.abs().max(1e-30));
        }
    }
}

#[test]
fn consistent_tangent_equals_dual_and_fd_elastic() {
    for beta in [0.0, 0.5, 1.0] {
        let m = steel(beta);
        let n = loaded_state(&m);
        // Unloading increment: elastic.
        let deps = [-2e-4, 1e-4, -2e-4, -1e-4, 1e-4];
        let out = return_map(&m, &n, &Vec5::from_column_slice(&deps)).unwrap();
        assert!(!out.plastic);
        let dep = consistent_tangent(&m, &out);
        assert_eq!(dep, elastic_matrix(&m));
        let hand = DMatrix::from_fn(5, 5, |i, j| dep[(i, j)]);
        let r = check(
            &StressOfStrain { m, n },
            &format!("D elastic, β = {beta}"),
            &deps,
            &hand,
            dep_options(),
        );
        assert!(r.passed(), "{r}");
    }
}

/// Transverse shear enters D as k·G (default k = 5/6) and the yield function with the factor 2 of P.
#[test]
fn transverse_shear_modulus_uses_the_correction_factor() {
    let m = steel(1.0);
    let d = elastic_matrix(&m);
    let g = 210_000.0 / 2.6;
    assert_relative_eq!(d[(3, 3)], g * 5.0 / 6.0, max_relative = 1e-15);
    let m2 = m.with_shear_factor(1.0).unwrap();
    assert_relative_eq!(elastic_matrix(&m2)[(4, 4)], g, max_relative = 1e-15);
}

#[test]
fn bad_parameters_are_rejected_with_name_and_value() {
    let cases: [(MaterialParams<f64>, &str); 8] = [
        (
            MaterialParams {
                poisson: 0.5,
                ..steel(1.0)
            },
            "poisson",
        ),
        (
            MaterialParams {
                poisson: -1.2,
                ..steel(1.0)
            },
            "poisson",
        ),
        (
            MaterialParams {
                sigma0: -250.0,
                ..steel(1.0)
            },
            "sigma0",
        ),
        (
            MaterialParams {
                beta: 1.5,
                ..steel(1.0)
            },
            "beta",
        ),
        (
            MaterialParams {
                beta: -0.1,
                ..steel(1.0)
            },
            "beta",
        ),
        (
            MaterialParams {
                young: f64::NAN,
                ..steel(1.0)
            },
            "young",
        ),
        (
            MaterialParams {
                hardening: -1.0,
                ..steel(1.0)
            },
            "hardening",
        ),
        (
            MaterialParams {
                shear_factor: 0.0,
                ..steel(1.0)
            },
            "shear_factor",
        ),
    ];
    for (m, name) in cases {
        let err = return_map(
            &m,
            &MaterialState::virgin(),
            &Vec5::new(1e-3, 0.0, 0.0, 0.0, 0.0),
        )
        .unwrap_err();
        let msg = err.to_string();
        assert!(
            matches!(err, MaterialError::InvalidParameter { name: n, .. } if n == name),
            "{msg}"
        );
        assert!(msg.contains(name) && msg.contains("expected"), "{msg}");
    }
    assert!(MaterialParams::new(210e3, 0.5, 250.0, 0.0, 1.0)
        .unwrap_err()
        .to_string()
        .contains("0.5"));
    assert!(MaterialParams::new(210e3, 0.3, -5.0, 0.0, 1.0)
        .unwrap_err()
        .to_string()
        .contains("-5"));
    let err = return_map(
        &steel(1.0),
        &MaterialState::virgin(),
        &Vec5::new(1e-3, f64::INFINITY, 0.0, 0.0, 0.0),
    );
    assert_eq!(
        err.unwrap_err(),
        MaterialError::NonFiniteStrain {
            index: 1,
            value: f64::INFINITY
        }
    );
}

/// The return map runs with a multi-direction dual (several design variables in one pass) and
/// gives the same derivatives as one scalar-dual pass per direction.
#[test]
fn multi_direction_dual_matches_scalar_duals() {
    use shelldsa::scalar::{dual_parts, seed, Dual};
    let m = steel(0.5);
    let n = loaded_state(&m);
    let deps = Vec5::new(4e-4, -1e-4, 3e-4, 2e-4, -1e-4);
    // Directions: E, σ0, H.
    let mv = MaterialParams {
        young: seed::<3>(m.young, 0),
        sigma0: seed::<3>(m.sigma0, 1),
        hardening: seed::<3>(m.hardening, 2),
        ..m.lift()
    };
    let outv = return_map(&mv, &n.lift(), &deps.map(|v| seed::<3>(v, 0) * 0.0 + v)).unwrap();
    for (k, field) in [0usize, 3, 4].iter().enumerate() {
        let mut arr = m.lift::<Dual>().to_array();
        arr[*field] = Dual::from_re(m.to_array()[*field]).derivative();
        let outd = return_map(
            &MaterialParams::from_array(arr),
            &n.lift(),
            &deps.map(Dual::from_re),
        )
        .unwrap();
        for i in 0..5 {
            let a = dual_parts(&outv.state.stress[i])[k];
            let b = outd.state.stress[i].eps;
            assert!(
                (a - b).abs() <= 1e-14 * b.abs().max(1e-3),
                "direction {k} σ{i}: {a} vs {b}"
            );
        }
    }
}

fn arb_material() -> impl Strategy<Value = MaterialParams<f64>> {
    (
        50e3..300e3f64,
        -0.3..0.45f64,
        100.0..500.0f64,
        0.0..5000.0f64,
        0.0..=1.0f64,
    )
        .prop_map(|(e, nu, s0, h, b)| MaterialParams::new(e, nu, s0, h, b).unwrap())
}

fn arb_strain() -> impl Strategy<Value = Vec5<f64>> {
    proptest::array::uniform5(-4e-3..4e-3f64).prop_map(Vec5::from)
}

/// Fixed seed: CI runs the same cases every time (reproducible). To explore, set
/// `SHELLDSA_PROPTEST_SEED` (and `PROPTEST_CASES`); cases that ever failed are replayed from
/// `material.proptest-regressions` first.
fn config() -> ProptestConfig {
    let seed = std::env::var("SHELLDSA_PROPTEST_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0x05e1_1d5a);
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(128);
    ProptestConfig {
        cases,
        rng_seed: proptest::test_runner::RngSeed::Fixed(seed),
        ..ProptestConfig::default()
    }
}

/// FD check on a random state: the best of a step study. A random state may lie arbitrarily close
/// to the yield surface (the kink of σ(Δε)), where the truncation error of any fixed step grows;
/// the round-off grows as the step shrinks. The study h ∈ {1e-6, 1e-7, 1e-8} (absolute, on
/// strains of ~1e-3) takes the step with the smallest error, as a user would, and the 1e-6
/// relative tolerance then applies to it. Its absolute floor must cover the round-off of the
/// smallest step: ε·|σ|/h ≈ 2.2e-16 · 1e3 / 1e-8 ≈ 2e-5, i.e. ~1.5e-10 of max|D^ep| ≈ 1.5e5
/// at the stiffest random material. Components below 1e-3 of the largest are therefore held to
/// 1e-6 · 1e-3 = 1e-9 of max|D^ep| (≥ 7× that round-off). With the deterministic floor 1e-4, one
/// case in 50,000 (seed 9) failed at 1.1e-6 on a component 8.6e-5 of the largest: round-off.
fn best_fd(
    f: &StressOfStrain,
    x: &[f64],
    hand: &DMatrix<f64>,
) -> shelldsa::verification::DerivativeReport {
    let random_state_fd = Tolerance {
        rel: 1e-6,
        floor: 1e-3,
    };
    [1e-6, 1e-7, 1e-8]
        .iter()
        .map(|&h| {
            let opts = CheckOptions {
                step: StepSize::Absolute(h),
                fd: random_state_fd,
                ..dep_options()
            };
            check(f, "D^ep random", x, hand, opts)
        })
        .min_by(|a, b| a.vs_fd.max_error().total_cmp(&b.vs_fd.max_error()))
        .unwrap()
}

proptest! {
    #![proptest_config(config())]

    /// Random material, random two-step history, random increment: converged plastic points lie on
    /// the yield surface, and D^ep equals the dual-number and FD Jacobians (item 5 for items 1–2).
    #[test]
    fn prop_return_map_and_tangent(m in arb_material(), e1 in arb_strain(), e2 in arb_strain(), e3 in arb_strain()) {
        let s1 = return_map(&m, &MaterialState::virgin(), &e1).unwrap().state;
        let n = return_map(&m, &s1, &e2).unwrap().state;
        let out = return_map(&m, &n, &e3).unwrap();
        if out.plastic {
            let kappa = m.sigma0 + m.beta * m.hardening * out.state.eps_p;
            prop_assert!(yield_function(&m, &out.state).abs() <= 1e-11 * kappa * kappa);
        }
        let dep = consistent_tangent(&m, &out);
        let hand = DMatrix::from_fn(5, 5, |i, j| dep[(i, j)]);
        let r = best_fd(&StressOfStrain { m, n }, e3.as_slice(), &hand);
        // The dual comparison holds everywhere; the FD comparison leaves out columns whose ±h
        // perturbation flips the elastic/plastic status (reported by the check).
        prop_assert!(r.vs_dual.passed(), "{}", r);
        prop_assert!(r.vs_fd.passed(), "{}", r);
    }

    /// Random history and design rates: the hand-derived sensitivity update of one step equals the
    /// dual-number derivative (item 5 for item 3).
    #[test]
    fn prop_one_step_sensitivity(m in arb_material(), e1 in arb_strain(), e2 in arb_strain(), rates in proptest::array::uniform5(-1.0..1.0f64), de in arb_strain()) {
        use shelldsa::scalar::Dual;
        let n = return_map(&m, &MaterialState::virgin(), &e1).unwrap().state;
        // Design rates of E, ν, σ0, H (β only where it stays inside [0, 1]).
        let dm = MaterialParams::from_array([rates[0] * 1e4, rates[1] * 0.01, 0.0, rates[2] * 10.0, rates[3] * 100.0,
            if m.beta > 0.01 && m.beta < 0.99 { rates[4] * 0.1 } else { 0.0 }]);
        // History sensitivities as a dual state: σ̇, α̇, ė^p of the step-1 state.
        let dn = MaterialState { stress: e1 * 1e5, back_stress: e1 * 1e4 * rates[4], eps_p: rates[0] * 1e-3 };
        let out = return_map(&m, &n, &e2).unwrap();
        let hand = material_sensitivity(&m, &e2, &out, &dm, &dn, &de);
        let md = MaterialParams::from_array(std::array::from_fn(|i| Dual::new(m.to_array()[i], dm.to_array()[i])));
        let nd = MaterialState {
            stress: Vec5::from_fn(|i, _| Dual::new(n.stress[i], dn.stress[i])),
            back_stress: Vec5::from_fn(|i, _| Dual::new(n.back_stress[i], dn.back_stress[i])),
            eps_p: Dual::new(n.eps_p, dn.eps_p),
        };
        let ed = Vec5::from_fn(|i, _| Dual::new(e2[i], de[i]));
        let outd = return_map(&md, &nd, &ed).unwrap();
        prop_assert_eq!(outd.plastic, out.plastic);
        let a = hand.to_array();
        let b: Vec<f64> = outd.state.stress.iter().chain(outd.state.back_stress.iter()).map(|v| v.eps)
            .chain(std::iter::once(outd.state.eps_p.eps)).collect();
        // Stress-like entries scaled by 1e-6·max|σ̇| floor; ē^p entries by their own magnitude.
        let smax = b[..10].iter().fold(0.0f64, |x, v| x.max(v.abs()));
        for i in 0..11 {
            let floor = if i < 10 { 1e-6 * smax } else { 1e-6 * b[10].abs().max(1e-12) };
            prop_assert!((a[i] - b[i]).abs() <= 1e-9 * b[i].abs().max(floor), "entry {}: {} vs {}", i, a[i], b[i]);
        }
    }
}
