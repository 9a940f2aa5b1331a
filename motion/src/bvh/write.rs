//! The BVH writer. Every number is written in the shortest decimal form that reads back to the
//! same f32, so a written file parses to identical values, and writing it again gives the same
//! bytes.

use super::Bvh;
use crate::skeleton::Skeleton;
use glam::Vec3;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::Path;

/// Writes `bvh` as BVH text (tab-indented hierarchy, one frame per line).
pub fn write<W: Write>(bvh: &Bvh, mut out: W) -> io::Result<()> {
    let mut text = String::with_capacity(4096);
    write_hierarchy(bvh.skeleton(), &mut text);
    text.push_str("MOTION\n");
    text.push_str(&format!("Frames: {}\n", bvh.frames()));
    text.push_str(&format!("Frame Time: {}\n", bvh.frame_time()));
    out.write_all(text.as_bytes())?;

    let channels = bvh.skeleton().channel_count();
    let mut row = Vec::with_capacity(channels * 12 + 1);
    let mut block = Vec::with_capacity(1 << 16);
    let mut number = ryu::Buffer::new();
    for frame in 0..bvh.frames() {
        row.clear();
        for (i, &v) in bvh.frame(frame).iter().enumerate() {
            if i > 0 {
                row.push(b' ');
            }
            push_f32(&mut row, &mut number, v);
        }
        row.push(b'\n');
        block.extend_from_slice(&row);
        if block.len() >= 1 << 16 {
            out.write_all(&block)?;
            block.clear();
        }
    }
    out.write_all(&block)?;
    out.flush()
}

/// Writes `bvh` to a plain (uncompressed) file.
pub fn write_path(bvh: &Bvh, path: impl AsRef<Path>) -> io::Result<()> {
    write(bvh, BufWriter::new(File::create(path)?))
}

fn write_hierarchy(skeleton: &Skeleton, text: &mut String) {
    text.push_str("HIERARCHY\n");
    let depths = skeleton.depths();
    let joints = skeleton.joints();
    let mut number = ryu::Buffer::new();
    let mut vec = |text: &mut String, v: Vec3| {
        let mut bytes = Vec::new();
        for (i, c) in v.to_array().into_iter().enumerate() {
            if i > 0 {
                bytes.push(b' ');
            }
            push_f32(&mut bytes, &mut number, c);
        }
        text.push_str(std::str::from_utf8(&bytes).expect("numbers are ASCII"));
    };
    for (index, joint) in joints.iter().enumerate() {
        let depth = depths[index];
        let pad = "\t".repeat(depth);
        let keyword = if index == 0 { "ROOT" } else { "JOINT" };
        text.push_str(&format!("{pad}{keyword} {}\n{pad}{{\n{pad}\tOFFSET ", joint.name));
        vec(text, joint.offset);
        text.push('\n');
        if !joint.channels.is_empty() {
            text.push_str(&format!("{pad}\tCHANNELS {}", joint.channels.len()));
            for c in joint.channels.as_slice() {
                text.push_str(&format!(" {c}"));
            }
            text.push('\n');
        }
        if let Some(end) = joint.end_site {
            text.push_str(&format!("{pad}\tEnd Site\n{pad}\t{{\n{pad}\t\tOFFSET "));
            vec(text, end);
            text.push_str(&format!("\n{pad}\t}}\n"));
        }
        // Close this joint and every ancestor whose subtree ends here.
        let next_depth = joints.get(index + 1).map_or(0, |_| depths[index + 1]);
        for d in (next_depth..=depth).rev() {
            text.push_str(&"\t".repeat(d));
            text.push_str("}\n");
        }
    }
}

/// Appends the shortest decimal that parses back to exactly `v`, without an exponent
/// (some BVH readers do not accept one) and without a trailing `.0`.
fn push_f32(out: &mut Vec<u8>, number: &mut ryu::Buffer, v: f32) {
    let text = number.format_finite(v);
    if text.contains('e') {
        out.extend_from_slice(format!("{v}").as_bytes());
    } else {
        out.extend_from_slice(text.strip_suffix(".0").unwrap_or(text).as_bytes());
    }
}
