//! The shipped held-out prompts of `anymo eval prompts` are held out from the real corpus: no
//! prompt shares a content word (up to a crude stem) with any caption, in any split, of the
//! clips of the action it asks for, and every action has real clips to calibrate its checks on;
//! nor any word with the synonyms generators are trained on.

use anymo_generator::paraphrase::SYNONYMS;
use anymo_models::eval::prompts::{ACTIONS, Body, HELDOUT_PROMPTS, action, parse_prompts};
use anymo_models::generation::is_human;
use anymo_tests::words::{content_words, related};
use anymo_tests::{data_dir, manifest_rows};
use std::collections::BTreeSet;

#[test]
fn no_held_out_prompt_shares_a_word_with_the_captions_of_its_action() {
    let Some(data) = data_dir() else { return };
    // (human subject, lowercase captions) of every clip.
    let clips: Vec<(bool, Vec<String>)> = manifest_rows(&data)
        .iter()
        .map(|row| (is_human(&row["subject"]), row["text"].split(" | ").map(str::to_lowercase).collect()))
        .collect();
    let captions_of = |name: &str| -> Vec<&String> {
        let action = action(name).expect("a known action");
        clips
            .iter()
            .filter(|(human, _)| *human == (action.body == Body::Human))
            .filter(|(_, captions)| captions.iter().any(|c| (action.describes)(c)))
            .flat_map(|(_, captions)| captions)
            .collect()
    };
    for action in &ACTIONS {
        assert!(captions_of(action.name).len() >= 3, "{}: too few real clips to calibrate on", action.name);
    }

    let prompts = parse_prompts(HELDOUT_PROMPTS).expect("the shipped prompts parse");
    let mut failures = Vec::new();
    for p in &prompts {
        let caption_words: BTreeSet<String> = captions_of(&p.action).iter().flat_map(|c| content_words(c)).collect();
        let shared: Vec<String> =
            content_words(&p.text).into_iter().filter(|w| caption_words.iter().any(|c| related(w, c))).collect();
        if !shared.is_empty() {
            failures.push(format!("{} {:?} shares {shared:?} with its action's captions", p.action, p.text));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn the_caption_augmentation_uses_no_word_of_the_held_out_prompts() {
    // Training rewords captions with these groups; the prompts must stay unseen wording.
    let lexicon: BTreeSet<String> =
        SYNONYMS.iter().flat_map(|group| group.iter()).flat_map(|phrase| content_words(phrase)).collect();
    let prompts = parse_prompts(HELDOUT_PROMPTS).expect("the shipped prompts parse");
    let shared: BTreeSet<String> =
        prompts.iter().flat_map(|p| content_words(&p.text)).filter(|w| lexicon.iter().any(|l| related(w, l))).collect();
    assert!(shared.is_empty(), "the held-out prompts share {shared:?} with the augmentation's synonyms");
}
