//! Shared by the director-filter tests: the filter among a problem's loads.
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
