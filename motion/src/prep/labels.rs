//! Semantic joint labels by rule (SATA C.3 without an external model): strip rig prefixes, find
//! the side, split the name into words, map anatomical synonyms across humans and animals to one
//! vocabulary, and drop numeric suffixes. `mixamorig:LeftUpLeg`, `CC_Base_L_Thigh` and
//! `UpperLeg.L` all become "left upper leg"; `Spine1` and `Spine2` become "spine segment".

use crate::skeleton::Skeleton;
use std::fmt;

/// The side of the body a joint is on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Side {
    /// The subject's left.
    Left,
    /// The subject's right.
    Right,
}

impl Side {
    /// The other side.
    pub fn mirrored(self) -> Side {
        match self {
            Side::Left => Side::Right,
            Side::Right => Side::Left,
        }
    }
}

/// A joint's semantic label.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct JointLabel {
    /// Left or right, when the name says so.
    pub side: Option<Side>,
    /// The body part in the shared vocabulary ("upper leg", "tail", "front foot").
    pub part: String,
    /// The numeric suffix of a chain segment (`Tail3` -> 3), when there is one.
    pub segment: Option<u32>,
    /// True for rig helpers that carry no anatomy (IK and pole targets, props, dummy roots).
    pub helper: bool,
}

impl JointLabel {
    /// The label as a short phrase for the sentence encoder, e.g. "left ear segment".
    pub fn text(&self) -> String {
        let mut out = String::new();
        if let Some(side) = self.side {
            out.push_str(if side == Side::Left { "left " } else { "right " });
        }
        out.push_str(&self.part);
        if self.segment.is_some() {
            out.push_str(" segment");
        }
        out
    }
}

impl fmt::Display for JointLabel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text())
    }
}

/// Rig prefixes that say which tool exported the file, not what the joint is.
const PREFIXES: [&str; 10] =
    ["mixamorig:", "mixamorig_", "cc_base_", "rl_", "bip01_", "bip01 ", "def-", "org-", "character1_", "joint_"];

/// Word synonyms mapped to the shared vocabulary; words not listed are kept as they are.
const SYNONYMS: &[(&str, &str)] = &[
    ("hip", "pelvis"),
    ("hips", "pelvis"),
    ("waist", "pelvis"),
    ("pelvis", "pelvis"),
    ("torso", "spine"),
    ("body", "spine"),
    ("thorax", "chest"),
    ("ribs", "chest"),
    ("clavicle", "shoulder"),
    ("collar", "shoulder"),
    ("shoulders", "shoulder"),
    ("upperarm", "upper arm"),
    ("uparm", "upper arm"),
    ("humerus", "upper arm"),
    ("forearm", "forearm"),
    ("lowerarm", "forearm"),
    ("palm", "hand"),
    ("fist", "hand"),
    ("wrist", "hand"),
    ("thigh", "upper leg"),
    ("upleg", "upper leg"),
    ("upperleg", "upper leg"),
    ("femur", "upper leg"),
    ("calf", "lower leg"),
    ("shin", "lower leg"),
    ("lowerleg", "lower leg"),
    ("lowleg", "lower leg"),
    ("knee", "lower leg"),
    ("ankle", "foot"),
    ("toes", "toe"),
    ("toebase", "toe"),
    ("pinky", "little finger"),
    ("little", "little finger"),
    ("ring", "ring finger"),
    ("index", "index finger"),
    ("thumb", "thumb"),
    ("fingers", "finger"),
    ("eyebrow", "brow"),
    ("jawroot", "jaw"),
    ("upperjaw", "upper jaw"),
    ("lowermouth", "jaw"),
    ("teeth", "teeth"),
    ("flipper", "fin"),
    ("sting", "stinger"),
    ("gun", "prop"),
    ("weapon", "prop"),
    ("virtualroot", "root"),
    ("boneroot", "root"),
    ("main", "body"),
];

/// Words that mark a rig helper rather than a body part.
const HELPER_WORDS: [&str; 7] = ["ik", "pole", "poletarget", "target", "pt", "prop", "root"];

/// Splits a name into lower-case words at separators, case changes (`IKFrontLeg` -> ik, front,
/// leg) and digit runs.
fn words(name: &str) -> Vec<String> {
    let chars: Vec<char> = name.chars().collect();
    let mut out: Vec<String> = Vec::new();
    let mut current = String::new();
    for (i, &c) in chars.iter().enumerate() {
        let boundary = i > 0 && {
            let p = chars[i - 1];
            let next_lower = chars.get(i + 1).is_some_and(|n| n.is_lowercase());
            !c.is_alphanumeric()
                || (c.is_ascii_digit() != p.is_ascii_digit())
                || (c.is_uppercase() && p.is_lowercase())
                || (c.is_uppercase() && p.is_uppercase() && next_lower)
        };
        if boundary && !current.is_empty() {
            out.push(std::mem::take(&mut current));
        }
        if c.is_alphanumeric() {
            current.extend(c.to_lowercase());
        }
    }
    if !current.is_empty() {
        out.push(current);
    }
    out
}

/// Takes the side off a name: `.L`, `_R`, ` l`, `Left...`, `L_...`, `LThumb`, and so on.
fn split_side(name: &str) -> (Option<Side>, String) {
    let side_of = |s: &str| match s.to_ascii_lowercase().as_str() {
        "l" | "left" | "lft" => Some(Side::Left),
        "r" | "right" | "rgt" => Some(Side::Right),
        _ => None,
    };
    // Suffix after a separator: Foot.L, Foot_r, Foot Left.
    if let Some(pos) = name.rfind(['.', '_', '-', ' '])
        && let Some(side) = side_of(&name[pos + 1..])
    {
        return (Some(side), name[..pos].to_string());
    }
    // Prefix before a separator: L_Foot, r.foot.
    if let Some(pos) = name.find(['.', '_', '-', ' '])
        && let Some(side) = side_of(&name[..pos])
    {
        return (Some(side), name[pos + 1..].to_string());
    }
    // Camel-case prefix: LeftUpLeg, RightHand, LThumb, RHipJoint.
    for (prefix, side) in [("Left", Side::Left), ("Right", Side::Right), ("L", Side::Left), ("R", Side::Right)] {
        if let Some(rest) = name.strip_prefix(prefix)
            && rest.chars().next().is_some_and(char::is_uppercase)
        {
            return (Some(side), rest.to_string());
        }
    }
    // A whole word anywhere: Shoulder Left Twist.
    let ws = words(name);
    if let Some(i) = ws.iter().position(|w| matches!(w.as_str(), "left" | "right")) {
        let side = side_of(&ws[i]);
        let rest: Vec<&str> = ws.iter().enumerate().filter(|(j, _)| *j != i).map(|(_, w)| w.as_str()).collect();
        return (side, rest.join("_"));
    }
    (None, name.to_string())
}

/// Labels one joint name.
pub fn label_name(name: &str) -> JointLabel {
    let mut base = name.trim();
    // Blender's duplicate suffix (`FrontLeg.L.001`).
    if let Some(pos) = base.rfind('.')
        && base.len() - pos == 4
        && base[pos + 1..].bytes().all(|b| b.is_ascii_digit())
    {
        base = &base[..pos];
    }
    let lower = base.to_ascii_lowercase();
    let mut stripped = base;
    for prefix in PREFIXES {
        if lower.starts_with(prefix) && lower.len() > prefix.len() {
            stripped = &base[prefix.len()..];
            break;
        }
    }
    let (side, rest) = split_side(stripped);
    let mut parts: Vec<String> = Vec::new();
    let mut segment = None;
    let ws = words(&rest);
    for (i, w) in ws.iter().enumerate() {
        if w.bytes().all(|b| b.is_ascii_digit()) {
            if i == ws.len() - 1 {
                segment = w.parse().ok();
            }
            continue;
        }
        let mapped = SYNONYMS.iter().find(|(from, _)| from == w).map_or(w.as_str(), |(_, to)| to);
        // Join "up leg" / "low arm" style pairs into their synonym.
        if let Some(prev) = parts.last() {
            let joined = format!("{prev}{w}");
            if let Some((_, to)) = SYNONYMS.iter().find(|(from, _)| *from == joined) {
                *parts.last_mut().expect("checked above") = (*to).to_string();
                continue;
            }
        }
        parts.push(mapped.to_string());
    }
    let helper = parts.iter().any(|p| HELPER_WORDS.contains(&p.as_str()));
    let part = if parts.is_empty() { "joint".to_string() } else { parts.join(" ") };
    JointLabel { side, part, segment, helper }
}

/// Labels every joint of a skeleton.
pub fn label_skeleton(skeleton: &Skeleton) -> Vec<JointLabel> {
    skeleton.joints().iter().map(|j| label_name(&j.name)).collect()
}

/// For every joint, the joint on the other side with the same label (itself for central joints
/// or joints without a partner), so left and right can be swapped.
pub fn mirror_pairs(labels: &[JointLabel]) -> Vec<usize> {
    (0..labels.len())
        .map(|i| {
            let Some(side) = labels[i].side else { return i };
            let want = JointLabel { side: Some(side.mirrored()), ..labels[i].clone() };
            labels.iter().position(|l| *l == want).unwrap_or(i)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn human_conventions_agree() {
        for name in ["mixamorig:LeftUpLeg", "CC_Base_L_Thigh", "UpperLeg.L", "UpperLeg_L", "LeftUpLeg", "l_thigh"] {
            assert_eq!(label_name(name).text(), "left upper leg", "{name}");
        }
        assert_eq!(label_name("RightForeArm").text(), "right forearm");
        assert_eq!(label_name("LowerArm_R").text(), "right forearm");
        assert_eq!(label_name("RThumb").text(), "right thumb");
        assert_eq!(label_name("LowerBack").text(), "lower back");
    }

    #[test]
    fn numeric_suffixes_become_segments() {
        let a = label_name("Spine1");
        let b = label_name("Spine2");
        assert_eq!(a.text(), "spine segment");
        assert_eq!((a.segment, b.segment), (Some(1), Some(2)));
        assert_eq!(label_name("Ear3.L").text(), "left ear segment");
        assert_eq!(label_name("CC_Base_R_UpperarmTwist02").text(), "right upper arm twist segment");
    }

    #[test]
    fn animal_parts_keep_their_qualifiers() {
        assert_eq!(label_name("FrontUpperLeg.R").text(), "right front upper leg");
        assert_eq!(label_name("BackLowLeg.L").text(), "left back lower leg");
        assert_eq!(label_name("FrontLeg.L.001").text(), "left front leg");
        assert_eq!(label_name("TopFlipper.R").text(), "right top fin");
        assert_eq!(label_name("Tail7").text(), "tail segment");
    }

    #[test]
    fn helpers_are_marked() {
        assert!(label_name("PoleTarget.L").helper);
        assert!(label_name("IKFrontLeg.R").helper);
        assert!(label_name("VirtualRoot").helper);
        assert!(label_name("joint_Root").helper);
        assert!(!label_name("Hips").helper);
    }

    #[test]
    fn mirror_pairs_swap_sides() {
        let labels: Vec<_> = ["Hips", "UpperLeg.L", "UpperLeg.R", "Tail"].iter().map(|n| label_name(n)).collect();
        assert_eq!(mirror_pairs(&labels), vec![0, 2, 1, 3]);
    }
}
