//! One server per database, enforced: `robocal serve` holds an exclusive OS lock on a lock file
//! beside its database (`robocal.db` → `robocal.db.lock`) for as long as it runs. A second server
//! on the same database finds it locked and refuses to start, before it opens the database,
//! naming the first one (PID, address, start time: what the holder wrote into the lock file).
//!
//! The lock is the operating system's (`flock(2)` on Unix, `LockFileEx` on Windows, through the
//! standard library's `File::try_lock`), held on the open file: it goes when the process goes,
//! however it ends, so a killed server (SIGKILL, a crash, a power cut) leaves no stale lock. The
//! file itself stays (emptied on a clean stop): deleting a lock file another process may have just
//! opened would let two processes each lock a different file of the same name.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{self, Read, Seek, SeekFrom, Write};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use serde::{Deserialize, Serialize};

/// Why the lock could not be taken.
#[derive(Debug, thiserror::Error)]
pub enum LockError {
    #[error(
        "the database {db} is served by another robocal process ({holder}); one server per database: its caches would go stale"
    )]
    Held { db: String, holder: String },
    #[error(
        "the database {db} is being read by `robocal migrate` (a shared lock); start the server once it has finished"
    )]
    Read { db: String },
    #[error("cannot lock the database {db} ({path}): {source}")]
    Io { db: String, path: String, source: io::Error },
}

/// What the holder writes into the lock file: who it is, where it listens, since when.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Holder {
    pub pid: u32,
    /// The bound address; `None` while the server is still opening its database.
    pub addr: Option<String>,
    /// RFC 3339, UTC.
    pub since: String,
}

impl Holder {
    fn describe(&self) -> String {
        let at = match &self.addr {
            Some(a) => format!("listening on {a}"),
            None => "starting, not listening yet".to_string(),
        };
        format!("PID {}, {at}, since {}", self.pid, self.since)
    }
}

/// The lock on a database; released when dropped (and by the OS if the process dies). A server's
/// is exclusive; a reader's (`robocal migrate` copying the database) is shared: readers exclude a
/// server, not each other, and write nothing into the file (they cannot all write it).
#[derive(Debug)]
pub struct DbLock {
    file: File,
    path: PathBuf,
    holder: Holder,
    shared: bool,
}

/// The lock file of the database at `db`: beside it, its file name with `.lock` appended, in the
/// database's real directory (symbolic links resolved, so two spellings of one database share a
/// lock). The database itself need not exist yet; its directory must.
pub fn lock_path(db: &Path) -> io::Result<(PathBuf, PathBuf)> {
    let name = db.file_name().ok_or_else(|| io::Error::other("the database path names no file"))?;
    let db = match std::fs::canonicalize(db) {
        Ok(p) => p,
        Err(e) if e.kind() == io::ErrorKind::NotFound => {
            let dir = db.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
            std::fs::canonicalize(dir)?.join(name)
        }
        Err(e) => return Err(e),
    };
    let mut lock = db.clone().into_os_string();
    lock.push(".lock");
    Ok((db, PathBuf::from(lock)))
}

impl DbLock {
    /// Take the lock of the database at `db`, or say who holds it. `Ok(None)` for SQLite's
    /// `:memory:`, which no other process can open.
    pub fn acquire(db: &Path) -> Result<Option<DbLock>, LockError> {
        Self::take(db, false)
    }

    /// A reader's lock: shared with other readers, refused while a server holds the database
    /// (naming it), and keeping one from starting until it is dropped.
    pub fn acquire_shared(db: &Path) -> Result<Option<DbLock>, LockError> {
        Self::take(db, true)
    }

    fn take(db: &Path, shared: bool) -> Result<Option<DbLock>, LockError> {
        if db.as_os_str() == ":memory:" {
            return Ok(None);
        }
        let shown = db.display().to_string();
        let (db, path) = lock_path(db).map_err(|source| LockError::Io {
            db: shown.clone(),
            path: format!("{shown}.lock"),
            source,
        })?;
        let io_error =
            |source| LockError::Io { db: db.display().to_string(), path: path.display().to_string(), source };
        let mut file =
            OpenOptions::new().read(true).write(true).create(true).truncate(false).open(&path).map_err(io_error)?;
        let taken = if shared { file.try_lock_shared() } else { file.try_lock() };
        match taken {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => {
                // Refused an exclusive lock: if a shared one is granted, only readers hold it.
                if !shared && file.try_lock_shared().is_ok() {
                    let _ = file.unlock();
                    return Err(LockError::Read { db: db.display().to_string() });
                }
                return Err(LockError::Held { db: db.display().to_string(), holder: read_holder(&mut file) });
            }
            Err(TryLockError::Error(e)) => return Err(io_error(e)),
        }
        let holder = Holder {
            pid: std::process::id(),
            addr: None,
            since: humantime::format_rfc3339_seconds(SystemTime::now()).to_string(),
        };
        let mut lock = DbLock { file, path: path.clone(), holder, shared };
        if !shared {
            lock.write().map_err(io_error)?;
        }
        Ok(Some(lock))
    }

    /// Record the address the server listens on (once it is bound).
    pub fn listening(&mut self, addr: SocketAddr) -> io::Result<()> {
        debug_assert!(!self.shared, "a reader does not listen");
        self.holder.addr = Some(addr.to_string());
        self.write()
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn holder(&self) -> &Holder {
        &self.holder
    }

    fn write(&mut self) -> io::Result<()> {
        let mut text = serde_json::to_string(&self.holder).expect("json");
        text.push('\n');
        self.file.set_len(0)?;
        self.file.seek(SeekFrom::Start(0))?;
        self.file.write_all(text.as_bytes())?;
        self.file.flush()
    }
}

impl Drop for DbLock {
    /// Empty the file (what it says is true only while it is locked), then release the lock
    /// explicitly. Closing the handle alone is not enough: the lock belongs to the open file
    /// description, which a process forked by this one in the meantime (a test harness or a demo
    /// spawning a child, between its fork and its exec) still shares — the lock would outlive
    /// this server by that window, and the next server on the database be refused
    /// ("its lock file says nothing yet"). An unlock releases it for every sharer.
    fn drop(&mut self) {
        if !self.shared {
            let _ = self.file.set_len(0);
        }
        let _ = self.file.unlock();
    }
}

/// Who holds the lock, as well as the lock file says: the holder may be between emptying and
/// writing it, so a file that does not parse is read again a few times.
fn read_holder(file: &mut File) -> String {
    for attempt in 0..5 {
        if attempt > 0 {
            std::thread::sleep(Duration::from_millis(20));
        }
        let mut text = String::new();
        if file.seek(SeekFrom::Start(0)).is_ok()
            && file.read_to_string(&mut text).is_ok()
            && let Ok(h) = serde_json::from_str::<Holder>(text.trim())
        {
            return h.describe();
        }
    }
    "PID unknown: its lock file says nothing yet".to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("robocal-lock-{tag}-{}-{}", std::process::id(), crate::db::new_id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn a_second_lock_on_one_database_is_refused_naming_the_first() {
        let d = dir("second");
        let db = d.join("robocal.db");
        let mut first = DbLock::acquire(&db).unwrap().unwrap();
        assert_eq!(first.path(), std::fs::canonicalize(&d).unwrap().join("robocal.db.lock"));
        let e = DbLock::acquire(&db).unwrap_err().to_string();
        assert!(e.contains(&format!("PID {}", std::process::id())) && e.contains("not listening yet"), "{e}");
        first.listening("127.0.0.1:8123".parse().unwrap()).unwrap();
        // Another spelling of the same database (relative to a symlinked or `..` path) is the same lock.
        let other = d.join("..").join(d.file_name().unwrap()).join("robocal.db");
        let e = DbLock::acquire(&other).unwrap_err().to_string();
        assert!(e.contains("listening on 127.0.0.1:8123") && e.contains("one server per database"), "{e}");
        assert!(e.contains(&std::fs::canonicalize(&d).unwrap().join("robocal.db").display().to_string()), "{e}");
        drop(first);
        // Released, and the file emptied.
        assert_eq!(std::fs::read_to_string(d.join("robocal.db.lock")).unwrap(), "");
        let again = DbLock::acquire(&db).unwrap().unwrap();
        let written: Holder = serde_json::from_str(&std::fs::read_to_string(again.path()).unwrap()).unwrap();
        assert_eq!(written, *again.holder());
        drop(again);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn readers_share_the_lock_and_exclude_a_server() {
        let d = dir("shared");
        let db = d.join("robocal.db");
        let first = DbLock::acquire_shared(&db).unwrap().unwrap();
        let second = DbLock::acquire_shared(&db).unwrap().unwrap();
        let e = DbLock::acquire(&db).unwrap_err();
        assert!(matches!(e, LockError::Read { .. }) && e.to_string().contains("robocal migrate"), "{e}");
        drop(first);
        assert!(matches!(DbLock::acquire(&db), Err(LockError::Read { .. })));
        drop(second);
        // A server's lock refuses a reader, naming the server; the file a reader leaves is empty.
        assert_eq!(std::fs::read_to_string(d.join("robocal.db.lock")).unwrap(), "");
        let server = DbLock::acquire(&db).unwrap().unwrap();
        let e = DbLock::acquire_shared(&db).unwrap_err().to_string();
        assert!(e.contains(&format!("PID {}", std::process::id())) && e.contains("one server per database"), "{e}");
        drop(server);
        assert!(DbLock::acquire_shared(&db).unwrap().is_some());
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn memory_databases_need_no_lock_and_a_missing_directory_is_an_error() {
        assert!(DbLock::acquire(Path::new(":memory:")).unwrap().is_none());
        let d = dir("missing");
        let e = DbLock::acquire(&d.join("no-such-dir").join("robocal.db")).unwrap_err();
        assert!(matches!(e, LockError::Io { .. }), "{e}");
        let _ = std::fs::remove_dir_all(&d);
    }
}
