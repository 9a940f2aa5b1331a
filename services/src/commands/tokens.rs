//! `anymo tokenize`, `anymo detokenize` and `anymo transfer`: motion to TAT tokens and back, on
//! the source skeleton or any other, with the shipped checkpoints.

use super::context::StoreArgs;
use super::input;
use anyhow::{Context, Result, anyhow, bail};
use anymo_services::models::codecs::Graphs;
use anymo_services::models::data::MODEL_FPS;
use anymo_services::models::shipped;
use anymo_tokenizer::bvh;
use anymo_tokenizer::motion::Motion;
use anymo_tokenizer::prep::clean::{CleanClip, CleanOptions, clean};
use anymo_tokenizer::tat::Tat;
use anymo_tokenizer::tat::window::{Tokens, detokenize, tokenize};
use anymo_tokenizer::text::CachedEncoder;
use clap::Parser;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Options shared by the token commands.
#[derive(Parser)]
pub struct ModelArgs {
    /// The checkpoints' folder.
    #[arg(long, default_value_os_t = shipped::default_dir())]
    checkpoints: PathBuf,
    /// The tokenizer checkpoint.
    #[arg(long, default_value = "tat")]
    model: String,
    #[command(flatten)]
    store: StoreArgs,
}

#[derive(Parser)]
pub struct TokenizeArgs {
    /// A BVH (or GLB) clip.
    input: PathBuf,
    /// The glTF animation to read (default: the first).
    #[arg(long)]
    animation: Option<String>,
    /// Write the tokens here instead of standard output.
    #[arg(short, long)]
    output: Option<PathBuf>,
    #[command(flatten)]
    model: ModelArgs,
}

#[derive(Parser)]
pub struct DetokenizeArgs {
    /// Tokens written by `anymo tokenize`.
    tokens: PathBuf,
    /// The skeleton to animate: a BVH file (its motion, if any, is ignored).
    #[arg(long)]
    skeleton: PathBuf,
    /// The BVH to write.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    model: ModelArgs,
}

#[derive(Parser)]
pub struct TransferArgs {
    /// The clip to move: a BVH (or GLB) file.
    input: PathBuf,
    /// The glTF animation to read (default: the first).
    #[arg(long)]
    animation: Option<String>,
    /// The skeleton to move it onto: a BVH file.
    #[arg(long)]
    to: PathBuf,
    /// The BVH to write.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    model: ModelArgs,
}

/// The tokens file: the tokens and the checkpoint that made them.
#[derive(Serialize, Deserialize)]
struct TokenFile {
    model: String,
    model_steps: u64,
    tokens: Tokens,
}

struct Loaded {
    tat: Tat,
    steps: u64,
    encoder: CachedEncoder,
}

fn load(args: &ModelArgs) -> Result<Loaded> {
    let mut encoder = CachedEncoder::new(args.store.encoder()?);
    let (tat, card) = shipped::load_tat(&args.checkpoints, &args.model, &mut encoder)?;
    Ok(Loaded { tat, steps: card.steps, encoder })
}

/// A user's clip: the motion as read and its cleaned form at the models' frame rate.
fn read_clip(path: &Path, animation: Option<&str>) -> Result<(Motion, CleanClip)> {
    let motion = input::read_motion(path, animation)?;
    let cleaned =
        clean(&motion, &CleanOptions::default()).map_err(|r| anyhow!("{} cannot be used: {r}", path.display()))?;
    let resampled = CleanClip { motion: cleaned.motion.resample(MODEL_FPS), ..cleaned };
    Ok((motion, resampled))
}

/// A target skeleton: its BVH (motion optional) as a one-frame rest pose, cleaned.
fn read_target(path: &Path) -> Result<(Motion, CleanClip)> {
    let clip =
        bvh::read_path(path, bvh::ReadOptions::default()).with_context(|| format!("reading {}", path.display()))?;
    let rest = Motion::rest_pose(clip.skeleton(), 1.0 / MODEL_FPS);
    let cleaned = clean(&rest, &CleanOptions::default())
        .map_err(|r| anyhow!("{} cannot be used as a target: {r}", path.display()))?;
    Ok((rest, cleaned))
}

pub(super) fn write_bvh(motion: &Motion, path: &Path) -> Result<()> {
    let mut out = Vec::new();
    bvh::write(&motion.to_bvh(), &mut out)?;
    std::fs::write(path, out).with_context(|| format!("writing {}", path.display()))
}

fn decode_onto(loaded: &mut Loaded, tokens: &Tokens, target: &Path) -> Result<Motion> {
    let (rest, cleaned) = read_target(target)?;
    let graph = Graphs::new(&mut loaded.encoder).of(cleaned.motion.skeleton())?;
    let decoded = detokenize(&loaded.tat, tokens, &graph, cleaned.motion.skeleton())?;
    Ok(cleaned.restore(&decoded, &rest))
}

pub fn run_tokenize(args: TokenizeArgs) -> Result<()> {
    let mut loaded = load(&args.model)?;
    let (_, cleaned) = read_clip(&args.input, args.animation.as_deref())?;
    let graph = Graphs::new(&mut loaded.encoder).of(cleaned.motion.skeleton())?;
    let tokens = tokenize(&mut loaded.tat, &graph, &cleaned.motion)?;
    let file = TokenFile { model: args.model.model.clone(), model_steps: loaded.steps, tokens };
    let text = serde_json::to_string(&file)? + "\n";
    match &args.output {
        Some(path) => std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?,
        None => print!("{text}"),
    }
    Ok(())
}

pub fn run_detokenize(args: DetokenizeArgs) -> Result<()> {
    let text = std::fs::read_to_string(&args.tokens).with_context(|| format!("reading {}", args.tokens.display()))?;
    let file: TokenFile = serde_json::from_str(&text)
        .with_context(|| format!("{} is not a tokens file from `anymo tokenize`", args.tokens.display()))?;
    let mut loaded = load(&args.model)?;
    let layers = loaded.tat.config().rvq.layers;
    let codes = loaded.tat.config().rvq.codes as u32;
    if file.tokens.codes.iter().flatten().any(|step| step.len() > layers || step.iter().any(|&c| c >= codes)) {
        bail!("the tokens do not fit checkpoint {} ({layers} layers of {codes} codes)", args.model.model);
    }
    let motion = decode_onto(&mut loaded, &file.tokens, &args.skeleton)?;
    write_bvh(&motion, &args.output)
}

pub fn run_transfer(args: TransferArgs) -> Result<()> {
    let mut loaded = load(&args.model)?;
    let (_, cleaned) = read_clip(&args.input, args.animation.as_deref())?;
    let graph = Graphs::new(&mut loaded.encoder).of(cleaned.motion.skeleton())?;
    let tokens = tokenize(&mut loaded.tat, &graph, &cleaned.motion)?;
    let motion = decode_onto(&mut loaded, &tokens, &args.to)?;
    write_bvh(&motion, &args.output)
}
