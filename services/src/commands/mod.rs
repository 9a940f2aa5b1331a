//! The subcommands of `anymo`, one module each.

mod convert;
mod fk;
mod input;
mod inspect;

use anyhow::Result;
use clap::{Parser, Subcommand};

/// anymo: motion for any skeleton.
#[derive(Parser)]
#[command(name = "anymo", version, about)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Show a BVH or glTF file's skeleton tree, channels, frames, labels and warnings.
    Inspect(inspect::Args),
    /// Convert a BVH or GLB file to BVH, optionally resampled or normalised.
    Convert(convert::Args),
    /// Print the global joint positions of one frame as JSON.
    Fk(fk::Args),
}

impl Cli {
    /// Runs the chosen subcommand.
    pub fn run(self) -> Result<()> {
        match self.command {
            Command::Inspect(args) => inspect::run(args),
            Command::Convert(args) => convert::run(args),
            Command::Fk(args) => fk::run(args),
        }
    }
}
