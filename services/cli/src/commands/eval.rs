//! `anymo eval tokenizer|generator|prompts|retrieval`: the tokenizer's reconstruction table
//! (TAT, baseline, ablations) with its transfer figures, text-to-motion by MoMask's protocol,
//! held-out prompts judged by what the motion does, and search by EVAL.md's retrieval protocol.

use super::context::{StoreArgs, checkpoints, writable_checkpoints};
use super::generate::SamplingArgs;
use super::search::WeightArgs;
use anyhow::{Context, Result};
use anymo_generator::Request;
use anymo_models::checkpoint::Checkpoint;
use anymo_models::data::ModelClip;
use anymo_models::eval::retrieval::Hybrid;
use anymo_models::eval::{self, by_example, generator, prompts, retrieval, tokenizer};
use anymo_models::quality::REAL_MOTION_KEY;
use anymo_models::search::SearchModels;
use anymo_retrieval::benchmark;
use anymo_tokenizer::dataset::Split;
use anymo_tokenizer::text::CachedEncoder;
use clap::{Parser, Subcommand};
use std::path::PathBuf;

#[derive(Parser)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

#[derive(Subcommand)]
enum What {
    /// Reconstruction and transfer of the trained tokenizers.
    Tokenizer(TokenizerArgs),
    /// Text-to-motion on the test split by MoMask's protocol, GT row beside the generators.
    Generator(GeneratorArgs),
    /// Held-out prompts worded unlike any caption, generated on every human and four-legged
    /// rig of the test and zero-shot splits and judged by what the motion does.
    Prompts(PromptsArgs),
    /// Search on the test split: held-out captions, paraphrases and motion by example, per
    /// retriever; then motion by example across skeletons, the whole corpus as the gallery.
    Retrieval(RetrievalArgs),
}

/// What every evaluation reads and writes.
#[derive(clap::Args)]
struct Common {
    /// The corpus manifest.
    #[arg(long, default_value = "../shared/data/manifest.tsv")]
    manifest: PathBuf,
    /// Use at most this many clips per split.
    #[arg(long)]
    limit: Option<usize>,
    /// A folder of checkpoints (`--record` writes to their cards) [default: as every command finds them]
    #[arg(long)]
    dir: Option<PathBuf>,
    /// Write the results as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    #[command(flatten)]
    store: StoreArgs,
}

impl Common {
    /// The folder `--record` writes to, settled before anything is measured.
    fn record_in(&self, record: bool) -> Result<Option<PathBuf>> {
        record.then(|| writable_checkpoints(self.dir.as_deref(), "--dir")).transpose()
    }

    /// Writes `value` as pretty JSON where `--json` says, if it does.
    fn write_json(&self, value: &serde_json::Value) -> Result<()> {
        if let Some(path) = &self.json {
            std::fs::write(path, serde_json::to_string_pretty(value)?)?;
        }
        Ok(())
    }
}

#[derive(Parser)]
struct RetrievalArgs {
    /// The evaluator checkpoint that embeds motions and queries.
    #[arg(long, default_value = "evaluator")]
    evaluator: String,
    /// The hybrid row's weights.
    #[command(flatten)]
    weights: WeightArgs,
    /// Choose the hybrid row's weights on the paraphrase benchmark's development half instead
    /// (the best MRR that keeps held-out caption queries' R@10), and print what was tried.
    #[arg(long, conflicts_with_all = ["bm25_weight", "caption_weight", "motion_weight", "bm25_known_exponent"])]
    calibrate: bool,
    /// A paraphrase benchmark (tab-separated query and relevant caption terms, as the shipped
    /// one) [default: the shipped benchmark].
    #[arg(long)]
    paraphrases: Option<PathBuf>,
    #[command(flatten)]
    common: Common,
}

#[derive(Parser)]
struct GeneratorArgs {
    /// Generators to compare, by checkpoint name.
    #[arg(long, value_delimiter = ',', default_value = "generator,generator-ar")]
    models: Vec<String>,
    /// The evaluator checkpoint.
    #[arg(long, default_value = "evaluator")]
    evaluator: String,
    /// Seed of the clip order and of sampling.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[command(flatten)]
    sampling: SamplingArgs,
    /// Record the results in each generator's card, and real clips' figures per skeleton (every
    /// split) in the evaluator's card, where quality reports find them.
    #[arg(long)]
    record: bool,
    #[command(flatten)]
    common: Common,
}

#[derive(Parser)]
struct PromptsArgs {
    /// Generators to compare, by checkpoint name.
    #[arg(long, value_delimiter = ',', default_value = "generator,generator-ar")]
    models: Vec<String>,
    /// The evaluator checkpoint (its card holds the real clips' floor the cleanup stands on).
    #[arg(long, default_value = "evaluator")]
    evaluator: String,
    /// A prompt file (tab-separated action and prompt, as the shipped one) [default: the
    /// shipped held-out prompts].
    #[arg(long)]
    prompts: Option<PathBuf>,
    /// Seed of sampling (prompt `i` is generated with seed + `i`).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[command(flatten)]
    sampling: SamplingArgs,
    /// Record each generator's pass rates in its card.
    #[arg(long)]
    record: bool,
    #[command(flatten)]
    common: Common,
}

#[derive(Parser)]
struct TokenizerArgs {
    /// Checkpoints to compare, by name.
    #[arg(long, value_delimiter = ',', default_value = "tat,baseline,tat-additive,tat-scratch")]
    models: Vec<String>,
    /// Source clips per transfer direction.
    #[arg(long, default_value_t = 8)]
    transfer_clips: usize,
    /// Skip measuring each model again on the same clips with turned joint frames (it doubles
    /// the time).
    #[arg(long)]
    no_invariance: bool,
    /// Record the results in each model's card.
    #[arg(long)]
    record: bool,
    #[command(flatten)]
    common: Common,
}

pub fn run(args: Args) -> Result<()> {
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    match args.what {
        What::Tokenizer(a) => run_tokenizer(a, &command),
        What::Generator(a) => run_generator(a, &command),
        What::Prompts(a) => run_prompts(a, &command),
        What::Retrieval(a) => run_retrieval(a, &command),
    }
}

fn run_tokenizer(args: TokenizerArgs, command: &str) -> Result<()> {
    let c = &args.common;
    let record_in = c.record_in(args.record)?;
    let (clips, rejected) = eval::clips(&c.manifest, c.limit)?;
    eprintln!("{rejected} clips rejected by cleaning");
    let mut encoder = CachedEncoder::new(c.store.encoder()?);
    let set = checkpoints(c.dir.as_deref());
    let invariance = !args.no_invariance;
    let report =
        tokenizer::evaluate_tokenizers(&set, &args.models, &clips, args.transfer_clips, invariance, &mut encoder)?;
    println!("{}", report.markdown);
    if let Some(dir) = &record_in {
        for (name, scores) in report.reconstruction.iter().filter(|(name, _)| args.models.contains(name)) {
            let cleaned_name = format!("{name}{}", eval::CLEANED);
            let cleaned = report.reconstruction.iter().find(|(n, _)| *n == cleaned_name).map(|(_, s)| s.clone());
            eval::record(dir, name, |metrics| {
                metrics["reconstruction"] = serde_json::Value::Object(scores.clone());
                if let Some(cleaned) = cleaned {
                    metrics["reconstruction_cleaned_up"] = serde_json::Value::Object(cleaned);
                }
                metrics["measured_by"] = command.into();
            })?;
        }
        for (name, transfer) in &report.transfer {
            let transfer = serde_json::to_value(transfer)?;
            eval::record(dir, name, |metrics| metrics["transfer"] = transfer)?;
        }
    }
    c.write_json(&report.json(command)?)
}

fn run_generator(args: GeneratorArgs, command: &str) -> Result<()> {
    let c = &args.common;
    let record_in = c.record_in(args.record)?;
    let (clips, rejected) = eval::clips(&c.manifest, c.limit)?;
    eprintln!("{} clips ({rejected} rejected by cleaning)", clips.len());
    let mut encoder = CachedEncoder::new(c.store.encoder()?);
    let set = checkpoints(c.dir.as_deref());
    let sampling = args.sampling.sampling();
    let (evaluator, models) = (&args.evaluator, &args.models);
    let (rows, real) =
        generator::evaluate_generators(&set, evaluator, models, &clips, &mut encoder, sampling, args.seed)?;
    println!("{}", generator::markdown(&rows));
    if let Some(dir) = &record_in {
        for name in &args.models {
            let mine: Vec<&generator::Row> = rows.iter().filter(|r| &r.model == name || r.model == "GT").collect();
            eval::record(dir, name, |metrics| {
                metrics["generation"] = serde_json::json!({ "rows": mine, "measured_by": command });
            })?;
        }
        let value = serde_json::to_value(&real)?;
        eval::record(dir, &args.evaluator, |metrics| {
            metrics[REAL_MOTION_KEY] = value;
            metrics[format!("{REAL_MOTION_KEY}_measured_by")] = command.into();
        })?;
    }
    c.write_json(&serde_json::json!({ "rows": rows, "real_motion": real, "command": command }))
}

fn run_prompts(args: PromptsArgs, command: &str) -> Result<()> {
    let c = &args.common;
    let record_in = c.record_in(args.record)?;
    let text = match &args.prompts {
        Some(path) => std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?,
        None => prompts::HELDOUT_PROMPTS.to_string(),
    };
    let held_out = prompts::parse_prompts(&text)?;
    let (clips, rejected) = eval::clips(&c.manifest, c.limit)?;
    eprintln!("{} prompts; {} clips ({rejected} rejected by cleaning)", held_out.len(), clips.len());
    let set = checkpoints(c.dir.as_deref());
    let encoder = || c.store.encoder();
    let models = &args.models;
    let draw = Request { steps: None, samples: 1, sampling: args.sampling.sampling(), seed: args.seed };
    let report = prompts::evaluate_prompts(&set, &args.evaluator, models, &clips, &held_out, &encoder, draw)?;
    println!("{}", report.markdown(models));
    if let Some(dir) = &record_in {
        for name in models {
            let rigs: Vec<serde_json::Value> = report
                .rigs
                .iter()
                .map(|r| serde_json::json!({ "rig": r.rig, "split": r.split, "real": r.real, "tokens": r.tokens, "generated": r.generated.get(name) }))
                .collect();
            eval::record(dir, name, |metrics| {
                metrics["held_out_prompts"] = serde_json::json!({ "rigs": rigs, "measured_by": command });
            })?;
        }
    }
    c.write_json(&serde_json::json!({ "report": report, "command": command }))
}

fn run_retrieval(args: RetrievalArgs, command: &str) -> Result<()> {
    let c = &args.common;
    let (clips, rejected) = eval::clips(&c.manifest, c.limit)?;
    let test: Vec<&ModelClip> = clips.iter().filter(|c| c.split == Split::Test).collect();
    eprintln!("{} clips, {} of them test clips ({rejected} rejected by cleaning)", clips.len(), test.len());
    let evaluator: Checkpoint = checkpoints(c.dir.as_deref()).get(&args.evaluator);
    let mut models = SearchModels::load(&evaluator, CachedEncoder::new(c.store.encoder()?))?;
    let text = match &args.paraphrases {
        Some(path) => std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?,
        None => benchmark::PARAPHRASES.to_string(),
    };
    let paraphrases = benchmark::parse(&text).context("reading the paraphrase benchmark")?;
    let hybrid = if args.calibrate { Hybrid::Calibrated } else { Hybrid::Fixed(args.weights.weights()) };
    let report = retrieval::evaluate(&mut models, &test, hybrid, &paraphrases)?;
    if let Some(calibration) = &report.calibration {
        println!("{}", retrieval::calibration_markdown(calibration));
    }
    println!("hybrid weights: {:?}\n", report.hybrid);
    println!("{}", retrieval::markdown(&report.rows));
    if !report.unanswerable.is_empty() {
        eprintln!("{} paraphrase queries have no relevant clip here and were left out", report.unanswerable.len());
    }
    let all: Vec<&ModelClip> = clips.iter().collect();
    let across = by_example::evaluate(&mut models, &all)?;
    println!("motion by example across skeletons (the query's own rig left out of the gallery)\n");
    println!("{}", by_example::markdown(&across));
    c.write_json(&serde_json::json!({ "report": report, "across_skeletons": across, "command": command }))
}
