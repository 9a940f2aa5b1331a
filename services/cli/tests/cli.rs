//! The `anymo` binary as a user runs it: inspect, convert and fk on real files, and clear
//! errors with a non-zero exit for bad input.

use anymo_motion::bvh::{self, ReadOptions};
use anymo_motion::kinematics::{all_joint_positions, joint_positions};
use anymo_motion::motion::Motion;
use anymo_tests::{data_dir, scratch_dir};
use std::path::Path;
use std::process::{Command, Output};

fn anymo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_anymo")).args(args).output().expect("the anymo binary runs")
}

fn stdout(out: &Output) -> String {
    assert!(out.status.success(), "failed: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout.clone()).unwrap()
}

fn malformed(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../motion/tests/malformed").join(name).to_string_lossy().into_owned()
}

#[test]
fn inspect_describes_a_clip() {
    let Some(dir) = data_dir() else { return };
    let file = dir.join("bandai/dataset-1/dataset-1_bow_active_001.bvh.gz");
    let text = stdout(&anymo(&["inspect", file.to_str().unwrap()]));
    assert!(text.contains("joints: 22  channels per frame: 132"), "{text}");
    assert!(text.contains("frames: 128  fps: 30.000"), "{text}");
    assert!(text.contains("UpperLeg_L  [Xposition Yposition Zposition Zrotation Xrotation Yrotation]"), "{text}");
    assert!(text.contains("left upper leg"), "{text}");
    assert!(text.contains("model root: \"Hips\""), "{text}");
}

#[test]
fn inspect_fails_with_the_line_of_a_malformed_file() {
    let out = anymo(&["inspect", &malformed("missing_open_brace.bvh")]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("line 7, column 3: expected {, found \"OFFSET\""), "{err}");
}

#[test]
fn fk_prints_joint_positions_as_json() {
    let Some(dir) = data_dir() else { return };
    let file = dir.join("cmu/007_11.bvh.gz");
    let json: serde_json::Value =
        serde_json::from_str(&stdout(&anymo(&["fk", file.to_str().unwrap(), "--frame", "5"]))).unwrap();
    let clip = bvh::read_path(&file, ReadOptions::default()).unwrap();
    let expected = joint_positions(&Motion::from_bvh(&clip), 5);
    let list = json.as_array().unwrap();
    assert_eq!(list.len(), clip.skeleton().len());
    for ((entry, joint), p) in list.iter().zip(clip.skeleton().joints()).zip(&expected) {
        assert_eq!(entry["name"], joint.name.as_str());
        let got: Vec<f32> = entry["position"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap() as f32).collect();
        assert_eq!(got, p.to_array().to_vec());
    }
    let out = anymo(&["fk", file.to_str().unwrap(), "--frame", "158"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("frame 158 is out of range"));
}

#[test]
fn fk_prints_global_orientations_and_headings() {
    // Orientations compose down the chain: a root turned 30 degrees about +Y and tilted, then a
    // child turned 45 more about its own +Y, faces 75 degrees; its quaternion is the product.
    let chain = scratch_dir("fk-headings").join("chain.bvh");
    std::fs::write(
        &chain,
        "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Yrotation Xrotation Zrotation\n \
         JOINT Spine\n {\n  OFFSET 0 1 0\n  CHANNELS 3 Yrotation Xrotation Zrotation\n  End Site\n  {\n   OFFSET 0 1 0\n  }\n }\n}\n\
         MOTION\nFrames: 1\nFrame Time: 0.0333333\n0 0 0 30 20 0 45 0 0\n",
    )
    .unwrap();
    let json: serde_json::Value = serde_json::from_str(&stdout(&anymo(&["fk", chain.to_str().unwrap()]))).unwrap();
    let heading = |j: usize| json[j]["heading_degrees"].as_f64().unwrap();
    assert!((heading(0) - 30.0).abs() < 1e-4, "{json}");
    let root = glam::Quat::from_rotation_y(30f32.to_radians()) * glam::Quat::from_rotation_x(20f32.to_radians());
    let spine = root * glam::Quat::from_rotation_y(45f32.to_radians());
    let got: Vec<f32> = json[1]["rotation"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap() as f32).collect();
    let want = spine.to_array();
    let equal_up_to = |sign: f32| got.iter().zip(&want).all(|(a, b)| (a - sign * b).abs() < 1e-6);
    assert!(equal_up_to(1.0) || equal_up_to(-1.0), "{got:?} against {want:?} (a quaternion or its negative)");
    assert!((heading(1) - 75.0).abs() < 1e-3, "{json}");
}

#[test]
fn convert_glb_animation_to_bvh() {
    let Some(dir) = data_dir() else { return };
    let out_dir = scratch_dir("convert-glb");
    let glb = dir.join("quaternius/glb/animals_pack/Horse.glb");
    let first = out_dir.join("first.bvh");
    stdout(&anymo(&["convert", glb.to_str().unwrap(), first.to_str().unwrap()]));
    // The first animation by default: Attack_Headbutt, 1 s at 30 fps.
    let clip = bvh::read_path(&first, ReadOptions { require_motion: true }).unwrap();
    assert_eq!(clip.frames(), 31);
    let walk = out_dir.join("walk.bvh");
    stdout(&anymo(&[
        "convert",
        glb.to_str().unwrap(),
        walk.to_str().unwrap(),
        "--animation",
        "AnimalArmature|Walk",
        "--fps",
        "60",
    ]));
    let clip = bvh::read_path(&walk, ReadOptions::default()).unwrap();
    assert!((clip.fps() - 60.0).abs() < 1e-6);
    assert_eq!(clip.frames(), 71, "1.17 s at 60 fps");
    let out = anymo(&["convert", glb.to_str().unwrap(), walk.to_str().unwrap(), "--animation", "Moonwalk"]);
    assert!(
        String::from_utf8_lossy(&out.stderr)
            .contains("no animation \"Moonwalk\"; the file has: AnimalArmature|Attack_Headbutt")
    );
}

#[test]
fn convert_bvh_keeps_numbers_or_changes_only_what_was_asked() {
    let Some(dir) = data_dir() else { return };
    let out_dir = scratch_dir("convert-bvh");
    let source = dir.join("xia/strutting_01_000.bvh.gz");
    let original = bvh::read_path(&source, ReadOptions::default()).unwrap();
    let copy = out_dir.join("copy.bvh");
    stdout(&anymo(&["convert", source.to_str().unwrap(), copy.to_str().unwrap()]));
    assert_eq!(bvh::read_path(&copy, ReadOptions::default()).unwrap(), original);

    let reordered = out_dir.join("xyz.bvh");
    stdout(&anymo(&["convert", source.to_str().unwrap(), reordered.to_str().unwrap(), "--euler-order", "XYZ"]));
    let clip = bvh::read_path(&reordered, ReadOptions::default()).unwrap();
    assert!(clip.skeleton().joints().iter().all(|j| j.channels.euler_order().to_string() == "XYZ"));
    let (a, b) = (all_joint_positions(&Motion::from_bvh(&original)), all_joint_positions(&Motion::from_bvh(&clip)));
    let worst = a.iter().zip(&b).map(|(p, q)| p.distance(*q)).fold(0.0f32, f32::max);
    assert!(worst < 1e-3 * original.skeleton().diameter(), "same poses in another Euler order ({worst})");

    let normalised = out_dir.join("normalised.bvh");
    stdout(&anymo(&["convert", source.to_str().unwrap(), normalised.to_str().unwrap(), "--normalise", "--fps", "30"]));
    let clip = bvh::read_path(&normalised, ReadOptions::default()).unwrap();
    assert!((clip.skeleton().diameter() - 1.0).abs() < 1e-4);
    assert!((clip.fps() - 30.0).abs() < 1e-6);
    let start = joint_positions(&Motion::from_bvh(&clip), 0)[0];
    assert!(start.x.abs() < 1e-5 && start.z.abs() < 1e-5, "starts at the origin: {start}");
}
