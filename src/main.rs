//! The `levelscan` command line: a thin layer over the library (see `cli/`).

mod cli;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    match cli::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if cli::is_broken_pipe(&e) => ExitCode::SUCCESS,
        Err(e) => {
            // The contract's one-line message: `FILE:LINE: what is wrong` for bad input.
            eprintln!("{e:#}");
            ExitCode::FAILURE
        }
    }
}
