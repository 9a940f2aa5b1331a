//! Every animation of every Quaternius GLB converts to BVH, and the result is plausible: it
//! reads back, its joints follow the glTF skin, and a walking horse keeps its hooves on the
//! ground.

use anymo_motion::bvh::{self, ReadOptions};
use anymo_motion::gltf::GltfAsset;
use anymo_motion::kinematics::all_joint_positions;
use anymo_motion::motion::Motion;
use anymo_motion::skeleton::EulerOrder;
use anymo_tests::{data_dir, files_with_suffix};

#[test]
fn every_glb_animation_converts_and_reads_back() {
    let Some(dir) = data_dir() else { return };
    let files = files_with_suffix(&dir.join("quaternius/glb"), ".glb");
    assert!(files.len() >= 100, "expected the Quaternius GLB set, found {}", files.len());
    let mut animations = 0;
    for path in &files {
        let asset = GltfAsset::open(path, EulerOrder::Zxy).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        for info in asset.animations() {
            let motion =
                asset.motion(info.index, 30.0).unwrap_or_else(|e| panic!("{} {}: {e}", path.display(), info.name));
            assert_eq!(motion.frames(), (info.duration as f64 * 30.0).round() as usize + 1);
            let mut text = Vec::new();
            bvh::write(&motion.to_bvh(), &mut text).unwrap();
            let back = Motion::from_bvh(&bvh::read(text.as_slice(), ReadOptions { require_motion: true }).unwrap());
            let (a, b) = (all_joint_positions(&motion), all_joint_positions(&back));
            let scale = motion.skeleton().diameter();
            let worst = a.iter().zip(&b).map(|(p, q)| p.distance(*q)).fold(0.0f32, f32::max);
            assert!(worst <= 1e-3 * scale, "{} {}: BVH moved joints by {worst}", path.display(), info.name);
            animations += 1;
        }
    }
    assert!(animations >= 800, "converted {animations} animations");
}

#[test]
fn control_bones_that_deform_nothing_are_dropped() {
    let Some(dir) = data_dir() else { return };
    let asset = GltfAsset::open(dir.join("quaternius/glb/animals_pack/Horse.glb"), EulerOrder::Zxy).unwrap();
    let names: Vec<&str> = asset.skeleton().joints().iter().map(|j| j.name.as_str()).collect();
    assert!(!names.iter().any(|n| n.starts_with("PoleTarget")), "{names:?}");
    // The hooves deform the mesh, so they stay, with the IK bones they hang from.
    assert!(names.contains(&"FF.L") && names.contains(&"IKFrontLeg.L"), "{names:?}");
}

#[test]
fn a_walking_horse_keeps_its_hooves_on_the_ground() {
    let Some(dir) = data_dir() else { return };
    let asset = GltfAsset::open(dir.join("quaternius/glb/animals_pack/Horse.glb"), EulerOrder::Zxy).unwrap();
    let walk = asset.find_animation("AnimalArmature|Walk").unwrap();
    let motion = asset.motion(walk, 30.0).unwrap();
    let skeleton = motion.skeleton();
    let n = skeleton.len();
    let positions = all_joint_positions(&motion);
    let hooves: Vec<usize> = ["FF.L", "FF.R", "FFB.L", "FFB.R"].iter().map(|h| skeleton.find(h).unwrap()).collect();
    let height = skeleton.rest_positions().iter().map(|p| p.y).fold(f32::MIN, f32::max);
    let touchdown: Vec<f32> = hooves
        .iter()
        .map(|&h| (0..motion.frames()).map(|f| positions[f * n + h].y).fold(f32::INFINITY, f32::min))
        .collect();
    // Every hoof comes down to the same ground level, just above the floor (y = 0 in glTF; the
    // hoof joint sits inside the hoof, above its sole)...
    let ground = touchdown.iter().copied().fold(f32::INFINITY, f32::min);
    assert!(ground > 0.0 && ground < 0.1 * height, "hooves touch down at {touchdown:?} (height {height})");
    for (h, t) in hooves.iter().zip(&touchdown) {
        assert!(t - ground < 0.02 * height, "{} touches down at {t}, others at {ground}", skeleton.joint(*h).name);
    }
    for f in 0..motion.frames() {
        let frame = &positions[f * n..(f + 1) * n];
        // ...in every frame some hoof stands on it and no body joint sinks below it...
        let lowest_hoof = hooves.iter().map(|&h| frame[h].y).fold(f32::INFINITY, f32::min);
        assert!(lowest_hoof - ground < 0.02 * height, "frame {f}: no hoof on the ground ({lowest_hoof})");
        for (j, p) in frame.iter().enumerate().skip(1) {
            assert!(p.y > ground - 0.02 * height, "frame {f}: {} below the ground", skeleton.joint(j).name);
        }
    }
    // ...and every hoof lifts during the cycle.
    for (&h, &t) in hooves.iter().zip(&touchdown) {
        let high = (0..motion.frames()).map(|f| positions[f * n + h].y).fold(f32::MIN, f32::max);
        assert!(high - t > 0.02 * height, "{}: never lifts", skeleton.joint(h).name);
    }
}
