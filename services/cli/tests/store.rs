//! The corpus store and ingest, against SQLite always and PostgreSQL when one is reachable at
//! 127.0.0.1:5432 (set ANYMO_TEST_POSTGRES to another URL of a database the test may create
//! databases from): idempotent ingest, exact export, matching migrations on both databases.

use anymo_store::ingest::{Item, Progress, ingest, items_from_manifest};
use anymo_store::{JobFile, JobStatus, NewGeneration, Store};
use anymo_tests::{data_dir, scratch_dir};
use anymo_tokenizer::text::{CachedEncoder, SentenceEncoder};
use std::io::Read;
use std::path::Path;

struct Quiet;
impl Progress for Quiet {
    fn clip_done(&self) {}
}

fn encoder() -> Option<CachedEncoder> {
    match SentenceEncoder::load(anymo_paths::encoder_dir().expect("a home folder or ANYMO_MODELS")) {
        Ok(e) => Some(CachedEncoder::new(e)),
        Err(e) => {
            eprintln!("skipping: {e}");
            None
        }
    }
}

/// A sample of the corpus: every 40th manifest row, so every source appears.
fn sample() -> Option<Vec<Item>> {
    let dir = data_dir()?;
    Some(items_from_manifest(&dir.join("manifest.tsv")).unwrap().into_iter().step_by(40).collect())
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap()
}

/// The contract every backend must keep.
async fn contract(store: &Store, encoder: &mut CachedEncoder, items: &[Item]) {
    let first = ingest(store, encoder, "sample", items, 2, &Quiet).await.unwrap();
    assert!(first.added > 30, "{first:?}");
    assert_eq!(first.added + first.skipped + first.rejected_count(), items.len());
    let dump = store.canonical_dump().await.unwrap();
    assert_eq!(dump.len(), first.added);

    // Running again adds nothing and changes nothing.
    let second = ingest(store, encoder, "sample again", items, 2, &Quiet).await.unwrap();
    assert_eq!((second.added, second.skipped), (0, first.added));
    assert_eq!(store.canonical_dump().await.unwrap(), dump);

    // Counts agree, and each clip exports exactly the bytes it was ingested from.
    let stats = store.stats().await.unwrap();
    assert_eq!(stats.clips as usize, first.added);
    let split_total: i64 = stats.groups.iter().filter(|g| g.0 == "split").map(|g| g.2).sum();
    assert_eq!(split_total, stats.clips);
    let skeletons = store.skeletons().await.unwrap();
    assert_eq!(skeletons.iter().map(|s| s.clips).sum::<i64>(), stats.clips);
    assert!(skeletons.iter().all(|s| s.labels.len() as i64 == s.joint_count));
    // Each skeleton names what is on it: the distinct sources and subjects of its clips, sorted,
    // which together cover the corpus's; one skeleton alone says the same.
    for s in &skeletons {
        assert!(!s.sources.is_empty() && !s.subjects.is_empty(), "skeleton {} has clips", s.id);
        assert!(s.sources.windows(2).all(|w| w[0] < w[1]) && s.subjects.windows(2).all(|w| w[0] < w[1]));
        let alone = store.skeleton(s.id).await.unwrap().expect("the skeleton");
        assert_eq!((&alone.sources, &alone.subjects), (&s.sources, &s.subjects));
    }
    let sources: Vec<&String> = skeletons.iter().flat_map(|s| &s.sources).collect();
    let subjects: Vec<&String> = skeletons.iter().flat_map(|s| &s.subjects).collect();
    for (group, mut seen) in [("source", sources), ("subject", subjects)] {
        seen.sort();
        seen.dedup();
        let mut grouped: Vec<&String> = stats.groups.iter().filter(|g| g.0 == group).map(|g| &g.1).collect();
        grouped.sort();
        assert_eq!(seen, grouped, "{group}");
    }
    for id in 1..=3 {
        let clip = store.clip(id).await.unwrap().expect("stored clip");
        let item = items.iter().find(|i| i.key == clip.source_path).expect("an ingested item");
        assert_eq!(clip.captions, item.captions);
        let mut original = Vec::new();
        flate2::read::MultiGzDecoder::new(std::fs::File::open(&item.file).unwrap()).read_to_end(&mut original).unwrap();
        assert!(store.clip_bvh(id).await.unwrap().unwrap() == original, "clip {id} exports its original bytes");
    }
    assert!(store.clip(1_000_000).await.unwrap().is_none());
    server_contract(store).await;
}

/// What the server keeps: results round-trip, and a job is claimed by one replica at a time,
/// taken over only once its owner stops reporting.
async fn server_contract(store: &Store) {
    let samples = ["first".to_string(), "second".to_string()];
    let request = serde_json::json!({ "prompt": "a dog walks" });
    let quality = serde_json::json!([{ "jitter": 1.5 }, { "jitter": 2.5 }]);
    let new = NewGeneration {
        kind: "generate",
        request: request.clone(),
        frames: 60,
        fps: 30.0,
        samples: &samples,
        quality: quality.clone(),
    };
    let id = store.insert_generation(&new).await.unwrap();
    let stored = store.generation(id).await.unwrap().unwrap();
    assert_eq!((stored.kind.as_str(), stored.samples, stored.frames, stored.request), ("generate", 2, 60, request));
    assert_eq!(stored.quality, Some(quality), "each sample's report comes back");
    assert_eq!(store.generation_sample(id, 1).await.unwrap().unwrap(), b"second");
    assert!(store.generation_sample(id, 2).await.unwrap().is_none());

    let files = vec![JobFile { name: "a.bvh".into(), captions: vec!["walks".into()], bytes: b"BVH".to_vec() }];
    let job = store.insert_job("ingest", &serde_json::json!({ "licence": "CC0-1.0" }), &files).await.unwrap();
    let claimed = store.claim_job("replica-a", 60_000).await.unwrap().expect("a queued job");
    assert_eq!((claimed.id, claimed.status, claimed.total), (job, JobStatus::Running, 1));
    assert!(store.claim_job("replica-b", 60_000).await.unwrap().is_none(), "a running job is not claimed twice");
    store.job_progress(job, 1).await.unwrap();
    tokio::time::sleep(std::time::Duration::from_millis(5)).await;
    let taken = store.claim_job("replica-b", 1).await.unwrap().expect("a job whose owner went quiet");
    assert_eq!((taken.id, taken.done), (job, 1));
    assert_eq!(store.requeue_jobs_of("replica-b").await.unwrap(), 1);
    assert_eq!(store.job(job).await.unwrap().unwrap().status, JobStatus::Queued);
    assert_eq!(store.job_files(job).await.unwrap()[0].captions, ["walks"]);
    store.claim_job("replica-a", 60_000).await.unwrap().expect("the requeued job");
    store.finish_job(job, Ok(&serde_json::json!({ "added": 1 })), 1).await.unwrap();
    let done = store.job(job).await.unwrap().unwrap();
    assert_eq!((done.status, done.result), (JobStatus::Done, Some(serde_json::json!({ "added": 1 }))));
    assert!(store.job_files(job).await.unwrap().is_empty(), "a finished job's upload is dropped");
    assert!(store.claim_job("replica-a", 1).await.unwrap().is_none(), "a finished job is never claimed");
}

#[test]
fn sqlite_store_keeps_the_contract() {
    let (Some(items), Some(mut encoder)) = (sample(), encoder()) else { return };
    let dir = scratch_dir("store-sqlite");
    runtime().block_on(async {
        let store = Store::open(&Store::default_url(&dir)).await.unwrap();
        contract(&store, &mut encoder, &items).await;
    });
}

#[test]
fn postgres_store_keeps_the_contract() {
    let (Some(items), Some(mut encoder)) = (sample(), encoder()) else { return };
    let admin =
        std::env::var("ANYMO_TEST_POSTGRES").unwrap_or_else(|_| "postgres://postgres@127.0.0.1:5432/test".into());
    runtime().block_on(async {
        sqlx::any::install_default_drivers();
        let Ok(pool) = sqlx::AnyPool::connect(&admin).await else {
            eprintln!("skipping: no PostgreSQL at {admin} (set ANYMO_TEST_POSTGRES)");
            return;
        };
        // A fresh database per run, dropped afterwards.
        let name = format!("anymo_test_{}", std::process::id());
        sqlx::query(sqlx::AssertSqlSafe(format!("DROP DATABASE IF EXISTS {name}"))).execute(&pool).await.unwrap();
        sqlx::query(sqlx::AssertSqlSafe(format!("CREATE DATABASE {name}"))).execute(&pool).await.unwrap();
        let url = format!("{}/{name}", admin.rsplit_once('/').unwrap().0);
        {
            let store = Store::open(&url).await.unwrap();
            contract(&store, &mut encoder, &items).await;
            // A second replica on the same database sees the same corpus.
            let replica = Store::open(&url).await.unwrap();
            assert_eq!(replica.canonical_dump().await.unwrap(), store.canonical_dump().await.unwrap());
        }
        sqlx::query(sqlx::AssertSqlSafe(format!("DROP DATABASE {name} WITH (FORCE)"))).execute(&pool).await.unwrap();
    });
}

#[test]
fn migrations_match_on_both_databases() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../migrations");
    let versions = |db: &str| {
        let mut v: Vec<String> =
            std::fs::read_dir(root.join(db)).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
        v.sort();
        v
    };
    assert_eq!(versions("sqlite"), versions("postgres"));
    assert!(!versions("sqlite").is_empty());
}
