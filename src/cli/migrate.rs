//! `robocal migrate`: a SQLite store copied into PostgreSQL, verified table by table
//! (`db::transfer`).

use std::str::FromStr;

use clap::Args;
use sqlx::postgres::PgConnectOptions;

use super::CliError;
use crate::db::transfer::{self, Options, TransferError};

#[derive(Args, Debug)]
pub struct MigrateArgs {
    /// The SQLite database to copy: `sqlite:PATH` or a plain path. Opened read-only; it must be
    /// at this robocal's latest migration, and no server may be running on it.
    #[arg(long)]
    pub from: String,
    /// The PostgreSQL database to fill: `postgres://user[:password]@host[:port]/database`. It must
    /// be empty (or hold an unfinished migration of the same source, which is then resumed).
    #[arg(long)]
    pub to: String,
    /// Rows per batch (each batch is one transaction).
    #[arg(long, default_value_t = 1000)]
    pub batch_rows: usize,
}

pub(super) fn migrate(a: MigrateArgs) -> Result<String, CliError> {
    if a.batch_rows == 0 {
        return Err(CliError::arg("--batch-rows", "must be at least 1"));
    }
    let source = transfer::source_path(&a.from);
    if !(a.to.starts_with("postgres://") || a.to.starts_with("postgresql://")) {
        return Err(CliError::arg("--to", "expected a postgres://user@host/database URL"));
    }
    let target =
        PgConnectOptions::from_str(&a.to).map_err(|e| CliError::arg("--to", format!("not a PostgreSQL URL: {e}")))?;
    // No server may write the source while it is copied (what it wrote after the snapshot would
    // be lost); a reader's share of the server's lock also keeps one from starting meanwhile, and
    // lets two migrations read one source at once. A source in a
    // directory where the lock file cannot be made (a read-only copy) has no server either.
    // (A missing source gets no lock file: `prepare` refuses it.)
    let _lock = if source.is_file() {
        match crate::server::lock::DbLock::acquire_shared(&source) {
            Ok(lock) => lock,
            Err(e @ crate::server::lock::LockError::Held { .. }) => {
                return Err(CliError::msg(format!("--from: {e}; stop it before migrating")));
            }
            Err(e) => {
                eprintln!("note: {e}; going on without the server lock");
                None
            }
        }
    } else {
        None
    };
    let opts = Options { batch_rows: a.batch_rows, stop_after_batches: None };
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError::msg(format!("cannot start the async runtime: {e}")))?;
    let mut progress = |line: &str| eprintln!("{line}");
    let verification = rt.block_on(transfer::migrate(&source, &target, &opts, &mut progress)).map_err(|e| match e {
        TransferError::Source { .. } | TransferError::SourceNotMigrated { .. } => CliError::msg(format!("--from: {e}")),
        TransferError::Unreachable { .. } => CliError::msg(format!("--to: {e}")),
        e => CliError::msg(e.to_string()),
    })?;
    let table = verification.table();
    if verification.ok() {
        Ok(format!(
            "{table}\nmigrated {} into {}: every table's rows and checksum match",
            source.display(),
            transfer::server_label(&target)
        ))
    } else {
        Err(CliError::failed(
            Some(table),
            format!(
                "the copy differs from the source in {}: the target keeps its migration marker; empty it and migrate again",
                verification.mismatched().join(", ")
            ),
        ))
    }
}
