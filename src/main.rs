//! `mrsmap`: multi-resolution surfel maps on the command line.

mod cli;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = cli::Cli::parse();
    if cli.command.prints_for_a_pipe() {
        // `mrsmap eval … | head` ends quietly, as a Unix tool does, instead of panicking
        // on the closed pipe (Rust ignores SIGPIPE by default).
        sigpipe::reset();
    }
    cli::run(cli.command).unwrap_or_else(|e| {
        eprintln!("{}", cli::report(&e));
        ExitCode::FAILURE
    })
}
