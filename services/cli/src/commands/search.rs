//! `anymo search ["QUERY"] [--like CLIP] [filters]`: the motion library by text, by example and
//! by metadata, as a table or JSON. The index is brought up to date with the store first.

use super::context::{CheckpointArgs, StoreArgs, runtime};
use super::input;
use anyhow::{Result, bail};
use anymo_models::search::{SearchModels, SyncReport, open_library, sync};
use anymo_retrieval::{Filter, Found, Library, Page, Weights};
use anymo_store::Store;
use anymo_tokenizer::text::CachedEncoder;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use tokio::runtime::Runtime;

/// A search's filters.
#[derive(clap::Args)]
struct FilterArgs {
    /// Only clips under this licence (e.g. CC0-1.0).
    #[arg(long)]
    licence: Option<String>,
    /// Only clips whose subject has these words (`dog` finds husky and shiba inu dogs).
    #[arg(long)]
    subject: Option<String>,
    /// Only clips from sources starting with this (e.g. quaternius, bandai).
    #[arg(long)]
    source: Option<String>,
    /// Only clips on skeletons whose fingerprint starts with this (see `anymo corpus skeletons`).
    #[arg(long)]
    skeleton: Option<String>,
    /// Only clips at least this many seconds long.
    #[arg(long)]
    min_seconds: Option<f64>,
    /// Only clips at most this many seconds long.
    #[arg(long)]
    max_seconds: Option<f64>,
}

impl FilterArgs {
    fn filter(&self) -> Filter {
        Filter {
            licence: self.licence.clone(),
            subject: self.subject.clone(),
            skeleton: self.skeleton.clone(),
            source: self.source.clone(),
            min_seconds: self.min_seconds,
            max_seconds: self.max_seconds,
        }
    }
}

/// How much each retriever counts (0 leaves one out); shared with `anymo eval retrieval`.
#[derive(clap::Args, Clone)]
pub struct WeightArgs {
    /// Weight of BM25 over captions, subject, path and joint labels.
    #[arg(long, default_value_t = Weights::default().bm25)]
    bm25_weight: f32,
    /// Weight of sentence-embedding similarity to captions.
    #[arg(long, default_value_t = Weights::default().captions)]
    caption_weight: f32,
    /// Weight of motion-embedding similarity (text or example against motions).
    #[arg(long, default_value_t = Weights::default().motions)]
    motion_weight: f32,
    /// BM25's weight is scaled by the share of the query's words the library holds, to this
    /// power (0: not scaled).
    #[arg(long, default_value_t = Weights::default().bm25_known_exponent)]
    bm25_known_exponent: f32,
}

impl WeightArgs {
    pub fn weights(&self) -> Weights {
        Weights {
            bm25: self.bm25_weight,
            captions: self.caption_weight,
            motions: self.motion_weight,
            bm25_known_exponent: self.bm25_known_exponent,
        }
    }
}

#[derive(clap::Args)]
pub struct Args {
    /// Words describing the motion (optional with --like).
    query: Option<String>,
    /// Find clips that move like this one (BVH, BVH.gz or GLB), on any skeleton.
    #[arg(long)]
    like: Option<PathBuf>,
    /// The animation to use when --like is a glTF file with several.
    #[arg(long)]
    animation: Option<String>,
    #[command(flatten)]
    filter: FilterArgs,
    /// Results per page.
    #[arg(short = 'k', long, default_value_t = 10)]
    limit: usize,
    /// Results to skip (for the next pages).
    #[arg(long, default_value_t = 0)]
    offset: usize,
    #[command(flatten)]
    weights: WeightArgs,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    index: IndexArgs,
    #[command(flatten)]
    store: StoreArgs,
}

/// The models behind the search index; shared with `anymo ingest`.
#[derive(clap::Args)]
pub struct IndexArgs {
    /// The evaluator checkpoint that embeds motions for search.
    #[arg(long, default_value = "evaluator")]
    evaluator: String,
    #[command(flatten)]
    checkpoints: CheckpointArgs,
}

/// The loaded search models and the data directory's index, brought up to date with the store.
pub struct SyncedIndex {
    /// The models.
    pub models: SearchModels,
    /// The index.
    pub library: Library,
    /// What the sync did.
    pub report: SyncReport,
}

impl IndexArgs {
    /// Loads the models, opens the index and syncs it with `store`, with a progress bar on
    /// standard error while there is something to index.
    pub fn sync(&self, store_args: &StoreArgs, runtime: &Runtime, store: &Store) -> Result<SyncedIndex> {
        let mut models = SearchModels::load(
            &self.checkpoints.set().get(&self.evaluator),
            CachedEncoder::new(store_args.encoder()?),
        )?;
        let library = std::sync::RwLock::new(open_library(&store_args.data_dir()?, &models)?);
        let bar = ProgressBar::hidden();
        bar.set_style(
            ProgressStyle::with_template("indexing {bar:40} {pos}/{len} clips eta {eta}").expect("a template"),
        );
        let report = runtime.block_on(sync(store, &library, &mut models, &mut |done, pending| {
            if bar.is_hidden() {
                bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
                bar.set_length(pending as u64);
            }
            bar.set_position(done as u64);
        }))?;
        bar.finish_and_clear();
        let library = library.into_inner().unwrap_or_else(std::sync::PoisonError::into_inner);
        Ok(SyncedIndex { models, library, report })
    }
}

pub fn run(args: Args) -> Result<()> {
    if args.query.as_deref().is_none_or(|q| q.trim().is_empty()) && args.like.is_none() {
        bail!("give words to search for, --like CLIP, or both");
    }
    let like = args.like.as_deref().map(|p| input::read_motion(p, args.animation.as_deref())).transpose()?;
    let runtime = runtime()?;
    let store = runtime.block_on(args.store.open())?;
    let SyncedIndex { mut models, library, report } = args.index.sync(&args.store, &runtime, &store)?;
    if report.indexed + report.removed > 0 {
        eprintln!("index updated: {} clips indexed, {} removed", report.indexed, report.removed);
    }
    for problem in &report.without_motion {
        eprintln!("warning: {problem}");
    }
    let query = models.query(
        args.query.as_deref(),
        like.as_ref(),
        args.filter.filter(),
        args.weights.weights(),
        (args.offset, args.limit),
    )?;
    let page = library.search(&query)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&page_json(&page, args.offset))?);
    } else {
        print_table(&page, args.offset);
    }
    Ok(())
}

/// A page as JSON: each hit's clip, the matched caption with its highlight ranges, and ranks.
fn page_json(page: &Page, offset: usize) -> serde_json::Value {
    let hits: Vec<serde_json::Value> = page
        .hits
        .iter()
        .enumerate()
        .map(|(i, h)| {
            let d = &h.document;
            serde_json::json!({
                "rank": offset + i + 1,
                "id": d.id,
                "path": d.path,
                "caption": h.snippet.as_ref().map_or_else(|| d.captions.first().cloned().unwrap_or_default(), |s| s.text.clone()),
                "highlights": h.snippet.as_ref().map(|s| s.highlights.iter().map(|r| [r.start, r.end]).collect::<Vec<_>>()).unwrap_or_default(),
                "captions": d.captions,
                "subject": d.subject,
                "source": d.source,
                "licence": d.licence,
                "skeleton": d.skeleton,
                "seconds": d.seconds,
                "score": h.score,
                "ranks": h.ranks,
            })
        })
        .collect();
    serde_json::json!({ "candidates": page.candidates, "hits": hits })
}

fn caption(hit: &Found) -> String {
    match &hit.snippet {
        Some(s) => s.marked("*", "*"),
        None => hit.document.captions.first().cloned().unwrap_or_default(),
    }
}

fn clipped(text: &str, width: usize) -> String {
    if text.chars().count() <= width {
        text.to_string()
    } else {
        let mut s: String = text.chars().take(width.saturating_sub(1)).collect();
        s.push('…');
        s
    }
}

fn print_table(page: &Page, offset: usize) {
    if page.hits.is_empty() {
        println!("no clips found");
        return;
    }
    let rows: Vec<[String; 8]> = page
        .hits
        .iter()
        .enumerate()
        .map(|(i, h)| {
            let d = &h.document;
            [
                (offset + i + 1).to_string(),
                format!("{:.4}", h.score),
                d.id.to_string(),
                clipped(&d.path, 56),
                clipped(&caption(h), 56),
                d.subject.clone(),
                d.source.clone(),
                d.licence.clone(),
            ]
        })
        .collect();
    let header = ["#", "score", "id", "clip", "caption", "subject", "source", "licence"];
    let widths: Vec<usize> = (0..header.len())
        .map(|c| rows.iter().map(|r| r[c].chars().count()).chain([header[c].len()]).max().unwrap_or(0))
        .collect();
    let line = |cells: Vec<&str>| {
        let padded: Vec<String> = cells.iter().zip(&widths).map(|(c, w)| format!("{c:<w$}")).collect();
        println!("{}", padded.join("  ").trim_end());
    };
    line(header.to_vec());
    for r in &rows {
        line(r.iter().map(String::as_str).collect());
    }
    println!(
        "{} of {} candidates (use --offset {} for more)",
        page.hits.len(),
        page.candidates,
        offset + page.hits.len()
    );
}
