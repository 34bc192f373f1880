//! The discrete shell: particles on a CAD patch, quadrature points with their RK shape functions,
//! histories, and the assembly of the point kernel ([`super::point`]) into the global internal
//! force and consistent tangent.
//!
//! Global DOFs: 5 per particle, `[Δū_I (3), α_I (2)]`, particle-major. Assembly runs the
//! quadrature points in parallel (rayon) and adds their contributions in point order, so serial
//! and parallel runs give bit-identical results.

use super::point::{
    point_residual, point_residual_with, ParticleState, PointHistory, PointIncrement, PointInput,
    ShapeData, SurfacePoint, DOFS_PER_PARTICLE,
};
use super::rotation::rotate_director;
use super::tangent::ThicknessTangent;
use super::ShellError;
use crate::geometry::Surface;
use crate::material::{MaterialParams, MaterialState};
use crate::meshfree::{Basis, MeshfreeError, ShapeFunctions, ShapeValues};
use crate::scalar::Real;
use nalgebra::{DMatrix, Vector3};
use rayon::prelude::*;

/// An in-plane quadrature point with its shape functions and initial geometry.
#[derive(Clone, Debug)]
pub struct QuadraturePoint {
    /// Parameter coordinates.
    pub uv: [f64; 2],
    /// Parameter-domain weight (the area element enters through det J).
    pub weight: f64,
    /// Initial geometry at the point.
    pub surface: SurfacePoint<f64>,
    /// Neighbour particle indices.
    pub neighbours: Vec<usize>,
    /// Their shape functions at the point.
    pub shape: Vec<ShapeData>,
}

/// Local contribution of one in-plane point (all thickness layers).
#[derive(Clone, Debug)]
pub struct LocalContribution {
    /// Global DOF indices (5 per neighbour).
    pub dofs: Vec<usize>,
    /// Internal force.
    pub residual: Vec<f64>,
    /// Tangent (when asked for).
    pub tangent: Option<DMatrix<f64>>,
    /// Trial histories of the thickness layers.
    pub history: Vec<PointHistory<f64>>,
    /// Number of plastic layers.
    pub plastic_layers: usize,
}

/// The committed mid-surface at one parameter point ([`ShellModel::sample`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MidSurfaceSample {
    /// Initial position `x̄⁰`.
    pub x0: Vector3<f64>,
    /// Initial unit normal `n⁰`.
    pub n0: Vector3<f64>,
    /// Displacement `ū`.
    pub displacement: Vector3<f64>,
    /// Director `d` (RK-interpolated, not normalised).
    pub director: Vector3<f64>,
}

/// Discretisation of a shell patch: particles, RK functions, quadrature, thickness.
#[derive(Clone, Debug)]
pub struct Discretisation {
    /// Particle parameter coordinates.
    pub particle_uv: Vec<[f64; 2]>,
    /// Support half-widths per particle.
    pub supports: Vec<[f64; 2]>,
    /// RK basis.
    pub basis: Basis,
    /// In-plane quadrature `(uv, parameter-domain weight)`.
    pub quadrature: Vec<([f64; 2], f64)>,
    /// Thickness rule `(ζ, weight)`.
    pub thickness_rule: Vec<(f64, f64)>,
    /// Shell thickness.
    pub thickness: f64,
}

/// The discrete shell.
#[derive(Clone, Debug)]
pub struct ShellModel {
    /// Committed particle states.
    pub particles: Vec<ParticleState<f64>>,
    /// Particle parameter coordinates.
    pub particle_uv: Vec<[f64; 2]>,
    /// In-plane quadrature points.
    pub points: Vec<QuadraturePoint>,
    /// Thickness rule: `(ζ, weight)`.
    pub thickness_rule: Vec<(f64, f64)>,
    /// Shell thickness.
    pub thickness: f64,
    /// Material.
    pub material: MaterialParams<f64>,
    /// Committed histories, `points.len() × thickness_rule.len()`, point-major.
    pub history: Vec<PointHistory<f64>>,
    /// The RK shape functions of the particles (for loads, essential conditions and output).
    pub shape_functions: ShapeFunctions,
}

/// Lamina vectors `e1, e2 ⟂ d`: `e1` along the projection of `t` (a surface tangent).
fn lamina_vectors(d: &Vector3<f64>, t: &Vector3<f64>) -> [Vector3<f64>; 2] {
    let e1 = (t - d * d.dot(t)).normalize();
    [e1, d.cross(&e1)]
}

impl ShellModel {
    /// Build the model: RK shape functions of the particles evaluated at the in-plane
    /// quadrature points, initial directors from the surface normal at each particle.
    pub fn new(
        surface: &Surface<f64>,
        disc: Discretisation,
        material: MaterialParams<f64>,
    ) -> Result<Self, ShellError> {
        let Discretisation {
            particle_uv,
            supports,
            basis,
            quadrature,
            thickness_rule,
            thickness,
        } = disc;
        material.validate()?;
        if !(thickness > 0.0 && thickness.is_finite()) {
            return Err(ShellError::InvalidInput(format!(
                "thickness = {thickness}: expected a finite value > 0"
            )));
        }
        let particles = particle_uv
            .iter()
            .map(|&[u, v]| {
                let sd = surface.eval(u, v);
                let n = sd.normal().map_err(|e| {
                    ShellError::InvalidInput(format!("particle at ({u}, {v}): {e}"))
                })?;
                Ok(ParticleState {
                    u: Vector3::zeros(),
                    d: n,
                    d0: n,
                    e: lamina_vectors(&n, &sd.xu),
                })
            })
            .collect::<Result<Vec<_>, ShellError>>()?;
        let sf = ShapeFunctions::new(particle_uv.clone(), supports, basis).map_err(mf)?;
        let points = quadrature
            .par_iter()
            .map(|&(uv, weight)| {
                let mut sv = ShapeValues::new();
                sf.evaluate(uv, &mut sv).map_err(mf)?;
                let sd = surface.eval(uv[0], uv[1]);
                sd.normal().map_err(|e| {
                    ShellError::InvalidInput(format!("quadrature point {uv:?}: {e}"))
                })?;
                Ok(QuadraturePoint {
                    uv,
                    weight,
                    surface: SurfacePoint::from_derivs(&sd),
                    neighbours: sv.neighbours().to_vec(),
                    shape: sv
                        .iter()
                        .map(|(_, psi, dpsi)| ShapeData::new(psi, dpsi))
                        .collect(),
                })
            })
            .collect::<Result<Vec<_>, ShellError>>()?;
        let history = points
            .iter()
            .flat_map(|p| {
                let h = PointHistory {
                    frame: p.surface.initial_frame(),
                    material: MaterialState::virgin(),
                };
                std::iter::repeat_n(h, thickness_rule.len())
            })
            .collect();
        Ok(ShellModel {
            particles,
            particle_uv,
            points,
            thickness_rule,
            thickness,
            material,
            history,
            shape_functions: sf,
        })
    }

    /// Number of global DOFs.
    pub fn n_dofs(&self) -> usize {
        DOFS_PER_PARTICLE * self.particles.len()
    }

    fn local_dofs(&self, p: &QuadraturePoint) -> Vec<usize> {
        p.neighbours
            .iter()
            .flat_map(|&i| (0..DOFS_PER_PARTICLE).map(move |c| DOFS_PER_PARTICLE * i + c))
            .collect()
    }

    /// The committed states of the neighbours of in-plane point `k` and their local DOF
    /// increments (5 per neighbour), gathered from the global generalised increment `dofs`, in
    /// scalar `T` (the states are lifted as constants). This is the one place where the global
    /// DOFs map to a point's local ones: loads, output and the DSA gather through it too.
    pub fn gather_local<T: Real>(&self, k: usize, dofs: &[T]) -> (Vec<ParticleState<T>>, Vec<T>) {
        let p = &self.points[k];
        let parts = p
            .neighbours
            .iter()
            .map(|&i| {
                let q = &self.particle_state(i);
                ParticleState {
                    u: q.u.map(T::cst),
                    d: q.d.map(T::cst),
                    d0: q.d0.map(T::cst),
                    e: q.e.map(|v| v.map(T::cst)),
                }
            })
            .collect();
        let x = self.local_dofs(p).iter().map(|&i| dofs[i]).collect();
        (parts, x)
    }

    /// Add a local vector of in-plane point `k` (5 per neighbour, as from
    /// [`ShellModel::gather_local`]) into the global generalised vector `global`: the transpose
    /// of the gather.
    pub fn scatter_local<T: Real>(&self, k: usize, local: &[T], global: &mut [T]) {
        for (&j, l) in self.points[k]
            .neighbours
            .iter()
            .zip(local.chunks_exact(DOFS_PER_PARTICLE))
        {
            self.scatter_particle(j, l, global);
        }
    }

    /// Committed state of shape-function particle `j` (an index into
    /// [`ShellModel::shape_functions`]).
    pub fn particle_state(&self, j: usize) -> ParticleState<f64> {
        self.particles[j]
    }

    /// The committed mid-surface at parameter coordinates `uv`: initial position and normal,
    /// RK-interpolated displacement `Σ Ψ_J ū_J` and director `n⁰ + Σ Ψ_J (d_J − d⁰_J)`
    /// (not normalised), for output and monitors.
    pub fn sample(
        &self,
        surface: &Surface<f64>,
        uv: [f64; 2],
    ) -> Result<MidSurfaceSample, ShellError> {
        let sd = surface.eval(uv[0], uv[1]);
        let n0 = sd
            .normal()
            .map_err(|e| ShellError::InvalidInput(format!("sample at {uv:?}: {e}")))?;
        let mut sv = ShapeValues::new();
        self.shape_functions.evaluate(uv, &mut sv).map_err(mf)?;
        let mut u = Vector3::zeros();
        let mut d = n0;
        for (j, psi, _) in sv.iter() {
            let p = self.particle_state(j);
            u += p.u * psi;
            d += (p.d - p.d0) * psi;
        }
        Ok(MidSurfaceSample {
            x0: sd.x,
            n0,
            displacement: u,
            director: d,
        })
    }

    /// Add the 5 local components `local` of shape-function particle `j` (an index into
    /// [`ShellModel::shape_functions`]) into the global generalised vector.
    pub fn scatter_particle<T: Real>(&self, j: usize, local: &[T], global: &mut [T]) {
        for (c, v) in local.iter().enumerate().take(DOFS_PER_PARTICLE) {
            global[DOFS_PER_PARTICLE * j + c] += *v;
        }
    }

    /// Contribution of in-plane point `k` for the global DOF increment `dofs`.
    pub fn local(
        &self,
        k: usize,
        dofs: &[f64],
        tangent: bool,
    ) -> Result<LocalContribution, ShellError> {
        let p = &self.points[k];
        let idx = self.local_dofs(p);
        let (parts, x) = self.gather_local(k, dofs);
        let nl = self.thickness_rule.len();
        let mut residual = vec![0.0; idx.len()];
        let mut k_loc = tangent.then(|| DMatrix::zeros(idx.len(), idx.len()));
        let inc = PointIncrement::new(&parts, &x)?;
        let mut k_sum = tangent
            .then(|| ThicknessTangent::new(&p.shape, &parts, &x))
            .transpose()?;
        let mut history = Vec::with_capacity(nl);
        let mut plastic_layers = 0;
        for (l, &(zeta, wz)) in self.thickness_rule.iter().enumerate() {
            let inp = PointInput {
                surface: &p.surface,
                zeta,
                thickness: self.thickness,
                weight: p.weight * wz,
                shape: &p.shape,
                particles: &parts,
                material: &self.material,
                history: &self.history[k * nl + l],
            };
            let res = point_residual_with(&inp, &inc)?;
            for (r, v) in residual.iter_mut().zip(&res.residual) {
                *r += v;
            }
            if let Some(ks) = k_sum.as_mut() {
                ks.add_layer(&inp, &res)?;
            }
            plastic_layers += usize::from(res.return_map.plastic);
            history.push(res.history);
        }
        if let (Some(ks), Some(km)) = (&k_sum, k_loc.as_mut()) {
            ks.add_to(km)?;
        }
        Ok(LocalContribution {
            dofs: idx,
            residual,
            tangent: k_loc,
            history,
            plastic_layers,
        })
    }

    /// All local contributions (parallel over in-plane points, returned in point order).
    pub fn contributions(
        &self,
        dofs: &[f64],
        tangent: bool,
    ) -> Result<Vec<LocalContribution>, ShellError> {
        if dofs.len() != self.n_dofs() {
            return Err(ShellError::Dimension {
                expected: self.n_dofs(),
                got: dofs.len(),
            });
        }
        (0..self.points.len())
            .into_par_iter()
            .map(|k| self.local(k, dofs, tangent))
            .collect()
    }

    /// Global internal force for the DOF increment `dofs` (point order: deterministic).
    pub fn internal_force(&self, contributions: &[LocalContribution]) -> Vec<f64> {
        let mut f = vec![0.0; self.n_dofs()];
        for c in contributions {
            for (&i, v) in c.dofs.iter().zip(&c.residual) {
                f[i] += v;
            }
        }
        f
    }

    /// Dense global tangent (for small models and tests; the sparse path assembles the same
    /// local matrices).
    pub fn dense_tangent(&self, contributions: &[LocalContribution]) -> DMatrix<f64> {
        let n = self.n_dofs();
        let mut k = DMatrix::zeros(n, n);
        for c in contributions {
            if let Some(km) = &c.tangent {
                for (a, &i) in c.dofs.iter().enumerate() {
                    for (b, &j) in c.dofs.iter().enumerate() {
                        k[(i, j)] += km[(a, b)];
                    }
                }
            }
        }
        k
    }

    /// Global internal force in scalar `T` (the dual-number reference of the assembled residual).
    pub fn internal_force_generic<T: Real>(&self, dofs: &[T]) -> Result<Vec<T>, ShellError> {
        let mut f = vec![T::zero(); self.n_dofs()];
        let nl = self.thickness_rule.len();
        let m = self.material.lift::<T>();
        for (k, p) in self.points.iter().enumerate() {
            let (parts, x) = self.gather_local(k, dofs);
            let s = SurfacePoint {
                x_a: p.surface.x_a.map(|v| v.map(T::cst)),
                n: p.surface.n.map(T::cst),
                n_a: p.surface.n_a.map(|v| v.map(T::cst)),
            };
            for (l, &(zeta, wz)) in self.thickness_rule.iter().enumerate() {
                let hk = &self.history[k * nl + l];
                let h = PointHistory {
                    frame: hk.frame.map(T::cst),
                    material: hk.material.lift(),
                };
                let inp = PointInput {
                    surface: &s,
                    zeta,
                    thickness: T::cst(self.thickness),
                    weight: p.weight * wz,
                    shape: &p.shape,
                    particles: &parts,
                    material: &m,
                    history: &h,
                };
                let res = point_residual(&inp, &x)?;
                self.scatter_local(k, &res.residual, &mut f);
            }
        }
        Ok(f)
    }

    /// Commit a converged increment: particle coefficients and directors move, the lamina
    /// vectors of each particle rotate with its director, histories become the trial ones.
    pub fn commit(&mut self, dofs: &[f64], contributions: Vec<LocalContribution>) {
        for (i, p) in self.particles.iter_mut().enumerate() {
            let q = &dofs[DOFS_PER_PARTICLE * i..DOFS_PER_PARTICLE * (i + 1)];
            let alpha = [q[3], q[4]];
            let d_new = rotate_director(&p.d, &p.e[0], &p.e[1], alpha);
            let e0 = rotate_director(&p.e[0], &p.e[0], &p.e[1], alpha);
            p.u += Vector3::new(q[0], q[1], q[2]);
            p.d = d_new;
            p.e = lamina_vectors(&d_new, &e0);
        }
        let nl = self.thickness_rule.len();
        for (k, c) in contributions.into_iter().enumerate() {
            for (l, h) in c.history.into_iter().enumerate() {
                self.history[k * nl + l] = h;
            }
        }
    }
}

fn mf(e: MeshfreeError) -> ShellError {
    ShellError::InvalidInput(e.to_string())
}
