//! The `shelldsa` command run in-process (`cli::main_with_args`), for tests that check exit
//! codes and written files.

/// Run `shelldsa ARGS…` and return its exit code.
pub fn cli(args: &[&str]) -> i32 {
    shelldsa::cli::main_with_args(
        std::iter::once("shelldsa")
            .chain(args.iter().copied())
            .map(String::from),
    )
}

/// Write the case `text` as `DIR/case.toml` (the directory made afresh), run `shelldsa run` on
/// it with output in `DIR/out` and the `extra` arguments, check that it exits with 0, and
/// return its `results.json`.
#[allow(dead_code)]
pub fn run_case_text(dir: &std::path::Path, text: &str, extra: &[&str]) -> serde_json::Value {
    let _ = std::fs::remove_dir_all(dir);
    let (code, case, out) = command_on_text("run", dir, "case", "out", text, extra);
    assert_eq!(
        code,
        0,
        "`shelldsa run` of {} exited with {code}",
        case.display()
    );
    serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap()
}

/// Write the case `text` as `DIR/NAME.toml`, run `shelldsa dsa` on it with output in
/// `DIR/NAME` and the `extra` arguments; return the exit code and the output directory.
#[allow(dead_code)]
pub fn dsa_case_text(
    dir: &std::path::Path,
    name: &str,
    text: &str,
    extra: &[&str],
) -> (i32, std::path::PathBuf) {
    let (code, _, out) = command_on_text("dsa", dir, name, name, text, extra);
    (code, out)
}

/// Write `text` as `DIR/CASE.toml` and run `shelldsa COMMAND` on it with output in `DIR/OUT`
/// and the `extra` arguments: the exit code, the case file and the output directory.
fn command_on_text(
    command: &str,
    dir: &std::path::Path,
    case: &str,
    out: &str,
    text: &str,
    extra: &[&str],
) -> (i32, std::path::PathBuf, std::path::PathBuf) {
    std::fs::create_dir_all(dir).unwrap();
    let case = dir.join(format!("{case}.toml"));
    std::fs::write(&case, text).unwrap();
    let out = dir.join(out);
    let mut args = vec![
        command,
        case.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    (cli(&args), case, out)
}

/// Displacement of monitor `name` at the last converged step of a `results.json`.
#[allow(dead_code)]
pub fn last_monitor(results: &serde_json::Value, name: &str) -> [f64; 3] {
    let steps = results["steps"].as_array().unwrap();
    let last = steps.iter().rev().find(|s| s["converged"] == true).unwrap();
    let d = &last["monitors"][name]["displacement"];
    [0, 1, 2].map(|i| d[i].as_f64().unwrap())
}
