//! Prompt -> BVH latency with the shipped checkpoints: sentence embedding, masked generation,
//! residual layers, decoding onto the skeleton, the cleanup and the quality report (with and
//! without the prompt scored by the evaluator), restoring it to the user's units and writing the
//! BVH text, for 4 s of motion on a 22-joint and a 50-joint skeleton. The target is prepared once
//! (a server caches it per skeleton); every request embeds its prompt anew. Each thread count runs
//! in a child process, since candle reads RAYON_NUM_THREADS when it starts a matmul.
//!
//! `cargo bench -p anymo-models --bench generate` (needs ../shared/data and `tools/setup.sh`).

use anymo_generator::Request;
use anymo_generator::sampling::Sampling;
use anymo_models::checkpoint::Checkpoint;
use anymo_models::studio::Studio;
use anymo_motion::bvh;
use anymo_motion::motion::Motion;
use anymo_tokenizer::text::{CachedEncoder, SentenceEncoder};
use std::path::{Path, PathBuf};
use std::time::Instant;

const PROMPTS: [&str; 4] =
    ["a person walks forward", "a dog jumps over something", "someone waves with the right hand", "a horse gallops"];
const RUNS: usize = 40;

fn data() -> Option<PathBuf> {
    let dir = std::env::var_os("ANYMO_DATA")
        .map_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"), PathBuf::from);
    dir.join("manifest.tsv").is_file().then_some(dir)
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

fn child(data: &Path, threads: &str) {
    let encoder = SentenceEncoder::load(anymo_paths::encoder_dir().expect("a home folder or ANYMO_MODELS"))
        .expect("bash tools/setup.sh --models");
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../checkpoints");
    let mut studio = Studio::load(
        &Checkpoint::in_dir(&shipped, "generator"),
        Some(&Checkpoint::in_dir(&shipped, "evaluator")),
        CachedEncoder::new(encoder),
    )
    .expect("the shipped generator");
    for file in
        ["bandai/dataset-1/dataset-1_walk_normal_001.bvh.gz", "quaternius/bvh/animals_pack/Husky__Attack.bvh.gz"]
    {
        let clip = bvh::read_path(data.join(file), bvh::ReadOptions::default()).expect("a corpus clip");
        let target = studio.target(&Motion::from_bvh(&clip)).expect("an animatable skeleton");
        let steps = studio.steps(4.0).expect("4 s is within the limit");
        for scoring in [true, false] {
            studio.set_scoring(scoring);
            let mut times = Vec::with_capacity(RUNS);
            for run in 0..RUNS + 3 {
                let started = Instant::now();
                let sampling = Sampling::default();
                let request = Request { steps: Some(steps), samples: 1, sampling, seed: run as u64 };
                let prompt = PROMPTS[run % PROMPTS.len()];
                let samples = studio.generate(prompt, &target, &request).expect("generation");
                let made = studio.render(samples, [0.0; 3], Some(120), &target, prompt).expect("decoding").remove(0);
                let mut out = Vec::new();
                bvh::write(&made.motion.to_bvh(), &mut out).expect("writing BVH");
                if run >= 3 {
                    times.push(started.elapsed().as_secs_f64() * 1000.0);
                }
            }
            times.sort_by(f64::total_cmp);
            println!(
                "prompt -> BVH, 4 s of motion, {} joints, {threads} thread(s), {}: p50 {:.1} ms, p95 {:.1} ms over {RUNS} \
                 requests; {:.1}x faster than real time at p50",
                clip.skeleton().len(),
                if scoring { "report with the prompt score" } else { "report without the prompt score (--no-score)" },
                percentile(&times, 0.5),
                percentile(&times, 0.95),
                4000.0 / percentile(&times, 0.5)
            );
        }
    }
}

fn main() {
    let Some(data) = data() else {
        eprintln!("skipping: no data at ../shared/data (set ANYMO_DATA)");
        return;
    };
    if let Ok(threads) = std::env::var("ANYMO_BENCH_CHILD") {
        child(&data, &threads);
        return;
    }
    let exe = std::env::current_exe().expect("the bench's own path");
    for threads in ["1", "2"] {
        let status = std::process::Command::new(&exe)
            .env("ANYMO_BENCH_CHILD", threads)
            .env("RAYON_NUM_THREADS", threads)
            .status()
            .expect("running the bench child");
        assert!(status.success(), "the {threads}-thread run failed");
    }
}
