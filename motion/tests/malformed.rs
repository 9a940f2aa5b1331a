//! Every hand-made malformed file in `tests/malformed` gives its own specific error, naming the
//! line and column, and never a panic. The expected messages are pinned in full.

use anymo_motion::bvh::{self, ReadOptions, SyntaxError};
use std::path::Path;

const EXPECTED: &[(&str, &str)] = &[
    ("empty.bvh", "line 1, column 1: expected HIERARCHY, found end of file"),
    ("missing_open_brace.bvh", "line 7, column 3: expected {, found \"OFFSET\""),
    ("unclosed_hierarchy.bvh", "line 14, column 3: expected JOINT, End Site or }, found end of file"),
    ("missing_motion.bvh", "line 15, column 2: expected MOTION, found end of file"),
    ("too_few_values.bvh", "line 20, column 1: frame 1 has 8 values but the hierarchy declares 9 channels"),
    ("too_many_values.bvh", "line 20, column 1: frame 1 has 10 values but the hierarchy declares 9 channels"),
    ("nan_value.bvh", "line 20, column 7: number \"nan\" is not finite"),
    ("infinite_offset.bvh", "line 8, column 12: number \"inf\" is not finite"),
    ("overflowing_number.bvh", "line 20, column 15: number \"1e39\" is not finite"),
    ("bad_number.bvh", "line 20, column 9: expected a number, found \"1.2.3\""),
    ("duplicate_joint.bvh", "line 6, column 8: joint name \"Hips\" is used twice (first at line 2)"),
    ("zero_frame_time.bvh", "line 18, column 13: frame time must be a positive number of seconds, found \"0\""),
    ("negative_frame_time.bvh", "line 18, column 13: frame time must be a positive number of seconds, found \"-0.1\""),
    ("missing_frames.bvh", "line 20, column 1: the file ends after 2 of the 3 frames that Frames: declares"),
    ("extra_frames.bvh", "line 20, column 1: more frame rows than the 1 that Frames: declares"),
    (
        "unknown_channel.bvh",
        "line 9, column 24: unknown channel \"Wrotation\": expected Xposition, Yposition, Zposition, Xrotation, Yrotation or Zrotation",
    ),
    ("duplicate_channel.bvh", "line 9, column 34: channel Zrotation is listed twice for this joint"),
    ("too_many_channels.bvh", "line 9, column 12: a joint has at most 6 channels, CHANNELS declares 7"),
    ("channel_count_mismatch.bvh", "line 9, column 33: expected a channel name, found end of line"),
    ("second_root.bvh", "line 16, column 1: a second ROOT: anymo reads files with one hierarchy"),
    ("offset_too_short.bvh", "line 4, column 12: expected a number, found end of line"),
    ("frames_not_a_number.bvh", "line 17, column 9: expected a number, found \"two\""),
    ("not_bvh.bvh", "line 1, column 1: expected HIERARCHY, found \"<html><body>404</body></html>\""),
    ("missing_joint_name.bvh", "line 6, column 7: expected a joint name, found end of line"),
];

fn here(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests").join(name)
}

/// Every file in `tests/<folder>` is listed in `expected`, and each gives exactly its error.
fn check_folder(folder: &str, expected: &[(&str, &str)]) {
    let dir = here(folder);
    let mut on_disk: Vec<String> =
        std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    on_disk.sort();
    let mut listed: Vec<String> = expected.iter().map(|(f, _)| f.to_string()).collect();
    listed.sort();
    assert_eq!(on_disk, listed, "every file in tests/{folder} has an expected error, and only those");
    for (file, message) in expected {
        let err = bvh::read_path(dir.join(file), ReadOptions::default()).expect_err(file);
        assert_eq!(err.to_string(), *message, "{file}");
    }
}

#[test]
fn each_malformed_file_gives_its_own_error() {
    check_folder("malformed", EXPECTED);
}

#[test]
fn a_skeleton_only_file_is_valid_unless_motion_is_required() {
    let path = here("skeleton_only.bvh");
    let clip = bvh::read_path(&path, ReadOptions::default()).unwrap();
    assert_eq!((clip.frames(), clip.skeleton().len()), (0, 2));
    let err = bvh::read_path(&path, ReadOptions { require_motion: true }).unwrap_err();
    assert_eq!(err.syntax(), Some(&SyntaxError::NoFrames));
    assert_eq!(err.line(), Some(17));
}

#[test]
fn gzip_is_recognised_by_content_and_a_corrupt_stream_is_an_io_error() {
    use std::io::Write;
    let text = std::fs::read(here("skeleton_only.bvh")).unwrap();
    let dir = std::env::temp_dir().join(format!("anymo-gz-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    gz.write_all(&text).unwrap();
    let bytes = gz.finish().unwrap();
    // A gzip file without the .gz suffix still reads.
    std::fs::write(dir.join("plain-name.bvh"), &bytes).unwrap();
    assert_eq!(bvh::read_path(dir.join("plain-name.bvh"), ReadOptions::default()).unwrap().skeleton().len(), 2);
    // A truncated stream is reported, not mistaken for a short file.
    std::fs::write(dir.join("cut.bvh.gz"), &bytes[..bytes.len() / 2]).unwrap();
    let err = bvh::read_path(dir.join("cut.bvh.gz"), ReadOptions::default()).unwrap_err();
    assert!(matches!(err, bvh::BvhError::Io(_)) || err.syntax().is_some(), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Inputs the fuzzer found, each pinned to the error it must now give.
const FUZZ_REGRESSIONS: &[(&str, &str)] = &[
    (
        // No channels and `Frames: 050000000` with no rows: once read as 50 million empty frames
        // (a timeout, then gigabytes in `Motion::from_bvh`); the rows must now back the claim.
        // (`ROOT V{` became `ROOT V {` when names began to keep a brace not set off by a space.)
        "zero_channels_fifty_million_frames.bvh",
        "line 8, column 1: the file ends after 0 of the 50000000 frames that Frames: declares",
    ),
    (
        // `ROOT ua={{{...{`: the last brace was taken as opening the joint, so the name written
        // back lost it again on reading. A brace is now part of the name unless white space
        // comes before it.
        "name_ending_in_braces.bvh",
        "line 3, column 3: expected {, found \"OFFSET\"",
    ),
];

#[test]
fn fuzz_regressions_give_their_errors() {
    check_folder("fuzz_regressions", FUZZ_REGRESSIONS);
}

#[test]
fn a_skeleton_without_channels_counts_its_empty_rows() {
    let text = "HIERARCHY\nROOT A\n{\n OFFSET 0 0 0\n}\nMOTION\nFrames: 2\nFrame Time: 0.5\n\n\n\n";
    assert_eq!(bvh::parse_str(text).unwrap().frames(), 2);
    let short = "HIERARCHY\nROOT A\n{\n OFFSET 0 0 0\n}\nMOTION\nFrames: 3\nFrame Time: 0.5\n\n";
    assert!(matches!(
        bvh::parse_str(short).unwrap_err().syntax(),
        Some(SyntaxError::MissingFrames { declared: 3, found: 1 })
    ));
}
