//! The server's errors: an HTTP status, a stable machine-readable code and a message a person
//! can act on, answered as JSON `{"error": {"code", "message"}}` over REST and as a status with
//! the same message over gRPC.

use anymo_models::error::ModelError;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use utoipa::ToSchema;

/// An error answered to a client.
#[derive(Debug, Clone)]
pub struct ApiError {
    /// The HTTP status.
    pub status: StatusCode,
    /// A stable code clients can match on.
    pub code: &'static str,
    /// What went wrong and what to do about it.
    pub message: String,
    /// Seconds after which to try again (busy answers).
    pub retry_after: Option<u64>,
}

/// The JSON body of an error.
#[derive(Serialize, ToSchema)]
pub struct ErrorBody {
    /// The error.
    pub error: ErrorDetail,
}

/// What an error says.
#[derive(Serialize, ToSchema)]
pub struct ErrorDetail {
    /// Stable code: `bad_request`, `bad_bvh`, `refused`, `too_large`, `over_limit`,
    /// `unauthorized`, `not_found`, `busy`, `timeout`, `unavailable` or `internal`.
    pub code: String,
    /// What went wrong.
    pub message: String,
}

impl ApiError {
    fn new(status: StatusCode, code: &'static str, message: impl Into<String>) -> ApiError {
        ApiError { status, code, message: message.into(), retry_after: None }
    }

    /// A request that is malformed (missing field, wrong type, bad JSON).
    pub fn bad_request(message: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::BAD_REQUEST, "bad_request", message)
    }

    /// A BVH file that does not parse; the message names the line.
    pub fn bad_bvh(what: &str, error: impl std::fmt::Display) -> ApiError {
        ApiError::new(StatusCode::BAD_REQUEST, "bad_bvh", format!("{what} is not a valid BVH file: {error}"))
    }

    /// A well-formed request the models cannot serve (see [`ModelError::Refused`]).
    pub fn refused(message: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, "refused", message)
    }

    /// A request over one of the server's limits; the message names the limit.
    pub fn over_limit(what: &str, limit: impl std::fmt::Display, got: impl std::fmt::Display) -> ApiError {
        ApiError::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "over_limit",
            format!("{what} is limited to {limit} on this server; {got} was asked"),
        )
    }

    /// A body over the size limit.
    pub fn too_large(limit: usize) -> ApiError {
        ApiError::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            "too_large",
            format!("request bodies are limited to {limit} bytes"),
        )
    }

    /// A missing or wrong API key.
    pub fn unauthorized(message: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::UNAUTHORIZED, "unauthorized", message)
    }

    /// Nothing there.
    pub fn not_found(message: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::NOT_FOUND, "not_found", message)
    }

    /// The queue is full: try again later.
    pub fn busy(what: &str, capacity: usize) -> ApiError {
        ApiError {
            retry_after: Some(1),
            ..ApiError::new(
                StatusCode::TOO_MANY_REQUESTS,
                "busy",
                format!("the {what} queue is full ({capacity} waiting); try again shortly"),
            )
        }
    }

    /// The request took longer than the server allows.
    pub fn timeout(seconds: f64) -> ApiError {
        ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "timeout",
            format!("the request did not finish within the server's {seconds} s limit"),
        )
    }

    /// The server cannot serve this now (shutting down, store unreachable).
    pub fn unavailable(message: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "unavailable", message)
    }

    /// A failure of the server's own.
    pub fn internal(error: impl std::fmt::Display) -> ApiError {
        ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, "internal", error.to_string())
    }

    /// A model operation's error: a refusal is the client's, anything else the server's.
    pub fn from_model(error: ModelError) -> ApiError {
        match error {
            ModelError::Refused(message) => ApiError::refused(message),
            failure => {
                tracing::error!("model failure: {failure}");
                ApiError::internal(failure.to_string())
            }
        }
    }
}

impl From<anymo_store::StoreError> for ApiError {
    fn from(error: anymo_store::StoreError) -> ApiError {
        tracing::error!("store failure: {error}");
        ApiError::unavailable(format!("the store failed: {error}"))
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let body = ErrorBody { error: ErrorDetail { code: self.code.to_string(), message: self.message } };
        let mut response = (self.status, axum::Json(body)).into_response();
        if let Some(seconds) = self.retry_after {
            response.headers_mut().insert(axum::http::header::RETRY_AFTER, seconds.into());
        }
        response
    }
}

impl From<ApiError> for tonic::Status {
    fn from(error: ApiError) -> tonic::Status {
        let code = match error.status {
            StatusCode::BAD_REQUEST | StatusCode::UNPROCESSABLE_ENTITY => tonic::Code::InvalidArgument,
            StatusCode::PAYLOAD_TOO_LARGE => tonic::Code::OutOfRange,
            StatusCode::UNAUTHORIZED => tonic::Code::Unauthenticated,
            StatusCode::NOT_FOUND => tonic::Code::NotFound,
            StatusCode::TOO_MANY_REQUESTS => tonic::Code::ResourceExhausted,
            StatusCode::SERVICE_UNAVAILABLE if error.code == "timeout" => tonic::Code::DeadlineExceeded,
            StatusCode::SERVICE_UNAVAILABLE => tonic::Code::Unavailable,
            _ => tonic::Code::Internal,
        };
        tonic::Status::new(code, format!("{}: {}", error.code, error.message))
    }
}
