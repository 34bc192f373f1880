//! The eigenvalues of the converged tangent nearest to zero along a shell case's load path, with
//! a description of each mode: the stability diagnosis of docs/stability.md.
//!
//! ```sh
//! cargo run --release --example tangent_spectrum -- CASE.toml [--grid NU NV] [--gauss G]
//!     [--subdivide S] [--jitter J] [--stabilise EPS] [--strength NAME] [--floor F] [--count K]
//!     [--every N] [--until LOAD]
//! ```
//!
//! At every `N`-th converged step (default: every step) it prints the load factor, the monitors'
//! displacements and the `K` smallest eigenvalues (by modulus) of the tangent restricted to the
//! admissible unknowns (multiplier rows and eliminated DOFs removed:
//! `shelldsa::solver::spectrum`), relative to the mean diagonal of the tangent at the unloaded
//! state. For the lowest three modes it prints the share of each DOF component
//! (u_x, u_y, u_z, α1, α2), the zig-zag indices along u and v (`Z = Σ(f_{i+1} − f_i)² /
//! 2Σ(f_{i+1}² + f_i²)` over neighbouring particles of the grid: 0 for a constant field, 1 for a
//! sign alternating from particle to particle, 0.5 for noise) and where the mode is largest.
//! After each printed step it splits the lowest mode's Rayleigh quotient into the part of the
//! particles' geometric director blocks at the committed state, `−Σ_I (m_I·d_I) |α_I|²`
//! (`ShellModel::director_force_normals`), and the rest, and prints the largest and the median
//! of `m_I·d_I` over the particles against the bending stiffness `E t³/(12(1 − ν²))` (the
//! director filter's `κ` at ε = 1). With `integration.director = "normalised"` the geometric
//! terms couple the particles, so the split is not printed.
use shelldsa::io::shell_build::build;
use shelldsa::io::shell_case::{read_shell_case, CellLayout};
use shelldsa::shell::point::DirectorField;
use shelldsa::shell::problem::ShellProblem;
use shelldsa::solver::newton::ConvergedStep;
use shelldsa::solver::observe::{Observed, StepObserver};
use shelldsa::solver::spectrum::{smallest_eigenpairs, SpectrumOptions};
use shelldsa::solver::{
    ConvergedTangent, EssentialBc, LinearSolver, Method, NonlinearProblem, ProblemError,
    SolverOptions,
};

struct Probe {
    count: usize,
    every: usize,
    seen: usize,
    scale: f64,
    counts: [usize; 2],
    domain: [[f64; 2]; 2],
    monitors: Vec<(String, [f64; 2])>,
    lines: Vec<String>,
    pending: Option<(f64, Vec<String>)>,
    h: f64,
    /// The lowest mode and its eigenvalue at the last printed step.
    lowest: Option<(f64, Vec<f64>)>,
    /// `E t³ / (12 (1 − ν²))`.
    bending: f64,
}

fn zigzag(x: &[f64], uv: &[[f64; 2]], counts: [usize; 2], domain: [[f64; 2]; 2]) -> [f64; 2] {
    let [nu, nv] = counts;
    let mut grid = vec![None; nu * nv];
    for (p, q) in uv.iter().enumerate() {
        let i = ((q[0] - domain[0][0]) / (domain[0][1] - domain[0][0]) * (nu - 1) as f64).round();
        let j = ((q[1] - domain[1][0]) / (domain[1][1] - domain[1][0]) * (nv - 1) as f64).round();
        let (i, j) = (i as usize, j as usize);
        if i < nu && j < nv {
            grid[j * nu + i] = Some(p);
        }
    }
    let mut out = [0.0; 2];
    for (d, (di, dj)) in [(1usize, 0usize), (0, 1)].into_iter().enumerate() {
        let (mut num, mut den) = (0.0, 0.0);
        for j in 0..nv - dj {
            for i in 0..nu - di {
                if let (Some(a), Some(b)) = (grid[j * nu + i], grid[(j + dj) * nu + i + di]) {
                    for c in 0..5 {
                        let (fa, fb) = (x[5 * a + c], x[5 * b + c]);
                        num += (fb - fa).powi(2);
                        den += 2.0 * (fa * fa + fb * fb);
                    }
                }
            }
        }
        out[d] = num / den.max(f64::MIN_POSITIVE);
    }
    out
}

impl StepObserver<&mut ShellProblem> for Probe {
    fn converged_tangent(&self, _problem: ConvergedTangent) -> ConvergedTangent {
        ConvergedTangent::Required
    }
    fn on_converged(
        &mut self,
        problem: &&mut ShellProblem,
        step: &ConvergedStep<'_>,
    ) -> Result<(), ProblemError> {
        self.seen += 1;
        if (self.seen - 1) % self.every != 0 {
            return Ok(());
        }
        let nq = problem.n_generalised();
        let sp = smallest_eigenpairs(
            step.solver,
            step.essential,
            nq,
            SpectrumOptions {
                count: self.count,
                ..Default::default()
            },
        )
        .map_err(|e| ProblemError::Failed(shelldsa::solver::Failure::new("spectrum", e)))?;
        let model = &problem.model;
        let mut out = Vec::new();
        let vals: Vec<String> = sp
            .pairs
            .iter()
            .map(|p| format!("{:+.3e}", p.value / self.scale))
            .collect();
        out.push(format!(
            "  λ/k̄: {}  (iterations {}, skew {:.1e}, worst residual {:.1e})",
            vals.join(" "),
            sp.iterations,
            sp.skew,
            sp.pairs.iter().map(|p| p.residual).fold(0.0, f64::max)
        ));
        let n_real = model.n_particles();
        let uv = &model.particle_uv[..n_real];
        for (k, p) in sp.pairs.iter().take(3).enumerate() {
            let mut share = [0.0; 5];
            for (i, x) in p.vector.iter().enumerate() {
                share[i % 5] += x * x;
            }
            let z = zigzag(&p.vector, uv, self.counts, self.domain);
            let (mut best, mut at) = (0.0, 0);
            for j in 0..n_real {
                let a: f64 = (0..5).map(|c| p.vector[5 * j + c].powi(2)).sum();
                if a > best {
                    best = a;
                    at = j;
                }
            }
            let t = model.coefficient_transfer(&p.vector, self.h);
            out.push(format!(
                "    transfer to the points: u {:.3} d {:.3}, h·grad u {:.3}, h·grad d {:.3}",
                t[0], t[1], t[2], t[3]
            ));
            out.push(format!(
                "  mode {k}: λ/k̄ {:+.3e}  shares (ux uy uz a1 a2) [{:.2} {:.2} {:.2} {:.2} {:.2}]  zig-zag u {:.2} v {:.2}  largest at (u, v) = ({:.3}, {:.3})",
                p.value / self.scale,
                share[0], share[1], share[2], share[3], share[4],
                z[0], z[1], uv[at][0], uv[at][1]
            ));
        }
        self.lines.push(format!(
            "{:.4} {}",
            step.load,
            sp.pairs
                .iter()
                .map(|p| format!("{:+.4e}", p.value / self.scale))
                .collect::<Vec<_>>()
                .join(" ")
        ));
        self.lowest = sp.pairs.first().map(|p| (p.value, p.vector.clone()));
        self.pending = Some((step.load, out));
        Ok(())
    }
    fn after_commit(&mut self, problem: &&mut ShellProblem, _u: &[f64], load: f64) {
        let mut line = format!("load {load:>10.4}");
        for (name, at) in &self.monitors {
            let d = problem.model.displacement_at(*at).unwrap_or_default();
            line += &format!("  {name} ({:+.4}, {:+.4}, {:+.4})", d.x, d.y, d.z);
        }
        println!("{line}");
        {
            // The part of the total director change that the RK approximation filters out.
            let model = &problem.model;
            let (mut num, mut den, mut top) = (0.0, 0.0, (0.0, 0usize));
            for i in 0..model.n_particles() {
                let Ok(sv) = model.shape_values(model.particle_uv[i]) else {
                    continue;
                };
                let dd = |j: usize| {
                    let st = model.particle_state(j);
                    st.d - st.d0
                };
                let mut g = dd(i);
                for (j, psi, _) in sv.iter() {
                    g -= dd(j) * psi;
                }
                num += g.norm_squared();
                den += dd(i).norm_squared();
                if g.norm() > top.0 {
                    top = (g.norm(), i);
                }
            }
            println!(
                "  filtered part of d − d⁰: {:.3e} (RMS ratio), largest |g| {:.3e} at (u, v) = ({:.3}, {:.3})",
                (num / den.max(f64::MIN_POSITIVE)).sqrt(),
                top.0,
                model.particle_uv[top.1][0],
                model.particle_uv[top.1][1]
            );
        }
        let printed = self.pending.is_some();
        for l in self.pending.take().map(|p| p.1).unwrap_or_default() {
            println!("{l}");
        }
        if let (true, Some((value, v))) = (printed, self.lowest.take()) {
            let s = match problem.model.director_force_normals() {
                Ok(s) => s,
                Err(e) => {
                    println!("  director forces: {e}");
                    return;
                }
            };
            let vv: f64 = v.iter().map(|x| x * x).sum();
            let geo: f64 = s
                .iter()
                .enumerate()
                .map(|(i, si)| -si * (v[5 * i + 3].powi(2) + v[5 * i + 4].powi(2)))
                .sum::<f64>()
                / vv;
            let mut sorted = s.clone();
            sorted.sort_by(f64::total_cmp);
            let max = sorted.last().copied().unwrap_or(0.0);
            let median = sorted[sorted.len() / 2];
            let positive = s.iter().filter(|x| **x > 0.0).count();
            if problem.model.director == DirectorField::Interpolated {
                println!(
                    "  lowest mode: λ/k̄ {:+.3e} = geometric blocks {:+.3e} + rest {:+.3e}",
                    value / self.scale,
                    geo / self.scale,
                    (value - geo) / self.scale
                );
            } else {
                // The normalised field's geometric terms couple the particles (N″, N‴): the
                // per-particle blocks above are those of the interpolant only.
                println!(
                    "  lowest mode: λ/k̄ {:+.3e} (normalised director field: no split into \
                     per-particle geometric blocks)",
                    value / self.scale
                );
            }
            println!(
                "  m·d: max {:+.3e}, median {:+.3e}, > 0 at {} of {} particles; κ(ε = 1) = {:.3e}, max/κ(ε = 1) = {:.3e}",
                max,
                median,
                positive,
                s.len(),
                self.bending,
                max / self.bending
            );
        }
    }
    fn on_restore(&mut self) {
        self.pending = None;
        self.lowest = None;
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = std::path::PathBuf::from(args.first().expect("usage: CASE.toml [options]"));
    let mut case = read_shell_case(&path).unwrap_or_else(|e| panic!("{e}"));
    let mut count = 8;
    let mut every = 1;
    let mut i = 1;
    let num = |k: usize| -> f64 {
        args.get(k)
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| panic!("option {} needs a number", args[k - 1]))
    };
    while i < args.len() {
        match args[i].as_str() {
            "--grid" => {
                case.particles.counts = [num(i + 1) as usize, num(i + 2) as usize];
                i += 3;
            }
            "--gauss" => {
                case.integration.gauss = num(i + 1) as usize;
                i += 2;
            }
            "--subdivide" => {
                case.integration.cells = CellLayout::PerParticleSpacing {
                    subdivide: num(i + 1) as usize,
                };
                i += 2;
            }
            "--jitter" => {
                case.particles.jitter = num(i + 1);
                i += 2;
            }
            "--stabilise" => {
                case.integration.director_stabilisation = num(i + 1);
                i += 2;
            }
            "--strength" => {
                case.integration.director_stabilisation_strength = match args
                    .get(i + 1)
                    .map(String::as_str)
                {
                    Some("bending") => shelldsa::shell::stabilisation::FilterStrength::Bending,
                    Some("director-force") => {
                        shelldsa::shell::stabilisation::FilterStrength::DirectorForce
                    }
                    other => panic!("--strength: {other:?}, expected bending or director-force"),
                };
                i += 2;
            }
            "--floor" => {
                case.integration.director_stabilisation_floor = num(i + 1);
                i += 2;
            }
            "--count" => {
                count = num(i + 1) as usize;
                i += 2;
            }
            "--every" => {
                every = num(i + 1) as usize;
                i += 2;
            }
            "--until" => {
                case.steps.final_load = num(i + 1);
                case.steps.stops.retain(|&s| s <= case.steps.final_load);
                i += 2;
            }
            other => panic!("unknown option {other}"),
        }
    }
    let mut built = build(&case).unwrap_or_else(|e| panic!("{e}"));
    let pattern = built.problem.pattern().clone();
    let n = pattern.n_dofs();
    let nq = built.problem.n_generalised();
    // Scale: mean diagonal of the unloaded tangent over the generalised DOFs.
    let mut r = vec![0.0; n];
    let mut values = vec![0.0; pattern.nnz()];
    built
        .problem
        .residual_and_tangent(&vec![0.0; n], 0.0, &mut r, &mut values)
        .unwrap();
    built.problem.restore();
    let scale = (0..nq)
        .map(|i| values[pattern.diag_slot(i)].abs())
        .sum::<f64>()
        / nq as f64;
    let _ = EssentialBc::none(n);
    // The particle spacing in the parameter box mapped to length: the mean of the distances
    // between grid neighbours is not needed here, the transfer uses parameter gradients.
    let h = {
        let d = built.problem.model.domain;
        let [nu, nv] = case.particles.counts;
        [
            (d[0][1] - d[0][0]) / (nu - 1) as f64,
            (d[1][1] - d[1][0]) / (nv - 1) as f64,
        ]
    };
    let h = h[0].max(h[1]);
    {
        // Pure zig-zag coefficient fields (u_z only) through the RK functions.
        let model = &built.problem.model;
        let np = model.n_particles();
        let [nu, nv] = case.particles.counts;
        let dom = model.domain;
        let idx = |q: [f64; 2]| {
            (
                ((q[0] - dom[0][0]) / (dom[0][1] - dom[0][0]) * (nu - 1) as f64).round() as i64,
                ((q[1] - dom[1][0]) / (dom[1][1] - dom[1][0]) * (nv - 1) as f64).round() as i64,
            )
        };
        for (name, f) in [
            (
                "smooth (all +1)",
                Box::new(|_: i64, _: i64| 1.0) as Box<dyn Fn(i64, i64) -> f64>,
            ),
            (
                "zig-zag along u",
                Box::new(|i: i64, _: i64| if i % 2 == 0 { 1.0 } else { -1.0 }),
            ),
            (
                "zig-zag along v",
                Box::new(|_: i64, j: i64| if j % 2 == 0 { 1.0 } else { -1.0 }),
            ),
            (
                "checkerboard",
                Box::new(|i: i64, j: i64| if (i + j) % 2 == 0 { 1.0 } else { -1.0 }),
            ),
        ] {
            let mut x = vec![0.0; 5 * np];
            for (p, q) in model.particle_uv[..np].iter().enumerate() {
                let (i, j) = idx(*q);
                x[5 * p + 2] = f(i, j);
            }
            let t = model.coefficient_transfer(&x, h);
            println!(
                "RK transfer of a u_z coefficient field {name}: value {:.4}, h·gradient {:.4}",
                t[0], t[2]
            );
        }
    }
    let probe = Probe {
        count,
        every,
        seen: 0,
        scale,
        counts: case.particles.counts,
        domain: built.problem.model.domain,
        monitors: case
            .monitors
            .iter()
            .map(|m| (m.name.clone(), m.at))
            .collect(),
        lines: Vec::new(),
        pending: None,
        h,
        lowest: None,
        bending: case.material.young * case.thickness.powi(3)
            / (12.0 * (1.0 - case.material.poisson * case.material.poisson)),
    };
    println!(
        "{}: {} particles, {} unknowns ({} generalised), mean diagonal k̄ = {:.4e}",
        path.display(),
        built.n_particles,
        n,
        nq,
        scale
    );
    let mut solver = LinearSolver::new(&pattern, Method::auto(&pattern), SolverOptions::default())
        .unwrap_or_else(|e| panic!("{e}"));
    let mut obs = Observed::new(&mut built.problem, probe);
    let result = built
        .newton
        .run(&mut obs, &pattern, &mut solver, &vec![0.0; n]);
    match result {
        Ok(rep) => println!("complete: {} attempts", rep.attempts.len()),
        Err(f) => println!("failed: {f}"),
    }
    println!("# load, smallest eigenvalues / k̄");
    for l in &obs.observer.lines {
        println!("{l}");
    }
}
