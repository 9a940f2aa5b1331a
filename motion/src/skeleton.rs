//! The skeleton: joints in parent-before-child order with offsets and the channel layout a BVH
//! file gave them, so that a clip can be written back exactly as it was read.

use glam::{EulerRot, Vec3};
use std::fmt;

/// A coordinate axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Axis {
    /// The X axis.
    X,
    /// The Y axis.
    Y,
    /// The Z axis.
    Z,
}

impl Axis {
    /// The axis index into a vector (X = 0, Y = 1, Z = 2).
    pub fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }

    /// The unit vector along the axis.
    pub fn unit(self) -> Vec3 {
        match self {
            Axis::X => Vec3::X,
            Axis::Y => Vec3::Y,
            Axis::Z => Vec3::Z,
        }
    }

    fn letter(self) -> char {
        match self {
            Axis::X => 'X',
            Axis::Y => 'Y',
            Axis::Z => 'Z',
        }
    }
}

/// One BVH channel: a translation or an Euler angle (degrees) about one axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Channel {
    /// Translation along an axis; it replaces that component of the joint's offset.
    Position(Axis),
    /// Rotation about an axis in degrees.
    Rotation(Axis),
}

impl Channel {
    /// Parses a BVH channel name such as `Xposition` or `zrotation` (case-insensitive).
    pub fn parse(name: &str) -> Option<Channel> {
        let lower = name.to_ascii_lowercase();
        let (axis, kind) = lower.split_at_checked(1)?;
        let axis = match axis {
            "x" => Axis::X,
            "y" => Axis::Y,
            "z" => Axis::Z,
            _ => return None,
        };
        match kind {
            "position" => Some(Channel::Position(axis)),
            "rotation" => Some(Channel::Rotation(axis)),
            _ => None,
        }
    }
}

impl fmt::Display for Channel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Channel::Position(a) => write!(f, "{}position", a.letter()),
            Channel::Rotation(a) => write!(f, "{}rotation", a.letter()),
        }
    }
}

/// The order in which three Euler rotations compose, as intrinsic rotations (`ZXY` = Rz * Rx * Ry).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum EulerOrder {
    /// Rx * Ry * Rz.
    Xyz,
    /// Rx * Rz * Ry.
    Xzy,
    /// Ry * Rx * Rz.
    Yxz,
    /// Ry * Rz * Rx.
    Yzx,
    /// Rz * Rx * Ry.
    Zxy,
    /// Rz * Ry * Rx.
    Zyx,
}

impl EulerOrder {
    /// All six orders.
    pub const ALL: [EulerOrder; 6] =
        [EulerOrder::Xyz, EulerOrder::Xzy, EulerOrder::Yxz, EulerOrder::Yzx, EulerOrder::Zxy, EulerOrder::Zyx];

    /// The three axes in composition order.
    pub fn axes(self) -> [Axis; 3] {
        use Axis::*;
        match self {
            EulerOrder::Xyz => [X, Y, Z],
            EulerOrder::Xzy => [X, Z, Y],
            EulerOrder::Yxz => [Y, X, Z],
            EulerOrder::Yzx => [Y, Z, X],
            EulerOrder::Zxy => [Z, X, Y],
            EulerOrder::Zyx => [Z, Y, X],
        }
    }

    /// The order whose axes are `axes`, if they are a permutation of X, Y, Z.
    pub fn from_axes(axes: [Axis; 3]) -> Option<EulerOrder> {
        EulerOrder::ALL.into_iter().find(|o| o.axes() == axes)
    }

    /// The matching intrinsic glam rotation sequence.
    pub fn glam(self) -> EulerRot {
        match self {
            EulerOrder::Xyz => EulerRot::XYZ,
            EulerOrder::Xzy => EulerRot::XZY,
            EulerOrder::Yxz => EulerRot::YXZ,
            EulerOrder::Yzx => EulerRot::YZX,
            EulerOrder::Zxy => EulerRot::ZXY,
            EulerOrder::Zyx => EulerRot::ZYX,
        }
    }
}

impl fmt::Display for EulerOrder {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [a, b, c] = self.axes();
        write!(f, "{}{}{}", a.letter(), b.letter(), c.letter())
    }
}

impl std::str::FromStr for EulerOrder {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        EulerOrder::ALL
            .into_iter()
            .find(|o| o.to_string().eq_ignore_ascii_case(s))
            .ok_or_else(|| format!("unknown Euler order {s:?}: expected one of XYZ, XZY, YXZ, YZX, ZXY, ZYX"))
    }
}

/// A joint's channels in file order: at most one of each of the six channels.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Channels(Vec<Channel>);

/// Why a channel list was refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ChannelsError {
    /// The same channel appears twice.
    #[error("channel {0} is listed twice")]
    Duplicate(Channel),
}

impl Channels {
    /// Builds a channel list, refusing duplicates.
    pub fn new(list: Vec<Channel>) -> Result<Channels, ChannelsError> {
        for (i, c) in list.iter().enumerate() {
            if list[..i].contains(c) {
                return Err(ChannelsError::Duplicate(*c));
            }
        }
        Ok(Channels(list))
    }

    /// Three position channels followed by three rotation channels in `order`, the usual root layout.
    pub fn position_rotation(order: EulerOrder) -> Channels {
        let mut list: Vec<Channel> = [Axis::X, Axis::Y, Axis::Z].map(Channel::Position).to_vec();
        list.extend(order.axes().map(Channel::Rotation));
        Channels(list)
    }

    /// Three rotation channels in `order`, the usual layout of a non-root joint.
    pub fn rotation(order: EulerOrder) -> Channels {
        Channels(order.axes().map(Channel::Rotation).to_vec())
    }

    /// The channels in file order.
    pub fn as_slice(&self) -> &[Channel] {
        &self.0
    }

    /// How many values this joint has in each frame.
    pub fn len(&self) -> usize {
        self.0.len()
    }

    /// True when the joint has no channels.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// True when any channel is a translation.
    pub fn has_position(&self) -> bool {
        self.0.iter().any(|c| matches!(c, Channel::Position(_)))
    }

    /// The Euler order the rotation channels compose in: the file's order, with absent axes
    /// appended in X, Y, Z order (they hold zero, so where they go does not change the rotation).
    pub fn euler_order(&self) -> EulerOrder {
        let mut axes: Vec<Axis> = self
            .0
            .iter()
            .filter_map(|c| match c {
                Channel::Rotation(a) => Some(*a),
                Channel::Position(_) => None,
            })
            .collect();
        for a in [Axis::X, Axis::Y, Axis::Z] {
            if !axes.contains(&a) {
                axes.push(a);
            }
        }
        EulerOrder::from_axes([axes[0], axes[1], axes[2]]).expect("three distinct axes")
    }
}

/// One joint of a skeleton.
#[derive(Clone, Debug, PartialEq)]
pub struct Joint {
    /// The joint's name as the file spelled it.
    pub name: String,
    /// Index of the parent joint; `None` only for the root (index 0).
    pub parent: Option<usize>,
    /// Offset from the parent joint in the rest pose, in the file's units and axes.
    pub offset: Vec3,
    /// The joint's channels in file order.
    pub channels: Channels,
    /// The end-site offset when the joint is a leaf with an `End Site` block.
    pub end_site: Option<Vec3>,
}

/// Why a list of joints is not a skeleton.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SkeletonError {
    /// No joints at all.
    #[error("a skeleton needs at least one joint")]
    Empty,
    /// Joint 0 has a parent or another joint has none.
    #[error("joint {index} ({name:?}): only the first joint may be the root, and it must be")]
    Root {
        /// Offending joint index.
        index: usize,
        /// Offending joint name.
        name: String,
    },
    /// A parent index that does not come before its child.
    #[error("joint {index} ({name:?}) names parent {parent}, which does not come before it")]
    ParentOrder {
        /// Offending joint index.
        index: usize,
        /// Offending joint name.
        name: String,
        /// The parent index it names.
        parent: usize,
    },
    /// Two joints share a name.
    #[error("joint name {0:?} is used twice")]
    DuplicateName(String),
    /// An offset or end site with a NaN or infinite component.
    #[error("joint {0:?} has a non-finite offset")]
    NonFinite(String),
    /// A name a BVH file cannot hold as it is: empty, with a line break, with white space at
    /// either end, or ending in a white-space-separated `{` (read back as an opening brace).
    #[error("joint name {0:?} cannot be written to BVH and read back")]
    BadName(String),
    /// Joints not listed depth-first (every joint's subtree right after it, as BVH lists them).
    #[error("joint {index} ({name:?}) breaks depth-first order: its parent's subtree ended before it")]
    NotDepthFirst {
        /// Offending joint index.
        index: usize,
        /// Offending joint name.
        name: String,
    },
}

/// True when a joint name survives a BVH round trip: not empty, no line break, no white space at
/// either end, and not ending in a white-space-separated `{` (which reads as an opening brace).
pub fn is_writable_name(name: &str) -> bool {
    !(name.is_empty()
        || name.contains(['\n', '\r'])
        || name.trim() != name
        || name.strip_suffix('{').is_some_and(|rest| rest.ends_with(char::is_whitespace)))
}

/// A skeleton: joints in depth-first order (each joint followed by its whole subtree, the order
/// a BVH file lists them in), rooted at joint 0.
///
/// The rest pose is the offsets with zero rotation. The invariants (one root at index 0,
/// depth-first order, unique names, finite offsets) hold for every value of this type.
#[derive(Clone, Debug, PartialEq)]
pub struct Skeleton {
    joints: Vec<Joint>,
}

impl Skeleton {
    /// Checks the invariants and builds the skeleton.
    pub fn new(joints: Vec<Joint>) -> Result<Skeleton, SkeletonError> {
        if joints.is_empty() {
            return Err(SkeletonError::Empty);
        }
        let mut names = std::collections::HashSet::with_capacity(joints.len());
        // The chain from the root to the previous joint: a joint's parent must be on it.
        let mut chain: Vec<usize> = Vec::new();
        for (index, joint) in joints.iter().enumerate() {
            match (index, joint.parent) {
                (0, None) => {}
                (0, Some(_)) | (_, None) => {
                    return Err(SkeletonError::Root { index, name: joint.name.clone() });
                }
                (_, Some(parent)) if parent >= index => {
                    return Err(SkeletonError::ParentOrder { index, name: joint.name.clone(), parent });
                }
                _ => {}
            }
            if let Some(parent) = joint.parent {
                while chain.last().is_some_and(|&c| c != parent) {
                    chain.pop();
                }
                if chain.is_empty() {
                    return Err(SkeletonError::NotDepthFirst { index, name: joint.name.clone() });
                }
            }
            chain.push(index);
            if !is_writable_name(&joint.name) {
                return Err(SkeletonError::BadName(joint.name.clone()));
            }
            if !names.insert(joint.name.as_str()) {
                return Err(SkeletonError::DuplicateName(joint.name.clone()));
            }
            let finite = joint.offset.is_finite() && joint.end_site.is_none_or(|e| e.is_finite());
            if !finite {
                return Err(SkeletonError::NonFinite(joint.name.clone()));
            }
        }
        Ok(Skeleton { joints })
    }

    /// The joints in parent-before-child order.
    pub fn joints(&self) -> &[Joint] {
        &self.joints
    }

    /// One joint.
    pub fn joint(&self, index: usize) -> &Joint {
        &self.joints[index]
    }

    /// The number of joints.
    pub fn len(&self) -> usize {
        self.joints.len()
    }

    /// Always false: a skeleton has at least its root.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// The parent of every joint (`None` for the root).
    pub fn parents(&self) -> impl Iterator<Item = Option<usize>> + '_ {
        self.joints.iter().map(|j| j.parent)
    }

    /// The index of the joint called `name`.
    pub fn find(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// The children of `joint`, in order.
    pub fn children(&self, joint: usize) -> impl Iterator<Item = usize> + '_ {
        self.joints.iter().enumerate().filter(move |(_, j)| j.parent == Some(joint)).map(|(i, _)| i)
    }

    /// True when `joint` has no child joints.
    pub fn is_leaf(&self, joint: usize) -> bool {
        self.children(joint).next().is_none()
    }

    /// The number of values in one frame of motion.
    pub fn channel_count(&self) -> usize {
        self.joints.iter().map(|j| j.channels.len()).sum()
    }

    /// Each joint's depth in the tree (the root is 0).
    pub fn depths(&self) -> Vec<usize> {
        let mut depth = vec![0; self.len()];
        for (i, j) in self.joints.iter().enumerate() {
            if let Some(p) = j.parent {
                depth[i] = depth[p] + 1;
            }
        }
        depth
    }

    /// Rest-pose joint positions relative to the root joint's rest position.
    pub fn rest_positions(&self) -> Vec<Vec3> {
        let mut pos = vec![Vec3::ZERO; self.len()];
        for (i, j) in self.joints.iter().enumerate().skip(1) {
            pos[i] = pos[j.parent.expect("non-root joint has a parent")] + j.offset;
        }
        pos
    }

    /// The skeleton's diameter: the length of the longest root-to-leaf chain of offsets
    /// (end sites included). NEC appendix B scales every skeleton so that this is 1.
    pub fn diameter(&self) -> f32 {
        let mut chain = vec![0.0f32; self.len()];
        let mut longest = 0.0f32;
        for (i, j) in self.joints.iter().enumerate() {
            if let Some(p) = j.parent {
                chain[i] = chain[p] + j.offset.length();
            }
            let tip = chain[i] + j.end_site.map_or(0.0, Vec3::length);
            longest = longest.max(tip);
        }
        longest
    }
}

/// A joint with three rotation channels and no end site, for tests that build skeletons.
#[cfg(test)]
pub(crate) fn rotating_joint(name: &str, parent: Option<usize>, offset: Vec3) -> Joint {
    Joint { name: name.into(), parent, offset, channels: Channels::rotation(EulerOrder::Zyx), end_site: None }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn joint(name: &str, parent: Option<usize>, offset: Vec3) -> Joint {
        Joint { name: name.into(), parent, offset, channels: Channels::default(), end_site: None }
    }

    #[test]
    fn channel_names_parse_case_insensitively_and_print_canonically() {
        assert_eq!(Channel::parse("Xposition"), Some(Channel::Position(Axis::X)));
        assert_eq!(Channel::parse("zROTATION"), Some(Channel::Rotation(Axis::Z)));
        assert_eq!(Channel::parse("Wrotation"), None);
        assert_eq!(Channel::parse(""), None);
        assert_eq!(Channel::Rotation(Axis::Y).to_string(), "Yrotation");
    }

    #[test]
    fn euler_order_completes_missing_axes() {
        let c = Channels::new(vec![Channel::Rotation(Axis::Z)]).unwrap();
        assert_eq!(c.euler_order(), EulerOrder::Zxy);
        let c = Channels::position_rotation(EulerOrder::Yzx);
        assert_eq!(c.euler_order(), EulerOrder::Yzx);
        assert!(Channels::new(vec![Channel::Rotation(Axis::Z), Channel::Rotation(Axis::Z)]).is_err());
    }

    #[test]
    fn skeleton_rejects_broken_trees() {
        assert_eq!(Skeleton::new(vec![]), Err(SkeletonError::Empty));
        let two_roots = vec![joint("a", None, Vec3::ZERO), joint("b", None, Vec3::ZERO)];
        assert!(matches!(Skeleton::new(two_roots), Err(SkeletonError::Root { index: 1, .. })));
        let dup = vec![joint("a", None, Vec3::ZERO), joint("a", Some(0), Vec3::ZERO)];
        assert_eq!(Skeleton::new(dup), Err(SkeletonError::DuplicateName("a".into())));
        for bad in ["", " a", "a\nb", "a {"] {
            let named = vec![joint(bad, None, Vec3::ZERO)];
            assert_eq!(Skeleton::new(named), Err(SkeletonError::BadName(bad.into())), "{bad:?}");
        }
        // b's subtree (b, c) ends when d, a child of the root, starts; e cannot join it again.
        let interleaved = vec![
            joint("a", None, Vec3::ZERO),
            joint("b", Some(0), Vec3::ZERO),
            joint("c", Some(1), Vec3::ZERO),
            joint("d", Some(0), Vec3::ZERO),
            joint("e", Some(1), Vec3::ZERO),
        ];
        assert!(matches!(Skeleton::new(interleaved), Err(SkeletonError::NotDepthFirst { index: 4, .. })));
    }

    #[test]
    fn diameter_is_the_longest_chain_including_end_sites() {
        let mut leaf = joint("c", Some(1), Vec3::new(0.0, 3.0, 0.0));
        leaf.end_site = Some(Vec3::new(0.0, 0.0, 2.0));
        let s = Skeleton::new(vec![
            joint("a", None, Vec3::new(100.0, 0.0, 0.0)),
            joint("b", Some(0), Vec3::new(0.0, 4.0, 0.0)),
            leaf,
            joint("d", Some(0), Vec3::new(8.0, 0.0, 0.0)),
        ])
        .unwrap();
        assert_eq!(s.diameter(), 9.0);
        assert_eq!(s.rest_positions()[2], Vec3::new(0.0, 7.0, 0.0));
        assert_eq!(s.depths(), vec![0, 1, 2, 1]);
        assert_eq!(s.children(0).collect::<Vec<_>>(), vec![1, 3]);
    }
}
