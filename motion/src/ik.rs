//! Analytic two-bone inverse kinematics: a hip, a knee and an ankle are turned so that the
//! ankle reaches a target while the knee stays in its current bending plane and the ankle keeps
//! its global orientation (so whatever hangs below it, a foot or a toe, moves rigidly).
//!
//! Written by hand: it is twenty lines of the law of cosines on `glam` vectors, and the IK crates
//! solve general chains iteratively on their own skeleton types.

use crate::kinematics::Transform;
use crate::skeleton::Skeleton;
use glam::{Quat, Vec3};

/// The end of a two-bone chain: a joint (the lower joint's child) or the lower joint's end site.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ankle {
    /// A child joint of the lower joint; its global rotation is kept.
    Joint(usize),
    /// The lower joint's end site.
    EndSite,
}

/// Three joints in a row: `upper` is `lower`'s parent, and the ankle hangs from `lower`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Chain {
    /// The joint whose rotation swings the first bone (a hip or shoulder).
    pub upper: usize,
    /// The joint whose rotation swings the second bone (a knee or elbow).
    pub lower: usize,
    /// Where the second bone ends.
    pub ankle: Ankle,
}

impl Chain {
    /// The chain if the joints really are in a row below a non-root upper joint with bones of
    /// non-zero length; `None` otherwise.
    pub fn new(skeleton: &Skeleton, upper: usize, lower: usize, ankle: Ankle) -> Option<Chain> {
        let chain = Chain { upper, lower, ankle };
        let connected = upper != 0
            && skeleton.joint(lower).parent == Some(upper)
            && match ankle {
                Ankle::Joint(a) => skeleton.joint(a).parent == Some(lower),
                Ankle::EndSite => skeleton.joint(lower).end_site.is_some(),
            };
        let [a, b] = chain.bone_lengths(skeleton);
        let least = 1e-4 * skeleton.diameter();
        (connected && a > least && b > least).then_some(chain)
    }

    /// The rest lengths of the two bones.
    pub fn bone_lengths(&self, skeleton: &Skeleton) -> [f32; 2] {
        let second = match self.ankle {
            Ankle::Joint(a) => skeleton.joint(a).offset,
            Ankle::EndSite => skeleton.joint(self.lower).end_site.unwrap_or(Vec3::ZERO),
        };
        [skeleton.joint(self.lower).offset.length(), second.length()]
    }

    /// The ankle's global position in a pose.
    pub fn ankle_position(&self, skeleton: &Skeleton, globals: &[Transform]) -> Vec3 {
        match self.ankle {
            Ankle::Joint(a) => globals[a].translation,
            Ankle::EndSite => globals[self.lower].apply(skeleton.joint(self.lower).end_site.unwrap_or(Vec3::ZERO)),
        }
    }

    /// Turns the chain's local rotations (`rotations`, one per joint of one frame, whose global
    /// transforms are `globals`) so that the ankle lands on `target`, or as near as the bones
    /// reach. The knee bends in the plane of the hip, the knee and the target; on a straight leg,
    /// towards `bend` (any vector with a component across the leg). `globals` is not updated.
    pub fn reach(&self, skeleton: &Skeleton, rotations: &mut [Quat], globals: &[Transform], target: Vec3, bend: Vec3) {
        let hip = globals[self.upper].translation;
        let knee = globals[self.lower].translation;
        let ankle = self.ankle_position(skeleton, globals);
        let (thigh, shin) = ((knee - hip).length(), (ankle - knee).length());
        let to_target = target - hip;
        let Some(along) = to_target.try_normalize() else { return };
        // The reach is kept just inside the triangle inequality so the knee keeps a direction.
        let slack = 1e-4 * (thigh + shin);
        let reach = to_target.length().clamp((thigh - shin).abs() + slack, thigh + shin - slack);
        let across = (knee - hip).reject_from_normalized(along);
        let across = across.try_normalize().or_else(|| bend.reject_from_normalized(along).try_normalize());
        let Some(across) = across.or_else(|| along.any_orthonormal_vector().try_normalize()) else { return };
        let cos_hip = ((thigh * thigh + reach * reach - shin * shin) / (2.0 * thigh * reach)).clamp(-1.0, 1.0);
        let new_knee = hip + thigh * (cos_hip * along + (1.0 - cos_hip * cos_hip).sqrt() * across);
        let new_ankle = hip + reach * along;
        let swing_upper = arc(knee - hip, new_knee - hip);
        let moved_ankle = new_knee + swing_upper * (ankle - knee);
        let swing_lower = arc(moved_ankle - new_knee, new_ankle - new_knee);
        let parent = skeleton.joint(self.upper).parent.map_or(Quat::IDENTITY, |p| globals[p].rotation);
        let upper = (swing_upper * globals[self.upper].rotation).normalize();
        let lower = (swing_lower * swing_upper * globals[self.lower].rotation).normalize();
        rotations[self.upper] = (parent.inverse() * upper).normalize();
        rotations[self.lower] = (upper.inverse() * lower).normalize();
        if let Ankle::Joint(a) = self.ankle {
            rotations[a] = (lower.inverse() * globals[a].rotation).normalize();
        }
    }
}

/// The shortest rotation taking direction `from` to direction `to` (identity for a zero vector).
fn arc(from: Vec3, to: Vec3) -> Quat {
    match (from.try_normalize(), to.try_normalize()) {
        (Some(a), Some(b)) => Quat::from_rotation_arc(a, b),
        _ => Quat::IDENTITY,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::global_transforms;
    use crate::skeleton::rotating_joint as joint;

    /// pelvis -> hip -> knee -> ankle -> toe (end site), a leg of two bones of length 0.5 and a
    /// foot pointing forward.
    fn leg() -> Skeleton {
        let mut joints = vec![
            joint("pelvis", None, Vec3::ZERO),
            joint("hip", Some(0), Vec3::new(0.1, 0.0, 0.0)),
            joint("knee", Some(1), Vec3::new(0.0, -0.5, 0.0)),
            joint("ankle", Some(2), Vec3::new(0.0, -0.5, 0.0)),
        ];
        joints[3].end_site = Some(Vec3::new(0.0, -0.05, 0.15));
        Skeleton::new(joints).unwrap()
    }

    fn pose(skeleton: &Skeleton, rotations: &[Quat]) -> Vec<Transform> {
        let translations: Vec<Vec3> = skeleton.joints().iter().map(|j| j.offset).collect();
        let mut out = Vec::new();
        global_transforms(skeleton, rotations, &translations, &mut out);
        out
    }

    #[test]
    fn the_ankle_reaches_a_reachable_target_and_keeps_its_orientation() {
        let skeleton = leg();
        let chain = Chain::new(&skeleton, 1, 2, Ankle::Joint(3)).unwrap();
        // A slightly bent knee, the body turned: the solve must not depend on a neutral start.
        let mut rotations =
            vec![Quat::from_rotation_y(0.7), Quat::IDENTITY, Quat::from_rotation_x(0.3), Quat::IDENTITY];
        let before = pose(&skeleton, &rotations);
        let target = Vec3::new(0.3, -0.7, 0.25);
        chain.reach(&skeleton, &mut rotations, &before, target, Vec3::Z);
        let after = pose(&skeleton, &rotations);
        assert!(after[3].translation.distance(target) < 1e-5, "{}", after[3].translation);
        assert!(after[3].rotation.angle_between(before[3].rotation) < 1e-4);
        // Bones keep their lengths, the pelvis does not move.
        assert!((after[2].translation.distance(after[1].translation) - 0.5).abs() < 1e-5);
        assert_eq!(after[0], before[0]);
        // The toe moved exactly as the ankle did.
        let toe = |g: &[Transform]| g[3].apply(skeleton.joint(3).end_site.unwrap());
        let moved = toe(&after) - toe(&before);
        assert!(moved.distance(after[3].translation - before[3].translation) < 1e-5);
    }

    #[test]
    fn the_knee_stays_in_its_bending_plane() {
        let skeleton = leg();
        let chain = Chain::new(&skeleton, 1, 2, Ankle::Joint(3)).unwrap();
        // Bent forward (towards +Z): the knee ahead of the hip-ankle line.
        let mut rotations =
            vec![Quat::IDENTITY, Quat::from_rotation_x(-0.4), Quat::from_rotation_x(0.8), Quat::IDENTITY];
        let before = pose(&skeleton, &rotations);
        // Pull the ankle up towards the hip: the knee must come further forward, not sideways.
        let target = before[3].translation + Vec3::new(0.0, 0.2, 0.0);
        chain.reach(&skeleton, &mut rotations, &before, target, Vec3::Z);
        let after = pose(&skeleton, &rotations);
        assert!(after[3].translation.distance(target) < 1e-5);
        assert!(after[2].translation.z > before[2].translation.z, "{}", after[2].translation);
        assert!((after[2].translation.x - 0.1).abs() < 1e-5, "{}", after[2].translation);
    }

    #[test]
    fn a_straight_leg_bends_towards_the_hint_and_an_unreachable_target_is_approached() {
        let skeleton = leg();
        let chain = Chain::new(&skeleton, 1, 2, Ankle::Joint(3)).unwrap();
        let mut rotations = vec![Quat::IDENTITY; 4];
        let before = pose(&skeleton, &rotations);
        chain.reach(&skeleton, &mut rotations, &before, Vec3::new(0.1, -0.8, 0.0), Vec3::Z);
        let after = pose(&skeleton, &rotations);
        assert!(after[3].translation.distance(Vec3::new(0.1, -0.8, 0.0)) < 1e-5);
        assert!(after[2].translation.z > 0.1, "{}", after[2].translation);
        // Two metres away: the leg points at it, fully stretched.
        let mut rotations = vec![Quat::IDENTITY; 4];
        chain.reach(&skeleton, &mut rotations, &before, Vec3::new(0.1, -2.0, 0.0), Vec3::Z);
        let after = pose(&skeleton, &rotations);
        assert!(after[3].translation.distance(Vec3::new(0.1, -1.0, 0.0)) < 1e-3, "{}", after[3].translation);
    }

    #[test]
    fn chains_must_be_connected_below_the_root() {
        let skeleton = leg();
        assert!(Chain::new(&skeleton, 0, 1, Ankle::Joint(2)).is_none(), "the root cannot swing");
        assert!(Chain::new(&skeleton, 1, 3, Ankle::EndSite).is_none(), "3 is not 1's child");
        assert!(Chain::new(&skeleton, 2, 3, Ankle::EndSite).is_some());
        assert!(Chain::new(&skeleton, 1, 2, Ankle::EndSite).is_none(), "the knee has no end site");
    }
}
