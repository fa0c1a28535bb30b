//! The `brdfd` command line: one clap-derived [`Cli`] with a subcommand per job, and [`run`].
//!
//! Each subcommand lives in its own file with its `Args` struct and a `run` function (a pair
//! that belongs together shares one: `reference` and `scan` in [`measure`], `status` and
//! `abort` in [`status`], `export` and `import` in [`scan_file`]); adding one (serve, scan,
//! reference, replay, …) is a variant in [`Command`], a file here, and an arm in [`run`]. The
//! operator subcommands that talk to a running daemon share [`operator`] (where the daemon is,
//! its JSON for the terminal) and [`follow`] (progress on the event stream). Errors go up as
//! `anyhow` chains with context; the binary prints them on one line.

use clap::{Parser, Subcommand};

pub mod crossval;
pub mod demo;
pub mod doctor;
pub mod exchange;
pub mod fit;
pub mod follow;
pub mod measure;
pub mod open;
pub mod operator;
pub mod record;
pub mod refit;
pub mod render;
pub mod replay;
pub mod report;
pub mod scan_file;
pub mod scans;
pub mod serve;
pub mod shell;
pub mod show;
pub mod status;
pub mod sync;
pub mod synth;
pub mod validate;

/// brdfd: spectral BRDF from two handheld instruments (X-Rite MA-T12 + Canon RA-532H).
#[derive(Debug, Parser)]
#[command(name = "brdfd", version, about, propagate_version = true, after_help = EXIT_CODES_HELP)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

/// Every subcommand.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Fit the spectral Cook–Torrance model to one scan file, without a daemon or database.
    Fit(fit::FitArgs),
    /// Validate the handheld estimate against a measured goniometric BRDF (ASTM E1392 or
    /// RGL .bsdf): the 14 readings it would give, fitted, predicting every measured direction.
    Validate(validate::ValidateArgs),
    /// Leave one geometry out of a scan file's fit, predict it, for each geometry and cost
    /// function: how well the fit predicts readings it has not seen.
    Crossval(crossval::CrossvalArgs),
    /// Write the eight synthetic example scans and their ground truth to a directory.
    Synth(synth::SynthArgs),
    /// The main job on the embedded default: replay the committed recordings (N9 reference and
    /// eight samples) through the whole daemon into a local SQLite file, fit all three cost
    /// functions, and compare them.
    Demo(demo::DemoArgs),
    /// Write the study report of stored scans: the paper's figures 4–12 and where the model misses (Fig. 13; PNG and SVG) and a
    /// summary (HTML, Markdown) with ΔE00 per sample and cost function, means with 95 % CI and
    /// sign tests.
    Report(report::ReportArgs),
    /// Draw a sample's fitted material on a sphere (31 bands, D65), one sphere per cost
    /// function, beside its measured swatches, as PNG.
    Render(render::RenderArgs),
    /// Export stored scans and fits as CGATS.17, X-Rite CxF3, CSV or JSON.
    ExportFormat(exchange::ExportArgs),
    /// Turn an instrument software export (X-Rite's QC .xlsx; MA-T12 CGATS or CxF3 + SRA
    /// CSV) or a brdfd export into brdfd.scan/1 files.
    ImportFormat(exchange::ImportArgs),
    /// Run the daemon: instruments, scan orchestrator, fit worker and the local HTTP API.
    Serve(serve::ServeArgs),
    /// Ask the running daemon to measure the white reference tile (Munsell N9).
    Reference(measure::ReferenceArgs),
    /// Ask the running daemon to scan a sample, with live progress per reading and per fit.
    Scan(measure::ScanArgs),
    /// List the scans in the running daemon's store, newest first.
    Scans(scans::ScansArgs),
    /// Show one scan: its state, readings, reference and fits with their ΔE00.
    Show(show::ShowArgs),
    /// Fit a stored scan again (other cost functions, method or seed).
    Refit(refit::RefitArgs),
    /// Stop the reference or scan in progress (its readings are kept).
    Abort(status::StatusArgs),
    /// The running daemon's state: what it is doing, the reference in force, fits pending.
    Status(status::StatusArgs),
    /// Write a stored scan as a brdfd.scan/1 file.
    Export(scan_file::ExportArgs),
    /// Import a brdfd.scan/1 file into the store; the daemon fits it.
    Import(scan_file::ImportArgs),
    /// Replay recorded session files against the whole daemon in-process (simulated devices →
    /// store → fits).
    Replay(replay::ReplayArgs),
    /// Measure once and record every frame to and from both instruments into session files.
    Record(record::RecordArgs),
    /// Forward a station's store to the lab's central PostgreSQL database (what `[sync] url`
    /// makes the daemon do continuously), e.g. from a stopped station.
    Sync(sync::SyncArgs),
    /// Print a one-time login link to the operator's web page (and open it on a desktop).
    Open(open::OpenArgs),
    /// Check the whole set-up at once (configuration, store and its lock, daemon and token,
    /// MA-T12 on USB, the SRA's serial port, the clock), each failure with its fix.
    Doctor(doctor::DoctorArgs),
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell).
    Completions(shell::CompletionsArgs),
    /// Print the man page (roff), or write one per subcommand into a directory.
    Man(shell::ManArgs),
}

/// The exit statuses, as `--help` lists them.
pub const EXIT_CODES_HELP: &str = "\
Exit status:
  0  done
  1  failed: the work ran and failed (a scan or fit failed or was aborted), or another error
  2  usage: bad arguments, or a request the daemon refused as malformed
  3  no daemon: nothing answers on the address, or the connection broke, or the daemon
     stopped under a command following a reference, scan or fits
  4  busy: the instruments are busy or the daemon is shutting down or full; retry later
  5  not authorised: the API token is missing or wrong, or the request was refused as
     cross-origin or for a wrong Host
  6  refused: the daemon's state does not allow it (no reference, stale reference, scan not
     complete), or no such scan or fit; or the central database refused this store for its
     station (`brdfd sync`: a copy of the station's store, a taken station id)";

/// The exit statuses of [`EXIT_CODES_HELP`].
pub mod exit {
    pub const FAILED: u8 = 1;
    pub const USAGE: u8 = 2;
    pub const NO_DAEMON: u8 = 3;
    pub const BUSY: u8 = 4;
    pub const NOT_AUTHORISED: u8 = 5;
    pub const REFUSED: u8 = 6;
}

/// `BRDFD_TOKEN` is set but holds no token: an authorisation error found before any request
/// (exit status 5, like the daemon's 401).
#[derive(Debug, thiserror::Error)]
#[error(
    "BRDFD_TOKEN does not hold an API token (64 hex digits, as in the token file); unset it to \
     use the token file, or set it to the file's content"
)]
pub struct MalformedTokenEnv;

/// The exit status for an error of [`run`]: the first daemon answer in its chain decides.
pub fn exit_code(err: &anyhow::Error) -> u8 {
    use crate::client::ClientError;
    use crate::sync::SyncError;
    for cause in err.chain() {
        if let Some(
            SyncError::Forked { .. }
            | SyncError::StationTaken { .. }
            | SyncError::StoreHasOtherId { .. }
            | SyncError::Retire { .. }
            | SyncError::Archived { .. },
        ) = cause.downcast_ref::<SyncError>()
        {
            return exit::REFUSED;
        }
        if cause.downcast_ref::<MalformedTokenEnv>().is_some() {
            return exit::NOT_AUTHORISED;
        }
        if cause.downcast_ref::<follow::DaemonGone>().is_some() {
            return exit::NO_DAEMON;
        }
        if let Some(e) = cause.downcast_ref::<ClientError>() {
            return match e {
                ClientError::NotRunning { .. } | ClientError::Transport { .. } => exit::NO_DAEMON,
                ClientError::Contract { .. } => exit::FAILED,
                ClientError::Unauthorized { .. } => exit::NOT_AUTHORISED,
                e if e.is_busy() => exit::BUSY,
                ClientError::Refused { status, .. } => match status {
                    403 | 421 => exit::NOT_AUTHORISED,
                    400 | 413 | 415 | 422 => exit::USAGE,
                    404 | 409 => exit::REFUSED,
                    _ => exit::FAILED,
                },
            };
        }
    }
    exit::FAILED
}

/// Runs one parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Fit(args) => fit::run(&args),
        Command::Crossval(args) => crossval::run(&args),
        Command::Synth(args) => synth::run(&args),
        Command::Validate(args) => validate::run(&args),
        Command::Demo(args) => demo::run(&args),
        Command::Report(args) => report::run(&args),
        Command::Render(args) => render::run(&args),
        Command::ExportFormat(args) => exchange::export(&args),
        Command::ImportFormat(args) => exchange::import(&args),
        Command::Serve(args) => serve::run(&args),
        Command::Reference(args) => measure::reference(&args),
        Command::Scan(args) => measure::scan(&args),
        Command::Scans(args) => scans::scans(&args),
        Command::Show(args) => show::show(&args),
        Command::Refit(args) => refit::refit(&args),
        Command::Abort(args) => status::abort(&args),
        Command::Status(args) => status::status(&args),
        Command::Export(args) => scan_file::export(&args),
        Command::Import(args) => scan_file::import(&args),
        Command::Replay(args) => replay::run(&args),
        Command::Record(args) => record::run(&args),
        Command::Sync(args) => sync::run(&args),
        Command::Completions(args) => shell::completions(&args),
        Command::Man(args) => shell::man(&args),
        Command::Doctor(args) => doctor::run(&args),
        Command::Open(args) => open::run(&args),
    }
}

/// Writes `bytes` to a new file at `path`; an existing file is refused unless `force` (the
/// operator asked to replace it), so an export never silently overwrites a measurement. The
/// rules of [`crate::safe_fs`] hold: never through a link, never onto the store or the token,
/// and `--force` replaces only a plain file.
pub fn write_new_file(path: &std::path::Path, bytes: &[u8], force: bool) -> anyhow::Result<()> {
    crate::safe_fs::write_file(path, bytes, crate::safe_fs::Replace::force(force))?;
    Ok(())
}

/// The folder `--out DIR` names, created if missing and held open; refused if it is a link.
pub fn out_dir(path: &std::path::Path) -> anyhow::Result<crate::safe_fs::Dir> {
    Ok(crate::safe_fs::Dir::create(path)?)
}

/// One file name per sample, for writing several samples into one directory: the sample's
/// slug, with `-2`, `-3`, … where two names give the same slug ("T.Sky blue" and "T.Sky-blue"),
/// so that no sample's file replaces another's.
pub fn distinct_file_stems<'a>(names: impl IntoIterator<Item = &'a str>) -> Vec<String> {
    let mut used: std::collections::HashSet<String> = Default::default();
    names
        .into_iter()
        .map(|name| {
            let base = crate::synth::slug(name);
            let mut stem = base.clone();
            let mut n = 1;
            while !used.insert(stem.to_ascii_lowercase()) {
                n += 1;
                stem = format!("{base}-{n}");
            }
            stem
        })
        .collect()
}

/// `": ERROR"` after a fit's status when the fit recorded an error, else nothing.
pub(crate) fn fit_error_suffix(run: &crate::store::FitRun) -> String {
    run.error
        .as_deref()
        .map(|e| format!(": {e}"))
        .unwrap_or_default()
}

/// An error chain on one line: `outer: inner: root`, with any line breaks inside a message
/// folded, so stderr always gets exactly one line.
pub fn one_line(err: &anyhow::Error) -> String {
    fold_lines(&format!("{err:#}"))
}

fn fold_lines(text: &str) -> String {
    text.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join(" ")
}

/// A clap usage error as one line: the message up to clap's "Usage:" block, folded, with a
/// pointer to `--help`. (Help and version requests are not errors; the caller prints those.)
pub fn usage_error_line(err: &clap::Error) -> String {
    let rendered = err.render().to_string();
    let message: Vec<&str> = rendered
        .lines()
        .take_while(|l| !l.starts_with("Usage:") && !l.starts_with("For more"))
        .collect();
    let line = fold_lines(&message.join("\n"));
    let line = line.strip_prefix("error: ").unwrap_or(&line).to_string();
    format!("{line} (see --help)")
}

#[cfg(test)]
mod file_tests {
    use super::*;

    #[test]
    fn samples_whose_names_slug_alike_get_distinct_files() {
        let stems = distinct_file_stems(["T.Sky blue", "T.Sky-blue", "t.sky blue", "Other"]);
        let lower: std::collections::HashSet<_> = stems.iter().map(|s| s.to_lowercase()).collect();
        assert_eq!(lower.len(), 4, "{stems:?}");
        assert_eq!(stems[0], crate::synth::slug("T.Sky blue"));
    }

    #[test]
    fn an_existing_file_is_replaced_only_with_force() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.json");
        write_new_file(&path, b"first", false).unwrap();
        let e = write_new_file(&path, b"second", false).unwrap_err();
        assert!(e.to_string().contains("--force"), "{e}");
        assert_eq!(std::fs::read(&path).unwrap(), b"first");
        write_new_file(&path, b"third", true).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"third");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_cli_definition_is_consistent() {
        Cli::command().debug_assert();
    }

    #[test]
    fn usage_errors_fold_to_one_line() {
        let e = Cli::try_parse_from(["brdfd", "fit", "--cost", "cf2"]).unwrap_err();
        let line = usage_error_line(&e);
        assert!(!line.contains('\n'));
        assert!(line.contains("--input"), "{line}");
        let e = Cli::try_parse_from(["brdfd", "fit", "--input", "x", "--cost", "cf9"]).unwrap_err();
        let line = usage_error_line(&e);
        assert!(line.contains("unknown cost function \"cf9\""), "{line}");
    }

    #[test]
    fn daemon_answers_map_to_distinct_exit_statuses() {
        use crate::client::ClientError;
        let addr: std::net::SocketAddr = "127.0.0.1:7878".parse().unwrap();
        let refused = |status: u16, kind: &str| ClientError::Refused {
            status,
            kind: kind.into(),
            message: "m".into(),
        };
        let cases = [
            (
                ClientError::NotRunning {
                    addr,
                    hint: String::new(),
                },
                exit::NO_DAEMON,
            ),
            (
                ClientError::Transport {
                    addr,
                    detail: "reset".into(),
                },
                exit::NO_DAEMON,
            ),
            (
                ClientError::Unauthorized {
                    addr,
                    message: "m".into(),
                    token_source: "t".into(),
                },
                exit::NOT_AUTHORISED,
            ),
            (refused(409, "busy"), exit::BUSY),
            (refused(503, "shutting_down"), exit::BUSY),
            (refused(503, ""), exit::BUSY),
            (refused(409, "no_reference"), exit::REFUSED),
            (refused(404, "not_found"), exit::REFUSED),
            (refused(400, "bad_request"), exit::USAGE),
            (refused(415, ""), exit::USAGE),
            (refused(403, ""), exit::NOT_AUTHORISED),
            (refused(500, "store"), exit::FAILED),
        ];
        for (e, code) in cases {
            let text = e.to_string();
            // Wrapped in context, as the commands return it.
            let err = anyhow::Error::new(e).context("scan");
            assert_eq!(exit_code(&err), code, "{text}");
        }
        assert_eq!(
            exit_code(&anyhow::anyhow!("scan 3 failed: timeout")),
            exit::FAILED
        );
        // A malformed BRDFD_TOKEN is an authorisation error, like the daemon's 401.
        assert_eq!(
            exit_code(&anyhow::Error::new(MalformedTokenEnv).context("status")),
            exit::NOT_AUTHORISED
        );
        let codes: std::collections::HashSet<u8> = [
            exit::FAILED,
            exit::USAGE,
            exit::NO_DAEMON,
            exit::BUSY,
            exit::NOT_AUTHORISED,
            exit::REFUSED,
        ]
        .into();
        assert_eq!(codes.len(), 6);
    }

    #[test]
    fn error_chains_fold_to_one_line() {
        let e = anyhow::anyhow!("root\ncause").context("outer");
        assert_eq!(one_line(&e), "outer: root cause");
    }
}
