//! Motion to TAT tokens and back, on the source skeleton or any other, as users meet it: the
//! CLI's `tokenize`, `detokenize` and `transfer` and the server's token endpoints use it.

use super::codecs::Graphs;
use super::data::MODEL_FPS;
use super::studio::{cleaned_clip, pose_source};
use crate::checkpoint::Checkpoint;
use crate::error::ModelError;
use crate::quality::{Made, QualityReport, RealMotion, clean_up};
use anymo_motion::cleanup::Cleanup;
use anymo_motion::motion::Motion;
use anymo_motion::prep::clean::{CleanOptions, clean};
use anymo_tokenizer::tat::window::{Tokens, detokenize, tokenize};
use anymo_tokenizer::tat::{Basis, Representation, Tat, anchor};
use anymo_tokenizer::text::CachedEncoder;
use serde::{Deserialize, Serialize};

/// The highest frame rate decoded motion is written at.
pub const MAX_FPS: f64 = 1000.0;

type Result<T, E = ModelError> = std::result::Result<T, E>;

/// The tokens file: the tokens and the checkpoint that made them.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TokenFile {
    /// The tokenizer checkpoint's name.
    pub model: String,
    /// Its training steps (which version of it).
    pub model_steps: u64,
    /// The tokens.
    pub tokens: Tokens,
}

/// A trained tokenizer with the sentence encoder its skeleton graphs need, the cleanup decoded
/// motion gets and the real clips' figures its quality reports compare with.
pub struct TokenCodec {
    tat: Tat,
    name: String,
    steps: u64,
    encoder: CachedEncoder,
    cleanup: Option<Cleanup>,
    real: RealMotion,
}

impl TokenCodec {
    /// Loads a tokenizer checkpoint.
    pub fn load(tokenizer: &Checkpoint, encoder: CachedEncoder) -> anyhow::Result<TokenCodec> {
        let mut encoder = encoder;
        let (tat, card) = tokenizer.load_tat(&mut encoder)?;
        let name = tokenizer.name().to_string();
        Ok(TokenCodec {
            tat,
            name,
            steps: card.steps,
            encoder,
            cleanup: Some(Cleanup::default()),
            real: RealMotion::default(),
        })
    }

    /// Sets the cleanup decoded motion gets (`None` gives the decoder's output as it is).
    pub fn set_cleanup(&mut self, cleanup: Option<Cleanup>) {
        self.cleanup = cleanup;
    }

    /// Sets the real clips' figures the quality reports compare with.
    pub fn set_real_motion(&mut self, real: RealMotion) {
        self.real = real;
    }

    /// A clip's tokens. A tokenizer of the reference representation reads the clip against
    /// its own mean pose.
    pub fn tokenize(&mut self, motion: &Motion) -> Result<TokenFile> {
        let cleaned = cleaned_clip(motion)?;
        let basis = Basis::of(self.tat.config().representation, cleaned.motion.skeleton(), [&cleaned.motion]);
        let entered = basis.enter(&cleaned.motion);
        let graph = Graphs::new(&mut self.encoder).of(entered.skeleton())?;
        let tokens = tokenize(&mut self.tat, &graph, &entered)?;
        Ok(TokenFile { model: self.name.clone(), model_steps: self.steps, tokens })
    }

    /// Tokens as motion on `target`'s skeleton (in its units, with its hierarchy and channels)
    /// at `fps` frames per second, refused when they do not fit this checkpoint or do not
    /// describe a clip. A tokenizer of the reference representation writes the motion around
    /// a pose taken from the target (see [`pose_source`]). The motion is
    /// cleaned up (see [`TokenCodec::set_cleanup`]) and comes with its quality report.
    pub fn detokenize(&mut self, tokens: &Tokens, target: &Motion, fps: f64) -> Result<Made> {
        self.check(tokens).map_err(ModelError::Refused)?;
        if !(fps > 0.0 && fps <= MAX_FPS) {
            return Err(ModelError::refused(format!("the frame rate must be in (0, {MAX_FPS}]; {fps} was asked")));
        }
        let representation = self.tat.config().representation;
        let rest = || Motion::rest_pose(target.skeleton(), 1.0 / MODEL_FPS);
        let posed = if representation == Representation::Reference { pose_source(target) } else { rest() };
        let source = if target.frames() > 0 { target.slice(0, 1) } else { rest() };
        let cleaned = clean(&posed, &CleanOptions::default())
            .map_err(|r| ModelError::refused(format!("the skeleton cannot be used as a target: {r}")))?;
        let basis = Basis::of(representation, cleaned.motion.skeleton(), [&cleaned.motion]);
        let skeleton = basis.enter_skeleton(&cleaned.motion);
        let graph = Graphs::new(&mut self.encoder).of(&skeleton)?;
        let decoded = basis.leave(&detokenize(&self.tat, tokens, &graph, &skeleton)?);
        let (decoded, planting) = clean_up(decoded, self.cleanup.as_ref(), &self.real);
        let quality = QualityReport::of(&decoded, planting, self.real.of(&decoded), None);
        let restored = cleaned.restore(&decoded, &source);
        // The models run at MODEL_FPS; the answer comes at the rate asked for.
        let motion = if (restored.fps() - fps).abs() > 1e-9 { restored.resample(fps) } else { restored };
        Ok(Made { motion, quality })
    }

    /// Why tokens (perhaps from a client) cannot be decoded by this checkpoint, if they cannot:
    /// the codes must fit its codebooks, every window must hold the same whole number of steps
    /// and cover the window, the windows must start inside the clip, in order, covering it, and
    /// the root anchors must lie inside it, in order.
    fn check(&self, tokens: &Tokens) -> Result<(), String> {
        let (layers, codes) = (self.tat.config().rvq.layers, self.tat.config().rvq.codes as u32);
        let per_token = self.tat.config().tat.frames_per_token();
        let steps = tokens.codes.first().map_or(0, Vec::len);
        let depth = tokens.codes.first().and_then(|w| w.first()).map_or(0, Vec::len);
        if steps == 0 || depth == 0 {
            return Err("the tokens hold no steps".into());
        }
        if depth > layers || tokens.codes.iter().flatten().flatten().any(|&c| c >= codes) {
            return Err(format!("the tokens do not fit checkpoint {} ({layers} layers of {codes} codes)", self.name));
        }
        if tokens.codes.iter().any(|w| w.len() != steps || w.iter().any(|step| step.len() != depth)) {
            return Err(format!("every window must hold {steps} steps of {depth} codes, as the first does"));
        }
        if tokens.window != steps * per_token {
            return Err(format!(
                "a window of {steps} steps covers {} frames, not {}",
                steps * per_token,
                tokens.window
            ));
        }
        let ordered = tokens.starts.first() == Some(&0) && tokens.starts.windows(2).all(|p| p[0] < p[1]);
        if tokens.starts.len() != tokens.codes.len() || !ordered {
            return Err("starts must be one ascending first frame per window, from 0".into());
        }
        let last = *tokens.starts.last().expect("one start per window");
        if tokens.frames == 0 || last >= tokens.frames || tokens.frames > last + tokens.window {
            return Err(format!("{} frames are not covered by windows starting at {:?}", tokens.frames, tokens.starts));
        }
        if !(tokens.fps > 0.0 && tokens.fps <= 1000.0 && tokens.start.iter().all(|v| v.is_finite())) {
            return Err("fps must be in (0, 1000] and the start finite".into());
        }
        anchor::check(&tokens.anchors, tokens.frames)
    }

    /// A clip moved onto `target`'s skeleton through tokens, at `fps` frames per second (see
    /// [`TokenCodec::detokenize`] for what the target's frames mean).
    pub fn transfer(&mut self, motion: &Motion, target: &Motion, fps: f64) -> Result<Made> {
        let file = self.tokenize(motion)?;
        self.detokenize(&file.tokens, target, fps)
    }
}
