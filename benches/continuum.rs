//! Cost of the continuum DSA's residual derivative (`ShellModel::internal_force_dots`, the
//! hand-derived `shell::point_sensitivity` kernels) against one f64 `internal_force_with` and
//! against the dual-number reference (`internal_force_with` in `DualSVec64<6>`), on the
//! elastoplastic hemisphere of `verification/hemisphere-plastic/case.toml` as the CLI builds it
//! (quarter model, 17 × 17 particles, 2 × 2 Gauss points per cell, 5 layers, image particles).
//!
//! State: one committed step (an equibiaxial stretch `Δū = ε x⁰`, ε = 4e-3, above the yield
//! strain, so every layer point has a plastic history), then an increment stretching by
//! `6e-3 (x − y)/R` (part of the points yield further, part unload). Seeds: all groups non-zero
//! (particles, histories, DOFs, thickness, one material parameter per seed set).
//!
//! Run: `cargo bench --bench continuum` (threads: `RAYON_NUM_THREADS`).

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Matrix3, Vector3};
use num_dual::DualSVec64;
use shelldsa::io::shell_build::{build, problem_model};
use shelldsa::io::shell_case::read_shell_case;
use shelldsa::material::{MaterialParams, MaterialState, Vec5};
use shelldsa::meshfree::XorShift64;
use shelldsa::sensitivity::dual::DesignDual;
use shelldsa::shell::model::ShellModel;
use shelldsa::shell::point::{ParticleState, PointHistory};
use shelldsa::shell::point_sensitivity::ModelSeeds;
use std::hint::black_box;

struct Rng(XorShift64);
impl Rng {
    fn r(&mut self, s: f64) -> f64 {
        s * (2.0 * self.0.next_f64() - 1.0)
    }
    fn v(&mut self, s: f64) -> Vector3<f64> {
        Vector3::new(self.r(s), self.r(s), self.r(s))
    }
}

/// Equibiaxial stretch `ε x⁰` (`x⁰ = R d⁰` on the sphere R = 10) or, for `eps < 0`, a stretch
/// `|ε| (x − y)/R`, with rotations of `rot` rad.
fn field(m: &ShellModel, eps: f64, rot: f64, rng: &mut Rng) -> Vec<f64> {
    m.particles
        .iter()
        .flat_map(|p| {
            let e = if eps < 0.0 {
                -eps * (p.d0.x - p.d0.y)
            } else {
                eps
            };
            let u = p.d0 * (10.0 * e) + rng.v(1e-4);
            [u.x, u.y, u.z, rng.r(rot), rng.r(rot)]
        })
        .collect()
}

struct Owned {
    particles: Vec<ParticleState<f64>>,
    history: Vec<PointHistory<f64>>,
    dofs: Vec<f64>,
    thickness: f64,
    material: MaterialParams<f64>,
}

fn seeds(m: &ShellModel, q: &[f64], k: usize, rng: &mut Rng) -> Owned {
    let mat = m.material.to_array();
    let material = MaterialParams::from_array(std::array::from_fn(|i| {
        if i == k % 6 {
            mat[i] * 0.5
        } else {
            0.0
        }
    }));
    Owned {
        particles: m
            .particles
            .iter()
            .map(|_| ParticleState {
                u: rng.v(1e-2),
                d: rng.v(1e-2),
                d0: rng.v(1e-3),
                e: [rng.v(1e-2), rng.v(1e-2)],
            })
            .collect(),
        history: m
            .history
            .iter()
            .map(|h| PointHistory {
                frame: rng.v(1e-2).cross_matrix() * h.frame,
                material: MaterialState {
                    stress: Vec5::from_fn(|_, _| rng.r(1e4)),
                    back_stress: Vec5::from_fn(|_, _| rng.r(1e3)),
                    eps_p: 0.1 * h.material.eps_p,
                },
            })
            .collect(),
        dofs: q.iter().map(|v| rng.r(0.3 * v.abs())).collect(),
        thickness: 0.01 * m.thickness,
        material,
    }
}

fn view(o: &Owned) -> ModelSeeds<'_> {
    ModelSeeds {
        surface: None,
        thickness: o.thickness,
        material: o.material,
        particles: &o.particles,
        history: &o.history,
        dofs: &o.dofs,
    }
}

type D = DualSVec64<6>;

/// The arguments of `internal_force_with` in `D`.
type DualInputs = (
    Vec<ParticleState<D>>,
    Vec<PointHistory<D>>,
    MaterialParams<D>,
    D,
    Vec<D>,
);

/// The dual reference's inputs for 6 seed sets in one `DualSVec64<6>` pass.
fn dual_inputs(m: &ShellModel, q: &[f64], s: &[Owned]) -> DualInputs {
    let d = |x: f64, parts: [f64; 6]| D::from_parts(x, &parts);
    let v3 = |x: &Vector3<f64>, f: &dyn Fn(&Owned) -> Vector3<f64>| {
        Vector3::from_fn(|i, _| d(x[i], std::array::from_fn(|k| f(&s[k])[i])))
    };
    let particles = m
        .particles
        .iter()
        .enumerate()
        .map(|(j, p)| ParticleState {
            u: v3(&p.u, &|o| o.particles[j].u),
            d: v3(&p.d, &|o| o.particles[j].d),
            d0: v3(&p.d0, &|o| o.particles[j].d0),
            e: [
                v3(&p.e[0], &|o| o.particles[j].e[0]),
                v3(&p.e[1], &|o| o.particles[j].e[1]),
            ],
        })
        .collect();
    let history = m
        .history
        .iter()
        .enumerate()
        .map(|(j, h)| PointHistory {
            frame: Matrix3::from_fn(|a, b| {
                d(
                    h.frame[(a, b)],
                    std::array::from_fn(|k| s[k].history[j].frame[(a, b)]),
                )
            }),
            material: MaterialState {
                stress: Vec5::from_fn(|i, _| {
                    d(
                        h.material.stress[i],
                        std::array::from_fn(|k| s[k].history[j].material.stress[i]),
                    )
                }),
                back_stress: Vec5::from_fn(|i, _| {
                    d(
                        h.material.back_stress[i],
                        std::array::from_fn(|k| s[k].history[j].material.back_stress[i]),
                    )
                }),
                eps_p: d(
                    h.material.eps_p,
                    std::array::from_fn(|k| s[k].history[j].material.eps_p),
                ),
            },
        })
        .collect();
    let mv = m.material.to_array();
    let material = MaterialParams::from_array(std::array::from_fn(|i| {
        d(mv[i], std::array::from_fn(|k| s[k].material.to_array()[i]))
    }));
    let thickness = d(m.thickness, std::array::from_fn(|k| s[k].thickness));
    let dofs = q
        .iter()
        .enumerate()
        .map(|(i, &x)| d(x, std::array::from_fn(|k| s[k].dofs[i])))
        .collect();
    (particles, history, material, thickness, dofs)
}

/// CPU time (user + system, all threads) of this process in seconds, from `/proc/self/stat`
/// (Linux; `None` elsewhere). The machine the figures were taken on is shared, so the CPU time
/// per call is reported beside criterion's wall time.
fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which is in parentheses and may contain spaces).
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    // utime and stime are fields 14 and 15 of the full line, 12 and 13 after the name.
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    // USER_HZ is 100 on Linux.
    Some(ticks / 100.0)
}

/// CPU milliseconds per call of `f` over `n` calls.
fn cpu_ms_per_call(n: usize, mut f: impl FnMut()) -> Option<f64> {
    let t0 = cpu_seconds()?;
    for _ in 0..n {
        f();
    }
    Some((cpu_seconds()? - t0) * 1e3 / n as f64)
}

fn bench(c: &mut Criterion) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("verification/hemisphere-plastic/case.toml");
    let case = read_shell_case(&path).unwrap();
    let built = build(&case).unwrap();
    let mut m = problem_model(&built.problem).clone();
    let mut rng = Rng(XorShift64::new(17));
    let q1 = field(&m, 4e-3, 1e-3, &mut rng);
    let (_, trial) = m
        .internal_force_with(&m.particles, &m.history, &m.material, m.thickness, &q1)
        .unwrap();
    let nl = m.thickness_rule.len();
    m.commit_histories(&q1, trial.chunks(nl).map(|c| c.to_vec()).collect());
    let q = field(&m, -6e-3, 1e-3, &mut rng);
    let (_, h) = m
        .internal_force_with(&m.particles, &m.history, &m.material, m.thickness, &q)
        .unwrap();
    let yielding = h
        .iter()
        .zip(&m.history)
        .filter(|(t, c)| t.material.eps_p > c.material.eps_p)
        .count();
    println!(
        "hemisphere-plastic: {} DOFs, {} images, {} layer points ({yielding} yielding in the step), {} threads",
        m.n_dofs(),
        m.symmetry.images.len(),
        h.len(),
        rayon::current_num_threads()
    );
    let owned: Vec<Owned> = (0..6).map(|k| seeds(&m, &q, k, &mut rng)).collect();
    let views: Vec<ModelSeeds> = owned.iter().map(view).collect();
    let (dp, dh, dm, dt, dq) = dual_inputs(&m, &q, &owned);
    // Sanity check of the figures' meaning: the hand-derived and dual force derivatives agree.
    let hand = m.internal_force_dots(&q, &views).unwrap();
    let (fd, _) = m.internal_force_with(&dp, &dh, &dm, dt, &dq).unwrap();
    for (k, (f, _)) in hand.iter().enumerate() {
        let scale = f.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
        let err = f
            .iter()
            .zip(&fd)
            .fold(0.0_f64, |a, (x, y)| a.max((x - y.part(k)).abs()));
        println!(
            "seed set {k}: max |hand − dual| / max |hand| = {:.2e}",
            err / scale
        );
    }
    let n = 40;
    let cpu = [
        cpu_ms_per_call(n, || {
            black_box(
                m.internal_force_with(&m.particles, &m.history, &m.material, m.thickness, &q)
                    .unwrap(),
            );
        }),
        cpu_ms_per_call(n, || {
            black_box(m.internal_force_dots(&q, &views[..1]).unwrap());
        }),
        cpu_ms_per_call(n, || {
            black_box(m.internal_force_dots(&q, &views).unwrap());
        }),
        cpu_ms_per_call(n / 4, || {
            black_box(m.internal_force_with(&dp, &dh, &dm, dt, &dq).unwrap());
        }),
    ];
    println!(
        "CPU time per call (all threads), ms: internal_force_with f64 {:?}, internal_force_dots 1 set {:?}, 6 sets {:?}, internal_force_with DualSVec64<6> {:?}",
        cpu[0], cpu[1], cpu[2], cpu[3]
    );
    // The continuum DSA's step with 4 design variables: the fictitious loads' pass (`Δq̇ = 0`,
    // keeping the layer data) and the history update's increment-only part, against the
    // former update (a second full pass seeded with `Δq̇`).
    let zero_dofs = vec![0.0; q.len()];
    let rhs_views: Vec<ModelSeeds> = views[..4]
        .iter()
        .map(|v| ModelSeeds {
            dofs: &zero_dofs,
            ..*v
        })
        .collect();
    let dofs_dot: Vec<&[f64]> = owned[..4].iter().map(|o| &o.dofs[..]).collect();
    let split = || {
        let (d, lin) = m.internal_force_dots_linearised(&q, &rhs_views).unwrap();
        let mut h: Vec<_> = d.into_iter().map(|(_, h)| h).collect();
        m.add_increment_history_dots(&lin, &dofs_dot, &mut h)
            .unwrap();
        (h, lin.memory_bytes())
    };
    let (split_h, bytes) = split();
    let full = m.internal_force_dots(&q, &views[..4]).unwrap();
    for (k, ((_, fh), sh)) in full.iter().zip(&split_h).enumerate() {
        let (mut err, mut scale) = (0.0_f64, 0.0_f64);
        for (a, b) in fh.iter().zip(sh) {
            for (x, y) in a
                .material
                .stress
                .iter()
                .chain(a.material.back_stress.iter())
                .zip(
                    b.material
                        .stress
                        .iter()
                        .chain(b.material.back_stress.iter()),
                )
            {
                err = err.max((x - y).abs());
                scale = scale.max(x.abs());
            }
        }
        println!(
            "seed set {k}: trial stresses, split (seed part + Δq̇ part) against one pass: max \
             difference / max = {:.2e}",
            err / scale
        );
    }
    let (d0, lin) = m.internal_force_dots_linearised(&q, &rhs_views).unwrap();
    let mut h0: Vec<_> = d0.into_iter().map(|(_, h)| h).collect();
    // Wall time, best of 10 blocks of 4 calls: the machine is shared, the least disturbed
    // block is the closest to the cost (run with RAYON_NUM_THREADS=1 for a per-core figure).
    let best_ms = |f: &mut dyn FnMut()| {
        (0..10)
            .map(|_| {
                let t = std::time::Instant::now();
                for _ in 0..4 {
                    f();
                }
                t.elapsed().as_secs_f64() * 1e3 / 4.0
            })
            .fold(f64::INFINITY, f64::min)
    };
    let (d1, lin1) = m.internal_force_dots_linearised(&q, &rhs_views).unwrap();
    let mut h1: Vec<_> = d1.into_iter().map(|(_, h)| h).collect();
    let best = [
        best_ms(&mut || {
            black_box(m.internal_force_dots_linearised(&q, &rhs_views).unwrap());
        }),
        best_ms(&mut || {
            m.add_increment_history_dots(&lin1, &dofs_dot, &mut h1)
                .unwrap();
        }),
        best_ms(&mut || {
            black_box(m.internal_force_dots(&q, &views[..4]).unwrap());
        }),
    ];
    println!(
        "4 seed sets, best wall ms per call: fictitious loads keeping the layer data {:.2}, \
         increment-only history part {:.2}; one full pass with Δq̇ {:.2}",
        best[0], best[1], best[2]
    );
    let cpu4 = [
        cpu_ms_per_call(n, || {
            black_box(m.internal_force_dots(&q, &rhs_views).unwrap());
        }),
        cpu_ms_per_call(n, || {
            black_box(m.internal_force_dots_linearised(&q, &rhs_views).unwrap());
        }),
        cpu_ms_per_call(n, || {
            m.add_increment_history_dots(&lin, &dofs_dot, &mut h0)
                .unwrap();
        }),
        cpu_ms_per_call(n, || {
            black_box(m.internal_force_dots(&q, &views[..4]).unwrap());
        }),
    ];
    println!(
        "4 seed sets, CPU ms per call: fictitious loads {:?}, the same keeping the layer data \
         {:?} ({:.1} MB kept), increment-only history part {:?}; one full pass with Δq̇ {:?}",
        cpu4[0],
        cpu4[1],
        bytes as f64 / 1e6,
        cpu4[2],
        cpu4[3]
    );
    let mut g = c.benchmark_group("continuum_hemisphere_plastic");
    g.sample_size(10);
    g.bench_function("internal_force_with_f64", |b| {
        b.iter(|| {
            black_box(
                m.internal_force_with(&m.particles, &m.history, &m.material, m.thickness, &q)
                    .unwrap(),
            )
        })
    });
    g.bench_function("internal_force_dots_1", |b| {
        b.iter(|| black_box(m.internal_force_dots(black_box(&q), &views[..1]).unwrap()))
    });
    g.bench_function("internal_force_dots_6", |b| {
        b.iter(|| black_box(m.internal_force_dots(black_box(&q), &views).unwrap()))
    });
    g.bench_function("internal_force_with_dualsvec6", |b| {
        b.iter(|| {
            black_box(
                m.internal_force_with(&dp, &dh, &dm, dt, black_box(&dq))
                    .unwrap(),
            )
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
