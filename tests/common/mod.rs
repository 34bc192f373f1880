//! Shared set-up of the clamped elastic strip used by the shell cantilever tests.
//!
//! A flat strip `L × 1`, thickness `t`, E, ν = 0, clamped at u = 0 through the transformation
//! method (exact on a flat strip, whose particles share their lamina vectors), loaded by a unit
//! transverse force spread uniformly over the tip edge u = 1.
#![allow(dead_code)] // each test file uses a subset

use nalgebra::{DMatrix, DVector, Vector3};
use shelldsa::geometry::{Rectangle, Surface};
use shelldsa::material::MaterialParams;
use shelldsa::meshfree::quadrature::{gauss_legendre, CellQuadrature};
use shelldsa::meshfree::transform::{edge_particles, Edge, Transformation};
use shelldsa::meshfree::{regular_grid, Basis, ParamBox, ShapeFunctions, ShapeValues};
use shelldsa::shell::model::{Discretisation, ShellModel};

/// The strip: model, shape functions, clamping transformation and the unit tip load (+z).
pub struct Strip {
    pub model: ShellModel,
    pub shape: ShapeFunctions,
    pub clamp: Transformation,
    pub tip_load: Vec<f64>,
}

/// Strip data: length, thickness, Young's modulus; `n_u × n_v` particles (quadratic basis,
/// support `support` spacings); cells aligned with the particle grid subdivided `sub` times with
/// `ppc × ppc` Gauss points.
#[derive(Clone, Copy)]
pub struct StripSpec {
    pub length: f64,
    pub thickness: f64,
    pub young: f64,
    pub n_u: usize,
    pub n_v: usize,
    pub support: f64,
    pub sub: usize,
    pub ppc: usize,
}

/// Build the strip: 2 Gauss points through the thickness, elastic material (yield stress 1e30).
pub fn strip(spec: &StripSpec) -> Strip {
    let StripSpec {
        length,
        thickness,
        young,
        n_u,
        n_v,
        support,
        sub,
        ppc,
    } = *spec;
    let rect = Rectangle::new(
        Vector3::zeros(),
        Vector3::new(length, 0.0, 0.0),
        Vector3::new(0.0, 1.0, 0.0),
    )
    .unwrap();
    let grid = regular_grid(ParamBox::unit(), n_u, n_v);
    let supports = grid.supports(support);
    let cq = CellQuadrature::for_particle_grid(&grid, sub, ppc).unwrap();
    let g2 = gauss_legendre(2).unwrap();
    let disc = Discretisation {
        particle_uv: grid.positions.clone(),
        supports: supports.clone(),
        basis: Basis::Quadratic,
        quadrature: cq.iter().map(|(p, w, _)| (p, w)).collect(),
        thickness_rule: g2
            .nodes
            .iter()
            .copied()
            .zip(g2.weights.iter().copied())
            .collect(),
        thickness,
    };
    let material = MaterialParams::new(young, 0.0, 1e30, 0.0, 1.0).unwrap();
    let model = ShellModel::new(&Surface::Rectangle(rect), disc, material).unwrap();
    let shape = ShapeFunctions::new(grid.positions.clone(), supports, Basis::Quadratic).unwrap();

    // f_I = ∫ Ψ_I(1, v) dv over the tip edge, 6 Gauss points per particle interval.
    let mut tip_load = vec![0.0; model.n_dofs()];
    let (gn, gw) = gauss_legendre(6).unwrap().mapped(0.0, 1.0);
    let mut sv = ShapeValues::new();
    let cells = n_v - 1;
    for cell in 0..cells {
        let (a, b) = (cell as f64 / cells as f64, (cell + 1) as f64 / cells as f64);
        for (&x, &w) in gn.iter().zip(&gw) {
            shape.evaluate([1.0, a + (b - a) * x], &mut sv).unwrap();
            for (i, psi, _) in sv.iter() {
                tip_load[5 * i + 2] += psi * w * (b - a);
            }
        }
    }
    let clamped = edge_particles(&grid.positions, &ParamBox::unit(), Edge::UMin, 1e-12);
    let clamp = Transformation::new(&shape, &clamped).unwrap();
    Strip {
        model,
        shape,
        clamp,
        tip_load,
    }
}

impl Strip {
    /// `|Λ⁻ᵀ r|` over the free DOFs: the residual norm in the transformed (nodal) space.
    pub fn clamped_residual_norm(&self, r: &[f64]) -> f64 {
        let mut rt = self.clamp.transform_vector(r, 5).unwrap();
        for d in self.clamp.constrained_dofs(5) {
            rt[d] = 0.0;
        }
        rt.iter().map(|v| v * v).sum::<f64>().sqrt()
    }

    /// Solve `K Δq = −r` with the clamped DOFs eliminated in the transformed (nodal) space,
    /// `K̃ = Λ⁻ᵀ K Λ⁻¹`, `r̃ = Λ⁻ᵀ r`, clamped nodal values held at zero; returns `Δq`.
    pub fn clamped_solve(&self, k: &DMatrix<f64>, r: &[f64]) -> Vec<f64> {
        let mut rt = DVector::from_vec(self.clamp.transform_vector(r, 5).unwrap());
        let mut kt = self.clamp.transform_matrix_dense(k, 5).unwrap();
        for d in self.clamp.constrained_dofs(5) {
            rt[d] = 0.0;
            kt.row_mut(d).fill(0.0);
            kt.column_mut(d).fill(0.0);
            kt[(d, d)] = 1.0;
        }
        let du = kt
            .lu()
            .solve(&(-rt))
            .expect("clamped tangent must be regular");
        self.clamp.to_generalised(du.as_slice(), 5).unwrap()
    }

    /// Value of component `c` of the RK approximation of the coefficients `q` at `(u, v)`.
    pub fn field(&self, q: impl Fn(usize) -> f64, uv: [f64; 2]) -> f64 {
        let mut sv = ShapeValues::new();
        self.shape.evaluate(uv, &mut sv).unwrap();
        sv.iter().map(|(i, psi, _)| psi * q(i)).sum()
    }
}
