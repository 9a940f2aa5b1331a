//! Loading any trained codec (TAT, its ablations, the baseline) by checkpoint name, and the
//! skeleton graphs they read skeletons through.

use crate::card::CodecCard;
use crate::checkpoint::Checkpoint;
use crate::data::{ModelClip, topology};
use anyhow::Result;
use anymo_motion::skeleton::Skeleton;
use anymo_tokenizer::nn::ModelCard;
use anymo_tokenizer::owo::SkeletonGraph;
use anymo_tokenizer::tat::{Baseline, Basis, Codec, Representation};
use anymo_tokenizer::text::CachedEncoder;
use std::collections::{BTreeMap, HashMap};

/// Loads a codec checkpoint (`tat`, `tat-additive`, `tat-scratch`, `baseline`, ...).
pub fn load(checkpoint: &Checkpoint, encoder: &mut CachedEncoder) -> Result<(Box<dyn Codec>, ModelCard<CodecCard>)> {
    let card: ModelCard<CodecCard> = checkpoint.card("a tokenizer or the baseline")?;
    let codec: Box<dyn Codec> = match &card.config {
        CodecCard::Baseline(config) => {
            let mut codec = Baseline::new(config.baseline.clone(), 0)?;
            let rest = checkpoint.load_into(codec.params_mut())?;
            codec.restore_buffers(&rest)?;
            Box::new(codec)
        }
        CodecCard::Tokenizer(_) => Box::new(checkpoint.load_tat(encoder)?.0),
    };
    Ok((codec, card))
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

/// The basis a codec of `representation` reads each skeleton of `clips` in, by topology (see
/// [`crate::data::topology`]): for the reference representation, the mean pose of all of that
/// skeleton's clips. Training, tokenizing a corpus for the generators and measuring on seen
/// rigs all read a skeleton in the same basis this way.
pub fn bases_by_topology(
    representation: Representation,
    clips: &[&ModelClip],
) -> BTreeMap<Vec<(Option<usize>, String)>, Basis> {
    let mut by_topology: BTreeMap<_, Vec<&ModelClip>> = BTreeMap::new();
    for c in clips {
        by_topology.entry(topology(&c.motion)).or_default().push(c);
    }
    by_topology
        .into_iter()
        .map(|(key, members)| {
            let skeleton = members[0].motion.skeleton();
            (key, Basis::of(representation, skeleton, members.iter().map(|c| &c.motion)))
        })
        .collect()
}
