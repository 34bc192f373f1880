//! Stress resultants of the committed state at an in-plane quadrature point: membrane forces
//! `N = Σ_l w_l (t/2) σ_l`, moments `M = Σ_l w_l (t/2) (ζ_l t/2) σ_l` and transverse shear
//! forces `Q_α = Σ_l w_l (t/2) σ_α3,l` per unit length, integrated through the thickness from
//! the layer stresses, with the top, middle and bottom layers' `ē^p` (eq 15) and von Mises
//! stress. Each layer stress is first resolved (eq 26 twice, `σᶜ = Qᶜ Qᵀ σˡ Q Qᶜᵀ`) in one
//! frame per point, the **initial lamina frame carried by the director**: the initial frame
//! `Q⁰` (rows `e1 = x̄⁰,1/|x̄⁰,1|`, `e2 = n⁰ × e1`, `n⁰`) rotated by the shortest rotation
//! taking `n⁰` to the current director `d/|d|` ([`director_rotation`]), so that `N11` stays the
//! membrane force along the (rotated) first parametric direction through large rotations.
//! `M` is positive when the stress grows towards the director (`ζ = +1`); `t` is the initial
//! thickness. The per-cell means written to VTU: `io::shell_output::cell_resultants`.

use super::model::ShellModel;
use crate::kinematics::{global_stress, local_stress, stress_from_vec5};
use crate::material::von_mises;
use nalgebra::{Matrix3, Rotation3, Vector3};

/// Thickness-integrated results at a quadrature point, or their mean over an integration
/// cell (see the module documentation).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CellResultants {
    /// Membrane forces `[N11, N22, N12]` per unit length, initial lamina frame.
    pub n: [f64; 3],
    /// Moments `[M11, M22, M12]` per unit length.
    pub m: [f64; 3],
    /// Transverse shear forces `[Q1, Q2]` per unit length.
    pub q: [f64; 2],
    /// Equivalent plastic strain at the top, middle and bottom layers.
    pub eps_p: [f64; 3],
    /// Von Mises stress at the top and bottom layers.
    pub von_mises: [f64; 2],
}

/// Layers nearest `ζ = +1`, nearest `ζ = 0` (all equally near), nearest `ζ = −1`.
pub(crate) fn layer_choice(rule: &[(f64, f64)]) -> (usize, Vec<usize>, usize) {
    let by = |f: &dyn Fn(f64) -> f64| {
        (0..rule.len())
            .min_by(|&a, &b| f(rule[a].0).total_cmp(&f(rule[b].0)))
            .unwrap_or(0)
    };
    let top = by(&|z| -z);
    let bottom = by(&|z| z);
    let zmin = rule.iter().map(|r| r.0.abs()).fold(f64::INFINITY, f64::min);
    let mid = (0..rule.len())
        .filter(|&l| rule[l].0.abs() <= zmin + 1e-12)
        .collect();
    (top, mid, bottom)
}

/// The frame of the resultants at in-plane quadrature point `k` (rows = basis vectors): the
/// initial lamina frame rotated by the shortest rotation from `n⁰` to the committed director
/// `d = n⁰ + Σ Ψ_I (d_I − d_I⁰)` (see the module documentation).
pub fn resultant_frame(model: &ShellModel, k: usize) -> Matrix3<f64> {
    let p = &model.points[k];
    let n0 = p.surface.n;
    let mut d = n0;
    for (&j, s) in p.neighbours.iter().zip(&p.shape) {
        let q = model.particle_state(j);
        d += (q.d - q.d0) * s.psi;
    }
    let r = Rotation3::from_scaled_axis(director_rotation(&n0, &d));
    p.surface.initial_frame() * r.matrix().transpose()
}

/// Thickness-integrated results at in-plane quadrature point `k` of the committed state.
pub fn point_resultants(model: &ShellModel, k: usize) -> CellResultants {
    let nl = model.thickness_rule.len();
    let half_t = model.thickness * 0.5;
    let q0 = resultant_frame(model, k);
    let mut r = CellResultants::default();
    let (top, mid, bottom) = layer_choice(&model.thickness_rule);
    for (l, &(zeta, wz)) in model.thickness_rule.iter().enumerate() {
        let h = &model.history[k * nl + l];
        let s0 = local_stress(
            &q0,
            &global_stress(&h.frame, &stress_from_vec5(&h.material.stress)),
        );
        let w = wz * half_t;
        let wm = w * zeta * half_t;
        let comps = [s0[(0, 0)], s0[(1, 1)], s0[(0, 1)]];
        for (c, s) in comps.iter().enumerate() {
            r.n[c] += w * s;
            r.m[c] += wm * s;
        }
        r.q[0] += w * s0[(0, 2)];
        r.q[1] += w * s0[(1, 2)];
    }
    let eps = |l: usize| model.history[k * nl + l].material.eps_p;
    let vm = |l: usize| von_mises(&model.history[k * nl + l].material.stress);
    r.eps_p = [
        eps(top),
        mid.iter().map(|&l| eps(l)).sum::<f64>() / mid.len().max(1) as f64,
        eps(bottom),
    ];
    r.von_mises = [vm(top), vm(bottom)];
    r
}

/// The rotation vector taking the unit vector `n0` to the direction of `d` by the shortest
/// rotation (zero when they are parallel; also zero, i.e. undefined, when antiparallel).
pub fn director_rotation(n0: &Vector3<f64>, d: &Vector3<f64>) -> Vector3<f64> {
    let dh = d.normalize();
    let axis = n0.cross(&dh);
    let s = axis.norm();
    let c = n0.dot(&dh);
    let theta = s.atan2(c);
    if s > 0.0 {
        axis * (theta / s)
    } else {
        Vector3::zeros()
    }
}
