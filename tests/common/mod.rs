//! Shared set-up of the shell reference tests: elastic test models, the clamped strip of the
//! cantilever tests, the Scordelis–Lo roof, and the solver helpers that run them.
//!
//! The strip is a flat `L × 1` shell, thickness `t`, E, ν = 0, clamped on u = 0 by the library's
//! edge constraints ([`edge_constraints`] with [`EdgeCondition::Clamped`]: every RK-interpolated
//! displacement component and rotation parameter held at the particles on the edge, exact on a
//! flat strip, whose particles share their lamina vectors), and loaded by a transverse force
//! spread uniformly over the tip edge u = 1 (point forces at the Gauss points of the edge).
//! [`ShellProblem`] with the Newton driver runs it as the CLI does ([`newton_run`]); the linear
//! response is one solve of the problem's tangent at the unloaded state ([`linear_solution`]).
#![allow(dead_code)] // each test file uses a subset

use nalgebra::{DMatrix, DVector, Vector3};
use shelldsa::geometry::{Rectangle, Surface};
use shelldsa::material::MaterialParams;
use shelldsa::meshfree::quadrature::{gauss_legendre, CellQuadrature};
use shelldsa::meshfree::{regular_grid, Basis, Edge, ParamBox, ShapeFunctions, ShapeValues};
use shelldsa::shell::constraints::{edge_constraints, EdgeCondition, LinearConstraint, RowKind};
use shelldsa::shell::load::{Gravity, Load, PointForce};
use shelldsa::shell::model::{Discretisation, ShellModel};
use shelldsa::shell::problem::ShellProblem;
use shelldsa::shell::symmetry::on_edge;
use shelldsa::solver::{
    EssentialBc, LinearSolver, Method, NewtonFailure, NewtonReport, NewtonSolver, NonlinearProblem,
    SolverOptions, StepRecord,
};

/// The strip: model (unloaded), clamp rows and the number of particles across the width.
pub struct Strip {
    pub model: ShellModel,
    pub clamp: Vec<LinearConstraint>,
    pub n_v: usize,
}

/// Discretisation of an elastic test shell on the unit parameter square: `n_u × n_v` particles
/// (quadratic basis, support `support` spacings), cells aligned with the particle grid subdivided
/// `sub` times with `ppc × ppc` Gauss points, 2 Gauss points through the thickness, ν = 0 and a
/// yield stress of 1e30 (elastic).
#[derive(Clone, Copy)]
pub struct ModelSpec {
    pub thickness: f64,
    pub young: f64,
    pub n_u: usize,
    pub n_v: usize,
    pub support: f64,
    pub sub: usize,
    pub ppc: usize,
}

/// The elastic shell model of `spec` on `surface`.
pub fn elastic_model(surface: &Surface<f64>, spec: &ModelSpec) -> ShellModel {
    let grid = regular_grid(ParamBox::unit(), spec.n_u, spec.n_v);
    let cq = CellQuadrature::for_particle_grid(&grid, spec.sub, spec.ppc).unwrap();
    let g2 = gauss_legendre(2).unwrap();
    let disc = Discretisation {
        supports: grid.supports(spec.support),
        particle_uv: grid.positions,
        basis: Basis::Quadratic,
        kernel: Default::default(),
        quadrature: cq.iter().map(|(p, w, _)| (p, w)).collect(),
        thickness_rule: g2
            .nodes
            .iter()
            .copied()
            .zip(g2.weights.iter().copied())
            .collect(),
        thickness: spec.thickness,
        symmetry: Vec::new(),
    };
    let material = MaterialParams::new(spec.young, 0.0, 1e30, 0.0, 1.0).unwrap();
    ShellModel::new(surface, disc, material).unwrap()
}

/// Indices (ascending, each once) of the particles at `positions` on any of `edges` of the unit
/// parameter square.
pub fn particles_on_edges(positions: &[[f64; 2]], edges: &[Edge]) -> Vec<usize> {
    let unit = [[0.0, 1.0], [0.0, 1.0]];
    (0..positions.len())
        .filter(|&i| edges.iter().any(|&e| on_edge(positions[i], e, unit)))
        .collect()
}

/// One row `Σ_k c_k d_k = g` of a dense constrained solve.
pub type Row = (Vec<(usize, f64)>, f64);

/// The rows fixing the RK-interpolated value of component `c` (of `comps` per particle) at each
/// of `points` to the matching entry of `values`: `Σ_I Ψ_I(ξ_J) d_{comps·I + c} = g_J`.
pub fn nodal_rows(
    shape: &ShapeFunctions,
    points: &[[f64; 2]],
    comps: usize,
    c: usize,
    values: &[f64],
) -> Vec<Row> {
    let mut sv = ShapeValues::new();
    points
        .iter()
        .zip(values)
        .map(|(&x, &g)| {
            shape.evaluate(x, &mut sv).unwrap();
            (
                sv.iter().map(|(i, psi, _)| (comps * i + c, psi)).collect(),
                g,
            )
        })
        .collect()
}

/// Solve `K d = f` subject to the rows `C d = g` by Lagrange multipliers: one dense LU of
/// `[K sCᵀ; sC 0]`, the rows scaled by `s = max_i |K_ii|` so that both blocks are of the same
/// size for the pivoting (the solution `d` does not depend on `s`). Returns `d`.
pub fn solve_constrained(k: &DMatrix<f64>, f: &[f64], rows: &[Row]) -> Vec<f64> {
    let n = k.nrows();
    let m = rows.len();
    let s = (0..n).fold(0.0_f64, |a, i| a.max(k[(i, i)].abs()));
    let mut a = DMatrix::zeros(n + m, n + m);
    a.view_mut((0, 0), (n, n)).copy_from(k);
    let mut b = DVector::zeros(n + m);
    b.rows_mut(0, n).copy_from_slice(f);
    for (r, (terms, g)) in rows.iter().enumerate() {
        for &(j, c) in terms {
            a[(n + r, j)] += s * c;
            a[(j, n + r)] += s * c;
        }
        b[n + r] = s * g;
    }
    let x = a.lu().solve(&b).expect("regular bordered system");
    x.as_slice()[..n].to_vec()
}

/// Value of component `c` of the RK approximation of the generalised DOFs `q` (5 per particle)
/// at `uv`.
pub fn field(model: &ShellModel, q: &[f64], c: usize, uv: [f64; 2]) -> f64 {
    let mut sv = ShapeValues::new();
    model.shape_functions.evaluate(uv, &mut sv).unwrap();
    sv.iter().map(|(i, psi, _)| psi * q[5 * i + c]).sum()
}

/// The linear response of `problem` at load factor 1 from its committed state: one solve of the
/// problem's tangent (constraint rows with their multipliers, essential conditions eliminated),
/// `K Δu = −r(u, 1)`. Returns the generalised DOFs `u + Δu` (without the multipliers).
pub fn linear_solution(problem: &mut ShellProblem) -> Vec<f64> {
    let n = problem.n_dofs();
    let pattern = problem.pattern().clone();
    let u = problem.state().to_vec();
    let mut r = vec![0.0; n];
    let mut values = vec![0.0; pattern.nnz()];
    problem
        .residual_and_tangent(&u, 1.0, &mut r, &mut values)
        .unwrap();
    let essential = problem.essential(1.0);
    let bc = EssentialBc::new(n, &essential).unwrap();
    let increments: Vec<f64> = bc
        .dofs()
        .iter()
        .zip(bc.values())
        .map(|(&d, &g)| g - u[d])
        .collect();
    let mut rhs: Vec<f64> = r.iter().map(|v| -v).collect();
    bc.apply_with(&pattern, &mut values, &mut rhs, &increments)
        .unwrap();
    let mut solver =
        LinearSolver::new(&pattern, Method::auto(&pattern), SolverOptions::default()).unwrap();
    solver.factorize(&values).unwrap();
    solver.solve_in_place(&mut rhs).unwrap();
    let nq = problem.n_generalised();
    (0..nq).map(|i| u[i] + rhs[i]).collect()
}

/// Run `newton` on `problem` from its committed state with the problem's sparse pattern and the
/// linear solver the CLI chooses for it; `progress` sees every attempted step.
pub fn newton_run(
    problem: &mut ShellProblem,
    newton: &NewtonSolver,
    progress: impl FnMut(&StepRecord),
) -> Result<NewtonReport, Box<NewtonFailure>> {
    let pattern = problem.pattern().clone();
    let mut solver =
        LinearSolver::new(&pattern, Method::auto(&pattern), SolverOptions::default()).unwrap();
    let u0 = problem.state().to_vec();
    newton.run_with_progress(problem, &pattern, &mut solver, &u0, progress)
}

/// Strip of length `length` and width 1 with the discretisation `model`.
#[derive(Clone, Copy)]
pub struct StripSpec {
    pub length: f64,
    pub model: ModelSpec,
}

/// The flat strip's surface.
pub fn strip_surface(length: f64) -> Surface<f64> {
    Surface::Rectangle(
        Rectangle::new(
            Vector3::zeros(),
            Vector3::new(length, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
        )
        .unwrap(),
    )
}

/// Build the strip.
pub fn strip(spec: &StripSpec) -> Strip {
    let model = elastic_model(&strip_surface(spec.length), &spec.model);
    let clamp = edge_constraints(&model, Edge::UMin, &EdgeCondition::Clamped).unwrap();
    Strip {
        model,
        clamp,
        n_v: spec.model.n_v,
    }
}

impl Strip {
    /// The tip load of total force `total` (global axes), uniform over the tip edge u = 1:
    /// `f_I = ∫ Ψ_I(1, v) dv total`, as point forces at 6 Gauss points per particle interval.
    pub fn tip_load(&self, total: [f64; 3]) -> Vec<Load> {
        let (gn, gw) = gauss_legendre(6).unwrap().mapped(0.0, 1.0);
        let cells = self.n_v - 1;
        let mut loads: Vec<Load> = Vec::new();
        for cell in 0..cells {
            let (a, b) = (cell as f64 / cells as f64, (cell + 1) as f64 / cells as f64);
            for (&x, &w) in gn.iter().zip(&gw) {
                loads.push(
                    PointForce {
                        uv: [1.0, a + (b - a) * x],
                        force: total.map(|f| f * w * (b - a)),
                    }
                    .into(),
                );
            }
        }
        loads
    }

    /// The clamped strip under `loads` with the further constraint rows `extra`.
    pub fn problem(&self, loads: Vec<Load>, extra: Vec<LinearConstraint>) -> ShellProblem {
        let mut rows = self.clamp.clone();
        rows.extend(extra);
        ShellProblem::new(self.model.clone(), loads, rows).unwrap()
    }

    /// Rows holding generalised component `c` (a displacement or rotation index) of every
    /// particle off the clamped edge at zero (e.g. the out-of-plane displacement and rotation of
    /// a plane problem; the clamp holds the interpolated values on the edge already).
    pub fn restrain_component(&self, c: usize) -> Vec<LinearConstraint> {
        let clamped = particles_on_edges(&self.model.particle_uv, &[Edge::UMin]);
        let kind = if c < 3 {
            RowKind::Displacement
        } else {
            RowKind::Rotation
        };
        (0..self.model.n_particles())
            .filter(|i| !clamped.contains(i))
            .map(|i| LinearConstraint::generalised(5 * i + c, 0.0, kind))
            .collect()
    }
}

/// Scordelis–Lo roof, linear (reference-values §2: R = 25, L = 50, half-angle 40°, t = 0.25,
/// E = 4.32e8, ν = 0, self-weight 90 per unit area; rigid diaphragms at the curved ends, the
/// in-plane displacements u_y = u_z held at their particles, and the axial displacement at the
/// middle particle of the first end): vertical deflection (downward positive) at the middle of
/// the free edge θ = +40°, with `n × n` particles, supports of `support` spacings, `sub` cells
/// per spacing of `ppc × ppc` Gauss points and VCI of `vci`. The library's problem: diaphragm
/// edge constraints, [`Gravity`], one linear solve ([`linear_solution`]).
pub fn scordelis_lo_deflection(
    n: usize,
    support: f64,
    sub: usize,
    ppc: usize,
    vci: shelldsa::meshfree::vci::VciOrder,
) -> f64 {
    use shelldsa::geometry::CylinderSector;
    let surface = Surface::CylinderSector(
        CylinderSector::new(
            Vector3::zeros(),
            Vector3::x(),
            Vector3::z(),
            25.0,
            [(-40f64).to_radians(), 40f64.to_radians()],
            [0.0, 50.0],
        )
        .unwrap(),
    );
    let spec = ModelSpec {
        thickness: 0.25,
        young: 4.32e8,
        n_u: n,
        n_v: n,
        support,
        sub,
        ppc,
    };
    let mut model = elastic_model(&surface, &spec);
    if vci != shelldsa::meshfree::vci::VciOrder::Off {
        let rule = shelldsa::shell::integration::boundary_rule(&model, ParamBox::unit()).unwrap();
        shelldsa::shell::integration::apply_vci(&mut model, vci, &rule).unwrap();
    }
    // Diaphragms at v = 0 and v = 1 (planes normal to the axis x); one axial displacement.
    let diaphragm = EdgeCondition::Diaphragm {
        normal: Vector3::x(),
    };
    let mut rows = edge_constraints(&model, Edge::VMin, &diaphragm).unwrap();
    rows.extend(edge_constraints(&model, Edge::VMax, &diaphragm).unwrap());
    let first_end = particles_on_edges(&model.particle_uv, &[Edge::VMin]);
    let mid = model.particle_uv[first_end[first_end.len() / 2]];
    rows.push(LinearConstraint::displacement(&model, mid, Vector3::x(), 0.0).unwrap());
    let weight = Load::Gravity(Gravity::new([0.0, 0.0, -90.0]).unwrap());
    let mut problem = ShellProblem::new(model, vec![weight], rows).unwrap();
    let q = linear_solution(&mut problem);
    -field(&problem.model, &q, 2, [1.0, 0.5])
}
