//! Clips of any length through fixed-size windows (SATA B.1): windows of `window` frames that
//! share `overlap` frames with the next, decoded and cross-faded over the shared frames.

use super::anchor::{self, RootAnchor, anchor_frames};
use super::codec::Codec;
use super::objective::Prepared;
use crate::dataset::Batch;
use crate::owo::SkeletonGraph;
use anymo_motion::features::{MotionFeatures, ROOT_DIMS, ROT_DIMS, Start, canonicalise, from_features, to_features};
use anymo_motion::motion::Motion;
use anymo_motion::skeleton::Skeleton;
use candle_core::{Device, Result, Tensor};
use rand::SeedableRng;
use serde::{Deserialize, Serialize};

/// First frames of the windows covering `frames` frames: every `window - overlap` frames, the
/// last one flush with the end (a clip shorter than a window gets one padded window).
pub fn window_starts(frames: usize, window: usize, overlap: usize) -> Vec<usize> {
    if frames <= window {
        return vec![0];
    }
    let stride = window - overlap;
    let mut starts: Vec<usize> = (0..).map(|k| k * stride).take_while(|&s| s + window < frames).collect();
    starts.push(frames - window);
    starts.dedup();
    starts
}

/// Features of a clip cut into windows, as a batch for one skeleton (short clips repeat their
/// last frame; the mask marks it).
pub fn windows_batch(features: &MotionFeatures, skeleton: &Skeleton, starts: &[usize], window: usize) -> Result<Batch> {
    let (j, frames) = (features.joints, features.frames);
    let b = starts.len();
    let (mut root, mut rotations, mut mask) = (Vec::new(), Vec::new(), Vec::new());
    for &s in starts {
        for f in 0..window {
            let src = (s + f).min(frames - 1);
            root.extend_from_slice(&features.root[src * ROOT_DIMS..(src + 1) * ROOT_DIMS]);
            rotations.extend_from_slice(&features.rotations[src * j * ROT_DIMS..(src + 1) * j * ROT_DIMS]);
            mask.push(if s + f < frames { 1.0f32 } else { 0.0 });
        }
    }
    let offsets: Vec<f32> =
        (0..b).flat_map(|_| skeleton.joints().iter().flat_map(|joint| joint.offset.to_array())).collect();
    let device = Device::Cpu;
    Ok(Batch {
        group: 0,
        parents: skeleton.parents().collect(),
        root: Tensor::from_vec(root, (b, window, ROOT_DIMS), &device)?,
        rotations: Tensor::from_vec(rotations, (b, window, j, ROT_DIMS), &device)?,
        offsets: Tensor::from_vec(offsets, (b, j, 3), &device)?,
        mask: Tensor::from_vec(mask, (b, window), &device)?,
        sources: starts.iter().map(|&s| (0, s)).collect(),
    })
}

/// Cross-fades decoded windows `(W, window, J, 6)` and `(W, window, 4)` into one clip's features.
pub fn blend(
    rotations: &[f32],
    root: &[f32],
    joints: usize,
    starts: &[usize],
    window: usize,
    frames: usize,
) -> MotionFeatures {
    let mut rot = vec![0f32; frames * joints * ROT_DIMS];
    let mut rt = vec![0f32; frames * ROOT_DIMS];
    let mut weight = vec![0f32; frames];
    for (w, &s) in starts.iter().enumerate() {
        // Ramps over the frames shared with the previous and the next window.
        let shared_before = if w > 0 { (starts[w - 1] + window).saturating_sub(s) } else { 0 };
        let shared_after = if w + 1 < starts.len() { (s + window).saturating_sub(starts[w + 1]) } else { 0 };
        for f in 0..window.min(frames - s) {
            let mut k = 1.0f32;
            if f < shared_before {
                k = k.min((f as f32 + 1.0) / (shared_before as f32 + 1.0));
            }
            if f >= window - shared_after {
                k = k.min((window - f) as f32 / (shared_after as f32 + 1.0));
            }
            let (dst, src) = (s + f, w * window + f);
            weight[dst] += k;
            for c in 0..joints * ROT_DIMS {
                rot[dst * joints * ROT_DIMS + c] += k * rotations[src * joints * ROT_DIMS + c];
            }
            for c in 0..ROOT_DIMS {
                rt[dst * ROOT_DIMS + c] += k * root[src * ROOT_DIMS + c];
            }
        }
    }
    for f in 0..frames {
        let k = 1.0 / weight[f].max(1e-6);
        rot[f * joints * ROT_DIMS..(f + 1) * joints * ROT_DIMS].iter_mut().for_each(|v| *v *= k);
        rt[f * ROOT_DIMS..(f + 1) * ROOT_DIMS].iter_mut().for_each(|v| *v *= k);
    }
    MotionFeatures { frames, joints, root: rt, rotations: rot }
}

/// A clip through a codec, with the canonicalised truth it is measured against.
pub struct Reconstructed {
    /// The canonicalised clip.
    pub truth: Motion,
    /// The reconstruction with the root pinned to the truth's anchors at every window start, as
    /// [`tokenize`] and [`detokenize`] deliver it.
    pub anchored: Motion,
    /// The reconstruction with the root integrated from the decoded rates alone, as generated
    /// tokens (which carry no anchors) decode.
    pub free: Motion,
    /// The reconstruction with the truth's root (its path, heading and orientation) in place of
    /// the decoded one: what is left is the error of the other joints.
    pub true_root: Motion,
}

/// A clip through a codec: canonicalised, windowed, encoded, quantised, decoded and blended.
pub fn reconstruct(
    codec: &mut dyn Codec,
    graph: &SkeletonGraph,
    motion: &Motion,
    window: usize,
    overlap: usize,
) -> Result<Reconstructed> {
    let truth = canonicalise(motion);
    let (features, start) = to_features(&truth);
    let starts = window_starts(features.frames, window, overlap);
    let batch = windows_batch(&features, truth.skeleton(), &starts, window)?;
    let prepared = Prepared::new(&batch, codec.root_stats())?;
    let out = codec.reconstruct(&prepared, graph, false, &mut rand_chacha::ChaCha8Rng::seed_from_u64(0))?;
    let root = codec.root_stats().denormalise(&out.prediction.root)?;
    let mut decoded = blend(
        &out.prediction.rotations.flatten_all()?.to_vec1()?,
        &root.flatten_all()?.to_vec1()?,
        features.joints,
        &starts,
        window,
        features.frames,
    );
    let free = from_features(&decoded, start, truth.skeleton(), truth.frame_time());
    anchor::pin(&mut decoded, &anchor::measure(&features, &anchor_frames(&starts, features.frames)));
    let anchored = from_features(&decoded, start, truth.skeleton(), truth.frame_time());
    let mut with_true_root = decoded;
    with_true_root.root.copy_from_slice(&features.root);
    let row = features.joints * ROT_DIMS;
    for f in 0..features.frames {
        with_true_root.rotations[f * row..f * row + ROT_DIMS]
            .copy_from_slice(&features.rotations[f * row..f * row + ROT_DIMS]);
    }
    let true_root = from_features(&with_true_root, start, truth.skeleton(), truth.frame_time());
    Ok(Reconstructed { truth, anchored, free, true_root })
}

/// A clip as tokens: per window, per token step, one code per RVQ layer.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Tokens {
    /// Frames of the clip.
    pub frames: usize,
    /// Frames per second.
    pub fps: f64,
    /// Frames per window.
    pub window: usize,
    /// First frame of each window.
    pub starts: Vec<usize>,
    /// Where and which way the clip starts (heading in radians, x and z in skeleton diameters).
    pub start: [f32; 3],
    /// `windows x steps x layers` codes.
    pub codes: Vec<Vec<Vec<u32>>>,
    /// The root at each window's first frame and the clip's last frame, which decoding holds the
    /// root to (none for generated tokens: their root runs free).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub anchors: Vec<RootAnchor>,
}

impl Tokens {
    /// The start the features leave out.
    pub fn start(&self) -> Start {
        Start { heading: self.start[0], planar: [self.start[1], self.start[2]] }
    }
}

/// Tokenizes a cleaned clip (diameter 1, model frame rate) with TAT.
pub fn tokenize(tat: &mut super::Tat, graph: &SkeletonGraph, motion: &Motion) -> Result<Tokens> {
    let (window, overlap) = (tat.config().window, tat.config().overlap);
    let truth = canonicalise(motion);
    let (_, original_start) = to_features(motion);
    let (features, _) = to_features(&truth);
    let starts = window_starts(features.frames, window, overlap);
    let batch = windows_batch(&features, truth.skeleton(), &starts, window)?;
    let prepared = Prepared::new(&batch, &tat.config().root)?;
    let condition = tat.condition(graph, &prepared.offsets)?;
    let codes = tat.encode(&prepared.input, &condition)?;
    let steps = codes.len() / starts.len();
    let anchors = anchor::measure(&features, &anchor_frames(&starts, features.frames));
    Ok(Tokens {
        frames: features.frames,
        fps: motion.fps(),
        window,
        starts,
        start: [original_start.heading, original_start.planar[0], original_start.planar[1]],
        codes: codes.chunks(steps).map(|c| c.to_vec()).collect(),
        anchors,
    })
}

/// A whole clip encoded in one window: its tokens and the encoder's latents before
/// quantisation (what the text-motion evaluator reads).
pub struct Encoded {
    /// The tokens (one window covering the clip).
    pub tokens: Tokens,
    /// `steps x latent_dim` latents.
    pub latent: Vec<f32>,
}

/// Encodes a cleaned clip in one window, padded to whole token steps. The encoder is
/// convolutional in time and attends over joints only, so a window of any length is valid.
pub fn encode_whole(tat: &mut super::Tat, graph: &SkeletonGraph, motion: &Motion) -> Result<Encoded> {
    let per_token = tat.config().tat.frames_per_token();
    let truth = canonicalise(motion);
    let (_, original_start) = to_features(motion);
    let (features, _) = to_features(&truth);
    let window = features.frames.div_ceil(per_token) * per_token;
    let batch = windows_batch(&features, truth.skeleton(), &[0], window)?;
    let prepared = Prepared::new(&batch, &tat.config().root)?;
    let condition = tat.condition(graph, &prepared.offsets)?;
    let (latent, codes) = tat.encode_with_latent(&prepared.input, &condition)?;
    Ok(Encoded {
        tokens: Tokens {
            frames: features.frames,
            fps: motion.fps(),
            window,
            starts: vec![0],
            start: [original_start.heading, original_start.planar[0], original_start.planar[1]],
            codes: vec![codes],
            anchors: Vec::new(),
        },
        latent: latent.flatten_all()?.to_vec1()?,
    })
}

impl Tokens {
    /// Tokens of one window of generated codes (`steps x layers`), starting at the origin.
    pub fn whole(codes: Vec<Vec<u32>>, frames_per_token: usize, fps: f64) -> Tokens {
        let frames = codes.len() * frames_per_token;
        Tokens {
            frames,
            fps,
            window: frames,
            starts: vec![0],
            start: [0.0; 3],
            codes: vec![codes],
            anchors: Vec::new(),
        }
    }
}

/// Decodes tokens onto a cleaned skeleton (diameter 1), the root held to the tokens' anchors.
pub fn detokenize(tat: &super::Tat, tokens: &Tokens, graph: &SkeletonGraph, skeleton: &Skeleton) -> Result<Motion> {
    let windows = tokens.codes.len();
    let j = skeleton.len();
    let offsets: Vec<f32> =
        (0..windows).flat_map(|_| skeleton.joints().iter().flat_map(|joint| joint.offset.to_array())).collect();
    let offsets = Tensor::from_vec(offsets, (windows, j, 3), &Device::Cpu)?;
    let condition = tat.condition(graph, &offsets)?;
    let flat: Vec<Vec<u32>> = tokens.codes.iter().flatten().cloned().collect();
    let prediction = tat.decode(&flat, windows, &condition)?;
    let root = tat.config().root.denormalise(&prediction.root)?;
    let mut decoded = blend(
        &prediction.rotations.flatten_all()?.to_vec1()?,
        &root.flatten_all()?.to_vec1()?,
        j,
        &tokens.starts,
        tokens.window,
        tokens.frames,
    );
    anchor::pin(&mut decoded, &tokens.anchors);
    Ok(from_features(&decoded, tokens.start(), skeleton, 1.0 / tokens.fps))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_cover_the_clip_with_the_overlap() {
        assert_eq!(window_starts(40, 64, 16), vec![0]);
        assert_eq!(window_starts(64, 64, 16), vec![0]);
        assert_eq!(window_starts(112, 64, 16), vec![0, 48]);
        assert_eq!(window_starts(130, 64, 16), vec![0, 48, 66]);
    }

    #[test]
    fn tokens_written_before_anchors_still_read_and_decode_free() {
        let old = r#"{"frames":20,"fps":30.0,"window":20,"starts":[0],"start":[0.5,1.0,2.0],"codes":[[[1,2]]]}"#;
        let tokens: Tokens = serde_json::from_str(old).unwrap();
        assert!(tokens.anchors.is_empty());
        assert_eq!(tokens.start(), Start { heading: 0.5, planar: [1.0, 2.0] });
        assert!(!serde_json::to_string(&tokens).unwrap().contains("anchors"), "no anchors, no field");
    }

    #[test]
    fn blending_identical_windows_gives_them_back() {
        let (joints, window) = (2, 8);
        let starts = window_starts(14, window, 2);
        let frames = 14;
        // Each window carries the frame index as its values, so any weighting returns it.
        let mut rot = Vec::new();
        let mut root = Vec::new();
        for &s in &starts {
            for f in 0..window {
                rot.extend(std::iter::repeat_n((s + f) as f32, joints * ROT_DIMS));
                root.extend(std::iter::repeat_n((s + f) as f32, ROOT_DIMS));
            }
        }
        let out = blend(&rot, &root, joints, &starts, window, frames);
        for f in 0..frames {
            assert!((out.root[f * ROOT_DIMS] - f as f32).abs() < 1e-5, "frame {f}");
            assert!((out.rotations[f * joints * ROT_DIMS + 5] - f as f32).abs() < 1e-5);
        }
    }
}
