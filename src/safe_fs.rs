//! Every file brdfd writes outside its store goes through this module: exports and scan files
//! (`--out`), reports and their figures, preview PNGs, session recordings and the watch
//! folder's notes and moves. The rules, the same everywhere:
//!
//! - **Never through a symbolic link.** A directory is opened once with `O_NOFOLLOW` and held
//!   ([`Dir`]); files are created relative to it with `O_CREAT | O_EXCL | O_NOFOLLOW`, which
//!   fails on any existing name, a link included; files are read with `O_NOFOLLOW` too.
//! - **Never onto a protected file.** The store, its `-wal`, `-shm` and `-journal` files, its
//!   lock and the API token are registered ([`protect`], [`protect_store`]) by whoever opens
//!   them; a name that is one of them (by path, or by device and inode: a hard link) is refused,
//!   with or without `--force`.
//! - **`--force` replaces only a file of brdfd's own kind:** a regular file with one link that
//!   is not an SQLite database or log (by content) and not named like a store's, lock's or
//!   token's file (`*.db`, `*-wal`, `*-shm`, `*-journal`, `*.lock`, `*.token`, `*.sessions`). The new content goes to a fresh temporary file in the same
//!   directory, which is then renamed over the old name: a rename replaces the name and never
//!   writes into what it pointed at.
//! - **Moves never replace.** [`Dir::move_to`] renames with `RENAME_NOREPLACE`.
//!
//! Errors name the file and say what to do ([`FsError`]).

use std::ffi::{CString, OsStr};
use std::io::{Read, Write};
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::os::unix::ffi::OsStrExt;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Why a file could not be written, read or moved.
#[derive(Debug, thiserror::Error)]
pub enum FsError {
    #[error(
        "{path} is a symbolic link: brdfd writes and reads only real files and folders there; \
         remove the link or choose another path"
    )]
    Symlink { path: PathBuf },
    #[error(
        "{path} is {what}, not a file brdfd wrote: it is never replaced, even with --force; \
         choose another path"
    )]
    NotOurs { path: PathBuf, what: &'static str },
    #[error(
        "{path} is {what}: brdfd never writes there, with or without --force; choose another \
         path"
    )]
    Protected { path: PathBuf, what: String },
    #[error("{path} exists already: choose another name, or pass --force to replace it")]
    Exists { path: PathBuf },
    #[error("{path} is {size} bytes, over the limit of {max} bytes{hint}")]
    TooLarge {
        path: PathBuf,
        size: u64,
        max: u64,
        hint: &'static str,
    },
    #[error("{path} is not a regular file ({what}); brdfd reads only regular files there")]
    NotRegular { path: PathBuf, what: &'static str },
    #[error("cannot {op} {path}: {source}")]
    Io {
        op: &'static str,
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

impl FsError {
    fn io(op: &'static str, path: impl Into<PathBuf>, source: std::io::Error) -> FsError {
        let path = path.into();
        if source.raw_os_error() == Some(libc::ELOOP) {
            return FsError::Symlink { path };
        }
        FsError::Io { op, path, source }
    }
}

/// A protected file: its path as given and, once it exists, its device and inode.
#[derive(Debug, Clone)]
struct Protected {
    path: PathBuf,
    what: String,
}

static PROTECTED: Mutex<Vec<Protected>> = Mutex::new(Vec::new());

/// Registers a file nothing brdfd writes may replace (`what` names it in the refusal).
pub fn protect(path: &Path, what: &str) {
    let path = absolute(path);
    let mut list = PROTECTED.lock().unwrap_or_else(|p| p.into_inner());
    if !list.iter().any(|p| p.path == path) {
        list.push(Protected {
            path,
            what: what.to_string(),
        });
    }
}

/// Registers a store file and every file SQLite and brdfd keep beside it.
pub fn protect_store(db: &Path) {
    protect(db, "the store");
    for suffix in ["-wal", "-shm", "-journal", ".lock"] {
        let mut name = db.as_os_str().to_os_string();
        name.push(suffix);
        protect(Path::new(&name), &format!("the store's {suffix} file"));
    }
}

/// `path` made absolute (its directory resolved as far as it exists), for comparing names.
fn absolute(path: &Path) -> PathBuf {
    let (Some(parent), Some(name)) = (path.parent(), path.file_name()) else {
        return path.to_path_buf();
    };
    let parent = if parent.as_os_str().is_empty() {
        Path::new(".")
    } else {
        parent
    };
    match std::fs::canonicalize(parent) {
        Ok(p) => p.join(name),
        Err(_) => std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf()),
    }
}

/// The protected file `path` is, if any: by name, or (for an existing file) by device and
/// inode, which also catches a hard link.
fn protected(path: &Path, id: Option<(u64, u64)>) -> Option<String> {
    let path = absolute(path);
    let list = PROTECTED.lock().unwrap_or_else(|p| p.into_inner()).clone();
    list.into_iter().find_map(|p| {
        let same_name = p.path == path;
        let same_file = id.is_some_and(|id| {
            std::fs::metadata(&p.path)
                .ok()
                .is_some_and(|m| file_id(&m) == id)
        });
        (same_name || same_file).then_some(p.what)
    })
}

fn file_id(m: &std::fs::Metadata) -> (u64, u64) {
    use std::os::unix::fs::MetadataExt;
    (m.dev(), m.ino())
}

fn cstr(name: &OsStr) -> Result<CString, std::io::Error> {
    CString::new(name.as_bytes())
        .map_err(|_| std::io::Error::new(std::io::ErrorKind::InvalidInput, "a NUL byte in a name"))
}

/// What `fstatat(…, AT_SYMLINK_NOFOLLOW)` says about an entry.
#[derive(Debug, Clone, Copy)]
pub struct Entry {
    pub kind: EntryKind,
    pub size: u64,
    pub links: u64,
    pub mtime: Option<std::time::SystemTime>,
    pub id: (u64, u64),
}

/// The kind of a directory entry, links not followed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EntryKind {
    File,
    Dir,
    Symlink,
    Other,
}

impl EntryKind {
    fn described(self) -> &'static str {
        match self {
            EntryKind::File => "a file",
            EntryKind::Dir => "a folder",
            EntryKind::Symlink => "a symbolic link",
            EntryKind::Other => "a device, pipe or socket",
        }
    }
}

fn entry_of(st: &libc::stat) -> Entry {
    let kind = match st.st_mode & libc::S_IFMT {
        libc::S_IFREG => EntryKind::File,
        libc::S_IFDIR => EntryKind::Dir,
        libc::S_IFLNK => EntryKind::Symlink,
        _ => EntryKind::Other,
    };
    let mtime = (st.st_mtime >= 0).then(|| {
        std::time::UNIX_EPOCH
            + std::time::Duration::new(
                st.st_mtime as u64,
                st.st_mtime_nsec.clamp(0, 999_999_999) as u32,
            )
    });
    Entry {
        kind,
        size: st.st_size.max(0) as u64,
        links: st.st_nlink as u64,
        mtime,
        id: (st.st_dev as u64, st.st_ino as u64),
    }
}

/// How [`Dir::write`] treats a name that exists.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Replace {
    /// Refuse ([`FsError::Exists`]).
    Never,
    /// Replace it if it is a file of brdfd's own kind (`--force`).
    OwnKind,
}

impl Replace {
    pub fn force(force: bool) -> Replace {
        if force {
            Replace::OwnKind
        } else {
            Replace::Never
        }
    }
}

/// A directory opened once (`O_DIRECTORY | O_NOFOLLOW`) and held: everything in it is reached
/// relative to this handle, so a folder renamed or swapped for a link afterwards does not
/// redirect anything.
#[derive(Debug)]
pub struct Dir {
    fd: OwnedFd,
    path: PathBuf,
}

impl Dir {
    /// Opens the directory at `path`; refused if it is a symbolic link.
    pub fn open(path: &Path) -> Result<Dir, FsError> {
        let c = cstr(path.as_os_str()).map_err(|e| FsError::io("open", path, e))?;
        let fd = unsafe {
            libc::open(
                c.as_ptr(),
                libc::O_RDONLY | libc::O_DIRECTORY | libc::O_NOFOLLOW | libc::O_CLOEXEC,
            )
        };
        if fd < 0 {
            let e = std::io::Error::last_os_error();
            // O_DIRECTORY | O_NOFOLLOW on a link fails with ENOTDIR (or ELOOP).
            if std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink()) {
                return Err(FsError::Symlink {
                    path: path.to_path_buf(),
                });
            }
            return Err(FsError::io("open the folder", path, e));
        }
        Ok(Dir {
            fd: unsafe { OwnedFd::from_raw_fd(fd) },
            path: path.to_path_buf(),
        })
    }

    /// Opens the directory at `path`, following it if it is a link (a path the user or the
    /// configuration named), and holds it from then on.
    pub fn open_following(path: &Path) -> Result<Dir, FsError> {
        let c = cstr(path.as_os_str()).map_err(|e| FsError::io("open", path, e))?;
        let fd = unsafe {
            libc::open(
                c.as_ptr(),
                libc::O_RDONLY | libc::O_DIRECTORY | libc::O_CLOEXEC,
            )
        };
        if fd < 0 {
            return Err(FsError::io(
                "open the folder",
                path,
                std::io::Error::last_os_error(),
            ));
        }
        Ok(Dir {
            fd: unsafe { OwnedFd::from_raw_fd(fd) },
            path: path.to_path_buf(),
        })
    }

    /// Creates the directory at `path` if missing (its parents too), then opens it; refused if
    /// it is a symbolic link.
    pub fn create(path: &Path) -> Result<Dir, FsError> {
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).map_err(|e| FsError::io("create", parent, e))?;
        }
        match std::fs::create_dir(path) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(e) => return Err(FsError::io("create", path, e)),
        }
        Dir::open(path)
    }

    /// A second handle on the same directory.
    pub fn try_clone(&self) -> Result<Dir, FsError> {
        Ok(Dir {
            fd: self
                .fd
                .try_clone()
                .map_err(|e| FsError::io("open the folder", &self.path, e))?,
            path: self.path.clone(),
        })
    }

    /// A path that leads to this directory itself whatever is renamed or swapped meanwhile
    /// (`/proc/self/fd/N` on Linux), for libraries that write to paths; elsewhere its path.
    pub fn held_path(&self) -> PathBuf {
        let proc = PathBuf::from(format!("/proc/self/fd/{}", self.fd.as_raw_fd()));
        if proc.is_dir() {
            proc
        } else {
            self.path.clone()
        }
    }

    /// The path it was opened as (for messages; nothing is reached through it).
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn at(&self, name: &str) -> PathBuf {
        self.path.join(name)
    }

    /// Its device and inode.
    pub fn id(&self) -> Result<(u64, u64), FsError> {
        let mut st: libc::stat = unsafe { std::mem::zeroed() };
        if unsafe { libc::fstat(self.fd.as_raw_fd(), &mut st) } != 0 {
            return Err(FsError::io(
                "stat",
                &self.path,
                std::io::Error::last_os_error(),
            ));
        }
        Ok((st.st_dev as u64, st.st_ino as u64))
    }

    /// The entry `name`, links not followed; `None` if there is none.
    pub fn entry(&self, name: &str) -> Result<Option<Entry>, FsError> {
        let c = cstr(OsStr::new(name)).map_err(|e| FsError::io("stat", self.at(name), e))?;
        let mut st: libc::stat = unsafe { std::mem::zeroed() };
        let r = unsafe {
            libc::fstatat(
                self.fd.as_raw_fd(),
                c.as_ptr(),
                &mut st,
                libc::AT_SYMLINK_NOFOLLOW,
            )
        };
        if r != 0 {
            let e = std::io::Error::last_os_error();
            if e.kind() == std::io::ErrorKind::NotFound {
                return Ok(None);
            }
            return Err(FsError::io("stat", self.at(name), e));
        }
        Ok(Some(entry_of(&st)))
    }

    /// The names in the directory (not `.` and `..`), each with its entry, links not
    /// followed. Names that are not UTF-8 are skipped.
    pub fn list(&self) -> Result<Vec<(String, Entry)>, FsError> {
        let dup = unsafe { libc::fcntl(self.fd.as_raw_fd(), libc::F_DUPFD_CLOEXEC, 0) };
        if dup < 0 {
            return Err(FsError::io(
                "list",
                &self.path,
                std::io::Error::last_os_error(),
            ));
        }
        let d = unsafe { libc::fdopendir(dup) };
        if d.is_null() {
            let e = std::io::Error::last_os_error();
            unsafe { libc::close(dup) };
            return Err(FsError::io("list", &self.path, e));
        }
        // fdopendir shares the offset of the descriptor it was given: start at the beginning.
        unsafe { libc::rewinddir(d) };
        let mut names = Vec::new();
        loop {
            let ent = unsafe { libc::readdir(d) };
            if ent.is_null() {
                break;
            }
            let name = unsafe { std::ffi::CStr::from_ptr((*ent).d_name.as_ptr()) };
            if let Ok(n) = name.to_str()
                && n != "."
                && n != ".."
            {
                names.push(n.to_string());
            }
        }
        unsafe { libc::closedir(d) };
        let mut out = Vec::with_capacity(names.len());
        for name in names {
            // A name gone meanwhile is skipped.
            if let Some(e) = self.entry(&name)? {
                out.push((name, e));
            }
        }
        out.sort_by(|a, b| a.0.cmp(&b.0));
        Ok(out)
    }

    /// Opens the subdirectory `name`, creating it if missing; refused if it is a link.
    pub fn subdir(&self, name: &str) -> Result<Dir, FsError> {
        let c = cstr(OsStr::new(name)).map_err(|e| FsError::io("create", self.at(name), e))?;
        let r = unsafe { libc::mkdirat(self.fd.as_raw_fd(), c.as_ptr(), 0o755) };
        if r != 0 {
            let e = std::io::Error::last_os_error();
            if e.kind() != std::io::ErrorKind::AlreadyExists {
                return Err(FsError::io("create", self.at(name), e));
            }
        }
        let fd = unsafe {
            libc::openat(
                self.fd.as_raw_fd(),
                c.as_ptr(),
                libc::O_RDONLY | libc::O_DIRECTORY | libc::O_NOFOLLOW | libc::O_CLOEXEC,
            )
        };
        if fd < 0 {
            let e = std::io::Error::last_os_error();
            if matches!(self.entry(name), Ok(Some(en)) if en.kind == EntryKind::Symlink) {
                return Err(FsError::Symlink {
                    path: self.at(name),
                });
            }
            return Err(FsError::io("open the folder", self.at(name), e));
        }
        Ok(Dir {
            fd: unsafe { OwnedFd::from_raw_fd(fd) },
            path: self.at(name),
        })
    }

    /// A new private directory (mode 0700) with a random name starting `prefix`, for files
    /// made elsewhere (by a library writing to a path) and then published with
    /// [`Dir::publish_from`].
    pub fn staging(&self, prefix: &str) -> Result<Dir, FsError> {
        let name = format!("{prefix}{}", crate::names::random_hex(8));
        let c = cstr(OsStr::new(&name)).map_err(|e| FsError::io("create", self.at(&name), e))?;
        if unsafe { libc::mkdirat(self.fd.as_raw_fd(), c.as_ptr(), 0o700) } != 0 {
            return Err(FsError::io(
                "create",
                self.at(&name),
                std::io::Error::last_os_error(),
            ));
        }
        self.subdir(&name)
    }

    /// Removes the (empty, or holding only files) subdirectory `name`.
    pub fn remove_tree(&self, name: &str) -> Result<(), FsError> {
        let sub = self.subdir(name)?;
        for (n, e) in sub.list()? {
            if e.kind != EntryKind::Dir {
                sub.unlink(&n)?;
            }
        }
        let c = cstr(OsStr::new(name)).map_err(|e| FsError::io("remove", self.at(name), e))?;
        if unsafe { libc::unlinkat(self.fd.as_raw_fd(), c.as_ptr(), libc::AT_REMOVEDIR) } != 0 {
            return Err(FsError::io(
                "remove",
                self.at(name),
                std::io::Error::last_os_error(),
            ));
        }
        Ok(())
    }

    fn unlink(&self, name: &str) -> Result<(), FsError> {
        let c = cstr(OsStr::new(name)).map_err(|e| FsError::io("remove", self.at(name), e))?;
        if unsafe { libc::unlinkat(self.fd.as_raw_fd(), c.as_ptr(), 0) } != 0 {
            return Err(FsError::io(
                "remove",
                self.at(name),
                std::io::Error::last_os_error(),
            ));
        }
        Ok(())
    }

    /// Creates `name` anew (`O_EXCL | O_NOFOLLOW`) and returns it open for writing.
    fn create_new(&self, name: &str, mode: u32) -> Result<std::fs::File, FsError> {
        let path = self.at(name);
        if let Some(what) = protected(&path, None) {
            return Err(FsError::Protected { path, what });
        }
        let c = cstr(OsStr::new(name)).map_err(|e| FsError::io("create", &path, e))?;
        let fd = unsafe {
            libc::openat(
                self.fd.as_raw_fd(),
                c.as_ptr(),
                libc::O_WRONLY | libc::O_CREAT | libc::O_EXCL | libc::O_NOFOLLOW | libc::O_CLOEXEC,
                mode as libc::c_uint,
            )
        };
        if fd < 0 {
            let e = std::io::Error::last_os_error();
            if e.kind() == std::io::ErrorKind::AlreadyExists {
                return Err(match self.entry(name) {
                    Ok(Some(en)) if en.kind == EntryKind::Symlink => FsError::Symlink { path },
                    _ => FsError::Exists { path },
                });
            }
            return Err(FsError::io("create", path, e));
        }
        Ok(unsafe { std::fs::File::from_raw_fd(fd) })
    }

    /// Checks that the existing entry `name` may be replaced under `--force`.
    fn replaceable(&self, name: &str, entry: &Entry) -> Result<(), FsError> {
        let path = self.at(name);
        if let Some(what) = protected(&path, Some(entry.id)) {
            return Err(FsError::Protected { path, what });
        }
        match entry.kind {
            EntryKind::File => {}
            EntryKind::Symlink => return Err(FsError::Symlink { path }),
            other => {
                return Err(FsError::NotOurs {
                    path,
                    what: other.described(),
                });
            }
        }
        if entry.links > 1 {
            return Err(FsError::NotOurs {
                path,
                what: "a file with other names (a hard link)",
            });
        }
        // Another store's files (not registered in this process): by name and by content.
        if [
            "-wal",
            "-shm",
            "-journal",
            ".db",
            ".lock",
            ".token",
            ".sessions",
        ]
        .iter()
        .any(|suffix| name.ends_with(suffix))
        {
            return Err(FsError::NotOurs {
                path,
                what: "named like a store, its log, lock or token",
            });
        }
        let mut head = [0u8; 16];
        if let Ok(mut f) = self.open_read(name) {
            let got = f.read(&mut head).unwrap_or(0);
            let head = &head[..got];
            let wal = head.len() >= 4 && head[..3] == [0x37, 0x7f, 0x06] && head[3] & 0xfe == 0x82;
            if head.starts_with(b"SQLite format 3\0") || wal {
                return Err(FsError::NotOurs {
                    path,
                    what: "an SQLite database or its log",
                });
            }
        }
        Ok(())
    }

    /// Writes `bytes` as the file `name`: a new file, or under [`Replace::OwnKind`] in place
    /// of an existing file of brdfd's own kind (through a temporary file and a rename).
    /// Returns the file's path.
    pub fn write(&self, name: &str, bytes: &[u8], replace: Replace) -> Result<PathBuf, FsError> {
        let path = self.at(name);
        let existing = self.entry(name)?;
        match (existing, replace) {
            (None, _) => {
                let mut f = self.create_new(name, 0o644)?;
                f.write_all(bytes)
                    .and_then(|()| f.sync_all())
                    .map_err(|e| FsError::io("write", &path, e))?;
            }
            (Some(e), Replace::Never) => {
                return Err(if e.kind == EntryKind::Symlink {
                    FsError::Symlink { path }
                } else if let Some(what) = protected(&path, Some(e.id)) {
                    FsError::Protected { path, what }
                } else {
                    FsError::Exists { path }
                });
            }
            (Some(e), Replace::OwnKind) => {
                self.replaceable(name, &e)?;
                let tmp = format!(".{name}.brdfd-{}", crate::names::random_hex(6));
                let mut f = self.create_new(&tmp, 0o644)?;
                let written = f.write_all(bytes).and_then(|()| f.sync_all());
                drop(f);
                if let Err(err) = written {
                    let _ = self.unlink(&tmp);
                    return Err(FsError::io("write", &path, err));
                }
                if let Err(err) = self.rename_within(&tmp, name, false) {
                    let _ = self.unlink(&tmp);
                    return Err(err);
                }
            }
        }
        Ok(path)
    }

    /// Moves `from` in `staged` to `name` here, under the rules of [`Dir::write`].
    pub fn publish_from(
        &self,
        staged: &Dir,
        from: &str,
        name: &str,
        replace: Replace,
    ) -> Result<PathBuf, FsError> {
        let path = self.at(name);
        if let Some(what) = protected(&path, None) {
            return Err(FsError::Protected { path, what });
        }
        match self.entry(name)? {
            None => staged.move_to(from, self, name)?,
            Some(e) if replace == Replace::OwnKind => {
                self.replaceable(name, &e)?;
                rename_at(staged, from, self, name, false)?;
            }
            Some(e) if e.kind == EntryKind::Symlink => return Err(FsError::Symlink { path }),
            Some(_) => return Err(FsError::Exists { path }),
        }
        Ok(path)
    }

    fn rename_within(&self, from: &str, to: &str, noreplace: bool) -> Result<(), FsError> {
        rename_at(self, from, self, to, noreplace)
    }

    /// Moves the entry `name` into `to` as `to_name`, never replacing what is there (the
    /// entry itself moves, a link as a link).
    pub fn move_to(&self, name: &str, to: &Dir, to_name: &str) -> Result<(), FsError> {
        rename_at(self, name, to, to_name, true)
    }

    /// A name for `name` that is free here: itself, else `STEM-2.REST`, `STEM-3.REST`, …
    pub fn free_name(&self, name: &str) -> Result<String, FsError> {
        if self.entry(name)?.is_none() {
            return Ok(name.to_string());
        }
        let (stem, rest) = match name.find('.') {
            Some(i) if i > 0 => (&name[..i], &name[i..]),
            _ => (name, ""),
        };
        for n in 2.. {
            let candidate = format!("{stem}-{n}{rest}");
            if self.entry(&candidate)?.is_none() {
                return Ok(candidate);
            }
        }
        unreachable!("an unused name")
    }

    /// Opens `name` for reading (`O_NOFOLLOW`, `O_NONBLOCK` so that a FIFO cannot hang the
    /// open), checked to be a regular file.
    fn open_read(&self, name: &str) -> Result<std::fs::File, FsError> {
        let path = self.at(name);
        let c = cstr(OsStr::new(name)).map_err(|e| FsError::io("open", &path, e))?;
        let fd = unsafe {
            libc::openat(
                self.fd.as_raw_fd(),
                c.as_ptr(),
                libc::O_RDONLY | libc::O_NOFOLLOW | libc::O_NONBLOCK | libc::O_CLOEXEC,
            )
        };
        if fd < 0 {
            return Err(FsError::io("open", path, std::io::Error::last_os_error()));
        }
        let file = unsafe { std::fs::File::from_raw_fd(fd) };
        let meta = file.metadata().map_err(|e| FsError::io("stat", &path, e))?;
        if !meta.is_file() {
            return Err(FsError::NotRegular {
                path,
                what: "a folder, device, pipe or socket",
            });
        }
        Ok(file)
    }

    /// Reads the regular file `name` (never through a link, never one with other names), at
    /// most `max` bytes: a larger file is refused without reading it.
    pub fn read_bounded(&self, name: &str, max: u64) -> Result<Vec<u8>, FsError> {
        let path = self.at(name);
        let file = self.open_read(name)?;
        let meta = file.metadata().map_err(|e| FsError::io("stat", &path, e))?;
        if meta.len() > max {
            return Err(FsError::TooLarge {
                path,
                size: meta.len(),
                max,
                hint: "",
            });
        }
        let mut out = Vec::with_capacity(meta.len() as usize);
        // The file may grow after the check: read one byte past the limit at most.
        file.take(max + 1)
            .read_to_end(&mut out)
            .map_err(|e| FsError::io("read", &path, e))?;
        if out.len() as u64 > max {
            return Err(FsError::TooLarge {
                path,
                size: out.len() as u64,
                max,
                hint: " (it grew while being read)",
            });
        }
        Ok(out)
    }
}

fn rename_at(
    from: &Dir,
    name: &str,
    to: &Dir,
    to_name: &str,
    noreplace: bool,
) -> Result<(), FsError> {
    let path = to.at(to_name);
    let a = cstr(OsStr::new(name)).map_err(|e| FsError::io("move", from.at(name), e))?;
    let b = cstr(OsStr::new(to_name)).map_err(|e| FsError::io("move", &path, e))?;
    #[cfg(target_os = "linux")]
    let r = unsafe {
        libc::renameat2(
            from.fd.as_raw_fd(),
            a.as_ptr(),
            to.fd.as_raw_fd(),
            b.as_ptr(),
            if noreplace { libc::RENAME_NOREPLACE } else { 0 },
        )
    };
    #[cfg(not(target_os = "linux"))]
    let r = {
        if noreplace && to.entry(to_name)?.is_some() {
            return Err(FsError::Exists { path });
        }
        unsafe {
            libc::renameat(
                from.fd.as_raw_fd(),
                a.as_ptr(),
                to.fd.as_raw_fd(),
                b.as_ptr(),
            )
        }
    };
    if r != 0 {
        let e = std::io::Error::last_os_error();
        if e.kind() == std::io::ErrorKind::AlreadyExists {
            return Err(FsError::Exists { path });
        }
        return Err(FsError::io("move into", path, e));
    }
    Ok(())
}

/// Writes `bytes` to the file at `path` under the rules of [`Dir::write`] (its directory must
/// exist).
pub fn write_file(path: &Path, bytes: &[u8], replace: Replace) -> Result<PathBuf, FsError> {
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .ok_or_else(|| FsError::Io {
            op: "write",
            path: path.to_path_buf(),
            source: std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "not a file name (or not UTF-8)",
            ),
        })?;
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let dir = Dir::open_following(parent)?;
    dir.write(name, bytes, replace)?;
    Ok(path.to_path_buf())
}

/// Creates the store's file, if missing, readable by its owner only (0600; 0640 under
/// systemd, where the unit's group lets operators read it), so that SQLite, which gives its
/// `-wal` and `-shm` files the database file's mode, creates those private too. An existing
/// store readable by other users loses those bits.
pub fn prepare_private_file(path: &Path) -> std::io::Result<()> {
    use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
    let mode = private_mode();
    match std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(mode)
        .custom_flags(libc::O_NOFOLLOW)
        .open(path)
    {
        Ok(_) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
            for p in std::iter::once(path.to_path_buf()).chain(["-wal", "-shm"].iter().map(|s| {
                let mut n = path.as_os_str().to_os_string();
                n.push(s);
                PathBuf::from(n)
            })) {
                if let Ok(m) = std::fs::metadata(&p)
                    && m.is_file()
                    && m.permissions().mode() & 0o007 != 0
                {
                    let tightened = m.permissions().mode() & 0o770 & !0o020;
                    std::fs::set_permissions(&p, std::fs::Permissions::from_mode(tightened))?;
                }
            }
            Ok(())
        }
        Err(e) => Err(e),
    }
}

/// 0600, or 0640 under systemd (which sets `INVOCATION_ID` for every unit it starts).
pub fn private_mode() -> u32 {
    if std::env::var_os("INVOCATION_ID").is_some() {
        0o640
    } else {
        0o600
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::symlink;

    #[test]
    fn a_new_file_is_never_created_through_a_link_or_over_a_name() {
        let t = tempfile::tempdir().unwrap();
        let victim = t.path().join("victim");
        std::fs::write(&victim, b"precious").unwrap();
        let out = t.path().join("out");
        std::fs::create_dir(&out).unwrap();
        symlink(&victim, out.join("index.html")).unwrap();
        symlink(t.path().join("nowhere"), out.join("dangling.html")).unwrap();
        let d = Dir::open(&out).unwrap();
        for replace in [Replace::Never, Replace::OwnKind] {
            let e = d.write("index.html", b"<html>", replace).unwrap_err();
            assert!(matches!(e, FsError::Symlink { .. }), "{e}");
            let e = d.write("dangling.html", b"<html>", replace).unwrap_err();
            assert!(matches!(e, FsError::Symlink { .. }), "{e}");
        }
        assert_eq!(std::fs::read(&victim).unwrap(), b"precious");
        assert!(!t.path().join("nowhere").exists());
        // A folder that is a link is refused.
        symlink(&out, t.path().join("linked")).unwrap();
        let e = Dir::open(&t.path().join("linked")).unwrap_err();
        assert!(matches!(e, FsError::Symlink { .. }), "{e}");
        let e = Dir::create(&t.path().join("linked")).unwrap_err();
        assert!(matches!(e, FsError::Symlink { .. }), "{e}");
    }

    #[test]
    fn force_replaces_only_a_plain_file_and_never_a_protected_one() {
        let t = tempfile::tempdir().unwrap();
        let d = Dir::open(t.path()).unwrap();
        d.write("a.json", b"1", Replace::Never).unwrap();
        let e = d.write("a.json", b"2", Replace::Never).unwrap_err();
        assert!(e.to_string().contains("--force"), "{e}");
        d.write("a.json", b"3", Replace::OwnKind).unwrap();
        assert_eq!(std::fs::read(t.path().join("a.json")).unwrap(), b"3");
        // A hard link to another file, an SQLite database, a folder: never.
        std::fs::write(t.path().join("other"), b"other").unwrap();
        std::fs::hard_link(t.path().join("other"), t.path().join("b.json")).unwrap();
        let e = d.write("b.json", b"x", Replace::OwnKind).unwrap_err();
        assert!(e.to_string().contains("hard link"), "{e}");
        std::fs::write(t.path().join("c.json"), b"SQLite format 3\0rest").unwrap();
        let e = d.write("c.json", b"x", Replace::OwnKind).unwrap_err();
        assert!(e.to_string().contains("SQLite"), "{e}");
        std::fs::write(t.path().join("w.json"), [0x37, 0x7f, 0x06, 0x82, 0, 0]).unwrap();
        let e = d.write("w.json", b"x", Replace::OwnKind).unwrap_err();
        assert!(e.to_string().contains("SQLite"), "{e}");
        std::fs::write(t.path().join("other.db-wal"), b"x").unwrap();
        let e = d.write("other.db-wal", b"x", Replace::OwnKind).unwrap_err();
        assert!(e.to_string().contains("named like a store"), "{e}");
        std::fs::create_dir(t.path().join("sub")).unwrap();
        assert!(d.write("sub", b"x", Replace::OwnKind).is_err());
        assert_eq!(std::fs::read(t.path().join("other")).unwrap(), b"other");
        // The protected files, by name (even before they exist) and by inode.
        let db = t.path().join("s.db");
        std::fs::write(&db, b"store").unwrap();
        protect_store(&db);
        for name in ["s.db", "s.db-wal", "s.db-shm", "s.db.lock"] {
            for replace in [Replace::Never, Replace::OwnKind] {
                let e = d.write(name, b"x", replace).unwrap_err();
                assert!(matches!(e, FsError::Protected { .. }), "{name}: {e}");
            }
        }
        assert!(!t.path().join("s.db-wal").exists());
        let sub = Dir::open(&t.path().join("sub")).unwrap();
        std::fs::hard_link(&db, t.path().join("sub/store-copy")).unwrap();
        let e = sub.write("store-copy", b"x", Replace::OwnKind).unwrap_err();
        assert!(matches!(e, FsError::Protected { .. }), "{e}");
        assert_eq!(std::fs::read(&db).unwrap(), b"store");
    }

    #[test]
    fn reads_are_bounded_and_refuse_links_and_pipes() {
        let t = tempfile::tempdir().unwrap();
        let d = Dir::open(t.path()).unwrap();
        std::fs::write(t.path().join("f"), vec![7u8; 100]).unwrap();
        assert_eq!(d.read_bounded("f", 100).unwrap().len(), 100);
        let e = d.read_bounded("f", 99).unwrap_err();
        assert!(
            matches!(
                e,
                FsError::TooLarge {
                    size: 100,
                    max: 99,
                    ..
                }
            ),
            "{e}"
        );
        symlink(t.path().join("f"), t.path().join("l")).unwrap();
        assert!(matches!(
            d.read_bounded("l", 1000).unwrap_err(),
            FsError::Symlink { .. }
        ));
        let fifo = CString::new(t.path().join("p").as_os_str().as_bytes()).unwrap();
        assert_eq!(unsafe { libc::mkfifo(fifo.as_ptr(), 0o600) }, 0);
        assert!(matches!(
            d.read_bounded("p", 1000).unwrap_err(),
            FsError::NotRegular { .. }
        ));
        let names: Vec<String> = d.list().unwrap().into_iter().map(|(n, _)| n).collect();
        assert_eq!(names, ["f", "l", "p"]);
        // Moves never replace.
        let sub = d.subdir("done").unwrap();
        std::fs::write(t.path().join("done/f"), b"kept").unwrap();
        assert!(matches!(
            d.move_to("f", &sub, "f").unwrap_err(),
            FsError::Exists { .. }
        ));
        let free = sub.free_name("f").unwrap();
        assert_eq!(free, "f-2");
        d.move_to("f", &sub, &free).unwrap();
        assert_eq!(std::fs::read(t.path().join("done/f")).unwrap(), b"kept");
    }

    #[test]
    fn a_held_path_follows_the_folder_not_its_name() {
        let t = tempfile::tempdir().unwrap();
        let d = Dir::create(&t.path().join("out")).unwrap();
        let staging = d.staging(".s-").unwrap();
        let held = staging.held_path();
        // The folder swapped away under its name: writes through the held path still land in
        // the folder brdfd created.
        std::fs::rename(t.path().join("out"), t.path().join("moved")).unwrap();
        std::fs::create_dir(t.path().join("out")).unwrap();
        std::fs::write(held.join("f.png"), b"png").unwrap();
        let name = staging.path().file_name().unwrap().to_owned();
        assert_eq!(
            std::fs::read(t.path().join("moved").join(&name).join("f.png")).unwrap(),
            b"png"
        );
        assert_eq!(std::fs::read_dir(t.path().join("out")).unwrap().count(), 0);
    }

    #[test]
    fn a_store_file_is_created_private() {
        use std::os::unix::fs::PermissionsExt;
        let t = tempfile::tempdir().unwrap();
        let db = t.path().join("s.db");
        prepare_private_file(&db).unwrap();
        let mode = std::fs::metadata(&db).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode & 0o077 & !0o040, 0, "{mode:o}");
        std::fs::set_permissions(&db, std::fs::Permissions::from_mode(0o644)).unwrap();
        prepare_private_file(&db).unwrap();
        let mode = std::fs::metadata(&db).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode & 0o007, 0, "{mode:o}");
    }
}
