//! The anymo server: REST under `/v1` (with an OpenAPI document and a docs page), gRPC with
//! reflection on the same port, Prometheus metrics, and the workers behind them. The models run
//! on worker threads behind bounded queues; results and jobs live in the store, so several
//! replicas can share one PostgreSQL.

pub mod auth;
pub mod engine;
pub mod error;
pub mod generation;
pub mod grpc;
pub mod jobs;
pub mod limits;
pub mod metrics;
pub mod motion;
pub mod rest;
pub mod search;
pub mod web;

use anyhow::{Context, Result};
use anymo_models::checkpoint::Checkpoints;
use anymo_models::quality::RealMotion;
use anymo_models::search::{SearchModels, open_library};
use anymo_models::studio::Studio;
use anymo_models::tokens::TokenCodec;
use anymo_store::Store;
use anymo_tokenizer::text::{CachedEncoder, SentenceEncoder};
use auth::ApiKeys;
pub use engine::Engine;
use generation::GenerationModels;
use jobs::JobRunner;
use limits::Limits;
use metrics::Metrics;
use search::SearchService;
use std::future::Future;
use std::net::SocketAddr;
use std::num::NonZeroUsize;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{SyncSender, sync_channel};
use std::time::{Duration, Instant};

/// How the server is set up.
#[derive(Clone, Debug)]
pub struct ServerConfig {
    /// Where to listen.
    pub addr: String,
    /// The data directory (the default SQLite store, the search index, upload scratch).
    pub data_dir: PathBuf,
    /// The store's URL (default: the data directory's SQLite file).
    pub database_url: Option<String>,
    /// The sentence encoder's folder.
    pub encoder_dir: PathBuf,
    /// Distinct texts whose sentence embeddings each model worker keeps, and whose vectors
    /// search keeps (least recently used go first), so the caches stay bounded however many
    /// distinct prompts and queries arrive.
    pub embedding_cache: NonZeroUsize,
    /// The checkpoints.
    pub checkpoints: Checkpoints,
    /// The generator checkpoint.
    pub generator: String,
    /// The tokenizer checkpoint for tokens and transfer.
    pub tokenizer: String,
    /// The evaluator checkpoint that embeds motion for search.
    pub evaluator: String,
    /// The limits.
    pub limits: Limits,
    /// The API keys.
    pub keys: ApiKeys,
    /// This replica's name in the jobs table (stable across restarts, unique among replicas).
    pub replica: String,
    /// How long shutdown waits for a running job before leaving it to be resumed.
    pub shutdown_grace: Duration,
}

/// What every request handler shares.
pub struct AppState {
    /// The store.
    pub store: Store,
    /// The generation workers.
    pub generation: Engine<GenerationModels>,
    /// Search: its models' thread, the shared index and the caches.
    pub search: Arc<SearchService>,
    /// The limits.
    pub limits: Limits,
    /// The API keys.
    pub keys: ApiKeys,
    /// The metrics.
    pub metrics: Metrics,
    jobs: SyncSender<()>,
}

impl AppState {
    /// Tells the job runner a job was queued.
    pub fn jobs_wake(&self) {
        let _ = self.jobs.try_send(());
    }
}

/// A server bound to its address, with its models loaded.
pub struct Server {
    listener: tokio::net::TcpListener,
    app: axum::Router,
    state: Arc<AppState>,
    busy: Arc<AtomicBool>,
    stopping: Arc<AtomicBool>,
    grace: Duration,
}

/// The sentence encoder behind a cache of the configured size.
fn encoder(config: &ServerConfig) -> Result<CachedEncoder> {
    let encoder = SentenceEncoder::load(&config.encoder_dir)?;
    Ok(CachedEncoder::with_capacity(encoder, config.embedding_cache))
}

impl Server {
    /// Opens the store, loads the models onto their workers, starts the job runner and binds.
    pub async fn start(config: ServerConfig) -> Result<Server> {
        let url = config.database_url.clone().unwrap_or_else(|| Store::default_url(&config.data_dir));
        let store = Store::open(&url).await.with_context(|| format!("opening the store at {url}"))?;
        let started = Instant::now();
        let mut workers = Vec::with_capacity(config.limits.workers.max(1));
        for _ in 0..config.limits.workers.max(1) {
            let c = config.clone();
            let models = tokio::task::spawn_blocking(move || -> Result<GenerationModels> {
                let evaluator = c.checkpoints.get(&c.evaluator);
                let studio = Studio::load(&c.checkpoints.get(&c.generator), Some(&evaluator), encoder(&c)?)?;
                let mut codec = TokenCodec::load(&c.checkpoints.get(&c.tokenizer), encoder(&c)?)?;
                codec.set_real_motion(RealMotion::of_evaluator(&evaluator)?);
                Ok(GenerationModels::new(studio, codec))
            })
            .await??;
            workers.push(models);
        }
        let generation = Engine::start("generation", workers, config.limits.queue);
        let runtime = tokio::runtime::Handle::current();
        let (search_models, library) = {
            let c = config.clone();
            tokio::task::spawn_blocking(move || -> Result<_> {
                let models = (0..c.limits.search_workers.max(1))
                    .map(|_| SearchModels::load(&c.checkpoints.get(&c.evaluator), encoder(&c)?))
                    .collect::<Result<Vec<_>>>()?;
                let library = open_library(&c.data_dir, &models[0])?;
                Ok((models, library))
            })
            .await??
        };
        let metrics = Metrics::default();
        let search = Arc::new(SearchService::start(
            search_models,
            library,
            store.clone(),
            runtime.clone(),
            config.embedding_cache,
            metrics.search_batch_texts(),
        )?);
        tracing::info!(seconds = started.elapsed().as_secs_f64(), "models loaded");

        let (jobs, wake) = sync_channel(1);
        let busy = Arc::new(AtomicBool::new(false));
        let stopping = Arc::new(AtomicBool::new(false));
        let runner = JobRunner {
            store: store.clone(),
            runtime,
            encoder: encoder(&config)?,
            scratch: config.data_dir.join("uploads"),
            owner: config.replica.clone(),
            search: search.clone(),
            busy: busy.clone(),
            stopping: stopping.clone(),
        };
        std::thread::Builder::new().name("anymo-jobs".into()).spawn(move || runner.run(wake))?;

        let state = Arc::new(AppState {
            store,
            generation,
            search,
            limits: config.limits.clone(),
            keys: config.keys.clone(),
            metrics,
            jobs,
        });
        let listener = tokio::net::TcpListener::bind(&config.addr)
            .await
            .with_context(|| format!("listening on {}", config.addr))?;
        let app = app(state.clone())?;
        Ok(Server { listener, app, state, busy, stopping, grace: config.shutdown_grace })
    }

    /// The state its handlers share (to call the operations in-process, as the load test's
    /// reference does).
    pub fn state(&self) -> Arc<AppState> {
        self.state.clone()
    }

    /// The address the server listens on.
    pub fn local_addr(&self) -> Result<SocketAddr> {
        Ok(self.listener.local_addr()?)
    }

    /// Serves until `shutdown` resolves, then answers the requests in flight, lets a running
    /// job finish (up to the grace period; an unfinished job resumes at the next start) and
    /// returns.
    pub async fn run(self, shutdown: impl Future<Output = ()> + Send + 'static) -> Result<()> {
        axum::serve(self.listener, self.app).with_graceful_shutdown(shutdown).await?;
        self.stopping.store(true, Ordering::SeqCst);
        let deadline = Instant::now() + self.grace;
        while self.busy.load(Ordering::SeqCst) && Instant::now() < deadline {
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        if self.busy.load(Ordering::SeqCst) {
            tracing::warn!("a job was still running at shutdown; it resumes when a server starts again");
        }
        Ok(())
    }
}

/// The REST and gRPC routes on one router, with the web page and the docs page, a JSON 404 for
/// anything else, and the timeout and metrics around every request.
fn app(state: Arc<AppState>) -> Result<axum::Router> {
    let (rest, api) = rest::router(state.clone());
    let reflection = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(grpc::DESCRIPTOR_SET)
        .build_v1()?;
    let grpc = tonic::service::Routes::new(grpc::service(state.clone())).add_service(reflection).into_axum_router();
    let docs = utoipa_swagger_ui::SwaggerUi::new("/docs").url("/openapi.json", api);
    Ok(rest
        .merge(grpc)
        .merge(docs)
        .merge(web::router())
        .fallback(rest::fallback)
        .layer(axum::middleware::from_fn_with_state(state, rest::observe)))
}
