//! The `ghostship` command: parse the arguments, run the command, report errors once as a chain
//! (`error: outer: inner: …`, non-zero exit; clap's usage errors exit with 2).

use std::process::ExitCode;

mod cli;

fn main() -> ExitCode {
    let args = cli::parse();
    match cli::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {}", cli::error_chain(&err));
            ExitCode::FAILURE
        }
    }
}
