//! Pinched hemisphere with an 18° hole (MacNeal & Harder 1985), linear: quarter model with
//! symmetry planes by image particles.
//!
//! R = 10, t = 0.04 (R/t = 250), E = 6.825e7, ν = 0.3, latitude 0–72°; symmetry planes x = 0 and
//! y = 0; the equator and the hole edge free; one point restrained in z (the rigid mode left by
//! the planes); quarter-model loads +P x at A = (R, 0, 0), −P y at B = (0, R, 0). Reference
//! (../shared/reference-values.md §1): radial displacement at A 0.094 (MacNeal–Harder), 0.0935 for
//! converged shear-deformable elements; target 0.0935 ± 1 %.
//!
//! ```text
//!   SphereZone: u = longitude 0–90°, v = latitude 0–72°
//!   u = 0 (UMin): the meridian in y = 0, n_s = y     A = (R,0,0) at (u, v) = (0, 0)
//!   u = 1 (UMax): the meridian in x = 0, n_s = x     B = (0,R,0) at (u, v) = (1, 0)
//! ```
//! Discretisation: quadratic basis, supports 3 spacings, one background cell per particle
//! interval with 2×2 or 3×3 Gauss points, 2 Gauss points through the thickness (elastic);
//! one load step through the Newton driver with faer LU at P = 1e-6, where the response is
//! linear to ~1e-8: the geometric nonlinearity changes δ_A by −8.6 % at P = 10 (Sze et al.'s
//! first load level) and δ_A, δ_B (equal in linear theory) differed by 8e-6 at P = 1e-3, so it
//! is first order in P. Displacements are reported per unit load.

use nalgebra::Vector3;
use shelldsa::geometry::{SphereZone, Surface};
use shelldsa::material::MaterialParams;
use shelldsa::meshfree::quadrature::{gauss_legendre, gauss_lobatto, CellQuadrature};
use shelldsa::meshfree::Edge;
use shelldsa::meshfree::{regular_grid, Basis, ParamBox};
use shelldsa::shell::constraints::LinearConstraint;
use shelldsa::shell::load::PointForce;
use shelldsa::shell::model::{Discretisation, ShellModel};
use shelldsa::shell::problem::{ProblemOptions, ShellProblem, SymmetryTreatment};
use shelldsa::shell::symmetry::SymmetryPlane;
use shelldsa::solver::{
    EssentialBc, LinearSolver, LoadStepping, Method, NewtonSolver, NonlinearProblem, SolverOptions,
};
use std::time::Instant;

const P: f64 = 1e-6;
const REFERENCE: f64 = 0.0935;

/// Thickness rule: 2 Gauss points (elastic) or 5 Lobatto points (the paper's plastic runs).
#[derive(Clone, Copy)]
enum Layers {
    Gauss2,
    Lobatto5,
}

fn hemisphere(n: usize, ppc: usize, layers: Layers, treatment: SymmetryTreatment) -> ShellProblem {
    let surface = Surface::SphereZone(
        SphereZone::new(
            Vector3::zeros(),
            10.0,
            [0.0, 72f64.to_radians()],
            [0.0, 90f64.to_radians()],
        )
        .unwrap(),
    );
    let grid = regular_grid(ParamBox::unit(), n, n);
    let cq = CellQuadrature::for_particle_grid(&grid, 1, ppc).unwrap();
    let rule = match layers {
        Layers::Gauss2 => gauss_legendre(2).unwrap(),
        Layers::Lobatto5 => gauss_lobatto(5).unwrap(),
    };
    let disc = Discretisation {
        supports: grid.supports(3.0),
        particle_uv: grid.positions,
        basis: Basis::Quadratic,
        kernel: Default::default(),
        quadrature: cq.iter().map(|(p, w, _)| (p, w)).collect(),
        thickness_rule: rule
            .nodes
            .iter()
            .copied()
            .zip(rule.weights.iter().copied())
            .collect(),
        thickness: 0.04,
        symmetry: vec![
            SymmetryPlane::new(Edge::UMin, Vector3::zeros(), Vector3::y()).unwrap(),
            SymmetryPlane::new(Edge::UMax, Vector3::zeros(), Vector3::x()).unwrap(),
        ],
    };
    let material = MaterialParams::new(6.825e7, 0.3, 1e30, 0.0, 1.0).unwrap();
    let model = ShellModel::new(&surface, disc, material).unwrap();
    let loads = vec![
        PointForce {
            uv: [0.0, 0.0],
            force: [P, 0.0, 0.0],
        }
        .into(),
        PointForce {
            uv: [1.0, 0.0],
            force: [0.0, -P, 0.0],
        }
        .into(),
    ];
    // The rigid translation along z: hold u_z at the top of the meridian through A.
    let hold = LinearConstraint::displacement(&model, [0.0, 1.0], Vector3::z(), 0.0).unwrap();
    ShellProblem::with_options(
        model,
        loads,
        vec![hold],
        ProblemOptions {
            symmetry: treatment,
            ..ProblemOptions::default()
        },
    )
    .unwrap()
}

struct Solution {
    a: f64,
    b: f64,
    iterations: usize,
    seconds: f64,
    reaction_z: f64,
}

fn solve(mut problem: ShellProblem) -> Solution {
    let t0 = Instant::now();
    let pattern = problem.pattern().clone();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    let newton = NewtonSolver {
        stepping: LoadStepping {
            initial_step: 1.0,
            ..LoadStepping::default()
        },
        ..NewtonSolver::default()
    };
    let u0 = problem.state().to_vec();
    let report = newton
        .run(&mut problem, &pattern, &mut solver, &u0)
        .expect("linear step");
    let seconds = t0.elapsed().as_secs_f64();
    let a = problem.model.displacement_at([0.0, 0.0]).unwrap();
    let b = problem.model.displacement_at([1.0, 0.0]).unwrap();
    Solution {
        a: a[0] / P,
        b: -b[1] / P,
        iterations: report.converged_steps().map(|s| s.iterations).sum(),
        seconds,
        reaction_z: problem.reactions()[0] / P,
    }
}

#[test]
fn pinched_hemisphere_converges_to_the_reference() {
    let mut rows = Vec::new();
    // 25 × 25 with 3 × 3 points (−7.96 %, 16 s) is left out to keep the test short.
    for (n, ppcs) in [(9, &[2, 3][..]), (13, &[2, 3]), (17, &[2, 3]), (25, &[2])] {
        for &ppc in ppcs {
            let s = solve(hemisphere(
                n,
                ppc,
                Layers::Gauss2,
                SymmetryTreatment::Eliminate,
            ));
            rows.push((n, ppc, s));
        }
    }
    println!("pinched hemisphere, reference {REFERENCE} (radial displacement per unit load)");
    println!("particles  Gauss/cell  δ_A        error     δ_B        iterations  time");
    for (n, ppc, s) in &rows {
        println!(
            "{n:>3} × {n:<3}  {ppc} × {ppc}       {:.6}  {:+.2} %  {:.6}   {}           {:.2} s",
            s.a,
            100.0 * (s.a / REFERENCE - 1.0),
            s.b,
            s.iterations,
            s.seconds
        );
    }
    for (_, _, s) in &rows {
        // In linear theory A and B move equally: the mirror x ↔ y maps the quarter, its
        // particle grid and its quadrature onto themselves and the load pattern onto its
        // negative. The geometric nonlinearity at P = 1e-6 is ~1e-8 relative; 1e-7 leaves room
        // for the driver's stopping tolerance.
        assert!((s.a / s.b - 1.0).abs() < 1e-7, "δ_A {} vs δ_B {}", s.a, s.b);
        // The loads have no z resultant, so the z restraint carries nothing: its reaction
        // (per unit load) is the driver's residual tolerance, 1e-8 of the load, at most.
        assert!(s.reaction_z.abs() < 1e-7, "z reaction {}", s.reaction_z);
    }
    // Convergence under refinement with 2×2 points per cell, and the finest grid within 1 %
    // of the reference (the issue's target).
    let two: Vec<f64> = rows
        .iter()
        .filter(|r| r.1 == 2)
        .map(|r| (r.2.a / REFERENCE - 1.0).abs())
        .collect();
    for w in two.windows(2) {
        assert!(w[1] < w[0], "no convergence with 2×2 points: {two:?}");
    }
    assert!(*two.last().unwrap() < 0.01, "25 × 25, 2×2: {two:?}");
}

/// Time per Newton iteration on the paper's discretisation (17 × 17 particles, 3 × 3 Gauss points
/// per cell, 5 Lobatto layers): assembly of residual and tangent, elimination, factorisation,
/// solve; and the symmetry conditions eliminated versus as multiplier rows.
#[test]
fn newton_iteration_cost_on_the_paper_hemisphere() {
    let mut results = Vec::new();
    for treatment in [SymmetryTreatment::Eliminate, SymmetryTreatment::Multipliers] {
        let t = Instant::now();
        let mut problem = hemisphere(17, 3, Layers::Lobatto5, treatment);
        let setup = t.elapsed().as_secs_f64();
        let pattern = problem.pattern().clone();
        let n = problem.n_dofs();
        let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
        let u = problem.state().to_vec();
        let mut r = vec![0.0; n];
        let mut values = vec![0.0; pattern.nnz()];
        let bc = EssentialBc::new(n, &problem.essential(1.0)).unwrap();
        let mut times = [f64::INFINITY; 3];
        let mut du = vec![0.0; n];
        for _ in 0..3 {
            let t = Instant::now();
            problem
                .residual_and_tangent(&u, 1.0, &mut r, &mut values)
                .unwrap();
            times[0] = times[0].min(t.elapsed().as_secs_f64());
            du = r.iter().map(|v| -v).collect();
            bc.apply(&pattern, &mut values, &mut du).unwrap();
            let t = Instant::now();
            solver.factorize(&values).unwrap();
            times[1] = times[1].min(t.elapsed().as_secs_f64());
            let t = Instant::now();
            solver.solve_in_place(&mut du).unwrap();
            times[2] = times[2].min(t.elapsed().as_secs_f64());
        }
        let nq = problem.n_generalised();
        // The model's own assembly of all point contributions (local matrices kept), for
        // comparison with the problem's assembly into the pattern.
        let t = Instant::now();
        let c = problem.model.contributions(&vec![0.0; nq], true).unwrap();
        let t_model = t.elapsed().as_secs_f64();
        drop(c);
        println!(
            "{treatment:?}: {} unknowns ({} generalised, {} eliminated, {} multipliers), nnz {}, \
             setup {setup:.3} s; per iteration: residual + tangent {:.3} s (model contributions \
             alone {t_model:.3} s), factorise {:.3} s, solve {:.4} s",
            n,
            nq,
            problem.fixed_dofs().len(),
            n - nq,
            pattern.nnz(),
            times[0],
            times[1],
            times[2]
        );
        // The linear displacement at A from this one solve (du is the correction from zero).
        let ua = problem
            .model
            .interpolate_translation([0.0, 0.0], &du[..nq])
            .unwrap();
        results.push(ua[0] / P);
    }
    println!(
        "δ_A: eliminated {:.10}, multipliers {:.10}",
        results[0], results[1]
    );
    // The same linear system, reduced two ways: the solutions agree to the factorisation's
    // round-off (condition of the shell tangent at R/t = 250 ~1e10: 1e-6 relative).
    assert!((results[0] / results[1] - 1.0).abs() < 1e-6);
    // The 3 × 3 rule locks at 17 × 17 (−28 % with 2 Gauss layers in the test above): the value
    // must lie in that range, not at the reference.
    assert!(
        results[0] > 0.6 * REFERENCE && results[0] < 0.8 * REFERENCE,
        "δ_A = {}",
        results[0]
    );
}

/// Displacement control: the same quarter model without loads, with the radial displacements
/// of the force-controlled solution prescribed at A and B as constraint rows (values ramping
/// with the load factor). The reactions of those rows (forces of the supports on the shell)
/// must be the loads they replace, +P along x at A and −P along y at B.
#[test]
fn displacement_control_reproduces_the_forces_as_reactions() {
    let force = hemisphere(13, 2, Layers::Gauss2, SymmetryTreatment::Eliminate);
    let model0 = force.model.clone();
    let s = solve(force);
    let mut problem = {
        let z = LinearConstraint::displacement(&model0, [0.0, 1.0], Vector3::z(), 0.0).unwrap();
        let a = LinearConstraint::displacement(&model0, [0.0, 0.0], Vector3::x(), s.a * P).unwrap();
        let b =
            LinearConstraint::displacement(&model0, [1.0, 0.0], Vector3::y(), -s.b * P).unwrap();
        ShellProblem::new(model0, Vec::new(), vec![z, a, b]).unwrap()
    };
    let pattern = problem.pattern().clone();
    let mut solver = LinearSolver::new(&pattern, Method::Lu, SolverOptions::default()).unwrap();
    let newton = NewtonSolver {
        stepping: LoadStepping {
            initial_step: 1.0,
            ..LoadStepping::default()
        },
        ..NewtonSolver::default()
    };
    let u0 = problem.state().to_vec();
    newton
        .run(&mut problem, &pattern, &mut solver, &u0)
        .expect("prescribed step");
    let r = problem.reactions();
    println!(
        "reactions per unit load: z {:.3e}, A {:.9}, B {:.9}",
        r[0] / P,
        r[1] / P,
        r[2] / P
    );
    // The prescribed values carry 7 digits of the force-controlled solution's stopping
    // tolerance; 1e-6 relative.
    assert!((r[1] / P - 1.0).abs() < 1e-6, "A: {}", r[1] / P);
    assert!((r[2] / P + 1.0).abs() < 1e-6, "B: {}", r[2] / P);
    assert!(r[0].abs() < 1e-6 * P);
}
