//! Which joint frames a codec reads a skeleton's motion in: the rig's own (tokenizer v1), or
//! frames rebased onto a reference pose of the skeleton (tokenizer v2, see
//! [`anymo_motion::reference`]), in which no rig's local-axis convention or rest pose shows.

use anymo_motion::motion::Motion;
use anymo_motion::reference::ReferencePose;
use serde::{Deserialize, Serialize};

/// A codec's representation of motion, recorded in its card.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Representation {
    /// Local rotations in the rig's own joint frames, relative to its BVH rest pose (cards
    /// written before the field existed).
    #[default]
    Rest,
    /// Rotations relative to a reference pose of the skeleton, every joint frame world-aligned
    /// at it and the body facing +Z.
    Reference,
}

impl std::str::FromStr for Representation {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "rest" => Ok(Representation::Rest),
            "reference" => Ok(Representation::Reference),
            other => Err(format!("no representation is called {other:?}; the choices are rest and reference")),
        }
    }
}

/// The joint frames one skeleton's motion is read in by a codec of some representation.
#[derive(Clone, Debug, PartialEq)]
pub enum Basis {
    /// The rig's own frames: motion goes through unchanged.
    Rest,
    /// Frames rebased onto this reference pose.
    Reference(ReferencePose),
}

impl Basis {
    /// The basis a codec of `representation` reads a skeleton in, from motion of that skeleton
    /// (all of one skeleton; the reference is their mean pose). Without frames, the reference
    /// is the skeleton's rest pose turned to face +Z, which is only as good as that rest pose.
    ///
    /// # Panics
    /// When the motions do not share one number of joints.
    pub fn of<'a>(
        representation: Representation,
        skeleton: &anymo_motion::skeleton::Skeleton,
        motions: impl IntoIterator<Item = &'a Motion>,
    ) -> Basis {
        match representation {
            Representation::Rest => Basis::Rest,
            Representation::Reference => Basis::Reference(
                ReferencePose::mean_of(motions)
                    .unwrap_or_else(|| ReferencePose::of_frame(&Motion::rest_pose(skeleton, 1.0 / 30.0), 0)),
            ),
        }
    }

    /// Motion in the rig's frames as the codec reads it.
    pub fn enter(&self, motion: &Motion) -> Motion {
        match self {
            Basis::Rest => motion.clone(),
            Basis::Reference(reference) => reference.rebase(motion),
        }
    }

    /// The skeleton of `motion` as the codec reads it (its offsets in this basis), without
    /// rebasing more than one frame.
    pub fn enter_skeleton(&self, motion: &Motion) -> anymo_motion::skeleton::Skeleton {
        self.enter(&motion.slice(0, 1)).skeleton().clone()
    }

    /// Motion the codec wrote, back in the rig's frames: the inverse of [`Basis::enter`].
    pub fn leave(&self, motion: &Motion) -> Motion {
        match self {
            Basis::Rest => motion.clone(),
            Basis::Reference(reference) => reference.restore(motion),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use anymo_motion::bvh::parse_str;
    use anymo_motion::kinematics::all_joint_positions;

    const TWO_FRAMES: &str = "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n \
        JOINT LeftLeg\n {\n  OFFSET 1 -1 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 -1 0\n  }\n }\n \
        JOINT RightLeg\n {\n  OFFSET -1 -1 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 -1 0\n  }\n }\n}\n\
        MOTION\nFrames: 2\nFrame Time: 0.1\n1 2 3 0 90 0 20 0 0 -20 0 0\n1 2 3 0 100 0 -20 0 0 20 0 0\n";

    #[test]
    fn the_reference_basis_rebases_and_leaves_exactly_the_rest_basis_not_at_all() {
        let motion = Motion::from_bvh(&parse_str(TWO_FRAMES).unwrap());
        let rest = Basis::of(Representation::Rest, motion.skeleton(), [&motion]);
        assert_eq!(rest.enter(&motion), motion);
        let basis = Basis::of(Representation::Reference, motion.skeleton(), [&motion]);
        let entered = basis.enter(&motion);
        assert_ne!(entered.skeleton(), motion.skeleton(), "offsets become the reference's bone vectors");
        let back = basis.leave(&entered);
        for (a, b) in all_joint_positions(&motion).iter().zip(all_joint_positions(&back)) {
            assert!(a.distance(b) < 1e-5, "{a} vs {b}");
        }
        for (a, b) in motion.all_rotations().iter().zip(back.all_rotations()) {
            assert!(a.dot(*b).abs() > 1.0 - 1e-5, "{a} vs {b}");
        }
    }

    #[test]
    fn without_frames_the_reference_is_the_rest_pose_facing_plus_z() {
        let motion = Motion::from_bvh(&parse_str(TWO_FRAMES).unwrap());
        let basis = Basis::of(Representation::Reference, motion.skeleton(), []);
        let rest = Motion::rest_pose(motion.skeleton(), 0.1);
        // The rest pose faces +Z already (left leg at +X), so it rebases to itself.
        for (a, b) in basis.enter(&rest).skeleton().joints().iter().zip(rest.skeleton().joints()) {
            assert!(a.offset.distance(b.offset) < 1e-6, "{} vs {}", a.offset, b.offset);
        }
        assert_eq!("reference".parse::<Representation>(), Ok(Representation::Reference));
        assert!("mean".parse::<Representation>().unwrap_err().contains("rest and reference"));
    }
}
