//! Tests of the finite-deformation kinematics (paper §2.3 eqs 22–31, §3 eqs 42, 50–58).
//!
//! Derivative tests are three-way ([`shelldsa::verification::check`]): the hand-derived
//! derivative against the dual-number derivative of the same generic kernel, and against central
//! differences. Tolerances (see [`opts`]), with `max` the largest reference component:
//! - hand vs dual, `1e-13` relative: both are exact derivatives evaluated in f64 with different
//!   operation orders (a handful of 3×3 products, one inverse of a matrix with condition number
//!   ≤ ~3), so they differ by round-off of the largest terms, measured ≈ `1e-16 · max`. A
//!   component smaller than `1e-2 · max` (small by cancellation) is held instead to the absolute
//!   bound `1e-13 · 1e-2 · max = 1e-15 · max` ≈ 5 ulps of the largest term: tight, and about 10×
//!   the round-off measured.
//! - hand vs central difference, `1e-7` relative: with the default step `h ≈ 6e-6` the truncation
//!   error `h²|f'''|/6` and the round-off `ε|f|/h` are both about `1e-11 · max` for these
//!   unit-scale kernels (measured ≤ `2.3e-11 · max`); components below `1e-2 · max` are held to
//!   `1e-9 · max`, which a difference quotient resolves with a margin of about 50.
//!
//! Worst errors measured are printed with `cargo test --test kinematics -- --nocapture`.

use nalgebra::DMatrix;
use proptest::prelude::*;
use shelldsa::kinematics::*;
use shelldsa::material::Vec5;
use shelldsa::verification::{
    check, CheckOptions, DerivativeReport, Differentiable, StepSize, Tolerance,
};
use shelldsa::Real;

// ---------------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------------

/// Tolerances of every three-way check (justified in the file's doc comment).
fn opts() -> CheckOptions {
    CheckOptions {
        dual: Tolerance {
            rel: 1e-13,
            floor: 1e-2,
        },
        fd: Tolerance {
            rel: 1e-7,
            floor: 1e-2,
        },
        step: StepSize::default(),
    }
}

/// Tolerances of the whole-step chain ([`Step`]): ten kernels deep, with unit-scale outputs
/// (`L`, `r`) and stresses of order 100 in one Jacobian. Over 4·10⁴ random steps the hand and
/// dual derivatives differed by at most 1.15e-13 relative (a stress derivative of 7.19 against a
/// largest component of 52.5: 8e-13 absolute, ≈ 70 ulps of the stresses entering it), so the
/// dual tolerance is `3e-13` here. Components below `1e-1 · max` are held to an absolute
/// `3e-14 · max` (dual) and `1e-8 · max` (differences; worst measured 1.3e-8 relative).
fn chain_opts() -> CheckOptions {
    CheckOptions {
        dual: Tolerance {
            rel: 3e-13,
            floor: 1e-1,
        },
        fd: Tolerance {
            rel: 1e-7,
            floor: 1e-1,
        },
        step: StepSize::default(),
    }
}

/// Run a three-way check, print the report, and fail with the report if it did not pass.
fn run_check<F: Differentiable>(
    f: &F,
    title: &str,
    x: &[f64],
    hand: &DMatrix<f64>,
) -> DerivativeReport {
    run_check_with(f, title, x, hand, opts())
}

fn run_check_with<F: Differentiable>(
    f: &F,
    title: &str,
    x: &[f64],
    hand: &DMatrix<f64>,
    o: CheckOptions,
) -> DerivativeReport {
    let r = check(f, title, x, hand, o);
    println!("{r}");
    assert!(r.passed(), "{r}");
    r
}

/// Rotation by `angle` about the unit vector along `axis` (Rodrigues), generic.
fn rotation<T: Real>(axis: [T; 3], angle: T) -> M3<T> {
    let norm = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    let n = [axis[0] / norm, axis[1] / norm, axis[2] / norm];
    let k = M3::new(
        T::zero(),
        -n[2],
        n[1],
        n[2],
        T::zero(),
        -n[0],
        -n[1],
        n[0],
        T::zero(),
    );
    M3::identity() + k * angle.sin() + k * k * (T::one() - angle.cos())
}

/// Cross-product matrix `[n]×` of the unit vector along `axis`.
fn cross_matrix(axis: [f64; 3]) -> M3<f64> {
    let norm = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    let n = [axis[0] / norm, axis[1] / norm, axis[2] / norm];
    M3::new(0.0, -n[2], n[1], n[2], 0.0, -n[0], -n[1], n[0], 0.0)
}

/// Largest absolute entry.
fn max_abs(m: &M3<f64>) -> f64 {
    m.iter().fold(0.0_f64, |a, v| a.max(v.abs()))
}

/// Matrix from 9 entries of `x` starting at `at`, row-major.
fn mat<T: Real>(x: &[T], at: usize) -> M3<T> {
    M3::from_fn(|i, j| x[at + 3 * i + j])
}

/// The 9 entries of `m`, row-major.
fn flat<T: Real>(m: &M3<T>) -> Vec<T> {
    (0..9).map(|k| m[(k / 3, k % 3)]).collect()
}

/// Unit matrix with a one at row-major position `k`.
fn unit(k: usize) -> M3<f64> {
    let mut m = M3::zeros();
    m[(k / 3, k % 3)] = 1.0;
    m
}

/// Jacobian whose column `j` is `col(j)`.
fn jacobian(n_in: usize, col: impl Fn(usize) -> Vec<f64>) -> DMatrix<f64> {
    let cols: Vec<Vec<f64>> = (0..n_in).map(col).collect();
    DMatrix::from_fn(cols[0].len(), n_in, |i, j| cols[j][i])
}

/// Deterministic pseudo-random numbers (SplitMix64), so failures reproduce.
struct Rng(u64);
impl Rng {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }
    fn axis(&mut self) -> [f64; 3] {
        loop {
            let a = [
                self.uniform(-1.0, 1.0),
                self.uniform(-1.0, 1.0),
                self.uniform(-1.0, 1.0),
            ];
            if a.iter().map(|v| v * v).sum::<f64>() > 0.1 {
                return a;
            }
        }
    }
    /// A rotation by 10°–60° about a random axis.
    fn rotation(&mut self) -> M3<f64> {
        let axis = self.axis();
        let angle = self.uniform(10.0, 60.0).to_radians();
        rotation(axis, angle)
    }
    /// A random symmetric matrix with entries in ±`a`.
    fn sym(&mut self, a: f64) -> M3<f64> {
        let m = M3::from_fn(|_, _| self.uniform(-a, a));
        (m + m.transpose()) * 0.5
    }
    fn general(&mut self, a: f64) -> M3<f64> {
        M3::from_fn(|_, _| self.uniform(-a, a))
    }
}

/// `H` of a step with a finite rotation and a stretch: `R (I + S) − I`.
fn random_h(rng: &mut Rng) -> M3<f64> {
    let r = rng.rotation();
    let s = rng.sym(0.1);
    r * (M3::identity() + s) - M3::identity()
}

// ---------------------------------------------------------------------------------------------
// 1. Rigid rotation (reference-values.md §4)
// ---------------------------------------------------------------------------------------------

fn sigma0() -> M3<f64> {
    M3::new(100.0, 30.0, -20.0, 30.0, -50.0, 10.0, -20.0, 10.0, 40.0)
}

/// Trace, second invariant `½(tr² − tr(σ²))` and determinant.
fn invariants(s: &M3<f64>) -> [f64; 3] {
    let tr = s.trace();
    [tr, 0.5 * (tr * tr - (s * s).trace()), s.determinant()]
}

/// Rotate σ0 rigidly by 90° about (1,2,3)/√14 in 1, 2, 10 and 100 steps, the gradient taken at
/// the mid-step configuration (reference-values.md §4). For a rigid step `ⁿ⁺¹x = R ⁿx`,
/// `H = R − I` and `L = 2(R − I)(R + I)⁻¹` is exactly skew: `Δε = 0` and `r = R` up to round-off.
///
/// Bounds: `|Δε| ≤ 1e-15` and `|r − Rₛ| ≤ 1e-15` (per-step round-off of unit-scale entries);
/// `|σ − Rσ0Rᵀ| ≤ 1e-12` after up to 100 steps (entries ≈ 100, so ≈ 1e-14 per step at worst,
/// accumulated; 8.1e-13 measured at 100 steps); the invariants relative to their size to `1e-13`.
/// The lamina frame updated by eq 27 must carry a constant local stress (eq 26):
/// `Qₙ σₙ Qₙᵀ = Q₀ σ0 Q₀ᵀ` to `4 ε · 100` per step, and the local strain increment (eq 30) must
/// vanish with `Δε`.
#[test]
fn rigid_rotation_is_exact_with_mid_step_gradient() {
    let axis = [1.0, 2.0, 3.0];
    let total = rotation(axis, 90f64.to_radians());
    let s0 = sigma0();
    let exact = total * s0 * total.transpose();
    let inv0 = invariants(&s0);
    let q0 = rotation([0.3, -1.0, 0.5], 0.7).transpose();
    let local0 = local_stress(&q0, &s0);
    for steps in [1usize, 2, 10, 100] {
        let step = rotation(axis, 90f64.to_radians() / steps as f64);
        let h = step - M3::identity();
        let (mut sigma, mut q) = (s0, q0);
        let (mut worst_deps, mut worst_r, mut worst_local_inc) = (0.0_f64, 0.0_f64, 0.0_f64);
        for _ in 0..steps {
            let l = mid_step_gradient(&h).expect("rigid step below a half-turn");
            let inc = hughes_winget(&l).expect("finite L");
            worst_deps = worst_deps.max(max_abs(&inc.deps));
            worst_r = worst_r.max(max_abs(&(inc.r - step)));
            worst_local_inc =
                worst_local_inc.max(max_abs(&local_strain_increment(&q, &inc.r_half, &inc.deps)));
            sigma = rotate_stress(&inc.r, &sigma);
            q = frame_update(&q, &inc.r);
        }
        let err = max_abs(&(sigma - exact));
        let local_err = max_abs(&(local_stress(&q, &sigma) - local0));
        let inv = invariants(&sigma);
        let inv_err = (0..3)
            .map(|k| ((inv[k] - inv0[k]) / inv0[k]).abs())
            .fold(0.0, f64::max);
        println!(
            "{steps:>3} steps: |Δε| {worst_deps:.2e}, |r − Rs| {worst_r:.2e}, |σ − Rσ0Rᵀ| {err:.2e}, \
             |σˡ − σˡ0| {local_err:.2e}, invariants rel {inv_err:.2e}, |Δεˡ| {worst_local_inc:.2e}"
        );
        assert!(
            worst_deps <= 1e-15,
            "{steps} steps: spurious strain {worst_deps:e}"
        );
        assert!(
            worst_local_inc <= 1e-15,
            "{steps} steps: spurious local strain {worst_local_inc:e}"
        );
        assert!(
            worst_r <= 1e-15,
            "{steps} steps: r differs from the step rotation by {worst_r:e}"
        );
        assert!(err <= 1e-12, "{steps} steps: |σ − Rσ0Rᵀ| = {err:e}");
        // The frame and the stress are two independently rounded chains of `steps` rotations:
        // allow 4 ulps of the largest stress entry (100) per step.
        let local_tol = steps as f64 * 4.0 * f64::EPSILON * 100.0;
        assert!(
            local_err <= local_tol,
            "{steps} steps: local stress drifted by {local_err:e} > {local_tol:e}"
        );
        assert!(
            inv_err <= 1e-13,
            "{steps} steps: invariants drifted by {inv_err:e} (relative)"
        );
    }
}

/// Negative control: the gradient taken at the start-of-step configuration (`L = H = R − I`)
/// gives `sym(R) − I = nnᵀ − I` for one 90° step: a spurious strain whose largest component is
/// `1/14 − 1 = −13/14 ≈ −0.93`; the rotation it yields is not the step rotation and the stress is
/// wrong by tens of percent. The test must see all of that.
#[test]
fn rigid_rotation_with_start_of_step_gradient_gives_spurious_strain() {
    let axis = [1.0, 2.0, 3.0];
    let step = rotation(axis, 90f64.to_radians());
    let h = step - M3::identity();
    let inc = hughes_winget(&h).expect("finite");
    let worst = max_abs(&inc.deps);
    println!("start-of-step gradient, one 90° step: largest |Δε| = {worst:.6}");
    assert!(
        (worst - 13.0 / 14.0).abs() < 1e-14,
        "spurious strain {worst}, expected 13/14"
    );
    assert!((inc.deps[(0, 0)] + 13.0 / 14.0).abs() < 1e-14);
    let s0 = sigma0();
    let err = max_abs(&(rotate_stress(&inc.r, &s0) - step * s0 * step.transpose()));
    println!("start-of-step gradient, one 90° step: |σ − Rσ0Rᵀ| = {err:.3}");
    assert!(err > 10.0, "the wrong rotation went unnoticed: {err}");
    assert!(max_abs(&(inc.r - step)) > 0.1);
}

// ---------------------------------------------------------------------------------------------
// 2. Orthogonality of r and ½r; the closed form against eqs 23 and 31 as written
// ---------------------------------------------------------------------------------------------

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, failure_persistence: None, rng_seed: proptest::test_runner::RngSeed::Fixed(0x4b1), ..ProptestConfig::default() })]

    /// `r` and `½r` are orthogonal with determinant 1 for random `Δω` (from random `L`, so a
    /// strain part rides along and must not matter). Entries are of unit scale, products of
    /// three 3×3 factors: a bound of `16 ε ≈ 3.6e-15` is round-off.
    #[test]
    fn r_and_half_r_are_rotations(entries in prop::collection::vec(-4.0f64..4.0, 9)) {
        let l = M3::from_row_slice(&entries);
        let inc = hughes_winget(&l).unwrap();
        let tol = 16.0 * f64::EPSILON;
        for (name, r) in [("r", inc.r), ("½r", inc.r_half)] {
            let orth = max_abs(&(r.transpose() * r - M3::identity()));
            let det = (r.determinant() - 1.0).abs();
            prop_assert!(orth <= tol, "{} not orthogonal: {:e}", name, orth);
            prop_assert!(det <= tol, "{} det − 1 = {:e}", name, det);
        }
        // Eq 23 and eq 31 as written, with a general inverse.
        let id = M3::<f64>::identity();
        let eq23 = id + (id - inc.domega * 0.5).try_inverse().unwrap() * inc.domega;
        let eq31 = id + (id - inc.domega * 0.25).try_inverse().unwrap() * inc.domega * 0.5;
        prop_assert!(max_abs(&(inc.r - eq23)) <= tol, "r vs eq 23");
        prop_assert!(max_abs(&(inc.r_half - eq31)) <= tol, "½r vs eq 31");
    }
}

/// `½r ½r ≠ r` in general (the paper's remark after eq 31): expanding both Cayley transforms,
/// `½r ½r − r = −(Δω³ + Δω⁴)/16 + O(Δω⁵)`, a third-order difference. Halving a small Δω divides
/// the gap by about 8, and the gap matches the series to its next order.
#[test]
fn half_rotation_squared_differs_from_r_at_third_order() {
    let w = M3::new(0.0, -0.3, 0.2, 0.3, 0.0, -0.4, -0.2, 0.4, 0.0);
    let gap = |s: f64| {
        let inc = hughes_winget(&(w * s)).unwrap();
        inc.r_half * inc.r_half - inc.r
    };
    assert!(max_abs(&gap(1.0)) > 1e-3, "½r² − r = {}", gap(1.0));
    let (g1, g2) = (max_abs(&gap(0.25)), max_abs(&gap(0.125)));
    let s = 0.125;
    let ws = w * s;
    let leading = -(ws * ws * ws + ws * ws * ws * ws) / 16.0;
    let rel = max_abs(&(gap(s) - leading)) / max_abs(&leading);
    println!("|½r² − r| at Δω/4, Δω/8: {g1:.3e}, {g2:.3e}, ratio {:.3}; vs −(Δω³ + Δω⁴)/16: rel. diff {rel:.2e}", g1 / g2);
    assert!((g1 / g2 - 8.0).abs() < 0.2, "ratio {}", g1 / g2);
    // The neglected O(Δω⁵) term is |ωs|² ≈ 0.5 % of the leading one here.
    assert!(
        rel < 0.02,
        "½r² − r differs from its series by {rel} (relative)"
    );
}

// ---------------------------------------------------------------------------------------------
// 3. Three-way derivative checks
// ---------------------------------------------------------------------------------------------

/// `H` (9 entries) → `L` (9 entries).
struct MidStep;
impl Differentiable for MidStep {
    fn n_inputs(&self) -> usize {
        9
    }
    fn eval<T: Real>(&self, x: &[T]) -> Vec<T> {
        flat(&mid_step_gradient(&mat(x, 0)).unwrap())
    }
}

fn check_mid_step(h: &M3<f64>, title: &str) -> DerivativeReport {
    let hand = jacobian(9, |j| flat(&mid_step_gradient_dot(h, &unit(j)).unwrap()));
    run_check(&MidStep, title, &flat(h), &hand)
}

#[test]
fn mid_step_gradient_dot_three_ways() {
    let mut rng = Rng(1);
    for k in 0..4 {
        check_mid_step(
            &random_h(&mut rng),
            &format!("mid_step_gradient_dot, H #{k}"),
        );
    }
}

/// Eqs 56–57: `M` applied to the rate of the gradient with respect to `ⁿ⁺¹x`, `Ġ = Ḣ (I + H)⁻¹`,
/// gives the same `L̇`; applied to the first line's `Ḣ F½⁻¹` (the transcription) it does not.
#[test]
fn m_tensor_of_eq_57_agrees_with_direct_derivative() {
    let mut rng = Rng(2);
    let mut worst = 0.0_f64;
    for _ in 0..8 {
        let h = random_h(&mut rng);
        let h_dot = rng.general(1.0);
        let direct = mid_step_gradient_dot(&h, &h_dot).unwrap();
        let f_inv = (M3::identity() + h).try_inverse().unwrap();
        let via_m = mid_step_gradient_dot_from_spatial(&h, &(h_dot * f_inv)).unwrap();
        let err = max_abs(&(via_m - direct)) / max_abs(&direct);
        worst = worst.max(err);
        assert!(err <= 1e-14, "M form vs direct: {err:e}");
        let f_half_inv = (M3::identity() + h * 0.5).try_inverse().unwrap();
        let transcribed = mid_step_gradient_dot_from_spatial(&h, &(h_dot * f_half_inv)).unwrap();
        assert!(max_abs(&(transcribed - direct)) / max_abs(&direct) > 1e-2);
    }
    println!("eq 57 M form vs direct L̇: worst relative difference {worst:.2e}");
}

/// Which part of the Hughes–Winget increment a kernel returns.
#[derive(Clone, Copy, Debug)]
enum HwPart {
    Deps,
    Domega,
    R,
    RHalf,
}

/// `L` (9 entries) → one part of [`HwIncrement`] (9 entries).
struct Hw(HwPart);
impl Differentiable for Hw {
    fn n_inputs(&self) -> usize {
        9
    }
    fn eval<T: Real>(&self, x: &[T]) -> Vec<T> {
        let inc = hughes_winget(&mat(x, 0)).unwrap();
        flat(&match self.0 {
            HwPart::Deps => inc.deps,
            HwPart::Domega => inc.domega,
            HwPart::R => inc.r,
            HwPart::RHalf => inc.r_half,
        })
    }
}

fn hw_hand(l: &M3<f64>, part: HwPart) -> DMatrix<f64> {
    let inc = hughes_winget(l).unwrap();
    jacobian(9, |j| {
        let d = hughes_winget_dot(&inc, &unit(j));
        flat(&match part {
            HwPart::Deps => d.deps_dot,
            HwPart::Domega => d.domega_dot,
            HwPart::R => d.r_dot,
            HwPart::RHalf => d.r_half_dot,
        })
    })
}

/// A mid-step gradient with a finite rotation (10°–60°) and a strain part.
fn random_l(rng: &mut Rng) -> M3<f64> {
    mid_step_gradient(&random_h(rng)).unwrap()
}

#[test]
fn hughes_winget_dot_three_ways() {
    let mut rng = Rng(3);
    for k in 0..4 {
        let l = random_l(&mut rng);
        for part in [HwPart::Deps, HwPart::Domega, HwPart::R, HwPart::RHalf] {
            run_check(
                &Hw(part),
                &format!("hughes_winget_dot {part:?}, L #{k}"),
                &flat(&l),
                &hw_hand(&l, part),
            );
        }
    }
}

/// Eq 55's `B^ε` as transcribed, `(4I − Δω)⁻¹ Δω̇ (I + r)`, disagrees with the dual-number
/// derivative of `½r`; with `½r` in place of `r` it agrees (the test above). The dual numbers
/// decide: the transcription is wrong by a relative amount of order `|Δω|`.
#[test]
fn transcribed_b_epsilon_of_eq_55_is_wrong() {
    let mut rng = Rng(4);
    let l = random_l(&mut rng);
    let inc = hughes_winget(&l).unwrap();
    let id = M3::<f64>::identity();
    let b_eps = (id * 4.0 - inc.domega).try_inverse().unwrap();
    let transcribed = jacobian(9, |j| flat(&(b_eps * skew(&unit(j)) * (id + inc.r))));
    let r = check(
        &Hw(HwPart::RHalf),
        "eq 55 B^ε as transcribed (with r)",
        &flat(&l),
        &transcribed,
        opts(),
    );
    println!("{r}");
    assert!(!r.vs_dual.passed() && r.vs_dual.max_error() > 1e-2, "{r}");
    // And B^σ as transcribed is right (same construction with 2I and r).
    let b_sig = (id * 2.0 - inc.domega).try_inverse().unwrap();
    let b_sigma = jacobian(9, |j| flat(&(b_sig * skew(&unit(j)) * (id + inc.r))));
    run_check(
        &Hw(HwPart::R),
        "eq 55 B^σ as transcribed",
        &flat(&l),
        &b_sigma,
    );
}

/// `(Qₙ, ½r, Δε)` (27 entries) → `Δεˡ` (9 entries), eq 30.
struct LocalStrain;
impl Differentiable for LocalStrain {
    fn n_inputs(&self) -> usize {
        27
    }
    fn eval<T: Real>(&self, x: &[T]) -> Vec<T> {
        flat(&local_strain_increment(&mat(x, 0), &mat(x, 9), &mat(x, 18)))
    }
}

/// Unit seed `j` of a kernel taking consecutive 3×3 matrices: (matrix index, seed).
fn seeds(n_mats: usize, j: usize) -> Vec<M3<f64>> {
    (0..n_mats)
        .map(|m| if j / 9 == m { unit(j % 9) } else { M3::zeros() })
        .collect()
}

fn check_local_strain(q: &M3<f64>, rh: &M3<f64>, deps: &M3<f64>, title: &str) {
    let hand = jacobian(27, |j| {
        let s = seeds(3, j);
        flat(&local_strain_increment_dot(
            q, &s[0], rh, &s[1], deps, &s[2],
        ))
    });
    let x: Vec<f64> = [flat(q), flat(rh), flat(deps)].concat();
    run_check(&LocalStrain, title, &x, &hand);
}

#[test]
fn local_strain_increment_dot_three_ways() {
    let mut rng = Rng(5);
    for k in 0..4 {
        let (q, rh, deps) = (rng.rotation().transpose(), rng.rotation(), rng.sym(0.05));
        check_local_strain(&q, &rh, &deps, &format!("local_strain_increment_dot #{k}"));
    }
}

/// `(Qₙ, r)` (18 entries) → `Qₙ₊₁` (9 entries), eq 27.
struct FrameUpdate;
impl Differentiable for FrameUpdate {
    fn n_inputs(&self) -> usize {
        18
    }
    fn eval<T: Real>(&self, x: &[T]) -> Vec<T> {
        flat(&frame_update(&mat(x, 0), &mat(x, 9)))
    }
}

#[test]
fn frame_update_dot_three_ways() {
    let mut rng = Rng(6);
    for k in 0..4 {
        let (q, r) = (rng.rotation().transpose(), rng.rotation());
        let hand = jacobian(18, |j| {
            let s = seeds(2, j);
            flat(&frame_update_dot(&q, &s[0], &r, &s[1]))
        });
        run_check(
            &FrameUpdate,
            &format!("frame_update_dot #{k}"),
            &[flat(&q), flat(&r)].concat(),
            &hand,
        );
    }
}

/// `(Q, σˡ)` (18 entries) → `σᵍ` (9 entries), eq 26; or `(r, σ)` → `r σ rᵀ`, eq 22.
struct StressMap {
    rotate: bool,
}
impl Differentiable for StressMap {
    fn n_inputs(&self) -> usize {
        18
    }
    fn eval<T: Real>(&self, x: &[T]) -> Vec<T> {
        let (a, s) = (mat(x, 0), mat(x, 9));
        flat(&if self.rotate {
            rotate_stress(&a, &s)
        } else {
            global_stress(&a, &s)
        })
    }
}

#[test]
fn global_stress_dot_and_rotate_stress_dot_three_ways() {
    let mut rng = Rng(7);
    for k in 0..4 {
        let (q, s) = (rng.rotation().transpose(), rng.sym(100.0));
        let hand = jacobian(18, |j| {
            let d = seeds(2, j);
            flat(&global_stress_dot(&q, &d[0], &s, &d[1]))
        });
        let x = [flat(&q), flat(&s)].concat();
        run_check(
            &StressMap { rotate: false },
            &format!("global_stress_dot #{k}"),
            &x,
            &hand,
        );
        let hand = jacobian(18, |j| {
            let d = seeds(2, j);
            flat(&rotate_stress_dot(&q, &d[0], &s, &d[1]))
        });
        run_check(
            &StressMap { rotate: true },
            &format!("rotate_stress_dot #{k}"),
            &x,
            &hand,
        );
    }
}

/// One whole step parametrised by a scalar design variable τ: a finite rotation (angle
/// `θ0 + aτ` about a fixed axis) with a stretch `S0 + τS1`, a lamina frame `Qₙ(τ)` rotated by
/// `φ0 + bτ`, and a local stress `σˡ0 + τS2`. Outputs: `L`, `Δε`, `Δω`, `r`, `½r`, `Δεˡ`,
/// `Qₙ₊₁` and the global stress `σᵍₙ₊₁ = Qₙ₊₁ᵀ (σˡₙ + Δσˡ) Qₙ₊₁` with a linear "material"
/// `Δσˡ = stress_from_vec5(k ⊙ strain_to_vec5(Δεˡ))`. The hand derivative chains every `*_dot`.
#[derive(Clone, Debug)]
struct Step {
    axis: [f64; 3],
    theta0: f64,
    a: f64,
    s0: M3<f64>,
    s1: M3<f64>,
    frame_axis: [f64; 3],
    phi0: f64,
    b: f64,
    sigma_l0: M3<f64>,
    s2: M3<f64>,
    moduli: Vec5<f64>,
}

impl Step {
    fn random(rng: &mut Rng) -> Self {
        Step {
            axis: rng.axis(),
            theta0: rng.uniform(10.0, 60.0).to_radians(),
            a: rng.uniform(-1.0, 1.0),
            s0: rng.sym(0.1),
            s1: rng.sym(0.1),
            frame_axis: rng.axis(),
            phi0: rng.uniform(10.0, 60.0).to_radians(),
            b: rng.uniform(-1.0, 1.0),
            sigma_l0: {
                let mut s = rng.sym(100.0);
                s[(2, 2)] = 0.0;
                s
            },
            s2: rng.sym(50.0),
            moduli: Vec5::new(1000.0, 1200.0, 400.0, 300.0, 350.0),
        }
    }

    /// The step at design τ.
    fn outputs<T: Real>(&self, tau: T) -> Vec<T> {
        let axis = self.axis.map(T::cst);
        let rot = rotation(axis, tau * self.a + self.theta0);
        let stretch = M3::identity() + lift::<T>(&self.s0) + lift::<T>(&self.s1) * tau;
        let h = rot * stretch - M3::identity();
        let q = rotation(self.frame_axis.map(T::cst), tau * self.b + self.phi0).transpose();
        let sigma_l = lift::<T>(&self.sigma_l0) + lift::<T>(&self.s2) * tau;
        let l = mid_step_gradient(&h).unwrap();
        let inc = hughes_winget(&l).unwrap();
        let deps_l = local_strain_increment(&q, &inc.r_half, &inc.deps);
        let moduli = self.moduli.map(T::cst);
        let dsig = stress_from_vec5(&moduli.component_mul(&strain_to_vec5(&deps_l)));
        let q1 = frame_update(&q, &inc.r);
        let sigma_g = global_stress(&q1, &(sigma_l + dsig));
        [
            l, inc.deps, inc.domega, inc.r, inc.r_half, deps_l, q1, sigma_g,
        ]
        .iter()
        .flat_map(flat)
        .collect()
    }

    /// Hand-derived d(outputs)/dτ at τ, chaining the `*_dot` functions.
    fn hand(&self, tau: f64) -> Vec<f64> {
        let n = cross_matrix(self.axis);
        let rot = rotation(self.axis, self.theta0 + self.a * tau);
        let stretch = M3::identity() + self.s0 + self.s1 * tau;
        let h = rot * stretch - M3::identity();
        let h_dot = n * rot * stretch * self.a + rot * self.s1;
        let frame = rotation(self.frame_axis, self.phi0 + self.b * tau);
        let q = frame.transpose();
        let q_dot = (cross_matrix(self.frame_axis) * frame * self.b).transpose();
        let sigma_l = self.sigma_l0 + self.s2 * tau;

        let l = mid_step_gradient(&h).unwrap();
        let l_dot = mid_step_gradient_dot(&h, &h_dot).unwrap();
        let inc = hughes_winget(&l).unwrap();
        let d = hughes_winget_dot(&inc, &l_dot);
        let deps_l = local_strain_increment(&q, &inc.r_half, &inc.deps);
        let deps_l_dot = local_strain_increment_dot(
            &q,
            &q_dot,
            &inc.r_half,
            &d.r_half_dot,
            &inc.deps,
            &d.deps_dot,
        );
        let dsig = stress_from_vec5(&self.moduli.component_mul(&strain_to_vec5(&deps_l)));
        let dsig_dot = stress_from_vec5(&self.moduli.component_mul(&strain_to_vec5(&deps_l_dot)));
        let q1 = frame_update(&q, &inc.r);
        let q1_dot = frame_update_dot(&q, &q_dot, &inc.r, &d.r_dot);
        let sigma_g_dot = global_stress_dot(&q1, &q1_dot, &(sigma_l + dsig), &(self.s2 + dsig_dot));
        [
            l_dot,
            d.deps_dot,
            d.domega_dot,
            d.r_dot,
            d.r_half_dot,
            deps_l_dot,
            q1_dot,
            sigma_g_dot,
        ]
        .iter()
        .flat_map(flat)
        .collect()
    }
}

impl Differentiable for Step {
    fn n_inputs(&self) -> usize {
        1
    }
    fn eval<T: Real>(&self, x: &[T]) -> Vec<T> {
        self.outputs(x[0])
    }
    fn output_label(&self, i: usize) -> String {
        let names = ["L", "Δε", "Δω", "r", "½r", "Δεˡ", "Qₙ₊₁", "σᵍₙ₊₁"];
        format!("{}[{},{}]", names[i / 9], i % 9 / 3 + 1, i % 3 + 1)
    }
    fn input_label(&self, _j: usize) -> String {
        "τ".to_string()
    }
}

fn check_step(step: &Step, tau: f64, title: &str) -> DerivativeReport {
    let hand = DMatrix::from_column_slice(72, 1, &step.hand(tau));
    run_check_with(step, title, &[tau], &hand, chain_opts())
}

#[test]
fn whole_step_chain_three_ways() {
    let mut rng = Rng(8);
    for k in 0..4 {
        let step = Step::random(&mut rng);
        check_step(&step, 0.3, &format!("whole step d/dτ #{k}"));
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, failure_persistence: None, rng_seed: proptest::test_runner::RngSeed::Fixed(0x4b2), ..ProptestConfig::default() })]

    /// The whole-step chain for random steps (finite rotations of 10°–60°, stretches to 10 %).
    #[test]
    fn whole_step_chain_random(seed in any::<u64>(), tau in -0.5f64..0.5) {
        let step = Step::random(&mut Rng(seed));
        let hand = DMatrix::from_column_slice(72, 1, &step.hand(tau));
        let r = check(&step, "whole step (proptest)", &[tau], &hand, chain_opts());
        prop_assert!(r.passed(), "{}", r);
    }

    /// All matrix entries: the mid-step gradient and the Hughes–Winget parts for random `H`.
    #[test]
    fn entrywise_derivatives_random(seed in any::<u64>()) {
        let mut rng = Rng(seed);
        let h = random_h(&mut rng);
        let hand = jacobian(9, |j| flat(&mid_step_gradient_dot(&h, &unit(j)).unwrap()));
        let r = check(&MidStep, "mid_step_gradient_dot (proptest)", &flat(&h), &hand, opts());
        prop_assert!(r.passed(), "{}", r);
        let l = mid_step_gradient(&h).unwrap();
        for part in [HwPart::R, HwPart::RHalf] {
            let r = check(&Hw(part), "hughes_winget_dot (proptest)", &flat(&l), &hw_hand(&l, part), opts());
            prop_assert!(r.passed(), "{}", r);
        }
        let (q, rh, deps) = (rng.rotation().transpose(), rng.rotation(), rng.sym(0.05));
        let hand = jacobian(27, |j| {
            let s = seeds(3, j);
            flat(&local_strain_increment_dot(&q, &s[0], &rh, &s[1], &deps, &s[2]))
        });
        let x: Vec<f64> = [flat(&q), flat(&rh), flat(&deps)].concat();
        let r = check(&LocalStrain, "local_strain_increment_dot (proptest)", &x, &hand, opts());
        prop_assert!(r.passed(), "{}", r);
    }
}

// ---------------------------------------------------------------------------------------------
// Voigt conversions and errors
// ---------------------------------------------------------------------------------------------

/// Round trips, and work conjugacy: `σ : ε` (full double contraction, σ33 = 0) equals the dot
/// product of the shell 5-vectors, which is what the factor 2 on the shear strains is for.
#[test]
fn vec5_conversions_round_trip_and_are_work_conjugate() {
    let s: Vec5<f64> = Vec5::new(100.0, -50.0, 30.0, 10.0, -20.0);
    let e: Vec5<f64> = Vec5::new(1e-3, -2e-3, 3e-3, 4e-3, -5e-3);
    let (sm, em) = (stress_from_vec5(&s), strain_from_vec5(&e));
    assert_eq!(stress_to_vec5(&sm), s);
    assert_eq!(strain_to_vec5(&em), e);
    assert_eq!(sm, sm.transpose());
    assert_eq!(em, em.transpose());
    assert_eq!((sm[(2, 2)], em[(2, 2)]), (0.0, 0.0));
    assert_eq!((sm[(0, 1)], sm[(1, 2)], sm[(2, 0)]), (30.0, 10.0, -20.0));
    assert_eq!(
        (em[(0, 1)], em[(1, 2)], em[(2, 0)]),
        (1.5e-3, 2e-3, -2.5e-3)
    );
    let tensor_work = sm.component_mul(&em).sum();
    assert!((tensor_work - s.dot(&e)).abs() <= 1e-15 * s.dot(&e).abs().max(1.0));
}

#[test]
fn bad_inputs_are_named_errors_not_panics() {
    // A rigid half-turn collapses the mid-step configuration: det(I + ½H) = 0.
    let half_turn = rotation([0.0, 0.0, 1.0], std::f64::consts::PI);
    let err = mid_step_gradient(&(half_turn - M3::identity())).unwrap_err();
    assert!(
        matches!(err, KinematicsError::Singular { what: "I + ½H", det, .. } if det.abs() < 1e-12),
        "{err}"
    );
    assert!(mid_step_gradient_dot(&(half_turn - M3::identity()), &M3::identity()).is_err());
    // An inverted mid-step configuration (det(I + ½H) < 0) is rejected too.
    let err = mid_step_gradient(&(M3::<f64>::identity() * -4.0)).unwrap_err();
    assert!(
        err.to_string().contains("I + ½H") && err.to_string().contains("det = -1e0"),
        "{err}"
    );
    // Non-finite entries are named with their position and value.
    let mut h = M3::<f64>::zeros();
    h[(1, 2)] = f64::NAN;
    let err = mid_step_gradient(&h).unwrap_err();
    assert!(
        matches!(err, KinematicsError::NonFinite { row: 1, col: 2, .. }),
        "{err}"
    );
    let mut l = M3::<f64>::zeros();
    l[(2, 0)] = f64::INFINITY;
    let err = hughes_winget(&l).unwrap_err();
    assert!(
        err.to_string().contains("(2, 0)") && err.to_string().contains("inf"),
        "{err}"
    );
    // |ω|² overflows: det(I − ½Δω) is not finite.
    let huge = M3::new(0.0, -1e200, 0.0, 1e200, 0.0, 0.0, 0.0, 0.0, 0.0);
    let err = hughes_winget(&huge).unwrap_err();
    assert!(
        matches!(
            err,
            KinematicsError::Singular {
                what: "I − ½Δω",
                ..
            }
        ),
        "{err}"
    );
    // Duals go through the same checks (on the real part).
    let hd: M3<shelldsa::scalar::Dual> = lift(&(half_turn - M3::identity()));
    assert!(mid_step_gradient(&hd).is_err());
}
