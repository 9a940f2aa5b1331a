//! Checkpoints: where they come from (a folder, or the set built into the `anymo` binary), one
//! named [`Checkpoint`] with its weights and typed model card, and rebuilding a trained tokenizer
//! from them.

use crate::card::{TokenizerCard, TrainedOnTokens};
use anymo_tokenizer::nn::{ModelCard, Params};
use anymo_tokenizer::owo::graph::GLOBAL_NODE_TEXT;
use anymo_tokenizer::tat::{Codec, Tat};
use anymo_tokenizer::text::CachedEncoder;
use candle_core::{Device, Tensor};
use serde::de::DeserializeOwned;
use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};

/// The tokenizer that tokens and transfer use, and that new evaluators and generators
/// are trained on, unless told otherwise: tokenizer v2, which reads every skeleton against a
/// reference pose (`tat`, v1, still ships and is chosen by name).
pub const DEFAULT_TOKENIZER: &str = "tat-v2";

/// A checkpoint compiled into a binary: its name, model card text and safetensors bytes.
#[derive(Debug)]
pub struct BuiltIn {
    /// The checkpoint's name (`tat`, `generator`, ...).
    pub name: &'static str,
    /// The model card, JSON.
    pub card: &'static str,
    /// The weights, safetensors.
    pub weights: &'static [u8],
}

/// Where a set of checkpoints lives.
#[derive(Clone, Debug)]
pub enum Checkpoints {
    /// `NAME.safetensors` and `NAME.json` files in a folder.
    Dir(PathBuf),
    /// The set compiled into the running binary.
    BuiltIn(&'static [BuiltIn]),
}

/// Why a checkpoint could not be read.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    /// No checkpoint of that name.
    #[error("checkpoint {name} not found in {location} ({hint})")]
    Missing {
        /// The name asked for.
        name: String,
        /// Where it was looked for.
        location: String,
        /// How to get one.
        hint: String,
    },
    /// A file could not be read.
    #[error("reading {path}: {error}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        error: std::io::Error,
    },
    /// The card is not JSON of a model card, or not of the kind of model asked for.
    #[error("the model card of {name} is not a card of {kind}: {error}")]
    Card {
        /// The checkpoint.
        name: String,
        /// The kind of model asked for.
        kind: &'static str,
        /// What did not fit.
        error: serde_json::Error,
    },
    /// The weights do not load into the model the card describes.
    #[error("loading the weights of {name}: {error}")]
    Weights {
        /// The checkpoint.
        name: String,
        /// The cause.
        error: candle_core::Error,
    },
    /// A model trained on a tokenizer whose weights have changed since.
    #[error(transparent)]
    StaleTokenizer(Box<StaleTokenizer>),
}

/// A generator or evaluator whose tokenizer's weights are not the ones it was trained on.
#[derive(Debug, thiserror::Error)]
#[error(
    "{model} was trained on other {tokenizer} weights than {location} holds (blake3 {trained_on}, found {present}); \
     retrain it with `anymo train {command}` or restore the {tokenizer} it was trained on"
)]
pub struct StaleTokenizer {
    /// The model.
    pub model: String,
    /// The tokenizer checkpoint's name.
    pub tokenizer: String,
    /// Where the tokenizer was found.
    pub location: String,
    /// The blake3 its card records.
    pub trained_on: String,
    /// The blake3 of the weights present.
    pub present: String,
    /// The training command that makes a new one.
    pub command: &'static str,
}

impl fmt::Display for Checkpoints {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Checkpoints::Dir(dir) => write!(f, "{}", dir.display()),
            Checkpoints::BuiltIn(_) => f.write_str("the checkpoints built into anymo"),
        }
    }
}

impl Checkpoints {
    /// The checkpoint named `name` in this set (it may not exist: reading it says so).
    pub fn get(&self, name: &str) -> Checkpoint {
        Checkpoint { set: self.clone(), name: name.to_string() }
    }
}

/// One named checkpoint: safetensors weights and the model card beside them.
#[derive(Clone, Debug)]
pub struct Checkpoint {
    set: Checkpoints,
    name: String,
}

impl Checkpoint {
    /// A checkpoint in a folder.
    pub fn in_dir(dir: &Path, name: &str) -> Checkpoint {
        Checkpoints::Dir(dir.to_path_buf()).get(name)
    }

    /// Its name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Another checkpoint of the same set (the OwO a tokenizer was trained over, the tokenizer a
    /// generator reads).
    pub fn sibling(&self, name: &str) -> Checkpoint {
        self.set.get(name)
    }

    /// Whether the set has this checkpoint (its weights and its card).
    pub fn exists(&self) -> bool {
        match (&self.set, self.files()) {
            (Checkpoints::BuiltIn(all), _) => self.built_in(all).is_ok(),
            (Checkpoints::Dir(_), Some((weights, card))) => weights.is_file() && card.is_file(),
            (Checkpoints::Dir(_), None) => false,
        }
    }

    /// The weights' and card's paths, for a checkpoint in a folder (training writes there).
    pub fn files(&self) -> Option<(PathBuf, PathBuf)> {
        match &self.set {
            Checkpoints::Dir(dir) => {
                Some((dir.join(format!("{}.safetensors", self.name)), dir.join(format!("{}.json", self.name))))
            }
            Checkpoints::BuiltIn(_) => None,
        }
    }

    fn missing(&self) -> CheckpointError {
        let train = match self.name.as_str() {
            "owo" => "owo",
            "evaluator" => "evaluator",
            n if n.starts_with("generator") => "generator",
            _ => "tokenizer",
        };
        CheckpointError::Missing {
            name: self.name.clone(),
            location: self.set.to_string(),
            hint: format!("anymo ships it in checkpoints/ and in the binary; train one with `anymo train {train}`"),
        }
    }

    fn built_in(&self, all: &'static [BuiltIn]) -> Result<&'static BuiltIn, CheckpointError> {
        all.iter().find(|c| c.name == self.name).ok_or_else(|| self.missing())
    }

    fn read(&self, path: &Path) -> Result<Vec<u8>, CheckpointError> {
        std::fs::read(path).map_err(|error| CheckpointError::Io { path: path.display().to_string(), error })
    }

    /// The model card's text.
    fn card_text(&self) -> Result<String, CheckpointError> {
        match (&self.set, self.files()) {
            (Checkpoints::BuiltIn(all), _) => Ok(self.built_in(all)?.card.to_string()),
            (Checkpoints::Dir(_), Some((weights, card))) => {
                if !weights.is_file() || !card.is_file() {
                    return Err(self.missing());
                }
                String::from_utf8(self.read(&card)?).map_err(|e| CheckpointError::Io {
                    path: card.display().to_string(),
                    error: std::io::Error::new(std::io::ErrorKind::InvalidData, e),
                })
            }
            (Checkpoints::Dir(_), None) => unreachable!("a folder's checkpoint has files"),
        }
    }

    /// The model card with its configuration read as `C`, the kind of model the caller expects
    /// (see [`crate::card`]); a card of another kind is refused, naming what did not fit.
    pub fn card<C: DeserializeOwned>(&self, kind: &'static str) -> Result<ModelCard<C>, CheckpointError> {
        let text = self.card_text()?;
        serde_json::from_str(&text).map_err(|error| CheckpointError::Card { name: self.name.clone(), kind, error })
    }

    /// The weights' bytes.
    pub fn weights(&self) -> Result<std::borrow::Cow<'static, [u8]>, CheckpointError> {
        match (&self.set, self.files()) {
            (Checkpoints::BuiltIn(all), _) => Ok(std::borrow::Cow::Borrowed(self.built_in(all)?.weights)),
            (Checkpoints::Dir(_), Some((weights, _))) => {
                if !weights.is_file() {
                    return Err(self.missing());
                }
                Ok(std::borrow::Cow::Owned(self.read(&weights)?))
            }
            (Checkpoints::Dir(_), None) => unreachable!("a folder's checkpoint has files"),
        }
    }

    /// Loads the weights into `params` and returns the tensors that are not parameters (buffers).
    pub fn load_into(&self, params: &mut Params) -> Result<HashMap<String, Tensor>, CheckpointError> {
        let weights = |error| CheckpointError::Weights { name: self.name.clone(), error };
        let tensors = candle_core::safetensors::load_buffer(&self.weights()?, &Device::Cpu).map_err(weights)?;
        params.assign(tensors).map_err(weights)
    }

    /// The blake3 of the weights (hex), which a generator's or evaluator's card records for the
    /// tokenizer it was trained on: a tokenizer retrained under the same name has another.
    pub fn weights_blake3(&self) -> Result<String, CheckpointError> {
        Ok(blake3::hash(&self.weights()?).to_hex().to_string())
    }

    /// Loads a trained TAT from this checkpoint, with the OwO its card names.
    pub fn load_tat(&self, encoder: &mut CachedEncoder) -> anyhow::Result<(Tat, ModelCard<TokenizerCard>)> {
        let card: ModelCard<TokenizerCard> = self.card("a tokenizer")?;
        let global = encoder.encode(&[GLOBAL_NODE_TEXT])?.remove(0);
        let mut owo_params = Params::new(0);
        let mut tat = Tat::new(card.config.tokenizer.clone(), 0, &mut owo_params, global)?;
        if card.config.owo_checkpoint != "random" {
            self.sibling(&card.config.owo_checkpoint).load_into(&mut owo_params)?;
        }
        let rest = self.load_into(tat.params_mut())?;
        tat.restore_buffers(&rest)?;
        Ok((tat, card))
    }

    /// Loads the TAT a model was trained on (as its card names it), refusing a tokenizer of that
    /// name whose weights are not the ones it was trained on: its codes would mean something else.
    pub fn load_tat_of<C: TrainedOnTokens>(
        &self,
        card: &ModelCard<C>,
        encoder: &mut CachedEncoder,
    ) -> anyhow::Result<Tat> {
        let trained = card.config.tokenizer();
        let tokenizer = self.sibling(&trained.tokenizer_checkpoint);
        let present = tokenizer.weights_blake3()?;
        if present != trained.tokenizer_blake3 {
            return Err(CheckpointError::StaleTokenizer(Box::new(StaleTokenizer {
                model: card.model.clone(),
                tokenizer: trained.tokenizer_checkpoint.clone(),
                location: match tokenizer.files() {
                    Some((weights, _)) => weights.display().to_string(),
                    None => tokenizer.set.to_string(),
                },
                trained_on: trained.tokenizer_blake3.clone(),
                present,
                command: C::TRAIN_COMMAND,
            }))
            .into());
        }
        Ok(tokenizer.load_tat(encoder)?.0)
    }
}
