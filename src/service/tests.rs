//! Unit tests of the service's own rules; the whole daemon is tested end to end in `tests/`.

use super::*;
use crate::store::ScanState;
use drivers::Instrument;

/// Claims the instruments as the orchestrator does (`acquisition.rs`).
fn claim(s: &Service, operation: Operation) -> Result<acquisition::BusyClaim, ServiceError> {
    s.inner.acquisition.claim(operation)
}

/// Whether a request would find the instruments free.
fn check_idle(s: &Service) -> Result<(), ServiceError> {
    s.inner.acquisition.check_idle()
}

async fn service() -> Service {
    service_on(
        Store::open_in_memory().await.unwrap(),
        // No cross-validation: 12 more real fits per fit, which these tests do not read.
        ServiceSettings {
            crossval: false,
            ..ServiceSettings::default()
        },
        ServiceOptions::default(),
    )
    .await
}

/// A service on `store` with simulated instruments.
async fn service_on(store: Store, settings: ServiceSettings, options: ServiceOptions) -> Service {
    let devices = Devices::simulated(
        mock_devices::recordings::playlist(Instrument::MaT12).unwrap(),
        mock_devices::recordings::playlist(Instrument::Sra).unwrap(),
        &mock_devices::ReplayOptions::strict().accelerated(),
        [None, None],
    )
    .unwrap();
    Service::start(store, devices, settings, options)
        .await
        .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_instruments_are_claimed_by_one_operation_at_a_time() {
    let s = service().await;
    let first = claim(&s, Operation::Scan { scan: ScanId(3) }).unwrap();
    let e = claim(
        &s,
        Operation::Reference {
            reference: ReferenceId(1),
        },
    )
    .unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.starts_with("the instruments are busy: scan 3 is in progress"),
        "{msg}"
    );
    assert!(msg.contains("brdfd abort"), "{msg}");
    assert!(matches!(check_idle(&s), Err(ServiceError::Busy { .. })));
    // Abort reaches the claimant.
    assert_eq!(s.abort().unwrap(), Operation::Scan { scan: ScanId(3) });
    tokio::time::timeout(Duration::from_secs(1), first.notified())
        .await
        .expect("abort notified");
    drop(first);
    assert!(check_idle(&s).is_ok());
    assert!(matches!(s.abort(), Err(ServiceError::Idle)));
    s.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_task_that_panics_frees_the_instruments() {
    let s = service().await;
    let held = claim(&s, Operation::Scan { scan: ScanId(4) }).unwrap();
    assert!(check_idle(&s).is_err());
    let task = tokio::spawn(async move {
        let _claim = held;
        panic!("a bug in the scan task");
    });
    assert!(task.await.unwrap_err().is_panic());
    assert!(check_idle(&s).is_ok(), "the claim outlived its task");
    assert!(matches!(s.abort(), Err(ServiceError::Idle)));
    s.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn scans_are_refused_before_a_reference_and_after_shutdown() {
    let s = service().await;
    assert!(matches!(
        s.request_scan("T.Early").await,
        Err(ServiceError::NoReference)
    ));
    assert!(matches!(
        s.request_scan("  ").await,
        Err(ServiceError::BadRequest(_))
    ));
    // Nothing was written for the refused requests.
    assert!(
        s.store()
            .list_scans(&Default::default())
            .await
            .unwrap()
            .is_empty()
    );
    assert!(s.stop_keeping_store().await);
    assert!(matches!(
        s.request_reference().await,
        Err(ServiceError::ShuttingDown)
    ));
    s.store().close().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn export_refuses_an_incomplete_scan() {
    let s = service().await;
    let store = s.store().clone();
    let r = store.begin_reference("Munsell N9", None).await.unwrap();
    for g in &crate::geometry::GEOMETRIES {
        let v = match g.device {
            crate::geometry::Device::MaT12 => crate::store::ReadingValues::Spectrum([0.7; 31]),
            crate::geometry::Device::Sra => crate::store::ReadingValues::Intensity(0.2),
        };
        store
            .add_reference_reading(r, g.device, g, &v, &[])
            .await
            .unwrap();
    }
    store.complete_reference(r).await.unwrap();
    let scan = store.request_scan("T.Half", r).await.unwrap();
    store.start_measuring(scan).await.unwrap();
    let e = s.export_scan(scan).await.unwrap_err();
    assert!(
        matches!(
            e,
            ServiceError::NotComplete {
                state: ScanState::Measuring,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("needs all 14 readings"), "{e}");
    s.shutdown().await;
}

#[test]
fn settings_follow_the_configuration() {
    let mut config = Config::default();
    config.fit.seed = 9;
    config.fit.cost_functions = vec![CostFunction::M2];
    let s = ServiceSettings::from_config(&config);
    assert_eq!(s.seed, 9);
    assert_eq!(s.cost_functions, [CostFunction::M2]);
    assert_eq!(s.reference_max_age, config.scan.reference_max_age);
    let f = s.fit_settings(CostFunction::Cf1, Method::Paper, 4);
    assert_eq!(
        (f.cost, f.method, f.seed),
        (CostFunction::Cf1, Method::Paper, 4)
    );
    // Measured scans are fitted under the luminance SRA model unless configured otherwise, the
    // SRA readings balanced under cf1 and m2 and weighed as the paper does under cf2.
    use crate::sra_reading::{SraReading, SraWeight};
    let balanced = SraReading::LUMINANCE.with_weight(SraWeight::Balanced);
    assert_eq!(f.sra, balanced);
    let f = s.fit_settings(CostFunction::Cf2, Method::Separable, 4);
    assert_eq!(f.sra, SraReading::LUMINANCE);
    config.fit.sra = crate::sra_reading::SraModel::Flat;
    let f = ServiceSettings::from_config(&config).fit_settings(CostFunction::Cf2, Method::Paper, 4);
    assert_eq!(f.sra, SraReading::FLAT);
    // `[fit] sra_weight` holds for every cost function; the paper preset weighs as the paper.
    config.fit.sra_weight = Some(SraWeight::Paper);
    let f = ServiceSettings::from_config(&config).fit_settings(CostFunction::M2, Method::Paper, 4);
    assert_eq!(f.sra, SraReading::FLAT);
    config.fit.sra_weight = None;
    config.fit.preset = crate::optimise::Preset::Paper;
    let f = ServiceSettings::from_config(&config).fit_settings(CostFunction::Cf1, Method::Paper, 4);
    assert_eq!(f.sra.weight, SraWeight::Paper);
    // A refit asking for the measured preset gets its weight per cost function.
    let request = RefitRequest {
        preset: Some(crate::optimise::Preset::Measured),
        ..RefitRequest::default()
    };
    let s = ServiceSettings::from_config(&config);
    assert_eq!(
        s.refit_settings(CostFunction::M2, &request).unwrap().sra,
        balanced
    );
    assert_eq!(
        s.refit_settings(CostFunction::Cf2, &request).unwrap().sra,
        SraReading::LUMINANCE
    );
}

/// A refit may ask for the luminance SRA model (`POST /scans/{id}/refit` `{"sra": …}`) on a
/// station configured with the paper's flat one: the fit records it in its settings and its
/// detail, and on a scan whose SRA reads the luminance it reproduces the readings' lightness.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_refit_can_ask_for_the_luminance_sra_model() {
    use crate::sra_reading::{SraModel, SraReading};
    use crate::synth::{SraResponse, SynthOptions, paper_samples, synth_scan};
    let mut config = Config::default();
    config.fit.sra = SraModel::Flat;
    let s = service_on(
        Store::open_in_memory().await.unwrap(),
        ServiceSettings::from_config(&config),
        ServiceOptions::default(),
    )
    .await;
    let opts = SynthOptions {
        sra_response: SraResponse::Luminance,
        ..SynthOptions::default()
    };
    let file = synth_scan(&paper_samples()[2], &opts).unwrap();
    let (scan, fits) = s.import_scan(&file).await.unwrap();
    assert_eq!(fits.len(), 3);
    let request: RefitRequest =
        serde_json::from_str(r#"{"cost_functions": ["cf2"], "sra": "luminance"}"#).unwrap();
    assert_eq!(request.sra, Some(SraModel::Luminance));
    let refit = s.refit(scan, &request).await.unwrap();
    assert!(
        s.wait_settled(scan, Duration::from_secs(300))
            .await
            .unwrap()
    );
    // The cf2 fit (cf1's and m2's balance the SRA readings, SCIENCE.md §5.2).
    let flat = s.store().fit_detail(fits[1]).await.unwrap();
    assert_eq!(flat.run.cost_function, CostFunction::Cf2);
    assert_eq!(flat.sra, SraReading::FLAT);
    assert!(flat.run.settings.get("sra").is_none());
    let d = s.store().fit_detail(refit[0]).await.unwrap();
    assert_eq!(
        d.run.status,
        crate::store::FitStatus::Done,
        "{:?}",
        d.run.error
    );
    assert_eq!(d.sra, SraReading::LUMINANCE);
    assert_eq!(d.run.settings["sra"]["model"], "luminance");
    let dl = d.specular_delta_l.unwrap();
    assert!(dl.mean < 0.01, "{dl:?}");
    s.shutdown().await;
}

/// A refit takes its preset, model and Fresnel factor from the request, else from the
/// configuration, records them with the fit, and refuses a model option with the paper's GA.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_refit_chooses_the_preset_model_and_fresnel() {
    use crate::model::{FresnelCosine, ModelKind};
    use crate::optimise::Preset;
    use crate::synth::{SynthOptions, paper_samples, synth_scan};
    let mut config = Config::default();
    config.fit.cost_functions = vec![CostFunction::Cf1];
    config.fit.bootstrap = 0;
    config.fit.crossval = false;
    let s = service_on(
        Store::open_in_memory().await.unwrap(),
        ServiceSettings::from_config(&config),
        ServiceOptions::default(),
    )
    .await;
    let file = synth_scan(&paper_samples()[1], &SynthOptions::default()).unwrap();
    let (scan, fits) = s.import_scan(&file).await.unwrap();
    let paper: RefitRequest = serde_json::from_str(r#"{"preset": "paper"}"#).unwrap();
    assert_eq!(paper.preset, Some(Preset::Paper));
    let paper = s.refit(scan, &paper).await.unwrap();
    let mixed: RefitRequest =
        serde_json::from_str(r#"{"preset": "paper", "fresnel": "exact", "model": "oren-nayar"}"#)
            .unwrap();
    let mixed = s.refit(scan, &mixed).await.unwrap();
    let refused: RefitRequest =
        serde_json::from_str(r#"{"method": "paper", "model": "two-lobe"}"#).unwrap();
    match s.refit(scan, &refused).await {
        Err(ServiceError::BadRequest(m)) => assert!(m.contains("separable"), "{m}"),
        other => panic!("a model option with the paper's GA was not refused: {other:?}"),
    }
    assert!(
        s.wait_settled(scan, Duration::from_secs(300))
            .await
            .unwrap()
    );
    let detail = |id| {
        let s = &s;
        async move { s.store().fit_detail(id).await.unwrap() }
    };
    // The configured default: exact Fresnel, the luminance SRA model.
    let d = detail(fits[0]).await;
    assert_eq!(d.run.settings["fresnel"], FresnelCosine::Exact.name());
    assert_eq!(d.run.settings["sra"]["model"], "luminance");
    // The paper's preset: Schlick on cos θi, the flat SRA model (left out of the settings).
    let d = detail(paper[0]).await;
    assert_eq!(d.run.settings["fresnel"], FresnelCosine::Incidence.name());
    assert!(d.run.settings.get("sra").is_none(), "{}", d.run.settings);
    // A choice beside the preset wins over it.
    let d = detail(mixed[0]).await;
    assert_eq!(
        d.run.status,
        crate::store::FitStatus::Done,
        "{:?}",
        d.run.error
    );
    assert_eq!(d.run.settings["fresnel"], FresnelCosine::Exact.name());
    assert_eq!(d.run.settings["model"], ModelKind::OrenNayar.name());
    assert!(d.run.settings.get("sra").is_none(), "{}", d.run.settings);
    s.shutdown().await;
}

/// A fit runs with the colorimetry it was queued with: one queued under a 10° observer with
/// ASTM E308 weighting, interrupted by a stop, and run after a start whose configuration says
/// the paper's 2° summation, is computed and stored under 10° E308.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fit_keeps_the_colorimetry_it_was_queued_with() {
    use crate::colour::{Colorimetry, Observer, Weighting};
    use crate::fit::FitScanError;
    use crate::optimise::{FitError, Progress};
    use crate::synth::{SynthOptions, paper_samples, synth_scan};
    use std::sync::Mutex;

    let queued_with = Colorimetry {
        observer: Observer::Cie1964TenDegree,
        weighting: Weighting::AstmE308,
    };
    let configured = |colorimetry| ServiceSettings {
        cost_functions: vec![CostFunction::Cf2],
        bootstrap: 0,
        crossval: false,
        colorimetry,
        ..ServiceSettings::default()
    };
    assert_ne!(configured(Colorimetry::default()).colorimetry, queued_with);
    let store = Store::open_in_memory().await.unwrap();

    // First run: the fit starts and runs until the daemon stops.
    let (started_tx, started_rx) = std::sync::mpsc::channel();
    let started_tx = Mutex::new(started_tx);
    let until_stopped: FitFn = Arc::new(move |job, observer| {
        let _ = started_tx.lock().unwrap().send(());
        let progress = Progress {
            generation: 1,
            generations_total: 1,
            best_cost: 1.0,
            evaluations: 1,
        };
        loop {
            if observer(&progress).is_break() {
                return Err(FitScanError::Fit {
                    sample: job.sample.clone(),
                    cost: job.request.settings.cost,
                    source: FitError::Cancelled,
                });
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    });
    let first = service_on(
        store.clone(),
        configured(queued_with),
        ServiceOptions {
            fit_fn: Some(until_stopped),
        },
    )
    .await;
    let file = synth_scan(&paper_samples()[1], &SynthOptions::default()).unwrap();
    let (scan, fits) = first.import_scan(&file).await.unwrap();
    assert_eq!(fits.len(), 1);
    let fit = fits[0];
    assert_eq!(
        store.fit_detail(fit).await.unwrap().run.colorimetry,
        Some(queued_with)
    );
    tokio::task::spawn_blocking(move || started_rx.recv_timeout(Duration::from_secs(60)).unwrap())
        .await
        .unwrap();
    assert!(first.stop_keeping_store().await);
    let left = store.fit_detail(fit).await.unwrap();
    assert_eq!(left.run.status, crate::store::FitStatus::Running);

    // Second run, configured with the paper's colorimetry: the fit is queued again and runs
    // with what it was queued with.
    let seen = Arc::new(Mutex::new(Vec::new()));
    let recording: FitFn = {
        let seen = seen.clone();
        let real = default_fit_fn();
        Arc::new(move |job, observer| {
            seen.lock().unwrap().push(job.request.colorimetry);
            real(job, observer)
        })
    };
    let second = service_on(
        store.clone(),
        configured(Colorimetry::default()),
        ServiceOptions {
            fit_fn: Some(recording),
        },
    )
    .await;
    assert!(
        second
            .wait_settled(scan, Duration::from_secs(300))
            .await
            .unwrap()
    );
    assert_eq!(*seen.lock().unwrap(), [queued_with]);
    let done = store.fit_detail(fit).await.unwrap();
    assert_eq!(
        done.run.status,
        crate::store::FitStatus::Done,
        "{:?}",
        done.run.error
    );
    assert_eq!(done.colorimetry, Some(queued_with));
    assert_eq!(done.run.colorimetry, Some(queued_with));
    // A fit queued now takes the colorimetry configured now.
    let refit = second.refit(scan, &RefitRequest::default()).await.unwrap();
    assert_eq!(
        store.fit_detail(refit[0]).await.unwrap().run.colorimetry,
        Some(Colorimetry::default())
    );
    second.shutdown().await;
}

#[tokio::test]
async fn the_end_of_a_scan_is_written_again_until_the_store_takes_it() {
    use super::orchestrator::{END_WRITE_ATTEMPTS, retry_store_write};
    use crate::store::StoreError;
    use std::sync::atomic::{AtomicU32, Ordering};

    // A disk that refuses twice, then accepts: the third try lands.
    let tries = AtomicU32::new(0);
    let out = retry_store_write(|| async {
        if tries.fetch_add(1, Ordering::SeqCst) < 2 {
            Err(StoreError::Database(sqlx::Error::PoolTimedOut))
        } else {
            Ok(())
        }
    })
    .await;
    assert!(out.is_ok(), "{out:?}");
    assert_eq!(tries.load(Ordering::SeqCst), 3);

    // A disk that never recovers: tried the stated number of times, and the error comes back.
    let tries = AtomicU32::new(0);
    let out = retry_store_write(|| async {
        tries.fetch_add(1, Ordering::SeqCst);
        Err(StoreError::Database(sqlx::Error::PoolTimedOut))
    })
    .await;
    assert!(matches!(out, Err(StoreError::Database(_))), "{out:?}");
    assert_eq!(tries.load(Ordering::SeqCst), END_WRITE_ATTEMPTS);

    // A refusal a retry cannot fix (the scan is no longer measuring) is not retried.
    let tries = AtomicU32::new(0);
    let out = retry_store_write(|| async {
        tries.fetch_add(1, Ordering::SeqCst);
        Err(StoreError::NotFound {
            what: "scan",
            id: 9,
        })
    })
    .await;
    assert!(matches!(out, Err(StoreError::NotFound { .. })), "{out:?}");
    assert_eq!(tries.load(Ordering::SeqCst), 1);
}
