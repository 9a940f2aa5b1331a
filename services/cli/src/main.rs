//! The `anymo` command line: motion files, the corpus, the models, search and the server.

mod commands;

use anyhow::Result;
use clap::Parser;

fn main() -> Result<()> {
    commands::Cli::parse().run()
}
