//! X-Rite MA-T12 (USB bulk): the wire codec and the real USB transport.

pub mod codec;
pub mod usb;
