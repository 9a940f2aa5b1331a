//! Forward kinematics: local joint transforms to global ones, in the skeleton's own units and axes.
//!
//! A joint's global transform is its parent's global transform, then the joint's local
//! translation, then its local rotation: `G_j = G_parent * T(t_j) * R_j`.

use crate::motion::Motion;
use crate::skeleton::Skeleton;
use glam::{Quat, Vec3};

/// A rigid transform: rotate, then translate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transform {
    /// Orientation.
    pub rotation: Quat,
    /// Position.
    pub translation: Vec3,
}

impl Transform {
    /// The identity transform.
    pub const IDENTITY: Transform = Transform { rotation: Quat::IDENTITY, translation: Vec3::ZERO };

    /// Applies the transform to a point.
    pub fn apply(&self, p: Vec3) -> Vec3 {
        self.rotation * p + self.translation
    }
}

/// Global transforms of every joint for one pose given as local rotations and translations.
pub fn global_transforms(skeleton: &Skeleton, rotations: &[Quat], translations: &[Vec3], out: &mut Vec<Transform>) {
    out.clear();
    out.reserve(skeleton.len());
    for (j, joint) in skeleton.joints().iter().enumerate() {
        let global = match joint.parent {
            None => Transform { rotation: rotations[j], translation: translations[j] },
            Some(p) => {
                let parent = out[p];
                Transform { rotation: parent.rotation * rotations[j], translation: parent.apply(translations[j]) }
            }
        };
        out.push(global);
    }
}

/// Global joint positions of one frame.
pub fn joint_positions(motion: &Motion, frame: usize) -> Vec<Vec3> {
    let mut transforms = Vec::new();
    global_transforms(motion.skeleton(), motion.rotations(frame), motion.translations(frame), &mut transforms);
    transforms.into_iter().map(|t| t.translation).collect()
}

/// Global joint positions of every frame, frame-major (`frames x joints`).
pub fn all_joint_positions(motion: &Motion) -> Vec<Vec3> {
    let mut out = Vec::with_capacity(motion.frames() * motion.skeleton().len());
    let mut transforms = Vec::new();
    for f in 0..motion.frames() {
        global_transforms(motion.skeleton(), motion.rotations(f), motion.translations(f), &mut transforms);
        out.extend(transforms.iter().map(|t| t.translation));
    }
    out
}

/// Global transforms of every frame, frame-major (`frames x joints`).
pub fn all_global_transforms(motion: &Motion) -> Vec<Transform> {
    let mut out = Vec::with_capacity(motion.frames() * motion.skeleton().len());
    let mut transforms = Vec::new();
    for f in 0..motion.frames() {
        global_transforms(motion.skeleton(), motion.rotations(f), motion.translations(f), &mut transforms);
        out.extend_from_slice(&transforms);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::parse_str;

    /// A three-joint chain whose global positions are worked out by hand below.
    const CHAIN: &str = "HIERARCHY
ROOT Root
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Upper
  {
    OFFSET 0 2 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT Lower
    {
      OFFSET 0 3 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      End Site
      {
        OFFSET 0 1 0
      }
    }
  }
}
MOTION
Frames: 1
Frame Time: 0.1
10 0 0 90 0 0 0 0 0 -90 0 0
";

    #[test]
    fn fk_of_a_hand_computed_chain() {
        let motion = Motion::from_bvh(&parse_str(CHAIN).unwrap());
        let p = joint_positions(&motion, 0);
        // Root at (10, 0, 0), turned +90 degrees about Z: its local +Y points to world -X.
        assert!((p[0] - Vec3::new(10.0, 0.0, 0.0)).length() < 1e-5);
        // Upper sits 2 along the root's +Y, i.e. at (8, 0, 0); it does not rotate.
        assert!((p[1] - Vec3::new(8.0, 0.0, 0.0)).length() < 1e-5);
        // Lower sits 3 further along the same direction: (5, 0, 0). Its own -90 degree turn
        // only moves its children.
        assert!((p[2] - Vec3::new(5.0, 0.0, 0.0)).length() < 1e-5);
    }
}
