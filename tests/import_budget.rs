//! The import budget through every door: attack files made from a committed real export (and
//! a CGATS export of a committed scan file), each refused with a message naming the limit and
//! the part of the file, within the memory the budget promises (peak resident memory at most
//! 256 MiB above a genuine import's).
//!
//! - The CLI: each read by the `brdfd` binary (`import-format`) under an address-space limit.
//! - The daemon: one `brdfd serve` takes each through the watch folder (its reason in
//!   `failed/`) and `POST /scans/import` (the refusal's message), and after each it still
//!   serves `status`, stores nothing, and its own peak resident memory stays within the budget
//!   above its idle one.

use std::io::{Cursor, Read, Write};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod common;

use common::{STEP_TIMEOUT, spawn_serve, write_simulated_config};

const REAL: &str = "tests/data/real-mat12/PAR_EW_RL_NG_3.xlsx";
const SPECTRAL: &str = "xl/worksheets/sheet3.xml";

fn unzip(bytes: &[u8]) -> Vec<(String, Vec<u8>)> {
    let mut z = zip::ZipArchive::new(Cursor::new(bytes)).unwrap();
    (0..z.len())
        .map(|i| {
            let mut f = z.by_index(i).unwrap();
            let mut b = Vec::new();
            f.read_to_end(&mut b).unwrap();
            (f.name().unwrap().into_owned(), b)
        })
        .collect()
}

fn rezip(parts: &[(String, Vec<u8>)]) -> Vec<u8> {
    let mut w = zip::ZipWriter::new(Cursor::new(Vec::new()));
    let opts = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    for (name, b) in parts {
        w.start_file(name.as_str(), opts).unwrap();
        w.write_all(b).unwrap();
    }
    w.finish().unwrap().into_inner()
}

/// The real export with `edit` applied to the text of `part`.
fn edited(part: &str, edit: impl FnOnce(String) -> String) -> Vec<u8> {
    let real = std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join(REAL)).unwrap();
    let mut parts = unzip(&real);
    let p = parts.iter_mut().find(|(n, _)| n == part).unwrap();
    let text = String::from_utf8(std::mem::take(&mut p.1)).unwrap();
    let new = edit(text.clone());
    assert_ne!(new, text);
    p.1 = new.into_bytes();
    rezip(&parts)
}

/// Runs `brdfd import-format FILE` under a 2 GiB address-space limit: (exit code, stderr,
/// peak resident memory in KiB).
fn import_format(file: &Path, out: &Path) -> (Option<i32>, String, i64) {
    // The limit is set by a shell that then execs brdfd. The child's peak (from wait4) counts
    // this process's resident memory when it was spawned: see the callers.
    let mut cmd = Command::new("sh");
    cmd.args(["-c", "ulimit -v 2097152 && exec \"$0\" \"$@\""])
        .arg(env!("CARGO_BIN_EXE_brdfd"))
        .args(["import-format", file.to_str().unwrap(), "--out"])
        .arg(out)
        .env_remove("BRDFD_CONFIG");
    let mut child = cmd
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut text = Vec::new();
        stderr.read_to_end(&mut text).unwrap();
        String::from_utf8_lossy(&text).into_owned()
    });
    // wait4 gives this child's own peak (RUSAGE_CHILDREN would be the largest of every child
    // the tests have waited for).
    let mut status = 0;
    // SAFETY: zeroed is a valid rusage.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: our own child's pid and valid pointers; std never waits for it after this.
    let pid = unsafe { libc::wait4(child.id() as i32, &mut status, 0, &mut usage) };
    assert_eq!(
        pid,
        child.id() as i32,
        "{}",
        std::io::Error::last_os_error()
    );
    let err = reader.join().unwrap();
    assert!(
        !libc::WIFSIGNALED(status),
        "{}: killed by signal {} (an allocation beyond the limit aborts)\n{err}",
        file.display(),
        libc::WTERMSIG(status)
    );
    let code = libc::WIFEXITED(status).then(|| libc::WEXITSTATUS(status));
    (code, err, usage.ru_maxrss)
}

/// One attack file: its name (the extension says its format), its bytes, what every refusal
/// of it must say, what the CLI's must say too, and whether `POST /scans/import` takes its
/// format (a brdfd scan file or an `.xlsx`; the watch folder and the CLI take every format).
struct Attack {
    name: &'static str,
    bytes: Vec<u8>,
    want: &'static [&'static str],
    cli_want: &'static [&'static str],
    http: bool,
}

/// The relationships namespace of the drawing's `r:embed`.
const REL_NS: &str = "http://schemas.openxmlformats.org/officeDocument/2006/relationships";

/// The drawing of the real export's `Texture Images` sheet.
const DRAWING: &str = "xl/drawings/drawing1.xml";

/// The drawing's first anchor element.
fn first_anchor(x: &str) -> &str {
    let s = x
        .find("<xdr:twoCellAnchor")
        .or_else(|| x.find("<xdr:oneCellAnchor"))
        .unwrap();
    let close = if x[s..].starts_with("<xdr:two") {
        "</xdr:twoCellAnchor>"
    } else {
        "</xdr:oneCellAnchor>"
    };
    &x[s..s + x[s..].find(close).unwrap() + close.len()]
}

/// The attack files that fit in a test (each a few MB at most), each aimed at a limit of the
/// import budget or at a reader's value checks.
fn attacks() -> Vec<Attack> {
    // One cell at the far end of a sheet: a dense grid of 2^34 cells.
    let far = edited(SPECTRAL, |x| {
        x.replace(
            "</sheetData>",
            r#"<row r="1048576"><c r="XFD1048576"><v>1</v></c></row></sheetData>"#,
        )
    });
    // One cell a million rows down in column Z.
    let deep = edited("xl/worksheets/sheet1.xml", |x| {
        x.replace(
            "</sheetData>",
            r#"<row r="1000000"><c r="Z1000000"><v>1</v></c></row></sheetData>"#,
        )
    });
    let long_name = edited("xl/sharedStrings.xml", |x| {
        x.replace(
            "<t>PAR_EW_RL_NG_3</t>",
            &format!("<t>{}</t>", "N".repeat(6 << 20)),
        )
    });
    let huge = edited(SPECTRAL, |x| {
        let at = x.find("<c r=\"D7\"").unwrap();
        let v = at + x[at..].find("<v>").unwrap() + 3;
        let e = v + x[v..].find("</v>").unwrap();
        format!("{}1e308{}", &x[..v], &x[e..])
    });
    let control = edited("xl/sharedStrings.xml", |x| {
        x.replace("<t>PAR_EW_RL_NG_3</t>", "<t>PAR\tNG_3</t>")
    });
    // 6,000 anchors in the sheet's last row, each as short as the drawing's markup allows (the
    // drawing stays under the markup allowance).
    let anchors = edited(DRAWING, |x| {
        let short = r#"<xdr:oneCellAnchor><xdr:from><xdr:col>1</xdr:col><xdr:row>1048575</xdr:row></xdr:from><xdr:pic><a:blip r:embed="rId1"/></xdr:pic></xdr:oneCellAnchor>"#;
        x.replacen(
            "<xdr:wsDr ",
            &format!(r#"<xdr:wsDr xmlns:r="{REL_NS}" "#),
            1,
        )
        .replacen(
            "</xdr:wsDr>",
            &format!("{}</xdr:wsDr>", short.repeat(6_000)),
            1,
        )
    });
    // 24 anchors on one 63 MiB image part (a PNG head, then zeros: a few kB deflated).
    let big_png = {
        let real = std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join(REAL)).unwrap();
        let mut parts = unzip(&real);
        let (_, png) = parts
            .iter_mut()
            .find(|(n, _)| n == "xl/media/image1.png")
            .unwrap();
        png.resize(63 << 20, 0);
        let d = parts.iter_mut().find(|(n, _)| n == DRAWING).unwrap();
        let x = String::from_utf8(std::mem::take(&mut d.1)).unwrap();
        let a = first_anchor(&x).to_string();
        d.1 = x.replacen(&a, &a.repeat(24), 1).into_bytes();
        rezip(&parts)
    };
    // A CGATS export of a committed scan, its data lines repeated to 31 MiB.
    let cgats = {
        let scan = brdfd::scan::Scan::read_file(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/t-sky-blue.scan.json"),
        )
        .unwrap();
        let tile = scan.reference.as_ref().unwrap();
        let text = brdfd::formats::cgats::instrument_export(&[
            (tile.name.as_str(), &tile.readings),
            (scan.sample.as_str(), &scan.readings),
        ]);
        let begin = text.find("BEGIN_DATA\n").unwrap() + "BEGIN_DATA\n".len();
        let end = begin + text[begin..].find("END_DATA").unwrap();
        let rows = &text[begin..end];
        let copies = (31 << 20) / rows.len();
        format!("{}{}{}", &text[..begin], rows.repeat(copies), &text[end..]).into_bytes()
    };
    vec![
        Attack {
            name: "far.xlsx",
            bytes: far,
            want: &[
                "far.xlsx: sheet \"Spectral Data\"",
                "to cell XFD1048576",
                "\"sheet cells\"",
                "ingest.max_sheet_cells",
            ],
            cli_want: &[],
            http: true,
        },
        Attack {
            name: "deep.xlsx",
            bytes: deep,
            want: &[
                "deep.xlsx: sheet \"Color Data\"",
                "to cell Z1000000",
                "\"sheet cells\"",
            ],
            cli_want: &[],
            http: true,
        },
        Attack {
            name: "long.xlsx",
            bytes: long_name,
            want: &[
                "long.xlsx: part \"xl/sharedStrings.xml\"",
                "beyond the import limit",
            ],
            cli_want: &[],
            http: true,
        },
        Attack {
            name: "huge.xlsx",
            bytes: huge,
            want: &["sheet \"Spectral Data\", cell D7: 1e308 is beyond any reflectance factor"],
            cli_want: &[],
            http: true,
        },
        Attack {
            name: "control.xlsx",
            bytes: control,
            want: &["control character U+0009"],
            cli_want: &["control.xlsx: the sample name"],
            http: true,
        },
        Attack {
            name: "anchors.xlsx",
            bytes: anchors,
            want: &[
                "anchors.xlsx: sheet \"Texture Images\" (6007 image anchors)",
                "\"images per file\"",
                "ingest.max_images",
            ],
            cli_want: &[],
            http: true,
        },
        Attack {
            name: "png.xlsx",
            bytes: big_png,
            want: &[
                "png.xlsx: part \"xl/media/image1.png\": 66060288 bytes",
                "\"archive part size\"",
            ],
            cli_want: &[],
            http: true,
        },
        Attack {
            name: "many.txt",
            bytes: cgats,
            want: &[
                "many.txt: the whole file",
                "\"records per file\"",
                "ingest.max_records",
            ],
            cli_want: &[],
            http: false,
        },
    ]
}

/// Fails naming `door` and `name` unless `message` holds each of `want`.
fn says(door: &str, name: &str, message: &str, want: &[&str]) {
    for w in want {
        assert!(
            message.contains(w),
            "{name} through {door}: {message:?} lacks {w:?}"
        );
    }
}

/// Fails unless the refusal of `name` through `door`, begun at `start`, came within the
/// budget's 20 s; prints how long it took.
fn in_time(door: &str, name: &str, start: Instant) {
    let took = start.elapsed();
    println!("{name} through {door}: refused in {took:.2?}");
    assert!(
        took < Duration::from_secs(20),
        "{name} through {door}: {took:?}"
    );
}

/// Fails unless `peak` (KiB of resident memory) is under 256 MiB above `base` (the
/// `base_is` memory); prints both.
fn within_budget(door: &str, name: &str, peak: i64, base: i64, base_is: &str) {
    println!(
        "{name} through {door}: peak {} MiB, {} MiB {base_is}",
        peak >> 10,
        base >> 10
    );
    assert!(
        peak - base < 256 << 10,
        "{name} through {door}: peak {peak} KiB against {base} KiB {base_is}"
    );
}

/// Set in the fresh process [`attack_files_are_refused_by_the_cli_within_the_budget`] runs
/// its measurements in.
const FRESH_PROCESS: &str = "BRDFD_IMPORT_BUDGET_FRESH_PROCESS";

#[test]
fn attack_files_are_refused_by_the_cli_within_the_budget() {
    // A child's peak resident memory counts this process's resident memory at the time it was
    // spawned, and whatever the other tests of this binary left resident (buffers the
    // allocator keeps, a client's pool) would count in every child. So the measurements run
    // in a fresh process of this test binary running this test alone; in it the attack files
    // are written (and their bytes freed) first, then its peak is reset.
    let _serial = common::serial();
    if std::env::var_os(FRESH_PROCESS).is_none() {
        let name = "attack_files_are_refused_by_the_cli_within_the_budget";
        let o = Command::new(std::env::current_exe().unwrap())
            .args([name, "--exact", "--nocapture", "--test-threads=1"])
            .env(FRESH_PROCESS, "1")
            .output()
            .unwrap();
        let out = String::from_utf8_lossy(&o.stdout);
        print!("{out}");
        eprint!("{}", String::from_utf8_lossy(&o.stderr));
        assert!(o.status.success(), "the fresh process failed: {}", o.status);
        assert!(out.contains("1 passed"), "the fresh process ran no test");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let mut cases = Vec::new();
    for a in attacks() {
        assert!(
            a.bytes.len() < 32 << 20,
            "{}: {} bytes",
            a.name,
            a.bytes.len()
        );
        let p = dir.path().join(a.name);
        std::fs::write(&p, &a.bytes).unwrap();
        cases.push((a.name, a.want, a.cli_want, p));
    }
    // The freed memory back to the system (malloc keeps it otherwise), then the peak reset.
    // SAFETY: malloc_trim only releases free memory of the allocator.
    unsafe { libc::malloc_trim(0) };
    std::fs::write("/proc/self/clear_refs", "5").unwrap();
    let own = memory_kib(std::process::id(), "VmHWM");

    // A genuine export: the baseline.
    let real = Path::new(env!("CARGO_MANIFEST_DIR")).join(REAL);
    let (code, err, baseline) = import_format(&real, &out);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        own < baseline,
        "this test's own peak ({own} KiB) is above a genuine import's ({baseline} KiB): the \
         children's peaks would be this process's"
    );

    for (name, want, cli_want, p) in cases {
        let started = Instant::now();
        let (code, err, peak) = import_format(&p, &out);
        in_time("the CLI", name, started);
        assert_eq!(code, Some(1), "{name}: {err}");
        says("the CLI", name, &err, want);
        says("the CLI", name, &err, cli_want);
        within_budget("the CLI", name, peak, baseline, "a genuine export's");
    }

    // `brdfd import` reads a scan file within the same file size, refusing a larger one
    // unread, before it looks for a daemon.
    let big = dir.path().join("big.scan.json");
    std::fs::File::create(&big)
        .unwrap()
        .set_len(40 << 20)
        .unwrap();
    let o = common::run_brdfd(
        &["import", big.to_str().unwrap(), "--addr", "127.0.0.1:9"],
        None,
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    says(
        "brdfd import",
        "big.scan.json",
        &err,
        &[
            "big.scan.json: the whole file: 41943040 bytes is beyond the import limit \"file \
             size\"",
        ],
    );
}

/// `VmHWM` (peak resident memory) or `VmRSS` of process `pid`, in KiB.
fn memory_kib(pid: u32, key: &str) -> i64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    status
        .lines()
        .find_map(|l| l.strip_prefix(key)?.strip_prefix(':'))
        .and_then(|v| v.split_whitespace().next()?.parse().ok())
        .unwrap_or_else(|| panic!("no {key} in /proc/{pid}/status"))
}

/// Polls `done` every 20 ms, failing with `what` after [`STEP_TIMEOUT`].
fn wait_for(what: &str, mut done: impl FnMut() -> bool) {
    let deadline = Instant::now() + STEP_TIMEOUT;
    while !done() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn attack_files_are_refused_by_the_watch_folder_and_http_and_the_daemon_stays_up() {
    let _serial = common::serial();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let inbox = dir.join("inbox");
    std::fs::create_dir(&inbox).unwrap();
    // A lone CGATS export waits 100 ms for its SRA CSV, then goes alone.
    write_simulated_config(
        dir,
        "",
        &format!(
            "[ingest]\nwatch = \"{}\"\nsettle_ms = 50\npoll_ms = 20\npair_wait_ms = 100\n\n",
            inbox.display()
        ),
    );
    let mut daemon = spawn_serve(&dir.join("brdfd.toml"), &[]);
    let pid = daemon.child.id();
    let client = &daemon.client;
    let scans = || {
        let v = client.get("/scans").unwrap();
        v.as_array()
            .or_else(|| v["scans"].as_array())
            .unwrap_or_else(|| panic!("no scan list in {v}"))
            .len()
    };
    assert_eq!(scans(), 0);
    let idle = memory_kib(pid, "VmRSS");
    for (i, a) in attacks().iter().enumerate() {
        // The watch folder: the file in failed/ with its reason, within the time budget
        // (settling and the pair wait of a CGATS export included).
        let dropped = Instant::now();
        std::fs::write(inbox.join(a.name), &a.bytes).unwrap();
        let reason = inbox.join("failed").join(format!("{}.error.txt", a.name));
        wait_for(&format!("{} in failed/", a.name), || reason.exists());
        in_time("the watch folder", a.name, dropped);
        let why = std::fs::read_to_string(&reason).unwrap();
        says("the watch folder", a.name, &why, a.want);
        // HTTP: refused with 400 (GUIDE.md, Security), naming the limit.
        if a.http {
            let sent = Instant::now();
            let e = client
                .post_bytes(&format!("/scans/import?file={}", a.name), &a.bytes)
                .expect_err(a.name);
            in_time("POST /scans/import", a.name, sent);
            let brdfd::client::ClientError::Refused { status, .. } = &e else {
                panic!("{}: {e}", a.name);
            };
            assert_eq!(*status, 400, "{}: {e}", a.name);
            says("POST /scans/import", a.name, &e.to_string(), a.want);
        }
        // Still up (serving `status`), every refusal counted (the count follows the move to
        // failed/), nothing stored.
        wait_for(&format!("{} counted as rejected", a.name), || {
            client.get("/status").unwrap()["ingest"]["rejected"] == i as u64 + 1
        });
        assert_eq!(scans(), 0, "{} stored a scan", a.name);
        let peak = memory_kib(pid, "VmHWM");
        within_budget("the daemon", a.name, peak, idle, "idle");
    }
    // A file whose name holds an escape sequence (one that would clear the screen): the
    // refusal names it, and `brdfd status` prints its last error with the escape shown, not
    // sent to the terminal.
    let name = "esc\u{1b}[2J.xlsx";
    std::fs::write(inbox.join(name), &attacks()[0].bytes).unwrap();
    let reason = inbox.join("failed").join(format!("{name}.error.txt"));
    wait_for("the escaped name in failed/", || reason.exists());
    wait_for("its refusal as the last error", || {
        client.get("/status").unwrap()["ingest"]["last_error"]
            .as_str()
            .is_some_and(|e| e.contains(name))
    });
    let config = dir.join("brdfd.toml");
    let addr = daemon.addr.to_string();
    let out = common::run_brdfd(
        &[
            "status",
            "--config",
            config.to_str().unwrap(),
            "--addr",
            &addr,
        ],
        None,
    );
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(out.status.success(), "{stdout}");
    assert!(
        stdout.contains("last error: esc\\u{1b}[2J.xlsx: sheet \"Spectral Data\"")
            && !stdout.contains('\u{1b}'),
        "{stdout:?}"
    );
    assert_eq!(scans(), 0);
    assert!(
        daemon.child.try_wait().unwrap().is_none(),
        "the daemon ended"
    );
}
