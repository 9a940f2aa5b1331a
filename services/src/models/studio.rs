//! Text to motion as users meet it: loaded models, a target skeleton prepared once, prompts
//! and durations checked against the limits, and generated codes rendered onto the user's own
//! skeleton. The CLI's `generate` and `edit` use it, and so do the benchmark and the server.

use super::codecs::Graphs;
use super::data::MODEL_FPS;
use super::{generation, shipped};
use anyhow::{Result, anyhow, bail};
use anymo_generator::generate::Codes;
use anymo_generator::{Generator, Request};
use anymo_tokenizer::motion::Motion;
use anymo_tokenizer::owo::SkeletonGraph;
use anymo_tokenizer::prep::clean::{CleanClip, CleanOptions, clean};
use anymo_tokenizer::skeleton::Skeleton;
use anymo_tokenizer::tat::Tat;
use anymo_tokenizer::tat::window::{Tokens, detokenize, encode_whole};
use anymo_tokenizer::text::{CachedEncoder, SentenceEncoder};
use std::path::Path;

/// Longest motion one request may ask for, in seconds.
pub const MAX_SECONDS: f64 = 30.0;

/// A skeleton ready to be animated: the user's rest pose, its cleaned form, its graph and
/// OwO's embedding of it.
pub struct Target {
    /// The user's skeleton as a one-frame rest pose (or the user's clip, for edits).
    pub source: Motion,
    /// The cleaned skeleton (and motion) the models work on.
    pub cleaned: CleanClip,
    /// Its skeleton graph.
    pub graph: SkeletonGraph,
    /// OwO's global embedding.
    pub embedding: Vec<f32>,
}

/// The tokenizer, a generator and the sentence encoder, loaded once.
pub struct Studio {
    /// The tokenizer the generator's codes belong to.
    pub tat: Tat,
    /// The generator.
    pub generator: Generator,
    /// The sentence encoder (with a cache of node texts).
    pub encoder: CachedEncoder,
}

impl Studio {
    /// Loads generator `model` from `checkpoints` with the tokenizer it was trained on.
    pub fn load(checkpoints: &Path, model: &str, encoder: SentenceEncoder) -> Result<Studio> {
        let (generator, card) = generation::load_generator(checkpoints, model)?;
        let mut encoder = CachedEncoder::new(encoder);
        let tat = shipped::load_tat_of(checkpoints, &card, &mut encoder)?;
        Ok(Studio { tat, generator, encoder })
    }

    /// Frames one token step covers.
    pub fn frames_per_token(&self) -> usize {
        self.tat.config().tat.frames_per_token()
    }

    /// Token steps covering `seconds`, refused outside `(0, MAX_SECONDS]`.
    pub fn steps(&self, seconds: f64) -> Result<usize> {
        if !(seconds > 0.0 && seconds <= MAX_SECONDS) {
            bail!("a duration must be more than 0 and at most {MAX_SECONDS} seconds; {seconds} was asked");
        }
        Ok(((seconds * MODEL_FPS).round() as usize).div_ceil(self.frames_per_token()).max(1))
    }

    /// The sentence embedding of a prompt.
    pub fn text(&mut self, prompt: &str) -> Result<Vec<f32>> {
        if prompt.trim().is_empty() {
            bail!("the prompt is empty");
        }
        Ok(self.encoder.encode(&[prompt])?.remove(0))
    }

    /// A skeleton to animate, from any skeleton (its rest pose is its offsets).
    pub fn target(&mut self, skeleton: &Skeleton) -> Result<Target> {
        let rest = Motion::rest_pose(skeleton, 1.0 / MODEL_FPS);
        let cleaned =
            clean(&rest, &CleanOptions::default()).map_err(|r| anyhow!("the skeleton cannot be animated: {r}"))?;
        self.prepare(rest, cleaned)
    }

    /// A user's clip to edit, with its codes and where it starts.
    pub fn clip(&mut self, motion: &Motion) -> Result<(Target, Codes, [f32; 3])> {
        if motion.frames() == 0 {
            bail!("the clip has no frames of motion");
        }
        let cleaned = clean(motion, &CleanOptions::default()).map_err(|r| anyhow!("the clip cannot be used: {r}"))?;
        let cleaned = CleanClip { motion: cleaned.motion.resample(MODEL_FPS), ..cleaned };
        let target = self.prepare(motion.clone(), cleaned)?;
        let encoded = encode_whole(&mut self.tat, &target.graph, &target.cleaned.motion)?;
        let Tokens { codes, start, .. } = encoded.tokens;
        Ok((target, codes.into_iter().next().unwrap_or_default(), start))
    }

    fn prepare(&mut self, source: Motion, cleaned: CleanClip) -> Result<Target> {
        let graph = Graphs::new(&mut self.encoder).of(cleaned.motion.skeleton())?;
        let embedding = self.tat.skeleton_embedding(&graph)?;
        Ok(Target { source, cleaned, graph, embedding })
    }

    /// New motion for a prompt on a target: `request.samples` code sequences.
    pub fn generate(&mut self, prompt: &str, target: &Target, request: &Request) -> Result<Vec<Codes>> {
        let text = self.text(prompt)?;
        Ok(self.generator.generate(&text, &target.embedding, request)?)
    }

    /// Decodes samples onto the target, cut to `frames` when given, back on the user's skeleton
    /// and in the user's units.
    pub fn render(
        &self,
        samples: Vec<Codes>,
        start: [f32; 3],
        frames: Option<usize>,
        target: &Target,
    ) -> Result<Vec<Motion>> {
        let skeleton = target.cleaned.motion.skeleton();
        samples
            .into_iter()
            .map(|codes| {
                let mut tokens = Tokens::whole(codes, self.frames_per_token(), MODEL_FPS);
                tokens.start = start;
                let decoded = detokenize(&self.tat, &tokens, &target.graph, skeleton)?;
                let decoded = decoded.slice(0, frames.unwrap_or(decoded.frames()));
                Ok(target.cleaned.restore(&decoded, &target.source))
            })
            .collect()
    }
}
