//! brdfd's instrument drivers: the X-Rite MA-T12 over USB and the Canon RA-532H ("SRA") over a
//! serial line. The wire framing is brdfd's own (the vendors' protocols are not public); it is
//! specified in `PROTOCOL.md` beside this crate.
//!
//! # Layout
//! - [`protocol`]: what is said, independent of bytes: requests, replies, readings, error codes,
//!   the [`protocol::Codec`] trait and the commands as small pure types; the instruments'
//!   geometry names ([`protocol::MAT12_GEOMETRIES`], [`protocol::SRA_GEOMETRIES`]).
//! - [`mat12::codec`], [`sra::codec`]: the bytes, one replaceable file per instrument, each
//!   with its geometry name ↔ wire code map. The codecs import `protocol`, never the reverse.
//! - [`session`]: the line-oriented session-file format (`brdfd-session 1`) that the recording
//!   tap writes and the simulated instruments replay, with fault directives.
//! - [`transport`]: the transport traits [`transport::UsbBulk`] and [`transport::SerialStream`]
//!   and their errors, and the USB packet size ([`transport::PACKET_SIZE`]); real
//!   implementations in [`mat12::usb`] (rusb) and [`sra::serial`] (serialport); the simulated
//!   ones live in `mock-devices`.
//! - [`driver`]: the async driver tasks ([`driver::spawn_mat12`], [`driver::spawn_sra`]): one
//!   OS thread per instrument owning the connection, commands in over an mpsc channel, events
//!   out on a broadcast channel, timeouts, resends and reconnection with backoff. Readings
//!   come as [`protocol::ReceivedReading`]s: the values and the reply frame exactly as received.
//! - [`tap`]: the recording tap, [`tap::Tap`] around any transport, writing every frame in both
//!   directions with timestamps to a session file through a [`tap::Recorder`].

#![warn(missing_docs)]

pub mod driver;
pub mod mat12;
pub mod protocol;
pub mod session;
pub mod sra;
pub mod tap;
#[cfg(test)]
pub(crate) mod test_support;
pub mod transport;

pub use driver::{DriverConfig, DriverError, DriverHandle, Event, spawn_mat12, spawn_sra};
pub use protocol::{Identity, Instrument, Reading, ReadingValue, ReceivedReading, Status};
pub use tap::{Recorder, Tap};
pub use transport::{SerialStream, TransportError, UsbBulk};
