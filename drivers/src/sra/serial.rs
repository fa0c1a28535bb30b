//! The real SRA transport: a serial port through `serialport` (built without libudev, so port
//! enumeration is unavailable and ports are opened by name). [`open_serial`] opens a named port
//! with the settings of PROTOCOL.md §3. Any `serialport` port — including one end of a
//! pseudo-terminal pair (`serialport::TTYPort::pair()`), which is how the simulated SRA is
//! reached — is a [`SerialStream`].

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
}
