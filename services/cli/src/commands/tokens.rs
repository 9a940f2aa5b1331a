//! `anymo tokenize`, `anymo detokenize` and `anymo transfer`: motion to TAT tokens and back, on
//! the source skeleton or any other, with the shipped checkpoints, at the target file's frame
//! rate unless `--fps` says otherwise. Decoded motion is cleaned up (`--no-cleanup` to skip)
//! and each file written is reported on standard output with its quality report.

use super::context::{CheckpointArgs, FinishArgs, StoreArgs, print_reports};
use super::input;
use anyhow::{Context, Result};
use anymo_models::checkpoint::DEFAULT_TOKENIZER;
use anymo_models::quality::RealMotion;
use anymo_models::tokens::{TokenCodec, TokenFile};
use anymo_motion::bvh;
use anymo_motion::motion::Motion;
use anymo_tokenizer::text::CachedEncoder;
use clap::Parser;
use std::path::{Path, PathBuf};

/// Options shared by the token commands.
#[derive(Parser)]
pub struct ModelArgs {
    #[command(flatten)]
    checkpoints: CheckpointArgs,
    /// The tokenizer checkpoint.
    #[arg(long, default_value = DEFAULT_TOKENIZER)]
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
    /// The skeleton to animate: a BVH file (the motion is written around the mean pose of its
    /// frames when it has some, else around its rest pose stood up)
    #[arg(long)]
    skeleton: PathBuf,
    /// The BVH to write.
    #[arg(short, long)]
    output: PathBuf,
    /// Frames per second of the output [default: the skeleton file's]
    #[arg(long)]
    fps: Option<f64>,
    #[command(flatten)]
    finish: FinishArgs,
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
    /// Frames per second of the output [default: the target file's]
    #[arg(long)]
    fps: Option<f64>,
    #[command(flatten)]
    finish: FinishArgs,
    #[command(flatten)]
    model: ModelArgs,
}

fn load(args: &ModelArgs) -> Result<TokenCodec> {
    TokenCodec::load(&args.checkpoints.set().get(&args.model), CachedEncoder::new(args.store.encoder()?))
}

/// A codec that finishes decoded motion as `finish` asks.
fn load_finishing(args: &ModelArgs, finish: &FinishArgs) -> Result<TokenCodec> {
    let mut codec = load(args)?;
    codec.set_cleanup(finish.cleanup());
    if let Some(evaluator) = finish.evaluator(&args.checkpoints.set()) {
        codec.set_real_motion(RealMotion::of_evaluator(&evaluator)?);
    }
    Ok(codec)
}

/// The target of a generation, detokenize or transfer: a BVH file's skeleton, with its frames
/// when it has any (a tokenizer of the reference representation poses the result around them),
/// and its frame rate.
pub(super) fn read_target(path: &Path) -> Result<(Motion, f64)> {
    let clip =
        bvh::read_path(path, bvh::ReadOptions::default()).with_context(|| format!("reading {}", path.display()))?;
    Ok((Motion::from_bvh(&clip), 1.0 / clip.frame_time()))
}

pub(super) fn write_bvh(motion: &Motion, path: &Path) -> Result<()> {
    let mut out = Vec::new();
    bvh::write(&motion.to_bvh(), &mut out)?;
    std::fs::write(path, out).with_context(|| format!("writing {}", path.display()))
}

pub fn run_tokenize(args: TokenizeArgs) -> Result<()> {
    let mut codec = load(&args.model)?;
    let motion = input::read_motion(&args.input, args.animation.as_deref())?;
    let file = codec.tokenize(&motion).with_context(|| format!("tokenizing {}", args.input.display()))?;
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
    let mut codec = load_finishing(&args.model, &args.finish)?;
    let (target, file_fps) = read_target(&args.skeleton)?;
    let made = codec.detokenize(&file, &target, args.fps.unwrap_or(file_fps))?;
    write_bvh(&made.motion, &args.output)?;
    print_reports([(args.output.as_path(), &made.quality)])
}

pub fn run_transfer(args: TransferArgs) -> Result<()> {
    let mut codec = load_finishing(&args.model, &args.finish)?;
    let motion = input::read_motion(&args.input, args.animation.as_deref())?;
    let (target, file_fps) = read_target(&args.to)?;
    let moved = codec.transfer(&motion, &target, args.fps.unwrap_or(file_fps))?;
    write_bvh(&moved.motion, &args.output)?;
    print_reports([(args.output.as_path(), &moved.quality)])
}
