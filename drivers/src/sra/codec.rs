//! The SRA wire codec: brdfd's own ASCII line framing for the Canon RA-532H over a serial line
//! (PROTOCOL.md, "SRA"). Canon's protocol is not public; this file is the only place that knows
//! these bytes, so a vendor's real protocol replaces this one file.
//!
//! A line is `<start><body>*<CRC>\r\n`: start `$` for requests and `!` for replies; body fields
//! separated by `,`; CRC = CRC-16/IBM-3740 of `<start><body>` as four upper-case hex digits.
//! `$`, `!` and `*` never occur inside a body, so after garbage the decoder resynchronises on the
//! last start character before a line end.
//!
//! Intensities are written in the shortest decimal that reads back to the same IEEE-754 binary64
//! value (Rust's `{}` formatting, `{:e}` outside 1e-5..1e9), so a recorded reading and the
//! driver's reading compare bit for bit.

use crate::protocol::{
    CRC16, Check, Codec, DeviceState, EncodeError, ErrorCode, FrameError, Identity, Instrument,
    Reading, ReadingValue, Request, RequestKind, Response, SRA_GEOMETRIES, Status,
};

/// Wire codes of [`SRA_GEOMETRIES`], index for index: the incidence = viewing angle in degrees.
pub const GEOMETRY_CODES: [&str; 2] = ["20", "60"];

/// Start of a request line.
pub const REQUEST_START: u8 = b'$';
/// Start of a reply line.
pub const REPLY_START: u8 = b'!';
/// Longest line, terminator included. A longer run without `\r\n` is dropped as garbage.
pub const MAX_LINE: usize = 128;
/// Serial settings brdfd opens the port with: 9600 baud, 8 data bits, no parity, 1 stop bit.
pub const BAUD_RATE: u32 = 9600;

/// The SRA codec.
#[derive(Debug, Clone, Copy, Default)]
pub struct SraCodec;

/// Wire code (`20`, `60`) of a geometry name.
pub fn geometry_code(name: &str) -> Option<&'static str> {
    SRA_GEOMETRIES
        .iter()
        .position(|g| *g == name)
        .map(|i| GEOMETRY_CODES[i])
}

/// Geometry name of a wire code.
pub fn geometry_name(code: &str) -> Option<&'static str> {
    GEOMETRY_CODES
        .iter()
        .position(|c| *c == code)
        .map(|i| SRA_GEOMETRIES[i])
}

const fn mnemonic(kind: RequestKind) -> &'static str {
    match kind {
        RequestKind::Identify => "ID",
        RequestKind::Status => "ST",
        RequestKind::Calibrate => "CAL",
        RequestKind::MeasureAll => "MA",
        RequestKind::Fetch => "RD",
        RequestKind::MeasureOne => "M1",
        RequestKind::Abort => "AB",
    }
}

fn kind_of(mnemonic: &str) -> Option<RequestKind> {
    Some(match mnemonic {
        "ID" => RequestKind::Identify,
        "ST" => RequestKind::Status,
        "CAL" => RequestKind::Calibrate,
        "MA" => RequestKind::MeasureAll,
        "RD" => RequestKind::Fetch,
        "M1" => RequestKind::MeasureOne,
        "AB" => RequestKind::Abort,
        _ => return None,
    })
}

const fn error_mnemonic(code: ErrorCode) -> &'static str {
    match code {
        ErrorCode::BadChecksum => "CRC",
        ErrorCode::UnknownRequest => "UNKNOWN",
        ErrorCode::NotCalibrated => "NOCAL",
        ErrorCode::Busy => "BUSY",
        ErrorCode::NoMeasurement => "NODATA",
        ErrorCode::BadGeometry => "BADGEOM",
        ErrorCode::MeasurementFailed => "FAULT",
        ErrorCode::Aborted => "ABORTED",
    }
}

fn error_code(s: &str) -> Option<ErrorCode> {
    ErrorCode::ALL.into_iter().find(|c| error_mnemonic(*c) == s)
}

const fn state_word(state: DeviceState) -> &'static str {
    match state {
        DeviceState::Ready => "READY",
        DeviceState::Busy => "BUSY",
        DeviceState::NeedsCalibration => "NOCAL",
    }
}

/// Characters allowed in a body: printable ASCII except the framing characters.
fn body_char(b: u8) -> bool {
    (0x20..=0x7E).contains(&b) && !matches!(b, b'$' | b'!' | b'*')
}

/// Build a whole line from a start character and body.
pub fn line(start: u8, body: &str) -> Vec<u8> {
    let mut out = Vec::with_capacity(body.len() + 8);
    out.push(start);
    out.extend_from_slice(body.as_bytes());
    let crc = CRC16.checksum(&out);
    out.extend_from_slice(format!("*{crc:04X}\r\n").as_bytes());
    out
}

/// First framing step: is a whole checksummed line starting with `start` at the front of `buf`?
pub fn check(buf: &[u8], start: u8) -> Check {
    if buf.is_empty() {
        return Check::Incomplete;
    }
    let Some(first) = buf.iter().position(|b| *b == start) else {
        return Check::Reject(buf.len(), FrameError::Garbage { skipped: buf.len() });
    };
    if first > 0 {
        return Check::Reject(first, FrameError::Garbage { skipped: first });
    }
    let Some(nl) = buf.iter().position(|b| *b == b'\n') else {
        if buf.len() >= MAX_LINE {
            // No terminator where one must be: drop up to a later start, or everything.
            let cut = buf[1..]
                .iter()
                .position(|b| *b == start)
                .map_or(buf.len(), |i| i + 1);
            return Check::Reject(
                cut,
                FrameError::LineTooLong {
                    len: cut,
                    max: MAX_LINE,
                },
            );
        }
        return Check::Incomplete;
    };
    // A line begins at the last start character before its terminator.
    let last = buf[..nl].iter().rposition(|b| *b == start).unwrap_or(0);
    if last > 0 {
        return Check::Reject(last, FrameError::Garbage { skipped: last });
    }
    let len = nl + 1;
    if len > MAX_LINE {
        return Check::Reject(len, FrameError::LineTooLong { len, max: MAX_LINE });
    }
    // <start><body>*XXXX\r\n: at least 1 + 0 + 5 + 2 bytes. Without that tail the bytes
    // cannot be a line of this protocol (noise that happens to hold a start character and a
    // line end): garbage, which does not cost the driver a resend (PROTOCOL.md §4).
    if len < 8 || buf[nl - 1] != b'\r' || buf[nl - 6] != b'*' {
        return Check::Reject(len, FrameError::NotALine { len });
    }
    let digits = &buf[nl - 5..nl - 1];
    if !digits
        .iter()
        .all(|b| b.is_ascii_digit() || (b'A'..=b'F').contains(b))
    {
        return Check::Reject(
            len,
            FrameError::malformed("checksum is not 4 upper-case hex digits"),
        );
    }
    let received =
        u16::from_str_radix(std::str::from_utf8(digits).expect("ascii"), 16).expect("checked hex");
    let computed = CRC16.checksum(&buf[..nl - 6]);
    if computed != received {
        return Check::Reject(len, FrameError::BadChecksum { computed, received });
    }
    Check::Frame(len)
}

/// The fields of one whole line. The checks of [`check`] are repeated (the CRC too), so
/// `parse_*` on bytes that did not come through `check` can never yield a reading.
fn fields(frame: &[u8]) -> Result<Vec<&str>, FrameError> {
    let start = *frame
        .first()
        .ok_or_else(|| FrameError::malformed("empty line"))?;
    match check(frame, start) {
        Check::Frame(len) if len == frame.len() => {}
        Check::Reject(_, e) => return Err(e),
        _ => return Err(FrameError::malformed("not exactly one whole SRA line")),
    }
    let body = &frame[1..frame.len() - 7];
    if let Some(b) = body.iter().find(|b| !body_char(**b)) {
        return Err(FrameError::malformed(format!(
            "byte 0x{b:02X} is not allowed in a line"
        )));
    }
    Ok(std::str::from_utf8(body)
        .expect("printable ascii")
        .split(',')
        .collect())
}

fn arity(f: &[&str], n: usize) -> Result<(), FrameError> {
    if f.len() == n {
        Ok(())
    } else {
        Err(FrameError::malformed(format!(
            "{} takes {} field(s), got {}",
            f[0],
            n - 1,
            f.len() - 1
        )))
    }
}

fn geometry_from(code: &str) -> Result<&'static str, FrameError> {
    geometry_name(code).ok_or_else(|| FrameError::UnknownGeometry {
        code: code.to_owned(),
    })
}

/// A small unsigned decimal with at most three digits (counts and percentages).
fn small_number(field: &str, s: &str) -> Result<u8, FrameError> {
    if s.is_empty() || s.len() > 3 || !s.bytes().all(|b| b.is_ascii_digit()) {
        return Err(FrameError::malformed(format!(
            "{field} {s:?} is not a number 0-255"
        )));
    }
    s.parse()
        .map_err(|_| FrameError::malformed(format!("{field} {s:?} is not a number 0-255")))
}

/// `-?digits(.digits)?(e-?digits)?`: the only decimal forms the codec writes; this keeps `inf`,
/// `NaN`, `+1`, hex floats and an upper-case `E` (PROTOCOL.md §3 lists only `e`) off the wire.
fn decimal_grammar(s: &str) -> bool {
    let s = s.strip_prefix('-').unwrap_or(s);
    let (mantissa, exp) = match s.split_once('e') {
        Some((m, e)) => (m, Some(e.strip_prefix('-').unwrap_or(e))),
        None => (s, None),
    };
    let digits = |t: &str| !t.is_empty() && t.bytes().all(|b| b.is_ascii_digit());
    let mantissa_ok = match mantissa.split_once('.') {
        Some((i, f)) => digits(i) && digits(f),
        None => digits(mantissa),
    };
    mantissa_ok && exp.is_none_or(digits)
}

fn parse_value(geometry: &'static str, s: &str) -> Result<f64, FrameError> {
    if !decimal_grammar(s) {
        return Err(FrameError::malformed(format!(
            "intensity {s:?} for {geometry} is not a decimal"
        )));
    }
    let v: f64 = s
        .parse()
        .map_err(|_| FrameError::malformed(format!("intensity {s:?} for {geometry}")))?;
    if !v.is_finite() {
        return Err(FrameError::NonFinite { geometry, band: 0 });
    }
    Ok(v)
}

/// Shortest decimal that reads back to exactly `v`.
pub fn format_value(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 || (1e-5..1e9).contains(&a) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

fn parse_reading(f: &[&str]) -> Result<Reading, FrameError> {
    arity(f, 3)?;
    let geometry = geometry_from(f[1])?;
    let v = parse_value(geometry, f[2])?;
    Ok(Reading {
        geometry,
        value: ReadingValue::Intensity(v),
    })
}

fn code_for(geometry: &str) -> Result<&'static str, EncodeError> {
    geometry_code(geometry).ok_or_else(|| EncodeError::unknown_geometry(Instrument::Sra, geometry))
}

fn reading_body(tag: &str, r: &Reading) -> Result<String, EncodeError> {
    let code = code_for(r.geometry)?;
    let ReadingValue::Intensity(v) = r.value else {
        return Err(EncodeError::WrongValueKind {
            instrument: Instrument::Sra,
            expected: "one intensity",
            found: "a 31-band reflectance",
        });
    };
    if !v.is_finite() {
        return Err(EncodeError::NonFinite {
            instrument: Instrument::Sra,
            geometry: r.geometry,
        });
    }
    Ok(format!("{tag},{code},{}", format_value(v)))
}

fn text_field(field: &'static str, s: &str) -> Result<(), EncodeError> {
    if s.bytes().all(|b| body_char(b) && b != b',') {
        Ok(())
    } else {
        Err(EncodeError::BadField {
            instrument: Instrument::Sra,
            field,
            value: s.to_owned(),
            why: "printable ASCII without , * $ or !",
        })
    }
}

impl Codec for SraCodec {
    const INSTRUMENT: Instrument = Instrument::Sra;

    fn check_request(buf: &[u8]) -> Check {
        check(buf, REQUEST_START)
    }

    fn check_response(buf: &[u8]) -> Check {
        check(buf, REPLY_START)
    }

    fn parse_request(frame: &[u8]) -> Result<Request, FrameError> {
        if frame.first() != Some(&REQUEST_START) {
            return Err(FrameError::malformed("a request starts with $"));
        }
        let f = fields(frame)?;
        let kind = kind_of(f[0]).ok_or_else(|| FrameError::UnknownOpcode { what: f[0].into() })?;
        Ok(match kind {
            RequestKind::Fetch => {
                arity(&f, 2)?;
                Request::Fetch {
                    geometry: geometry_from(f[1])?,
                }
            }
            RequestKind::MeasureOne => {
                arity(&f, 2)?;
                Request::MeasureOne {
                    geometry: geometry_from(f[1])?,
                }
            }
            simple => {
                arity(&f, 1)?;
                match simple {
                    RequestKind::Identify => Request::Identify,
                    RequestKind::Status => Request::Status,
                    RequestKind::Calibrate => Request::Calibrate,
                    RequestKind::MeasureAll => Request::MeasureAll,
                    _ => Request::Abort,
                }
            }
        })
    }

    fn parse_response(frame: &[u8]) -> Result<Response, FrameError> {
        if frame.first() != Some(&REPLY_START) {
            return Err(FrameError::malformed("a reply starts with !"));
        }
        let f = fields(frame)?;
        match f[0] {
            "ID" => {
                arity(&f, 4)?;
                Ok(Response::Identity(Identity {
                    model: f[1].into(),
                    serial: f[2].into(),
                    firmware: f[3].into(),
                }))
            }
            "ST" => {
                arity(&f, 3)?;
                let state = match f[1] {
                    "READY" => DeviceState::Ready,
                    "BUSY" => DeviceState::Busy,
                    "NOCAL" => DeviceState::NeedsCalibration,
                    s => return Err(FrameError::malformed(format!("STATUS state {s:?} unknown"))),
                };
                Status::parsed(state, small_number("battery", f[2])?).map(Response::Status)
            }
            "CAL" => arity(&f, 1).map(|_| Response::Calibrated),
            "MA" => {
                arity(&f, 2)?;
                Ok(Response::Measured {
                    count: small_number("count", f[1])?,
                })
            }
            "RD" => parse_reading(&f).map(Response::Fetched),
            "M1" => parse_reading(&f).map(Response::MeasuredOne),
            "AB" => arity(&f, 1).map(|_| Response::Aborted),
            "ER" => {
                if !(3..=4).contains(&f.len()) {
                    return Err(FrameError::malformed("ER takes 2 or 3 fields"));
                }
                let request = kind_of(f[1]).ok_or_else(|| {
                    FrameError::malformed(format!("ER names unknown request {:?}", f[1]))
                })?;
                let code = error_code(f[2])
                    .ok_or_else(|| FrameError::malformed(format!("ER code {:?} unknown", f[2])))?;
                let geometry = match f.get(3) {
                    Some(c) => Some(geometry_from(c)?),
                    None => None,
                };
                Ok(Response::Error {
                    request,
                    code,
                    geometry,
                })
            }
            other => Err(FrameError::UnknownOpcode { what: other.into() }),
        }
    }

    fn encode_request(request: &Request) -> Result<Vec<u8>, EncodeError> {
        let m = mnemonic(request.kind());
        let body = match request.geometry() {
            Some(g) => format!("{m},{}", code_for(g)?),
            None => m.to_owned(),
        };
        Ok(line(REQUEST_START, &body))
    }

    fn encode_response(response: &Response) -> Result<Vec<u8>, EncodeError> {
        let body = match response {
            Response::Identity(id) => {
                text_field("model", &id.model)?;
                text_field("serial", &id.serial)?;
                text_field("firmware", &id.firmware)?;
                format!("ID,{},{},{}", id.model, id.serial, id.firmware)
            }
            Response::Status(s) => {
                s.check_encodable(Instrument::Sra)?;
                format!("ST,{},{}", state_word(s.state), s.battery_percent)
            }
            Response::Calibrated => "CAL".to_owned(),
            Response::Measured { count } => format!("MA,{count}"),
            Response::Fetched(r) => reading_body("RD", r)?,
            Response::MeasuredOne(r) => reading_body("M1", r)?,
            Response::Aborted => "AB".to_owned(),
            Response::Error {
                request,
                code,
                geometry,
            } => match geometry {
                Some(g) => format!(
                    "ER,{},{},{}",
                    mnemonic(*request),
                    error_mnemonic(*code),
                    code_for(g)?
                ),
                None => format!("ER,{},{}", mnemonic(*request), error_mnemonic(*code)),
            },
        };
        let bytes = line(REPLY_START, &body);
        if bytes.len() > MAX_LINE {
            return Err(EncodeError::BadField {
                instrument: Instrument::Sra,
                field: "line",
                value: body,
                why: "a line is at most 128 bytes",
            });
        }
        Ok(bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::golden;
    use crate::test_support::{
        arbitrary_bytes_yield_no_reading, assert_every_bit_flip_is_caught, assert_golden_requests,
        decodes_once_in_any_chunking, drain,
    };
    use bytes::BytesMut;
    use proptest::prelude::*;
    use proptest::sample::select;

    fn intensity(geometry: &'static str, v: f64) -> Reading {
        Reading {
            geometry,
            value: ReadingValue::Intensity(v),
        }
    }

    // Golden lines come verbatim from PROTOCOL.md (CRCs computed independently of this code).
    #[test]
    fn golden_requests_encode_and_parse() {
        assert_golden_requests::<SraCodec>(&[
            (Request::Identify, "sra IDENTIFY"),
            (Request::Status, "sra STATUS"),
            (Request::Calibrate, "sra CALIBRATE"),
            (Request::MeasureAll, "sra MEASURE-ALL"),
            (Request::Fetch { geometry: "sra-20" }, "sra FETCH sra-20"),
            (
                Request::MeasureOne { geometry: "sra-60" },
                "sra MEASURE-ONE sra-60",
            ),
            (Request::Abort, "sra ABORT"),
        ]);
    }

    #[test]
    fn golden_replies_encode_and_parse() {
        let cases = [
            (
                Response::Identity(Identity {
                    model: "RA-532H".into(),
                    serial: "SN-004711".into(),
                    firmware: "FW 1.07".into(),
                }),
                "sra IDENTITY",
            ),
            (
                Response::Status(Status {
                    state: DeviceState::Ready,
                    battery_percent: 64,
                }),
                "sra STATUS ready 64%",
            ),
            (Response::Calibrated, "sra CALIBRATED"),
            (Response::Measured { count: 2 }, "sra MEASURED 2"),
            (
                Response::Fetched(intensity("sra-20", 3.1)),
                "sra READING sra-20",
            ),
            (
                Response::Fetched(intensity("sra-60", 7.9)),
                "sra READING sra-60",
            ),
            (
                Response::MeasuredOne(intensity("sra-60", 0.245)),
                "sra READING (measure-one) sra-60",
            ),
            (Response::Aborted, "sra ABORTED"),
            (
                Response::Error {
                    request: RequestKind::Fetch,
                    code: ErrorCode::NoMeasurement,
                    geometry: Some("sra-20"),
                },
                "sra ERROR FETCH NO-MEASUREMENT sra-20",
            ),
        ];
        for (resp, label) in cases {
            let bytes = golden(label);
            assert_eq!(SraCodec::encode_response(&resp).unwrap(), bytes, "{label}");
            let mut buf = BytesMut::from(&bytes[..]);
            assert_eq!(
                SraCodec::decode_response(&mut buf),
                Ok(Some(resp)),
                "{label}"
            );
        }
    }

    #[test]
    fn resynchronises_after_garbage_containing_start_characters() {
        let good = golden("sra READING sra-20");
        let mut buf = BytesMut::from(&b"\x00\xff!!RD,2"[..]);
        buf.extend_from_slice(&good);
        let mut got = Vec::new();
        let mut errors = 0;
        loop {
            match SraCodec::decode_response(&mut buf) {
                Ok(Some(r)) => got.push(r),
                Ok(None) => break,
                Err(_) => errors += 1,
            }
        }
        assert_eq!(got, vec![Response::Fetched(intensity("sra-20", 3.1))]);
        assert!(errors >= 1);
        assert!(buf.is_empty());
    }

    #[test]
    fn parsing_without_the_check_step_still_verifies_the_checksum() {
        let mut bad = golden("sra READING sra-20");
        bad[5] = b'1';
        assert!(matches!(
            SraCodec::parse_response(&bad),
            Err(FrameError::BadChecksum { .. })
        ));
        let two = [golden("sra ABORTED"), golden("sra ABORTED")].concat();
        assert!(
            SraCodec::parse_response(&two).is_err(),
            "one line at a time"
        );
    }

    #[test]
    fn partial_lines_wait() {
        let good = golden("sra READING sra-60");
        for cut in 0..good.len() {
            assert_eq!(
                check(&good[..cut], REPLY_START),
                Check::Incomplete,
                "cut {cut}"
            );
        }
    }

    #[test]
    fn a_line_without_terminator_is_dropped_at_the_limit() {
        let mut buf = BytesMut::from(&[b'!'; 1][..]);
        buf.extend_from_slice(&[b'7'; MAX_LINE]);
        assert!(matches!(
            SraCodec::decode_response(&mut buf),
            Err(FrameError::LineTooLong { .. })
        ));
        assert!(buf.is_empty());
    }

    #[test]
    fn lower_case_checksum_and_non_decimal_values_are_refused() {
        let mut good = golden("sra READING sra-20");
        let n = good.len();
        assert_eq!(good[n - 6], b'F', "golden CRC is F721");
        good[n - 6] = b'f';
        assert!(matches!(check(&good, REPLY_START), Check::Reject(..)));
        for v in ["inf", "NaN", "+1", "0x10", "1e400", "1.", ".5", ""] {
            let bytes = line(REPLY_START, &format!("RD,20,{v}"));
            let mut buf = BytesMut::from(&bytes[..]);
            assert!(
                SraCodec::decode_response(&mut buf).is_err(),
                "{v:?} accepted"
            );
        }
    }

    #[test]
    fn lines_without_the_checksum_tail_are_garbage_and_damaged_lines_are_not() {
        // Too short, no `\r`, no `*`: noise holding a start character and a line end. Dropped
        // as garbage (no resend, PROTOCOL.md §4); the reply behind it decodes.
        let reply = golden("sra READING sra-20");
        for noise in [
            &b"!\r\n"[..],
            b"!$\x00\r\n",
            b"!RD,20,3.1*F721\n",
            b"!RD,20,3.1F721\r\n",
        ] {
            let mut buf = BytesMut::from(noise);
            buf.extend_from_slice(&reply);
            let e = SraCodec::decode_response(&mut buf).unwrap_err();
            assert_eq!(e, FrameError::NotALine { len: noise.len() }, "{noise:?}");
            assert!(e.is_garbage());
            let (response, raw) = SraCodec::decode_response_frame(&mut buf).unwrap().unwrap();
            assert_eq!(response, Response::Fetched(intensity("sra-20", 3.1)));
            assert_eq!(raw[..], reply[..], "the line's bytes as received");
        }
        // A whole line whose checksum fails, or is not upper-case hex, was a reply, damaged.
        let n = reply.len();
        for (at, b) in [(5, b'1'), (n - 6, b'f')] {
            let mut bad = reply.clone();
            bad[at] = b;
            let Check::Reject(len, e) = check(&bad, REPLY_START) else {
                panic!("byte {at} = {b} accepted")
            };
            assert_eq!(len, n, "dropped whole");
            assert!(!e.is_garbage(), "{e}");
        }
    }

    #[test]
    fn a_non_canonical_intensity_is_read_and_its_bytes_kept() {
        // `3.10` is not how the codec writes 3.1, but it is a valid line: the value is read
        // and the frame handed back is the one received, not a re-encoding.
        let received = line(REPLY_START, "RD,20,3.10");
        let mut buf = BytesMut::from(&received[..]);
        let (response, raw) = SraCodec::decode_response_frame(&mut buf).unwrap().unwrap();
        assert_eq!(response, Response::Fetched(intensity("sra-20", 3.1)));
        assert_eq!(raw[..], received[..]);
        assert_ne!(SraCodec::encode_response(&response).unwrap(), received);
    }

    #[test]
    fn every_single_bit_flip_of_a_golden_reading_is_caught() {
        assert_every_bit_flip_is_caught::<SraCodec>(&golden("sra READING (measure-one) sra-60"));
    }

    /// `<start><body>*XXXX\r\n` with the checksum from the independent bit-by-bit CRC, so the
    /// line passes the checksum and reaches the field parsers.
    fn framed(start: u8, body: &[u8]) -> Vec<u8> {
        let mut out = vec![start];
        out.extend_from_slice(body);
        let crc = crate::test_support::crc16_bitwise(&out);
        out.extend_from_slice(format!("*{crc:04X}\r\n").as_bytes());
        out
    }

    /// PROTOCOL.md §3's intensity grammar, `-?digits(.digits)?(e-?digits)?`, as a regular
    /// expression: the oracle the value parser is checked against.
    fn intensity_grammar() -> regex::Regex {
        regex::Regex::new(r"^-?[0-9]+(\.[0-9]+)?(e-?[0-9]+)?$").unwrap()
    }

    /// The property every checksummed line must satisfy: no panic; a line whose body is all
    /// body characters is consumed whole; a READING is accepted exactly when PROTOCOL.md says
    /// it is valid (code 20 or 60, the decimal grammar, a finite value) with the correctly
    /// rounded value; whatever is accepted re-encodes to bytes that decode to the same thing.
    fn check_framed(start: u8, body: &[u8], grammar: &regex::Regex) -> Result<(), TestCaseError> {
        let bytes = framed(start, body);
        let clean = body.iter().all(|b| body_char(*b));
        let mut buf = BytesMut::from(&bytes[..]);
        let got = SraCodec::decode_response(&mut buf);
        if clean {
            prop_assert!(
                buf.is_empty(),
                "a checksummed line must be consumed whole: {got:?}"
            );
        }
        let text = String::from_utf8_lossy(body);
        let fields: Vec<&str> = text.split(',').collect();
        if start == REPLY_START && clean && matches!(fields[0], "RD" | "M1") {
            let oracle = (bytes.len() <= MAX_LINE
                && fields.len() == 3
                && matches!(fields[1], "20" | "60")
                && grammar.is_match(fields[2]))
            .then(|| fields[2].parse::<f64>().unwrap())
            .filter(|v| v.is_finite());
            match (&got, oracle) {
                (Ok(Some(Response::Fetched(r) | Response::MeasuredOne(r))), Some(v)) => {
                    prop_assert_eq!(geometry_code(r.geometry), Some(fields[1]));
                    let ReadingValue::Intensity(x) = r.value else {
                        return Err(TestCaseError::fail("SRA reading is not an intensity"));
                    };
                    prop_assert_eq!(x.to_bits(), v.to_bits());
                }
                (Err(_), None) => {}
                _ => prop_assert!(false, "{text:?}: parser {got:?}, oracle {oracle:?}"),
            }
        }
        if let Ok(Some(resp)) = &got {
            let again = SraCodec::encode_response(resp).unwrap();
            let back = SraCodec::decode_response(&mut BytesMut::from(&again[..]));
            prop_assert!(
                matches!(&back, Ok(Some(b)) if b == resp),
                "{resp:?} came back as {back:?}"
            );
            if let (
                Response::Fetched(a) | Response::MeasuredOne(a),
                Ok(Some(Response::Fetched(b) | Response::MeasuredOne(b))),
            ) = (resp, &back)
            {
                prop_assert!(a.bit_eq(b));
            }
        }
        let mut buf = BytesMut::from(&bytes[..]);
        let req = SraCodec::decode_request(&mut buf);
        if clean {
            prop_assert!(
                buf.is_empty(),
                "a checksummed line must be consumed whole: {req:?}"
            );
        }
        if let Ok(Some(req)) = &req {
            let again = SraCodec::encode_request(req).unwrap();
            prop_assert_eq!(
                SraCodec::decode_request(&mut BytesMut::from(&again[..])),
                Ok(Some(*req))
            );
        }
        Ok(())
    }

    /// Fields as the fuzz writes them: the protocol's words and codes, decimal-looking text
    /// (the value parser's ground), and any printable ASCII.
    fn field() -> impl Strategy<Value = String> {
        prop_oneof![
            3 => select(vec![
                "ID", "ST", "CAL", "MA", "RD", "M1", "AB", "ER", "READY", "BUSY", "NOCAL",
                "20", "60", "0", "2", "100", "101", "CRC", "UNKNOWN", "NODATA", "BADGEOM",
                "FAULT", "ABORTED",
            ]).prop_map(str::to_owned),
            3 => "[-+0-9.eE]{0,24}",
            1 => "-?[0-9]{1,110}(\\.[0-9]{1,30})?(e-?[0-9]{1,4})?",
            1 => "[ -~]{0,12}",
        ]
    }

    /// Every golden reply and request line of PROTOCOL.md, as (start, body).
    fn golden_lines() -> Vec<(u8, Vec<u8>)> {
        [
            "IDENTIFY",
            "STATUS",
            "CALIBRATE",
            "MEASURE-ALL",
            "FETCH sra-20",
            "MEASURE-ONE sra-60",
            "ABORT",
            "IDENTITY",
            "STATUS ready 64%",
            "CALIBRATED",
            "MEASURED 2",
            "READING sra-20",
            "READING sra-60",
            "READING (measure-one) sra-60",
            "ABORTED",
            "ERROR FETCH NO-MEASUREMENT sra-20",
        ]
        .iter()
        .map(|label| {
            let g = golden(&format!("sra {label}"));
            (g[0], g[1..g.len() - 7].to_vec())
        })
        .collect()
    }

    /// One edit of a golden line's body (the checksum is recomputed afterwards): a byte set,
    /// inserted or removed, a cut, or one comma-separated field replaced.
    #[derive(Debug, Clone)]
    enum Edit {
        Set(usize, u8),
        Insert(usize, u8),
        Remove(usize),
        Truncate(usize),
        Field(usize, String),
    }

    fn edit() -> impl Strategy<Value = Edit> {
        let byte = prop_oneof![
            4 => select(b"-+.0123456789eE,".to_vec()),
            2 => 0x20u8..=0x7E,
            1 => any::<u8>(),
        ];
        prop_oneof![
            (any::<usize>(), byte.clone()).prop_map(|(i, b)| Edit::Set(i, b)),
            (any::<usize>(), byte).prop_map(|(i, b)| Edit::Insert(i, b)),
            any::<usize>().prop_map(Edit::Remove),
            any::<usize>().prop_map(Edit::Truncate),
            (any::<usize>(), field()).prop_map(|(i, f)| Edit::Field(i, f)),
        ]
    }

    fn apply_edits(mut body: Vec<u8>, edits: &[Edit]) -> Vec<u8> {
        let at = |i: usize, n: usize| if n == 0 { 0 } else { i % n };
        for e in edits {
            match e {
                Edit::Set(i, b) if !body.is_empty() => {
                    let i = at(*i, body.len());
                    body[i] = *b;
                }
                Edit::Insert(i, b) => body.insert(at(*i, body.len() + 1), *b),
                Edit::Remove(i) if !body.is_empty() => {
                    body.remove(at(*i, body.len()));
                }
                Edit::Truncate(i) => body.truncate(at(*i, body.len() + 1)),
                Edit::Field(i, f) => {
                    let text = String::from_utf8_lossy(&body).into_owned();
                    let mut fields: Vec<&str> = text.split(',').collect();
                    let i = at(*i, fields.len());
                    fields[i] = f;
                    body = fields.join(",").into_bytes();
                }
                _ => {}
            }
        }
        body
    }

    proptest! {
        #![proptest_config(crate::test_support::config())]

        #[test]
        fn random_lines_past_the_crc_parse_exactly_or_are_refused(
            start in prop_oneof![Just(REPLY_START), Just(REQUEST_START)],
            fields in proptest::collection::vec(field(), 1..6),
        ) {
            check_framed(start, fields.join(",").as_bytes(), &intensity_grammar())?;
        }

        #[test]
        fn golden_lines_mutated_past_the_crc_parse_exactly_or_are_refused(
            which in 0usize..16,
            edits in proptest::collection::vec(edit(), 1..5),
        ) {
            let (start, body) = golden_lines().swap_remove(which);
            check_framed(start, &apply_edits(body, &edits), &intensity_grammar())?;
        }
    }

    #[test]
    fn every_golden_line_passes_the_fuzz_property_unchanged() {
        // The property must accept what PROTOCOL.md says is valid, or it checks nothing.
        let grammar = intensity_grammar();
        for (start, body) in golden_lines() {
            assert_eq!(
                framed(start, &body),
                line(start, std::str::from_utf8(&body).unwrap())
            );
            check_framed(start, &body, &grammar).unwrap();
        }
        // And it must refuse what PROTOCOL.md calls malformed.
        for bad in ["inf", "NaN", "+1", ".5", "1.", "1E5", "0x1p3", "1e400"] {
            assert!(
                SraCodec::decode_response(&mut BytesMut::from(
                    &framed(REPLY_START, format!("RD,20,{bad}").as_bytes())[..]
                ))
                .is_err(),
                "{bad}"
            );
        }
    }

    proptest! {
        #![proptest_config(crate::test_support::config())]

        #[test]
        fn arbitrary_bytes_never_panic_nor_yield_a_reading(
            bytes in proptest::collection::vec(any::<u8>(), 0..2048)
        ) {
            arbitrary_bytes_yield_no_reading::<SraCodec>(&bytes)?;
        }

        #[test]
        fn plausible_lines_with_wrong_checksums_never_yield_a_reading(
            code in prop_oneof![Just("20"), Just("60")],
            value in "[-0-9.e]{1,20}",
            crc in any::<u16>(),
        ) {
            let body = format!("!RD,{code},{value}");
            prop_assume!(crc != CRC16.checksum(body.as_bytes()));
            let bytes = format!("{body}*{crc:04X}\r\n").into_bytes();
            let mut buf = BytesMut::from(&bytes[..]);
            prop_assert!(drain::<SraCodec>(&mut buf).is_empty());
        }

        #[test]
        fn intensities_round_trip_bit_for_bit_in_any_chunking(
            bits in any::<u64>(),
            g in 0usize..2,
            chunk in 1usize..=16,
        ) {
            let v = f64::from_bits(bits);
            prop_assume!(v.is_finite());
            let r = intensity(SRA_GEOMETRIES[g], v);
            let bytes = SraCodec::encode_response(&Response::Fetched(r)).unwrap();
            prop_assert!(bytes.len() <= MAX_LINE);
            decodes_once_in_any_chunking::<SraCodec>(&bytes, chunk, &r)?;
        }
    }
}
