//! Penalty contact between the shell's faces and rigid tools, as an external follower load.
//!
//! **Slave points** sit at the in-plane quadrature points on the top (`ζ = +1`) and/or bottom
//! (`ζ = −1`) face: `x = x̄ + ζ (t/2) d` with the RK-interpolated current mid-surface and
//! director, exactly as the shell kinematics place the faces (`docs/shell-formulation.md` §1):
//!
//! `x̄ = x̄⁰ + Σ_J Ψ_J (ū_J + Δū_J)`, `d = n⁰ + Σ_J Ψ_J (d_J(α_J) − d⁰_J)`, *not normalised*
//! (the internal force puts the material point of layer `ζ` at the same `x̄ + ζ t/2 d`).
//!
//! **Weight:** the initial area of the face at the point, `w |x⁰,1 × x⁰,2|` with
//! `x⁰,α = x̄⁰,α + ζ t/2 n⁰,α` (the penalty integral of eq 69 over the initial face; for a flat
//! sheet this is the mid-surface area, on a curved one it differs by `O(t/R)`).
//!
//! **Force** on the generalised DOFs (the variation `δx = Σ_J Ψ_J (δū_J + ζ t/2 ∂d_J/∂α_β δα_Jβ)`
//! of eq 70): `f_J = Ψ_J f`, `m_Jβ = Ψ_J ζ t/2 (∂d_J/∂α_β)·f`, with `f` the point's penalty force
//! ([`crate::contact::penalty_force`]) against the nearest tool. **Stiffness** (eq 72, hand-derived):
//! with `v_a = ∂x/∂q_a` (`Ψ_J e_c` for a translation, `Ψ_J ζ t/2 ∂d_J/∂α_β` for a rotation) and
//! `K = ∂f/∂x` ([`crate::contact::penalty_tangent`]),
//! `∂f_a/∂q_b = v_a·K v_b + δ_JK Ψ_J ζ t/2 (∂²d_J/∂α_β∂α_γ)·f` (the second term for two
//! rotations of the same particle).
//!
//! **Pseudo-time.** The tools move with the solver's load factor `λ` (the pseudo-time `t`), and
//! the penalty force is not scaled by it: the contact is a prescribed load
//! ([`crate::shell::load::Load::Contact`]), so [`ShellContact::force_tracked`] receives
//! `factor = t` and adds `f_c(q; t)` (and likewise the stiffness); [`crate::shell::problem::ShellProblem`] subtracts it from the residual.
//!
//! **Checks.** The analysis' evaluations ([`ShellContact::force_tracked`],
//! [`ShellContact::add_stiffness`]) track the gaps: when the pseudo-time changes
//! (a new step), a slave point whose gap to a tool goes from `> 0` at the previous pseudo-time
//! to `< −thickness` is a [`ContactError::PathCrossesSheet`] (the tool passed through the sheet
//! in one step). [`ShellContact::check_engaged`] reports the tools that never touched the sheet
//! (not an error at the point level). Both reset with [`ShellContact::reset_tracking`] (call it
//! after building a `ShellProblem`, whose set-up evaluates the loads at `t = 1`).

use crate::contact::penalty::{penalty_force, penalty_tangent};
use crate::contact::projection::{closest_point, ContactPoint};
use crate::contact::tool::RigidTool;
use crate::contact::{invalid, ContactError};
use crate::geometry::Surface;
use crate::kinematics::rotation::{director_derivatives, rotate_director};
use crate::scalar::Real;
use crate::shell::gather::GatherMap;
use crate::shell::model::ShellModel;
use crate::shell::point::{
    director_first_derivatives, ParticleState, SurfacePoint, DOFS_PER_PARTICLE,
};
use crate::shell::ShellError;
use nalgebra::{DMatrix, Vector3};
use std::sync::Mutex;

type V3<T> = Vector3<T>;

impl From<ContactError> for ShellError {
    fn from(e: ContactError) -> Self {
        match e {
            e @ (ContactError::PathCrossesSheet { .. }
            | ContactError::ProjectionNotConverged { .. }) => {
                ShellError::StepTooLarge(format!("contact: {e}"))
            }
            other => ShellError::InvalidInput(format!("contact: {other}")),
        }
    }
}

/// Default penalty factor `c` of `ω = c E / t` ([`ShellContact::default_penalty`]), from the
/// penalty study of `tests/contact_shell.rs` (`docs/contact.md` §5): the penetration is
/// `p t/(c E)`; on the cylinder pressed 1.5 t into a clamped plate (R/t = 10) the final tool
/// force changes by 1.1e-4 from c = 1 to 100 and by 1.4e-5 from c = 10 to 100, while the run
/// takes 9 s, 27 s and 97 s (more load-step cuts as the contact stiffens). c = 10 keeps the
/// penalty error of the force near 1e-5 at a third of the cost of c = 100. Above c ≈ 1e3 the
/// round-off of the gap (`ε |x|`) times `ω` limits the resolution of the pressure (§5).
pub const DEFAULT_PENALTY_FACTOR: f64 = 10.0;

/// Which faces of the sheet carry slave points.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ContactFaces {
    /// `ζ = +1` (the side the mid-surface normal `n⁰` points to).
    Top,
    /// `ζ = −1`.
    Bottom,
    /// Both faces.
    Both,
}

impl ContactFaces {
    fn zetas(self) -> &'static [f64] {
        match self {
            ContactFaces::Top => &[1.0],
            ContactFaces::Bottom => &[-1.0],
            ContactFaces::Both => &[1.0, -1.0],
        }
    }
}

/// Slave points of one in-plane quadrature point.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Site {
    pub(super) point: usize,
    x0: V3<f64>,
    /// Initial mid-surface normal `n⁰`.
    pub(super) n0: V3<f64>,
    /// `(ζ, initial face area weight)`.
    faces: Vec<(f64, f64)>,
}

/// Gaps of the last tracked evaluation: per slave point (site-major, face-minor), per tool.
#[derive(Debug, Default)]
struct Tracker {
    last: Option<(f64, Vec<Vec<Option<f64>>>)>,
    touched: Vec<bool>,
    /// Per slave point, the tool it penetrates (its force's tool) at the last tracked
    /// evaluation.
    active: Option<Vec<Option<usize>>>,
    /// Slave points whose entry of `active` changed, summed over the tracked evaluations.
    changes: u64,
}

/// One tool in a [`ContactReport`].
#[derive(Clone, Debug, PartialEq)]
pub struct ToolReport {
    /// Tool name.
    pub name: String,
    /// Translation `a(t)` of the tool.
    pub position: [f64; 3],
    /// Rotation vector `θ(t)` of the tool.
    pub rotation: [f64; 3],
    /// Force the sheet exerts on the tool, `−Σ f` over its active slave points (what a load
    /// cell in the press measures; equal and opposite to the contact force on the sheet).
    pub force: [f64; 3],
    /// Number of active (penetrating) slave points.
    pub active_points: usize,
}

/// One slave point in a [`ContactReport`].
#[derive(Clone, Debug, PartialEq)]
pub struct SlaveReport {
    /// Quadrature point index.
    pub point: usize,
    /// Face, `+1` or `−1`.
    pub zeta: f64,
    /// Parameter coordinates.
    pub uv: [f64; 2],
    /// Nearest tool (interior projection), if any.
    pub tool: Option<usize>,
    /// Gap to it (eq 68).
    pub gap: Option<f64>,
    /// Contact pressure `−ω g` (zero when not penetrating).
    pub pressure: f64,
}

/// Contact state at `(q, t)`: per tool and per slave point.
#[derive(Clone, Debug, PartialEq)]
pub struct ContactReport {
    /// Per tool.
    pub tools: Vec<ToolReport>,
    /// Per slave point (quadrature-point-major, top face first).
    pub slaves: Vec<SlaveReport>,
    /// Contact pressure per quadrature point of the model, `[top, bottom]` (zero where there is
    /// no slave point or no contact): for output.
    pub pressure: Vec<[f64; 2]>,
}

/// Frictionless penalty contact of the shell with rigid tools (eqs 69–72); a follower load
/// of the problem ([`crate::shell::load::Load::Contact`]).
#[derive(Debug)]
pub struct ShellContact {
    tools: Vec<RigidTool>,
    penalty: f64,
    sites: Vec<Site>,
    n_dofs: usize,
    n_points: usize,
    thickness: f64,
    tracker: Mutex<Tracker>,
}

/// The design-dependent inputs of the contact force in scalar `T`
/// ([`ShellContact::force_with`]).
#[derive(Clone, Copy, Debug)]
pub struct ContactInputs<'a, T> {
    /// Committed states of the real particles (as `ShellModel::particles`; images follow their
    /// sources).
    pub particles: &'a [ParticleState<T>],
    /// Shell thickness `t`.
    pub thickness: T,
    /// Penalty `ω`.
    pub penalty: T,
    /// Per tool, a translation added to its path (zero: the tools as built).
    pub offsets: &'a [V3<T>],
    /// Per tool, a rotation vector `φ` (radians, global axes) turning the tool as built about
    /// its pivot before its motion, `x^c = c + R(θ(t)) R(φ) R_φ₀ (X − c) + a(t)`
    /// ([`crate::contact::ToolPath::motion_with`]; zero: the tools as built).
    pub rotations: &'a [V3<T>],
    /// Per tool, its surface as built in scalar `T` (tool-shape design variables seed its
    /// design parameters, `Surface::with_design_parameters`; the value parts must be the
    /// tools' own surfaces); `None`: the tools' surfaces as constants.
    pub surfaces: Option<&'a [Surface<T>]>,
    /// The initial geometry of the in-plane points in `T` (shape design variables: the slave
    /// sites move with the design velocity of the mid-surface, eq 74's `V⁰`); `None`: the
    /// sites as built from the surface ([`ShellContact::new`]).
    pub initial: Option<InitialGeometry<'a, T>>,
}

/// The initial geometry of a model's in-plane points as the contact's slave sites use it, in
/// scalar `T` ([`ContactInputs::initial`]); for [`super::contact_sensitivity::ContactSeeds::initial`] its design
/// derivatives (`V⁰ = ∂x̄⁰/∂τ` and the [`SurfacePoint`] dots of
/// [`crate::sensitivity::shape::ShapeVelocity`]).
///
/// With it, a site at in-plane point `k` puts its slave point at
/// `x = x̄⁰ + Σ Ψ_J (ū_J + Δū_J) + ζ t/2 d`, `d = n⁰ + Σ Ψ_J (d_J(α_J) − d⁰_J)`, and weighs it by
/// the initial face area `w |x⁰,1 × x⁰,2|`, `x⁰,α = x̄⁰,α + ζ t/2 n⁰,α`, with `x̄⁰ =
/// positions[k]` and `x̄⁰,α, n⁰, n⁰,α` from `surfaces[k]` (the module documentation's
/// definitions, evaluated on the given geometry instead of the one the contact was built on).
#[derive(Clone, Copy, Debug)]
pub struct InitialGeometry<'a, T> {
    /// Per in-plane point (as `ShellModel::points`): the initial mid-surface position `x̄⁰`.
    pub positions: &'a [V3<T>],
    /// Per in-plane point: `x̄⁰,α`, `n⁰`, `n⁰,α`.
    pub surfaces: &'a [SurfacePoint<T>],
}

impl<T> InitialGeometry<'_, T> {
    /// Both lists hold one entry per in-plane point of `model`.
    pub(super) fn check(&self, model: &ShellModel) -> Result<(), ShellError> {
        for got in [self.positions.len(), self.surfaces.len()] {
            if got != model.points.len() {
                return Err(ShellError::Dimension {
                    expected: model.points.len(),
                    got,
                });
            }
        }
        Ok(())
    }
}

/// The committed state of shape-function particle `j` from the real particles' `particles`: an
/// image is `Q` times its source's (as `ShellModel::particle_state`).
pub(crate) fn neighbour_state<T: Real>(
    model: &ShellModel,
    j: usize,
    particles: &[ParticleState<T>],
) -> ParticleState<T> {
    let n = model.particles.len();
    if j < n {
        return particles[j];
    }
    let im = &model.symmetry.images[j - n];
    let q = im.map.map(T::cst);
    let s = particles[im.source];
    ParticleState {
        u: q * s.u,
        d: q * s.d,
        d0: q * s.d0,
        e: [q * s.e[0], q * s.e[1]],
    }
}

/// The evaluated kinematics of one site (generic).
pub(super) struct SiteEval<T> {
    /// Local DOF increments (5 per neighbour) and states, from `gather_local`.
    pub(super) parts: Vec<ParticleState<T>>,
    pub(super) local: Vec<T>,
    /// Per face: slave position and per-tool interior projections.
    pub(super) faces: Vec<FaceEval<T>>,
    /// Penalty `ω`.
    pub(super) penalty: T,
}

pub(super) struct FaceEval<T> {
    pub(super) zeta: f64,
    /// `ζ t/2`.
    pub(super) zh: T,
    /// Initial face area weight `w`.
    pub(super) area: T,
    pub(super) contacts: Vec<Option<ContactPoint<T>>>,
}

impl<T: Real> FaceEval<T> {
    /// The nearest tool: the interior projection with the smallest gap.
    pub(super) fn nearest(&self) -> Option<(usize, &ContactPoint<T>)> {
        self.contacts
            .iter()
            .enumerate()
            .filter_map(|(i, c)| c.as_ref().map(|c| (i, c)))
            .min_by(|a, b| a.1.gap.value().total_cmp(&b.1.gap.value()))
    }
}

impl ShellContact {
    /// Contact of `model` (built on `surface`) with `tools` on the given faces, penalty `ω`
    /// (force per length³, > 0; see [`Self::default_penalty`]).
    pub fn new(
        model: &ShellModel,
        surface: &Surface<f64>,
        tools: Vec<RigidTool>,
        faces: ContactFaces,
        penalty: f64,
    ) -> Result<Self, ContactError> {
        if !(penalty.is_finite() && penalty > 0.0) {
            return Err(invalid(
                "penalty",
                penalty,
                "a finite penalty > 0 (force per length³)",
            ));
        }
        if tools.is_empty() {
            return Err(invalid("tools", "[]", "at least one tool"));
        }
        for (i, t) in tools.iter().enumerate() {
            if tools[..i].iter().any(|o| o.name == t.name) {
                return Err(invalid(
                    format!("tools[{i}].name"),
                    &t.name,
                    "a name not used by another tool",
                ));
            }
        }
        let h = model.thickness / 2.0;
        let mut sites = Vec::with_capacity(model.points.len());
        for (k, p) in model.points.iter().enumerate() {
            let sd = surface.eval(p.uv[0], p.uv[1]);
            let n0 = sd.normal().map_err(|e| ContactError::InvalidInput {
                field: format!("surface normal at quadrature point {k} {:?}", p.uv),
                value: e.to_string(),
                expected: "a regular mid-surface point".into(),
            })?;
            let s = &p.surface;
            let faces = faces
                .zetas()
                .iter()
                .map(|&z| {
                    let a1 = s.x_a[0] + s.n_a[0] * (z * h);
                    let a2 = s.x_a[1] + s.n_a[1] * (z * h);
                    (z, a1.cross(&a2).norm() * p.weight)
                })
                .collect();
            sites.push(Site {
                point: k,
                x0: sd.x,
                n0,
                faces,
            });
        }
        let n_tools = tools.len();
        Ok(ShellContact {
            tools,
            penalty,
            sites,
            n_dofs: model.n_dofs(),
            n_points: model.points.len(),
            thickness: model.thickness,
            tracker: Mutex::new(Tracker {
                last: None,
                touched: vec![false; n_tools],
                active: None,
                changes: 0,
            }),
        })
    }

    /// `ω = DEFAULT_PENALTY_FACTOR · E / t` for `model`'s material and thickness.
    pub fn default_penalty(model: &ShellModel) -> f64 {
        DEFAULT_PENALTY_FACTOR * model.material.young / model.thickness
    }

    /// The tools.
    pub fn tools(&self) -> &[RigidTool] {
        &self.tools
    }

    /// The penalty `ω`.
    pub fn penalty(&self) -> f64 {
        self.penalty
    }

    /// The slave sites (one per in-plane quadrature point), in evaluation order.
    pub(super) fn sites(&self) -> &[Site] {
        &self.sites
    }

    pub(super) fn check_model(
        &self,
        model: &ShellModel,
        q: usize,
        f: Option<usize>,
    ) -> Result<(), ShellError> {
        if model.n_dofs() != self.n_dofs || model.points.len() != self.n_points {
            return Err(ShellError::InvalidInput(format!(
                "contact built for a model with {} DOFs and {} points, used with one of {} and {}",
                self.n_dofs,
                self.n_points,
                model.n_dofs(),
                model.points.len()
            )));
        }
        for got in std::iter::once(q).chain(f) {
            if got != self.n_dofs {
                return Err(ShellError::Dimension {
                    expected: self.n_dofs,
                    got,
                });
            }
        }
        Ok(())
    }

    /// Slave positions and projections of every site at `(q, t)`, generic, with the model's
    /// committed state, thickness and penalty and the tools on their paths.
    pub(super) fn evaluate<T: Real>(
        &self,
        model: &ShellModel,
        q: &[T],
        t: f64,
        surfaces: &[Surface<T>],
    ) -> Result<Vec<SiteEval<T>>, ContactError> {
        let particles: Vec<ParticleState<T>> = model.particles.iter().map(|p| p.lift()).collect();
        let offsets = vec![V3::zeros(); self.tools.len()];
        let inputs = ContactInputs {
            particles: &particles,
            thickness: T::cst(model.thickness),
            penalty: T::cst(self.penalty),
            offsets: &offsets,
            rotations: &offsets,
            surfaces: None,
            initial: None,
        };
        self.evaluate_with(model, &inputs, q, t, surfaces)
    }

    /// Slave positions and projections of every site at `(q, t)` from `inputs` (committed
    /// particle states, thickness, tool offsets and rotations in scalar `T`), generic.
    fn evaluate_with<T: Real>(
        &self,
        model: &ShellModel,
        inputs: &ContactInputs<'_, T>,
        q: &[T],
        t: f64,
        surfaces: &[Surface<T>],
    ) -> Result<Vec<SiteEval<T>>, ContactError> {
        let motions: Vec<_> = self
            .tools
            .iter()
            .zip(inputs.offsets.iter().zip(inputs.rotations))
            .map(|(tl, (o, phi))| tl.path.motion_with(t, phi, o))
            .collect();
        let mut out = Vec::with_capacity(self.sites.len());
        for site in &self.sites {
            let (_, local) = model.gather_local(site.point, q);
            let p = &model.points[site.point];
            let parts: Vec<ParticleState<T>> = p
                .neighbours
                .iter()
                .map(|&j| neighbour_state(model, j, inputs.particles))
                .collect();
            // The initial geometry: given in `T` (shape design variables) or the sites' own.
            let (x0, sf) = match &inputs.initial {
                Some(g) => (g.positions[site.point], g.surfaces[site.point]),
                None => (
                    site.x0.map(T::cst),
                    SurfacePoint {
                        n: site.n0.map(T::cst),
                        ..p.surface.lift()
                    },
                ),
            };
            let mut xbar = x0;
            let mut d = sf.n;
            for (n, (s, st)) in p.shape.iter().zip(&parts).enumerate() {
                let x = &local[DOFS_PER_PARTICLE * n..DOFS_PER_PARTICLE * (n + 1)];
                xbar += (st.u + V3::new(x[0], x[1], x[2])) * T::cst(s.psi);
                let dj = rotate_director(&st.d, &st.e[0], &st.e[1], [x[3], x[4]]);
                d += (dj - st.d0) * T::cst(s.psi);
            }
            let mut faces = Vec::with_capacity(site.faces.len());
            for &(zeta, _) in &site.faces {
                // ζ t/2 and the initial face area w |x⁰,1 × x⁰,2| (module documentation).
                let zh = inputs.thickness * (zeta * 0.5);
                let a1 = sf.x_a[0] + sf.n_a[0] * zh;
                let a2 = sf.x_a[1] + sf.n_a[1] * zh;
                let area = a1.cross(&a2).norm() * p.weight;
                let xs = xbar + d * zh;
                let mut contacts = Vec::with_capacity(self.tools.len());
                for ((tool, surf), motion) in self.tools.iter().zip(surfaces).zip(&motions) {
                    let cp = closest_point(surf, motion, tool.side, &tool.grid, &xs, &tool.name)?;
                    contacts.push(cp.is_interior().then_some(cp));
                }
                faces.push(FaceEval {
                    zeta,
                    zh,
                    area,
                    contacts,
                });
            }
            out.push(SiteEval {
                parts,
                local,
                faces,
                penalty: inputs.penalty,
            });
        }
        Ok(out)
    }

    /// The tools' surfaces in `T`: those of `inputs` (checked: one per tool) or the tools' own
    /// as constants.
    fn input_surfaces<T: Real>(
        &self,
        inputs: &ContactInputs<'_, T>,
    ) -> Result<Vec<Surface<T>>, ShellError> {
        match inputs.surfaces {
            Some(s) if s.len() != self.tools.len() => Err(ShellError::Dimension {
                expected: self.tools.len(),
                got: s.len(),
            }),
            Some(s) => Ok(s.to_vec()),
            None => Ok(self.tools.iter().map(|tl| tl.surface.lift()).collect()),
        }
    }

    /// Add `f_c` from evaluated sites (generic).
    fn scatter_forces<T: Real>(&self, model: &ShellModel, evals: &[SiteEval<T>], f: &mut [T]) {
        for (site, ev) in self.sites.iter().zip(evals) {
            let p = &model.points[site.point];
            let mut total: Option<(V3<T>, V3<T>)> = None; // (Σ f, Σ ζ t/2 f)
            for face in &ev.faces {
                let Some((_, cp)) = face.nearest() else {
                    continue;
                };
                if !cp.is_active() {
                    continue;
                }
                // f = −ω w g n (eq 70).
                let fc = cp.normal * (cp.gap * -(ev.penalty * face.area));
                let (a, b) = total.get_or_insert((V3::zeros(), V3::zeros()));
                *a += fc;
                *b += fc * face.zh;
            }
            let Some((fsum, msum)) = total else {
                continue;
            };
            let mut local = Vec::with_capacity(DOFS_PER_PARTICLE * p.shape.len());
            for (n, (s, st)) in p.shape.iter().zip(&ev.parts).enumerate() {
                let x = &ev.local[DOFS_PER_PARTICLE * n..DOFS_PER_PARTICLE * (n + 1)];
                let da = director_first_derivatives(st, [x[3], x[4]]);
                let fp = fsum * T::cst(s.psi);
                local.extend_from_slice(&[
                    fp[0],
                    fp[1],
                    fp[2],
                    da[0].dot(&msum) * s.psi,
                    da[1].dot(&msum) * s.psi,
                ]);
            }
            model.scatter_local(site.point, &local, f);
        }
    }

    /// Adds `f_c(q; t)` in scalar `T` with the design-dependent inputs in `T` (the dual-number
    /// reference, `crate::sensitivity::dual`): the committed particle states of `inputs` (so
    /// that their sensitivities, the history dependence of the contact force, are carried),
    /// the thickness (slave faces at `ζ t/2`, face areas), the penalty, each tool's
    /// translation added to its path (tool-position design variables, eq 76 with a constant
    /// `V^c`) and each tool's rotation `R(φ)` of the tool as built composed into its motion
    /// (tool-rotation design variables: the moved point, its tangents and curvatures and the
    /// normal all turn, eq 76 with `V^c = ȧ + Ω (x^c − p)`), each tool's surface in `T`
    /// ([`ContactInputs::surfaces`]: a tool-shape variable moves the tool point, tangents and
    /// normal at fixed `ξ`, eq 76's `V^c = R ∂X/∂p`) and, when given, the initial
    /// geometry of the in-plane points ([`ContactInputs::initial`]: a shape design variable
    /// moves the slave points with `V⁰ + ζ t/2 ṅ⁰` and changes the face areas, eq 74).
    /// Eqs 68–70 evaluated through
    /// [`closest_point`], whose final Newton correction in `T` carries the projection
    /// sensitivity of eq (80). Not tracked.
    pub fn force_with<T: Real>(
        &self,
        model: &ShellModel,
        inputs: &ContactInputs<'_, T>,
        q: &[T],
        t: f64,
        f: &mut [T],
    ) -> Result<(), ShellError> {
        self.check_model(model, q.len(), Some(f.len()))?;
        if inputs.particles.len() != model.particles.len() {
            return Err(ShellError::Dimension {
                expected: model.particles.len(),
                got: inputs.particles.len(),
            });
        }
        for got in [inputs.offsets.len(), inputs.rotations.len()] {
            if got != self.tools.len() {
                return Err(ShellError::Dimension {
                    expected: self.tools.len(),
                    got,
                });
            }
        }
        if let Some(g) = &inputs.initial {
            g.check(model)?;
        }
        let surfaces = self.input_surfaces(inputs)?;
        let evals = self.evaluate_with(model, inputs, q, t, &surfaces)?;
        self.scatter_forces(model, &evals, f);
        Ok(())
    }

    /// The force the sheet exerts on each tool (in the contact's order), `−Σ f` over the tool's
    /// active slave points (eq 70's `f = −ω w g n`), in scalar `T` with the design-dependent
    /// inputs of [`Self::force_with`]: the response a load cell in the press measures (the
    /// punch force), generic so that the dual-number reference differentiates it through the
    /// same evaluation. Not tracked.
    pub fn tool_forces_with<T: Real>(
        &self,
        model: &ShellModel,
        inputs: &ContactInputs<'_, T>,
        q: &[T],
        t: f64,
    ) -> Result<Vec<V3<T>>, ShellError> {
        self.check_model(model, q.len(), None)?;
        if inputs.particles.len() != model.particles.len() {
            return Err(ShellError::Dimension {
                expected: model.particles.len(),
                got: inputs.particles.len(),
            });
        }
        if let Some(g) = &inputs.initial {
            g.check(model)?;
        }
        let surfaces = self.input_surfaces(inputs)?;
        let evals = self.evaluate_with(model, inputs, q, t, &surfaces)?;
        let mut out = vec![V3::zeros(); self.tools.len()];
        for ev in &evals {
            for face in &ev.faces {
                if let Some((i, cp)) = face.nearest() {
                    if cp.is_active() {
                        // −f = ω w g n on the tool.
                        out[i] += cp.normal * (cp.gap * (ev.penalty * face.area));
                    }
                }
            }
        }
        Ok(out)
    }

    /// Record the gaps of an f64 evaluation at `t` and check for a tool crossing the sheet.
    fn track(
        &self,
        model: &ShellModel,
        evals: &[SiteEval<f64>],
        t: f64,
    ) -> Result<(), ContactError> {
        let gaps: Vec<Vec<Option<f64>>> = evals
            .iter()
            .flat_map(|ev| {
                ev.faces
                    .iter()
                    .map(|fe| fe.contacts.iter().map(|c| c.map(|c| c.gap)).collect())
            })
            .collect();
        let mut tr = self.tracker.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((t_prev, prev)) = &tr.last {
            if *t_prev != t {
                let mut slave = 0;
                for (site, ev) in self.sites.iter().zip(evals) {
                    for fe in &ev.faces {
                        for (i, (before, after)) in prev[slave].iter().zip(&gaps[slave]).enumerate()
                        {
                            if let (Some(b), Some(a)) = (before, after) {
                                if *b > 0.0 && *a < -self.thickness {
                                    return Err(ContactError::PathCrossesSheet {
                                        tool: self.tools[i].name.clone(),
                                        point: site.point,
                                        zeta: fe.zeta,
                                        uv: model.points[site.point].uv,
                                        gap_before: *b,
                                        gap_after: *a,
                                        t_before: *t_prev,
                                        t_after: t,
                                        thickness: self.thickness,
                                    });
                                }
                            }
                        }
                        slave += 1;
                    }
                }
            }
        }
        let active: Vec<Option<usize>> = evals
            .iter()
            .flat_map(|ev| ev.faces.iter())
            .map(|fe| {
                fe.nearest()
                    .filter(|(_, cp)| cp.is_active())
                    .map(|(i, _)| i)
            })
            .collect();
        for i in active.iter().flatten() {
            tr.touched[*i] = true;
        }
        if let Some(before) = &tr.active {
            let changed = before.iter().zip(&active).filter(|(a, b)| a != b).count();
            tr.changes += changed as u64;
        }
        tr.active = Some(active);
        tr.last = Some((t, gaps));
        Ok(())
    }

    /// The slave points that changed the tool they penetrate (or started or stopped
    /// penetrating) from one tracked evaluation to the next, summed since the contact was
    /// built: the active set's changes ([`crate::solver::NonlinearProblem::active_set_changes`]).
    pub fn active_set_changes(&self) -> u64 {
        self.tracker
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .changes
    }

    /// The f64 evaluation of the analysis (tracked).
    fn evaluate_tracked(
        &self,
        model: &ShellModel,
        q: &[f64],
        t: f64,
    ) -> Result<Vec<SiteEval<f64>>, ContactError> {
        let surfaces: Vec<Surface<f64>> = self.tools.iter().map(|tl| tl.surface.clone()).collect();
        let evals = self.evaluate(model, q, t, &surfaces)?;
        self.track(model, &evals, t)?;
        Ok(evals)
    }

    /// `Err(InitialPenetration)` for the tool whose slave point lies deepest inside it, deeper
    /// than the sheet thickness, on the undeformed sheet at `t = 0` (the committed state of
    /// `model` before any step): the penalty cannot push such a sheet out, and the first step's
    /// evaluations would report a crossing instead. A smaller overlap (a die set flush with the
    /// sheet) is the penalty's to resolve and passes. Not tracked.
    pub fn initial_penetration(&self, model: &ShellModel) -> Result<(), ContactError> {
        let q = vec![0.0; model.n_dofs()];
        let surfaces: Vec<Surface<f64>> = self.tools.iter().map(|tl| tl.surface.clone()).collect();
        let evals = self.evaluate(model, &q, 0.0, &surfaces)?;
        let mut deepest: Option<(f64, usize, f64, usize)> = None;
        for (site, ev) in self.sites.iter().zip(&evals) {
            for fe in &ev.faces {
                for (i, c) in fe.contacts.iter().enumerate() {
                    if let Some(c) = c {
                        if c.gap < -self.thickness && deepest.is_none_or(|d| c.gap < d.0) {
                            deepest = Some((c.gap, i, fe.zeta, site.point));
                        }
                    }
                }
            }
        }
        match deepest {
            None => Ok(()),
            Some((gap, i, zeta, point)) => Err(ContactError::InitialPenetration {
                tool: self.tools[i].name.clone(),
                point,
                zeta,
                uv: model.points[point].uv,
                gap,
                thickness: self.thickness,
            }),
        }
    }

    /// Forget the tracked gaps and the touched tools (call after a `ShellProblem` is built: its
    /// set-up evaluates the loads at `t = 1`).
    pub fn reset_tracking(&self) {
        let mut tr = self.tracker.lock().unwrap_or_else(|e| e.into_inner());
        tr.last = None;
        tr.touched.iter_mut().for_each(|b| *b = false);
    }

    /// `Err(ToolsNeverTouched)` naming the tools that had no penetrating slave point in any
    /// tracked evaluation since the last [`Self::reset_tracking`] (a tool path that misses the
    /// sheet; not an error at the point level, so the run decides when to ask).
    pub fn check_engaged(&self) -> Result<(), ContactError> {
        let tr = self.tracker.lock().unwrap_or_else(|e| e.into_inner());
        let tools: Vec<String> = self
            .tools
            .iter()
            .zip(&tr.touched)
            .filter(|(_, &t)| !t)
            .map(|(tl, _)| tl.name.clone())
            .collect();
        if tools.is_empty() {
            Ok(())
        } else {
            Err(ContactError::ToolsNeverTouched { tools })
        }
    }

    /// The contact state at the increment `q` and pseudo-time `t` (not tracked): per tool its
    /// position, the force the sheet exerts on it and its active points; per slave point the
    /// nearest tool, gap and pressure; the pressure per quadrature point.
    pub fn report(
        &self,
        model: &ShellModel,
        q: &[f64],
        t: f64,
    ) -> Result<ContactReport, ShellError> {
        self.check_model(model, q.len(), None)?;
        let surfaces: Vec<Surface<f64>> = self.tools.iter().map(|tl| tl.surface.clone()).collect();
        let evals = self.evaluate(model, q, t, &surfaces)?;
        let mut tools: Vec<ToolReport> = self
            .tools
            .iter()
            .map(|tl| {
                let (a, th) = tl.path.position(t);
                ToolReport {
                    name: tl.name.clone(),
                    position: a,
                    rotation: th,
                    force: [0.0; 3],
                    active_points: 0,
                }
            })
            .collect();
        let mut slaves = Vec::new();
        let mut pressure = vec![[0.0; 2]; model.points.len()];
        for (site, ev) in self.sites.iter().zip(&evals) {
            for fe in &ev.faces {
                let near = fe.nearest();
                let mut pr = 0.0;
                if let Some((i, cp)) = near {
                    if cp.is_active() {
                        pr = -self.penalty * cp.gap;
                        let fc = penalty_force(cp, self.penalty, fe.area);
                        for c in 0..3 {
                            tools[i].force[c] -= fc[c];
                        }
                        tools[i].active_points += 1;
                    }
                }
                pressure[site.point][if fe.zeta > 0.0 { 0 } else { 1 }] = pr;
                slaves.push(SlaveReport {
                    point: site.point,
                    zeta: fe.zeta,
                    uv: model.points[site.point].uv,
                    tool: near.map(|(i, _)| i),
                    gap: near.map(|(_, c)| c.gap),
                    pressure: pr,
                });
            }
        }
        Ok(ContactReport {
            tools,
            slaves,
            pressure,
        })
    }
}

impl ShellContact {
    /// Adds `f_c(q; t = factor)` (module documentation), in scalar `T`; the
    /// tools' surfaces are lifted as constants (derivatives with respect to `q` only). Not
    /// tracked.
    pub fn force_generic<T: Real>(
        &self,
        model: &ShellModel,
        q: &[T],
        factor: f64,
        f: &mut [T],
    ) -> Result<(), ShellError> {
        self.check_model(model, q.len(), Some(f.len()))?;
        let t = factor;
        let surfaces: Vec<Surface<T>> = self.tools.iter().map(|tl| tl.surface.lift()).collect();
        let evals = self.evaluate(model, q, t, &surfaces)?;
        self.scatter_forces(model, &evals, f);
        Ok(())
    }

    /// Adds `f_c(q; t = factor)`: the penalty forces at pseudo-time `factor`, not scaled by it
    /// (module documentation). Tracked (tool crossing check).
    pub fn force_tracked(
        &self,
        model: &ShellModel,
        q: &[f64],
        factor: f64,
        f: &mut [f64],
    ) -> Result<(), ShellError> {
        self.check_model(model, q.len(), Some(f.len()))?;
        let t = factor;
        let evals = self.evaluate_tracked(model, q, t)?;
        self.scatter_forces(model, &evals, f);
        Ok(())
    }

    /// Adds `∂f_c/∂q` at pseudo-time `factor` (hand-derived, module
    /// documentation). The entries lie in the cells of the quadrature points, which every
    /// `ShellProblem` pattern holds, so the active set may change freely. Tracked.
    pub fn add_stiffness(
        &self,
        model: &ShellModel,
        q: &[f64],
        factor: f64,
        out: &mut Vec<(usize, usize, f64)>,
    ) -> Result<(), ShellError> {
        self.check_model(model, q.len(), None)?;
        let t = factor;
        let evals = self.evaluate_tracked(model, q, t)?;
        let h = model.thickness / 2.0;
        let mut map = GatherMap::new(model);
        for (site, ev) in self.sites.iter().zip(&evals) {
            let active: Vec<(&FaceEval<f64>, &ContactPoint<f64>)> = ev
                .faces
                .iter()
                .filter_map(|fe| fe.nearest().map(|(_, cp)| (fe, cp)))
                .filter(|(_, cp)| cp.is_active())
                .collect();
            if active.is_empty() {
                continue;
            }
            let p = &model.points[site.point];
            let n = p.shape.len();
            let dirs: Vec<_> = ev
                .parts
                .iter()
                .enumerate()
                .map(|(j, st)| {
                    let x = &ev.local[DOFS_PER_PARTICLE * j..DOFS_PER_PARTICLE * (j + 1)];
                    director_derivatives(&st.d, &st.e[0], &st.e[1], [x[3], x[4]])
                })
                .collect();
            let mut kl = DMatrix::zeros(DOFS_PER_PARTICLE * n, DOFS_PER_PARTICLE * n);
            for (fe, cp) in active {
                let zh = fe.zeta * h;
                let k = penalty_tangent(cp, self.penalty, fe.area);
                let fc = penalty_force(cp, self.penalty, fe.area);
                // v_a = ∂x/∂q_a as the columns of V (3 × 5n).
                let mut v = DMatrix::zeros(3, DOFS_PER_PARTICLE * n);
                for (j, (s, dj)) in p.shape.iter().zip(&dirs).enumerate() {
                    let b = DOFS_PER_PARTICLE * j;
                    for c in 0..3 {
                        v[(c, b + c)] = s.psi;
                    }
                    for be in 0..2 {
                        for c in 0..3 {
                            v[(c, b + 3 + be)] = s.psi * zh * dj.d_a[be][c];
                        }
                    }
                }
                let kd = DMatrix::from_column_slice(3, 3, k.as_slice());
                kl += v.transpose() * kd * &v;
                for (j, (s, dj)) in p.shape.iter().zip(&dirs).enumerate() {
                    let b = DOFS_PER_PARTICLE * j + 3;
                    for be in 0..2 {
                        for ga in 0..2 {
                            kl[(b + be, b + ga)] += dj.d_ab[be][ga].dot(&fc) * (s.psi * zh);
                        }
                    }
                }
            }
            let local: Vec<(usize, usize)> = p
                .neighbours
                .iter()
                .flat_map(|&j| (0..DOFS_PER_PARTICLE).map(move |c| (j, c)))
                .collect();
            map.add_triplets(model, &local, &kl, out);
        }
        Ok(())
    }
}
