//! Simulated instruments for brdfd: an X-Rite MA-T12 and a Canon RA-532H ("SRA") that replay
//! recorded sessions (`brdfd-session 1` files, PROTOCOL.md §5) through the same transports the
//! real ones use, with fault injection; the generator of synthetic sessions; and the committed
//! synthetic recordings. brdfd's demo and tests run on these with no instrument attached.
//!
//! This crate speaks the wire format only through the `drivers` crate's codecs and session-file
//! reader; it does not depend on the root `brdfd` crate (which depends on it).
//!
//! # Layout
//! - [`script`]: session files (one, or several back to back) cut into exchanges, with their
//!   fault directives and faults added in code; the readings a replay must deliver.
//! - [`engine`]: the replay engine without I/O — strict or lenient matching ([`Mode`]),
//!   recorded, scaled or no delays ([`Timing`]), the faults, and the [`ReplayReport`].
//! - [`usb`]: [`SimMat12`], whose connections ([`SimUsb`]) implement `drivers::UsbBulk`.
//! - [`pty`]: [`SimSra`], serving a real pseudo-terminal pair (`serialport::TTYPort::pair`);
//!   the driver gets the slave end as its serial stream.
//! - [`generate`]: [`generate_reference_session`] and [`generate_sample_session`], which turn
//!   given readings into the sessions the real driver and instruments would produce.
//! - [`recordings`]: the committed synthetic recordings (`recordings/`), embedded, so the demo
//!   runs with nothing on disk.
//! - `wire` (private): the drivers' codecs chosen by instrument at run time.
//!
//! Outside `src/`: `recordings/` (the session files, ground truth, README),
//! `examples/make_recordings.rs` (regenerates them), `tests/` (each driver against its
//! simulated instrument, faults, the real USB transport without a device), and
//! `benches/replay.rs` (the accelerated replay of all recordings through both drivers).

#![warn(missing_docs)]

use drivers::Instrument;
use drivers::session::SessionError;

pub mod engine;
pub mod generate;
pub mod pty;
pub mod recordings;
pub mod script;
pub mod usb;
mod wire;

pub use engine::{Cue, Mismatch, Mode, ReplayOptions, ReplayReport, Timing};
pub use generate::{
    GenerateError, GenerateOptions, Readings, SessionPair, generate_reference_session,
    generate_sample_session,
};
pub use pty::SimSra;
pub use script::{Script, ScriptObject};
pub use usb::{SimMat12, SimUsb};

/// Why a simulated instrument cannot be set up. Connection failures at run time are
/// `drivers::TransportError`s, as with the real transports.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MockError {
    /// The session file does not parse; the message names the line.
    #[error(transparent)]
    Session(#[from] SessionError),
    #[error("no session to replay: give the simulated instrument at least one session file")]
    /// No session was given.
    NoSessions,
    #[error(
        "session {session} ({label}) is for the {found}, but the replay is for the {expected}: \
         replay each instrument's sessions on its own simulated instrument"
    )]
    /// A session of a multi-session script is for the other instrument.
    WrongInstrument {
        /// 0-based index of the session.
        session: usize,
        /// The session's label (file name or description).
        label: String,
        /// The instrument the session records.
        found: Instrument,
        /// The instrument being simulated.
        expected: Instrument,
    },
    #[error(
        "the script is a recording of the {script}; it cannot be replayed by the simulated \
         {simulated}: use the other simulated instrument or the other session file"
    )]
    /// The script records the other instrument.
    NotForThisInstrument {
        /// The instrument the script records.
        script: Instrument,
        /// The instrument being simulated.
        simulated: Instrument,
    },
    #[error("fault `{fault}` cannot be applied: {detail}")]
    /// A fault added in code does not fit the script.
    BadFault {
        /// The fault, as written in a session file.
        fault: String,
        /// Why it cannot be applied.
        detail: String,
    },
    #[error(
        "replay speed factor {speed} must be a positive finite number (1 = recorded timing, \
         10 = ten times faster; use Timing::Immediate for no delays)"
    )]
    /// A replay speed factor that is zero, negative or not finite.
    BadSpeed {
        /// The factor given.
        speed: f64,
    },
}
