//! Drawing tokens from logits (temperature, top-k, classifier-free guidance) and MoMask's
//! cosine masking schedule.

use rand::Rng;
use serde::{Deserialize, Serialize};

/// How tokens are drawn.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct Sampling {
    /// Softmax temperature; 0 takes the most likely token.
    pub temperature: f32,
    /// Only the `top_k` most likely tokens can be drawn (0: all).
    pub top_k: usize,
    /// Classifier-free guidance scale: 1 is the conditional model alone.
    pub guidance: f32,
}

impl Default for Sampling {
    fn default() -> Sampling {
        Sampling { temperature: 0.7, top_k: 0, guidance: 2.0 }
    }
}

/// Guided logits: `uncond + s (cond - uncond)`.
pub fn guide(conditional: &[f32], unconditional: &[f32], scale: f32) -> Vec<f32> {
    conditional.iter().zip(unconditional).map(|(c, u)| u + scale * (c - u)).collect()
}

/// Draws a token from `logits`; returns it and its probability under the tempered distribution.
pub fn draw<R: Rng + ?Sized>(logits: &[f32], sampling: &Sampling, rng: &mut R) -> (u32, f32) {
    if sampling.temperature <= 0.0 {
        let (best, _) =
            logits.iter().enumerate().fold((0, f32::NEG_INFINITY), |a, (i, &v)| if v > a.1 { (i, v) } else { a });
        return (best as u32, softmax_at(logits, 1.0, best));
    }
    let mut order: Vec<usize> = (0..logits.len()).collect();
    if sampling.top_k > 0 && sampling.top_k < logits.len() {
        order.select_nth_unstable_by(sampling.top_k - 1, |&a, &b| logits[b].total_cmp(&logits[a]));
        order.truncate(sampling.top_k);
    }
    let max = order.iter().map(|&i| logits[i]).fold(f32::NEG_INFINITY, f32::max);
    let weights: Vec<f32> = order.iter().map(|&i| ((logits[i] - max) / sampling.temperature).exp()).collect();
    let total: f32 = weights.iter().sum();
    let mut u = rng.random::<f32>() * total;
    for (k, &w) in weights.iter().enumerate() {
        if u < w || k + 1 == weights.len() {
            return (order[k] as u32, w / total);
        }
        u -= w;
    }
    unreachable!("the loop returns at its last weight")
}

fn softmax_at(logits: &[f32], temperature: f32, at: usize) -> f32 {
    let max = logits.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let total: f32 = logits.iter().map(|v| ((v - max) / temperature).exp()).sum();
    ((logits[at] - max) / temperature).exp() / total
}

/// Tokens still masked after step `step` of `steps` when `masked` start masked (cosine schedule).
pub fn still_masked(masked: usize, step: usize, steps: usize) -> usize {
    let ratio = (std::f64::consts::FRAC_PI_2 * (step + 1) as f64 / steps as f64).cos();
    ((masked as f64 * ratio).floor() as usize).min(masked.saturating_sub(1))
}

/// Fraction of a sequence masked in training for a uniform draw `u` (cosine schedule).
pub fn training_mask_ratio(u: f32) -> f32 {
    (std::f32::consts::FRAC_PI_2 * u).cos()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn top_k_one_is_greedy_and_seeds_repeat() {
        let logits = [0.1, 3.0, 2.9, -1.0];
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let top1 = Sampling { temperature: 1.0, top_k: 1, guidance: 1.0 };
        for _ in 0..20 {
            assert_eq!(draw(&logits, &top1, &mut rng).0, 1);
        }
        let any = Sampling { temperature: 1.0, top_k: 0, guidance: 1.0 };
        let a: Vec<u32> =
            (0..50).scan(rand_chacha::ChaCha8Rng::seed_from_u64(9), |r, _| Some(draw(&logits, &any, r).0)).collect();
        let b: Vec<u32> =
            (0..50).scan(rand_chacha::ChaCha8Rng::seed_from_u64(9), |r, _| Some(draw(&logits, &any, r).0)).collect();
        assert_eq!(a, b);
        assert!(a.contains(&2), "a near-tie is drawn sometimes");
    }

    #[test]
    fn sampling_follows_the_softmax() {
        let logits = [0.0, 2f32.ln()];
        let any = Sampling { temperature: 1.0, top_k: 0, guidance: 1.0 };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let ones = (0..30_000).filter(|_| draw(&logits, &any, &mut rng).0 == 1).count();
        assert!((ones as f64 / 30_000.0 - 2.0 / 3.0).abs() < 0.01, "{ones}");
    }

    #[test]
    fn the_schedule_unmasks_everything_by_the_last_step() {
        let left: Vec<usize> = (0..10).map(|s| still_masked(30, s, 10)).collect();
        assert!(left.windows(2).all(|w| w[0] >= w[1]), "{left:?}");
        assert_eq!(left[9], 0);
        assert!(left[0] < 30);
        assert_eq!(guide(&[2.0], &[1.0], 3.0), vec![4.0]);
    }
}
