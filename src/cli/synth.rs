//! `brdfd synth`: write the eight synthetic example scans and their ground truth.
//!
//! This is how `tests/data/` is generated: `brdfd synth --out tests/data` for the noise-free
//! scans and `brdfd synth --out tests/data --noise 0.01` for the 1 % noise ones. With
//! `--sessions`, the same readings are also written as device session files (the frames the
//! drivers and an instrument speaking `drivers/PROTOCOL.md` would exchange), ready for
//! `brdfd replay`.

use std::path::{Path, PathBuf};

use anyhow::Context;

use mock_devices::generate::{GenerateOptions, Readings, SessionPair};
use mock_devices::{generate_reference_session, generate_sample_session};

use crate::scan::DeviceReadings;
use crate::synth::{GroundTruth, SraResponse, SynthOptions, paper_samples, slug, synth_scan};

#[derive(Debug, clap::Args)]
pub struct SynthArgs {
    /// Directory to write into (created if missing). Per sample: `<slug>.scan.json` (noise-free)
    /// or `<slug>.noisy.scan.json` (with --noise), and `<slug>.truth.json`, the parameters.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,

    /// Relative σ of the multiplicative Gaussian noise on every device reading, sample and
    /// reference alike (0.01 = 1 %); 0 writes noise-free scans.
    #[arg(long, value_name = "σ", default_value_t = 0.0)]
    pub noise: f64,

    /// What the simulated SRA reads: `band-mean` (the mean of the true spectral BRDF over the
    /// 31 bands, the paper's assumption) or `luminance` (its luminance under CIE illuminant C
    /// and the 2° V(λ), what a gloss meter reads; fit such scans with `--sra luminance`).
    #[arg(long, value_name = "band-mean|luminance", default_value_t = SraResponse::BandMean)]
    pub sra_response: SraResponse,

    /// Seed of the noise; sample i (0–7, in the listed order) uses seed + i.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub seed: u64,

    /// Also write device session files for `brdfd replay`: `n9.{ma_t12,sra}.session` (the
    /// reference readings of the first sample's scan) and `<slug>.{ma_t12,sra}.session` per
    /// sample. Replay them with `brdfd replay DIR/n9.*.session DIR/<slug>.*.session`.
    #[arg(long)]
    pub sessions: bool,

    /// Print one JSON object per sample (`{"sample", "scan", "truth", "sessions"}`) instead of lines.
    #[arg(long)]
    pub json: bool,
}

/// The file names of one sample's scan and truth for a given noise level.
pub fn file_names(truth: &GroundTruth, noisy: bool) -> (String, String) {
    let s = slug(&truth.sample);
    let scan = if noisy {
        format!("{s}.noisy.scan.json")
    } else {
        format!("{s}.scan.json")
    };
    (scan, format!("{s}.truth.json"))
}

pub fn run(args: &SynthArgs) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating output directory {}", args.out.display()))?;
    for (i, truth) in paper_samples().iter().enumerate() {
        let opts = SynthOptions {
            noise: args.noise,
            seed: args.seed.wrapping_add(i as u64),
            sra_response: args.sra_response,
            ..SynthOptions::default()
        };
        let scan = synth_scan(truth, &opts)?;
        let (scan_name, truth_name) = file_names(truth, args.noise > 0.0);
        let text = scan.to_json_pretty()?;
        crate::safe_fs::write_file(
            &args.out.join(&scan_name),
            text.as_bytes(),
            crate::safe_fs::Replace::OwnKind,
        )?;
        write_truth(&args.out.join(&truth_name), truth)?;
        if !args.json {
            println!("{}  {}  {}", truth.sample, scan_name, truth_name);
        }
        let mut sessions = Vec::new();
        if args.sessions {
            if i == 0 {
                let pair = generate_reference_session(
                    &device_readings(
                        &scan
                            .reference
                            .as_ref()
                            .expect("synthetic scans have an N9 reference")
                            .readings,
                    ),
                    &GenerateOptions::default(),
                )?;
                sessions.extend(write_sessions(&args.out, "n9", &pair, args.json)?);
            }
            let pair = generate_sample_session(
                &truth.sample,
                &device_readings(&scan.readings),
                &GenerateOptions::default(),
            )?;
            sessions.extend(write_sessions(
                &args.out,
                &slug(&truth.sample),
                &pair,
                args.json,
            )?);
        }
        if args.json {
            println!(
                "{}",
                serde_json::json!({
                    "sample": truth.sample,
                    "scan": args.out.join(&scan_name),
                    "truth": args.out.join(&truth_name),
                    "sessions": sessions,
                })
            );
        }
    }
    Ok(())
}

/// A scan's readings in the session generator's form (both in geometry-table order).
fn device_readings(readings: &DeviceReadings) -> Readings {
    Readings {
        ma_t12: readings.ma_t12,
        sra: readings.sra.expect("synthetic scans have SRA readings"),
    }
}

fn write_sessions(
    dir: &Path,
    stem: &str,
    pair: &SessionPair,
    quiet: bool,
) -> anyhow::Result<Vec<std::path::PathBuf>> {
    let mut written = Vec::new();
    for (device, session) in [("ma_t12", &pair.ma_t12), ("sra", &pair.sra)] {
        let path = dir.join(format!("{stem}.{device}.session"));
        crate::safe_fs::write_file(
            &path,
            session.to_text().as_bytes(),
            crate::safe_fs::Replace::OwnKind,
        )?;
        if !quiet {
            println!("  {}", path.display());
        }
        written.push(path);
    }
    Ok(written)
}

fn write_truth(path: &Path, truth: &GroundTruth) -> anyhow::Result<()> {
    let mut text = serde_json::to_string_pretty(truth)?;
    text.push('\n');
    crate::safe_fs::write_file(path, text.as_bytes(), crate::safe_fs::Replace::OwnKind)?;
    Ok(())
}
