//! The instrument's codec chosen at run time: the simulated instruments and the generator hold
//! an [`Instrument`] rather than a codec type parameter, and call the drivers' codecs through
//! these few functions. No framing is implemented here: every byte goes through
//! `drivers::mat12::codec` or `drivers::sra::codec`.

use drivers::Instrument;
use drivers::mat12::codec::Mat12Codec;
use drivers::protocol::{Check, Codec, EncodeError, Request, Response};
use drivers::sra::codec::SraCodec;

/// Framing verdict on bytes sent by the host (brdfd) to `instrument`.
pub(crate) fn check_request(instrument: Instrument, buf: &[u8]) -> Check {
    match instrument {
        Instrument::MaT12 => Mat12Codec::check_request(buf),
        Instrument::Sra => SraCodec::check_request(buf),
    }
}

/// The request in `frame` if it is exactly one whole, valid request frame.
pub(crate) fn parse_request(instrument: Instrument, frame: &[u8]) -> Option<Request> {
    if check_request(instrument, frame) != Check::Frame(frame.len()) {
        return None;
    }
    match instrument {
        Instrument::MaT12 => Mat12Codec::parse_request(frame).ok(),
        Instrument::Sra => SraCodec::parse_request(frame).ok(),
    }
}

/// The reply in `frame` if it is exactly one whole, valid reply frame.
pub(crate) fn parse_response(instrument: Instrument, frame: &[u8]) -> Option<Response> {
    let check = match instrument {
        Instrument::MaT12 => Mat12Codec::check_response(frame),
        Instrument::Sra => SraCodec::check_response(frame),
    };
    if check != Check::Frame(frame.len()) {
        return None;
    }
    match instrument {
        Instrument::MaT12 => Mat12Codec::parse_response(frame).ok(),
        Instrument::Sra => SraCodec::parse_response(frame).ok(),
    }
}

#[cfg(test)]
pub(crate) fn encode_request(
    instrument: Instrument,
    request: &Request,
) -> Result<Vec<u8>, EncodeError> {
    match instrument {
        Instrument::MaT12 => Mat12Codec::encode_request(request),
        Instrument::Sra => SraCodec::encode_request(request),
    }
}

pub(crate) fn encode_response(
    instrument: Instrument,
    response: &Response,
) -> Result<Vec<u8>, EncodeError> {
    match instrument {
        Instrument::MaT12 => Mat12Codec::encode_response(response),
        Instrument::Sra => SraCodec::encode_response(response),
    }
}

/// What a frame says, for reports and session-file comments; the same text the recording tap
/// writes (the `Display` of the decoded request or reply).
pub(crate) fn describe_request(instrument: Instrument, frame: &[u8]) -> String {
    match parse_request(instrument, frame) {
        Some(r) => r.to_string(),
        None => format!("{} bytes that are not a request", frame.len()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_round_trip_through_the_drivers_codecs() {
        for instrument in [Instrument::MaT12, Instrument::Sra] {
            let g = instrument.geometries()[1];
            for request in [
                Request::Identify,
                Request::MeasureAll,
                Request::Fetch { geometry: g },
            ] {
                let bytes = encode_request(instrument, &request).unwrap();
                assert_eq!(parse_request(instrument, &bytes), Some(request));
                // One byte short is not a whole frame, so not a request.
                assert_eq!(parse_request(instrument, &bytes[..bytes.len() - 1]), None);
            }
        }
        // The PROTOCOL.md golden IDENTIFY frames.
        assert_eq!(
            encode_request(Instrument::MaT12, &Request::Identify).unwrap(),
            [0x4D, 0x54, 0x01, 0x00, 0x00, 0xE4, 0xA9]
        );
        assert_eq!(
            encode_request(Instrument::Sra, &Request::Identify).unwrap(),
            b"$ID*298E\r\n"
        );
    }
}
