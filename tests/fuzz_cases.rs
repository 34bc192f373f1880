//! Case-file fuzzing: mutated case files through `shelldsa check`, and the accepted small ones
//! through a short `shelldsa run`, each in its own process (the binary built with the tests),
//! with a time bound.
//!
//! Every mutant must end in one of the documented exit codes (0 ok, 1 bad input or set-up
//! failure, 2 derivative check outside tolerance, 3 analysis stopped early) within the time
//! bound: a panic (exit 101 or "panicked" on stderr), a signal (abort, stack overflow, out of
//! memory) or a timeout is a failure. A mutant that must be rejected (a non-finite number, a
//! fixed-length array of another length, a negative tolerance, a value of another type, a
//! subnormal finite-difference step, an unknown key) and is accepted by `check` is "nonsense
//! accepted", also a failure; so is a run that exits 0 with a non-finite monitored
//! displacement.
//!
//! The CI run is seeded and bounded: `SHELLDSA_FUZZ_N` mutants (default 1000), a short run of
//! every `SHELLDSA_FUZZ_RUN_EVERY`-th (default 2nd) mutant that `check` accepts and whose
//! estimate is small, and a wall budget `SHELLDSA_FUZZ_BUDGET_S` (default 50 s) after which it
//! stops early and reports how many it tried. A longer run:
//!
//! ```sh
//! SHELLDSA_FUZZ_N=5000 SHELLDSA_FUZZ_SEED=1 SHELLDSA_FUZZ_RUN_EVERY=1 SHELLDSA_FUZZ_BUDGET_S=1500 \
//!     cargo test --release --test fuzz_cases -- --nocapture
//! ```

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use toml::Value;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A small shell case that runs in a fraction of a second: a clamped 1 × 1 plate, 5 × 5
/// particles, a tip force, two load steps, one design variable for the `[[design]]` checks.
const SHELL: &str = r#"
thickness = 0.02

[problem]
kind = "shell"
title = "fuzz plate"

[surface]
type = "rectangle"
origin = [0.0, 0.0, 0.0]
edge_u = [1.0, 0.0, 0.0]
edge_v = [0.0, 1.0, 0.0]

[particles]
grid = [5, 5]
jitter = 0.1
seed = 3

[kernel]
basis = "linear"
support = 2.0

[integration]
cells = "per-particle-spacing"
subdivide = 1
gauss = 2
thickness_points = 3
thickness_rule = "gauss"
vci = "first"

[material]
young = 1.0e5
poisson = 0.3
sigma0 = 1.0e3
hardening = 100.0
beta = 0.5

[[boundary]]
kind = "clamped"
edge = "u-min"

[[boundary]]
kind = "fixed"
at = [1.0, 1.0]
components = ["ux", "uy"]

[[load]]
kind = "point-force"
at = [1.0, 0.5]
force = [0.0, 0.0, 1.0e-4]

[[load]]
kind = "pressure"
value = 1.0e-4
scaling = "proportional"

[steps]
initial_step = 0.5
min_step = 0.01
max_step = 0.5
final_load = 1.0
max_iterations = 15
max_active_set_iterations = 20
residual_rtol = 1e-8
residual_atol = 0.0
energy_rtol = 1e-14
cut_factor = 0.5
grow_factor = 1.5
easy_iterations = 4
predictor = "secant"
stops = [0.5]

[[monitor]]
name = "tip"
at = [1.0, 0.5]

[output]
vtu = false
every = 1
subdivide = 1
plot = false

[[design]]
name = "t"
kind = "thickness"
fd_steps = [1e-3, 1e-4]

[dsa]
methods = ["continuum", "dual", "fd"]
monitors = ["tip.uz"]
"#;

/// A short material-point path.
const PATH: &str = r#"
[problem]
kind = "material-path"
title = "fuzz path"

[material]
young = 210000.0
poisson = 0.3
shear_factor = 0.8333333333333334
sigma0 = 250.0
hardening = 1000.0
beta = 0.5

[design]
name = "tau"
tau = 0.0
fd_step = 1e-6
material_rate = { young = 21000.0, sigma0 = 40.0 }

[[path.segment]]
steps = 6
increment = [4e-4, -1e-4, 2e-4, 0.0, 0.0]
rate = [8e-5, 1e-5, 6e-5, 0.0, 0.0]

[[path.segment]]
steps = 4
increment = [-4e-4, 0.0, 1e-4, 1e-4, 0.0]

[check]
dual_rel = 1e-9
fd_rel = 1e-5
fd_floor = 1e-4
"#;

/// Keys whose arrays have no fixed length.
const VARIABLE_LENGTH: [&str; 10] = [
    "stops",
    "fd_steps",
    "knots_u",
    "knots_v",
    "control_points",
    "components",
    "methods",
    "monitors",
    "keys",
    "cells",
];

/// Keys that hold a tolerance (a negative one must be rejected).
fn is_tolerance(key: &str) -> bool {
    ["rtol", "atol", "_rel", "floor"]
        .iter()
        .any(|s| key.ends_with(s))
}

/// splitmix64: a small, fixed, portable generator (the sequence of mutants is a function of
/// the seed alone).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
    fn pick<'a, T>(&mut self, v: &'a [T]) -> &'a T {
        &v[self.below(v.len())]
    }
}

/// Where a leaf sits: the path of table keys and array indices.
#[derive(Clone, Debug)]
enum Step {
    Key(String),
    Index(usize),
}

fn leaves(v: &Value, path: &mut Vec<Step>, out: &mut Vec<Vec<Step>>) {
    match v {
        Value::Table(t) => {
            for (k, x) in t {
                path.push(Step::Key(k.clone()));
                out.push(path.clone());
                leaves(x, path, out);
                path.pop();
            }
        }
        Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                path.push(Step::Index(i));
                out.push(path.clone());
                leaves(x, path, out);
                path.pop();
            }
        }
        _ => {}
    }
}

fn get_mut<'a>(v: &'a mut Value, path: &[Step]) -> &'a mut Value {
    path.iter().fold(v, |v, s| match (s, v) {
        (Step::Key(k), Value::Table(t)) => t.get_mut(k).unwrap(),
        (Step::Index(i), Value::Array(a)) => &mut a[*i],
        _ => unreachable!(),
    })
}

/// The innermost key of a path (for a leaf inside an array, the array's key).
fn key_of(path: &[Step]) -> String {
    path.iter()
        .rev()
        .find_map(|s| match s {
            Step::Key(k) => Some(k.clone()),
            Step::Index(_) => None,
        })
        .unwrap_or_default()
}

fn dotted(path: &[Step]) -> String {
    let mut s = String::new();
    for p in path {
        match p {
            Step::Key(k) => {
                if !s.is_empty() {
                    s.push('.');
                }
                s.push_str(k);
            }
            Step::Index(i) => s.push_str(&format!("[{i}]")),
        }
    }
    s
}

/// One mutation and whether the mutant must be rejected.
struct Mutant {
    text: String,
    what: String,
    must_reject: bool,
}

const SPECIAL: [f64; 14] = [
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    0.0,
    -1.0,
    1e308,
    -1e308,
    5e-324,
    1e-300,
    1e12,
    0.5,
    2.0,
    1e-20,
    -1e-9,
];

const STRINGS: [&str; 9] = [
    "",
    "x",
    "\u{1b}[31mred\u{1b}[0m",
    "u-min",
    "clamped",
    "linear",
    "ux",
    "thickness",
    "continuum",
];

fn mutate(base: &str, rng: &mut Rng) -> Mutant {
    let mut v: Value = Value::Table(toml::from_str(base).unwrap());
    let mut all = Vec::new();
    leaves(&v, &mut Vec::new(), &mut all);
    let path = rng.pick(&all).clone();
    let key = key_of(&path);
    let node = get_mut(&mut v, &path);
    let mut must_reject = false;
    let what;
    match node.clone() {
        Value::Float(_) | Value::Integer(_) => {
            let choice = rng.below(SPECIAL.len() + 4);
            if choice < SPECIAL.len() {
                let x = SPECIAL[choice];
                // Integers where the key holds one; floats elsewhere.
                *node = if matches!(node, Value::Integer(_)) && x.fract() == 0.0 && x.abs() < 1e15 {
                    Value::Integer(x as i64)
                } else {
                    Value::Float(x)
                };
                must_reject = !x.is_finite()
                    || (is_tolerance(&key) && x < 0.0)
                    || (key.starts_with("fd_step") && x > 0.0 && x < f64::MIN_POSITIVE);
                what = format!("{} = {x:e}", dotted(&path));
            } else if choice == SPECIAL.len() {
                *node = Value::String("1".into());
                must_reject = true;
                what = format!("{} = \"1\" (a string)", dotted(&path));
            } else {
                let f = [1e6, -1.0, 1e-6][choice - SPECIAL.len() - 1];
                *node = match node {
                    Value::Integer(i) => Value::Integer(((*i as f64) * f) as i64),
                    Value::Float(x) => Value::Float(*x * f),
                    _ => unreachable!(),
                };
                what = format!("{} scaled by {f:e}", dotted(&path));
            }
        }
        Value::String(_) => {
            let s = *rng.pick(&STRINGS);
            *node = Value::String(s.into());
            what = format!("{} = {s:?}", dotted(&path));
        }
        Value::Boolean(b) => {
            if rng.below(2) == 0 {
                *node = Value::Boolean(!b);
                what = format!("{} = {}", dotted(&path), !b);
            } else {
                *node = Value::Integer(1);
                must_reject = true;
                what = format!("{} = 1 (not a boolean)", dotted(&path));
            }
        }
        Value::Array(a) => {
            let numeric = a
                .iter()
                .all(|x| matches!(x, Value::Float(_) | Value::Integer(_)));
            let fixed = numeric && !a.is_empty() && !VARIABLE_LENGTH.contains(&key.as_str());
            match rng.below(4) {
                0 if !a.is_empty() => {
                    let mut b = a.clone();
                    b.push(a[a.len() - 1].clone());
                    what = format!("{} with an entry appended", dotted(&path));
                    *node = Value::Array(b);
                    must_reject = fixed;
                }
                1 if !a.is_empty() => {
                    let mut b = a.clone();
                    b.pop();
                    what = format!("{} with its last entry dropped", dotted(&path));
                    *node = Value::Array(b);
                    must_reject = fixed;
                }
                2 if numeric && key == "stops" => {
                    // 10,000 stops: beyond the default attempt cap.
                    let b: Vec<Value> = (1..=10_000)
                        .map(|k| Value::Float(k as f64 / 10_000.0))
                        .collect();
                    *node = Value::Array(b);
                    must_reject = true;
                    what = format!("{} = 10,000 stops", dotted(&path));
                }
                _ => {
                    *node = Value::Array(Vec::new());
                    must_reject = fixed;
                    what = format!("{} = []", dotted(&path));
                }
            }
        }
        Value::Table(_) => {
            // Remove the key, or add an unknown one to the table.
            if rng.below(2) == 0 {
                if let Value::Table(t) = node {
                    t.insert("unknown_key".into(), Value::Integer(1));
                }
                must_reject = true;
                what = format!("{}.unknown_key = 1", dotted(&path));
            } else {
                let parent = get_mut(&mut v, &path[..path.len() - 1]);
                match (parent, path.last().unwrap()) {
                    (Value::Table(t), Step::Key(k)) => {
                        t.remove(k);
                    }
                    (Value::Array(a), Step::Index(i)) => {
                        a.remove(*i);
                    }
                    _ => unreachable!(),
                }
                what = format!("{} removed", dotted(&path));
            }
        }
        Value::Datetime(_) => unreachable!(),
    }
    Mutant {
        text: toml::to_string(&v).unwrap(),
        what,
        must_reject,
    }
}

/// How a process ended.
#[derive(Debug, PartialEq)]
enum End {
    Code(i32),
    Panic,
    Signal,
    Timeout,
}

/// Run the binary with `args`, killing it after `limit`.
fn run_bin(args: &[&str], limit: Duration) -> (End, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_shelldsa"))
        .args(args)
        .env("RAYON_NUM_THREADS", "1")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let t = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break Some(s);
        }
        if t.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(2));
    };
    let err = reader.join().unwrap();
    let end = match status {
        None => End::Timeout,
        Some(s) => match s.code() {
            Some(101) => End::Panic,
            Some(_) if err.contains("panicked") => End::Panic,
            Some(c) => End::Code(c),
            None => End::Signal,
        },
    };
    (end, err)
}

#[derive(Default, Debug)]
struct Tally {
    tried: usize,
    clean_errors: usize,
    accepted: usize,
    runs: usize,
    panics: Vec<String>,
    hangs: Vec<String>,
    aborts: Vec<String>,
    nonsense: Vec<String>,
}

/// Cap a mutant's run (the harness's bound, not part of the mutation): at most 40 step
/// attempts of at most 20 iterations, no VTU or plot output; only small accepted cases run.
fn runnable(text: &str, path: &Path) -> Option<String> {
    let case = shelldsa::io::parse_case(text, path).ok()?;
    let mut v: toml::Table = toml::from_str(text).ok()?;
    match case {
        shelldsa::io::Case::Shell(s) => {
            let e = s.estimate();
            if e.unknowns > 1000 || e.layer_points > 20_000 || e.min_steps > 20.0 {
                return None;
            }
            let steps = v.get_mut("steps")?.as_table_mut()?;
            steps.insert("max_attempts".into(), Value::Integer(40));
            let it = steps
                .get("max_iterations")
                .and_then(Value::as_integer)
                .unwrap_or(20)
                .min(20);
            steps.insert("max_iterations".into(), Value::Integer(it));
            let mut out = toml::Table::new();
            out.insert("vtu".into(), Value::Boolean(false));
            out.insert("plot".into(), Value::Boolean(false));
            v.insert("output".into(), Value::Table(out));
        }
        shelldsa::io::Case::MaterialPath(m) => {
            if m.path.n_steps() > 2000 {
                return None;
            }
        }
    }
    toml::to_string(&v).ok()
}

fn fuzz(seed: u64, n: usize, budget: Duration, runs_every: usize) -> Tally {
    let dir = root()
        .join("target")
        .join("fuzz-cases")
        .join(format!("seed-{seed}"));
    std::fs::create_dir_all(&dir).unwrap();
    // (name, text, whether its accepted mutants also run)
    let mut bases: Vec<(String, String, bool)> = vec![
        ("plate".into(), SHELL.into(), true),
        ("path".into(), PATH.into(), true),
    ];
    // The shipped cases, for `check` only (their runs are too long for this budget).
    for name in [
        "hemisphere-plastic",
        "cylindrical-bending",
        "hemisphere-plastic-dsa",
        "scordelis-lo",
    ] {
        let p = root().join("verification").join(name).join("case.toml");
        bases.push((name.into(), std::fs::read_to_string(p).unwrap(), false));
    }
    let mut rng = Rng(seed);
    let mut t = Tally::default();
    let start = Instant::now();
    let check_limit = Duration::from_secs(20);
    let run_limit = Duration::from_secs(30);
    for k in 0..n {
        if start.elapsed() > budget {
            println!("wall budget reached after {k} mutants");
            break;
        }
        // The small bases more often: they also run.
        let b = if rng.below(3) == 0 {
            2 + rng.below(bases.len() - 2)
        } else {
            rng.below(2)
        };
        let (name, base, runs) = &bases[b];
        let m = mutate(base, &mut rng);
        let file = dir.join(format!("m{k}.toml"));
        std::fs::write(&file, &m.text).unwrap();
        let f = file.to_str().unwrap();
        let label = format!("{f} ({name}: {})", m.what);
        t.tried += 1;
        let (end, err) = run_bin(&["check", f], check_limit);
        match end {
            End::Code(0) => {
                t.accepted += 1;
                if m.must_reject {
                    t.nonsense.push(label.clone());
                }
            }
            End::Code(1) => {
                t.clean_errors += 1;
                if !err.contains("error:") {
                    t.nonsense
                        .push(format!("{label}: exit 1 without an error message"));
                }
            }
            End::Code(c) => t.nonsense.push(format!("{label}: check exited with {c}")),
            End::Panic => t.panics.push(format!("{label}: {err}")),
            End::Signal => t.aborts.push(label.clone()),
            End::Timeout => t.hangs.push(label.clone()),
        }
        if !runs || end != End::Code(0) || t.accepted % runs_every != 0 {
            continue;
        }
        let Some(text) = runnable(&m.text, &file) else {
            continue;
        };
        std::fs::write(&file, text).unwrap();
        let out = dir.join(format!("m{k}.out"));
        t.runs += 1;
        let (end, err) = run_bin(
            &["run", f, "--out", out.to_str().unwrap(), "--quiet"],
            run_limit,
        );
        match end {
            End::Code(0) => {
                if let Some(bad) = non_finite_result(&out) {
                    t.nonsense.push(format!("{label}: run exit 0 with {bad}"));
                }
            }
            End::Code(1..=3) => {}
            End::Code(c) => t.nonsense.push(format!("{label}: run exited with {c}")),
            End::Panic => t.panics.push(format!("{label} (run): {err}")),
            End::Signal => t.aborts.push(format!("{label} (run)")),
            End::Timeout => t.hangs.push(format!("{label} (run)")),
        }
        let _ = std::fs::remove_dir_all(&out);
    }
    t
}

/// A shell run's last converged monitor displacement, if not finite (a material path's results
/// are checked by its own derivative check and exit code).
fn non_finite_result(out: &Path) -> Option<String> {
    let text = std::fs::read_to_string(out.join("results.json")).ok()?;
    let r: serde_json::Value = serde_json::from_str(&text).ok()?;
    let steps = r["steps"].as_array()?;
    let last = steps.iter().rev().find(|s| s["converged"] == true)?;
    for (name, m) in last["monitors"].as_object()? {
        for d in m["displacement"].as_array()? {
            if !d.as_f64().is_some_and(f64::is_finite) {
                return Some(format!("monitor {name} displacement {d}"));
            }
        }
    }
    None
}

fn env_or<T: std::str::FromStr>(key: &str, default: T) -> T {
    std::env::var(key)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

#[test]
fn mutated_case_files_end_cleanly() {
    let seed = env_or("SHELLDSA_FUZZ_SEED", 20_261_126_u64);
    let n = env_or("SHELLDSA_FUZZ_N", 1000_usize);
    let budget = Duration::from_secs(env_or("SHELLDSA_FUZZ_BUDGET_S", 50_u64));
    let runs_every = env_or("SHELLDSA_FUZZ_RUN_EVERY", 2_usize).max(1);
    let t0 = Instant::now();
    let t = fuzz(seed, n, budget, runs_every);
    println!(
        "fuzz seed {seed}: {} mutants tried ({:.1} s), {} clean errors, {} accepted, {} short \
         runs; panics {}, hangs {}, aborts {}, nonsense accepted {}",
        t.tried,
        t0.elapsed().as_secs_f64(),
        t.clean_errors,
        t.accepted,
        t.runs,
        t.panics.len(),
        t.hangs.len(),
        t.aborts.len(),
        t.nonsense.len()
    );
    for (what, list) in [
        ("panic", &t.panics),
        ("hang", &t.hangs),
        ("abort", &t.aborts),
        ("nonsense accepted", &t.nonsense),
    ] {
        for l in list {
            println!("{what}: {l}");
        }
    }
    assert!(
        t.tried >= 20.min(n),
        "only {} mutants in the budget",
        t.tried
    );
    assert!(t.panics.is_empty(), "panics: {:#?}", t.panics);
    assert!(t.hangs.is_empty(), "hangs: {:#?}", t.hangs);
    assert!(t.aborts.is_empty(), "aborts: {:#?}", t.aborts);
    assert!(
        t.nonsense.is_empty(),
        "nonsense accepted: {:#?}",
        t.nonsense
    );
}
