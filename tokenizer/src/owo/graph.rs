//! A skeleton as OwO's input graph: joints plus one global node, parent<->child edges carrying
//! the rest offset, and global<->joint edges carrying none.

use crate::text::{CachedEncoder, EMBEDDING_DIM, TextError};
use anymo_motion::prep::labels::label_name;
use anymo_motion::skeleton::Skeleton;
use candle_core::{Device, Result, Tensor};
use glam::Vec3;

/// Features per node: the embedding of the joint's name as written, then of its semantic label.
pub const NODE_INPUT_DIM: usize = 2 * EMBEDDING_DIM;
/// Text of the global node.
pub const GLOBAL_NODE_TEXT: &str = "global";
/// Label text standing in for a hidden label.
pub const UNKNOWN_LABEL_TEXT: &str = "joint";

/// One skeleton, ready for OwO.
#[derive(Clone, Debug)]
pub struct SkeletonGraph {
    /// Parent of each joint.
    pub parents: Vec<Option<usize>>,
    /// Rest offsets scaled so the skeleton's diameter is 1.
    pub offsets: Vec<Vec3>,
    /// `joints x NODE_INPUT_DIM`.
    pub node_text: Vec<f32>,
    /// The label text of each joint (the semantic pretraining target).
    pub labels: Vec<String>,
}

impl SkeletonGraph {
    /// Builds the graph of a skeleton, embedding names and labels with `encoder`.
    pub fn new(skeleton: &Skeleton, encoder: &mut CachedEncoder) -> std::result::Result<SkeletonGraph, TextError> {
        let names: Vec<&str> = skeleton.joints().iter().map(|j| j.name.as_str()).collect();
        let labels: Vec<String> = names.iter().map(|n| label_name(n).text()).collect();
        let spoken: Vec<String> = names.iter().map(|n| spoken_name(n)).collect();
        let name_vectors = encoder.encode(&spoken.iter().map(String::as_str).collect::<Vec<_>>())?;
        let label_vectors = encoder.encode(&labels.iter().map(String::as_str).collect::<Vec<_>>())?;
        let mut node_text = Vec::with_capacity(names.len() * NODE_INPUT_DIM);
        for (n, l) in name_vectors.iter().zip(&label_vectors) {
            node_text.extend_from_slice(n);
            node_text.extend_from_slice(l);
        }
        let scale = 1.0 / skeleton.diameter().max(1e-6);
        Ok(SkeletonGraph {
            parents: skeleton.parents().collect(),
            offsets: skeleton.joints().iter().map(|j| j.offset * scale).collect(),
            node_text,
            labels,
        })
    }

    /// Hides the semantic label of the joints for which `hide` is true, putting `unknown` (the
    /// embedding of a label-less phrase) in its place: the graph then knows those joints only by
    /// their written names and their place in the tree.
    pub fn hide_labels(&mut self, unknown: &[f32], hide: impl Fn(usize) -> bool) {
        for j in 0..self.joints() {
            if hide(j) {
                let k = j * NODE_INPUT_DIM + EMBEDDING_DIM;
                self.node_text[k..k + EMBEDDING_DIM].copy_from_slice(unknown);
            }
        }
    }

    /// Number of joints.
    pub fn joints(&self) -> usize {
        self.parents.len()
    }

    /// Rest positions of the joints (root at the origin).
    pub fn rest_positions(&self) -> Vec<Vec3> {
        let mut out: Vec<Vec3> = Vec::with_capacity(self.joints());
        for (j, parent) in self.parents.iter().enumerate() {
            let p = match parent {
                Some(p) => out[*p] + self.offsets[j],
                None => Vec3::ZERO,
            };
            out.push(p);
        }
        out
    }

    /// The lowest common ancestor of two joints.
    pub fn lca(&self, a: usize, b: usize) -> usize {
        let ancestors = |mut j: usize| {
            let mut chain = vec![j];
            while let Some(p) = self.parents[j] {
                chain.push(p);
                j = p;
            }
            chain
        };
        let of_a = ancestors(a);
        ancestors(b).into_iter().find(|j| of_a.contains(j)).expect("a tree has one root")
    }
}

/// A joint name split into words for the sentence encoder (`mixamorig:LeftUpLeg` -> "mixamorig left
/// up leg"), since sub-word pieces of camel case carry little meaning.
pub fn spoken_name(name: &str) -> String {
    let mut out = String::with_capacity(name.len() + 8);
    let mut prev: Option<char> = None;
    for c in name.chars() {
        let boundary = match prev {
            Some(p) => (c.is_ascii_uppercase() && p.is_ascii_lowercase()) || (c.is_ascii_digit() != p.is_ascii_digit()),
            None => false,
        };
        if !c.is_ascii_alphanumeric() {
            if !out.ends_with(' ') && !out.is_empty() {
                out.push(' ');
            }
        } else {
            if boundary && !out.ends_with(' ') {
                out.push(' ');
            }
            out.push(c.to_ascii_lowercase());
        }
        prev = Some(c);
    }
    out.trim().to_string()
}

/// Sinusoidal features of an offset, per axis: `sin, cos` of `pi * 2^k * x` for `k < freqs`.
pub fn sinusoidal(offset: Vec3, freqs: usize, out: &mut Vec<f32>) {
    for x in offset.to_array() {
        for k in 0..freqs {
            let a = std::f32::consts::PI * (1u32 << k) as f32 * x;
            out.push(a.sin());
            out.push(a.cos());
        }
    }
}

/// Several skeletons as one disjoint graph, so one pass encodes them all.
pub struct GraphBatch {
    /// `(nodes, NODE_INPUT_DIM)`: each skeleton's joints, then its global node.
    pub nodes: Tensor,
    /// Source node of each directed edge.
    pub src: Tensor,
    /// Target node of each directed edge.
    pub dst: Tensor,
    /// `(edges, 6 * freqs)`: sinusoidal offset features of each edge.
    pub edge_offsets: Tensor,
    /// For each skeleton, its first node and its joint count (its global node follows the joints).
    pub ranges: Vec<(usize, usize)>,
}

impl GraphBatch {
    /// Joins skeleton graphs; `global_text` is the embedding of [`GLOBAL_NODE_TEXT`].
    pub fn new(graphs: &[&SkeletonGraph], global_text: &[f32], freqs: usize) -> Result<GraphBatch> {
        let mut nodes = Vec::new();
        let (mut src, mut dst, mut offsets) = (Vec::new(), Vec::new(), Vec::new());
        let mut ranges = Vec::new();
        let mut start = 0usize;
        for g in graphs {
            let j = g.joints();
            nodes.extend_from_slice(&g.node_text);
            nodes.extend_from_slice(global_text);
            nodes.extend_from_slice(global_text);
            let global = start + j;
            for (child, parent) in g.parents.iter().enumerate() {
                if let Some(p) = parent {
                    let o = g.offsets[child];
                    src.extend([(start + p) as u32, (start + child) as u32]);
                    dst.extend([(start + child) as u32, (start + p) as u32]);
                    sinusoidal(o, freqs, &mut offsets);
                    sinusoidal(-o, freqs, &mut offsets);
                }
                src.extend([global as u32, (start + child) as u32]);
                dst.extend([(start + child) as u32, global as u32]);
                sinusoidal(Vec3::ZERO, freqs, &mut offsets);
                sinusoidal(Vec3::ZERO, freqs, &mut offsets);
            }
            ranges.push((start, j));
            start += j + 1;
        }
        let device = Device::Cpu;
        let edges = src.len();
        Ok(GraphBatch {
            nodes: Tensor::from_vec(nodes, (start, NODE_INPUT_DIM), &device)?,
            src: Tensor::from_vec(src, edges, &device)?,
            dst: Tensor::from_vec(dst, edges, &device)?,
            edge_offsets: Tensor::from_vec(offsets, (edges, 6 * freqs), &device)?,
            ranges,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_spoken_as_words() {
        assert_eq!(spoken_name("mixamorig:LeftUpLeg"), "mixamorig left up leg");
        assert_eq!(spoken_name("CC_Base_L_Thigh"), "cc base l thigh");
        assert_eq!(spoken_name("Spine2"), "spine 2");
        assert_eq!(spoken_name("UpperLeg.L"), "upper leg l");
    }
}
