//! The instrument-independent meaning of the protocol: what brdfd asks an instrument
//! ([`Request`]), what an instrument answers ([`Response`]), the values carried (identity,
//! status, readings), the framing verdict every codec returns ([`Check`]), the codec trait
//! ([`Codec`]) and the commands as small pure types ([`Command`]: id, `to_bytes`,
//! `parse_response`).
//!
//! The bytes live in the codecs (`mat12::codec`, `sra::codec`), one file per instrument, so that a
//! vendor's real protocol can replace one file without touching the driver, the tap or the mock
//! devices. Everything here is pure: no I/O, no clocks.

use std::fmt;

use bytes::{Buf, BytesMut};

/// Number of spectral bands in an MA-T12 reading: 400–700 nm every 10 nm (SCIENCE.md §1).
pub const BANDS: usize = 31;

/// CRC-16/IBM-3740, also called CRC-16/CCITT-FALSE: polynomial 0x1021, initial value 0xFFFF,
/// no reflection, no final XOR. Check value for ASCII `123456789` is 0x29B1. Both codecs use it.
pub const CRC16: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_IBM_3740);

/// The MA-T12's 12 geometry names in SCIENCE.md §2 order (the wire codes are in
/// `mat12::codec`).
pub const MAT12_GEOMETRIES: [&str; 12] = [
    "15as-45", "15as-30", "15as-15", "15as15", "15as45", "15as80", "45as-15", "45as15", "45as25",
    "45as45", "45as75", "45as110",
];

/// The SRA's 2 geometry names in SCIENCE.md §2 order (the wire codes are in `sra::codec`).
pub const SRA_GEOMETRIES: [&str; 2] = ["sra-20", "sra-60"];

/// The two instruments brdfd drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Instrument {
    /// X-Rite MA-T12 multi-angle spectrophotometer, USB bulk.
    MaT12,
    /// Canon RA-532H surface reflectance analyser ("SRA"), serial line.
    Sra,
}

impl Instrument {
    /// The key used for the instrument in session files, scan files and the store.
    pub const fn key(self) -> &'static str {
        match self {
            Instrument::MaT12 => "ma_t12",
            Instrument::Sra => "sra",
        }
    }

    /// The instrument for a key written by [`Instrument::key`].
    pub fn from_key(key: &str) -> Option<Instrument> {
        match key {
            "ma_t12" => Some(Instrument::MaT12),
            "sra" => Some(Instrument::Sra),
            _ => None,
        }
    }

    /// The wire geometry names, in SCIENCE.md §2 order.
    pub fn geometries(self) -> &'static [&'static str] {
        match self {
            Instrument::MaT12 => &MAT12_GEOMETRIES,
            Instrument::Sra => &SRA_GEOMETRIES,
        }
    }

    /// The interned name if `name` is one of this instrument's geometries.
    pub fn geometry(self, name: &str) -> Option<&'static str> {
        self.geometries().iter().copied().find(|g| *g == name)
    }
}

impl fmt::Display for Instrument {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Instrument::MaT12 => "X-Rite MA-T12",
            Instrument::Sra => "Canon RA-532H (SRA)",
        })
    }
}

/// Who the instrument says it is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Identity {
    /// Model name as the instrument reports it.
    pub model: String,
    /// Serial number.
    pub serial: String,
    /// Firmware version.
    pub firmware: String,
}

impl fmt::Display for Identity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} serial {} firmware {}",
            self.model, self.serial, self.firmware
        )
    }
}

/// What the instrument is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeviceState {
    /// Calibrated and idle: a measurement can start.
    Ready,
    /// A measurement or calibration is running.
    Busy,
    /// The white/reference calibration is missing or expired: calibrate before measuring.
    NeedsCalibration,
}

/// Reply to a status request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Status {
    /// What the instrument is doing: ready, busy, or in need of calibration.
    pub state: DeviceState,
    /// Battery charge, percent (0–100). Both instruments are handheld.
    pub battery_percent: u8,
}

impl Status {
    /// A status read off the wire: a battery charge over 100 % makes the frame malformed.
    pub(crate) fn parsed(state: DeviceState, battery_percent: u8) -> Result<Status, FrameError> {
        if battery_percent > 100 {
            return Err(FrameError::malformed(format!(
                "STATUS battery {battery_percent}% is over 100%"
            )));
        }
        Ok(Status {
            state,
            battery_percent,
        })
    }

    /// Refuses a battery charge over 100 % before it goes on the wire to `instrument`.
    pub(crate) fn check_encodable(&self, instrument: Instrument) -> Result<(), EncodeError> {
        if self.battery_percent > 100 {
            return Err(EncodeError::BadField {
                instrument,
                field: "battery_percent",
                value: self.battery_percent.to_string(),
                why: "a percentage is at most 100",
            });
        }
        Ok(())
    }
}

/// The value of one reading, as the instrument reports it (no processing).
// A spectrum is 248 bytes inline: readings stay `Copy` and allocation-free; they are moved a few
// dozen times per scan, so boxing would buy nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ReadingValue {
    /// MA-T12: reflectance factor (0–1 scale, may exceed 1 near the specular direction) in
    /// 31 bands, 400–700 nm every 10 nm.
    Reflectance([f64; BANDS]),
    /// SRA: the instrument's achromatic 1D-BRDF intensity at the geometry.
    Intensity(f64),
}

/// One reading at one geometry. The codecs only produce readings from frames with a valid
/// checksum whose values are all finite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    /// The geometry's wire name (SCIENCE.md §2), e.g. `15as-45` or `sra-20`.
    pub geometry: &'static str,
    /// The value measured at the geometry.
    pub value: ReadingValue,
}

impl Reading {
    /// Whether two readings are identical bit for bit (`PartialEq` on f64 says -0 == 0).
    pub fn bit_eq(&self, other: &Reading) -> bool {
        self.geometry == other.geometry
            && match (&self.value, &other.value) {
                (ReadingValue::Reflectance(a), ReadingValue::Reflectance(b)) => {
                    a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
                }
                (ReadingValue::Intensity(a), ReadingValue::Intensity(b)) => {
                    a.to_bits() == b.to_bits()
                }
                _ => false,
            }
    }
}

/// A reading together with the reply frame that carried it, byte for byte as received: what the
/// driver hands out (in [`crate::Event::Reading`] and from the `measure_*_received` commands) so
/// that the bytes an instrument sent can be kept for forensics — when a vendor's real codec is
/// written, a stored frame shows what actually arrived, not what brdfd's codec would have sent.
#[derive(Debug, Clone, PartialEq)]
pub struct ReceivedReading {
    /// The reading decoded from [`ReceivedReading::raw`].
    pub reading: Reading,
    /// The whole validated reply frame as it came off the wire: for the MA-T12 the message from
    /// its `MT` magic to its CRC, for the SRA the line from its `!` to its `\r\n`. Bytes dropped
    /// before it (garbage, damaged frames) are not included.
    pub raw: Vec<u8>,
}

impl fmt::Display for Reading {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.value {
            ReadingValue::Reflectance(v) => write!(
                f,
                "{} reflectance 400nm {} 550nm {} 700nm {}",
                self.geometry, v[0], v[15], v[30]
            ),
            ReadingValue::Intensity(v) => write!(f, "{} intensity {}", self.geometry, v),
        }
    }
}

/// The kinds of request, for error replies that say which request failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RequestKind {
    /// IDENTIFY: who the instrument is.
    Identify,
    /// STATUS: state and battery.
    Status,
    /// CALIBRATE: the white/reference calibration.
    Calibrate,
    /// MEASURE-ALL: every geometry in one trigger.
    MeasureAll,
    /// FETCH: one buffered result of MEASURE-ALL.
    Fetch,
    /// MEASURE-ONE: one geometry now.
    MeasureOne,
    /// ABORT: stop whatever is running.
    Abort,
}

impl RequestKind {
    /// Upper-case name used in PROTOCOL.md and in session-file comments.
    pub const fn name(self) -> &'static str {
        match self {
            RequestKind::Identify => "IDENTIFY",
            RequestKind::Status => "STATUS",
            RequestKind::Calibrate => "CALIBRATE",
            RequestKind::MeasureAll => "MEASURE-ALL",
            RequestKind::Fetch => "FETCH",
            RequestKind::MeasureOne => "MEASURE-ONE",
            RequestKind::Abort => "ABORT",
        }
    }
}

impl fmt::Display for RequestKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A request from brdfd to an instrument. Every request is idempotent, so a retry is a
/// byte-identical resend (PROTOCOL.md, "Retries").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Request {
    /// Ask who the instrument is (model, serial, firmware).
    Identify,
    /// Ask for the instrument's state and battery charge.
    Status,
    /// Take the white/reference calibration on the instrument's own tile.
    Calibrate,
    /// Measure every geometry in one trigger; the instrument buffers the results.
    MeasureAll,
    /// Send the buffered result of the last MEASURE-ALL for one geometry.
    Fetch {
        /// The geometry's wire name.
        geometry: &'static str,
    },
    /// Measure one geometry now and send its result.
    MeasureOne {
        /// The geometry's wire name.
        geometry: &'static str,
    },
    /// Stop whatever is running; discard buffered results.
    Abort,
}

impl Request {
    /// Which kind of request this is (for error replies and messages).
    pub const fn kind(&self) -> RequestKind {
        match self {
            Request::Identify => RequestKind::Identify,
            Request::Status => RequestKind::Status,
            Request::Calibrate => RequestKind::Calibrate,
            Request::MeasureAll => RequestKind::MeasureAll,
            Request::Fetch { .. } => RequestKind::Fetch,
            Request::MeasureOne { .. } => RequestKind::MeasureOne,
            Request::Abort => RequestKind::Abort,
        }
    }

    /// The geometry the request is about, if any.
    pub const fn geometry(&self) -> Option<&'static str> {
        match self {
            Request::Fetch { geometry } | Request::MeasureOne { geometry } => Some(geometry),
            _ => None,
        }
    }
}

impl fmt::Display for Request {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.geometry() {
            Some(g) => write!(f, "{} {}", self.kind(), g),
            None => write!(f, "{}", self.kind()),
        }
    }
}

/// Why an instrument refused a request (the error reply of PROTOCOL.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorCode {
    /// The instrument received a request with a bad checksum: resend it.
    BadChecksum,
    /// The instrument does not know the request.
    UnknownRequest,
    /// Calibrate first.
    NotCalibrated,
    /// A measurement or calibration is running: wait and resend.
    Busy,
    /// FETCH without a buffered MEASURE-ALL (never measured, aborted, or power-cycled).
    NoMeasurement,
    /// The geometry code is not one of the instrument's.
    BadGeometry,
    /// Lamp, detector or mechanics failed during the measurement.
    MeasurementFailed,
    /// The request was interrupted by ABORT.
    Aborted,
}

impl ErrorCode {
    /// Every error code, in wire-code order.
    pub const ALL: [ErrorCode; 8] = [
        ErrorCode::BadChecksum,
        ErrorCode::UnknownRequest,
        ErrorCode::NotCalibrated,
        ErrorCode::Busy,
        ErrorCode::NoMeasurement,
        ErrorCode::BadGeometry,
        ErrorCode::MeasurementFailed,
        ErrorCode::Aborted,
    ];

    /// What an operator should do about it.
    pub const fn advice(self) -> &'static str {
        match self {
            ErrorCode::BadChecksum => "the request was corrupted on the line; it is resent",
            ErrorCode::UnknownRequest => "the firmware does not support this request",
            ErrorCode::NotCalibrated => "calibrate the instrument on its reference tile",
            ErrorCode::Busy => "wait for the running measurement to finish",
            ErrorCode::NoMeasurement => "measure all geometries again before fetching",
            ErrorCode::BadGeometry => "the geometry is not one of this instrument's",
            ErrorCode::MeasurementFailed => {
                "check the lamp and that the instrument sits flat on the sample"
            }
            ErrorCode::Aborted => "the measurement was aborted",
        }
    }
}

impl fmt::Display for ErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            ErrorCode::BadChecksum => "BAD-CHECKSUM",
            ErrorCode::UnknownRequest => "UNKNOWN-REQUEST",
            ErrorCode::NotCalibrated => "NOT-CALIBRATED",
            ErrorCode::Busy => "BUSY",
            ErrorCode::NoMeasurement => "NO-MEASUREMENT",
            ErrorCode::BadGeometry => "BAD-GEOMETRY",
            ErrorCode::MeasurementFailed => "MEASUREMENT-FAILED",
            ErrorCode::Aborted => "ABORTED",
        })
    }
}

/// A reply from an instrument. Each reply names the request it answers (by its kind and, for
/// readings, the geometry), so a late duplicate is recognised and dropped.
#[derive(Debug, Clone, PartialEq)]
pub enum Response {
    /// Answer to IDENTIFY.
    Identity(Identity),
    /// Answer to STATUS.
    Status(Status),
    /// CALIBRATE done.
    Calibrated,
    /// MEASURE-ALL done; `count` geometries are buffered.
    Measured {
        /// How many geometries the instrument buffered.
        count: u8,
    },
    /// Answer to FETCH.
    Fetched(Reading),
    /// Answer to MEASURE-ONE.
    MeasuredOne(Reading),
    /// ABORT done: whatever was running has stopped.
    Aborted,
    /// The instrument refused `request` (about `geometry`, if any).
    Error {
        /// The kind of request refused.
        request: RequestKind,
        /// Why the instrument refused it.
        code: ErrorCode,
        /// The geometry the request was about, if any.
        geometry: Option<&'static str>,
    },
}

impl Response {
    /// Whether this reply answers `request` (rather than being a stale reply to another one).
    pub fn answers(&self, request: &Request) -> bool {
        match (self, request) {
            (Response::Identity(_), Request::Identify)
            | (Response::Status(_), Request::Status)
            | (Response::Calibrated, Request::Calibrate)
            | (Response::Measured { .. }, Request::MeasureAll)
            | (Response::Aborted, Request::Abort) => true,
            (Response::Fetched(r), Request::Fetch { geometry })
            | (Response::MeasuredOne(r), Request::MeasureOne { geometry }) => {
                r.geometry == *geometry
            }
            (
                Response::Error {
                    request: kind,
                    geometry,
                    ..
                },
                req,
            ) => *kind == req.kind() && (geometry.is_none() || *geometry == req.geometry()),
            _ => false,
        }
    }
}

impl fmt::Display for Response {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Response::Identity(id) => write!(f, "IDENTITY {id}"),
            Response::Status(s) => {
                write!(f, "STATUS {:?} battery {}%", s.state, s.battery_percent)
            }
            Response::Calibrated => f.write_str("CALIBRATED"),
            Response::Measured { count } => write!(f, "MEASURED {count} geometries"),
            Response::Fetched(r) => write!(f, "READING {r}"),
            Response::MeasuredOne(r) => write!(f, "READING (measure-one) {r}"),
            Response::Aborted => f.write_str("ABORTED"),
            Response::Error {
                request,
                code,
                geometry,
            } => match geometry {
                Some(g) => write!(f, "ERROR {code} in reply to {request} {g}"),
                None => write!(f, "ERROR {code} in reply to {request}"),
            },
        }
    }
}

/// Why bytes from the line are not an acceptable frame. Codec-level: the driver adds the
/// instrument and geometry when it reports one.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    #[error("{skipped} byte(s) of garbage before the next frame start were dropped")]
    /// Bytes that precede the next frame start.
    Garbage {
        /// How many bytes were dropped.
        skipped: usize,
    },
    #[error("frame declares a {declared}-byte payload, more than the protocol's {max}: dropped")]
    /// An MA-T12 header declares a payload larger than the protocol allows.
    BadLength {
        /// The payload length in the header.
        declared: usize,
        /// The largest payload the protocol allows.
        max: usize,
    },
    #[error("line of {len} bytes without a terminator exceeds the protocol's {max}: dropped")]
    /// An SRA run of bytes without a line end within the protocol's limit.
    LineTooLong {
        /// Length of the run, in bytes.
        len: usize,
        /// The longest line the protocol allows.
        max: usize,
    },
    #[error("{len}-byte line does not end in *XXXX\\r\\n, so it cannot be a frame: dropped")]
    /// An SRA line without the `*XXXX\r\n` tail.
    NotALine {
        /// Length of the line, in bytes.
        len: usize,
    },
    #[error("checksum mismatch (frame says {received:04X}, bytes give {computed:04X}): dropped")]
    /// The frame's CRC does not match its bytes.
    BadChecksum {
        /// The CRC computed over the received bytes.
        computed: u16,
        /// The CRC the frame carries.
        received: u16,
    },
    #[error("frame is not well formed: {detail}")]
    /// A frame with a valid checksum whose fields do not parse.
    Malformed {
        /// What is wrong with it.
        detail: String,
    },
    #[error("unknown opcode or mnemonic {what:?}")]
    /// An opcode (MA-T12) or mnemonic (SRA) the protocol does not define.
    UnknownOpcode {
        /// The opcode or mnemonic as received.
        what: String,
    },
    #[error("unknown geometry code {code:?}")]
    /// A geometry wire code the instrument does not have.
    UnknownGeometry {
        /// The code as received.
        code: String,
    },
    #[error("reading for {geometry} has a non-finite value in band {band}")]
    /// A reading with a NaN or infinite value.
    NonFinite {
        /// The reading's geometry.
        geometry: &'static str,
        /// The first non-finite band (0 for an SRA intensity).
        band: usize,
    },
}

impl FrameError {
    /// Whether the dropped bytes never formed a frame — bytes before a frame start, an MA-T12
    /// header declaring an impossible length, an SRA run without a line end within the limit,
    /// an SRA line without the `*XXXX\r\n` tail — rather than a whole frame that failed its
    /// checks (bad checksum, malformed body). The driver keeps waiting after garbage (the reply
    /// may follow it) and resends at once after a damaged frame (the reply is lost):
    /// PROTOCOL.md §4.
    pub fn is_garbage(&self) -> bool {
        match self {
            FrameError::Garbage { .. }
            | FrameError::BadLength { .. }
            | FrameError::LineTooLong { .. }
            | FrameError::NotALine { .. } => true,
            FrameError::BadChecksum { .. }
            | FrameError::Malformed { .. }
            | FrameError::UnknownOpcode { .. }
            | FrameError::UnknownGeometry { .. }
            | FrameError::NonFinite { .. } => false,
        }
    }

    pub(crate) fn malformed(detail: impl Into<String>) -> FrameError {
        FrameError::Malformed {
            detail: detail.into(),
        }
    }
}

/// Why a request or response cannot be put on the wire.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EncodeError {
    #[error("{instrument} has no geometry {geometry:?}; its geometries are {known}")]
    /// The request names a geometry the instrument does not have.
    UnknownGeometry {
        /// The instrument the frame is for.
        instrument: Instrument,
        /// The geometry asked for.
        geometry: String,
        /// The instrument's geometries, listed for the message.
        known: String,
    },
    #[error("{instrument} readings carry {expected}, not {found}")]
    /// A reading of the other instrument's kind (spectrum vs. intensity).
    WrongValueKind {
        /// The instrument the frame is for.
        instrument: Instrument,
        /// The kind of value the instrument carries.
        expected: &'static str,
        /// The kind of value given.
        found: &'static str,
    },
    #[error("{instrument} reading for {geometry} has a non-finite value: readings must be finite")]
    /// A reading with a NaN or infinite value.
    NonFinite {
        /// The instrument the frame is for.
        instrument: Instrument,
        /// The reading's geometry.
        geometry: &'static str,
    },
    #[error("{field} {value:?} cannot be sent to the {instrument}: {why}")]
    /// A field the wire format cannot carry (e.g. a separator inside an SRA identity field).
    BadField {
        /// The instrument the frame is for.
        instrument: Instrument,
        /// Which field.
        field: &'static str,
        /// The value given.
        value: String,
        /// Why it cannot be sent.
        why: &'static str,
    },
}

impl EncodeError {
    pub(crate) fn unknown_geometry(instrument: Instrument, geometry: &str) -> EncodeError {
        EncodeError::UnknownGeometry {
            instrument,
            geometry: geometry.to_owned(),
            known: instrument.geometries().join(" "),
        }
    }
}

/// The verdict of the first framing step on a receive buffer (mini-redis style: check a whole
/// frame is buffered, then parse it).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Check {
    /// Not enough bytes for a verdict yet: read more. A partial frame is not an error.
    Incomplete,
    /// `buf[..len]` is one whole frame with a valid checksum.
    Frame(usize),
    /// `buf[..len]` must be dropped (garbage, bad checksum, impossible length); check again
    /// after dropping it: this is how the decoder resynchronises.
    Reject(usize, FrameError),
}

/// One instrument's wire format. Implemented by `mat12::codec::Mat12Codec` and
/// `sra::codec::SraCodec`; a vendor's real protocol would be a third implementation.
///
/// `check_*` and `parse_*` are the two framing steps; `decode_*` combines them on a buffer.
/// The device-side half (`parse_request`, `encode_response`) is what the simulated instruments use.
pub trait Codec: Send + Sync + 'static {
    /// The instrument this codec speaks to.
    const INSTRUMENT: Instrument;

    /// Framing verdict on bytes sent by brdfd.
    fn check_request(buf: &[u8]) -> Check;
    /// Framing verdict on bytes sent by the instrument.
    fn check_response(buf: &[u8]) -> Check;
    /// Parse exactly one whole request frame (as delimited by `check_request`). Verifies the
    /// framing and checksum again, so it is safe on any bytes.
    fn parse_request(frame: &[u8]) -> Result<Request, FrameError>;
    /// Parse exactly one whole response frame (as delimited by `check_response`). Verifies the
    /// framing and checksum again, so it is safe on any bytes: no reading without a valid checksum.
    fn parse_response(frame: &[u8]) -> Result<Response, FrameError>;
    /// The bytes brdfd sends for `request`.
    fn encode_request(request: &Request) -> Result<Vec<u8>, EncodeError>;
    /// The bytes an instrument sends for `response` (used by the simulated instruments).
    fn encode_response(response: &Response) -> Result<Vec<u8>, EncodeError>;

    /// Take one request off the front of `buf`. `Ok(None)`: incomplete, read more. `Err`: the
    /// offending bytes were dropped; call again to continue after them.
    fn decode_request(buf: &mut BytesMut) -> Result<Option<Request>, FrameError> {
        Ok(decode_with(buf, Self::check_request, Self::parse_request)?.map(|(request, _)| request))
    }

    /// Take one response off the front of `buf`; same contract as [`Codec::decode_request`].
    fn decode_response(buf: &mut BytesMut) -> Result<Option<Response>, FrameError> {
        Ok(Self::decode_response_frame(buf)?.map(|(response, _)| response))
    }

    /// [`Codec::decode_response`] that also hands back the frame's bytes exactly as they were
    /// taken off the buffer (the driver keeps them with a reading).
    fn decode_response_frame(
        buf: &mut BytesMut,
    ) -> Result<Option<(Response, BytesMut)>, FrameError> {
        decode_with(buf, Self::check_response, Self::parse_response)
    }
}

fn decode_with<T>(
    buf: &mut BytesMut,
    check: fn(&[u8]) -> Check,
    parse: fn(&[u8]) -> Result<T, FrameError>,
) -> Result<Option<(T, BytesMut)>, FrameError> {
    match check(buf) {
        Check::Incomplete => Ok(None),
        Check::Reject(len, err) => {
            buf.advance(len.min(buf.len()).max(1));
            Err(err)
        }
        Check::Frame(len) => {
            let frame = buf.split_to(len);
            let parsed = parse(&frame)?;
            Ok(Some((parsed, frame)))
        }
    }
}

// `Response` carries a reading inline (see `ReadingValue`), hence the large `Err`.
#[allow(clippy::result_large_err)]
/// A command as a small pure type (probe-rs style): which request it is, its bytes for a given
/// codec, and what it makes of a reply.
pub trait Command {
    /// What a successful reply yields.
    type Output;
    /// The request this command sends.
    fn request(&self) -> Request;

    /// Command id: the request kind.
    fn kind(&self) -> RequestKind {
        self.request().kind()
    }

    /// The bytes of this command for instrument codec `C`.
    fn to_bytes<C: Codec>(&self) -> Result<Vec<u8>, EncodeError> {
        C::encode_request(&self.request())
    }

    /// What a decoded reply means for this command.
    fn parse_response(&self, response: Response) -> Answer<Self::Output> {
        let request = self.request();
        if !response.answers(&request) {
            return Answer::NotMine(response);
        }
        if let Response::Error { code, .. } = response {
            return Answer::Refused(code);
        }
        match self.extract(response) {
            Ok(out) => Answer::Done(out),
            Err(other) => Answer::NotMine(other),
        }
    }

    /// Pull the output out of a reply that answers this command; give the reply back otherwise.
    fn extract(&self, response: Response) -> Result<Self::Output, Response>;
}

/// What a reply means to the command waiting for it.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum Answer<T> {
    /// The reply answers the command: its output.
    Done(T),
    /// The instrument refused the command.
    Refused(ErrorCode),
    /// A reply to some other (earlier) request: drop it and keep waiting.
    NotMine(Response),
}

/// IDENTIFY → [`Identity`].
#[derive(Debug, Clone, Copy)]
pub struct Identify;
/// STATUS → [`Status`].
#[derive(Debug, Clone, Copy)]
pub struct GetStatus;
/// CALIBRATE → `()`.
#[derive(Debug, Clone, Copy)]
pub struct Calibrate;
/// MEASURE-ALL → number of geometries buffered.
#[derive(Debug, Clone, Copy)]
pub struct MeasureAll;
/// FETCH geometry → [`Reading`].
#[derive(Debug, Clone, Copy)]
pub struct Fetch {
    /// The geometry's wire name.
    pub geometry: &'static str,
}
/// MEASURE-ONE geometry → [`Reading`].
#[derive(Debug, Clone, Copy)]
pub struct MeasureOne {
    /// The geometry's wire name.
    pub geometry: &'static str,
}
/// ABORT → `()`.
#[derive(Debug, Clone, Copy)]
pub struct Abort;

impl Command for Identify {
    type Output = Identity;
    fn request(&self) -> Request {
        Request::Identify
    }
    fn extract(&self, response: Response) -> Result<Identity, Response> {
        match response {
            Response::Identity(id) => Ok(id),
            other => Err(other),
        }
    }
}

impl Command for GetStatus {
    type Output = Status;
    fn request(&self) -> Request {
        Request::Status
    }
    fn extract(&self, response: Response) -> Result<Status, Response> {
        match response {
            Response::Status(s) => Ok(s),
            other => Err(other),
        }
    }
}

impl Command for Calibrate {
    type Output = ();
    fn request(&self) -> Request {
        Request::Calibrate
    }
    fn extract(&self, response: Response) -> Result<(), Response> {
        match response {
            Response::Calibrated => Ok(()),
            other => Err(other),
        }
    }
}

impl Command for MeasureAll {
    type Output = u8;
    fn request(&self) -> Request {
        Request::MeasureAll
    }
    fn extract(&self, response: Response) -> Result<u8, Response> {
        match response {
            Response::Measured { count } => Ok(count),
            other => Err(other),
        }
    }
}

impl Command for Fetch {
    type Output = Reading;
    fn request(&self) -> Request {
        Request::Fetch {
            geometry: self.geometry,
        }
    }
    fn extract(&self, response: Response) -> Result<Reading, Response> {
        match response {
            Response::Fetched(r) => Ok(r),
            other => Err(other),
        }
    }
}

impl Command for MeasureOne {
    type Output = Reading;
    fn request(&self) -> Request {
        Request::MeasureOne {
            geometry: self.geometry,
        }
    }
    fn extract(&self, response: Response) -> Result<Reading, Response> {
        match response {
            Response::MeasuredOne(r) => Ok(r),
            other => Err(other),
        }
    }
}

impl Command for Abort {
    type Output = ();
    fn request(&self) -> Request {
        Request::Abort
    }
    fn extract(&self, response: Response) -> Result<(), Response> {
        match response {
            Response::Aborted => Ok(()),
            other => Err(other),
        }
    }
}

/// A golden frame from PROTOCOL.md: the bytes of the fenced block opened by
/// ```` ```golden <label> ````. Tests use the document verbatim so the two cannot drift apart.
#[cfg(test)]
pub(crate) fn golden(label: &str) -> Vec<u8> {
    const DOC: &str = include_str!("../PROTOCOL.md");
    let fence = format!("```golden {label}\n");
    let start = DOC
        .find(&fence)
        .unwrap_or_else(|| panic!("PROTOCOL.md has no golden {label:?}"))
        + fence.len();
    let end = start + DOC[start..].find("```").expect("unterminated golden block");
    let hex: String = DOC[start..end].split_whitespace().collect();
    (0..hex.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&hex[i..i + 2], 16).expect("golden block is hex"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc16_matches_the_catalogue_check_value() {
        // CRC-16/IBM-3740 (CCITT-FALSE) check value from the CRC RevEng catalogue.
        assert_eq!(CRC16.checksum(b"123456789"), 0x29B1);
    }

    #[test]
    fn replies_answer_only_their_request() {
        let r = Reading {
            geometry: "15as45",
            value: ReadingValue::Intensity(1.0),
        };
        assert!(Response::Fetched(r).answers(&Request::Fetch { geometry: "15as45" }));
        assert!(!Response::Fetched(r).answers(&Request::Fetch { geometry: "15as15" }));
        assert!(!Response::Fetched(r).answers(&Request::MeasureOne { geometry: "15as45" }));
        assert!(!Response::Calibrated.answers(&Request::Abort));
        let err = Response::Error {
            request: RequestKind::Fetch,
            code: ErrorCode::NoMeasurement,
            geometry: Some("15as45"),
        };
        assert!(err.answers(&Request::Fetch { geometry: "15as45" }));
        assert!(!err.answers(&Request::Fetch { geometry: "45as45" }));
        assert!(!err.answers(&Request::Status));
    }

    #[test]
    fn commands_sort_replies() {
        let fetch = Fetch { geometry: "sra-20" };
        let r = Reading {
            geometry: "sra-20",
            value: ReadingValue::Intensity(2.5),
        };
        assert_eq!(fetch.parse_response(Response::Fetched(r)), Answer::Done(r));
        assert_eq!(
            fetch.parse_response(Response::Status(Status {
                state: DeviceState::Ready,
                battery_percent: 80
            })),
            Answer::NotMine(Response::Status(Status {
                state: DeviceState::Ready,
                battery_percent: 80
            }))
        );
        assert_eq!(
            fetch.parse_response(Response::Error {
                request: RequestKind::Fetch,
                code: ErrorCode::Busy,
                geometry: None
            }),
            Answer::Refused(ErrorCode::Busy)
        );
    }

    #[test]
    fn bit_eq_distinguishes_signed_zero() {
        let a = Reading {
            geometry: "sra-20",
            value: ReadingValue::Intensity(0.0),
        };
        let b = Reading {
            geometry: "sra-20",
            value: ReadingValue::Intensity(-0.0),
        };
        assert_eq!(a, b);
        assert!(!a.bit_eq(&b));
        assert!(a.bit_eq(&a));
    }
}
