//! Driver tests against small in-test fake instruments: a fake device that answers with the
//! codec (the golden formats of PROTOCOL.md), behind a fake USB transport and a fake serial
//! stream, with scripted faults. Every test runs under a timeout, so a hang fails it.

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use bytes::BytesMut;

use super::*;
use crate::protocol::{DeviceState, ReadingValue, Request, Response};
use crate::transport::{SerialStream, UsbBulk};

/// What a fault does when it fires.
#[derive(Debug, Clone)]
enum Act {
    /// Flip one bit in the reply (in its payload, so the CRC no longer matches).
    Corrupt,
    /// Send no reply.
    Drop,
    /// Answer ERROR BUSY instead.
    Busy,
    /// Send these bytes before the reply.
    Garbage(Vec<u8>),
    /// Send the previous reply again before this one (a late duplicate).
    DuplicatePrevious,
    /// Drop the connection instead of answering.
    Disconnect,
    /// Hold the reply back this long.
    Delay(Duration),
    /// Answer with this error code.
    Refuse(ErrorCode),
    /// Answer with these bytes instead of the reply.
    Replace(Vec<u8>),
}

#[derive(Debug, Clone)]
struct Fault {
    kind: RequestKind,
    geometry: Option<&'static str>,
    act: Act,
    times: u32,
}

fn fault(kind: RequestKind, geometry: Option<&'static str>, act: Act, times: u32) -> Fault {
    Fault {
        kind,
        geometry,
        act,
        times,
    }
}

/// A simulated instrument that answers through codec `C`. Shared between connections (it
/// survives a reconnection, as a USB re-enumeration without power loss would).
struct Device<C: Codec> {
    readings: Vec<Reading>,
    measured: bool,
    faults: Vec<Fault>,
    /// Requests decoded, in order.
    seen: Vec<Request>,
    /// Bytes from the host not yet decoded.
    inbox: BytesMut,
    /// Bytes for the host, each run available from its instant.
    outbox: VecDeque<(Instant, Vec<u8>)>,
    last_reply: Option<Vec<u8>>,
    /// Every reply frame put on the wire, with the request it answered (after any fault
    /// altered it; garbage and duplicates not included).
    sent: Vec<(Request, Vec<u8>)>,
    /// Connection generation: a transport whose generation is older is dead.
    generation: u32,
    /// Connections the factory should refuse from now on.
    refuse_connections: u32,
    connections: u32,
    _codec: PhantomData<C>,
}

type Shared<C> = Arc<Mutex<Device<C>>>;

fn spectrum(seed: usize) -> [f64; protocol::BANDS] {
    // Arbitrary, non-round values so a bit-for-bit comparison means something.
    std::array::from_fn(|i| 0.05 + 0.9 * ((seed * 31 + i) as f64 * 0.618_033_988_749).fract())
}

impl<C: Codec> Device<C> {
    fn new() -> Shared<C> {
        let readings = C::INSTRUMENT
            .geometries()
            .iter()
            .enumerate()
            .map(|(k, &geometry)| Reading {
                geometry,
                value: match C::INSTRUMENT {
                    Instrument::MaT12 => ReadingValue::Reflectance(spectrum(k)),
                    Instrument::Sra => ReadingValue::Intensity(1.0 / 3.0 + k as f64 * 7.1),
                },
            })
            .collect();
        Arc::new(Mutex::new(Device {
            readings,
            measured: false,
            faults: Vec::new(),
            seen: Vec::new(),
            inbox: BytesMut::new(),
            outbox: VecDeque::new(),
            last_reply: None,
            sent: Vec::new(),
            generation: 0,
            refuse_connections: 0,
            connections: 0,
            _codec: PhantomData,
        }))
    }

    fn reading(&self, geometry: &str) -> Reading {
        *self
            .readings
            .iter()
            .find(|r| r.geometry == geometry)
            .expect("known geometry")
    }

    fn answer(&mut self, request: &Request) -> Response {
        match *request {
            Request::Identify => Response::Identity(Identity {
                model: format!("fake {}", C::INSTRUMENT.key()),
                serial: "T-1".into(),
                firmware: "0".into(),
            }),
            Request::Status => Response::Status(Status {
                state: DeviceState::Ready,
                battery_percent: 90,
            }),
            Request::Calibrate => Response::Calibrated,
            Request::MeasureAll => {
                self.measured = true;
                Response::Measured {
                    count: self.readings.len() as u8,
                }
            }
            Request::Fetch { geometry } if self.measured => {
                Response::Fetched(self.reading(geometry))
            }
            Request::Fetch { geometry } => Response::Error {
                request: RequestKind::Fetch,
                code: ErrorCode::NoMeasurement,
                geometry: Some(geometry),
            },
            Request::MeasureOne { geometry } => Response::MeasuredOne(self.reading(geometry)),
            Request::Abort => {
                // A real instrument stops measuring: replies still held back are never sent.
                self.measured = false;
                self.outbox.clear();
                Response::Aborted
            }
        }
    }

    /// Take host bytes; queue replies. Returns false if the connection must drop.
    fn receive(&mut self, bytes: &[u8]) -> bool {
        self.inbox.extend_from_slice(bytes);
        loop {
            let request = match C::decode_request(&mut self.inbox) {
                Ok(Some(r)) => r,
                Ok(None) => return true,
                Err(_) => continue,
            };
            self.seen.push(request);
            let mut reply = C::encode_response(&self.answer(&request)).unwrap();
            let mut at = Instant::now();
            let fired = self.faults.iter_mut().find(|f| {
                f.times > 0
                    && f.kind == request.kind()
                    && (f.geometry.is_none() || f.geometry == request.geometry())
            });
            if let Some(f) = fired {
                f.times -= 1;
                match f.act.clone() {
                    Act::Corrupt => {
                        let i = reply.len() / 2;
                        reply[i] ^= 0x04;
                    }
                    Act::Drop => continue,
                    Act::Busy => {
                        reply = C::encode_response(&Response::Error {
                            request: request.kind(),
                            code: ErrorCode::Busy,
                            geometry: None,
                        })
                        .unwrap()
                    }
                    Act::Refuse(code) => {
                        reply = C::encode_response(&Response::Error {
                            request: request.kind(),
                            code,
                            geometry: request.geometry(),
                        })
                        .unwrap()
                    }
                    Act::Garbage(g) => self.outbox.push_back((at, g)),
                    Act::DuplicatePrevious => {
                        if let Some(prev) = self.last_reply.clone() {
                            self.outbox.push_back((at, prev));
                        }
                    }
                    Act::Disconnect => {
                        self.generation += 1;
                        self.outbox.clear();
                        self.inbox.clear();
                        return false;
                    }
                    Act::Delay(d) => at += d,
                    Act::Replace(bytes) => reply = bytes,
                }
            }
            self.last_reply = Some(reply.clone());
            self.sent.push((request, reply.clone()));
            self.outbox.push_back((at, reply));
        }
    }

    /// Up to `max` bytes that are due now.
    fn take(&mut self, max: usize) -> Vec<u8> {
        let Some((at, _)) = self.outbox.front() else {
            return Vec::new();
        };
        if *at > Instant::now() {
            return Vec::new();
        }
        let (at, mut bytes) = self.outbox.pop_front().unwrap();
        if bytes.len() > max {
            let rest = bytes.split_off(max);
            self.outbox.push_front((at, rest));
        }
        bytes
    }
}

/// One connection to a fake device.
struct Conn<C: Codec> {
    device: Shared<C>,
    generation: u32,
    timeout: Duration,
}

fn connect<C: Codec>(device: &Shared<C>) -> Result<Conn<C>, TransportError> {
    let mut d = device.lock().unwrap();
    if d.refuse_connections > 0 {
        d.refuse_connections -= 1;
        return Err(TransportError::UsbNotFound {
            vendor_id: 0x0765,
            product_id: None,
            detail: None,
        });
    }
    d.connections += 1;
    d.outbox.clear();
    d.inbox.clear();
    Ok(Conn {
        device: device.clone(),
        generation: d.generation,
        timeout: Duration::from_millis(10),
    })
}

impl<C: Codec> Conn<C> {
    fn alive(&self, d: &Device<C>) -> Result<(), TransportError> {
        if d.generation == self.generation {
            Ok(())
        } else {
            Err(TransportError::Disconnected {
                detail: "fake device unplugged".into(),
            })
        }
    }

    fn write(&mut self, data: &[u8]) -> Result<usize, TransportError> {
        let mut d = self.device.lock().unwrap();
        self.alive(&d)?;
        if !d.receive(data) {
            return Err(TransportError::Disconnected {
                detail: "fake device unplugged".into(),
            });
        }
        Ok(data.len())
    }

    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, TransportError> {
        let end = Instant::now() + timeout;
        loop {
            {
                let mut d = self.device.lock().unwrap();
                self.alive(&d)?;
                let bytes = d.take(buf.len());
                if !bytes.is_empty() {
                    buf[..bytes.len()].copy_from_slice(&bytes);
                    return Ok(bytes.len());
                }
            }
            if Instant::now() >= end {
                return Err(TransportError::Timeout { timeout });
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }
}

impl UsbBulk for Conn<Mat12Codec> {
    fn write_bulk(&mut self, data: &[u8], _: Duration) -> Result<usize, TransportError> {
        assert!(data.len() <= 64, "USB transfers are at most 64 bytes");
        self.write(data)
    }
    fn read_bulk(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, TransportError> {
        self.read(buf, timeout)
    }
}

impl Read for Conn<SraCodec> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        // Serial reads come in small, arbitrary pieces: at most 5 bytes here.
        let n = buf.len().min(5);
        let timeout = self.timeout;
        Conn::read(self, &mut buf[..n], timeout).map_err(|e| match e {
            TransportError::Timeout { .. } => io::Error::new(io::ErrorKind::TimedOut, "timeout"),
            other => io::Error::new(io::ErrorKind::BrokenPipe, other.to_string()),
        })
    }
}

impl Write for Conn<SraCodec> {
    fn write(&mut self, data: &[u8]) -> io::Result<usize> {
        Conn::write(self, data)
            .map_err(|e| io::Error::new(io::ErrorKind::BrokenPipe, e.to_string()))
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

impl SerialStream for Conn<SraCodec> {
    fn set_timeout(&mut self, timeout: Duration) -> Result<(), TransportError> {
        self.timeout = timeout;
        Ok(())
    }
}

/// Short waits, but not so short that a loaded machine misses a reply that is on its way: the
/// tests count resends exactly, so a reply that comes must come within the timeout (the device
/// here answers at once; 500 ms is hundreds of times its reply time), and only a dropped reply
/// may ever wait the timeout out.
fn fast() -> DriverConfig {
    DriverConfig {
        reply_timeout: Duration::from_millis(500),
        measure_timeout: Duration::from_millis(1000),
        busy_wait: Duration::from_millis(5),
        backoff_initial: Duration::from_millis(5),
        backoff_max: Duration::from_millis(20),
        ..DriverConfig::default()
    }
}

fn mat12(device: &Shared<Mat12Codec>) -> DriverHandle {
    let d = device.clone();
    spawn_mat12(move || connect(&d), fast())
}

fn mat12_with(device: &Shared<Mat12Codec>, config: DriverConfig) -> DriverHandle {
    let d = device.clone();
    spawn_mat12(move || connect(&d), config)
}

fn sra(device: &Shared<SraCodec>) -> DriverHandle {
    let d = device.clone();
    spawn_sra(move || connect(&d), fast())
}

/// Every test body runs under this limit: a hang is a failure, not a stuck CI.
async fn within<T>(f: impl std::future::Future<Output = T>) -> T {
    tokio::time::timeout(Duration::from_secs(10), f)
        .await
        .expect("test hung")
}

fn drain(rx: &mut broadcast::Receiver<Event>) -> Vec<Event> {
    let mut out = Vec::new();
    while let Ok(e) = rx.try_recv() {
        out.push(e);
    }
    out
}

fn fetches<C: Codec>(device: &Shared<C>, geometry: &str) -> usize {
    let d = device.lock().unwrap();
    d.seen
        .iter()
        .filter(|r| matches!(r, Request::Fetch { geometry: g } if *g == geometry))
        .count()
}

fn assert_bit_equal(got: &[Reading], want: &[Reading]) {
    assert_eq!(got.len(), want.len());
    for (g, w) in got.iter().zip(want) {
        assert!(g.bit_eq(w), "{g} differs from {w}");
    }
}

/// The readings without their frames.
fn values(received: &[ReceivedReading]) -> Vec<Reading> {
    received.iter().map(|r| r.reading).collect()
}

/// The last reply frame the fake device sent to `request`.
fn last_reply_to<C: Codec>(device: &Shared<C>, request: Request) -> Vec<u8> {
    let d = device.lock().unwrap();
    d.sent
        .iter()
        .rev()
        .find(|(r, _)| *r == request)
        .map(|(_, bytes)| bytes.clone())
        .unwrap_or_else(|| panic!("the device never answered {request}"))
}

/// Each reading's frame is, byte for byte, the last reply the device sent to its FETCH.
fn assert_fetched_frames_as_sent<C: Codec>(device: &Shared<C>, received: &[ReceivedReading]) {
    for r in received {
        let geometry = r.reading.geometry;
        assert_eq!(
            r.raw,
            last_reply_to(device, Request::Fetch { geometry }),
            "{geometry}: the frame as the device sent it"
        );
    }
}

#[tokio::test]
async fn mat12_measures_all_twelve_bit_for_bit_with_events() {
    within(async {
        let device = Device::<Mat12Codec>::new();
        let handle = mat12(&device);
        let mut events = handle.subscribe();
        let received = handle.measure_all_received().await.unwrap();
        let readings = values(&received);
        assert_bit_equal(&readings, &device.lock().unwrap().readings);
        assert_fetched_frames_as_sent(&device, &received);
        // 256-byte frames (four 64-byte USB packets), each reassembled exactly.
        assert!(received.iter().all(|r| r.raw.len() == 256));
        let names: Vec<_> = readings.iter().map(|r| r.geometry).collect();
        assert_eq!(names, crate::protocol::MAT12_GEOMETRIES);
        let events = drain(&mut events);
        let measuring: Vec<_> = events
            .iter()
            .filter_map(|e| match e {
                Event::Measuring { k, n, geometry, .. } => Some((*k, *n, *geometry)),
                _ => None,
            })
            .collect();
        assert_eq!(measuring.len(), 12);
        assert_eq!(measuring[0], (1, 12, "15as-45"));
        assert_eq!(measuring[11], (12, 12, "45as110"));
        // The events carry the same readings with the same frames, in order.
        let read: Vec<&ReceivedReading> = events
            .iter()
            .filter_map(|e| match e {
                Event::Reading { reading, .. } => Some(reading),
                _ => None,
            })
            .collect();
        assert_eq!(read, received.iter().collect::<Vec<_>>());
        // First connection was made at spawn, with IDENTIFY first on the wire.
        assert_eq!(device.lock().unwrap().seen[0], Request::Identify);
        handle.shutdown().await;
    })
    .await
}

#[tokio::test]
async fn sra_measures_both_geometries_through_a_chunked_stream() {
    within(async {
        let device = Device::<SraCodec>::new();
        let handle = sra(&device);
        let received = handle.measure_all_received().await.unwrap();
        assert_bit_equal(&values(&received), &device.lock().unwrap().readings);
        // Lines that came in 5-byte pieces are handed back whole, `!` to `\r\n`.
        assert_fetched_frames_as_sent(&device, &received);
        assert!(received.iter().all(|r| r.raw.ends_with(b"\r\n")));
        let one = handle.measure_one_received("sra-60").await.unwrap();
        assert!(one.reading.bit_eq(&device.lock().unwrap().readings[1]));
        assert_eq!(
            one.raw,
            last_reply_to(&device, Request::MeasureOne { geometry: "sra-60" })
        );
        let values_only = handle.measure_one("sra-20").await.unwrap();
        assert!(values_only.bit_eq(&device.lock().unwrap().readings[0]));
        assert_eq!(handle.status().await.unwrap().state, DeviceState::Ready);
        handle.calibrate().await.unwrap();
        assert_eq!(handle.identify().await.unwrap().model, "fake sra");
    })
    .await
}

#[tokio::test]
async fn a_corrupted_reading_is_refetched_and_then_used() {
    within(async {
        let device = Device::<Mat12Codec>::new();
        device.lock().unwrap().faults.push(fault(
            RequestKind::Fetch,
            Some("45as25"),
            Act::Corrupt,
            2,
        ));
        let handle = mat12(&device);
        let received = handle.measure_all_received().await.unwrap();
        assert_bit_equal(&values(&received), &device.lock().unwrap().readings);
        assert_eq!(
            fetches(&device, "45as25"),
            3,
            "two corrupted replies, one good"
        );
        // The frame kept is the good third reply, not one of the corrupted ones.
        assert_fetched_frames_as_sent(&device, &received);
        let fetch = Request::Fetch { geometry: "45as25" };
        let replies: Vec<Vec<u8>> = device
            .lock()
            .unwrap()
            .sent
            .iter()
            .filter(|(r, _)| *r == fetch)
            .map(|(_, b)| b.clone())
            .collect();
        assert_eq!(replies.len(), 3);
        assert_ne!(replies[0], replies[2]);
        assert_eq!(fetches(&device, "45as15"), 1);
    })
    .await
}

#[tokio::test]
async fn persistent_corruption_fails_cleanly_naming_instrument_and_geometry() {
    within(async {
        let device = Device::<SraCodec>::new();
        device.lock().unwrap().faults.push(fault(
            RequestKind::Fetch,
            Some("sra-60"),
            Act::Corrupt,
            u32::MAX,
        ));
        let handle = sra(&device);
        let mut events = handle.subscribe();
        let err = handle.measure_all().await.unwrap_err();
        assert!(matches!(
            err,
            DriverError::NoValidReply {
                geometry: Some("sra-60"),
                sends: 4,
                ..
            }
        ));
        let msg = err.to_string();
        assert!(msg.contains("Canon RA-532H"), "{msg}");
        assert!(msg.contains("sra-60"), "{msg}");
        assert!(msg.contains("checksum"), "{msg}");
        assert_eq!(fetches(&device, "sra-60"), 4, "1 send + max_resends 3");
        assert!(
            drain(&mut events)
                .iter()
                .any(|e| matches!(e, Event::Error { .. }))
        );
        // The driver is still usable.
        device.lock().unwrap().faults.clear();
        assert_eq!(handle.measure_all().await.unwrap().len(), 2);
    })
    .await
}

#[tokio::test]
async fn a_lost_reply_times_out_and_is_requested_again() {
    within(async {
        let device = Device::<Mat12Codec>::new();
        device
            .lock()
            .unwrap()
            .faults
            .push(fault(RequestKind::Fetch, Some("15as15"), Act::Drop, 1));
        let handle = mat12(&device);
        let started = Instant::now();
        let readings = handle.measure_all().await.unwrap();
        assert_bit_equal(&readings, &device.lock().unwrap().readings);
        assert_eq!(fetches(&device, "15as15"), 2);
        assert!(
            started.elapsed() >= fast().reply_timeout,
            "waited for the reply timeout"
        );
    })
    .await
}

#[tokio::test]
async fn no_reply_at_all_fails_with_the_request_named() {
    within(async {
        let device = Device::<Mat12Codec>::new();
        let handle = mat12(&device);
        handle.identify().await.unwrap();
        device
            .lock()
            .unwrap()
            .faults
            .push(fault(RequestKind::Status, None, Act::Drop, u32::MAX));
        let err = handle.status().await.unwrap_err();
        assert!(matches!(
            err,
            DriverError::NoValidReply {
                request: RequestKind::Status,
                ..
            }
        ));
        assert!(err.to_string().contains("no reply within 500 ms"), "{err}");
    })
    .await
}

#[tokio::test]
async fn busy_is_waited_out() {
    within(async {
        let device = Device::<SraCodec>::new();
        device
            .lock()
            .unwrap()
            .faults
            .push(fault(RequestKind::MeasureAll, None, Act::Busy, 2));
        let handle = sra(&device);
        assert_eq!(handle.measure_all().await.unwrap().len(), 2);
        let seen = &device.lock().unwrap().seen;
        assert_eq!(
            seen.iter().filter(|r| **r == Request::MeasureAll).count(),
            3
        );
    })
    .await
}

#[tokio::test]
async fn a_refusal_is_reported_with_advice() {
    within(async {
        let device = Device::<Mat12Codec>::new();
        device.lock().unwrap().faults.push(fault(
            RequestKind::MeasureAll,
            None,
            Act::Refuse(ErrorCode::NotCalibrated),
            1,
        ));
        let handle = mat12(&device);
        let err = handle.measure_all().await.unwrap_err();
        assert_eq!(
            err,
            DriverError::Refused {
                instrument: Instrument::MaT12,
                request: RequestKind::MeasureAll,
                geometry: None,
                code: ErrorCode::NotCalibrated
            }
        );
        assert!(
            err.to_string().contains("calibrate the instrument"),
            "{err}"
        );
        // A refusal about one geometry names it.
        let fresh = Device::<Mat12Codec>::new();
        fresh.lock().unwrap().faults.push(fault(
            RequestKind::Fetch,
            Some("15as-45"),
            Act::Refuse(ErrorCode::NoMeasurement),
            1,
        ));
        let h2 = mat12(&fresh);
        let err = h2.measure_all().await.unwrap_err();
        assert!(matches!(
            err,
            DriverError::Refused {
                code: ErrorCode::NoMeasurement,
                geometry: Some("15as-45"),
                ..
            }
        ));
    })
    .await
}

#[tokio::test]
async fn garbage_and_stale_duplicates_are_dropped_without_a_resend() {
    within(async {
        let device = Device::<SraCodec>::new();
        {
            let mut d = device.lock().unwrap();
            d.faults.push(fault(
                RequestKind::Fetch,
                Some("sra-20"),
                Act::Garbage(b"\x00\xff!!RD,6".to_vec()),
                1,
            ));
            d.faults.push(fault(
                RequestKind::Fetch,
                Some("sra-60"),
                Act::DuplicatePrevious,
                1,
            ));
        }
        let handle = sra(&device);
        let received = handle.measure_all_received().await.unwrap();
        assert_bit_equal(&values(&received), &device.lock().unwrap().readings);
        // The garbage before the reading is not part of its frame.
        assert_fetched_frames_as_sent(&device, &received);
        assert_eq!(fetches(&device, "sra-20"), 1);
        assert_eq!(
            fetches(&device, "sra-60"),
            1,
            "the duplicate sra-20 reading was not taken"
        );
    })
    .await
}

#[tokio::test]
async fn garbage_that_looks_like_a_broken_frame_costs_no_resend() {
    // PROTOCOL.md §4: bytes that never form a frame are dropped and the reply that follows
    // them is used. Here: an MA-T12 header with an impossible length, and SRA noise holding a
    // start character and a line end but no `*XXXX` tail.
    within(async {
        let device = Device::<Mat12Codec>::new();
        device.lock().unwrap().faults.push(fault(
            RequestKind::Fetch,
            Some("15as15"),
            Act::Garbage(vec![0x4D, 0x54, 0xFF, 0xFF, 0xFF, 0x00, 0x4D]),
            1,
        ));
        let handle = mat12(&device);
        let received = handle.measure_all_received().await.unwrap();
        assert_bit_equal(&values(&received), &device.lock().unwrap().readings);
        assert_fetched_frames_as_sent(&device, &received);
        assert_eq!(fetches(&device, "15as15"), 1, "no resend");

        let device = Device::<SraCodec>::new();
        device.lock().unwrap().faults.push(fault(
            RequestKind::Fetch,
            Some("sra-20"),
            Act::Garbage(b"!\r\n!$\x00\r\n!RD,20,3.1F721\r\n".to_vec()),
            1,
        ));
        let handle = sra(&device);
        let received = handle.measure_all_received().await.unwrap();
        assert_bit_equal(&values(&received), &device.lock().unwrap().readings);
        assert_fetched_frames_as_sent(&device, &received);
        assert_eq!(fetches(&device, "sra-20"), 1, "no resend");
    })
    .await
}

#[tokio::test]
async fn the_frame_kept_is_the_one_received_not_a_re_encoding() {
    // `3.10` is a valid SRA intensity that brdfd's codec would write `3.1`: only a frame kept
    // as received can hold it.
    within(async {
        let device = Device::<SraCodec>::new();
        let sent = crate::sra::codec::line(b'!', "RD,20,3.10");
        device.lock().unwrap().faults.push(fault(
            RequestKind::Fetch,
            Some("sra-20"),
            Act::Replace(sent.clone()),
            1,
        ));
        let handle = sra(&device);
        let mut events = handle.subscribe();
        let received = handle.measure_all_received().await.unwrap();
        assert!(received[0].reading.bit_eq(&Reading {
            geometry: "sra-20",
            value: ReadingValue::Intensity(3.1),
        }));
        assert_eq!(received[0].raw, sent);
        let canonical = SraCodec::encode_response(&Response::Fetched(received[0].reading));
        assert_ne!(canonical.unwrap(), sent);
        let event_frame = drain(&mut events).into_iter().find_map(|e| match e {
            Event::Reading { reading, .. } if reading.reading.geometry == "sra-20" => {
                Some(reading.raw)
            }
            _ => None,
        });
        assert_eq!(event_frame, Some(sent));
    })
    .await
}

#[tokio::test]
async fn a_disconnect_mid_scan_reconnects_identifies_and_resumes() {
    within(async {
        let device = Device::<Mat12Codec>::new();
        device.lock().unwrap().faults.push(fault(
            RequestKind::Fetch,
            Some("45as-15"),
            Act::Disconnect,
            1,
        ));
        let handle = mat12(&device);
        handle.identify().await.unwrap();
        let mut events = handle.subscribe();
        let readings = handle.measure_all().await.unwrap();
        assert_bit_equal(&readings, &device.lock().unwrap().readings);
        let events = drain(&mut events);
        let kinds: Vec<&str> = events
            .iter()
            .filter_map(|e| match e {
                Event::Disconnected { .. } => Some("disconnected"),
                Event::Reconnecting { .. } => Some("reconnecting"),
                Event::Connected { .. } => Some("connected"),
                _ => None,
            })
            .collect();
        assert_eq!(kinds, ["disconnected", "reconnecting", "connected"]);
        let d = device.lock().unwrap();
        assert_eq!(d.connections, 2);
        // After the reconnection: IDENTIFY, then the same FETCH again.
        let i = d
            .seen
            .iter()
            .rposition(|r| *r == Request::Identify)
            .unwrap();
        assert_eq!(
            d.seen[i + 1],
            Request::Fetch {
                geometry: "45as-15"
            }
        );
    })
    .await
}

#[tokio::test]
async fn a_device_that_stays_away_fails_the_command_naming_the_geometry() {
    within(async {
        let device = Device::<SraCodec>::new();
        {
            let mut d = device.lock().unwrap();
            d.faults.push(fault(
                RequestKind::Fetch,
                Some("sra-60"),
                Act::Disconnect,
                1,
            ));
            d.refuse_connections = 0;
        }
        let handle = sra(&device);
        handle.identify().await.unwrap();
        device.lock().unwrap().refuse_connections = u32::MAX;
        let mut events = handle.subscribe();
        let err = handle.measure_all().await.unwrap_err();
        let DriverError::Disconnected {
            geometry, attempts, ..
        } = &err
        else {
            panic!("expected Disconnected, got {err:?}")
        };
        assert_eq!((*geometry, *attempts), (Some("sra-60"), 5));
        assert!(err.to_string().contains("sra-60"), "{err}");
        assert!(err.to_string().contains("Canon RA-532H"), "{err}");
        let delays: Vec<Duration> = drain(&mut events)
            .iter()
            .filter_map(|e| match e {
                Event::Reconnecting { delay, .. } => Some(*delay),
                _ => None,
            })
            .collect();
        let ms = |m| Duration::from_millis(m);
        assert_eq!(
            delays,
            [ms(0), ms(5), ms(10), ms(20), ms(20)],
            "exponential, capped"
        );
    })
    .await
}

#[tokio::test]
async fn no_instrument_at_start_is_an_error_not_a_crash() {
    within(async {
        let device = Device::<Mat12Codec>::new();
        device.lock().unwrap().refuse_connections = u32::MAX;
        let handle = mat12(&device);
        let err = handle.measure_all().await.unwrap_err();
        assert!(matches!(
            err,
            DriverError::Disconnected { geometry: None, .. }
        ));
        assert!(err.to_string().contains("MA-T12 not found on USB"), "{err}");
        // Plugging it in later works without restarting the driver.
        device.lock().unwrap().refuse_connections = 0;
        assert_eq!(handle.measure_all().await.unwrap().len(), 12);
    })
    .await
}

#[tokio::test]
async fn unknown_geometry_is_refused_before_the_wire() {
    within(async {
        let device = Device::<Mat12Codec>::new();
        let handle = mat12(&device);
        let err = handle.measure_one("sra-20").await.unwrap_err();
        assert!(matches!(err, DriverError::UnknownGeometry { .. }));
        assert!(err.to_string().contains("15as-45 15as-30"), "{err}");
        let r = handle.measure_one("45as110").await.unwrap();
        assert!(r.bit_eq(&device.lock().unwrap().readings[11]));
    })
    .await
}

#[tokio::test]
async fn abort_interrupts_a_slow_measurement() {
    within(async {
        let device = Device::<Mat12Codec>::new();
        device.lock().unwrap().faults.push(fault(
            RequestKind::MeasureAll,
            None,
            Act::Delay(Duration::from_secs(2)),
            1,
        ));
        // Generous margins so a loaded machine cannot let the measurement finish first.
        let config = DriverConfig {
            measure_timeout: Duration::from_secs(4),
            ..fast()
        };
        let handle = mat12_with(&device, config);
        handle.identify().await.unwrap();
        let h = handle.clone();
        let scan = tokio::spawn(async move { h.measure_all().await });
        // Abort once the device has the request (a state, not a guess at how long that takes);
        // the reply is held 2 s, so the error below can only be the abort's.
        while !device.lock().unwrap().seen.contains(&Request::MeasureAll) {
            tokio::task::yield_now().await;
        }
        handle.abort().await.unwrap();
        let err = scan.await.unwrap().unwrap_err();
        assert!(matches!(
            err,
            DriverError::Aborted {
                request: RequestKind::MeasureAll,
                ..
            }
        ));
        assert_eq!(device.lock().unwrap().seen.last(), Some(&Request::Abort));
        // The next scan runs normally.
        assert_eq!(handle.measure_all().await.unwrap().len(), 12);
        // An abort that was counted but never queued (its future dropped in between) only
        // concerns commands queued before it.
        handle
            .abort
            .fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        assert_eq!(handle.measure_all().await.unwrap().len(), 12);
    })
    .await
}

/// A tiny xorshift so the noise is reproducible without a dependency.
fn noise(seed: &mut u64, len: usize) -> Vec<u8> {
    (0..len)
        .map(|_| {
            *seed ^= *seed << 13;
            *seed ^= *seed >> 7;
            *seed ^= *seed << 17;
            *seed as u8
        })
        .collect()
}

#[tokio::test]
async fn a_device_that_answers_noise_never_panics_the_driver_nor_yields_a_reading() {
    within(async {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let config = DriverConfig {
            reply_timeout: Duration::from_millis(15),
            ..fast()
        };
        for round in 0..10 {
            let device = Device::<Mat12Codec>::new();
            let handle = mat12_with(&device, config.clone());
            handle.identify().await.unwrap();
            let mut bytes = noise(&mut seed, 16 + round * 40);
            if round % 2 == 0 {
                // A plausible header makes the parser, not just the resync, do the work.
                bytes.splice(0..0, [b'M', b'T', 0x85, 0xF9, 0x00]);
            }
            device.lock().unwrap().faults.push(fault(
                RequestKind::Fetch,
                None,
                Act::Replace(bytes),
                u32::MAX,
            ));
            let err = handle.measure_all().await.unwrap_err();
            assert!(matches!(
                err,
                DriverError::NoValidReply {
                    geometry: Some("15as-45"),
                    ..
                }
            ));
            // Still alive and answering.
            assert_eq!(handle.status().await.unwrap().battery_percent, 90);
        }
    })
    .await
}

#[tokio::test]
async fn commands_after_shutdown_report_stopped() {
    within(async {
        let device = Device::<SraCodec>::new();
        let handle = sra(&device);
        let other = handle.clone();
        handle.shutdown().await;
        let err = other.status().await.unwrap_err();
        assert_eq!(
            err,
            DriverError::Stopped {
                instrument: Instrument::Sra
            }
        );
    })
    .await
}

#[test]
fn backoff_doubles_up_to_the_cap_and_the_deadline_covers_the_worst_case() {
    let c = DriverConfig::default();
    let ms = |m| Duration::from_millis(m);
    let delays: Vec<_> = (1..=7).map(|a| c.backoff(a)).collect();
    assert_eq!(
        delays,
        [
            ms(0),
            ms(100),
            ms(200),
            ms(400),
            ms(800),
            ms(1600),
            ms(2000)
        ]
    );
    assert_eq!(c.backoff(60), ms(2000));
    // MEASURE-ALL (4 × 10.2 s) + 12 FETCH (12 × 4 × 1.2 s) + 5 reconnections + 1 s.
    // Waits before attempts 2–5 (the first is immediate), and an IDENTIFY budget for each.
    let reconnect = ms(100 + 200 + 400 + 800) + ms(4 * 1200 * 5);
    assert_eq!(
        c.command_deadline(12),
        ms(4 * 10_200) + ms(12 * 4 * 1200) + reconnect + ms(1000)
    );
}

#[tokio::test]
async fn a_scan_recorded_through_the_tap_replays_to_the_same_readings() {
    use crate::session::{Direction, Session};
    use crate::tap::{Recorder, Tap};
    use crate::test_support::Sink;

    within(async {
        let device = Device::<Mat12Codec>::new();
        device.lock().unwrap().faults.push(fault(
            RequestKind::Fetch,
            Some("15as80"),
            Act::Corrupt,
            1,
        ));
        let sink = Sink::default();
        let recorder =
            Recorder::new(sink.clone(), Instrument::MaT12, &["unit test".into()]).unwrap();
        let (d, rec) = (device.clone(), recorder.clone());
        let handle = spawn_mat12(move || Ok(Tap::new(connect(&d)?, rec.clone())), fast());
        let received = handle.measure_all_received().await.unwrap();
        let readings = values(&received);
        handle.shutdown().await;
        recorder.finish().unwrap();

        let text = sink.text();
        let session = Session::parse(&text).unwrap();
        let requests: Vec<Request> = session
            .frames
            .iter()
            .filter(|f| f.direction == Direction::ToDevice)
            .map(|f| Mat12Codec::parse_request(&f.bytes).unwrap())
            .collect();
        assert_eq!(requests[..2], [Request::Identify, Request::MeasureAll]);
        assert_eq!(requests.len(), 2 + 12 + 1, "12 fetches and one resend");
        // The corrupted reply is on record, marked, and the readings on record are the driver's.
        assert!(text.contains("# not a frame: checksum mismatch"), "{text}");
        let recorded: Vec<(Reading, &[u8])> = session
            .frames
            .iter()
            .filter(|f| f.direction == Direction::FromDevice)
            .filter_map(|f| match Mat12Codec::parse_response(&f.bytes) {
                Ok(Response::Fetched(r)) => Some((r, &f.bytes[..])),
                _ => None,
            })
            .collect();
        assert_eq!(recorded.len(), 12, "{text}");
        let (values_on_record, frames_on_record): (Vec<Reading>, Vec<&[u8]>) =
            recorded.into_iter().unzip();
        assert_bit_equal(&values_on_record, &readings);
        // And each reading's frame is the `<` line on record for its FETCH, byte for byte.
        let frames: Vec<&[u8]> = received.iter().map(|r| &r.raw[..]).collect();
        assert_eq!(frames, frames_on_record);
    })
    .await
}
