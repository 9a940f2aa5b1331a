//! The training loops: OwO pretraining and tokenizer (TAT or baseline) training, with a progress
//! bar, checkpoints every few minutes and exact resumption after a kill.

use anyhow::{Context, Result};
use anymo_tokenizer::dataset::{LoaderConfig, TrainingClip, WindowLoader};
use anymo_tokenizer::nn::{AdamW, AdamWConfig, ModelCard, Params, snapshot};
use anymo_tokenizer::owo::SkeletonGraph;
use anymo_tokenizer::owo::pretrain::{Pretrainer, schedule};
use anymo_tokenizer::tat::Codec;
use anymo_tokenizer::tat::objective::{LossParts, Prepared, loss};
use anymo_tokenizer::text::CachedEncoder;
use candle_core::Tensor;
use indicatif::{ProgressBar, ProgressStyle};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Where a run keeps its resumable state, apart from the checkpoint it ships: one file,
/// `state.safetensors` (see [`anymo_tokenizer::nn::snapshot`]), replaced at every save, so it can
/// be committed and a run continued on another machine.
pub struct RunDir {
    path: PathBuf,
}

/// What a run has done so far.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct RunState {
    /// Optimiser steps taken.
    pub step: u64,
    /// Seconds spent training so far.
    pub seconds: f64,
}

impl RunDir {
    /// The run state file in `dir` (created when missing).
    pub fn new(dir: &Path) -> Result<RunDir> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        Ok(RunDir { path: dir.join("state.safetensors") })
    }

    /// The state file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Restores parameters and optimiser when the run was started before; returns its state and
    /// the saved buffers.
    pub fn resume(
        &self,
        params: &mut Params,
        optimiser: &mut AdamW,
    ) -> Result<Option<(RunState, HashMap<String, Tensor>)>> {
        if snapshot::progress(&self.path)?.is_none() {
            return Ok(None);
        }
        let (progress, buffers) = snapshot::load(&self.path, params, optimiser)
            .with_context(|| format!("resuming from {}", self.path.display()))?;
        let state = serde_json::from_str(&progress).with_context(|| format!("reading {}", self.path.display()))?;
        Ok(Some((state, buffers)))
    }

    /// Saves parameters, optimiser and state in one file, written beside and renamed over the
    /// previous one, so a kill at any point leaves one whole save.
    pub fn save(&self, params: &Params, optimiser: &AdamW, state: &RunState) -> Result<()> {
        snapshot::save(&self.path, params, optimiser, &serde_json::to_string(state)?)
            .with_context(|| format!("saving the run state to {}", self.path.display()))
    }
}

/// Logs a progress line now and then when stderr is not a terminal (a background run's log).
struct LogLines {
    last: Instant,
    enabled: bool,
}

impl LogLines {
    fn new() -> LogLines {
        use std::io::IsTerminal;
        LogLines { last: Instant::now(), enabled: !std::io::stderr().is_terminal() }
    }

    fn maybe(&mut self, step: u64, total: u64, message: &str) {
        if self.enabled && (self.last.elapsed() >= Duration::from_secs(30) || step == total) {
            eprintln!("step {step}/{total} {message}");
            self.last = Instant::now();
        }
    }
}

fn progress(total: u64, start: u64) -> ProgressBar {
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} steps  {per_sec}  eta {eta}  {msg}")
            .expect("a valid template")
            .progress_chars("=> "),
    );
    bar.set_position(start);
    bar
}

/// Pretrains OwO for `pretrainer`'s configured steps, resuming from `run` when it holds a state
/// and saving it every `save_every`.
pub fn pretrain_owo(
    pretrainer: &mut Pretrainer,
    steps: u64,
    encoder: &mut CachedEncoder,
    run: &RunDir,
    save_every: Duration,
) -> Result<RunState> {
    let mut optimiser = AdamW::new(&pretrainer.params, AdamWConfig::default())?;
    let mut state = RunState::default();
    if let Some((saved, _)) = run.resume(&mut pretrainer.params, &mut optimiser)? {
        state = saved;
        eprintln!("resuming OwO pretraining at step {}", state.step);
    }
    let bar = progress(steps, state.step);
    let mut log = LogLines::new();
    let mut last_save = Instant::now();
    let started = Instant::now() - Duration::from_secs_f64(state.seconds);
    while state.step < steps {
        let (total, parts, scores) = pretrainer.step_losses(state.step, encoder)?;
        let grads = total.backward()?;
        optimiser.step(&pretrainer.params, &grads, pretrainer.learning_rate(state.step))?;
        state.step += 1;
        state.seconds = started.elapsed().as_secs_f64();
        bar.set_position(state.step);
        let message = format!(
            "offset {:.4} lca {:.3} label {:.3} | lca acc {:.2} label acc {:.2}",
            parts[0], parts[1], parts[2], scores.lca_accuracy, scores.label_accuracy
        );
        log.maybe(state.step, steps, &message);
        bar.set_message(message);
        if last_save.elapsed() >= save_every || state.step == steps {
            run.save(&pretrainer.params, &optimiser, &state)?;
            last_save = Instant::now();
        }
    }
    bar.finish();
    Ok(state)
}

/// Settings of a tokenizer training run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CodecTraining {
    /// Optimiser steps in all.
    pub steps: u64,
    /// Steps of the checkpoint the run continues (0 for a fresh one): the run starts there, and
    /// its learning rate warms up and decays over the steps after it.
    #[serde(default)]
    pub start: u64,
    /// Peak learning rate.
    pub lr: f64,
    /// Warm-up steps.
    pub warmup: u64,
    /// Seed of sampling (initialisation has its own in the model).
    pub seed: u64,
    /// Windows per batch (fewer for large skeletons).
    pub batch_size: usize,
    /// Batches per step, each of one skeleton (cards from before it was recorded: 1).
    #[serde(default = "one")]
    pub skeletons_per_step: usize,
    /// Frames per training window, at most (cards from before it was recorded: 64).
    #[serde(default = "default_window")]
    pub window: usize,
    /// Joints over all windows of a batch, at most.
    pub max_batch_joints: usize,
    /// Seconds between saves of the run state (cards from before it was recorded: 120).
    #[serde(default = "default_save_every_seconds")]
    pub save_every_seconds: u64,
    /// Probability of rebasing a window's rest pose (cards that do not record it were trained
    /// with 0.5).
    #[serde(default = "default_rebase")]
    pub rebase: f64,
    /// Probability of rebasing a window on a frame of any clip of its skeleton (cards that do
    /// not record it were trained without).
    #[serde(default)]
    pub rebase_other: f64,
    /// Probability of reading a window against its own clip's mean pose (cards that do not
    /// record it were trained without).
    #[serde(default)]
    pub rebase_own: f64,
}

fn one() -> usize {
    1
}

fn default_window() -> usize {
    64
}

fn default_save_every_seconds() -> u64 {
    120
}

fn default_rebase() -> f64 {
    0.5
}

/// Running means of the loss terms, for the progress bar.
#[derive(Default)]
struct Running {
    parts: LossParts,
    n: f32,
}

impl Running {
    fn add(&mut self, p: &LossParts) {
        let k = 1.0 / (self.n + 1.0).min(50.0);
        let mix = |a: &mut f32, b: f32| *a += (b - *a) * k;
        mix(&mut self.parts.rotation, p.rotation);
        mix(&mut self.parts.position, p.position);
        mix(&mut self.parts.root, p.root);
        mix(&mut self.parts.velocity, p.velocity);
        mix(&mut self.parts.commitment, p.commitment);
        mix(&mut self.parts.heading, p.heading);
        mix(&mut self.parts.path, p.path);
        mix(&mut self.parts.contact, p.contact);
        mix(&mut self.parts.skating, p.skating);
        self.n += 1.0;
    }
}

/// Trains a codec on windows of `clips`, `skeletons_per_step` batches of one skeleton each per
/// step, the step's loss their mean.
pub fn train_codec(
    codec: &mut dyn Codec,
    clips: Vec<TrainingClip>,
    graph_of: &mut dyn FnMut(&anymo_motion::skeleton::Skeleton) -> Result<SkeletonGraph>,
    settings: &CodecTraining,
    run: &RunDir,
) -> Result<RunState> {
    let mut optimiser = AdamW::new(codec.params(), AdamWConfig::default())?;
    // A continued run starts at its checkpoint's step.
    let mut state = RunState { step: settings.start, ..RunState::default() };
    if let Some((saved, buffers)) = run.resume(codec.params_mut(), &mut optimiser)? {
        codec.restore_buffers(&buffers)?;
        state = saved;
        eprintln!("resuming at step {} from {}", state.step, run.path().display());
    }
    let config = LoaderConfig {
        window: settings.window,
        batch_size: settings.batch_size,
        skeletons_per_step: settings.skeletons_per_step,
        max_batch_joints: settings.max_batch_joints,
        seed: settings.seed,
        rebase: settings.rebase,
        rebase_other: settings.rebase_other,
        rebase_own: settings.rebase_own,
        ..LoaderConfig::default()
    };
    let loader = WindowLoader::new(clips, config);
    let graphs: Vec<SkeletonGraph> =
        (0..loader.groups()).map(|g| graph_of(loader.group_skeleton(g))).collect::<Result<_>>()?;
    let bar = progress(settings.steps, state.step);
    let mut log = LogLines::new();
    let mut last_save = Instant::now();
    let started = Instant::now() - Duration::from_secs_f64(state.seconds);
    let mut running = Running::default();
    let mut frames = 0usize;
    let window_start = Instant::now();
    while state.step < settings.steps {
        let batches = loader.step(state.step)?;
        let mut rng = ChaCha8Rng::seed_from_u64(settings.seed ^ state.step.wrapping_mul(0x2545_F491_4F6C_DD1D));
        let mut total: Option<Tensor> = None;
        for batch in &batches {
            let prepared = Prepared::new(batch, codec.root_stats())?;
            let out = codec.reconstruct(&prepared, &graphs[batch.group], true, &mut rng)?;
            let (loss, parts) = loss(&out.prediction, &prepared, codec.root_stats(), &out.commitment, codec.weights())?;
            running.add(&parts);
            frames += batch.sources.len() * batch.rotations.dim(1)?;
            let share = (loss / batches.len() as f64)?;
            total = Some(match total {
                Some(t) => (t + share)?,
                None => share,
            });
        }
        let grads = total.expect("a step has batches").backward()?;
        optimiser.step(
            codec.params(),
            &grads,
            schedule(settings.lr, settings.warmup, settings.steps - settings.start, state.step - settings.start),
        )?;
        state.step += 1;
        state.seconds = started.elapsed().as_secs_f64();
        bar.set_position(state.step);
        let fps = frames as f64 / window_start.elapsed().as_secs_f64();
        let r = &running.parts;
        let message = format!(
            "rot {:.4} pos {:.5} root {:.3} vel {:.6} contact {:.4} skate {:.6} heading {:.4} path {:.4} commit {:.4} | \
             {fps:.0} frames/s",
            r.rotation, r.position, r.root, r.velocity, r.contact, r.skating, r.heading, r.path, r.commitment
        );
        log.maybe(state.step, settings.steps, &message);
        bar.set_message(message);
        if last_save.elapsed() >= Duration::from_secs(settings.save_every_seconds) || state.step == settings.steps {
            codec.sync_buffers()?;
            run.save(codec.params(), &optimiser, &state)?;
            last_save = Instant::now();
        }
    }
    codec.sync_buffers()?;
    run.save(codec.params(), &optimiser, &state)?;
    bar.finish();
    Ok(state)
}

/// Settings of a run of the generic step loop.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StepTraining {
    /// Optimiser steps in all.
    pub steps: u64,
    /// Steps of the checkpoint the run continues (0 for a fresh one): the run starts there, and
    /// its learning rate warms up and decays over the steps after it.
    #[serde(default)]
    pub start: u64,
    /// Peak learning rate.
    pub lr: f64,
    /// Warm-up steps.
    pub warmup: u64,
    /// Seed of sampling.
    pub seed: u64,
    /// Batch size.
    pub batch_size: usize,
    /// Seconds between saves of the run state.
    pub save_every_seconds: u64,
}

/// Trains a model whose every step draws its own batch: `step(model, rng)` returns the loss
/// and a progress message. The step's generator is seeded from the run seed and the step
/// number, so a resumed run draws exactly the batches the killed one would have.
pub fn train_steps<M>(
    model: &mut M,
    params_mut: impl Fn(&mut M) -> &mut Params,
    settings: &StepTraining,
    run: &RunDir,
    mut step: impl FnMut(&M, &mut ChaCha8Rng) -> Result<(Tensor, String)>,
) -> Result<RunState> {
    let mut optimiser = AdamW::new(params_mut(model), AdamWConfig::default())?;
    // A continued run starts at its checkpoint's step.
    let mut state = RunState { step: settings.start, ..RunState::default() };
    if let Some((saved, _)) = run.resume(params_mut(model), &mut optimiser)? {
        state = saved;
        eprintln!("resuming at step {}", state.step);
    }
    let bar = progress(settings.steps, state.step);
    let mut log = LogLines::new();
    let mut last_save = Instant::now();
    let started = Instant::now() - Duration::from_secs_f64(state.seconds);
    while state.step < settings.steps {
        let mut rng = ChaCha8Rng::seed_from_u64(settings.seed ^ state.step.wrapping_mul(0x2545_F491_4F6C_DD1D));
        let (loss, message) = step(model, &mut rng)?;
        let grads = loss.backward()?;
        let lr = schedule(settings.lr, settings.warmup, settings.steps - settings.start, state.step - settings.start);
        optimiser.step(params_mut(model), &grads, lr)?;
        state.step += 1;
        state.seconds = started.elapsed().as_secs_f64();
        bar.set_position(state.step);
        log.maybe(state.step, settings.steps, &message);
        bar.set_message(message);
        if last_save.elapsed() >= Duration::from_secs(settings.save_every_seconds) || state.step == settings.steps {
            run.save(params_mut(model), &optimiser, &state)?;
            last_save = Instant::now();
        }
    }
    run.save(params_mut(model), &optimiser, &state)?;
    bar.finish();
    Ok(state)
}

/// Writes a shipped checkpoint: weights and model card side by side.
pub fn ship<C: Serialize>(params: &Params, card: &ModelCard<C>, dir: &Path, name: &str) -> Result<()> {
    std::fs::create_dir_all(dir)?;
    params.save(&dir.join(format!("{name}.safetensors")))?;
    card.save(&dir.join(format!("{name}.json")))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn values(params: &Params) -> Vec<f32> {
        params.vars().next().unwrap().1.as_tensor().to_vec1().unwrap()
    }

    #[test]
    fn a_save_cut_short_leaves_the_previous_one_whole() {
        let dir = std::env::temp_dir().join(format!("anymo-run-dir-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let run = RunDir::new(&dir).unwrap();
        let mut params = Params::new(0);
        params.constant("w", &[2], 1.0).unwrap();
        let optimiser = AdamW::new(&params, AdamWConfig::default()).unwrap();
        let set = |params: &Params, v: f32| {
            params.vars().next().unwrap().1.set(&Tensor::new(&[v, v], &candle_core::Device::Cpu).unwrap()).unwrap()
        };
        run.save(&params, &optimiser, &RunState { step: 1, seconds: 1.0 }).unwrap();
        set(&params, 2.0);
        run.save(&params, &optimiser, &RunState { step: 2, seconds: 2.0 }).unwrap();
        let files: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(files, ["state.safetensors"], "one file, replaced");

        // A kill while step 3 was being written leaves its temporary file half done.
        std::fs::write(dir.join("state.safetensors.tmp"), b"half a header").unwrap();

        let mut restored = Params::new(1);
        restored.constant("w", &[2], 0.0).unwrap();
        let mut optimiser = AdamW::new(&restored, AdamWConfig::default()).unwrap();
        let (state, _) = run.resume(&mut restored, &mut optimiser).unwrap().unwrap();
        assert_eq!(state.step, 2);
        assert_eq!(values(&restored), [2.0, 2.0], "step 2's weights, not the half-saved step 3's");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
