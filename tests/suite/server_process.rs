//! The real `robocal serve` process over a real socket: graceful shutdown on SIGTERM, and a job
//! running when the server is killed (SIGKILL) completes after a restart; processes opening a
//! new database together; one server per database, enforced; logs without colour codes when
//! stderr is not a terminal, and as JSON lines.

use crate::common;

use std::net::TcpListener;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use axum::http::Method;
use robocal::http::client::Client;
use robocal::server::lock::LockError;
use robocal::server::{ServeError, ServeOptions};
use serde_json::{Value, json};

fn start(db: &Path, port: u16) -> Child {
    Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["serve", "--db", db.to_str().unwrap(), "--bind", &format!("127.0.0.1:{port}"), "--grace-s", "1"])
        .env("RUST_LOG", "warn")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("robocal serve starts")
}

fn signal(child: &Child, sig: &str) {
    let ok = Command::new("kill").args([sig, &child.id().to_string()]).status().unwrap().success();
    assert!(ok, "kill {sig}");
}

fn wait_exit(child: &mut Child, within: Duration) -> std::process::ExitStatus {
    let t = Instant::now();
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        assert!(t.elapsed() < within, "the server did not exit");
        std::thread::sleep(Duration::from_millis(20));
    }
}

async fn setup(client: &Client) -> (String, String) {
    let robot: Value = client
        .post("/v1/robots", &json!({"name": "r", "robot": {"preset": "irb120"}, "base_guess": common::base_guess()}))
        .await
        .unwrap();
    let artefact: Value = client
        .post(
            "/v1/artefacts",
            &json!({"name": "a", "distances_mm": {"d12": 300, "d13": 300, "d23": 300}, "ball_diameter_mm": 12.7}),
        )
        .await
        .unwrap();
    (robot["id"].as_str().unwrap().into(), artefact["id"].as_str().unwrap().into())
}

/// Over a real socket: requests, problem documents, and SIGTERM stopping the process cleanly.
#[tokio::test]
async fn serves_over_a_socket_and_stops_on_sigterm() {
    let dir = common::fresh_dir("socket");
    let db = dir.join("robocal.db");
    let port = common::free_port();
    let mut child = start(&db, port);
    let client = Client::new(&format!("http://127.0.0.1:{port}"), None).unwrap();
    common::wait_ready(&client).await;
    let (rid, _) = setup(&client).await;
    let got: Value = client.get(&format!("/v1/robots/{rid}")).await.unwrap();
    assert_eq!(got["name"], "r");
    let a = client.send(Method::GET, "/v1/robots/none", None, &[]).await.unwrap();
    assert_eq!(a.status.as_u16(), 404);
    assert_eq!(a.headers["content-type"], "application/problem+json");
    assert!(a.headers.contains_key("x-request-id"));
    let m = client.send(Method::GET, "/metrics", None, &[]).await.unwrap();
    assert!(String::from_utf8_lossy(&m.body).contains("robocal_http_requests_total"));
    signal(&child, "-TERM");
    let status = wait_exit(&mut child, Duration::from_secs(30));
    assert!(status.success(), "graceful shutdown exits 0, got {status}");
    // The database survives, with the robot.
    let mut child = start(&db, port);
    common::wait_ready(&client).await;
    let got: Value = client.get(&format!("/v1/robots/{rid}")).await.unwrap();
    assert_eq!(got["id"], rid.as_str());
    child.kill().unwrap();
    let _ = child.wait();
    let _ = std::fs::remove_dir_all(&dir);
}

/// A job running when the server is killed is requeued at the next start and completes.
#[tokio::test]
async fn a_job_survives_a_killed_server() {
    let dir = common::fresh_dir("kill");
    let db = dir.join("robocal.db");
    let port = common::free_port();
    let mut child = start(&db, port);
    let client = Client::new(&format!("http://127.0.0.1:{port}"), None).unwrap();
    common::wait_ready(&client).await;
    let (rid, aid) = setup(&client).await;
    // A pose plan big enough to be caught running: 3 × 1500 candidates, DETMAX, 3000 tracker poses.
    let job: Value = client
        .post(
            &format!("/v1/robots/{rid}/pose-plans"),
            &json!({"artefact_id": aid, "tool": {"tcp_mm": [40, 0, 130], "mass_kg": 1.7, "com_mm": [30, 0, 64]},
                    "per_ball": 1500, "validation": 3000, "select": {"n": 75}, "seed": 3}),
        )
        .await
        .unwrap();
    let id = job["id"].as_str().unwrap().to_string();
    let t = Instant::now();
    loop {
        let j: Value = client.get(&format!("/v1/jobs/{id}")).await.unwrap();
        match j["state"].as_str().unwrap() {
            "running" => break,
            "queued" => {}
            other => panic!("the job ended ({other}) before it could be killed: make it bigger"),
        }
        assert!(t.elapsed() < Duration::from_secs(30), "the job never started");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    child.kill().unwrap(); // SIGKILL: no cleanup of any kind
    let _ = child.wait();

    let mut child = start(&db, port);
    common::wait_ready(&client).await;
    let t = Instant::now();
    let done = loop {
        let j: Value = client.get(&format!("/v1/jobs/{id}")).await.unwrap();
        if matches!(j["state"].as_str(), Some("succeeded" | "failed" | "cancelled")) {
            break j;
        }
        assert!(t.elapsed() < Duration::from_secs(600), "the requeued job did not finish: {j}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    assert_eq!(done["state"], "succeeded", "{done}");
    assert_eq!(done["attempts"], 2, "claimed once before the kill and once after: {done}");
    let plan: Value =
        client.get(&format!("/v1/pose-plans/{}", done["result"]["pose_plan_id"].as_str().unwrap())).await.unwrap();
    assert_eq!(plan["plan"]["identification"].as_array().unwrap().len(), 75);
    assert_eq!(plan["plan"]["validation"].as_array().unwrap().len(), 3000);
    assert_eq!(plan["plan"]["candidates"], 4500);
    child.kill().unwrap();
    let _ = child.wait();
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--grace-s` bounds the shutdown: SIGTERM during a large pose plan, with a client sending its
/// headers slowly and another trickling a body, and the process exits within grace + 2 s (it used
/// to wait for the solver's thread, 12 s more, holding the database). The job is put back in the
/// queue at the deadline: a new server on the database (the lock is free) claims it again.
#[tokio::test]
async fn a_shutdown_ends_within_the_grace_period() {
    use std::io::Write;
    let dir = common::fresh_dir("grace");
    let db = dir.join("robocal.db");
    let port = common::free_port();
    let mut child = start(&db, port);
    let client = Client::new(&format!("http://127.0.0.1:{port}"), None).unwrap();
    common::wait_ready(&client).await;
    let (rid, aid) = setup(&client).await;
    let job: Value = client
        .post(
            &format!("/v1/robots/{rid}/pose-plans"),
            &json!({"artefact_id": aid, "tool": {"tcp_mm": [40, 0, 130], "mass_kg": 1.7, "com_mm": [30, 0, 64]},
                    "per_ball": 2000, "validation": 10000, "select": {"n": 75}, "seed": 5}),
        )
        .await
        .unwrap();
    let id = job["id"].as_str().unwrap().to_string();
    let t = Instant::now();
    loop {
        let j: Value = client.get(&format!("/v1/jobs/{id}")).await.unwrap();
        match j["state"].as_str().unwrap() {
            "running" => break,
            "queued" => {}
            other => panic!("the job ended ({other}) before the shutdown: make it bigger"),
        }
        assert!(t.elapsed() < Duration::from_secs(30), "the job never started");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    // Two hostile connections open across the shutdown.
    let mut slow_headers = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
    slow_headers.write_all(b"GET /healthz HTTP/1.1\r\nHost: t\r\n").unwrap();
    let mut slow_body = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
    slow_body.write_all(b"POST /v1/robots HTTP/1.1\r\nHost: t\r\nContent-Length: 100\r\n\r\n{").unwrap();
    tokio::time::sleep(Duration::from_millis(200)).await;
    let t = Instant::now();
    signal(&child, "-TERM");
    let status = wait_exit(&mut child, Duration::from_secs(30));
    let took = t.elapsed();
    assert!(status.success(), "a bounded shutdown still exits 0, got {status}");
    assert!(took < Duration::from_secs(3), "exited {took:?} after SIGTERM with --grace-s 1");
    eprintln!("SIGTERM during a pose plan, --grace-s 1: exited after {took:?}");
    drop((slow_headers, slow_body));
    let mut child = start(&db, port);
    common::wait_ready(&client).await;
    let j: Value = client.get(&format!("/v1/jobs/{id}")).await.unwrap();
    assert!(j["state"] == "queued" || j["state"] == "running", "{j}");
    let t = Instant::now();
    let again = loop {
        let j: Value = client.get(&format!("/v1/jobs/{id}")).await.unwrap();
        if j["attempts"] == 2 || t.elapsed() > Duration::from_secs(30) {
            break j;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    };
    assert_eq!(again["attempts"], 2, "put back in the queue at the deadline, claimed again: {again}");
    child.kill().unwrap();
    let _ = child.wait();
    let _ = std::fs::remove_dir_all(&dir);
}

/// A server and two `robocal token create` started together on a database that does not exist
/// yet: all three open it (one creates and migrates it, the others wait their turn), the tokens
/// are both stored, and the server accepts them.
#[tokio::test]
async fn processes_opening_a_new_database_together_take_turns() {
    for round in 0..5 {
        let dir = common::fresh_dir(&format!("new-db-{round}"));
        let db = dir.join("new.db");
        let port = common::free_port();
        let mut server = start(&db, port);
        let create = |name: &str| {
            Command::new(env!("CARGO_BIN_EXE_robocal"))
                .args(["token", "create", "--db", db.to_str().unwrap(), "--name", name, "--scopes", "read"])
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap()
        };
        let (a, b) = (create("a"), create("b"));
        let mut secrets = Vec::new();
        for c in [a, b] {
            let out = c.wait_with_output().unwrap();
            assert!(out.status.success(), "round {round}: {}", String::from_utf8_lossy(&out.stderr));
            let v: Value = serde_json::from_slice(&out.stdout).unwrap();
            secrets.push(v["token"].as_str().unwrap().to_string());
        }
        let url = format!("http://127.0.0.1:{port}");
        common::wait_ready(&Client::new(&url, None).unwrap()).await;
        for s in &secrets {
            let authed = Client::new(&url, Some(s.clone())).unwrap();
            let r = authed.send(Method::GET, "/v1/tokens", None, &[]).await.unwrap();
            assert_eq!(r.status.as_u16(), 403, "round {round}: a live read token, refused only for its scope");
        }
        signal(&server, "-TERM");
        assert!(wait_exit(&mut server, Duration::from_secs(30)).success());
    }
}

/// One server per database: a second `serve` on a database that a running server holds exits at
/// once, status 2, naming the first one's PID and address; the first is not disturbed. Once the
/// first is killed (SIGKILL: no cleanup of any kind) the OS has released its lock and a new server
/// starts on the database; after a clean stop the lock file is left empty.
#[tokio::test]
async fn a_second_server_on_one_database_is_refused_until_the_first_is_gone() {
    let dir = common::fresh_dir("one-server");
    let db = dir.join("robocal.db");
    let (port, other_port) = (common::free_port(), common::free_port());
    let mut first = start(&db, port);
    let client = Client::new(&format!("http://127.0.0.1:{port}"), None).unwrap();
    common::wait_ready(&client).await;

    let t = Instant::now();
    let second = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["serve", "--db", db.to_str().unwrap(), "--bind", &format!("127.0.0.1:{other_port}")])
        .env("RUST_LOG", "warn")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&second.stderr);
    assert!(t.elapsed() < Duration::from_secs(10), "refused at once, took {:?}", t.elapsed());
    assert_eq!(second.status.code(), Some(2), "{err}");
    let real_db = std::fs::canonicalize(&dir).unwrap().join("robocal.db");
    for expected in [
        format!("error: the database {} is served by another robocal process", real_db.display()),
        format!("PID {}", first.id()),
        format!("listening on 127.0.0.1:{port}"),
        "one server per database".to_string(),
    ] {
        assert!(err.contains(&expected), "{expected:?} not in: {err}");
    }
    // It never listened, and the first one still serves.
    assert!(std::net::TcpStream::connect(("127.0.0.1", other_port)).is_err());
    let r = client.send(Method::GET, "/readyz", None, &[]).await.unwrap();
    assert!(r.status.is_success());

    first.kill().unwrap(); // SIGKILL
    let _ = first.wait();
    let mut next = start(&db, other_port);
    let next_client = Client::new(&format!("http://127.0.0.1:{other_port}"), None).unwrap();
    common::wait_ready(&next_client).await;
    let lock: Value = serde_json::from_str(&std::fs::read_to_string(dir.join("robocal.db.lock")).unwrap()).unwrap();
    assert_eq!(lock["pid"], next.id());
    assert_eq!(lock["addr"], format!("127.0.0.1:{other_port}"));
    assert!(lock["since"].as_str().unwrap().ends_with('Z'), "{lock}");
    signal(&next, "-TERM");
    assert!(wait_exit(&mut next, Duration::from_secs(30)).success());
    assert_eq!(std::fs::read_to_string(dir.join("robocal.db.lock")).unwrap(), "", "emptied on a clean stop");
    let _ = std::fs::remove_dir_all(&dir);
}

/// In one process (the demo's and the tests' in-process servers): a server whose address is
/// refused releases the database's lock, so the next one starts; while that one runs, another on
/// the same database is refused with `ServeError::Locked`.
#[tokio::test]
async fn a_refused_address_releases_the_database_lock() {
    let dir = common::fresh_dir("bind-refused");
    let db = dir.join("robocal.db");
    let taken = TcpListener::bind("127.0.0.1:0").unwrap();
    let e = robocal::server::start(ServeOptions::new(db.clone(), taken.local_addr().unwrap())).await.err().unwrap();
    assert!(matches!(e, ServeError::Bind { .. }), "{e}");
    let running = robocal::server::start(ServeOptions::new(db.clone(), ([127, 0, 0, 1], 0).into())).await.unwrap();
    let e = robocal::server::start(ServeOptions::new(db.clone(), ([127, 0, 0, 1], 0).into())).await.err().unwrap();
    assert!(matches!(e, ServeError::Locked(LockError::Held { .. })), "{e}");
    assert!(e.to_string().contains(&format!("listening on {}", running.addr)), "{e}");
    running.stop().await.unwrap();
    let again = robocal::server::start(ServeOptions::new(db.clone(), ([127, 0, 0, 1], 0).into())).await.unwrap();
    again.stop().await.unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// A server's stderr (its log) from start to a clean stop, with one request carrying the
/// request id `rid` in between; `RUST_LOG` lets through tower-http's per-request events.
async fn log_of_one_request(tag: &str, extra: &[&str], rid: &str) -> String {
    let dir = common::fresh_dir(tag);
    let db = dir.join("robocal.db");
    let port = common::free_port();
    let child = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["serve", "--db", db.to_str().unwrap(), "--bind", &format!("127.0.0.1:{port}"), "--grace-s", "1"])
        .args(extra)
        .env("RUST_LOG", "info,tower_http=debug")
        .env_remove("NO_COLOR")
        .env_remove("ROBOCAL_LOG_FORMAT")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let client = Client::new(&format!("http://127.0.0.1:{port}"), None).unwrap();
    common::wait_ready(&client).await;
    let r = client.send(Method::GET, "/v1/robots", None, &[("x-request-id", rid)]).await.unwrap();
    assert_eq!(r.status.as_u16(), 200);
    signal(&child, "-TERM");
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    let _ = std::fs::remove_dir_all(&dir);
    String::from_utf8(out.stderr).unwrap()
}

/// Text logs to a pipe (not a terminal): no ANSI escape codes, the request's span readable.
#[tokio::test]
async fn text_logs_to_a_pipe_have_no_colour_codes() {
    let log = log_of_one_request("log-text", &[], "text-log-rid-1").await;
    assert!(!log.contains('\x1b'), "an escape code in: {log:?}");
    assert!(log.contains("robocal serving") && log.contains("stopped"), "{log}");
    assert!(log.contains("request_id=text-log-rid-1"), "{log}");
}

/// `--log-format json`: every line is one JSON object with a timestamp, a level and the event's
/// fields (its message among them); the request's events carry the http span with its request id.
#[tokio::test]
async fn json_logs_are_one_object_per_line_with_the_request_id() {
    let log = log_of_one_request("log-json", &["--log-format", "json"], "json-log-rid-1").await;
    assert!(!log.contains('\x1b'), "an escape code in: {log:?}");
    let lines: Vec<Value> = log
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}")))
        .collect();
    for l in &lines {
        assert!(l["timestamp"].is_string() && l["level"].is_string() && l["target"].is_string(), "{l}");
        assert!(l["fields"]["message"].is_string(), "{l}");
    }
    let serving = lines.iter().find(|l| l["fields"]["message"] == "robocal serving").expect("the start line");
    assert_eq!(serving["level"], "INFO");
    assert!(serving["fields"]["addr"].as_str().unwrap().starts_with("127.0.0.1:"), "{serving}");
    let request: Vec<&Value> = lines.iter().filter(|l| l["span"]["request_id"] == "json-log-rid-1").collect();
    assert!(!request.is_empty(), "no event in the request's span: {log}");
    assert!(request.iter().all(|l| l["span"]["name"] == "http" && l["span"]["uri"] == "/v1/robots"), "{request:?}");
}

/// A `--cors-origin` that is not an origin is refused at start-up, status 2, naming the option;
/// nothing is created.
#[test]
fn a_bad_cors_origin_is_refused_at_start_up() {
    let dir = common::fresh_dir("cors-arg");
    let db = dir.join("robocal.db");
    let out = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["serve", "--db", db.to_str().unwrap(), "--bind", "127.0.0.1:0"])
        .args(["--cors-origin", "https://ok.example", "--cors-origin", "https://dash.example.com/"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("error: --cors-origin: 'https://dash.example.com/' is not an origin: no trailing slash"),
        "{err}"
    );
    assert!(!db.exists() && !dir.join("robocal.db.lock").exists());
    let _ = std::fs::remove_dir_all(&dir);
}
