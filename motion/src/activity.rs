//! What a motion does, in figures a prompt's words can be checked against on any rig: how fast
//! and which way the body travels relative to where it faces, how far it turns, whether its feet
//! leave the ground together (running, jumping), how high a foot or a hand gets, and how far the
//! head comes down towards the hips (bowing).
//!
//! Lengths are in diameters of the skeleton and times in seconds, so rigs of any size and frame
//! rate compare. The body's place is the mean of its joints, its facing the direction of its
//! left-to-right axis (see [`crate::reference::facing_angle`]), its parts found by the
//! rule-based joint labels (a head, hands, feet), so a figure a rig has no part for is `None`.

use crate::contact::{find_feet, foot_points, ground_height};
use crate::kinematics::{all_global_transforms, all_joint_positions};
use crate::motion::Motion;
use crate::prep::labels::{JointLabel, Side, label_skeleton};
use crate::quality::CONTACT_HEIGHT;
use crate::reference::facing_angle;
use glam::Vec3;
use std::f32::consts::{PI, TAU};

/// The figures of one motion.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Activity {
    /// Length of the motion, seconds.
    pub seconds: f32,
    /// Mean speed at which the body makes headway along the way it faces (diameters per
    /// second; negative when it goes backwards): the root's motion against the foot it stands
    /// on (the lowest), so a walk looped in place counts as the walk it is and feet gliding
    /// along with the body make none. A rig without feet counts its root's motion.
    pub forward_speed: f32,
    /// The same towards the body's own left (negative towards its right).
    pub leftward_speed: f32,
    /// Net horizontal distance the root covers from the first frame to the last over the
    /// seconds (diameters per second): near zero for waving on the spot or walking in a circle.
    pub travel_speed: f32,
    /// Mean horizontal speed of the feet relative to the root (diameters per second): how much
    /// the legs move at all, whether the body travels or loops in place. `None` without feet.
    pub foot_speed: Option<f32>,
    /// Net turn of the facing, degrees; positive to the left (counter-clockwise seen from above).
    pub turn_degrees: f32,
    /// Share of frames in which every foot is off the ground (by more than [`CONTACT_HEIGHT`]):
    /// runs and jumps have some, walks almost none. `None` without feet.
    pub flight: Option<f32>,
    /// Highest the lowest foot gets above the ground (diameters): a jump's height. `None`
    /// without feet.
    pub jump_height: Option<f32>,
    /// Highest any foot gets above the ground (diameters): a kick or a high step. `None`
    /// without feet.
    pub foot_raise: Option<f32>,
    /// Highest the left hand gets relative to the head (diameters; positive above it). `None`
    /// without a head and a left hand.
    pub left_hand_lift: Option<f32>,
    /// The same for the right hand.
    pub right_hand_lift: Option<f32>,
    /// How far the head's height above the hips drops below its median at the deepest point
    /// (diameters): a bow's depth. `None` without a head.
    pub head_drop: Option<f32>,
}

impl Activity {
    /// The higher of the two hands' lifts (either hand raised), if the rig has a hand.
    pub fn hand_lift(&self) -> Option<f32> {
        match (self.left_hand_lift, self.right_hand_lift) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b),
        }
    }

    /// The lower of the two hands' lifts (both hands raised), if the rig has both.
    pub fn both_hands_lift(&self) -> Option<f32> {
        Some(self.left_hand_lift?.min(self.right_hand_lift?))
    }
}

/// Measures a motion (at least two frames; fewer give all zeros and `None`s).
pub fn measure(motion: &Motion) -> Activity {
    let skeleton = motion.skeleton();
    let (n, frames) = (skeleton.len(), motion.frames());
    if frames < 2 || n == 0 {
        return Activity::default();
    }
    let seconds = ((frames - 1) as f64 * motion.frame_time()) as f32;
    let scale = 1.0 / skeleton.diameter().max(f32::MIN_POSITIVE);
    let positions: Vec<Vec3> = all_joint_positions(motion).into_iter().map(|p| p * scale).collect();
    let pose = |f: usize| &positions[f * n..(f + 1) * n];
    let labels = label_skeleton(skeleton);

    // Feet against the ground they stand on.
    let feet = find_feet(motion);
    let k = feet.len();
    let globals = all_global_transforms(motion);
    let points: Vec<Vec3> = foot_points(motion, &feet, &globals).into_iter().map(|p| p * scale).collect();
    let foot = |f: usize, i: usize| points[f * k + i];
    let ground = if k == 0 { 0.0 } else { ground_height(&points, k) };
    // The foot a frame stands on: its lowest, when that is on the ground.
    let stance = |f: usize| {
        (0..k)
            .min_by(|&a, &b| foot(f, a).y.total_cmp(&foot(f, b).y))
            .filter(|&i| foot(f, i).y - ground < CONTACT_HEIGHT)
    };

    // Headway and turns, in the body's own frame at each step.
    let sides: Vec<Option<Side>> = labels.iter().map(|l| if l.helper { None } else { l.side }).collect();
    let facing: Vec<f32> = (0..frames).map(|f| facing_angle(&sides, pose(f))).collect();
    let (mut forward, mut leftward, mut turn) = (0.0f32, 0.0f32, 0.0f32);
    for f in 1..frames {
        let mut step = pose(f)[0] - pose(f - 1)[0];
        if let Some(i) = stance(f - 1) {
            step -= foot(f, i) - foot(f - 1, i);
        }
        let a = facing[f - 1];
        forward += step.x * a.sin() + step.z * a.cos();
        leftward += step.x * a.cos() - step.z * a.sin();
        turn += wrapped(facing[f] - facing[f - 1]);
    }
    let net = pose(frames - 1)[0] - pose(0)[0];

    let foot_speed = (k > 0).then(|| {
        let moved = (1..frames)
            .flat_map(|f| (0..k).map(move |i| (f, i)))
            .map(|(f, i)| ((foot(f, i) - pose(f)[0]) - (foot(f - 1, i) - pose(f - 1)[0])).with_y(0.0).length())
            .sum::<f32>();
        moved / (k as f32 * seconds)
    });
    let (flight, jump_height, foot_raise) = if feet.is_empty() {
        (None, None, None)
    } else {
        let lowest: Vec<f32> =
            points.chunks(k).map(|p| p.iter().map(|v| v.y).fold(f32::INFINITY, f32::min) - ground).collect();
        let airborne = lowest.iter().filter(|&&h| h > CONTACT_HEIGHT).count() as f32 / frames as f32;
        let highest = points.iter().map(|p| p.y - ground).fold(f32::NEG_INFINITY, f32::max);
        (Some(airborne), Some(lowest.iter().copied().fold(f32::NEG_INFINITY, f32::max)), Some(highest))
    };

    // Head and hands.
    let head = find_part(&labels, "head", None);
    let lift = |side: Side| {
        let (head, hand) = (head?, find_part(&labels, "hand", Some(side))?);
        Some((0..frames).map(|f| pose(f)[hand].y - pose(f)[head].y).fold(f32::NEG_INFINITY, f32::max))
    };
    let head_drop = head.map(|head| {
        let mut above: Vec<f32> = (0..frames).map(|f| pose(f)[head].y - pose(f)[0].y).collect();
        let lowest = above.iter().copied().fold(f32::INFINITY, f32::min);
        above.sort_by(f32::total_cmp);
        above[frames / 2] - lowest
    });

    Activity {
        seconds,
        forward_speed: forward / seconds,
        leftward_speed: leftward / seconds,
        travel_speed: net.x.hypot(net.z) / seconds,
        foot_speed,
        turn_degrees: turn.to_degrees(),
        flight,
        jump_height,
        foot_raise,
        left_hand_lift: lift(Side::Left),
        right_hand_lift: lift(Side::Right),
        head_drop,
    }
}

/// The first joint (not a rig helper) whose label's part is `part` on side `side` (any side
/// when `None`).
fn find_part(labels: &[JointLabel], part: &str, side: Option<Side>) -> Option<usize> {
    labels.iter().position(|l| !l.helper && l.part == part && (side.is_none() || l.side == side))
}

/// An angle difference brought into `(-pi, pi]`.
fn wrapped(angle: f32) -> f32 {
    let a = angle.rem_euclid(TAU);
    if a > PI { a - TAU } else { a }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::parse_str;
    use glam::{EulerRot, Quat};
    use std::f32::consts::FRAC_PI_2;

    /// One frame of [`humanoid`]: the root's place and turn about +Y, both thighs' swing about
    /// +X and the left shoulder's about +Z (radians).
    #[derive(Clone, Copy, Default)]
    struct Frame {
        root: Vec3,
        yaw: f32,
        thighs: f32,
        shoulder: f32,
    }

    fn at(x: f32, y: f32, z: f32) -> Frame {
        Frame { root: Vec3::new(x, y, z), ..Frame::default() }
    }

    /// A small humanoid (hips at 0.95 when standing, soles on the floor, arms hanging, facing
    /// +Z with its left at +X) whose limbs are named `{side}Up{leg}`, `{side}{leg}`,
    /// `{side}{foot}`, for `frames` frames at 30 fps.
    fn humanoid(leg: &str, foot: &str, frames: usize, frame: impl Fn(usize) -> Frame) -> Motion {
        let leg = |s: &str, x: f32| crate::contact::tests::leg_bvh(s, x, leg, foot);
        let arm = |s: &str, x: f32| {
            format!(
                "JOINT {s}Arm\n{{\nOFFSET {x} 0.35 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n\
                 JOINT {s}Hand\n{{\nOFFSET 0 -0.55 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n\
                 End Site\n{{\nOFFSET 0 -0.1 0\n}}\n}}\n}}\n"
            )
        };
        let mut text = format!(
            "HIERARCHY\nROOT Hips\n{{\nOFFSET 0 0.95 0\nCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n\
             {}{}JOINT Spine\n{{\nOFFSET 0 0.3 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n{}{}\
             JOINT Head\n{{\nOFFSET 0 0.4 0\nCHANNELS 3 Zrotation Xrotation Yrotation\nEnd Site\n{{\nOFFSET 0 0.1 0\n}}\n}}\n}}\n}}\n\
             MOTION\nFrames: {frames}\nFrame Time: {}\n",
            leg("Left", 0.1),
            leg("Right", -0.1),
            arm("Left", 0.2),
            arm("Right", -0.2),
            1.0 / 30.0
        );
        for f in 0..frames {
            let Frame { root, yaw, thighs, shoulder } = frame(f);
            let thigh = [0.0, thighs.to_degrees(), 0.0];
            // Channels (Z X Y): root, left leg, right leg, spine, left arm and hand, right arm
            // and hand, head.
            let mut values = vec![root.x, root.y, root.z, 0.0, 0.0, yaw.to_degrees()];
            for _ in 0..2 {
                values.extend(thigh);
                values.extend([0.0; 6]);
            }
            values.extend([0.0; 3]);
            values.extend([shoulder.to_degrees(), 0.0, 0.0]);
            values.extend([0.0; 12]);
            text += &values.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(" ");
            text.push('\n');
        }
        Motion::from_bvh(&parse_str(&text).unwrap())
    }

    #[test]
    fn headway_is_made_against_the_foot_stood_on() {
        // Standing still, both thighs swing back by 0.3 rad over one second: the soles (0.85
        // below the hip and 0.15 ahead of it) slide back, so the body makes headway as on a
        // treadmill, though its root never moves.
        let motion = humanoid("Leg", "Foot", 31, |f| Frame { thighs: 0.3 * f as f32 / 30.0, ..at(0.0, 0.95, 0.0) });
        let d = motion.skeleton().diameter();
        let sole_z = |a: f32| -0.85 * a.sin() + 0.15 * a.cos();
        let a = measure(&motion);
        assert!((a.seconds - 1.0).abs() < 1e-5, "{a:?}");
        assert!((a.forward_speed - (sole_z(0.0) - sole_z(0.3)) / d).abs() < 1e-4, "{a:?}");
        assert!(a.leftward_speed.abs() < 1e-5 && a.travel_speed == 0.0, "{a:?}");
        // Both soles swing the same way, so the legs move as fast as the headway.
        assert!((a.foot_speed.unwrap() - a.forward_speed).abs() < 1e-4, "{a:?}");
        // Gliding with its feet makes no headway, though the root travels.
        let glide = measure(&humanoid("Leg", "Foot", 31, |f| at(0.03 * f as f32, 0.95, 0.0)));
        assert!(glide.forward_speed.abs() < 1e-5 && glide.leftward_speed.abs() < 1e-5, "{glide:?}");
        assert!((glide.travel_speed - 0.9 / d).abs() < 1e-4 && glide.foot_speed.unwrap() < 1e-5, "{glide:?}");
    }

    #[test]
    fn a_rig_without_feet_travels_with_its_root_in_its_own_frame() {
        // Facing +X (yaw +90 degrees) and moving 0.03 a frame along +X: forwards at 0.9 units/s.
        let facing_x = |root: Vec3| Frame { root, yaw: FRAC_PI_2, ..Frame::default() };
        let motion = humanoid("Fin", "Flap", 31, |f| facing_x(Vec3::new(0.03 * f as f32, 0.95, 0.0)));
        let d = motion.skeleton().diameter();
        let a = measure(&motion);
        assert!((a.forward_speed - 0.9 / d).abs() < 1e-4 && a.leftward_speed.abs() < 1e-4, "{a:?}");
        assert!((a.travel_speed - 0.9 / d).abs() < 1e-4 && a.turn_degrees.abs() < 1e-3, "{a:?}");
        // Along -X is backwards; along -Z is to its left (its left is -Z when it faces +X).
        let back = measure(&humanoid("Fin", "Flap", 31, |f| facing_x(Vec3::new(-0.03 * f as f32, 0.95, 0.0))));
        assert!((back.forward_speed + 0.9 / d).abs() < 1e-4, "{back:?}");
        let side = measure(&humanoid("Fin", "Flap", 31, |f| facing_x(Vec3::new(0.0, 0.95, -0.03 * f as f32))));
        assert!((side.leftward_speed - 0.9 / d).abs() < 1e-4 && side.forward_speed.abs() < 1e-4, "{side:?}");
    }

    #[test]
    fn turning_counts_left_as_positive_across_the_half_turn() {
        // Yaw from 0 to 270 degrees in 3-degree steps: three quarter turns to the left, through
        // the wrap at 180.
        let turning =
            |degrees: f32| move |f: usize| Frame { yaw: (degrees * f as f32).to_radians(), ..at(0.0, 0.95, 0.0) };
        let a = measure(&humanoid("Leg", "Foot", 91, turning(3.0)));
        assert!((a.turn_degrees - 270.0).abs() < 0.05, "{a:?}");
        assert!((measure(&humanoid("Leg", "Foot", 31, turning(-2.0))).turn_degrees + 60.0).abs() < 0.05);
        assert!(a.travel_speed < 1e-5, "{a:?}");
    }

    #[test]
    fn a_jump_leaves_the_ground_and_a_standing_body_does_not() {
        // On the floor for 20 frames, then 10 frames raised by 0.3: the lowest foot is 0.3 up in
        // a third of the frames.
        let motion = humanoid("Leg", "Foot", 30, |f| at(0.0, if f < 20 { 0.95 } else { 1.25 }, 0.0));
        let d = motion.skeleton().diameter();
        let a = measure(&motion);
        assert!((a.jump_height.unwrap() - 0.3 / d).abs() < 1e-4, "{a:?}");
        assert!((a.foot_raise.unwrap() - 0.3 / d).abs() < 1e-4, "{a:?}");
        assert!((a.flight.unwrap() - 10.0 / 30.0).abs() < 1e-5, "{a:?}");
        let still = measure(&humanoid("Leg", "Foot", 30, |_| at(0.0, 0.95, 0.0)));
        assert_eq!((still.flight, still.jump_height), (Some(0.0), Some(0.0)), "{still:?}");
        assert_eq!(still.head_drop, Some(0.0));
    }

    #[test]
    fn a_raised_arm_puts_its_hand_over_the_head() {
        // The left arm (shoulder at 0.95 + 0.3 + 0.35 = 1.6) swings up to point straight up
        // (180 degrees about +Z) over 30 frames: its hand joint ends at 1.6 + 0.55 = 2.15, the
        // head joint stays at 0.95 + 0.3 + 0.4 = 1.65.
        let motion = humanoid("Leg", "Foot", 31, |f| Frame { shoulder: PI * f as f32 / 30.0, ..at(0.0, 0.95, 0.0) });
        let d = motion.skeleton().diameter();
        let a = measure(&motion);
        assert!((a.left_hand_lift.unwrap() - 0.5 / d).abs() < 1e-4, "{a:?}");
        // The right hand hangs at 1.6 - 0.55 = 1.05 all along.
        assert!((a.right_hand_lift.unwrap() + 0.6 / d).abs() < 1e-4, "{a:?}");
        assert_eq!(a.hand_lift(), a.left_hand_lift);
        assert_eq!(a.both_hands_lift(), a.right_hand_lift);
    }

    #[test]
    fn a_bow_brings_the_head_down_towards_the_hips() {
        // The spine leans forward to 90 degrees over the second half of the clip: the head
        // (0.4 up the spine) ends level with the spine's base, so its height above the hips
        // drops from 0.7 to 0.3.
        let skeleton = humanoid("Leg", "Foot", 2, |_| at(0.0, 0.95, 0.0)).skeleton().clone();
        let spine = skeleton.find("Spine").unwrap();
        let (mut rotations, mut translations) = (Vec::new(), Vec::new());
        for f in 0..21 {
            let lean = if f < 10 { 0.0 } else { FRAC_PI_2 * (f - 10) as f32 / 10.0 };
            for (j, joint) in skeleton.joints().iter().enumerate() {
                rotations.push(if j == spine {
                    Quat::from_euler(EulerRot::XYZ, lean, 0.0, 0.0)
                } else {
                    Quat::IDENTITY
                });
                translations.push(if j == 0 { Vec3::new(0.0, 0.95, 0.0) } else { joint.offset });
            }
        }
        let bow = Motion::new(skeleton, 1.0 / 30.0, rotations, translations).unwrap();
        let d = bow.skeleton().diameter();
        // The median frame (10) still stands: the drop is the full 0.4.
        let a = measure(&bow);
        assert!((a.head_drop.unwrap() - 0.4 / d).abs() < 1e-4, "{a:?}");
    }

    #[test]
    fn rigs_without_the_parts_have_no_figures_for_them() {
        let a = measure(&humanoid("Fin", "Flap", 3, |_| at(0.0, 0.95, 0.0)));
        assert_eq!((a.flight, a.jump_height, a.foot_raise), (None, None, None));
        assert!(a.hand_lift().is_some() && a.head_drop.is_some(), "{a:?}");
        let legless = measure(&crate::contact::tests::biped("Fin", "Flap"));
        assert_eq!((legless.left_hand_lift, legless.both_hands_lift()), (None, None), "the biped has no arms");
        let one_frame = Motion::rest_pose(crate::contact::tests::biped("Leg", "Foot").skeleton(), 0.1);
        assert_eq!(measure(&one_frame), Activity::default());
    }
}
