//! A clamped cantilever strip under a tip shear force, linear response (one solve of the shell
//! problem's tangent at the unloaded state).
//!
//! Reference: Timoshenko beam theory, δ = PL³/(3EI) + PL/(k G A), exact for a strip with ν = 0
//! (no anticlastic curvature). Data of Sze, Liu & Lo (2004) §3.2's cantilever: L = 12, b = 1,
//! t = 0.1, E = 1.2e6, ν = 0; P = 1, k = 5/6: δ = 5.76 + 2.4e-4 = 5.76024.
//!
//! ```text
//!   clamped  ┌──────────────────────────────┐  ↑ P (at u = 1, spread over the width)
//!   u = 0    └──────────────────────────────┘
//! ```
//! The library's [`ShellProblem`] (tests/common): the clamp as exact linear constraints with
//! Lagrange multipliers, every RK-interpolated displacement component and rotation parameter of
//! the particles on u = 0 held (on a flat strip every particle has the same lamina vectors, so the
//! rotation conditions are exact, docs/shell-formulation.md §6.2); the tip load as point forces
//! at the Gauss points of the tip edge; the tangent assembled into the problem's sparse pattern.

mod common;

use shelldsa::shell::problem::ShellProblem;

const L: f64 = 12.0;
const E: f64 = 1.2e6;

/// Tip deflection for `n_u × n_v` particles, `sub` cell subdivisions, `ppc` Gauss points per
/// cell direction: one linear solve `K q = f` from the unloaded state.
fn tip_deflection(n_u: usize, n_v: usize, support: f64, sub: usize, ppc: usize) -> f64 {
    let s = common::strip(&common::StripSpec {
        length: L,
        model: common::ModelSpec {
            thickness: 0.1,
            young: E,
            n_u,
            n_v,
            support,
            sub,
            ppc,
        },
    });
    let mut problem = s.problem(s.tip_load([0.0, 0.0, 1.0]), Vec::new());
    let q = common::linear_solution(&mut problem);
    common::field(&problem.model, &q, 2, [1.0, 0.5])
}

#[test]
fn cantilever_tip_shear_matches_timoshenko_beam() {
    let i = 1.0 * 0.1f64.powi(3) / 12.0;
    let g = E / 2.0;
    let exact = L.powi(3) / (3.0 * E * i) + L / (5.0 / 6.0 * g * 0.1);
    let mut rows = Vec::new();
    for n_u in [13, 25, 49] {
        let d = tip_deflection(n_u, 3, 3.0, 2, 4);
        rows.push((n_u, d, d / exact - 1.0));
    }
    println!("Timoshenko δ = {exact:.6}");
    for (n_u, d, e) in &rows {
        println!(
            "{n_u:>3} × 3 particles: δ = {d:.6}  error {:+.3} %",
            100.0 * e
        );
    }
    // Measured: −1.201 %, −0.094 %, −0.006 %. Each doubling of the particles must cut the error
    // by at least 4 (the O(h²) of a quadratic basis; observed 12.8 and 15.7, so no shear
    // locking at L/t = 120), and the finest grid must be within 0.1 % of beam theory.
    for w in rows.windows(2) {
        assert!(
            w[1].2.abs() < w[0].2.abs() / 4.0,
            "convergence too slow: {rows:?}"
        );
    }
    let last = rows.last().unwrap().2;
    assert!(
        last.abs() < 1e-3,
        "finest grid off by {:.3} %",
        100.0 * last
    );
}

/// The Newton driver on the same problem, as the CLI runs it: at a tip load of 1e-4 the
/// response is linear to (δ/L)² ≈ 2e-9, so one load step must reproduce the linear solve of
/// `tip_deflection` (25 × 3 particles) to 1e-7 relative.
#[test]
fn newton_driver_reproduces_the_linear_solution() {
    use shelldsa::solver::{LoadStepping, NewtonOptions, NewtonSolver};

    let linear = tip_deflection(25, 3, 3.0, 2, 4);
    let p = 1e-4;
    let s = common::strip(&common::StripSpec {
        length: L,
        model: common::ModelSpec {
            thickness: 0.1,
            young: E,
            n_u: 25,
            n_v: 3,
            support: 3.0,
            sub: 2,
            ppc: 4,
        },
    });
    assert_eq!(
        s.clamp.len(),
        3 * 5,
        "3 particles on the clamped edge, 5 rows each"
    );
    let mut problem: ShellProblem = s.problem(s.tip_load([0.0, 0.0, p]), Vec::new());
    let newton = NewtonSolver {
        options: NewtonOptions {
            residual_rtol: 1e-10,
            ..NewtonOptions::default()
        },
        stepping: LoadStepping {
            initial_step: 1.0,
            ..LoadStepping::default()
        },
    };
    let report = common::newton_run(&mut problem, &newton, |r| {
        println!("residual norms {:?}", r.residual_norms);
    })
    .expect("one linear step");
    let its: Vec<usize> = report.converged_steps().map(|r| r.iterations).collect();
    let w = problem.model.displacement_at([1.0, 0.5]).unwrap()[2] / p;
    println!("Newton driver: iterations {its:?}, δ/P = {w:.8} (linear {linear:.8})");
    assert_eq!(its.len(), 1, "a linear response converges in one load step");
    assert!(
        (w / linear - 1.0).abs() < 1e-7,
        "Newton {w} vs linear {linear}"
    );
    // Force balance: the internal force of any state sums to zero over the particles (RK
    // functions reproduce constants), so the z-reactions of the clamp (each row's coefficients
    // Ψ_I(ξ_J) sum to 1) must balance the tip load P: Σ R_z = −P, up to the converged residual
    // (rtol 1e-10 of the load); 1e-8 relative leaves round-off room.
    let reactions = problem.reactions();
    let rz: f64 = problem
        .constraints()
        .iter()
        .zip(&reactions)
        .filter(|(c, _)| c.label.ends_with("along (0, 0, 1)"))
        .map(|(_, r)| r)
        .sum();
    println!("clamp reactions: Σ R_z = {rz:.6e} (tip load {p:e})");
    assert!((rz + p).abs() < 1e-8 * p, "Σ R_z = {rz}, expected −{p}");
}
