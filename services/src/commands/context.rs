//! Where a command finds the store and the models: `--data-dir` (or `ANYMO_DATA_DIR`, default
//! `anymo-data`), `DATABASE_URL` for another database, `ANYMO_MODELS` for another model folder.

use anyhow::{Context, Result};
use anymo_services::store::Store;
use anymo_tokenizer::text::{MODEL_DIR_NAME, SentenceEncoder};
use std::path::PathBuf;

/// Options shared by the commands that use the store.
#[derive(clap::Args, Clone)]
pub struct StoreArgs {
    /// The data directory (SQLite store, models).
    #[arg(long, global = true, env = "ANYMO_DATA_DIR", default_value = "anymo-data")]
    pub data_dir: PathBuf,
    /// A database URL (sqlite://PATH or postgres://...) instead of the data directory's SQLite file.
    #[arg(long, global = true, env = "DATABASE_URL")]
    pub database_url: Option<String>,
}

impl StoreArgs {
    /// Opens the store, creating and migrating it as needed.
    pub async fn open(&self) -> Result<Store> {
        let url = self.database_url.clone().unwrap_or_else(|| Store::default_url(&self.data_dir));
        Store::open(&url).await.with_context(|| format!("opening the store at {url}"))
    }

    /// Loads the sentence encoder from `$ANYMO_MODELS` or the data directory's models folder.
    pub fn encoder(&self) -> Result<SentenceEncoder> {
        let base = std::env::var_os("ANYMO_MODELS").map_or_else(|| self.data_dir.join("models"), PathBuf::from);
        Ok(SentenceEncoder::load(base.join(MODEL_DIR_NAME))?)
    }
}

/// A single-threaded async runtime for one command.
pub fn runtime() -> Result<tokio::runtime::Runtime> {
    Ok(tokio::runtime::Builder::new_current_thread().enable_all().build()?)
}
