//! The two transport traits the drivers are generic over — [`UsbBulk`] (MA-T12) and
//! [`SerialStream`] (SRA) — their shared error type, and the adapters that turn either into the
//! frame-oriented link the driver task uses.
//!
//! Real implementations sit beside the simulated ones: `mat12::usb::RusbBulk` (rusb) and
//! `sra::serial` (serialport) here; the simulated instruments live in `mock-devices` and
//! implement the same traits. Both traits are `Send + 'static` so a connection can move onto
//! the driver's I/O thread.

use std::io::{self, Read, Write};
use std::time::Duration;

/// Why a transport call failed. The driver treats [`TransportError::Timeout`] as "resend",
/// [`TransportError::Disconnected`] as "reconnect", and the rest as "cannot connect".
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TransportError {
    /// No matching device, or libusb could not list the bus at all (`detail` says why).
    #[error(
        "MA-T12 not found on USB (vendor id 0x{vendor_id:04x}{}{}): check the cable and udev permissions",
        product_id.map(|p| format!(", product id 0x{p:04x}")).unwrap_or_default(),
        detail.as_ref().map(|d| format!("; {d}")).unwrap_or_default()
    )]
    UsbNotFound {
        /// The vendor id searched for.
        vendor_id: u16,
        /// The product id searched for, if one was set.
        product_id: Option<u16>,
        /// Why the bus could not be listed, if that was the problem.
        detail: Option<String>,
    },
    #[error(
        "MA-T12 on USB bus {bus} address {address} cannot be opened: no permission; add a udev rule \
         giving the brdfd user access to vendor id 0x{vendor_id:04x} (e.g. MODE=\"0660\", GROUP=\"plugdev\")"
    )]
    /// The device is there but the brdfd user may not open it.
    UsbPermission {
        /// USB bus number.
        bus: u8,
        /// Device address on the bus.
        address: u8,
        /// The device's vendor id.
        vendor_id: u16,
    },
    #[error("MA-T12 on USB: {detail}: check the cable and udev permissions")]
    /// Any other libusb failure while opening the device.
    UsbOther {
        /// libusb's error.
        detail: String,
    },
    #[error(
        "MA-T12: cannot claim USB interface {interface} ({detail}): is another program using the instrument?"
    )]
    /// The interface is claimed by another driver or program.
    UsbClaim {
        /// The interface number.
        interface: u8,
        /// libusb's error.
        detail: String,
    },
    #[error(
        "cannot open serial port {port} for the SRA ({detail}): check the port name, the cable, and that the brdfd user is in the port's group (often dialout)"
    )]
    /// The serial port cannot be opened.
    SerialOpen {
        /// The port's name.
        port: String,
        /// The operating system's error.
        detail: String,
    },
    #[error("no data within {} ms", timeout.as_millis())]
    /// Nothing arrived within the timeout: the driver resends.
    Timeout {
        /// The timeout that passed.
        timeout: Duration,
    },
    #[error("link lost: {detail}")]
    /// The link is gone: the driver reconnects.
    Disconnected {
        /// What the transport reported.
        detail: String,
    },
}

impl TransportError {
    /// Classify an I/O error from a byte stream: a timeout, or a lost link.
    pub fn from_io(e: &io::Error, timeout: Duration) -> TransportError {
        match e.kind() {
            io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock => {
                TransportError::Timeout { timeout }
            }
            _ => TransportError::Disconnected {
                detail: e.to_string(),
            },
        }
    }
}

/// USB full-speed bulk packet size (PROTOCOL.md §2): the driver writes frames in chunks of at
/// most this and reads with a buffer of this size.
pub const PACKET_SIZE: usize = 64;

/// A USB bulk pipe pair (the MA-T12's transport).
pub trait UsbBulk: Send + 'static {
    /// Write one bulk transfer. The driver never passes more than 64 bytes.
    /// Returns the number of bytes written.
    fn write_bulk(&mut self, data: &[u8], timeout: Duration) -> Result<usize, TransportError>;

    /// Read one bulk transfer into `buf` (the driver passes 64 bytes). Returns the number of
    /// bytes read (at least 1), `Err(Timeout)` when nothing arrived in time.
    fn read_bulk(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, TransportError>;
}

/// A serial byte stream (the SRA's transport): `Read + Write`, with a timeout that applies to
/// each following read and write. A read that times out returns `io::ErrorKind::TimedOut`; a
/// read of 0 bytes or any other error means the link is gone.
pub trait SerialStream: Read + Write + Send + 'static {
    /// Set the timeout for each following read and write.
    fn set_timeout(&mut self, timeout: Duration) -> Result<(), TransportError>;

    /// Drop bytes received but not yet read. Default: nothing to drop.
    fn clear_input(&mut self) -> Result<(), TransportError> {
        Ok(())
    }
}

impl<T: UsbBulk + ?Sized> UsbBulk for Box<T> {
    fn write_bulk(&mut self, data: &[u8], timeout: Duration) -> Result<usize, TransportError> {
        (**self).write_bulk(data, timeout)
    }
    fn read_bulk(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, TransportError> {
        (**self).read_bulk(buf, timeout)
    }
}

/// The frame-level view of a transport that the driver task uses.
pub(crate) trait Link: Send + 'static {
    /// Send a whole frame.
    fn send(&mut self, frame: &[u8], timeout: Duration) -> Result<(), TransportError>;
    /// Receive some bytes (at least 1), or `Err(Timeout)`.
    fn recv(&mut self, buf: &mut Vec<u8>, timeout: Duration) -> Result<(), TransportError>;
    /// Drop pending input before a (re)send, where the transport can.
    fn discard_input(&mut self);
}

/// USB bulk as a link: frames go out in 64-byte transfers (the full-speed bulk packet size,
/// PROTOCOL.md §2) and come in 64 bytes at a time.
pub(crate) struct UsbLink<T: UsbBulk>(pub T);

impl<T: UsbBulk> Link for UsbLink<T> {
    fn send(&mut self, frame: &[u8], timeout: Duration) -> Result<(), TransportError> {
        for packet in frame.chunks(PACKET_SIZE) {
            let mut sent = 0;
            while sent < packet.len() {
                let n = self.0.write_bulk(&packet[sent..], timeout)?;
                if n == 0 {
                    return Err(TransportError::Disconnected {
                        detail: "USB bulk write accepted no bytes".into(),
                    });
                }
                sent += n;
            }
        }
        Ok(())
    }

    fn recv(&mut self, buf: &mut Vec<u8>, timeout: Duration) -> Result<(), TransportError> {
        let mut packet = [0u8; PACKET_SIZE];
        let n = self.0.read_bulk(&mut packet, timeout)?;
        if n == 0 {
            // A zero-length packet carries nothing; report it as "nothing yet".
            return Err(TransportError::Timeout { timeout });
        }
        buf.extend_from_slice(&packet[..n.min(packet.len())]);
        Ok(())
    }

    fn discard_input(&mut self) {}
}

/// A serial stream as a link.
pub(crate) struct SerialLink<T: SerialStream>(pub T);

impl<T: SerialStream> Link for SerialLink<T> {
    fn send(&mut self, frame: &[u8], timeout: Duration) -> Result<(), TransportError> {
        self.0.set_timeout(timeout)?;
        self.0
            .write_all(frame)
            .map_err(|e| TransportError::from_io(&e, timeout))?;
        self.0
            .flush()
            .map_err(|e| TransportError::from_io(&e, timeout))
    }

    fn recv(&mut self, buf: &mut Vec<u8>, timeout: Duration) -> Result<(), TransportError> {
        self.0.set_timeout(timeout)?;
        let mut chunk = [0u8; 256];
        match self.0.read(&mut chunk) {
            Ok(0) => Err(TransportError::Disconnected {
                detail: "end of stream".into(),
            }),
            Ok(n) => {
                buf.extend_from_slice(&chunk[..n.min(chunk.len())]);
                Ok(())
            }
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {
                Err(TransportError::Timeout { timeout })
            }
            Err(e) => Err(TransportError::from_io(&e, timeout)),
        }
    }

    fn discard_input(&mut self) {
        // Best effort: the decoder copes with stale bytes anyway.
        let _ = self.0.clear_input();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn usb_not_found_message_says_what_to_do() {
        let e = TransportError::UsbNotFound {
            vendor_id: 0x0765,
            product_id: None,
            detail: None,
        };
        assert_eq!(
            e.to_string(),
            "MA-T12 not found on USB (vendor id 0x0765): check the cable and udev permissions"
        );
        let e = TransportError::UsbNotFound {
            vendor_id: 0x0765,
            product_id: Some(0xd020),
            detail: Some("libusb cannot list the bus: Other error".into()),
        };
        assert_eq!(
            e.to_string(),
            "MA-T12 not found on USB (vendor id 0x0765, product id 0xd020; libusb cannot list \
             the bus: Other error): check the cable and udev permissions"
        );
    }

    #[test]
    fn io_errors_are_classified() {
        let t = Duration::from_millis(5);
        let timeout = io::Error::new(io::ErrorKind::TimedOut, "x");
        assert_eq!(
            TransportError::from_io(&timeout, t),
            TransportError::Timeout { timeout: t }
        );
        let pipe = io::Error::new(io::ErrorKind::BrokenPipe, "gone");
        assert!(matches!(
            TransportError::from_io(&pipe, t),
            TransportError::Disconnected { .. }
        ));
    }

    /// A USB fake that records transfer sizes.
    struct Sizes(Vec<usize>);
    impl UsbBulk for Sizes {
        fn write_bulk(&mut self, data: &[u8], _: Duration) -> Result<usize, TransportError> {
            self.0.push(data.len());
            Ok(data.len())
        }
        fn read_bulk(&mut self, _: &mut [u8], timeout: Duration) -> Result<usize, TransportError> {
            Err(TransportError::Timeout { timeout })
        }
    }

    #[test]
    fn usb_link_writes_at_most_64_bytes_per_transfer() {
        let mut link = UsbLink(Sizes(Vec::new()));
        link.send(&[0u8; 256 + 10], Duration::from_millis(1))
            .unwrap();
        assert_eq!(link.0.0, vec![64, 64, 64, 64, 10]);
    }
}
