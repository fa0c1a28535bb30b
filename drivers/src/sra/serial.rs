//! The real SRA transport: a serial port through `serialport` (built without libudev, so port
//! enumeration is unavailable and ports are opened by name). [`open_serial`] opens a named port
//! with the settings of PROTOCOL.md §3. Any `serialport` port — including one end of a
//! pseudo-terminal pair (`serialport::TTYPort::pair()`), which is how the simulated SRA is
//! reached — is a [`SerialStream`].
//!
//! On a pseudo-terminal, bytes written just before the other end closes can be lost: the reader
//! is told of the hang-up first. A simulated instrument that means to send a reply and then
//! disconnect must let the reply be read before it closes.

use std::time::Duration;

use serialport::{ClearBuffer, DataBits, FlowControl, Parity, SerialPort, StopBits};

use crate::transport::{SerialStream, TransportError};

/// Open `port` (a device path such as the USB-serial adapter's, or `COM3`) at `baud` (PROTOCOL.md §3 uses 9600), 8N1, no
/// flow control.
pub fn open_serial(port: &str, baud: u32) -> Result<Box<dyn SerialPort>, TransportError> {
    serialport::new(port, baud)
        .data_bits(DataBits::Eight)
        .parity(Parity::None)
        .stop_bits(StopBits::One)
        .flow_control(FlowControl::None)
        .timeout(Duration::from_secs(1))
        .open()
        .map_err(|e| TransportError::SerialOpen {
            port: port.to_owned(),
            detail: e.to_string(),
        })
}

fn setting_error(e: serialport::Error) -> TransportError {
    TransportError::Disconnected {
        detail: format!("serial port: {e}"),
    }
}

impl SerialStream for Box<dyn SerialPort> {
    fn set_timeout(&mut self, timeout: Duration) -> Result<(), TransportError> {
        SerialPort::set_timeout(self.as_mut(), timeout).map_err(setting_error)
    }

    fn clear_input(&mut self) -> Result<(), TransportError> {
        self.clear(ClearBuffer::Input).map_err(setting_error)
    }
}

#[cfg(unix)]
impl SerialStream for serialport::TTYPort {
    fn set_timeout(&mut self, timeout: Duration) -> Result<(), TransportError> {
        SerialPort::set_timeout(self, timeout).map_err(setting_error)
    }

    fn clear_input(&mut self) -> Result<(), TransportError> {
        self.clear(ClearBuffer::Input).map_err(setting_error)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn opening_a_missing_port_names_it() {
        let err = open_serial("brdfd-no-such-serial-port", 9600).expect_err("port does not exist");
        let msg = err.to_string();
        assert!(msg.contains("brdfd-no-such-serial-port"), "{msg}");
        assert!(msg.contains("check the port name"), "{msg}");
    }

    /// The SRA driver through a real pseudo-terminal pair (the OS tty layer), against a small
    /// device thread on the other end that answers with the codec. Then the device end closes:
    /// the driver sees a lost link, not a timeout, and fails cleanly naming the geometry.
    #[cfg(unix)]
    #[tokio::test]
    async fn the_driver_talks_through_a_real_pty_and_notices_when_it_closes() {
        use std::io::{Read, Write};
        use std::sync::{Arc, Mutex};

        use bytes::BytesMut;
        use serialport::TTYPort;

        use crate::driver::{DriverConfig, DriverError, spawn_sra};
        use crate::protocol::{Codec, Identity, Reading, ReadingValue, Request, Response};
        use crate::sra::codec::SraCodec;

        let (mut device_end, host_end) = TTYPort::pair().expect("a pseudo-terminal pair");
        let device = std::thread::spawn(move || {
            let mut inbox = BytesMut::new();
            let mut buf = [0u8; 64];
            SerialPort::set_timeout(&mut device_end, Duration::from_millis(20)).unwrap();
            let mut answered = 0;
            // Answer IDENTIFY, MEASURE-ONE, MEASURE-ALL, FETCH sra-20; hang up on FETCH sra-60. (Hanging up
            // right after a write can lose the written bytes: the host sees the hang-up first.)
            while answered < 5 {
                let Ok(n) = device_end.read(&mut buf) else {
                    continue;
                };
                inbox.extend_from_slice(&buf[..n]);
                while let Ok(Some(request)) = SraCodec::decode_request(&mut inbox) {
                    let reply = match request {
                        Request::Identify => Response::Identity(Identity {
                            model: "RA-532H".into(),
                            serial: "pty".into(),
                            firmware: "1".into(),
                        }),
                        Request::MeasureAll => Response::Measured { count: 2 },
                        Request::MeasureOne { geometry } => Response::MeasuredOne(Reading {
                            geometry,
                            value: ReadingValue::Intensity(0.1 + 0.2),
                        }),
                        Request::Fetch { geometry: "sra-60" } => {
                            answered += 1;
                            break;
                        }
                        Request::Fetch { geometry } => Response::Fetched(Reading {
                            geometry,
                            value: ReadingValue::Intensity(0.1 + 0.2),
                        }),
                        other => panic!("unexpected {other}"),
                    };
                    device_end
                        .write_all(&SraCodec::encode_response(&reply).unwrap())
                        .unwrap();
                    answered += 1;
                }
            }
            // Dropping `device_end` closes the master side of the pty.
        });

        let host = Arc::new(Mutex::new(Some(host_end)));
        let config = DriverConfig {
            reply_timeout: Duration::from_millis(300),
            backoff_initial: Duration::from_millis(5),
            ..DriverConfig::default()
        };
        let handle = spawn_sra(
            move || {
                host.lock()
                    .unwrap()
                    .take()
                    .ok_or(TransportError::SerialOpen {
                        port: "pty".into(),
                        detail: "the pseudo-terminal is gone".into(),
                    })
            },
            config,
        );
        let one = tokio::time::timeout(Duration::from_secs(10), handle.measure_one("sra-20"))
            .await
            .expect("no hang")
            .unwrap();
        // 0.1 + 0.2 = 0.30000000000000004: the decimal on the wire keeps every bit.
        let ReadingValue::Intensity(v) = one.value else {
            panic!("not an intensity")
        };
        assert_eq!(v.to_bits(), (0.1f64 + 0.2).to_bits());
        let err = tokio::time::timeout(Duration::from_secs(10), handle.measure_all())
            .await
            .expect("no hang")
            .unwrap_err();
        device.join().unwrap();
        let DriverError::Disconnected { geometry, .. } = &err else {
            panic!("expected a lost link, got {err:?}")
        };
        assert_eq!(
            *geometry,
            Some("sra-60"),
            "sra-20 was answered, sra-60 was in progress"
        );
        assert!(err.to_string().contains("pseudo-terminal is gone"), "{err}");
    }
}
