//! Hand-derived design sensitivity of the penalty contact force (the paper's §4.2, eqs 73–83),
//! for the continuum (direct differentiation) path: the derivative `ḟ_c = d f_c/dτ` of the
//! generalised contact force of [`ShellContact`] at a state `(q; t)` for given derivatives of
//! its inputs ([`ContactSeeds`]):
//!
//! - the **tool translations** `ȧ_i` (a tool-position design variable moves the whole tool:
//!   the design velocity on the tool is the constant `V^c = ȧ`, eq 76; its tangents
//!   `x^c,α` and curvatures do not change);
//! - the **tool rotations** `φ̇_i` (a tool-rotation design variable turns the tool as built
//!   about its pivot `c` before its motion, `x^c = c + R(t) R_φ (X − c) + a(t)`,
//!   [`crate::contact::ToolPath::rotated`]): at `φ = 0`, `d(R(t) R_φ)/dτ = R(t) [φ̇]× = Ω R(t)` with
//!   `Ω = [R(t) φ̇]×` (`R(t) = R(θ(t))`, the path's rotation), so with the moved pivot
//!   `p = c + a(t)` the design velocity of the tool point is `V^c = ȧ + Ω (x^c − p)` (eq 76),
//!   and the tangents, second derivatives and normal move with the tool:
//!   `V^c,α = Ω x^c,α`, `V^c,αβ = Ω x^c,αβ`, `ṅ|_ξ = Ω n`;
//! - the **tool shapes** `ṗ_k` (a tool-shape design variable changes a design parameter of the
//!   tool's surface, `X(ξ; p)`, [`crate::contact::RigidTool::reshaped`]): at fixed surface
//!   parameters `ξ` the tool point moves by `V^c = R ∂X/∂p ṗ` and its tangents by
//!   `V^c,α = R ∂X,α/∂p ṗ` (eq 76, `R = R(t) R_φ` the tool's rotation;
//!   [`crate::contact::RigidTool::shape_velocity`]); the normal turns at fixed `ξ` by
//!   `ṅ|_ξ = (I − n nᵀ) ċ / (n·c)`, `c = x^c,1 × x^c,2`, `ċ = V^c,1 × x^c,2 + x^c,1 × V^c,2`
//!   (`n = ±c/|c|`). Its curvature change does not enter the force's derivative (only the
//!   tangent stiffness's);
//! - the **thickness** `ṫ` (slave faces at `ζ t/2`, initial face areas) and the **penalty**
//!   `ω̇` (`ω = c E/t` makes it design-dependent);
//! - the **shell state**: the committed particle states' dots `ū̇, ḋ, ė` (the history
//!   dependence) and the increment's `Δq̇`;
//! - the **design velocity of the initial geometry** (a shape design variable,
//!   [`ContactSeeds::initial`]): at every in-plane point `V⁰ = ∂x̄⁰/∂τ` and the dots
//!   `ẋ⁰,α, ṅ⁰, ṅ⁰,α` of [`crate::sensitivity::shape::ShapeVelocity`]. The discretisation lives
//!   on the surface's parameter domain (shape functions and weights do not move), so the
//!   paper's updated design velocity of the slave point (eq 74, `ⁿV = V⁰ + ⁿu̇` on the
//!   current configuration) is `V⁰ + ζ t/2 ṅ⁰` from the initial geometry plus the state
//!   terms below (the particles' `ḋ⁰ = ḋ = ṅ(ξ_I)` of the initial state cancel in
//!   `d_J − d⁰_J` until the director turns).
//!
//! **Slave point.** `x = x̄ + ζ t/2 d`, `x̄ = x̄⁰ + Σ Ψ_J (ū_J + Δū_J)`,
//! `d = n⁰ + Σ Ψ_J (d_J(α_J) − d⁰_J)` (`docs/contact.md` §4), so
//! `ẋ = V⁰ + Σ Ψ_J (ū̇_J + Δū̇_J) + ζ ṫ/2 d + ζ t/2 (ṅ⁰ + Σ Ψ_J (ḋ_J(α_J) − ḋ⁰_J))`
//! (`V⁰ = ṅ⁰ = 0` but for a shape variable) with `ḋ_J(α)` the
//! directional derivative of Rodrigues' rotation `d(α) = dⁿ + f1 c + f2 θ×c`
//! (`θ = α1 e1 + α2 e2`, `c = θ×dⁿ`, `x = θ·θ`) in all of `dⁿ, e1, e2, α`:
//! `ḋ = ḋⁿ + f1' ẋ c + f1 ċ + f2' ẋ θ×c + f2 (θ̇×c + θ×ċ)`, `θ̇ = α̇_β e_β + α_β ė_β`,
//! `ẋ = 2 θ·θ̇`, `ċ = θ̇×dⁿ + θ×ḋⁿ`.
//!
//! **Projection sensitivity (eq 80).** Differentiating eq (67),
//! `(x − x^c(ξ))·x^c,α(ξ) = 0`, with the tool point moving by `V^c` and its tangents by
//! `V^c,α` (`Ω x^c,α` for a rotation, `R ∂X,α/∂p ṗ` for a tool shape, zero for a
//! translation):
//! `(ẋ − V^c − x^c,β ξ̇_β)·x^c,α + (x − x^c)·(V^c,α + x^c,αβ ξ̇_β) = 0`; with
//! `x − x^c = g n` (eq 68 at an interior projection) this is
//! `A ξ̇ = [x^c,α·(ẋ − V^c) + g n·V^c,α]`, `A = m − g b` (eqs 79–80). **Gap and normal:**
//! `g = (x − x^c)·n`, so
//! `ġ = n·(ẋ − V^c − x^c,β ξ̇_β) + g n·ṅ = n·(ẋ − V^c)` (eq 78; `n ⟂ x^c,β`, `n·ṅ = 0`);
//! the normal turns with the tool (`ṅ|_ξ`: `Ω n` for a rotation, the tool-shape term above)
//! and slides along it: `ṅ = ṅ|_ξ + n,β ξ̇_β` with
//! Weingarten's `n,β = −(b m⁻¹)_βγ x^c,γ` (the curvature term of eqs 77, 83).
//! **Force (eq 83's `b'_N` with the state terms):** `f = −ω w g n`
//! (eq 70), so `ḟ = −(ω̇ w g + ω ẇ g + ω w ġ) n − ω w g ṅ`, with `ẇ` the derivative of
//! the initial face area `w |x⁰,1 × x⁰,2|`, `x⁰,α = x̄⁰,α + ζ t/2 n⁰,α`:
//! `ẇ = w_q (c/|c|)·ċ` with `c = x⁰,1 × x⁰,2`,
//! `ċ = ẋ⁰,1 × x⁰,2 + x⁰,1 × ẋ⁰,2`, `ẋ⁰,α = ẋ̄⁰,α + ζ t/2 ṅ⁰,α + ζ ṫ/2 n⁰,α` (`w_q` the
//! quadrature weight, design-free). With a shape variable `V⁰` enters `ẋ` (so eq 78's
//! `ġ = n·(ẋ − V^c)` and eq 80's right-hand side `x^c,α·(ẋ − V^c)`): the slave point moves
//! relative to the tool with the sheet's design velocity, eq 74's `V` in eqs 78–83.
//!
//! **Generalised force.** `f_J = Ψ_J Σ f`, `m_Jβ = Ψ_J (∂d_J/∂α_β)·Σ ζ t/2 f`, so
//! `ṁ_Jβ = Ψ_J [(∂d_J/∂α_β)˙·Σ ζ t/2 f + (∂d_J/∂α_β)·Σ (ζ ṫ/2 f + ζ t/2 ḟ)]`, where the
//! derivative of `∂d/∂α_β = f1' x_β c + f1 c_β + f2' x_β θ×c + f2 w_β`
//! (`x_β = 2 θ·e_β`, `c_β = e_β×dⁿ`, `w_β = e_β×c + θ×c_β`) is taken by the product rule
//! with `f1'', f2''` ([`rodrigues_coefficient_derivatives`]).
//!
//! A point whose projection lies on a tool's boundary carries no force (the tool is not
//! extended beyond its patch, `docs/contact.md` §2), so its derivative is zero; at the switch
//! (`g = 0` or the projection reaching the boundary) the force is not differentiable.
//! Verified against the dual-number evaluation [`ShellContact::force_with`] and central
//! differences (`tests/dsa_contact.rs`).

use super::contact::{neighbour_state, InitialGeometry, ShellContact, SiteEval};
use crate::kinematics::rotation::rodrigues_coefficient_derivatives;
use crate::kinematics::rotation::rotate_director;
use crate::shell::model::ShellModel;
use crate::shell::point::{director_first_derivatives, ParticleState, DOFS_PER_PARTICLE};
use crate::shell::ShellError;
use nalgebra::{Vector2, Vector3};

type V3 = Vector3<f64>;

/// The design rates of one rigid tool's placement ([`ContactSeeds::tools`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ToolRate {
    /// `ȧ`: the derivative of the translation added to its path (`V^c = ȧ`, eq 76): a unit
    /// vector along the axis of a tool-position variable, zero otherwise.
    pub translation: [f64; 3],
    /// `φ̇`: the derivative of the rotation vector turning the tool as built about its pivot
    /// (global axes; `V^c = Ω (x^c − p)`, `Ω = [R(t) φ̇]×`, module documentation): a unit
    /// vector along the axis of a tool-rotation variable, zero otherwise.
    pub rotation: [f64; 3],
    /// `(k, ṗ_k)`: the rate of the tool surface's design parameter `k`
    /// (`Surface::design_parameters`) of a tool-shape variable (`V^c = R ∂X/∂p ṗ`,
    /// `V^c,α = R ∂X,α/∂p ṗ` at fixed `ξ`, module documentation); `None` otherwise.
    pub shape: Option<(usize, f64)>,
}

/// Derivatives of the contact force's inputs with respect to one design variable
/// ([`ShellContact::force_dot`]).
#[derive(Clone, Copy, Debug)]
pub struct ContactSeeds<'a> {
    /// Per tool (in the contact's order), the rates of its translation and rotation (eq 76's
    /// `V^c`).
    pub tools: &'a [ToolRate],
    /// `ṫ` (1 for the thickness variable).
    pub thickness: f64,
    /// `ω̇` (non-zero when the penalty is `c E/t` and the variable is `E` or `t`).
    pub penalty: f64,
    /// Per real particle, the derivatives of its committed state (`ū̇, ḋ, ḋ⁰, ė`).
    pub particles: &'a [ParticleState<f64>],
    /// The derivative of the increment `Δq̇` (generalised DOFs).
    pub increment: &'a [f64],
    /// The design velocity of the initial geometry at every in-plane point (a shape design
    /// variable; `None`: the geometry does not move): `V⁰ = ∂x̄⁰/∂τ` as `positions` and the
    /// [`crate::shell::point::SurfacePoint`] dots `ẋ⁰,α, ṅ⁰, ṅ⁰,α` as `surfaces` (those of
    /// [`crate::sensitivity::shape::ShapeVelocity`]). The slave point moves by `V⁰ + ζ t/2 ṅ⁰`
    /// and the face area changes (module documentation).
    pub initial: Option<InitialGeometry<'a, f64>>,
}

/// Rodrigues' rotated director `d(α)` of [`crate::kinematics::rotation::rotate_director`]: its
/// directional derivative for the state dots `sd` and `α̇`, and the directional derivatives of
/// its first derivatives `∂d/∂α_β` (module documentation).
fn director_dots(
    st: &ParticleState<f64>,
    sd: &ParticleState<f64>,
    alpha: [f64; 2],
    adot: [f64; 2],
) -> (V3, [V3; 2]) {
    let (dn, e) = (st.d, st.e);
    let (dnd, ed) = (sd.d, sd.e);
    let theta = e[0] * alpha[0] + e[1] * alpha[1];
    let thd = e[0] * adot[0] + e[1] * adot[1] + ed[0] * alpha[0] + ed[1] * alpha[1];
    let x = theta.dot(&theta);
    let xd = 2.0 * theta.dot(&thd);
    let ([f1, f1p, f1pp], [f2, f2p, f2pp]) = rodrigues_coefficient_derivatives(x);
    let c = theta.cross(&dn);
    let cd = thd.cross(&dn) + theta.cross(&dnd);
    let tc = theta.cross(&c);
    let tcd = thd.cross(&c) + theta.cross(&cd);
    let d_dot = dnd + c * (f1p * xd) + cd * f1 + tc * (f2p * xd) + tcd * f2;
    let da_dot = std::array::from_fn(|b| {
        let xb = 2.0 * theta.dot(&e[b]);
        let xbd = 2.0 * (thd.dot(&e[b]) + theta.dot(&ed[b]));
        let cb = e[b].cross(&dn);
        let cbd = ed[b].cross(&dn) + e[b].cross(&dnd);
        let wb = e[b].cross(&c) + theta.cross(&cb);
        let wbd = ed[b].cross(&c) + e[b].cross(&cd) + thd.cross(&cb) + theta.cross(&cbd);
        c * (f1pp * xd * xb + f1p * xbd)
            + cd * (f1p * xb)
            + cb * (f1p * xd)
            + cbd * f1
            + tc * (f2pp * xd * xb + f2p * xbd)
            + tcd * (f2p * xb)
            + wb * (f2p * xd)
            + wbd * f2
    });
    (d_dot, da_dot)
}

impl ShellContact {
    /// The hand-derived derivative `ḟ_c = d f_c/dτ` (generalised DOFs, length
    /// `model.n_dofs()`) of the contact force at the increment `q` from `model`'s committed
    /// state and pseudo-time `load`, for the input derivatives `seeds` (module documentation;
    /// eqs 78–83). Not tracked.
    pub fn force_dot(
        &self,
        model: &ShellModel,
        q: &[f64],
        load: f64,
        seeds: &ContactSeeds<'_>,
    ) -> Result<Vec<f64>, ShellError> {
        Ok(self
            .force_dots(model, q, load, std::slice::from_ref(seeds))?
            .pop()
            .unwrap_or_default())
    }

    /// [`ShellContact::force_dot`] for several seed sets (design variables) at once: the slave
    /// positions and their projections onto the tools are evaluated once and shared.
    pub fn force_dots(
        &self,
        model: &ShellModel,
        q: &[f64],
        load: f64,
        seeds: &[ContactSeeds<'_>],
    ) -> Result<Vec<Vec<f64>>, ShellError> {
        self.check_seeds(model, q, seeds)?;
        let surfaces: Vec<_> = self.tools().iter().map(|tl| tl.surface.clone()).collect();
        let evals = self.evaluate(model, q, load, &surfaces)?;
        seeds
            .iter()
            .map(|sd| Ok(self.dot_with(model, &evals, load, sd)?.0))
            .collect()
    }

    /// The hand-derived derivatives of the forces the sheet exerts on the tools
    /// ([`ShellContact::tool_forces_with`]): per seed set, per tool, `−Σ ḟ` over the tool's
    /// active slave points (the same eqs 78–83 as [`Self::force_dots`]). At a converged state
    /// (`q = 0`) with the seeds of the carried sensitivities this is the total design
    /// derivative of the punch force.
    pub fn tool_force_dots(
        &self,
        model: &ShellModel,
        q: &[f64],
        load: f64,
        seeds: &[ContactSeeds<'_>],
    ) -> Result<Vec<Vec<[f64; 3]>>, ShellError> {
        self.check_seeds(model, q, seeds)?;
        let surfaces: Vec<_> = self.tools().iter().map(|tl| tl.surface.clone()).collect();
        let evals = self.evaluate(model, q, load, &surfaces)?;
        seeds
            .iter()
            .map(|sd| Ok(self.dot_with(model, &evals, load, sd)?.1))
            .collect()
    }

    /// The seed sets fit `model`, `q` and the tools.
    fn check_seeds(
        &self,
        model: &ShellModel,
        q: &[f64],
        seeds: &[ContactSeeds<'_>],
    ) -> Result<(), ShellError> {
        for sd in seeds {
            self.check_model(model, q.len(), Some(sd.increment.len()))?;
            for (expected, got) in [
                (model.particles.len(), sd.particles.len()),
                (self.tools().len(), sd.tools.len()),
            ] {
                if expected != got {
                    return Err(ShellError::Dimension { expected, got });
                }
            }
            if let Some(g) = &sd.initial {
                g.check(model)?;
            }
        }
        Ok(())
    }

    /// The force derivative for one seed set from the evaluated sites at pseudo-time `load`:
    /// the generalised `ḟ_c` and, per tool, the derivative of the force on it (`−Σ ḟ`).
    fn dot_with(
        &self,
        model: &ShellModel,
        evals: &[SiteEval<f64>],
        load: f64,
        seeds: &ContactSeeds<'_>,
    ) -> Result<(Vec<f64>, Vec<[f64; 3]>), ShellError> {
        let omega = self.penalty();
        // Per tool: ȧ, the spin ω_t = R(θ(t)) φ̇ (Ω = [ω_t]×) and the moved pivot p = c + a(t).
        let tool_motion: Vec<(V3, V3, V3)> = self
            .tools()
            .iter()
            .zip(seeds.tools)
            .map(|(tl, rate)| {
                let m = tl.motion(load);
                let spin = tl.path.path_rotation(load) * V3::from(rate.rotation);
                (V3::from(rate.translation), spin, m.pivot + m.translation)
            })
            .collect();
        let mut out = vec![0.0; model.n_dofs()];
        let mut on_tools = vec![[0.0; 3]; self.tools().len()];
        for (site, ev) in self.sites().iter().zip(evals) {
            let active: Vec<_> = ev
                .faces
                .iter()
                .filter_map(|fe| fe.nearest().map(|(i, cp)| (fe, i, cp)))
                .filter(|(_, _, cp)| cp.is_active())
                .collect();
            if active.is_empty() {
                continue;
            }
            let p = &model.points[site.point];
            let (_, local_dot) = model.gather_local(site.point, seeds.increment);
            // Per neighbour: the state dots, ḋ_J(α) and (∂d_J/∂α_β)˙.
            let mut xbar_dot = V3::zeros();
            let mut d = V3::zeros();
            let mut d_dot = V3::zeros();
            let mut da = Vec::with_capacity(p.shape.len());
            let mut da_dot = Vec::with_capacity(p.shape.len());
            for (n, ((s, st), &j)) in p.shape.iter().zip(&ev.parts).zip(&p.neighbours).enumerate() {
                let x = &ev.local[DOFS_PER_PARTICLE * n..DOFS_PER_PARTICLE * (n + 1)];
                let xd = &local_dot[DOFS_PER_PARTICLE * n..DOFS_PER_PARTICLE * (n + 1)];
                let sd = neighbour_state(model, j, seeds.particles);
                xbar_dot += (sd.u + V3::new(xd[0], xd[1], xd[2])) * s.psi;
                let dj = rotate_director(&st.d, &st.e[0], &st.e[1], [x[3], x[4]]);
                d += (dj - st.d0) * s.psi;
                let (djd, dad) = director_dots(st, &sd, [x[3], x[4]], [xd[3], xd[4]]);
                d_dot += (djd - sd.d0) * s.psi;
                da.push(director_first_derivatives(st, [x[3], x[4]]));
                da_dot.push(dad);
            }
            // d = n⁰ + Σ Ψ (d_J − d⁰_J); a shape variable moves x̄⁰ by V⁰ and turns n⁰ (eq 74).
            let d = site.n0 + d;
            let initial = seeds
                .initial
                .as_ref()
                .map(|g| (g.positions[site.point], g.surfaces[site.point]));
            if let Some((v0, sf_dot)) = &initial {
                xbar_dot += v0;
                d_dot += sf_dot.n;
            }
            let mut msum = V3::zeros();
            let (mut fsum_dot, mut msum_dot) = (V3::zeros(), V3::zeros());
            for (fe, tool, cp) in active {
                let zh = fe.zh;
                let zh_dot = fe.zeta * 0.5 * seeds.thickness;
                // Face area w |a1 × a2|, a_α = x̄⁰,α + ζ t/2 n⁰,α;
                // ȧ_α = ẋ⁰,α + ζ t/2 ṅ⁰,α + ζ ṫ/2 n⁰,α.
                let sf = &p.surface;
                let a1 = sf.x_a[0] + sf.n_a[0] * zh;
                let a2 = sf.x_a[1] + sf.n_a[1] * zh;
                let cr = a1.cross(&a2);
                let mut tan_dot = [sf.n_a[0] * zh_dot, sf.n_a[1] * zh_dot];
                if let Some((_, sf_dot)) = &initial {
                    for (ad, (xd, nd)) in tan_dot.iter_mut().zip(sf_dot.x_a.iter().zip(&sf_dot.n_a))
                    {
                        *ad += xd + nd * zh;
                    }
                }
                let cr_dot = tan_dot[0].cross(&a2) + a1.cross(&tan_dot[1]);
                let w_dot = cr.dot(&cr_dot) / cr.norm() * p.weight;
                let w = fe.area;
                // Relative velocity of the slave point to the tool point,
                // V^c = ȧ + Ω (x^c − p) (eq 76).
                let (a_dot, spin, pivot) = &tool_motion[tool];
                let t = [cp.surface.xu, cp.surface.xv];
                let n = cp.normal;
                // A tool shape: V^c = R ∂X/∂p ṗ, V^c,α = R ∂X,α/∂p ṗ at fixed ξ and the
                // normal's turn there, ṅ|_ξ = (I − n nᵀ) ċ / (n·c) (module documentation).
                let (mut v_c, mut v_ca, mut n_dot_xi) = (
                    *a_dot + spin.cross(&(cp.surface.x - pivot)),
                    [spin.cross(&t[0]), spin.cross(&t[1])],
                    spin.cross(&n),
                );
                if let Some((k, rate)) = seeds.tools[tool].shape {
                    let tl = &self.tools()[tool];
                    let (vx, va) = tl.shape_velocity(k, cp.xi, load).map_err(|e| {
                        ShellError::InvalidInput(format!(
                            "contact sensitivity: design velocity of tool `{}` at ξ = {:?}: {e}",
                            tl.name, cp.xi
                        ))
                    })?;
                    let (vx, va) = (vx * rate, [va[0] * rate, va[1] * rate]);
                    v_c += vx;
                    v_ca[0] += va[0];
                    v_ca[1] += va[1];
                    let c = t[0].cross(&t[1]);
                    let c_dot = va[0].cross(&t[1]) + t[0].cross(&va[1]);
                    n_dot_xi += (c_dot - n * n.dot(&c_dot)) / n.dot(&c);
                }
                let x_dot = xbar_dot + d * zh_dot + d_dot * zh;
                let rel = x_dot - v_c;
                let a_inv = cp.a_matrix().try_inverse();
                let m_inv = cp.metric().try_inverse();
                let (Some(a_inv), Some(m_inv)) = (a_inv, m_inv) else {
                    return Err(ShellError::InvalidInput(format!(
                        "contact sensitivity: singular projection matrix at quadrature point {} \
                         (ζ = {}): expected a regular tool point off its centres of curvature",
                        site.point, fe.zeta
                    )));
                };
                // Eq 80: A ξ̇ = [x^c,α·(ẋ − V^c) + g n·V^c,α].
                let g = cp.gap;
                let rhs = |a: usize| t[a].dot(&rel) + g * n.dot(&v_ca[a]);
                let xi_dot = a_inv * Vector2::new(rhs(0), rhs(1));
                let g_dot = n.dot(&rel);
                // ṅ = ṅ|_ξ + n,β ξ̇_β, Weingarten: n,β = −(b m⁻¹)_βγ x^c,γ.
                let bm = cp.curvature() * m_inv;
                let mut n_dot = n_dot_xi;
                for b in 0..2 {
                    for gm in 0..2 {
                        n_dot -= t[gm] * (bm[(b, gm)] * xi_dot[b]);
                    }
                }
                let f = cp.normal * (-omega * w * g);
                let f_dot = cp.normal
                    * -(seeds.penalty * w * g + omega * w_dot * g + omega * w * g_dot)
                    - n_dot * (omega * w * g);
                fsum_dot += f_dot;
                for (a, b) in on_tools[tool].iter_mut().zip(f_dot.iter()) {
                    *a -= b;
                }
                msum += f * zh;
                msum_dot += f * zh_dot + f_dot * zh;
            }
            let mut local = Vec::with_capacity(DOFS_PER_PARTICLE * p.shape.len());
            for (n, s) in p.shape.iter().enumerate() {
                let fp = fsum_dot * s.psi;
                local.extend_from_slice(&[
                    fp[0],
                    fp[1],
                    fp[2],
                    (da_dot[n][0].dot(&msum) + da[n][0].dot(&msum_dot)) * s.psi,
                    (da_dot[n][1].dot(&msum) + da[n][1].dot(&msum_dot)) * s.psi,
                ]);
            }
            model.scatter_local(site.point, &local, &mut out);
        }
        Ok((out, on_tools))
    }
}
