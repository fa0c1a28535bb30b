//! `brdfd export-format` and `brdfd import-format`: scans and fits in the exchange formats
//! colour tools read (CGATS.17, CxF3, CSV, JSON), and the instruments' own software exports
//! (MA-T12 CGATS or CxF3 with the SRA's CSV) turned into `brdfd.scan/1` files.

use std::path::{Path, PathBuf};

use crate::formats::budget::Budget;
use crate::formats::{self, ExportOptions, Format, ImportOptions};
use crate::scan::ScanError;

use super::report::StoreSelection;

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

/// What `import-format` reads: an exchange file, or X-Rite's QC `.xlsx` export.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImportFormat {
    Exchange(Format),
    /// X-Rite's quality-control `.xlsx` export of MA-T12 measurements.
    XriteXlsx,
}

fn parse_import_format(s: &str) -> Result<ImportFormat, String> {
    if s == "xrite-xlsx" {
        return Ok(ImportFormat::XriteXlsx);
    }
    s.parse()
        .map(ImportFormat::Exchange)
        .map_err(|e: String| format!("{e}, xrite-xlsx"))
}

#[derive(Debug, clap::Args)]
#[command(after_long_help = IMPORT_HELP)]
pub struct ImportArgs {
    /// The instrument software's export: the MA-T12's CGATS or CxF3 (with --sra), X-Rite's QC
    /// `.xlsx` export (one or more files), or a brdfd export in any format.
    #[arg(value_name = "FILE", required = true, num_args = 1..)]
    pub files: Vec<PathBuf>,

    /// Format of FILE; default: from its extension (.xlsx → xrite-xlsx, .cxf → cxf3, .csv,
    /// .json, else cgats).
    #[arg(long, value_name = "cgats|cxf3|csv|json|xrite-xlsx", value_parser = parse_import_format)]
    pub format: Option<ImportFormat>,

    /// The SRA's CSV export (`sample,geometry,intensity`), needed when FILE has no SRA values
    /// (one FILE only). An X-Rite `.xlsx` export has none and needs none: its scans are fitted
    /// over the 12 MA-T12 geometries.
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

    /// Print one JSON object per scan (`{"sample", "file"}`, and for an `.xlsx` the colorimetry
    /// check) instead of lines.
    #[arg(long)]
    pub json: bool,
}

const IMPORT_HELP: &str = "\
X-Rite's QC .xlsx export (Color Data, Spectral Data, Texture Images) holds the MA-T12's 12
readings of each measurement as reflectance factor relative to the instrument's own white
calibration; it has no Munsell N9 and no SRA readings. Each measurement becomes one scan with
reference \"instrument calibration\" and no specular readings, keeping the measurement time,
the job and standard names, the illuminant/observer and the file's SHA-256. The import
recomputes X-Rite's L*a*b* from the spectra (ASTM E308 weighting under the file's
illuminant/observer) and prints the largest ΔE00; a geometry more than 0.01 apart is a
warning that names it.

The MA-T12's CGATS.17 or CxF3 export of a session holds the N9 tile (by --reference name) and
the samples, 12 spectra each, 400-700 nm; the SRA's two readings per object come from its CSV
(--sra, columns sample,geometry,intensity). The import keeps what the file says of its origin:
CGATS CREATED and INSTRUMENTATION (and SERIAL_NUMBER, ORIGINATOR), CxF3 Object CreationDate,
Device Model and SerialNumber, and FileInformation Creator. A CGATS export reads like this
(one data set per line, fields by name):

  CGATS.17
  ORIGINATOR \"MA-T12 software\"
  CREATED \"2024-05-29T16:37:15\"
  INSTRUMENTATION \"MA-T12\"
  KEYWORD \"GEOMETRY\"
  BEGIN_DATA_FORMAT
  SAMPLE_ID SAMPLE_NAME GEOMETRY SPECTRAL_NM400 SPECTRAL_NM410 ... SPECTRAL_NM700
  END_DATA_FORMAT
  BEGIN_DATA
  1 \"Munsell N9\" \"15as-45\" 0.79768 0.79768 ... 0.79768
  ...
  13 \"T.Sky blue\" \"15as-45\" 0.205024 0.247581 ... 0.116043
  END_DATA

A CxF3 export has one Object per tile or sample with one ReflectanceSpectrum per geometry, each
naming a ColorSpecification whose MeasurementSpec gives the MultiAngle BRDFAngle (its Notation
the geometry, e.g. 15as-45) and WavelengthRange StartWL=\"400\" Increment=\"10\". Complete
examples of both, with their SRA CSV, are in the source tree's tests/data/instrument-exports/.

Examples:
  brdfd import-format PAR_EW_RL_NG_3.xlsx PAR_PW_RO_NG_1.xlsx --out scans/
  brdfd import scans/*.scan.json
  brdfd import-format tests/data/instrument-exports/mat12-session.cgats.txt --sra tests/data/instrument-exports/mat12-session.sra.csv --out scans/
  brdfd import-format tests/data/instrument-exports/mat12-session.cxf --sra tests/data/instrument-exports/mat12-session.sra.csv --out scans/";

fn format_of(path: &Path) -> ImportFormat {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("xlsx") => ImportFormat::XriteXlsx,
        Some("cxf") | Some("xml") => ImportFormat::Exchange(Format::Cxf3),
        Some("csv") => ImportFormat::Exchange(Format::Csv),
        Some("json") => ImportFormat::Exchange(Format::Json),
        _ => ImportFormat::Exchange(Format::Cgats),
    }
}

/// One scan read from FILE, with what its import has to say.
pub struct Imported {
    pub scan: crate::scan::Scan,
    /// The colorimetry check of an X-Rite export: (largest ΔE00, where, warning).
    pub check: Option<(f64, &'static str, Option<String>)>,
}

/// The scans `brdfd import-format` reads from `file` with these options (its `files`, `out`,
/// `force` and `json` are not read); the Python package's `brdfd.import_export` calls it too.
pub fn read_one(args: &ImportArgs, file: &Path) -> anyhow::Result<Vec<Imported>> {
    let imported = read_unchecked(args, file)?;
    // The names the daemon would refuse (control characters, length) are refused here too.
    for i in &imported {
        let s = &i.scan;
        crate::service::check_name("sample name", &s.sample)
            .and_then(|()| crate::service::check_name("reference name", s.reference_label()))
            .map_err(|e| anyhow::anyhow!("{}: {e}", file.display()))?;
    }
    Ok(imported)
}

fn read_unchecked(args: &ImportArgs, file: &Path) -> anyhow::Result<Vec<Imported>> {
    let format = args.format.unwrap_or_else(|| format_of(file));
    match format {
        ImportFormat::XriteXlsx => {
            if args.sra.is_some() {
                anyhow::bail!(
                    "{}: an X-Rite .xlsx export takes no --sra: its scans have no specular readings",
                    file.display()
                );
            }
            let scans = formats::xrite::read_file(file, &Budget::default())?;
            Ok(scans
                .into_iter()
                .map(|s| Imported {
                    check: Some((s.check.largest, s.check.largest_at, s.warning())),
                    scan: s.scan,
                })
                .collect())
        }
        ImportFormat::Exchange(format) => {
            let budget = Budget::default();
            let text = formats::read_text_within(file, &budget)?;
            let sra = match &args.sra {
                Some(p) => Some((
                    p.display().to_string(),
                    formats::read_text_within(p, &budget)?,
                )),
                None => None,
            };
            let scans = formats::import(
                format,
                &file.display().to_string(),
                &text,
                sra.as_ref().map(|(n, t)| (n.as_str(), t.as_str())),
                &ImportOptions {
                    reference: args.reference.clone(),
                    budget,
                },
            )?;
            Ok(scans
                .into_iter()
                .map(|scan| Imported { scan, check: None })
                .collect())
        }
    }
}

pub fn import(args: &ImportArgs) -> anyhow::Result<()> {
    if args.sra.is_some() && args.files.len() > 1 {
        anyhow::bail!(
            "--sra pairs one SRA CSV with one MA-T12 export; give one FILE with it ({} given)",
            args.files.len()
        );
    }
    // Every file is read and checked before anything is written: a bad file writes nothing.
    let mut imported = Vec::new();
    for file in &args.files {
        imported.extend(read_one(args, file)?);
    }
    let out = super::out_dir(&args.out)?;
    let stems = super::distinct_file_stems(imported.iter().map(|s| s.scan.sample.as_str()));
    for (item, stem) in imported.iter().zip(stems) {
        let scan = &item.scan;
        let text = scan
            .to_json_pretty()
            .map_err(|e: ScanError| anyhow::anyhow!(e))?;
        let path = out.write(
            &format!("{stem}.scan.json"),
            text.as_bytes(),
            crate::safe_fs::Replace::force(args.force),
        )?;
        if let Some((_, _, Some(warning))) = &item.check {
            eprintln!("warning: {warning}");
        }
        if args.json {
            let mut v = serde_json::json!({ "sample": scan.sample, "file": path });
            if let Some((largest, at, warning)) = &item.check {
                v["colorimetry_check"] = serde_json::json!({
                    "largest_delta_e00": largest,
                    "at": at,
                    "warning": warning,
                });
            }
            println!("{v}");
        } else {
            let what = match (&scan.reference, &item.check) {
                (None, Some((largest, at, _))) => format!(
                    "  (reference: instrument calibration, no specular readings; L*a*b* as the file's within ΔE00 {largest:.1e}, largest at {at})"
                ),
                _ => String::new(),
            };
            println!("{} → {}{what}", scan.sample, path.display());
        }
    }
    Ok(())
}
