//! Prometheus metrics at `GET /metrics`: requests by route, method and status, their latency,
//! what was generated, how many requests wait for the model workers, and how many query texts
//! search embeds per batch.

use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::Registry;

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct RequestLabels {
    route: String,
    method: String,
    status: u16,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct RouteLabels {
    route: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct KindLabels {
    kind: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct QueueLabels {
    queue: String,
}

/// The server's metrics.
pub struct Metrics {
    registry: Registry,
    requests: Family<RequestLabels, Counter>,
    latency: Family<RouteLabels, Histogram>,
    generated: Family<KindLabels, Counter>,
    waiting: Family<QueueLabels, Gauge>,
    search_batch_texts: Histogram,
}

impl Default for Metrics {
    fn default() -> Metrics {
        let mut registry = Registry::with_prefix("anymo");
        let requests = Family::<RequestLabels, Counter>::default();
        registry.register("http_requests", "HTTP requests answered, by route, method and status", requests.clone());
        let latency = Family::<RouteLabels, Histogram>::new_with_constructor(|| {
            Histogram::new(exponential_buckets(0.0005, 2.0, 18))
        });
        registry.register("http_request_duration_seconds", "Time to answer an HTTP request, by route", latency.clone());
        let generated = Family::<KindLabels, Counter>::default();
        registry.register("motions_generated", "Motions made, by kind of request", generated.clone());
        let waiting = Family::<QueueLabels, Gauge>::default();
        registry.register("queue_waiting", "Requests waiting for a model worker, by queue", waiting.clone());
        let search_batch_texts = Histogram::new(exponential_buckets(1.0, 2.0, 7));
        registry.register(
            "search_batch_texts",
            "Query texts embedded together in one batch of the sentence encoder",
            search_batch_texts.clone(),
        );
        Metrics { registry, requests, latency, generated, waiting, search_batch_texts }
    }
}

impl Metrics {
    /// Counts an answered request.
    pub fn request(&self, route: &str, method: &str, status: u16, seconds: f64) {
        let labels = RequestLabels { route: route.to_string(), method: method.to_string(), status };
        self.requests.get_or_create(&labels).inc();
        self.latency.get_or_create(&RouteLabels { route: route.to_string() }).observe(seconds);
    }

    /// The histogram of texts per search embedding batch, for the search models' thread.
    pub fn search_batch_texts(&self) -> Histogram {
        self.search_batch_texts.clone()
    }

    /// Counts motions made by a kind of request.
    pub fn generated(&self, kind: &str, motions: usize) {
        self.generated.get_or_create(&KindLabels { kind: kind.to_string() }).inc_by(motions as u64);
    }

    /// The metrics in Prometheus' text format, with the queues' current depths.
    pub fn render(&self, queues: &[(&str, usize)]) -> String {
        for (queue, waiting) in queues {
            self.waiting.get_or_create(&QueueLabels { queue: queue.to_string() }).set(*waiting as i64);
        }
        let mut out = String::new();
        prometheus_client::encoding::text::encode(&mut out, &self.registry).expect("writing to a string");
        out
    }
}
