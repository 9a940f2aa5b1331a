//! Synthetic skeleton variants for OwO pretraining. The corpus holds only a few dozen distinct
//! topologies; these make more that stay anatomically plausible: limb chains dropped or
//! duplicated, bones rescaled, and joints renamed in other rigs' conventions.

use anymo_motion::prep::labels::{Side, label_name};
use anymo_motion::skeleton::{Joint, Skeleton};
use glam::Quat;
use rand::Rng;

/// Naming conventions of common rigs, for renaming.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Convention {
    /// `LeftUpperLeg`, `Spine2`.
    Camel,
    /// `UpperLeg.L`, `Spine2`.
    Blender,
    /// `upper_leg_l`.
    Snake,
    /// `mixamorig:LeftUpperLeg`.
    Mixamo,
    /// `CC_Base_L_UpperLeg`.
    CharacterCreator,
}

impl Convention {
    /// Every convention.
    pub const ALL: [Convention; 5] =
        [Convention::Camel, Convention::Blender, Convention::Snake, Convention::Mixamo, Convention::CharacterCreator];

    /// The name of a joint with this label in this convention.
    pub fn name(self, side: Option<Side>, part: &str, segment: Option<u32>) -> String {
        let words: Vec<&str> = part.split_whitespace().collect();
        let camel: String = words.iter().map(|w| capitalise(w)).collect();
        let (long, short) = match side {
            Some(Side::Left) => ("Left", "L"),
            Some(Side::Right) => ("Right", "R"),
            None => ("", ""),
        };
        let seg = segment.map(|s| s.to_string()).unwrap_or_default();
        match self {
            Convention::Camel => format!("{long}{camel}{seg}"),
            Convention::Blender => {
                let side = if short.is_empty() { String::new() } else { format!(".{short}") };
                format!("{camel}{side}{seg}")
            }
            Convention::Snake => {
                let mut name = words.join("_");
                if !seg.is_empty() {
                    name.push_str(&seg);
                }
                if !short.is_empty() {
                    name.push('_');
                    name.push_str(&short.to_ascii_lowercase());
                }
                name
            }
            Convention::Mixamo => format!("mixamorig:{long}{camel}{seg}"),
            Convention::CharacterCreator => {
                let side = if short.is_empty() { String::new() } else { format!("{short}_") };
                format!("CC_Base_{side}{camel}{seg}")
            }
        }
    }
}

fn capitalise(word: &str) -> String {
    let mut c = word.chars();
    match c.next() {
        Some(f) => f.to_uppercase().chain(c).collect(),
        None => String::new(),
    }
}

/// Renames every joint in `convention`, keeping names unique.
pub fn rename(skeleton: &Skeleton, convention: Convention) -> Skeleton {
    let mut seen = std::collections::HashSet::new();
    let joints = skeleton
        .joints()
        .iter()
        .map(|j| {
            let label = label_name(&j.name);
            let mut name = convention.name(label.side, &label.part, label.segment);
            let mut k = 2;
            while name.is_empty() || !seen.insert(name.clone()) {
                name = format!("{}{k}", convention.name(label.side, &label.part, label.segment));
                k += 1;
            }
            Joint { name, ..j.clone() }
        })
        .collect();
    Skeleton::new(joints).expect("renaming keeps the tree")
}

/// The joints of the subtree rooted at `joint` (a contiguous range in depth-first order).
fn subtree(skeleton: &Skeleton, joint: usize) -> std::ops::Range<usize> {
    let mut end = joint + 1;
    let depth = skeleton.depths();
    while end < skeleton.len() && depth[end] > depth[joint] {
        end += 1;
    }
    joint..end
}

/// Removes the subtree rooted at `joint` (not the root).
pub fn drop_subtree(skeleton: &Skeleton, joint: usize) -> Skeleton {
    assert!(joint > 0, "the root cannot be dropped");
    let gone = subtree(skeleton, joint);
    let remap = |i: usize| if i >= gone.end { i - gone.len() } else { i };
    let joints = skeleton
        .joints()
        .iter()
        .enumerate()
        .filter(|(i, _)| !gone.contains(i))
        .map(|(_, j)| Joint { parent: j.parent.map(remap), ..j.clone() })
        .collect();
    Skeleton::new(joints).expect("dropping a subtree keeps a tree")
}

/// Copies the subtree rooted at `joint` (not the root) beside itself, turned by `angle` about the
/// up axis, with names suffixed by `suffix`.
pub fn duplicate_subtree(skeleton: &Skeleton, joint: usize, angle: f32, suffix: &str) -> Skeleton {
    assert!(joint > 0, "the root cannot be duplicated");
    let range = subtree(skeleton, joint);
    let turn = Quat::from_rotation_y(angle);
    let mut joints: Vec<Joint> = skeleton.joints()[..range.end].to_vec();
    let shift = range.len();
    for (k, j) in skeleton.joints()[range.clone()].iter().enumerate() {
        let parent = if k == 0 { j.parent } else { j.parent.map(|p| p + shift) };
        joints.push(Joint {
            name: format!("{}{suffix}", j.name),
            parent,
            offset: turn * j.offset,
            end_site: j.end_site.map(|e| turn * e),
            channels: j.channels.clone(),
        });
    }
    for j in &skeleton.joints()[range.end..] {
        joints.push(Joint { parent: j.parent.map(|p| if p >= range.end { p + shift } else { p }), ..j.clone() });
    }
    Skeleton::new(joints).expect("duplicating a subtree keeps a tree")
}

/// Scales every bone by its own factor from `[1 - spread, 1 + spread]`.
pub fn rescale_bones(skeleton: &Skeleton, spread: f32, rng: &mut impl Rng) -> Skeleton {
    let joints = skeleton
        .joints()
        .iter()
        .map(|j| {
            let f = rng.random_range(1.0 - spread..=1.0 + spread);
            Joint { offset: j.offset * f, end_site: j.end_site.map(|e| e * f), ..j.clone() }
        })
        .collect();
    Skeleton::new(joints).expect("scaling keeps the tree")
}

/// A random variant: maybe a chain dropped or duplicated, bones rescaled, maybe renamed.
pub fn random_variant(skeleton: &Skeleton, rng: &mut impl Rng) -> Skeleton {
    let mut s = skeleton.clone();
    let candidates: Vec<usize> = (1..s.len()).filter(|&j| subtree(&s, j).len() <= s.len() / 3).collect();
    if !candidates.is_empty() && s.len() > 4 {
        let joint = candidates[rng.random_range(0..candidates.len())];
        match rng.random_range(0..3) {
            0 => s = drop_subtree(&s, joint),
            1 => s = duplicate_subtree(&s, joint, rng.random_range(-1.2..1.2f32), "Extra"),
            _ => {}
        }
    }
    s = rescale_bones(&s, 0.3, rng);
    if rng.random_bool(0.5) {
        s = rename(&s, Convention::ALL[rng.random_range(0..Convention::ALL.len())]);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use anymo_motion::bvh::parse_str;
    use anymo_motion::motion::Motion;
    use glam::Vec3;

    fn skeleton() -> Skeleton {
        let text = "HIERARCHY\nROOT Hips\n{\n OFFSET 0 1 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n \
            JOINT LeftUpLeg\n {\n  OFFSET 0.2 0 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  JOINT LeftLeg\n  {\n   OFFSET 0 -0.5 0\n   CHANNELS 3 Zrotation Xrotation Yrotation\n   End Site\n   {\n    OFFSET 0 -0.5 0\n   }\n  }\n }\n \
            JOINT Spine1\n {\n  OFFSET 0 0.3 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 0.3 0\n  }\n }\n}\nMOTION\nFrames: 0\nFrame Time: 0.0333333\n";
        Motion::from_bvh(&parse_str(text).unwrap()).skeleton().clone()
    }

    #[test]
    fn renaming_keeps_labels() {
        let s = skeleton();
        for c in Convention::ALL {
            let r = rename(&s, c);
            for (a, b) in s.joints().iter().zip(r.joints()) {
                assert_eq!(label_name(&a.name).text(), label_name(&b.name).text(), "{c:?}: {} vs {}", a.name, b.name);
            }
        }
        assert_eq!(rename(&s, Convention::Blender).joint(1).name, "UpperLeg.L");
        assert_eq!(rename(&s, Convention::Mixamo).joint(3).name, "mixamorig:Spine1");
    }

    #[test]
    fn chains_drop_and_duplicate_in_depth_first_order() {
        let s = skeleton();
        let dropped = drop_subtree(&s, 1);
        assert_eq!(dropped.joints().iter().map(|j| j.name.as_str()).collect::<Vec<_>>(), ["Hips", "Spine1"]);
        assert_eq!(dropped.joint(1).parent, Some(0));
        let twice = duplicate_subtree(&s, 1, std::f32::consts::PI, "Extra");
        let names: Vec<&str> = twice.joints().iter().map(|j| j.name.as_str()).collect();
        assert_eq!(names, ["Hips", "LeftUpLeg", "LeftLeg", "LeftUpLegExtra", "LeftLegExtra", "Spine1"]);
        assert_eq!(twice.joint(4).parent, Some(3));
        assert_eq!(twice.joint(5).parent, Some(0));
        assert!((twice.joint(3).offset - Vec3::new(-0.2, 0.0, 0.0)).length() < 1e-6);
    }
}
