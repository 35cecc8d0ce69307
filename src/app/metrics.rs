//! The Prometheus registry: requests by route and status, request latency histograms by route,
//! jobs by state (read from the store at scrape time), solver durations by job kind. The HTTP
//! layer counts requests into it and serves it; the job workers time their solver runs.

use prometheus::{Encoder, HistogramOpts, HistogramVec, IntCounterVec, IntGaugeVec, Opts, Registry, TextEncoder};

pub struct Metrics {
    registry: Registry,
    pub requests: IntCounterVec,
    pub latency: HistogramVec,
    pub jobs: IntGaugeVec,
    pub solver: HistogramVec,
}

impl Default for Metrics {
    fn default() -> Self {
        Self::new()
    }
}

impl Metrics {
    pub fn new() -> Self {
        let registry = Registry::new();
        let requests = IntCounterVec::new(
            Opts::new("robocal_http_requests_total", "HTTP requests by route, method and status"),
            &["route", "method", "status"],
        )
        .expect("metric");
        let latency = HistogramVec::new(
            HistogramOpts::new("robocal_http_request_duration_seconds", "HTTP request latency by route")
                .buckets(vec![0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0]),
            &["route", "method"],
        )
        .expect("metric");
        let jobs =
            IntGaugeVec::new(Opts::new("robocal_jobs", "Jobs in the store by state"), &["state"]).expect("metric");
        let solver = HistogramVec::new(
            HistogramOpts::new("robocal_solver_duration_seconds", "Time in the solver by job kind and outcome")
                .buckets(vec![0.001, 0.005, 0.01, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0, 300.0]),
            &["kind", "outcome"],
        )
        .expect("metric");
        for c in [
            Box::new(requests.clone()) as Box<dyn prometheus::core::Collector>,
            Box::new(latency.clone()),
            Box::new(jobs.clone()),
            Box::new(solver.clone()),
        ] {
            registry.register(c).expect("distinct metric names");
        }
        Metrics { registry, requests, latency, jobs, solver }
    }

    /// The text exposition format.
    pub fn render(&self) -> String {
        let mut buf = Vec::new();
        TextEncoder::new().encode(&self.registry.gather(), &mut buf).expect("text encoding");
        String::from_utf8(buf).expect("the text format is UTF-8")
    }
}
