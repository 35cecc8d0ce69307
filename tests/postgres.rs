//! The HTTP and job suites in one test binary, so that their PostgreSQL pass (issue 27) costs one
//! build and one run, not one per file:
//!
//! ```sh
//! export ROBOCAL_TEST_PG=$(scripts/pg_cluster.sh start)
//! ROBOCAL_TEST_BACKEND=postgres cargo test --locked --test postgres
//! ```
//!
//! The backend is the one `ROBOCAL_TEST_BACKEND` names (`tests/common`): each `TestApp` gets a
//! fresh database of its own on the server `ROBOCAL_TEST_PG` names, dropped with it. Each suite
//! is the very file `cargo test` runs on SQLite, included here as a module, so both backends pass
//! the same assertions. `cargo test` does not run this binary (`test = false` in Cargo.toml): on
//! SQLite it would repeat the suites it already ran.

// Each suite declares `tests/common` itself (it is also a test binary of its own), so the helpers
// are loaded once per suite here: the copies are identical and private to their suite.
#![allow(clippy::duplicate_mod)]

#[path = "http_api.rs"]
mod http_api;

#[path = "cancel_race.rs"]
mod cancel_race;

#[path = "http_history.rs"]
mod http_history;

#[path = "iso9283_http.rs"]
mod iso9283_http;

#[path = "security.rs"]
mod security;

#[path = "held_out.rs"]
mod held_out;

#[path = "http_programs.rs"]
mod http_programs;

#[path = "http_reports.rs"]
mod http_reports;

#[path = "replicas.rs"]
mod replicas;
