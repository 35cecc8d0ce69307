//! Slow and hostile clients against a real server over a socket (in this process, with short
//! limits so the tests take seconds): headers sent slowly are cut at the header timeout, a body
//! trickled below the minimum rate is cut with 408, a declared body over the limit is refused
//! with 413 before any of it is sent, and hyper's own refusals — a URI too long (414), headers
//! too large (431), a request that is not HTTP (400) — are problem documents like every other.
//! Meanwhile the server answers other clients. The connection limit is tested against the real
//! `robocal serve` process (its flags), with slowloris connections taking every slot.

use crate::common;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use robocal::server::{Running, ServeOptions};
use serde_json::Value;

const HEADER_TIMEOUT: Duration = Duration::from_secs(1);

/// A server on a fresh database: header timeout 1 s; bodies at ≥ 100 bytes a second after 0.3 s.
async fn server() -> (Running, std::path::PathBuf) {
    let dir = common::fresh_dir("hostile");
    let mut opts = ServeOptions::new(dir.join("robocal.db"), "127.0.0.1:0".parse().unwrap());
    opts.header_timeout = HEADER_TIMEOUT;
    opts.config.body_min_rate = 100;
    opts.config.body_grace = Duration::from_millis(300);
    (robocal::server::start(opts).await.unwrap(), dir)
}

/// A blocking connection (the tests write at their own pace).
fn connect(r: &Running) -> TcpStream {
    let s = TcpStream::connect(r.addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s
}

/// Everything the server sends until it closes the connection.
fn read_all(s: &mut TcpStream) -> Vec<u8> {
    let mut out = Vec::new();
    let mut buf = [0u8; 4096];
    loop {
        match s.read(&mut buf) {
            Ok(0) => return out,
            Ok(n) => out.extend_from_slice(&buf[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => return out,
            Err(e) => panic!("reading: {e} (after {} bytes)", out.len()),
        }
    }
}

/// An HTTP/1.1 answer: status, headers (names lower-cased), body.
fn parse(answer: &[u8]) -> (u16, Vec<(String, String)>, Vec<u8>) {
    let at = answer.windows(4).position(|w| w == b"\r\n\r\n").unwrap_or_else(|| {
        panic!("not an HTTP answer: {:?}", String::from_utf8_lossy(answer));
    });
    let head = String::from_utf8_lossy(&answer[..at]).into_owned();
    let mut lines = head.split("\r\n");
    let status = lines.next().unwrap()[9..12].parse().unwrap();
    let headers = lines
        .map(|l| {
            let (k, v) = l.split_once(':').unwrap();
            (k.trim().to_ascii_lowercase(), v.trim().to_string())
        })
        .collect();
    (status, headers, answer[at + 4..].to_vec())
}

/// The answer is a problem document with this status; the document.
fn problem(answer: &[u8], status: u16) -> Value {
    let (got, headers, body) = parse(answer);
    let header = |k: &str| headers.iter().find(|(n, _)| n == k).map(|(_, v)| v.as_str());
    assert_eq!(got, status, "{}", String::from_utf8_lossy(answer));
    assert_eq!(header("content-type"), Some("application/problem+json"), "{}", String::from_utf8_lossy(answer));
    let len: usize = header("content-length").expect("a length").parse().unwrap();
    assert_eq!(len, body.len());
    let p: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(p["status"], status);
    assert!(p["type"].as_str().unwrap().starts_with("urn:robocal:problem:"), "{p}");
    assert!(p["detail"].is_string(), "{p}");
    p
}

/// Another client's `GET /healthz`, on its own connection: answered 200.
fn healthy(r: &Running) {
    let mut s = connect(r);
    s.write_all(b"GET /healthz HTTP/1.1\r\nHost: t\r\nConnection: close\r\n\r\n").unwrap();
    let (status, _, _) = parse(&read_all(&mut s));
    assert_eq!(status, 200);
}

/// A client sending a header line every 200 ms is disconnected at the header timeout, with no
/// answer (there is no request to answer); other clients are served meanwhile. The connection
/// would otherwise stay open as long as the client keeps sending.
#[tokio::test(flavor = "multi_thread")]
async fn headers_sent_slowly_are_cut_at_the_header_timeout() {
    let (r, dir) = server().await;
    let addr = r.addr;
    let slow = tokio::task::spawn_blocking(move || {
        // Timed from before the connection: the server's header timer starts when it accepts
        // it, so a clock started after the connect read 997 ms for a 1 s timeout once.
        let t = Instant::now();
        let mut s = TcpStream::connect(addr).unwrap();
        s.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
        s.write_all(b"GET /healthz HTTP/1.1\r\nHost: t\r\n").unwrap();
        let mut buf = [0u8; 256];
        while t.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(200));
            if s.write_all(b"X-Slow: 1\r\n").is_err() {
                return (t.elapsed(), 0);
            }
            match s.read(&mut buf) {
                Ok(n) => return (t.elapsed(), n),
                Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
                Err(_) => return (t.elapsed(), 0),
            }
        }
        (t.elapsed(), usize::MAX)
    });
    tokio::time::sleep(Duration::from_millis(300)).await;
    let r2 = tokio::task::spawn_blocking({
        let r_addr = r.addr;
        move || {
            let mut s = TcpStream::connect(r_addr).unwrap();
            s.write_all(b"GET /healthz HTTP/1.1\r\nHost: t\r\nConnection: close\r\n\r\n").unwrap();
            parse(&read_all(&mut s)).0
        }
    });
    assert_eq!(r2.await.unwrap(), 200);
    let (after, answered) = slow.await.unwrap();
    assert_ne!(answered, usize::MAX, "still open after {after:?}");
    assert_eq!(answered, 0, "the server answered a request it never received");
    assert!(after >= HEADER_TIMEOUT && after < HEADER_TIMEOUT + Duration::from_millis(900), "closed after {after:?}");
    eprintln!("slow headers: closed after {after:?} (header timeout {HEADER_TIMEOUT:?})");
    r.stop().await.unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// A body trickled at a byte every 100 ms falls behind 100 bytes a second after 0.3 s: cut with
/// 408 problem+json within about 0.4 s (0.3 s + n/100 s allowed after n bytes: behind at the 3rd
/// byte), and the connection closed; nothing is stored.
#[tokio::test(flavor = "multi_thread")]
async fn a_body_sent_too_slowly_is_cut_with_408() {
    let (r, dir) = server().await;
    let addr = r.addr;
    let (answer, took) = tokio::task::spawn_blocking(move || {
        let mut s = TcpStream::connect(addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        let t = Instant::now();
        s.write_all(
            b"POST /v1/robots HTTP/1.1\r\nHost: t\r\nContent-Type: application/json\r\nContent-Length: 10000\r\n\r\n",
        )
        .unwrap();
        s.set_nonblocking(false).unwrap();
        let mut reader = s.try_clone().unwrap();
        let writer = std::thread::spawn(move || {
            for _ in 0..100 {
                std::thread::sleep(Duration::from_millis(100));
                if s.write_all(b" ").is_err() {
                    return;
                }
            }
        });
        let answer = read_all(&mut reader);
        let took = t.elapsed();
        let _ = writer.join();
        (answer, took)
    })
    .await
    .unwrap();
    let p = problem(&answer, 408);
    assert_eq!(p["type"], "urn:robocal:problem:request-timeout");
    assert!(p["detail"].as_str().unwrap().contains("too slowly"), "{p}");
    assert!(took < Duration::from_secs(2), "answered after {took:?}");
    eprintln!("slow body: 408 after {took:?}: {p}");
    healthy(&r);
    let robots = robocal::http::client::Client::new(&r.url(), None).unwrap();
    let listed: Value = robots.get("/v1/robots").await.unwrap();
    assert_eq!(listed.as_array().unwrap().len(), 0);
    r.stop().await.unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// A declared `Content-Length` of 1 GiB is refused with 413 problem+json as soon as the headers
/// are in, without a byte of the body sent; the limit is named.
#[tokio::test(flavor = "multi_thread")]
async fn a_declared_body_over_the_limit_is_refused_at_once() {
    let (r, dir) = server().await;
    let addr = r.addr;
    let (answer, took) = tokio::task::spawn_blocking(move || {
        let mut s = TcpStream::connect(addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        let t = Instant::now();
        s.write_all(b"POST /v1/sessions/x/measurements HTTP/1.1\r\nHost: t\r\nContent-Type: application/json\r\nContent-Length: 1073741824\r\n\r\n").unwrap();
        let a = read_all(&mut s);
        (a, t.elapsed())
    })
    .await
    .unwrap();
    let p = problem(&answer, 413);
    assert_eq!(p["type"], "urn:robocal:problem:too-large");
    let detail = p["detail"].as_str().unwrap();
    assert!(detail.contains("1073741824") && detail.contains(&(32 * 1024 * 1024).to_string()), "{p}");
    assert!(took < Duration::from_secs(1), "answered after {took:?}");
    eprintln!("declared 1 GiB: 413 after {took:?}: {p}");
    r.stop().await.unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// hyper's own refusals are problem documents: a 100,000-character path (414), a 1 MB header
/// (431), a request line that is not HTTP (400).
#[tokio::test(flavor = "multi_thread")]
async fn protocol_refusals_are_problem_documents() {
    let (r, dir) = server().await;
    let addr = r.addr;
    let cases: Vec<(Vec<u8>, u16, &str)> = vec![
        (format!("GET /{} HTTP/1.1\r\nHost: t\r\n\r\n", "a".repeat(100_000)).into_bytes(), 414, "uri-too-long"),
        (
            format!("GET /healthz HTTP/1.1\r\nHost: t\r\nX-Big: {}\r\n\r\n", "b".repeat(1_000_000)).into_bytes(),
            431,
            "request-header-fields-too-large",
        ),
        (b"HELLO there\r\n\r\n".to_vec(), 400, "malformed"),
    ];
    for (request, status, slug) in cases {
        let answer = tokio::task::spawn_blocking(move || {
            let mut s = TcpStream::connect(addr).unwrap();
            s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
            // The server may answer and close before the whole request is written: read while
            // writing, so the answer is in before the connection is reset.
            let mut w = s.try_clone().unwrap();
            let writer = std::thread::spawn(move || {
                let _ = w.write_all(&request);
            });
            let a = read_all(&mut s);
            let _ = writer.join();
            a
        })
        .await
        .unwrap();
        let p = problem(&answer, status);
        assert_eq!(p["type"], format!("urn:robocal:problem:{slug}"), "{p}");
        eprintln!("{status}: {p}");
    }
    healthy(&r);
    r.stop().await.unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// Kills the server process when dropped: a test that fails leaves nothing behind.
struct Process(std::process::Child);

impl Drop for Process {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A `GET /healthz` on its own connection: the status, and how long the answer took.
fn get_healthz(addr: std::net::SocketAddr) -> (u16, Duration) {
    let t = Instant::now();
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    s.write_all(b"GET /healthz HTTP/1.1\r\nHost: t\r\nConnection: close\r\n\r\n").unwrap();
    let a = read_all(&mut s);
    (parse(&a).0, t.elapsed())
}

/// The real `robocal serve` process with `--max-connections 2 --header-timeout-s 1`: two
/// slowloris connections (headers never ended) take both slots; a third client is neither
/// refused nor answered while they hold them — it waits in the listener's backlog — and is
/// answered 200 once the header timeout closes them (about 1 s after they connected), while the
/// slow connections get no answer. Without the limit it would be answered at once; without the
/// header timeout, never.
#[test]
fn the_connection_limit_holds_new_clients_until_the_slow_ones_are_cut() {
    let dir = common::fresh_dir("conn-limit");
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let addr: std::net::SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    let db = dir.join("robocal.db");
    let _server = Process(
        std::process::Command::new(env!("CARGO_BIN_EXE_robocal"))
            .args(["serve", "--db", db.to_str().unwrap(), "--bind", &addr.to_string()])
            .args(["--header-timeout-s", "1", "--max-connections", "2", "--grace-s", "1"])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap(),
    );
    let t = Instant::now();
    loop {
        if let Ok(mut s) = TcpStream::connect(addr) {
            s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
            if s.write_all(b"GET /healthz HTTP/1.1\r\nHost: t\r\nConnection: close\r\n\r\n").is_ok()
                && read_all(&mut s).starts_with(b"HTTP/1.1 200")
            {
                break;
            }
        }
        assert!(t.elapsed() < Duration::from_secs(20), "the server never answered");
        std::thread::sleep(Duration::from_millis(50));
    }
    // The ready check's connection is closed: both slots are free. An idle server answers at once.
    std::thread::sleep(Duration::from_millis(200));
    let (status, quick) = get_healthz(addr);
    assert_eq!(status, 200);
    assert!(quick < Duration::from_millis(300), "an idle server took {quick:?}");
    std::thread::sleep(Duration::from_millis(200));
    let slow: Vec<TcpStream> = (0..2)
        .map(|_| {
            let mut s = TcpStream::connect(addr).unwrap();
            s.write_all(b"GET /healthz HTTP/1.1\r\nHost: t\r\n").unwrap();
            s
        })
        .collect();
    let opened = Instant::now();
    std::thread::sleep(Duration::from_millis(100));
    let (status, waited) = get_healthz(addr);
    assert_eq!(status, 200);
    assert!(
        waited >= Duration::from_millis(600) && waited < Duration::from_secs(3),
        "the third client was answered after {waited:?} (the slow ones were cut after about 1 s)"
    );
    eprintln!(
        "connection limit 2, two slowloris connections: a third client answered after {waited:?} ({:?} after they connected)",
        opened.elapsed()
    );
    for mut s in slow {
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        assert_eq!(read_all(&mut s), b"", "a slow connection got an answer to headers it never ended");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
