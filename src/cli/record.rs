//! `brdfd record`: measure one object on both instruments and record every frame, both
//! directions, with timestamps, through the drivers' recording tap into two session files
//! (`<OUT>/<slug>.ma_t12.session`, `<OUT>/<slug>.sra.session`) that `brdfd replay` and the
//! simulated instruments replay. The conversation is the daemon's own (IDENTIFY on connecting,
//! MEASURE-ALL, a FETCH per geometry), so a recording replays strictly.
//!
//! The instruments come from the configuration (`--config`; by default the simulated ones,
//! which makes a recording of the embedded recordings — useful to check the round trip).
//! The daemon must not be running on the same instruments: they take one master at a time.
//! To record everything a running daemon says instead, set `record` under `[devices.*]`.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use drivers::Instrument;
use mock_devices::generate::{REFERENCE_NAME, REFERENCE_NOTE, SAMPLE_NOTE};

use crate::config::{Config, LogLevel};
use crate::service::Devices;

#[derive(Debug, clap::Args)]
pub struct RecordArgs {
    /// The sample's name; without it the white reference tile is measured.
    #[arg(long, value_name = "NAME")]
    pub sample: Option<String>,
    /// Directory for the two session files (created if missing).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// The configuration naming the instruments (default: simulated).
    #[arg(long, short, value_name = "FILE")]
    pub config: Option<PathBuf>,

    /// Print `{"object", "ma_t12_readings", "sra_readings", "sessions"}` instead of lines.
    #[arg(long)]
    pub json: bool,
}

/// The session files a recording of `object` writes in `dir`.
pub fn session_paths(dir: &Path, object: &str) -> [PathBuf; 2] {
    let slug = crate::synth::slug(object);
    [
        dir.join(format!("{slug}.ma_t12.session")),
        dir.join(format!("{slug}.sra.session")),
    ]
}

pub fn run(args: &RecordArgs) -> anyhow::Result<()> {
    let mut config = Config::load_or_default(args.config.as_deref())?;
    crate::cli::serve::init_logging(LogLevel::Warn, config.log.json);
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let (object, note) = match &args.sample {
        Some(s) if s.trim().is_empty() => bail!("--sample: the sample name is empty"),
        Some(s) => (s.trim().to_string(), format!("{SAMPLE_NOTE}{}", s.trim())),
        None => (
            "reference".to_string(),
            format!("{REFERENCE_NOTE}{REFERENCE_NAME}"),
        ),
    };
    if config.devices.sra.transport == crate::config::SraTransport::Off {
        bail!(
            "the SRA is turned off ([devices.sra] transport = \"off\"), and a recording is a \
             pair of sessions, one per instrument: set [devices.sra] transport to \"serial\" \
             (or \"simulated\") to record"
        );
    }
    let [m_path, s_path] = session_paths(&args.out, &object);
    config.devices.ma_t12.record = Some(m_path.clone());
    config.devices.sra.record = Some(s_path.clone());
    let readings = crate::cli::serve::runtime()?.block_on(async {
        let devices =
            Devices::from_config(&config.devices, &mock_devices::ReplayOptions::lenient())?;
        let sra = devices.sra.as_ref().expect("the SRA is on (checked above)");
        let (m, s) = tokio::join!(devices.ma_t12.measure_all(), sra.measure_all());
        let recorders = devices.recorders.clone();
        devices.shutdown().await?;
        drop(recorders);
        anyhow::Ok((m?, s?))
    })?;
    // The tap wrote the header when it was created; add the object's note so that `replay`
    // knows what was measured.
    for (path, instrument) in [(&m_path, Instrument::MaT12), (&s_path, Instrument::Sra)] {
        add_note(path, &note).with_context(|| format!("{instrument}: {}", path.display()))?;
    }
    if args.json {
        println!(
            "{}",
            serde_json::json!({
                "object": object,
                "ma_t12_readings": readings.0.len(),
                "sra_readings": readings.1.len(),
                "sessions": [m_path, s_path],
            })
        );
        return Ok(());
    }
    println!(
        "recorded {} MA-T12 and {} SRA readings of {object}:\n  {}\n  {}",
        readings.0.len(),
        readings.1.len(),
        m_path.display(),
        s_path.display()
    );
    Ok(())
}

/// Inserts a `note` line after the header lines of a session file.
fn add_note(path: &Path, note: &str) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(path)?;
    let mut out = String::with_capacity(text.len() + note.len() + 8);
    let mut inserted = false;
    for line in text.lines() {
        let header = line.starts_with("brdfd-session") || line.starts_with("device ");
        if !inserted && !header {
            out.push_str(&format!("note {note}\n"));
            inserted = true;
        }
        out.push_str(line);
        out.push('\n');
    }
    if !inserted {
        out.push_str(&format!("note {note}\n"));
    }
    drivers::session::Session::parse(&out).context("the recorded session does not parse")?;
    crate::safe_fs::write_file(path, out.as_bytes(), crate::safe_fs::Replace::OwnKind)?;
    Ok(())
}
