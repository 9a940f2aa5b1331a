//! `anymo train owo|tokenizer|evaluator|generator`: the options of a training run, handed to
//! the recipes of `anymo_models::recipe`, which train on a manifest's train split and ship the
//! checkpoint with its model card.

use super::context::{StoreArgs, writable_checkpoints};
use anyhow::{Result, bail};
use anymo_generator::generate::Kind;
use anymo_models::checkpoint::DEFAULT_TOKENIZER;
use anymo_models::recipe::{self, EvaluatorRecipe, GeneratorRecipe, Run, TokenizerRecipe};
use anymo_tokenizer::dataset::LoaderConfig;
use anymo_tokenizer::tat::Representation;
use anymo_tokenizer::text::CachedEncoder;
use clap::{Parser, Subcommand, ValueEnum};
use std::path::PathBuf;
use std::time::Duration;

#[derive(Parser)]
pub struct Args {
    #[command(subcommand)]
    model: Model,
}

#[derive(Subcommand)]
enum Model {
    /// Pretrain OwO on every distinct training skeleton and synthetic variants.
    Owo(OwoArgs),
    /// Train TAT (or the zero-padded baseline, or an ablation) on the train split.
    Tokenizer(TokenizerArgs),
    /// Train the text-motion evaluator contrastively on the train split's TAT latents.
    Evaluator(EvaluatorArgs),
    /// Train the text-to-motion generator (masked or autoregressive) on the train split's tokens.
    Generator(GeneratorArgs),
}

#[derive(Parser)]
struct EvaluatorArgs {
    #[command(flatten)]
    common: Common,
    /// The tokenizer checkpoint whose latents the evaluator reads.
    #[arg(long, default_value = DEFAULT_TOKENIZER)]
    tokenizer: String,
    /// Optimiser steps.
    #[arg(long, default_value_t = 2000)]
    steps: u64,
    /// Clips per batch (the contrastive negatives).
    #[arg(long, default_value_t = 64)]
    batch_size: usize,
    /// Peak learning rate.
    #[arg(long, default_value_t = 3e-4)]
    lr: f64,
    /// Reworded variants per caption to train the text side on beside the captions (0:
    /// captions only, as the shipped evaluator).
    #[arg(long, default_value_t = 0)]
    paraphrases: usize,
}

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
enum GeneratorKind {
    /// MoMask's masked transformer.
    Masked,
    /// T2M-GPT's autoregressive transformer.
    Autoregressive,
}

#[derive(Parser)]
struct GeneratorArgs {
    #[command(flatten)]
    common: Common,
    /// The tokenizer checkpoint whose tokens the generator writes.
    #[arg(long, default_value = DEFAULT_TOKENIZER)]
    tokenizer: String,
    /// The first-layer model.
    #[arg(long, value_enum, default_value = "masked")]
    kind: GeneratorKind,
    /// Checkpoint name (default: `generator`, or `generator-ar` for the autoregressive kind).
    #[arg(long)]
    name: Option<String>,
    /// Optimiser steps.
    #[arg(long, default_value_t = 4000)]
    steps: u64,
    /// Crops per batch.
    #[arg(long, default_value_t = 32)]
    batch_size: usize,
    /// Peak learning rate.
    #[arg(long, default_value_t = 3e-4)]
    lr: f64,
    /// Transformer width (a tiny model for tests: 64).
    #[arg(long, default_value_t = 192)]
    dim: usize,
    /// Reworded variants per caption to train on beside the captions (0: captions only, as the
    /// shipped generators; 4 was measured in docs/measurements/generation.md).
    #[arg(long, default_value_t = 0)]
    paraphrases: usize,
    /// Length of the Gaussian noise added to each prompt embedding in training (0: none; 0.3
    /// was measured with the paraphrases).
    #[arg(long, default_value_t = 0.0)]
    text_noise: f32,
    /// Continue training the checkpoint of this name in the output folder (the optimiser and the
    /// learning-rate warm-up start again) up to `--steps` in all. With `--steps` at its own
    /// steps it takes none and writes the checkpoint again with its training captions, which
    /// generators trained before they kept them lack.
    #[arg(long)]
    continue_shipped: bool,
}

#[derive(Parser)]
struct Common {
    /// The corpus manifest.
    #[arg(long, default_value = "../shared/data/manifest.tsv")]
    manifest: PathBuf,
    /// Use at most this many clips per split (a quick run).
    #[arg(long)]
    limit: Option<usize>,
    /// The checkpoints folder the trained checkpoint is written to, and earlier ones read from
    /// (the repository's checkpoints/ replaces the shipped ones) [default: $ANYMO_CHECKPOINTS]
    #[arg(long)]
    out_dir: Option<PathBuf>,
    /// Where the resumable run state lives (default: DATA_DIR/train/NAME).
    #[arg(long)]
    run_dir: Option<PathBuf>,
    /// Seed of initialisation and sampling.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Seconds between saves of the resumable run state.
    #[arg(long, default_value_t = 120)]
    save_every: u64,
    #[command(flatten)]
    store: StoreArgs,
}

#[derive(Parser)]
struct OwoArgs {
    #[command(flatten)]
    common: Common,
    /// Optimiser steps.
    #[arg(long, default_value_t = 3000)]
    steps: u64,
}

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
enum Variant {
    /// TAT with gated FiLM over pretrained OwO.
    Tat,
    /// TAT with NEC's additive fusion.
    TatAdditive,
    /// TAT over an OwO that was never pretrained (frozen at initialisation).
    TatScratch,
    /// The zero-padded RVQ-VAE of NEC Table 1.
    Baseline,
}

#[derive(Parser)]
struct TokenizerArgs {
    #[command(flatten)]
    common: Common,
    /// Which model.
    #[arg(long, value_enum, default_value = "tat")]
    variant: Variant,
    /// Checkpoint name (default: the variant's).
    #[arg(long)]
    name: Option<String>,
    /// Optimiser steps.
    #[arg(long, default_value_t = 4000)]
    steps: u64,
    /// Windows per batch (fewer for skeletons with many joints).
    #[arg(long, default_value_t = 16)]
    batch_size: usize,
    /// Peak learning rate.
    #[arg(long, default_value_t = 5e-4)]
    lr: f64,
    /// RVQ layers.
    #[arg(long, default_value_t = 6)]
    rvq_layers: usize,
    /// Codes per RVQ layer.
    #[arg(long, default_value_t = 1024)]
    codes: usize,
    /// Continue training the checkpoint of this name in the output folder (its weights and
    /// codebooks; the optimiser and the learning-rate warm-up start again) up to `--steps` in
    /// all, so that training can go on across machines that do not keep run states.
    #[arg(long)]
    continue_shipped: bool,
    /// A loss term's weight, as NAME=VALUE (repeatable). The terms: rotation, root, position,
    /// velocity, contact, skating, commitment, heading and path (the root's heading and path
    /// integrated over each window; off by default); the others keep their defaults.
    #[arg(long = "weight", value_name = "NAME=VALUE", value_parser = parse_weight)]
    weights: Vec<(String, f32)>,
    /// Probability of rebasing a window on the pose of one of its frames (NEC C.1).
    #[arg(long, default_value_t = LoaderConfig::default().rebase)]
    rebase: f64,
    /// Probability of rebasing a window on a frame of any clip of its skeleton: motion read
    /// against a reference pose taken from other motion, as on a rig known from a few files.
    #[arg(long, default_value_t = LoaderConfig::default().rebase_other)]
    rebase_other: f64,
    /// Probability of reading a window against its own clip's mean pose, as `anymo tokenize`
    /// reads a user's clip.
    #[arg(long, default_value_t = LoaderConfig::default().rebase_own)]
    rebase_own: f64,
    /// The joint frames the codec reads motion in: `reference` (frames world-aligned at each
    /// skeleton's mean pose, facing +Z: no rig convention shows) or `rest` (each rig's own
    /// frames and BVH rest pose, as tokenizer v1).
    #[arg(long, default_value = "reference")]
    representation: Representation,
    /// Batches per optimiser step, each of one skeleton.
    #[arg(long, default_value_t = 2)]
    skeletons_per_step: usize,
    /// The baseline's trunk width in channels (only with `--variant baseline`; default 256, as
    /// v1's baseline). A run's state is about 12 bytes per parameter: 128 keeps it under the
    /// 20 MB a run may commit.
    #[arg(long)]
    width: Option<usize>,
}

pub fn run(args: Args) -> Result<()> {
    match args.model {
        Model::Owo(a) => {
            let (run, mut encoder) = a.common.run()?;
            recipe::train_owo(&run, a.steps, &mut encoder)?;
        }
        Model::Tokenizer(a) => {
            if a.width.is_some() && a.variant != Variant::Baseline {
                bail!("--width sets the baseline's trunk; TAT's widths are fixed (leave --width out)");
            }
            let (run, mut encoder) = a.common.run()?;
            let recipe = TokenizerRecipe {
                variant: match a.variant {
                    Variant::Tat => recipe::Variant::Tat,
                    Variant::TatAdditive => recipe::Variant::TatAdditive,
                    Variant::TatScratch => recipe::Variant::TatScratch,
                    Variant::Baseline => recipe::Variant::Baseline { width: a.width.unwrap_or(recipe::BASELINE_WIDTH) },
                },
                name: a.name,
                steps: a.steps,
                batch_size: a.batch_size,
                lr: a.lr,
                rvq_layers: a.rvq_layers,
                codes: a.codes,
                continue_shipped: a.continue_shipped,
                weights: a.weights,
                rebase: a.rebase,
                rebase_other: a.rebase_other,
                rebase_own: a.rebase_own,
                representation: a.representation,
                skeletons_per_step: a.skeletons_per_step,
            };
            recipe::train_tokenizer(&run, &recipe, &mut encoder)?;
        }
        Model::Evaluator(a) => {
            let (run, mut encoder) = a.common.run()?;
            let recipe = EvaluatorRecipe {
                tokenizer: a.tokenizer,
                steps: a.steps,
                batch_size: a.batch_size,
                lr: a.lr,
                paraphrases: a.paraphrases,
            };
            recipe::train_evaluator(&run, &recipe, &mut encoder)?;
        }
        Model::Generator(a) => {
            let (run, mut encoder) = a.common.run()?;
            let recipe = GeneratorRecipe {
                tokenizer: a.tokenizer,
                kind: match a.kind {
                    GeneratorKind::Masked => Kind::Masked,
                    GeneratorKind::Autoregressive => Kind::Autoregressive,
                },
                name: a.name,
                steps: a.steps,
                batch_size: a.batch_size,
                lr: a.lr,
                dim: a.dim,
                paraphrases: a.paraphrases,
                text_noise: a.text_noise,
                continue_shipped: a.continue_shipped,
            };
            recipe::train_generator(&run, &recipe, &mut encoder)?;
        }
    }
    Ok(())
}

impl Common {
    /// The run these options describe (its output folder settled before any training), and the
    /// sentence encoder.
    fn run(&self) -> Result<(Run, CachedEncoder)> {
        let (state_dir, exact) = match &self.run_dir {
            Some(dir) => (dir.clone(), true),
            None => (self.store.data_dir()?.join("train"), false),
        };
        let run = Run {
            manifest: self.manifest.clone(),
            limit: self.limit,
            out_dir: writable_checkpoints(self.out_dir.as_deref(), "--out-dir")?,
            state_dir,
            exact,
            seed: self.seed,
            save_every: Duration::from_secs(self.save_every),
            command: std::env::args().collect::<Vec<_>>().join(" "),
        };
        Ok((run, CachedEncoder::new(self.store.encoder()?)))
    }
}

/// A `NAME=VALUE` loss weight from the command line.
fn parse_weight(text: &str) -> Result<(String, f32), String> {
    let (name, value) = text.split_once('=').ok_or_else(|| format!("expected NAME=VALUE, found {text:?}"))?;
    let value: f32 = value.parse().map_err(|_| format!("the weight of {name} is not a number: {value:?}"))?;
    if !value.is_finite() || value < 0.0 {
        return Err(format!("the weight of {name} must be a finite number of at least 0, not {value}"));
    }
    Ok((name.to_string(), value))
}
