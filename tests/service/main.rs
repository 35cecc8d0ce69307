//! The service's HTTP and job suites in one test binary, run on both backends (issue 27): `cargo
//! test` runs it on SQLite, and the PostgreSQL pass runs the same binary again, without building
//! anything more:
//!
//! ```sh
//! export ROBOCAL_TEST_PG=$(scripts/pg_cluster.sh start)
//! ROBOCAL_TEST_BACKEND=postgres cargo test --locked --test service
//! ```
//!
//! The backend is the one `ROBOCAL_TEST_BACKEND` names (`tests/common`): unset, each `TestApp`
//! has a fresh SQLite file; `postgres`, a fresh database of its own on the server
//! `ROBOCAL_TEST_PG` names, dropped with it. Both backends pass the same assertions. One binary
//! rather than one per suite: each test binary links the whole service, and the suites share
//! their helpers (`tests/common`), compiled once here.

#[path = "../common/mod.rs"]
mod common;

mod cancel_race;
mod held_out;
mod http_api;
mod http_diagnosis;
mod http_history;
mod http_programs;
mod http_reports;
mod iso9283_http;
/// Several replicas on one PostgreSQL database; skipped on SQLite.
mod replicas;
mod security;
