//! What the tokenizers are trained and measured on: a loader batch turned into model inputs and
//! targets, and the reconstruction losses (features, FK positions, velocities, contacts, foot
//! skating) shared by TAT and the zero-padded baseline.

use super::fk::Levels;
use crate::dataset::Batch;
use crate::nn::relu;
use candle_core::{D, Device, Result, Tensor};
use serde::{Deserialize, Serialize};

/// Mean and spread of the root features (yaw rate, heading-frame velocity, height), measured on
/// the training data and kept with the model.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct RootStats {
    /// Means.
    pub mean: [f32; 4],
    /// Standard deviations.
    pub std: [f32; 4],
}

impl RootStats {
    /// Measures the statistics of `(frames x 4)` root features.
    pub fn measure(root: &[f32]) -> RootStats {
        let n = (root.len() / 4).max(1) as f64;
        let mut mean = [0f64; 4];
        let mut sq = [0f64; 4];
        for row in root.chunks_exact(4) {
            for k in 0..4 {
                mean[k] += row[k] as f64 / n;
                sq[k] += (row[k] as f64).powi(2) / n;
            }
        }
        let std = std::array::from_fn(|k| ((sq[k] - mean[k] * mean[k]).max(0.0).sqrt() as f32).max(1e-4));
        RootStats { mean: mean.map(|m| m as f32), std }
    }

    fn tensors(&self) -> Result<(Tensor, Tensor)> {
        Ok((Tensor::new(&self.mean, &Device::Cpu)?, Tensor::new(&self.std, &Device::Cpu)?))
    }

    /// `(…, 4)` raw -> normalised.
    pub fn normalise(&self, root: &Tensor) -> Result<Tensor> {
        let (m, s) = self.tensors()?;
        root.broadcast_sub(&m)?.broadcast_div(&s)
    }

    /// `(…, 4)` normalised -> raw.
    pub fn denormalise(&self, root: &Tensor) -> Result<Tensor> {
        let (m, s) = self.tensors()?;
        root.broadcast_mul(&s)?.broadcast_add(&m)
    }
}

/// Contact thresholds, in diameters and diameters per frame at 30 fps.
pub const CONTACT_HEIGHT: f32 = 0.05;
/// See [`CONTACT_HEIGHT`].
pub const CONTACT_SPEED: f32 = 0.01;

/// A batch as model inputs and targets.
pub struct Prepared {
    /// `(B, T, J, INPUT_DIMS)` encoder input.
    pub input: Tensor,
    /// `(B, T, J, 6)` target rot6D.
    pub rotations: Tensor,
    /// `(B, T, 4)` normalised root features.
    pub root: Tensor,
    /// `(B, T, J, 3)` target positions (root at the origin of the heading frame, at its height).
    pub positions: Tensor,
    /// `(B, T, J)` 1 where a joint is low and still in the world.
    pub contacts: Tensor,
    /// `(B, T)` real frames.
    pub mask: Tensor,
    /// `(B, J, 3)` rest offsets.
    pub offsets: Tensor,
    /// The tree by depth.
    pub levels: Levels,
}

/// Root positions `(B, T, 3)` at the origin of the heading frame, at the given height `(B, T)`.
pub fn root_positions(height: &Tensor) -> Result<Tensor> {
    let zeros = height.zeros_like()?.unsqueeze(D::Minus1)?;
    Tensor::cat(&[&zeros, &height.unsqueeze(D::Minus1)?, &zeros], D::Minus1)
}

/// Velocities along time `(B, T, ...)`, the last frame zero.
pub fn velocities(x: &Tensor) -> Result<Tensor> {
    let t = x.dim(1)?;
    let diff = (x.narrow(1, 1, t - 1)? - x.narrow(1, 0, t - 1)?)?;
    Tensor::cat(&[&diff, &x.narrow(1, 0, 1)?.zeros_like()?], 1)
}

/// How far each joint moves in the world from each frame to the next, in the heading frame of
/// the first `(B, T, J, 3)`, the last frame zero: `positions` are root-centred in each frame's
/// heading frame and `root` holds the raw root features (yaw rate, planar velocity, height), so
/// the step is `R_y(yaw) p[t + 1] + v - p[t]`. A planted foot of a walk is still here while it
/// moves backwards under the root in `positions`.
pub fn world_velocities(positions: &Tensor, root: &Tensor) -> Result<Tensor> {
    let t = positions.dim(1)?;
    let channel = |k: usize| root.narrow(1, 0, t - 1)?.narrow(D::Minus1, k, 1)?.unsqueeze(D::Minus1);
    let (yaw, vx, vz) = (channel(0)?, channel(1)?, channel(2)?);
    let (cos, sin) = (yaw.cos()?, yaw.sin()?);
    let next = positions.narrow(1, 1, t - 1)?;
    let (x, y, z) = (next.narrow(D::Minus1, 0, 1)?, next.narrow(D::Minus1, 1, 1)?, next.narrow(D::Minus1, 2, 1)?);
    let turned_x = (x.broadcast_mul(&cos)? + z.broadcast_mul(&sin)?)?.broadcast_add(&vx)?;
    let turned_z = (z.broadcast_mul(&cos)? - x.broadcast_mul(&sin)?)?.broadcast_add(&vz)?;
    let moved = (Tensor::cat(&[&turned_x, &y, &turned_z], D::Minus1)? - positions.narrow(1, 0, t - 1)?)?;
    Tensor::cat(&[&moved, &positions.narrow(1, 0, 1)?.zeros_like()?], 1)
}

/// The horizontal part `(…, 2)` of velocities `(…, 3)`.
fn planar(v: &Tensor) -> Result<Tensor> {
    Tensor::cat(&[&v.narrow(D::Minus1, 0, 1)?, &v.narrow(D::Minus1, 2, 1)?], D::Minus1)
}

impl Prepared {
    /// Builds inputs and targets from a loader batch.
    pub fn new(batch: &Batch, stats: &RootStats) -> Result<Prepared> {
        let levels = Levels::new(&batch.parents)?;
        let (b, t, j, _) = batch.rotations.dims4()?;
        let height = batch.root.narrow(D::Minus1, 3, 1)?.squeeze(D::Minus1)?;
        let positions = levels.positions(&batch.rotations, &batch.offsets, &root_positions(&height)?)?;
        let velocity = velocities(&positions)?;
        let root = stats.normalise(&batch.root)?;
        let root_slot =
            Tensor::cat(&[&root.unsqueeze(2)?, &Tensor::zeros((b, t, j - 1, 4), root.dtype(), root.device())?], 2)?;
        let input = Tensor::cat(&[&batch.rotations, &root_slot, &positions, &(&velocity * 10.0)?], D::Minus1)?;
        let low = positions.narrow(D::Minus1, 1, 1)?.squeeze(D::Minus1)?.lt(CONTACT_HEIGHT)?;
        let world = planar(&world_velocities(&positions, &batch.root)?)?;
        let slow = world.sqr()?.sum(D::Minus1)?.sqrt()?.lt(CONTACT_SPEED)?;
        let contacts = (low.to_dtype(candle_core::DType::F32)? * slow.to_dtype(candle_core::DType::F32)?)?;
        Ok(Prepared {
            input,
            rotations: batch.rotations.clone(),
            root,
            positions,
            contacts,
            mask: batch.mask.clone(),
            offsets: batch.offsets.clone(),
            levels,
        })
    }
}

/// A decoded batch.
pub struct Prediction {
    /// `(B, T, J, 6)`.
    pub rotations: Tensor,
    /// `(B, T, 4)` normalised root features.
    pub root: Tensor,
    /// `(B, T, J)` contact logits, when the model predicts them.
    pub contacts: Option<Tensor>,
}

/// Loss weights.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct LossWeights {
    /// rot6D.
    pub rotation: f32,
    /// Root features.
    pub root: f32,
    /// FK joint positions.
    pub position: f32,
    /// Joint velocities.
    pub velocity: f32,
    /// Contact classification.
    pub contact: f32,
    /// Foot sliding in the world (the decoded root's motion included) while the truth is in
    /// contact.
    pub skating: f32,
    /// RVQ commitment.
    pub commitment: f32,
    /// Heading integrated from the yaw rate over the window (cards that do not record it were
    /// trained without it).
    #[serde(default)]
    pub heading: f32,
    /// Root path integrated from heading and planar velocity over the window (likewise).
    #[serde(default)]
    pub path: f32,
}

impl Default for LossWeights {
    /// Rotation, root and position weights are the ones that measured best when the shipped TAT
    /// was continued (README, "What the recipe changed"): positions cannot see a bone's twist
    /// about its own axis, so only the rotation term pins it, and the root features carry the
    /// heading that long clips integrate. The heading and path terms are off: continuing the
    /// shipped TAT with them made the integrated heading worse, not better (README, probes).
    fn default() -> Self {
        LossWeights {
            rotation: 10.0,
            root: 4.0,
            position: 16.0,
            velocity: 20.0,
            contact: 0.1,
            skating: 20.0,
            commitment: 0.02,
            heading: 0.0,
            path: 0.0,
        }
    }
}

/// Each loss term's value, for logs.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize)]
pub struct LossParts {
    /// rot6D mean squared error.
    pub rotation: f32,
    /// Root feature mean squared error.
    pub root: f32,
    /// FK position mean squared error.
    pub position: f32,
    /// Velocity mean squared error.
    pub velocity: f32,
    /// Contact cross-entropy.
    pub contact: f32,
    /// Foot sliding.
    pub skating: f32,
    /// Commitment.
    pub commitment: f32,
    /// Integrated heading mean squared error (radians²).
    pub heading: f32,
    /// Integrated root path mean squared error (diameters²).
    pub path: f32,
}

fn masked_mean(err: &Tensor, mask: &Tensor) -> Result<Tensor> {
    // err: (B, T, ...) ; mask: (B, T)
    let extra: usize = err.dims()[2..].iter().product();
    let m =
        mask.reshape(mask.dims().iter().copied().chain(std::iter::repeat_n(1, err.rank() - 2)).collect::<Vec<_>>())?;
    let total = err.broadcast_mul(&m)?.sum_all()?;
    total / (mask.sum_all()?.to_scalar::<f32>()? as f64 * extra as f64).max(1.0)
}

/// The heading `(B, T)` and planar root path `(B, T, 2)` that raw root features `(B, T, 4)`
/// integrate to over a window, from heading 0 at the origin, as `features::from_features`
/// integrates them; frames outside `mask` add nothing.
pub fn trajectory(root: &Tensor, mask: &Tensor) -> Result<(Tensor, Tensor)> {
    let t = root.dim(1)?;
    // `x.matmul(before)[t]` sums x over the frames before t.
    let before = (Tensor::triu2(t, root.dtype(), root.device())? - Tensor::eye(t, root.dtype(), root.device())?)?;
    let channel = |k: usize| root.narrow(D::Minus1, k, 1)?.squeeze(D::Minus1)?.mul(mask);
    let (yaw, vx, vz) = (channel(0)?, channel(1)?, channel(2)?);
    let heading = yaw.broadcast_matmul(&before)?;
    let (cos, sin) = (heading.cos()?, heading.sin()?);
    let dx = ((&vx * &cos)? + (&vz * &sin)?)?;
    let dz = ((&vz * &cos)? - (&vx * &sin)?)?;
    let path = Tensor::stack(&[dx.broadcast_matmul(&before)?, dz.broadcast_matmul(&before)?], D::Minus1)?;
    Ok((heading, path))
}

/// The weighted loss of a prediction, and its terms.
pub fn loss(
    prediction: &Prediction,
    truth: &Prepared,
    stats: &RootStats,
    commitment: &Tensor,
    w: &LossWeights,
) -> Result<(Tensor, LossParts)> {
    let mask = &truth.mask;
    let rotation = masked_mean(&(&prediction.rotations - &truth.rotations)?.sqr()?, mask)?;
    let root = masked_mean(&(&prediction.root - &truth.root)?.sqr()?, mask)?;
    let height = stats.denormalise(&prediction.root)?.narrow(D::Minus1, 3, 1)?.squeeze(D::Minus1)?;
    let positions = truth.levels.positions(&prediction.rotations, &truth.offsets, &root_positions(&height)?)?;
    let position = masked_mean(&(&positions - &truth.positions)?.sqr()?, mask)?;
    let v_pred = velocities(&positions)?;
    let v_true = velocities(&truth.positions)?;
    let velocity = masked_mean(&(&v_pred - &v_true)?.sqr()?, mask)?;
    let root_pred = stats.denormalise(&prediction.root)?;
    let sliding = planar(&world_velocities(&positions, &root_pred)?)?;
    let skating = masked_mean(&(sliding.sqr()?.sum(D::Minus1)? * &truth.contacts)?, mask)?;
    let contact = match &prediction.contacts {
        Some(logits) => {
            // Binary cross-entropy with logits: softplus(x) - y x.
            let softplus = (logits.abs()?.neg()?.exp()? + 1.0)?.log()?.add(&relu(logits)?)?;
            masked_mean(&(softplus - (logits * &truth.contacts)?)?, mask)?
        }
        None => Tensor::new(0f32, &Device::Cpu)?,
    };
    let (heading_true, path_true) = trajectory(&stats.denormalise(&truth.root)?, mask)?;
    let (heading_pred, path_pred) = trajectory(&root_pred, mask)?;
    let heading = masked_mean(&(heading_pred - heading_true)?.sqr()?, mask)?;
    let path = masked_mean(&(path_pred - path_true)?.sqr()?.sum(D::Minus1)?, mask)?;
    let mut total = ((&rotation * w.rotation as f64)?
        + (&root * w.root as f64)?
        + (&position * w.position as f64)?
        + (&velocity * w.velocity as f64)?
        + (&contact * w.contact as f64)?
        + (&skating * w.skating as f64)?
        + (commitment * w.commitment as f64)?)?;
    // Off by default: left out of the total then, so the backward pass does not go through them
    // (they are still logged).
    for (term, weight) in [(&heading, w.heading), (&path, w.path)] {
        if weight > 0.0 {
            total = (total + (term * weight as f64)?)?;
        }
    }
    let v = |t: &Tensor| t.to_scalar::<f32>();
    let parts = LossParts {
        rotation: v(&rotation)?,
        root: v(&root)?,
        position: v(&position)?,
        velocity: v(&velocity)?,
        contact: v(&contact)?,
        skating: v(&skating)?,
        commitment: v(commitment)?,
        heading: v(&heading)?,
        path: v(&path)?,
    };
    Ok((total, parts))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::FRAC_PI_2;

    #[test]
    fn a_foot_planted_under_a_moving_turning_root_is_still_in_the_world() {
        use anymo_motion::features::{ROOT_DIMS, root_path};
        // The root walks 0.1 forward and turns 0.2 rad per frame; a foot planted in the world at
        // (0.3, 0, 1) is seen from the root's heading frame, where it moves every frame.
        let frames = 4;
        let rows = vec![[0.2f32, 0.0, 0.1, 0.5]; frames];
        let features = anymo_motion::features::MotionFeatures {
            frames,
            joints: 1,
            root: rows.iter().flatten().copied().collect(),
            rotations: vec![0.0; frames * 6],
        };
        assert_eq!(ROOT_DIMS, 4);
        let foot = glam::Vec3::new(0.3, 0.0, 1.0);
        let seen: Vec<[f32; 3]> = root_path(&features)
            .into_iter()
            .map(|(heading, planar)| (glam::Quat::from_rotation_y(heading).inverse() * (foot - planar)).to_array())
            .collect();
        let flat: Vec<f32> = seen.into_iter().flatten().collect();
        let positions = Tensor::from_vec(flat, (1, frames, 1, 3), &Device::Cpu).unwrap();
        let root = Tensor::from_vec(features.root.clone(), (1, frames, 4), &Device::Cpu).unwrap();
        let world: Vec<f32> = world_velocities(&positions, &root).unwrap().flatten_all().unwrap().to_vec1().unwrap();
        assert!(world.iter().all(|v| v.abs() < 1e-5), "{world:?}");
        let local: Vec<f32> = velocities(&positions).unwrap().flatten_all().unwrap().to_vec1().unwrap();
        assert!(local.iter().any(|v| v.abs() > 0.05), "seen from the root it moves: {local:?}");
    }

    #[test]
    fn trajectory_integrates_turns_and_steps_like_the_features_do() {
        // A quarter turn and one unit forward (+Z of the heading frame) per frame; the last two
        // frames are padding, so the last frame must not move on from the one before it.
        let rows = [[FRAC_PI_2, 0.0, 1.0, 0.5]; 5];
        let root = Tensor::new(&rows, &Device::Cpu).unwrap().unsqueeze(0).unwrap();
        let mask = Tensor::new(&[[1f32, 1.0, 1.0, 0.0, 0.0]], &Device::Cpu).unwrap();
        let (heading, path) = trajectory(&root, &mask).unwrap();
        let heading: Vec<f32> = heading.flatten_all().unwrap().to_vec1().unwrap();
        let path: Vec<f32> = path.flatten_all().unwrap().to_vec1().unwrap();
        let expected_heading = [0.0, FRAC_PI_2, 2.0 * FRAC_PI_2, 3.0 * FRAC_PI_2, 3.0 * FRAC_PI_2];
        // Facing +Z, then +X, then -Z: (x, z) per frame; padding adds nothing.
        let expected_path = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 0.0, 1.0, 0.0];
        assert_eq!((heading.len(), path.len()), (5, 10));
        for (got, want) in heading.iter().zip(expected_heading).chain(path.iter().zip(expected_path)) {
            assert!((got - want).abs() < 1e-5, "{heading:?} {path:?}");
        }
    }
}
