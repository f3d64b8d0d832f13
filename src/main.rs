//! `mrsmap`: multi-resolution surfel maps on the command line.

mod cli;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = cli::Cli::parse();
    cli::run(cli.command).unwrap_or_else(|e| {
        eprintln!("{}", cli::report(&e));
        ExitCode::FAILURE
    })
}
