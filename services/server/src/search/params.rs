//! What a search asks and what it answers: the request's filters and page, and the page of
//! results with each clip's details and matched words.

use anymo_retrieval::Page;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

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

impl SearchPage {
    /// The library's page as answered, ranks counted from `offset`.
    pub fn new(page: Page, offset: usize) -> SearchPage {
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
}
