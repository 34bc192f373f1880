//! Hand-derived forward (directional) derivative of the point residual for the continuum design
//! sensitivity analysis (path 2; paper §3, eqs 37–65).
//!
//! The continuum DSA differentiates the residual of one converged step `R(Δq; ⁿs, τ)` with
//! respect to everything it depends on. At one layer point this is [`point_residual_dot`]: the
//! derivative of [`point_residual_with`](super::point::point_residual_with)'s residual and trial history, linear in the seeds
//! ([`PointSeeds`]):
//! - the design velocity of the initial geometry `ẋ⁰,α, ṅ⁰, ṅ⁰,α` (shape variables),
//! - the thickness rate `ṫ` and the material-parameter rates `Ė, ν̇, k̇, σ̇0, Ḣ, β̇`,
//! - the sensitivities of the neighbours' committed states `ⁿū̇, ⁿḋ, ḋ⁰, ė1, ė2`,
//! - the history sensitivities `ⁿQ̇, ⁿ(σ̇, α̇, ė^p)` (eq 49's history terms),
//! - the increment's sensitivity `Δq̇` (which reproduces [`super::point::point_tangent`]'s
//!   columns).
//!
//! The chain, stage by stage (point.rs's notation; `˙ = d/dτ`):
//! - `J̇ⁿ = [ẋ,1 + ḋ,1 z + d,1 ż | ẋ,2 + ḋ,2 z + d,2 ż | ḋ t/2 + d ṫ/2]`, `z = ζt/2`: the
//!   parametric gradient of the design velocity `ⁿV` of the step-start configuration (with
//!   `x̄,α = x̄⁰,α + Σ Ψ_I,α ū_I`, `d = n⁰ + Σ Ψ_I (d_I − d⁰_I)`), so `∇ⁿV = J̇ⁿ Jⁿ⁻¹`,
//! - `Ġ` from `Δū̇_I, Δḋ_I` ([`PointIncrementDot`]) and `ż, ṫ`,
//! - `Ḣ = (Ġ − H J̇ⁿ) Jⁿ⁻¹`: the increment's gradient rate with the term `−H ∇ⁿV` of eqs 39–40,
//! - `L̇ = F½⁻¹ Ḣ F½⁻¹` (eqs 56–57, [`crate::kinematics::mid_step_gradient_dot`]),
//! - `Δε̇, Δω̇, ṙ, ½ṙ` (eqs 54–55, 58, [`crate::kinematics::hughes_winget_dot`]),
//! - `Δε̇ˡ` with `ⁿQ̇` (eq 50, [`crate::kinematics::local_strain_increment_dot`]),
//! - the return-map sensitivity `ⁿ⁺¹(σ̇, α̇, ė^p)` (eqs 44–49, [`crate::material::material_sensitivity`]),
//! - `ⁿ⁺¹Q̇ = ⁿQ̇ rᵀ + ⁿQ ṙᵀ` (eq 51), `σ̇ᵍ` (eq 42),
//! - `Ṗ = tr(J⁻¹J̇) P + w det J σ̇ᵍ J⁻ᵀ − P J̇ᵀ J⁻ᵀ` on `ⁿ⁺¹J = Jⁿ + G` (the `J̇` and `Ḟ⁻¹`
//!   terms of eqs 38 and 41, with the parametric volume element carrying `div V`),
//! - the rows (the structural form's derivative, eqs 38, 62–64: `a*` with `Δż` plus `a'_V`):
//!   `ḟ_I = Ψ_I,α Ṗ:α`, and
//!   `ṙ_Iβ = (∂d_I/∂α_β)˙ · m_I + ∂d_I/∂α_β · ṁ_I` with `ṁ_I = ḟ_I z + f_I ż + Ṗ:3 Ψ_I t/2 +
//!   P:3 Ψ_I ṫ/2`.
//!
//! Every stage is checked against the dual-number derivative of the generic kernel and central
//! differences in `tests/point_sensitivity.rs`; where the paper's transcription differs
//! (eq 55's `B^ε`, eqs 46–49's factors, eq 56's first line), the dual number decides, as in the
//! kinematics and material modules.
//!
//! At model level, [`ShellModel::internal_force_dots`] evaluates the f64 point once per layer
//! point and applies the derivative to several seed sets (design variables) at once.

use super::model::ShellModel;
use super::point::{
    DirectorField, ParticleState, PointHistory, PointIncrement, PointInput, PointKinematics,
    PointResult, ShapeData, SurfacePoint, DOFS_PER_PARTICLE,
};
use super::ShellError;
use crate::kinematics::rotation::rodrigues_coefficient_derivatives;
use crate::kinematics::unit_director::{
    n_prime, n_second, n_second_apply, n_third, step_change, UnitDirectorStep,
};
use crate::kinematics::{
    frame_update, global_stress, hughes_winget, local_strain_increment, mid_step_gradient,
    strain_to_vec5, stress_from_vec5, M3,
};
use crate::material::{
    elastic_matrix, return_map, Mat5, MaterialParams, MaterialSensitivity, StrainMap, Vec5,
};
use nalgebra::{Matrix3, SMatrix, Vector3};
use rayon::prelude::*;

type V3 = Vector3<f64>;

/// The seeds of one directional derivative at one layer point (all linear).
#[derive(Clone, Copy, Debug)]
pub struct PointSeeds<'a> {
    /// Design velocity of the initial geometry at the point (`ẋ⁰,α`, `ṅ⁰`, `ṅ⁰,α`), for shape
    /// variables; `None` = zero.
    pub surface: Option<&'a SurfacePoint<f64>>,
    /// `ṫ`.
    pub thickness: f64,
    /// `Ė, ν̇, k̇, σ̇0, Ḣ, β̇` ([`MaterialParams::zero`] for none).
    pub material: MaterialParams<f64>,
    /// Sensitivities of the neighbours' committed states (`ⁿū̇, ⁿḋ, ḋ⁰, ė1, ė2`), in the order
    /// of [`PointInput::particles`].
    pub particles: &'a [ParticleState<f64>],
    /// `ⁿQ̇` and `ⁿ(σ̇, α̇, ė^p)` at this layer point.
    pub history: &'a PointHistory<f64>,
    /// `Δq̇` (5 per neighbour: `Δū̇_I`, `α̇_I`). It enters the residual through
    /// [`PointIncrementDot`], built from it once per in-plane point; here its length is checked.
    pub dofs: &'a [f64],
}

/// Derivative of one layer point's residual and trial history ([`point_residual_dot`]).
#[derive(Clone, Debug, PartialEq)]
pub struct PointDot {
    /// `d/dτ` of the internal force, `5 × n_neighbours` as [`PointResult::residual`].
    pub residual: Vec<f64>,
    /// `d/dτ` of the trial history `ⁿ⁺¹(Q, σ, α, ē^p)`.
    pub history: PointHistory<f64>,
}

/// Derivative of [`PointIncrement`] (layer-independent, once per in-plane point): `Δū̇_I`,
/// `Δḋ_I` and `d/dτ ∂d_I/∂α_β`.
#[derive(Clone, Debug, PartialEq)]
pub struct PointIncrementDot {
    /// `Δū̇_I`.
    pub du: Vec<V3>,
    /// `Δḋ_I`, the derivative of Rodrigues' increment `f1 θ×dⁿ + f2 θ×(θ×dⁿ)`.
    pub dd: Vec<V3>,
    /// `d/dτ ∂d_I/∂α_β`.
    pub d_alpha: Vec<[V3; 2]>,
}

/// Rodrigues' coefficients and their first two derivatives with respect to `x = θ·θ`.
#[derive(Clone, Copy, Debug)]
struct Coefficients {
    f1: [f64; 3],
    f2: [f64; 3],
}

impl Coefficients {
    fn at(theta: &V3) -> Self {
        let (f1, f2) = rodrigues_coefficient_derivatives(theta.dot(theta));
        Coefficients { f1, f2 }
    }
}

/// `d/dτ [f1 θ×v + f2 θ×(θ×v)]` (Rodrigues' increment of a vector `v` rotated by `θ`), with
/// `ẋ = 2θ·θ̇`, `c = θ×v`, `ċ = θ̇×v + θ×v̇`.
fn rodrigues_increment_dot(v: &V3, v_dot: &V3, theta: &V3, theta_dot: &V3, k: &Coefficients) -> V3 {
    let x_dot = theta.dot(theta_dot) * 2.0;
    let c = theta.cross(v);
    let c_dot = theta_dot.cross(v) + theta.cross(v_dot);
    let tc = theta.cross(&c);
    let tc_dot = theta_dot.cross(&c) + theta.cross(&c_dot);
    c_dot * k.f1[0] + c * (k.f1[1] * x_dot) + tc_dot * k.f2[0] + tc * (k.f2[1] * x_dot)
}

/// `d/dτ ∂d/∂α_β` of Rodrigues' formula ([`crate::kinematics::rotation::director_derivatives`]): with
/// `c = θ×d`, `x_β = 2θ·e_β`, `c_β = e_β×d`, `w_β = e_β×c + θ×c_β`,
/// `∂d/∂α_β = f1' x_β c + f1 c_β + f2' x_β θ×c + f2 w_β`, differentiated by the product rule in
/// `θ, d, e_β` (the second derivatives `f''` enter through `ẋ`).
fn director_first_derivatives_dot(
    d: &V3,
    d_dot: &V3,
    e: &[V3; 2],
    e_dot: &[V3; 2],
    theta: &V3,
    theta_dot: &V3,
    k: &Coefficients,
) -> [V3; 2] {
    let ([_, f1p, f1pp], [_, f2p, f2pp]) = (k.f1, k.f2);
    let (f1, f2) = (k.f1[0], k.f2[0]);
    let x_dot = theta.dot(theta_dot) * 2.0;
    let c = theta.cross(d);
    let c_dot = theta_dot.cross(d) + theta.cross(d_dot);
    let tc = theta.cross(&c);
    let tc_dot = theta_dot.cross(&c) + theta.cross(&c_dot);
    std::array::from_fn(|b| {
        let xb = theta.dot(&e[b]) * 2.0;
        let xb_dot = (theta_dot.dot(&e[b]) + theta.dot(&e_dot[b])) * 2.0;
        let cb = e[b].cross(d);
        let cb_dot = e_dot[b].cross(d) + e[b].cross(d_dot);
        let wb = e[b].cross(&c) + theta.cross(&cb);
        let wb_dot =
            e_dot[b].cross(&c) + e[b].cross(&c_dot) + theta_dot.cross(&cb) + theta.cross(&cb_dot);
        c_dot * (f1p * xb)
            + c * (f1pp * x_dot * xb + f1p * xb_dot)
            + cb_dot * f1
            + cb * (f1p * x_dot)
            + tc_dot * (f2p * xb)
            + tc * (f2pp * x_dot * xb + f2p * xb_dot)
            + wb_dot * f2
            + wb * (f2p * x_dot)
    })
}

fn invalid(field: &str, got: usize, expected: usize, what: &str) -> ShellError {
    ShellError::InvalidInput(format!(
        "{field}: {got} entries, expected {expected} ({what})"
    ))
}

impl PointIncrementDot {
    /// From the neighbours' committed states `particles`, their sensitivities `particles_dot`,
    /// the DOF increments `dofs` and their sensitivities `dofs_dot` (5 per neighbour: `Δū_I`
    /// then `α_I`): `θ̇ = ė1 α1 + ė2 α2 + e1 α̇1 + e2 α̇2` drives the derivatives of Rodrigues'
    /// increment and of its virtual directors.
    pub fn new(
        particles: &[ParticleState<f64>],
        particles_dot: &[ParticleState<f64>],
        dofs: &[f64],
        dofs_dot: &[f64],
    ) -> Result<Self, ShellError> {
        let n = particles.len();
        const D: usize = DOFS_PER_PARTICLE;
        if particles_dot.len() != n {
            return Err(invalid(
                "particles_dot",
                particles_dot.len(),
                n,
                "one per particle",
            ));
        }
        if dofs.len() != D * n {
            return Err(invalid("dofs", dofs.len(), D * n, "5 per particle"));
        }
        if dofs_dot.len() != D * n {
            return Err(invalid("dofs_dot", dofs_dot.len(), D * n, "5 per particle"));
        }
        let mut out = PointIncrementDot {
            du: Vec::with_capacity(n),
            dd: Vec::with_capacity(n),
            d_alpha: Vec::with_capacity(n),
        };
        for (((p, pd), q), qd) in particles
            .iter()
            .zip(particles_dot)
            .zip(dofs.chunks_exact(D))
            .zip(dofs_dot.chunks_exact(D))
        {
            let (du, dd, da) = particle_increment_dot(p, pd, q, qd);
            out.du.push(du);
            out.dd.push(dd);
            out.d_alpha.push(da);
        }
        Ok(out)
    }
}

/// One particle's `(Δū̇, Δḋ, (∂d/∂α_β)˙)`.
pub(crate) fn particle_increment_dot(
    p: &ParticleState<f64>,
    pd: &ParticleState<f64>,
    q: &[f64],
    qd: &[f64],
) -> (V3, V3, [V3; 2]) {
    let k = Coefficients::at(&rotation_vector(p, q));
    particle_increment_dot_with(p, pd, q, qd, &k)
}

/// The rotation vector `θ = e1 α1 + e2 α2` of a particle's increment `q` (5 DOFs).
fn rotation_vector(p: &ParticleState<f64>, q: &[f64]) -> V3 {
    p.e[0] * q[3] + p.e[1] * q[4]
}

/// `θ̇ = ė1 α1 + ė2 α2 + e1 α̇1 + e2 α̇2` ([`rotation_vector`] differentiated).
fn rotation_vector_dot(
    p: &ParticleState<f64>,
    pd: &ParticleState<f64>,
    q: &[f64],
    qd: &[f64],
) -> V3 {
    rotation_vector(pd, q) + rotation_vector(p, qd)
}

/// [`particle_increment_dot`] with Rodrigues' coefficients `k` of the increment given (they
/// depend on the f64 state alone, so one evaluation serves every seed set).
fn particle_increment_dot_with(
    p: &ParticleState<f64>,
    pd: &ParticleState<f64>,
    q: &[f64],
    qd: &[f64],
    k: &Coefficients,
) -> (V3, V3, [V3; 2]) {
    let (theta, theta_dot) = (rotation_vector(p, q), rotation_vector_dot(p, pd, q, qd));
    (
        V3::new(qd[0], qd[1], qd[2]),
        rodrigues_increment_dot(&p.d, &pd.d, &theta, &theta_dot, k),
        director_first_derivatives_dot(&p.d, &pd.d, &p.e, &pd.e, &theta, &theta_dot, k),
    )
}

/// Derivative of [`crate::shell::model::commit_particle`], the particle update of a
/// converged step: `ū̇ + Δū̇`, the director and first lamina vector rotated by Rodrigues'
/// formula (derivatives as [`PointIncrementDot`]), and the re-orthogonalised lamina vectors
/// `e1 = a/|a|`, `a = t − d (d·t)`: `ė1 = (ȧ − e1 (e1·ȧ))/|a|`, `ė2 = ḋ × e1 + d × ė1`.
/// `q`, `q_dot`: the particle's 5 DOF increments and their sensitivities (the first 5 entries
/// are used).
pub fn commit_particle_dot(
    p: &ParticleState<f64>,
    p_dot: &ParticleState<f64>,
    q: &[f64],
    q_dot: &[f64],
) -> ParticleState<f64> {
    let (theta, theta_dot) = (
        rotation_vector(p, q),
        rotation_vector_dot(p, p_dot, q, q_dot),
    );
    let k = Coefficients::at(&theta);
    let rotate = |v: &V3| {
        let c = theta.cross(v);
        v + c * k.f1[0] + theta.cross(&c) * k.f2[0]
    };
    let d = rotate(&p.d);
    let t = rotate(&p.e[0]);
    let d_dot = p_dot.d + rodrigues_increment_dot(&p.d, &p_dot.d, &theta, &theta_dot, &k);
    let t_dot = p_dot.e[0] + rodrigues_increment_dot(&p.e[0], &p_dot.e[0], &theta, &theta_dot, &k);
    let dt = d.dot(&t);
    let a = t - d * dt;
    let a_dot = t_dot - d_dot * dt - d * (d_dot.dot(&t) + d.dot(&t_dot));
    let na = a.norm();
    let e1 = a / na;
    let e1_dot = (a_dot - e1 * e1.dot(&a_dot)) / na;
    ParticleState {
        u: p_dot.u + V3::new(q_dot[0], q_dot[1], q_dot[2]),
        d: d_dot,
        d0: p_dot.d0,
        e: [e1_dot, d_dot.cross(&e1) + d.cross(&e1_dot)],
    }
}

/// Layer-independent sums of one seed set at one in-plane point (the neighbour loops of `J̇ⁿ`
/// and `Ġ`), combined with `z = ζt/2` per layer. The same sums of the values (without dots)
/// are the point's [`ValueSums`].
#[derive(Clone, Copy, Debug, Default)]
struct SeedSums {
    /// `ẋ⁰,α + Σ Ψ_I,α ū̇_I`.
    xa: [V3; 2],
    /// `ṅ⁰,α + Σ Ψ_I,α (ḋ_I − ḋ⁰_I)`.
    da: [V3; 2],
    /// `ṅ⁰ + Σ Ψ_I (ḋ_I − ḋ⁰_I)`.
    d: V3,
    /// `Σ Ψ_I,α Δū̇_I`.
    g_u: [V3; 2],
    /// `Σ Ψ_I,α Δḋ_I`.
    g_d: [V3; 2],
    /// `Σ Ψ_I Δḋ_I`.
    g_d3: V3,
}

impl SeedSums {
    /// `nb(i)`: neighbour i's state sensitivity, `Δū̇_I` and `Δḋ_I` (or, for [`ValueSums`], its
    /// state, `Δū` and `Δd`); `surface`: the surface's terms (`ẋ⁰,α`, `ṅ⁰,α`, `ṅ⁰`; zero
    /// without a surface seed).
    fn new<'p>(
        shape: &[ShapeData],
        surface: Option<&SurfacePoint<f64>>,
        nb: impl Fn(usize) -> (&'p ParticleState<f64>, V3, V3),
    ) -> Self {
        let mut f = FlatSums::start(surface);
        for (i, sh) in shape.iter().enumerate() {
            let (p, du, dd) = nb(i);
            f.add(sh, &flat_row(p, du, dd));
        }
        f.sums()
    }
}

/// `[ū, Δū, d − d⁰, Δd]` of a particle (or their sensitivities): its terms in the neighbour
/// sums of [`FlatSums`].
fn flat_row(p: &ParticleState<f64>, du: V3, dd: V3) -> [f64; 12] {
    let ddir = p.d - p.d0;
    let mut row = [0.0; 12];
    for (c, v) in [p.u, du, ddir, dd].iter().enumerate() {
        row[3 * c..3 * c + 3].copy_from_slice(v.as_slice());
    }
    row
}

/// One shape-function particle's f64 data in [`ShellModel::internal_force_dots`]: its
/// committed state, local DOF increment `x`, [`flat_row`] of the values, `∂d/∂α_β` after the
/// increment and Rodrigues' coefficients of the increment (shared by every seed set).
struct ParticleValues {
    state: ParticleState<f64>,
    x: [f64; DOFS_PER_PARTICLE],
    row: [f64; 12],
    d_alpha: [V3; 2],
    k: Coefficients,
}

/// One shape-function particle's data of one seed set, as the neighbour loops read it: `row`
/// = `[ū̇, Δū̇, ḋ − ḋ⁰, Δḋ]` ([`flat_row`] of the sensitivities) and
/// `(∂d/∂α_β)˙`.
#[derive(Clone, Copy, Debug)]
struct NeighbourDot {
    row: [f64; 12],
    d_alpha: [V3; 2],
}

/// The neighbour sums of [`SeedSums`] in flat form: `a[α] = Σ Ψ_I,α row_I` (the sums
/// `x̄,α, Σ Ψ,α Δū, d,α, Σ Ψ,α Δd` of the rows of [`flat_row`]) and
/// `psi = Σ Ψ_I row_I[6..12]` (`d`, `Σ Ψ Δd`), on fixed-size arrays.
#[derive(Clone, Copy, Debug, Default)]
struct FlatSums {
    a: [[f64; 12]; 2],
    psi: [f64; 6],
}

impl FlatSums {
    /// The surface's terms alone (`ẋ⁰,α`, `ṅ⁰,α`, `ṅ⁰`; zero without a surface seed).
    fn start(surface: Option<&SurfacePoint<f64>>) -> Self {
        let mut f = FlatSums::default();
        if let Some(sp) = surface {
            for a in 0..2 {
                f.a[a][0..3].copy_from_slice(sp.x_a[a].as_slice());
                f.a[a][6..9].copy_from_slice(sp.n_a[a].as_slice());
            }
            f.psi[0..3].copy_from_slice(sp.n.as_slice());
        }
        f
    }

    // Indexed loops: this form compiled to 2.9 M fewer instructions per pass on the hemisphere
    // (callgrind) than iterator zips over the accumulators.
    #[allow(clippy::needless_range_loop)]
    #[inline]
    fn add(&mut self, sh: &ShapeData, row: &[f64; 12]) {
        let [w0, w1] = sh.dpsi;
        for c in 0..12 {
            self.a[0][c] += row[c] * w0;
            self.a[1][c] += row[c] * w1;
        }
        for c in 0..6 {
            self.psi[c] += row[6 + c] * sh.psi;
        }
    }

    fn sums(&self) -> SeedSums {
        let v = |s: &[f64]| V3::new(s[0], s[1], s[2]);
        SeedSums {
            xa: [v(&self.a[0][0..3]), v(&self.a[1][0..3])],
            g_u: [v(&self.a[0][3..6]), v(&self.a[1][3..6])],
            da: [v(&self.a[0][6..9]), v(&self.a[1][6..9])],
            g_d: [v(&self.a[0][9..12]), v(&self.a[1][9..12])],
            d: v(&self.psi[0..3]),
            g_d3: v(&self.psi[3..6]),
        }
    }

    /// The sums of several seed sets at once into `out` (one per item of `surfaces`), each
    /// seed set's added in neighbour order as [`SeedSums::new`] does (the same floating-point
    /// results). The seed sets outside and the neighbours inside, so that one seed set's
    /// accumulators stay in registers over its neighbour loop. `row(s, i)`: seed set `s`'s row
    /// of neighbour `i`.
    fn fill_all<'s, 'r>(
        out: &mut Vec<SeedSums>,
        shape: &[ShapeData],
        surfaces: impl Iterator<Item = Option<&'s SurfacePoint<f64>>>,
        row: impl Fn(usize, usize) -> &'r [f64; 12],
    ) {
        out.clear();
        out.extend(surfaces.enumerate().map(|(s, surface)| {
            let mut acc = FlatSums::start(surface);
            for (i, sh) in shape.iter().enumerate() {
                acc.add(sh, row(s, i));
            }
            acc.sums()
        }));
    }
}

/// Value sums at one in-plane point (f64, layer-independent): `x̄,α = x⁰,α + Σ Ψ_I,α ū_I`,
/// `d,α = n⁰,α + Σ Ψ_I,α (d_I − d⁰_I)`, `d = n⁰ + Σ Ψ_I (d_I − d⁰_I)`, `Σ Ψ_I,α Δū_I`,
/// `Σ Ψ_I,α Δd_I`, `Σ Ψ_I Δd_I`: the layers' `Jⁿ` and `G` (and the factors of `ż`, `ṫ/2`).
/// The same neighbour sums as [`SeedSums`], of the values.
type ValueSums = SeedSums;

impl ValueSums {
    fn of_values(
        s: &SurfacePoint<f64>,
        shape: &[ShapeData],
        particles: &[ParticleState<f64>],
        incr: &PointIncrement<f64>,
    ) -> Self {
        SeedSums::new(shape, Some(s), |i| (&particles[i], incr.du[i], incr.dd[i]))
    }

    /// The f64 evaluation of one layer of the point ([`point_residual_with`](super::point::point_residual_with)'s chain, eqs
    /// 22–32) from the layer-independent sums: `Jⁿ = [x̄,α + d,α z | d t/2]`,
    /// `G = [Σ Ψ,α Δū + z Σ Ψ,α Δd | t/2 Σ Ψ Δd]`, then `H`, `L` (eq 57), the Hughes–Winget
    /// increment, `Δεˡ`, the return map, `ⁿ⁺¹Q`, `σᵍ` and `P = w det J σᵍ J⁻ᵀ`. Only the
    /// residual rows are left out (`residual` is empty): the model forms them once per in-plane
    /// point from the thickness sums of `P`. The same checks and errors as
    /// [`point_residual_with`](super::point::point_residual_with).
    fn layer(&self, inp: &PointInput<f64>) -> Result<PointResult<f64>, ShellError> {
        let half_t = inp.thickness * 0.5;
        let z = half_t * inp.zeta;
        let jn = M3::from_columns(&[
            self.xa[0] + self.da[0] * z,
            self.xa[1] + self.da[1] * z,
            self.d * half_t,
        ]);
        let g = M3::from_columns(&[
            self.g_u[0] + self.g_d[0] * z,
            self.g_u[1] + self.g_d[1] * z,
            self.g_d3 * half_t,
        ]);
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
        let (det1, j1_inv) = invert(&(jn + g), "ⁿ⁺¹J (end-of-step configuration)")?;
        let p = sigma_g * j1_inv.transpose() * (det1 * inp.weight);
        Ok(PointResult {
            residual: Vec::new(),
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
                unit_director: None,
            },
        })
    }
}

/// The unit director's maps at one in-plane point ([`DirectorField::Normalised`], module
/// [`crate::kinematics::unit_director`]): the step-start and end-of-step directors of the
/// interpolants `rₙ` and `r₁ = rₙ + Σ Ψ_I Δd_I`, with `N′` and `H(r,α)` at both.
struct UnitPoint {
    step: UnitDirectorStep<f64>,
    np_n: M3<f64>,
    h_n: [M3<f64>; 2],
    np_1: M3<f64>,
    h_1: [M3<f64>; 2],
    /// `N′₁ − N′ₙ` and `H₁(r,α) − Hₙ(r,α)`, formed without cancellation.
    dnp: M3<f64>,
    dh: [M3<f64>; 2],
}

impl UnitPoint {
    /// From the value sums of the interpolant (`d = rₙ`, `d,α = rₙ,α`, `g_d3 = δ`,
    /// `g_d = δ,α`).
    fn new(raw: &ValueSums) -> Self {
        let step = step_change(&raw.d, &raw.da, &raw.g_d3, &raw.g_d);
        let (dn, d1, l1, ln) = (step.dn, step.d1, step.l1, step.ln);
        UnitPoint {
            np_n: n_prime(&dn, ln),
            h_n: [n_second(&dn, ln, &raw.da[0]), n_second(&dn, ln, &raw.da[1])],
            np_1: n_prime(&d1, l1),
            h_1: [
                n_second(&d1, l1, &step.r1_a[0]),
                n_second(&d1, l1, &step.r1_a[1]),
            ],
            dnp: step.n_prime_change(),
            dh: [
                step.n_second_change(0, &raw.da[0]),
                step.n_second_change(1, &raw.da[1]),
            ],
            step,
        }
    }

    /// The value sums of the unit director: `d = dₙ`, `d,α = dₙ,α`, `g_d3 = d₁ − dₙ`,
    /// `g_d = d₁,α − dₙ,α`.
    fn values(&self, raw: &ValueSums) -> ValueSums {
        let st = &self.step;
        SeedSums {
            d: st.dn,
            da: st.dn_a,
            g_d3: st.dd,
            g_d: st.dd_a,
            ..*raw
        }
    }

    /// The seed sums of the unit director from those of the interpolant:
    /// `ḋ = N′ ṙ`, `ḋ,α = N′ ṙ,α + H(r,α) ṙ` at both ends of the step (`ṙ₁ = ṙₙ + δ̇`).
    ///
    /// The changes over the step are formed from the changes of the maps
    /// ([`UnitDirectorStep::n_prime_change`], [`UnitDirectorStep::n_second_change`]):
    /// `ḋ₁ − ḋₙ = N′₁ δ̇ + ΔN′ ṙₙ` and
    /// `ḋ₁,α − ḋₙ,α = N′₁ δ̇,α + ΔN′ ṙₙ,α + H₁(r,α) δ̇ + ΔH(r,α) ṙₙ`, not as differences of
    /// the two ends, whose cancellation would leave an absolute error of order ε |ṙₙ| in a
    /// change of order |δ̇| (the small increments of an elastic step).
    fn seeds(&self, raw: &SeedSums) -> SeedSums {
        let dn_dot = self.np_n * raw.d;
        let dn_a = [0, 1].map(|a| self.np_n * raw.da[a] + self.h_n[a] * raw.d);
        let dnp = &self.dnp;
        let g_d = [0, 1].map(|a| {
            self.np_1 * raw.g_d[a] + dnp * raw.da[a] + self.h_1[a] * raw.g_d3 + self.dh[a] * raw.d
        });
        SeedSums {
            d: dn_dot,
            da: dn_a,
            g_d3: self.np_1 * raw.g_d3 + dnp * raw.d,
            g_d,
            ..*raw
        }
    }

    /// The rows' maps of the unit director for the layer sums `val` and, per seed set, the
    /// interpolant's seed sums `raw[s]`, their stress sums `dots[s]` and `ṫ/2`.
    fn rows(
        &self,
        val: &StressSums,
        raw: &[SeedSums],
        dots: &[StressSums],
        half_t_dot: &[f64],
    ) -> UnitRows {
        let (d1, l1) = (self.step.d1, self.step.l1);
        let r1_a = self.step.r1_a;
        let y = [val.pz.column(0).into_owned(), val.pz.column(1).into_owned()];
        let hy = [n_second(&d1, l1, &y[0]), n_second(&d1, l1, &y[1])];
        let t_sum = n_third(&d1, l1, &y[0], &r1_a[0]) + n_third(&d1, l1, &y[1], &r1_a[1]);
        let geo = self.h_1[0] * y[0] + self.h_1[1] * y[1];
        let mut r1_dot = Vec::with_capacity(raw.len());
        let mut geo_dot = Vec::with_capacity(raw.len());
        for ((rs, dot), &htd) in raw.iter().zip(dots).zip(half_t_dot) {
            let rd = rs.d + rs.g_d3;
            let rad = [rs.da[0] + rs.g_d[0], rs.da[1] + rs.g_d[1]];
            // ẏ_α = Σ (z Ṗ + ż P):α, ż = ζ ṫ/2.
            let yd = |a: usize| dot.pz.column(a) + val.pzeta.column(a) * htd;
            geo_dot.push(
                t_sum * rd
                    + self.h_1[0] * yd(0)
                    + self.h_1[1] * yd(1)
                    + hy[0] * rad[0]
                    + hy[1] * rad[1],
            );
            r1_dot.push(rd);
        }
        UnitRows {
            np: self.np_1,
            d: d1,
            l: l1,
            geo,
            r1_dot,
            geo_dot,
        }
    }
}

/// What the residual rows' derivative needs of a unit director ([`UnitPoint::rows`]): with the
/// interpolant's moment `m_I`, the row moment is `m̂_I = N′ m_I + Ψ_I g`,
/// `g = Σ_α H(r,α) y_α`, `y_α = Σ z P:α`, and
/// `m̂̇_I = N′ ṁ_I + H(m_I) ṙ + Ψ_I ġ`, `ġ = Σ_α [T(y_α, r,α) ṙ + H(r,α) ẏ_α + H(y_α) ṙ,α]`.
struct UnitRows {
    np: M3<f64>,
    d: V3,
    l: f64,
    geo: V3,
    r1_dot: Vec<V3>,
    geo_dot: Vec<V3>,
}

impl UnitRows {
    /// `H(y) b` without forming `H(y)`.
    fn h_apply(&self, y: &V3, b: &V3) -> V3 {
        n_second_apply(&self.d, self.l, y, b)
    }
}

/// `(det M, M⁻¹)` of a configuration matrix; a non-positive (or NaN) determinant is an error
/// naming the matrix, as in the analysis.
fn invert(m: &M3<f64>, what: &'static str) -> Result<(f64, M3<f64>), ShellError> {
    let det = m.determinant();
    if det.is_nan() || det <= 0.0 {
        return Err(ShellError::NonPositiveJacobian { what, det });
    }
    let inv = m
        .try_inverse()
        .ok_or(ShellError::NonPositiveJacobian { what, det })?;
    Ok((det, inv))
}

/// The f64 data of one layer point shared by all seed sets, with the seed-independent factors
/// of the chain formed once ([`LayerKeep`] holds those the increment-only part needs).
struct LayerData {
    zeta: f64,
    half_t: f64,
    z: f64,
    h: M3<f64>,
    /// `2 · ½rᵀ Δε Aᵀ` (the `Q̇ₙ` term of eq 50, doubled for `Δε̇ˡ`'s symmetric part) and `rᵀ`
    /// (the `Q̇ₙ` term of eq 51).
    r_half_t_c2: M3<f64>,
    r_t: M3<f64>,
    /// `ⁿ⁺¹Qᵀ E_k ⁿ⁺¹Q` for the five unit stresses `E_k` of [`stress_from_vec5`] (rows: the
    /// symmetric entries `00, 11, 22, 01, 12, 02`): `ⁿ⁺¹Qᵀ σ̇ˡ ⁿ⁺¹Q = B σ̇ˡ` (eq 42).
    b: SMatrix<f64, 6, 5>,
    /// `ⁿ⁺¹Qᵀ σˡ`.
    qt_sigma: M3<f64>,
    /// `ⁿ⁺¹J⁻¹` and `w det J J⁻ᵀ`.
    jinv: M3<f64>,
    jinv_t_w: M3<f64>,
    p: M3<f64>,
    /// The return-map sensitivity's seed-independent factors (eqs 44–49).
    material: MaterialSensitivity,
    keep: LayerKeep,
}

/// `strain_to_vec5(X)` of a matrix given by its entries `e(i, j)` (the (2, 2) entry unused).
fn vec5_of(e: impl Fn(usize, usize) -> f64) -> Vec5<f64> {
    Vec5::new(
        e(0, 0),
        e(1, 1),
        e(0, 1) + e(1, 0),
        e(1, 2) + e(2, 1),
        e(2, 0) + e(0, 2),
    )
}

/// `strain_to_vec5(A B)` without forming the product's unused (2, 2) entry.
fn vec5_of_product(a: &M3<f64>, b: &M3<f64>) -> Vec5<f64> {
    vec5_of(|i, j| a[(i, 0)] * b[(0, j)] + a[(i, 1)] * b[(1, j)] + a[(i, 2)] * b[(2, j)])
}

/// The axial vector of `skew M` (`skew M = [ω]×`).
fn axial(m: &M3<f64>) -> V3 {
    V3::new(
        (m[(2, 1)] - m[(1, 2)]) * 0.5,
        (m[(0, 2)] - m[(2, 0)]) * 0.5,
        (m[(1, 0)] - m[(0, 1)]) * 0.5,
    )
}

impl LayerData {
    fn new(inp: &PointInput<f64>, res: &PointResult<f64>) -> Self {
        let k = &res.kinematics;
        // F½⁻¹ = (I + ½H)⁻¹ = I − ½H F½⁻¹ = I − ½L (eq 57: L = H F½⁻¹), with L = Δε + Δω.
        let f_half_inv = M3::identity() - (k.inc.deps + k.inc.domega) * 0.5;
        let q_n = inp.history.frame;
        let r_half_t = k.inc.r_half.transpose();
        let a = q_n * r_half_t;
        let c = k.inc.deps * a.transpose();
        // Δεˡ = A Δε Aᵀ (eq 50's value, kinematics::local_strain_increment).
        let deps_l = strain_to_vec5(&(a * c));
        let half_t = inp.thickness * 0.5;
        let q1 = res.history.frame;
        let sigma_l = stress_from_vec5(&res.history.material.stress);
        let jinv_t = k.j1_inv.transpose();
        let material = MaterialSensitivity::new(inp.material, &deps_l, &res.return_map);
        // The rotation rates are linear in the spin rate's axial vector ω (Δω̇ = [ω]×,
        // eqs 54–55): ṙ = Σ ω_i (I − ½Δω)⁻¹ E_i ½(I + r), ½ṙ = Σ ω_i (I − ¼Δω)⁻¹ E_i ¼(I + ½r)
        // with E_i = [e_i]×, so the terms Qₙ ½ṙᵀ Δε Aᵀ (eq 50) and Qₙ ṙᵀ (eq 51) are
        // Σ ω_i of per-layer matrices, formed once here for every seed set:
        // (R E_i S)ᵀ = −Sᵀ E_i Rᵀ. The resolvents follow from the Cayley transforms of the f64
        // evaluation: r = 2(I − ½Δω)⁻¹ − I, ½r = 2(I − ¼Δω)⁻¹ − I (eqs 23, 31).
        // So (I − ½Δω)⁻¹ = ½(I + r) = S1 and (I − ¼Δω)⁻¹ = ½(I + ½r) = 2 S2.
        let s1 = (M3::identity() + k.inc.r) * 0.5;
        let r2 = (M3::identity() + k.inc.r_half) * 0.5;
        let s2 = r2 * 0.5;
        let (u, w) = (q_n * s2.transpose(), r2.transpose() * c);
        let (v, r1t) = (q_n * s1.transpose(), s1.transpose());
        // −(U [e_i]×) W = U:j ⊗ Wk: − U:k ⊗ Wj: for (i, j, k) cyclic ([e_i]× e_j = e_k,
        // [e_i]× e_k = −e_j): two outer products instead of two matrix products.
        let frame_rot = std::array::from_fn(|i| {
            let (j, k) = ((i + 1) % 3, (i + 2) % 3);
            v.column(j) * r1t.row(k) - v.column(k) * r1t.row(j)
        });
        // Of the strain term X + Xᵀ (X the outer products' difference) only `strain_to_vec5`
        // enters `Δε̇ˡ`: 2 · strain_to_vec5(X).
        let strain_rot5 = std::array::from_fn(|i| {
            let (j, k) = ((i + 1) % 3, (i + 2) % 3);
            vec5_of(|p, q| u[(p, j)] * w[(k, q)] - u[(p, k)] * w[(j, q)]) * 2.0
        });
        // B's columns: Qᵀ E_k Q = q_i ⊗ q_j (+ q_j ⊗ q_i), q_i the rows of ⁿ⁺¹Q.
        let qr: [V3; 3] = std::array::from_fn(|i| q1.row(i).transpose());
        let sym = |x: &V3, y: &V3| {
            nalgebra::Vector6::new(
                x[0] * y[0] + y[0] * x[0],
                x[1] * y[1] + y[1] * x[1],
                x[2] * y[2] + y[2] * x[2],
                x[0] * y[1] + y[0] * x[1],
                x[1] * y[2] + y[1] * x[2],
                x[0] * y[2] + y[0] * x[2],
            )
        };
        let b = SMatrix::<f64, 6, 5>::from_columns(&[
            sym(&qr[0], &qr[0]) * 0.5,
            sym(&qr[1], &qr[1]) * 0.5,
            sym(&qr[0], &qr[1]),
            sym(&qr[1], &qr[2]),
            sym(&qr[2], &qr[0]),
        ]);
        let jn_inv_f = k.jn_inv * f_half_inv;
        LayerData {
            zeta: inp.zeta,
            half_t,
            z: half_t * inp.zeta,
            h: k.h,
            r_half_t_c2: r_half_t * c * 2.0,
            r_t: k.inc.r.transpose(),
            b,
            qt_sigma: q1.transpose() * sigma_l,
            jinv: k.j1_inv,
            jinv_t_w: jinv_t * (k.det1 * inp.weight),
            p: k.p,
            material,
            keep: LayerKeep {
                a_f: a * f_half_inv,
                f_a: jn_inv_f * a.transpose(),
                a,
                strain_rot5,
                frame_rot,
                material: material.strain_map(),
            },
        }
    }

    /// The layer's `Ṗ` for one seed set, added into `acc` (with its `z`-moment), and the trial
    /// history's derivative.
    fn apply(
        &self,
        values: &ValueSums,
        sums: &SeedSums,
        t_dot: f64,
        material_dot: &MaterialParams<f64>,
        history_dot: &PointHistory<f64>,
        acc: &mut StressSums,
    ) -> PointHistory<f64> {
        let (z, half_t, k) = (self.z, self.half_t, &self.keep);
        let half_t_dot = t_dot * 0.5;
        let z_dot = half_t_dot * self.zeta;
        // J̇ⁿ: the parametric gradient of the step-start design velocity ⁿV.
        let jn_dot = M3::from_columns(&[
            sums.xa[0] + sums.da[0] * z + values.da[0] * z_dot,
            sums.xa[1] + sums.da[1] * z + values.da[1] * z_dot,
            sums.d * half_t + values.d * half_t_dot,
        ]);
        // Ġ (the increment's gradient on the parameter coordinates).
        let g_dot = M3::from_columns(&[
            sums.g_u[0] + sums.g_d[0] * z + values.g_d[0] * z_dot,
            sums.g_u[1] + sums.g_d[1] * z + values.g_d[1] * z_dot,
            sums.g_d3 * half_t + values.g_d3 * half_t_dot,
        ]);
        // Ḣ = Ġ Jⁿ⁻¹ − G Jⁿ⁻¹ J̇ⁿ Jⁿ⁻¹ = (Ġ − H J̇ⁿ) Jⁿ⁻¹ (the −H ∇ⁿV term of eqs 39–40), and
        // L̇ = F½⁻¹ Ḣ F½⁻¹ (eqs 56–57), seen in the rotated frame (LayerKeep::rates).
        let (deps_dot_l, omega) = k.rates(&(g_dot - self.h * jn_dot));
        // Δε̇ˡ with the history frame's sensitivity (eq 50): Ȧ = Q̇ₙ ½rᵀ + Qₙ ½ṙᵀ.
        let deps_l_dot = k.strain_dot(
            &vec5_of_product(&history_dot.frame, &self.r_half_t_c2),
            &omega,
            &deps_dot_l,
        );
        // Return-map sensitivity (eqs 44–49).
        let mat_dot = self
            .material
            .apply(material_dot, &history_dot.material, &deps_l_dot);
        // ⁿ⁺¹Q̇ = Q̇ₙ rᵀ + Qₙ ṙᵀ (eq 51) and σ̇ᵍ = Q̇ᵀσˡQ + Qᵀσ̇ˡQ + QᵀσˡQ̇ (eq 42; σˡ is
        // symmetric, so the first term is the transpose of the last; Qᵀσ̇ˡQ = B σ̇ˡ).
        let q1_dot = history_dot.frame * self.r_t + k.frame_rate(&omega);
        let x = self.qt_sigma * q1_dot;
        let s = self.b * mat_dot.stress;
        let (s01, s12, s02) = (
            x[(0, 1)] + x[(1, 0)] + s[3],
            x[(1, 2)] + x[(2, 1)] + s[4],
            x[(0, 2)] + x[(2, 0)] + s[5],
        );
        let sigma_g_dot = M3::new(
            x[(0, 0)] * 2.0 + s[0],
            s01,
            s02,
            s01,
            x[(1, 1)] * 2.0 + s[1],
            s12,
            s02,
            s12,
            x[(2, 2)] * 2.0 + s[2],
        );
        // P = w det(J) σᵍ J⁻ᵀ on J = Jⁿ + G:
        // Ṗ = tr(J⁻¹J̇) P + w det J σ̇ᵍ J⁻ᵀ − P J̇ᵀ J⁻ᵀ.
        // With K = J⁻¹J̇: Ṗ = tr(K) P + w det J σ̇ᵍ J⁻ᵀ − P Kᵀ.
        let kk = self.jinv * (jn_dot + g_dot);
        let p_dot = self.p * kk.trace() + sigma_g_dot * self.jinv_t_w - self.p * kk.transpose();
        acc.add(&p_dot, z);
        PointHistory {
            frame: q1_dot,
            material: mat_dot,
        }
    }
}

/// Thickness sums of the nominal stress `P` of the layers of one point: `Σ_l P_l`, `Σ_l z_l P_l`
/// (the first two columns only are used with `z`) and `Σ_l ζ_l P_l`. The rows are linear in
/// them (`f_I = Ψ_I,α P:α`, `m_I = z f_I + t/2 Ψ_I P:3`), so the rows of all layers are formed
/// once per point from these sums rather than once per layer.
#[derive(Clone, Copy, Debug)]
struct StressSums {
    p: M3<f64>,
    pz: M3<f64>,
    pzeta: M3<f64>,
}

impl StressSums {
    fn zero() -> Self {
        StressSums {
            p: M3::zeros(),
            pz: M3::zeros(),
            pzeta: M3::zeros(),
        }
    }
    fn add(&mut self, p: &M3<f64>, z: f64) {
        self.p += p;
        self.pz += p * z;
    }
    fn add_value(&mut self, p: &M3<f64>, z: f64, zeta: f64) {
        self.add(p, z);
        self.pzeta += p * zeta;
    }
}

/// The residual rows' derivative (eqs 62–64) from the layer sums of the nominal stress `val`
/// and of its derivative `dots[s]` (one per seed set, with `half_t_dot[s] = ṫ/2`):
/// `ḟ_I = Ψ_I,α Σ Ṗ:α`, `m_I = Ψ_I,α Σ z P:α + t/2 Ψ_I Σ P:3`,
/// `ṁ_I = Ψ_I,α (Σ z Ṗ:α + ṫ/2 Σ ζ P:α) + Ψ_I (t/2 Σ Ṗ:3 + ṫ/2 Σ P:3)` (`ż = ζ ṫ/2`),
/// `ṙ_Iβ = (∂d_I/∂α_β)˙ · m_I + ∂d_I/∂α_β · ṁ_I`. The neighbour loop is outside, so each
/// neighbour's shape data and the seed-independent moment `m_I` are formed once. Neighbour
/// `i`'s rows of every seed set (`rows[s]`, 5 each) go to `emit(i, rows)`.
#[allow(clippy::too_many_arguments)]
fn add_rows_dot_all(
    shape: &[ShapeData],
    d_alpha: &[[V3; 2]],
    d_alpha_dot: impl Fn(usize, usize) -> [V3; 2],
    half_t: f64,
    half_t_dot: &[f64],
    val: &StressSums,
    dots: &[StressSums],
    unit: Option<&UnitRows>,
    rows: &mut Vec<[f64; DOFS_PER_PARTICLE]>,
    mut emit: impl FnMut(usize, &[[f64; DOFS_PER_PARTICLE]]),
) {
    let p3 = val.p.column(2);
    rows.clear();
    rows.resize(dots.len(), [0.0; DOFS_PER_PARTICLE]);
    for (i, (sh, da)) in shape.iter().zip(d_alpha).enumerate() {
        let [t0, t1] = sh.dpsi_test;
        let m = val.pz.column(0) * t0 + val.pz.column(1) * t1 + p3 * (half_t * sh.psi);
        let mz = val.pzeta.column(0) * t0 + val.pzeta.column(1) * t1;
        for (s, ((dot, &htd), o)) in dots.iter().zip(half_t_dot).zip(rows.iter_mut()).enumerate() {
            let dad = d_alpha_dot(s, i);
            let pd3 = dot.p.column(2);
            let f_dot = dot.p.column(0) * t0 + dot.p.column(1) * t1;
            let m_dot = dot.pz.column(0) * t0
                + dot.pz.column(1) * t1
                + mz * htd
                + pd3 * (half_t * sh.psi)
                + p3 * (htd * sh.psi);
            let (m, m_dot) = match unit {
                None => (m, m_dot),
                Some(u) => (
                    u.np * m + u.geo * sh.psi,
                    u.np * m_dot + u.h_apply(&m, &u.r1_dot[s]) + u.geo_dot[s] * sh.psi,
                ),
            };
            *o = [
                f_dot[0],
                f_dot[1],
                f_dot[2],
                dad[0].dot(&m) + da[0].dot(&m_dot),
                dad[1].dot(&m) + da[1].dot(&m_dot),
            ];
        }
        emit(i, rows);
    }
}

/// `d/dτ` of [`point_residual_with`](super::point::point_residual_with)'s residual and trial history at one layer point.
///
/// `inp`, `incr`, `res`: the f64 evaluation (`res = point_residual_with(inp, incr)`);
/// `incr_dot`: the increment's derivative ([`PointIncrementDot::new`] from `inp.particles`,
/// `seeds.particles`, the DOFs and `seeds.dofs`); `seeds`: the remaining seeds. Linear in the
/// seeds. Errors name the field whose length does not match the neighbours.
pub fn point_residual_dot(
    inp: &PointInput<f64>,
    incr: &PointIncrement<f64>,
    incr_dot: &PointIncrementDot,
    res: &PointResult<f64>,
    seeds: &PointSeeds,
) -> Result<PointDot, ShellError> {
    let n = inp.shape.len();
    check_point_sizes(inp, incr, incr_dot, res, seeds)?;
    let raw_values = ValueSums::of_values(inp.surface, inp.shape, inp.particles, incr);
    let raw_sums = SeedSums::new(inp.shape, seeds.surface, |i| {
        (&seeds.particles[i], incr_dot.du[i], incr_dot.dd[i])
    });
    let unit = (inp.director == DirectorField::Normalised).then(|| UnitPoint::new(&raw_values));
    let (values, sums) = match &unit {
        None => (raw_values, raw_sums),
        Some(u) => (u.values(&raw_values), u.seeds(&raw_sums)),
    };
    let layer = LayerData::new(inp, res);
    let mut dot = StressSums::zero();
    let history = layer.apply(
        &values,
        &sums,
        seeds.thickness,
        &seeds.material,
        seeds.history,
        &mut dot,
    );
    let mut val = StressSums::zero();
    val.add_value(&layer.p, layer.z, layer.zeta);
    let mut residual = vec![0.0; DOFS_PER_PARTICLE * n];
    let half_t_dot = [seeds.thickness * 0.5];
    let unit_rows = unit.as_ref().map(|u| {
        u.rows(
            &val,
            std::slice::from_ref(&raw_sums),
            std::slice::from_ref(&dot),
            &half_t_dot,
        )
    });
    add_rows_dot_all(
        inp.shape,
        &incr.d_alpha,
        |_, i| incr_dot.d_alpha[i],
        layer.half_t,
        &half_t_dot,
        &val,
        std::slice::from_ref(&dot),
        unit_rows.as_ref(),
        &mut Vec::new(),
        |i, rows| {
            let at = DOFS_PER_PARTICLE * i;
            residual[at..at + DOFS_PER_PARTICLE].copy_from_slice(&rows[0]);
        },
    );
    Ok(PointDot { residual, history })
}

fn check_point_sizes(
    inp: &PointInput<f64>,
    incr: &PointIncrement<f64>,
    incr_dot: &PointIncrementDot,
    res: &PointResult<f64>,
    seeds: &PointSeeds,
) -> Result<(), ShellError> {
    let n = inp.shape.len();
    let per = "one per neighbour (inp.shape)";
    for (field, got) in [
        ("inp.particles", inp.particles.len()),
        ("incr.du", incr.du.len()),
        ("incr.dd", incr.dd.len()),
        ("incr.d_alpha", incr.d_alpha.len()),
        ("incr_dot.du", incr_dot.du.len()),
        ("incr_dot.dd", incr_dot.dd.len()),
        ("incr_dot.d_alpha", incr_dot.d_alpha.len()),
        ("seeds.particles", seeds.particles.len()),
    ] {
        if got != n {
            return Err(invalid(field, got, n, per));
        }
    }
    let nd = DOFS_PER_PARTICLE * n;
    let per5 = "5 per neighbour (inp.shape)";
    if seeds.dofs.len() != nd {
        return Err(invalid("seeds.dofs", seeds.dofs.len(), nd, per5));
    }
    if res.residual.len() != nd {
        return Err(invalid("res.residual", res.residual.len(), nd, per5));
    }
    Ok(())
}

/// One seed set's result of [`ShellModel::internal_force_dots`]: `d f_int/dτ` (`n_dofs`) and the
/// trial history sensitivities (point-major, as [`ShellModel::history`]).
pub type InternalForceDot = (Vec<f64>, Vec<PointHistory<f64>>);

/// The seeds of one design variable for the whole model ([`ShellModel::internal_force_dots`]).
#[derive(Clone, Copy, Debug)]
pub struct ModelSeeds<'a> {
    /// Design velocity of the initial geometry per in-plane point (as [`ShellModel::points`]);
    /// `None` = zero.
    pub surface: Option<&'a [SurfacePoint<f64>]>,
    /// `ṫ`.
    pub thickness: f64,
    /// `Ė, ν̇, k̇, σ̇0, Ḣ, β̇`.
    pub material: MaterialParams<f64>,
    /// Sensitivities of the committed states of the real particles (as
    /// [`ShellModel::particles`]; images follow through their fixed maps).
    pub particles: &'a [ParticleState<f64>],
    /// History sensitivities, point-major as [`ShellModel::history`].
    pub history: &'a [PointHistory<f64>],
    /// `Δq̇` on the global DOFs (`n_dofs`).
    pub dofs: &'a [f64],
}

/// One in-plane point's kept data in [`ShellModel::internal_force_dots_linearised`]: its layers'
/// [`LayerKeep`] and its unit director's end-of-step maps.
type KeepSlot<'a> = (&'a mut [LayerKeep], &'a mut Option<[M3<f64>; 3]>);

/// The number of fixed point chunks of [`ShellModel::internal_force_dots`] (a few per
/// thread for load balance; each holds one force vector per seed set).
const POINT_CHUNKS: usize = 32;

/// Per-chunk buffers of [`ShellModel::internal_force_dots`], reused from point to point.
#[derive(Default)]
struct Scratch {
    rows: Vec<[f64; DOFS_PER_PARTICLE]>,
    parts: Vec<ParticleState<f64>>,
    d_alpha: Vec<[V3; 2]>,
    sums: Vec<SeedSums>,
    unit_sums: Vec<SeedSums>,
    dots: Vec<StressSums>,
}

impl ShellModel {
    /// The fixed map of shape-function particle `j`: `(source, Q, det Q)`, `Q = I` for a real one.
    fn seed_map(&self, j: usize) -> (usize, Matrix3<f64>, f64) {
        let n = self.particles.len();
        if j < n {
            (j, Matrix3::identity(), 1.0)
        } else {
            let im = &self.symmetry.images[j - n];
            (im.source, im.map, im.det)
        }
    }

    fn check_model_seeds(&self, s: usize, seeds: &ModelSeeds) -> Result<(), ShellError> {
        let f = |name: &str| format!("seeds[{s}].{name}");
        if let Some(sp) = seeds.surface {
            if sp.len() != self.points.len() {
                return Err(invalid(
                    &f("surface"),
                    sp.len(),
                    self.points.len(),
                    "one per in-plane point",
                ));
            }
        }
        if seeds.particles.len() != self.particles.len() {
            return Err(invalid(
                &f("particles"),
                seeds.particles.len(),
                self.particles.len(),
                "one per real particle",
            ));
        }
        if seeds.history.len() != self.history.len() {
            return Err(invalid(
                &f("history"),
                seeds.history.len(),
                self.history.len(),
                "one per layer point, point-major",
            ));
        }
        if seeds.dofs.len() != self.n_dofs() {
            return Err(invalid(
                &f("dofs"),
                seeds.dofs.len(),
                self.n_dofs(),
                "5 per real particle",
            ));
        }
        for (name, v) in [("thickness", seeds.thickness)].into_iter().chain(
            crate::material::PARAM_NAMES
                .iter()
                .copied()
                .zip(seeds.material.to_array()),
        ) {
            if !v.is_finite() {
                return Err(ShellError::InvalidInput(format!(
                    "{}: {v}, expected a finite rate",
                    f(name)
                )));
            }
        }
        Ok(())
    }

    /// Sensitivities of the global internal force (eq 32) and of the trial histories for several
    /// seed sets at once (the internal-force part of the continuum DSA's sensitivity equation,
    /// eqs 62–65: with `Δq̇` seeded alone it is the tangent times `Δq̇`, with the other seeds the
    /// fictitious load).
    ///
    /// `dofs` is the converged increment `Δq` (f64, `n_dofs`); `seeds[v]` the seeds of design
    /// variable `v` ([`ModelSeeds`]). Returns, per seed set, `d f_int/dτ` (`n_dofs`) and the
    /// trial history sensitivities (point-major, as [`ShellModel::history`]). The f64 point
    /// evaluation (the chain of [`point_residual_with`](super::point::point_residual_with) from
    /// `Jⁿ` and `G` formed with per-point neighbour sums, without the residual rows) is done
    /// once per layer point and shared by all seed sets; the per-particle increment
    /// derivatives once per shape-function particle; the
    /// residual rows once per in-plane point from the thickness sums of `P` and `Ṗ` (the rows
    /// are linear in them), not once per layer. Images follow their sources: an image's state
    /// dot is `Q ṡ`, its DOF dot `T q̇`. Points run in parallel and are summed in point order
    /// (deterministic, bit-identical run to run). Equal to the derivative part of
    /// [`ShellModel::internal_force_with`] in dual numbers with the same seeds (to round-off:
    /// `tests/point_sensitivity.rs`). Errors name the seed set and field of a wrong length or a
    /// non-finite rate.
    pub fn internal_force_dots(
        &self,
        dofs: &[f64],
        seeds: &[ModelSeeds],
    ) -> Result<Vec<InternalForceDot>, ShellError> {
        Ok(self.force_dots(dofs, seeds, None, Vec::new())?.0)
    }

    /// [`Self::internal_force_dots`], keeping what the increment-only part of the trial-history
    /// derivative needs ([`StepLinearisation`]): with the seeds' `dofs` zero (the fictitious
    /// loads of eq 65), the returned histories are the seed part of `ⁿ⁺¹(Q̇, σ̇, α̇, ė^p)`, and
    /// [`Self::add_increment_history_dots`] adds the part of `Δq̇` once eq 65 is solved: by
    /// linearity the same trial histories as `internal_force_dots` seeded with `Δq̇` as well,
    /// without a second f64 evaluation of the layer points.
    pub fn internal_force_dots_linearised(
        &self,
        dofs: &[f64],
        seeds: &[ModelSeeds],
    ) -> Result<(Vec<InternalForceDot>, StepLinearisation), ShellError> {
        self.internal_force_dots_linearised_into(dofs, seeds, Vec::new(), None)
    }

    /// [`Self::internal_force_dots_linearised`] writing the trial-history derivatives into
    /// `buffers` (one per seed set, of any content: every entry is overwritten) when they fit
    /// (`seeds.len()` buffers of [`ShellModel::history`]'s length), instead of new zeroed
    /// vectors, and the layer data into the storage of `previous` (a linearisation of this
    /// model, of any step): a caller stepping through an analysis hands back the previous
    /// step's histories and linearisation and saves allocating and filling them. Buffers that
    /// do not fit are replaced. The same results either way.
    pub fn internal_force_dots_linearised_into(
        &self,
        dofs: &[f64],
        seeds: &[ModelSeeds],
        buffers: Vec<Vec<PointHistory<f64>>>,
        previous: Option<StepLinearisation>,
    ) -> Result<(Vec<InternalForceDot>, StepLinearisation), ShellError> {
        let layers = previous.map(|l| l.layers).unwrap_or_default();
        let (out, lin) = self.force_dots(dofs, seeds, Some(layers), buffers)?;
        Ok((
            out,
            lin.expect("force_dots keeps the linearisation when asked"),
        ))
    }

    fn force_dots(
        &self,
        dofs: &[f64],
        seeds: &[ModelSeeds],
        keep: Option<Vec<LayerKeep>>,
        buffers: Vec<Vec<PointHistory<f64>>>,
    ) -> Result<(Vec<InternalForceDot>, Option<StepLinearisation>), ShellError> {
        const D: usize = DOFS_PER_PARTICLE;
        if dofs.len() != self.n_dofs() {
            return Err(invalid(
                "dofs",
                dofs.len(),
                self.n_dofs(),
                "5 per real particle",
            ));
        }
        for (s, sd) in seeds.iter().enumerate() {
            self.check_model_seeds(s, sd)?;
        }
        let ns = seeds.len();
        let nl = self.thickness_rule.len();
        let n_sf = self.particles.len() + self.symmetry.images.len();
        // Per shape-function particle: f64 state, local DOFs and increment (as the analysis
        // forms them), then, seed-major (`s · n_sf + j`), the derivatives of every seed set.
        let local_dofs = |j: usize, g: &[f64]| self.particle_dofs(j, g);
        let per: Vec<ParticleValues> = (0..n_sf)
            .into_par_iter()
            .map(|j| {
                let state = self.particle_state(j);
                let x = local_dofs(j, dofs);
                let inc = PointIncrement::new(std::slice::from_ref(&state), &x)?;
                Ok(ParticleValues {
                    row: flat_row(&state, inc.du[0], inc.dd[0]),
                    state,
                    x,
                    d_alpha: inc.d_alpha[0],
                    k: Coefficients::at(&rotation_vector(&state, &x)),
                })
            })
            .collect::<Result<_, ShellError>>()?;
        let per_dot: Vec<NeighbourDot> = (0..ns * n_sf)
            .into_par_iter()
            .map(|idx| {
                let (sd, j) = (&seeds[idx / n_sf], idx % n_sf);
                let (src, q, _) = self.seed_map(j);
                let ps = sd.particles[src];
                let sdot = if j < self.particles.len() {
                    ps
                } else {
                    ParticleState {
                        u: q * ps.u,
                        d: q * ps.d,
                        d0: q * ps.d0,
                        e: [q * ps.e[0], q * ps.e[1]],
                    }
                };
                let (state, x, k) = (&per[j].state, &per[j].x, &per[j].k);
                let (du, dd, da) =
                    particle_increment_dot_with(state, &sdot, x, &local_dofs(j, sd.dofs), k);
                NeighbourDot {
                    row: flat_row(&sdot, du, dd),
                    d_alpha: da,
                }
            })
            .collect();
        // Per in-plane point: the f64 layers once, every seed set on each; results flat
        // (seed-major) so that a point allocates two vectors whatever the number of seed sets.
        // The trial histories' derivatives are written in place: per seed set, point-major, each
        // point writing its own layers' slots (no per-point buffers to copy afterwards).
        // (Every slot is written below, so recycled buffers need no zero-fill.)
        let n_hist = self.history.len();
        let keep_layers = keep.is_some();
        let mut hist_out = buffers;
        hist_out.truncate(ns);
        for h in hist_out.iter_mut().filter(|h| h.len() != n_hist) {
            *h = vec![PointHistory::ZERO; n_hist];
        }
        hist_out.resize_with(ns, || vec![PointHistory::ZERO; n_hist]);
        let mut slots: Vec<Vec<&mut [PointHistory<f64>]>> = (0..self.points.len())
            .map(|_| Vec::with_capacity(ns))
            .collect();
        for h in hist_out.iter_mut() {
            for (slot, chunk) in slots.iter_mut().zip(h.chunks_exact_mut(nl)) {
                slot.push(chunk);
            }
        }
        // The kept layer data, point-major, written in place as the histories (recycled
        // storage of the right length needs no fill either).
        let mut layers = keep.unwrap_or_default();
        if keep_layers {
            layers.resize(n_hist, LayerKeep::default());
        }
        // Per point, the unit director's end-of-step maps `N′, H(r,α)` (normalised director
        // field) for the increment-only history part.
        let mut units: Vec<Option<[M3<f64>; 3]>> = if keep_layers {
            vec![None; self.points.len()]
        } else {
            Vec::new()
        };
        let mut keep_slots: Vec<Option<KeepSlot<'_>>> = if keep_layers {
            layers
                .chunks_exact_mut(nl)
                .zip(units.iter_mut())
                .map(Some)
                .collect()
        } else {
            (0..self.points.len()).map(|_| None).collect()
        };
        // Points in fixed contiguous chunks: each chunk sums its rows into its own per-seed
        // force vectors (small, cache-resident) in point order, and the chunks are summed in
        // chunk order: deterministic and independent of the number of threads, without a
        // per-point row buffer to store and read back.
        let n_dofs = self.n_dofs();
        let half_t_dot: Vec<f64> = seeds.iter().map(|sd| sd.thickness * 0.5).collect();
        let chunk_len = self.points.len().div_ceil(POINT_CHUNKS).max(1);
        let accs = slots
            .into_par_iter()
            .zip(keep_slots.par_iter_mut())
            .enumerate()
            .chunks(chunk_len)
            .map(|items| -> Result<Vec<f64>, ShellError> {
                let mut sc = Scratch::default();
                let sc = &mut sc;
                let mut acc = vec![0.0; ns * n_dofs];
                for (k, (mut hist, kept)) in items {
                    let p = &self.points[k];
                    let nb = &p.neighbours;
                    sc.parts.clear();
                    sc.parts.extend(nb.iter().map(|&j| per[j].state));
                    sc.d_alpha.clear();
                    sc.d_alpha.extend(nb.iter().map(|&j| per[j].d_alpha));
                    let mut values = FlatSums::start(Some(&p.surface));
                    for (sh, &j) in p.shape.iter().zip(nb) {
                        values.add(sh, &per[j].row);
                    }
                    let raw_values = values.sums();
                    FlatSums::fill_all(
                        &mut sc.sums,
                        &p.shape,
                        seeds.iter().map(|sd| sd.surface.map(|sp| &sp[k])),
                        |s, i| &per_dot[s * n_sf + nb[i]].row,
                    );
                    let unit = (self.director == DirectorField::Normalised)
                        .then(|| UnitPoint::new(&raw_values));
                    let values = match &unit {
                        None => raw_values,
                        Some(u) => {
                            sc.unit_sums.clear();
                            sc.unit_sums.extend(sc.sums.iter().map(|r| u.seeds(r)));
                            u.values(&raw_values)
                        }
                    };
                    if let (Some(u), Some((_, slot))) = (&unit, kept.as_mut()) {
                        **slot = Some([u.np_1, u.h_1[0], u.h_1[1]]);
                    }
                    let layer_sums = if unit.is_some() {
                        &sc.unit_sums
                    } else {
                        &sc.sums
                    };
                    sc.dots.clear();
                    sc.dots.resize(ns, StressSums::zero());
                    let mut val = StressSums::zero();
                    for l in 0..nl {
                        let inp = self.layer_input(k, l, &sc.parts);
                        let res = values.layer(&inp)?;
                        let layer = LayerData::new(&inp, &res);
                        if let Some((kept, _)) = kept.as_mut() {
                            kept[l] = layer.keep;
                        }
                        val.add_value(&layer.p, layer.z, layer.zeta);
                        for (s, (sd, acc)) in seeds.iter().zip(sc.dots.iter_mut()).enumerate() {
                            hist[s][l] = layer.apply(
                                &values,
                                &layer_sums[s],
                                sd.thickness,
                                &sd.material,
                                &sd.history[k * nl + l],
                                acc,
                            );
                        }
                    }
                    let unit_rows = unit
                        .as_ref()
                        .map(|u| u.rows(&val, &sc.sums, &sc.dots, &half_t_dot));
                    add_rows_dot_all(
                        &p.shape,
                        &sc.d_alpha,
                        |s, i| per_dot[s * n_sf + nb[i]].d_alpha,
                        self.thickness * 0.5,
                        &half_t_dot,
                        &val,
                        &sc.dots,
                        unit_rows.as_ref(),
                        &mut sc.rows,
                        |i, rows| {
                            // Scattered at once (ShellModel::scatter_particle, the source's map
                            // looked up once for every seed set).
                            let j = nb[i];
                            let (src, q, det) = self.seed_map(j);
                            let real = j < self.particles.len();
                            for (s, o) in rows.iter().enumerate() {
                                let at = s * n_dofs + D * src;
                                let g = &mut acc[at..at + D];
                                if real {
                                    for (gc, v) in g.iter_mut().zip(o) {
                                        *gc += *v;
                                    }
                                } else {
                                    for c in 0..3 {
                                        g[c] +=
                                            o[0] * q[(0, c)] + o[1] * q[(1, c)] + o[2] * q[(2, c)];
                                    }
                                    g[3] += o[3] * det;
                                    g[4] += o[4] * det;
                                }
                            }
                        },
                    );
                }
                Ok(acc)
            })
            .collect::<Result<Vec<_>, ShellError>>()?;
        // Seed sets in parallel, each the sum of the chunks in chunk order.
        let out: Vec<InternalForceDot> = hist_out
            .into_par_iter()
            .enumerate()
            .map(|(s, h)| {
                let mut f = vec![0.0; n_dofs];
                for acc in &accs {
                    for (fi, a) in f.iter_mut().zip(&acc[s * n_dofs..(s + 1) * n_dofs]) {
                        *fi += a;
                    }
                }
                (f, h)
            })
            .collect();
        let lin = keep_layers.then(|| StepLinearisation {
            particles: per.into_iter().map(|v| (v.state, v.x, v.k)).collect(),
            layers,
            units,
        });
        Ok((out, lin))
    }

    /// Add the increment-only part of the trial-history derivative (eqs 44–51 with `Δq̇` the
    /// only seed) to `histories[v]` for `dofs_dot[v]` (`Δq̇` of seed set `v`, `n_dofs`), at the
    /// step `lin` was kept at ([`Self::internal_force_dots_linearised`], same model state: the
    /// model must not have committed since). Per layer point the chain is the `Δq̇` column of
    /// [`point_residual_dot`]'s: `Ġ(Δq̇)` (with `Δḋ_I` of Rodrigues' increment), `Ḣ = Ġ Jⁿ⁻¹`
    /// (`J̇ⁿ = 0`), `L̇ = F½⁻¹ Ḣ F½⁻¹` (eqs 56–57), the Hughes–Winget derivatives (eqs 54–55,
    /// 58), `Δε̇ˡ` with `ⁿQ̇ = 0` (eq 50), the strain part of the return-map sensitivity
    /// (eqs 44–49) and `Q̇ = Qₙ ṙᵀ` (eq 51); no `Ṗ`, no residual rows. Points run in parallel
    /// (deterministic). Errors name the seed set and field of a wrong length, or a `lin` that
    /// does not fit the model.
    pub fn add_increment_history_dots(
        &self,
        lin: &StepLinearisation,
        dofs_dot: &[&[f64]],
        histories: &mut [Vec<PointHistory<f64>>],
    ) -> Result<(), ShellError> {
        let n_sf = self.particles.len() + self.symmetry.images.len();
        if lin.particles.len() != n_sf {
            return Err(invalid(
                "lin.particles",
                lin.particles.len(),
                n_sf,
                "one per shape-function particle of the model",
            ));
        }
        let nl = self.thickness_rule.len();
        if lin.layers.len() != self.history.len() {
            return Err(invalid(
                "lin.layers",
                lin.layers.len(),
                self.history.len(),
                "one per layer point of the model, per in-plane point",
            ));
        }
        if histories.len() != dofs_dot.len() {
            return Err(invalid(
                "histories",
                histories.len(),
                dofs_dot.len(),
                "one per seed set (dofs_dot)",
            ));
        }
        for (s, (q, h)) in dofs_dot.iter().zip(histories.iter()).enumerate() {
            if q.len() != self.n_dofs() {
                return Err(invalid(
                    &format!("dofs_dot[{s}]"),
                    q.len(),
                    self.n_dofs(),
                    "5 per real particle",
                ));
            }
            if h.len() != self.history.len() {
                return Err(invalid(
                    &format!("histories[{s}]"),
                    h.len(),
                    self.history.len(),
                    "one per layer point, point-major",
                ));
            }
        }
        let ns = dofs_dot.len();
        // Per shape-function particle and seed set (seed-major): `Δū̇_I`, `Δḋ_I` of `Δq̇` alone
        // (particle_increment_dot with the state's sensitivity zero: θ̇ = e1 α̇1 + e2 α̇2).
        let per_dot: Vec<(V3, V3)> = (0..ns * n_sf)
            .into_par_iter()
            .map(|idx| {
                let (qd, j) = (dofs_dot[idx / n_sf], idx % n_sf);
                let x = self.particle_dofs(j, qd);
                let (p, xs, k) = &lin.particles[j];
                // θ̇ = e1 α̇1 + e2 α̇2: the rotation vector of the DOF rates.
                let (theta, theta_dot) = (rotation_vector(p, xs), rotation_vector(p, &x));
                let dd = rodrigues_increment_dot(&p.d, &V3::zeros(), &theta, &theta_dot, k);
                (V3::new(x[0], x[1], x[2]), dd)
            })
            .collect();
        let half_t = self.thickness * 0.5;
        let d = elastic_matrix(&self.material);
        // Added in place: per in-plane point, its layers' slots of every seed set.
        let mut slots: Vec<Vec<&mut [PointHistory<f64>]>> = (0..self.points.len())
            .map(|_| Vec::with_capacity(ns))
            .collect();
        for h in histories.iter_mut() {
            for (slot, chunk) in slots.iter_mut().zip(h.chunks_exact_mut(nl)) {
                slot.push(chunk);
            }
        }
        slots.into_par_iter().enumerate().for_each(|(k, mut hist)| {
            let p = &self.points[k];
            let nb = &p.neighbours;
            for (s, h) in hist.iter_mut().enumerate() {
                let base = s * n_sf;
                // Σ Ψ,α Δū̇, Σ Ψ,α Δḋ, Σ Ψ Δḋ (the other sums of SeedSums are zero).
                let mut sums = SeedSums::default();
                for (sh, &j) in p.shape.iter().zip(nb) {
                    let (du, dd) = &per_dot[base + j];
                    for a in 0..2 {
                        sums.g_u[a] += du * sh.dpsi[a];
                        sums.g_d[a] += dd * sh.dpsi[a];
                    }
                    sums.g_d3 += dd * sh.psi;
                }
                if let Some(Some([np, h1, h2])) = lin.units.get(k) {
                    // ḋ₁ = N′ δ̇, ḋ₁,α = N′ δ̇,α + H(r,α) δ̇ (ṙₙ = 0 for Δq̇ alone).
                    let d3 = sums.g_d3;
                    sums.g_d = [np * sums.g_d[0] + h1 * d3, np * sums.g_d[1] + h2 * d3];
                    sums.g_d3 = np * d3;
                }
                for (l, (&(zeta, _), hl)) in
                    self.thickness_rule.iter().zip(h.iter_mut()).enumerate()
                {
                    let inc = lin.layers[k * nl + l].increment_history_dot(
                        &d,
                        half_t,
                        half_t * zeta,
                        &sums,
                    );
                    add_history(hl, &inc);
                }
            }
        });
        Ok(())
    }
}

fn add_history(a: &mut PointHistory<f64>, b: &PointHistory<f64>) {
    a.frame += b.frame;
    a.material.stress += b.material.stress;
    a.material.back_stress += b.material.back_stress;
    a.material.eps_p += b.material.eps_p;
}

/// The seed-independent factors of one layer point's derivative chain, formed once from the
/// f64 evaluation and shared by every seed set; kept by the fictitious loads' pass for the
/// increment-only part of the trial-history derivative
/// ([`ShellModel::add_increment_history_dots`]): ≈ 1 kB per layer point (6 3×3 matrices, three
/// 5-vectors and the compact strain part of the return-map sensitivity, [`StrainMap`]),
/// whatever the number of seed sets (`benches/continuum.rs` prints the total).
#[derive(Clone, Copy, Debug, Default)]
struct LayerKeep {
    /// `A F½⁻¹` and `Jⁿ⁻¹ F½⁻¹ Aᵀ`, with `A = Qₙ ½rᵀ` (eq 50) and `F½ = I + ½H`: the rate
    /// `L̇ = F½⁻¹ Ḣ F½⁻¹` (eqs 56–57) seen in the rotated frame, `A L̇ Aᵀ`.
    a_f: M3<f64>,
    f_a: M3<f64>,
    /// `A` (orthogonal: the product of two rotations).
    a: M3<f64>,
    /// `2 · strain_to_vec5(Qₙ (½ṙ_i)ᵀ Δε Aᵀ)` for the spin rate `ω = e_i` (eqs 50, 54–55): the
    /// symmetric part of eq 50's `Ȧ Δε Aᵀ + A Δε Ȧᵀ` from the rotation rate is
    /// `Σ ω_i strain_rot5[i]`.
    strain_rot5: [Vec5<f64>; 3],
    /// `Qₙ ṙ_iᵀ` for `ω = e_i` (eqs 51, 54–55): `Qₙ ṙᵀ = Σ ω_i frame_rot[i]`.
    frame_rot: [M3<f64>; 3],
    /// The return-map sensitivity's strain part (eqs 44–49, 48).
    material: StrainMap,
}

impl LayerKeep {
    /// The Hughes–Winget rates of `L̇ = F½⁻¹ Ḣ F½⁻¹` (eqs 54–58) for `Ḣ Jⁿ = y`: the rotated
    /// strain rate `A Δε̇ Aᵀ` (`Δε̇ = sym L̇`, eq 50's middle term) as `strain_to_vec5`, and the
    /// axial vector `ω` of `Δω̇ = skew L̇ = [ω]×` (the rotation rates follow from `ω` through
    /// [`Self::strain_rot5`](LayerKeep) and [`Self::frame_rate`]). With `M = A L̇ Aᵀ`:
    /// `A Δε̇ Aᵀ = sym M`, and, `A` being a rotation, `skew M = A [ω]× Aᵀ = [Aω]×`, so
    /// `ω = Aᵀ axial(skew M)`.
    fn rates(&self, y: &M3<f64>) -> (Vec5<f64>, V3) {
        let m = self.a_f * y * self.f_a;
        (strain_to_vec5(&m), self.a.tr_mul(&axial(&m)))
    }

    /// `Qₙ ṙᵀ` for the spin rate `ω` (eqs 51, 54–55).
    fn frame_rate(&self, omega: &V3) -> M3<f64> {
        self.frame_rot[0] * omega[0] + self.frame_rot[1] * omega[1] + self.frame_rot[2] * omega[2]
    }

    /// `Δε̇ˡ = Ȧ Δε Aᵀ + A Δε̇ Aᵀ + A Δε Ȧᵀ` (eq 50, [`crate::kinematics::local_strain_increment_dot`])
    /// as `strain_to_vec5`: `history` is the part of `Q̇ₙ` (`2 · strain_to_vec5(Q̇ₙ ½rᵀ Δε Aᵀ)`,
    /// `Δε` symmetric, so the last term is the transpose of the first), `deps` the rotated
    /// strain rate of [`Self::rates`].
    fn strain_dot(&self, history: &Vec5<f64>, omega: &V3, deps: &Vec5<f64>) -> Vec5<f64> {
        history
            + self.strain_rot5[0] * omega[0]
            + self.strain_rot5[1] * omega[1]
            + self.strain_rot5[2] * omega[2]
            + deps
    }

    /// The `Δq̇` column of [`LayerData::apply`] (`J̇ⁿ = 0`, `ż = ṫ = 0`, no history or
    /// material seeds): `ⁿ⁺¹(Q̇, σ̇, α̇, ė^p)`.
    fn increment_history_dot(
        &self,
        d: &Mat5<f64>,
        half_t: f64,
        z: f64,
        sums: &SeedSums,
    ) -> PointHistory<f64> {
        let g_dot = M3::from_columns(&[
            sums.g_u[0] + sums.g_d[0] * z,
            sums.g_u[1] + sums.g_d[1] * z,
            sums.g_d3 * half_t,
        ]);
        // L̇ = F½⁻¹ Ġ Jⁿ⁻¹ F½⁻¹ (eqs 56–57).
        let (deps_dot, omega) = self.rates(&g_dot);
        // Eq 50 with Ȧ = Qₙ ½ṙᵀ.
        let deps_l_dot = self.strain_dot(&Vec5::zeros(), &omega, &deps_dot);
        let mat_dot = self.material.apply(d, &deps_l_dot);
        // Eq 51 with Q̇ₙ = 0.
        PointHistory {
            frame: self.frame_rate(&omega),
            material: mat_dot,
        }
    }
}

/// The f64 data of a converged step kept by [`ShellModel::internal_force_dots_linearised`] for
/// [`ShellModel::add_increment_history_dots`]: per shape-function particle its committed state
/// and local DOF increment, per layer point the kinematics and return-map outcome the
/// increment-only chain needs.
#[derive(Clone, Debug)]
pub struct StepLinearisation {
    particles: Vec<(ParticleState<f64>, [f64; DOFS_PER_PARTICLE], Coefficients)>,
    /// Per layer point, point-major (as [`ShellModel::history`]).
    layers: Vec<LayerKeep>,
    /// Per in-plane point of a normalised director field: `N′, H(r,₁), H(r,₂)` at the end of
    /// the step (`None` for the interpolated field).
    units: Vec<Option<[M3<f64>; 3]>>,
}

impl StepLinearisation {
    /// Heap memory held (bytes).
    pub fn memory_bytes(&self) -> usize {
        self.particles.capacity()
            * std::mem::size_of::<(ParticleState<f64>, [f64; 5], Coefficients)>()
            + self.layers.capacity() * std::mem::size_of::<LayerKeep>()
            + self.units.capacity() * std::mem::size_of::<Option<[M3<f64>; 3]>>()
    }
}
