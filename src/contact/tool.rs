//! Rigid tools: a parametric surface, the side that is solid, and a rigid motion driven by the
//! pseudo-time `t` (the solver's load factor).
//!
//! The moved surface is `x^c(ξ; t) = c + R(t) (X(ξ) − c) + a(t)` (`X` the surface as built, `c`
//! the pivot, `R(t)` the rotation of the rotation vector `θ(t)`, `a(t)` the translation). Its
//! tangents are `x^c,α = R X,α` and the contact normal of eq (66) is `n = s R n_X` with
//! `s = ±1` from [`Side`], so that `n` points out of the solid tool.
//!
//! A path may carry an **orientation** `R_φ` of the tool as built (a rotation about the pivot
//! applied before the motion, [`ToolPath::rotated`]: the tool-rotation design variable of
//! `crate::sensitivity::DesignKind::ToolRotation`): then `R(t)` above stands for
//! `R(θ(t)) R_φ`, so `x^c = c + R(θ(t)) R_φ (X − c) + a(t)`. The orientation is kept as its
//! own factor (never folded into the keys' rotation vectors, which are interpolated), so a
//! rotated tool is represented exactly.

use super::{invalid, ContactError};
use crate::geometry::{GeometryError, Surface, SurfaceDerivs};
use crate::kinematics::rotation::rodrigues_coefficients;
use crate::scalar::Real;
use nalgebra::{Matrix3, Vector3};

type V3<T> = Vector3<T>;

/// Which side of the surface is solid, relative to the surface normal of eq (66)
/// (`x_u × x_v / |…|`, documented on each patch type).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The solid lies behind the surface: its outward normal is `+n_X` (e.g. a cylinder or sphere
    /// punch with the patch's outward normal, or a die whose rectangle normal points up at the
    /// sheet).
    Positive,
    /// The solid lies in front: its outward normal is `−n_X`.
    Negative,
}

impl Side {
    /// `s = +1` or `−1`.
    pub fn sign(self) -> f64 {
        match self {
            Side::Positive => 1.0,
            Side::Negative => -1.0,
        }
    }
}

/// One entry of a [`ToolPath`] table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathKey {
    /// Pseudo-time (load factor).
    pub t: f64,
    /// Translation `a` at `t`.
    pub translation: [f64; 3],
    /// Rotation vector `θ` at `t` (axis times angle in radians, about the pivot).
    pub rotation: [f64; 3],
}

/// Rigid motion as a piecewise-linear table of `(t, a, θ)` about a fixed pivot `c`.
///
/// Between keys the translation and the rotation *vector* are interpolated linearly (for a
/// rotation about a fixed axis that is the exact uniform rotation; otherwise a smooth path that
/// passes through every key). Before the first key and after the last the tool rests at that key.
#[derive(Clone, Debug, PartialEq)]
pub struct ToolPath {
    pivot: [f64; 3],
    keys: Vec<PathKey>,
    /// Orientation `R_φ` of the tool as built, applied about the pivot before the motion
    /// (identity unless [`ToolPath::rotated`]).
    orientation: Matrix3<f64>,
}

impl ToolPath {
    /// A validated path: at least one key, finite numbers, strictly increasing times.
    pub fn new(pivot: [f64; 3], keys: Vec<PathKey>) -> Result<Self, ContactError> {
        for (c, v) in pivot.iter().enumerate() {
            if !v.is_finite() {
                return Err(invalid(format!("path.pivot[{c}]"), v, "a finite number"));
            }
        }
        if keys.is_empty() {
            return Err(invalid("path.keys", "[]", "at least one key"));
        }
        for (i, k) in keys.iter().enumerate() {
            if !k.t.is_finite() {
                return Err(invalid(format!("path.keys[{i}].t"), k.t, "a finite number"));
            }
            for (name, v) in [("translation", k.translation), ("rotation", k.rotation)] {
                for (c, x) in v.iter().enumerate() {
                    if !x.is_finite() {
                        return Err(invalid(
                            format!("path.keys[{i}].{name}[{c}]"),
                            x,
                            "a finite number",
                        ));
                    }
                }
            }
            if i > 0 && k.t <= keys[i - 1].t {
                return Err(invalid(
                    format!("path.keys[{i}].t"),
                    k.t,
                    &format!(
                        "a time greater than path.keys[{}].t = {}",
                        i - 1,
                        keys[i - 1].t
                    ),
                ));
            }
        }
        Ok(ToolPath {
            pivot,
            keys,
            orientation: Matrix3::identity(),
        })
    }

    /// A tool at rest at its built position.
    pub fn fixed() -> Self {
        ToolPath {
            pivot: [0.0; 3],
            keys: vec![PathKey {
                t: 0.0,
                translation: [0.0; 3],
                rotation: [0.0; 3],
            }],
            orientation: Matrix3::identity(),
        }
    }

    /// A pure translation growing linearly from `0` at `t = 0` to `stroke` at `t = 1`.
    pub fn linear_stroke(stroke: [f64; 3]) -> Result<Self, ContactError> {
        Self::new(
            [0.0; 3],
            vec![
                PathKey {
                    t: 0.0,
                    translation: [0.0; 3],
                    rotation: [0.0; 3],
                },
                PathKey {
                    t: 1.0,
                    translation: stroke,
                    rotation: [0.0; 3],
                },
            ],
        )
    }

    /// The pivot `c`.
    pub fn pivot(&self) -> [f64; 3] {
        self.pivot
    }

    /// The keys.
    pub fn keys(&self) -> &[PathKey] {
        &self.keys
    }

    /// Translation `a(t)` and rotation vector `θ(t)` (linear between keys, constant outside).
    pub fn position(&self, t: f64) -> ([f64; 3], [f64; 3]) {
        let k = &self.keys;
        let first = k[0];
        let last = k[k.len() - 1];
        if t.is_nan() || t <= first.t {
            return (first.translation, first.rotation);
        }
        if t >= last.t {
            return (last.translation, last.rotation);
        }
        let i = k.partition_point(|p| p.t <= t); // k[i-1].t <= t < k[i].t
        let (p, q) = (k[i - 1], k[i]);
        let s = (t - p.t) / (q.t - p.t);
        let lerp = |a: [f64; 3], b: [f64; 3]| std::array::from_fn(|c| a[c] + (b[c] - a[c]) * s);
        (
            lerp(p.translation, q.translation),
            lerp(p.rotation, q.rotation),
        )
    }

    /// The same path translated by `offset` at every key (the pivot moves along, so a rotating
    /// tool turns about its moved pivot): the whole motion shifted by `offset`, the tool-position
    /// design variable of `crate::sensitivity::DesignKind::Tool`.
    pub fn translated(&self, offset: [f64; 3]) -> Result<Self, ContactError> {
        let keys = self
            .keys
            .iter()
            .map(|k| PathKey {
                t: k.t,
                translation: std::array::from_fn(|c| k.translation[c] + offset[c]),
                rotation: k.rotation,
            })
            .collect();
        let mut p = ToolPath::new(self.pivot, keys)?;
        p.orientation = self.orientation;
        Ok(p)
    }

    /// The same path with the tool as built turned by the rotation vector `phi` (radians,
    /// axis times angle, global axes) about the pivot `c`, before its motion:
    /// `x^c = c + R(θ(t)) R_φ R₀ (X − c) + a(t)` with `R₀` this path's orientation (identity
    /// for a path from [`ToolPath::new`]). The orientation is composed exactly (a matrix, not
    /// an interpolated rotation vector): the tool-rotation design variable of
    /// `crate::sensitivity::DesignKind::ToolRotation`.
    pub fn rotated(&self, phi: [f64; 3]) -> Result<Self, ContactError> {
        for (c, v) in phi.iter().enumerate() {
            if !v.is_finite() {
                return Err(invalid(
                    format!("path.orientation[{c}]"),
                    v,
                    "a finite rotation (radians)",
                ));
            }
        }
        let r = RigidMotion::new(V3::zeros(), V3::from(phi), V3::zeros()).rotation;
        Ok(ToolPath {
            pivot: self.pivot,
            keys: self.keys.clone(),
            orientation: r * self.orientation,
        })
    }

    /// The orientation `R_φ` of the tool as built (identity unless [`ToolPath::rotated`]).
    pub fn orientation(&self) -> Matrix3<f64> {
        self.orientation
    }

    /// The rotation `R(θ(t))` of the path alone (without the orientation): the frame in which a
    /// design rotation `φ̇` of the tool as built acts at `t` (`Ω = [R(θ(t)) φ̇]×`,
    /// `crate::shell::contact_sensitivity`).
    pub fn path_rotation(&self, t: f64) -> Matrix3<f64> {
        let (_, theta) = self.position(t);
        RigidMotion::new(V3::zeros(), V3::from(theta), V3::zeros()).rotation
    }

    /// The rigid motion at pseudo-time `t`: pivot `c`, rotation `R(θ(t)) R_φ`, translation
    /// `a(t)`.
    pub fn motion(&self, t: f64) -> RigidMotion<f64> {
        let (a, theta) = self.position(t);
        let mut m = RigidMotion::new(V3::from(self.pivot), V3::from(theta), V3::from(a));
        m.rotation *= self.orientation;
        m
    }

    /// The rigid motion at pseudo-time `t` with a further design rotation `phi` of the tool as
    /// built and a design translation `offset`, in scalar `T` (the dual-number reference seeds
    /// them): pivot `c`, rotation `R(θ(t)) R(φ) R_φ₀`, translation `a(t) + offset`. With
    /// `phi = 0` and `offset = 0` it equals [`ToolPath::motion`] exactly (`R(0) = I`).
    pub fn motion_with<T: Real>(&self, t: f64, phi: &V3<T>, offset: &V3<T>) -> RigidMotion<T> {
        let (a, theta) = self.position(t);
        let path = RigidMotion::new(V3::from(self.pivot), V3::from(theta), V3::from(a));
        let design = RigidMotion::new(V3::zeros(), *phi, V3::zeros()).rotation;
        RigidMotion {
            pivot: path.pivot.map(T::cst),
            rotation: path.rotation.map(T::cst) * design * self.orientation.map(T::cst),
            translation: path.translation.map(T::cst) + offset,
        }
    }
}

/// A rigid motion `X ↦ c + R (X − c) + a`, generic so that the translation, the rotation or the
/// pivot can carry a design derivative (tool position as a design variable, eq 76's `V^c`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidMotion<T> {
    /// Pivot `c`.
    pub pivot: V3<T>,
    /// Rotation `R`.
    pub rotation: Matrix3<T>,
    /// Translation `a`.
    pub translation: V3<T>,
}

impl<T: Real> RigidMotion<T> {
    /// From the pivot, a rotation vector `θ` (Rodrigues: `R = I + f1 [θ]× + f2 [θ]×²`) and the
    /// translation.
    pub fn new(pivot: V3<T>, theta: V3<T>, translation: V3<T>) -> Self {
        let (f1, f2) = rodrigues_coefficients(theta.dot(&theta));
        let k = theta.cross_matrix();
        let rotation = Matrix3::identity() + k * f1 + k * k * f2;
        RigidMotion {
            pivot,
            rotation,
            translation,
        }
    }

    /// The identity.
    pub fn identity() -> Self {
        RigidMotion {
            pivot: V3::zeros(),
            rotation: Matrix3::identity(),
            translation: V3::zeros(),
        }
    }

    /// `c + R (X − c) + a`.
    pub fn apply(&self, x: &V3<T>) -> V3<T> {
        self.pivot + self.rotation * (x - self.pivot) + self.translation
    }

    /// The inverse map to the tool's built position: `c + Rᵀ (x − a − c)`.
    pub fn to_reference(&self, x: &V3<T>) -> V3<T> {
        self.pivot + self.rotation.transpose() * (x - self.translation - self.pivot)
    }

    /// Real parts.
    pub fn value(&self) -> RigidMotion<f64> {
        RigidMotion {
            pivot: self.pivot.map(|v| v.value()),
            rotation: self.rotation.map(|v| v.value()),
            translation: self.translation.map(|v| v.value()),
        }
    }
}

impl RigidMotion<f64> {
    /// As constants of scalar `T`.
    pub fn lift<T: Real>(&self) -> RigidMotion<T> {
        RigidMotion {
            pivot: self.pivot.map(T::cst),
            rotation: self.rotation.map(T::cst),
            translation: self.translation.map(T::cst),
        }
    }
}

/// Samples `X(ξ_ij)` of a surface on a regular grid of its parameter box, in the built position:
/// the initial guess of the projection (the nearest sample), computed once per tool.
#[derive(Clone, Debug, PartialEq)]
pub struct CoarseGrid {
    /// `(ξ, X(ξ))`.
    pub samples: Vec<([f64; 2], V3<f64>)>,
    /// Diagonal of the samples' bounding box (the tool's length scale).
    pub size: f64,
}

impl CoarseGrid {
    /// `n × n` samples (`n ≥ 2`) including the boundary; every sample must have a normal
    /// (a regular parametrisation: no pole, no collapsed edge).
    pub fn new(surface: &Surface<f64>, n: usize) -> Result<Self, GeometryError> {
        let d = surface.domain();
        let n = n.max(2);
        let mut samples = Vec::with_capacity(n * n);
        let (mut lo, mut hi) = (V3::repeat(f64::INFINITY), V3::repeat(f64::NEG_INFINITY));
        for i in 0..n {
            for j in 0..n {
                let u = d[0][0] + (d[0][1] - d[0][0]) * i as f64 / (n - 1) as f64;
                let v = d[1][0] + (d[1][1] - d[1][0]) * j as f64 / (n - 1) as f64;
                let s = surface.eval(u, v);
                s.normal()?;
                lo = lo.inf(&s.x);
                hi = hi.sup(&s.x);
                samples.push(([u, v], s.x));
            }
        }
        Ok(CoarseGrid {
            samples,
            size: (hi - lo).norm(),
        })
    }

    /// The sample nearest to `x` (in the built position).
    pub fn nearest(&self, x: &V3<f64>) -> [f64; 2] {
        let mut best = (f64::INFINITY, self.samples[0].0);
        for (xi, p) in &self.samples {
            let d = (p - x).norm_squared();
            if d < best.0 {
                best = (d, *xi);
            }
        }
        best.1
    }
}

/// Samples per parameter direction of a tool's [`CoarseGrid`] (17 × 17 = 289 points: on the
/// analytic patches at most 1/16 of the range apart, so the nearest sample lies in the basin of
/// the Newton projection for curvatures up to ~16 per tool length).
pub const COARSE_GRID_SAMPLES: usize = 17;

/// A rigid tool (die, punch, blank holder).
#[derive(Clone, Debug, PartialEq)]
pub struct RigidTool {
    /// Name (for reports and errors).
    pub name: String,
    /// The surface in its built position.
    pub surface: Surface<f64>,
    /// Which side is solid.
    pub side: Side,
    /// Its motion.
    pub path: ToolPath,
    /// Coarse samples for the projection's initial guess.
    pub grid: CoarseGrid,
}

impl RigidTool {
    /// A validated tool: a valid surface with a normal at every sample of its coarse grid and a
    /// non-empty name.
    pub fn new(
        name: impl Into<String>,
        surface: Surface<f64>,
        side: Side,
        path: ToolPath,
    ) -> Result<Self, ContactError> {
        let name = name.into();
        if name.trim().is_empty() {
            return Err(invalid("tool.name", &name, "a non-empty name"));
        }
        let geom = |e| ContactError::Geometry {
            tool: name.clone(),
            source: e,
        };
        surface.validate().map_err(geom)?;
        let grid = CoarseGrid::new(&surface, COARSE_GRID_SAMPLES).map_err(geom)?;
        if !(grid.size.is_finite() && grid.size > 0.0) {
            return Err(invalid(
                format!("tool `{name}`.surface extent"),
                grid.size,
                "a surface of positive finite size",
            ));
        }
        Ok(RigidTool {
            name,
            surface,
            side,
            path,
            grid,
        })
    }

    /// The rigid motion at pseudo-time `t`.
    pub fn motion(&self, t: f64) -> RigidMotion<f64> {
        self.path.motion(t)
    }

    /// The same tool (name, side, path) with design parameters of its surface moved:
    /// `offsets` lists `(index in Surface::design_parameters, offset added)`. The surface is
    /// rebuilt and validated and the coarse grid recomputed ([`RigidTool::new`]), so a
    /// perturbed tool that is not a valid tool is an error naming the parameter, never a
    /// panic: the tool-shape design variable of `crate::sensitivity::DesignKind::ToolShape`.
    pub fn reshaped(&self, offsets: &[(usize, f64)]) -> Result<Self, ContactError> {
        let mut p = self.surface.parameter_values();
        let names = self.surface.parameter_names();
        let key = |k: usize| {
            format!(
                "tool `{}`.shape.{}",
                self.name,
                names.get(k).map_or("?", |n| n.as_str())
            )
        };
        for &(k, delta) in offsets {
            let count = p.len();
            let Some(slot) = p.get_mut(k) else {
                return Err(invalid(
                    format!("tool `{}` surface parameter index", self.name),
                    k,
                    &format!(
                        "an index below {count} (the {} surface's parameters: {})",
                        self.surface.kind(),
                        names.join(", ")
                    ),
                ));
            };
            if !delta.is_finite() {
                return Err(invalid(key(k), delta, "a finite offset"));
            }
            *slot += delta;
        }
        let described = || {
            offsets
                .iter()
                .map(|&(k, d)| format!("{} + {d:e}", key(k)))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let surface = self
            .surface
            .with_design_parameters::<f64>(&p)
            .map_err(|e| {
                invalid(
                    described(),
                    e.to_string(),
                    "a valid tool surface after the design change",
                )
            })?;
        RigidTool::new(self.name.clone(), surface, self.side, self.path.clone()).map_err(|e| {
            invalid(
                described(),
                e.to_string(),
                "a valid tool after the design change",
            )
        })
    }

    /// The design velocity of the tool's surface parameter `parameter` at the surface point
    /// `ξ` and pseudo-time `t`, moved with the tool: `V^c = R ∂X/∂p` and
    /// `V^c,α = R ∂X,α/∂p` at fixed `ξ` (eq 76; `R` the motion's rotation,
    /// [`crate::geometry::Surface::design_velocity`]).
    pub fn shape_velocity(
        &self,
        parameter: usize,
        xi: [f64; 2],
        t: f64,
    ) -> Result<(V3<f64>, [V3<f64>; 2]), GeometryError> {
        let d = self.surface.design_velocity(parameter, xi[0], xi[1])?;
        let r = self.motion(t).rotation;
        Ok((r * d.x, [r * d.xu, r * d.xv]))
    }

    /// The moved surface point and its derivatives at `ξ` and pseudo-time `t`:
    /// `x^c = c + R (X − c) + a`, `x^c,α = R X,α`, `x^c,αβ = R X,αβ`.
    pub fn moved(&self, xi: [f64; 2], t: f64) -> SurfaceDerivs<f64> {
        moved_derivs(&self.surface.eval(xi[0], xi[1]), &self.motion(t))
    }
}

/// A surface point and its derivatives moved rigidly.
pub fn moved_derivs<T: Real>(s: &SurfaceDerivs<T>, m: &RigidMotion<T>) -> SurfaceDerivs<T> {
    let r = &m.rotation;
    SurfaceDerivs {
        x: m.apply(&s.x),
        xu: r * s.xu,
        xv: r * s.xv,
        xuu: r * s.xuu,
        xuv: r * s.xuv,
        xvv: r * s.xvv,
    }
}
