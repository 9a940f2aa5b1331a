//! Text to motion as users meet it: loaded models, a target skeleton prepared once, prompts
//! and durations checked against the limits, and generated codes rendered onto the user's own
//! skeleton. The CLI's `generate` and `edit` use it, and so do the benchmark and the server.

use super::codecs::Graphs;
use super::data::MODEL_FPS;
use super::generation;
use crate::checkpoint::Checkpoint;
use crate::error::ModelError;
use crate::quality::{Made, QualityReport, RealMotion, clean_up, cosine};
use anymo_generator::generate::Codes;
use anymo_generator::{Evaluator, GenerationError, Generator, Request};
use anymo_motion::cleanup::Cleanup;
use anymo_motion::motion::Motion;
use anymo_motion::posture::upright;
use anymo_motion::prep::clean::{CleanClip, CleanOptions, clean};
use anymo_tokenizer::owo::SkeletonGraph;
use anymo_tokenizer::tat::window::{Tokens, detokenize, encode_whole};
use anymo_tokenizer::tat::{Basis, Tat};
use anymo_tokenizer::text::CachedEncoder;

/// Longest motion one request may ask for, in seconds.
pub const MAX_SECONDS: f64 = 30.0;

type Result<T, E = ModelError> = std::result::Result<T, E>;

fn refuse(message: impl Into<String>) -> ModelError {
    ModelError::refused(message)
}

/// A user's clip cleaned for the models and at their frame rate, refused with the reason when
/// it cannot be (the edits, the tokenizer and search by example all read clips this way).
pub fn cleaned_clip(motion: &Motion) -> Result<CleanClip> {
    if motion.frames() == 0 {
        return Err(refuse("the clip has no frames of motion"));
    }
    let cleaned =
        clean(motion, &CleanOptions::default()).map_err(|r| refuse(format!("the clip cannot be used: {r}")))?;
    Ok(CleanClip { motion: cleaned.motion.resample(MODEL_FPS), ..cleaned })
}

/// What the reference pose of a target is taken from (a tokenizer of the reference
/// representation writes motion around it): a user's file's frames when it has motion (more
/// than one frame), else its one pose (its only frame, or its rest pose) stood up (see
/// [`upright`]). A rest pose that is no pose at all (every bone along one axis, as in Bandai's,
/// LAFAN1's and CMU's files) gives no usable reference: such rigs need a file with motion.
pub fn pose_source(file: &Motion) -> Motion {
    match file.frames() {
        0 => upright(&Motion::rest_pose(file.skeleton(), 1.0 / MODEL_FPS)),
        1 => upright(file),
        _ => file.clone(),
    }
}

/// The frames `seconds` of motion take at the models' frame rate.
pub fn frames_of(seconds: f64) -> usize {
    (seconds * MODEL_FPS).round() as usize
}

/// A skeleton ready to be animated: the user's rest pose, its cleaned form, its graph and
/// OwO's embedding of it.
pub struct Target {
    /// The user's skeleton as a one-frame rest pose (or the user's clip, for edits).
    pub source: Motion,
    /// The cleaned skeleton (and motion).
    pub cleaned: CleanClip,
    /// The joint frames the tokenizer reads the skeleton in.
    pub basis: Basis,
    /// The cleaned motion in that basis: what the models work on.
    pub entered: Motion,
    /// Its skeleton graph.
    pub graph: SkeletonGraph,
    /// OwO's global embedding.
    pub embedding: Vec<f32>,
}

/// The tokenizer, a generator and the sentence encoder, loaded once, with what judges the
/// motion it makes and how that motion is cleaned up.
pub struct Studio {
    /// The tokenizer the generator's codes belong to.
    pub tat: Tat,
    /// The generator.
    pub generator: Generator,
    /// The sentence encoder (with a cache of node texts).
    pub encoder: CachedEncoder,
    /// The evaluator, when it reads the generator's tokenizer: it scores motion against prompts.
    judge: Option<Evaluator>,
    /// Real clips' figures per skeleton, from the evaluator's card.
    real: RealMotion,
    /// The cleanup decoded motion gets (`None`: none).
    cleanup: Option<Cleanup>,
    /// Whether quality reports carry the prompt score (one pass of the tokenizer's encoder).
    scoring: bool,
}

impl Studio {
    /// Loads a generator checkpoint with the tokenizer it was trained on, and the evaluator
    /// `evaluator`, if any, for the quality reports (the real clips' figures its card records,
    /// and its prompt score when it reads the same tokenizer). Decoded motion gets the default
    /// cleanup; see [`Studio::set_cleanup`].
    pub fn load(generator: &Checkpoint, evaluator: Option<&Checkpoint>, encoder: CachedEncoder) -> Result<Studio> {
        let (model, card) = generation::load_generator(generator)?;
        let mut encoder = encoder;
        let tat = generator.load_tat_of(&card, &mut encoder)?;
        let (judge, real) = match evaluator {
            Some(evaluator) => {
                let (judge, judge_card) = generation::load_evaluator(evaluator)?;
                let real = RealMotion::from_card_metrics(&judge_card.metrics);
                ((judge_card.config.trained_on == card.config.trained_on).then_some(judge), real)
            }
            None => (None, RealMotion::default()),
        };
        Ok(Studio { tat, generator: model, encoder, judge, real, cleanup: Some(Cleanup::default()), scoring: true })
    }

    /// Sets the cleanup decoded motion gets (`None` gives the decoder's output as it is).
    pub fn set_cleanup(&mut self, cleanup: Option<Cleanup>) {
        self.cleanup = cleanup;
    }

    /// Sets whether quality reports carry the prompt score, which costs one pass of the
    /// tokenizer's encoder over the motion (on by default).
    pub fn set_scoring(&mut self, scoring: bool) {
        self.scoring = scoring;
    }

    /// Frames one token step covers.
    pub fn frames_per_token(&self) -> usize {
        self.tat.config().tat.frames_per_token()
    }

    /// Token steps covering `seconds`, refused outside `(0, MAX_SECONDS]`.
    pub fn steps(&self, seconds: f64) -> Result<usize> {
        if !(seconds > 0.0 && seconds <= MAX_SECONDS) {
            return Err(refuse(format!(
                "a duration must be more than 0 and at most {MAX_SECONDS} seconds; {seconds} was asked"
            )));
        }
        Ok(frames_of(seconds).div_ceil(self.frames_per_token()).max(1))
    }

    /// The generator's condition for a prompt: its sentence embedding, read as the nearest
    /// caption the generator trained on (see [`anymo_generator::anchors`]).
    pub fn text(&mut self, prompt: &str) -> Result<Vec<f32>> {
        if prompt.trim().is_empty() {
            return Err(refuse("the prompt is empty"));
        }
        Ok(self.generator.read_prompt(&self.encoder.encode(&[prompt])?.remove(0)))
    }

    /// A skeleton to animate, from a user's file: the motion is written around a pose taken
    /// from it (see [`pose_source`]).
    pub fn target(&mut self, file: &Motion) -> Result<Target> {
        let cleaned = clean(&pose_source(file), &CleanOptions::default())
            .map_err(|r| refuse(format!("the skeleton cannot be animated: {r}")))?;
        let source =
            if file.frames() > 0 { file.slice(0, 1) } else { Motion::rest_pose(file.skeleton(), 1.0 / MODEL_FPS) };
        self.prepare(source, cleaned)
    }

    /// A user's clip to edit, with its codes and where it starts.
    pub fn clip(&mut self, motion: &Motion) -> Result<(Target, Codes, [f32; 3])> {
        let target = self.prepare(motion.clone(), cleaned_clip(motion)?)?;
        let encoded = encode_whole(&mut self.tat, &target.graph, &target.entered)?;
        let Tokens { codes, start, .. } = encoded.tokens;
        Ok((target, codes.into_iter().next().unwrap_or_default(), start))
    }

    fn prepare(&mut self, source: Motion, cleaned: CleanClip) -> Result<Target> {
        let basis = Basis::of(self.tat.config().representation, cleaned.motion.skeleton(), [&cleaned.motion]);
        let entered = basis.enter(&cleaned.motion);
        let graph = Graphs::new(&mut self.encoder).of(entered.skeleton())?;
        let embedding = self.tat.skeleton_embedding(&graph)?;
        Ok(Target { source, cleaned, basis, entered, graph, embedding })
    }

    /// New motion for a prompt on a target: `request.samples` code sequences.
    pub fn generate(&mut self, prompt: &str, target: &Target, request: &Request) -> Result<Vec<Codes>> {
        let text = self.text(prompt)?;
        self.generator.generate(&text, &target.embedding, request).map_err(refusal_of)
    }

    /// New motion for a prompt on a target, rendered: `seconds` long, or as long as the length
    /// predictor says for the prompt.
    pub fn generate_motion(
        &mut self,
        prompt: &str,
        target: &Target,
        seconds: Option<f64>,
        request: &Request,
    ) -> Result<Vec<Made>> {
        let steps = match seconds {
            Some(s) => self.steps(s)?,
            None => {
                let text = self.text(prompt)?;
                self.generator.predict_steps(&text, &target.embedding)?
            }
        };
        let samples = self.generate(prompt, target, &Request { steps: Some(steps), ..request.clone() })?;
        self.render(samples, [0.0; 3], seconds.map(frames_of), target, prompt)
    }

    /// A clip with the span `from..to` seconds regenerated from a prompt and the rest kept.
    pub fn inpaint(&mut self, clip: &Motion, prompt: &str, span: (f64, f64), request: &Request) -> Result<Vec<Made>> {
        let (from, to) = span;
        if !(from >= 0.0 && to > from) {
            return Err(refuse(format!("the span must satisfy 0 <= from < to; got {from}..{to}")));
        }
        let (target, codes, start) = self.clip(clip)?;
        let per = self.frames_per_token() as f64 / MODEL_FPS;
        let duration = target.cleaned.motion.frames() as f64 / MODEL_FPS;
        if from >= duration {
            return Err(refuse(format!("the span starts at {from} s but the clip lasts {duration:.2} s")));
        }
        let keep: Vec<bool> =
            (0..codes.len()).map(|t| !((t as f64 + 1.0) * per > from && (t as f64) * per < to)).collect();
        let text = self.text(prompt)?;
        let samples = self.generator.inpaint(&text, &target.embedding, &codes, &keep, request).map_err(refusal_of)?;
        let frames = target.cleaned.motion.frames();
        self.render(samples, start, Some(frames), &target, prompt)
    }

    /// A clip followed by `seconds` of new motion from a prompt.
    pub fn extend(&mut self, clip: &Motion, prompt: &str, seconds: f64, request: &Request) -> Result<Vec<Made>> {
        let extra = self.steps(seconds)?;
        let (target, codes, start) = self.clip(clip)?;
        let text = self.text(prompt)?;
        let samples = self.generator.extend(&text, &target.embedding, &codes, extra, request).map_err(refusal_of)?;
        let frames = target.cleaned.motion.frames() + frames_of(seconds);
        self.render(samples, start, Some(frames), &target, prompt)
    }

    /// Prompts one after another on a skeleton (a user's file, see [`Studio::target`]), each
    /// `(prompt, seconds)` flowing into the next.
    /// Their prompt score is against the prompts joined by ", then ".
    pub fn chain(&mut self, file: &Motion, parts: &[(String, f64)], request: &Request) -> Result<Vec<Made>> {
        self.steps(parts.iter().map(|p| p.1).sum()).map_err(|e| refuse(format!("the chain as a whole: {e}")))?;
        let target = self.target(file)?;
        let mut conditions = Vec::with_capacity(parts.len());
        for (prompt, seconds) in parts {
            conditions.push((self.text(prompt)?, self.steps(*seconds)?));
        }
        let refs: Vec<(&[f32], usize)> = conditions.iter().map(|(t, s)| (t.as_slice(), *s)).collect();
        let samples = self.generator.chain(&refs, &target.embedding, request).map_err(refusal_of)?;
        let frames = parts.iter().map(|p| frames_of(p.1)).sum();
        let prompt: Vec<&str> = parts.iter().map(|p| p.0.as_str()).collect();
        self.render(samples, [0.0; 3], Some(frames), &target, &prompt.join(", then "))
    }

    /// Decodes samples onto the target, cut to `frames` when given, cleaned up, back on the
    /// user's skeleton and in the user's units, each with its quality report (scored against
    /// `prompt`).
    pub fn render(
        &mut self,
        samples: Vec<Codes>,
        start: [f32; 3],
        frames: Option<usize>,
        target: &Target,
        prompt: &str,
    ) -> Result<Vec<Made>> {
        let skeleton = target.entered.skeleton();
        let mut made = Vec::with_capacity(samples.len());
        for codes in samples {
            let mut tokens = Tokens::whole(codes, self.frames_per_token(), MODEL_FPS);
            tokens.start = start;
            let decoded = target.basis.leave(&detokenize(&self.tat, &tokens, &target.graph, skeleton)?);
            let decoded = decoded.slice(0, frames.unwrap_or(decoded.frames()));
            let (motion, planting) = clean_up(decoded, self.cleanup.as_ref(), &self.real);
            let text = self.text_similarity(prompt, &motion, target)?;
            let quality = QualityReport::of(&motion, planting, self.real.of(&motion), text);
            made.push(Made { motion: target.cleaned.restore(&motion, &target.source), quality });
        }
        Ok(made)
    }

    /// The cosine of the prompt and a motion (cleaned form, on the target) in the evaluator's
    /// space, when the evaluator reads this generator's tokenizer.
    fn text_similarity(&mut self, prompt: &str, motion: &Motion, target: &Target) -> Result<Option<f32>> {
        let Some(judge) = self.judge.as_ref().filter(|_| self.scoring) else { return Ok(None) };
        let encoded = encode_whole(&mut self.tat, &target.graph, &target.basis.enter(motion))?;
        let width = judge.config().max_tokens * judge.config().latent_dim;
        let motion = judge.embed_one(&encoded.latent[..encoded.latent.len().min(width)])?;
        let text = judge.embed_sentence(&self.encoder.encode(&[prompt])?.remove(0))?;
        Ok(Some(cosine(&motion, &text)))
    }
}

/// A generator error, as a refusal when the request caused it.
fn refusal_of(error: GenerationError) -> ModelError {
    match error {
        GenerationError::Model(e) => e.into(),
        refused => refuse(refused.to_string()),
    }
}
