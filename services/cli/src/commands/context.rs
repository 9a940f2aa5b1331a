//! What the commands share: where the store, the sentence encoder and the checkpoints are (as
//! `anymo_paths` resolves them, so the binary works from any folder), and a runtime.

use anyhow::{Context, Result};
use anymo_models::checkpoint::{Checkpoint, Checkpoints};
use anymo_models::quality::QualityReport;
use anymo_motion::cleanup::Cleanup;
use anymo_store::Store;
use anymo_tokenizer::text::SentenceEncoder;
use std::path::PathBuf;

/// The checkpoints compiled into this binary (every checkpoint of the repository's
/// `checkpoints/` when it was built).
static BUILT_IN: &[anymo_models::checkpoint::BuiltIn] = include!(concat!(env!("OUT_DIR"), "/built_in.rs"));

/// Options shared by the commands that use the store.
#[derive(clap::Args, Clone)]
pub struct StoreArgs {
    /// The data directory: the SQLite store, the search index, upload scratch and training runs
    /// [default: $ANYMO_DATA_DIR, else anymo/ in your data directory, ~/.local/share/anymo]
    #[arg(long, global = true)]
    pub data_dir: Option<PathBuf>,
    /// A database URL (sqlite://PATH or postgres://...) instead of the data directory's SQLite file.
    #[arg(long, global = true, env = "DATABASE_URL")]
    pub database_url: Option<String>,
}

impl StoreArgs {
    /// The data directory.
    pub fn data_dir(&self) -> Result<PathBuf> {
        Ok(anymo_paths::data_dir(self.data_dir.as_deref())?)
    }

    /// Opens the store, creating and migrating it as needed.
    pub async fn open(&self) -> Result<Store> {
        let url = match &self.database_url {
            Some(url) => url.clone(),
            None => Store::default_url(&self.data_dir()?),
        };
        Store::open(&url).await.with_context(|| format!("opening the store at {url}"))
    }

    /// Loads the sentence encoder (`$ANYMO_MODELS`, else where `tools/setup.sh` installs it).
    pub fn encoder(&self) -> Result<SentenceEncoder> {
        Ok(SentenceEncoder::load(anymo_paths::encoder_dir()?)?)
    }
}

/// Which checkpoints a command reads.
#[derive(clap::Args, Clone)]
pub struct CheckpointArgs {
    /// A folder of checkpoints to use instead of those built into anymo
    /// [default: $ANYMO_CHECKPOINTS, else checkpoints/ beside the binary, else the built-in ones]
    #[arg(long)]
    pub checkpoints: Option<PathBuf>,
}

impl CheckpointArgs {
    /// The checkpoints to read.
    pub fn set(&self) -> Checkpoints {
        checkpoints(self.checkpoints.as_deref())
    }
}

/// The checkpoints in `given`, else as [`anymo_paths::checkpoints_dir`] finds them, else the
/// built-in ones.
pub fn checkpoints(given: Option<&std::path::Path>) -> Checkpoints {
    anymo_paths::checkpoints_dir(given).map_or(Checkpoints::BuiltIn(BUILT_IN), Checkpoints::Dir)
}

/// The folder a command that writes checkpoints (training, `eval --record`) works in: the one
/// given, else `$ANYMO_CHECKPOINTS` or `checkpoints/` beside the binary.
pub fn writable_checkpoints(given: Option<&std::path::Path>, option: &str) -> Result<PathBuf> {
    anymo_paths::checkpoints_dir(given).with_context(|| {
        format!(
            "this command writes checkpoints and model cards to a folder: pass {option} DIR (the repository's \
             checkpoints/ to replace the shipped ones) or set {}",
            anymo_paths::CHECKPOINTS_ENV
        )
    })
}

/// How motion the models decode is finished, and what its quality report compares with
/// (generate, edit, detokenize and transfer).
#[derive(clap::Args, Clone)]
pub struct FinishArgs {
    /// Give the decoder's motion as it is: no smoothing and no foot planting
    #[arg(long)]
    pub no_cleanup: bool,
    /// Leave the prompt score out of the quality report of generated motion (it costs one pass
    /// of the tokenizer's encoder over the motion)
    #[arg(long)]
    pub no_score: bool,
    /// The evaluator checkpoint whose card holds real clips' figures per skeleton, and which
    /// scores generated motion against its prompt [default: evaluator, when the checkpoints
    /// have one; without it the reports have no real clips' figures and no prompt score]
    #[arg(long)]
    pub evaluator: Option<String>,
}

impl FinishArgs {
    /// The cleanup asked for.
    pub fn cleanup(&self) -> Option<Cleanup> {
        (!self.no_cleanup).then(Cleanup::default)
    }

    /// The evaluator to report with: the one asked for (loading it says if it is missing), or
    /// the set's `evaluator` when there is one.
    pub fn evaluator(&self, set: &Checkpoints) -> Option<Checkpoint> {
        match &self.evaluator {
            Some(name) => Some(set.get(name)),
            None => Some(set.get("evaluator")).filter(Checkpoint::exists),
        }
    }
}

/// Prints one line of JSON on standard output for each file written: its path and the motion's
/// quality report.
pub fn print_reports<'a>(made: impl IntoIterator<Item = (&'a std::path::Path, &'a QualityReport)>) -> Result<()> {
    for (path, quality) in made {
        println!("{}", serde_json::json!({ "output": path, "quality": quality }));
    }
    Ok(())
}

/// A single-threaded async runtime for one command.
pub fn runtime() -> Result<tokio::runtime::Runtime> {
    Ok(tokio::runtime::Builder::new_current_thread().enable_all().build()?)
}
