//! Search at scale: the ingested corpus's index replicated to 50,000 clips (each copy under its
//! own ids and paths, its vectors jittered so copies are not exact duplicates), then the time to
//! build the index from scratch, to reopen it, and the latency of top-10 queries: hybrid, BM25
//! only, vectors only (both, and each space alone), hybrid under a filter, and by example. The same-run reference is one
//! plain pass of dot products over every vector in f32 (what an exact scan would read without
//! the int8 codes), and the query
//! embedding (sentence encoder + evaluator projection) is timed on its own.
//!
//! `cargo bench -p anymo-services --bench search` after `anymo ingest ../shared/data/manifest.tsv`
//! (which builds the index this replicates) and `bash tools/setup.sh --models`.

use anymo_models::checkpoint::Checkpoint;
use anymo_models::search::{SearchModels, library_dir};
use anymo_retrieval::{Entry, Filter, Library, Query, Weights};
use anymo_tokenizer::text::{CachedEncoder, SentenceEncoder};
use rand::{Rng, SeedableRng};
use std::path::Path;
use std::time::Instant;

const TARGET: usize = 50_000;
const RUNS: usize = 2000;
const QUERIES: [&str; 8] = [
    "a horse gallops",
    "a quadruped gallops then jumps",
    "a person walks in a sad manner",
    "someone waves goodbye",
    "a dog attacks",
    "a fish swims",
    "an angry person kicks",
    "a spider idles",
];

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

fn jitter(v: &[f32], rng: &mut impl Rng) -> Vec<f32> {
    let mut out: Vec<f32> = v.iter().map(|x| x + rng.random_range(-0.02..0.02)).collect();
    let norm = out.iter().map(|x| x * x).sum::<f32>().sqrt().max(1e-12);
    out.iter_mut().for_each(|x| *x /= norm);
    out
}

fn replicate(base: &[Entry]) -> Vec<Entry> {
    let stride = base.iter().map(|e| e.document.id).max().unwrap_or(0) + 1;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let mut out = Vec::with_capacity(TARGET);
    for copy in 0.. {
        for e in base {
            if out.len() == TARGET {
                return out;
            }
            let mut document = e.document.clone();
            document.id = copy * stride + e.document.id;
            document.path = format!("copy-{copy}/{}", document.path);
            out.push(Entry {
                document,
                caption_vector: e
                    .caption_vector
                    .as_deref()
                    .map(|v| if copy == 0 { v.to_vec() } else { jitter(v, &mut rng) }),
                motion_vector: e
                    .motion_vector
                    .as_deref()
                    .map(|v| if copy == 0 { v.to_vec() } else { jitter(v, &mut rng) }),
            });
        }
    }
    out
}

fn time_queries(library: &Library, queries: &[Query]) -> (f64, f64) {
    let mut times = Vec::with_capacity(RUNS);
    for run in 0..RUNS + 10 {
        let started = Instant::now();
        let page = library.search(&queries[run % queries.len()]).expect("a valid query");
        assert!(!page.hits.is_empty());
        if run >= 10 {
            times.push(started.elapsed().as_secs_f64() * 1000.0);
        }
    }
    times.sort_by(f64::total_cmp);
    (percentile(&times, 0.5), percentile(&times, 0.99))
}

fn main() {
    let data_dir = anymo_paths::default_data_dir().expect("a home folder or ANYMO_DATA_DIR");
    let Ok(encoder) = SentenceEncoder::load(anymo_paths::encoder_dir().expect("a home folder or ANYMO_MODELS")) else {
        eprintln!("skipping: no sentence encoder (run `bash tools/setup.sh --models`)");
        return;
    };
    let mut models = SearchModels::load(
        &Checkpoint::in_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../checkpoints"), "evaluator"),
        CachedEncoder::new(encoder),
    )
    .expect("the shipped evaluator");
    let source = Library::open(&library_dir(&data_dir), models.spaces().clone()).expect("the search index");
    if source.is_empty() {
        eprintln!("skipping: the search index is empty (run `anymo ingest ../shared/data/manifest.tsv` first)");
        return;
    }
    let base: Vec<Entry> = source.ids().into_iter().filter_map(|id| source.entry(id)).collect();
    let entries = replicate(&base);
    println!("{} clips replicated to {}", base.len(), entries.len());

    let dir = std::env::temp_dir().join(format!("anymo-search-bench-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let started = Instant::now();
    let mut library = Library::open(&dir, models.spaces().clone()).expect("a new index");
    library.upsert(entries.clone()).expect("indexing");
    let build = started.elapsed().as_secs_f64();
    drop(library);
    let started = Instant::now();
    let library = Library::open(&dir, models.spaces().clone()).expect("reopening");
    let reopen = started.elapsed().as_secs_f64();
    assert_eq!(library.len(), TARGET);
    println!("index build (text + both vector indexes, on disk): {build:.1} s; reopen: {reopen:.2} s");

    let started = Instant::now();
    let embedded: Vec<(String, Vec<f32>, Vec<f32>)> = QUERIES
        .iter()
        .map(|q| {
            let v = models.text_vectors(q).expect("embedding a query");
            (q.to_string(), v.caption, v.motion)
        })
        .collect();
    let embed_ms = started.elapsed().as_secs_f64() * 1000.0 / QUERIES.len() as f64;
    let query = |(text, c, m): &(String, Vec<f32>, Vec<f32>), weights: Weights, filter: Filter| Query {
        text: Some(text.clone()),
        caption_vector: Some(c.clone()),
        motion_vector: Some(m.clone()),
        filter,
        weights,
        offset: 0,
        limit: 10,
    };
    let all = |weights: Weights, filter: Filter| -> Vec<Query> {
        embedded.iter().map(|e| query(e, weights, filter.clone())).collect()
    };
    let examples: Vec<Query> = base
        .iter()
        .step_by(base.len() / 8)
        .filter_map(|e| e.motion_vector.clone())
        .map(|m| Query { motion_vector: Some(m), weights: Weights::new(0.0, 0.0, 1.0), limit: 10, ..Query::default() })
        .collect();

    // The reference: one pass of dot products over every caption and motion vector.
    let flat: Vec<Vec<f32>> =
        entries.iter().flat_map(|e| [e.caption_vector.clone(), e.motion_vector.clone()]).flatten().collect();
    let mut reference = Vec::new();
    for run in 0..40 {
        let (_, c, m) = &embedded[run % embedded.len()];
        let started = Instant::now();
        let total: f32 = flat
            .iter()
            .map(|v| v.iter().zip(if v.len() == c.len() { c } else { m }).map(|(a, b)| a * b).sum::<f32>())
            .sum();
        std::hint::black_box(total);
        reference.push(started.elapsed().as_secs_f64() * 1000.0);
    }
    reference.sort_by(f64::total_cmp);
    let reference = percentile(&reference, 0.5);

    let dogs = Filter { subject: Some("dog".into()), ..Filter::default() };
    let rows: [(&str, Vec<Query>); 7] = [
        ("hybrid top-10", all(Weights::default(), Filter::default())),
        ("BM25 only", all(Weights::new(1.0, 0.0, 0.0), Filter::default())),
        ("vectors only", all(Weights::new(0.0, 1.0, 1.0), Filter::default())),
        ("hybrid, --subject dog", all(Weights::default(), dogs)),
        ("by example (motion vectors)", examples),
        ("caption vectors only", all(Weights::new(0.0, 1.0, 0.0), Filter::default())),
        ("motion vectors only (text)", all(Weights::new(0.0, 0.0, 1.0), Filter::default())),
    ];
    println!("{} clips, 1 thread, {RUNS} queries each, top 10:", library.len());
    for (name, queries) in rows {
        let (p50, p99) = time_queries(&library, &queries);
        println!("  {name:<28} p50 {p50:.2} ms  p99 {p99:.2} ms  ({:.2}x the reference scan)", p50 / reference);
    }
    println!("  reference: one plain pass of dot products over all {} vectors: {reference:.2} ms", flat.len());
    println!("  query embedding (sentence encoder + evaluator projection): {embed_ms:.1} ms per query");
    let _ = std::fs::remove_dir_all(&dir);
}
