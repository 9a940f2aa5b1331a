//! `anymo inspect FILE`: what a motion file holds and what might be wrong with it.

use super::input::{self, Input};
use anyhow::Result;
use anymo_motion::motion::Motion;
use anymo_motion::prep::clean::{CleanOptions, clean};
use anymo_motion::prep::labels::label_skeleton;
use anymo_motion::skeleton::{EulerOrder, Skeleton};
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// A .bvh, .bvh.gz, .glb or .gltf file.
    file: PathBuf,
    /// For glTF: the animation to check (default: the first).
    #[arg(long)]
    animation: Option<String>,
}

pub fn run(args: Args) -> Result<()> {
    let input = input::read(&args.file, args.animation.as_deref(), None, EulerOrder::Zxy)?;
    let mut out = String::new();
    writeln!(out, "file: {}", args.file.display())?;
    let motion = match &input {
        Input::Bvh(clip) => {
            writeln!(out, "format: BVH")?;
            Some(Motion::from_bvh(clip))
        }
        Input::Gltf { animations, chosen, .. } => {
            writeln!(out, "format: glTF with {} animations", animations.len())?;
            for a in animations {
                writeln!(out, "  animation {:>3} {:<32} {:.2} s", a.index, a.name, a.duration)?;
            }
            if let Some((name, _)) = chosen {
                writeln!(out, "sampled animation: {name} at {} fps", input::DEFAULT_GLTF_FPS)?;
            }
            chosen.as_ref().map(|(_, m)| m.clone())
        }
    };
    let skeleton = match (&input, &motion) {
        (_, Some(m)) => m.skeleton().clone(),
        (Input::Gltf { skeleton, .. }, None) => (**skeleton).clone(),
        (Input::Bvh(clip), None) => clip.skeleton().clone(),
    };
    writeln!(out, "joints: {}  channels per frame: {}", skeleton.len(), skeleton.channel_count())?;
    if let Some(m) = &motion {
        let seconds = m.frames().saturating_sub(1) as f64 * m.frame_time();
        writeln!(out, "frames: {}  fps: {:.3}  duration: {seconds:.2} s", m.frames(), m.fps())?;
    }
    writeln!(out, "diameter (longest root-to-leaf chain): {:.4}", skeleton.diameter())?;
    writeln!(out, "tree (name  [channels]  bone length  label):")?;
    write_tree(&skeleton, &mut out)?;
    let warnings = warnings(&skeleton, motion.as_ref());
    writeln!(out, "warnings: {}", if warnings.is_empty() { "none" } else { "" })?;
    for w in warnings {
        writeln!(out, "  - {w}")?;
    }
    print!("{out}");
    Ok(())
}

fn write_tree(skeleton: &Skeleton, out: &mut String) -> std::fmt::Result {
    let labels = label_skeleton(skeleton);
    let depths = skeleton.depths();
    for (j, joint) in skeleton.joints().iter().enumerate() {
        let channels: Vec<String> = joint.channels.as_slice().iter().map(|c| c.to_string()).collect();
        let helper = if labels[j].helper { " (helper)" } else { "" };
        let bone = if j == 0 { "root".to_string() } else { format!("{:.4}", joint.offset.length()) };
        writeln!(
            out,
            "  {}{}  [{}]  {bone}  {}{helper}",
            "  ".repeat(depths[j]),
            joint.name,
            channels.join(" "),
            labels[j]
        )?;
    }
    Ok(())
}

fn warnings(skeleton: &Skeleton, motion: Option<&Motion>) -> Vec<String> {
    let mut out = Vec::new();
    for (j, joint) in skeleton.joints().iter().enumerate().skip(1) {
        if joint.offset.length() <= f32::EPSILON * skeleton.diameter().max(1.0) {
            out.push(format!("joint {:?} has a zero-length bone", joint.name));
        }
        if joint.channels.has_position() {
            let varies = motion.is_some_and(|m| {
                (0..m.frames()).any(|f| m.translations(f)[j].distance(joint.offset) > 1e-4 * skeleton.diameter())
            });
            let how = if varies { "that move it off its offset" } else { "equal to its offset" };
            out.push(format!("non-root joint {:?} has position channels {how}", joint.name));
        }
    }
    match motion {
        None => out.push("no motion: a skeleton only".to_string()),
        Some(m) if m.frames() == 0 => out.push("Frames: 0: a skeleton only".to_string()),
        Some(m) => {
            match clean(m, &CleanOptions::default()) {
                Ok(c) => {
                    let dropped = skeleton.len() - c.motion.skeleton().len();
                    if dropped > 0 {
                        let root = &c.motion.skeleton().joint(0).name;
                        out.push(format!("cleaning for models drops {dropped} joints (helpers, static dummy roots); model root: {root:?}"));
                    }
                }
                Err(reason) => out.push(format!("rejected for model input: {reason}")),
            }
        }
    }
    out
}
