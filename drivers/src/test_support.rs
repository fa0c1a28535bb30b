//! Test-only support shared by the codec, session, tap and driver tests: how many cases every
//! property test runs, an independent CRC, the checks every codec must pass whatever its bytes
//! (generic over [`Codec`]), and an in-memory sink for the recorder.
//!
//! Case count: 2,000 cases per property in every `cargo test` run (CI included), so each parser
//! of outside bytes sees at least 2,000 generated inputs per run; `PROPTEST_CASES=N` overrides
//! it for a long run (TESTING.md gives the command and the last result). Failures are persisted
//! by proptest's default, `proptest-regressions/` beside `src/`, which is committed so that a
//! case once found is replayed first on every later run.
use std::io::{self, Write};
use std::sync::{Arc, Mutex};

use bytes::BytesMut;
use proptest::prelude::{TestCaseError, prop_assert, prop_assert_eq};
use proptest::test_runner::Config;

use crate::protocol::{Codec, Reading, Request, Response, golden};

/// Cases per property when `PROPTEST_CASES` is not set.
pub(crate) const CI_CASES: u32 = 2_000;

/// proptest's defaults (failure persistence included) with [`CI_CASES`] cases unless
/// `PROPTEST_CASES` says otherwise.
pub(crate) fn config() -> Config {
    let mut c = Config::default();
    if std::env::var_os("PROPTEST_CASES").is_none() {
        c.cases = CI_CASES;
    }
    c
}

/// CRC-16/IBM-3740 (poly 0x1021, init 0xFFFF, no reflection, no final xor) computed bit by bit,
/// independently of the `crc` crate the codecs use: the fuzz tests frame their payloads with it,
/// so a codec whose checksum drifted would refuse them.
pub(crate) fn crc16_bitwise(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in bytes {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// Every response `C` decodes off the front of `buf`, dropping what it rejects, until it needs
/// more bytes.
pub(crate) fn drain<C: Codec>(buf: &mut BytesMut) -> Vec<Response> {
    let mut out = Vec::new();
    while !buf.is_empty() {
        match C::decode_response(buf) {
            Ok(None) => break,
            Ok(Some(r)) => out.push(r),
            Err(_) => {}
        }
    }
    out
}

/// Panics if any single-bit flip of the valid frame `good` decodes to a response under `C`.
pub(crate) fn assert_every_bit_flip_is_caught<C: Codec>(good: &[u8]) {
    for byte in 0..good.len() {
        for bit in 0..8 {
            let mut bad = good.to_vec();
            bad[byte] ^= 1 << bit;
            let mut buf = BytesMut::from(&bad[..]);
            while !buf.is_empty() {
                match C::decode_response(&mut buf) {
                    Ok(None) => break,
                    Ok(Some(r)) => panic!("flip {byte}:{bit} decoded to {r}"),
                    Err(_) => {}
                }
            }
        }
    }
}

/// Each request encodes under `C` to the bytes of its PROTOCOL.md golden frame, labelled beside
/// it, and those bytes decode back to the request, consumed whole.
pub(crate) fn assert_golden_requests<C: Codec>(cases: &[(Request, &str)]) {
    for &(req, label) in cases {
        let bytes = golden(label);
        assert_eq!(C::encode_request(&req).unwrap(), bytes, "{label}");
        let mut buf = BytesMut::from(&bytes[..]);
        assert_eq!(C::decode_request(&mut buf), Ok(Some(req)), "{label}");
        assert!(buf.is_empty());
    }
}

/// The property of arbitrary bytes: neither of `C`'s decoders panics on them, and the response
/// decoder never makes a reading of them.
pub(crate) fn arbitrary_bytes_yield_no_reading<C: Codec>(
    bytes: &[u8],
) -> Result<(), TestCaseError> {
    let mut buf = BytesMut::from(bytes);
    for r in drain::<C>(&mut buf) {
        prop_assert!(!matches!(
            r,
            Response::Fetched(_) | Response::MeasuredOne(_)
        ));
    }
    let mut buf = BytesMut::from(bytes);
    while !buf.is_empty() {
        if let Ok(None) = C::decode_request(&mut buf) {
            break;
        }
    }
    Ok(())
}

/// The property of an encoded FETCH reply `bytes` fed to `C`'s response decoder `chunk` bytes at
/// a time: it decodes to exactly one reply, whose reading is `sent` bit for bit.
pub(crate) fn decodes_once_in_any_chunking<C: Codec>(
    bytes: &[u8],
    chunk: usize,
    sent: &Reading,
) -> Result<(), TestCaseError> {
    let mut buf = BytesMut::new();
    let mut got = Vec::new();
    for piece in bytes.chunks(chunk) {
        buf.extend_from_slice(piece);
        while let Some(resp) = C::decode_response(&mut buf).unwrap() {
            got.push(resp);
        }
    }
    prop_assert_eq!(got.len(), 1);
    let Response::Fetched(back) = &got[0] else {
        panic!("not a reading")
    };
    prop_assert!(back.bit_eq(sent));
    Ok(())
}

/// A shared in-memory sink for a [`crate::tap::Recorder`], so a test can read what it wrote.
#[derive(Clone, Default)]
pub(crate) struct Sink(Arc<Mutex<Vec<u8>>>);

impl Write for Sink {
    fn write(&mut self, b: &[u8]) -> io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(b);
        Ok(b.len())
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

impl Sink {
    /// Everything written so far, as text.
    pub(crate) fn text(&self) -> String {
        String::from_utf8(self.0.lock().unwrap().clone()).unwrap()
    }
}

#[test]
fn the_bitwise_crc_matches_the_catalogue_check_value() {
    // CRC RevEng catalogue, CRC-16/IBM-3740: check = 0x29B1 over "123456789".
    assert_eq!(crc16_bitwise(b"123456789"), 0x29B1);
}
