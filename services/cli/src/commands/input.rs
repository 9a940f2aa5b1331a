//! Reading a motion file the user names: BVH (plain or gzipped) or glTF/GLB.

use anyhow::{Context, Result};
use anymo_motion::bvh::{self, Bvh, ReadOptions};
use anymo_motion::gltf::{AnimationInfo, GltfAsset};
use anymo_motion::motion::Motion;
use anymo_motion::skeleton::EulerOrder;
use std::path::Path;

/// The frame rate glTF animations are sampled at unless the user picks one.
pub const DEFAULT_GLTF_FPS: f64 = 30.0;

/// A file read for a command.
pub enum Input {
    /// A BVH file, with its values exactly as written.
    Bvh(Bvh),
    /// A glTF file: its animations and the one sampled (if it has any).
    Gltf {
        animations: Vec<AnimationInfo>,
        chosen: Option<(String, Motion)>,
        skeleton: Box<anymo_motion::skeleton::Skeleton>,
    },
}

/// True when the path names a glTF file.
pub fn is_gltf(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("glb") || e.eq_ignore_ascii_case("gltf"))
}

/// Reads `path`; for glTF, samples `animation` (default: the first) at `fps`.
pub fn read(path: &Path, animation: Option<&str>, fps: Option<f64>, order: EulerOrder) -> Result<Input> {
    if is_gltf(path) {
        let asset = GltfAsset::open(path, order).with_context(|| format!("reading {}", path.display()))?;
        let animations = asset.animations();
        let index = match animation {
            Some(name) => Some(asset.find_animation(name)?),
            None => animations.first().map(|a| a.index),
        };
        let chosen = match index {
            Some(i) => {
                let motion = asset.motion(i, fps.unwrap_or(DEFAULT_GLTF_FPS))?;
                Some((animations[i].name.clone(), motion))
            }
            None => None,
        };
        Ok(Input::Gltf { animations, chosen, skeleton: Box::new(asset.skeleton().clone()) })
    } else {
        let clip =
            bvh::read_path(path, ReadOptions::default()).with_context(|| format!("reading {}", path.display()))?;
        Ok(Input::Bvh(clip))
    }
}

/// The motion of a clip file (BVH, or a glTF file's `animation`, default its first), refused
/// when it has no frames.
pub fn read_motion(path: &Path, animation: Option<&str>) -> Result<Motion> {
    let motion = match read(path, animation, None, EulerOrder::Zxy)? {
        Input::Bvh(clip) => Motion::from_bvh(&clip),
        Input::Gltf { chosen: Some((_, motion)), .. } => motion,
        Input::Gltf { .. } => anyhow::bail!("{} has no animation to read", path.display()),
    };
    if motion.frames() == 0 {
        anyhow::bail!("{} has no frames of motion", path.display());
    }
    Ok(motion)
}
