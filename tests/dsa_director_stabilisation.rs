//! The director-filter stabilisation (`docs/stability.md` §3) in the three derivative paths.
//!
//! 1. Its coefficients `δ_IJ − Ψ_J(ξ_I)` live on the parameter domain: the hemisphere's shape
//!    variables (radius, latitude of the hole's rim) leave them unchanged, bit for bit.
//! 2. Model level: at a rotated committed state with symmetry images and a fixed increment,
//!    the hand-derived design derivative (`DirectorFilter::add_design_derivative`: `κ̇` from
//!    `Ė, ν̇, ṫ`, `Ḃ` from the committed `ḋ, ė`) against the `Dual64` force on the dual
//!    committed state (`Load::force` with a `LoadState`, the call of the dual reference), and
//!    against central differences of the force of a filter rebuilt on the perturbed model
//!    (`DirectorFilter::new` + `force`, the analysis' own path). The load stiffness against the
//!    `Dual64` Jacobian in the increment. Both on the model's own RK functions and on those of
//!    supports of 2 spacings (`integration.director_stabilisation_support`).
//! 3. Whole run: the reduced elastoplastic hemisphere (`verification/hemisphere-plastic-dsa/
//!    ci.toml`) with `director_stabilisation = 0.1` (its filter on supports of 2 spacings,
//!    `director_stabilisation_support = 2`) through `shelldsa dsa`: continuum = dual,
//!    both against central differences of complete re-runs, Taylor rates, and `--terms`: the
//!    continuum's `filter` group against the dual force of the filter alone.
//!
//! Run: `cargo test --release --test dsa_director_stabilisation -- --nocapture`.

use nalgebra::Vector3;
use num_dual::Dual64;
use serde_json::Value;
use shelldsa::io::shell_build;
use shelldsa::io::shell_case::parse_shell_case;
use shelldsa::shell::load::{Load, LoadState};
use shelldsa::shell::model::{commit_particle, ShellModel};
use shelldsa::shell::point::{ParticleState, DOFS_PER_PARTICLE};
use shelldsa::shell::problem::ShellProblem;
use shelldsa::shell::stabilisation::DirectorFilter;
use std::path::{Path, PathBuf};

#[path = "common/cli.rs"]
mod cli;
use cli::cli;

#[path = "common/dsa_checks.rs"]
mod dsa_checks;
use dsa_checks::assert_three_ways;

#[path = "common/director_filter.rs"]
mod director_filter;
use director_filter::filter;

#[path = "common/small_bending.rs"]
mod small_bending;
use small_bending::{max_abs, Lcg};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The case's kernel support (spacings).
const KERNEL_SUPPORT: f64 = 3.0;
/// The filter supports tested: the kernel's (the default) and the smallest
/// (`integration.director_stabilisation_support`, docs/stability.md §8).
const FILTER_SUPPORTS: [f64; 2] = [KERNEL_SUPPORT, 2.0];

/// The reduced plastic hemisphere with the stabilisation on, on a `grid × grid` particle set,
/// its filter on RK functions of `support` spacings.
fn case_text(grid: usize, support: f64) -> String {
    let t = std::fs::read_to_string(root().join("verification/hemisphere-plastic-dsa/ci.toml"))
        .unwrap();
    assert!(t.contains("grid = [9, 9]") && t.contains("[integration]\n"));
    assert!(t.contains(&format!("support = {KERNEL_SUPPORT:.1}")));
    t.replace("grid = [9, 9]", &format!("grid = [{grid}, {grid}]"))
        .replacen(
            "[integration]\n",
            &format!(
                "[integration]\ndirector_stabilisation = 0.1\n\
                 director_stabilisation_support = {support}\n"
            ),
            1,
        )
}

fn problem(text: &str) -> ShellProblem {
    let case = parse_shell_case(text, Path::new("stabilised.toml")).unwrap();
    shell_build::build(&case).unwrap().problem
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).fold(0.0, |m, (x, y)| m.max((x - y).abs()))
}

#[test]
fn filter_rows_live_on_the_parameter_domain() {
    for support in FILTER_SUPPORTS {
        rows_on_the_parameter_domain(support);
    }
}

fn rows_on_the_parameter_domain(support: f64) {
    let text = case_text(9, support);
    let nominal = problem(&text);
    let f0 = filter(&nominal);
    assert!(f0.rows().iter().all(|r| r.len() > 1));
    // Images among the row entries (the symmetry planes): the test covers their maps.
    let n = nominal.model.n_particles();
    assert!(f0.rows().iter().flatten().any(|(j, _)| *j >= n));
    for (from, to) in [
        ("radius = 10.0", "radius = 10.3"),
        ("latitude_deg = [0.0, 72.0]", "latitude_deg = [0.0, 75.0]"),
    ] {
        assert!(text.contains(from));
        let moved = problem(&text.replace(from, to));
        // Same coefficients, bit for bit: Ψ_J(ξ_I) has no shape design derivative.
        assert_eq!(filter(&moved).rows(), f0.rows(), "{to}");
        assert_eq!(moved.model.particle_uv, nominal.model.particle_uv);
        // κ = ε E t³/(12(1 − ν²)) does not see the geometry.
        assert_eq!(filter(&moved).kappa(), f0.kappa());
    }
}

/// The seeds of one direction: rotation rates of the committed particles (rad per unit τ)
/// and the rates of `E, ν, t`.
#[derive(Clone)]
struct Seeds {
    rotation: Vec<[f64; 2]>,
    young: f64,
    poisson: f64,
    thickness: f64,
}

/// The committed particle states at design `τ` (generic): each of `base` rotated by `τ` times
/// its rotation rate with the model's own particle update (Rodrigues).
fn particles_at<T: shelldsa::scalar::Real>(
    base: &[ParticleState<f64>],
    s: &Seeds,
    tau: T,
) -> Vec<ParticleState<T>> {
    base.iter()
        .zip(&s.rotation)
        .map(|(p, r)| {
            let z = T::zero();
            commit_particle(&p.lift(), &[z, z, z, tau * r[0], tau * r[1]])
        })
        .collect()
}

/// The filter force of a filter rebuilt on `model` with the design at `τ` (the analysis' path:
/// `DirectorFilter::new` reads `E, ν, t` of the model, `force` its committed states), its rows
/// from supports `scale` times the model's.
fn rebuilt_force(
    model: &ShellModel,
    (eps, scale): (f64, f64),
    s: &Seeds,
    tau: f64,
    q: &[f64],
) -> Vec<f64> {
    let mut m = model.clone();
    m.particles = particles_at(&model.particles, s, tau);
    m.material.young += tau * s.young;
    m.material.poisson += tau * s.poisson;
    m.thickness += tau * s.thickness;
    let filt = DirectorFilter::new(&m, eps)
        .and_then(|f| f.with_filter_support(&m, scale))
        .unwrap();
    let mut f = vec![0.0; q.len()];
    filt.force(&m, q, &mut f).unwrap();
    f
}

#[test]
fn design_derivative_three_ways() {
    for support in FILTER_SUPPORTS {
        design_derivative_with_filter_support(support);
    }
}

fn design_derivative_with_filter_support(support: f64) {
    let scale_of_support = support / KERNEL_SUPPORT;
    let p = problem(&case_text(9, support));
    let filt = filter(&p).clone();
    let mut model = p.model.clone();
    let n = model.n_particles();
    let mut rng = Lcg(17);
    // A committed state away from the initial one: every particle rotated by up to 0.2 rad.
    for st in &mut model.particles {
        let a = [0.2 * rng.next(), 0.2 * rng.next()];
        *st = commit_particle(st, &[0.0, 0.0, 0.0, a[0], a[1]]);
    }
    // The increment: rotations up to 0.02 rad (translations do not enter).
    let q: Vec<f64> = (0..DOFS_PER_PARTICLE * n)
        .map(|i| {
            if i % DOFS_PER_PARTICLE >= 3 {
                0.02 * rng.next()
            } else {
                1e-3 * rng.next()
            }
        })
        .collect();
    let (e, nu, t) = (
        model.material.young,
        model.material.poisson,
        model.thickness,
    );
    let rotation: Vec<[f64; 2]> = (0..n).map(|_| [rng.next(), rng.next()]).collect();
    let none = Seeds {
        rotation: vec![[0.0; 2]; n],
        young: 0.0,
        poisson: 0.0,
        thickness: 0.0,
    };
    let cases = [
        (
            "directors",
            Seeds {
                rotation: rotation.clone(),
                ..none.clone()
            },
        ),
        (
            "young",
            Seeds {
                young: e,
                ..none.clone()
            },
        ),
        (
            "poisson",
            Seeds {
                poisson: 1.0,
                ..none.clone()
            },
        ),
        (
            "thickness",
            Seeds {
                thickness: t,
                ..none.clone()
            },
        ),
        (
            "all",
            Seeds {
                rotation,
                young: e,
                poisson: 1.0,
                thickness: t,
            },
        ),
    ];
    for (name, s) in &cases {
        // Dual: the state and design in Dual64, through the dual reference's call.
        let parts = particles_at(&model.particles, s, Dual64::new(0.0, 1.0));
        let surfaces = [];
        let state = LoadState {
            particles: &parts,
            surfaces: &surfaces,
            positions: None,
            surface: None,
            thickness: Dual64::new(t, s.thickness),
            young: Dual64::new(e, s.young),
            poisson: Dual64::new(nu, s.poisson),
            tool_offsets: &[],
            tool_rotations: &[],
            tool_surfaces: None,
        };
        let qd: Vec<Dual64> = q.iter().map(|&x| Dual64::from(x)).collect();
        let mut fd = vec![Dual64::from(0.0); q.len()];
        Load::DirectorFilter(filt.clone())
            .force(&model, Some(&state), &qd, 1.0, &mut fd)
            .unwrap();
        let dual: Vec<f64> = fd.iter().map(|x| x.eps).collect();
        // Its value part is the analysis' force.
        let mut f64_force = vec![0.0; q.len()];
        filt.force(&model, &q, &mut f64_force).unwrap();
        let values: Vec<f64> = fd.iter().map(|x| x.re).collect();
        assert!(max_diff(&values, &f64_force) <= 1e-14 * max_abs(&f64_force));

        // Hand-derived.
        let dots: Vec<ParticleState<f64>> = parts
            .iter()
            .map(|p| {
                let v = |x: &Vector3<Dual64>| x.map(|c| c.eps);
                ParticleState {
                    u: v(&p.u),
                    d: v(&p.d),
                    d0: v(&p.d0),
                    e: [v(&p.e[0]), v(&p.e[1])],
                }
            })
            .collect();
        let kd = filt.kappa_dot([e, nu, t], [s.young, s.poisson, s.thickness]);
        let mut hand = vec![0.0; q.len()];
        filt.add_design_derivative(&model, &dots, kd, &q, &mut hand)
            .unwrap();

        let scale = max_abs(&dual);
        assert!(scale > 0.0, "{name}");
        let e_dual = max_diff(&hand, &dual) / scale;

        // Central differences of the rebuilt filter's force.
        let central = |h: f64| -> f64 {
            let fp = rebuilt_force(&model, (filt.epsilon(), scale_of_support), s, h, &q);
            let fm = rebuilt_force(&model, (filt.epsilon(), scale_of_support), s, -h, &q);
            let c: Vec<f64> = fp
                .iter()
                .zip(&fm)
                .map(|(a, b)| (a - b) / (2.0 * h))
                .collect();
            max_diff(&c, &hand) / scale
        };
        let (e1, e2) = (central(1e-3), central(5e-4));
        println!(
            "filter support {support}, {name:>10}: max|ḟ| {scale:.3e}, hand − dual \
             {e_dual:.2e}, hand − central {e1:.2e} (h 1e-3), {e2:.2e} (h 5e-4)"
        );
        // Two evaluations of the same sums, terms of the size of the largest entry:
        // round-off, 1e-13 of the largest entry.
        assert!(e_dual <= 1e-13, "{name}: hand vs dual {e_dual:e}");
        // Central differences: truncation O(h²) for the rotations (second derivatives of
        // Rodrigues' update of order 1 per rad², h = 1e-3: ~1e-7), exact to round-off for
        // κ's E and ν and t³'s quadratic share; 1e-5 leaves a margin of 100.
        assert!(e1 <= 1e-5 && e2 <= 1e-5, "{name}: central {e1:e}, {e2:e}");
        // Where truncation dominates, it falls as h² (ratio 4 when h halves).
        if e1 > 1e-10 {
            let r = e1 / e2;
            assert!((3.5..4.5).contains(&r), "{name}: ratio {r}");
        }
    }
}

#[test]
fn load_stiffness_is_the_jacobian_of_the_force() {
    for support in FILTER_SUPPORTS {
        load_stiffness_with_filter_support(support);
    }
}

fn load_stiffness_with_filter_support(support: f64) {
    let p = problem(&case_text(9, support));
    let filt = filter(&p);
    let mut model = p.model.clone();
    let n = model.n_particles();
    let mut rng = Lcg(5);
    for st in &mut model.particles {
        let a = [0.2 * rng.next(), 0.2 * rng.next()];
        *st = commit_particle(st, &[0.0, 0.0, 0.0, a[0], a[1]]);
    }
    let q: Vec<f64> = (0..DOFS_PER_PARTICLE * n)
        .map(|_| 0.02 * rng.next())
        .collect();
    let mut trip = Vec::new();
    filt.add_stiffness(&model, &mut trip).unwrap();
    let mut worst = 0.0f64;
    let mut scale = 0.0f64;
    for col in [
        3,
        4,
        DOFS_PER_PARTICLE * (n / 2) + 3,
        DOFS_PER_PARTICLE * (n - 1) + 4,
    ] {
        let qd: Vec<Dual64> = q
            .iter()
            .enumerate()
            .map(|(i, &x)| Dual64::new(x, if i == col { 1.0 } else { 0.0 }))
            .collect();
        let mut f = vec![Dual64::from(0.0); q.len()];
        filt.force(&model, &qd, &mut f).unwrap();
        let mut k = vec![0.0; q.len()];
        for &(r, c, v) in &trip {
            if c == col {
                k[r] += v;
            }
        }
        let jac: Vec<f64> = f.iter().map(|x| x.eps).collect();
        worst = worst.max(max_diff(&jac, &k));
        scale = scale.max(max_abs(&jac));
    }
    println!(
        "filter support {support}: stiffness against the dual Jacobian: {:.2e} of {scale:.3e}",
        worst / scale
    );
    assert!(scale > 0.0);
    // Linear in q: the same products in another order, round-off.
    assert!(worst <= 1e-13 * scale);
}

/// The reduced plastic hemisphere (9 × 9, 14 steps to P = 35, first yield in step 11) with
/// `director_stabilisation = 0.1` on the filter of the smallest support (2 spacings: its rows
/// reach into the images across both symmetry planes, and the finite differences' re-runs
/// rebuild it from the case key) and the design variables R, φ1 (shape), t, σ0 of the case
/// plus E and ν (the filter's `κ`): three ways through `shelldsa dsa`. The model-level tests
/// above check both supports; the derivative code does not depend on the rows.
#[test]
fn stabilised_hemisphere_three_ways_through_the_cli() {
    let extra = "[[design]]\nname = \"E\"\nkind = \"material.young\"\nfd_steps = [1e-3, 1e-4]\n\n\
                 [[design]]\nname = \"nu\"\nkind = \"material.poisson\"\nfd_steps = [1e-3, 1e-4]\n\n[dsa]\n";
    let text = case_text(9, 2.0).replacen("[dsa]\n", extra, 1);
    let dir = root().join("target/dsa-stabilisation-tests");
    std::fs::create_dir_all(&dir).unwrap();
    let case = dir.join("case.toml");
    std::fs::write(&case, &text).unwrap();
    let out = dir.join("out");
    let t0 = std::time::Instant::now();
    let code = cli(&[
        "dsa",
        case.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--terms",
        "12",
    ]);
    println!("dsa run {:.1} s", t0.elapsed().as_secs_f64());
    assert_eq!(code, 0);
    let a: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("sensitivity.json")).unwrap())
            .unwrap();
    assert!(a["dual_state_mismatch"].as_f64().unwrap() < 1e-12);

    // --terms 12: the filter group, continuum against the dual force of the filter alone
    // with every seed; and every other group with the filter's share taken out.
    let terms: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("terms.json")).unwrap()).unwrap();
    let bs = terms["breakdowns"].as_array().unwrap();
    assert_eq!(bs.len(), 6);
    for b in bs {
        let groups = b["groups"].as_array().unwrap();
        let scale = groups
            .iter()
            .map(|g| g["dual_max"].as_f64().unwrap())
            .fold(0.0, f64::max);
        let filter = groups.iter().find(|g| g["group"] == "filter").unwrap();
        let fmax = filter["dual_max"].as_f64().unwrap();
        println!(
            "{:>6}: filter group max|dual| {fmax:.3e} ({:.2e} of the largest group), \
             continuum − dual {:.2e} of the group",
            b["variable"],
            fmax / scale,
            filter["relative"].as_f64().unwrap()
        );
        // Every variable reaches the filter: through κ (t, E, ν) or the committed directors
        // (all of them, σ0 after first yield).
        assert!(fmax > 0.0, "{}", b["variable"]);
        // Round-off of the group's own sums: 1e-12 of its largest entry.
        assert!(filter["max_difference"].as_f64().unwrap() <= 1e-12 * fmax);
        for g in groups {
            // As tests/dsa_cli.rs: 1e-12 of the largest group entry.
            assert!(
                g["max_difference"].as_f64().unwrap() <= 1e-12 * scale,
                "{}: {g}",
                b["variable"]
            );
        }
    }

    assert_eq!(assert_three_ways(&a), 6);
}
