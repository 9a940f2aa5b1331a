//! The training recipes behind `anymo train`: for each model, from a manifest's train split to a
//! checkpoint and its typed model card in a checkpoints folder. The loops themselves (resumable,
//! bit-exact) are [`crate::train`]'s; a recipe chooses the model's shape, the data and the
//! settings, and records them.

use crate::card::{BaselineCard, CodecCard, EvaluatorCard, GeneratorCard, TokenizerCard, TokenizerRef};
use crate::checkpoint::Checkpoint;
use crate::data::{self, ModelClip};
use crate::{codecs, generation, train};
use anyhow::{Context, Result, bail};
use anymo_generator::generate::Kind;
use anymo_generator::{Evaluator, EvaluatorConfig, Generator, GeneratorConfig, TokenClip};
use anymo_motion::features::{canonicalise, to_features};
use anymo_motion::skeleton::Skeleton;
use anymo_tokenizer::dataset::{Split, TrainingClip};
use anymo_tokenizer::nn::{DataRecord, ModelCard, Params};
use anymo_tokenizer::owo::graph::GLOBAL_NODE_TEXT;
use anymo_tokenizer::owo::pretrain::{PretrainConfig, Pretrainer};
use anymo_tokenizer::owo::{OwoConfig, SkeletonGraph};
use anymo_tokenizer::tat::objective::{LossWeights, RootStats};
use anymo_tokenizer::tat::rvq::RvqConfig;
use anymo_tokenizer::tat::temporal::Upsampling;
use anymo_tokenizer::tat::{Baseline, BaselineConfig, Codec, Fusion, Representation, Tat, TokenizerConfig};
use anymo_tokenizer::text::CachedEncoder;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

/// What every training run shares.
#[derive(Clone, Debug)]
pub struct Run {
    /// The corpus manifest.
    pub manifest: PathBuf,
    /// At most this many clips per split (a quick run).
    pub limit: Option<usize>,
    /// The checkpoints folder the run writes to, and reads the models it builds on from.
    pub out_dir: PathBuf,
    /// Where the resumable state of a checkpoint named `NAME` lives: this folder itself when
    /// `exact`, else its `NAME/` subfolder.
    pub state_dir: PathBuf,
    /// Whether `state_dir` is the run's own folder rather than a parent of per-name folders.
    pub exact: bool,
    /// Seed of initialisation and sampling.
    pub seed: u64,
    /// Time between saves of the resumable state.
    pub save_every: Duration,
    /// The command line, recorded in the card.
    pub command: String,
}

impl Run {
    fn state(&self, name: &str) -> Result<train::RunDir> {
        train::RunDir::new(&if self.exact { self.state_dir.clone() } else { self.state_dir.join(name) })
    }

    fn clips(&self) -> Result<Vec<ModelClip>> {
        eprintln!("reading {}", self.manifest.display());
        let (clips, rejected) = data::load_manifest(&self.manifest, self.limit)
            .with_context(|| format!("reading the manifest {}", self.manifest.display()))?;
        eprintln!("{} clips usable, {rejected} rejected by cleaning", clips.len());
        Ok(clips)
    }

    /// Writes the weights and card as checkpoint `name` and says where.
    fn ship<C: Serialize>(&self, params: &Params, card: &ModelCard<C>, name: &str) -> Result<PathBuf> {
        train::ship(params, card, &self.out_dir, name)?;
        let weights = self.out_dir.join(format!("{name}.safetensors"));
        eprintln!("wrote {}", weights.display());
        Ok(weights)
    }
}

fn distinct_skeletons<'a>(clips: impl Iterator<Item = &'a ModelClip>) -> Vec<Skeleton> {
    let mut by_topology = BTreeMap::new();
    for c in clips {
        by_topology.entry(data::topology(&c.motion)).or_insert_with(|| c.motion.skeleton().clone());
    }
    by_topology.into_values().collect()
}

fn train_split(clips: &[ModelClip]) -> Vec<&ModelClip> {
    clips.iter().filter(|c| c.split == Split::Train).collect()
}

/// Pretrains OwO for `steps` on every distinct training skeleton and its synthetic variants,
/// measures it on the zero-shot skeletons, and ships it as `owo`.
pub fn train_owo(run: &Run, steps: u64, encoder: &mut CachedEncoder) -> Result<PathBuf> {
    let clips = run.clips()?;
    let train_skeletons = distinct_skeletons(clips.iter().filter(|c| c.split == Split::Train));
    let zero_shot = distinct_skeletons(clips.iter().filter(|c| c.split == Split::ZeroShot));
    eprintln!("{} training skeletons, {} zero-shot skeletons", train_skeletons.len(), zero_shot.len());
    let config = PretrainConfig { steps, seed: run.seed, ..PretrainConfig::default() };
    let mut pretrainer = Pretrainer::new(config.clone(), train_skeletons.clone(), encoder)?;
    let state = train::pretrain_owo(&mut pretrainer, steps, encoder, &run.state("owo")?, run.save_every)?;
    let zero = pretrainer.evaluate(&zero_shot, false, encoder)?;
    let zero_hidden = pretrainer.evaluate(&zero_shot, true, encoder)?;
    let seen = pretrainer.evaluate(&train_skeletons, false, encoder)?;
    eprintln!("zero-shot skeletons: {zero:?}\nzero-shot, labels hidden: {zero_hidden:?}\ntraining skeletons: {seen:?}");
    let card = ModelCard {
        model: "owo".into(),
        config,
        data: data::data_record(&run.manifest, &train_split(&clips)),
        steps: state.step,
        metrics: serde_json::json!({
            "zero_shot_skeletons": zero,
            "zero_shot_skeletons_labels_hidden": zero_hidden,
            "training_skeletons": seen,
            "zero_shot_count": zero_shot.len(),
            "training_count": train_skeletons.len(),
            "train_seconds": state.seconds,
            "measured_by": run.command,
        }),
        command: run.command.clone(),
    };
    run.ship(&pretrainer.params, &card, "owo")
}

/// Which codec a tokenizer run trains.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Variant {
    /// TAT with gated FiLM over pretrained OwO.
    Tat,
    /// TAT with NEC's additive fusion.
    TatAdditive,
    /// TAT over an OwO that was never pretrained (frozen at initialisation).
    TatScratch,
    /// The zero-padded RVQ-VAE of NEC Table 1, its convolutional trunk `width` channels wide.
    Baseline {
        /// Channels of the trunk ([`BASELINE_WIDTH`] unless told).
        width: usize,
    },
}

/// The baseline's trunk width as first trained (tokenizer v1's `baseline`).
pub const BASELINE_WIDTH: usize = 256;

impl Variant {
    /// The checkpoint name a run of this variant ships under by default.
    pub fn name(self) -> &'static str {
        match self {
            Variant::Tat => "tat",
            Variant::TatAdditive => "tat-additive",
            Variant::TatScratch => "tat-scratch",
            Variant::Baseline { .. } => "baseline",
        }
    }
}

/// A tokenizer run.
#[derive(Clone, Debug)]
pub struct TokenizerRecipe {
    /// Which codec.
    pub variant: Variant,
    /// The checkpoint name (default: the variant's).
    pub name: Option<String>,
    /// Optimiser steps in all.
    pub steps: u64,
    /// Windows per batch.
    pub batch_size: usize,
    /// Peak learning rate.
    pub lr: f64,
    /// RVQ layers.
    pub rvq_layers: usize,
    /// Codes per RVQ layer.
    pub codes: usize,
    /// Go on from the checkpoint of this name in the output folder (its weights and codebooks,
    /// with a fresh optimiser and warm-up) up to `steps` in all.
    pub continue_shipped: bool,
    /// Loss weights set by name; the others keep their defaults.
    pub weights: Vec<(String, f32)>,
    /// Probability of rebasing a window on the pose of one of its frames (NEC C.1).
    pub rebase: f64,
    /// Probability of rebasing a window on a frame of any clip of its skeleton.
    pub rebase_other: f64,
    /// Probability of reading a window against its own clip's mean pose.
    pub rebase_own: f64,
    /// The joint frames the codec reads motion in.
    pub representation: Representation,
    /// Batches per step, each of one skeleton.
    pub skeletons_per_step: usize,
}

/// A codec's typed card configuration, as written and compared when a run continues.
#[derive(Clone, Debug, Serialize)]
#[serde(untagged)]
enum CodecConfig {
    Tokenizer { owo_checkpoint: String, tokenizer: TokenizerConfig },
    Baseline { baseline: BaselineConfig },
}

/// The training clips as the codec reads them, each skeleton's in its basis (see
/// [`codecs::bases_by_topology`]).
fn training_clips(clips: &[&ModelClip], representation: Representation) -> Vec<TrainingClip> {
    let bases = codecs::bases_by_topology(representation, clips);
    clips
        .iter()
        .map(|c| TrainingClip {
            motion: bases[&data::topology(&c.motion)].enter(&c.motion),
            source: c.item.source.clone(),
        })
        .collect()
}

/// Root statistics over the training clips' features.
fn root_stats(clips: &[TrainingClip]) -> RootStats {
    let mut all = Vec::new();
    for c in clips {
        let (f, _) = to_features(&canonicalise(&c.motion));
        all.extend_from_slice(&f.root);
    }
    RootStats::measure(&all)
}

/// Trains TAT, one of its ablations or the baseline on the train split and ships it.
pub fn train_tokenizer(run: &Run, recipe: &TokenizerRecipe, encoder: &mut CachedEncoder) -> Result<PathBuf> {
    let weights = loss_weights(&recipe.weights)?;
    let clips = run.clips()?;
    let train_clips = train_split(&clips);
    let representation = recipe.representation;
    let motions = training_clips(&train_clips, representation);
    let stats = root_stats(&motions);
    let name = recipe.name.clone().unwrap_or_else(|| recipe.variant.name().to_string());
    let rvq = RvqConfig { layers: recipe.rvq_layers, codes: recipe.codes, ..RvqConfig::default() };
    let global = encoder.encode(&[GLOBAL_NODE_TEXT])?.remove(0);
    let mut owo_params = Params::new(0);
    let (mut codec, config): (Box<dyn Codec>, CodecConfig) = match recipe.variant {
        Variant::Baseline { width } => {
            let max_joints = clips.iter().map(|c| c.motion.skeleton().len()).max().unwrap_or(1);
            let upsampling = Upsampling::Interpolate;
            let config = BaselineConfig {
                max_joints,
                dim: width,
                blocks: 2,
                upsampling,
                rvq,
                root: stats,
                weights,
                representation,
            };
            (Box::new(Baseline::new(config.clone(), run.seed)?), CodecConfig::Baseline { baseline: config })
        }
        v => {
            let fusion = if v == Variant::TatAdditive { Fusion::Additive } else { Fusion::Film };
            let mut config = TokenizerConfig::new(stats, fusion, representation);
            config.rvq = rvq;
            config.weights = weights;
            config.owo = OwoConfig::default();
            let tat = Tat::new(config.clone(), run.seed, &mut owo_params, global)?;
            let owo_checkpoint = if v == Variant::TatScratch { "random" } else { "owo" }.to_string();
            if owo_checkpoint != "random" {
                Checkpoint::in_dir(&run.out_dir, &owo_checkpoint).load_into(&mut owo_params)?;
            }
            (Box::new(tat), CodecConfig::Tokenizer { owo_checkpoint, tokenizer: config })
        }
    };
    eprintln!("{name}: {} parameters", codec.params().count());
    let data = data::data_record(&run.manifest, &train_clips);
    let previous = if recipe.continue_shipped {
        Some(load_to_continue(codec.as_mut(), run, recipe, &name, &config, &data)?)
    } else {
        None
    };
    let start = previous.as_ref().map_or(0, |card| card.steps);
    let settings = train::CodecTraining {
        steps: recipe.steps,
        start,
        lr: recipe.lr,
        warmup: 200.min((recipe.steps - start) / 10),
        seed: run.seed,
        batch_size: recipe.batch_size,
        skeletons_per_step: recipe.skeletons_per_step,
        window: 64,
        max_batch_joints: 16 * 24,
        rebase: recipe.rebase,
        rebase_other: recipe.rebase_other,
        rebase_own: recipe.rebase_own,
        save_every_seconds: run.save_every.as_secs(),
    };
    let mut graph_of = |s: &Skeleton| -> Result<SkeletonGraph> { Ok(SkeletonGraph::new(s, encoder)?) };
    let state = train::train_codec(codec.as_mut(), motions, &mut graph_of, &settings, &run.state(&name)?)?;
    let (command, metrics) = lineage(run, previous.as_ref(), state.seconds);
    let steps = state.step;
    match config {
        CodecConfig::Tokenizer { owo_checkpoint, tokenizer } => {
            let config = TokenizerCard { owo_checkpoint, tokenizer, training: settings };
            let card = ModelCard { model: name.clone(), config, data, steps, metrics, command };
            run.ship(codec.params(), &card, &name)
        }
        CodecConfig::Baseline { baseline } => {
            let card = ModelCard {
                model: name.clone(),
                config: BaselineCard { baseline, training: settings },
                data,
                steps,
                metrics,
                command,
            };
            run.ship(codec.params(), &card, &name)
        }
    }
}

/// The default loss weights with the named ones set.
pub fn loss_weights(set: &[(String, f32)]) -> Result<LossWeights> {
    let mut weights = serde_json::to_value(LossWeights::default())?;
    for (name, value) in set {
        match weights.get_mut(name) {
            Some(slot) => *slot = (*value).into(),
            None => bail!(
                "no loss term is called {name}; the terms are {}",
                weights.as_object().map(|o| o.keys().cloned().collect::<Vec<_>>().join(", ")).unwrap_or_default()
            ),
        }
    }
    Ok(serde_json::from_value(weights)?)
}

/// A codec configuration without its loss weights, which shape a run and not the model, as
/// JSON written from the typed values (so a card that spelled an f32 with more digits compares
/// equal).
fn model_shape(config: &CodecConfig) -> Result<serde_json::Value> {
    let mut value: serde_json::Value = serde_json::from_str(&serde_json::to_string(config)?)?;
    for model in ["tokenizer", "baseline"] {
        value.get_mut(model).and_then(|m| m.as_object_mut()).map(|m| m.remove("weights"));
    }
    Ok(value)
}

/// The paths (`tokenizer.rvq.codes`) at which two JSON values differ.
fn differing(path: &str, a: &serde_json::Value, b: &serde_json::Value) -> Vec<String> {
    match (a.as_object(), b.as_object()) {
        (Some(a), Some(b)) => {
            let keys: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
            keys.into_iter()
                .flat_map(|k| {
                    let null = serde_json::Value::Null;
                    let at = if path.is_empty() { k.clone() } else { format!("{path}.{k}") };
                    differing(&at, a.get(k).unwrap_or(&null), b.get(k).unwrap_or(&null))
                })
                .collect()
        }
        _ if a == b => Vec::new(),
        _ => vec![path.to_string()],
    }
}

/// A run's card command and metrics: a continued run's command lists every run that made the
/// checkpoint, and its training time adds to theirs.
fn lineage<C>(run: &Run, previous: Option<&ModelCard<C>>, seconds: f64) -> (String, serde_json::Value) {
    let earlier = previous.and_then(|card| card.metrics["train_seconds"].as_f64()).unwrap_or(0.0);
    let command = match previous {
        Some(card) => format!("{} && {}", card.command, run.command),
        None => run.command.clone(),
    };
    (command, serde_json::json!({ "train_seconds": earlier + seconds }))
}

/// Refuses to continue checkpoint `name`, trained with the model configuration and data of
/// `was`, as a run with those of `now`: a continued run must build the same model on the same
/// clips.
fn same_model_and_data(
    name: &str,
    run: &Run,
    was: (&serde_json::Value, &DataRecord),
    now: (&serde_json::Value, &DataRecord),
) -> Result<()> {
    if was.0 != now.0 {
        bail!(
            "{name} in {} was trained with another configuration (differing: {}); continue it with the options \
             it was trained with",
            run.out_dir.display(),
            differing("", was.0, now.0).join(", ")
        );
    }
    if was.1 != now.1 {
        bail!(
            "{name} was trained on other data ({} clips of {}, blake3 {}); continue it on the same clips",
            was.1.clips,
            was.1.source,
            was.1.manifest_blake3
        );
    }
    Ok(())
}

/// Loads checkpoint `name` of the output folder into `codec` to continue it, after checking
/// that it has the same model configuration (loss weights may differ: they shape the run, not
/// the model), was trained on the same data, and has fewer steps than asked for.
fn load_to_continue(
    codec: &mut dyn Codec,
    run: &Run,
    recipe: &TokenizerRecipe,
    name: &str,
    config: &CodecConfig,
    data: &DataRecord,
) -> Result<ModelCard<CodecCard>> {
    let checkpoint = Checkpoint::in_dir(&run.out_dir, name);
    let previous: ModelCard<CodecCard> = checkpoint.card("a tokenizer or the baseline")?;
    let was = match &previous.config {
        CodecCard::Tokenizer(t) => {
            CodecConfig::Tokenizer { owo_checkpoint: t.owo_checkpoint.clone(), tokenizer: t.tokenizer.clone() }
        }
        CodecCard::Baseline(b) => CodecConfig::Baseline { baseline: b.baseline.clone() },
    };
    same_model_and_data(name, run, (&model_shape(&was)?, &previous.data), (&model_shape(config)?, data))?;
    if previous.steps >= recipe.steps {
        bail!("{name} has {} steps already; pass --steps above that to continue it", previous.steps);
    }
    let rest = checkpoint.load_into(codec.params_mut())?;
    codec.restore_buffers(&rest)?;
    eprintln!("continuing {name} from step {}", previous.steps);
    Ok(previous)
}

/// The train split tokenized by a tokenizer of the output folder, and what the card records
/// about both.
struct TokenCorpus {
    clips: Vec<TokenClip>,
    record: DataRecord,
    rvq: RvqConfig,
    skeleton_dim: usize,
    trained_on: TokenizerRef,
}

fn token_corpus(run: &Run, tokenizer: &str, decoded: bool, encoder: &mut CachedEncoder) -> Result<TokenCorpus> {
    let clips = run.clips()?;
    let train_clips = train_split(&clips);
    let checkpoint = Checkpoint::in_dir(&run.out_dir, tokenizer);
    let (mut tat, _) = checkpoint.load_tat(encoder)?;
    eprintln!("tokenizing {} training clips with {tokenizer}", train_clips.len());
    let tokens = generation::token_clips(&train_clips, &mut tat, encoder, decoded)?;
    Ok(TokenCorpus {
        clips: tokens,
        record: data::data_record(&run.manifest, &train_clips),
        rvq: tat.config().rvq,
        skeleton_dim: tat.config().owo.dim,
        trained_on: TokenizerRef {
            tokenizer_checkpoint: tokenizer.to_string(),
            tokenizer_blake3: checkpoint.weights_blake3()?,
        },
    })
}

/// The step loop's settings for a run from `start` (0: a fresh model) up to `steps` in all.
fn step_settings(run: &Run, steps: u64, start: u64, lr: f64, batch_size: usize) -> train::StepTraining {
    train::StepTraining {
        steps,
        start,
        lr,
        warmup: 200.min((steps - start) / 10),
        seed: run.seed,
        batch_size,
        save_every_seconds: run.save_every.as_secs(),
    }
}

/// A run of the text-motion evaluator.
#[derive(Clone, Debug)]
pub struct EvaluatorRecipe {
    /// The tokenizer checkpoint whose latents it reads.
    pub tokenizer: String,
    /// Optimiser steps.
    pub steps: u64,
    /// Clips per batch (the contrastive negatives).
    pub batch_size: usize,
    /// Peak learning rate.
    pub lr: f64,
    /// Reworded variants per caption to train the text side on beside the captions.
    pub paraphrases: usize,
}

/// Trains the evaluator contrastively on the train split's latents (half of them from the
/// clips' own tokens decoded and encoded again) against their captions and reworded variants,
/// and ships it as `evaluator`.
pub fn train_evaluator(run: &Run, recipe: &EvaluatorRecipe, encoder: &mut CachedEncoder) -> Result<PathBuf> {
    let mut corpus = token_corpus(run, &recipe.tokenizer, true, encoder)?;
    let added = generation::add_paraphrases(&mut corpus.clips, recipe.paraphrases, encoder, run.seed)?;
    eprintln!("{added} reworded captions added");
    let clips = &corpus.clips;
    let config = EvaluatorConfig::new(corpus.rvq.dim);
    let mut model = Evaluator::new(config, run.seed)?;
    eprintln!("evaluator: {} parameters", model.params().count());
    let settings = step_settings(run, recipe.steps, 0, recipe.lr, recipe.batch_size);
    let mut running = 0f32;
    let state =
        train::train_steps(&mut model, Evaluator::params_mut, &settings, &run.state("evaluator")?, |m, rng| {
            let loss = m.batch_loss(clips, settings.batch_size, rng)?;
            running += (loss.to_scalar::<f32>()? - running) * 0.05;
            Ok((loss, format!("contrastive {running:.3}")))
        })?;
    let card = ModelCard {
        model: "evaluator".into(),
        config: EvaluatorCard {
            trained_on: corpus.trained_on,
            evaluator: config,
            training: settings,
            paraphrases: recipe.paraphrases,
        },
        data: corpus.record,
        steps: state.step,
        metrics: serde_json::json!({ "train_seconds": state.seconds }),
        command: run.command.clone(),
    };
    run.ship(model.params(), &card, "evaluator")
}

/// A run of a generator.
#[derive(Clone, Debug)]
pub struct GeneratorRecipe {
    /// The tokenizer checkpoint whose tokens it writes.
    pub tokenizer: String,
    /// The first-layer model.
    pub kind: Kind,
    /// The checkpoint name (default: `generator`, or `generator-ar` for the autoregressive kind).
    pub name: Option<String>,
    /// Optimiser steps.
    pub steps: u64,
    /// Crops per batch.
    pub batch_size: usize,
    /// Peak learning rate.
    pub lr: f64,
    /// Transformer width.
    pub dim: usize,
    /// Reworded variants per caption to train on beside the captions.
    pub paraphrases: usize,
    /// Length of the noise added to prompt embeddings in training (see
    /// [`GeneratorConfig::text_noise`]).
    pub text_noise: f32,
    /// Go on from the checkpoint of this name in the output folder (its weights, with a fresh
    /// optimiser and warm-up) up to `steps` in all; at its own steps, take none and write it
    /// again with its training captions as anchors.
    pub continue_shipped: bool,
}

/// Trains a generator on the train split's tokens (captions with their reworded variants) and
/// ships it with the captions (not the variants) as its anchors.
pub fn train_generator(run: &Run, recipe: &GeneratorRecipe, encoder: &mut CachedEncoder) -> Result<PathBuf> {
    let mut corpus = token_corpus(run, &recipe.tokenizer, false, encoder)?;
    let anchors = generation::caption_anchors(&corpus.clips).context("the training clips have no captions")?;
    let added = generation::add_paraphrases(&mut corpus.clips, recipe.paraphrases, encoder, run.seed)?;
    eprintln!("{added} reworded captions added");
    let (clips, rvq) = (&corpus.clips, corpus.rvq);
    let name = recipe.name.clone().unwrap_or_else(|| match recipe.kind {
        Kind::Masked => "generator".into(),
        Kind::Autoregressive => "generator-ar".into(),
    });
    let mut config = GeneratorConfig::new(recipe.kind, corpus.skeleton_dim, rvq.layers, rvq.codes);
    config.base.dim = recipe.dim;
    config.base.ff = 2 * recipe.dim;
    config.residual.dim = recipe.dim;
    config.residual.ff = 2 * recipe.dim;
    config.length_hidden = recipe.dim;
    config.text_noise = recipe.text_noise;
    let mut model = Generator::new(config.clone(), run.seed)?;
    eprintln!("{name}: {} parameters", model.params().count());
    let previous = if recipe.continue_shipped {
        Some(generator_to_continue(&mut model, run, recipe, &name, &corpus)?)
    } else {
        None
    };
    let start = previous.as_ref().map_or(0, |card| card.steps);
    let settings = step_settings(run, recipe.steps, start, recipe.lr, recipe.batch_size);
    let seconds = if start < recipe.steps {
        let mut running = [0f32; 3];
        let state = train::train_steps(&mut model, Generator::params_mut, &settings, &run.state(&name)?, |m, rng| {
            let (loss, parts) = m.batch_loss(clips, settings.batch_size, rng)?;
            for (r, p) in running.iter_mut().zip(parts) {
                *r += (p - *r) * 0.05;
            }
            Ok((loss, format!("base {:.3} residual {:.3} length {:.3}", running[0], running[1], running[2])))
        })?;
        state.seconds
    } else {
        eprintln!("{name} has {start} steps already: no step to take");
        0.0
    };
    eprintln!(
        "{name}: a prompt further than cosine {:.3} from all of its {} training captions will be read as the nearest",
        anchors.within(),
        anchors.len()
    );
    model.set_anchors(anchors)?;
    let (command, metrics) = lineage(run, previous.as_ref(), seconds);
    let card = ModelCard {
        model: name.clone(),
        config: GeneratorCard {
            trained_on: corpus.trained_on,
            generator: config,
            training: settings,
            paraphrases: recipe.paraphrases,
        },
        data: corpus.record,
        steps: recipe.steps,
        metrics,
        command,
    };
    run.ship(model.params(), &card, &name)
}

/// Loads generator `name` of the output folder into `model` to continue it, after checking that
/// it has the same configuration, writes codes of the same tokenizer weights, was trained on the
/// same clips with as many reworded captions, and has at most the steps asked for.
fn generator_to_continue(
    model: &mut Generator,
    run: &Run,
    recipe: &GeneratorRecipe,
    name: &str,
    corpus: &TokenCorpus,
) -> Result<ModelCard<GeneratorCard>> {
    let checkpoint = Checkpoint::in_dir(&run.out_dir, name);
    let previous: ModelCard<GeneratorCard> = checkpoint.card("a generator")?;
    let (was, now) = (serde_json::to_value(&previous.config.generator)?, serde_json::to_value(model.config())?);
    same_model_and_data(name, run, (&was, &previous.data), (&now, &corpus.record))?;
    if previous.config.trained_on != corpus.trained_on {
        bail!(
            "{name} writes codes of {} (blake3 {}), not of {} in {} (blake3 {}); train a new generator for this \
             tokenizer",
            previous.config.trained_on.tokenizer_checkpoint,
            previous.config.trained_on.tokenizer_blake3,
            corpus.trained_on.tokenizer_checkpoint,
            run.out_dir.display(),
            corpus.trained_on.tokenizer_blake3
        );
    }
    if previous.config.paraphrases != recipe.paraphrases {
        bail!("{name} was trained with --paraphrases {}; continue it with the same", previous.config.paraphrases);
    }
    if previous.steps > recipe.steps {
        bail!("{name} has {} steps already; pass --steps of at least that to continue it", previous.steps);
    }
    checkpoint.load_into(model.params_mut())?;
    eprintln!("continuing {name} from step {}", previous.steps);
    Ok(previous)
}
