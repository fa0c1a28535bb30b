//! `brdfd export` and `brdfd import`: a stored scan as a brdfd.scan/1 file, and such a file
//! into the store (then following its fits); and [`read_scan_input`], how the commands that
//! fit a file without the store (`fit`, `crossval`, `render`) read theirs.

use std::path::{Path, PathBuf};

use anyhow::Context;
use serde_json::json;

use super::follow::{follow_scan, pending_fits, print_scan_result};
use super::operator::{DaemonArgs, tagged, terminal_safe};
use crate::store::ScanId;

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
    /// A brdfd.scan/1 file, or X-Rite's QC `.xlsx` export (each measurement becomes a scan:
    /// reference instrument calibration, no specular readings). Other instrument exports go
    /// through `brdfd import-format` first.
    #[arg(value_name = "FILE")]
    pub file: PathBuf,
    /// Import FILE even if the same file (the same bytes, whatever its name or the way it
    /// came in: `brdfd import`, the watch folder, `POST /scans/import`) was imported before;
    /// without it, a file imported before is not imported again, and its scans are named.
    #[arg(long)]
    pub again: bool,
    /// Return once imported, without following the fits.
    #[arg(long)]
    pub detach: bool,
    /// NDJSON on stdout, as for `brdfd scan --json`.
    #[arg(long)]
    pub json: bool,
}
pub fn export(args: &ExportArgs) -> anyhow::Result<()> {
    let text = args.daemon.client()?.export_scan(ScanId(args.scan))?;
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

/// The scan of a file given to `fit --input`, `crossval` or `render --input`: a
/// `brdfd.scan/1` file, or an X-Rite `.xlsx` export holding one sample (imported as
/// `brdfd import-format` would, its warning printed). A file of another kind, or an export
/// with several samples, is refused with the command that turns it into scan files.
pub fn read_scan_input(path: &Path) -> anyhow::Result<crate::scan::Scan> {
    let file = path.display();
    const CONVERT: &str = "turn an instrument's export (CGATS, CxF3 with the SRA's CSV, X-Rite \
        .xlsx) into scan files with `brdfd import-format FILE --out DIR` (see `brdfd \
        import-format --help`)";
    if is_xlsx(path) {
        let mut scans =
            crate::formats::xrite::read_file(path, &crate::formats::budget::Budget::default())?;
        if scans.len() != 1 {
            let names: Vec<String> = scans
                .iter()
                .map(|x| terminal_safe(&x.scan.sample))
                .collect();
            anyhow::bail!(
                "{file} holds {} samples ({}); this command fits one: write one scan file per \
                 sample with `brdfd import-format {file} --out DIR` and give it one of them",
                scans.len(),
                names.join(", ")
            );
        }
        let x = scans.remove(0);
        if let Some(w) = x.warning() {
            eprintln!("warning: {w}");
        }
        return Ok(x.scan);
    }
    crate::scan::Scan::read_file(path).map_err(|e| not_a_scan_file(path, e, CONVERT))
}

/// Whether `path` names an X-Rite QC export (by its extension, as `import-format` decides).
fn is_xlsx(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("xlsx"))
}

/// A scan file's error, named with its path; where the file is not a brdfd.scan/1 document at
/// all (not JSON, no or an unknown `format`), with `hint` on what to do with it instead.
fn not_a_scan_file(path: &Path, e: crate::scan::ScanError, hint: &str) -> anyhow::Error {
    use crate::scan::ScanError;
    let file = path.display();
    match e {
        ScanError::Syntax(json) => {
            anyhow::anyhow!("{file} is not a brdfd.scan/1 file: it is not JSON ({json}); {hint}")
        }
        e @ (ScanError::MissingFormat | ScanError::UnknownFormat { .. }) => {
            anyhow::anyhow!("{file}: {e}; {hint}")
        }
        e => anyhow::Error::new(e),
    }
}

/// `brdfd import` of an X-Rite `.xlsx`: read and checked here (errors name the file), sent
/// as it is, each scan's fits followed in turn.
fn import_xlsx(args: &ImportArgs) -> anyhow::Result<()> {
    let scans =
        crate::formats::xrite::read_file(&args.file, &crate::formats::budget::Budget::default())?;
    for s in &scans {
        if let Some(w) = s.warning() {
            eprintln!("warning: {w}");
        }
    }
    let bytes = std::fs::read(&args.file)
        .with_context(|| format!("cannot read {}", args.file.display()))?;
    let client = args.daemon.client()?;
    let v = client.import_xlsx(&bytes, &query(args))?;
    if repeated(args, &v)? {
        return Ok(());
    }
    if args.json {
        println!("{}", tagged("accepted", &v)?);
    }
    let ids = v.scans.clone().unwrap_or_default();
    for (scan, x) in ids.iter().zip(&scans) {
        if !args.json {
            println!(
                "{} ({}) imported as scan {scan}: reference instrument calibration, no specular \
                 readings; L*a*b* as the file's within ΔE00 {:.1e}",
                terminal_safe(&args.file.display().to_string()),
                terminal_safe(&x.scan.sample),
                x.check.largest
            );
        }
        if !args.detach {
            let events = client.events()?;
            let pending = pending_fits(&client, *scan)?;
            if !pending.is_empty() {
                follow_scan(&client, events, *scan, pending, args.json)?;
            }
            print_scan_result(&client.scan(*scan)?, args.json)?;
        }
    }
    Ok(())
}

pub fn import(args: &ImportArgs) -> anyhow::Result<()> {
    if is_xlsx(&args.file) {
        return import_xlsx(args);
    }
    // Within the import budget's file size, as every door reads (a larger file is refused
    // unread).
    let text =
        crate::formats::read_text_within(&args.file, &crate::formats::budget::Budget::default())?;
    // Checked here too, so a bad file is named with its path before anything is sent.
    if let Err(e) = crate::scan::Scan::from_json(text.as_bytes()) {
        const OTHER_FORMATS: &str = "an instrument's export (CGATS, CxF3, the SRA's CSV) is \
            imported with `brdfd import-format` (see `brdfd import-format --help`)";
        return Err(match e {
            e @ (crate::scan::ScanError::Syntax(_)
            | crate::scan::ScanError::MissingFormat
            | crate::scan::ScanError::UnknownFormat { .. }) => {
                not_a_scan_file(&args.file, e, OTHER_FORMATS)
            }
            e => anyhow::Error::new(e).context(format!("{}", args.file.display())),
        });
    }
    let client = args.daemon.client()?;
    let events = (!args.detach).then(|| client.events()).transpose()?;
    let v = client.import_scan(&text, &query(args))?;
    if repeated(args, &v)? {
        return Ok(());
    }
    let scan = v.scan.ok_or_else(|| {
        anyhow::anyhow!(
            "the daemon imported {} without naming its scan",
            args.file.display()
        )
    })?;
    let fits = &v.fits;
    if args.json {
        println!("{}", tagged("accepted", &v)?);
    } else {
        let ids: Vec<i64> = fits.iter().map(|f| f.0).collect();
        println!(
            "{} imported as scan {scan}; fits {ids:?} queued",
            terminal_safe(&args.file.display().to_string())
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
        print_scan_result(&client.scan(scan)?, args.json)?;
    }
    Ok(())
}

/// What `brdfd import` sends with the file: its name (recorded with its scans) and `--again`.
fn query(args: &ImportArgs) -> crate::wire::ImportQuery {
    crate::wire::ImportQuery {
        file: args
            .file
            .file_name()
            .map(|n| n.to_string_lossy().into_owned()),
        again: args.again,
    }
}

/// Says so and returns true when the daemon answered that the file was imported before: "FILE:
/// already imported as scan 3 on … from …; nothing was imported again; `brdfd import --again
/// FILE` imports it anyway" (with --json, the answer tagged `already_imported`).
fn repeated(args: &ImportArgs, v: &crate::wire::Imported) -> anyhow::Result<bool> {
    let Some(a) = &v.already_imported else {
        return Ok(false);
    };
    if args.json {
        println!("{}", tagged("already_imported", v)?);
        return Ok(true);
    }
    let prior = crate::store::PriorImport {
        sha256: a.sha256.clone(),
        scans: v
            .scans
            .clone()
            .unwrap_or_else(|| v.scan.into_iter().collect()),
        file_name: a.file_name.clone(),
        imported_at_ms: a.imported_at_ms,
    };
    let file = args.file.display();
    println!(
        "{}: {}; `brdfd import --again {}` imports it anyway",
        terminal_safe(&file.to_string()),
        terminal_safe(&crate::service::already_imported(&prior)),
        terminal_safe(&file.to_string())
    );
    Ok(true)
}
