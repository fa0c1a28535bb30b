//! The real MA-T12 transport: USB bulk through libusb (`rusb`, built from its vendored source,
//! so nothing needs installing). On a machine without the instrument — or without permission to
//! open it, or with no usable USB bus at all — [`RusbBulk::open`] returns an error that says
//! what to check; it never panics.
//!
//! The vendor id is X-Rite's (0x0765); the product id, interface and endpoints are brdfd's
//! assumptions (PROTOCOL.md §2) and are configurable in [`UsbIds`].

use std::time::Duration;

use rusb::UsbContext;

use crate::transport::{TransportError, UsbBulk};

/// X-Rite's USB vendor id.
pub const XRITE_VENDOR_ID: u16 = 0x0765;

/// Which USB device and endpoints are the MA-T12.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UsbIds {
    /// USB vendor id (X-Rite: [`XRITE_VENDOR_ID`]).
    pub vendor_id: u16,
    /// `None`: the first device of the vendor. Set it when other X-Rite devices are plugged in.
    pub product_id: Option<u16>,
    /// Number of the interface to claim.
    pub interface: u8,
    /// Bulk OUT endpoint address.
    pub endpoint_out: u8,
    /// Bulk IN endpoint address.
    pub endpoint_in: u8,
}

impl Default for UsbIds {
    fn default() -> UsbIds {
        UsbIds {
            vendor_id: XRITE_VENDOR_ID,
            product_id: None,
            interface: 0,
            endpoint_out: 0x01,
            endpoint_in: 0x81,
        }
    }
}

/// An open, claimed MA-T12 on USB.
pub struct RusbBulk {
    handle: rusb::DeviceHandle<rusb::Context>,
    ids: UsbIds,
}

impl std::fmt::Debug for RusbBulk {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RusbBulk")
            .field("ids", &self.ids)
            .finish_non_exhaustive()
    }
}

impl RusbBulk {
    /// Find, open and claim the MA-T12.
    pub fn open(ids: UsbIds) -> Result<RusbBulk, TransportError> {
        // No usable USB bus at all (no usbfs, as in a container) is still "not found": the
        // operator's checks are the same.
        let unlisted = |e: rusb::Error| TransportError::UsbNotFound {
            vendor_id: ids.vendor_id,
            product_id: ids.product_id,
            detail: Some(format!("libusb cannot list the bus: {e}")),
        };
        let context = rusb::Context::new().map_err(unlisted)?;
        let devices = context.devices().map_err(unlisted)?;
        let not_found = TransportError::UsbNotFound {
            vendor_id: ids.vendor_id,
            product_id: ids.product_id,
            detail: None,
        };
        let device = devices
            .iter()
            .find(|d| {
                d.device_descriptor().is_ok_and(|desc| {
                    desc.vendor_id() == ids.vendor_id
                        && ids.product_id.is_none_or(|p| desc.product_id() == p)
                })
            })
            .ok_or(not_found.clone())?;
        let handle = device.open().map_err(|e| match e {
            rusb::Error::Access => TransportError::UsbPermission {
                bus: device.bus_number(),
                address: device.address(),
                vendor_id: ids.vendor_id,
            },
            rusb::Error::NoDevice | rusb::Error::NotFound => not_found.clone(),
            other => TransportError::UsbOther {
                detail: format!("cannot open the device: {other}"),
            },
        })?;
        // Not supported on every platform; where it is not, a kernel driver would show up as a
        // claim failure below with its own message.
        let _ = handle.set_auto_detach_kernel_driver(true);
        handle.claim_interface(ids.interface).map_err(|e| match e {
            rusb::Error::Access => TransportError::UsbPermission {
                bus: device.bus_number(),
                address: device.address(),
                vendor_id: ids.vendor_id,
            },
            other => TransportError::UsbClaim {
                interface: ids.interface,
                detail: other.to_string(),
            },
        })?;
        Ok(RusbBulk { handle, ids })
    }
}

fn map_error(e: rusb::Error, timeout: Duration) -> TransportError {
    match e {
        rusb::Error::Timeout => TransportError::Timeout { timeout },
        other => TransportError::Disconnected {
            detail: format!("USB: {other}"),
        },
    }
}

impl UsbBulk for RusbBulk {
    fn write_bulk(&mut self, data: &[u8], timeout: Duration) -> Result<usize, TransportError> {
        self.handle
            .write_bulk(self.ids.endpoint_out, data, timeout)
            .map_err(|e| map_error(e, timeout))
    }

    fn read_bulk(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, TransportError> {
        self.handle
            .read_bulk(self.ids.endpoint_in, buf, timeout)
            .map_err(|e| map_error(e, timeout))
    }
}

impl Drop for RusbBulk {
    fn drop(&mut self) {
        let _ = self.handle.release_interface(self.ids.interface);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On a machine without an X-Rite device (CI, this project's machines) opening fails with a
    /// message that says what to check, and does not panic. A product id nobody uses makes the
    /// test independent of what is plugged in.
    #[test]
    fn opening_without_a_device_gives_a_clear_error() {
        let ids = UsbIds {
            product_id: Some(0xfff7),
            ..UsbIds::default()
        };
        let err = RusbBulk::open(ids).expect_err("no MA-T12 with product id 0xfff7 exists");
        let msg = err.to_string();
        match err {
            TransportError::UsbNotFound {
                vendor_id,
                product_id,
                ..
            } => {
                assert_eq!((vendor_id, product_id), (0x0765, Some(0xfff7)));
                assert!(
                    msg.starts_with("MA-T12 not found on USB (vendor id 0x0765"),
                    "{msg}"
                );
                assert!(
                    msg.ends_with("check the cable and udev permissions"),
                    "{msg}"
                );
            }
            other => panic!("unexpected error {other:?}"),
        }
    }
}
