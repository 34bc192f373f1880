//! Cantilever under an end moment (Sze, Liu & Lo 2004, FEAD 40:1551, §3.2;
//! `../shared/reference-values.md` §2): a clamped strip L = 12, width 1, t = 0.1, E = 1.2e6,
//! ν = 0 rolls up under the end moment `M`; at `M_max = 2π EI/L` it closes into a full circle.
//! Exact (inextensible elastica, uniform curvature `M/EI`), with `θ = 2π M/M_max`:
//! tip `−u = L (1 − sin θ/θ)`, `w = L (1 − cos θ)/θ`.
//!
//! ```text
//!   clamped ┌──────────────────────┐ ↺ M (line moment on the tip edge)      ╭──╮
//!           └──────────────────────┘                               →       │  │ (M = M_max)
//!                                                                          ╰══╯
//! ```
//! The moment is `shell::load::Moment` on the tip edge u = 1 (about −y, per unit width), acting
//! through the rotation of the interpolated director; the bending stays in the x–z plane, where
//! that load is exactly conservative (docs/loads.md), and the test checks the symmetry of its
//! stiffness at the rolled-up state. The library's `ShellProblem` (tests/common: the clamp as
//! constraint rows with Lagrange multipliers, sparse pattern), solved by the Newton driver with
//! the secant predictor, the load factor `M/M_max` in three runs (0 → 0.25 → 0.5 → 1) with equal
//! steps.
//!
//! Discretisation and why: 25 × 3 particles (quadratic basis, supports of 3 spacings), one
//! background cell per particle spacing with 2 × 2 Gauss points, 2 Gauss points through the
//! thickness, 8 load steps per quarter of `M_max` (a rotation of 0.2 rad per step at the tip).
//! Measured alternatives (error of the tip displacement vector at M/M_max = 0.25, 8 steps per
//! quarter): 4 × 4 Gauss points lock (0.53 % against 0.17 %) and cost 4 times as much; 13 × 3
//! particles reach the full circle with a 0.93 % error, 49 × 3 particles with 0.25 % (with the
//! interpolated director field they stop at M/M_max = 0.95, docs/loads.md). The test and the
//! refinement study run in about 4 s together (release, 2 cores).
//!
//! Out-of-plane motion (the displacement across the width, `u_y`, and the rotation `α1` about
//! the lamina vector along the strip) is held at zero on every particle (generalised DOFs off the
//! clamped edge, interpolated values on it): a plane problem, exact
//! for the planar solution. Without it, the tangent of the 49 × 3 strip acquires a negative
//! eigenvalue in an out-of-plane mode between M/M_max = 0.75 and 0.85 (the ignored test below
//! measures it), and the symmetric path is then followed only because round-off keeps the
//! iterates symmetric. With the interpolated director field, even planar, the 49 × 3 strip's
//! tangent becomes singular near M/M_max ≈ 0.93 (2 × 2 points; ≈ 0.997 with 4 × 4) in a
//! checkerboard of the director rotations `α2`, and the driver stops there; the normalised
//! field (the default) removes it (docs/loads.md). Open: whether the out-of-plane loss of
//! stability is a property of the discrete shell (the incremental Hughes–Winget update) or of
//! the load.

mod common;

use shelldsa::meshfree::Edge;
use shelldsa::shell::load::Moment;
use shelldsa::shell::problem::ShellProblem;
use shelldsa::solver::{LoadStepping, NewtonOptions, NewtonSolver};
use std::f64::consts::PI;

const L: f64 = 12.0;
const E: f64 = 1.2e6;
const T: f64 = 0.1;

/// Exact tip `(−u, w)` at `M/M_max = ratio`.
fn exact(ratio: f64) -> (f64, f64) {
    let th = 2.0 * PI * ratio;
    (L * (1.0 - th.sin() / th), L * (1.0 - th.cos()) / th)
}

fn m_max() -> f64 {
    2.0 * PI * (E * T.powi(3) / 12.0) / L
}

/// The strip `n_u × 3` with the end moment `M_max` (load factor 1) on the tip edge.
fn problem(n_u: usize, planar: bool) -> (ShellProblem, Moment) {
    let strip = common::strip(&common::StripSpec {
        length: L,
        model: common::ModelSpec {
            thickness: T,
            young: E,
            n_u,
            n_v: 3,
            support: 3.0,
            sub: 1,
            ppc: 2,
        },
    });
    // About −y: the tip rotates from +x towards +z (w > 0). Two intervals of 4 Gauss points
    // across the width (one per particle spacing).
    let moment = Moment::on_edge(
        &strip.model,
        &common::strip_surface(L),
        Edge::UMax,
        [0.0, -m_max(), 0.0],
        2,
        4,
    )
    .unwrap();
    let planar_rows = if planar {
        [strip.restrain_component(1), strip.restrain_component(3)].concat()
    } else {
        Vec::new()
    };
    let p = strip.problem(vec![moment.clone().into()], planar_rows);
    (p, moment)
}

/// Result at one load level.
#[derive(Debug)]
struct Level {
    ratio: f64,
    u: f64,
    w: f64,
    /// `|tip − exact| / |exact|` (vectors `(−u, w)`).
    error: f64,
    iterations: Vec<usize>,
    failed: usize,
}

/// Roll the strip up to each of `levels` (ascending, from 0), `steps_per_quarter` equal steps
/// per 0.25 of `M_max`, residual tolerance 1e-10 relative to the moment's force norm.
fn roll_up(
    problem: &mut ShellProblem,
    levels: &[f64],
    steps_per_quarter: usize,
) -> Result<Vec<Level>, String> {
    let mut start = 0.0;
    let mut out = Vec::new();
    for &end in levels {
        let steps = ((end - start) / 0.25 * steps_per_quarter as f64).round();
        let h = (end - start) / steps;
        let newton = NewtonSolver {
            options: NewtonOptions {
                residual_rtol: 1e-10,
                ..Default::default()
            },
            stepping: LoadStepping {
                start,
                end,
                initial_step: h,
                max_step: h,
                min_step: 1e-4 * h,
                ..Default::default()
            },
        };
        let report = common::newton_run(problem, &newton, |_| {}).map_err(|f| f.to_string())?;
        start = end;
        let (ue, we) = exact(end);
        let tip = problem.model.displacement_at([1.0, 0.5]).unwrap();
        let (un, wn) = (-tip[0], tip[2]);
        out.push(Level {
            ratio: end,
            u: un,
            w: wn,
            error: ((un - ue).powi(2) + (wn - we).powi(2)).sqrt() / ue.hypot(we),
            iterations: report.converged_steps().map(|s| s.iterations).collect(),
            failed: report.attempts.iter().filter(|s| !s.converged).count(),
        });
    }
    Ok(out)
}

#[test]
fn cantilever_rolls_into_a_circle_under_an_end_moment() {
    let (mut p, moment) = problem(25, true);
    let levels = roll_up(&mut p, &[0.25, 0.5, 1.0], 8).expect("rolls up to the full circle");
    println!("M/M_max   −u (exact)          w (exact)          error    iterations per step");
    for l in &levels {
        let (ue, we) = exact(l.ratio);
        println!(
            "{:<8} {:>8.5} ({ue:>8.5})  {:>8.5} ({we:>8.5})  {:.3} %  {:?}",
            l.ratio,
            l.u,
            l.w,
            100.0 * l.error,
            l.iterations
        );
    }
    // Measured: 0.166 %, 0.150 %, 0.155 % (8, 8 and 16 steps of 6–8 iterations). The
    // benchmark's 1 % is the spread of converged shell theories (reference-values.md).
    for l in &levels {
        assert!(
            l.error < 0.01,
            "M/M_max = {}: error {:.3} %",
            l.ratio,
            100.0 * l.error
        );
        assert_eq!(l.failed, 0, "M/M_max = {}: a step was cut", l.ratio);
        // Quadratic convergence from the secant prediction of a 0.2 rad step: ≤ 10 updates
        // (measured 6–9); a tangent missing the load stiffness needs many more.
        assert!(l.iterations.iter().all(|&k| k <= 10), "{:?}", l.iterations);
    }
    assert!(levels[0].w > 0.0, "the moment about −y lifts the tip");
    // The rolled-up state is planar, where the moment is conservative: its stiffness is
    // symmetric to round-off (a Hessian).
    let model = &p.model;
    let mut trip = Vec::new();
    moment
        .add_stiffness(model, &vec![0.0; model.n_dofs()], 1.0, &mut trip)
        .unwrap();
    let n = model.n_dofs();
    let mut k = nalgebra::DMatrix::<f64>::zeros(n, n);
    for (i, j, v) in trip {
        k[(i, j)] += v;
    }
    let skew = (&k - k.transpose()).norm() / k.norm();
    println!("moment stiffness at the full circle: |K − Kᵀ|/|K| = {skew:.2e}");
    assert!(skew < 1e-13, "{skew:e}");
}

#[test]
fn refinement_in_particles_and_load_steps() {
    // Up to M/M_max = 0.5 (half a circle), where every discretisation here converges.
    let mut table = Vec::new();
    for (n_u, steps) in [(13, 8), (25, 4), (25, 8), (25, 16), (49, 8)] {
        let (mut p, _) = problem(n_u, true);
        let levels = roll_up(&mut p, &[0.25, 0.5], steps).expect("rolls up to a half circle");
        table.push((n_u, steps, levels));
    }
    println!("particles  steps/quarter  error at 0.25   error at 0.5   iterations (0.25, 0.5)");
    for (n_u, steps, l) in &table {
        println!(
            "{n_u:>4} × 3  {steps:>8}        {:>8.3} %      {:>8.3} %    {:?} {:?}",
            100.0 * l[0].error,
            100.0 * l[1].error,
            l[0].iterations,
            l[1].iterations
        );
    }
    let err = |n_u: usize, steps: usize, k: usize| {
        table
            .iter()
            .find(|t| t.0 == n_u && t.1 == steps)
            .map(|t| t.2[k].error)
            .unwrap()
    };
    // Measured (0.25 / 0.5): 13×3: 0.503 / 0.478 %; 25×3 with 4, 8, 16 steps per quarter:
    // 0.411 / 0.357, 0.166 / 0.150, 0.041 / 0.018 %; 49×3: 0.162 / 0.172 %. At 8 steps the
    // step size dominates beyond 25 particles (the incremental update is second-order
    // accurate per step), so particles and steps are refined separately.
    for k in 0..2 {
        assert!(err(25, 16, k) < err(25, 8, k) && err(25, 8, k) < err(25, 4, k));
        assert!(err(25, 8, k) < err(13, 8, k));
        for t in &table {
            assert!(
                t.2[k].error < 0.01,
                "{} × 3, {} steps: {:?}",
                t.0,
                t.1,
                t.2[k]
            );
        }
    }
}

/// Diagnostic (about a minute): the tangent of the strip *without* the plane restriction, at
/// 49 × 3 particles, along the planar path. Its smallest eigenvalue on the constraints' null
/// space (inverse iteration on the non-symmetric `Zᵀ K Z`, `Z` an orthonormal basis of the
/// generalised DOFs that satisfy the clamp rows) is positive at M/M_max = 0.5 and negative by
/// 0.85, with a mode that is almost all out-of-plane (`u_y`, `α1`). Measured: +6.8e-3 (in-plane
/// mode) at 0.5, −5.9e-3 (u_y 92 %, α1 6 %) at 0.85.
#[test]
#[ignore]
fn unrestrained_strip_loses_out_of_plane_stability() {
    use nalgebra::{DMatrix, DVector};
    use shelldsa::solver::NonlinearProblem;
    let (mut p, _) = problem(49, false);
    let nq = p.n_generalised();
    // Z: the eigenvectors of CᵀC with a zero eigenvalue (rows of O(1) coefficients).
    let mut c = DMatrix::<f64>::zeros(p.constraints().len(), nq);
    for (r, row) in p.constraints().iter().enumerate() {
        for &(j, v) in &row.terms {
            c[(r, j)] = v;
        }
    }
    let eig = (c.transpose() * &c).symmetric_eigen();
    let null: Vec<usize> = (0..nq)
        .filter(|&i| eig.eigenvalues[i].abs() < 1e-10)
        .collect();
    assert_eq!(null.len(), nq - p.constraints().len());
    let z = DMatrix::from_fn(nq, null.len(), |i, a| eig.eigenvectors[(i, null[a])]);
    let pattern = p.pattern().clone();
    let mut values = vec![0.0; pattern.nnz()];
    let mut start = 0.0;
    let mut found = Vec::new();
    for (end, steps) in [(0.25, 8.0), (0.5, 8.0), (0.75, 8.0), (0.85, 4.0)] {
        let h = (end - start) / steps;
        let newton = NewtonSolver {
            options: NewtonOptions {
                residual_rtol: 1e-10,
                ..Default::default()
            },
            stepping: LoadStepping {
                start,
                end,
                initial_step: h,
                max_step: h,
                ..Default::default()
            },
        };
        common::newton_run(&mut p, &newton, |_| {}).unwrap();
        start = end;
        // K_int − λ ∂f_ext/∂q at the converged state: the generalised block of the tangent.
        let u = p.state().to_vec();
        p.tangent(&u, end, &mut values).unwrap();
        let k = pattern
            .to_dense(&values)
            .view((0, 0), (nq, nq))
            .into_owned();
        let kf = z.transpose() * k * &z;
        let lu = kf.lu();
        let mut x = DVector::from_fn(null.len(), |i, _| ((i * 7919) % 13) as f64 - 6.0);
        let mut rq = 0.0;
        for _ in 0..60 {
            let y = lu.solve(&x).unwrap();
            rq = x.dot(&y) / x.dot(&x);
            x = &y / y.norm();
        }
        let mode = &z * &x;
        let mut share = [0.0; 5];
        for (i, v) in mode.iter().enumerate() {
            share[i % 5] += v * v;
        }
        println!(
            "M/M_max {end}: smallest eigenvalue {:+.3e}, mode (u_x, u_y, u_z, α1, α2) {share:.3?}",
            1.0 / rq
        );
        found.push((end, 1.0 / rq, share[1] + share[3]));
    }
    assert!(found[1].1 > 0.0, "{found:?}");
    let last = found.last().unwrap();
    assert!(last.1 < 0.0 && last.2 > 0.9, "{found:?}");
}
