//! `brdfd sync --db FILE --to URL [--once]`: forwards a station's store to the lab's central
//! PostgreSQL database — the same forwarder the daemon runs with `[sync] url`, for a station
//! that is stopped (or has no network while it runs). The store is only read: the cursor of
//! what was sent lives in the central database, so running it twice sends nothing twice.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;

use crate::config::Config;
use crate::sync::{Forwarder, ForwarderOptions};

#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  brdfd sync --db brdfd.db --to postgres://lab@db.lab/brdfd --once
      send everything not yet sent, print what was sent, exit
  brdfd sync --config /etc/brdfd/brdfd.toml
      the configured store, station id and [sync] url; keep forwarding until Ctrl-C

The central schema is created or brought up to date on first contact. A central database
migrated by a newer brdfd is refused, and so is a station id another store already forwards
under. Every row is keyed by (station, local id): a resend changes nothing, a row that changed
(a fit that finished, a scan that failed) is updated.")]
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
    /// it, keep forwarding new rows as the store receives them, until Ctrl-C.
    #[arg(long)]
    pub once: bool,

    /// Configuration file for the defaults above.
    #[arg(long, value_name = "brdfd.toml")]
    pub config: Option<PathBuf>,

    /// NDJSON on stdout: `{"type":"start","station","store","central"}`, one
    /// `{"type":"batch","entries","rows":{table: n},"cursor"}` per batch, and
    /// `{"type":"drained","rows","seconds"}` when nothing is pending.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &SyncArgs) -> anyhow::Result<()> {
    let config = Config::load_or_default(args.config.as_deref())?;
    let db = args.db.clone().unwrap_or_else(|| config.store.path.clone());
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
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
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
                let rows: serde_json::Map<String, serde_json::Value> = r
                    .rows
                    .iter()
                    .map(|(t, n)| (t.to_string(), serde_json::Value::from(*n)))
                    .collect();
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
        let sent = forwarder.drain(&mut print).await?;
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
        if !args.once {
            if !json {
                println!("forwarding new rows as they are stored; Ctrl-C to stop");
            }
            let stop = async {
                let _ = tokio::signal::ctrl_c().await;
            };
            forwarder.run(stop, &mut print).await;
        }
        Ok::<_, anyhow::Error>(())
    })
    .with_context(|| format!("forwarding {}", db.display()))
}
