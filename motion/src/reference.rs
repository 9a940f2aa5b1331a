//! A skeleton's reference pose, and motion rebased onto it (NEC appendix C.1, made
//! deterministic).
//!
//! A BVH rest pose is rarely a real pose (lying on its side, sticks along +Y), and each rig's
//! joint frames follow its own convention, so raw local rotations are large per-rig constants
//! plus a small motion. Rebasing turns every joint's frame so that it is aligned with the world
//! at the reference pose, with the body facing +Z: local rotations become deltas from the
//! reference, and the skeleton's offsets become the reference pose's bone vectors. Two rigs that
//! differ only in their joint frames or rest pose rebase to the same motion on the same skeleton
//! (exactly, up to rounding), and [`ReferencePose::restore`] gives the user's own frames back.

use crate::kinematics::all_global_transforms;
use crate::motion::Motion;
use crate::prep::augment::turn_joint_frames;
use crate::prep::labels::{Side, label_skeleton};
use glam::{Quat, Vec3};

/// Each joint's global rotation in a pose that faces +Z with Y up.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferencePose {
    globals: Vec<Quat>,
}

impl ReferencePose {
    /// The mean pose of motions of one skeleton: every frame is turned to face +Z (see
    /// [`facing_angle`]), then each joint takes the normalised mean of its global rotations
    /// (signs aligned). The mean is taken over rotations of the world, not of the rig's local
    /// axes, so turning the rig's joint frames turns the mean with them. `None` without frames.
    ///
    /// # Panics
    /// When the motions do not share one number of joints.
    pub fn mean_of<'a>(motions: impl IntoIterator<Item = &'a Motion>) -> Option<ReferencePose> {
        let mut sums: Vec<glam::Vec4> = Vec::new();
        let mut first: Vec<Quat> = Vec::new();
        for motion in motions {
            let n = motion.skeleton().len();
            if sums.is_empty() {
                sums = vec![glam::Vec4::ZERO; n];
            }
            assert_eq!(sums.len(), n, "every motion of a reference pose has {} joints", sums.len());
            for pose in facing_poses(motion) {
                if first.is_empty() {
                    first = pose.clone();
                }
                for (j, q) in pose.into_iter().enumerate() {
                    let v = glam::Vec4::from(q);
                    sums[j] += if v.dot(glam::Vec4::from(first[j])) < 0.0 { -v } else { v };
                }
            }
        }
        (!first.is_empty())
            .then(|| ReferencePose { globals: sums.into_iter().map(|s| Quat::from_vec4(s).normalize()).collect() })
    }

    /// A reference pose from each joint's global rotation (as [`ReferencePose::globals`] gives
    /// them), normalised.
    pub fn from_globals(globals: impl IntoIterator<Item = Quat>) -> ReferencePose {
        ReferencePose { globals: globals.into_iter().map(Quat::normalize).collect() }
    }

    /// Each joint's global rotation in the pose.
    pub fn globals(&self) -> &[Quat] {
        &self.globals
    }

    /// The pose of one frame of a motion, turned to face +Z.
    ///
    /// # Panics
    /// When `frame` is not a frame of the motion.
    pub fn of_frame(motion: &Motion, frame: usize) -> ReferencePose {
        let one = motion.slice(frame, 1);
        ReferencePose { globals: facing_poses(&one).remove(0) }
    }

    /// The motion with every joint frame turned to be world-aligned at this reference: local
    /// rotations are deltas from it, offsets are its bone vectors. World positions are unchanged.
    ///
    /// # Panics
    /// When the motion's skeleton has another number of joints.
    pub fn rebase(&self, motion: &Motion) -> Motion {
        let turns: Vec<Quat> = self.globals.iter().map(|q| q.inverse()).collect();
        turn_joint_frames(motion, &turns)
    }

    /// The inverse of [`ReferencePose::rebase`]: motion on the rebased skeleton back in the
    /// joint frames of the skeleton this reference was taken on.
    ///
    /// # Panics
    /// When the motion's skeleton has another number of joints.
    pub fn restore(&self, rebased: &Motion) -> Motion {
        turn_joint_frames(rebased, &self.globals)
    }
}

/// Every frame's global rotations, turned about +Y so the frame faces +Z.
fn facing_poses(motion: &Motion) -> Vec<Vec<Quat>> {
    let n = motion.skeleton().len();
    let labels = label_skeleton(motion.skeleton());
    let sides: Vec<Option<Side>> = labels.iter().map(|l| l.side).collect();
    all_global_transforms(motion)
        .chunks(n)
        .map(|frame| {
            let positions: Vec<Vec3> = frame.iter().map(|t| t.translation).collect();
            let turn = Quat::from_rotation_y(-facing_angle(&sides, &positions));
            frame.iter().map(|t| (turn * t.rotation).normalize()).collect()
        })
        .collect()
}

/// The angle about +Y from +Z to the direction a pose faces, from joint positions alone (so it
/// does not depend on the rig's joint frames): [`side_facing`] when the skeleton has joints of
/// both sides, else the horizontal direction from the root to the mean of the joints (a snake's
/// or fish's body axis), else 0.
pub fn facing_angle(sides: &[Option<Side>], positions: &[Vec3]) -> f32 {
    side_facing(sides, positions).unwrap_or_else(|| {
        let axis = positions.iter().sum::<Vec3>() / positions.len().max(1) as f32 - positions[0];
        yaw_of(axis).unwrap_or(0.0)
    })
}

/// The angle about +Y from +Z to the forward of a pose's left-to-right axis (the mean of its
/// left joints minus the mean of its right ones, crossed with +Y); `None` without joints of both
/// sides or when that axis is vertical.
pub fn side_facing(sides: &[Option<Side>], positions: &[Vec3]) -> Option<f32> {
    let mean = |side: Side| {
        let pts: Vec<Vec3> = sides.iter().zip(positions).filter(|(s, _)| **s == Some(side)).map(|(_, p)| *p).collect();
        (!pts.is_empty()).then(|| pts.iter().sum::<Vec3>() / pts.len() as f32)
    };
    yaw_of((mean(Side::Left)? - mean(Side::Right)?).cross(Vec3::Y))
}

/// The angle about +Y from +Z to a direction's horizontal part, if it has one.
fn yaw_of(direction: Vec3) -> Option<f32> {
    (direction.x.hypot(direction.z) > 1e-6).then(|| direction.x.atan2(direction.z))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::parse_str;
    use crate::features::tests::WALK;
    use crate::features::to_features;
    use crate::kinematics::all_joint_positions;

    fn walk() -> Motion {
        Motion::from_bvh(&parse_str(WALK).unwrap())
    }

    fn turns() -> Vec<Quat> {
        vec![
            Quat::from_euler(glam::EulerRot::XYZ, 0.3, -1.2, 2.0),
            Quat::from_euler(glam::EulerRot::XYZ, -2.5, 0.4, 0.1),
            Quat::from_euler(glam::EulerRot::XYZ, 1.0, 1.0, -0.7),
        ]
    }

    #[test]
    fn rebasing_keeps_positions_and_restoring_gives_the_rig_back() {
        let motion = walk();
        let reference = ReferencePose::mean_of([&motion]).unwrap();
        let rebased = reference.rebase(&motion);
        let restored = reference.restore(&rebased);
        for (p, q) in all_joint_positions(&motion).iter().zip(all_joint_positions(&rebased)) {
            assert!(p.distance(q) < 1e-4, "{p} vs {q}");
        }
        for (a, b) in motion.all_rotations().iter().zip(restored.all_rotations()) {
            assert!(a.dot(*b).abs() > 1.0 - 1e-5, "{a} vs {b}");
        }
        for (a, b) in motion.skeleton().joints().iter().zip(restored.skeleton().joints()) {
            assert!(a.offset.distance(b.offset) < 1e-5);
        }
    }

    #[test]
    fn the_reference_pose_rebases_to_identity_and_faces_plus_z() {
        let motion = walk();
        let reference = ReferencePose::of_frame(&motion, 2);
        let rebased = reference.rebase(&motion);
        // Below the root, frame 2's local rotations are the identity.
        for q in &rebased.rotations(2)[1..] {
            assert!(q.angle_between(Quat::IDENTITY) < 1e-3, "{q}");
        }
        // The root's is a pure turn about +Y (the heading frame 2 faces).
        let root = rebased.rotations(2)[0];
        assert!((root * Vec3::Y).distance(Vec3::Y) < 1e-4, "{root}");
        // Its offsets are the pose's bone vectors facing +Z: left leg at +X.
        assert!(rebased.skeleton().joint(1).offset.x > 0.5, "{}", rebased.skeleton().joint(1).offset);
    }

    #[test]
    fn rigs_that_differ_in_joint_frames_rebase_to_the_same_features() {
        let motion = walk();
        let turned = turn_joint_frames(&motion, &turns());
        let a = ReferencePose::mean_of([&motion]).unwrap().rebase(&motion);
        let b = ReferencePose::mean_of([&turned]).unwrap().rebase(&turned);
        let ((fa, _), (fb, _)) = (to_features(&a), to_features(&b));
        for (x, y) in fa.rotations.iter().chain(&fa.root).zip(fb.rotations.iter().chain(&fb.root)) {
            assert!((x - y).abs() < 1e-4, "{x} vs {y}");
        }
        for (ja, jb) in a.skeleton().joints().iter().zip(b.skeleton().joints()) {
            assert!(ja.offset.distance(jb.offset) < 1e-4, "{} vs {}", ja.offset, jb.offset);
        }
    }

    #[test]
    fn facing_comes_from_sides_then_from_the_body_axis() {
        let sides = [None, Some(Side::Left), Some(Side::Right)];
        let across = [Vec3::ZERO, Vec3::new(1.0, 0.0, 0.0), Vec3::new(-1.0, 0.0, 0.0)];
        assert!(facing_angle(&sides, &across).abs() < 1e-6, "left at +X faces +Z");
        let snake = [Vec3::ZERO, Vec3::new(-1.0, 0.0, 0.0), Vec3::new(-2.0, 0.0, 0.0)];
        let angle = facing_angle(&[None; 3], &snake);
        assert!((angle + std::f32::consts::FRAC_PI_2).abs() < 1e-6, "{angle}");
    }
}
