//! The `ballbar` binary; all logic is in the library.

fn main() -> std::process::ExitCode {
    ballbar_cli::main_with_args(std::env::args_os())
}
