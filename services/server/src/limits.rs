//! What one request may ask of the server. Every limit is refused with its value in the
//! message, so a client knows what to change.

use super::error::ApiError;
use std::time::Duration;

/// The server's limits.
#[derive(Clone, Debug)]
pub struct Limits {
    /// Largest request body, in bytes.
    pub body_bytes: usize,
    /// Most joints a skeleton may have.
    pub joints: usize,
    /// Most frames an uploaded clip may have.
    pub frames: usize,
    /// Longest motion to generate, in seconds (at most the models' 30 s).
    pub seconds: f64,
    /// Most samples one generation may draw.
    pub samples: usize,
    /// Most files one ingest upload may carry.
    pub files: usize,
    /// Requests that may wait for the generation workers; more are answered 429.
    pub queue: usize,
    /// Generation workers (each loads its own models and runs one request at a time).
    pub workers: usize,
    /// Search models' threads (each loads its own encoder and embeds one batch at a time).
    pub search_workers: usize,
    /// Longest a request may take, waiting included.
    pub timeout: Duration,
}

impl Default for Limits {
    fn default() -> Limits {
        Limits {
            body_bytes: 32 << 20,
            joints: 256,
            frames: 36_000,
            seconds: anymo_models::studio::MAX_SECONDS,
            samples: 8,
            files: 1_000,
            queue: 16,
            workers: cores(),
            search_workers: cores(),
            timeout: Duration::from_secs(120),
        }
    }
}

/// The cores this process may use: `anymo serve` runs each model call on one thread and as many
/// workers as cores, which keeps more of the machine busy than one call on every core.
fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
}

impl Limits {
    /// Refuses a duration outside `(0, seconds]`.
    pub fn check_seconds(&self, seconds: f64) -> Result<(), ApiError> {
        if !seconds.is_finite() || seconds <= 0.0 {
            return Err(ApiError::bad_request(format!("seconds must be a positive number; {seconds} was asked")));
        }
        if seconds > self.seconds {
            return Err(ApiError::over_limit("motion length", format!("{} s", self.seconds), format!("{seconds} s")));
        }
        Ok(())
    }

    /// Refuses a sample count outside `1..=samples`.
    pub fn check_samples(&self, samples: usize) -> Result<(), ApiError> {
        if samples == 0 {
            return Err(ApiError::bad_request("samples must be at least 1"));
        }
        if samples > self.samples {
            return Err(ApiError::over_limit("samples per request", self.samples, samples));
        }
        Ok(())
    }

    /// Refuses a skeleton with too many joints, or a clip with too many frames.
    pub fn check_clip(&self, what: &str, joints: usize, frames: usize) -> Result<(), ApiError> {
        if joints > self.joints {
            return Err(ApiError::over_limit(&format!("joints of {what}"), self.joints, joints));
        }
        if frames > self.frames {
            return Err(ApiError::over_limit(&format!("frames of {what}"), self.frames, frames));
        }
        Ok(())
    }
}
