//! The two instruments as the service sees them: a [`Devices`] pair of driver handles, built
//! from the `[devices.*]` configuration — the simulated instruments of `mock-devices` replaying
//! a session (the embedded recordings by default), or the real USB and serial transports — with
//! the drivers' recording tap around every connection when `record` is set.
//!
//! The service only ever talks to [`drivers::DriverHandle`]s, so tests build a [`Devices`]
//! from any transport factory they like (faults, a cable that can be pulled).

use std::path::{Path, PathBuf};

use drivers::mat12::usb::{RusbBulk, UsbIds};
use drivers::sra::serial::open_serial;
use drivers::{DriverConfig, DriverHandle, Instrument, Recorder, Tap};
use mock_devices::{Cue, MockError, ReplayOptions, ReplayReport, Script, SimMat12, SimSra};

use crate::config::{DevicesConfig, MaT12Transport, SraTransport};

/// Why the instruments could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum DeviceSetupError {
    /// A session file for a simulated instrument could not be read.
    #[error("cannot read the {instrument} session file {path}: {source}; check [devices] session")]
    ReadSession {
        instrument: Instrument,
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A session file or the replay options are unusable.
    #[error("simulated {instrument}: {source}")]
    Simulation {
        instrument: Instrument,
        #[source]
        source: MockError,
    },
    /// The recording tap's session file could not be created.
    #[error("cannot create the {instrument} recording {path}: {source}; check [devices] record")]
    Record {
        instrument: Instrument,
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// The simulated instruments behind a [`Devices`], kept for their replay reports.
#[derive(Debug, Clone)]
pub struct Simulators {
    pub ma_t12: Option<SimMat12>,
    pub sra: Option<SimSra>,
}

/// Both instruments' driver tasks.
#[derive(Debug, Clone)]
pub struct Devices {
    pub ma_t12: DriverHandle,
    /// `None` when the SRA is turned off (`[devices.sra] transport = "off"`): measurements
    /// then have the 12 MA-T12 geometries only.
    pub sra: Option<DriverHandle>,
    /// The simulated instruments, where simulated.
    pub simulators: Simulators,
    /// The recording taps' session writers, to be finished at shutdown.
    pub recorders: Vec<Recorder>,
}

/// A recorded session's object as provenance names it: the embedded recording's file stem and
/// its sample when it is one of those, else the sample (or tile) the session's notes name.
fn recording_name(object: Option<&mock_devices::ScriptObject>) -> String {
    use mock_devices::ScriptObject;
    match object {
        Some(ScriptObject::Sample(name)) => match mock_devices::recordings::by_name(name) {
            Some(r) => format!("{} ({name})", r.name),
            None => format!("the recording of \"{name}\""),
        },
        Some(ScriptObject::Reference) => {
            format!(
                "{} (reference tile)",
                mock_devices::recordings::reference().name
            )
        }
        Some(ScriptObject::Unknown) => "a recording whose notes name no object".into(),
        None => "nothing (the recording has no measurement left)".into(),
    }
}

impl Devices {
    /// Both handles from drivers started elsewhere (tests).
    pub fn new(ma_t12: DriverHandle, sra: DriverHandle) -> Devices {
        Devices {
            ma_t12,
            sra: Some(sra),
            simulators: Simulators {
                ma_t12: None,
                sra: None,
            },
            recorders: Vec::new(),
        }
    }

    /// Simulated instruments replaying the given scripts, with the drivers' default
    /// timeouts, and no SRA (`sra` = `None`), or both ([`Devices::simulated`]).
    pub fn simulated_mat12_only(
        ma_t12: Script,
        options: &ReplayOptions,
    ) -> Result<Devices, DeviceSetupError> {
        let sim_m = sim_mat12(ma_t12, options)?;
        Ok(Devices {
            ma_t12: spawn_mat12_with(sim_m.factory(), DriverConfig::default(), None),
            sra: None,
            simulators: Simulators {
                ma_t12: Some(sim_m),
                sra: None,
            },
            recorders: Vec::new(),
        })
    }

    /// Whether the SRA takes part in measurements (it is not turned off).
    pub fn has_sra(&self) -> bool {
        self.sra.is_some()
    }

    /// The driver handles of the instruments in use, MA-T12 first.
    pub fn handles(&self) -> impl Iterator<Item = &DriverHandle> {
        std::iter::once(&self.ma_t12).chain(self.sra.as_ref())
    }

    /// Simulated instruments replaying the given scripts, with the drivers' default timeouts.
    pub fn simulated(
        ma_t12: Script,
        sra: Script,
        options: &ReplayOptions,
        record: [Option<&Path>; 2],
    ) -> Result<Devices, DeviceSetupError> {
        let sim_m = sim_mat12(ma_t12, options)?;
        let sim_s =
            SimSra::new(sra, options.clone()).map_err(|source| DeviceSetupError::Simulation {
                instrument: Instrument::Sra,
                source,
            })?;
        let mut recorders = Vec::new();
        let ma_t12 = spawn_mat12_with(
            sim_m.factory(),
            DriverConfig::default(),
            recorder(Instrument::MaT12, record[0], &mut recorders)?,
        );
        let sra = spawn_sra_with(
            sim_s.factory(),
            DriverConfig::default(),
            recorder(Instrument::Sra, record[1], &mut recorders)?,
        );
        Ok(Devices {
            ma_t12,
            sra: Some(sra),
            simulators: Simulators {
                ma_t12: Some(sim_m),
                sra: Some(sim_s),
            },
            recorders,
        })
    }

    /// The instruments the configuration describes. Simulated instruments replay with
    /// `options` (the daemon uses lenient matching, so that any sequence of references and
    /// scans gets answers; `brdfd replay` uses strict).
    pub fn from_config(
        config: &DevicesConfig,
        options: &ReplayOptions,
    ) -> Result<Devices, DeviceSetupError> {
        let mut recorders = Vec::new();
        let mut simulators = Simulators {
            ma_t12: None,
            sra: None,
        };
        let m = &config.ma_t12;
        let m_cfg = DriverConfig {
            measure_timeout: m.timeout,
            max_resends: m.retries,
            ..DriverConfig::default()
        };
        let m_rec = recorder(Instrument::MaT12, m.record.as_deref(), &mut recorders)?;
        let ma_t12 = match &m.transport {
            MaT12Transport::Simulated { session } => {
                let script = script(Instrument::MaT12, session.as_deref())?;
                let sim = sim_mat12(script, options)?;
                let handle = spawn_mat12_with(sim.factory(), m_cfg, m_rec);
                simulators.ma_t12 = Some(sim);
                handle
            }
            MaT12Transport::Usb { product_id } => {
                let ids = UsbIds {
                    product_id: *product_id,
                    ..UsbIds::default()
                };
                spawn_mat12_with(move || RusbBulk::open(ids), m_cfg, m_rec)
            }
        };
        let s = &config.sra;
        let s_cfg = DriverConfig {
            measure_timeout: s.timeout,
            max_resends: s.retries,
            ..DriverConfig::default()
        };
        let s_rec = match s.transport {
            SraTransport::Off => None,
            _ => recorder(Instrument::Sra, s.record.as_deref(), &mut recorders)?,
        };
        let sra = match &s.transport {
            SraTransport::Off => None,
            SraTransport::Simulated { session } => {
                let script = script(Instrument::Sra, session.as_deref())?;
                let sim = SimSra::new(script, options.clone()).map_err(|source| {
                    DeviceSetupError::Simulation {
                        instrument: Instrument::Sra,
                        source,
                    }
                })?;
                let handle = spawn_sra_with(sim.factory(), s_cfg, s_rec);
                simulators.sra = Some(sim);
                Some(handle)
            }
            SraTransport::Serial { port, baud } => {
                let (port, baud) = (port.clone(), *baud);
                Some(spawn_sra_with(
                    move || open_serial(&port, baud),
                    s_cfg,
                    s_rec,
                ))
            }
        };
        Ok(Devices {
            ma_t12,
            sra,
            simulators,
            recorders,
        })
    }

    /// The handle for one instrument; `None` for the SRA when it is turned off.
    pub fn handle(&self, instrument: Instrument) -> Option<&DriverHandle> {
        match instrument {
            Instrument::MaT12 => Some(&self.ma_t12),
            Instrument::Sra => self.sra.as_ref(),
        }
    }

    /// Simulated instruments replaying leniently (as under `brdfd serve`) answer the next
    /// measurement from their recording of this sample (`None`: of the reference tile), so
    /// that what the operator scans is what they see. A sample with no recording gets the
    /// next recording in the playlist, as before, and the log says so. Real instruments are
    /// not touched.
    ///
    /// Returns, when an instrument is simulated, which recording will answer, as the scan's
    /// provenance says it (`simulated — replayed from synthetic-t-sky-blue (T.Sky blue)`).
    pub fn cue_simulators(&self, sample: Option<&str>) -> Option<String> {
        let what = sample.map_or_else(
            || "the reference tile".to_string(),
            |s| format!("sample \"{s}\""),
        );
        let cued = [
            (
                Instrument::MaT12,
                self.simulators.ma_t12.as_ref().map(|s| s.cue(sample)),
            ),
            (
                Instrument::Sra,
                self.simulators.sra.as_ref().map(|s| s.cue(sample)),
            ),
        ];
        for (instrument, cue) in cued {
            match cue {
                Some(Cue::Cued { session }) => tracing::debug!(
                    %instrument,
                    session,
                    "the simulated instrument answers {what} from its recording"
                ),
                Some(Cue::NoRecording { sessions }) => tracing::info!(
                    %instrument,
                    "the simulated instrument has no recording of {what}: it answers with the \
                     next recording of its playlist ({sessions} sessions)"
                ),
                Some(Cue::Strict) | None => {}
            }
        }
        let answering = [
            self.simulators.ma_t12.as_ref().map(|s| s.answering()),
            self.simulators.sra.as_ref().map(|s| s.answering()),
        ];
        let named: Vec<String> = answering
            .into_iter()
            .flatten()
            .map(|a| recording_name(a.as_ref().map(|(_, object)| object)))
            .collect();
        match named.as_slice() {
            [] => None,
            [one] => Some(format!("simulated — replayed from {one}")),
            [a, b] if a == b => Some(format!("simulated — replayed from {a}")),
            [a, b] => Some(format!(
                "simulated — replayed from {a} (MA-T12) and {b} (RA-532H)"
            )),
            more => Some(format!("simulated — replayed from {}", more.join(", "))),
        }
    }

    /// The simulated instruments' replay reports (strict-mode mismatches, faults fired).
    pub fn replay_reports(&self) -> Vec<(Instrument, ReplayReport)> {
        let mut out = Vec::new();
        if let Some(s) = &self.simulators.ma_t12 {
            out.push((Instrument::MaT12, s.report()));
        }
        if let Some(s) = &self.simulators.sra {
            out.push((Instrument::Sra, s.report()));
        }
        out
    }

    /// Stops both driver tasks (waiting for their threads to close the connections) and
    /// finishes the recordings. Returns the first recording error, if any.
    pub async fn shutdown(self) -> std::io::Result<()> {
        self.ma_t12.shutdown().await;
        if let Some(sra) = self.sra {
            sra.shutdown().await;
        }
        let mut first = Ok(());
        for r in &self.recorders {
            let done = r.finish();
            if first.is_ok() {
                first = done;
            }
        }
        first
    }
}

/// The script a simulated instrument replays: the session file given, or every embedded
/// recording back to back (the Munsell N9 reference, then the eight samples).
fn script(instrument: Instrument, session: Option<&Path>) -> Result<Script, DeviceSetupError> {
    let sim_err = |source| DeviceSetupError::Simulation { instrument, source };
    match session {
        None => mock_devices::recordings::playlist(instrument).map_err(sim_err),
        Some(path) => {
            let text =
                std::fs::read_to_string(path).map_err(|source| DeviceSetupError::ReadSession {
                    instrument,
                    path: path.to_path_buf(),
                    source,
                })?;
            Script::parse(&text).map_err(sim_err)
        }
    }
}

/// The simulated MA-T12 replaying `script`.
fn sim_mat12(script: Script, options: &ReplayOptions) -> Result<SimMat12, DeviceSetupError> {
    SimMat12::new(script, options.clone()).map_err(|source| DeviceSetupError::Simulation {
        instrument: Instrument::MaT12,
        source,
    })
}

/// The next event of a driver's channel, or never when there is no driver (the SRA turned
/// off), for a `select!` branch over an optional instrument.
pub(crate) async fn recv_if_present(
    rx: &mut Option<tokio::sync::broadcast::Receiver<drivers::Event>>,
) -> Result<drivers::Event, tokio::sync::broadcast::error::RecvError> {
    match rx {
        Some(rx) => rx.recv().await,
        None => std::future::pending().await,
    }
}

fn recorder(
    instrument: Instrument,
    path: Option<&Path>,
    all: &mut Vec<Recorder>,
) -> Result<Option<Recorder>, DeviceSetupError> {
    let Some(path) = path else { return Ok(None) };
    let notes = vec![format!("recorded by brdfd {}", env!("CARGO_PKG_VERSION"))];
    // A recording from an earlier run is moved aside, never truncated.
    rotate_aside(path).map_err(|source| DeviceSetupError::Record {
        instrument,
        path: path.to_path_buf(),
        source,
    })?;
    let r =
        Recorder::create(path, instrument, &notes).map_err(|source| DeviceSetupError::Record {
            instrument,
            path: path.to_path_buf(),
            source,
        })?;
    all.push(r.clone());
    Ok(Some(r))
}

/// Moves an existing file at `path` to `STEM.YYYYMMDDTHHMMSSZ.EXT` beside it (with a counter if
/// that exists too), so that a new recording never overwrites an old one.
pub fn rotate_aside(path: &Path) -> std::io::Result<Option<PathBuf>> {
    if std::fs::symlink_metadata(path).is_err() {
        return Ok(None);
    }
    let stamp = jiff::Timestamp::now()
        .strftime("%Y%m%dT%H%M%SZ")
        .to_string();
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let ext = path
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    for n in 0..1000 {
        let suffix = if n == 0 {
            String::new()
        } else {
            format!("-{n}")
        };
        let aside = path.with_file_name(format!("{stem}.{stamp}{suffix}{ext}"));
        if std::fs::symlink_metadata(&aside).is_err() {
            std::fs::rename(path, &aside)?;
            tracing::info!(from = %path.display(), to = %aside.display(), "kept the previous recording");
            return Ok(Some(aside));
        }
    }
    Err(std::io::Error::other(
        "a thousand recordings with the same timestamp",
    ))
}

/// Starts the MA-T12 driver, with every connection the factory opens wrapped in the tap when
/// recording.
pub fn spawn_mat12_with<T, F>(
    mut factory: F,
    config: DriverConfig,
    recorder: Option<Recorder>,
) -> DriverHandle
where
    T: drivers::UsbBulk,
    F: FnMut() -> Result<T, drivers::TransportError> + Send + 'static,
{
    match recorder {
        None => drivers::spawn_mat12(factory, config),
        Some(r) => drivers::spawn_mat12(move || Ok(Tap::new(factory()?, r.clone())), config),
    }
}

/// Starts the SRA driver, with every connection wrapped in the tap when recording.
pub fn spawn_sra_with<T, F>(
    mut factory: F,
    config: DriverConfig,
    recorder: Option<Recorder>,
) -> DriverHandle
where
    T: drivers::SerialStream,
    F: FnMut() -> Result<T, drivers::TransportError> + Send + 'static,
{
    match recorder {
        None => drivers::spawn_sra(factory, config),
        Some(r) => drivers::spawn_sra(move || Ok(Tap::new(factory()?, r.clone())), config),
    }
}

#[cfg(test)]
mod tests {
    use super::rotate_aside;

    #[test]
    fn a_recording_is_moved_aside_under_its_utc_timestamp() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("session.jsonl");
        assert_eq!(rotate_aside(&path).unwrap(), None, "nothing to move");
        std::fs::write(&path, "first").unwrap();
        let before = jiff::Timestamp::now().as_second();
        let aside = rotate_aside(&path).unwrap().expect("moved aside");
        let after = jiff::Timestamp::now().as_second();
        assert!(!path.exists());
        assert_eq!(std::fs::read_to_string(&aside).unwrap(), "first");
        let name = aside.file_name().unwrap().to_str().unwrap();
        let stamp = name
            .strip_prefix("session.")
            .and_then(|s| s.strip_suffix(".jsonl"))
            .expect(name);
        // STEM.YYYYMMDDTHHMMSSZ.EXT, in UTC, between the two readings of the clock.
        let at: jiff::Timestamp = jiff::fmt::strtime::parse("%Y%m%dT%H%M%SZ", stamp)
            .and_then(|t| t.to_datetime())
            .and_then(|t| jiff::tz::TimeZone::UTC.to_timestamp(t))
            .expect(stamp);
        assert!((before..=after).contains(&at.as_second()), "{stamp}");
        // A second one in the same second gets a counter, never overwriting the first.
        std::fs::write(&path, "second").unwrap();
        let again = rotate_aside(&path).unwrap().expect("moved aside");
        assert_ne!(again, aside);
        assert_eq!(std::fs::read_to_string(&aside).unwrap(), "first");
        assert_eq!(std::fs::read_to_string(&again).unwrap(), "second");
    }
}
