//! Serde descriptions of surfaces for case files, converted to [`Surface<f64>`] with validation.
//!
//! Angles are given in degrees (`*_deg` fields) and stored in radians. Example (TOML):
//!
//! ```toml
//! [punch]
//! type = "sphere-zone"
//! centre = [0.0, 0.0, 0.0]
//! radius = 10.0
//! latitude_deg = [0.0, 72.0]     # pinched hemisphere: 18° hole at the pole
//! longitude_deg = [0.0, 90.0]
//!
//! [die]
//! type = "nurbs"
//! degree_u = 1
//! degree_v = 1
//! knots_u = [0.0, 0.0, 1.0, 1.0]
//! knots_v = [0.0, 0.0, 1.0, 1.0]
//! # rows i (along u), each a list of [x, y, z, w] along v
//! control_points = [[[0, 0, 0, 1], [0, 1, 0, 1]], [[1, 0, 0, 1], [1, 1, 0, 1]]]
//! ```

use super::{
    AnnulusSector, CylinderSector, GeometryError, NurbsSurface, Rectangle, SphereZone, Surface,
};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// A surface as written in a case file; `type` selects the kind. Build with [`SurfaceSpec::build`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum SurfaceSpec {
    /// `type = "rectangle"`: see [`Rectangle`].
    Rectangle {
        /// Corner at `(u, v) = (0, 0)`.
        origin: [f64; 3],
        /// Edge along `u`.
        edge_u: [f64; 3],
        /// Edge along `v`.
        edge_v: [f64; 3],
    },
    /// `type = "annulus-sector"`: see [`AnnulusSector`].
    AnnulusSector {
        /// Centre of the circles.
        centre: [f64; 3],
        /// Plane normal (the surface normal).
        normal: [f64; 3],
        /// Direction of angle 0.
        reference: [f64; 3],
        /// Inner radius ≥ 0.
        inner_radius: f64,
        /// Outer radius > inner radius.
        outer_radius: f64,
        /// `[start, end]` in degrees.
        angle_deg: [f64; 2],
    },
    /// `type = "cylinder-sector"`: see [`CylinderSector`].
    CylinderSector {
        /// A point on the axis.
        origin: [f64; 3],
        /// Axis direction.
        axis: [f64; 3],
        /// Direction of angle 0.
        reference: [f64; 3],
        /// Radius > 0.
        radius: f64,
        /// `[start, end]` in degrees.
        angle_deg: [f64; 2],
        /// `[start, end]` along the unit axis from `origin`.
        length: [f64; 2],
    },
    /// `type = "sphere-zone"`: see [`SphereZone`] (pole on `+z`).
    SphereZone {
        /// Centre.
        centre: [f64; 3],
        /// Radius > 0.
        radius: f64,
        /// `[start, end]` in degrees from the equator, inside `[−90, 90]`.
        latitude_deg: [f64; 2],
        /// `[start, end]` in degrees from `+x` towards `+y`.
        longitude_deg: [f64; 2],
    },
    /// `type = "nurbs"`: see [`NurbsSurface`].
    Nurbs {
        /// Degree along `u` (1..=3).
        degree_u: usize,
        /// Degree along `v` (1..=3).
        degree_v: usize,
        /// Open (clamped) knot vector along `u`, `n_u + degree_u + 1` entries.
        knots_u: Vec<f64>,
        /// Open (clamped) knot vector along `v`, `n_v + degree_v + 1` entries.
        knots_v: Vec<f64>,
        /// `control_points[i][j] = [x, y, z, w]`: row `i` along `u`, entry `j` along `v`;
        /// Cartesian coordinates and weight (not pre-multiplied by the weight).
        control_points: Vec<Vec<[f64; 4]>>,
    },
}

impl SurfaceSpec {
    /// Validated surface.
    pub fn build(&self) -> Result<Surface<f64>, GeometryError> {
        let v = |a: &[f64; 3]| Vector3::new(a[0], a[1], a[2]);
        let rad = |a: &[f64; 2]| [a[0].to_radians(), a[1].to_radians()];
        Ok(match self {
            SurfaceSpec::Rectangle {
                origin,
                edge_u,
                edge_v,
            } => Surface::Rectangle(Rectangle::new(v(origin), v(edge_u), v(edge_v))?),
            SurfaceSpec::AnnulusSector {
                centre,
                normal,
                reference,
                inner_radius,
                outer_radius,
                angle_deg,
            } => Surface::AnnulusSector(AnnulusSector::new(
                v(centre),
                v(normal),
                v(reference),
                *inner_radius,
                *outer_radius,
                rad(angle_deg),
            )?),
            SurfaceSpec::CylinderSector {
                origin,
                axis,
                reference,
                radius,
                angle_deg,
                length,
            } => Surface::CylinderSector(CylinderSector::new(
                v(origin),
                v(axis),
                v(reference),
                *radius,
                rad(angle_deg),
                *length,
            )?),
            SurfaceSpec::SphereZone {
                centre,
                radius,
                latitude_deg,
                longitude_deg,
            } => Surface::SphereZone(SphereZone::new(
                v(centre),
                *radius,
                rad(latitude_deg),
                rad(longitude_deg),
            )?),
            SurfaceSpec::Nurbs {
                degree_u,
                degree_v,
                knots_u,
                knots_v,
                control_points,
            } => {
                let points = control_points
                    .iter()
                    .map(|r| r.iter().map(|c| Vector3::new(c[0], c[1], c[2])).collect())
                    .collect();
                let weights = control_points
                    .iter()
                    .map(|r| r.iter().map(|c| c[3]).collect())
                    .collect();
                Surface::Nurbs(NurbsSurface::new(
                    [*degree_u, *degree_v],
                    [knots_u.clone(), knots_v.clone()],
                    points,
                    weights,
                )?)
            }
        })
    }
}
