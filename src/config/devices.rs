//! `[devices.ma_t12]` and `[devices.sra]`: how each instrument is reached (real or simulated,
//! which a file must choose) and the settings every instrument has.

use std::path::PathBuf;
use std::time::Duration;

use serde::Deserialize;

use super::check::{Checker, ConfigError, S};

/// `[devices.*]`
#[derive(Debug, Clone, PartialEq)]
pub struct DevicesConfig {
    pub ma_t12: MaT12Config,
    pub sra: SraConfig,
}

/// One `[devices.*]` section: how the instrument is reached (`T`) and the settings every
/// instrument has.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceConfig<T> {
    pub transport: T,
    /// Reply timeout of a measuring command.
    pub timeout: Duration,
    /// Resends of a request after a timeout or a corrupt reply.
    pub retries: u32,
    /// Where the recording tap writes this instrument's traffic; `None` = no recording.
    pub record: Option<PathBuf>,
}

/// `[devices.ma_t12]`
pub type MaT12Config = DeviceConfig<MaT12Transport>;

/// How brdfd reaches the MA-T12.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MaT12Transport {
    /// The simulated instrument, replaying a session file; `None` = the built-in recording.
    Simulated { session: Option<PathBuf> },
    /// USB bulk; `product_id` narrows the search when several X-Rite devices are attached.
    Usb { product_id: Option<u16> },
}

/// `[devices.sra]`
pub type SraConfig = DeviceConfig<SraTransport>;

/// How brdfd reaches the SRA.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SraTransport {
    /// The simulated instrument (over a pseudo-terminal), replaying a session file; `None` =
    /// the built-in recording.
    Simulated { session: Option<PathBuf> },
    /// A serial port, e.g. `/dev/ttyUSB0`.
    Serial { port: String, baud: u32 },
    /// No SRA (`transport = "off"`): a lab with only an MA-T12. References and scans are
    /// measured on the 12 MA-T12 geometries and fitted over them (SCIENCE.md §3).
    Off,
}

impl Default for DevicesConfig {
    /// Both instruments simulated, replaying the built-in recordings.
    fn default() -> Self {
        DevicesConfig {
            ma_t12: MaT12Config {
                transport: MaT12Transport::Simulated { session: None },
                timeout: Duration::from_millis(defaults::TIMEOUT_MS),
                retries: defaults::RETRIES,
                record: None,
            },
            sra: SraConfig {
                transport: SraTransport::Simulated { session: None },
                timeout: Duration::from_millis(defaults::TIMEOUT_MS),
                retries: defaults::RETRIES,
                record: None,
            },
        }
    }
}

/// Defaults of this section, shared by its `Default` and its checks (and written out in
/// `SHIPPED`).
mod defaults {
    /// The measuring commands' reply timeout of drivers/PROTOCOL.md §4.
    pub const TIMEOUT_MS: u64 = 10_000;
    /// drivers/PROTOCOL.md §4: 3 resends, 4 sends in all.
    pub const RETRIES: u32 = 3;
    pub const SRA_PORT: &str = "/dev/ttyUSB0";
    /// drivers/PROTOCOL.md §3: 9600 baud, 8N1.
    pub const SRA_BAUD: u32 = 9600;
}

/// A configuration file must say which instruments it runs: replayed recordings landing in a
/// production store unnoticed is the failure this prevents. (No file at all runs the simulated
/// instruments, loudly: that is the try-it-out default.)
const REQUIRED_TRANSPORT_MA_T12: &str = "must be set: \"usb\" for the instrument, or \"simulated\" \
     to replay a recording (no instrument; every scan is then marked simulated)";
const REQUIRED_TRANSPORT_SRA: &str = "must be set: \"serial\" for the instrument, \"simulated\" \
     to replay a recording (no instrument; every scan is then marked simulated), or \"off\" \
     when the lab has no SRA (scans then have the 12 MA-T12 geometries only)";

fn timeout(ms: u64) -> Result<Duration, String> {
    // Above 10 minutes a dead instrument would hold a scan for longer than any operator waits.
    if (1..=600_000).contains(&ms) {
        Ok(Duration::from_millis(ms))
    } else {
        Err(format!("{ms} is out of range: a timeout is 1 to 600000 ms"))
    }
}

fn retries(n: u32) -> Result<u32, String> {
    if n <= 10 {
        Ok(n)
    } else {
        Err(format!("{n} is out of range: 0 to 10 resends"))
    }
}

/// The full names of the keys every `[devices.*]` section has, for messages.
struct DeviceKeys {
    transport: &'static str,
    session: &'static str,
    timeout_ms: &'static str,
    retries: &'static str,
    record: &'static str,
}

/// The [`DeviceKeys`] of section `$section` (e.g. `"devices.sra"`).
macro_rules! device_keys {
    ($section:literal) => {
        DeviceKeys {
            transport: concat!($section, ".transport"),
            session: concat!($section, ".session"),
            timeout_ms: concat!($section, ".timeout_ms"),
            retries: concat!($section, ".retries"),
            record: concat!($section, ".record"),
        }
    };
}

// ---- Stage 1: the section's shape ----------------------------------------------------------

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawDevices {
    #[serde(default)]
    ma_t12: RawMaT12,
    #[serde(default)]
    sra: RawSra,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawMaT12 {
    transport: S<String>,
    session: S<String>,
    product_id: S<u16>,
    timeout_ms: S<u64>,
    retries: S<u32>,
    record: S<String>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSra {
    transport: S<String>,
    session: S<String>,
    port: S<String>,
    baud: S<u32>,
    timeout_ms: S<u64>,
    retries: S<u32>,
    record: S<String>,
}

// ---- Stage 2: its checks ------------------------------------------------------------------

impl Checker<'_> {
    /// `[devices.*]`: the MA-T12's section, then the SRA's.
    pub(super) fn devices(&self, raw: &RawDevices) -> Result<DevicesConfig, ConfigError> {
        Ok(DevicesConfig {
            ma_t12: self.ma_t12(&raw.ma_t12)?,
            sra: self.sra(&raw.sra)?,
        })
    }

    /// `[devices.ma_t12]`: the transport, then the keys every instrument has.
    fn ma_t12(&self, raw: &RawMaT12) -> Result<MaT12Config, ConfigError> {
        const KEYS: DeviceKeys = device_keys!("devices.ma_t12");
        let usb = self.real_transport(&KEYS, &raw.transport, "usb", REQUIRED_TRANSPORT_MA_T12)?;
        let transport = if usb {
            MaT12Transport::Usb {
                product_id: raw.product_id.as_ref().map(|p| *p.get_ref()),
            }
        } else {
            MaT12Transport::Simulated {
                session: self.path(KEYS.session, &raw.session)?,
            }
        };
        self.device(&KEYS, transport, &raw.timeout_ms, &raw.retries, &raw.record)
    }

    /// `[devices.sra]`: the transport and the serial settings (checked whichever transport is
    /// chosen), then the keys every instrument has.
    fn sra(&self, raw: &RawSra) -> Result<SraConfig, ConfigError> {
        const KEYS: DeviceKeys = device_keys!("devices.sra");
        let off = raw
            .transport
            .as_ref()
            .is_some_and(|t| t.get_ref().trim() == "off");
        let serial =
            !off && self.real_transport(&KEYS, &raw.transport, "serial", REQUIRED_TRANSPORT_SRA)?;
        let port = self.value(
            "devices.sra.port",
            &raw.port,
            defaults::SRA_PORT.into(),
            |p| {
                if p.trim().is_empty() {
                    Err("must name the serial device, e.g. \"/dev/ttyUSB0\"".into())
                } else {
                    Ok(p)
                }
            },
        )?;
        let baud = self.value("devices.sra.baud", &raw.baud, defaults::SRA_BAUD, |b| {
            if (50..=4_000_000).contains(&b) {
                Ok(b)
            } else {
                Err(format!("{b} is not a serial speed: 50 to 4000000 baud"))
            }
        })?;
        let transport = if off {
            SraTransport::Off
        } else if serial {
            SraTransport::Serial { port, baud }
        } else {
            SraTransport::Simulated {
                session: self.path(KEYS.session, &raw.session)?,
            }
        };
        self.device(&KEYS, transport, &raw.timeout_ms, &raw.retries, &raw.record)
    }

    /// A section's `transport`: `true` for the real one (`real`, e.g. "usb"), `false` for
    /// "simulated" (or, when the file need not choose, nothing).
    fn real_transport(
        &self,
        keys: &DeviceKeys,
        raw: &S<String>,
        real: &str,
        required: &'static str,
    ) -> Result<bool, ConfigError> {
        self.value(keys.transport, raw, String::new(), |t| match t.as_str() {
            "" if self.require_transport => Err(required.into()),
            "" => Ok(false),
            "simulated" => Ok(false),
            t if t == real => Ok(true),
            other if keys.transport == "devices.sra.transport" => Err(format!(
                "unknown transport \"{other}\": expected \"simulated\", \"{real}\" or \"off\""
            )),
            other => Err(format!(
                "unknown transport \"{other}\": expected \"simulated\" or \"{real}\""
            )),
        })
    }

    /// The device block every `[devices.*]` section shares: `timeout_ms`, `retries` and
    /// `record`, around the section's checked `transport`.
    fn device<T>(
        &self,
        keys: &DeviceKeys,
        transport: T,
        timeout_ms: &S<u64>,
        retries_raw: &S<u32>,
        record: &S<String>,
    ) -> Result<DeviceConfig<T>, ConfigError> {
        Ok(DeviceConfig {
            transport,
            timeout: self.value(keys.timeout_ms, timeout_ms, defaults::TIMEOUT_MS, timeout)?,
            retries: self.value(keys.retries, retries_raw, defaults::RETRIES, retries)?,
            record: self.path(keys.record, record)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::tests::parse;
    use crate::config::*;

    #[test]
    fn a_file_must_choose_its_instruments() {
        let e = Config::from_toml("", "brdfd.toml").unwrap_err();
        assert!(
            e.to_string().starts_with(
                "brdfd.toml: devices.ma_t12.transport: must be set: \"usb\" for the instrument"
            ),
            "{e}"
        );
        let e =
            Config::from_toml("[devices.ma_t12]\ntransport = \"usb\"\n", "brdfd.toml").unwrap_err();
        assert!(
            e.to_string().contains("devices.sra.transport: must be set"),
            "{e}"
        );
        let c = Config::from_toml(
            "[devices.ma_t12]\ntransport = \"simulated\"\n[devices.sra]\ntransport = \"simulated\"\n",
            "brdfd.toml",
        )
        .unwrap();
        assert_eq!(c, Config::default());
    }

    #[test]
    fn real_transports_and_their_settings() {
        let c = parse(
            "[devices.ma_t12]\ntransport = \"usb\"\nproduct_id = 0x1234\ntimeout_ms = 5000\n\
             [devices.sra]\ntransport = \"serial\"\nport = \"/dev/ttyS1\"\nbaud = 19200\n\
             record = \"sra.session\"\nretries = 0\n",
        )
        .unwrap();
        assert_eq!(
            c.devices.ma_t12.transport,
            MaT12Transport::Usb {
                product_id: Some(0x1234)
            }
        );
        assert_eq!(c.devices.ma_t12.timeout, Duration::from_secs(5));
        assert_eq!(
            c.devices.sra.transport,
            SraTransport::Serial {
                port: "/dev/ttyS1".into(),
                baud: 19200
            }
        );
        assert_eq!(c.devices.sra.retries, 0);
        assert_eq!(c.devices.sra.record, Some(PathBuf::from("sra.session")));
        let c = parse("[devices.sra]\nsession = \"recordings/sra-glossy.session\"\n").unwrap();
        assert_eq!(
            c.devices.sra.transport,
            SraTransport::Simulated {
                session: Some("recordings/sra-glossy.session".into())
            }
        );
        let e = parse("[devices.sra]\ntransport = \"rs232\"\n").unwrap_err();
        assert_eq!(
            e.to_string(),
            "test.toml:2: devices.sra.transport: unknown transport \"rs232\": expected \
             \"simulated\", \"serial\" or \"off\""
        );
        // A lab with only an MA-T12 turns the SRA off; the serial keys are still checked.
        let c = parse("[devices.sra]\ntransport = \"off\"\n").unwrap();
        assert_eq!(c.devices.sra.transport, SraTransport::Off);
        let e = parse("[devices.sra]\ntransport = \"off\"\nbaud = 3\n").unwrap_err();
        assert!(e.to_string().contains("devices.sra.baud"), "{e}");
        let e = parse("[devices.ma_t12]\n\ntimeout_ms = 0\n").unwrap_err();
        assert!(
            matches!(
                &e,
                ConfigError::Invalid {
                    line: Some(3),
                    key: "devices.ma_t12.timeout_ms",
                    ..
                }
            ),
            "{e}"
        );
    }
}
