//! Retrieval by the protocol of EVAL.md, on held-out captions so that no query is answered by
//! finding its own words: every test clip's last caption is its query, and the clip is indexed
//! with its other captions only (none, for a clip with one caption). A result is relevant when
//! any of its captions, held out or not, equals the query. Motion to motion: each clip's motion
//! embedding as the query, itself left out, clips sharing a caption relevant.

use super::Table;
use crate::data::{MODEL_FPS, ModelClip};
use crate::generation::is_human;
use crate::search::{SearchModels, caption_vector};
use anyhow::Result;
use anymo_motion::prep::labels::label_skeleton;
use anymo_retrieval::library::MAX_LIMIT;
use anymo_retrieval::metrics::RankSummary;
use anymo_retrieval::{ClipDocument, Entry, Library, Query, Weights};
use anymo_store::ingest::fingerprint;
use serde::Serialize;

/// One line of the table.
#[derive(Debug, Serialize)]
pub struct RetrievalRow {
    /// `text -> motion` or `motion -> motion`.
    pub task: &'static str,
    /// Which retrievers were fused.
    pub retrievers: &'static str,
    /// `all`, `humans` or `animals` (by the query clip's subject).
    pub subset: &'static str,
    /// The figures.
    pub summary: RankSummary,
}

/// The retriever combinations compared for text queries; the last is the hybrid, with the
/// weights asked for.
fn text_retrievers(hybrid: Weights) -> [(&'static str, Weights); 5] {
    [
        ("BM25", Weights { bm25: 1.0, captions: 0.0, motions: 0.0 }),
        ("caption vectors", Weights { bm25: 0.0, captions: 1.0, motions: 0.0 }),
        ("motion vectors", Weights { bm25: 0.0, captions: 0.0, motions: 1.0 }),
        ("vectors", Weights { bm25: 0.0, captions: 1.0, motions: 1.0 }),
        ("hybrid", hybrid),
    ]
}

/// A named group of query clips.
type Subset = (&'static str, fn(&ModelClip) -> bool);

fn same_text(a: &str, b: &str) -> bool {
    a.trim().eq_ignore_ascii_case(b.trim())
}

/// Rank (1-based) of the first result `relevant` accepts, not counting `skip`; the gallery size
/// when there is none (an unfound clip counts as last).
fn first_relevant(
    library: &Library,
    query: &Query,
    relevant: &dyn Fn(u64) -> bool,
    skip: Option<u64>,
) -> Result<usize> {
    let mut rank = 0;
    let mut offset = 0;
    while offset + MAX_LIMIT <= anymo_retrieval::library::MAX_DEPTH {
        let page = library.search(&Query { offset, limit: MAX_LIMIT, ..query.clone() })?;
        for hit in &page.hits {
            if Some(hit.document.id) == skip {
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
    Ok(library.len() - usize::from(skip.is_some()))
}

/// The retrieval table over `clips` (the test split), the hybrid row with weights `hybrid`.
pub fn evaluate(models: &mut SearchModels, clips: &[&ModelClip], hybrid: Weights) -> Result<Vec<RetrievalRow>> {
    let retrievers = text_retrievers(hybrid);
    let clips: Vec<&ModelClip> = clips.iter().copied().filter(|c| !c.item.captions.is_empty()).collect();
    let id = |i: usize| i as u64 + 1;
    let mut library = Library::in_memory(models.spaces().clone());
    let mut entries = Vec::with_capacity(clips.len());
    for (i, clip) in clips.iter().enumerate() {
        let captions = &clip.item.captions[..clip.item.captions.len() - 1];
        let refs: Vec<&str> = captions.iter().map(String::as_str).collect();
        let embeddings = models.sentences(&refs)?;
        let skeleton = clip.motion.skeleton();
        entries.push(Entry {
            document: ClipDocument {
                id: id(i),
                path: clip.item.key.clone(),
                captions: captions.to_vec(),
                subject: clip.item.subject.clone(),
                source: clip.item.source.clone(),
                licence: clip.item.licence.clone(),
                skeleton: fingerprint(skeleton),
                joint_labels: label_skeleton(skeleton).iter().map(|l| l.text()).collect(),
                seconds: clip.motion.frames() as f64 / MODEL_FPS,
            },
            caption_vector: caption_vector(&embeddings),
            motion_vector: Some(models.embed_cleaned(&clip.motion)?),
        });
    }
    let motion_vectors: Vec<Vec<f32>> = entries.iter().map(|e| e.motion_vector.clone().unwrap_or_default()).collect();
    library.upsert(entries)?;

    let subsets: [Subset; 3] =
        [("all", |_| true), ("humans", |c| is_human(&c.item.subject)), ("animals", |c| !is_human(&c.item.subject))];
    let mut text_ranks: Vec<Vec<usize>> = vec![Vec::new(); retrievers.len()];
    for clip in &clips {
        let text = clip.item.captions.last().expect("clips without captions were left out");
        let relevant = |doc: u64| clips[(doc - 1) as usize].item.captions.iter().any(|c| same_text(c, text));
        let (caption_vector, motion_vector) = models.text_vectors(text)?;
        for (r, (_, weights)) in retrievers.iter().enumerate() {
            let query = Query {
                text: Some(text.clone()),
                caption_vector: Some(caption_vector.clone()),
                motion_vector: Some(motion_vector.clone()),
                weights: *weights,
                ..Query::default()
            };
            text_ranks[r].push(first_relevant(&library, &query, &relevant, None)?);
        }
    }
    let mut example_ranks = Vec::new();
    for (i, clip) in clips.iter().enumerate() {
        let shares = |doc: u64| {
            let other = &clips[(doc - 1) as usize].item.captions;
            clip.item.captions.iter().any(|a| other.iter().any(|b| same_text(a, b)))
        };
        let has_partner = (0..clips.len()).any(|j| j != i && shares(id(j)));
        let query = Query {
            motion_vector: Some(motion_vectors[i].clone()),
            weights: Weights { bm25: 0.0, captions: 0.0, motions: 1.0 },
            ..Query::default()
        };
        example_ranks.push(has_partner.then(|| first_relevant(&library, &query, &shares, Some(id(i)))).transpose()?);
    }

    let mut rows = Vec::new();
    for (subset, keep) in subsets {
        let picked: Vec<usize> = (0..clips.len()).filter(|&i| keep(clips[i])).collect();
        if picked.is_empty() {
            continue;
        }
        for (r, (name, _)) in retrievers.iter().enumerate() {
            let ranks: Vec<usize> = picked.iter().map(|&i| text_ranks[r][i]).collect();
            rows.push(RetrievalRow {
                task: "text -> motion",
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
    Ok(rows)
}

/// The rows as a Markdown table.
pub fn markdown(rows: &[RetrievalRow]) -> String {
    let mut table =
        Table::new(&["task", "retrievers", "queries", "queries' subjects", "R@1", "R@5", "R@10", "median rank"]);
    for r in rows {
        let s = &r.summary;
        table.row(&[
            r.task.to_string(),
            r.retrievers.to_string(),
            s.queries.to_string(),
            r.subset.to_string(),
            format!("{:.3}", s.r1),
            format!("{:.3}", s.r5),
            format!("{:.3}", s.r10),
            s.median_rank.to_string(),
        ]);
    }
    table.into_text()
}
