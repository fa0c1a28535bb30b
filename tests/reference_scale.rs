//! `[reference] reflectance` end to end: a daemon configured with the tile's calibration
//! records it with the reference set it measures, and the scan measured against that
//! reference is processed on the absolute scale (SCIENCE.md §3): every measured value is the
//! relative one times ρ_ref (per band for the MA-T12, by the band mean for the SRA); a daemon
//! without the setting records nothing and keeps the relative scale.

#![allow(clippy::await_holding_lock)]

mod common;

use brdfd::config::Config;
use brdfd::processing::{self, ProcessingOptions, Scale};
use brdfd::service::{ServiceOptions, ServiceSettings};
use brdfd::spectral::BANDS;

use common::*;

#[test]
fn a_calibrated_tile_is_recorded_and_scales_the_measured_brdf() {
    let _one = serial();
    tokio::runtime::Runtime::new()
        .unwrap()
        .block_on(bounded(async {
            // A tile that is not flat, so per-band and band-mean scaling differ.
            let rho: [f64; BANDS] = std::array::from_fn(|b| 0.74 + 0.002 * b as f64);
            let values: Vec<String> = rho.iter().map(f64::to_string).collect();
            let config = Config::from_toml(
                &format!(
                    "[reference]\nreflectance = [{}]\n[devices.ma_t12]\ntransport = \"simulated\"\n\
                     [devices.sra]\ntransport = \"simulated\"\n",
                    values.join(", ")
                ),
                "brdfd.toml",
            )
            .unwrap();
            assert_eq!(config.reference.reflectance, Some(rho));
            let settings = ServiceSettings {
                cost_functions: vec![brdfd::cost::CostFunction::Cf1],
                crossval: false,
                ..ServiceSettings::from_config(&config)
            };
            let devices = simulated(&strict_fast());
            let d = start(devices, settings, ServiceOptions::default()).await;
            let reference = measure_reference(&d.service).await;
            let detail = d.store.reference_detail(reference).await.unwrap();
            assert_eq!(detail.reference.rho_ref, Some(rho));

            let sample = mock_devices::recordings::samples()[0].sample.unwrap();
            let scan = scan_and_settle(&d.service, sample).await;
            let processed = d.store.processed_for_scan(scan).await.unwrap();
            assert_eq!(processed.len(), 1);
            let absolute = processed[0].brdf;

            // The same scan processed relative to the tile, outside the daemon.
            let study = brdfd::report::load::from_store(
                &d.store,
                &brdfd::report::load::Selection::Scans(vec![scan]),
            )
            .await
            .unwrap();
            let s = &study.samples[0];
            assert_eq!(s.scale(), Scale::of(Some(&rho)));
            let relative = processing::process(&s.scan, &ProcessingOptions::default()).unwrap();
            let mean = rho.iter().sum::<f64>() / BANDS as f64;
            for g in 0..14 {
                for b in 0..BANDS {
                    let k = if g < 12 { rho[b] } else { mean };
                    let want = relative.values[g][b] * k;
                    assert!(
                        (absolute.values[g][b] - want).abs() <= 1e-14 * want.abs(),
                        "geometry {g} band {b}: {} vs {want}",
                        absolute.values[g][b]
                    );
                }
            }
            d.service.shutdown().await;
        }));
}

#[test]
fn without_the_setting_nothing_is_recorded_and_the_scale_is_relative() {
    let _one = serial();
    tokio::runtime::Runtime::new()
        .unwrap()
        .block_on(bounded(async {
            let d = start_builtin(strict_fast()).await;
            let reference = measure_reference(&d.service).await;
            let detail = d.store.reference_detail(reference).await.unwrap();
            assert_eq!(detail.reference.rho_ref, None);
            d.service.shutdown().await;
        }));
}
