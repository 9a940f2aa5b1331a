//! A tokens file carries its clip's own pose: decoded on any file of the clip's rig, the clip
//! comes back in its own posture rather than the target file's, and a file without the pose code
//! (as written before it existed) still decodes, around the target's pose.

use anymo_motion::bvh::{self, ReadOptions};
use anymo_motion::kinematics::all_joint_positions;
use anymo_motion::motion::Motion;
use anymo_tests::{data_dir, gunzip, models_dir, run_anymo, scratch_dir, succeeded};
use std::path::Path;

fn anymo(models: &Path, args: &[&str]) -> std::process::Output {
    run_anymo(env!("CARGO_BIN_EXE_anymo"), models, args)
}

fn motion(path: &Path) -> Motion {
    Motion::from_bvh(
        &bvh::read_path(path, ReadOptions::default()).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
}

/// Mean distance between the joints of two motions on one hierarchy, in the truth's diameters.
fn error(truth: &Motion, decoded: &Motion) -> f32 {
    let frames = truth.frames().min(decoded.frames());
    let (a, b) = (all_joint_positions(&truth.slice(0, frames)), all_joint_positions(&decoded.slice(0, frames)));
    a.iter().zip(&b).map(|(p, q)| p.distance(*q)).sum::<f32>() / a.len() as f32 / truth.skeleton().diameter()
}

#[test]
fn tokens_come_back_in_their_own_pose_on_another_file_of_their_rig() {
    let (Some(shared), Some(models)) = (data_dir(), models_dir()) else { return };
    let dir = scratch_dir("pose-code");
    let s = |p: &Path| p.to_string_lossy().into_owned();
    // An old person's bow (bent over) and a dash (upright, leaning into the run): one rig.
    let (bow, dash) = (dir.join("bow.bvh"), dir.join("dash.bvh"));
    gunzip(&shared.join("bandai/dataset-1/dataset-1_bow_old_001.bvh.gz"), &bow);
    gunzip(&shared.join("bandai/dataset-1/dataset-1_dash_normal_001.bvh.gz"), &dash);
    let tokens = dir.join("bow.tokens.json");
    succeeded(anymo(&models, &["tokenize", &s(&bow), "-o", &s(&tokens)]));
    let file: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&tokens).unwrap()).unwrap();
    let joints = file["pose"]["joints"].as_array().expect("the tokens file carries the pose code");
    assert!(joints.iter().all(|j| j["rotation"].as_array().unwrap().len() == 4));

    let decode = |tokens: &Path, on: &Path, name: &str| {
        let out = dir.join(name);
        succeeded(anymo(&models, &["detokenize", &s(tokens), "--skeleton", &s(on), "-o", &s(&out)]));
        motion(&out)
    };
    let truth = motion(&bow);
    let on_itself = error(&truth, &decode(&tokens, &bow, "on-bow.bvh"));
    let on_dash = error(&truth, &decode(&tokens, &dash, "on-dash.bvh"));
    let mut plain = file.clone();
    plain.as_object_mut().unwrap().remove("pose");
    let without = dir.join("bow.plain.json");
    std::fs::write(&without, serde_json::to_string(&plain).unwrap()).unwrap();
    let around_dash = error(&truth, &decode(&without, &dash, "plain-on-dash.bvh"));
    eprintln!(
        "joint error against the bow: on its own file {on_itself:.4}, on the dash's {on_dash:.4}, without the code {around_dash:.4}"
    );
    // Measured on the shipped models: 0.0091 on its own file, 0.0050 on the dash's, 0.0178
    // without the code (the bow's own file has end sites of no length, which its decoding
    // reads too).
    assert!(on_dash < 1.5 * on_itself, "on another file of its rig the bow decodes as well as on its own");
    assert!(around_dash > 2.0 * on_dash, "without its pose the bow is read around the dash's posture");
    std::fs::remove_dir_all(&dir).unwrap();
}
