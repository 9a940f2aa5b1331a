//! Augmentations that make new training clips with the same meaning: joint frames turned (the
//! same motion on a rig of another convention, which reference-pose rebasing and NEC appendix
//! C.1's base-pose randomisation build on), left/right mirroring, and bone-length scaling. Each takes its random
//! choices as arguments, so the caller's seeded generator decides and results are reproducible.

use super::labels::{label_skeleton, mirror_pairs};
use crate::motion::Motion;
use crate::skeleton::{Joint, Skeleton};
use glam::{Quat, Vec3};

/// Why a skeleton cannot be mirrored.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum MirrorError {
    /// A left/right pair whose parents are not themselves a pair.
    #[error("joint {joint:?} pairs with {partner:?}, but their parents are not mirror images")]
    Asymmetric {
        /// A joint.
        joint: String,
        /// Its partner on the other side.
        partner: String,
    },
}

/// Re-expresses a motion on a rig whose joint frames are turned: joint `j`'s frame becomes
/// `F_j * turns[j]`, as if the rig had been built with other local axes. Every joint's world
/// position in every frame is unchanged (exactly, up to rounding); the offsets, end sites, rest
/// pose and local rotations change (`R'_j = turns[parent]^-1 R_j turns[j]`). This is how the
/// same motion looks on rigs of other conventions, which a tokenizer must not tell apart.
pub fn turn_joint_frames(motion: &Motion, turns: &[Quat]) -> Motion {
    let skeleton = motion.skeleton();
    let n = skeleton.len();
    assert_eq!(turns.len(), n, "one turn per joint");
    let parent_turn = |j: usize| skeleton.joint(j).parent.map_or(Quat::IDENTITY, |p| turns[p]);
    let joints: Vec<Joint> = skeleton
        .joints()
        .iter()
        .enumerate()
        .map(|(j, joint)| Joint {
            offset: if j == 0 { joint.offset } else { parent_turn(j).inverse() * joint.offset },
            end_site: joint.end_site.map(|e| turns[j].inverse() * e),
            ..joint.clone()
        })
        .collect();
    let turned = Skeleton::new(joints).expect("same tree, finite offsets");
    let mut rotations = Vec::with_capacity(motion.frames() * n);
    let mut translations = Vec::with_capacity(motion.frames() * n);
    for f in 0..motion.frames() {
        for (j, turn) in turns.iter().enumerate() {
            let local = parent_turn(j).inverse() * motion.rotations(f)[j] * *turn;
            rotations.push(local.normalize());
            let t = motion.translations(f)[j];
            translations.push(if j == 0 { t } else { parent_turn(j).inverse() * t });
        }
    }
    Motion::new(turned, motion.frame_time(), rotations, translations).expect("shapes match")
}

/// Mirrors a motion across the X = 0 plane and swaps left and right joints (found by their
/// semantic labels), so a left-handed wave becomes a right-handed one on the same skeleton.
pub fn mirror(motion: &Motion) -> Result<Motion, MirrorError> {
    let skeleton = motion.skeleton();
    let pair = mirror_pairs(&label_skeleton(skeleton));
    for (j, joint) in skeleton.joints().iter().enumerate() {
        let partner = skeleton.joint(pair[j]);
        if joint.parent.map(|p| pair[p]) != partner.parent {
            return Err(MirrorError::Asymmetric { joint: joint.name.clone(), partner: partner.name.clone() });
        }
    }
    let flip = |v: Vec3| Vec3::new(-v.x, v.y, v.z);
    let flip_rotation = |q: Quat| Quat::from_xyzw(q.x, -q.y, -q.z, q.w);
    let joints: Vec<Joint> = skeleton
        .joints()
        .iter()
        .enumerate()
        .map(|(j, joint)| {
            let partner = skeleton.joint(pair[j]);
            Joint { offset: flip(partner.offset), end_site: partner.end_site.map(flip), ..joint.clone() }
        })
        .collect();
    let mirrored = Skeleton::new(joints).expect("same tree, finite offsets");
    let n = skeleton.len();
    let mut rotations = Vec::with_capacity(motion.frames() * n);
    let mut translations = Vec::with_capacity(motion.frames() * n);
    for f in 0..motion.frames() {
        let (rot, trans) = (motion.rotations(f), motion.translations(f));
        for &p in &pair {
            rotations.push(flip_rotation(rot[p]));
            translations.push(flip(trans[p]));
        }
    }
    Ok(Motion::new(mirrored, motion.frame_time(), rotations, translations).expect("shapes match"))
}

/// Scales each bone by its factor (`factors[j]` for the bone ending at joint `j`; the root's
/// factor scales its translation). Rotations are kept, so the motion keeps its meaning on a
/// body of other proportions.
pub fn scale_bones(motion: &Motion, factors: &[f32]) -> Motion {
    let skeleton = motion.skeleton();
    assert_eq!(factors.len(), skeleton.len(), "one factor per joint");
    let joints: Vec<Joint> = skeleton
        .joints()
        .iter()
        .zip(factors)
        .map(|(joint, &s)| Joint { offset: joint.offset * s, end_site: joint.end_site.map(|e| e * s), ..joint.clone() })
        .collect();
    let scaled = Skeleton::new(joints).expect("same tree, finite offsets");
    let n = skeleton.len();
    let translations = motion.all_translations().iter().enumerate().map(|(k, t)| *t * factors[k % n]).collect();
    Motion::new(scaled, motion.frame_time(), motion.all_rotations().to_vec(), translations).expect("shapes match")
}

/// Bone factors that are equal for left/right partners, from one raw factor per joint: each
/// joint takes the mean of its own and its partner's factor, so scaled bodies stay symmetric.
pub fn symmetric_factors(skeleton: &Skeleton, raw: &[f32]) -> Vec<f32> {
    let pair = mirror_pairs(&label_skeleton(skeleton));
    (0..skeleton.len()).map(|j| 0.5 * (raw[j] + raw[pair[j]])).collect()
}
