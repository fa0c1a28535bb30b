//! The watch folder (`[ingest] watch`, src/service/ingest.rs) against a live `brdfd serve`
//! child on loopback: simulated instruments, a real SQLite store and folder in a temporary
//! directory, every request with the token. Each test ends by checking that the store and the
//! folders agree: every file dropped is in `done/` (its scans stored once, with their
//! provenance) or in `failed/` beside its `.error.txt` (nothing stored), and nothing is left in
//! the folder or in `.importing/`.

// `serial()` is held across each whole test on purpose.
#![allow(clippy::await_holding_lock)]

mod common;

use std::collections::BTreeSet;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use brdfd::client::Client;
use brdfd::scan::{DeviceReadings, Scan};
use serde_json::Value;

use common::*;

/// The tests stop the daemon in two ways and read its watch-folder status.
impl ServeChild {
    /// SIGTERM, and the exit status must be success.
    fn stop(mut self) {
        // SAFETY: kill(2) on our own child's pid.
        unsafe { libc::kill(self.child.id() as i32, libc::SIGTERM) };
        let status = self.child.wait().unwrap();
        assert!(status.success(), "brdfd serve ended with {status}");
    }

    /// SIGKILL: no chance to finish anything.
    fn kill(mut self) {
        self.child.kill().unwrap();
        self.child.wait().unwrap();
    }

    fn ingest(&self) -> Value {
        self.client.get("/status").unwrap()["ingest"].clone()
    }
}

/// The test's directory: `brdfd.toml`, the store and the watch folder `inbox/`.
struct Lab {
    _tmp: tempfile::TempDir,
    dir: PathBuf,
    inbox: PathBuf,
}

impl Lab {
    fn new(settle_ms: u64, pair_wait_ms: u64) -> Lab {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().to_path_buf();
        let inbox = dir.join("inbox");
        std::fs::create_dir(&inbox).unwrap();
        write_simulated_config(
            &dir,
            "",
            &format!(
                "[fit]\ncost_functions = [\"cf2\"]\nbootstrap = 0\n\n\
                 [ingest]\nwatch = \"{}\"\nsettle_ms = {settle_ms}\npoll_ms = 20\npair_wait_ms = {pair_wait_ms}\n\n",
                inbox.display()
            ),
        );
        Lab {
            _tmp: tmp,
            dir,
            inbox,
        }
    }

    fn serve(&self) -> ServeChild {
        spawn_serve(&self.dir.join("brdfd.toml"), &[])
    }

    fn sub(&self, name: &str) -> PathBuf {
        self.inbox.join(name)
    }

    /// The file names in `inbox/SUB` (`""`: the folder itself, files only).
    fn names(&self, sub: &str) -> BTreeSet<String> {
        std::fs::read_dir(self.inbox.join(sub))
            .unwrap()
            .map(|e| e.unwrap())
            .filter(|e| e.file_type().unwrap().is_file())
            .map(|e| e.file_name().into_string().unwrap())
            .collect()
    }

    /// Everything dropped has been dealt with: the folder and `.importing/` are empty.
    fn settled(&self) -> bool {
        self.names("").is_empty() && self.names(".importing").is_empty()
    }
}

/// Polls `cond` until it holds, failing after [`STEP_TIMEOUT`] with `what`.
fn wait_for(what: &str, mut cond: impl FnMut() -> bool) {
    let deadline = Instant::now() + STEP_TIMEOUT;
    while !cond() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Polls `probe` every 20 ms until it gives a value, failing with `failure` after
/// [`STEP_TIMEOUT`]: [`wait_for`] for the in-process tests.
async fn poll_until<T>(failure: &str, mut probe: impl AsyncFnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + STEP_TIMEOUT;
    loop {
        if let Some(v) = probe().await {
            return v;
        }
        assert!(Instant::now() < deadline, "{failure}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// A temporary directory for an in-process test, with the path of its store (`brdfd.db`) and
/// its watch folder (`inbox/`, made).
fn store_and_inbox() -> (tempfile::TempDir, PathBuf, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let db = tmp.path().join("brdfd.db");
    let inbox = tmp.path().join("inbox");
    std::fs::create_dir(&inbox).unwrap();
    (tmp, db, inbox)
}

fn example(name: &str) -> Scan {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(format!("{name}.scan.json"));
    Scan::read_file(path).unwrap()
}

/// The objects an MA-T12 session export names: the reference tile, then the sample.
fn session_objects(scan: &Scan) -> [(&str, &DeviceReadings); 2] {
    let tile = scan.reference.as_ref().unwrap();
    [
        (tile.name.as_str(), &tile.readings),
        (scan.sample.as_str(), &scan.readings),
    ]
}

/// The session as CGATS, 12 rows per object (the shape `src/formats/cgats.rs` reads by object
/// name).
fn cgats_export(scan: &Scan) -> String {
    brdfd::formats::cgats::instrument_export(&session_objects(scan))
}

/// The same as X-Rite CxF3 (the shape `src/formats/cxf3.rs` reads by object name: the grid
/// in the specification, bands beyond 400–700 nm).
fn cxf3_export(scan: &Scan) -> String {
    brdfd::formats::cxf3::instrument_export(&session_objects(scan))
}

fn sra_csv(scan: &Scan) -> String {
    brdfd::formats::sra::write_scans(std::slice::from_ref(scan))
}

/// Every scan in the store, newest first (the daemon's listing).
fn scans(client: &Client) -> Vec<Value> {
    let v = client.get("/scans?limit=500").unwrap();
    v.as_array()
        .or_else(|| v["scans"].as_array())
        .unwrap_or_else(|| panic!("no scan list in {v}"))
        .clone()
}

/// The rows of `ingested_files` (hash, file name), from the stopped daemon's store.
fn ingested(lab: &Lab) -> Vec<(String, String)> {
    block_on(async {
        let store = brdfd::store::Store::open(lab.dir.join("brdfd.db"))
            .await
            .unwrap();
        let files = store.ingested_files().await.unwrap();
        // Each file's scans are in the store, complete, with the file in their provenance.
        for f in &files {
            assert!(!f.scans.is_empty());
            for &s in &f.scans {
                let d = store.scan_detail(s).await.unwrap();
                assert_eq!(d.scan.state, brdfd::store::ScanState::Complete);
                let detail = d.scan.provenance.source_detail.unwrap_or_default();
                assert!(detail.contains(&f.file_name), "{detail} / {}", f.file_name);
            }
        }
        store.close().await;
        files.into_iter().map(|f| (f.sha256, f.file_name)).collect()
    })
}

/// Writes `bytes` to `path` in `pieces` parts, flushing each.
fn write_in_pieces(path: &Path, bytes: &[u8], pieces: usize, between: impl Fn(usize)) {
    let mut f = std::fs::File::create(path).unwrap();
    let size = bytes.len().div_ceil(pieces);
    for (i, chunk) in bytes.chunks(size).enumerate() {
        f.write_all(chunk).unwrap();
        f.flush().unwrap();
        between(i);
    }
}

/// A service on `store` with the simulated instruments (strict, accelerated), fitting cf2
/// only and without bootstrap, watching `inbox` (settling 50 ms, polling every 20 ms).
async fn watching_service(store: &brdfd::store::Store, inbox: &Path) -> brdfd::service::Service {
    let settings = brdfd::service::ServiceSettings {
        cost_functions: vec![brdfd::cost::CostFunction::Cf2],
        bootstrap: 0,
        crossval: false,
        ingest: Some(brdfd::service::IngestSettings {
            dir: inbox.to_path_buf(),
            settle: Duration::from_millis(50),
            poll: Duration::from_millis(20),
            pair_wait: Duration::from_secs(600),
            reference: "Munsell N9".into(),
            budget: brdfd::formats::budget::Budget::default(),
        }),
        ..settings()
    };
    brdfd::service::Service::start(
        store.clone(),
        simulated(&strict_fast()),
        settings,
        brdfd::service::ServiceOptions::default(),
    )
    .await
    .unwrap()
}

#[test]
fn files_written_slowly_in_pieces_are_imported_whole_and_fitted() {
    let _serial = serial();
    // A settle time long enough that a pause between two pieces never reaches it.
    let lab = Lab::new(3000, 600_000);
    let daemon = lab.serve();
    let mut events = daemon.client.events().unwrap();
    let scan = example("t-sky-blue");
    let export = cgats_export(&scan);
    let csv = sra_csv(&scan);

    // The export in ten pieces; after the first, wait until the daemon has seen the partial
    // file (it counts as waiting), so the pieces really arrive under its eyes.
    write_in_pieces(&lab.sub("session 1.cgats"), export.as_bytes(), 10, |i| {
        if i == 0 {
            wait_for("the daemon to see the partial export", || {
                daemon.ingest()["waiting"].as_u64() == Some(1)
            });
        }
        std::thread::sleep(Duration::from_millis(30));
    });
    // The export is complete but its SRA CSV is not there: it waits for it (pair_wait is
    // long), however long it has settled.
    write_in_pieces(&lab.sub("session 1.sra.csv"), csv.as_bytes(), 3, |_| {
        std::thread::sleep(Duration::from_millis(30))
    });
    wait_for("both files in done/", || {
        lab.names("done") == BTreeSet::from(["session 1.cgats".into(), "session 1.sra.csv".into()])
    });
    assert!(lab.settled());
    assert!(lab.names("failed").is_empty(), "{:?}", lab.names("failed"));

    // One scan, the export's readings bit for bit, its provenance naming both files.
    let list = scans(&daemon.client);
    assert_eq!(list.len(), 1, "{list:?}");
    let id = list[0]["id"].as_i64().unwrap();
    let shown = daemon.client.get(&format!("/scans/{id}")).unwrap();
    assert_eq!(shown["scan"]["sample"], scan.sample.as_str());
    assert_eq!(shown["scan"]["provenance"]["source"], "imported");
    assert_eq!(
        shown["scan"]["provenance"]["source_detail"],
        "CGATS export session 1.cgats; originator MA-T12 software; SRA readings from \
         session 1.sra.csv"
    );
    let exported = Scan::from_json(
        daemon
            .client
            .get_text(&format!("/scans/{id}/export"))
            .unwrap()
            .as_bytes(),
    )
    .unwrap();
    assert_eq!(exported.readings, scan.readings);
    assert_eq!(
        exported.reference.as_ref().unwrap().readings,
        scan.reference.as_ref().unwrap().readings
    );
    // Fitted like a measured scan: the configured cost function's fit is queued or further.
    let fits = shown["fits"].as_array().unwrap();
    assert_eq!(fits.len(), 1, "{shown}");

    // The event, and the status.
    let imported = events
        .by_ref()
        .find(|e| e["type"] == "file_imported")
        .expect("a file_imported event");
    assert_eq!(imported["file"], "session 1.cgats and session 1.sra.csv");
    assert_eq!(imported["scans"][0].as_i64(), Some(id));
    assert_eq!(imported["sha256"].as_str().unwrap().len(), 64);
    let status = daemon.ingest();
    assert_eq!(status["imported"], 1, "{status}");
    assert_eq!(status["rejected"], 0, "{status}");
    assert_eq!(status["waiting"], 0, "{status}");
    let cli = run_brdfd(
        &[
            "status",
            "--config",
            lab.dir.join("brdfd.toml").to_str().unwrap(),
            "--addr",
            &daemon.addr.to_string(),
        ],
        None,
    );
    let out = String::from_utf8_lossy(&cli.stdout);
    assert!(cli.status.success(), "{out}");
    assert!(
        out.contains("inbox: 1 imported, 0 rejected since start, 0 waiting"),
        "{out}"
    );
    daemon.stop();
    let rows = ingested(&lab);
    assert_eq!(rows.len(), 1);
    assert_eq!(rows[0].1, "session 1.cgats");
}

#[test]
fn broken_files_go_to_failed_with_the_reason_and_nothing_is_stored() {
    let _serial = serial();
    let lab = Lab::new(100, 300);
    let daemon = lab.serve();
    let mut events = daemon.client.events().unwrap();
    let scan = example("t-pebble-grey");

    // A number that is not one, on a known line of the export.
    let export = cgats_export(&scan);
    let mut lines: Vec<String> = export.lines().map(str::to_string).collect();
    let line = lines.iter().position(|l| l.starts_with("14 ")).unwrap() + 1;
    // The last value of data row 14 (SPECTRAL_NM700) becomes a word.
    let (row, _) = lines[line - 1].rsplit_once(' ').unwrap();
    lines[line - 1] = format!("{row} zero");
    let bad = lines.join("\n") + "\n";
    std::fs::write(lab.sub("bad.txt"), &bad).unwrap();
    std::fs::write(lab.sub("bad.sra.csv"), sra_csv(&scan)).unwrap();
    // A scan file cut short, an SRA CSV without its export, and a file the folder ignores.
    let json = scan.to_json_pretty().unwrap();
    std::fs::write(lab.sub("cut.scan.json"), &json[..json.len() / 2]).unwrap();
    std::fs::write(lab.sub("lonely.sra.csv"), sra_csv(&scan)).unwrap();
    std::fs::write(lab.sub("notes.md"), "not for brdfd").unwrap();

    wait_for("four files and their reasons in failed/", || {
        lab.names("failed").len() == 8
    });
    assert_eq!(
        lab.names(""),
        BTreeSet::from(["notes.md".into()]),
        "only the unknown file stays"
    );
    assert!(lab.names(".importing").is_empty());
    assert!(lab.names("done").is_empty());
    let reason = |name: &str| {
        std::fs::read_to_string(lab.sub("failed").join(format!("{name}.error.txt"))).unwrap()
    };
    let why = reason("bad.txt");
    assert!(
        why.contains(&format!("bad.txt:{line}: SPECTRAL_NM700")),
        "{why}"
    );
    assert!(why.contains("drop it into"), "{why}");
    assert_eq!(
        reason("bad.sra.csv"),
        why.replace("bad.txt was", "bad.sra.csv was")
    );
    let why = reason("cut.scan.json");
    assert!(why.contains("cut.scan.json"), "{why}");
    let why = reason("lonely.sra.csv");
    assert!(why.contains("no MA-T12 export beside it"), "{why}");

    // Nothing stored; three rejections (the pair counts once), each an event.
    assert!(scans(&daemon.client).is_empty());
    let status = daemon.ingest();
    assert_eq!(status["rejected"], 3, "{status}");
    assert_eq!(status["imported"], 0, "{status}");
    assert!(status["last_error"].as_str().is_some(), "{status}");
    let rejected: BTreeSet<String> = events
        .by_ref()
        .filter(|e| e["type"] == "file_rejected")
        .take(3)
        .map(|e| e["file"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(
        rejected,
        BTreeSet::from([
            "bad.txt and bad.sra.csv".into(),
            "cut.scan.json".into(),
            "lonely.sra.csv".into()
        ])
    );
    daemon.stop();
    assert!(ingested(&lab).is_empty());
}

#[test]
fn the_same_content_twice_is_imported_once() {
    let _serial = serial();
    let lab = Lab::new(100, 600_000);
    let daemon = lab.serve();
    let bytes = example("t-sky-blue").to_json_pretty().unwrap();
    std::fs::write(lab.sub("a.scan.json"), &bytes).unwrap();
    wait_for("a.scan.json in done/", || lab.names("done").len() == 1);
    let first = scans(&daemon.client)[0]["id"].as_i64().unwrap();
    // The same bytes again, under the same name and under another: not imported, moved to
    // done/ (not failed/) beside a note naming the first import.
    std::fs::write(lab.sub("a.scan.json"), &bytes).unwrap();
    std::fs::write(lab.sub("b.scan.json"), &bytes).unwrap();
    wait_for("both copies in done/ with their notes", || {
        lab.names("done").len() == 5
    });
    assert!(lab.settled());
    assert!(lab.names("failed").is_empty(), "{:?}", lab.names("failed"));
    assert_eq!(
        lab.names("done"),
        BTreeSet::from([
            "a.scan.json".into(),
            "a-2.scan.json".into(),
            "a-2.scan.json.note.txt".into(),
            "b.scan.json".into(),
            "b.scan.json.note.txt".into(),
        ])
    );
    let why = std::fs::read_to_string(lab.sub("done/b.scan.json.note.txt")).unwrap();
    assert!(
        why.contains(&format!("already imported as scan {first} on ")),
        "{why}"
    );
    assert!(why.contains("from a.scan.json"), "{why}");
    assert!(why.contains("brdfd import --again b.scan.json"), "{why}");
    assert_eq!(scans(&daemon.client).len(), 1);
    let status = daemon.ingest();
    assert_eq!(status["already_imported"], 2, "{status}");
    assert_eq!(status["rejected"], 0, "{status}");
    // A second drop of a name already in done/ keeps every file there.
    let other = example("t-pebble-grey").to_json_pretty().unwrap();
    std::fs::write(lab.sub("a.scan.json"), &other).unwrap();
    wait_for("the new a.scan.json in done/", || {
        lab.names("done").len() == 6
    });
    assert!(lab.names("done").contains("a-3.scan.json"));
    assert_eq!(scans(&daemon.client).len(), 2);
    daemon.stop();
    assert_eq!(ingested(&lab).len(), 2);
}

/// The real X-Rite export the door tests import.
fn xlsx() -> (PathBuf, &'static str) {
    let name = "PAR_PW_CB_NG_1.xlsx";
    (
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/real-mat12")
            .join(name),
        name,
    )
}

/// `brdfd import FILE --detach` (and `extra`) against the lab's daemon (its configuration for
/// the token, its address as it printed it): exit code and stdout.
fn cli_import(
    lab: &Lab,
    daemon: &ServeChild,
    file: &Path,
    extra: &[&str],
) -> (Option<i32>, String) {
    let config = lab.dir.join("brdfd.toml");
    let addr = daemon.addr.to_string();
    let mut args = vec![
        "import",
        file.to_str().unwrap(),
        "--detach",
        "--config",
        config.to_str().unwrap(),
        "--addr",
        &addr,
    ];
    args.extend_from_slice(extra);
    let out = run_brdfd(&args, None);
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{args:?}: {stdout} {stderr}");
    (out.status.code(), stdout)
}

/// One file through every door: `brdfd import` twice gives one scan and names it the second
/// time; dropped into the watch folder under another name it goes to done/ with a note; over
/// HTTP the answer is the first scan; `--again` imports it anyway. The file's name is in the
/// scan's provenance once, whatever the door.
#[test]
fn a_file_is_imported_once_whatever_the_door_unless_asked_again() {
    let _serial = serial();
    let lab = Lab::new(100, 600_000);
    let daemon = lab.serve();
    let (path, name) = xlsx();
    // The CLI, twice.
    let (_, first_out) = cli_import(&lab, &daemon, &path, &[]);
    assert!(first_out.contains("imported as scan"), "{first_out}");
    let list = scans(&daemon.client);
    assert_eq!(list.len(), 1, "{list:?}");
    let first = list[0]["id"].as_i64().unwrap();
    let (_, again_out) = cli_import(&lab, &daemon, &path, &[]);
    assert!(
        again_out.contains(&format!("already imported as scan {first} on ")),
        "{again_out}"
    );
    assert!(again_out.contains(&format!("from {name}")), "{again_out}");
    assert!(again_out.contains("--again"), "{again_out}");
    assert_eq!(scans(&daemon.client).len(), 1);
    // The file name once in the provenance, not "the uploaded .xlsx".
    let shown = daemon.client.get(&format!("/scans/{first}")).unwrap();
    let detail = shown["scan"]["provenance"]["source_detail"]
        .as_str()
        .unwrap()
        .to_string();
    assert_eq!(detail.matches(name).count(), 1, "{detail}");
    assert!(!detail.contains("uploaded"), "{detail}");
    assert!(!detail.starts_with("imported from"), "{detail}");
    // The camera's images came with it, in the same transaction.
    let want = brdfd::formats::xrite::read_file(&path, &Default::default()).unwrap()[0]
        .textures
        .len();
    assert_eq!(shown["textures"].as_array().unwrap().len(), want, "{shown}");
    // The watch folder, under another name: done/ with a note, no new scan.
    std::fs::copy(&path, lab.sub("renamed.xlsx")).unwrap();
    wait_for("renamed.xlsx in done/ with its note", || {
        lab.names("done").len() == 2
    });
    assert!(lab.names("failed").is_empty(), "{:?}", lab.names("failed"));
    let note = std::fs::read_to_string(lab.sub("done/renamed.xlsx.note.txt")).unwrap();
    assert!(
        note.contains(&format!("already imported as scan {first} on ")),
        "{note}"
    );
    assert!(note.contains(&format!("from {name}")), "{note}");
    assert_eq!(daemon.ingest()["already_imported"], 1);
    // HTTP: 200, the first scan, no fit queued, the message.
    let bytes = std::fs::read(&path).unwrap();
    let v = daemon
        .client
        .post_bytes("/scans/import?file=other.xlsx", &bytes)
        .unwrap();
    assert_eq!(v["scan"].as_i64(), Some(first), "{v}");
    assert_eq!(v["fits"].as_array().unwrap().len(), 0, "{v}");
    let message = v["already_imported"]["message"].as_str().unwrap();
    assert!(message.contains(&format!("from {name}")), "{v}");
    assert!(message.contains("again=true"), "{v}");
    assert_eq!(scans(&daemon.client).len(), 1);
    // --again imports it anyway: a second scan.
    let (_, forced) = cli_import(&lab, &daemon, &path, &["--again"]);
    assert!(forced.contains("imported as scan"), "{forced}");
    assert!(!forced.contains("already"), "{forced}");
    let list = scans(&daemon.client);
    assert_eq!(list.len(), 2, "{list:?}");
    // Then the repeat names both.
    let (_, third) = cli_import(&lab, &daemon, &path, &[]);
    assert!(third.contains("already imported as scans"), "{third}");
    daemon.stop();
}

/// A scan file uploaded over HTTP with its name, then given to `brdfd import`: recognised.
#[test]
fn a_file_uploaded_over_http_is_recognised_by_the_cli() {
    let _serial = serial();
    let lab = Lab::new(100, 600_000);
    let daemon = lab.serve();
    let text = example("t-sky-blue").to_json_pretty().unwrap();
    let file = lab.dir.join("sky.scan.json");
    std::fs::write(&file, &text).unwrap();
    let v = daemon
        .client
        .post_text("/scans/import?file=sky.scan.json", &text)
        .unwrap();
    let first = v["scan"].as_i64().unwrap();
    let shown = daemon.client.get(&format!("/scans/{first}")).unwrap();
    assert_eq!(
        shown["scan"]["provenance"]["source_detail"], "brdfd.scan/1 file sky.scan.json",
        "{shown}"
    );
    let (_, out) = cli_import(&lab, &daemon, &file, &[]);
    assert!(
        out.contains(&format!("already imported as scan {first} on ")),
        "{out}"
    );
    assert!(out.contains("from sky.scan.json"), "{out}");
    assert_eq!(scans(&daemon.client).len(), 1);
    daemon.stop();
}

/// An X-Rite export and the scan file `brdfd import-format` converts it to are one
/// measurement: whichever is imported second is recognised as imported (its scan file names
/// the export's SHA-256 among its origin notes), unless asked again.
#[test]
fn an_export_and_its_conversion_are_imported_once() {
    let _serial = serial();
    let lab = Lab::new(100, 600_000);
    let daemon = lab.serve();
    let (path, name) = xlsx();
    let converted = lab.dir.join("converted");
    let out = run_brdfd(
        &[
            "import-format",
            path.to_str().unwrap(),
            "--out",
            converted.to_str().unwrap(),
        ],
        None,
    );
    assert!(out.status.success(), "{out:?}");
    let json: Vec<PathBuf> = std::fs::read_dir(&converted)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().ends_with(".scan.json"))
        .collect();
    assert_eq!(json.len(), 1, "{json:?}");
    // The conversion first, then the export itself: the export is recognised.
    let (_, first_out) = cli_import(&lab, &daemon, &json[0], &[]);
    assert!(first_out.contains("imported as scan"), "{first_out}");
    let first = scans(&daemon.client)[0]["id"].as_i64().unwrap();
    let (_, again) = cli_import(&lab, &daemon, &path, &[]);
    assert!(
        again.contains(&format!("already imported as scan {first} on ")),
        "{again}"
    );
    assert_eq!(scans(&daemon.client).len(), 1);
    // Asked again, the export is imported; then a repeat of the export names both scans of
    // the measurement, the conversion's and its own.
    let (_, forced) = cli_import(&lab, &daemon, &path, &["--again"]);
    assert!(forced.contains("imported as scan"), "{forced}");
    let list = scans(&daemon.client);
    assert_eq!(list.len(), 2, "{list:?}");
    let (_, repeat) = cli_import(&lab, &daemon, &path, &[]);
    assert!(repeat.contains("already imported as scans"), "{repeat}");
    // The watch folder knows the export after its conversion too.
    std::fs::copy(&path, lab.sub(name)).unwrap();
    wait_for("the export in done/ with its note", || {
        lab.names("done").len() == 2
    });
    let note = std::fs::read_to_string(lab.sub(&format!("done/{name}.note.txt"))).unwrap();
    assert!(note.contains("already imported as scans"), "{note}");
    assert_eq!(scans(&daemon.client).len(), 2);
    daemon.stop();
}

/// `n` distinct scans: the examples under numbered sample names.
fn many_scans(n: usize) -> Vec<Scan> {
    let names = [
        "t-freesia-pink",
        "t-lavender-blue",
        "t-mandarin-orange",
        "t-manzana-green",
        "t-pebble-grey",
        "t-prairie-green",
        "t-saffron-yellow",
        "t-sky-blue",
    ];
    let examples: Vec<Scan> = names.iter().map(|n| example(n)).collect();
    (0..n)
        .map(|i| {
            let mut s = examples[i % examples.len()].clone();
            s.sample = format!("{} #{i}", s.sample);
            s
        })
        .collect()
}

/// The scan files of `n` distinct samples (the examples under numbered names).
fn many(n: usize) -> Vec<(String, String)> {
    many_scans(n)
        .into_iter()
        .enumerate()
        .map(|(i, s)| (format!("s{i:03}.scan.json"), s.to_json_pretty().unwrap()))
        .collect()
}

#[test]
fn a_hundred_files_at_once_are_each_imported_once() {
    let _serial = serial();
    let lab = Lab::new(100, 600_000);
    let daemon = lab.serve();
    // 60 scan files and 20 MA-T12 exports (10 CGATS, 10 CxF3), each with its SRA CSV: 100
    // files, 80 imports.
    let mut files = many(60);
    let mut mains = BTreeSet::new();
    for (i, mut scan) in many_scans(20).into_iter().enumerate() {
        scan.sample = format!("{} (export {i})", scan.sample);
        let (name, text) = if i % 2 == 0 {
            (format!("export {i:02}.cgats"), cgats_export(&scan))
        } else {
            (format!("Export {i:02}.CXF"), cxf3_export(&scan))
        };
        files.push((name.clone(), text));
        files.push((format!("export {i:02}.sra.csv"), sra_csv(&scan)));
        mains.insert(name);
    }
    assert_eq!(files.len(), 100);
    for (name, text) in &files {
        std::fs::write(lab.sub(name), text).unwrap();
    }
    wait_for("100 files in done/", || lab.names("done").len() == 100);
    assert!(lab.settled());
    assert!(lab.names("failed").is_empty(), "{:?}", lab.names("failed"));
    let expected: BTreeSet<String> = files.iter().map(|(n, _)| n.clone()).collect();
    assert_eq!(lab.names("done"), expected);
    let samples: BTreeSet<String> = scans(&daemon.client)
        .iter()
        .map(|s| s["sample"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(samples.len(), 80);
    assert_eq!(daemon.ingest()["imported"], 80);
    daemon.stop();
    let rows = ingested(&lab);
    assert_eq!(rows.len(), 80);
    let names: BTreeSet<String> = rows.into_iter().map(|(_, n)| n).collect();
    let mut imported: BTreeSet<String> = files
        .iter()
        .map(|(n, _)| n.clone())
        .filter(|n| n.ends_with(".scan.json"))
        .collect();
    imported.extend(mains);
    assert_eq!(names, imported);
}

#[test]
fn a_daemon_killed_mid_import_starts_again_with_what_it_was_importing_in_failed() {
    let _serial = serial();
    let lab = Lab::new(100, 600_000);
    let files = many(40);
    let daemon = lab.serve();
    for (name, text) in &files {
        std::fs::write(lab.sub(name), text).unwrap();
    }
    wait_for("some files imported", || {
        daemon.ingest()["imported"].as_u64().unwrap_or(0) >= 3
    });
    daemon.kill();
    let done_before = lab.names("done").len();
    // Whatever the kill interrupted, add both in-flight states by hand: a file whose import
    // committed but which was not moved yet (a copy of one in done/ put back into
    // .importing/), and a file moved into .importing/ whose import had not committed (as one
    // whose reader aborted the daemon).
    let committed = lab.names("done").into_iter().next().unwrap();
    std::fs::copy(
        lab.sub("done").join(&committed),
        lab.sub(".importing").join("committed.scan.json"),
    )
    .unwrap();
    let mut fresh = example("t-sky-blue");
    fresh.sample = "in flight".into();
    std::fs::write(
        lab.sub(".importing/fresh.scan.json"),
        fresh.to_json_pretty().unwrap(),
    )
    .unwrap();

    // The daemon starts and serves status; nothing in .importing/ is read again.
    let daemon = lab.serve();
    wait_for("every file done or failed", || {
        lab.settled() && lab.names("done").len() + lab.names("failed").len() / 2 == 42
    });
    let failed: BTreeSet<String> = lab
        .names("failed")
        .into_iter()
        .filter(|n| !n.ends_with(".error.txt"))
        .collect();
    assert!(failed.contains("fresh.scan.json"), "{failed:?}");
    assert!(lab.names("done").contains("committed.scan.json"));
    for name in &failed {
        let note =
            std::fs::read_to_string(lab.sub("failed").join(format!("{name}.error.txt"))).unwrap();
        assert!(
            note.contains("brdfd stopped while importing this file")
                && note.contains("It is not read again automatically")
                && note.contains("move it back into the watch folder"),
            "{name}: {note}"
        );
    }
    let status = daemon.ingest();
    let interrupted: BTreeSet<String> = status["interrupted"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap().to_string())
        .collect();
    assert_eq!(interrupted, failed);
    assert!(
        status["last_error"]
            .as_str()
            .is_some_and(|e| e.contains("the daemon stopped while importing it")),
        "{status}"
    );
    // `brdfd status` says it too.
    let token = lab.dir.join("brdfd.token");
    let out = run_brdfd(
        &[
            "status",
            "--addr",
            &daemon.addr.to_string(),
            "--token-file",
            token.to_str().unwrap(),
        ],
        None,
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    assert!(
        stdout.contains("the daemon stopped while importing")
            && stdout.contains("fresh.scan.json")
            && stdout.contains("not read again"),
        "{stdout}"
    );
    // How far the first run got, and what the kill interrupted, vary.
    eprintln!(
        "{done_before} of 40 files were done when the daemon was killed; {} interrupted",
        failed.len() - 1
    );
    let samples: Vec<String> = scans(&daemon.client)
        .iter()
        .map(|s| s["sample"].as_str().unwrap().to_string())
        .collect();
    // The 40, less those the kill interrupted; the committed copy was not imported again and
    // the fresh one not at all.
    assert_eq!(samples.len(), 40 - (failed.len() - 1), "{samples:?}");
    assert_eq!(samples.iter().collect::<BTreeSet<_>>().len(), samples.len());
    assert!(!samples.contains(&"in flight".to_string()));
    daemon.stop();
    let rows = ingested(&lab);
    assert_eq!(rows.len(), samples.len());
}

/// A file that cannot be imported yet (here for its bytes: an unfinished upload holds most of
/// the import budget) does not hold up the files behind it; while the bytes are held, an upload
/// over what is left is refused with 503 naming `[ingest] max_held_mib`; once the upload is
/// gone the waiting file is read.
#[test]
fn a_waiting_import_does_not_stall_the_folder_and_bodies_held_at_once_are_bounded() {
    use std::io::Read;
    let _serial = serial();
    let lab = Lab::new(50, 0);
    let config = lab.dir.join("brdfd.toml");
    let text = std::fs::read_to_string(&config)
        .unwrap()
        .replace("[ingest]\n", "[ingest]\nmax_held_mib = 64\n");
    std::fs::write(&config, text).unwrap();
    let daemon = lab.serve();
    let upload = |length: u64| {
        let mut c = std::net::TcpStream::connect(daemon.addr).unwrap();
        write!(
            c,
            "POST /scans/import HTTP/1.1\r\nHost: {}\r\nAuthorization: Bearer {}\r\n\
             Content-Type: application/json\r\nConnection: close\r\nContent-Length: {length}\r\n\r\n{{",
            daemon.addr, daemon.token
        )
        .unwrap();
        c
    };
    // 63 of the 64 MiB held by an upload that has sent one byte of its body.
    let holder = upload(63 << 20);
    wait_for("the upload's bytes held", || {
        let metrics = daemon.client.get_text("/metrics").unwrap_or_default();
        metrics.contains("brdfd_import_held_bytes 66060288")
    });
    // A second upload over what is left is refused at once, naming the bound.
    let mut second = upload(2 << 20);
    let mut answer = String::new();
    second.read_to_string(&mut answer).unwrap();
    assert!(answer.starts_with("HTTP/1.1 503"), "{answer}");
    assert!(
        answer.to_ascii_lowercase().contains("retry-after: 1"),
        "{answer}"
    );
    assert!(
        answer.contains("holds 63 MiB of import bodies")
            && answer.contains("[ingest] max_held_mib"),
        "{answer}"
    );
    // A 2 MiB file waits in the folder for its bytes; a scan file dropped after it is
    // imported meanwhile.
    std::fs::write(lab.sub("big.scan.json"), vec![b' '; 2 << 20]).unwrap();
    std::thread::sleep(Duration::from_millis(200));
    std::fs::write(
        lab.sub("small.scan.json"),
        example("t-sky-blue").to_json_pretty().unwrap(),
    )
    .unwrap();
    wait_for("the small file imported", || {
        lab.names("done").contains("small.scan.json")
    });
    assert!(lab.names("").contains("big.scan.json"));
    assert_eq!(daemon.ingest()["waiting"], 1);
    // The upload gone, its bytes are given back and the big file is read (and refused).
    drop(holder);
    wait_for("the big file read", || {
        lab.settled() && lab.names("failed").contains("big.scan.json")
    });
    let note = std::fs::read_to_string(lab.sub("failed/big.scan.json.error.txt")).unwrap();
    assert!(note.contains("big.scan.json"), "{note}");
    daemon.stop();
}

/// In-process: a daemon stopped after an import committed but before its fits were queued
/// (the row says `fits_queued = 0` and the scan has no fit) queues them at the next start, and
/// the folder's task records that it did.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fits_not_queued_before_a_stop_are_queued_at_the_next_start() {
    let _serial = serial();
    bounded(async {
        let (_tmp, db, inbox) = store_and_inbox();
        let scan = example("t-manzana-green");
        let readings = |r: &brdfd::scan::DeviceReadings| {
            brdfd::geometry::GEOMETRIES
                .iter()
                .map(|g| brdfd::store::NewReading {
                    device: g.device,
                    geometry: g,
                    values: match g.device {
                        brdfd::geometry::Device::MaT12 => {
                            brdfd::store::ReadingValues::Spectrum(r.ma_t12[g.index])
                        }
                        brdfd::geometry::Device::Sra => brdfd::store::ReadingValues::Intensity(
                            r.sra.unwrap()[g.index - brdfd::geometry::MA_T12_COUNT],
                        ),
                    },
                    raw_frame: &[],
                })
                .collect::<Vec<_>>()
        };
        let provenance = brdfd::store::Provenance {
            source: brdfd::store::Source::Imported,
            source_detail: Some("imported from x.scan.json, brdfd.scan/1 file".into()),
            ..brdfd::store::Provenance::unknown()
        };
        let (r, m) = (
            readings(&scan.reference.as_ref().unwrap().readings),
            readings(&scan.readings),
        );
        // The scan as the watch folder would import it, under `sample_name`.
        let as_imported = |sample_name| brdfd::store::ImportedScan {
            sample_name,
            reference_name: "Munsell N9 (imported)",
            provenance: &provenance,
            reference_readings: Some(&r),
            readings: &m,
            taken_at_ms: None,
            textures: &[],
        };
        let store = brdfd::store::Store::open(&db).await.unwrap();
        let hash = "ab".repeat(32);
        let imported = store
            .import_file(
                &hash,
                "x.scan.json",
                None,
                &[as_imported(scan.sample.as_str())],
            )
            .await
            .unwrap();
        let brdfd::store::FileImport::Imported(file) = imported else {
            panic!("{imported:?}")
        };
        assert!(!file.fits_queued);
        let scan_id = file.scans[0];
        assert!(store.fits_for_scan(scan_id).await.unwrap().is_empty());
        // The same hash again is refused inside the transaction, writing nothing.
        let again = store
            .import_file(&hash, "y.scan.json", None, &[as_imported("other")])
            .await
            .unwrap();
        assert_eq!(
            again,
            brdfd::store::FileImport::AlreadyImported(file.clone())
        );
        store.close().await;

        let store = brdfd::store::Store::open(&db).await.unwrap();
        let service = watching_service(&store, &inbox).await;
        poll_until("the fits were never queued", async || {
            store.ingested_files().await.unwrap()[0]
                .fits_queued
                .then_some(())
        })
        .await;
        let fits = store.fits_for_scan(scan_id).await.unwrap();
        assert_eq!(fits.len(), 1, "{fits:?}");
        assert!(service.wait_settled(scan_id, STEP_TIMEOUT).await.unwrap());
        let fits = store.fits_for_scan(scan_id).await.unwrap();
        assert_eq!(fits[0].status, brdfd::store::FitStatus::Done, "{fits:?}");
        // The folders were made, and the status shows the folder.
        for sub in ["done", "failed", ".importing"] {
            assert!(inbox.join(sub).is_dir(), "{sub}");
        }
        let status = service.status().await.unwrap().ingest.unwrap();
        assert_eq!(status.dir, inbox.display().to_string());
        service.shutdown().await;
    })
    .await;
}

#[test]
fn a_watch_folder_that_does_not_exist_stops_the_start_naming_it() {
    let lab = Lab::new(100, 1000);
    std::fs::remove_dir(&lab.inbox).unwrap();
    let out = run_brdfd(
        &[
            "serve",
            "--config",
            lab.dir.join("brdfd.toml").to_str().unwrap(),
        ],
        None,
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(&format!(
            "[ingest] watch = {}: no such directory; create it",
            lab.inbox.display()
        )),
        "{err}"
    );
}

/// In-process: a store that fails the import (a trigger stands for a full disk) leaves the
/// file in `.importing/` with the error in the status and no half-imported scan; once the
/// store works again the next pass imports it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_store_failure_leaves_the_file_in_flight_until_the_store_works() {
    use sqlx::Connection;
    let _serial = serial();
    bounded(async {
        let (_tmp, db, inbox) = store_and_inbox();
        let store = brdfd::store::Store::open(&db).await.unwrap();
        // A second connection to the same file, as another process would have.
        let mut raw = sqlx::SqliteConnection::connect(&format!("sqlite://{}", db.display()))
            .await
            .unwrap();
        sqlx::query(
            "CREATE TRIGGER full_disk BEFORE INSERT ON ingested_files
             BEGIN SELECT RAISE(ABORT, 'database or disk is full (test)'); END",
        )
        .execute(&mut raw)
        .await
        .unwrap();
        let service = watching_service(&store, &inbox).await;
        let text = example("t-lavender-blue").to_json_pretty().unwrap();
        std::fs::write(inbox.join("l.scan.json"), &text).unwrap();
        let status = poll_until("no error reported", async || {
            let s = service.status().await.unwrap().ingest.unwrap();
            s.last_error.is_some().then_some(s)
        })
        .await;
        let e = status.last_error.unwrap();
        assert!(e.contains("l.scan.json: the store failed"), "{e}");
        assert!(e.contains("disk is full (test)"), "{e}");
        assert!(e.contains("left in .importing/ and tried again"), "{e}");
        assert!(inbox.join(".importing/l.scan.json").is_file());
        assert!(!inbox.join("failed/l.scan.json").exists());
        // The transaction left nothing behind.
        let all = brdfd::store::ScanFilter {
            limit: 500,
            ..Default::default()
        };
        assert!(store.list_scans(&all).await.unwrap().is_empty());
        assert_eq!(status.imported, 0);

        sqlx::query("DROP TRIGGER full_disk")
            .execute(&mut raw)
            .await
            .unwrap();
        raw.close().await.unwrap();
        poll_until("never imported after the store recovered", async || {
            inbox.join("done/l.scan.json").is_file().then_some(())
        })
        .await;
        assert!(!inbox.join(".importing/l.scan.json").exists());
        assert_eq!(store.list_scans(&all).await.unwrap().len(), 1);
        assert_eq!(store.ingested_files().await.unwrap().len(), 1);
        assert_eq!(service.status().await.unwrap().ingest.unwrap().imported, 1);
        service.shutdown().await;
    })
    .await;
}
