//! Motion: per-frame local rotations and translations of every joint of a skeleton, decoded
//! from BVH channels and encoded back to them.

use crate::bvh::Bvh;
use crate::rotation::{euler_to_quat, quat_to_euler};
use crate::skeleton::{Channel, Channels, EulerOrder, Joint, Skeleton};
use glam::{Quat, Vec3};

/// A motion on a skeleton: for every frame and joint, the local rotation and the local
/// translation (the joint's offset, with any position channels replacing its components).
#[derive(Clone, Debug, PartialEq)]
pub struct Motion {
    skeleton: Skeleton,
    frame_time: f64,
    frames: usize,
    rotations: Vec<Quat>,
    translations: Vec<Vec3>,
}

/// Why arrays do not make a motion.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MotionError {
    /// Rotation or translation arrays whose length is not frames x joints.
    #[error("expected {expected} rotations and translations (frames x joints), got {rotations} and {translations}")]
    Shape {
        /// frames x joints.
        expected: usize,
        /// Rotations given.
        rotations: usize,
        /// Translations given.
        translations: usize,
    },
    /// Frame time zero, negative or not finite.
    #[error("frame time must be a positive number of seconds, got {0}")]
    FrameTime(f64),
}

impl Motion {
    /// Builds a motion from frame-major arrays of `frames x skeleton.len()` local transforms.
    pub fn new(
        skeleton: Skeleton,
        frame_time: f64,
        rotations: Vec<Quat>,
        translations: Vec<Vec3>,
    ) -> Result<Motion, MotionError> {
        let joints = skeleton.len();
        let frames = rotations.len() / joints;
        if rotations.len() != frames * joints || translations.len() != rotations.len() {
            return Err(MotionError::Shape {
                expected: frames * joints,
                rotations: rotations.len(),
                translations: translations.len(),
            });
        }
        if !(frame_time.is_finite() && frame_time > 0.0) {
            return Err(MotionError::FrameTime(frame_time));
        }
        Ok(Motion { skeleton, frame_time, frames, rotations, translations })
    }

    /// Decodes the channels of a BVH file (Euler angles compose in the file's channel order).
    pub fn from_bvh(bvh: &Bvh) -> Motion {
        let skeleton = bvh.skeleton().clone();
        let joints = skeleton.len();
        let mut rotations = Vec::with_capacity(bvh.frames() * joints);
        let mut translations = Vec::with_capacity(bvh.frames() * joints);
        let orders: Vec<_> = skeleton.joints().iter().map(|j| j.channels.euler_order()).collect();
        for frame in 0..bvh.frames() {
            let mut values = bvh.frame(frame).iter();
            for (joint, order) in skeleton.joints().iter().zip(&orders) {
                let mut translation = joint.offset;
                let mut angles = [0.0f32; 3];
                let axes = order.axes();
                for channel in joint.channels.as_slice() {
                    let v = *values.next().expect("a frame holds every channel");
                    match channel {
                        Channel::Position(axis) => translation[axis.index()] = v,
                        Channel::Rotation(axis) => {
                            let slot = axes.iter().position(|a| a == axis).expect("order covers every axis");
                            angles[slot] = v;
                        }
                    }
                }
                rotations.push(euler_to_quat(*order, angles));
                translations.push(translation);
            }
        }
        Motion { skeleton, frame_time: bvh.frame_time(), frames: bvh.frames(), rotations, translations }
    }

    /// Encodes the motion as channel values of its skeleton's channel layout. Rotations of joints
    /// without rotation channels and translations of joints without position channels are not
    /// representable and are dropped (they are the rest pose in any motion read from a file).
    pub fn to_bvh(&self) -> Bvh {
        let skeleton = &self.skeleton;
        let mut values = Vec::with_capacity(self.frames * skeleton.channel_count());
        for frame in 0..self.frames {
            for (j, joint) in skeleton.joints().iter().enumerate() {
                let order = joint.channels.euler_order();
                let k = frame * skeleton.len() + j;
                let angles = quat_to_euler(order, self.rotations[k]);
                let axes = order.axes();
                for channel in joint.channels.as_slice() {
                    values.push(match channel {
                        Channel::Position(axis) => self.translations[k][axis.index()],
                        Channel::Rotation(axis) => {
                            angles[axes.iter().position(|a| a == axis).expect("order covers every axis")]
                        }
                    });
                }
            }
        }
        Bvh::new(skeleton.clone(), self.frame_time, self.frames, values).expect("the layout matches the skeleton")
    }

    /// The motion resampled at `fps`: rotations by slerp and translations linearly between the
    /// two nearest source frames, covering the same time span (first to last frame).
    pub fn resample(&self, fps: f64) -> Motion {
        let n = self.skeleton.len();
        if self.frames == 0 {
            return Motion { frame_time: 1.0 / fps, ..self.clone() };
        }
        let span = (self.frames - 1) as f64 * self.frame_time;
        let frames = (span * fps).round() as usize + 1;
        let mut rotations = Vec::with_capacity(frames * n);
        let mut translations = Vec::with_capacity(frames * n);
        for f in 0..frames {
            let source = (f as f64 / fps / self.frame_time).min((self.frames - 1) as f64);
            let a = source.floor() as usize;
            let b = (a + 1).min(self.frames - 1);
            let u = (source - a as f64) as f32;
            for j in 0..n {
                rotations.push(self.rotations[a * n + j].slerp(self.rotations[b * n + j], u));
                translations.push(self.translations[a * n + j].lerp(self.translations[b * n + j], u));
            }
        }
        Motion { skeleton: self.skeleton.clone(), frame_time: 1.0 / fps, frames, rotations, translations }
    }

    /// The same motion on a skeleton whose joints use `order` for their rotation channels.
    pub fn with_euler_order(&self, order: EulerOrder) -> Motion {
        let joints = self
            .skeleton
            .joints()
            .iter()
            .map(|j| {
                let has_rotation = j.channels.as_slice().iter().any(|c| matches!(c, Channel::Rotation(_)));
                let channels = match (j.channels.has_position(), has_rotation) {
                    (true, _) => Channels::position_rotation(order),
                    (false, true) => Channels::rotation(order),
                    (false, false) => j.channels.clone(),
                };
                Joint { channels, ..j.clone() }
            })
            .collect();
        let skeleton = Skeleton::new(joints).expect("same tree");
        Motion { skeleton, ..self.clone() }
    }

    /// The skeleton.
    pub fn skeleton(&self) -> &Skeleton {
        &self.skeleton
    }

    /// Seconds per frame.
    pub fn frame_time(&self) -> f64 {
        self.frame_time
    }

    /// Frames per second.
    pub fn fps(&self) -> f64 {
        1.0 / self.frame_time
    }

    /// The number of frames.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Local rotations of every joint in `frame`.
    pub fn rotations(&self, frame: usize) -> &[Quat] {
        let j = self.skeleton.len();
        &self.rotations[frame * j..(frame + 1) * j]
    }

    /// Local translations of every joint in `frame`.
    pub fn translations(&self, frame: usize) -> &[Vec3] {
        let j = self.skeleton.len();
        &self.translations[frame * j..(frame + 1) * j]
    }

    /// One frame of the skeleton's rest pose (no rotation, translations at the offsets): the
    /// motion a bare skeleton is cleaned and animated through.
    pub fn rest_pose(skeleton: &Skeleton, frame_time: f64) -> Motion {
        let translations = skeleton.joints().iter().map(|j| j.offset).collect();
        Motion::new(skeleton.clone(), frame_time, vec![Quat::IDENTITY; skeleton.len()], translations)
            .expect("one rotation and one translation per joint")
    }

    /// Frames `first..first + count` (clamped to the clip) as a motion of their own.
    pub fn slice(&self, first: usize, count: usize) -> Motion {
        let j = self.skeleton().len();
        let first = first.min(self.frames());
        let end = (first + count).min(self.frames());
        Motion::new(
            self.skeleton().clone(),
            self.frame_time(),
            self.all_rotations()[first * j..end * j].to_vec(),
            self.all_translations()[first * j..end * j].to_vec(),
        )
        .expect("a slice of a valid motion is valid")
    }
    /// All local rotations, frame-major.
    pub fn all_rotations(&self) -> &[Quat] {
        &self.rotations
    }

    /// All local translations, frame-major.
    pub fn all_translations(&self) -> &[Vec3] {
        &self.translations
    }

    /// Splits the motion into its skeleton, frame time, rotations and translations.
    pub fn into_parts(self) -> (Skeleton, f64, Vec<Quat>, Vec<Vec3>) {
        (self.skeleton, self.frame_time, self.rotations, self.translations)
    }
}
