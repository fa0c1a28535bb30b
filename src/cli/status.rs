//! `brdfd status` and `brdfd abort`: what the daemon is doing, and stopping it.

use super::operator::{DaemonArgs, id, s};

/// `brdfd status` and `brdfd abort`.
#[derive(Debug, clap::Args)]
pub struct StatusArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// Print the daemon's JSON answer.
    #[arg(long)]
    pub json: bool,
}
pub fn status(args: &StatusArgs) -> anyhow::Result<()> {
    let v = args.daemon.client()?.get("/status")?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!("brdfd {} on {}", s(&v, "version"), args.daemon.addr()?);
    match v["busy"].as_object() {
        Some(b) => {
            let op = &b["operation"];
            let what = if s(op, "kind") == "scan" {
                format!("scan {}", id(op, "scan"))
            } else {
                format!("reference {}", id(op, "reference"))
            };
            println!(
                "measuring: {what} for {:.0} s",
                b["seconds"].as_f64().unwrap_or(0.0)
            );
        }
        None => println!("instruments idle"),
    }
    match v["reference"].as_object() {
        Some(r) => println!(
            "reference in force: {} ({}), {:.1} h old{}",
            r["id"],
            r["name"].as_str().unwrap_or(""),
            r["age_hours"].as_f64().unwrap_or(0.0),
            if r["stale"].as_bool() == Some(true) {
                " — too old: measure a new one with `brdfd reference`"
            } else {
                ""
            }
        ),
        None => println!("no reference measured yet: run `brdfd reference`"),
    }
    println!(
        "fits: {} queued, {} running; instruments simulated: MA-T12 {}, SRA {}",
        v["fits_queued"], v["fits_running"], v["simulated"]["ma_t12"], v["simulated"]["sra"]
    );
    if let Some(sync) = v["sync"].as_object() {
        println!(
            "forwarding as station {} to {}: {} entries waiting, {} rows forwarded since start{}",
            sync["station"].as_str().unwrap_or("?"),
            sync["central"].as_str().unwrap_or("?"),
            sync["backlog"],
            sync["rows_forwarded"],
            match sync["last_error"].as_str() {
                Some(e) if sync["refused"].as_bool() == Some(true) => {
                    format!("; REFUSED, nothing of this store is forwarded: {e}")
                }
                Some(e) => format!("; last error: {e}"),
                None => String::new(),
            }
        );
        if let Some(v) = sync["last_verify"].as_str() {
            println!("last comparison with the central database: {v}");
        }
    }
    if let Some(ingest) = v["ingest"].as_object() {
        println!(
            "watch folder {}: {} imported, {} rejected since start, {} waiting{}",
            ingest["dir"].as_str().unwrap_or("?"),
            ingest["imported"],
            ingest["rejected"],
            ingest["waiting"],
            match ingest["last_error"].as_str() {
                Some(e) => format!("; last error: {e}"),
                None => String::new(),
            }
        );
    }
    Ok(())
}
pub fn abort(args: &StatusArgs) -> anyhow::Result<()> {
    let v = args.daemon.client()?.post("/abort", None)?;
    if args.json {
        println!("{v}");
        return Ok(());
    }
    let op = &v["aborted"];
    match s(op, "kind").as_str() {
        "scan" => println!(
            "scan {} aborting; its readings so far are kept",
            id(op, "scan")
        ),
        _ => println!("reference {} aborting", id(op, "reference")),
    }
    Ok(())
}
