//! `anymo convert IN OUT`: BVH or GLB to BVH, optionally resampled, re-ordered or normalised.

use super::input::{self, Input};
use anyhow::{Context, Result, bail};
use anymo_motion::bvh;
use anymo_motion::features::canonicalise;
use anymo_motion::motion::Motion;
use anymo_motion::prep::clean::{CleanOptions, clean};
use anymo_motion::skeleton::EulerOrder;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Input: .bvh, .bvh.gz, .glb or .gltf.
    input: PathBuf,
    /// Output .bvh file.
    output: PathBuf,
    /// Resample to this frame rate (glTF animations are sampled at 30 fps by default).
    #[arg(long)]
    fps: Option<f64>,
    /// Rewrite every joint's rotation channels in this Euler order (XYZ, XZY, YXZ, YZX, ZXY, ZYX).
    #[arg(long)]
    euler_order: Option<EulerOrder>,
    /// Write the cleaned, normalised model input instead (helpers dropped, dummy roots collapsed,
    /// diameter 1, starting at the origin facing +Z).
    #[arg(long)]
    normalise: bool,
    /// The glTF animation to convert (default: the first).
    #[arg(long)]
    animation: Option<String>,
}

pub fn run(args: Args) -> Result<()> {
    if let Some(fps) = args.fps
        && !(fps.is_finite() && fps > 0.0)
    {
        bail!("--fps must be a positive number, got {fps}");
    }
    let order = args.euler_order.unwrap_or(EulerOrder::Zxy);
    let unchanged = args.fps.is_none() && args.euler_order.is_none() && !args.normalise;
    let clip = match input::read(&args.input, args.animation.as_deref(), args.fps, order)? {
        // A plain copy keeps the file's numbers exactly.
        Input::Bvh(clip) if unchanged => clip,
        Input::Bvh(clip) => transform(Motion::from_bvh(&clip), &args, true)?.to_bvh(),
        Input::Gltf { chosen: Some((_, motion)), .. } => transform(motion, &args, false)?.to_bvh(),
        Input::Gltf { chosen: None, .. } => bail!("{} has no animations to convert", args.input.display()),
    };
    bvh::write_path(&clip, &args.output).with_context(|| format!("writing {}", args.output.display()))?;
    eprintln!(
        "wrote {}: {} joints, {} frames at {:.3} fps",
        args.output.display(),
        clip.skeleton().len(),
        clip.frames(),
        clip.fps()
    );
    Ok(())
}

/// Applies the requested changes; `resample` is false where the reader already sampled at --fps.
fn transform(mut motion: Motion, args: &Args, resample: bool) -> Result<Motion> {
    if let (Some(fps), true) = (args.fps, resample) {
        motion = motion.resample(fps);
    }
    if args.normalise {
        let cleaned = clean(&motion, &CleanOptions::default()).map_err(|r| anyhow::anyhow!("cannot normalise: {r}"))?;
        motion = canonicalise(&cleaned.motion);
    }
    if let Some(order) = args.euler_order {
        motion = motion.with_euler_order(order);
    }
    Ok(motion)
}
