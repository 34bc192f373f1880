//! The discrete shell: particles on a CAD patch, quadrature points with their RK shape functions,
//! histories, and the assembly of the point kernel ([`super::point`]) into the global internal
//! force and consistent tangent.
//!
//! Global DOFs: 5 per real particle, `[Δū_I (3), α_I (2)]`, particle-major. Symmetry planes add
//! image particles ([`super::symmetry`]): shape-function particles without DOFs of their own,
//! whose state and local DOFs are a fixed linear map of their source,
//! `T_j = diag(Q_j, det(Q_j) I₂)`. [`ShellModel::gather_local`], [`ShellModel::scatter_local`] and
//! [`ShellModel::scatter_particle`] are the one seam between global and point-local DOFs and
//! apply these maps; a point's contribution is returned on the global DOFs of its distinct
//! source particles (its *cell*). Assembly runs the quadrature points in parallel (rayon) and
//! adds their contributions in point order, so serial and parallel runs give bit-identical
//! results.

use super::point::{
    point_residual_with, DirectorField, ParticleState, PointHistory, PointIncrement, PointInput,
    ShapeData, SurfacePoint, DOFS_PER_PARTICLE,
};
use super::symmetry::{SymmetryLayout, SymmetryPlane};
use super::tangent::{CellSlot, ThicknessTangent};
use super::ShellError;
use crate::geometry::{GeometryError, Surface};
use crate::kinematics::rotation::{director_derivatives, rotate_director, DirectorDerivatives};
use crate::material::{MaterialParams, MaterialState};
use crate::meshfree::{Basis, KernelFunction, MeshfreeError, ShapeFunctions, ShapeValues};
use crate::scalar::Real;
use nalgebra::{DMatrix, Matrix3, Vector3};
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
    /// Neighbour particle indices (shape-function particles: real, or image when
    /// `≥ ShellModel::n_particles()`).
    pub neighbours: Vec<usize>,
    /// Their shape functions at the point.
    pub shape: Vec<ShapeData>,
    /// The distinct real particles behind the neighbours (an image stands for its source), in
    /// first-occurrence order: the point's global DOFs are 5 per source (its cell).
    pub sources: Vec<usize>,
    /// For each neighbour, its source's position in [`QuadraturePoint::sources`].
    pub source_slot: Vec<usize>,
}

/// Contribution of one in-plane point (all thickness layers) on the global DOFs of its cell.
#[derive(Clone, Debug)]
pub struct LocalContribution {
    /// Global DOF indices (5 per source particle of the point, [`QuadraturePoint::sources`]).
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

/// Receives the thickness-integrated tangent of a point ([`ShellModel::layers`]).
type TangentSink<'s> = dyn FnMut(&ThicknessTangent<'_>) -> Result<(), ShellError> + 's;

/// What the thickness layers of one in-plane point give ([`ShellModel::layers`]).
struct Layers {
    residual: Vec<f64>,
    history: Vec<PointHistory<f64>>,
    plastic_layers: usize,
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

/// Per shape-function particle (real and image) data of one global increment, shared by the
/// points that have the particle as a neighbour: the committed state, the five local DOFs, the
/// director increment and its first derivatives ([`PointIncrement`]) and, for the tangent, the
/// director derivatives. Built by [`ShellModel::particle_cache`]; the same values a point would
/// compute for itself, computed once.
#[derive(Clone, Debug)]
pub struct ParticleCache {
    states: Vec<ParticleState<f64>>,
    local: Vec<[f64; DOFS_PER_PARTICLE]>,
    dd: Vec<Vector3<f64>>,
    d_alpha: Vec<[Vector3<f64>; 2]>,
    dirs: Option<Vec<DirectorDerivatives>>,
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
    /// RK kernel function.
    pub kernel: KernelFunction,
    /// In-plane quadrature `(uv, parameter-domain weight)`.
    pub quadrature: Vec<([f64; 2], f64)>,
    /// Thickness rule `(ζ, weight)`.
    pub thickness_rule: Vec<(f64, f64)>,
    /// Shell thickness.
    pub thickness: f64,
    /// Symmetry planes (image particles, [`super::symmetry`]); empty for none.
    pub symmetry: Vec<SymmetryPlane>,
}

/// The discrete shell.
#[derive(Clone, Debug)]
pub struct ShellModel {
    /// Committed states of the real particles (the image states follow from them,
    /// [`ShellModel::particle_state`]).
    pub particles: Vec<ParticleState<f64>>,
    /// Real particle parameter coordinates.
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
    /// The RK shape functions of the real and image particles (for loads, essential conditions
    /// and output): shape-function particle `j < n_particles()` is real, `j ≥` is image
    /// `j − n_particles()` of [`ShellModel::symmetry`].
    pub shape_functions: ShapeFunctions,
    /// Symmetry planes, image particles and the real particles on the planes.
    pub symmetry: SymmetryLayout,
    /// Parameter domain `[[u0, u1], [v0, v1]]` of the surface.
    pub domain: [[f64; 2]; 2],
    /// The director field at the quadrature points.
    pub director: DirectorField,
}

/// The DOF map of a shape-function particle: `x_j = T_j q_source`, `T_j = diag(Q, det I₂)`.
#[derive(Clone, Copy, Debug)]
struct DofMap {
    source: usize,
    /// `(Q, det Q)` for an image; `None` for a real particle (`T = I`).
    map: Option<(Matrix3<f64>, f64)>,
}

/// Lamina vectors `e1, e2 ⟂ d`: `e1 = (t − d (d·t))/|…|` along the projection of `t` (a
/// surface tangent), `e2 = d × e1`; generic over the scalar.
pub fn lamina_vectors<T: Real>(d: &Vector3<T>, t: &Vector3<T>) -> [Vector3<T>; 2] {
    let e1 = (t - d * d.dot(t)).normalize();
    [e1, d.cross(&e1)]
}

/// The particle update of a converged step, generic over the scalar (the analysis' commit and
/// the dual reference's): `ū += Δū`, the director and the first lamina vector rotated by
/// Rodrigues' formula with the increment's `α`, the lamina vectors re-orthogonalised.
pub fn commit_particle<T: Real>(p: &ParticleState<T>, q: &[T]) -> ParticleState<T> {
    let alpha = [q[3], q[4]];
    let d = rotate_director(&p.d, &p.e[0], &p.e[1], alpha);
    let e0 = rotate_director(&p.e[0], &p.e[0], &p.e[1], alpha);
    ParticleState {
        u: p.u + Vector3::new(q[0], q[1], q[2]),
        d,
        d0: p.d0,
        e: lamina_vectors(&d, &e0),
    }
}

/// The initial state of the particle at `uv` of `surface`, generic over the scalar (the
/// model's and, with the design parameters in a dual scalar, the dual reference's):
/// `ū = 0`, `d = d⁰ = n(ξ_I)`, and the lamina vectors with `e1` along the projection of
/// `hint` (a symmetry plane's normal) or else of `x,u`.
pub fn initial_particle<T: Real>(
    surface: &Surface<T>,
    [u, v]: [f64; 2],
    hint: Option<Vector3<f64>>,
) -> Result<ParticleState<T>, GeometryError> {
    let sd = surface.eval(T::cst(u), T::cst(v));
    let n = sd.normal()?;
    let t = hint.map_or(sd.xu, |h| h.map(T::cst));
    Ok(ParticleState {
        u: Vector3::zeros(),
        d: n,
        d0: n,
        e: lamina_vectors(&n, &t),
    })
}

/// The initial histories of points with the initial geometry `surfaces`, generic over the
/// scalar: per point and each of its `layers`, the initial lamina frame and the virgin
/// material state.
pub fn initial_histories<'a, T: Real>(
    surfaces: impl Iterator<Item = &'a SurfacePoint<T>>,
    layers: usize,
) -> Vec<PointHistory<T>> {
    surfaces
        .flat_map(|s| {
            let h = PointHistory {
                frame: s.initial_frame(),
                material: MaterialState::virgin(),
            };
            std::iter::repeat_n(h, layers)
        })
        .collect()
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
            kernel,
            quadrature,
            thickness_rule,
            thickness,
            symmetry,
        } = disc;
        material.validate()?;
        if !(thickness > 0.0 && thickness.is_finite()) {
            return Err(ShellError::InvalidInput(format!(
                "thickness = {thickness}: expected a finite value > 0"
            )));
        }
        if supports.len() != particle_uv.len() {
            return Err(ShellError::InvalidInput(format!(
                "supports: {} entries for {} particles: expected one per particle",
                supports.len(),
                particle_uv.len()
            )));
        }
        let domain = surface.domain();
        for plane in &symmetry {
            plane.validate(surface)?;
        }
        let layout = SymmetryLayout::new(&particle_uv, &supports, domain, symmetry)?;
        let particles = particle_uv
            .iter()
            .enumerate()
            .map(|(i, &[u, v])| {
                // On a symmetry edge e1 = n_s (which lies in the tangent plane there), so that
                // the symmetric rotation is α1 and the forbidden one α2.
                initial_particle(surface, [u, v], layout.lamina_hint(i))
                    .map_err(|e| ShellError::InvalidInput(format!("particle at ({u}, {v}): {e}")))
            })
            .collect::<Result<Vec<_>, ShellError>>()?;
        let n_real = particle_uv.len();
        let mut sf_uv = particle_uv.clone();
        let mut sf_sup = supports;
        for im in &layout.images {
            sf_uv.push(im.uv);
            sf_sup.push(im.support);
        }
        let sf = ShapeFunctions::new(sf_uv, sf_sup, basis)
            .map_err(mf)?
            .with_kernel(kernel);
        let source_of = |j: usize| {
            if j < n_real {
                j
            } else {
                layout.images[j - n_real].source
            }
        };
        let points = quadrature
            .par_iter()
            .map(|&(uv, weight)| {
                let mut sv = ShapeValues::new();
                sf.evaluate(uv, &mut sv).map_err(mf)?;
                let sd = surface.eval(uv[0], uv[1]);
                sd.normal().map_err(|e| {
                    ShellError::InvalidInput(format!("quadrature point {uv:?}: {e}"))
                })?;
                let neighbours = sv.neighbours().to_vec();
                let mut sources: Vec<usize> = Vec::with_capacity(neighbours.len());
                let source_slot = neighbours
                    .iter()
                    .map(|&j| {
                        let s = source_of(j);
                        match sources.iter().position(|&x| x == s) {
                            Some(k) => k,
                            None => {
                                sources.push(s);
                                sources.len() - 1
                            }
                        }
                    })
                    .collect();
                Ok(QuadraturePoint {
                    uv,
                    weight,
                    surface: SurfacePoint::from_derivs(&sd),
                    neighbours,
                    shape: sv
                        .iter()
                        .map(|(_, psi, dpsi)| ShapeData::new(psi, dpsi))
                        .collect(),
                    sources,
                    source_slot,
                })
            })
            .collect::<Result<Vec<_>, ShellError>>()?;
        let history = initial_histories(points.iter().map(|p| &p.surface), thickness_rule.len());
        Ok(ShellModel {
            particles,
            particle_uv,
            points,
            thickness_rule,
            thickness,
            material,
            history,
            shape_functions: sf,
            symmetry: layout,
            domain,
            director: DirectorField::default(),
        })
    }

    /// Number of global DOFs (5 per real particle).
    pub fn n_dofs(&self) -> usize {
        DOFS_PER_PARTICLE * self.particles.len()
    }

    /// Number of real particles (shape-function particles beyond are images).
    pub fn n_particles(&self) -> usize {
        self.particles.len()
    }

    /// Sizes of a generalised vector `q`, a force vector `f` (both `n_dofs`) and, when given,
    /// a list of per-particle states (`n_particles`).
    pub(crate) fn check_state_sizes(
        &self,
        q: usize,
        f: usize,
        particles: Option<usize>,
    ) -> Result<(), ShellError> {
        let n = self.n_dofs();
        for got in [q, f] {
            if got != n {
                return Err(ShellError::Dimension { expected: n, got });
            }
        }
        match particles {
            Some(got) if got != self.n_particles() => Err(ShellError::Dimension {
                expected: self.n_particles(),
                got,
            }),
            _ => Ok(()),
        }
    }

    /// Global DOFs of the cell of in-plane point `k` (5 per source particle).
    pub fn point_dofs(&self, k: usize) -> Vec<usize> {
        self.points[k]
            .sources
            .iter()
            .flat_map(|&i| (0..DOFS_PER_PARTICLE).map(move |c| DOFS_PER_PARTICLE * i + c))
            .collect()
    }

    /// The per-particle data of the global increment `dofs` for every shape-function particle
    /// (real and image): what every point would otherwise recompute for each of its neighbours
    /// ([`ParticleCache`]). The director derivatives of the tangent only when `tangent`.
    pub fn particle_cache(&self, dofs: &[f64], tangent: bool) -> Result<ParticleCache, ShellError> {
        if dofs.len() != self.n_dofs() {
            return Err(ShellError::Dimension {
                expected: self.n_dofs(),
                got: dofs.len(),
            });
        }
        let n_sf = self.particles.len() + self.symmetry.images.len();
        let per: Vec<_> = (0..n_sf)
            .into_par_iter()
            .map(|j| {
                let state = self.particle_state(j);
                // The local DOFs exactly as `gather_local` forms them.
                let x = self.particle_dofs(j, dofs);
                let inc = PointIncrement::new(std::slice::from_ref(&state), &x)?;
                let dirs = tangent.then(|| {
                    director_derivatives(&state.d, &state.e[0], &state.e[1], [x[3], x[4]])
                });
                Ok((state, x, inc.dd[0], inc.d_alpha[0], dirs))
            })
            .collect::<Result<_, ShellError>>()?;
        let mut cache = ParticleCache {
            states: Vec::with_capacity(n_sf),
            local: Vec::with_capacity(n_sf),
            dd: Vec::with_capacity(n_sf),
            d_alpha: Vec::with_capacity(n_sf),
            dirs: tangent.then(|| Vec::with_capacity(n_sf)),
        };
        for (state, x, dd, da, dirs) in per {
            cache.states.push(state);
            cache.local.push(x);
            cache.dd.push(dd);
            cache.d_alpha.push(da);
            if let (Some(v), Some(d)) = (cache.dirs.as_mut(), dirs) {
                v.push(d);
            }
        }
        Ok(cache)
    }

    fn dof_map(&self, j: usize) -> DofMap {
        let n = self.particles.len();
        if j < n {
            DofMap {
                source: j,
                map: None,
            }
        } else {
            let im = &self.symmetry.images[j - n];
            DofMap {
                source: im.source,
                map: Some((im.map, im.det)),
            }
        }
    }

    /// The real particle whose DOFs shape-function particle `j` uses (itself if real).
    pub fn source_of(&self, j: usize) -> usize {
        self.dof_map(j).source
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
            .map(|&i| self.particle_state(i).lift())
            .collect();
        let mut x = Vec::with_capacity(DOFS_PER_PARTICLE * p.neighbours.len());
        for &j in &p.neighbours {
            x.extend_from_slice(&self.particle_dofs(j, dofs));
        }
        (parts, x)
    }

    /// The local DOFs of shape-function particle `j` from the global generalised vector
    /// `dofs`: its own for a real particle, `T q` of its source's for a symmetry image
    /// (`ū_img = Q ū`, `α_img = det(Q) α`).
    pub fn particle_dofs<T: Real>(&self, j: usize, dofs: &[T]) -> [T; DOFS_PER_PARTICLE] {
        let m = self.dof_map(j);
        let q = &dofs[DOFS_PER_PARTICLE * m.source..DOFS_PER_PARTICLE * (m.source + 1)];
        match m.map {
            None => [q[0], q[1], q[2], q[3], q[4]],
            Some((qm, det)) => [
                q[0] * qm[(0, 0)] + q[1] * qm[(0, 1)] + q[2] * qm[(0, 2)],
                q[0] * qm[(1, 0)] + q[1] * qm[(1, 1)] + q[2] * qm[(1, 2)],
                q[0] * qm[(2, 0)] + q[1] * qm[(2, 1)] + q[2] * qm[(2, 2)],
                q[3] * det,
                q[4] * det,
            ],
        }
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
    /// [`ShellModel::shape_functions`]): a real particle's own, or for an image the map `Q` of
    /// its source's (`ū, d, d⁰, e` all mapped by `Q`), so images always follow their sources.
    pub fn particle_state(&self, j: usize) -> ParticleState<f64> {
        let m = self.dof_map(j);
        let p = self.particles[m.source];
        match m.map {
            None => p,
            Some((q, _)) => ParticleState {
                u: q * p.u,
                d: q * p.d,
                d0: q * p.d0,
                e: [q * p.e[0], q * p.e[1]],
            },
        }
    }

    /// The state of shape-function particle `j` from the real particles' `particles` (another
    /// committed state, in scalar `T`): a real particle's own, or for an image the map `Q` of
    /// its source's, as [`ShellModel::particle_state`].
    pub fn particle_state_in<T: Real>(
        &self,
        j: usize,
        particles: &[ParticleState<T>],
    ) -> ParticleState<T> {
        let m = self.dof_map(j);
        let p = particles[m.source];
        match m.map {
            None => p,
            Some((q, _)) => {
                let q = q.map(T::cst);
                ParticleState {
                    u: q * p.u,
                    d: q * p.d,
                    d0: q * p.d0,
                    e: [q * p.e[0], q * p.e[1]],
                }
            }
        }
    }

    /// The RK shape functions (real and image particles) at parameter coordinates `uv`.
    pub fn shape_values(&self, uv: [f64; 2]) -> Result<ShapeValues, ShellError> {
        let mut sv = ShapeValues::new();
        self.shape_functions.evaluate(uv, &mut sv).map_err(mf)?;
        Ok(sv)
    }

    /// The real particle whose DOFs shape-function particle `j` uses, and `det Q` of its map
    /// (1 for a real particle): an image's rotation parameters are `det Q` times its source's.
    pub fn dof_source(&self, j: usize) -> (usize, f64) {
        let m = self.dof_map(j);
        (m.source, m.map.map_or(1.0, |(_, det)| det))
    }

    /// The committed RK-interpolated mid-surface displacement `Σ Ψ_J ū_J` at parameter
    /// coordinates `uv` (no surface needed; [`ShellModel::sample`] adds the geometry).
    pub fn displacement_at(&self, uv: [f64; 2]) -> Result<Vector3<f64>, ShellError> {
        let mut sv = ShapeValues::new();
        self.shape_functions.evaluate(uv, &mut sv).map_err(mf)?;
        Ok(sv.iter().fold(Vector3::zeros(), |u, (j, psi, _)| {
            u + self.particle_state(j).u * psi
        }))
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

    /// RMS over the quadrature points of the interpolated translation and director increment
    /// (`Σ Ψ_J ū_J`, `Σ Ψ_J (α_J × d_J)`) and of their gradients times the spacing `h`, relative to
    /// the RMS of the particles' coefficients: how much of a coefficient vector the RK
    /// approximation passes to the points (1 for a smooth field): `[translation, director,
    /// h·translation gradient, h·director gradient]` for the generalised vector `x` (5 per real
    /// particle) and the particle spacing `h` in the parameter box. A coefficient field that
    /// alternates from particle to particle passes nothing at supports of 4 and 8 spacings
    /// (docs/stability.md §6).
    pub fn coefficient_transfer(&self, x: &[f64], h: f64) -> [f64; 4] {
        let n = self.n_particles();
        let (mut cu, mut cd) = (0.0, 0.0);
        for j in 0..n {
            let st = self.particle_state(j);
            let a = st.e[0] * x[5 * j + 3] + st.e[1] * x[5 * j + 4];
            cd += a.cross(&st.d).norm_squared();
            cu += (0..3).map(|c| x[5 * j + c].powi(2)).sum::<f64>();
        }
        let (mut fu, mut fd, mut gu, mut gd, mut w) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (k, p) in self.points.iter().enumerate() {
            let (parts, loc) = self.gather_local(k, x);
            let mut u = [nalgebra::Vector3::zeros(); 3];
            let mut d = [nalgebra::Vector3::zeros(); 3];
            for (i, (sd, st)) in p.shape.iter().zip(&parts).enumerate() {
                let q = &loc[5 * i..5 * i + 5];
                let uu = nalgebra::Vector3::new(q[0], q[1], q[2]);
                let dd = (st.e[0] * q[3] + st.e[1] * q[4]).cross(&st.d);
                for (m, f) in [sd.psi, sd.dpsi[0], sd.dpsi[1]].into_iter().enumerate() {
                    u[m] += uu * f;
                    d[m] += dd * f;
                }
            }
            w += 1.0;
            fu += u[0].norm_squared();
            fd += d[0].norm_squared();
            gu += (u[1].norm_squared() + u[2].norm_squared()) * h * h;
            gd += (d[1].norm_squared() + d[2].norm_squared()) * h * h;
        }
        let r = |f: f64, c: f64| ((f / w) / (c / n as f64).max(f64::MIN_POSITIVE)).sqrt();
        [r(fu, cu), r(fd, cd), r(gu, cu), r(gd, cd)]
    }

    /// The translation of shape-function particle `j` (real, or an image mapped from its
    /// source) in the DOF vector `q` (`n_dofs` long, e.g. a displacement sensitivity).
    pub fn translation_in(&self, j: usize, q: &[f64]) -> Vector3<f64> {
        let m = self.dof_map(j);
        let b = DOFS_PER_PARTICLE * m.source;
        let v = Vector3::new(q[b], q[b + 1], q[b + 2]);
        m.map.map_or(v, |(qm, _)| qm * v)
    }

    /// The RK interpolation `Σ Ψ_J (T_J q)_ū` at `uv` of the translational part of a generalised
    /// vector `q` (an increment, a Newton correction, a design sensitivity), images mapped from
    /// their sources.
    pub fn interpolate_translation(
        &self,
        uv: [f64; 2],
        q: &[f64],
    ) -> Result<Vector3<f64>, ShellError> {
        if q.len() != self.n_dofs() {
            return Err(ShellError::Dimension {
                expected: self.n_dofs(),
                got: q.len(),
            });
        }
        let mut sv = ShapeValues::new();
        self.shape_functions.evaluate(uv, &mut sv).map_err(mf)?;
        Ok(sv.iter().fold(Vector3::zeros(), |u, (j, psi, _)| {
            u + self.translation_in(j, q) * psi
        }))
    }

    /// Add the 5 local components `local` of shape-function particle `j` (an index into
    /// [`ShellModel::shape_functions`]) into the global generalised vector: `Tᵀ local` on its
    /// source's DOFs (`Qᵀ` on the forces, `det Q` on the moments of an image).
    pub fn scatter_particle<T: Real>(&self, j: usize, local: &[T], global: &mut [T]) {
        let m = self.dof_map(j);
        let g = &mut global[DOFS_PER_PARTICLE * m.source..DOFS_PER_PARTICLE * (m.source + 1)];
        match m.map {
            None => {
                for (gc, v) in g.iter_mut().zip(local.iter().take(DOFS_PER_PARTICLE)) {
                    *gc += *v;
                }
            }
            Some((q, det)) => {
                for c in 0..3 {
                    g[c] += local[0] * q[(0, c)] + local[1] * q[(1, c)] + local[2] * q[(2, c)];
                }
                g[3] += local[3] * det;
                g[4] += local[4] * det;
            }
        }
    }

    /// Map a point's neighbour-local residual (5 per neighbour) to its cell (5 per source):
    /// `r_c = Σ T_aᵀ r_a`. Without images nothing is done.
    fn residual_to_cell(&self, p: &QuadraturePoint, mut residual: Vec<f64>) -> Vec<f64> {
        const D: usize = DOFS_PER_PARTICLE;
        let maps = self.image_maps(p);
        if maps.is_empty() {
            return residual;
        }
        // Tᵀ r on the images' blocks.
        for &(a, q, det) in &maps {
            let r = &mut residual[D * a..D * a + D];
            let v = q.transpose() * Vector3::new(r[0], r[1], r[2]);
            r[..3].copy_from_slice(v.as_slice());
            r[3] *= det;
            r[4] *= det;
        }
        let mut rc = vec![0.0; D * p.sources.len()];
        for (a, r) in residual.chunks_exact(D).enumerate() {
            let s = D * p.source_slot[a];
            for (x, v) in rc[s..s + D].iter_mut().zip(r) {
                *x += v;
            }
        }
        rc
    }

    /// Contribution of in-plane point `k` for the global DOF increment `dofs`.
    pub fn local(
        &self,
        k: usize,
        dofs: &[f64],
        tangent: bool,
    ) -> Result<LocalContribution, ShellError> {
        let p = &self.points[k];
        let nc = DOFS_PER_PARTICLE * p.sources.len();
        let mut k_cell = tangent.then(|| DMatrix::zeros(nc, nc));
        let mut add = |ks: &ThicknessTangent<'_>| match k_cell.as_mut() {
            Some(km) => ks.add_to_cell(&self.cell_slots(p), p.sources.len(), km.as_mut_slice()),
            None => Ok(()),
        };
        let layers = self.layers(
            k,
            dofs,
            None,
            tangent.then_some(&mut add as &mut TangentSink<'_>),
        )?;
        let residual = self.residual_to_cell(p, layers.residual);
        let (history, plastic_layers) = (layers.history, layers.plastic_layers);
        Ok(LocalContribution {
            dofs: self.point_dofs(k),
            residual,
            tangent: k_cell,
            history,
            plastic_layers,
        })
    }

    /// The cell slots of the neighbours of `p`: their source's block and, for an image, its
    /// DOF map ([`ThicknessTangent::add_to_cell`]).
    fn cell_slots(&self, p: &QuadraturePoint) -> Vec<CellSlot> {
        p.neighbours
            .iter()
            .zip(&p.source_slot)
            .map(|(&j, &slot)| CellSlot {
                slot,
                image: self.dof_map(j).map,
            })
            .collect()
    }

    /// The layers of in-plane point `k`: local residual summed over the thickness (5 per
    /// neighbour), the trial histories and the number of plastic layers; the
    /// thickness-integrated tangent, when `tangent` is given, is handed to it (shared by
    /// [`ShellModel::local`] and [`ShellModel::add_to_cell`]).
    fn layers(
        &self,
        k: usize,
        dofs: &[f64],
        cache: Option<&ParticleCache>,
        tangent: Option<&mut TangentSink<'_>>,
    ) -> Result<Layers, ShellError> {
        let p = &self.points[k];
        let nl = self.thickness_rule.len();
        let (parts, x, inc, mut k_sum) = match cache {
            None => {
                let (parts, x) = self.gather_local(k, dofs);
                let inc = PointIncrement::new(&parts, &x)?;
                (parts, x, inc, None)
            }
            Some(c) => {
                let parts: Vec<_> = p.neighbours.iter().map(|&j| c.states[j]).collect();
                let x: Vec<f64> = p.neighbours.iter().flat_map(|&j| c.local[j]).collect();
                let inc = PointIncrement {
                    du: p
                        .neighbours
                        .iter()
                        .map(|&j| Vector3::new(c.local[j][0], c.local[j][1], c.local[j][2]))
                        .collect(),
                    dd: p.neighbours.iter().map(|&j| c.dd[j]).collect(),
                    d_alpha: p.neighbours.iter().map(|&j| c.d_alpha[j]).collect(),
                    unit: None,
                };
                (parts, x, inc, None)
            }
        };
        // The unit director's step, once for all layers.
        let inc = inc.with_unit_director(&self.layer_input(k, 0, &parts));
        let mut residual = vec![0.0; x.len()];
        if tangent.is_some() {
            k_sum = Some(match cache.and_then(|c| c.dirs.as_ref()) {
                Some(dirs) => ThicknessTangent::with_directors(
                    &p.shape,
                    &parts,
                    p.neighbours.iter().map(|&j| dirs[j]).collect(),
                )?,
                None => ThicknessTangent::new(&p.shape, &parts, &x)?,
            });
        }
        let mut history = Vec::with_capacity(nl);
        let mut plastic_layers = 0;
        for l in 0..nl {
            let inp = self.layer_input(k, l, &parts);
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
        if let (Some(ks), Some(sink)) = (&k_sum, tangent) {
            sink(ks)?;
        }
        Ok(Layers {
            residual,
            history,
            plastic_layers,
        })
    }

    /// The f64 input of layer `l` of in-plane point `k` (the model's surface, thickness,
    /// material and committed history), with the neighbours' states `particles`.
    pub(crate) fn layer_input<'a>(
        &'a self,
        k: usize,
        l: usize,
        particles: &'a [ParticleState<f64>],
    ) -> PointInput<'a, f64> {
        let p = &self.points[k];
        let (zeta, wz) = self.thickness_rule[l];
        PointInput {
            surface: &p.surface,
            zeta,
            thickness: self.thickness,
            weight: p.weight * wz,
            shape: &p.shape,
            particles,
            material: &self.material,
            history: &self.history[k * self.thickness_rule.len() + l],
            director: self.director,
        }
    }

    /// The images among the neighbours of `p`: `(neighbour slot, Q, det Q)`.
    fn image_maps(&self, p: &QuadraturePoint) -> Vec<(usize, Matrix3<f64>, f64)> {
        p.neighbours
            .iter()
            .enumerate()
            .filter_map(|(a, &j)| self.dof_map(j).map.map(|(q, det)| (a, q, det)))
            .collect()
    }

    /// Add the internal force of in-plane point `k` for the global increment `dofs`, and its
    /// consistent tangent when `tangent` is given, into the arrays of its cell (5 per source
    /// particle, [`QuadraturePoint::sources`] order as [`ShellModel::point_dofs`]; the tangent
    /// column-major). Returns the trial histories of the layers and the number of plastic
    /// layers. The same values as [`ShellModel::local`] (to round-off: the tangent is added in
    /// place rather than formed and then summed), without a per-point matrix: the assembly path
    /// of [`super::problem::ShellProblem`], which sums the points of a cell into one buffer.
    pub fn add_to_cell(
        &self,
        k: usize,
        dofs: &[f64],
        residual: &mut [f64],
        tangent: Option<&mut [f64]>,
    ) -> Result<(Vec<PointHistory<f64>>, usize), ShellError> {
        self.add_to_cell_cached(k, dofs, None, residual, tangent)
    }

    /// [`ShellModel::add_to_cell`] with the per-particle data of `dofs` computed once for all
    /// points ([`ShellModel::particle_cache`], built with `tangent` when a tangent is asked
    /// for): bit for bit the same results.
    pub fn add_to_cell_cached(
        &self,
        k: usize,
        dofs: &[f64],
        cache: Option<&ParticleCache>,
        residual: &mut [f64],
        tangent: Option<&mut [f64]>,
    ) -> Result<(Vec<PointHistory<f64>>, usize), ShellError> {
        const D: usize = DOFS_PER_PARTICLE;
        let p = &self.points[k];
        let nc = D * p.sources.len();
        if residual.len() != nc {
            return Err(ShellError::Dimension {
                expected: nc,
                got: residual.len(),
            });
        }
        if let Some(t) = &tangent {
            if t.len() != nc * nc {
                return Err(ShellError::Dimension {
                    expected: nc * nc,
                    got: t.len(),
                });
            }
        }
        let tangent_requested = tangent.is_some();
        let mut tangent = tangent;
        let mut add = |ks: &ThicknessTangent<'_>| -> Result<(), ShellError> {
            let Some(kc) = tangent.as_deref_mut() else {
                return Ok(());
            };
            if p.neighbours.len() == p.sources.len() && self.image_maps(p).is_empty() {
                // No images: the neighbours are the sources, in order.
                return ks.add_to_slice(kc);
            }
            ks.add_to_cell(&self.cell_slots(p), p.sources.len(), kc)
        };
        let with_tangent = tangent_requested;
        let Layers {
            residual: r_loc,
            history,
            plastic_layers,
        } = self.layers(
            k,
            dofs,
            cache,
            with_tangent.then_some(&mut add as &mut TangentSink<'_>),
        )?;
        let r_cell = self.residual_to_cell(p, r_loc);
        for (a, b) in residual.iter_mut().zip(&r_cell) {
            *a += b;
        }
        Ok((history, plastic_layers))
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

    /// Global internal force in scalar `T` (the dual-number reference of the assembled residual),
    /// with the committed states, material and thickness lifted as constants.
    pub fn internal_force_generic<T: Real>(&self, dofs: &[T]) -> Result<Vec<T>, ShellError> {
        let particles: Vec<ParticleState<T>> = self.particles.iter().map(|p| p.lift()).collect();
        let history: Vec<PointHistory<T>> = self.history.iter().map(|h| h.lift()).collect();
        let (f, _) = self.internal_force_with(
            &particles,
            &history,
            &self.material.lift::<T>(),
            T::cst(self.thickness),
            dofs,
        )?;
        Ok(f)
    }

    /// Global internal force (eq 32) and the trial histories (point-major, as
    /// [`ShellModel::history`]) in scalar `T`, from `T`-valued committed states of the real
    /// particles (images follow through the seam's fixed maps), committed histories, material
    /// and thickness. With dual numbers whose derivative parts carry design sensitivities this
    /// is the residual of the dual-number design sensitivity reference (`crate::sensitivity`):
    /// the kernels of the analysis, no hand-derived derivative. Points are evaluated in
    /// parallel and summed in point order (deterministic).
    pub fn internal_force_with<T: Real>(
        &self,
        particles: &[ParticleState<T>],
        history: &[PointHistory<T>],
        material: &MaterialParams<T>,
        thickness: T,
        dofs: &[T],
    ) -> Result<(Vec<T>, Vec<PointHistory<T>>), ShellError> {
        self.internal_force_with_surfaces(particles, history, material, thickness, dofs, None)
    }

    /// [`ShellModel::internal_force_with`] with the initial geometry of every quadrature point
    /// given in `T` (`surfaces`, as [`ShellModel::points`]; `None`: the model's, lifted): the
    /// residual of the dual reference for shape design variables.
    pub fn internal_force_with_surfaces<T: Real>(
        &self,
        particles: &[ParticleState<T>],
        history: &[PointHistory<T>],
        material: &MaterialParams<T>,
        thickness: T,
        dofs: &[T],
        surfaces: Option<&[SurfacePoint<T>]>,
    ) -> Result<(Vec<T>, Vec<PointHistory<T>>), ShellError> {
        let nl = self.thickness_rule.len();
        for (expected, got) in [
            (self.n_dofs(), dofs.len()),
            (self.particles.len(), particles.len()),
            (self.history.len(), history.len()),
            (
                self.points.len(),
                surfaces.map_or(self.points.len(), |s| s.len()),
            ),
        ] {
            if expected != got {
                return Err(ShellError::Dimension { expected, got });
            }
        }
        let per_point = (0..self.points.len())
            .into_par_iter()
            .map(|k| {
                let p = &self.points[k];
                // The neighbours' states in T: an image is `Q` times its source's (as
                // `particle_state`), its local DOFs `T_j q` (as `gather_local`).
                let (_, x) = self.gather_local(k, dofs);
                let parts: Vec<ParticleState<T>> = p
                    .neighbours
                    .iter()
                    .map(|&j| {
                        let m = self.dof_map(j);
                        let s = particles[m.source];
                        match m.map {
                            None => s,
                            Some((q, _)) => {
                                let qt = q.map(T::cst);
                                ParticleState {
                                    u: qt * s.u,
                                    d: qt * s.d,
                                    d0: qt * s.d0,
                                    e: [qt * s.e[0], qt * s.e[1]],
                                }
                            }
                        }
                    })
                    .collect();
                let s = surfaces.map_or_else(|| p.surface.lift::<T>(), |s| s[k]);
                let input = |l: usize| {
                    let (zeta, wz) = self.thickness_rule[l];
                    PointInput {
                        surface: &s,
                        zeta,
                        thickness,
                        weight: p.weight * wz,
                        shape: &p.shape,
                        particles: &parts,
                        material,
                        history: &history[k * nl + l],
                        director: self.director,
                    }
                };
                let inc = PointIncrement::new(&parts, &x)?.with_unit_director(&input(0));
                let mut residual = vec![T::zero(); x.len()];
                let mut trial = Vec::with_capacity(nl);
                for l in 0..nl {
                    let res = point_residual_with(&input(l), &inc)?;
                    for (r, v) in residual.iter_mut().zip(&res.residual) {
                        *r += *v;
                    }
                    trial.push(res.history);
                }
                Ok((residual, trial))
            })
            .collect::<Result<Vec<_>, ShellError>>()?;
        let mut f = vec![T::zero(); self.n_dofs()];
        let mut trial = Vec::with_capacity(self.history.len());
        for (k, (r, h)) in per_point.into_iter().enumerate() {
            self.scatter_local(k, &r, &mut f);
            trial.extend(h);
        }
        Ok((f, trial))
    }

    /// The normal component `m_I · d_I` of each real particle's director force on the
    /// committed state (zero increment), `m_I = Σ_points Σ_layers (f z + P_{:3} t/2 Ψ_I)`,
    /// `f = P_{:1} Ψ̃_I,1 + P_{:2} Ψ̃_I,2`: the vector whose products with `∂d_I/∂α_b` are the
    /// particle's rotation residuals. At `α = 0` the second derivative of the director update
    /// is `∂²d_I/∂α_b∂α_γ = −δ_bγ d_I`, so the tangent's block of the particle's two rotations
    /// holds `−(m_I · d_I) I₂`: a particle with `m_I · d_I > 0` is destabilised by it. An
    /// image's contribution `m_j · d_j` goes to its source (`d_j = Q d_src`, `m_j · Q d_src`).
    /// In point order, so the sums are deterministic.
    pub fn director_force_normals(&self) -> Result<Vec<f64>, ShellError> {
        let per_point = (0..self.points.len())
            .into_par_iter()
            .map(|k| {
                let p = &self.points[k];
                let parts: Vec<ParticleState<f64>> = p
                    .neighbours
                    .iter()
                    .map(|&j| self.particle_state(j))
                    .collect();
                let x = vec![0.0; DOFS_PER_PARTICLE * parts.len()];
                let inc = PointIncrement::new(&parts, &x)?;
                let mut m = vec![Vector3::zeros(); parts.len()];
                for l in 0..self.thickness_rule.len() {
                    let inp = self.layer_input(k, l, &parts);
                    let res = point_residual_with(&inp, &inc)?;
                    let pk = res.kinematics.p;
                    let half_t = inp.thickness * 0.5;
                    let z = half_t * inp.zeta;
                    for (ma, sh) in m.iter_mut().zip(p.shape.iter()) {
                        let f = pk.column(0) * sh.dpsi_test[0] + pk.column(1) * sh.dpsi_test[1];
                        *ma += f * z + pk.column(2) * (half_t * sh.psi);
                    }
                }
                Ok(m.iter().zip(&parts).map(|(ma, st)| ma.dot(&st.d)).collect())
            })
            .collect::<Result<Vec<Vec<f64>>, ShellError>>()?;
        let mut s = vec![0.0; self.n_particles()];
        for (p, vals) in self.points.iter().zip(per_point) {
            for (&j, v) in p.neighbours.iter().zip(vals) {
                s[self.source_of(j)] += v;
            }
        }
        Ok(s)
    }

    /// Commit a converged increment: particle coefficients and directors move, the lamina
    /// vectors of each particle rotate with its director, histories become the trial ones.
    /// Images follow their sources ([`ShellModel::particle_state`]).
    pub fn commit(&mut self, dofs: &[f64], contributions: Vec<LocalContribution>) {
        self.commit_histories(dofs, contributions.into_iter().map(|c| c.history).collect());
    }

    /// [`ShellModel::commit`] with the trial histories given per in-plane point (the layers of
    /// point `k` in `histories[k]`).
    pub fn commit_histories(&mut self, dofs: &[f64], histories: Vec<Vec<PointHistory<f64>>>) {
        for (p, q) in self
            .particles
            .iter_mut()
            .zip(dofs.chunks_exact(DOFS_PER_PARTICLE))
        {
            *p = commit_particle(p, q);
        }
        let nl = self.thickness_rule.len();
        for (k, hs) in histories.into_iter().enumerate() {
            for (l, h) in hs.into_iter().enumerate() {
                self.history[k * nl + l] = h;
            }
        }
    }
}

fn mf(e: MeshfreeError) -> ShellError {
    ShellError::Shape {
        context: "",
        source: e,
    }
}
