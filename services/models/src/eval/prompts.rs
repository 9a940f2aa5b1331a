//! Held-out prompts judged by what the motion does: prompts worded unlike any caption of the clips they target, each with kinematic checks
//! of its action (which way and how fast the body makes headway, turns, feet in the air, hands
//! over the head, a bowed head), calibrated on the real training clips of that action, then
//! generated on every human and four-legged rig of the test and zero-shot splits and passed or
//! failed. The real test clips of each action pass through the same checks (the ceiling), and so
//! do their tokens decoded as generated tokens are (the ceiling a generator on that tokenizer
//! has).
//!
//! The figures come from [`anymo_motion::activity`], on motion cleaned as the models see it, so
//! a rig's helpers and units do not change them.

use super::Table;
use crate::checkpoint::Checkpoints;
use crate::data::ModelClip;
use crate::generation::is_human;
use crate::quality::skeleton_key;
use crate::studio::Studio;
use anyhow::{Context, Result};
use anymo_generator::Request;
use anymo_motion::activity::{Activity, measure};
use anymo_motion::contact::find_feet;
use anymo_motion::kinematics::all_global_transforms;
use anymo_motion::motion::Motion;
use anymo_motion::prep::labels::{Side, label_skeleton};
use anymo_motion::reference::facing_angle;
use anymo_tokenizer::dataset::Split;
use anymo_tokenizer::text::{CachedEncoder, SentenceEncoder};
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The shipped held-out prompts: `action<TAB>prompt` lines, `#` comments.
pub const HELDOUT_PROMPTS: &str = include_str!("heldout_prompts.tsv");

/// A check's lower bound is this quantile of the real training clips of its action (an upper
/// bound the mirror one), so about nine in ten real clips pass each check.
pub const QUANTILE: f32 = 0.1;

/// An action is judged on a kind of body only when at least this many real training clips of
/// it calibrate its checks.
pub const MIN_CLIPS: usize = 3;

/// A lower bound on getting about (headway, flight) is calibrated only on clips whose feet move
/// at least this fast relative to the root (diameters per second): some converted game clips
/// hold their legs still (their IK was not baked) and would set it at zero.
pub const MOVING_FEET: f32 = 0.1;

/// The kinds of body the prompts address.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Body {
    /// A rig of a human subject.
    Human,
    /// Any other rig standing on four feet.
    FourLegged,
}

impl Body {
    /// The kind of body of a clip, if it is one the prompts address.
    pub fn of(subject: &str, motion: &Motion) -> Option<Body> {
        if is_human(subject) {
            Some(Body::Human)
        } else if stands_on_four(motion) {
            Some(Body::FourLegged)
        } else {
            None
        }
    }
}

/// Feet in front of the hind pair by at least this much (diameters, along the facing in the
/// first frame) make a quadruped; a biped's four toe tips do not.
pub const FORE_AND_HIND: f32 = 0.15;

/// Whether a motion's rig stands on four feet, two in front of the other two.
fn stands_on_four(motion: &Motion) -> bool {
    let feet = find_feet(motion);
    if feet.len() != 4 || motion.frames() == 0 {
        return false;
    }
    let skeleton = motion.skeleton();
    let pose = all_global_transforms(&motion.slice(0, 1));
    let sides: Vec<Option<Side>> = label_skeleton(skeleton).into_iter().map(|l| l.side).collect();
    let positions: Vec<Vec3> = pose.iter().map(|t| t.translation).collect();
    let facing = facing_angle(&sides, &positions);
    let forward = Vec3::new(facing.sin(), 0.0, facing.cos());
    let mut along: Vec<f32> = feet.iter().map(|f| f.point(skeleton, &pose).dot(forward)).collect();
    along.sort_by(f32::total_cmp);
    along[2] - along[1] >= FORE_AND_HIND * skeleton.diameter()
}

/// A figure of [`Activity`] a check reads, signed so that more is more of the action.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Figure {
    /// Headway along the facing (diameters per second).
    Forward,
    /// Headway against the facing.
    Backward,
    /// Headway across the facing, either way.
    Sideways,
    /// Net distance covered per second.
    Travel,
    /// How fast the feet move relative to the root (legs at work, even looped in place).
    FootSpeed,
    /// Net turn to the left (degrees).
    TurnLeft,
    /// Net turn to the right (degrees).
    TurnRight,
    /// Share of frames with every foot in the air.
    Flight,
    /// Highest the lowest foot gets.
    JumpHeight,
    /// Highest any foot gets.
    FootRaise,
    /// Highest either hand gets relative to the head.
    HandLift,
    /// Highest both hands get together relative to the head (the lower of the two).
    BothHandsLift,
    /// How far the head comes down towards the hips.
    HeadDrop,
}

impl Figure {
    /// Whether the figure measures getting about (see [`MOVING_FEET`]).
    pub fn is_locomotion(self) -> bool {
        matches!(
            self,
            Figure::Forward | Figure::Backward | Figure::Sideways | Figure::Travel | Figure::FootSpeed | Figure::Flight
        )
    }

    /// The figure of a motion's activity; `None` when the rig has no part for it.
    pub fn of(self, a: &Activity) -> Option<f32> {
        match self {
            Figure::Forward => Some(a.forward_speed),
            Figure::Backward => Some(-a.forward_speed),
            Figure::Sideways => Some(a.leftward_speed.abs()),
            Figure::Travel => Some(a.travel_speed),
            Figure::FootSpeed => a.foot_speed,
            Figure::TurnLeft => Some(a.turn_degrees),
            Figure::TurnRight => Some(-a.turn_degrees),
            Figure::Flight => a.flight,
            Figure::JumpHeight => a.jump_height,
            Figure::FootRaise => a.foot_raise,
            Figure::HandLift => a.hand_lift(),
            Figure::BothHandsLift => a.both_hands_lift(),
            Figure::HeadDrop => a.head_drop,
        }
    }
}

/// Which side of its threshold a figure must be on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Bound {
    /// At least the threshold (the [`QUANTILE`] of the real clips).
    AtLeast,
    /// At most the threshold (the `1 - QUANTILE` quantile).
    AtMost,
}

/// An action the held-out prompts ask for.
#[derive(Clone, Copy, Debug)]
pub struct Action {
    /// Its name in the prompt file.
    pub name: &'static str,
    /// The body it is asked of.
    pub body: Body,
    /// Whether a real clip's caption (lowercase) describes this action.
    pub describes: fn(&str) -> bool,
    /// What its motion must do.
    pub checks: &'static [(Figure, Bound)],
}

/// Whether a caption walks straight (no turn, no backing or sidestep, no jump on the way).
fn walks_straight(c: &str) -> bool {
    c.contains("walk") && !["backward", "sideways", "turn", "jump", "obstacle", "dribble"].iter().any(|w| c.contains(w))
}

/// The actions of the held-out prompts, their real clips and their checks.
pub const ACTIONS: [Action; 15] = [
    Action {
        name: "walk",
        body: Body::Human,
        describes: walks_straight,
        checks: &[(Figure::Forward, Bound::AtLeast), (Figure::Flight, Bound::AtMost)],
    },
    Action {
        name: "backwards",
        body: Body::Human,
        describes: |c| c.contains("walks backward"),
        checks: &[(Figure::Backward, Bound::AtLeast)],
    },
    Action {
        name: "sidestep",
        body: Body::Human,
        describes: |c| c.contains("walks sideways"),
        checks: &[(Figure::Sideways, Bound::AtLeast)],
    },
    Action {
        name: "turn-left",
        body: Body::Human,
        describes: |c| c.contains("turns left"),
        checks: &[(Figure::TurnLeft, Bound::AtLeast)],
    },
    Action {
        name: "turn-right",
        body: Body::Human,
        describes: |c| c.contains("turns right"),
        checks: &[(Figure::TurnRight, Bound::AtLeast)],
    },
    Action {
        name: "run",
        body: Body::Human,
        describes: |c| c.contains("runs") || c.contains("dashes"),
        checks: &[(Figure::Forward, Bound::AtLeast), (Figure::Flight, Bound::AtLeast)],
    },
    Action {
        name: "raise-hand",
        body: Body::Human,
        describes: |c| c.contains("raises the left hand") || c.contains("raises the right hand"),
        checks: &[(Figure::HandLift, Bound::AtLeast)],
    },
    Action {
        name: "raise-hands",
        body: Body::Human,
        describes: |c| c.contains("raises both hands"),
        checks: &[(Figure::BothHandsLift, Bound::AtLeast)],
    },
    Action {
        name: "wave",
        body: Body::Human,
        describes: |c| c.contains("waves"),
        checks: &[(Figure::HandLift, Bound::AtLeast)],
    },
    Action {
        name: "bow",
        body: Body::Human,
        describes: |c| c.contains("bows"),
        checks: &[(Figure::HeadDrop, Bound::AtLeast)],
    },
    Action {
        name: "jump",
        body: Body::Human,
        describes: |c| c.contains("jumps"),
        checks: &[(Figure::JumpHeight, Bound::AtLeast)],
    },
    Action {
        name: "idle",
        body: Body::Human,
        describes: |c| c.contains("idle"),
        checks: &[(Figure::Travel, Bound::AtMost), (Figure::Flight, Bound::AtMost)],
    },
    Action {
        name: "kick",
        body: Body::Human,
        describes: |c| c.contains("kicks"),
        checks: &[(Figure::FootRaise, Bound::AtLeast)],
    },
    Action {
        name: "animal-walk",
        body: Body::FourLegged,
        describes: |c| c.contains("walks"),
        checks: &[
            (Figure::Forward, Bound::AtLeast),
            (Figure::FootSpeed, Bound::AtLeast),
            (Figure::Flight, Bound::AtMost),
        ],
    },
    Action {
        name: "animal-run",
        body: Body::FourLegged,
        describes: |c| c.contains("runs") || c.contains("gallops"),
        checks: &[(Figure::Forward, Bound::AtLeast), (Figure::FootSpeed, Bound::AtLeast)],
    },
];

/// The action named `name`.
pub fn action(name: &str) -> Option<&'static Action> {
    ACTIONS.iter().find(|a| a.name == name)
}

/// A held-out prompt and the action it asks for.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Prompt {
    /// The action's name.
    pub action: String,
    /// The words.
    pub text: String,
}

/// Reads prompts in the held-out file's format, refusing unknown actions.
pub fn parse_prompts(text: &str) -> Result<Vec<Prompt>> {
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.starts_with('#'))
        .map(|(i, line)| {
            let (name, prompt) =
                line.split_once('\t').with_context(|| format!("line {}: expected action<TAB>prompt", i + 1))?;
            action(name).with_context(|| format!("line {}: unknown action {name:?}", i + 1))?;
            Ok(Prompt { action: name.to_string(), text: prompt.trim().to_string() })
        })
        .collect()
}

/// Whether any caption of a clip describes `action`.
fn shows(action: &Action, captions: &[String]) -> bool {
    captions.iter().any(|c| (action.describes)(&c.to_lowercase()))
}

/// The actions of `body` that a clip with these captions shows.
fn shown<'a>(body: Body, captions: &'a [String]) -> impl Iterator<Item = &'static Action> + 'a {
    ACTIONS.iter().filter(move |a| a.body == body && shows(a, captions))
}

/// One check with its threshold.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Threshold {
    /// The figure read.
    pub figure: Figure,
    /// Which side it must be on.
    pub bound: Bound,
    /// The threshold.
    pub value: f32,
}

impl Threshold {
    /// Whether an activity passes; `None` when the rig has no part for the figure.
    pub fn passes(&self, a: &Activity) -> Option<bool> {
        self.figure.of(a).map(|v| match self.bound {
            Bound::AtLeast => v >= self.value,
            Bound::AtMost => v <= self.value,
        })
    }
}

/// The checks of every action judged on each kind of body, from real training clips.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Calibration {
    /// By action name: the body, the clips measured and the thresholds.
    pub actions: BTreeMap<String, Calibrated>,
}

/// One action's calibrated checks.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Calibrated {
    /// Real training clips of the action it was calibrated on.
    pub clips: usize,
    /// Its checks.
    pub checks: Vec<Threshold>,
}

impl Calibration {
    /// Thresholds from the `(body, captions, activity)` of real clips: for each action with at
    /// least [`MIN_CLIPS`] clips of its body that show the figure, each check's [`QUANTILE`]
    /// (lower bounds, on getting about from clips whose feet move) or `1 - QUANTILE` (upper
    /// bounds) of that figure.
    pub fn from_real<'a>(clips: impl IntoIterator<Item = (Body, &'a [String], Activity)>) -> Calibration {
        let clips: Vec<(Body, &[String], Activity)> = clips.into_iter().collect();
        let mut actions = BTreeMap::new();
        for action in &ACTIONS {
            let mine: Vec<&Activity> =
                clips.iter().filter(|(b, c, _)| *b == action.body && shows(action, c)).map(|(_, _, a)| a).collect();
            let checks: Option<Vec<Threshold>> = action
                .checks
                .iter()
                .map(|&(figure, bound)| {
                    let moving = |a: &&&Activity| a.foot_speed.is_some_and(|v| v >= MOVING_FEET);
                    let shows_it = |a: &&&Activity| bound == Bound::AtMost || !figure.is_locomotion() || moving(a);
                    let values: Vec<f32> = mine.iter().filter(shows_it).filter_map(|a| figure.of(a)).collect();
                    let q = if bound == Bound::AtLeast { QUANTILE } else { 1.0 - QUANTILE };
                    (values.len() >= MIN_CLIPS).then(|| Threshold { figure, bound, value: quantile(values, q) })
                })
                .collect();
            if let Some(checks) = checks {
                actions.insert(action.name.to_string(), Calibrated { clips: mine.len(), checks });
            }
        }
        Calibration { actions }
    }

    /// Whether an activity does `action`, by the checks the rig has parts for; `None` when the
    /// action is not calibrated or no check applies (a rig without feet cannot be judged on
    /// jumping).
    pub fn passes(&self, action: &str, a: &Activity) -> Option<bool> {
        let verdicts: Vec<bool> = self.actions.get(action)?.checks.iter().filter_map(|t| t.passes(a)).collect();
        (!verdicts.is_empty()).then(|| verdicts.iter().all(|&v| v))
    }
}

/// The `q` quantile of `values` (linear between the nearest ranks).
fn quantile(mut values: Vec<f32>, q: f32) -> f32 {
    values.sort_by(f32::total_cmp);
    let at = q * (values.len() - 1) as f32;
    let (low, high) = (at.floor() as usize, at.ceil() as usize);
    values[low] + (values[high] - values[low]) * (at - low as f32)
}

/// Passes out of tries.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Passes {
    /// Samples that passed every check.
    pub passed: usize,
    /// Samples judged.
    pub tried: usize,
}

impl Passes {
    fn add(&mut self, pass: bool) {
        self.passed += usize::from(pass);
        self.tried += 1;
    }

    /// The pass rate (0 when nothing was judged).
    pub fn rate(&self) -> f32 {
        if self.tried == 0 { 0.0 } else { self.passed as f32 / self.tried as f32 }
    }
}

/// One rig's results.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RigRow {
    /// The rig's subjects, source and joint count ("person (lafan1, 22 joints)").
    pub rig: String,
    /// Its kind of body.
    pub body: Body,
    /// Its split (`test` or `zero-shot`).
    pub split: String,
    /// Its real held-out clips of calibrated actions passing their action's checks.
    pub real: Passes,
    /// The same clips tokenized and decoded as generated tokens are (no root path, the default
    /// cleanup), through the first generator's tokenizer: what a generator that wrote a real
    /// clip's tokens would score.
    pub tokens: Passes,
    /// Each model's generated samples passing their prompt's checks, by checkpoint name.
    pub generated: BTreeMap<String, Passes>,
}

/// One action's results over every rig.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ActionRow {
    /// The action.
    pub action: String,
    /// Real held-out clips passing.
    pub real: Passes,
    /// Their tokens decoded as generated tokens are, passing (see [`RigRow::tokens`]).
    pub tokens: Passes,
    /// Each model's samples passing, by checkpoint name.
    pub generated: BTreeMap<String, Passes>,
}

/// One generated sample, with the figures its checks read.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Sample {
    /// The generator.
    pub model: String,
    /// The rig it was generated on.
    pub rig: String,
    /// The prompt's action.
    pub action: String,
    /// The prompt.
    pub prompt: String,
    /// Each check's figure (`None`: the rig has no part for it).
    pub figures: Vec<(Figure, Option<f32>)>,
    /// Whether it passed every check.
    pub passed: bool,
}

/// The whole evaluation.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PromptReport {
    /// The checks used.
    pub calibration: Calibration,
    /// Prompts in the set.
    pub prompts: usize,
    /// Per rig.
    pub rigs: Vec<RigRow>,
    /// Per action.
    pub actions: Vec<ActionRow>,
    /// Every generated sample.
    pub samples: Vec<Sample>,
}

/// A rig to generate on: its kind of body and its held-out clips with their figures (the
/// first one's frames give the target's pose).
struct Rig<'a> {
    body: Body,
    clips: Vec<(&'a ModelClip, Activity)>,
}

/// Calibrates the checks on the training clips of `clips`, then generates every held-out prompt
/// of `prompts` on each human and four-legged rig of the test and zero-shot splits (one sample,
/// the length the prompt's length predictor gives, the default cleanup, the sampling and seed of
/// `draw`; prompt `i` gets seed + `i`) with each generator of `models`, and judges samples, the
/// rigs' real clips and those clips' own tokens decoded as generated tokens are (through the
/// first model's tokenizer).
pub fn evaluate_prompts(
    set: &Checkpoints,
    evaluator: &str,
    models: &[String],
    clips: &[ModelClip],
    prompts: &[Prompt],
    encoder: &dyn Fn() -> Result<SentenceEncoder>,
    draw: Request,
) -> Result<PromptReport> {
    let Request { sampling, seed, .. } = draw;
    let bodies: Vec<Option<Body>> = clips.iter().map(|c| Body::of(&c.item.subject, &c.motion)).collect();
    let activities: Vec<Activity> = clips.iter().map(|c| measure(&c.motion)).collect();
    let calibration = Calibration::from_real(
        clips
            .iter()
            .zip(&bodies)
            .zip(&activities)
            .filter(|((c, b), _)| c.split == Split::Train && b.is_some())
            .map(|((c, b), a)| (b.expect("filtered"), c.item.captions.as_slice(), *a)),
    );

    let mut rigs: BTreeMap<(String, String), Rig> = BTreeMap::new();
    for ((clip, body), activity) in clips.iter().zip(&bodies).zip(&activities) {
        let Some(body) = body else { continue };
        if clip.split == Split::Train {
            continue;
        }
        rigs.entry((clip.split.as_str().to_string(), skeleton_key(&clip.motion)))
            .or_insert_with(|| Rig { body: *body, clips: Vec::new() })
            .clips
            .push((clip, *activity));
    }

    let mut rows: Vec<RigRow> = Vec::new();
    let mut by_action: BTreeMap<String, ActionRow> = BTreeMap::new();
    for ((split, _), rig) in &rigs {
        let mut subjects: Vec<&str> = rig.clips.iter().map(|(c, _)| c.item.subject.as_str()).collect();
        subjects.sort_unstable();
        subjects.dedup();
        let first = rig.clips[0].0;
        let mut row = RigRow {
            rig: format!("{} ({}, {} joints)", subjects.join(", "), first.item.source, first.motion.skeleton().len()),
            body: rig.body,
            split: split.clone(),
            real: Passes::default(),
            tokens: Passes::default(),
            generated: BTreeMap::new(),
        };
        for (clip, activity) in &rig.clips {
            for action in shown(rig.body, &clip.item.captions) {
                if let Some(pass) = calibration.passes(action.name, activity) {
                    row.real.add(pass);
                    action_row(&mut by_action, action.name).real.add(pass);
                }
            }
        }
        rows.push(row);
    }

    if let Some(first) = models.first() {
        let mut studio = Studio::load(&set.get(first), Some(&set.get(evaluator)), CachedEncoder::new(encoder()?))?;
        studio.set_scoring(false);
        for (row, rig) in rows.iter_mut().zip(rigs.values()) {
            for (clip, _) in &rig.clips {
                let judged: Vec<&Action> =
                    shown(rig.body, &clip.item.captions).filter(|a| calibration.actions.contains_key(a.name)).collect();
                if judged.is_empty() {
                    continue;
                }
                let (target, codes, _) = studio.clip(&clip.motion)?;
                let made = studio.render(vec![codes], [0.0; 3], None, &target, "")?.remove(0);
                let activity = measure(&made.motion);
                for action in judged {
                    if let Some(pass) = calibration.passes(action.name, &activity) {
                        row.tokens.add(pass);
                        action_row(&mut by_action, action.name).tokens.add(pass);
                    }
                }
            }
        }
    }

    let mut samples = Vec::new();
    for name in models {
        let evaluator = set.get(evaluator);
        let mut studio = Studio::load(&set.get(name), Some(&evaluator), CachedEncoder::new(encoder()?))?;
        studio.set_scoring(false);
        for (row, rig) in rows.iter_mut().zip(rigs.values()) {
            let target = studio.target(&rig.clips[0].0.motion)?;
            let mut passes = Passes::default();
            for (i, prompt) in prompts.iter().enumerate() {
                let action = action(&prompt.action).expect("parsed prompts name known actions");
                if action.body != rig.body || !calibration.actions.contains_key(action.name) {
                    continue;
                }
                let request = Request { steps: None, samples: 1, sampling, seed: seed.wrapping_add(i as u64) };
                let made = studio.generate_motion(&prompt.text, &target, None, &request)?.remove(0);
                let activity = measure(&made.motion);
                let Some(pass) = calibration.passes(action.name, &activity) else { continue };
                passes.add(pass);
                samples.push(Sample {
                    model: name.clone(),
                    rig: row.rig.clone(),
                    action: action.name.to_string(),
                    prompt: prompt.text.clone(),
                    figures: action.checks.iter().map(|&(figure, _)| (figure, figure.of(&activity))).collect(),
                    passed: pass,
                });
                action_row(&mut by_action, action.name).generated.entry(name.clone()).or_default().add(pass);
            }
            eprintln!("{name} on {} ({}): {}/{} pass", row.rig, row.split, passes.passed, passes.tried);
            row.generated.insert(name.clone(), passes);
        }
    }
    let actions = by_action.into_values().collect();
    Ok(PromptReport { calibration, prompts: prompts.len(), rigs: rows, actions, samples })
}

/// The row of `action` in `rows`, made empty if it is not there yet.
fn action_row<'a>(rows: &'a mut BTreeMap<String, ActionRow>, action: &str) -> &'a mut ActionRow {
    rows.entry(action.to_string()).or_insert_with(|| ActionRow {
        action: action.to_string(),
        real: Passes::default(),
        tokens: Passes::default(),
        generated: BTreeMap::new(),
    })
}

impl PromptReport {
    /// The per-rig and per-action tables, each model's pass rate beside the real clips'.
    pub fn markdown(&self, models: &[String]) -> String {
        let cell = |p: &Passes| format!("{:.0}% ({}/{})", 100.0 * p.rate(), p.passed, p.tried);
        let none = Passes::default();
        let mut headers = vec!["rig", "body", "split", "real clips", "their tokens"];
        headers.extend(models.iter().map(String::as_str));
        let mut rigs = Table::new(&headers);
        for r in &self.rigs {
            let mut cells =
                vec![r.rig.clone(), format!("{:?}", r.body), r.split.clone(), cell(&r.real), cell(&r.tokens)];
            cells.extend(models.iter().map(|m| cell(r.generated.get(m).unwrap_or(&none))));
            rigs.row(&cells);
        }
        let mut headers = vec!["action", "real clips", "their tokens"];
        headers.extend(models.iter().map(String::as_str));
        let mut actions = Table::new(&headers);
        for a in &self.actions {
            let mut cells = vec![a.action.clone(), cell(&a.real), cell(&a.tokens)];
            cells.extend(models.iter().map(|m| cell(a.generated.get(m).unwrap_or(&none))));
            actions.row(&cells);
        }
        let mut checks = Table::new(&["action", "real training clips", "checks"]);
        for (name, c) in &self.calibration.actions {
            let said: Vec<String> = c
                .checks
                .iter()
                .map(|t| {
                    format!("{:?} {} {:.3}", t.figure, if t.bound == Bound::AtLeast { ">=" } else { "<=" }, t.value)
                })
                .collect();
            checks.row(&[name.clone(), c.clips.to_string(), said.join(", ")]);
        }
        format!("{}\n{}\n{}", rigs.into_text(), actions.into_text(), checks.into_text())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn walking(forward: f32, flight: f32) -> Activity {
        Activity { forward_speed: forward, flight: Some(flight), foot_speed: Some(1.0), ..Activity::default() }
    }

    #[test]
    fn thresholds_are_quantiles_of_the_action_s_real_clips() {
        let walk = vec!["a person walks".to_string()];
        let run = vec!["a person runs".to_string()];
        let bow = vec!["a person bows".to_string()];
        // Ten walks at forward speeds 0.1 .. 1.0 and flight 0 .. 0.09; runs too few to judge.
        let mut clips: Vec<(Body, &[String], Activity)> =
            (1..=10).map(|i| (Body::Human, walk.as_slice(), walking(0.1 * i as f32, 0.01 * (i - 1) as f32))).collect();
        clips.push((Body::Human, run.as_slice(), walking(3.0, 0.4)));
        // A four-legged walk does not calibrate the human one; a walk whose legs stand still
        // sets no lower bound on headway, only the upper one on flight.
        clips.push((Body::FourLegged, walk.as_slice(), walking(-5.0, 1.0)));
        clips.push((Body::Human, walk.as_slice(), Activity { foot_speed: Some(0.0), ..walking(0.0, 0.0) }));
        let c = Calibration::from_real(clips);
        let walk = &c.actions["walk"];
        assert_eq!(walk.clips, 11);
        // The 0.1 quantile of 0.1..1.0 sits 0.9 of the way from the first rank to the second;
        // the 0.9 quantile of the eleven flights 0, 0, 0.01 .. 0.09 is the tenth, 0.08.
        assert!((walk.checks[0].value - 0.19).abs() < 1e-5, "{walk:?}");
        assert!((walk.checks[1].value - 0.08).abs() < 1e-5, "{walk:?}");
        assert!(!c.actions.contains_key("run") && !c.actions.contains_key("animal-walk"), "{c:?}");
        assert_eq!(c.passes("walk", &walking(0.5, 0.0)), Some(true));
        assert_eq!(c.passes("walk", &walking(-0.5, 0.0)), Some(false), "backwards is no walk");
        assert_eq!(c.passes("walk", &walking(0.5, 0.2)), Some(false), "in the air is no walk");
        assert_eq!(c.passes("run", &walking(3.0, 0.4)), None);
        // A rig without feet is judged by the checks it has the parts for, and not at all when
        // it has none.
        assert_eq!(c.passes("walk", &Activity { forward_speed: 0.5, ..Activity::default() }), Some(true));
        assert_eq!(c.passes("walk", &Activity { forward_speed: 0.1, ..Activity::default() }), Some(false));
        let lifts = Calibration::from_real((0..4).map(|i| {
            (Body::Human, bow.as_slice(), Activity { head_drop: Some(0.1 * i as f32), ..Activity::default() })
        }));
        assert_eq!(lifts.passes("bow", &Activity::default()), None, "no head, no verdict");
    }

    #[test]
    fn the_shipped_prompts_parse_and_bad_lines_are_named() {
        let prompts = parse_prompts(HELDOUT_PROMPTS).unwrap();
        assert!(prompts.len() >= 150, "{}", prompts.len());
        for action in &ACTIONS {
            assert!(prompts.iter().any(|p| p.action == action.name), "no prompt for {}", action.name);
        }
        let err = parse_prompts("walk\tsomebody strolls\nfly\ta bird soars").unwrap_err();
        assert!(err.to_string().contains("line 2: unknown action \"fly\""), "{err}");
        assert!(parse_prompts("no tab here").unwrap_err().to_string().contains("line 1"));
    }
}
