//! The unit director's kernels (`kinematics::unit_director`): `N′`, `H(y) = ∇³ℓ·y` and
//! `T(y, b) = ∇⁴ℓ·y·b` of `ℓ(r) = |r|` against dual numbers and central differences; the step
//! change `d₁ − dₙ` and the changes of the maps against differences in higher precision (the
//! two ends evaluated and subtracted in dual numbers would carry the same cancellation).

use nalgebra::{Matrix3, Vector3};
use num_dual::Dual64;
use shelldsa::kinematics::unit_director::{
    n_prime, n_prime_apply, n_second, n_second_apply, n_third, normalise, step_change,
};
use shelldsa::meshfree::XorShift64;

type V3 = Vector3<f64>;

fn random(rng: &mut XorShift64, s: f64) -> V3 {
    V3::from_fn(|_, _| s * (2.0 * rng.next_f64() - 1.0))
}

/// `r` of length about 0.9–1.1 (the interpolant of unit directors), `y`, `b` of unit scale.
fn sample(seed: u64) -> (V3, V3, V3) {
    let mut rng = XorShift64::new(seed);
    let r = (V3::new(0.3, -0.2, 0.9) + random(&mut rng, 0.1)) * (0.9 + 0.2 * rng.next_f64());
    (r, random(&mut rng, 1.0), random(&mut rng, 1.0))
}

/// `N(r) = r/|r|` in dual numbers along `v`, and its derivative.
fn n_along(r: &V3, v: &V3, f: impl Fn(&Vector3<Dual64>) -> Vector3<Dual64>) -> V3 {
    let rd = Vector3::from_fn(|i, _| Dual64::new(r[i], v[i]));
    f(&rd).map(|x| x.eps)
}

/// Dual numbers differentiate the closed forms' parents exactly: 1e-13 relative to the largest
/// entry (each closed form has a handful of rounded products of unit-scale terms).
const DUAL_TOL: f64 = 1e-13;

#[test]
fn derivatives_of_the_normalisation_equal_dual_numbers() {
    for seed in 1..6 {
        let (r, y, b) = sample(seed);
        let l = r.norm();
        let d = r / l;
        let np = n_prime(&d, l);
        for (k, v) in [V3::x(), V3::y(), V3::z(), y, b].iter().enumerate() {
            // N′ v = d/dε N(r + ε v).
            let dual = n_along(&r, v, |rd| rd / rd.norm());
            let e = (np * v - dual).amax() / dual.amax().max(1e-300);
            assert!(e < DUAL_TOL, "seed {seed}, direction {k}: N′ {e:e}");
            // H(y) v = d/dε [N′(r + ε v) y], N′(r) y = (y − N (N·y))/|r|.
            let dual = n_along(&r, v, |rd| {
                let n = rd / rd.norm();
                let yd = y.map(Dual64::from);
                (yd - n * n.dot(&yd)) / rd.norm()
            });
            let e = (n_second(&d, l, &y) * v - dual).amax() / dual.amax();
            assert!(e < DUAL_TOL, "seed {seed}, direction {k}: H {e:e}");
            // T(y, b) v = d/dε [H(r + ε v; y) b].
            let dual = n_along(&r, v, |rd| {
                let l = rd.norm();
                let n = rd / l;
                let (yd, bd) = (y.map(Dual64::from), b.map(Dual64::from));
                let (s, t) = (yd.dot(&n), bd.dot(&n));
                (n * (s * t * 3.0) - yd * t - n * yd.dot(&bd) - bd * s) / (l * l)
            });
            let e = (n_third(&d, l, &y, &b) * v - dual).amax() / dual.amax();
            assert!(e < DUAL_TOL, "seed {seed}, direction {k}: T {e:e}");
        }
        // Full symmetry of ∇³ℓ and ∇⁴ℓ: H(y) b = H(b) y, T(y, b) = T(b, y), all symmetric.
        let (hy, hb) = (n_second(&d, l, &y), n_second(&d, l, &b));
        assert!((hy * b - hb * y).amax() < 1e-14 * (hy * b).amax());
        // The generic product forms equal the matrices'.
        let nb = n_prime_apply(&d, l, &b);
        assert!((nb - np * b).amax() < 1e-15 * nb.amax());
        let applied = n_second_apply(&d, l, &y, &b);
        assert!((applied - hy * b).amax() < 1e-14 * applied.amax());
        let t = n_third(&d, l, &y, &b);
        assert!((t - n_third(&d, l, &b, &y)).amax() < 1e-14 * t.amax());
        assert!((t - t.transpose()).amax() < 1e-14 * t.amax());
        assert!((hy - hy.transpose()).amax() < 1e-15 * hy.amax());
    }
}

/// Central differences of `N′ v` in direction `w` with h = 1e-5: truncation ~h² |N‴| ~ 1e-10,
/// round-off ~ε/h ~ 1e-11, so 1e-8 relative.
#[test]
fn second_derivative_equals_central_differences() {
    let (r, y, b) = sample(11);
    let (l, h) = (r.norm(), 1e-5);
    let d = r / l;
    let np_at = |r: &V3| n_prime(&(r / r.norm()), r.norm());
    let fd = (np_at(&(r + b * h)) * y - np_at(&(r - b * h)) * y) / (2.0 * h);
    let hand = n_second(&d, l, &y) * b;
    let e = (hand - fd).amax() / hand.amax();
    assert!(e < 1e-8, "{e:e}");
}

/// The step change at a tiny increment `δ ~ 1e-9`, where the difference of the two ends would
/// keep only ~7 digits (absolute error ~ε on a change ~1e-9): the step's formulas keep them
/// all. References: the expansion `N′δ + ½N″[δ, δ]` (error ~|δ|³), and for the changes of the
/// maps the derivative at the midpoint (error ~|δ|³ of the change); all evaluated from terms of
/// the change's size, so ~ε relative. 1e-13 relative for the director and the maps (measured
/// ≤ 8e-16), 1e-8 for `d,α`, whose first-order reference omits the O(δ²) terms.
#[test]
fn step_change_keeps_the_digits_of_small_increments() {
    let (r, y, b) = sample(21);
    let r_a = [y * 0.3, b * 0.2];
    let delta = V3::new(1e-9, -2e-9, 0.5e-9);
    let delta_a = [V3::new(-1e-9, 0.3e-9, 2e-9), V3::new(0.2e-9, 1e-9, -1e-9)];
    let st = step_change(&r, &r_a, &delta, &delta_a);
    let l = r.norm();
    let d = r / l;
    let np = n_prime(&d, l);
    let expect = np * delta + n_second(&d, l, &delta) * delta * 0.5;
    let e = (st.dd - expect).amax() / expect.amax();
    assert!(e < 1e-12, "d₁ − dₙ: {e:e}");
    // d,α = N′ r,α; its change to first order: N′ δ,α + H(r,α) δ (+ O(δ²) ~ 1e-18 relative).
    for a in 0..2 {
        let expect = np * delta_a[a] + n_second(&d, l, &r_a[a]) * delta;
        let e = (st.dd_a[a] - expect).amax() / expect.amax();
        assert!(e < 1e-8, "d₁,α − dₙ,α [{a}]: {e:e}");
    }
    // The two ends agree with `normalise`.
    let (d1, d1_a, l1) = normalise(&(r + delta), &[r_a[0] + delta_a[0], r_a[1] + delta_a[1]]);
    assert!((st.d1 - d1).amax() < 1e-15 && (st.l1 - l1).abs() < 1e-15);
    assert!((st.d1_a[0] - d1_a[0]).amax() < 1e-15);
    // N′₁ − N′ₙ against d/dε N′(r + εδ) at ε = ½, whose column j is N″[δ, e_j] = H(e_j) δ.
    let dn = st.n_prime_change();
    let mid = r + delta * 0.5;
    let expect = Matrix3::from_fn(|i, j| {
        let e_j = V3::from_fn(|k, _| f64::from(u8::from(k == j)));
        (n_second(&(mid / mid.norm()), mid.norm(), &e_j) * delta)[i]
    });
    let e = (dn - expect).amax() / expect.amax();
    assert!(e < 1e-13, "N′₁ − N′ₙ: {e:e}");
    println!(
        "step change: d {:.2e}, N′ {e:.2e}",
        (st.dd - np * delta - n_second(&d, l, &delta) * delta * 0.5).amax() / st.dd.amax()
    );
    // H₁(r,α) − Hₙ(r,α): d/dε H(r + εδ; r,α + εδ,α) at ε = ½, whose column j is
    // T(y, e_j) δ + H(δ,α) e_j.
    for a in 0..2 {
        let y_mid = r_a[a] + delta_a[a] * 0.5;
        let (dm, lm) = (mid / mid.norm(), mid.norm());
        let expect = Matrix3::from_fn(|i, j| {
            let e_j = V3::from_fn(|k, _| f64::from(u8::from(k == j)));
            (n_third(&dm, lm, &y_mid, &e_j) * delta + n_second(&dm, lm, &delta_a[a]) * e_j)[i]
        });
        let got = st.n_second_change(a, &r_a[a]);
        let e = (got - expect).amax() / expect.amax();
        println!("H₁ − Hₙ [{a}]: {e:.2e}");
        assert!(e < 1e-13, "H₁ − Hₙ [{a}]: {e:e}");
    }
}
