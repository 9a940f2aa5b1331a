//! Cleaning for model input (NEC appendix B): rig helpers dropped, limbs that float on a dummy
//! root (IK-driven feet) re-attached to the body, dummy roots collapsed into their child,
//! translation kept on the root only, clips with abnormal bones rejected with a reason, and
//! everything scaled so the skeleton's diameter is 1.
//!
//! The cleaned hierarchy is decided by the rig, not by one clip's motion: which joints are
//! dummies and which limbs float follow from names and the file's channels, and a floating limb
//! goes to the body joint it moves with (the nearest of those that hold it equally still, so a
//! clip in which nothing moves chooses as a moving one does). Every clip of a rig therefore
//! cleans to the same tree, so its clips share one reference pose, and tokens taken on one clip
//! read back on another.
//!
//! Cleaning never changes what a user gets back: [`CleanClip::restore`] writes a cleaned motion
//! onto the original skeleton, reproducing every kept joint's global position.

use super::labels::label_name;
use crate::kinematics::{Transform, all_global_transforms};
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
    /// A child branch of a dummy root with at most this fraction of the joints of the largest
    /// branch, whose top joint the file animates in position, is a floating limb (an IK-driven
    /// foot), re-attached to the joint of the largest branch it moves most rigidly with.
    pub floating_limb_fraction: f32,
}

impl Default for CleanOptions {
    fn default() -> Self {
        CleanOptions { max_bone_fraction: 0.75, max_translation_drift: 0.05, floating_limb_fraction: 0.25 }
    }
}

/// Why a clip is not fit for model input.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Rejection {
    /// No motion.
    #[error("the clip has no frames")]
    NoFrames,
    /// Every joint at the same place.
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
        /// The joint whose translation drifts.
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
    /// The factor the original units were multiplied by (1 / cleaned diameter in original units).
    pub scale: f32,
    /// The original skeleton.
    pub original: Skeleton,
}

/// Cleans a motion for model input, or says why it cannot be used.
pub fn clean(motion: &Motion, options: &CleanOptions) -> Result<CleanClip, Rejection> {
    if motion.frames() == 0 {
        return Err(Rejection::NoFrames);
    }
    let original = motion.skeleton();
    let joints = original.joints();
    let n = original.len();
    let frames = motion.frames();
    let globals = all_global_transforms(motion);

    // 1. Drop helper branches (IK and pole targets, props) hanging anywhere below the root.
    let mut keep = vec![true; n];
    for (i, joint) in joints.iter().enumerate().skip(1) {
        let parent = joint.parent.expect("non-root");
        keep[i] = keep[parent] && !is_helper_branch(&joint.name);
    }
    let mut parent: Vec<Option<usize>> = joints.iter().map(|j| j.parent).collect();

    // 2. Walk down dummy roots: re-attach floating limbs, then collapse while one child remains.
    // A dummy is a helper by name, or a carrier frame: a root whose one child the file moves in
    // position. Neither depends on the clip's motion, so all clips of a rig agree.
    let mut root = 0;
    loop {
        let kids: Vec<usize> = (0..n).filter(|&c| keep[c] && parent[c] == Some(root)).collect();
        let carrier = kids.len() == 1 && joints[kids[0]].channels.has_position();
        if !label_name(&joints[root].name).helper && !carrier {
            break;
        }
        if kids.len() > 1 {
            reattach_floating_limbs(original, &kids, &mut parent, &keep, &globals, options.floating_limb_fraction);
        }
        let kids: Vec<usize> = (0..n).filter(|&c| keep[c] && parent[c] == Some(root)).collect();
        if kids.len() != 1 || !(0..n).any(|d| keep[d] && parent[d] == Some(kids[0])) {
            break;
        }
        keep[root] = false;
        parent[kids[0]] = None;
        root = kids[0];
    }

    // The cleaned tree in depth-first order, children in original order.
    let mut order = Vec::with_capacity(n);
    let mut stack = vec![root];
    while let Some(j) = stack.pop() {
        order.push(j);
        let kids: Vec<usize> = (0..n).filter(|&c| keep[c] && parent[c] == Some(j)).collect();
        stack.extend(kids.into_iter().rev());
    }
    let mut new_index = vec![usize::MAX; n];
    for (k, &j) in order.iter().enumerate() {
        new_index[j] = k;
    }

    // 3. Local transforms in the cleaned tree, from the original global ones. Non-root joints
    // keep their mean translation as the offset; only the root moves.
    let m = order.len();
    let mut rotations = Vec::with_capacity(frames * m);
    let mut translations = Vec::with_capacity(frames * m);
    for f in 0..frames {
        let g = &globals[f * n..(f + 1) * n];
        for &j in &order {
            let local = match parent[j] {
                None => g[j],
                Some(p) => relative(g[p], g[j]),
            };
            rotations.push(local.rotation);
            translations.push(local.translation);
        }
    }
    let offsets: Vec<Vec3> =
        (0..m).map(|k| (0..frames).map(|f| translations[f * m + k]).sum::<Vec3>() / frames as f32).collect();
    let mut new_joints: Vec<Joint> = order
        .iter()
        .enumerate()
        .map(|(k, &j)| Joint {
            name: joints[j].name.clone(),
            parent: parent[j].map(|p| new_index[p]),
            offset: if k == 0 { Vec3::ZERO } else { offsets[k] },
            channels: joints[j].channels.clone(),
            // Global rotations are unchanged, so an end site keeps its local offset.
            end_site: joints[j].end_site,
        })
        .collect();
    let diameter = Skeleton::new(new_joints.clone()).expect("a tree of kept joints").diameter();
    if diameter <= f32::EPSILON * original.diameter().max(1.0) {
        return Err(Rejection::ZeroSize);
    }
    let scale = 1.0 / diameter;

    // 4. Reject abnormal bones and drifting translations.
    for (k, &j) in order.iter().enumerate().skip(1) {
        let fraction = offsets[k].length() * scale;
        if fraction > options.max_bone_fraction {
            return Err(Rejection::LongBone {
                joint: joints[j].name.clone(),
                fraction,
                limit: options.max_bone_fraction,
            });
        }
        let drift = (0..frames).map(|f| translations[f * m + k].distance(offsets[k])).fold(0.0f32, f32::max) * scale;
        if drift > options.max_translation_drift {
            return Err(Rejection::TranslationDrift {
                joint: joints[j].name.clone(),
                drift,
                limit: options.max_translation_drift,
            });
        }
    }

    // 5. Scale to diameter 1.
    for joint in &mut new_joints {
        joint.offset *= scale;
        joint.end_site = joint.end_site.map(|e| e * scale);
    }
    let skeleton = Skeleton::new(new_joints).expect("scaling keeps a valid skeleton");
    for f in 0..frames {
        translations[f * m] *= scale;
        for k in 1..m {
            translations[f * m + k] = skeleton.joint(k).offset;
        }
    }
    let motion = Motion::new(skeleton, motion.frame_time(), rotations, translations).expect("shapes match");
    Ok(CleanClip { motion, source_joint: order, scale, original: original.clone() })
}

impl CleanClip {
    /// Writes a motion on the cleaned skeleton (this clip's, or a model's output for it) back onto
    /// the original skeleton. Kept joints take the cleaned motion's global transforms; dropped
    /// joints (helpers, collapsed roots) keep their local transform from the first frame of
    /// `source`. Units go back to the original ones.
    pub fn restore(&self, cleaned: &Motion, source: &Motion) -> Motion {
        let n = self.original.len();
        let m = self.source_joint.len();
        let frames = cleaned.frames();
        let mut cleaned_of = vec![None; n];
        for (k, &j) in self.source_joint.iter().enumerate() {
            cleaned_of[j] = Some(k);
        }
        let cleaned_globals = all_global_transforms(cleaned);
        let mut rotations = Vec::with_capacity(frames * n);
        let mut translations = Vec::with_capacity(frames * n);
        let mut g = vec![Transform::IDENTITY; n];
        for f in 0..frames {
            for j in 0..n {
                let parent = self.original.joint(j).parent;
                g[j] = match cleaned_of[j] {
                    Some(k) => {
                        let t = cleaned_globals[f * m + k];
                        Transform { rotation: t.rotation, translation: t.translation / self.scale }
                    }
                    None => {
                        let local =
                            Transform { rotation: source.rotations(0)[j], translation: source.translations(0)[j] };
                        parent.map_or(local, |p| compose(g[p], local))
                    }
                };
                let local = parent.map_or(g[j], |p| relative(g[p], g[j]));
                rotations.push(local.rotation);
                translations.push(local.translation);
            }
        }
        Motion::new(self.original.clone(), cleaned.frame_time(), rotations, translations).expect("shapes match")
    }
}

/// Re-parents the small branches among `kids` (children of a dummy root) whose top joint the
/// file animates in position to the joint of the largest branch they move most rigidly with,
/// the nearest of those when several hold it equally still (a leg held still in an idle holds
/// its foot as rigidly as its hip does). A branch the file only rotates is fixed in the root's
/// frame and stays where it is; whether a branch floats never depends on how much it moves in
/// one clip, so every clip of a rig makes the same choice.
fn reattach_floating_limbs(
    skeleton: &Skeleton,
    kids: &[usize],
    parent: &mut [Option<usize>],
    keep: &[bool],
    globals: &[Transform],
    fraction: f32,
) {
    let (joints, n) = (skeleton.joints(), parent.len());
    let frames = globals.len() / n;
    let tie = RIGID_TIE * skeleton.diameter();
    let in_branch = |parent: &[Option<usize>], top: usize| -> Vec<usize> {
        let mut members = vec![top];
        let mut i = 0;
        while i < members.len() {
            let at = members[i];
            members.extend((0..n).filter(|&c| keep[c] && parent[c] == Some(at)));
            i += 1;
        }
        members
    };
    // How far `limb` strays from its mean position in the frame of `candidate`.
    let drift = |limb: usize, candidate: usize| {
        let local = |f: usize| relative(globals[f * n + candidate], globals[f * n + limb]).translation;
        let mean = (0..frames).map(local).sum::<Vec3>() / frames as f32;
        (0..frames).map(|f| local(f).distance(mean)).fold(0.0f32, f32::max)
    };
    // How far `limb` sits from `candidate`'s origin, or its end site, on average.
    let distance = |limb: usize, candidate: usize| {
        let at = |f: usize| {
            let (g, p) = (globals[f * n + candidate], globals[f * n + limb].translation);
            let tip = joints[candidate].end_site.map_or(f32::INFINITY, |e| g.apply(e).distance(p));
            g.translation.distance(p).min(tip)
        };
        (0..frames).map(at).sum::<f32>() / frames as f32
    };
    let branches: Vec<Vec<usize>> = kids.iter().map(|&k| in_branch(parent, k)).collect();
    let body = (0..kids.len()).max_by_key(|&b| branches[b].len()).expect("at least two children");
    let limit = (branches[body].len() as f32 * fraction).max(1.0);
    for (b, branch) in branches.iter().enumerate() {
        let limb = kids[b];
        if b == body || branch.len() as f32 > limit || !joints[limb].channels.has_position() {
            continue;
        }
        let drifts: Vec<f32> = branches[body].iter().map(|&c| drift(limb, c)).collect();
        let least = drifts.iter().copied().fold(f32::INFINITY, f32::min);
        let chosen = branches[body]
            .iter()
            .zip(&drifts)
            .filter(|(_, d)| **d <= least + tie)
            .map(|(&c, _)| (c, distance(limb, c)))
            .min_by(|x, y| x.1.total_cmp(&y.1))
            .expect("the body branch has its top joint");
        parent[limb] = Some(chosen.0);
    }
}

/// Drifts within this fraction of the skeleton's diameter count as equally rigid when a
/// floating limb picks the joint it moves with.
const RIGID_TIE: f32 = 1e-3;

/// True for joints that start a rig-helper branch (IK and pole targets, props).
fn is_helper_branch(name: &str) -> bool {
    let label = label_name(name);
    label.helper && label.part != "root"
}

fn compose(a: Transform, b: Transform) -> Transform {
    Transform { rotation: (a.rotation * b.rotation).normalize(), translation: a.apply(b.translation) }
}

/// `b` expressed in the frame of `a`.
fn relative(a: Transform, b: Transform) -> Transform {
    let inverse = a.rotation.inverse();
    Transform { rotation: (inverse * b.rotation).normalize(), translation: inverse * (b.translation - a.translation) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::skeleton::{Channels, EulerOrder, rotating_joint};
    use glam::Quat;

    /// A joint the file moves in position as well as rotating.
    fn positioned(name: &str, parent: Option<usize>, offset: Vec3) -> Joint {
        Joint { channels: Channels::position_rotation(EulerOrder::Zyx), ..rotating_joint(name, parent, offset) }
    }

    /// A body under `root`: hips (moved in position), spine and head, two legs of thigh and
    /// shin, the shins ending 0.4 below their knee.
    fn body(root: Joint) -> Vec<Joint> {
        let mut joints = vec![root, positioned("Hips", Some(0), Vec3::Y)];
        joints.push(rotating_joint("Spine", Some(1), Vec3::Y * 0.5));
        joints.push(rotating_joint("Head", Some(2), Vec3::Y * 0.5));
        for (side, x) in [("L", 0.2), ("R", -0.2)] {
            let thigh = joints.len();
            joints.push(rotating_joint(&format!("Thigh.{side}"), Some(1), Vec3::X * x));
            let shin = Joint {
                end_site: Some(Vec3::Y * -0.4),
                ..rotating_joint(&format!("Shin.{side}"), Some(thigh), Vec3::Y * -0.5)
            };
            joints.push(shin);
        }
        joints
    }

    /// 20 frames: the hips travel `speed` per frame along +Z, the left knee bends by up to
    /// `swing` radians, and the joint named `Foot`, when the file moves it in position, sits at
    /// the left shin's tip (an IK target; the root stays at the origin, so its translation is
    /// that position).
    fn clip(skeleton: &Skeleton, speed: f32, swing: f32) -> Motion {
        let (n, frames) = (skeleton.len(), 20);
        let index = |name: &str| skeleton.joints().iter().position(|j| j.name == name);
        let (hips, shin) = (index("Hips").unwrap(), index("Shin.L").unwrap());
        let mut rotations = Vec::new();
        let mut translations = Vec::new();
        for f in 0..frames {
            let mut r = vec![Quat::IDENTITY; n];
            r[shin] = Quat::from_rotation_x(swing * (f as f32 * 0.7).sin());
            let mut t: Vec<Vec3> = skeleton.joints().iter().map(|j| j.offset).collect();
            t[hips] += Vec3::Z * speed * f as f32;
            rotations.extend(r);
            translations.extend(t);
        }
        let motion = Motion::new(skeleton.clone(), 1.0 / 30.0, rotations.clone(), translations.clone()).unwrap();
        if let Some(foot) = index("Foot").filter(|&f| skeleton.joint(f).channels.has_position()) {
            let globals = all_global_transforms(&motion);
            let tip = skeleton.joint(shin).end_site.unwrap();
            for f in 0..frames {
                translations[f * n + foot] = globals[f * n + shin].apply(tip);
            }
        }
        Motion::new(skeleton.clone(), 1.0 / 30.0, rotations, translations).unwrap()
    }

    fn parent_name(motion: &Motion, name: &str) -> Option<String> {
        let skeleton = motion.skeleton();
        let joint = skeleton.joints().iter().find(|j| j.name == name).expect("the joint is kept");
        joint.parent.map(|p| skeleton.joint(p).name.clone())
    }

    #[test]
    fn a_root_that_carries_its_child_in_position_collapses_whatever_its_name() {
        // "Reference" is no helper by name; it is a dummy because the file moves the hips on it.
        let skeleton = Skeleton::new(body(rotating_joint("Reference", None, Vec3::ZERO))).unwrap();
        for speed in [0.0, 0.1] {
            let cleaned = clean(&clip(&skeleton, speed, 0.5), &CleanOptions::default()).unwrap().motion;
            assert_eq!(cleaned.skeleton().joint(0).name, "Hips", "speed {speed}");
            assert_eq!(cleaned.skeleton().len(), skeleton.len() - 1);
        }
        // A root whose one child only rotates is part of the body, moving or not.
        let mut joints = body(rotating_joint("Pelvis", None, Vec3::ZERO));
        joints[1] = rotating_joint("Hips", Some(0), Vec3::Y);
        let skeleton = Skeleton::new(joints).unwrap();
        let cleaned = clean(&clip(&skeleton, 0.0, 0.5), &CleanOptions::default()).unwrap().motion;
        assert_eq!(cleaned.skeleton().joint(0).name, "Pelvis");
    }

    #[test]
    fn a_floating_foot_goes_to_its_shin_in_every_clip() {
        let mut joints = body(rotating_joint("Root", None, Vec3::ZERO));
        joints.push(positioned("Foot", Some(0), Vec3::new(0.2, 0.1, 0.0)));
        let skeleton = Skeleton::new(joints).unwrap();
        // Walking with a bending knee only the shin holds the foot still; standing stock-still
        // every joint does, and the shin's tip is where the foot is.
        for (speed, swing) in [(0.1, 0.6), (0.0, 0.0)] {
            let cleaned = clean(&clip(&skeleton, speed, swing), &CleanOptions::default()).unwrap().motion;
            assert_eq!(cleaned.skeleton().joint(0).name, "Hips", "speed {speed}");
            assert_eq!(parent_name(&cleaned, "Foot").as_deref(), Some("Shin.L"), "speed {speed}, swing {swing}");
        }
        // A foot the file only rotates is fixed in the root's frame and stays on it.
        let mut joints = body(rotating_joint("Root", None, Vec3::ZERO));
        joints.push(rotating_joint("Foot", Some(0), Vec3::new(0.2, 0.1, 0.0)));
        let skeleton = Skeleton::new(joints).unwrap();
        let cleaned = clean(&clip(&skeleton, 0.0, 0.6), &CleanOptions::default()).unwrap().motion;
        assert_eq!(parent_name(&cleaned, "Foot").as_deref(), Some("Root"));
    }
}
