//! How plausible a motion looks, in numbers a user can check against real clips: feet that
//! slide, float or sink, and joints that shake or jump. All lengths are in diameters of the
//! skeleton, so rigs of any size compare; the floor is y = 0.

use crate::contact::{find_feet, foot_points, ground_height};
use crate::kinematics::{all_global_transforms, all_joint_positions};
use crate::metrics::{foot_skating, ground_penetration};
use crate::motion::Motion;
use glam::Vec3;

/// A foot within this height of the floor (diameters) in two frames running is on the ground
/// for [`Quality::foot_skating`] (the height anymo's evaluations use).
pub const CONTACT_HEIGHT: f32 = 0.05;

/// The frame rate [`Quality::max_step`] is stated at.
pub const STEP_FPS: f32 = 30.0;

/// The plausibility figures of one motion.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quality {
    /// The feet found ([`crate::contact::find_feet`]); 0 for a rig without legs.
    pub feet: usize,
    /// Mean horizontal speed of feet on the ground (diameters per second); `None` without feet.
    pub foot_skating: Option<f32>,
    /// Mean height of the lowest foot above the floor (diameters); `None` without feet. A walk
    /// that floats has a high one.
    pub foot_flight: Option<f32>,
    /// Where the feet meet the ground: the 5th percentile of the lowest foot's height
    /// (diameters; see [`crate::contact::ground_height`]). Near 0 for soles; a rig whose leg ends
    /// are hocks stands them higher. `None` without feet.
    pub foot_ground: Option<f32>,
    /// Mean depth of joints below the floor (diameters).
    pub ground_penetration: f32,
    /// Mean joint acceleration (diameters per second squared): shaking shows here.
    pub jitter: f32,
    /// The largest distance one joint moves between two frames, stated at 30 fps (diameters).
    pub max_step: f32,
    /// Mean height of the body's centre (the mean of its joints) above the floor (diameters):
    /// posture shows here (a dog on its hind legs carries its body high, a lying one low).
    pub body_height: f32,
}

/// Measures a motion (at least three frames give a jitter; fewer give zero).
pub fn measure(motion: &Motion) -> Quality {
    let skeleton = motion.skeleton();
    let (n, frames, fps) = (skeleton.len(), motion.frames(), motion.fps() as f32);
    let scale = 1.0 / skeleton.diameter().max(f32::MIN_POSITIVE);
    let positions: Vec<Vec3> = all_joint_positions(motion).into_iter().map(|p| p * scale).collect();
    let feet = find_feet(motion);
    let (foot_skating, foot_flight, foot_ground) = if feet.is_empty() {
        (None, None, None)
    } else {
        let globals = all_global_transforms(motion);
        let points: Vec<Vec3> = foot_points(motion, &feet, &globals).into_iter().map(|p| p * scale).collect();
        let k = feet.len();
        let all: Vec<usize> = (0..k).collect();
        let flight =
            points.chunks(k).map(|p| p.iter().map(|v| v.y).fold(f32::INFINITY, f32::min).max(0.0)).sum::<f32>()
                / frames.max(1) as f32;
        let ground = ground_height(&points, k);
        (Some(foot_skating(&points, k, &all, fps, CONTACT_HEIGHT)), Some(flight), Some(ground))
    };
    let at = |f: usize, j: usize| positions[f * n + j];
    let accelerations = (1..frames.saturating_sub(1))
        .flat_map(|f| (0..n).map(move |j| (at(f + 1, j) - 2.0 * at(f, j) + at(f - 1, j)).length() * fps * fps));
    let count = frames.saturating_sub(2) * n;
    let jitter = if count == 0 { 0.0 } else { accelerations.map(f64::from).sum::<f64>() as f32 / count as f32 };
    let max_step =
        (1..frames).flat_map(|f| (0..n).map(move |j| at(f, j).distance(at(f - 1, j)))).fold(0.0f32, f32::max) * fps
            / STEP_FPS;
    let body_height = positions.iter().map(|p| p.y).sum::<f32>() / positions.len().max(1) as f32;
    Quality {
        feet: feet.len(),
        foot_skating,
        foot_flight,
        foot_ground,
        ground_penetration: ground_penetration(&positions),
        jitter,
        max_step,
        body_height,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::tests::biped;
    use glam::Quat;

    /// The biped's root moved by `path(frame)` for `frames` frames at `fps`.
    fn moved(frames: usize, fps: f64, path: impl Fn(usize) -> Vec3) -> Motion {
        let (skeleton, _, _, _) = biped("Leg", "Foot").into_parts();
        let n = skeleton.len();
        let mut translations = Vec::new();
        for f in 0..frames {
            for j in 0..n {
                translations.push(if j == 0 { path(f) } else { skeleton.joint(j).offset });
            }
        }
        Motion::new(skeleton, 1.0 / fps, vec![Quat::IDENTITY; frames * n], translations).unwrap()
    }

    #[test]
    fn a_steady_glide_has_no_jitter_and_skates_at_its_speed() {
        // Feet on the floor (toe tips at y = 0), the body gliding 0.01 units a frame at 30 fps.
        let motion = moved(10, 30.0, |f| Vec3::new(0.0, 0.95, 0.01 * f as f32));
        let d = motion.skeleton().diameter();
        let q = measure(&motion);
        assert!(q.jitter < 1e-3, "{q:?}");
        assert!((q.foot_skating.unwrap() - 0.3 / d).abs() < 1e-4, "{q:?}");
        assert!(q.foot_flight.unwrap() < 1e-6 && q.ground_penetration == 0.0, "{q:?}");
        assert!(q.foot_ground.unwrap().abs() < 1e-6, "{q:?}");
        assert!((q.max_step - 0.01 / d).abs() < 1e-5, "{q:?}");
        // The nine joints' mean height: hips 0.95, legs 0.85, 0.45, 0.05 (twice), spine 1.25, head 1.65.
        let centre = (0.95 + 2.0 * (0.85 + 0.45 + 0.05) + 1.25 + 1.65) / 9.0;
        assert!((q.body_height - centre / d).abs() < 1e-4, "{q:?}");
    }

    #[test]
    fn floating_shaking_and_sinking_show() {
        // Raised 0.2 and shaking by 0.02 every other frame at 60 fps.
        let motion = moved(11, 60.0, |f| Vec3::new(0.0, 1.15 + if f % 2 == 0 { 0.02 } else { 0.0 }, 0.0));
        let d = motion.skeleton().diameter();
        let q = measure(&motion);
        // Every joint accelerates by 0.04 units per frame squared.
        assert!((q.jitter - 0.04 * 3600.0 / d).abs() < 1e-2, "{q:?}");
        // The step is stated at 30 fps: 0.02 in a 60 fps frame is 0.04 in a 30 fps one.
        assert!((q.max_step - 0.04 / d).abs() < 1e-5, "{q:?}");
        assert!((q.foot_flight.unwrap() - (0.2 + 0.02 * 6.0 / 11.0) / d).abs() < 1e-4, "{q:?}");
        assert!((q.foot_ground.unwrap() - 0.2 / d).abs() < 1e-4, "the lowest frames: {q:?}");
        assert_eq!(q.foot_skating, Some(0.0), "never near the floor");
        // Sunk 0.1: the ankles go below the floor.
        let sunk = measure(&moved(3, 30.0, |_| Vec3::new(0.0, 0.85, 0.0)));
        assert!(sunk.ground_penetration > 0.0 && sunk.foot_flight == Some(0.0), "{sunk:?}");
        assert_eq!(measure(&biped("Fin", "Flap")).foot_skating, None);
        assert_eq!((measure(&biped("Fin", "Flap")).feet, sunk.feet), (0, 2));
    }
}
