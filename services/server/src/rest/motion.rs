//! REST endpoints that make motion: generate, edit, transfer, tokenize and detokenize, and the
//! stored results. Each takes multipart/form-data (files as parts) or JSON (files as BVH text).
//! Motion is answered as BVH text, or with `Accept: application/json` as a JSON list of samples.
//! The `*Body` types are the documented shape of each body (they are read field by field).

use super::form::Form;
use crate::AppState;
use crate::auth::{Access, ApiKeys};
use crate::error::{ApiError, ErrorBody};
use crate::generation::{self, Edit, Generated, SamplingOptions};
use crate::motion::{ClipSource, SkeletonSource};
use anymo_models::quality::QualityReport;
use anymo_models::tokens::TokenFile;
use axum::extract::{Request, State};
use axum::http::{HeaderMap, HeaderValue, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use std::sync::Arc;
use utoipa::ToSchema;

/// The fields of `POST /v1/generate`.
#[derive(ToSchema)]
pub struct GenerateBody {
    /// What the motion shows, in English.
    pub prompt: String,
    /// Seconds of motion (default: the length the model predicts for the prompt).
    pub seconds: Option<f64>,
    /// The skeleton to animate: a BVH file (multipart) or its text (JSON).
    #[schema(format = Binary)]
    pub skeleton: Option<String>,
    /// Or a stored skeleton's id (`GET /v1/skeletons`).
    pub skeleton_id: Option<i64>,
    /// Samples to draw (default 1).
    pub samples: Option<u32>,
    /// Seed (default 0): the same request and seed give the same motion.
    pub seed: Option<u64>,
    /// Classifier-free guidance, 0 to 20 (default 2).
    pub guidance: Option<f32>,
    /// Temperature, 0 to 10 (default 0.7).
    pub temperature: Option<f32>,
    /// Draw among the k likeliest tokens only (default 0: all).
    pub top_k: Option<u32>,
    /// Clean up the decoded motion: light smoothing and planted feet (default true).
    pub cleanup: Option<bool>,
    /// Score the motion against the prompt in its quality report (default true; it costs one
    /// pass of the tokenizer's encoder).
    pub score: Option<bool>,
}

/// The fields of `POST /v1/edit/inpaint` and `POST /v1/edit/continue`.
#[derive(ToSchema)]
pub struct EditBody {
    /// What the new motion shows.
    pub prompt: String,
    /// The clip to edit: a BVH file (multipart) or its text (JSON).
    #[schema(format = Binary)]
    pub clip: Option<String>,
    /// Or a stored clip's id.
    pub clip_id: Option<i64>,
    /// Inpaint: start of the span to regenerate, seconds.
    pub from: Option<f64>,
    /// Inpaint: end of the span, seconds.
    pub to: Option<f64>,
    /// Continue: seconds to add.
    pub seconds: Option<f64>,
    /// Samples to draw (default 1).
    pub samples: Option<u32>,
    /// Seed (default 0).
    pub seed: Option<u64>,
    /// Classifier-free guidance, 0 to 20 (default 2).
    pub guidance: Option<f32>,
    /// Temperature, 0 to 10 (default 0.7).
    pub temperature: Option<f32>,
    /// Clean up the decoded motion: light smoothing and planted feet (default true).
    pub cleanup: Option<bool>,
    /// Score the motion against the prompt in its quality report (default true; it costs one
    /// pass of the tokenizer's encoder).
    pub score: Option<bool>,
}

/// The fields of `POST /v1/transfer`.
#[derive(ToSchema)]
pub struct TransferBody {
    /// The clip to move: a BVH file (multipart) or its text (JSON).
    #[schema(format = Binary)]
    pub clip: Option<String>,
    /// Or a stored clip's id.
    pub clip_id: Option<i64>,
    /// The skeleton to move it onto: a BVH file or its text.
    #[schema(format = Binary)]
    pub skeleton: Option<String>,
    /// Or a stored skeleton's id.
    pub skeleton_id: Option<i64>,
    /// Clean up the decoded motion: light smoothing and planted feet (default true).
    pub cleanup: Option<bool>,
}

/// The fields of `POST /v1/tokenize`.
#[derive(ToSchema)]
pub struct TokenizeBody {
    /// The clip: a BVH file (multipart) or its text (JSON).
    #[schema(format = Binary)]
    pub clip: Option<String>,
    /// Or a stored clip's id.
    pub clip_id: Option<i64>,
}

/// The fields of `POST /v1/detokenize`.
#[derive(ToSchema)]
pub struct DetokenizeBody {
    /// The tokens, as `POST /v1/tokenize` or `anymo tokenize` wrote them (JSON).
    #[schema(value_type = Object)]
    pub tokens: serde_json::Value,
    /// The skeleton to animate: a BVH file or its text.
    #[schema(format = Binary)]
    pub skeleton: Option<String>,
    /// Or a stored skeleton's id.
    pub skeleton_id: Option<i64>,
    /// Clean up the decoded motion: light smoothing and planted feet (default true).
    pub cleanup: Option<bool>,
}

/// One sample of a result.
#[derive(Serialize, ToSchema)]
pub struct Sample {
    /// Its index among the result's samples.
    pub index: usize,
    /// The stored result it belongs to.
    pub generation_id: i64,
    /// Frames.
    pub frames: usize,
    /// Frames per second.
    pub fps: f64,
    /// Where to fetch it again.
    pub url: String,
    /// The BVH text.
    pub bvh: String,
    /// How plausible the motion is: foot skating, foot flight, jitter against real clips of
    /// the skeleton, and for generated motion its score against the prompt.
    pub quality: QualityReport,
}

/// The sampling fields of a form.
fn sampling(form: &Form) -> Result<SamplingOptions, ApiError> {
    Ok(SamplingOptions {
        samples: form.number("samples")?,
        seed: form.number("seed")?,
        guidance: form.number("guidance")?,
        temperature: form.number("temperature")?,
        top_k: form.number("top_k")?,
        cleanup: form.flag("cleanup")?,
        score: form.flag("score")?,
    })
}

/// The skeleton a form names: an uploaded file (`file_field`) or a stored id.
fn skeleton_source(form: &Form, file_field: &str) -> Result<SkeletonSource, ApiError> {
    match (form.bytes(file_field), form.number::<i64>("skeleton_id")?) {
        (Some(_), Some(_)) => Err(ApiError::bad_request(format!("send {file_field} or skeleton_id, not both"))),
        (Some(bytes), None) => Ok(SkeletonSource::Bvh(bytes.to_vec())),
        (None, Some(id)) => Ok(SkeletonSource::Stored(id)),
        (None, None) => {
            Err(ApiError::bad_request(format!("send the skeleton: a BVH file as {file_field}, or skeleton_id")))
        }
    }
}

/// The clip a form names: an uploaded file (`clip`) or a stored id (`clip_id`).
fn clip_source(form: &Form) -> Result<ClipSource, ApiError> {
    match (form.bytes("clip"), form.number::<i64>("clip_id")?) {
        (Some(_), Some(_)) => Err(ApiError::bad_request("send clip or clip_id, not both")),
        (Some(bytes), None) => Ok(ClipSource::Bvh(bytes.to_vec())),
        (None, Some(id)) => Ok(ClipSource::Stored(id)),
        (None, None) => Err(ApiError::bad_request("send the clip: a BVH file as clip, or clip_id")),
    }
}

/// True when the client asked for JSON.
fn wants_json(headers: &HeaderMap) -> bool {
    headers.get(header::ACCEPT).and_then(|v| v.to_str().ok()).is_some_and(|a| a.contains("application/json"))
}

/// A result as the client asked: the first sample's BVH text (with the result's id, where its
/// samples are and the first sample's quality report as JSON in headers), or every sample as
/// JSON.
pub fn answer(generated: Generated, json: bool) -> Response {
    let location = format!("/v1/generations/{}", generated.id);
    let mut response = if json {
        let samples: Vec<Sample> = generated
            .samples
            .into_iter()
            .zip(generated.quality)
            .enumerate()
            .map(|(index, (bvh, quality))| Sample {
                index,
                generation_id: generated.id,
                frames: generated.frames,
                fps: generated.fps,
                url: format!("{location}/samples/{index}"),
                bvh,
                quality,
            })
            .collect();
        axum::Json(samples).into_response()
    } else {
        let count = generated.samples.len();
        let report =
            generated.quality.first().map(|q| ascii_json(&serde_json::to_string(q).expect("a report serialises")));
        let first = generated.samples.into_iter().next().unwrap_or_default();
        let mut response = ([(header::CONTENT_TYPE, "text/plain; charset=utf-8")], first).into_response();
        let headers = response.headers_mut();
        headers.insert("x-samples", count.into());
        if let Some(report) = report {
            headers.insert("x-quality", HeaderValue::from_str(&report).expect("ASCII JSON"));
        }
        let disposition = format!("attachment; filename=\"generation-{}.bvh\"", generated.id);
        headers.insert(header::CONTENT_DISPOSITION, HeaderValue::from_str(&disposition).expect("ASCII"));
        response
    };
    let headers = response.headers_mut();
    headers.insert("x-generation-id", generated.id.into());
    headers.insert(header::LOCATION, HeaderValue::from_str(&location).expect("ASCII"));
    response
}

/// JSON text with every character outside ASCII written as a `\u` escape (a surrogate pair
/// beyond the first plane), so it can travel in a header: JSON parsers read it as the same text.
fn ascii_json(json: &str) -> String {
    let mut out = String::with_capacity(json.len());
    for c in json.chars() {
        if c.is_ascii() {
            out.push(c);
        } else {
            let mut units = [0u16; 2];
            for unit in c.encode_utf16(&mut units) {
                out.push_str(&format!("\\u{unit:04x}"));
            }
        }
    }
    out
}

/// Motion from a prompt on any skeleton.
#[utoipa::path(
    post, path = "/v1/generate", tag = "motion",
    request_body(content(
        (GenerateBody = "multipart/form-data"),
        (GenerateBody = "application/json"),
    )),
    responses(
        (status = 200, description = "The first sample's BVH text (headers: X-Generation-Id, X-Samples, Location, and X-Quality: its quality report as JSON); with Accept: application/json, every sample with its report", content(
            (String = "text/plain"),
            (Vec<Sample> = "application/json"),
        )),
        (status = 400, description = "Malformed request or BVH (the message names the line)", body = ErrorBody),
        (status = 401, description = "A key is needed", body = ErrorBody),
        (status = 404, description = "No such stored skeleton", body = ErrorBody),
        (status = 413, description = "Body over the limit", body = ErrorBody),
        (status = 422, description = "Over a limit, or the skeleton cannot be animated", body = ErrorBody),
        (status = 429, description = "The generation queue is full", body = ErrorBody),
        (status = 503, description = "Timed out or unavailable", body = ErrorBody),
    ),
    security((), ("api_key" = [])),
)]
pub async fn generate(State(state): State<Arc<AppState>>, request: Request) -> Result<Response, ApiError> {
    let json = wants_json(request.headers());
    let check = |headers: &HeaderMap| state.keys.check(Access::Generate, ApiKeys::presented(headers));
    let form = Form::read_if(request, state.limits.body_bytes, check).await?;
    let prompt = form.required_text("prompt")?;
    let seconds = form.number("seconds")?;
    let generated =
        generation::generate(&state, prompt, seconds, skeleton_source(&form, "skeleton")?, sampling(&form)?).await?;
    Ok(answer(generated, json))
}

async fn edit_with(state: Arc<AppState>, request: Request, inpaint: bool) -> Result<Response, ApiError> {
    let json = wants_json(request.headers());
    let check = |headers: &HeaderMap| state.keys.check(Access::Generate, ApiKeys::presented(headers));
    let form = Form::read_if(request, state.limits.body_bytes, check).await?;
    let prompt = form.required_text("prompt")?;
    let required = |name: &str| {
        form.number::<f64>(name)?.ok_or_else(|| ApiError::bad_request(format!("the field {name} is missing")))
    };
    let edit = if inpaint {
        Edit::Inpaint { from: required("from")?, to: required("to")? }
    } else {
        Edit::Continue { seconds: required("seconds")? }
    };
    let generated = generation::edit(&state, clip_source(&form)?, prompt, edit, sampling(&form)?).await?;
    Ok(answer(generated, json))
}

/// A clip with a span regenerated from a prompt, the rest kept.
#[utoipa::path(
    post, path = "/v1/edit/inpaint", tag = "motion",
    request_body(content((EditBody = "multipart/form-data"), (EditBody = "application/json"))),
    responses(
        (status = 200, description = "The edited clip's BVH text, or every sample as JSON", content(
            (String = "text/plain"), (Vec<Sample> = "application/json"),
        )),
        (status = 400, description = "Malformed request or BVH", body = ErrorBody),
        (status = 404, description = "No such stored clip", body = ErrorBody),
        (status = 422, description = "Over a limit, or the clip cannot be used", body = ErrorBody),
        (status = 429, description = "The generation queue is full", body = ErrorBody),
    ),
    security((), ("api_key" = [])),
)]
pub async fn inpaint(State(state): State<Arc<AppState>>, request: Request) -> Result<Response, ApiError> {
    edit_with(state, request, true).await
}

/// A clip continued by new motion from a prompt.
#[utoipa::path(
    post, path = "/v1/edit/continue", tag = "motion",
    request_body(content((EditBody = "multipart/form-data"), (EditBody = "application/json"))),
    responses(
        (status = 200, description = "The continued clip's BVH text, or every sample as JSON", content(
            (String = "text/plain"), (Vec<Sample> = "application/json"),
        )),
        (status = 400, description = "Malformed request or BVH", body = ErrorBody),
        (status = 404, description = "No such stored clip", body = ErrorBody),
        (status = 422, description = "Over a limit, or the clip cannot be used", body = ErrorBody),
        (status = 429, description = "The generation queue is full", body = ErrorBody),
    ),
    security((), ("api_key" = [])),
)]
pub async fn extend(State(state): State<Arc<AppState>>, request: Request) -> Result<Response, ApiError> {
    edit_with(state, request, false).await
}

/// A clip moved onto another skeleton, through tokens.
#[utoipa::path(
    post, path = "/v1/transfer", tag = "motion",
    request_body(content((TransferBody = "multipart/form-data"), (TransferBody = "application/json"))),
    responses(
        (status = 200, description = "The moved clip's BVH text on the target skeleton", content(
            (String = "text/plain"), (Vec<Sample> = "application/json"),
        )),
        (status = 400, description = "Malformed request or BVH", body = ErrorBody),
        (status = 404, description = "No such stored clip or skeleton", body = ErrorBody),
        (status = 422, description = "Over a limit, or the clip cannot be used", body = ErrorBody),
        (status = 429, description = "The generation queue is full", body = ErrorBody),
    ),
)]
pub async fn transfer(State(state): State<Arc<AppState>>, request: Request) -> Result<Response, ApiError> {
    let json = wants_json(request.headers());
    let form = Form::read(request, state.limits.body_bytes).await?;
    let (clip, to) = (clip_source(&form)?, skeleton_source(&form, "skeleton")?);
    let generated = generation::transfer(&state, clip, to, form.flag("cleanup")?).await?;
    Ok(answer(generated, json))
}

/// A clip as TAT tokens (they carry no skeleton: any skeleton can decode them).
#[utoipa::path(
    post, path = "/v1/tokenize", tag = "motion",
    request_body(content((TokenizeBody = "multipart/form-data"), (TokenizeBody = "application/json"))),
    responses(
        (status = 200, description = "The tokens file", body = Object),
        (status = 400, description = "Malformed request or BVH", body = ErrorBody),
        (status = 404, description = "No such stored clip", body = ErrorBody),
        (status = 422, description = "Over a limit, or the clip cannot be used", body = ErrorBody),
        (status = 429, description = "The generation queue is full", body = ErrorBody),
    ),
)]
pub async fn tokenize(State(state): State<Arc<AppState>>, request: Request) -> Result<axum::Json<TokenFile>, ApiError> {
    let form = Form::read(request, state.limits.body_bytes).await?;
    Ok(axum::Json(generation::tokenize(&state, clip_source(&form)?).await?))
}

/// Tokens as motion on a skeleton.
#[utoipa::path(
    post, path = "/v1/detokenize", tag = "motion",
    request_body(content((DetokenizeBody = "multipart/form-data"), (DetokenizeBody = "application/json"))),
    responses(
        (status = 200, description = "The motion's BVH text on the skeleton", content(
            (String = "text/plain"), (Vec<Sample> = "application/json"),
        )),
        (status = 400, description = "Malformed request, tokens or BVH", body = ErrorBody),
        (status = 404, description = "No such stored skeleton", body = ErrorBody),
        (status = 422, description = "Tokens that do not fit the tokenizer, or over a limit", body = ErrorBody),
        (status = 429, description = "The generation queue is full", body = ErrorBody),
    ),
)]
pub async fn detokenize(State(state): State<Arc<AppState>>, request: Request) -> Result<Response, ApiError> {
    let json = wants_json(request.headers());
    let form = Form::read(request, state.limits.body_bytes).await?;
    let tokens = form.bytes("tokens").ok_or_else(|| ApiError::bad_request("the field tokens is missing"))?;
    let tokens: TokenFile = serde_json::from_slice(tokens)
        .map_err(|e| ApiError::bad_request(format!("tokens is not a tokens file from /v1/tokenize: {e}")))?;
    let to = skeleton_source(&form, "skeleton")?;
    let generated = generation::detokenize(&state, tokens, to, form.flag("cleanup")?).await?;
    Ok(answer(generated, json))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_in_a_header_is_ascii_and_reads_back_the_same() {
        let value = serde_json::json!({ "subject": "chien élégant 🐕", "jitter": 1.5 });
        let text = ascii_json(&value.to_string());
        assert!(text.is_ascii() && HeaderValue::from_str(&text).is_ok(), "{text}");
        assert!(text.contains("\\u00e9") && text.contains("\\ud83d\\udc15"), "{text}");
        assert_eq!(serde_json::from_str::<serde_json::Value>(&text).unwrap(), value);
    }
}
