//! Motion by example across skeletons: a clip of one rig as the query, clips of the same action
//! on other rigs as the answers. The action is the clip's first caption without its subject
//! ([`action_key`]: "a white horse gallops" and "a wolf gallops" are both `gallop`), so a horse's
//! gallop is answered by the wolf's and the dog's, and a human wave by waves on other human rigs.
//! The query's own rig is left out of the gallery, so every answer is on another skeleton; the
//! queries are the test clips (rigs the models trained on, clips they never saw) and the
//! zero-shot clips (rigs that no model saw and, with their own rig left out, that the index does
//! not hold either). The gallery is every clip of the corpus, as a user's library would be.

use super::Table;
use super::retrieval::{Embedded, RANK_HEADERS, Subset, doc_index, embed, first_relevant, library_of, rank_cells};
use crate::data::ModelClip;
use crate::generation::is_human;
use crate::search::SearchModels;
use anyhow::Result;
use anymo_retrieval::metrics::RankSummary;
use anymo_retrieval::{Library, Query, Weights};
use anymo_tokenizer::dataset::Split;
use serde::Serialize;

/// Words of a caption's subject phrase that are not the manifest's subject itself: the people
/// and robots the corpus's captions name beside their subject ("a man", "a mech robot").
const SUBJECT_NOUNS: [&str; 4] = ["person", "man", "woman", "robot"];

/// The action a caption names, for comparing clips of different subjects: lower case, the
/// subject phrase dropped (everything up to the first occurrence of the subject's last word, or
/// else of one of [`SUBJECT_NOUNS`], or else the first word, and any of [`SUBJECT_NOUNS`] right
/// after), punctuation dropped and each word's plural or third-person `s` taken off, so
/// "a person: walk" and "a man walks" agree. `None` when nothing is left.
pub fn action_key(caption: &str, subject: &str) -> Option<String> {
    let trimmed = |w: &str| w.trim_matches(|c: char| !c.is_alphanumeric()).to_lowercase();
    let words: Vec<String> = caption.split_whitespace().map(trimmed).collect();
    let subject_word = subject.split_whitespace().last().map(str::to_lowercase);
    let end_of_subject = words
        .iter()
        .position(|w| Some(w) == subject_word.as_ref())
        .or_else(|| words.iter().position(|w| SUBJECT_NOUNS.contains(&w.as_str())))
        .map_or(1, |i| i + 1);
    let rest: Vec<String> = words[end_of_subject.min(words.len())..]
        .iter()
        .skip_while(|w| SUBJECT_NOUNS.contains(&w.as_str()))
        .filter(|w| !w.is_empty())
        .map(|w| match w.strip_suffix('s') {
            Some(stem) if stem.len() >= 3 && !stem.ends_with('s') => stem.to_string(),
            _ => w.clone(),
        })
        .collect();
    (!rest.is_empty()).then(|| rest.join(" "))
}

/// One line of the table.
#[derive(Debug, Serialize)]
pub struct ExampleRow {
    /// The queries' split: `test` (seen rigs) or `zero-shot` (unseen rigs).
    pub split: &'static str,
    /// `all`, `humans` or `other bodies`, by the query clip's subject.
    pub subset: &'static str,
    /// The figures: rank of the first clip of the same action on another rig.
    pub summary: RankSummary,
}

/// The table over `clips` (the whole corpus: the gallery; its test and zero-shot clips are the
/// queries), searched by the motion vectors alone as `anymo search --like` ranks.
pub fn evaluate(models: &mut SearchModels, clips: &[&ModelClip]) -> Result<Vec<ExampleRow>> {
    let clips: Vec<&ModelClip> = clips.iter().copied().filter(|c| !c.item.captions.is_empty()).collect();
    let embedded: Vec<Embedded> = embed(models, &clips)?;
    let gallery: Vec<GalleryClip> = clips
        .iter()
        .zip(&embedded)
        .map(|(clip, e)| GalleryClip {
            action: action_key(&clip.item.captions[0], &clip.item.subject),
            skeleton: e.document.skeleton.clone(),
            motion_vector: e.motion_vector.clone(),
            query: clip.split != Split::Train,
        })
        .collect();
    let library = library_of(models, embedded.iter().map(|e| e.entry(e.document.captions.len())).collect())?;
    let ranks = ranks_across_rigs(&library, &gallery)?;

    let mut rows = Vec::new();
    for (split, name) in [(Split::Test, "test"), (Split::ZeroShot, "zero-shot")] {
        let subsets: [Subset; 3] = [
            ("all", |_| true),
            ("humans", |c| is_human(&c.item.subject)),
            ("other bodies", |c| !is_human(&c.item.subject)),
        ];
        for (subset, keep) in subsets {
            let picked: Vec<usize> = ranks
                .iter()
                .filter(|(i, _)| clips[*i].split == split && keep(clips[*i]))
                .map(|(_, rank)| *rank)
                .collect();
            if !picked.is_empty() {
                rows.push(ExampleRow { split: name, subset, summary: RankSummary::of(&picked) });
            }
        }
    }
    Ok(rows)
}

/// A clip of the gallery, as the ranking sees it (document `i + 1` of the library is clip `i`).
pub struct GalleryClip {
    /// Its action ([`action_key`]), `None` when its caption names none.
    pub action: Option<String>,
    /// Its skeleton's fingerprint.
    pub skeleton: String,
    /// Its motion vector.
    pub motion_vector: Vec<f32>,
    /// Whether it is asked as a query.
    pub query: bool,
}

/// For each query clip with an action that some clip of another rig shares, its index and the
/// rank of the first such clip when `library` is searched by its motion vector, the clips of its
/// own rig (itself among them) left out.
pub fn ranks_across_rigs(library: &Library, gallery: &[GalleryClip]) -> Result<Vec<(usize, usize)>> {
    let mut ranks = Vec::new();
    for (i, clip) in gallery.iter().enumerate() {
        let Some(action) = clip.action.as_deref().filter(|_| clip.query) else { continue };
        let own_rig = |doc: usize| gallery[doc].skeleton == clip.skeleton;
        let answers = |doc: usize| !own_rig(doc) && gallery[doc].action.as_deref() == Some(action);
        if !(0..gallery.len()).any(answers) {
            continue;
        }
        let query = Query {
            motion_vector: Some(clip.motion_vector.clone()),
            weights: Weights::new(0.0, 0.0, 1.0),
            ..Query::default()
        };
        let rank = first_relevant(library, &query, &|doc| answers(doc_index(doc)), &|doc| own_rig(doc_index(doc)))?;
        ranks.push((i, rank));
    }
    Ok(ranks)
}

/// The rows as a Markdown table.
pub fn markdown(rows: &[ExampleRow]) -> String {
    let mut table = Table::new(&[&["queries' split", "queries' subset", "queries"][..], &RANK_HEADERS].concat());
    for r in rows {
        let cells = [r.split.to_string(), r.subset.to_string(), r.summary.queries.to_string()];
        table.row(&[&cells[..], &rank_cells(&r.summary)].concat());
    }
    table.into_text()
}

#[cfg(test)]
mod tests {
    use super::{GalleryClip, action_key, ranks_across_rigs};
    use anymo_retrieval::{ClipDocument, Entry, Library, Space, Spaces};

    fn clip(action: &str, skeleton: &str, angle_deg: f32, query: bool) -> GalleryClip {
        let a = angle_deg.to_radians();
        GalleryClip {
            action: Some(action.to_string()),
            skeleton: skeleton.to_string(),
            motion_vector: vec![a.cos(), a.sin()],
            query,
        }
    }

    fn library(gallery: &[GalleryClip]) -> Library {
        let space = |model: &str| Space { model: model.into(), dim: 2 };
        let mut library = Library::in_memory(Spaces { captions: space("captions"), motions: space("motions") });
        let entries = gallery.iter().enumerate().map(|(i, c)| Entry {
            document: ClipDocument {
                id: i as u64 + 1,
                path: format!("clip{i}"),
                captions: vec![],
                subject: String::new(),
                source: String::new(),
                licence: String::new(),
                skeleton: c.skeleton.clone(),
                joint_labels: vec![],
                seconds: 1.0,
            },
            caption_vector: None,
            motion_vector: Some(c.motion_vector.clone()),
        });
        library.upsert(entries.collect()).unwrap();
        library
    }

    #[test]
    fn ranks_count_only_other_rigs_and_find_the_first_same_action() {
        // The horse gallop's nearest clips are its own rig's (left out), then a wolf idle (rank
        // 1), then the wolf's gallop (rank 2) and a dog's gallop (rank 3).
        let gallery = vec![
            clip("gallop", "horse", 0.0, true),
            clip("idle", "horse", 1.0, false),
            clip("gallop", "horse", 2.0, false),
            clip("idle", "wolf", 10.0, false),
            clip("gallop", "wolf", 20.0, false),
            clip("gallop", "dog", 30.0, true),
            clip("wave", "human", 90.0, true),
        ];
        let ranks = ranks_across_rigs(&library(&gallery), &gallery).unwrap();
        // The wave has no partner on another rig and is not asked; the dog's gallop finds the
        // wolf's first (10 degrees off) before the horse's.
        assert_eq!(ranks, vec![(0, 2), (5, 1)]);
    }

    #[test]
    fn action_key_drops_the_subject_phrase_and_agrees_across_wordings() {
        assert_eq!(action_key("a white horse gallops", "horse").as_deref(), Some("gallop"));
        assert_eq!(action_key("a wolf gallops", "wolf").as_deref(), Some("gallop"));
        assert_eq!(
            action_key("a husky dog jumps while galloping", "husky dog").as_deref(),
            Some("jump while galloping")
        );
        assert_eq!(action_key("a mech robot walks", "mech").as_deref(), Some("walk"));
        assert_eq!(action_key("a man walks", "person").as_deref(), Some("walk"));
        assert_eq!(action_key("a person: walk", "person").as_deref(), Some("walk"));
        assert_eq!(
            action_key("a person bows in an active manner", "person").as_deref(),
            Some("bow in an active manner")
        );
        assert_eq!(
            action_key("a large monster shakes its head no", "large monster").as_deref(),
            Some("shake its head no")
        );
        assert_eq!(action_key("a cow is hit from the left", "cow").as_deref(), Some("is hit from the left"));
        assert_eq!(action_key("a horse", "horse"), None);
    }
}
