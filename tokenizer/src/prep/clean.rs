//! Cleaning for model input (NEC appendix B): rig helpers dropped, static dummy roots collapsed
//! into their child, translation kept on the root only, clips with abnormal bones rejected with a
//! reason, and everything scaled so the skeleton's diameter is 1.
//!
//! Cleaning never changes what a user gets back: [`CleanClip::restore`] writes a cleaned motion
//! onto the original skeleton, exactly undoing every step.

use super::labels::label_name;
use crate::kinematics::Transform;
use crate::motion::Motion;
use crate::skeleton::{Joint, Skeleton};
use glam::Vec3;

/// Thresholds of the cleaning steps.
#[derive(Clone, Copy, Debug)]
pub struct CleanOptions {
    /// Reject a clip when one bone is longer than this fraction of the skeleton's diameter.
    pub max_bone_fraction: f32,
    /// Reject a clip when a non-root joint's translation drifts from its mean by more than this
    /// fraction of the diameter (frame-dependent bone lengths: tracking or export errors).
    pub max_translation_drift: f32,
    /// Motion this close to constant (diameter units, or radians) counts as static.
    pub static_tolerance: f32,
}

impl Default for CleanOptions {
    fn default() -> Self {
        CleanOptions { max_bone_fraction: 0.75, max_translation_drift: 0.05, static_tolerance: 1e-4 }
    }
}

/// Why a clip is not fit for model input.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Rejection {
    /// No motion.
    #[error("the clip has no frames")]
    NoFrames,
    /// Every joint at the same place in the rest pose.
    #[error("the skeleton has zero size (all offsets are zero)")]
    ZeroSize,
    /// One bone dominates the skeleton.
    #[error("bone {joint:?} is {fraction:.2} of the skeleton's diameter (limit {limit:.2})")]
    LongBone {
        /// The joint at the end of the bone.
        joint: String,
        /// Its length as a fraction of the diameter.
        fraction: f32,
        /// The limit.
        limit: f32,
    },
    /// Bone lengths change from frame to frame.
    #[error("joint {joint:?} moves {drift:.3} diameters off its mean offset (limit {limit:.3})")]
    TranslationDrift {
        /// The joint whose translation channels drift.
        joint: String,
        /// The largest drift, in diameters.
        drift: f32,
        /// The limit.
        limit: f32,
    },
}

/// A clip prepared for the models, with what it takes to go back to the original skeleton.
#[derive(Clone, Debug)]
pub struct CleanClip {
    /// The cleaned motion: one root carrying all translation, scaled to diameter 1.
    pub motion: Motion,
    /// For each cleaned joint, its index in the original skeleton.
    pub source_joint: Vec<usize>,
    /// The factor the original units were multiplied by (1 / original diameter).
    pub scale: f32,
    /// The original skeleton.
    pub original: Skeleton,
    /// Each collapsed dummy root (outermost first) with its local transform in the first frame,
    /// in original units: restored motions hold it there and give the rest to its child.
    collapsed: Vec<(usize, Transform)>,
}

/// Cleans a motion for model input, or says why it cannot be used.
pub fn clean(motion: &Motion, options: &CleanOptions) -> Result<CleanClip, Rejection> {
    if motion.frames() == 0 {
        return Err(Rejection::NoFrames);
    }
    let original = motion.skeleton().clone();
    let joints = original.joints();
    let n = original.len();

    // 1. Drop helper subtrees (IK and pole targets, props) hanging anywhere below the root.
    let mut keep = vec![true; n];
    for (i, joint) in joints.iter().enumerate().skip(1) {
        let parent = joint.parent.expect("non-root");
        keep[i] = keep[parent] && !is_helper_branch(&joint.name);
    }

    // 2. Collapse dummy roots (static, or named as rig roots) with a single kept child: the
    // child takes over their transform, frame by frame.
    let mut root = 0;
    let mut collapsed = Vec::new();
    let frames = motion.frames();
    loop {
        let kids: Vec<usize> = original.children(root).filter(|&c| keep[c]).collect();
        let dummy = label_name(&joints[root].name).helper || is_static(motion, root, options.static_tolerance);
        if kids.len() != 1 || !dummy || original.is_leaf(kids[0]) {
            break;
        }
        let t = Transform { rotation: motion.rotations(0)[root], translation: motion.translations(0)[root] };
        collapsed.push((root, t));
        keep[root] = false;
        root = kids[0];
    }

    // Build the cleaned skeleton: kept joints in original order, `root` first.
    let source_joint: Vec<usize> = (0..n).filter(|&i| keep[i]).collect();
    debug_assert_eq!(source_joint[0], root);
    let mut new_index = vec![usize::MAX; n];
    for (k, &i) in source_joint.iter().enumerate() {
        new_index[i] = k;
    }

    // 3. Translation on the root only: other joints keep their mean translation as the offset.
    let diameter_guess = original.diameter();
    let mut offsets = Vec::with_capacity(source_joint.len());
    for &i in &source_joint {
        let mean = (0..frames).map(|f| motion.translations(f)[i]).sum::<Vec3>() / frames as f32;
        offsets.push(mean);
    }

    let mut new_joints: Vec<Joint> = source_joint
        .iter()
        .enumerate()
        .map(|(k, &i)| Joint {
            name: joints[i].name.clone(),
            parent: if k == 0 { None } else { Some(new_index[joints[i].parent.expect("non-root")]) },
            offset: if k == 0 { Vec3::ZERO } else { offsets[k] },
            channels: joints[i].channels.clone(),
            end_site: joints[i].end_site,
        })
        .collect();
    let provisional = Skeleton::new(new_joints.clone()).expect("a subtree of a valid skeleton");
    let diameter = provisional.diameter();
    if diameter <= f32::EPSILON * diameter_guess.max(1.0) || diameter <= 0.0 {
        return Err(Rejection::ZeroSize);
    }
    let scale = 1.0 / diameter;

    // 4. Reject abnormal bones and drifting translations.
    for (k, &i) in source_joint.iter().enumerate().skip(1) {
        let fraction = offsets[k].length() * scale;
        if fraction > options.max_bone_fraction {
            return Err(Rejection::LongBone {
                joint: joints[i].name.clone(),
                fraction,
                limit: options.max_bone_fraction,
            });
        }
        let drift =
            (0..frames).map(|f| (motion.translations(f)[i] - offsets[k]).length()).fold(0.0f32, f32::max) * scale;
        if drift > options.max_translation_drift {
            return Err(Rejection::TranslationDrift {
                joint: joints[i].name.clone(),
                drift,
                limit: options.max_translation_drift,
            });
        }
    }

    // 5. Scale to diameter 1 and assemble the motion.
    for joint in &mut new_joints {
        joint.offset *= scale;
        joint.end_site = joint.end_site.map(|e| e * scale);
    }
    let skeleton = Skeleton::new(new_joints).expect("scaling keeps a valid skeleton");
    let m = source_joint.len();
    let mut rotations = Vec::with_capacity(frames * m);
    let mut translations = Vec::with_capacity(frames * m);
    for f in 0..frames {
        let (rot, trans) = (motion.rotations(f), motion.translations(f));
        for (k, &i) in source_joint.iter().enumerate() {
            if k == 0 {
                let base = collapsed.iter().fold(Transform::IDENTITY, |acc, (r, _)| {
                    compose(acc, Transform { rotation: rot[*r], translation: trans[*r] })
                });
                let t = compose(base, Transform { rotation: rot[i], translation: trans[i] });
                rotations.push(t.rotation);
                translations.push(t.translation * scale);
            } else {
                rotations.push(rot[i]);
                translations.push(skeleton.joint(k).offset);
            }
        }
    }
    let motion = Motion::new(skeleton, motion.frame_time(), rotations, translations).expect("shapes match");
    Ok(CleanClip { motion, source_joint, scale, original, collapsed })
}

impl CleanClip {
    /// Writes a motion on the cleaned skeleton (this clip's, or a model's output for it) back onto
    /// the original skeleton: dropped joints return to the values they had in the first frame of
    /// the source clip (collapsed roots too, their child carrying the motion), units to the
    /// original ones. Every kept joint's global position is reproduced.
    pub fn restore(&self, cleaned: &Motion, source: &Motion) -> Motion {
        let n = self.original.len();
        let frames = cleaned.frames();
        let base = self.collapsed.iter().fold(Transform::IDENTITY, |acc, (_, t)| compose(acc, *t));
        let inverse_base = invert(base);
        let mut rotations = Vec::with_capacity(frames * n);
        let mut translations = Vec::with_capacity(frames * n);
        for f in 0..frames {
            let mut rot = source.rotations(0).to_vec();
            let mut trans = source.translations(0).to_vec();
            for (root, t) in &self.collapsed {
                rot[*root] = t.rotation;
                trans[*root] = t.translation;
            }
            let (crot, ctrans) = (cleaned.rotations(f), cleaned.translations(f));
            for (k, &i) in self.source_joint.iter().enumerate() {
                if k == 0 {
                    let root = Transform { rotation: crot[0], translation: ctrans[0] / self.scale };
                    let local = compose(inverse_base, root);
                    rot[i] = local.rotation;
                    trans[i] = local.translation;
                } else {
                    rot[i] = crot[k];
                    trans[i] = self.original.joint(i).offset;
                }
            }
            rotations.extend(rot);
            translations.extend(trans);
        }
        Motion::new(self.original.clone(), cleaned.frame_time(), rotations, translations).expect("shapes match")
    }
}

/// True for joints that start a rig-helper branch (IK and pole targets, props).
fn is_helper_branch(name: &str) -> bool {
    let label = label_name(name);
    label.helper && label.part != "root"
}

/// True when a joint's local transform is the same in every frame.
fn is_static(motion: &Motion, joint: usize, tolerance: f32) -> bool {
    let r0 = motion.rotations(0)[joint];
    let t0 = motion.translations(0)[joint];
    let size = motion.skeleton().diameter().max(f32::MIN_POSITIVE);
    (1..motion.frames()).all(|f| {
        let r = motion.rotations(f)[joint];
        let t = motion.translations(f)[joint];
        crate::rotation::geodesic_angle(r0, r) <= tolerance && (t - t0).length() / size <= tolerance
    })
}

fn compose(a: Transform, b: Transform) -> Transform {
    Transform { rotation: a.rotation * b.rotation, translation: a.apply(b.translation) }
}

fn invert(t: Transform) -> Transform {
    let rotation = t.rotation.inverse();
    Transform { rotation, translation: -(rotation * t.translation) }
}
