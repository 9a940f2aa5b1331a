//! Reconstruction metrics of `../shared/docs/EVAL.md`: MPJPE (with and without translation),
//! GeoDist, foot skating and ground penetration. (EVAL.md's SAN transfer error needs the same
//! motion on two rigs, which the corpus does not have; transfer is measured by cycle consistency
//! in `anymo eval tokenizer` instead.)
//!
//! Positions are frame-major slices of `frames x joints`; scale skeletons to diameter 1 first
//! (see [`crate::prep::clean`]) to get diameter-normalised figures.

use crate::rotation::geodesic_angle;
use crate::skeleton::Skeleton;
use glam::{Quat, Vec3};

/// Mean Euclidean distance between corresponding joints over all joints and frames, with the
/// global translation included ("MPJPE (with trans)").
pub fn mpjpe(predicted: &[Vec3], truth: &[Vec3]) -> f32 {
    assert_eq!(predicted.len(), truth.len(), "same frames and joints");
    mean(predicted.iter().zip(truth).map(|(p, t)| p.distance(*t)))
}

/// MPJPE after aligning the root (joint 0 of each frame) of the prediction to the truth's.
pub fn mpjpe_root_aligned(predicted: &[Vec3], truth: &[Vec3], joints: usize) -> f32 {
    assert_eq!(predicted.len(), truth.len(), "same frames and joints");
    let errors = predicted.chunks(joints).zip(truth.chunks(joints)).flat_map(|(p, t)| {
        let (pr, tr) = (p[0], t[0]);
        p.iter().zip(t).map(move |(a, b)| (*a - pr).distance(*b - tr))
    });
    mean(errors)
}

/// MPJPE after aligning the root position and turning each predicted frame about +Y by the
/// angle that fits it best to the truth's (least squares, in closed form): a heading error that
/// builds up over a long clip no longer counts, so what is left is the pose. The fit is on the
/// joints themselves, so it holds for rigs whose root rotation has no clear heading.
pub fn mpjpe_yaw_aligned(predicted: &[Vec3], truth: &[Vec3], joints: usize) -> f32 {
    assert_eq!(predicted.len(), truth.len(), "same frames and joints");
    let errors = predicted.chunks(joints).zip(truth.chunks(joints)).flat_map(|(p, t)| {
        let (pr, tr) = (p[0], t[0]);
        // Rotating a about +Y by theta gives a . b = cos(theta) c + sin(theta) s.
        let (c, s) = p.iter().zip(t).fold((0.0f32, 0.0f32), |(c, s), (a, b)| {
            let (a, b) = (*a - pr, *b - tr);
            (c + a.x * b.x + a.z * b.z, s + a.z * b.x - a.x * b.z)
        });
        let turn = Quat::from_rotation_y(s.atan2(c));
        p.iter().zip(t).map(move |(a, b)| (turn * (*a - pr)).distance(*b - tr))
    });
    mean(errors)
}

/// The mean angle (degrees) by which the predicted body is turned against the truth: per frame,
/// the angle of the rotation that best fits the predicted root-relative joint positions onto the
/// truth's (least squares, Kabsch), averaged over frames. A reconstruction that keeps the pose
/// scores near 0; a body turned about the vertical, tipped nose-up, or with its spine reversed
/// scores the size of that turn, whichever joint carries it, where MPJPE would only average it.
pub fn body_turn_deg(predicted: &[Vec3], truth: &[Vec3], joints: usize) -> f32 {
    assert_eq!(predicted.len(), truth.len(), "same frames and joints");
    let angles = predicted.chunks(joints).zip(truth.chunks(joints)).map(|(p, t)| {
        let (pr, tr) = (p[0], t[0]);
        let mut h = nalgebra::Matrix3::<f64>::zeros();
        for (a, b) in p.iter().zip(t) {
            let (a, b) = (*a - pr, *b - tr);
            h += nalgebra::Vector3::new(a.x as f64, a.y as f64, a.z as f64)
                * nalgebra::RowVector3::new(b.x as f64, b.y as f64, b.z as f64);
        }
        let svd = h.svd(true, true);
        let (u, v_t) = (svd.u.expect("asked for U"), svd.v_t.expect("asked for V^T"));
        let mut d = nalgebra::Matrix3::<f64>::identity();
        d[(2, 2)] = (v_t.transpose() * u.transpose()).determinant().signum();
        let r = v_t.transpose() * d * u.transpose();
        (((r.trace() - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees()) as f32
    });
    mean(angles)
}

/// Mean geodesic angle in degrees between corresponding local rotations.
pub fn geodesic_distance_deg(predicted: &[Quat], truth: &[Quat]) -> f32 {
    assert_eq!(predicted.len(), truth.len(), "same frames and joints");
    mean(predicted.iter().zip(truth).map(|(p, t)| geodesic_angle(*p, *t).to_degrees()))
}

/// What a joint's rotation moves, to tell apart the GeoDist that positions can see from the
/// GeoDist only the rotations themselves show.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JointKind {
    /// The root: its rotation carries the heading.
    Root,
    /// A joint whose rotation moves some other joint, so positions constrain it.
    Inner,
    /// A joint whose rotation moves no joint: a leaf (its end site is not a joint), or a joint
    /// whose descendants all sit on it at zero offset.
    Unseen,
}

impl JointKind {
    /// Offsets shorter than this fraction of the diameter count as zero.
    const ZERO_OFFSET: f32 = 1e-4;

    /// The kind of every joint of `skeleton`, in joint order.
    pub fn of(skeleton: &Skeleton) -> Vec<JointKind> {
        let zero = Self::ZERO_OFFSET * skeleton.diameter();
        let mut moves = vec![false; skeleton.len()];
        // Parents come before their children, so walking back visits a subtree before its root.
        for (i, joint) in skeleton.joints().iter().enumerate().skip(1).rev() {
            let parent = joint.parent.expect("non-root joint has a parent");
            moves[parent] |= moves[i] || joint.offset.length() > zero;
        }
        moves
            .iter()
            .enumerate()
            .map(|(i, &m)| match (i, m) {
                (0, _) => JointKind::Root,
                (_, true) => JointKind::Inner,
                (_, false) => JointKind::Unseen,
            })
            .collect()
    }
}

/// The summed geodesic angle (degrees) and joint-frame count of each [`JointKind`], in the
/// order root, inner, unseen, over frame-major `frames x joints` rotations.
pub fn geodesic_sums_by_kind(predicted: &[Quat], truth: &[Quat], kinds: &[JointKind]) -> [(f64, usize); 3] {
    assert_eq!(predicted.len(), truth.len(), "same frames and joints");
    let mut out = [(0f64, 0usize); 3];
    for (i, (p, t)) in predicted.iter().zip(truth).enumerate() {
        let slot = &mut out[kinds[i % kinds.len()] as usize];
        slot.0 += geodesic_angle(*p, *t).to_degrees() as f64;
        slot.1 += 1;
    }
    out
}

/// Foot skating: the mean horizontal speed (units per second) of the given foot joints over the
/// frames where they are in contact (height at most `contact_height` above y = 0 in both frames
/// of a step). Zero when no foot is ever in contact.
pub fn foot_skating(positions: &[Vec3], joints: usize, feet: &[usize], fps: f32, contact_height: f32) -> f32 {
    let frames = positions.len() / joints;
    let speeds = (1..frames).flat_map(|f| {
        feet.iter().filter_map(move |&j| {
            let (a, b) = (positions[(f - 1) * joints + j], positions[f * joints + j]);
            (a.y <= contact_height && b.y <= contact_height).then(|| (b - a).with_y(0.0).length() * fps)
        })
    });
    mean(speeds)
}

/// Ground penetration: the mean depth below the floor (y = 0) over all joints and frames,
/// counting joints above the floor as zero.
pub fn ground_penetration(positions: &[Vec3]) -> f32 {
    mean(positions.iter().map(|p| (-p.y).max(0.0)))
}

fn mean(values: impl Iterator<Item = f32>) -> f32 {
    let (sum, count) = values.fold((0.0f64, 0usize), |(s, c), v| (s + v as f64, c + 1));
    if count == 0 { 0.0 } else { (sum / count as f64) as f32 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yaw_alignment_removes_a_turn_and_nothing_else() {
        // One frame of a root and two joints; the prediction is the truth turned by 90 degrees
        // about +Y around the root, then moved by 2 in x.
        let truth = [Vec3::new(1.0, 1.0, 0.0), Vec3::new(1.0, 1.0, 1.0), Vec3::new(2.0, 1.5, 0.0)];
        let turn = Quat::from_rotation_y(std::f32::consts::FRAC_PI_2);
        let mut predicted: Vec<Vec3> =
            truth.iter().map(|p| turn * (*p - truth[0]) + truth[0] + Vec3::new(2.0, 0.0, 0.0)).collect();
        // Root-aligned only, both joints are sqrt(2) off in the plane.
        let plain = mpjpe_root_aligned(&predicted, &truth, 3);
        assert!((plain - 2.0 * 2f32.sqrt() / 3.0).abs() < 1e-5, "{plain}");
        assert!(mpjpe_yaw_aligned(&predicted, &truth, 3) < 1e-5);
        // A height error is not a turn, so it stays (the best turn is still the same one).
        predicted[2].y += 1.0;
        let aligned = mpjpe_yaw_aligned(&predicted, &truth, 3);
        assert!((aligned - 1.0 / 3.0).abs() < 1e-5, "{aligned}");
    }

    #[test]
    fn mpjpe_with_and_without_translation() {
        // Two frames of two joints; the prediction is the truth shifted by (3, 4, 0) with the
        // second joint also off by 1 in y in frame 1.
        let truth = [Vec3::ZERO, Vec3::Y, Vec3::X, Vec3::X + Vec3::Y];
        let shift = Vec3::new(3.0, 4.0, 0.0);
        let mut predicted: Vec<Vec3> = truth.iter().map(|p| *p + shift).collect();
        predicted[3].y += 1.0;
        // Distances 5, 5, 5, |(3, 5, 0)| = sqrt(34).
        let expected = (15.0 + 34f32.sqrt()) / 4.0;
        assert!((mpjpe(&predicted, &truth) - expected).abs() < 1e-5);
        // Root-aligned: only the 1 in frame 1 remains, over 4 joint-frames.
        assert!((mpjpe_root_aligned(&predicted, &truth, 2) - 0.25).abs() < 1e-6);
    }

    #[test]
    fn geodesic_distance_in_degrees() {
        let a = [Quat::IDENTITY, Quat::from_rotation_x(0.5)];
        let b = [Quat::from_rotation_y(30f32.to_radians()), Quat::from_rotation_x(0.5)];
        assert!((geodesic_distance_deg(&a, &b) - 15.0).abs() < 1e-3);
    }

    #[test]
    fn joint_kinds_follow_what_each_rotation_moves() {
        use crate::skeleton::rotating_joint as joint;
        // hips -> pelvis (zero offset) -> thigh -> foot (leaf with an end site);
        // hips -> marker (zero offset, leaf).
        let mut joints = vec![
            joint("hips", None, Vec3::ZERO),
            joint("pelvis", Some(0), Vec3::ZERO),
            joint("thigh", Some(1), Vec3::new(0.0, -0.4, 0.0)),
            joint("foot", Some(2), Vec3::new(0.0, -0.4, 0.0)),
            joint("marker", Some(0), Vec3::ZERO),
        ];
        joints[3].end_site = Some(Vec3::new(0.0, 0.0, 0.1));
        let skeleton = Skeleton::new(joints).unwrap();
        use JointKind::*;
        assert_eq!(JointKind::of(&skeleton), [Root, Inner, Inner, Unseen, Unseen]);
        // Two frames; only the foot (frame 0, 30 degrees) and the marker (frame 1, 90) are off.
        let truth = vec![Quat::IDENTITY; 10];
        let mut predicted = truth.clone();
        predicted[3] = Quat::from_rotation_x(30f32.to_radians());
        predicted[9] = Quat::from_rotation_y(90f32.to_radians());
        let sums = geodesic_sums_by_kind(&predicted, &truth, &JointKind::of(&skeleton));
        assert_eq!([sums[0].1, sums[1].1, sums[2].1], [2, 4, 4]);
        assert!(sums[0].0.abs() < 1e-4 && sums[1].0.abs() < 1e-4, "{sums:?}");
        assert!((sums[2].0 - 120.0).abs() < 1e-3, "{sums:?}");
    }

    #[test]
    fn skating_counts_only_grounded_sliding() {
        // One foot, three frames at 10 fps: slides 0.1 on the ground, then lifts off.
        let p = [Vec3::new(0.0, 0.0, 0.0), Vec3::new(0.1, 0.01, 0.0), Vec3::new(0.5, 0.5, 0.0)];
        let fs = foot_skating(&p, 1, &[0], 10.0, 0.02);
        assert!((fs - 1.0).abs() < 1e-5, "{fs}");
        assert_eq!(foot_skating(&p, 1, &[0], 10.0, 0.001), 0.0);
    }

    #[test]
    fn body_turn_is_the_angle_of_the_best_fitting_rotation() {
        let truth = [Vec3::ZERO, Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0), Vec3::new(0.0, 0.0, 2.0)];
        assert!(body_turn_deg(&truth, &truth, 4) < 1e-3);
        for (axis, degrees) in [(Vec3::Y, 140.0f32), (Vec3::X, 40.0), (Vec3::new(1.0, 1.0, 0.0).normalize(), 170.0)] {
            let turn = Quat::from_axis_angle(axis, degrees.to_radians());
            // Shifted too: the root's position does not count.
            let turned: Vec<Vec3> = truth.iter().map(|p| turn * *p + Vec3::new(3.0, 0.0, -1.0)).collect();
            let got = body_turn_deg(&turned, &truth, 4);
            assert!((got - degrees).abs() < 0.01, "{axis} by {degrees}: {got}");
        }
    }

    #[test]
    fn penetration_is_the_mean_depth_below_the_floor() {
        let p = [Vec3::new(0.0, -0.2, 0.0), Vec3::new(0.0, 0.3, 0.0)];
        assert!((ground_penetration(&p) - 0.1).abs() < 1e-6);
    }
}
