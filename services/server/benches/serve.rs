//! Load test of `anymo serve` over loopback: concurrent clients send search and generate
//! requests for a bounded time, and the bench prints throughput, p50/p99 latency and errors,
//! each against a reference measured in the same run:
//! - distinct search queries against the sentence encoder's own rate on batches of 16 new texts
//!   (in-process, no server): embedding every new query is the cost a server cannot avoid, so
//!   the ratio says how much of the encoder's rate the server keeps;
//! - a repeated query, the case the server's caches answer, against a goal of 3,000 req/s;
//! - generation against the same call in-process (no HTTP, no JSON).
//!
//! Run after the README's main command has filled the data folder (or set `ANYMO_DATA_DIR`):
//! `RAYON_NUM_THREADS=1 cargo bench --workspace --bench serve` (`ANYMO_BENCH_SECONDS` per row,
//! default 20). `RAYON_NUM_THREADS=1` is what `anymo serve` sets for itself when it is unset:
//! each model call on one thread, one worker per core.

use anymo_models::checkpoint::Checkpoints;
use anymo_server::generation::{self, SamplingOptions};
use anymo_server::limits::Limits;
use anymo_server::motion::SkeletonSource;
use anymo_server::{Server, ServerConfig};
use anymo_tokenizer::text::SentenceEncoder;
use std::sync::Arc;
use std::time::{Duration, Instant};

const QUERIES: [&str; 6] =
    ["a horse gallops", "a person walks", "a dog jumps", "someone bows angrily", "a spider attacks", "kick"];

/// Clients of the search rows: the 16 connections.
const CONNECTIONS: usize = 16;

/// Query or prompt `k`: every one is new text, so no cache answers it.
fn text(k: usize) -> String {
    format!("{} {k}", QUERIES[k % QUERIES.len()])
}

struct Tally {
    latencies: Vec<f64>,
    errors: usize,
    elapsed: f64,
}

impl Tally {
    fn rate(&self) -> f64 {
        self.latencies.len() as f64 / self.elapsed
    }

    fn at(&mut self, q: f64) -> f64 {
        self.latencies.sort_by(f64::total_cmp);
        self.latencies[((self.latencies.len() as f64 - 1.0) * q).round() as usize] * 1e3
    }

    fn report(&mut self, name: &str, against: &str) {
        let (p50, p99) = (self.at(0.5), self.at(0.99));
        println!(
            "{name:<34} {:>6} ok {:>4} errors {:>9.1} req/s  p50 {p50:>8.2} ms  p99 {p99:>8.2} ms  {against}",
            self.latencies.len(),
            self.errors,
            self.rate(),
        );
    }
}

/// `clients` loops sending `request` until `duration` has passed.
async fn load<F, Fut>(clients: usize, duration: Duration, request: F) -> Tally
where
    F: Fn(usize) -> Fut + Send + Sync + 'static,
    Fut: std::future::Future<Output = bool> + Send,
{
    let request = Arc::new(request);
    let started = Instant::now();
    let tasks: Vec<_> = (0..clients)
        .map(|c| {
            let request = request.clone();
            tokio::spawn(async move {
                let (mut latencies, mut errors, mut k) = (Vec::new(), 0, c);
                while started.elapsed() < duration {
                    let t = Instant::now();
                    if request(k).await {
                        latencies.push(t.elapsed().as_secs_f64())
                    } else {
                        errors += 1
                    }
                    k += clients;
                }
                (latencies, errors)
            })
        })
        .collect();
    let mut tally = Tally { latencies: Vec::new(), errors: 0, elapsed: 0.0 };
    for task in tasks {
        let (l, e) = task.await.expect("a client task");
        tally.latencies.extend(l);
        tally.errors += e;
    }
    tally.elapsed = started.elapsed().as_secs_f64();
    tally
}

/// The sentence encoder's own rate in texts per second, on batches of `batch` new texts, for
/// `duration`, from `encoders` side by side, each on a thread of its own (and the threads
/// candle gives it).
fn encoder_rate(encoders: &[SentenceEncoder], batch: usize, duration: Duration) -> anyhow::Result<f64> {
    std::thread::scope(|s| {
        let each: Vec<_> = encoders
            .iter()
            .enumerate()
            .map(|(t, encoder)| s.spawn(move || one_encoder_rate(encoder, batch, 50_000_000 * (t + 1), duration)))
            .collect();
        each.into_iter().map(|e| e.join().expect("an encoder thread panicked")).sum()
    })
}

/// [`encoder_rate`] in this thread, its texts numbered from `k`.
fn one_encoder_rate(encoder: &SentenceEncoder, batch: usize, mut k: usize, duration: Duration) -> anyhow::Result<f64> {
    let (started, mut texts) = (Instant::now(), 0usize);
    while started.elapsed() < duration {
        let owned: Vec<String> = (k..k + batch).map(text).collect();
        let refs: Vec<&str> = owned.iter().map(String::as_str).collect();
        encoder.encode(&refs)?;
        texts += batch;
        k += batch;
    }
    Ok(texts as f64 / started.elapsed().as_secs_f64())
}

fn main() -> anyhow::Result<()> {
    let data_dir = anymo_paths::default_data_dir()?;
    let seconds: u64 = std::env::var("ANYMO_BENCH_SECONDS").ok().and_then(|s| s.parse().ok()).unwrap_or(20);
    let duration = Duration::from_secs(seconds);
    let encoder_dir = anymo_paths::encoder_dir()?;
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    runtime.block_on(async move {
        let config = ServerConfig {
            addr: "127.0.0.1:0".into(),
            data_dir: data_dir.clone(),
            database_url: None,
            encoder_dir: encoder_dir.clone(),
            embedding_cache: anymo_tokenizer::text::DEFAULT_CACHE_TEXTS,
            checkpoints: Checkpoints::Dir(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../checkpoints")),
            generator: "generator".into(),
            tokenizer: anymo_models::checkpoint::DEFAULT_TOKENIZER.into(),
            evaluator: "evaluator".into(),
            limits: Limits { queue: 64, ..Limits::default() },
            keys: Default::default(),
            replica: "bench".into(),
            shutdown_grace: Duration::from_secs(1),
        };
        let server = Server::start(config).await?;
        let state = server.state();
        let base = format!("http://{}", server.local_addr()?);
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let serving = tokio::spawn(server.run(async {
            let _ = stopped.await;
        }));
        let client = reqwest::Client::new();
        let clips: serde_json::Value = client.get(format!("{base}/v1/health")).send().await?.json().await?;
        anyhow::ensure!(
            clips["clips"].as_i64().unwrap_or(0) > 0,
            "the store in {} is empty: run the README's main command first",
            data_dir.display()
        );
        let skeleton = client.get(format!("{base}/v1/skeletons/1/bvh")).send().await?.bytes().await?.to_vec();
        println!(
            "loopback load test, {seconds} s per row, {CONNECTIONS} connections for search, on {} cores",
            std::thread::available_parallelism()?.get()
        );
        // The index is in step with the store before anything is timed.
        let warm = format!("{base}/v1/search?q=warm&limit=10");
        anyhow::ensure!(client.get(warm).send().await?.status().is_success(), "the warm-up search failed");

        // The reference is the encoder's best batched rate here: one encoder per core side by
        // side, as the server runs them (`cargo bench --workspace --bench sentence_encoder`
        // prints it beside one encoder's rate).
        let cores = std::thread::available_parallelism()?.get();
        let encoders = (0..cores).map(|_| SentenceEncoder::load(&encoder_dir)).collect::<Result<Vec<_>, _>>()?;
        let batched = tokio::task::block_in_place(|| encoder_rate(&encoders, CONNECTIONS, duration))?;
        let lone = tokio::task::block_in_place(|| encoder_rate(&encoders[..1], 1, duration))?;
        drop(encoders);
        println!(
            "{:<34} {batched:>9.1} texts/s in batches of {CONNECTIONS}, one encoder per core; {lone:.1} texts/s one at a time",
            "sentence encoder in-process"
        );

        let search_row = |name: &str, query: fn(usize) -> String| {
            let (client, base) = (client.clone(), base.clone());
            let name = name.to_string();
            async move {
                let tally = load(CONNECTIONS, duration, move |k| {
                    let url = format!("{base}/v1/search?q={}&limit=10", query(k).replace(' ', "%20"));
                    let client = client.clone();
                    async move { client.get(url).send().await.is_ok_and(|r| r.status().is_success()) }
                })
                .await;
                (name, tally)
            }
        };
        let (name, mut distinct) = search_row("search, distinct queries", |k| text(1_000_000 + k)).await;
        let ratio = distinct.rate() / batched;
        distinct.report(&name, &format!("{ratio:.2}x the encoder's batched rate (goal >= 0.80)"));
        let (name, mut repeated) = search_row("search, one repeated query", |_| text(7)).await;
        let goal = if repeated.rate() >= 3_000.0 { "met" } else { "not met" };
        repeated.report(&name, &format!("goal >= 3,000 req/s: {goal}"));

        // Generation against the same call in-process, one at a time.
        let mut reference = Vec::new();
        for k in 0..5 {
            let sampling = SamplingOptions { seed: Some(k), ..Default::default() };
            let t = Instant::now();
            generation::generate(
                &state,
                "a person walks".into(),
                Some(4.0),
                SkeletonSource::Bvh(skeleton.clone()),
                sampling,
            )
            .await
            .map_err(|e| anyhow::anyhow!(e.message))?;
            reference.push(t.elapsed().as_secs_f64());
        }
        reference.sort_by(f64::total_cmp);
        let generate_reference = reference[reference.len() / 2] * 1e3;
        for clients in [1, 4] {
            let base_k = clients * 100_000;
            let (client, base, skeleton) = (client.clone(), base.clone(), skeleton.clone());
            let mut tally = load(clients, duration, move |k| {
                let k = base_k + k;
                let form = reqwest::multipart::Form::new()
                    .text("prompt", text(k))
                    .text("seconds", "4")
                    .text("seed", k.to_string())
                    .part("skeleton", reqwest::multipart::Part::bytes(skeleton.clone()).file_name("s.bvh"));
                let request = client.post(format!("{base}/v1/generate")).multipart(form);
                async move { request.send().await.is_ok_and(|r| r.status().is_success()) }
            })
            .await;
            let p50 = tally.at(0.5);
            tally.report(
                &format!("generate 4 s, {clients} clients"),
                &format!("p50 {:.2}x the in-process call ({generate_reference:.2} ms)", p50 / generate_reference),
            );
        }
        let _ = stop.send(());
        serving.await??;
        Ok(())
    })
}
