//! `brdfd serve` idle: resident memory under 30 MiB. The daemon is started as a child process
//! on its defaults (simulated instruments, a store in a temporary directory, a free loopback
//! port); once it has printed where it listens and settled for half a second, `VmRSS` is read
//! from `/proc/PID/status` (Linux). The figure is printed (`--nocapture`).

#![cfg(target_os = "linux")]

mod common;

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use common::*;

/// Resident set size of process `pid`, KiB.
fn vm_rss_kib(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("VmRSS in /proc/PID/status")
}

#[test]
fn serve_idles_under_30_mib_resident() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_brdfd"))
        .args(["serve", "--listen", "127.0.0.1:0", "--db"])
        .arg(dir.path().join("brdfd.db"))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let mut line = String::new();
        let _ = BufReader::new(stdout).read_line(&mut line);
        let _ = tx.send(line);
    });
    let line = rx.recv_timeout(STEP_TIMEOUT);
    std::thread::sleep(Duration::from_millis(500));
    let rss = vm_rss_kib(child.id());
    let _ = child.kill();
    let _ = child.wait();
    assert!(line.unwrap().contains("listening on http://127.0.0.1:"));
    println!(
        "brdfd serve idle: VmRSS {rss} KiB ({:.1} MiB)",
        rss as f64 / 1024.0
    );
    assert!(rss < 30 * 1024, "VmRSS {rss} KiB is over 30 MiB");
}
