//! `brdfd doctor`: every check of a station's set-up at once, each failure with its fix, so a
//! new user does not find the problems one error at a time.
//!
//! This module owns the checks and their wording: the configuration (and which file), the
//! store's directory and file (writable by this user), the store's lock (`src/store/lock.rs`:
//! free, or held by the daemon that answers; a lock held by a live process that is not an
//! answering daemon, or naming a process that has ended, is a failure), the daemon (reachable
//! with the API token), the MA-T12 on USB (vendor id 0765 in `/sys/bus/usb/devices`, and its
//! device node readable and writable), the SRA's serial port (present, and in a group of the
//! user's), forwarding (the central database of `[sync] url` answers, and this store's standing
//! there: registered by it, not a refused copy, how many entries wait), and the clock (not before this brdfd was built). Device checks of simulated
//! instruments say "simulated: skipped". Nothing is changed: files are probed with a temporary
//! file that is removed, device nodes with `access(2)`, the lock by trying it for an instant.
//! The exit status is non-zero if any check fails; `--json` prints one JSON object.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::config::{Config, MaT12Transport, SraTransport};

#[derive(Debug, clap::Args)]
pub struct DoctorArgs {
    /// The configuration file to check (and to take the store, address and devices from).
    #[arg(long, short, value_name = "FILE", env = "BRDFD_CONFIG")]
    pub config: Option<PathBuf>,
    /// The daemon's API address [default: [api] listen of the configuration].
    #[arg(long, value_name = "IP:PORT")]
    pub addr: Option<SocketAddr>,
    /// The file holding the daemon's API token [default: [api] token_file, else brdfd.token
    /// beside the store]. BRDFD_TOKEN, when set, is used instead.
    #[arg(long, value_name = "FILE")]
    pub token_file: Option<PathBuf>,
    /// Print one JSON object: `{"ok", "config_file", "checks": [{"check", "status", "detail",
    /// "fix"}]}`, status "ok", "fail" or "skipped".
    #[arg(long)]
    pub json: bool,
}

/// How a check ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    Ok,
    Fail,
    Skipped,
}

/// One check's result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Check {
    pub check: &'static str,
    pub status: Outcome,
    /// What was found.
    pub detail: String,
    /// What to do, for a failure.
    pub fix: Option<String>,
}

impl Check {
    fn ok(check: &'static str, detail: impl Into<String>) -> Check {
        Check {
            check,
            status: Outcome::Ok,
            detail: detail.into(),
            fix: None,
        }
    }
    fn fail(check: &'static str, detail: impl Into<String>, fix: impl Into<String>) -> Check {
        Check {
            check,
            status: Outcome::Fail,
            detail: detail.into(),
            fix: Some(fix.into()),
        }
    }
    fn skipped(check: &'static str, detail: impl Into<String>) -> Check {
        Check {
            check,
            status: Outcome::Skipped,
            detail: detail.into(),
            fix: None,
        }
    }
}

/// The whole report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    pub ok: bool,
    /// The configuration file read, or `None` for the built-in defaults.
    pub config_file: Option<String>,
    pub checks: Vec<Check>,
}

pub fn run(args: &DoctorArgs) -> anyhow::Result<()> {
    let report = diagnose(args);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        for c in &report.checks {
            let tag = match c.status {
                Outcome::Ok => "ok  ",
                Outcome::Fail => "FAIL",
                Outcome::Skipped => "skip",
            };
            println!("{tag} {}: {}", c.check, c.detail);
            if let Some(fix) = &c.fix {
                println!("     fix: {fix}");
            }
        }
    }
    let failed = report
        .checks
        .iter()
        .filter(|c| c.status == Outcome::Fail)
        .count();
    if failed > 0 {
        anyhow::bail!(
            "{failed} of {} checks failed (each is shown with its fix {})",
            report.checks.len(),
            if args.json { "in the JSON" } else { "above" }
        );
    }
    Ok(())
}

/// Runs every check.
pub fn diagnose(args: &DoctorArgs) -> Report {
    let mut checks = Vec::new();
    // The same search as every other command: --config, BRDFD_CONFIG, the user's and the
    // system's file, else the defaults.
    let origin = match &args.config {
        Some(path) => crate::config::ConfigOrigin::File {
            path: path.clone(),
            via: "--config",
        },
        None => Config::search(&crate::config::SearchEnv::from_process()),
    };
    let config_file = match &origin {
        crate::config::ConfigOrigin::File { path, .. } => Some(path.display().to_string()),
        crate::config::ConfigOrigin::Defaults => None,
    };
    let config = match &origin {
        crate::config::ConfigOrigin::File { path, via } => match Config::load(path) {
            Ok(c) => {
                checks.push(Check::ok(
                    "config",
                    format!(
                        "{} parses and every value is accepted (found through {via})",
                        path.display()
                    ),
                ));
                Some(c)
            }
            Err(e) => {
                checks.push(Check::fail(
                    "config",
                    e.to_string(),
                    "correct the line and key named (config/brdfd.toml has every key with a \
                     comment), or point --config / BRDFD_CONFIG at another file",
                ));
                None
            }
        },
        crate::config::ConfigOrigin::Defaults => {
            checks.push(Check::ok(
                "config",
                format!("{origin}: simulated instruments, brdfd.db in the working directory"),
            ));
            Some(Config::default())
        }
    };
    match &config {
        Some(config) => {
            checks.push(store_check(&config.store.path));
            let daemon = daemon_check(config, args);
            let daemon_ok = daemon.status == Outcome::Ok;
            checks.push(lock_check(&config.store.path, daemon_ok, config.api.listen));
            checks.push(daemon);
            checks.push(central_check(config));
            checks.push(usb_check(&config.devices.ma_t12.transport));
            checks.push(serial_check(&config.devices.sra.transport));
        }
        None => {
            for name in [
                "store",
                "store lock",
                "daemon",
                "central database",
                "MA-T12 (USB)",
                "SRA (serial)",
            ] {
                checks.push(Check::skipped(name, "the configuration does not parse"));
            }
        }
    }
    checks.push(clock_check(now_unix(), build_unix()));
    Report {
        ok: checks.iter().all(|c| c.status != Outcome::Fail),
        config_file,
        checks,
    }
}

fn user() -> String {
    // SAFETY: geteuid has no preconditions.
    let uid = unsafe { libc::geteuid() };
    match name_of_id("/etc/passwd", uid) {
        Some(name) => format!("{name} (uid {uid})"),
        None => format!("uid {uid}"),
    }
}

/// The name of user or group `id` in an `/etc/passwd`-shaped file.
fn name_of_id(file: &str, id: u32) -> Option<String> {
    let text = std::fs::read_to_string(file).ok()?;
    text.lines().find_map(|l| {
        let mut f = l.split(':');
        let name = f.next()?;
        let _pw = f.next()?;
        (f.next()?.parse::<u32>().ok()? == id).then(|| name.to_string())
    })
}

/// The store's directory and file: present and writable by this user.
fn store_check(db: &Path) -> Check {
    const NAME: &str = "store";
    let dir = match db.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if !dir.is_dir() {
        return Check::fail(
            NAME,
            format!(
                "the store's directory {} does not exist ([store] path = {})",
                dir.display(),
                db.display()
            ),
            format!(
                "create it for brdfd's user (mkdir -p {}), or set [store] path",
                dir.display()
            ),
        );
    }
    let probe = dir.join(format!(".brdfd-doctor-{}", std::process::id()));
    match std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
    {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
        }
        Err(e) => {
            return Check::fail(
                NAME,
                format!(
                    "{} cannot create files in {} ({e}); the store, its write-ahead log and its \
                     lock file live there",
                    user(),
                    dir.display()
                ),
                format!(
                    "run brdfd as the user that owns {0} (the systemd unit's user brdfd), or \
                     give this user write access (chown USER {0}), or set [store] path to a \
                     writable place",
                    dir.display()
                ),
            );
        }
    }
    for file in [db.to_path_buf(), crate::store::lock::lock_path(db)] {
        if !file.exists() {
            continue;
        }
        if let Err(e) = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&file)
        {
            return Check::fail(
                NAME,
                format!(
                    "{} cannot open {} for writing ({e})",
                    user(),
                    file.display()
                ),
                format!(
                    "run brdfd as the file's owner, or chown it to brdfd's user: chown USER {}",
                    file.display()
                ),
            );
        }
    }
    Check::ok(
        NAME,
        if db.exists() {
            format!("{} exists and is writable by {}", db.display(), user())
        } else {
            format!(
                "{} will be created at the first start ({} may write to {})",
                db.display(),
                user(),
                dir.display()
            )
        },
    )
}

/// The PID a lock file's text names (`pid N — …`).
fn named_pid(text: &str) -> Option<i32> {
    text.strip_prefix("pid ")?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

/// Whether process `pid` exists.
fn alive(pid: i32) -> bool {
    if pid <= 0 {
        return false;
    }
    // SAFETY: signal 0 only checks that the process exists and may be signalled.
    let r = unsafe { libc::kill(pid, 0) };
    r == 0 || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
}

/// The store's lock: free, or held by the daemon that answers.
fn lock_check(db: &Path, daemon_ok: bool, addr: SocketAddr) -> Check {
    const NAME: &str = "store lock";
    let file = crate::store::lock::lock_path(db);
    match crate::store::lock::holder(db) {
        Ok(None) => {
            let last = std::fs::read_to_string(&file).ok();
            let detail = match last.as_deref().and_then(named_pid) {
                Some(pid) => format!(
                    "free; {} names pid {pid}, which no longer holds it (a stopped or crashed \
                     brdfd leaves no stale lock: the kernel releases it)",
                    file.display()
                ),
                None => "free".to_string(),
            };
            Check::ok(NAME, detail)
        }
        Ok(Some(holder)) => match named_pid(&holder) {
            Some(pid) if alive(pid) && daemon_ok => {
                Check::ok(NAME, format!("held by the running daemon ({holder})"))
            }
            Some(pid) if alive(pid) => Check::fail(
                NAME,
                format!(
                    "held by pid {pid} ({holder}), which is running, but no daemon answers on \
                     {addr}: `brdfd serve` on this store will be refused while it holds it"
                ),
                format!(
                    "let that command finish, or stop it (kill {pid}); if it is a daemon on \
                     another address, point --addr or [api] listen at it"
                ),
            ),
            _ => Check::fail(
                NAME,
                format!(
                    "held, but the holder named in {} ({}) has ended: a process that inherited \
                     its open lock file holds it",
                    file.display(),
                    if holder.is_empty() {
                        "nobody"
                    } else {
                        holder.as_str()
                    }
                ),
                format!(
                    "find the process with `fuser -v {0}` (or `lsof {0}`) and stop it",
                    file.display()
                ),
            ),
        },
        Err(e) => Check::fail(
            NAME,
            format!("cannot check {}: {e}", file.display()),
            format!(
                "run as brdfd's user, or give it write access to {}",
                file.display()
            ),
        ),
    }
}

/// The daemon: answers `GET /status` with the token.
fn daemon_check(config: &Config, args: &DoctorArgs) -> Check {
    const NAME: &str = "daemon";
    let addr = args.addr.unwrap_or(config.api.listen);
    let client = crate::client::Client::new(addr);
    let (client, source) = if let Ok(text) = std::env::var("BRDFD_TOKEN") {
        match crate::api::Token::parse(&text) {
            Some(t) => (
                client.with_token(&t, "sent the token of BRDFD_TOKEN"),
                "BRDFD_TOKEN".to_string(),
            ),
            None => {
                return Check::fail(
                    NAME,
                    "BRDFD_TOKEN does not hold an API token (64 hex digits)",
                    "unset BRDFD_TOKEN to use the token file, or set it to the file's content",
                );
            }
        }
    } else {
        let path = args
            .token_file
            .clone()
            .unwrap_or_else(|| config.api.token_path(&config.store.path));
        match crate::api::Token::read(&path) {
            Ok(t) => (
                client.with_token(&t, format!("sent the token of {}", path.display())),
                path.display().to_string(),
            ),
            Err(e) => {
                // Whether anything listens is still worth saying.
                let listening =
                    std::net::TcpStream::connect_timeout(&addr, std::time::Duration::from_secs(2))
                        .is_ok();
                return Check::fail(
                    NAME,
                    format!(
                        "{e}{}",
                        if listening {
                            format!(" (something listens on {addr})")
                        } else {
                            format!("; nothing listens on {addr} either")
                        }
                    ),
                    "start the daemon (`brdfd serve --config FILE`, or `systemctl start brdfd`), \
                     which creates the token file; read it as the daemon's user or a member of \
                     its group, or pass --token-file / BRDFD_TOKEN",
                );
            }
        }
    };
    match client.status() {
        Ok(v) => Check::ok(
            NAME,
            format!(
                "brdfd {} answers on {addr} and accepts the token of {source}",
                super::operator::terminal_safe(&v.version)
            ),
        ),
        Err(crate::client::ClientError::NotRunning { .. }) => Check::fail(
            NAME,
            format!("no brdfd daemon is listening on {addr}"),
            "start it: `brdfd serve --config FILE` (or `systemctl start brdfd`); if it runs \
             elsewhere, pass --addr or set [api] listen",
        ),
        Err(e @ crate::client::ClientError::Unauthorized { .. }) => Check::fail(
            NAME,
            e.to_string(),
            "use the daemon's own token file ([api] token_file, else brdfd.token beside its \
             store): pass --config with the daemon's configuration, --token-file or BRDFD_TOKEN",
        ),
        Err(e) => Check::fail(
            NAME,
            e.to_string(),
            format!("check that the process on {addr} is brdfd (`brdfd status --addr {addr}`)"),
        ),
    }
}

/// The X-Rite vendor id.
pub const XRITE_VENDOR: &str = "0765";

/// An X-Rite device in sysfs: (sysfs name, product id, device node).
/// Forwarding: the central database answers, and this store's standing there as
/// `[station] id` (src/sync/forward.rs `diagnose`: read only, on both sides).
fn central_check(config: &Config) -> Check {
    const NAME: &str = "central database";
    let Some(url) = &config.sync.url else {
        return Check::skipped(NAME, "no [sync] url: this station does not forward");
    };
    let rt = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            return Check::fail(
                NAME,
                format!("cannot start the async runtime: {e}"),
                "retry",
            );
        }
    };
    let result = rt.block_on(crate::sync::forward::diagnose(
        &config.store.path,
        url,
        &config.station.id,
    ));
    match result {
        Ok(detail) => Check::ok(NAME, detail),
        Err(e) => {
            use crate::sync::SyncError;
            let fix = match &e {
                SyncError::Forked { .. } => format!(
                    "this store is a copy of station \"{}\"'s store: stop its daemon, run \
                     `brdfd sync --db {} --adopt NEW_ID` and set [station] id = \"NEW_ID\"; or, \
                     to make it the station (a bench moved to a new PC), stop the old store's \
                     daemon and run `brdfd sync --db {} --retire-old ARCHIVE_ID`",
                    config.station.id,
                    config.store.path.display(),
                    config.store.path.display()
                ),
                SyncError::Archived { .. } => {
                    "give this station its own [station] id in brdfd.toml".to_string()
                }
                SyncError::StationTaken { .. } | SyncError::StoreHasOtherId { .. } => {
                    "give this station its own [station] id in brdfd.toml".to_string()
                }
                SyncError::NewerSchema { .. } => "upgrade brdfd on this station".to_string(),
                _ => "check [sync] url (host, port, user, password, database) and that the \
                      server runs; the station keeps measuring meanwhile"
                    .to_string(),
            };
            Check::fail(NAME, crate::sync::forward::describe(&e), fix)
        }
    }
}

fn xrite_devices(sysfs: &Path) -> Vec<(String, String, PathBuf)> {
    let Ok(entries) = std::fs::read_dir(sysfs) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for e in entries.flatten() {
        let p = e.path();
        let read = |f: &str| {
            std::fs::read_to_string(p.join(f))
                .ok()
                .map(|s| s.trim().to_string())
        };
        if read("idVendor").as_deref() != Some(XRITE_VENDOR) {
            continue;
        }
        let product = read("idProduct").unwrap_or_default();
        let node = match (read("busnum"), read("devnum")) {
            (Some(b), Some(d)) => match (b.parse::<u32>(), d.parse::<u32>()) {
                (Ok(b), Ok(d)) => PathBuf::from(format!("/dev/bus/usb/{b:03}/{d:03}")),
                _ => continue,
            },
            _ => continue,
        };
        out.push((e.file_name().to_string_lossy().into_owned(), product, node));
    }
    out.sort();
    out
}

/// Whether this user may read and write `path` (`access(2)`, real ids).
fn accessible(path: &Path) -> std::io::Result<()> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(path.as_os_str().as_bytes())
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))?;
    // SAFETY: a valid NUL-terminated path; access only reads it.
    if unsafe { libc::access(c.as_ptr(), libc::R_OK | libc::W_OK) } == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// The MA-T12 on USB: attached (vendor 0765) and its node readable and writable.
fn usb_check(transport: &MaT12Transport) -> Check {
    const NAME: &str = "MA-T12 (USB)";
    let product_id = match transport {
        MaT12Transport::Simulated { .. } => return Check::skipped(NAME, "simulated: skipped"),
        MaT12Transport::Usb { product_id } => *product_id,
    };
    let all = xrite_devices(Path::new("/sys/bus/usb/devices"));
    let wanted = product_id.map(|p| format!("{p:04x}"));
    let found: Vec<_> = all
        .iter()
        .filter(|(_, product, _)| wanted.as_deref().is_none_or(|w| w == product))
        .collect();
    let Some((name, product, node)) = found.first() else {
        return Check::fail(
            NAME,
            match (&wanted, all.is_empty()) {
                (Some(w), false) => format!(
                    "X-Rite devices are attached, but none with product id {w} ([devices.ma_t12] \
                     product_id): {}",
                    all.iter()
                        .map(|(_, p, _)| format!("0765:{p}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
                _ => format!(
                    "no X-Rite device (USB vendor id {XRITE_VENDOR}) is attached{}",
                    wanted
                        .as_ref()
                        .map(|w| format!(" (product id {w} asked for)"))
                        .unwrap_or_default()
                ),
            },
            "plug the MA-T12 in (a port on the PC, not an unpowered hub) and switch it on; \
             `lsusb -d 0765:` must list it; fix or remove [devices.ma_t12] product_id if set",
        );
    };
    match accessible(node) {
        Ok(()) => Check::ok(
            NAME,
            format!(
                "0765:{product} at {name}, {} readable and writable",
                node.display()
            ),
        ),
        Err(e) => Check::fail(
            NAME,
            format!(
                "0765:{product} at {name}, but {} cannot open {} ({e})",
                user(),
                node.display()
            ),
            "install the udev rule that gives the node to brdfd's group: install -D -m 0644 \
             config/70-brdfd.rules /etc/udev/rules.d/70-brdfd.rules && udevadm control --reload \
             && udevadm trigger; then add the user to that group (usermod -aG brdfd USER) and \
             log in again",
        ),
    }
}

/// The groups of this process (effective group and supplementary groups).
fn my_groups() -> Vec<u32> {
    // SAFETY: getgroups with a buffer of the size it reported.
    unsafe {
        let n = libc::getgroups(0, std::ptr::null_mut());
        let mut gs = vec![0 as libc::gid_t; n.max(0) as usize];
        let n = libc::getgroups(gs.len() as i32, gs.as_mut_ptr());
        gs.truncate(n.max(0) as usize);
        gs.push(libc::getegid());
        gs
    }
}

/// The SRA's serial port: present, and readable and writable through a group of the user's.
fn serial_check(transport: &SraTransport) -> Check {
    use std::os::unix::fs::MetadataExt;
    const NAME: &str = "SRA (serial)";
    let port = match transport {
        SraTransport::Simulated { .. } => return Check::skipped(NAME, "simulated: skipped"),
        SraTransport::Off => return Check::skipped(NAME, "turned off: skipped"),
        SraTransport::Serial { port, .. } => port,
    };
    let path = Path::new(port);
    let meta = match std::fs::metadata(path) {
        Ok(m) => m,
        Err(e) => {
            return Check::fail(
                NAME,
                format!("the serial port {port} ([devices.sra] port) is not there ({e})"),
                "plug in the RA-532H's serial or USB-serial cable; `ls /dev/serial/by-id/` lists \
                 the ports present; set [devices.sra] port to the right one (a /dev/serial/by-id/ \
                 name survives re-plugging)",
            );
        }
    };
    let gid = meta.gid();
    let group = name_of_id("/etc/group", gid).unwrap_or_else(|| gid.to_string());
    let member = my_groups().contains(&gid);
    match accessible(path) {
        Ok(()) => Check::ok(
            NAME,
            format!(
                "{port} is there (group {group}, mode {:o}) and {} may read and write it",
                meta.mode() & 0o777,
                user()
            ),
        ),
        Err(e) if !member => Check::fail(
            NAME,
            format!(
                "{port} belongs to group {group} (mode {:o}), and {} is not in it ({e})",
                meta.mode() & 0o777,
                user()
            ),
            format!(
                "add the user to the group: sudo usermod -aG {group} USER, then log in again \
                 (the systemd unit has SupplementaryGroups=dialout)"
            ),
        ),
        Err(e) => Check::fail(
            NAME,
            format!(
                "{port} (group {group}, mode {:o}) cannot be opened by {} ({e})",
                meta.mode() & 0o777,
                user()
            ),
            format!(
                "give the group read and write access (chmod g+rw {port}, or a udev rule with \
                 MODE=\"0660\"), or log in again if you were just added to {group}"
            ),
        ),
    }
}

fn now_unix() -> i64 {
    crate::store::now_ms() / 1000
}

/// When this brdfd was built (seconds since the epoch; `build.rs`).
fn build_unix() -> i64 {
    env!("BRDFD_BUILD_UNIX").parse().unwrap_or(0)
}

/// The clock: not before the build (scan times and the reference's age depend on it).
fn clock_check(now: i64, built: i64) -> Check {
    const NAME: &str = "clock";
    let now_s = crate::formats::rfc3339_utc(now);
    if now < built {
        Check::fail(
            NAME,
            format!(
                "the clock says {now_s}, before this brdfd was built ({}): scan times and the \
                 reference's age would be wrong",
                crate::formats::rfc3339_utc(built)
            ),
            "set the clock: `timedatectl set-ntp true` (or `sudo date -s …`), and check the \
             PC's CMOS battery if it loses the time at every boot",
        )
    } else {
        Check::ok(
            NAME,
            format!(
                "{now_s}, after this brdfd was built ({})",
                crate::formats::rfc3339_utc(built)
            ),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_clock_before_the_build_fails_with_its_fix() {
        let c = clock_check(1_000, 2_000);
        assert_eq!(c.status, Outcome::Fail);
        assert!(c.detail.contains("before this brdfd was built"), "{c:?}");
        assert!(c.fix.unwrap().contains("timedatectl"));
        assert_eq!(clock_check(2_000, 2_000).status, Outcome::Ok);
        // The real clock is after this build.
        assert_eq!(clock_check(now_unix(), build_unix()).status, Outcome::Ok);
        assert!(build_unix() > 1_700_000_000);
    }

    #[test]
    fn lock_files_name_their_pid() {
        assert_eq!(named_pid("pid 42 — brdfd serve on http://x"), Some(42));
        assert_eq!(named_pid("garbage"), None);
        assert!(alive(std::process::id() as i32));
        assert!(!alive(0));
    }

    #[test]
    fn x_rite_devices_are_found_by_vendor_id_in_sysfs() {
        let dir = tempfile::tempdir().unwrap();
        for (name, vendor, product, bus, dev) in [
            ("1-1", "0765", "5020", "1", "7"),
            ("1-2", "046d", "c52b", "1", "3"),
        ] {
            let d = dir.path().join(name);
            std::fs::create_dir(&d).unwrap();
            for (f, v) in [
                ("idVendor", vendor),
                ("idProduct", product),
                ("busnum", bus),
                ("devnum", dev),
            ] {
                std::fs::write(d.join(f), format!("{v}\n")).unwrap();
            }
        }
        assert_eq!(
            xrite_devices(dir.path()),
            vec![(
                "1-1".to_string(),
                "5020".to_string(),
                PathBuf::from("/dev/bus/usb/001/007")
            )]
        );
    }

    #[test]
    fn simulated_instruments_are_skipped() {
        let c = usb_check(&MaT12Transport::Simulated { session: None });
        assert_eq!(
            (c.status, c.detail.as_str()),
            (Outcome::Skipped, "simulated: skipped")
        );
        let c = serial_check(&SraTransport::Simulated { session: None });
        assert_eq!(
            (c.status, c.detail.as_str()),
            (Outcome::Skipped, "simulated: skipped")
        );
    }
}
