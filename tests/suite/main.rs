//! Every suite that does not run on both backends, in one test binary: the numerical core against
//! its references (published tables, finite differences, a second implementation, the real UR10
//! data), the CLI and the real `robocal serve` process, the importers, the parsers under fuzzing,
//! crash safety, README's commands, and the PostgreSQL-specific checks (`migrate`, the two
//! migration sets), which skip loudly without `ROBOCAL_TEST_PG`.
//!
//! One binary rather than one per suite, as `tests/service/` is: every test binary links the
//! whole service (≈ 120 MB each unoptimised), so thirty-odd of them cost CI minutes of linking and
//! disk, and `tests/common` is compiled once here. One suite alone: `cargo test --test suite
//! cli::` (a module path filters its tests).

#[path = "../common/mod.rs"]
mod common;

mod cli;
mod cli_exports;
mod crash_safety;
mod crossval;
mod demo;
mod detmax;
mod diagnosis;
mod examples;
mod extreme_inputs;
mod fuzz_parsers;
mod hostile_clients;
mod identify_accuracy;
mod import;
mod iso9283;
mod migrate_pg;
mod migrations;
mod peer_rtb;
mod poses;
mod postgres_schema;
mod program_filter;
mod program_fuzz;
/// Controller programs generated for the filter and fuzz suites.
mod programs;
mod properties;
mod readme;
mod real_data;
mod server_process;
mod study;
mod three_reflectors;
mod uncertainty;
mod ur10_calibration;
mod validation;
mod virtual_cell;
