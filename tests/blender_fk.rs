//! anymo's forward kinematics agrees with Blender's BVH importer, the reference users trust.
//!
//! The references are bone head positions that `tools/blender_fk_batch.py` wrote with Blender
//! 3.4 (`tests/fixtures/blender_fk`, one clip per skeleton of the corpus, first, middle and
//! last frame). Set `ANYMO_BLENDER_REFS` to a folder made the same way to check more clips
//! (the README's figure covers every clip of the corpus).

use anymo_motion::bvh::{self, ReadOptions};
use anymo_motion::kinematics::joint_positions;
use anymo_motion::motion::Motion;
use anymo_tests::{data_dir, reference_files};
use serde_json::Value;

/// The largest tolerated distance, as a fraction of the skeleton's diameter. Blender stores
/// positions in f32 and the references are rounded to 5 decimals.
const TOLERANCE: f32 = 2e-5;

#[test]
fn fk_matches_blenders_importer() {
    let Some(data) = data_dir() else { return };
    let refs = reference_files("ANYMO_BLENDER_REFS", "blender_fk");
    let mut worst = (0.0f32, String::new());
    for reference in &refs {
        let stem = reference.file_stem().and_then(|s| s.to_str()).expect("utf-8 name");
        let clip_path = data.join(stem.replace('+', "/"));
        let clip = bvh::read_path(&clip_path, ReadOptions::default())
            .unwrap_or_else(|e| panic!("{}: {e}", clip_path.display()));
        let motion = Motion::from_bvh(&clip);
        let diameter = clip.skeleton().diameter().max(1e-6);
        let json: Value = serde_json::from_str(&std::fs::read_to_string(reference).unwrap()).unwrap();
        let bones: Vec<&str> = json["bones"].as_array().unwrap().iter().map(|b| b.as_str().unwrap()).collect();
        assert_eq!(bones.len(), clip.skeleton().len(), "{stem}: Blender made a bone per joint");
        for (frame, positions) in json["frames"].as_object().unwrap() {
            let frame: usize = frame.parse().unwrap();
            let ours = joint_positions(&motion, frame);
            for (name, blender) in bones.iter().zip(positions.as_array().unwrap()) {
                let joint = clip.skeleton().find(name).unwrap_or_else(|| panic!("{stem}: no joint {name}"));
                let b: Vec<f32> = blender.as_array().unwrap().iter().map(|v| v.as_f64().unwrap() as f32).collect();
                let error = ours[joint].distance(glam::Vec3::new(b[0], b[1], b[2])) / diameter;
                if error > worst.0 {
                    worst = (error, format!("{stem} frame {frame} joint {name}"));
                }
            }
        }
    }
    eprintln!("{} clips checked; largest difference {:.2e} diameters at {}", refs.len(), worst.0, worst.1);
    assert!(worst.0 <= TOLERANCE, "FK differs from Blender by {} diameters at {}", worst.0, worst.1);
}
