//! Shell kinematics, stress update and internal force at one quadrature point (ξ, ζ), with the
//! consistent tangent from hand-derived directional derivatives (docs/shell-formulation.md §3–5).
//!
//! Configuration at step n and at a point:
//! `x̄ⁿ,α = x̄⁰,α + Σ Ψ_I,α ū_Iⁿ`, `dⁿ = n⁰ + Σ Ψ_I (d_Iⁿ − d_I⁰)` (and its ξ-derivatives;
//! with [`DirectorField::Normalised`] that interpolant divided by its length),
//! `Jⁿ = ∂ⁿx/∂(ξ1, ξ2, ζ) = [x̄ⁿ,1 + ζt/2 dⁿ,1 | x̄ⁿ,2 + ζt/2 dⁿ,2 | t/2 dⁿ]`.
//! Increment with DOFs `(Δū_I, α_I)`: `Δd_I = d_I(α_I) − d_Iⁿ`, and
//! `G = ∂Δz/∂(ξ, ζ) = [Σ Ψ_I,1 (Δū_I + ζt/2 Δd_I) | Σ Ψ_I,2 (…) | t/2 Σ Ψ_I Δd_I]`.
//! Then `H = G Jⁿ⁻¹` (eq 28's gradient on ⁿx), the Hughes–Winget update (eqs 22–31), the return
//! map in the lamina frame (eqs 19–21), `ⁿ⁺¹Q = ⁿQ rᵀ` (eq 27), `σᵍ = Qᵀσˡ Q` (eq 26).
//! Internal virtual work (eq 32) on `ⁿ⁺¹J = Jⁿ + G`: `w ∫ ∂δz/∂x : σ det J = w Gδ : P` with
//! `P = det(J) σᵍ J⁻ᵀ`; so for particle I, `f_I = Ψ_I,1 P:1 + Ψ_I,2 P:2` (translations) and
//! `r_Iβ = ∂d_I/∂α_β · m_I`, `m_I = ζt/2 (Ψ_I,1 P:1 + Ψ_I,2 P:2) + t/2 Ψ_I P:3` (rotations).

use super::ShellError;
use crate::kinematics::rotation::{director_derivatives, rodrigues_coefficients};
use crate::kinematics::unit_director::{step_change, UnitDirectorStep};
use crate::kinematics::HwIncrement;
use crate::kinematics::{
    frame_update, frame_update_dot, global_stress, global_stress_dot, hughes_winget,
    hughes_winget_dot, local_strain_increment, local_strain_increment_dot, mid_step_gradient,
    mid_step_gradient_dot, strain_to_vec5, stress_from_vec5, M3,
};
use crate::material::{consistent_tangent, return_map, MaterialParams, MaterialState, ReturnMap};
use crate::scalar::Real;
use nalgebra::{DMatrix, Vector3};

type V3<T> = Vector3<T>;

/// Degrees of freedom per particle: 3 translations, 2 director rotations.
pub const DOFS_PER_PARTICLE: usize = 5;

/// How the director at a quadrature point follows from the particles' directors.
///
/// The default is [`DirectorField::Normalised`]: the interpolant shortens where the rotations
/// alternate from particle to particle, which releases bending energy and drives the director
/// checkerboard to a false limit point under compression; normalised, the field keeps that
/// mode's stiffness without a stabilisation parameter (docs/stability.md §9: every shipped case
/// runs to its end with it, and the plastic hemisphere converges under refinement).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DirectorField {
    /// The RK interpolant `d = n⁰ + Σ Ψ_I (d_I − d_I⁰)`, whose length may differ from 1.
    Interpolated,
    /// The interpolant normalised at the point, `d = r/|r|`
    /// ([`crate::kinematics::unit_director`], docs/stability.md §9).
    #[default]
    Normalised,
}

impl DirectorField {
    /// The name of the case format (`integration.director`).
    pub fn name(self) -> &'static str {
        match self {
            DirectorField::Interpolated => "interpolated",
            DirectorField::Normalised => "normalised",
        }
    }
}

/// Initial (CAD) geometry at an in-plane quadrature point: position derivatives and the unit
/// normal with its derivatives. Generic: a shape design variable enters here.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint<T> {
    /// `x̄⁰,1`, `x̄⁰,2`.
    pub x_a: [V3<T>; 2],
    /// `n⁰`.
    pub n: V3<T>,
    /// `n⁰,1`, `n⁰,2`.
    pub n_a: [V3<T>; 2],
}

impl<T: Real> SurfacePoint<T> {
    /// From surface derivatives: `n = c/|c|`, `c = x,1 × x,2`, `n,α = (c,α − n (n·c,α))/|c|`.
    pub fn from_derivs(s: &crate::geometry::SurfaceDerivs<T>) -> Self {
        let c = s.xu.cross(&s.xv);
        let len = c.norm();
        let n = c / len;
        let cu = s.xuu.cross(&s.xv) + s.xu.cross(&s.xuv);
        let cv = s.xuv.cross(&s.xv) + s.xu.cross(&s.xvv);
        let proj = |ca: V3<T>| (ca - n * n.dot(&ca)) / len;
        SurfacePoint {
            x_a: [s.xu, s.xv],
            n,
            n_a: [proj(cu), proj(cv)],
        }
    }
    /// The initial lamina frame: rows `e1 = x̄,1/|x̄,1|`, `e2 = n × e1`, `e3 = n`.
    pub fn initial_frame(&self) -> M3<T> {
        let e1 = self.x_a[0].normalize();
        let e2 = self.n.cross(&e1);
        M3::from_rows(&[e1.transpose(), e2.transpose(), self.n.transpose()])
    }
}

impl SurfacePoint<f64> {
    /// The same geometry as constants of scalar `T` (a dual-number evaluation without a seed
    /// in the geometry).
    pub fn lift<T: Real>(&self) -> SurfacePoint<T> {
        SurfacePoint {
            x_a: self.x_a.map(|v| v.map(T::cst)),
            n: self.n.map(T::cst),
            n_a: self.n_a.map(|v| v.map(T::cst)),
        }
    }
}

/// Committed state of one particle (the generalised coefficients of the RK approximation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParticleState<T> {
    /// Mid-surface displacement coefficient `ū_Iⁿ`.
    pub u: V3<T>,
    /// Director coefficient `d_Iⁿ` (unit).
    pub d: V3<T>,
    /// Initial director coefficient `d_I⁰`.
    pub d0: V3<T>,
    /// Rotation axes `e1_I, e2_I ⟂ d_Iⁿ` of the two rotation DOFs.
    pub e: [V3<T>; 2],
}

impl ParticleState<f64> {
    /// The same state as constants of scalar `T`.
    pub fn lift<T: Real>(&self) -> ParticleState<T> {
        ParticleState {
            u: self.u.map(T::cst),
            d: self.d.map(T::cst),
            d0: self.d0.map(T::cst),
            e: self.e.map(|v| v.map(T::cst)),
        }
    }
}

/// One neighbour's shape-function data at the point (on the parameter domain: design-free).
///
/// Trial and test gradients are kept apart: the kinematics use the RK gradients `Ψ_I,α`
/// (which keep the reproducing conditions); the virtual work uses test gradients, which a
/// variationally consistent integration may correct so that the discrete divergence theorem
/// holds at the quadrature points (a Petrov–Galerkin form; without correction both are equal).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShapeData {
    /// `Ψ_I`.
    pub psi: f64,
    /// Trial gradients `Ψ_I,1`, `Ψ_I,2`.
    pub dpsi: [f64; 2],
    /// Test gradients (equal to `dpsi` unless corrected).
    pub dpsi_test: [f64; 2],
}

impl ShapeData {
    /// Shape data with equal trial and test gradients.
    pub fn new(psi: f64, dpsi: [f64; 2]) -> Self {
        ShapeData {
            psi,
            dpsi,
            dpsi_test: dpsi,
        }
    }
}

/// History at the point: lamina frame and material state (stress in the lamina frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointHistory<T> {
    /// Lamina frame `Q` (rows are the lamina basis vectors).
    pub frame: M3<T>,
    /// Stress, back stress, effective plastic strain.
    pub material: MaterialState<T>,
}

impl PointHistory<f64> {
    /// All zero (e.g. a zero history sensitivity).
    pub const ZERO: Self = PointHistory {
        frame: M3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        material: MaterialState {
            stress: crate::material::Vec5::new(0.0, 0.0, 0.0, 0.0, 0.0),
            back_stress: crate::material::Vec5::new(0.0, 0.0, 0.0, 0.0, 0.0),
            eps_p: 0.0,
        },
    };

    /// The same history as constants of scalar `T`.
    pub fn lift<T: Real>(&self) -> PointHistory<T> {
        PointHistory {
            frame: self.frame.map(T::cst),
            material: self.material.lift(),
        }
    }
}

/// Everything a point evaluation needs.
#[derive(Clone, Copy, Debug)]
pub struct PointInput<'a, T> {
    /// Initial geometry.
    pub surface: &'a SurfacePoint<T>,
    /// Thickness coordinate ζ in [−1, 1].
    pub zeta: f64,
    /// Shell thickness `t`.
    pub thickness: T,
    /// Quadrature weight (parameter-domain weight times thickness weight).
    pub weight: f64,
    /// Shape functions of the neighbours.
    pub shape: &'a [ShapeData],
    /// Committed states of the neighbours (same order).
    pub particles: &'a [ParticleState<T>],
    /// Material.
    pub material: &'a MaterialParams<T>,
    /// Committed history at the point.
    pub history: &'a PointHistory<T>,
    /// The director field at the point.
    pub director: DirectorField,
}

/// Intermediate kinematics of a point evaluation, kept for the tangent (and the DSA), so that
/// neither recomputes the chain of §3.
#[derive(Clone, Copy, Debug)]
pub struct PointKinematics<T> {
    /// `(Jⁿ)⁻¹`.
    pub jn_inv: M3<T>,
    /// `H = G (Jⁿ)⁻¹ = ∂Δz/∂ⁿx`.
    pub h: M3<T>,
    /// Hughes–Winget increment from `L = H (I + ½H)⁻¹`.
    pub inc: HwIncrement<T>,
    /// `(ⁿ⁺¹J)⁻¹`.
    pub j1_inv: M3<T>,
    /// `det ⁿ⁺¹J`.
    pub det1: T,
    /// Global stress `ⁿ⁺¹σᵍ`.
    pub sigma_g: M3<T>,
    /// `P = w det(J) σᵍ J⁻ᵀ`.
    pub p: M3<T>,
    /// With [`DirectorField::Normalised`]: the end-of-step unit director at the point.
    pub unit_director: Option<UnitDirector<T>>,
}

/// The end-of-step unit director at a point and the interpolant it normalises: what the
/// virtual director fields and the tangent need (`N′`, `N″` at `r₁`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnitDirector<T> {
    /// `d₁ = r₁/|r₁|`.
    pub d: V3<T>,
    /// `|r₁|`.
    pub l: T,
    /// `r₁,α`.
    pub r_a: [V3<T>; 2],
}

/// Result of a point evaluation.
#[derive(Clone, Debug)]
pub struct PointResult<T> {
    /// Internal force, `5 × n_neighbours`, ordered `[f_I (3), r_I1, r_I2]` per neighbour.
    pub residual: Vec<T>,
    /// Trial history at n+1.
    pub history: PointHistory<T>,
    /// Outcome of the return map.
    pub return_map: ReturnMap<T>,
    /// Intermediate kinematics.
    pub kinematics: PointKinematics<T>,
}

/// Configuration matrices at step n: `Jⁿ`.
fn step_start_jacobian<T: Real>(inp: &PointInput<T>) -> M3<T> {
    let s = inp.surface;
    let mut xa = s.x_a;
    let mut d = s.n;
    let mut da = s.n_a;
    for (sh, p) in inp.shape.iter().zip(inp.particles) {
        let dd = p.d - p.d0;
        for a in 0..2 {
            xa[a] += p.u * T::cst(sh.dpsi[a]);
            da[a] += dd * T::cst(sh.dpsi[a]);
        }
        d += dd * T::cst(sh.psi);
    }
    let half_t = inp.thickness * 0.5;
    let z = half_t * inp.zeta;
    M3::from_columns(&[xa[0] + da[0] * z, xa[1] + da[1] * z, d * half_t])
}

/// The interpolant of the directors at the point, `r = n⁰ + Σ Ψ_I (d_I − d_I⁰)`, with its
/// ξ-derivatives, and the increment's `δ = Σ Ψ_I Δd_I`, `δ,α = Σ Ψ_I,α Δd_I`.
#[allow(clippy::type_complexity)]
fn interpolated_directors<T: Real>(
    inp: &PointInput<T>,
    dd: &[V3<T>],
) -> (V3<T>, [V3<T>; 2], V3<T>, [V3<T>; 2]) {
    let s = inp.surface;
    let (mut r, mut r_a) = (s.n, s.n_a);
    let (mut delta, mut delta_a) = (V3::zeros(), [V3::zeros(), V3::zeros()]);
    for ((sh, p), d) in inp.shape.iter().zip(inp.particles).zip(dd) {
        let v = p.d - p.d0;
        r += v * T::cst(sh.psi);
        delta += *d * T::cst(sh.psi);
        for a in 0..2 {
            r_a[a] += v * T::cst(sh.dpsi[a]);
            delta_a[a] += *d * T::cst(sh.dpsi[a]);
        }
    }
    (r, r_a, delta, delta_a)
}

/// The unit director's step at the point from the interpolant and the increments `Δd_I`.
fn unit_director_step<T: Real>(inp: &PointInput<T>, dd: &[V3<T>]) -> UnitDirectorStep<T> {
    let (r, r_a, delta, delta_a) = interpolated_directors(inp, dd);
    step_change(&r, &r_a, &delta, &delta_a)
}

/// `Jⁿ` and `G` with the unit director ([`DirectorField::Normalised`]) of the step `st`:
/// `Jⁿ = [x̄,α + z dₙ,α | t/2 dₙ]`, `G = [Σ Ψ_I,α Δū_I + z (d₁,α − dₙ,α) | t/2 (d₁ − dₙ)]`.
fn unit_director_jacobians<T: Real>(
    inp: &PointInput<T>,
    du: &[V3<T>],
    st: &UnitDirectorStep<T>,
) -> (M3<T>, M3<T>, UnitDirector<T>) {
    let half_t = inp.thickness * 0.5;
    let z = half_t * inp.zeta;
    let mut xa = inp.surface.x_a;
    let mut ga = [V3::zeros(), V3::zeros()];
    for ((sh, p), u) in inp.shape.iter().zip(inp.particles).zip(du) {
        for a in 0..2 {
            xa[a] += p.u * T::cst(sh.dpsi[a]);
            ga[a] += *u * T::cst(sh.dpsi[a]);
        }
    }
    let jn = M3::from_columns(&[
        xa[0] + st.dn_a[0] * z,
        xa[1] + st.dn_a[1] * z,
        st.dn * half_t,
    ]);
    let g = M3::from_columns(&[
        ga[0] + st.dd_a[0] * z,
        ga[1] + st.dd_a[1] * z,
        st.dd * half_t,
    ]);
    let unit = UnitDirector {
        d: st.d1,
        l: st.l1,
        r_a: st.r1_a,
    };
    (jn, g, unit)
}

/// Gradient of the increment `G = ∂Δz/∂(ξ, ζ)` from per-particle `(Δū_I, Δd_I)`.
fn increment_gradient<T: Real>(inp: &PointInput<T>, du: &[V3<T>], dd: &[V3<T>]) -> M3<T> {
    let half_t = inp.thickness * 0.5;
    let z = half_t * inp.zeta;
    let mut c = [V3::zeros(), V3::zeros(), V3::zeros()];
    for ((sh, u), d) in inp.shape.iter().zip(du).zip(dd) {
        let top = *u + *d * z;
        c[0] += top * T::cst(sh.dpsi[0]);
        c[1] += top * T::cst(sh.dpsi[1]);
        c[2] += *d * (half_t * sh.psi);
    }
    M3::from_columns(&c)
}

fn invert<T: Real>(m: &M3<T>, what: &'static str) -> Result<(T, M3<T>), ShellError> {
    let det = m.determinant();
    if det.value().is_nan() || det.value() <= 0.0 {
        return Err(ShellError::NonPositiveJacobian {
            what,
            det: det.value(),
        });
    }
    let inv = m.try_inverse().ok_or(ShellError::NonPositiveJacobian {
        what,
        det: det.value(),
    })?;
    Ok((det, inv))
}

/// The layer-independent part of a point's increment, per neighbour: `Δū_I`,
/// `Δd_I = d_I(α_I) − d_Iⁿ` (Rodrigues' exact rotation) and the virtual directors `∂d_I/∂α_β`.
/// The thickness layers of an in-plane point share it ([`point_residual_with`]), so the
/// rotations are evaluated once per in-plane point rather than once per layer.
#[derive(Clone, Debug, PartialEq)]
pub struct PointIncrement<T> {
    /// `Δū_I`.
    pub du: Vec<V3<T>>,
    /// `Δd_I`.
    pub dd: Vec<V3<T>>,
    /// `∂d_I/∂α_1`, `∂d_I/∂α_2` at `α_I`.
    pub d_alpha: Vec<[V3<T>; 2]>,
    /// The step of the unit director at the in-plane point ([`DirectorField::Normalised`]),
    /// once set by [`PointIncrement::with_unit_director`]; without it each layer forms it.
    pub unit: Option<UnitDirectorStep<T>>,
}

impl<T: Real> PointIncrement<T> {
    /// From the neighbours' committed states and the DOF increments (5 per neighbour:
    /// `Δū_I` then `α_I`).
    pub fn new(particles: &[ParticleState<T>], dofs: &[T]) -> Result<Self, ShellError> {
        let n = particles.len();
        if dofs.len() != DOFS_PER_PARTICLE * n {
            return Err(ShellError::Dimension {
                expected: DOFS_PER_PARTICLE * n,
                got: dofs.len(),
            });
        }
        let mut du = Vec::with_capacity(n);
        let mut dd = Vec::with_capacity(n);
        let mut d_alpha = Vec::with_capacity(n);
        for (p, q) in particles.iter().zip(dofs.chunks_exact(DOFS_PER_PARTICLE)) {
            du.push(V3::new(q[0], q[1], q[2]));
            // Δd_I = f1 θ×dⁿ + f2 θ×(θ×dⁿ) (Rodrigues' formula without the dⁿ term): forming
            // d(α) − dⁿ instead cancels to an absolute error ~ε, which the transverse shear
            // stiffness turns into a load-independent residual floor (~3e-10 on the hemisphere).
            let theta = p.e[0] * q[3] + p.e[1] * q[4];
            let (f1, f2) = rodrigues_coefficients(theta.dot(&theta));
            let c = theta.cross(&p.d);
            dd.push(c * f1 + theta.cross(&c) * f2);
            // Virtual director of the rotation DOFs: the exact ∂d_I/∂α_β of Rodrigues' formula.
            d_alpha.push(director_first_derivatives(p, [q[3], q[4]]));
        }
        Ok(PointIncrement {
            du,
            dd,
            d_alpha,
            unit: None,
        })
    }

    /// With the normalised director field of `inp` (any layer of the in-plane point): the
    /// unit director's step formed once here for all layers (it does not depend on ζ).
    pub fn with_unit_director(mut self, inp: &PointInput<T>) -> Self {
        if inp.director == DirectorField::Normalised {
            self.unit = Some(unit_director_step(inp, &self.dd));
        }
        self
    }
}

/// Residual (internal force) of the point for DOF increments `dofs` (5 per neighbour:
/// `Δū_I` then `α_I`), generic over the scalar: with dual numbers this is the reference.
pub fn point_residual<T: Real>(
    inp: &PointInput<T>,
    dofs: &[T],
) -> Result<PointResult<T>, ShellError> {
    let n = inp.shape.len();
    if dofs.len() != DOFS_PER_PARTICLE * n || inp.particles.len() != n {
        return Err(ShellError::Dimension {
            expected: DOFS_PER_PARTICLE * n,
            got: dofs.len(),
        });
    }
    point_residual_with(inp, &PointIncrement::new(inp.particles, dofs)?)
}

/// [`point_residual`] with the layer-independent increment computed beforehand (from
/// `inp.particles` and the DOFs): the same result, for the layers of one in-plane point.
pub fn point_residual_with<T: Real>(
    inp: &PointInput<T>,
    incr: &PointIncrement<T>,
) -> Result<PointResult<T>, ShellError> {
    let n = inp.shape.len();
    for got in [
        inp.particles.len(),
        incr.du.len(),
        incr.dd.len(),
        incr.d_alpha.len(),
    ] {
        if got != n {
            return Err(ShellError::Dimension { expected: n, got });
        }
    }
    let (jn, g, unit_director) = match inp.director {
        DirectorField::Interpolated => (
            step_start_jacobian(inp),
            increment_gradient(inp, &incr.du, &incr.dd),
            None,
        ),
        DirectorField::Normalised => {
            let formed;
            let st = match &incr.unit {
                Some(st) => st,
                None => {
                    formed = unit_director_step(inp, &incr.dd);
                    &formed
                }
            };
            let (jn, g, unit) = unit_director_jacobians(inp, &incr.du, st);
            (jn, g, Some(unit))
        }
    };
    let (_, jn_inv) = invert(&jn, "Jⁿ (step-start configuration)")?;
    let h = g * jn_inv;
    let l = mid_step_gradient(&h)?;
    let inc = hughes_winget(&l)?;
    let q_n = inp.history.frame;
    let deps_l = local_strain_increment(&q_n, &inc.r_half, &inc.deps);
    let rm = return_map(
        inp.material,
        &inp.history.material,
        &strain_to_vec5(&deps_l),
    )?;
    let q1 = frame_update(&q_n, &inc.r);
    let sigma_g = global_stress(&q1, &stress_from_vec5(&rm.state.stress));
    let j1 = jn + g;
    let (det1, j1_inv) = invert(&j1, "ⁿ⁺¹J (end-of-step configuration)")?;
    let p = sigma_g * j1_inv.transpose() * (det1 * T::cst(inp.weight));
    let half_t = inp.thickness * 0.5;
    let z = half_t * inp.zeta;
    let mut residual = Vec::with_capacity(DOFS_PER_PARTICLE * n);
    match &unit_director {
        None => {
            for (sh, da) in inp.shape.iter().zip(&incr.d_alpha) {
                let f =
                    p.column(0) * T::cst(sh.dpsi_test[0]) + p.column(1) * T::cst(sh.dpsi_test[1]);
                let m = f * z + p.column(2) * (half_t * sh.psi);
                residual.extend_from_slice(&[f[0], f[1], f[2], da[0].dot(&m), da[1].dot(&m)]);
            }
        }
        Some(u) => {
            // Virtual fields of the unit director: δd = N′ δr, δd,α = N′ δr,α + N″[δr, r,α]
            // with δr = Ψ_I δd_I, δr,α = Ψ̃_I,α δd_I. So the moment m_I of the interpolant
            // becomes N′ m_I + Ψ_I Σ_α H(z P:α) r,α (module `unit_director`).
            use crate::kinematics::unit_director::{n_prime_apply, n_second_apply};
            let geo = n_second_apply(&u.d, u.l, &(p.column(0) * z), &u.r_a[0])
                + n_second_apply(&u.d, u.l, &(p.column(1) * z), &u.r_a[1]);
            for (sh, da) in inp.shape.iter().zip(&incr.d_alpha) {
                let f =
                    p.column(0) * T::cst(sh.dpsi_test[0]) + p.column(1) * T::cst(sh.dpsi_test[1]);
                let m = n_prime_apply(&u.d, u.l, &(f * z + p.column(2) * (half_t * sh.psi)))
                    + geo * T::cst(sh.psi);
                residual.extend_from_slice(&[f[0], f[1], f[2], da[0].dot(&m), da[1].dot(&m)]);
            }
        }
    }
    Ok(PointResult {
        residual,
        history: PointHistory {
            frame: q1,
            material: rm.state,
        },
        return_map: rm,
        kinematics: PointKinematics {
            jn_inv,
            h,
            inc,
            j1_inv,
            det1,
            sigma_g,
            p,
            unit_director,
        },
    })
}

/// `∂d/∂α_β` of Rodrigues' formula, generic (same formula as
/// [`crate::kinematics::rotation::director_derivatives`], written over `T` so the residual is generic).
pub(crate) fn director_first_derivatives<T: Real>(
    p: &ParticleState<T>,
    alpha: [T; 2],
) -> [V3<T>; 2] {
    let theta = p.e[0] * alpha[0] + p.e[1] * alpha[1];
    let x = theta.dot(&theta);
    let (f1, f2, f1p, f2p) = crate::kinematics::rotation::rodrigues_with_first_derivatives(x);
    let c = theta.cross(&p.d);
    let tc = theta.cross(&c);
    std::array::from_fn(|b| {
        let xb = theta.dot(&p.e[b]) * 2.0;
        let cb = p.e[b].cross(&p.d);
        let wb = p.e[b].cross(&c) + theta.cross(&cb);
        c * (f1p * xb) + cb * f1 + tc * (f2p * xb) + wb * f2
    })
}

/// Consistent tangent `∂r/∂dofs` of [`point_residual`] (5n × 5n), assembled column by column
/// from hand-derived directional derivatives of every stage (docs/shell-formulation.md §5):
/// `Ġ` → `Ḣ = Ġ Jⁿ⁻¹` → `L̇` (eqs 56–57) → `Δε̇, ṙ, ½ṙ` (eqs 54–55, 58) → `Δε̇ˡ` (eq 50) →
/// `σ̇ˡ = D^ep Δε̇ˡ` (eq 47) → `Q̇`, `σ̇ᵍ` (eqs 42, 51) → `Ṗ` → `ṙ_a`, plus the change of the
/// rotation virtual fields (`∂²d/∂α²`).
pub fn point_tangent(
    inp: &PointInput<f64>,
    dofs: &[f64],
    res: &PointResult<f64>,
) -> Result<DMatrix<f64>, ShellError> {
    let n = inp.shape.len();
    let nd = DOFS_PER_PARTICLE * n;
    let dirs: Vec<_> = inp
        .particles
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let q = &dofs[DOFS_PER_PARTICLE * i..DOFS_PER_PARTICLE * (i + 1)];
            director_derivatives(&p.d, &p.e[0], &p.e[1], [q[3], q[4]])
        })
        .collect();
    if inp.director != DirectorField::Interpolated {
        return Err(ShellError::InvalidInput(
            "point_tangent (the reference sweep) takes the interpolated director field; the \
             normalised one's tangent is ThicknessTangent's"
                .into(),
        ));
    }
    let PointKinematics {
        jn_inv,
        h,
        inc,
        j1_inv,
        det1,
        sigma_g,
        p,
        ..
    } = res.kinematics;
    let q_n = inp.history.frame;
    let dep = consistent_tangent(inp.material, &res.return_map);
    let q1 = res.history.frame;
    let sigma_l = stress_from_vec5(&res.history.material.stress);
    let w = inp.weight;
    let half_t = inp.thickness * 0.5;
    let z = half_t * inp.zeta;
    let m_of = |pm: &M3<f64>, sh: &ShapeData| {
        let f = pm.column(0) * sh.dpsi_test[0] + pm.column(1) * sh.dpsi_test[1];
        (f, f * z + pm.column(2) * (half_t * sh.psi))
    };
    let mut k = DMatrix::zeros(nd, nd);
    for col in 0..nd {
        let (pk, ck) = (col / DOFS_PER_PARTICLE, col % DOFS_PER_PARTICLE);
        let shk = &inp.shape[pk];
        // Ġ for this direction: a unit translation, or the director rate ∂d/∂α.
        let (vu, vd) = if ck < 3 {
            let mut e = V3::zeros();
            e[ck] = 1.0;
            (e, V3::zeros())
        } else {
            (V3::zeros(), dirs[pk].d_a[ck - 3])
        };
        let top = vu + vd * z;
        let g_dot = M3::from_columns(&[
            top * shk.dpsi[0],
            top * shk.dpsi[1],
            vd * (half_t * shk.psi),
        ]);
        let h_dot = g_dot * jn_inv;
        let l_dot = mid_step_gradient_dot(&h, &h_dot)?;
        let inc_dot = hughes_winget_dot(&inc, &l_dot);
        let deps_l_dot = local_strain_increment_dot(
            &q_n,
            &M3::zeros(),
            &inc.r_half,
            &inc_dot.r_half_dot,
            &inc.deps,
            &inc_dot.deps_dot,
        );
        let sigma_l_dot = stress_from_vec5(&(dep * strain_to_vec5(&deps_l_dot)));
        let q1_dot = frame_update_dot(&q_n, &M3::zeros(), &inc.r, &inc_dot.r_dot);
        let sigma_g_dot = global_stress_dot(&q1, &q1_dot, &sigma_l, &sigma_l_dot);
        // P = det(J) σ J⁻ᵀ w, J̇ = Ġ: Ṗ = w det J [tr(J⁻¹J̇) σ J⁻ᵀ + σ̇ J⁻ᵀ − σ J⁻ᵀ J̇ᵀ J⁻ᵀ].
        let jinv_t = j1_inv.transpose();
        let tr = (j1_inv * g_dot).trace();
        let p_dot = (sigma_g * jinv_t * tr + sigma_g_dot * jinv_t
            - sigma_g * jinv_t * g_dot.transpose() * jinv_t)
            * (det1 * w);
        for (i, sh) in inp.shape.iter().enumerate() {
            let (f_dot, m_dot) = m_of(&p_dot, sh);
            let r0 = DOFS_PER_PARTICLE * i;
            k[(r0, col)] = f_dot[0];
            k[(r0 + 1, col)] = f_dot[1];
            k[(r0 + 2, col)] = f_dot[2];
            for b in 0..2 {
                let mut v = dirs[i].d_a[b].dot(&m_dot);
                if i == pk && ck >= 3 {
                    let (_, m) = m_of(&p, sh);
                    v += dirs[i].d_ab[b][ck - 3].dot(&m);
                }
                k[(r0 + 3 + b, col)] = v;
            }
        }
    }
    Ok(k)
}
