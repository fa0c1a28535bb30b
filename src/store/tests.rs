//! Tests of the store's verbs, on in-memory stores and on real files in a temporary directory.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sqlx::Row;

use super::*;
use crate::cost::CostFunction;
use crate::geometry::{Device, GEOMETRIES, GEOMETRY_COUNT, Geometry, by_name};
use crate::processing::{MeasuredBrdf, SpecularStrategy};
use crate::spectral::{BANDS, Spectrum};

/// Values of the right kind for `g`, all distinct and with full mantissas, from `rng`.
fn values_for(g: &Geometry, rng: &mut ChaCha8Rng) -> ReadingValues {
    match g.device {
        Device::MaT12 => ReadingValues::Spectrum(std::array::from_fn(|_| rng.random::<f64>())),
        Device::Sra => ReadingValues::Intensity(rng.random::<f64>() * 10.0),
    }
}

fn frame(g: &Geometry) -> Vec<u8> {
    let mut f = vec![0x02, g.index as u8];
    f.extend_from_slice(g.name.as_bytes());
    f.push(0x03);
    f
}

/// A complete reference set with positive values.
async fn complete_reference(store: &Store) -> ReferenceId {
    let id = store.begin_reference("Munsell N9", None).await.unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for g in &GEOMETRIES {
        let v = match values_for(g, &mut rng) {
            ReadingValues::Spectrum(s) => ReadingValues::Spectrum(s.map(|x| 0.7 + x * 0.1)),
            ReadingValues::Intensity(x) => ReadingValues::Intensity(0.2 + x),
        };
        store
            .add_reference_reading(id, g.device, g, &v, &frame(g))
            .await
            .unwrap();
    }
    store.complete_reference(id).await.unwrap();
    id
}

/// A scan in `measuring` with readings at the first `n` geometries; returns the values stored.
async fn measuring_scan(
    store: &Store,
    reference: ReferenceId,
    sample: &str,
    n: usize,
) -> (ScanId, Vec<ReadingValues>) {
    let scan = store.request_scan(sample, reference).await.unwrap();
    store.start_measuring(scan).await.unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(scan.0 as u64);
    let mut stored = Vec::new();
    for g in &GEOMETRIES[..n] {
        let v = values_for(g, &mut rng);
        store
            .add_reading(scan, g.device, g, &v, &frame(g))
            .await
            .unwrap();
        stored.push(v);
    }
    (scan, stored)
}

fn brdf(seed: u64) -> MeasuredBrdf {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    MeasuredBrdf::full(std::array::from_fn(|_| {
        std::array::from_fn(|_| rng.random::<f64>() / 3.0)
    }))
}

fn new_fit(cf: CostFunction) -> NewFit {
    NewFit {
        method: "paper".into(),
        cost_function: cf,
        settings: serde_json::json!({"population": 64, "generations": 200, "seed": u64::MAX}),
        seed: u64::MAX,
        colorimetry: Default::default(),
    }
}

#[tokio::test]
async fn instruments_are_upserted_by_serial() {
    let store = Store::open_in_memory().await.unwrap();
    let a = store
        .add_instrument(Device::MaT12, "MAT-0042", "MA-T12 fw 1.0")
        .await
        .unwrap();
    let b = store
        .add_instrument(Device::Sra, "SRA-7", "RA-532H")
        .await
        .unwrap();
    let again = store
        .add_instrument(Device::MaT12, "MAT-0042", "MA-T12 fw 1.1")
        .await
        .unwrap();
    assert_eq!(a, again);
    assert_ne!(a, b);
    let all = store.instruments().await.unwrap();
    assert_eq!(all.len(), 2);
    assert_eq!(all[0].identity, "MA-T12 fw 1.1");
    assert_eq!(all[0].device, Device::MaT12);
    assert!(all[0].first_seen_ms <= all[0].last_seen_ms);
    let e = store
        .add_instrument(Device::Sra, " ", "x")
        .await
        .unwrap_err();
    assert_eq!(e.to_string(), "instrument serial number must not be empty");
}

#[tokio::test]
async fn reference_sets_complete_only_with_14_positive_readings() {
    let store = Store::open_in_memory().await.unwrap();
    assert_eq!(store.latest_reference().await.unwrap(), None);
    let rho: Spectrum = [0.77; BANDS];
    let id = store
        .begin_reference("Munsell N9", Some(&rho))
        .await
        .unwrap();
    let g = by_name("45as25").unwrap();
    let v = ReadingValues::Spectrum([0.8; BANDS]);
    store
        .add_reference_reading(id, Device::MaT12, g, &v, b"raw")
        .await
        .unwrap();
    let e = store
        .add_reference_reading(id, Device::MaT12, g, &v, b"raw")
        .await
        .unwrap_err();
    assert_eq!(
        e.to_string(),
        format!("reference {id} already holds a reading at 45as25: each geometry is measured once")
    );
    let mut zero = [0.8; BANDS];
    zero[0] = 0.0;
    let e = store
        .add_reference_reading(
            id,
            Device::MaT12,
            by_name("15as15").unwrap(),
            &ReadingValues::Spectrum(zero),
            b"",
        )
        .await
        .unwrap_err();
    assert!(
        e.to_string().starts_with(&format!(
            "reference {id} reading at 15as15: the value at 400 nm is 0;"
        )),
        "{e}"
    );
    let e = store.complete_reference(id).await.unwrap_err();
    assert!(
        matches!(e, StoreError::ReferenceIncomplete { have: 1, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("missing 15as-45, 15as-30"), "{e}");
    assert!(!e.to_string().contains("45as25,"), "{e}");
    assert_eq!(store.latest_reference().await.unwrap(), None);

    let full = complete_reference(&store).await;
    let latest = store.latest_reference().await.unwrap().unwrap();
    assert_eq!(latest.id, full);
    assert_eq!(latest.status, ReferenceStatus::Complete);
    assert_eq!(latest.reading_count, GEOMETRY_COUNT);
    assert!(latest.completed_at_ms.is_some());
    let e = store
        .add_reference_reading(
            full,
            Device::Sra,
            by_name("sra-20").unwrap(),
            &ReadingValues::Intensity(1.0),
            b"",
        )
        .await
        .unwrap_err();
    assert_eq!(
        e.to_string(),
        format!("reference {full} is complete, not measuring: cannot add a reading to it")
    );

    store.fail_reference(id, "tile dropped").await.unwrap();
    let detail = store.reference_detail(id).await.unwrap();
    assert_eq!(detail.reference.status, ReferenceStatus::Failed);
    assert_eq!(detail.reference.reason.as_deref(), Some("tile dropped"));
    assert_eq!(detail.reference.rho_ref, Some(rho));
    assert_eq!(detail.readings.len(), 1);
    assert!(store.fail_reference(id, "again").await.is_err());
    let e = store
        .begin_reference("N9", Some(&[-0.1; BANDS]))
        .await
        .unwrap_err();
    assert!(matches!(e, StoreError::NonPositiveReference { .. }), "{e}");

    // A newer complete set becomes the one in force.
    let newer = complete_reference(&store).await;
    assert_eq!(store.latest_reference().await.unwrap().unwrap().id, newer);
}

#[tokio::test]
async fn scans_need_a_complete_reference() {
    let store = Store::open_in_memory().await.unwrap();
    let e = store
        .request_scan("T.Freesia pink", ReferenceId(99))
        .await
        .unwrap_err();
    assert_eq!(e.to_string(), "reference 99 does not exist in the store");
    let open = store.begin_reference("Munsell N9", None).await.unwrap();
    let e = store
        .request_scan("T.Freesia pink", open)
        .await
        .unwrap_err();
    assert_eq!(
        e.to_string(),
        format!("reference {open} is measuring, not complete: cannot scan against it")
    );
    let reference = complete_reference(&store).await;
    let e = store.request_scan("", reference).await.unwrap_err();
    assert!(matches!(e, StoreError::Empty { .. }));
    let a = store
        .request_scan("T.Freesia pink", reference)
        .await
        .unwrap();
    let b = store
        .request_scan("T.Freesia pink", reference)
        .await
        .unwrap();
    let da = store.scan_detail(a).await.unwrap();
    let db = store.scan_detail(b).await.unwrap();
    assert_eq!(
        da.scan.sample_id, db.scan.sample_id,
        "one sample row per name"
    );
    assert_eq!(da.scan.state, ScanState::Requested);
    assert_eq!(da.reference.reference.id, reference);
    assert_eq!(da.reference.readings.len(), GEOMETRY_COUNT);
}

#[tokio::test]
async fn readings_join_only_measuring_scans_once_per_geometry() {
    let store = Store::open_in_memory().await.unwrap();
    let reference = complete_reference(&store).await;
    let scan = store.request_scan("S", reference).await.unwrap();
    let g = &GEOMETRIES[0];
    let v = ReadingValues::Spectrum([0.4; BANDS]);
    let e = store
        .add_reading(scan, g.device, g, &v, b"")
        .await
        .unwrap_err();
    assert_eq!(
        e.to_string(),
        format!("scan {scan} is requested, not measuring: cannot add a reading to it")
    );
    store.start_measuring(scan).await.unwrap();
    let e = store.start_measuring(scan).await.unwrap_err();
    assert!(matches!(
        e,
        StoreError::ScanState {
            state: ScanState::Measuring,
            ..
        }
    ));
    store.add_reading(scan, g.device, g, &v, b"").await.unwrap();
    let e = store
        .add_reading(scan, g.device, g, &v, b"")
        .await
        .unwrap_err();
    assert!(
        matches!(
            e,
            StoreError::DuplicateReading {
                geometry: "15as-45",
                ..
            }
        ),
        "{e}"
    );
    let sra = by_name("sra-20").unwrap();
    let e = store
        .add_reading(scan, Device::MaT12, sra, &v, b"")
        .await
        .unwrap_err();
    assert!(matches!(e, StoreError::WrongDevice { .. }), "{e}");
    let e = store
        .add_reading(
            scan,
            Device::Sra,
            sra,
            &ReadingValues::Intensity(f64::INFINITY),
            b"",
        )
        .await
        .unwrap_err();
    assert!(matches!(e, StoreError::NonFinite { .. }), "{e}");
    // A sample reading of exactly 0 is legal (a black sample, a dark geometry).
    store
        .add_reading(scan, Device::Sra, sra, &ReadingValues::Intensity(0.0), b"")
        .await
        .unwrap();
    let e = store
        .add_reading(ScanId(1234), g.device, g, &v, b"")
        .await
        .unwrap_err();
    assert_eq!(e.to_string(), "scan 1234 does not exist in the store");
}

#[tokio::test]
async fn failed_scan_keeps_its_five_readings() {
    let store = Store::open_in_memory().await.unwrap();
    let reference = complete_reference(&store).await;
    let (scan, stored) = measuring_scan(&store, reference, "T.Prairie green", 5).await;
    store
        .fail_scan(scan, "MA-T12 timed out at 45as-15")
        .await
        .unwrap();
    let d = store.scan_detail(scan).await.unwrap();
    assert_eq!(d.scan.state, ScanState::Failed);
    assert_eq!(
        d.scan.reason.as_deref(),
        Some("MA-T12 timed out at 45as-15")
    );
    assert!(d.scan.finished_at_ms.is_some());
    assert_eq!(d.scan.reading_count, 5);
    assert_eq!(d.readings.len(), 5);
    for ((r, v), g) in d.readings.iter().zip(&stored).zip(&GEOMETRIES) {
        assert_eq!(r.geometry.name, g.name);
        assert_eq!(&r.values, v);
        assert_eq!(r.raw_frame, frame(g));
    }
    let e = store.complete_scan(scan).await.unwrap_err();
    assert_eq!(
        e.to_string(),
        format!("scan {scan} is failed, not measuring: cannot complete it")
    );
    assert!(store.fail_scan(scan, "again").await.is_err());
    assert!(store.abort_scan(scan).await.is_err());
    let e = store
        .add_reading(
            scan,
            Device::Sra,
            &GEOMETRIES[13],
            &ReadingValues::Intensity(1.0),
            b"",
        )
        .await
        .unwrap_err();
    assert!(matches!(
        e,
        StoreError::ScanState {
            state: ScanState::Failed,
            ..
        }
    ));
    assert!(store.fail_scan(scan, "  ").await.is_err());
}

#[tokio::test]
async fn complete_scan_refuses_a_scan_missing_readings() {
    let store = Store::open_in_memory().await.unwrap();
    let reference = complete_reference(&store).await;
    let (scan, _) = measuring_scan(&store, reference, "S", 13).await;
    let e = store.complete_scan(scan).await.unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "scan {scan} holds 13 of 14 readings (missing sra-60): cannot complete it; measure \
             the missing geometries, or fail or abort the scan"
        )
    );
    assert_eq!(
        store.scan_detail(scan).await.unwrap().scan.state,
        ScanState::Measuring
    );
    let g = &GEOMETRIES[13];
    store
        .add_reading(scan, g.device, g, &ReadingValues::Intensity(2.5), b"")
        .await
        .unwrap();
    store.complete_scan(scan).await.unwrap();
    let d = store.scan_detail(scan).await.unwrap();
    assert_eq!(d.scan.state, ScanState::Complete);
    assert_eq!(d.readings.len(), GEOMETRY_COUNT);
    let order: Vec<_> = d.readings.iter().map(|r| r.geometry.index).collect();
    assert_eq!(order, (0..GEOMETRY_COUNT).collect::<Vec<_>>());
    assert!(store.complete_scan(scan).await.is_err());

    // A scan that never started measuring cannot complete either.
    let requested = store.request_scan("S", reference).await.unwrap();
    let e = store.complete_scan(requested).await.unwrap_err();
    assert!(matches!(
        e,
        StoreError::ScanState {
            state: ScanState::Requested,
            ..
        }
    ));
}

#[tokio::test]
async fn abort_and_list_scans() {
    let store = Store::open_in_memory().await.unwrap();
    let reference = complete_reference(&store).await;
    let a = store.request_scan("A", reference).await.unwrap();
    let (b, _) = measuring_scan(&store, reference, "B", 2).await;
    let (c, _) = measuring_scan(&store, reference, "A", 14).await;
    store.complete_scan(c).await.unwrap();
    store.abort_scan(b).await.unwrap();
    let d = store.scan_detail(b).await.unwrap();
    assert_eq!(d.scan.state, ScanState::Aborted);
    assert_eq!(d.readings.len(), 2);

    let all = store.list_scans(&ScanFilter::default()).await.unwrap();
    assert_eq!(all.iter().map(|s| s.id).collect::<Vec<_>>(), [c, b, a]);
    let of_a = store
        .list_scans(&ScanFilter {
            sample: Some("A".into()),
            ..ScanFilter::default()
        })
        .await
        .unwrap();
    assert_eq!(of_a.iter().map(|s| s.id).collect::<Vec<_>>(), [c, a]);
    let complete = store
        .list_scans(&ScanFilter {
            state: Some(ScanState::Complete),
            ..ScanFilter::default()
        })
        .await
        .unwrap();
    assert_eq!(complete.len(), 1);
    assert_eq!(complete[0].reading_count, GEOMETRY_COUNT);
    let one = store
        .list_scans(&ScanFilter {
            limit: 1,
            ..ScanFilter::default()
        })
        .await
        .unwrap();
    assert_eq!(one.len(), 1);
}

#[tokio::test]
async fn interrupted_scans_are_failed_at_start_up_keeping_readings() {
    let store = Store::open_in_memory().await.unwrap();
    let reference = complete_reference(&store).await;
    let requested = store.request_scan("A", reference).await.unwrap();
    let (measuring, _) = measuring_scan(&store, reference, "B", 7).await;
    let (complete, _) = measuring_scan(&store, reference, "C", 14).await;
    store.complete_scan(complete).await.unwrap();
    let ids = store.mark_interrupted_scans_failed().await.unwrap();
    assert_eq!(ids, [requested, measuring]);
    for id in ids {
        let d = store.scan_detail(id).await.unwrap();
        assert_eq!(d.scan.state, ScanState::Failed);
        assert_eq!(d.scan.reason.as_deref(), Some(scans::INTERRUPTED_REASON));
    }
    assert_eq!(
        store.scan_detail(measuring).await.unwrap().readings.len(),
        7
    );
    assert_eq!(
        store.scan_detail(complete).await.unwrap().scan.state,
        ScanState::Complete
    );
    assert!(
        store
            .mark_interrupted_scans_failed()
            .await
            .unwrap()
            .is_empty()
    );
}

#[tokio::test]
async fn a_batch_of_readings_is_stored_whole_or_not_at_all() {
    let store = Store::open_in_memory().await.unwrap();
    let reference = complete_reference(&store).await;
    let (scan, _) = measuring_scan(&store, reference, "S", 0).await;
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let frames: Vec<Vec<u8>> = GEOMETRIES.iter().map(frame).collect();
    let mut batch: Vec<NewReading> = GEOMETRIES
        .iter()
        .zip(&frames)
        .map(|(g, f)| NewReading {
            device: g.device,
            geometry: g,
            values: values_for(g, &mut rng),
            raw_frame: f,
        })
        .collect();
    // The last one repeats the first geometry: the whole batch must roll back.
    let dup = batch[0];
    let last = std::mem::replace(&mut batch[13], dup);
    let e = store.add_readings_tx(scan, &batch).await.unwrap_err();
    assert!(matches!(e, StoreError::DuplicateReading { .. }), "{e}");
    assert_eq!(store.scan_detail(scan).await.unwrap().readings.len(), 0);

    batch[13] = last;
    let ids = store.add_readings_tx(scan, &batch).await.unwrap();
    assert_eq!(ids.len(), GEOMETRY_COUNT);
    store.complete_scan(scan).await.unwrap();
    let d = store.scan_detail(scan).await.unwrap();
    for (r, n) in d.readings.iter().zip(&batch) {
        assert_eq!(r.values, n.values);
        assert_eq!(r.raw_frame, n.raw_frame);
    }
    let e = store.add_readings_tx(scan, &batch[..1]).await.unwrap_err();
    assert!(matches!(
        e,
        StoreError::ScanState {
            state: ScanState::Complete,
            ..
        }
    ));
}

#[tokio::test]
async fn an_import_is_stored_whole_or_not_at_all() {
    let store = Store::open_in_memory().await.unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let frames: Vec<Vec<u8>> = GEOMETRIES.iter().map(frame).collect();
    let set = |rng: &mut ChaCha8Rng, offset: f64| -> Vec<ReadingValues> {
        GEOMETRIES
            .iter()
            .map(|g| match values_for(g, rng) {
                ReadingValues::Spectrum(s) => ReadingValues::Spectrum(s.map(|x| offset + x)),
                ReadingValues::Intensity(x) => ReadingValues::Intensity(offset + x),
            })
            .collect()
    };
    let (reference_values, sample_values) = (set(&mut rng, 0.5), set(&mut rng, 0.0));
    let batch = |values: &[ReadingValues]| -> Vec<NewReading<'_>> {
        GEOMETRIES
            .iter()
            .zip(values)
            .zip(&frames)
            .map(|((g, v), f)| NewReading {
                device: g.device,
                geometry: g,
                values: *v,
                raw_frame: f,
            })
            .collect()
    };
    let (reference, sample) = (batch(&reference_values), batch(&sample_values));
    let provenance = Provenance {
        source: Source::Imported,
        source_detail: Some("x.scan.json".into()),
        ..Provenance::unknown()
    };
    const TABLES: [&str; 5] = [
        "reference_sets",
        "reference_readings",
        "samples",
        "scans",
        "readings",
    ];
    async fn counts(store: &Store) -> Vec<i64> {
        let mut out = Vec::new();
        for t in TABLES {
            out.push(store.count_rows(t).await.unwrap());
        }
        out
    }
    let empty = counts(&store).await;

    // Refused before anything is written: a missing geometry, a repeated one.
    let e = store
        .import_scan("S", "N9 (imported)", &provenance, &reference, &sample[..13])
        .await
        .unwrap_err();
    assert!(
        e.to_string()
            .contains("holds 13 of 14 readings (missing sra-60)"),
        "{e}"
    );
    let mut repeated = sample.clone();
    repeated[13] = repeated[12];
    let e = store
        .import_scan("S", "N9 (imported)", &provenance, &reference, &repeated)
        .await
        .unwrap_err();
    assert!(matches!(e, StoreError::DuplicateReading { .. }), "{e}");
    assert_eq!(counts(&store).await, empty);

    // A failure inside the transaction, at the very last row (the disk refuses it): nothing
    // of the reference set, the sample, the scan or the 27 rows before it stays.
    sqlx::query(
        "CREATE TRIGGER refuse_last BEFORE INSERT ON readings WHEN NEW.geometry = 'sra-60'
         BEGIN SELECT RAISE(ABORT, 'disk I/O error'); END",
    )
    .execute(&store.writer)
    .await
    .unwrap();
    let e = store
        .import_scan("S", "N9 (imported)", &provenance, &reference, &sample)
        .await
        .unwrap_err();
    assert!(e.to_string().contains("disk I/O error"), "{e}");
    assert_eq!(counts(&store).await, empty);

    // Without the fault it lands complete, with its provenance.
    sqlx::query("DROP TRIGGER refuse_last")
        .execute(&store.writer)
        .await
        .unwrap();
    let (reference_id, scan) = store
        .import_scan("S", "N9 (imported)", &provenance, &reference, &sample)
        .await
        .unwrap();
    let d = store.scan_detail(scan).await.unwrap();
    assert_eq!(d.scan.state, ScanState::Complete);
    let provenance = provenance.clone().settled(true);
    assert_eq!(d.scan.provenance, provenance);
    assert_eq!(d.reference.reference.id, reference_id);
    assert_eq!(d.reference.reference.provenance, provenance);
    assert_eq!(d.reference.readings.len(), GEOMETRY_COUNT);
    for (r, n) in d.readings.iter().zip(&sample) {
        assert_eq!(r.values, n.values);
        assert_eq!(r.raw_frame, n.raw_frame);
    }
}

#[tokio::test]
async fn processed_scans_and_fit_runs() {
    let store = Store::open_in_memory().await.unwrap();
    let reference = complete_reference(&store).await;
    let (scan, _) = measuring_scan(&store, reference, "S", 14).await;
    let measured = brdf(5);
    let e = store
        .add_processed(scan, SpecularStrategy::Ratio, &measured)
        .await
        .unwrap_err();
    assert_eq!(
        e.to_string(),
        format!("scan {scan} is measuring, not complete: cannot store its processed BRDF")
    );
    store.complete_scan(scan).await.unwrap();
    let p = store
        .add_processed(scan, SpecularStrategy::Ratio, &measured)
        .await
        .unwrap();
    let e = store
        .add_processed(scan, SpecularStrategy::Ratio, &measured)
        .await
        .unwrap_err();
    assert!(matches!(e, StoreError::AlreadyProcessed { .. }), "{e}");
    let p9 = store
        .add_processed(scan, SpecularStrategy::PaperEq9, &brdf(6))
        .await
        .unwrap();
    let back = store.processed(p).await.unwrap();
    assert_eq!(back.brdf, measured);
    assert_eq!(back.scan, scan);
    assert_eq!(back.specular, SpecularStrategy::Ratio);
    assert_eq!(store.processed_for_scan(scan).await.unwrap().len(), 2);
    let mut bad = measured;
    bad.values[13][30] = f64::NAN;
    let e = store
        .add_processed(scan, SpecularStrategy::Ratio, &bad)
        .await
        .unwrap_err();
    assert!(
        e.to_string()
            .contains("at sra-60: the BRDF at 700 nm is NaN"),
        "{e}"
    );

    // queue → start → finish, with evaluation.
    let f1 = store
        .queue_fit(p, &new_fit(CostFunction::Cf1))
        .await
        .unwrap();
    let f2 = store
        .queue_fit(p9, &new_fit(CostFunction::Cf2))
        .await
        .unwrap();
    let f3 = store
        .queue_fit(p, &new_fit(CostFunction::M2))
        .await
        .unwrap();
    let e = store
        .queue_fit(ProcessedId(999), &new_fit(CostFunction::Cf1))
        .await
        .unwrap_err();
    assert_eq!(
        e.to_string(),
        "processed scan 999 does not exist in the store"
    );
    assert_eq!(
        store
            .queued_fits()
            .await
            .unwrap()
            .iter()
            .map(|f| f.id)
            .collect::<Vec<_>>(),
        [f1, f2, f3]
    );
    // The SRA reading model of each fit (migration 0015): from its settings, flat by default.
    let sra_of = |id: FitRunId| {
        sqlx::query_scalar::<_, String>("SELECT sra FROM fit_runs WHERE id = $1")
            .bind(id.0)
            .fetch_one(&store.reader)
    };
    assert_eq!(sra_of(f1).await.unwrap(), "flat");
    let mut lum = new_fit(CostFunction::Cf2);
    lum.settings["sra"] = serde_json::json!({"model": "luminance"});
    assert_eq!(
        lum.sra_model().unwrap(),
        crate::sra_reading::SraModel::Luminance
    );
    let mut bad = new_fit(CostFunction::Cf2);
    bad.settings["sra"] = serde_json::json!({"model": "grey"});
    let e = store.queue_fit(p, &bad).await.unwrap_err().to_string();
    assert!(e.contains("sra"), "{e}");
    let outcome = FitResult {
        cost: 0.012_345_678_901_234_5,
        params: serde_json::json!({"kd": vec![0.5; BANDS], "ks": 0.3, "alpha": 0.2, "ior": 1.5}),
        best_cost_per_generation: vec![0.5, 0.1, 0.012_345_678_901_234_5],
        evaluations: 12_800,
        generations: 3,
        wall_ms: 17.25,
    };
    let de: [f64; GEOMETRY_COUNT] = std::array::from_fn(|g| g as f64 + 0.5);
    let e = store.finish_fit(f1, &outcome, &de).await.unwrap_err();
    assert_eq!(
        e.to_string(),
        format!("fit run {f1} is queued, not running: cannot finish it")
    );
    store.start_fit(f1).await.unwrap();
    assert!(store.start_fit(f1).await.is_err());
    let mut bad_de = de;
    bad_de[4] = f64::NAN;
    let e = store.finish_fit(f1, &outcome, &bad_de).await.unwrap_err();
    assert!(e.to_string().contains("ΔE00 at 15as45 is NaN"), "{e}");
    store.finish_fit(f1, &outcome, &de).await.unwrap();
    let d = store.fit_detail(f1).await.unwrap();
    assert_eq!(d.run.status, FitStatus::Done);
    assert_eq!(d.run.result.as_ref(), Some(&outcome));
    assert_eq!(d.run.seed, u64::MAX);
    assert_eq!(d.run.settings, new_fit(CostFunction::Cf1).settings);
    assert_eq!(d.run.cost_function, CostFunction::Cf1);
    assert_eq!(d.run.specular, SpecularStrategy::Ratio);
    assert_eq!(d.run.scan, scan);
    let ev = d.evaluation.unwrap();
    assert_eq!(ev.per_geometry, de);
    // 0.5 … 13.5: mean and median 7, max 13.5; diffuse 0.5 … 11.5; specular 12.5, 13.5.
    assert_eq!((ev.all.mean, ev.all.median, ev.all.max), (7.0, 7.0, 13.5));
    assert_eq!(
        (ev.diffuse.mean, ev.diffuse.median, ev.diffuse.max),
        (6.0, 6.0, 11.5)
    );
    assert_eq!(
        (
            ev.specular.unwrap().mean,
            ev.specular.unwrap().median,
            ev.specular.unwrap().max
        ),
        (13.0, 13.0, 13.5)
    );
    assert!(store.cancel_fit(f1).await.is_err());

    // fail and cancel; a crash leaves one running, which start-up re-queues.
    store
        .fail_fit(f2, "non-finite measured data at sra-20")
        .await
        .unwrap();
    let d2 = store.fit_detail(f2).await.unwrap();
    assert_eq!(d2.run.status, FitStatus::Failed);
    assert_eq!(
        d2.run.error.as_deref(),
        Some("non-finite measured data at sra-20")
    );
    assert_eq!(d2.run.result, None);
    assert_eq!(d2.evaluation, None);
    store.start_fit(f3).await.unwrap();
    assert_eq!(store.requeue_interrupted_fits().await.unwrap(), [f3]);
    assert_eq!(
        store.fit_detail(f3).await.unwrap().run.status,
        FitStatus::Queued
    );
    store.cancel_fit(f3).await.unwrap();
    let e = store.fail_fit(f3, "late").await.unwrap_err();
    assert!(matches!(
        e,
        StoreError::FitState {
            status: FitStatus::Cancelled,
            ..
        }
    ));
    let fits = store.fits_for_scan(scan).await.unwrap();
    assert_eq!(
        fits.iter().map(|f| (f.id, f.status)).collect::<Vec<_>>(),
        [
            (f1, FitStatus::Done),
            (f2, FitStatus::Failed),
            (f3, FitStatus::Cancelled)
        ]
    );
    assert!(store.queued_fits().await.unwrap().is_empty());
    assert!(matches!(
        store.fit_detail(FitRunId(77)).await.unwrap_err(),
        StoreError::NotFound { .. }
    ));
}

#[tokio::test]
async fn the_newest_measured_reference_skips_imported_ones() {
    let store = Store::open_in_memory().await.unwrap();
    let measured = complete_reference(&store).await;
    // A newer, complete reference set that came with an import.
    let imported = store
        .begin_reference("Munsell N9 (imported)", None)
        .await
        .unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    for g in &GEOMETRIES {
        let v = match values_for(g, &mut rng) {
            ReadingValues::Spectrum(s) => ReadingValues::Spectrum(s.map(|x| 0.7 + x * 0.1)),
            ReadingValues::Intensity(x) => ReadingValues::Intensity(0.2 + x),
        };
        store
            .add_reference_reading(imported, g.device, g, &v, b"")
            .await
            .unwrap();
    }
    store
        .set_reference_provenance(
            imported,
            &Provenance {
                source: Source::Imported,
                ..Provenance::unknown()
            },
        )
        .await
        .unwrap();
    store.complete_reference(imported).await.unwrap();
    assert_eq!(
        store.latest_reference().await.unwrap().unwrap().id,
        imported
    );
    // The import is known by its provenance, not its name.
    let latest = store.latest_measured_reference().await.unwrap().unwrap();
    assert_eq!(latest.id, measured);
    let also_measured = store
        .begin_reference("N9 (imported) by name only", None)
        .await
        .unwrap();
    for g in &GEOMETRIES {
        let v = values_for(g, &mut rng);
        store
            .add_reference_reading(also_measured, g.device, g, &v, b"")
            .await
            .unwrap();
    }
    store.complete_reference(also_measured).await.unwrap();
    assert_eq!(
        store.latest_measured_reference().await.unwrap().unwrap().id,
        also_measured
    );
}

#[tokio::test]
async fn the_sql_views_decode_every_stored_value_bit_for_bit() {
    let store = Store::open_in_memory().await.unwrap();
    let reference = complete_reference(&store).await;
    let (scan, mut stored) = measuring_scan(&store, reference, "S", 13).await;
    // The last geometry (sra-60) with an edge value, and edge values in one spectrum: zero,
    // negative zero, the smallest subnormal, a large and a negative value.
    let edge = ReadingValues::Intensity(f64::MIN_POSITIVE / 3.0);
    let g = &GEOMETRIES[13];
    store
        .add_reading(scan, g.device, g, &edge, b"")
        .await
        .unwrap();
    stored.push(edge);
    store.complete_scan(scan).await.unwrap();
    let (scan2, _) = measuring_scan(&store, reference, "T", 0).await;
    let mut spectrum = [0.25; BANDS];
    spectrum[..5].copy_from_slice(&[0.0, -0.0, 5e-324, 1.7e308, -1.5]);
    let g0 = &GEOMETRIES[0];
    store
        .add_reading(
            scan2,
            g0.device,
            g0,
            &ReadingValues::Spectrum(spectrum),
            b"",
        )
        .await
        .unwrap();

    let rows: Vec<(i64, String, i64, Option<i64>, f64)> = sqlx::query_as(
        "SELECT scan_id, geometry, band, nm, value FROM reading_values
         ORDER BY scan_id, reading_id, band",
    )
    .fetch_all(&store.reader)
    .await
    .unwrap();
    let mut expected: Vec<(i64, String, i64, Option<i64>, f64)> = Vec::new();
    for (g, v) in GEOMETRIES.iter().zip(&stored) {
        for (band, x) in v.as_slice().iter().enumerate() {
            let nm = (g.device == Device::MaT12).then_some(400 + 10 * band as i64);
            expected.push((scan.0, g.name.to_string(), band as i64, nm, *x));
        }
    }
    for (band, x) in spectrum.iter().enumerate() {
        expected.push((
            scan2.0,
            g0.name.to_string(),
            band as i64,
            Some(400 + 10 * band as i64),
            *x,
        ));
    }
    assert_eq!(rows.len(), expected.len());
    for (got, want) in rows.iter().zip(&expected) {
        assert_eq!(
            (&got.0, &got.1, got.2, got.3),
            (&want.0, &want.1, want.2, want.3)
        );
        assert_eq!(got.4.to_bits(), want.4.to_bits(), "{got:?} vs {want:?}");
    }

    // The reference readings and the processed BRDF, likewise.
    let refs: Vec<(i64, f64)> = sqlx::query_as(
        "SELECT band, value FROM reference_reading_values WHERE geometry = '45as45' ORDER BY band",
    )
    .fetch_all(&store.reader)
    .await
    .unwrap();
    let detail = store.reference_detail(reference).await.unwrap();
    let want = detail
        .readings
        .iter()
        .find(|r| r.geometry.name == "45as45")
        .unwrap();
    assert_eq!(refs.len(), BANDS);
    for ((band, v), w) in refs.iter().zip(want.values.as_slice()) {
        assert_eq!(v.to_bits(), w.to_bits(), "band {band}");
    }
    let m = brdf(4);
    let p = store
        .add_processed(scan, SpecularStrategy::Ratio, &m)
        .await
        .unwrap();
    let values: Vec<(i64, i64, f64)> = sqlx::query_as(
        "SELECT geometry_index, band, value FROM processed_values WHERE processed_id = $1
         ORDER BY geometry_index, band",
    )
    .bind(p.0)
    .fetch_all(&store.reader)
    .await
    .unwrap();
    assert_eq!(values.len(), GEOMETRY_COUNT * BANDS);
    for (g, b, v) in values {
        assert_eq!(
            v.to_bits(),
            m.values[g as usize][b as usize].to_bits(),
            "{g} {b}"
        );
    }
}

#[tokio::test]
async fn the_schema_backs_up_the_verbs() {
    let store = Store::open_in_memory().await.unwrap();
    let reference = complete_reference(&store).await;
    let (scan, _) = measuring_scan(&store, reference, "S", 0).await;
    let insert = |device: &'static str, geometry: &'static str, len: usize| {
        sqlx::query(
            "INSERT INTO readings (scan_id, device, geometry, values_f64le, raw_frame,
                                   received_at_ms) VALUES ($1, $2, $3, $4, x'', 0)",
        )
        .bind(scan.0)
        .bind(device)
        .bind(geometry)
        .bind(vec![0u8; len])
    };
    // The CHECK's geometry lists are the geometry table's, device by device.
    for g in &GEOMETRIES {
        let len = if g.device == Device::MaT12 { 248 } else { 8 };
        let wrong = if g.device == Device::MaT12 {
            "sra"
        } else {
            "ma_t12"
        };
        let wrong_len = if g.device == Device::MaT12 { 8 } else { 248 };
        assert!(
            insert(wrong, g.name, wrong_len)
                .execute(&store.writer)
                .await
                .is_err()
        );
        assert!(
            insert(g.device.key(), g.name, len + 8)
                .execute(&store.writer)
                .await
                .is_err()
        );
        insert(g.device.key(), g.name, len)
            .execute(&store.writer)
            .await
            .unwrap();
    }
    assert!(
        insert("ma_t12", "15as99", 248)
            .execute(&store.writer)
            .await
            .is_err()
    );
    // Foreign keys are on.
    let e = sqlx::query(
        "INSERT INTO scans (sample_id, reference_id, state, requested_at_ms)
         VALUES (999, 999, 'requested', 0)",
    )
    .execute(&store.writer)
    .await
    .unwrap_err();
    assert!(backend::is_foreign_key_violation(&e), "{e}");
}

#[tokio::test]
async fn concurrent_device_tasks_write_through_one_writer() {
    let store = Store::open_in_memory().await.unwrap();
    let reference = complete_reference(&store).await;
    let (scan, _) = measuring_scan(&store, reference, "S", 0).await;
    let task = |store: Store, device: Device| async move {
        for g in crate::geometry::of_device(device) {
            store
                .add_reading(
                    scan,
                    device,
                    g,
                    &values_for(g, &mut ChaCha8Rng::seed_from_u64(1)),
                    &frame(g),
                )
                .await
                .unwrap();
            tokio::task::yield_now().await;
        }
    };
    let a = tokio::spawn(task(store.clone(), Device::MaT12));
    let b = tokio::spawn(task(store.clone(), Device::Sra));
    a.await.unwrap();
    b.await.unwrap();
    store.complete_scan(scan).await.unwrap();
    // Nothing lost or doubled by the interleaving: all 14, each with its own values and frame.
    let d = store.scan_detail(scan).await.unwrap();
    assert_eq!(d.scan.state, ScanState::Complete);
    assert_eq!(d.scan.reading_count, 14);
    assert_eq!(d.readings.len(), 14);
    let mut names: Vec<&str> = d.readings.iter().map(|r| r.geometry.name).collect();
    names.sort_unstable();
    let mut want: Vec<&str> = GEOMETRIES.iter().map(|g| g.name).collect();
    want.sort_unstable();
    assert_eq!(names, want);
    for r in &d.readings {
        assert_eq!(
            r.values,
            values_for(r.geometry, &mut ChaCha8Rng::seed_from_u64(1))
        );
        assert_eq!(r.raw_frame, frame(r.geometry));
    }
}

/// `_sqlx_migrations` as (version, checksum, installed_on), in order.
async fn applied(store: &Store) -> Vec<(i64, Vec<u8>, String)> {
    sqlx::query(
        "SELECT version, checksum, CAST(installed_on AS TEXT) FROM _sqlx_migrations ORDER BY version",
    )
    .fetch_all(&store.writer)
    .await
    .unwrap()
    .iter()
    .map(|r| (r.get(0), r.get(1), r.get(2)))
    .collect()
}

#[tokio::test]
async fn a_file_store_reopens_without_reapplying_migrations() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("brdfd.db");
    let store = Store::open(&path).await.unwrap();
    let pragma = |name: &'static str| {
        let store = store.clone();
        async move {
            sqlx::query(&format!("PRAGMA {name}"))
                .fetch_one(&store.writer)
                .await
                .unwrap()
        }
    };
    assert_eq!(pragma("journal_mode").await.get::<String, _>(0), "wal");
    // 1 = NORMAL.
    assert_eq!(pragma("synchronous").await.get::<i64, _>(0), 1);
    assert_eq!(pragma("foreign_keys").await.get::<i64, _>(0), 1);
    let first = applied(&store).await;
    assert_eq!(first.len(), MIGRATOR.iter().count());
    // Every file in migrations/ is embedded and applied (an independent count of the files).
    let files = std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/migrations"))
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "sql")
        })
        .count();
    assert_eq!(first.len(), files);
    let reference = complete_reference(&store).await;
    let (scan, _) = measuring_scan(&store, reference, "S", 3).await;
    store.close().await;

    let store = Store::open(&path).await.unwrap();
    assert_eq!(applied(&store).await, first, "no migration re-applied");
    assert_eq!(store.integrity_check().await.unwrap(), ["ok"]);
    assert_eq!(store.mark_interrupted_scans_failed().await.unwrap(), [scan]);
    assert_eq!(store.scan_detail(scan).await.unwrap().readings.len(), 3);
    store.close().await;
}

/// A copy of the database file alone, taken once the store closed, is the whole store, even
/// when another connection (a report reading the file, an operator's `sqlite3`) was still
/// open as it closed: the close folds the write-ahead log into the file itself instead of
/// leaving it to the last connection, which may be a read-only one that cannot.
#[tokio::test]
async fn the_file_alone_holds_the_whole_store_once_it_is_closed() {
    use sqlx::Connection;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("brdfd.db");
    let store = Store::open(&path).await.unwrap();
    let reference = complete_reference(&store).await;
    let uid: String = sqlx::query_scalar("SELECT uid FROM sync_identity")
        .fetch_one(&store.writer)
        .await
        .unwrap();
    let mut onlooker = sqlx::SqliteConnection::connect_with(
        &sqlx::sqlite::SqliteConnectOptions::new()
            .filename(&path)
            .read_only(true),
    )
    .await
    .unwrap();
    let _: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM readings")
        .fetch_one(&mut onlooker)
        .await
        .unwrap();
    store.close().await;

    let copy = dir.path().join("copy.db");
    std::fs::copy(&path, &copy).unwrap();
    onlooker.close().await.unwrap();
    let copied = Store::open(&copy).await.unwrap();
    let copied_uid: String = sqlx::query_scalar("SELECT uid FROM sync_identity")
        .fetch_one(&copied.writer)
        .await
        .unwrap();
    assert_eq!(copied_uid, uid, "the copy is of the same store");
    assert_eq!(
        copied.latest_reference().await.unwrap().map(|r| r.id),
        Some(reference)
    );
    let closed: Option<i64> = sqlx::query_scalar(
        "SELECT closed_at_ms FROM sync_lineage ORDER BY seq DESC LIMIT 1 OFFSET 1",
    )
    .fetch_one(&copied.writer)
    .await
    .unwrap();
    assert!(
        closed.is_some(),
        "the copy knows its original was closed cleanly"
    );
    copied.close().await;
}

#[tokio::test]
async fn a_store_that_applied_an_earlier_wording_of_a_reworded_migration_opens() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("brdfd.db");
    let store = Store::open(&path).await.unwrap();
    let reference = complete_reference(&store).await;
    let (scan, _) = measuring_scan(&store, reference, "S", 3).await;
    let current = applied(&store).await;
    // As a store written before the rewording recorded it.
    for (version, earlier) in super::REWORDED_MIGRATIONS {
        sqlx::query("UPDATE _sqlx_migrations SET checksum = ? WHERE version = ?")
            .bind(hex::decode(earlier).unwrap())
            .bind(version)
            .execute(&store.writer)
            .await
            .unwrap();
    }
    assert_ne!(applied(&store).await, current);
    store.close().await;

    let store = Store::open(&path).await.unwrap();
    assert_eq!(
        applied(&store).await,
        current,
        "the current checksums are recorded"
    );
    assert_eq!(store.scan_detail(scan).await.unwrap().readings.len(), 3);
    store.close().await;

    // A checksum that is neither wording is still refused.
    let store = Store::open(&path).await.unwrap();
    sqlx::query("UPDATE _sqlx_migrations SET checksum = x'00' WHERE version = ?")
        .bind(super::REWORDED_MIGRATIONS[0].0)
        .execute(&store.writer)
        .await
        .unwrap();
    store.close().await;
    let refused = Store::open(&path).await.unwrap_err();
    assert!(refused.to_string().contains("15"), "{refused}");
}

#[tokio::test]
async fn spectra_round_trip_bit_for_bit_through_a_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("exact.db");
    let store = Store::open(&path).await.unwrap();
    let reference = complete_reference(&store).await;
    let scan = store.request_scan("exact", reference).await.unwrap();
    store.start_measuring(scan).await.unwrap();
    // Awkward values: full 53-bit mantissas, subnormals, extremes, negative zero.
    let mut rng = ChaCha8Rng::seed_from_u64(2024);
    let mut written = Vec::new();
    for g in &GEOMETRIES {
        let v = match g.device {
            Device::MaT12 => {
                let mut s: Spectrum =
                    std::array::from_fn(|_| f64::from_bits(rng.random::<u64>() >> 2));
                s[0] = 5e-324;
                s[1] = -0.0;
                s[2] = f64::MAX;
                s[3] = 0.1 + 0.2;
                ReadingValues::Spectrum(s)
            }
            Device::Sra => ReadingValues::Intensity(1.0 / 3.0 + g.index as f64),
        };
        store
            .add_reading(scan, g.device, g, &v, &frame(g))
            .await
            .unwrap();
        written.push(v);
    }
    store.complete_scan(scan).await.unwrap();
    let measured = brdf(11);
    let p = store
        .add_processed(scan, SpecularStrategy::Ratio, &measured)
        .await
        .unwrap();
    store.close().await;

    let store = Store::open(&path).await.unwrap();
    let d = store.scan_detail(scan).await.unwrap();
    for (r, w) in d.readings.iter().zip(&written) {
        let (a, b) = (r.values.as_slice(), w.as_slice());
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(b) {
            assert_eq!(x.to_bits(), y.to_bits(), "{}", r.geometry.name);
        }
    }
    let back = store.processed(p).await.unwrap().brdf;
    for (x, y) in back
        .values
        .as_flattened()
        .iter()
        .zip(measured.values.as_flattened())
    {
        assert_eq!(x.to_bits(), y.to_bits());
    }
    assert_eq!(store.integrity_check().await.unwrap(), ["ok"]);
    store.close().await;
}

#[tokio::test]
async fn an_unwritable_path_names_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("no-such-dir").join("brdfd.db");
    let e = Store::open(&path).await.unwrap_err();
    assert!(matches!(e, StoreError::Open { .. }), "{e}");
    assert!(e.to_string().contains("no-such-dir"), "{e}");
}

/// A scan from an instrument's own software: no tile (the instrument's calibration) and no SRA
/// readings. It imports with its 12 readings, reads back as such, and its fit's evaluation
/// keeps the 12 geometries and no specular summary.
#[tokio::test]
async fn instrument_calibration_scans_without_sra_readings() {
    let store = Store::open_in_memory().await.unwrap();
    let spectrum = |g: usize| -> Spectrum {
        std::array::from_fn(|b| 0.2 + 0.01 * g as f64 + 0.001 * b as f64)
    };
    let readings: Vec<NewReading<'_>> = crate::geometry::ma_t12()
        .iter()
        .map(|g| NewReading {
            device: Device::MaT12,
            geometry: g,
            values: ReadingValues::Spectrum(spectrum(g.index)),
            raw_frame: &[],
        })
        .collect();
    let provenance = Provenance::unknown();
    let import = ImportedScan {
        sample_name: "PAR_PW_RO_NG_1",
        reference_name: "instrument calibration",
        provenance: &provenance,
        reference_readings: None,
        readings: &readings,
        taken_at_ms: Some(1_723_000_000_000),
        textures: &[],
    };
    let (reference, scan) = store.import(&import).await.unwrap();
    let detail = store.scan_detail(scan).await.unwrap();
    assert!(detail.reference.reference.instrument_calibration);
    assert_eq!(detail.reference.reference.id, reference);
    assert!(!detail.scan.specular_readings);
    assert_eq!(detail.scan.requested_at_ms, 1_723_000_000_000);
    let file = detail.to_scan().unwrap();
    assert!(file.reference.is_none() && file.readings.sra.is_none());
    assert_eq!(file.readings.ma_t12[11], spectrum(11));

    // One SRA reading without the other is an incomplete scan; a tile is refused without the
    // SRA readings the scan has.
    let mut with_one_sra = readings.clone();
    with_one_sra.push(NewReading {
        device: Device::Sra,
        geometry: by_name("sra-20").unwrap(),
        values: ReadingValues::Intensity(1.0),
        raw_frame: &[],
    });
    let e = store
        .import(&ImportedScan {
            readings: &with_one_sra,
            ..import
        })
        .await
        .unwrap_err();
    assert!(e.to_string().contains("sra-60"), "{e}");

    let measured = crate::processing::process(&file, &Default::default()).unwrap();
    let p = store
        .add_processed(scan, SpecularStrategy::Ratio, &measured)
        .await
        .unwrap();
    let back = store.processed(p).await.unwrap();
    assert_eq!(back.brdf.geometries, crate::geometry::GeometrySet::MA_T12);
    assert_eq!(back.brdf, measured);
    let f = store
        .queue_fit(p, &new_fit(CostFunction::Cf2))
        .await
        .unwrap();
    store.start_fit(f).await.unwrap();
    let outcome = FitResult {
        cost: 0.1,
        params: serde_json::json!({"kd": vec![0.1; BANDS], "ks": 0.2, "alpha": 0.3, "ior": 1.5}),
        best_cost_per_generation: vec![0.2, 0.1],
        evaluations: 10,
        generations: 2,
        wall_ms: 1.0,
    };
    let mut de = [f64::NAN; GEOMETRY_COUNT];
    for (g, v) in de.iter_mut().enumerate().take(12) {
        *v = 0.5 + g as f64 * 0.1;
    }
    store
        .finish_fit_with(
            f,
            &outcome,
            &de,
            crate::geometry::GeometrySet::MA_T12,
            crate::colour::Colorimetry::default(),
        )
        .await
        .unwrap();
    let d = store.fit_detail(f).await.unwrap();
    let e = d.evaluation.unwrap();
    assert!(e.specular.is_none());
    assert!(e.per_geometry[12].is_nan() && e.per_geometry[13].is_nan());
    assert!((e.all.mean - (0.5 + 0.55)).abs() < 1e-12, "{:?}", e.all);
    assert!(d.specular_delta_l.is_none());
}

#[tokio::test]
async fn each_instrument_of_a_scan_says_its_origin() {
    let store = Store::open_in_memory().await.unwrap();
    let origins = |d: &ScanDetail| {
        let p = &d.scan.provenance;
        (p.ma_t12.origin, p.sra.origin, p.simulated(), p.real())
    };
    // An instrument export without SRA readings: the MA-T12 imported, the SRA absent.
    let readings: Vec<NewReading<'_>> = crate::geometry::ma_t12()
        .iter()
        .map(|g| NewReading {
            device: Device::MaT12,
            geometry: g,
            values: ReadingValues::Spectrum([0.3; BANDS]),
            raw_frame: &[],
        })
        .collect();
    let provenance = Provenance {
        source: Source::Imported,
        source_detail: Some("paint.xlsx".into()),
        ..Provenance::unknown()
    };
    let (_, export) = store
        .import(&ImportedScan {
            sample_name: "paint",
            reference_name: "instrument calibration",
            provenance: &provenance,
            reference_readings: None,
            readings: &readings,
            taken_at_ms: None,
            textures: &[],
        })
        .await
        .unwrap();
    let d = store.scan_detail(export).await.unwrap();
    assert_eq!(
        origins(&d),
        (
            InstrumentOrigin::Imported,
            InstrumentOrigin::Absent,
            false,
            true
        )
    );
    let json = serde_json::to_value(&d.scan).unwrap();
    assert_eq!(json["provenance"]["ma_t12"]["origin"], "imported");
    assert_eq!(json["provenance"]["sra"]["origin"], "absent");
    assert_eq!(
        d.scan.provenance.summary(),
        "imported: paint.xlsx",
        "the file is named once"
    );

    // The daemon's scans: on simulated instruments, then on real ones.
    let reference = complete_reference(&store).await;
    for (simulated, expect) in [
        (true, InstrumentOrigin::Simulated),
        (false, InstrumentOrigin::Measured),
    ] {
        let (scan, _) = measuring_scan(&store, reference, "S", GEOMETRY_COUNT).await;
        store.complete_scan(scan).await.unwrap();
        let one = InstrumentProvenance {
            simulated: Some(simulated),
            ..InstrumentProvenance::unknown()
        };
        let p = Provenance {
            ma_t12: one.clone(),
            sra: one,
            source: Source::Measured,
            source_detail: None,
        };
        store.set_scan_provenance(scan, &p).await.unwrap();
        let d = store.scan_detail(scan).await.unwrap();
        assert_eq!(origins(&d), (expect, expect, simulated, !simulated));
    }
    // A replay is simulated whatever its flag says.
    assert_eq!(
        InstrumentOrigin::of(Some(false), Source::Replay, true),
        InstrumentOrigin::Simulated
    );
}
