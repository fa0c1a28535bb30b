//! Tier 3 of TESTING.md: the drivers against REAL instruments. Compiled only with
//! `--features hardware-tests`, so `cargo test` passes on a machine with no instruments.
//!
//! Run on a lab PC with both instruments attached and the N9 tile on the bench:
//! `BRDFD_SRA_PORT=/dev/ttyUSB0 cargo test -p brdfd-drivers --features hardware-tests -- --test-threads 1`
//! (`BRDFD_MA_T12_PRODUCT_ID=0x…` picks one X-Rite device when several are plugged in).
//!
//! These tests check the framing of `PROTOCOL.md`, which is brdfd's own: until a vendor's protocol
//! replaces a codec, a real instrument is expected to FAIL them, and that failure (no reply, or
//! refused frames) is the first thing to look at when writing the real codec.
#![cfg(feature = "hardware-tests")]

use drivers::driver::{DriverConfig, spawn_mat12, spawn_sra};
use drivers::mat12::usb::{RusbBulk, UsbIds};
use drivers::sra::codec::BAUD_RATE;
use drivers::sra::serial::open_serial;

fn product_id() -> Option<u16> {
    let raw = std::env::var("BRDFD_MA_T12_PRODUCT_ID").ok()?;
    let digits = raw.trim_start_matches("0x");
    Some(u16::from_str_radix(digits, 16).expect("BRDFD_MA_T12_PRODUCT_ID: a hex USB product id"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ma_t12_identifies_and_measures_every_geometry() {
    let ids = UsbIds {
        product_id: product_id(),
        ..UsbIds::default()
    };
    let handle = spawn_mat12(move || RusbBulk::open(ids), DriverConfig::default());
    let identity = handle.identify().await.expect("MA-T12 IDENTIFY");
    println!("MA-T12: {identity:?}");
    let readings = handle
        .measure_all_received()
        .await
        .expect("MA-T12 MEASURE-ALL");
    assert_eq!(readings.len(), handle.geometries().len());
    for r in &readings {
        assert!(
            !r.raw.is_empty(),
            "{}: no raw frame kept",
            r.reading.geometry
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sra_identifies_and_measures_both_geometries() {
    let port = std::env::var("BRDFD_SRA_PORT")
        .expect("BRDFD_SRA_PORT: the serial port of the Canon RA-532H, e.g. /dev/ttyUSB0");
    let handle = spawn_sra(
        move || open_serial(&port, BAUD_RATE),
        DriverConfig::default(),
    );
    let identity = handle.identify().await.expect("SRA IDENTIFY");
    println!("SRA: {identity:?}");
    let readings = handle
        .measure_all_received()
        .await
        .expect("SRA MEASURE-ALL");
    assert_eq!(readings.len(), handle.geometries().len());
}
