//! Peak memory of reading a large BVH file, against the file's size: the reader streams, so it
//! should need little more than the parsed values (4 bytes per channel value) and never twice
//! the file.
//!
//! `cargo bench -p anymo-tokenizer --bench bvh_memory` builds a file of about 200 MB by
//! repeating the frames of the longest LAFAN1 take, then reads it with `bvh::read_path`.
//! Linux only: peak resident memory comes from /proc/self/status, reset through
//! /proc/self/clear_refs.

use anymo_motion::bvh::{self, Bvh, ReadOptions};
use std::path::{Path, PathBuf};

const TARGET_BYTES: u64 = 200_000_000;

fn peak_rss_kib() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").expect("Linux /proc");
    let line = status.lines().find(|l| l.starts_with("VmHWM:")).expect("VmHWM line");
    line.split_whitespace().nth(1).and_then(|v| v.parse().ok()).expect("a number of kB")
}

fn reset_peak() {
    std::fs::write("/proc/self/clear_refs", "5").expect("writable /proc/self/clear_refs");
}

fn data_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("ANYMO_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"));
    dir.join("manifest.tsv").is_file().then_some(dir)
}

fn main() {
    let Some(dir) = data_dir() else {
        eprintln!("skipping: no data at ../shared/data (set ANYMO_DATA)");
        return;
    };
    let longest = std::fs::read_dir(dir.join("lafan1"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .max_by_key(|p| std::fs::metadata(p).unwrap().len())
        .unwrap();
    let source = bvh::read_path(&longest, ReadOptions::default()).unwrap();
    let path = std::env::temp_dir().join(format!("anymo-bvh-memory-{}.bvh", std::process::id()));
    {
        let mut text = Vec::new();
        bvh::write(&source, &mut text).unwrap();
        let per_frame = text.len() as u64 / source.frames() as u64;
        let frames = (TARGET_BYTES / per_frame) as usize;
        let values: Vec<f32> =
            source.values().iter().copied().cycle().take(frames * source.skeleton().channel_count()).collect();
        let big = Bvh::new(source.skeleton().clone(), source.frame_time(), frames, values).unwrap();
        bvh::write_path(&big, &path).unwrap();
    }
    drop(source);
    let size = std::fs::metadata(&path).unwrap().len();

    reset_peak();
    let before = peak_rss_kib();
    let start = std::time::Instant::now();
    let clip = bvh::read_path(&path, ReadOptions::default()).unwrap();
    let seconds = start.elapsed().as_secs_f64();
    let peak = peak_rss_kib();
    std::fs::remove_file(&path).unwrap();

    let file_mb = size as f64 / 1e6;
    let values_mb = (clip.values().len() * 4) as f64 / 1e6;
    let grew_mb = (peak.saturating_sub(before) * 1024) as f64 / 1e6;
    println!("file: {file_mb:.1} MB, {} frames x {} channels", clip.frames(), clip.skeleton().channel_count());
    println!("parsed values: {values_mb:.1} MB (f32)");
    println!(
        "peak memory added while reading: {grew_mb:.1} MB = {:.2}x the file, {:.2}x the values",
        grew_mb / file_mb,
        grew_mb / values_mb
    );
    println!("read in {seconds:.2} s ({:.0} MB/s from disk cache)", file_mb / seconds);
}
