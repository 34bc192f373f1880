//! The small punch-bending case shared by `tests/dsa_contact.rs` and
//! `tests/dsa_shape_contact.rs`: a quarter sheet 30 × 5 × 1 mm (13 × 3 particles,
//! elastoplastic aluminium as in `verification/cylindrical-bending/`), a cylinder punch
//! (R = 10) pushed down at x = 0, a cylinder die (R = 10) at x = 22, a constant self-weight;
//! and the small helpers both tests use.
#![allow(dead_code)]

use nalgebra::Vector3;
use shelldsa::io::dsa_case::DsaSpec;
use shelldsa::io::dsa_study::{base_design, CaseAnalysis};
use shelldsa::io::shell_case::{parse_shell_case, ShellCase};
use shelldsa::sensitivity::study;
use shelldsa::shell::point::ParticleState;
use std::path::Path;

/// The small bending case; `{final}` is the last load factor (1 = 6 mm of stroke), `{design}`
/// the `[[design]]`/`[dsa]` part.
pub const CASE: &str = r#"
thickness = 1.0
[problem]
kind = "shell"
title = "small punch bending (tests/dsa_contact.rs)"
[surface]
type = "rectangle"
origin = [0.0, 0.0, 0.0]
edge_u = [30.0, 0.0, 0.0]
edge_v = [0.0, 5.0, 0.0]
[particles]
grid = [13, 3]
[kernel]
basis = "quadratic"
support = 3.0
[integration]
cells = "per-particle-spacing"
subdivide = 1
gauss = 2
thickness_points = 5
thickness_rule = "lobatto"
vci = "second"
[material]
young = 70000.0
poisson = 0.34
sigma0 = 184.3
hardening = 70.0
beta = 1.0
[[boundary]]
kind = "symmetry"
edge = "u-min"
normal = [1.0, 0.0, 0.0]
point = [0.0, 0.0, 0.0]
[[boundary]]
kind = "symmetry"
edge = "v-min"
normal = [0.0, 1.0, 0.0]
point = [0.0, 0.0, 0.0]
[[load]]
kind = "gravity"
per_area = [0.0, 0.0, -2.6487e-5]
scaling = "constant"
[contact]
faces = "both"
penalty = 1000.0
[[tool]]
name = "punch"
side = "positive"
[tool.surface]
type = "cylinder-sector"
origin = [0.0, -5.0, 10.51]
axis = [0.0, 1.0, 0.0]
reference = [1.0, 0.0, 0.0]
radius = 10.0
angle_deg = [0.0, 135.0]
length = [0.0, 15.0]
[tool.path]
keys = [
    { t = 0.0, translation = [0.0, 0.0, 0.0] },
    { t = 1.0, translation = [0.0, 0.0, -6.0] },
]
[[tool]]
name = "die"
side = "positive"
[tool.surface]
type = "cylinder-sector"
origin = [22.0, -5.0, -10.49]
axis = [0.0, 1.0, 0.0]
reference = [-1.0, 0.0, 0.0]
radius = 10.0
angle_deg = [-30.0, 150.0]
length = [0.0, 15.0]
[tool.path]
keys = [{ t = 0.0, translation = [0.0, 0.0, 0.0] }]
[steps]
initial_step = 0.01
min_step = 1e-5
max_step = 0.02
final_load = {final}
stops = [0.25]
max_iterations = 8
residual_rtol = 1e-10
[[monitor]]
name = "center"
at = [0.0, 0.0]
[[monitor]]
name = "edge"
at = [1.0, 0.0]
[output]
vtu = false
plot = false
{design}
"#;

pub fn case(final_load: f64, design: &str) -> ShellCase {
    let text = CASE
        .replace("{final}", &format!("{final_load:?}"))
        .replace("{design}", design);
    parse_shell_case(&text, Path::new("tests/common/small_bending.rs")).unwrap()
}

/// A deterministic pseudo-random sequence in [−1, 1) (an LCG; no dependency).
pub struct Lcg(pub u64);

impl Lcg {
    pub fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }
    pub fn v3(&mut self, s: f64) -> Vector3<f64> {
        Vector3::new(self.next() * s, self.next() * s, self.next() * s)
    }
}

pub fn zero_state() -> ParticleState<f64> {
    ParticleState {
        u: Vector3::zeros(),
        d: Vector3::zeros(),
        d0: Vector3::zeros(),
        e: [Vector3::zeros(); 2],
    }
}

pub fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m, x| m.max(x.abs()))
}

pub fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).fold(0.0, |m, (x, y)| m.max((x - y).abs()))
}

/// Asserts the Taylor remainder's rate `2 ± 0.1` (the derivative of the discrete response) at
/// every step of `var` with at least three unflagged step sizes; returns how many steps were
/// fitted.
pub fn assert_taylor_rates(var: &study::VariableResult, name: &str) -> usize {
    let mut fitted = 0;
    for f in &var.taylor {
        if f.used.len() >= 3 {
            let rate = f.rate.unwrap();
            assert!(
                (rate - 2.0).abs() < 0.1,
                "{name}: step {} rate {rate}",
                f.step + 1
            );
            fitted += 1;
        }
    }
    fitted
}

/// The study of case `c` with `spec` (no progress lines).
pub fn run_case(c: &ShellCase, spec: &DsaSpec) -> study::DsaResult {
    study::run(
        &CaseAnalysis { case: c },
        &base_design(c),
        spec,
        &mut |_| {},
    )
    .unwrap()
}
