//! The sentence encoder's rate on short queries, in texts per second, one at a time, in a batch
//! of 4 (about what a search server gathers under load) and of 16 (when 16 clients ask
//! together), and its achieved FLOP/s against this machine's dense matmul rate measured in the
//! same run with the same threads. The FLOPs counted are the encoder's matmuls (projections,
//! feed-forward and attention, on the batch's padded tokens); element-wise work is not counted,
//! so the figure is a lower bound on the work done.
//!
//! `cargo bench --workspace --bench sentence_encoder` after `bash tools/setup.sh --models`
//! (RAYON_NUM_THREADS sets the threads; `anymo serve` runs each model call on one, the other
//! commands on every core).

use anymo_tokenizer::nn::flops;
use anymo_tokenizer::text::{EMBEDDING_DIM, SentenceEncoder};
use std::time::{Duration, Instant};

/// Queries as search users type them; a number makes every text new.
const QUERIES: [&str; 6] =
    ["a horse gallops", "a person walks", "a dog jumps", "someone bows angrily", "a spider attacks", "kick"];

/// all-MiniLM-L6-v2's layers and feed-forward width.
const LAYERS: usize = 6;
const FEED_FORWARD: usize = 1536;

/// Matmul FLOPs of one forward pass over `texts` padded to `tokens` tokens each.
fn encoder_flops(texts: usize, tokens: usize) -> f64 {
    let rows = (texts * tokens) as f64;
    let d = EMBEDDING_DIM as f64;
    let projections = 4.0 * d * d + 2.0 * d * FEED_FORWARD as f64;
    let attention = 2.0 * tokens as f64 * d;
    2.0 * LAYERS as f64 * rows * (projections + attention)
}

/// Texts per second and FLOP/s over batches of `batch` new texts for 5 seconds; `tokens` gives
/// the length a batch is padded to.
fn rate(encoder: &SentenceEncoder, tokens: &dyn Fn(&[&str]) -> usize, batch: usize) -> (f64, f64) {
    let duration = Duration::from_secs(5);
    let (mut texts, mut flops, mut k) = (0usize, 0f64, 0usize);
    let started = Instant::now();
    while started.elapsed() < duration {
        let owned: Vec<String> = (k..k + batch).map(|i| format!("{} {i}", QUERIES[i % QUERIES.len()])).collect();
        let refs: Vec<&str> = owned.iter().map(String::as_str).collect();
        encoder.encode(&refs).unwrap();
        flops += encoder_flops(batch, tokens(&refs));
        texts += batch;
        k += batch;
    }
    let seconds = started.elapsed().as_secs_f64();
    (texts as f64 / seconds, flops / seconds)
}

fn main() {
    let Some(dir) = anymo_paths::encoder_dir().ok().filter(|d| d.join("model.safetensors").is_file()) else {
        eprintln!("skipping: no sentence encoder (run `bash tools/setup.sh --models`)");
        return;
    };
    let threads = std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "all cores".into());
    let encoder = SentenceEncoder::load(&dir).unwrap();
    // The encoder pads a batch to its longest text.
    let tokenizer = tokenizers::Tokenizer::from_file(dir.join("tokenizer.json")).unwrap();
    let tokens = |texts: &[&str]| {
        let encodings = tokenizer.encode_batch(texts.to_vec(), true).unwrap();
        encodings.iter().map(|e| e.get_attention_mask().iter().filter(|&&m| m == 1).count()).max().unwrap_or(0)
    };
    encoder.encode(&["warm up"]).unwrap();
    let reference = flops::dense_matmul_rate().unwrap();
    println!("threads: {threads}; queries like \"{} 123\"", QUERIES[0]);
    for batch in [1, 4, 16] {
        let (texts, flops) = rate(&encoder, &tokens, batch);
        println!(
            "batch {batch:>2}: {texts:>7.1} texts/s, {:>6.1} GFLOP/s (matmuls), {:>5.1}% of the matmul rate",
            flops / 1e9,
            100.0 * flops / reference
        );
    }
    // One encoder per core, each on its own thread and batches: what a server with a models'
    // thread per core gets (its matmuls then run on one thread each: RAYON_NUM_THREADS=1).
    // Batches of 8 are the most that 16 clients, one query each in flight, give each of two
    // threads at once.
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    let encoders: Vec<SentenceEncoder> = (0..cores).map(|_| SentenceEncoder::load(&dir).unwrap()).collect();
    for batch in [8, 16] {
        let side_by_side: Vec<(f64, f64)> = std::thread::scope(|s| {
            let workers: Vec<_> = encoders.iter().map(|e| s.spawn(|| rate(e, &tokens, batch))).collect();
            workers.into_iter().map(|w| w.join().unwrap()).collect()
        });
        let (texts, flops) = side_by_side.iter().fold((0.0, 0.0), |(t, f), (a, b)| (t + a, f + b));
        println!(
            "batch {batch:>2} on {cores} threads side by side: {texts:>7.1} texts/s, {:>6.1} GFLOP/s (matmuls), {:>5.1}% of the matmul rate",
            flops / 1e9,
            100.0 * flops / reference
        );
    }
    println!("dense 1024x1024 f32 matmul, same run: {:.1} GFLOP/s", reference / 1e9);
}
