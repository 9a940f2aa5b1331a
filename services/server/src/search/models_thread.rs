//! The search models' threads. The sentence encoder, the tokenizer and the evaluator hold caches
//! and are used through `&mut`, so each thread owns a set of them; one batch of the encoder
//! costs far less than its texts one at a time, and two encoders side by side, one per core,
//! embed more than one encoder on both cores (`cargo bench --workspace --bench
//! sentence_encoder`). So there is one thread per core, taking jobs from one queue: a thread
//! gathers the query texts that wait together into one batch while the others embed theirs.
//! The threads also embed example clips and keep the shared index in step with the store (one
//! at a time: they are the index's only writers).

use super::signature::Signature;
use crate::error::ApiError;
use anymo_models::search::{SearchModels, TextVectors, sync};
use anymo_motion::motion::Motion;
use anymo_retrieval::Library;
use anymo_store::Store;
use prometheus_client::metrics::histogram::Histogram;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TryRecvError, TrySendError, sync_channel};
use std::sync::{Arc, Mutex, PoisonError, RwLock};
use std::time::{Duration, Instant};
use tokio::runtime::Handle;
use tokio::sync::oneshot;

/// The most texts embedded in one batch.
const MAX_BATCH: usize = 32;

/// How long a batch waits for texts that queries announced and have not sent yet. A lone query
/// never waits: with nothing announced, the batch goes at once.
const BATCH_WAIT: Duration = Duration::from_millis(2);

type Answer<T> = oneshot::Sender<Result<T, ApiError>>;

/// What the thread is asked: texts go in batches, tasks one at a time.
enum Job {
    Text(String, Answer<TextVectors>),
    Task(Task),
}

enum Task {
    Example(Box<Motion>, Answer<Vec<f32>>),
    /// Sync the index with the store; answered when done, if anyone waits.
    Sync(Option<Answer<()>>),
}

/// What the handles and the thread share.
#[derive(Default)]
struct Shared {
    /// Queries that will send a text soon.
    announced: AtomicUsize,
    /// Jobs sent and not yet taken.
    waiting: AtomicUsize,
    /// The store's signature the index was last synced to.
    synced: Mutex<Option<Signature>>,
    /// Held by the thread syncing the index, so that syncs run one at a time.
    syncing: Mutex<()>,
}

impl Shared {
    fn synced(&self) -> Option<Signature> {
        *self.synced.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// A handle on the models' threads.
pub struct ModelsThread {
    jobs: SyncSender<Job>,
    capacity: usize,
    shared: Arc<Shared>,
}

/// What the thread owns.
struct Owner {
    models: SearchModels,
    library: Arc<RwLock<Library>>,
    store: Store,
    runtime: Handle,
    shared: Arc<Shared>,
    batch_texts: Histogram,
}

impl ModelsThread {
    /// Starts a thread for each set of `models` over `library`, fed from `store` (their queries
    /// run on `runtime`); up to `capacity` jobs wait for them. `batch_texts` observes the texts of every batch.
    pub fn start(
        models: Vec<SearchModels>,
        library: Arc<RwLock<Library>>,
        store: Store,
        runtime: Handle,
        capacity: usize,
        batch_texts: Histogram,
    ) -> std::io::Result<ModelsThread> {
        let (jobs, taken) = sync_channel(capacity);
        let taken = Arc::new(Mutex::new(taken));
        let shared = Arc::new(Shared::default());
        for (k, models) in models.into_iter().enumerate() {
            let owner = Owner {
                models,
                library: library.clone(),
                store: store.clone(),
                runtime: runtime.clone(),
                shared: shared.clone(),
                batch_texts: batch_texts.clone(),
            };
            let taken = taken.clone();
            std::thread::Builder::new().name(format!("anymo-search-models-{k}")).spawn(move || owner.run(&taken))?;
        }
        Ok(ModelsThread { jobs, capacity, shared })
    }

    /// Jobs waiting for the thread now.
    pub fn waiting(&self) -> usize {
        self.shared.waiting.load(Ordering::Relaxed)
    }

    /// The store's signature the index was last synced to (`None` before the first sync).
    pub fn synced(&self) -> Option<Signature> {
        self.shared.synced()
    }

    /// Says a text will come, so that a batch under way waits a moment for it.
    pub fn announce(&self) -> Announcement<'_> {
        self.shared.announced.fetch_add(1, Ordering::SeqCst);
        Announcement { thread: self }
    }

    /// An example clip's motion vector.
    pub async fn example(&self, motion: Motion) -> Result<Vec<f32>, ApiError> {
        answered(self.send(|answer| Job::Task(Task::Example(Box::new(motion), answer)))?).await
    }

    /// Brings the index up to date with the store, and returns when it is.
    pub async fn sync(&self) -> Result<(), ApiError> {
        answered(self.send(|answer| Job::Task(Task::Sync(Some(answer))))?).await
    }

    /// Asks for a sync without waiting for it; false when the queue is full.
    pub fn sync_soon(&self) -> bool {
        self.shared.waiting.fetch_add(1, Ordering::Relaxed);
        let sent = self.jobs.try_send(Job::Task(Task::Sync(None))).is_ok();
        if !sent {
            self.shared.waiting.fetch_sub(1, Ordering::Relaxed);
        }
        sent
    }

    fn send<T>(&self, job: impl FnOnce(Answer<T>) -> Job) -> Result<oneshot::Receiver<Result<T, ApiError>>, ApiError> {
        let (answer, answered) = oneshot::channel();
        self.shared.waiting.fetch_add(1, Ordering::Relaxed);
        self.jobs.try_send(job(answer)).map_err(|e| {
            self.shared.waiting.fetch_sub(1, Ordering::Relaxed);
            match e {
                TrySendError::Full(_) => ApiError::busy("search", self.capacity),
                TrySendError::Disconnected(_) => ApiError::unavailable("the search models' thread has stopped"),
            }
        })?;
        Ok(answered)
    }
}

/// A text announced to the models' thread: sent with [`Announcement::embed`], or withdrawn when
/// dropped (the query was answered without it).
pub struct Announcement<'a> {
    thread: &'a ModelsThread,
}

impl Announcement<'_> {
    /// The text's vectors, embedded in a batch with the texts that wait with it.
    pub async fn embed(self, text: String) -> Result<TextVectors, ApiError> {
        let sent = self.thread.send(|answer| Job::Text(text, answer));
        // Withdrawn only once the text is in the queue, so the batch that waits for it finds it.
        drop(self);
        answered(sent?).await
    }
}

impl Drop for Announcement<'_> {
    fn drop(&mut self) {
        self.thread.shared.announced.fetch_sub(1, Ordering::SeqCst);
    }
}

async fn answered<T>(answer: oneshot::Receiver<Result<T, ApiError>>) -> Result<T, ApiError> {
    answer.await.unwrap_or_else(|_| Err(ApiError::internal("the search models failed on this request (they panicked)")))
}

impl Owner {
    /// Takes jobs until the queue closes. The queue is held while a batch is gathered, so one
    /// thread gathers at a time and the others work.
    fn run(mut self, jobs: &Mutex<Receiver<Job>>) {
        loop {
            let (mut texts, mut others) = (Vec::new(), Vec::new());
            {
                let jobs = jobs.lock().unwrap_or_else(PoisonError::into_inner);
                let Ok(first) = jobs.recv() else { return };
                self.take(first, &mut texts, &mut others);
                if !texts.is_empty() {
                    self.gather(&jobs, &mut texts, &mut others);
                }
            }
            if !texts.is_empty() {
                self.guarded(|owner| owner.embed(texts));
            }
            for task in others {
                self.guarded(|owner| owner.handle(task));
            }
        }
    }

    /// Runs `work`; a panic drops the answers it held (their queries get an error) and leaves
    /// the thread running.
    fn guarded(&mut self, work: impl FnOnce(&mut Owner)) {
        if catch_unwind(AssertUnwindSafe(|| work(self))).is_err() {
            tracing::error!("the search models panicked on a request");
        }
    }

    fn take(&self, job: Job, texts: &mut Vec<(String, Answer<TextVectors>)>, others: &mut Vec<Task>) {
        self.shared.waiting.fetch_sub(1, Ordering::Relaxed);
        match job {
            Job::Text(text, answer) => texts.push((text, answer)),
            Job::Task(task) => others.push(task),
        }
    }

    /// Adds to the batch the texts already queued, and those announced that come within
    /// [`BATCH_WAIT`]; other jobs queued meanwhile run after the batch. (Splitting the pending
    /// texts between the threads instead gave no more queries per second: larger batches
    /// embed each text for less.)
    fn gather(&self, jobs: &Receiver<Job>, texts: &mut Vec<(String, Answer<TextVectors>)>, others: &mut Vec<Task>) {
        let deadline = Instant::now() + BATCH_WAIT;
        while texts.len() < MAX_BATCH {
            let job = match jobs.try_recv() {
                Ok(job) => job,
                Err(TryRecvError::Disconnected) => return,
                Err(TryRecvError::Empty) => {
                    let now = Instant::now();
                    if self.shared.announced.load(Ordering::SeqCst) == 0 || now >= deadline {
                        return;
                    }
                    match jobs.recv_timeout(deadline - now) {
                        Ok(job) => job,
                        Err(_) => return,
                    }
                }
            };
            self.take(job, texts, others);
        }
    }

    fn embed(&mut self, texts: Vec<(String, Answer<TextVectors>)>) {
        // A query whose client went away is not embedded.
        let texts: Vec<_> = texts.into_iter().filter(|(_, answer)| !answer.is_closed()).collect();
        if texts.is_empty() {
            return;
        }
        self.batch_texts.observe(texts.len() as f64);
        let refs: Vec<&str> = texts.iter().map(|(t, _)| t.as_str()).collect();
        match self.models.texts_vectors(&refs) {
            Ok(vectors) => {
                for ((_, answer), v) in texts.into_iter().zip(vectors) {
                    let _ = answer.send(Ok(v));
                }
            }
            Err(e) => {
                let error = ApiError::from_model(e);
                for (_, answer) in texts {
                    let _ = answer.send(Err(error.clone()));
                }
            }
        }
    }

    fn handle(&mut self, task: Task) {
        match task {
            Task::Example(motion, answer) => {
                if !answer.is_closed() {
                    let _ = answer.send(self.models.motion_vector(&motion).map_err(ApiError::from_model));
                }
            }
            Task::Sync(answer) => {
                let synced = self.sync();
                if let Err(e) = &synced {
                    tracing::error!("syncing the search index with the store: {}", e.message);
                }
                if let Some(answer) = answer {
                    let _ = answer.send(synced);
                }
            }
        }
    }

    /// Syncs the index with the store unless it already reflects the store's signature.
    fn sync(&mut self) -> Result<(), ApiError> {
        let shared = self.shared.clone();
        let _syncing = shared.syncing.lock().unwrap_or_else(PoisonError::into_inner);
        let signature = self.runtime.block_on(self.store.clips_signature())?;
        if self.shared.synced() == Some(signature) {
            return Ok(());
        }
        let report = self
            .runtime
            .block_on(sync(&self.store, &self.library, &mut self.models, &mut |_, _| {}))
            .map_err(|e| ApiError::internal(format!("updating the search index: {e:#}")))?;
        if report.indexed + report.removed > 0 {
            tracing::info!(indexed = report.indexed, removed = report.removed, "search index synced with the store");
        }
        for problem in &report.without_motion {
            tracing::warn!("{problem}");
        }
        *self.shared.synced.lock().unwrap_or_else(PoisonError::into_inner) = Some(signature);
        Ok(())
    }
}
