//! `brdfd export` and `brdfd import`: a stored scan as a brdfd.scan/1 file, and such a file
//! into the store (then following its fits).

use std::path::PathBuf;

use anyhow::Context;
use serde_json::json;

use super::follow::{follow_scan, pending_fits, print_scan_result};
use super::operator::{DaemonArgs, id, queued_fits, tagged};

#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// The scan's id.
    #[arg(value_name = "SCAN")]
    pub scan: i64,
    /// Write here instead of stdout (refused if it exists, unless --force).
    #[arg(long, short, value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Replace FILE if it exists.
    #[arg(long)]
    pub force: bool,
    /// With --output: print `{"scan":…,"file":…}` instead of the sentence.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, clap::Args)]
pub struct ImportArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// A brdfd.scan/1 file.
    #[arg(value_name = "FILE")]
    pub file: PathBuf,
    /// Return once imported, without following the fits.
    #[arg(long)]
    pub detach: bool,
    /// NDJSON on stdout, as for `brdfd scan --json`.
    #[arg(long)]
    pub json: bool,
}
pub fn export(args: &ExportArgs) -> anyhow::Result<()> {
    let text = args
        .daemon
        .client()?
        .get_text(&format!("/scans/{}/export", args.scan))?;
    match &args.output {
        Some(path) => {
            super::write_new_file(path, text.as_bytes(), args.force)?;
            if args.json {
                println!("{}", json!({ "scan": args.scan, "file": path }));
            } else {
                eprintln!("scan {} written to {}", args.scan, path.display());
            }
        }
        None => println!("{text}"),
    }
    Ok(())
}

pub fn import(args: &ImportArgs) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(&args.file)
        .with_context(|| format!("cannot read {}", args.file.display()))?;
    // Checked here too, so a bad file is named with its path before anything is sent.
    if let Err(e) = crate::scan::Scan::from_json(text.as_bytes()) {
        use crate::scan::ScanError;
        const OTHER_FORMATS: &str = "an instrument's export (CGATS, CxF3, the SRA's CSV) is \
            imported with `brdfd import-format` (see `brdfd import-format --help`)";
        let file = args.file.display();
        return Err(match e {
            ScanError::Syntax(json) => anyhow::anyhow!(
                "{file} is not a brdfd.scan/1 file: it is not JSON ({json}); {OTHER_FORMATS}"
            ),
            e @ (ScanError::MissingFormat | ScanError::UnknownFormat { .. }) => {
                anyhow::anyhow!("{file}: {e}; {OTHER_FORMATS}")
            }
            e => anyhow::Error::new(e).context(format!("{file}")),
        });
    }
    let client = args.daemon.client()?;
    let events = (!args.detach).then(|| client.events()).transpose()?;
    let v = client.post_text("/scans/import", &text)?;
    let scan = id(&v, "scan");
    let fits = queued_fits(&v);
    if args.json {
        println!("{}", tagged("accepted", &v));
    } else {
        println!(
            "{} imported as scan {scan}; fits {fits:?} queued",
            args.file.display()
        );
    }
    if let Some(events) = events {
        if !fits.is_empty() {
            // Fits may already have finished before the stream saw them: check first.
            let pending = pending_fits(&client, scan)?;
            if !pending.is_empty() {
                follow_scan(&client, events, scan, pending, args.json)?;
            }
        }
        print_scan_result(&client.get(&format!("/scans/{scan}"))?, args.json);
    }
    Ok(())
}
