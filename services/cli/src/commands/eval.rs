//! `anymo eval tokenizer|generator|retrieval`: the tokenizer's reconstruction table (TAT,
//! baseline, ablations) with its transfer figures, text-to-motion by MoMask's protocol, and
//! search by EVAL.md's retrieval protocol.

use super::context::{StoreArgs, checkpoints, writable_checkpoints};
use super::generate::SamplingArgs;
use super::search::WeightArgs;
use anyhow::{Context, Result};
use anymo_models::card::CodecCard;
use anymo_models::checkpoint::Checkpoint;
use anymo_models::codecs::{self, Graphs};
use anymo_models::data::{self, ModelClip};
use anymo_models::evaluate::{self, Sums, TransferScores};
use anymo_models::search::{self, SearchModels};
use anymo_models::{generation, generation_eval};
use anymo_tokenizer::dataset::Split;
use anymo_tokenizer::nn::load_card;
use anymo_tokenizer::text::CachedEncoder;
use clap::{Parser, Subcommand};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

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
    /// Search on the test split: text -> motion and motion -> motion, per retriever.
    Retrieval(RetrievalArgs),
}

#[derive(Parser)]
struct RetrievalArgs {
    /// The corpus manifest.
    #[arg(long, default_value = "../shared/data/manifest.tsv")]
    manifest: PathBuf,
    /// The evaluator checkpoint that embeds motions and queries.
    #[arg(long, default_value = "evaluator")]
    evaluator: String,
    /// Use at most this many clips per split.
    #[arg(long)]
    limit: Option<usize>,
    /// The hybrid row's weights.
    #[command(flatten)]
    weights: WeightArgs,
    /// A folder of checkpoints (`--record` writes to their cards) [default: as every command finds them]
    #[arg(long)]
    dir: Option<PathBuf>,
    /// Write the results as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    #[command(flatten)]
    store: StoreArgs,
}

#[derive(Parser)]
struct GeneratorArgs {
    /// The corpus manifest.
    #[arg(long, default_value = "../shared/data/manifest.tsv")]
    manifest: PathBuf,
    /// Generators to compare, by checkpoint name.
    #[arg(long, value_delimiter = ',', default_value = "generator,generator-ar")]
    models: Vec<String>,
    /// The evaluator checkpoint.
    #[arg(long, default_value = "evaluator")]
    evaluator: String,
    /// Use at most this many clips per split.
    #[arg(long)]
    limit: Option<usize>,
    /// Seed of the clip order and of sampling.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[command(flatten)]
    sampling: SamplingArgs,
    /// A folder of checkpoints (`--record` writes to their cards) [default: as every command finds them]
    #[arg(long)]
    dir: Option<PathBuf>,
    /// Write the results as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Record the results in each generator's card.
    #[arg(long)]
    record: bool,
    #[command(flatten)]
    store: StoreArgs,
}

#[derive(Parser)]
struct TokenizerArgs {
    /// The corpus manifest.
    #[arg(long, default_value = "../shared/data/manifest.tsv")]
    manifest: PathBuf,
    /// Checkpoints to compare, by name.
    #[arg(long, value_delimiter = ',', default_value = "tat,baseline,tat-additive,tat-scratch")]
    models: Vec<String>,
    /// Use at most this many clips per split.
    #[arg(long)]
    limit: Option<usize>,
    /// Source clips per transfer direction.
    #[arg(long, default_value_t = 8)]
    transfer_clips: usize,
    /// A folder of checkpoints (`--record` writes to their cards) [default: as every command finds them]
    #[arg(long)]
    dir: Option<PathBuf>,
    /// Write the results as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Record the results in each model's card.
    #[arg(long)]
    record: bool,
    #[command(flatten)]
    store: StoreArgs,
}

pub fn run(args: Args) -> Result<()> {
    match args.what {
        What::Tokenizer(a) => tokenizer(a),
        What::Generator(a) => generator(a),
        What::Retrieval(a) => retrieval(a),
    }
}

/// The usable clips of the test split (at most `limit` per split of the manifest).
fn test_clips(manifest: &std::path::Path, limit: Option<usize>) -> Result<Vec<ModelClip>> {
    let (clips, rejected) =
        data::load_manifest(manifest, limit).with_context(|| format!("reading the manifest {}", manifest.display()))?;
    let test: Vec<ModelClip> = clips.into_iter().filter(|c| c.split == Split::Test).collect();
    eprintln!("{} test clips ({rejected} rejected by cleaning)", test.len());
    Ok(test)
}

fn f(x: f64) -> String {
    format!("{x:.4}")
}

fn tokenizer(args: TokenizerArgs) -> Result<()> {
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let (clips, rejected) = data::load_manifest(&args.manifest, args.limit)
        .with_context(|| format!("reading the manifest {}", args.manifest.display()))?;
    let eval_clips: Vec<&ModelClip> = clips.iter().filter(|c| c.split != Split::Train).collect();
    eprintln!("{} test and zero-shot clips ({rejected} rejected by cleaning)", eval_clips.len());
    let mut encoder = CachedEncoder::new(args.store.encoder()?);
    let mut results = serde_json::Map::new();
    let mut tables = Tables::default();
    for name in &args.models {
        let (mut codec, card) = codecs::load(&checkpoints(args.dir.as_deref()).get(name), &mut encoder)?;
        let (window, overlap) = match &card.config {
            CodecCard::Tokenizer(t) => (t.tokenizer.window, t.tokenizer.overlap),
            CodecCard::Baseline(_) => (BASELINE_WINDOW, BASELINE_OVERLAP),
        };
        let mut graphs = Graphs::new(&mut encoder);
        let rec = evaluate::reconstruction(codec.as_mut(), &mut graphs, &eval_clips, window, overlap)?;
        let model_json = tables.add(name, &rec)?;
        if args.record {
            record(&writable_checkpoints(args.dir.as_deref(), "--dir")?, name, |metrics| {
                metrics["reconstruction"] = serde_json::Value::Object(model_json.clone());
                metrics["measured_by"] = command.clone().into();
            })?;
        }
        results.insert(name.clone(), serde_json::Value::Object(model_json));
    }
    let reference = evaluate::static_reference(&eval_clips);
    results.insert(STATIC_REFERENCE.into(), serde_json::Value::Object(tables.add(STATIC_REFERENCE, &reference)?));
    let Tables { table, per_source, by_kind } = tables;
    println!("{table}\n{per_source}\n{by_kind}");
    if args.models.iter().any(|m| m == "tat") {
        let transfers = transfer_table(&args, &clips, &mut encoder)?;
        let mut t = String::from(
            "| transfer | target | clips | cycle MPJPE | reconstruction MPJPE | FS | GP | distance correlation |\n|---|---|---|---|---|---|---|---|\n",
        );
        for s in &transfers {
            t.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {:.3} |\n",
                s.name,
                s.target,
                s.clips,
                f(s.cycle_mpjpe),
                f(s.reconstruction_mpjpe),
                f(s.fs),
                f(s.gp),
                s.distance_correlation
            ));
        }
        println!("{t}");
        if args.record {
            let transfer = serde_json::to_value(&transfers)?;
            record(&writable_checkpoints(args.dir.as_deref(), "--dir")?, "tat", |metrics| {
                metrics["transfer"] = transfer;
            })?;
        }
        results.insert("transfer".into(), serde_json::to_value(&transfers)?);
    }
    results.insert("command".into(), command.into());
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&results)?)?;
    }
    Ok(())
}

/// The reference row's name: each clip held in its mean pose (see [`evaluate::static_pose`]).
const STATIC_REFERENCE: &str = "static pose (reference)";

/// The reconstruction tables, per split and per source, as Markdown.
struct Tables {
    table: String,
    per_source: String,
    by_kind: String,
}

impl Default for Tables {
    fn default() -> Self {
        Tables {
            table: String::from(
                "| model | split | clips | MPJPE | MPJPE (yaw aligned) | MPJPE (free root) | MPJPE (with trans) | GeoDist (deg) | GeoDist (free root) | FS | GP | FS (GT) | GP (GT) |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
            ),
            per_source: String::from(
                "| model | split | source | clips | MPJPE | MPJPE (yaw aligned) | MPJPE (free root) | MPJPE (with trans) | GeoDist (deg) | GeoDist (free root) |\n|---|---|---|---|---|---|---|---|---|---|\n",
            ),
            by_kind: String::from(
                "| model | split | GeoDist (deg) | root | joints that move joints | joints that move none |\n|---|---|---|---|---|---|\n",
            ),
        }
    }
}

impl Tables {
    /// Adds one model's rows; returns its scores per split and per source, as JSON.
    fn add(
        &mut self,
        name: &str,
        rec: &evaluate::Reconstruction,
    ) -> Result<serde_json::Map<String, serde_json::Value>> {
        let mut by_split: BTreeMap<String, Sums> = BTreeMap::new();
        let mut model_json = serde_json::Map::new();
        for ((split, source), sums) in &rec.groups {
            by_split.entry(split.clone()).or_default().merge(sums);
            let s = sums.scores();
            self.per_source.push_str(&format!(
                "| {name} | {split} | {source} | {} | {} | {} | {} | {} | {:.2} | {:.2} |\n",
                s.clips,
                f(s.mpjpe),
                f(s.mpjpe_yaw),
                f(s.mpjpe_free),
                f(s.mpjpe_trans),
                s.geodist,
                s.geodist_free
            ));
            model_json.insert(format!("{split}/{source}"), serde_json::to_value(s)?);
        }
        for (split, sums) in &by_split {
            let s = sums.scores();
            self.table.push_str(&format!(
                "| {name} | {split} | {} | {} | {} | {} | {} | {:.2} | {:.2} | {} | {} | {} | {} |\n",
                s.clips,
                f(s.mpjpe),
                f(s.mpjpe_yaw),
                f(s.mpjpe_free),
                f(s.mpjpe_trans),
                s.geodist,
                s.geodist_free,
                f(s.fs),
                f(s.gp),
                f(s.fs_truth),
                f(s.gp_truth)
            ));
            self.by_kind.push_str(&format!(
                "| {name} | {split} | {:.2} | {:.2} | {:.2} | {:.2} |\n",
                s.geodist, s.geodist_root, s.geodist_inner, s.geodist_unseen
            ));
            model_json.insert(split.clone(), serde_json::to_value(s)?);
        }
        if rec.refused > 0 {
            self.table.push_str(&format!(
                "| {name} | refused | {} | (skeleton larger than the model takes) | | | | | | | | | |\n",
                rec.refused
            ));
            model_json.insert("refused".into(), rec.refused.into());
        }
        Ok(model_json)
    }
}

/// Human -> human of other proportions, human -> quadruped, quadruped -> quadruped, each from
/// test clips onto a skeleton of another subject.
fn transfer_table(
    args: &TokenizerArgs,
    clips: &[ModelClip],
    encoder: &mut CachedEncoder,
) -> Result<Vec<TransferScores>> {
    let (mut tat, _) = checkpoints(args.dir.as_deref()).get("tat").load_tat(encoder)?;
    let mut graphs = Graphs::new(encoder);
    let pick = |source: &str, split: Split| -> Vec<&ModelClip> {
        clips.iter().filter(|c| c.item.source == source && c.split == split).take(args.transfer_clips).collect()
    };
    let first = |subject: &str| clips.iter().find(|c| c.item.subject == subject);
    let humans = pick("bandai-namco-dataset-2", Split::Test);
    let horses: Vec<&ModelClip> = clips
        .iter()
        .filter(|c| c.item.subject == "horse" && c.split != Split::Train)
        .take(args.transfer_clips)
        .collect();
    let mut out = Vec::new();
    let plans: [(&str, &Vec<&ModelClip>, Option<&ModelClip>); 4] = [
        ("human -> human (CMU rig)", &humans, clips.iter().find(|c| c.item.source == "cmu-mocap")),
        ("human -> human (Xia rig)", &humans, clips.iter().find(|c| c.item.source == "xia-style")),
        ("human -> quadruped", &humans, first("horse")),
        ("quadruped -> quadruped", &horses, first("wolf")),
    ];
    for (name, sources, target) in plans {
        let Some(target) = target else { continue };
        if sources.is_empty() {
            continue;
        }
        out.push(evaluate::transfer(&mut tat, &mut graphs, name, sources, target)?);
    }
    Ok(out)
}

fn generator(args: GeneratorArgs) -> Result<()> {
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let clips = test_clips(&args.manifest, args.limit)?;
    let test: Vec<&ModelClip> = clips.iter().collect();
    let mut encoder = CachedEncoder::new(args.store.encoder()?);
    let set = checkpoints(args.dir.as_deref());
    let evaluator_checkpoint = set.get(&args.evaluator);
    let (evaluator, evaluator_card) = generation::load_evaluator(&evaluator_checkpoint)?;
    let mut tat = evaluator_checkpoint.load_tat_of(&evaluator_card, &mut encoder)?;
    let mut loaded = Vec::new();
    for name in &args.models {
        let checkpoint = set.get(name);
        let (generator, card) = generation::load_generator(&checkpoint)?;
        let tokenizer = checkpoint.load_tat_of(&card, &mut encoder)?;
        eprintln!("{name}: {} steps", card.steps);
        loaded.push((name.clone(), generator, tokenizer));
    }
    let refs: Vec<generation_eval::Candidate> = loaded
        .iter()
        .map(|(name, generator, tokenizer)| generation_eval::Candidate { name: name.clone(), generator, tokenizer })
        .collect();
    let sampling = args.sampling.sampling();
    let rows = generation_eval::evaluate(&mut tat, &evaluator, &refs, &test, &mut encoder, sampling, args.seed)?;
    let mut table = String::from(
        "| model | clips | R@1 | R@2 | R@3 | FID | MM-Dist | FS | GP | s/clip |\n|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in &rows {
        table.push_str(&format!(
            "| {} ({}) | {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.4} | {:.4} | {:.3} |\n",
            r.model,
            r.subset,
            r.clips,
            r.r_precision[0],
            r.r_precision[1],
            r.r_precision[2],
            r.fid,
            r.mm_dist,
            r.foot_skating,
            r.ground_penetration,
            r.seconds_per_clip
        ));
    }
    println!("{table}");
    if args.record {
        let dir = writable_checkpoints(args.dir.as_deref(), "--dir")?;
        for name in &args.models {
            let mine: Vec<&generation_eval::Row> =
                rows.iter().filter(|r| &r.model == name || r.model == "GT").collect();
            record(&dir, name, |metrics| {
                metrics["generation"] = serde_json::json!({ "rows": mine, "measured_by": command });
            })?;
        }
    }
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&serde_json::json!({ "rows": rows, "command": command }))?)?;
    }
    Ok(())
}

fn retrieval(args: RetrievalArgs) -> Result<()> {
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let clips = test_clips(&args.manifest, args.limit)?;
    let test: Vec<&ModelClip> = clips.iter().collect();
    let evaluator = checkpoints(args.dir.as_deref()).get(&args.evaluator);
    let mut models = SearchModels::load(&evaluator, CachedEncoder::new(args.store.encoder()?))?;
    let rows = search::evaluate::evaluate(&mut models, &test, args.weights.weights())?;
    let mut table = String::from(
        "| task | retrievers | queries | queries' subjects | R@1 | R@5 | R@10 | median rank |\n|---|---|---|---|---|---|---|---|\n",
    );
    for r in &rows {
        let s = &r.summary;
        table.push_str(&format!(
            "| {} | {} | {} | {} | {:.3} | {:.3} | {:.3} | {} |\n",
            r.task, r.retrievers, s.queries, r.subset, s.r1, s.r5, s.r10, s.median_rank
        ));
    }
    println!("{table}");
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&serde_json::json!({ "rows": rows, "command": command }))?)?;
    }
    Ok(())
}

/// The baseline's windows when measured (it has no window in its card: NEC's Table 1 protocol).
const BASELINE_WINDOW: usize = 64;
/// The overlap of the baseline's windows.
const BASELINE_OVERLAP: usize = 16;

/// Updates the figures in a model card of the checkpoints folder `dir` (`--record`).
fn record(dir: &Path, name: &str, update: impl FnOnce(&mut serde_json::Value)) -> Result<()> {
    let (_, path) = Checkpoint::in_dir(dir, name).files().expect("a folder's checkpoint has files");
    let mut card = load_card(&path)?;
    update(&mut card.metrics);
    card.save(&path).with_context(|| format!("writing {}", path.display()))
}
