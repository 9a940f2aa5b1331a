//! The generator's and evaluator's data and checkpoints: clips tokenized whole by the shipped
//! TAT with their caption and skeleton embeddings, and loading trained models by name.

use super::codecs::{Graphs, bases_by_topology};
use super::data::{ModelClip, topology};
use crate::card::{EvaluatorCard, GeneratorCard};
use crate::checkpoint::Checkpoint;
use anyhow::Result;
use anymo_generator::anchors::{ANCHORS_TENSOR, WITHIN_TENSOR};
use anymo_generator::paraphrase::{self, Rewording};
use anymo_generator::{CaptionAnchors, Evaluator, Generator, TokenClip};
use anymo_tokenizer::nn::ModelCard;
use anymo_tokenizer::tat::Tat;
use anymo_tokenizer::tat::window::{detokenize, encode_whole};
use anymo_tokenizer::text::CachedEncoder;
use rand::SeedableRng;

/// Subjects counted as humans in the per-subject figures; every other subject is an animal or
/// creature.
pub const HUMAN_SUBJECTS: [&str; 4] = ["person", "character", "astronaut", "knight"];

/// Whether a subject is human.
pub fn is_human(subject: &str) -> bool {
    HUMAN_SUBJECTS.contains(&subject)
}

/// Tokenizes clips whole with TAT (each skeleton in its basis, see
/// [`crate::codecs::bases_by_topology`]) and embeds their captions and skeletons; with
/// `decoded`, also the latents of each clip's codes decoded and encoded again (for the
/// evaluator).
pub fn token_clips(
    clips: &[&ModelClip],
    tat: &mut Tat,
    encoder: &mut CachedEncoder,
    decoded: bool,
) -> Result<Vec<TokenClip>> {
    let mut out = Vec::with_capacity(clips.len());
    let bases = bases_by_topology(tat.config().representation, clips);
    for clip in clips {
        let motion = bases[&topology(&clip.motion)].enter(&clip.motion);
        let captions =
            if clip.item.captions.is_empty() { vec![clip.item.subject.clone()] } else { clip.item.captions.clone() };
        let refs: Vec<&str> = captions.iter().map(String::as_str).collect();
        let text = encoder.encode(&refs)?;
        let graph = Graphs::new(encoder).of(motion.skeleton())?;
        let skeleton = tat.skeleton_embedding(&graph)?;
        let encoded = encode_whole(tat, &graph, &motion)?;
        let decoded_latent = if decoded {
            let again = detokenize(tat, &encoded.tokens, &graph, motion.skeleton())?;
            encode_whole(tat, &graph, &again)?.latent
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

/// Adds up to `per_caption` reworded variants of each clip's captions (see
/// [`anymo_generator::paraphrase`]) with their sentence embeddings, drawn from `seed`; returns
/// how many were added. Training then draws among a clip's captions and their variants alike.
pub fn add_paraphrases(
    clips: &mut [TokenClip],
    per_caption: usize,
    encoder: &mut CachedEncoder,
    seed: u64,
) -> Result<usize> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut added = 0;
    for clip in clips.iter_mut() {
        let new: Vec<String> = clip
            .captions
            .iter()
            .flat_map(|c| paraphrase::variants(c, per_caption, Rewording::default(), &mut rng))
            .filter(|v| !clip.captions.contains(v))
            .collect();
        let refs: Vec<&str> = new.iter().map(String::as_str).collect();
        clip.text.extend(encoder.encode(&refs)?);
        added += new.len();
        clip.captions.extend(new);
    }
    Ok(added)
}

/// Loads a trained generator (`generator`, `generator-ar`, ...), with the captions it trained
/// on when its weights keep them.
pub fn load_generator(checkpoint: &Checkpoint) -> Result<(Generator, ModelCard<GeneratorCard>)> {
    let card: ModelCard<GeneratorCard> = checkpoint.card("a generator")?;
    let mut generator = Generator::new(card.config.generator.clone(), 0)?;
    let buffers = checkpoint.load_into(generator.params_mut())?;
    if let (Some(captions), Some(within)) = (buffers.get(ANCHORS_TENSOR), buffers.get(WITHIN_TENSOR)) {
        generator.set_anchors(CaptionAnchors::from_tensors(captions, within)?)?;
    }
    Ok((generator, card))
}

/// The distinct captions of `clips` as a generator's anchors (see [`anymo_generator::anchors`]);
/// `None` for clips without captions.
pub fn caption_anchors(clips: &[TokenClip]) -> Option<CaptionAnchors> {
    CaptionAnchors::new(clips.iter().flat_map(|c| c.text.iter().map(Vec::as_slice)))
}

/// Loads a trained text-motion evaluator.
pub fn load_evaluator(checkpoint: &Checkpoint) -> Result<(Evaluator, ModelCard<EvaluatorCard>)> {
    let card: ModelCard<EvaluatorCard> = checkpoint.card("an evaluator")?;
    let mut evaluator = Evaluator::new(card.config.evaluator, 0)?;
    checkpoint.load_into(evaluator.params_mut())?;
    Ok((evaluator, card))
}
