//! A `brdfd serve` child process on loopback for the end-to-end tests that need the real
//! binary (signals, a second daemon, raw HTTP, the watch folder): a configuration with
//! simulated instruments, the spawn that reads the address the daemon prints, and polling.

use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use brdfd::client::Client;

use super::{STEP_TIMEOUT, client_of_serve};

/// A running `brdfd serve`, killed when dropped, and what the tests need of it.
pub struct ServeChild {
    pub child: Child,
    /// The address the daemon printed.
    pub addr: SocketAddr,
    /// A client with the daemon's token.
    pub client: Client,
    /// The token the daemon wrote to `brdfd.token`.
    pub token: String,
    /// The configuration's directory (the store, the token).
    pub dir: PathBuf,
}

impl Drop for ServeChild {
    fn drop(&mut self) {
        // A test that failed half-way must not leave a daemon behind.
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Writes `dir/brdfd.toml`: the store `dir/brdfd.db`, the API on a free loopback port with
/// `api_extra` lines appended to `[api]`, warnings only in the log, the whole `sections` text
/// (e.g. `[fit]` or `[ingest]`, each ending in a blank line), and both instruments simulated.
pub fn write_simulated_config(dir: &Path, api_extra: &str, sections: &str) -> PathBuf {
    let path = dir.join("brdfd.toml");
    // No cross-validation (12 more fits per fit, minutes per scan in a debug build) unless a
    // test sets `crossval` itself.
    let sections = if sections.contains("crossval") {
        sections.to_string()
    } else if sections.contains("[fit]\n") {
        sections.replacen("[fit]\n", "[fit]\ncrossval = false\n", 1)
    } else {
        format!("[fit]\ncrossval = false\n\n{sections}")
    };
    let text = format!(
        "[store]\npath = \"{}\"\n\n[api]\nlisten = \"127.0.0.1:0\"\n{api_extra}\n\n[log]\nlevel = \"warn\"\n\n\
         {sections}[devices.ma_t12]\ntransport = \"simulated\"\n\n[devices.sra]\ntransport = \"simulated\"\n",
        dir.join("brdfd.db").display()
    );
    std::fs::write(&path, text).unwrap();
    path
}

/// Starts `brdfd serve --config CONFIG EXTRA_ARGS…` (without the environment's BRDFD_TOKEN and
/// BRDFD_CONFIG) and waits for the line that says where it listens.
pub fn spawn_serve(config: &Path, extra_args: &[&str]) -> ServeChild {
    let mut child = Command::new(env!("CARGO_BIN_EXE_brdfd"))
        .args(["serve", "--config"])
        .arg(config)
        .args(extra_args)
        .env_remove("BRDFD_TOKEN")
        .env_remove("BRDFD_CONFIG")
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("brdfd serve starts");
    let line = first_line(&mut child).expect("the daemon prints where it listens");
    let addr: SocketAddr = line
        .split("http://")
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|a| a.parse().ok())
        .unwrap_or_else(|| panic!("no address in {line:?}"));
    let dir = config.parent().unwrap().to_path_buf();
    let token = std::fs::read_to_string(dir.join("brdfd.token"))
        .unwrap()
        .trim()
        .to_string();
    ServeChild {
        child,
        addr,
        client: client_of_serve(addr, &dir),
        token,
        dir,
    }
}

/// The first line `child` prints on its piped stdout (read on a thread of its own), or the
/// timeout after [`STEP_TIMEOUT`].
pub fn first_line(child: &mut Child) -> Result<String, mpsc::RecvTimeoutError> {
    let stdout = child.stdout.take().expect("a piped stdout");
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let mut line = String::new();
        let _ = BufReader::new(stdout).read_line(&mut line);
        let _ = tx.send(line);
    });
    rx.recv_timeout(STEP_TIMEOUT)
}

/// Polls until `done`, failing after [`STEP_TIMEOUT`].
pub fn wait_until(what: &str, mut done: impl FnMut() -> bool) {
    let deadline = Instant::now() + STEP_TIMEOUT;
    while !done() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        // A polling interval, not a synchronisation: the state is checked again after it.
        std::thread::sleep(Duration::from_millis(10));
    }
}
