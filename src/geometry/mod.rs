//! Parametric surfaces `x(u, v)`: the shell mid-surface and the rigid contact tools (die, punch).
//!
//! Every surface evaluates its position and its first and second parametric derivatives
//! ([`SurfaceDerivs`]) generically over the scalar [`Real`], both in its own parameters (radius,
//! control points, weights: future design variables) and in the parameter `(u, v)` (contact
//! projection solves for `(u, v)` with Newton; design sensitivity differentiates through it).
//!
//! # Conventions
//!
//! - Tangents and normal follow the paper's eq (66): `e₁ = x,₁ = x_u`, `e₂ = x,₂ = x_v`,
//!   `n = e₁ × e₂ / ‖e₁ × e₂‖` ([`SurfaceDerivs::normal`]). The orientation of each patch is
//!   therefore fixed by its parametrisation and documented on the patch type: cylinder and sphere
//!   normals point *away from the axis / centre*; the rectangle's is `edge_u × edge_v`, the
//!   annulus's is its `normal` field.
//! - The analytic patches ([`Rectangle`], [`AnnulusSector`], [`CylinderSector`], [`SphereZone`])
//!   use normalised parameters `(u, v) ∈ [0, 1]²`: a radius or angle range is mapped linearly onto
//!   `[0, 1]`, so the parameter box never depends on a design parameter and the design velocity
//!   `∂x/∂p` at fixed `(u, v)` is defined everywhere. NURBS patches use their knot range.
//! - Curvature: second fundamental form `b_αβ = n · x,αβ` (paper eqs 79–80 use `n · x,αβ`), shape
//!   operator `m⁻¹ b` with the metric `m_αβ = e_α · e_β`, mean curvature `H = ½ tr(m⁻¹ b)`.
//!   With this sign a sphere of radius R with outward normal has `H = −1/R`.
//! - Outside the domain [`Surface::eval`] *extrapolates* (analytic patches: the same closed form;
//!   NURBS: the polynomial piece of the first/last knot span), which keeps a Newton projection
//!   smooth near edges. [`Surface::eval_checked`] returns [`GeometryError::OutsideDomain`] instead
//!   and [`Surface::clamp`] clamps a parameter pair into the box.
//!
//! # Design parameters
//!
//! [`Surface::design_parameters`] lists every real scalar of a surface by name (`"radius"`,
//! `"centre.x"`, `"cp[3][2].z"`, `"weight[1][1]"`, …); [`Surface::with_design_parameters`] rebuilds
//! the same surface with every parameter replaced by a value of another scalar type, so seeding one
//! entry with a dual number gives `∂x/∂p`. Structural data (NURBS degrees and knot vectors) are not
//! design parameters.
//!
//! # Validation
//!
//! Constructors, [`Surface::validate`] and [`SurfaceSpec::build`] return a [`GeometryError`] naming
//! the field, the value and what was expected. Evaluation itself never panics: a surface built
//! around validation (public fields of an analytic patch edited by hand) yields NaN, not a panic.

mod analytic;
mod nurbs;
mod spec;

pub use analytic::{AnnulusSector, CylinderSector, Rectangle, SphereZone};
pub use nurbs::{basis_function_derivatives, find_span, BasisDerivs, NurbsSurface, MAX_DEGREE};
pub use spec::SurfaceSpec;

use crate::scalar::Real;
use nalgebra::{Matrix2, Vector2, Vector3};
use thiserror::Error;

/// Position and first and second parametric derivatives of a surface at one `(u, v)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceDerivs<T> {
    /// Position `x(u, v)`.
    pub x: Vector3<T>,
    /// `∂x/∂u` (the paper's `e₁`, eq 66).
    pub xu: Vector3<T>,
    /// `∂x/∂v` (the paper's `e₂`, eq 66).
    pub xv: Vector3<T>,
    /// `∂²x/∂u²`.
    pub xuu: Vector3<T>,
    /// `∂²x/∂u∂v`.
    pub xuv: Vector3<T>,
    /// `∂²x/∂v²`.
    pub xvv: Vector3<T>,
}

impl<T: Real> SurfaceDerivs<T> {
    /// Tangent vectors `(e₁, e₂) = (x,₁, x,₂)` of the paper's eq (66).
    pub fn tangents(&self) -> (Vector3<T>, Vector3<T>) {
        (self.xu, self.xv)
    }

    /// `x,αβ` as `[[x_uu, x_uv], [x_uv, x_vv]]`.
    pub fn second_derivatives(&self) -> [[Vector3<T>; 2]; 2] {
        [[self.xuu, self.xuv], [self.xuv, self.xvv]]
    }

    /// Unit normal `n = e₁ × e₂ / ‖e₁ × e₂‖` (paper eq 66). Errors where the parametrisation is
    /// singular — `‖e₁ × e₂‖ ≤ 10⁻¹² (‖e₁‖² + ‖e₂‖²)`, for example a sphere pole or the centre of
    /// a full disc, where round-off leaves a meaningless non-zero cross product — or not finite.
    pub fn normal(&self) -> Result<Vector3<T>, GeometryError> {
        let c = self.xu.cross(&self.xv);
        let norm = c.norm();
        let nv = norm.value();
        let scale = self.xu.norm_squared().value() + self.xv.norm_squared().value();
        if nv > 1e-12 * scale && nv.is_finite() {
            Ok(c / norm)
        } else {
            Err(GeometryError::DegenerateNormal { norm: nv })
        }
    }

    /// Metric (first fundamental form) `m_αβ = e_α · e_β`.
    pub fn metric(&self) -> Matrix2<T> {
        let m12 = self.xu.dot(&self.xv);
        Matrix2::new(self.xu.dot(&self.xu), m12, m12, self.xv.dot(&self.xv))
    }

    /// Second fundamental form `b_αβ = n · x,αβ`.
    pub fn second_fundamental_form(&self) -> Result<Matrix2<T>, GeometryError> {
        let n = self.normal()?;
        let b12 = n.dot(&self.xuv);
        Ok(Matrix2::new(n.dot(&self.xuu), b12, b12, n.dot(&self.xvv)))
    }

    /// Shape operator (mixed curvature tensor) `m⁻¹ b`; its eigenvalues are the principal
    /// curvatures (sign as [`Self::second_fundamental_form`]).
    pub fn shape_operator(&self) -> Result<Matrix2<T>, GeometryError> {
        let b = self.second_fundamental_form()?;
        let m = self.metric();
        let det = m[(0, 0)] * m[(1, 1)] - m[(0, 1)] * m[(1, 0)];
        let minv = Matrix2::new(m[(1, 1)], -m[(0, 1)], -m[(1, 0)], m[(0, 0)]) / det;
        Ok(minv * b)
    }

    /// Mean curvature `H = ½ tr(m⁻¹ b)` (`−1/R` on a sphere with outward normal).
    pub fn mean_curvature(&self) -> Result<T, GeometryError> {
        let s = self.shape_operator()?;
        Ok((s[(0, 0)] + s[(1, 1)]) * 0.5)
    }

    /// Gaussian curvature `K = det b / det m`.
    pub fn gaussian_curvature(&self) -> Result<T, GeometryError> {
        let b = self.second_fundamental_form()?;
        let m = self.metric();
        Ok((b[(0, 0)] * b[(1, 1)] - b[(0, 1)] * b[(1, 0)])
            / (m[(0, 0)] * m[(1, 1)] - m[(0, 1)] * m[(1, 0)]))
    }

    /// Normal curvature `κ = dᵀ b d / dᵀ m d` along the parametric direction `d = (du, dv)`.
    pub fn normal_curvature(&self, d: Vector2<T>) -> Result<T, GeometryError> {
        let b = self.second_fundamental_form()?;
        let m = self.metric();
        Ok(d.dot(&(b * d)) / d.dot(&(m * d)))
    }

    /// Real parts.
    pub fn value(&self) -> SurfaceDerivs<f64> {
        let f = |v: &Vector3<T>| v.map(|c| c.value());
        SurfaceDerivs {
            x: f(&self.x),
            xu: f(&self.xu),
            xv: f(&self.xv),
            xuu: f(&self.xuu),
            xuv: f(&self.xuv),
            xvv: f(&self.xvv),
        }
    }
}

/// Invalid surface data, named by field, with the value found and what was expected.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum GeometryError {
    /// A NURBS degree outside `1..=3`.
    #[error("`{field}` = {value}: expected a degree in 1..=3")]
    Degree {
        /// `degree_u` or `degree_v`.
        field: String,
        /// The degree given.
        value: usize,
    },
    /// A knot vector of the wrong length.
    #[error(
        "`{field}` has {value} knots: expected {expected} (control points {n_points} + degree {degree} + 1)"
    )]
    KnotCount {
        /// `knots_u` or `knots_v`.
        field: String,
        /// Number of knots given.
        value: usize,
        /// Number required.
        expected: usize,
        /// Control points in that direction.
        n_points: usize,
        /// Degree in that direction.
        degree: usize,
    },
    /// A decreasing knot.
    #[error("`{field}` is not non-decreasing: knot {index} = {value} is less than knot {} = {previous}", index - 1)]
    KnotsDecreasing {
        /// `knots_u` or `knots_v`.
        field: String,
        /// Index of the offending knot (≥ 1).
        index: usize,
        /// Its value.
        value: f64,
        /// The knot before it.
        previous: f64,
    },
    /// A knot vector that is not open (clamped).
    #[error(
        "`{field}` = {knots:?} is not clamped: expected the first {multiplicity} and the last {multiplicity} knots equal (degree {})",
        multiplicity - 1
    )]
    KnotsNotClamped {
        /// `knots_u` or `knots_v`.
        field: String,
        /// The knots given.
        knots: Vec<f64>,
        /// Required end multiplicity (degree + 1).
        multiplicity: usize,
    },
    /// A knot repeated too often: more than the degree inside (the surface would be
    /// discontinuous), more than degree + 1 at an end (a control point would drop out).
    #[error("`{field}`: knot {value} has multiplicity {multiplicity}: expected {expected}")]
    KnotMultiplicity {
        /// `knots_u` or `knots_v`.
        field: String,
        /// The knot value.
        value: f64,
        /// Its multiplicity.
        multiplicity: usize,
        /// What was expected.
        expected: String,
    },
    /// A NaN or infinite number.
    #[error("`{field}` = {value}: expected a finite number")]
    NonFinite {
        /// Field name (`radius`, `cp[1][2].z`, `knots_u[3]`, …).
        field: String,
        /// The value given.
        value: f64,
    },
    /// A NURBS weight that is zero or negative.
    #[error("`{field}` = {value}: expected a weight > 0")]
    NonPositiveWeight {
        /// `weight[i][j]`.
        field: String,
        /// The value given.
        value: f64,
    },
    /// A zero or negative radius.
    #[error("`{field}` = {value}: expected {expected}")]
    InvalidRadius {
        /// `radius`, `inner_radius`, `outer_radius`.
        field: String,
        /// The value given.
        value: f64,
        /// What was expected.
        expected: String,
    },
    /// An empty or inadmissible parameter range (`[start, end]` with `end ≤ start`, a latitude
    /// beyond a pole, an angle span over a full turn, an empty knot range).
    #[error("`{field}` = [{start}, {end}]: expected {expected}")]
    InvalidRange {
        /// `angle`, `latitude`, `length`, `knots_u`, …
        field: String,
        /// Range start.
        start: f64,
        /// Range end.
        end: f64,
        /// What was expected.
        expected: String,
    },
    /// A zero direction or edge vector, or two that are parallel.
    #[error("`{field}` = {value:?}: expected {expected}")]
    DegenerateVector {
        /// `axis`, `edge_u`, `reference`, …
        field: String,
        /// The vector given.
        value: [f64; 3],
        /// What was expected.
        expected: String,
    },
    /// A control net of the wrong shape.
    #[error("`{field}` has {got} entries: expected {expected}")]
    ControlNet {
        /// `control_points`, `control_points[2]`, `weights`, …
        field: String,
        /// Entries found.
        got: usize,
        /// What was expected.
        expected: String,
    },
    /// A parameter outside the surface's domain (from [`Surface::eval_checked`]).
    #[error("`{field}` = {value}: expected a value in the domain [{}, {}]", range[0], range[1])]
    OutsideDomain {
        /// `u` or `v`.
        field: String,
        /// The value given.
        value: f64,
        /// The domain in that direction.
        range: [f64; 2],
    },
    /// A design-parameter vector of the wrong length.
    #[error("`design parameters` has {got} values: expected {expected} for this {kind} surface")]
    ParameterCount {
        /// Values given.
        got: usize,
        /// Values required ([`Surface::n_design_parameters`]).
        expected: usize,
        /// Surface kind.
        kind: &'static str,
    },
    /// A design-parameter index the surface does not have.
    #[error("design parameter {index}: expected an index below {count} (the parameters of this {kind} surface)")]
    ParameterIndex {
        /// The index given.
        index: usize,
        /// Number of design parameters ([`Surface::n_design_parameters`]).
        count: usize,
        /// Surface kind.
        kind: &'static str,
    },
    /// The normal is undefined (`x_u × x_v = 0`).
    #[error("`normal` is undefined: |x_u × x_v| = {norm}: expected a regular point (x_u, x_v independent)")]
    DegenerateNormal {
        /// `‖x_u × x_v‖`.
        norm: f64,
    },
}

/// A rigid tool or shell mid-surface: one of the analytic patches or a NURBS patch.
#[derive(Clone, Debug, PartialEq)]
pub enum Surface<T> {
    /// Flat parallelogram.
    Rectangle(Rectangle<T>),
    /// Sector of a flat annulus.
    AnnulusSector(AnnulusSector<T>),
    /// Sector of a circular cylinder.
    CylinderSector(CylinderSector<T>),
    /// Latitude/longitude zone of a sphere.
    SphereZone(SphereZone<T>),
    /// Rational B-spline patch.
    Nurbs(NurbsSurface<T>),
}

impl<T: Real> Surface<T> {
    /// Kind name (`"rectangle"`, `"annulus-sector"`, `"cylinder-sector"`, `"sphere-zone"`,
    /// `"nurbs"`, as in [`SurfaceSpec`]).
    pub fn kind(&self) -> &'static str {
        match self {
            Surface::Rectangle(_) => "rectangle",
            Surface::AnnulusSector(_) => "annulus-sector",
            Surface::CylinderSector(_) => "cylinder-sector",
            Surface::SphereZone(_) => "sphere-zone",
            Surface::Nurbs(_) => "nurbs",
        }
    }

    /// Position and first and second derivatives at `(u, v)`. Extrapolates outside the domain
    /// (see the module documentation); never panics.
    pub fn eval(&self, u: T, v: T) -> SurfaceDerivs<T> {
        match self {
            Surface::Rectangle(s) => s.eval(u, v),
            Surface::AnnulusSector(s) => s.eval(u, v),
            Surface::CylinderSector(s) => s.eval(u, v),
            Surface::SphereZone(s) => s.eval(u, v),
            Surface::Nurbs(s) => s.eval(u, v),
        }
    }

    /// As [`Self::eval`], but a parameter outside [`Self::domain`] (or NaN) is an error.
    pub fn eval_checked(&self, u: T, v: T) -> Result<SurfaceDerivs<T>, GeometryError> {
        let d = self.domain();
        for (field, value, range) in [("u", u.value(), d[0]), ("v", v.value(), d[1])] {
            if !(value >= range[0] && value <= range[1]) {
                return Err(GeometryError::OutsideDomain {
                    field: field.to_string(),
                    value,
                    range,
                });
            }
        }
        Ok(self.eval(u, v))
    }

    /// Parameter box `[[u_min, u_max], [v_min, v_max]]`: `[0, 1]²` for analytic patches, the knot
    /// range for NURBS.
    pub fn domain(&self) -> [[f64; 2]; 2] {
        match self {
            Surface::Nurbs(s) => s.domain(),
            _ => [[0.0, 1.0], [0.0, 1.0]],
        }
    }

    /// `(u, v)` clamped into [`Self::domain`]; a clamped coordinate becomes a constant (its
    /// derivative part is zero). NaN is mapped to the lower bound.
    pub fn clamp(&self, u: T, v: T) -> (T, T) {
        let d = self.domain();
        let c = |x: T, r: [f64; 2]| {
            let xv = x.value();
            if xv >= r[0] && xv <= r[1] {
                x
            } else if xv > r[1] {
                T::cst(r[1])
            } else {
                T::cst(r[0])
            }
        };
        (c(u, d[0]), c(v, d[1]))
    }

    /// Check every field (see [`GeometryError`]).
    pub fn validate(&self) -> Result<(), GeometryError> {
        match self {
            Surface::Rectangle(s) => s.validate(),
            Surface::AnnulusSector(s) => s.validate(),
            Surface::CylinderSector(s) => s.validate(),
            Surface::SphereZone(s) => s.validate(),
            Surface::Nurbs(s) => s.validate(),
        }
    }

    /// The design parameters in a fixed order, as scalars of type `T`.
    pub fn parameter_values(&self) -> Vec<T> {
        match self {
            Surface::Rectangle(s) => s.scalars(),
            Surface::AnnulusSector(s) => s.scalars(),
            Surface::CylinderSector(s) => s.scalars(),
            Surface::SphereZone(s) => s.scalars(),
            Surface::Nurbs(s) => s.scalars(),
        }
    }

    /// Names of the design parameters, in the order of [`Self::design_parameters`].
    pub fn parameter_names(&self) -> Vec<String> {
        match self {
            Surface::Rectangle(_) => Rectangle::<T>::names(),
            Surface::AnnulusSector(_) => AnnulusSector::<T>::names(),
            Surface::CylinderSector(_) => CylinderSector::<T>::names(),
            Surface::SphereZone(_) => SphereZone::<T>::names(),
            Surface::Nurbs(s) => s.names(),
        }
    }

    /// Number of design parameters.
    pub fn n_design_parameters(&self) -> usize {
        match self {
            Surface::Rectangle(_) => analytic::N_RECTANGLE,
            Surface::AnnulusSector(_) => analytic::N_ANNULUS,
            Surface::CylinderSector(_) => analytic::N_CYLINDER,
            Surface::SphereZone(_) => analytic::N_SPHERE,
            Surface::Nurbs(s) => s.n_scalars(),
        }
    }

    /// Every design parameter by name with its (real) value, for example `("radius", 10.0)`,
    /// `("cp[3][2].z", 1.5)`, `("weight[1][1]", 0.707…)`. Angles are in radians.
    pub fn design_parameters(&self) -> Vec<(String, f64)> {
        self.parameter_names()
            .into_iter()
            .zip(self.parameter_values().iter().map(|p| p.value()))
            .collect()
    }

    /// Index of the design parameter called `name`.
    pub fn parameter_index(&self, name: &str) -> Option<usize> {
        self.parameter_names().iter().position(|n| n == name)
    }

    /// The same surface type and structure (NURBS degrees, knots) with every design parameter
    /// replaced by `p` (ordered as [`Self::design_parameters`]), validated. Seed one entry of `p`
    /// with a dual number to obtain `∂x/∂p` from [`Surface::eval`].
    pub fn with_design_parameters<U: Real>(&self, p: &[U]) -> Result<Surface<U>, GeometryError> {
        let expected = self.n_design_parameters();
        if p.len() != expected {
            return Err(GeometryError::ParameterCount {
                got: p.len(),
                expected,
                kind: self.kind(),
            });
        }
        let s = self.rebuild(p);
        s.validate()?;
        Ok(s)
    }

    /// Real parts (derivative parts dropped).
    pub fn value(&self) -> Surface<f64> {
        let p: Vec<f64> = self.parameter_values().iter().map(|x| x.value()).collect();
        self.rebuild(&p)
    }

    /// Rebuild with parameters `p` of the right length, without validation (internal).
    fn rebuild<U: Real>(&self, p: &[U]) -> Surface<U> {
        match self {
            Surface::Rectangle(_) => Surface::Rectangle(Rectangle::<T>::from_scalars(p)),
            Surface::AnnulusSector(_) => {
                Surface::AnnulusSector(AnnulusSector::<T>::from_scalars(p))
            }
            Surface::CylinderSector(_) => {
                Surface::CylinderSector(CylinderSector::<T>::from_scalars(p))
            }
            Surface::SphereZone(_) => Surface::SphereZone(SphereZone::<T>::from_scalars(p)),
            Surface::Nurbs(s) => Surface::Nurbs(s.with_scalars(p)),
        }
    }
}

impl Surface<f64> {
    /// Design velocity of the surface: `∂/∂p` of [`Surface::eval`] (position and its first
    /// and second parametric derivatives at fixed `(u, v)`) for design parameter `parameter`
    /// (ordered as [`Surface::design_parameters`]). Hand-derived for every patch kind (no dual
    /// numbers): analytic patches by the product rule through their closed forms (radius,
    /// centre, frame vectors through their normalisations, angle and length ranges through
    /// the linear maps of `(u, v)`); NURBS control-point coordinates linearly through the
    /// rational basis, weights rationally. This is the geometric input of the paper's design
    /// velocity field (eqs 37–43) on the parametric discretisation, where `(u, v)` does not
    /// move with the design.
    ///
    /// Errors: an index beyond [`Surface::n_design_parameters`]
    /// ([`GeometryError::ParameterIndex`]), a non-finite `(u, v)` or result
    /// ([`GeometryError::NonFinite`]).
    pub fn design_velocity(
        &self,
        parameter: usize,
        u: f64,
        v: f64,
    ) -> Result<SurfaceDerivs<f64>, GeometryError> {
        let count = self.n_design_parameters();
        if parameter >= count {
            return Err(GeometryError::ParameterIndex {
                index: parameter,
                count,
                kind: self.kind(),
            });
        }
        check_finite("u", u)?;
        check_finite("v", v)?;
        let mut pd = vec![0.0; count];
        pd[parameter] = 1.0;
        let d = match self {
            Surface::Rectangle(s) => s.design_velocity(&pd, u, v),
            Surface::AnnulusSector(s) => s.design_velocity(&pd, u, v),
            Surface::CylinderSector(s) => s.design_velocity(&pd, u, v),
            Surface::SphereZone(s) => s.design_velocity(&pd, u, v),
            Surface::Nurbs(s) => s.design_velocity(parameter, u, v),
        };
        for (field, vec) in [
            ("x", d.x),
            ("xu", d.xu),
            ("xv", d.xv),
            ("xuu", d.xuu),
            ("xuv", d.xuv),
            ("xvv", d.xvv),
        ] {
            for c in vec.iter() {
                check_finite(&format!("design velocity {field} at ({u}, {v})"), *c)?;
            }
        }
        Ok(d)
    }

    /// The same surface with scalar type `U` (derivative parts zero).
    pub fn lift<U: Real>(&self) -> Surface<U> {
        let p: Vec<U> = self.parameter_values().iter().map(|&x| U::cst(x)).collect();
        self.rebuild(&p)
    }

    /// Build from a deserialised description (validated).
    pub fn from_spec(spec: &SurfaceSpec) -> Result<Self, GeometryError> {
        spec.build()
    }
}

impl TryFrom<&SurfaceSpec> for Surface<f64> {
    type Error = GeometryError;
    fn try_from(spec: &SurfaceSpec) -> Result<Self, GeometryError> {
        spec.build()
    }
}

impl TryFrom<SurfaceSpec> for Surface<f64> {
    type Error = GeometryError;
    fn try_from(spec: SurfaceSpec) -> Result<Self, GeometryError> {
        spec.build()
    }
}

// ---------------------------------------------------------------------------------------------
// Validation helpers shared by the patch types.

/// `value` must be finite.
pub(crate) fn check_finite(field: &str, value: f64) -> Result<(), GeometryError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(GeometryError::NonFinite {
            field: field.to_string(),
            value,
        })
    }
}

/// Every component of `v` finite and `v ≠ 0`.
pub(crate) fn check_vector<T: Real>(
    field: &str,
    v: &Vector3<T>,
    nonzero: bool,
) -> Result<(), GeometryError> {
    let a = [v.x.value(), v.y.value(), v.z.value()];
    for (c, name) in a.iter().zip(["x", "y", "z"]) {
        check_finite(&format!("{field}.{name}"), *c)?;
    }
    if nonzero && a.iter().all(|c| *c == 0.0) {
        return Err(GeometryError::DegenerateVector {
            field: field.to_string(),
            value: a,
            expected: "a non-zero vector".to_string(),
        });
    }
    Ok(())
}

/// `[start, end]` finite with `end > start` and, if given, inside `[lo, hi]` and at most `max_span`.
pub(crate) fn check_range(
    field: &str,
    start: f64,
    end: f64,
    bounds: Option<(f64, f64)>,
    max_span: Option<f64>,
) -> Result<(), GeometryError> {
    check_finite(&format!("{field}_start"), start)?;
    check_finite(&format!("{field}_end"), end)?;
    let err = |expected: String| GeometryError::InvalidRange {
        field: field.to_string(),
        start,
        end,
        expected,
    };
    if end <= start {
        return Err(err("a non-empty range, end > start".to_string()));
    }
    if let Some((lo, hi)) = bounds {
        // A relative slack of a few ulps admits ±π/2 given in degrees and converted.
        let slack = 4.0 * f64::EPSILON * lo.abs().max(hi.abs());
        if start < lo - slack || end > hi + slack {
            return Err(err(format!("a range inside [{lo}, {hi}]")));
        }
    }
    if let Some(m) = max_span {
        if end - start > m * (1.0 + 4.0 * f64::EPSILON) {
            return Err(err(format!("a span of at most {m}")));
        }
    }
    Ok(())
}

/// Unit vector along `reference` minus its component along the unit vector `axis`.
pub(crate) fn orthonormal<T: Real>(axis: &Vector3<T>, reference: &Vector3<T>) -> Vector3<T> {
    let r = reference - axis * reference.dot(axis);
    let n = r.norm();
    r / n
}

/// `reference` must not be parallel to `axis` (both non-zero).
pub(crate) fn check_not_parallel<T: Real>(
    field: &str,
    reference: &Vector3<T>,
    axis_field: &str,
    axis: &Vector3<T>,
) -> Result<(), GeometryError> {
    let a = axis.map(|c| c.value());
    let r = reference.map(|c| c.value());
    let s = a.cross(&r).norm();
    if s <= 1e-10 * a.norm() * r.norm() || !s.is_finite() {
        return Err(GeometryError::DegenerateVector {
            field: field.to_string(),
            value: [r.x, r.y, r.z],
            expected: format!(
                "a vector not parallel to `{axis_field}` = [{}, {}, {}]",
                a.x, a.y, a.z
            ),
        });
    }
    Ok(())
}

/// Push `name.x`, `name.y`, `name.z`.
pub(crate) fn push_vec_names(out: &mut Vec<String>, name: &str) {
    for c in ["x", "y", "z"] {
        out.push(format!("{name}.{c}"));
    }
}
