//! The `shelldsa` command line.
//!
//! Nothing it prints can panic: standard output goes through `Console`, which ends the
//! printed output quietly when its reader closes it (`shelldsa run CASE | head -1`; the run
//! goes on and writes its files) and reports any other write error once (`> /dev/full`);
//! standard error is written without failing. The exit statuses are [`EXIT_STATUS_HELP`].

use crate::io::shell_build::{self, BuildError, RunStatus};
use crate::io::shell_case::ShellCase;
use crate::io::shell_output::StepSummary;
use crate::io::{read_case, Case, MaterialPathCase};
use crate::material::STATE_LABELS;
use crate::scalar::Dual;
use crate::verification::Tolerance;
use clap::{Parser, Subcommand};
use serde_json::json;
use std::borrow::Cow;
use std::cell::Cell;
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Success.
pub const EXIT_OK: i32 = 0;
/// Bad input: the case file, the command-line arguments, or a case that cannot be built.
pub const EXIT_BAD_INPUT: i32 = 1;
/// A derivative check outside its tolerance (material-path cases).
pub const EXIT_CHECK_FAILED: i32 = 2;
/// The analysis stopped before its end (a Newton failure; in `dsa`, a failed method or
/// finite-difference re-run). Every converged result is written.
pub const EXIT_STOPPED: i32 = 3;
/// Output error: a results file, the output directory or the standard output could not be
/// written.
pub const EXIT_OUTPUT: i32 = 4;

/// The exit statuses, as `--help` prints them.
pub const EXIT_STATUS_HELP: &str = "Exit status:
  0  success
  1  bad input: the case file, the command-line arguments, or a case that cannot be built
     (nothing is run)
  2  a derivative check outside its tolerance (material-path cases)
  3  the analysis stopped before its end (Newton failure; in `dsa`, a failed method or
     finite-difference re-run): every converged result is written, the failure is named
  4  output error: a results file, the output directory or the standard output could not be
     written (a reader that closes the standard output early, as `| head` does, is not an
     error: the printed output ends and the run finishes its files)";

/// Design sensitivity analysis of nonlinear shells, checked three ways.
#[derive(Debug, Parser)]
#[command(name = "shelldsa", version, about, after_help = EXIT_STATUS_HELP)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run a case: the analysis and every derivative method, with results written to --out.
    #[command(after_help = EXIT_STATUS_HELP)]
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
    /// Design sensitivities of a shell case with `[[design]]` tables, three ways: the
    /// hand-derived continuum DSA, the dual-number reference and central differences of
    /// complete re-runs, for the monitored responses (displacements, tool forces, chord
    /// angles, plastic strain, thinning, distance from a target: `[dsa]`); a table per design
    /// variable in the format of the paper's Tables 1–2, plots, and DIR/sensitivity.json
    /// (rewritten after each converged step and run, with a `status` and the `failures`).
    /// Design variables (`[[design]] kind`): `thickness`, `material.<parameter>`,
    /// `shape.<surface parameter>`, `tool.<name>.<x|y|z|rx|ry|rz>` (a tool's position) and
    /// `tool.<name>.shape.<tool surface parameter>` (a tool's shape: a die's `radius`, a NURBS
    /// die's `cp[i][j].x|y|z` or `weight[i][j]`).
    #[command(after_help = EXIT_STATUS_HELP)]
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
    #[command(after_help = EXIT_STATUS_HELP)]
    Check {
        /// Case file (TOML).
        case: PathBuf,
    },
}

/// Text as printed: control characters other than line breaks and tabs (terminal escape
/// sequences, carriage returns, bells) are shown escaped (`\u{1b}`), never sent raw.
pub fn printable(text: &str) -> Cow<'_, str> {
    let raw = |c: char| c.is_control() && c != '\n' && c != '\t';
    if !text.chars().any(raw) {
        return Cow::Borrowed(text);
    }
    Cow::Owned(
        text.chars()
            .map(|c| {
                if raw(c) {
                    c.escape_unicode().to_string()
                } else {
                    c.to_string()
                }
            })
            .collect(),
    )
}

/// A line on standard error; a failure to write it is ignored (there is nowhere left to say so).
fn eline(text: &str) {
    let _ = writeln!(std::io::stderr().lock(), "{}", printable(text));
}

/// The state of standard output.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Stdout {
    Open,
    /// Closed by its reader (broken pipe): nothing more is printed, not an error.
    Closed,
    /// Failed otherwise (a full device): reported once, the exit status becomes [`EXIT_OUTPUT`].
    Failed,
}

/// Standard output of one command (see the module documentation).
struct Console {
    state: Cell<Stdout>,
}

impl Console {
    fn new() -> Self {
        Console {
            state: Cell::new(Stdout::Open),
        }
    }

    /// Print a line (through [`printable`]), flushed at once.
    fn line(&self, text: &str) {
        if self.state.get() != Stdout::Open {
            return;
        }
        let mut o = std::io::stdout().lock();
        let written = o
            .write_all(printable(text).as_bytes())
            .and_then(|()| o.write_all(b"\n"))
            .and_then(|()| o.flush());
        if let Err(e) = written {
            if e.kind() == std::io::ErrorKind::BrokenPipe {
                self.state.set(Stdout::Closed);
            } else {
                self.state.set(Stdout::Failed);
                eline(&format!(
                    "error: cannot write to standard output: {e} (the command goes on, and a \
                     run still writes its files)"
                ));
            }
        }
    }

    /// The exit status of a command that would exit with `code`: [`EXIT_OUTPUT`] instead of
    /// success, a failed check or a stopped analysis when standard output failed.
    fn status(&self, code: i32) -> i32 {
        if self.state.get() == Stdout::Failed
            && matches!(code, EXIT_OK | EXIT_CHECK_FAILED | EXIT_STOPPED)
        {
            EXIT_OUTPUT
        } else {
            code
        }
    }
}

/// Print a formatted line on a [`Console`].
macro_rules! say {
    ($con:expr, $($arg:tt)*) => {
        $con.line(&format!($($arg)*))
    };
}

/// Print a formatted line on standard error.
macro_rules! err {
    ($($arg:tt)*) => {
        eline(&format!($($arg)*))
    };
}

/// Run the command line `args` (the program name first) and return the exit status
/// ([`EXIT_STATUS_HELP`]).
pub fn main_with_args<I: IntoIterator<Item = String>>(args: I) -> i32 {
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => {
            let printed = e.print();
            return match (e.use_stderr(), printed) {
                (true, _) => EXIT_BAD_INPUT,
                // `--help` or `--version` on standard output: a closed pipe is no error, a
                // failed write (a full device) is an output error like any other.
                (false, Err(w)) if w.kind() != std::io::ErrorKind::BrokenPipe => {
                    eline(&format!("error: cannot write to standard output: {w}"));
                    EXIT_OUTPUT
                }
                (false, _) => EXIT_OK,
            };
        }
    };
    let con = Console::new();
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
                            err!("error: {}: {e}", case.display());
                            return EXIT_BAD_INPUT;
                        }
                    }
                }
                _ => None,
            };
            say!(con, "{}: ok ({})", case.display(), describe(&c));
            report(&con, &c);
            if let (Case::Shell(_), None) = (&c, &boundary) {
                say!(
                    con,
                    "boundary: not assembled here (over a million particles): `run` does"
                );
            }
            if let Some(set) = boundary {
                say!(
                    con,
                    "boundary: {} constraint rows, {} DOFs eliminated by symmetry, {} rows \
                     merged (already held by another entry or a symmetry plane)",
                    set.rows.len(),
                    set.fixed.len(),
                    set.merged.len()
                );
            }
            EXIT_OK
        }),
        Command::Run { case, out, quiet } => read_case(&case).map(|c| run(&con, &c, &out, quiet)),
        Command::Dsa {
            case,
            out,
            methods,
            terms,
        } => read_case(&case).map(|c| dsa(&con, &c, &out, methods.as_deref(), terms)),
    };
    match result {
        Ok(code) => con.status(code),
        Err(e) => {
            err!("error: {e}");
            EXIT_BAD_INPUT
        }
    }
}

/// The case's resource estimate and warnings ([`crate::io::case_report`]), printed before any
/// work.
fn report(con: &Console, c: &Case) {
    report_lines(con, crate::io::case_report(c));
}

/// Print the lines of a case report.
fn report_lines(con: &Console, lines: Vec<String>) {
    for line in lines {
        say!(con, "{line}");
    }
}

/// The most load steps a run of `c` can converge: every step but those clipped to a `stops`
/// level or to the final load is at least `min_step` long.
fn max_load_steps(c: &ShellCase) -> f64 {
    (c.steps.final_load / c.steps.min_step).ceil() + c.steps.stops.len() as f64 + 1.0
}

/// `shelldsa dsa` (exit statuses: [`EXIT_STATUS_HELP`]). Everything that can be checked
/// before the analysis is: the case kind, the methods, `--terms` (at least 1, at most the
/// steps the case can take), the design variables and the output directory, which receives a
/// first `sensitivity.json` (`status` `"running"`). The file is rewritten after every run.
fn dsa(
    con: &Console,
    case: &Case,
    out: &Path,
    methods: Option<&[String]>,
    terms: Option<usize>,
) -> i32 {
    use crate::io::{dsa_output, dsa_study};
    use crate::sensitivity::study;
    let Case::Shell(c) = case else {
        err!(
            "error: `shelldsa dsa` takes a shell case (`[problem] kind = \"shell\"`); a \
             material-path case carries its sensitivities in `shelldsa run`"
        );
        return EXIT_BAD_INPUT;
    };
    let spec = match &c.dsa {
        Some(s) => s,
        None => {
            err!(
                "error: {}",
                crate::io::CaseError::NoDesign {
                    path: c.path.clone()
                }
            );
            return EXIT_BAD_INPUT;
        }
    };
    let methods = match methods {
        Some(m) => match crate::io::dsa_case::parse_methods(m, "--methods", &c.path) {
            Ok(m) => m,
            Err(e) => {
                err!("error: {e}");
                return EXIT_BAD_INPUT;
            }
        },
        None => spec.methods.clone(),
    };
    if let Some(step) = terms {
        let most = max_load_steps(c);
        if step == 0 || step as f64 > most {
            err!(
                "error: --terms {step}: expected a load step in 1..={most} (the case takes at \
                 most ⌈final_load / min_step⌉ = ⌈{} / {}⌉ steps, one more for rounding, and one \
                 for each of its {} stop(s))",
                c.steps.final_load,
                c.steps.min_step,
                c.steps.stops.len()
            );
            return EXIT_BAD_INPUT;
        }
    }
    let spec = match dsa_study::validate(c, &methods) {
        Ok(s) => s,
        Err(e) => {
            err!("error: {e}");
            return EXIT_BAD_INPUT;
        }
    };
    let path = out.join("sensitivity.json");
    let written = std::fs::create_dir_all(out)
        .map_err(|e| format!("cannot create output directory {}: {e}", out.display()))
        .and_then(|()| {
            dsa_output::write_json(&path, &dsa_output::empty_json(c, &spec, "running"))
                .map_err(|e| e.to_string())
        });
    if let Err(e) = written {
        err!("error: {e}");
        return EXIT_OUTPUT;
    }
    say!(
        con,
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
    report_lines(con, crate::io::shell_report(c));
    // The first error writing sensitivity.json while the methods run (they go on).
    let mut write_error: Option<String> = None;
    // The last results written: kept with the failure if the run stops.
    let mut last: Option<serde_json::Value> = None;
    let progress = &mut |line: &str| con.line(line);
    let analysis = dsa_study::CaseAnalysis { case: c };
    let base = dsa_study::base_design(c);
    let mut vtu = dsa_output::StepVtu::new(out, c);
    let writer: Option<&mut dyn study::StepWriter> = match c.output.vtu {
        true => Some(&mut vtu),
        false => None,
    };
    let run = study::run_with_output(&analysis, &base, &spec, terms, writer, progress, &mut |r| {
        if write_error.is_none() {
            let doc = dsa_output::to_json(c, r, "running");
            if let Err(e) = dsa_output::write_json(&path, &doc) {
                err!("error: {e} (the run goes on)");
                write_error = Some(e.to_string());
            }
            last = Some(doc);
        }
    });
    let result = match run {
        Ok(r) => r,
        Err(e) => {
            err!("error: {e}");
            let stopped = matches!(
                e,
                study::DsaError::Sensitivity(crate::sensitivity::dual::SensitivityError::Newton(_))
            );
            let status = format!("failed: {e}");
            let doc = match last {
                // Every converged step of the run that stopped.
                Some(mut doc) => {
                    doc["status"] = serde_json::Value::String(status);
                    doc
                }
                None => dsa_output::empty_json(c, &spec, &status),
            };
            let _ = dsa_output::write_json(&path, &doc);
            return if stopped {
                EXIT_STOPPED
            } else {
                EXIT_BAD_INPUT
            };
        }
    };
    say!(con, "");
    for v in 0..result.variables.len() {
        say!(con, "{}", dsa_output::table(&result, v));
    }
    let fmt = |t: Option<f64>| t.map_or("—".to_string(), |t| format!("{t:.3} s"));
    say!(
        con,
        "timing: analysis {:.3} s (separate plain run), continuum {} (DSA inside a hooked run of \
         {}), dual {} (reference inside a hooked run of {}), fd {}",
        result.time_analysis,
        fmt(result.time_continuum),
        fmt(result.time_continuum_run),
        fmt(result.time_dual),
        fmt(result.time_dual_run),
        fmt(result.time_fd)
    );
    let cost = result.cost();
    if let (Some(t), Some(own)) = (result.continuum_stages, cost.continuum_own) {
        say!(
            con,
            "continuum DSA per design variable: {:.2} % of the analysis; stages: right-hand sides \
             {:.3} s, solve {:.3} s{}, history update {:.3} s, monitors {:.3} s",
            100.0 * own,
            t.rhs,
            t.solve,
            if t.krylov_iterations + t.krylov_fallbacks > 0 {
                format!(
                    " ({} preconditioned iterations on the converged tangents; {} step(s) \
                     factorised for the DSA where GMRES gave up)",
                    t.krylov_iterations, t.krylov_fallbacks
                )
            } else {
                String::new()
            },
            t.update,
            t.record
        );
    }
    if let Some(whole) = cost.hooked_over_plain {
        say!(
            con,
            "hooked run over the plain run, per design variable: {:.2} % (everything the {} \
             add{}, the tangents at converged states included)",
            100.0 * whole,
            match (result.time_continuum, result.time_dual) {
                (Some(_), Some(_)) => "continuum DSA and the dual reference",
                (Some(_), None) => "continuum DSA",
                _ => "dual reference",
            },
            if result.time_continuum.is_some() && result.time_dual.is_some() {
                ""
            } else {
                "s"
            }
        );
    }
    for f in &result.failures {
        say!(con, "failed: {f}");
    }
    let status = if result.failures.is_empty() {
        "complete"
    } else {
        "incomplete"
    };
    if let Err(e) = dsa_output::write_json(&path, &dsa_output::to_json(c, &result, status)) {
        err!("error: {e}");
        return EXIT_OUTPUT;
    }
    say!(con, "wrote {} ({status})", path.display());
    if let Some(e) = &result.vtu_error {
        // The other files are still written; the exit status says an output failed.
        err!("error: {e}");
        write_error.get_or_insert_with(|| e.clone());
    }
    if !result.vtu.is_empty() {
        say!(
            con,
            "wrote {} VTU file(s) with the sensitivity fields and {}",
            result.vtu.len(),
            out.join(crate::io::shell_output::PVD_FILE).display()
        );
    }
    match crate::io::dsa_plots::write(out, &result) {
        Ok(files) => say!(
            con,
            "wrote {} figure(s): {}",
            files.len(),
            files
                .iter()
                .filter_map(|f| f.file_name()?.to_str())
                .collect::<Vec<_>>()
                .join(", ")
        ),
        Err(e) => {
            err!("error: {e}");
            return EXIT_OUTPUT;
        }
    }
    if write_error.is_some() {
        // Written in the end, but not while the methods ran.
        return EXIT_OUTPUT;
    }
    let mut code = if result.failures.is_empty() {
        EXIT_OK
    } else {
        EXIT_STOPPED
    };
    if let Some(step) = terms {
        say!(
            con,
            "term breakdown at step {step} (analysis with the dual reference, Dual64):"
        );
        let bs = match study::terms(&analysis, &base, &spec, step) {
            Ok(b) => b,
            Err(e) => {
                err!("error: --terms {step}: {e}");
                return EXIT_STOPPED;
            }
        };
        for b in &bs {
            say!(con, "{}", dsa_output::terms_table(b));
        }
        let path = out.join("terms.json");
        if let Err(e) = dsa_output::write_json(&path, &dsa_output::terms_json(&bs)) {
            err!("error: {e}");
            code = EXIT_OUTPUT;
        } else {
            say!(con, "wrote {}", path.display());
        }
        match crate::io::dsa_plots::write_terms(out, &bs) {
            Ok(p) => say!(con, "wrote {}", p.display()),
            Err(e) => {
                err!("error: {e}");
                code = EXIT_OUTPUT;
            }
        }
    }
    code
}

fn describe(c: &Case) -> String {
    match c {
        Case::MaterialPath(m) => format!(
            "material-path, {} steps, design variable `{}`",
            m.path.n_steps(),
            m.design_name
        ),
        Case::Shell(s) => {
            let mut director = s.integration.director.name().to_string() + " director field";
            if s.integration.director_stabilisation > 0.0 {
                director += &format!(
                    ", director stabilisation ε = {}",
                    s.integration.director_stabilisation
                );
            }
            format!(
                "shell on a {} surface, {} × {} particles, {} basis, {} kernel on supports of {} \
             spacings, {director}, {} boundary condition(s), {} load(s), {} tool(s), {} \
             monitor(s), load factor to {}",
                s.surface.kind(),
                s.particles.counts[0],
                s.particles.counts[1],
                s.kernel.basis,
                s.kernel.function.name(),
                s.kernel.support,
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

fn run(con: &Console, case: &Case, out: &Path, quiet: bool) -> i32 {
    if let Err(e) = std::fs::create_dir_all(out) {
        err!(
            "error: cannot create output directory {}: {e}",
            out.display()
        );
        return EXIT_OUTPUT;
    }
    match case {
        Case::MaterialPath(c) => {
            report(con, case);
            match run_material_path(con, c, out, quiet) {
                Ok(code) => code,
                Err(Failure { code, message }) => {
                    err!("error: {message}");
                    code
                }
            }
        }
        Case::Shell(c) => run_shell(con, c, out, quiet),
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

fn run_shell(con: &Console, c: &ShellCase, out: &Path, quiet: bool) -> i32 {
    let start = Instant::now();
    let built =
        shell_build::build(c).and_then(|b| shell_build::tools_clear_of_the_sheet(&b).map(|()| b));
    let mut built = match built {
        Ok(b) => b,
        Err(e) => {
            err!("error: {}: {e}", c.path.display());
            return EXIT_BAD_INPUT;
        }
    };
    let unknowns = crate::solver::NonlinearProblem::n_dofs(&built.problem);
    let particle_dofs = shell_build::problem_model(&built.problem).n_dofs();
    let multipliers = match unknowns.saturating_sub(particle_dofs) {
        0 => String::new(),
        m => format!(" ({particle_dofs} of the particles, {m} constraint multiplier(s))"),
    };
    say!(
        con,
        "{}: {} particles, {} unknowns{multipliers}, {} quadrature points × {} layers (built in \
         {:.2} s)",
        c.title,
        built.n_particles,
        unknowns,
        shell_build::problem_model(&built.problem).points.len(),
        shell_build::problem_model(&built.problem)
            .thickness_rule
            .len(),
        start.elapsed().as_secs_f64()
    );
    let gauge = built.problem.gauge_modes();
    if !gauge.is_empty() {
        say!(
            con,
            "{} coefficient mode(s) invisible to the field (patterns alternating from particle \
             to particle between symmetry planes, support near a multiple of 4 spacings; largest \
             field transfer {:.1e}) fixed by one zero-valued constraint row each \
             (docs/stability.md)",
            gauge.len(),
            gauge.iter().map(|m| m.transfer).fold(0.0, f64::max)
        );
    }
    report_lines(con, crate::io::shell_report(c));
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
    let mut checkerboard_seen = false;
    let result = shell_build::run(c, &mut built, out, start, |s| {
        let mut line = step_line(c, s);
        if !checkerboard_seen && checkerboard_warning(s).is_some() {
            checkerboard_seen = true;
            line.push_str(
                "\nwarning: the director changes are mostly a pattern the RK approximation does \
                 not resolve: a director checkerboard (details at the end of the run)",
            );
        }
        match &bar {
            Some(b) => {
                b.println(printable(&line));
                b.set_position((1000.0 * s.load_factor / final_load).round() as u64);
                b.set_message(format!("{:.4e} / {final_load:e}", s.load_factor));
            }
            None if !quiet => con.line(&line),
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
                    say!(con, "{}", step_line(c, s));
                }
            }
            for w in &summary.warnings {
                say!(con, "warning: {w}");
            }
            let complete = matches!(summary.status, RunStatus::Complete);
            // Arc-length control stops at the first converged step at or past `final_load`:
            // a step long against the path to it overshoots, and the run has few points.
            if let (Some([ds, _, ds_max]), Some(s), true) = (c.steps.arc_length, last, complete) {
                let end = c.steps.final_load;
                let past = (s.load_factor - end) / end.abs();
                if past > 0.1 {
                    say!(
                        con,
                        "warning: the arc-length run ended at load factor {:.6e}, {:.0} % past \
                         steps.final_load = {end:e}, in {} converged step(s): the arc lengths \
                         (steps.arc_length = {ds:e}, steps.max_arc_length = {ds_max:e}) are long \
                         against this path; shorter ones land closer and trace it with more \
                         points",
                        s.load_factor,
                        100.0 * past,
                        summary.steps.len()
                    );
                }
            }
            if let (Some(cs), None, true) = (&c.contact, &summary.separation, complete) {
                if let Some(r) = &cs.release {
                    say!(
                        con,
                        "warning: the release tool `{r}` did not separate from the sheet"
                    );
                }
            }
            say!(
                con,
                "{}: {} converged step(s) in {} attempt(s), load factor {:e}, {:.2} s; results in {}",
                summary.status.label(),
                summary.steps.len(),
                summary.attempts,
                last.map_or(0.0, |s| s.load_factor),
                summary.wall_time_s,
                out.display()
            );
            if let Some((s, what)) = summary
                .steps
                .iter()
                .find_map(|s| checkerboard_warning(s).map(|w| (s, w)))
            {
                let remedy = match c.integration.director {
                    crate::shell::point::DirectorField::Interpolated => {
                        "integration.director = \"normalised\" or \
                         integration.director_stabilisation"
                    }
                    crate::shell::point::DirectorField::Normalised => {
                        "integration.director_stabilisation or more particles"
                    }
                };
                say!(
                    con,
                    "warning: at converged step {} (load factor {:e}) {what} are a pattern that \
                     the RK approximation does not pass to the shell: a checkerboard of the \
                     director rotations (docs/stability.md §10; per step in results.json, \
                     `director_unresolved` and `director_unresolved_step`); the path from there \
                     is likely spurious. Remedy: {}.",
                    s.step,
                    s.load_factor,
                    remedy
                );
            }
            if let (Some((n, smallest)), Some(cs)) = (summary.stopped_switching, &c.contact) {
                let penalty = cs.penalty.as_key();
                say!(
                    con,
                    "note: each of the {n} attempts after the last converged step changed the \
                     contact active set (a slave point started or stopped penetrating a tool) \
                     and failed, down to a step of {smallest:.3e}: a shorter step does not help. \
                     A penalty too stiff for the sheet's bending stiffness does this (one \
                     switching point moves the sheet far more than the step does); try a \
                     smaller [contact] penalty (here {penalty}; docs/contact.md §5)."
                );
            } else if matches!(summary.status, RunStatus::Failed(_))
                && c.integration.director == crate::shell::point::DirectorField::Interpolated
                && c.integration.director_stabilisation == 0.0
                && c.steps.arc_length.is_none()
            {
                say!(
                    con,
                    "note: under load control a run stops at a limit point, a bifurcation or where \
                     a spurious mode loses its stiffness. With the interpolated director field \
                     (integration.director = \"interpolated\") a director checkerboard can \
                     soften under compression until it stops the run; the default \
                     integration.director = \"normalised\" keeps its stiffness \
                     (docs/stability.md §9). A true limit point needs [steps] control = \
                     \"arc-length\"."
                );
            }
            match &summary.status {
                RunStatus::Complete => EXIT_OK,
                RunStatus::Failed(reason) => {
                    // The reason on standard error too, for a caller that keeps only that.
                    err!(
                        "error: the analysis stopped after {} converged step(s), at load factor {:e}: \
                         {reason}",
                        summary.steps.len(),
                        last.map_or(0.0, |s| s.load_factor)
                    );
                    EXIT_STOPPED
                }
            }
        }
        Err(e) => {
            err!("error: {e}");
            match e {
                BuildError::Output(_) => EXIT_OUTPUT,
                _ => EXIT_BAD_INPUT,
            }
        }
    }
}

/// What of a converged step's director changes is unresolved beyond the warning levels
/// (`shell::stabilisation`), in words; `None` below both.
fn checkerboard_warning(s: &StepSummary) -> Option<String> {
    use crate::shell::stabilisation::{UNRESOLVED_SHARE_WARNING, UNRESOLVED_STEP_SHARE_WARNING};
    let total = s.director_unresolved.unwrap_or(0.0);
    let step = s.director_unresolved_step.unwrap_or(0.0);
    if total > UNRESOLVED_SHARE_WARNING {
        Some(format!(
            "{:.0} % of the particles' director changes since the start (more than {:.0} %)",
            100.0 * total,
            100.0 * UNRESOLVED_SHARE_WARNING
        ))
    } else if step > UNRESOLVED_STEP_SHARE_WARNING {
        Some(format!(
            "{:.0} % of the step's director changes (more than {:.0} %)",
            100.0 * step,
            100.0 * UNRESOLVED_STEP_SHARE_WARNING
        ))
    } else {
        None
    }
}

/// A failed command: its exit status and message.
struct Failure {
    code: i32,
    message: String,
}

/// A failure of the computation on the case's data.
fn bad_input(e: impl std::fmt::Display) -> Failure {
    Failure {
        code: EXIT_BAD_INPUT,
        message: e.to_string(),
    }
}

/// A failure to write a result.
fn output_error(e: impl std::fmt::Display) -> Failure {
    Failure {
        code: EXIT_OUTPUT,
        message: e.to_string(),
    }
}

fn run_material_path(
    con: &Console,
    c: &MaterialPathCase,
    out: &Path,
    quiet: bool,
) -> Result<i32, Failure> {
    let start = Instant::now();
    let p = &c.path;
    // Time each method on its own.
    let t = Instant::now();
    let (states, plastic) = p.run::<f64>(p.tau).map_err(bad_input)?;
    let t_analysis = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let hand = p.hand_derived().map_err(bad_input)?;
    let t_continuum = (t.elapsed().as_secs_f64() - t_analysis).max(0.0);
    let t = Instant::now();
    let (dual_states, _) = p
        .run(Dual::from_re(p.tau).derivative())
        .map_err(bad_input)?;
    let t_dual = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let (sp, _) = p.run::<f64>(p.tau + c.fd_step).map_err(bad_input)?;
    let (sm, _) = p.run::<f64>(p.tau - c.fd_step).map_err(bad_input)?;
    let t_fd = t.elapsed().as_secs_f64();
    let check = p
        .check(
            c.fd_step,
            Tolerance::rel(c.check.dual_rel),
            Tolerance {
                rel: c.check.fd_rel,
                floor: c.check.fd_floor,
            },
        )
        .map_err(bad_input)?;

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
                crate::io::shell_output::csv_field(STATE_LABELS[i]),
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
    let write = |name: &str, bytes: &[u8]| {
        let path = out.join(name);
        crate::io::vtu::replace_file(&path, bytes)
            .map_err(|e| output_error(format!("cannot write {}: {e}", path.display())))
    };
    let text = serde_json::to_string_pretty(&results).map_err(output_error)?;
    write("results.json", text.as_bytes())?;
    write("sensitivity.csv", csv.as_bytes())?;
    plot_material_path(
        c,
        &states,
        &hand.sensitivities,
        &dual_states,
        &sp,
        &sm,
        &check,
        &out.join("sensitivity.png"),
    )
    .map_err(output_error)?;

    say!(
        con,
        "{} — design variable `{}` at τ = {}",
        c.title,
        c.design_name,
        p.tau
    );
    if !quiet {
        say!(
            con,
            "{:>4} {:>7} {:>14} {:>14} {:>14} {:>14} {:>9}",
            "step",
            "status",
            "σ11",
            "σ̇11 continuum",
            "σ̇11 dual",
            "σ̇11 FD",
            "FD/cont%"
        );
        for k in 0..p.n_steps() {
            let fd = (sp[k].stress[0] - sm[k].stress[0]) / (2.0 * c.fd_step);
            let h = hand.sensitivities[k].stress[0];
            say!(
                con,
                "{:>4} {:>7} {:>14.6e} {:>14.6e} {:>14.6e} {:>14.6e} {:>9.4}",
                k + 1,
                if plastic[k] { "plastic" } else { "elastic" },
                states[k].stress[0],
                h,
                dual_states[k].stress[0].eps,
                fd,
                100.0 * fd / h
            );
        }
        say!(
            con,
            "\nper-step errors (all 11 history components, scaled):\n{check}"
        );
    } else {
        say!(con, "{}\n{}", check.vs_dual, check.vs_fd);
    }
    say!(
        con,
        "timing: analysis {:.3e} s, continuum DSA {:.3e} s, dual {:.3e} s, FD {:.3e} s",
        t_analysis,
        t_continuum,
        t_dual,
        t_fd
    );
    say!(
        con,
        "wrote results.json, sensitivity.csv and sensitivity.png to {}",
        out.display()
    );
    say!(
        con,
        "{}",
        if passed {
            "derivative check: PASSED"
        } else {
            "derivative check: FAILED"
        }
    );
    Ok(if passed { EXIT_OK } else { EXIT_CHECK_FAILED })
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
) -> Result<(), crate::io::plot::PlotError> {
    use crate::io::plot::{figure, Panel, Scale, Series, Style};
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
                x_scale: Scale::Linear,
                y_scale: Scale::Linear,
                series: vec![
                    Series {
                        label: "σ11",
                        points: steps(&|k| states[k].stress[0]),
                        style: Style::Line,
                    },
                    Series {
                        label: "σ12",
                        points: steps(&|k| states[k].stress[2]),
                        style: Style::Line,
                    },
                    Series {
                        label: "α11",
                        points: steps(&|k| states[k].back_stress[0]),
                        style: Style::Line,
                    },
                ],
            },
            Panel {
                title: &title,
                x_label: "step",
                y_label: "dσ11/dτ",
                x_scale: Scale::Linear,
                y_scale: Scale::Linear,
                series: vec![
                    Series {
                        label: "continuum (eqs 44-49)",
                        points: steps(&|k| hand[k].stress[0]),
                        style: Style::Line,
                    },
                    Series {
                        label: "dual numbers",
                        points: steps(&|k| dual[k].stress[0].eps),
                        style: Style::Dots,
                    },
                    Series {
                        label: "central difference",
                        points: steps(&|k| (sp[k].stress[0] - sm[k].stress[0]) / (2.0 * h)),
                        style: Style::Dots,
                    },
                ],
            },
            Panel {
                title: "worst scaled error per step (all 11 history components)",
                x_label: "step",
                y_label: "error",
                x_scale: Scale::Linear,
                y_scale: Scale::Log,
                series: vec![
                    Series {
                        label: "continuum vs dual",
                        points: steps(&|k| check.per_step[k].dual_error),
                        style: Style::Dots,
                    },
                    Series {
                        label: "continuum vs FD",
                        points: steps(&|k| check.per_step[k].fd_error),
                        style: Style::Dots,
                    },
                ],
            },
        ],
    )
}
