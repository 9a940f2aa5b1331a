//! Ingest throughput on the full `../shared/data` manifest into a fresh SQLite store, with the
//! sentence encoder's own rate on the manifest's distinct captions measured in the same run
//! (the part of ingest that is model inference).
//!
//! `cargo bench -p anymo-services --bench ingest` (needs `bash tools/setup.sh` for the model).

use anymo_store::Store;
use anymo_store::ingest::{Progress, ingest, items_from_manifest};
use anymo_tokenizer::text::{CachedEncoder, SentenceEncoder};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::time::Instant;

struct Quiet;
impl Progress for Quiet {
    fn clip_done(&self) {}
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let data = std::env::var_os("ANYMO_DATA").map_or_else(|| root.join("../shared/data"), PathBuf::from);
    if !data.join("manifest.tsv").is_file() {
        eprintln!("skipping: no data at {} (set ANYMO_DATA)", data.display());
        return;
    }
    let load = || {
        SentenceEncoder::load(anymo_paths::encoder_dir().expect("a home folder or ANYMO_MODELS"))
            .expect("the sentence encoder (bash tools/setup.sh)")
    };
    let items = items_from_manifest(&data.join("manifest.tsv")).unwrap();
    let captions: BTreeSet<&str> = items.iter().flat_map(|i| i.captions.iter().map(String::as_str)).collect();
    let captions: Vec<&str> = captions.into_iter().collect();

    let encoder = load();
    let start = Instant::now();
    for batch in captions.chunks(64) {
        encoder.encode(batch).unwrap();
    }
    let encode_seconds = start.elapsed().as_secs_f64();

    let dir = std::env::temp_dir().join(format!("anymo-ingest-bench-{}", std::process::id()));
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let mut encoder = CachedEncoder::new(load());
    let (summary, seconds) = runtime.block_on(async {
        let store = Store::open(&Store::default_url(&dir)).await.unwrap();
        let start = Instant::now();
        let summary = ingest(&store, &mut encoder, "bench", &items, 2, &Quiet).await.unwrap();
        (summary, start.elapsed().as_secs_f64())
    });
    std::fs::remove_dir_all(&dir).unwrap();
    println!(
        "manifest: {} clips, {} distinct captions; 2 threads, SQLite, one transaction per clip",
        items.len(),
        captions.len()
    );
    println!(
        "ingest: {:.1} s, {:.0} clips/s ({} added, {} skipped, {} rejected)",
        seconds,
        items.len() as f64 / seconds,
        summary.added,
        summary.skipped,
        summary.rejected_count()
    );
    println!(
        "sentence encoder alone on the distinct captions: {encode_seconds:.1} s ({:.0} texts/s), {:.0}% of the ingest",
        captions.len() as f64 / encode_seconds,
        100.0 * encode_seconds / seconds
    );
}
