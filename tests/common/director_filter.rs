//! Shared by the director-filter tests: the filter among a problem's loads, a deterministic
//! generator of test perturbations, and the largest magnitude of a vector.
use shelldsa::shell::load::Load;
use shelldsa::shell::problem::ShellProblem;
use shelldsa::shell::stabilisation::DirectorFilter;

/// The director filter among the problem's loads (a case with `director_stabilisation > 0`).
pub fn filter(p: &ShellProblem) -> &DirectorFilter {
    p.loads()
        .iter()
        .find_map(|l| match l {
            Load::DirectorFilter(f) => Some(f),
            _ => None,
        })
        .expect("director_stabilisation > 0 adds the filter to the loads")
}

/// A small linear congruential generator: uniform in [−1, 1).
pub struct Lcg(pub u64);
impl Lcg {
    pub fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// The largest magnitude of `v`.
pub fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |a, x| a.max(x.abs()))
}
