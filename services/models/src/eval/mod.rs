//! The evaluations of `../shared/docs/EVAL.md`, each a report with its Markdown tables and its
//! figures as JSON: the tokenizers' reconstruction and transfer ([`tokenizer`]), text to motion
//! ([`generator`]), held-out prompts judged by what the generated motion does ([`prompts`]), search ([`retrieval`]) and motion by example across skeletons
//! ([`by_example`]). The metrics themselves are the domain crates'
//! (`anymo_motion::metrics`, `anymo_generator::evaluator`, `anymo_retrieval::metrics`); these
//! modules are the protocols that choose the clips, run the models and tabulate.

pub mod by_example;
pub mod generator;
pub mod prompts;
pub mod retrieval;
pub mod tokenizer;

use crate::checkpoint::Checkpoint;
use crate::data::{self, ModelClip};
use anyhow::{Context, Result};
use anymo_tokenizer::nn::load_card;
use std::path::Path;

/// What a row's name gets when its motion went through the cleanup users get by default.
pub const CLEANED: &str = " + cleanup";

/// The usable clips of a manifest (at most `limit` per split), with how many cleaning rejected.
pub fn clips(manifest: &Path, limit: Option<usize>) -> Result<(Vec<ModelClip>, usize)> {
    data::load_manifest(manifest, limit).with_context(|| format!("reading the manifest {}", manifest.display()))
}

/// Updates the figures in the model card of checkpoint `name` in the folder `dir`.
pub fn record(dir: &Path, name: &str, update: impl FnOnce(&mut serde_json::Value)) -> Result<()> {
    let (_, path) = Checkpoint::in_dir(dir, name).files().expect("a folder's checkpoint has files");
    let mut card = load_card(&path)?;
    update(&mut card.metrics);
    card.save(&path).with_context(|| format!("writing {}", path.display()))
}

/// A number as the tables print distances.
fn f(x: f64) -> String {
    format!("{x:.4}")
}

/// A Markdown table, built row by row.
struct Table(String);

impl Table {
    /// A table with these column headers and no rows.
    fn new(headers: &[&str]) -> Table {
        Table(format!("| {} |\n|{}\n", headers.join(" | "), "---|".repeat(headers.len())))
    }

    /// Appends a row of cells.
    fn row(&mut self, cells: &[String]) {
        self.0.push_str(&format!("| {} |\n", cells.join(" | ")));
    }

    /// The table's text.
    fn into_text(self) -> String {
        self.0
    }
}
