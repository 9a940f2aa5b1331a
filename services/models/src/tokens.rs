//! Motion to TAT tokens and back, on the source skeleton or any other, as users meet it: the
//! CLI's `tokenize`, `detokenize` and `transfer` and the server's token endpoints use it.

use super::codecs::Graphs;
use super::data::MODEL_FPS;
use super::studio::{cleaned_clip, pose_source};
use crate::checkpoint::Checkpoint;
use crate::error::ModelError;
use crate::quality::{Made, QualityReport, RealMotion, clean_up};
use anymo_motion::cleanup::Cleanup;
use anymo_motion::motion::Motion;
use anymo_motion::prep::clean::{CleanOptions, clean};
use anymo_motion::reference::ReferencePose;
use anymo_motion::skeleton::Skeleton;
use anymo_tokenizer::tat::window::{Tokens, detokenize, tokenize};
use anymo_tokenizer::tat::{Basis, Representation, Tat, anchor};
use anymo_tokenizer::text::CachedEncoder;
use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

/// The highest frame rate decoded motion is written at.
pub const MAX_FPS: f64 = 1000.0;

type Result<T, E = ModelError> = std::result::Result<T, E>;

/// The tokens file: the tokens and the checkpoint that made them.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TokenFile {
    /// The tokenizer checkpoint's name.
    pub model: String,
    /// Its training steps (which version of it).
    pub model_steps: u64,
    /// The tokens.
    pub tokens: Tokens,
    /// The clip's own mean pose, which the tokens were read against (a tokenizer of the
    /// reference representation; files from before it existed have none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose: Option<PoseCode>,
}

/// A clip's mean pose, written beside its tokens: the tokens hold the motion around it, and
/// decoding on the skeleton they came from reads them against it, so a clip comes back in its
/// own pose whichever file of its rig is the target. On any other skeleton the target's own
/// pose is used, as for generated tokens.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseCode {
    /// The cleaned skeleton's joints, in order.
    pub joints: Vec<PoseJoint>,
}

/// One joint of a [`PoseCode`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseJoint {
    /// Its name.
    pub name: String,
    /// Its parent's index (none for the root).
    pub parent: Option<usize>,
    /// Its rest offset's direction (zero for a joint on its parent), which tells the rig's
    /// joint-frame convention apart from another rig's with the same names.
    pub direction: [f32; 3],
    /// Its end site's direction, for a leaf that has one (the only trace of a leaf's frame).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub end: Option<[f32; 3]>,
    /// Its global rotation in the mean pose facing +Z (x, y, z, w), to 4 decimals.
    pub rotation: [f32; 4],
}

/// The largest angle between a joint's rest direction in a pose code and in a target for the
/// code to apply: the same rig, perhaps of other proportions, never another joint-frame
/// convention (whose rest bones point elsewhere).
pub const POSE_CODE_DEGREES: f32 = 10.0;

impl PoseCode {
    /// The code of a reference pose taken on `skeleton` (cleaned).
    pub fn new(skeleton: &Skeleton, pose: &ReferencePose) -> PoseCode {
        let round = |x: f32| (x * 1e4).round() / 1e4;
        let joints = skeleton
            .joints()
            .iter()
            .zip(pose.globals())
            .map(|(joint, q)| PoseJoint {
                name: joint.name.clone(),
                parent: joint.parent,
                direction: joint.offset.normalize_or_zero().to_array().map(round),
                end: joint.end_site.map(|e| e.normalize_or_zero().to_array().map(round)),
                rotation: q.to_array().map(round),
            })
            .collect();
        PoseCode { joints }
    }

    /// Why a code (perhaps from a client) cannot be read, if it cannot: every rotation must be
    /// a unit quaternion (to the 4 decimals written) and every direction finite.
    fn check(&self) -> Result<(), String> {
        let unit = |q: &[f32; 4]| (Quat::from_array(*q).length() - 1.0).abs() < 1e-2;
        let finite = |v: &[f32; 3]| v.iter().all(|x| x.is_finite());
        match self
            .joints
            .iter()
            .find(|j| !unit(&j.rotation) || !finite(&j.direction) || !j.end.as_ref().is_none_or(finite))
        {
            Some(joint) => {
                Err(format!("the pose code of joint {:?} is not a unit rotation with finite directions", joint.name))
            }
            None => Ok(()),
        }
    }

    /// The pose, when `skeleton` (cleaned) is the one the code was taken on: the same joints,
    /// parents and, within [`POSE_CODE_DEGREES`], directions of the bones and end sites both
    /// have.
    pub fn reference_on(&self, skeleton: &Skeleton) -> Option<ReferencePose> {
        let cos = POSE_CODE_DEGREES.to_radians().cos();
        // Bones of no length point nowhere, and files of one rig differ in them (an end site
        // of length 0 in one, 10 cm in another): only bones both have are compared.
        let along = |code: [f32; 3], bone: Vec3| {
            let (a, b) = (Vec3::from_array(code), bone.normalize_or_zero());
            a.length() < 0.5 || b == Vec3::ZERO || a.dot(b) >= cos
        };
        let same = self.joints.len() == skeleton.len()
            && self.joints.iter().zip(skeleton.joints()).all(|(code, joint)| {
                let ends = match (code.end, joint.end_site) {
                    (Some(a), Some(b)) => along(a, b),
                    _ => true,
                };
                // The root's offset is where the file puts the body, not a bone.
                let bone = joint.parent.is_none() || along(code.direction, joint.offset);
                code.name == joint.name && code.parent == joint.parent && bone && ends
            });
        same.then(|| ReferencePose::from_globals(self.joints.iter().map(|j| Quat::from_array(j.rotation))))
    }
}

/// A trained tokenizer with the sentence encoder its skeleton graphs need, the cleanup decoded
/// motion gets and the real clips' figures its quality reports compare with.
pub struct TokenCodec {
    tat: Tat,
    name: String,
    steps: u64,
    encoder: CachedEncoder,
    cleanup: Option<Cleanup>,
    real: RealMotion,
}

impl TokenCodec {
    /// Loads a tokenizer checkpoint.
    pub fn load(tokenizer: &Checkpoint, encoder: CachedEncoder) -> anyhow::Result<TokenCodec> {
        let mut encoder = encoder;
        let (tat, card) = tokenizer.load_tat(&mut encoder)?;
        let name = tokenizer.name().to_string();
        Ok(TokenCodec {
            tat,
            name,
            steps: card.steps,
            encoder,
            cleanup: Some(Cleanup::default()),
            real: RealMotion::default(),
        })
    }

    /// Sets the cleanup decoded motion gets (`None` gives the decoder's output as it is).
    pub fn set_cleanup(&mut self, cleanup: Option<Cleanup>) {
        self.cleanup = cleanup;
    }

    /// Sets the real clips' figures the quality reports compare with.
    pub fn set_real_motion(&mut self, real: RealMotion) {
        self.real = real;
    }

    /// A clip's tokens. A tokenizer of the reference representation reads the clip against
    /// its own mean pose, which the file carries as its [`PoseCode`].
    pub fn tokenize(&mut self, motion: &Motion) -> Result<TokenFile> {
        let cleaned = cleaned_clip(motion)?;
        let skeleton = cleaned.motion.skeleton();
        let (basis, pose) = match Basis::of(self.tat.config().representation, skeleton, [&cleaned.motion]) {
            Basis::Reference(mean) => {
                let code = PoseCode::new(skeleton, &mean);
                // Read against the pose as the file writes it (to 4 decimals), as decoding will.
                let written = code.reference_on(skeleton).unwrap_or(mean);
                (Basis::Reference(written), Some(code))
            }
            Basis::Rest => (Basis::Rest, None),
        };
        let entered = basis.enter(&cleaned.motion);
        let graph = Graphs::new(&mut self.encoder).of(entered.skeleton())?;
        let tokens = tokenize(&mut self.tat, &graph, &entered)?;
        Ok(TokenFile { model: self.name.clone(), model_steps: self.steps, tokens, pose })
    }

    /// A tokens file as motion on `target`'s skeleton (in its units, with its hierarchy and
    /// channels) at `fps` frames per second, refused when the tokens do not fit this checkpoint
    /// or do not describe a clip. A tokenizer of the reference representation writes the motion
    /// around the file's pose code when the target is the skeleton it came from, else around a
    /// pose taken from the target (see [`pose_source`]). The motion is cleaned up (see
    /// [`TokenCodec::set_cleanup`]) and comes with its quality report.
    pub fn detokenize(&mut self, file: &TokenFile, target: &Motion, fps: f64) -> Result<Made> {
        let tokens = &file.tokens;
        self.check(tokens).map_err(ModelError::Refused)?;
        if let Some(code) = &file.pose {
            code.check().map_err(ModelError::Refused)?;
        }
        if !(fps > 0.0 && fps <= MAX_FPS) {
            return Err(ModelError::refused(format!("the frame rate must be in (0, {MAX_FPS}]; {fps} was asked")));
        }
        let representation = self.tat.config().representation;
        let rest = || Motion::rest_pose(target.skeleton(), 1.0 / MODEL_FPS);
        let posed = if representation == Representation::Reference { pose_source(target) } else { rest() };
        let source = if target.frames() > 0 { target.slice(0, 1) } else { rest() };
        let cleaned = clean(&posed, &CleanOptions::default())
            .map_err(|r| ModelError::refused(format!("the skeleton cannot be used as a target: {r}")))?;
        let coded = file.pose.as_ref().and_then(|code| code.reference_on(cleaned.motion.skeleton()));
        let basis = match coded {
            Some(reference) if representation == Representation::Reference => Basis::Reference(reference),
            _ => Basis::of(representation, cleaned.motion.skeleton(), [&cleaned.motion]),
        };
        let skeleton = basis.enter_skeleton(&cleaned.motion);
        let graph = Graphs::new(&mut self.encoder).of(&skeleton)?;
        let decoded = basis.leave(&detokenize(&self.tat, tokens, &graph, &skeleton)?);
        // Anchored tokens (a real clip's) carry the root's path: the cleanup keeps it.
        let cleanup = self.cleanup.map(|c| Cleanup { keep_root: c.keep_root || !tokens.anchors.is_empty(), ..c });
        let (decoded, planting) = clean_up(decoded, cleanup.as_ref(), &self.real);
        let quality = QualityReport::of(&decoded, planting, self.real.of(&decoded), None);
        let restored = cleaned.restore(&decoded, &source);
        // The models run at MODEL_FPS; the answer comes at the rate asked for.
        let motion = if (restored.fps() - fps).abs() > 1e-9 { restored.resample(fps) } else { restored };
        Ok(Made { motion, quality })
    }

    /// Why tokens (perhaps from a client) cannot be decoded by this checkpoint, if they cannot:
    /// the codes must fit its codebooks, every window must hold the same whole number of steps
    /// and cover the window, the windows must start inside the clip, in order, covering it, and
    /// the root anchors must lie inside it, in order.
    fn check(&self, tokens: &Tokens) -> Result<(), String> {
        let (layers, codes) = (self.tat.config().rvq.layers, self.tat.config().rvq.codes as u32);
        let per_token = self.tat.config().tat.frames_per_token();
        let steps = tokens.codes.first().map_or(0, Vec::len);
        let depth = tokens.codes.first().and_then(|w| w.first()).map_or(0, Vec::len);
        if steps == 0 || depth == 0 {
            return Err("the tokens hold no steps".into());
        }
        if depth > layers || tokens.codes.iter().flatten().flatten().any(|&c| c >= codes) {
            return Err(format!("the tokens do not fit checkpoint {} ({layers} layers of {codes} codes)", self.name));
        }
        if tokens.codes.iter().any(|w| w.len() != steps || w.iter().any(|step| step.len() != depth)) {
            return Err(format!("every window must hold {steps} steps of {depth} codes, as the first does"));
        }
        if tokens.window != steps * per_token {
            return Err(format!(
                "a window of {steps} steps covers {} frames, not {}",
                steps * per_token,
                tokens.window
            ));
        }
        let ordered = tokens.starts.first() == Some(&0) && tokens.starts.windows(2).all(|p| p[0] < p[1]);
        if tokens.starts.len() != tokens.codes.len() || !ordered {
            return Err("starts must be one ascending first frame per window, from 0".into());
        }
        let last = *tokens.starts.last().expect("one start per window");
        if tokens.frames == 0 || last >= tokens.frames || tokens.frames > last + tokens.window {
            return Err(format!("{} frames are not covered by windows starting at {:?}", tokens.frames, tokens.starts));
        }
        if !(tokens.fps > 0.0 && tokens.fps <= 1000.0 && tokens.start.iter().all(|v| v.is_finite())) {
            return Err("fps must be in (0, 1000] and the start finite".into());
        }
        anchor::check(&tokens.anchors, tokens.frames)
    }

    /// A clip moved onto `target`'s skeleton through tokens, at `fps` frames per second (see
    /// [`TokenCodec::detokenize`] for what the target's frames mean).
    pub fn transfer(&mut self, motion: &Motion, target: &Motion, fps: f64) -> Result<Made> {
        let file = self.tokenize(motion)?;
        self.detokenize(&file, target, fps)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use anymo_motion::bvh::parse_str;
    use anymo_motion::prep::augment::{scale_bones, turn_joint_frames};

    const SWAY: &str = "HIERARCHY\nROOT Hips\n{\n OFFSET 0 1 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n \
        JOINT LeftLeg\n {\n  OFFSET 0.2 -0.5 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 -0.5 0\n  }\n }\n \
        JOINT RightLeg\n {\n  OFFSET -0.2 -0.5 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 -0.5 0\n  }\n }\n}\n\
        MOTION\nFrames: 3\nFrame Time: 0.0333333\n0 1 0 0 10 0 30 0 0 -5 0 0\n0 1 0 0 12 0 35 0 0 -10 0 0\n0 1 0 0 14 0 40 0 0 -15 0 0\n";

    fn sway() -> Motion {
        Motion::from_bvh(&parse_str(SWAY).unwrap())
    }

    #[test]
    fn a_pose_code_gives_its_pose_back_on_its_own_rig_of_any_proportions() {
        let motion = sway();
        let mean = ReferencePose::mean_of([&motion]).unwrap();
        let code = PoseCode::new(motion.skeleton(), &mean);
        let back = code.reference_on(motion.skeleton()).expect("the skeleton it was taken on");
        for (a, b) in mean.globals().iter().zip(back.globals()) {
            let apart = (*a - *b).to_array().iter().fold(0f32, |m, x| m.max(x.abs()));
            assert!(apart < 2e-4, "{a} against {b}: written to 4 decimals");
        }
        let longer = scale_bones(&motion, &[1.0, 1.3, 0.8]);
        assert!(code.reference_on(longer.skeleton()).is_some(), "other proportions are the same rig");
        let json = serde_json::to_string(&code).unwrap();
        assert_eq!(serde_json::from_str::<PoseCode>(&json).unwrap(), code);
        assert_eq!(code.check(), Ok(()));
        let mut broken = code.clone();
        broken.joints[1].rotation = [0.0; 4];
        assert!(broken.check().unwrap_err().contains("\"LeftLeg\""), "a client's zero rotation is refused by name");
    }

    #[test]
    fn a_pose_code_does_not_apply_to_another_rig() {
        let motion = sway();
        let code = PoseCode::new(motion.skeleton(), &ReferencePose::mean_of([&motion]).unwrap());
        // The same names with the legs' frames turned (rest bones pointing elsewhere): another
        // convention, whose joint rotations the code's would misread.
        let turns = [Quat::IDENTITY, Quat::from_rotation_z(0.5), Quat::IDENTITY];
        let turned = turn_joint_frames(&motion, &turns);
        assert!(code.reference_on(turned.skeleton()).is_none());
        let renamed = SWAY.replace("LeftLeg", "LeftFin");
        let other = Motion::from_bvh(&parse_str(&renamed).unwrap());
        assert!(code.reference_on(other.skeleton()).is_none(), "other joint names");
    }
}
