//! `brdfd sync --db FILE --to URL [--once] [--verify] [--adopt NEW_ID | --retire-old ARCHIVE_ID]`:
//! forwards a station's
//! store to the lab's central PostgreSQL database — the same forwarder the daemon runs with
//! `[sync] url`, for a station that is stopped (or has no network while it runs). The store is
//! only read: the cursor of what was sent lives in the central database, so running it twice
//! sends nothing twice. `--adopt` and `--retire-old` are the exceptions, the two ways out for a
//! copy of a station's store that the station refuses: `--adopt` makes the copy a station of
//! its own (src/sync/lineage.rs); `--retire-old` moves what the central database holds of the
//! station to an archive id and gives the station id to the copy (src/sync/retire.rs). Both
//! open the store as its owner, so its daemon must be stopped.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;

use crate::config::Config;
use crate::store::Store;
use crate::sync::{Forwarder, ForwarderOptions};

#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  brdfd sync --db brdfd.db --to postgres://lab@db.lab/brdfd --once
      send everything not yet sent, print what was sent, exit
  brdfd sync --config /etc/brdfd/brdfd.toml
      the configured store, station id and [sync] url; keep forwarding until Ctrl-C,
      retrying with back-off whatever fails
  brdfd sync --db brdfd.db --to postgres://lab@db.lab/brdfd --verify --once
      compare every row with the central database, re-send what it lacks, exit
  brdfd sync --db copy.db --adopt bench-7
      make a copy of a station's store a station of its own (then set [station] id)
  brdfd sync --db brdfd.db --to postgres://lab@db.lab/brdfd --retire-old bench-3-old-pc
      a bench moved to a new PC whose copy of the store is refused: keep the old PC's rows
      centrally as station bench-3-old-pc, make this store station bench-3 (its [station] id)
      and send everything it holds; stop the old PC's daemon first

The central schema is created or brought up to date on first contact. A central database
migrated by a newer brdfd is refused, and so is a station id another store already forwards
under, and a copy of a station's store that went its own way after it was copied (exit
status 6, the message names `--adopt` and `--retire-old`). Every row is keyed by (station, local id): a resend
changes nothing, a row that changed (a fit that finished, a scan that failed) is updated.")]
pub struct SyncArgs {
    /// The station's SQLite store; default: the configuration's `[store] path`.
    #[arg(long, value_name = "FILE")]
    pub db: Option<PathBuf>,

    /// The central database, postgres://USER[:PASSWORD]@HOST[:PORT]/DATABASE; default: the
    /// configuration's `[sync] url`.
    #[arg(long, value_name = "URL")]
    pub to: Option<String>,

    /// The station id recorded on every row; default: the configuration's `[station] id`
    /// (itself the host name by default).
    #[arg(long, value_name = "ID")]
    pub station: Option<String>,

    /// Send what is pending, then exit (exit status 1 if it could not all be sent). Without
    /// it, keep forwarding new rows as the store receives them, until Ctrl-C, retrying with
    /// back-off after any failure.
    #[arg(long)]
    pub once: bool,

    /// First compare every forwarded row of the store with the central database (SHA-256 per
    /// row, per table) and re-send what is missing or different: after the central database
    /// was restored from a backup. The daemon does it by itself when it finds the central
    /// database behind what the store already deleted.
    #[arg(long)]
    pub verify: bool,

    /// Make this store (a copy of a station's store, refused for that station) a station of
    /// its own called NEW_ID: a new store id and every row queued again; then exit. The
    /// daemon must be stopped. Set [station] id = "NEW_ID" afterwards (or pass --station).
    #[arg(long, value_name = "NEW_ID", conflicts_with_all = ["once", "verify"])]
    pub adopt: Option<String>,

    /// Make this store (a copy of a station's store, refused for that station: a bench moved
    /// to a new PC while the old one went on) the station: what the central database holds
    /// of the station is kept under ARCHIVE_ID, a station of its own marked retired; then this
    /// store sends everything it holds under the station id, and exits. Refused while the old
    /// store still forwards. This store's daemon must be stopped too.
    #[arg(
        long,
        value_name = "ARCHIVE_ID",
        conflicts_with_all = ["once", "verify", "adopt"]
    )]
    pub retire_old: Option<String>,

    /// Configuration file for the defaults above.
    #[arg(long, value_name = "brdfd.toml")]
    pub config: Option<PathBuf>,

    /// NDJSON on stdout: `{"type":"start","station","store","central"}`, one
    /// `{"type":"verify","tables":[…],"cursor"}` with --verify (and, with `"automatic":
    /// true`, for each comparison the one-shot ran by itself because the central database
    /// was behind what the store had pruned), one
    /// `{"type":"batch","entries","rows":{table: n},"cursor"}` per batch, and
    /// `{"type":"drained","rows","seconds"}` when nothing is pending.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &SyncArgs) -> anyhow::Result<()> {
    let config = Config::load_or_default(args.config.as_deref())?;
    let db = args.db.clone().unwrap_or_else(|| config.store.path.clone());
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    if let Some(new_id) = &args.adopt {
        return rt
            .block_on(adopt(&db, new_id))
            .with_context(|| format!("adopting {}", db.display()));
    }
    let url = match (&args.to, &config.sync.url) {
        (Some(u), _) | (None, Some(u)) => u.clone(),
        (None, None) => anyhow::bail!(
            "no central database: pass --to postgres://USER@HOST/DATABASE or set [sync] url"
        ),
    };
    let station = args
        .station
        .clone()
        .unwrap_or_else(|| config.station.id.clone());
    let mut options = ForwarderOptions::new(station.clone(), url);
    options.batch = config.sync.batch;
    if let Some(archive) = &args.retire_old {
        return rt
            .block_on(retire_old(&db, options, archive, args.json))
            .with_context(|| format!("retiring station \"{station}\"'s old store"));
    }
    rt.block_on(async {
        let mut forwarder = Forwarder::for_file(&db, options).await?;
        let central = forwarder
            .status()
            .lock()
            .map(|s| s.central.clone())
            .unwrap_or_default();
        let json = args.json;
        if json {
            println!(
                "{}",
                serde_json::json!({
                    "type": "start", "station": station, "store": db, "central": central,
                })
            );
        } else {
            println!("station {station}: {} → {central}", db.display());
        }
        let started = Instant::now();
        let mut print = |r: &crate::sync::BatchReport| {
            if json {
                let rows = rows_by_table(&r.rows);
                println!(
                    "{}",
                    serde_json::json!({
                        "type": "batch", "entries": r.entries, "rows": rows, "cursor": r.cursor,
                    })
                );
            } else {
                println!("{r}");
            }
        };
        if !args.once {
            // Continuous: nothing stops it but Ctrl-C (the comparison, when asked for, is its
            // first step, retried like any other).
            if !json {
                println!("forwarding until Ctrl-C; failures are retried with back-off");
            }
            if args.verify {
                forwarder.request_verify();
            }
            // Errors, refusals and the comparisons after a restore are logged on stderr.
            crate::cli::serve::init_logging(crate::config::LogLevel::Info, json);
            let stop = async {
                let _ = tokio::signal::ctrl_c().await;
            };
            forwarder.run(stop, &mut print).await;
            return Ok(());
        }
        let mut extra = 0;
        if args.verify {
            let report = forwarder.verify().await?;
            extra = report.extra();
            if json {
                println!(
                    "{}",
                    serde_json::json!({
                        "type": "verify", "tables": report.tables, "cursor": report.cursor,
                    })
                );
            } else {
                for t in &report.tables {
                    println!(
                        "{:<22} {:>7} rows here, {:>7} centrally, {:>6} re-sent, {} extra; \
                         sha256 {}",
                        t.table,
                        t.local,
                        t.central,
                        t.resent,
                        t.extra,
                        &t.digest[..16]
                    );
                }
                println!("{report}");
            }
        }
        let sent = forwarder.drain(&mut print).await?;
        // The central database was behind what this store had pruned (restored from a
        // backup): the forwarder compared and re-sent by itself before the batches.
        for report in forwarder.take_automatic_verifies() {
            extra += report.extra();
            if json {
                println!(
                    "{}",
                    serde_json::json!({
                        "type": "verify", "automatic": true, "tables": report.tables,
                        "cursor": report.cursor,
                    })
                );
            } else {
                println!(
                    "the central database was behind what this store had already pruned \
                     (restored from a backup?); {report}"
                );
            }
        }
        if json {
            println!(
                "{}",
                serde_json::json!({
                    "type": "drained", "rows": sent, "seconds": started.elapsed().as_secs_f64(),
                })
            );
        } else {
            println!(
                "{sent} rows sent in {:.2} s; nothing pending",
                started.elapsed().as_secs_f64()
            );
        }
        if extra > 0 {
            anyhow::bail!(
                "the central database holds {extra} rows for station \"{station}\" that this \
                 store does not have: another store forwarded under this id"
            );
        }
        Ok::<_, anyhow::Error>(())
    })
    .with_context(|| format!("forwarding {}", db.display()))
}

async fn adopt(db: &std::path::Path, new_id: &str) -> anyhow::Result<()> {
    if !db.exists() {
        anyhow::bail!("no store at {}", db.display());
    }
    let store = Store::open(db).await?;
    let queued = crate::sync::lineage::adopt(store.sync_pools().0).await?;
    store.close().await;
    println!(
        "{} is now a store of its own ({queued} rows queued to forward); set [station] id = \
         \"{new_id}\" in its brdfd.toml (or pass --station {new_id}) and start it",
        db.display()
    );
    Ok(())
}

/// `--retire-old ARCHIVE_ID`: the station's central rows to the archive, the station to this
/// store (a new incarnation of it, so the old store is refused if it comes back), then
/// everything this store holds sent.
async fn retire_old(
    db: &std::path::Path,
    options: ForwarderOptions,
    archive: &str,
    json: bool,
) -> anyhow::Result<()> {
    if !db.exists() {
        anyhow::bail!("no store at {}", db.display());
    }
    let station = options.station.clone();
    let store = Store::open(db).await?;
    let result = async {
        let (writer, _) = store.sync_pools();
        let uid: String = sqlx::query_scalar("SELECT uid FROM sync_identity")
            .fetch_one(writer)
            .await
            .context("reading the store's id")?;
        let incarnation = crate::sync::lineage::read(writer)
            .await?
            .last()
            .map(|i| i.id.clone())
            .context("the store has no incarnation")?;
        let central = crate::sync::Central::connect_and_migrate(&options.url).await?;
        let retired =
            crate::sync::retire::retire(&central, &station, archive, &uid, &incarnation).await;
        central.close().await;
        let retired = retired?;
        if json {
            let rows = rows_by_table(&retired.rows);
            println!(
                "{}",
                serde_json::json!({
                    "type": "retired", "station": station, "archive": archive,
                    "host": retired.host, "rows": rows,
                    "old_store_last_seen_seconds": retired.last_seen_seconds,
                })
            );
        } else {
            println!(
                "station {station}: the old store's {} central rows (host {}) are now station \
                 {archive}; this store is station {station}",
                retired.total_rows(),
                retired.host
            );
            if let Some(seconds) = retired.last_seen_seconds {
                println!(
                    "the old store last forwarded {seconds:.0} s ago; if it still runs it is \
                     refused from its next forward on (stop it, or give it a station of its own \
                     with --adopt)"
                );
            }
        }
        let started = Instant::now();
        let mut forwarder = Forwarder::for_store(&store, options).await?;
        let report = forwarder.verify().await?;
        let sent = forwarder.drain(&mut |_| {}).await?;
        if json {
            println!(
                "{}",
                serde_json::json!({
                    "type": "drained", "resent": report.resent(), "rows": sent,
                    "seconds": started.elapsed().as_secs_f64(),
                })
            );
        } else {
            println!(
                "{} rows sent in {:.2} s; nothing pending. Start this station's daemon as \
                 station {station}",
                report.resent() + sent as usize,
                started.elapsed().as_secs_f64()
            );
        }
        Ok::<_, anyhow::Error>(())
    }
    .await;
    store.close().await;
    result
}

/// Row counts per table as the JSON object of `--json` lines.
fn rows_by_table<N: Copy + Into<serde_json::Value>>(
    rows: &[(&str, N)],
) -> serde_json::Map<String, serde_json::Value> {
    rows.iter()
        .map(|(t, n)| (t.to_string(), (*n).into()))
        .collect()
}
