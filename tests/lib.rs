//! Helpers shared by anymo's end-to-end tests: finding the real data in `../shared/data`.
//!
//! Tests that need the data call [`data_dir`] and return early, printing why, when it is
//! absent; set `ANYMO_DATA` to point elsewhere.

use std::path::{Path, PathBuf};

/// The data folder (`$ANYMO_DATA`, else `../shared/data` beside the workspace), if present.
pub fn data_dir() -> Option<PathBuf> {
    let dir = match std::env::var_os("ANYMO_DATA") {
        Some(dir) => PathBuf::from(dir),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"),
    };
    if dir.join("manifest.tsv").is_file() {
        Some(dir)
    } else {
        eprintln!("skipping: no data at {} (set ANYMO_DATA to the shared data folder)", dir.display());
        None
    }
}

/// The folder holding the sentence encoder's folder, where `anymo` itself looks for it (see
/// `anymo_paths::models_dir`), if the model is there.
pub fn models_dir() -> Option<PathBuf> {
    let models = anymo_paths::models_dir().expect("a home folder or ANYMO_MODELS");
    if models.join(anymo_paths::ENCODER_DIR_NAME).join("model.safetensors").is_file() {
        Some(models)
    } else {
        eprintln!("skipping: no sentence encoder in {} (bash tools/setup.sh --models)", models.display());
        None
    }
}

/// Every file below `dir` whose name ends with `suffix`, sorted.
pub fn files_with_suffix(dir: &Path, suffix: &str) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).expect("data folder is readable") {
            let path = entry.expect("data folder entry").path();
            if path.is_dir() {
                stack.push(path);
            } else if path.to_string_lossy().ends_with(suffix) {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

/// A manifest of the real manifest's lines whose path passes `keep`, written in `dir` with the
/// clips linked beside it, so a test can ingest a small library.
pub fn manifest(shared: &Path, dir: &Path, keep: &dyn Fn(&str) -> bool) -> PathBuf {
    let text = std::fs::read_to_string(shared.join("manifest.tsv")).expect("the manifest is readable");
    let mut lines = text.lines();
    let mut out = format!("{}\n", lines.next().expect("a header"));
    for line in lines.filter(|l| keep(l.split('\t').next().unwrap_or_default())) {
        let path = line.split('\t').next().unwrap_or_default();
        let link = dir.join(path);
        if !link.exists() {
            std::fs::create_dir_all(link.parent().expect("a folder")).expect("a scratch folder");
            std::os::unix::fs::symlink(shared.join(path), &link).expect("a link to the clip");
        }
        out.push_str(line);
        out.push('\n');
    }
    let file = dir.join(format!("manifest-{}.tsv", out.lines().count()));
    std::fs::write(&file, out).expect("a writable scratch folder");
    file
}

/// A scratch directory unique to one test, emptied first.
pub fn scratch_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("anymo-tests-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

/// The JSON reference files of a check: those in the folder named by the environment variable
/// `env` when it is set, else the committed ones in `tests/fixtures/<fixture>`; sorted.
pub fn reference_files(env: &str, fixture: &str) -> Vec<PathBuf> {
    let dir = match std::env::var_os(env) {
        Some(dir) => PathBuf::from(dir),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures").join(fixture),
    };
    let mut refs: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("reference folder {}: {e}", dir.display()))
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    refs.sort();
    assert!(!refs.is_empty(), "no references in {}", dir.display());
    refs
}

/// Runs the `anymo` binary at `binary` (a test's `env!("CARGO_BIN_EXE_anymo")`) with `args`, the
/// sentence encoder in `models`, the built-in checkpoints and one thread, as a user's first run.
pub fn run_anymo(binary: &str, models: &Path, args: &[&str]) -> std::process::Output {
    std::process::Command::new(binary)
        .args(args)
        .env("ANYMO_MODELS", models)
        .env_remove("ANYMO_CHECKPOINTS")
        .env("RAYON_NUM_THREADS", "1")
        .output()
        .expect("the anymo binary runs")
}

/// Asserts that a command succeeded, showing its standard error when it did not.
pub fn succeeded(out: std::process::Output) -> std::process::Output {
    assert!(out.status.success(), "command failed: {}", String::from_utf8_lossy(&out.stderr));
    out
}

/// Every tensor of a safetensors file, flattened, sorted by name (to compare checkpoints).
pub fn safetensors_values(path: &Path) -> Vec<(String, Vec<f32>)> {
    let mut all: Vec<(String, Vec<f32>)> = candle_core::safetensors::load(path, &candle_core::Device::Cpu)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .into_iter()
        .map(|(k, t)| (k, t.flatten_all().expect("flatten").to_vec1().expect("f32 values")))
        .collect();
    all.sort_by(|a, b| a.0.cmp(&b.0));
    all
}

/// Writes the decompressed contents of a `.gz` file to `to`.
pub fn gunzip(from: &Path, to: &Path) {
    use std::io::Read;
    let mut text = Vec::new();
    flate2::read::MultiGzDecoder::new(std::fs::File::open(from).expect("a readable .gz"))
        .read_to_end(&mut text)
        .expect("valid gzip");
    std::fs::write(to, text).expect("a writable scratch file");
}

/// Waits until a training run's one-file state (`state.safetensors`) records `step`; panics
/// after 10 minutes, so a run that never saves fails the test instead of passing it late.
pub fn wait_for_saved_step(state: &Path, step: u64) {
    let started = std::time::Instant::now();
    loop {
        let done = anymo_tokenizer::nn::snapshot::progress(state)
            .expect("a readable run state")
            .and_then(|p| serde_json::from_str::<serde_json::Value>(&p).ok())
            .and_then(|v| v["step"].as_u64())
            .unwrap_or(0);
        if done >= step {
            return;
        }
        assert!(
            started.elapsed() < std::time::Duration::from_secs(600),
            "{} did not reach step {step} in 10 minutes (it is at {done})",
            state.display()
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// Whether a tool an end-to-end test needs (as `bash tools/setup.sh --test-tools` installs it)
/// is at `path`. Where it is not, the test should skip, and this says so; but with
/// `ANYMO_REQUIRE_TEST_TOOLS` set (as `.ci/run` sets it) a missing tool fails the test instead,
/// so CI never passes a test it did not run.
pub fn test_tool(path: &Path, what: &str) -> bool {
    if path.exists() {
        return true;
    }
    let how = format!("no {what} at {} (bash tools/setup.sh --test-tools)", path.display());
    assert!(std::env::var_os("ANYMO_REQUIRE_TEST_TOOLS").is_none(), "{how}, and ANYMO_REQUIRE_TEST_TOOLS is set");
    eprintln!("skipping: {how}");
    false
}

/// The rows of the manifest in the data folder `data`, each as its cells by column name.
pub fn manifest_rows(data: &Path) -> Vec<std::collections::HashMap<String, String>> {
    let manifest = std::fs::read_to_string(data.join("manifest.tsv")).expect("a readable manifest");
    let mut lines = manifest.lines();
    let header: Vec<&str> = lines.next().expect("a header").split('\t').collect();
    lines
        .map(|line| header.iter().zip(line.split('\t')).map(|(h, cell)| (h.to_string(), cell.to_string())).collect())
        .collect()
}

/// Content words and a crude stem, to check that a held-out query or prompt shares no word with
/// the captions it targets.
pub mod words {
    /// Words that carry no content (articles, prepositions, pronouns, conjunctions).
    const FUNCTION_WORDS: &[&str] = &[
        "a", "an", "the", "in", "on", "of", "with", "to", "and", "or", "its", "his", "her", "their", "them", "is",
        "are", "at", "by", "for", "from", "as", "into", "onto", "then", "while", "after", "before", "one", "both",
    ];

    /// The words of `text` that carry content, lowercased.
    pub fn content_words(text: &str) -> Vec<String> {
        text.split(|c: char| !c.is_alphanumeric())
            .filter(|w| !w.is_empty())
            .map(str::to_lowercase)
            .filter(|w| !FUNCTION_WORDS.contains(&w.as_str()))
            .collect()
    }

    /// A crude stem: one common suffix off, keeping at least three letters.
    pub fn stem(word: &str) -> &str {
        for suffix in ["ing", "ed", "es", "s", "ly"] {
            if let Some(root) = word.strip_suffix(suffix).filter(|r| r.len() >= 3) {
                return root;
            }
        }
        word
    }

    /// Same stem, or one stem (of four letters or more) begins the other ("wave" / "waves").
    pub fn related(a: &str, b: &str) -> bool {
        let (a, b) = (stem(a), stem(b));
        a == b || (a.len() >= 4 && b.starts_with(a)) || (b.len() >= 4 && a.starts_with(b))
    }
}
