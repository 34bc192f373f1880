//! Symmetry planes by image particles (docs/shell-formulation.md §6.1).
//!
//! A symmetry plane lies on a parametric edge of the patch (`u = u_e` or `v = v_e`), with a
//! physical plane through `point` with unit normal `n_s`. The reflection `S = I − 2 n_s n_sᵀ` maps
//! the shell onto itself, and the parametric mirror `u → 2 u_e − u` (or in `v`) is the physical
//! mirror near the edge: `x̄⁰(2u_e − u, v) = S x̄⁰(u, v)`. Every real particle strictly off the edge
//! whose support reaches across it gets an **image particle** at the mirrored parameter
//! coordinates, with the same support. Its state is a fixed linear map of its source:
//! `ū_img = S ū`, `d_img = S d`, `d⁰_img = S d⁰`, `e_img = S e`, and its rotation DOFs are
//! `α_img = det(S) α`, because for any orthogonal `Q`
//! `Q exp([θ]×) v = exp([det(Q) Q θ]×) Q v` (`Q [θ]× Qᵀ = det(Q) [Qθ]×`), so the image rotates its
//! director by `det(Q) Q θ = Σ_β (det(Q) α_β) (Q e_β)`. Two planes meeting at a corner give images
//! of images with `Q = S₂ S₁` (`det Q = +1`), generated here by repeated reflection.
//!
//! The RK functions are built on real and image particles, so the discrete field is exactly
//! mirror-symmetric; the quadrature points stay in the real domain and the global DOFs are those
//! of the real particles only ([`super::model::ShellModel`] maps between them).
//!
//! Particles **on** a symmetry edge are their own images. Their DOFs must be symmetric:
//! `ū·n_s = 0`, and no rotation about `d × n_s`: with the lamina vectors chosen at build time as
//! `e1 = n_s`, `e2 = d × n_s`, that is simply `α2 = 0`, exact for finite rotations (a rotation
//! about `n_s` keeps `d` in the plane and keeps `e1 = n_s`). A particle on two planes has both
//! rotations fixed ([`SymmetryLayout::self_conditions`]).

use crate::geometry::Surface;
use crate::meshfree::Edge;
use nalgebra::{Matrix3, Vector3};
use thiserror::Error;

/// Relative tolerance of the plane checks (against the size of the patch).
const PLANE_TOL: f64 = 1e-9;
/// Relative tolerance for "on the edge" (against the parameter width of the domain).
const EDGE_TOL: f64 = 1e-9;
/// Sample points per edge for the plane checks.
const EDGE_SAMPLES: usize = 33;

/// Errors of the symmetry-plane set-up. Each names the edge and the measured deviation.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum SymmetryError {
    /// The normal is zero or not finite.
    #[error("symmetry plane on edge {edge:?}: normal {normal:?} must be a finite non-zero vector")]
    InvalidNormal {
        /// Edge of the plane.
        edge: Edge,
        /// The given normal.
        normal: [f64; 3],
    },
    /// The plane's point is not finite.
    #[error("symmetry plane on edge {edge:?}: point {point:?} must be finite")]
    InvalidPoint {
        /// Edge of the plane.
        edge: Edge,
        /// The given point.
        point: [f64; 3],
    },
    /// Two planes on one edge.
    #[error("two symmetry planes on edge {edge:?}: expected at most one per edge")]
    DuplicateEdge {
        /// The edge.
        edge: Edge,
    },
    /// The edge does not lie in the plane.
    #[error(
        "symmetry plane on edge {edge:?}: the edge point at (u, v) = {uv:?} is at distance \
         {distance:e} from the plane (tolerance {tolerance:e}): expected the edge to lie in the plane"
    )]
    EdgeOffPlane {
        /// Edge of the plane.
        edge: Edge,
        /// Parameter coordinates of the worst edge point.
        uv: [f64; 2],
        /// Its distance from the plane.
        distance: f64,
        /// The tolerance (relative 1e-9 of the patch size).
        tolerance: f64,
    },
    /// The surface normal on the edge leaves the plane.
    #[error(
        "symmetry plane on edge {edge:?}: the surface normal at (u, v) = {uv:?} has component \
         {deviation:e} along the plane normal (tolerance {tolerance:e}): expected it to lie in the plane"
    )]
    NormalOffPlane {
        /// Edge of the plane.
        edge: Edge,
        /// Parameter coordinates of the worst edge point.
        uv: [f64; 2],
        /// `|n · n_s|`.
        deviation: f64,
        /// The tolerance.
        tolerance: f64,
    },
    /// The parameter lines crossing the edge are not normal to the plane, so the parametric
    /// mirror is not the physical mirror.
    #[error(
        "symmetry plane on edge {edge:?}: the parameter line crossing the edge at (u, v) = {uv:?} \
         makes sin(angle) = {deviation:e} with the plane normal (tolerance {tolerance:e}): the \
         parametric mirror is then not the physical mirror; expected parameter lines normal to \
         the plane"
    )]
    NotMirrorParameterised {
        /// Edge of the plane.
        edge: Edge,
        /// Parameter coordinates of the worst edge point.
        uv: [f64; 2],
        /// `|x,t × n_s| / |x,t|` for the crossing derivative `x,t`.
        deviation: f64,
        /// The tolerance.
        tolerance: f64,
    },
    /// Two planes whose reflections do not commute (not orthogonal) meet at a corner.
    #[error(
        "symmetry planes on edges {a:?} and {b:?} meet at a corner but their reflections do not \
         commute (normals at {angle_deg:.6}°): expected orthogonal planes"
    )]
    NonCommuting {
        /// First edge.
        a: Edge,
        /// Second edge.
        b: Edge,
        /// Angle between the normals in degrees.
        angle_deg: f64,
    },
}

/// A symmetry plane on a parametric edge of the patch.
#[derive(Clone, Debug, PartialEq)]
pub struct SymmetryPlane {
    /// The parametric edge lying in the plane.
    pub edge: Edge,
    /// A point of the plane.
    pub point: Vector3<f64>,
    /// Unit normal `n_s` of the plane.
    pub normal: Vector3<f64>,
    /// A name for errors and reports (default `"symmetry plane on edge <edge>"`).
    pub label: String,
}

impl SymmetryPlane {
    /// A plane through `point` with normal `normal` (normalised here) on `edge`.
    pub fn new(
        edge: Edge,
        point: Vector3<f64>,
        normal: Vector3<f64>,
    ) -> Result<Self, SymmetryError> {
        let len = normal.norm();
        if !(len.is_finite() && len > 0.0) {
            return Err(SymmetryError::InvalidNormal {
                edge,
                normal: normal.into(),
            });
        }
        if !point.iter().all(|v| v.is_finite()) {
            return Err(SymmetryError::InvalidPoint {
                edge,
                point: point.into(),
            });
        }
        Ok(SymmetryPlane {
            edge,
            point,
            normal: normal / len,
            label: format!("symmetry plane on edge {edge:?}"),
        })
    }

    /// With a new label (e.g. the case file's entry).
    pub fn labelled(mut self, label: impl Into<String>) -> Self {
        self.label = label.into();
        self
    }

    /// The reflection `S = I − 2 n_s n_sᵀ`.
    pub fn reflection(&self) -> Matrix3<f64> {
        Matrix3::identity() - self.normal * self.normal.transpose() * 2.0
    }

    /// Check against the surface: the edge lies in the plane, the surface normal along the
    /// edge lies in the plane, and the parameter lines crossing the edge are normal to it (so
    /// that the parametric mirror is the physical one), at 33 points along the edge.
    pub fn validate(&self, surface: &Surface<f64>) -> Result<(), SymmetryError> {
        let dom = surface.domain();
        let (axis, c) = edge_coordinate(self.edge, dom);
        let other = 1 - axis;
        let samples: Vec<_> = (0..EDGE_SAMPLES)
            .map(|s| {
                let t = s as f64 / (EDGE_SAMPLES - 1) as f64;
                let mut uv = [0.0; 2];
                uv[axis] = c;
                uv[other] = dom[other][0] + t * (dom[other][1] - dom[other][0]);
                (uv, surface.eval(uv[0], uv[1]))
            })
            .collect();
        let size = samples
            .iter()
            .map(|(_, s)| s.xu.norm() + s.xv.norm())
            .fold(0.0f64, f64::max);
        let n = self.normal;
        // Worst point of a deviation measure (NaN counts as infinitely bad).
        let worst = |f: &dyn Fn(&crate::geometry::SurfaceDerivs<f64>) -> f64| {
            samples
                .iter()
                .map(|(uv, s)| {
                    let d = f(s);
                    (*uv, if d.is_nan() { f64::INFINITY } else { d })
                })
                .fold(([0.0; 2], 0.0f64), |a, b| if b.1 > a.1 { b } else { a })
        };
        let tolerance = PLANE_TOL * size;
        let (uv, distance) = worst(&|s| (s.x - self.point).dot(&n).abs());
        if distance > tolerance {
            return Err(SymmetryError::EdgeOffPlane {
                edge: self.edge,
                uv,
                distance,
                tolerance,
            });
        }
        let (uv, deviation) = worst(&|s| {
            let c = s.xu.cross(&s.xv);
            (c.dot(&n) / c.norm()).abs()
        });
        if deviation > PLANE_TOL {
            return Err(SymmetryError::NormalOffPlane {
                edge: self.edge,
                uv,
                deviation,
                tolerance: PLANE_TOL,
            });
        }
        let (uv, deviation) = worst(&|s| {
            let xt = if axis == 0 { s.xu } else { s.xv };
            xt.cross(&n).norm() / xt.norm()
        });
        if deviation > PLANE_TOL {
            return Err(SymmetryError::NotMirrorParameterised {
                edge: self.edge,
                uv,
                deviation,
                tolerance: PLANE_TOL,
            });
        }
        Ok(())
    }
}

/// `(axis, coordinate)` of a parametric edge of the domain `[[u0, u1], [v0, v1]]`.
pub fn edge_coordinate(edge: Edge, domain: [[f64; 2]; 2]) -> (usize, f64) {
    match edge {
        Edge::UMin => (0, domain[0][0]),
        Edge::UMax => (0, domain[0][1]),
        Edge::VMin => (1, domain[1][0]),
        Edge::VMax => (1, domain[1][1]),
    }
}

/// Whether parameter point `uv` lies on `edge` (within 1e-9 of the domain width).
pub fn on_edge(uv: [f64; 2], edge: Edge, domain: [[f64; 2]; 2]) -> bool {
    let (axis, c) = edge_coordinate(edge, domain);
    (uv[axis] - c).abs() <= EDGE_TOL * (domain[axis][1] - domain[axis][0])
}

/// An image particle: a mirror of real particle `source` (a shape-function particle without
/// DOFs of its own).
#[derive(Clone, Debug, PartialEq)]
pub struct ImageParticle {
    /// The real particle it mirrors.
    pub source: usize,
    /// Parameter coordinates (outside the domain).
    pub uv: [f64; 2],
    /// Support half-widths (those of the source).
    pub support: [f64; 2],
    /// The orthogonal map `Q` (a reflection, or a product of two for a corner image):
    /// `ū_img = Q ū`, `d_img = Q d`, `e_img = Q e`.
    pub map: Matrix3<f64>,
    /// `det Q = ±1`: `α_img = det(Q) α`.
    pub det: f64,
    /// Planes reflected across, in order (indices into [`SymmetryLayout::planes`]).
    pub planes: Vec<usize>,
}

/// The symmetry conditions on one real particle lying on one or two symmetry edges.
#[derive(Clone, Debug, PartialEq)]
pub struct SelfCondition {
    /// The particle.
    pub particle: usize,
    /// Normals `n_s` of the planes it lies on: `ū·n_s = 0` for each.
    pub normals: Vec<Vector3<f64>>,
    /// Rotation DOFs held at zero (1 = `α2` on one plane; 0 and 1 on two planes).
    pub rotations: Vec<usize>,
}

/// Planes, image particles and the particles lying on the planes.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct SymmetryLayout {
    /// The symmetry planes.
    pub planes: Vec<SymmetryPlane>,
    /// Image particles; shape-function particle `n_real + k` is `images[k]`.
    pub images: Vec<ImageParticle>,
    /// For every real particle, the planes (indices) whose edge it lies on.
    pub on_planes: Vec<Vec<usize>>,
}

impl SymmetryLayout {
    /// Build the images of the real particles `particle_uv` (supports `supports`) for `planes`
    /// on the parameter domain `domain`: every particle (real or image) strictly off a plane's
    /// edge is reflected across it, and the reflection is kept if its support overlaps the
    /// domain; repeated until no new image appears (corner images of two planes).
    pub fn new(
        particle_uv: &[[f64; 2]],
        supports: &[[f64; 2]],
        domain: [[f64; 2]; 2],
        planes: Vec<SymmetryPlane>,
    ) -> Result<Self, SymmetryError> {
        for (a, p) in planes.iter().enumerate() {
            if planes[..a].iter().any(|q| q.edge == p.edge) {
                return Err(SymmetryError::DuplicateEdge { edge: p.edge });
            }
        }
        let on = |uv: [f64; 2]| -> Vec<usize> {
            (0..planes.len())
                .filter(|&p| on_edge(uv, planes[p].edge, domain))
                .collect()
        };
        let on_planes: Vec<Vec<usize>> = particle_uv.iter().map(|&uv| on(uv)).collect();
        let reflections: Vec<Matrix3<f64>> = planes.iter().map(|p| p.reflection()).collect();
        let width = [domain[0][1] - domain[0][0], domain[1][1] - domain[1][0]];
        let same_pos = |a: [f64; 2], b: [f64; 2]| {
            (a[0] - b[0]).abs() <= EDGE_TOL * width[0] && (a[1] - b[1]).abs() <= EDGE_TOL * width[1]
        };
        let overlaps = |uv: [f64; 2], a: [f64; 2]| {
            (0..2).all(|k| {
                let d = (domain[k][0] - uv[k]).max(uv[k] - domain[k][1]).max(0.0);
                d < a[k]
            })
        };
        // Work list: (uv, support, source, map, planes reflected across).
        type Item = ([f64; 2], [f64; 2], usize, Matrix3<f64>, Vec<usize>);
        let mut all: Vec<Item> = particle_uv
            .iter()
            .zip(supports)
            .enumerate()
            .map(|(i, (&uv, &a))| (uv, a, i, Matrix3::identity(), Vec::new()))
            .collect();
        let mut next = 0;
        while next < all.len() {
            let (uv, a, src, map, seq) = all[next].clone();
            next += 1;
            for (p, plane) in planes.iter().enumerate() {
                if on_edge(uv, plane.edge, domain) {
                    continue; // its own image across this plane
                }
                let (axis, c) = edge_coordinate(plane.edge, domain);
                let mut m = uv;
                m[axis] = 2.0 * c - uv[axis];
                if !overlaps(m, a) {
                    continue;
                }
                let qm = reflections[p] * map;
                if let Some(k) = all.iter().position(|it| same_pos(it.0, m)) {
                    let it = &all[k];
                    if it.2 != src || (it.3 - qm).abs().max() > 1e-12 {
                        let other = it.4.last().or(seq.last()).copied().unwrap_or(p);
                        let (na, nb) = (plane.normal, planes[other].normal);
                        return Err(SymmetryError::NonCommuting {
                            a: plane.edge,
                            b: planes[other].edge,
                            angle_deg: na.dot(&nb).clamp(-1.0, 1.0).acos().to_degrees(),
                        });
                    }
                    continue;
                }
                let mut s = seq.clone();
                s.push(p);
                all.push((m, a, src, qm, s));
            }
        }
        let images = all
            .into_iter()
            .skip(particle_uv.len())
            .map(|(uv, support, source, map, planes)| ImageParticle {
                source,
                uv,
                support,
                det: map.determinant().signum(),
                map,
                planes,
            })
            .collect();
        Ok(SymmetryLayout {
            planes,
            images,
            on_planes,
        })
    }

    /// The symmetry conditions of the real particles lying on planes: `ū·n_s = 0` per plane,
    /// `α2 = 0` on one plane (the lamina vectors are `e1 = n_s`, `e2 = d × n_s` there), both
    /// rotations on two planes.
    pub fn self_conditions(&self) -> Vec<SelfCondition> {
        self.on_planes
            .iter()
            .enumerate()
            .filter(|(_, p)| !p.is_empty())
            .map(|(i, p)| SelfCondition {
                particle: i,
                normals: p.iter().map(|&k| self.planes[k].normal).collect(),
                rotations: if p.len() == 1 { vec![1] } else { vec![0, 1] },
            })
            .collect()
    }

    /// The unit normal to use as the first lamina vector of real particle `i` (the normal of
    /// the first plane it lies on), if any.
    pub fn lamina_hint(&self, i: usize) -> Option<Vector3<f64>> {
        self.on_planes[i].first().map(|&p| self.planes[p].normal)
    }
}
