//! Cleaning, canonicalisation, features and augmentation on the real corpus: every step either
//! keeps the motion exactly or changes it in the one way it means to.

use anymo_motion::bvh::{self, ReadOptions};
use anymo_motion::features::{canonicalise, from_features, to_features};
use anymo_motion::kinematics::all_joint_positions;
use anymo_motion::motion::Motion;
use anymo_motion::prep::augment::{mirror, scale_bones, turn_joint_frames};
use anymo_motion::prep::clean::{CleanOptions, Rejection, clean};
use anymo_motion::prep::labels::{label_skeleton, mirror_pairs};
use anymo_motion::reference::ReferencePose;
use anymo_tests::{data_dir, files_with_suffix};
use glam::{Quat, Vec3};
use std::collections::BTreeMap;
use std::path::PathBuf;

fn corpus_sample(step: usize) -> Option<Vec<PathBuf>> {
    let dir = data_dir()?;
    Some(files_with_suffix(&dir, ".bvh.gz").into_iter().step_by(step).collect())
}

fn load(path: &PathBuf) -> Motion {
    Motion::from_bvh(&bvh::read_path(path, ReadOptions { require_motion: true }).unwrap())
}

fn worst_distance(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter().zip(b).map(|(p, q)| p.distance(*q)).fold(0.0, f32::max)
}

#[test]
fn cleaning_restores_exactly_onto_the_original_skeleton() {
    let Some(files) = corpus_sample(1) else { return };
    let mut rejected: BTreeMap<String, usize> = BTreeMap::new();
    for path in &files {
        let motion = load(path);
        let cleaned = match clean(&motion, &CleanOptions::default()) {
            Ok(c) => c,
            Err(reason) => {
                let source = path.strip_prefix(data_dir().unwrap()).unwrap().iter().next().unwrap().to_string_lossy();
                let kind = match reason {
                    Rejection::TranslationDrift { joint, .. } => format!("{source}: {joint} drifts"),
                    Rejection::LongBone { joint, .. } => format!("{source}: {joint} too long"),
                    other => format!("{source}: {other}"),
                };
                *rejected.entry(kind).or_default() += 1;
                continue;
            }
        };
        let skeleton = cleaned.motion.skeleton();
        assert!((skeleton.diameter() - 1.0).abs() < 1e-4, "{}", path.display());
        // Only the root translates.
        for f in 0..cleaned.motion.frames() {
            for (j, t) in cleaned.motion.translations(f).iter().enumerate().skip(1) {
                assert_eq!(*t, skeleton.joint(j).offset);
            }
        }
        let restored = cleaned.restore(&cleaned.motion, &motion);
        assert_eq!(restored.skeleton(), motion.skeleton(), "the user's skeleton is untouched");
        let (a, b) = (all_joint_positions(&motion), all_joint_positions(&restored));
        let n = motion.skeleton().len();
        let diameter = motion.skeleton().diameter();
        for &j in &cleaned.source_joint {
            let worst = (0..motion.frames()).map(|f| a[f * n + j].distance(b[f * n + j])).fold(0.0, f32::max);
            assert!(worst <= 0.06 * diameter, "{}: joint {j} moved {worst}", path.display());
        }
    }
    eprintln!("{} clips, {} rejected: {rejected:?}", files.len(), rejected.values().sum::<usize>());
    assert!(rejected.values().sum::<usize>() * 10 < files.len(), "most clips are usable: {rejected:?}");
}

#[test]
fn every_clip_of_a_rig_cleans_to_one_hierarchy() {
    let Some(files) = corpus_sample(1) else { return };
    // A rig is a hierarchy as its files write it; its clips must agree on the cleaned one, or
    // they cannot share a reference pose and one clip's tokens do not read back on another.
    type Tree = Vec<(Option<usize>, String)>;
    let tree = |m: &Motion| -> Tree { m.skeleton().joints().iter().map(|j| (j.parent, j.name.clone())).collect() };
    let mut rigs: BTreeMap<Tree, BTreeMap<Tree, Vec<String>>> = BTreeMap::new();
    for path in &files {
        let motion = load(path);
        let Ok(cleaned) = clean(&motion, &CleanOptions::default()) else { continue };
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        rigs.entry(tree(&motion)).or_default().entry(tree(&cleaned.motion)).or_default().push(name);
    }
    let split: Vec<Vec<&Vec<String>>> =
        rigs.values().filter(|cleaned| cleaned.len() > 1).map(|cleaned| cleaned.values().collect()).collect();
    assert!(rigs.len() > 30, "the corpus holds many rigs: {}", rigs.len());
    assert!(split.is_empty(), "rigs whose clips clean to different hierarchies: {split:?}");
}

#[test]
fn clean_clips_drop_helpers_and_collapse_dummy_roots() {
    let Some(dir) = data_dir() else { return };
    let bandai = load(&dir.join("bandai/dataset-1/dataset-1_bow_active_001.bvh.gz"));
    let cleaned = clean(&bandai, &CleanOptions::default()).unwrap();
    // Bandai's `joint_Root`, a helper by its name, is folded into `Hips`.
    assert_eq!(cleaned.motion.skeleton().joint(0).name, "Hips");
    assert_eq!(cleaned.motion.skeleton().len(), bandai.skeleton().len() - 1);
    let horse = load(&dir.join("quaternius/bvh/animals_pack/Horse__Walk.bvh.gz"));
    let cleaned = clean(&horse, &CleanOptions::default()).unwrap();
    let names: Vec<&str> = cleaned.motion.skeleton().joints().iter().map(|j| j.name.as_str()).collect();
    assert!(!names.iter().any(|n| n.contains("PoleTarget") || n.starts_with("IK")), "{names:?}");
    assert_ne!(names[0], "VirtualRoot");
    // The mech's feet float on its dummy root, animated in position, and go back under the shin
    // they move with, also when the legs hardly move and the hip holds the foot almost as still.
    let parent_of = |cleaned: &Motion, name: &str| {
        let skeleton = cleaned.skeleton();
        let joint = skeleton.joints().iter().find(|j| j.name == name).expect("the joint is kept");
        skeleton.joint(joint.parent.expect("not the root")).name.clone()
    };
    for clip in ["Dance", "No"] {
        let path = dir.join(format!("quaternius/bvh/ultimate_space_pack/Mech_FinnTheFrog_transformed__{clip}.bvh.gz"));
        let cleaned = clean(&load(&path), &CleanOptions::default()).unwrap().motion;
        assert_eq!(cleaned.skeleton().joint(0).name, "Body", "{clip}");
        assert_eq!(parent_of(&cleaned, "Foot.L"), "LowerLeg.L", "{clip}");
        assert_eq!(parent_of(&cleaned, "Foot.R"), "LowerLeg.R", "{clip}");
    }
    // The spider's foot targets are only rotated by the file: fixed in its root's frame, they
    // stay there, in the idle as in the walk.
    for clip in ["Idle", "Walk"] {
        let path = dir.join(format!("quaternius/bvh/easy_enemies_pack/Spider__Spider_{clip}.bvh.gz"));
        let cleaned = clean(&load(&path), &CleanOptions::default()).unwrap().motion;
        assert_eq!(parent_of(&cleaned, "FrontFoot.L"), "Root", "{clip}");
    }
}

#[test]
fn features_rebuild_canonical_clips() {
    let Some(files) = corpus_sample(9) else { return };
    for path in &files {
        let Ok(cleaned) = clean(&load(path), &CleanOptions::default()) else { continue };
        let canonical = canonicalise(&cleaned.motion);
        let (features, start) = to_features(&canonical);
        assert!(start.planar[0].abs() < 1e-5 && start.planar[1].abs() < 1e-5);
        let back = from_features(&features, start, canonical.skeleton(), canonical.frame_time());
        let worst = worst_distance(&all_joint_positions(&canonical), &all_joint_positions(&back));
        // Diameter 1: the rebuilt motion is within a thousandth of the skeleton's size.
        assert!(worst < 1e-3, "{}: features moved joints by {worst}", path.display());
    }
}

#[test]
fn rebasing_on_a_frame_keeps_every_position() {
    let Some(files) = corpus_sample(29) else { return };
    for path in &files {
        let motion = load(path);
        let rebased = ReferencePose::of_frame(&motion, motion.frames() / 2).rebase(&motion);
        assert_ne!(rebased.skeleton(), motion.skeleton());
        let worst = worst_distance(&all_joint_positions(&motion), &all_joint_positions(&rebased));
        assert!(worst < 1e-4 * motion.skeleton().diameter().max(1.0), "{}: {worst}", path.display());
    }
}

#[test]
fn turning_joint_frames_keeps_every_position_and_turns_back() {
    let Some(files) = corpus_sample(29) else { return };
    for (k, path) in files.iter().enumerate() {
        let motion = load(path);
        let n = motion.skeleton().len();
        // Seeded, arbitrary turns: each joint's frame about its own axis by its own angle.
        let turns: Vec<Quat> = (0..n)
            .map(|j| {
                let a = (j * 7 + k * 3) as f32;
                Quat::from_axis_angle(Vec3::new(a.sin(), a.cos(), 0.3 + (a * 0.5).sin()).normalize(), 0.4 + a % 2.7)
            })
            .collect();
        let turned = turn_joint_frames(&motion, &turns);
        assert_ne!(turned.skeleton(), motion.skeleton(), "{}: the rig's conventions change", path.display());
        let worst = worst_distance(&all_joint_positions(&motion), &all_joint_positions(&turned));
        assert!(worst < 1e-4 * motion.skeleton().diameter().max(1.0), "{}: {worst}", path.display());
        let inverse: Vec<Quat> = turns.iter().map(|q| q.inverse()).collect();
        let back = turn_joint_frames(&turned, &inverse);
        let angle = back
            .all_rotations()
            .iter()
            .zip(motion.all_rotations())
            .map(|(a, b)| a.angle_between(*b))
            .fold(0.0f32, f32::max);
        // f32 products and the arccos near 1 cost about a milliradian; a wrong turn costs radians.
        assert!(angle < 5e-3, "{}: turning back is off by {angle} rad", path.display());
    }
}

#[test]
fn mirroring_swaps_sides_and_twice_is_the_identity() {
    let Some(dir) = data_dir() else { return };
    for clip in ["bandai/dataset-1/dataset-1_bow_active_001.bvh.gz", "quaternius/bvh/animals_pack/Horse__Walk.bvh.gz"] {
        let motion = clean(&load(&dir.join(clip)), &CleanOptions::default()).unwrap().motion;
        let pair = mirror_pairs(&label_skeleton(motion.skeleton()));
        assert!(pair.iter().enumerate().any(|(i, &p)| i != p), "{clip}: has left/right pairs");
        let mirrored = mirror(&motion).unwrap();
        let (a, b) = (all_joint_positions(&motion), all_joint_positions(&mirrored));
        let n = motion.skeleton().len();
        for f in 0..motion.frames() {
            for j in 0..n {
                let expected = a[f * n + pair[j]] * Vec3::new(-1.0, 1.0, 1.0);
                assert!(b[f * n + j].distance(expected) < 1e-4, "{clip} frame {f} joint {j}");
            }
        }
        let twice = mirror(&mirrored).unwrap();
        assert!(worst_distance(&a, &all_joint_positions(&twice)) < 1e-4);
    }
}

#[test]
fn bone_scaling_scales_the_body_not_the_path() {
    let Some(dir) = data_dir() else { return };
    let motion = clean(&load(&dir.join("bandai/dataset-1/dataset-1_bow_active_001.bvh.gz")), &CleanOptions::default())
        .unwrap()
        .motion;
    let n = motion.skeleton().len();
    let mut factors = vec![2.0; n];
    factors[0] = 1.0;
    let scaled = scale_bones(&motion, &factors);
    assert!((scaled.skeleton().diameter() - 2.0).abs() < 1e-4);
    let (a, b) = (all_joint_positions(&motion), all_joint_positions(&scaled));
    for f in 0..motion.frames() {
        let (ra, rb) = (a[f * n], b[f * n]);
        assert!(ra.distance(rb) < 1e-6, "the root path is kept");
        for j in 1..n {
            assert!(((b[f * n + j] - rb) - (a[f * n + j] - ra) * 2.0).length() < 1e-4);
        }
    }
}

#[test]
fn the_loader_batches_real_clips_into_finite_tensors() {
    use anymo_tokenizer::dataset::{LoaderConfig, TrainingClip, WindowLoader};
    let Some(files) = corpus_sample(97) else { return };
    let clips: Vec<TrainingClip> = files
        .iter()
        .filter_map(|p| {
            let motion = clean(&load(p), &CleanOptions::default()).ok()?.motion;
            Some(TrainingClip { motion, source: p.parent()?.display().to_string() })
        })
        .collect();
    let config = LoaderConfig { window: 32, batch_size: 4, seed: 1, skeletons_per_step: 4, ..LoaderConfig::default() };
    let loader = WindowLoader::new(clips, config);
    let batches: Vec<_> = (0..8).flat_map(|step| loader.step(step).unwrap()).collect();
    for b in &batches {
        for t in [&b.root, &b.rotations, &b.offsets] {
            let v: Vec<f32> = t.flatten_all().unwrap().to_vec1().unwrap();
            assert!(v.iter().all(|x| x.is_finite()));
        }
        // Canonical windows stand on the floor: root heights stay within a few diameters of it.
        let root: Vec<f32> = b.root.flatten_all().unwrap().to_vec1().unwrap();
        assert!(root.chunks(4).all(|r| r[3] > -0.1 && r[3] < 5.0), "root heights in diameters");
    }
}

#[test]
fn a_walk_has_feet_that_touch_down_and_lift() {
    use anymo_motion::features::foot_joints;
    use anymo_motion::kinematics::all_joint_positions;
    use anymo_motion::prep::labels::label_name;
    let Some(dir) = data_dir() else { return };
    let walk = dir.join("bandai/dataset-1/dataset-1_walk_active_001.bvh.gz");
    let motion = canonicalise(&clean(&load(&walk), &CleanOptions::default()).unwrap().motion);
    let feet = foot_joints(&motion, 0.05);
    let names: Vec<String> = feet.iter().map(|&j| label_name(&motion.skeleton().joint(j).name).text()).collect();
    assert_eq!(feet.len(), 2, "{names:?}");
    assert!(names.iter().all(|n| n.contains("toe") || n.contains("foot")), "{names:?}");
    // In contact: within 3% of the diameter of the floor and slower than 0.5% of it per frame.
    let (positions, n, frames) = (all_joint_positions(&motion), motion.skeleton().len(), motion.frames());
    for (&foot, name) in feet.iter().zip(&names) {
        let at = |f: usize| positions[f * n + foot];
        let down =
            (1..frames - 1).filter(|&f| at(f).y <= 0.03 && (at(f + 1) - at(f - 1)).length() / 2.0 <= 0.005).count();
        assert!(down > frames / 10 && down < frames * 9 / 10, "{name}: in contact {down} of {frames} frames");
    }
}

/// Mean angle (degrees) of the non-root joints' local rotations from the identity.
fn mean_local_angle(motion: &Motion) -> f32 {
    let n = motion.skeleton().len();
    let angles: Vec<f32> = motion
        .all_rotations()
        .iter()
        .enumerate()
        .filter(|(k, _)| k % n != 0)
        .map(|(_, q)| q.angle_between(Quat::IDENTITY))
        .collect();
    angles.iter().sum::<f32>() / angles.len().max(1) as f32 * 180.0 / std::f32::consts::PI
}

#[test]
fn rebasing_on_the_mean_pose_leaves_small_deltas_that_no_rig_convention_changes() {
    let Some(files) = corpus_sample(29) else { return };
    let mut tested = 0;
    for (k, path) in files.iter().enumerate() {
        let Ok(cleaned) = clean(&load(path), &CleanOptions::default()) else { continue };
        let motion = cleaned.motion;
        let n = motion.skeleton().len();
        let reference = ReferencePose::mean_of([&motion]).unwrap();
        let rebased = reference.rebase(&motion);
        let (raw, delta) = (mean_local_angle(&motion), mean_local_angle(&rebased));
        eprintln!("{}: local rotations {raw:.1} deg from rest, {delta:.1} deg from the mean pose", path.display());
        assert!(delta < 30.0, "{}: {delta} deg from the clip's own mean pose", path.display());

        // The same world motion on a rig with other local axes rebases to the same features.
        let turns: Vec<Quat> = (0..n)
            .map(|j| {
                let a = (j * 5 + k * 11) as f32;
                Quat::from_axis_angle(Vec3::new(a.cos(), 0.2 + a.sin(), (a * 0.3).sin()).normalize(), 0.3 + a % 2.9)
            })
            .collect();
        let turned = turn_joint_frames(&motion, &turns);
        let again = ReferencePose::mean_of([&turned]).unwrap().rebase(&turned);
        let ((a, _), (b, _)) = (to_features(&rebased), to_features(&again));
        let worst = a
            .rotations
            .iter()
            .chain(&a.root)
            .zip(b.rotations.iter().chain(&b.root))
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max);
        assert!(worst < 5e-3, "{}: features differ by {worst} on a rig with turned joint frames", path.display());
        let offsets = rebased
            .skeleton()
            .joints()
            .iter()
            .zip(again.skeleton().joints())
            .map(|(p, q)| p.offset.distance(q.offset))
            .fold(0.0f32, f32::max);
        assert!(offsets < 1e-4, "{}: rebased offsets differ by {offsets}", path.display());
        tested += 1;
    }
    assert!(tested >= 30, "only {tested} clips could be cleaned");
}
