//! Retrieval by the protocol of EVAL.md, on held-out captions so that no query is answered by
//! finding its own words: every test clip's last caption is its query, and the clip is indexed
//! with its other captions only (none, for a clip with one caption). A result is relevant when
//! any of its captions, held out or not, equals the query. Motion to motion: each clip's motion
//! embedding as the query, itself left out, clips sharing a caption relevant. Paraphrases: the
//! queries of a benchmark (`anymo_retrieval::benchmark`) worded unlike any caption, against the
//! test clips indexed with all their captions, reported per half (development, test).

use super::Table;
use crate::data::{MODEL_FPS, ModelClip};
use crate::generation::is_human;
use crate::search::{SearchModels, caption_vector};
use anyhow::Result;
use anymo_motion::prep::labels::label_skeleton;
use anymo_retrieval::benchmark::{BenchmarkQuery, Half};
use anymo_retrieval::library::MAX_LIMIT;
use anymo_retrieval::metrics::RankSummary;
use anymo_retrieval::{ClipDocument, Entry, Library, Query, Weights};
use anymo_store::ingest::fingerprint;
use serde::Serialize;

/// One line of the table.
#[derive(Debug, Serialize)]
pub struct RetrievalRow {
    /// `caption -> motion` (held-out captions), `paraphrase -> motion` or `motion -> motion`.
    pub task: &'static str,
    /// Which retrievers were fused.
    pub retrievers: &'static str,
    /// `all`, `humans` or `animals` (by the query clip's subject), or a paraphrase benchmark half.
    pub subset: &'static str,
    /// The figures.
    pub summary: RankSummary,
}

/// The retriever combinations compared for text queries; the last is the hybrid, with the
/// weights asked for.
fn text_retrievers(hybrid: Weights) -> [(&'static str, Weights); 5] {
    [
        ("BM25", Weights::new(1.0, 0.0, 0.0)),
        ("caption vectors", Weights::new(0.0, 1.0, 0.0)),
        ("motion vectors", Weights::new(0.0, 0.0, 1.0)),
        ("vectors", Weights::new(0.0, 1.0, 1.0)),
        ("hybrid", hybrid),
    ]
}

/// A named group of query clips.
pub(super) type Subset = (&'static str, fn(&ModelClip) -> bool);

fn same_text(a: &str, b: &str) -> bool {
    a.trim().eq_ignore_ascii_case(b.trim())
}

/// Rank (1-based) of the first result `relevant` accepts, not counting those `skip` accepts;
/// the number of results counted when there is none (an unfound clip counts as last).
pub(super) fn first_relevant(
    library: &Library,
    query: &Query,
    relevant: &dyn Fn(u64) -> bool,
    skip: &dyn Fn(u64) -> bool,
) -> Result<usize> {
    let mut rank = 0;
    let mut offset = 0;
    while offset + MAX_LIMIT <= anymo_retrieval::library::MAX_DEPTH {
        let page = library.search(&Query { offset, limit: MAX_LIMIT, ..query.clone() })?;
        for hit in &page.hits {
            if skip(hit.document.id) {
                continue;
            }
            rank += 1;
            if relevant(hit.document.id) {
                return Ok(rank);
            }
        }
        if page.hits.len() < MAX_LIMIT {
            break;
        }
        offset += MAX_LIMIT;
    }
    Ok((0..library.len()).filter(|&i| !skip(doc_id(i))).count())
}

/// A text query with its vectors, embedded once and searched under several weightings.
struct TextQuery {
    text: String,
    caption_vector: Vec<f32>,
    motion_vector: Vec<f32>,
    /// Which clips (by index into the gallery) answer it.
    relevant: Vec<bool>,
}

impl TextQuery {
    fn new(models: &mut SearchModels, text: &str, relevant: Vec<bool>) -> Result<TextQuery> {
        let vectors = models.text_vectors(text)?;
        Ok(TextQuery {
            text: text.to_string(),
            caption_vector: vectors.caption,
            motion_vector: vectors.motion,
            relevant,
        })
    }

    /// The rank of the first relevant clip in `library` under `weights`.
    fn rank(&self, library: &Library, weights: Weights) -> Result<usize> {
        let query = Query {
            text: Some(self.text.clone()),
            caption_vector: Some(self.caption_vector.clone()),
            motion_vector: Some(self.motion_vector.clone()),
            weights,
            ..Query::default()
        };
        first_relevant(library, &query, &|doc| self.relevant[doc_index(doc)], &|_| false)
    }
}

/// Gallery clip `i`'s document id.
pub(super) fn doc_id(i: usize) -> u64 {
    i as u64 + 1
}

/// The gallery index of document `id`.
pub(super) fn doc_index(id: u64) -> usize {
    (id - 1) as usize
}

/// A gallery clip's vectors and document, computed once for both libraries.
pub(super) struct Embedded {
    pub(super) document: ClipDocument,
    caption_embeddings: Vec<Vec<f32>>,
    pub(super) motion_vector: Vec<f32>,
}

impl Embedded {
    /// The library entry indexing the clip with its first `captions` captions.
    pub(super) fn entry(&self, captions: usize) -> Entry {
        Entry {
            document: ClipDocument { captions: self.document.captions[..captions].to_vec(), ..self.document.clone() },
            caption_vector: caption_vector(&self.caption_embeddings[..captions]),
            motion_vector: Some(self.motion_vector.clone()),
        }
    }
}

pub(super) fn embed(models: &mut SearchModels, clips: &[&ModelClip]) -> Result<Vec<Embedded>> {
    clips
        .iter()
        .enumerate()
        .map(|(i, clip)| {
            let refs: Vec<&str> = clip.item.captions.iter().map(String::as_str).collect();
            let skeleton = clip.motion.skeleton();
            Ok(Embedded {
                document: ClipDocument {
                    id: doc_id(i),
                    path: clip.item.key.clone(),
                    captions: clip.item.captions.clone(),
                    subject: clip.item.subject.clone(),
                    source: clip.item.source.clone(),
                    licence: clip.item.licence.clone(),
                    skeleton: fingerprint(skeleton),
                    joint_labels: label_skeleton(skeleton).iter().map(|l| l.text()).collect(),
                    seconds: clip.motion.frames() as f64 / MODEL_FPS,
                },
                caption_embeddings: models.sentences(&refs)?,
                motion_vector: models.embed_cleaned(&clip.motion)?,
            })
        })
        .collect()
}

pub(super) fn library_of(models: &SearchModels, entries: Vec<Entry>) -> Result<Library> {
    let mut library = Library::in_memory(models.spaces().clone());
    library.upsert(entries)?;
    Ok(library)
}

/// The hybrid row's weights: given, or chosen by [`calibrate`].
#[derive(Clone, Copy, Debug)]
pub enum Hybrid {
    /// These weights.
    Fixed(Weights),
    /// The weights calibration chooses on the paraphrases' development half.
    Calibrated,
}

/// One setting calibration tried, with what it measured.
#[derive(Debug, Serialize)]
pub struct Tried {
    /// The setting.
    pub weights: Weights,
    /// On the paraphrase benchmark's development half.
    pub development: RankSummary,
    /// On the held-out caption queries (the guard).
    pub captions: RankSummary,
}

/// What calibration tried and chose.
#[derive(Debug, Serialize)]
pub struct Calibration {
    /// The setting with the best development-half MRR among those that keep caption-query
    /// R@10 at least at plain, equal-weight fusion's.
    pub chosen: Weights,
    /// Plain equal-weight fusion's figures, the reference of the guard.
    pub plain: Tried,
    /// Every setting tried.
    pub tried: Vec<Tried>,
}

/// What [`evaluate`] measured.
#[derive(Debug, Serialize)]
pub struct RetrievalReport {
    /// The table's rows.
    pub rows: Vec<RetrievalRow>,
    /// The hybrid row's weights.
    pub hybrid: Weights,
    /// How they were chosen, when calibrated.
    pub calibration: Option<Calibration>,
    /// Paraphrase queries left out because no test clip answers them.
    pub unanswerable: Vec<String>,
}

/// The settings calibration tries: caption vectors at 1, BM25 and motion vectors at 1/8 to 1,
/// BM25 scaled by the query's known words to the power 0, 1, 2 or 4. Only ratios matter to
/// reciprocal rank fusion, so fixing one weight loses nothing.
fn candidate_weights() -> Vec<Weights> {
    let levels = [0.125, 0.25, 0.5, 1.0];
    let mut out = Vec::new();
    for bm25_known_exponent in [0.0, 1.0, 2.0, 4.0] {
        for bm25 in levels {
            for motions in levels {
                out.push(Weights { bm25, captions: 1.0, motions, bm25_known_exponent });
            }
        }
    }
    out
}

/// Chooses fusion weights on the development paraphrases: the best MRR among the settings
/// whose caption-query R@10 is at least plain equal-weight fusion's, so that calibrating for
/// paraphrases costs corpus-style queries nothing.
fn calibrate(
    development: &[&TextQuery],
    full: &Library,
    captions: &[TextQuery],
    held_out: &Library,
) -> Result<Calibration> {
    let measure = |weights: Weights| -> Result<Tried> {
        let development = development.iter().map(|q| q.rank(full, weights)).collect::<Result<Vec<_>>>()?;
        let captions = captions.iter().map(|q| q.rank(held_out, weights)).collect::<Result<Vec<_>>>()?;
        Ok(Tried { weights, development: RankSummary::of(&development), captions: RankSummary::of(&captions) })
    };
    let plain = measure(Weights::new(1.0, 1.0, 1.0))?;
    let tried = candidate_weights().into_iter().map(measure).collect::<Result<Vec<_>>>()?;
    let chosen = tried
        .iter()
        .filter(|t| t.captions.r10 >= plain.captions.r10)
        .max_by(|a, b| a.development.mrr.total_cmp(&b.development.mrr))
        .map_or(plain.weights, |t| t.weights);
    Ok(Calibration { chosen, plain, tried })
}

/// The retrieval table over `clips` (the test split): held-out captions as queries (humans,
/// animals, all), motion by example, and the paraphrase benchmark's two halves against the
/// clips indexed with all their captions; the hybrid row with the `hybrid` weights.
pub fn evaluate(
    models: &mut SearchModels,
    clips: &[&ModelClip],
    hybrid: Hybrid,
    paraphrases: &[BenchmarkQuery],
) -> Result<RetrievalReport> {
    let clips: Vec<&ModelClip> = clips.iter().copied().filter(|c| !c.item.captions.is_empty()).collect();
    let embedded = embed(models, &clips)?;
    let held_out = library_of(models, embedded.iter().map(|e| e.entry(e.document.captions.len() - 1)).collect())?;
    let full = library_of(models, embedded.iter().map(|e| e.entry(e.document.captions.len())).collect())?;

    let mut caption_queries = Vec::with_capacity(clips.len());
    for clip in &clips {
        let text = clip.item.captions.last().expect("clips without captions were left out");
        let relevant = clips.iter().map(|c| c.item.captions.iter().any(|x| same_text(x, text))).collect();
        caption_queries.push(TextQuery::new(models, text, relevant)?);
    }
    let mut unanswerable = Vec::new();
    let mut paraphrase_queries = Vec::new();
    for q in paraphrases {
        let relevant: Vec<bool> = clips.iter().map(|c| q.relevance.accepts(&c.item.captions)).collect();
        if relevant.contains(&true) {
            paraphrase_queries.push((q.half, TextQuery::new(models, &q.text, relevant)?));
        } else {
            unanswerable.push(q.text.clone());
        }
    }
    let (hybrid, calibration) = match hybrid {
        Hybrid::Fixed(weights) => (weights, None),
        Hybrid::Calibrated => {
            let development: Vec<&TextQuery> =
                paraphrase_queries.iter().filter(|(h, _)| *h == Half::Development).map(|(_, q)| q).collect();
            let calibration = calibrate(&development, &full, &caption_queries, &held_out)?;
            (calibration.chosen, Some(calibration))
        }
    };
    let retrievers = text_retrievers(hybrid);
    let text_ranks = retrievers
        .iter()
        .map(|(_, w)| caption_queries.iter().map(|q| q.rank(&held_out, *w)).collect::<Result<Vec<_>>>())
        .collect::<Result<Vec<_>>>()?;

    let mut example_ranks = Vec::new();
    for (i, clip) in clips.iter().enumerate() {
        let shares = |doc: u64| {
            let other = &clips[doc_index(doc)].item.captions;
            clip.item.captions.iter().any(|a| other.iter().any(|b| same_text(a, b)))
        };
        let has_partner = (0..clips.len()).any(|j| j != i && shares(doc_id(j)));
        let query = Query {
            motion_vector: Some(embedded[i].motion_vector.clone()),
            weights: Weights::new(0.0, 0.0, 1.0),
            ..Query::default()
        };
        example_ranks.push(
            has_partner.then(|| first_relevant(&held_out, &query, &shares, &|doc| doc == doc_id(i))).transpose()?,
        );
    }

    let subsets: [Subset; 3] =
        [("all", |_| true), ("humans", |c| is_human(&c.item.subject)), ("animals", |c| !is_human(&c.item.subject))];
    let mut rows = Vec::new();
    for (subset, keep) in subsets {
        let picked: Vec<usize> = (0..clips.len()).filter(|&i| keep(clips[i])).collect();
        if picked.is_empty() {
            continue;
        }
        for (r, (name, _)) in retrievers.iter().enumerate() {
            let ranks: Vec<usize> = picked.iter().map(|&i| text_ranks[r][i]).collect();
            rows.push(RetrievalRow {
                task: "caption -> motion",
                retrievers: name,
                subset,
                summary: RankSummary::of(&ranks),
            });
        }
        let ranks: Vec<usize> = picked.iter().filter_map(|&i| example_ranks[i]).collect();
        rows.push(RetrievalRow {
            task: "motion -> motion",
            retrievers: "motion vectors",
            subset,
            summary: RankSummary::of(&ranks),
        });
    }

    for (half, subset) in [(Half::Development, "development half"), (Half::Test, "test half")] {
        let picked: Vec<&TextQuery> = paraphrase_queries.iter().filter(|(h, _)| *h == half).map(|(_, q)| q).collect();
        if picked.is_empty() {
            continue;
        }
        for (name, weights) in &retrievers {
            let ranks = picked.iter().map(|q| q.rank(&full, *weights)).collect::<Result<Vec<_>>>()?;
            rows.push(RetrievalRow {
                task: "paraphrase -> motion",
                retrievers: name,
                subset,
                summary: RankSummary::of(&ranks),
            });
        }
    }
    Ok(RetrievalReport { rows, hybrid, calibration, unanswerable })
}

/// The rank columns every search table ends with.
pub(super) const RANK_HEADERS: [&str; 5] = ["R@1", "R@5", "R@10", "MRR", "median rank"];

/// A summary's cells under [`RANK_HEADERS`].
pub(super) fn rank_cells(s: &RankSummary) -> [String; 5] {
    [
        format!("{:.3}", s.r1),
        format!("{:.3}", s.r5),
        format!("{:.3}", s.r10),
        format!("{:.3}", s.mrr),
        s.median_rank.to_string(),
    ]
}

/// The rows as a Markdown table.
pub fn markdown(rows: &[RetrievalRow]) -> String {
    let mut table = Table::new(&[&["task", "retrievers", "queries", "queries' subset"][..], &RANK_HEADERS].concat());
    for r in rows {
        let s = &r.summary;
        let cells = [r.task.to_string(), r.retrievers.to_string(), s.queries.to_string(), r.subset.to_string()];
        table.row(&[&cells[..], &rank_cells(s)].concat());
    }
    table.into_text()
}

/// What calibration tried, as a Markdown table (the chosen setting marked).
pub fn calibration_markdown(c: &Calibration) -> String {
    let mut table = Table::new(&[
        "BM25",
        "captions",
        "motions",
        "known-words exponent",
        "development R@10",
        "development MRR",
        "caption R@10",
        "caption MRR",
        "",
    ]);
    for t in std::iter::once(&c.plain).chain(&c.tried) {
        let w = t.weights;
        table.row(&[
            w.bm25.to_string(),
            w.captions.to_string(),
            w.motions.to_string(),
            w.bm25_known_exponent.to_string(),
            format!("{:.3}", t.development.r10),
            format!("{:.3}", t.development.mrr),
            format!("{:.3}", t.captions.r10),
            format!("{:.3}", t.captions.mrr),
            if w == c.chosen { "chosen".into() } else { String::new() },
        ]);
    }
    table.into_text()
}
