//! Typed model-card configurations, one per kind of model: what `config` holds in the JSON card
//! beside each checkpoint's weights, read as the struct of the kind the caller expects (see
//! [`crate::checkpoint::Checkpoint::card`]) instead of by string keys.

use crate::train::{CodecTraining, StepTraining};
use anymo_generator::{EvaluatorConfig, GeneratorConfig};
use anymo_tokenizer::tat::{BaselineConfig, TokenizerConfig};
use serde::{Deserialize, Serialize};

/// The tokenizer a generator or evaluator was trained on: its codes mean something only to the
/// tokenizer with these very weights.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct TokenizerRef {
    /// The tokenizer checkpoint's name.
    pub tokenizer_checkpoint: String,
    /// The blake3 (hex) of its weights at training time.
    pub tokenizer_blake3: String,
}

/// A TAT checkpoint's card (`tat` and its ablations).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TokenizerCard {
    /// The OwO checkpoint it was trained over (`random` for none).
    #[serde(default = "default_owo")]
    pub owo_checkpoint: String,
    /// The model's shape.
    pub tokenizer: TokenizerConfig,
    /// The training run's settings.
    pub training: CodecTraining,
}

fn default_owo() -> String {
    "owo".to_string()
}

/// The zero-padded baseline's card.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BaselineCard {
    /// The model's shape.
    pub baseline: BaselineConfig,
    /// The training run's settings.
    pub training: CodecTraining,
}

/// Either codec's card: a checkpoint `anymo eval tokenizer` can measure.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(untagged)]
pub enum CodecCard {
    /// TAT.
    Tokenizer(TokenizerCard),
    /// The baseline.
    Baseline(BaselineCard),
}

/// A generator's card (`generator`, `generator-ar`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GeneratorCard {
    /// The tokenizer it generates codes of.
    #[serde(flatten)]
    pub trained_on: TokenizerRef,
    /// The model's shape.
    pub generator: GeneratorConfig,
    /// The training run's settings.
    pub training: StepTraining,
    /// Reworded variants per caption that training drew among beside the captions (0: the
    /// captions only, as generators trained before caption augmentation).
    #[serde(default)]
    pub paraphrases: usize,
}

/// The text-motion evaluator's card.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct EvaluatorCard {
    /// The tokenizer whose codes it reads.
    #[serde(flatten)]
    pub trained_on: TokenizerRef,
    /// The model's shape.
    pub evaluator: EvaluatorConfig,
    /// The training run's settings.
    pub training: StepTraining,
    /// Reworded variants per caption that training drew among beside the captions (0: the
    /// captions only, as evaluators trained before caption augmentation).
    #[serde(default)]
    pub paraphrases: usize,
}

/// A model trained on a tokenizer's codes.
pub trait TrainedOnTokens {
    /// The `anymo train` subcommand that makes a new one.
    const TRAIN_COMMAND: &'static str;
    /// The tokenizer it was trained on.
    fn tokenizer(&self) -> &TokenizerRef;
}

impl TrainedOnTokens for GeneratorCard {
    const TRAIN_COMMAND: &'static str = "generator";
    fn tokenizer(&self) -> &TokenizerRef {
        &self.trained_on
    }
}

impl TrainedOnTokens for EvaluatorCard {
    const TRAIN_COMMAND: &'static str = "evaluator";
    fn tokenizer(&self) -> &TokenizerRef {
        &self.trained_on
    }
}
