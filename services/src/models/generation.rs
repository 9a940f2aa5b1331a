//! The generator's and evaluator's data and checkpoints: clips tokenized whole by the shipped
//! TAT with their caption and skeleton embeddings, and loading trained models by name.

use super::codecs::Graphs;
use super::data::ModelClip;
use super::shipped;
use anyhow::{Context, Result};
use anymo_generator::{Evaluator, EvaluatorConfig, Generator, GeneratorConfig, TokenClip};
use anymo_tokenizer::nn::ModelCard;
use anymo_tokenizer::tat::Tat;
use anymo_tokenizer::tat::window::{detokenize, encode_whole};
use anymo_tokenizer::text::CachedEncoder;
use std::path::Path;

/// Subjects counted as humans in the per-subject figures; every other subject is an animal or
/// creature.
pub const HUMAN_SUBJECTS: [&str; 4] = ["person", "character", "astronaut", "knight"];

/// Whether a subject is human.
pub fn is_human(subject: &str) -> bool {
    HUMAN_SUBJECTS.contains(&subject)
}

/// Tokenizes clips whole with TAT and embeds their captions and skeletons; with `decoded`, also
/// the latents of each clip's codes decoded and encoded again (for the evaluator).
pub fn token_clips(
    clips: &[&ModelClip],
    tat: &mut Tat,
    encoder: &mut CachedEncoder,
    decoded: bool,
) -> Result<Vec<TokenClip>> {
    let mut out = Vec::with_capacity(clips.len());
    for clip in clips {
        let captions =
            if clip.item.captions.is_empty() { vec![clip.item.subject.clone()] } else { clip.item.captions.clone() };
        let refs: Vec<&str> = captions.iter().map(String::as_str).collect();
        let text = encoder.encode(&refs)?;
        let graph = Graphs::new(encoder).of(clip.motion.skeleton())?;
        let skeleton = tat.skeleton_embedding(&graph)?;
        let encoded = encode_whole(tat, &graph, &clip.motion)?;
        let decoded_latent = if decoded {
            let motion = detokenize(tat, &encoded.tokens, &graph, clip.motion.skeleton())?;
            encode_whole(tat, &graph, &motion)?.latent
        } else {
            Vec::new()
        };
        out.push(TokenClip {
            key: clip.item.key.clone(),
            subject: clip.item.subject.clone(),
            captions,
            text,
            skeleton,
            codes: encoded.tokens.codes.into_iter().next().unwrap_or_default(),
            latent: encoded.latent,
            decoded_latent,
        });
    }
    Ok(out)
}

/// Loads a trained generator (`generator`, `generator-ar`, ...) from `dir`.
pub fn load_generator(dir: &Path, name: &str) -> Result<(Generator, ModelCard)> {
    let card = shipped::card(dir, name)?;
    let config: GeneratorConfig = serde_json::from_value(card.config["generator"].clone())
        .with_context(|| format!("model card of {name} has no generator configuration"))?;
    let mut generator = Generator::new(config, 0)?;
    generator.params_mut().load(&shipped::files(dir, name).0).with_context(|| format!("loading {name}"))?;
    Ok((generator, card))
}

/// Loads the trained evaluator named `name` from `dir`.
pub fn load_evaluator(dir: &Path, name: &str) -> Result<(Evaluator, ModelCard)> {
    let card = shipped::card(dir, name)?;
    let config: EvaluatorConfig = serde_json::from_value(card.config["evaluator"].clone())
        .with_context(|| format!("model card of {name} has no evaluator configuration"))?;
    let mut evaluator = Evaluator::new(config, 0)?;
    evaluator.params_mut().load(&shipped::files(dir, name).0).with_context(|| format!("loading {name}"))?;
    Ok((evaluator, card))
}
