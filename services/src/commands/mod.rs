//! The subcommands of `anymo`, one module each.

mod context;
mod convert;
mod corpus;
mod fk;
mod ingest;
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
    /// Add a folder of BVH/GLB files or a manifest TSV to the corpus store.
    Ingest(ingest::Args),
    /// Show what the corpus store holds, or export a clip.
    Corpus(corpus::Args),
}

impl Cli {
    /// Runs the chosen subcommand.
    pub fn run(self) -> Result<()> {
        match self.command {
            Command::Inspect(args) => inspect::run(args),
            Command::Convert(args) => convert::run(args),
            Command::Fk(args) => fk::run(args),
            Command::Ingest(args) => ingest::run(args),
            Command::Corpus(args) => corpus::run(args),
        }
    }
}
