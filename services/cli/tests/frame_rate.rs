//! Decoded motion comes at the target file's frame rate: a 60 fps clip round-trips through
//! tokens at 60 fps with its own length, `--fps` overrides that, and a transfer answers at the
//! rate of the skeleton file it moves onto. The models run at 30 fps in between.

use anymo_motion::bvh::{self, ReadOptions};
use anymo_tests::{data_dir, gunzip, models_dir, run_anymo, scratch_dir, succeeded};
use std::path::Path;

fn anymo(models: &Path, args: &[&str]) -> std::process::Output {
    run_anymo(env!("CARGO_BIN_EXE_anymo"), models, args)
}

fn read(path: &Path) -> bvh::Bvh {
    bvh::read_path(path, ReadOptions::default()).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn decoded_motion_takes_the_target_files_frame_rate() {
    let (Some(shared), Some(models)) = (data_dir(), models_dir()) else { return };
    let dir = scratch_dir("frame-rate");
    let clip = dir.join("cmu.bvh");
    gunzip(&shared.join("cmu/001_01.bvh.gz"), &clip);
    let source = read(&clip);
    assert!((source.fps() - 60.0).abs() < 0.01, "the CMU clip is 60 fps");
    let s = |p: &Path| p.to_string_lossy().into_owned();
    let tokens = dir.join("tokens.json");
    succeeded(anymo(&models, &["tokenize", &s(&clip), "-o", &s(&tokens)]));

    let back = dir.join("back.bvh");
    succeeded(anymo(&models, &["detokenize", &s(&tokens), "--skeleton", &s(&clip), "-o", &s(&back)]));
    let back = read(&back);
    assert!((back.frame_time() - source.frame_time()).abs() < 1e-6, "{} fps", back.fps());
    assert!(back.frames().abs_diff(source.frames()) <= 1, "{} frames against {}", back.frames(), source.frames());

    let slow_path = dir.join("slow.bvh");
    succeeded(anymo(
        &models,
        &["detokenize", &s(&tokens), "--skeleton", &s(&clip), "--fps", "24", "-o", &s(&slow_path)],
    ));
    let slow = read(&slow_path);
    assert!((slow.fps() - 24.0).abs() < 1e-3, "{} fps", slow.fps());
    let seconds = |b: &bvh::Bvh| (b.frames() - 1) as f64 * b.frame_time();
    assert!((seconds(&slow) - seconds(&source)).abs() < 0.1, "the same duration at another rate");

    let horse = dir.join("horse.bvh");
    gunzip(&shared.join("quaternius/bvh/animals_pack/Horse__Walk.bvh.gz"), &horse);
    let moved = dir.join("moved.bvh");
    succeeded(anymo(&models, &["transfer", &s(&clip), "--to", &s(&horse), "-o", &s(&moved)]));
    let moved = read(&moved);
    assert!((moved.frame_time() - read(&horse).frame_time()).abs() < 1e-6, "{} fps", moved.fps());

    let refused =
        anymo(&models, &["detokenize", &s(&tokens), "--skeleton", &s(&clip), "--fps", "0", "-o", &s(&slow_path)]);
    assert!(!refused.status.success());
    assert!(String::from_utf8_lossy(&refused.stderr).contains("frame rate must be in (0, 1000]"));
    std::fs::remove_dir_all(&dir).unwrap();
}
