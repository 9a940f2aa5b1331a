//! What the search engine knows about a clip: the text it is found by and the metadata it is
//! filtered and shown by. The store owns clips; this is the engine's copy of what it needs.

use serde::{Deserialize, Serialize};

/// One searchable clip.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClipDocument {
    /// The clip's id in the store.
    pub id: u64,
    /// The clip's path as ingested.
    pub path: String,
    /// Its captions, in order.
    pub captions: Vec<String>,
    /// Species or "person".
    pub subject: String,
    /// Source dataset.
    pub source: String,
    /// Licence identifier (SPDX where the source gives one).
    pub licence: String,
    /// Topology fingerprint of its skeleton.
    pub skeleton: String,
    /// Semantic labels of the skeleton's joints ("left hind foot", ...).
    pub joint_labels: Vec<String>,
    /// Duration in seconds.
    pub seconds: f64,
}
