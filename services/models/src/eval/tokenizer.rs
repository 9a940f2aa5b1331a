//! The tokenizer evaluation of EVAL.md: reconstruction (MPJPE with and without translation,
//! GeoDist, foot skating, ground penetration, how far the body turns) per split and source, as
//! decoded and after the cleanup users get by default (`+ cleanup`), beside two references that are no model (each clip held in its mean pose, and in its rig's
//! rest pose); each model against the mean-pose reference source by source; the same clips on
//! rigs whose joint frames are turned (the world motion unchanged), which a tokenizer should not
//! tell apart; for a codec on the reference pose, the same clips read against their own mean
//! pose as a tokens file carries it (its pose code); and zero-shot
//! transfer (cycle consistency, foot skating and ground penetration of transfers, and NEC
//! appendix F's correlation of pairwise motion distances before and after).

use super::{CLEANED, Table, f};
use crate::card::CodecCard;
use crate::checkpoint::Checkpoints;
use crate::codecs::{self, Graphs, bases_by_topology};
use crate::data::{ModelClip, topology};
use crate::quality::{RealMotion, clean_up};
use crate::tokens::PoseCode;
use anyhow::Result;
use anymo_motion::cleanup::Cleanup;
use anymo_motion::features::{canonicalise, foot_joints};
use anymo_motion::kinematics::all_joint_positions;
use anymo_motion::metrics::{
    JointKind, body_turn_deg, foot_skating, geodesic_distance_deg, geodesic_sums_by_kind, ground_penetration, mpjpe,
    mpjpe_root_aligned, mpjpe_yaw_aligned,
};
use anymo_motion::motion::Motion;
use anymo_motion::prep::augment::turn_joint_frames;
use anymo_motion::reference::ReferencePose;
use anymo_tokenizer::dataset::Split;
use anymo_tokenizer::tat::window::{detokenize, reconstruct, tokenize};
use anymo_tokenizer::tat::{Basis, Codec, Representation, Tat};
use anymo_tokenizer::text::CachedEncoder;
use glam::Quat;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Contact height for foot skating, in skeleton diameters.
pub const CONTACT_HEIGHT: f32 = 0.05;
/// Feet are leaves whose mean height is within this fraction of the diameter of the lowest leaf's.
pub const FOOT_BAND: f32 = 0.1;

/// Frame-weighted sums of the reconstruction metrics.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Sums {
    /// Clips measured.
    pub clips: usize,
    /// Frames measured.
    pub frames: usize,
    mpjpe: f64,
    mpjpe_trans: f64,
    mpjpe_yaw: f64,
    mpjpe_free: f64,
    geodist: f64,
    geodist_free: f64,
    fs: f64,
    gp: f64,
    fs_truth: f64,
    gp_truth: f64,
    /// Summed angle and joint-frame count per [`JointKind`] (root, inner, unseen), anchored.
    #[serde(default)]
    geodist_kinds: [(f64, usize); 3],
    #[serde(default)]
    mpjpe_true_root: f64,
    #[serde(default)]
    body_turn: f64,
    /// Clips whose body is turned by more than [`TURNED_DEGREES`] on average.
    #[serde(default)]
    turned: usize,
}

/// A reconstruction whose body is turned by more than this (mean over its frames, degrees) is
/// counted as a turned or reversed body: a failure, whatever its MPJPE.
pub const TURNED_DEGREES: f64 = 45.0;

/// The mean metrics of a set of clips.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Scores {
    /// Clips measured.
    pub clips: usize,
    /// Frames measured.
    pub frames: usize,
    /// Root-aligned MPJPE, diameters.
    pub mpjpe: f64,
    /// MPJPE with translation, diameters.
    pub mpjpe_trans: f64,
    /// MPJPE with the root's position and the best turn about +Y aligned per frame: the pose
    /// alone, without the heading error that builds up over a long clip.
    pub mpjpe_yaw: f64,
    /// Root-aligned MPJPE with the root integrated from the decoded rates alone (no anchors), as
    /// generated tokens decode: the heading error builds up over the clip.
    #[serde(default)]
    pub mpjpe_free: f64,
    /// Mean geodesic distance of local rotations, degrees.
    pub geodist: f64,
    /// GeoDist without anchors (the root joint's rotation carries the heading).
    #[serde(default)]
    pub geodist_free: f64,
    /// Foot skating of the reconstruction, diameters per second.
    pub fs: f64,
    /// Ground penetration of the reconstruction, diameters.
    pub gp: f64,
    /// Foot skating of the truth.
    pub fs_truth: f64,
    /// Ground penetration of the truth.
    pub gp_truth: f64,
    /// GeoDist of the root joint alone (anchored), degrees. This and the next two are means
    /// over joint-frames of their kind, so a rig with more such joints weighs more.
    #[serde(default)]
    pub geodist_root: f64,
    /// GeoDist of the joints whose rotation moves other joints, degrees: what positions see.
    #[serde(default)]
    pub geodist_inner: f64,
    /// GeoDist of the joints whose rotation moves no joint (leaves, joints with only zero-offset
    /// descendants), degrees: what no position loss or MPJPE sees.
    #[serde(default)]
    pub geodist_unseen: f64,
    /// Root-aligned MPJPE with the truth's root in place of the decoded one: the other joints'
    /// error alone.
    #[serde(default)]
    pub mpjpe_true_root: f64,
    /// How far the decoded body is turned against the truth, degrees (see
    /// [`anymo_motion::metrics::body_turn_deg`]), frame-weighted.
    #[serde(default)]
    pub body_turn: f64,
    /// Clips whose body is turned by more than [`TURNED_DEGREES`].
    #[serde(default)]
    pub turned_clips: usize,
}

impl Sums {
    /// Adds one clip's truth and reconstruction, with the root anchored, free, and the truth's.
    pub fn add(&mut self, truth: &Motion, rebuilt: &Motion, free: &Motion, true_root: &Motion) {
        let n = truth.skeleton().len();
        let frames = truth.frames();
        let (pt, pr) = (all_joint_positions(truth), all_joint_positions(rebuilt));
        let feet = foot_joints(truth, FOOT_BAND);
        let fps = truth.fps() as f32;
        let w = frames as f64;
        self.clips += 1;
        self.frames += frames;
        self.mpjpe += w * mpjpe_root_aligned(&pr, &pt, n) as f64;
        self.mpjpe_trans += w * mpjpe(&pr, &pt) as f64;
        self.mpjpe_yaw += w * mpjpe_yaw_aligned(&pr, &pt, n) as f64;
        self.mpjpe_true_root += w * mpjpe_root_aligned(&all_joint_positions(true_root), &pt, n) as f64;
        let turn = body_turn_deg(&pr, &pt, n) as f64;
        self.body_turn += w * turn;
        self.turned += usize::from(turn > TURNED_DEGREES);
        self.mpjpe_free += w * mpjpe_root_aligned(&all_joint_positions(free), &pt, n) as f64;
        self.geodist_free += w * geodesic_distance_deg(free.all_rotations(), truth.all_rotations()) as f64;
        self.fs += w * foot_skating(&pr, n, &feet, fps, CONTACT_HEIGHT) as f64;
        self.gp += w * ground_penetration(&pr) as f64;
        self.fs_truth += w * foot_skating(&pt, n, &feet, fps, CONTACT_HEIGHT) as f64;
        self.gp_truth += w * ground_penetration(&pt) as f64;
        let kinds = JointKind::of(truth.skeleton());
        let by_kind = geodesic_sums_by_kind(rebuilt.all_rotations(), truth.all_rotations(), &kinds);
        // The clip's mean over joints and frames, weighted by its frames: the summed angle / joints.
        self.geodist += by_kind.iter().map(|(sum, _)| sum).sum::<f64>() / n as f64;
        add_kinds(&mut self.geodist_kinds, by_kind);
    }

    /// Adds another set.
    pub fn merge(&mut self, o: &Sums) {
        self.clips += o.clips;
        self.frames += o.frames;
        self.mpjpe += o.mpjpe;
        self.mpjpe_trans += o.mpjpe_trans;
        self.mpjpe_yaw += o.mpjpe_yaw;
        self.mpjpe_free += o.mpjpe_free;
        self.geodist += o.geodist;
        self.geodist_free += o.geodist_free;
        self.fs += o.fs;
        self.gp += o.gp;
        self.fs_truth += o.fs_truth;
        self.gp_truth += o.gp_truth;
        add_kinds(&mut self.geodist_kinds, o.geodist_kinds);
        self.mpjpe_true_root += o.mpjpe_true_root;
        self.body_turn += o.body_turn;
        self.turned += o.turned;
    }

    /// The means.
    pub fn scores(&self) -> Scores {
        let w = (self.frames as f64).max(1.0);
        Scores {
            clips: self.clips,
            frames: self.frames,
            mpjpe: self.mpjpe / w,
            mpjpe_trans: self.mpjpe_trans / w,
            mpjpe_yaw: self.mpjpe_yaw / w,
            mpjpe_free: self.mpjpe_free / w,
            geodist: self.geodist / w,
            geodist_free: self.geodist_free / w,
            fs: self.fs / w,
            gp: self.gp / w,
            fs_truth: self.fs_truth / w,
            gp_truth: self.gp_truth / w,
            geodist_root: kind_mean(self.geodist_kinds[JointKind::Root as usize]),
            geodist_inner: kind_mean(self.geodist_kinds[JointKind::Inner as usize]),
            geodist_unseen: kind_mean(self.geodist_kinds[JointKind::Unseen as usize]),
            mpjpe_true_root: self.mpjpe_true_root / w,
            body_turn: self.body_turn / w,
            turned_clips: self.turned,
        }
    }
}

/// Adds summed angles and joint-frame counts per kind.
fn add_kinds(into: &mut [(f64, usize); 3], add: [(f64, usize); 3]) {
    for (sum, more) in into.iter_mut().zip(add) {
        *sum = (sum.0 + more.0, sum.1 + more.1);
    }
}

/// The mean of a summed angle over its joint-frames (zero when there are none).
fn kind_mean((sum, count): (f64, usize)) -> f64 {
    if count == 0 { 0.0 } else { sum / count as f64 }
}

/// Reconstruction results of one codec: per `(split, source)`, and clips it could not take.
#[derive(Default)]
pub struct Reconstruction {
    /// Sums per split and source.
    pub groups: BTreeMap<(String, String), Sums>,
    /// Clips the codec refused (the baseline cannot take skeletons larger than its padding).
    pub refused: usize,
}

impl Reconstruction {
    /// The sums merged over each split's sources.
    pub fn by_split(&self) -> BTreeMap<String, Sums> {
        let mut out: BTreeMap<String, Sums> = BTreeMap::new();
        for ((split, _), sums) in &self.groups {
            out.entry(split.clone()).or_default().merge(sums);
        }
        out
    }
}

/// Runs every clip through the codec, each read in its basis (`bases[k]` for `clips[k]`) and
/// measured back in its rig's own joint frames: as decoded, and with `cleanup`, also after the
/// cleanup every decoded result gets by default (planted feet standing on the floor `real`
/// records for the rig, as `anymo detokenize` does).
pub fn reconstruction(
    codec: &mut dyn Codec,
    graphs: &mut Graphs,
    clips: &[&ModelClip],
    bases: &[Basis],
    (window, overlap): (usize, usize),
    cleanup: Option<&RealMotion>,
) -> Result<Rebuilt> {
    let mut out = Rebuilt { decoded: Reconstruction::default(), cleaned: cleanup.map(|_| Reconstruction::default()) };
    for (clip, basis) in clips.iter().zip(bases) {
        let entered = basis.enter(&clip.motion);
        let graph = graphs.of(entered.skeleton())?;
        let key = (clip.split.as_str().to_string(), clip.item.source.clone());
        let Ok(r) = reconstruct(codec, &graph, &entered, window, overlap) else {
            out.decoded.refused += 1;
            if let Some(cleaned) = &mut out.cleaned {
                cleaned.refused += 1;
            }
            continue;
        };
        let [truth, anchored, free, true_root] = [&r.truth, &r.anchored, &r.free, &r.true_root].map(|m| basis.leave(m));
        if let (Some(cleaned), Some(real)) = (&mut out.cleaned, cleanup) {
            // Decoded on the clip's anchors, as `anymo detokenize` decodes a real clip's tokens,
            // so the root keeps its path.
            let cleanup = Cleanup { keep_root: true, ..Cleanup::default() };
            let finish = |m: &Motion| clean_up(m.clone(), Some(&cleanup), real).0;
            cleaned.groups.entry(key.clone()).or_default().add(
                &truth,
                &finish(&anchored),
                &finish(&free),
                &finish(&true_root),
            );
        }
        out.decoded.groups.entry(key).or_default().add(&truth, &anchored, &free, &true_root);
    }
    Ok(out)
}

/// A codec's reconstructions of a set of clips, as decoded and after the cleanup.
pub struct Rebuilt {
    /// As the decoder gives them.
    pub decoded: Reconstruction,
    /// After the default cleanup, when it was asked for.
    pub cleaned: Option<Reconstruction>,
}

/// The basis each of `measured` is read in by a codec of `representation`, from clips other
/// than itself: for a rig with training clips among `all`, theirs (as in training); for any
/// other rig, the other clips of that rig in `all`; for a rig with no other clip, its rest pose.
pub fn held_bases(representation: Representation, all: &[&ModelClip], measured: &[&ModelClip]) -> Vec<Basis> {
    let train: Vec<&ModelClip> = all.iter().copied().filter(|c| c.split == Split::Train).collect();
    let seen = bases_by_topology(representation, &train);
    measured
        .iter()
        .map(|clip| {
            let key = topology(&clip.motion);
            seen.get(&key).cloned().unwrap_or_else(|| {
                let others = all.iter().filter(|c| !std::ptr::eq(**c, *clip) && topology(&c.motion) == key);
                Basis::of(representation, clip.motion.skeleton(), others.map(|c| &c.motion))
            })
        })
        .collect()
}

/// Each clip's basis from its own mean pose as `anymo tokenize` writes it beside the tokens
/// (its [`PoseCode`]): what a clip's tokens are read against on the rig they came from. Against
/// the held-out bases of [`held_bases`] (what generated tokens, or tokens without their pose,
/// are read against) it tells how much of a codec's error is the reference pose differing from
/// the clip's own, and how much the codec's.
pub fn pose_code_bases(measured: &[&ModelClip]) -> Vec<Basis> {
    measured
        .iter()
        .map(|clip| {
            let skeleton = clip.motion.skeleton();
            let mean = ReferencePose::mean_of([&clip.motion]).expect("a clip has frames");
            Basis::Reference(PoseCode::new(skeleton, &mean).reference_on(skeleton).unwrap_or(mean))
        })
        .collect()
}

/// A clip held still: every joint but the root keeps its mean local rotation over the clip, and
/// the root moves as it does in the clip. A reference for the table: a tokenizer that keeps no
/// motion but the root's would score this.
pub fn static_pose(motion: &Motion, _: &Basis) -> Motion {
    let (n, frames) = (motion.skeleton().len(), motion.frames());
    let mean: Vec<glam::Quat> = (0..n)
        .map(|j| {
            let first = glam::Vec4::from(motion.rotations(0)[j]);
            let sum = (0..frames).fold(glam::Vec4::ZERO, |acc, f| {
                let q = glam::Vec4::from(motion.rotations(f)[j]);
                acc + if q.dot(first) < 0.0 { -q } else { q }
            });
            glam::Quat::from_vec4(sum).normalize()
        })
        .collect();
    let rotations = (0..frames)
        .flat_map(|f| (0..n).map(move |j| (f, j)))
        .map(|(f, j)| if j == 0 { motion.rotations(f)[0] } else { mean[j] })
        .collect();
    Motion::new(motion.skeleton().clone(), motion.frame_time(), rotations, motion.all_translations().to_vec())
        .expect("the clip's own shapes")
}

/// A reference that is no model: each clip replaced by `hold` of itself and its basis (such as
/// [`static_pose`], [`rest_hold`] or [`reference_hold`]), grouped like [`reconstruction`].
pub fn held_reference(clips: &[&ModelClip], bases: &[Basis], hold: fn(&Motion, &Basis) -> Motion) -> Reconstruction {
    let mut out = Reconstruction::default();
    for (clip, basis) in clips.iter().zip(bases) {
        let truth = canonicalise(&clip.motion);
        let held = hold(&truth, basis);
        out.groups
            .entry((clip.split.as_str().to_string(), clip.item.source.clone()))
            .or_default()
            .add(&truth, &held, &held, &held);
    }
    out
}

/// A clip held in its rig's rest pose: every joint but the root at the identity local rotation,
/// the root exactly as in the clip. What a tokenizer that kept only the root would give, on a rig
/// whose rest pose is a real pose; on a rig whose rest pose lies on its side, far worse.
pub fn rest_hold(motion: &Motion, _: &Basis) -> Motion {
    let n = motion.skeleton().len();
    let rotations =
        motion.all_rotations().iter().enumerate().map(|(k, q)| if k % n == 0 { *q } else { Quat::IDENTITY }).collect();
    Motion::new(motion.skeleton().clone(), motion.frame_time(), rotations, motion.all_translations().to_vec())
        .expect("the clip's own shapes")
}

/// A clip held in its basis's reference pose: [`rest_hold`] in the basis, so every joint but the
/// root keeps the reference's rotation and the root moves exactly as in the clip. What a
/// tokenizer of the reference representation that kept only the root would give.
pub fn reference_hold(motion: &Motion, basis: &Basis) -> Motion {
    basis.leave(&rest_hold(&basis.enter(motion), basis))
}

/// The clips re-expressed on rigs whose every joint frame is turned by a random rotation
/// (uniform over rotations, the same for every clip of a rig: seeded by the rig's joint names):
/// the same world motion on rigs of other local-axis conventions and other rest poses.
pub fn with_turned_frames(clips: &[&ModelClip]) -> Vec<ModelClip> {
    clips
        .iter()
        .map(|clip| {
            let names: Vec<&str> = clip.motion.skeleton().joints().iter().map(|j| j.name.as_str()).collect();
            let seed = u64::from_le_bytes(blake3::hash(names.join("/").as_bytes()).as_bytes()[..8].try_into().unwrap());
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let turns: Vec<Quat> = names.iter().map(|_| uniform_rotation(&mut rng)).collect();
            ModelClip { item: clip.item.clone(), split: clip.split, motion: turn_joint_frames(&clip.motion, &turns) }
        })
        .collect()
}

/// A rotation drawn uniformly (Shoemake's method).
fn uniform_rotation(rng: &mut impl Rng) -> Quat {
    let (u1, u2, u3): (f32, f32, f32) = (rng.random(), rng.random(), rng.random());
    let tau = std::f32::consts::TAU;
    let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
    Quat::from_xyzw(a * (tau * u2).sin(), a * (tau * u2).cos(), b * (tau * u3).sin(), b * (tau * u3).cos())
}

/// One transfer direction: clips of one kind onto one target skeleton.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TransferScores {
    /// What moves where ("human -> quadruped").
    pub name: String,
    /// The target skeleton's subject and joint count.
    pub target: String,
    /// Clips transferred.
    pub clips: usize,
    /// Root-aligned MPJPE of A -> B -> A against A, diameters.
    pub cycle_mpjpe: f64,
    /// Root-aligned MPJPE of A -> A (plain reconstruction), for reference.
    pub reconstruction_mpjpe: f64,
    /// Foot skating of the transfers, diameters per second.
    pub fs: f64,
    /// Ground penetration of the transfers, diameters.
    pub gp: f64,
    /// Pearson correlation of pairwise motion distances before and after transfer (NEC F).
    pub distance_correlation: f64,
}

fn pairwise(motions: &[Motion]) -> Vec<f64> {
    let mut out = Vec::new();
    let positions: Vec<Vec<glam::Vec3>> = motions.iter().map(all_joint_positions).collect();
    for a in 0..motions.len() {
        for b in a + 1..motions.len() {
            let n = motions[a].skeleton().len();
            let frames = motions[a].frames().min(motions[b].frames());
            let d = mpjpe_root_aligned(&positions[a][..frames * n], &positions[b][..frames * n], n);
            out.push(d as f64);
        }
    }
    out
}

fn pearson(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len().max(1) as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let cov: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let vx: f64 = x.iter().map(|a| (a - mx).powi(2)).sum();
    let vy: f64 = y.iter().map(|b| (b - my).powi(2)).sum();
    cov / (vx * vy).sqrt().max(1e-12)
}

/// A transfer target: a cleaned clip whose skeleton and feet are the target's, and the basis
/// it is read in.
pub struct Rig<'a> {
    /// The clip.
    pub clip: &'a ModelClip,
    /// Its basis.
    pub basis: &'a Basis,
}

/// Transfers `sources` (each read in its basis, `bases[k]` for `sources[k]`) onto `target`.
/// Every motion is measured in its rig's own joint frames.
pub fn transfer(
    tat: &mut Tat,
    graphs: &mut Graphs,
    name: &str,
    sources: &[&ModelClip],
    bases: &[Basis],
    target: Rig,
) -> Result<TransferScores> {
    let target_skeleton = target.basis.enter_skeleton(&target.clip.motion);
    let target_graph = graphs.of(&target_skeleton)?;
    let feet = foot_joints(&target.clip.motion, FOOT_BAND);
    let (mut cycle, mut recon, mut fs, mut gp, mut frames) = (0f64, 0f64, 0f64, 0f64, 0f64);
    let mut originals = Vec::new();
    let mut transferred = Vec::new();
    for (clip, basis) in sources.iter().zip(bases) {
        let entered = basis.enter(&clip.motion);
        let graph = graphs.of(entered.skeleton())?;
        let tokens = tokenize(tat, &graph, &entered)?;
        let own = detokenize(tat, &tokens, &graph, entered.skeleton())?;
        let moved = detokenize(tat, &tokens, &target_graph, &target_skeleton)?;
        let back_tokens = tokenize(tat, &target_graph, &moved)?;
        let back = detokenize(tat, &back_tokens, &graph, entered.skeleton())?;
        let moved = target.basis.leave(&moved);
        let n = clip.motion.skeleton().len();
        let truth = all_joint_positions(&clip.motion);
        let w = clip.motion.frames() as f64;
        cycle += w * mpjpe_root_aligned(&all_joint_positions(&back), &truth, n) as f64;
        recon += w * mpjpe_root_aligned(&all_joint_positions(&own), &truth, n) as f64;
        let pm = all_joint_positions(&moved);
        fs += w * foot_skating(&pm, target_skeleton.len(), &feet, moved.fps() as f32, CONTACT_HEIGHT) as f64;
        gp += w * ground_penetration(&pm) as f64;
        frames += w;
        originals.push(clip.motion.clone());
        transferred.push(moved);
    }
    let frames = frames.max(1.0);
    Ok(TransferScores {
        name: name.to_string(),
        target: format!("{} ({} joints)", target.clip.item.subject, target_skeleton.len()),
        clips: sources.len(),
        cycle_mpjpe: cycle / frames,
        reconstruction_mpjpe: recon / frames,
        fs: fs / frames,
        gp: gp / frames,
        distance_correlation: pearson(&pairwise(&originals), &pairwise(&transferred)),
    })
}

/// What a codec's row name gets when each clip is read against its own pose code (see
/// [`pose_code_bases`]), as a tokens file decodes on its own rig.
pub const WITH_POSE_CODE: &str = " (with its pose code)";

/// The reference row's name: each clip held in its mean pose (see [`static_pose`]).
pub const STATIC_REFERENCE: &str = "static pose (reference)";
/// The other reference row's name: each clip held in its rig's rest pose (see [`rest_hold`]).
pub const REST_REFERENCE: &str = "rest pose (reference)";
/// The third reference row's name: each clip held in a reference pose of its rig taken from
/// other clips (see [`reference_hold`] and [`held_bases`]), the root exact.
pub const REFERENCE_HOLD: &str = "reference pose (reference)";

/// The baseline's windows when measured (its card has none: NEC Table 1's protocol).
const BASELINE_WINDOW: usize = 64;
/// The overlap of the baseline's windows.
const BASELINE_OVERLAP: usize = 16;

/// What `anymo eval tokenizer` measures.
pub struct TokenizerReport {
    /// The reconstruction tables (per split, per source, GeoDist by joint kind) and each TAT's
    /// transfer table, as Markdown.
    pub markdown: String,
    /// Each model's scores per split and per source, then the static reference's, by name.
    pub reconstruction: Vec<(String, serde_json::Map<String, serde_json::Value>)>,
    /// Each TAT's transfers, by name.
    pub transfer: Vec<(String, Vec<TransferScores>)>,
}

impl TokenizerReport {
    /// The whole report as one JSON object, with the command that made it.
    pub fn json(&self, command: &str) -> Result<serde_json::Value> {
        let mut out: serde_json::Map<String, serde_json::Value> =
            self.reconstruction.iter().map(|(k, v)| (k.clone(), serde_json::Value::Object(v.clone()))).collect();
        if !self.transfer.is_empty() {
            let by_model = self.transfer.iter().map(|(k, v)| Ok((k.clone(), serde_json::to_value(v)?)));
            out.insert("transfer".into(), serde_json::Value::Object(by_model.collect::<Result<_>>()?));
        }
        out.insert("command".into(), command.into());
        Ok(serde_json::Value::Object(out))
    }
}

/// Reconstruction of the test and zero-shot clips of `clips` by each named codec of `set`,
/// each clip read in a basis taken from other clips of its rig (see [`held_bases`]), beside the
/// three references; with `invariance`, each codec again on the same clips with turned joint
/// frames; and for each TAT among them, its transfers (`transfer_clips` source clips per
/// direction, none when 0).
pub fn evaluate_tokenizers(
    set: &Checkpoints,
    names: &[String],
    clips: &[ModelClip],
    transfer_clips: usize,
    invariance: bool,
    encoder: &mut CachedEncoder,
) -> Result<TokenizerReport> {
    let all: Vec<&ModelClip> = clips.iter().collect();
    let eval_clips: Vec<&ModelClip> = clips.iter().filter(|c| c.split != Split::Train).collect();
    eprintln!("{} test and zero-shot clips", eval_clips.len());
    let rest_bases = vec![Basis::Rest; eval_clips.len()];
    let reference_bases = held_bases(Representation::Reference, &all, &eval_clips);
    let bases = |representation| match representation {
        Representation::Rest => &rest_bases,
        Representation::Reference => &reference_bases,
    };
    let reference = held_reference(&eval_clips, &rest_bases, static_pose);
    // The floors the cleanup stands feet on, from the training clips only (a rig no model saw
    // gets none, as in `anymo detokenize`).
    let train: Vec<&ModelClip> = all.iter().copied().filter(|c| c.split == Split::Train).collect();
    let real = RealMotion::measure(&train);
    let mut tables = Tables::new(&reference);
    let turned_all = if invariance { with_turned_frames(&all) } else { Vec::new() };
    let turned_refs: Vec<&ModelClip> = turned_all.iter().filter(|c| c.split != Split::Train).collect();
    let turned_all_refs: Vec<&ModelClip> = turned_all.iter().collect();
    let turned_reference_bases = held_bases(Representation::Reference, &turned_all_refs, &turned_refs);
    let turned_bases = |representation| match representation {
        Representation::Rest => &rest_bases,
        Representation::Reference => &turned_reference_bases,
    };
    let mut reconstruction = Vec::new();
    let mut transfer = Vec::new();
    for name in names {
        let (mut codec, card) = codecs::load(&set.get(name), encoder)?;
        let (window, overlap, representation) = match &card.config {
            CodecCard::Tokenizer(t) => (t.tokenizer.window, t.tokenizer.overlap, t.tokenizer.representation),
            CodecCard::Baseline(b) => (BASELINE_WINDOW, BASELINE_OVERLAP, b.baseline.representation),
        };
        let mut graphs = Graphs::new(encoder);
        let windows = (window, overlap);
        let rebuilt = self::reconstruction(
            codec.as_mut(),
            &mut graphs,
            &eval_clips,
            bases(representation),
            windows,
            Some(&real),
        )?;
        let own = rebuilt.decoded;
        reconstruction.push((name.clone(), tables.add(name, &own)?));
        if let Some(cleaned) = rebuilt.cleaned {
            let label = format!("{name}{CLEANED}");
            reconstruction.push((label.clone(), tables.add(&label, &cleaned)?));
        }
        if representation == Representation::Reference {
            let coded = pose_code_bases(&eval_clips);
            let rebuilt = self::reconstruction(codec.as_mut(), &mut graphs, &eval_clips, &coded, windows, None)?;
            let label = format!("{name}{WITH_POSE_CODE}");
            reconstruction.push((label.clone(), tables.add(&label, &rebuilt.decoded)?));
        }
        if invariance {
            let on = turned_bases(representation);
            let turned = self::reconstruction(codec.as_mut(), &mut graphs, &turned_refs, on, windows, None)?.decoded;
            let label = format!("{name} (turned frames)");
            reconstruction.push((label.clone(), tables.add(&label, &turned)?));
            tables.compare_rigs(name, &own, &turned);
        }
        if matches!(card.config, CodecCard::Tokenizer(_)) && transfer_clips > 0 {
            drop(codec);
            transfer.push((name.clone(), transfers(set, name, clips, transfer_clips, encoder)?));
        }
    }
    reconstruction.push((STATIC_REFERENCE.to_string(), tables.add(STATIC_REFERENCE, &reference)?));
    let rest = held_reference(&eval_clips, &rest_bases, rest_hold);
    reconstruction.push((REST_REFERENCE.to_string(), tables.add(REST_REFERENCE, &rest)?));
    let held = held_reference(&eval_clips, &reference_bases, reference_hold);
    reconstruction.push((REFERENCE_HOLD.to_string(), tables.add(REFERENCE_HOLD, &held)?));
    let mut markdown = tables.into_text();
    for (name, transfers) in &transfer {
        markdown.push_str(&format!("\n{name}\n\n{}", transfer_table(transfers)));
    }
    Ok(TokenizerReport { markdown, reconstruction, transfer })
}

/// The transfer table, as Markdown.
fn transfer_table(transfers: &[TransferScores]) -> String {
    let mut t = Table::new(&[
        "transfer",
        "target",
        "clips",
        "cycle MPJPE",
        "reconstruction MPJPE",
        "FS",
        "GP",
        "distance correlation",
    ]);
    for s in transfers {
        t.row(&[
            s.name.clone(),
            s.target.clone(),
            s.clips.to_string(),
            f(s.cycle_mpjpe),
            f(s.reconstruction_mpjpe),
            f(s.fs),
            f(s.gp),
            format!("{:.3}", s.distance_correlation),
        ]);
    }
    t.into_text()
}

/// The reconstruction tables, per split and per source, as Markdown.
struct Tables {
    table: Table,
    per_source: Table,
    by_kind: Table,
    against_static: Table,
    invariance: Table,
    /// The static reference's scores per split and source, which every model is held against.
    reference: BTreeMap<(String, String), Scores>,
}

/// The columns every reconstruction row has, after its model and split (and source).
const SCORES: [&str; 7] = [
    "clips",
    "MPJPE",
    "MPJPE (yaw aligned)",
    "MPJPE (free root)",
    "MPJPE (with trans)",
    "GeoDist (deg)",
    "GeoDist (free root)",
];

impl Tables {
    /// Empty tables, holding models against `reference` source by source.
    fn new(reference: &Reconstruction) -> Tables {
        let columns = |first: &[&'static str], last: &[&'static str]| -> Vec<&'static str> {
            first.iter().chain(&SCORES).chain(last).copied().collect()
        };
        Tables {
            table: Table::new(&columns(&["model", "split"], &["FS", "GP", "FS (GT)", "GP (GT)"])),
            per_source: Table::new(&columns(&["model", "split", "source"], &[])),
            by_kind: Table::new(&[
                "model",
                "split",
                "GeoDist (deg)",
                "root",
                "joints that move joints",
                "joints that move none",
            ]),
            against_static: Table::new(&[
                "model",
                "split",
                "sources",
                "sources below the static pose",
                "MPJPE (mean over sources)",
                "static pose (mean over sources)",
                "ratio (mean over sources)",
                "worst ratio",
                "MPJPE (true root)",
                "body turn (deg)",
                "turned bodies",
            ]),
            invariance: Table::new(&[
                "model",
                "split",
                "MPJPE (own rigs)",
                "MPJPE (turned frames)",
                "ratio",
                "GeoDist (own rigs)",
                "GeoDist (turned frames)",
                "turned bodies (own / turned frames)",
            ]),
            reference: reference.groups.iter().map(|(k, sums)| (k.clone(), sums.scores())).collect(),
        }
    }

    /// Every table, as Markdown.
    fn into_text(self) -> String {
        [self.table, self.per_source, self.by_kind, self.against_static, self.invariance]
            .map(Table::into_text)
            .join("\n")
    }

    /// A row per split holding `model` on its own rigs against the same clips with turned frames.
    fn compare_rigs(&mut self, model: &str, own: &Reconstruction, turned: &Reconstruction) {
        let (own, turned) = (own.by_split(), turned.by_split());
        for (split, o) in &own {
            let Some(t) = turned.get(split) else { continue };
            let (o, t) = (o.scores(), t.scores());
            self.invariance.row(&[
                model.to_string(),
                split.clone(),
                f(o.mpjpe),
                f(t.mpjpe),
                format!("{:.2}", t.mpjpe / o.mpjpe.max(1e-12)),
                format!("{:.2}", o.geodist),
                format!("{:.2}", t.geodist),
                format!("{} / {}", o.turned_clips, t.turned_clips),
            ]);
        }
    }

    /// A row per split: the model's MPJPE against the static reference's on each source.
    fn add_against_static(&mut self, name: &str, rec: &Reconstruction) {
        let mut by_split: BTreeMap<&str, Vec<(&str, f64, f64)>> = BTreeMap::new();
        for ((split, source), sums) in &rec.groups {
            if let Some(reference) = self.reference.get(&(split.clone(), source.clone())) {
                by_split.entry(split).or_default().push((source, sums.scores().mpjpe, reference.mpjpe));
            }
        }
        let split_scores = rec.by_split();
        for (split, sources) in by_split {
            let n = sources.len() as f64;
            let ratio = |(_, model, reference): &(&str, f64, f64)| model / reference.max(1e-12);
            let worst = sources.iter().max_by(|a, b| ratio(a).total_cmp(&ratio(b))).expect("a source");
            let s = split_scores[split].scores();
            self.against_static.row(&[
                name.to_string(),
                split.to_string(),
                sources.len().to_string(),
                sources.iter().filter(|x| ratio(x) < 1.0).count().to_string(),
                f(sources.iter().map(|x| x.1).sum::<f64>() / n),
                f(sources.iter().map(|x| x.2).sum::<f64>() / n),
                format!("{:.2}", sources.iter().map(ratio).sum::<f64>() / n),
                format!("{:.2} ({})", ratio(worst), worst.0),
                f(s.mpjpe_true_root),
                format!("{:.1}", s.body_turn),
                s.turned_clips.to_string(),
            ]);
        }
    }
}

/// The cells of [`SCORES`].
fn score_cells(s: &Scores) -> Vec<String> {
    vec![
        s.clips.to_string(),
        f(s.mpjpe),
        f(s.mpjpe_yaw),
        f(s.mpjpe_free),
        f(s.mpjpe_trans),
        format!("{:.2}", s.geodist),
        format!("{:.2}", s.geodist_free),
    ]
}

impl Tables {
    /// Adds one model's rows; returns its scores per split and per source, as JSON.
    fn add(&mut self, name: &str, rec: &Reconstruction) -> Result<serde_json::Map<String, serde_json::Value>> {
        let by_split = rec.by_split();
        let mut model_json = serde_json::Map::new();
        if name != STATIC_REFERENCE {
            self.add_against_static(name, rec);
        }
        for ((split, source), sums) in &rec.groups {
            let s = sums.scores();
            self.per_source.row(&[&[name.to_string(), split.clone(), source.clone()][..], &score_cells(&s)].concat());
            model_json.insert(format!("{split}/{source}"), serde_json::to_value(s)?);
        }
        for (split, sums) in &by_split {
            let s = sums.scores();
            let truth = [f(s.fs), f(s.gp), f(s.fs_truth), f(s.gp_truth)];
            self.table.row(&[&[name.to_string(), split.clone()][..], &score_cells(&s), &truth].concat());
            let kinds = [s.geodist, s.geodist_root, s.geodist_inner, s.geodist_unseen].map(|g| format!("{g:.2}"));
            self.by_kind.row(&[&[name.to_string(), split.clone()][..], &kinds].concat());
            model_json.insert(split.clone(), serde_json::to_value(s)?);
        }
        if rec.refused > 0 {
            let mut cells = vec![name.to_string(), "refused".into(), rec.refused.to_string()];
            cells.push("(skeleton larger than the model takes)".into());
            cells.resize(SCORES.len() + 6, String::new());
            self.table.row(&cells);
            model_json.insert("refused".into(), rec.refused.into());
        }
        Ok(model_json)
    }
}

/// Human -> human of other proportions, human -> quadruped, quadruped -> quadruped, each from
/// test clips onto a skeleton of another subject, by the TAT checkpoint `model`. Sources are read
/// in bases held out as in [`held_bases`]; a target in the basis of its own clip, as a user's
/// target file gives it.
fn transfers(
    set: &Checkpoints,
    model: &str,
    clips: &[ModelClip],
    per_direction: usize,
    encoder: &mut CachedEncoder,
) -> Result<Vec<TransferScores>> {
    let (mut tat, _) = set.get(model).load_tat(encoder)?;
    let representation = tat.config().representation;
    let all: Vec<&ModelClip> = clips.iter().collect();
    let mut graphs = Graphs::new(encoder);
    let pick = |source: &str, split: Split| -> Vec<&ModelClip> {
        clips.iter().filter(|c| c.item.source == source && c.split == split).take(per_direction).collect()
    };
    let first = |subject: &str| clips.iter().find(|c| c.item.subject == subject);
    let humans = pick("bandai-namco-dataset-2", Split::Test);
    let horses: Vec<&ModelClip> =
        clips.iter().filter(|c| c.item.subject == "horse" && c.split != Split::Train).take(per_direction).collect();
    let mut out = Vec::new();
    let plans: [(&str, &Vec<&ModelClip>, Option<&ModelClip>); 4] = [
        ("human -> human (CMU rig)", &humans, clips.iter().find(|c| c.item.source == "cmu-mocap")),
        ("human -> human (Xia rig)", &humans, clips.iter().find(|c| c.item.source == "xia-style")),
        ("human -> quadruped", &humans, first("horse")),
        ("quadruped -> quadruped", &horses, first("wolf")),
    ];
    for (name, sources, target) in plans {
        let Some(target) = target else { continue };
        if sources.is_empty() {
            continue;
        }
        let source_bases = held_bases(representation, &all, sources);
        let target_basis = Basis::of(representation, target.motion.skeleton(), [&target.motion]);
        let rig = Rig { clip: target, basis: &target_basis };
        out.push(transfer(&mut tat, &mut graphs, name, sources, &source_bases, rig)?);
    }
    Ok(out)
}
