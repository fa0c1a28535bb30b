//! Fault soak of forwarding: several `brdfd serve` stations (real processes, simulated
//! instruments) forward to a PostgreSQL cluster of the test's own while faults are injected
//! one after another — `kill -9` of a station daemon, `pg_ctl stop -m immediate` of the
//! postmaster, the central database restored from an earlier `pg_dump`, and a station's live
//! store copied (`VACUUM INTO`) to a second daemon under the same station id. After each fault
//! the harness waits until every station is idle and checks that the central database equals
//! the union of the stations' stores, row for row and column for column (floats by their bits),
//! that nothing else is in it, and that the copy was refused. It prints the faults survived and
//! the time from the end of each fault to central = union (p50, p99, max; it includes waiting
//! for the stations to come to rest: a scan under way is aborted in most rounds, and let run,
//! fits and all, in the others).
//!
//! Before the first fault the stations measure for a while with nothing going wrong, and the
//! lag from local commit to central commit is read from each station's `status` (the
//! forwarder's figure over the entries it sent) and printed.
//!
//! `fault_soak_reduced` (run with the suite) measures for 10 s and injects each kind of fault
//! once; `fault_soak` (ignored; `cargo test --release --test sync_soak -- --ignored`) measures
//! for `BRDFD_SOAK_LAG_SECONDS` (default 120) and injects `BRDFD_SOAK_FAULTS` (default 100)
//! random ones, seeded by `BRDFD_SOAK_SEED` (default 1).

// `common::serial()` is a process-wide std mutex held for a whole test on purpose: each
// `#[tokio::test]` has its own runtime, so no task of the same runtime waits for it.
#![allow(clippy::await_holding_lock)]

mod common;
#[path = "common/pg.rs"]
mod pg;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};
use serde_json::json;

use common::*;
use pg::{Cluster, TestDb, central_tables, local_tables};

/// One station: its directory (configuration, store, token) and its daemon when running.
struct Station {
    name: String,
    dir: tempfile::TempDir,
    config: PathBuf,
    daemon: Option<ServeChild>,
}

/// The stations fit under the paper's flat SRA model with 20 bootstrap resamples: cf2's
/// full-search bootstrap under the luminance default takes minutes per scan in a debug build,
/// longer than a round may take to converge when a scan is let run to its end; the soak checks
/// forwarding, and 20 resamples make as many rows to forward as 200 (the intervals are
/// forwarded like every other column).
fn sections(name: &str, url: &str) -> String {
    format!(
        "[station]\nid = \"{name}\"\n\n[sync]\nurl = \"{url}\"\nbatch = 20\n\n[fit]\nsra = \"flat\"\nbootstrap = 20\n\n"
    )
}

impl Station {
    fn new(name: &str, url: &str) -> Station {
        let dir = tempfile::tempdir().unwrap();
        let config = write_simulated_config(dir.path(), "", &sections(name, url));
        Station {
            name: name.to_string(),
            dir,
            config,
            daemon: None,
        }
    }

    fn db(&self) -> PathBuf {
        self.dir.path().join("brdfd.db")
    }

    fn start(&mut self) {
        self.daemon = Some(spawn_serve(&self.config, &[]));
    }

    fn client(&self) -> &brdfd::client::Client {
        &self.daemon.as_ref().expect("running").client
    }

    /// `kill -9`.
    fn kill(&mut self) {
        if let Some(mut d) = self.daemon.take() {
            d.child.kill().unwrap();
            d.child.wait().unwrap();
        }
    }

    /// Starts something: a reference when none is in force, else a scan (refusals, such as
    /// busy instruments, are part of the game).
    fn poke(&self, n: usize) {
        let c = self.client();
        let Ok(status) = c.get("/status") else {
            return;
        };
        if !status["busy"].is_null() {
            return;
        }
        if status["reference"].is_null() {
            let _ = c.post("/reference", None);
        } else {
            let _ = c.post("/scans", Some(&json!({ "sample": format!("T.Soak {n}") })));
        }
    }

    fn idle(&self) -> bool {
        let Ok(s) = self.client().get("/status") else {
            return false;
        };
        s["busy"].is_null()
            && s["fits_queued"] == 0
            && s["fits_running"] == 0
            && s["bootstraps_pending"].as_u64().unwrap_or(0) == 0
    }
}

/// Waits until every station is idle and the central database equals the union of their
/// stores; returns how long that took.
async fn converged(stations: &[Station], url: &str, timeout: Duration) -> Duration {
    let t0 = Instant::now();
    loop {
        let mut equal = stations.iter().all(Station::idle);
        if equal {
            for s in stations {
                let local = local_tables(&s.db()).await;
                let Some(central) = try_central(url, &s.name).await else {
                    equal = false;
                    break;
                };
                if local != central {
                    equal = false;
                    break;
                }
            }
        }
        if equal {
            // Nothing of any other store (a refused copy) is in it either.
            let pool = sqlx::PgPool::connect(url).await.unwrap();
            let names: Vec<String> = sqlx::query_scalar(
                "SELECT DISTINCT station FROM readings UNION SELECT DISTINCT station FROM scans",
            )
            .fetch_all(&pool)
            .await
            .unwrap();
            pool.close().await;
            for n in &names {
                assert!(
                    stations.iter().any(|s| &s.name == n),
                    "rows of an unknown station {n} centrally"
                );
            }
            return t0.elapsed();
        }
        assert!(
            t0.elapsed() < timeout,
            "central did not become the union of the stations within {timeout:?}"
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

/// The central tables of `station`, or `None` while the database does not answer.
async fn try_central(url: &str, station: &str) -> Option<pg::Tables> {
    let pool = sqlx::PgPool::connect(url).await.ok()?;
    pool.close().await;
    Some(central_tables(url, station).await)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Fault {
    KillStation,
    KillPostmaster,
    RestoreDump,
    CopyStore,
}

/// A live copy of `station`'s store started as a second daemon under the same id: it must be
/// refused (and it is then killed; nothing of it may reach the central database).
async fn copy_store(station: &Station, url: &str) {
    let dir = tempfile::tempdir().unwrap();
    {
        use sqlx::Connection;
        let mut c = sqlx::SqliteConnection::connect_with(
            &sqlx::sqlite::SqliteConnectOptions::new().filename(station.db()),
        )
        .await
        .unwrap();
        sqlx::query(&format!(
            "VACUUM INTO '{}'",
            dir.path().join("brdfd.db").display()
        ))
        .execute(&mut c)
        .await
        .unwrap();
        c.close().await.unwrap();
    }
    let config = write_simulated_config(dir.path(), "", &sections(&station.name, url));
    let mut copy = spawn_serve(&config, &[]);
    let _ = copy.client.post("/reference", None);
    let deadline = Instant::now() + STEP_TIMEOUT;
    loop {
        let s = copy.client.get("/status").unwrap();
        if s["sync"]["refused"] == true {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "the copy was not refused: {}",
            s["sync"]
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    copy.child.kill().unwrap();
    copy.child.wait().unwrap();
}

/// The stations measuring without faults for `seconds` (a reference, then scans back to back,
/// at the recordings' pace); then each station's lag from local commit to central commit
/// over the entries it forwarded while measuring (`status.sync.lag`), printed per station and
/// for the worst; then they come to rest and central must be their union.
async fn lag_phase(stations: &[Station], url: &str, seconds: u64) {
    let t0 = Instant::now();
    let mut n = 0;
    while t0.elapsed() < Duration::from_secs(seconds) {
        for s in stations {
            n += 1;
            s.poke(n);
        }
        tokio::time::sleep(Duration::from_millis(500)).await;
    }
    // The lag as the stations forwarded while measuring (read before they come to rest: the
    // fits' bootstraps of the scans that finished can take minutes in a debug build).
    let mut worst = (0.0_f64, 0.0_f64, 0.0_f64);
    let mut entries = 0;
    for s in stations {
        let status = s.client().get("/status").unwrap();
        let lag = &status["sync"]["lag"];
        let (p50, p99, max) = (
            lag["p50_ms"]
                .as_f64()
                .expect("a lag once entries were forwarded"),
            lag["p99_ms"].as_f64().unwrap(),
            lag["max_ms"].as_f64().unwrap(),
        );
        entries += lag["entries"].as_u64().unwrap();
        eprintln!(
            "lag {}: local commit → central commit over {} entries: p50 {p50:.0} ms, \
             p99 {p99:.0} ms, max {max:.0} ms",
            s.name, lag["entries"]
        );
        worst = (worst.0.max(p50), worst.1.max(p99), worst.2.max(max));
    }
    eprintln!(
        "lag with {} stations measuring for {seconds} s ({entries} entries): worst station \
         p50 {:.0} ms, p99 {:.0} ms, max {:.0} ms",
        stations.len(),
        worst.0,
        worst.1,
        worst.2
    );
    for s in stations {
        let _ = s.client().post("/abort", None);
    }
    converged(stations, url, Duration::from_secs(900)).await;
}

async fn soak(faults: &[Fault], seed: u64, lag_seconds: u64) {
    let cluster = Cluster::start();
    let db = TestDb::create_on(&cluster.admin_url(), "soak");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut stations: Vec<Station> = (1..=3)
        .map(|i| Station::new(&format!("soak-{i}"), &db.url))
        .collect();
    for s in &mut stations {
        s.start();
    }
    lag_phase(&stations, &db.url, lag_seconds).await;
    let dump = tempfile::NamedTempFile::new().unwrap();
    let mut dumped = false;
    let mut recoveries = Vec::new();
    let mut n = 0;
    for (round, fault) in faults.iter().enumerate() {
        for s in &stations {
            n += 1;
            s.poke(n);
        }
        tokio::time::sleep(Duration::from_millis(rng.random_range(100..1500))).await;
        match fault {
            Fault::KillStation => {
                let i = rng.random_range(0..stations.len());
                stations[i].kill();
                stations[i].start();
            }
            Fault::KillPostmaster => {
                cluster.stop_immediate();
                tokio::time::sleep(Duration::from_millis(rng.random_range(100..2000))).await;
                cluster.restart();
            }
            Fault::RestoreDump => {
                if dumped {
                    db.restore(dump.path());
                } else {
                    db.dump(dump.path());
                    dumped = true;
                }
            }
            Fault::CopyStore => {
                let i = rng.random_range(0..stations.len());
                copy_store(&stations[i], &db.url).await;
            }
        }
        // Scans at the recordings' pace take a minute: the one under way is aborted (its
        // readings so far are kept and forwarded), so that the stores come to rest quickly;
        // every few rounds one is let run to its end, fits and all.
        if rng.random_bool(0.8) {
            for s in &stations {
                if let Some(d) = &s.daemon {
                    let _ = d.client.post("/abort", None);
                }
            }
        }
        let took = converged(&stations, &db.url, Duration::from_secs(180)).await;
        recoveries.push(took);
        eprintln!(
            "fault {} ({fault:?}) survived; central = union after {took:?}",
            round + 1
        );
        // A newer dump now and then, for the next restore.
        if dumped && rng.random_bool(0.3) {
            db.dump(dump.path());
        }
    }
    recoveries.sort();
    let q = |p: f64| recoveries[((recoveries.len() - 1) as f64 * p).round() as usize];
    let rows: usize = {
        let mut total = 0;
        for s in &stations {
            total += local_tables(&s.db())
                .await
                .values()
                .map(Vec::len)
                .sum::<usize>();
        }
        total
    };
    eprintln!(
        "soak: {} faults survived, 0 rows lost, doubled or mixed ({rows} rows compared); \
         fault end → central = union p50 {:?}, p99 {:?}, max {:?}",
        faults.len(),
        q(0.5),
        q(0.99),
        recoveries.last().unwrap()
    );
    for s in &mut stations {
        s.kill();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fault_soak_reduced() {
    let _serial = serial();
    soak(
        &[
            Fault::RestoreDump, // takes the dump
            Fault::KillStation,
            Fault::KillPostmaster,
            Fault::CopyStore,
            Fault::RestoreDump,
        ],
        1,
        10,
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "long: cargo test --release --test sync_soak -- --ignored"]
async fn fault_soak() {
    let _serial = serial();
    let n: usize = std::env::var("BRDFD_SOAK_FAULTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(100);
    let seed: u64 = std::env::var("BRDFD_SOAK_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x5eed);
    let kinds = [
        Fault::KillStation,
        Fault::KillPostmaster,
        Fault::RestoreDump,
        Fault::CopyStore,
    ];
    let faults: Vec<Fault> = (0..n)
        .map(|_| kinds[rng.random_range(0..kinds.len())])
        .collect();
    let lag_seconds: u64 = std::env::var("BRDFD_SOAK_LAG_SECONDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(120);
    soak(&faults, seed, lag_seconds).await;
}
