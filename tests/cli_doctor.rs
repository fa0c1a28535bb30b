//! `brdfd doctor` as a child process: one test per failing check (a store directory the user
//! cannot write, no MA-T12 on USB and no serial port, a serial port in a group the user is not
//! in, the store's lock held by a live process and naming one that has ended), and the passing
//! case against a live `brdfd serve` with simulated instruments. Each reads `--json` and the
//! exit status; the text output is checked to carry each failure's fix.
//!
//! The permission tests run `doctor` as the user `nobody` (uid 65534) when the tests run as
//! root (root passes every permission check), and as the user itself otherwise.

// `serial()` is held across each whole test on purpose.
#![allow(clippy::await_holding_lock)]

mod common;

use std::os::unix::fs::PermissionsExt;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use serde_json::Value;

use common::*;

const NOBODY: u32 = 65534;

fn is_root() -> bool {
    // SAFETY: geteuid has no preconditions.
    unsafe { libc::geteuid() == 0 }
}

/// A directory every user may enter (tempdir makes 0700 ones).
fn open_dir() -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::set_permissions(tmp.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
    tmp
}

/// A configuration in `dir` with the store at `db`, the API on `listen`, and `devices`.
fn config(dir: &Path, db: &Path, listen: &str, devices: &str) -> PathBuf {
    let path = dir.join("brdfd.toml");
    std::fs::write(
        &path,
        format!(
            "[store]\npath = \"{}\"\n\n[api]\nlisten = \"{listen}\"\n\n[log]\nlevel = \"warn\"\n\n{devices}",
            db.display()
        ),
    )
    .unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
    path
}

const SIMULATED: &str =
    "[devices.ma_t12]\ntransport = \"simulated\"\n\n[devices.sra]\ntransport = \"simulated\"\n";

/// A port nothing listens on: bound, then released.
fn free_port() -> String {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    l.local_addr().unwrap().to_string()
}

struct Doctor {
    success: bool,
    json: Value,
    text: String,
}

impl Doctor {
    fn check(&self, name: &str) -> &Value {
        self.json["checks"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["check"] == name)
            .unwrap_or_else(|| panic!("no check {name} in {}", self.json))
    }

    fn status(&self, name: &str) -> &str {
        self.check(name)["status"].as_str().unwrap()
    }

    fn detail(&self, name: &str) -> String {
        self.check(name)["detail"].as_str().unwrap().to_string()
    }

    fn fix(&self, name: &str) -> String {
        self.check(name)["fix"].as_str().unwrap_or("").to_string()
    }

    /// Asserts that check `name`'s detail says `part`, with the whole answer if not.
    #[track_caller]
    fn assert_detail(&self, name: &str, part: &str) {
        assert!(self.detail(name).contains(part), "{}", self.json);
    }

    /// Asserts that check `name`'s fix says `part`, with the whole answer if not.
    #[track_caller]
    fn assert_fix(&self, name: &str, part: &str) {
        assert!(self.fix(name).contains(part), "{}", self.json);
    }
}

/// Runs `brdfd doctor --config CONFIG` twice (`--json` and text), as `uid` if given.
fn doctor(config: &Path, uid: Option<u32>) -> Doctor {
    // Another user may not be able to reach the build directory (a checkout under a 0700
    // directory): run a copy of the binary from a directory anyone can enter.
    let copy = uid.map(|_| {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
        let bin = dir.path().join("brdfd");
        std::fs::copy(env!("CARGO_BIN_EXE_brdfd"), &bin).unwrap();
        std::fs::set_permissions(&bin, std::fs::Permissions::from_mode(0o755)).unwrap();
        (dir, bin)
    });
    let program = copy
        .as_ref()
        .map_or(Path::new(env!("CARGO_BIN_EXE_brdfd")), |(_, bin)| {
            bin.as_path()
        });
    let run = |json: bool| {
        let mut cmd = Command::new(program);
        cmd.arg("doctor").arg("--config").arg(config);
        if json {
            cmd.arg("--json");
        }
        cmd.env_remove("BRDFD_TOKEN").env_remove("BRDFD_CONFIG");
        cmd.current_dir(config.parent().unwrap());
        if let Some(uid) = uid {
            // As root, std also drops the supplementary groups.
            cmd.uid(uid).gid(uid);
        }
        // The copy was just written: while another test thread forks, its child briefly holds
        // the copy's write descriptor (until it execs), and exec fails with ETXTBSY. Retry.
        let mut tries = 0;
        loop {
            match cmd.output() {
                Err(e) if e.kind() == std::io::ErrorKind::ExecutableFileBusy && tries < 100 => {
                    tries += 1;
                    std::thread::sleep(std::time::Duration::from_millis(10));
                }
                r => break r.expect("brdfd doctor runs"),
            }
        }
    };
    let json = run(true);
    let text = run(false);
    assert_eq!(json.status.code(), text.status.code());
    let stderr = String::from_utf8_lossy(&json.stderr).to_string();
    let parsed: Value = serde_json::from_slice(&json.stdout)
        .unwrap_or_else(|e| panic!("doctor --json: {e}; stderr {stderr}"));
    assert_eq!(
        parsed["ok"].as_bool(),
        Some(json.status.success()),
        "the exit status follows the checks: {parsed}"
    );
    if !json.status.success() {
        assert!(stderr.contains("checks failed"), "{stderr}");
    }
    Doctor {
        success: json.status.success(),
        json: parsed,
        text: String::from_utf8(text.stdout).unwrap(),
    }
}

#[test]
fn with_a_daemon_running_on_simulated_instruments_every_check_passes() {
    let _serial = serial();
    let tmp = open_dir();
    let dir = tmp.path();
    let cfg = config(dir, &dir.join("brdfd.db"), "127.0.0.1:0", SIMULATED);
    let mut child = Command::new(env!("CARGO_BIN_EXE_brdfd"))
        .args(["serve", "--config"])
        .arg(&cfg)
        .env_remove("BRDFD_TOKEN")
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let line = serve::first_line(&mut child).unwrap();
    let addr = line
        .split("http://")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .unwrap()
        .to_string();
    // The daemon's address into the configuration doctor reads.
    let cfg = config(dir, &dir.join("brdfd.db"), &addr, SIMULATED);
    let d = doctor(&cfg, None);
    let _ = child.kill();
    let _ = child.wait();
    assert!(d.success, "{}", d.json);
    assert_eq!(d.json["config_file"], cfg.display().to_string());
    assert!(d.detail("config").contains("brdfd.toml parses"));
    assert_eq!(d.status("store"), "ok");
    assert_eq!(d.status("store lock"), "ok");
    assert!(
        d.detail("store lock")
            .contains("held by the running daemon")
    );
    assert_eq!(d.status("daemon"), "ok");
    d.assert_detail("daemon", "accepts the token");
    for device in ["MA-T12 (USB)", "SRA (serial)"] {
        assert_eq!(d.status(device), "skipped");
        assert_eq!(d.detail(device), "simulated: skipped");
    }
    assert_eq!(d.status("clock"), "ok");
    assert!(
        d.text.contains("skip MA-T12 (USB): simulated: skipped"),
        "{}",
        d.text
    );
}

#[test]
fn a_config_that_does_not_parse_fails_naming_its_line() {
    let tmp = open_dir();
    let cfg = tmp.path().join("brdfd.toml");
    std::fs::write(&cfg, "[api]\nlisten = \"nowhere\"\n").unwrap();
    let d = doctor(&cfg, None);
    assert!(!d.success);
    assert_eq!(d.status("config"), "fail");
    d.assert_detail("config", "brdfd.toml:2");
    assert_eq!(d.status("daemon"), "skipped");
    assert_eq!(d.status("clock"), "ok");
}

#[test]
fn a_store_directory_the_user_cannot_write_fails_with_its_fix() {
    let tmp = open_dir();
    let store = tmp.path().join("store");
    std::fs::create_dir(&store).unwrap();
    // Root-owned 0755 is not writable for nobody; for a normal user, 0555 is not writable.
    let (mode, uid) = if is_root() {
        (0o755, Some(NOBODY))
    } else {
        (0o555, None)
    };
    std::fs::set_permissions(&store, std::fs::Permissions::from_mode(mode)).unwrap();
    let cfg = config(tmp.path(), &store.join("brdfd.db"), &free_port(), SIMULATED);
    let d = doctor(&cfg, uid);
    std::fs::set_permissions(&store, std::fs::Permissions::from_mode(0o755)).unwrap();
    assert!(!d.success);
    assert_eq!(d.status("store"), "fail", "{}", d.json);
    d.assert_detail("store", "cannot create files in");
    d.assert_detail("store", "Permission denied");
    d.assert_fix("store", "chown");
    assert!(d.text.contains("FAIL store:"), "{}", d.text);
    assert!(d.text.contains("fix: run brdfd as the user"), "{}", d.text);
    // And nothing was left behind by the probe of a writable directory.
    let d = doctor(&cfg, None);
    assert_eq!(d.status("store"), "ok", "{}", d.json);
    assert!(std::fs::read_dir(&store).unwrap().next().is_none());
}

#[test]
fn no_daemon_no_mat12_and_no_serial_port_fail_with_their_fixes() {
    let tmp = open_dir();
    let cfg = config(
        tmp.path(),
        &tmp.path().join("brdfd.db"),
        &free_port(),
        "[devices.ma_t12]\ntransport = \"usb\"\nproduct_id = 0x7fff\n\n\
         [devices.sra]\ntransport = \"serial\"\nport = \"/dev/brdfd-test-no-such-port\"\n",
    );
    let d = doctor(&cfg, None);
    assert!(!d.success);
    assert_eq!(d.status("daemon"), "fail");
    d.assert_fix("daemon", "brdfd serve");
    assert_eq!(d.status("MA-T12 (USB)"), "fail");
    // No X-Rite device with this (unused) product id is attached to a test machine.
    d.assert_detail("MA-T12 (USB)", "7fff");
    d.assert_fix("MA-T12 (USB)", "lsusb -d 0765:");
    assert_eq!(d.status("SRA (serial)"), "fail");
    d.assert_detail(
        "SRA (serial)",
        "/dev/brdfd-test-no-such-port ([devices.sra] port) is not there",
    );
    assert!(d.fix("SRA (serial)").contains("/dev/serial/by-id/"));
    assert_eq!(d.status("store"), "ok");
}

#[test]
fn a_serial_port_in_a_group_the_user_is_not_in_fails_naming_the_group() {
    // A node owned by root:root, mode 0660, stands for /dev/ttyUSB0 (root:dialout 0660).
    let tmp = open_dir();
    let port = tmp.path().join("ttyFAKE0");
    std::fs::write(&port, "").unwrap();
    std::fs::set_permissions(&port, std::fs::Permissions::from_mode(0o660)).unwrap();
    let cfg = config(
        tmp.path(),
        &tmp.path().join("brdfd.db"),
        &free_port(),
        &format!(
            "[devices.ma_t12]\ntransport = \"simulated\"\n\n[devices.sra]\ntransport = \"serial\"\nport = \"{}\"\n",
            port.display()
        ),
    );
    if !is_root() {
        // Only root can give a file to a group the user is not in; as a normal user the
        // port is the user's own group's and passes.
        let d = doctor(&cfg, None);
        assert_eq!(d.status("SRA (serial)"), "ok", "{}", d.json);
        return;
    }
    let d = doctor(&cfg, Some(NOBODY));
    assert!(!d.success);
    assert_eq!(d.status("SRA (serial)"), "fail", "{}", d.json);
    d.assert_detail("SRA (serial)", "belongs to group root");
    d.assert_detail("SRA (serial)", "is not in it");
    d.assert_fix("SRA (serial)", "usermod -aG root");
    // The owner's group is fine.
    let d = doctor(&cfg, None);
    assert_eq!(d.status("SRA (serial)"), "ok", "{}", d.json);
}

#[test]
fn a_lock_held_by_a_live_process_without_a_daemon_fails() {
    let tmp = open_dir();
    let db = tmp.path().join("brdfd.db");
    let cfg = config(tmp.path(), &db, &free_port(), SIMULATED);
    // This test process holds the store, as `brdfd replay --db` would.
    let lock = brdfd::store::StoreLock::acquire(&db, "brdfd replay").unwrap();
    let d = doctor(&cfg, None);
    let pid = std::process::id();
    assert!(!d.success);
    assert_eq!(d.status("store lock"), "fail", "{}", d.json);
    assert!(
        d.detail("store lock").contains(&format!(
            "held by pid {pid} (pid {pid} — brdfd replay), which is running"
        )),
        "{}",
        d.json
    );
    d.assert_fix("store lock", &format!("kill {pid}"));
    drop(lock);
    // Released: the file still names this process, which no longer holds it.
    let d = doctor(&cfg, None);
    assert_eq!(d.status("store lock"), "ok", "{}", d.json);
    assert!(d.detail("store lock").contains(&format!("names pid {pid}")));
}

/// The pid of a process that has ended (spawned, waited for).
fn dead_pid() -> u32 {
    let mut child = Command::new("true").spawn().unwrap();
    let pid = child.id();
    child.wait().unwrap();
    pid
}

#[test]
fn a_lock_naming_a_process_that_has_ended() {
    let tmp = open_dir();
    let db = tmp.path().join("brdfd.db");
    let cfg = config(tmp.path(), &db, &free_port(), SIMULATED);
    let lock_file = brdfd::store::lock::lock_path(&db);
    let dead = dead_pid();

    // A crashed daemon's lock file: it names the dead pid, and nobody holds the lock. That is
    // harmless (flock ends with its holder), and said so.
    std::fs::write(
        &lock_file,
        format!("pid {dead} — brdfd serve on http://127.0.0.1:7878\n"),
    )
    .unwrap();
    let d = doctor(&cfg, None);
    assert_eq!(d.status("store lock"), "ok", "{}", d.json);
    d.assert_detail(
        "store lock",
        &format!("names pid {dead}, which no longer holds it"),
    );

    // Held, but by a process other than the one named (one that inherited the descriptor of a
    // dead daemon): a failure, with how to find the real holder.
    let lock = brdfd::store::StoreLock::acquire(&db, "brdfd serve").unwrap();
    std::fs::write(
        &lock_file,
        format!("pid {dead} — brdfd serve on http://127.0.0.1:7878\n"),
    )
    .unwrap();
    let d = doctor(&cfg, None);
    drop(lock);
    assert!(!d.success);
    assert_eq!(d.status("store lock"), "fail", "{}", d.json);
    d.assert_detail("store lock", "has ended");
    assert!(
        d.fix("store lock")
            .contains(&format!("fuser -v {}", lock_file.display())),
        "{}",
        d.json
    );
}
