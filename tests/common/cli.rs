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
