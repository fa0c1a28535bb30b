//! Several stations, one lab, against a real PostgreSQL (tests/common/pg.rs): stations on the
//! replayed recordings forward their stores to a central database while they measure, and the
//! central database ends up holding exactly the union of their stores — row for row, column
//! for column, and as the same exports and the same report — after three stations forwarding at
//! once, after the server was killed (`pg_ctl stop -m immediate`) mid-forward and restarted,
//! and after a station was restarted mid-forward. A second store under a taken station id and
//! a central schema newer than this brdfd are refused; a bad URL or a wrong password is one
//! clear line while the station goes on measuring.

// `common::serial()` is a process-wide std mutex held for a whole test on purpose: each
// `#[tokio::test]` has its own runtime, so no task of the same runtime waits for it.
#![allow(clippy::await_holding_lock)]

mod common;
#[path = "common/pg.rs"]
mod pg;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::Duration;

use brdfd::formats::{ExportOptions, Format};
use brdfd::report::load::{Selection, from_central, from_store};
use brdfd::service::{Service, ServiceOptions, ServiceSettings};
use brdfd::store::Store;
use brdfd::store::central::CentralSelection;
use brdfd::sync::tables::TABLES;
use brdfd::sync::{Central, Forwarder, ForwarderOptions, SyncError};
use sqlx::Row;

use common::*;
use pg::{Cluster, TestDb, central_tables, highest_seq, local_tables, wait_for};

/// Forwarding settings for tests: small batches, quick polls and retries.
fn forwarding(station: &str, url: &str, batch: usize) -> ForwarderOptions {
    ForwarderOptions {
        batch,
        poll: Duration::from_millis(20),
        max_backoff: Duration::from_millis(300),
        ..ForwarderOptions::new(station, url)
    }
}

/// The service settings of a station forwarding as `station`.
fn station_settings(station: &str, url: &str, batch: usize) -> ServiceSettings {
    ServiceSettings {
        sync: Some(forwarding(station, url, batch)),
        // Intervals are forwarded like every other column; a few resamples make them quickly
        // enough for the comparison to wait for them (`bootstraps_pending`).
        bootstrap: 5,
        ..settings()
    }
}

/// A station: the daemon in-process on the replayed recordings, forwarding as `station`.
async fn station(station: &str, url: &str, batch: usize) -> TestDaemon {
    start(
        simulated(&strict_fast()),
        station_settings(station, url, batch),
        ServiceOptions::default(),
    )
    .await
}

/// The first `n` samples of the recordings.
fn samples(n: usize) -> Vec<&'static str> {
    mock_devices::recordings::samples()
        .iter()
        .take(n)
        .map(|s| s.sample.unwrap())
        .collect()
}

/// The reference, then `n` samples, each settled (fits done).
async fn measure(d: &TestDaemon, n: usize) {
    measure_reference(&d.service).await;
    for s in samples(n) {
        scan_and_settle(&d.service, s).await;
    }
}

/// Waits until the central database acknowledged everything the store at `db` has queued
/// (the status alone may predate the last commit).
async fn drained_service(service: &Service, db: &Path) {
    wait_for(
        "the central cursor to reach the store's last entry",
        STEP_TIMEOUT,
        || async {
            // A bootstrap still running would write its intervals after the check.
            let status = service.status().await.unwrap();
            let s = status.sync.expect("forwarding");
            status.bootstraps_pending == 0
                && s.cursor == Some(highest_seq(db).await)
                && s.last_error.is_none()
        },
    )
    .await;
}

async fn drained(d: &TestDaemon) {
    drained_service(&d.service, &d.db).await;
}

/// Waits until the station's forwarder has sent its first rows.
async fn some_rows_forwarded(service: &Service, what: &str) {
    wait_for(what, STEP_TIMEOUT, || async {
        service.status().await.unwrap().sync.unwrap().rows_forwarded > 0
    })
    .await;
}

/// Runs `brdfd sync --db DB --to URL --station STATION EXTRA…`.
fn brdfd_sync(db: &Path, url: &str, station: &str, extra: &[&str]) -> Output {
    let mut args = vec![
        "sync",
        "--db",
        db.to_str().unwrap(),
        "--to",
        url,
        "--station",
        station,
    ];
    args.extend_from_slice(extra);
    run_brdfd(&args, None)
}

/// Checks that a `brdfd` run succeeded, showing its stderr if not.
fn assert_ran(out: &Output) {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The NDJSON lines a `brdfd sync --json` run printed.
fn ndjson(out: &Output) -> Vec<serde_json::Value> {
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// Rows per station in the central database, per table.
async fn central_station_counts(url: &str) -> BTreeMap<(String, &'static str), i64> {
    let pool = sqlx::PgPool::connect(url).await.unwrap();
    let mut out = BTreeMap::new();
    for t in &TABLES {
        let rows = sqlx::query(&format!(
            "SELECT station, COUNT(*) FROM {} GROUP BY station",
            t.name
        ))
        .fetch_all(&pool)
        .await
        .unwrap();
        for r in rows {
            out.insert((r.get::<String, _>(0), t.name), r.get::<i64, _>(1));
        }
    }
    pool.close().await;
    out
}

/// The station's store and the central database hold the same rows for it, and export the
/// same study (JSON: every reading, fit and ΔE00).
async fn assert_same(db: &Path, url: &str, station: &str) {
    let local = local_tables(db).await;
    let central = central_tables(url, station).await;
    for t in &TABLES {
        assert!(
            !local[t.name].is_empty() || t.name == "instruments",
            "{}: the station stored rows",
            t.name
        );
        assert_eq!(
            local[t.name].len(),
            central[t.name].len(),
            "{station}: {} row count, station vs central",
            t.name
        );
        assert_eq!(
            local[t.name], central[t.name],
            "{station}: {} contents, station vs central",
            t.name
        );
    }
    let store = Store::open_read_only(db).await.unwrap();
    let local_study = from_store(&store, &Selection::All).await.unwrap();
    let c = Central::connect(url).await.unwrap();
    let central_study = from_central(
        c.pool(),
        &CentralSelection {
            station: Some(station.to_string()),
            scans: None,
        },
    )
    .await
    .unwrap();
    c.close().await;
    let opts = ExportOptions::default();
    assert_eq!(
        brdfd::formats::export(&local_study, Format::Json, &opts).unwrap(),
        brdfd::formats::export(&central_study, Format::Json, &opts).unwrap(),
        "{station}: the JSON export of the station's store and of the central database"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn three_stations_forwarding_at_once_make_the_union_of_their_stores() {
    let _serial = serial();
    let db = TestDb::create("union");
    bounded(async {
        let names = ["bench-1", "bench-2", "bench-3"];
        let mut stations = Vec::new();
        for n in names {
            stations.push(station(n, &db.url, 40).await);
        }
        // All three measure at the same time while forwarding.
        let work: Vec<_> = stations
            .iter()
            .enumerate()
            .map(|(i, d)| measure(d, 1 + i))
            .collect();
        futures_join_all(work).await;
        for d in &stations {
            drained(d).await;
        }
        for (d, n) in stations.iter().zip(names) {
            d.service.stop_keeping_store().await;
            assert_same(&d.db, &db.url, n).await;
        }
        // Nothing else arrived: the central rows are exactly the three stores' rows.
        let counts = central_station_counts(&db.url).await;
        let mut expected = BTreeMap::new();
        for (d, n) in stations.iter().zip(names) {
            for (t, rows) in local_tables(&d.db).await {
                if !rows.is_empty() {
                    expected.insert((n.to_string(), t), rows.len() as i64);
                }
            }
        }
        assert_eq!(counts, expected, "central rows per station and table");

        // Across stations the report names each sample with its station.
        let c = Central::connect(&db.url).await.unwrap();
        let all = from_central(c.pool(), &CentralSelection::default())
            .await
            .unwrap();
        assert_eq!(all.samples.len(), 1 + 2 + 3);
        assert!(
            all.samples.iter().any(|s| s.name.ends_with("[bench-3]")),
            "{:?}",
            all.samples.iter().map(|s| &s.name).collect::<Vec<_>>()
        );
        c.close().await;
        for d in &stations {
            d.store.close().await;
        }
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_station_report_from_the_central_database_is_the_report_of_its_store() {
    let _serial = serial();
    let db = TestDb::create("report");
    let d = bounded(async {
        let d = station("bench-p", &db.url, 100).await;
        measure(&d, 2).await;
        drained(&d).await;
        d.service.stop_keeping_store().await;
        d
    })
    .await;
    // Drawing the figures in a debug build takes a while on a loaded machine: outside the
    // bound of the daemon part.
    let out = tempfile::tempdir().unwrap();
    let store = Store::open_read_only(&d.db).await.unwrap();
    let local = from_store(&store, &Selection::All).await.unwrap();
    let c = Central::connect(&db.url).await.unwrap();
    let central = from_central(
        c.pool(),
        &CentralSelection {
            station: Some("bench-p".into()),
            scans: None,
        },
    )
    .await
    .unwrap();
    c.close().await;
    assert_eq!(local.samples.len(), 2);
    // Every figure (PNG, SVG) and the summary pages, byte for byte.
    let (a, b) = (out.path().join("station"), out.path().join("central"));
    let fa = brdfd::report::write_report(&local, &a, &mut |_, _, _| {}).unwrap();
    let fb = brdfd::report::write_report(&central, &b, &mut |_, _, _| {}).unwrap();
    assert_eq!(fa.figures.len(), fb.figures.len());
    let mut compared = 0;
    for entry in std::fs::read_dir(&a).unwrap() {
        let name = entry.unwrap().file_name();
        assert_eq!(
            std::fs::read(a.join(&name)).unwrap(),
            std::fs::read(b.join(&name)).unwrap(),
            "report file {name:?}: station vs central"
        );
        compared += 1;
    }
    assert!(compared > 10, "{compared} report files");
    store.close().await;
    d.store.close().await;
}

/// Joins futures without a dependency: polls them all on this task.
async fn futures_join_all<F: std::future::Future<Output = ()>>(futs: Vec<F>) {
    let mut futs: Vec<_> = futs.into_iter().map(Box::pin).collect();
    let mut done = vec![false; futs.len()];
    std::future::poll_fn(|cx| {
        for (f, d) in futs.iter_mut().zip(done.iter_mut()) {
            if !*d && f.as_mut().poll(cx).is_ready() {
                *d = true;
            }
        }
        if done.iter().all(|d| *d) {
            std::task::Poll::Ready(())
        } else {
            std::task::Poll::Pending
        }
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_server_killed_mid_forward_and_restarted_loses_and_doubles_nothing() {
    let _serial = serial();
    let cluster = Cluster::start();
    let db = TestDb::create_on(&cluster.admin_url(), "outage");
    bounded(async {
        // Batches of 3 entries: the first scan alone is dozens of transactions.
        let d = station("bench-o", &db.url, 3).await;
        measure_reference(&d.service).await;
        let first = samples(3);
        let scan = d.service.request_scan(first[0]).await.unwrap();
        some_rows_forwarded(&d.service, "some rows forwarded").await;
        cluster.stop_immediate();
        // The station goes on measuring with the server gone.
        assert!(d.service.wait_settled(scan, STEP_TIMEOUT).await.unwrap());
        scan_and_settle(&d.service, first[1]).await;
        wait_for("the outage in the status", STEP_TIMEOUT, || async {
            let s = d.service.status().await.unwrap().sync.unwrap();
            s.last_error.is_some() && !s.connected && s.backlog > 0
        })
        .await;
        let s = d.service.status().await.unwrap().sync.unwrap();
        let e = s.last_error.unwrap();
        assert!(!e.contains('\n') && e.contains("central database"), "{e}");

        cluster.restart();
        scan_and_settle(&d.service, first[2]).await;
        drained(&d).await;
        d.service.stop_keeping_store().await;
        assert_same(&d.db, &db.url, "bench-o").await;
        d.store.close().await;
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_station_restarted_mid_forward_loses_and_doubles_nothing() {
    let _serial = serial();
    let db = TestDb::create("restart");
    bounded(async {
        // The first life: the station measures its reference with a slow forwarder (one
        // outbox entry per transaction) and is stopped as soon as the first rows arrived,
        // with the rest of the reference's 15 entries still to send; stopping drops the
        // forwarder's transaction under way.
        let d = station("bench-r", &db.url, 1).await;
        measure_reference(&d.service).await;
        some_rows_forwarded(&d.service, "the first rows forwarded").await;
        d.service.stop_keeping_store().await;
        let before = d.service.status().await.unwrap().sync.unwrap();
        assert!(before.backlog > 0, "stopped mid-forward: {before:?}");
        d.store.close().await;

        // The second life, on the same store: forwarding resumes from the central cursor.
        let (store, service) = service_on(&d.db, station_settings("bench-r", &db.url, 50)).await;
        measure_reference(&service).await;
        scan_and_drain(&service, &d.db, samples(1)[0]).await;
        service.stop_keeping_store().await;
        assert_same(&d.db, &db.url, "bench-r").await;
        store.close().await;
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_taken_station_id_and_a_newer_central_schema_are_refused() {
    let db = TestDb::create("refuse");
    bounded(async {
        let a = Store::open_in_memory().await.unwrap();
        let b = Store::open_in_memory().await.unwrap();
        let mut fa = Forwarder::for_store(&a, forwarding("bench-x", &db.url, 10))
            .await
            .unwrap();
        assert!(
            fa.step().await.unwrap().is_none(),
            "an empty store sends nothing"
        );
        // Another store under the same id.
        let mut fb = Forwarder::for_store(&b, forwarding("bench-x", &db.url, 10))
            .await
            .unwrap();
        let e = fb.step().await.unwrap_err();
        assert!(matches!(e, SyncError::StationTaken { .. }), "{e}");
        let text = e.to_string();
        assert!(
            text.contains("bench-x") && text.contains("[station] id"),
            "{text}"
        );
        // The same store under a second id.
        let mut fa2 = Forwarder::for_store(&a, forwarding("bench-y", &db.url, 10))
            .await
            .unwrap();
        let e = fa2.step().await.unwrap_err();
        assert!(matches!(e, SyncError::StoreHasOtherId { .. }), "{e}");

        // A newer brdfd migrated the central database.
        let pool = sqlx::PgPool::connect(&db.url).await.unwrap();
        sqlx::query(
            "INSERT INTO _sqlx_migrations (version, description, success, checksum,
                                           execution_time)
             VALUES (9999, 'from the future', true, '\\x00', 0)",
        )
        .execute(&pool)
        .await
        .unwrap();
        pool.close().await;
        let e = Central::connect_and_migrate(&db.url).await.unwrap_err();
        assert!(
            matches!(e, SyncError::NewerSchema { found: 9999, .. }),
            "{e}"
        );
        assert!(e.to_string().contains("upgrade brdfd"), "{e}");
        let mut fa3 = Forwarder::for_store(&a, forwarding("bench-x", &db.url, 10))
            .await
            .unwrap();
        assert!(matches!(
            fa3.step().await.unwrap_err(),
            SyncError::NewerSchema { .. }
        ));
        // The command line says it in one line and fails.
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("brdfd.db");
        Store::open(&file).await.unwrap().close().await;
        let out = brdfd_sync(&file, &db.url, "bench-z", &["--once"]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains("newer than this brdfd"), "{err}");
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bad_url_or_a_wrong_password_is_one_line_and_the_station_keeps_measuring() {
    let _serial = serial();
    let cluster = Cluster::start();
    bounded(async {
        let wrong = format!(
            "postgres://postgres:not-the-password@127.0.0.1:{}/postgres",
            cluster.port
        );
        let d = station("bench-w", &wrong, 50).await;
        measure_reference(&d.service).await;
        let scan = scan_and_settle(&d.service, samples(1)[0]).await;
        let detail = d.store.scan_detail(scan).await.unwrap();
        assert_eq!(detail.scan.state, brdfd::store::ScanState::Complete);
        let s = d.service.status().await.unwrap().sync.unwrap();
        let e = s.last_error.expect("the refusal is in the status");
        assert!(e.contains("password authentication failed"), "{e}");
        assert!(
            !e.contains("not-the-password"),
            "the password is not shown: {e}"
        );
        assert!(s.backlog > 0);
        d.service.stop_keeping_store().await;

        // brdfd sync: one line on stderr, non-zero exit, for a wrong password, a refused
        // connection and a URL that is not one.
        for (url, says) in [
            (wrong.as_str(), "password authentication failed"),
            ("postgres://postgres@127.0.0.1:1/x", "cannot connect"),
            ("postgres://postgres@127.0.0.1:notaport/x", "not valid"),
        ] {
            let out = brdfd_sync(&d.db, url, "bench-w", &["--once"]);
            let err = String::from_utf8_lossy(&out.stderr);
            assert!(!out.status.success(), "{url}");
            assert_eq!(err.trim().lines().count(), 1, "{url}: {err}");
            assert!(err.contains(says), "{url}: {err}");
            assert!(!err.contains("not-the-password"), "{err}");
        }
        // With the right password it sends everything; --json says so in NDJSON.
        let out = brdfd_sync(
            &d.db,
            &cluster.admin_url(),
            "bench-w",
            &["--once", "--json"],
        );
        assert_ran(&out);
        let lines = ndjson(&out);
        assert_eq!(lines[0]["type"], "start", "{lines:?}");
        assert_eq!(lines[0]["station"], "bench-w", "{lines:?}");
        let last = lines.last().unwrap();
        assert_eq!(last["type"], "drained", "{lines:?}");
        let batched: u64 = lines
            .iter()
            .filter(|l| l["type"] == "batch")
            .map(|l| {
                l["rows"]
                    .as_object()
                    .unwrap()
                    .values()
                    .map(|n| n.as_u64().unwrap())
                    .sum::<u64>()
            })
            .sum();
        assert!(batched > 0, "{lines:?}");
        assert_eq!(last["rows"].as_u64(), Some(batched), "{lines:?}");
        d.store.close().await;
    })
    .await;
}

/// A daemon in-process on the replayed recordings and the store file `db` (opened as its
/// owner: a new incarnation of that store), with `settings`.
async fn service_on(db: &Path, settings: ServiceSettings) -> (Store, Service) {
    let store = Store::open(db).await.unwrap();
    let devices = simulated(&strict_fast());
    let service = Service::start(store.clone(), devices, settings, ServiceOptions::default())
        .await
        .unwrap();
    (store, service)
}

/// [`service_on`] as a station forwarding as `name` in batches of 20, after it measured the
/// reference and scanned `sample`.
async fn station_on_scanned(db: &Path, name: &str, url: &str, sample: &str) -> (Store, Service) {
    let (store, service) = service_on(db, station_settings(name, url, 20)).await;
    measure_reference(&service).await;
    scan_and_settle(&service, sample).await;
    (store, service)
}

/// Scans `sample`, then waits until the central database acknowledged all the store at `db`
/// queued.
async fn scan_and_drain(service: &Service, db: &Path, sample: &str) {
    scan_and_settle(service, sample).await;
    drained_service(service, db).await;
}

/// Stops a station, keeping its store, and closes the store.
async fn stop_station(store: &Store, service: &Service) {
    service.stop_keeping_store().await;
    store.close().await;
}

/// A station whose store was copied while it ran, and the copy refused under its id.
struct CopiedStation {
    /// Holds both store files.
    dir: tempfile::TempDir,
    orig: PathBuf,
    copy: PathBuf,
    /// The original station, still running.
    store: Store,
    service: Service,
    /// Why the central database refused the copy.
    refusal: String,
}

/// A station `name` on a new store measures, scans and forwards a first sample; its store is
/// copied while it runs (`VACUUM INTO`, as a backup tool copies it), and it scans and forwards
/// a second sample. The copy then starts under `name`, scans `copy_sample`, is refused (and
/// told that `--adopt` is a way out) and is stopped.
async fn copied_station(name: &str, url: &str, copy_sample: &str) -> CopiedStation {
    let dir = tempfile::tempdir().unwrap();
    let orig = dir.path().join("orig.db");
    let copy = dir.path().join("copy.db");
    let (store, service) = station_on_scanned(&orig, name, url, samples(1)[0]).await;
    drained_service(&service, &orig).await;
    vacuum_into(&orig, &copy).await;
    scan_and_drain(&service, &orig, samples(2)[1]).await;
    let (cs, csvc) = station_on_scanned(&copy, name, url, copy_sample).await;
    let refusal = refused(&csvc).await;
    assert!(refusal.contains("--adopt NEW_ID"), "{refusal}");
    stop_station(&cs, &csvc).await;
    CopiedStation {
        dir,
        orig,
        copy,
        store,
        service,
        refusal,
    }
}

/// `VACUUM INTO`: a consistent copy of a live store, as a backup tool takes it.
async fn vacuum_into(db: &Path, copy: &Path) {
    use sqlx::Connection;
    let mut c = sqlx::SqliteConnection::connect_with(
        &sqlx::sqlite::SqliteConnectOptions::new().filename(db),
    )
    .await
    .unwrap();
    sqlx::query(&format!("VACUUM INTO '{}'", copy.display()))
        .execute(&mut c)
        .await
        .unwrap();
    c.close().await.unwrap();
}

/// Waits until the station's forwarder says the central database refuses its store.
async fn refused(service: &Service) -> String {
    let deadline = std::time::Instant::now() + STEP_TIMEOUT;
    loop {
        let s = service.status().await.unwrap().sync.unwrap();
        if s.refused {
            break;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "the copy was not refused: {s:?}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    service
        .status()
        .await
        .unwrap()
        .sync
        .unwrap()
        .last_error
        .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_copied_store_is_refused_and_nothing_of_it_is_mixed_in() {
    let _serial = serial();
    let db = TestDb::create("fork");
    bounded(async {
        // The original's first life: a reference and a scan, forwarded; a copy of the live
        // store (a backup tool's), then the original goes on. The live copy starts while the
        // original runs: the original forwarded past the point it was copied at, so the copy
        // is refused, whatever it measures.
        let CopiedStation {
            dir,
            orig,
            store,
            service,
            refusal: e,
            ..
        } = copied_station("bench-f", &db.url, samples(1)[0]).await;
        // Its history differs from the station's where the station's rows reach (or it does
        // not reach that far).
        assert!(
            e.contains("is not this store's") || e.contains("older copy"),
            "{e}"
        );

        // The original stops; its checkpointed file is copied; the original starts again
        // (a new incarnation after everything it sent: accepted) and goes on.
        stop_station(&store, &service).await;
        let file_copy = dir.path().join("file-copy.db");
        std::fs::copy(&orig, &file_copy).unwrap();
        let (store, service) = station_on_scanned(&orig, "bench-f", &db.url, samples(1)[0]).await;
        drained_service(&service, &orig).await;

        // The file copy starts second: refused (the station went on as an incarnation this
        // copy never had, so its chain differs from the station's).
        let (cs, csvc) = station_on_scanned(&file_copy, "bench-f", &db.url, samples(1)[0]).await;
        let e = refused(&csvc).await;
        assert!(
            e.contains("is not this store's") || e.contains("older copy"),
            "{e}"
        );
        let status = csvc.status().await.unwrap().sync.unwrap();
        assert!(status.backlog > 0, "its rows wait: {status:?}");
        stop_station(&cs, &csvc).await;

        // The original went on through it all; the central database holds its rows, exactly.
        scan_and_drain(&service, &orig, samples(2)[1]).await;
        service.stop_keeping_store().await;
        assert_same(&orig, &db.url, "bench-f").await;
        let pool = sqlx::PgPool::connect(&db.url).await.unwrap();
        let refusals: i64 =
            sqlx::query_scalar("SELECT COUNT(*) FROM station_refusals WHERE station = 'bench-f'")
                .fetch_one(&pool)
                .await
                .unwrap();
        assert!(refusals >= 2, "{refusals} refusals recorded centrally");
        pool.close().await;
        store.close().await;

        // `brdfd doctor` says which store is the station's and which is a refused copy.
        let db_url = db.url.clone();
        let doctor = |db: &Path| {
            let config = dir.path().join("doctor.toml");
            std::fs::write(
                &config,
                format!(
                    "[store]\npath = \"{}\"\n[station]\nid = \"bench-f\"\n[sync]\nurl = \"{}\"\n\
                     [devices.ma_t12]\ntransport = \"simulated\"\n\
                     [devices.sra]\ntransport = \"simulated\"\n",
                    db.display(),
                    db_url
                ),
            )
            .unwrap();
            let out = run_brdfd(
                &["doctor", "--config", config.to_str().unwrap(), "--json"],
                None,
            );
            let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
            v["checks"]
                .as_array()
                .unwrap()
                .iter()
                .find(|c| c["check"] == "central database")
                .cloned()
                .expect("a central database check")
        };
        let c = doctor(&orig);
        assert_eq!(c["status"], "ok", "{c}");
        assert!(
            c["detail"].as_str().unwrap().contains("is this store's"),
            "{c}"
        );
        let c = doctor(&file_copy);
        assert_eq!(c["status"], "fail", "{c}");
        assert!(c["fix"].as_str().unwrap().contains("--adopt"), "{c}");

        // `brdfd sync` of the copy: exit status 6, one line naming the way out.
        let sync = |station: &str| brdfd_sync(&file_copy, &db.url, station, &["--once"]);
        let out = sync("bench-f");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(6), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains("--adopt"), "{err}");
        // The way out: adopt the copy as a station of its own; it then forwards everything
        // it holds under the new id, and the original's rows are untouched.
        let copy = file_copy.to_str().unwrap();
        let out = run_brdfd(&["sync", "--db", copy, "--adopt", "bench-f2"], None);
        assert_ran(&out);
        assert!(String::from_utf8_lossy(&out.stdout).contains("[station] id = \"bench-f2\""));
        assert_ran(&sync("bench-f2"));
        assert_same(&file_copy, &db.url, "bench-f2").await;
        assert_same(&orig, &db.url, "bench-f").await;
    })
    .await;
}

/// Central rows of `station`, over every forwarded table.
async fn central_rows(url: &str, station: &str) -> usize {
    central_tables(url, station)
        .await
        .values()
        .map(Vec::len)
        .sum()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bench_moved_to_a_new_pc_takes_its_station_id_over_by_retiring_the_old_store() {
    let _serial = serial();
    let db = TestDb::create("retire");
    bounded(async {
        // The store is copied to the bench's new PC, but the old PC goes on for a while. The
        // new PC measures under the station id: refused, and told both ways out.
        let CopiedStation {
            dir: _dir,
            orig: old,
            copy: new,
            store,
            service,
            refusal: e,
        } = copied_station("bench-r", &db.url, samples(3)[2]).await;
        assert!(e.contains("--retire-old ARCHIVE_ID"), "{e}");

        let retire =
            |archive: &str| brdfd_sync(&new, &db.url, "bench-r", &["--retire-old", archive]);
        // Retiring reads no clock: it goes through at once, even though the old PC still
        // runs, keeps the old store's rows as the archive and gives the station id to the new
        // PC's store, which sends all it holds. When the old store last forwarded is told.
        let out = retire("bench-r-old-pc");
        assert_ran(&out);
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            stdout.contains("are now station bench-r-old-pc"),
            "{stdout}"
        );
        assert!(
            stdout.contains("the old store last forwarded")
                && stdout.contains("refused from its next forward on"),
            "{stdout}"
        );
        assert_same(&new, &db.url, "bench-r").await;
        assert_same(&old, &db.url, "bench-r-old-pc").await;
        let pool = sqlx::PgPool::connect(&db.url).await.unwrap();
        let from: Option<String> = sqlx::query_scalar(
            "SELECT retired_from FROM stations WHERE station = 'bench-r-old-pc'",
        )
        .fetch_one(&pool)
        .await
        .unwrap();
        assert_eq!(from.as_deref(), Some("bench-r"));
        pool.close().await;
        // The old PC, still running, scans again: refused from that forward on, and its new
        // scan is mixed in nowhere.
        let archived = central_rows(&db.url, "bench-r-old-pc").await;
        scan_and_settle(&service, samples(4)[3]).await;
        refused(&service).await;
        stop_station(&store, &service).await;
        assert_eq!(central_rows(&db.url, "bench-r-old-pc").await, archived);
        assert_same(&new, &db.url, "bench-r").await;
        // Retiring again to the same archive id is refused: it is taken.
        let out = retire("bench-r-old-pc");
        assert_eq!(out.status.code(), Some(6));
        assert!(String::from_utf8_lossy(&out.stderr).contains("already in use"));
        assert_same(&new, &db.url, "bench-r").await;

        // The new PC's daemon goes on as the station.
        let (ns, nsvc) = station_on_scanned(&new, "bench-r", &db.url, samples(4)[3]).await;
        drained_service(&nsvc, &new).await;
        assert_same(&new, &db.url, "bench-r").await;

        // The old PC, started again, is refused, and nothing of it is mixed in anywhere.
        let archived = central_rows(&db.url, "bench-r-old-pc").await;
        let (os, osvc) = station_on_scanned(&old, "bench-r", &db.url, samples(1)[0]).await;
        refused(&osvc).await;
        stop_station(&os, &osvc).await;
        stop_station(&ns, &nsvc).await;
        assert_same(&new, &db.url, "bench-r").await;
        assert_eq!(central_rows(&db.url, "bench-r-old-pc").await, archived);
        // Nothing forwards under the archive id.
        let out = brdfd_sync(&old, &db.url, "bench-r-old-pc", &["--once"]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(6), "{err}");
        assert!(
            err.contains("is the archive of station \"bench-r\""),
            "{err}"
        );
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_central_database_restored_from_a_backup_is_caught_up() {
    let _serial = serial();
    let db = TestDb::create("restore");
    bounded(async {
        let d = station("bench-b", &db.url, 20).await;
        measure(&d, 1).await;
        drained(&d).await;
        let dump = d.dir.path().join("central.dump");
        db.dump(&dump);
        // Two more scans, forwarded and deleted from the station's outbox.
        for s in &samples(3)[1..] {
            scan_and_settle(&d.service, s).await;
        }
        drained(&d).await;
        // The lab restores yesterday's backup: the two scans are gone centrally.
        db.restore(&dump);
        // The idle daemon notices, compares and re-sends them.
        wait_for("the comparison after the restore", STEP_TIMEOUT, || async {
            let s = d.service.status().await.unwrap().sync.unwrap();
            s.last_verify.is_some_and(|v| !v.contains(" 0 re-sent"))
        })
        .await;
        drained(&d).await;
        d.service.stop_keeping_store().await;
        assert_same(&d.db, &db.url, "bench-b").await;
        // A second comparison finds everything in place and sends nothing.
        let out = brdfd_sync(&d.db, &db.url, "bench-b", &["--verify", "--once", "--json"]);
        assert_ran(&out);
        let lines = ndjson(&out);
        let verify = lines
            .iter()
            .find(|l| l["type"] == "verify")
            .expect("a verify line");
        for t in verify["tables"].as_array().unwrap() {
            assert_eq!(t["resent"], 0, "{t}");
            assert_eq!(t["extra"], 0, "{t}");
            assert_eq!(t["local"], t["central"], "{t}");
        }
        d.store.close().await;
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn brdfd_sync_keeps_forwarding_through_outages_and_resumes_at_once() {
    let _serial = serial();
    let cluster = Cluster::start();
    let db = TestDb::create_on(&cluster.admin_url(), "resume");
    bounded(async {
        // A stopped station's store with everything still to send.
        let d = station("bench-s", "postgres://postgres@127.0.0.1:1/none", 50).await;
        measure(&d, 2).await;
        d.service.stop_keeping_store().await;
        d.store.close().await;
        let highest = highest_seq(&d.db).await;
        let config = d.dir.path().join("brdfd.toml");
        std::fs::write(
            &config,
            "[devices.ma_t12]\ntransport = \"simulated\"\n\
             [devices.sra]\ntransport = \"simulated\"\n[sync]\nbatch = 1\n",
        )
        .unwrap();
        // `brdfd sync` (continuous) started while the server is down.
        cluster.stop_immediate();
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_brdfd"))
            .args(["sync", "--config", config.to_str().unwrap(), "--db"])
            .arg(&d.db)
            .args(["--to", &db.url, "--station", "bench-s"])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        // Long enough for the back-off to grow past several seconds.
        tokio::time::sleep(Duration::from_secs(8)).await;
        assert!(child.try_wait().unwrap().is_none(), "brdfd sync gave up");
        let cursor = |url: String| async move {
            let Ok(pool) = sqlx::PgPool::connect(&url).await else {
                return -1;
            };
            let c: Option<i64> =
                sqlx::query_scalar("SELECT cursor FROM stations WHERE station = 'bench-s'")
                    .fetch_optional(&pool)
                    .await
                    .ok()
                    .flatten();
            pool.close().await;
            c.unwrap_or(0)
        };
        let back = std::time::Instant::now();
        cluster.restart();
        wait_for("the first batch after the restart", STEP_TIMEOUT, || {
            let url = db.url.clone();
            async move { cursor(url).await > 0 }
        })
        .await;
        let resumed = back.elapsed();
        assert!(
            resumed < Duration::from_millis(2500),
            "resumed after {resumed:?}"
        );
        // Killed again (while catching up, or just after): it goes on once the server is
        // back.
        cluster.stop_immediate();
        tokio::time::sleep(Duration::from_secs(2)).await;
        assert!(
            child.try_wait().unwrap().is_none(),
            "brdfd sync gave up while catching up"
        );
        cluster.restart();
        wait_for("everything forwarded", STEP_TIMEOUT, || {
            let url = db.url.clone();
            async move { cursor(url).await == highest }
        })
        .await;
        child.kill().unwrap();
        child.wait().unwrap();
        assert_same(&d.db, &db.url, "bench-s").await;
    })
    .await;
}

/// A decoded value of a values view: row id, band key, wavelength and the value's bits.
type ValueRow = (i64, i64, Option<i64>, Option<u64>);

/// The rows of a values view as [`ValueRow`]s; `T` is the integer type of the database's
/// band and wavelength columns (64-bit in the station's SQLite, 32-bit in PostgreSQL).
fn value_rows<T: Into<i64>>(
    rows: Result<Vec<(i64, T, Option<T>, Option<f64>)>, sqlx::Error>,
) -> Vec<ValueRow> {
    rows.unwrap()
        .into_iter()
        .map(|(id, k, nm, v)| (id, k.into(), nm.map(Into::into), v.map(f64::to_bits)))
        .collect()
}

/// The station's finished fits: id, cost function and the three parameters.
const LOCAL_FITS: &str = "
    SELECT id, cost_function, json_extract(params_json, '$.ks'),
           json_extract(params_json, '$.alpha'), json_extract(params_json, '$.ior')
    FROM fit_runs WHERE status = 'done' ORDER BY id";

/// [`LOCAL_FITS`] from the central `fit_results` view, for the station bound as `$1`.
const CENTRAL_FITS: &str = "
    SELECT fit_run_id, cost_function, ks, alpha, mu FROM fit_results
    WHERE station = $1 AND simulated AND measured_at > now() - interval '1 hour'
      AND de00_mean IS NOT NULL
    ORDER BY fit_run_id";

/// Fit rows from [`LOCAL_FITS`] or [`CENTRAL_FITS`], the parameters bit for bit.
fn fit_rows(
    rows: Result<Vec<(i64, String, f64, f64, f64)>, sqlx::Error>,
) -> Vec<(i64, String, u64, u64, u64)> {
    rows.unwrap()
        .into_iter()
        .map(|(id, cost, ks, alpha, third)| {
            (id, cost, ks.to_bits(), alpha.to_bits(), third.to_bits())
        })
        .collect()
}

/// The pooled query of GUIDE.md "The central database with SQL".
const POOLED_QUERY: &str = "
    SELECT lab_sample, cost_function, COUNT(DISTINCT station) AS stations, COUNT(*) AS fits,
           avg(ks) AS ks, avg(alpha) AS alpha, avg(mu) AS mu,
           avg(de00_diffuse_mean) AS de00_diffuse
    FROM fit_results
    WHERE lab_sample IS NOT NULL
    GROUP BY lab_sample, cost_function
    ORDER BY lab_sample, cost_function";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_central_views_decode_as_the_stations_and_pool_across_stations() {
    let _serial = serial();
    let db = TestDb::create("views");
    bounded(async {
        let names = ["bench-v1", "bench-v2"];
        let mut stations = Vec::new();
        for n in names {
            let d = station(n, &db.url, 100).await;
            measure(&d, 1).await;
            drained(&d).await;
            d.service.stop_keeping_store().await;
            stations.push(d);
        }
        let pg = sqlx::PgPool::connect(&db.url).await.unwrap();
        for (d, n) in stations.iter().zip(names) {
            let local = pg::read_only_store(&d.db).await;
            // Every decoded value, bit for bit, station view vs central view.
            for (view, id) in [
                ("reading_values", "reading_id"),
                ("reference_reading_values", "reading_id"),
                ("processed_values", "processed_id"),
            ] {
                let band = if view == "processed_values" {
                    "geometry_index * 31 + band"
                } else {
                    "band"
                };
                let sql = |station: bool| {
                    format!(
                        "SELECT {id}, {band} AS k, nm, value FROM {view} {} ORDER BY {id}, k",
                        if station { "WHERE station = $1" } else { "" }
                    )
                };
                let a = value_rows::<i64>(sqlx::query_as(&sql(false)).fetch_all(&local).await);
                let b = value_rows::<i32>(sqlx::query_as(&sql(true)).bind(n).fetch_all(&pg).await);
                assert!(!a.is_empty(), "{view}");
                assert_eq!(a, b, "{n}: {view}, station vs central");
            }
            // fit_results: one row per finished fit, parameters as the station's JSON says.
            let local_fits = fit_rows(sqlx::query_as(LOCAL_FITS).fetch_all(&local).await);
            let central_fits = fit_rows(sqlx::query_as(CENTRAL_FITS).bind(n).fetch_all(&pg).await);
            assert!(!local_fits.is_empty());
            assert_eq!(local_fits, central_fits, "{n}: fit_results");
            // fit_configuration: each fit's model, Fresnel factor and SRA model as its
            // settings say (these stations fit under the paper's Fresnel and SRA model).
            let local_config: Vec<(i64, String, String, String)> = sqlx::query_as(
                "SELECT id, COALESCE(json_extract(settings_json, '$.model'), 'paper'),
                        json_extract(settings_json, '$.fresnel'), sra
                 FROM fit_runs ORDER BY id",
            )
            .fetch_all(&local)
            .await
            .unwrap();
            let central_config: Vec<(i64, String, String, String, String)> = sqlx::query_as(
                "SELECT fit_run_id, model, fresnel, sra, preset FROM fit_configuration
                 WHERE station = $1 ORDER BY fit_run_id",
            )
            .bind(n)
            .fetch_all(&pg)
            .await
            .unwrap();
            assert_eq!(
                local_config,
                central_config
                    .iter()
                    .map(|(id, m, f, s, _)| (*id, m.clone(), f.clone(), s.clone()))
                    .collect::<Vec<_>>(),
                "{n}: fit_configuration"
            );
            assert!(
                central_config
                    .iter()
                    .all(|c| (c.2.as_str(), c.3.as_str(), c.4.as_str())
                        == ("incidence", "flat", "paper")),
                "{central_config:?}"
            );
            // And the paper's weights of the SRA readings (settings without a weight).
            let weights: Vec<String> = sqlx::query_scalar(
                "SELECT DISTINCT sra_weight FROM fit_configuration WHERE station = $1",
            )
            .bind(n)
            .fetch_all(&pg)
            .await
            .unwrap();
            assert_eq!(weights, ["paper"], "{n}: fit_configuration.sra_weight");
            let kd: i64 = sqlx::query_scalar(
                "SELECT COUNT(kd) FROM kd_values WHERE station = $1 AND kd >= 0",
            )
            .bind(n)
            .fetch_one(&pg)
            .await
            .unwrap();
            assert_eq!(kd, 31 * local_fits.len() as i64, "{n}: kd_values");
            local.close().await;
        }
        // The lab says the two stations' first samples are the same tile; GUIDE.md's query
        // pools them.
        sqlx::query("INSERT INTO lab_samples (lab_sample) VALUES ('L-0001')")
            .execute(&pg)
            .await
            .unwrap();
        sqlx::query(
            "INSERT INTO sample_identities (station, sample_id, lab_sample)
             SELECT station, id, 'L-0001' FROM samples",
        )
        .execute(&pg)
        .await
        .unwrap();
        let pooled = sqlx::query(POOLED_QUERY).fetch_all(&pg).await.unwrap();
        assert!(!pooled.is_empty());
        for r in &pooled {
            assert_eq!(r.get::<String, _>("lab_sample"), "L-0001");
            assert_eq!(r.get::<i64, _>("stations"), 2, "pooled over both stations");
            assert!(r.get::<f64, _>("ks").is_finite());
        }
        pg.close().await;
        for d in &stations {
            d.store.close().await;
        }
    })
    .await;
}

/// A station's store at `db` with a reference and a settled scan of the first sample, forwarded
/// by nothing yet (the daemon ran without `[sync]`); returns the reference.
async fn store_with_a_scan(db: &Path) -> brdfd::store::ReferenceId {
    let (store, service) = service_on(db, settings()).await;
    let reference = measure_reference(&service).await;
    scan_and_settle(&service, samples(1)[0]).await;
    stop_station(&store, &service).await;
    reference
}

/// What a lab does between two runs of `brdfd sync --once`: opens the store (a new incarnation
/// of it, as `brdfd demo` or a restarted daemon does) and asks for a scan of `sample`.
async fn scan_requested(db: &Path, reference: brdfd::store::ReferenceId, sample: &str) {
    let store = Store::open(db).await.unwrap();
    store.request_scan(sample, reference).await.unwrap();
    store.close().await;
}

/// The stations row's cursor, horizon and chain head.
async fn station_row(url: &str, station: &str) -> (i64, i64, Option<String>) {
    let pool = sqlx::PgPool::connect(url).await.unwrap();
    let row: (i64, i64, Option<String>) =
        sqlx::query_as("SELECT cursor, horizon, head FROM stations WHERE station = $1")
            .bind(station)
            .fetch_one(&pool)
            .await
            .unwrap();
    pool.close().await;
    row
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn brdfd_sync_once_at_any_pace_is_accepted_and_an_upgraded_station_resends_nothing() {
    let _serial = serial();
    let db = TestDb::create("pace");
    bounded(async {
        let dir = tempfile::tempdir().unwrap();
        let store = dir.path().join("brdfd.db");
        let reference = store_with_a_scan(&store).await;
        let once = || brdfd_sync(&store, &db.url, "bench-p", &["--once", "--json"]);
        // Twice straight after each other (in the same second on an idle machine; no clock
        // decides): the second run finds nothing to send, and is accepted.
        assert_ran(&once());
        let out = once();
        assert_ran(&out);
        assert_eq!(ndjson(&out).last().unwrap()["rows"], 0, "{out:?}");
        // Twenty rounds of a scan, then two runs straight after: every one accepted, and the
        // central database holds the store row for row each time.
        let names = samples(3);
        for round in 0..20 {
            scan_requested(&store, reference, names[round % names.len()]).await;
            assert_ran(&once());
            assert_ran(&once());
        }
        assert_same(&store, &db.url, "bench-p").await;

        // A central database last written by a brdfd before the chain (central step 0010 adds
        // `head` as NULL): the station's next run is checked by its incarnation, sends only
        // what is new, and records the head.
        let (cursor, _, head) = station_row(&db.url, "bench-p").await;
        assert_eq!(head.as_deref().map(str::len), Some(64));
        let pool = sqlx::PgPool::connect(&db.url).await.unwrap();
        sqlx::query("UPDATE stations SET head = NULL WHERE station = 'bench-p'")
            .execute(&pool)
            .await
            .unwrap();
        pool.close().await;
        scan_requested(&store, reference, names[0]).await;
        let out = once();
        assert_ran(&out);
        let entries: i64 = ndjson(&out)
            .iter()
            .filter(|l| l["type"] == "batch")
            .map(|l| l["entries"].as_i64().unwrap())
            .sum();
        let high = highest_seq(&store).await;
        assert_eq!(
            entries,
            high - cursor,
            "only the entries after the cursor: {out:?}"
        );
        assert!(
            entries < cursor,
            "no full resend: {entries} entries of {high}"
        );
        let (cursor, horizon, head) = station_row(&db.url, "bench-p").await;
        assert_eq!((cursor, horizon), (high, high));
        assert!(head.is_some(), "the head is recorded");
        assert_same(&store, &db.url, "bench-p").await;
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_copy_synced_alternately_with_its_original_is_refused_and_the_original_never() {
    let _serial = serial();
    let db = TestDb::create("alternate");
    bounded(async {
        let dir = tempfile::tempdir().unwrap();
        let orig = dir.path().join("orig.db");
        let copy = dir.path().join("copy.db");
        let reference = store_with_a_scan(&orig).await;
        let once = |file: &Path| brdfd_sync(file, &db.url, "bench-a", &["--once"]);
        assert_ran(&once(&orig));
        std::fs::copy(&orig, &copy).unwrap();
        // An exact copy that has not gone its own way is the same history: accepted, and it
        // has nothing to send.
        assert_ran(&once(&copy));
        let names = samples(3);
        for round in 0..3 {
            // The original scans and syncs: accepted, every time.
            scan_requested(&orig, reference, names[round]).await;
            assert_ran(&once(&orig));
            // The copy scans and syncs: refused, with both ways out, every time.
            scan_requested(&copy, reference, names[(round + 1) % 3]).await;
            let out = once(&copy);
            let err = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(6), "{err}");
            assert!(
                err.contains("--adopt NEW_ID") && err.contains("--retire-old ARCHIVE_ID"),
                "{err}"
            );
            assert!(
                err.contains("is not this store's") || err.contains("older copy"),
                "{err}"
            );
            assert_same(&orig, &db.url, "bench-a").await;
        }
    })
    .await;
}

/// Outbox entries the store at `db` still holds (the daemon deletes what was acknowledged).
async fn outbox_len(db: &Path) -> i64 {
    let pool = pg::read_only_store(db).await;
    let n = sqlx::query_scalar("SELECT COUNT(*) FROM sync_outbox")
        .fetch_one(&pool)
        .await
        .unwrap();
    pool.close().await;
    n
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_central_database_restored_steps_back_is_caught_up_by_sync_once_and_by_the_daemon() {
    let _serial = serial();
    let db = TestDb::create("rollback");
    bounded(async {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("brdfd.db");
        let settings = || station_settings("bench-k", &db.url, 20);
        let (store, service) = service_on(&file, settings()).await;
        let reference = measure_reference(&service).await;
        scan_and_settle(&service, samples(1)[0]).await;
        drained_service(&service, &file).await;
        // Six steps, each a scan asked for, forwarded by the daemon and deleted from the
        // store's outbox; the central database is dumped after each.
        let mut dumps = Vec::new();
        for (i, name) in samples(3).iter().cycle().take(6).enumerate() {
            store.request_scan(name, reference).await.unwrap();
            drained_service(&service, &file).await;
            let dump = dir.path().join(format!("step-{i}.dump"));
            db.dump(&dump);
            dumps.push(dump);
        }
        stop_station(&store, &service).await;
        assert_eq!(outbox_len(&file).await, 0, "the daemon pruned its outbox");
        assert_same(&file, &db.url, "bench-k").await;

        for back in [1, 2, 5] {
            let dump = &dumps[dumps.len() - 1 - back];
            // Restored, then the station's one-shot sync: it finds the central database
            // behind what its outbox no longer holds and sends again from its tables.
            db.restore(dump);
            let extra: &[&str] = if back == 5 {
                &["--once", "--verify", "--json"]
            } else {
                &["--once", "--json"]
            };
            let out = brdfd_sync(&file, &db.url, "bench-k", extra);
            assert_ran(&out);
            // Asked for (--verify) or run by itself (the central database was behind what the
            // outbox had pruned), the comparison is printed with what it re-sent.
            let lines = ndjson(&out);
            let verify = lines.iter().find(|l| l["type"] == "verify").unwrap();
            let resent: u64 = verify["tables"]
                .as_array()
                .unwrap()
                .iter()
                .map(|t| t["resent"].as_u64().unwrap())
                .sum();
            assert!(resent > 0, "the one-shot says what it repaired: {verify}");
            if back != 5 {
                assert_eq!(verify["automatic"], true, "{verify}");
            }
            assert_same(&file, &db.url, "bench-k").await;
            let (cursor, horizon, _) = station_row(&db.url, "bench-k").await;
            assert_eq!((cursor, horizon), (highest_seq(&file).await, cursor));

            // Restored again, then the daemon: the same, by itself.
            db.restore(dump);
            let (store, service) = service_on(&file, settings()).await;
            wait_for("the daemon's comparison", STEP_TIMEOUT, || async {
                let s = service.status().await.unwrap().sync.unwrap();
                s.last_verify.is_some_and(|v| !v.contains(" 0 re-sent"))
            })
            .await;
            drained_service(&service, &file).await;
            stop_station(&store, &service).await;
            assert_same(&file, &db.url, "bench-k").await;
        }
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_copy_of_a_running_station_is_refused_even_when_it_forwards_first() {
    let _serial = serial();
    let db = TestDb::create("livecopy");
    bounded(async {
        let dir = tempfile::tempdir().unwrap();
        let orig = dir.path().join("orig.db");
        let copy = dir.path().join("copy.db");
        let (store, service) = station_on_scanned(&orig, "bench-l", &db.url, samples(1)[0]).await;
        drained_service(&service, &orig).await;
        // A backup tool copies the running station's store while the central database holds
        // all of it; the copy starts and measures before the original writes anything more:
        // refused all the same, with both ways out.
        vacuum_into(&orig, &copy).await;
        let (cs, csvc) = station_on_scanned(&copy, "bench-l", &db.url, samples(2)[1]).await;
        let e = refused(&csvc).await;
        assert!(e.contains("taken at outbox entry"), "{e}");
        assert!(
            e.contains("--adopt NEW_ID") && e.contains("--retire-old"),
            "{e}"
        );
        stop_station(&cs, &csvc).await;
        // The original goes on, accepted, and the central database holds it exactly.
        scan_and_drain(&service, &orig, samples(2)[1]).await;
        stop_station(&store, &service).await;
        assert_same(&orig, &db.url, "bench-l").await;
    })
    .await;
}
