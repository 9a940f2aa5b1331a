//! glTF / GLB import: a skin's joints become a [`Skeleton`], each animation is resampled at a
//! chosen frame rate into a [`Motion`] on it.
//!
//! glTF joints carry rest rotations and may sit under scaled or rotated armature nodes; BVH
//! rest poses have zero rotation. So offsets are taken from the rest pose in world axes and
//! every frame's rotations are re-expressed relative to that rest pose: joint positions are the
//! glTF's world-space joint positions, frame by frame. Nodes outside the skin (IK and pole
//! targets, meshes, cameras) are dropped.

use crate::motion::Motion;
use crate::prep::labels::label_name;
use crate::skeleton::{Channels, EulerOrder, Joint, Skeleton};
use glam::{Mat4, Quat, Vec3};
use gltf::animation::util::ReadOutputs;
use gltf::animation::{Interpolation, Property};
use std::collections::HashMap;
use std::path::Path;

/// Why a glTF file could not be imported.
#[derive(Debug, thiserror::Error)]
pub enum GltfError {
    /// The file is not readable glTF.
    #[error("reading glTF: {0}")]
    Gltf(#[from] gltf::Error),
    /// No skin, so no skeleton.
    #[error("the file has no skin: there is no skeleton to import")]
    NoSkin,
    /// The animation asked for does not exist.
    #[error("no animation {wanted:?}; the file has: {available}")]
    NoAnimation {
        /// The name asked for.
        wanted: String,
        /// The names it has.
        available: String,
    },
    /// An animation channel whose keyframes cannot be read.
    #[error("animation {animation:?}: {reason}")]
    BadChannel {
        /// The animation.
        animation: String,
        /// What is wrong.
        reason: String,
    },
}

/// A loaded glTF asset: its skeleton and its animations.
pub struct GltfAsset {
    document: gltf::Document,
    buffers: Vec<gltf::buffer::Data>,
    /// Skin joint node indices in skeleton order (parents first); `None` for a synthetic root.
    nodes: Vec<Option<usize>>,
    parent_of_node: HashMap<usize, usize>,
    skeleton: Skeleton,
}

/// One animation of the asset.
#[derive(Clone, Debug, PartialEq)]
pub struct AnimationInfo {
    /// Index in the file.
    pub index: usize,
    /// Name (or `animation<index>` when unnamed).
    pub name: String,
    /// Length in seconds.
    pub duration: f32,
}

/// Node transforms of the rest pose (local TRS per node).
type LocalTrs = Vec<(Vec3, Quat, Vec3)>;

impl GltfAsset {
    /// Loads a .glb or .gltf file and builds the skeleton of its largest skin, with rotation
    /// channels in `order` (the root also gets position channels).
    pub fn open(path: impl AsRef<Path>, order: EulerOrder) -> Result<GltfAsset, GltfError> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(|e| GltfError::Gltf(gltf::Error::Io(e)))?;
        // Draco-compressed meshes fail validation; the skeleton and animations do not need them.
        let (gltf::Gltf { document, blob }, meshes_readable) = match gltf::Gltf::from_slice(&bytes) {
            Ok(gltf) => (gltf, true),
            Err(error) => {
                let gltf = gltf::Gltf::from_slice_without_validation(&bytes)?;
                if !gltf.document.extensions_required().any(|e| e == "KHR_draco_mesh_compression") {
                    return Err(error.into());
                }
                (gltf, false)
            }
        };
        let buffers = gltf::import_buffers(&document, path.parent(), blob)?;
        let skin = document.skins().max_by_key(|s| s.joints().count()).ok_or(GltfError::NoSkin)?;

        let mut parent_of_node = HashMap::new();
        for node in document.nodes() {
            for child in node.children() {
                parent_of_node.insert(child.index(), node.index());
            }
        }
        let in_skin = if meshes_readable {
            deforming_joints(&document, &buffers, &skin, &parent_of_node)
        } else {
            anatomical_joints(&document, &skin, &parent_of_node)
        };
        // The nearest ancestor of each joint that is also a joint.
        let joint_parent = |node: usize| {
            let mut at = node;
            while let Some(&p) = parent_of_node.get(&at) {
                if in_skin.contains(&p) {
                    return Some(p);
                }
                at = p;
            }
            None
        };
        // Order joints parents-first: depth-first from the roots, children in file order.
        let roots: Vec<usize> = in_skin.iter().copied().filter(|&n| joint_parent(n).is_none()).collect();
        let mut nodes: Vec<Option<usize>> = Vec::new();
        if roots.len() > 1 {
            nodes.push(None);
        }
        let mut stack: Vec<usize> = roots.iter().rev().copied().collect();
        while let Some(n) = stack.pop() {
            nodes.push(Some(n));
            let mut kids: Vec<usize> = in_skin.iter().copied().filter(|&c| joint_parent(c) == Some(n)).collect();
            kids.reverse();
            stack.extend(kids);
        }

        let rest = rest_trs(&document);
        let world = world_matrices(&document, &parent_of_node, &rest);
        let position_of = |slot: &Option<usize>| slot.map_or(Vec3::ZERO, |n| world[n].w_axis.truncate());
        let mut names: HashMap<String, usize> = HashMap::new();
        let mut joints = Vec::with_capacity(nodes.len());
        for (k, slot) in nodes.iter().enumerate() {
            let parent = match slot {
                None => None,
                Some(n) => match joint_parent(*n) {
                    Some(p) => Some(nodes.iter().position(|s| *s == Some(p)).expect("parents come first")),
                    None if k == 0 => None,
                    None => Some(0),
                },
            };
            let base = slot.map_or_else(
                || "Root".to_string(),
                |n| {
                    document
                        .nodes()
                        .nth(n)
                        .and_then(|node| node.name().map(str::to_string))
                        .unwrap_or_else(|| format!("joint{n}"))
                },
            );
            let name = unique_name(&mut names, base);
            let position = position_of(slot);
            let offset = match parent {
                None => position,
                Some(p) => position - position_of(&nodes[p]),
            };
            let channels =
                if parent.is_none() { Channels::position_rotation(order) } else { Channels::rotation(order) };
            joints.push(Joint { name, parent, offset, channels, end_site: None });
        }
        // Leaves get an end site continuing their bone, half its length, for viewers.
        for k in 0..joints.len() {
            let is_leaf = !joints.iter().any(|j| j.parent == Some(k));
            if is_leaf {
                let offset = joints[k].offset;
                joints[k].end_site = Some(if offset.length() > 0.0 { offset * 0.5 } else { Vec3::new(0.0, 0.01, 0.0) });
            }
        }
        let skeleton = Skeleton::new(joints).map_err(|e| GltfError::BadChannel {
            animation: String::new(),
            reason: format!("the skin is not a tree: {e}"),
        })?;
        Ok(GltfAsset { document, buffers, nodes, parent_of_node, skeleton })
    }

    /// The skeleton of the skin.
    pub fn skeleton(&self) -> &Skeleton {
        &self.skeleton
    }

    /// The animations in the file.
    pub fn animations(&self) -> Vec<AnimationInfo> {
        self.document
            .animations()
            .map(|a| {
                let duration = a
                    .channels()
                    .filter_map(|c| {
                        let reader = c.reader(|b| Some(&self.buffers[b.index()]));
                        reader.read_inputs().map(|i| i.fold(0.0f32, f32::max))
                    })
                    .fold(0.0f32, f32::max);
                AnimationInfo { index: a.index(), name: animation_name(&a), duration }
            })
            .collect()
    }

    /// Finds an animation by name.
    pub fn find_animation(&self, name: &str) -> Result<usize, GltfError> {
        let all = self.animations();
        all.iter().find(|a| a.name == name).map(|a| a.index).ok_or_else(|| GltfError::NoAnimation {
            wanted: name.to_string(),
            available: all.iter().map(|a| a.name.as_str()).collect::<Vec<_>>().join(", "),
        })
    }

    /// Samples animation `index` at `fps` (first key to last, inclusive) into a motion.
    pub fn motion(&self, index: usize, fps: f64) -> Result<Motion, GltfError> {
        let animation = self.document.animations().nth(index).ok_or_else(|| GltfError::NoAnimation {
            wanted: format!("#{index}"),
            available: self.animations().iter().map(|a| a.name.clone()).collect::<Vec<_>>().join(", "),
        })?;
        let name = animation_name(&animation);
        let mut tracks = Vec::new();
        for channel in animation.channels() {
            let reader = channel.reader(|b| Some(&self.buffers[b.index()]));
            let bad = |reason: &str| GltfError::BadChannel { animation: name.clone(), reason: reason.to_string() };
            let times: Vec<f32> = reader.read_inputs().ok_or_else(|| bad("keyframe times missing"))?.collect();
            let values: Vec<[f32; 4]> = match reader.read_outputs().ok_or_else(|| bad("keyframe values missing"))? {
                ReadOutputs::Translations(t) => t.map(|v| [v[0], v[1], v[2], 0.0]).collect(),
                ReadOutputs::Scales(s) => s.map(|v| [v[0], v[1], v[2], 0.0]).collect(),
                ReadOutputs::Rotations(r) => r.into_f32().collect(),
                ReadOutputs::MorphTargetWeights(_) => continue,
            };
            let interpolation = channel.sampler().interpolation();
            let per_key = if interpolation == Interpolation::CubicSpline { 3 } else { 1 };
            if times.is_empty() || values.len() != times.len() * per_key {
                return Err(bad("keyframe times and values do not match"));
            }
            tracks.push(Track {
                node: channel.target().node().index(),
                property: channel.target().property(),
                interpolation,
                times,
                values,
            });
        }
        let duration = tracks.iter().filter_map(|t| t.times.last().copied()).fold(0.0f32, f32::max) as f64;
        let frames = (duration * fps).round() as usize + 1;
        let rest = rest_trs(&self.document);
        let rest_world = world_matrices(&self.document, &self.parent_of_node, &rest);
        let rest_rotation: Vec<Quat> =
            self.nodes.iter().map(|s| s.map_or(Quat::IDENTITY, |n| rotation_of(&rest_world[n]))).collect();
        let n = self.skeleton.len();
        let mut rotations = Vec::with_capacity(frames * n);
        let mut translations = Vec::with_capacity(frames * n);
        let mut global = vec![Quat::IDENTITY; n];
        let mut position = vec![Vec3::ZERO; n];
        for f in 0..frames {
            let t = (f as f64 / fps) as f32;
            let mut pose = rest.clone();
            for track in &tracks {
                let v = track.sample(t);
                let trs = &mut pose[track.node];
                match track.property {
                    Property::Translation => trs.0 = Vec3::new(v[0], v[1], v[2]),
                    Property::Rotation => trs.1 = Quat::from_array(v).normalize(),
                    Property::Scale => trs.2 = Vec3::new(v[0], v[1], v[2]),
                    Property::MorphTargetWeights => {}
                }
            }
            let world = world_matrices(&self.document, &self.parent_of_node, &pose);
            for (k, slot) in self.nodes.iter().enumerate() {
                let rotation = slot.map_or(Quat::IDENTITY, |node| rotation_of(&world[node]));
                position[k] = slot.map_or(Vec3::ZERO, |node| world[node].w_axis.truncate());
                global[k] = (rotation * rest_rotation[k].inverse()).normalize();
                match self.skeleton.joint(k).parent {
                    None => {
                        rotations.push(global[k]);
                        translations.push(position[k]);
                    }
                    Some(p) => {
                        rotations.push((global[p].inverse() * global[k]).normalize());
                        translations.push(global[p].inverse() * (position[k] - position[p]));
                    }
                }
            }
        }
        // Joints whose bone changes length or direction in the parent's frame (animated
        // translation or scale) keep that as position channels; the others use their offset.
        let tolerance = 1e-4 * self.skeleton.diameter().max(f32::MIN_POSITIVE);
        let mut joints = self.skeleton.joints().to_vec();
        for (k, joint) in joints.iter_mut().enumerate().skip(1) {
            let moves = (0..frames).any(|f| translations[f * n + k].distance(joint.offset) > tolerance);
            if moves {
                joint.channels = Channels::position_rotation(joint.channels.euler_order());
            } else {
                (0..frames).for_each(|f| translations[f * n + k] = joint.offset);
            }
        }
        let skeleton = Skeleton::new(joints).expect("same tree");
        Ok(Motion::new(skeleton, 1.0 / fps, rotations, translations).expect("shapes match"))
    }
}

/// The skin's joints that move some vertex, themselves or through a descendant joint: control
/// bones (IK and pole targets) exported into the skin deform nothing and are left out. When no
/// mesh uses the skin, every joint is kept.
fn deforming_joints(
    document: &gltf::Document,
    buffers: &[gltf::buffer::Data],
    skin: &gltf::Skin<'_>,
    parent_of_node: &HashMap<usize, usize>,
) -> Vec<usize> {
    let joints: Vec<usize> = skin.joints().map(|n| n.index()).collect();
    let mut weight = vec![0.0f32; joints.len()];
    let mut any_mesh = false;
    for node in document.nodes().filter(|n| n.skin().is_some_and(|s| s.index() == skin.index())) {
        let Some(mesh) = node.mesh() else { continue };
        for primitive in mesh.primitives() {
            let reader = primitive.reader(|b| Some(&buffers[b.index()]));
            let (Some(js), Some(ws)) = (reader.read_joints(0), reader.read_weights(0)) else { continue };
            any_mesh = true;
            for (j, w) in js.into_u16().zip(ws.into_f32()) {
                for (slot, amount) in j.iter().zip(w) {
                    if let Some(total) = weight.get_mut(*slot as usize) {
                        *total += amount.max(0.0);
                    }
                }
            }
        }
    }
    if !any_mesh {
        return joints;
    }
    let mut deforms: Vec<bool> = weight.iter().map(|&w| w > 0.0).collect();
    // A joint stays when any joint below it deforms: walk each deforming joint's ancestors.
    for k in 0..joints.len() {
        if weight[k] > 0.0 {
            let mut at = joints[k];
            while let Some(&p) = parent_of_node.get(&at) {
                if let Some(i) = joints.iter().position(|&n| n == p) {
                    deforms[i] = true;
                }
                at = p;
            }
        }
    }
    joints.into_iter().zip(deforms).filter(|(_, d)| *d).map(|(n, _)| n).collect()
}

/// Without readable meshes, the skin's joints minus branches whose every joint is a rig helper
/// by name (pole targets, IK controls with nothing anatomical below them).
fn anatomical_joints(
    document: &gltf::Document,
    skin: &gltf::Skin<'_>,
    parent_of_node: &HashMap<usize, usize>,
) -> Vec<usize> {
    let joints: Vec<usize> = skin.joints().map(|n| n.index()).collect();
    let name_of =
        |n: usize| document.nodes().nth(n).and_then(|node| node.name().map(str::to_string)).unwrap_or_default();
    let mut keep = vec![false; joints.len()];
    for (k, &node) in joints.iter().enumerate() {
        if !label_name(&name_of(node)).helper {
            keep[k] = true;
            let mut at = node;
            while let Some(&p) = parent_of_node.get(&at) {
                if let Some(i) = joints.iter().position(|&n| n == p) {
                    keep[i] = true;
                }
                at = p;
            }
        }
    }
    joints.into_iter().zip(keep).filter(|(_, k)| *k).map(|(n, _)| n).collect()
}

fn animation_name(animation: &gltf::Animation<'_>) -> String {
    animation.name().map_or_else(|| format!("animation{}", animation.index()), str::to_string)
}

fn unique_name(seen: &mut HashMap<String, usize>, base: String) -> String {
    let base = if base.trim().is_empty() { "joint".to_string() } else { base.trim().to_string() };
    let count = seen.entry(base.clone()).or_insert(0);
    *count += 1;
    if *count == 1 { base } else { format!("{base}_{count}") }
}

fn rest_trs(document: &gltf::Document) -> LocalTrs {
    document
        .nodes()
        .map(|n| {
            let (t, r, s) = n.transform().decomposed();
            (Vec3::from_array(t), Quat::from_array(r).normalize(), Vec3::from_array(s))
        })
        .collect()
}

/// World matrices of every node for the given local transforms.
fn world_matrices(document: &gltf::Document, parent_of: &HashMap<usize, usize>, local: &LocalTrs) -> Vec<Mat4> {
    let count = document.nodes().count();
    let mut world: Vec<Option<Mat4>> = vec![None; count];
    fn resolve(i: usize, parent_of: &HashMap<usize, usize>, local: &LocalTrs, world: &mut Vec<Option<Mat4>>) -> Mat4 {
        if let Some(m) = world[i] {
            return m;
        }
        let (t, r, s) = local[i];
        let own = Mat4::from_scale_rotation_translation(s, r, t);
        let m = match parent_of.get(&i) {
            Some(&p) => resolve(p, parent_of, local, world) * own,
            None => own,
        };
        world[i] = Some(m);
        m
    }
    (0..count).map(|i| resolve(i, parent_of, local, &mut world)).collect()
}

fn rotation_of(m: &Mat4) -> Quat {
    let (_, rotation, _) = m.to_scale_rotation_translation();
    rotation.normalize()
}

/// One animated property of one node.
struct Track {
    node: usize,
    property: Property,
    interpolation: Interpolation,
    times: Vec<f32>,
    values: Vec<[f32; 4]>,
}

impl Track {
    /// The value at time `t`, held constant outside the keyed range.
    fn sample(&self, t: f32) -> [f32; 4] {
        let cubic = self.interpolation == Interpolation::CubicSpline;
        let value = |k: usize| if cubic { self.values[3 * k + 1] } else { self.values[k] };
        let last = self.times.len() - 1;
        if t <= self.times[0] {
            return value(0);
        }
        if t >= self.times[last] {
            return value(last);
        }
        let k = self.times.partition_point(|&x| x <= t) - 1;
        let (t0, t1) = (self.times[k], self.times[k + 1]);
        let dt = t1 - t0;
        let u = if dt > 0.0 { (t - t0) / dt } else { 0.0 };
        let rotation = self.property == Property::Rotation;
        match self.interpolation {
            Interpolation::Step => value(k),
            Interpolation::Linear if rotation => {
                Quat::from_array(value(k)).normalize().slerp(Quat::from_array(value(k + 1)).normalize(), u).to_array()
            }
            Interpolation::Linear => std::array::from_fn(|i| value(k)[i] + (value(k + 1)[i] - value(k)[i]) * u),
            Interpolation::CubicSpline => {
                let (p0, m0) = (self.values[3 * k + 1], self.values[3 * k + 2]);
                let (p1, m1) = (self.values[3 * (k + 1) + 1], self.values[3 * (k + 1)]);
                let (u2, u3) = (u * u, u * u * u);
                let h = [2.0 * u3 - 3.0 * u2 + 1.0, u3 - 2.0 * u2 + u, -2.0 * u3 + 3.0 * u2, u3 - u2];
                let out: [f32; 4] =
                    std::array::from_fn(|i| h[0] * p0[i] + h[1] * dt * m0[i] + h[2] * p1[i] + h[3] * dt * m1[i]);
                if rotation { Quat::from_array(out).normalize().to_array() } else { out }
            }
        }
    }
}
