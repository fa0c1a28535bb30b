//! The daemon's log on stderr, as GUIDE.md "Running the daemon" describes it: text by default,
//! one JSON object per line with `[log] json = true`, the level from `[log] level` unless
//! `RUST_LOG` overrides it. (Under systemd the log goes to journald instead:
//! `src/cli/serve.rs`'s journald tests.)

mod common;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::mpsc;

use common::STEP_TIMEOUT;

/// Starts `brdfd serve` on a configuration with simulated instruments and the given `[log]`
/// section, reads its stderr until a line contains `until`, stops it with SIGTERM, and returns
/// every stderr line and the address the daemon printed on stdout.
fn log_of(dir: &Path, log: &str, rust_log: Option<&str>, until: &str) -> (Vec<String>, String) {
    let config = dir.join("brdfd.toml");
    std::fs::write(
        &config,
        format!(
            "[store]\npath = \"{}\"\n\n[api]\nlisten = \"127.0.0.1:0\"\n\n[log]\n{log}\n\n\
             [devices.ma_t12]\ntransport = \"simulated\"\n\n[devices.sra]\ntransport = \"simulated\"\n",
            dir.join("brdfd.db").display()
        ),
    )
    .unwrap();
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_brdfd"));
    cmd.args(["serve", "--config"])
        .arg(&config)
        .env_remove("BRDFD_TOKEN")
        .env_remove("BRDFD_CONFIG")
        // Not under systemd: the log goes to stderr.
        .env_remove("JOURNAL_STREAM")
        .env_remove("RUST_LOG")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    if let Some(filter) = rust_log {
        cmd.env("RUST_LOG", filter);
    }
    /// Kills the daemon if the test fails half-way.
    struct Killed(std::process::Child);
    impl Drop for Killed {
        fn drop(&mut self) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
    let mut child = Killed(cmd.spawn().expect("brdfd serve starts"));
    let stdout = child.0.stdout.take().unwrap();
    let stderr = child.0.stderr.take().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let mut line = String::new();
        let _ = BufReader::new(stdout).read_line(&mut line);
        let _ = tx.send(line);
    });
    let (line_tx, line_rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if line_tx.send(line).is_err() {
                break;
            }
        }
    });
    let printed = rx
        .recv_timeout(STEP_TIMEOUT)
        .expect("the daemon prints where it listens");
    let mut lines = Vec::new();
    loop {
        let line = line_rx
            .recv_timeout(STEP_TIMEOUT)
            .unwrap_or_else(|_| panic!("no log line with {until:?}; read: {lines:#?}"));
        let done = line.contains(until);
        lines.push(line);
        if done {
            break;
        }
    }
    // A graceful stop (SIGTERM), so the log is complete up to the daemon's exit.
    let status = Command::new("kill")
        .args(["-TERM", &child.0.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(status.success());
    let exit = child.0.wait().unwrap();
    assert!(exit.success(), "a graceful stop exits 0: {exit}");
    // The pipe closes with the process: read the rest.
    while let Ok(line) = line_rx.recv_timeout(STEP_TIMEOUT) {
        lines.push(line);
    }
    (lines, printed)
}

/// The address in the daemon's "listening on http://ADDR" line.
fn address(printed: &str) -> &str {
    printed
        .split("http://")
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .unwrap_or_else(|| panic!("no address in {printed:?}"))
}

/// The lines the daemon writes to stderr itself, before and beside the log.
fn is_banner(line: &str) -> bool {
    line.starts_with("configuration: ") || line.starts_with("*** SIMULATED INSTRUMENTS")
}

#[test]
fn json_log_lines_are_objects_with_level_message_and_fields() {
    let _serial = common::serial();
    let dir = tempfile::tempdir().unwrap();
    let (lines, printed) = log_of(
        dir.path(),
        "level = \"info\"\njson = true",
        None,
        "\"serving\"",
    );
    let mut serving = None;
    for line in lines.iter().filter(|l| !is_banner(l)) {
        let v: serde_json::Value = serde_json::from_str(line)
            .unwrap_or_else(|e| panic!("a log line that is not JSON ({e}): {line}"));
        let level = v["level"]
            .as_str()
            .unwrap_or_else(|| panic!("no level: {line}"));
        assert!(
            ["ERROR", "WARN", "INFO"].contains(&level),
            "level {level} below info: {line}"
        );
        assert!(v["fields"]["message"].is_string(), "no message: {line}");
        assert!(v["timestamp"].is_string(), "no timestamp: {line}");
        if v["fields"]["message"] == "serving" {
            serving = Some(v);
        }
    }
    let serving = serving.expect("the serving line");
    assert_eq!(serving["level"], "INFO");
    // Fields are JSON fields, not text inside the message.
    assert_eq!(serving["fields"]["addr"], address(&printed));
    assert_eq!(
        serving["fields"]["store"],
        dir.path().join("brdfd.db").display().to_string()
    );
    // The stop is logged.
    assert!(
        lines.iter().any(|l| l.contains("\"shutting down\"")),
        "{lines:#?}"
    );
    // The simulated-instruments warning is in the log too, at warn.
    assert!(
        lines
            .iter()
            .filter(|l| !is_banner(l))
            .any(|l| l.contains("\"WARN\"") && l.contains("SIMULATED INSTRUMENTS")),
        "{lines:#?}"
    );
}

#[test]
fn rust_log_overrides_the_configured_level_and_text_is_the_default() {
    let _serial = common::serial();
    let dir = tempfile::tempdir().unwrap();
    // Text: one line per event with its level and its fields as key=value.
    let (lines, printed) = log_of(dir.path(), "level = \"info\"", None, "serving");
    let serving = lines
        .iter()
        .find(|l| l.contains("serving"))
        .expect("the serving line");
    assert!(serving.contains("INFO"), "{serving}");
    assert!(
        serving.contains(&format!("addr={}", address(&printed))),
        "{serving}"
    );
    assert!(!serving.trim_start().starts_with('{'), "{serving}");

    // RUST_LOG=warn: the info lines are gone, the warning stays; the configured level says info.
    let dir = tempfile::tempdir().unwrap();
    let (lines, _) = log_of(
        dir.path(),
        "level = \"info\"\njson = true",
        Some("warn"),
        "\"WARN\"",
    );
    let logged: Vec<serde_json::Value> = lines
        .iter()
        .filter(|l| !is_banner(l))
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect();
    assert!(
        logged.iter().any(|v| v["level"] == "WARN"),
        "the warning is logged: {lines:#?}"
    );
    assert!(
        logged.iter().all(|v| v["level"] != "INFO"),
        "RUST_LOG=warn let info through: {lines:#?}"
    );
}
