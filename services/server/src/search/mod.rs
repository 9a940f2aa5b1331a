//! Search as the server offers it, built to keep up with many clients on few cores:
//! - the query texts that arrive together are embedded in one batch of the sentence encoder by
//!   one of the models' threads, one per core ([`models_thread`]), which also embed example
//!   clips and are the index's only writers;
//! - the index is shared behind a read-write lock and searched by one reader per core;
//! - queries that arrive together share one read of the store's clip signature
//!   ([`signature`]); when it differs from the one the index was synced to (another request,
//!   an ingest job or another replica changed the clips), the index catches up first, so every
//!   replica's index follows the shared store;
//! - two bounded caches, least recently used first out, answer repeated work: query vectors by
//!   text, and whole pages by request and signature ([`pages`]).

pub mod models_thread;
pub mod pages;
pub mod params;
pub mod signature;

use super::AppState;
use super::error::ApiError;
use super::motion::ClipSource;
use anymo_models::search::{SearchModels, TextVectors, query, read};
use anymo_retrieval::{Filter, Library, SearchError, Weights};
use anymo_store::Store;
use lru::LruCache;
use models_thread::ModelsThread;
use pages::{PAGES, PageCache, PageKey};
pub use params::{SearchHit, SearchPage, SearchParams};
use prometheus_client::metrics::histogram::Histogram;
use signature::SignatureReads;
use std::num::NonZeroUsize;
use std::sync::{Arc, Mutex, PoisonError, RwLock};
use tokio::runtime::Handle;
use tokio::sync::Semaphore;

/// Search requests that may wait for the models' threads.
const QUEUE: usize = 64;

/// Everything a search needs, shared by all requests.
pub struct SearchService {
    library: Arc<RwLock<Library>>,
    models: ModelsThread,
    signature: SignatureReads,
    pages: PageCache,
    vectors: Mutex<LruCache<String, TextVectors>>,
    readers: Semaphore,
}

impl SearchService {
    /// Starts a models' thread for each set of `models` over `library`, fed from `store`, and
    /// asks them to sync the index with the store before the first query needs it. `vectors`
    /// bounds the query vectors kept; `batch_texts` observes the texts of each embedding batch.
    pub fn start(
        models: Vec<SearchModels>,
        library: Library,
        store: Store,
        runtime: Handle,
        vectors: NonZeroUsize,
        batch_texts: Histogram,
    ) -> std::io::Result<SearchService> {
        let library = Arc::new(RwLock::new(library));
        let signature = SignatureReads::new(store.clone());
        let models = ModelsThread::start(models, library.clone(), store, runtime, QUEUE, batch_texts)?;
        models.sync_soon();
        let cores = std::thread::available_parallelism().map_or(1, NonZeroUsize::get);
        Ok(SearchService {
            library,
            models,
            signature,
            pages: PageCache::new(PAGES),
            vectors: Mutex::new(LruCache::new(vectors)),
            readers: Semaphore::new(cores),
        })
    }

    /// Clips searchable now.
    pub fn searchable(&self) -> usize {
        read(&self.library).len()
    }

    /// Search jobs waiting for the models' threads.
    pub fn waiting(&self) -> usize {
        self.models.waiting()
    }

    /// Asks for the index to catch up with the store soon (after an ingest job).
    pub fn sync_soon(&self) {
        if !self.models.sync_soon() {
            tracing::warn!("the search queue is full; the index catches up at the next query");
        }
    }

    fn cached_vectors(&self, text: &str) -> Option<TextVectors> {
        self.vectors.lock().unwrap_or_else(PoisonError::into_inner).get(text).cloned()
    }

    fn keep_vectors(&self, text: &str, vectors: &TextVectors) {
        self.vectors.lock().unwrap_or_else(PoisonError::into_inner).put(text.to_string(), vectors.clone());
    }
}

/// Searches the library by text, by example (an uploaded or stored clip) and by filters.
pub async fn search(state: &AppState, params: SearchParams, like: Option<ClipSource>) -> Result<SearchPage, ApiError> {
    let text = params.q.as_deref().map(str::trim).filter(|q| !q.is_empty()).map(String::from);
    let like = like.or(params.like_clip.map(ClipSource::Stored));
    if text.is_none() && like.is_none() {
        return Err(ApiError::bad_request("give words to search for (q), an example clip (like_clip), or both"));
    }
    if text.as_ref().is_some_and(|t| t.chars().count() > super::generation::MAX_PROMPT_CHARS) {
        return Err(ApiError::over_limit("the query", super::generation::MAX_PROMPT_CHARS, "more characters"));
    }
    let timeout = state.limits.timeout;
    tokio::time::timeout(timeout, answer(state, params, text, like))
        .await
        .unwrap_or_else(|_| Err(ApiError::timeout(timeout.as_secs_f64())))
}

async fn answer(
    state: &AppState,
    params: SearchParams,
    text: Option<String>,
    like: Option<ClipSource>,
) -> Result<SearchPage, ApiError> {
    let service = &state.search;
    let cached = text.as_deref().and_then(|t| service.cached_vectors(t));
    let announcement = (text.is_some() && cached.is_none()).then(|| service.models.announce());
    let signature = service.signature.read().await?;
    // An uploaded example is not part of the request's parameters, so its pages are not kept.
    let key = (!matches!(like, Some(ClipSource::Bvh(_)))).then(|| PageKey::new(&params, signature));
    if let Some(page) = key.as_ref().and_then(|k| service.pages.get(k)) {
        return Ok(page);
    }
    if service.models.synced() != Some(signature) {
        service.models.sync().await?;
    }
    let vectors = match (announcement, &text) {
        (Some(announcement), Some(t)) => {
            let vectors = announcement.embed(t.clone()).await?;
            service.keep_vectors(t, &vectors);
            Some(vectors)
        }
        _ => cached,
    };
    let example = match &like {
        Some(source) => Some(service.models.example(state.clip(source).await?).await?),
        None => None,
    };
    let filter = Filter {
        licence: params.licence.clone(),
        subject: params.subject.clone(),
        skeleton: params.skeleton.clone(),
        source: params.source.clone(),
        min_seconds: params.min_seconds,
        max_seconds: params.max_seconds,
    };
    let (offset, limit) = (params.offset.unwrap_or(0), params.limit.unwrap_or(10));
    let query = query(text.as_deref(), vectors, example, filter, Weights::default(), (offset, limit));
    let _reader = service.readers.acquire().await.map_err(|_| ApiError::unavailable("the server is stopping"))?;
    let library = service.library.clone();
    let page = tokio::task::spawn_blocking(move || read(&library).search(&query))
        .await
        .map_err(|_| ApiError::internal("the search failed on this request (it panicked)"))?
        .map_err(|e| match e {
            SearchError::Limit { .. } | SearchError::Filter(_) | SearchError::NothingToSearch => {
                ApiError::bad_request(e.to_string())
            }
            other => ApiError::internal(other),
        })?;
    let page = SearchPage::new(page, offset);
    // Kept only when ranked among the clips the signature names.
    if let Some(key) = key.filter(|_| service.models.synced() == Some(signature)) {
        service.pages.put(key, page.clone());
    }
    Ok(page)
}
