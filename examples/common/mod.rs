//! What the examples share: their arguments from the command line, the example scans of
//! `tests/data/`, a two-thread runtime, the service on a fresh store with the simulated
//! instruments of the embedded recordings, and a percentile.

#![allow(dead_code)] // each example uses a different subset

use std::path::Path;

use brdfd::service::{Devices, Service, ServiceOptions, ServiceSettings};
use brdfd::store::Store;
use drivers::Instrument;

// The study binaries' helpers, compiled from their one file: an example cannot depend on
// brdfd-tools, which depends on brdfd.
#[path = "../../tools/src/shared.rs"]
pub mod shared;

/// The whole numbers given after the example's name.
pub fn counts() -> Vec<usize> {
    std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("counts are whole numbers"))
        .collect()
}

/// A multi-threaded runtime on two workers.
pub fn runtime() -> std::io::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
}

/// The service on a new store in `dir`, with the simulated instruments of the embedded
/// recordings (lenient, at recorded timing) and the default settings.
pub async fn simulated_service(dir: &Path) -> anyhow::Result<Service> {
    let store = Store::open(dir.join("brdfd.db")).await?;
    let devices = Devices::simulated(
        mock_devices::recordings::playlist(Instrument::MaT12)?,
        mock_devices::recordings::playlist(Instrument::Sra)?,
        &mock_devices::ReplayOptions::lenient(),
        [None, None],
    )?;
    Ok(Service::start(
        store,
        devices,
        ServiceSettings::default(),
        ServiceOptions::default(),
    )
    .await?)
}

/// The value at fraction `p` of a sorted sample.
pub fn percentile(sorted: &[f64], p: f64) -> f64 {
    let i = ((sorted.len() as f64 - 1.0) * p).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}
