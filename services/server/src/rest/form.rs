//! One reader for request bodies that come as multipart/form-data (files uploaded as parts) or
//! as a JSON object (files as BVH text in string fields), so every endpoint takes both the same
//! way. Rejections become the server's JSON errors.

use crate::error::ApiError;
use axum::extract::multipart::MultipartError;
use axum::extract::{FromRequest, Multipart, Request};
use axum::http::HeaderMap;
use axum::http::header::CONTENT_TYPE;
use http_body_util::BodyExt;
use std::str::FromStr;

/// A part of a form: its bytes and, for an uploaded file, its name.
#[derive(Clone, Debug)]
pub struct Part {
    /// The file name the client gave, if it is a file.
    pub file_name: Option<String>,
    /// The bytes.
    pub bytes: Vec<u8>,
}

/// A request body's fields by name, in order (a name may repeat, e.g. several files).
#[derive(Debug, Default)]
pub struct Form {
    parts: Vec<(String, Part)>,
}

fn multipart_error(error: MultipartError, limit: usize) -> ApiError {
    if error.status() == axum::http::StatusCode::PAYLOAD_TOO_LARGE {
        ApiError::too_large(limit)
    } else {
        ApiError::bad_request(format!("the multipart body cannot be read: {}", error.body_text()))
    }
}

impl Form {
    /// Reads the body as [`Form::read`] does once `check` accepts the request's headers. A
    /// refused request's body is still read to its end (at most `limit` bytes, dropped as they
    /// arrive), so a client that is still uploading receives the refusal instead of a connection
    /// closed under it.
    pub async fn read_if(
        request: Request,
        limit: usize,
        check: impl FnOnce(&HeaderMap) -> Result<(), ApiError>,
    ) -> Result<Form, ApiError> {
        if let Err(refusal) = check(request.headers()) {
            let mut body = request.into_body();
            let mut read = 0usize;
            while let Some(Ok(frame)) = body.frame().await {
                read += frame.data_ref().map_or(0, |data| data.len());
                if read > limit {
                    break;
                }
            }
            return Err(refusal);
        }
        Form::read(request, limit).await
    }

    /// Reads a multipart or JSON body, refusing other content types.
    pub async fn read(request: Request, limit: usize) -> Result<Form, ApiError> {
        let content_type =
            request.headers().get(CONTENT_TYPE).and_then(|v| v.to_str().ok()).unwrap_or_default().to_ascii_lowercase();
        if content_type.starts_with("multipart/form-data") {
            let mut multipart = Multipart::from_request(request, &())
                .await
                .map_err(|e| ApiError::bad_request(format!("the multipart body cannot be read: {}", e.body_text())))?;
            let mut parts = Vec::new();
            while let Some(field) = multipart.next_field().await.map_err(|e| multipart_error(e, limit))? {
                let name = field.name().unwrap_or_default().to_string();
                let file_name = field.file_name().map(str::to_string);
                let bytes = field.bytes().await.map_err(|e| multipart_error(e, limit))?.to_vec();
                parts.push((name, Part { file_name, bytes }));
            }
            Ok(Form { parts })
        } else if content_type.starts_with("application/json") {
            let bytes =
                axum::body::to_bytes(request.into_body(), limit).await.map_err(|_| ApiError::too_large(limit))?;
            let value: serde_json::Value = serde_json::from_slice(&bytes)
                .map_err(|e| ApiError::bad_request(format!("the JSON body cannot be read: {e}")))?;
            let serde_json::Value::Object(object) = value else {
                return Err(ApiError::bad_request("the JSON body must be an object"));
            };
            let mut parts = Vec::new();
            for (name, value) in object {
                let values = match value {
                    serde_json::Value::Array(items) if name == "files" => items,
                    serde_json::Value::Null => continue,
                    other => vec![other],
                };
                for value in values {
                    let bytes = match value {
                        serde_json::Value::String(s) => s.into_bytes(),
                        other => other.to_string().into_bytes(),
                    };
                    parts.push((name.clone(), Part { file_name: None, bytes }));
                }
            }
            Ok(Form { parts })
        } else {
            Err(ApiError::bad_request(format!(
                "send multipart/form-data or application/json, not {:?}",
                if content_type.is_empty() { "no content type" } else { content_type.as_str() }
            )))
        }
    }

    /// Every part, in order.
    pub fn parts(&self) -> &[(String, Part)] {
        &self.parts
    }

    /// The bytes of the first part named `name`.
    pub fn bytes(&self, name: &str) -> Option<&[u8]> {
        self.parts.iter().find(|(n, _)| n == name).map(|(_, p)| p.bytes.as_slice())
    }

    /// A text field, refused when it is not UTF-8.
    pub fn text(&self, name: &str) -> Result<Option<String>, ApiError> {
        self.bytes(name)
            .map(|b| {
                String::from_utf8(b.to_vec()).map_err(|_| ApiError::bad_request(format!("{name} must be UTF-8 text")))
            })
            .transpose()
    }

    /// A required text field.
    pub fn required_text(&self, name: &str) -> Result<String, ApiError> {
        self.text(name)?.ok_or_else(|| ApiError::bad_request(format!("the field {name} is missing")))
    }

    /// A true-or-false field (empty counts as absent): `true`/`false` or `1`/`0`.
    pub fn flag(&self, name: &str) -> Result<Option<bool>, ApiError> {
        match self.text(name)?.as_deref().map(str::trim) {
            None | Some("") => Ok(None),
            Some("true" | "1") => Ok(Some(true)),
            Some("false" | "0") => Ok(Some(false)),
            Some(text) => Err(ApiError::bad_request(format!("{name} must be true or false; {text:?} was sent"))),
        }
    }

    /// A number field (empty counts as absent), refused when it does not parse.
    pub fn number<T: FromStr>(&self, name: &str) -> Result<Option<T>, ApiError> {
        match self.text(name)?.as_deref().map(str::trim) {
            None | Some("") => Ok(None),
            Some(text) => text
                .parse()
                .map(Some)
                .map_err(|_| ApiError::bad_request(format!("{name} must be a number; {text:?} was sent"))),
        }
    }
}
