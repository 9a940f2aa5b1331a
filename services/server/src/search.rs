//! Search as the server offers it. One worker owns the search models and the library; before
//! each query it checks a cheap signature of the store's clips and syncs the index when another
//! request, an ingest job or another replica changed them, so every replica's index follows the
//! shared store.

use super::AppState;
use super::error::ApiError;
use super::motion::ClipSource;
use anymo_models::search::{SearchModels, sync};
use anymo_retrieval::{Filter, Library, Page, SearchError, Weights};
use anymo_store::Store;
use serde::{Deserialize, Serialize};
use tokio::runtime::Handle;
use utoipa::{IntoParams, ToSchema};

/// What the search worker owns.
pub struct SearchWorker {
    models: SearchModels,
    library: Library,
    store: Store,
    runtime: Handle,
    signature: Option<(i64, i64)>,
}

impl SearchWorker {
    /// A worker over a library; `runtime` runs its store queries.
    pub fn new(models: SearchModels, library: Library, store: Store, runtime: Handle) -> SearchWorker {
        SearchWorker { models, library, store, runtime, signature: None }
    }

    /// Clips searchable now.
    pub fn searchable(&self) -> usize {
        self.library.len()
    }

    /// Brings the index up to date when the store's clips changed since the last look.
    pub fn refresh(&mut self) -> Result<(), ApiError> {
        let signature = self.runtime.block_on(self.store.clips_signature())?;
        if self.signature == Some(signature) {
            return Ok(());
        }
        let report = self
            .runtime
            .block_on(sync(&self.store, &mut self.library, &mut self.models, &mut |_, _| {}))
            .map_err(|e| ApiError::internal(format!("updating the search index: {e:#}")))?;
        if report.indexed + report.removed > 0 {
            tracing::info!(indexed = report.indexed, removed = report.removed, "search index synced with the store");
        }
        for problem in &report.without_motion {
            tracing::warn!("{problem}");
        }
        self.signature = Some(signature);
        Ok(())
    }
}

/// A search's filters and page, as query parameters.
#[derive(Clone, Debug, Default, Deserialize, Serialize, IntoParams, ToSchema)]
#[into_params(parameter_in = Query)]
pub struct SearchParams {
    /// Words describing the motion.
    pub q: Option<String>,
    /// Find clips that move like this stored clip (on any skeleton).
    pub like_clip: Option<i64>,
    /// Only clips under this licence (e.g. CC0-1.0).
    pub licence: Option<String>,
    /// Only clips whose subject has these words (`dog` finds husky and shiba inu dogs).
    pub subject: Option<String>,
    /// Only clips from sources starting with this (e.g. quaternius).
    pub source: Option<String>,
    /// Only clips on skeletons whose fingerprint starts with this.
    pub skeleton: Option<String>,
    /// Only clips at least this many seconds long.
    pub min_seconds: Option<f64>,
    /// Only clips at most this many seconds long.
    pub max_seconds: Option<f64>,
    /// Results per page (1 to 100, default 10).
    pub limit: Option<usize>,
    /// Results to skip (at most 1,000 deep in all).
    pub offset: Option<usize>,
}

/// One result.
#[derive(Clone, Debug, Serialize, ToSchema)]
pub struct SearchHit {
    /// 1-based rank over all pages.
    pub rank: usize,
    /// The clip's id (`GET /v1/clips/{id}`).
    pub id: i64,
    /// The clip's path in the corpus.
    pub path: String,
    /// The caption that best matches, or the first.
    pub caption: String,
    /// Byte ranges of the matched words in `caption`.
    pub highlights: Vec<[usize; 2]>,
    /// Every caption.
    pub captions: Vec<String>,
    /// Subject (species or person).
    pub subject: String,
    /// Source dataset.
    pub source: String,
    /// Licence.
    pub licence: String,
    /// Skeleton fingerprint.
    pub skeleton: String,
    /// Duration.
    pub seconds: f64,
    /// Fused score (higher is better).
    pub score: f32,
}

/// A page of results.
#[derive(Clone, Debug, Serialize, ToSchema)]
pub struct SearchPage {
    /// The results, best first.
    pub hits: Vec<SearchHit>,
    /// Candidates there are to page through.
    pub candidates: usize,
}

fn page_of(page: Page, offset: usize) -> SearchPage {
    let hits = page
        .hits
        .into_iter()
        .enumerate()
        .map(|(i, h)| {
            let d = h.document;
            let (caption, highlights) = match h.snippet {
                Some(s) => (s.text.clone(), s.highlights.iter().map(|r| [r.start, r.end]).collect()),
                None => (d.captions.first().cloned().unwrap_or_default(), Vec::new()),
            };
            SearchHit {
                rank: offset + i + 1,
                id: d.id as i64,
                path: d.path,
                caption,
                highlights,
                captions: d.captions,
                subject: d.subject,
                source: d.source,
                licence: d.licence,
                skeleton: d.skeleton,
                seconds: d.seconds,
                score: h.score,
            }
        })
        .collect();
    SearchPage { hits, candidates: page.candidates }
}

/// Searches the library by text, by example (an uploaded or stored clip) and by filters.
pub async fn search(state: &AppState, params: SearchParams, like: Option<ClipSource>) -> Result<SearchPage, ApiError> {
    let text = params.q.clone().filter(|q| !q.trim().is_empty());
    let like = like.or(params.like_clip.map(ClipSource::Stored));
    if text.is_none() && like.is_none() {
        return Err(ApiError::bad_request("give words to search for (q), an example clip (like_clip), or both"));
    }
    if text.as_ref().is_some_and(|t| t.chars().count() > super::generation::MAX_PROMPT_CHARS) {
        return Err(ApiError::over_limit("the query", super::generation::MAX_PROMPT_CHARS, "more characters"));
    }
    let example = match &like {
        Some(source) => Some(state.clip(source).await?),
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
    state
        .search
        .run(state.limits.timeout, move |worker: &mut SearchWorker| {
            worker.refresh()?;
            let query = worker
                .models
                .query(text.as_deref(), example.as_ref(), filter, Weights::default(), (offset, limit))
                .map_err(ApiError::from_model)?;
            let page = worker.library.search(&query).map_err(|e| match e {
                SearchError::Limit { .. } | SearchError::Filter(_) | SearchError::NothingToSearch => {
                    ApiError::bad_request(e.to_string())
                }
                other => ApiError::internal(other),
            })?;
            Ok(page_of(page, offset))
        })
        .await
}
