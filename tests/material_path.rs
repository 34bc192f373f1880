//! Path dependence of the material-point sensitivity (foundation issue, item 3).
//!
//! A 60-step non-proportional strain path (loading, unloading, reversal, reloading, with in-plane
//! and transverse shears) whose strains and material parameters all depend on a design parameter
//! τ: the hand-derived history sensitivities (eqs 44–49, carried from step to step) against the
//! dual-number derivative of the same return map and against central differences of re-runs.

use shelldsa::material::{MaterialParams, Vec5};
use shelldsa::verification::material_path::MaterialPath;
use shelldsa::verification::Tolerance;

/// Central-difference step on τ. The strains are O(1e-3) and their τ-rates O(1e-4), so h = 1e-6
/// moves a strain by ~1e-10: truncation error (h² times the curvature of the path response,
/// O(1) in τ) ~1e-12, round-off ε·|σ|/h ~ 1e-16·1/1e-6 = 1e-10 relative. The 1e-5 tolerance of
/// the issue is far above both.
const H: f64 = 1e-6;

/// FD tolerance 1e-5 relative. Its floor: a central difference carries an absolute round-off of
/// about ε·max|y|/h plus the return map's convergence tolerance (1e-15 relative) divided by h,
/// i.e. ≈ 3 · 2.2e-16 / 1e-6 + 1e-15 / 1e-6 ≈ 2e-9 on scaled outputs of size ~3. Components
/// smaller than 1e-4 of the largest sensitivity (~2.5) are therefore compared absolutely, at
/// 1e-5 · 1e-4 · 2.5 = 2.5e-9, the level of that noise; all larger components relatively.
const FD_TOL: Tolerance = Tolerance {
    rel: 1e-5,
    floor: 1e-4,
};

fn check_path(beta: f64) {
    let path = MaterialPath::non_proportional_60(beta).unwrap();
    // 1e-9: the hand-derived and dual paths evaluate the same converged states; differences are
    // round-off amplified by the 60-step recursion. 1e-5: truncation + round-off bound above.
    let r = path.check(H, Tolerance::rel(1e-9), FD_TOL).unwrap();
    println!("β = {beta}\n{r}");
    assert!(r.passed(), "β = {beta}:\n{r}");
    assert!(
        r.flipped_steps.is_empty(),
        "no status flip is expected within ±h on this path:\n{r}"
    );
    let n_plastic = r.response.plastic.iter().filter(|&&p| p).count();
    let n_elastic = r.per_step.len() - n_plastic;
    // The path must exercise both branches (and reversed yielding), or it tests nothing.
    assert!(
        n_plastic >= 20 && n_elastic >= 3,
        "plastic {n_plastic}, elastic {n_elastic}"
    );
    // Every step is checked, not only the last.
    assert_eq!(r.per_step.len(), 60);
    for s in &r.per_step {
        assert!(
            s.dual_error <= 1e-9 && s.fd_error <= 1e-5,
            "step {}: {s:?}",
            s.step
        );
    }
}

#[test]
fn path_sensitivity_mixed_hardening() {
    check_path(0.5);
}

#[test]
fn path_sensitivity_isotropic_hardening() {
    check_path(1.0);
}

#[test]
fn path_sensitivity_kinematic_hardening() {
    check_path(0.0);
}

/// A path whose first step ends exactly on the yield surface at τ0 = 1: the elastic/plastic status
/// of that step flips within ±h, and the check must say so rather than compare across the kink.
#[test]
fn status_flip_within_perturbation_is_detected_and_reported() {
    let m = MaterialParams::new(210_000.0, 0.3, 250.0, 1000.0, 1.0).unwrap();
    // Equibiaxial strain e reaches yield when E e/(1−ν) = σ0.
    let e_y = 250.0 * (1.0 - 0.3) / 210_000.0;
    let dir = Vec5::new(1.0, 1.0, 0.0, 0.0, 0.0);
    let path = MaterialPath {
        material: m,
        material_rate: MaterialParams::zero(),
        increments: vec![Vec5::zeros(), dir * 1e-4],
        increment_rates: vec![dir * e_y, Vec5::zeros()],
        tau: 1.0,
    };
    let r = path.check(1e-6, Tolerance::rel(1e-9), FD_TOL).unwrap();
    println!("{r}");
    assert_eq!(r.flipped_steps, vec![0], "{r}");
    assert!(r.to_string().contains("FLIPS within ±h"));
    // Nothing after the flip enters the FD comparison.
    assert_eq!(r.vs_fd.compared, 0);
}
