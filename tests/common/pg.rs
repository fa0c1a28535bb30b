//! PostgreSQL for the forwarding tests (`tests/sync_*.rs`): a fresh database per test on the
//! lab-style server, and a throwaway server of a test's own to stop and restart.
//!
//! - The server is `BRDFD_TEST_POSTGRES` (an admin URL, e.g.
//!   `postgres://postgres@127.0.0.1:5432/postgres`), by default that very URL. `.ci/run` sets it
//!   to the machine's server when one answers, or to a throwaway cluster it starts. A test that
//!   cannot reach it fails with what to do; it never skips.
//! - [`TestDb`] creates a database with a unique name and drops it (with its connections) when
//!   the test ends, passed or failed.
//! - [`Cluster`] runs `initdb` and `pg_ctl` from the PostgreSQL binaries (`BRDFD_TEST_PG_BINDIR`,
//!   else `pg_config --bindir`, else `/usr/lib/postgresql/*/bin`) on a free port in a temporary
//!   directory, with password authentication over TCP, as a non-root user (PostgreSQL refuses
//!   to run as root: under root the commands run as the `postgres` user via `runuser`).

#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use brdfd::sync::tables::{Kind, TABLES};
use sqlx::Row;

/// The admin URL of the test server.
pub fn admin_url() -> String {
    std::env::var("BRDFD_TEST_POSTGRES")
        .unwrap_or_else(|_| "postgres://postgres@127.0.0.1:5432/postgres".to_string())
}

/// `url` with its database replaced by `db`.
pub fn with_database(url: &str, db: &str) -> String {
    let (base, query) = match url.split_once('?') {
        Some((b, q)) => (b, format!("?{q}")),
        None => (url, String::new()),
    };
    let scheme_end = base.find("://").map_or(0, |i| i + 3);
    let base = match base[scheme_end..].find('/') {
        Some(i) => &base[..scheme_end + i],
        None => base,
    };
    format!("{base}/{db}{query}")
}

/// Runs `sql` on the server at `admin` (one statement, no result).
pub fn admin_exec(admin: &str, sql: &str) {
    let admin = admin.to_string();
    let sql = sql.to_string();
    // Its own runtime on its own thread: callable from sync code, async tests and Drop alike.
    std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(async {
            use sqlx::Connection;
            let mut c = sqlx::PgConnection::connect(&admin)
                .await
                .unwrap_or_else(|e| {
                    panic!(
                        "the PostgreSQL test server {admin} does not answer ({e}); run the tests \
                     with `bash .ci/run`, which starts one, or set BRDFD_TEST_POSTGRES to an \
                     admin URL"
                    )
                });
            sqlx::query(&sql)
                .execute(&mut c)
                .await
                .unwrap_or_else(|e| panic!("{sql}: {e}"));
            let _ = c.close().await;
        })
    })
    .join()
    .unwrap_or_else(|p| std::panic::resume_unwind(p))
}

static COUNTER: AtomicUsize = AtomicUsize::new(0);

/// A fresh database, dropped at the end of the test.
pub struct TestDb {
    pub url: String,
    admin: String,
    name: String,
}

impl TestDb {
    /// A new database on the test server.
    pub fn create(label: &str) -> TestDb {
        TestDb::create_on(&admin_url(), label)
    }

    /// A new database on the server at `admin`.
    pub fn create_on(admin: &str, label: &str) -> TestDb {
        let name = format!(
            "brdfd_{label}_{}_{}",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::SeqCst)
        );
        admin_exec(admin, &format!("CREATE DATABASE {name}"));
        TestDb {
            url: with_database(admin, &name),
            admin: admin.to_string(),
            name,
        }
    }
}

impl TestDb {
    /// The database's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// `pg_dump -Fc` of the database into `file`.
    pub fn dump(&self, file: &Path) {
        let out = Command::new(bindir().join("pg_dump"))
            .args(["-Fc", "-f"])
            .arg(file)
            .arg(&self.url)
            .output()
            .expect("pg_dump runs");
        assert!(
            out.status.success(),
            "pg_dump: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }

    /// Replaces the database by the dump `file`, as an administrator restoring a backup
    /// would: restored beside it, then the live one dropped (its connections cut) and the
    /// restored one renamed in its place.
    pub fn restore(&self, file: &Path) {
        let staging = format!("{}_restored", self.name);
        admin_exec(&self.admin, &format!("CREATE DATABASE {staging}"));
        let out = Command::new(bindir().join("pg_restore"))
            .args(["--no-owner", "-d"])
            .arg(with_database(&self.admin, &staging))
            .arg(file)
            .output()
            .expect("pg_restore runs");
        assert!(
            out.status.success(),
            "pg_restore: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        admin_exec(
            &self.admin,
            &format!("DROP DATABASE {} WITH (FORCE)", self.name),
        );
        admin_exec(
            &self.admin,
            &format!("ALTER DATABASE {staging} RENAME TO {}", self.name),
        );
    }
}

impl Drop for TestDb {
    fn drop(&mut self) {
        let admin = self.admin.clone();
        let sql = format!("DROP DATABASE IF EXISTS {} WITH (FORCE)", self.name);
        // A server a test left stopped cannot drop anything; the cluster's directory goes.
        let _ = std::panic::catch_unwind(move || admin_exec(&admin, &sql));
    }
}

/// The directory of the PostgreSQL server binaries.
pub fn bindir() -> PathBuf {
    if let Ok(d) = std::env::var("BRDFD_TEST_PG_BINDIR") {
        return PathBuf::from(d);
    }
    if let Ok(out) = Command::new("pg_config").arg("--bindir").output()
        && out.status.success()
    {
        let d = PathBuf::from(String::from_utf8_lossy(&out.stdout).trim());
        if d.join("initdb").exists() && d.join("pg_ctl").exists() {
            return d;
        }
    }
    let mut found: Vec<PathBuf> = std::fs::read_dir("/usr/lib/postgresql")
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path().join("bin"))
        .filter(|b| b.join("initdb").exists())
        .collect();
    found.sort();
    found.pop().unwrap_or_else(|| {
        panic!(
            "no PostgreSQL server binaries (initdb, pg_ctl): install Debian's postgresql \
             (`bash .ci/run` does) or set BRDFD_TEST_PG_BINDIR"
        )
    })
}

fn is_root() -> bool {
    // SAFETY: geteuid has no preconditions.
    unsafe { libc::geteuid() == 0 }
}

/// A PostgreSQL server of the test's own.
pub struct Cluster {
    dir: tempfile::TempDir,
    pub port: u16,
    /// The password of user `postgres` over TCP.
    pub password: String,
    bin: PathBuf,
}

impl Cluster {
    fn data(&self) -> PathBuf {
        self.dir.path().join("data")
    }

    fn run(&self, program: &str, args: &[&str]) -> std::process::Output {
        let exe = self.bin.join(program);
        let mut cmd = if is_root() {
            let mut c = Command::new("runuser");
            c.args(["-u", "postgres", "--"]).arg(&exe);
            c
        } else {
            Command::new(&exe)
        };
        cmd.args(args);
        cmd.output()
            .unwrap_or_else(|e| panic!("{} cannot run: {e}", exe.display()))
    }

    fn check(&self, what: &str, out: std::process::Output) {
        assert!(
            out.status.success(),
            "{what} failed: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }

    /// `initdb` and start on a free port.
    pub fn start() -> Cluster {
        let bin = bindir();
        let dir = tempfile::Builder::new()
            .prefix("brdfd-pg-")
            .tempdir()
            .unwrap();
        let password = "brdfd-test-password".to_string();
        let pwfile = dir.path().join("pw");
        std::fs::write(&pwfile, &password).unwrap();
        if is_root() {
            let st = Command::new("chown")
                .args(["-R", "postgres:postgres"])
                .arg(dir.path())
                .status()
                .expect("chown runs");
            assert!(st.success(), "chown of the cluster directory");
        }
        let port = {
            let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
            l.local_addr().unwrap().port()
        };
        let c = Cluster {
            dir,
            port,
            password,
            bin,
        };
        let data = c.data();
        let out = c.run(
            "initdb",
            &[
                "-D",
                data.to_str().unwrap(),
                "-U",
                "postgres",
                "--auth-local=trust",
                "--auth-host=scram-sha-256",
                &format!("--pwfile={}", pwfile.display()),
                "--no-sync",
            ],
        );
        c.check("initdb", out);
        c.pg_start();
        c
    }

    fn pg_start(&self) {
        let data = self.data();
        let log = self.dir.path().join("log");
        let opts = format!(
            "-p {} -k {} -c listen_addresses=127.0.0.1 -c fsync=off",
            self.port,
            self.dir.path().display()
        );
        let out = self.run(
            "pg_ctl",
            &[
                "-D",
                data.to_str().unwrap(),
                "-l",
                log.to_str().unwrap(),
                "-o",
                &opts,
                "-w",
                "-t",
                "60",
                "start",
            ],
        );
        self.check("pg_ctl start", out);
    }

    /// `pg_ctl stop -m immediate`: the server dies as in a crash, connections cut.
    pub fn stop_immediate(&self) {
        let out = self.pg_stop();
        self.check("pg_ctl stop", out);
    }

    /// `pg_ctl stop -m immediate`, whatever it answers.
    fn pg_stop(&self) -> std::process::Output {
        let data = self.data();
        self.run(
            "pg_ctl",
            &[
                "-D",
                data.to_str().unwrap(),
                "-m",
                "immediate",
                "-w",
                "stop",
            ],
        )
    }

    /// Starts the server again on the same port (crash recovery replays its WAL).
    pub fn restart(&self) {
        self.pg_start();
    }

    /// The admin URL, with the password.
    pub fn admin_url(&self) -> String {
        format!(
            "postgres://postgres:{}@127.0.0.1:{}/postgres",
            self.password, self.port
        )
    }

    pub fn dir(&self) -> &Path {
        self.dir.path()
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = self.pg_stop();
    }
}

/// Waits until `f` is true, polling every 50 ms; panics naming `what` after `timeout`.
pub async fn wait_for<F, Fut>(what: &str, timeout: Duration, mut f: F)
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = bool>,
{
    let deadline = std::time::Instant::now() + timeout;
    while !f().await {
        assert!(
            std::time::Instant::now() < deadline,
            "timed out after {timeout:?} waiting for {what}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// One column's value in a comparable form: integers and text as they are, f64 by its bits,
/// bytes in hex.
pub fn cell_sqlite(row: &sqlx::sqlite::SqliteRow, i: usize, kind: Kind) -> String {
    match kind {
        Kind::Int => format!("{:?}", row.try_get_unchecked::<Option<i64>, _>(i).unwrap()),
        Kind::Text => format!(
            "{:?}",
            row.try_get_unchecked::<Option<String>, _>(i).unwrap()
        ),
        Kind::Real => format!(
            "{:?}",
            row.try_get_unchecked::<Option<f64>, _>(i)
                .unwrap()
                .map(f64::to_bits)
        ),
        Kind::Blob => format!(
            "{:?}",
            row.try_get_unchecked::<Option<Vec<u8>>, _>(i).unwrap()
        ),
    }
}

pub fn cell_pg(row: &sqlx::postgres::PgRow, i: usize, kind: Kind) -> String {
    match kind {
        Kind::Int => format!("{:?}", row.get::<Option<i64>, _>(i)),
        Kind::Text => format!("{:?}", row.get::<Option<String>, _>(i)),
        Kind::Real => format!("{:?}", row.get::<Option<f64>, _>(i).map(f64::to_bits)),
        Kind::Blob => format!("{:?}", row.get::<Option<Vec<u8>>, _>(i)),
    }
}

pub type Tables = BTreeMap<&'static str, Vec<Vec<String>>>;

/// A read-only pool on the store file at `db`, beside whatever else has it open.
pub async fn read_only_store(db: &Path) -> sqlx::SqlitePool {
    sqlx::SqlitePool::connect_with(
        sqlx::sqlite::SqliteConnectOptions::new()
            .filename(db)
            .read_only(true),
    )
    .await
    .unwrap()
}

/// The highest outbox entry the store at `db` ever queued, read afresh from the file.
pub async fn highest_seq(db: &Path) -> i64 {
    let pool = read_only_store(db).await;
    let seq: Option<i64> =
        sqlx::query_scalar("SELECT seq FROM sqlite_sequence WHERE name = 'sync_outbox'")
            .fetch_optional(&pool)
            .await
            .unwrap();
    pool.close().await;
    seq.unwrap_or(0)
}

/// The query of every forwarded column of `t`, in key order, `filter` (a `WHERE` clause or
/// nothing) between.
fn select_all(t: &brdfd::sync::tables::Table, filter: &str) -> String {
    let cols: Vec<&str> = t.columns.iter().map(|(n, _)| *n).collect();
    format!(
        "SELECT {} FROM {} {filter}ORDER BY {}",
        cols.join(", "),
        t.name,
        t.key.join(", ")
    )
}

/// The rows of `t` as text, one cell per forwarded column, by `cell`.
fn as_text<R>(
    t: &brdfd::sync::tables::Table,
    rows: &[R],
    cell: fn(&R, usize, Kind) -> String,
) -> Vec<Vec<String>> {
    rows.iter()
        .map(|r| {
            t.columns
                .iter()
                .enumerate()
                .map(|(i, (_, k))| cell(r, i, *k))
                .collect()
        })
        .collect()
}

/// Every forwarded table of a station's store file, every forwarded column, in key order.
pub async fn local_tables(db: &Path) -> Tables {
    let pool = read_only_store(db).await;
    let mut out = BTreeMap::new();
    for t in &TABLES {
        let rows = sqlx::query(&select_all(t, ""))
            .fetch_all(&pool)
            .await
            .unwrap();
        out.insert(t.name, as_text(t, &rows, cell_sqlite));
    }
    pool.close().await;
    out
}

/// The same, of one station in the central database.
pub async fn central_tables(url: &str, station: &str) -> Tables {
    let pool = sqlx::PgPool::connect(url).await.unwrap();
    let mut out = BTreeMap::new();
    for t in &TABLES {
        let rows = sqlx::query(&select_all(t, "WHERE station = $1 "))
            .bind(station)
            .fetch_all(&pool)
            .await
            .unwrap();
        out.insert(t.name, as_text(t, &rows, cell_pg));
    }
    pool.close().await;
    out
}
