//! The training loops: OwO pretraining and tokenizer (TAT or baseline) training, with a progress
//! bar, checkpoints every few minutes and exact resumption after a kill.

use anyhow::{Context, Result};
use anymo_motion::motion::Motion;
use anymo_tokenizer::dataset::{LoaderConfig, WindowLoader};
use anymo_tokenizer::nn::{AdamW, AdamWConfig, ModelCard, Params};
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

/// Where a run keeps its resumable state, apart from the checkpoint it ships.
pub struct RunDir {
    dir: PathBuf,
}

/// What a run has done so far.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct RunState {
    /// Optimiser steps taken.
    pub step: u64,
    /// Loader epoch in progress.
    pub epoch: u64,
    /// Batches of that epoch already used.
    pub batch: usize,
    /// Seconds spent training so far.
    pub seconds: f64,
    /// Subdirectory holding the parameters and optimiser of this state (run directories saved
    /// before it was recorded kept them at the top).
    #[serde(default)]
    pub saved_in: Option<String>,
}

impl RunDir {
    /// A run directory (created when missing).
    pub fn new(dir: &Path) -> Result<RunDir> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        Ok(RunDir { dir: dir.to_path_buf() })
    }

    /// The saved state, if the run was started before.
    pub fn state(&self) -> Result<Option<RunState>> {
        let path = self.dir.join("state.json");
        if !path.exists() {
            return Ok(None);
        }
        let text = std::fs::read_to_string(&path)?;
        Ok(Some(serde_json::from_str(&text).with_context(|| format!("reading {}", path.display()))?))
    }

    /// Restores parameters and optimiser from the save that `state` records; returns the saved
    /// buffers.
    pub fn restore(
        &self,
        state: &RunState,
        params: &mut Params,
        optimiser: &mut AdamW,
    ) -> Result<HashMap<String, Tensor>> {
        let dir = state.saved_in.as_ref().map_or_else(|| self.dir.clone(), |sub| self.dir.join(sub));
        let rest = params.load(&dir.join("params.safetensors")).context("loading the run's parameters")?;
        optimiser.load(&dir.join("optimiser.safetensors")).context("loading the run's optimiser state")?;
        Ok(rest)
    }

    /// Saves parameters, optimiser and state. Weights go to a directory of their own; the state
    /// that names it is renamed into place last, so a kill at any point leaves one consistent
    /// save (the new one or the previous one), never new weights under an old step.
    pub fn save(&self, params: &Params, optimiser: &AdamW, state: &RunState) -> Result<()> {
        let sub = format!("save-{}", state.step);
        let dir = self.dir.join(&sub);
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        params.save(&dir.join("params.safetensors"))?;
        optimiser.save(&dir.join("optimiser.safetensors"))?;
        let state = RunState { saved_in: Some(sub.clone()), ..state.clone() };
        let tmp = self.dir.join("state.json.tmp");
        std::fs::write(&tmp, serde_json::to_string_pretty(&state)?)?;
        std::fs::rename(&tmp, self.dir.join("state.json"))?;
        self.remove_saves_other_than(&sub)
    }

    /// Deletes earlier saves, and weights of the layout before `saved_in`, once a newer save is
    /// in place.
    fn remove_saves_other_than(&self, keep: &str) -> Result<()> {
        for entry in std::fs::read_dir(&self.dir)? {
            let entry = entry?;
            let name = entry.file_name().to_string_lossy().into_owned();
            if name.starts_with("save-") && name != keep {
                std::fs::remove_dir_all(entry.path())?;
            } else if name == "params.safetensors" || name == "optimiser.safetensors" {
                std::fs::remove_file(entry.path())?;
            }
        }
        Ok(())
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
    if let Some(saved) = run.state()? {
        run.restore(&saved, &mut pretrainer.params, &mut optimiser)?;
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
    /// Joints over all windows of a batch, at most.
    pub max_batch_joints: usize,
    /// Seconds between saves of the run state (cards from before it was recorded: 120).
    #[serde(default = "default_save_every_seconds")]
    pub save_every_seconds: u64,
    /// Probability of rebasing a window's rest pose (cards that do not record it were trained
    /// with 0.5).
    #[serde(default = "default_rebase")]
    pub rebase: f64,
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
        self.n += 1.0;
    }
}

/// Trains a codec on windows of `clips`; `graphs[g]` is the skeleton graph of loader group `g`.
pub fn train_codec(
    codec: &mut dyn Codec,
    clips: Vec<Motion>,
    graph_of: &mut dyn FnMut(&anymo_motion::skeleton::Skeleton) -> Result<SkeletonGraph>,
    settings: &CodecTraining,
    run: &RunDir,
) -> Result<RunState> {
    let mut optimiser = AdamW::new(codec.params(), AdamWConfig::default())?;
    // A continued run starts at its checkpoint's step, with epochs numbered from there so that it
    // draws new shuffles.
    let mut state = RunState { step: settings.start, epoch: settings.start, ..RunState::default() };
    if let Some(saved) = run.state()? {
        let rest = run.restore(&saved, codec.params_mut(), &mut optimiser)?;
        codec.restore_buffers(&rest)?;
        state = saved;
        eprintln!("resuming at step {} (epoch {}, batch {})", state.step, state.epoch, state.batch);
    }
    let config = LoaderConfig {
        batch_size: settings.batch_size,
        max_batch_joints: settings.max_batch_joints,
        seed: settings.seed,
        rebase: settings.rebase,
        ..LoaderConfig::default()
    };
    let mut loader = WindowLoader::new(clips, config);
    let graphs: Vec<SkeletonGraph> =
        (0..loader.groups()).map(|g| graph_of(loader.group_skeleton(g))).collect::<Result<_>>()?;
    let bar = progress(settings.steps, state.step);
    let mut log = LogLines::new();
    let mut last_save = Instant::now();
    let started = Instant::now() - Duration::from_secs_f64(state.seconds);
    let mut running = Running::default();
    let mut frames = 0usize;
    let window_start = Instant::now();
    'training: while state.step < settings.steps {
        loader.reseed(settings.seed.wrapping_add(state.epoch.wrapping_mul(0x9E37_79B9_7F4A_7C15)));
        let batches = loader.epoch()?;
        for (index, batch) in batches.iter().enumerate().skip(state.batch) {
            let prepared = Prepared::new(batch, codec.root_stats())?;
            let mut rng = ChaCha8Rng::seed_from_u64(settings.seed ^ state.step.wrapping_mul(0x2545_F491_4F6C_DD1D));
            let out = codec.reconstruct(&prepared, &graphs[batch.group], true, &mut rng)?;
            let (total, parts) =
                loss(&out.prediction, &prepared, codec.root_stats(), &out.commitment, codec.weights())?;
            let grads = total.backward()?;
            optimiser.step(
                codec.params(),
                &grads,
                schedule(settings.lr, settings.warmup, settings.steps - settings.start, state.step - settings.start),
            )?;
            running.add(&parts);
            frames += batch.sources.len() * batch.rotations.dim(1)?;
            state.step += 1;
            state.batch = index + 1;
            state.seconds = started.elapsed().as_secs_f64();
            bar.set_position(state.step);
            let fps = frames as f64 / window_start.elapsed().as_secs_f64();
            let r = &running.parts;
            let message = format!(
                "rot {:.4} pos {:.5} root {:.3} heading {:.4} path {:.4} vel {:.6} commit {:.4} | {fps:.0} frames/s",
                r.rotation, r.position, r.root, r.heading, r.path, r.velocity, r.commitment
            );
            log.maybe(state.step, settings.steps, &message);
            bar.set_message(message);
            if last_save.elapsed() >= Duration::from_secs(settings.save_every_seconds) || state.step == settings.steps {
                codec.sync_buffers()?;
                run.save(codec.params(), &optimiser, &state)?;
                last_save = Instant::now();
            }
            if state.step >= settings.steps {
                break 'training;
            }
        }
        state.epoch += 1;
        state.batch = 0;
    }
    codec.sync_buffers()?;
    run.save(codec.params(), &optimiser, &state)?;
    bar.finish();
    Ok(state)
}

/// Settings of a run of the generic step loop.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StepTraining {
    /// Optimiser steps.
    pub steps: u64,
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
    let mut state = RunState::default();
    if let Some(saved) = run.state()? {
        run.restore(&saved, params_mut(model), &mut optimiser)?;
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
        let lr = schedule(settings.lr, settings.warmup, settings.steps, state.step);
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
        run.save(&params, &optimiser, &RunState { step: 1, ..RunState::default() }).unwrap();
        set(&params, 2.0);
        run.save(&params, &optimiser, &RunState { step: 2, ..RunState::default() }).unwrap();
        assert!(!dir.join("save-1").exists(), "a newer save replaces the older one");

        // A kill after the weights of step 3 were written but before its state was.
        set(&params, 3.0);
        std::fs::create_dir_all(dir.join("save-3")).unwrap();
        params.save(&dir.join("save-3/params.safetensors")).unwrap();

        let state = run.state().unwrap().unwrap();
        assert_eq!(state.step, 2);
        let mut restored = Params::new(1);
        restored.constant("w", &[2], 0.0).unwrap();
        let mut optimiser = AdamW::new(&restored, AdamWConfig::default()).unwrap();
        run.restore(&state, &mut restored, &mut optimiser).unwrap();
        assert_eq!(values(&restored), [2.0, 2.0], "step 2's weights, not the half-saved step 3's");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
