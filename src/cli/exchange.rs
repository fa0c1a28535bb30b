//! `brdfd export-format` and `brdfd import-format`: scans and fits in the exchange formats
//! colour tools read (CGATS.17, CxF3, CSV, JSON), and the instruments' own software exports
//! (MA-T12 CGATS or CxF3 with the SRA's CSV) turned into `brdfd.scan/1` files.

use std::path::{Path, PathBuf};

use crate::formats::{self, ExportOptions, Format, ImportOptions};
use crate::scan::ScanError;

use super::report::StoreSelection;

fn parse_format(s: &str) -> Result<Format, String> {
    s.parse()
}

/// What `export-format` writes: an exchange file, or renderer materials (one file per fit).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExportKind {
    Exchange(Format),
    /// Mitsuba 3 scenes, one per finished fit.
    Mitsuba,
    /// glTF 2.0 files, one per finished fit.
    Gltf,
    /// The tidy CSV tables `spectra.csv` and `fits.csv`.
    Tidy,
}

fn parse_export_kind(s: &str) -> Result<ExportKind, String> {
    match s {
        "mitsuba" => Ok(ExportKind::Mitsuba),
        "gltf" => Ok(ExportKind::Gltf),
        "tidy" => Ok(ExportKind::Tidy),
        _ => s.parse().map(ExportKind::Exchange).map_err(|_| {
            format!("unknown format \"{s}\"; valid: cgats, cxf3, csv, json, tidy, mitsuba, gltf")
        }),
    }
}

#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    /// `cgats` (CGATS.17 text), `cxf3` (X-Rite CxF3 XML), `csv`, or `json` (everything,
    /// including fitted parameters); `tidy`: the directory --out gets `spectra.csv` (one row per
    /// scan × geometry × band: provenance, reading, reference, measured and fitted values) and
    /// `fits.csv` (one row per fit: parameters, intervals, ΔE00) for pandas or R; or, for
    /// renderers, one file per finished fit into the directory --out: `mitsuba` (Mitsuba 3
    /// scene: spectral material, sphere, camera, the preview's D65 light) or `gltf` (glTF 2.0
    /// material on a sphere, RGB approximation).
    #[arg(long, value_name = "cgats|cxf3|csv|json|tidy|mitsuba|gltf", value_parser = parse_export_kind)]
    pub format: ExportKind,

    #[command(flatten)]
    pub select: StoreSelection,

    /// File to write (refused if it exists, unless --force); a directory (created if missing)
    /// for `tidy`, `mitsuba` and `gltf`, whose files are likewise never replaced without
    /// --force.
    #[arg(long, value_name = "FILE|DIR")]
    pub out: PathBuf,

    /// Replace files that exist.
    #[arg(long)]
    pub force: bool,

    /// Print `{"samples", "format", "files"}` instead of lines.
    #[arg(long)]
    pub json: bool,
}

pub fn export(args: &ExportArgs) -> anyhow::Result<()> {
    let study = args.select.load()?;
    let format = match args.format {
        ExportKind::Exchange(f) => f,
        kind => {
            let opts = ExportOptions::default();
            let files = match kind {
                ExportKind::Mitsuba => formats::mitsuba::scenes(&study, &opts)?
                    .into_iter()
                    .map(|(n, t)| (n, t.into_bytes()))
                    .collect::<Vec<_>>(),
                ExportKind::Tidy => formats::tidy::files(&study)?
                    .into_iter()
                    .map(|(n, t)| (n, t.into_bytes()))
                    .collect::<Vec<_>>(),
                _ => formats::gltf::files(&study, &opts)?,
            };
            let out = super::out_dir(&args.out)?;
            let mut written = Vec::new();
            for (name, bytes) in &files {
                let path = out.write(name, bytes, crate::safe_fs::Replace::force(args.force))?;
                if !args.json {
                    println!("{}", path.display());
                }
                written.push(path);
            }
            if args.json {
                println!(
                    "{}",
                    serde_json::json!({
                        "samples": study.samples.len(),
                        "format": format!("{kind:?}").to_lowercase(),
                        "files": written,
                    })
                );
            }
            return Ok(());
        }
    };
    let text = formats::export(&study, format, &ExportOptions::default())?;
    super::write_new_file(&args.out, text.as_bytes(), args.force)?;
    if args.json {
        println!(
            "{}",
            serde_json::json!({
                "samples": study.samples.len(),
                "format": format.name(),
                "files": [&args.out],
            })
        );
        return Ok(());
    }
    println!(
        "{} samples as {} in {}",
        study.samples.len(),
        format,
        args.out.display()
    );
    Ok(())
}

#[derive(Debug, clap::Args)]
pub struct ImportArgs {
    /// The MA-T12's export (CGATS or CxF3), or a brdfd export in any format.
    #[arg(value_name = "FILE")]
    pub file: PathBuf,

    /// Format of FILE; default: from its extension (.cxf → cxf3, .csv, .json, else cgats).
    #[arg(long, value_name = "cgats|cxf3|csv|json", value_parser = parse_format)]
    pub format: Option<Format>,

    /// The SRA's CSV export (`sample,geometry,intensity`), needed when FILE has no SRA values.
    #[arg(long, value_name = "SRA.csv")]
    pub sra: Option<PathBuf>,

    /// In an instrument's export, the object with this name is the white reference tile.
    #[arg(long, value_name = "NAME", default_value = formats::DEFAULT_REFERENCE)]
    pub reference: String,

    /// Directory to write one `brdfd.scan/1` file per sample into (`<sample>.scan.json`);
    /// `brdfd import` then puts them in the store.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,

    /// Replace files that exist in DIR.
    #[arg(long)]
    pub force: bool,

    /// Print one JSON object per scan (`{"sample", "file"}`) instead of lines.
    #[arg(long)]
    pub json: bool,
}

fn format_of(path: &Path) -> Format {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("cxf") | Some("xml") => Format::Cxf3,
        Some("csv") => Format::Csv,
        Some("json") => Format::Json,
        _ => Format::Cgats,
    }
}

pub fn import(args: &ImportArgs) -> anyhow::Result<()> {
    let format = args.format.unwrap_or_else(|| format_of(&args.file));
    let text = formats::read_text(&args.file)?;
    let sra = match &args.sra {
        Some(p) => Some((p.display().to_string(), formats::read_text(p)?)),
        None => None,
    };
    let scans = formats::import(
        format,
        &args.file.display().to_string(),
        &text,
        sra.as_ref().map(|(n, t)| (n.as_str(), t.as_str())),
        &ImportOptions {
            reference: args.reference.clone(),
        },
    )?;
    let out = super::out_dir(&args.out)?;
    let stems = super::distinct_file_stems(scans.iter().map(|s| s.sample.as_str()));
    for (scan, stem) in scans.iter().zip(stems) {
        let text = scan
            .to_json_pretty()
            .map_err(|e: ScanError| anyhow::anyhow!(e))?;
        let path = out.write(
            &format!("{stem}.scan.json"),
            text.as_bytes(),
            crate::safe_fs::Replace::force(args.force),
        )?;
        if args.json {
            println!(
                "{}",
                serde_json::json!({ "sample": scan.sample, "file": path })
            );
        } else {
            println!("{} → {}", scan.sample, path.display());
        }
    }
    Ok(())
}
