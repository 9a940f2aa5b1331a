//! The motion capabilities as the server offers them, one function each for REST and gRPC
//! alike: generate, edit (inpaint, continue), transfer, tokenize and detokenize. Each checks
//! the request against the limits, runs the models on a generation worker, and stores what it
//! made, so a result can be fetched again by id.

use super::AppState;
use super::error::ApiError;
use super::motion::{ClipSource, SkeletonSource, bvh_text};
use anymo_generator::Request;
use anymo_generator::sampling::Sampling;
use anymo_models::data::MODEL_FPS;
use anymo_models::quality::{Made, QualityReport};
use anymo_models::studio::{Studio, Target};
use anymo_models::tokens::{TokenCodec, TokenFile};
use anymo_motion::cleanup::Cleanup;
use anymo_motion::motion::Motion;
use anymo_store::NewGeneration;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::sync::Arc;
use utoipa::ToSchema;

/// Longest prompt, in characters (the sentence encoder reads 256 tokens at most).
pub const MAX_PROMPT_CHARS: usize = 1_000;

/// Targets a worker keeps prepared (a skeleton's graph and OwO embedding take a while).
const CACHED_TARGETS: usize = 16;

/// What a generation worker owns.
pub struct GenerationModels {
    /// The generator with its tokenizer and sentence encoder.
    pub studio: Studio,
    /// The tokenizer for tokens and transfer.
    pub codec: TokenCodec,
    targets: VecDeque<(blake3::Hash, Arc<Target>)>,
}

impl GenerationModels {
    /// Models for one worker.
    pub fn new(studio: Studio, codec: TokenCodec) -> GenerationModels {
        GenerationModels { studio, codec, targets: VecDeque::new() }
    }

    /// The prepared target of a skeleton's file (see [`Studio::target`]), from the cache when
    /// the same file was seen lately.
    fn target(&mut self, file: &Motion) -> Result<Arc<Target>, ApiError> {
        let key = file_key(file);
        if let Some(k) = self.targets.iter().position(|(h, _)| *h == key) {
            let hit = self.targets.remove(k).expect("a found position");
            self.targets.push_back(hit);
        } else {
            let target = self.studio.target(file).map_err(ApiError::from_model)?;
            if self.targets.len() == CACHED_TARGETS {
                self.targets.pop_front();
            }
            self.targets.push_back((key, Arc::new(target)));
        }
        Ok(self.targets.back().expect("just pushed").1.clone())
    }
}

/// What tells two skeleton files apart: the skeleton and every value of its frames.
fn file_key(file: &Motion) -> blake3::Hash {
    let mut hasher = blake3::Hasher::new();
    hasher.update(format!("{:?}", file.skeleton()).as_bytes());
    for q in file.all_rotations() {
        for v in q.to_array() {
            hasher.update(&v.to_le_bytes());
        }
    }
    for t in file.all_translations() {
        for v in t.to_array() {
            hasher.update(&v.to_le_bytes());
        }
    }
    hasher.finalize()
}

/// How samples are drawn; anything left out takes the server's default.
#[derive(Clone, Debug, Default, Deserialize, Serialize, ToSchema)]
pub struct SamplingOptions {
    /// Samples to draw (default 1).
    pub samples: Option<usize>,
    /// Seed: the same request and seed give the same motion (default 0).
    pub seed: Option<u64>,
    /// Classifier-free guidance scale, 0 to 20 (default 2; 1 is no guidance).
    pub guidance: Option<f32>,
    /// Sampling temperature, 0 to 10 (default 0.7; 0 always takes the likeliest token).
    pub temperature: Option<f32>,
    /// Draw only among the k likeliest tokens (default 0: all).
    pub top_k: Option<usize>,
    /// Clean up the decoded motion: smoothing and planted feet (default true).
    pub cleanup: Option<bool>,
    /// Score the motion against its prompt in its quality report (default true; it costs one
    /// pass of the tokenizer's encoder).
    pub score: Option<bool>,
}

impl SamplingOptions {
    /// The cleanup these options ask for.
    pub fn cleanup(&self) -> Option<Cleanup> {
        cleanup_of(self.cleanup)
    }
}

/// The cleanup a request's `cleanup` field asks for (absent: the default cleanup).
pub fn cleanup_of(asked: Option<bool>) -> Option<Cleanup> {
    asked.unwrap_or(true).then(Cleanup::default)
}

impl SamplingOptions {
    /// The generator request these options make, refused when out of range.
    pub fn request(&self, state: &AppState) -> Result<Request, ApiError> {
        let defaults = Sampling::default();
        let samples = self.samples.unwrap_or(1);
        state.limits.check_samples(samples)?;
        let guidance = self.guidance.unwrap_or(defaults.guidance);
        if !(0.0..=20.0).contains(&guidance) {
            return Err(ApiError::bad_request(format!("guidance must be between 0 and 20; {guidance} was asked")));
        }
        let temperature = self.temperature.unwrap_or(defaults.temperature);
        if !(0.0..=10.0).contains(&temperature) {
            return Err(ApiError::bad_request(format!(
                "temperature must be between 0 and 10; {temperature} was asked"
            )));
        }
        Ok(Request {
            steps: None,
            samples,
            sampling: Sampling { temperature, top_k: self.top_k.unwrap_or(0), guidance },
            seed: self.seed.unwrap_or(0),
        })
    }
}

/// A stored result.
#[derive(Clone, Debug, Serialize, ToSchema)]
pub struct Generated {
    /// Its id: `GET /v1/generations/{id}` shows it again.
    pub id: i64,
    /// Frames of each sample.
    pub frames: usize,
    /// Frames per second.
    pub fps: f64,
    /// Each sample's BVH text.
    pub samples: Vec<String>,
    /// Each sample's quality report.
    pub quality: Vec<QualityReport>,
}

/// Checks a prompt: not empty, not too long.
fn check_prompt(prompt: &str) -> Result<(), ApiError> {
    if prompt.trim().is_empty() {
        return Err(ApiError::bad_request("the prompt is empty: say what the motion shows"));
    }
    let chars = prompt.chars().count();
    if chars > MAX_PROMPT_CHARS {
        return Err(ApiError::over_limit("the prompt", format!("{MAX_PROMPT_CHARS} characters"), chars));
    }
    Ok(())
}

/// Stores motions made by `kind` for `request` and answers them.
async fn keep(
    state: &AppState,
    kind: &str,
    request: serde_json::Value,
    made: Vec<Made>,
) -> Result<Generated, ApiError> {
    let samples: Vec<String> = made.iter().map(|m| bvh_text(&m.motion)).collect();
    let frames = made.first().map_or(0, |m| m.motion.frames());
    let fps = made.first().map_or(MODEL_FPS, |m| m.motion.fps());
    let quality: Vec<QualityReport> = made.into_iter().map(|m| m.quality).collect();
    let report = serde_json::to_value(&quality).map_err(|e| ApiError::internal(e.to_string()))?;
    let new = NewGeneration { kind, request, frames: frames as i64, fps, samples: &samples, quality: report };
    let id = state.store.insert_generation(&new).await?;
    state.metrics.generated(kind, samples.len());
    Ok(Generated { id, frames, fps, samples, quality })
}

/// What the stored record says of a skeleton source (the id, or that it was uploaded).
fn describe(source: &SkeletonSource) -> serde_json::Value {
    match source {
        SkeletonSource::Bvh(bytes) => serde_json::json!({ "uploaded_bytes": bytes.len() }),
        SkeletonSource::Stored(id) => serde_json::json!({ "skeleton_id": id }),
    }
}

/// Motion from a prompt on a skeleton, `seconds` long (or as long as the length predictor says).
pub async fn generate(
    state: &AppState,
    prompt: String,
    seconds: Option<f64>,
    skeleton: SkeletonSource,
    sampling: SamplingOptions,
) -> Result<Generated, ApiError> {
    check_prompt(&prompt)?;
    if let Some(s) = seconds {
        state.limits.check_seconds(s)?;
    }
    let request = sampling.request(state)?;
    let (target, _) = state.target(&skeleton).await?;
    let record = serde_json::json!({
        "prompt": prompt, "seconds": seconds, "skeleton": describe(&skeleton), "sampling": sampling,
    });
    let (cleanup, score) = (sampling.cleanup(), sampling.score.unwrap_or(true));
    let made = state
        .generation
        .run(state.limits.timeout, move |m: &mut GenerationModels| {
            let target = m.target(&target)?;
            m.studio.set_cleanup(cleanup);
            m.studio.set_scoring(score);
            m.studio.generate_motion(&prompt, &target, seconds, &request).map_err(ApiError::from_model)
        })
        .await?;
    keep(state, "generate", record, made).await
}

/// An edit of a clip.
#[derive(Clone, Debug)]
pub enum Edit {
    /// Regenerate the span `from..to` seconds.
    Inpaint {
        /// Start of the span, seconds.
        from: f64,
        /// End of the span, seconds.
        to: f64,
    },
    /// Add `seconds` of motion after the clip.
    Continue {
        /// Seconds to add.
        seconds: f64,
    },
}

/// A clip edited from a prompt.
pub async fn edit(
    state: &AppState,
    clip: ClipSource,
    prompt: String,
    edit: Edit,
    sampling: SamplingOptions,
) -> Result<Generated, ApiError> {
    check_prompt(&prompt)?;
    let request = sampling.request(state)?;
    let (kind, record) = match &edit {
        Edit::Inpaint { from, to } => {
            if !(from.is_finite() && to.is_finite() && *from >= 0.0 && to > from) {
                return Err(ApiError::bad_request(format!("the span must satisfy 0 <= from < to; got {from}..{to}")));
            }
            ("inpaint", serde_json::json!({ "prompt": prompt, "from": from, "to": to, "sampling": sampling }))
        }
        Edit::Continue { seconds } => {
            state.limits.check_seconds(*seconds)?;
            ("continue", serde_json::json!({ "prompt": prompt, "seconds": seconds, "sampling": sampling }))
        }
    };
    let motion = state.clip(&clip).await?;
    let (cleanup, score) = (sampling.cleanup(), sampling.score.unwrap_or(true));
    let made = state
        .generation
        .run(state.limits.timeout, move |m: &mut GenerationModels| {
            m.studio.set_cleanup(cleanup);
            m.studio.set_scoring(score);
            let made = match edit {
                Edit::Inpaint { from, to } => m.studio.inpaint(&motion, &prompt, (from, to), &request),
                Edit::Continue { seconds } => m.studio.extend(&motion, &prompt, seconds, &request),
            };
            made.map_err(ApiError::from_model)
        })
        .await?;
    keep(state, kind, record, made).await
}

/// A clip moved onto another skeleton.
/// `cleanup` as [`cleanup_of`] reads it.
pub async fn transfer(
    state: &AppState,
    clip: ClipSource,
    to: SkeletonSource,
    cleanup: Option<bool>,
) -> Result<Generated, ApiError> {
    let motion = state.clip(&clip).await?;
    let (target, fps) = state.target(&to).await?;
    let record = serde_json::json!({
        "clip": match &clip { ClipSource::Stored(id) => serde_json::json!({ "clip_id": id }), ClipSource::Bvh(b) => serde_json::json!({ "uploaded_bytes": b.len() }) },
        "to": describe(&to),
        "cleanup": cleanup,
    });
    let moved = state
        .generation
        .run(state.limits.timeout, move |m: &mut GenerationModels| {
            m.codec.set_cleanup(cleanup_of(cleanup));
            m.codec.transfer(&motion, &target, fps).map_err(ApiError::from_model)
        })
        .await?;
    keep(state, "transfer", record, vec![moved]).await
}

/// A clip's TAT tokens.
pub async fn tokenize(state: &AppState, clip: ClipSource) -> Result<TokenFile, ApiError> {
    let motion = state.clip(&clip).await?;
    state
        .generation
        .run(state.limits.timeout, move |m: &mut GenerationModels| {
            m.codec.tokenize(&motion).map_err(ApiError::from_model)
        })
        .await
}

/// Tokens as motion on a skeleton (`cleanup` as [`cleanup_of`] reads it).
pub async fn detokenize(
    state: &AppState,
    tokens: TokenFile,
    to: SkeletonSource,
    cleanup: Option<bool>,
) -> Result<Generated, ApiError> {
    if tokens.tokens.frames > state.limits.frames {
        return Err(ApiError::over_limit("frames of the tokens", state.limits.frames, tokens.tokens.frames));
    }
    let (target, fps) = state.target(&to).await?;
    let record = serde_json::json!({
        "model": tokens.model, "frames": tokens.tokens.frames, "to": describe(&to), "cleanup": cleanup,
    });
    let made = state
        .generation
        .run(state.limits.timeout, move |m: &mut GenerationModels| {
            m.codec.set_cleanup(cleanup_of(cleanup));
            m.codec.detokenize(&tokens, &target, fps).map_err(ApiError::from_model)
        })
        .await?;
    keep(state, "detokenize", record, vec![made]).await
}
