//! The simulated X-Rite MA-T12: a [`SimMat12`] replays a script, and each
//! [`SimMat12::connect`] opens a [`SimUsb`] connection implementing the drivers' USB bulk
//! transport trait ([`UsbBulk`]), so `drivers::spawn_mat12` drives it exactly as it drives
//! `RusbBulk`.
//!
//! Like a real full-speed bulk pipe, a device frame comes back in reads of at most 64 bytes and
//! a read never returns bytes of two frames (a short packet ends a transfer). The device is
//! sequential: a request that arrives while replies are still pending is answered after them.
//! A link dropped by a fault fails every later read and write with the error rusb gives for a
//! vanished device; once the instrument is unplugged (a code-chosen fault), `connect` fails with
//! the real transport's "not found" error.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use drivers::mat12::usb::XRITE_VENDOR_ID;
use drivers::{Instrument, TransportError, UsbBulk};

use crate::MockError;
use crate::engine::{Engine, Out, ReplayOptions, ReplayReport};
use crate::script::Script;

/// The message rusb gives for `LIBUSB_ERROR_NO_DEVICE`, as the real transport reports it.
const NO_DEVICE: &str = "USB: No such device (it may have been disconnected)";

/// Full-speed bulk packet size (PROTOCOL.md §2).
const PACKET: usize = drivers::transport::PACKET_SIZE;

#[derive(Debug)]
struct Shared {
    engine: Engine,
    /// Bumped by every connection; an older connection is dead.
    generation: u64,
}

/// A simulated MA-T12. Cheap to clone; clones are the same instrument.
#[derive(Debug, Clone)]
pub struct SimMat12 {
    shared: Arc<Mutex<Shared>>,
}

impl SimMat12 {
    /// An instrument replaying `script` (which must be an MA-T12 script).
    pub fn new(script: Script, options: ReplayOptions) -> Result<SimMat12, MockError> {
        if script.instrument() != Instrument::MaT12 {
            return Err(MockError::NotForThisInstrument {
                script: script.instrument(),
                simulated: Instrument::MaT12,
            });
        }
        Ok(SimMat12 {
            shared: Arc::new(Mutex::new(Shared {
                engine: Engine::new(script, options)?,
                generation: 0,
            })),
        })
    }

    fn lock(&self) -> MutexGuard<'_, Shared> {
        // The state is plain data; a panic elsewhere cannot leave it half-updated in a way that
        // matters more than the panic itself.
        self.shared.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Plug in: open a new USB connection (a new handle after a re-enumeration). Any older
    /// connection is dead from now on.
    pub fn connect(&self) -> Result<SimUsb, TransportError> {
        let mut shared = self.lock();
        if shared.engine.unplugged() {
            return Err(TransportError::UsbNotFound {
                vendor_id: XRITE_VENDOR_ID,
                product_id: None,
                detail: None,
            });
        }
        shared.generation += 1;
        let generation = shared.generation;
        let out = shared.engine.on_connect();
        drop(shared);
        let mut conn = SimUsb {
            shared: self.shared.clone(),
            generation,
            outbox: VecDeque::new(),
            busy_until: Instant::now(),
            dead: None,
        };
        conn.schedule(out);
        Ok(conn)
    }

    /// A transport factory for `drivers::spawn_mat12`: each call is a [`SimMat12::connect`].
    pub fn factory(&self) -> impl FnMut() -> Result<SimUsb, TransportError> + Send + 'static {
        let sim = self.clone();
        move || sim.connect()
    }

    /// What happened so far.
    pub fn report(&self) -> ReplayReport {
        self.lock().engine.report()
    }

    /// Lenient replay: answer the next measurement from the recorded session of this sample
    /// (`None`: of the reference tile). See [`Cue`].
    pub fn cue(&self, sample: Option<&str>) -> crate::Cue {
        self.lock().engine.cue_object(sample)
    }

    /// What the next measurement is answered from: the object of the recorded session that
    /// replays next (after a [`Self::cue`], the one cued), with the session's number.
    pub fn answering(&self) -> Option<(usize, crate::ScriptObject)> {
        let shared = self.lock();
        let n = shared.engine.answering_session()?;
        Some((n, shared.engine.script().object(n).clone()))
    }

    /// The script being replayed.
    pub fn script(&self) -> Script {
        self.lock().engine.script().clone()
    }
}

#[derive(Debug)]
enum Pending {
    Bytes { at: Instant, bytes: Vec<u8> },
    Drop { at: Instant },
}

/// One open USB connection to a [`SimMat12`].
#[derive(Debug)]
pub struct SimUsb {
    shared: Arc<Mutex<Shared>>,
    generation: u64,
    outbox: VecDeque<Pending>,
    /// When the device has sent everything already scheduled.
    busy_until: Instant,
    /// Why the link is gone, once it is.
    dead: Option<String>,
}

impl SimUsb {
    fn schedule(&mut self, out: Vec<Out>) {
        let mut t = self.busy_until.max(Instant::now());
        for o in out {
            match o {
                Out::Send { delay, bytes } => {
                    t += delay;
                    self.outbox.push_back(Pending::Bytes { at: t, bytes });
                }
                Out::Drop { delay, .. } => {
                    t += delay;
                    self.outbox.push_back(Pending::Drop { at: t });
                }
                Out::Cancel => {
                    self.outbox.retain(|p| matches!(p, Pending::Drop { .. }));
                    t = Instant::now();
                }
            }
        }
        self.busy_until = t;
    }

    /// The link state now: a drop whose time has come, or a newer connection, kills it.
    fn alive(&mut self) -> Result<(), TransportError> {
        if self.dead.is_none() {
            let current = self
                .shared
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .generation;
            if current != self.generation {
                self.dead = Some(NO_DEVICE.into());
            } else if let Some(Pending::Drop { at }) = self.outbox.front()
                && *at <= Instant::now()
            {
                self.outbox.clear();
                self.dead = Some(NO_DEVICE.into());
            }
        }
        match &self.dead {
            Some(detail) => Err(TransportError::Disconnected {
                detail: detail.clone(),
            }),
            None => Ok(()),
        }
    }
}

impl UsbBulk for SimUsb {
    fn write_bulk(&mut self, data: &[u8], _timeout: Duration) -> Result<usize, TransportError> {
        self.alive()?;
        let out = self
            .shared
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .engine
            .on_bytes(data);
        self.schedule(out);
        Ok(data.len())
    }

    fn read_bulk(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, TransportError> {
        let deadline = Instant::now() + timeout;
        loop {
            self.alive()?;
            let now = Instant::now();
            let at = match self.outbox.front() {
                Some(Pending::Bytes { at, .. } | Pending::Drop { at }) => Some(*at),
                None => None,
            };
            match at {
                Some(at) if at <= now => {
                    let Some(Pending::Bytes { bytes, .. }) = self.outbox.front_mut() else {
                        continue; // a drop that is due: `alive` reports it
                    };
                    let n = bytes.len().min(buf.len()).min(PACKET);
                    buf[..n].copy_from_slice(&bytes[..n]);
                    bytes.drain(..n);
                    if bytes.is_empty() {
                        self.outbox.pop_front();
                    }
                    return Ok(n);
                }
                _ => {
                    let wake = at.map_or(deadline, |a| a.min(deadline));
                    if now >= deadline {
                        return Err(TransportError::Timeout { timeout });
                    }
                    std::thread::sleep(wake.saturating_duration_since(now));
                    if Instant::now() >= deadline && at.is_none_or(|a| a > deadline) {
                        return Err(TransportError::Timeout { timeout });
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use drivers::protocol::Request;
    use drivers::session::Fault;

    /// The MA-T12 golden frames of PROTOCOL.md as a session: IDENTIFY, then FETCH 15as-45 with
    /// the 256-byte ramp reading.
    fn session() -> String {
        let reading = "4d5485f90001000000000000d03f000000000000d13f000000000000d23f000000000000d33f000000000000d43f000000000000d53f000000000000d63f000000000000d73f000000000000d83f000000000000d93f000000000000da3f000000000000db3f000000000000dc3f000000000000dd3f000000000000de3f000000000000df3f000000000000e03f000000000080e03f000000000000e13f000000000080e13f000000000000e23f000000000080e23f000000000000e33f000000000080e33f000000000000e43f000000000080e43f000000000000e53f000000000080e53f000000000000e63f000000000080e63f000000000000e73fcb6e";
        format!(
            "brdfd-session 1\ndevice ma_t12\nnote golden\n\
             0 > 4d54010000e4a9\n\
             2 < 4d54811b00064d412d54313209534e2d30303031323309465720322e312e30347beb\n\
             3 > 4d5405010001232d\n\
             6 < {reading}\n"
        )
    }

    fn sim(faults: &[Fault]) -> SimMat12 {
        let mut script = Script::parse(&session()).unwrap();
        for f in faults {
            script.add_fault(f.clone()).unwrap();
        }
        SimMat12::new(script, ReplayOptions::strict().accelerated()).unwrap()
    }

    fn request(r: Request) -> Vec<u8> {
        crate::wire::encode_request(Instrument::MaT12, &r).unwrap()
    }

    fn read_all(usb: &mut SimUsb) -> (Vec<usize>, Vec<u8>) {
        let mut sizes = Vec::new();
        let mut all = Vec::new();
        let mut buf = [0u8; 64];
        while let Ok(n) = usb.read_bulk(&mut buf, Duration::from_millis(20)) {
            sizes.push(n);
            all.extend_from_slice(&buf[..n]);
        }
        (sizes, all)
    }

    #[test]
    fn replies_come_in_64_byte_packets_frame_by_frame() {
        let sim = sim(&[]);
        let mut usb = sim.connect().unwrap();
        usb.write_bulk(&request(Request::Identify), Duration::from_millis(5))
            .unwrap();
        let (sizes, _) = read_all(&mut usb);
        assert_eq!(sizes, vec![34]);
        usb.write_bulk(
            &request(Request::Fetch {
                geometry: "15as-45",
            }),
            Duration::from_millis(5),
        )
        .unwrap();
        let (sizes, bytes) = read_all(&mut usb);
        assert_eq!(sizes, vec![64, 64, 64, 64]);
        assert_eq!(
            bytes,
            Script::parse(&session()).unwrap().exchanges()[1].replies[0].bytes
        );
        assert!(sim.report().mismatches.is_empty());
    }

    #[test]
    fn a_dropped_link_says_no_device_and_a_new_connection_works() {
        let sim = sim(&[Fault::Disconnect { after: 1 }]);
        let mut usb = sim.connect().unwrap();
        usb.write_bulk(&request(Request::Identify), Duration::from_millis(5))
            .unwrap();
        let mut buf = [0u8; 64];
        assert_eq!(usb.read_bulk(&mut buf, Duration::from_millis(5)), Ok(34));
        let err = usb
            .read_bulk(&mut buf, Duration::from_millis(5))
            .unwrap_err();
        assert_eq!(
            err,
            TransportError::Disconnected {
                detail: NO_DEVICE.into()
            }
        );
        assert!(usb.write_bulk(&[0], Duration::from_millis(5)).is_err());
        let mut again = sim.connect().unwrap();
        again
            .write_bulk(&request(Request::Identify), Duration::from_millis(5))
            .unwrap();
        assert_eq!(again.read_bulk(&mut buf, Duration::from_millis(5)), Ok(34));
    }

    #[test]
    fn unplugged_means_not_found() {
        let script = Script::parse(&session()).unwrap();
        let options = ReplayOptions {
            unplug_after: Some(0),
            ..ReplayOptions::strict().accelerated()
        };
        let sim = SimMat12::new(script, options).unwrap();
        let mut usb = sim.connect().unwrap();
        usb.write_bulk(&request(Request::Identify), Duration::from_millis(5))
            .unwrap();
        let mut buf = [0u8; 64];
        assert!(matches!(
            usb.read_bulk(&mut buf, Duration::from_millis(5)),
            Err(TransportError::Disconnected { .. })
        ));
        let err = sim.connect().unwrap_err();
        assert!(
            err.to_string().starts_with("MA-T12 not found on USB"),
            "{err}"
        );
    }

    #[test]
    fn a_sra_script_is_refused() {
        let sra = "brdfd-session 1\ndevice sra\n0 > 2449442a323938450d0a\n";
        let err = SimMat12::new(Script::parse(sra).unwrap(), ReplayOptions::strict()).unwrap_err();
        assert!(err.to_string().contains("simulated X-Rite MA-T12"), "{err}");
    }

    #[test]
    fn reads_wait_for_recorded_timing() {
        let script = Script::parse(&session()).unwrap();
        let sim = SimMat12::new(script, ReplayOptions::strict()).unwrap();
        let mut usb = sim.connect().unwrap();
        let start = Instant::now();
        usb.write_bulk(&request(Request::Identify), Duration::from_millis(5))
            .unwrap();
        let mut buf = [0u8; 64];
        // Recorded: the IDENTITY came 2 ms after the request.
        assert_eq!(usb.read_bulk(&mut buf, Duration::from_millis(500)), Ok(34));
        assert!(start.elapsed() >= Duration::from_millis(2));
        // Nothing more: a read times out after its timeout.
        let t = Instant::now();
        assert!(matches!(
            usb.read_bulk(&mut buf, Duration::from_millis(30)),
            Err(TransportError::Timeout { .. })
        ));
        assert!(t.elapsed() >= Duration::from_millis(30));
    }
}
