//! The `anymo` command line: inspect, convert and pose motion files.

mod commands;

use anyhow::Result;
use clap::Parser;

fn main() -> Result<()> {
    commands::Cli::parse().run()
}
