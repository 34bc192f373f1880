//! Derivative-check machinery: hand-derived derivatives against the dual-number reference and
//! against central finite differences, with tolerances scaled by magnitude and a readable report
//! naming the worst component.
//!
//! A function to check implements [`Differentiable`]: a map from `n_inputs` scalars (design
//! variables, strain components, …) to `n_outputs` scalars, written once, generic over [`Real`].
//! The same code is then
//! - differentiated with dual numbers ([`dual_jacobian`]), one [`Dual`] pass per input;
//! - differenced centrally ([`central_jacobian`]), with a reported step and detection of
//!   *active-set flips*: inputs whose ±h perturbation changes a discrete state (yield status,
//!   contact status) reported by [`Differentiable::active_set`]; such columns are flagged and the
//!   comparison can leave them out, never silently;
//! - compared with a hand-derived Jacobian ([`compare`], [`check`]).
//!
//! Component errors are measured as `|a − b| / max(|b|, floor · scale)`, where `scale` is the
//! largest `|b|` of the reference: a relative error for components that matter, an absolute error
//! (relative to the largest component) for components that are round-off-sized.

pub mod material_path;

use crate::scalar::{Dual, Real};
use nalgebra::DMatrix;
use std::fmt;

/// A vector function `y = f(x)`, generic over the scalar so it runs with f64 and dual numbers.
pub trait Differentiable {
    /// Number of inputs `x`.
    fn n_inputs(&self) -> usize;
    /// Evaluate the outputs. Must have the same length for every call.
    fn eval<T: Real>(&self, x: &[T]) -> Vec<T>;
    /// Name of input `j` for reports.
    fn input_label(&self, j: usize) -> String {
        format!("x[{j}]")
    }
    /// Name of output `i` for reports.
    fn output_label(&self, i: usize) -> String {
        format!("y[{i}]")
    }
    /// Discrete state at `x` (for example the elastic/plastic status of every step). A change of
    /// any entry between `x` and `x ± h` flags the finite difference of that input.
    fn active_set(&self, _x: &[f64]) -> Vec<u8> {
        Vec::new()
    }
    /// Name of active-set entry `k` for reports.
    fn active_label(&self, k: usize) -> String {
        format!("status[{k}]")
    }
}

/// Function values at `x` in f64.
pub fn values<F: Differentiable>(f: &F, x: &[f64]) -> Vec<f64> {
    f.eval(x)
}

/// Jacobian `∂y/∂x` (outputs × inputs) from dual numbers: one [`Dual`] pass per input.
pub fn dual_jacobian<F: Differentiable>(f: &F, x: &[f64]) -> DMatrix<f64> {
    let n = f.n_inputs();
    assert_eq!(
        x.len(),
        n,
        "dual_jacobian: x has {} entries, f takes {n}",
        x.len()
    );
    let mut cols: Vec<Vec<f64>> = Vec::with_capacity(n);
    for j in 0..n {
        let xd: Vec<Dual> = x
            .iter()
            .enumerate()
            .map(|(k, &v)| {
                if k == j {
                    Dual::from_re(v).derivative()
                } else {
                    Dual::from_re(v)
                }
            })
            .collect();
        cols.push(f.eval(&xd).iter().map(|y| y.eps).collect());
    }
    let m = cols.first().map_or(0, Vec::len);
    DMatrix::from_fn(m, n, |i, j| cols[j][i])
}

/// How the finite-difference step is chosen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StepSize {
    /// `h_j = h · max(1, |x_j|)`.
    Relative(f64),
    /// `h_j = h`.
    Absolute(f64),
}

impl Default for StepSize {
    /// `h = ε^(1/3) ≈ 6e-6` relative: balances the O(h²) truncation of a central difference
    /// against the O(ε/h) round-off, the textbook optimum for smooth functions of unit scale.
    fn default() -> Self {
        StepSize::Relative(f64::EPSILON.cbrt())
    }
}

impl StepSize {
    /// The step used for an input of value `x`.
    pub fn at(&self, x: f64) -> f64 {
        match *self {
            StepSize::Relative(h) => h * x.abs().max(1.0),
            StepSize::Absolute(h) => h,
        }
    }
}

/// A finite-difference column whose perturbation changed the function's active set.
#[derive(Clone, Debug, PartialEq)]
pub struct ActiveSetFlip {
    /// Perturbed input.
    pub input: usize,
    /// Input name.
    pub input_label: String,
    /// Active-set entries that changed at `x + h` or `x − h`.
    pub entries: Vec<(usize, String)>,
}

/// Central-difference Jacobian with the steps used and the active-set flips found.
#[derive(Clone, Debug)]
pub struct CentralDifference {
    /// `(f(x + h e_j) − f(x − h e_j)) / 2h`, outputs × inputs.
    pub jacobian: DMatrix<f64>,
    /// Step `h_j` used for each input.
    pub steps: Vec<f64>,
    /// Inputs whose ±h perturbation changed the active set.
    pub flips: Vec<ActiveSetFlip>,
}

/// Central differences of `f` at `x` for every input.
pub fn central_jacobian<F: Differentiable>(f: &F, x: &[f64], step: StepSize) -> CentralDifference {
    let n = f.n_inputs();
    assert_eq!(
        x.len(),
        n,
        "central_jacobian: x has {} entries, f takes {n}",
        x.len()
    );
    let base_set = f.active_set(x);
    let mut cols = Vec::with_capacity(n);
    let mut steps = Vec::with_capacity(n);
    let mut flips = Vec::new();
    for j in 0..n {
        let h = step.at(x[j]);
        let mut xp = x.to_vec();
        let mut xm = x.to_vec();
        xp[j] += h;
        xm[j] -= h;
        let h_eff = (xp[j] - xm[j]) * 0.5; // the step actually represented in floating point
        let yp: Vec<f64> = f.eval(&xp);
        let ym: Vec<f64> = f.eval(&xm);
        cols.push(
            yp.iter()
                .zip(&ym)
                .map(|(p, m)| (p - m) / (2.0 * h_eff))
                .collect::<Vec<f64>>(),
        );
        steps.push(h_eff);
        if !base_set.is_empty() {
            let sp = f.active_set(&xp);
            let sm = f.active_set(&xm);
            let entries: Vec<(usize, String)> = (0..base_set.len())
                .filter(|&k| sp.get(k) != Some(&base_set[k]) || sm.get(k) != Some(&base_set[k]))
                .map(|k| (k, f.active_label(k)))
                .collect();
            if !entries.is_empty() {
                flips.push(ActiveSetFlip {
                    input: j,
                    input_label: f.input_label(j),
                    entries,
                });
            }
        }
    }
    let m = cols.first().map_or(0, Vec::len);
    CentralDifference {
        jacobian: DMatrix::from_fn(m, n, |i, j| cols[j][i]),
        steps,
        flips,
    }
}

/// Tolerance of a comparison: `|a − b| ≤ rel · max(|b|, floor · max|b|)` for every component.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tolerance {
    /// Relative tolerance.
    pub rel: f64,
    /// Fraction of the largest reference component below which a component is compared
    /// absolutely (against `floor · max|b|`) rather than relatively.
    pub floor: f64,
}

impl Tolerance {
    /// Relative tolerance `rel` with the floor `max(1e-6, 100 ε / rel)`.
    ///
    /// Components smaller than a millionth of the largest are round-off-sized and are held to
    /// an absolute bound instead. Entries computed from sums and differences of terms as large as
    /// the largest carry an absolute round-off of a few ε·max. So the absolute bound
    /// `rel · floor · max` is never set below `100 ε · max`: for `rel = 1e-10` the floor is 2.2e-4.
    pub fn rel(rel: f64) -> Self {
        Tolerance {
            rel,
            floor: (100.0 * f64::EPSILON / rel).max(1e-6),
        }
    }
}

/// One compared component.
#[derive(Clone, Debug, PartialEq)]
pub struct ComponentError {
    /// Output index.
    pub output: usize,
    /// Input index.
    pub input: usize,
    /// Checked value (hand-derived).
    pub value: f64,
    /// Reference value.
    pub reference: f64,
    /// Scaled error `|a − b| / max(|b|, floor · scale)`.
    pub error: f64,
}

/// Result of comparing a Jacobian with a reference.
#[derive(Clone, Debug)]
pub struct Comparison {
    /// What was compared with what, for the report.
    pub name: String,
    /// Tolerance used.
    pub tol: Tolerance,
    /// Largest |reference| component (the scale of the absolute floor).
    pub scale: f64,
    /// Worst component, if any was compared.
    pub worst: Option<ComponentError>,
    /// Components over tolerance.
    pub failures: usize,
    /// Components compared.
    pub compared: usize,
    /// Labels of the worst component: (output, input).
    pub worst_labels: Option<(String, String)>,
}

impl Comparison {
    /// True when every compared component is within tolerance.
    pub fn passed(&self) -> bool {
        self.failures == 0
    }
    /// Worst scaled error (0 when nothing was compared).
    pub fn max_error(&self) -> f64 {
        self.worst.as_ref().map_or(0.0, |w| w.error)
    }
}

impl fmt::Display for Comparison {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let status = if self.passed() { "ok" } else { "FAILED" };
        write!(
            f,
            "{:<34} {status:>6}: max scaled error {:.3e} (tol {:.1e}, floor {:.0e}·{:.3e}), {} of {} over",
            self.name,
            self.max_error(),
            self.tol.rel,
            self.tol.floor,
            self.scale,
            self.failures,
            self.compared
        )?;
        if let (Some(w), Some((o, i))) = (&self.worst, &self.worst_labels) {
            write!(
                f,
                "\n{:>42} worst ∂{o}/∂{i}: {:+.12e} vs {:+.12e}",
                "", w.value, w.reference
            )?;
        }
        Ok(())
    }
}

/// Compare `value` with `reference` component by component, skipping the input columns listed in
/// `skip_inputs` (for example those flagged by an active-set flip).
pub fn compare_matrices(
    name: &str,
    value: &DMatrix<f64>,
    reference: &DMatrix<f64>,
    tol: Tolerance,
    skip_inputs: &[usize],
    labels: &dyn Fn(usize, usize) -> (String, String),
) -> Comparison {
    assert_eq!(value.shape(), reference.shape(), "compare: shapes differ");
    let scale = reference
        .column_iter()
        .enumerate()
        .filter(|(j, _)| !skip_inputs.contains(j))
        .flat_map(|(_, c)| c.iter().map(|v| v.abs()).collect::<Vec<_>>())
        .fold(0.0_f64, f64::max);
    let mut worst: Option<ComponentError> = None;
    let mut failures = 0;
    let mut compared = 0;
    for j in 0..value.ncols() {
        if skip_inputs.contains(&j) {
            continue;
        }
        for i in 0..value.nrows() {
            let (a, b) = (value[(i, j)], reference[(i, j)]);
            let denom = b.abs().max(tol.floor * scale).max(f64::MIN_POSITIVE);
            let error = if a == b { 0.0 } else { (a - b).abs() / denom };
            compared += 1;
            // A NaN error is a failure.
            if error.is_nan() || error > tol.rel {
                failures += 1;
            }
            let worse = match &worst {
                None => true,
                Some(w) => error > w.error || error.is_nan(),
            };
            if worse {
                worst = Some(ComponentError {
                    output: i,
                    input: j,
                    value: a,
                    reference: b,
                    error,
                });
            }
        }
    }
    let worst_labels = worst.as_ref().map(|w| labels(w.output, w.input));
    Comparison {
        name: name.to_string(),
        tol,
        scale,
        worst,
        failures,
        compared,
        worst_labels,
    }
}

/// Compare a hand-derived Jacobian with a reference Jacobian of `f`.
pub fn compare<F: Differentiable>(
    f: &F,
    name: &str,
    value: &DMatrix<f64>,
    reference: &DMatrix<f64>,
    tol: Tolerance,
    skip_inputs: &[usize],
) -> Comparison {
    compare_matrices(name, value, reference, tol, skip_inputs, &|i, j| {
        (f.output_label(i), f.input_label(j))
    })
}

/// Tolerances and step of a three-way check.
#[derive(Clone, Copy, Debug)]
pub struct CheckOptions {
    /// Hand-derived against dual numbers: agreement to round-off.
    pub dual: Tolerance,
    /// Hand-derived against central differences: agreement to truncation error.
    pub fd: Tolerance,
    /// Finite-difference step.
    pub step: StepSize,
}

impl CheckOptions {
    /// Tolerances `dual_rel` and `fd_rel` with the default floor and step.
    pub fn new(dual_rel: f64, fd_rel: f64) -> Self {
        CheckOptions {
            dual: Tolerance::rel(dual_rel),
            fd: Tolerance::rel(fd_rel),
            step: StepSize::default(),
        }
    }
}

/// The three-way check of one hand-derived Jacobian.
#[derive(Clone, Debug)]
pub struct DerivativeReport {
    /// Title of the check.
    pub title: String,
    /// Hand-derived against the dual-number Jacobian.
    pub vs_dual: Comparison,
    /// Hand-derived against central differences (flipped columns left out).
    pub vs_fd: Comparison,
    /// The central-difference steps and active-set flips.
    pub fd: CentralDifference,
    /// The dual-number Jacobian.
    pub dual: DMatrix<f64>,
}

impl DerivativeReport {
    /// Both comparisons within tolerance.
    pub fn passed(&self) -> bool {
        self.vs_dual.passed() && self.vs_fd.passed()
    }
}

impl fmt::Display for DerivativeReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "== {} ==", self.title)?;
        writeln!(f, "{}", self.vs_dual)?;
        let (hmin, hmax) = self
            .fd
            .steps
            .iter()
            .fold((f64::INFINITY, 0.0_f64), |(a, b), &h| (a.min(h), b.max(h)));
        writeln!(f, "{}", self.vs_fd)?;
        write!(
            f,
            "{:>42} central-difference step h in [{hmin:.2e}, {hmax:.2e}]",
            ""
        )?;
        for flip in &self.fd.flips {
            let names: Vec<&str> = flip.entries.iter().map(|(_, s)| s.as_str()).collect();
            write!(
                f,
                "\n{:>42} active set flips within ±h of {} (left out of the FD comparison): {}",
                "",
                flip.input_label,
                names.join(", ")
            )?;
        }
        Ok(())
    }
}

/// Check a hand-derived Jacobian `hand` (outputs × inputs) of `f` at `x` three ways.
pub fn check<F: Differentiable>(
    f: &F,
    title: &str,
    x: &[f64],
    hand: &DMatrix<f64>,
    opts: CheckOptions,
) -> DerivativeReport {
    let dual = dual_jacobian(f, x);
    let fd = central_jacobian(f, x, opts.step);
    let skip: Vec<usize> = fd.flips.iter().map(|fl| fl.input).collect();
    let vs_dual = compare(
        f,
        "hand-derived vs dual numbers",
        hand,
        &dual,
        opts.dual,
        &[],
    );
    let vs_fd = compare(
        f,
        "hand-derived vs central differences",
        hand,
        &fd.jacobian,
        opts.fd,
        &skip,
    );
    DerivativeReport {
        title: title.to_string(),
        vs_dual,
        vs_fd,
        fd,
        dual,
    }
}

/// One row of a Taylor remainder test.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TaylorRow {
    /// Step along the direction.
    pub h: f64,
    /// `‖f(x + h d) − f(x) − h J d‖∞`.
    pub remainder: f64,
    /// Observed rate `log(r_k / r_{k−1}) / log(h_k / h_{k−1})` (NaN for the first row).
    pub rate: f64,
}

/// Taylor remainder test: with an exact directional derivative `jd = J d`, the remainder falls as
/// `h²`; with a wrong one, as `h`.
pub fn taylor_remainder<F: Differentiable>(
    f: &F,
    x: &[f64],
    direction: &[f64],
    jd: &[f64],
    hs: &[f64],
) -> Vec<TaylorRow> {
    let f0 = f.eval(x);
    let mut rows: Vec<TaylorRow> = Vec::with_capacity(hs.len());
    for &h in hs {
        let xh: Vec<f64> = x.iter().zip(direction).map(|(a, d)| a + h * d).collect();
        let fh = f.eval(&xh);
        let remainder = fh
            .iter()
            .zip(&f0)
            .zip(jd)
            .map(|((a, b), d)| (a - b - h * d).abs())
            .fold(0.0, f64::max);
        let rate = match rows.last() {
            Some(p) => (remainder / p.remainder).ln() / (h / p.h).ln(),
            None => f64::NAN,
        };
        rows.push(TaylorRow { h, remainder, rate });
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;

    /// f(x, y) = (x² y, sin x + y³).
    struct Toy;
    impl Differentiable for Toy {
        fn n_inputs(&self) -> usize {
            2
        }
        fn eval<T: Real>(&self, x: &[T]) -> Vec<T> {
            vec![x[0] * x[0] * x[1], x[0].sin() + x[1].powi(3)]
        }
    }

    fn toy_jacobian(x: &[f64]) -> DMatrix<f64> {
        DMatrix::from_row_slice(
            2,
            2,
            &[
                2.0 * x[0] * x[1],
                x[0] * x[0],
                x[0].cos(),
                3.0 * x[1] * x[1],
            ],
        )
    }

    #[test]
    fn correct_jacobian_passes_three_ways() {
        let x = [0.7, -1.3];
        let r = check(
            &Toy,
            "toy",
            &x,
            &toy_jacobian(&x),
            CheckOptions::new(1e-14, 1e-8),
        );
        assert!(r.passed(), "{r}");
        assert!(r.fd.flips.is_empty());
    }

    #[test]
    fn wrong_jacobian_is_caught_and_named() {
        let x = [0.7, -1.3];
        let mut j = toy_jacobian(&x);
        j[(1, 0)] *= 1.0 + 1e-6; // a relative error of 1e-6 in one component
        let r = check(&Toy, "toy", &x, &j, CheckOptions::new(1e-10, 1e-8));
        assert!(!r.vs_dual.passed());
        let w = r.vs_dual.worst.as_ref().unwrap();
        assert_eq!((w.output, w.input), (1, 0));
        assert!((w.error - 1e-6).abs() < 1e-9);
        assert!(r.to_string().contains("∂y[1]/∂x[0]"));
    }

    #[test]
    fn nan_is_a_failure() {
        let x = [0.7, -1.3];
        let mut j = toy_jacobian(&x);
        j[(0, 1)] = f64::NAN;
        let r = check(&Toy, "toy", &x, &j, CheckOptions::new(1e-10, 1e-6));
        assert!(!r.vs_dual.passed() && !r.vs_fd.passed());
    }

    /// |x| has a kink at 0: its active set is the sign.
    struct Kink;
    impl Differentiable for Kink {
        fn n_inputs(&self) -> usize {
            1
        }
        fn eval<T: Real>(&self, x: &[T]) -> Vec<T> {
            vec![x[0].abs()]
        }
        fn active_set(&self, x: &[f64]) -> Vec<u8> {
            vec![u8::from(x[0] >= 0.0)]
        }
    }

    #[test]
    fn active_set_flip_is_reported_and_left_out() {
        let r = check(
            &Kink,
            "kink",
            &[1e-9],
            &DMatrix::from_element(1, 1, 1.0),
            CheckOptions::new(1e-14, 1e-8),
        );
        assert_eq!(r.fd.flips.len(), 1);
        assert_eq!(r.vs_fd.compared, 0);
        assert!(r.to_string().contains("active set flips"));
    }

    #[test]
    fn taylor_rate_is_two_for_exact_and_one_for_wrong_derivative() {
        let x = [0.7, -1.3];
        let d = [0.3, 0.8];
        let jd: Vec<f64> = (toy_jacobian(&x) * nalgebra::DVector::from_row_slice(&d))
            .iter()
            .copied()
            .collect();
        let hs = [1e-1, 5e-2, 2.5e-2, 1.25e-2];
        let rows = taylor_remainder(&Toy, &x, &d, &jd, &hs);
        for r in &rows[1..] {
            assert!((r.rate - 2.0).abs() < 0.1, "{rows:?}");
        }
        // With a 1 % error in J d the remainder is 0.01·h·|Jd| + O(h²): at h ≤ 1e-4 the linear
        // term is ~100 times the quadratic one (|f''| ~ 1 here), so the rate is 1 within 0.05.
        let wrong: Vec<f64> = jd.iter().map(|v| v * 1.01).collect();
        let small = [1e-4, 5e-5, 2.5e-5, 1.25e-5];
        let rows = taylor_remainder(&Toy, &x, &d, &wrong, &small);
        for r in &rows[1..] {
            assert!((r.rate - 1.0).abs() < 0.05, "{rows:?}");
        }
    }
}
