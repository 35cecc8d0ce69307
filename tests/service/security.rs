//! Security: every `/v1` operation of the OpenAPI document — enumerated from the document, so a
//! route added later is covered without touching this file — refuses a missing, malformed,
//! revoked or wrong-scope token with a problem document; the served document declares the
//! security the server's mode enforces; token management needs an admin token on loopback too;
//! tokens never reach the logs; the server binds to loopback by default.

use crate::common;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use axum::http::Method;
use clap::Parser;
use common::{TestApp, assert_problem};
use robocal::db::tokens::{self, Scope};
use robocal::http::ServiceConfig;
use serde_json::{Value, json};

/// Every operation of a document: (method, path template, operation object).
fn operations(doc: &Value) -> Vec<(Method, String, Value)> {
    let mut out = Vec::new();
    for (path, item) in doc["paths"].as_object().expect("paths") {
        for (name, method) in [
            ("get", Method::GET),
            ("post", Method::POST),
            ("put", Method::PUT),
            ("patch", Method::PATCH),
            ("delete", Method::DELETE),
        ] {
            if let Some(op) = item.get(name) {
                out.push((method, path.clone(), op.clone()));
            }
        }
    }
    out
}

/// The scope an operation's bearer requirement names, if it has one.
fn bearer_scope(op: &Value) -> Option<String> {
    op["security"].as_array()?.iter().find_map(|r| r.get("bearer")?.get(0)?.as_str().map(str::to_string))
}

/// A concrete URL for a path template: path parameters filled with values of their declared
/// type (ids that do not exist: authentication is decided before the resource is looked up).
fn concrete(path: &str, op: &Value) -> String {
    let mut url = path.to_string();
    for p in op["parameters"].as_array().into_iter().flatten() {
        if p["in"] == "path" {
            let name = p["name"].as_str().unwrap();
            let value = if p["schema"]["type"] == "integer" { "0" } else { "no-such-id" };
            url = url.replace(&format!("{{{name}}}"), value);
        }
    }
    assert!(!url.contains('{'), "{path}: a path parameter is not declared");
    url
}

async fn call(app: &TestApp, method: &Method, url: &str, auth: Option<&str>) -> common::Res {
    let headers: Vec<(&str, &str)> = auth.map(|a| ("authorization", a)).into_iter().collect();
    let (ct, body) = if matches!(*method, Method::POST | Method::PUT | Method::PATCH) {
        (Some("application/json"), b"{}".to_vec())
    } else {
        (None, Vec::new())
    };
    app.raw(method.clone(), url, ct, body, &headers).await
}

/// With authentication required: each `/v1` operation declares a bearer scope, refuses a missing,
/// malformed, unknown, revoked and wrong-scope token (401/403 problem+json), and lets the
/// declared scope through (so the declaration is the scope the handler asks for).
#[tokio::test]
async fn every_v1_operation_refuses_missing_malformed_revoked_and_wrong_scope_tokens() {
    let app = TestApp::new(ServiceConfig { require_auth: true, ..Default::default() }, false).await;
    let served = app.get("/openapi.json").await;
    assert_eq!(served.status, 200);
    assert_eq!(served.body, serde_json::to_value(robocal::http::openapi()).unwrap(), "the committed form is served");

    let pool = &app.state.pool;
    let (revoked, revoked_secret) = tokens::create(pool, "gone", &[Scope::Admin]).await.unwrap();
    assert!(tokens::revoke(pool, &revoked.id).await.unwrap());
    let mut scoped = std::collections::HashMap::new();
    for s in Scope::ALL {
        scoped.insert(s.as_str().to_string(), tokens::create(pool, s.as_str(), &[s]).await.unwrap().1);
    }
    // Every non-admin scope but one: what a token lacking exactly that scope can do.
    let mut all_but = std::collections::HashMap::new();
    for need in Scope::ALL {
        let others: Vec<Scope> = Scope::ALL.into_iter().filter(|s| *s != need && *s != Scope::Admin).collect();
        all_but.insert(need.as_str().to_string(), tokens::create(pool, "all-but", &others).await.unwrap().1);
    }

    let doc = served.body;
    let ops = operations(&doc);
    let v1: Vec<_> = ops.iter().filter(|(_, p, _)| p.starts_with("/v1/")).collect();
    assert!(v1.len() >= 40, "{} /v1 operations: is the document complete?", v1.len());
    for (method, path, op) in v1 {
        let what = format!("{method} {path}");
        let scope = bearer_scope(op).unwrap_or_else(|| panic!("{what}: no bearer scope declared"));
        assert!(Scope::parse(&scope).is_some(), "{what}: '{scope}' is not a scope");
        let url = concrete(path, op);
        for (auth, case) in [
            (None, "missing"),
            (Some("Basic YWRtaW46YWRtaW4="), "not bearer"),
            (Some("Bearer"), "bearer without token"),
            (Some("Bearer   "), "blank token"),
            (Some("Bearer rc_0000000000000000000000000000000000000000"), "unknown token"),
        ] {
            let r = call(&app, method, &url, auth).await;
            assert_eq!(r.status, 401, "{what} ({case}): {}", r.text);
            assert_problem(&r, 401, None);
        }
        let r = call(&app, method, &url, Some(&format!("Bearer {revoked_secret}"))).await;
        assert_problem(&r, 401, None);
        let r = call(&app, method, &url, Some(&format!("Bearer {}", all_but[&scope]))).await;
        assert_eq!(r.status, 403, "{what} (without '{scope}'): {}", r.text);
        assert_problem(&r, 403, None);
        assert!(r.body["detail"].as_str().unwrap().contains(&format!("'{scope}'")), "{what}: {}", r.text);
        for ok in [&scoped[&scope], &scoped["admin"]] {
            let r = call(&app, method, &url, Some(&format!("Bearer {ok}"))).await;
            assert!(r.status != 401 && r.status != 403, "{what}: the declared scope '{scope}' is refused: {}", r.text);
        }
    }
    // Operations outside /v1 (health, readiness, metrics, this document) need no token.
    for (method, path, op) in ops.iter().filter(|(_, p, _)| !p.starts_with("/v1/")) {
        assert!(op.get("security").is_none(), "{method} {path}");
        assert_eq!(call(&app, method, path, None).await.status, 200, "{method} {path}");
    }
    app.stop().await;
}

/// On loopback without `--require-auth`: the served document declares an empty requirement for
/// what needs no token and keeps bearer on token management, which refuses a request without an
/// admin token — no local process can mint itself a token.
#[tokio::test]
async fn loopback_mode_declares_what_it_enforces_and_token_routes_still_need_admin() {
    let app = TestApp::new(ServiceConfig::default(), false).await;
    let doc = app.get("/openapi.json").await.body;
    assert_eq!(doc, serde_json::to_value(robocal::http::openapi_for(false)).unwrap());
    let (_, reader) = tokens::create(&app.state.pool, "reader", &[Scope::Read]).await.unwrap();
    let mut token_ops = 0;
    for (method, path, op) in operations(&doc).iter().filter(|(_, p, _)| p.starts_with("/v1/")) {
        let url = concrete(path, op);
        let none = call(&app, method, &url, None).await;
        if path.starts_with("/v1/tokens") {
            token_ops += 1;
            assert_eq!(bearer_scope(op).as_deref(), Some("admin"), "{method} {path}");
            assert_problem(&none, 401, None);
            assert_problem(&call(&app, method, &url, Some(&format!("Bearer {reader}"))).await, 403, None);
        } else {
            assert_eq!(op["security"], json!([{}]), "{method} {path}: no token needed");
            assert!(none.status != 401 && none.status != 403, "{method} {path}: {}", none.text);
            // A token that is sent is still checked.
            assert_problem(&call(&app, method, &url, Some("Bearer rc_unknown")).await, 401, None);
        }
    }
    assert_eq!(token_ops, 3, "create, list, revoke");
    app.stop().await;
}

/// The default bind address is loopback (so a server started without flags needs a token for
/// nothing but token management, and is reachable from this machine only).
#[test]
fn the_server_binds_to_loopback_by_default() {
    // The environment variable would override the default.
    if std::env::var_os("ROBOCAL_BIND").is_some() {
        panic!("unset ROBOCAL_BIND to run this test");
    }
    let cli = robocal::cli::Cli::try_parse_from(["robocal", "serve"]).unwrap();
    let robocal::cli::Command::Serve(args) = cli.command else { panic!("serve") };
    let addr: std::net::SocketAddr = args.bind.parse().unwrap();
    assert!(addr.ip().is_loopback(), "{addr}");
    let help = Command::new(env!("CARGO_BIN_EXE_robocal")).args(["serve", "--help"]).output().unwrap();
    assert!(String::from_utf8_lossy(&help.stdout).contains("[default: 127.0.0.1:8080]"));
}

/// Tokens never appear in the server's logs, at the most verbose level, whether accepted,
/// created over HTTP, refused or revoked.
#[tokio::test]
async fn tokens_never_appear_in_the_logs() {
    let dir = common::fresh_dir("security-logs");
    let db = dir.join("robocal.db");
    let log = dir.join("serve.log");
    let port = common::free_port();
    let mut server = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["serve", "--db", db.to_str().unwrap(), "--bind", &format!("127.0.0.1:{port}"), "--require-auth"])
        .args(["--grace-s", "1"])
        .env("RUST_LOG", "trace")
        .env_remove("ROBOCAL_LOG_FORMAT")
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&log).unwrap())
        .spawn()
        .unwrap();
    let url = format!("http://127.0.0.1:{port}");
    let anon = robocal::http::client::Client::new(&url, None).unwrap();
    let t = Instant::now();
    while !anon.send(Method::GET, "/readyz", None, &[]).await.is_ok_and(|a| a.status.is_success()) {
        assert!(t.elapsed() < Duration::from_secs(60), "the server did not start");
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    // The first token from the command line, as an operator makes it (after the server migrated).
    let out = Command::new(env!("CARGO_BIN_EXE_robocal"))
        .args(["token", "create", "--db", db.to_str().unwrap(), "--name", "ops", "--scopes", "admin"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let admin = serde_json::from_slice::<Value>(&out.stdout).unwrap()["token"].as_str().unwrap().to_string();
    let client = robocal::http::client::Client::new(&url, Some(admin.clone())).unwrap();
    assert!(client.send(Method::GET, "/v1/robots", None, &[]).await.unwrap().status.is_success());
    let made: Value = client.post("/v1/tokens", &json!({"name": "dash", "scopes": ["read"]})).await.unwrap();
    let reader = made["token"].as_str().unwrap().to_string();
    let reader_client = robocal::http::client::Client::new(&url, Some(reader.clone())).unwrap();
    // Refused: the wrong scope, and after revocation.
    let r =
        reader_client.send(Method::POST, "/v1/robots", Some(("application/json", b"{}".to_vec())), &[]).await.unwrap();
    assert_eq!(r.status, 403);
    let id = made["id"].as_str().unwrap();
    assert_eq!(client.send(Method::DELETE, &format!("/v1/tokens/{id}"), None, &[]).await.unwrap().status, 204);
    assert_eq!(reader_client.send(Method::GET, "/v1/robots", None, &[]).await.unwrap().status, 401);
    // A token-shaped secret that is unknown.
    let stranger = "rc_ffffffffffffffffffffffffffffffffffffffffffff";
    let c = robocal::http::client::Client::new(&url, Some(stranger.into())).unwrap();
    assert_eq!(c.send(Method::GET, "/v1/robots", None, &[]).await.unwrap().status, 401);

    assert!(Command::new("kill").args(["-TERM", &server.id().to_string()]).status().unwrap().success());
    let t = Instant::now();
    while server.try_wait().unwrap().is_none() {
        assert!(t.elapsed() < Duration::from_secs(30), "the server did not stop");
        std::thread::sleep(Duration::from_millis(20));
    }
    let text = std::fs::read_to_string(&log).unwrap();
    assert!(text.contains("/v1/robots") && text.contains("/v1/tokens"), "the log records the requests:\n{text}");
    for secret in [&admin, &reader, &stranger.to_string()] {
        assert!(!text.contains(secret.as_str()), "a token in the log");
        // Nor its hash, which would let a log reader match a stored row to a request.
        assert!(!text.contains(&tokens::hash(secret)), "a token's hash in the log");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
