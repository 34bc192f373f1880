//! Shape design variables: the design velocity field of the paper (eqs 37–43) on the
//! parametric discretisation, hand-derived, and the dual-number geometry of the reference.
//!
//! The shell is discretised on the parameter domain of its mid-surface: particle and
//! quadrature coordinates `(u, v)`, the RK shape functions, quadrature weights and VCI test
//! gradients do not move with a shape design variable `τ` (a surface parameter: a radius, a
//! centre coordinate, a NURBS control-point coordinate or weight). The design velocity
//! `V = ∂x⁰/∂τ` at fixed `(u, v)` (eq 37: the material points keep their parametric
//! coordinates) therefore enters only through the initial geometry:
//!
//! - per quadrature point, `ẋ⁰,α` and the normal's `ṅ⁰`, `ṅ⁰,α` ([`SurfacePoint`] dots,
//!   [`SurfacePoint::from_derivs_dot`]): the `∂/∂τ` of the metric and curvature terms of
//!   eqs 38–43;
//! - per particle, the initial director `d⁰ = n(ξ_I)` and the lamina vectors `e₁, e₂` built
//!   from it ([`lamina_vectors_dot`]);
//! - per point and layer, the initial lamina frame ([`SurfacePoint::initial_frame_dot`]);
//! - per quadrature point, the mid-surface point's own velocity `V⁰ = ẋ̄⁰`, where the
//!   contact's slave points sit (`shell::contact::InitialGeometry`; eq 74's `V⁰` in the
//!   contact terms of eqs 78–83).
//!
//! Everything here is `f64` code with the derivatives written out; `tests/dsa_shape.rs`
//! compares it with a `Dual64` evaluation of the f64 code path and with central differences.
//! [`dual_geometry`] builds the same quantities in a dual scalar for the dual reference
//! (`super::dual`), exactly as `ShellModel::new` builds them in `f64`.

use crate::geometry::{GeometryError, Surface, SurfaceDerivs};
use crate::kinematics::M3;
use crate::material::MaterialState;
use crate::scalar::DesignDual;
use crate::shell::model::{initial_histories, initial_particle, ShellModel};
use crate::shell::point::{ParticleState, PointHistory, SurfacePoint};
use nalgebra::Vector3;

type V3 = Vector3<f64>;

/// `(v/|v|, ∂(v/|v|))` for the derivative `vd` of `v`.
fn unit_dot(v: &V3, vd: &V3) -> (V3, V3) {
    let len = v.norm();
    let n = v / len;
    (n, (vd - n * n.dot(vd)) / len)
}

impl SurfacePoint<f64> {
    /// `∂/∂τ` of [`SurfacePoint::from_derivs`] for surface derivatives `s` and their design
    /// derivatives `s_dot` ([`Surface::design_velocity`]). With `c = x,1 × x,2`, `n = c/|c|`,
    /// `c,α = x,1α × x,2 + x,1 × x,2α`, `n,α = (c,α − n (n·c,α))/|c|`:
    /// `ċ = ẋ,1 × x,2 + x,1 × ẋ,2`, `ṅ = (ċ − n (n·ċ))/|c|`, and
    /// `ṅ,α = (ċ,α − ṅ (n·c,α) − n (ṅ·c,α + n·ċ,α))/|c| − n,α (n·ċ)/|c|`.
    pub fn from_derivs_dot(
        s: &SurfaceDerivs<f64>,
        s_dot: &SurfaceDerivs<f64>,
    ) -> SurfacePoint<f64> {
        let c = s.xu.cross(&s.xv);
        let len = c.norm();
        let n = c / len;
        let cd = s_dot.xu.cross(&s.xv) + s.xu.cross(&s_dot.xv);
        let len_d = n.dot(&cd);
        let nd = (cd - n * len_d) / len;
        let ca = [
            s.xuu.cross(&s.xv) + s.xu.cross(&s.xuv),
            s.xuv.cross(&s.xv) + s.xu.cross(&s.xvv),
        ];
        let cad = [
            s_dot.xuu.cross(&s.xv)
                + s.xuu.cross(&s_dot.xv)
                + s_dot.xu.cross(&s.xuv)
                + s.xu.cross(&s_dot.xuv),
            s_dot.xuv.cross(&s.xv)
                + s.xuv.cross(&s_dot.xv)
                + s_dot.xu.cross(&s.xvv)
                + s.xu.cross(&s_dot.xvv),
        ];
        let na_dot = |a: usize| {
            let na = (ca[a] - n * n.dot(&ca[a])) / len;
            let num_d = cad[a] - nd * n.dot(&ca[a]) - n * (nd.dot(&ca[a]) + n.dot(&cad[a]));
            num_d / len - na * (len_d / len)
        };
        SurfacePoint {
            x_a: [s_dot.xu, s_dot.xv],
            n: nd,
            n_a: [na_dot(0), na_dot(1)],
        }
    }

    /// `∂/∂τ` of [`SurfacePoint::initial_frame`] (rows `e1 = x̄,1/|x̄,1|`, `e2 = n × e1`,
    /// `e3 = n`) for the geometry's design derivative `dot` ([`Self::from_derivs_dot`]).
    pub fn initial_frame_dot(&self, dot: &SurfacePoint<f64>) -> M3<f64> {
        let (e1, e1d) = unit_dot(&self.x_a[0], &dot.x_a[0]);
        let e2d = dot.n.cross(&e1) + self.n.cross(&e1d);
        M3::from_rows(&[e1d.transpose(), e2d.transpose(), dot.n.transpose()])
    }
}

/// `∂/∂τ` of [`crate::shell::model::lamina_vectors`] for the derivatives `d_dot`, `t_dot` of the director and the
/// hint: `w = t − d (d·t)`, `ẇ = ṫ − ḋ (d·t) − d (ḋ·t + d·ṫ)`, `ė1 = (ẇ − e1 (e1·ẇ))/|w|`,
/// `ė2 = ḋ × e1 + d × ė1`.
pub fn lamina_vectors_dot(d: &V3, d_dot: &V3, t: &V3, t_dot: &V3) -> [V3; 2] {
    let dt = d.dot(t);
    let w = t - d * dt;
    let wd = t_dot - d_dot * dt - d * (d_dot.dot(t) + d.dot(t_dot));
    let (e1, e1d) = unit_dot(&w, &wd);
    [e1d, d_dot.cross(&e1) + d.cross(&e1d)]
}

/// The design velocity field of one shape design variable on a model's discretisation
/// (eqs 37–43): the design derivatives of every geometric input of `ShellModel::new`.
#[derive(Clone, Debug, PartialEq)]
pub struct ShapeVelocity {
    /// Index of the surface's design parameter.
    pub parameter: usize,
    /// Per quadrature point (as `ShellModel::points`): `ẋ⁰,α`, `ṅ⁰`, `ṅ⁰,α`.
    pub points: Vec<SurfacePoint<f64>>,
    /// Per quadrature point: `V⁰ = ẋ̄⁰`, the design velocity of the mid-surface point itself
    /// (the contact's slave points sit there, `shell::contact::InitialGeometry`).
    pub positions: Vec<V3>,
    /// Per real particle (as `ShellModel::particles`): `u̇ = 0`, `ḋ⁰ = ḋ = ṅ(ξ_I)`, `ė1, ė2`.
    pub particles: Vec<ParticleState<f64>>,
    /// Per point and layer (as `ShellModel::history`): the initial frame's derivative,
    /// material state 0 (the virgin state does not depend on the geometry).
    pub history: Vec<PointHistory<f64>>,
}

/// A model and a surface that do not belong together, or a parameter the surface does not have.
fn check_model(model: &ShellModel, surface: &Surface<f64>) -> Result<(), GeometryError> {
    if surface.domain() != model.domain {
        return Err(GeometryError::InvalidRange {
            field: "surface domain".into(),
            start: surface.domain()[0][0],
            end: surface.domain()[0][1],
            expected: format!("the model's parameter domain {:?}", model.domain),
        });
    }
    Ok(())
}

/// The first lamina vector's hint of real particle `i`: the symmetry plane's normal on a
/// symmetry edge (design-independent), else `x,1` (as `ShellModel::new`).
fn hint(model: &ShellModel, i: usize) -> Option<V3> {
    model.symmetry.lamina_hint(i)
}

impl ShapeVelocity {
    /// The design velocity of `surface`'s design parameter `parameter` on `model` (built on
    /// `surface`). Errors: a parameter the surface does not have, a model on another
    /// parameter domain, a degenerate normal at a particle or point.
    pub fn new(
        model: &ShellModel,
        surface: &Surface<f64>,
        parameter: usize,
    ) -> Result<Self, GeometryError> {
        check_model(model, surface)?;
        let (points, positions): (Vec<_>, Vec<_>) = model
            .points
            .iter()
            .map(|p| {
                let [u, v] = p.uv;
                let s = surface.eval(u, v);
                s.normal()?;
                let sd = surface.design_velocity(parameter, u, v)?;
                Ok((SurfacePoint::from_derivs_dot(&s, &sd), sd.x))
            })
            .collect::<Result<Vec<_>, GeometryError>>()?
            .into_iter()
            .unzip();
        let particles = model
            .particle_uv
            .iter()
            .enumerate()
            .map(|(i, &[u, v])| {
                let s = surface.eval(u, v);
                let n = s.normal()?;
                let sd = surface.design_velocity(parameter, u, v)?;
                let nd = SurfacePoint::from_derivs_dot(&s, &sd).n;
                let (t, td) = match hint(model, i) {
                    Some(h) => (h, V3::zeros()),
                    None => (s.xu, sd.xu),
                };
                Ok(ParticleState {
                    u: V3::zeros(),
                    d: nd,
                    d0: nd,
                    e: lamina_vectors_dot(&n, &nd, &t, &td),
                })
            })
            .collect::<Result<Vec<_>, GeometryError>>()?;
        let nl = model.thickness_rule.len();
        let history = model
            .points
            .iter()
            .zip(&points)
            .flat_map(|(p, dot)| {
                let h = PointHistory {
                    frame: p.surface.initial_frame_dot(dot),
                    material: MaterialState::virgin(),
                };
                std::iter::repeat_n(h, nl)
            })
            .collect();
        Ok(ShapeVelocity {
            parameter,
            points,
            positions,
            particles,
            history,
        })
    }
}

/// The initial geometry of `model` in a dual scalar `D`, built from `surface` with its design
/// parameters in `D` (`seeds[k]`: the derivative parts of parameter `k`, length
/// `D::DIRECTIONS`), with the model's own constructors ([`initial_particle`],
/// [`initial_histories`]) as `ShellModel::new` builds it in `f64`: per quadrature point
/// the [`SurfacePoint`], per particle `d = d⁰ = n(ξ_I)` and the lamina vectors, per point and
/// layer the initial frame with the virgin material state.
pub fn dual_geometry<D: DesignDual>(
    model: &ShellModel,
    surface: &Surface<f64>,
    seeds: &[Vec<f64>],
) -> Result<DualGeometry<D>, GeometryError> {
    check_model(model, surface)?;
    let values = surface.parameter_values();
    let p: Vec<D> = values
        .iter()
        .enumerate()
        .map(|(k, &x)| match seeds.get(k) {
            Some(s) => D::from_parts(x, s),
            None => D::cst(x),
        })
        .collect();
    let s = surface.with_design_parameters::<D>(&p)?;
    let (points, positions): (Vec<_>, Vec<_>) = model
        .points
        .iter()
        .map(|q| {
            let sd = s.eval(D::cst(q.uv[0]), D::cst(q.uv[1]));
            sd.normal()?;
            Ok((SurfacePoint::from_derivs(&sd), sd.x))
        })
        .collect::<Result<Vec<_>, GeometryError>>()?
        .into_iter()
        .unzip();
    let particles = model
        .particle_uv
        .iter()
        .enumerate()
        .map(|(i, &uv)| initial_particle(&s, uv, hint(model, i)))
        .collect::<Result<Vec<_>, GeometryError>>()?;
    let history = initial_histories(points.iter(), model.thickness_rule.len());
    Ok(DualGeometry {
        points,
        positions,
        particles,
        history,
        surface: s,
    })
}

/// The initial geometry in a dual scalar ([`dual_geometry`]).
#[derive(Clone, Debug)]
pub struct DualGeometry<D> {
    /// Per quadrature point.
    pub points: Vec<SurfacePoint<D>>,
    /// Per quadrature point: the mid-surface position `x̄⁰`.
    pub positions: Vec<Vector3<D>>,
    /// Per real particle (initial states).
    pub particles: Vec<ParticleState<D>>,
    /// Per point and layer (initial histories).
    pub history: Vec<PointHistory<D>>,
    /// The surface itself, its design parameters in `D`.
    pub surface: Surface<D>,
}
