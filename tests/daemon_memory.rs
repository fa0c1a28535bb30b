//! `brdfd serve` idle: under 16 MiB of its own memory. The daemon is started as a child process
//! on its defaults (simulated instruments, a store in a temporary directory, a free loopback
//! port); once it has printed where it listens and settled for half a second, `RssAnon` (heap,
//! stacks: what the daemon allocated) and `VmRSS` are read from `/proc/PID/status` (Linux).
//! Both are printed (`--nocapture`); only `RssAnon` is checked, because `VmRSS` also counts the
//! pages of the binary the kernel happens to have mapped in, which move with the kernel's
//! fault-around and the page cache (a debug binary is 200 MB: 22 to 32 MiB seen on one machine).

#![cfg(target_os = "linux")]

mod common;

use std::process::{Command, Stdio};
use std::time::Duration;

use common::*;

/// A `/proc/PID/status` field of process `pid` (`VmRSS`, `RssAnon`), KiB.
fn status_kib(pid: u32, field: &str) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    status
        .lines()
        .find_map(|l| l.strip_prefix(field)?.strip_prefix(':'))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or_else(|| panic!("{field} in /proc/PID/status"))
}

#[test]
fn serve_idles_with_under_16_mib_of_its_own_memory() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_brdfd"))
        .args(["serve", "--listen", "127.0.0.1:0", "--db"])
        .arg(dir.path().join("brdfd.db"))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let line = serve::first_line(&mut child);
    std::thread::sleep(Duration::from_millis(500));
    let rss = status_kib(child.id(), "VmRSS");
    let anon = status_kib(child.id(), "RssAnon");
    let _ = child.kill();
    let _ = child.wait();
    assert!(line.unwrap().contains("listening on http://127.0.0.1:"));
    println!(
        "brdfd serve idle: RssAnon {anon} KiB ({:.1} MiB), VmRSS {rss} KiB ({:.1} MiB)",
        anon as f64 / 1024.0,
        rss as f64 / 1024.0
    );
    assert!(anon < 16 * 1024, "RssAnon {anon} KiB is over 16 MiB");
}
