//! The watch folder (`[ingest] watch = "DIR"`): what the instruments' own software exports,
//! and brdfd scan files, dropped into DIR become stored, fitted scans without an operator.
//!
//! This module owns the folder's life cycle; the parsing is `src/formats/` (the same code as
//! `brdfd import-format`) and the writing is one store transaction ([`Store::import_file`]).
//!
//! **What is read, and how files pair.** `NAME.scan.json` is a `brdfd.scan/1` file. `NAME.cxf`
//! (CxF3) and `NAME.txt` / `NAME.cgats` (CGATS) are MA-T12 exports; the SRA's CSV of the same
//! session is `NAME.sra.csv` (same NAME, case-insensitive), and the two are imported together.
//! An export whose `.sra.csv` has not appeared within `pair_wait` is imported alone (which works
//! for brdfd's own exports, which hold the SRA readings, and otherwise fails saying where the
//! CSV goes); an `.sra.csv` with no export after `pair_wait` is moved to `failed/`. Names
//! starting with `.` (partial uploads of many tools) and other files are left alone.
//!
//! **When.** The folder is listed every `poll` (polling, not inotify: it works the same on
//! network shares and bind mounts, where the instrument PC may write and inotify sees nothing,
//! and needs no dependency; a listing a second is nothing next to a scan). A file is taken once
//! its size and modification time have stayed the same for `settle`, so a file still being
//! written (or copied in pieces) is never read half-way.
//!
//! **Crash safety.** A file taken is first renamed into `DIR/.importing/` (atomic on one file
//! system), read from there, hashed (SHA-256) and parsed; its scans and its hash are written in
//! one store transaction (`ingested_files`, `migrations/0012_ingest.sql`); then its fits are
//! queued and the hash row marked so; only then is the file renamed into `DIR/done/`. What a
//! stopped daemon left in `.importing/` is settled at start, before any pass, and never parsed:
//! a hash already recorded means the import committed, and the file goes to `done/`; any
//! other file was being imported when the daemon stopped, perhaps because of it (a reader
//! that aborts the process), so it goes to `failed/` with a note saying so, is named in the
//! log and in `status` (`interrupted`), and is not read again unless someone drops it again:
//! one file cannot keep the daemon down through its restarts. Scans imported but whose fits
//! were not queued yet are queued at start. A file is never imported twice: the same content
//! dropped again, under any name, or imported before through `brdfd import` or
//! `POST /scans/import` (every door records each scan's file, `scan_imports`), is not imported
//! again: it is moved to `done/` beside `NAME.note.txt` naming the earlier import, and counted
//! in `status` (`already_imported`). A store failure (a full disk) leaves the file in
//! `.importing/` to be tried again at a later pass of the same run.
//!
//! **Bounded.** Imports run off the folder's pass, each on a task of its own,
//! [`IMPORTS_AT_ONCE`] at a time; a file's bytes are held in the service's import budget
//! (`[ingest] max_held_mib`, shared with `POST /scans/import`,
//! [`super::import_budget`]) from before it is read until its import is over. A file is
//! taken only when a slot and its bytes are free; until then it waits in the folder
//! (`waiting` in `status`) and the files behind it go on, so one slow file does not hold up
//! the rest. A reader's own time and memory are bounded in the reader (`src/formats/`).
//!
//! **What the folder can do to the daemon.** Whoever can write into DIR can drop files, not
//! redirect brdfd's writes: DIR and its three subfolders are opened once at start and held
//! ([`crate::safe_fs::Dir`]); every listing, read, note and move is relative to those handles,
//! a subfolder swapped for a link or another folder stops the folder's passes (named in
//! `status`), moves never replace a name (`RENAME_NOREPLACE`) and notes are created with
//! `O_EXCL | O_NOFOLLOW`. A symbolic link, a file with other names (a hard link) or anything
//! but a regular file is moved to `failed/` unread; a file over `[ingest] max_file_mib` too,
//! and no file is read past that bound.
//!
//! **Outcomes.** `DIR/done/NAME` (with `DIR/done/NAME.note.txt` for a file imported before),
//! or `DIR/failed/NAME` with `DIR/failed/NAME.error.txt` saying why (the parser's message names file, line and field); an existing name there gets `-2`,
//! `-3`, … before its first dot. Each file gives an [`Event::FileImported`] or
//! [`Event::FileRejected`], and `status` shows the folder's counts and last error.
//!
//! [`WatchFolder`] owns the folder's status (only its task changes it); the imported scans go
//! to the pipeline to be fitted, as an import through the API would.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use tokio::sync::Semaphore;

use crate::formats::budget::{Budget, Limit};
use crate::formats::xrite_xlsx::TextureImage;
use crate::formats::{self, Format, ImportOptions};
use crate::safe_fs::{Dir, EntryKind, FsError, Replace};
use crate::scan::Scan;
use crate::store::{FileImport, ImportedScan, NewTexture, Provenance, StoreError};

use super::context::Context;
use super::events::Event;
use super::import_budget::{BudgetError, HeldBytes};
use super::pipeline::{
    IMPORTED_SUFFIX, Pipeline, already_imported, check_name, file_provenance, new_readings,
    new_textures,
};
use super::shutdown::TaskGuard;
use super::{RefitRequest, ServiceError};

/// Where finished files go, and the folder of files being imported.
pub const DONE: &str = "done";
pub const FAILED: &str = "failed";
pub const IMPORTING: &str = ".importing";

/// Imports the watch folder runs at once, each on a task of its own: a slow file holds one,
/// and the files behind it go on through the other.
pub const IMPORTS_AT_ONCE: usize = 2;

/// The watch folder's settings (`[ingest]`).
#[derive(Debug, Clone, PartialEq)]
pub struct IngestSettings {
    pub dir: PathBuf,
    pub settle: Duration,
    pub poll: Duration,
    pub pair_wait: Duration,
    /// In an instrument's export, the object with this name is the reference tile.
    pub reference: String,
    /// The limits every file is read within (its file size: the largest file read).
    pub budget: crate::formats::budget::Budget,
}

impl IngestSettings {
    pub fn from_config(c: &crate::config::IngestConfig) -> Option<IngestSettings> {
        c.watch.as_ref().map(|dir| IngestSettings {
            dir: dir.clone(),
            settle: c.settle,
            poll: c.poll,
            pair_wait: c.pair_wait,
            reference: c.reference.clone(),
            budget: c.budget,
        })
    }
}

/// The watch folder in `GET /status`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IngestStatus {
    /// The folder watched.
    pub dir: String,
    /// Files seen and not yet taken (still changing, or waiting for their pair).
    pub waiting: usize,
    /// Files imported since start.
    pub imported: u64,
    /// Files moved to failed/ since start.
    pub rejected: u64,
    /// Files moved to done/ since start without being imported: their content was imported
    /// before (through any door), as the note beside each says.
    #[serde(default)]
    pub already_imported: u64,
    /// The last file imported or rejected.
    pub last_file: Option<String>,
    /// The last rejection or error, with its file.
    pub last_error: Option<String>,
    /// Files found in `.importing/` at start, their import not committed: the daemon stopped
    /// while importing them (perhaps because of them), so they were moved to `failed/` with a
    /// note instead of being read again (the first 20).
    #[serde(default)]
    pub interrupted: Vec<String>,
}

/// What a file in the folder is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    ScanFile,
    /// X-Rite's QC `.xlsx` export: MA-T12 only, no SRA CSV to wait for.
    XriteXlsx,
    Export(Format),
    SraCsv,
}

/// The kind of a file name and the NAME part that pairs it, or `None` for files left alone.
fn kind_of(name: &str) -> Option<(Kind, String)> {
    if name.starts_with('.') {
        return None;
    }
    let lower = name.to_ascii_lowercase();
    for (suffix, kind) in [
        (".scan.json", Kind::ScanFile),
        (".xlsx", Kind::XriteXlsx),
        (".sra.csv", Kind::SraCsv),
        (".cxf", Kind::Export(Format::Cxf3)),
        (".cgats", Kind::Export(Format::Cgats)),
        (".txt", Kind::Export(Format::Cgats)),
    ] {
        if let Some(stem) = lower.strip_suffix(suffix)
            && !stem.is_empty()
        {
            return Some((kind, stem.to_string()));
        }
    }
    None
}

/// One import: a file, or an export with its SRA CSV.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Unit {
    main: String,
    partner: Option<String>,
    /// Rejected without reading (an SRA CSV with no export).
    orphan: bool,
}

impl Unit {
    fn names(&self) -> Vec<&str> {
        std::iter::once(self.main.as_str())
            .chain(self.partner.as_deref())
            .collect()
    }

    fn shown(&self) -> String {
        match &self.partner {
            Some(p) => format!("{} and {p}", self.main),
            None => self.main.clone(),
        }
    }
}

/// What a file looked like when last listed.
#[derive(Debug, Clone, Copy)]
struct Seen {
    size: u64,
    mtime: Option<SystemTime>,
    /// Since when size and mtime are what they are.
    unchanged_since: Instant,
    first_seen: Instant,
}

/// The watcher's memory between passes.
#[derive(Debug, Default)]
struct Watch {
    seen: HashMap<String, Seen>,
}

/// A listed file: name, kind, pairing NAME, size, modification time.
type Listed = (String, Kind, String, u64, Option<SystemTime>);

/// The files of `dir` the folder reads, with their size and modification time; and the names
/// of the folder's kinds that are not plain regular files (links, hard links, pipes, folders),
/// with why, to be moved to `failed/` unread.
fn list(dir: &Dir) -> Result<(Vec<Listed>, Vec<(String, String)>), FsError> {
    let mut out = Vec::new();
    let mut refused = Vec::new();
    for (name, entry) in dir.list()? {
        let Some((kind, stem)) = kind_of(&name) else {
            continue;
        };
        let why = match entry.kind {
            EntryKind::File if entry.links > 1 => Some(
                "it has other names (a hard link): the watch folder reads only files of its own",
            ),
            EntryKind::File => None,
            EntryKind::Symlink => {
                Some("it is a symbolic link: the watch folder reads only regular files in it")
            }
            EntryKind::Dir => continue,
            EntryKind::Other => Some("it is not a regular file (a pipe, socket or device)"),
        };
        match why {
            Some(why) => refused.push((name, why.to_string())),
            None => out.push((name, kind, stem, entry.size, entry.mtime)),
        }
    }
    Ok((out, refused))
}

/// The watch folder and its subfolders, opened once at start and held.
#[derive(Debug)]
pub(super) struct Folders {
    root: Dir,
    done: Dir,
    failed: Dir,
    importing: Dir,
}

impl Folders {
    fn open(dir: &Path) -> Result<Folders, FsError> {
        // DIR itself is the operator's setting and may be a link they made; what is inside it
        // is not followed.
        let root = Dir::open_following(dir)?;
        Ok(Folders {
            done: root.subdir(DONE)?,
            failed: root.subdir(FAILED)?,
            importing: root.subdir(IMPORTING)?,
            root,
        })
    }

    /// Whether DIR and its subfolders are still the folders opened at start; else why not.
    fn check(&self, dir: &Path) -> Result<(), String> {
        let same = std::fs::metadata(dir).ok().map(|m| {
            use std::os::unix::fs::MetadataExt;
            (m.dev(), m.ino())
        }) == self.root.id().ok();
        if !same {
            return Err(format!(
                "{} is no longer the folder watched since the start (moved or replaced);                  restore it and restart brdfd serve",
                dir.display()
            ));
        }
        for (name, held) in [
            (DONE, &self.done),
            (FAILED, &self.failed),
            (IMPORTING, &self.importing),
        ] {
            let now = self.root.entry(name).ok().flatten();
            let ok = now.is_some_and(|e| e.kind == EntryKind::Dir && Some(e.id) == held.id().ok());
            if !ok {
                return Err(format!(
                    "{}/{name} was replaced since the start (by a link or another folder):                      nothing is imported until it is restored and brdfd serve restarted",
                    dir.display()
                ));
            }
        }
        Ok(())
    }
}

/// Groups the files of a listing into imports. `ready(name)` says whether a file has settled;
/// `waited(name)` whether it has waited `pair_wait` for its pair. Returns the units ready and
/// how many files still wait.
fn units(
    files: &[(String, Kind, String)],
    ready: impl Fn(&str) -> bool,
    waited: impl Fn(&str) -> bool,
) -> (Vec<Unit>, usize) {
    let mut out = Vec::new();
    let mut taken = 0;
    let sra_of = |stem: &str| {
        files
            .iter()
            .find(|(_, k, s)| *k == Kind::SraCsv && s == stem)
            .map(|(n, _, _)| n.clone())
    };
    let has_export = |stem: &str| {
        files
            .iter()
            .any(|(_, k, s)| matches!(k, Kind::Export(_)) && s == stem)
    };
    for (name, kind, stem) in files {
        match kind {
            Kind::ScanFile | Kind::XriteXlsx if ready(name) => out.push(Unit {
                main: name.clone(),
                partner: None,
                orphan: false,
            }),
            Kind::Export(_) if ready(name) => match sra_of(stem) {
                Some(sra) if ready(&sra) => out.push(Unit {
                    main: name.clone(),
                    partner: Some(sra),
                    orphan: false,
                }),
                Some(_) => {}
                None if waited(name) => out.push(Unit {
                    main: name.clone(),
                    partner: None,
                    orphan: false,
                }),
                None => {}
            },
            Kind::SraCsv if ready(name) && !has_export(stem) && waited(name) => out.push(Unit {
                main: name.clone(),
                partner: None,
                orphan: true,
            }),
            _ => {}
        }
    }
    for u in &out {
        taken += u.names().len();
    }
    (out, files.len() - taken)
}

/// The SHA-256 of a file, or of an export and its SRA CSV (each length-prefixed).
pub fn content_hash(main: &[u8], partner: Option<&[u8]>) -> String {
    let mut h = Sha256::new();
    match partner {
        None => h.update(main),
        Some(p) => {
            for part in [main, p] {
                h.update((part.len() as u64).to_le_bytes());
                h.update(part);
            }
        }
    }
    hex::encode(h.finalize())
}

/// A name for `name` in `failed/` such that it and its `NAME.error.txt` note are both free.
fn free_failed_name(failed: &Dir, name: &str) -> Result<String, FsError> {
    let mut candidate = failed.free_name(name)?;
    let (stem, rest) = match name.find('.') {
        Some(i) if i > 0 => (&name[..i], &name[i..]),
        _ => (name, ""),
    };
    let mut n = 1;
    while failed.entry(&format!("{candidate}.error.txt"))?.is_some()
        || failed.entry(&candidate)?.is_some()
    {
        n += 1;
        candidate = format!("{stem}-{n}{rest}");
    }
    Ok(candidate)
}

/// Why a file could not be imported: its fault (moved to failed/) or the store's (tried again).
enum Failure {
    Rejected(String),
    Retry(String),
}

/// What became of a unit that did not fail.
enum Outcome {
    /// Imported now: the file (as shown), its scans, its content hash.
    Imported(String, Vec<crate::store::ScanId>, String),
    /// An import that committed before a stop (recovering): only the move was left.
    Committed,
    /// Its content was imported before: not imported again; the note says by which import.
    Repeat(String),
}

/// What a unit's files hold: their content hash, the scans, and each scan's texture images
/// (the instrument camera's, from an X-Rite `.xlsx`; none from other files).
type UnitContent = (String, Vec<Scan>, Vec<Vec<TextureImage>>);

/// How much of a file in `.importing/` is read: the bytes held for it in the import budget
/// (its size when they were held), within the import budget's file size
/// (`[ingest] max_file_mib`).
#[derive(Debug, Clone, Copy)]
struct ReadLimit {
    bytes: u64,
    budget: Budget,
}

/// Each file of `unit` (in `dir`, where it is now): how much of it is read, its size now at
/// most `max_file_mib`.
fn read_limits(
    settings: &IngestSettings,
    dir: &Dir,
    unit: &Unit,
) -> Result<Vec<ReadLimit>, String> {
    unit.names()
        .into_iter()
        .map(|name| match dir.entry(name) {
            Ok(Some(e)) => Ok(ReadLimit {
                bytes: e.size.min(settings.budget.max_file_bytes),
                budget: settings.budget,
            }),
            Ok(None) => Err(format!("{name} is gone from the watch folder")),
            Err(e) => Err(format!("{name}: {e}")),
        })
        .collect()
}

/// What an import holds while it runs: an import slot, its files' bytes in the import budget
/// (given back when dropped), and how much of each file is read.
struct Held {
    _slot: tokio::sync::OwnedSemaphorePermit,
    _bytes: HeldBytes,
    limits: Vec<ReadLimit>,
}

/// Reads `name` from `dir`, no further than `limit`.
fn read_held(dir: &Dir, name: &str, limit: ReadLimit) -> Result<Vec<u8>, String> {
    dir.read_bounded(name, limit.bytes).map_err(|e| match e {
        FsError::TooLarge { size, .. } => {
            match limit
                .budget
                .check(Limit::FileBytes, name, "the whole file", size)
            {
                Err(over) => format!("{over} (nothing of it was read)"),
                Ok(()) => format!(
                    "{name} grew to {size} bytes while it was being imported (it was {} bytes \
                     when taken): something still writes to it; drop it again once it is written",
                    limit.bytes
                ),
            }
        }
        e => format!("{name}: {e}"),
    })
}

/// The scans in a unit's files (read from `.importing/`, each within its limit), with their
/// content hash and texture images.
fn read_unit(
    dir: &Dir,
    unit: &Unit,
    reference: &str,
    limits: &[ReadLimit],
    budget: &crate::formats::budget::Budget,
) -> Result<UnitContent, String> {
    let main = read_held(dir, &unit.main, limits[0])?;
    let partner = match &unit.partner {
        Some(p) => Some(read_held(dir, p, limits[1])?),
        None => None,
    };
    let hash = content_hash(&main, partner.as_deref());
    let (kind, stem) = kind_of(&unit.main).ok_or("not a file the watch folder reads")?;
    let text = |name: &str, bytes: Vec<u8>| {
        String::from_utf8(bytes).map_err(|e| {
            format!(
                "{name}: not UTF-8 text (byte {}): export it as UTF-8",
                e.utf8_error().valid_up_to()
            )
        })
    };
    let scans = match kind {
        Kind::ScanFile => vec![Scan::from_json(&main).map_err(|e| format!("{}: {e}", unit.main))?],
        Kind::XriteXlsx => {
            let scans =
                formats::xrite::read(&main, &unit.main, budget).map_err(|e| e.to_string())?;
            for s in &scans {
                if let Some(w) = s.warning() {
                    tracing::warn!(file = %unit.main, "{w}");
                }
            }
            let (scans, textures) = scans.into_iter().map(|s| (s.scan, s.textures)).unzip();
            return Ok((hash, scans, textures));
        }
        Kind::SraCsv => {
            return Err(format!(
                "{}: an SRA CSV with no MA-T12 export beside it; drop it together with \
                 {stem}.cxf, {stem}.txt or {stem}.cgats (the same NAME)",
                unit.main
            ));
        }
        Kind::Export(format) => {
            let main_text = text(&unit.main, main)?;
            let sra = match (&unit.partner, partner) {
                (Some(name), Some(bytes)) => Some((name.clone(), text(name, bytes)?)),
                _ => None,
            };
            formats::import(
                format,
                &unit.main,
                &main_text,
                sra.as_ref().map(|(n, t)| (n.as_str(), t.as_str())),
                &ImportOptions {
                    reference: reference.to_string(),
                    budget: *budget,
                },
            )
            .map_err(|e| {
                let mut m = e.to_string();
                if unit.partner.is_none() {
                    m.push_str(&format!(
                        " (an MA-T12 export is imported with the SRA's CSV beside it, named \
                         {stem}.sra.csv; none was there)"
                    ));
                }
                m
            })?
        }
    };
    let textures = vec![Vec::new(); scans.len()];
    Ok((hash, scans, textures))
}

/// The running watch folder (module docs): its status, and what its task imports with.
#[derive(Clone)]
pub(super) struct WatchFolder {
    ctx: Context,
    /// Where imported scans are processed and their fits queued.
    pipeline: Pipeline,
    /// Changed by the folder's task alone; read by `status`.
    status: Arc<Mutex<IngestStatus>>,
    /// The names in `.importing/` whose import runs now (not to be taken again).
    in_flight: Arc<Mutex<HashSet<String>>>,
    /// One permit per import running at once ([`IMPORTS_AT_ONCE`]).
    slots: Arc<Semaphore>,
}

impl WatchFolder {
    /// Starts the watch-folder task: checks the folder, creates `done/`, `failed/` and
    /// `.importing/` in it, then polls until shutdown.
    pub(super) async fn start(
        ctx: Context,
        pipeline: Pipeline,
        settings: IngestSettings,
    ) -> Result<WatchFolder, ServiceError> {
        let dir = &settings.dir;
        if !dir.is_dir() {
            return Err(ServiceError::BadRequest(format!(
                "[ingest] watch = {}: no such directory; create it (writable by brdfd's user) \
                 or fix the setting",
                dir.display()
            )));
        }
        let folders = Folders::open(dir).map_err(|e| {
            ServiceError::BadRequest(format!(
                "[ingest] watch = {}: {e}; make the folder writable by brdfd's user, with \
                 {DONE}/, {FAILED}/ and {IMPORTING}/ real folders in it",
                dir.display()
            ))
        })?;
        let status = Arc::new(Mutex::new(IngestStatus {
            dir: dir.display().to_string(),
            waiting: 0,
            imported: 0,
            rejected: 0,
            already_imported: 0,
            last_file: None,
            last_error: None,
            interrupted: Vec::new(),
        }));
        let watch_folder = WatchFolder {
            ctx,
            pipeline,
            status,
            in_flight: Arc::default(),
            slots: Arc::new(Semaphore::new(IMPORTS_AT_ONCE)),
        };
        let (guard, mut stop) = watch_folder.ctx.task_slot().await?;
        tracing::info!(dir = %dir.display(), "watching the folder for exports and scan files");
        let folder = watch_folder.clone();
        let (settings, folders) = (Arc::new(settings), Arc::new(folders));
        tokio::spawn(async move {
            folder.settle_interrupted(&settings, &folders).await;
            folder.queue_pending_ingest_fits().await;
            let mut watch = Watch::default();
            loop {
                match folders.check(&settings.dir) {
                    Ok(()) => {
                        folder
                            .ingest_pass(&settings, &folders, &mut watch, &guard)
                            .await
                    }
                    Err(e) => folder.note_error(e),
                }
                tokio::select! {
                    _ = tokio::time::sleep(settings.poll) => {}
                    _ = stop.recv() => break,
                }
            }
        });
        Ok(watch_folder)
    }

    fn ingest_stopping(&self) -> bool {
        self.ctx.is_stopping()
    }

    fn with_ingest_status(&self, f: impl FnOnce(&mut IngestStatus)) {
        f(&mut self.status.lock().unwrap_or_else(|p| p.into_inner()));
    }

    /// The watch folder's state now.
    pub(super) fn status(&self) -> IngestStatus {
        self.status
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// Queues the fits of imported files whose fits a stopped daemon had not queued yet.
    async fn queue_pending_ingest_fits(&self) {
        let pending = match self.ctx.store.ingested_awaiting_fits().await {
            Ok(p) => p,
            Err(e) => {
                tracing::error!(error = %e, "cannot read the watch folder's imports");
                return;
            }
        };
        for file in pending {
            self.queue_ingest_fits(&file).await;
        }
    }

    /// Processes the scans of an imported file and queues their fits (those with no fit yet),
    /// then records that this was done.
    async fn queue_ingest_fits(&self, file: &crate::store::IngestedFile) {
        for &scan in &file.scans {
            match self.ctx.store.fits_for_scan(scan).await {
                Ok(fits) if !fits.is_empty() => continue,
                Ok(_) => {}
                Err(e) => {
                    tracing::error!(error = %e, %scan, "cannot read the fits of an imported scan");
                    return;
                }
            }
            if let Err(e) = self
                .pipeline
                .process_and_queue(scan, &RefitRequest::default())
                .await
            {
                // Not the file's fault once it is stored (e.g. a reading processing refuses):
                // the scan stays, unfitted, as an import through the API would.
                tracing::warn!(error = %e, %scan, file = %file.file_name, "imported scan not fitted");
            }
        }
        if let Err(e) = self.ctx.store.mark_ingest_fits_queued(file.id).await {
            tracing::error!(error = %e, "cannot record that the imported scans' fits are queued");
        }
    }

    /// At start, before any pass: what a stopped daemon left in `.importing/`. A unit whose
    /// hash is recorded committed before the stop and goes to `done/` (only hashed, not
    /// parsed). Any other was being imported when the daemon stopped, and perhaps stopped it
    /// (a reader that aborts the process): it goes to `failed/` with a note saying so, is
    /// named in the log and in `status`, and is never read again automatically, so that one
    /// file cannot keep the daemon down through its restarts.
    async fn settle_interrupted(&self, settings: &IngestSettings, f: &Folders) {
        let (files, refused) = match list(&f.importing) {
            Ok(l) => l,
            Err(e) => return self.note_error(e.to_string()),
        };
        for (name, why) in refused {
            self.refuse_unread(f, &f.importing, &name, &why);
        }
        let files: Vec<_> = files.into_iter().map(|(n, k, s, _, _)| (n, k, s)).collect();
        let (units, _) = units(&files, |_| true, |_| true);
        for unit in units {
            let committed = match self.unit_hash(settings, f, &unit).await {
                Ok(hash) => match self.ctx.store.ingested_file(&hash).await {
                    Ok(found) => found.is_some(),
                    Err(e) => {
                        // Unknown: left where it is; the passes' recovery decides later.
                        self.note_error(format!("{}: the store failed: {e}", unit.shown()));
                        continue;
                    }
                },
                Err(_) => false,
            };
            if committed {
                // Its fits, if not queued yet, are queued by `queue_pending_ingest_fits`.
                for name in unit.names() {
                    if let Err(e) = self.file_to_done(f, name) {
                        self.note_error(format!("cannot move {name} into {DONE}/: {e}"));
                    }
                }
                continue;
            }
            let file = unit.shown();
            let reason = format!(
                "brdfd stopped while importing this file (it was found in {IMPORTING}/ at the \
                 next start, its import not committed). It is not read again automatically, in \
                 case reading it is what stopped the daemon; nothing of it is in the store. If \
                 the daemon stopped for another reason (a restart, a power cut), move it back \
                 into the watch folder to import it."
            );
            tracing::error!(
                file = %file,
                "the daemon stopped while importing this file; moved to {FAILED}/ unread, with a note"
            );
            for name in unit.names() {
                if let Err(e) = self.file_to_failed(f, &f.importing, name, &reason) {
                    self.note_error(format!("cannot move {name} into {FAILED}/: {e}"));
                }
            }
            self.with_ingest_status(|s| {
                s.rejected += 1;
                // Named in full up to a screenful; the notes in failed/ say the rest.
                if s.interrupted.len() < 20 {
                    s.interrupted.push(file.clone());
                }
                s.last_file = Some(file.clone());
                s.last_error = Some(format!(
                    "{file}: the daemon stopped while importing it; moved to {FAILED}/, not read \
                     again"
                ));
            });
            self.ctx.events.send(Event::FileRejected { file, reason });
        }
    }

    /// The content hash of a unit in `.importing/`, read within the import budget.
    async fn unit_hash(
        &self,
        settings: &IngestSettings,
        f: &Folders,
        unit: &Unit,
    ) -> Result<String, String> {
        let limits = read_limits(settings, &f.importing, unit)?;
        let _held = self
            .ctx
            .import_budget
            .hold(limits.iter().map(|l| l.bytes).sum())
            .await
            .map_err(|e| format!("{}: {e}", unit.shown()))?;
        let dir = f.importing.try_clone().map_err(|e| e.to_string())?;
        let unit = unit.clone();
        tokio::task::spawn_blocking(move || {
            let main = read_held(&dir, &unit.main, limits[0])?;
            let partner = match &unit.partner {
                Some(p) => Some(read_held(&dir, p, limits[1])?),
                None => None,
            };
            Ok(content_hash(&main, partner.as_deref()))
        })
        .await
        .map_err(|e| e.to_string())?
    }

    /// Holds an import slot and the bytes of a unit's files (in `dir`, where they are now) in
    /// the import budget, without waiting: `None` when either is not free now (the unit waits
    /// for a later pass, and the files behind it go on).
    fn try_hold_unit(
        &self,
        settings: &IngestSettings,
        dir: &Dir,
        unit: &Unit,
    ) -> Result<Option<Held>, String> {
        let limits = read_limits(settings, dir, unit)?;
        let Ok(slot) = self.slots.clone().try_acquire_owned() else {
            return Ok(None);
        };
        match self
            .ctx
            .import_budget
            .try_hold(limits.iter().map(|l| l.bytes).sum())
        {
            Ok(bytes) => Ok(Some(Held {
                _slot: slot,
                _bytes: bytes,
                limits,
            })),
            Err(BudgetError::Full { .. }) => Ok(None),
            Err(e) => Err(format!("{}: {e}", unit.shown())),
        }
    }

    /// Runs a unit's import on a task of its own, with what it holds, a guard (shutdown waits
    /// for it) and its names in `in_flight`; nothing when a name is in flight already.
    fn spawn_import(
        &self,
        settings: &Arc<IngestSettings>,
        f: &Arc<Folders>,
        unit: Unit,
        recovering: bool,
        held: Held,
        guard: &TaskGuard,
    ) {
        {
            let mut in_flight = self.in_flight.lock().unwrap_or_else(|p| p.into_inner());
            if unit.names().iter().any(|n| in_flight.contains(*n)) {
                return;
            }
            in_flight.extend(unit.names().into_iter().map(str::to_string));
        }
        let (folder, settings, f, guard) =
            (self.clone(), settings.clone(), f.clone(), guard.clone());
        tokio::spawn(async move {
            let _guard = guard;
            folder.finish(&settings, &f, &unit, recovering, held).await;
            let mut in_flight = folder.in_flight.lock().unwrap_or_else(|p| p.into_inner());
            for name in unit.names() {
                in_flight.remove(name);
            }
        });
    }

    /// Whether any of `names` is being imported now.
    fn in_flight(&self, names: &[&str]) -> bool {
        let in_flight = self.in_flight.lock().unwrap_or_else(|p| p.into_inner());
        names.iter().any(|n| in_flight.contains(*n))
    }

    /// One pass: go on with what is in `.importing/` and not being imported (a store failure
    /// at an earlier pass), then take the files that have settled. Each import runs on a task
    /// of its own ([`IMPORTS_AT_ONCE`] at most); a file with no free slot waits in the folder.
    async fn ingest_pass(
        &self,
        settings: &Arc<IngestSettings>,
        f: &Arc<Folders>,
        watch: &mut Watch,
        guard: &TaskGuard,
    ) {
        // 1. In flight and not running: a store failure at an earlier pass.
        match list(&f.importing) {
            Ok((files, refused)) if !files.is_empty() || !refused.is_empty() => {
                for (name, why) in refused {
                    self.refuse_unread(f, &f.importing, &name, &why);
                }
                let files: Vec<_> = files
                    .into_iter()
                    .map(|(n, k, s, _, _)| (n, k, s))
                    .filter(|(n, _, _)| !self.in_flight(&[n]))
                    .collect();
                let (units, _) = units(&files, |_| true, |_| true);
                for unit in units {
                    if self.ingest_stopping() {
                        return;
                    }
                    match self.try_hold_unit(settings, &f.importing, &unit) {
                        Ok(Some(held)) => self.spawn_import(settings, f, unit, true, held, guard),
                        Ok(None) => {}
                        Err(e) => self.note_error(e),
                    }
                }
            }
            Ok(_) => {}
            Err(e) => self.note_error(e.to_string()),
        }
        // 2. New files that have settled.
        let listing = match list(&f.root) {
            Ok((l, refused)) => {
                for (name, why) in refused {
                    self.refuse_unread(f, &f.root, &name, &why);
                }
                l
            }
            Err(e) => {
                self.note_error(e.to_string());
                return;
            }
        };
        let now = Instant::now();
        let mut seen = HashMap::with_capacity(listing.len());
        for (name, _, _, size, mtime) in &listing {
            let s = match watch.seen.get(name) {
                Some(s) if s.size == *size && s.mtime == *mtime => *s,
                Some(s) => Seen {
                    size: *size,
                    mtime: *mtime,
                    unchanged_since: now,
                    first_seen: s.first_seen,
                },
                None => Seen {
                    size: *size,
                    mtime: *mtime,
                    unchanged_since: now,
                    first_seen: now,
                },
            };
            seen.insert(name.clone(), s);
        }
        watch.seen = seen;
        let files: Vec<_> = listing
            .into_iter()
            .map(|(n, k, s, _, _)| (n, k, s))
            .collect();
        let (units, mut waiting) = units(
            &files,
            |n| {
                watch
                    .seen
                    .get(n)
                    .is_some_and(|s| now.duration_since(s.unchanged_since) >= settings.settle)
            },
            |n| {
                watch
                    .seen
                    .get(n)
                    .is_some_and(|s| now.duration_since(s.first_seen) >= settings.pair_wait)
            },
        );
        for unit in units {
            if self.ingest_stopping() {
                return;
            }
            // A file of the same name still in flight (a store failure being retried) is not
            // replaced: this one waits until that one is done.
            if unit
                .names()
                .iter()
                .any(|n| !matches!(f.importing.entry(n), Ok(None)))
            {
                waiting += unit.names().len();
                continue;
            }
            // So does a file with no free import slot, or whose bytes are not free in the
            // import budget now: it stays in the folder, and the files behind it go on.
            let held = match self.try_hold_unit(settings, &f.root, &unit) {
                Ok(Some(held)) => held,
                Ok(None) => {
                    waiting += unit.names().len();
                    continue;
                }
                Err(e) => {
                    self.note_error(e);
                    continue;
                }
            };
            // Into .importing/ first: from here on the file is the daemon's.
            let mut moved = Vec::new();
            let mut failed = None;
            for name in unit.names() {
                match f.root.move_to(name, &f.importing, name) {
                    Ok(()) => moved.push(name),
                    Err(e) => {
                        failed = Some(format!("cannot move {name} into {IMPORTING}/: {e}"));
                        break;
                    }
                }
            }
            for name in unit.names() {
                watch.seen.remove(name);
            }
            if let Some(e) = failed {
                // Put back what moved, to be tried again at the next pass.
                for name in moved {
                    if let Err(e) = f.importing.move_to(name, &f.root, name) {
                        tracing::warn!(error = %e, file = %name,
                            "cannot put the file back from .importing/ after a failed import");
                    }
                }
                self.note_error(e);
                continue;
            }
            self.spawn_import(settings, f, unit, false, held, guard);
        }
        self.with_ingest_status(|s| s.waiting = waiting);
    }

    /// Moves an entry that is not a plain regular file (a link, a hard link, a pipe) from
    /// `from` to `failed/` without reading it, beside a note saying why.
    fn refuse_unread(&self, f: &Folders, from: &Dir, name: &str, why: &str) {
        let reason = format!("{name} was not read: {why}");
        match self.file_to_failed(f, from, name, &reason) {
            Ok(()) => {
                self.with_ingest_status(|s| {
                    s.rejected += 1;
                    s.last_file = Some(name.to_string());
                    s.last_error = Some(reason.clone());
                });
                self.ctx.events.send(Event::FileRejected {
                    file: name.to_string(),
                    reason,
                });
            }
            Err(e) => self.note_error(format!("cannot move {name} into {FAILED}/: {e}")),
        }
    }

    /// Writes the note `failed/NAME.error.txt` (a new file, never through a link) and moves
    /// `name` from `from` to `failed/NAME`; both names are free ones.
    fn file_to_failed(
        &self,
        f: &Folders,
        from: &Dir,
        name: &str,
        reason: &str,
    ) -> Result<(), FsError> {
        let mut last = None;
        // A name taken between the choice and the move (by another writer) is tried again.
        for _ in 0..8 {
            let to = free_failed_name(&f.failed, name)?;
            let text = format!(
                "{name} was not imported into the store.\n\n{reason}\n\nFix the file and drop \
                 it into the watch folder again.\n"
            );
            match f
                .failed
                .write(&format!("{to}.error.txt"), text.as_bytes(), Replace::Never)
                .and_then(|_| from.move_to(name, &f.failed, &to))
            {
                Ok(()) => return Ok(()),
                Err(e @ (FsError::Exists { .. } | FsError::Symlink { .. })) => last = Some(e),
                Err(e) => return Err(e),
            }
        }
        Err(last.expect("tried at least once"))
    }

    /// Moves `name` from `.importing/` to a free name in `done/`, never replacing one; returns
    /// the name it has there.
    fn file_to_done(&self, f: &Folders, name: &str) -> Result<String, FsError> {
        let mut last = None;
        for _ in 0..8 {
            let to = f.done.free_name(name)?;
            match f.importing.move_to(name, &f.done, &to) {
                Ok(()) => return Ok(to),
                Err(e @ FsError::Exists { .. }) => last = Some(e),
                Err(e) => return Err(e),
            }
        }
        Err(last.expect("tried at least once"))
    }

    fn note_error(&self, message: String) {
        let mut changed = false;
        self.with_ingest_status(|s| {
            changed = s.last_error.as_deref() != Some(message.as_str());
            s.last_error = Some(message.clone());
        });
        if changed {
            tracing::error!(error = %message, "watch folder");
        }
    }

    /// Imports a unit whose files are in `.importing/`, and moves them to `done/` or
    /// `failed/`. `recovering`: the files were found in `.importing/` (a previous pass or run
    /// took them), so a recorded hash means that import committed.
    async fn finish(
        &self,
        settings: &IngestSettings,
        f: &Folders,
        unit: &Unit,
        recovering: bool,
        held: Held,
    ) {
        let outcome = if unit.orphan {
            Err(Failure::Rejected(format!(
                "{}: an SRA CSV with no MA-T12 export beside it within {} s; drop it together \
                 with its export (NAME.cxf, NAME.txt or NAME.cgats for NAME.sra.csv)",
                unit.main,
                settings.pair_wait.as_secs()
            )))
        } else {
            self.import_unit(settings, f, unit, recovering, &held.limits)
                .await
        };
        match outcome {
            Ok(Outcome::Repeat(note)) => {
                let anyway = match &unit.partner {
                    Some(p) => format!(
                        "brdfd import-format {} --sra {p} --out DIR, then brdfd import each \
                         DIR/*.scan.json",
                        unit.main
                    ),
                    None => format!("brdfd import --again {}", unit.main),
                };
                for name in unit.names() {
                    match self.file_to_done(f, name) {
                        Ok(to) => {
                            let text = format!(
                                "{name} was not imported again: {note}.\n\nTo import it \
                                 anyway, as new scans: {anyway}\n"
                            );
                            if let Err(e) = f.done.write(
                                &format!("{to}.note.txt"),
                                text.as_bytes(),
                                Replace::Never,
                            ) {
                                tracing::warn!(error = %e, file = %to, "cannot write the note");
                            }
                        }
                        Err(e) => self.note_error(format!("cannot move {name} into {DONE}/: {e}")),
                    }
                }
                let file = unit.shown();
                tracing::info!(file = %file, "{note}; moved to {DONE}/ with a note");
                self.with_ingest_status(|s| {
                    s.already_imported += 1;
                    s.last_file = Some(file.clone());
                });
            }
            Ok(done) => {
                for name in unit.names() {
                    if let Err(e) = self.file_to_done(f, name) {
                        self.note_error(format!("cannot move {name} into {DONE}/: {e}"));
                    }
                }
                if let Outcome::Imported(file, scans, sha256) = done {
                    self.with_ingest_status(|s| {
                        s.imported += 1;
                        s.last_file = Some(file.clone());
                    });
                    self.ctx.events.send(Event::FileImported {
                        file,
                        scans,
                        sha256,
                    });
                }
            }
            Err(Failure::Retry(message)) => {
                self.note_error(format!(
                    "{}: {message}; left in {IMPORTING}/ and tried again",
                    unit.shown()
                ));
            }
            Err(Failure::Rejected(reason)) => {
                for name in unit.names() {
                    if let Err(e) = self.file_to_failed(f, &f.importing, name, &reason) {
                        self.note_error(format!("cannot move {name} into {FAILED}/: {e}"));
                    }
                }
                let file = unit.shown();
                self.with_ingest_status(|s| {
                    s.rejected += 1;
                    s.last_file = Some(file.clone());
                    // The reason names the file already when a reader refused it.
                    s.last_error = Some(if reason.starts_with(&format!("{file}: ")) {
                        reason.clone()
                    } else {
                        format!("{file}: {reason}")
                    });
                });
                self.ctx.events.send(Event::FileRejected { file, reason });
            }
        }
    }

    /// Reads, checks and stores one unit.
    async fn import_unit(
        &self,
        settings: &IngestSettings,
        f: &Folders,
        unit: &Unit,
        recovering: bool,
        limits: &[ReadLimit],
    ) -> Result<Outcome, Failure> {
        let (hash, scans, textures) = {
            let limits = limits.to_vec();
            let unit = unit.clone();
            let reference = settings.reference.clone();
            let budget = settings.budget;
            let dir = f
                .importing
                .try_clone()
                .map_err(|e| Failure::Retry(e.to_string()))?;
            tokio::task::spawn_blocking(move || {
                read_unit(&dir, &unit, &reference, &limits, &budget)
            })
            .await
            .map_err(|e| Failure::Retry(format!("reading the file failed: {e}")))?
            .map_err(Failure::Rejected)?
        };
        for s in &scans {
            check_name("sample name", &s.sample)
                .and_then(|()| check_name("reference name", s.reference_label()))
                .map_err(|e| Failure::Rejected(format!("{}: {e}", unit.main)))?;
        }
        // The file named once, whatever the door (`pipeline::file_provenance`).
        let kind = match kind_of(&unit.main).map(|(k, _)| k) {
            Some(Kind::ScanFile) => super::pipeline::SCAN_FILE,
            Some(Kind::XriteXlsx) => super::pipeline::XRITE_XLSX,
            _ => "instrument software export",
        };
        let names: Vec<String> = scans
            .iter()
            .map(|s| format!("{}{IMPORTED_SUFFIX}", s.reference_label()))
            .collect();
        let readings: Vec<_> = scans
            .iter()
            .map(|s| {
                (
                    s.reference.as_ref().map(|r| new_readings(&r.readings)),
                    new_readings(&s.readings),
                )
            })
            .collect();
        // Each scan's own origin (an instrument export's time and instrument) over the file's.
        let origins: Vec<(Provenance, Option<i64>)> = scans
            .iter()
            .map(|s| {
                let (mut p, taken) = file_provenance(s, kind, Some(&unit.main))?;
                if let (Some(partner), Some(d)) = (&unit.partner, p.source_detail.as_mut()) {
                    d.push_str(&format!("; SRA readings from {partner}"));
                }
                Ok((p, taken))
            })
            .collect::<Result<_, crate::scan::ScanError>>()
            .map_err(|e| Failure::Rejected(format!("{}: {e}", unit.main)))?;
        let textures: Vec<Vec<NewTexture<'_>>> = textures.iter().map(|t| new_textures(t)).collect();
        let imports: Vec<ImportedScan<'_>> = scans
            .iter()
            .zip(&names)
            .zip(&readings)
            .zip(&origins)
            .zip(&textures)
            .map(|((((s, name), (r, m)), (p, taken)), t)| ImportedScan {
                sample_name: &s.sample,
                reference_name: name,
                provenance: p,
                reference_readings: r.as_deref(),
                readings: m,
                taken_at_ms: *taken,
                textures: t,
            })
            .collect();
        let stored = self
            .ctx
            .timed_store(self.ctx.store.import_file(
                &hash,
                &unit.main,
                unit.partner.as_deref(),
                &imports,
            ))
            .await;
        match stored {
            Ok(FileImport::Imported(file)) => {
                for &scan in &file.scans {
                    self.ctx.events.send(Event::ScanComplete { scan });
                }
                self.queue_ingest_fits(&file).await;
                Ok(Outcome::Imported(unit.shown(), file.scans, hash))
            }
            Ok(FileImport::AlreadyImported(file)) if recovering => {
                // This run or the last took it and committed; only the move was left.
                if !file.fits_queued {
                    self.queue_ingest_fits(&file).await;
                }
                Ok(Outcome::Committed)
            }
            Ok(FileImport::AlreadyImported(file)) => {
                // Every door's imports of this content, the watch folder's among them.
                let prior = match self.ctx.store.prior_import(&hash).await {
                    Ok(Some(p)) => p,
                    _ => crate::store::PriorImport {
                        sha256: file.sha256.clone(),
                        scans: file.scans.clone(),
                        file_name: Some(match &file.partner_name {
                            Some(p) => format!("{} and {p}", file.file_name),
                            None => file.file_name.clone(),
                        }),
                        imported_at_ms: file.imported_at_ms,
                    },
                };
                Ok(Outcome::Repeat(already_imported(&prior)))
            }
            Ok(FileImport::ImportedElsewhere(prior)) => {
                Ok(Outcome::Repeat(already_imported(&prior)))
            }
            Err(StoreError::Database(e)) => Err(Failure::Retry(format!("the store failed: {e}"))),
            Err(e) => Err(Failure::Rejected(format!("{}: {e}", unit.main))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn files(names: &[&str]) -> Vec<(String, Kind, String)> {
        names
            .iter()
            .map(|n| {
                let (k, s) = kind_of(n).unwrap();
                (n.to_string(), k, s)
            })
            .collect()
    }

    #[test]
    fn names_say_what_a_file_is_and_how_it_pairs() {
        assert_eq!(
            kind_of("Panel 3.CXF"),
            Some((Kind::Export(Format::Cxf3), "panel 3".into()))
        );
        assert_eq!(
            kind_of("a.txt"),
            Some((Kind::Export(Format::Cgats), "a".into()))
        );
        assert_eq!(kind_of("a.SRA.csv"), Some((Kind::SraCsv, "a".into())));
        assert_eq!(kind_of("a.scan.json"), Some((Kind::ScanFile, "a".into())));
        assert_eq!(
            kind_of("PAR_1.XLSX"),
            Some((Kind::XriteXlsx, "par_1".into()))
        );
        for ignored in [".a.cxf", "a.csv", "a.json", "a.cxf.part", ".scan.json", "x"] {
            assert_eq!(kind_of(ignored), None, "{ignored}");
        }
    }

    #[test]
    fn exports_pair_with_their_sra_csv_and_wait_for_it() {
        let f = files(&["a.cxf", "a.sra.csv", "b.txt", "c.sra.csv", "d.scan.json"]);
        // Everything settled, nothing waited long: a pairs, d goes alone, b and c wait.
        let (u, waiting) = units(&f, |_| true, |_| false);
        assert_eq!(
            u,
            vec![
                Unit {
                    main: "a.cxf".into(),
                    partner: Some("a.sra.csv".into()),
                    orphan: false
                },
                Unit {
                    main: "d.scan.json".into(),
                    partner: None,
                    orphan: false
                },
            ]
        );
        assert_eq!(waiting, 2);
        // After pair_wait: b alone, c rejected as an orphan.
        let (u, waiting) = units(&f, |_| true, |_| true);
        assert_eq!(u.len(), 4);
        assert!(u.contains(&Unit {
            main: "b.txt".into(),
            partner: None,
            orphan: false
        }));
        assert!(u.contains(&Unit {
            main: "c.sra.csv".into(),
            partner: None,
            orphan: true
        }));
        assert_eq!(waiting, 0);
        // A pair waits while its CSV is still changing.
        let (u, waiting) = units(&f, |n| n != "a.sra.csv", |_| true);
        assert!(!u.iter().any(|u| u.main == "a.cxf"));
        assert_eq!(waiting, 2);
    }

    #[test]
    fn hashes_and_free_names() {
        assert_eq!(
            content_hash(b"abc", None),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        // Moving bytes between the two files of a pair changes the hash.
        assert_ne!(
            content_hash(b"ab", Some(b"c")),
            content_hash(b"a", Some(b"bc"))
        );
        let dir = tempfile::tempdir().unwrap();
        let d = Dir::open(dir.path()).unwrap();
        assert_eq!(free_failed_name(&d, "p.sra.csv").unwrap(), "p.sra.csv");
        std::fs::write(dir.path().join("p.sra.csv"), "").unwrap();
        assert_eq!(free_failed_name(&d, "p.sra.csv").unwrap(), "p-2.sra.csv");
        // A note's name taken (a planted link) moves both on.
        std::os::unix::fs::symlink("/nowhere", dir.path().join("p-2.sra.csv.error.txt")).unwrap();
        assert_eq!(free_failed_name(&d, "p.sra.csv").unwrap(), "p-3.sra.csv");
    }
}
