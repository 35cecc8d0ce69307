//! Load generator for a running `robocal serve` (issue 16, item 7), driven by
//! `scripts/load_test.sh [seconds] [clients]`.
//!
//! `clients` concurrent clients, each on its own keep-alive HTTP/1.1 connection, for `seconds`:
//! measurement batches (100 measurements, each batch with its own `Idempotency-Key`, retried with
//! the same key after a transport error), compensation requests (10 targets against the active
//! parameter set), and history reads (`GET /v1/robots/{id}/parameter-sets`, `GET /v1/jobs`), while
//! identification jobs are submitted (at most one every `--job-every-ms`) and run. Afterwards it
//! waits for the job queue to drain and checks against what the clients sent: zero errors, every
//! session's measurement count equal to the acknowledged batches' (nothing lost, nothing
//! duplicated), every job ended. It prints p50 / p99 / max per endpoint and exits 1 on any
//! failed check.
//!
//! `--slowloris N` adds N hostile connections for the same time: each sends a request line and
//! then one header line every `--slow-every-ms` (default 2000), never the blank line that ends the
//! headers, and connects again when the server closes it — a slowloris attack. It reports how
//! long the server let them hold a connection (its header timeout), while the table shows what
//! they cost the other clients; a connection held longer than `--slow-limit-s` (default 15: the
//! server's 10 s header timeout and a slow-loris period) fails the run.
//!
//! ```text
//! cargo run --release --example load -- --url http://127.0.0.1:8080 --seconds 60 --clients 64 [--slowloris 500]
//! ```

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use axum::http::{Method, Request, StatusCode, header};
use http_body_util::{BodyExt, Full};
use hyper::body::Bytes;
use hyper_util::rt::TokioIo;
use rand::{Rng, SeedableRng};
use robocal::domain::cell::CellFile;
use robocal::sim::simulate::{SimulateOptions, simulate};
use serde_json::{Value, json};
use tokio::sync::Mutex;

struct Args {
    url: String,
    seconds: u64,
    clients: usize,
    batch: usize,
    job_every: Duration,
    slowloris: usize,
    slow_every: Duration,
    slow_limit: Duration,
}

fn args() -> Args {
    let mut a = Args {
        url: "http://127.0.0.1:8080".into(),
        seconds: 60,
        clients: 64,
        batch: 100,
        job_every: Duration::from_millis(2000),
        slowloris: 0,
        slow_every: Duration::from_millis(2000),
        slow_limit: Duration::from_secs(15),
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let v = it.next().unwrap_or_else(|| die(&format!("{k} needs a value")));
        let num = |v: &str| v.parse::<u64>().unwrap_or_else(|_| die(&format!("{k}: '{v}' is not a whole number")));
        match k.as_str() {
            "--url" => a.url = v,
            "--seconds" => a.seconds = num(&v),
            "--clients" => a.clients = num(&v).max(1) as usize,
            "--batch" => a.batch = num(&v).clamp(1, 10_000) as usize,
            "--job-every-ms" => a.job_every = Duration::from_millis(num(&v)),
            "--slowloris" => a.slowloris = num(&v) as usize,
            "--slow-every-ms" => a.slow_every = Duration::from_millis(num(&v).max(1)),
            "--slow-limit-s" => a.slow_limit = Duration::from_secs(num(&v)),
            _ => die(&format!(
                "unknown option {k} (--url, --seconds, --clients, --batch, --job-every-ms, --slowloris, --slow-every-ms, --slow-limit-s)"
            )),
        }
    }
    a
}

fn die(msg: &str) -> ! {
    eprintln!("error: {msg}");
    std::process::exit(2)
}

/// One keep-alive HTTP/1.1 connection; reconnects after a transport error.
struct Conn {
    addr: String,
    sender: Option<hyper::client::conn::http1::SendRequest<Full<Bytes>>>,
}

struct Reply {
    status: StatusCode,
    body: Bytes,
    headers: axum::http::HeaderMap,
}

impl Reply {
    fn json(&self) -> Value {
        serde_json::from_slice(&self.body).unwrap_or(Value::Null)
    }
}

impl Conn {
    fn new(url: &str) -> Conn {
        let addr = url.strip_prefix("http://").unwrap_or(url).trim_end_matches('/').to_string();
        Conn { addr, sender: None }
    }

    async fn send(
        &mut self,
        method: Method,
        path: &str,
        body: Option<&[u8]>,
        key: Option<&str>,
    ) -> Result<Reply, String> {
        if self.sender.as_ref().is_none_or(|s| s.is_closed()) {
            let stream = tokio::net::TcpStream::connect(&self.addr).await.map_err(|e| format!("connect: {e}"))?;
            let _ = stream.set_nodelay(true);
            let (sender, conn) =
                hyper::client::conn::http1::handshake(TokioIo::new(stream)).await.map_err(|e| e.to_string())?;
            tokio::spawn(async move {
                let _ = conn.await;
            });
            self.sender = Some(sender);
        }
        let sender = self.sender.as_mut().expect("connected");
        sender.ready().await.map_err(|e| format!("connection: {e}"))?;
        let mut req = Request::builder().method(method).uri(path).header(header::HOST, self.addr.as_str());
        if body.is_some() {
            req = req.header(header::CONTENT_TYPE, "application/json");
        }
        if let Some(k) = key {
            req = req.header("idempotency-key", k);
        }
        let req = req.body(Full::new(Bytes::copy_from_slice(body.unwrap_or_default()))).map_err(|e| e.to_string())?;
        let res = match sender.send_request(req).await {
            Ok(r) => r,
            Err(e) => {
                self.sender = None;
                return Err(format!("request: {e}"));
            }
        };
        let status = res.status();
        let headers = res.headers().clone();
        let body = res.into_body().collect().await.map_err(|e| format!("body: {e}"))?.to_bytes();
        Ok(Reply { status, body, headers })
    }
}

/// Latencies and errors per endpoint.
#[derive(Default)]
struct Stats {
    lat: BTreeMap<&'static str, Vec<Duration>>,
    errors: BTreeMap<&'static str, Vec<String>>,
    retries: u64,
}

impl Stats {
    fn merge(&mut self, o: Stats) {
        for (k, v) in o.lat {
            self.lat.entry(k).or_default().extend(v);
        }
        for (k, v) in o.errors {
            self.errors.entry(k).or_default().extend(v);
        }
        self.retries += o.retries;
    }
}

struct Shared {
    robot: String,
    id_session: String,
    set_id: String,
    batch_body: Vec<u8>,
    deadline: Instant,
    job_every: Duration,
    last_job: Mutex<Instant>,
    jobs: Mutex<Vec<String>>,
    key_seq: AtomicU64,
}

const BATCH: &str = "POST /v1/sessions/{id}/measurements";
const COMPENSATE: &str = "POST /v1/robots/{id}/compensate";
const SETS: &str = "GET /v1/robots/{id}/parameter-sets";
const JOBS: &str = "GET /v1/jobs";
const IDENTIFY: &str = "POST /v1/robots/{id}/identifications";

fn targets() -> Value {
    let mut t = Vec::new();
    for i in 0..5 {
        let f = i as f64;
        t.push(json!({"id": format!("p{i}"), "position_mm": [300.0 + 10.0 * f, -50.0 + 20.0 * f, 300.0], "rotation_deg": [0, 180, 0], "cfx": 0}));
        t.push(json!({"id": format!("j{i}"), "joints_deg": [5.0 * f, 20.0, -10.0, 0.0, 45.0 + f, 0.0]}));
    }
    Value::Array(t)
}

/// One client: its own session, its own connection; returns its stats and the measurements its
/// acknowledged batches hold.
async fn client(url: String, sh: Arc<Shared>, session: String, seed: u64) -> (Stats, u64) {
    let mut c = Conn::new(&url);
    let mut st = Stats::default();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut acknowledged = 0u64;
    let compensate = serde_json::to_vec(&json!({"targets": targets(), "parameter_set_id": sh.set_id,
        "allow_unvalidated": true, "allow_outside_envelope": true}))
    .unwrap();
    let identify = serde_json::to_vec(&json!({"sessions": [sh.id_session]})).unwrap();
    while Instant::now() < sh.deadline {
        let roll: f64 = rng.random();
        let (ep, method, path, body, key): (&'static str, Method, String, Option<&[u8]>, Option<String>) =
            if roll < 0.02 && {
                let mut last = sh.last_job.lock().await;
                let due = last.elapsed() >= sh.job_every;
                if due {
                    *last = Instant::now();
                }
                due
            } {
                (IDENTIFY, Method::POST, format!("/v1/robots/{}/identifications", sh.robot), Some(&identify), None)
            } else if roll < 0.40 {
                let key = format!("load-{}", sh.key_seq.fetch_add(1, Ordering::Relaxed));
                (BATCH, Method::POST, format!("/v1/sessions/{session}/measurements"), Some(&sh.batch_body), Some(key))
            } else if roll < 0.70 {
                (COMPENSATE, Method::POST, format!("/v1/robots/{}/compensate", sh.robot), Some(&compensate), None)
            } else if roll < 0.85 {
                (SETS, Method::GET, format!("/v1/robots/{}/parameter-sets", sh.robot), None, None)
            } else {
                (JOBS, Method::GET, "/v1/jobs?limit=20".to_string(), None, None)
            };
        let t = Instant::now();
        // Only a keyed upload is retried after a transport error (the key makes it safe); the
        // others count as errors at once.
        let mut tries = 0;
        let r = loop {
            tries += 1;
            match c.send(method.clone(), &path, body, key.as_deref()).await {
                Err(e) if key.is_some() && tries < 4 => {
                    st.retries += 1;
                    let _ = e;
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
                r => break r,
            }
        };
        let took = t.elapsed();
        match r {
            Ok(rep) if rep.status.is_success() => {
                st.lat.entry(ep).or_default().push(took);
                if ep == BATCH {
                    acknowledged += rep.json()["count"].as_u64().unwrap_or(0);
                }
                if ep == IDENTIFY
                    && let Some(id) = rep.json()["id"].as_str()
                {
                    sh.jobs.lock().await.push(id.to_string());
                }
                if ep == SETS && rep.headers.get("x-total-count").is_none() {
                    st.errors.entry(ep).or_default().push("no X-Total-Count".into());
                }
            }
            Ok(rep) => {
                st.errors.entry(ep).or_default().push(format!("{} {}", rep.status, String::from_utf8_lossy(&rep.body)))
            }
            Err(e) => st.errors.entry(ep).or_default().push(e),
        }
    }
    (st, acknowledged)
}

/// What the slowloris connections met.
#[derive(Default)]
struct Slow {
    opened: u64,
    /// How long each connection the server closed had been open.
    closed_after: Vec<Duration>,
    /// How long the connections still open at the end had been.
    open_for: Vec<Duration>,
    /// Bytes the server sent them (an answer to headers it never received would be a bug).
    answered: u64,
}

/// One slowloris connection after another until `deadline`: a request line, then a header line
/// every `every`, never the end of the headers.
async fn slowloris(addr: String, deadline: Instant, every: Duration, seed: u64) -> Slow {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut out = Slow::default();
    // Spread the connections' starts over one period, so they do not move in step.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    tokio::time::sleep(every.mul_f64(rng.random())).await;
    while Instant::now() < deadline {
        let Ok(mut s) = tokio::net::TcpStream::connect(&addr).await else {
            tokio::time::sleep(Duration::from_millis(100)).await;
            continue;
        };
        out.opened += 1;
        let t = Instant::now();
        let mut buf = [0u8; 1024];
        let mut closed = s.write_all(b"POST /v1/robots HTTP/1.1\r\nHost: slowloris\r\n").await.is_err();
        while !closed && Instant::now() < deadline {
            tokio::select! {
                _ = tokio::time::sleep(every) => closed = s.write_all(b"X-Slow: 1\r\n").await.is_err(),
                r = s.read(&mut buf) => {
                    if let Ok(n) = r {
                        out.answered += n as u64;
                    }
                    closed = true;
                }
            }
        }
        if closed {
            out.closed_after.push(t.elapsed());
        } else {
            out.open_for.push(t.elapsed());
        }
    }
    out
}

fn pct(v: &mut [Duration], p: f64) -> f64 {
    v.sort();
    let i = ((v.len() as f64 - 1.0) * p).round() as usize;
    v[i].as_secs_f64() * 1000.0
}

async fn must(c: &mut Conn, method: Method, path: &str, body: &Value) -> Value {
    let b = serde_json::to_vec(body).unwrap();
    let r = c.send(method, path, Some(&b), None).await.unwrap_or_else(|e| die(&format!("{path}: {e}")));
    if !r.status.is_success() {
        die(&format!("{path}: {} {}", r.status, String::from_utf8_lossy(&r.body)));
    }
    r.json()
}

async fn get(c: &mut Conn, path: &str) -> Reply {
    c.send(Method::GET, path, None, None).await.unwrap_or_else(|e| die(&format!("{path}: {e}")))
}

async fn wait_job(c: &mut Conn, id: &str, within: Duration) -> Value {
    let t = Instant::now();
    loop {
        let j = get(c, &format!("/v1/jobs/{id}")).await.json();
        if matches!(j["state"].as_str(), Some("succeeded" | "failed" | "cancelled")) {
            return j;
        }
        if t.elapsed() > within {
            return j;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

#[tokio::main]
async fn main() {
    let a = args();
    let mut c = Conn::new(&a.url);

    // Set-up: a robot, an artefact, an identification session, a first identification (the
    // parameter set compensation uses), one session per client.
    let sim = simulate(&SimulateOptions { seed: 11, id_per_ball: 30, validation: 30, ..Default::default() })
        .unwrap_or_else(|e| die(&format!("simulate: {e}")));
    let cell = CellFile::from_cell(&sim.cell);
    let s0 = &cell.sessions[0];
    let tag = robocal::db::new_id();
    let robot = must(
        &mut c,
        Method::POST,
        "/v1/robots",
        &json!({"name": format!("load-{tag}"), "robot": {"preset": "irb120"},
                "base_guess": {"x_mm": 160.211, "y_mm": -255.727, "z_mm": -220.548, "a_deg": 91.603, "b_deg": 0.496, "c_deg": -1.384}}),
    )
    .await;
    let rid = robot["id"].as_str().unwrap().to_string();
    let art = must(
        &mut c,
        Method::POST,
        "/v1/artefacts",
        &json!({"name": format!("load-{tag}"), "distances_mm": {"d12": 300, "d13": 300, "d23": 300}, "ball_diameter_mm": 12.7}),
    )
    .await;
    let aid = art["id"].as_str().unwrap().to_string();
    let new_session = |name: String| {
        json!({"name": name, "purpose": s0.purpose, "instrument": s0.instrument, "tool": s0.tool,
               "artefact_id": aid, "identify_tcp": s0.identify_tcp})
    };
    let sid = must(&mut c, Method::POST, &format!("/v1/robots/{rid}/sessions"), &new_session("identification".into()))
        .await["id"]
        .as_str()
        .unwrap()
        .to_string();
    must(&mut c, Method::POST, &format!("/v1/sessions/{sid}/measurements"), &json!({"measurements": s0.measurements}))
        .await;
    let job =
        must(&mut c, Method::POST, &format!("/v1/robots/{rid}/identifications"), &json!({"sessions": [sid]})).await;
    let job = wait_job(&mut c, job["id"].as_str().unwrap(), Duration::from_secs(300)).await;
    if job["state"] != "succeeded" {
        die(&format!("the first identification did not succeed: {job}"));
    }
    let set_id = job["result"]["parameter_set_id"].as_str().unwrap().to_string();
    let mut sessions = Vec::new();
    for i in 0..a.clients {
        let s = must(&mut c, Method::POST, &format!("/v1/robots/{rid}/sessions"), &new_session(format!("client-{i}")))
            .await;
        sessions.push(s["id"].as_str().unwrap().to_string());
    }
    let batch: Vec<_> = s0.measurements.iter().cycle().take(a.batch).collect();
    let sh = Arc::new(Shared {
        robot: rid.clone(),
        id_session: sid.clone(),
        set_id,
        batch_body: serde_json::to_vec(&json!({"measurements": batch})).unwrap(),
        deadline: Instant::now() + Duration::from_secs(a.seconds),
        job_every: a.job_every,
        last_job: Mutex::new(Instant::now()),
        jobs: Mutex::new(Vec::new()),
        key_seq: AtomicU64::new(0),
    });

    eprintln!(
        "load: {} clients{} for {} s against {} …",
        a.clients,
        if a.slowloris > 0 { format!(" and {} slowloris connections", a.slowloris) } else { String::new() },
        a.seconds,
        a.url
    );
    let addr = a.url.strip_prefix("http://").unwrap_or(&a.url).trim_end_matches('/').to_string();
    let slow: Vec<_> = (0..a.slowloris)
        .map(|i| tokio::spawn(slowloris(addr.clone(), sh.deadline, a.slow_every, 1_000_000 + i as u64)))
        .collect();
    let t0 = Instant::now();
    let handles: Vec<_> = sessions
        .iter()
        .enumerate()
        .map(|(i, s)| tokio::spawn(client(a.url.clone(), sh.clone(), s.clone(), i as u64)))
        .collect();
    let mut stats = Stats::default();
    let mut sent = Vec::new();
    for h in handles {
        let (s, n) = h.await.expect("a client task");
        stats.merge(s);
        sent.push(n);
    }
    let ran = t0.elapsed();
    let mut slow_stats = Slow::default();
    for h in slow {
        let s = h.await.expect("a slowloris task");
        slow_stats.opened += s.opened;
        slow_stats.closed_after.extend(s.closed_after);
        slow_stats.open_for.extend(s.open_for);
        slow_stats.answered += s.answered;
    }

    // The queue drains: every job submitted ends.
    let t = Instant::now();
    let jobs = sh.jobs.lock().await.clone();
    let mut job_states = BTreeMap::<String, usize>::new();
    let mut failures = Vec::new();
    for id in &jobs {
        let j = wait_job(&mut c, id, Duration::from_secs(600)).await;
        let st = j["state"].as_str().unwrap_or("?").to_string();
        if st != "succeeded" {
            failures.push(format!("job {id} ended {st}: {j}"));
        }
        *job_states.entry(st).or_default() += 1;
    }
    let drained_in = t.elapsed();
    for state in ["queued", "running"] {
        let r = get(&mut c, &format!("/v1/jobs?state={state}&limit=1")).await;
        let n = r.headers.get("x-total-count").and_then(|v| v.to_str().ok()).unwrap_or("?").to_string();
        if n != "0" {
            failures.push(format!("{n} job(s) still {state} after the run"));
        }
    }

    // Nothing lost, nothing duplicated: each session holds exactly what was acknowledged.
    let mut mismatches = 0;
    for (s, n) in sessions.iter().zip(&sent) {
        let r = get(&mut c, &format!("/v1/sessions/{s}/measurements?limit=1")).await;
        let stored: u64 =
            r.headers.get("x-total-count").and_then(|v| v.to_str().ok()?.parse().ok()).unwrap_or(u64::MAX);
        if stored != *n {
            mismatches += 1;
            failures.push(format!("session {s}: {stored} measurements stored, {n} acknowledged"));
        }
    }

    // The table.
    println!(
        "{} clients, {:.1} s, batches of {} measurements; identification jobs: {} submitted, {:?}, drained {:.1} s after the run",
        a.clients,
        ran.as_secs_f64(),
        a.batch,
        jobs.len(),
        job_states,
        drained_in.as_secs_f64()
    );
    println!(
        "{:<40} {:>8} {:>7} {:>9} {:>9} {:>9} {:>8}",
        "endpoint", "requests", "errors", "p50 ms", "p99 ms", "max ms", "req/s"
    );
    let mut total = 0;
    let mut errors = 0;
    for ep in [BATCH, COMPENSATE, SETS, JOBS, IDENTIFY] {
        let mut v = stats.lat.remove(ep).unwrap_or_default();
        let e = stats.errors.get(ep).map_or(0, Vec::len);
        total += v.len() + e;
        errors += e;
        if v.is_empty() {
            println!("{ep:<40} {:>8} {e:>7}", 0);
            continue;
        }
        let n = v.len();
        let (p50, p99, max) = (pct(&mut v, 0.5), pct(&mut v, 0.99), pct(&mut v, 1.0));
        println!("{ep:<40} {n:>8} {e:>7} {p50:>9.1} {p99:>9.1} {max:>9.1} {:>8.1}", n as f64 / ran.as_secs_f64());
    }
    let acknowledged: u64 = sent.iter().sum();
    println!(
        "requests: {total}, errors: {errors}, transport retries (same key): {}; measurements acknowledged {acknowledged}, sessions matching {}/{}",
        stats.retries,
        sessions.len() - mismatches,
        sessions.len()
    );
    if a.slowloris > 0 {
        let closed = slow_stats.closed_after.len();
        let held = if closed > 0 {
            format!(
                "closed by the server after a median {:.1} s (max {:.1} s)",
                pct(&mut slow_stats.closed_after, 0.5) / 1000.0,
                pct(&mut slow_stats.closed_after, 1.0) / 1000.0
            )
        } else {
            "none closed by the server".to_string()
        };
        println!(
            "slowloris: {} connections at a time, a header line every {} ms: {} opened, {closed} {held}; {} bytes answered to them",
            a.slowloris,
            a.slow_every.as_millis(),
            slow_stats.opened,
            slow_stats.answered
        );
        let longest = slow_stats.closed_after.iter().chain(&slow_stats.open_for).max().copied().unwrap_or_default();
        if longest > a.slow_limit {
            failures.push(format!(
                "a slowloris connection stayed open {:.1} s (more than --slow-limit-s {}): no header timeout?",
                longest.as_secs_f64(),
                a.slow_limit.as_secs()
            ));
        }
        if slow_stats.answered > 0 {
            failures.push(format!(
                "the server sent {} bytes to clients that never ended their headers",
                slow_stats.answered
            ));
        }
    }
    for (ep, errs) in &stats.errors {
        for e in errs.iter().take(3) {
            println!("error {ep}: {e}");
        }
    }
    for f in &failures {
        println!("FAILED: {f}");
    }
    if errors > 0 || !failures.is_empty() {
        std::process::exit(1);
    }
    println!("ok: zero errors, nothing lost or duplicated, the job queue drained");
}
