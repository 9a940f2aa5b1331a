//! The training data loader: random windows of clips, augmented (mirroring, rest-pose
//! rebasing, bone-length scaling), canonicalised, turned into model features and batched by
//! skeleton into candle tensors. Deterministic for a seed (ChaCha8, whose stream is fixed
//! across platforms and versions).

use anymo_motion::features::{ROOT_DIMS, ROT_DIMS, canonicalise, to_features};
use anymo_motion::motion::Motion;
use anymo_motion::prep::augment::{mirror, rebase_rest_pose, scale_bones, symmetric_factors};
use candle_core::{Device, Tensor};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::BTreeMap;

/// How windows are cut and augmented.
#[derive(Clone, Debug)]
pub struct LoaderConfig {
    /// Frames per window; shorter clips are padded (see [`Batch::mask`]).
    pub window: usize,
    /// Windows per batch (at most; the last batch of a skeleton may be smaller).
    pub batch_size: usize,
    /// Seed of the random choices.
    pub seed: u64,
    /// Probability of mirroring a window (when its skeleton has left/right pairs).
    pub mirror: f64,
    /// Probability of rebasing a window's rest pose on one of its frames (NEC C.1). Rebased
    /// windows have rotations near the identity; real clips of rigs with bone-aligned frames
    /// have rotations far from it, so a high share of rebased windows starves those.
    pub rebase: f64,
    /// Bone lengths are scaled by factors drawn from `[1 - s, 1 + s]` (0 turns it off).
    pub bone_scale: f32,
    /// At most this many joints over all windows of a batch, so batches of large skeletons
    /// hold fewer windows and memory stays bounded.
    pub max_batch_joints: usize,
}

impl Default for LoaderConfig {
    fn default() -> Self {
        LoaderConfig {
            window: 64,
            batch_size: 16,
            seed: 0,
            mirror: 0.5,
            rebase: 0.1,
            bone_scale: 0.1,
            max_batch_joints: 512,
        }
    }
}

/// One batch: windows of clips that share a skeleton topology.
#[derive(Debug)]
pub struct Batch {
    /// Index of the skeleton group (clips with the same parents and joint names).
    pub group: usize,
    /// Parent of each joint.
    pub parents: Vec<Option<usize>>,
    /// `(B, T, ROOT_DIMS)`: yaw rate, heading-frame velocity x and z, height.
    pub root: Tensor,
    /// `(B, T, J, ROT_DIMS)`: rot6D of every joint (the root without its heading).
    pub rotations: Tensor,
    /// `(B, J, 3)`: each window's rest offsets (augmentation changes them).
    pub offsets: Tensor,
    /// `(B, T)`: 1 for real frames, 0 for padding after a short clip's end.
    pub mask: Tensor,
    /// For each window, the clip it came from and its first frame.
    pub sources: Vec<(usize, usize)>,
}

/// Windows of training clips, batched by skeleton.
pub struct WindowLoader {
    clips: Vec<Motion>,
    groups: Vec<Vec<usize>>,
    config: LoaderConfig,
    rng: ChaCha8Rng,
}

impl WindowLoader {
    /// A loader over cleaned clips (see [`anymo_motion::prep::clean`]).
    pub fn new(clips: Vec<Motion>, config: LoaderConfig) -> WindowLoader {
        let mut by_topology: BTreeMap<Vec<(Option<usize>, String)>, Vec<usize>> = BTreeMap::new();
        for (i, clip) in clips.iter().enumerate() {
            let key = clip.skeleton().joints().iter().map(|j| (j.parent, j.name.clone())).collect();
            by_topology.entry(key).or_default().push(i);
        }
        let rng = ChaCha8Rng::seed_from_u64(config.seed);
        WindowLoader { clips, groups: by_topology.into_values().collect(), config, rng }
    }

    /// The number of skeleton groups.
    pub fn groups(&self) -> usize {
        self.groups.len()
    }

    /// Restarts the random sequence from `seed` (a new epoch of a resumed run).
    pub fn reseed(&mut self, seed: u64) {
        self.rng = ChaCha8Rng::seed_from_u64(seed);
    }

    /// The skeleton shared by the clips of a group (rest offsets of its first clip).
    pub fn group_skeleton(&self, group: usize) -> &anymo_motion::skeleton::Skeleton {
        self.clips[self.groups[group][0]].skeleton()
    }

    /// One epoch: every clip gives one window per `window` frames of its length (at least one),
    /// at random starts; windows are shuffled within their group and batched; batches of all
    /// groups are shuffled.
    pub fn epoch(&mut self) -> candle_core::Result<Vec<Batch>> {
        let mut plans: Vec<(usize, Vec<(usize, usize)>)> = Vec::new();
        for (g, members) in self.groups.iter().enumerate() {
            let mut windows = Vec::new();
            for &c in members {
                let frames = self.clips[c].frames();
                let count = (frames / self.config.window).max(1);
                for _ in 0..count {
                    let start = if frames > self.config.window {
                        self.rng.random_range(0..=frames - self.config.window)
                    } else {
                        0
                    };
                    windows.push((c, start));
                }
            }
            shuffle(&mut windows, &mut self.rng);
            let joints = self.clips[members[0]].skeleton().len();
            let size = self.config.batch_size.min(self.config.max_batch_joints / joints).max(1);
            for batch in windows.chunks(size) {
                plans.push((g, batch.to_vec()));
            }
        }
        shuffle(&mut plans, &mut self.rng);
        plans.into_iter().map(|(g, windows)| self.batch(g, windows)).collect()
    }

    fn batch(&mut self, group: usize, windows: Vec<(usize, usize)>) -> candle_core::Result<Batch> {
        let t = self.config.window;
        let first = &self.clips[windows[0].0];
        let j = first.skeleton().len();
        let parents: Vec<Option<usize>> = first.skeleton().parents().collect();
        let b = windows.len();
        let (mut root, mut rotations) =
            (Vec::with_capacity(b * t * ROOT_DIMS), Vec::with_capacity(b * t * j * ROT_DIMS));
        let (mut offsets, mut mask) = (Vec::with_capacity(b * j * 3), Vec::with_capacity(b * t));
        for &(clip, start) in &windows {
            let motion = self.window(clip, start);
            let motion = self.augment(motion);
            let (features, _) = to_features(&canonicalise(&motion));
            let real = features.frames;
            for f in 0..t {
                // Padding repeats the last real frame, masked out.
                let src = f.min(real - 1);
                root.extend_from_slice(&features.root[src * ROOT_DIMS..(src + 1) * ROOT_DIMS]);
                rotations.extend_from_slice(&features.rotations[src * j * ROT_DIMS..(src + 1) * j * ROT_DIMS]);
                mask.push(if f < real { 1.0f32 } else { 0.0 });
            }
            offsets.extend(motion.skeleton().joints().iter().flat_map(|joint| joint.offset.to_array()));
        }
        let device = Device::Cpu;
        Ok(Batch {
            group,
            parents,
            root: Tensor::from_vec(root, (b, t, ROOT_DIMS), &device)?,
            rotations: Tensor::from_vec(rotations, (b, t, j, ROT_DIMS), &device)?,
            offsets: Tensor::from_vec(offsets, (b, j, 3), &device)?,
            mask: Tensor::from_vec(mask, (b, t), &device)?,
            sources: windows,
        })
    }

    /// Frames `start..start + window` of a clip (fewer at its end).
    fn window(&self, clip: usize, start: usize) -> Motion {
        let m = &self.clips[clip];
        let end = (start + self.config.window).min(m.frames());
        let n = m.skeleton().len();
        let rotations = m.all_rotations()[start * n..end * n].to_vec();
        let translations = m.all_translations()[start * n..end * n].to_vec();
        Motion::new(m.skeleton().clone(), m.frame_time(), rotations, translations).expect("a slice of a motion")
    }

    fn augment(&mut self, mut motion: Motion) -> Motion {
        if self.rng.random_bool(self.config.mirror)
            && let Ok(mirrored) = mirror(&motion)
        {
            motion = mirrored;
        }
        if self.rng.random_bool(self.config.rebase) {
            let base = self.rng.random_range(0..motion.frames());
            motion = rebase_rest_pose(&motion, base);
        }
        if self.config.bone_scale > 0.0 {
            let s = self.config.bone_scale;
            let raw: Vec<f32> =
                (0..motion.skeleton().len()).map(|_| self.rng.random_range(1.0 - s..=1.0 + s)).collect();
            let mut factors = symmetric_factors(motion.skeleton(), &raw);
            factors[0] = 1.0;
            motion = scale_bones(&motion, &factors);
        }
        motion
    }
}

/// Fisher-Yates with the loader's generator (kept here so the order depends only on the seed).
fn shuffle<T>(items: &mut [T], rng: &mut ChaCha8Rng) {
    for i in (1..items.len()).rev() {
        items.swap(i, rng.random_range(0..=i));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use anymo_motion::bvh::parse_str;

    fn clip(name: &str, frames: usize) -> Motion {
        let mut text = format!(
            "HIERARCHY\nROOT Hips\n{{\n OFFSET 0 1 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n \
             JOINT {name}.L\n {{\n  OFFSET 0.2 -0.5 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  End Site\n  {{\n   OFFSET 0 -0.5 0\n  }}\n }}\n \
             JOINT {name}.R\n {{\n  OFFSET -0.2 -0.5 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  End Site\n  {{\n   OFFSET 0 -0.5 0\n  }}\n }}\n}}\n\
             MOTION\nFrames: {frames}\nFrame Time: 0.0333333\n"
        );
        for f in 0..frames {
            let a = f as f32;
            text.push_str(&format!(
                "{} 1 {} {} 0 {} {} 0 0 {} 0 0\n",
                a * 0.01,
                a * 0.02,
                a,
                a * 2.0,
                a * 3.0,
                -a * 3.0
            ));
        }
        Motion::from_bvh(&parse_str(&text).unwrap())
    }

    #[test]
    fn batches_group_skeletons_and_pad_short_clips() {
        let clips = vec![clip("Leg", 100), clip("Leg", 40), clip("Fin", 70)];
        let config = LoaderConfig { window: 32, batch_size: 8, ..LoaderConfig::default() };
        let mut loader = WindowLoader::new(clips, config);
        assert_eq!(loader.groups(), 2);
        let batches = loader.epoch().unwrap();
        // 100 / 32 = 3 windows, 40 / 32 = 1, 70 / 32 = 2.
        assert_eq!(batches.iter().map(|b| b.sources.len()).sum::<usize>(), 6);
        for b in &batches {
            let n = b.sources.len();
            assert_eq!(b.rotations.dims(), &[n, 32, 3, ROT_DIMS]);
            assert_eq!(b.root.dims(), &[n, 32, ROOT_DIMS]);
            assert_eq!(b.offsets.dims(), &[n, 3, 3]);
            assert!(b.sources.iter().all(|(c, _)| (*c == 2) == (b.group == 0)), "the Fin clip is alone in group 0");
        }
        let short = vec![clip("Leg", 10)];
        let mut loader = WindowLoader::new(short, LoaderConfig { window: 16, ..LoaderConfig::default() });
        let batch = loader.epoch().unwrap().remove(0);
        let mask: Vec<f32> = batch.mask.flatten_all().unwrap().to_vec1().unwrap();
        assert_eq!(mask.iter().sum::<f32>(), 10.0);
        assert_eq!(&mask[9..11], &[1.0, 0.0]);
    }

    #[test]
    fn the_same_seed_gives_the_same_batches() {
        let make = |seed| {
            let clips = vec![clip("Leg", 90), clip("Leg", 64)];
            let mut loader = WindowLoader::new(clips, LoaderConfig { window: 24, seed, ..LoaderConfig::default() });
            loader
                .epoch()
                .unwrap()
                .into_iter()
                .map(|b| (b.sources, b.rotations.flatten_all().unwrap().to_vec1::<f32>().unwrap()))
                .collect::<Vec<_>>()
        };
        assert_eq!(make(7), make(7));
        assert_ne!(make(7), make(8));
    }
}
