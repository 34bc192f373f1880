//! The results of `shelldsa dsa` written out: the table of each design variable in the format
//! of the paper's Tables 1–2, `sensitivity.json` (`docs/sensitivity.md`), the term breakdown
//! (`terms.json`) and the VTU files of the run with the derivative methods ([`StepVtu`]).

use super::shell_build;
use super::shell_case::ShellCase;
use super::shell_output::{
    add_sensitivity_fields, shell_vtu_with_contact, OutputError, OutputGrid, SensitivityField,
    PVD_FILE,
};
use super::vtu::PvdCollection;
use crate::sensitivity::study::{
    continuum_vs_dual, max_rel_diff, DsaResult, DsaSpec, StepWriter, VariableResult, VtuStep,
};
use crate::sensitivity::terms::TermBreakdown;
use crate::sensitivity::{Quantity, SensitivityFields};
use crate::shell::contact::ShellContact;
use crate::shell::model::ShellModel;
use crate::solver::Failure;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The VTU files of the run that carries the derivative methods, in the plain run's layout
/// (`[output] vtu`, `every`, `subdivide`; `shell.pvd` and `steps/step_NNNN.vtu`, step 0 the
/// initial state, every `every`-th converged step and the one reaching `final_load`): every
/// array of the plain run's VTU ([`shell_vtu_with_contact`]) and, per design variable and
/// method, the sensitivity fields of [`add_sensitivity_fields`], named
/// `d_u/d_<variable> (<method>)` and `d_eps_p_<top|mid|bottom>/d_<variable> (<method>)`.
pub struct StepVtu<'a> {
    dir: PathBuf,
    case: &'a ShellCase,
    grid: Option<OutputGrid>,
    contact: Option<Arc<ShellContact>>,
    variables: Vec<String>,
    pvd: PvdCollection,
    time: Duration,
    written: Vec<VtuStep>,
    error: Option<Failure>,
}

impl<'a> StepVtu<'a> {
    /// The writer into `dir` for `case`'s output grid (opened by the study with the hooked
    /// run's contact and the names of its design variables, [`StepWriter::open`]).
    pub fn new(dir: &Path, case: &'a ShellCase) -> Self {
        StepVtu {
            dir: dir.to_owned(),
            case,
            grid: None,
            contact: None,
            variables: Vec::new(),
            pvd: PvdCollection::new(dir.join(PVD_FILE)),
            time: Duration::ZERO,
            written: Vec::new(),
            error: None,
        }
    }
}

impl StepWriter for StepVtu<'_> {
    /// The case's output grid; `contact` gives the contact pressure.
    fn open(
        &mut self,
        contact: Option<Arc<ShellContact>>,
        variables: Vec<String>,
    ) -> Result<(), Failure> {
        let case = self.case;
        let cq = shell_build::particle_grid(case);
        let cq = shell_build::cell_quadrature(case, &cq)
            .map_err(|e| Failure::new("the VTU files' grid", e))?;
        let grid = OutputGrid::new(&cq, case.output.subdivide)
            .map_err(|e| Failure::new("the VTU files' grid", e))?;
        let steps = self.dir.join("steps");
        super::shell_output::fresh_steps_dir(&steps).map_err(|e| {
            Failure::new(
                format!(
                    "cannot create or clear the step files of {}",
                    steps.display()
                ),
                e,
            )
        })?;
        self.grid = Some(grid);
        self.contact = contact;
        self.variables = variables;
        Ok(())
    }

    /// Every `every`-th converged step and the one reaching `final_load` (as the plain run).
    fn due(&self, step: usize, load: f64) -> bool {
        let s = &self.case.steps;
        let last = (s.final_load - load).abs() <= 1e-12 * s.final_load.abs().max(1.0);
        self.error.is_none() && (step % self.case.output.every == 0 || last)
    }

    fn write(
        &mut self,
        step: usize,
        load: f64,
        model: &ShellModel,
        methods: &[(&str, Option<&dyn SensitivityFields>)],
    ) {
        if self.error.is_some() {
            return;
        }
        let t = Instant::now();
        if let Err(e) = self.write_files(step, load, model, methods) {
            self.error = Some(e);
        }
        self.time += t.elapsed();
    }

    fn time(&self) -> Duration {
        self.time
    }

    fn error(&self) -> Option<&Failure> {
        self.error.as_ref()
    }

    fn written(&self) -> &[VtuStep] {
        &self.written
    }
}

impl StepVtu<'_> {
    fn write_files(
        &mut self,
        step: usize,
        load: f64,
        model: &ShellModel,
        methods: &[(&str, Option<&dyn SensitivityFields>)],
    ) -> Result<(), Failure> {
        let pressure = match &self.contact {
            Some(c) => Some(
                c.report(model, &vec![0.0; model.n_dofs()], load)
                    .map_err(|e| Failure::new(format!("contact at step {step}"), e))?
                    .pressure,
            ),
            None => None,
        };
        let n_layer_points = model.points.len() * model.thickness_rule.len();
        let mut fields = Vec::new();
        for (method, f) in methods {
            for (v, name) in self.variables.iter().enumerate() {
                let (translations, plastic_strain) = match f {
                    Some(f) => (f.translations(model, v), f.plastic_strain(v)),
                    None => (vec![0.0; model.n_dofs()], vec![0.0; n_layer_points]),
                };
                fields.push(SensitivityField {
                    label: format!("{name} ({method})"),
                    translations,
                    plastic_strain,
                });
            }
        }
        let rel = format!("steps/step_{step:04}.vtu");
        let path = self.dir.join(&rel);
        type Error = Box<dyn std::error::Error + Send + Sync>;
        let in_file = |e: Error| Failure::new(path.display().to_string(), e);
        let grid =
            (self.grid.as_ref()).ok_or_else(|| in_file("the writer was not opened".into()))?;
        let w = shell_vtu_with_contact(model, &self.case.surface, grid, pressure.as_deref())
            .and_then(|w| add_sensitivity_fields(w, model, grid, &fields))
            .map_err(|e| in_file(e.into()))?;
        w.write(&path).map_err(|e| in_file(e.into()))?;
        self.pvd
            .add_and_write(load, &rel)
            .map_err(|e| Failure::new(PVD_FILE, e))?;
        self.written.push(VtuStep {
            step,
            load,
            file: rel,
        });
        Ok(())
    }
}

/// A number for JSON: `null` when not finite (JSON has no NaN).
fn num(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

/// `sensitivity.json` before any analysis (`status` `"running"`, no steps yet) or after a plain
/// analysis that failed (`status` `"failed: ..."`).
pub fn empty_json(case: &ShellCase, spec: &DsaSpec, status: &str) -> Value {
    json!({
        "kind": "shell-dsa",
        "case": case.path.display().to_string(),
        "title": case.title,
        "status": status,
        "failures": [],
        "methods": spec.methods.iter().map(|m| m.name()).collect::<Vec<_>>(),
        "design_variables": spec.design.iter().map(|d| d.variable.name.clone()).collect::<Vec<_>>(),
        "variables": [],
        "loads": [],
    })
}

/// Write `doc` as `DIR/sensitivity.json` (pretty, replaced whole: a reader or a killed run
/// sees the previous or the new file).
pub fn write_json(path: &std::path::Path, doc: &Value) -> Result<(), OutputError> {
    let text = serde_json::to_string_pretty(doc).map_err(|source| OutputError::Document {
        path: path.to_path_buf(),
        source,
    })?;
    super::vtu::replace_file(path, text.as_bytes()).map_err(|source| OutputError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// The notes written at the top of `sensitivity.json`.
pub const NOTES: [&str; 6] = [
    "continuum: the hand-derived continuum DSA (eqs 37-65: fictitious loads solved with the \
     converged, factorised tangent at every step); dual: the dual-number reference through \
     the same kernels; continuum_vs_dual: per variable, the largest |continuum - dual| \
     relative to max |dual| over the steps and monitors",
    "timing_s.analysis: wall time of a separate plain run of the analysis (no sensitivity \
     hook), the nominal run of the finite differences; timing_s.continuum and timing_s.dual: \
     each method's own time inside its analysis run with the hook (the whole hooked runs: \
     continuum_run_total_s, dual_run_total_s; with both methods asked for, one run observed \
     by both, so the two totals are the same run's); timing_s.continuum_stages: the continuum DSA by stage (fictitious loads, solve, history update, monitors; s), with the preconditioned iterations (GMRES's Arnoldi steps) of its solves on the converged tangents (krylov_iterations) and the steps where GMRES gave up and the DSA factorised the tangent (krylov_fallbacks); timing_s.fd: all finite-difference re-runs",
    "fd_central and fd_step are lists, one entry per step size of the variable's fd_steps \
     (relative steps h/|tau|; fd_step holds the absolute h); fd_flagged[k] marks load steps \
     where the yield status of some layer point differs among the runs at tau-h, tau, tau+h \
     (at that step or an earlier one): such differences straddle a kink and are not \
     comparable",
    "taylor: per load step, the least-squares slope of log |psi(tau+h) - psi(tau) - h psi'| \
     (max over the monitors; psi' the continuum derivative when it ran, else the dual one) \
     against log h over the unflagged step sizes; 2 when psi' is the derivative of the \
     discrete response",
    "cost_per_variable: fractions of the plain analysis' wall time per design variable; \
     continuum_own and dual_own: each method's own time in the hooked run; hooked_over_plain: \
     (hooked run - plain run) / plain run / variables, everything the methods add including \
     the tangents at converged states (with both methods, one run carries both)",
    "vtu: the files of the run with the derivative methods (the plain run's VTU layout and \
     arrays, plus point data uv, d_u/d_<variable> (<method>) = sum_J Psi_J du_J/dtau at the \
     node, the derivative a displacement monitor there records, and cell data \
     d_eps_p_<top|mid|bottom>/d_<variable> (<method>), the cell means of the layer points' \
     deps_p/dtau with the nominal weights); timing_s.vtu: writing them, left out of the \
     hooked run totals",
];

/// `sensitivity.json`. Everything but `timing_s` and `dual_run_total_s` is a deterministic
/// function of the case. `status` is `"running"` while the methods run (the file is rewritten
/// after each), then `"complete"`, or `"incomplete"` when some method or re-run failed
/// (`failures` names each: method, variable, h, error).
pub fn to_json(case: &ShellCase, r: &DsaResult, status: &str) -> Value {
    let monitors: Vec<Value> = r
        .spec
        .monitors
        .iter()
        .map(|m| match &m.quantity {
            Quantity::Displacement { uv, component } => {
                json!({"label": m.label, "quantity": "displacement", "uv": uv, "component": component})
            }
            Quantity::ToolForce { tool, component } => {
                json!({"label": m.label, "quantity": "tool-force", "tool": tool, "component": component})
            }
            Quantity::ChordAngle { points, plane, .. } => {
                json!({"label": m.label, "quantity": "chord-angle", "points": points, "plane": plane})
            }
            Quantity::TargetDistance {
                points, targets, ..
            } => {
                json!({"label": m.label, "quantity": "target-distance", "points": points, "targets": targets})
            }
            Quantity::PlasticStrain {
                region,
                layers,
                rho,
            } => {
                json!({"label": m.label, "quantity": "plastic-strain", "region": region,
                       "layers": format!("{layers:?}").to_lowercase(), "rho": rho})
            }
            Quantity::Thinning { region, rho } => {
                json!({"label": m.label, "quantity": "thinning-strain", "region": region, "rho": rho})
            }
        })
        .collect();
    let variables: Vec<Value> = r
        .variables
        .iter()
        .map(|v| {
            let steps: Vec<Value> = (0..r.nominal.loads.len())
                .map(|s| {
                    let mut comps = serde_json::Map::new();
                    for (m, mon) in r.spec.monitors.iter().enumerate() {
                        comps.insert(
                            mon.label.clone(),
                            json!({
                                "value": num(r.nominal.values[s][m]),
                                "continuum": v.continuum.as_ref().and_then(|d| d.get(s)).map_or(Value::Null, |d| num(d[m])),
                                "dual": v.dual.as_ref().and_then(|d| d.get(s)).map_or(Value::Null, |d| num(d[m])),
                                "fd_central": v.fd.iter().map(|c| num(c.derivatives[s][m])).collect::<Vec<_>>(),
                                "fd_step": v.fd.iter().map(|c| num(c.h)).collect::<Vec<_>>(),
                            }),
                        );
                    }
                    json!({
                        "step": s + 1,
                        "load": r.nominal.loads[s],
                        "plastic_points": r.nominal.yielding[s].iter().filter(|y| **y).count(),
                        "fd_flagged": v.fd.iter().map(|c| c.flagged[s]).collect::<Vec<_>>(),
                        "taylor_remainder": v.fd.iter().map(|c| c.taylor.as_ref().and_then(|t| t.remainder.get(s)).map_or(Value::Null, |t| num(*t))).collect::<Vec<_>>(),
                        "monitors": comps,
                    })
                })
                .collect();
            let fits: Vec<Value> = v
                .taylor
                .iter()
                .map(|f| {
                    json!({
                        "step": f.step + 1,
                        "rate": f.rate.map_or(Value::Null, num),
                        "used_h": f.used,
                        "excluded_h_active_set": f.excluded,
                        "exact_h": f.exact,
                        "roundoff_h": f.roundoff,
                    })
                })
                .collect();
            let rates: Vec<f64> = v.taylor.iter().filter_map(|f| f.rate).collect();
            json!({
                "name": v.entry.variable.name,
                "kind": v.entry.variable.kind.key(),
                "value": v.value,
                "fd_steps_relative": v.entry.fd_steps,
                "fd_steps": v.fd.iter().map(|c| c.h).collect::<Vec<_>>(),
                "flagged_steps": flagged_steps(v),
                "continuum_vs_dual": continuum_vs_dual(v).map_or(Value::Null, num),
                "taylor": {
                    "rate_min": rates.iter().copied().reduce(f64::min),
                    "rate_max": rates.iter().copied().reduce(f64::max),
                    "per_step": fits,
                },
                "steps": steps,
            })
        })
        .collect();
    let failures: Vec<Value> = r
        .failures
        .iter()
        .map(|f| {
            json!({
                "method": f.method,
                "variable": f.variable,
                "h": f.h,
                "fd_step_relative": f.relative,
                "error": f.message,
            })
        })
        .collect();
    json!({
        "kind": "shell-dsa",
        "case": case.path.display().to_string(),
        "title": case.title,
        "status": status,
        "failures": failures,
        "notes": NOTES,
        "methods": r.spec.methods.iter().map(|m| m.name()).collect::<Vec<_>>(),
        "monitors": monitors,
        "loads": r.nominal.loads,
        "dual_value_difference": r.dual_value_difference.map_or(Value::Null, num),
        "dual_state_mismatch": r.dual_state_mismatch.map_or(Value::Null, num),
        "continuum_value_difference": r.continuum_value_difference.map_or(Value::Null, num),
        "timing_s": {
            "analysis": r.time_analysis,
            "continuum": r.time_continuum,
            "dual": r.time_dual,
            "fd": r.time_fd,
            "vtu": r.time_vtu,
            "continuum_stages": r.continuum_stages.map_or(Value::Null, |t| json!({
                "rhs": t.rhs,
                "solve": t.solve,
                "update": t.update,
                "record": t.record,
                "krylov_iterations": t.krylov_iterations,
                "krylov_fallbacks": t.krylov_fallbacks,
            })),
        },
        "cost_per_variable": {
            "continuum_own": r.cost().continuum_own.map_or(Value::Null, num),
            "dual_own": r.cost().dual_own.map_or(Value::Null, num),
            "hooked_over_plain": r.cost().hooked_over_plain.map_or(Value::Null, num),
        },
        "dual_run_total_s": r.time_dual_run,
        "continuum_run_total_s": r.time_continuum_run,
        "vtu": {
            "collection": (!r.vtu.is_empty()).then_some(super::shell_output::PVD_FILE),
            "steps": r.vtu.iter().map(|v| json!({"step": v.step, "load": v.load, "file": v.file})).collect::<Vec<_>>(),
            "error": r.vtu_error,
        },
        "variables": variables,
    })
}

/// Per step size, the 1-based load steps flagged by the active-set test.
fn flagged_steps(v: &VariableResult) -> Vec<Value> {
    v.fd
        .iter()
        .map(|c| {
            json!({
                "fd_step_relative": c.relative,
                "steps": c.flagged.iter().enumerate().filter(|(_, f)| **f).map(|(s, _)| s + 1).collect::<Vec<_>>(),
            })
        })
        .collect()
}

fn cell(v: Option<f64>) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:>13.5e}"),
        _ => format!("{:>13}", "—"),
    }
}

/// The table of one design variable in the format of the paper's Tables 1–2, at its first
/// step size `h` (`Δτ`): per load step and monitor component ψ, `Δψ = (ψ(τ+h) − ψ(τ−h))/2`
/// (central differences), `ψ'Δτ` per method, and `Δψ / ψ'Δτ × 100` (finite differences
/// against the continuum derivative when it ran, else the dual one: the paper's ratio).
/// `*` marks a step flagged by the active-set test.
pub fn table(r: &DsaResult, v: usize) -> String {
    let var = &r.variables[v];
    let col = var.fd.first();
    let mut s = format!(
        "design variable `{}` ({}), τ = {:e}{}\n",
        var.entry.variable.name,
        var.entry.variable.kind.key(),
        var.value,
        col.map_or(String::from(", no finite differences"), |c| {
            if var.entry.variable.kind.is_offset() {
                // τ is the tool's offset or rotation (0): fd_steps are absolute.
                format!(", Δτ = {:e} (absolute: τ is the tool's offset)", c.h)
            } else {
                format!(", Δτ = {:e} (h/|τ| = {:e})", c.h, c.relative)
            }
        })
    );
    let (dual_head, cont_head) = if col.is_some() {
        ("ψ'Δτ dual", "ψ'Δτ cont.")
    } else {
        ("ψ' dual", "ψ' cont.")
    };
    s.push_str(&format!(
        "{:>4} {:>11} {:<10} {:>13} {:>13} {:>13} {:>13} {:>10}\n",
        "step", "λ", "monitor", "ψ", "Δψ (FD)", dual_head, cont_head, "ratio×100"
    ));
    for st in 0..r.nominal.loads.len() {
        let flag = col.is_some_and(|c| c.flagged[st]);
        for (m, mon) in r.spec.monitors.iter().enumerate() {
            let fd = col.map(|c| c.derivatives[st][m] * c.h);
            let scaled = |d: &Vec<Vec<f64>>| {
                let g = d.get(st)?[m];
                col.map(|c| g * c.h).or(Some(g))
            };
            let dual = var.dual.as_ref().and_then(scaled);
            let cont = var.continuum.as_ref().and_then(scaled);
            let ratio = match (fd, cont.or(dual)) {
                (Some(a), Some(b)) if b != 0.0 => format!("{:>10.4}", 100.0 * a / b),
                (Some(0.0), Some(_)) => format!("{:>10}", "0 = 0"),
                _ => format!("{:>10}", "—"),
            };
            s.push_str(&format!(
                "{:>4} {:>11} {:<10} {} {} {} {} {}{}\n",
                st + 1,
                super::plot::plain_tick(r.nominal.loads[st]),
                mon.label,
                cell(Some(r.nominal.values[st][m])),
                cell(fd),
                cell(dual),
                cell(cont),
                ratio,
                if flag { " *" } else { "" }
            ));
        }
    }
    for c in &var.fd {
        s.push_str(&format!(
            "h/|τ| = {:e}: max |Δψ/ψ'Δτ − 1| over unflagged components with |ψ'| ≥ 1e-6 max|ψ'|: {}\n",
            c.relative,
            max_rel_diff(var, c).map_or("—".into(), |e| format!("{e:.3e}"))
        ));
    }
    if let Some(e) = continuum_vs_dual(var) {
        s.push_str(&format!(
            "continuum vs dual: max |ψ'_cont − ψ'_dual| / max |ψ'_dual| = {e:.3e}\n"
        ));
    }
    let rates: Vec<String> = var
        .taylor
        .iter()
        .filter_map(|f| f.rate.map(|r| format!("{}: {r:.3}", f.step + 1)))
        .collect();
    if !rates.is_empty() {
        s.push_str(&format!("Taylor rate per step: {}\n", rates.join(", ")));
    }
    let roundoff: Vec<String> = var
        .taylor
        .iter()
        .filter(|f| f.rate.is_none() && !f.roundoff.is_empty())
        .map(|f| (f.step + 1).to_string())
        .collect();
    if !roundoff.is_empty() {
        s.push_str(&format!(
            "Taylor remainder at the responses' round-off (no rate) at step {}\n",
            roundoff.join(", ")
        ));
    }
    let flagged: Vec<String> = var
        .fd
        .iter()
        .filter(|c| c.flagged.iter().any(|f| *f))
        .map(|c| {
            let first = c.flagged.iter().position(|f| *f).map_or(0, |p| p + 1);
            format!("h/|τ| = {:e} from step {first}", c.relative)
        })
        .collect();
    if !flagged.is_empty() {
        s.push_str(&format!(
            "* active set changed within ±h (not comparable): {}\n",
            flagged.join("; ")
        ));
    }
    s
}

/// The breakdown of one variable as a table: per group the largest continuum and dual entries
/// and their largest difference with its row (particle, DOF); then the end-of-step
/// sensitivities field by field with the worst integration point or particle.
pub fn terms_table(b: &TermBreakdown) -> String {
    let mut s = format!(
        "terms at step {} (λ = {:e}), design variable `{}` ({}):\n",
        b.step,
        b.load,
        b.variable.name,
        b.variable.kind.key()
    );
    s.push_str(&format!(
        "{:<10} {:>13} {:>13} {:>13} {:>10}  worst row\n",
        "group", "max|cont.|", "max|dual|", "max|diff|", "rel."
    ));
    for g in &b.groups {
        let worst = match g.worst_dof {
            _ if g.max_difference == 0.0 => "—".to_string(),
            Some((p, c)) => format!("particle {p} dof {c}"),
            None => format!("constraint row {}", g.worst_row),
        };
        s.push_str(&format!(
            "{:<10} {:>13.5e} {:>13.5e} {:>13.5e} {:>10.2e}  {}\n",
            g.group.map_or("total", |t| t.name()),
            g.continuum_max,
            g.dual_max,
            g.max_difference,
            g.relative(),
            worst
        ));
    }
    s.push_str(&format!(
        "{:<12} {:>13} {:>13} {:>10}  worst point\n",
        "n+1 field", "max|dual|", "max|diff|", "rel."
    ));
    for f in &b.update {
        let at = match f.worst.1 {
            _ if f.max_difference == 0.0 => "—".to_string(),
            Some(l) => format!(
                "point {} layer {l} at ({:.4}, {:.4})",
                f.worst.0, f.worst_uv[0], f.worst_uv[1]
            ),
            None => format!(
                "particle {} at ({:.4}, {:.4})",
                f.worst.0, f.worst_uv[0], f.worst_uv[1]
            ),
        };
        s.push_str(&format!(
            "{:<12} {:>13.5e} {:>13.5e} {:>10.2e}  {}\n",
            f.field,
            f.dual_max,
            f.max_difference,
            f.relative(),
            at
        ));
    }
    s
}

/// `terms.json`: the breakdowns of all variables.
pub fn terms_json(bs: &[TermBreakdown]) -> Value {
    let one = |b: &TermBreakdown| {
        json!({
            "step": b.step,
            "load": b.load,
            "variable": b.variable.name,
            "kind": b.variable.kind.key(),
            "groups": b.groups.iter().map(|g| json!({
                "group": g.group.map_or("total", |t| t.name()),
                "continuum_max": num(g.continuum_max),
                "dual_max": num(g.dual_max),
                "max_difference": num(g.max_difference),
                "relative": num(g.relative()),
                "worst_row": g.worst_row,
                "worst_particle_dof": g.worst_dof,
            })).collect::<Vec<_>>(),
            "update": b.update.iter().map(|f| json!({
                "field": f.field,
                "dual_max": num(f.dual_max),
                "max_difference": num(f.max_difference),
                "relative": num(f.relative()),
                "worst_index": f.worst.0,
                "worst_layer": f.worst.1,
                "worst_uv": f.worst_uv,
            })).collect::<Vec<_>>(),
        })
    };
    json!({
        "kind": "shell-dsa-terms",
        "notes": [
            "groups: the continuum fictitious load (eq 65's right-hand side) of each term group, \
             seeded with the dual reference's committed sensitivities at the step start, against \
             the dual residual's derivative part with only that group seeded; total = all groups",
            "update: the continuum end-of-step sensitivities (its own solve of eq 65 with the \
             converged tangent, history update eqs 44-51, particle update) against the dual \
             reference's committed dual state",
        ],
        "breakdowns": bs.iter().map(one).collect::<Vec<_>>(),
    })
}
