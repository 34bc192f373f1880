//! Three-way check of the path-dependent material-point sensitivity (eqs 44–49).
//!
//! A strain path `Δε_k(τ) = a_k + τ b_k` (k = 1…N) and material parameters `m(τ) = m0 + τ m1` depend
//! on one design parameter τ. The history `ᵏ(σ, α, ē^p)` is integrated with the return map, and
//! its τ-derivative at every step is computed
//! - by hand: [`crate::material::material_sensitivity`] carried from step to step;
//! - with dual numbers: the same [`crate::material::return_map`] run with [`crate::scalar::Dual`];
//! - by central differences of whole re-runs at τ ± h, with the steps whose elastic/plastic status
//!   flips inside ±h detected and reported (the comparison stops at the first flipped step, since
//!   every later step inherits the kink).
//!
//! Outputs are made dimensionless so one tolerance fits all: `σ/σ0`, `α/σ0`, `ē^p E/σ0`.

use super::{
    central_jacobian, compare_matrices, dual_jacobian, Comparison, Differentiable, StepSize,
    Tolerance,
};
use crate::material::{
    material_sensitivity, return_map, MaterialError, MaterialParams, MaterialState, Vec5,
    STATE_LABELS,
};
use crate::scalar::Real;
use nalgebra::DMatrix;
use std::fmt;

/// A strain path and material whose data depend linearly on a design parameter τ.
#[derive(Clone, Debug)]
pub struct MaterialPath {
    /// Material at τ = 0.
    pub material: MaterialParams<f64>,
    /// `dm/dτ`.
    pub material_rate: MaterialParams<f64>,
    /// Strain increments `a_k` at τ = 0.
    pub increments: Vec<Vec5<f64>>,
    /// `b_k = dΔε_k/dτ`.
    pub increment_rates: Vec<Vec5<f64>>,
    /// The design point τ0 at which derivatives are taken.
    pub tau: f64,
}

/// Values, hand-derived sensitivities and elastic/plastic status at every step.
#[derive(Clone, Debug)]
pub struct PathResponse {
    /// State after each step.
    pub states: Vec<MaterialState<f64>>,
    /// Hand-derived `d state/dτ` after each step.
    pub sensitivities: Vec<MaterialState<f64>>,
    /// Whether each step was plastic.
    pub plastic: Vec<bool>,
    /// Newton iterations of each return map.
    pub iterations: Vec<usize>,
}

impl MaterialPath {
    /// Number of steps.
    pub fn n_steps(&self) -> usize {
        self.increments.len()
    }

    /// The first τ-dependent value (a material parameter or a strain-increment component
    /// with a non-zero rate) that `τ ± h` leaves unchanged in floating point, named for a
    /// message; `None` when the step reaches every one (or `h` is not a finite step > 0,
    /// reported as such).
    pub fn lost_in_step(&self, h: f64) -> Option<String> {
        if !(h.is_finite() && h > 0.0) {
            return Some(format!("every value (h = {h})"));
        }
        let (lo, hi) = (self.tau - h, self.tau + h);
        if lo == self.tau || hi == self.tau {
            return Some(format!("τ = {} itself", self.tau));
        }
        let m0 = self.material_at(self.tau).to_array();
        let (ml, mh) = (
            self.material_at(lo).to_array(),
            self.material_at(hi).to_array(),
        );
        let rate = self.material_rate.to_array();
        for (i, name) in crate::material::PARAM_NAMES.iter().enumerate() {
            if rate[i] != 0.0 && (ml[i] == m0[i] || mh[i] == m0[i]) {
                return Some(format!("material.{name} = {}", m0[i]));
            }
        }
        for k in 0..self.n_steps() {
            let (a, l, u) = (
                self.increment_at(k, self.tau),
                self.increment_at(k, lo),
                self.increment_at(k, hi),
            );
            for c in 0..5 {
                if self.increment_rates[k][c] != 0.0 && (l[c] == a[c] || u[c] == a[c]) {
                    return Some(format!(
                        "the strain increment component {c} of step {} (= {:e})",
                        k + 1,
                        a[c]
                    ));
                }
            }
        }
        None
    }

    fn material_at<T: Real>(&self, tau: T) -> MaterialParams<T> {
        let a = self.material.to_array();
        let b = self.material_rate.to_array();
        MaterialParams::from_array(std::array::from_fn(|i| tau * b[i] + a[i]))
    }

    fn increment_at<T: Real>(&self, k: usize, tau: T) -> Vec5<T> {
        Vec5::from_fn(|i, _| tau * self.increment_rates[k][i] + self.increments[k][i])
    }

    /// Output scaling: `σ/σ0`, `α/σ0`, `ē^p E/σ0` (σ0, E at τ = 0).
    fn scales(&self) -> [f64; 11] {
        let s = 1.0 / self.material.sigma0;
        let e = self.material.young / self.material.sigma0;
        [s, s, s, s, s, s, s, s, s, s, e]
    }

    /// Run the path at τ in scalar `T` (f64 for values and differences, duals for the reference).
    pub fn run<T: Real>(
        &self,
        tau: T,
    ) -> Result<(Vec<MaterialState<T>>, Vec<bool>), MaterialError> {
        let m = self.material_at(tau);
        let mut state = MaterialState::<T>::virgin();
        let mut states = Vec::with_capacity(self.n_steps());
        let mut plastic = Vec::with_capacity(self.n_steps());
        for k in 0..self.n_steps() {
            let out = return_map(&m, &state, &self.increment_at(k, tau))?;
            state = out.state;
            states.push(state);
            plastic.push(out.plastic);
        }
        Ok((states, plastic))
    }

    /// Analysis at τ0 with the hand-derived sensitivity carried from step to step.
    pub fn hand_derived(&self) -> Result<PathResponse, MaterialError> {
        let m = self.material_at(self.tau);
        let dm = self.material_rate;
        let mut state = MaterialState::<f64>::virgin();
        let mut dstate = MaterialState::<f64>::zero();
        let mut r = PathResponse {
            states: vec![],
            sensitivities: vec![],
            plastic: vec![],
            iterations: vec![],
        };
        for k in 0..self.n_steps() {
            let deps = self.increment_at(k, self.tau);
            let out = return_map(&m, &state, &deps)?;
            dstate = material_sensitivity(&m, &deps, &out, &dm, &dstate, &self.increment_rates[k]);
            state = out.state;
            r.states.push(state);
            r.sensitivities.push(dstate);
            r.plastic.push(out.plastic);
            r.iterations.push(out.iterations);
        }
        Ok(r)
    }

    /// The three-way check at τ0 with central-difference step `h` on τ.
    pub fn check(
        &self,
        h: f64,
        dual_tol: Tolerance,
        fd_tol: Tolerance,
    ) -> Result<PathCheck, MaterialError> {
        // Surface errors (invalid parameters at τ0 ± h) before the generic machinery runs.
        self.run::<f64>(self.tau - h)?;
        self.run::<f64>(self.tau + h)?;
        let resp = self.hand_derived()?;
        let sc = self.scales();
        let n = self.n_steps();
        let hand = DMatrix::from_fn(n * 11, 1, |i, _| {
            resp.sensitivities[i / 11].to_array()[i % 11] * sc[i % 11]
        });
        let x = [self.tau];
        let dual = dual_jacobian(self, &x);
        let fd = central_jacobian(self, &x, StepSize::Absolute(h));
        let flipped_steps: Vec<usize> = fd
            .flips
            .iter()
            .flat_map(|f| f.entries.iter().map(|(k, _)| *k))
            .collect();
        let first_flip = flipped_steps.iter().copied().min();
        let labels = |i: usize, _j: usize| (self.output_label(i), "τ".to_string());
        let vs_dual = compare_matrices(
            "hand-derived vs dual numbers",
            &hand,
            &dual,
            dual_tol,
            &[],
            &labels,
        );
        let rows = first_flip.unwrap_or(n) * 11;
        let vs_fd = compare_matrices(
            "hand-derived vs central differences",
            &hand.rows(0, rows).into_owned(),
            &fd.jacobian.rows(0, rows).into_owned(),
            fd_tol,
            &[],
            &labels,
        );
        let per_step = (0..n)
            .map(|k| {
                let err = |refm: &DMatrix<f64>, floor: f64| {
                    let scale = refm.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
                    (0..11)
                        .map(|c| {
                            let (a, b) = (hand[(k * 11 + c, 0)], refm[(k * 11 + c, 0)]);
                            (a - b).abs() / b.abs().max(floor * scale).max(f64::MIN_POSITIVE)
                        })
                        .fold(0.0, f64::max)
                };
                StepCheck {
                    step: k + 1,
                    plastic: resp.plastic[k],
                    dual_error: err(&dual, dual_tol.floor),
                    fd_error: err(&fd.jacobian, fd_tol.floor),
                    flipped: flipped_steps.contains(&k),
                }
            })
            .collect();
        Ok(PathCheck {
            response: resp,
            per_step,
            vs_dual,
            vs_fd,
            h,
            flipped_steps,
        })
    }

    /// The 60-step non-proportional path of the test suite and the shipped example: loading in
    /// tension with shear, unloading into reversed yield, rotation of the strain direction with
    /// transverse shears, and reloading along a new direction; every strain increment and every
    /// material parameter depends on τ. Material: E = 210000, ν = 0.3, σ0 = 250, H = 1000, mixed
    /// hardening β (given), shear correction 5/6.
    pub fn non_proportional_60(beta: f64) -> Result<Self, MaterialError> {
        let material = MaterialParams::new(210_000.0, 0.3, 250.0, 1000.0, beta)?;
        // β can only move where it stays inside [0, 1] at τ0 ± h.
        let beta_rate = if beta > 0.0 && beta < 1.0 { 0.2 } else { 0.0 };
        let material_rate =
            MaterialParams::from_array([21_000.0, 0.02, 0.05, 40.0, 300.0, beta_rate]);
        let mut increments = Vec::with_capacity(60);
        let mut increment_rates = Vec::with_capacity(60);
        for k in 0..60 {
            let t = k as f64;
            let a = match k {
                // loading: tension with in-plane shear, well past first yield (ε_y ≈ 1.2e-3)
                0..=14 => Vec5::new(4.0e-4, -1.0e-4, 2.0e-4, 0.0, 0.0),
                // unloading and reversed yielding
                15..=26 => Vec5::new(-5.0e-4, 1.5e-4, -1.0e-4, 0.5e-4, 0.0),
                // rotation of the strain direction with transverse shears
                27..=39 => Vec5::new(
                    1.0e-4 * (0.3 * t).cos(),
                    2.0e-4 * (0.3 * t).sin(),
                    -3.0e-4,
                    2.0e-4,
                    -1.5e-4,
                ),
                // reloading along a new direction
                _ => Vec5::new(-1.0e-4, 4.0e-4, 1.0e-4, -0.5e-4, 1.0e-4),
            };
            let b = Vec5::new(
                0.2 * a[0],
                -0.1 * a[1],
                0.3 * a[2],
                1.0e-5 * (0.7 * t).sin(),
                1.0e-5 * (0.4 * t).cos(),
            );
            increments.push(a);
            increment_rates.push(b);
        }
        Ok(MaterialPath {
            material,
            material_rate,
            increments,
            increment_rates,
            tau: 0.0,
        })
    }
}

impl Differentiable for MaterialPath {
    fn n_inputs(&self) -> usize {
        1
    }
    /// Scaled states after every step; NaN everywhere if a return map fails (which then fails
    /// every comparison visibly).
    fn eval<T: Real>(&self, x: &[T]) -> Vec<T> {
        let sc = self.scales();
        match self.run(x[0]) {
            Ok((states, _)) => states
                .iter()
                .flat_map(|s| {
                    let a = [
                        s.stress[0],
                        s.stress[1],
                        s.stress[2],
                        s.stress[3],
                        s.stress[4],
                        s.back_stress[0],
                        s.back_stress[1],
                        s.back_stress[2],
                        s.back_stress[3],
                        s.back_stress[4],
                        s.eps_p,
                    ];
                    (0..11).map(move |i| a[i] * sc[i])
                })
                .collect(),
            Err(_) => vec![T::cst(f64::NAN); self.n_steps() * 11],
        }
    }
    fn input_label(&self, _j: usize) -> String {
        "τ".into()
    }
    fn output_label(&self, i: usize) -> String {
        format!("{}@step{}", STATE_LABELS[i % 11], i / 11 + 1)
    }
    fn active_set(&self, x: &[f64]) -> Vec<u8> {
        self.run(x[0])
            .map(|(_, p)| p.into_iter().map(u8::from).collect())
            .unwrap_or_default()
    }
    fn active_label(&self, k: usize) -> String {
        format!("step {} elastic/plastic", k + 1)
    }
}

/// Errors of one step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepCheck {
    /// Step number (1-based).
    pub step: usize,
    /// Plastic step.
    pub plastic: bool,
    /// Worst scaled error of the hand-derived sensitivity against dual numbers at this step.
    pub dual_error: f64,
    /// Worst scaled error against central differences at this step.
    pub fd_error: f64,
    /// The elastic/plastic status of this step flips within ±h.
    pub flipped: bool,
}

/// Outcome of [`MaterialPath::check`].
#[derive(Clone, Debug)]
pub struct PathCheck {
    /// The analysis and hand-derived sensitivity.
    pub response: PathResponse,
    /// Errors step by step.
    pub per_step: Vec<StepCheck>,
    /// Over all steps against dual numbers.
    pub vs_dual: Comparison,
    /// Over the steps before the first flip against central differences.
    pub vs_fd: Comparison,
    /// Central-difference step on τ.
    pub h: f64,
    /// Steps (0-based) whose status flips within ±h.
    pub flipped_steps: Vec<usize>,
}

impl PathCheck {
    /// Both comparisons within tolerance.
    ///
    /// A comparison whose tolerances are not finite numbers in `(0, 1)` or whose errors are not
    /// finite (NaN compares false with every bound) does not pass.
    pub fn passed(&self) -> bool {
        let sane = |c: &Comparison| {
            let t = c.tol;
            t.rel > 0.0
                && t.rel < 1.0
                && t.floor > 0.0
                && t.floor < 1.0
                && c.max_error().is_finite()
        };
        // FD is compared before the first flip only (as `vs_fd`).
        let first_flip = self
            .flipped_steps
            .iter()
            .copied()
            .min()
            .unwrap_or(usize::MAX);
        let steps_finite =
            self.per_step.iter().enumerate().all(|(k, s)| {
                s.dual_error.is_finite() && (k >= first_flip || s.fd_error.is_finite())
            });
        self.vs_dual.passed()
            && self.vs_fd.passed()
            && sane(&self.vs_dual)
            && sane(&self.vs_fd)
            && steps_finite
    }
}

impl fmt::Display for PathCheck {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "step  status   hand−dual    hand−FD    flip")?;
        for s in &self.per_step {
            writeln!(
                f,
                "{:>4}  {:<7} {:>10.2e} {:>10.2e}    {}",
                s.step,
                if s.plastic { "plastic" } else { "elastic" },
                s.dual_error,
                s.fd_error,
                if s.flipped { "FLIPS within ±h" } else { "" }
            )?;
        }
        writeln!(f, "{}", self.vs_dual)?;
        write!(
            f,
            "{}\ncentral-difference step h = {:.1e}",
            self.vs_fd, self.h
        )?;
        if !self.flipped_steps.is_empty() {
            let s: Vec<String> = self
                .flipped_steps
                .iter()
                .map(|k| (k + 1).to_string())
                .collect();
            write!(
                f,
                "\nstatus flips within ±h at steps {}: FD compared only before step {}",
                s.join(", "),
                s[0]
            )?;
        }
        Ok(())
    }
}
