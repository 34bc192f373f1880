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
use shelldsa::shell::load::ExternalLoad;
use shelldsa::shell::model::{Discretisation, ShellModel};
use shelldsa::shell::ShellError;

/// The strip: model, shape functions, clamping transformation and the unit tip load (+z).
pub struct Strip {
    pub model: ShellModel,
    pub shape: ShapeFunctions,
    pub clamp: Transformation,
    pub tip_load: Vec<f64>,
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

/// Solve `K Δq = −r` in the transformed (nodal) space of `t`, `K̃ = Λ⁻ᵀ K Λ⁻¹`, `r̃ = Λ⁻ᵀ r`,
/// with the nodal DOFs `fixed` held at zero; returns the generalised `Δq`.
pub fn solve_with_fixed(
    t: &Transformation,
    k: &DMatrix<f64>,
    r: &[f64],
    fixed: &[usize],
) -> Vec<f64> {
    let mut rt = DVector::from_vec(t.transform_vector(r, 5).unwrap());
    let mut kt = t.transform_matrix_dense(k, 5).unwrap();
    for &d in fixed {
        rt[d] = 0.0;
        kt.row_mut(d).fill(0.0);
        kt.column_mut(d).fill(0.0);
        kt[(d, d)] = 1.0;
    }
    let du = kt
        .lu()
        .solve(&(-rt))
        .expect("supported tangent must be regular");
    t.to_generalised(du.as_slice(), 5).unwrap()
}

/// Strip of length `length` and width 1 with the discretisation `model`.
#[derive(Clone, Copy)]
pub struct StripSpec {
    pub length: f64,
    pub model: ModelSpec,
}

/// Build the strip.
pub fn strip(spec: &StripSpec) -> Strip {
    let rect = Rectangle::new(
        Vector3::zeros(),
        Vector3::new(spec.length, 0.0, 0.0),
        Vector3::new(0.0, 1.0, 0.0),
    )
    .unwrap();
    let model = elastic_model(&Surface::Rectangle(rect), &spec.model);
    let shape = model.shape_functions.clone();
    let n_v = spec.model.n_v;

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
    let clamped = edge_particles(&model.particle_uv, &ParamBox::unit(), Edge::UMin, 1e-12);
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

    /// Solve `K Δq = −r` with every nodal DOF of the clamped particles held at zero.
    pub fn clamped_solve(&self, k: &DMatrix<f64>, r: &[f64]) -> Vec<f64> {
        solve_with_fixed(&self.clamp, k, r, &self.clamp.constrained_dofs(5))
    }

    /// Value of component `c` of the RK approximation of the coefficients `q` at `(u, v)`.
    pub fn field(&self, q: impl Fn(usize) -> f64, uv: [f64; 2]) -> f64 {
        let mut sv = ShapeValues::new();
        self.shape.evaluate(uv, &mut sv).unwrap();
        sv.iter().map(|(i, psi, _)| psi * q(i)).sum()
    }
}

/// A dead load given directly as a generalised force vector (load factor 1), e.g. the strip's
/// edge-integrated tip load.
#[derive(Debug, Clone)]
pub struct GeneralisedLoad(pub Vec<f64>);

impl ExternalLoad for GeneralisedLoad {
    fn add_force(
        &self,
        model: &ShellModel,
        _q: &[f64],
        factor: f64,
        f: &mut [f64],
    ) -> Result<(), ShellError> {
        if f.len() != self.0.len() || model.n_dofs() != f.len() {
            return Err(ShellError::Dimension {
                expected: self.0.len(),
                got: f.len(),
            });
        }
        for (a, b) in f.iter_mut().zip(&self.0) {
            *a += factor * b;
        }
        Ok(())
    }
}

/// Scordelis–Lo roof, linear (reference-values §2: R = 25, L = 50, half-angle 40°, t = 0.25,
/// E = 4.32e8, ν = 0, self-weight 90 per unit area; diaphragms u_y = u_z = 0 at the curved ends
/// by the transformation method, one axial nodal value fixed): vertical deflection (downward
/// positive) at the middle of the free edge θ = +40°, with `n × n` particles, supports of
/// `support` spacings, `sub` cells per spacing of `ppc × ppc` Gauss points and VCI of `vci`.
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
    let nd = model.n_dofs();
    let c = model.contributions(&vec![0.0; nd], true).unwrap();
    let k = model.dense_tangent(&c);

    // Self-weight: f_I = −90 ∫ Ψ_I dA ẑ, dA = |x̄,1 × x̄,2| dξ at the model's quadrature points.
    let mut f = vec![0.0; nd];
    for p in &model.points {
        let da = p.surface.x_a[0].cross(&p.surface.x_a[1]).norm() * p.weight;
        for (&i, s) in p.neighbours.iter().zip(&p.shape) {
            f[5 * i + 2] -= 90.0 * s.psi * da;
        }
    }

    // Diaphragms at v = 0 and v = 1: nodal u_y = u_z = 0; one nodal u_x = 0.
    let uv = &model.particle_uv;
    let mut ends = edge_particles(uv, &ParamBox::unit(), Edge::VMin, 1e-12);
    let first_end = ends.clone();
    ends.extend(edge_particles(uv, &ParamBox::unit(), Edge::VMax, 1e-12));
    let t = Transformation::new(&model.shape_functions, &ends).unwrap();
    let mut fixed: Vec<usize> = ends.iter().flat_map(|&i| [5 * i + 1, 5 * i + 2]).collect();
    fixed.push(5 * first_end[first_end.len() / 2]);
    // K q = f, i.e. K Δq = −r with r = −f.
    let minus_f: Vec<f64> = f.iter().map(|v| -v).collect();
    let q = solve_with_fixed(&t, &k, &minus_f, &fixed);
    let mut sv = ShapeValues::new();
    model.shape_functions.evaluate([1.0, 0.5], &mut sv).unwrap();
    -sv.iter().map(|(i, psi, _)| psi * q[5 * i + 2]).sum::<f64>()
}
