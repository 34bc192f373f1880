//! Cost of the design sensitivity methods against the analysis : per case
//! shipped in `verification/*-dsa/`, criterion times the whole plain analysis
//! (`analysis`: no hook, residual-first acceptance), the analysis with the continuum DSA of all
//! the case's design variables in its hook (`continuum`) and with the dual-number reference
//! (`dual`, `DualSVec64<n>`). Each hooked run also reports its method's own time (the hook),
//! printed once per case as a fraction of the plain analysis per design variable: the
//! paper's measure (its Table 1–2 discussion: 3.1 % hemisphere, 14 % bending). The continuum's
//! figure is printed twice: best of 3 runs each (plain and hooked), and per (plain, hooked)
//! pair of runs with the median of the pairs (the typical figure on a shared machine, where
//! the best-of figure is the least disturbed one).
//!
//! The whole-run figure `(hooked − plain) / plain / variables` is printed in wall time and in
//! the process' CPU time (user + system, from `/proc/self/stat`), which on a shared machine
//! says what the hooked run adds whatever the other tenants take. The continuum runs on the
//! default schedule (in the analysis' hook); `DSA_BENCH_SCHEDULE=concurrent` (or
//! `synchronous`) chooses, and `DSA_BENCH_SOLVE=krylov` (or `factorised`) how the hook solves
//! the sensitivity systems (default: the library's).
//!
//! `cargo bench --bench dsa` (≈ 10 min on 2 cores); one case:
//! `cargo bench --bench dsa -- hemisphere-plastic-dsa` (or `cylindrical-bending-dsa`). The
//! percentages alone (no criterion samples): `cargo bench --bench dsa -- nomatch`; one case's
//! percentages: `DSA_BENCH_CASE=hemisphere cargo bench --bench dsa -- nomatch`.

use criterion::{criterion_group, criterion_main, Criterion};
use shelldsa::io::dsa_study::CaseAnalysis;
use shelldsa::io::shell_case::{read_shell_case, ShellCase};
use shelldsa::sensitivity::continuum::{ContinuumSchedule, SensitivitySolve};
use shelldsa::sensitivity::dual::{run_dual_on, DualMode};
use shelldsa::sensitivity::fd::{self, Analysis};
use shelldsa::sensitivity::{run_hooked, Design, DesignVariable, DsaAnalysis, HookedMethods};
use shelldsa::shell::problem::ShellProblem;
use shelldsa::solver::NewtonSolver;
use std::hint::black_box;
use std::time::Instant;

const CASES: [&str; 2] = [
    "verification/hemisphere-plastic-dsa/case.toml",
    "verification/cylindrical-bending-dsa/case.toml",
];

struct Setup {
    case: ShellCase,
    vars: Vec<DesignVariable>,
    schedule: ContinuumSchedule,
    solve: SensitivitySolve,
}

/// CPU time of this process so far (user + system, s; clock ticks of 10 ms).
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // The fields after the command name (in parentheses, which may hold spaces).
    let rest = stat.rsplit_once(')').map_or("", |r| r.1);
    let f: Vec<f64> = rest
        .split_whitespace()
        .map(|x| x.parse().unwrap_or(0.0))
        .collect();
    // utime and stime are fields 14 and 15 of the line, 12 and 13 after the name.
    (f.get(11).copied().unwrap_or(0.0) + f.get(12).copied().unwrap_or(0.0)) / 100.0
}

impl Setup {
    fn new(rel: &str) -> Self {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(rel);
        let case = read_shell_case(&path).unwrap();
        let vars = case.dsa.as_ref().unwrap().variables();
        let schedule = match std::env::var("DSA_BENCH_SCHEDULE").as_deref() {
            Ok("synchronous") => ContinuumSchedule::Synchronous,
            Ok("concurrent") => ContinuumSchedule::Concurrent,
            _ => ContinuumSchedule::default(),
        };
        let solve = match std::env::var("DSA_BENCH_SOLVE").as_deref() {
            Ok("krylov") => SensitivitySolve::Krylov,
            Ok("factorised") => SensitivitySolve::Factorised,
            _ => SensitivitySolve::default(),
        };
        Setup {
            case,
            vars,
            schedule,
            solve,
        }
    }
    fn base(&self) -> Design {
        shelldsa::io::dsa_study::base_design(&self.case)
    }
    fn analysis(&self) -> f64 {
        let a = CaseAnalysis { case: &self.case };
        let (p, n) = a.build(&self.base()).unwrap();
        let monitors = &self.case.dsa.as_ref().unwrap().monitors;
        fd::response(p, &n, a.solver(), monitors)
            .unwrap()
            .loads
            .len() as f64
    }
    /// The problem (with its loads) and its driver.
    fn problem(&self) -> (ShellProblem, NewtonSolver) {
        let a = CaseAnalysis { case: &self.case };
        a.build(&self.base()).unwrap()
    }
    /// The analysis of `problem` driven by `newton`, with the case's variables and monitors.
    fn dsa_analysis<'a>(
        &'a self,
        problem: ShellProblem,
        newton: &'a NewtonSolver,
    ) -> DsaAnalysis<'a> {
        DsaAnalysis {
            problem,
            surface: Some(&self.case.surface),
            variables: self.vars.clone(),
            monitors: self.case.dsa.as_ref().unwrap().monitors.clone(),
            newton,
            solver: CaseAnalysis { case: &self.case }.solver(),
        }
    }
    /// (method time, whole run time) in seconds.
    fn continuum(&self) -> (f64, f64) {
        let (p, n) = self.problem();
        let methods = HookedMethods {
            continuum: true,
            dual: None,
            schedule: self.schedule,
            solve: self.solve,
        };
        let (r, _) = run_hooked(self.dsa_analysis(p, &n), methods, &mut |_| {}).unwrap();
        let r = r.unwrap();
        let t = r.timing;
        eprintln!(
            "continuum ({:?}, {:?}) stages: rhs {:.3} s, solve {:.3} s ({} preconditioned iterations, {} \
             steps factorised by the DSA), update {:.3} s, record {:.3} s; converged tangents \
             on the DSA's thread {:.3} s; analysis {:.3} s of the run's {:.3} s",
            r.schedule,
            self.solve,
            t.rhs,
            t.solve,
            t.krylov_iterations,
            t.krylov_fallbacks,
            t.update,
            t.record,
            t.tangent,
            r.analysis.as_secs_f64(),
            r.total.as_secs_f64()
        );
        (r.dsa.as_secs_f64(), r.total.as_secs_f64())
    }
    fn dual(&self) -> (f64, f64) {
        let (p, n) = self.problem();
        let r = run_dual_on(self.dsa_analysis(p, &n), DualMode::Vector).unwrap();
        (r.reference.as_secs_f64(), r.total.as_secs_f64())
    }
}

fn bench(c: &mut Criterion) {
    // `DSA_BENCH_CASE=hemisphere` (a substring of the case directory) restricts the run to the
    // matching cases (the percentages are computed before criterion's own filter applies).
    let only = std::env::var("DSA_BENCH_CASE").unwrap_or_default();
    for rel in CASES.into_iter().filter(|r| r.contains(&only)) {
        let s = Setup::new(rel);
        let name = rel.split('/').nth(1).unwrap();
        // The methods' own time per variable against the plain analysis, best of 3 each (the
        // machine is shared: the minimum is the least disturbed), and the continuum's ratio
        // per pair of runs (a plain analysis, then the hooked run: the two see about the same
        // load from the machine's other tenants), whose median is the typical figure.
        let nv = s.vars.len() as f64;
        let mut cpu = Vec::new();
        let pairs: Vec<(f64, (f64, f64))> = (0..3)
            .map(|_| {
                let (t, c0) = (Instant::now(), cpu_seconds());
                black_box(s.analysis());
                let (plain, c1) = (t.elapsed().as_secs_f64(), cpu_seconds());
                let hooked = s.continuum();
                cpu.push((c1 - c0, cpu_seconds() - c1));
                (plain, hooked)
            })
            .collect();
        println!(
            "{name}: continuum ({:?}), CPU time (plain, hooked) per pair: {} s; (hooked − plain) \
             / plain / variables in CPU time: {} %",
            s.schedule,
            cpu.iter()
                .map(|(p, h)| format!("({p:.2}, {h:.2})"))
                .collect::<Vec<_>>()
                .join(" "),
            cpu.iter()
                .map(|(p, h)| format!("{:.2}", 100.0 * (h - p) / p / nv))
                .collect::<Vec<_>>()
                .join(" / ")
        );
        let mut whole: Vec<f64> = pairs
            .iter()
            .map(|(a, (_, h))| 100.0 * (h - a) / a / nv)
            .collect();
        whole.sort_by(f64::total_cmp);
        println!(
            "{name}: whole run (hooked − plain) / plain / variables in each pair: {}",
            pairs_and_median(&whole)
        );
        let t_analysis = pairs.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
        let (t_cont, t_cont_run) = pairs.iter().fold((f64::INFINITY, f64::INFINITY), |a, p| {
            (a.0.min(p.1 .0), a.1.min(p.1 .1))
        });
        let mut paired: Vec<f64> = pairs.iter().map(|(a, (c, _))| 100.0 * c / a / nv).collect();
        paired.sort_by(f64::total_cmp);
        println!(
            "{name}: continuum DSA per variable in each (plain, hooked) pair of runs: {}",
            pairs_and_median(&paired)
        );
        let (t_dual, t_dual_run) = (0..3)
            .map(|_| s.dual())
            .fold((f64::INFINITY, f64::INFINITY), |a, b| {
                (a.0.min(b.0), a.1.min(b.1))
            });
        println!(
            "{name}: {} design variables; plain analysis {t_analysis:.3} s; continuum DSA \
             {t_cont:.3} s = {:.2} % of the analysis per variable (hooked run {t_cont_run:.3} s: \
             {:.2} % per variable over the plain run, the converged tangent included); dual \
             {t_dual:.3} s = {:.2} % per variable (hooked run {t_dual_run:.3} s: {:.2} %)",
            s.vars.len(),
            100.0 * t_cont / t_analysis / nv,
            100.0 * (t_cont_run - t_analysis) / t_analysis / nv,
            100.0 * t_dual / t_analysis / nv,
            100.0 * (t_dual_run - t_analysis) / t_analysis / nv,
        );
        let mut g = c.benchmark_group(name);
        g.sample_size(10);
        g.bench_function("analysis", |b| b.iter(|| black_box(s.analysis())));
        g.bench_function("continuum", |b| b.iter(|| black_box(s.continuum())));
        g.bench_function("dual", |b| b.iter(|| black_box(s.dual())));
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);

/// Sorted percentages as `a / b / c % (median m %)`.
fn pairs_and_median(sorted: &[f64]) -> String {
    let all: Vec<String> = sorted.iter().map(|r| format!("{r:.2}")).collect();
    format!(
        "{} % (median {:.2} %)",
        all.join(" / "),
        sorted[sorted.len() / 2]
    )
}
