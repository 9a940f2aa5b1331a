//! The generator: a first-layer token model (masked or autoregressive), the residual
//! transformer and the length predictor under one set of parameters, and what users ask of it:
//! generation of any length, inpainting, continuation and prompt chains.

use crate::anchors::CaptionAnchors;
use crate::autoregressive::Autoregressive;
use crate::condition::Condition;
use crate::corpus::{TokenClip, draw_batch};
use crate::length::LengthPredictor;
use crate::masked::MaskedTransformer;
use crate::residual::ResidualTransformer;
use crate::sampling::Sampling;
use crate::token_model::TokenModel;
use crate::trunk::TrunkConfig;
use anymo_tokenizer::nn::Params;
use candle_core::Tensor;
type Result<T, E = candle_core::Error> = std::result::Result<T, E>;
use rand::{Rng, RngCore, SeedableRng};
use serde::{Deserialize, Serialize};

/// Which first-layer model.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum Kind {
    /// MoMask's masked transformer with iterative decoding.
    Masked,
    /// T2M-GPT's next-token transformer.
    Autoregressive,
}

/// Everything that defines a generator checkpoint.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct GeneratorConfig {
    /// The first-layer model.
    pub kind: Kind,
    /// Its trunk.
    pub base: TrunkConfig,
    /// The residual transformer's trunk.
    pub residual: TrunkConfig,
    /// RVQ layers.
    pub layers: usize,
    /// Codes per layer.
    pub codes: usize,
    /// Iterations of masked decoding.
    pub decoding_steps: usize,
    /// Probability that training drops the prompt (for classifier-free guidance).
    pub text_dropout: f32,
    /// Length of the Gaussian noise training adds to each prompt embedding (a unit vector)
    /// before setting it back to unit length, so that nearby wordings condition alike; 0 for
    /// none (generators trained before it existed).
    #[serde(default)]
    pub text_noise: f32,
    /// Hidden width of the length predictor.
    pub length_hidden: usize,
}

impl GeneratorConfig {
    /// The default shape for a tokenizer of `layers x codes` and skeleton embeddings of
    /// `skeleton_dim`.
    pub fn new(kind: Kind, skeleton_dim: usize, layers: usize, codes: usize) -> GeneratorConfig {
        let trunk = TrunkConfig { dim: 192, layers: 4, heads: 4, ff: 384, max_tokens: 64, skeleton_dim };
        GeneratorConfig {
            kind,
            base: trunk,
            residual: TrunkConfig { layers: 3, ..trunk },
            layers,
            codes,
            decoding_steps: 10,
            text_dropout: 0.1,
            text_noise: 0.0,
            length_hidden: 192,
        }
    }

    /// Longest sequence one pass generates; longer ones continue window by window.
    pub fn max_tokens(&self) -> usize {
        self.base.max_tokens
    }
}

/// What a user asks for.
#[derive(Clone, Debug)]
pub struct Request {
    /// Token steps to generate (`None`: the length predictor decides).
    pub steps: Option<usize>,
    /// Samples to draw.
    pub samples: usize,
    /// How tokens are drawn.
    pub sampling: Sampling,
    /// Seed of the draw: the same request and seed give the same motion.
    pub seed: u64,
}

/// Why a generation cannot run.
#[derive(Debug, thiserror::Error)]
pub enum GenerationError {
    /// Zero samples or zero steps asked for.
    #[error("nothing to generate: ask for at least one sample of at least one token step")]
    Empty,
    /// The codes given to an edit do not fit the model.
    #[error("the clip's tokens do not fit this generator ({layers} layers of {codes} codes)")]
    CodesDoNotFit {
        /// Layers the generator knows.
        layers: usize,
        /// Codes per layer.
        codes: usize,
    },
    /// A model error.
    #[error(transparent)]
    Model(#[from] candle_core::Error),
}

/// Codes of one sample: `steps x layers`.
pub type Codes = Vec<Vec<u32>>;

/// The trained generator.
pub struct Generator {
    config: GeneratorConfig,
    params: Params,
    base: Box<dyn TokenModel + Send + Sync>,
    residual: ResidualTransformer,
    length: LengthPredictor,
    anchors: Option<CaptionAnchors>,
}

impl Generator {
    /// A fresh generator initialised from `seed`.
    pub fn new(config: GeneratorConfig, seed: u64) -> Result<Generator> {
        let mut params = Params::new(seed);
        let base: Box<dyn TokenModel + Send + Sync> = match config.kind {
            Kind::Masked => {
                Box::new(MaskedTransformer::new(&mut params, &config.base, config.codes, config.decoding_steps)?)
            }
            Kind::Autoregressive => Box::new(Autoregressive::new(&mut params, &config.base, config.codes)?),
        };
        let residual = ResidualTransformer::new(&mut params, &config.residual, config.layers, config.codes)?;
        let length =
            LengthPredictor::new(&mut params, config.base.skeleton_dim, config.length_hidden, config.max_tokens())?;
        Ok(Generator { config, params, base, residual, length, anchors: None })
    }

    /// The configuration.
    pub fn config(&self) -> &GeneratorConfig {
        &self.config
    }

    /// The parameters.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Keeps the captions the generator trained on with its weights (saved as buffers, see
    /// [`crate::anchors`]), so that [`Generator::read_prompt`] reads prompts as them.
    pub fn set_anchors(&mut self, anchors: CaptionAnchors) -> Result<()> {
        for (name, tensor) in anchors.to_tensors()? {
            self.params.set_buffer(name, tensor);
        }
        self.anchors = Some(anchors);
        Ok(())
    }

    /// The condition a prompt's sentence embedding gives: the nearest caption the generator
    /// trained on when the prompt is far from all of them (see [`crate::anchors`]), else the
    /// embedding itself, as for a generator saved without its captions.
    pub fn read_prompt(&self, text: &[f32]) -> Vec<f32> {
        match &self.anchors {
            Some(anchors) => anchors.read(text),
            None => text.to_vec(),
        }
    }

    /// The parameters, for loading.
    pub fn params_mut(&mut self) -> &mut Params {
        &mut self.params
    }

    /// Training loss on crops `(B, L, layers)` of clips `clip_steps` long: the first-layer,
    /// residual and length terms, and their sum.
    pub fn loss(
        &self,
        codes: &[Codes],
        text: &[&[f32]],
        skeleton: &[&[f32]],
        clip_steps: &[usize],
        rng: &mut dyn RngCore,
    ) -> Result<(Tensor, [f32; 3])> {
        let noisy: Vec<Vec<f32>> = text.iter().map(|t| with_noise(t, self.config.text_noise, rng)).collect();
        let noisy: Vec<&[f32]> = noisy.iter().map(Vec::as_slice).collect();
        let full = Condition::new(&noisy, skeleton)?;
        let zero = vec![0f32; text[0].len()];
        let dropped: Vec<&[f32]> =
            noisy.iter().map(|&t| if rng.random::<f32>() < self.config.text_dropout { &zero[..] } else { t }).collect();
        let condition = Condition::new(&dropped, skeleton)?;
        let first: Vec<Vec<u32>> = codes.iter().map(|row| row.iter().map(|step| step[0]).collect()).collect();
        let base = self.base.loss(&first, &condition, rng)?;
        let residual = self.residual.loss(codes, &condition, rng)?;
        let length = self.length.loss(&full, clip_steps)?;
        let total = ((&base + &residual)? + (&length * 0.1)?)?;
        let parts = [base.to_scalar::<f32>()?, residual.to_scalar::<f32>()?, length.to_scalar::<f32>()?];
        Ok((total, parts))
    }

    /// The training loss on a batch of `batch` crops drawn from `clips` (see [`Generator::loss`]).
    pub fn batch_loss(&self, clips: &[TokenClip], batch: usize, rng: &mut dyn RngCore) -> Result<(Tensor, [f32; 3])> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(rng.next_u64());
        let (length, crops) = draw_batch(clips, batch, self.config.max_tokens(), &mut rng);
        let codes: Vec<Codes> = crops.iter().map(|c| clips[c.clip].codes[c.start..c.start + length].to_vec()).collect();
        let text: Vec<&[f32]> = crops.iter().map(|c| clips[c.clip].text[c.caption].as_slice()).collect();
        let skeleton: Vec<&[f32]> = crops.iter().map(|c| clips[c.clip].skeleton.as_slice()).collect();
        let steps: Vec<usize> = crops.iter().map(|c| clips[c.clip].steps()).collect();
        self.loss(&codes, &text, &skeleton, &steps, &mut rng)
    }

    /// Token steps the length predictor gives a prompt on a skeleton.
    pub fn predict_steps(&self, text: &[f32], skeleton: &[f32]) -> Result<usize> {
        Ok(self.length.predict(&Condition::new(&[text], &[skeleton])?)?[0])
    }

    /// New motion: `request.samples` code sequences for a prompt on a skeleton.
    pub fn generate(&self, text: &[f32], skeleton: &[f32], request: &Request) -> Result<Vec<Codes>, GenerationError> {
        let steps = match request.steps {
            Some(steps) => steps,
            None => self.predict_steps(text, skeleton)?,
        };
        self.fill(text, skeleton, vec![None; steps], request)
    }

    /// Temporal inpainting: a clip's codes with the steps where `keep` is false regenerated from
    /// the prompt.
    pub fn inpaint(
        &self,
        text: &[f32],
        skeleton: &[f32],
        codes: &[Vec<u32>],
        keep: &[bool],
        request: &Request,
    ) -> Result<Vec<Codes>, GenerationError> {
        self.check(codes)?;
        let known = codes.iter().zip(keep).map(|(c, &k)| k.then(|| c.clone())).collect();
        self.fill(text, skeleton, known, request)
    }

    /// Continuation: a clip's codes followed by `extra` new steps from the prompt.
    pub fn extend(
        &self,
        text: &[f32],
        skeleton: &[f32],
        codes: &[Vec<u32>],
        extra: usize,
        request: &Request,
    ) -> Result<Vec<Codes>, GenerationError> {
        self.check(codes)?;
        let known = codes.iter().cloned().map(Some).chain(std::iter::repeat_n(None, extra)).collect();
        self.fill(text, skeleton, known, request)
    }

    /// Prompts one after another (each with its steps), every part generated as the
    /// continuation of what came before, so the transitions are the model's own.
    pub fn chain(
        &self,
        parts: &[(&[f32], usize)],
        skeleton: &[f32],
        request: &Request,
    ) -> Result<Vec<Codes>, GenerationError> {
        let Some((&(first_text, first_steps), rest)) = parts.split_first() else {
            return Err(GenerationError::Empty);
        };
        let mut samples = self.fill(first_text, skeleton, vec![None; first_steps], request)?;
        for (k, &(text, steps)) in rest.iter().enumerate() {
            let mut next = Vec::with_capacity(samples.len());
            for (s, sample) in samples.iter().enumerate() {
                let one =
                    Request { samples: 1, seed: request.seed ^ ((k as u64 + 1) << 32 | s as u64), ..request.clone() };
                let known = sample.iter().cloned().map(Some).chain(std::iter::repeat_n(None, steps)).collect();
                next.push(self.fill(text, skeleton, known, &one)?.remove(0));
            }
            samples = next;
        }
        Ok(samples)
    }

    fn check(&self, codes: &[Vec<u32>]) -> Result<(), GenerationError> {
        let fits = codes
            .iter()
            .all(|step| step.len() == self.config.layers && step.iter().all(|&c| (c as usize) < self.config.codes));
        if fits {
            Ok(())
        } else {
            Err(GenerationError::CodesDoNotFit { layers: self.config.layers, codes: self.config.codes })
        }
    }

    /// Fills the unknown steps of `known` once per sample. Sample `k` draws from its own
    /// generator (seeded from the request's seed and `k`), so it is the same whatever the
    /// number of samples asked for.
    fn fill(
        &self,
        text: &[f32],
        skeleton: &[f32],
        known: Vec<Option<Vec<u32>>>,
        request: &Request,
    ) -> Result<Vec<Codes>, GenerationError> {
        if request.samples == 0 || known.is_empty() {
            return Err(GenerationError::Empty);
        }
        let condition = Condition::new(&[text], &[skeleton])?;
        (0..request.samples)
            .map(|k| {
                let seed = request.seed.wrapping_add((k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
                Ok(self.fill_one(&condition, known.clone(), &request.sampling, &mut rng)?)
            })
            .collect()
    }

    /// One sample, window by window when longer than one pass: each later window keeps the
    /// second half of the one before it as context.
    fn fill_one(
        &self,
        condition: &Condition,
        known: Vec<Option<Vec<u32>>>,
        sampling: &Sampling,
        rng: &mut dyn RngCore,
    ) -> Result<Codes> {
        let max = self.config.max_tokens();
        let total = known.len();
        let mut state = known;
        let mut start = 0;
        loop {
            let end = (start + max).min(total);
            if state[start..end].iter().any(Option::is_none) {
                let window = vec![state[start..end].to_vec()];
                let filled = self.fill_window(condition, &window, sampling, rng)?.remove(0);
                for (slot, step) in state[start..end].iter_mut().zip(filled) {
                    *slot = Some(step);
                }
            }
            if end == total {
                break;
            }
            start = end - max / 2;
        }
        Ok(state.into_iter().map(|s| s.expect("filled")).collect())
    }

    fn fill_window(
        &self,
        condition: &Condition,
        known: &[Vec<Option<Vec<u32>>>],
        sampling: &Sampling,
        rng: &mut dyn RngCore,
    ) -> Result<Vec<Codes>> {
        let first: Vec<Vec<Option<u32>>> =
            known.iter().map(|row| row.iter().map(|s| s.as_ref().map(|c| c[0])).collect()).collect();
        let base = self.base.sample(condition, &first, sampling, rng)?;
        let residual_known: Vec<Vec<Vec<Option<u32>>>> = known
            .iter()
            .map(|row| {
                row.iter()
                    .map(|s| match s {
                        Some(c) => c.iter().copied().map(Some).collect(),
                        None => vec![None; self.config.layers],
                    })
                    .collect()
            })
            .collect();
        self.residual.sample(condition, &base, &residual_known, sampling, rng)
    }
}

/// A unit embedding moved by Gaussian noise of expected length `length` and set back to unit
/// length (unchanged for `length` 0).
fn with_noise(embedding: &[f32], length: f32, rng: &mut dyn RngCore) -> Vec<f32> {
    if length == 0.0 {
        return embedding.to_vec();
    }
    let sigma = length / (embedding.len() as f32).sqrt();
    let normal = rand_distr::Normal::new(0.0, sigma).expect("a finite, non-negative deviation");
    let moved: Vec<f32> = embedding.iter().map(|x| x + rand_distr::Distribution::sample(&normal, rng)).collect();
    let norm = moved.iter().map(|x| x * x).sum::<f32>().sqrt().max(f32::MIN_POSITIVE);
    moved.into_iter().map(|x| x / norm).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::condition::TEXT_DIM;

    fn tiny(kind: Kind) -> Generator {
        let mut config = GeneratorConfig::new(kind, 8, 3, 16);
        for trunk in [&mut config.base, &mut config.residual] {
            *trunk = TrunkConfig { dim: 16, layers: 1, heads: 2, ff: 32, max_tokens: 8, skeleton_dim: 8 };
        }
        config.length_hidden = 16;
        config.decoding_steps = 4;
        Generator::new(config, 3).unwrap()
    }

    fn request(samples: usize) -> Request {
        Request { steps: Some(5), samples, sampling: Sampling::default(), seed: 11 }
    }

    #[test]
    fn edits_keep_what_they_are_given_for_both_kinds() {
        let text = vec![0.05; TEXT_DIM];
        let skeleton = vec![0.1; 8];
        for kind in [Kind::Masked, Kind::Autoregressive] {
            let g = tiny(kind);
            let clip: Codes = (0..6).map(|t| vec![t as u32, (t * 2) as u32, 15 - t as u32]).collect();
            let keep = [true, true, false, false, true, true];
            for sample in g.inpaint(&text, &skeleton, &clip, &keep, &request(2)).unwrap() {
                assert_eq!(sample.len(), 6);
                for t in [0, 1, 4, 5] {
                    assert_eq!(sample[t], clip[t], "{kind:?} kept step {t}");
                }
                assert!(sample.iter().all(|s| s.len() == 3 && s.iter().all(|&c| c < 16)));
            }
            // Longer than one pass (8 steps): the window slides and the clip stays a prefix.
            let longer = g.extend(&text, &skeleton, &clip, 9, &request(1)).unwrap().remove(0);
            assert_eq!(longer.len(), 15);
            assert_eq!(longer[..6], clip[..]);
            let chained = g.chain(&[(&text, 3), (&text, 4)], &skeleton, &request(1)).unwrap().remove(0);
            assert_eq!(chained.len(), 7);
        }
    }

    #[test]
    fn prompt_noise_moves_an_embedding_by_about_its_length_and_keeps_it_unit() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let unit: Vec<f32> = (0..TEXT_DIM).map(|i| if i == 0 { 1.0 } else { 0.0 }).collect();
        assert_eq!(with_noise(&unit, 0.0, &mut rng), unit);
        let draws = 200;
        let mut cosine = 0.0;
        for _ in 0..draws {
            let moved = with_noise(&unit, 0.3, &mut rng);
            let norm = moved.iter().map(|x| x * x).sum::<f32>().sqrt();
            assert!((norm - 1.0).abs() < 1e-5, "{norm}");
            cosine += moved[0] / draws as f32;
        }
        // Noise of length 0.3 at right angles to most of the vector: cos = 1 / sqrt(1 + 0.09).
        assert!((cosine - 1.0 / 1.09f32.sqrt()).abs() < 0.01, "{cosine}");
    }

    #[test]
    fn samples_are_seeded_one_by_one_and_bad_requests_are_refused() {
        let g = tiny(Kind::Masked);
        let (text, skeleton) = (vec![0.05; TEXT_DIM], vec![0.1; 8]);
        let one = g.generate(&text, &skeleton, &request(1)).unwrap();
        let three = g.generate(&text, &skeleton, &request(3)).unwrap();
        assert_eq!(one[0], three[0]);
        assert_eq!(three.len(), 3);
        assert!(matches!(g.generate(&text, &skeleton, &request(0)), Err(GenerationError::Empty)));
        let foreign: Codes = vec![vec![99, 0, 0]];
        assert!(matches!(
            g.inpaint(&text, &skeleton, &foreign, &[false], &request(1)),
            Err(GenerationError::CodesDoNotFit { layers: 3, codes: 16 })
        ));
        let predicted = g.predict_steps(&text, &skeleton).unwrap();
        assert!((1..=8).contains(&predicted));
    }

    #[test]
    fn every_parameter_learns() {
        for kind in [Kind::Masked, Kind::Autoregressive] {
            let g = tiny(kind);
            let codes: Vec<Codes> =
                (0..4).map(|r| (0..5).map(|t| vec![(r + t) as u32 % 16, t as u32, r as u32]).collect()).collect();
            let text: Vec<Vec<f32>> = (0..4).map(|r| vec![0.01 * r as f32; TEXT_DIM]).collect();
            let text: Vec<&[f32]> = text.iter().map(Vec::as_slice).collect();
            let skeleton = vec![0.2f32; 8];
            let skeletons = vec![skeleton.as_slice(); 4];
            let mut learned = std::collections::BTreeSet::new();
            for seed in 0..8 {
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
                let (loss, _) = g.loss(&codes, &text, &skeletons, &[5, 6, 7, 9], &mut rng).unwrap();
                let grads = loss.backward().unwrap();
                for (name, var) in g.params().vars() {
                    let grad = grads
                        .get(var.as_tensor())
                        .map(|t| t.abs().unwrap().sum_all().unwrap().to_scalar::<f32>().unwrap());
                    if grad.is_some_and(|v| v > 0.0) {
                        learned.insert(name.clone());
                    }
                }
            }
            let missing: Vec<&String> = g.params().vars().map(|(n, _)| n).filter(|n| !learned.contains(*n)).collect();
            assert!(missing.is_empty(), "{kind:?}: no gradient reaches {missing:?}");
        }
    }
}
