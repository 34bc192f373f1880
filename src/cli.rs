//! The `shelldsa` command line.

use crate::io::shell_build::{self, RunStatus};
use crate::io::shell_case::ShellCase;
use crate::io::shell_output::StepSummary;
use crate::io::{read_case, Case, MaterialPathCase};
use crate::material::STATE_LABELS;
use crate::scalar::Dual;
use crate::verification::Tolerance;
use clap::{Parser, Subcommand};
use serde_json::json;
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Design sensitivity analysis of nonlinear shells, checked three ways.
#[derive(Debug, Parser)]
#[command(name = "shelldsa", version, about)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run a case: the analysis and every derivative method, with results written to --out.
    Run {
        /// Case file (TOML).
        case: PathBuf,
        /// Output directory (created if missing).
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// Print only the summary.
        #[arg(long)]
        quiet: bool,
    },
    /// Design sensitivities of a shell case with `[[design]]` tables: the dual-number
    /// reference and central differences of complete re-runs, a table per design variable in
    /// the format of the paper's Tables 1–2, and DIR/sensitivity.json.
    Dsa {
        /// Case file (TOML) with at least one [[design]] table.
        case: PathBuf,
        /// Output directory (created if missing).
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// Methods, comma-separated: `continuum`, `dual`, `fd` (default: the case's
        /// `[dsa] methods`, else all three).
        #[arg(long, value_delimiter = ',')]
        methods: Option<Vec<String>>,
        /// Term-by-term breakdown at this converged load step (1-based): each group of the
        /// continuum fictitious load against the dual reference seeded with that group only;
        /// printed and written to DIR/terms.json.
        #[arg(long)]
        terms: Option<usize>,
    },
    /// Read and validate a case file without running it.
    Check {
        /// Case file (TOML).
        case: PathBuf,
    },
}

/// Exit status: 0 success, 1 bad input, set-up or I/O failure, 2 derivative check outside
/// tolerance, 3 shell analysis stopped before the final load factor (the converged steps are
/// written).
pub fn main_with_args<I: IntoIterator<Item = String>>(args: I) -> i32 {
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() { 1 } else { 0 };
        }
    };
    let result = match cli.command {
        Command::Check { case } => read_case(&case).map(|c| {
            // The boundary entries as the analysis imposes them (overlaps merged, a component
            // held at two values refused). That builds the particles' shape functions, so a
            // grid beyond a million particles is left to `run` (which builds them anyway).
            let boundary = match &c {
                Case::Shell(s)
                    if s.particles.counts[0].saturating_mul(s.particles.counts[1]) <= 1_000_000 =>
                {
                    match shell_build::check_boundary(s) {
                        Ok(set) => Some(set),
                        Err(e) => {
                            eprintln!("error: {}: {e}", case.display());
                            return 1;
                        }
                    }
                }
                _ => None,
            };
            println!("{}: ok ({})", case.display(), describe(&c));
            if let (Case::Shell(_), None) = (&c, &boundary) {
                println!("boundary: not assembled here (over a million particles): `run` does");
            }
            if let Some(set) = boundary {
                println!(
                    "boundary: {} constraint rows, {} DOFs eliminated by symmetry, {} rows \
                     merged (already held by another entry or a symmetry plane)",
                    set.rows.len(),
                    set.fixed.len(),
                    set.merged.len()
                );
            }
            if let Case::Shell(s) = &c {
                let missing = shell_build::unsupported(s);
                if !missing.is_empty() {
                    println!("note: this build cannot run the case yet:");
                    for m in &missing {
                        println!("  {m}");
                    }
                }
            }
            0
        }),
        Command::Run { case, out, quiet } => read_case(&case).map(|c| run(&c, &out, quiet)),
        Command::Dsa {
            case,
            out,
            methods,
            terms,
        } => read_case(&case).map(|c| dsa(&c, &out, methods.as_deref(), terms)),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e}");
            1
        }
    }
}

/// `shelldsa dsa`: exit 0 on success, 1 on bad input or a failed run.
fn dsa(case: &Case, out: &Path, methods: Option<&[String]>, terms: Option<usize>) -> i32 {
    use crate::io::dsa_run;
    let Case::Shell(c) = case else {
        eprintln!(
            "error: `shelldsa dsa` takes a shell case (`[problem] kind = \"shell\"`); a \
             material-path case carries its sensitivities in `shelldsa run`"
        );
        return 1;
    };
    let spec = match &c.dsa {
        Some(s) => s,
        None => {
            eprintln!(
                "error: {}",
                dsa_run::DsaError::NoDesign(c.path.display().to_string())
            );
            return 1;
        }
    };
    let methods = match methods {
        Some(m) => match crate::io::dsa_case::parse_methods(m, "--methods", &c.path) {
            Ok(m) => m,
            Err(e) => {
                eprintln!("error: {e}");
                return 1;
            }
        },
        None => spec.methods.clone(),
    };
    let spec = match dsa_run::validate(c, &methods) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return 1;
        }
    };
    if let Err(e) = std::fs::create_dir_all(out) {
        eprintln!(
            "error: cannot create output directory {}: {e}",
            out.display()
        );
        return 1;
    }
    println!(
        "{}: {} design variable(s) ({}), {} monitored component(s), methods {}",
        c.title,
        spec.design.len(),
        spec.design
            .iter()
            .map(|d| d.variable.name.as_str())
            .collect::<Vec<_>>()
            .join(", "),
        spec.monitors.len(),
        spec.methods
            .iter()
            .map(|m| m.name())
            .collect::<Vec<_>>()
            .join(",")
    );
    let result = match dsa_run::run(c, &spec, &mut |line| println!("{line}")) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: {e}");
            return 1;
        }
    };
    println!();
    for v in 0..result.variables.len() {
        println!("{}", dsa_run::table(&result, v));
    }
    let fmt = |t: Option<f64>| t.map_or("—".to_string(), |t| format!("{t:.3} s"));
    println!(
        "timing: analysis {:.3} s (separate plain run), continuum {} (DSA inside a hooked run of \
         {}), dual {} (reference inside a hooked run of {}), fd {}",
        result.time_analysis,
        fmt(result.time_continuum),
        fmt(result.time_continuum_run),
        fmt(result.time_dual),
        fmt(result.time_dual_run),
        fmt(result.time_fd)
    );
    if let (Some(t), Some(dsa)) = (result.continuum_stages, result.time_continuum) {
        let nv = result.variables.len().max(1) as f64;
        println!(
            "continuum DSA per design variable: {:.2} % of the analysis; stages: right-hand sides \
             {:.3} s, solve {:.3} s, history update {:.3} s, monitors {:.3} s, load check {:.3} s",
            100.0 * dsa / result.time_analysis / nv,
            t.rhs,
            t.solve,
            t.update,
            t.record,
            t.check
        );
    }
    let json = dsa_run::to_json(c, &result);
    let path = out.join("sensitivity.json");
    let text = match serde_json::to_string_pretty(&json) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: sensitivity.json: {e}");
            return 1;
        }
    };
    if let Err(e) = std::fs::write(&path, text) {
        eprintln!("error: cannot write {}: {e}", path.display());
        return 1;
    }
    println!("wrote {}", path.display());
    if let Some(step) = terms {
        println!("term breakdown at step {step} (analysis with the dual reference, Dual64):");
        let bs = match dsa_run::terms(c, &spec, step) {
            Ok(b) => b,
            Err(e) => {
                eprintln!("error: --terms {step}: {e}");
                return 1;
            }
        };
        for b in &bs {
            println!("{}", dsa_run::terms_table(b));
        }
        let path = out.join("terms.json");
        let written = serde_json::to_string_pretty(&dsa_run::terms_json(&bs))
            .map_err(|e| e.to_string())
            .and_then(|t| std::fs::write(&path, t).map_err(|e| e.to_string()));
        if let Err(e) = written {
            eprintln!("error: cannot write {}: {e}", path.display());
            return 1;
        }
        println!("wrote {}", path.display());
    }
    0
}

fn describe(c: &Case) -> String {
    match c {
        Case::MaterialPath(m) => format!(
            "material-path, {} steps, design variable `{}`",
            m.path.n_steps(),
            m.design_name
        ),
        Case::Shell(s) => {
            format!(
                "shell on a {} surface, {} × {} particles, {} basis, {} boundary condition(s), {} \
             load(s), {} tool(s), {} monitor(s), load factor to {}",
                s.surface.kind(),
                s.particles.counts[0],
                s.particles.counts[1],
                s.kernel.basis,
                s.boundary.len(),
                s.loads.len(),
                s.tools.len(),
                s.monitors.len(),
                s.steps.final_load
            ) + &s.dsa.as_ref().map_or(String::new(), |d| {
                format!(", {} design variable(s) for `shelldsa dsa`", d.design.len())
            })
        }
    }
}

fn run(case: &Case, out: &Path, quiet: bool) -> i32 {
    if let Err(e) = std::fs::create_dir_all(out) {
        eprintln!(
            "error: cannot create output directory {}: {e}",
            out.display()
        );
        return 1;
    }
    match case {
        Case::MaterialPath(c) => match run_material_path(c, out, quiet) {
            Ok(code) => code,
            Err(e) => {
                eprintln!("error: {e}");
                1
            }
        },
        Case::Shell(c) => run_shell(c, out, quiet),
    }
}

/// One progress line of a converged shell step.
fn step_line(c: &ShellCase, s: &StepSummary) -> String {
    let mut line = format!(
        "step {:>4}  λ = {:<12.6e} it {:>2}  |r| {:.3e}",
        s.step,
        s.load_factor,
        s.iterations,
        s.residual_norms.last().copied().unwrap_or(f64::NAN)
    );
    for (m, d) in c.monitors.iter().zip(&s.monitors) {
        line.push_str(&format!(
            "  {} = ({:.5e}, {:.5e}, {:.5e})",
            m.name, d[0], d[1], d[2]
        ));
    }
    if let Some(ct) = &s.contact {
        for t in &ct.tools {
            line.push_str(&format!(
                "  {} F = ({:.4e}, {:.4e}, {:.4e}) on {} pt",
                t.name, t.force[0], t.force[1], t.force[2], t.active_points
            ));
        }
        line.push_str(&format!("  active {}", ct.active_points));
    }
    if let Some(sep) = &s.separation {
        line.push_str(&format!(
            "\nseparation: tool `{}` carries no force at step {} (t = {}; last in contact at t = {})",
            sep.tool, sep.step, sep.t, sep.t_before
        ));
    }
    line
}

fn run_shell(c: &ShellCase, out: &Path, quiet: bool) -> i32 {
    let start = Instant::now();
    let mut built = match shell_build::build(c) {
        Ok(b) => b,
        Err(e) => {
            eprintln!("error: {}: {e}", c.path.display());
            return 1;
        }
    };
    println!(
        "{}: {} particles, {} unknowns, {} quadrature points × {} layers (built in {:.2} s)",
        c.title,
        built.n_particles,
        crate::solver::NonlinearProblem::n_dofs(&built.problem),
        shell_build::problem_model(&built.problem).points.len(),
        shell_build::problem_model(&built.problem)
            .thickness_rule
            .len(),
        start.elapsed().as_secs_f64()
    );
    let bar = (!quiet && std::io::stdout().is_terminal()).then(|| {
        let b = indicatif::ProgressBar::new(1000);
        if let Ok(style) = indicatif::ProgressStyle::with_template(
            "{elapsed_precise} [{bar:40}] load factor {msg}",
        ) {
            b.set_style(style.progress_chars("=> "));
        }
        b
    });
    let final_load = c.steps.final_load;
    let result = shell_build::run(c, &mut built, out, start, |s| {
        let line = step_line(c, s);
        match &bar {
            Some(b) => {
                b.println(line);
                b.set_position((1000.0 * s.load_factor / final_load).round() as u64);
                b.set_message(format!("{:.4e} / {final_load:e}", s.load_factor));
            }
            None if !quiet => println!("{line}"),
            None => {}
        }
    });
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    match result {
        Ok(summary) => {
            let last = summary.steps.last();
            if quiet {
                if let Some(s) = last {
                    println!("{}", step_line(c, s));
                }
            }
            for w in &summary.warnings {
                println!("warning: {w}");
            }
            if let (Some(cs), None) = (&c.contact, &summary.separation) {
                if let Some(r) = &cs.release {
                    println!("warning: the release tool `{r}` did not separate from the sheet");
                }
            }
            println!(
                "{}: {} converged step(s) in {} attempt(s), load factor {:e}, {:.2} s; results in {}",
                summary.status.label(),
                summary.steps.len(),
                summary.attempts,
                last.map_or(0.0, |s| s.load_factor),
                summary.wall_time_s,
                out.display()
            );
            match summary.status {
                RunStatus::Complete => 0,
                RunStatus::Failed(_) => 3,
            }
        }
        Err(e) => {
            eprintln!("error: {e}");
            1
        }
    }
}

fn run_material_path(
    c: &MaterialPathCase,
    out: &Path,
    quiet: bool,
) -> Result<i32, Box<dyn std::error::Error>> {
    let start = Instant::now();
    let p = &c.path;
    // Time each method on its own.
    let t = Instant::now();
    let (states, plastic) = p.run::<f64>(p.tau)?;
    let t_analysis = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let hand = p.hand_derived()?;
    let t_continuum = (t.elapsed().as_secs_f64() - t_analysis).max(0.0);
    let t = Instant::now();
    let (dual_states, _) = p.run(Dual::from_re(p.tau).derivative())?;
    let t_dual = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let (sp, _) = p.run::<f64>(p.tau + c.fd_step)?;
    let (sm, _) = p.run::<f64>(p.tau - c.fd_step)?;
    let t_fd = t.elapsed().as_secs_f64();
    let check = p.check(
        c.fd_step,
        Tolerance::rel(c.check.dual_rel),
        Tolerance {
            rel: c.check.fd_rel,
            floor: c.check.fd_floor,
        },
    )?;

    let mut steps = Vec::with_capacity(p.n_steps());
    let mut csv = String::from("step,plastic,component,value,continuum,dual,fd_central\n");
    for k in 0..p.n_steps() {
        let v = states[k].to_array();
        let h = hand.sensitivities[k].to_array();
        let d = dual_state_eps(&dual_states[k]);
        let fp = sp[k].to_array();
        let fm = sm[k].to_array();
        let mut comps = serde_json::Map::new();
        for i in 0..11 {
            let fd = (fp[i] - fm[i]) / (2.0 * c.fd_step);
            comps.insert(
                STATE_LABELS[i].into(),
                json!({"value": v[i], "continuum": h[i], "dual": d[i], "fd_central": fd, "fd_step": c.fd_step}),
            );
            csv.push_str(&format!(
                "{},{},{},{:.16e},{:.16e},{:.16e},{:.16e}\n",
                k + 1,
                plastic[k],
                STATE_LABELS[i],
                v[i],
                h[i],
                d[i],
                fd
            ));
        }
        let sc = &check.per_step[k];
        steps.push(json!({
            "step": k + 1,
            "plastic": plastic[k],
            "iterations": hand.iterations[k],
            "components": comps,
            "error_vs_dual": sc.dual_error,
            "error_vs_fd": sc.fd_error,
            "status_flips_within_fd_step": sc.flipped,
        }));
    }
    let passed = check.passed();
    let results = json!({
        "kind": "material-path",
        "title": c.title,
        "design_variable": c.design_name,
        "tau": p.tau,
        "wall_time_s": start.elapsed().as_secs_f64(),
        "timing_s": {"analysis": t_analysis, "continuum": t_continuum, "dual": t_dual, "fd": t_fd},
        "check": {
            "passed": passed,
            "dual": {"max_scaled_error": check.vs_dual.max_error(), "tolerance": c.check.dual_rel},
            "fd": {"max_scaled_error": check.vs_fd.max_error(), "tolerance": c.check.fd_rel, "floor": c.check.fd_floor},
            "flipped_steps": check.flipped_steps.iter().map(|k| k + 1).collect::<Vec<_>>(),
        },
        "steps": steps,
    });
    std::fs::write(
        out.join("results.json"),
        serde_json::to_string_pretty(&results)?,
    )?;
    std::fs::write(out.join("sensitivity.csv"), csv)?;
    plot_material_path(
        c,
        &states,
        &hand.sensitivities,
        &dual_states,
        &sp,
        &sm,
        &check,
        &out.join("sensitivity.png"),
    )?;

    let mut o = std::io::stdout().lock();
    writeln!(
        o,
        "{} — design variable `{}` at τ = {}",
        c.title, c.design_name, p.tau
    )?;
    if !quiet {
        writeln!(
            o,
            "{:>4} {:>7} {:>14} {:>14} {:>14} {:>14} {:>9}",
            "step", "status", "σ11", "σ̇11 continuum", "σ̇11 dual", "σ̇11 FD", "FD/cont%"
        )?;
        for k in 0..p.n_steps() {
            let fd = (sp[k].stress[0] - sm[k].stress[0]) / (2.0 * c.fd_step);
            let h = hand.sensitivities[k].stress[0];
            writeln!(
                o,
                "{:>4} {:>7} {:>14.6e} {:>14.6e} {:>14.6e} {:>14.6e} {:>9.4}",
                k + 1,
                if plastic[k] { "plastic" } else { "elastic" },
                states[k].stress[0],
                h,
                dual_states[k].stress[0].eps,
                fd,
                100.0 * fd / h
            )?;
        }
        writeln!(
            o,
            "\nper-step errors (all 11 history components, scaled):\n{check}"
        )?;
    } else {
        writeln!(o, "{}\n{}", check.vs_dual, check.vs_fd)?;
    }
    writeln!(
        o,
        "timing: analysis {:.3e} s, continuum DSA {:.3e} s, dual {:.3e} s, FD {:.3e} s",
        t_analysis, t_continuum, t_dual, t_fd
    )?;
    writeln!(
        o,
        "wrote results.json, sensitivity.csv and sensitivity.png to {}",
        out.display()
    )?;
    writeln!(
        o,
        "{}",
        if passed {
            "derivative check: PASSED"
        } else {
            "derivative check: FAILED"
        }
    )?;
    Ok(if passed { 0 } else { 2 })
}

fn dual_state_eps(s: &crate::material::MaterialState<Dual>) -> [f64; 11] {
    let mut a = [0.0; 11];
    for i in 0..5 {
        a[i] = s.stress[i].eps;
        a[5 + i] = s.back_stress[i].eps;
    }
    a[10] = s.eps_p.eps;
    a
}

/// Response, sensitivity three ways, and per-step errors: `sensitivity.png`.
#[allow(clippy::too_many_arguments)]
fn plot_material_path(
    c: &MaterialPathCase,
    states: &[crate::material::MaterialState<f64>],
    hand: &[crate::material::MaterialState<f64>],
    dual: &[crate::material::MaterialState<Dual>],
    sp: &[crate::material::MaterialState<f64>],
    sm: &[crate::material::MaterialState<f64>],
    check: &crate::verification::material_path::PathCheck,
    path: &Path,
) -> Result<(), String> {
    use crate::io::plot::{figure, Panel, Scale, Series};
    let steps = |f: &dyn Fn(usize) -> f64| -> Vec<(f64, f64)> {
        (0..states.len()).map(|k| ((k + 1) as f64, f(k))).collect()
    };
    let h = c.fd_step;
    let title = format!("{}: sensitivity d/d{} three ways", c.title, c.design_name);
    figure(
        path,
        1000,
        1100,
        &[
            Panel {
                title: "response",
                x_label: "step",
                y_label: "stress",
                y_scale: Scale::Linear,
                series: vec![
                    Series {
                        label: "σ11",
                        points: steps(&|k| states[k].stress[0]),
                        markers: false,
                    },
                    Series {
                        label: "σ12",
                        points: steps(&|k| states[k].stress[2]),
                        markers: false,
                    },
                    Series {
                        label: "α11",
                        points: steps(&|k| states[k].back_stress[0]),
                        markers: false,
                    },
                ],
            },
            Panel {
                title: &title,
                x_label: "step",
                y_label: "dσ11/dτ",
                y_scale: Scale::Linear,
                series: vec![
                    Series {
                        label: "continuum (eqs 44-49)",
                        points: steps(&|k| hand[k].stress[0]),
                        markers: false,
                    },
                    Series {
                        label: "dual numbers",
                        points: steps(&|k| dual[k].stress[0].eps),
                        markers: true,
                    },
                    Series {
                        label: "central difference",
                        points: steps(&|k| (sp[k].stress[0] - sm[k].stress[0]) / (2.0 * h)),
                        markers: true,
                    },
                ],
            },
            Panel {
                title: "worst scaled error per step (all 11 history components)",
                x_label: "step",
                y_label: "error",
                y_scale: Scale::Log,
                series: vec![
                    Series {
                        label: "continuum vs dual",
                        points: steps(&|k| check.per_step[k].dual_error),
                        markers: true,
                    },
                    Series {
                        label: "continuum vs FD",
                        points: steps(&|k| check.per_step[k].fd_error),
                        markers: true,
                    },
                ],
            },
        ],
    )
}
