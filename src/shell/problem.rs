//! The shell as a [`NonlinearProblem`] for the Newton driver (docs/shell-formulation.md §6).
//!
//! Unknowns: the generalised DOFs `q` of the real particles (5 each, accumulated over the
//! steps; the model's increment within a step is `q − q_committed`), followed by one Lagrange
//! multiplier `μ_c` per constraint row ([`super::constraints`]). With the row scales `k_c`:
//!
//! ```text
//! r_q = f_int(q) − λ f_ext(q) + Σ_c k_c μ_c C_cᵀ        K = [ K_int − λ ∂f_ext/∂q   k Cᵀ ]
//! r_c = k_c (C_c q − λ g_c)                               [ k C                   0   ]
//! ```
//!
//! The scale `k_c` is a representative stiffness that makes the constraint residual force-like:
//! `E t` (membrane stiffness per unit length: force per displacement) for displacement rows and
//! `E t³/12` (bending stiffness: moment per rotation) for rotation rows. It leaves the solution
//! unchanged and keeps the residual norm and the LU pivoting balanced. The physical multiplier
//! is `k_c μ_c`; [`ShellProblem::reactions`] reports the force (or moment) the support exerts on
//! the shell, `−k_c μ_c`, so that `f_int = λ f_ext + Σ_c reaction_c C_cᵀ` at equilibrium.
//!
//! Coefficient modes that the RK field does not see ([`super::gauge`]: alternating patterns at
//! supports of 4 and 8 spacings between symmetry planes) get one zero-valued row each, after
//! the given rows; the field is unchanged and the bordered tangent regular.
//!
//! Symmetry conditions of particles on a plane ([`super::symmetry`]) are eliminated as fixed
//! generalised DOFs through [`NonlinearProblem::essential`] when possible (`α2`, and `ū·n_s`
//! when `n_s` is a coordinate axis), and become multiplier rows otherwise
//! ([`SymmetryTreatment`]). The rows are assembled by [`super::constraints::assemble`]: rows
//! that others (or the symmetry) already impose, such as a corner held by two edges, are
//! merged, so the multiplier block has full rank; a component held at two values is an error.
//!
//! The sparse pattern is built once from the quadrature points' cells (their neighbours'
//! source particles, through the image map), the constraint rows and the load-stiffness
//! entries of follower loads; the tangent is assembled straight into the pattern's value slots
//! by [`crate::solver::assemble`] (deterministic, parallel, memory bounded by its batches).
//! A follower load must report the same `(row, column)` entries for every state (values may be
//! zero): its entries at `q = 0` enter the pattern.

use super::constraints::{assemble, LinearConstraint, MergedRow, RowKind, SymmetryRows};
use super::gauge::GaugeMode;
use super::load::{Load, LoadScaling};
use super::model::ShellModel;
use super::point::{PointHistory, DOFS_PER_PARTICLE};
use super::ShellError;
use crate::solver::{
    assemble_vector, assemble_with, AssemblyBuffers, AssemblyError, ConvergedTangent, Execution,
    NonlinearProblem, ProblemError, SparsityPattern,
};
use nalgebra::DVector;
use std::sync::OnceLock;

/// How the symmetry conditions of the particles on a plane are imposed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum SymmetryTreatment {
    /// `α2 = 0` (both rotations on two planes) eliminated as fixed generalised DOFs; `ū·n_s = 0`
    /// eliminated when `n_s` is a coordinate axis, a multiplier row otherwise.
    #[default]
    Eliminate,
    /// Every symmetry condition a multiplier row (for comparison).
    Multipliers,
}

/// Options of [`ShellProblem`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct ProblemOptions {
    /// Symmetry conditions.
    pub symmetry: SymmetryTreatment,
    /// Serial or parallel assembly (bit-identical results).
    pub execution: Execution,
}

type Histories = Vec<Vec<PointHistory<f64>>>;

/// The shell problem. A clone is an independent problem at the same committed state (the
/// continuum DSA's thread replays the analysis' commits on one).
#[derive(Clone, Debug)]
pub struct ShellProblem {
    /// The discrete shell (committed state).
    pub model: ShellModel,
    loads: Vec<Load>,
    constraints: Vec<LinearConstraint>,
    scales: Vec<f64>,
    fixed: Vec<usize>,
    pattern: SparsityPattern,
    /// Quadrature points of each point cell of the pattern (cells `0..groups.len()`).
    groups: Vec<Vec<usize>>,
    /// Per constraint row, per term: slots of `(row, dof)` and `(dof, row)`.
    constraint_slots: Vec<Vec<(usize, usize)>>,
    n_q: usize,
    committed: Vec<f64>,
    cache: Option<(Vec<f64>, Histories)>,
    load_norm: f64,
    /// `‖f_ext(q; λ)‖` of the prescribed loads at the last evaluation (their force scale).
    prescribed_norm: f64,
    execution: Execution,
    redundant: Vec<MergedRow>,
    /// Coefficient modes fixed by rows ([`super::gauge`]).
    gauge: Vec<GaugeMode>,
    /// Cell buffers of the tangent assembly, reused over the Newton iterations.
    buffers: AssemblyBuffers,
    /// A failure of [`NonlinearProblem::commit`] (updating a load from the committed state),
    /// reported by the next evaluation.
    commit_error: Option<String>,
}

/// A load's error: [`ShellError::StepTooLarge`] lets the driver cut the step, anything else
/// stops the run.
fn load_error(e: ShellError) -> ProblemError {
    match e {
        ShellError::StepTooLarge(m) => ProblemError::Recoverable(m),
        other => fatal(other),
    }
}

fn fatal<E: std::fmt::Display>(e: E) -> ProblemError {
    ProblemError::Fatal(e.to_string())
}

/// A point evaluation failure, naming the point.
#[derive(Debug)]
struct PointError {
    point: usize,
    uv: [f64; 2],
    source: ShellError,
}

impl std::fmt::Display for PointError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "quadrature point {} at (u, v) = {:?}: {}",
            self.point, self.uv, self.source
        )
    }
}

fn assembly_error(e: AssemblyError<PointError>) -> ProblemError {
    match e {
        // An inverted cell or a failed return map: a smaller step may succeed.
        AssemblyError::Cell { source, .. } => ProblemError::Recoverable(source.to_string()),
        other => fatal(other),
    }
}

impl ShellProblem {
    /// The problem with default options ([`SymmetryTreatment::Eliminate`], parallel assembly).
    pub fn new(
        model: ShellModel,
        loads: Vec<Load>,
        constraints: Vec<LinearConstraint>,
    ) -> Result<Self, ShellError> {
        Self::with_options(model, loads, constraints, ProblemOptions::default())
    }

    /// The problem: `loads` at load factor 1, `constraints` (rows on the generalised DOFs, in
    /// any overlap; the symmetry conditions of the model's planes are added here, and repeated
    /// rows merged: [`super::constraints::assemble`]).
    pub fn with_options(
        model: ShellModel,
        loads: Vec<Load>,
        constraints: Vec<LinearConstraint>,
        options: ProblemOptions,
    ) -> Result<Self, ShellError> {
        let n_q = model.n_dofs();
        let treatment = match options.symmetry {
            SymmetryTreatment::Eliminate => SymmetryRows::Eliminate,
            SymmetryTreatment::Multipliers => SymmetryRows::Rows,
        };
        // Coefficient modes the field does not see get one row each, after the given rows.
        let gauge = super::gauge::gauge_modes(&model);
        let mut constraints = constraints;
        constraints.extend(gauge.iter().map(|m| m.constraint()));
        let set = assemble(&model, constraints, treatment)?;
        let (rows, fixed, redundant) = (set.rows, set.fixed, set.merged);
        let (e, t) = (model.material.young, model.thickness);
        let scales: Vec<f64> = rows
            .iter()
            .map(|r| match r.kind {
                RowKind::Displacement => e * t,
                RowKind::Rotation => e * t * t * t / 12.0,
            })
            .collect();
        let n = n_q + rows.len();

        // Pattern: point cells, constraint cells, then any follower-load entries they miss.
        // Points with the same DOF list (the Gauss points of one background cell when the
        // supports end on cell lines, as on a regular grid) share a pattern cell: their
        // matrices are summed before the scatter, which cuts the slot map and the scatter by
        // the number of points per cell.
        let mut groups: Vec<Vec<usize>> = Vec::new();
        let mut cells: Vec<Vec<usize>> = Vec::new();
        let mut index: std::collections::HashMap<Vec<usize>, usize> =
            std::collections::HashMap::new();
        for k in 0..model.points.len() {
            let dofs = model.point_dofs(k);
            match index.get(&dofs) {
                Some(&g) => groups[g].push(k),
                None => {
                    index.insert(dofs.clone(), cells.len());
                    groups.push(vec![k]);
                    cells.push(dofs);
                }
            }
        }
        for (c, r) in rows.iter().enumerate() {
            let mut cell = vec![n_q + c];
            cell.extend(r.terms.iter().map(|t| t.0));
            cells.push(cell);
        }
        let pattern_error = |e: crate::solver::SolverError| ShellError::InvalidInput(e.to_string());
        let mut pattern = SparsityPattern::from_cells(n, &cells)
            .map_err(pattern_error)?
            .with_multipliers_from(n_q);
        let zeros = vec![0.0; n_q];
        let mut entries = Vec::new();
        for l in loads.iter().filter(|l| l.is_follower()) {
            // A prescribed load (a tool on its path) is probed at the start level 0.
            let level = match l.scaling() {
                LoadScaling::Proportional => 1.0,
                LoadScaling::Prescribed => 0.0,
            };
            l.add_stiffness(&model, &zeros, level, &mut entries)?;
        }
        let mut missing: Vec<Vec<usize>> = entries
            .iter()
            .filter(|&&(i, j, _)| pattern.slot(i, j).is_none())
            .map(|&(i, j, _)| vec![i, j])
            .collect();
        if !missing.is_empty() {
            missing.sort_unstable();
            missing.dedup();
            cells.extend(missing);
            pattern = SparsityPattern::from_cells(n, &cells)
                .map_err(pattern_error)?
                .with_multipliers_from(n_q);
        }
        let constraint_slots = rows
            .iter()
            .enumerate()
            .map(|(c, r)| {
                r.terms
                    .iter()
                    .map(|&(d, _)| {
                        let s1 = pattern.slot(n_q + c, d);
                        let s2 = pattern.slot(d, n_q + c);
                        s1.zip(s2).ok_or_else(|| {
                            ShellError::InvalidInput(format!(
                                "constraint `{}`: DOF {d} missing from the pattern",
                                r.label
                            ))
                        })
                    })
                    .collect::<Result<Vec<_>, _>>()
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut f = vec![0.0; n_q];
        for l in loads
            .iter()
            .filter(|l| l.scaling() == LoadScaling::Proportional)
        {
            l.add_force(&model, &zeros, 1.0, &mut f)?;
        }
        let load_norm = (f.iter().map(|v| v * v).sum::<f64>()
            + rows
                .iter()
                .zip(&scales)
                .map(|(r, k)| (k * r.value).powi(2))
                .sum::<f64>())
        .sqrt();
        Ok(ShellProblem {
            model,
            loads,
            constraints: rows,
            scales,
            fixed,
            pattern,
            groups,
            constraint_slots,
            n_q,
            committed: vec![0.0; n],
            cache: None,
            load_norm,
            prescribed_norm: 0.0,
            execution: options.execution,
            redundant,
            gauge,
            buffers: AssemblyBuffers::new(),
            commit_error: None,
        })
    }

    /// The rows left out because others or the symmetry planes already impose them, with what
    /// imposes each (e.g. a corner particle's rows repeated by the two edges meeting there, or
    /// a diaphragm's component along a symmetry plane's normal at the corner where they meet).
    pub fn redundant_constraints(&self) -> &[MergedRow] {
        &self.redundant
    }

    /// The coefficient modes that the RK field does not see, each held by a constraint row
    /// ([`super::gauge`]); empty for most models.
    pub fn gauge_modes(&self) -> &[GaugeMode] {
        &self.gauge
    }

    /// What unknown `dof` is, for messages: a generalised DOF of a particle (its index,
    /// parameter coordinates and component), or the multiplier of a constraint row (its label).
    pub fn describe_dof(&self, dof: usize) -> String {
        const NAMES: [&str; DOFS_PER_PARTICLE] = ["ū_x", "ū_y", "ū_z", "α1", "α2"];
        if dof < self.n_q {
            let (i, c) = (dof / DOFS_PER_PARTICLE, dof % DOFS_PER_PARTICLE);
            let fixed = if self.fixed.binary_search(&dof).is_ok() {
                ", eliminated by symmetry"
            } else {
                ""
            };
            format!(
                "particle {i} at (u, v) = {:?}, component {}{fixed}",
                self.model.particle_uv[i], NAMES[c]
            )
        } else if let Some(row) = self.constraints.get(dof - self.n_q) {
            format!("the multiplier of constraint `{}`", row.label)
        } else {
            format!("unknown {dof} (beyond the {} unknowns)", self.n_dofs())
        }
    }

    /// The sparse pattern of the tangent (give it to the driver and its solver).
    pub fn pattern(&self) -> &SparsityPattern {
        &self.pattern
    }

    /// Number of generalised DOFs (5 per real particle).
    pub fn n_generalised(&self) -> usize {
        self.n_q
    }

    /// A smooth deformed state that is not an equilibrium, for benchmarks and probes of the
    /// tangent: generalised DOF `j` is `10⁻³ sin(0.37 j)` (displacements and rotations of the
    /// strain level of the paper's runs), the multipliers zero. The tangent there has generic
    /// values, with no symmetry an equilibrium path would give it.
    pub fn generic_state(&self) -> Vec<f64> {
        (0..self.n_dofs())
            .map(|j| {
                if j < self.n_q {
                    1e-3 * ((j as f64) * 0.37).sin()
                } else {
                    0.0
                }
            })
            .collect()
    }

    /// The constraint rows (user rows after the symmetry rows), in multiplier order.
    pub fn constraints(&self) -> &[LinearConstraint] {
        &self.constraints
    }

    /// The constraint rows' part of the residual at the unknowns `u` (generalised displacements
    /// then one multiplier `μ_c` per row) and load factor `load`, over any scalar: each row
    /// `g_c = Σ a u_d − λ ḡ_c` (scaled by `k_c`) adds `k_c a μ_c` to the residual of each of its
    /// DOFs `d` and sets its own entry `r[n_q + c] = k_c g_c`. The analysis evaluates it in f64,
    /// the dual reference with the unknowns' design sensitivities.
    pub fn add_constraint_rows<T: crate::scalar::Real>(&self, u: &[T], load: f64, r: &mut [T]) {
        let n_q = self.n_q;
        for (c, (row, &k)) in self.constraints.iter().zip(&self.scales).enumerate() {
            let mu = u[n_q + c];
            let mut g = T::cst(-load * row.value);
            for &(d, a) in &row.terms {
                r[d] += mu * (k * a);
                g += u[d] * a;
            }
            r[n_q + c] = g * k;
        }
    }

    /// The row scales `k_c` (`E t` or `E t³/12`).
    pub fn constraint_scales(&self) -> &[f64] {
        &self.scales
    }

    /// Generalised DOFs eliminated as symmetry conditions (held at zero).
    pub fn fixed_dofs(&self) -> &[usize] {
        &self.fixed
    }

    /// The committed unknowns `[q, μ]`: the initial vector of a further driver run.
    pub fn state(&self) -> &[f64] {
        &self.committed
    }

    /// The converged generalised DOFs `q` (accumulated over the steps).
    pub fn generalised_dofs(&self) -> &[f64] {
        &self.committed[..self.n_q]
    }

    /// The converged (scaled) multipliers `μ`.
    pub fn multipliers(&self) -> &[f64] {
        &self.committed[self.n_q..]
    }

    /// The reactions: for each constraint row, the generalised force (displacement rows) or
    /// moment (rotation rows) the support exerts on the shell, `−k_c μ_c`.
    pub fn reactions(&self) -> Vec<f64> {
        self.multipliers()
            .iter()
            .zip(&self.scales)
            .map(|(m, k)| -m * k)
            .collect()
    }

    /// The external loads, in the order given.
    pub fn loads(&self) -> &[Load] {
        &self.loads
    }

    /// The external generalised force `λ f_ext(q)` for the increment `q` from the committed
    /// state (length [`Self::n_generalised`]).
    pub fn external_force(&self, q: &[f64], load: f64) -> Result<Vec<f64>, ShellError> {
        let mut f = vec![0.0; self.n_q];
        for l in &self.loads {
            l.add_force(&self.model, q, load, &mut f)?;
        }
        Ok(f)
    }

    /// Residual (and tangent into `values` when given) at the unknowns `u`; caches the trial
    /// histories for [`NonlinearProblem::commit`].
    fn evaluate(
        &mut self,
        u: &[f64],
        load: f64,
        r: &mut [f64],
        values: Option<&mut [f64]>,
    ) -> Result<(), ProblemError> {
        if let Some(e) = &self.commit_error {
            return Err(fatal(format!("after the last committed step: {e}")));
        }
        let n = self.pattern.n_dofs();
        if u.len() != n || r.len() != n {
            return Err(fatal(format!(
                "unknowns of length {} and residual of length {}: expected {n}",
                u.len(),
                r.len()
            )));
        }
        let n_q = self.n_q;
        let q: Vec<f64> = u[..n_q]
            .iter()
            .zip(&self.committed)
            .map(|(a, b)| a - b)
            .collect();
        let model = &self.model;
        let pattern = &self.pattern;
        let np = model.points.len();
        let groups = &self.groups;
        let hist: Vec<OnceLock<Vec<PointHistory<f64>>>> =
            (0..np).map(|_| OnceLock::new()).collect();
        let point_error = |k: usize, e: ShellError| PointError {
            point: k,
            uv: model.points[k].uv,
            source: e,
        };
        let cache = model
            .particle_cache(&q, values.is_some())
            .map_err(|e| fatal(format!("particle data: {e}")))?;
        let cache = &cache;
        // The points of cell `c` in a fixed order (deterministic sums) into its arrays.
        let cell = |c: usize, kc: Option<&mut [f64]>, fc: &mut [f64]| -> Result<(), PointError> {
            let Some(group) = groups.get(c) else {
                // Constraint and load cells: structure only, values added below.
                return Ok(());
            };
            let mut kc = kc;
            for &k in group {
                let (h, _) = model
                    .add_to_cell_cached(k, &q, Some(cache), fc, kc.as_deref_mut())
                    .map_err(|e| point_error(k, e))?;
                // Each point is evaluated once per assembly.
                let _ = hist[k].set(h);
            }
            Ok(())
        };
        match values {
            Some(vals) => {
                assemble_with(
                    pattern,
                    vals,
                    r,
                    self.execution,
                    &mut self.buffers,
                    |c, kc, fc| cell(c, Some(kc), fc),
                )
                .map_err(assembly_error)?;
                for ((row, slots), &k) in self
                    .constraints
                    .iter()
                    .zip(&self.constraint_slots)
                    .zip(&self.scales)
                {
                    for (&(_, a), &(s1, s2)) in row.terms.iter().zip(slots) {
                        vals[s1] += k * a;
                        vals[s2] += k * a;
                    }
                }
                let mut trip = Vec::new();
                for l in self.loads.iter().filter(|l| l.is_follower()) {
                    match l.scaling() {
                        LoadScaling::Proportional => {
                            l.add_stiffness(model, &q, -load, &mut trip)
                                .map_err(load_error)?;
                        }
                        LoadScaling::Prescribed => {
                            let from = trip.len();
                            l.add_stiffness(model, &q, load, &mut trip)
                                .map_err(load_error)?;
                            for e in &mut trip[from..] {
                                e.2 = -e.2;
                            }
                        }
                    }
                }
                for (i, j, v) in trip {
                    let s = pattern.slot(i, j).ok_or_else(|| {
                        fatal(format!(
                            "load stiffness entry ({i}, {j}) is not in the pattern: a follower \
                             load must report the same entries for every state"
                        ))
                    })?;
                    vals[s] += v;
                }
            }
            None => {
                assemble_vector(pattern, r, self.execution, |c| {
                    let mut f = DVector::zeros(pattern.cell_dofs(c).len());
                    cell(c, None, f.as_mut_slice()).map(|()| f)
                })
                .map_err(assembly_error)?;
            }
        }
        let histories = hist
            .into_iter()
            .map(|h| h.into_inner())
            .collect::<Option<Histories>>()
            .ok_or_else(|| fatal("a quadrature point was not evaluated"))?;
        let mut prescribed = Vec::new();
        for l in &self.loads {
            match l.scaling() {
                LoadScaling::Proportional => l
                    .add_force(model, &q, -load, &mut r[..n_q])
                    .map_err(load_error)?,
                LoadScaling::Prescribed => {
                    prescribed.resize(n_q, 0.0);
                    l.add_force(model, &q, load, &mut prescribed)
                        .map_err(load_error)?;
                }
            }
        }
        for (ri, f) in r.iter_mut().zip(&prescribed) {
            *ri -= f;
        }
        self.prescribed_norm = prescribed.iter().map(|v| v * v).sum::<f64>().sqrt();
        self.add_constraint_rows(u, load, r);
        self.cache = Some((u.to_vec(), histories));
        Ok(())
    }
}

impl NonlinearProblem for ShellProblem {
    fn n_dofs(&self) -> usize {
        self.pattern.n_dofs()
    }
    fn residual(&mut self, u: &[f64], load: f64, r: &mut [f64]) -> Result<(), ProblemError> {
        self.evaluate(u, load, r, None)
    }
    fn tangent(&mut self, u: &[f64], load: f64, values: &mut [f64]) -> Result<(), ProblemError> {
        let mut r = vec![0.0; self.pattern.n_dofs()];
        self.evaluate(u, load, &mut r, Some(values))
    }
    fn residual_and_tangent(
        &mut self,
        u: &[f64],
        load: f64,
        r: &mut [f64],
        values: &mut [f64],
    ) -> Result<(), ProblemError> {
        self.evaluate(u, load, r, Some(values))
    }
    fn essential(&self, _load: f64) -> Vec<(usize, f64)> {
        self.fixed.iter().map(|&d| (d, 0.0)).collect()
    }
    /// `∂r/∂λ`: `−f_ext(q)` of the proportional loads (linear in λ, followers included),
    /// `−k_c g_c` on the constraint rows, and the central difference in λ (step
    /// `1e-6 max(1, |λ|)`) of the prescribed loads' `−f(q; λ)` (zero for constant loads).
    fn load_derivative(
        &mut self,
        u: &[f64],
        load: f64,
        out: &mut [f64],
    ) -> Result<bool, ProblemError> {
        let n_q = self.n_q;
        let q: Vec<f64> = u[..n_q]
            .iter()
            .zip(&self.committed)
            .map(|(a, b)| a - b)
            .collect();
        out.fill(0.0);
        let h = 1e-6 * load.abs().max(1.0);
        for l in &self.loads {
            match l.scaling() {
                LoadScaling::Proportional => l
                    .add_force(&self.model, &q, -1.0, &mut out[..n_q])
                    .map_err(load_error)?,
                LoadScaling::Prescribed => {
                    let mut minus = vec![0.0; n_q];
                    let mut plus = vec![0.0; n_q];
                    l.add_force(&self.model, &q, load - h, &mut minus)
                        .map_err(load_error)?;
                    l.add_force(&self.model, &q, load + h, &mut plus)
                        .map_err(load_error)?;
                    for ((o, m), p) in out[..n_q].iter_mut().zip(&minus).zip(&plus) {
                        *o += (m - p) / (2.0 * h);
                    }
                }
            }
        }
        for (c, (row, &k)) in self.constraints.iter().zip(&self.scales).enumerate() {
            out[n_q + c] = -k * row.value;
        }
        Ok(true)
    }
    /// The arc length measures the generalised DOFs (not the multipliers).
    fn path_dofs(&self) -> usize {
        self.n_q
    }
    fn describe_unknown(&self, dof: usize) -> Option<String> {
        Some(self.describe_dof(dof))
    }
    /// The contacts' count of slave points that changed the tool they penetrate (or started
    /// or stopped penetrating) between tracked evaluations ([`crate::shell::contact::ShellContact::active_set_changes`]).
    fn active_set_changes(&self) -> u64 {
        self.loads
            .iter()
            .filter_map(|l| l.contact())
            .map(|c| c.contact.active_set_changes())
            .sum()
    }
    fn force_norm(&self, load: f64) -> f64 {
        // The prescribed loads' force (contact) at the last evaluation: at the driver's first
        // evaluation of a step, the predicted state.
        load.abs() * self.load_norm + self.prescribed_norm
    }
    /// The analysis has no convergence hook: residual-first acceptance is allowed (a design
    /// sensitivity wrapper that solves with the converged tangent declares `Required`).
    fn converged_tangent(&self) -> ConvergedTangent {
        ConvergedTangent::NotNeeded
    }
    fn commit(&mut self, u: &[f64], load: f64) {
        let cached = matches!(&self.cache, Some((uc, _)) if uc == u);
        if !cached {
            let mut r = vec![0.0; self.pattern.n_dofs()];
            if self.evaluate(u, load, &mut r, None).is_err() {
                return; // unreachable for a state the driver evaluated
            }
        }
        let Some((_, histories)) = self.cache.take() else {
            return;
        };
        let q: Vec<f64> = u[..self.n_q]
            .iter()
            .zip(&self.committed)
            .map(|(a, b)| a - b)
            .collect();
        self.model.commit_histories(&q, histories);
        self.committed = u.to_vec();
        // The per-particle strength of the director filter follows the committed state (a
        // state the driver has just evaluated: its points evaluate again at zero increment).
        for l in &mut self.loads {
            if let Load::DirectorFilter(f) = l {
                if let Err(e) = f.update(&self.model) {
                    self.commit_error = Some(e.to_string());
                }
            }
        }
    }
    fn restore(&mut self) {
        self.cache = None;
    }
}
