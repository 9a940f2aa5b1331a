//! REST endpoints over the motion library: search, the corpus (clips, skeletons, counts),
//! ingest uploads and their jobs, and stored generation results. Path parameters are typed ids:
//! they select rows in the store and never name files.

use super::form::Form;
use crate::AppState;
use crate::auth::{Access, ApiKeys};
use crate::error::{ApiError, ErrorBody};
use crate::jobs::{IngestParams, JobView, accept_ingest};
use crate::motion::ClipSource;
use crate::search::{SearchPage, SearchParams, search};
use anymo_store::{ClipRow, JobFile, SkeletonRow};
use axum::extract::rejection::{PathRejection, QueryRejection};
use axum::extract::{FromRequestParts, Path, Query, Request, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use utoipa::{IntoParams, ToSchema};

impl From<PathRejection> for ApiError {
    fn from(rejection: PathRejection) -> ApiError {
        ApiError::not_found(format!("no such resource: {}", rejection.body_text()))
    }
}

impl From<QueryRejection> for ApiError {
    fn from(rejection: QueryRejection) -> ApiError {
        ApiError::bad_request(rejection.body_text())
    }
}

/// Path parameters, refused as JSON errors.
#[derive(FromRequestParts)]
#[from_request(via(Path), rejection(ApiError))]
pub struct Ids<T>(pub T);

/// Query parameters, refused as JSON errors.
#[derive(FromRequestParts)]
#[from_request(via(Query), rejection(ApiError))]
pub struct Params<T>(pub T);

/// A stored clip.
#[derive(Serialize, ToSchema)]
pub struct ClipView {
    /// Id.
    pub id: i64,
    /// Path in the corpus.
    pub path: String,
    /// Its skeleton's id.
    pub skeleton_id: i64,
    /// Source dataset.
    pub source: String,
    /// Licence.
    pub licence: String,
    /// Subject.
    pub subject: String,
    /// Frames per second.
    pub fps: f64,
    /// Frames.
    pub frames: i64,
    /// Duration.
    pub seconds: f64,
    /// Dataset split (train, test, zero-shot).
    pub split: String,
    /// Captions.
    pub captions: Vec<String>,
    /// Where its BVH is.
    pub bvh_url: String,
}

impl From<ClipRow> for ClipView {
    fn from(c: ClipRow) -> ClipView {
        ClipView {
            bvh_url: format!("/v1/clips/{}/bvh", c.id),
            seconds: c.frames as f64 / c.fps.max(1e-9),
            id: c.id,
            path: c.source_path,
            skeleton_id: c.skeleton_id,
            source: c.source,
            licence: c.licence,
            subject: c.subject,
            fps: c.fps,
            frames: c.frames,
            split: c.split,
            captions: c.captions,
        }
    }
}

/// A stored skeleton.
#[derive(Serialize, ToSchema)]
pub struct SkeletonView {
    /// Id.
    pub id: i64,
    /// Topology fingerprint (a search filter).
    pub fingerprint: String,
    /// Joints.
    pub joints: i64,
    /// Clips on it.
    pub clips: i64,
    /// Each joint's semantic label.
    pub labels: Vec<String>,
    /// The sources of its clips.
    pub sources: Vec<String>,
    /// The subjects of its clips (`person`, `horse`, ...).
    pub subjects: Vec<String>,
    /// Where its skeleton-only BVH is.
    pub bvh_url: String,
}

impl From<SkeletonRow> for SkeletonView {
    fn from(s: SkeletonRow) -> SkeletonView {
        SkeletonView {
            bvh_url: format!("/v1/skeletons/{}/bvh", s.id),
            id: s.id,
            fingerprint: s.fingerprint,
            joints: s.joint_count,
            clips: s.clips,
            labels: s.labels,
            sources: s.sources,
            subjects: s.subjects,
        }
    }
}

/// A page of clips.
#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct ClipPage {
    /// Clips with ids above this (default 0: from the start).
    pub after: Option<i64>,
    /// Clips per page, 1 to 500 (default 50).
    pub limit: Option<i64>,
}

/// The corpus in counts.
#[derive(Serialize, ToSchema)]
pub struct StatsView {
    /// Clips.
    pub clips: i64,
    /// Distinct skeletons.
    pub skeletons: i64,
    /// Captions.
    pub captions: i64,
    /// `[group, name, clips, frames]` rows for groups source, licence, subject, split, skeleton.
    pub groups: Vec<(String, String, i64, i64)>,
}

fn bvh_response(bytes: Vec<u8>, name: &str) -> Response {
    let disposition = format!("attachment; filename=\"{name}.bvh\"");
    (
        [(header::CONTENT_TYPE, "text/plain; charset=utf-8".to_string()), (header::CONTENT_DISPOSITION, disposition)],
        bytes,
    )
        .into_response()
}

/// Search the library by text and filters, or by a stored example clip.
#[utoipa::path(
    get, path = "/v1/search", tag = "library", params(SearchParams),
    responses(
        (status = 200, description = "A page of results", body = SearchPage),
        (status = 400, description = "Nothing to search by, or a page outside the limits", body = ErrorBody),
        (status = 404, description = "No such example clip", body = ErrorBody),
        (status = 429, description = "The search queue is full", body = ErrorBody),
    ),
)]
pub async fn search_get(
    State(state): State<Arc<AppState>>,
    Params(params): Params<SearchParams>,
) -> Result<axum::Json<SearchPage>, ApiError> {
    Ok(axum::Json(search(&state, params, None).await?))
}

/// The fields of `POST /v1/search`: the query parameters of `GET /v1/search`, plus an example.
#[derive(ToSchema)]
pub struct SearchBody {
    /// Words describing the motion.
    pub q: Option<String>,
    /// Find clips that move like this BVH clip (on any skeleton).
    #[schema(format = Binary)]
    pub like: Option<String>,
    /// Only this licence.
    pub licence: Option<String>,
    /// Only subjects with these words.
    pub subject: Option<String>,
    /// Only sources starting with this.
    pub source: Option<String>,
    /// Results per page (1 to 100).
    pub limit: Option<u32>,
    /// Results to skip.
    pub offset: Option<u32>,
}

/// Search the library by an uploaded example clip (and text and filters).
#[utoipa::path(
    post, path = "/v1/search", tag = "library",
    request_body(content((SearchBody = "multipart/form-data"), (SearchBody = "application/json"))),
    responses(
        (status = 200, description = "A page of results", body = SearchPage),
        (status = 400, description = "Nothing to search by, a malformed clip or page", body = ErrorBody),
        (status = 422, description = "The example clip cannot be used", body = ErrorBody),
        (status = 429, description = "The search queue is full", body = ErrorBody),
    ),
)]
pub async fn search_post(
    State(state): State<Arc<AppState>>,
    request: Request,
) -> Result<axum::Json<SearchPage>, ApiError> {
    let form = Form::read(request, state.limits.body_bytes).await?;
    let params = SearchParams {
        q: form.text("q")?,
        like_clip: form.number("like_clip")?,
        licence: form.text("licence")?,
        subject: form.text("subject")?,
        source: form.text("source")?,
        skeleton: form.text("skeleton")?,
        min_seconds: form.number("min_seconds")?,
        max_seconds: form.number("max_seconds")?,
        limit: form.number("limit")?,
        offset: form.number("offset")?,
    };
    let like = form.bytes("like").map(|b| ClipSource::Bvh(b.to_vec()));
    Ok(axum::Json(search(&state, params, like).await?))
}

/// A page of stored clips, by ascending id.
#[utoipa::path(
    get, path = "/v1/clips", tag = "corpus", params(ClipPage),
    responses((status = 200, description = "Clips", body = Vec<ClipView>), (status = 400, description = "A bad page", body = ErrorBody)),
)]
pub async fn list_clips(
    State(state): State<Arc<AppState>>,
    Params(page): Params<ClipPage>,
) -> Result<axum::Json<Vec<ClipView>>, ApiError> {
    let limit = page.limit.unwrap_or(50);
    if !(1..=500).contains(&limit) {
        return Err(ApiError::bad_request(format!("limit must be between 1 and 500; {limit} was asked")));
    }
    let clips = state.store.list_clips(page.after.unwrap_or(0), limit).await?;
    Ok(axum::Json(clips.into_iter().map(ClipView::from).collect()))
}

/// One stored clip.
#[utoipa::path(
    get, path = "/v1/clips/{id}", tag = "corpus", params(("id" = i64, Path, description = "Clip id")),
    responses((status = 200, description = "The clip", body = ClipView), (status = 404, description = "No such clip", body = ErrorBody)),
)]
pub async fn get_clip(State(state): State<Arc<AppState>>, Ids(id): Ids<i64>) -> Result<axum::Json<ClipView>, ApiError> {
    let clip = state.store.clip(id).await?.ok_or_else(|| ApiError::not_found(format!("no clip {id}")))?;
    Ok(axum::Json(clip.into()))
}

/// Delete a stored clip (needs an API key).
#[utoipa::path(
    delete, path = "/v1/clips/{id}", tag = "corpus", params(("id" = i64, Path, description = "Clip id")),
    responses(
        (status = 204, description = "Deleted"),
        (status = 401, description = "A valid API key is needed", body = ErrorBody),
        (status = 404, description = "No such clip", body = ErrorBody),
    ),
    security(("api_key" = [])),
)]
pub async fn delete_clip(
    State(state): State<Arc<AppState>>,
    headers: HeaderMap,
    Ids(id): Ids<i64>,
) -> Result<StatusCode, ApiError> {
    state.keys.check(Access::Write, ApiKeys::presented(&headers))?;
    if state.store.delete_clip(id).await? {
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(ApiError::not_found(format!("no clip {id}")))
    }
}

/// A stored clip's BVH, exactly as ingested.
#[utoipa::path(
    get, path = "/v1/clips/{id}/bvh", tag = "corpus", params(("id" = i64, Path, description = "Clip id")),
    responses((status = 200, description = "BVH text", body = String, content_type = "text/plain"), (status = 404, description = "No such clip", body = ErrorBody)),
)]
pub async fn clip_bvh(State(state): State<Arc<AppState>>, Ids(id): Ids<i64>) -> Result<Response, ApiError> {
    let bytes = state.store.clip_bvh(id).await?.ok_or_else(|| ApiError::not_found(format!("no clip {id}")))?;
    Ok(bvh_response(bytes, &format!("clip-{id}")))
}

/// The stored skeletons.
#[utoipa::path(
    get, path = "/v1/skeletons", tag = "corpus",
    responses((status = 200, description = "Skeletons", body = Vec<SkeletonView>)),
)]
pub async fn list_skeletons(State(state): State<Arc<AppState>>) -> Result<axum::Json<Vec<SkeletonView>>, ApiError> {
    Ok(axum::Json(state.store.skeletons().await?.into_iter().map(SkeletonView::from).collect()))
}

/// One stored skeleton.
#[utoipa::path(
    get, path = "/v1/skeletons/{id}", tag = "corpus", params(("id" = i64, Path, description = "Skeleton id")),
    responses((status = 200, description = "The skeleton", body = SkeletonView), (status = 404, description = "No such skeleton", body = ErrorBody)),
)]
pub async fn get_skeleton(
    State(state): State<Arc<AppState>>,
    Ids(id): Ids<i64>,
) -> Result<axum::Json<SkeletonView>, ApiError> {
    let skeleton = state.store.skeleton(id).await?.ok_or_else(|| ApiError::not_found(format!("no skeleton {id}")))?;
    Ok(axum::Json(skeleton.into()))
}

/// A stored skeleton as a skeleton-only BVH (upload it to generate on it elsewhere).
#[utoipa::path(
    get, path = "/v1/skeletons/{id}/bvh", tag = "corpus", params(("id" = i64, Path, description = "Skeleton id")),
    responses((status = 200, description = "BVH text", body = String, content_type = "text/plain"), (status = 404, description = "No such skeleton", body = ErrorBody)),
)]
pub async fn skeleton_bvh(State(state): State<Arc<AppState>>, Ids(id): Ids<i64>) -> Result<Response, ApiError> {
    let skeleton = state.store.skeleton(id).await?.ok_or_else(|| ApiError::not_found(format!("no skeleton {id}")))?;
    Ok(bvh_response(skeleton.hierarchy.into_bytes(), &format!("skeleton-{id}")))
}

/// The corpus in counts.
#[utoipa::path(get, path = "/v1/stats", tag = "corpus", responses((status = 200, description = "Counts", body = StatsView)))]
pub async fn stats(State(state): State<Arc<AppState>>) -> Result<axum::Json<StatsView>, ApiError> {
    let s = state.store.stats().await?;
    Ok(axum::Json(StatsView { clips: s.clips, skeletons: s.skeletons, captions: s.captions, groups: s.groups }))
}

/// The fields of `POST /v1/ingest`.
#[derive(ToSchema)]
pub struct IngestBody {
    /// BVH files (`.bvh` or `.bvh.gz`), any number of parts named `files`; a `.txt` part with
    /// the same stem holds a file's captions, one per line.
    #[schema(value_type = Vec<String>, format = Binary)]
    pub files: Vec<String>,
    /// Source dataset of every clip (default `upload`).
    pub source: Option<String>,
    /// Licence of every clip (default `unknown`).
    pub licence: Option<String>,
    /// Subject of every clip (default `unknown`).
    pub subject: Option<String>,
}

/// The stem of an uploaded file name: without `.bvh.gz`, `.bvh` or `.txt`.
fn stem(name: &str) -> (&str, bool) {
    for (suffix, motion) in [(".bvh.gz", true), (".bvh", true), (".txt", false)] {
        if let Some(s) = name.strip_suffix(suffix) {
            return (s, motion);
        }
    }
    (name, true)
}

/// Upload clips to ingest (needs an API key). The upload is stored before the answer, and a
/// job ingests it: follow `GET /v1/jobs/{id}`.
#[utoipa::path(
    post, path = "/v1/ingest", tag = "corpus",
    request_body(content = IngestBody, content_type = "multipart/form-data"),
    responses(
        (status = 202, description = "Accepted: the job", body = JobView),
        (status = 400, description = "No files, or a malformed BVH (the message names the file and line)", body = ErrorBody),
        (status = 401, description = "A valid API key is needed", body = ErrorBody),
        (status = 413, description = "Body over the limit", body = ErrorBody),
        (status = 422, description = "Over a limit", body = ErrorBody),
    ),
    security(("api_key" = [])),
)]
pub async fn ingest(State(state): State<Arc<AppState>>, request: Request) -> Result<Response, ApiError> {
    let check = |headers: &HeaderMap| state.keys.check(Access::Write, ApiKeys::presented(headers));
    let form = Form::read_if(request, state.limits.body_bytes, check).await?;
    let mut files: Vec<JobFile> = Vec::new();
    let mut captions: Vec<(String, Vec<String>)> = Vec::new();
    for (name, part) in form.parts().iter().filter(|(n, _)| n == "files") {
        let file_name = part.file_name.clone().unwrap_or_else(|| format!("{name}-{}.bvh", files.len() + 1));
        let (stem, motion) = stem(&file_name);
        if motion {
            files.push(JobFile { name: file_name.clone(), captions: Vec::new(), bytes: part.bytes.clone() });
        } else {
            let text = String::from_utf8_lossy(&part.bytes);
            captions.push((
                stem.to_string(),
                text.lines().map(str::trim).filter(|l| !l.is_empty()).map(String::from).collect(),
            ));
        }
    }
    for (caption_stem, lines) in captions {
        match files.iter_mut().find(|f| stem(&f.name).0 == caption_stem) {
            Some(file) => file.captions = lines,
            None => return Err(ApiError::bad_request(format!("{caption_stem}.txt has no .bvh file of the same name"))),
        }
    }
    let params = IngestParams {
        source: form.text("source")?.unwrap_or_default(),
        licence: form.text("licence")?.unwrap_or_default(),
        subject: form.text("subject")?.unwrap_or_default(),
    };
    let job = accept_ingest(&state, params, files).await?;
    let location = format!("/v1/jobs/{}", job.id);
    Ok((StatusCode::ACCEPTED, [(header::LOCATION, location)], axum::Json(job)).into_response())
}

/// A job's status and progress.
#[utoipa::path(
    get, path = "/v1/jobs/{id}", tag = "corpus", params(("id" = i64, Path, description = "Job id")),
    responses((status = 200, description = "The job", body = JobView), (status = 404, description = "No such job", body = ErrorBody)),
)]
pub async fn get_job(State(state): State<Arc<AppState>>, Ids(id): Ids<i64>) -> Result<axum::Json<JobView>, ApiError> {
    let job = state.store.job(id).await?.ok_or_else(|| ApiError::not_found(format!("no job {id}")))?;
    Ok(axum::Json(job.into()))
}

/// A stored result.
#[derive(Serialize, ToSchema)]
pub struct GenerationView {
    /// Id.
    pub id: i64,
    /// What made it: generate, inpaint, continue, transfer or detokenize.
    pub kind: String,
    /// The request.
    #[schema(value_type = Object)]
    pub request: serde_json::Value,
    /// Frames of each sample.
    pub frames: i64,
    /// Frames per second.
    pub fps: f64,
    /// Where each sample's BVH is.
    pub samples: Vec<String>,
    /// Each sample's quality report (absent for results stored before reports).
    pub quality: Option<Vec<anymo_models::quality::QualityReport>>,
    /// When it was made (ms since the epoch).
    pub created_ms: i64,
}

/// A stored result's record.
#[utoipa::path(
    get, path = "/v1/generations/{id}", tag = "motion", params(("id" = i64, Path, description = "Result id")),
    responses((status = 200, description = "The result", body = GenerationView), (status = 404, description = "No such result", body = ErrorBody)),
)]
pub async fn get_generation(
    State(state): State<Arc<AppState>>,
    Ids(id): Ids<i64>,
) -> Result<axum::Json<GenerationView>, ApiError> {
    let g = state.store.generation(id).await?.ok_or_else(|| ApiError::not_found(format!("no result {id}")))?;
    Ok(axum::Json(GenerationView {
        samples: (0..g.samples).map(|k| format!("/v1/generations/{id}/samples/{k}")).collect(),
        id: g.id,
        kind: g.kind,
        request: g.request,
        frames: g.frames,
        fps: g.fps,
        quality: g.quality.and_then(|q| serde_json::from_value(q).ok()),
        created_ms: g.created_ms,
    }))
}

/// One sample of a stored result, as BVH.
#[utoipa::path(
    get, path = "/v1/generations/{id}/samples/{index}", tag = "motion",
    params(("id" = i64, Path, description = "Result id"), ("index" = i64, Path, description = "Sample index, from 0")),
    responses((status = 200, description = "BVH text", body = String, content_type = "text/plain"), (status = 404, description = "No such sample", body = ErrorBody)),
)]
pub async fn generation_sample(
    State(state): State<Arc<AppState>>,
    Ids((id, index)): Ids<(i64, i64)>,
) -> Result<Response, ApiError> {
    let bytes = state
        .store
        .generation_sample(id, index)
        .await?
        .ok_or_else(|| ApiError::not_found(format!("no sample {index} of result {id}")))?;
    Ok(bvh_response(bytes, &format!("generation-{id}-{index}")))
}
