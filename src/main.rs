fn main() {
    std::process::exit(shelldsa::cli::main_with_args(std::env::args()));
}
