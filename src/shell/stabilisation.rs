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

use super::model::ShellModel;
use super::point::{ParticleState, DOFS_PER_PARTICLE};
use super::ShellError;
use crate::scalar::Real;
use nalgebra::{Matrix3x2, Vector2, Vector3};

/// The stabilisation of one model (module documentation).
#[derive(Debug, Clone)]
pub struct DirectorFilter {
    /// The factor `ε`.
    epsilon: f64,
    /// `κ = ε E t³ / (12 (1 − ν²))`.
    kappa: f64,
    /// Per real particle `I`: `(shape-function particle j, coefficient δ_Ij − Ψ_j(ξ_I))`.
    rows: Vec<Vec<(usize, f64)>>,
}

/// Per row: `(source particle, block)` mapping the source's two rotation increments to `g_I`.
type Blocks<T> = Vec<Vec<(usize, Matrix3x2<T>)>>;

impl DirectorFilter {
    /// The stabilisation of `model` with factor `epsilon` (> 0, finite).
    pub fn new(model: &ShellModel, epsilon: f64) -> Result<Self, ShellError> {
        let mp = &model.material;
        let kappa = Self::stiffness(epsilon, mp.young, mp.poisson, model.thickness);
        let mut rows = Vec::with_capacity(model.n_particles());
        for i in 0..model.n_particles() {
            let sv = model.shape_values(model.particle_uv[i])?;
            let mut row: Vec<(usize, f64)> = sv.iter().map(|(j, psi, _)| (j, -psi)).collect();
            match row.iter_mut().find(|(j, _)| *j == i) {
                Some(t) => t.1 += 1.0,
                None => row.push((i, 1.0)),
            }
            rows.push(row);
        }
        Ok(DirectorFilter {
            epsilon,
            kappa,
            rows,
        })
    }

    /// `κ = ε E t³ / (12 (1 − ν²))` in scalar `T`.
    fn stiffness<T: Real>(epsilon: f64, young: T, poisson: T, thickness: T) -> T {
        young * thickness.powi(3) * epsilon / ((T::one() - poisson * poisson) * 12.0)
    }

    /// The factor `ε`.
    pub fn epsilon(&self) -> f64 {
        self.epsilon
    }

    /// The stiffness `κ` of the model it was built for.
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

/// Add `f = −κ Bᵀ B α` for the blocks `blocks`.
fn apply<T: Real>(blocks: &Blocks<T>, kappa: T, q: &[T], f: &mut [T]) {
    for row in blocks {
        let mut g = Vector3::zeros();
        for (s, b) in row {
            g += b * alpha(q, *s);
        }
        for (s, b) in row {
            sub_rotation(f, *s, b.transpose() * g * kappa);
        }
    }
}

impl DirectorFilter {
    /// Add `f = −κ Bᵀ B α` (the rotation increments of `q`) into `f`, in scalar `T`, on the
    /// model's committed state and with its `κ`.
    pub fn force<T: Real>(
        &self,
        model: &ShellModel,
        q: &[T],
        f: &mut [T],
    ) -> Result<(), ShellError> {
        self.check(model, None, q.len(), f.len())?;
        let blocks: Blocks<T> = self
            .blocks(model)
            .into_iter()
            .map(|row| row.into_iter().map(|(s, b)| (s, b.map(T::cst))).collect())
            .collect();
        apply(&blocks, T::cst(self.kappa), q, f);
        Ok(())
    }

    /// Add `f = −κ Bᵀ B α` into `f` in scalar `T` on the committed states `particles` of the
    /// real particles (as `ShellModel::particles`; the images follow their sources) with the
    /// stiffness `kappa`: the same force on another committed state and design (the dual
    /// reference's, [`super::load::LoadState`]).
    pub fn force_with<T: Real>(
        &self,
        model: &ShellModel,
        particles: &[ParticleState<T>],
        kappa: T,
        q: &[T],
        f: &mut [T],
    ) -> Result<(), ShellError> {
        self.check(model, Some(particles.len()), q.len(), f.len())?;
        let blocks = self.blocks_of(model, |j| model.particle_state_in(j, particles));
        apply(&blocks, kappa, q, f);
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
        self.check(model, Some(particles_dot.len()), q.len(), f.len())?;
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

    /// Sizes: `q` and `f` are generalised vectors of the model, `particles` (when given) one
    /// state per real particle.
    fn check(
        &self,
        model: &ShellModel,
        particles: Option<usize>,
        q: usize,
        f: usize,
    ) -> Result<(), ShellError> {
        let n = model.n_dofs();
        for got in [q, f] {
            if got != n {
                return Err(ShellError::Dimension { expected: n, got });
            }
        }
        match particles {
            Some(got) if got != model.n_particles() => Err(ShellError::Dimension {
                expected: model.n_particles(),
                got,
            }),
            _ => Ok(()),
        }
    }

    /// Add the tangent `−κ Bᵀ B` as global entries (independent of the increment).
    pub fn add_stiffness(
        &self,
        model: &ShellModel,
        out: &mut Vec<(usize, usize, f64)>,
    ) -> Result<(), ShellError> {
        for row in self.blocks(model) {
            for (s, bs) in &row {
                for (p, bp) in &row {
                    let k = bs.transpose() * bp * (-self.kappa);
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
