//! The MA-T12 wire codec: brdfd's own binary framing for the X-Rite MA-T12 over USB bulk
//! (PROTOCOL.md, "MA-T12"). X-Rite's protocol is not public; this file is the only place that
//! knows these bytes, so a vendor's real protocol replaces this one file.
//!
//! Frame (both directions), all integers little-endian:
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 2 | magic `4D 54` (`MT`) |
//! | 2 | 1 | opcode (requests 0x01–0x07, replies = request \| 0x80, error 0xFF) |
//! | 3 | 2 | payload length N (u16, at most [`MAX_PAYLOAD`]) |
//! | 5 | N | payload |
//! | 5+N | 2 | CRC-16/IBM-3740 of bytes 0..5+N (u16) |
//!
//! Readings are 31 IEEE-754 binary64 values: the reflectance factor travels exactly, so a
//! recorded reading and the driver's reading compare bit for bit.

use crate::protocol::{
    BANDS, CRC16, Check, Codec, DeviceState, EncodeError, ErrorCode, FrameError, Identity,
    Instrument, MAT12_GEOMETRIES, Reading, ReadingValue, Request, RequestKind, Response, Status,
};

/// Frame start.
pub const MAGIC: [u8; 2] = *b"MT";
/// Magic + opcode + length.
pub const HEADER_LEN: usize = 5;
/// CRC trailer.
pub const CRC_LEN: usize = 2;
/// Largest payload accepted; a larger declared length is treated as corruption.
pub const MAX_PAYLOAD: usize = 1024;

/// Opcode of the IDENTIFY request.
pub const OP_IDENTIFY: u8 = 0x01;
/// Opcode of the STATUS request.
pub const OP_STATUS: u8 = 0x02;
/// Opcode of the CALIBRATE request.
pub const OP_CALIBRATE: u8 = 0x03;
/// Opcode of the MEASURE-ALL request.
pub const OP_MEASURE_ALL: u8 = 0x04;
/// Opcode of the FETCH request.
pub const OP_FETCH: u8 = 0x05;
/// Opcode of the MEASURE-ONE request.
pub const OP_MEASURE_ONE: u8 = 0x06;
/// Opcode of the ABORT request.
pub const OP_ABORT: u8 = 0x07;
/// A reply's opcode is its request's opcode with the high bit set.
pub const REPLY_BIT: u8 = 0x80;
/// Opcode of an error reply: the instrument refused a request.
pub const OP_ERROR: u8 = 0xFF;

/// Payload of a reading: geometry code + 31 × f64.
const READING_PAYLOAD: usize = 1 + 8 * BANDS;

/// The MA-T12 codec.
#[derive(Debug, Clone, Copy, Default)]
pub struct Mat12Codec;

/// Wire code (1–12) of a geometry name: its position in [`MAT12_GEOMETRIES`] plus one.
pub fn geometry_code(name: &str) -> Option<u8> {
    MAT12_GEOMETRIES
        .iter()
        .position(|g| *g == name)
        .map(|i| i as u8 + 1)
}

/// Geometry name of a wire code (1–12).
pub fn geometry_name(code: u8) -> Option<&'static str> {
    MAT12_GEOMETRIES
        .get((code as usize).checked_sub(1)?)
        .copied()
}

const fn opcode_of(kind: RequestKind) -> u8 {
    match kind {
        RequestKind::Identify => OP_IDENTIFY,
        RequestKind::Status => OP_STATUS,
        RequestKind::Calibrate => OP_CALIBRATE,
        RequestKind::MeasureAll => OP_MEASURE_ALL,
        RequestKind::Fetch => OP_FETCH,
        RequestKind::MeasureOne => OP_MEASURE_ONE,
        RequestKind::Abort => OP_ABORT,
    }
}

fn kind_of(opcode: u8) -> Option<RequestKind> {
    Some(match opcode {
        OP_IDENTIFY => RequestKind::Identify,
        OP_STATUS => RequestKind::Status,
        OP_CALIBRATE => RequestKind::Calibrate,
        OP_MEASURE_ALL => RequestKind::MeasureAll,
        OP_FETCH => RequestKind::Fetch,
        OP_MEASURE_ONE => RequestKind::MeasureOne,
        OP_ABORT => RequestKind::Abort,
        _ => return None,
    })
}

const fn error_byte(code: ErrorCode) -> u8 {
    match code {
        ErrorCode::BadChecksum => 0x01,
        ErrorCode::UnknownRequest => 0x02,
        ErrorCode::NotCalibrated => 0x03,
        ErrorCode::Busy => 0x04,
        ErrorCode::NoMeasurement => 0x05,
        ErrorCode::BadGeometry => 0x06,
        ErrorCode::MeasurementFailed => 0x07,
        ErrorCode::Aborted => 0x08,
    }
}

fn error_code(byte: u8) -> Option<ErrorCode> {
    ErrorCode::ALL.into_iter().find(|c| error_byte(*c) == byte)
}

const fn state_byte(state: DeviceState) -> u8 {
    match state {
        DeviceState::Ready => 0,
        DeviceState::Busy => 1,
        DeviceState::NeedsCalibration => 2,
    }
}

/// Build a whole frame around `payload`.
pub fn frame(opcode: u8, payload: &[u8]) -> Vec<u8> {
    debug_assert!(payload.len() <= MAX_PAYLOAD);
    let mut out = Vec::with_capacity(HEADER_LEN + payload.len() + CRC_LEN);
    out.extend_from_slice(&MAGIC);
    out.push(opcode);
    out.extend_from_slice(&(payload.len() as u16).to_le_bytes());
    out.extend_from_slice(payload);
    let crc = CRC16.checksum(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

/// First framing step (the same for both directions): is a whole, checksummed frame at the
/// front of `buf`? Leading bytes that cannot start a frame are rejected as garbage; a trailing
/// lone `M` is kept because the `T` may be in the next packet.
pub fn check(buf: &[u8]) -> Check {
    if buf.is_empty() {
        return Check::Incomplete;
    }
    let start = (0..buf.len())
        .find(|&i| buf[i] == MAGIC[0] && buf.get(i + 1).is_none_or(|b| *b == MAGIC[1]))
        .unwrap_or(buf.len());
    if start > 0 {
        return Check::Reject(start, FrameError::Garbage { skipped: start });
    }
    if buf.len() < HEADER_LEN {
        return Check::Incomplete;
    }
    let declared = u16::from_le_bytes([buf[3], buf[4]]) as usize;
    if declared > MAX_PAYLOAD {
        // Drop the magic only: a real frame may start inside what we took for this header.
        return Check::Reject(
            2,
            FrameError::BadLength {
                declared,
                max: MAX_PAYLOAD,
            },
        );
    }
    let total = HEADER_LEN + declared + CRC_LEN;
    if buf.len() < total {
        return Check::Incomplete;
    }
    let body = &buf[..HEADER_LEN + declared];
    let computed = CRC16.checksum(body);
    let received = u16::from_le_bytes([buf[total - 2], buf[total - 1]]);
    if computed != received {
        return Check::Reject(total, FrameError::BadChecksum { computed, received });
    }
    Check::Frame(total)
}

/// Split one whole frame into (opcode, payload). The checks of [`check`] are repeated (the CRC
/// too), so `parse_*` on bytes that did not come through `check` can never yield a reading.
fn split(frame: &[u8]) -> Result<(u8, &[u8]), FrameError> {
    match check(frame) {
        Check::Frame(len) if len == frame.len() => {}
        Check::Reject(_, e) => return Err(e),
        _ => return Err(FrameError::malformed("not exactly one whole MA-T12 frame")),
    }
    let declared = u16::from_le_bytes([frame[3], frame[4]]) as usize;
    Ok((frame[2], &frame[HEADER_LEN..HEADER_LEN + declared]))
}

fn expect_len(what: &str, payload: &[u8], len: usize) -> Result<(), FrameError> {
    if payload.len() == len {
        Ok(())
    } else {
        Err(FrameError::malformed(format!(
            "{what} payload must be {len} byte(s), got {}",
            payload.len()
        )))
    }
}

fn geometry_from(code: u8) -> Result<&'static str, FrameError> {
    geometry_name(code).ok_or(FrameError::UnknownGeometry {
        code: format!("0x{code:02X}"),
    })
}

fn parse_reading(payload: &[u8]) -> Result<Reading, FrameError> {
    expect_len("READING", payload, READING_PAYLOAD)?;
    let geometry = geometry_from(payload[0])?;
    let mut values = [0.0; BANDS];
    for (band, (v, bytes)) in values
        .iter_mut()
        .zip(payload[1..].chunks_exact(8))
        .enumerate()
    {
        let x = f64::from_le_bytes(bytes.try_into().expect("chunks_exact(8)"));
        if !x.is_finite() {
            return Err(FrameError::NonFinite { geometry, band });
        }
        *v = x;
    }
    Ok(Reading {
        geometry,
        value: ReadingValue::Reflectance(values),
    })
}

fn parse_string(payload: &[u8], at: &mut usize, field: &str) -> Result<String, FrameError> {
    let len = *payload
        .get(*at)
        .ok_or_else(|| FrameError::malformed(format!("IDENTITY ends before {field}")))?
        as usize;
    let bytes = payload
        .get(*at + 1..*at + 1 + len)
        .ok_or_else(|| FrameError::malformed(format!("IDENTITY {field} runs past the payload")))?;
    *at += 1 + len;
    let s = std::str::from_utf8(bytes)
        .map_err(|_| FrameError::malformed(format!("IDENTITY {field} is not UTF-8")))?;
    if s.chars().any(char::is_control) {
        return Err(FrameError::malformed(format!(
            "IDENTITY {field} has control characters"
        )));
    }
    Ok(s.to_owned())
}

fn encode_string(out: &mut Vec<u8>, field: &'static str, s: &str) -> Result<(), EncodeError> {
    if s.len() > u8::MAX as usize || s.chars().any(char::is_control) {
        return Err(EncodeError::BadField {
            instrument: Instrument::MaT12,
            field,
            value: s.to_owned(),
            why: "at most 255 bytes of UTF-8 without control characters",
        });
    }
    out.push(s.len() as u8);
    out.extend_from_slice(s.as_bytes());
    Ok(())
}

fn code_for(geometry: &str) -> Result<u8, EncodeError> {
    geometry_code(geometry)
        .ok_or_else(|| EncodeError::unknown_geometry(Instrument::MaT12, geometry))
}

fn reading_payload(r: &Reading) -> Result<Vec<u8>, EncodeError> {
    let code = code_for(r.geometry)?;
    let ReadingValue::Reflectance(values) = &r.value else {
        return Err(EncodeError::WrongValueKind {
            instrument: Instrument::MaT12,
            expected: "31-band reflectance",
            found: "an intensity",
        });
    };
    if values.iter().any(|v| !v.is_finite()) {
        return Err(EncodeError::NonFinite {
            instrument: Instrument::MaT12,
            geometry: r.geometry,
        });
    }
    let mut p = Vec::with_capacity(READING_PAYLOAD);
    p.push(code);
    for v in values {
        p.extend_from_slice(&v.to_le_bytes());
    }
    Ok(p)
}

impl Codec for Mat12Codec {
    const INSTRUMENT: Instrument = Instrument::MaT12;

    fn check_request(buf: &[u8]) -> Check {
        check(buf)
    }

    fn check_response(buf: &[u8]) -> Check {
        check(buf)
    }

    fn parse_request(frame: &[u8]) -> Result<Request, FrameError> {
        let (op, payload) = split(frame)?;
        let geometry = |name: &str| -> Result<&'static str, FrameError> {
            expect_len(name, payload, 1)?;
            geometry_from(payload[0])
        };
        let no_payload = |name: &str, req: Request| -> Result<Request, FrameError> {
            expect_len(name, payload, 0).map(|_| req)
        };
        match op {
            OP_IDENTIFY => no_payload("IDENTIFY", Request::Identify),
            OP_STATUS => no_payload("STATUS", Request::Status),
            OP_CALIBRATE => no_payload("CALIBRATE", Request::Calibrate),
            OP_MEASURE_ALL => no_payload("MEASURE-ALL", Request::MeasureAll),
            OP_FETCH => Ok(Request::Fetch {
                geometry: geometry("FETCH")?,
            }),
            OP_MEASURE_ONE => Ok(Request::MeasureOne {
                geometry: geometry("MEASURE-ONE")?,
            }),
            OP_ABORT => no_payload("ABORT", Request::Abort),
            other => Err(FrameError::UnknownOpcode {
                what: format!("0x{other:02X}"),
            }),
        }
    }

    fn parse_response(frame: &[u8]) -> Result<Response, FrameError> {
        let (op, payload) = split(frame)?;
        const IDENTITY: u8 = OP_IDENTIFY | REPLY_BIT;
        const STATUS: u8 = OP_STATUS | REPLY_BIT;
        const CALIBRATED: u8 = OP_CALIBRATE | REPLY_BIT;
        const MEASURED: u8 = OP_MEASURE_ALL | REPLY_BIT;
        const FETCHED: u8 = OP_FETCH | REPLY_BIT;
        const MEASURED_ONE: u8 = OP_MEASURE_ONE | REPLY_BIT;
        const ABORTED: u8 = OP_ABORT | REPLY_BIT;
        match op {
            IDENTITY => {
                let mut at = 0;
                let model = parse_string(payload, &mut at, "model")?;
                let serial = parse_string(payload, &mut at, "serial")?;
                let firmware = parse_string(payload, &mut at, "firmware")?;
                if at != payload.len() {
                    return Err(FrameError::malformed("IDENTITY has bytes after firmware"));
                }
                Ok(Response::Identity(Identity {
                    model,
                    serial,
                    firmware,
                }))
            }
            STATUS => {
                expect_len("STATUS", payload, 2)?;
                let state = match payload[0] {
                    0 => DeviceState::Ready,
                    1 => DeviceState::Busy,
                    2 => DeviceState::NeedsCalibration,
                    s => return Err(FrameError::malformed(format!("STATUS state {s} unknown"))),
                };
                Status::parsed(state, payload[1]).map(Response::Status)
            }
            CALIBRATED => expect_len("CALIBRATED", payload, 0).map(|_| Response::Calibrated),
            MEASURED => {
                expect_len("MEASURED", payload, 1)?;
                Ok(Response::Measured { count: payload[0] })
            }
            FETCHED => parse_reading(payload).map(Response::Fetched),
            MEASURED_ONE => parse_reading(payload).map(Response::MeasuredOne),
            ABORTED => expect_len("ABORTED", payload, 0).map(|_| Response::Aborted),
            OP_ERROR => {
                expect_len("ERROR", payload, 3)?;
                let request = kind_of(payload[0]).ok_or_else(|| {
                    FrameError::malformed(format!("ERROR names request 0x{:02X}", payload[0]))
                })?;
                let code = error_code(payload[1]).ok_or_else(|| {
                    FrameError::malformed(format!("ERROR code 0x{:02X} unknown", payload[1]))
                })?;
                let geometry = match payload[2] {
                    0 => None,
                    c => Some(geometry_from(c)?),
                };
                Ok(Response::Error {
                    request,
                    code,
                    geometry,
                })
            }
            other => Err(FrameError::UnknownOpcode {
                what: format!("0x{other:02X}"),
            }),
        }
    }

    fn encode_request(request: &Request) -> Result<Vec<u8>, EncodeError> {
        let op = opcode_of(request.kind());
        Ok(match request.geometry() {
            Some(g) => frame(op, &[code_for(g)?]),
            None => frame(op, &[]),
        })
    }

    fn encode_response(response: &Response) -> Result<Vec<u8>, EncodeError> {
        let reply = |kind: RequestKind| opcode_of(kind) | REPLY_BIT;
        Ok(match response {
            Response::Identity(id) => {
                let mut p = Vec::new();
                encode_string(&mut p, "model", &id.model)?;
                encode_string(&mut p, "serial", &id.serial)?;
                encode_string(&mut p, "firmware", &id.firmware)?;
                frame(reply(RequestKind::Identify), &p)
            }
            Response::Status(s) => {
                s.check_encodable(Instrument::MaT12)?;
                frame(
                    reply(RequestKind::Status),
                    &[state_byte(s.state), s.battery_percent],
                )
            }
            Response::Calibrated => frame(reply(RequestKind::Calibrate), &[]),
            Response::Measured { count } => frame(reply(RequestKind::MeasureAll), &[*count]),
            Response::Fetched(r) => frame(reply(RequestKind::Fetch), &reading_payload(r)?),
            Response::MeasuredOne(r) => frame(reply(RequestKind::MeasureOne), &reading_payload(r)?),
            Response::Aborted => frame(reply(RequestKind::Abort), &[]),
            Response::Error {
                request,
                code,
                geometry,
            } => {
                let g = match geometry {
                    Some(g) => code_for(g)?,
                    None => 0,
                };
                frame(OP_ERROR, &[opcode_of(*request), error_byte(*code), g])
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bytes::BytesMut;
    use proptest::prelude::*;

    use crate::protocol::golden;
    use crate::test_support::{
        arbitrary_bytes_yield_no_reading, assert_every_bit_flip_is_caught, assert_golden_requests,
        decodes_once_in_any_chunking, drain,
    };
    use crate::transport::PACKET_SIZE;

    /// The ramp used by PROTOCOL.md's golden READING: 0.25 + i/64, exact in binary64.
    fn golden_ramp() -> [f64; BANDS] {
        std::array::from_fn(|i| 0.25 + i as f64 / 64.0)
    }

    fn identity() -> Identity {
        Identity {
            model: "MA-T12".into(),
            serial: "SN-000123".into(),
            firmware: "FW 2.1.04".into(),
        }
    }

    // Golden frames come verbatim from PROTOCOL.md (its CRCs were computed with an independent
    // bit-by-bit CRC-16/CCITT-FALSE, not with this code).
    #[test]
    fn golden_requests_encode_and_parse() {
        assert_golden_requests::<Mat12Codec>(&[
            (Request::Identify, "mat12 IDENTIFY"),
            (Request::Status, "mat12 STATUS"),
            (Request::Calibrate, "mat12 CALIBRATE"),
            (Request::MeasureAll, "mat12 MEASURE-ALL"),
            (
                Request::Fetch {
                    geometry: "15as-45",
                },
                "mat12 FETCH 15as-45",
            ),
            (
                Request::MeasureOne {
                    geometry: "45as110",
                },
                "mat12 MEASURE-ONE 45as110",
            ),
            (Request::Abort, "mat12 ABORT"),
        ]);
    }

    #[test]
    fn golden_replies_encode_and_parse() {
        let reading = Reading {
            geometry: "15as-45",
            value: ReadingValue::Reflectance(golden_ramp()),
        };
        let cases = [
            (Response::Identity(identity()), "mat12 IDENTITY"),
            (
                Response::Status(Status {
                    state: DeviceState::Ready,
                    battery_percent: 87,
                }),
                "mat12 STATUS ready 87%",
            ),
            (Response::Calibrated, "mat12 CALIBRATED"),
            (Response::Measured { count: 12 }, "mat12 MEASURED 12"),
            (Response::Fetched(reading), "mat12 READING 15as-45"),
            (Response::Aborted, "mat12 ABORTED"),
            (
                Response::Error {
                    request: RequestKind::MeasureAll,
                    code: ErrorCode::NotCalibrated,
                    geometry: None,
                },
                "mat12 ERROR MEASURE-ALL NOT-CALIBRATED",
            ),
        ];
        for (resp, label) in cases {
            let bytes = golden(label);
            assert_eq!(
                Mat12Codec::encode_response(&resp).unwrap(),
                bytes,
                "{label}"
            );
            assert_eq!(Mat12Codec::parse_response(&bytes), Ok(resp), "{label}");
        }
    }

    #[test]
    fn golden_reading_is_exact_and_four_packets_long() {
        let bytes = golden("mat12 READING 15as-45");
        assert_eq!(bytes.len(), 4 * PACKET_SIZE);
        let Ok(Response::Fetched(back)) = Mat12Codec::parse_response(&bytes) else {
            panic!("golden reading did not parse")
        };
        let ReadingValue::Reflectance(v) = back.value else {
            panic!("not a spectrum")
        };
        for (i, x) in v.iter().enumerate() {
            assert_eq!(x.to_bits(), (0.25 + i as f64 / 64.0).to_bits(), "band {i}");
        }
    }

    #[test]
    fn partial_frames_wait_and_garbage_is_skipped() {
        let bytes = golden("mat12 STATUS ready 87%");
        for cut in 0..bytes.len() {
            assert_eq!(check(&bytes[..cut]), Check::Incomplete, "cut at {cut}");
        }
        let mut buf = BytesMut::from(&b"\x00\xffxyM"[..]);
        buf.extend_from_slice(&bytes);
        // `M` followed by `M` cannot start a frame, so the garbage is `00 FF x y M`.
        assert_eq!(
            Mat12Codec::decode_response(&mut buf),
            Err(FrameError::Garbage { skipped: 5 })
        );
        assert!(matches!(
            Mat12Codec::decode_response(&mut buf),
            Ok(Some(Response::Status(_)))
        ));
    }

    #[test]
    fn parsing_without_the_check_step_still_verifies_the_checksum() {
        let mut bad = golden("mat12 READING 15as-45");
        bad[100] ^= 0x10;
        assert!(matches!(
            Mat12Codec::parse_response(&bad),
            Err(FrameError::BadChecksum { .. })
        ));
        let mut long = golden("mat12 ABORTED");
        long.push(0);
        assert!(
            Mat12Codec::parse_response(&long).is_err(),
            "one frame exactly"
        );
    }

    #[test]
    fn bad_checksum_is_rejected_whole() {
        let mut bytes = golden("mat12 MEASURED 12");
        bytes[5] ^= 0x01;
        let mut buf = BytesMut::from(&bytes[..]);
        buf.extend_from_slice(&golden("mat12 MEASURED 12"));
        assert!(matches!(
            Mat12Codec::decode_response(&mut buf),
            Err(FrameError::BadChecksum { .. })
        ));
        // The good copy behind it decodes.
        assert_eq!(
            Mat12Codec::decode_response(&mut buf),
            Ok(Some(Response::Measured { count: 12 }))
        );
    }

    #[test]
    fn an_impossible_length_is_garbage_and_a_bad_checksum_a_damaged_frame() {
        // `MT` with a declared length over 1024 cannot be delimited: only the magic is dropped,
        // as garbage (no resend, PROTOCOL.md §4); the reply behind it decodes.
        let reply = golden("mat12 MEASURED 12");
        let mut buf = BytesMut::from(&[0x4D, 0x54, 0xFF, 0xFF, 0xFF][..]);
        buf.extend_from_slice(&reply);
        let e = Mat12Codec::decode_response(&mut buf).unwrap_err();
        assert_eq!(
            e,
            FrameError::BadLength {
                declared: 0xFFFF,
                max: MAX_PAYLOAD
            }
        );
        assert!(e.is_garbage());
        let e = Mat12Codec::decode_response(&mut buf).unwrap_err();
        assert_eq!(e, FrameError::Garbage { skipped: 3 });
        assert!(e.is_garbage());
        let (response, raw) = Mat12Codec::decode_response_frame(&mut buf)
            .unwrap()
            .unwrap();
        assert_eq!(response, Response::Measured { count: 12 });
        assert_eq!(raw[..], reply[..], "the frame's bytes as received");
        // A delimited frame that fails its checksum was a reply, damaged.
        let mut bad = reply.clone();
        bad[5] ^= 0x01;
        let e = Mat12Codec::decode_response(&mut BytesMut::from(&bad[..])).unwrap_err();
        assert!(matches!(e, FrameError::BadChecksum { .. }) && !e.is_garbage());
    }

    #[test]
    fn every_single_bit_flip_of_the_golden_reading_is_caught() {
        assert_every_bit_flip_is_caught::<Mat12Codec>(&golden("mat12 READING 15as-45"));
    }

    #[test]
    fn non_finite_reading_is_refused() {
        let mut values = golden_ramp();
        values[7] = f64::NAN;
        let r = Reading {
            geometry: "45as45",
            value: ReadingValue::Reflectance(values),
        };
        assert!(Mat12Codec::encode_response(&Response::Fetched(r)).is_err());
        let mut payload = vec![10u8];
        for v in values {
            payload.extend_from_slice(&v.to_le_bytes());
        }
        let bytes = frame(OP_FETCH | REPLY_BIT, &payload);
        assert_eq!(
            Mat12Codec::parse_response(&bytes),
            Err(FrameError::NonFinite {
                geometry: "45as45",
                band: 7
            })
        );
    }

    #[test]
    fn geometry_codes_cover_the_twelve_names() {
        for (i, name) in MAT12_GEOMETRIES.iter().enumerate() {
            assert_eq!(geometry_code(name), Some(i as u8 + 1));
            assert_eq!(geometry_name(i as u8 + 1), Some(*name));
        }
        assert_eq!(geometry_name(0), None);
        assert_eq!(geometry_name(13), None);
        assert_eq!(geometry_code("sra-20"), None);
    }

    /// Builds a frame with the independent bit-by-bit CRC, so the bytes pass the checksum
    /// and reach the payload parser.
    fn framed(op: u8, payload: &[u8]) -> Vec<u8> {
        let mut out = MAGIC.to_vec();
        out.push(op);
        out.extend_from_slice(&(payload.len() as u16).to_le_bytes());
        out.extend_from_slice(payload);
        let crc = crate::test_support::crc16_bitwise(&out);
        out.extend_from_slice(&crc.to_le_bytes());
        out
    }

    /// What a correct parser must make of a reading payload, read straight from PROTOCOL.md's
    /// layout (code 1-12, then 31 little-endian binary64, all finite): `Some` iff it is valid.
    fn reading_oracle(payload: &[u8]) -> Option<(u8, Vec<u64>)> {
        if payload.len() != 1 + 8 * 31 || !(1..=12).contains(&payload[0]) {
            return None;
        }
        let bits: Vec<u64> = payload[1..]
            .chunks(8)
            .map(|c| u64::from_le_bytes(c.try_into().unwrap()))
            .collect();
        bits.iter()
            .all(|b| f64::from_bits(*b).is_finite())
            .then_some((payload[0], bits))
    }

    /// The property every correctly checksummed frame must satisfy, in both directions: the
    /// parser never panics, consumes exactly the frame, and whatever it accepts re-encodes to
    /// the same bytes (the encoding is canonical); a reading is accepted exactly when the
    /// oracle says it is valid, with the values bit for bit.
    fn check_framed(op: u8, payload: &[u8]) -> Result<(), TestCaseError> {
        let bytes = framed(op, payload);
        let mut buf = BytesMut::from(&bytes[..]);
        let got = Mat12Codec::decode_response(&mut buf);
        prop_assert!(
            buf.is_empty(),
            "a checksummed frame must be consumed whole: {got:?}"
        );
        if op == OP_FETCH | REPLY_BIT || op == OP_MEASURE_ONE | REPLY_BIT {
            let oracle = reading_oracle(payload);
            match (&got, &oracle) {
                (Ok(Some(Response::Fetched(r) | Response::MeasuredOne(r))), Some((code, bits))) => {
                    prop_assert_eq!(geometry_code(r.geometry), Some(*code));
                    let ReadingValue::Reflectance(v) = r.value else {
                        return Err(TestCaseError::fail("MA-T12 reading is not a spectrum"));
                    };
                    let got_bits: Vec<u64> = v.iter().map(|x| x.to_bits()).collect();
                    prop_assert_eq!(&got_bits, bits);
                }
                (Err(_), None) => {}
                _ => prop_assert!(false, "op 0x{op:02X}: parser {got:?}, oracle {oracle:?}"),
            }
        }
        if let Ok(Some(resp)) = &got {
            prop_assert_eq!(Mat12Codec::encode_response(resp).unwrap(), bytes.clone());
        }
        let mut buf = BytesMut::from(&bytes[..]);
        let req = Mat12Codec::decode_request(&mut buf);
        prop_assert!(
            buf.is_empty(),
            "a checksummed frame must be consumed whole: {req:?}"
        );
        if let Ok(Some(req)) = &req {
            prop_assert_eq!(Mat12Codec::encode_request(req).unwrap(), bytes);
        }
        Ok(())
    }

    /// Every golden frame of PROTOCOL.md, as (opcode, payload).
    fn golden_frames() -> Vec<(u8, Vec<u8>)> {
        [
            "IDENTIFY",
            "STATUS",
            "CALIBRATE",
            "MEASURE-ALL",
            "FETCH 15as-45",
            "MEASURE-ONE 45as110",
            "ABORT",
            "IDENTITY",
            "STATUS ready 87%",
            "CALIBRATED",
            "MEASURED 12",
            "READING 15as-45",
            "ABORTED",
            "ERROR MEASURE-ALL NOT-CALIBRATED",
        ]
        .iter()
        .map(|label| {
            let g = golden(&format!("mat12 {label}"));
            (g[2], g[HEADER_LEN..g.len() - CRC_LEN].to_vec())
        })
        .collect()
    }

    /// One edit of a golden frame's opcode or payload; the CRC is recomputed afterwards.
    #[derive(Debug, Clone)]
    enum Edit {
        Set(usize, u8),
        Flip(usize, u8),
        Insert(usize, u8),
        Remove(usize),
        Truncate(usize),
        /// Overwrite 8 bytes with a binary64 (NaN, infinities, subnormals, -0.0 included).
        Float(usize, u64),
        Opcode(u8),
    }

    fn edit() -> impl Strategy<Value = Edit> {
        let special = prop_oneof![
            Just(f64::NAN.to_bits()),
            Just(f64::INFINITY.to_bits()),
            Just(f64::NEG_INFINITY.to_bits()),
            Just((-0.0f64).to_bits()),
            Just(1u64),
            Just(0x7FF0_0000_0000_0001u64),
            any::<u64>(),
        ];
        prop_oneof![
            (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Edit::Set(i, b)),
            (any::<usize>(), 0u8..8).prop_map(|(i, b)| Edit::Flip(i, b)),
            (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Edit::Insert(i, b)),
            any::<usize>().prop_map(Edit::Remove),
            any::<usize>().prop_map(Edit::Truncate),
            (any::<usize>(), special).prop_map(|(i, b)| Edit::Float(i, b)),
            prop_oneof![any::<u8>(), (1u8..=7).prop_map(|o| o | REPLY_BIT)].prop_map(Edit::Opcode),
        ]
    }

    fn apply_edits(mut op: u8, mut p: Vec<u8>, edits: &[Edit]) -> (u8, Vec<u8>) {
        for e in edits {
            let at = |i: usize, n: usize| if n == 0 { 0 } else { i % n };
            match *e {
                Edit::Set(i, b) if !p.is_empty() => {
                    let i = at(i, p.len());
                    p[i] = b;
                }
                Edit::Flip(i, b) if !p.is_empty() => {
                    let i = at(i, p.len());
                    p[i] ^= 1 << b;
                }
                Edit::Insert(i, b) => p.insert(at(i, p.len() + 1), b),
                Edit::Remove(i) if !p.is_empty() => {
                    p.remove(at(i, p.len()));
                }
                Edit::Truncate(i) => p.truncate(at(i, p.len() + 1)),
                // Aligned on a band when the payload is a reading's, so values are hit whole.
                Edit::Float(i, bits) if p.len() >= 9 => {
                    let start = 1 + 8 * at(i, (p.len() - 1) / 8);
                    p[start..start + 8].copy_from_slice(&bits.to_le_bytes());
                }
                Edit::Opcode(o) => op = o,
                _ => {}
            }
        }
        (op, p)
    }

    proptest! {
        #![proptest_config(crate::test_support::config())]

        #[test]
        fn random_payloads_past_the_crc_parse_exactly_or_are_refused(
            op in prop_oneof![
                3 => (1u8..=7).prop_map(|o| o | REPLY_BIT),
                1 => 1u8..=7,
                1 => Just(OP_ERROR),
                1 => any::<u8>(),
            ],
            payload in prop_oneof![
                proptest::collection::vec(any::<u8>(), 0..=8),
                proptest::collection::vec(any::<u8>(), 0..=MAX_PAYLOAD),
                // A reading's length with a plausible code: the value parser is reached.
                (0u8..=14, proptest::collection::vec(any::<u8>(), 8 * BANDS))
                    .prop_map(|(c, rest)| { let mut p = vec![c]; p.extend(rest); p }),
            ],
        ) {
            check_framed(op, &payload)?;
        }

        #[test]
        fn golden_frames_mutated_past_the_crc_parse_exactly_or_are_refused(
            which in 0usize..14,
            edits in proptest::collection::vec(edit(), 1..6),
        ) {
            let (op, payload) = golden_frames().swap_remove(which);
            let (op, payload) = apply_edits(op, payload, &edits);
            check_framed(op, &payload)?;
        }
    }

    #[test]
    fn every_golden_frame_passes_the_fuzz_property_unchanged() {
        // The property must accept what PROTOCOL.md says is valid, or it checks nothing.
        for (op, payload) in golden_frames() {
            assert_eq!(framed(op, &payload), frame(op, &payload));
            check_framed(op, &payload).unwrap();
        }
    }

    proptest! {
        #![proptest_config(crate::test_support::config())]

        #[test]
        fn arbitrary_bytes_never_panic_nor_yield_a_reading(
            bytes in proptest::collection::vec(any::<u8>(), 0..2048)
        ) {
            arbitrary_bytes_yield_no_reading::<Mat12Codec>(&bytes)?;
        }

        #[test]
        fn arbitrary_bytes_after_magic_never_yield_a_reading(
            op in prop_oneof![Just(0x85u8), Just(0x86u8), any::<u8>()],
            rest in proptest::collection::vec(any::<u8>(), 0..600)
        ) {
            // Aim the fuzz at the parser: a plausible header, then noise.
            let mut bytes = vec![b'M', b'T', op, READING_PAYLOAD as u8, 0];
            bytes.extend_from_slice(&rest);
            let mut buf = BytesMut::from(&bytes[..]);
            for r in drain::<Mat12Codec>(&mut buf) {
                prop_assert!(!matches!(r, Response::Fetched(_) | Response::MeasuredOne(_)));
            }
        }

        #[test]
        fn readings_round_trip_bit_for_bit_in_any_chunking(
            code in 1u8..=12,
            bits in proptest::array::uniform31(any::<u64>()),
            chunk in 1usize..=64,
        ) {
            let values = bits.map(|b| {
                let x = f64::from_bits(b);
                if x.is_finite() { x } else { 0.5 }
            });
            let r = Reading {
                geometry: geometry_name(code).unwrap(),
                value: ReadingValue::Reflectance(values),
            };
            let bytes = Mat12Codec::encode_response(&Response::Fetched(r)).unwrap();
            decodes_once_in_any_chunking::<Mat12Codec>(&bytes, chunk, &r)?;
        }
    }
}
