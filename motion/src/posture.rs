//! Standing a body up. A rest pose is often not a standing pose, and a reference pose taken
//! from one lying on its side would have generated motion lie on the floor. A rig with legs is
//! turned as a whole so that its legs point down: from the mean of its ankles to the mean of its
//! hips (the ends of each leg's two-bone chain) is +Y. Some rest poses are no pose at all
//! (Bandai's, LAFAN1's and CMU's put every bone along one axis, legs and spine alike); turning
//! cannot help those, and only frames of real motion give them a pose.

use crate::contact::leg_ends;
use crate::kinematics::all_global_transforms;
use crate::motion::Motion;
use glam::{Quat, Vec3};

/// The motion turned about its root by the rotation that stands its first frame up (unchanged
/// for a rig without legs, or when its legs and body do not point apart).
pub fn upright(motion: &Motion) -> Motion {
    let Some(turn) = standing_turn(motion) else { return motion.clone() };
    let (skeleton, frame_time, mut rotations, translations) = motion.clone().into_parts();
    let n = skeleton.len();
    for f in 0..motion.frames() {
        rotations[f * n] = (turn * rotations[f * n]).normalize();
    }
    Motion::new(skeleton, frame_time, rotations, translations).expect("shapes unchanged")
}

/// The rotation taking the first frame's ankles-to-hips direction to +Y.
fn standing_turn(motion: &Motion) -> Option<Quat> {
    let ends = leg_ends(motion);
    if ends.is_empty() {
        return None;
    }
    let skeleton = motion.skeleton();
    let first = all_global_transforms(&motion.slice(0, 1));
    let count = ends.len() as f32;
    let ankles = ends.iter().map(|e| e.chain.ankle_position(skeleton, &first)).sum::<Vec3>() / count;
    let hips = ends.iter().map(|e| first[e.chain.upper].translation).sum::<Vec3>() / count;
    let up = (hips - ankles).try_normalize().filter(|_| hips.distance(ankles) > 1e-3 * skeleton.diameter())?;
    Some(Quat::from_rotation_arc(up, Vec3::Y))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::tests::biped;
    use crate::kinematics::all_joint_positions;

    /// The biped with its root turned by `turn`.
    fn turned(leg: &str, foot: &str, turn: Quat) -> Motion {
        let (skeleton, frame_time, mut rotations, translations) = biped(leg, foot).into_parts();
        let n = skeleton.len();
        for f in 0..rotations.len() / n {
            rotations[f * n] = turn * rotations[f * n];
        }
        Motion::new(skeleton, frame_time, rotations, translations).unwrap()
    }

    #[test]
    fn a_body_lying_on_its_side_or_face_stands_up() {
        let standing = all_joint_positions(&biped("Leg", "Foot").slice(0, 1));
        for turn in [Quat::from_rotation_z(1.5), Quat::from_rotation_x(-1.2), Quat::from_rotation_z(3.0)] {
            let stood = all_joint_positions(&upright(&turned("Leg", "Foot", turn)).slice(0, 1));
            // Relative to the root, every joint is where it is when standing, up to a turn about +Y.
            for (a, b) in stood.iter().zip(&standing) {
                let (a, b) = (*a - stood[0], *b - standing[0]);
                assert!((a.y - b.y).abs() < 1e-4, "{turn}: {a} against {b}");
                assert!((a.length() - b.length()).abs() < 1e-4);
            }
        }
        // Standing already: nothing moves.
        let same = upright(&biped("Leg", "Foot"));
        assert!(same.rotations(0)[0].angle_between(Quat::IDENTITY) < 1e-4);
    }

    #[test]
    fn a_rig_without_legs_is_left_as_it_lies() {
        let lying = turned("Fin", "Flap", Quat::from_rotation_z(1.5));
        assert_eq!(upright(&lying).all_rotations(), lying.all_rotations());
    }
}
