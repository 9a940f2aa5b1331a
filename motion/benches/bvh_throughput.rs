//! BVH parse and write throughput on the shared corpus, side by side in one run with the
//! `bvh_anim` crate and (when installed, see `tools/setup-bench.sh`) the Python libraries
//! pybvh, bvhio and bvh. Every reader gets the same decompressed bytes; the figure is MB of BVH
//! text per second on one core, best of three passes, and how many files each could not read.
//!
//! `cargo bench -p anymo-tokenizer --bench bvh_throughput` (set ANYMO_DATA to the data folder if
//! it is not at ../shared/data).

use anymo_motion::bvh::{self, ReadOptions};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

struct Figure {
    reader: String,
    bytes: usize,
    seconds: f64,
    failed: usize,
    files: usize,
}

impl Figure {
    fn mb_per_s(&self) -> f64 {
        self.bytes as f64 / 1e6 / self.seconds
    }
}

fn data_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("ANYMO_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"));
    dir.join("manifest.tsv").is_file().then_some(dir)
}

fn corpus(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.to_string_lossy().ends_with(".bvh.gz") {
                let mut text = Vec::new();
                flate2::read::MultiGzDecoder::new(std::fs::File::open(&path).unwrap()).read_to_end(&mut text).unwrap();
                out.push((path, text));
            }
        }
    }
    out.sort();
    out
}

/// Best of three timed passes of `run` over every file; `run` says whether the file was read.
fn best_of_three(files: &[(PathBuf, Vec<u8>)], mut run: impl FnMut(&[u8]) -> bool) -> (Duration, usize, usize) {
    let mut best = Duration::MAX;
    let (mut bytes, mut failed) = (0, 0);
    for _ in 0..3 {
        let (mut b, mut f) = (0, 0);
        let start = Instant::now();
        for (_, text) in files {
            if run(text) {
                b += text.len();
            } else {
                f += 1;
            }
        }
        best = best.min(start.elapsed());
        (bytes, failed) = (b, f);
    }
    (best, bytes, failed)
}

fn main() {
    let Some(dir) = data_dir() else {
        eprintln!("skipping: no data at ../shared/data (set ANYMO_DATA)");
        return;
    };
    let files = corpus(&dir);
    let total: usize = files.iter().map(|(_, t)| t.len()).sum();
    println!(
        "corpus: {} files, {:.1} MB of BVH text (decompressed in memory), 1 thread",
        files.len(),
        total as f64 / 1e6
    );
    let mut figures = Vec::new();

    let (time, bytes, failed) =
        best_of_three(&files, |text| std::hint::black_box(bvh::read(text, ReadOptions::default())).is_ok());
    figures.push(Figure {
        reader: "anymo read".into(),
        bytes,
        seconds: time.as_secs_f64(),
        failed,
        files: files.len(),
    });

    let parsed: Vec<_> = files.iter().map(|(_, t)| bvh::read(t.as_slice(), ReadOptions::default()).unwrap()).collect();
    let mut out = Vec::with_capacity(64 << 20);
    let mut best = Duration::MAX;
    let mut written = 0;
    for _ in 0..3 {
        written = 0;
        let start = Instant::now();
        for clip in &parsed {
            out.clear();
            bvh::write(clip, &mut out).unwrap();
            written += out.len();
        }
        best = best.min(start.elapsed());
    }
    figures.push(Figure {
        reader: "anymo write".into(),
        bytes: written,
        seconds: best.as_secs_f64(),
        failed: 0,
        files: files.len(),
    });

    let (time, bytes, failed) = best_of_three(&files, |text| std::hint::black_box(bvh_anim::from_bytes(text)).is_ok());
    figures.push(Figure {
        reader: "bvh_anim read".into(),
        bytes,
        seconds: time.as_secs_f64(),
        failed,
        files: files.len(),
    });
    let anim: Vec<_> = files.iter().filter_map(|(_, t)| bvh_anim::from_bytes(t).ok()).collect();
    let start = Instant::now();
    let mut anim_written = 0;
    for clip in &anim {
        anim_written += clip.to_bstring().len();
    }
    figures.push(Figure {
        reader: "bvh_anim write".into(),
        bytes: anim_written,
        seconds: start.elapsed().as_secs_f64(),
        failed: files.len() - anim.len(),
        files: files.len(),
    });

    figures.extend(python_peers(&files));

    let anymo_read = figures[0].mb_per_s();
    println!("{:<16} {:>10} {:>14} {:>22}", "reader", "MB/s", "files failed", "anymo read / this");
    for f in &figures {
        println!(
            "{:<16} {:>10.1} {:>9} / {:<4} {:>18.1}x",
            f.reader,
            f.mb_per_s(),
            f.failed,
            f.files,
            anymo_read / f.mb_per_s()
        );
    }
}

/// Runs `tools/bench_python_bvh.py` over plain copies of the corpus in a temporary folder.
fn python_peers(files: &[(PathBuf, Vec<u8>)]) -> Vec<Figure> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tools/bench_python_bvh.py");
    let tmp = std::env::temp_dir().join(format!("anymo-bench-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    for (i, (_, text)) in files.iter().enumerate() {
        std::fs::write(tmp.join(format!("{i:05}.bvh")), text).unwrap();
    }
    let output = Command::new("python3").arg(&script).arg(&tmp).output();
    std::fs::remove_dir_all(&tmp).unwrap();
    let output = match output {
        Ok(o) if o.status.success() => o,
        Ok(o) => {
            eprintln!("python peers did not run: {}", String::from_utf8_lossy(&o.stderr));
            return Vec::new();
        }
        Err(e) => {
            eprintln!("python peers did not run: {e}");
            return Vec::new();
        }
    };
    // One line per library: name, bytes read, seconds, files failed, files.
    String::from_utf8_lossy(&output.stdout)
        .lines()
        .filter_map(|line| {
            let cols: Vec<&str> = line.split('\t').collect();
            if cols.len() != 5 {
                eprintln!("{line}");
                return None;
            }
            Some(Figure {
                reader: cols[0].to_string(),
                bytes: cols[1].parse().ok()?,
                seconds: cols[2].parse().ok()?,
                failed: cols[3].parse().ok()?,
                files: cols[4].parse().ok()?,
            })
        })
        .collect()
}
