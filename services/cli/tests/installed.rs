//! The `anymo` binary copied out of the build tree, as `cargo install` or a user would leave it,
//! and run from an unrelated folder: it finds the sentence encoder where `tools/setup.sh` put it
//! and uses the checkpoints built into it, so a clip round-trips through tokens with nothing
//! from the repository beside it or in the working folder.

use anymo_motion::bvh::{self, ReadOptions};
use anymo_tests::{data_dir, gunzip, models_dir, scratch_dir, succeeded};
use std::path::Path;
use std::process::Command;

/// The copied binary, run in `cwd` with no checkpoint or data folder from the environment.
fn installed(binary: &Path, cwd: &Path, args: &[&str]) -> std::process::Output {
    Command::new(binary)
        .args(args)
        .current_dir(cwd)
        .env_remove("ANYMO_CHECKPOINTS")
        .env_remove("ANYMO_DATA_DIR")
        .env_remove("DATABASE_URL")
        .env("RAYON_NUM_THREADS", "1")
        .output()
        .expect("the copied binary runs")
}

#[test]
fn a_copied_binary_runs_from_any_folder() {
    let (Some(shared), Some(_)) = (data_dir(), models_dir()) else { return };
    let root = scratch_dir("installed");
    let bin = root.join("bin");
    let work = root.join("somewhere-else");
    std::fs::create_dir_all(&bin).unwrap();
    std::fs::create_dir_all(&work).unwrap();
    let binary = bin.join("anymo");
    std::fs::copy(env!("CARGO_BIN_EXE_anymo"), &binary).unwrap();
    let clip = work.join("walk.bvh");
    gunzip(&shared.join("bandai/dataset-1/dataset-1_walk_normal_001.bvh.gz"), &clip);

    let tokens = installed(&binary, &work, &["tokenize", "walk.bvh", "-o", "walk.tokens.json"]);
    succeeded(tokens);
    let decoded =
        installed(&binary, &work, &["detokenize", "walk.tokens.json", "--skeleton", "walk.bvh", "-o", "decoded.bvh"]);
    succeeded(decoded);
    let source = bvh::read_path(&clip, ReadOptions::default()).unwrap();
    let back = bvh::read_path(work.join("decoded.bvh"), ReadOptions::default()).unwrap();
    assert_eq!(back.skeleton(), source.skeleton(), "the user's hierarchy, offsets and channels come back");
    assert!(back.frames() > 0, "decoded motion has frames");

    // A checkpoint folder beside the binary is used instead of the built-in set: an empty one
    // has no tokenizer, and the error says where it looked.
    std::fs::create_dir_all(bin.join("checkpoints")).unwrap();
    let refused = installed(&binary, &work, &["tokenize", "walk.bvh", "-o", "again.json"]);
    assert!(!refused.status.success());
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(err.contains("checkpoint tat-v2 not found in") && err.contains("bin/checkpoints"), "{err}");
    std::fs::remove_dir_all(&root).unwrap();
}
