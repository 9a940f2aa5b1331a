//! Where anymo finds its files, decided at run time so that the binary works from any folder
//! and after it is copied or installed elsewhere. This is the one place that knows:
//! - the data folder (the default SQLite store, the search index, upload scratch):
//!   `--data-dir`, else `$ANYMO_DATA_DIR`, else `anymo/` in the user's data directory
//!   (`$XDG_DATA_HOME`, usually `~/.local/share`);
//! - the sentence encoder: `$ANYMO_MODELS/all-MiniLM-L6-v2`, else `models/all-MiniLM-L6-v2`
//!   in that default data folder, which is where `tools/setup.sh` puts it;
//! - a checkpoints folder: `--checkpoints`, else `$ANYMO_CHECKPOINTS`, else `checkpoints/`
//!   beside the binary; when there is none, the binary uses the checkpoints built into it.
//!
//! Nothing here reads the current folder, so `cd /tmp && anymo ...` finds the same files.

use std::path::{Path, PathBuf};

/// Overrides the data folder.
pub const DATA_DIR_ENV: &str = "ANYMO_DATA_DIR";
/// Overrides the folder that holds the sentence encoder's folder.
pub const MODELS_ENV: &str = "ANYMO_MODELS";
/// Overrides the checkpoints the binary carries with a folder of them.
pub const CHECKPOINTS_ENV: &str = "ANYMO_CHECKPOINTS";
/// The sentence encoder's folder name under the models folder.
pub const ENCODER_DIR_NAME: &str = "all-MiniLM-L6-v2";

/// Why a default location could not be worked out.
#[derive(Debug, thiserror::Error)]
pub enum PathError {
    /// Neither the environment nor the system names a home folder.
    #[error(
        "cannot find your home folder to keep anymo's data in ({0}); set {DATA_DIR_ENV} (or pass --data-dir) \
         and {MODELS_ENV}"
    )]
    NoHome(String),
}

/// The data folder when no `--data-dir` is given: `$ANYMO_DATA_DIR`, else the user's data
/// directory's `anymo/`.
pub fn default_data_dir() -> Result<PathBuf, PathError> {
    if let Some(dir) = env_path(DATA_DIR_ENV) {
        return Ok(dir);
    }
    user_data_dir()
}

/// The data folder: the one given (by a flag), else [`default_data_dir`].
pub fn data_dir(given: Option<&Path>) -> Result<PathBuf, PathError> {
    match given {
        Some(dir) => Ok(dir.to_path_buf()),
        None => default_data_dir(),
    }
}

/// The folder holding the sentence encoder's folder: `$ANYMO_MODELS`, else `models/` in the
/// user's anymo data directory (where `tools/setup.sh` installs it).
pub fn models_dir() -> Result<PathBuf, PathError> {
    match env_path(MODELS_ENV) {
        Some(dir) => Ok(dir),
        None => Ok(user_data_dir()?.join("models")),
    }
}

/// The sentence encoder's own folder (`model.safetensors`, `tokenizer.json`, `config.json`).
pub fn encoder_dir() -> Result<PathBuf, PathError> {
    Ok(models_dir()?.join(ENCODER_DIR_NAME))
}

/// A folder of checkpoints to use instead of the built-in ones: the one given (by a flag), else
/// `$ANYMO_CHECKPOINTS`, else `checkpoints/` beside the running binary if it exists. `None`
/// means the built-in checkpoints.
pub fn checkpoints_dir(given: Option<&Path>) -> Option<PathBuf> {
    if let Some(dir) = given {
        return Some(dir.to_path_buf());
    }
    if let Some(dir) = env_path(CHECKPOINTS_ENV) {
        return Some(dir);
    }
    let exe = std::env::current_exe().ok()?;
    let beside = exe.parent()?.join("checkpoints");
    beside.is_dir().then_some(beside)
}

/// `anymo/` in the user's data directory (`$XDG_DATA_HOME`, else `~/.local/share`).
fn user_data_dir() -> Result<PathBuf, PathError> {
    use etcetera::BaseStrategy;
    let strategy = etcetera::choose_base_strategy().map_err(|e| PathError::NoHome(e.to_string()))?;
    Ok(strategy.data_dir().join("anymo"))
}

/// An environment variable as a path, unless unset or empty.
fn env_path(name: &str) -> Option<PathBuf> {
    std::env::var_os(name).filter(|v| !v.is_empty()).map(PathBuf::from)
}
