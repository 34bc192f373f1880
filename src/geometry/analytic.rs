//! Exact analytic patches, generic over the scalar in their parameters and in `(u, v)`.
//!
//! All use normalised parameters `(u, v) ∈ [0, 1]²` mapped linearly onto their radius, angle and
//! length ranges, and closed-form first and second derivatives. Angles are in radians.

use super::{
    check_finite, check_not_parallel, check_range, check_vector, orthonormal, push_vec_names,
};
use super::{GeometryError, SurfaceDerivs};
use crate::scalar::Real;
use nalgebra::Vector3;
use std::f64::consts::{FRAC_PI_2, TAU};

pub(crate) const N_RECTANGLE: usize = 9;
pub(crate) const N_ANNULUS: usize = 13;
pub(crate) const N_CYLINDER: usize = 14;
pub(crate) const N_SPHERE: usize = 8;

fn v3<U: Real>(p: &[U]) -> Vector3<U> {
    Vector3::new(p[0], p[1], p[2])
}

fn lerp<T: Real>(range: [T; 2], t: T) -> (T, T) {
    let d = range[1] - range[0];
    (range[0] + d * t, d)
}

/// Flat parallelogram `x = origin + u edge_u + v edge_v`, `(u, v) ∈ [0, 1]²`.
///
/// Normal (eq 66): `edge_u × edge_v / ‖edge_u × edge_v‖`.
/// Design parameters: `origin.{x,y,z}`, `edge_u.{x,y,z}`, `edge_v.{x,y,z}`.
#[derive(Clone, Debug, PartialEq)]
pub struct Rectangle<T> {
    /// Corner at `(u, v) = (0, 0)`.
    pub origin: Vector3<T>,
    /// Edge from `(0, 0)` to `(1, 0)`.
    pub edge_u: Vector3<T>,
    /// Edge from `(0, 0)` to `(0, 1)`; not parallel to `edge_u`.
    pub edge_v: Vector3<T>,
}

impl<T: Real> Rectangle<T> {
    /// Validated constructor.
    pub fn new(
        origin: Vector3<T>,
        edge_u: Vector3<T>,
        edge_v: Vector3<T>,
    ) -> Result<Self, GeometryError> {
        let s = Rectangle {
            origin,
            edge_u,
            edge_v,
        };
        s.validate()?;
        Ok(s)
    }

    /// Finite fields, non-zero and non-parallel edges.
    pub fn validate(&self) -> Result<(), GeometryError> {
        check_vector("origin", &self.origin, false)?;
        check_vector("edge_u", &self.edge_u, true)?;
        check_vector("edge_v", &self.edge_v, true)?;
        check_not_parallel("edge_v", &self.edge_v, "edge_u", &self.edge_u)
    }

    /// Position and derivatives at `(u, v)`.
    pub fn eval(&self, u: T, v: T) -> SurfaceDerivs<T> {
        let z = Vector3::zeros();
        SurfaceDerivs {
            x: self.origin + self.edge_u * u + self.edge_v * v,
            xu: self.edge_u,
            xv: self.edge_v,
            xuu: z,
            xuv: z,
            xvv: z,
        }
    }

    pub(crate) fn scalars(&self) -> Vec<T> {
        [self.origin, self.edge_u, self.edge_v]
            .iter()
            .flat_map(|v| v.iter().copied())
            .collect()
    }

    pub(crate) fn names() -> Vec<String> {
        let mut n = Vec::with_capacity(N_RECTANGLE);
        for f in ["origin", "edge_u", "edge_v"] {
            push_vec_names(&mut n, f);
        }
        n
    }

    pub(crate) fn from_scalars<U: Real>(p: &[U]) -> Rectangle<U> {
        Rectangle {
            origin: v3(&p[0..3]),
            edge_u: v3(&p[3..6]),
            edge_v: v3(&p[6..9]),
        }
    }
}

/// Sector of a flat annulus: `x = centre + r (cos θ e₁ + sin θ e₂)` with
/// `r = r_in + u (r_out − r_in)`, `θ = θ₀ + v (θ₁ − θ₀)`, `(u, v) ∈ [0, 1]²`.
///
/// `e₁` is the unit part of `reference` orthogonal to `normal`, `e₂ = n̂ × e₁`; the normal of
/// eq (66) is `+normal/‖normal‖`. `inner_radius = 0` (a disc sector) is allowed; the normal is then
/// undefined at `u = 0`.
/// Design parameters: `centre.{x,y,z}`, `normal.{x,y,z}`, `reference.{x,y,z}`, `inner_radius`,
/// `outer_radius`, `angle_start`, `angle_end`.
#[derive(Clone, Debug, PartialEq)]
pub struct AnnulusSector<T> {
    /// Centre of the circles.
    pub centre: Vector3<T>,
    /// Plane normal (any length > 0); the surface normal.
    pub normal: Vector3<T>,
    /// Direction of `θ = 0` (any length; its component along `normal` is ignored).
    pub reference: Vector3<T>,
    /// Inner radius ≥ 0 (at `u = 0`).
    pub inner_radius: T,
    /// Outer radius > inner radius (at `u = 1`).
    pub outer_radius: T,
    /// `[θ₀, θ₁]` in radians, `θ₀ < θ₁ ≤ θ₀ + 2π`.
    pub angle: [T; 2],
}

impl<T: Real> AnnulusSector<T> {
    /// Validated constructor.
    pub fn new(
        centre: Vector3<T>,
        normal: Vector3<T>,
        reference: Vector3<T>,
        inner_radius: T,
        outer_radius: T,
        angle: [T; 2],
    ) -> Result<Self, GeometryError> {
        let s = AnnulusSector {
            centre,
            normal,
            reference,
            inner_radius,
            outer_radius,
            angle,
        };
        s.validate()?;
        Ok(s)
    }

    /// Finite fields, `0 ≤ r_in < r_out`, non-empty angle range of at most 2π, `reference` not
    /// parallel to `normal`.
    pub fn validate(&self) -> Result<(), GeometryError> {
        check_vector("centre", &self.centre, false)?;
        check_vector("normal", &self.normal, true)?;
        check_vector("reference", &self.reference, true)?;
        check_not_parallel("reference", &self.reference, "normal", &self.normal)?;
        let (ri, ro) = (self.inner_radius.value(), self.outer_radius.value());
        check_finite("inner_radius", ri)?;
        check_finite("outer_radius", ro)?;
        if ri < 0.0 {
            return Err(GeometryError::InvalidRadius {
                field: "inner_radius".into(),
                value: ri,
                expected: "a radius ≥ 0".into(),
            });
        }
        if ro <= ri {
            return Err(GeometryError::InvalidRadius {
                field: "outer_radius".into(),
                value: ro,
                expected: format!("a radius > inner_radius = {ri}"),
            });
        }
        check_range(
            "angle",
            self.angle[0].value(),
            self.angle[1].value(),
            None,
            Some(TAU),
        )
    }

    /// Position and derivatives at `(u, v)`.
    pub fn eval(&self, u: T, v: T) -> SurfaceDerivs<T> {
        let n = self.normal / self.normal.norm();
        let e1 = orthonormal(&n, &self.reference);
        let e2 = n.cross(&e1);
        let (r, dr) = lerp([self.inner_radius, self.outer_radius], u);
        let (th, dth) = lerp(self.angle, v);
        let (s, c) = (th.sin(), th.cos());
        let rho = e1 * c + e2 * s; // radial unit vector
        let tau = e2 * c - e1 * s; // ∂ρ/∂θ
        SurfaceDerivs {
            x: self.centre + rho * r,
            xu: rho * dr,
            xv: tau * (r * dth),
            xuu: Vector3::zeros(),
            xuv: tau * (dr * dth),
            xvv: -rho * (r * dth * dth),
        }
    }

    pub(crate) fn scalars(&self) -> Vec<T> {
        let mut p: Vec<T> = [self.centre, self.normal, self.reference]
            .iter()
            .flat_map(|v| v.iter().copied())
            .collect();
        p.extend([
            self.inner_radius,
            self.outer_radius,
            self.angle[0],
            self.angle[1],
        ]);
        p
    }

    pub(crate) fn names() -> Vec<String> {
        let mut n = Vec::with_capacity(N_ANNULUS);
        for f in ["centre", "normal", "reference"] {
            push_vec_names(&mut n, f);
        }
        n.extend(["inner_radius", "outer_radius", "angle_start", "angle_end"].map(String::from));
        n
    }

    pub(crate) fn from_scalars<U: Real>(p: &[U]) -> AnnulusSector<U> {
        AnnulusSector {
            centre: v3(&p[0..3]),
            normal: v3(&p[3..6]),
            reference: v3(&p[6..9]),
            inner_radius: p[9],
            outer_radius: p[10],
            angle: [p[11], p[12]],
        }
    }
}

/// Sector of a circular cylinder: `x = origin + R (cos θ e₁ + sin θ e₂) + s â` with
/// `θ = θ₀ + u (θ₁ − θ₀)`, `s = s₀ + v (s₁ − s₀)`, `(u, v) ∈ [0, 1]²`.
///
/// `â = axis/‖axis‖`, `e₁` the unit part of `reference` orthogonal to `â`, `e₂ = â × e₁`. With this
/// orientation `x_u × x_v` points radially **outward** (away from the axis).
/// Design parameters: `origin.{x,y,z}`, `axis.{x,y,z}`, `reference.{x,y,z}`, `radius`,
/// `angle_start`, `angle_end`, `length_start`, `length_end`.
#[derive(Clone, Debug, PartialEq)]
pub struct CylinderSector<T> {
    /// A point on the axis (`s = 0`).
    pub origin: Vector3<T>,
    /// Axis direction (any length > 0).
    pub axis: Vector3<T>,
    /// Direction of `θ = 0` (any length; its component along `axis` is ignored).
    pub reference: Vector3<T>,
    /// Radius > 0.
    pub radius: T,
    /// `[θ₀, θ₁]` in radians, `θ₀ < θ₁ ≤ θ₀ + 2π`.
    pub angle: [T; 2],
    /// `[s₀, s₁]` along the unit axis, `s₀ < s₁`.
    pub length: [T; 2],
}

impl<T: Real> CylinderSector<T> {
    /// Validated constructor.
    pub fn new(
        origin: Vector3<T>,
        axis: Vector3<T>,
        reference: Vector3<T>,
        radius: T,
        angle: [T; 2],
        length: [T; 2],
    ) -> Result<Self, GeometryError> {
        let s = CylinderSector {
            origin,
            axis,
            reference,
            radius,
            angle,
            length,
        };
        s.validate()?;
        Ok(s)
    }

    /// Finite fields, `R > 0`, non-empty ranges (angle span at most 2π), `reference` not parallel
    /// to `axis`.
    pub fn validate(&self) -> Result<(), GeometryError> {
        check_vector("origin", &self.origin, false)?;
        check_vector("axis", &self.axis, true)?;
        check_vector("reference", &self.reference, true)?;
        check_not_parallel("reference", &self.reference, "axis", &self.axis)?;
        check_radius(self.radius.value())?;
        check_range(
            "angle",
            self.angle[0].value(),
            self.angle[1].value(),
            None,
            Some(TAU),
        )?;
        check_range(
            "length",
            self.length[0].value(),
            self.length[1].value(),
            None,
            None,
        )
    }

    /// Position and derivatives at `(u, v)`.
    pub fn eval(&self, u: T, v: T) -> SurfaceDerivs<T> {
        let a = self.axis / self.axis.norm();
        let e1 = orthonormal(&a, &self.reference);
        let e2 = a.cross(&e1);
        let (th, dth) = lerp(self.angle, u);
        let (s, ds) = lerp(self.length, v);
        let (sn, cs) = (th.sin(), th.cos());
        let rho = e1 * cs + e2 * sn;
        let tau = e2 * cs - e1 * sn;
        let r = self.radius;
        SurfaceDerivs {
            x: self.origin + rho * r + a * s,
            xu: tau * (r * dth),
            xv: a * ds,
            xuu: -rho * (r * dth * dth),
            xuv: Vector3::zeros(),
            xvv: Vector3::zeros(),
        }
    }

    pub(crate) fn scalars(&self) -> Vec<T> {
        let mut p: Vec<T> = [self.origin, self.axis, self.reference]
            .iter()
            .flat_map(|v| v.iter().copied())
            .collect();
        p.extend([
            self.radius,
            self.angle[0],
            self.angle[1],
            self.length[0],
            self.length[1],
        ]);
        p
    }

    pub(crate) fn names() -> Vec<String> {
        let mut n = Vec::with_capacity(N_CYLINDER);
        for f in ["origin", "axis", "reference"] {
            push_vec_names(&mut n, f);
        }
        n.extend(
            [
                "radius",
                "angle_start",
                "angle_end",
                "length_start",
                "length_end",
            ]
            .map(String::from),
        );
        n
    }

    pub(crate) fn from_scalars<U: Real>(p: &[U]) -> CylinderSector<U> {
        CylinderSector {
            origin: v3(&p[0..3]),
            axis: v3(&p[3..6]),
            reference: v3(&p[6..9]),
            radius: p[9],
            angle: [p[10], p[11]],
            length: [p[12], p[13]],
        }
    }
}

/// Latitude/longitude zone of a sphere with its pole on `+z`:
/// `x = centre + R (cos φ cos λ, cos φ sin λ, sin φ)` with longitude `λ = λ₀ + u (λ₁ − λ₀)` and
/// latitude `φ = φ₀ + v (φ₁ − φ₀)`, `(u, v) ∈ [0, 1]²`.
///
/// Latitude is measured from the equator (`φ = 0`) towards the `+z` pole (`φ = π/2`): the
/// pinched hemisphere with an 18° hole is `latitude = [0°, 72°]` (one quadrant: `longitude =
/// [0°, 90°]`). With `u` along longitude and `v` along latitude, `x_u × x_v` points **outward**
/// (away from the centre). At a pole (`φ = ±π/2`) the parametrisation is singular.
/// Design parameters: `centre.{x,y,z}`, `radius`, `latitude_start`, `latitude_end`,
/// `longitude_start`, `longitude_end`.
#[derive(Clone, Debug, PartialEq)]
pub struct SphereZone<T> {
    /// Centre.
    pub centre: Vector3<T>,
    /// Radius > 0.
    pub radius: T,
    /// `[φ₀, φ₁]` in radians inside `[−π/2, π/2]`, `φ₀ < φ₁`.
    pub latitude: [T; 2],
    /// `[λ₀, λ₁]` in radians, `λ₀ < λ₁ ≤ λ₀ + 2π`.
    pub longitude: [T; 2],
}

impl<T: Real> SphereZone<T> {
    /// Validated constructor.
    pub fn new(
        centre: Vector3<T>,
        radius: T,
        latitude: [T; 2],
        longitude: [T; 2],
    ) -> Result<Self, GeometryError> {
        let s = SphereZone {
            centre,
            radius,
            latitude,
            longitude,
        };
        s.validate()?;
        Ok(s)
    }

    /// Finite fields, `R > 0`, latitude range non-empty inside `[−π/2, π/2]`, longitude range
    /// non-empty of at most 2π.
    pub fn validate(&self) -> Result<(), GeometryError> {
        check_vector("centre", &self.centre, false)?;
        check_radius(self.radius.value())?;
        check_range(
            "latitude",
            self.latitude[0].value(),
            self.latitude[1].value(),
            Some((-FRAC_PI_2, FRAC_PI_2)),
            None,
        )?;
        check_range(
            "longitude",
            self.longitude[0].value(),
            self.longitude[1].value(),
            None,
            Some(TAU),
        )
    }

    /// Position and derivatives at `(u, v)`.
    pub fn eval(&self, u: T, v: T) -> SurfaceDerivs<T> {
        let (lam, dl) = lerp(self.longitude, u);
        let (phi, dp) = lerp(self.latitude, v);
        let (sl, cl) = (lam.sin(), lam.cos());
        let (sp, cp) = (phi.sin(), phi.cos());
        let r = self.radius;
        let zero = T::zero();
        // Unit radial vector and its λ, φ derivatives.
        let rad = Vector3::new(cp * cl, cp * sl, sp);
        let d_lam = Vector3::new(-(cp * sl), cp * cl, zero);
        let d_phi = Vector3::new(-(sp * cl), -(sp * sl), cp);
        let d_lam_lam = Vector3::new(-(cp * cl), -(cp * sl), zero);
        let d_lam_phi = Vector3::new(sp * sl, -(sp * cl), zero);
        SurfaceDerivs {
            x: self.centre + rad * r,
            xu: d_lam * (r * dl),
            xv: d_phi * (r * dp),
            xuu: d_lam_lam * (r * dl * dl),
            xuv: d_lam_phi * (r * dl * dp),
            xvv: -rad * (r * dp * dp),
        }
    }

    pub(crate) fn scalars(&self) -> Vec<T> {
        let mut p: Vec<T> = self.centre.iter().copied().collect();
        p.extend([
            self.radius,
            self.latitude[0],
            self.latitude[1],
            self.longitude[0],
            self.longitude[1],
        ]);
        p
    }

    pub(crate) fn names() -> Vec<String> {
        let mut n = Vec::with_capacity(N_SPHERE);
        push_vec_names(&mut n, "centre");
        n.extend(
            [
                "radius",
                "latitude_start",
                "latitude_end",
                "longitude_start",
                "longitude_end",
            ]
            .map(String::from),
        );
        n
    }

    pub(crate) fn from_scalars<U: Real>(p: &[U]) -> SphereZone<U> {
        SphereZone {
            centre: v3(&p[0..3]),
            radius: p[3],
            latitude: [p[4], p[5]],
            longitude: [p[6], p[7]],
        }
    }
}

fn check_radius(r: f64) -> Result<(), GeometryError> {
    check_finite("radius", r)?;
    if r > 0.0 {
        Ok(())
    } else {
        Err(GeometryError::InvalidRadius {
            field: "radius".into(),
            value: r,
            expected: "a radius > 0".into(),
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Hand-derived design velocities `∂/∂p` of `eval` (x and its first and second parametric
// derivatives at fixed (u, v)), for the paper's design velocity field (eqs 37–43). Every patch
// is differentiated by the product rule through its closed form; `pd` is the direction in the
// space of its design parameters (a unit vector for one parameter).

type V3 = Vector3<f64>;

fn v3f(p: &[f64]) -> V3 {
    V3::new(p[0], p[1], p[2])
}

/// `(v/|v|, ∂(v/|v|))` for a direction `vd` of `v`: `(vd − n (n·vd)) / |v|`.
fn unit_dot(v: &V3, vd: &V3) -> (V3, V3) {
    let len = v.norm();
    let n = v / len;
    (n, (vd - n * n.dot(vd)) / len)
}

/// The unit part of `r` orthogonal to the unit vector `a` ([`orthonormal`]) and its
/// derivative for the directions `ad` of `a` and `rd` of `r`.
fn orthonormal_dot(a: &V3, ad: &V3, r: &V3, rd: &V3) -> (V3, V3) {
    let ra = r.dot(a);
    let w = r - a * ra;
    let wd = rd - ad * ra - a * (rd.dot(a) + r.dot(ad));
    unit_dot(&w, &wd)
}

/// `(ρ, τ, ρ̇, τ̇)` of `ρ = e₁ cos θ + e₂ sin θ`, `τ = ∂ρ/∂θ = e₂ cos θ − e₁ sin θ` for the
/// directions `ė₁, ė₂, θ̇`.
fn polar_dot(e1: &V3, e2: &V3, e1d: &V3, e2d: &V3, th: f64, thd: f64) -> [V3; 4] {
    let (s, c) = th.sin_cos();
    let rho = e1 * c + e2 * s;
    let tau = e2 * c - e1 * s;
    let rhod = e1d * c + e2d * s + tau * thd;
    let taud = e2d * c - e1d * s - rho * thd;
    [rho, tau, rhod, taud]
}

/// `(value, ∂value)` of `lerp(range, t)` and of its span `range[1] − range[0]`.
fn lerp_dot(range: [f64; 2], rd: [f64; 2], t: f64) -> (f64, f64, f64, f64) {
    let d = range[1] - range[0];
    let dd = rd[1] - rd[0];
    (range[0] + d * t, rd[0] + dd * t, d, dd)
}

impl Rectangle<f64> {
    /// `∂/∂p` of [`Rectangle::eval`] in the direction `pd` of the design parameters
    /// (`origin`, `edge_u`, `edge_v`): `ẋ = ȯ + u ė_u + v ė_v`, `ẋ_u = ė_u`, `ẋ_v = ė_v`.
    pub(crate) fn design_velocity(&self, pd: &[f64], u: f64, v: f64) -> SurfaceDerivs<f64> {
        let (od, eud, evd) = (v3f(&pd[0..3]), v3f(&pd[3..6]), v3f(&pd[6..9]));
        let z = V3::zeros();
        SurfaceDerivs {
            x: od + eud * u + evd * v,
            xu: eud,
            xv: evd,
            xuu: z,
            xuv: z,
            xvv: z,
        }
    }
}

impl AnnulusSector<f64> {
    /// `∂/∂p` of [`AnnulusSector::eval`] in the direction `pd` of the design parameters,
    /// by the product rule through `x = c + r ρ(θ)`, `x_u = r' ρ`, `x_v = r θ' τ`,
    /// `x_uv = r' θ' τ`, `x_vv = −r θ'² ρ` (`r' = r_out − r_in`, `θ' = θ₁ − θ₀`), with the
    /// frame `n̂`, `e₁`, `e₂ = n̂ × e₁` differentiated through its normalisations.
    pub(crate) fn design_velocity(&self, pd: &[f64], u: f64, v: f64) -> SurfaceDerivs<f64> {
        let (cd, nd, refd) = (v3f(&pd[0..3]), v3f(&pd[3..6]), v3f(&pd[6..9]));
        let (n, n_d) = unit_dot(&self.normal, &nd);
        let (e1, e1d) = orthonormal_dot(&n, &n_d, &self.reference, &refd);
        let e2 = n.cross(&e1);
        let e2d = n_d.cross(&e1) + n.cross(&e1d);
        let (r, rdot, dr, drdot) =
            lerp_dot([self.inner_radius, self.outer_radius], [pd[9], pd[10]], u);
        let (th, thdot, dth, dthdot) = lerp_dot(self.angle, [pd[11], pd[12]], v);
        let [rho, tau, rhod, taud] = polar_dot(&e1, &e2, &e1d, &e2d, th, thdot);
        SurfaceDerivs {
            x: cd + rhod * r + rho * rdot,
            xu: rhod * dr + rho * drdot,
            xv: taud * (r * dth) + tau * (rdot * dth + r * dthdot),
            xuu: V3::zeros(),
            xuv: taud * (dr * dth) + tau * (drdot * dth + dr * dthdot),
            xvv: -(rhod * (r * dth * dth) + rho * (rdot * dth * dth + r * 2.0 * dth * dthdot)),
        }
    }
}

impl CylinderSector<f64> {
    /// `∂/∂p` of [`CylinderSector::eval`] in the direction `pd` of the design parameters,
    /// by the product rule through `x = o + R ρ(θ) + s â`, `x_u = R θ' τ`, `x_v = s' â`,
    /// `x_uu = −R θ'² ρ`, with `â` and `e₁`, `e₂ = â × e₁` differentiated through their
    /// normalisations.
    pub(crate) fn design_velocity(&self, pd: &[f64], u: f64, v: f64) -> SurfaceDerivs<f64> {
        let (od, axd, refd) = (v3f(&pd[0..3]), v3f(&pd[3..6]), v3f(&pd[6..9]));
        let (a, ad) = unit_dot(&self.axis, &axd);
        let (e1, e1d) = orthonormal_dot(&a, &ad, &self.reference, &refd);
        let e2 = a.cross(&e1);
        let e2d = ad.cross(&e1) + a.cross(&e1d);
        let (th, thdot, dth, dthdot) = lerp_dot(self.angle, [pd[10], pd[11]], u);
        let (s, sdot, ds, dsdot) = lerp_dot(self.length, [pd[12], pd[13]], v);
        let [rho, tau, rhod, taud] = polar_dot(&e1, &e2, &e1d, &e2d, th, thdot);
        let (r, rdot) = (self.radius, pd[9]);
        let z = V3::zeros();
        SurfaceDerivs {
            x: od + rhod * r + rho * rdot + ad * s + a * sdot,
            xu: taud * (r * dth) + tau * (rdot * dth + r * dthdot),
            xv: ad * ds + a * dsdot,
            xuu: -(rhod * (r * dth * dth) + rho * (rdot * dth * dth + r * 2.0 * dth * dthdot)),
            xuv: z,
            xvv: z,
        }
    }
}

impl SphereZone<f64> {
    /// `∂/∂p` of [`SphereZone::eval`] in the direction `pd` of the design parameters. With
    /// `f(λ, φ) = (cos φ cos λ, cos φ sin λ, sin φ)`: `x = c + R f`, `x_u = R λ' f_λ`,
    /// `x_v = R φ' f_φ`, `x_uu = R λ'² f_λλ`, `x_uv = R λ' φ' f_λφ`, `x_vv = −R φ'² f`; the
    /// angles move with `λ̇ = λ̇₀ + u (λ̇₁ − λ̇₀)`, `φ̇` likewise, so the third angular
    /// derivatives `f_λλλ = −f_λ`, `f_λλφ`, `f_λφφ = −f_λ`, `f_φφφ = −f_φ` enter.
    pub(crate) fn design_velocity(&self, pd: &[f64], u: f64, v: f64) -> SurfaceDerivs<f64> {
        let cd = v3f(&pd[0..3]);
        let (r, rdot) = (self.radius, pd[3]);
        let (phi, phid, dp, dpd) = lerp_dot(self.latitude, [pd[4], pd[5]], v);
        let (lam, lamd, dl, dld) = lerp_dot(self.longitude, [pd[6], pd[7]], u);
        let (sl, cl) = lam.sin_cos();
        let (sp, cp) = phi.sin_cos();
        let f = V3::new(cp * cl, cp * sl, sp);
        let f_l = V3::new(-cp * sl, cp * cl, 0.0);
        let f_p = V3::new(-sp * cl, -sp * sl, cp);
        let f_ll = V3::new(-cp * cl, -cp * sl, 0.0);
        let f_lp = V3::new(sp * sl, -sp * cl, 0.0);
        let f_llp = V3::new(sp * cl, sp * sl, 0.0);
        // Design derivatives of f and its angular derivatives (f_φφ = −f).
        let fd = f_l * lamd + f_p * phid;
        let f_ld = f_ll * lamd + f_lp * phid;
        let f_pd = f_lp * lamd - f * phid;
        let f_lld = -f_l * lamd + f_llp * phid;
        let f_lpd = f_llp * lamd - f_l * phid;
        SurfaceDerivs {
            x: cd + fd * r + f * rdot,
            xu: f_ld * (r * dl) + f_l * (rdot * dl + r * dld),
            xv: f_pd * (r * dp) + f_p * (rdot * dp + r * dpd),
            xuu: f_lld * (r * dl * dl) + f_ll * (rdot * dl * dl + r * 2.0 * dl * dld),
            xuv: f_lpd * (r * dl * dp) + f_lp * (rdot * dl * dp + r * (dld * dp + dl * dpd)),
            xvv: -(fd * (r * dp * dp) + f * (rdot * dp * dp + r * 2.0 * dp * dpd)),
        }
    }
}
