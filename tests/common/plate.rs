//! The yielding clamped plate of the design-sensitivity tests (`tests/dsa_dual.rs`,
//! `tests/dsa_continuum.rs`): a flat 1 × 1 plate, t = 0.05, clamped on its four edges, 7 × 7
//! particles (quadratic basis, support 3 spacings), 2 × 2 Gauss points per cell, 5 Lobatto
//! points through the thickness, E = 1000, ν = 0.3, σ0 = 1, H = 100, β = 0.5, follower
//! pressure p = 0.02 in 5 equal steps (first yield in step 4; `tests/dsa_dual.rs` header).
#![allow(dead_code)] // each test file uses a subset

use nalgebra::Vector3;
use shelldsa::geometry::{Rectangle, Surface};
use shelldsa::material::MaterialParams;
use shelldsa::meshfree::quadrature::{gauss_lobatto, CellQuadrature};
use shelldsa::meshfree::{regular_grid, Basis, ParamBox};
use shelldsa::sensitivity::dual::SensitivityError;
use shelldsa::sensitivity::fd::Analysis;
use shelldsa::sensitivity::{Design, DesignVariable, MaterialParameter, Monitor};
use shelldsa::shell::constraints::LinearConstraint;
use shelldsa::shell::load::Pressure;
use shelldsa::shell::model::{Discretisation, ShellModel};
use shelldsa::shell::problem::ShellProblem;
use shelldsa::solver::{LoadStepping, NewtonOptions, NewtonSolver, Predictor};

pub type V3 = Vector3<f64>;

pub const PRESSURE: f64 = 0.02;
pub const STEPS: usize = 5;

pub fn nominal_design() -> Design {
    Design {
        thickness: 0.05,
        material: MaterialParams::new(1000.0, 0.3, 1.0, 100.0, 0.5).unwrap(),
        surface: None,
        tool_offsets: Default::default(),
    }
}

/// Tolerances at the round-off floor (the driver accepts there: `Acceptance::RoundoffFloor`),
/// so that the re-runs' responses carry no convergence error at the size of a finite
/// difference; equal steps landing exactly on every level (the re-runs take the same steps).
pub fn driver(steps: usize) -> NewtonSolver {
    let dl = 1.0 / steps as f64;
    NewtonSolver {
        options: NewtonOptions {
            residual_rtol: 1e-13,
            energy_rtol: 1e-26,
            ..NewtonOptions::default()
        },
        stepping: LoadStepping {
            start: 0.0,
            end: 1.0,
            initial_step: dl,
            min_step: dl,
            max_step: dl,
            grow_factor: 1.0,
            predictor: Predictor::Zero,
            stops: (1..=steps).map(|k| k as f64 * dl).collect(),
            ..LoadStepping::default()
        },
    }
}

pub struct Plate;

impl Plate {
    pub fn model(design: &Design) -> ShellModel {
        let grid = regular_grid(ParamBox::unit(), 7, 7);
        let cq = CellQuadrature::for_particle_grid(&grid, 1, 2).unwrap();
        let lob = gauss_lobatto(5).unwrap();
        let disc = Discretisation {
            supports: grid.supports(3.0),
            particle_uv: grid.positions,
            basis: Basis::Quadratic,
            kernel: Default::default(),
            quadrature: cq.iter().map(|(p, w, _)| (p, w)).collect(),
            thickness_rule: lob.nodes.iter().copied().zip(lob.weights).collect(),
            thickness: design.thickness,
            symmetry: Vec::new(),
        };
        let surface = Surface::Rectangle(Rectangle::new(V3::zeros(), V3::x(), V3::y()).unwrap());
        ShellModel::new(&surface, disc, design.material).unwrap()
    }

    pub fn pressure() -> Pressure {
        // n⁰ = +z: a negative pressure pushes the plate down (−z).
        Pressure::new(-PRESSURE).unwrap()
    }

    pub fn problem(design: &Design) -> ShellProblem {
        let model = Self::model(design);
        // Clamped: three displacements and two rotations held at every boundary particle
        // (each particle once: the corners belong to two edges).
        let mut rows = Vec::new();
        for &uv in &model.particle_uv {
            if uv.iter().any(|&x| x == 0.0 || x == 1.0) {
                for axis in [V3::x(), V3::y(), V3::z()] {
                    rows.push(LinearConstraint::displacement(&model, uv, axis, 0.0).unwrap());
                }
                for b in 0..2 {
                    rows.push(LinearConstraint::rotation(&model, uv, b, 0.0).unwrap());
                }
            }
        }
        let loads = vec![Self::pressure().into()];
        ShellProblem::new(model, loads, rows).unwrap()
    }

    pub fn monitors() -> Vec<Monitor> {
        vec![
            Monitor::new("w(centre)", [0.5, 0.5], 2).unwrap(),
            Monitor::new("w(quarter, mid)", [0.25, 0.5], 2).unwrap(),
            Monitor::new("w(quarter, quarter)", [0.25, 0.25], 2).unwrap(),
            Monitor::new("u(quarter, mid)", [0.25, 0.5], 0).unwrap(),
            Monitor::new("v(quarter, quarter)", [0.25, 0.25], 1).unwrap(),
        ]
    }
}

impl Analysis for Plate {
    fn build(&self, design: &Design) -> Result<(ShellProblem, NewtonSolver), SensitivityError> {
        Ok((Self::problem(design), driver(STEPS)))
    }
}

pub fn variables() -> Vec<DesignVariable> {
    vec![
        DesignVariable::thickness(),
        DesignVariable::material(MaterialParameter::Young),
        DesignVariable::material(MaterialParameter::Sigma0),
        DesignVariable::material(MaterialParameter::Hardening),
        DesignVariable::material(MaterialParameter::Poisson),
        DesignVariable::material(MaterialParameter::Beta),
    ]
}
