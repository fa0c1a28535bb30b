//! The session-file format (`brdfd-session 1`): a line-oriented record of every frame between
//! brdfd and one instrument, with timestamps, plus optional fault directives for the simulated
//! instruments. Written by the recording tap, replayed by `mock-devices`; specified in
//! PROTOCOL.md ("Session files").
//!
//! ```text
//! brdfd-session 1
//! device ma_t12
//! note synthetic: generated from ground truth, not recorded from an instrument
//! fault corrupt frame=5 offset=9 xor=ff times=1
//! # free comment
//! 0 > 4d54010000e4a9  # IDENTIFY
//! 3 < 4d54811b00…7beb  # IDENTITY MA-T12 serial SN-000123 firmware FW 2.1.04
//! ```
//!
//! One frame per line so that two recordings diff line by line; the hex is the data, the
//! trailing `# …` is a decoded comment for people and is ignored when reading.

use std::fmt;
use std::io::Read;

use crate::protocol::Instrument;

/// First line of every session file.
pub const HEADER: &str = "brdfd-session";
/// The format version this code reads and writes.
pub const FORMAT_VERSION: u32 = 1;

/// Which way a frame went.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Direction {
    /// brdfd → instrument, written `>`.
    ToDevice,
    /// instrument → brdfd, written `<`.
    FromDevice,
}

impl Direction {
    /// The character that marks the direction in a session file: `>` or `<`.
    pub const fn symbol(self) -> char {
        match self {
            Direction::ToDevice => '>',
            Direction::FromDevice => '<',
        }
    }
}

/// One frame (or, for bytes that never formed a frame, one run of them) on the line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// Milliseconds since the session started.
    pub t_ms: u64,
    /// Which way the bytes went.
    pub direction: Direction,
    /// The bytes exactly as on the line.
    pub bytes: Vec<u8>,
    /// The decoded comment, without the `#`. Informative only.
    pub comment: Option<String>,
}

impl fmt::Display for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} {} {}",
            self.t_ms,
            self.direction.symbol(),
            to_hex(&self.bytes)
        )?;
        if let Some(c) = &self.comment {
            write!(f, "  # {}", c.replace(['\r', '\n'], " "))?;
        }
        Ok(())
    }
}

/// A fault for a simulated instrument to inject while replaying. Frame numbers count the frame
/// lines of the file from 0, in both directions. Applied by `mock-devices`; the outcomes the
/// driver guarantees are in PROTOCOL.md ("Faults").
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Fault {
    /// `disconnect after=K`: the instrument drops the connection once frame K has gone by.
    Disconnect {
        /// The frame after which the link drops.
        after: usize,
    },
    /// `no-reply frame=K [times=N]`: device frame K is not sent, the first N times it is due.
    NoReply {
        /// The device frame withheld.
        frame: usize,
        /// How many times it is withheld.
        times: u32,
    },
    /// `corrupt frame=K offset=O [xor=XX] [times=N]`: byte O of device frame K is XORed with XX
    /// (hex, default ff) the first N times it is sent.
    Corrupt {
        /// The device frame to damage.
        frame: usize,
        /// Offset of the byte to damage.
        offset: usize,
        /// The mask XORed into the byte.
        xor: u8,
        /// How many times the frame is damaged.
        times: u32,
    },
    /// `garbage frame=K bytes=HEX`: the bytes are sent just before device frame K.
    Garbage {
        /// The device frame the garbage precedes.
        frame: usize,
        /// The garbage bytes.
        bytes: Vec<u8>,
    },
    /// `slow delay_ms=D [frame=K]`: every device frame (or only frame K) is sent D ms late.
    Slow {
        /// The extra delay, in milliseconds.
        delay_ms: u64,
        /// The only frame delayed; `None`: every device frame.
        frame: Option<usize>,
    },
}

impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Fault::Disconnect { after } => write!(f, "disconnect after={after}"),
            Fault::NoReply { frame, times } => write!(f, "no-reply frame={frame} times={times}"),
            Fault::Corrupt {
                frame,
                offset,
                xor,
                times,
            } => {
                write!(
                    f,
                    "corrupt frame={frame} offset={offset} xor={xor:02x} times={times}"
                )
            }
            Fault::Garbage { frame, bytes } => {
                write!(f, "garbage frame={frame} bytes={}", to_hex(bytes))
            }
            Fault::Slow {
                delay_ms,
                frame: None,
            } => write!(f, "slow delay_ms={delay_ms}"),
            Fault::Slow {
                delay_ms,
                frame: Some(k),
            } => {
                write!(f, "slow delay_ms={delay_ms} frame={k}")
            }
        }
    }
}

/// A whole session file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Session {
    /// The instrument recorded (the `device` line).
    pub instrument: Instrument,
    /// `note` lines: provenance (e.g. "synthetic"), sample name, anything a reader needs.
    pub notes: Vec<String>,
    /// `fault` lines: what a simulated instrument injects when it replays the session.
    pub faults: Vec<Fault>,
    /// The frames in file order.
    pub frames: Vec<Frame>,
}

/// Why a session file cannot be read. Every message names the line and what to fix.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SessionError {
    #[error("session file: cannot read it: {detail}")]
    /// The file cannot be read.
    Io {
        /// The I/O error.
        detail: String,
    },
    #[error("session file does not start with `{HEADER} {FORMAT_VERSION}`: is it a session file?")]
    /// The first line is not the format header.
    MissingHeader,
    #[error(
        "session file line {line}: format version {found:?} is not supported (this brdfd reads {FORMAT_VERSION})"
    )]
    /// The header names a format version this brdfd cannot read.
    UnsupportedVersion {
        /// 1-based line number.
        line: usize,
        /// The version in the file.
        found: String,
    },
    #[error("session file line {line}: unknown device {found:?} (use ma_t12 or sra)")]
    /// The `device` line names no known instrument.
    UnknownDevice {
        /// 1-based line number.
        line: usize,
        /// The device key in the file.
        found: String,
    },
    #[error("session file: no `device` line before the first frame")]
    /// A frame comes before the `device` line.
    MissingDevice,
    #[error("session file line {line}: {detail}")]
    /// A line that is not a frame, note, fault, comment or device line.
    BadLine {
        /// 1-based line number.
        line: usize,
        /// What is wrong with it.
        detail: String,
    },
    #[error("session file line {line}: bad fault directive: {detail}")]
    /// A `fault` line that does not parse.
    BadFault {
        /// 1-based line number.
        line: usize,
        /// What is wrong with it.
        detail: String,
    },
    #[error(
        "session file line {line}: time {t_ms} ms is before the previous frame's {previous} ms"
    )]
    /// A frame's timestamp is earlier than the frame before it.
    TimeGoesBackwards {
        /// 1-based line number.
        line: usize,
        /// The frame's time, ms since the session started.
        t_ms: u64,
        /// The previous frame's time, ms.
        previous: u64,
    },
}

impl Session {
    /// An empty session for `instrument`.
    pub fn new(instrument: Instrument) -> Session {
        Session {
            instrument,
            notes: Vec::new(),
            faults: Vec::new(),
            frames: Vec::new(),
        }
    }

    /// Read a session file.
    pub fn read(mut reader: impl Read) -> Result<Session, SessionError> {
        let mut text = String::new();
        reader
            .read_to_string(&mut text)
            .map_err(|e| SessionError::Io {
                detail: e.to_string(),
            })?;
        Session::parse(&text)
    }

    /// Parse the text of a session file.
    pub fn parse(text: &str) -> Result<Session, SessionError> {
        let mut seen_header = false;
        let mut instrument = None;
        let mut notes = Vec::new();
        let mut faults = Vec::new();
        let mut fault_lines = Vec::new();
        let mut frames: Vec<Frame> = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let line = i + 1;
            let trimmed = raw.trim();
            if trimmed.is_empty() || trimmed.starts_with('#') {
                continue;
            }
            let bad = |detail: String| SessionError::BadLine { line, detail };
            if !seen_header {
                let version = trimmed
                    .strip_prefix(HEADER)
                    .ok_or(SessionError::MissingHeader)?;
                let version = version.trim();
                if version != FORMAT_VERSION.to_string() {
                    return Err(SessionError::UnsupportedVersion {
                        line,
                        found: version.into(),
                    });
                }
                seen_header = true;
                continue;
            }
            let (word, rest) = trimmed.split_once(' ').unwrap_or((trimmed, ""));
            let rest = rest.trim();
            if word.bytes().all(|b| b.is_ascii_digit()) {
                if instrument.is_none() {
                    return Err(SessionError::MissingDevice);
                }
                let frame = parse_frame(word, rest).map_err(bad)?;
                if let Some(prev) = frames.last()
                    && frame.t_ms < prev.t_ms
                {
                    return Err(SessionError::TimeGoesBackwards {
                        line,
                        t_ms: frame.t_ms,
                        previous: prev.t_ms,
                    });
                }
                frames.push(frame);
                continue;
            }
            if !frames.is_empty() {
                return Err(bad(format!(
                    "`{word}` after the first frame: header lines (device, note, fault) come first"
                )));
            }
            match word {
                "device" => {
                    instrument = Some(Instrument::from_key(rest).ok_or_else(|| {
                        SessionError::UnknownDevice {
                            line,
                            found: rest.into(),
                        }
                    })?);
                }
                "note" => notes.push(rest.to_owned()),
                "fault" => {
                    faults.push(
                        parse_fault(rest)
                            .map_err(|detail| SessionError::BadFault { line, detail })?,
                    );
                    fault_lines.push(line);
                }
                other => {
                    return Err(bad(format!(
                        "unknown directive `{other}` (expected device, note, fault or a frame)"
                    )));
                }
            }
        }
        if !seen_header {
            return Err(SessionError::MissingHeader);
        }
        let instrument = instrument.ok_or(SessionError::MissingDevice)?;
        for (fault, line) in faults.iter().zip(fault_lines) {
            check_fault(fault, &frames)
                .map_err(|detail| SessionError::BadFault { line, detail })?;
        }
        Ok(Session {
            instrument,
            notes,
            faults,
            frames,
        })
    }

    /// The file text; [`Session::parse`] reads it back to an equal session.
    pub fn to_text(&self) -> String {
        self.to_string()
    }

    /// The header lines (format, device, notes, faults), each ending in `\n`.
    pub fn header_text(instrument: Instrument, notes: &[String], faults: &[Fault]) -> String {
        let mut out = format!("{HEADER} {FORMAT_VERSION}\ndevice {}\n", instrument.key());
        for n in notes {
            out.push_str(&format!("note {}\n", n.replace(['\r', '\n'], " ")));
        }
        for f in faults {
            out.push_str(&format!("fault {f}\n"));
        }
        out
    }
}

impl fmt::Display for Session {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&Session::header_text(
            self.instrument,
            &self.notes,
            &self.faults,
        ))?;
        for frame in &self.frames {
            writeln!(f, "{frame}")?;
        }
        Ok(())
    }
}

/// Lower-case hex, no separators.
pub fn to_hex(bytes: &[u8]) -> String {
    use fmt::Write;
    let mut s = String::with_capacity(bytes.len() * 2);
    for b in bytes {
        let _ = write!(s, "{b:02x}");
    }
    s
}

/// Hex (either case) to bytes.
pub fn from_hex(s: &str) -> Result<Vec<u8>, String> {
    if !s.len().is_multiple_of(2) {
        return Err(format!("hex {s:?} has an odd number of digits"));
    }
    if let Some(c) = s.chars().find(|c| !c.is_ascii_hexdigit()) {
        return Err(format!("{c:?} is not a hex digit"));
    }
    Ok((0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).expect("hex"))
        .collect())
}

fn parse_frame(t: &str, rest: &str) -> Result<Frame, String> {
    let t_ms = t
        .parse()
        .map_err(|_| format!("time {t:?} is not a whole number of ms"))?;
    let (data, comment) = match rest.split_once('#') {
        Some((d, c)) => (d.trim(), Some(c.trim().to_owned())),
        None => (rest, None),
    };
    let (dir, hex) = data.split_once(' ').unwrap_or((data, ""));
    let direction = match dir {
        ">" => Direction::ToDevice,
        "<" => Direction::FromDevice,
        other => {
            return Err(format!(
                "direction {other:?} must be > (to device) or < (from device)"
            ));
        }
    };
    let hex = hex.trim();
    if hex.is_empty() {
        return Err("frame has no bytes".into());
    }
    let bytes = from_hex(hex)?;
    Ok(Frame {
        t_ms,
        direction,
        bytes,
        comment,
    })
}

fn parse_fault(text: &str) -> Result<Fault, String> {
    let mut words = text.split_whitespace();
    let kind = words.next().ok_or("empty fault directive")?;
    let mut args = std::collections::BTreeMap::new();
    for w in words {
        let (k, v) = w
            .split_once('=')
            .ok_or_else(|| format!("{w:?} is not key=value"))?;
        if args.insert(k, v).is_some() {
            return Err(format!("{k} given twice"));
        }
    }
    let allowed: &[&str] = match kind {
        "disconnect" => &["after"],
        "no-reply" => &["frame", "times"],
        "corrupt" => &["frame", "offset", "xor", "times"],
        "garbage" => &["frame", "bytes"],
        "slow" => &["delay_ms", "frame"],
        other => {
            return Err(format!(
                "unknown fault {other:?} (disconnect, no-reply, corrupt, garbage, slow)"
            ));
        }
    };
    if let Some(k) = args.keys().find(|k| !allowed.contains(k)) {
        return Err(format!("{kind} takes {}, not {k}", allowed.join(", ")));
    }
    fn num<T: std::str::FromStr>(
        args: &std::collections::BTreeMap<&str, &str>,
        key: &str,
    ) -> Result<Option<T>, String> {
        args.get(key)
            .map(|v| {
                v.parse::<T>()
                    .map_err(|_| format!("{key}={v} is not a whole number"))
            })
            .transpose()
    }
    let need = |key: &str| format!("{kind} needs {key}=");
    let times = num::<u32>(&args, "times")?.unwrap_or(1);
    if times == 0 {
        return Err("times must be at least 1".into());
    }
    Ok(match kind {
        "disconnect" => Fault::Disconnect {
            after: num(&args, "after")?.ok_or_else(|| need("after"))?,
        },
        "no-reply" => Fault::NoReply {
            frame: num(&args, "frame")?.ok_or_else(|| need("frame"))?,
            times,
        },
        "corrupt" => {
            let xor = match args.get("xor") {
                Some(x) => {
                    u8::from_str_radix(x, 16).map_err(|_| format!("xor={x} is not a hex byte"))?
                }
                None => 0xff,
            };
            if xor == 0 {
                return Err("xor=00 would not change the byte".into());
            }
            Fault::Corrupt {
                frame: num(&args, "frame")?.ok_or_else(|| need("frame"))?,
                offset: num(&args, "offset")?.ok_or_else(|| need("offset"))?,
                xor,
                times,
            }
        }
        "garbage" => {
            let bytes = from_hex(args.get("bytes").ok_or_else(|| need("bytes"))?)?;
            if bytes.is_empty() {
                return Err("garbage needs at least one byte".into());
            }
            Fault::Garbage {
                frame: num(&args, "frame")?.ok_or_else(|| need("frame"))?,
                bytes,
            }
        }
        _ => Fault::Slow {
            delay_ms: num(&args, "delay_ms")?.ok_or_else(|| need("delay_ms"))?,
            frame: num(&args, "frame")?,
        },
    })
}

/// A fault must point at a frame that exists, and at a device frame where it changes what the
/// device sends.
fn check_fault(fault: &Fault, frames: &[Frame]) -> Result<(), String> {
    let device_frame = |k: usize| -> Result<&Frame, String> {
        let f = frames
            .get(k)
            .ok_or_else(|| format!("frame {k} does not exist (the file has {})", frames.len()))?;
        if f.direction != Direction::FromDevice {
            return Err(format!(
                "frame {k} is sent by brdfd (>), not by the device (<)"
            ));
        }
        Ok(f)
    };
    match fault {
        Fault::Disconnect { after } => {
            if *after >= frames.len() {
                return Err(format!(
                    "frame {after} does not exist (the file has {})",
                    frames.len()
                ));
            }
        }
        Fault::NoReply { frame, .. } | Fault::Garbage { frame, .. } => {
            device_frame(*frame)?;
        }
        Fault::Corrupt { frame, offset, .. } => {
            let f = device_frame(*frame)?;
            if *offset >= f.bytes.len() {
                return Err(format!(
                    "offset {offset} is past frame {frame}'s {} bytes",
                    f.bytes.len()
                ));
            }
        }
        Fault::Slow { frame: Some(k), .. } => {
            device_frame(*k)?;
        }
        Fault::Slow { frame: None, .. } => {}
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(super) const EXAMPLE: &str = "\
brdfd-session 1
device sra
note synthetic: made up for this test
fault corrupt frame=3 offset=4 xor=01 times=2
fault no-reply frame=1
fault garbage frame=3 bytes=00ff21
fault slow delay_ms=250
fault disconnect after=2
# a comment line
0 > 2449442a323938450d0a  # IDENTIFY
4 < 2149442c52412d353332482c534e2d3030343731312c465720312e30372a333b33300d0a  # IDENTITY
10 > 2452442c32302a364536360d0a  # FETCH sra-20
12 < 2152442c32302c332e312a463732310d0a  # READING sra-20 intensity 3.1
";

    #[test]
    fn parses_header_faults_and_frames() {
        let s = Session::parse(EXAMPLE).unwrap();
        assert_eq!(s.instrument, Instrument::Sra);
        assert_eq!(
            s.notes,
            vec!["synthetic: made up for this test".to_string()]
        );
        assert_eq!(s.frames.len(), 4);
        assert_eq!(s.frames[1].direction, Direction::FromDevice);
        assert_eq!(s.frames[2].t_ms, 10);
        assert_eq!(&s.frames[0].bytes, b"$ID*298E\r\n");
        assert_eq!(
            s.frames[3].comment.as_deref(),
            Some("READING sra-20 intensity 3.1")
        );
        assert_eq!(
            s.faults,
            vec![
                Fault::Corrupt {
                    frame: 3,
                    offset: 4,
                    xor: 1,
                    times: 2
                },
                Fault::NoReply { frame: 1, times: 1 },
                Fault::Garbage {
                    frame: 3,
                    bytes: vec![0, 0xff, 0x21]
                },
                Fault::Slow {
                    delay_ms: 250,
                    frame: None
                },
                Fault::Disconnect { after: 2 },
            ]
        );
    }

    #[test]
    fn text_round_trips() {
        let s = Session::parse(EXAMPLE).unwrap();
        let again = Session::parse(&s.to_text()).unwrap();
        assert_eq!(s, again);
        // Writing is canonical: a second trip gives the same text.
        assert_eq!(again.to_text(), s.to_text());
    }

    #[test]
    fn errors_name_the_line_and_the_fix() {
        let cases: [(&str, &str); 8] = [
            ("hello\n", "does not start with"),
            (
                "brdfd-session 2\ndevice sra\n",
                "version \"2\" is not supported",
            ),
            (
                "brdfd-session 1\ndevice lamp\n",
                "line 2: unknown device \"lamp\"",
            ),
            ("brdfd-session 1\n0 > 00\n", "no `device` line"),
            (
                "brdfd-session 1\ndevice sra\n0 = 00\n",
                "line 3: direction \"=\"",
            ),
            (
                "brdfd-session 1\ndevice sra\n0 > 0g\n",
                "line 3: 'g' is not a hex digit",
            ),
            (
                "brdfd-session 1\ndevice sra\n5 > 00\n4 < 00\n",
                "line 4: time 4 ms is before",
            ),
            (
                "brdfd-session 1\ndevice sra\nfault corrupt frame=0 offset=0\n0 > 00\n",
                "line 3: bad fault directive: frame 0 is sent by brdfd",
            ),
        ];
        for (text, want) in cases {
            let err = Session::parse(text).unwrap_err().to_string();
            assert!(err.contains(want), "{text:?}: {err}");
        }
    }

    #[test]
    fn faults_are_checked_against_the_frames() {
        let base = "brdfd-session 1\ndevice sra\n";
        let frames = "0 > 00\n1 < 0102\n";
        for (fault, ok) in [
            ("fault corrupt frame=1 offset=1", true),
            ("fault corrupt frame=1 offset=2", false),
            ("fault corrupt frame=1 offset=0 xor=00", false),
            ("fault no-reply frame=2", false),
            ("fault no-reply frame=1 times=0", false),
            ("fault disconnect after=1", true),
            ("fault disconnect after=2", false),
            ("fault slow delay_ms=5 frame=1", true),
            ("fault slow delay_ms=5 frame=0", false),
            ("fault garbage frame=1 bytes=", false),
            ("fault explode frame=1", false),
            ("fault no-reply frame=1 offset=3", false),
        ] {
            let r = Session::parse(&format!("{base}{fault}\n{frames}"));
            assert_eq!(r.is_ok(), ok, "{fault}: {r:?}");
        }
    }
}

/// Property tests: whatever text a session file holds, [`Session::parse`] returns (never
/// panics), an error names a problem, and a session it accepts writes a file that reads back
/// to the same text.
#[cfg(test)]
mod proptests {
    use super::*;
    use proptest::prelude::*;
    use proptest::sample::{Index, select};

    /// Words of the format, and values that are out of range or not what a key takes.
    const WORDS: [&str; 30] = [
        "brdfd-session 1",
        "brdfd-session 2",
        "device sra",
        "device ma_t12",
        "note",
        "fault",
        "corrupt",
        "no-reply",
        "garbage",
        "slow",
        "disconnect",
        "frame=0",
        "frame=99",
        "offset=18446744073709551616",
        "xor=00",
        "xor=fff",
        "times=0",
        "bytes=0",
        "after=1",
        "delay_ms=5",
        ">",
        "<",
        "0",
        "18446744073709551616",
        "00ff",
        "0g",
        "#",
        " ",
        "\n",
        "\r\n",
    ];

    /// A valid session, edited.
    #[derive(Debug, Clone)]
    enum Edit {
        Delete(Index),
        Insert(Index, &'static str),
        Truncate(Index),
    }

    fn edit() -> impl Strategy<Value = Edit> {
        prop_oneof![
            any::<Index>().prop_map(Edit::Delete),
            (any::<Index>(), select(WORDS.to_vec())).prop_map(|(i, w)| Edit::Insert(i, w)),
            any::<Index>().prop_map(Edit::Truncate),
        ]
    }

    fn apply(text: &str, edits: &[Edit]) -> String {
        let mut t = text.to_string();
        for e in edits {
            // A char boundary picked by the index, the end of the text included.
            let at = |i: &Index, t: &str| {
                let k = i.index(t.chars().count() + 1);
                t.char_indices().nth(k).map_or(t.len(), |(at, _)| at)
            };
            match e {
                Edit::Delete(i) => {
                    let k = at(i, &t);
                    if k < t.len() {
                        t.remove(k);
                    }
                }
                Edit::Insert(i, w) => {
                    let k = at(i, &t);
                    t.insert_str(k, w);
                }
                Edit::Truncate(i) => {
                    let k = at(i, &t);
                    t.truncate(k);
                }
            }
        }
        t
    }

    fn check(text: &str) -> Result<(), TestCaseError> {
        match Session::parse(text) {
            Err(e) => {
                let shown = e.to_string();
                prop_assert!(
                    !shown.trim().is_empty() && !shown.trim_end().ends_with(':'),
                    "error without a message: {shown:?}"
                );
            }
            Ok(s) => {
                // Notes and comments lose lone carriage returns on writing; the written text
                // itself reads back to the same text.
                let written = s.to_text();
                let again = Session::parse(&written)
                    .map_err(|e| TestCaseError::fail(format!("cannot read it back: {e}")))?;
                prop_assert_eq!(again.to_text(), written);
            }
        }
        Ok(())
    }

    proptest! {
        #![proptest_config(crate::test_support::config())]

        #[test]
        fn arbitrary_text_is_rejected_or_read(text in any::<String>()) {
            check(&text)?;
        }

        #[test]
        fn session_words_are_rejected_or_read(
            words in proptest::collection::vec(select(WORDS.to_vec()), 0..40)
        ) {
            check(&words.concat())?;
        }

        #[test]
        fn an_edited_session_is_rejected_or_read(
            edits in proptest::collection::vec(edit(), 1..4)
        ) {
            check(&apply(tests::EXAMPLE, &edits))?;
        }
    }
}
