//! The subcommands of `anymo`, one module each.

mod context;
mod convert;
mod corpus;
mod eval;
mod fk;
mod generate;
mod ingest;
mod input;
mod inspect;
mod search;
mod serve;
mod tokens;
mod train;

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
    /// Train a model (OwO, the tokenizer, its baseline and ablations) on a manifest.
    Train(train::Args),
    /// Measure trained models by the protocol of EVAL.md.
    Eval(eval::Args),
    /// Turn a clip into TAT tokens (JSON).
    Tokenize(tokens::TokenizeArgs),
    /// Turn tokens into motion on a given skeleton (BVH).
    Detokenize(tokens::DetokenizeArgs),
    /// Move a clip onto another skeleton (BVH), through tokens.
    Transfer(tokens::TransferArgs),
    /// Motion from a text prompt on any skeleton (BVH).
    Generate(generate::GenerateArgs),
    /// Edit a clip by prompt: inpaint a span, continue it, or chain prompts.
    Edit(generate::EditArgs),
    /// Search the motion library by text, by example clip and by filters.
    Search(search::Args),
    /// Serve the REST and gRPC API (generation, editing, transfer, tokens, search, corpus).
    Serve(serve::Args),
}

impl Cli {
    /// The threads each model call's matrix products use: one for `serve`, whose workers (one
    /// per core) run calls side by side, which embeds 1.3x the queries one encoder on every
    /// core does (`cargo bench --workspace --bench sentence_encoder`); every core for the other
    /// commands, which make one call at a time.
    pub fn threads_per_call(&self, cores: usize) -> usize {
        match self.command {
            Command::Serve(_) => 1,
            _ => cores,
        }
    }

    /// Runs the chosen subcommand.
    pub fn run(self) -> Result<()> {
        match self.command {
            Command::Inspect(args) => inspect::run(args),
            Command::Convert(args) => convert::run(args),
            Command::Fk(args) => fk::run(args),
            Command::Ingest(args) => ingest::run(args),
            Command::Corpus(args) => corpus::run(args),
            Command::Train(args) => train::run(args),
            Command::Eval(args) => eval::run(args),
            Command::Tokenize(args) => tokens::run_tokenize(args),
            Command::Detokenize(args) => tokens::run_detokenize(args),
            Command::Transfer(args) => tokens::run_transfer(args),
            Command::Generate(args) => generate::run_generate(args),
            Command::Edit(args) => generate::run_edit(args),
            Command::Search(args) => search::run(args),
            Command::Serve(args) => serve::run(args),
        }
    }
}
