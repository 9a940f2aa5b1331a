//! Load test of `anymo serve` over loopback: concurrent clients send search and generate
//! requests for a bounded time, and the bench prints throughput, p50/p99 latency and errors.
//! The reference, measured in the same run, is the same operation called in-process (no HTTP,
//! no JSON), so the ratio is what the server itself adds.
//!
//! Run after the README's main command has filled `anymo-data` (or set `ANYMO_DATA_DIR`):
//! `cargo bench -p anymo-services --bench serve`. Every query and prompt is new text.

use anymo_models::checkpoint::Checkpoints;
use anymo_server::generation::{self, SamplingOptions};
use anymo_server::limits::Limits;
use anymo_server::motion::SkeletonSource;
use anymo_server::search::{SearchParams, search};
use anymo_server::{Server, ServerConfig};
use std::sync::Arc;
use std::time::{Duration, Instant};

const QUERIES: [&str; 6] =
    ["a horse gallops", "a person walks", "a dog jumps", "someone bows angrily", "a spider attacks", "kick"];

/// Query or prompt `k`: every one is new text, so the sentence encoder's cache never answers it.
fn text(k: usize) -> String {
    format!("{} {k}", QUERIES[k % QUERIES.len()])
}

struct Tally {
    latencies: Vec<f64>,
    errors: usize,
    elapsed: f64,
}

impl Tally {
    fn report(&mut self, name: &str, reference: f64) {
        self.latencies.sort_by(f64::total_cmp);
        let at = |q: f64| self.latencies[((self.latencies.len() as f64 - 1.0) * q).round() as usize] * 1e3;
        let ok = self.latencies.len();
        println!(
            "{name:<34} {ok:>6} ok {:>4} errors {:>8.1} req/s  p50 {:>8.2} ms  p99 {:>8.2} ms  (in-process p50 {:>7.2} ms, {:.2}x)",
            self.errors,
            ok as f64 / self.elapsed,
            at(0.5),
            at(0.99),
            reference * 1e3,
            at(0.5) / (reference * 1e3)
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

fn main() -> anyhow::Result<()> {
    let data_dir = anymo_paths::default_data_dir()?;
    let seconds: u64 = std::env::var("ANYMO_BENCH_SECONDS").ok().and_then(|s| s.parse().ok()).unwrap_or(20);
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    runtime.block_on(async move {
        let config = ServerConfig {
            addr: "127.0.0.1:0".into(),
            data_dir: data_dir.clone(),
            database_url: None,
            encoder_dir: anymo_paths::encoder_dir()?,
            embedding_cache: anymo_tokenizer::text::DEFAULT_CACHE_TEXTS,
            checkpoints: Checkpoints::Dir(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../checkpoints")),
            generator: "generator".into(),
            tokenizer: "tat".into(),
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
        println!("loopback load test, {seconds} s per row, on {} cores", std::thread::available_parallelism()?.get());

        // Reference: the operations in-process, one at a time.
        let mut reference = Vec::new();
        for k in 0..50 {
            let params = SearchParams { q: Some(text(1_000_000 + k)), ..Default::default() };
            let t = Instant::now();
            search(&state, params, None).await.map_err(|e| anyhow::anyhow!(e.message))?;
            reference.push(t.elapsed().as_secs_f64());
        }
        reference.sort_by(f64::total_cmp);
        let search_reference = reference[reference.len() / 2];
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
        let generate_reference = reference[reference.len() / 2];

        let duration = Duration::from_secs(seconds);
        for clients in [1, 8] {
            let (client, base) = (client.clone(), base.clone());
            let base_k = clients * 100_000;
            let mut tally = load(clients, duration, move |k| {
                let k = base_k + k;
                let url = format!("{base}/v1/search?q={}&limit=10", text(k).replace(' ', "%20"));
                let client = client.clone();
                async move { client.get(url).send().await.is_ok_and(|r| r.status().is_success()) }
            })
            .await;
            tally.report(&format!("search, {clients} clients"), search_reference);
        }
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
            tally.report(&format!("generate 4 s, {clients} clients"), generate_reference);
        }
        let _ = stop.send(());
        serving.await??;
        Ok(())
    })
}
