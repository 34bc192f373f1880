//! The command line under output errors and bad arguments: standard output closed by its
//! reader (a broken pipe) or on a full device, a results file that cannot be written, `dsa`
//! arguments and output directories refused before any analysis, a failed finite-difference
//! re-run that keeps the other variables, CSV fields with commas and quotes, and names with
//! control characters. The binary is spawned (its standard output is what is under test).

use serde_json::Value;
use shelldsa::cli::{EXIT_BAD_INPUT, EXIT_OK, EXIT_OUTPUT, EXIT_STOPPED};
use shelldsa::io::shell_case::parse_shell_case;
use shelldsa::io::shell_output::csv_field;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};

fn unique_dir(tag: &str) -> PathBuf {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let dir = std::env::temp_dir().join(format!(
        "shelldsa-cli-output-{tag}-{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn shelldsa() -> Command {
    Command::new(env!("CARGO_BIN_EXE_shelldsa"))
}

/// A clamped cantilever strip (L = 12, b = 1, t = 0.1, E = 1.2e6, ν = 0, 13 × 3 particles)
/// with a tip force `force`, yield stress `sigma0` (5 Lobatto layers), load steps `steps` and
/// the extra text `extra` (design tables).
fn cantilever(force: f64, sigma0: f64, steps: &str, extra: &str) -> String {
    format!(
        r#"
thickness = 0.1
[problem]
kind = "shell"
title = "cantilever"
[surface]
type = "rectangle"
origin = [0.0, 0.0, 0.0]
edge_u = [12.0, 0.0, 0.0]
edge_v = [0.0, 1.0, 0.0]
[particles]
grid = [13, 3]
[kernel]
basis = "quadratic"
support = 3.0
[integration]
cells = "per-particle-spacing"
gauss = 3
thickness_points = 5
thickness_rule = "lobatto"
[material]
young = 1.2e6
poisson = 0.0
sigma0 = {sigma0:e}
hardening = 0.0
beta = 1.0
[[boundary]]
kind = "clamped"
edge = "u-min"
[[load]]
kind = "point-force"
at = [1.0, 0.5]
force = [0.0, 0.0, {force:e}]
[steps]
{steps}
[[monitor]]
name = "tip"
at = [1.0, 0.5]
{extra}
"#
    )
}

/// An elastic cantilever in `n` equal load steps.
fn elastic(n: usize) -> String {
    let h = 1.0 / n as f64;
    cantilever(
        1e-4,
        1e30,
        &format!("initial_step = {h:e}\nmin_step = {h:e}\nmax_step = {h:e}"),
        "",
    )
}

/// `shelldsa COMMAND CASE --out OUT`, its output captured.
fn command_into(command: &str, case: &Path, out: &Path) -> Output {
    shelldsa()
        .args([
            command,
            case.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .output()
        .unwrap()
}

/// `shelldsa run CASE --out OUT`, its output captured.
fn run_into(case: &Path, out: &Path) -> Output {
    command_into("run", case, out)
}

fn write_case(dir: &Path, text: &str) -> PathBuf {
    let case = dir.join("case.toml");
    std::fs::write(&case, text).unwrap();
    case
}

/// `shelldsa dsa` on the case `text` written into `dir`, with its output in `dir/out`: the
/// process' output (checked for a panic) and the output directory.
fn dsa_in(dir: &Path, text: &str) -> (Output, PathBuf) {
    let case = write_case(dir, text);
    let out = dir.join("out");
    let o = command_into("dsa", &case, &out);
    assert_no_panic(&o);
    (o, out)
}

/// `shelldsa run CASE --out OUT` started with its standard output and error piped to the test.
fn spawn_run(case: &Path, out: &Path) -> std::process::Child {
    shelldsa()
        .args([
            "run",
            case.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// No panic message and not Rust's panic exit status.
fn assert_no_panic(out: &Output) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_ne!(out.status.code(), Some(101), "{stderr}");
}

/// Every `*.tmp` file under `dir`.
fn tmp_files(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            found.extend(tmp_files(&p));
        } else if p.extension().is_some_and(|x| x == "tmp") {
            found.push(p);
        }
    }
    found
}

/// The files of a complete run of `n` steps: results.json final with every step, the PVD with
/// the initial state and every step, steps.jsonl with every step, no temporary file.
fn assert_complete_run(out: &Path, n: usize) {
    let res = json(&out.join("results.json"));
    assert_eq!(res["status"], "complete");
    assert_eq!(res["steps"].as_array().unwrap().len(), n);
    let pvd = std::fs::read_to_string(out.join("shell.pvd")).unwrap();
    assert_eq!(pvd.matches("<DataSet").count(), n + 1);
    let log = std::fs::read_to_string(out.join("steps.jsonl")).unwrap();
    let lines: Vec<Value> = log
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), n);
    assert_eq!(lines[n - 1]["step"], n);
    assert!(tmp_files(out).is_empty(), "{:?}", tmp_files(out));
}

/// `shelldsa run CASE | head -0`: the reader closes standard output before the first line. The
/// run must not panic, must finish with its usual status and write all its files.
#[test]
fn run_with_stdout_closed_by_its_reader_finishes_its_files() {
    let dir = unique_dir("pipe-closed");
    let case = write_case(&dir, &elastic(40));
    let out = dir.join("out");
    let mut child = spawn_run(&case, &out);
    drop(child.stdout.take()); // the read end closed: every write gets EPIPE
    let o = child.wait_with_output().unwrap();
    assert_no_panic(&o);
    assert_eq!(o.status.code(), Some(EXIT_OK));
    // Quiet: a closed pipe is not an error to report.
    assert!(
        o.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert_complete_run(&out, 40);
    let _ = std::fs::remove_dir_all(&dir);
}

/// `shelldsa run CASE | head -1`: the reader takes one line and goes. Whether later lines meet
/// the closed pipe depends on timing; either way no panic, exit 0 and complete files.
#[test]
fn run_piped_into_head_1_finishes_its_files() {
    let dir = unique_dir("pipe-head");
    let case = write_case(&dir, &elastic(40));
    let out = dir.join("out");
    let mut child = spawn_run(&case, &out);
    let mut first = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    assert!(first.starts_with("cantilever: "), "{first}");
    let o = child.wait_with_output().unwrap();
    assert_no_panic(&o);
    assert_eq!(o.status.code(), Some(EXIT_OK));
    assert_complete_run(&out, 40);
    let _ = std::fs::remove_dir_all(&dir);
}

/// `shelldsa run CASE > /dev/full`: a clear error on standard error, once; the run still writes
/// its files; exit status 4 (output error).
#[test]
fn run_with_stdout_on_a_full_device_reports_an_output_error() {
    let Ok(full) = std::fs::OpenOptions::new().write(true).open("/dev/full") else {
        println!("no /dev/full on this system: nothing to test");
        return;
    };
    let dir = unique_dir("dev-full");
    let case = write_case(&dir, &elastic(5));
    let out = dir.join("out");
    let o = shelldsa()
        .args([
            "run",
            case.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .stdout(full)
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    assert_no_panic(&o);
    assert_eq!(o.status.code(), Some(EXIT_OUTPUT));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(
        stderr.matches("cannot write to standard output").count(),
        1,
        "{stderr}"
    );
    assert!(stderr.contains("No space left on device"), "{stderr}");
    assert_complete_run(&out, 5);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A results file that cannot be written (here the temporary VTU of step 3 is a link to
/// /dev/full, which takes no byte: as a full disk): the run stops with exit status 4 and an
/// error naming the file, results.json gets a final status naming the failure (not
/// "running"), steps.jsonl keeps the converged steps, and no temporary file is left.
#[test]
fn a_full_disk_while_writing_results_is_an_output_error() {
    if !Path::new("/dev/full").exists() {
        println!("no /dev/full on this system: nothing to test");
        return;
    }
    let dir = unique_dir("disk-full");
    let case = write_case(&dir, &elastic(6));
    let out = dir.join("out");
    std::fs::create_dir_all(out.join("steps")).unwrap();
    std::os::unix::fs::symlink("/dev/full", out.join("steps/step_0003.vtu.tmp")).unwrap();
    let o = run_into(&case, &out);
    assert_no_panic(&o);
    assert_eq!(o.status.code(), Some(EXIT_OUTPUT));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains("step_0003.vtu") && stderr.contains("No space left"),
        "{stderr}"
    );
    let res = json(&out.join("results.json"));
    let status = res["status"].as_str().unwrap();
    assert!(
        status.starts_with("failed: writing results: ") && status.contains("No space left"),
        "{status}"
    );
    // Steps 1 and 2 converged and were recorded; step 3's results failed.
    let log = std::fs::read_to_string(out.join("steps.jsonl")).unwrap();
    assert_eq!(log.lines().count(), 2, "{log}");
    let converged = res["steps"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|s| s["converged"] == true)
        .count();
    assert_eq!(converged, 2, "{res}");
    assert!(tmp_files(&out).is_empty(), "{:?}", tmp_files(&out));
    let _ = std::fs::remove_dir_all(&dir);
}

/// `shelldsa dsa`'s arguments and output directory are checked before any analysis: nothing
/// is printed on standard output (the first line would follow the plain analysis) and each
/// error names the argument.
#[test]
fn dsa_refuses_bad_arguments_before_the_analysis() {
    let dir = unique_dir("dsa-checks");
    let design = "[[design]]\nname = \"t\"\nkind = \"thickness\"\nfd_steps = [1e-4]\n\
                  [dsa]\nmonitors = [\"tip\"]\nmethods = [\"fd\"]\n";
    let case = write_case(
        &dir,
        &cantilever(
            1e-4,
            1e30,
            "initial_step = 0.25\nmin_step = 0.25\nmax_step = 0.25",
            design,
        ),
    );
    let out = dir.join("out");
    let dsa = |extra: &[&str], out: &Path| {
        let o = shelldsa()
            .args([
                "dsa",
                case.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
            ])
            .args(extra)
            .output()
            .unwrap();
        assert_no_panic(&o);
        assert!(
            o.stdout.is_empty(),
            "{}",
            String::from_utf8_lossy(&o.stdout)
        );
        (
            o.status.code(),
            String::from_utf8_lossy(&o.stderr).to_string(),
        )
    };
    // Step 0, and a step beyond what the case can take (4 steps of 0.25: at most 1/0.25 + 1).
    for step in ["0", "99999"] {
        let (code, e) = dsa(&["--terms", step], &out);
        assert_eq!(code, Some(EXIT_BAD_INPUT), "{e}");
        assert!(
            e.contains(&format!("--terms {step}")) && e.contains("1..=5"),
            "{e}"
        );
    }
    let (code, e) = dsa(&["--methods", "fd,adjoint"], &out);
    assert_eq!(code, Some(EXIT_BAD_INPUT), "{e}");
    assert!(e.contains("--methods") && e.contains("adjoint"), "{e}");
    assert!(!out.exists(), "nothing is written for bad arguments");
    // An output directory that cannot be created (its parent is a file).
    let blocker = dir.join("file");
    std::fs::write(&blocker, "not a directory").unwrap();
    let (code, e) = dsa(&[], &blocker.join("out"));
    assert_eq!(code, Some(EXIT_OUTPUT), "{e}");
    assert!(e.contains("cannot create output directory"), "{e}");
    // An output directory whose sensitivity.json cannot be written (a directory of that name).
    std::fs::create_dir_all(out.join("sensitivity.json")).unwrap();
    let (code, e) = dsa(&[], &out);
    assert_eq!(code, Some(EXIT_OUTPUT), "{e}");
    assert!(e.contains("sensitivity.json"), "{e}");
    assert!(tmp_files(&out).is_empty(), "{:?}", tmp_files(&out));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A finite-difference re-run that fails: the elastic–perfectly plastic cantilever (σ0 = 100)
/// carries P = 0.02 in four fixed steps (its last converged level with σ0 = 100 is 0.025, see
/// tests/shell_output.rs), but not with σ0 halved, which the step 0.5 of `s0` asks for at
/// τ − h (the limit load scales with σ0). That re-run is reported with its variable and h;
/// the other step size of `s0`, and the variable `t` after it, are kept; exit status 3.
#[test]
fn dsa_keeps_the_other_variables_when_a_re_run_fails() {
    let dir = unique_dir("dsa-fd-failure");
    let design = "[[design]]\nname = \"s0\"\nkind = \"material.sigma0\"\nfd_steps = [1e-3, 0.5]\n\
                  [[design]]\nname = \"t\"\nkind = \"thickness\"\nfd_steps = [1e-3]\n\
                  [dsa]\nmonitors = [\"tip\"]\nmethods = [\"fd\"]\n";
    let (o, out) = dsa_in(
        &dir,
        &cantilever(
            0.02,
            100.0,
            "initial_step = 0.25\nmin_step = 0.25\nmax_step = 0.25\nmax_iterations = 12",
            design,
        ),
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(EXIT_STOPPED), "{stdout}");
    assert!(
        stdout.contains("failed: fd: re-run of `s0` at τ − h (h = 5e1"),
        "{stdout}"
    );
    let s = json(&out.join("sensitivity.json"));
    assert_eq!(s["status"], "incomplete");
    let failures = s["failures"].as_array().unwrap();
    assert_eq!(failures.len(), 1, "{failures:?}");
    assert_eq!(failures[0]["method"], "fd");
    assert_eq!(failures[0]["variable"], "s0");
    assert_eq!(failures[0]["h"], -50.0);
    assert_eq!(failures[0]["fd_step_relative"], 0.5);
    let vars = s["variables"].as_array().unwrap();
    assert_eq!(vars.len(), 2);
    // s0 keeps its 1e-3 column (h = 1e-3 · 100); t its only one, with a derivative at every
    // step (the thickness changes the elastic response too).
    let h = vars[0]["fd_steps"].as_array().unwrap();
    assert_eq!(h.len(), 1);
    assert!((h[0].as_f64().unwrap() - 0.1).abs() <= 1e-15, "{h:?}");
    assert_eq!(vars[1]["name"], "t");
    assert_eq!(vars[1]["fd_steps"].as_array().unwrap().len(), 1);
    let steps = vars[1]["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 4);
    for st in steps {
        let fd = st["monitors"]["tip.uz"]["fd_central"][0].as_f64().unwrap();
        assert!(fd.is_finite() && fd != 0.0, "{st}");
    }
    assert!(tmp_files(&out).is_empty());
    let _ = std::fs::remove_dir_all(&dir);
}

/// A `dsa` whose plain analysis stops (the elastic–perfectly plastic cantilever asked for about
/// twice its limit load, as in tests/shell_output.rs: the last converged level is P = 0.025 of
/// the 0.04 asked for) keeps the converged steps in sensitivity.json, with the failure as its
/// status, and exits with 3.
#[test]
fn dsa_whose_analysis_stops_keeps_its_converged_steps() {
    let dir = unique_dir("dsa-analysis-stops");
    let design = "[[design]]\nname = \"t\"\nkind = \"thickness\"\nfd_steps = [1e-3]\n\
                  [dsa]\nmonitors = [\"tip\"]\nmethods = [\"continuum\", \"dual\"]\n";
    let (o, out) = dsa_in(
        &dir,
        &cantilever(
            0.04,
            100.0,
            "initial_step = 0.25\nmin_step = 0.05\nmax_step = 0.25\nmax_iterations = 12",
            design,
        ),
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(EXIT_STOPPED), "{stdout}");
    let s = json(&out.join("sensitivity.json"));
    let status = s["status"].as_str().unwrap();
    assert!(status.starts_with("failed: analysis"), "{status}");
    let loads: Vec<f64> = s["loads"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l.as_f64().unwrap())
        .collect();
    // At least the elastic first step (0.25) converged, and not the whole load.
    assert!(loads.len() >= 2, "{loads:?}");
    assert!(loads.windows(2).all(|w| w[0] < w[1]) && loads[loads.len() - 1] < 1.0);
    let steps = s["variables"][0]["steps"].as_array().unwrap();
    assert_eq!(steps.len(), loads.len());
    for st in steps {
        let v = st["monitors"]["tip.uz"]["value"].as_f64().unwrap();
        assert!(v > 0.0, "{st}");
    }
    assert!(tmp_files(&out).is_empty());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `dsa` hands its results over after every converged step of the plain analysis and of the run
/// with the derivative methods (so sensitivity.json follows the run step by step), and the
/// derivative columns grow one step at a time.
#[test]
fn dsa_updates_after_every_converged_step() {
    use shelldsa::io::dsa_case::DsaMethod;
    use shelldsa::io::dsa_study::{self, base_design, CaseAnalysis};
    use shelldsa::sensitivity::study;
    let dir = unique_dir("dsa-step-updates");
    let design = "[[design]]\nname = \"t\"\nkind = \"thickness\"\nfd_steps = [1e-3]\n\
                  [dsa]\nmonitors = [\"tip\"]\n";
    let text = cantilever(
        1e-4,
        1e30,
        "initial_step = 0.2\nmin_step = 0.2\nmax_step = 0.2",
        design,
    );
    let path = write_case(&dir, &text);
    let case = parse_shell_case(&text, &path).unwrap();
    let methods = [DsaMethod::Continuum, DsaMethod::Dual];
    let spec = dsa_study::validate(&case, &methods).unwrap();
    // (nominal steps, continuum steps, dual steps) at each update.
    let mut seen: Vec<(usize, usize, usize)> = Vec::new();
    let r = study::run_observed(
        &CaseAnalysis { case: &case },
        &base_design(&case),
        &spec,
        None,
        &mut |_| {},
        &mut |r| {
            let v = &r.variables[0];
            seen.push((
                r.nominal.loads.len(),
                v.continuum.as_ref().map_or(0, |c| c.len()),
                v.dual.as_ref().map_or(0, |d| d.len()),
            ));
        },
    )
    .unwrap();
    let n = r.nominal.loads.len();
    assert_eq!(n, 5);
    for k in 1..=n {
        assert!(seen.contains(&(k, 0, 0)), "plain step {k}: {seen:?}");
        assert!(seen.contains(&(n, k, k)), "hooked step {k}: {seen:?}");
    }
    // The columns handed over while the run went on are the final ones' leading steps.
    assert_eq!(r.variables[0].continuum.as_ref().unwrap().len(), n);
    let _ = std::fs::remove_dir_all(&dir);
}

/// RFC 4180 fields: quoted (quotes doubled) when they hold a comma, a quote, a line break or
/// edge white space.
#[test]
fn csv_fields_are_quoted_when_needed() {
    assert_eq!(csv_field("punch_fx"), "punch_fx");
    assert_eq!(csv_field("punch, left_fx"), "\"punch, left_fx\"");
    assert_eq!(csv_field("the \"die\"_x"), "\"the \"\"die\"\"_x\"");
    assert_eq!(csv_field("a\nb"), "\"a\nb\"");
    assert_eq!(csv_field(" pad"), "\" pad\"");
}

/// Names and titles with control characters (a terminal escape sequence, a line break) are
/// rejected when the case is read, the error naming the key.
#[test]
fn names_with_control_characters_are_rejected_naming_the_key() {
    let base = elastic(2);
    for (from, to, key) in [
        (
            "title = \"cantilever\"",
            "title = \"\\u001b[31mred\"",
            "problem.title",
        ),
        ("name = \"tip\"", "name = \"tip\\u0007\"", "monitor[0].name"),
        ("name = \"tip\"", "name = \"t\\nip\"", "monitor[0].name"),
    ] {
        let text = base.replace(from, to);
        assert_ne!(text, base);
        let e = parse_shell_case(&text, Path::new("c.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(key) && e.contains("control characters"),
            "{key}: {e}"
        );
        // The value is shown escaped in the message, never raw.
        assert!(!e.contains('\u{1b}') && !e.contains('\u{7}'), "{e:?}");
    }
}

/// Fields of one CSV line (RFC 4180: quoted fields with doubled quotes).
fn csv_line(line: &str) -> Vec<String> {
    let mut fields = vec![String::new()];
    let (mut quoted, mut chars) = (false, line.chars().peekable());
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                chars.next();
                fields.last_mut().unwrap().push('"');
            }
            ('"', _) => quoted = !quoted,
            (',', false) => fields.push(String::new()),
            (c, _) => fields.last_mut().unwrap().push(c),
        }
    }
    fields
}

/// A tool named with a comma and quotes: tool_forces.csv quotes its header fields, so that a
/// CSV reader finds the same number of fields in the header as in every row.
#[test]
fn tool_names_with_commas_are_quoted_in_tool_forces_csv() {
    let name = "punch, \\\"A\\\""; // TOML for: punch, "A"
    let case = format!(
        r#"
thickness = 0.1
[problem]
kind = "shell"
title = "plate and tools"
[surface]
type = "rectangle"
origin = [0.0, 0.0, 0.0]
edge_u = [4.0, 0.0, 0.0]
edge_v = [0.0, 1.0, 0.0]
[particles]
grid = [9, 3]
[kernel]
basis = "quadratic"
support = 3.0
[integration]
cells = "per-particle-spacing"
gauss = 2
thickness_points = 3
thickness_rule = "lobatto"
[material]
young = 1000.0
poisson = 0.3
sigma0 = 1e30
hardening = 0.0
beta = 1.0
[[boundary]]
kind = "fixed"
everywhere = true
components = ["ux", "uy"]
[[load]]
kind = "gravity"
per_area = [0.0, 0.0, -1e-3]
scaling = "constant"
[steps]
initial_step = 0.5
min_step = 0.1
max_step = 0.5
predictor = "zero"
residual_atol = 1e-12
[[monitor]]
name = "mid"
at = [0.5, 0.5]
[output]
vtu = false
plot = false
[[tool]]
name = "{name}"
side = "positive"
[tool.surface]
type = "cylinder-sector"
origin = [2.0, -1.0, 1.05]
axis = [0.0, 1.0, 0.0]
reference = [1.0, 0.0, 0.0]
radius = 1.0
angle_deg = [0.0, 180.0]
length = [0.0, 3.0]
[tool.path]
stroke = [0.0, 0.0, 0.5]
[[tool]]
name = "die"
side = "positive"
[tool.surface]
type = "rectangle"
origin = [-1.0, -1.0, -0.0499]
edge_u = [6.0, 0.0, 0.0]
edge_v = [0.0, 3.0, 0.0]
[tool.path]
keys = [{{ t = 0.0, translation = [0.0, 0.0, 0.0] }}]
"#
    );
    let dir = unique_dir("csv-quoting");
    let path = write_case(&dir, &case);
    let out = dir.join("out");
    let o = run_into(&path, &out);
    assert_no_panic(&o);
    assert_eq!(
        o.status.code(),
        Some(EXIT_OK),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let csv = std::fs::read_to_string(out.join("tool_forces.csv")).unwrap();
    let mut lines = csv.lines();
    let header = csv_line(lines.next().unwrap());
    assert_eq!(header.len(), 3 + 2 * 7, "{header:?}");
    assert_eq!(header[3], "punch, \"A\"_x");
    assert_eq!(header[9], "punch, \"A\"_active_points");
    assert_eq!(header[10], "die_x");
    let mut rows = 0;
    for l in lines {
        assert_eq!(csv_line(l).len(), header.len(), "{l}");
        rows += 1;
    }
    assert!(rows >= 2, "{csv}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// SIGKILL at some moment of a run (after 1, 40 and 150 progress lines of a 300-step run, with
/// the rewrites of results.json and the PVD spaced out past step 32): results.json and the PVD
/// are whole and valid (the one from the last rewrite), steps.jsonl holds at least every step
/// results.json lists, each line valid JSON but possibly a last one cut by the kill.
#[test]
fn a_killed_run_leaves_valid_results() {
    let dir = unique_dir("sigkill");
    let case = write_case(&dir, &elastic(300));
    for after in [1usize, 40, 150] {
        let out = dir.join(format!("out-{after}"));
        let mut child = spawn_run(&case, &out);
        let mut reader = BufReader::new(child.stdout.take().unwrap());
        let mut line = String::new();
        // Progress lines of converged steps start with "step"; the header and the case's
        // estimate come before them.
        let mut steps = 0;
        while steps < after {
            line.clear();
            if reader.read_line(&mut line).unwrap() == 0 {
                break; // the run ended first
            }
            if line.starts_with("step ") {
                steps += 1;
            }
        }
        child.kill().unwrap();
        child.wait().unwrap();
        let res = json(&out.join("results.json"));
        let listed = res["steps"].as_array().unwrap().len();
        assert!(
            ["running", "complete"].contains(&res["status"].as_str().unwrap()),
            "{}",
            res["status"]
        );
        let pvd = std::fs::read_to_string(out.join("shell.pvd")).unwrap();
        assert!(pvd.trim_end().ends_with("</VTKFile>"), "{pvd}");
        assert!(pvd.matches("<DataSet").count() > listed, "{pvd}");
        let log = std::fs::read_to_string(out.join("steps.jsonl")).unwrap();
        let whole: Vec<&str> = if log.ends_with('\n') {
            log.lines().collect()
        } else {
            let mut l: Vec<&str> = log.lines().collect();
            l.pop();
            l
        };
        for l in &whole {
            let _: Value = serde_json::from_str(l).unwrap();
        }
        assert!(whole.len() >= listed, "{} < {listed}", whole.len());
        assert!(whole.len() >= after, "{} < {after}", whole.len());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A run into the output directory of a longer earlier run: the earlier run's step files are
/// removed, so `steps/` holds this run's files only (the PVD lists them); other files stay.
#[test]
fn a_rerun_into_the_same_directory_removes_the_earlier_step_files() {
    let dir = unique_dir("rerun");
    let out = dir.join("out");
    let run = |n: usize| {
        let case = write_case(&dir, &elastic(n));
        let o = run_into(&case, &out);
        assert_no_panic(&o);
        assert_eq!(o.status.code(), Some(EXIT_OK));
    };
    let vtus = || {
        let mut v: Vec<String> = std::fs::read_dir(out.join("steps"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    };
    run(6);
    assert_eq!(vtus().len(), 7, "{:?}", vtus());
    std::fs::write(out.join("steps/notes.txt"), "kept").unwrap();
    run(2);
    assert_complete_run(&out, 2);
    assert_eq!(
        vtus(),
        [
            "notes.txt",
            "step_0000.vtu",
            "step_0001.vtu",
            "step_0002.vtu"
        ]
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `shelldsa --help > /dev/full` and `--version`: the output error is reported and the exit
/// status says so, as for any command.
#[test]
fn help_on_a_full_device_is_an_output_error() {
    for flag in ["--help", "--version"] {
        let Ok(full) = std::fs::OpenOptions::new().write(true).open("/dev/full") else {
            println!("no /dev/full on this system: nothing to test");
            return;
        };
        let o = shelldsa()
            .arg(flag)
            .stdout(full)
            .stderr(Stdio::piped())
            .output()
            .unwrap();
        assert_no_panic(&o);
        assert_eq!(o.status.code(), Some(EXIT_OUTPUT), "{flag}");
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(
            stderr.contains("cannot write to standard output"),
            "{stderr}"
        );
    }
}
