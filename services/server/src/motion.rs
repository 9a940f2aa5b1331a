//! Motion as clients send and receive it: BVH bytes (plain or gzipped) checked against the
//! limits, skeletons and clips either uploaded or stored, and motion written back as BVH text.

use super::AppState;
use super::error::ApiError;
use anymo_motion::bvh::{self, Bvh, ReadOptions};
use anymo_motion::motion::Motion;
use std::io::Read;

/// Where a skeleton comes from.
#[derive(Clone, Debug)]
pub enum SkeletonSource {
    /// A BVH file's bytes (its motion, if any, is ignored).
    Bvh(Vec<u8>),
    /// A stored skeleton's id.
    Stored(i64),
}

/// Where a clip comes from.
#[derive(Clone, Debug)]
pub enum ClipSource {
    /// A BVH file's bytes.
    Bvh(Vec<u8>),
    /// A stored clip's id.
    Stored(i64),
}

/// BVH bytes as text: gzip is detected by its magic bytes and inflated up to `limit` bytes.
fn inflate(what: &str, bytes: &[u8], limit: usize) -> Result<Vec<u8>, ApiError> {
    if !bytes.starts_with(&[0x1f, 0x8b]) {
        return Ok(bytes.to_vec());
    }
    let mut text = Vec::new();
    flate2::read::MultiGzDecoder::new(bytes)
        .take(limit as u64 + 1)
        .read_to_end(&mut text)
        .map_err(|e| ApiError::bad_bvh(what, format!("corrupt gzip: {e}")))?;
    if text.len() > limit {
        return Err(ApiError::over_limit(&format!("the inflated size of {what}"), format!("{limit} bytes"), "more"));
    }
    Ok(text)
}

/// Parses a client's BVH file, refused with the line and column when malformed and with the
/// limit when it has too many joints or frames.
pub fn parse_bvh(state: &AppState, what: &str, bytes: &[u8], require_motion: bool) -> Result<Bvh, ApiError> {
    if bytes.iter().all(u8::is_ascii_whitespace) {
        return Err(ApiError::bad_request(format!("{what} is empty")));
    }
    let text = inflate(what, bytes, state.limits.body_bytes.saturating_mul(8))?;
    let clip = bvh::read(text.as_slice(), ReadOptions { require_motion }).map_err(|e| ApiError::bad_bvh(what, e))?;
    state.limits.check_clip(what, clip.skeleton().len(), clip.frames())?;
    Ok(clip)
}

impl AppState {
    /// The skeleton a request names, with frames when there are some (a tokenizer of the
    /// reference representation poses motion around them): an uploaded file's own, or for a
    /// stored skeleton the motion of its first stored clip. With it, the frame rate motion
    /// decoded onto it takes: an uploaded file's own, 30 for a stored skeleton (the rate the
    /// store keeps skeletons at).
    pub async fn target(&self, source: &SkeletonSource) -> Result<(Motion, f64), ApiError> {
        match source {
            SkeletonSource::Bvh(bytes) => {
                let file = parse_bvh(self, "the skeleton", bytes, false)?;
                Ok((Motion::from_bvh(&file), file.fps()))
            }
            SkeletonSource::Stored(id) => {
                let row = self.store.skeleton(*id).await?.ok_or_else(|| {
                    ApiError::not_found(format!("no skeleton {id} in the store (GET /v1/skeletons lists them)"))
                })?;
                let file = bvh::read(row.hierarchy.as_bytes(), ReadOptions::default())
                    .map_err(|e| ApiError::internal(format!("stored skeleton {id} does not parse: {e}")))?;
                let skeleton = Motion::from_bvh(&file);
                let posed = match self.store.first_clip_of_skeleton(*id).await? {
                    Some(clip) => self.clip(&ClipSource::Stored(clip)).await?,
                    None => skeleton.clone(),
                };
                // The clip is on the same skeleton; its joints must line up with the stored one's.
                let same = posed.skeleton().len() == skeleton.skeleton().len()
                    && posed
                        .skeleton()
                        .joints()
                        .iter()
                        .zip(skeleton.skeleton().joints())
                        .all(|(a, b)| a.name == b.name);
                Ok((if same { posed } else { skeleton }, file.fps()))
            }
        }
    }

    /// The clip a request names, as motion.
    pub async fn clip(&self, source: &ClipSource) -> Result<Motion, ApiError> {
        let clip = match source {
            ClipSource::Bvh(bytes) => parse_bvh(self, "the clip", bytes, true)?,
            ClipSource::Stored(id) => {
                let bytes = self.store.clip_bvh(*id).await?.ok_or_else(|| {
                    ApiError::not_found(format!("no clip {id} in the store (GET /v1/clips lists them)"))
                })?;
                bvh::read(bytes.as_slice(), ReadOptions { require_motion: true })
                    .map_err(|e| ApiError::internal(format!("stored clip {id} does not parse: {e}")))?
            }
        };
        Ok(Motion::from_bvh(&clip))
    }
}

/// A motion as BVH text.
pub fn bvh_text(motion: &Motion) -> String {
    let mut out = Vec::new();
    bvh::write(&motion.to_bvh(), &mut out).expect("writing to memory");
    String::from_utf8(out).expect("BVH text is UTF-8")
}
