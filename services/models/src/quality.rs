//! The quality report that comes with every motion anymo makes (generate, edit, transfer,
//! detokenize): feet that slide, float or sink, shaking and jumps, the same figures for real
//! clips of that skeleton when the corpus has some, and for generated motion how well it
//! matches its prompt in the evaluator's space. A user can tell a usable take from a bad one
//! without opening it.

use crate::data::{ModelClip, topology};
use anymo_motion::cleanup::{Cleanup, Planting};
use anymo_motion::motion::Motion;
use anymo_motion::quality::{Quality, measure};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};

/// The key under which the evaluator's card records [`RealMotion`].
pub const REAL_MOTION_KEY: &str = "real_motion";

/// A motion made for a user, on their skeleton, with its quality report.
#[derive(Clone, Debug)]
pub struct Made {
    /// The motion, on the user's own skeleton and in their units.
    pub motion: Motion,
    /// How plausible it is.
    pub quality: QualityReport,
}

/// What one made motion is like. Lengths are in diameters of the skeleton, the floor is y = 0.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct QualityReport {
    /// Whether the foot-contact cleanup ran on it.
    pub cleaned_up: bool,
    /// Feet found on the skeleton (0: a rig without legs; the foot figures are then absent).
    pub feet: usize,
    /// Fraction of foot-frames the cleanup held planted (0 when it did not run).
    pub planted: f32,
    /// Mean horizontal speed of feet on the ground, diameters per second.
    pub foot_skating: Option<f32>,
    /// Mean height of the lowest foot above the floor, diameters (a floating walk shows here).
    pub foot_flight: Option<f32>,
    /// Mean depth of joints below the floor, diameters.
    pub ground_penetration: f32,
    /// Mean joint acceleration, diameters per second squared.
    pub jitter: f32,
    /// The largest distance one joint moves in one frame at 30 fps, diameters.
    pub max_step: f32,
    /// Mean height of the body's centre (the mean of its joints), diameters: posture.
    pub body_height: f32,
    /// The same figures for real clips of this skeleton in the corpus (their medians), when the
    /// evaluator's card knows the skeleton.
    pub real: Option<SkeletonReference>,
    /// `jitter` over the real clips' jitter (1 is as smooth as real motion).
    pub jitter_ratio: Option<f32>,
    /// Cosine similarity of the prompt and the motion in the evaluator's space (-1 to 1, higher
    /// is a closer match; what real test clips score with their own captions is in
    /// docs/measurements/generation.md), for generated motion.
    pub text_similarity: Option<f32>,
}

impl QualityReport {
    /// The report of `motion` (cleaned form: diameter 1, at the models' rate), with what the
    /// cleanup did (`None`: it did not run), the real clips of its skeleton and its prompt score.
    pub fn of(motion: &Motion, planting: Option<Planting>, real: Option<SkeletonReference>, text: Option<f32>) -> Self {
        let Quality { feet, foot_skating, foot_flight, ground_penetration, jitter, max_step, body_height, .. } =
            measure(motion);
        QualityReport {
            cleaned_up: planting.is_some(),
            feet,
            planted: planting.map_or(0.0, |p| p.planted),
            foot_skating,
            foot_flight,
            ground_penetration,
            jitter,
            max_step,
            body_height,
            jitter_ratio: real.as_ref().filter(|r| r.jitter > 0.0).map(|r| jitter / r.jitter),
            real,
            text_similarity: text,
        }
    }
}

/// Decoded motion through the cleanup when there is one, with what it did. Planted feet stand
/// where real clips of the skeleton put them (`real`'s `foot_ground`), else on the floor.
pub fn clean_up(decoded: Motion, cleanup: Option<&Cleanup>, real: &RealMotion) -> (Motion, Option<Planting>) {
    match cleanup {
        Some(cleanup) => {
            let floor = real.of(&decoded).and_then(|r| r.foot_ground).unwrap_or(cleanup.floor);
            let (motion, planting) = Cleanup { floor, ..*cleanup }.apply(&decoded);
            (motion, Some(planting))
        }
        None => (decoded, None),
    }
}

/// Real clips' figures for one skeleton (medians over its clips).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct SkeletonReference {
    /// The subjects of its clips in the manifest, sorted and joined by ", " ("donkey, horse").
    pub subject: String,
    /// Clips measured.
    pub clips: usize,
    /// Median jitter.
    pub jitter: f32,
    /// Median foot skating (absent for a rig without feet).
    pub foot_skating: Option<f32>,
    /// Median foot flight.
    pub foot_flight: Option<f32>,
    /// Median body height (0 in tables recorded before it was measured).
    #[serde(default)]
    pub body_height: f32,
    /// Median height where the feet meet the ground (see
    /// [`anymo_motion::quality::Quality::foot_ground`]): what the cleanup stands planted feet at.
    #[serde(default)]
    pub foot_ground: Option<f32>,
}

/// [`SkeletonReference`] by skeleton: the blake3 of the cleaned skeleton's joint names and
/// parents (the topology the models group clips by).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RealMotion(pub BTreeMap<String, SkeletonReference>);

impl RealMotion {
    /// Measures clips (cleaned, at the models' rate) per skeleton.
    pub fn measure(clips: &[&ModelClip]) -> RealMotion {
        let mut by_skeleton: BTreeMap<String, (BTreeSet<String>, Vec<Quality>)> = BTreeMap::new();
        for clip in clips {
            let entry = by_skeleton.entry(skeleton_key(&clip.motion)).or_default();
            entry.0.insert(clip.item.subject.clone());
            entry.1.push(measure(&clip.motion));
        }
        RealMotion(
            by_skeleton
                .into_iter()
                .map(|(key, (subjects, figures))| {
                    let median_of =
                        |get: &dyn Fn(&Quality) -> Option<f32>| median(figures.iter().filter_map(get).collect());
                    let reference = SkeletonReference {
                        subject: subjects.into_iter().collect::<Vec<_>>().join(", "),
                        clips: figures.len(),
                        jitter: median_of(&|q| Some(q.jitter)).unwrap_or(0.0),
                        foot_skating: median_of(&|q| q.foot_skating),
                        foot_flight: median_of(&|q| q.foot_flight),
                        body_height: median_of(&|q| Some(q.body_height)).unwrap_or(0.0),
                        foot_ground: median_of(&|q| q.foot_ground),
                    };
                    (key, reference)
                })
                .collect(),
        )
    }

    /// The reference of a skeleton (given by any cleaned motion on it), if it was measured.
    pub fn of(&self, motion: &Motion) -> Option<SkeletonReference> {
        self.0.get(&skeleton_key(motion)).cloned()
    }

    /// The table the card of evaluator checkpoint `evaluator` records.
    pub fn of_evaluator(evaluator: &crate::checkpoint::Checkpoint) -> anyhow::Result<RealMotion> {
        let card: anymo_tokenizer::nn::ModelCard<crate::card::EvaluatorCard> = evaluator.card("an evaluator")?;
        Ok(RealMotion::from_card_metrics(&card.metrics))
    }

    /// The table an evaluator's card records, or an empty one when it records none.
    pub fn from_card_metrics(metrics: &serde_json::Value) -> RealMotion {
        metrics.get(REAL_MOTION_KEY).and_then(|v| serde_json::from_value(v.clone()).ok()).unwrap_or_default()
    }
}

/// The cosine of two vectors (0 when one is zero): the prompt score of a report.
pub fn cosine(a: &[f32], b: &[f32]) -> f32 {
    let dot: f32 = a.iter().zip(b).map(|(x, y)| x * y).sum();
    let norm = |v: &[f32]| v.iter().map(|x| x * x).sum::<f32>().sqrt();
    dot / (norm(a) * norm(b)).max(f32::MIN_POSITIVE)
}

/// The key of a cleaned motion's skeleton in [`RealMotion`].
pub fn skeleton_key(motion: &Motion) -> String {
    let text: String = topology(motion).iter().map(|(parent, name)| format!("{parent:?}:{name};")).collect();
    blake3::hash(text.as_bytes()).to_hex()[..16].to_string()
}

fn median(mut values: Vec<f32>) -> Option<f32> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f32::total_cmp);
    Some(values[values.len() / 2])
}
