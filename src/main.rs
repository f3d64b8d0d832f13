//! `mrsmap`: multi-resolution surfel maps on the command line.

mod cli;

use anyhow::Result;
use clap::Parser;

fn main() -> Result<()> {
    let cli = cli::Cli::parse();
    cli::run(cli.command)
}
