//! BVH files: a streaming reader with errors that name the line and column, and a writer whose
//! output reads back to identical numbers.
//!
//! Written here rather than taken from a crate: `bvh_anim` (0.4, alpha) is 3x slower, reads
//! whole files into memory, and its errors do not say where a file went wrong (see
//! `benches/bvh_throughput.rs`).
//!
//! ```
//! let text = "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n End Site\n {\n  OFFSET 0 1 0\n }\n}\nMOTION\nFrames: 1\nFrame Time: 0.5\n1 2 3 0 90 0\n";
//! let bvh = anymo_motion::bvh::parse_str(text).unwrap();
//! assert_eq!(bvh.frames(), 1);
//! let mut out = Vec::new();
//! anymo_motion::bvh::write(&bvh, &mut out).unwrap();
//! assert_eq!(anymo_motion::bvh::parse_str(std::str::from_utf8(&out).unwrap()).unwrap(), bvh);
//! ```

mod error;
mod read;
mod write;

pub use error::{BvhError, SyntaxError};
pub use read::{ReadOptions, parse_str, read, read_path};
pub use write::{write, write_path};

use crate::skeleton::Skeleton;

/// A BVH file as read: the skeleton, the frame time and every channel value of every frame.
///
/// Values are kept as the file's channels (f32) so that writing gives back the same numbers.
#[derive(Clone, Debug, PartialEq)]
pub struct Bvh {
    skeleton: Skeleton,
    frame_time: f64,
    frames: usize,
    values: Vec<f32>,
}

/// Why channel values do not fit a skeleton.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LayoutError {
    /// The value count is not frames x channels.
    #[error("{values} values do not fill {frames} frames of {channels} channels")]
    ValueCount {
        /// Values given.
        values: usize,
        /// Frames claimed.
        frames: usize,
        /// Channels per frame of the skeleton.
        channels: usize,
    },
    /// Frame time zero, negative or not finite.
    #[error("frame time must be a positive number of seconds, got {0}")]
    FrameTime(f64),
    /// A NaN or infinite channel value.
    #[error("channel value {index} is not finite")]
    NonFinite {
        /// Index into the flat value array.
        index: usize,
    },
}

impl Bvh {
    /// Builds a file from a skeleton and `frames` rows of `skeleton.channel_count()` values.
    pub fn new(skeleton: Skeleton, frame_time: f64, frames: usize, values: Vec<f32>) -> Result<Bvh, LayoutError> {
        let channels = skeleton.channel_count();
        if values.len() != frames * channels {
            return Err(LayoutError::ValueCount { values: values.len(), frames, channels });
        }
        if !(frame_time.is_finite() && frame_time > 0.0) {
            return Err(LayoutError::FrameTime(frame_time));
        }
        if let Some(index) = values.iter().position(|v| !v.is_finite()) {
            return Err(LayoutError::NonFinite { index });
        }
        Ok(Bvh { skeleton, frame_time, frames, values })
    }

    /// The skeleton.
    pub fn skeleton(&self) -> &Skeleton {
        &self.skeleton
    }

    /// Seconds per frame, as the file gave it.
    pub fn frame_time(&self) -> f64 {
        self.frame_time
    }

    /// Frames per second.
    pub fn fps(&self) -> f64 {
        1.0 / self.frame_time
    }

    /// The number of frames (zero for a skeleton-only file).
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// The channel values of frame `index`, in file order.
    pub fn frame(&self, index: usize) -> &[f32] {
        let n = self.skeleton.channel_count();
        &self.values[index * n..(index + 1) * n]
    }

    /// Every value of every frame, row after row.
    pub fn values(&self) -> &[f32] {
        &self.values
    }

    /// Splits the file into its skeleton and its values.
    pub fn into_parts(self) -> (Skeleton, f64, usize, Vec<f32>) {
        (self.skeleton, self.frame_time, self.frames, self.values)
    }
}
