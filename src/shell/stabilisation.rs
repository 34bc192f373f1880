//! Director-filter stabilisation: a stiffness on the part of the particles' director
//! increments that the reproducing-kernel approximation filters out (docs/stability.md).
//!
//! The director field at a point is `d(ξ) = n⁰(ξ) + Σ_J Ψ_J(ξ) (d_J − d_J⁰)`. A coefficient
//! vector that alternates in sign from particle to particle in both directions (a
//! checkerboard) reaches the points with about 2 % of its amplitude (quadratic basis, supports
//! of 3 spacings), so its bending and shear stiffness is about 1e-4 of a smooth field's, while
//! the geometric term of the director update, `∂²d_I/∂α² · m_I`, acts on the coefficients
//! themselves, unfiltered. Under load it drives the checkerboard to zero stiffness.
//!
//! The remedy penalises, per step, the difference between each particle's director increment
//! and the RK interpolant of all of them at the particle:
//!
//! ```text
//! g_I = δd_I − Σ_J Ψ_J(ξ_I) δd_J,   δd_J = (α_J1 e1_J + α_J2 e2_J) × d_Jⁿ,
//! E_s = ½ κ Σ_I |g_I|²,   κ = ε E t³ / (12 (1 − ν²))
//! ```
//!
//! `g` vanishes for every director increment field whose coefficients are samples of a
//! quadratic (the basis reproduces quadratics), so smooth solutions feel it only through the
//! third-order remainder, while the checkerboard gets a stiffness `κ` per particle: that of
//! a bending mode of wavelength of the order of the spacing. The term is linear in the rotation
//! increments of the step (the lamina vectors and directors are the committed ones), so its
//! residual `κ Bᵀ B α` and tangent `κ Bᵀ B` are exact and symmetric positive semi-definite.
//! It enters the problem as the prescribed configuration-dependent load `f = −κ Bᵀ B α`
//! ([`super::load::Load::DirectorFilter`]).
//!
//! **Support.** `Ψ_J(ξ_I)` are by default the model's own RK functions. They may instead be
//! built with the same basis, kernel function and image particles on supports `scale` times
//! the model's ([`DirectorFilter::with_filter_support`], case key
//! `integration.director_stabilisation_support`). On a regular lattice the penalty per unit `ε`
//! of a coefficient pattern of wave vector `ω` is `(1 − ψ̂(ω))²`: a smaller support keeps more
//! of it at the checkerboard `ω h = (π, π)` than at the smooth wavelengths that a point load's
//! under-resolved rotations carry (docs/stability.md §8). The rows still vanish on quadratics,
//! and their reach (and the tangent's pattern) does not grow.
//!
//! **Design derivative.** `Ψ_J(ξ_I)` lives on the parameter domain (the particles' `(u, v)`
//! and the kernels do not move with any design variable), so at a fixed increment `α` the
//! force depends on the design only through `κ(E, ν, t)` and the committed directors and
//! lamina vectors in `B`:
//!
//! ```text
//! ḟ = −κ̇ Bᵀ B α − κ (Ḃᵀ B α + Bᵀ Ḃ α),   κ̇ = κ (Ė/E + 2ν ν̇/(1 − ν²) + 3 ṫ/t),
//! Ḃ_IJ = c_IJ [ė1_J × d_J + e1_J × ḋ_J,  ė2_J × d_J + e2_J × ḋ_J]
//! ```
//!
//! ([`DirectorFilter::add_design_derivative`], hand-derived; the dual-number reference
//! evaluates [`DirectorFilter::force_with`] on its dual committed state instead.)
//!
//! **Strength.** [`FilterStrength::Bending`] sets the constant `κ` above for every particle.
//! [`FilterStrength::DirectorForce`] sets it per particle from the destabilising term itself:
//! at the start of a step (`α = 0` about the committed lamina vectors) the geometric block of
//! particle `I`'s two rotations is `∂²d_I/∂α_b∂α_γ · m_I = −(m_I · d_I) δ_bγ`
//! ([`ShellModel::director_force_normals`]), so
//!
//! ```text
//! E_s = ½ Σ_I κ_I |g_I|²,   κ_I = ε max(0, m_I · d_I) + φ E t³ / (12 (1 − ν²))
//! ```
//!
//! (committed state, frozen in the step; the floor `φ`, default 0, is a small constant part)
//!
//! restores to a checkerboard what that block takes from it (ε of order 1–2) and vanishes
//! where the director forces do not destabilise, in particular in the first step from an
//! unstressed state: a linear analysis is unchanged. The `κ_I` are recomputed when a step is
//! committed ([`DirectorFilter::update`]), so within a step the term stays quadratic in the
//! increment with the exact symmetric tangent `Σ_I κ_I B_Iᵀ B_I`. Its design derivative would
//! need that of the committed director forces, which the sensitivity methods do not carry: they
//! refuse it ([`super::load::Load::takes_state`]).

use super::model::ShellModel;
use super::point::{ParticleState, DOFS_PER_PARTICLE};
use super::ShellError;
use crate::meshfree::{ShapeFunctions, ShapeValues};
use crate::scalar::Real;
use nalgebra::{Matrix3x2, Vector2, Vector3};

/// How the stiffness of the stabilisation is set (module documentation; case key
/// `integration.director_stabilisation_strength`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FilterStrength {
    /// `κ = ε E t³ / (12 (1 − ν²))` for every particle (`"bending"`).
    #[default]
    Bending,
    /// `κ_I = ε max(0, m_I · d_I)` per particle from the committed director forces
    /// (`"director-force"`).
    DirectorForce,
}

impl FilterStrength {
    /// The name of the case format.
    pub fn name(self) -> &'static str {
        match self {
            FilterStrength::Bending => "bending",
            FilterStrength::DirectorForce => "director-force",
        }
    }
}

/// The stabilisation of one model (module documentation).
#[derive(Debug, Clone)]
pub struct DirectorFilter {
    /// The factor `ε`.
    epsilon: f64,
    /// How `κ` is set.
    strength: FilterStrength,
    /// `κ = ε E t³ / (12 (1 − ν²))` ([`FilterStrength::Bending`]).
    kappa: f64,
    /// Per real particle `κ_I` ([`FilterStrength::DirectorForce`]; empty otherwise).
    kappa_rows: Vec<f64>,
    /// The floor of [`FilterStrength::DirectorForce`], `φ E t³ / (12 (1 − ν²))`, added to
    /// every `κ_I`.
    floor: f64,
    /// Per real particle `I`: `(shape-function particle j, coefficient δ_Ij − Ψ_j(ξ_I))`.
    rows: Vec<Vec<(usize, f64)>>,
}

/// Per row: `(source particle, block)` mapping the source's two rotation increments to `g_I`.
type Blocks<T> = Vec<Vec<(usize, Matrix3x2<T>)>>;

impl DirectorFilter {
    /// The stabilisation of `model` with factor `epsilon` (> 0, finite) and the constant
    /// stiffness ([`FilterStrength::Bending`]).
    pub fn new(model: &ShellModel, epsilon: f64) -> Result<Self, ShellError> {
        Self::with_strength(model, epsilon, FilterStrength::Bending, 0.0)
    }

    /// The stabilisation of `model` with factor `epsilon` (> 0, finite) and the stiffness set
    /// by `strength`; for [`FilterStrength::DirectorForce`] from the model's committed state,
    /// plus `floor` (≥ 0, finite) times the bending stiffness `E t³ / (12 (1 − ν²))` (ignored
    /// for [`FilterStrength::Bending`]).
    pub fn with_strength(
        model: &ShellModel,
        epsilon: f64,
        strength: FilterStrength,
        floor: f64,
    ) -> Result<Self, ShellError> {
        let mp = &model.material;
        let kappa = Self::stiffness(epsilon, mp.young, mp.poisson, model.thickness);
        let rows = model_rows(model)?;
        let mut filter = DirectorFilter {
            epsilon,
            strength,
            kappa,
            kappa_rows: Vec::new(),
            floor: Self::stiffness(floor, mp.young, mp.poisson, model.thickness),
            rows,
        };
        filter.update(model)?;
        Ok(filter)
    }

    /// Recompute the per-particle stiffness from the model's committed state
    /// ([`FilterStrength::DirectorForce`]: `κ_I = ε max(0, m_I · d_I) + φ E t³/(12 (1 − ν²))`);
    /// nothing for the constant stiffness. Called when a step is committed.
    pub fn update(&mut self, model: &ShellModel) -> Result<(), ShellError> {
        if self.strength == FilterStrength::DirectorForce {
            let s = model.director_force_normals()?;
            if s.len() != self.rows.len() {
                return Err(ShellError::Dimension {
                    expected: self.rows.len(),
                    got: s.len(),
                });
            }
            let (e, floor) = (self.epsilon, self.floor);
            self.kappa_rows = s.iter().map(|v| e * v.max(0.0) + floor).collect();
        }
        Ok(())
    }

    /// The rows from RK functions whose supports are the model's times `scale` (in `(0, 1]`;
    /// 1 keeps the model's own functions), with the model's basis and kernel function (module
    /// documentation, "Support"). Where such a function is not defined at a particle (too few
    /// particles in the smaller support for the basis, at a boundary without a symmetry
    /// plane), that row takes the smallest of `scale · 1.25^k` that is, up to the model's own.
    pub fn with_filter_support(
        mut self,
        model: &ShellModel,
        scale: f64,
    ) -> Result<Self, ShellError> {
        if !(scale.is_finite() && scale > 0.0 && scale <= 1.0) {
            return Err(ShellError::InvalidInput(format!(
                "director filter support scale {scale}: expected a number in (0, 1] (the \
                 filter's support over the kernel's)"
            )));
        }
        if scale == 1.0 {
            return Ok(self);
        }
        let sf = &model.shape_functions;
        let mut ladder = Vec::new();
        let mut s = scale;
        while s < 1.0 {
            let set = ShapeFunctions::new(
                sf.particles().to_vec(),
                sf.supports().iter().map(|a| [a[0] * s, a[1] * s]).collect(),
                sf.basis(),
            )
            .map_err(|e| ShellError::InvalidInput(format!("director filter support: {e}")))?
            .with_kernel(sf.kernel());
            ladder.push(set);
            s *= 1.25;
        }
        let mut sv = ShapeValues::new();
        for (i, row) in self.rows.iter_mut().enumerate() {
            let uv = model.particle_uv[i];
            if ladder.iter().any(|set| set.evaluate(uv, &mut sv).is_ok()) {
                *row = filter_row(i, &sv);
            }
        }
        Ok(self)
    }

    /// How the stiffness is set.
    pub fn strength(&self) -> FilterStrength {
        self.strength
    }

    /// The stiffness of row (real particle) `i`.
    pub fn row_kappa(&self, i: usize) -> f64 {
        match self.strength {
            FilterStrength::Bending => self.kappa,
            FilterStrength::DirectorForce => self.kappa_rows[i],
        }
    }

    /// `κ = ε E t³ / (12 (1 − ν²))` in scalar `T`.
    fn stiffness<T: Real>(epsilon: f64, young: T, poisson: T, thickness: T) -> T {
        young * thickness.powi(3) * epsilon / ((T::one() - poisson * poisson) * 12.0)
    }

    /// The factor `ε`.
    pub fn epsilon(&self) -> f64 {
        self.epsilon
    }

    /// The stiffness `κ` of the model it was built for (the constant of
    /// [`FilterStrength::Bending`]; [`DirectorFilter::row_kappa`] gives each row's).
    pub fn kappa(&self) -> f64 {
        self.kappa
    }

    /// The stiffness `κ(E, ν, t)` for another material and thickness, in scalar `T` (the
    /// dual-number reference's seeded design).
    pub fn kappa_of<T: Real>(&self, young: T, poisson: T, thickness: T) -> T {
        Self::stiffness(self.epsilon, young, poisson, thickness)
    }

    /// `κ̇ = κ (Ė/E + 2ν ν̇/(1 − ν²) + 3 ṫ/t)` at `(E, ν, t)` for the rates `(Ė, ν̇, ṫ)`.
    pub fn kappa_dot(&self, [e, nu, t]: [f64; 3], [e_dot, nu_dot, t_dot]: [f64; 3]) -> f64 {
        self.kappa_of(e, nu, t)
            * (e_dot / e + 2.0 * nu * nu_dot / (1.0 - nu * nu) + 3.0 * t_dot / t)
    }

    /// The filter rows: per real particle `I`, `(shape-function particle j, δ_Ij − Ψ_j(ξ_I))`.
    /// They depend on the parameter domain alone.
    pub fn rows(&self) -> &[Vec<(usize, f64)>] {
        &self.rows
    }

    /// Per row: the blocks `(source particle, c · det Q · [e1 × d, e2 × d])` of the committed
    /// states `state(j)` of the shape-function particles (an image's state is `Q` times its
    /// source's), mapping the source's two rotation increments to `g_I`, merged by source.
    fn blocks_of<T: Real>(
        &self,
        model: &ShellModel,
        state: impl Fn(usize) -> ParticleState<T>,
    ) -> Blocks<T> {
        self.rows
            .iter()
            .map(|row| {
                let mut out: Vec<(usize, Matrix3x2<T>)> = Vec::with_capacity(row.len());
                for &(j, c) in row {
                    let st = state(j);
                    let (src, det) = model.dof_source(j);
                    let a1: Vector3<T> = st.e[0].cross(&st.d) * T::cst(c * det);
                    let a2: Vector3<T> = st.e[1].cross(&st.d) * T::cst(c * det);
                    let b = Matrix3x2::from_columns(&[a1, a2]);
                    match out.iter_mut().find(|(s, _)| *s == src) {
                        Some(t) => t.1 += b,
                        None => out.push((src, b)),
                    }
                }
                out
            })
            .collect()
    }

    /// The blocks on the model's committed state.
    fn blocks(&self, model: &ShellModel) -> Blocks<f64> {
        self.blocks_of(model, |j| model.particle_state(j))
    }
}

const ROT: usize = 3;

/// The [`DirectorResolution::unresolved_share`] above which `shelldsa run` warns that a
/// checkerboard has taken over the director field.
pub const UNRESOLVED_SHARE_WARNING: f64 = 0.5;

/// The [`DirectorResolution::step_share`] above which `shelldsa run` warns that a step's
/// director changes are mostly a checkerboard (docs/stability.md §10: at most 0.57 on the
/// shipped cases that follow their references, 0.95–0.98 where the mode takes a path over).
pub const UNRESOLVED_STEP_SHARE_WARNING: f64 = 0.75;

/// A step whose director changes are at most this fraction of those since the reference state
/// ([`DirectorResolution::step_change_ratio`]) moved the directors only by the convergence
/// noise of its states (the default Newton tolerance is 1e-8 relative), so its
/// [`DirectorResolution::step_share`] is the share of that noise and is not reported. Measured
/// on the bending case (`verification/cylindrical-bending`): its real steps move at least
/// 7e-5 of the accumulated changes; after the punch's separation, where nothing moves, 3.6e-11,
/// and the last two steps 8e-17 and 1e-18, whose shares of round-off read 0.55 and 0.76.
pub const NEGLIGIBLE_STEP_CHANGE: f64 = 1e-8;

/// Director changes since the reference state whose root mean square over the real particles
/// ([`DirectorResolution::change_rms`]) is at most this are the round-off of the unit directors
/// (`10³ ε`), and their shares are not reported: a plate translated onto a die without
/// rotating (`tests/contact_case.rs`) has changes of 6.9e-16 whose share read 0.92.
pub const NEGLIGIBLE_DIRECTOR_CHANGE: f64 = 1e3 * f64::EPSILON;

/// How much of the particles' director changes the RK approximation leaves out: the
/// diagnostic of the checkerboard mode (docs/stability.md), for any director field and
/// stabilisation.
///
/// With the filter rows `g_I = Δd_I − Σ_J Ψ_J(ξ_I) Δd_J` of the module documentation applied to
/// the changes since the reference state, `Δd_J = d_J − d_J⁰` (images mapped from their
/// sources), the share is
///
/// ```text
/// s = ( Σ_I |g_I|² / Σ_I |Δd_I|² )^½    over the real particles I.
/// ```
///
/// The rows vanish on changes whose coefficients are samples of a quadratic, so a smooth
/// rotation field gives a share of the order of its third-order remainder (at most a few
/// per cent on the shipped cases), while a checkerboard, which the approximation passes to
/// the points with about 2 % of its amplitude, gives a share near 1.
///
/// Measured on the shipped cases (`director_unresolved` in results.json, 2026-11-27): runs
/// that follow their reference stay at or below 0.25 over their whole paths (the linear
/// pinched cylinder 0.19, whose point load leaves the rotations near it under-resolved; the
/// stabilised semi-cylinder and pull-out cylinder 0.04 and 0.11; the hinged roof and the
/// bending case 0.06; the plastic hemisphere 0.015 at 17², and 0.25 at 49² as its path
/// drifts), while the semi-cylinder and the pull-out cylinder without stabilisation, whose
/// paths the checkerboard takes over, reach 0.89 and 0.76. [`UNRESOLVED_SHARE_WARNING`]
/// lies between.
#[derive(Debug, Clone)]
pub struct DirectorResolution {
    rows: Vec<Vec<(usize, f64)>>,
    /// The directors of every shape-function particle (images included) at the last
    /// [`DirectorResolution::advance`].
    last: Vec<Vector3<f64>>,
}

impl DirectorResolution {
    /// The rows of `model`'s own RK functions at its real particles.
    pub fn new(model: &ShellModel) -> Result<Self, ShellError> {
        let rows = model_rows(model)?;
        let last = (0..model.shape_functions.particles().len())
            .map(|j| model.particle_state(j).d)
            .collect();
        Ok(DirectorResolution { rows, last })
    }

    /// The share `s` on the model's committed state (0 where no director has changed).
    pub fn unresolved_share(&self, model: &ShellModel) -> f64 {
        self.share_of(|j| {
            let st = model.particle_state(j);
            st.d - st.d0
        })
    }

    /// The share of the changes since the last [`DirectorResolution::advance`] (since
    /// construction before the first): of the last step's changes when advanced once per
    /// committed step.
    pub fn step_share(&self, model: &ShellModel) -> f64 {
        self.share_of(|j| model.particle_state(j).d - self.last[j])
    }

    /// The root mean square of the directors' changes since the reference state,
    /// `(Σ_I |d_I − d_I⁰|² / n)^½` over the `n` real particles.
    pub fn change_rms(&self, model: &ShellModel) -> f64 {
        let n = self.rows.len();
        if n > 0 {
            (self.total_sq(model) / n as f64).sqrt()
        } else {
            0.0
        }
    }

    /// The size of the changes since the last [`DirectorResolution::advance`] relative to
    /// those since the reference state, `(Σ_I |d_I − d_I^last|² / Σ_I |d_I − d_I⁰|²)^½` over
    /// the real particles (0 where no director has changed).
    pub fn step_change_ratio(&self, model: &ShellModel) -> f64 {
        let all = self.total_sq(model);
        if all > 0.0 {
            let step: f64 = (0..self.rows.len())
                .map(|i| (model.particle_state(i).d - self.last[i]).norm_squared())
                .sum();
            (step / all).sqrt()
        } else {
            0.0
        }
    }

    /// `Σ_I |d_I − d_I⁰|²` over the real particles.
    fn total_sq(&self, model: &ShellModel) -> f64 {
        (0..self.rows.len())
            .map(|i| {
                let st = model.particle_state(i);
                (st.d - st.d0).norm_squared()
            })
            .sum()
    }

    /// Take the model's committed directors as the start of the next step.
    pub fn advance(&mut self, model: &ShellModel) {
        for (j, d) in self.last.iter_mut().enumerate() {
            *d = model.particle_state(j).d;
        }
    }

    fn share_of(&self, change: impl Fn(usize) -> Vector3<f64>) -> f64 {
        let changes: Vec<Vector3<f64>> = (0..self.last.len()).map(change).collect();
        let (mut left_out, mut all) = (0.0, 0.0);
        for (i, row) in self.rows.iter().enumerate() {
            let g: Vector3<f64> = row.iter().map(|&(j, c)| changes[j] * c).sum();
            left_out += g.norm_squared();
            all += changes[i].norm_squared();
        }
        if all > 0.0 {
            (left_out / all).sqrt()
        } else {
            0.0
        }
    }
}

/// The filter rows of `model`'s own RK functions at its real particles.
fn model_rows(model: &ShellModel) -> Result<Vec<Vec<(usize, f64)>>, ShellError> {
    (0..model.n_particles())
        .map(|i| Ok(filter_row(i, &model.shape_values(model.particle_uv[i])?)))
        .collect()
}

/// Row `i` of the filter, `(j, δ_ij − Ψ_j(ξ_i))`, from the RK functions `sv` at particle `i`.
fn filter_row(i: usize, sv: &ShapeValues) -> Vec<(usize, f64)> {
    let mut row: Vec<(usize, f64)> = sv.iter().map(|(j, psi, _)| (j, -psi)).collect();
    match row.iter_mut().find(|(j, _)| *j == i) {
        Some(t) => t.1 += 1.0,
        None => row.push((i, 1.0)),
    }
    row
}

/// The two rotation increments of source particle `s` in `q`.
fn alpha<T: Real>(q: &[T], s: usize) -> Vector2<T> {
    Vector2::new(
        q[DOFS_PER_PARTICLE * s + ROT],
        q[DOFS_PER_PARTICLE * s + ROT + 1],
    )
}

/// Subtract the two rotation rows `r` from source particle `s`'s entries of `f`.
fn sub_rotation<T: Real>(f: &mut [T], s: usize, r: Vector2<T>) {
    f[DOFS_PER_PARTICLE * s + ROT] -= r[0];
    f[DOFS_PER_PARTICLE * s + ROT + 1] -= r[1];
}

/// Add `f = −Σ_I κ_I B_Iᵀ B_I α` for the blocks `blocks` (row `I`'s stiffness `kappa(I)`).
fn apply<T: Real>(blocks: &Blocks<T>, kappa: impl Fn(usize) -> T, q: &[T], f: &mut [T]) {
    for (i, row) in blocks.iter().enumerate() {
        let mut g = Vector3::zeros();
        for (s, b) in row {
            g += b * alpha(q, *s);
        }
        let k = kappa(i);
        for (s, b) in row {
            sub_rotation(f, *s, b.transpose() * g * k);
        }
    }
}

impl DirectorFilter {
    /// Add `f = −Σ_I κ_I B_Iᵀ B_I α` (the rotation increments of `q`) into `f`, in scalar `T`,
    /// on the model's committed state and with its stiffness.
    pub fn force<T: Real>(
        &self,
        model: &ShellModel,
        q: &[T],
        f: &mut [T],
    ) -> Result<(), ShellError> {
        model.check_state_sizes(q.len(), f.len(), None)?;
        let blocks: Blocks<T> = self
            .blocks(model)
            .into_iter()
            .map(|row| row.into_iter().map(|(s, b)| (s, b.map(T::cst))).collect())
            .collect();
        apply(&blocks, |i| T::cst(self.row_kappa(i)), q, f);
        Ok(())
    }

    /// Add `f = −κ Bᵀ B α` into `f` in scalar `T` on the committed states `particles` of the
    /// real particles (as `ShellModel::particles`; the images follow their sources) with the
    /// stiffness `kappa`: the same force on another committed state and design (the dual
    /// reference's, [`super::load::LoadState`]). Only for the constant stiffness: the
    /// per-particle one depends on the committed director forces, which this does not take.
    pub fn force_with<T: Real>(
        &self,
        model: &ShellModel,
        particles: &[ParticleState<T>],
        kappa: T,
        q: &[T],
        f: &mut [T],
    ) -> Result<(), ShellError> {
        model.check_state_sizes(q.len(), f.len(), Some(particles.len()))?;
        self.constant_only("the force on another committed state and design")?;
        let blocks = self.blocks_of(model, |j| model.particle_state_in(j, particles));
        apply(&blocks, |_| kappa, q, f);
        Ok(())
    }

    /// Add the design derivative of the force at the fixed increment `q` into `f`,
    /// hand-derived (module documentation):
    /// `ḟ = −κ̇ Bᵀ B α − κ (Ḃᵀ B α + Bᵀ Ḃ α)`, with `Ḃ` from the committed states'
    /// sensitivities `particles_dot` (real particles; `ḋ`, `ė` are used) and `κ̇` from
    /// [`DirectorFilter::kappa_dot`].
    pub fn add_design_derivative(
        &self,
        model: &ShellModel,
        particles_dot: &[ParticleState<f64>],
        kappa_dot: f64,
        q: &[f64],
        f: &mut [f64],
    ) -> Result<(), ShellError> {
        model.check_state_sizes(q.len(), f.len(), Some(particles_dot.len()))?;
        self.constant_only("the design derivative")?;
        for row in &self.rows {
            // (source, B block, Ḃ block), merged by source.
            let mut bl: Vec<(usize, Matrix3x2<f64>, Matrix3x2<f64>)> =
                Vec::with_capacity(row.len());
            for &(j, c) in row {
                let st = model.particle_state(j);
                let sd = model.particle_state_in(j, particles_dot);
                let (src, det) = model.dof_source(j);
                let k = c * det;
                let b =
                    Matrix3x2::from_columns(&[st.e[0].cross(&st.d) * k, st.e[1].cross(&st.d) * k]);
                let bd = Matrix3x2::from_columns(&[
                    (sd.e[0].cross(&st.d) + st.e[0].cross(&sd.d)) * k,
                    (sd.e[1].cross(&st.d) + st.e[1].cross(&sd.d)) * k,
                ]);
                match bl.iter_mut().find(|(s, _, _)| *s == src) {
                    Some(t) => {
                        t.1 += b;
                        t.2 += bd;
                    }
                    None => bl.push((src, b, bd)),
                }
            }
            let mut g = Vector3::zeros();
            let mut g_dot = Vector3::zeros();
            for (s, b, bd) in &bl {
                let a = alpha(q, *s);
                g += b * a;
                g_dot += bd * a;
            }
            for (s, b, bd) in &bl {
                let r = b.transpose() * g * kappa_dot
                    + (bd.transpose() * g + b.transpose() * g_dot) * self.kappa;
                sub_rotation(f, *s, r);
            }
        }
        Ok(())
    }

    /// An error for `what` unless the stiffness is the constant one.
    fn constant_only(&self, what: &str) -> Result<(), ShellError> {
        match self.strength {
            FilterStrength::Bending => Ok(()),
            FilterStrength::DirectorForce => Err(ShellError::InvalidInput(format!(
                "director stabilisation with strength \"{}\": {what} is not implemented \
                 (it needs the design derivative of the committed director forces; expected \
                 strength \"{}\")",
                FilterStrength::DirectorForce.name(),
                FilterStrength::Bending.name()
            ))),
        }
    }

    /// Add the tangent `−Σ_I κ_I B_Iᵀ B_I` as global entries (independent of the increment;
    /// the entries of a row with `κ_I = 0` are kept, so the pattern does not change).
    pub fn add_stiffness(
        &self,
        model: &ShellModel,
        out: &mut Vec<(usize, usize, f64)>,
    ) -> Result<(), ShellError> {
        for (i, row) in self.blocks(model).into_iter().enumerate() {
            let kappa = self.row_kappa(i);
            for (s, bs) in &row {
                for (p, bp) in &row {
                    let k = bs.transpose() * bp * (-kappa);
                    for a in 0..2 {
                        for b in 0..2 {
                            out.push((
                                DOFS_PER_PARTICLE * s + ROT + a,
                                DOFS_PER_PARTICLE * p + ROT + b,
                                k[(a, b)],
                            ));
                        }
                    }
                }
            }
        }
        Ok(())
    }
}
