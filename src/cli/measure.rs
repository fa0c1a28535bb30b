//! `brdfd reference` and `brdfd scan`: ask the daemon to measure the white reference tile or a
//! sample, then follow the measurement (and a scan's fits) on the event stream.

use super::follow::{follow_reference, follow_scan, print_scan_result};
use super::operator::{DaemonArgs, tagged};

#[derive(Debug, clap::Args)]
pub struct ReferenceArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// Return once the daemon has accepted the request, without following progress.
    #[arg(long)]
    pub detach: bool,
    /// NDJSON on stdout: the daemon's answer, then each of its events about this reference
    /// (`GET /events` objects), one per line.
    #[arg(long)]
    pub json: bool,
}
#[derive(Debug, clap::Args)]
pub struct ScanArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// The sample's name, e.g. "T.Sky blue".
    #[arg(long, value_name = "NAME")]
    pub sample: String,
    /// Return once the daemon has accepted the request, without following progress.
    #[arg(long)]
    pub detach: bool,
    /// NDJSON on stdout: the daemon's answer, each of its events about this scan and its fits
    /// (`GET /events` objects), then `{"type":"result","scan":…}` with the scan's detail.
    #[arg(long)]
    pub json: bool,
}
pub fn reference(args: &ReferenceArgs) -> anyhow::Result<()> {
    let client = args.daemon.client()?;
    let events = (!args.detach).then(|| client.events()).transpose()?;
    let v = client.request_reference()?;
    let reference = v.reference;
    if args.json {
        println!("{}", tagged("accepted", &v)?);
    } else {
        // The SRA turned off: the tile is measured on the MA-T12 alone.
        let sra_off = client.status().is_ok_and(|s| s.sra_off());
        println!(
            "reference {reference} started: {}",
            reference_started(sra_off)
        );
    }
    match events {
        Some(events) => follow_reference(&client, events, reference, args.json),
        None => Ok(()),
    }
}

/// What `brdfd reference` says it measures.
pub(super) fn reference_started(sra_off: bool) -> &'static str {
    if sra_off {
        "measuring the Munsell N9 tile on the MA-T12 (SRA off: the 12 MA-T12 geometries)"
    } else {
        "measuring the Munsell N9 tile on both instruments"
    }
}

pub fn scan(args: &ScanArgs) -> anyhow::Result<()> {
    let client = args.daemon.client()?;
    let events = (!args.detach).then(|| client.events()).transpose()?;
    let v = client.request_scan(&args.sample)?;
    let scan = v.scan;
    if args.json {
        println!("{}", tagged("accepted", &v)?);
    } else {
        println!("scan {scan} started: sample \"{}\"", args.sample);
    }
    match events {
        Some(events) => {
            follow_scan(&client, events, scan, Vec::new(), args.json)?;
            print_scan_result(&client.scan(scan)?, args.json)?;
            Ok(())
        }
        None => Ok(()),
    }
}
