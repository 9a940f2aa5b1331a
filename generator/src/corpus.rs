//! Clips as the token models see them (codes, encoder latents, caption and skeleton
//! embeddings) and batches of equal-length crops drawn from them.

use rand::Rng;
use rand::seq::IndexedRandom;

/// One clip, tokenized whole by TAT.
#[derive(Clone, Debug)]
pub struct TokenClip {
    /// The clip's key in the corpus.
    pub key: String,
    /// Who moves (`person`, `horse`, ...).
    pub subject: String,
    /// Its captions.
    pub captions: Vec<String>,
    /// Sentence embedding of each caption.
    pub text: Vec<Vec<f32>>,
    /// OwO global embedding of its skeleton.
    pub skeleton: Vec<f32>,
    /// `steps x layers` RVQ codes.
    pub codes: Vec<Vec<u32>>,
    /// `steps x latent_dim` encoder output before quantisation (what the evaluator reads).
    pub latent: Vec<f32>,
    /// The same for the clip's own codes decoded and encoded again (empty when not computed):
    /// the evaluator also trains on these, so that it measures motion, not the tokenizer's
    /// reconstruction error.
    pub decoded_latent: Vec<f32>,
}

impl TokenClip {
    /// Token steps.
    pub fn steps(&self) -> usize {
        self.codes.len()
    }

    /// Width of a latent row.
    pub fn latent_dim(&self) -> usize {
        self.latent.len() / self.steps().max(1)
    }
}

/// A crop of a clip in a batch: `length` steps from `start`, described by caption `caption`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Crop {
    /// Index of the clip.
    pub clip: usize,
    /// First step.
    pub start: usize,
    /// Index of the caption.
    pub caption: usize,
}

/// A batch of `batch` crops of one length (so no padding is needed): the length is that of a
/// random clip (capped at `max_tokens`), and crops come from clips at most half as long again,
/// so a caption still describes most of its crop.
pub fn draw_batch(clips: &[TokenClip], batch: usize, max_tokens: usize, rng: &mut impl Rng) -> (usize, Vec<Crop>) {
    let usable: Vec<usize> = (0..clips.len()).filter(|&i| clips[i].steps() >= 2).collect();
    let anchor = *usable.choose(rng).expect("a corpus with a clip of at least two token steps");
    let length = clips[anchor].steps().min(max_tokens);
    let longest = if length == max_tokens { usize::MAX } else { length + length.div_ceil(2) };
    let near: Vec<usize> = usable.iter().copied().filter(|&i| (length..=longest).contains(&clips[i].steps())).collect();
    let crops = (0..batch)
        .map(|_| {
            let clip = *near.choose(rng).expect("the anchor itself is near");
            let c = &clips[clip];
            Crop {
                clip,
                start: rng.random_range(0..=c.steps() - length),
                caption: rng.random_range(0..c.captions.len()),
            }
        })
        .collect();
    (length, crops)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn clip(steps: usize) -> TokenClip {
        TokenClip {
            key: format!("c{steps}"),
            subject: "person".into(),
            captions: vec!["a".into(), "b".into()],
            text: vec![vec![0.0; 4]; 2],
            skeleton: vec![0.0; 2],
            codes: vec![vec![0; 2]; steps],
            latent: vec![0.0; steps * 3],
            decoded_latent: Vec::new(),
        }
    }

    #[test]
    fn crops_fit_their_clips_and_share_a_length() {
        let clips: Vec<TokenClip> = [1, 3, 8, 10, 11, 40, 90].into_iter().map(clip).collect();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..200 {
            let (length, crops) = draw_batch(&clips, 16, 32, &mut rng);
            assert!((2..=32).contains(&length));
            for c in crops {
                let steps = clips[c.clip].steps();
                assert!(c.start + length <= steps);
                assert!(length == 32 || steps <= length + length.div_ceil(2), "{steps} for {length}");
            }
        }
        assert_eq!(clips[2].latent_dim(), 3);
    }
}
