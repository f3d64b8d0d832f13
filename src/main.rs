//! `mrsmap`: multi-resolution surfel maps on the command line.

mod cli;

use anyhow::Result;
use clap::Parser;
use std::process::ExitCode;

fn main() -> Result<ExitCode> {
    let cli = cli::Cli::parse();
    cli::run(cli.command)
}
