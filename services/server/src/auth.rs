//! API keys. Writes (ingest, delete) always need one; generation needs one when the server is
//! started with `--keys-for-generate`. A key comes as `Authorization: Bearer KEY` or
//! `X-Api-Key: KEY`. Keys are kept as hashes and compared as hashes, so the comparison takes
//! the same time whatever the key.

use super::error::ApiError;

/// What a request does, for the key check.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Access {
    /// Changes the corpus.
    Write,
    /// Runs the generator.
    Generate,
}

/// The server's keys.
#[derive(Clone, Debug, Default)]
pub struct ApiKeys {
    hashes: Vec<blake3::Hash>,
    generate_needs_key: bool,
}

impl ApiKeys {
    /// Keys from their texts (empty ones ignored).
    pub fn new(keys: &[String], generate_needs_key: bool) -> ApiKeys {
        let hashes =
            keys.iter().map(|k| k.trim()).filter(|k| !k.is_empty()).map(|k| blake3::hash(k.as_bytes())).collect();
        ApiKeys { hashes, generate_needs_key }
    }

    /// True when the server has at least one key.
    pub fn any(&self) -> bool {
        !self.hashes.is_empty()
    }

    /// Allows or refuses `access` for a request that presented `key`.
    pub fn check(&self, access: Access, key: Option<&str>) -> Result<(), ApiError> {
        if access == Access::Generate && !self.generate_needs_key {
            return Ok(());
        }
        if self.hashes.is_empty() {
            return Err(ApiError::unauthorized(
                "this server has no API keys, so it refuses writes: start it with --api-key KEY (or ANYMO_API_KEYS)",
            ));
        }
        let Some(key) = key else {
            return Err(ApiError::unauthorized(
                "this needs an API key: send Authorization: Bearer KEY or X-Api-Key: KEY",
            ));
        };
        let presented = blake3::hash(key.trim().as_bytes());
        if self.hashes.contains(&presented) { Ok(()) } else { Err(ApiError::unauthorized("the API key is not valid")) }
    }

    /// The key a request's headers present, if any.
    pub fn presented(headers: &axum::http::HeaderMap) -> Option<&str> {
        let bearer = headers
            .get(axum::http::header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.strip_prefix("Bearer ").or_else(|| v.strip_prefix("bearer ")));
        bearer.or_else(|| headers.get("x-api-key").and_then(|v| v.to_str().ok()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_need_a_configured_key_and_generation_only_when_asked() {
        let none = ApiKeys::new(&[], false);
        assert_eq!(none.check(Access::Write, Some("k")).unwrap_err().code, "unauthorized");
        assert!(none.check(Access::Generate, None).is_ok());
        let keys = ApiKeys::new(&["s3cret".into(), " ".into()], true);
        assert!(keys.check(Access::Write, Some("s3cret")).is_ok());
        assert!(keys.check(Access::Generate, Some(" s3cret ")).is_ok());
        assert!(keys.check(Access::Write, Some("s3cre")).unwrap_err().message.contains("not valid"));
        assert!(keys.check(Access::Generate, None).unwrap_err().message.contains("Bearer"));
        assert!(keys.check(Access::Write, Some("")).is_err(), "an empty key never matches the ignored blank one");
    }

    #[test]
    fn a_key_comes_as_a_bearer_token_or_a_header() {
        let mut headers = axum::http::HeaderMap::new();
        assert_eq!(ApiKeys::presented(&headers), None);
        headers.insert("x-api-key", "abc".parse().unwrap());
        assert_eq!(ApiKeys::presented(&headers), Some("abc"));
        headers.insert(axum::http::header::AUTHORIZATION, "Bearer xyz".parse().unwrap());
        assert_eq!(ApiKeys::presented(&headers), Some("xyz"));
    }
}
