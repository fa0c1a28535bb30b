//! What a simulated instrument replays: one or more session files (`brdfd-session 1`, read with
//! `drivers::session`) of the same instrument, cut into exchanges — a request from brdfd and
//! the device frames that followed it — with their fault directives.
//!
//! Several sessions can be replayed back to back (a playlist: the N9 reference, then the
//! samples). Frames are then numbered through the whole playlist, in file order, both
//! directions counted, so for a single session the numbers are the file's own (PROTOCOL.md §5);
//! a session's own `fault` lines are shifted by the number of frames before it.

use std::fmt;

use drivers::Instrument;
use drivers::protocol::{Reading, Request, Response};
use drivers::session::{Direction, Fault, Session};

use crate::MockError;
use crate::wire;

/// One recorded frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Recorded {
    /// Frame number through the whole script (the file's own number for a single session).
    pub index: usize,
    /// Milliseconds since its session started, as recorded.
    pub t_ms: u64,
    /// The frame's bytes as recorded.
    pub bytes: Vec<u8>,
}

/// A request from brdfd and the device frames recorded after it, up to the next request.
#[derive(Debug, Clone, PartialEq)]
pub struct Exchange {
    /// Which session of the script it comes from (0-based).
    pub session: usize,
    /// `None` for device frames recorded before any request (replayed at the first connection).
    pub request: Option<Recorded>,
    /// The request decoded with the instrument's codec; `None` if the recorded bytes are not a
    /// valid request (a recording of a corrupted write).
    pub parsed: Option<Request>,
    /// The device frames recorded after the request, in order.
    pub replies: Vec<Recorded>,
}

impl Exchange {
    /// The request bytes, if the exchange has a request.
    pub fn request_bytes(&self) -> Option<&[u8]> {
        self.request.as_ref().map(|r| r.bytes.as_slice())
    }
}

/// A replayable script for one instrument.
#[derive(Debug, Clone, PartialEq)]
pub struct Script {
    instrument: Instrument,
    exchanges: Vec<Exchange>,
    faults: Vec<Fault>,
    /// Device direction of every frame, by global number (for checking faults).
    directions: Vec<(Direction, usize)>,
    /// The sessions' first `note` line or "session N", for messages.
    labels: Vec<String>,
    /// What each session measured, from its notes (`note sample …`, `note reference …`).
    objects: Vec<ScriptObject>,
}

/// What one session of a script measured, as its notes say.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ScriptObject {
    /// The white reference tile (`note reference …`).
    Reference,
    /// A sample (`note sample NAME`).
    Sample(String),
    /// The notes do not say.
    Unknown,
}

impl Script {
    /// A script replaying one session.
    pub fn new(session: Session) -> Result<Script, MockError> {
        Script::from_sessions([session])
    }

    /// Parse the text of one session file into a script.
    pub fn parse(text: &str) -> Result<Script, MockError> {
        Script::new(Session::parse(text)?)
    }

    /// A script replaying `sessions` back to back. They must all be of one instrument.
    pub fn from_sessions(sessions: impl IntoIterator<Item = Session>) -> Result<Script, MockError> {
        let mut script: Option<Script> = None;
        for (n, session) in sessions.into_iter().enumerate() {
            let label = session
                .notes
                .first()
                .cloned()
                .unwrap_or_else(|| format!("session {n}"));
            let s = script.get_or_insert_with(|| Script {
                instrument: session.instrument,
                exchanges: Vec::new(),
                faults: Vec::new(),
                directions: Vec::new(),
                labels: Vec::new(),
                objects: Vec::new(),
            });
            if session.instrument != s.instrument {
                return Err(MockError::WrongInstrument {
                    session: n,
                    label,
                    found: session.instrument,
                    expected: s.instrument,
                });
            }
            let offset = s.directions.len();
            for (k, frame) in session.frames.iter().enumerate() {
                let recorded = Recorded {
                    index: offset + k,
                    t_ms: frame.t_ms,
                    bytes: frame.bytes.clone(),
                };
                s.directions.push((frame.direction, frame.bytes.len()));
                match frame.direction {
                    Direction::ToDevice => s.exchanges.push(Exchange {
                        session: n,
                        parsed: wire::parse_request(s.instrument, &frame.bytes),
                        request: Some(recorded),
                        replies: Vec::new(),
                    }),
                    Direction::FromDevice => {
                        match s.exchanges.last_mut().filter(|e| e.session == n) {
                            Some(e) => e.replies.push(recorded),
                            None => s.exchanges.push(Exchange {
                                session: n,
                                request: None,
                                parsed: None,
                                replies: vec![recorded],
                            }),
                        }
                    }
                }
            }
            for fault in &session.faults {
                // The session parser has checked its faults against its own frames.
                s.faults.push(shift(fault, offset));
            }
            s.labels.push(label);
            s.objects.push(if crate::generate::is_reference(&session) {
                ScriptObject::Reference
            } else {
                match crate::generate::sample_of(&session) {
                    Some(name) => ScriptObject::Sample(name.to_string()),
                    None => ScriptObject::Unknown,
                }
            });
        }
        script.ok_or(MockError::NoSessions)
    }

    /// Add a fault chosen in code. Frame numbers count through the whole script.
    pub fn add_fault(&mut self, fault: Fault) -> Result<(), MockError> {
        self.check_fault(&fault)
            .map_err(|detail| MockError::BadFault {
                fault: fault.to_string(),
                detail,
            })?;
        self.faults.push(fault);
        Ok(())
    }

    /// [`Script::add_fault`], builder style.
    pub fn with_fault(mut self, fault: Fault) -> Result<Script, MockError> {
        self.add_fault(fault)?;
        Ok(self)
    }

    fn check_fault(&self, fault: &Fault) -> Result<(), String> {
        let n = self.directions.len();
        let device_frame = |k: usize| -> Result<usize, String> {
            match self.directions.get(k) {
                None => Err(format!("frame {k} does not exist (the script has {n})")),
                Some((Direction::ToDevice, _)) => Err(format!(
                    "frame {k} is sent by brdfd (>), not by the device (<)"
                )),
                Some((Direction::FromDevice, len)) => Ok(*len),
            }
        };
        if let Fault::NoReply { times: 0, .. } | Fault::Corrupt { times: 0, .. } = fault {
            return Err("times must be at least 1".into());
        }
        match fault {
            Fault::Disconnect { after } if *after >= n => {
                Err(format!("frame {after} does not exist (the script has {n})"))
            }
            Fault::Disconnect { .. } | Fault::Slow { frame: None, .. } => Ok(()),
            Fault::Corrupt {
                frame, offset, xor, ..
            } => {
                let len = device_frame(*frame)?;
                if *xor == 0 {
                    Err("xor=00 would not change the byte".into())
                } else if *offset >= len {
                    Err(format!(
                        "offset {offset} is past frame {frame}'s {len} bytes"
                    ))
                } else {
                    Ok(())
                }
            }
            Fault::Garbage { frame, bytes } => {
                device_frame(*frame)?;
                if bytes.is_empty() {
                    Err("garbage needs at least one byte".into())
                } else {
                    Ok(())
                }
            }
            Fault::NoReply { frame, .. }
            | Fault::Slow {
                frame: Some(frame), ..
            } => device_frame(*frame).map(|_| ()),
        }
    }

    /// The instrument the script records.
    pub fn instrument(&self) -> Instrument {
        self.instrument
    }

    /// The exchanges in script order.
    pub fn exchanges(&self) -> &[Exchange] {
        &self.exchanges
    }

    /// Every fault, from the session files and from code, in global frame numbers.
    pub fn faults(&self) -> &[Fault] {
        &self.faults
    }

    /// Number of frames in the script, both directions.
    pub fn frame_count(&self) -> usize {
        self.directions.len()
    }

    /// Number of sessions in the script.
    pub fn session_count(&self) -> usize {
        self.labels.len()
    }

    /// What session `n` measured.
    pub fn object(&self, n: usize) -> &ScriptObject {
        self.objects.get(n).unwrap_or(&ScriptObject::Unknown)
    }

    /// The first session of the reference tile (`sample` `None`) or of the sample of that name
    /// (ignoring case), if the script holds one.
    pub fn session_of(&self, sample: Option<&str>) -> Option<usize> {
        self.objects.iter().position(|o| match (o, sample) {
            (ScriptObject::Reference, None) => true,
            (ScriptObject::Sample(name), Some(wanted)) => name.eq_ignore_ascii_case(wanted),
            _ => false,
        })
    }

    /// The label of session `n` (its first note), for messages.
    pub fn label(&self, n: usize) -> &str {
        self.labels.get(n).map_or("?", String::as_str)
    }

    /// Every reading the recording holds (the device frames that decode to a reading, through
    /// the instrument's codec), in recorded order: what a replay must deliver bit for bit.
    pub fn readings(&self) -> Vec<Reading> {
        self.exchanges
            .iter()
            .flat_map(|e| &e.replies)
            .filter_map(|r| match wire::parse_response(self.instrument, &r.bytes)? {
                Response::Fetched(reading) | Response::MeasuredOne(reading) => Some(reading),
                _ => None,
            })
            .collect()
    }

    /// The readings of session `n` only.
    pub fn session_readings(&self, n: usize) -> Vec<Reading> {
        self.exchanges
            .iter()
            .filter(|e| e.session == n)
            .flat_map(|e| &e.replies)
            .filter_map(|r| match wire::parse_response(self.instrument, &r.bytes)? {
                Response::Fetched(reading) | Response::MeasuredOne(reading) => Some(reading),
                _ => None,
            })
            .collect()
    }
}

impl fmt::Display for Script {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} replay of {} session(s), {} frames",
            self.instrument,
            self.labels.len(),
            self.directions.len()
        )
    }
}

fn shift(fault: &Fault, offset: usize) -> Fault {
    match fault.clone() {
        Fault::Disconnect { after } => Fault::Disconnect {
            after: after + offset,
        },
        Fault::NoReply { frame, times } => Fault::NoReply {
            frame: frame + offset,
            times,
        },
        Fault::Corrupt {
            frame,
            offset: o,
            xor,
            times,
        } => Fault::Corrupt {
            frame: frame + offset,
            offset: o,
            xor,
            times,
        },
        Fault::Garbage { frame, bytes } => Fault::Garbage {
            frame: frame + offset,
            bytes,
        },
        Fault::Slow { delay_ms, frame } => Fault::Slow {
            delay_ms,
            frame: frame.map(|k| k + offset),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two SRA sessions, the second with a fault of its own (golden frames of PROTOCOL.md).
    const A: &str = "\
brdfd-session 1
device sra
note first
0 > 2449442a323938450d0a
4 < 2149442c52412d353332482c534e2d3030343731312c465720312e30372a333b33300d0a
10 > 2452442c32302a364536360d0a
12 < 2152442c32302c332e312a463732310d0a
";
    const B: &str = "\
brdfd-session 1
device sra
note second
fault corrupt frame=1 offset=2
0 > 2452442c32302a364536360d0a
2 < 2152442c32302c332e312a463732310d0a
";

    #[test]
    fn exchanges_group_replies_under_their_request() {
        let s = Script::parse(A).unwrap();
        assert_eq!(s.instrument(), Instrument::Sra);
        assert_eq!(s.exchanges().len(), 2);
        assert_eq!(s.exchanges()[0].parsed, Some(Request::Identify));
        assert_eq!(s.exchanges()[1].replies[0].index, 3);
        let r = s.readings();
        assert_eq!(r.len(), 1);
        assert_eq!(r[0].geometry, "sra-20");
    }

    #[test]
    fn playlist_numbers_frames_through_and_shifts_faults() {
        let s = Script::from_sessions([Session::parse(A).unwrap(), Session::parse(B).unwrap()])
            .unwrap();
        assert_eq!(s.frame_count(), 6);
        assert_eq!(s.session_count(), 2);
        assert_eq!(s.label(1), "second");
        assert_eq!(
            s.faults(),
            &[Fault::Corrupt {
                frame: 5,
                offset: 2,
                xor: 0xff,
                times: 1
            }]
        );
        assert_eq!(s.session_readings(1).len(), 1);
    }

    #[test]
    fn code_faults_are_checked_against_the_frames() {
        let s = Script::parse(A).unwrap();
        for (fault, ok) in [
            (Fault::NoReply { frame: 3, times: 2 }, true),
            (Fault::NoReply { frame: 2, times: 1 }, false),
            (Fault::NoReply { frame: 3, times: 0 }, false),
            (Fault::Disconnect { after: 3 }, true),
            (Fault::Disconnect { after: 4 }, false),
            (
                Fault::Corrupt {
                    frame: 3,
                    offset: 17,
                    xor: 1,
                    times: 1,
                },
                false,
            ),
            (
                Fault::Garbage {
                    frame: 1,
                    bytes: vec![0],
                },
                true,
            ),
            (
                Fault::Slow {
                    delay_ms: 5,
                    frame: Some(9),
                },
                false,
            ),
        ] {
            let r = s.clone().with_fault(fault.clone());
            assert_eq!(r.is_ok(), ok, "{fault}: {r:?}");
            if let Err(e) = r {
                assert!(e.to_string().contains(&fault.to_string()), "{e}");
            }
        }
    }

    #[test]
    fn instruments_cannot_be_mixed() {
        let usb = "brdfd-session 1\ndevice ma_t12\nnote usb\n0 > 4d54010000e4a9\n";
        let err = Script::from_sessions([Session::parse(A).unwrap(), Session::parse(usb).unwrap()])
            .unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("session 1 (usb)"), "{msg}");
        assert!(msg.contains("X-Rite MA-T12"), "{msg}");
        assert!(matches!(
            Script::from_sessions(Vec::<Session>::new()),
            Err(MockError::NoSessions)
        ));
    }
}
