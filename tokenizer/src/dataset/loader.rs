//! The training data loader: windows of clips drawn per optimiser step, augmented (mirroring,
//! reference-pose rebasing on one of the window's frames, bone-length scaling), canonicalised,
//! turned into model features and batched by skeleton into candle tensors.
//!
//! Sampling is balanced so no corpus dominates: each batch draws a source with probability
//! proportional to the square root of its frames, then a skeleton uniformly among that source's,
//! then windows from that skeleton's clips in proportion to their frames. Windows hold only real
//! frames: a batch whose shortest clip is shorter than a window has shorter windows. A step's
//! batches depend only on the seed and the step number (ChaCha8, whose stream is fixed across
//! platforms and versions), so a resumed run draws exactly what the killed one would have.

use anymo_motion::features::{ROOT_DIMS, ROT_DIMS, canonicalise, to_features};
use anymo_motion::motion::Motion;
use anymo_motion::prep::augment::{mirror, scale_bones, symmetric_factors};
use anymo_motion::reference::ReferencePose;
use candle_core::{Device, Tensor};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::BTreeMap;

/// How windows are drawn and augmented.
#[derive(Clone, Debug)]
pub struct LoaderConfig {
    /// Frames per window, at most.
    pub window: usize,
    /// Window lengths are whole multiples of this (the codec's frames per token).
    pub frames_per_token: usize,
    /// Windows per batch (fewer for large skeletons, see `max_batch_joints`).
    pub batch_size: usize,
    /// Batches per step, each of one skeleton.
    pub skeletons_per_step: usize,
    /// Seed of the random choices.
    pub seed: u64,
    /// Probability of mirroring a window (when its skeleton has left/right pairs).
    pub mirror: f64,
    /// Probability of rebasing a window on the pose of one of its frames (NEC C.1): the same
    /// motion written on another reference pose, as a user's file may give one.
    pub rebase: f64,
    /// Probability of rebasing a window on a frame of any clip of its skeleton (after the
    /// rebasing above): the same motion against a reference pose taken from other motion, as the
    /// reference of a rig seen only through a user's few files is. 0 draws nothing, so runs
    /// from before it existed sample as they did.
    pub rebase_other: f64,
    /// Probability of reading a window against the mean pose of its own clip (before the
    /// rebasings above): motion as `anymo tokenize` reads a user's clip, around that clip's own
    /// pose rather than its rig's. 0 draws nothing, so runs from before it existed sample as
    /// they did.
    pub rebase_own: f64,
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
            frames_per_token: 4,
            batch_size: 16,
            skeletons_per_step: 1,
            seed: 0,
            mirror: 0.5,
            rebase: 0.1,
            rebase_other: 0.0,
            rebase_own: 0.0,
            bone_scale: 0.1,
            max_batch_joints: 512,
        }
    }
}

/// A training clip and the corpus it comes from (sampling balances corpora).
#[derive(Clone, Debug)]
pub struct TrainingClip {
    /// The cleaned motion.
    pub motion: Motion,
    /// Its source (corpus) name.
    pub source: String,
}

/// One batch: windows of clips that share a skeleton.
#[derive(Debug)]
pub struct Batch {
    /// Index of the skeleton group (clips of one source with the same parents and joint names).
    pub group: usize,
    /// Parent of each joint.
    pub parents: Vec<Option<usize>>,
    /// `(B, T, ROOT_DIMS)`: yaw rate, heading-frame velocity x and z, height.
    pub root: Tensor,
    /// `(B, T, J, ROT_DIMS)`: rot6D of every joint (the root without its heading).
    pub rotations: Tensor,
    /// `(B, J, 3)`: each window's rest offsets (augmentation changes them).
    pub offsets: Tensor,
    /// `(B, T)`: 1 for real frames, 0 for padding after a short clip's end (decoding pads;
    /// training windows never do).
    pub mask: Tensor,
    /// For each window, the clip it came from and its first frame.
    pub sources: Vec<(usize, usize)>,
}

/// A corpus: its sampling weight and its skeleton groups.
#[derive(Clone, Debug)]
struct Source {
    weight: f64,
    groups: Vec<usize>,
}

/// Windows of training clips, batched by skeleton, drawn per step.
pub struct WindowLoader {
    clips: Vec<Motion>,
    /// Each clip's own mean pose, when windows are read against it.
    own_means: Vec<Option<ReferencePose>>,
    groups: Vec<Vec<usize>>,
    sources: Vec<Source>,
    config: LoaderConfig,
}

impl WindowLoader {
    /// A loader over cleaned clips (see [`anymo_motion::prep::clean`]); clips shorter than one
    /// token are left out.
    ///
    /// # Panics
    /// When no clip is at least one token long.
    pub fn new(clips: Vec<TrainingClip>, config: LoaderConfig) -> WindowLoader {
        type Topology = Vec<(Option<usize>, String)>;
        let mut by_key: BTreeMap<(String, Topology), Vec<usize>> = BTreeMap::new();
        let clips: Vec<TrainingClip> =
            clips.into_iter().filter(|c| c.motion.frames() >= config.frames_per_token).collect();
        assert!(!clips.is_empty(), "the loader needs a clip of at least {} frames", config.frames_per_token);
        for (i, clip) in clips.iter().enumerate() {
            let topology = clip.motion.skeleton().joints().iter().map(|j| (j.parent, j.name.clone())).collect();
            by_key.entry((clip.source.clone(), topology)).or_default().push(i);
        }
        let mut sources: BTreeMap<&str, Source> = BTreeMap::new();
        for (g, ((source, _), members)) in by_key.iter().enumerate() {
            let entry = sources.entry(source).or_insert(Source { weight: 0.0, groups: Vec::new() });
            entry.weight += members.iter().map(|&c| clips[c].motion.frames() as f64).sum::<f64>();
            entry.groups.push(g);
        }
        let sources = sources.into_values().map(|s| Source { weight: s.weight.sqrt(), ..s }).collect();
        let groups = by_key.into_values().collect();
        let clips: Vec<Motion> = clips.into_iter().map(|c| c.motion).collect();
        let own_means = clips
            .iter()
            .map(|clip| if config.rebase_own > 0.0 { ReferencePose::mean_of([clip]) } else { None })
            .collect();
        WindowLoader { clips, own_means, groups, sources, config }
    }

    /// The number of skeleton groups.
    pub fn groups(&self) -> usize {
        self.groups.len()
    }

    /// The skeleton shared by the clips of a group (rest offsets of its first clip).
    pub fn group_skeleton(&self, group: usize) -> &anymo_motion::skeleton::Skeleton {
        self.clips[self.groups[group][0]].skeleton()
    }

    /// The batches of optimiser step `step`: [`LoaderConfig::skeletons_per_step`] of them, each
    /// of one skeleton.
    pub fn step(&self, step: u64) -> candle_core::Result<Vec<Batch>> {
        let mut rng = ChaCha8Rng::seed_from_u64(self.config.seed ^ step.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        (0..self.config.skeletons_per_step).map(|_| self.draw(&mut rng)).collect()
    }

    /// One batch: a source, one of its skeletons, and windows of its clips.
    fn draw(&self, rng: &mut ChaCha8Rng) -> candle_core::Result<Batch> {
        let source = &self.sources[pick(self.sources.iter().map(|s| s.weight), rng)];
        let group = source.groups[rng.random_range(0..source.groups.len())];
        let members = &self.groups[group];
        let joints = self.clips[members[0]].skeleton().len();
        let size = self.config.batch_size.min(self.config.max_batch_joints / joints).max(1);
        let chosen: Vec<usize> =
            (0..size).map(|_| members[pick(members.iter().map(|&c| self.clips[c].frames() as f64), rng)]).collect();
        let shortest = chosen.iter().map(|&c| self.clips[c].frames()).min().expect("a window");
        let per_token = self.config.frames_per_token;
        let length = self.config.window.min(shortest) / per_token * per_token;
        let windows = chosen.into_iter().map(|c| (c, rng.random_range(0..=self.clips[c].frames() - length))).collect();
        self.batch(group, windows, length, rng)
    }

    fn batch(
        &self,
        group: usize,
        windows: Vec<(usize, usize)>,
        t: usize,
        rng: &mut ChaCha8Rng,
    ) -> candle_core::Result<Batch> {
        let first = &self.clips[windows[0].0];
        let j = first.skeleton().len();
        let parents: Vec<Option<usize>> = first.skeleton().parents().collect();
        let b = windows.len();
        let (mut root, mut rotations) =
            (Vec::with_capacity(b * t * ROOT_DIMS), Vec::with_capacity(b * t * j * ROT_DIMS));
        let mut offsets = Vec::with_capacity(b * j * 3);
        for &(clip, start) in &windows {
            let motion = self.augment(group, clip, self.clips[clip].slice(start, t), rng);
            let (features, _) = to_features(&canonicalise(&motion));
            root.extend_from_slice(&features.root);
            rotations.extend_from_slice(&features.rotations);
            offsets.extend(motion.skeleton().joints().iter().flat_map(|joint| joint.offset.to_array()));
        }
        let device = Device::Cpu;
        Ok(Batch {
            group,
            parents,
            root: Tensor::from_vec(root, (b, t, ROOT_DIMS), &device)?,
            rotations: Tensor::from_vec(rotations, (b, t, j, ROT_DIMS), &device)?,
            offsets: Tensor::from_vec(offsets, (b, j, 3), &device)?,
            mask: Tensor::ones((b, t), candle_core::DType::F32, &device)?,
            sources: windows,
        })
    }

    /// A window of clip `clip` of skeleton group `group`, augmented as the configuration says.
    fn augment(&self, group: usize, clip: usize, mut motion: Motion, rng: &mut ChaCha8Rng) -> Motion {
        if self.config.rebase_own > 0.0
            && rng.random_bool(self.config.rebase_own)
            && let Some(own) = &self.own_means[clip]
        {
            motion = own.rebase(&motion);
        }
        if rng.random_bool(self.config.mirror)
            && let Ok(mirrored) = mirror(&motion)
        {
            motion = mirrored;
        }
        if rng.random_bool(self.config.rebase) {
            let base = rng.random_range(0..motion.frames());
            motion = ReferencePose::of_frame(&motion, base).rebase(&motion);
        }
        if self.config.rebase_other > 0.0 && rng.random_bool(self.config.rebase_other) {
            let members = &self.groups[group];
            let other = &self.clips[members[rng.random_range(0..members.len())]];
            let base = rng.random_range(0..other.frames());
            motion = ReferencePose::of_frame(other, base).rebase(&motion);
        }
        if self.config.bone_scale > 0.0 {
            let s = self.config.bone_scale;
            let raw: Vec<f32> = (0..motion.skeleton().len()).map(|_| rng.random_range(1.0 - s..=1.0 + s)).collect();
            let mut factors = symmetric_factors(motion.skeleton(), &raw);
            factors[0] = 1.0;
            motion = scale_bones(&motion, &factors);
        }
        motion
    }
}

/// An index drawn with probability proportional to its weight.
fn pick(weights: impl Iterator<Item = f64> + Clone, rng: &mut ChaCha8Rng) -> usize {
    let total: f64 = weights.clone().sum();
    let mut x = rng.random_range(0.0..total);
    let mut last = 0;
    for (i, w) in weights.enumerate() {
        if x < w {
            return i;
        }
        x -= w;
        last = i;
    }
    last
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

    fn from(source: &str, motion: Motion) -> TrainingClip {
        TrainingClip { motion, source: source.to_string() }
    }

    #[test]
    fn batches_hold_one_skeleton_and_only_real_frames() {
        let clips = vec![from("a", clip("Leg", 100)), from("a", clip("Leg", 41)), from("b", clip("Fin", 70))];
        let config = LoaderConfig { window: 32, batch_size: 8, skeletons_per_step: 3, ..LoaderConfig::default() };
        let loader = WindowLoader::new(clips, config);
        assert_eq!(loader.groups(), 2);
        for step in 0..20 {
            for b in loader.step(step).unwrap() {
                let (n, t) = (b.sources.len(), b.rotations.dim(1).unwrap());
                assert_eq!(n, 8);
                assert!(t % 4 == 0 && t <= 32 && t > 0, "{t} frames");
                assert_eq!(b.rotations.dims(), &[n, t, 3, ROT_DIMS]);
                assert_eq!(b.root.dims(), &[n, t, ROOT_DIMS]);
                assert_eq!(b.offsets.dims(), &[n, 3, 3]);
                let frames = [100, 41, 70];
                assert!(b.sources.iter().all(|&(c, start)| start + t <= frames[c]), "no window runs past its clip");
                assert!(
                    b.sources.iter().all(|(c, _)| (*c == 2) == (b.group == 1)),
                    "the Fin clip is alone in its group"
                );
                assert_eq!(b.mask.sum_all().unwrap().to_scalar::<f32>().unwrap(), (n * t) as f32);
            }
        }
    }

    #[test]
    fn sources_are_drawn_by_the_root_of_their_frames_and_skeletons_uniformly() {
        // Source a: 1600 frames over two skeletons; source b: 400 frames over one. By the root
        // of their frames a is drawn 40 / (40 + 20) = 2/3 of the time, and each of its two
        // skeletons 1/3, whatever their own frame counts.
        let mut clips: Vec<TrainingClip> = (0..15).map(|_| from("a", clip("Leg", 100))).collect();
        clips.push(from("a", clip("Arm", 100)));
        clips.extend((0..4).map(|_| from("b", clip("Fin", 100))));
        let config = LoaderConfig { window: 16, batch_size: 1, seed: 5, ..LoaderConfig::default() };
        let loader = WindowLoader::new(clips, config);
        let mut counts = [0usize; 3];
        let steps = 3000;
        for step in 0..steps {
            counts[loader.step(step).unwrap()[0].group] += 1;
        }
        let share = counts.map(|c| c as f64 / steps as f64);
        for (got, want) in share.iter().zip([1.0 / 3.0; 3]) {
            assert!((got - want).abs() < 0.03, "{share:?}");
        }
    }

    #[test]
    fn rebasing_on_another_clip_turns_the_joint_frames_and_keeps_the_bones() {
        let clips = || vec![from("a", clip("Leg", 90)), from("a", clip("Leg", 64))];
        let plain = LoaderConfig {
            window: 24,
            batch_size: 4,
            mirror: 0.0,
            rebase: 0.0,
            bone_scale: 0.0,
            ..LoaderConfig::default()
        };
        let draw = |config: LoaderConfig| WindowLoader::new(clips(), config).step(0).unwrap().remove(0);
        let (kept, rebased) = (draw(plain.clone()), draw(LoaderConfig { rebase_other: 1.0, ..plain }));
        assert_eq!(kept.sources, rebased.sources, "the same windows");
        let bones = |b: &Batch| b.offsets.to_vec3::<f32>().unwrap();
        let (before, after) = (bones(&kept), bones(&rebased));
        let length = |v: &[f32]| v.iter().map(|x| x * x).sum::<f32>().sqrt();
        let mut turned = 0;
        for (window_before, window_after) in before.iter().zip(&after) {
            for (a, b) in window_before.iter().zip(window_after) {
                assert!((length(a) - length(b)).abs() < 1e-5, "a bone keeps its length: {a:?} {b:?}");
                turned += usize::from(a.iter().zip(b).any(|(x, y)| (x - y).abs() > 1e-3));
            }
        }
        assert!(turned > 0, "some bone points another way in the other clip's reference");
        let rotations = |b: &Batch| b.rotations.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        assert_ne!(rotations(&kept), rotations(&rebased));
    }

    #[test]
    fn windows_read_against_their_own_clip_sit_around_the_identity() {
        // A window that is its whole clip (legs swinging 0 to 45 degrees), read against that
        // clip's mean pose: each leg's rotations average to about no rotation (swinging -22.5
        // to 22.5 degrees), while against the rest pose they do not.
        let clips = || vec![from("a", clip("Leg", 16))];
        let plain = LoaderConfig {
            window: 16,
            batch_size: 1,
            mirror: 0.0,
            rebase: 0.0,
            bone_scale: 0.0,
            ..LoaderConfig::default()
        };
        let draw = |config: LoaderConfig| WindowLoader::new(clips(), config).step(0).unwrap().remove(0);
        let off_identity = |b: &Batch| {
            let all = b.rotations.squeeze(0).unwrap().to_vec3::<f32>().unwrap();
            let identity = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
            (1..3)
                .map(|j| {
                    let mean: Vec<f32> =
                        (0..ROT_DIMS).map(|d| all.iter().map(|frame| frame[j][d]).sum::<f32>() / 16.0).collect();
                    mean.iter().zip(identity).map(|(m, i)| (m - i).abs()).sum::<f32>()
                })
                .fold(0.0f32, f32::max)
        };
        let (kept, own) = (draw(plain.clone()), draw(LoaderConfig { rebase_own: 1.0, ..plain }));
        assert_eq!(kept.sources, own.sources, "the same windows");
        let (from_rest, from_own) = (off_identity(&kept), off_identity(&own));
        assert!(from_own < from_rest / 5.0, "around their own mean {from_own}, around the rest pose {from_rest}");
    }

    #[test]
    fn a_step_depends_only_on_the_seed_and_its_number() {
        let make = |seed, step| {
            let clips = vec![from("a", clip("Leg", 90)), from("a", clip("Leg", 64))];
            let config = LoaderConfig { window: 24, seed, skeletons_per_step: 2, ..LoaderConfig::default() };
            let loader = WindowLoader::new(clips, config);
            loader
                .step(step)
                .unwrap()
                .into_iter()
                .map(|b| (b.sources, b.rotations.flatten_all().unwrap().to_vec1::<f32>().unwrap()))
                .collect::<Vec<_>>()
        };
        assert_eq!(make(7, 3), make(7, 3));
        assert_ne!(make(7, 3), make(8, 3));
        assert_ne!(make(7, 3), make(7, 4));
    }
}
