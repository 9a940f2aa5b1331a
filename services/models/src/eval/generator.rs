//! The generation evaluation of EVAL.md (MoMask's protocol, NEC appendix D): each test clip's
//! caption generated on the clip's own skeleton at the clip's length, scored by the evaluator
//! beside the real motion (the GT row, the ceiling): R-Precision top-1/2/3 in groups of 32,
//! FID, MM-Dist, foot skating and ground penetration, for all clips, humans and animals.

use super::Table;
use super::tokenizer::{CONTACT_HEIGHT, FOOT_BAND};
use crate::checkpoint::Checkpoints;
use crate::codecs::{Graphs, bases_by_topology};
use crate::data::{ModelClip, topology};
use crate::generation::{self, is_human, token_clips};
use anyhow::Result;
use anymo_generator::evaluator::{fid, mm_dist, r_precision};
use anymo_generator::generate::Codes;
use anymo_generator::sampling::Sampling;
use anymo_generator::{Evaluator, Generator, Request};
use anymo_motion::features::foot_joints;
use anymo_motion::kinematics::all_joint_positions;
use anymo_motion::metrics::{foot_skating, ground_penetration};
use anymo_motion::motion::Motion;
use anymo_tokenizer::tat::Tat;
use anymo_tokenizer::tat::window::{Tokens, detokenize, encode_whole};
use anymo_tokenizer::text::CachedEncoder;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// The row of the real clips' own tokens decoded: the tokenizer's ceiling for any generator.
pub const TOKENIZER_ROW: &str = "GT tokens";

/// R-Precision's group size (one true caption among 31 others).
pub const GROUP: usize = 32;

/// One row of the table.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Row {
    /// `GT` or the generator's checkpoint name.
    pub model: String,
    /// Which clips: `all`, `humans` or `animals`.
    pub subset: String,
    /// Clips scored.
    pub clips: usize,
    /// R-Precision top-1, top-2, top-3.
    pub r_precision: [f32; 3],
    /// FID against the real motions' embeddings (0 for GT).
    pub fid: f64,
    /// Mean motion-to-caption distance.
    pub mm_dist: f32,
    /// Foot skating, diameters per second.
    pub foot_skating: f32,
    /// Ground penetration, diameters.
    pub ground_penetration: f32,
    /// Mean seconds to generate and decode one clip (0 for GT).
    pub seconds_per_clip: f64,
}

struct Scored {
    motion: Vec<f32>,
    text: Vec<f32>,
    fs: f32,
    gp: f32,
    human: bool,
}

fn foot_figures(motion: &Motion) -> (f32, f32) {
    let positions = all_joint_positions(motion);
    let feet = foot_joints(motion, FOOT_BAND);
    let n = motion.skeleton().len();
    (foot_skating(&positions, n, &feet, motion.fps() as f32, CONTACT_HEIGHT), ground_penetration(&positions))
}

/// A generator under evaluation: its name, the model, and the tokenizer it was trained on, which
/// decodes its codes (the evaluator's tokenizer then encodes the motion, as it does real clips).
struct Candidate<'a> {
    /// The checkpoint name, for the table.
    pub name: String,
    /// The model.
    pub generator: &'a Generator,
    /// The tokenizer its codes belong to.
    pub tokenizer: &'a Tat,
}

/// Scores the real test motions and each generator's motions for the same captions; `tat` is
/// the tokenizer the evaluator reads.
fn evaluate(
    tat: &mut Tat,
    evaluator: &Evaluator,
    generators: &[Candidate],
    test: &[&ModelClip],
    encoder: &mut CachedEncoder,
    sampling: Sampling,
    seed: u64,
) -> Result<Vec<Row>> {
    let mut clips = token_clips(test, tat, encoder, false)?;
    let mut order: Vec<usize> = (0..clips.len()).collect();
    order.shuffle(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed));
    clips = order.iter().map(|&i| clips[i].clone()).collect();
    let motions: Vec<&ModelClip> = order.iter().map(|&i| test[i]).collect();
    let max = evaluator.config().max_tokens;
    let per_token = tat.config().tat.frames_per_token();
    let latent_dim = evaluator.config().latent_dim;

    let mut truth = Vec::with_capacity(clips.len());
    for (clip, model_clip) in clips.iter().zip(&motions) {
        let steps = clip.steps().min(max);
        let frames = (steps * per_token).min(model_clip.motion.frames());
        let (fs, gp) = foot_figures(&model_clip.motion.slice(0, frames));
        truth.push(Scored {
            motion: evaluator.embed_one(&clip.latent[..steps * latent_dim])?,
            text: evaluator.embed_sentence(&clip.text[0])?,
            fs,
            gp,
            human: is_human(&clip.subject),
        });
    }
    let mut rows = table("GT", &truth, &truth, 0.0);

    // Each model's codes (or the real clip's own, for the tokenizer's row) decoded on the clip's
    // skeleton by the tokenizer they belong to, re-encoded and scored like the real motion.
    let bases = bases_by_topology(tat.config().representation, test);
    let mut score = |codes: Codes, i: usize, decoder: Option<&Tat>, tat: &mut Tat| -> Result<Scored> {
        let skeleton = &bases[&topology(&motions[i].motion)].enter_skeleton(&motions[i].motion);
        let graph = Graphs::new(encoder).of(skeleton)?;
        let tokens = Tokens::whole(codes, per_token, motions[i].motion.fps());
        let motion = detokenize(decoder.unwrap_or(&*tat), &tokens, &graph, skeleton)?;
        let encoded = encode_whole(tat, &graph, &motion)?;
        let (fs, gp) = foot_figures(&motion);
        Ok(Scored {
            motion: evaluator.embed_one(&encoded.latent)?,
            text: truth[i].text.clone(),
            fs,
            gp,
            human: truth[i].human,
        })
    };
    let started = Instant::now();
    let mut decoded = Vec::with_capacity(clips.len());
    for (i, clip) in clips.iter().enumerate() {
        decoded.push(score(clip.codes[..clip.steps().min(max)].to_vec(), i, None, tat)?);
    }
    let seconds = started.elapsed().as_secs_f64() / clips.len().max(1) as f64;
    rows.extend(table(TOKENIZER_ROW, &decoded, &truth, seconds));

    for Candidate { name, generator, tokenizer } in generators {
        let started = Instant::now();
        let mut generated = Vec::with_capacity(clips.len());
        for (i, clip) in clips.iter().enumerate() {
            let steps = clip.steps().min(max).min(generator.config().max_tokens());
            let request = Request { steps: Some(steps), samples: 1, sampling, seed: seed.wrapping_add(i as u64) };
            let codes = generator.generate(&clip.text[0], &clip.skeleton, &request)?.remove(0);
            generated.push(score(codes, i, Some(*tokenizer), tat)?);
        }
        let seconds = started.elapsed().as_secs_f64() / clips.len().max(1) as f64;
        rows.extend(table(name, &generated, &truth, seconds));
    }
    Ok(rows)
}

/// Which scored clips a row covers.
type Subset = fn(&Scored) -> bool;

fn table(model: &str, scored: &[Scored], truth: &[Scored], seconds: f64) -> Vec<Row> {
    let subsets: [(&str, Subset); 3] = [("all", |_| true), ("humans", |s| s.human), ("animals", |s| !s.human)];
    subsets
        .iter()
        .filter_map(|(subset, keep)| {
            let chosen: Vec<&Scored> = scored.iter().filter(|s| keep(s)).collect();
            let real: Vec<&Scored> = truth.iter().filter(|s| keep(s)).collect();
            if chosen.len() < 2 {
                return None;
            }
            let motions: Vec<Vec<f32>> = chosen.iter().map(|s| s.motion.clone()).collect();
            let texts: Vec<Vec<f32>> = chosen.iter().map(|s| s.text.clone()).collect();
            let real_motions: Vec<Vec<f32>> = real.iter().map(|s| s.motion.clone()).collect();
            let n = chosen.len() as f32;
            Some(Row {
                model: model.to_string(),
                subset: subset.to_string(),
                clips: chosen.len(),
                r_precision: r_precision(&motions, &texts, GROUP.min(chosen.len())),
                fid: fid(&motions, &real_motions),
                mm_dist: mm_dist(&motions, &texts),
                foot_skating: chosen.iter().map(|s| s.fs).sum::<f32>() / n,
                ground_penetration: chosen.iter().map(|s| s.gp).sum::<f32>() / n,
                seconds_per_clip: seconds,
            })
        })
        .collect()
}

/// Loads the evaluator `evaluator` and each generator of `models` from `set` (each with the
/// tokenizer its card names) and scores them on `test` (see [`evaluate`]).
pub fn evaluate_generators(
    set: &Checkpoints,
    evaluator: &str,
    models: &[String],
    test: &[&ModelClip],
    encoder: &mut CachedEncoder,
    sampling: Sampling,
    seed: u64,
) -> Result<Vec<Row>> {
    let evaluator_checkpoint = set.get(evaluator);
    let (evaluator, evaluator_card) = generation::load_evaluator(&evaluator_checkpoint)?;
    let mut tat = evaluator_checkpoint.load_tat_of(&evaluator_card, encoder)?;
    let mut loaded = Vec::new();
    for name in models {
        let checkpoint = set.get(name);
        let (generator, card) = generation::load_generator(&checkpoint)?;
        let tokenizer = checkpoint.load_tat_of(&card, encoder)?;
        eprintln!("{name}: {} steps", card.steps);
        loaded.push((name.clone(), generator, tokenizer));
    }
    let candidates: Vec<Candidate> = loaded
        .iter()
        .map(|(name, generator, tokenizer)| Candidate { name: name.clone(), generator, tokenizer })
        .collect();
    evaluate(&mut tat, &evaluator, &candidates, test, encoder, sampling, seed)
}

/// The rows as a Markdown table.
pub fn markdown(rows: &[Row]) -> String {
    let mut table = Table::new(&["model", "clips", "R@1", "R@2", "R@3", "FID", "MM-Dist", "FS", "GP", "s/clip"]);
    fn three(x: impl std::fmt::Display) -> String {
        format!("{x:.3}")
    }
    for r in rows {
        table.row(&[
            format!("{} ({})", r.model, r.subset),
            r.clips.to_string(),
            three(r.r_precision[0]),
            three(r.r_precision[1]),
            three(r.r_precision[2]),
            three(r.fid),
            three(r.mm_dist),
            format!("{:.4}", r.foot_skating),
            format!("{:.4}", r.ground_penetration),
            three(r.seconds_per_clip),
        ]);
    }
    table.into_text()
}
