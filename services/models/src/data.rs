//! Clips for the models: read from a manifest, cleaned (NEC appendix B), resampled to the
//! models' frame rate, with their split.

use anymo_motion::bvh;
use anymo_motion::motion::Motion;
use anymo_motion::prep::clean::{CleanOptions, clean};
use anymo_store::ingest::{IngestError, Item, items_from_manifest};
use anymo_tokenizer::dataset::{Split, split_of};
use anymo_tokenizer::nn::checkpoint::DataRecord;
use std::collections::BTreeSet;
use std::path::Path;

/// Frame rate the models work at.
pub const MODEL_FPS: f64 = 30.0;

/// One clip ready for a model.
pub struct ModelClip {
    /// The manifest item.
    pub item: Item,
    /// Which split it belongs to.
    pub split: Split,
    /// Cleaned, diameter 1, at [`MODEL_FPS`].
    pub motion: Motion,
}

/// Reads every usable clip of a manifest (at most `limit` per split when given), skipping those
/// cleaning rejects. Returns the clips and how many were rejected.
pub fn load_manifest(manifest: &Path, limit: Option<usize>) -> Result<(Vec<ModelClip>, usize), IngestError> {
    let items = items_from_manifest(manifest)?;
    let mut counts = std::collections::HashMap::new();
    let chosen: Vec<(Item, Split)> = items
        .into_iter()
        .filter_map(|item| {
            let split = split_of(&item.key);
            let n = counts.entry(split).or_insert(0usize);
            *n += 1;
            (limit.is_none_or(|l| *n <= l)).then_some((item, split))
        })
        .collect();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let per = chosen.len().div_ceil(threads).max(1);
    let results: Vec<Option<ModelClip>> = std::thread::scope(|scope| {
        let handles: Vec<_> = chosen
            .chunks(per)
            .map(|part| {
                scope.spawn(move || part.iter().map(|(item, split)| read_clip(item, *split)).collect::<Vec<_>>())
            })
            .collect();
        handles.into_iter().flat_map(|h| h.join().expect("a reading thread panicked")).collect()
    });
    let rejected = results.iter().filter(|r| r.is_none()).count();
    Ok((results.into_iter().flatten().collect(), rejected))
}

fn read_clip(item: &Item, split: Split) -> Option<ModelClip> {
    let clip = bvh::read_path(&item.file, bvh::ReadOptions { require_motion: true }).ok()?;
    let motion = Motion::from_bvh(&clip);
    let cleaned = clean(&motion, &CleanOptions::default()).ok()?;
    let motion = cleaned.motion.resample(MODEL_FPS);
    (motion.frames() >= 8).then_some(ModelClip { item: item.clone(), split, motion })
}

/// The topology key of a skeleton: parents and names.
pub fn topology(motion: &Motion) -> Vec<(Option<usize>, String)> {
    motion.skeleton().joints().iter().map(|j| (j.parent, j.name.clone())).collect()
}

/// What a model trained on `clips` records about its data.
pub fn data_record(manifest: &Path, clips: &[&ModelClip]) -> DataRecord {
    let hash = std::fs::read(manifest).map(|b| blake3::hash(&b).to_hex().to_string()).unwrap_or_default();
    let licences: BTreeSet<String> = clips.iter().map(|c| c.item.licence.clone()).collect();
    let skeletons: BTreeSet<_> = clips.iter().map(|c| topology(&c.motion)).collect();
    DataRecord {
        source: manifest.display().to_string(),
        manifest_blake3: hash,
        licences: licences.into_iter().collect(),
        clips: clips.len(),
        skeletons: skeletons.len(),
    }
}
