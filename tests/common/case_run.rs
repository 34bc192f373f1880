//! Runs a shell case text in process, as `shelldsa run` does, with its output in a temporary
//! directory of its own (removed afterwards: the tests of one file run in parallel).
#![allow(dead_code)] // each test file uses a subset

use shelldsa::io::shell_build::{self, RunStatus, RunSummary};
use shelldsa::io::shell_case::parse_shell_case;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

/// The text of the shipped case `verification/<dir>/case.toml`.
pub fn shipped_case(dir: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("verification")
        .join(dir)
        .join("case.toml");
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Parses, builds and runs `text` (`name` is the file name its errors carry) and asserts that
/// the run completed.
pub fn run_complete(text: &str, name: &str) -> RunSummary {
    static RUNS: AtomicUsize = AtomicUsize::new(0);
    let case = parse_shell_case(text, Path::new(name)).unwrap();
    let mut built = shell_build::build(&case).unwrap();
    let run = RUNS.fetch_add(1, Ordering::Relaxed);
    let out = std::env::temp_dir().join(format!("shelldsa-{name}-{}-{run}", std::process::id()));
    let s = shell_build::run(&case, &mut built, &out, std::time::Instant::now(), |_| {}).unwrap();
    let _ = std::fs::remove_dir_all(&out);
    assert_eq!(s.status, RunStatus::Complete, "{name}");
    s
}
