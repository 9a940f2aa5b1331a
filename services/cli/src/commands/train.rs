//! `anymo train owo|tokenizer`: pretrain the skeleton encoder, train the tokenizer (or the
//! baseline and ablations) on a manifest's train split, and ship the checkpoint with its card.

use super::context::{StoreArgs, writable_checkpoints};
use anyhow::{Context, Result, bail};
use anymo_generator::generate::Kind;
use anymo_generator::{Evaluator, EvaluatorConfig, Generator, GeneratorConfig, TokenClip};
use anymo_models::checkpoint::Checkpoint;
use anymo_models::{data, generation, train};
use anymo_motion::features::{canonicalise, to_features};
use anymo_motion::skeleton::Skeleton;
use anymo_tokenizer::dataset::{LoaderConfig, Split};
use anymo_tokenizer::nn::DataRecord;
use anymo_tokenizer::nn::{ModelCard, Params};
use anymo_tokenizer::owo::graph::GLOBAL_NODE_TEXT;
use anymo_tokenizer::owo::pretrain::{PretrainConfig, Pretrainer};
use anymo_tokenizer::owo::{OwoConfig, SkeletonGraph};
use anymo_tokenizer::tat::objective::{LossWeights, RootStats};
use anymo_tokenizer::tat::rvq::RvqConfig;
use anymo_tokenizer::tat::{Baseline, BaselineConfig, Codec, Fusion, Tat, TokenizerConfig};
use anymo_tokenizer::text::CachedEncoder;
use clap::{Parser, Subcommand, ValueEnum};
use std::collections::BTreeMap;
use std::path::PathBuf;

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
    #[arg(long, default_value = "tat")]
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
    #[arg(long, default_value = "tat")]
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

impl Variant {
    fn name(self) -> &'static str {
        match self {
            Variant::Tat => "tat",
            Variant::TatAdditive => "tat-additive",
            Variant::TatScratch => "tat-scratch",
            Variant::Baseline => "baseline",
        }
    }
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
    /// Probability of rebasing a window's rest pose on one of its frames (NEC C.1).
    #[arg(long, default_value_t = LoaderConfig::default().rebase)]
    rebase: f64,
}

pub fn run(args: Args) -> Result<()> {
    // Where the checkpoint goes is settled before any training, not after it.
    let common = match &args.model {
        Model::Owo(a) => &a.common,
        Model::Tokenizer(a) => &a.common,
        Model::Evaluator(a) => &a.common,
        Model::Generator(a) => &a.common,
    };
    common.out_dir()?;
    match args.model {
        Model::Owo(a) => owo(a),
        Model::Tokenizer(a) => tokenizer(a),
        Model::Evaluator(a) => evaluator(a),
        Model::Generator(a) => generator(a),
    }
}

fn command_line() -> String {
    std::env::args().collect::<Vec<_>>().join(" ")
}

fn distinct_skeletons<'a>(clips: impl Iterator<Item = &'a data::ModelClip>) -> Vec<Skeleton> {
    let mut by_topology = BTreeMap::new();
    for c in clips {
        by_topology.entry(data::topology(&c.motion)).or_insert_with(|| c.motion.skeleton().clone());
    }
    by_topology.into_values().collect()
}

fn load(common: &Common) -> Result<Vec<data::ModelClip>> {
    eprintln!("reading {}", common.manifest.display());
    let (clips, rejected) = data::load_manifest(&common.manifest, common.limit)
        .with_context(|| format!("reading the manifest {}", common.manifest.display()))?;
    eprintln!("{} clips usable, {rejected} rejected by cleaning", clips.len());
    Ok(clips)
}

impl Common {
    /// The checkpoints folder this run writes to.
    fn out_dir(&self) -> Result<PathBuf> {
        writable_checkpoints(self.out_dir.as_deref(), "--out-dir")
    }
}

fn run_dir(common: &Common, name: &str) -> Result<train::RunDir> {
    let dir = match &common.run_dir {
        Some(dir) => dir.clone(),
        None => common.store.data_dir()?.join("train").join(name),
    };
    train::RunDir::new(&dir)
}

fn owo(args: OwoArgs) -> Result<()> {
    let clips = load(&args.common)?;
    let train_skeletons = distinct_skeletons(clips.iter().filter(|c| c.split == Split::Train));
    let zero_shot = distinct_skeletons(clips.iter().filter(|c| c.split == Split::ZeroShot));
    eprintln!("{} training skeletons, {} zero-shot skeletons", train_skeletons.len(), zero_shot.len());
    let mut encoder = CachedEncoder::new(args.common.store.encoder()?);
    let config = PretrainConfig { steps: args.steps, seed: args.common.seed, ..PretrainConfig::default() };
    let mut pretrainer = Pretrainer::new(config.clone(), train_skeletons.clone(), &mut encoder)?;
    let run = run_dir(&args.common, "owo")?;
    let save_every = std::time::Duration::from_secs(args.common.save_every);
    let state = train::pretrain_owo(&mut pretrainer, args.steps, &mut encoder, &run, save_every)?;
    let zero = pretrainer.evaluate(&zero_shot, false, &mut encoder)?;
    let zero_hidden = pretrainer.evaluate(&zero_shot, true, &mut encoder)?;
    let seen = pretrainer.evaluate(&train_skeletons, false, &mut encoder)?;
    eprintln!("zero-shot skeletons: {zero:?}\nzero-shot, labels hidden: {zero_hidden:?}\ntraining skeletons: {seen:?}");
    let train_clips: Vec<&data::ModelClip> = clips.iter().filter(|c| c.split == Split::Train).collect();
    let card = ModelCard {
        model: "owo".into(),
        config: serde_json::to_value(&config)?,
        data: data::data_record(&args.common.manifest, &train_clips),
        steps: state.step,
        metrics: serde_json::json!({
            "zero_shot_skeletons": zero,
            "zero_shot_skeletons_labels_hidden": zero_hidden,
            "training_skeletons": seen,
            "zero_shot_count": zero_shot.len(),
            "training_count": train_skeletons.len(),
            "train_seconds": state.seconds,
            "measured_by": command_line(),
        }),
        command: command_line(),
    };
    train::ship(&pretrainer.params, &card, &args.common.out_dir()?, "owo")?;
    eprintln!("wrote {}", args.common.out_dir()?.join("owo.safetensors").display());
    Ok(())
}

/// Root statistics over the training clips' features.
fn root_stats(clips: &[&data::ModelClip]) -> RootStats {
    let mut all = Vec::new();
    for c in clips {
        let (f, _) = to_features(&canonicalise(&c.motion));
        all.extend_from_slice(&f.root);
    }
    RootStats::measure(&all)
}

fn tokenizer(args: TokenizerArgs) -> Result<()> {
    let weights = loss_weights(&args.weights)?;
    let clips = load(&args.common)?;
    let train_clips: Vec<&data::ModelClip> = clips.iter().filter(|c| c.split == Split::Train).collect();
    let stats = root_stats(&train_clips);
    let name = args.name.clone().unwrap_or_else(|| args.variant.name().to_string());
    let rvq = RvqConfig { layers: args.rvq_layers, codes: args.codes, ..RvqConfig::default() };
    let mut encoder = CachedEncoder::new(args.common.store.encoder()?);
    let global = encoder.encode(&[GLOBAL_NODE_TEXT])?.remove(0);
    let mut owo_params = Params::new(0);
    let owo_name = match args.variant {
        Variant::TatScratch => "random".to_string(),
        _ => "owo".to_string(),
    };
    let (mut codec, config): (Box<dyn Codec>, serde_json::Value) = match args.variant {
        Variant::Baseline => {
            let max_joints = clips.iter().map(|c| c.motion.skeleton().len()).max().unwrap_or(1);
            let config = BaselineConfig { max_joints, dim: 256, blocks: 2, rvq, root: stats, weights };
            let value = serde_json::json!({ "baseline": config });
            (Box::new(Baseline::new(config, args.common.seed)?), value)
        }
        v => {
            let fusion = if v == Variant::TatAdditive { Fusion::Additive } else { Fusion::Film };
            let mut config = TokenizerConfig::new(stats, fusion);
            config.rvq = rvq;
            config.weights = weights;
            config.owo = OwoConfig::default();
            let tat = Tat::new(config.clone(), args.common.seed, &mut owo_params, global)?;
            if owo_name != "random" {
                Checkpoint::in_dir(&args.common.out_dir()?, &owo_name).load_into(&mut owo_params)?;
            }
            let value = serde_json::json!({ "tokenizer": config, "owo_checkpoint": owo_name });
            (Box::new(tat), value)
        }
    };
    eprintln!("{name}: {} parameters", codec.params().count());
    let data = data::data_record(&args.common.manifest, &train_clips);
    let previous = if args.continue_shipped {
        Some(load_to_continue(codec.as_mut(), &args, &name, &config, &data)?)
    } else {
        None
    };
    let start = previous.as_ref().map_or(0, |card| card.steps);
    let settings = train::CodecTraining {
        steps: args.steps,
        start,
        lr: args.lr,
        warmup: 200.min((args.steps - start) / 10),
        seed: args.common.seed,
        batch_size: args.batch_size,
        max_batch_joints: 16 * 24,
        rebase: args.rebase,
        save_every_seconds: args.common.save_every,
    };
    let run = run_dir(&args.common, &name)?;
    let motions = train_clips.iter().map(|c| c.motion.clone()).collect();
    let mut graph_of = |s: &Skeleton| -> Result<SkeletonGraph> { Ok(SkeletonGraph::new(s, &mut encoder)?) };
    let state = train::train_codec(codec.as_mut(), motions, &mut graph_of, &settings, &run)?;
    let earlier_seconds = previous.as_ref().and_then(|card| card.metrics["train_seconds"].as_f64()).unwrap_or(0.0);
    let command = match &previous {
        Some(card) => format!("{} && {}", card.command, command_line()),
        None => command_line(),
    };
    let card = ModelCard {
        model: name.clone(),
        config: {
            let mut c = config;
            c["training"] = serde_json::to_value(&settings)?;
            c
        },
        data,
        steps: state.step,
        metrics: serde_json::json!({ "train_seconds": earlier_seconds + state.seconds }),
        command,
    };
    train::ship(codec.params(), &card, &args.common.out_dir()?, &name)?;
    eprintln!("wrote {}", args.common.out_dir()?.join(format!("{name}.safetensors")).display());
    Ok(())
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

/// The default loss weights with the given ones set.
fn loss_weights(set: &[(String, f32)]) -> Result<LossWeights> {
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

/// Loads the shipped checkpoint `name` into `codec` to continue it, after checking that it has
/// the same model configuration (loss weights may differ), was trained on the same data, and
/// has fewer steps than asked for.
fn load_to_continue(
    codec: &mut dyn Codec,
    args: &TokenizerArgs,
    name: &str,
    config: &serde_json::Value,
    data: &DataRecord,
) -> Result<ModelCard> {
    let dir = &args.common.out_dir()?;
    let checkpoint = Checkpoint::in_dir(dir, name);
    let previous: ModelCard = checkpoint.card("a tokenizer or the baseline")?;
    // The loss weights and the training settings shape the run, not the model: a continued run
    // may change them, and its card records the new ones.
    let model_config = |c: &serde_json::Value| {
        let mut c = c.clone();
        if let Some(o) = c.as_object_mut() {
            o.remove("training");
            for model in ["tokenizer", "baseline"] {
                o.get_mut(model).and_then(|m| m.as_object_mut()).map(|m| m.remove("weights"));
            }
        }
        c
    };
    if model_config(&previous.config) != model_config(config) {
        bail!(
            "{name} in {} was trained with another configuration; continue it with the options it was trained with",
            dir.display()
        );
    }
    if previous.data != *data {
        bail!(
            "{name} was trained on other data ({} clips of {}, blake3 {}); continue it on the same clips",
            previous.data.clips,
            previous.data.source,
            previous.data.manifest_blake3
        );
    }
    if previous.steps >= args.steps {
        bail!("{name} has {} steps already; pass --steps above that to continue it", previous.steps);
    }
    let rest = checkpoint.load_into(codec.params_mut())?;
    codec.restore_buffers(&rest)?;
    eprintln!("continuing {name} from step {}", previous.steps);
    Ok(previous)
}

/// The train split tokenized by a shipped tokenizer, and what the card records about both.
struct TokenCorpus {
    clips: Vec<TokenClip>,
    record: DataRecord,
    rvq: RvqConfig,
    skeleton_dim: usize,
    /// The card's `tokenizer_checkpoint` and `tokenizer_blake3`.
    tokenizer: serde_json::Value,
}

fn token_clips(common: &Common, tokenizer: &str, decoded: bool) -> Result<TokenCorpus> {
    let clips = load(common)?;
    let train_clips: Vec<&data::ModelClip> = clips.iter().filter(|c| c.split == Split::Train).collect();
    let mut encoder = CachedEncoder::new(common.store.encoder()?);
    let checkpoint = Checkpoint::in_dir(&common.out_dir()?, tokenizer);
    let (mut tat, _) = checkpoint.load_tat(&mut encoder)?;
    eprintln!("tokenizing {} training clips with {tokenizer}", train_clips.len());
    let tokens = generation::token_clips(&train_clips, &mut tat, &mut encoder, decoded)?;
    let record = data::data_record(&common.manifest, &train_clips);
    let blake3 = checkpoint.weights_blake3()?;
    Ok(TokenCorpus {
        clips: tokens,
        record,
        rvq: tat.config().rvq,
        skeleton_dim: tat.config().owo.dim,
        tokenizer: serde_json::json!({ "tokenizer_checkpoint": tokenizer, "tokenizer_blake3": blake3 }),
    })
}

/// The card configuration of a model trained on a token corpus: the model's own configuration
/// under `key`, the tokenizer it read, and the training settings.
fn trained_on_tokens(
    corpus: &TokenCorpus,
    key: &str,
    model: serde_json::Value,
    settings: &train::StepTraining,
) -> Result<serde_json::Value> {
    let mut config = corpus.tokenizer.clone();
    config[key] = model;
    config["training"] = serde_json::to_value(settings)?;
    Ok(config)
}

fn step_settings(common: &Common, steps: u64, lr: f64, batch_size: usize) -> train::StepTraining {
    train::StepTraining {
        steps,
        lr,
        warmup: 200.min(steps / 10),
        seed: common.seed,
        batch_size,
        save_every_seconds: common.save_every,
    }
}

fn evaluator(args: EvaluatorArgs) -> Result<()> {
    let corpus = token_clips(&args.common, &args.tokenizer, true)?;
    let clips = &corpus.clips;
    let config = EvaluatorConfig::new(corpus.rvq.dim);
    let mut model = Evaluator::new(config, args.common.seed)?;
    eprintln!("evaluator: {} parameters", model.params().count());
    let settings = step_settings(&args.common, args.steps, args.lr, args.batch_size);
    let run = run_dir(&args.common, "evaluator")?;
    let mut running = 0f32;
    let state = train::train_steps(&mut model, Evaluator::params_mut, &settings, &run, |m, rng| {
        let loss = m.batch_loss(clips, settings.batch_size, rng)?;
        running += (loss.to_scalar::<f32>()? - running) * 0.05;
        Ok((loss, format!("contrastive {running:.3}")))
    })?;
    let card = ModelCard {
        model: "evaluator".into(),
        config: trained_on_tokens(&corpus, "evaluator", serde_json::to_value(config)?, &settings)?,
        data: corpus.record,
        steps: state.step,
        metrics: serde_json::json!({ "train_seconds": state.seconds }),
        command: command_line(),
    };
    train::ship(model.params(), &card, &args.common.out_dir()?, "evaluator")?;
    eprintln!("wrote {}", args.common.out_dir()?.join("evaluator.safetensors").display());
    Ok(())
}

fn generator(args: GeneratorArgs) -> Result<()> {
    let corpus = token_clips(&args.common, &args.tokenizer, false)?;
    let (clips, rvq) = (&corpus.clips, corpus.rvq);
    let kind = match args.kind {
        GeneratorKind::Masked => Kind::Masked,
        GeneratorKind::Autoregressive => Kind::Autoregressive,
    };
    let name = args.name.clone().unwrap_or_else(|| match kind {
        Kind::Masked => "generator".into(),
        Kind::Autoregressive => "generator-ar".into(),
    });
    let mut config = GeneratorConfig::new(kind, corpus.skeleton_dim, rvq.layers, rvq.codes);
    config.base.dim = args.dim;
    config.base.ff = 2 * args.dim;
    config.residual.dim = args.dim;
    config.residual.ff = 2 * args.dim;
    config.length_hidden = args.dim;
    let mut model = Generator::new(config.clone(), args.common.seed)?;
    eprintln!("{name}: {} parameters", model.params().count());
    let settings = step_settings(&args.common, args.steps, args.lr, args.batch_size);
    let run = run_dir(&args.common, &name)?;
    let mut running = [0f32; 3];
    let state = train::train_steps(&mut model, Generator::params_mut, &settings, &run, |m, rng| {
        let (loss, parts) = m.batch_loss(clips, settings.batch_size, rng)?;
        for (r, p) in running.iter_mut().zip(parts) {
            *r += (p - *r) * 0.05;
        }
        Ok((loss, format!("base {:.3} residual {:.3} length {:.3}", running[0], running[1], running[2])))
    })?;
    let card = ModelCard {
        model: name.clone(),
        config: trained_on_tokens(&corpus, "generator", serde_json::to_value(&config)?, &settings)?,
        data: corpus.record,
        steps: state.step,
        metrics: serde_json::json!({ "train_seconds": state.seconds }),
        command: command_line(),
    };
    train::ship(model.params(), &card, &args.common.out_dir()?, &name)?;
    eprintln!("wrote {}", args.common.out_dir()?.join(format!("{name}.safetensors")).display());
    Ok(())
}
