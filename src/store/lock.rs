//! One owner per store: an exclusive `flock` on a lock file beside the database
//! (`brdfd.db` → `brdfd.db.lock`), taken by every command that writes the store (`serve`,
//! `demo`, `replay --db`, …) and held for as long as the store is open.
//!
//! Why a lock file and not SQLite's own locking: SQLite serialises single writes, but two
//! daemons on one file would each believe they own its life cycles (the second marks the first
//! one's live scan "failed: daemon stopped during the scan" and re-queues its fits). `flock` is
//! released by the kernel when the holder exits, however it exits, so a crashed daemon never
//! leaves a stale lock; the file keeps the last holder's PID and address for the refusal
//! message and for `brdfd doctor`. Read-only commands (`report`, `export-format`) take no lock
//! and open the database read-only.

use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};

/// Why the store's lock could not be taken.
#[derive(Debug, thiserror::Error)]
pub enum LockError {
    #[error(
        "the store {store} is in use by another brdfd ({holder}); stop it first, or use a read-only \
         command (`brdfd report`, `brdfd export-format`) or the operator commands, which talk to it"
    )]
    Held { store: PathBuf, holder: String },
    #[error(
        "cannot open the store's lock file {path}: {source}; check that brdfd's user can write to its directory"
    )]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// The lock file of the store at `db`.
pub fn lock_path(db: &Path) -> PathBuf {
    let mut name = db.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(".lock");
    db.with_file_name(name)
}

/// A held store lock; released when dropped.
#[derive(Debug)]
pub struct StoreLock {
    file: File,
    path: PathBuf,
}

impl StoreLock {
    /// Takes the lock of the store at `db`, at once or not at all, and records this process as
    /// the holder (`holder` adds what it is, e.g. "brdfd serve").
    pub fn acquire(db: &Path, holder: &str) -> Result<StoreLock, LockError> {
        let path = lock_path(db);
        let io = |source| LockError::Io {
            path: lock_path(db),
            source,
        };
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .mode(crate::safe_fs::private_mode())
            .open(&path)
            .map_err(io)?;
        if !try_lock_exclusive(&file).map_err(io)? {
            let mut text = String::new();
            let _ = file.read_to_string(&mut text);
            let holder = text.trim();
            return Err(LockError::Held {
                store: db.to_path_buf(),
                holder: if holder.is_empty() {
                    "a process that has not said who it is".into()
                } else {
                    holder.replace('\n', ", ")
                },
            });
        }
        let mut lock = StoreLock { file, path };
        lock.describe(holder).map_err(io)?;
        Ok(lock)
    }

    /// Rewrites what the lock file says of its holder (e.g. once the API address is known).
    pub fn describe(&mut self, what: &str) -> std::io::Result<()> {
        self.file.set_len(0)?;
        self.file.seek(SeekFrom::Start(0))?;
        writeln!(self.file, "pid {} — {what}", std::process::id())?;
        self.file.flush()
    }

    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// Whoever holds the lock of the store at `db` now: `Ok(None)` when nobody does (any PID in
/// the file is then a process that has ended), else its description. Takes the lock for an
/// instant to find out, so never call it on a store this process holds.
pub fn holder(db: &Path) -> std::io::Result<Option<String>> {
    let path = lock_path(db);
    let mut file = match OpenOptions::new().read(true).write(true).open(&path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e),
    };
    if try_lock_exclusive(&file)? {
        // Dropping the file releases it again.
        return Ok(None);
    }
    let mut text = String::new();
    file.read_to_string(&mut text)?;
    Ok(Some(text.trim().to_string()))
}

#[cfg(unix)]
fn try_lock_exclusive(file: &File) -> std::io::Result<bool> {
    use std::os::unix::io::AsRawFd;
    // SAFETY: flock on a file descriptor we own; no memory is touched.
    let r = unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) };
    if r == 0 {
        return Ok(true);
    }
    let e = std::io::Error::last_os_error();
    if e.raw_os_error() == Some(libc::EWOULDBLOCK) {
        Ok(false)
    } else {
        Err(e)
    }
}

#[cfg(not(unix))]
fn try_lock_exclusive(file: &File) -> std::io::Result<bool> {
    file.try_lock().map(|()| true).or_else(|e| match e {
        std::fs::TryLockError::WouldBlock => Ok(false),
        std::fs::TryLockError::Error(e) => Err(e),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_owner_is_refused_naming_the_first_and_the_lock_ends_with_it() {
        let dir = tempfile::tempdir().unwrap();
        let db = dir.path().join("brdfd.db");
        assert_eq!(lock_path(&db), dir.path().join("brdfd.db.lock"));
        assert_eq!(holder(&db).unwrap(), None);
        let mut first = StoreLock::acquire(&db, "brdfd serve").unwrap();
        first
            .describe("brdfd serve on http://127.0.0.1:7878")
            .unwrap();
        let e = StoreLock::acquire(&db, "brdfd replay").unwrap_err();
        let shown = e.to_string();
        assert!(
            shown.contains(&format!(
                "pid {} — brdfd serve on http://127.0.0.1:7878",
                std::process::id()
            )),
            "{shown}"
        );
        assert!(shown.contains("stop it first"), "{shown}");
        assert!(holder(&db).unwrap().unwrap().contains("127.0.0.1:7878"));
        drop(first);
        // The file still names the old holder, but nobody holds the lock.
        assert_eq!(holder(&db).unwrap(), None);
        let _again = StoreLock::acquire(&db, "brdfd replay").unwrap();
    }
}
