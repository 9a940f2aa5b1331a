//! A prompt is read as the caption it means when it is far from every caption a generator was
//! trained on, and as it is when it is among them: checked with the real sentence encoder on
//! the distinct captions of the corpus's training split, as `anymo train generator` keeps them.

use anymo_generator::CaptionAnchors;
use anymo_tests::{data_dir, manifest_rows, models_dir};
use anymo_tokenizer::dataset::{Split, split_of};
use anymo_tokenizer::text::SentenceEncoder;
use std::collections::BTreeSet;

fn cosine(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[test]
fn a_paraphrase_reads_as_the_caption_it_means_and_a_caption_as_itself() {
    let (Some(data), Some(models)) = (data_dir(), models_dir()) else { return };
    let encoder = SentenceEncoder::load(models.join(anymo_paths::ENCODER_DIR_NAME)).expect("the sentence encoder");
    let captions: BTreeSet<String> = manifest_rows(&data)
        .iter()
        .filter(|row| split_of(&row["path"]) == Split::Train)
        .flat_map(|row| row["text"].split(" | ").map(|c| c.trim().to_string()).collect::<Vec<_>>())
        .collect();
    let captions: Vec<&str> = captions.iter().map(String::as_str).collect();
    let anchors = CaptionAnchors::new(encoder.encode(&captions).unwrap().iter().map(Vec::as_slice)).unwrap();
    assert_eq!(anchors.len(), captions.len());

    // "a woman waves hello" captions training clips; the paraphrase shares no content word with
    // it. "a horse gallops" captions only a test clip; its nearest training caption is "a horse
    // jumps while galloping", which asks for more.
    assert!(captions.contains(&"a woman waves hello") && !captions.contains(&"a horse gallops"));
    let texts =
        ["a woman waves hello", "a lady signals hi to a neighbour", "a horse gallops", "a horse jumps while galloping"];
    let [caption, paraphrase, unseen, jumping] = <[Vec<f32>; 4]>::try_from(encoder.encode(&texts).unwrap()).unwrap();
    let same = |a: &[f32], b: &[f32]| cosine(a, b) > 0.99999;
    assert!(same(&anchors.read(&caption), &caption), "a caption reads as itself");
    assert!(same(&anchors.read(&paraphrase), &caption), "the paraphrase reads as the caption it means");
    assert!(cosine(&unseen, &jumping) >= anchors.within(), "the test caption lies among the training captions");
    assert!(same(&anchors.read(&unseen), &unseen), "and is read as it is");
    assert_eq!(anchors.read(&[0.0; 384]), [0.0; 384], "the unconditional prompt stays zero");
}
