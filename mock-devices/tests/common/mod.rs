//! Helpers shared by the integration tests: the lock that serialises pseudo-terminal tests,
//! driver settings with short timeouts, one scan of a simulated instrument through its driver,
//! and the bit-for-bit comparison of readings.

#![allow(dead_code)] // each test binary uses a different subset

use std::sync::{Mutex, MutexGuard};
use std::time::Duration;

use drivers::protocol::Reading;
use drivers::{DriverConfig, DriverError, DriverHandle, Event, Instrument};
use mock_devices::{ReplayOptions, ReplayReport, Script, SimMat12, SimSra};

/// Every test body runs under this; a hang fails the test instead of stalling the suite.
pub const TEST_TIMEOUT: Duration = Duration::from_secs(30);

/// `body`'s output, failing the test if it takes longer than [`TEST_TIMEOUT`].
pub async fn within<F: std::future::Future>(body: F) -> F::Output {
    tokio::time::timeout(TEST_TIMEOUT, body)
        .await
        .expect("within the test timeout")
}

/// Tests that open pseudo-terminal pairs take this lock: the pairs come from one kernel pool,
/// and timing-sensitive pty tests should not compete with each other for the two cores.
static PTY: Mutex<()> = Mutex::new(());

pub fn pty_lock() -> MutexGuard<'static, ()> {
    // A test that failed while holding the lock does not make the others fail.
    PTY.lock().unwrap_or_else(|p| p.into_inner())
}

/// Driver settings for fault tests: the rules of PROTOCOL.md §4 with shorter times, so that a
/// test of four timeouts takes two seconds, not four. Accelerated replies come back within
/// milliseconds; 500 ms leaves room for a machine busy compiling, so that no spurious timeout
/// adds a resend the tests count.
pub fn fast_config() -> DriverConfig {
    DriverConfig {
        reply_timeout: Duration::from_millis(500),
        measure_timeout: Duration::from_millis(1000),
        max_resends: 3,
        busy_wait: Duration::from_millis(10),
        reconnect_attempts: 3,
        backoff_initial: Duration::from_millis(10),
        backoff_max: Duration::from_millis(40),
        ..DriverConfig::default()
    }
}

/// A simulated instrument of either kind, with the driver task driving it.
pub struct Rig {
    pub handle: DriverHandle,
    pub events: tokio::sync::broadcast::Receiver<Event>,
    report: Box<dyn Fn() -> ReplayReport + Send + Sync>,
    /// Held for SRA rigs while the pty is in use.
    _pty: Option<MutexGuard<'static, ()>>,
}

impl Rig {
    /// Spawn the instrument's real driver task on a simulated instrument replaying `script`.
    pub fn new(script: Script, options: ReplayOptions, config: DriverConfig) -> Rig {
        match script.instrument() {
            Instrument::MaT12 => {
                let sim = SimMat12::new(script, options).expect("simulated MA-T12");
                let handle = drivers::spawn_mat12(sim.factory(), config);
                let events = handle.subscribe();
                Rig {
                    handle,
                    events,
                    report: Box::new(move || sim.report()),
                    _pty: None,
                }
            }
            Instrument::Sra => {
                let guard = pty_lock();
                let sim = SimSra::new(script, options).expect("simulated SRA");
                let handle = drivers::spawn_sra(sim.factory(), config);
                let events = handle.subscribe();
                Rig {
                    handle,
                    events,
                    report: Box::new(move || sim.report()),
                    _pty: Some(guard),
                }
            }
        }
    }

    pub fn report(&self) -> ReplayReport {
        (self.report)()
    }

    /// Events received so far.
    pub fn drain_events(&mut self) -> Vec<Event> {
        let mut out = Vec::new();
        while let Ok(e) = self.events.try_recv() {
            out.push(e);
        }
        out
    }

    /// Stop the driver (closing the connection) and give the final report.
    pub async fn finish(self) -> ReplayReport {
        let Rig {
            handle,
            report,
            _pty,
            ..
        } = self;
        handle.shutdown().await;
        report()
    }
}

/// One MEASURE-ALL scan of `script` through its driver, under [`TEST_TIMEOUT`].
pub async fn scan(
    script: Script,
    options: ReplayOptions,
    config: DriverConfig,
) -> (Result<Vec<Reading>, DriverError>, ReplayReport, Vec<Event>) {
    let mut rig = Rig::new(script, options, config);
    let result = tokio::time::timeout(TEST_TIMEOUT, rig.handle.measure_all())
        .await
        .expect("the scan hung");
    let events = rig.drain_events();
    let report = rig.finish().await;
    (result, report, events)
}

/// Readings equal bit for bit (geometry and every value), in order.
pub fn assert_bit_eq(got: &[Reading], want: &[Reading], what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: number of readings");
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            g.bit_eq(w),
            "{what}: reading {k} differs: got {g}, recorded {w}"
        );
    }
}
