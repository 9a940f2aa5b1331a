//! What the tests that run `anymo serve` share: the binary on a free port, killed when dropped,
//! and the small real library it serves.

use anymo_tests::{manifest, succeeded};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

/// The API key the test servers accept.
pub const KEY: &str = "test-key-1";

/// A running `anymo serve`, killed when dropped.
pub struct Served {
    /// The process.
    pub child: Child,
    /// Its address, `http://127.0.0.1:PORT`.
    pub base: String,
}

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The binary with a data folder and the models, and no store or keys from the environment.
pub fn anymo(data: &Path, models: &Path, args: &[&str]) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_anymo"));
    command.args(args).arg("--data-dir").arg(data).env("ANYMO_MODELS", models);
    command.env_remove("DATABASE_URL").env_remove("ANYMO_API_KEYS");
    command
}

/// Starts a server on a free port and waits for the line that gives its address.
pub fn serve(data: &Path, models: &Path, extra: &[&str], env: &[(&str, &str)]) -> Served {
    let mut command = anymo(data, models, &["serve", "--addr", "127.0.0.1:0", "--api-key", KEY]);
    command.args(extra);
    for (k, v) in env {
        command.env(k, v);
    }
    let mut child = command.stdout(Stdio::piped()).stderr(Stdio::inherit()).spawn().expect("anymo serve starts");
    let stdout = child.stdout.take().expect("piped stdout");
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut line = String::new();
        let _ = BufReader::new(stdout).read_line(&mut line);
        let _ = tx.send(line);
    });
    let line = rx.recv_timeout(Duration::from_secs(300)).expect("the server says where it listens");
    let base = line.split_whitespace().find(|w| w.starts_with("http://")).expect("an address").to_string();
    Served { child, base }
}

/// The library the tests serve: horses, huskies and two kinds of Bandai motion.
fn library(shared: &Path, scratch: &Path) -> PathBuf {
    manifest(shared, scratch, &|p| {
        p.contains("/Horse__")
            || p.contains("/Husky__")
            || p.contains("dataset-1_walk_normal")
            || p.contains("dataset-1_bow_angry")
    })
}

/// A data folder under `scratch` with [`library`] ingested (and indexed), ready to serve.
pub fn ingested_library(shared: &Path, models: &Path, scratch: &Path) -> PathBuf {
    let data = scratch.join("data");
    let list = library(shared, scratch);
    succeeded(anymo(&data, models, &["ingest", list.to_str().expect("a UTF-8 path")]).output().expect("anymo runs"));
    data
}
