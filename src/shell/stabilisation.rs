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

use super::model::ShellModel;
use super::point::DOFS_PER_PARTICLE;
use super::ShellError;
use crate::scalar::Real;
use nalgebra::{Matrix3x2, Vector3};

/// The stabilisation of one model (module documentation).
#[derive(Debug, Clone)]
pub struct DirectorFilter {
    /// `κ = ε E t³ / (12 (1 − ν²))`.
    kappa: f64,
    /// Per real particle `I`: `(shape-function particle j, coefficient δ_Ij − Ψ_j(ξ_I))`.
    rows: Vec<Vec<(usize, f64)>>,
}

impl DirectorFilter {
    /// The stabilisation of `model` with factor `epsilon` (> 0, finite).
    pub fn new(model: &ShellModel, epsilon: f64) -> Result<Self, ShellError> {
        let mp = &model.material;
        let (e, nu, t) = (mp.young, mp.poisson, model.thickness);
        let kappa = epsilon * e * t * t * t / (12.0 * (1.0 - nu * nu));
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
        Ok(DirectorFilter { kappa, rows })
    }

    /// The stiffness `κ`.
    pub fn kappa(&self) -> f64 {
        self.kappa
    }

    /// Per row: the blocks `(source particle, c · det Q · Q[e1 × d, e2 × d])` mapping the
    /// source's two rotation increments to `g_I`, merged by source.
    fn blocks(&self, model: &ShellModel) -> Vec<Vec<(usize, Matrix3x2<f64>)>> {
        self.rows
            .iter()
            .map(|row| {
                let mut out: Vec<(usize, Matrix3x2<f64>)> = Vec::with_capacity(row.len());
                for &(j, c) in row {
                    let st = model.particle_state(j);
                    let (src, det) = model.dof_source(j);
                    let a1: Vector3<f64> = st.e[0].cross(&st.d) * (c * det);
                    let a2: Vector3<f64> = st.e[1].cross(&st.d) * (c * det);
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
}

const ROT: usize = 3;

impl DirectorFilter {
    /// Add `f = −κ Bᵀ B α` (the rotation increments of `q`) into `f`, in scalar `T`.
    pub fn force<T: Real>(
        &self,
        model: &ShellModel,
        q: &[T],
        f: &mut [T],
    ) -> Result<(), ShellError> {
        let kappa = T::cst(self.kappa);
        for row in self.blocks(model) {
            let mut g = Vector3::zeros();
            for (s, b) in &row {
                let a = nalgebra::Vector2::new(
                    q[DOFS_PER_PARTICLE * s + ROT],
                    q[DOFS_PER_PARTICLE * s + ROT + 1],
                );
                g += b.map(T::cst) * a;
            }
            for (s, b) in &row {
                let r = b.map(T::cst).transpose() * g * kappa;
                f[DOFS_PER_PARTICLE * s + ROT] -= r[0];
                f[DOFS_PER_PARTICLE * s + ROT + 1] -= r[1];
            }
        }
        Ok(())
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
