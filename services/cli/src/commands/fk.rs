//! `anymo fk FILE --frame N`: global joint positions and orientations as JSON, in the file's
//! units and axes; the heading column shows which way each joint turns about the vertical, to
//! compare a decoded clip with its source.

use anyhow::{Context, Result, bail};
use anymo_motion::bvh::{self, ReadOptions};
use anymo_motion::features::{heading_of, wrap_angle};
use anymo_motion::kinematics::global_transforms;
use anymo_motion::motion::Motion;
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
struct JointPose<'a> {
    name: &'a str,
    position: [f32; 3],
    /// Global orientation as a unit quaternion, `[x, y, z, w]`.
    rotation: [f32; 4],
    /// The orientation's twist about +Y, degrees in [-180, 180).
    heading_degrees: f32,
}

pub fn run(args: Args) -> Result<()> {
    let clip = bvh::read_path(&args.file, ReadOptions { require_motion: true })
        .with_context(|| format!("reading {}", args.file.display()))?;
    if args.frame >= clip.frames() {
        bail!("frame {} is out of range: {} has frames 0..{}", args.frame, args.file.display(), clip.frames());
    }
    let motion = Motion::from_bvh(&clip);
    let mut transforms = Vec::new();
    let f = args.frame;
    global_transforms(motion.skeleton(), motion.rotations(f), motion.translations(f), &mut transforms);
    let out: Vec<JointPose> = motion
        .skeleton()
        .joints()
        .iter()
        .zip(&transforms)
        .map(|(j, t)| JointPose {
            name: &j.name,
            position: t.translation.to_array(),
            rotation: t.rotation.to_array(),
            heading_degrees: wrap_angle(heading_of(t.rotation)).to_degrees(),
        })
        .collect();
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}
