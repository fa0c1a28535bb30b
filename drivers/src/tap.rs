//! The recording tap: [`Tap<T>`] wraps any transport ([`UsbBulk`] or [`SerialStream`]) and
//! passes every byte through unchanged while a [`Recorder`] writes it, both directions, with a
//! timestamp, to a session file (`brdfd-session 1`, see [`crate::session`] and PROTOCOL.md §5).
//!
//! The recorder writes one line per protocol frame as the instrument's codec delimits it, not
//! per USB packet or serial read, so two recordings of the same conversation diff cleanly.
//! Bytes that never form a frame get their own line with a comment saying why. One recorder
//! can outlive a connection: give each new connection's tap a clone of it (from the driver's
//! transport factory) and the session continues in the same file, with a comment line at each
//! new connection.
//!
//! A failure to write the recording never disturbs the instrument traffic: the first error is
//! kept and returned by [`Recorder::finish`].

use std::fs::File;
use std::io::{self, BufWriter, Read, Write};
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::mat12::codec::Mat12Codec;
use crate::protocol::{Check, Codec, Instrument};
use crate::session::{Direction, Frame, Session};
use crate::sra::codec::SraCodec;
use crate::transport::{SerialStream, TransportError, UsbBulk};

struct State {
    out: Box<dyn Write + Send>,
    instrument: Instrument,
    start: Instant,
    /// Bytes seen in each direction that do not yet make a whole frame: [to device, from device].
    pending: [Vec<u8>; 2],
    connections: u32,
    /// The first write error, if any.
    error: Option<String>,
}

/// Writes a session file; cheap to clone (all clones write the same file).
#[derive(Clone)]
pub struct Recorder {
    state: Arc<Mutex<State>>,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder").finish_non_exhaustive()
    }
}

const fn slot(direction: Direction) -> usize {
    match direction {
        Direction::ToDevice => 0,
        Direction::FromDevice => 1,
    }
}

/// The codec's framing verdict and description for one direction.
fn check(instrument: Instrument, direction: Direction, buf: &[u8]) -> Check {
    match (instrument, direction) {
        (Instrument::MaT12, Direction::ToDevice) => Mat12Codec::check_request(buf),
        (Instrument::MaT12, Direction::FromDevice) => Mat12Codec::check_response(buf),
        (Instrument::Sra, Direction::ToDevice) => SraCodec::check_request(buf),
        (Instrument::Sra, Direction::FromDevice) => SraCodec::check_response(buf),
    }
}

fn describe_with<C: Codec>(direction: Direction, frame: &[u8]) -> String {
    let described = match direction {
        Direction::ToDevice => C::parse_request(frame).map(|r| r.to_string()),
        Direction::FromDevice => C::parse_response(frame).map(|r| r.to_string()),
    };
    described.unwrap_or_else(|e| format!("checksum ok but not understood: {e}"))
}

fn describe(instrument: Instrument, direction: Direction, frame: &[u8]) -> String {
    match instrument {
        Instrument::MaT12 => describe_with::<Mat12Codec>(direction, frame),
        Instrument::Sra => describe_with::<SraCodec>(direction, frame),
    }
}

impl State {
    fn t_ms(&self) -> u64 {
        self.start.elapsed().as_millis() as u64
    }

    fn write_line(&mut self, line: &str) {
        if self.error.is_some() {
            return;
        }
        if let Err(e) = writeln!(self.out, "{line}") {
            tracing::warn!(error = %e, "session recording failed; instrument traffic continues");
            self.error = Some(e.to_string());
        }
    }

    fn emit(&mut self, direction: Direction, bytes: Vec<u8>, comment: String) {
        let frame = Frame {
            t_ms: self.t_ms(),
            direction,
            bytes,
            comment: Some(comment),
        };
        self.write_line(&frame.to_string());
    }

    fn record(&mut self, direction: Direction, bytes: &[u8]) {
        let s = slot(direction);
        self.pending[s].extend_from_slice(bytes);
        loop {
            let verdict = check(self.instrument, direction, &self.pending[s]);
            let (len, comment) = match verdict {
                Check::Incomplete => break,
                Check::Frame(len) => (
                    len,
                    describe(self.instrument, direction, &self.pending[s][..len]),
                ),
                Check::Reject(len, why) => (
                    len.clamp(1, self.pending[s].len()),
                    format!("not a frame: {why}"),
                ),
            };
            let frame: Vec<u8> = self.pending[s].drain(..len).collect();
            self.emit(direction, frame, comment);
            if self.pending[s].is_empty() {
                break;
            }
        }
    }

    fn flush_pending(&mut self) {
        for direction in [Direction::ToDevice, Direction::FromDevice] {
            let rest = std::mem::take(&mut self.pending[slot(direction)]);
            if !rest.is_empty() {
                self.emit(direction, rest, "incomplete".into());
            }
        }
        if self.error.is_none()
            && let Err(e) = self.out.flush()
        {
            self.error = Some(e.to_string());
        }
    }
}

impl Drop for State {
    fn drop(&mut self) {
        self.flush_pending();
    }
}

impl Recorder {
    /// Start a session on `out`: writes the header lines (format, device, notes) at once.
    pub fn new(
        out: impl Write + Send + 'static,
        instrument: Instrument,
        notes: &[String],
    ) -> io::Result<Recorder> {
        let mut out: Box<dyn Write + Send> = Box::new(out);
        out.write_all(Session::header_text(instrument, notes, &[]).as_bytes())?;
        Ok(Recorder {
            state: Arc::new(Mutex::new(State {
                out,
                instrument,
                start: Instant::now(),
                pending: [Vec::new(), Vec::new()],
                connections: 0,
                error: None,
            })),
        })
    }

    /// Start a session in a new file at `path` (replacing any file there).
    pub fn create(
        path: impl AsRef<Path>,
        instrument: Instrument,
        notes: &[String],
    ) -> io::Result<Recorder> {
        let file = File::create(path.as_ref())?;
        Recorder::new(BufWriter::new(file), instrument, notes)
    }

    /// The instrument whose session is being recorded.
    pub fn instrument(&self) -> Instrument {
        self.lock().instrument
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        // A panic elsewhere while holding the lock leaves the state usable: it is only buffers.
        self.state
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Record bytes that went one way.
    pub fn record(&self, direction: Direction, bytes: &[u8]) {
        if !bytes.is_empty() {
            self.lock().record(direction, bytes);
        }
    }

    fn connection_opened(&self) {
        let mut s = self.lock();
        s.connections += 1;
        let line = format!("# connection {} opened at {} ms", s.connections, s.t_ms());
        s.write_line(&line);
    }

    /// Write out any incomplete frame, flush, and report the first write error, if any.
    pub fn finish(&self) -> io::Result<()> {
        let mut s = self.lock();
        s.flush_pending();
        match &s.error {
            Some(e) => Err(io::Error::other(format!("session recording failed: {e}"))),
            None => Ok(()),
        }
    }
}

/// A transport wrapped so that everything through it is recorded.
#[derive(Debug)]
pub struct Tap<T> {
    inner: T,
    recorder: Recorder,
}

impl<T> Tap<T> {
    /// Wrap a freshly opened connection. Writes a comment line marking the new connection.
    pub fn new(inner: T, recorder: Recorder) -> Tap<T> {
        recorder.connection_opened();
        Tap { inner, recorder }
    }

    /// The wrapped connection.
    pub fn get_ref(&self) -> &T {
        &self.inner
    }

    /// The wrapped connection, unwrapped.
    pub fn into_inner(self) -> T {
        self.inner
    }
}

impl<T: UsbBulk> UsbBulk for Tap<T> {
    fn write_bulk(&mut self, data: &[u8], timeout: Duration) -> Result<usize, TransportError> {
        let n = self.inner.write_bulk(data, timeout)?;
        self.recorder
            .record(Direction::ToDevice, &data[..n.min(data.len())]);
        Ok(n)
    }

    fn read_bulk(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, TransportError> {
        let n = self.inner.read_bulk(buf, timeout)?;
        self.recorder
            .record(Direction::FromDevice, &buf[..n.min(buf.len())]);
        Ok(n)
    }
}

impl<T: Read> Read for Tap<T> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.recorder
            .record(Direction::FromDevice, &buf[..n.min(buf.len())]);
        Ok(n)
    }
}

impl<T: Write> Write for Tap<T> {
    fn write(&mut self, data: &[u8]) -> io::Result<usize> {
        let n = self.inner.write(data)?;
        self.recorder
            .record(Direction::ToDevice, &data[..n.min(data.len())]);
        Ok(n)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

impl<T: SerialStream> SerialStream for Tap<T> {
    fn set_timeout(&mut self, timeout: Duration) -> Result<(), TransportError> {
        self.inner.set_timeout(timeout)
    }

    fn clear_input(&mut self) -> Result<(), TransportError> {
        self.inner.clear_input()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::{Request, Response, golden};
    use crate::test_support::Sink;
    use std::collections::VecDeque;

    /// USB fake that hands out queued bytes in packets of `packet` bytes.
    struct Usb {
        replies: VecDeque<u8>,
        packet: usize,
    }
    impl UsbBulk for Usb {
        fn write_bulk(&mut self, data: &[u8], _: Duration) -> Result<usize, TransportError> {
            Ok(data.len())
        }
        fn read_bulk(
            &mut self,
            buf: &mut [u8],
            timeout: Duration,
        ) -> Result<usize, TransportError> {
            let n = self.replies.len().min(buf.len()).min(self.packet);
            if n == 0 {
                return Err(TransportError::Timeout { timeout });
            }
            for b in buf.iter_mut().take(n) {
                *b = self.replies.pop_front().unwrap();
            }
            Ok(n)
        }
    }

    #[test]
    fn usb_packets_are_recorded_as_whole_frames_with_comments() {
        let sink = Sink::default();
        let rec = Recorder::new(sink.clone(), Instrument::MaT12, &["test".into()]).unwrap();
        let reading = golden("mat12 READING 15as-45");
        let mut replies: VecDeque<u8> = b"\x00\x01".iter().copied().collect();
        replies.extend(&reading);
        let mut tap = Tap::new(
            Usb {
                replies,
                packet: 64,
            },
            rec.clone(),
        );
        let fetch = golden("mat12 FETCH 15as-45");
        // The request in two writes: still one line.
        tap.write_bulk(&fetch[..3], Duration::ZERO).unwrap();
        tap.write_bulk(&fetch[3..], Duration::ZERO).unwrap();
        let mut buf = [0u8; 64];
        while tap.read_bulk(&mut buf, Duration::ZERO).is_ok() {}
        rec.finish().unwrap();

        let text = sink.text();
        assert!(
            text.starts_with("brdfd-session 1\ndevice ma_t12\nnote test\n"),
            "{text}"
        );
        assert!(text.contains("# connection 1 opened at"), "{text}");
        let session = Session::parse(&text).unwrap();
        assert_eq!(session.instrument, Instrument::MaT12);
        assert_eq!(session.frames.len(), 3, "{text}");
        let [req, junk, rep] = &session.frames[..] else {
            unreachable!()
        };
        assert_eq!((req.direction, &req.bytes), (Direction::ToDevice, &fetch));
        assert_eq!(req.comment.as_deref(), Some("FETCH 15as-45"));
        assert_eq!(junk.bytes, vec![0, 1]);
        assert!(
            junk.comment
                .as_deref()
                .unwrap()
                .starts_with("not a frame: 2 byte(s) of garbage")
        );
        assert_eq!(
            (rep.direction, &rep.bytes),
            (Direction::FromDevice, &reading)
        );
        assert!(
            rep.comment
                .as_deref()
                .unwrap()
                .starts_with("READING 15as-45 reflectance")
        );
        // The recorded bytes decode to what went over the wire.
        assert_eq!(
            Mat12Codec::parse_request(&req.bytes),
            Ok(Request::Fetch {
                geometry: "15as-45"
            })
        );
        assert!(matches!(
            Mat12Codec::parse_response(&rep.bytes),
            Ok(Response::Fetched(_))
        ));
    }

    /// Serial fake: reads come back a few bytes at a time.
    struct Serial {
        replies: VecDeque<u8>,
        written: Vec<u8>,
    }
    impl Read for Serial {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            let n = self.replies.len().min(buf.len()).min(3);
            if n == 0 {
                return Err(io::Error::new(io::ErrorKind::TimedOut, "timeout"));
            }
            for b in buf.iter_mut().take(n) {
                *b = self.replies.pop_front().unwrap();
            }
            Ok(n)
        }
    }
    impl Write for Serial {
        fn write(&mut self, b: &[u8]) -> io::Result<usize> {
            self.written.extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }
    impl SerialStream for Serial {
        fn set_timeout(&mut self, _: Duration) -> Result<(), TransportError> {
            Ok(())
        }
    }

    #[test]
    fn serial_reads_in_pieces_make_one_line_per_frame_and_a_cut_frame_is_marked() {
        let sink = Sink::default();
        let rec = Recorder::new(sink.clone(), Instrument::Sra, &[]).unwrap();
        let r20 = golden("sra READING sra-20");
        let r60 = golden("sra READING sra-60");
        let mut replies: VecDeque<u8> = r20.iter().chain(&r60).copied().collect();
        replies.extend(b"!RD,6");
        let mut tap = Tap::new(
            Serial {
                replies,
                written: Vec::new(),
            },
            rec.clone(),
        );
        tap.write_all(&golden("sra FETCH sra-20")).unwrap();
        let mut buf = [0u8; 16];
        while tap.read(&mut buf).is_ok() {}
        assert_eq!(
            tap.get_ref().written,
            golden("sra FETCH sra-20"),
            "passes bytes through"
        );
        drop(tap);
        drop(rec); // the last clone: leftovers are written as `incomplete`

        let session = Session::parse(&sink.text()).unwrap();
        let bytes: Vec<&[u8]> = session.frames.iter().map(|f| &f.bytes[..]).collect();
        assert_eq!(
            bytes,
            [&golden("sra FETCH sra-20")[..], &r20, &r60, b"!RD,6"]
        );
        assert_eq!(
            session.frames[1].comment.as_deref(),
            Some("READING sra-20 intensity 3.1")
        );
        assert_eq!(session.frames[3].comment.as_deref(), Some("incomplete"));
        assert!(session.frames.windows(2).all(|w| w[0].t_ms <= w[1].t_ms));
    }

    struct Broken;
    impl Write for Broken {
        fn write(&mut self, _: &[u8]) -> io::Result<usize> {
            Err(io::Error::other("disk full"))
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn a_failing_recording_does_not_disturb_the_traffic() {
        // The header goes out at creation, so let it through and fail afterwards.
        struct Later(u32);
        impl Write for Later {
            fn write(&mut self, b: &[u8]) -> io::Result<usize> {
                self.0 += 1;
                if self.0 > 1 {
                    Broken.write(b)
                } else {
                    Ok(b.len())
                }
            }
            fn flush(&mut self) -> io::Result<()> {
                Ok(())
            }
        }
        let rec = Recorder::new(Later(0), Instrument::MaT12, &[]).unwrap();
        let replies = golden("mat12 ABORTED").into_iter().collect();
        let mut tap = Tap::new(
            Usb {
                replies,
                packet: 64,
            },
            rec.clone(),
        );
        let mut buf = [0u8; 64];
        assert_eq!(tap.read_bulk(&mut buf, Duration::ZERO), Ok(7));
        let err = rec.finish().unwrap_err();
        assert!(err.to_string().contains("disk full"), "{err}");
    }
}
