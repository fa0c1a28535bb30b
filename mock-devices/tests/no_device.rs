//! On a machine without an MA-T12 (CI, the project's machines), the real USB transport gives a
//! clear "not found / no permission" error, and the driver task built on it fails its commands
//! with that error — naming the instrument — instead of crashing or hanging.

use std::time::Duration;

use drivers::mat12::usb::{RusbBulk, UsbIds};
use drivers::{DriverConfig, DriverError, Instrument, TransportError};

/// The operator-facing advice every "cannot reach the MA-T12" error must carry.
fn assert_actionable(msg: &str) {
    assert!(msg.contains("MA-T12"), "{msg}");
    assert!(
        msg.contains("not found on USB") || msg.contains("no permission"),
        "{msg}"
    );
    assert!(msg.contains("udev"), "{msg}");
}

#[test]
fn opening_the_real_transport_without_a_device_says_what_to_check() {
    // A product id no X-Rite device uses: the test does not depend on what is plugged in.
    let ids = UsbIds {
        product_id: Some(0xfff7),
        ..UsbIds::default()
    };
    let err = RusbBulk::open(ids).expect_err("no MA-T12 with product id 0xfff7");
    assert!(
        matches!(
            err,
            TransportError::UsbNotFound { .. } | TransportError::UsbPermission { .. }
        ),
        "{err:?}"
    );
    assert_actionable(&err.to_string());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_driver_on_the_real_transport_fails_cleanly_without_a_device() {
    let ids = UsbIds {
        product_id: Some(0xfff7),
        ..UsbIds::default()
    };
    let config = DriverConfig {
        reconnect_attempts: 2,
        backoff_initial: Duration::from_millis(5),
        ..DriverConfig::default()
    };
    let handle = drivers::spawn_mat12(move || RusbBulk::open(ids), config);
    let err = tokio::time::timeout(Duration::from_secs(30), handle.measure_all())
        .await
        .expect("the driver hung without a device")
        .expect_err("no device to measure with");
    let DriverError::Disconnected {
        instrument,
        request,
        attempts,
        ref last,
        ..
    } = err
    else {
        panic!("expected a connection error, got {err:?}");
    };
    assert_eq!(instrument, Instrument::MaT12);
    assert_eq!(request, drivers::protocol::RequestKind::MeasureAll);
    assert_eq!(attempts, 2);
    assert_actionable(last);
    let msg = err.to_string();
    assert!(
        msg.starts_with("X-Rite MA-T12: link lost during MEASURE-ALL"),
        "{msg}"
    );
    // The driver is still alive and answers the next command the same way.
    let again = tokio::time::timeout(Duration::from_secs(30), handle.identify())
        .await
        .expect("hung");
    assert!(
        matches!(again, Err(DriverError::Disconnected { .. })),
        "{again:?}"
    );
    handle.shutdown().await;
}
