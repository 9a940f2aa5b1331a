//! `anymo fk FILE --frame N`: global joint positions as JSON, in the file's units and axes.

use anyhow::{Context, Result, bail};
use anymo_tokenizer::bvh::{self, ReadOptions};
use anymo_tokenizer::kinematics::joint_positions;
use anymo_tokenizer::motion::Motion;
use serde::Serialize;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// A .bvh or .bvh.gz file.
    file: PathBuf,
    /// The 0-based frame.
    #[arg(long, default_value_t = 0)]
    frame: usize,
}

#[derive(Serialize)]
struct JointPosition<'a> {
    name: &'a str,
    position: [f32; 3],
}

pub fn run(args: Args) -> Result<()> {
    let clip = bvh::read_path(&args.file, ReadOptions { require_motion: true })
        .with_context(|| format!("reading {}", args.file.display()))?;
    if args.frame >= clip.frames() {
        bail!("frame {} is out of range: {} has frames 0..{}", args.frame, args.file.display(), clip.frames());
    }
    let motion = Motion::from_bvh(&clip);
    let positions = joint_positions(&motion, args.frame);
    let out: Vec<JointPosition> = motion
        .skeleton()
        .joints()
        .iter()
        .zip(&positions)
        .map(|(j, p)| JointPosition { name: &j.name, position: p.to_array() })
        .collect();
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}
