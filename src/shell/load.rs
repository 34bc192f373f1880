//! External loads on the shell, at load factor 1 (the driver scales them by λ).
//!
//! A load adds its generalised force `f_ext(q)` (5 components per particle: forces on `Δū_I`,
//! moments on `α_I`) for the increment `q` from the committed state: the discrete load linear
//! form `l(z̄)` of the paper's eq. 33 (and its follower generalisation). Configuration-dependent
//! loads (pressure following the surface, a moment acting through the current director) also
//! add their load stiffness `∂f_ext/∂q`; the problem's tangent is then `K − λ ∂f_ext/∂q` (the
//! linearised load term of eq. 36).
//!
//! Loads:
//! - [`PointForce`]: a dead point force at a parameter point, `f_I = Ψ_I(ξ_P) P`;
//! - [`Gravity`]: a dead load per unit initial area, `f_I = ∫ Ψ_I b dA⁰`;
//! - [`Pressure`]: a follower pressure normal to the current mid-surface,
//!   `f_I = ∫ p Ψ_I (x,1 × x,2) dξ`;
//! - [`Moment`]: a line moment per unit initial length on a parametric edge, acting through the
//!   rotation of the interpolated director, `δW = ∫ m · (d × δd)/|d|² ds`;
//! - [`EdgeForce`]: a dead force per unit initial length on a parametric edge,
//!   `f_I = ∫ Ψ_I p ds⁰`;
//! - the contact with rigid tools ([`ContactLoad`], `crate::shell::contact`), the director
//!   filter ([`DirectorFilter`]) and any of them held constant.
//!
//! [`Load`] is the one closed type of them all, which the problem owns and the design
//! sensitivity methods evaluate.
//!
//! Every load goes from global to point-local degrees of freedom through the model's one seam
//! ([`ShellModel::gather_local`], [`ShellModel::scatter_local`],
//! [`ShellModel::scatter_particle`], [`ShellModel::particle_state`]); a load stiffness is mapped
//! back with the transpose of the scatter ([`GatherMap`]), so a particle whose DOFs are a linear
//! map of other particles' (a symmetry image) is handled by the seam alone. The forces are
//! written once, generic over the scalar ([`Load::force`]), so that their dual-number Jacobian
//! is the reference of the hand-derived stiffness. Formulas, signs and derivations: `docs/loads.md`.

use super::gather::GatherMap;
use super::model::ShellModel;
use super::point::{director_first_derivatives, ParticleState, SurfacePoint, DOFS_PER_PARTICLE};
use super::point_sensitivity::particle_increment_dot;
use super::stabilisation::{DirectorFilter, FilterStrength};
use super::ShellError;
use crate::geometry::Surface;
use crate::kinematics::rotation::{director_derivatives, rotate_director};
use crate::meshfree::quadrature::gauss_legendre;
use crate::meshfree::Edge;
use crate::meshfree::{ParamBox, ShapeValues};
use crate::scalar::Real;
use crate::shell::contact::ShellContact;
use crate::shell::contact::{ContactInputs, InitialGeometry};
use nalgebra::{DMatrix, Matrix3, Vector3};
use std::sync::Arc;

type V3<T> = Vector3<T>;

/// How a load depends on the load factor `λ` of the nonlinear driver.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum LoadScaling {
    /// `λ f_ext(q)`: the driver's `factor` multiplies the load (forces, pressure, moments).
    #[default]
    Proportional,
    /// `f_ext(q; λ)`: the load is a given function of the level `λ` and is not scaled by it
    /// (contact with rigid tools moving along a path in the pseudo-time `λ`, a load held
    /// constant, the director filter). Its [`Load::add_force`] and [`Load::add_stiffness`]
    /// receive `factor = λ`.
    Prescribed,
}

/// An external load of the shell problem: every kind the model has. The force is written once
/// over any scalar ([`Load::force`]): the analysis evaluates it in `f64`, its dual-number
/// Jacobian in `q` is the reference of the hand-derived [`Load::add_stiffness`]
/// (`tests/shell_loads.rs`), and the dual-number design sensitivity reference evaluates the
/// same object on its dual committed state ([`LoadState`]).
#[derive(Clone, Debug)]
pub enum Load {
    /// A dead point force.
    PointForce(PointForce),
    /// A dead load per unit initial area.
    Gravity(Gravity),
    /// A follower pressure.
    Pressure(Pressure),
    /// A line moment on an edge, acting through the director.
    Moment(Moment),
    /// A dead force per unit initial length on an edge.
    EdgeForce(EdgeForce),
    /// Penalty contact with rigid tools moving with the pseudo-time (prescribed).
    Contact(ContactLoad),
    /// The director-filter stabilisation (prescribed: not scaled by the load factor).
    DirectorFilter(DirectorFilter),
    /// A load held at its full value at every load factor: the inner load at factor 1
    /// (prescribed).
    Constant(Box<Load>),
}

/// The contact with rigid tools as a load: the contact (shared, so that a run keeps a handle
/// for its per-step reports and gap tracking) and how its penalty was set.
#[derive(Clone, Debug)]
pub struct ContactLoad {
    /// The contact.
    pub contact: Arc<ShellContact>,
    /// `Some(c)` when the penalty is `ω = c E / t` (`penalty_factor`): a design sensitivity
    /// then differentiates `ω` with `E` and `t`, as a re-run does; `None` for a given `ω`.
    pub penalty_factor: Option<f64>,
}

impl ContactLoad {
    /// The contact's inputs on the committed state and design `s`: its particles, thickness,
    /// tool placements, initial geometry and the penalty (`ω = c E / t` follows `E` and `t`).
    pub fn inputs<'a, T: Real>(&self, s: &LoadState<'a, T>) -> ContactInputs<'a, T> {
        let penalty = match self.penalty_factor {
            Some(k) => s.young * k / s.thickness,
            None => T::cst(self.contact.penalty()),
        };
        ContactInputs {
            particles: s.particles,
            thickness: s.thickness,
            penalty,
            offsets: s.tool_offsets,
            rotations: s.tool_rotations,
            surfaces: s.tool_surfaces,
            initial: s.positions.map(|positions| InitialGeometry {
                positions,
                surfaces: s.surfaces,
            }),
        }
    }

    /// The forces the sheet exerts on the tools at the increment `q` from the committed state
    /// `s` and pseudo-time `factor` ([`ShellContact::tool_forces_with`]), in scalar `T`.
    pub fn tool_forces<T: Real>(
        &self,
        model: &ShellModel,
        s: &LoadState<'_, T>,
        q: &[T],
        factor: f64,
    ) -> Result<Vec<V3<T>>, ShellError> {
        self.contact
            .tool_forces_with(model, &self.inputs(s), q, factor)
    }
}

/// A committed state and design other than the model's own, in scalar `T`, for
/// [`Load::force`]: the dual-number reference's state of a group of design variables, whose
/// derivative parts are the carried sensitivities (committed displacements, directors and
/// lamina vectors, initial geometry, thickness, Young's modulus and Poisson's ratio, tool
/// positions).
#[derive(Clone, Copy, Debug)]
pub struct LoadState<'a, T> {
    /// Committed states of the real particles (as `ShellModel::particles`).
    pub particles: &'a [ParticleState<T>],
    /// Initial geometry `x̄⁰,α, n⁰, n⁰,α` per quadrature point (as `ShellModel::points`).
    pub surfaces: &'a [SurfacePoint<T>],
    /// Initial mid-surface position `x̄⁰` per quadrature point when it carries a shape design
    /// derivative (`None`: the contact's slave sites as built).
    pub positions: Option<&'a [V3<T>]>,
    /// The initial mid-surface in `T` when it carries a shape design derivative (`None`: the
    /// surface as built): where an edge force takes its arc-length element.
    pub surface: Option<&'a Surface<T>>,
    /// Shell thickness.
    pub thickness: T,
    /// Young's modulus (of a penalty `ω = c E / t`, of the director filter's `κ`).
    pub young: T,
    /// Poisson's ratio (of the director filter's `κ`).
    pub poisson: T,
    /// Per tool of the contact: a translation added to its path.
    pub tool_offsets: &'a [V3<T>],
    /// Per tool of the contact: a rotation vector of the tool as built about its pivot.
    pub tool_rotations: &'a [V3<T>],
    /// Per tool of the contact: its surface in `T`, seeded with tool-shape design variables
    /// (`None`: the tools' own surfaces).
    pub tool_surfaces: Option<&'a [crate::geometry::Surface<T>]>,
}

impl<T: Real> LoadState<'_, T> {
    /// The increment `q` with the derivative part of the committed displacements `ⁿū` added
    /// to its translations: a load that depends on `ⁿū + Δū` only (a follower pressure or edge
    /// force, evaluated on the model's f64 committed state) then carries `ⁿū̇`.
    fn shifted(&self, q: &[T]) -> Vec<T> {
        q.iter()
            .enumerate()
            .map(|(i, x)| {
                let (p, c) = (i / DOFS_PER_PARTICLE, i % DOFS_PER_PARTICLE);
                match self.particles.get(p) {
                    Some(st) if c < 3 => *x + st.u[c] - T::cst(st.u[c].value()),
                    _ => *x,
                }
            })
            .collect()
    }
}

impl Load {
    /// The kind, as the case format names it.
    pub fn kind(&self) -> &'static str {
        match self {
            Load::PointForce(_) => "point-force",
            Load::Gravity(_) => "gravity",
            Load::Pressure(_) => "pressure",
            Load::Moment(_) => "moment",
            Load::EdgeForce(_) => "edge-force",
            Load::Contact(_) => "contact",
            Load::DirectorFilter(_) => "director-stabilisation",
            Load::Constant(inner) => inner.kind(),
        }
    }

    /// How the load depends on the load factor.
    pub fn scaling(&self) -> LoadScaling {
        match self {
            Load::Contact(_) | Load::DirectorFilter(_) | Load::Constant(_) => {
                LoadScaling::Prescribed
            }
            _ => LoadScaling::Proportional,
        }
    }

    /// Whether `f_ext` depends on the configuration (then [`Load::add_stiffness`] is not
    /// empty).
    pub fn is_follower(&self) -> bool {
        match self {
            Load::PointForce(_) | Load::Gravity(_) => false,
            Load::EdgeForce(e) => e.is_follower(),
            Load::Pressure(_) | Load::Moment(_) | Load::Contact(_) | Load::DirectorFilter(_) => {
                true
            }
            Load::Constant(inner) => inner.is_follower(),
        }
    }

    /// For a load on an edge (an edge force or moment, also held constant): the design
    /// velocities of its edge points' initial geometry for `surface`'s design parameter
    /// `parameter`; empty for other loads.
    pub fn edge_velocities(
        &self,
        surface: &Surface<f64>,
        parameter: usize,
    ) -> Result<Vec<EdgeVelocity>, ShellError> {
        match self {
            Load::EdgeForce(e) => e.rule().velocities(surface, parameter),
            Load::Moment(m) => m.rule().velocities(surface, parameter),
            Load::Constant(inner) => inner.edge_velocities(surface, parameter),
            _ => Ok(Vec::new()),
        }
    }

    /// For a load on an edge: its edge points' initial geometry on `surface` in `T`; empty for
    /// other loads.
    pub fn edge_geometry_on<T: Real>(
        &self,
        surface: &Surface<T>,
    ) -> Result<Vec<EdgeGeometry<T>>, ShellError> {
        match self {
            Load::EdgeForce(e) => e.rule().geometry_on(surface),
            Load::Moment(m) => m.rule().geometry_on(surface),
            Load::Constant(inner) => inner.edge_geometry_on(surface),
            _ => Ok(Vec::new()),
        }
    }

    /// The edge force of this load (also inside [`Load::Constant`]).
    pub fn edge_force(&self) -> Option<&EdgeForce> {
        match self {
            Load::EdgeForce(e) => Some(e),
            Load::Constant(inner) => inner.edge_force(),
            _ => None,
        }
    }

    /// The contact of this load (also inside [`Load::Constant`]).
    pub fn contact(&self) -> Option<&ContactLoad> {
        match self {
            Load::Contact(c) => Some(c),
            Load::Constant(inner) => inner.contact(),
            _ => None,
        }
    }

    /// Whether [`Load::force`] takes a [`LoadState`]: every kind but the director filter with
    /// the per-particle strength (that of the committed director forces is not carried).
    pub fn takes_state(&self) -> bool {
        match self {
            Load::DirectorFilter(l) => l.strength() == FilterStrength::Bending,
            Load::Constant(inner) => inner.takes_state(),
            _ => true,
        }
    }

    /// Add `factor · f_ext(q)` into `f` in scalar `T` (global generalised DOFs; `q` is the
    /// generalised increment from the committed state); for a [`LoadScaling::Prescribed`]
    /// load `f_ext(q; λ)` with `λ = factor` (a [`Load::Constant`] evaluates its inner load at
    /// factor 1). `state`: `None` for the model's committed state and design as built; a
    /// [`LoadState`] for another one (the kinds of [`Load::takes_state`]). The contact is not
    /// tracked here ([`Load::add_force`] is).
    pub fn force<T: Real>(
        &self,
        model: &ShellModel,
        state: Option<&LoadState<'_, T>>,
        q: &[T],
        factor: f64,
        f: &mut [T],
    ) -> Result<(), ShellError> {
        match (self, state) {
            (Load::PointForce(l), _) => l.force(model, factor, f),
            (Load::Gravity(l), None) => l.force(model, q, factor, f),
            // A dead load per unit initial area: on the state's initial geometry.
            (Load::Gravity(l), Some(s)) => {
                l.force_with_surfaces(model, s.surfaces, s.thickness, factor, f)
            }
            (Load::Pressure(l), None) => l.force(model, q, factor, f),
            // The pressure depends on the committed displacement `ⁿū` and the increment `Δū`
            // only through their sum: the increment carries the state's `ⁿū̇`.
            (Load::Pressure(l), Some(s)) => {
                check_sizes(model, q.len(), None)?;
                l.force_with_surfaces(model, s.surfaces, &s.shifted(q), factor, f)
            }
            (Load::Moment(l), None) => l.force(model, q, factor, f),
            // On the state's committed directors and lamina vectors and its initial surface.
            (Load::Moment(l), Some(s)) => {
                l.force_with(model, Some(s.particles), s.surface, q, factor, f)
            }
            (Load::EdgeForce(l), None) => l.force(model, q, factor, f),
            // On the state's initial surface when it has one; a follower depends on `ⁿū + Δū`
            // as the pressure does.
            (Load::EdgeForce(l), Some(s)) => {
                check_sizes(model, q.len(), None)?;
                l.force_with(model, s.surface, &s.shifted(q), factor, f)
            }
            (Load::DirectorFilter(l), None) => l.force(model, q, f),
            // On the state's committed directors and lamina vectors, with κ(E, ν, t).
            (Load::DirectorFilter(l), Some(s)) => {
                let kappa = l.kappa_of(s.young, s.poisson, s.thickness);
                l.force_with(model, s.particles, kappa, q, f)
            }
            (Load::Contact(c), None) => c.contact.force_generic(model, q, factor, f),
            (Load::Contact(c), Some(s)) => c.contact.force_with(model, &c.inputs(s), q, factor, f),
            (Load::Constant(inner), s) => inner.force(model, s, q, 1.0, f),
        }
    }

    /// Add `factor · f_ext(q)` (a prescribed load: `f_ext(q; λ = factor)`) in `f64` on the
    /// model's committed state: [`Load::force`], with the contact's gaps tracked (the check
    /// for a tool crossing the sheet in one step).
    pub fn add_force(
        &self,
        model: &ShellModel,
        q: &[f64],
        factor: f64,
        f: &mut [f64],
    ) -> Result<(), ShellError> {
        match self {
            Load::Contact(c) => c.contact.force_tracked(model, q, factor, f),
            Load::Constant(inner) => inner.add_force(model, q, 1.0, f),
            _ => self.force(model, None, q, factor, f),
        }
    }

    /// Add `factor · ∂f_ext/∂q` (a prescribed load: `∂f_ext(q; λ)/∂q` with `λ = factor`) as
    /// global `(row, column, value)` entries, hand-derived (empty for a dead load).
    pub fn add_stiffness(
        &self,
        model: &ShellModel,
        q: &[f64],
        factor: f64,
        out: &mut Vec<(usize, usize, f64)>,
    ) -> Result<(), ShellError> {
        match self {
            Load::PointForce(_) | Load::Gravity(_) => Ok(()),
            Load::EdgeForce(l) => l.add_stiffness(model, q, factor, out),
            Load::Pressure(l) => l.add_stiffness(model, q, factor, out),
            Load::Moment(l) => l.add_stiffness(model, q, factor, out),
            Load::Contact(c) => c.contact.add_stiffness(model, q, factor, out),
            Load::DirectorFilter(l) => l.add_stiffness(model, out),
            Load::Constant(inner) => inner.add_stiffness(model, q, 1.0, out),
        }
    }
}

macro_rules! load_from {
    ($($kind:ident),*) => {
        $(impl From<$kind> for Load {
            fn from(l: $kind) -> Self {
                Load::$kind(l)
            }
        })*
    };
}
load_from!(PointForce, Gravity, Pressure, Moment, EdgeForce);

fn check_sizes(model: &ShellModel, q: usize, f: Option<usize>) -> Result<(), ShellError> {
    let n = model.n_dofs();
    for got in std::iter::once(q).chain(f) {
        if got != n {
            return Err(ShellError::Dimension { expected: n, got });
        }
    }
    Ok(())
}

fn check_finite(field: &str, v: &[f64]) -> Result<(), ShellError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(ShellError::InvalidInput(format!(
            "{field} = {v:?}: expected finite values"
        )))
    }
}

fn check_region(field: &str, region: &Option<ParamBox>) -> Result<(), ShellError> {
    if let Some(b) = region {
        let ok = (0..2).all(|k| b.lo[k].is_finite() && b.hi[k].is_finite() && b.lo[k] <= b.hi[k]);
        if !ok {
            return Err(ShellError::InvalidInput(format!(
                "{field} = {b:?}: expected finite corners with lo <= hi"
            )));
        }
    }
    Ok(())
}

/// The quadrature points of `model` inside `region` (all of them without one); an empty
/// selection is an error naming the region.
fn selected_points(
    model: &ShellModel,
    region: &Option<ParamBox>,
    what: &str,
) -> Result<Vec<usize>, ShellError> {
    let sel: Vec<usize> = (0..model.points.len())
        .filter(|&k| region.is_none_or(|b| b.contains(model.points[k].uv)))
        .collect();
    if sel.is_empty() {
        return Err(ShellError::InvalidInput(format!(
            "{what} region {region:?}: contains no quadrature point of the model ({} points)",
            model.points.len()
        )));
    }
    Ok(sel)
}

/// `[a]×`, the matrix of `v ↦ a × v`.
fn skew(a: &V3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -a[2], a[1], a[2], 0.0, -a[0], -a[1], a[0], 0.0)
}

/// A dead point force `P` at parameter coordinates `uv` (a point of the mid-surface),
/// distributed to the coefficients by the shape functions: `f_I = Ψ_I(ξ_P) P`.
#[derive(Clone, Debug, PartialEq)]
pub struct PointForce {
    /// Parameter coordinates of the load point.
    pub uv: [f64; 2],
    /// Force vector (global axes).
    pub force: [f64; 3],
}

impl PointForce {
    /// Add `factor · f` into `f` (dead: no dependence on the state).
    pub fn force<T: Real>(
        &self,
        model: &ShellModel,
        factor: f64,
        f: &mut [T],
    ) -> Result<(), ShellError> {
        check_sizes(model, f.len(), None)?;
        let mut sv = ShapeValues::new();
        model
            .shape_functions
            .evaluate(self.uv, &mut sv)
            .map_err(|e| ShellError::InvalidInput(format!("point force at {:?}: {e}", self.uv)))?;
        for (j, psi, _) in sv.iter() {
            let l = [
                T::cst(psi * self.force[0] * factor),
                T::cst(psi * self.force[1] * factor),
                T::cst(psi * self.force[2] * factor),
                T::zero(),
                T::zero(),
            ];
            model.scatter_particle(j, &l, f);
        }
        Ok(())
    }
}

/// A dead load per unit initial mid-surface area (gravity, self-weight: `b = ρ t g`), on the
/// whole surface or on the quadrature points inside a parameter box:
/// `f_I = ∫ Ψ_I b dA⁰ = Σ_qp Ψ_I b |x̄⁰,1 × x̄⁰,2| w` (the paper's eq. 33 with the body force
/// integrated through the thickness). Translations only.
///
/// Given per unit volume (`ρ g`), the load per unit area is `ρ g t`: it follows the thickness,
/// and a thickness design variable differentiates it ([`Gravity::add_thickness_derivative`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Gravity {
    load: [f64; 3],
    basis: GravityBasis,
    region: Option<ParamBox>,
}

/// What a [`Gravity`] load is given per.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GravityBasis {
    /// Force per unit area (`b`).
    Area,
    /// Force per unit volume (`ρ g`; per unit area `ρ g t`).
    Volume,
}

impl Gravity {
    /// Load `b` per unit area (global axes) over the whole surface.
    pub fn new(load: [f64; 3]) -> Result<Self, ShellError> {
        check_finite("gravity load per unit area", &load)?;
        Ok(Gravity {
            load,
            basis: GravityBasis::Area,
            region: None,
        })
    }
    /// Load `ρ g` per unit volume (global axes) over the whole surface: `ρ g t` per unit area.
    pub fn per_volume(load: [f64; 3]) -> Result<Self, ShellError> {
        check_finite("gravity load per unit volume", &load)?;
        Ok(Gravity {
            load,
            basis: GravityBasis::Volume,
            region: None,
        })
    }
    /// What the load is given per.
    pub fn basis(&self) -> GravityBasis {
        self.basis
    }
    /// The factor from the given load to the load per unit area: `t` per volume, else 1.
    fn per_area_factor<T: Real>(&self, thickness: T) -> T {
        match self.basis {
            GravityBasis::Area => T::one(),
            GravityBasis::Volume => thickness,
        }
    }
    /// The thickness design derivative of the force (hand-derived): per unit volume,
    /// `∂f_I/∂t · ṫ = ṫ ∫ Ψ_I ρg dA⁰`; nothing per unit area.
    pub fn add_thickness_derivative(
        &self,
        model: &ShellModel,
        t_dot: f64,
        factor: f64,
        f: &mut [f64],
    ) -> Result<(), ShellError> {
        check_sizes(model, f.len(), None)?;
        if self.basis == GravityBasis::Area || t_dot == 0.0 {
            return Ok(());
        }
        let per_thickness = Gravity {
            basis: GravityBasis::Area,
            ..self.clone()
        };
        let q = vec![0.0; f.len()];
        per_thickness.force(model, &q, factor * t_dot, f)
    }
    /// Restrict to the quadrature points inside `region` (a box that cuts through background
    /// cells integrates the cut cells only approximately).
    pub fn within(mut self, region: ParamBox) -> Result<Self, ShellError> {
        self.region = Some(region);
        check_region("gravity region", &self.region)?;
        Ok(self)
    }
    /// The load as given: per unit area, or per unit volume ([`Gravity::basis`]).
    pub fn load(&self) -> [f64; 3] {
        self.load
    }

    /// The shape design derivative of the force (hand-derived): with the design velocity
    /// `V,α = ẋ⁰,α` at every quadrature point (`velocity`, as `model.points`), the area element
    /// `|c|`, `c = x̄⁰,1 × x̄⁰,2`, changes by `n⁰ · (V,1 × x̄⁰,2 + x̄⁰,1 × V,2)`.
    pub fn add_design_derivative(
        &self,
        model: &ShellModel,
        velocity: &[SurfacePoint<f64>],
        factor: f64,
        f: &mut [f64],
    ) -> Result<(), ShellError> {
        check_sizes(model, f.len(), None)?;
        check_surfaces(model, velocity)?;
        for k in selected_points(model, &self.region, "gravity")? {
            let p = &model.points[k];
            let [x1, x2] = p.surface.x_a;
            let [v1, v2] = velocity[k].x_a;
            let c = x1.cross(&x2);
            let da_dot = c.dot(&(v1.cross(&x2) + x1.cross(&v2))) / c.norm()
                * p.weight
                * factor
                * self.per_area_factor(model.thickness);
            let local: Vec<f64> = p
                .shape
                .iter()
                .flat_map(|sh| {
                    let w = da_dot * sh.psi;
                    [
                        w * self.load[0],
                        w * self.load[1],
                        w * self.load[2],
                        0.0,
                        0.0,
                    ]
                })
                .collect();
            model.scatter_local(k, &local, f);
        }
        Ok(())
    }

    /// [`Gravity::force`] with the initial geometry of every quadrature point in `T`
    /// (`surfaces`, as `model.points`) and the thickness in `T`: the area element
    /// `|x̄⁰,1 × x̄⁰,2|` then carries a shape design derivative and a load per unit volume a
    /// thickness derivative (the dual reference).
    pub fn force_with_surfaces<T: Real>(
        &self,
        model: &ShellModel,
        surfaces: &[SurfacePoint<T>],
        thickness: T,
        factor: f64,
        f: &mut [T],
    ) -> Result<(), ShellError> {
        check_sizes(model, f.len(), None)?;
        check_surfaces(model, surfaces)?;
        let scale = self.per_area_factor(thickness);
        for k in selected_points(model, &self.region, "gravity")? {
            let p = &model.points[k];
            let s = &surfaces[k];
            let da = s.x_a[0].cross(&s.x_a[1]).norm() * scale * p.weight * factor;
            let local: Vec<T> = p
                .shape
                .iter()
                .flat_map(|sh| {
                    let w = da * sh.psi;
                    [
                        w * self.load[0],
                        w * self.load[1],
                        w * self.load[2],
                        T::zero(),
                        T::zero(),
                    ]
                })
                .collect();
            model.scatter_local(k, &local, f);
        }
        Ok(())
    }
}

/// One surface point per quadrature point of `model`.
fn check_surfaces<T>(model: &ShellModel, surfaces: &[SurfacePoint<T>]) -> Result<(), ShellError> {
    if surfaces.len() != model.points.len() {
        return Err(ShellError::Dimension {
            expected: model.points.len(),
            got: surfaces.len(),
        });
    }
    Ok(())
}

impl Gravity {
    /// Add `factor · f` into `f`, in scalar `T` (dead: `q` is checked for its size only).
    pub fn force<T: Real>(
        &self,
        model: &ShellModel,
        q: &[T],
        factor: f64,
        f: &mut [T],
    ) -> Result<(), ShellError> {
        check_sizes(model, q.len(), Some(f.len()))?;
        let scale = self.per_area_factor(model.thickness);
        for k in selected_points(model, &self.region, "gravity")? {
            let p = &model.points[k];
            let da = p.surface.x_a[0].cross(&p.surface.x_a[1]).norm() * scale * p.weight * factor;
            let local: Vec<T> = p
                .shape
                .iter()
                .flat_map(|s| {
                    let w = s.psi * da;
                    [
                        T::cst(self.load[0] * w),
                        T::cst(self.load[1] * w),
                        T::cst(self.load[2] * w),
                        T::zero(),
                        T::zero(),
                    ]
                })
                .collect();
            model.scatter_local(k, &local, f);
        }
        Ok(())
    }
}

/// A follower pressure `p` per unit current area, normal to the current mid-surface, on the
/// whole surface or on the quadrature points inside a parameter box:
///
/// `f_I = ∫ p Ψ_I (x̄,1 × x̄,2) dξ = Σ_qp w p Ψ_I (x̄,1 × x̄,2)`,
/// `x̄,α = x̄⁰,α + Σ_J Ψ_J,α (ū_J + Δū_J)`.
///
/// **Sign:** `x̄,1 × x̄,2 = n |x̄,1 × x̄,2|` with `n` the current normal, which starts as the
/// surface normal `n⁰ = x̄⁰,1 × x̄⁰,2 / |…|` of the geometry. A positive `p` pushes the surface
/// along `+n` (for a cylinder with outward `n⁰`, an internal pressure). Translations only; the
/// rotation DOFs carry no pressure work (a mid-surface load).
///
/// Load stiffness (hand-derived, `docs/loads.md`): the 3×3 block of particles `(I, J)` is
/// `∂f_I/∂Δū_J = Σ_qp w p Ψ_I (Ψ_J,2 [x̄,1]× − Ψ_J,1 [x̄,2]×)`; it is not symmetric in general
/// (a pressure on an open surface whose boundary moves is not conservative).
#[derive(Clone, Debug, PartialEq)]
pub struct Pressure {
    pressure: f64,
    region: Option<ParamBox>,
}

impl Pressure {
    /// Pressure `p` (sign: see the type's documentation) over the whole surface.
    pub fn new(pressure: f64) -> Result<Self, ShellError> {
        check_finite("pressure", &[pressure])?;
        Ok(Pressure {
            pressure,
            region: None,
        })
    }
    /// Restrict to the quadrature points inside `region`.
    pub fn within(mut self, region: ParamBox) -> Result<Self, ShellError> {
        self.region = Some(region);
        check_region("pressure region", &self.region)?;
        Ok(self)
    }
    /// The pressure.
    pub fn pressure(&self) -> f64 {
        self.pressure
    }

    /// `x̄,1`, `x̄,2` at point `k` for the gathered states and local increments.
    fn tangents<T: Real>(
        model: &ShellModel,
        k: usize,
        parts: &[ParticleState<T>],
        x: &[T],
    ) -> [V3<T>; 2] {
        let p = &model.points[k];
        Self::tangents_from(p.surface.x_a.map(|v| v.map(T::cst)), model, k, parts, x)
    }

    /// `x̄,α = x̄⁰,α + Σ_J Ψ_J,α (ū_J + Δū_J)` from the initial tangents `x0a` at point `k`.
    fn tangents_from<T: Real>(
        x0a: [V3<T>; 2],
        model: &ShellModel,
        k: usize,
        parts: &[ParticleState<T>],
        x: &[T],
    ) -> [V3<T>; 2] {
        let p = &model.points[k];
        let mut xa = x0a;
        for (n, (s, st)) in p.shape.iter().zip(parts).enumerate() {
            let q = &x[DOFS_PER_PARTICLE * n..DOFS_PER_PARTICLE * n + 3];
            let u = st.u + V3::new(q[0], q[1], q[2]);
            for (a, xa) in xa.iter_mut().enumerate() {
                *xa += u * T::cst(s.dpsi[a]);
            }
        }
        xa
    }
}

impl Pressure {
    /// The shape design derivative of the force at fixed state (hand-derived, the load term
    /// `l'_V` of eq 37 for a follower pressure): with the design velocity `V,α = ẋ⁰,α` of the
    /// initial geometry at every quadrature point (`velocity`, as `model.points`),
    /// `ḟ_I = p w λ (V,1 × x̄,2 + x̄,1 × V,2) Ψ_I` on the current tangents `x̄,α`.
    pub fn add_design_derivative(
        &self,
        model: &ShellModel,
        velocity: &[SurfacePoint<f64>],
        q: &[f64],
        factor: f64,
        f: &mut [f64],
    ) -> Result<(), ShellError> {
        check_sizes(model, q.len(), Some(f.len()))?;
        check_surfaces(model, velocity)?;
        for k in selected_points(model, &self.region, "pressure")? {
            let (parts, x) = model.gather_local(k, q);
            let [x1, x2] = Self::tangents(model, k, &parts, &x);
            let p = &model.points[k];
            let [v1, v2] = velocity[k].x_a;
            let c = (v1.cross(&x2) + x1.cross(&v2)) * (self.pressure * p.weight * factor);
            let local: Vec<f64> = p
                .shape
                .iter()
                .flat_map(|s| {
                    let v = c * s.psi;
                    [v[0], v[1], v[2], 0.0, 0.0]
                })
                .collect();
            model.scatter_local(k, &local, f);
        }
        Ok(())
    }

    /// [`Pressure::force`] with the initial geometry of every quadrature point in `T`
    /// (`surfaces`, as `model.points`): `x̄⁰,α` then carries a shape design derivative
    /// (the dual reference for shape design variables).
    pub fn force_with_surfaces<T: Real>(
        &self,
        model: &ShellModel,
        surfaces: &[SurfacePoint<T>],
        q: &[T],
        factor: f64,
        f: &mut [T],
    ) -> Result<(), ShellError> {
        check_sizes(model, q.len(), Some(f.len()))?;
        check_surfaces(model, surfaces)?;
        for k in selected_points(model, &self.region, "pressure")? {
            let (parts, x) = model.gather_local(k, q);
            let [x1, x2] = Self::tangents_from(surfaces[k].x_a, model, k, &parts, &x);
            let p = &model.points[k];
            let c = x1.cross(&x2) * T::cst(self.pressure * p.weight * factor);
            let local: Vec<T> = p
                .shape
                .iter()
                .flat_map(|s| {
                    let v = c * T::cst(s.psi);
                    [v[0], v[1], v[2], T::zero(), T::zero()]
                })
                .collect();
            model.scatter_local(k, &local, f);
        }
        Ok(())
    }
}

impl Pressure {
    /// Add `factor · f(q)` into `f`, in scalar `T`.
    pub fn force<T: Real>(
        &self,
        model: &ShellModel,
        q: &[T],
        factor: f64,
        f: &mut [T],
    ) -> Result<(), ShellError> {
        check_sizes(model, q.len(), Some(f.len()))?;
        for k in selected_points(model, &self.region, "pressure")? {
            let (parts, x) = model.gather_local(k, q);
            let [x1, x2] = Self::tangents(model, k, &parts, &x);
            let p = &model.points[k];
            let c = x1.cross(&x2) * T::cst(self.pressure * p.weight * factor);
            let local: Vec<T> = p
                .shape
                .iter()
                .flat_map(|s| {
                    let v = c * T::cst(s.psi);
                    [v[0], v[1], v[2], T::zero(), T::zero()]
                })
                .collect();
            model.scatter_local(k, &local, f);
        }
        Ok(())
    }
}

impl Pressure {
    /// Add `factor · ∂f/∂q` as global entries (hand-derived: the type's documentation).
    pub fn add_stiffness(
        &self,
        model: &ShellModel,
        q: &[f64],
        factor: f64,
        out: &mut Vec<(usize, usize, f64)>,
    ) -> Result<(), ShellError> {
        check_sizes(model, q.len(), None)?;
        let mut map = GatherMap::new(model);
        for k in selected_points(model, &self.region, "pressure")? {
            let (parts, x) = model.gather_local(k, q);
            let [x1, x2] = Self::tangents(model, k, &parts, &x);
            let p = &model.points[k];
            let pw = self.pressure * p.weight * factor;
            let (s1, s2) = (skew(&x1), skew(&x2));
            let n = p.shape.len();
            let mut kl = DMatrix::zeros(3 * n, 3 * n);
            for (i, si) in p.shape.iter().enumerate() {
                for (j, sj) in p.shape.iter().enumerate() {
                    let block = (s1 * sj.dpsi[1] - s2 * sj.dpsi[0]) * (pw * si.psi);
                    kl.view_mut((3 * i, 3 * j), (3, 3)).copy_from(&block);
                }
            }
            let local: Vec<(usize, usize)> = p
                .neighbours
                .iter()
                .flat_map(|&j| (0..3).map(move |c| (j, c)))
                .collect();
            map.add_triplets(model, &local, &kl, out);
        }
        Ok(())
    }
}

/// The design velocity of an edge rule's initial geometry at one edge point, for one shape
/// design variable: `ẋ̄⁰,u`, `ẋ̄⁰,v` and `ṅ⁰`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgeVelocity {
    /// `ẋ̄⁰,u`, `ẋ̄⁰,v`.
    pub x_a: [V3<f64>; 2],
    /// `ṅ⁰`.
    pub n: V3<f64>,
}

/// The initial geometry of an edge rule at one edge point in `T`: `x̄⁰,u`, `x̄⁰,v` and `n⁰`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgeGeometry<T> {
    /// `x̄⁰,u`, `x̄⁰,v`.
    pub x_a: [V3<T>; 2],
    /// `n⁰ = x̄⁰,u × x̄⁰,v / |…|`.
    pub n: V3<T>,
}

/// The Gauss rule of a load on an edge (an edge force or moment), with the model it was built
/// for: the edge points, their weights, initial geometry and RK shape functions (`edge_rule`).
#[derive(Clone, Debug, PartialEq)]
pub struct EdgeRule {
    /// What the rule belongs to, in errors.
    what: &'static str,
    n_dofs: usize,
    points: Vec<EdgePoint>,
}

impl EdgeRule {
    fn new(
        model: &ShellModel,
        surface: &Surface<f64>,
        edge: Edge,
        intervals: usize,
        points: usize,
        what: &'static str,
    ) -> Result<Self, ShellError> {
        Ok(EdgeRule {
            what,
            n_dofs: model.n_dofs(),
            points: edge_rule(model, surface, edge, intervals, points, what)?,
        })
    }

    /// Total edge length in the initial configuration (the sum of the rule's weights).
    pub fn edge_length(&self) -> f64 {
        self.points.iter().map(|p| p.weight).sum()
    }

    /// The design velocities of the edge points' initial geometry for `surface`'s design
    /// parameter `parameter` (`surface`: the one the load was built on): `ẋ̄⁰,α` from the
    /// surface, `ṅ⁰ = (ċ − n⁰ (n⁰·ċ))/|c|` with `c = x̄⁰,u × x̄⁰,v`.
    pub fn velocities(
        &self,
        surface: &Surface<f64>,
        parameter: usize,
    ) -> Result<Vec<EdgeVelocity>, ShellError> {
        let what = self.what;
        self.points
            .iter()
            .map(|ep| {
                let sd = surface
                    .design_velocity(parameter, ep.uv[0], ep.uv[1])
                    .map_err(|e| {
                        ShellError::InvalidInput(format!(
                            "{what}: design velocity at edge point {:?}: {e}",
                            ep.uv
                        ))
                    })?;
                let c = ep.x0a[0].cross(&ep.x0a[1]);
                let c_dot = sd.xu.cross(&ep.x0a[1]) + ep.x0a[0].cross(&sd.xv);
                let n = c / c.norm();
                Ok(EdgeVelocity {
                    x_a: [sd.xu, sd.xv],
                    n: (c_dot - n * n.dot(&c_dot)) / c.norm(),
                })
            })
            .collect()
    }

    /// The edge points' initial geometry on `surface` in `T`.
    pub fn geometry_on<T: Real>(
        &self,
        surface: &Surface<T>,
    ) -> Result<Vec<EdgeGeometry<T>>, ShellError> {
        let what = self.what;
        self.points
            .iter()
            .map(|ep| {
                let sd = surface.eval(T::cst(ep.uv[0]), T::cst(ep.uv[1]));
                let n = sd.normal().map_err(|e| {
                    ShellError::InvalidInput(format!("{what} edge point {:?}: {e}", ep.uv))
                })?;
                Ok(EdgeGeometry {
                    x_a: [sd.xu, sd.xv],
                    n,
                })
            })
            .collect()
    }

    /// The load is bound to the model it was built for (its edge shape functions are
    /// evaluated once): another model is rejected by its DOF count.
    fn check_model(&self, model: &ShellModel) -> Result<(), ShellError> {
        if model.n_dofs() != self.n_dofs {
            return Err(ShellError::InvalidInput(format!(
                "{} built for a model with {} DOFs, used with one of {}",
                self.what,
                self.n_dofs,
                model.n_dofs()
            )));
        }
        Ok(())
    }
}

/// The rule of a line load on `edge` of the parameter domain of `surface`: `intervals` equal
/// intervals of the edge's parameter line with `points` Gauss–Legendre points each, the
/// weights times the initial arc-length element `|x̄⁰,t|`, the initial normals and the RK shape
/// functions (`what` names the load in errors).
fn edge_rule(
    model: &ShellModel,
    surface: &Surface<f64>,
    edge: Edge,
    intervals: usize,
    points: usize,
    what: &str,
) -> Result<Vec<EdgePoint>, ShellError> {
    if intervals == 0 {
        return Err(ShellError::InvalidInput(format!(
            "{what} edge rule: intervals = 0, expected at least 1"
        )));
    }
    let rule = gauss_legendre(points)
        .map_err(|e| ShellError::InvalidInput(format!("{what} edge rule: {e}")))?;
    let dom = surface.domain();
    // Fixed coordinate index and value, and the running coordinate's range.
    let (fixed, value, run) = match edge {
        Edge::UMin => (0, dom[0][0], dom[1]),
        Edge::UMax => (0, dom[0][1], dom[1]),
        Edge::VMin => (1, dom[1][0], dom[0]),
        Edge::VMax => (1, dom[1][1], dom[0]),
    };
    let mut sv = ShapeValues::new();
    let mut pts = Vec::with_capacity(intervals * points);
    for i in 0..intervals {
        let a = run[0] + (run[1] - run[0]) * i as f64 / intervals as f64;
        let b = run[0] + (run[1] - run[0]) * (i + 1) as f64 / intervals as f64;
        let (xs, ws) = rule.mapped(a, b);
        for (&t, &w) in xs.iter().zip(&ws) {
            let mut uv = [0.0; 2];
            uv[fixed] = value;
            uv[1 - fixed] = t;
            let sd = surface.eval(uv[0], uv[1]);
            let n0 = sd
                .normal()
                .map_err(|e| ShellError::InvalidInput(format!("{what} edge point {uv:?}: {e}")))?;
            let tangent = if fixed == 0 { sd.xv } else { sd.xu };
            model
                .shape_functions
                .evaluate(uv, &mut sv)
                .map_err(|e| ShellError::InvalidInput(format!("{what} edge point {uv:?}: {e}")))?;
            pts.push(EdgePoint {
                uv,
                gauss: w,
                along: 1 - fixed,
                x0a: [sd.xu, sd.xv],
                weight: w * tangent.norm(),
                n0,
                shape: sv.iter().map(|(j, psi, _)| (j, psi)).collect(),
                grads: sv.iter().map(|(_, _, g)| g).collect(),
            });
        }
    }
    Ok(pts)
}

/// A force per unit length on a parametric edge, integrated with the Gauss rule of
/// `edge_rule` on the edge's parameter line (translations only; `docs/loads.md`):
///
/// - **dead** ([`EdgeForce::on_edge`]): `p` in global axes per unit initial length,
///   `f_I = ∫_edge Ψ_I p ds⁰ = Σ_g Ψ_I(ξ_g) p |x̄⁰,t(ξ_g)| w_g`;
/// - **follower** ([`EdgeForce::follower_on_edge`]): components `c = (c_o, c_n, c_t)` per unit
///   current length along the edge's current frame, the outward in-plane normal `ô`, the
///   surface normal `n̂ = a/|a|` (`a = x̄,u × x̄,v`) and the tangent `t̂ = x̄,t/|x̄,t|`:
///   `f_I = Σ_g w_g Ψ_I [c_o σ (n̂ × x̄,t) + c_n |x̄,t| n̂ + c_t x̄,t]`, where
///   `x̄,α = x̄⁰,α + Σ_J Ψ_J,α (ū_J + Δū_J)` and `ô = σ n̂ × t̂` (`σ = ±1` by the edge: `n̂ × t̂`
///   points into increasing `v` along a `v`-edge's `u` and into decreasing `u` along a
///   `u`-edge's `v`).
///
/// The follower's load stiffness (hand-derived, [`EdgeForce::add_stiffness`]): with
/// `N_J = (I − n̂n̂ᵀ)(Ψ_J,v [x̄,u]× − Ψ_J,u [x̄,v]×)/|a|` (the rate of `n̂` per `Δū_J`), the
/// block of particles `(I, J)` is `Σ_g w_g Ψ_I [c_o σ (Ψ_J,t [n̂]× − [x̄,t]× N_J)
/// + c_n (|x̄,t| N_J + Ψ_J,t n̂ x̄,tᵀ/|x̄,t|) + c_t Ψ_J,t I]`.
#[derive(Clone, Debug, PartialEq)]
pub struct EdgeForce {
    force: [f64; 3],
    /// `Some(σ)` for a follower (the outward normal's orientation), `None` for a dead force.
    follower: Option<f64>,
    rule: EdgeRule,
}

impl EdgeForce {
    /// The dead force `force` per unit initial length (global axes) on `edge` of `surface`
    /// (the surface `model` was built on), integrated with `intervals` intervals of `points`
    /// Gauss points.
    pub fn on_edge(
        model: &ShellModel,
        surface: &Surface<f64>,
        edge: Edge,
        force: [f64; 3],
        intervals: usize,
        points: usize,
    ) -> Result<Self, ShellError> {
        Self::with_frame(model, surface, edge, force, None, (intervals, points))
    }

    /// The follower force with components `[c_o, c_n, c_t]` per unit current length along the
    /// edge's current outward in-plane normal, surface normal and tangent (the type's
    /// documentation), on `edge` of `surface`.
    pub fn follower_on_edge(
        model: &ShellModel,
        surface: &Surface<f64>,
        edge: Edge,
        components: [f64; 3],
        intervals: usize,
        points: usize,
    ) -> Result<Self, ShellError> {
        let sigma = match edge {
            Edge::UMin | Edge::VMax => 1.0,
            Edge::UMax | Edge::VMin => -1.0,
        };
        Self::with_frame(
            model,
            surface,
            edge,
            components,
            Some(sigma),
            (intervals, points),
        )
    }

    /// The force `force` on `edge` of `surface`, dead (`follower = None`) or a follower with
    /// the outward normal's orientation `Some(σ)`, integrated with `rule = (intervals, points)`.
    fn with_frame(
        model: &ShellModel,
        surface: &Surface<f64>,
        edge: Edge,
        force: [f64; 3],
        follower: Option<f64>,
        (intervals, points): (usize, usize),
    ) -> Result<Self, ShellError> {
        check_finite("edge force per unit length", &force)?;
        Ok(EdgeForce {
            force,
            follower,
            rule: EdgeRule::new(model, surface, edge, intervals, points, "edge force")?,
        })
    }

    /// The force per unit length: global components (dead) or `[c_o, c_n, c_t]` (follower).
    pub fn per_length(&self) -> [f64; 3] {
        self.force
    }

    /// Whether the force follows the edge's current frame.
    pub fn is_follower(&self) -> bool {
        self.follower.is_some()
    }

    /// The edge rule.
    pub fn rule(&self) -> &EdgeRule {
        &self.rule
    }
}

/// The current tangents of an edge point and the quantities of the follower force built on
/// them.
struct EdgeFrame<T> {
    /// `x̄,u`, `x̄,v`.
    xa: [V3<T>; 2],
    /// `a = x̄,u × x̄,v` and `|a|`.
    a_norm: T,
    /// `n̂ = a/|a|`.
    n: V3<T>,
    /// `x̄,t` and `|x̄,t|`.
    xt: V3<T>,
    xt_norm: T,
}

impl<T: Real> EdgeFrame<T> {
    fn new(xa: [V3<T>; 2], along: usize) -> Self {
        let a = xa[0].cross(&xa[1]);
        let a_norm = a.norm();
        let xt = xa[along];
        EdgeFrame {
            xa,
            a_norm,
            n: a / a_norm,
            xt,
            xt_norm: xt.norm(),
        }
    }

    /// `c_o σ (n̂ × x̄,t) + c_n |x̄,t| n̂ + c_t x̄,t`.
    fn force(&self, c: [f64; 3], sigma: f64) -> V3<T> {
        self.n.cross(&self.xt) * T::cst(c[0] * sigma)
            + self.n * (self.xt_norm * c[1])
            + self.xt * T::cst(c[2])
    }
}

impl EdgeFrame<f64> {
    /// The force's rate for tangent rates `dxa` (`ẋ̄,u`, `ẋ̄,v`).
    fn force_rate(&self, c: [f64; 3], sigma: f64, along: usize, dxa: [V3<f64>; 2]) -> V3<f64> {
        let da = dxa[0].cross(&self.xa[1]) + self.xa[0].cross(&dxa[1]);
        let dn = (da - self.n * self.n.dot(&da)) / self.a_norm;
        let dxt = dxa[along];
        (dn.cross(&self.xt) + self.n.cross(&dxt)) * (c[0] * sigma)
            + (dn * self.xt_norm + self.n * (self.xt.dot(&dxt) / self.xt_norm)) * c[1]
            + dxt * c[2]
    }
}

impl EdgeForce {
    /// Add `factor · f` into `f`, in scalar `T`, on the model's committed state and the
    /// increment `q` (a dead force does not depend on it).
    pub fn force<T: Real>(
        &self,
        model: &ShellModel,
        q: &[T],
        factor: f64,
        f: &mut [T],
    ) -> Result<(), ShellError> {
        self.force_with(model, None, q, factor, f)
    }

    /// [`EdgeForce::force`] on the initial surface `surface` in `T` when given (the state's
    /// design, the dual reference): the tangents `x̄⁰,α` of every edge point evaluated on it,
    /// so that the arc-length element (dead) or the current frame (follower) carries the shape
    /// design derivative. The rule's points and shape functions live on the parameter domain
    /// and do not move.
    pub fn force_with<T: Real>(
        &self,
        model: &ShellModel,
        surface: Option<&Surface<T>>,
        q: &[T],
        factor: f64,
        f: &mut [T],
    ) -> Result<(), ShellError> {
        self.rule.check_model(model)?;
        check_sizes(model, q.len(), Some(f.len()))?;
        let initial = surface.map(|s| self.rule.geometry_on(s)).transpose()?;
        for (g, ep) in self.rule.points.iter().enumerate() {
            let x0a = match &initial {
                Some(t) => t[g].x_a,
                None => ep.x0a.map(|v| v.map(T::cst)),
            };
            match self.follower {
                None => {
                    let s = match &initial {
                        Some(_) => x0a[ep.along].norm() * (ep.gauss * factor),
                        None => T::cst(ep.weight * factor),
                    };
                    self.scatter_dead(model, ep, s, f);
                }
                Some(sigma) => {
                    let frame = EdgeFrame::new(current_tangents(model, ep, x0a, q), ep.along);
                    let v = frame.force(self.force, sigma) * T::cst(ep.gauss * factor);
                    self.scatter(model, ep, v, f);
                }
            }
        }
        Ok(())
    }

    /// The shape design derivative of the force at the increment `q` (hand-derived), with
    /// `velocities` from [`EdgeRule::velocities`] (one per edge point). Dead:
    /// only the arc-length element changes, `d|x̄⁰,t|/dτ = x̄⁰,t · ẋ̄⁰,t / |x̄⁰,t|`. Follower: the
    /// current tangents change by `ẋ̄,α = ẋ̄⁰,α`, and the frame with them (the rate of the
    /// type's force expression). Adds `factor · ḟ` into `f`.
    pub fn add_design_derivative(
        &self,
        model: &ShellModel,
        velocities: &[EdgeVelocity],
        q: &[f64],
        factor: f64,
        f: &mut [f64],
    ) -> Result<(), ShellError> {
        self.rule.check_model(model)?;
        check_sizes(model, q.len(), Some(f.len()))?;
        if velocities.len() != self.rule.points.len() {
            return Err(ShellError::Dimension {
                expected: self.rule.points.len(),
                got: velocities.len(),
            });
        }
        for (ep, v) in self.rule.points.iter().zip(velocities) {
            match self.follower {
                None => {
                    let t = ep.x0a[ep.along];
                    let s = t.dot(&v.x_a[ep.along]) / t.norm() * (ep.gauss * factor);
                    self.scatter_dead(model, ep, s, f);
                }
                Some(sigma) => {
                    let frame = EdgeFrame::new(current_tangents(model, ep, ep.x0a, q), ep.along);
                    let v = frame.force_rate(self.force, sigma, ep.along, v.x_a);
                    self.scatter(model, ep, v * (ep.gauss * factor), f);
                }
            }
        }
        Ok(())
    }

    /// Add `factor · ∂f/∂q` as global entries (hand-derived: the type's documentation); none
    /// for a dead force. Every pair of an edge point's particles is entered, zero or not, so
    /// that the pattern built from the entries at `q = 0` holds the later ones.
    pub fn add_stiffness(
        &self,
        model: &ShellModel,
        q: &[f64],
        factor: f64,
        out: &mut Vec<(usize, usize, f64)>,
    ) -> Result<(), ShellError> {
        let Some(sigma) = self.follower else {
            return Ok(());
        };
        self.rule.check_model(model)?;
        check_sizes(model, q.len(), None)?;
        let mut map = GatherMap::new(model);
        for ep in &self.rule.points {
            let frame = EdgeFrame::new(current_tangents(model, ep, ep.x0a, q), ep.along);
            let n = ep.shape.len();
            let w = ep.gauss * factor;
            let mut kl = DMatrix::zeros(3 * n, 3 * n);
            for (j, g) in ep.grads.iter().enumerate() {
                // The force's rate per unit Δū_J along each axis: columns of the 3×3 block.
                let cols: [V3<f64>; 3] = std::array::from_fn(|c| {
                    let e = V3::ith(c, 1.0);
                    frame.force_rate(self.force, sigma, ep.along, [e * g[0], e * g[1]])
                });
                for (i, &(_, psi_i)) in ep.shape.iter().enumerate() {
                    for (c, col) in cols.iter().enumerate() {
                        for r in 0..3 {
                            kl[(3 * i + r, 3 * j + c)] = w * psi_i * col[r];
                        }
                    }
                }
            }
            let local: Vec<(usize, usize)> = ep
                .shape
                .iter()
                .flat_map(|&(j, _)| (0..3).map(move |c| (j, c)))
                .collect();
            let rows: Vec<Vec<(usize, f64)>> = local
                .iter()
                .map(|&(j, c)| map.rows(model, j)[c].clone())
                .collect();
            for (a, ra) in rows.iter().enumerate() {
                for (b, rb) in rows.iter().enumerate() {
                    let v = kl[(a, b)];
                    for &(i, gi) in ra {
                        for &(jj, gj) in rb {
                            out.push((i, jj, gi * v * gj));
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// Scatter `s · Ψ_J · p` (the dead force `p`) of edge point `ep` to the translations of
    /// its particles.
    fn scatter_dead<T: Real>(&self, model: &ShellModel, ep: &EdgePoint, s: T, f: &mut [T]) {
        for &(j, psi) in &ep.shape {
            let c = s * psi;
            let local = [
                c * self.force[0],
                c * self.force[1],
                c * self.force[2],
                T::zero(),
                T::zero(),
            ];
            model.scatter_particle(j, &local, f);
        }
    }

    /// Scatter the force `v` of edge point `ep` (its weight included) to the translations of
    /// its particles, `Ψ_J v` each.
    fn scatter<T: Real>(&self, model: &ShellModel, ep: &EdgePoint, v: V3<T>, f: &mut [T]) {
        for &(j, psi) in &ep.shape {
            let c = v * T::cst(psi);
            let local = [c[0], c[1], c[2], T::zero(), T::zero()];
            model.scatter_particle(j, &local, f);
        }
    }
}

/// The current tangents `x̄,α = x̄⁰,α + Σ_J Ψ_J,α (ū_J + Δū_J)` at edge point `ep`, from the
/// initial ones `x0a`, the model's committed displacements and the increment `q`.
fn current_tangents<T: Real>(
    model: &ShellModel,
    ep: &EdgePoint,
    x0a: [V3<T>; 2],
    q: &[T],
) -> [V3<T>; 2] {
    let mut xa = x0a;
    for (&(j, _), g) in ep.shape.iter().zip(&ep.grads) {
        let x = model.particle_dofs(j, q);
        let u = model.particle_state(j).u.map(T::cst) + V3::new(x[0], x[1], x[2]);
        for (a, xa) in xa.iter_mut().enumerate() {
            *xa += u * T::cst(g[a]);
        }
    }
    xa
}

/// One point of an edge rule, with its shape functions.
#[derive(Clone, Debug, PartialEq)]
struct EdgePoint {
    uv: [f64; 2],
    /// Gauss weight on the parameter line.
    gauss: f64,
    /// The running parameter: 0 (`u`, a `v`-edge) or 1 (`v`, a `u`-edge).
    along: usize,
    /// The initial tangents `x̄⁰,u`, `x̄⁰,v` (`x̄⁰,t` is the one along the edge).
    x0a: [V3<f64>; 2],
    /// Gauss weight times the initial arc-length element `|x̄⁰,t|`.
    weight: f64,
    /// Initial normal `n⁰`.
    n0: V3<f64>,
    /// Shape-function particles and `Ψ_J`.
    shape: Vec<(usize, f64)>,
    /// `∇Ψ_J` on the parameter domain, parallel to `shape`.
    grads: Vec<[f64; 2]>,
}

/// A line moment `m` per unit initial length on a parametric edge, about a fixed (global) axis,
/// acting through the rotation of the RK-interpolated director
/// `d(ξ) = n⁰(ξ) + Σ_J Ψ_J(ξ) (d_J − d⁰_J)`:
///
/// `δW = ∫ m · δθ ds`, `δθ = d × δd / |d|²`, `δd = Σ_J Ψ_J Σ_β (∂d_J/∂α_β) δα_Jβ`,
///
/// so the generalised moment on `α_Jβ` is `f_Jβ = ∫ Ψ_J (∂d_J/∂α_β) · g ds` with
/// `g = (m × d)/|d|²`, and the load stiffness is
/// `∂f_Jβ/∂α_Kγ = ∫ Ψ_J [δ_JK (∂²d_J/∂α_β∂α_γ) · g + (∂d_J/∂α_β) · A Ψ_K (∂d_K/∂α_γ)] ds` with
/// `A = ∂g/∂d = [m]×/|d|² − 2 (m × d) dᵀ/|d|⁴`. No force on the translations.
///
/// **Conservative** exactly when `d` stays in the plane normal to `m` (planar bending about a
/// fixed axis): then `m · δθ = |m| δφ` with `φ` the angle of `d` in that plane, the load has the
/// potential `−|m| ∫ φ ds` and its stiffness is symmetric. When `d` leaves that plane,
/// `(d × δd)·m/|d|²` is not a total differential and the stiffness has a skew part
/// (measured in `tests/shell_loads.rs`; `docs/loads.md`).
///
/// The edge is integrated with `intervals` equal sub-intervals of `points` Gauss–Legendre points
/// each; the load is bound to the model it was built for (its shape functions at the edge
/// points are computed once).
#[derive(Clone, Debug, PartialEq)]
pub struct Moment {
    moment: [f64; 3],
    rule: EdgeRule,
}

impl Moment {
    /// The moment `moment` per unit initial length (global axes) on `edge` of the parameter
    /// domain of `surface` (the surface `model` was built on).
    pub fn on_edge(
        model: &ShellModel,
        surface: &Surface<f64>,
        edge: Edge,
        moment: [f64; 3],
        intervals: usize,
        points: usize,
    ) -> Result<Self, ShellError> {
        check_finite("moment per unit length", &moment)?;
        Ok(Moment {
            moment,
            rule: EdgeRule::new(model, surface, edge, intervals, points, "moment")?,
        })
    }

    /// The moment per unit length.
    pub fn moment(&self) -> [f64; 3] {
        self.moment
    }

    /// The edge rule.
    pub fn rule(&self) -> &EdgeRule {
        &self.rule
    }

    /// The model, the sizes of `q` and `f`, and of a given particle list (`particles`).
    fn check_inputs(
        &self,
        model: &ShellModel,
        particles: Option<usize>,
        q: usize,
        f: usize,
    ) -> Result<(), ShellError> {
        self.rule.check_model(model)?;
        model.check_state_sizes(q, f, particles)
    }
}

impl Moment {
    /// Add `factor · f(q)` into `f`, in scalar `T`.
    pub fn force<T: Real>(
        &self,
        model: &ShellModel,
        q: &[T],
        factor: f64,
        f: &mut [T],
    ) -> Result<(), ShellError> {
        self.force_with(model, None, None, q, factor, f)
    }

    /// [`Moment::force`] on a given committed state and design in `T` (the dual reference):
    /// the committed particles `particles` (real ones, as `ShellModel::particles`; `None`: the
    /// model's) and the initial surface `surface` (`None`: as built), which gives the edge
    /// points' initial normals `n⁰` and arc-length elements.
    pub fn force_with<T: Real>(
        &self,
        model: &ShellModel,
        particles: Option<&[ParticleState<T>]>,
        surface: Option<&Surface<T>>,
        q: &[T],
        factor: f64,
        f: &mut [T],
    ) -> Result<(), ShellError> {
        self.check_inputs(model, particles.map(<[_]>::len), q.len(), f.len())?;
        let m = V3::from(self.moment).map(|v| T::cst(v * factor));
        let mut map = GatherMap::new(model);
        let initial = surface.map(|s| self.rule.geometry_on(s)).transpose()?;
        for (g, ep) in self.rule.points.iter().enumerate() {
            let (mut d, weight) = match &initial {
                Some(geo) => (geo[g].n, geo[g].x_a[ep.along].norm() * ep.gauss),
                None => (ep.n0.map(T::cst), T::cst(ep.weight)),
            };
            let mut da = Vec::with_capacity(ep.shape.len());
            for &(j, psi) in &ep.shape {
                let st: ParticleState<T> = match particles {
                    Some(p) => model.particle_state_in(j, p),
                    None => model.particle_state(j).lift(),
                };
                let alpha = [map.gather(model, j, 3, q), map.gather(model, j, 4, q)];
                let dj = rotate_director(&st.d, &st.e[0], &st.e[1], alpha);
                d += (dj - st.d0) * T::cst(psi);
                da.push(director_first_derivatives(&st, alpha));
            }
            let g = m.cross(&d) * (weight / d.norm_squared());
            for (&(j, psi), dj) in ep.shape.iter().zip(&da) {
                let local = [
                    T::zero(),
                    T::zero(),
                    T::zero(),
                    dj[0].dot(&g) * psi,
                    dj[1].dot(&g) * psi,
                ];
                model.scatter_particle(j, &local, f);
            }
        }
        Ok(())
    }
}

impl Moment {
    /// The design derivative of the force at the increment `q` (hand-derived), adding
    /// `factor · ḟ` into `f`: with the committed particles' sensitivities `particles_dot` (real
    /// particles, `ⁿḋ, ḋ⁰, ⁿė`; `None`: left out) the end-of-step directors change by
    /// `ⁿḋ_J + Δḋ_J` and their derivatives `(∂d_J/∂α_β)˙` (Rodrigues' formula differentiated,
    /// as the point kernel's); with the edge points' design velocities `velocities` (`None`:
    /// left out) the interpolated director's `n⁰` by `ṅ⁰` and the weight by the length
    /// element's `x̄⁰,t · ẋ̄⁰,t / |x̄⁰,t|`. Then, with `ḋ = ṅ⁰ + Σ_J Ψ_J (ⁿḋ_J + Δḋ_J − ḋ⁰_J)`,
    /// `ġ = w [m × ḋ − 2 (d·ḋ) g/w] / |d|² + ẇ g/w` and
    /// `ḟ_Jβ = Σ_g Ψ_J [(∂d_J/∂α_β)˙ · g + (∂d_J/∂α_β) · ġ]`.
    pub fn add_design_derivative(
        &self,
        model: &ShellModel,
        particles_dot: Option<&[ParticleState<f64>]>,
        velocities: Option<&[EdgeVelocity]>,
        q: &[f64],
        factor: f64,
        f: &mut [f64],
    ) -> Result<(), ShellError> {
        self.check_inputs(model, particles_dot.map(<[_]>::len), q.len(), f.len())?;
        if let Some(v) = velocities {
            if v.len() != self.rule.points.len() {
                return Err(ShellError::Dimension {
                    expected: self.rule.points.len(),
                    got: v.len(),
                });
            }
        }
        let m = V3::from(self.moment) * factor;
        let zero = [0.0; DOFS_PER_PARTICLE];
        for (g, ep) in self.rule.points.iter().enumerate() {
            let (mut d, mut d_dot, w, mut w_dot) = (ep.n0, V3::zeros(), ep.weight, 0.0);
            if let Some(v) = velocities {
                let t = ep.x0a[ep.along];
                d_dot = v[g].n;
                w_dot = t.dot(&v[g].x_a[ep.along]) / t.norm() * ep.gauss;
            }
            let mut da = Vec::with_capacity(ep.shape.len());
            let mut da_dot = Vec::with_capacity(ep.shape.len());
            for &(j, psi) in &ep.shape {
                let st = model.particle_state(j);
                let x = model.particle_dofs(j, q);
                let alpha = [x[3], x[4]];
                d += (rotate_director(&st.d, &st.e[0], &st.e[1], alpha) - st.d0) * psi;
                da.push(director_first_derivatives(&st, alpha));
                match particles_dot {
                    Some(p) => {
                        let sd = model.particle_state_in(j, p);
                        let (_, dd, dda) = particle_increment_dot(&st, &sd, &x, &zero);
                        d_dot += (sd.d + dd - sd.d0) * psi;
                        da_dot.push(dda);
                    }
                    None => da_dot.push([V3::zeros(); 2]),
                }
            }
            let dd = d.norm_squared();
            let mxd = m.cross(&d);
            let gv = mxd * (w / dd);
            let g_dot =
                (m.cross(&d_dot) * w - mxd * (2.0 * w * d.dot(&d_dot) / dd) + mxd * w_dot) / dd;
            for ((&(j, psi), a), a_dot) in ep.shape.iter().zip(&da).zip(&da_dot) {
                let local = [
                    0.0,
                    0.0,
                    0.0,
                    (a_dot[0].dot(&gv) + a[0].dot(&g_dot)) * psi,
                    (a_dot[1].dot(&gv) + a[1].dot(&g_dot)) * psi,
                ];
                model.scatter_particle(j, &local, f);
            }
        }
        Ok(())
    }
}

impl Moment {
    /// Add `factor · ∂f/∂q` as global entries (hand-derived: the type's documentation).
    pub fn add_stiffness(
        &self,
        model: &ShellModel,
        q: &[f64],
        factor: f64,
        out: &mut Vec<(usize, usize, f64)>,
    ) -> Result<(), ShellError> {
        self.rule.check_model(model)?;
        check_sizes(model, q.len(), None)?;
        let m = V3::from(self.moment) * factor;
        let mut map = GatherMap::new(model);
        for ep in &self.rule.points {
            let mut d = ep.n0;
            let mut dirs = Vec::with_capacity(ep.shape.len());
            for &(j, psi) in &ep.shape {
                let st = model.particle_state(j);
                let alpha = [map.gather(model, j, 3, q), map.gather(model, j, 4, q)];
                let h = director_derivatives(&st.d, &st.e[0], &st.e[1], alpha);
                d += (h.d - st.d0) * psi;
                dirs.push(h);
            }
            let dd = d.norm_squared();
            let mxd = m.cross(&d);
            let g = mxd * (ep.weight / dd);
            let a = (skew(&m) / dd - mxd * d.transpose() * (2.0 / (dd * dd))) * ep.weight;
            let n = ep.shape.len();
            let mut kl = DMatrix::zeros(2 * n, 2 * n);
            for (i, (&(_, pi), hi)) in ep.shape.iter().zip(&dirs).enumerate() {
                for (j, (&(_, pj), hj)) in ep.shape.iter().zip(&dirs).enumerate() {
                    for b in 0..2 {
                        for c in 0..2 {
                            let mut v = hi.d_a[b].dot(&(a * hj.d_a[c])) * (pi * pj);
                            if i == j {
                                v += hi.d_ab[b][c].dot(&g) * pi;
                            }
                            kl[(2 * i + b, 2 * j + c)] = v;
                        }
                    }
                }
            }
            let local: Vec<(usize, usize)> = ep
                .shape
                .iter()
                .flat_map(|&(j, _)| (3..5).map(move |c| (j, c)))
                .collect();
            map.add_triplets(model, &local, &kl, out);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn skew_is_the_cross_product_matrix() {
        let a = V3::new(0.3, -1.2, 2.0);
        let v = V3::new(-0.7, 0.4, 1.1);
        assert!((skew(&a) * v - a.cross(&v)).norm() < 1e-15);
    }
}
