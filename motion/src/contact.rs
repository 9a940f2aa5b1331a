//! Feet and when they touch the ground, on any rig.
//!
//! A foot is a leg's two-bone chain (see [`crate::ik`]) with a contact point at its end: the
//! lowest leaf below it (its end site when it has one). Legs are found by the rule-based joint
//! labels (a joint whose label says leg, foot, toe, paw, hoof or heel), so a fish, a snake or a
//! bee has no feet, and a spider has eight. Contacts are read from the motion itself, relative
//! to the ground the clip stands on, so a clip that floats still has its steps found.

use crate::ik::{Ankle, Chain};
use crate::kinematics::{Transform, all_global_transforms};
use crate::motion::Motion;
use crate::prep::labels::label_skeleton;
use crate::skeleton::Skeleton;
use glam::Vec3;

/// Words of a joint label that make it part of a leg.
const LEG_WORDS: [&str; 6] = ["leg", "foot", "toe", "paw", "hoof", "heel"];

/// Feet are the leg ends whose mean height is within this fraction of the diameter of the
/// lowest one's (a human's hands, a horse's raised tail are not feet).
pub const FOOT_BAND: f32 = 0.1;

/// A foot: the chain that moves it and the leaf whose end touches the ground.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Foot {
    /// The hip, knee and ankle that place it.
    pub chain: Chain,
    /// The leaf joint whose end (its end site, or itself) is the contact point.
    pub leaf: usize,
}

impl Foot {
    /// The contact point's global position in a pose.
    pub fn point(&self, skeleton: &Skeleton, globals: &[Transform]) -> Vec3 {
        let leaf = &globals[self.leaf];
        skeleton.joint(self.leaf).end_site.map_or(leaf.translation, |tip| leaf.apply(tip))
    }
}

/// Every frame's contact point of each foot, frame-major (`frames x feet`), in the motion's
/// units, from its global transforms (`frames x joints`).
pub fn foot_points(motion: &Motion, feet: &[Foot], globals: &[Transform]) -> Vec<Vec3> {
    let (skeleton, n) = (motion.skeleton(), motion.skeleton().len());
    (0..motion.frames())
        .flat_map(|f| feet.iter().map(move |foot| foot.point(skeleton, &globals[f * n..(f + 1) * n])))
        .collect()
}

/// The feet of a motion's skeleton, ordered by leaf: the [`leg_ends`] whose mean height over the
/// motion is within [`FOOT_BAND`] of the lowest one's. Empty for a rig without legs.
pub fn find_feet(motion: &Motion) -> Vec<Foot> {
    let skeleton = motion.skeleton();
    if motion.frames() == 0 {
        return Vec::new();
    }
    let globals = all_global_transforms(motion);
    let n = skeleton.len();
    let ends: Vec<(Foot, f32)> = leg_ends(motion)
        .into_iter()
        .map(|foot| {
            let height =
                (0..motion.frames()).map(|f| foot.point(skeleton, &globals[f * n..(f + 1) * n]).y).sum::<f32>()
                    / motion.frames() as f32;
            (foot, height)
        })
        .collect();
    let lowest = ends.iter().map(|f| f.1).fold(f32::INFINITY, f32::min);
    let band = FOOT_BAND * skeleton.diameter();
    ends.into_iter().filter(|f| f.1 <= lowest + band).map(|f| f.0).collect()
}

/// Every leg's end, ordered by leaf, whatever the pose: a leaf below a leg joint with its best
/// chain, and of the leaves sharing a chain (a foot's toes) the lowest in the motion's first
/// frame. Empty for a rig without legs.
pub fn leg_ends(motion: &Motion) -> Vec<Foot> {
    let skeleton = motion.skeleton();
    if motion.frames() == 0 {
        return Vec::new();
    }
    let labels = label_skeleton(skeleton);
    let leggy = |j: usize| !labels[j].helper && labels[j].part.split(' ').any(|w| LEG_WORDS.contains(&w));
    let first = all_global_transforms(&motion.slice(0, 1));
    let mut by_chain: Vec<(Foot, f32)> = Vec::new();
    let in_leg = |leaf: usize| {
        std::iter::successors(Some(leaf), |&j| skeleton.joint(j).parent).take(4).any(|j| j != 0 && leggy(j))
    };
    for leaf in (1..skeleton.len()).filter(|&j| skeleton.is_leaf(j) && !labels[j].helper && in_leg(j)) {
        let Some(chain) = leg_chain(skeleton, leaf, &leggy) else { continue };
        let foot = Foot { chain, leaf };
        let height = foot.point(skeleton, &first).y;
        match by_chain.iter_mut().find(|(f, _)| f.chain == chain) {
            Some(slot) if height < slot.1 => *slot = (foot, height),
            Some(_) => {}
            None => by_chain.push((foot, height)),
        }
    }
    let mut ends: Vec<Foot> = by_chain.into_iter().map(|f| f.0).collect();
    ends.sort_by_key(|f| f.leaf);
    ends
}

/// The two-bone chain that best places a leg leaf: the ankle is the leaf's end site, the leaf,
/// or one of its two nearest ancestors, the hip is a leg joint or a joint with no other child
/// (a quadruped's shoulder; never a pelvis or a body, which would turn the trunk), and of those
/// the chain with the longest bones wins (a human's thigh and shin, not the foot and toe).
fn leg_chain(skeleton: &Skeleton, leaf: usize, leggy: &dyn Fn(usize) -> bool) -> Option<Chain> {
    let parent = |j: usize| skeleton.joint(j).parent;
    let mut candidates = Vec::new();
    if let Some(p) = parent(leaf) {
        candidates.push(Chain::new(skeleton, p, leaf, Ankle::EndSite));
    }
    let mut ankle = Some(leaf);
    for _ in 0..3 {
        let Some(a) = ankle else { break };
        let lower = parent(a);
        let upper = lower.and_then(parent);
        if let (Some(lower), Some(upper)) = (lower, upper) {
            candidates.push(Chain::new(skeleton, upper, lower, Ankle::Joint(a)));
        }
        ankle = lower;
    }
    candidates
        .into_iter()
        .flatten()
        .filter(|c| leggy(c.upper) || skeleton.children(c.upper).count() == 1)
        .map(|c| (c, c.bone_lengths(skeleton).iter().sum::<f32>()))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|c| c.0)
}

/// Thresholds of contact detection, in diameters and seconds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactRule {
    /// A foot lower than this above the clip's ground may be planted.
    pub height: f32,
    /// A foot slower than this (horizontally, diameters per second) may be planted.
    pub speed: f32,
    /// Gaps in a contact of at most this many frames are closed.
    pub bridge: usize,
    /// Contacts shorter than this many frames are dropped.
    pub shortest: usize,
}

impl Default for ContactRule {
    /// Measured on the corpus's real walks: planted feet stay within 0.05 diameters of the floor
    /// and move under 1 diameter per second, and a step lasts at least 3 frames at 30 fps.
    fn default() -> Self {
        ContactRule { height: 0.05, speed: 1.0, bridge: 2, shortest: 3 }
    }
}

/// The ground a clip stands on: the 5th percentile of the lowest foot's height over its frames
/// (`points` is frames x feet contact points). A clip that floats has its ground above zero.
pub fn ground_height(points: &[Vec3], feet: usize) -> f32 {
    if feet == 0 || points.is_empty() {
        return 0.0;
    }
    let mut lowest: Vec<f32> =
        points.chunks(feet).map(|p| p.iter().map(|v| v.y).fold(f32::INFINITY, f32::min)).collect();
    lowest.sort_by(f32::total_cmp);
    lowest[(lowest.len() - 1) * 5 / 100]
}

/// For each foot, for each frame, whether it is planted. `points` is frames x feet contact
/// points in diameters, `ground` the clip's ground height.
pub fn contacts(points: &[Vec3], feet: usize, fps: f32, ground: f32, rule: &ContactRule) -> Vec<Vec<bool>> {
    let frames = points.len().checked_div(feet).unwrap_or(0);
    (0..feet)
        .map(|k| {
            let at = |f: usize| points[f * feet + k];
            let mut planted: Vec<bool> = (0..frames)
                .map(|f| {
                    let (a, b) = (at(f.saturating_sub(1)), at((f + 1).min(frames - 1)));
                    let span = ((f + 1).min(frames - 1) - f.saturating_sub(1)).max(1) as f32;
                    let speed = (b - a).with_y(0.0).length() * fps / span;
                    at(f).y - ground <= rule.height && speed <= rule.speed
                })
                .collect();
            close_gaps(&mut planted, rule.bridge);
            drop_short(&mut planted, rule.shortest);
            planted
        })
        .collect()
}

/// The runs of `true` in `flags`, as `start..end` ranges.
pub fn runs(flags: &[bool]) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut start = None;
    for (f, &on) in flags.iter().chain(std::iter::once(&false)).enumerate() {
        match (on, start) {
            (true, None) => start = Some(f),
            (false, Some(s)) => {
                out.push(s..f);
                start = None;
            }
            _ => {}
        }
    }
    out
}

fn close_gaps(flags: &mut [bool], bridge: usize) {
    let found = runs(flags);
    for pair in found.windows(2) {
        if pair[1].start - pair[0].end <= bridge {
            flags[pair[0].end..pair[1].start].fill(true);
        }
    }
}

fn drop_short(flags: &mut [bool], shortest: usize) {
    for run in runs(flags) {
        if run.len() < shortest {
            flags[run].fill(false);
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::bvh::parse_str;

    /// The BVH text of one leg hanging from the hips at `x`: thigh `{side}Up{leg}`, shin
    /// `{side}{leg}` and foot `{side}{foot}` with a toe end site, soles 0.95 below the hips.
    pub(crate) fn leg_bvh(side: &str, x: f32, leg: &str, foot: &str) -> String {
        format!(
            "JOINT {side}Up{leg}\n{{\nOFFSET {x} -0.1 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n\
             JOINT {side}{leg}\n{{\nOFFSET 0 -0.4 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n\
             JOINT {side}{foot}\n{{\nOFFSET 0 -0.4 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n\
             End Site\n{{\nOFFSET 0 -0.05 0.15\n}}\n}}\n}}\n}}\n"
        )
    }

    /// A biped standing for two frames: hips, two legs of thigh, shin and foot (with a toe end
    /// site), a spine and a head; `{leg}` and `{foot}` name the leg and foot joints.
    pub(crate) fn biped(leg: &str, foot: &str) -> Motion {
        let side = |s: &str, x: f32| leg_bvh(s, x, leg, foot);
        // The root's position channels replace its offset.
        let frame = format!("0 0.95 0 {}", ["0"; 27].join(" "));
        let text = format!(
            "HIERARCHY\nROOT Hips\n{{\nOFFSET 0 0.95 0\nCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n\
             {}{}JOINT Spine\n{{\nOFFSET 0 0.3 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n\
             JOINT Head\n{{\nOFFSET 0 0.4 0\nCHANNELS 3 Zrotation Xrotation Yrotation\nEnd Site\n{{\nOFFSET 0 0.1 0\n}}\n}}\n}}\n}}\n\
             MOTION\nFrames: 2\nFrame Time: 0.1\n{}\n{}\n",
            side("Left", 0.1),
            side("Right", -0.1),
            frame,
            frame
        );
        Motion::from_bvh(&parse_str(&text).unwrap())
    }

    #[test]
    fn a_biped_has_two_feet_placed_by_thigh_and_shin_and_a_rig_without_legs_has_none() {
        let motion = biped("Leg", "Foot");
        let skeleton = motion.skeleton();
        let feet = find_feet(&motion);
        let named = |j: usize| skeleton.joint(j).name.as_str();
        let chains: Vec<[&str; 3]> = feet
            .iter()
            .map(|f| {
                let Ankle::Joint(ankle) = f.chain.ankle else { panic!("{f:?}") };
                [named(f.chain.upper), named(f.chain.lower), named(ankle)]
            })
            .collect();
        assert_eq!(chains, [["LeftUpLeg", "LeftLeg", "LeftFoot"], ["RightUpLeg", "RightLeg", "RightFoot"]]);
        assert_eq!(feet.iter().map(|f| named(f.leaf)).collect::<Vec<_>>(), ["LeftFoot", "RightFoot"]);
        // The contact point is the toe's end site: 0.95 - 0.1 - 0.4 - 0.4 - 0.05 = 0 above the floor.
        let globals = all_global_transforms(&motion);
        assert!(feet[0].point(skeleton, &globals[..skeleton.len()]).y.abs() < 1e-6);
        assert!(find_feet(&biped("Fin", "Flap")).is_empty(), "fins are not legs");
    }

    #[test]
    fn contacts_need_low_and_slow_and_close_short_gaps() {
        // One foot at 10 fps: planted (frames 0-4) with a one-frame blip up at 2, then swinging.
        let heights = [0.0, 0.01, 0.2, 0.01, 0.0, 0.3, 0.3, 0.0];
        let xs = [0.0, 0.0, 0.0, 0.0, 0.0, 0.5, 1.0, 1.0];
        let points: Vec<Vec3> = heights.iter().zip(xs).map(|(&y, x)| Vec3::new(x, y, 0.0)).collect();
        let rule = ContactRule { height: 0.05, speed: 1.0, bridge: 1, shortest: 2 };
        let planted = contacts(&points, 1, 10.0, 0.0, &rule);
        // Frame 7 is low but alone (and still moving into place at frame 6): dropped as too short.
        assert_eq!(planted[0], [true, true, true, true, false, false, false, false]);
        // A clip floating 0.1 above its ground finds the same steps against that ground.
        let floating: Vec<Vec3> = points.iter().map(|p| *p + Vec3::Y * 0.1).collect();
        assert_eq!(contacts(&floating, 1, 10.0, 0.1, &rule), planted);
        assert!((ground_height(&floating, 1) - 0.1).abs() < 1e-6);
        assert_eq!(runs(&[false, true, true, false, true]), [1..3, 4..5]);
    }
}
