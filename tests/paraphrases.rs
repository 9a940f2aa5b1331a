//! The shipped paraphrase benchmark measures what it claims on the real corpus: every query is
//! answered by at least one test clip, and no query shares a content word (up to a crude stem)
//! with the captions of the clips that answer it, so BM25 cannot find them by the query's words.

use anymo_retrieval::benchmark::{PARAPHRASES, parse};
use anymo_tests::words::{content_words, related};
use anymo_tests::{data_dir, manifest_rows};
use anymo_tokenizer::dataset::{Split, split_of};
use std::collections::BTreeSet;

#[test]
fn the_stem_rule_catches_inflections_and_keeps_distinct_words_apart() {
    assert!(related("waving", "waves") && related("gallops", "gallop") && related("hand", "hands"));
    assert!(!related("stroll", "walks") && !related("raptor", "velociraptor") && !related("man", "many"));
}

#[test]
fn every_paraphrase_is_answered_by_test_clips_whose_captions_share_none_of_its_words() {
    let Some(data) = data_dir() else { return };
    let test_captions: Vec<Vec<String>> = manifest_rows(&data)
        .iter()
        .filter(|row| split_of(&row["path"]) == Split::Test)
        .map(|row| row["text"].split(" | ").map(String::from).collect())
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
