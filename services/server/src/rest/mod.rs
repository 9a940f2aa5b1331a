//! The REST API under `/v1`, its OpenAPI 3 document at `/openapi.json` and a docs page at
//! `/docs`, with the limits, timeout and metrics every request goes through.

pub mod form;
pub mod library;
pub mod motion;
pub mod system;

use super::AppState;
use super::error::ApiError;
use axum::Router;
use axum::extract::{DefaultBodyLimit, MatchedPath, Request, State};
use axum::middleware::Next;
use axum::response::Response;
use std::sync::Arc;
use std::time::Instant;
use utoipa::openapi::security::{ApiKey, ApiKeyValue, HttpAuthScheme, HttpBuilder, SecurityScheme};
use utoipa::{Modify, OpenApi};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

#[derive(OpenApi)]
#[openapi(
    info(
        title = "anymo",
        description = "Motion for any skeleton: text to motion, editing, transfer, tokens, search and the corpus. \
                       Errors are JSON: {\"error\": {\"code\", \"message\"}}.",
    ),
    modifiers(&Keys),
    tags(
        (name = "motion", description = "Generate, edit, transfer and tokenize motion"),
        (name = "library", description = "Search the motion library"),
        (name = "corpus", description = "Clips, skeletons, ingest and jobs"),
        (name = "system", description = "Health, readiness and metrics"),
    ),
)]
struct ApiDoc;

/// The API key schemes: a bearer token or an `X-Api-Key` header.
struct Keys;

impl Modify for Keys {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        let components = openapi.components.get_or_insert_with(Default::default);
        components
            .add_security_scheme("api_key", SecurityScheme::ApiKey(ApiKey::Header(ApiKeyValue::new("x-api-key"))));
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()),
        );
    }
}

/// The REST routes and their OpenAPI document.
pub fn router(state: Arc<AppState>) -> (Router, utoipa::openapi::OpenApi) {
    let (router, api) = OpenApiRouter::with_openapi(ApiDoc::openapi())
        .routes(routes!(system::health))
        .routes(routes!(system::ready))
        .routes(routes!(system::metrics))
        .routes(routes!(motion::generate))
        .routes(routes!(motion::inpaint))
        .routes(routes!(motion::extend))
        .routes(routes!(motion::transfer))
        .routes(routes!(motion::tokenize))
        .routes(routes!(motion::detokenize))
        .routes(routes!(library::get_generation))
        .routes(routes!(library::generation_sample))
        .routes(routes!(library::search_get, library::search_post))
        .routes(routes!(library::list_clips))
        .routes(routes!(library::get_clip, library::delete_clip))
        .routes(routes!(library::clip_bvh))
        .routes(routes!(library::list_skeletons))
        .routes(routes!(library::get_skeleton))
        .routes(routes!(library::skeleton_bvh))
        .routes(routes!(library::stats))
        .routes(routes!(library::ingest))
        .routes(routes!(library::get_job))
        .split_for_parts();
    let router = router.layer(DefaultBodyLimit::max(state.limits.body_bytes)).with_state(state);
    (router, api)
}

/// Unknown routes answer a JSON 404.
pub async fn fallback() -> ApiError {
    ApiError::not_found("no such endpoint: see /openapi.json or /docs")
}

/// Times out requests (as a JSON error) and counts them in the metrics by route.
pub async fn observe(State(state): State<Arc<AppState>>, request: Request, next: Next) -> Response {
    let started = Instant::now();
    let route = request.extensions().get::<MatchedPath>().map_or("unmatched", |p| p.as_str()).to_string();
    let method = request.method().to_string();
    // The models time out on their own; this bounds everything else (a slow body, the store).
    let limit = state.limits.timeout + std::time::Duration::from_secs(5);
    let response = match tokio::time::timeout(limit, next.run(request)).await {
        Ok(response) => response,
        Err(_) => axum::response::IntoResponse::into_response(ApiError::timeout(limit.as_secs_f64())),
    };
    state.metrics.request(&route, &method, response.status().as_u16(), started.elapsed().as_secs_f64());
    response
}
