//! Model features (NEC 4.1 with SATA's root) and their exact inverse, plus canonicalisation.
//!
//! Per frame, the root carries heading-invariant motion: yaw rate, planar velocity in the heading
//! frame, height, and its orientation with the heading removed (rot6D); every other joint carries
//! its local rotation relative to the rest pose (rot6D). So a motion means the same wherever it
//! starts and whichever way it faces. Encoder-side extras (root-relative positions, velocities,
//! foot contacts) are derived from the same motion.

use crate::kinematics::{all_global_transforms, all_joint_positions};
use crate::motion::Motion;
use crate::prep::labels::label_skeleton;
use crate::reference::side_facing;
use crate::rotation::{quat_to_rot6d, rot6d_to_quat, twist_about};
use crate::skeleton::Skeleton;
use glam::{Quat, Vec3};

/// Root features per frame: yaw rate (radians per frame), planar velocity (x, z) in the heading
/// frame (units per frame), height.
pub const ROOT_DIMS: usize = 4;
/// rot6D per joint.
pub const ROT_DIMS: usize = 6;

/// Where and which way a motion starts: what the features leave out.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Start {
    /// Heading (rotation about +Y, radians) of the root in the first frame.
    pub heading: f32,
    /// Root position (x, z) in the first frame.
    pub planar: [f32; 2],
}

/// The features of a motion, frame-major.
#[derive(Clone, Debug, PartialEq)]
pub struct MotionFeatures {
    /// Number of frames.
    pub frames: usize,
    /// Number of joints.
    pub joints: usize,
    /// `frames x ROOT_DIMS`: yaw rate, heading-frame velocity x and z, height. The last frame's
    /// rates are zero.
    pub root: Vec<f32>,
    /// `frames x joints x ROT_DIMS`: the root's orientation without heading, then every other
    /// joint's local rotation.
    pub rotations: Vec<f32>,
}

/// The heading of a rotation: the angle (radians) of its twist about +Y. The features remove the
/// root's, so a model's decoded root orientation should have none.
pub fn heading_of(q: Quat) -> f32 {
    let twist = twist_about(q, Vec3::Y);
    2.0 * twist.y.atan2(twist.w)
}

/// Computes the features of a motion; with the returned [`Start`] they give the motion back.
pub fn to_features(motion: &Motion) -> (MotionFeatures, Start) {
    let (frames, joints) = (motion.frames(), motion.skeleton().len());
    let mut root = Vec::with_capacity(frames * ROOT_DIMS);
    let mut rotations = Vec::with_capacity(frames * joints * ROT_DIMS);
    let headings: Vec<f32> = (0..frames).map(|f| heading_of(motion.rotations(f)[0])).collect();
    for f in 0..frames {
        let heading = Quat::from_rotation_y(headings[f]);
        let position = motion.translations(f)[0];
        let (yaw_rate, velocity) = if f + 1 < frames {
            let delta = motion.translations(f + 1)[0] - position;
            (wrap_angle(headings[f + 1] - headings[f]), heading.inverse() * delta)
        } else {
            (0.0, Vec3::ZERO)
        };
        root.extend([yaw_rate, velocity.x, velocity.z, position.y]);
        for (j, q) in motion.rotations(f).iter().enumerate() {
            let local = if j == 0 { heading.inverse() * *q } else { *q };
            rotations.extend(quat_to_rot6d(local));
        }
    }
    let start = match frames {
        0 => Start::default(),
        _ => {
            let p = motion.translations(0)[0];
            Start { heading: headings[0], planar: [p.x, p.z] }
        }
    };
    (MotionFeatures { frames, joints, root, rotations }, start)
}

/// The root's heading and planar position at each frame, integrated from the features' rates
/// from heading 0 at the origin in frame 0.
pub fn root_path(features: &MotionFeatures) -> Vec<(f32, Vec3)> {
    let mut out = Vec::with_capacity(features.frames);
    let (mut heading, mut planar) = (0f32, Vec3::ZERO);
    for f in 0..features.frames {
        out.push((heading, planar));
        let r = &features.root[f * ROOT_DIMS..(f + 1) * ROOT_DIMS];
        planar += Quat::from_rotation_y(heading) * Vec3::new(r[1], 0.0, r[2]);
        heading += r[0];
    }
    out
}

/// Rebuilds a motion on `skeleton` from features (exact up to float for features of a real
/// motion; the nearest rotations for a model's raw 6D output).
pub fn from_features(features: &MotionFeatures, start: Start, skeleton: &Skeleton, frame_time: f64) -> Motion {
    let (frames, joints) = (features.frames, features.joints);
    assert_eq!(joints, skeleton.len(), "features are for a skeleton with {joints} joints");
    let mut rotations = Vec::with_capacity(frames * joints);
    let mut translations = Vec::with_capacity(frames * joints);
    let start_turn = Quat::from_rotation_y(start.heading);
    let origin = Vec3::new(start.planar[0], 0.0, start.planar[1]);
    for (f, (heading, planar)) in root_path(features).into_iter().enumerate() {
        let height = features.root[f * ROOT_DIMS + 3];
        let heading_q = Quat::from_rotation_y(start.heading + heading);
        let planar = origin + start_turn * planar;
        for j in 0..joints {
            let k = (f * joints + j) * ROT_DIMS;
            let six: [f32; 6] = features.rotations[k..k + ROT_DIMS].try_into().expect("six values");
            let local = rot6d_to_quat(six);
            if j == 0 {
                rotations.push((heading_q * local).normalize());
                translations.push(Vec3::new(planar.x, height, planar.z));
            } else {
                rotations.push(local);
                translations.push(skeleton.joint(j).offset);
            }
        }
    }
    Motion::new(skeleton.clone(), frame_time, rotations, translations).expect("shapes match")
}

/// An angle (radians) brought into [-pi, pi).
pub fn wrap_angle(a: f32) -> f32 {
    let two_pi = std::f32::consts::TAU;
    a - two_pi * ((a + std::f32::consts::PI) / two_pi).floor()
}

/// The feet of a motion: leaf joints whose mean height over the clip is within `band` (a
/// fraction of the diameter) of the lowest leaf's. Taken from the motion, not the rest pose,
/// since rest poses are not always standing (Bandai's lies on its side).
pub fn foot_joints(motion: &Motion, band: f32) -> Vec<usize> {
    let skeleton = motion.skeleton();
    let n = skeleton.len();
    if motion.frames() == 0 {
        return Vec::new();
    }
    let positions = all_joint_positions(motion);
    let mean_height =
        |j: usize| (0..motion.frames()).map(|f| positions[f * n + j].y).sum::<f32>() / motion.frames() as f32;
    let leaves: Vec<(usize, f32)> = (0..n).filter(|&j| skeleton.is_leaf(j)).map(|j| (j, mean_height(j))).collect();
    let lowest = leaves.iter().map(|l| l.1).fold(f32::INFINITY, f32::min);
    let tolerance = band * skeleton.diameter();
    leaves.into_iter().filter(|l| l.1 <= lowest + tolerance).map(|l| l.0).collect()
}

/// Moves and turns a motion so it starts at the origin on the floor, facing +Z, Y up (the input
/// must already be Y up). Facing comes from the left/right joints (their across vector) when the
/// skeleton has labelled sides, else from the root's heading.
pub fn canonicalise(motion: &Motion) -> Motion {
    if motion.frames() == 0 {
        return motion.clone();
    }
    let skeleton = motion.skeleton();
    let n = skeleton.len();
    let globals = all_global_transforms(motion);
    let first: Vec<Vec3> = globals[..n].iter().map(|t| t.translation).collect();
    let turn = Quat::from_rotation_y(-facing_angle(motion, &first));
    let root0 = first[0];
    // The floor is the lowest point reached by any joint or end site.
    let floor = globals
        .iter()
        .enumerate()
        .flat_map(|(k, t)| {
            let tip = skeleton.joint(k % n).end_site.map(|e| t.apply(e).y);
            std::iter::once(t.translation.y).chain(tip)
        })
        .fold(f32::INFINITY, f32::min);
    let (skeleton, frame_time, mut rotations, mut translations) = motion.clone().into_parts();
    for f in 0..motion.frames() {
        rotations[f * n] = (turn * rotations[f * n]).normalize();
        let t = translations[f * n];
        let planar = turn * Vec3::new(t.x - root0.x, 0.0, t.z - root0.z);
        translations[f * n] = Vec3::new(planar.x, t.y - floor, planar.z);
    }
    Motion::new(skeleton, frame_time, rotations, translations).expect("shapes match")
}

/// The angle about +Y from +Z to the direction the subject faces in the first frame.
fn facing_angle(motion: &Motion, first: &[Vec3]) -> f32 {
    let sides: Vec<_> = label_skeleton(motion.skeleton()).iter().map(|l| l.side).collect();
    side_facing(&sides, first).unwrap_or_else(|| heading_of(motion.rotations(0)[0]))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::bvh::parse_str;
    use crate::kinematics::all_joint_positions;

    /// A two-legged walk of four frames, shared with the other modules' tests.
    pub(crate) const WALK: &str = "HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT LeftLeg
  {
    OFFSET 1 -1 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 -1 0
    }
  }
  JOINT RightLeg
  {
    OFFSET -1 -1 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 -1 0
    }
  }
}
MOTION
Frames: 4
Frame Time: 0.1
5 2 7 0 0 90 10 0 0 -10 0 0
5.5 2.1 7 3 0 100 -10 0 0 10 0 0
6 2 7.2 5 2 120 10 5 0 -10 0 0
6.4 2 7.1 4 0 150 -10 0 3 10 0 0
";

    #[test]
    fn features_invert_exactly() {
        let motion = Motion::from_bvh(&parse_str(WALK).unwrap());
        let (features, start) = to_features(&motion);
        let back = from_features(&features, start, motion.skeleton(), motion.frame_time());
        let (a, b) = (all_joint_positions(&motion), all_joint_positions(&back));
        for (p, q) in a.iter().zip(&b) {
            assert!(p.distance(*q) < 1e-4, "{p} vs {q}");
        }
    }

    #[test]
    fn features_do_not_depend_on_start_position_or_heading() {
        let motion = Motion::from_bvh(&parse_str(WALK).unwrap());
        let canonical = canonicalise(&motion);
        let (a, _) = to_features(&motion);
        let (b, start) = to_features(&canonical);
        // Root velocities and all rotations are heading-invariant; height moves with the floor.
        for f in 0..a.frames {
            for d in 0..3 {
                assert!((a.root[f * ROOT_DIMS + d] - b.root[f * ROOT_DIMS + d]).abs() < 1e-4);
            }
        }
        for (x, y) in a.rotations.iter().zip(&b.rotations) {
            assert!((x - y).abs() < 1e-4);
        }
        // The canonical clip starts at the origin facing +Z.
        assert!(start.planar[0].abs() < 1e-5 && start.planar[1].abs() < 1e-5);
    }

    #[test]
    fn canonical_clip_faces_plus_z_and_stands_on_the_floor() {
        let motion = Motion::from_bvh(&parse_str(WALK).unwrap());
        let canonical = canonicalise(&motion);
        let p = all_joint_positions(&canonical);
        // Left is +X when facing +Z with Y up.
        let across = p[1] - p[2];
        assert!(across.x > 0.0 && across.z.abs() < 1e-4, "{across}");
        // The end sites hang 1 below the legs: the lowest point touches y = 0.
        let floor = p.iter().map(|q| q.y).fold(f32::INFINITY, f32::min);
        assert!(floor > 0.0);
        assert!(p[0].x.abs() < 1e-5 && p[0].z.abs() < 1e-5);
    }
}
