//! The simulated Canon RA-532H ("SRA") on a real pseudo-terminal pair. Each
//! [`SimSra::connect`] opens a pair with `serialport::TTYPort::pair()`, hands the slave end to
//! the driver as its serial stream, and serves the master end from a device thread, so every
//! byte crosses the OS tty layer exactly as with a USB-serial adapter.
//!
//! Raw mode matters: a tty in its default ("cooked") mode would turn the protocol's `\r\n` into
//! `\n\n` (ICRNL), echo requests back (ECHO), hold bytes until a line end (ICANON) and eat
//! 0x03/0x11/0x13 (ISIG, IXON). `TTYPort::pair` applies `cfmakeraw` to the slave; [`connect`]
//! reads the termios back and refuses a pair that is not raw ([`termios_is_raw`] says what
//! is checked). On Linux the pty pair has one set of termios flags, the slave's.
//!
//! The device thread is sequential like the instrument: it reads requests, and sends each reply
//! when its (recorded, scaled, or faulted) time comes. A `disconnect` fault closes the master,
//! which the driver sees as a hang-up on its end. The thread ends when the driver closes its
//! end, when a newer connection replaces this one, or when the [`SimSra`] is dropped.
//!
//! Opening pty pairs is cheap but not free, and the pairs share the kernel's pty pool: tests
//! that open them are serialised (see `tests/common`).
//!
//! [`connect`]: SimSra::connect

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::os::fd::AsRawFd;
use std::sync::{Arc, Mutex, MutexGuard, Weak};
use std::time::{Duration, Instant};

use drivers::{Instrument, TransportError};
use serialport::{SerialPort, TTYPort};
use tracing::{debug, warn};

use crate::MockError;
use crate::engine::{Engine, Out, ReplayOptions, ReplayReport};
use crate::script::Script;

/// How long the device thread blocks in one read, so it notices a replaced connection or a
/// dropped instrument promptly, and sends replies on time (1 ms resolution below this).
const POLL: Duration = Duration::from_millis(10);

/// How long a `disconnect` fault that follows a reply waits for the driver to read the reply.
const HANGUP_GRACE: Duration = Duration::from_millis(50);

/// Port name used in errors about the simulated instrument's pty.
const PORT: &str = "simulated SRA (pseudo-terminal)";

#[derive(Debug)]
struct Shared {
    engine: Engine,
    /// Bumped by every connection; the device thread of an older one stops.
    generation: u64,
}

fn lock(shared: &Mutex<Shared>) -> MutexGuard<'_, Shared> {
    shared.lock().unwrap_or_else(|p| p.into_inner())
}

/// A simulated SRA. Cheap to clone; clones are the same instrument.
#[derive(Debug, Clone)]
pub struct SimSra {
    shared: Arc<Mutex<Shared>>,
}

impl SimSra {
    /// An instrument replaying `script` (which must be an SRA script).
    pub fn new(script: Script, options: ReplayOptions) -> Result<SimSra, MockError> {
        if script.instrument() != Instrument::Sra {
            return Err(MockError::NotForThisInstrument {
                script: script.instrument(),
                simulated: Instrument::Sra,
            });
        }
        Ok(SimSra {
            shared: Arc::new(Mutex::new(Shared {
                engine: Engine::new(script, options)?,
                generation: 0,
            })),
        })
    }

    /// Plug in: open a new pty pair, start the device on its master end, and return the slave
    /// end (a `drivers::SerialStream`). An older connection's device thread stops.
    pub fn connect(&self) -> Result<TTYPort, TransportError> {
        let (master, slave) = self.open_pair()?;
        self.start(master, None)?;
        Ok(slave)
    }

    /// Like [`SimSra::connect`], but the driver's end is opened by its device path through
    /// `drivers::sra::serial::open_serial` (9600 8N1), the way brdfd opens a real port.
    pub fn connect_by_name(&self) -> Result<Box<dyn SerialPort>, TransportError> {
        let (master, slave) = self.open_pair()?;
        let name = slave.name().ok_or_else(|| TransportError::SerialOpen {
            port: PORT.into(),
            detail: "the pseudo-terminal has no device path".into(),
        })?;
        let port = drivers::sra::serial::open_serial(&name, drivers::sra::codec::BAUD_RATE)?;
        // The device keeps its own slave descriptor open, so closing the driver's end is not a
        // hang-up; the thread stops on the next connection or when the instrument is dropped.
        self.start(master, Some(slave))?;
        Ok(port)
    }

    /// A transport factory for `drivers::spawn_sra`: each call is a [`SimSra::connect`].
    pub fn factory(&self) -> impl FnMut() -> Result<TTYPort, TransportError> + Send + 'static {
        let sim = self.clone();
        move || sim.connect()
    }

    /// What happened so far.
    pub fn report(&self) -> ReplayReport {
        lock(&self.shared).engine.report()
    }

    /// Lenient replay: answer the next measurement from the recorded session of this sample
    /// (`None`: of the reference tile). See [`Cue`].
    pub fn cue(&self, sample: Option<&str>) -> crate::Cue {
        lock(&self.shared).engine.cue_object(sample)
    }

    /// What the next measurement is answered from: the object of the recorded session that
    /// replays next (after a [`Self::cue`], the one cued), with the session's number.
    pub fn answering(&self) -> Option<(usize, crate::ScriptObject)> {
        let shared = lock(&self.shared);
        let n = shared.engine.answering_session()?;
        Some((n, shared.engine.script().object(n).clone()))
    }

    /// The script being replayed.
    pub fn script(&self) -> Script {
        lock(&self.shared).engine.script().clone()
    }

    fn open_pair(&self) -> Result<(TTYPort, TTYPort), TransportError> {
        if lock(&self.shared).engine.unplugged() {
            return Err(TransportError::SerialOpen {
                port: PORT.into(),
                detail: "No such file or directory (the simulated instrument was unplugged)".into(),
            });
        }
        let (master, slave) = TTYPort::pair().map_err(|e| TransportError::SerialOpen {
            port: PORT.into(),
            detail: format!("cannot open a pseudo-terminal pair: {e}"),
        })?;
        ensure_raw(&slave).map_err(|e| TransportError::SerialOpen {
            port: PORT.into(),
            detail: format!("cannot put the pseudo-terminal in raw mode: {e}"),
        })?;
        Ok((master, slave))
    }

    fn start(&self, master: TTYPort, keep: Option<TTYPort>) -> Result<(), TransportError> {
        let (generation, first) = {
            let mut shared = lock(&self.shared);
            shared.generation += 1;
            (shared.generation, shared.engine.on_connect())
        };
        let weak = Arc::downgrade(&self.shared);
        std::thread::Builder::new()
            .name(format!("sim-sra-{generation}"))
            .spawn(move || {
                let _keep = keep;
                serve(master, weak, generation, first);
            })
            .map(|_| ())
            .map_err(|e| TransportError::SerialOpen {
                port: PORT.into(),
                detail: format!("cannot start the simulated instrument's thread: {e}"),
            })
    }
}

/// Whether the tty behind `fd` is in raw mode, as `cfmakeraw` leaves it: no input
/// translation (IGNBRK BRKINT PARMRK ISTRIP INLCR IGNCR ICRNL IXON off), no output processing
/// (OPOST off), no echo, line editing or signals (ECHO ECHONL ICANON ISIG IEXTEN off), and
/// 8-bit characters without parity (CS8, PARENB off).
pub fn termios_is_raw(fd: &impl AsRawFd) -> io::Result<bool> {
    let t = termios(fd.as_raw_fd())?;
    let input = libc::IGNBRK
        | libc::BRKINT
        | libc::PARMRK
        | libc::ISTRIP
        | libc::INLCR
        | libc::IGNCR
        | libc::ICRNL
        | libc::IXON;
    let local = libc::ECHO | libc::ECHONL | libc::ICANON | libc::ISIG | libc::IEXTEN;
    Ok(t.c_iflag & input == 0
        && t.c_oflag & libc::OPOST == 0
        && t.c_lflag & local == 0
        && t.c_cflag & libc::CSIZE == libc::CS8
        && t.c_cflag & libc::PARENB == 0)
}

fn termios(fd: i32) -> io::Result<libc::termios> {
    // SAFETY: `termios` is plain old data, fully written by a successful tcgetattr; `fd` is an
    // open descriptor owned by the caller for the duration of the call.
    unsafe {
        let mut t: libc::termios = std::mem::zeroed();
        if libc::tcgetattr(fd, &mut t) != 0 {
            return Err(io::Error::last_os_error());
        }
        Ok(t)
    }
}

/// Make sure the pair is raw; `TTYPort::pair` should already have done it.
fn ensure_raw(slave: &TTYPort) -> io::Result<()> {
    if termios_is_raw(slave)? {
        return Ok(());
    }
    warn!("pseudo-terminal not in raw mode after TTYPort::pair; applying cfmakeraw");
    let fd = slave.as_raw_fd();
    let mut t = termios(fd)?;
    // SAFETY: `t` is a valid termios read from `fd`, which is open.
    unsafe {
        libc::cfmakeraw(&mut t);
        if libc::tcsetattr(fd, libc::TCSANOW, &t) != 0 {
            return Err(io::Error::last_os_error());
        }
    }
    if termios_is_raw(slave)? {
        Ok(())
    } else {
        Err(io::Error::other("raw mode did not apply"))
    }
}

enum Pending {
    Bytes { at: Instant, bytes: Vec<u8> },
    Drop { at: Instant },
}

impl Pending {
    fn at(&self) -> Instant {
        match self {
            Pending::Bytes { at, .. } | Pending::Drop { at } => *at,
        }
    }
}

/// The device thread of one connection.
fn serve(mut master: TTYPort, shared: Weak<Mutex<Shared>>, generation: u64, first: Vec<Out>) {
    let mut pending = VecDeque::new();
    let mut busy_until = Instant::now();
    let mut schedule = |pending: &mut VecDeque<Pending>, out: Vec<Out>| {
        let mut t = busy_until.max(Instant::now());
        for o in out {
            match o {
                Out::Send { delay, bytes } => {
                    t += delay;
                    pending.push_back(Pending::Bytes { at: t, bytes });
                }
                Out::Drop { delay, .. } => {
                    t += delay;
                    pending.push_back(Pending::Drop { at: t });
                }
                Out::Cancel => {
                    pending.retain(|p| matches!(p, Pending::Drop { .. }));
                    t = Instant::now();
                }
            }
        }
        busy_until = t;
    };
    schedule(&mut pending, first);
    let mut buf = [0u8; 256];
    // Set when a `disconnect` fault falls due just after a reply: closing the master at once
    // would let the kernel flush that reply from the slave's input queue before the driver reads
    // it, so the master closes when the driver's next bytes arrive (it has read the reply), or
    // after a grace period.
    let mut hangup_at: Option<Instant> = None;
    let mut replied = false;
    loop {
        {
            let Some(shared) = shared.upgrade() else {
                debug!("simulated SRA dropped; device thread stops");
                return;
            };
            if lock(&shared).generation != generation {
                debug!("a newer connection replaced this one; device thread stops");
                return;
            }
        }
        let now = Instant::now();
        if hangup_at.is_some_and(|t| t <= now) {
            debug!("fault: closing the pty master after the grace period");
            return;
        }
        while hangup_at.is_none() && pending.front().is_some_and(|p| p.at() <= now) {
            match pending.pop_front() {
                Some(Pending::Bytes { bytes, .. }) => {
                    // A write blocks only if the driver stopped reading a full pty buffer.
                    let _ = master.set_timeout(Duration::from_secs(1));
                    if let Err(e) = master.write_all(&bytes) {
                        debug!(error = %e, "driver end gone while replying; device thread stops");
                        return;
                    }
                    replied = true;
                }
                Some(Pending::Drop { .. }) if replied => {
                    hangup_at = Some(now + HANGUP_GRACE);
                }
                Some(Pending::Drop { .. }) => {
                    debug!("fault: closing the pty master (the driver sees a hang-up)");
                    return;
                }
                None => {}
            }
        }
        let next = hangup_at.or_else(|| pending.front().map(Pending::at));
        let wait = next
            .map_or(POLL, |t| t.saturating_duration_since(now).min(POLL))
            .max(Duration::from_millis(1));
        let _ = master.set_timeout(wait);
        match master.read(&mut buf) {
            Ok(0) => return,
            Ok(_) if hangup_at.is_some() => {
                debug!("fault: closing the pty master; the driver's request is lost with the link");
                return;
            }
            Ok(n) => {
                replied = false;
                let Some(shared) = shared.upgrade() else {
                    return;
                };
                let out = lock(&shared).engine.on_bytes(&buf[..n]);
                schedule(&mut pending, out);
            }
            Err(e) if e.kind() == io::ErrorKind::TimedOut => {}
            Err(e) => {
                debug!(error = %e, "driver closed its end; device thread stops");
                return;
            }
        }
    }
}
