//! The checkpoints anymo ships and loads: where they live and how a trained tokenizer is rebuilt
//! from its weights and model card.

use anyhow::{Context, Result, bail};
use anymo_tokenizer::nn::{ModelCard, Params, load_card};
use anymo_tokenizer::owo::graph::GLOBAL_NODE_TEXT;
use anymo_tokenizer::tat::{Codec, Tat, TokenizerConfig};
use anymo_tokenizer::text::CachedEncoder;
use std::path::{Path, PathBuf};

/// The shipped checkpoints' folder: `$ANYMO_CHECKPOINTS`, else the repository's
/// `tokenizer/checkpoints`.
pub fn default_dir() -> PathBuf {
    match std::env::var_os("ANYMO_CHECKPOINTS") {
        Some(dir) => PathBuf::from(dir),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("../tokenizer/checkpoints"),
    }
}

/// Weights and card of a named checkpoint in `dir`.
pub fn files(dir: &Path, name: &str) -> (PathBuf, PathBuf) {
    (dir.join(format!("{name}.safetensors")), dir.join(format!("{name}.json")))
}

/// Reads a checkpoint's model card, with an error that says how to get the checkpoint.
pub fn card(dir: &Path, name: &str) -> Result<ModelCard> {
    let (weights, card) = files(dir, name);
    if !weights.exists() || !card.exists() {
        bail!(
            "checkpoint {name} not found in {} (a clean clone ships it in tokenizer/checkpoints; train one with `anymo train {}`)",
            dir.display(),
            match name {
                "owo" => "owo",
                "evaluator" => "evaluator",
                n if n.starts_with("generator") => "generator",
                _ => "tokenizer",
            }
        );
    }
    Ok(load_card(&card)?)
}

/// Loads a trained TAT (`name`, usually `tat`) and the OwO it was trained over.
pub fn load_tat(dir: &Path, name: &str, encoder: &mut CachedEncoder) -> Result<(Tat, ModelCard)> {
    let card = card(dir, name)?;
    let config: TokenizerConfig = serde_json::from_value(card.config["tokenizer"].clone())
        .with_context(|| format!("model card of {name} has no tokenizer configuration"))?;
    let owo_name = card.config["owo_checkpoint"].as_str().unwrap_or("owo").to_string();
    let global = encoder.encode(&[GLOBAL_NODE_TEXT])?.remove(0);
    let mut owo_params = Params::new(0);
    let mut tat = Tat::new(config, 0, &mut owo_params, global)?;
    if owo_name != "random" {
        let (owo_weights, _) = files(dir, &owo_name);
        owo_params.load(&owo_weights).with_context(|| format!("loading {}", owo_weights.display()))?;
    }
    let rest = tat.params_mut().load(&files(dir, name).0)?;
    tat.restore_buffers(&rest)?;
    Ok((tat, card))
}

/// The blake3 of a checkpoint's weights (hex), which a generator's or evaluator's card records
/// for the tokenizer it was trained on: a tokenizer retrained under the same name has another.
pub fn weights_blake3(dir: &Path, name: &str) -> Result<String> {
    let (weights, _) = files(dir, name);
    let bytes = std::fs::read(&weights).with_context(|| format!("reading {}", weights.display()))?;
    Ok(blake3::hash(&bytes).to_hex().to_string())
}

/// Loads the TAT a generator or evaluator was trained on, as its model card names it, and
/// refuses a tokenizer of that name whose weights are not the ones it was trained on (its codes
/// would mean something else).
pub fn load_tat_of(dir: &Path, card: &ModelCard, encoder: &mut CachedEncoder) -> Result<Tat> {
    let tokenizer = card.config["tokenizer_checkpoint"].as_str().unwrap_or("tat");
    let trained_on = card.config["tokenizer_blake3"].as_str().with_context(|| {
        format!(
            "the model card of {} does not record which {tokenizer} weights it was trained on; retrain it",
            card.model
        )
    })?;
    let present = weights_blake3(dir, tokenizer)?;
    if present != trained_on {
        bail!(
            "{} was trained on other {tokenizer} weights than {} holds (blake3 {trained_on}, found {present}); \
             retrain it with `anymo train {}` or restore the {tokenizer} it was trained on",
            card.model,
            dir.join(format!("{tokenizer}.safetensors")).display(),
            if card.model == "evaluator" { "evaluator" } else { "generator" }
        );
    }
    Ok(load_tat(dir, tokenizer, encoder)?.0)
}
