//! Tests of the quadrature rules (`shelldsa::meshfree::quadrature`).

use shelldsa::meshfree::quadrature::*;
use shelldsa::meshfree::ParamBox;

/// `∫_{−1}^{1} x^k dx`.
fn exact_monomial(k: u32) -> f64 {
    if k % 2 == 1 {
        0.0
    } else {
        2.0 / (k as f64 + 1.0)
    }
}

/// Gauss–Legendre with n points is exact for x^k, k ≤ 2n − 1, to 1e-14, and not for x^{2n}.
#[test]
fn gauss_legendre_exactness() {
    let mut worst: f64 = 0.0;
    for n in 1..=MAX_GAUSS_POINTS {
        let r = gauss_legendre(n).unwrap();
        assert_eq!(r.len(), n);
        assert!(
            (r.weights.iter().sum::<f64>() - 2.0).abs() < 1e-14,
            "n = {n}"
        );
        assert!(r.weights.iter().all(|&w| w > 0.0));
        assert!(r.nodes.windows(2).all(|w| w[0] < w[1]));
        assert!(r.nodes.iter().all(|&x| x > -1.0 && x < 1.0));
        for k in 0..=(2 * n as u32 - 1) {
            let e = (r.integrate(|x| x.powi(k as i32)) - exact_monomial(k)).abs();
            worst = worst.max(e);
            assert!(e < 1e-14, "Gauss n = {n}, x^{k}: error {e:e}");
        }
        let k = 2 * n as u32;
        let e = (r.integrate(|x| x.powi(k as i32)) - exact_monomial(k)).abs();
        assert!(
            e > 1e-6,
            "Gauss n = {n} should not integrate x^{k} exactly ({e:e})"
        );
    }
    println!("Gauss–Legendre worst monomial error: {worst:.2e}");
}

/// Gauss–Lobatto with n points is exact for x^k, k ≤ 2n − 3, and not for x^{2n−2}.
#[test]
fn gauss_lobatto_exactness() {
    let mut worst: f64 = 0.0;
    for n in 2..=MAX_LOBATTO_POINTS {
        let r = gauss_lobatto(n).unwrap();
        assert_eq!(r.len(), n);
        assert_eq!(r.nodes[0], -1.0);
        assert_eq!(r.nodes[n - 1], 1.0);
        assert!(
            (r.weights.iter().sum::<f64>() - 2.0).abs() < 1e-14,
            "n = {n}"
        );
        assert!(r.weights.iter().all(|&w| w > 0.0));
        assert!(r.nodes.windows(2).all(|w| w[0] < w[1]));
        for k in 0..=(2 * n as u32 - 3) {
            let e = (r.integrate(|x| x.powi(k as i32)) - exact_monomial(k)).abs();
            worst = worst.max(e);
            assert!(e < 1e-14, "Lobatto n = {n}, x^{k}: error {e:e}");
        }
        let k = 2 * n as u32 - 2;
        let e = (r.integrate(|x| x.powi(k as i32)) - exact_monomial(k)).abs();
        assert!(
            e > 1e-6,
            "Lobatto n = {n} should not integrate x^{k} exactly ({e:e})"
        );
    }
    println!("Gauss–Lobatto worst monomial error: {worst:.2e}");
}

/// Spot values against published tables (16+ digits).
#[test]
fn rules_match_tabulated_values() {
    let g3 = gauss_legendre(3).unwrap();
    assert!((g3.nodes[2] - 0.774_596_669_241_483_4).abs() <= 2.3e-16);
    assert!(
        (g3.weights[0] - 5.0 / 9.0).abs() < 1e-15,
        "{:e}",
        g3.weights[0] - 5.0 / 9.0
    );
    assert_eq!(g3.nodes[1], 0.0);
    assert!((g3.weights[1] - 8.0 / 9.0).abs() < 1e-15);
    let g5 = gauss_legendre(5).unwrap();
    assert!((g5.nodes[4] - 0.906_179_845_938_664).abs() < 1e-15);
    assert!((g5.weights[4] - 0.236_926_885_056_189_1).abs() < 1e-15);
    let g10 = gauss_legendre(10).unwrap();
    assert!((g10.nodes[9] - 0.973_906_528_517_171_7).abs() < 1e-15);
    assert!((g10.weights[9] - 0.066_671_344_308_688_14).abs() < 1e-15);
    assert!((g10.nodes[5] - 0.148_874_338_981_631_2).abs() < 1e-15);
    assert!((g10.weights[5] - 0.295_524_224_714_752_9).abs() < 1e-15);
    let l7 = gauss_lobatto(7).unwrap();
    assert!((l7.nodes[5] - 0.830_223_896_278_566_9).abs() < 1e-15);
    assert!((l7.nodes[4] - 0.468_848_793_470_714_2).abs() < 1e-15);
    assert!((l7.weights[6] - 1.0 / 21.0).abs() < 1e-15);
    assert!((l7.weights[5] - 0.276_826_047_361_565_9).abs() < 1e-15);
    assert!((l7.weights[4] - 0.431_745_381_209_862_6).abs() < 1e-15);
    assert!((l7.weights[3] - 256.0 / 525.0).abs() < 1e-15);
    let l5 = gauss_lobatto(5).unwrap();
    assert!((l5.nodes[3] - 21f64.sqrt() / 7.0).abs() < 1e-15);
    assert!((l5.weights[0] - 0.1).abs() < 1e-15);
    assert!((l5.weights[1] - 49.0 / 90.0).abs() < 1e-15);
    assert!((l5.weights[2] - 32.0 / 45.0).abs() < 1e-15);
    let l3 = gauss_lobatto(3).unwrap();
    assert_eq!(l3.nodes, vec![-1.0, 0.0, 1.0]);
    assert!((l3.weights[1] - 4.0 / 3.0).abs() < 1e-15);
}

#[test]
fn thickness_rules() {
    let g = ThicknessRule::Gauss(2).rule().unwrap();
    assert!((g.nodes[1] - 1.0 / 3f64.sqrt()).abs() <= 2.3e-16);
    let l = ThicknessRule::Lobatto(5).rule().unwrap();
    assert_eq!(l.nodes[0], -1.0);
    assert_eq!(l.nodes[4], 1.0);
    assert_eq!(ThicknessRule::Lobatto(5).points(), 5);
    // ∫ ζ² dζ = 2/3 through the thickness.
    assert!((l.integrate(|z| z * z) - 2.0 / 3.0).abs() < 1e-15);
}

/// Cell quadrature integrates a bivariate polynomial exactly over a box; weights sum to the area;
/// cell indices and cell boxes are consistent.
#[test]
fn cell_quadrature_integrates_bivariate_polynomial() {
    let b = ParamBox::new([0.5, 2.0], [-1.0, 1.5]);
    // p(u, v) = Σ c_ij u^i v^j, i ≤ 5, j ≤ 4: exact with 3 Gauss points per direction.
    let coef = |i: i32, j: i32| 0.3 * (i + 1) as f64 - 0.2 * (j as f64) + 0.05 * (i * j) as f64;
    let p = |x: [f64; 2]| {
        let mut s = 0.0;
        for i in 0..=5 {
            for j in 0..=4 {
                s += coef(i, j) * x[0].powi(i) * x[1].powi(j);
            }
        }
        s
    };
    let mut exact = 0.0;
    for i in 0..=5 {
        for j in 0..=4 {
            let iu = (b.hi[0].powi(i + 1) - b.lo[0].powi(i + 1)) / (i + 1) as f64;
            let iv = (b.hi[1].powi(j + 1) - b.lo[1].powi(j + 1)) / (j + 1) as f64;
            exact += coef(i, j) * iu * iv;
        }
    }
    for (nu, nv) in [(1, 1), (3, 5), (7, 2)] {
        let q = CellQuadrature::new(b, nu, nv, 3).unwrap();
        assert_eq!(q.len(), nu * nv * 9);
        assert_eq!(q.n_cells(), [nu, nv]);
        let area: f64 = q.weights().iter().sum();
        assert!((area - 3.75).abs() < 1e-14);
        let e = (q.integrate(p) - exact).abs();
        assert!(e < 1e-13 * exact.abs(), "{nu}×{nv}: {e:e} (exact {exact})");
        for (x, _, c) in q.iter() {
            assert!(q.cell_box(c).contains(x));
        }
        // Degree 6 in u is not integrated exactly by 3 points in one cell.
        if nu == 1 {
            let e6 = (q.integrate(|x| x[0].powi(6))
                - (b.hi[0].powi(7) - b.lo[0].powi(7)) / 7.0 * 2.5)
                .abs();
            assert!(e6 > 1e-8);
        }
    }
}

#[test]
fn cell_quadrature_for_particle_grid() {
    let g = shelldsa::meshfree::jittered_grid(ParamBox::unit(), 6, 4, 0.3, 3);
    let q = CellQuadrature::for_particle_grid(&g, 2, 4).unwrap();
    assert_eq!(q.n_cells(), [10, 6]);
    assert_eq!(q.len(), 60 * 16);
    assert_eq!(q.param_box(), ParamBox::unit());
}

#[test]
fn errors_name_parameter_and_value() {
    let e = gauss_legendre(11).unwrap_err();
    assert!(e.to_string().contains("n = 11"), "{e}");
    assert!(gauss_legendre(0).is_err());
    let e = gauss_lobatto(1).unwrap_err();
    assert!(e.to_string().contains("Gauss–Lobatto") && e.to_string().contains("n = 1"));
    assert!(gauss_lobatto(8).is_err());
    assert!(ThicknessRule::Lobatto(9).rule().is_err());
    let e = CellQuadrature::new(ParamBox::new([0.0, 1.0], [2.0, 2.0]), 2, 2, 2).unwrap_err();
    assert_eq!(
        e,
        QuadratureError::EmptyBox {
            axis: "v",
            lo: 2.0,
            hi: 2.0
        }
    );
    assert!(e.to_string().contains("along v"));
    let e = CellQuadrature::new(ParamBox::unit(), 0, 2, 2).unwrap_err();
    assert!(e.to_string().contains("n_cells_u = 0"), "{e}");
    let e = CellQuadrature::new(ParamBox::unit(), 2, 2, 12).unwrap_err();
    assert!(e.to_string().contains("n = 12"), "{e}");
}
