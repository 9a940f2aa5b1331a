//! Health, readiness and metrics.

use crate::AppState;
use crate::error::{ApiError, ErrorBody};
use axum::extract::State;
use axum::http::header;
use axum::response::IntoResponse;
use serde::Serialize;
use std::sync::Arc;
use utoipa::ToSchema;

/// What `GET /v1/health` says.
#[derive(Serialize, ToSchema)]
pub struct Health {
    /// `ok`.
    pub status: String,
    /// The server's version.
    pub version: String,
    /// Clips in the store.
    pub clips: i64,
    /// Requests a generation worker is running.
    pub generation_running: usize,
    /// Requests waiting for a generation worker.
    pub generation_waiting: usize,
    /// Search jobs waiting for the search models' thread.
    pub search_waiting: usize,
    /// What one request may ask (so a client can offer only what will be accepted).
    pub limits: LimitsView,
}

/// The limits a client sees.
#[derive(Serialize, ToSchema)]
pub struct LimitsView {
    /// Longest motion to generate, in seconds.
    pub seconds: f64,
    /// Most samples one generation may draw.
    pub samples: usize,
    /// Largest request body, in bytes.
    pub body_bytes: usize,
    /// Most joints a skeleton may have.
    pub joints: usize,
    /// Most frames an uploaded clip may have.
    pub frames: usize,
}

/// The server is up and its store answers.
#[utoipa::path(
    get, path = "/v1/health", tag = "system",
    responses((status = 200, description = "Up", body = Health), (status = 503, description = "The store does not answer", body = ErrorBody)),
)]
pub async fn health(State(state): State<Arc<AppState>>) -> Result<axum::Json<Health>, ApiError> {
    let (clips, _) = state.store.clips_signature().await?;
    Ok(axum::Json(Health {
        status: "ok".into(),
        version: env!("CARGO_PKG_VERSION").into(),
        clips,
        generation_running: state.generation.active(),
        generation_waiting: state.generation.waiting(),
        search_waiting: state.search.waiting(),
        limits: LimitsView {
            seconds: state.limits.seconds,
            samples: state.limits.samples,
            body_bytes: state.limits.body_bytes,
            joints: state.limits.joints,
            frames: state.limits.frames,
        },
    }))
}

/// The server can take work: the store answers and the generation queue has room.
#[utoipa::path(
    get, path = "/v1/ready", tag = "system",
    responses((status = 200, description = "Ready", body = Health), (status = 503, description = "Not ready, and why", body = ErrorBody)),
)]
pub async fn ready(State(state): State<Arc<AppState>>) -> Result<axum::Json<Health>, ApiError> {
    state.store.ping().await.map_err(|e| ApiError::unavailable(format!("the store does not answer: {e}")))?;
    if state.generation.waiting() >= state.limits.queue {
        return Err(ApiError::unavailable("the generation queue is full"));
    }
    health(State(state)).await
}

/// Prometheus metrics (text format).
#[utoipa::path(
    get, path = "/metrics", tag = "system",
    responses((status = 200, description = "Metrics in Prometheus' text format", body = String, content_type = "text/plain")),
)]
pub async fn metrics(State(state): State<Arc<AppState>>) -> impl IntoResponse {
    let text = state.metrics.render(&[("generation", state.generation.waiting()), ("search", state.search.waiting())]);
    ([(header::CONTENT_TYPE, "application/openmetrics-text; version=1.0.0; charset=utf-8")], text)
}
