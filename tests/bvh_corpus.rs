//! Every BVH file of the shared corpus reads, writes back to identical numbers, and decodes
//! to a motion that encodes back to the same poses.

use anymo_motion::bvh::{self, ReadOptions};
use anymo_motion::kinematics::all_joint_positions;
use anymo_motion::motion::Motion;
use anymo_tests::{data_dir, files_with_suffix};

#[test]
fn every_corpus_file_round_trips_exactly_through_the_writer() {
    let Some(dir) = data_dir() else { return };
    let files = files_with_suffix(&dir, ".bvh.gz");
    assert!(files.len() > 1000, "expected the full corpus, found {} files", files.len());
    for path in &files {
        let clip = bvh::read_path(path, ReadOptions { require_motion: true })
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut text = Vec::new();
        bvh::write(&clip, &mut text).unwrap();
        let again = bvh::read(text.as_slice(), ReadOptions::default()).unwrap();
        assert_eq!(again, clip, "{}", path.display());
        // Bit-identical values, including the sign of zeros.
        let bits = |b: &bvh::Bvh| b.values().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&again), bits(&clip), "{}", path.display());
        // Writing what was written gives the same bytes.
        let mut text2 = Vec::new();
        bvh::write(&again, &mut text2).unwrap();
        assert!(text == text2, "{}: second write differs", path.display());
    }
}

#[test]
fn every_corpus_motion_encodes_back_to_the_same_poses() {
    let Some(dir) = data_dir() else { return };
    for path in files_with_suffix(&dir, ".bvh.gz").iter().step_by(7) {
        let clip = bvh::read_path(path, ReadOptions::default()).unwrap();
        let motion = Motion::from_bvh(&clip);
        let again = Motion::from_bvh(&motion.to_bvh());
        let scale = clip.skeleton().diameter().max(1e-6);
        let a = all_joint_positions(&motion);
        let b = all_joint_positions(&again);
        let worst = a.iter().zip(&b).map(|(p, q)| p.distance(*q)).fold(0.0f32, f32::max);
        assert!(worst / scale < 1e-4, "{}: joints moved by {worst} (diameter {scale})", path.display());
    }
}
