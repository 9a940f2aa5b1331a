//! `anymo generate` and `anymo edit`: a prompt to motion on any skeleton, and token-level edits
//! of a clip (inpainting a span, continuing it, chaining prompts), with the shipped checkpoints.
//! Decoded motion is cleaned up (`--no-cleanup` to skip), and each sample written is reported on
//! standard output with its quality report.

use super::context::{CheckpointArgs, FinishArgs, StoreArgs, print_reports};
use super::tokens::{read_target, write_bvh};
use anyhow::{Context, Result, bail};
use anymo_generator::Request;
use anymo_generator::sampling::Sampling;
use anymo_models::data::MODEL_FPS;
use anymo_models::quality::Made;
use anymo_models::studio::Studio;
use anymo_tokenizer::text::CachedEncoder;
use clap::{Parser, Subcommand};
use std::path::{Path, PathBuf};

/// Options shared by generation and editing.
#[derive(Parser)]
pub struct GenerationArgs {
    #[command(flatten)]
    checkpoints: CheckpointArgs,
    /// The generator checkpoint (`generator`: masked; `generator-ar`: autoregressive).
    #[arg(long, default_value = "generator")]
    model: String,
    /// Samples to draw (written as OUT, OUT-2, OUT-3, ...).
    #[arg(long, default_value_t = 1)]
    samples: usize,
    /// Seed: the same request and seed give the same motion.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[command(flatten)]
    sampling: SamplingArgs,
    #[command(flatten)]
    finish: FinishArgs,
    #[command(flatten)]
    store: StoreArgs,
}

/// How tokens are drawn (shared with `anymo eval generator`).
#[derive(clap::Args, Clone)]
pub struct SamplingArgs {
    /// Classifier-free guidance scale (1: none).
    #[arg(long, default_value_t = Sampling::default().guidance)]
    guidance: f32,
    /// Sampling temperature (0: always the most likely token).
    #[arg(long, default_value_t = Sampling::default().temperature)]
    temperature: f32,
    /// Draw only among the k most likely tokens (0: all).
    #[arg(long, default_value_t = 0)]
    top_k: usize,
}

impl SamplingArgs {
    /// The sampling these options ask for.
    pub fn sampling(&self) -> Sampling {
        Sampling { temperature: self.temperature, top_k: self.top_k, guidance: self.guidance }
    }
}

#[derive(Parser)]
pub struct GenerateArgs {
    /// What the motion shows, in English.
    prompt: String,
    /// The skeleton to animate: a BVH file (the motion is written around the mean pose of its
    /// frames when it has some, else around its rest pose stood up)
    #[arg(long)]
    skeleton: PathBuf,
    /// Duration in seconds (default: the length the model predicts for the prompt).
    #[arg(long, conflicts_with = "frames")]
    seconds: Option<f64>,
    /// Duration in frames at 30 fps.
    #[arg(long)]
    frames: Option<usize>,
    /// The BVH to write.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    generation: GenerationArgs,
}

#[derive(Parser)]
pub struct EditArgs {
    #[command(subcommand)]
    edit: Edit,
}

#[derive(Subcommand)]
enum Edit {
    /// Regenerate the span FROM..TO seconds of a clip from a prompt, keeping the rest.
    Inpaint {
        /// The clip: a BVH file.
        input: PathBuf,
        /// What the new span shows.
        #[arg(long)]
        prompt: String,
        /// Start of the span, seconds.
        #[arg(long)]
        from: f64,
        /// End of the span, seconds.
        #[arg(long)]
        to: f64,
        /// The BVH to write.
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        generation: GenerationArgs,
    },
    /// Extend a clip by SECONDS of motion from a prompt.
    Continue {
        /// The clip: a BVH file.
        input: PathBuf,
        /// What the continuation shows.
        #[arg(long)]
        prompt: String,
        /// Seconds to add.
        #[arg(long)]
        seconds: f64,
        /// The BVH to write.
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        generation: GenerationArgs,
    },
    /// Prompts one after another on one skeleton, each flowing into the next:
    /// `--prompt "a person walks" --seconds 3 --prompt "a person sits down" --seconds 2`.
    Chain {
        /// The skeleton to animate: a BVH file (posed as for `anymo generate --skeleton`).
        #[arg(long)]
        skeleton: PathBuf,
        /// The prompts, in order.
        #[arg(long = "prompt", required = true)]
        prompts: Vec<String>,
        /// Seconds of each prompt, in the same order.
        #[arg(long = "seconds", required = true)]
        seconds: Vec<f64>,
        /// The BVH to write.
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        generation: GenerationArgs,
    },
}

fn load(args: &GenerationArgs) -> Result<(Studio, Request)> {
    if args.samples == 0 {
        bail!("--samples must be at least 1");
    }
    let set = args.checkpoints.set();
    let encoder = CachedEncoder::new(args.store.encoder()?);
    let mut studio = Studio::load(&set.get(&args.model), args.finish.evaluator(&set).as_ref(), encoder)?;
    studio.set_cleanup(args.finish.cleanup());
    studio.set_scoring(!args.finish.no_score);
    Ok((studio, Request { steps: None, samples: args.samples, sampling: args.sampling.sampling(), seed: args.seed }))
}

/// Writes each sample (see [`sample_path`]) and prints its quality report.
fn write_all(made: Vec<Made>, output: &Path) -> Result<()> {
    let paths: Vec<PathBuf> = (0..made.len()).map(|k| sample_path(output, k)).collect();
    for (m, path) in made.iter().zip(&paths) {
        write_bvh(&m.motion, path)?;
    }
    print_reports(paths.iter().map(PathBuf::as_path).zip(made.iter().map(|m| &m.quality)))
}

/// Where sample `k` goes: OUT for the first, OUT-2, OUT-3, ... for the others.
fn sample_path(output: &Path, k: usize) -> PathBuf {
    if k == 0 {
        return output.to_path_buf();
    }
    let stem = output.file_stem().map_or_else(|| "sample".into(), |s| s.to_string_lossy().into_owned());
    let ext = output.extension().map_or_else(|| "bvh".into(), |s| s.to_string_lossy().into_owned());
    output.with_file_name(format!("{stem}-{}.{ext}", k + 1))
}

pub fn run_generate(args: GenerateArgs) -> Result<()> {
    let (mut studio, request) = load(&args.generation)?;
    let target = studio.target(&read_target(&args.skeleton)?.0)?;
    let seconds = args.seconds.or(args.frames.map(|f| f as f64 / MODEL_FPS));
    write_all(studio.generate_motion(&args.prompt, &target, seconds, &request)?, &args.output)
}

pub fn run_edit(args: EditArgs) -> Result<()> {
    match args.edit {
        Edit::Inpaint { input, prompt, from, to, output, generation } => {
            let (mut studio, request) = load(&generation)?;
            let clip = super::input::read_motion(&input, None)?;
            let motions =
                studio.inpaint(&clip, &prompt, (from, to), &request).with_context(|| input.display().to_string())?;
            write_all(motions, &output)
        }
        Edit::Continue { input, prompt, seconds, output, generation } => {
            let (mut studio, request) = load(&generation)?;
            let clip = super::input::read_motion(&input, None)?;
            write_all(studio.extend(&clip, &prompt, seconds, &request)?, &output)
        }
        Edit::Chain { skeleton, prompts, seconds, output, generation } => {
            if prompts.len() != seconds.len() {
                bail!("give one --seconds per --prompt ({} prompts, {} durations)", prompts.len(), seconds.len());
            }
            let (mut studio, request) = load(&generation)?;
            let parts: Vec<(String, f64)> = prompts.into_iter().zip(seconds).collect();
            write_all(studio.chain(&read_target(&skeleton)?.0, &parts, &request)?, &output)
        }
    }
}
