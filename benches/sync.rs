//! Forwarding to the central PostgreSQL database, and reporting from it.
//!
//! 1. Live: 8 stations, each a store file running `brdfd demo` (the committed recordings
//!    replayed through the whole daemon, 8 scans × 3 fits) with its forwarder running
//!    alongside, all at once. Prints rows/s into PostgreSQL over the run and the lag from each
//!    outbox entry's local commit to the central commit of its batch (p50, p99, max).
//! 2. Catch-up: the same 8 stores forwarded again from scratch into a second database, all at
//!    once (a lab coming back from an outage): rows/s.
//! 3. Report: the 8 stations' scans cloned in SQL up to 10,000 scans (1,250 stations of 8),
//!    then the study loaded from the central database (`brdfd report --db postgres://…`'s
//!    loader) and the whole report written; times both.
//!
//! `cargo bench --bench sync` (release profile). The server is `BRDFD_BENCH_POSTGRES` (an admin
//! URL; default `postgres://postgres@127.0.0.1:5432/postgres`); the bench creates its databases
//! and drops them. `BRDFD_BENCH_SCANS` changes the 10,000.

#[path = "../tests/common/pg.rs"]
mod pg;

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use brdfd::cli::demo::{DemoArgs, run_demo};
use brdfd::optimise::{Method, Settings};
use brdfd::report::load::from_central;
use brdfd::store::Store;
use brdfd::store::central::CentralSelection;
use brdfd::sync::tables::TABLES;
use brdfd::sync::{BatchReport, Central, Forwarder, ForwarderOptions};
use pg::highest_seq;

const STATIONS: usize = 8;

fn admin() -> String {
    std::env::var("BRDFD_BENCH_POSTGRES")
        .unwrap_or_else(|_| "postgres://postgres@127.0.0.1:5432/postgres".into())
}

fn with_database(url: &str, db: &str) -> String {
    let scheme_end = url.find("://").map_or(0, |i| i + 3);
    match url[scheme_end..].find('/') {
        Some(i) => format!("{}/{db}", &url[..scheme_end + i]),
        None => format!("{url}/{db}"),
    }
}

async fn admin_exec(sql: &str) {
    use sqlx::Connection;
    let mut c = sqlx::PgConnection::connect(&admin())
        .await
        .unwrap_or_else(|e| {
            panic!(
                "the benchmark's PostgreSQL server does not answer ({e}); set BRDFD_BENCH_POSTGRES"
            )
        });
    sqlx::query(sql).execute(&mut c).await.unwrap();
    c.close().await.unwrap();
}

fn percentile(sorted: &[i64], p: f64) -> i64 {
    if sorted.is_empty() {
        return 0;
    }
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i]
}

#[derive(Default)]
struct Collected {
    rows: usize,
    lags: Vec<i64>,
    last_commit: Option<Instant>,
}

/// Runs one forwarder per store (`stores[i]`, its file `paths[i]`) until `until_done` is true
/// and the central database has acknowledged everything the store queued.
async fn forward_all(
    stores: &[Store],
    paths: &[std::path::PathBuf],
    url: &str,
    collected: Arc<Mutex<Collected>>,
    until_done: tokio::sync::watch::Receiver<bool>,
) -> Vec<tokio::task::JoinHandle<()>> {
    let mut tasks = Vec::new();
    for (i, store) in stores.iter().enumerate() {
        let f = Forwarder::for_store(store, ForwarderOptions::new(format!("bench-{i}"), url))
            .await
            .unwrap();
        let status = f.status();
        let c = collected.clone();
        let mut done = until_done.clone();
        let path = paths[i].clone();
        tasks.push(tokio::spawn(async move {
            let stop = async move {
                // Stop once the producers are done and this store's outbox is all sent.
                loop {
                    let finished = *done.borrow();
                    if finished {
                        let cursor = status.lock().unwrap().cursor;
                        if cursor == Some(highest_seq(&path).await) {
                            break;
                        }
                    }
                    tokio::select! {
                        _ = done.changed() => {}
                        _ = tokio::time::sleep(Duration::from_millis(20)) => {}
                    }
                }
            };
            let mut on_batch = |r: &BatchReport| {
                let mut c = c.lock().unwrap();
                c.rows += r.total_rows();
                c.lags.extend_from_slice(&r.lags_ms);
                c.last_commit = Some(Instant::now());
            };
            f.run(stop, &mut on_batch).await;
        }));
    }
    tasks
}

async fn count_rows(url: &str) -> i64 {
    let pool = sqlx::PgPool::connect(url).await.unwrap();
    let mut n = 0;
    for t in &TABLES {
        let c: i64 = sqlx::query_scalar(&format!("SELECT COUNT(*) FROM {}", t.name))
            .fetch_one(&pool)
            .await
            .unwrap();
        n += c;
    }
    pool.close().await;
    n
}

fn main() {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let tag = std::process::id();
    let live_db = format!("brdfd_bench_live_{tag}");
    let catchup_db = format!("brdfd_bench_catchup_{tag}");
    rt.block_on(async {
        admin_exec(&format!("CREATE DATABASE {live_db}")).await;
        admin_exec(&format!("CREATE DATABASE {catchup_db}")).await;
    });
    let live_url = with_database(&admin(), &live_db);
    let catchup_url = with_database(&admin(), &catchup_db);
    let dirs: Vec<tempfile::TempDir> = (0..STATIONS)
        .map(|_| tempfile::tempdir().unwrap())
        .collect();

    // 1. Live.
    let (stores, live_rows, live_secs, lags) = rt.block_on(async {
        Central::connect_and_migrate(&live_url)
            .await
            .unwrap()
            .close()
            .await;
        let mut stores = Vec::new();
        for d in &dirs {
            stores.push(Store::open(d.path().join("brdfd.db")).await.unwrap());
        }
        let collected = Arc::new(Mutex::new(Collected::default()));
        let (done_tx, done_rx) = tokio::sync::watch::channel(false);
        let started = Instant::now();
        let paths: Vec<_> = dirs.iter().map(|d| d.path().join("brdfd.db")).collect();
        let forwarders = forward_all(&stores, &paths, &live_url, collected.clone(), done_rx).await;
        let mut demos = Vec::new();
        for (store, d) in stores.iter().zip(&dirs) {
            let store = store.clone();
            let args = DemoArgs {
                dir: d.path().to_path_buf(),
                method: Method::default(),
                seed: Settings::default().seed,
                jobs: Some(1),
                bootstrap: 0,
                json: false,
            };
            demos.push(tokio::spawn(async move {
                run_demo(&store, &args).await.unwrap();
            }));
        }
        for d in demos {
            d.await.unwrap();
        }
        let produced = started.elapsed().as_secs_f64();
        done_tx.send(true).unwrap();
        for f in forwarders {
            f.await.unwrap();
        }
        let c = collected.lock().unwrap();
        let secs = c.last_commit.unwrap().duration_since(started).as_secs_f64();
        println!(
            "live: {STATIONS} stations running the demo ({produced:.2} s until the last fit) \
             while forwarding"
        );
        let mut lags = c.lags.clone();
        lags.sort_unstable();
        (stores, c.rows, secs, lags)
    });
    // Rows sent count every update (a fit sent queued, running, done); the tables hold each once.
    let central_rows = rt.block_on(count_rows(&live_url));
    println!(
        "live: {live_rows} rows forwarded ({central_rows} rows in the central tables) in \
         {live_secs:.2} s = {:.0} rows/s; lag local commit → central commit over {} outbox \
         entries: p50 {} ms, p99 {} ms, max {} ms",
        live_rows as f64 / live_secs,
        lags.len(),
        percentile(&lags, 0.50),
        percentile(&lags, 0.99),
        lags.last().copied().unwrap_or(0)
    );

    // 2. Catch-up: the full stores again, into an empty database, all at once. The daemon
    //    forwarders pruned their outboxes, so the stores are re-queued through a fresh copy.
    let (catchup_rows, catchup_secs) = rt.block_on(async {
        Central::connect_and_migrate(&catchup_url)
            .await
            .unwrap()
            .close()
            .await;
        // Copies of the stores with a full outbox, as the migration's backfill queues an old
        // store's rows.
        let mut copies = Vec::new();
        let mut paths = Vec::new();
        let copy_dirs: Vec<tempfile::TempDir> = (0..STATIONS)
            .map(|_| tempfile::tempdir().unwrap())
            .collect();
        for (d, c) in dirs.iter().zip(&copy_dirs) {
            let path = c.path().join("brdfd.db");
            let src = sqlx::SqlitePool::connect_with(
                sqlx::sqlite::SqliteConnectOptions::new().filename(d.path().join("brdfd.db")),
            )
            .await
            .unwrap();
            sqlx::query(&format!("VACUUM INTO '{}'", path.display()))
                .execute(&src)
                .await
                .unwrap();
            src.close().await;
            requeue_everything(&path).await;
            copies.push(Store::open(&path).await.unwrap());
            paths.push(path);
        }
        let collected = Arc::new(Mutex::new(Collected::default()));
        let (done_tx, done_rx) = tokio::sync::watch::channel(true);
        let started = Instant::now();
        let forwarders =
            forward_all(&copies, &paths, &catchup_url, collected.clone(), done_rx).await;
        for f in forwarders {
            f.await.unwrap();
        }
        drop(done_tx);
        let secs = started.elapsed().as_secs_f64();
        let rows = collected.lock().unwrap().rows;
        for c in copies {
            c.close().await;
        }
        drop(copy_dirs);
        (rows, secs)
    });
    println!(
        "catch-up: {STATIONS} stores forwarded from scratch at once: {catchup_rows} rows in \
         {catchup_secs:.2} s = {:.0} rows/s",
        catchup_rows as f64 / catchup_secs
    );

    // 3. Report on 10,000 scans.
    let scans: usize = std::env::var("BRDFD_BENCH_SCANS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(10_000);
    rt.block_on(async {
        let pool = sqlx::PgPool::connect(&live_url).await.unwrap();
        let per_station: i64 = sqlx::query_scalar(
            "SELECT COUNT(*) FROM scans WHERE station = 'bench-0' AND state = 'complete'",
        )
        .fetch_one(&pool)
        .await
        .unwrap();
        let copies = (scans as i64 + per_station - 1) / per_station;
        let t = Instant::now();
        clone_station(&pool, "bench-0", copies).await;
        let total: i64 = sqlx::query_scalar(
            "SELECT COUNT(*) FROM scans WHERE state = 'complete' AND station LIKE 'clone-%'",
        )
        .fetch_one(&pool)
        .await
        .unwrap();
        println!(
            "report: {total} complete scans in {copies} cloned stations (SQL, {:.1} s)",
            t.elapsed().as_secs_f64()
        );
        sqlx::query("ANALYZE").execute(&pool).await.unwrap();
        // Only the clones: exactly `total` scans.
        sqlx::query("DELETE FROM evaluations WHERE station LIKE 'bench-%'")
            .execute(&pool)
            .await
            .unwrap();
        for t in TABLES.iter().rev() {
            if t.name != "evaluations" {
                sqlx::query(&format!(
                    "DELETE FROM {} WHERE station LIKE 'bench-%'",
                    t.name
                ))
                .execute(&pool)
                .await
                .unwrap();
            }
        }
        let t = Instant::now();
        let study = from_central(&pool, &CentralSelection::default())
            .await
            .unwrap();
        let load = t.elapsed().as_secs_f64();
        let out = tempfile::tempdir().unwrap();
        let t = Instant::now();
        let files = brdfd::report::write_report(&study, out.path(), &mut |_, _, _| {}).unwrap();
        let write = t.elapsed().as_secs_f64();
        println!(
            "report: {} samples loaded from the central database in {load:.2} s; report \
             written ({} figures + summary) in {write:.2} s; {:.2} s in all",
            study.samples.len(),
            files.figures.len(),
            load + write
        );
        pool.close().await;
    });

    for s in &stores {
        rt.block_on(s.close());
    }
    rt.block_on(async {
        admin_exec(&format!("DROP DATABASE {live_db} WITH (FORCE)")).await;
        admin_exec(&format!("DROP DATABASE {catchup_db} WITH (FORCE)")).await;
    });
}

/// Queues every row of the store file at `path` again, as the migration's backfill does for
/// an old store (with a new uid: it is another station).
async fn requeue_everything(path: &std::path::Path) {
    let pool =
        &sqlx::SqlitePool::connect_with(sqlx::sqlite::SqliteConnectOptions::new().filename(path))
            .await
            .unwrap();
    sqlx::query("UPDATE sync_identity SET uid = lower(hex(randomblob(16)))")
        .execute(pool)
        .await
        .unwrap();
    sqlx::query("DELETE FROM sync_outbox")
        .execute(pool)
        .await
        .unwrap();
    for (table, id, at) in [
        ("instruments", "id", "last_seen_ms"),
        ("samples", "id", "created_at_ms"),
        ("reference_sets", "id", "taken_at_ms"),
        ("reference_readings", "id", "taken_at_ms"),
        ("scans", "id", "requested_at_ms"),
        ("readings", "id", "received_at_ms"),
        ("processed", "id", "created_at_ms"),
        ("fit_runs", "id", "queued_at_ms"),
        ("evaluation_summaries", "fit_run_id", "0"),
    ] {
        sqlx::query(&format!(
            "INSERT INTO sync_outbox (table_name, row_id, at_ms)
             SELECT '{table}', {id}, {at} FROM {table} ORDER BY {id}"
        ))
        .execute(pool)
        .await
        .unwrap();
    }
    pool.close().await;
}

/// Copies station `from` into `copies` new stations `clone-N` in the central database.
async fn clone_station(pool: &sqlx::PgPool, from: &str, copies: i64) {
    let mut tx = pool.begin().await.unwrap();
    sqlx::query(
        "INSERT INTO stations (station, store_uid, cursor)
         SELECT 'clone-' || g, 'clone-' || g, 0 FROM generate_series(1, $1) g",
    )
    .bind(copies)
    .execute(&mut *tx)
    .await
    .unwrap();
    for t in &TABLES {
        let cols: Vec<&str> = t.columns.iter().map(|(n, _)| *n).collect();
        sqlx::query(&format!(
            "INSERT INTO {table} (station, {cols})
             SELECT 'clone-' || g, {cols} FROM {table}, generate_series(1, $1) g
             WHERE station = $2",
            table = t.name,
            cols = cols.join(", ")
        ))
        .bind(copies)
        .bind(from)
        .execute(&mut *tx)
        .await
        .unwrap();
    }
    tx.commit().await.unwrap();
}
