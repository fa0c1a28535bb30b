//! The daemon cross-validates every fit it stores (`[fit] crossval`): after a scan's fit, each
//! MA-T12 geometry is held out in turn and predicted by a fit without it; the predictions and
//! their mean are stored with the fit, read back by the store, the study the report draws, the
//! API and `brdfd show` (text and `--json`), beside the fit's own ΔE00. A fit stored without
//! one (cross-validation off, or the daemon stopped while it ran) gets it at the next start.

mod common;

use std::time::{Duration, Instant};

use brdfd::cost::CostFunction;
use brdfd::geometry::GEOMETRIES;
use brdfd::service::{Service, ServiceOptions, ServiceSettings};
use brdfd::study::load::{Selection, from_store};
use serde_json::Value;

use common::*;

/// One cost function under the flat SRA model, no bootstrap: the 12 held-out fits (with
/// `crossval`) are the only extra work.
fn one_cf1_fit(crossval: bool) -> ServiceSettings {
    ServiceSettings {
        cost_functions: vec![CostFunction::Cf1],
        bootstrap: 0,
        crossval,
        ..settings()
    }
}

/// Waits until `service` has no fit and no cross-validation left to run.
async fn wait_for_crossvals(service: &Service) {
    let started = Instant::now();
    loop {
        let s = service.status().await.unwrap();
        if s.crossvals_pending == 0 && s.fits_running == 0 && s.fits_queued == 0 {
            return;
        }
        assert!(
            started.elapsed() < STEP_TIMEOUT,
            "the cross-validation did not end: {s:?}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fit_stored_without_its_cross_validation_gets_it_at_the_next_start() {
    let _serial = serial();
    bounded(async {
        let off = one_cf1_fit(false);
        let d = start(
            simulated(&strict_fast()),
            off.clone(),
            ServiceOptions::default(),
        )
        .await;
        measure_reference(&d.service).await;
        let scan = scan_and_settle(&d.service, "T.Later").await;
        let fit = d.store.fits_for_scan(scan).await.unwrap()[0].id;
        assert!(d.store.fit_detail(fit).await.unwrap().crossval.is_none());
        assert_eq!(
            d.store.done_fits_without_crossval().await.unwrap(),
            vec![fit]
        );
        d.service.stop_keeping_store().await;

        // The next start, cross-validation on: counted in `status` from the start, computed,
        // stored with the fit.
        let on = ServiceSettings {
            crossval: true,
            ..off
        };
        let service = Service::start(
            d.store.clone(),
            simulated(&strict_fast()),
            on,
            ServiceOptions::default(),
        )
        .await
        .unwrap();
        let pending = service.status().await.unwrap().crossvals_pending;
        let already = d.store.fit_detail(fit).await.unwrap().crossval.is_some();
        assert!(pending == 1 || already, "{pending} pending");
        wait_for_crossvals(&service).await;
        let detail = d.store.fit_detail(fit).await.unwrap();
        let cv = detail
            .crossval
            .expect("the cross-validation computed at start-up");
        assert_eq!(cv.held_out.len(), 12);
        assert_eq!(cv.cost, CostFunction::Cf1);
        let diffuse = detail.evaluation.unwrap().diffuse.mean;
        assert!(
            (cv.fitted_mean - diffuse).abs() < 1e-9,
            "{cv:?} vs {diffuse}"
        );
        assert!(cv.held_out_mean > cv.fitted_mean, "{cv:?}");
        assert!(
            d.store
                .done_fits_without_crossval()
                .await
                .unwrap()
                .is_empty()
        );
        service.stop_keeping_store().await;

        // A start with nothing left to do computes nothing.
        let service = Service::start(
            d.store.clone(),
            simulated(&strict_fast()),
            ServiceSettings {
                crossval: true,
                ..settings()
            },
            ServiceOptions::default(),
        )
        .await
        .unwrap();
        assert_eq!(service.status().await.unwrap().crossvals_pending, 0);
        assert_eq!(d.store.fit_detail(fit).await.unwrap().crossval, Some(cv));
        service.shutdown().await;
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_stored_fit_gets_its_held_out_delta_e_shown_beside_its_fitted_one() {
    let _serial = serial();
    bounded(async {
        let settings = one_cf1_fit(true);
        let d = start(
            simulated(&strict_fast()),
            settings,
            ServiceOptions::default(),
        )
        .await;
        measure_reference(&d.service).await;
        let scan = scan_and_settle(&d.service, "T.Held").await;
        let started = Instant::now();
        wait_for_crossvals(&d.service).await;
        eprintln!(
            "cross-validation of one cf1 fit: {:.1} s",
            started.elapsed().as_secs_f64()
        );

        // Stored with the fit, read back whole.
        let runs = d.store.fits_for_scan(scan).await.unwrap();
        assert_eq!(runs.len(), 1);
        let detail = d.store.fit_detail(runs[0].id).await.unwrap();
        let cv = detail.crossval.clone().expect("the fit's cross-validation");
        let names: Vec<&str> = cv.held_out.iter().map(|h| h.geometry.as_str()).collect();
        let ma: Vec<&str> = GEOMETRIES[..12].iter().map(|g| g.name).collect();
        assert_eq!(
            names, ma,
            "each MA-T12 geometry held out once, in table order"
        );
        assert_eq!(cv.cost, CostFunction::Cf1);
        let mean = cv.held_out.iter().map(|h| h.delta_e00).sum::<f64>() / 12.0;
        assert_eq!(cv.held_out_mean, mean);
        // The in-sample figure is the stored fit's own, not a second fit's.
        let diffuse = detail.evaluation.unwrap().diffuse.mean;
        assert!(
            (cv.fitted_mean - diffuse).abs() < 1e-9,
            "{cv:?} vs {diffuse}"
        );
        // Real recordings: a reading the fit did not see is predicted worse than one it did.
        assert!(cv.held_out_mean > cv.fitted_mean, "{cv:?}");
        assert!(
            cv.held_out_mean.is_finite() && cv.held_out_mean < 20.0,
            "{cv:?}"
        );

        // The study the report draws carries it.
        let study = from_store(&d.store, &Selection::Scans(vec![scan]))
            .await
            .unwrap();
        let done = study.samples[0].done(CostFunction::Cf1).unwrap();
        assert_eq!(done.crossval.as_ref(), Some(&cv));

        // The API and `brdfd show`.
        let (api, _client, token_file) = start_api(&d.service, d.dir.path()).await;
        let addr = api.local_addr().to_string();
        let token = token_file.display().to_string();
        let scan_arg = scan.to_string();
        let (json, text) = tokio::task::spawn_blocking(move || {
            let args = ["show", &scan_arg, "--addr", &addr, "--token-file", &token];
            let text = run_brdfd(&args, None);
            let mut with_json = args.to_vec();
            with_json.push("--json");
            (run_brdfd(&with_json, None), text)
        })
        .await
        .unwrap();
        assert!(
            json.status.success(),
            "{}",
            String::from_utf8_lossy(&json.stderr)
        );
        let v: Value = serde_json::from_slice(&json.stdout).unwrap();
        let shown = &v["fits"][0]["crossval"];
        assert_eq!(shown["held_out_mean"].as_f64(), Some(cv.held_out_mean));
        assert_eq!(shown["held_out"].as_array().unwrap().len(), 12);
        assert_eq!(shown["held_out"][6]["geometry"], "45as-15");
        assert_eq!(
            shown["held_out"][6]["measured_lab"]
                .as_array()
                .unwrap()
                .len(),
            3
        );
        let text = String::from_utf8_lossy(&text.stdout);
        let line = format!(
            "held-out ΔE00 {:.3} (fitted {:.3}; each MA-T12 geometry predicted by a fit without it",
            cv.held_out_mean, cv.fitted_mean
        );
        assert!(text.contains(&line), "{line}\nnot in\n{text}");
        assert!(
            text.contains("how far to trust the estimate off the measured angles"),
            "{text}"
        );
        // The science choices the fit was made with (these tests' settings: the paper's
        // Fresnel factor).
        assert!(text.contains("model paper, Fresnel incidence"), "{text}");
        // The reach verdict, derived from what is stored, with the held-out ΔE00 among its
        // evidence (SCIENCE.md §12.7).
        let reach = &v["fits"][0]["reach"];
        assert_eq!(
            reach["evidence"]["held_out_delta_e00"].as_f64(),
            Some(cv.held_out_mean),
            "{reach}"
        );
        assert!(reach["verdict"].is_string(), "{reach}");
        assert!(text.contains("       reach: "), "{text}");

        d.service.shutdown().await;
        api.stop(Duration::from_secs(1)).await;
    })
    .await;
}
