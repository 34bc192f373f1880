//! The term-by-term breakdown of the continuum DSA against the dual-number reference
//! (`shelldsa dsa --terms STEP`): which group of the fictitious load, of which equation, at
//! which step and particle or integration point, disagrees.
//!
//! The analysis runs with the dual reference ([`DualDsa`] with `Dual64`, one dual state per
//! variable) in its hook, inside the breakdown's observer; at the chosen converged step, *before* the dual update,
//! the observer takes the dual reference's committed sensitivities `ⁿṡ` as the continuum
//! method's seeds (so that errors accumulated over earlier steps do not mix in) and compares,
//! for every design variable and every [`TermGroup`]:
//! - the continuum fictitious load of the group ([`fictitious_loads`], the hand-derived point
//!   kernel, eqs 49–64) with the derivative part of the dual residual seeded with that group
//!   only (the other derivative parts set to zero), row by row (the worst row names its
//!   particle and DOF). The director filter is a group of its own ([`TermGroup::Filter`]): its
//!   dual force with all derivative parts, taken out of the other groups' dual residuals;
//! - and, after the step, the continuum history update (eqs 44–51: `ⁿ⁺¹(σ̇, α̇, ė^p, Q̇)`,
//!   from its own solve of eq 65 with the same factorised tangent) with the dual reference's
//!   committed dual histories, field by field (the worst integration point names its in-plane
//!   point, parameter coordinates and layer).

use super::continuum::{fictitious_loads, SensitivityState, StepState, TermGroup};
use super::dual::{DualDsa, DualState, SensitivityError};
use super::DesignVariable;
use crate::geometry::Surface;
use crate::material::MaterialParams;
use crate::shell::contact_sensitivity::ToolRate;
use crate::shell::load::EdgeVelocity;
use crate::shell::point::{ParticleState, PointHistory, SurfacePoint, DOFS_PER_PARTICLE};
use crate::shell::point_sensitivity::{commit_particle_dot, ModelSeeds};
use crate::shell::problem::ShellProblem;
use crate::solver::observe::{Observed, StepObserver};
use crate::solver::Failure;
use crate::solver::{
    ConvergedStep, ConvergedTangent, LinearSolver, NewtonSolver, NonlinearProblem, ProblemError,
    SolverOptions,
};
use num_dual::Dual64;

/// One group's fictitious load, continuum against dual.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupComparison {
    /// The group (`None`: all groups, the whole right-hand side).
    pub group: Option<TermGroup>,
    /// `max |continuum|` over the rows.
    pub continuum_max: f64,
    /// `max |dual|` over the rows.
    pub dual_max: f64,
    /// `max |continuum − dual|`.
    pub max_difference: f64,
    /// The row where it occurs.
    pub worst_row: usize,
    /// That row's particle and DOF (`None` for a constraint row).
    pub worst_dof: Option<(usize, usize)>,
}

impl GroupComparison {
    /// `max |continuum − dual|` relative to `max |dual|` (absolute when the dual is 0).
    pub fn relative(&self) -> f64 {
        if self.dual_max > 0.0 {
            self.max_difference / self.dual_max
        } else {
            self.max_difference
        }
    }
}

/// One history field's update at the end of the step, continuum against dual.
#[derive(Clone, Debug, PartialEq)]
pub struct FieldComparison {
    /// `stress`, `back_stress`, `eps_p`, `frame`, `particle.u`, `particle.d`, `particle.e`.
    pub field: &'static str,
    /// `max |dual|` over the integration points (or particles).
    pub dual_max: f64,
    /// `max |continuum − dual|`.
    pub max_difference: f64,
    /// Where: integration point (in-plane point, layer) or particle index (layer `None`).
    pub worst: (usize, Option<usize>),
    /// Parameter coordinates of the worst point or particle.
    pub worst_uv: [f64; 2],
}

impl FieldComparison {
    /// `max |continuum − dual|` relative to `max |dual|` (absolute when the dual is 0).
    pub fn relative(&self) -> f64 {
        if self.dual_max > 0.0 {
            self.max_difference / self.dual_max
        } else {
            self.max_difference
        }
    }
}

/// The breakdown of one design variable at one step.
#[derive(Clone, Debug, PartialEq)]
pub struct TermBreakdown {
    /// Converged step (1-based).
    pub step: usize,
    /// Load factor.
    pub load: f64,
    /// The variable.
    pub variable: DesignVariable,
    /// Per group, then the whole right-hand side (`group: None`).
    pub groups: Vec<GroupComparison>,
    /// The end-of-step sensitivities, field by field.
    pub update: Vec<FieldComparison>,
}

/// The continuum seeds carried by a dual state (its derivative parts).
fn seeds_of(problem: &ShellProblem, g: &DualState<Dual64>) -> SensitivityState {
    let pv = |v: &nalgebra::Vector3<Dual64>| v.map(|x| x.eps);
    SensitivityState {
        particles: g
            .particles
            .iter()
            .map(|p| ParticleState {
                u: pv(&p.u),
                d: pv(&p.d),
                d0: pv(&p.d0),
                e: [pv(&p.e[0]), pv(&p.e[1])],
            })
            .collect(),
        history: g.history.iter().map(history_parts).collect(),
        unknowns: g.unknowns.iter().map(|x| x.eps).collect(),
        // With a shape variable's positions (`Some`) the surface dots are kept too, zero or
        // not: the contact takes both (a translation of the sheet moves x̄⁰ alone).
        surface: (g.positions.is_some()
            || g.surfaces.iter().any(|p| {
                p.n.iter().any(|x| x.eps != 0.0)
                    || p.x_a.iter().any(|v| v.iter().any(|x| x.eps != 0.0))
            }))
        .then(|| {
            g.surfaces
                .iter()
                .map(|p| SurfacePoint {
                    x_a: p.x_a.map(|v| pv(&v)),
                    n: pv(&p.n),
                    n_a: p.n_a.map(|v| pv(&v)),
                })
                .collect()
        }),
        // V⁰ of the contact's slave sites, with the surface dots (a shape variable's group).
        position: g.positions.as_ref().map(|x| x.iter().map(pv).collect()),
        // The edge loads' design velocities, from the seeded surface (a shape variable's; its
        // values are the surface the loads were built on, whose edge normals were checked
        // then, so the evaluation does not fail).
        edge_velocities: match &g.surface {
            Some(s) => problem
                .loads()
                .iter()
                .map(|l| {
                    l.edge_geometry_on(s)
                        .map(|geo| {
                            geo.iter()
                                .map(|e| EdgeVelocity {
                                    x_a: e.x_a.map(|v| pv(&v)),
                                    n: pv(&e.n),
                                })
                                .collect()
                        })
                        .unwrap_or_default()
                })
                .collect(),
            None => Vec::new(),
        },
        thickness: g.thickness.eps,
        material: MaterialParams::from_array(g.material.to_array().map(|x| x.eps)),
        // Tool translations, rotations and shapes all feed the `Tool` group (V^c, eq 76).
        tools: g
            .tool_offsets
            .iter()
            .zip(&g.tool_rotations)
            .enumerate()
            .map(|(i, (a, r))| ToolRate {
                translation: [a[0].eps, a[1].eps, a[2].eps],
                rotation: [r[0].eps, r[1].eps, r[2].eps],
                // One variable per dual state: at most one seeded surface parameter.
                shape: g.tool_surfaces.as_ref().and_then(|s| {
                    s[i].parameter_values()
                        .iter()
                        .enumerate()
                        .find(|(_, p)| p.eps != 0.0)
                        .map(|(k, p)| (k, p.eps))
                }),
            })
            .collect(),
    }
}

fn history_parts(h: &PointHistory<Dual64>) -> PointHistory<f64> {
    PointHistory {
        frame: h.frame.map(|x| x.eps),
        material: crate::material::MaterialState {
            stress: h.material.stress.map(|x| x.eps),
            back_stress: h.material.back_stress.map(|x| x.eps),
            eps_p: h.material.eps_p.eps,
        },
    }
}

/// The dual state with only `group`'s derivative parts kept.
fn masked(g: &DualState<Dual64>, group: TermGroup) -> DualState<Dual64> {
    let c = |x: &Dual64| Dual64::from(x.re);
    let mut m = g.clone();
    if group != TermGroup::History {
        for p in &mut m.particles {
            *p = ParticleState {
                u: p.u.map(|x| c(&x)),
                d: p.d.map(|x| c(&x)),
                d0: p.d0.map(|x| c(&x)),
                e: [p.e[0].map(|x| c(&x)), p.e[1].map(|x| c(&x))],
            };
        }
        for h in &mut m.history {
            h.frame = h.frame.map(|x| c(&x));
            h.material.stress = h.material.stress.map(|x| c(&x));
            h.material.back_stress = h.material.back_stress.map(|x| c(&x));
            h.material.eps_p = c(&h.material.eps_p);
        }
        for u in &mut m.unknowns {
            *u = c(u);
        }
    }
    if group != TermGroup::Design && group != TermGroup::Load {
        m.thickness = c(&m.thickness);
        for p in &mut m.surfaces {
            p.x_a = p.x_a.map(|v| v.map(|x| c(&x)));
            p.n = p.n.map(|x| c(&x));
            p.n_a = p.n_a.map(|v| v.map(|x| c(&x)));
        }
        for x in m.positions.iter_mut().flatten() {
            *x = x.map(|v| c(&v));
        }
        m.surface = None;
    }
    if group != TermGroup::Tool {
        for v in m.tool_offsets.iter_mut().chain(&mut m.tool_rotations) {
            *v = v.map(|x| c(&x));
        }
        m.tool_surfaces = None;
    }
    if group != TermGroup::Material {
        m.material = MaterialParams::from_array(m.material.to_array().map(|x| c(&x)));
    }
    m
}

fn compare_rows(group: Option<TermGroup>, c: &[f64], d: &[f64], n_q: usize) -> GroupComparison {
    let mut out = GroupComparison {
        group,
        continuum_max: 0.0,
        dual_max: 0.0,
        max_difference: 0.0,
        worst_row: 0,
        worst_dof: None,
    };
    for (i, (a, b)) in c.iter().zip(d).enumerate() {
        out.continuum_max = out.continuum_max.max(a.abs());
        out.dual_max = out.dual_max.max(b.abs());
        let e = (a - b).abs();
        if e > out.max_difference {
            out.max_difference = e;
            out.worst_row = i;
        }
    }
    out.worst_dof = (out.worst_row < n_q).then_some((
        out.worst_row / DOFS_PER_PARTICLE,
        out.worst_row % DOFS_PER_PARTICLE,
    ));
    out
}

/// Accumulates one field's comparison.
struct FieldAcc(FieldComparison);

impl FieldAcc {
    fn new(field: &'static str) -> Self {
        FieldAcc(FieldComparison {
            field,
            dual_max: 0.0,
            max_difference: 0.0,
            worst: (0, None),
            worst_uv: [0.0; 2],
        })
    }
    fn add(&mut self, c: f64, d: f64, at: (usize, Option<usize>), uv: [f64; 2]) {
        self.0.dual_max = self.0.dual_max.max(d.abs());
        let e = (c - d).abs();
        if e > self.0.max_difference {
            self.0.max_difference = e;
            self.0.worst = at;
            self.0.worst_uv = uv;
        }
    }
}

/// The observer of the breakdown at one step.
#[derive(Debug)]
struct Breakdown {
    /// The dual reference (its hooks run first).
    dual: DualDsa<Dual64>,
    /// 0-based converged step.
    step: usize,
    /// The continuum's end-of-step sensitivities, per variable (set at the step).
    pending: Option<(f64, Vec<SensitivityState>)>,
    out: Vec<TermBreakdown>,
}

fn fatal(e: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> ProblemError {
    ProblemError::Failed(Failure::new("term breakdown", e))
}

impl Breakdown {
    fn at_step(
        &mut self,
        problem: &ShellProblem,
        step: &ConvergedStep<'_>,
    ) -> Result<(), SensitivityError> {
        let dp = &self.dual;
        let model = &problem.model;
        let n = step.u.len();
        let n_q = problem.n_generalised();
        let du: Vec<f64> = step
            .u
            .iter()
            .zip(problem.state())
            .map(|(a, b)| a - b)
            .collect();
        let dq: Vec<Dual64> = du[..n_q].iter().map(|&v| Dual64::from(v)).collect();
        let at = StepState {
            du: &du,
            u: step.u,
            load: step.load,
        };
        let states: Vec<SensitivityState> =
            dp.groups().iter().map(|g| seeds_of(problem, g)).collect();
        let zero = SensitivityState::zero(problem);
        let mut per_var: Vec<Vec<GroupComparison>> = vec![Vec::new(); states.len()];
        let groups: Vec<Option<TermGroup>> = TermGroup::ALL
            .iter()
            .map(|g| Some(*g))
            .chain([None])
            .collect();
        for group in groups {
            let cont = fictitious_loads(problem, &states, &zero, at, group)?;
            for (v, g) in dp.groups().iter().enumerate() {
                let gm = match group {
                    Some(TermGroup::Filter) | None => g.clone(),
                    Some(t) => masked(g, t),
                };
                // The geometry seeds (Design) act on the internal force and on the loads; the
                // loads' share is the Load group: split R = f_int − f_ext.
                let mut d: Vec<f64> = match group {
                    // The filter's force with every seed (R = … − f_ext).
                    Some(TermGroup::Filter) => dp
                        .dual_filter(problem, &gm, &dq, step.load)?
                        .iter()
                        .map(|x| -x.eps)
                        .collect(),
                    Some(TermGroup::Design) | Some(TermGroup::Load) => {
                        let r = dp.dual_residual(problem, &gm, &dq, step.u, step.load)?;
                        let f = dp.dual_external(problem, &gm, &dq, step.load)?;
                        let mut d: Vec<f64> = if group == Some(TermGroup::Load) {
                            vec![0.0; r.len()]
                        } else {
                            r.iter().map(|x| x.eps).collect()
                        };
                        for (di, fi) in d.iter_mut().zip(&f) {
                            if group == Some(TermGroup::Load) {
                                *di = -fi.eps;
                            } else {
                                *di += fi.eps;
                            }
                        }
                        d
                    }
                    _ => dp
                        .dual_residual(problem, &gm, &dq, step.u, step.load)?
                        .iter()
                        .map(|x| x.eps)
                        .collect(),
                };
                // The filter's share of f_ext is its own group: out of the other groups'
                // residuals (Design is f_int alone).
                if matches!(
                    group,
                    Some(
                        TermGroup::History
                            | TermGroup::Material
                            | TermGroup::Load
                            | TermGroup::Tool
                    )
                ) {
                    let fl = dp.dual_filter(problem, &gm, &dq, step.load)?;
                    for (di, fi) in d.iter_mut().zip(&fl) {
                        *di += fi.eps;
                    }
                }
                per_var[v].push(compare_rows(group, &cont[v], &d, n_q));
            }
        }
        // The continuum's own step: solve eq 65 with the total right-hand side, update.
        let rhs = fictitious_loads(problem, &states, &zero, at, None)?;
        let nv = states.len();
        let mut b = vec![0.0; n * nv];
        for (v, r) in rhs.iter().enumerate() {
            let col = &mut b[v * n..(v + 1) * n];
            for (c, ri) in col.iter_mut().zip(r) {
                *c = -ri;
            }
            step.essential.zero_constrained(col);
        }
        step.solver.solve_columns_in_place(&mut b, nv)?;
        let seeds: Vec<ModelSeeds> = states
            .iter()
            .enumerate()
            .map(|(v, s)| ModelSeeds {
                surface: s.surface.as_deref(),
                thickness: s.thickness,
                material: s.material,
                particles: &s.particles,
                history: &s.history,
                dofs: &b[v * n..v * n + n_q],
            })
            .collect();
        let dots = model.internal_force_dots(&du[..n_q], &seeds)?;
        let next: Vec<SensitivityState> = states
            .iter()
            .zip(dots)
            .enumerate()
            .map(|(v, (s, (_, history)))| {
                let dqd = &b[v * n..(v + 1) * n];
                SensitivityState {
                    particles: model
                        .particles
                        .iter()
                        .zip(&s.particles)
                        .enumerate()
                        .map(|(i, (p, pd))| {
                            let r = DOFS_PER_PARTICLE * i..DOFS_PER_PARTICLE * (i + 1);
                            commit_particle_dot(p, pd, &du[r.clone()], &dqd[r])
                        })
                        .collect(),
                    history,
                    unknowns: s.unknowns.iter().zip(dqd).map(|(a, d)| a + d).collect(),
                    surface: s.surface.clone(),
                    position: s.position.clone(),
                    edge_velocities: s.edge_velocities.clone(),
                    thickness: s.thickness,
                    material: s.material,
                    tools: s.tools.clone(),
                }
            })
            .collect();
        for (v, groups) in per_var.into_iter().enumerate() {
            self.out.push(TermBreakdown {
                step: step.step + 1,
                load: step.load,
                variable: dp.variables()[v].clone(),
                groups,
                update: Vec::new(),
            });
        }
        self.pending = Some((step.load, next));
        Ok(())
    }

    fn after(&mut self, problem: &ShellProblem) {
        let Some((_, next)) = self.pending.take() else {
            return;
        };
        let dp = &self.dual;
        let model = &problem.model;
        let nl = model.thickness_rule.len();
        let first = self.out.len() - next.len();
        for (v, (c, g)) in next.iter().zip(dp.groups()).enumerate() {
            let mut acc: Vec<FieldAcc> = [
                "stress",
                "back_stress",
                "eps_p",
                "frame",
                "particle.u",
                "particle.d",
                "particle.e",
            ]
            .into_iter()
            .map(FieldAcc::new)
            .collect();
            for (i, (hc, hd)) in c.history.iter().zip(&g.history).enumerate() {
                let at = (i / nl, Some(i % nl));
                let uv = model.points[i / nl].uv;
                let hd = history_parts(hd);
                for k in 0..5 {
                    acc[0].add(hc.material.stress[k], hd.material.stress[k], at, uv);
                    acc[1].add(
                        hc.material.back_stress[k],
                        hd.material.back_stress[k],
                        at,
                        uv,
                    );
                }
                acc[2].add(hc.material.eps_p, hd.material.eps_p, at, uv);
                for (a, b) in hc.frame.iter().zip(hd.frame.iter()) {
                    acc[3].add(*a, *b, at, uv);
                }
            }
            for (i, (pc, pd)) in c.particles.iter().zip(&g.particles).enumerate() {
                let uv = model.particle_uv[i];
                for k in 0..3 {
                    acc[4].add(pc.u[k], pd.u[k].eps, (i, None), uv);
                    acc[5].add(pc.d[k], pd.d[k].eps, (i, None), uv);
                    acc[6].add(pc.e[0][k], pd.e[0][k].eps, (i, None), uv);
                    acc[6].add(pc.e[1][k], pd.e[1][k].eps, (i, None), uv);
                }
            }
            self.out[first + v].update = acc.into_iter().map(|a| a.0).collect();
        }
    }
}

impl StepObserver<ShellProblem> for Breakdown {
    fn converged_tangent(&self, problem: ConvergedTangent) -> ConvergedTangent {
        self.dual.converged_tangent(problem)
    }
    fn on_converged(
        &mut self,
        problem: &ShellProblem,
        step: &ConvergedStep<'_>,
    ) -> Result<(), ProblemError> {
        self.dual.on_converged(problem, step)?;
        if step.step == self.step {
            self.at_step(problem, step).map_err(fatal)?;
        }
        Ok(())
    }
    fn before_commit(&mut self, problem: &ShellProblem, u: &[f64], load: f64) {
        self.dual.before_commit(problem, u, load);
    }
    fn after_commit(&mut self, problem: &ShellProblem, u: &[f64], load: f64) {
        self.dual.after_commit(problem, u, load);
        self.after(problem);
    }
    fn on_restore(&mut self) {
        self.dual.on_restore();
        if self.pending.take().is_some() {
            self.out.retain(|b| b.step != self.step + 1);
        }
    }
    fn failure(&self) -> Option<Failure> {
        self.dual.failure()
    }
}

/// Run the analysis of `problem` (built on `surface`, needed by shape variables) with the dual reference (`Dual64`, one pass per variable) and
/// break the continuum fictitious load down by [`TermGroup`] at converged step `step`
/// (1-based), one [`TermBreakdown`] per variable.
pub fn breakdown(
    problem: ShellProblem,
    surface: Option<&Surface<f64>>,
    variables: Vec<DesignVariable>,
    newton: &NewtonSolver,
    solver: SolverOptions,
    step: usize,
) -> Result<Vec<TermBreakdown>, SensitivityError> {
    if step == 0 {
        return Err(SensitivityError::StepOutOfRange { step, steps: None });
    }
    let pattern = problem.pattern().clone();
    let mut linear = LinearSolver::new(&pattern, crate::solver::Method::auto(&pattern), solver)?;
    let dual = DualDsa::<Dual64>::new(&problem, surface, variables, Vec::new())?;
    let obs = Breakdown {
        dual,
        step: step - 1,
        pending: None,
        out: Vec::new(),
    };
    let mut p = Observed::new(problem, obs);
    let u0 = vec![0.0; p.n_dofs()];
    let report = newton
        .run(&mut p, &pattern, &mut linear, &u0)
        .map_err(SensitivityError::Newton)?;
    if p.observer.out.is_empty() {
        let steps = report.attempts.iter().filter(|a| a.converged).count();
        return Err(SensitivityError::StepOutOfRange {
            step,
            steps: Some(steps),
        });
    }
    Ok(p.observer.out)
}
