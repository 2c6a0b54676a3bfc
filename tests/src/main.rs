//! `ballbar` for the end-to-end tests: the same entry point as the real binary.

fn main() -> std::process::ExitCode {
    ballbar_cli::main_with_args(std::env::args_os())
}
