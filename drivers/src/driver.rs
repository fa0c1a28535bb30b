//! The async driver tasks: one per instrument, each owning its connection on a dedicated OS
//! thread (the transports are blocking), taking commands over an mpsc channel with a oneshot
//! reply, and emitting typed state events and readings on a broadcast channel. Each reading
//! travels with the bytes of the reply frame that carried it, as received (not re-encoded), so
//! the daemon can store what the instrument actually sent.
//!
//! The rules (PROTOCOL.md §4): every exchange has a reply timeout; a reply with a bad checksum,
//! a malformed reply, a timeout, or an instrument's BAD-CHECKSUM/BUSY error leads to a
//! byte-identical resend, at most [`DriverConfig::max_resends`] times; a lost link leads to
//! reconnection through the transport factory with exponential backoff, at most
//! [`DriverConfig::reconnect_attempts`] attempts per command, after which the command fails with
//! an error naming the instrument and the geometry in progress. Garbage — bytes that never form
//! a frame — is dropped without a resend, since the reply may still follow it. Every byte from
//! the instrument goes through the codec, which returns errors rather than panicking; a panic in
//! the worker would still only fail the command in hand.
//!
//! `tracing`: span `driver{instrument}` around the thread, span `command{request}` around each
//! command.

use std::marker::PhantomData;
use std::panic::AssertUnwindSafe;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use bytes::BytesMut;
use tokio::sync::{broadcast, mpsc, oneshot};
use tracing::{debug, info, info_span, warn};

use crate::mat12::codec::Mat12Codec;
use crate::protocol::{
    self, Answer, Codec, Command, ErrorCode, Identity, Instrument, Reading, ReceivedReading,
    RequestKind, Status,
};
use crate::sra::codec::SraCodec;
use crate::transport::{Link, SerialLink, SerialStream, TransportError, UsbBulk, UsbLink};

/// Timeouts, resends and reconnection. Defaults are those of PROTOCOL.md §4.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DriverConfig {
    /// Reply timeout for IDENTIFY, STATUS, FETCH and ABORT.
    pub reply_timeout: Duration,
    /// Reply timeout for CALIBRATE, MEASURE-ALL and MEASURE-ONE (the instrument is measuring).
    pub measure_timeout: Duration,
    /// Resends of one request after a timeout, a bad or malformed reply, or an instrument's
    /// BAD-CHECKSUM or BUSY error.
    pub max_resends: u32,
    /// Wait before resending after BUSY.
    pub busy_wait: Duration,
    /// Connection attempts per command once the link is lost (the first immediately).
    pub reconnect_attempts: u32,
    /// Wait before the second attempt; doubles for each further attempt.
    pub backoff_initial: Duration,
    /// Longest wait between attempts.
    pub backoff_max: Duration,
    /// Commands that can wait in the queue.
    pub queue_len: usize,
    /// Events kept for slow subscribers before they lag.
    pub event_capacity: usize,
}

impl Default for DriverConfig {
    fn default() -> DriverConfig {
        DriverConfig {
            reply_timeout: Duration::from_secs(1),
            measure_timeout: Duration::from_secs(10),
            max_resends: 3,
            busy_wait: Duration::from_millis(200),
            reconnect_attempts: 5,
            backoff_initial: Duration::from_millis(100),
            backoff_max: Duration::from_secs(2),
            queue_len: 16,
            event_capacity: 256,
        }
    }
}

impl DriverConfig {
    /// Wait before connection attempt `attempt` (1-based): none, then `backoff_initial`
    /// doubling up to `backoff_max`.
    pub fn backoff(&self, attempt: u32) -> Duration {
        if attempt <= 1 {
            return Duration::ZERO;
        }
        let factor = 1u32.checked_shl(attempt - 2).unwrap_or(u32::MAX);
        self.backoff_initial
            .saturating_mul(factor)
            .min(self.backoff_max)
    }

    /// Worst case of one request with all its resends.
    fn exchange_budget(&self, timeout: Duration) -> Duration {
        (timeout + self.busy_wait).saturating_mul(self.max_resends + 1)
    }

    /// Backstop deadline for one command at the async API: long enough for the slowest command
    /// (MEASURE-ALL and a FETCH per geometry, each with all resends, plus every reconnection with
    /// its IDENTIFY) to run to its own clean error, so it only fires if the I/O thread hangs.
    pub fn command_deadline(&self, geometries: usize) -> Duration {
        let reconnect: Duration = (1..=self.reconnect_attempts)
            .map(|a| self.backoff(a) + self.exchange_budget(self.reply_timeout))
            .sum();
        self.exchange_budget(self.measure_timeout)
            + self
                .exchange_budget(self.reply_timeout)
                .saturating_mul(geometries as u32)
            + reconnect
            + Duration::from_secs(1)
    }
}

/// What a driver reports to every subscriber.
// `Reading` holds a spectrum inline (see `protocol::ReadingValue`) and its frame: a few dozen
// events per scan, so the size costs nothing, while a box would add an allocation per event.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A connection is open and the instrument answered IDENTIFY.
    Connected {
        /// The instrument this event is about.
        instrument: Instrument,
        /// What the instrument answered to IDENTIFY.
        identity: Identity,
    },
    /// Fetching geometry `k` of `n` (1-based) of a MEASURE-ALL.
    Measuring {
        /// The instrument this event is about.
        instrument: Instrument,
        /// 1-based position of the geometry in the MEASURE-ALL.
        k: usize,
        /// Number of geometries in the MEASURE-ALL.
        n: usize,
        /// The geometry being fetched.
        geometry: &'static str,
    },
    /// A reading arrived (from MEASURE-ALL or MEASURE-ONE), with the reply frame that carried
    /// it as received.
    Reading {
        /// The instrument this event is about.
        instrument: Instrument,
        /// The reading and the reply frame that carried it.
        reading: ReceivedReading,
    },
    /// The link is gone (or could not be opened).
    Disconnected {
        /// The instrument this event is about.
        instrument: Instrument,
        /// Why the link is gone.
        reason: String,
    },
    /// About to make connection attempt `attempt` after waiting `delay`.
    Reconnecting {
        /// The instrument this event is about.
        instrument: Instrument,
        /// 1-based number of the connection attempt about to start.
        attempt: u32,
        /// How long the driver waits before it.
        delay: Duration,
    },
    /// A command failed.
    Error {
        /// The instrument this event is about.
        instrument: Instrument,
        /// What went wrong.
        error: DriverError,
    },
}

fn at(geometry: &Option<&'static str>) -> String {
    geometry
        .map(|g| format!(" at geometry {g}"))
        .unwrap_or_default()
}

/// Why a driver command failed. Every message names the instrument and, where one was in
/// progress, the geometry.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DriverError {
    #[error("{instrument}: no valid reply to {request}{} after {sends} sends (last problem: {last}); check the cable and that the instrument is switched on", at(.geometry))]
    /// Every send of the request timed out or drew only damaged or unrelated frames.
    NoValidReply {
        /// The instrument the command was for.
        instrument: Instrument,
        /// The request that went unanswered.
        request: RequestKind,
        /// The geometry the request was about, if any.
        geometry: Option<&'static str>,
        /// How many times the request was sent.
        sends: u32,
        /// The last problem seen (timeout, damaged frame, ...).
        last: String,
    },
    #[error("{instrument} refused {request}{}: {code}: {}", at(.geometry), .code.advice())]
    /// The instrument answered with an error code.
    Refused {
        /// The instrument the command was for.
        instrument: Instrument,
        /// The request refused.
        request: RequestKind,
        /// The geometry the request was about, if any.
        geometry: Option<&'static str>,
        /// The instrument's reason.
        code: ErrorCode,
    },
    #[error("{instrument}: link lost during {request}{} and {attempts} connection attempt(s) failed (last: {last}); check the cable and power, then retry the scan", at(.geometry))]
    /// The link dropped during the request and reconnecting failed.
    Disconnected {
        /// The instrument the command was for.
        instrument: Instrument,
        /// The request in progress.
        request: RequestKind,
        /// The geometry the request was about, if any.
        geometry: Option<&'static str>,
        /// How many connection attempts failed.
        attempts: u32,
        /// The last connection error.
        last: String,
    },
    #[error("{instrument} has no geometry {geometry:?}; its geometries are {known}")]
    /// The caller named a geometry the instrument does not have.
    UnknownGeometry {
        /// The instrument the command was for.
        instrument: Instrument,
        /// The geometry asked for.
        geometry: String,
        /// The instrument's geometries, listed for the message.
        known: String,
    },
    #[error(
        "{instrument}: MEASURE-ALL reported {count} geometries, expected {expected}: check the instrument's measurement mode"
    )]
    /// MEASURE-ALL buffered a number of geometries other than the instrument's.
    WrongCount {
        /// The instrument the command was for.
        instrument: Instrument,
        /// The count the instrument reported.
        count: u8,
        /// The instrument's number of geometries.
        expected: usize,
    },
    #[error("{instrument}: {request}{} aborted", at(.geometry))]
    /// The command was cut short by an abort.
    Aborted {
        /// The instrument the command was for.
        instrument: Instrument,
        /// The request in progress.
        request: RequestKind,
        /// The geometry the request was about, if any.
        geometry: Option<&'static str>,
    },
    #[error("{instrument}: {request} did not finish within {} ms: the driver thread is stuck; restart brdfd", .after.as_millis())]
    /// The driver thread did not answer within the command's deadline.
    Timeout {
        /// The instrument the command was for.
        instrument: Instrument,
        /// The request that did not finish.
        request: RequestKind,
        /// The deadline that passed.
        after: Duration,
    },
    #[error("{instrument}: the driver has stopped")]
    /// The driver task has ended; no command can be sent.
    Stopped {
        /// The instrument the command was for.
        instrument: Instrument,
    },
}

type Reply<T> = oneshot::Sender<Result<T, DriverError>>;

enum Job {
    Identify(Reply<Identity>),
    Status(Reply<Status>),
    Calibrate(Reply<()>),
    MeasureAll(Reply<Vec<ReceivedReading>>),
    MeasureOne(&'static str, Reply<ReceivedReading>),
    Abort(Reply<()>),
    Shutdown(oneshot::Sender<()>),
}

/// A cheap, cloneable handle to one instrument's driver task. The task stops when
/// [`DriverHandle::shutdown`] is called or the last handle is dropped.
#[derive(Debug, Clone)]
pub struct DriverHandle {
    instrument: Instrument,
    /// Each job goes with the abort epoch current when it was queued.
    jobs: mpsc::Sender<(u64, Job)>,
    events: broadcast::Sender<Event>,
    /// The abort epoch: `abort()` increments it, and every job queued before that (the one
    /// running included) fails as aborted at its next check. The thread sees it between
    /// exchanges without waiting for the queue; a std atomic because the thread is not async.
    /// An epoch rather than a flag, so nothing has to reset it (a cancelled `abort()` cannot
    /// leave later commands aborted).
    abort: Arc<AtomicU64>,
    deadline: Duration,
}

impl std::fmt::Debug for Job {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Job::Identify(_) => "Identify",
            Job::Status(_) => "Status",
            Job::Calibrate(_) => "Calibrate",
            Job::MeasureAll(_) => "MeasureAll",
            Job::MeasureOne(..) => "MeasureOne",
            Job::Abort(_) => "Abort",
            Job::Shutdown(_) => "Shutdown",
        })
    }
}

/// Start the MA-T12 driver. `factory` opens a new USB connection; it is called for the first
/// connection and for every reconnection.
pub fn spawn_mat12<T, F>(mut factory: F, config: DriverConfig) -> DriverHandle
where
    T: UsbBulk,
    F: FnMut() -> Result<T, TransportError> + Send + 'static,
{
    spawn::<Mat12Codec>(
        Box::new(move || Ok(Box::new(UsbLink(factory()?)) as Box<dyn Link>)),
        config,
    )
}

/// Start the SRA driver. `factory` opens a new serial connection; it is called for the first
/// connection and for every reconnection.
pub fn spawn_sra<T, F>(mut factory: F, config: DriverConfig) -> DriverHandle
where
    T: SerialStream,
    F: FnMut() -> Result<T, TransportError> + Send + 'static,
{
    spawn::<SraCodec>(
        Box::new(move || Ok(Box::new(SerialLink(factory()?)) as Box<dyn Link>)),
        config,
    )
}

type Factory = Box<dyn FnMut() -> Result<Box<dyn Link>, TransportError> + Send>;

fn spawn<C: Codec>(factory: Factory, config: DriverConfig) -> DriverHandle {
    let instrument = C::INSTRUMENT;
    let (jobs, rx) = mpsc::channel(config.queue_len.max(1));
    let (events, _) = broadcast::channel(config.event_capacity.max(1));
    let abort = Arc::new(AtomicU64::new(0));
    let deadline = config.command_deadline(instrument.geometries().len());
    let mut worker = Worker::<C> {
        config,
        factory,
        link: None,
        rx_buf: BytesMut::new(),
        events: events.clone(),
        abort: abort.clone(),
        job_epoch: 0,
        _codec: PhantomData,
    };
    std::thread::Builder::new()
        .name(format!("brdfd-{}", instrument.key()))
        .spawn(move || worker.run(rx))
        .expect("spawning an OS thread for the driver");
    DriverHandle {
        instrument,
        jobs,
        events,
        abort,
        deadline,
    }
}

impl DriverHandle {
    /// The instrument this driver talks to.
    pub fn instrument(&self) -> Instrument {
        self.instrument
    }

    /// The instrument's geometry names, in SCIENCE.md §2 order (the order of MEASURE-ALL).
    pub fn geometries(&self) -> &'static [&'static str] {
        self.instrument.geometries()
    }

    /// Events from now on.
    pub fn subscribe(&self) -> broadcast::Receiver<Event> {
        self.events.subscribe()
    }

    async fn call<T>(
        &self,
        request: RequestKind,
        job: impl FnOnce(Reply<T>) -> Job,
    ) -> Result<T, DriverError> {
        let stopped = DriverError::Stopped {
            instrument: self.instrument,
        };
        let (tx, rx) = oneshot::channel();
        let epoch = self.abort.load(Ordering::SeqCst);
        self.jobs
            .send((epoch, job(tx)))
            .await
            .map_err(|_| stopped.clone())?;
        match tokio::time::timeout(self.deadline, rx).await {
            Ok(Ok(result)) => result,
            Ok(Err(_)) => Err(stopped),
            Err(_) => Err(DriverError::Timeout {
                instrument: self.instrument,
                request,
                after: self.deadline,
            }),
        }
    }

    /// Ask the instrument who it is (IDENTIFY).
    pub async fn identify(&self) -> Result<Identity, DriverError> {
        self.call(RequestKind::Identify, Job::Identify).await
    }

    /// Ask the instrument for its state and battery charge (STATUS).
    pub async fn status(&self) -> Result<Status, DriverError> {
        self.call(RequestKind::Status, Job::Status).await
    }

    /// Take the instrument's reference calibration.
    pub async fn calibrate(&self) -> Result<(), DriverError> {
        self.call(RequestKind::Calibrate, Job::Calibrate).await
    }

    /// Measure every geometry and fetch the readings, in SCIENCE.md §2 order, each with the
    /// reply frame that carried it as received. Emits `Measuring` and `Reading` events as it
    /// goes.
    pub async fn measure_all_received(&self) -> Result<Vec<ReceivedReading>, DriverError> {
        self.call(RequestKind::MeasureAll, Job::MeasureAll).await
    }

    /// [`DriverHandle::measure_all_received`] without the frames: the readings' values only.
    pub async fn measure_all(&self) -> Result<Vec<Reading>, DriverError> {
        let received = self.measure_all_received().await?;
        Ok(received.into_iter().map(|r| r.reading).collect())
    }

    /// Measure one geometry, by its wire name; the reading comes with the reply frame that
    /// carried it as received.
    pub async fn measure_one_received(
        &self,
        geometry: &str,
    ) -> Result<ReceivedReading, DriverError> {
        let Some(g) = self.instrument.geometry(geometry) else {
            return Err(DriverError::UnknownGeometry {
                instrument: self.instrument,
                geometry: geometry.to_owned(),
                known: self.geometries().join(" "),
            });
        };
        self.call(RequestKind::MeasureOne, |tx| Job::MeasureOne(g, tx))
            .await
    }

    /// [`DriverHandle::measure_one_received`] without the frame: the reading's values only.
    pub async fn measure_one(&self, geometry: &str) -> Result<Reading, DriverError> {
        Ok(self.measure_one_received(geometry).await?.reading)
    }

    /// Abort: the command in progress fails with `Aborted` at its next exchange boundary (or
    /// while waiting for a reply), then ABORT is sent to the instrument.
    pub async fn abort(&self) -> Result<(), DriverError> {
        self.abort.fetch_add(1, Ordering::SeqCst);
        self.call(RequestKind::Abort, Job::Abort).await
    }

    /// Stop the task after the commands already queued, and wait until its thread has closed
    /// the connection.
    pub async fn shutdown(self) {
        let (tx, rx) = oneshot::channel();
        if self.jobs.send((0, Job::Shutdown(tx))).await.is_ok() {
            let _ = rx.await;
        }
    }
}

/// Why one exchange did not produce an answer.
enum Failure {
    /// The link is gone: reconnect.
    Link(TransportError),
    /// Final: report to the caller.
    Final(DriverError),
}

struct Worker<C: Codec> {
    config: DriverConfig,
    factory: Factory,
    /// The open connection, if any.
    link: Option<Box<dyn Link>>,
    /// Bytes received and not yet decoded.
    rx_buf: BytesMut,
    events: broadcast::Sender<Event>,
    abort: Arc<AtomicU64>,
    /// Abort epoch when the job in hand was queued.
    job_epoch: u64,
    _codec: PhantomData<C>,
}

/// How long to block in one transport read, so an abort is noticed while waiting for a reply.
const POLL_SLICE: Duration = Duration::from_millis(50);

impl<C: Codec> Worker<C> {
    fn emit(&self, event: Event) {
        // No subscriber is not an error.
        let _ = self.events.send(event);
    }

    fn run(&mut self, mut rx: mpsc::Receiver<(u64, Job)>) {
        let span = info_span!("driver", instrument = C::INSTRUMENT.key());
        let _enter = span.enter();
        if let Err(reason) = self.connect() {
            info!(%reason, "not connected at start; will connect on the first command");
            self.emit(Event::Disconnected {
                instrument: C::INSTRUMENT,
                reason,
            });
        }
        while let Some((epoch, job)) = rx.blocking_recv() {
            self.job_epoch = epoch;
            if let Job::Shutdown(done) = job {
                self.link = None;
                let _ = done.send(());
                return;
            }
            let name = format!("{job:?}");
            let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| self.handle(job)));
            if outcome.is_err() {
                // A bug, not something the instrument can cause; the caller sees `Stopped`
                // for this command (its reply sender was dropped) and the next command starts
                // on a fresh connection.
                warn!(job = %name, "driver command panicked; dropping the connection");
                self.link = None;
            }
        }
        debug!("all handles dropped; driver stops");
    }

    fn handle(&mut self, job: Job) {
        match job {
            Job::Identify(tx) => {
                let r = self.command(&protocol::Identify, self.config.reply_timeout);
                self.finish(tx, r);
            }
            Job::Status(tx) => {
                let r = self.command(&protocol::GetStatus, self.config.reply_timeout);
                self.finish(tx, r);
            }
            Job::Calibrate(tx) => {
                let r = self.command(&protocol::Calibrate, self.config.measure_timeout);
                self.finish(tx, r);
            }
            Job::MeasureAll(tx) => {
                let r = self.measure_all();
                self.finish(tx, r);
            }
            Job::MeasureOne(geometry, tx) => {
                let r = self
                    .command_framed(
                        &protocol::MeasureOne { geometry },
                        self.config.measure_timeout,
                    )
                    .map(received);
                if let Ok(reading) = &r {
                    self.emit(Event::Reading {
                        instrument: C::INSTRUMENT,
                        reading: reading.clone(),
                    });
                }
                self.finish(tx, r);
            }
            Job::Abort(tx) => {
                let r = self.command(&protocol::Abort, self.config.reply_timeout);
                self.finish(tx, r);
            }
            Job::Shutdown(_) => unreachable!("handled in run"),
        }
    }

    fn finish<T>(&self, tx: Reply<T>, result: Result<T, DriverError>) {
        if let Err(e) = &result {
            warn!(error = %e, "command failed");
            self.emit(Event::Error {
                instrument: C::INSTRUMENT,
                error: e.clone(),
            });
        }
        // The caller may have given up; nothing to do then.
        let _ = tx.send(result);
    }

    fn measure_all(&mut self) -> Result<Vec<ReceivedReading>, DriverError> {
        let geometries = C::INSTRUMENT.geometries();
        let n = geometries.len();
        let count = self.command(&protocol::MeasureAll, self.config.measure_timeout)?;
        if count as usize != n {
            return Err(DriverError::WrongCount {
                instrument: C::INSTRUMENT,
                count,
                expected: n,
            });
        }
        let mut readings = Vec::with_capacity(n);
        for (i, &geometry) in geometries.iter().enumerate() {
            self.emit(Event::Measuring {
                instrument: C::INSTRUMENT,
                k: i + 1,
                n,
                geometry,
            });
            let reading = received(
                self.command_framed(&protocol::Fetch { geometry }, self.config.reply_timeout)?,
            );
            self.emit(Event::Reading {
                instrument: C::INSTRUMENT,
                reading: reading.clone(),
            });
            readings.push(reading);
        }
        Ok(readings)
    }

    /// Run one command to its end: resends, reconnections, clean error.
    fn command<K: Command>(
        &mut self,
        cmd: &K,
        timeout: Duration,
    ) -> Result<K::Output, DriverError> {
        self.command_framed(cmd, timeout).map(|(out, _)| out)
    }

    /// [`Worker::command`] that also returns the reply frame that answered, as received.
    fn command_framed<K: Command>(
        &mut self,
        cmd: &K,
        timeout: Duration,
    ) -> Result<(K::Output, BytesMut), DriverError> {
        let request = cmd.request();
        let span = info_span!("command", request = %request);
        let _enter = span.enter();
        let mut attempts_left = self.config.reconnect_attempts;
        let mut attempts_made = 0;
        loop {
            if self.link.is_none() {
                let mut last = String::from("no attempt allowed (reconnect_attempts = 0)");
                while self.link.is_none() {
                    if attempts_left == 0 {
                        return Err(DriverError::Disconnected {
                            instrument: C::INSTRUMENT,
                            request: request.kind(),
                            geometry: request.geometry(),
                            attempts: attempts_made,
                            last,
                        });
                    }
                    self.check_abort(cmd)?;
                    attempts_left -= 1;
                    attempts_made += 1;
                    let delay = self.config.backoff(attempts_made);
                    self.emit(Event::Reconnecting {
                        instrument: C::INSTRUMENT,
                        attempt: attempts_made,
                        delay,
                    });
                    std::thread::sleep(delay);
                    if let Err(reason) = self.connect() {
                        warn!(attempt = attempts_made, %reason, "connection attempt failed");
                        last = reason;
                    }
                }
            }
            match self.exchange(cmd, timeout) {
                Ok(out) => return Ok(out),
                Err(Failure::Final(e)) => return Err(e),
                Err(Failure::Link(e)) => self.lose_link(e.to_string()),
            }
        }
    }

    fn lose_link(&mut self, reason: String) {
        warn!(%reason, "link lost");
        self.link = None;
        self.rx_buf.clear();
        self.emit(Event::Disconnected {
            instrument: C::INSTRUMENT,
            reason,
        });
    }

    /// Open a connection through the factory and introduce it with IDENTIFY.
    fn connect(&mut self) -> Result<(), String> {
        let link = (self.factory)().map_err(|e| e.to_string())?;
        self.link = Some(link);
        self.rx_buf.clear();
        match self.exchange(&protocol::Identify, self.config.reply_timeout) {
            Ok((identity, _)) => {
                info!(%identity, "connected");
                self.emit(Event::Connected {
                    instrument: C::INSTRUMENT,
                    identity,
                });
                Ok(())
            }
            Err(failure) => {
                self.link = None;
                Err(match failure {
                    Failure::Link(e) => e.to_string(),
                    Failure::Final(e) => e.to_string(),
                })
            }
        }
    }

    fn check_abort<K: Command>(&self, cmd: &K) -> Result<(), DriverError> {
        let request = cmd.request();
        if request.kind() != RequestKind::Abort
            && self.abort.load(Ordering::SeqCst) > self.job_epoch
        {
            return Err(DriverError::Aborted {
                instrument: C::INSTRUMENT,
                request: request.kind(),
                geometry: request.geometry(),
            });
        }
        Ok(())
    }

    /// Send the request and wait for its answer on the current link, resending as allowed.
    /// Returns the answer and the reply frame it came in.
    fn exchange<K: Command>(
        &mut self,
        cmd: &K,
        timeout: Duration,
    ) -> Result<(K::Output, BytesMut), Failure> {
        let request = cmd.request();
        let bytes = cmd.to_bytes::<C>().map_err(|e| {
            // Only reachable with a geometry from another instrument; the handle checks names.
            Failure::Final(DriverError::UnknownGeometry {
                instrument: C::INSTRUMENT,
                geometry: request.geometry().unwrap_or_default().to_owned(),
                known: format!("{e}"),
            })
        })?;
        let mut last = String::new();
        for send in 1..=self.config.max_resends + 1 {
            self.check_abort(cmd).map_err(Failure::Final)?;
            if send > 1 {
                debug!(send, %last, "resending");
            }
            let link = self.link.as_mut().expect("exchange needs a link");
            link.discard_input();
            self.rx_buf.clear();
            match link.send(&bytes, timeout) {
                Ok(()) => {}
                Err(TransportError::Timeout { .. }) => {
                    last = "the write timed out".into();
                    continue;
                }
                Err(e) => return Err(Failure::Link(e)),
            }
            match self.await_answer(cmd, timeout)? {
                Ok(out) => return Ok(out),
                Err(Retry::Busy) => {
                    last = "the instrument was busy".into();
                    std::thread::sleep(self.config.busy_wait);
                }
                Err(Retry::Because(why)) => {
                    warn!(%why, "no usable reply; will resend");
                    last = why;
                }
            }
        }
        Err(Failure::Final(DriverError::NoValidReply {
            instrument: C::INSTRUMENT,
            request: request.kind(),
            geometry: request.geometry(),
            sends: self.config.max_resends + 1,
            last,
        }))
    }

    /// Read and decode until the reply to `cmd` arrives, the timeout passes, or a damaged
    /// frame calls for a resend. Outer `Err`: link lost or final; inner `Err`: resend.
    /// `Ok(Ok(_))` carries the answering frame's bytes as they were received.
    fn await_answer<K: Command>(
        &mut self,
        cmd: &K,
        timeout: Duration,
    ) -> Result<Result<(K::Output, BytesMut), Retry>, Failure> {
        let request = cmd.request();
        let deadline = Instant::now() + timeout;
        let mut chunk = Vec::with_capacity(256);
        loop {
            loop {
                match C::decode_response_frame(&mut self.rx_buf) {
                    Ok(Some((response, frame))) => match cmd.parse_response(response) {
                        Answer::Done(out) => return Ok(Ok((out, frame))),
                        Answer::Refused(ErrorCode::BadChecksum) => {
                            return Ok(Err(Retry::Because(
                                "the instrument received a corrupted request".into(),
                            )));
                        }
                        Answer::Refused(ErrorCode::Busy) => return Ok(Err(Retry::Busy)),
                        Answer::Refused(code) => {
                            return Err(Failure::Final(DriverError::Refused {
                                instrument: C::INSTRUMENT,
                                request: request.kind(),
                                geometry: request.geometry(),
                                code,
                            }));
                        }
                        Answer::NotMine(other) => {
                            debug!(reply = %other, "dropping a reply that does not answer {request}")
                        }
                    },
                    Ok(None) => break,
                    // Bytes that never formed a frame (PROTOCOL.md §4): the reply may follow
                    // them, so keep waiting; if it does not, the timeout resends.
                    Err(e) if e.is_garbage() => debug!(error = %e, "dropped garbage"),
                    // A whole frame that failed its checks: the reply was damaged and will not
                    // come again unasked, so resend at once.
                    Err(e) => return Ok(Err(Retry::Because(e.to_string()))),
                }
            }
            self.check_abort(cmd).map_err(Failure::Final)?;
            let now = Instant::now();
            if now >= deadline {
                return Ok(Err(Retry::Because(format!(
                    "no reply within {} ms",
                    timeout.as_millis()
                ))));
            }
            chunk.clear();
            let link = self.link.as_mut().expect("exchange needs a link");
            match link.recv(&mut chunk, (deadline - now).min(POLL_SLICE)) {
                Ok(()) => self.rx_buf.extend_from_slice(&chunk),
                Err(TransportError::Timeout { .. }) => {}
                Err(e) => return Err(Failure::Link(e)),
            }
        }
    }
}

enum Retry {
    Busy,
    Because(String),
}

/// A reading and the bytes of the frame it came in.
fn received((reading, frame): (Reading, BytesMut)) -> ReceivedReading {
    ReceivedReading {
        reading,
        raw: frame.to_vec(),
    }
}

#[cfg(test)]
mod tests;
