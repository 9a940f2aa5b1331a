//! Long jobs: an uploaded ingest. The upload is stored whole with the job before the client is
//! answered, then a runner thread claims queued jobs from the store (any replica may), ingests
//! each clip in its own transaction and reports progress. A job whose process died resumes where
//! its clips stopped: ingest skips what is already stored, so nothing committed is lost or doubled.

use super::AppState;
use super::error::ApiError;
use super::search::SearchService;
use anymo_store::ingest::{Item, Progress, ingest};
use anymo_store::{Job, JobFile, Store};
use anymo_tokenizer::text::CachedEncoder;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicI64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::Duration;
use tokio::runtime::Handle;
use utoipa::ToSchema;

/// A running job that has not reported for this long is taken to be dead, and another runner
/// (on any replica) takes it over.
pub const STALE_MS: i64 = 30_000;

/// How often a running job reports its progress (and that it is alive).
const REPORT_EVERY: Duration = Duration::from_millis(100);

/// How long an idle runner waits before looking for jobs again (other replicas' jobs, and
/// jobs whose runner died, are found this way).
const POLL_EVERY: Duration = Duration::from_secs(2);

/// What an ingest upload says of its clips.
#[derive(Clone, Debug, Default, Deserialize, Serialize, ToSchema)]
pub struct IngestParams {
    /// Source dataset (default `upload`).
    pub source: String,
    /// Licence of every clip (default `unknown`).
    pub licence: String,
    /// Subject of every clip: species or `person` (default `unknown`).
    pub subject: String,
}

/// A job as clients see it.
#[derive(Clone, Debug, Serialize, ToSchema)]
pub struct JobView {
    /// Id: `GET /v1/jobs/{id}`.
    pub id: i64,
    /// What it does.
    pub kind: String,
    /// `queued`, `running`, `done` or `failed`.
    pub status: String,
    /// Clips handled.
    pub done: i64,
    /// Clips in all.
    pub total: i64,
    /// What it did, once done: clips added, already stored and rejected (with reasons).
    #[schema(value_type = Object)]
    pub result: Option<serde_json::Value>,
    /// Why it failed.
    pub error: Option<String>,
    /// When it was accepted (ms since the epoch).
    pub created_ms: i64,
    /// When it last reported.
    pub updated_ms: i64,
}

impl From<Job> for JobView {
    fn from(job: Job) -> JobView {
        JobView {
            id: job.id,
            kind: job.kind,
            status: job.status.as_str().to_string(),
            done: job.done,
            total: job.total,
            result: job.result,
            error: job.error,
            created_ms: job.created_ms,
            updated_ms: job.updated_ms,
        }
    }
}

/// A name safe to show and store: letters, digits, `.`, `-` and `_` only.
fn safe_name(name: &str) -> String {
    let cleaned: String =
        name.chars().map(|c| if c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_') { c } else { '_' }).collect();
    cleaned.trim_start_matches('.').chars().take(120).collect()
}

/// Accepts an upload: every file must be a BVH within the limits, or nothing is stored.
pub async fn accept_ingest(state: &AppState, params: IngestParams, files: Vec<JobFile>) -> Result<JobView, ApiError> {
    if files.is_empty() {
        return Err(ApiError::bad_request("the upload holds no .bvh or .bvh.gz file"));
    }
    if files.len() > state.limits.files {
        return Err(ApiError::over_limit("files per upload", state.limits.files, files.len()));
    }
    for file in &files {
        super::motion::parse_bvh(state, &format!("file {:?}", file.name), &file.bytes, true)?;
    }
    let files: Vec<JobFile> = files.into_iter().map(|f| JobFile { name: safe_name(&f.name), ..f }).collect();
    let params = serde_json::to_value(&params).expect("parameters serialise");
    let id = state.store.insert_job("ingest", &params, &files).await?;
    state.jobs_wake();
    let job = state.store.job(id).await?.ok_or_else(|| ApiError::internal("a job vanished as it was stored"))?;
    Ok(job.into())
}

/// The job runner: one thread that claims jobs and runs them.
pub struct JobRunner {
    /// The store jobs come from.
    pub store: Store,
    /// Runs the store's queries.
    pub runtime: Handle,
    /// Embeds captions and joint labels of ingested clips.
    pub encoder: CachedEncoder,
    /// Where uploaded files are unpacked while their job runs.
    pub scratch: PathBuf,
    /// This replica's name in the jobs table.
    pub owner: String,
    /// Search, told to sync its index after a job.
    pub search: Arc<SearchService>,
    /// Set while a job runs.
    pub busy: Arc<AtomicBool>,
    /// Set when the server stops: no new job is claimed.
    pub stopping: Arc<AtomicBool>,
}

struct Counter(Arc<AtomicI64>);

impl Progress for Counter {
    fn clip_done(&self) {
        self.0.fetch_add(1, Ordering::Relaxed);
    }
}

impl JobRunner {
    /// Runs jobs until the server stops; `wake` says a job was queued here.
    pub fn run(mut self, wake: Receiver<()>) {
        // A job this replica was running when its process died is taken up again at once.
        if let Err(e) = self.runtime.block_on(self.store.requeue_jobs_of(&self.owner)) {
            tracing::error!("requeueing this replica's interrupted jobs: {e}");
        }
        while !self.stopping.load(Ordering::SeqCst) {
            let claimed = self.runtime.block_on(self.store.claim_job(&self.owner, STALE_MS));
            match claimed {
                Ok(Some(job)) => {
                    self.busy.store(true, Ordering::SeqCst);
                    self.run_job(job);
                    self.busy.store(false, Ordering::SeqCst);
                    continue;
                }
                Ok(None) => {}
                Err(e) => tracing::error!("looking for jobs: {e}"),
            }
            match wake.recv_timeout(POLL_EVERY) {
                Ok(()) | Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return,
            }
        }
    }

    fn run_job(&mut self, job: Job) {
        tracing::info!(job = job.id, kind = job.kind, "job started");
        let dir = self.scratch.join(format!("job-{}", job.id));
        let outcome = self.ingest_job(&job, &dir);
        let _ = std::fs::remove_dir_all(&dir);
        let finished = match &outcome {
            Ok((result, done)) => self.runtime.block_on(self.store.finish_job(job.id, Ok(result), *done)),
            Err(e) => {
                tracing::error!(job = job.id, "job failed: {e:#}");
                self.runtime.block_on(self.store.finish_job(job.id, Err(&format!("{e:#}")), 0))
            }
        };
        if let Err(e) = finished {
            tracing::error!(job = job.id, "recording the end of the job: {e}");
        }
        self.search.sync_soon();
        tracing::info!(job = job.id, "job ended");
    }

    fn ingest_job(&mut self, job: &Job, dir: &Path) -> anyhow::Result<(serde_json::Value, i64)> {
        anyhow::ensure!(job.kind == "ingest", "unknown job kind {:?}", job.kind);
        let params: IngestParams = serde_json::from_value(job.params.clone())?;
        let files = self.runtime.block_on(self.store.job_files(job.id))?;
        std::fs::create_dir_all(dir)?;
        let mut items = Vec::with_capacity(files.len());
        for (k, file) in files.into_iter().enumerate() {
            // The stored name is shown, never used as a path: each file is unpacked by position.
            let path = dir.join(format!("{k:05}.bvh"));
            std::fs::write(&path, &file.bytes)?;
            items.push(Item {
                key: format!("upload/job-{}/{}", job.id, file.name),
                file: path,
                animation: None,
                source: or_default(&params.source, "upload"),
                licence: or_default(&params.licence, "unknown"),
                subject: or_default(&params.subject, "unknown"),
                captions: file.captions,
            });
        }
        let done = Arc::new(AtomicI64::new(0));
        let running = Arc::new(AtomicBool::new(true));
        let reporter = {
            let (store, done, running, id) = (self.store.clone(), done.clone(), running.clone(), job.id);
            self.runtime.spawn(async move {
                while running.load(Ordering::SeqCst) {
                    if let Err(e) = store.job_progress(id, done.load(Ordering::Relaxed)).await {
                        tracing::warn!(job = id, "reporting progress: {e}");
                    }
                    tokio::time::sleep(REPORT_EVERY).await;
                }
            })
        };
        let label = format!("upload job {}", job.id);
        let summary =
            self.runtime.block_on(ingest(&self.store, &mut self.encoder, &label, &items, 1, &Counter(done.clone())));
        running.store(false, Ordering::SeqCst);
        let _ = self.runtime.block_on(reporter);
        let summary = summary?;
        let rejected: Vec<serde_json::Value> = self
            .runtime
            .block_on(self.store.rejections(summary.run))?
            .into_iter()
            .map(|(path, reason)| serde_json::json!({ "file": path, "reason": reason }))
            .collect();
        let result = serde_json::json!({
            "added": summary.added, "already_stored": summary.skipped, "rejected": rejected,
        });
        Ok((result, items.len() as i64))
    }
}

fn or_default(value: &str, default: &str) -> String {
    if value.trim().is_empty() { default.to_string() } else { value.trim().to_string() }
}
