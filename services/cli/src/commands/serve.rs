//! `anymo serve`: the REST and gRPC server, with the embedded SQLite store and the shipped
//! checkpoints by default.

use super::context::{CheckpointArgs, StoreArgs};
use anyhow::{Context, Result};
use anymo_models::checkpoint::DEFAULT_TOKENIZER;
use anymo_server::auth::ApiKeys;
use anymo_server::limits::Limits;
use anymo_server::{Server, ServerConfig};
use anymo_tokenizer::text::DEFAULT_CACHE_TEXTS;
use std::num::NonZeroUsize;
use std::time::Duration;

#[derive(clap::Args)]
pub struct Args {
    /// Where to listen (HOST:PORT; port 0 picks a free one).
    #[arg(long, env = "ANYMO_ADDR", default_value = "127.0.0.1:8080")]
    addr: String,
    /// API keys that allow writes (ingest, delete); repeat, or comma-separate in ANYMO_API_KEYS.
    #[arg(long = "api-key", env = "ANYMO_API_KEYS", value_delimiter = ',', hide_env_values = true)]
    api_keys: Vec<String>,
    /// Require an API key for generation and edits too.
    #[arg(long)]
    keys_for_generate: bool,
    /// Largest request body, in bytes.
    #[arg(long, default_value_t = Limits::default().body_bytes)]
    max_body_bytes: usize,
    /// Most joints a skeleton may have.
    #[arg(long, default_value_t = Limits::default().joints)]
    max_joints: usize,
    /// Most frames an uploaded clip may have.
    #[arg(long, default_value_t = Limits::default().frames)]
    max_frames: usize,
    /// Longest motion to generate, in seconds (at most 30).
    #[arg(long, default_value_t = Limits::default().seconds)]
    max_seconds: f64,
    /// Most samples per generation.
    #[arg(long, default_value_t = Limits::default().samples)]
    max_samples: usize,
    /// Most files per ingest upload.
    #[arg(long, default_value_t = Limits::default().files)]
    max_files: usize,
    /// Generation requests that may wait; more are answered 429.
    #[arg(long, default_value_t = Limits::default().queue)]
    queue: usize,
    /// Generation workers (each runs one request at a time with its own models; default: one
    /// per core).
    #[arg(long, default_value_t = Limits::default().workers)]
    workers: usize,
    /// Search models' threads (each embeds one batch of queries at a time with its own sentence
    /// encoder; default: one per core).
    #[arg(long, default_value_t = Limits::default().search_workers)]
    search_workers: usize,
    /// Longest a request may take, in seconds, waiting included.
    #[arg(long, default_value_t = Limits::default().timeout.as_secs())]
    timeout_seconds: u64,
    /// How long shutdown waits for a running ingest job (it resumes at the next start if cut).
    #[arg(long, default_value_t = 30)]
    shutdown_grace_seconds: u64,
    /// This replica's name in the shared jobs table (default: host name and data directory).
    #[arg(long, env = "ANYMO_REPLICA")]
    replica: Option<String>,
    #[command(flatten)]
    checkpoints: CheckpointArgs,
    /// Distinct prompts and captions whose sentence embeddings each model worker keeps, and
    /// distinct search queries whose vectors search keeps; the least recently used go first.
    #[arg(long, default_value_t = DEFAULT_CACHE_TEXTS)]
    embedding_cache: NonZeroUsize,
    /// The generator checkpoint.
    #[arg(long, default_value = "generator")]
    generator: String,
    /// The tokenizer checkpoint for tokens and transfer.
    #[arg(long, default_value = DEFAULT_TOKENIZER)]
    tokenizer: String,
    /// The evaluator checkpoint that embeds motion for search.
    #[arg(long, default_value = "evaluator")]
    evaluator: String,
    #[command(flatten)]
    store: StoreArgs,
}

/// A replica name that stays the same across restarts of one deployment.
fn default_replica(data_dir: &std::path::Path) -> String {
    let host = std::fs::read_to_string("/etc/hostname").map(|h| h.trim().to_string()).unwrap_or_default();
    let dir = std::fs::canonicalize(data_dir).unwrap_or_else(|_| data_dir.to_path_buf());
    format!("{host}:{}", dir.display())
}

/// Resolves on Ctrl-C or SIGTERM.
async fn shutdown_signal() {
    let interrupt = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut signal) => {
                signal.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    tokio::select! { () = interrupt => {}, () = terminate => {} }
    tracing::info!("shutting down: finishing the requests in flight");
}

pub fn run(args: Args) -> Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info,tantivy=warn".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    let data_dir = args.store.data_dir()?;
    std::fs::create_dir_all(&data_dir)
        .with_context(|| format!("creating the data directory {}", data_dir.display()))?;
    let config = ServerConfig {
        addr: args.addr.clone(),
        replica: args.replica.clone().unwrap_or_else(|| default_replica(&data_dir)),
        data_dir,
        database_url: args.store.database_url.clone(),
        encoder_dir: anymo_paths::encoder_dir()?,
        embedding_cache: args.embedding_cache,
        checkpoints: args.checkpoints.set(),
        generator: args.generator.clone(),
        tokenizer: args.tokenizer.clone(),
        evaluator: args.evaluator.clone(),
        limits: Limits {
            body_bytes: args.max_body_bytes,
            joints: args.max_joints,
            frames: args.max_frames,
            seconds: args.max_seconds.min(anymo_models::studio::MAX_SECONDS),
            samples: args.max_samples,
            files: args.max_files,
            queue: args.queue,
            workers: args.workers.max(1),
            search_workers: args.search_workers.max(1),
            timeout: Duration::from_secs(args.timeout_seconds.max(1)),
        },
        keys: ApiKeys::new(&args.api_keys, args.keys_for_generate),
        shutdown_grace: Duration::from_secs(args.shutdown_grace_seconds),
    };
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    runtime.block_on(async move {
        let server = Server::start(config).await?;
        let addr = server.local_addr()?;
        if !args.api_keys.iter().any(|k| !k.trim().is_empty()) {
            tracing::warn!("no API keys: ingest and delete are refused (start with --api-key KEY to allow them)");
        }
        // The one line on standard output: scripts and tests read the address from it.
        println!("anymo listening on http://{addr} (REST /v1, docs /docs, gRPC anymo.v1.Anymo)");
        server.run(shutdown_signal()).await
    })
}
