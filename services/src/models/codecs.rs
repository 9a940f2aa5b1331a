//! Loading any trained codec (TAT, its ablations, the baseline) by checkpoint name, and the
//! skeleton graphs they read skeletons through.

use super::shipped;
use anyhow::{Context, Result};
use anymo_tokenizer::nn::ModelCard;
use anymo_tokenizer::owo::SkeletonGraph;
use anymo_tokenizer::skeleton::Skeleton;
use anymo_tokenizer::tat::{Baseline, BaselineConfig, Codec};
use anymo_tokenizer::text::CachedEncoder;
use std::collections::HashMap;
use std::path::Path;

/// Loads the codec named `name` (`tat`, `tat-additive`, `tat-scratch`, `baseline`, ...) from `dir`.
pub fn load(dir: &Path, name: &str, encoder: &mut CachedEncoder) -> Result<(Box<dyn Codec>, ModelCard)> {
    let card = shipped::card(dir, name)?;
    if card.config.get("baseline").is_some() {
        let config: BaselineConfig = serde_json::from_value(card.config["baseline"].clone())
            .with_context(|| format!("model card of {name} has no baseline configuration"))?;
        let mut codec = Baseline::new(config, 0)?;
        let rest = codec.params_mut().load(&shipped::files(dir, name).0)?;
        codec.restore_buffers(&rest)?;
        return Ok((Box::new(codec), card));
    }
    let (tat, card) = shipped::load_tat(dir, name, encoder)?;
    Ok((Box::new(tat), card))
}

/// Skeleton graphs by topology, embedded once.
pub struct Graphs<'a> {
    encoder: &'a mut CachedEncoder,
    cache: HashMap<Vec<(Option<usize>, String)>, SkeletonGraph>,
}

impl<'a> Graphs<'a> {
    /// An empty cache over an encoder.
    pub fn new(encoder: &'a mut CachedEncoder) -> Graphs<'a> {
        Graphs { encoder, cache: HashMap::new() }
    }

    /// The graph of a skeleton.
    pub fn of(&mut self, skeleton: &Skeleton) -> Result<SkeletonGraph> {
        let key: Vec<_> = skeleton.joints().iter().map(|j| (j.parent, j.name.clone())).collect();
        if let Some(g) = self.cache.get(&key) {
            let mut g = g.clone();
            let scale = 1.0 / skeleton.diameter().max(1e-6);
            g.offsets = skeleton.joints().iter().map(|j| j.offset * scale).collect();
            return Ok(g);
        }
        let g = SkeletonGraph::new(skeleton, self.encoder)?;
        self.cache.insert(key, g.clone());
        Ok(g)
    }
}
