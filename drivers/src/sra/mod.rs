//! Canon RA-532H "SRA" (serial): the wire codec and the real serial transport.

pub mod codec;
pub mod serial;
