//! The shipped paraphrase benchmark measures what it claims on the real corpus: every query is
//! answered by at least one test clip, and no query shares a content word (up to a crude stem)
//! with the captions of the clips that answer it, so BM25 cannot find them by the query's words.

use anymo_retrieval::benchmark::{PARAPHRASES, parse};
use anymo_tests::data_dir;
use anymo_tokenizer::dataset::{Split, split_of};
use std::collections::BTreeSet;

/// Words that carry no content (articles, prepositions, pronouns, conjunctions).
const FUNCTION_WORDS: &[&str] = &[
    "a", "an", "the", "in", "on", "of", "with", "to", "and", "or", "its", "his", "her", "their", "them", "is", "are",
    "at", "by", "for", "from", "as", "into", "onto", "then", "while", "after", "before", "one", "both",
];

fn content_words(text: &str) -> Vec<String> {
    text.split(|c: char| !c.is_alphanumeric())
        .filter(|w| !w.is_empty())
        .map(str::to_lowercase)
        .filter(|w| !FUNCTION_WORDS.contains(&w.as_str()))
        .collect()
}

/// A crude stem: one common suffix off, keeping at least three letters.
fn stem(word: &str) -> &str {
    for suffix in ["ing", "ed", "es", "s", "ly"] {
        if let Some(root) = word.strip_suffix(suffix).filter(|r| r.len() >= 3) {
            return root;
        }
    }
    word
}

/// Same stem, or one stem (of four letters or more) begins the other ("wave" / "waves").
fn related(a: &str, b: &str) -> bool {
    let (a, b) = (stem(a), stem(b));
    a == b || (a.len() >= 4 && b.starts_with(a)) || (b.len() >= 4 && a.starts_with(b))
}

#[test]
fn the_stem_rule_catches_inflections_and_keeps_distinct_words_apart() {
    assert!(related("waving", "waves") && related("gallops", "gallop") && related("hand", "hands"));
    assert!(!related("stroll", "walks") && !related("raptor", "velociraptor") && !related("man", "many"));
}

#[test]
fn every_paraphrase_is_answered_by_test_clips_whose_captions_share_none_of_its_words() {
    let Some(data) = data_dir() else { return };
    let manifest = std::fs::read_to_string(data.join("manifest.tsv")).expect("a readable manifest");
    let mut lines = manifest.lines();
    let header: Vec<&str> = lines.next().expect("a header").split('\t').collect();
    let column = |name: &str| header.iter().position(|h| *h == name).expect("manifest column");
    let (path, text) = (column("path"), column("text"));
    let test_captions: Vec<Vec<String>> = lines
        .map(|l| l.split('\t').collect::<Vec<&str>>())
        .filter(|row| split_of(row[path]) == Split::Test)
        .map(|row| row[text].split(" | ").map(String::from).collect())
        .collect();
    assert!(test_captions.len() > 100, "{} test clips", test_captions.len());

    let queries = parse(PARAPHRASES).expect("the shipped benchmark parses");
    let mut failures = Vec::new();
    for q in &queries {
        let answers: Vec<&Vec<String>> = test_captions.iter().filter(|c| q.relevance.accepts(c)).collect();
        if answers.is_empty() {
            failures.push(format!("{:?}: no test clip answers it", q.text));
            continue;
        }
        let caption_words: BTreeSet<String> =
            answers.iter().flat_map(|c| c.iter()).flat_map(|c| content_words(c)).collect();
        let shared: Vec<String> =
            content_words(&q.text).into_iter().filter(|w| caption_words.iter().any(|c| related(w, c))).collect();
        if !shared.is_empty() {
            failures.push(format!("{:?} shares {shared:?} with its answers' captions", q.text));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
