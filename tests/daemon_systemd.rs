//! `brdfd serve` under systemd's notify protocol, without systemd: the test binds the
//! notification socket itself (a Unix datagram socket, as systemd does), starts the daemon with
//! NOTIFY_SOCKET and WATCHDOG_USEC set, and reads what it sends: READY=1 once the API answers,
//! then WATCHDOG=1 pings at half the watchdog period, and STOPPING=1 on SIGTERM.

mod common;

use std::io::{BufRead, BufReader};
use std::os::unix::net::UnixDatagram;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::*;

fn messages_until(socket: &UnixDatagram, want: &str, within: Duration) -> Vec<String> {
    let deadline = Instant::now() + within;
    let mut seen = Vec::new();
    let mut buf = [0u8; 4096];
    while !seen.iter().any(|m: &String| m.lines().any(|l| l == want)) {
        assert!(
            Instant::now() < deadline,
            "no {want} within {within:?}; got {seen:?}"
        );
        if let Ok(n) = socket.recv(&mut buf) {
            seen.push(String::from_utf8_lossy(&buf[..n]).into_owned());
        }
    }
    seen
}

#[test]
fn serve_says_ready_pets_the_watchdog_and_says_stopping() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let socket_path = dir.path().join("notify.sock");
    let socket = UnixDatagram::bind(&socket_path).unwrap();
    socket
        .set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_brdfd"))
        .args(["serve", "--listen", "127.0.0.1:0", "--db"])
        .arg(dir.path().join("brdfd.db"))
        .env("NOTIFY_SOCKET", &socket_path)
        .env("WATCHDOG_USEC", "400000")
        .env_remove("WATCHDOG_PID")
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert!(line.contains("listening on http://127.0.0.1:"), "{line}");
    let first = messages_until(&socket, "READY=1", STEP_TIMEOUT);
    assert!(
        first
            .iter()
            .any(|m| m.contains("STATUS=listening on http://127.0.0.1:")),
        "{first:?}"
    );
    // At least two pings: the daemon keeps petting, not just once.
    messages_until(&socket, "WATCHDOG=1", STEP_TIMEOUT);
    messages_until(&socket, "WATCHDOG=1", STEP_TIMEOUT);
    // SAFETY: signalling our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    messages_until(&socket, "STOPPING=1", STEP_TIMEOUT);
    let status = child.wait().unwrap();
    assert!(status.success(), "{status:?}");
}
