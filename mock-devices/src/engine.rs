//! The replay engine, without I/O: it is fed the bytes brdfd sends and answers with what the
//! device sends back (bytes, each after a delay, or "drop the link"). The USB and pty
//! transports wrap it; everything about matching, timing and faults is decided here.
//!
//! Matching a request to the recording ([`Mode`]):
//! - **Strict**: the request must be byte-identical to the next recorded request. A request
//!   identical to the previous one is a resend (PROTOCOL.md §4: every request is idempotent and
//!   a retry is a byte-identical resend), answered by replaying the previous exchange again.
//!   Anything else is a mismatch: it is recorded in the [`ReplayReport`] and answered with the
//!   protocol's ERROR UNKNOWN-REQUEST, so the driver fails the command cleanly.
//! - **Lenient**: the request is matched by what it asks (kind and geometry), at the next
//!   recorded exchange that asks the same, searching forward and then from the start.
//!
//! In both modes IDENTIFY — the introduction the driver sends on every new connection — is
//! answered wherever it comes, from the recorded IDENTIFY nearest before the replay position,
//! without moving the position; and a recorded IDENTIFY that the driver does not send because its
//! connection is already open (sessions replayed back to back) is skipped.
//!
//! ABORT, which the driver sends whenever the operator stops a measurement, is answered the same
//! way: wherever it comes, from the recorded ABORT exchange nearest the replay position (each
//! generated session records one after its last FETCH), without moving the position. Like the
//! instrument, which stops measuring, the simulated one first drops every reply it still had
//! scheduled (the aborted MEASURE-ALL's answer never comes). A recorded ABORT the driver does not
//! send (a scan that was not aborted) is skipped, and is not counted as remaining. A recording
//! with no ABORT exchange answers it with ERROR UNKNOWN-REQUEST, as any request nothing recorded
//! answers.
//!
//! Timing ([`Timing`]): a device frame is sent after the recorded delay since the request (or
//! since the previous device frame), scaled by the speed factor or left out. Fault delays
//! (`slow`) are never scaled: they exist to exceed the driver's timeouts.
//!
//! Faults (PROTOCOL.md §5) are keyed by frame number: `disconnect after=K` fires once, when
//! frame K has gone by; `no-reply`, `corrupt` count how many times the device frame was due or
//! sent; `garbage` goes out once, before the first sending of its frame; `slow` delays every
//! sending. [`ReplayOptions::unplug_after`] is a code-only fault: the link drops and the
//! instrument never comes back.

use std::collections::{HashMap, HashSet};
use std::fmt;
use std::time::Duration;

use drivers::Instrument;
use drivers::protocol::{Check, ErrorCode, Request, Response};
use drivers::session::{Fault, to_hex};
use tracing::{debug, warn};

use crate::MockError;
use crate::script::Script;
use crate::wire;

/// How requests are matched against the recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Mode {
    /// Byte for byte, in recorded order.
    #[default]
    Strict,
    /// By request kind and geometry, wherever it was recorded.
    Lenient,
}

/// How fast device frames are sent.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Timing {
    /// The recorded delays.
    #[default]
    Recorded,
    /// The recorded delays divided by this factor (2.0 = twice as fast). Must be > 0.
    Speed(f64),
    /// No delays at all (accelerated replay).
    Immediate,
}

/// How a simulated instrument replays its script.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ReplayOptions {
    /// How requests are matched against the script.
    pub mode: Mode,
    /// How the recorded delays are replayed.
    pub timing: Timing,
    /// Code-only fault: once this frame has gone by, the link drops and the instrument is gone
    /// for good (every later connection attempt fails as if it were unplugged).
    pub unplug_after: Option<usize>,
}

impl ReplayOptions {
    /// Strict matching at recorded timing: a faithful replay.
    pub fn strict() -> ReplayOptions {
        ReplayOptions::default()
    }

    /// Lenient matching at recorded timing.
    pub fn lenient() -> ReplayOptions {
        ReplayOptions {
            mode: Mode::Lenient,
            ..ReplayOptions::default()
        }
    }

    /// The same, with no delays.
    pub fn accelerated(self) -> ReplayOptions {
        ReplayOptions {
            timing: Timing::Immediate,
            ..self
        }
    }

    /// The same, `factor` times faster than recorded.
    pub fn speed(self, factor: f64) -> ReplayOptions {
        ReplayOptions {
            timing: Timing::Speed(factor),
            ..self
        }
    }

    pub(crate) fn check(&self) -> Result<(), MockError> {
        match self.timing {
            Timing::Speed(f) if !(f.is_finite() && f > 0.0) => {
                Err(MockError::BadSpeed { speed: f })
            }
            _ => Ok(()),
        }
    }

    fn scale(&self, ms: u64) -> Duration {
        match self.timing {
            Timing::Recorded => Duration::from_millis(ms),
            Timing::Speed(f) => Duration::from_secs_f64(ms as f64 / 1000.0 / f),
            Timing::Immediate => Duration::ZERO,
        }
    }
}

/// A request that did not match the recording.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Mismatch {
    /// Frame number of the recorded request that was expected, if any was left.
    pub expected_frame: Option<usize>,
    /// What the recording expected (decoded, then hex), or "the end of the recording".
    pub expected: String,
    /// What arrived (decoded, then hex).
    pub received: String,
}

impl fmt::Display for Mismatch {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.expected_frame {
            Some(k) => write!(
                f,
                "expected frame {k}, {}; received {}",
                self.expected, self.received
            ),
            None => write!(f, "expected {}; received {}", self.expected, self.received),
        }
    }
}

/// What happened during a replay, for tests and for the daemon's logs.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ReplayReport {
    /// Connections opened (the first one and every reconnection).
    pub connections: u32,
    /// Whole request frames received.
    pub requests: u32,
    /// Exchanges replayed, resends and IDENTIFYs included.
    pub served: u32,
    /// Requests that did not match the recording (strict mode), or that nothing recorded
    /// answers (lenient mode). Each was answered with ERROR UNKNOWN-REQUEST.
    pub mismatches: Vec<Mismatch>,
    /// Bytes from brdfd that never formed a request (dropped, as the device would).
    pub dropped: Vec<String>,
    /// Faults as they fired, in order, e.g. "corrupt frame 5 (1 of 2)".
    pub faults_fired: Vec<String>,
    /// Recorded exchanges (with a request) not replayed yet.
    pub remaining: usize,
}

/// What the device does next.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Out {
    /// Send these bytes, `delay` after the previous output (or after now).
    Send { delay: Duration, bytes: Vec<u8> },
    /// Drop the link `delay` after the previous output. `unplug`: never come back.
    Drop { delay: Duration, unplug: bool },
    /// Forget every reply scheduled but not yet sent (the instrument was told to ABORT); what
    /// follows is timed from now.
    Cancel,
}

/// What [`crate::SimMat12::cue`] / [`crate::SimSra::cue`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cue {
    /// The next measurement is answered from this session.
    Cued {
        /// The session's number in the script (0-based).
        session: usize,
    },
    /// The script (of this many sessions) has no recording of the object: the next recording
    /// answers, as without a cue.
    NoRecording {
        /// How many sessions the script holds.
        sessions: usize,
    },
    /// Strict replay follows the recording's order: no jump.
    Strict,
}

/// The replay state of one simulated instrument; it survives reconnections (the instrument
/// keeps its buffer when the cable is re-plugged).
#[derive(Debug)]
pub(crate) struct Engine {
    script: Script,
    options: ReplayOptions,
    /// Next recorded exchange to replay.
    cursor: usize,
    /// Last exchange replayed (answers a resend).
    last: Option<usize>,
    /// The current connection has been introduced with IDENTIFY.
    introduced: bool,
    /// Bytes from brdfd not yet framed.
    inbox: Vec<u8>,
    due: HashMap<usize, u32>,
    sent: HashMap<usize, u32>,
    garbage_sent: HashSet<usize>,
    disconnects_fired: HashSet<usize>,
    unplug_fired: bool,
    prelude_sent: bool,
    report: ReplayReport,
}

impl Engine {
    pub(crate) fn new(script: Script, options: ReplayOptions) -> Result<Engine, MockError> {
        options.check()?;
        if let Some(k) = options.unplug_after
            && k >= script.frame_count()
        {
            return Err(MockError::BadFault {
                fault: format!("unplug after={k}"),
                detail: format!(
                    "frame {k} does not exist (the script has {})",
                    script.frame_count()
                ),
            });
        }
        let mut engine = Engine {
            script,
            options,
            cursor: 0,
            last: None,
            introduced: false,
            inbox: Vec::new(),
            due: HashMap::new(),
            sent: HashMap::new(),
            garbage_sent: HashSet::new(),
            disconnects_fired: HashSet::new(),
            unplug_fired: false,
            prelude_sent: false,
            report: ReplayReport::default(),
        };
        engine.update_remaining();
        Ok(engine)
    }

    pub(crate) fn instrument(&self) -> Instrument {
        self.script.instrument()
    }

    pub(crate) fn script(&self) -> &Script {
        &self.script
    }

    pub(crate) fn report(&self) -> ReplayReport {
        self.report.clone()
    }

    /// Lenient replay only: moves the replay position to the start of the first session of
    /// this sample (`None`: of the reference tile), so that the next measurement is answered
    /// from it (the operator asked for that sample). Strict replay never jumps.
    pub(crate) fn cue_object(&mut self, sample: Option<&str>) -> Cue {
        if self.options.mode != Mode::Lenient {
            return Cue::Strict;
        }
        let Some(session) = self.script.session_of(sample) else {
            return Cue::NoRecording {
                sessions: self.script.session_count(),
            };
        };
        let Some(i) = self
            .script
            .exchanges()
            .iter()
            .position(|e| e.session == session && e.request.is_some())
        else {
            return Cue::NoRecording {
                sessions: self.script.session_count(),
            };
        };
        self.cursor = i;
        self.last = None;
        self.update_remaining();
        Cue::Cued { session }
    }

    /// The session the next measurement (MEASURE-ALL) is answered from: the first recorded at or
    /// after the replay position, else the first from the start (lenient replay wraps round).
    pub(crate) fn answering_session(&self) -> Option<usize> {
        let ex = self.script.exchanges();
        let at = self.cursor.min(ex.len());
        let is_measure = |i: &usize| ex[*i].parsed == Some(Request::MeasureAll);
        (at..ex.len())
            .find(is_measure)
            .or_else(|| (0..at).find(is_measure))
            .map(|i| ex[i].session)
    }

    /// The instrument was unplugged for good by [`ReplayOptions::unplug_after`].
    pub(crate) fn unplugged(&self) -> bool {
        self.unplug_fired
    }

    fn update_remaining(&mut self) {
        self.report.remaining = self.script.exchanges()
            [self.cursor.min(self.script.exchanges().len())..]
            .iter()
            .filter(|e| e.request.is_some() && e.parsed != Some(Request::Abort))
            .count();
    }

    /// A new connection is open: it must be introduced again; device frames recorded before any
    /// request go out on the first connection.
    pub(crate) fn on_connect(&mut self) -> Vec<Out> {
        self.report.connections += 1;
        self.introduced = false;
        self.inbox.clear();
        let mut out = Vec::new();
        if !self.prelude_sent {
            self.prelude_sent = true;
            if let Some(first) = self.script.exchanges().first()
                && first.request.is_none()
            {
                self.serve(0, &mut out);
                self.cursor = 1;
                self.update_remaining();
            }
        }
        out
    }

    /// Bytes arrived from brdfd.
    pub(crate) fn on_bytes(&mut self, bytes: &[u8]) -> Vec<Out> {
        self.inbox.extend_from_slice(bytes);
        let mut out = Vec::new();
        loop {
            match wire::check_request(self.instrument(), &self.inbox) {
                Check::Incomplete => break,
                Check::Reject(len, why) => {
                    let len = len.clamp(1, self.inbox.len());
                    let dropped: Vec<u8> = self.inbox.drain(..len).collect();
                    debug!(%why, "simulated instrument dropped bytes that are not a request");
                    self.report
                        .dropped
                        .push(format!("{} ({why})", to_hex(&dropped)));
                }
                Check::Frame(len) => {
                    let frame: Vec<u8> = self.inbox.drain(..len).collect();
                    self.on_request(&frame, &mut out);
                }
            }
        }
        out
    }

    fn on_request(&mut self, frame: &[u8], out: &mut Vec<Out>) {
        self.report.requests += 1;
        let parsed = wire::parse_request(self.instrument(), frame);
        let n = self.script.exchanges().len();
        if parsed == Some(Request::Identify) {
            self.introduced = true;
            if self.cursor < n
                && self.script.exchanges()[self.cursor].request_bytes() == Some(frame)
            {
                self.advance(self.cursor, out);
            } else if let Some(i) = self.identify_exchange() {
                self.serve(i, out);
            } else {
                self.refuse(frame, parsed, out);
            }
            return;
        }
        if parsed == Some(Request::Abort) {
            match self.abort_exchange() {
                Some(i) => {
                    out.push(Out::Cancel);
                    self.serve(i, out);
                }
                None => self.refuse(frame, parsed, out),
            }
            self.update_remaining();
            return;
        }
        // Recorded introductions the driver does not repeat on an open connection, and
        // recorded ABORTs of measurements that were not aborted this time.
        while self.cursor < n
            && matches!(
                self.script.exchanges()[self.cursor].parsed,
                Some(Request::Identify | Request::Abort)
            )
        {
            self.cursor += 1;
        }
        let matches = |i: usize| -> bool {
            let e = &self.script.exchanges()[i];
            match self.options.mode {
                Mode::Strict => e.request_bytes() == Some(frame),
                Mode::Lenient => parsed.is_some() && e.parsed == parsed,
            }
        };
        if self.cursor < n && matches(self.cursor) {
            self.advance(self.cursor, out);
        } else if let Some(l) = self.last.filter(|&l| matches(l)) {
            debug!(
                exchange = l,
                "resend: replaying the previous exchange again"
            );
            self.serve(l, out);
        } else if self.options.mode == Mode::Lenient
            && let Some(i) = (self.cursor..n)
                .chain(0..self.cursor.min(n))
                .find(|&i| matches(i))
        {
            self.advance(i, out);
        } else {
            self.refuse(frame, parsed, out);
        }
        self.update_remaining();
    }

    /// The recorded IDENTIFY nearest before the replay position, else the first after it.
    fn identify_exchange(&self) -> Option<usize> {
        let ex = self.script.exchanges();
        let is_id = |i: &usize| ex[*i].parsed == Some(Request::Identify);
        (0..self.cursor.min(ex.len()))
            .rev()
            .find(is_id)
            .or_else(|| (self.cursor..ex.len()).find(is_id))
    }

    /// The recorded ABORT first at or after the replay position, else the last before it.
    fn abort_exchange(&self) -> Option<usize> {
        let ex = self.script.exchanges();
        let is_abort = |i: &usize| ex[*i].parsed == Some(Request::Abort);
        (self.cursor.min(ex.len())..ex.len())
            .find(is_abort)
            .or_else(|| (0..self.cursor.min(ex.len())).rev().find(is_abort))
    }

    fn advance(&mut self, i: usize, out: &mut Vec<Out>) {
        self.serve(i, out);
        self.last = Some(i);
        self.cursor = i + 1;
        self.update_remaining();
    }

    fn refuse(&mut self, frame: &[u8], parsed: Option<Request>, out: &mut Vec<Out>) {
        let instrument = self.instrument();
        let describe = |bytes: &[u8]| {
            format!(
                "{} ({})",
                wire::describe_request(instrument, bytes),
                to_hex(bytes)
            )
        };
        let expected = self.script.exchanges()[self.cursor.min(self.script.exchanges().len())..]
            .iter()
            .find_map(|e| e.request.as_ref());
        let mismatch = Mismatch {
            expected_frame: expected.map(|r| r.index),
            expected: expected.map_or_else(
                || "the end of the recording".to_string(),
                |r| describe(&r.bytes),
            ),
            received: describe(frame),
        };
        warn!(%mismatch, "simulated {instrument}: request does not match the recording");
        self.report.mismatches.push(mismatch);
        // A request the codec cannot even parse has no kind to refuse; like a real device,
        // say nothing (the driver times out).
        if let Some(request) = parsed {
            let error = Response::Error {
                request: request.kind(),
                code: ErrorCode::UnknownRequest,
                geometry: request.geometry(),
            };
            match wire::encode_response(instrument, &error) {
                Ok(bytes) => out.push(Out::Send {
                    delay: Duration::ZERO,
                    bytes,
                }),
                Err(e) => warn!(error = %e, "cannot encode the error reply"),
            }
        }
    }

    /// Drop the link if a disconnect (or unplug) fault is due once frame `k` has gone by.
    fn drop_after(&mut self, k: usize, out: &mut Vec<Out>) -> bool {
        if self.options.unplug_after == Some(k) && !self.unplug_fired {
            self.unplug_fired = true;
            self.report
                .faults_fired
                .push(format!("unplug after frame {k}"));
            out.push(Out::Drop {
                delay: Duration::ZERO,
                unplug: true,
            });
            return true;
        }
        let fire = self.script.faults().iter().enumerate().find_map(|(n, f)| {
            matches!(f, Fault::Disconnect { after } if *after == k)
                .then_some(n)
                .filter(|n| !self.disconnects_fired.contains(n))
        });
        if let Some(n) = fire {
            self.disconnects_fired.insert(n);
            self.report
                .faults_fired
                .push(format!("disconnect after frame {k}"));
            out.push(Out::Drop {
                delay: Duration::ZERO,
                unplug: false,
            });
            return true;
        }
        false
    }

    /// Replay exchange `i`'s device frames, with faults.
    fn serve(&mut self, i: usize, out: &mut Vec<Out>) {
        self.report.served += 1;
        let exchange = self.script.exchanges()[i].clone();
        if let Some(req) = &exchange.request
            && self.drop_after(req.index, out)
        {
            return;
        }
        let mut previous_t = exchange
            .request
            .as_ref()
            .map_or(exchange.replies.first().map_or(0, |r| r.t_ms), |r| r.t_ms);
        // Delay owed by frames that were not sent (a no-reply fault), so later frames keep
        // their recorded time.
        let mut carried = Duration::ZERO;
        for reply in &exchange.replies {
            let k = reply.index;
            let slow = self.slow(k);
            if !slow.is_zero() {
                self.report
                    .faults_fired
                    .push(format!("slow frame {k} (+{} ms)", slow.as_millis()));
            }
            let mut delay =
                carried + self.options.scale(reply.t_ms.saturating_sub(previous_t)) + slow;
            carried = Duration::ZERO;
            previous_t = reply.t_ms;
            let due = {
                let d = self.due.entry(k).or_insert(0);
                *d += 1;
                *d
            };
            let suppressed = self.script.faults().iter().any(
                |f| matches!(f, Fault::NoReply { frame, times } if *frame == k && due <= *times),
            );
            if suppressed {
                self.report
                    .faults_fired
                    .push(format!("no-reply frame {k} (time {due})"));
                carried = delay;
                continue;
            }
            if !self.garbage_sent.contains(&k) {
                let garbage: Vec<u8> = self
                    .script
                    .faults()
                    .iter()
                    .filter_map(|f| match f {
                        Fault::Garbage { frame, bytes } if *frame == k => Some(bytes.clone()),
                        _ => None,
                    })
                    .flatten()
                    .collect();
                if !garbage.is_empty() {
                    self.garbage_sent.insert(k);
                    self.report.faults_fired.push(format!(
                        "garbage before frame {k} ({} bytes)",
                        garbage.len()
                    ));
                    out.push(Out::Send {
                        delay,
                        bytes: garbage,
                    });
                    delay = Duration::ZERO;
                }
            }
            let sent = {
                let s = self.sent.entry(k).or_insert(0);
                *s += 1;
                *s
            };
            let mut bytes = reply.bytes.clone();
            for f in self.script.faults() {
                if let Fault::Corrupt {
                    frame,
                    offset,
                    xor,
                    times,
                } = f
                    && *frame == k
                    && sent <= *times
                    && let Some(b) = bytes.get_mut(*offset)
                {
                    *b ^= xor;
                    self.report.faults_fired.push(format!(
                        "corrupt frame {k} byte {offset} ({sent} of {times})"
                    ));
                }
            }
            out.push(Out::Send { delay, bytes });
            if self.drop_after(k, out) {
                return;
            }
        }
    }

    /// Extra delay of device frame `k` from `slow` faults.
    fn slow(&self, k: usize) -> Duration {
        self.script
            .faults()
            .iter()
            .filter_map(|f| match f {
                Fault::Slow { delay_ms, frame } if frame.is_none_or(|x| x == k) => {
                    Some(Duration::from_millis(*delay_ms))
                }
                _ => None,
            })
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use drivers::protocol::Request;

    #[test]
    fn a_cue_moves_lenient_replay_to_the_sample_asked_for() {
        let playlist = crate::recordings::playlist(Instrument::MaT12).unwrap();
        let sky = playlist.session_of(Some("t.sky BLUE")).unwrap();
        assert_eq!(
            playlist.object(sky),
            &crate::script::ScriptObject::Sample("T.Sky blue".into())
        );
        let mut e = Engine::new(playlist.clone(), ReplayOptions::lenient()).unwrap();
        assert_eq!(e.cue_object(Some("T.Sky blue")), Cue::Cued { session: sky });
        let first = &e.script.exchanges()[e.cursor];
        assert_eq!(first.session, sky);
        assert!(first.request.is_some());
        assert_eq!(e.cue_object(None), Cue::Cued { session: 0 });
        assert_eq!(e.cursor, 0);
        assert_eq!(
            e.cue_object(Some("T.Unknown")),
            Cue::NoRecording { sessions: 9 }
        );
        assert_eq!(e.cursor, 0, "no recording: the position does not move");
        let mut strict = Engine::new(playlist, ReplayOptions::strict()).unwrap();
        assert_eq!(strict.cue_object(Some("T.Sky blue")), Cue::Strict);
        assert_eq!(strict.cursor, 0);
    }

    #[test]
    fn abort_is_answered_wherever_it_comes_and_skipped_when_not_sent() {
        let playlist = crate::recordings::playlist(Instrument::Sra).unwrap();
        let wire = |r: Request| wire::encode_request(Instrument::Sra, &r).unwrap();
        let aborted = wire::encode_response(Instrument::Sra, &Response::Aborted).unwrap();
        for options in [ReplayOptions::lenient(), ReplayOptions::strict()] {
            let mut e = Engine::new(playlist.clone(), options.accelerated()).unwrap();
            e.on_connect();
            e.on_bytes(&wire(Request::Identify));
            // MEASURE-ALL's answer is scheduled; ABORT drops it and answers ABORTED.
            let measured = e.on_bytes(&wire(Request::MeasureAll));
            assert_eq!(sends(&measured).len(), 1);
            let out = e.on_bytes(&wire(Request::Abort));
            assert_eq!(out.first(), Some(&Out::Cancel), "{out:?}");
            assert_eq!(sends(&out), vec![(Duration::ZERO, aborted.clone())]);
            assert!(
                e.report().mismatches.is_empty(),
                "{:?}",
                e.report().mismatches
            );
        }
        // A scan that is not aborted replays to the end: its recorded ABORT is skipped and not
        // counted as remaining, and strict replay goes on into the next session.
        let mut e = Engine::new(playlist.clone(), ReplayOptions::strict().accelerated()).unwrap();
        e.on_connect();
        for session in 0..2 {
            e.on_bytes(&wire(Request::Identify));
            e.on_bytes(&wire(Request::MeasureAll));
            for g in drivers::protocol::SRA_GEOMETRIES {
                let reading = e.on_bytes(&wire(Request::Fetch { geometry: g }));
                assert_eq!(sends(&reading).len(), 1, "session {session} {g}");
            }
        }
        assert!(
            e.report().mismatches.is_empty(),
            "{:?}",
            e.report().mismatches
        );
        let per_session = 2 + drivers::protocol::SRA_GEOMETRIES.len();
        assert_eq!(
            e.report().remaining,
            (playlist.session_count() - 2) * per_session
        );
    }

    /// SRA golden frames (PROTOCOL.md §3) as a small session: IDENTIFY, MEASURE-ALL, two FETCHes.
    const SESSION: &str = "\
brdfd-session 1
device sra
note test
0 > 2449442a323938450d0a
40 < 2149442c52412d353332482c534e2d3030343731312c465720312e30372a333b33300d0a
41 > 244d412a423545460d0a
1500 < 214d412c322a394246340d0a
1501 > 2452442c32302a364536360d0a
1520 < 2152442c32302c332e312a463732310d0a
1521 > 2452442c36302a413241320d0a
1540 < 2152442c36302c372e392a414334380d0a
";

    fn req(r: Request) -> Vec<u8> {
        wire::encode_request(Instrument::Sra, &r).unwrap()
    }

    fn sends(out: &[Out]) -> Vec<(Duration, Vec<u8>)> {
        out.iter()
            .filter_map(|o| match o {
                Out::Send { delay, bytes } => Some((*delay, bytes.clone())),
                Out::Drop { .. } | Out::Cancel => None,
            })
            .collect()
    }

    fn engine(options: ReplayOptions, faults: &[Fault]) -> Engine {
        let mut script = Script::parse(SESSION).unwrap();
        for f in faults {
            script.add_fault(f.clone()).unwrap();
        }
        let mut e = Engine::new(script, options).unwrap();
        e.on_connect();
        e
    }

    fn frame(k: usize) -> Vec<u8> {
        drivers::session::Session::parse(SESSION).unwrap().frames[k]
            .bytes
            .clone()
    }

    const FETCH20: Request = Request::Fetch { geometry: "sra-20" };
    const FETCH60: Request = Request::Fetch { geometry: "sra-60" };

    /// The FETCH sra-60 request was not in PROTOCOL.md's examples; check the session's bytes are
    /// what the codec makes, so the test session is a valid recording.
    #[test]
    fn test_session_is_what_the_codec_sends() {
        assert_eq!(frame(6), req(FETCH60));
        assert_eq!(frame(4), req(FETCH20));
    }

    #[test]
    fn strict_replays_in_order_at_recorded_timing() {
        let mut e = engine(ReplayOptions::strict(), &[]);
        let out = sends(&e.on_bytes(&req(Request::Identify)));
        assert_eq!(out, vec![(Duration::from_millis(40), frame(1))]);
        // Bytes may arrive in pieces.
        let ma = req(Request::MeasureAll);
        assert!(e.on_bytes(&ma[..3]).is_empty());
        assert_eq!(
            sends(&e.on_bytes(&ma[3..])),
            vec![(Duration::from_millis(1459), frame(3))]
        );
        assert_eq!(sends(&e.on_bytes(&req(FETCH20)))[0].1, frame(5));
        assert_eq!(e.report().remaining, 1);
        assert_eq!(sends(&e.on_bytes(&req(FETCH60)))[0].1, frame(7));
        let r = e.report();
        assert!(r.mismatches.is_empty(), "{r:?}");
        assert_eq!((r.requests, r.served, r.remaining), (4, 4, 0));
    }

    #[test]
    fn strict_refuses_out_of_order_and_reports_it() {
        let mut e = engine(ReplayOptions::strict().accelerated(), &[]);
        e.on_bytes(&req(Request::Identify));
        e.on_bytes(&req(Request::MeasureAll));
        let out = sends(&e.on_bytes(&req(FETCH60)));
        let error = wire::encode_response(
            Instrument::Sra,
            &Response::Error {
                request: drivers::protocol::RequestKind::Fetch,
                code: ErrorCode::UnknownRequest,
                geometry: Some("sra-60"),
            },
        )
        .unwrap();
        assert_eq!(out, vec![(Duration::ZERO, error)]);
        let r = e.report();
        assert_eq!(r.mismatches.len(), 1);
        let m = r.mismatches[0].to_string();
        assert!(
            m.starts_with("expected frame 4, FETCH sra-20 (2452442c"),
            "{m}"
        );
        assert!(m.contains("received FETCH sra-60"), "{m}");
        // The position did not move: the expected request is still answered.
        assert_eq!(sends(&e.on_bytes(&req(FETCH20)))[0].1, frame(5));
    }

    #[test]
    fn lenient_answers_by_kind_and_geometry_in_any_order() {
        let mut e = engine(ReplayOptions::lenient().accelerated(), &[]);
        e.on_bytes(&req(Request::Identify));
        assert_eq!(sends(&e.on_bytes(&req(FETCH60)))[0].1, frame(7));
        // Searching wraps round to the start.
        assert_eq!(sends(&e.on_bytes(&req(FETCH20)))[0].1, frame(5));
        assert_eq!(sends(&e.on_bytes(&req(Request::MeasureAll)))[0].1, frame(3));
        // Nothing recorded answers STATUS: refused and reported.
        let out = sends(&e.on_bytes(&req(Request::Status)));
        assert_eq!(out.len(), 1);
        assert!(out[0].1.starts_with(b"!ER,ST,UNKNOWN"), "{:?}", out[0]);
        assert_eq!(e.report().mismatches.len(), 1);
    }

    #[test]
    fn resends_and_reconnections_replay_without_moving_on() {
        let mut e = engine(ReplayOptions::strict().accelerated(), &[]);
        e.on_bytes(&req(Request::Identify));
        e.on_bytes(&req(Request::MeasureAll));
        assert_eq!(sends(&e.on_bytes(&req(FETCH20)))[0].1, frame(5));
        // A resend of FETCH sra-20 is answered again.
        assert_eq!(sends(&e.on_bytes(&req(FETCH20)))[0].1, frame(5));
        // A new connection is introduced with IDENTIFY; the replay continues where it was.
        e.on_connect();
        assert_eq!(sends(&e.on_bytes(&req(Request::Identify)))[0].1, frame(1));
        assert_eq!(sends(&e.on_bytes(&req(FETCH60)))[0].1, frame(7));
        let r = e.report();
        assert!(r.mismatches.is_empty(), "{r:?}");
        assert_eq!(r.connections, 2);
    }

    #[test]
    fn speed_factor_scales_recorded_delays_but_not_fault_delays() {
        let slow = Fault::Slow {
            delay_ms: 300,
            frame: Some(1),
        };
        let mut e = engine(ReplayOptions::strict().speed(4.0), &[slow]);
        let out = sends(&e.on_bytes(&req(Request::Identify)));
        assert_eq!(out[0].0, Duration::from_millis(10 + 300));
        let out = sends(&e.on_bytes(&req(Request::MeasureAll)));
        assert_eq!(out[0].0, Duration::from_secs_f64(1.459 / 4.0));
        assert!(matches!(
            Engine::new(
                Script::parse(SESSION).unwrap(),
                ReplayOptions::strict().speed(0.0)
            ),
            Err(MockError::BadSpeed { .. })
        ));
    }

    #[test]
    fn no_reply_and_corrupt_count_their_times() {
        let mut e = engine(
            ReplayOptions::strict().accelerated(),
            &[
                Fault::NoReply { frame: 5, times: 2 },
                Fault::Corrupt {
                    frame: 7,
                    offset: 9,
                    xor: 0x01,
                    times: 1,
                },
            ],
        );
        e.on_bytes(&req(Request::Identify));
        e.on_bytes(&req(Request::MeasureAll));
        assert!(sends(&e.on_bytes(&req(FETCH20))).is_empty());
        assert!(sends(&e.on_bytes(&req(FETCH20))).is_empty());
        assert_eq!(sends(&e.on_bytes(&req(FETCH20)))[0].1, frame(5));
        let bad = sends(&e.on_bytes(&req(FETCH60)));
        let mut want = frame(7);
        want[9] ^= 0x01;
        assert_eq!(bad[0].1, want);
        assert_eq!(sends(&e.on_bytes(&req(FETCH60)))[0].1, frame(7));
        assert_eq!(
            e.report().faults_fired,
            vec![
                "no-reply frame 5 (time 1)",
                "no-reply frame 5 (time 2)",
                "corrupt frame 7 byte 9 (1 of 1)"
            ]
        );
    }

    #[test]
    fn garbage_goes_once_and_disconnect_fires_once() {
        let mut e = engine(
            ReplayOptions::lenient().accelerated(),
            &[
                Fault::Garbage {
                    frame: 3,
                    bytes: vec![0x21, 0x00, 0xff],
                },
                Fault::Disconnect { after: 4 },
            ],
        );
        e.on_bytes(&req(Request::Identify));
        let out = sends(&e.on_bytes(&req(Request::MeasureAll)));
        assert_eq!(
            out,
            vec![
                (Duration::ZERO, vec![0x21, 0, 0xff]),
                (Duration::ZERO, frame(3))
            ]
        );
        // Frame 4 is the FETCH request: the link drops on receiving it, nothing is answered.
        let out = e.on_bytes(&req(FETCH20));
        assert_eq!(
            out,
            vec![Out::Drop {
                delay: Duration::ZERO,
                unplug: false
            }]
        );
        // After reconnecting, the resend is answered; no second disconnect, no garbage again.
        e.on_connect();
        e.on_bytes(&req(Request::Identify));
        assert_eq!(sends(&e.on_bytes(&req(FETCH20)))[0].1, frame(5));
        assert_eq!(
            sends(&e.on_bytes(&req(Request::MeasureAll))),
            vec![(Duration::ZERO, frame(3))]
        );
    }

    #[test]
    fn playlists_skip_introductions_the_driver_does_not_repeat() {
        let one = drivers::session::Session::parse(SESSION).unwrap();
        let script = Script::from_sessions([one.clone(), one]).unwrap();
        let mut e = Engine::new(script, ReplayOptions::strict().accelerated()).unwrap();
        e.on_connect();
        for _ in 0..2 {
            e.on_bytes(&req(Request::Identify));
            for r in [Request::MeasureAll, FETCH20, FETCH60] {
                assert_eq!(sends(&e.on_bytes(&req(r))).len(), 1);
            }
        }
        let r = e.report();
        assert!(r.mismatches.is_empty(), "{r:?}");
        assert_eq!(r.remaining, 0);
        // On one connection the second session's IDENTIFY is skipped.
        let one = drivers::session::Session::parse(SESSION).unwrap();
        let script = Script::from_sessions([one.clone(), one]).unwrap();
        let mut e = Engine::new(script, ReplayOptions::strict().accelerated()).unwrap();
        e.on_connect();
        e.on_bytes(&req(Request::Identify));
        for _ in 0..2 {
            for r in [Request::MeasureAll, FETCH20, FETCH60] {
                assert_eq!(sends(&e.on_bytes(&req(r))).len(), 1);
            }
        }
        let r = e.report();
        assert!(r.mismatches.is_empty(), "{r:?}");
        assert_eq!(r.remaining, 0);
    }

    #[test]
    fn bytes_that_are_not_requests_are_dropped_and_reported() {
        let mut e = engine(ReplayOptions::strict(), &[]);
        let mut bad = req(Request::Identify);
        bad[1] ^= 0x20; // `$id`: the CRC no longer matches
        assert!(e.on_bytes(&bad).is_empty());
        assert!(e.on_bytes(b"xyz").is_empty());
        let r = e.report();
        assert_eq!(r.requests, 0);
        assert_eq!(r.dropped.len(), 2, "{r:?}");
    }
}
