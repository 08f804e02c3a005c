//! The `fmrh` binary: the command line lives in the library (`src/cli/`), beside the rooms it
//! uses; this is only its entry point.

fn main() -> std::process::ExitCode {
    fmrh::run_cli()
}
