//! Killing `anymo ingest` with SIGKILL part-way loses nothing committed and leaves no clip half
//! stored: running it again completes with exactly the store an uninterrupted run makes.

use anymo_store::Store;
use anymo_tests::{data_dir, files_with_suffix, models_dir, scratch_dir};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn ingest(folder: &Path, data: &Path, models: &Path) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_anymo"));
    command
        .arg("ingest")
        .arg(folder)
        .arg("--no-index")
        .arg("--data-dir")
        .arg(data)
        .env("ANYMO_MODELS", models)
        .env_remove("DATABASE_URL")
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    command
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap()
}

fn dump(data: &Path) -> Vec<String> {
    runtime().block_on(async { Store::open(&Store::default_url(data)).await.unwrap().canonical_dump().await.unwrap() })
}

#[test]
fn a_killed_ingest_resumes_to_the_same_store() {
    let (Some(shared), Some(models)) = (data_dir(), models_dir()) else { return };
    // A folder of links to every 4th BVH clip of the corpus.
    let folder = scratch_dir("kill-input");
    for file in files_with_suffix(&shared, ".bvh.gz").iter().step_by(4) {
        let link = folder.join(file.strip_prefix(&shared).unwrap());
        std::fs::create_dir_all(link.parent().unwrap()).unwrap();
        std::os::unix::fs::symlink(file, link).unwrap();
    }

    let whole = scratch_dir("kill-whole");
    assert!(ingest(&folder, &whole, &models).status().unwrap().success());
    let expected = dump(&whole);
    assert!(expected.len() > 300, "{} clips", expected.len());

    // Kill a second run once it has stored some clips.
    let killed = scratch_dir("kill-resumed");
    let mut child = ingest(&folder, &killed, &models).spawn().unwrap();
    let db = killed.join("anymo.db");
    let start = Instant::now();
    let stored = loop {
        std::thread::sleep(Duration::from_millis(50));
        let count = if db.exists() {
            runtime().block_on(async {
                let pool = sqlx::AnyPool::connect(&format!("sqlite://{}?mode=ro", db.display())).await.ok()?;
                let row: (i64,) = sqlx::query_as("SELECT COUNT(*) FROM clips").fetch_one(&pool).await.ok()?;
                Some(row.0)
            })
        } else {
            None
        };
        if count.is_some_and(|c| c >= 50) || child.try_wait().unwrap().is_some() {
            break count;
        }
        assert!(start.elapsed() < Duration::from_secs(300), "ingest made no progress");
    };
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let partial = dump(&killed);
    assert!(stored.is_some() && partial.len() < expected.len(), "the kill landed mid-way ({} clips)", partial.len());
    // What was committed is whole: every stored clip is one the full run stores, byte for byte.
    assert!(partial.iter().all(|line| expected.contains(line)));

    assert!(ingest(&folder, &killed, &models).status().unwrap().success());
    assert_eq!(dump(&killed), expected);
}
