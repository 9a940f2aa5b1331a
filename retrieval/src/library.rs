//! The search engine over a motion library: clip documents in the tantivy index, caption
//! embeddings and motion embeddings in exact vector indexes, and hybrid ranking that fuses the
//! three by reciprocal rank fusion under one filter.
//!
//! On disk (`dir/`): `text/` (tantivy), `captions.vec`, `motions.vec` and `models.json` (which
//! models made the vectors; vectors of another model are dropped on open and must be
//! recomputed). The tantivy commit is the commit point: vectors are saved before it when adding
//! and after it when removing, so after a crash every catalogued clip has the vectors it was
//! given, and stray vectors of uncatalogued clips are pruned on open.

use crate::document::ClipDocument;
use crate::filter::{Allowed, Filter, FilterError, FilterKey};
use crate::fusion::{DEFAULT_K, Retrieved, fuse_with_coverage};
use crate::text::{Snippet, TextIndex};
use crate::vector::{ExactIndex, IndexError, VectorIndex};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Most results one page may hold.
pub const MAX_LIMIT: usize = 100;
/// Deepest result a query may reach (offset + limit).
pub const MAX_DEPTH: usize = 1000;
/// Each retriever contributes at least this many candidates to the fusion, so a page's order
/// does not depend on how deep it is.
const MIN_CANDIDATES: usize = 100;

/// Why the library failed.
#[derive(Debug, thiserror::Error)]
pub enum SearchError {
    /// The full-text index failed.
    #[error("text index: {0}")]
    Text(#[from] tantivy::TantivyError),
    /// A vector index failed.
    #[error(transparent)]
    Vector(#[from] IndexError),
    /// The filter cannot be applied.
    #[error(transparent)]
    Filter(#[from] FilterError),
    /// A page outside the limits.
    #[error("{what} must be between {min} and {max}; {got} was asked")]
    Limit {
        /// What was out of range.
        what: &'static str,
        /// Smallest allowed.
        min: usize,
        /// Largest allowed.
        max: usize,
        /// What was asked.
        got: usize,
    },
    /// A query with nothing to search by.
    #[error("a search needs text, an example clip, or both")]
    NothingToSearch,
    /// `models.json` could not be read or written.
    #[error("{path}: {reason}")]
    Models {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
}

/// A vector space: the model that makes the vectors, and their width.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Space {
    /// The model's identity (name and checkpoint hash).
    pub model: String,
    /// Vector width.
    pub dim: usize,
}

/// The two vector spaces of a library.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Spaces {
    /// Sentence embeddings of captions (and of text queries).
    pub captions: Space,
    /// The text-motion evaluator's joint space: motion embeddings of clips, and the embeddings
    /// of text queries and example clips compared with them.
    pub motions: Space,
}

/// A clip to add, with its vectors in the library's spaces.
#[derive(Clone, Debug)]
pub struct Entry {
    /// What is indexed and shown.
    pub document: ClipDocument,
    /// Mean of the caption embeddings, unit length; `None` without captions.
    pub caption_vector: Option<Vec<f32>>,
    /// The motion embedding, unit length; `None` when the clip could not be embedded.
    pub motion_vector: Option<Vec<f32>>,
}

/// How much each retriever counts in the fusion; 0 leaves it out.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Weights {
    /// BM25 over the text fields.
    pub bm25: f32,
    /// Query sentence embedding against caption embeddings.
    pub captions: f32,
    /// Query embedding (of text or of an example) against motion embeddings.
    pub motions: f32,
    /// BM25's weight is multiplied by the share of the query's words that the library holds,
    /// raised to this power (0: not at all). A query worded unlike every caption ("somebody
    /// bids farewell") matches only incidental words, and its BM25 list should then count
    /// little; a query in the library's own words keeps BM25's full weight.
    pub bm25_known_exponent: f32,
}

impl Weights {
    /// Plain reciprocal rank fusion with these weights (BM25 not scaled by known words).
    pub fn new(bm25: f32, captions: f32, motions: f32) -> Weights {
        Weights { bm25, captions, motions, bm25_known_exponent: 0.0 }
    }
}

impl Default for Weights {
    /// The weights `anymo eval retrieval --calibrate` chose on the development half of the
    /// paraphrase benchmark (docs/measurements/search.md): the sentence embeddings lead,
    /// BM25 counts fully only for queries in the library's own words.
    fn default() -> Weights {
        Weights { bm25: 0.25, captions: 1.0, motions: 0.125, bm25_known_exponent: 4.0 }
    }
}

/// A search: any of text (BM25), a caption-space vector and a motion-space vector, under a
/// filter, one page at a time.
#[derive(Clone, Debug, Default)]
pub struct Query {
    /// Words for BM25 and snippets.
    pub text: Option<String>,
    /// The text's sentence embedding.
    pub caption_vector: Option<Vec<f32>>,
    /// The text's or an example clip's embedding in the motion space.
    pub motion_vector: Option<Vec<f32>>,
    /// Which clips may be returned.
    pub filter: Filter,
    /// Retriever weights.
    pub weights: Weights,
    /// Results skipped (for later pages).
    pub offset: usize,
    /// Results returned.
    pub limit: usize,
}

/// Where a clip ranked in each retriever (1 is best).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Ranks {
    /// BM25 rank.
    pub bm25: Option<usize>,
    /// Caption-vector rank.
    pub captions: Option<usize>,
    /// Motion-vector rank.
    pub motions: Option<usize>,
}

/// One result.
#[derive(Clone, Debug)]
pub struct Found {
    /// The clip.
    pub document: ClipDocument,
    /// Fused score (higher is better).
    pub score: f32,
    /// Ranks in each retriever.
    pub ranks: Ranks,
    /// The caption that best matches the query's words, marked.
    pub snippet: Option<Snippet>,
}

/// A page of results.
#[derive(Clone, Debug)]
pub struct Page {
    /// The results, best first.
    pub hits: Vec<Found>,
    /// Candidates the fusion ranked (the results there are to page through).
    pub candidates: usize,
}

struct Catalogued {
    document: ClipDocument,
    key: FilterKey,
}

/// A searchable motion library.
pub struct Library {
    text: TextIndex,
    captions: ExactIndex,
    motions: ExactIndex,
    catalog: HashMap<u64, Catalogued>,
    spaces: Spaces,
    dir: Option<PathBuf>,
}

impl Library {
    /// An empty library in memory only.
    pub fn in_memory(spaces: Spaces) -> Library {
        Library {
            text: TextIndex::in_memory(),
            captions: ExactIndex::new(spaces.captions.dim),
            motions: ExactIndex::new(spaces.motions.dim),
            catalog: HashMap::new(),
            spaces,
            dir: None,
        }
    }

    /// Opens the library in `dir` (creating it), keeping the vectors made by `spaces`' models
    /// and dropping those of other models; [`Library::incomplete`] then lists what to recompute.
    pub fn open(dir: &Path, spaces: Spaces) -> Result<Library, SearchError> {
        let text = TextIndex::open(&dir.join("text"))?;
        let models_path = dir.join("models.json");
        let previous: Option<Spaces> = match std::fs::read(&models_path) {
            Ok(bytes) => Some(
                serde_json::from_slice(&bytes)
                    .map_err(|e| SearchError::Models { path: models_path.clone(), reason: e.to_string() })?,
            ),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            Err(e) => return Err(SearchError::Models { path: models_path, reason: e.to_string() }),
        };
        let load = |file: &str, space: &Space, before: Option<&Space>| -> Result<ExactIndex, SearchError> {
            let path = dir.join(file);
            if before == Some(space) && path.exists() {
                let index = ExactIndex::load(&path)?;
                if index.dim() == space.dim {
                    return Ok(index);
                }
            }
            Ok(ExactIndex::new(space.dim))
        };
        let captions = load("captions.vec", &spaces.captions, previous.as_ref().map(|p| &p.captions))?;
        let motions = load("motions.vec", &spaces.motions, previous.as_ref().map(|p| &p.motions))?;
        let catalog = text
            .documents()?
            .into_iter()
            .map(|document| (document.id, Catalogued { key: FilterKey::of(&document), document }))
            .collect();
        let mut library = Library { text, captions, motions, catalog, spaces, dir: Some(dir.to_path_buf()) };
        let stray: Vec<u64> = library
            .captions
            .ids()
            .chain(library.motions.ids())
            .filter(|id| !library.catalog.contains_key(id))
            .collect();
        for id in &stray {
            library.captions.remove(*id);
            library.motions.remove(*id);
        }
        library.save_vectors()?;
        Ok(library)
    }

    /// The vector spaces the library holds.
    pub fn spaces(&self) -> &Spaces {
        &self.spaces
    }

    /// Clips in the library.
    pub fn len(&self) -> usize {
        self.catalog.len()
    }

    /// Whether the library is empty.
    pub fn is_empty(&self) -> bool {
        self.catalog.is_empty()
    }

    /// Whether clip `id` is in the library.
    pub fn contains(&self, id: u64) -> bool {
        self.catalog.contains_key(&id)
    }

    /// A clip's document.
    pub fn document(&self, id: u64) -> Option<&ClipDocument> {
        self.catalog.get(&id).map(|c| &c.document)
    }

    /// A clip's document and vectors, as they would be added again (to copy a library).
    pub fn entry(&self, id: u64) -> Option<Entry> {
        Some(Entry {
            document: self.document(id)?.clone(),
            caption_vector: self.captions.get(id).map(<[f32]>::to_vec),
            motion_vector: self.motions.get(id).map(<[f32]>::to_vec),
        })
    }

    /// Every clip id, ascending.
    pub fn ids(&self) -> Vec<u64> {
        let mut ids: Vec<u64> = self.catalog.keys().copied().collect();
        ids.sort_unstable();
        ids
    }

    /// Catalogued clips lacking a vector they should have: a caption vector (when they have
    /// captions) or a motion vector. Ascending.
    pub fn incomplete(&self) -> Vec<u64> {
        let mut ids: Vec<u64> = self
            .catalog
            .values()
            .filter(|c| {
                let id = c.document.id;
                (!c.document.captions.is_empty() && !self.captions.contains(id)) || !self.motions.contains(id)
            })
            .map(|c| c.document.id)
            .collect();
        ids.sort_unstable();
        ids
    }

    /// Adds clips (replacing those with the same ids), committed together. On failure the
    /// library is as it was (in memory; on disk the commit point decides).
    pub fn upsert(&mut self, entries: Vec<Entry>) -> Result<(), SearchError> {
        let before: Vec<Option<Entry>> = entries.iter().map(|e| self.entry(e.document.id)).collect();
        let result = self.try_upsert(&entries);
        if result.is_err() {
            for (e, old) in entries.iter().zip(before) {
                let id = e.document.id;
                let (caption, motion) = old.map_or((None, None), |o| (o.caption_vector, o.motion_vector));
                for (index, vector) in [(&mut self.captions, caption), (&mut self.motions, motion)] {
                    match vector {
                        Some(v) => index.upsert(id, &v).expect("restoring a vector that fitted"),
                        None => {
                            index.remove(id);
                        }
                    }
                }
            }
            return result;
        }
        for e in entries {
            let document = e.document;
            self.catalog.insert(document.id, Catalogued { key: FilterKey::of(&document), document });
        }
        Ok(())
    }

    /// Writes vectors (saved first) and documents (committed last).
    fn try_upsert(&mut self, entries: &[Entry]) -> Result<(), SearchError> {
        for e in entries {
            let id = e.document.id;
            for (index, vector) in [(&mut self.captions, &e.caption_vector), (&mut self.motions, &e.motion_vector)] {
                match vector {
                    Some(v) => index.upsert(id, v)?,
                    None => {
                        index.remove(id);
                    }
                }
            }
        }
        self.save_vectors()?;
        let documents: Vec<ClipDocument> = entries.iter().map(|e| e.document.clone()).collect();
        self.text.write(&documents, &[])?;
        Ok(())
    }

    /// Removes clips; ids not in the library are ignored.
    pub fn remove(&mut self, ids: &[u64]) -> Result<(), SearchError> {
        self.text.write(&[], ids)?;
        for id in ids {
            self.catalog.remove(id);
            self.captions.remove(*id);
            self.motions.remove(*id);
        }
        self.save_vectors()
    }

    fn save_vectors(&self) -> Result<(), SearchError> {
        let Some(dir) = &self.dir else { return Ok(()) };
        self.captions.save(&dir.join("captions.vec"))?;
        self.motions.save(&dir.join("motions.vec"))?;
        let path = dir.join("models.json");
        let tmp = dir.join("models.json.tmp");
        let json = serde_json::to_vec_pretty(&self.spaces).expect("spaces serialise");
        std::fs::write(&tmp, json)
            .and_then(|_| std::fs::rename(&tmp, &path))
            .map_err(|e| SearchError::Models { path, reason: e.to_string() })
    }

    /// One page of results for `query`.
    pub fn search(&self, query: &Query) -> Result<Page, SearchError> {
        if !(1..=MAX_LIMIT).contains(&query.limit) {
            return Err(SearchError::Limit { what: "the page size", min: 1, max: MAX_LIMIT, got: query.limit });
        }
        let depth = query.offset.saturating_add(query.limit);
        if depth > MAX_DEPTH {
            return Err(SearchError::Limit { what: "offset + page size", min: 1, max: MAX_DEPTH, got: depth });
        }
        query.filter.validate()?;
        let text = query.text.as_deref().map(str::trim).filter(|t| !t.is_empty());
        let w = query.weights;
        let use_bm25 = text.is_some() && w.bm25 > 0.0;
        let use_captions = query.caption_vector.is_some() && w.captions > 0.0;
        let use_motions = query.motion_vector.is_some() && w.motions > 0.0;
        if !(use_bm25 || use_captions || use_motions) {
            return Err(SearchError::NothingToSearch);
        }
        let allowed = if query.filter.is_empty() {
            Allowed::all()
        } else {
            let filter = query.filter.compile();
            Allowed::only(self.catalog.values().filter(|c| filter.accepts(&c.key)).map(|c| c.document.id))
        };
        // Every vector belongs to a catalogued clip (pruned on open, rolled back on a failed
        // upsert), so only the filter is consulted.
        let keep = |id: u64| allowed.contains(id);
        let candidates = depth.max(MIN_CANDIDATES);
        let vector_list = |index: &ExactIndex, v: &Option<Vec<f32>>, on: bool| -> Result<Vec<u64>, SearchError> {
            match v {
                Some(v) if on => Ok(index.search(v, candidates, &keep)?.into_iter().map(|h| h.id).collect()),
                _ => Ok(Vec::new()),
            }
        };
        let bm25: Vec<u64> = match text {
            Some(t) if use_bm25 => self.text.search(t, &allowed, candidates)?.into_iter().map(|h| h.0).collect(),
            _ => Vec::new(),
        };
        let captions = vector_list(&self.captions, &query.caption_vector, use_captions)?;
        let motions = vector_list(&self.motions, &query.motion_vector, use_motions)?;
        let everything = |_: u64| true;
        let has_caption = |id: u64| self.captions.contains(id);
        let has_motion = |id: u64| self.motions.contains(id);
        let active = |on: bool, weight: f32| if on { weight } else { 0.0 };
        let known = match text {
            Some(t) if use_bm25 && w.bm25_known_exponent > 0.0 => self.text.known_share(t)?.powf(w.bm25_known_exponent),
            _ => 1.0,
        };
        let fused = fuse_with_coverage(
            &[
                Retrieved { ids: &bm25, weight: active(use_bm25, w.bm25 * known), covers: &everything },
                Retrieved { ids: &captions, weight: active(use_captions, w.captions), covers: &has_caption },
                Retrieved { ids: &motions, weight: active(use_motions, w.motions), covers: &has_motion },
            ],
            DEFAULT_K,
        );
        let rank = |list: &[u64], id: u64| list.iter().position(|&x| x == id).map(|p| p + 1);
        let highlighter = text.map(|t| self.text.highlighter(t)).transpose()?;
        let hits = fused
            .iter()
            .skip(query.offset)
            .take(query.limit)
            .filter_map(|&(id, score)| {
                let document = self.catalog.get(&id)?.document.clone();
                let snippet = highlighter.as_ref().and_then(|h| h.best(&document.captions));
                let ranks = Ranks { bm25: rank(&bm25, id), captions: rank(&captions, id), motions: rank(&motions, id) };
                Some(Found { document, score, ranks, snippet })
            })
            .collect();
        Ok(Page { hits, candidates: fused.len() })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spaces(model: &str) -> Spaces {
        Spaces { captions: Space { model: "minilm".into(), dim: 2 }, motions: Space { model: model.into(), dim: 2 } }
    }

    fn entry(id: u64, subject: &str, caption: &str, caption_vector: [f32; 2], motion_vector: [f32; 2]) -> Entry {
        Entry {
            document: ClipDocument {
                id,
                path: format!("{subject}_{id}.bvh"),
                captions: vec![caption.into()],
                subject: subject.into(),
                source: "pack".into(),
                licence: if id.is_multiple_of(2) { "CC0-1.0".into() } else { "CC-BY-4.0".into() },
                skeleton: format!("{subject}-skeleton"),
                joint_labels: vec![],
                seconds: id as f64,
            },
            caption_vector: Some(caption_vector.to_vec()),
            motion_vector: Some(motion_vector.to_vec()),
        }
    }

    fn corpus() -> Vec<Entry> {
        vec![
            entry(1, "horse", "a horse gallops", [1.0, 0.0], [1.0, 0.0]),
            entry(2, "donkey", "a donkey runs fast", [0.8, 0.6], [0.9, 0.436]),
            entry(3, "person", "a person waves", [0.0, 1.0], [0.0, 1.0]),
            entry(4, "horse", "a horse eats grass", [0.6, 0.8], [0.2, 0.98]),
        ]
    }

    fn ids(page: &Page) -> Vec<u64> {
        page.hits.iter().map(|h| h.document.id).collect()
    }

    #[test]
    fn hybrid_filters_and_pages() {
        let mut library = Library::in_memory(spaces("evaluator"));
        library.upsert(corpus()).unwrap();
        let query = Query {
            text: Some("gallop".into()),
            caption_vector: Some(vec![1.0, 0.0]),
            motion_vector: Some(vec![1.0, 0.0]),
            weights: Weights::new(1.0, 1.0, 1.0),
            limit: 10,
            ..Query::default()
        };
        let page = library.search(&query).unwrap();
        assert_eq!(ids(&page), vec![1, 2, 4, 3]);
        assert_eq!(page.hits[0].ranks, Ranks { bm25: Some(1), captions: Some(1), motions: Some(1) });
        assert_eq!(page.hits[0].snippet.as_ref().unwrap().marked("<b>", "</b>"), "a horse <b>gallops</b>");
        let expected = 3.0 / (DEFAULT_K + 1.0);
        assert!((page.hits[0].score - expected).abs() < 1e-7);

        let second = library.search(&Query { offset: 1, limit: 2, ..query.clone() }).unwrap();
        assert_eq!(ids(&second), vec![2, 4]);
        assert_eq!(second.candidates, 4);

        let horses = Query { filter: Filter { subject: Some("horse".into()), ..Filter::default() }, ..query.clone() };
        assert_eq!(ids(&library.search(&horses).unwrap()), vec![1, 4]);
        let long_cc0 = Filter { licence: Some("CC0-1.0".into()), min_seconds: Some(3.0), ..Filter::default() };
        assert_eq!(ids(&library.search(&Query { filter: long_cc0, ..query.clone() }).unwrap()), vec![4]);

        let only_motion = Query {
            text: None,
            caption_vector: None,
            motion_vector: Some(vec![0.0, 1.0]),
            limit: 2,
            ..Query::default()
        };
        assert_eq!(ids(&library.search(&only_motion).unwrap()), vec![3, 4]);
        assert!(library.search(&only_motion).unwrap().hits[0].snippet.is_none());
    }

    #[test]
    fn bm25_counts_by_the_share_of_the_query_words_the_library_knows() {
        let mut library = Library::in_memory(spaces("evaluator"));
        library.upsert(corpus()).unwrap();
        // "horse" is known, "pony" and "sprints" are not ("a" and "as" are stop words).
        assert_eq!(library.text.known_share("a pony sprints as a horse").unwrap(), 1.0 / 3.0);
        assert_eq!(library.text.known_share("horses gallop").unwrap(), 1.0);
        assert_eq!(library.text.known_share("the a").unwrap(), 0.0);
        // The sentence embedding points at the donkey (2); BM25's matches are the incidental
        // "horse" of 1 and 4.
        let query = |text: &str, bm25_known_exponent: f32| Query {
            text: Some(text.into()),
            caption_vector: Some(vec![0.9, 0.436]),
            weights: Weights { bm25: 1.0, captions: 1.0, motions: 0.0, bm25_known_exponent },
            limit: 10,
            ..Query::default()
        };
        let fused = |hit: &Found, bm25_weight: f32| {
            let rank = |r: Option<usize>| r.map_or(0.0, |r| 1.0 / (DEFAULT_K + r as f32));
            bm25_weight * rank(hit.ranks.bm25) + rank(hit.ranks.captions)
        };
        let paraphrase = "a pony sprints as a horse";
        let plain = library.search(&query(paraphrase, 0.0)).unwrap();
        assert_eq!(ids(&plain)[0], 1, "unscaled, the incidental match wins");
        let scaled = library.search(&query(paraphrase, 4.0)).unwrap();
        assert_eq!(ids(&scaled)[0], 2);
        for hit in &scaled.hits {
            assert!((hit.score - fused(hit, 1.0 / 81.0)).abs() < 1e-7, "{hit:?}");
        }
        // A query in the library's own words keeps BM25's full weight.
        let own_words = library.search(&query("a horse gallops", 4.0)).unwrap();
        assert_eq!(ids(&own_words)[0], 1);
        for hit in &own_words.hits {
            assert!((hit.score - fused(hit, 1.0)).abs() < 1e-7, "{hit:?}");
        }
    }

    #[test]
    fn a_failed_upsert_changes_nothing() {
        let mut library = Library::in_memory(spaces("evaluator"));
        library.upsert(corpus()).unwrap();
        let mut replaced = entry(1, "horse", "a horse gallops", [0.0, 1.0], [0.0, 1.0]);
        replaced.document.captions = vec!["a horse rears".into()];
        let mut bad = entry(9, "cat", "a cat naps", [1.0, 0.0], [1.0, 0.0]);
        bad.motion_vector = Some(vec![1.0, 0.0, 0.0]);
        assert!(library.upsert(vec![replaced, bad]).is_err());
        assert_eq!(library.ids(), vec![1, 2, 3, 4]);
        let kept = library.entry(1).unwrap();
        assert_eq!(kept.document, corpus()[0].document);
        assert_eq!(kept.caption_vector, corpus()[0].caption_vector);
        let motion = Query { motion_vector: Some(vec![1.0, 0.0]), limit: 1, ..Query::default() };
        assert_eq!(ids(&library.search(&motion).unwrap()), vec![1]);
    }

    #[test]
    fn refusals_name_the_limit() {
        let library = Library::in_memory(spaces("evaluator"));
        let text = Query { text: Some("walk".into()), limit: 10, ..Query::default() };
        assert!(matches!(library.search(&Query { limit: 0, ..text.clone() }), Err(SearchError::Limit { .. })));
        let deep = library.search(&Query { offset: 995, ..text.clone() }).unwrap_err().to_string();
        assert_eq!(deep, "offset + page size must be between 1 and 1000; 1005 was asked");
        assert!(matches!(
            library.search(&Query { text: Some("  ".into()), ..text.clone() }),
            Err(SearchError::NothingToSearch)
        ));
        let bad = Filter { max_seconds: Some(-1.0), ..Filter::default() };
        assert!(matches!(library.search(&Query { filter: bad, ..text.clone() }), Err(SearchError::Filter(_))));
        let wrong_width = Query { motion_vector: Some(vec![1.0; 3]), ..text };
        assert!(matches!(library.search(&wrong_width), Err(SearchError::Vector(IndexError::Dimension { .. }))));
    }

    #[test]
    fn persists_updates_and_drops_vectors_of_another_model() {
        let dir = std::env::temp_dir().join(format!("anymo-library-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        {
            let mut library = Library::open(&dir, spaces("evaluator-a")).unwrap();
            library.upsert(corpus()).unwrap();
            library.remove(&[3]).unwrap();
            let mut changed = entry(4, "horse", "a horse gallops uphill", [1.0, 0.0], [1.0, 0.0]);
            changed.motion_vector = None;
            library.upsert(vec![changed]).unwrap();
        }
        let library = Library::open(&dir, spaces("evaluator-a")).unwrap();
        assert_eq!(library.ids(), vec![1, 2, 4]);
        assert_eq!(library.document(4).unwrap().captions, vec!["a horse gallops uphill".to_string()]);
        assert_eq!(library.incomplete(), vec![4]);
        let kept = library.entry(2).unwrap();
        assert_eq!(kept.document, corpus()[1].document);
        assert_eq!(kept.motion_vector, corpus()[1].motion_vector);
        assert!(library.entry(3).is_none());
        let gallop = Query { text: Some("gallops".into()), limit: 10, ..Query::default() };
        let mut found = ids(&library.search(&gallop).unwrap());
        found.sort();
        assert_eq!(found, vec![1, 4]);
        drop(library);

        let library = Library::open(&dir, spaces("evaluator-b")).unwrap();
        assert_eq!(library.incomplete(), vec![1, 2, 4]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
