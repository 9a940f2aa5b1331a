//! Root anchors: where the root is and which way it faces at a few frames of a clip, kept beside
//! the tokens so that a decoded clip's heading and path cannot drift between them.
//!
//! The features carry the root as rates (yaw rate, planar velocity), which decoding integrates.
//! A small bias in a decoded rate adds up over a long clip: LAFAN1's four-minute clips end up
//! facing the wrong way although every pose is right. Three numbers per window (the heading and
//! planar position at its first frame) bound that error to one window, at no cost to the codes.

use anymo_motion::features::{MotionFeatures, ROOT_DIMS, root_path};
use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

/// The root's heading and planar position at one frame, relative to the clip's first frame (its
/// heading is 0 there and its position the origin), in the features' units.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct RootAnchor {
    /// The frame.
    pub frame: usize,
    /// Heading turned since the first frame, radians, unwrapped (two turns are 4 pi).
    pub heading: f32,
    /// Planar position (x, z) in the first frame's heading frame.
    pub planar: [f32; 2],
}

/// The frames anchored for windows starting at `starts`: each window's first frame and the
/// clip's last frame.
pub fn anchor_frames(starts: &[usize], frames: usize) -> Vec<usize> {
    let mut out: Vec<usize> = starts.iter().copied().filter(|&s| s < frames).collect();
    if frames > 0 {
        out.push(frames - 1);
    }
    out.sort_unstable();
    out.dedup();
    out
}

/// Measures the anchors of a clip's features at `frames` (ascending, inside the clip).
pub fn measure(features: &MotionFeatures, frames: &[usize]) -> Vec<RootAnchor> {
    let path = root_path(features);
    frames
        .iter()
        .map(|&frame| {
            let (heading, planar) = path[frame];
            RootAnchor { frame, heading, planar: [planar.x, planar.z] }
        })
        .collect()
}

/// Corrects decoded features so that integrating them passes through every anchor: between two
/// anchors, each frame's yaw rate is shifted by the same amount so the turn between them is the
/// anchored one, then each frame's planar step by the same vector (in the world frame) so the
/// displacement is too. Frames before the first anchor and after the last are left as decoded.
/// Anchors must be ascending and inside the clip.
pub fn pin(features: &mut MotionFeatures, anchors: &[RootAnchor]) {
    for pair in anchors.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        debug_assert!(a.frame < b.frame && b.frame < features.frames, "anchors ascend inside the clip");
        let turned: f32 = (a.frame..b.frame).map(|f| features.root[f * ROOT_DIMS]).sum();
        let shift = (b.heading - a.heading - turned) / (b.frame - a.frame) as f32;
        (a.frame..b.frame).for_each(|f| features.root[f * ROOT_DIMS] += shift);
    }
    // With the turns right, the headings along the clip are the anchored ones up to the offset
    // at the first anchor (none when it is frame 0, as for every tokenized clip).
    let path = root_path(features);
    let Some(first) = anchors.first() else { return };
    let offset = first.heading - path[first.frame].0;
    for pair in anchors.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        let moved = Quat::from_rotation_y(offset) * (path[b.frame].1 - path[a.frame].1);
        let wanted = Vec3::new(b.planar[0] - a.planar[0], 0.0, b.planar[1] - a.planar[1]);
        let step = (wanted - moved) / (b.frame - a.frame) as f32;
        for (f, &(heading, _)) in path.iter().enumerate().take(b.frame).skip(a.frame) {
            let local = Quat::from_rotation_y(heading + offset).inverse() * step;
            features.root[f * ROOT_DIMS + 1] += local.x;
            features.root[f * ROOT_DIMS + 2] += local.z;
        }
    }
}

/// Why anchors cannot belong to a clip of `frames` frames, if they cannot.
pub fn check(anchors: &[RootAnchor], frames: usize) -> Result<(), String> {
    if anchors.iter().any(|a| a.frame >= frames) {
        return Err(format!("root anchors must lie inside the clip's {frames} frames"));
    }
    if anchors.windows(2).any(|p| p[0].frame >= p[1].frame) {
        return Err("root anchors must be in ascending frame order".into());
    }
    if anchors.iter().any(|a| !(a.heading.is_finite() && a.planar.iter().all(|v| v.is_finite()))) {
        return Err("root anchors must be finite".into());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A clip turning at a steady rate while walking forward, at height 1.
    fn walk(frames: usize, yaw_rate: f32, speed: f32) -> MotionFeatures {
        let root = (0..frames).flat_map(|_| [yaw_rate, 0.0, speed, 1.0]).collect();
        MotionFeatures { frames, joints: 1, root, rotations: vec![0.0; frames * 6] }
    }

    #[test]
    fn anchors_cover_every_window_start_and_the_last_frame() {
        assert_eq!(anchor_frames(&[0, 48, 66], 130), vec![0, 48, 66, 129]);
        assert_eq!(anchor_frames(&[0], 1), vec![0]);
        assert_eq!(anchor_frames(&[0], 40), vec![0, 39]);
    }

    #[test]
    fn a_straight_walk_is_anchored_where_it_went() {
        let anchors = measure(&walk(11, 0.0, 0.5), &[0, 10]);
        assert_eq!(anchors[0], RootAnchor { frame: 0, heading: 0.0, planar: [0.0, 0.0] });
        assert_eq!(anchors[1].heading, 0.0);
        assert!((anchors[1].planar[1] - 5.0).abs() < 1e-6 && anchors[1].planar[0].abs() < 1e-6);
    }

    #[test]
    fn a_quarter_turn_walks_a_quarter_circle() {
        // 100 steps of length 0.01, each turned d = pi/200 more than the last (turning +Y takes
        // +Z towards +X). Step i points along (sin id, cos id), so the walk ends at
        // 0.01 sin(50d) / sin(d/2) * (sin(49.5d), cos(49.5d)): near a quarter circle of radius
        // 2/pi, (0.637, 0.637).
        let d = std::f64::consts::FRAC_PI_2 / 100.0;
        let end = measure(&walk(101, d as f32, 0.01), &[100])[0];
        let chord = 0.01 * (50.0 * d).sin() / (d / 2.0).sin();
        let (x, z) = (chord * (49.5 * d).sin(), chord * (49.5 * d).cos());
        assert!((end.heading as f64 - std::f64::consts::FRAC_PI_2).abs() < 1e-5);
        assert!((end.planar[0] as f64 - x).abs() < 1e-5 && (end.planar[1] as f64 - z).abs() < 1e-5, "{end:?}");
        assert!((x - 2.0 / std::f64::consts::PI).abs() < 6e-3 && (z - 2.0 / std::f64::consts::PI).abs() < 6e-3);
    }

    #[test]
    fn pinning_a_drifting_decode_puts_it_through_the_anchors() {
        let truth = walk(130, 0.02, 0.03);
        let anchors = measure(&truth, &anchor_frames(&[0, 48, 66], 130));
        // The decode turns too slowly, drifts sideways and walks too fast.
        let mut decoded = truth.clone();
        for f in 0..decoded.frames {
            decoded.root[f * ROOT_DIMS] *= 0.8;
            decoded.root[f * ROOT_DIMS + 1] += 0.004;
            decoded.root[f * ROOT_DIMS + 2] *= 1.3;
        }
        let before = measure(&decoded, &[129])[0];
        assert!((before.heading - anchors[3].heading).abs() > 0.4, "the decode drifts: {before:?}");
        pin(&mut decoded, &anchors);
        for (got, want) in measure(&decoded, &[0, 48, 66, 129]).iter().zip(&anchors) {
            assert!((got.heading - want.heading).abs() < 1e-4, "{got:?} against {want:?}");
            assert!((got.planar[0] - want.planar[0]).abs() < 1e-4, "{got:?} against {want:?}");
            assert!((got.planar[1] - want.planar[1]).abs() < 1e-4, "{got:?} against {want:?}");
        }
        // Only the rates moved: the height is as decoded.
        assert!((0..decoded.frames).all(|f| decoded.root[f * ROOT_DIMS + 3] == 1.0));
    }

    #[test]
    fn pinning_the_truth_to_its_own_anchors_changes_nothing() {
        let truth = walk(70, -0.05, 0.02);
        let mut pinned = truth.clone();
        pin(&mut pinned, &measure(&truth, &anchor_frames(&[0, 6], 70)));
        for (a, b) in pinned.root.iter().zip(&truth.root) {
            assert!((a - b).abs() < 1e-6);
        }
    }

    #[test]
    fn anchors_outside_the_clip_or_out_of_order_are_refused() {
        let at = |frame| RootAnchor { frame, heading: 0.0, planar: [0.0, 0.0] };
        assert!(check(&[at(0), at(9)], 10).is_ok());
        assert!(check(&[at(0), at(10)], 10).unwrap_err().contains("inside the clip's 10 frames"));
        assert!(check(&[at(5), at(5)], 10).unwrap_err().contains("ascending"));
        let nan = RootAnchor { frame: 1, heading: f32::NAN, planar: [0.0, 0.0] };
        assert!(check(&[nan], 10).unwrap_err().contains("finite"));
    }
}
