//! The `brdfd` command line: one clap-derived [`Cli`] with a subcommand per job, and [`run`].
//!
//! Each subcommand lives in its own file with its `Args` struct and a `run` function; adding
//! one (serve, scan, reference, replay, …) is a variant in [`Command`], a file here, and an arm in
//! [`run`]. Errors go up as `anyhow` chains with context; the binary prints them on one line.

use clap::{Parser, Subcommand};

pub mod demo;
pub mod exchange;
pub mod fit;
pub mod report;
pub mod synth;

/// brdfd: spectral BRDF from two handheld instruments (X-Rite MA-T12 + Canon RA-532H).
#[derive(Debug, Parser)]
#[command(name = "brdfd", version, about, propagate_version = true)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

/// Every subcommand.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Fit the spectral Cook–Torrance model to one scan file, without a daemon or database.
    Fit(fit::FitArgs),
    /// Write the eight synthetic example scans and their ground truth to a directory.
    Synth(synth::SynthArgs),
    /// Fit the eight embedded example scans with all three cost functions and compare them.
    Demo(demo::DemoArgs),
    /// Write the study report of stored scans: the paper's figures 4–12 (PNG and SVG) and a
    /// summary (HTML, Markdown) with ΔE00 per sample and cost function, means with 95 % CI and
    /// sign tests.
    Report(report::ReportArgs),
    /// Export stored scans and fits as CGATS.17, X-Rite CxF3, CSV or JSON.
    ExportFormat(exchange::ExportArgs),
    /// Turn an instrument software export (MA-T12 CGATS or CxF3 + SRA CSV) or a brdfd export
    /// into brdfd.scan/1 files.
    ImportFormat(exchange::ImportArgs),
}

/// Runs one parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Fit(args) => fit::run(&args),
        Command::Synth(args) => synth::run(&args),
        Command::Demo(args) => demo::run(&args),
        Command::Report(args) => report::run(&args),
        Command::ExportFormat(args) => exchange::export(&args),
        Command::ImportFormat(args) => exchange::import(&args),
    }
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
    fn error_chains_fold_to_one_line() {
        let e = anyhow::anyhow!("root\ncause").context("outer");
        assert_eq!(one_line(&e), "outer: root cause");
    }
}
