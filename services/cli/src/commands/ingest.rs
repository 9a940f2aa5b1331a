//! `anymo ingest PATH`: a folder of BVH/GLB files or a manifest TSV into the corpus store, then
//! the new clips into the search index.

use super::context::{StoreArgs, runtime};
use super::search::IndexArgs;
use anyhow::{Context, Result};
use anymo_store::Store;
use anymo_store::ingest::{Progress, ingest, items_from_folder, items_from_manifest};
use anymo_tokenizer::text::CachedEncoder;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::time::Instant;

#[derive(clap::Args)]
pub struct Args {
    /// A folder (BVH, BVH.gz, GLB; captions in sidecar .txt files) or a manifest .tsv.
    path: PathBuf,
    /// Threads reading and cleaning clips.
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// Leave the search index as it is (the next `anymo search` brings it up to date).
    #[arg(long)]
    no_index: bool,
    #[command(flatten)]
    index: IndexArgs,
    #[command(flatten)]
    store: StoreArgs,
}

struct Bar(ProgressBar);

impl Progress for Bar {
    fn clip_done(&self) {
        self.0.inc(1);
    }
}

pub fn run(args: Args) -> Result<()> {
    let items = if args.path.is_dir() { items_from_folder(&args.path)? } else { items_from_manifest(&args.path)? };
    let mut encoder = CachedEncoder::new(args.store.encoder()?);
    let runtime = runtime()?;
    let store = runtime.block_on(args.store.open())?;
    let bar = ProgressBar::new(items.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} clips {per_sec} eta {eta}").expect("a valid template"),
    );
    let start = Instant::now();
    let label = args.path.display().to_string();
    let summary = runtime
        .block_on(ingest(&store, &mut encoder, &label, &items, args.threads, &Bar(bar.clone())))
        .with_context(|| format!("ingesting {label}"))?;
    bar.finish_and_clear();
    let seconds = start.elapsed().as_secs_f64();
    println!(
        "ingest run {}: {} clips in {seconds:.1} s ({:.0} clips/s): {} added, {} already stored, {} rejected",
        summary.run,
        items.len(),
        items.len() as f64 / seconds.max(1e-9),
        summary.added,
        summary.skipped,
        summary.rejected_count()
    );
    for (reason, paths) in &summary.rejected {
        println!("  rejected {} x {reason}", paths.len());
        for p in paths.iter().take(3) {
            println!("      {p}");
        }
    }
    if !args.no_index {
        update_index(&args, &runtime, &store)?;
    }
    Ok(())
}

/// Indexes the clips the search index lacks.
fn update_index(args: &Args, runtime: &tokio::runtime::Runtime, store: &Store) -> Result<()> {
    let start = Instant::now();
    let synced = args
        .index
        .sync(&args.store, runtime, store)
        .context("updating the search index (use --no-index to ingest without it)")?;
    let report = &synced.report;
    println!(
        "search index: {} clips indexed, {} removed in {:.1} s; {} clips searchable",
        report.indexed,
        report.removed,
        start.elapsed().as_secs_f64(),
        synced.library.len()
    );
    for problem in &report.without_motion {
        println!("  {problem}");
    }
    Ok(())
}
