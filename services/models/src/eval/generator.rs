//! The generation evaluation of EVAL.md (MoMask's protocol, NEC appendix D): each test clip's
//! caption generated on the clip's own skeleton at the clip's length, scored by the evaluator
//! beside the real motion (the GT row, the ceiling): R-Precision top-1/2/3 in groups of 32,
//! FID, MM-Dist and the plausibility figures of [`anymo_motion::quality`] (foot skating, foot
//! flight, ground penetration, jitter, the largest one-frame step and the body's height) and
//! the prompt score of the quality report (the cosine of motion and caption), for all clips,
//! humans and animals. Every decoded row comes twice: as the decoder gives it, and after the cleanup users
//! get by default (`+ cleanup`).

use super::{CLEANED, Table};
use crate::checkpoint::Checkpoints;
use crate::codecs::{Graphs, bases_by_topology};
use crate::data::{ModelClip, topology};
use crate::generation::{self, is_human, token_clips};
use crate::quality::{RealMotion, clean_up, cosine};
use anyhow::Result;
use anymo_generator::evaluator::{fid, mm_dist, r_precision};
use anymo_generator::generate::Codes;
use anymo_generator::sampling::Sampling;
use anymo_generator::{Evaluator, Generator, Request};
use anymo_motion::cleanup::Cleanup;
use anymo_motion::quality::{Quality, measure};
use anymo_tokenizer::dataset::Split;
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

/// A joint moving further than this in one frame at 30 fps (diameters) is a jump.
pub const JUMP: f32 = 0.1;

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
    /// Foot skating, diameters per second (mean over clips of rigs with feet).
    pub foot_skating: f32,
    /// Foot flight: the lowest foot's mean height, diameters (mean over clips of rigs with feet).
    pub foot_flight: f32,
    /// Ground penetration, diameters.
    pub ground_penetration: f32,
    /// Mean joint acceleration, diameters per second squared.
    pub jitter: f32,
    /// The largest one-frame step of any joint in any clip, at 30 fps, diameters.
    pub max_step: f32,
    /// The fraction of clips with a step over [`JUMP`].
    pub jumpy: f32,
    /// Mean height of the body's centre, diameters (posture: against the GT row's).
    pub body_height: f32,
    /// Mean cosine of each motion and its caption in the evaluator's space: the quality
    /// report's prompt score, averaged.
    pub text_similarity: f32,
    /// Mean seconds to generate and decode one clip (0 for GT).
    pub seconds_per_clip: f64,
}

struct Scored {
    motion: Vec<f32>,
    text: Vec<f32>,
    quality: Quality,
    human: bool,
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
/// the tokenizer the evaluator reads, `real` the real clips' figures the cleanup stands feet by,
/// `draw` the sampling and the seed (of the clip order; clip `i` is generated with seed + `i`).
fn evaluate(
    real: &RealMotion,
    tat: &mut Tat,
    evaluator: &Evaluator,
    generators: &[Candidate],
    test: &[&ModelClip],
    encoder: &mut CachedEncoder,
    draw: Request,
) -> Result<Vec<Row>> {
    let Request { sampling, seed, .. } = draw;
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
        truth.push(Scored {
            motion: evaluator.embed_one(&clip.latent[..steps * latent_dim])?,
            text: evaluator.embed_sentence(&clip.text[0])?,
            quality: measure(&model_clip.motion.slice(0, frames)),
            human: is_human(&clip.subject),
        });
    }
    let mut rows = table("GT", &truth, &truth, 0.0);

    // Each model's codes (or the real clip's own, for the tokenizer's row) decoded on the clip's
    // skeleton by the tokenizer they belong to, re-encoded and scored like the real motion, as
    // decoded and after the cleanup (on the motion in the skeleton's own frames, as users get
    // it).
    let bases = bases_by_topology(tat.config().representation, test);
    let cleanup = Cleanup::default();
    let mut score = |codes: Codes, i: usize, decoder: Option<&Tat>, tat: &mut Tat| -> Result<[Scored; 2]> {
        let basis = &bases[&topology(&motions[i].motion)];
        let skeleton = &basis.enter_skeleton(&motions[i].motion);
        let graph = Graphs::new(encoder).of(skeleton)?;
        let tokens = Tokens::whole(codes, per_token, motions[i].motion.fps());
        let decoded = basis.leave(&detokenize(decoder.unwrap_or(&*tat), &tokens, &graph, skeleton)?);
        let (cleaned, _) = clean_up(decoded.clone(), Some(&cleanup), real);
        let mut scored = |motion| -> Result<Scored> {
            let encoded = encode_whole(tat, &graph, &basis.enter(&motion))?;
            Ok(Scored {
                motion: evaluator.embed_one(&encoded.latent)?,
                text: truth[i].text.clone(),
                quality: measure(&motion),
                human: truth[i].human,
            })
        };
        Ok([scored(decoded)?, scored(cleaned)?])
    };
    let started = Instant::now();
    let (mut decoded, mut decoded_clean) = (Vec::with_capacity(clips.len()), Vec::with_capacity(clips.len()));
    for (i, clip) in clips.iter().enumerate() {
        let [raw, clean] = score(clip.codes[..clip.steps().min(max)].to_vec(), i, None, tat)?;
        decoded.push(raw);
        decoded_clean.push(clean);
    }
    let seconds = started.elapsed().as_secs_f64() / clips.len().max(1) as f64;
    rows.extend(table(TOKENIZER_ROW, &decoded, &truth, seconds));
    rows.extend(table(&format!("{TOKENIZER_ROW}{CLEANED}"), &decoded_clean, &truth, seconds));

    for Candidate { name, generator, tokenizer } in generators {
        let started = Instant::now();
        let (mut generated, mut generated_clean) = (Vec::with_capacity(clips.len()), Vec::with_capacity(clips.len()));
        for (i, clip) in clips.iter().enumerate() {
            let steps = clip.steps().min(max).min(generator.config().max_tokens());
            let request = Request { steps: Some(steps), samples: 1, sampling, seed: seed.wrapping_add(i as u64) };
            let codes = generator.generate(&generator.read_prompt(&clip.text[0]), &clip.skeleton, &request)?.remove(0);
            let [raw, clean] = score(codes, i, Some(*tokenizer), tat)?;
            generated.push(raw);
            generated_clean.push(clean);
        }
        let seconds = started.elapsed().as_secs_f64() / clips.len().max(1) as f64;
        rows.extend(table(name, &generated, &truth, seconds));
        rows.extend(table(&format!("{name}{CLEANED}"), &generated_clean, &truth, seconds));
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
            let with_feet: Vec<&Quality> =
                chosen.iter().map(|s| &s.quality).filter(|q| q.foot_skating.is_some()).collect();
            let foot_mean = |get: fn(&Quality) -> Option<f32>| {
                with_feet.iter().filter_map(|q| get(q)).sum::<f32>() / with_feet.len().max(1) as f32
            };
            Some(Row {
                model: model.to_string(),
                subset: subset.to_string(),
                clips: chosen.len(),
                r_precision: r_precision(&motions, &texts, GROUP.min(chosen.len())),
                fid: fid(&motions, &real_motions),
                mm_dist: mm_dist(&motions, &texts),
                foot_skating: foot_mean(|q| q.foot_skating),
                foot_flight: foot_mean(|q| q.foot_flight),
                ground_penetration: chosen.iter().map(|s| s.quality.ground_penetration).sum::<f32>() / n,
                jitter: chosen.iter().map(|s| s.quality.jitter).sum::<f32>() / n,
                max_step: chosen.iter().map(|s| s.quality.max_step).fold(0.0, f32::max),
                jumpy: chosen.iter().filter(|s| s.quality.max_step > JUMP).count() as f32 / n,
                body_height: chosen.iter().map(|s| s.quality.body_height).sum::<f32>() / n,
                text_similarity: chosen.iter().map(|s| cosine(&s.motion, &s.text)).sum::<f32>() / n,
                seconds_per_clip: seconds,
            })
        })
        .collect()
}

/// Loads the evaluator `evaluator` and each generator of `models` from `set` (each with the
/// tokenizer its card names) and scores them on the test clips of `clips` (see [`evaluate`]),
/// with real clips' figures per skeleton measured on all of `clips`, which it also returns.
pub fn evaluate_generators(
    set: &Checkpoints,
    evaluator: &str,
    models: &[String],
    clips: &[ModelClip],
    encoder: &mut CachedEncoder,
    sampling: Sampling,
    seed: u64,
) -> Result<(Vec<Row>, RealMotion)> {
    let real = RealMotion::measure(&clips.iter().collect::<Vec<_>>());
    let test: Vec<&ModelClip> = clips.iter().filter(|c| c.split == Split::Test).collect();
    eprintln!("{} test clips; real motion measured on {} skeletons", test.len(), real.0.len());
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
    let draw = Request { steps: None, samples: 1, sampling, seed };
    let rows = evaluate(&real, &mut tat, &evaluator, &candidates, &test, encoder, draw)?;
    Ok((rows, real))
}

/// The rows as a Markdown table.
pub fn markdown(rows: &[Row]) -> String {
    let headers = [
        "model", "clips", "R@1", "R@2", "R@3", "FID", "MM-Dist", "FS", "flight", "GP", "jitter", "max step", "jumpy",
        "height", "match", "s/clip",
    ];
    let mut table = Table::new(&headers);
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
            format!("{:.4}", r.foot_flight),
            format!("{:.4}", r.ground_penetration),
            format!("{:.1}", r.jitter),
            three(r.max_step),
            three(r.jumpy),
            three(r.body_height),
            three(r.text_similarity),
            three(r.seconds_per_clip),
        ]);
    }
    table.into_text()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_row_has_a_cell_under_each_header() {
        let row = Row {
            model: "m".into(),
            subset: "all".into(),
            clips: 2,
            r_precision: [0.1, 0.2, 0.3],
            fid: 0.5,
            mm_dist: 0.6,
            foot_skating: 0.7,
            foot_flight: 0.8,
            ground_penetration: 0.9,
            jitter: 1.0,
            max_step: 1.1,
            jumpy: 0.5,
            body_height: 0.4,
            text_similarity: 0.345,
            seconds_per_clip: 0.2,
        };
        let text = markdown(&[row]);
        let lines: Vec<&str> = text.lines().collect();
        let cells = |line: &str| line.matches('|').count();
        assert_eq!(cells(lines[0]), cells(lines[2]), "{text}");
        assert!(lines[0].contains("| match |") && lines[2].contains("| 0.345 |"), "{text}");
    }
}
