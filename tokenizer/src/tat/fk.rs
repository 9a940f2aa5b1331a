//! Differentiable forward kinematics on tensors: rot6D -> rotation matrices -> global joint
//! positions, level by level of the tree so a deep skeleton costs one step per depth, not per
//! joint.

use candle_core::{D, Device, Result, Tensor};

/// Rotation matrices `(..., 3, 3)` from rot6D `(..., 6)` by Gram-Schmidt, stored column-major
/// (`m[..., c, r]` is row `r` of column `c`), matching [`anymo_motion::rotation::rot6d_to_quat`].
pub fn rot6d_to_matrix(six: &Tensor) -> Result<Tensor> {
    let a = six.narrow(D::Minus1, 0, 3)?;
    let b = six.narrow(D::Minus1, 3, 3)?;
    let x = normalise(&a)?;
    let y = normalise(&(&b - x.broadcast_mul(&(&x * &b)?.sum_keepdim(D::Minus1)?)?)?)?;
    let z = cross(&x, &y)?;
    Tensor::stack(&[x, y, z], D::Minus2)
}

fn normalise(v: &Tensor) -> Result<Tensor> {
    v.broadcast_div(&(v.sqr()?.sum_keepdim(D::Minus1)? + 1e-8)?.sqrt()?)
}

fn cross(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    let c = |t: &Tensor, i: usize| t.narrow(D::Minus1, i, 1);
    let (a0, a1, a2) = (c(a, 0)?, c(a, 1)?, c(a, 2)?);
    let (b0, b1, b2) = (c(b, 0)?, c(b, 1)?, c(b, 2)?);
    Tensor::cat(
        &[((&a1 * &b2)? - (&a2 * &b1)?)?, ((&a2 * &b0)? - (&a0 * &b2)?)?, ((&a0 * &b1)? - (&a1 * &b0)?)?],
        D::Minus1,
    )
}

/// `m v` for column-major `m (..., 3, 3)` and `v (..., 3)`.
pub fn rotate(m: &Tensor, v: &Tensor) -> Result<Tensor> {
    m.broadcast_mul(&v.unsqueeze(D::Minus1)?)?.sum(D::Minus2)
}

/// `a b` for column-major matrices.
pub fn compose(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    a.unsqueeze(a.rank() - 2)?.broadcast_mul(&b.unsqueeze(D::Minus1)?)?.sum(D::Minus2)
}

/// A skeleton's tree as depth levels, precomputed once per topology.
#[derive(Clone, Debug)]
pub struct Levels {
    /// Joints of each depth.
    levels: Vec<Vec<usize>>,
    /// For each level after the first, the index of each joint's parent within the level above.
    parent_slots: Vec<Tensor>,
    /// The joints of each level as a tensor.
    members: Vec<Tensor>,
    /// Where each joint lands when the levels are concatenated.
    order: Tensor,
}

impl Levels {
    /// Levels of a tree given by its parents (depth-first order, root first).
    pub fn new(parents: &[Option<usize>]) -> Result<Levels> {
        let mut depth = vec![0usize; parents.len()];
        for (j, p) in parents.iter().enumerate() {
            if let Some(p) = p {
                depth[j] = depth[*p] + 1;
            }
        }
        let max = depth.iter().copied().max().unwrap_or(0);
        let levels: Vec<Vec<usize>> =
            (0..=max).map(|d| (0..parents.len()).filter(|&j| depth[j] == d).collect()).collect();
        let device = Device::Cpu;
        let mut parent_slots = Vec::new();
        for d in 1..levels.len() {
            let slots: Vec<u32> = levels[d]
                .iter()
                .map(|&j| {
                    levels[d - 1].iter().position(|&k| Some(k) == parents[j]).expect("parent one level up") as u32
                })
                .collect();
            parent_slots.push(Tensor::from_vec(slots, levels[d].len(), &device)?);
        }
        let members = levels
            .iter()
            .map(|l| Tensor::from_vec(l.iter().map(|&j| j as u32).collect::<Vec<_>>(), l.len(), &device))
            .collect::<Result<_>>()?;
        let flat: Vec<usize> = levels.iter().flatten().copied().collect();
        let mut order = vec![0u32; flat.len()];
        for (slot, &j) in flat.iter().enumerate() {
            order[j] = slot as u32;
        }
        let order = Tensor::from_vec(order, flat.len(), &device)?;
        Ok(Levels { levels, parent_slots, members, order })
    }

    /// Global joint positions `(B, T, J, 3)` from rot6D `(B, T, J, 6)` (the root's orientation
    /// first), rest offsets `(B, J, 3)` and the root's position `(B, T, 3)`.
    pub fn positions(&self, rot6d: &Tensor, offsets: &Tensor, root: &Tensor) -> Result<Tensor> {
        let local = rot6d_to_matrix(rot6d)?;
        let mut rotations: Vec<Tensor> = Vec::with_capacity(self.levels.len());
        let mut positions: Vec<Tensor> = Vec::with_capacity(self.levels.len());
        rotations.push(local.index_select(&self.members[0], 2)?);
        positions.push(root.unsqueeze(2)?);
        for d in 1..self.levels.len() {
            let slots = &self.parent_slots[d - 1];
            let parent_rotation = rotations[d - 1].index_select(slots, 2)?;
            let parent_position = positions[d - 1].index_select(slots, 2)?;
            let offset = offsets.index_select(&self.members[d], 1)?.unsqueeze(1)?;
            let position = parent_position.broadcast_add(&rotate(&parent_rotation, &offset)?)?;
            let rotation = compose(&parent_rotation, &local.index_select(&self.members[d], 2)?)?;
            rotations.push(rotation);
            positions.push(position);
        }
        Tensor::cat(&positions, 2)?.index_select(&self.order, 2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use anymo_motion::bvh::parse_str;
    use anymo_motion::features::{ROT_DIMS, to_features};
    use anymo_motion::kinematics::all_joint_positions;
    use anymo_motion::motion::Motion;

    #[test]
    fn tensor_fk_matches_the_reference_chain() {
        let text = "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n \
            JOINT A\n {\n  OFFSET 0.2 0.1 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  JOINT B\n  {\n   OFFSET 0 -0.5 0.1\n   CHANNELS 3 Zrotation Xrotation Yrotation\n   End Site\n   {\n    OFFSET 0 -0.5 0\n   }\n  }\n }\n \
            JOINT C\n {\n  OFFSET 0 0.3 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 0.3 0\n  }\n }\n}\n\
            MOTION\nFrames: 2\nFrame Time: 0.0333333\n0 1 0 10 20 30 40 50 60 -30 15 5 7 8 9\n0 1 0 -10 25 35 45 -50 60 30 15 -5 17 18 19\n";
        let motion = Motion::from_bvh(&parse_str(text).unwrap());
        let (features, _) = to_features(&motion);
        let (frames, joints) = (2, 4);
        let device = Device::Cpu;
        let rot = Tensor::from_vec(features.rotations.clone(), (1, frames, joints, ROT_DIMS), &device).unwrap();
        let offsets: Vec<f32> = motion.skeleton().joints().iter().flat_map(|j| j.offset.to_array()).collect();
        let offsets = Tensor::from_vec(offsets, (1, joints, 3), &device).unwrap();
        let root = Tensor::from_vec(vec![0.0f32, 1.0, 0.0, 0.0, 1.0, 0.0], (1, frames, 3), &device).unwrap();
        let levels = Levels::new(&motion.skeleton().parents().collect::<Vec<_>>()).unwrap();
        let got: Vec<f32> = levels.positions(&rot, &offsets, &root).unwrap().flatten_all().unwrap().to_vec1().unwrap();
        // The reference: the glam FK of the same motion with its heading removed.
        let (skeleton, ft, mut rotations, translations) = motion.clone().into_parts();
        for f in 0..frames {
            let six: [f32; 6] = features.rotations[f * joints * 6..f * joints * 6 + 6].try_into().unwrap();
            rotations[f * joints] = anymo_motion::rotation::rot6d_to_quat(six);
        }
        let unheaded = Motion::new(skeleton, ft, rotations, translations).unwrap();
        let want = all_joint_positions(&unheaded);
        for (k, p) in want.iter().enumerate() {
            let g = glam::Vec3::new(got[3 * k], got[3 * k + 1], got[3 * k + 2]);
            assert!((g - *p).length() < 1e-5, "joint {k}: {g} vs {p}");
        }
    }
}
