//! The motion library's search engine, fed from the store and the models: documents and
//! caption embeddings come from the store, motion embeddings from the text-motion evaluator over
//! the tokenizer's latents (so a clip on any skeleton lands in one space), and queries become
//! vectors in both spaces.

use crate::checkpoint::Checkpoint;
use crate::codecs::Graphs;
use crate::error::ModelError;
use crate::generation;
use crate::studio::cleaned_clip;
use anyhow::{Context, Result};
use anymo_generator::Evaluator;
use anymo_motion::motion::Motion;
use anymo_retrieval::{ClipDocument, Entry, Filter, Library, Query, Space, Spaces, Weights};
use anymo_store::{IndexRecord, Store};
use anymo_tokenizer::tat::Basis;
use anymo_tokenizer::tat::Tat;
use anymo_tokenizer::tat::window::encode_whole;
use anymo_tokenizer::text::CachedEncoder;
use std::path::{Path, PathBuf};
use std::sync::{PoisonError, RwLock, RwLockReadGuard, RwLockWriteGuard};

/// Clips indexed per commit while syncing.
const BATCH: usize = 64;

/// Where the library's index lives inside a data directory.
pub fn library_dir(data_dir: &Path) -> PathBuf {
    data_dir.join("search")
}

/// The models that turn text and motion into the library's vectors.
pub struct SearchModels {
    encoder: CachedEncoder,
    tat: Tat,
    evaluator: Evaluator,
    spaces: Spaces,
}

/// Unit length (a zero vector stays zero).
fn unit(mut v: Vec<f32>) -> Vec<f32> {
    let norm = v.iter().map(|x| x * x).sum::<f32>().sqrt();
    if norm > 0.0 {
        v.iter_mut().for_each(|x| *x /= norm);
    }
    v
}

/// A clip's caption vector: the mean of its caption embeddings, unit length; `None` without
/// captions.
pub fn caption_vector(embeddings: &[Vec<f32>]) -> Option<Vec<f32>> {
    let first = embeddings.first()?;
    let mut mean = vec![0f32; first.len()];
    for e in embeddings {
        mean.iter_mut().zip(e).for_each(|(m, x)| *m += x);
    }
    Some(unit(mean))
}

impl SearchModels {
    /// Loads an evaluator checkpoint, with the tokenizer it reads.
    pub fn load(evaluator: &Checkpoint, encoder: CachedEncoder) -> Result<SearchModels> {
        let (model, card) = generation::load_evaluator(evaluator)?;
        let mut encoder = encoder;
        let tat = evaluator.load_tat_of(&card, &mut encoder)?;
        let blake3 = evaluator.weights_blake3()?;
        let motion_dim = model.embed_sentence(&[0.0; anymo_tokenizer::text::EMBEDDING_DIM])?.len();
        let spaces = Spaces {
            captions: Space { model: "all-MiniLM-L6-v2".into(), dim: anymo_tokenizer::text::EMBEDDING_DIM },
            motions: Space { model: format!("{}:{}", evaluator.name(), &blake3[..16]), dim: motion_dim },
        };
        Ok(SearchModels { encoder, tat, evaluator: model, spaces })
    }

    /// Sentence embeddings of `texts`.
    pub fn sentences(&mut self, texts: &[&str]) -> Result<Vec<Vec<f32>>> {
        Ok(self.encoder.encode(texts)?)
    }

    /// The spaces these models make vectors in.
    pub fn spaces(&self) -> &Spaces {
        &self.spaces
    }

    /// A text's vectors: its sentence embedding (caption space) and the evaluator's projection of
    /// it (motion space).
    pub fn text_vectors(&mut self, text: &str) -> Result<TextVectors, ModelError> {
        Ok(self.texts_vectors(&[text])?.remove(0))
    }

    /// [`SearchModels::text_vectors`] of several texts, their sentence embeddings computed in one
    /// batch of the encoder (a batch costs far less than its texts one at a time).
    pub fn texts_vectors(&mut self, texts: &[&str]) -> Result<Vec<TextVectors>, ModelError> {
        let sentences = self.encoder.encode(texts)?;
        sentences
            .into_iter()
            .map(|sentence| {
                let motion = self.evaluator.embed_sentence(&sentence)?;
                Ok(TextVectors { caption: unit(sentence), motion: unit(motion) })
            })
            .collect()
    }

    /// A clip's motion embedding: cleaned and resampled as for the models, then
    /// [`SearchModels::embed_cleaned`].
    pub fn motion_vector(&mut self, motion: &Motion) -> Result<Vec<f32>, ModelError> {
        self.embed_cleaned(&cleaned_clip(motion)?.motion)
    }

    /// The motion embedding of a clip already cleaned and at the models' frame rate: encoded
    /// whole by the tokenizer, embedded window by window (the evaluator reads at most its
    /// `max_tokens` steps at once) and averaged, weighted by window length.
    pub fn embed_cleaned(&mut self, motion: &Motion) -> Result<Vec<f32>, ModelError> {
        if motion.frames() < 2 {
            return Err(ModelError::refused("the clip is too short to search by (it needs at least two frames)"));
        }
        let basis = Basis::of(self.tat.config().representation, motion.skeleton(), [motion]);
        let motion = basis.enter(motion);
        let graph = Graphs::new(&mut self.encoder).of(motion.skeleton())?;
        let latent = encode_whole(&mut self.tat, &graph, &motion)?.latent;
        let config = self.evaluator.config();
        let window = config.max_tokens * config.latent_dim;
        let mut sum = vec![0f32; self.spaces.motions.dim];
        for rows in latent.chunks(window) {
            let e = self.evaluator.embed_one(rows)?;
            sum.iter_mut().zip(&e).for_each(|(s, x)| *s += x * rows.len() as f32);
        }
        Ok(unit(sum))
    }

    /// The library query for text and/or an example clip: see [`query`].
    pub fn query(
        &mut self,
        text: Option<&str>,
        like: Option<&Motion>,
        filter: Filter,
        weights: Weights,
        page: (usize, usize),
    ) -> Result<Query, ModelError> {
        let text = text.map(str::trim).filter(|t| !t.is_empty());
        let vectors = text.map(|t| self.text_vectors(t)).transpose()?;
        let example = like.map(|m| self.motion_vector(m)).transpose()?;
        Ok(query(text, vectors, example, filter, weights, page))
    }

    /// The library entry of a stored clip, given its BVH text, and why it has no motion vector
    /// when it has none.
    pub fn entry(&mut self, record: IndexRecord, bvh: &[u8]) -> (Entry, Option<String>) {
        let clip = &record.clip;
        let caption_vector = caption_vector(&record.caption_embeddings);
        let motion_vector = anymo_motion::bvh::read(bvh, anymo_motion::bvh::ReadOptions { require_motion: true })
            .map_err(|e| ModelError::Failed(e.into()))
            .and_then(|b| self.motion_vector(&Motion::from_bvh(&b)));
        let (motion_vector, problem) = match motion_vector {
            Ok(v) => (Some(v), None),
            Err(e) => (None, Some(format!("clip {} ({}) has no motion embedding: {e:#}", clip.id, clip.source_path))),
        };
        let entry = Entry {
            document: ClipDocument {
                id: clip.id as u64,
                path: clip.source_path.clone(),
                captions: clip.captions.clone(),
                subject: clip.subject.clone(),
                source: clip.source.clone(),
                licence: clip.licence.clone(),
                skeleton: record.fingerprint,
                joint_labels: record.joint_labels,
                seconds: clip.frames as f64 / clip.fps.max(1e-9),
            },
            caption_vector,
            motion_vector,
        };
        (entry, problem)
    }
}

/// A text's vectors in the library's two spaces, unit length.
#[derive(Clone, Debug, PartialEq)]
pub struct TextVectors {
    /// The sentence embedding (caption space).
    pub caption: Vec<f32>,
    /// The evaluator's projection of it (motion space).
    pub motion: Vec<f32>,
}

/// The library query for a text (with its vectors) and/or an example clip's motion vector:
/// BM25 and caption vectors from the text; the motion vector from the example when there is
/// one, else from the text.
pub fn query(
    text: Option<&str>,
    vectors: Option<TextVectors>,
    example: Option<Vec<f32>>,
    filter: Filter,
    weights: Weights,
    page: (usize, usize),
) -> Query {
    let (caption_vector, text_motion) = match vectors {
        Some(v) => (Some(v.caption), Some(v.motion)),
        None => (None, None),
    };
    Query {
        text: text.map(String::from),
        caption_vector,
        motion_vector: example.or(text_motion),
        filter,
        weights,
        offset: page.0,
        limit: page.1,
    }
}

/// What a sync changed.
#[derive(Debug, Default, PartialEq)]
pub struct SyncReport {
    /// Clips indexed (new, or missing a vector).
    pub indexed: usize,
    /// Clips removed (no longer in the store).
    pub removed: usize,
    /// Clips indexed without a motion vector, and why (they are found by text only, and are
    /// tried again at the next sync).
    pub without_motion: Vec<String>,
}

/// Brings `library` up to date with `store`: indexes stored clips it lacks or holds without
/// their vectors, and removes clips the store no longer has. Commits every [`BATCH`] clips, so
/// an interrupted sync keeps what it did; the library is locked for writing only while a batch
/// goes in, so searches go on while a long sync embeds. `progress(done, pending)` is called
/// after each batch.
pub async fn sync(
    store: &Store,
    library: &RwLock<Library>,
    models: &mut SearchModels,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<SyncReport> {
    let stored = store.clip_ids().await?;
    let stored_set: std::collections::HashSet<u64> = stored.iter().map(|&id| id as u64).collect();
    let gone: Vec<u64> = read(library).ids().into_iter().filter(|id| !stored_set.contains(id)).collect();
    write(library).remove(&gone)?;
    let pending: Vec<i64> = {
        let library = read(library);
        let incomplete: std::collections::HashSet<u64> = library.incomplete().into_iter().collect();
        stored.into_iter().filter(|&id| !library.contains(id as u64) || incomplete.contains(&(id as u64))).collect()
    };
    let mut report = SyncReport { indexed: pending.len(), removed: gone.len(), without_motion: Vec::new() };
    let mut done = 0;
    for batch in pending.chunks(BATCH) {
        let mut entries = Vec::with_capacity(batch.len());
        for &id in batch {
            let (Some(record), Some(bvh)) = (store.index_record(id).await?, store.clip_bvh(id).await?) else {
                continue;
            };
            let (entry, problem) = models.entry(record, &bvh);
            report.without_motion.extend(problem);
            entries.push(entry);
        }
        write(library).upsert(entries)?;
        done += batch.len();
        progress(done, pending.len());
    }
    Ok(report)
}

/// The library for reading. A holder that panicked left it as its last commit did, so the
/// lock's poisoning is not an error here.
pub fn read(library: &RwLock<Library>) -> RwLockReadGuard<'_, Library> {
    library.read().unwrap_or_else(PoisonError::into_inner)
}

/// The library for writing (see [`read`] on poisoning).
pub fn write(library: &RwLock<Library>) -> RwLockWriteGuard<'_, Library> {
    library.write().unwrap_or_else(PoisonError::into_inner)
}

/// Opens the library of a data directory for `models`, ready to sync.
pub fn open_library(data_dir: &Path, models: &SearchModels) -> Result<Library> {
    let dir = library_dir(data_dir);
    Library::open(&dir, models.spaces().clone())
        .with_context(|| format!("opening the search index in {}", dir.display()))
}
