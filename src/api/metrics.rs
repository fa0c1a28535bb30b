//! `GET /metrics`: the daemon's state in the Prometheus text exposition format (version
//! 0.0.4), for the lab's monitoring. Behind the token like every route but `/healthz`: a
//! Prometheus scrape job sends it with `authorization: { credentials_file: /var/lib/brdfd/brdfd.token }`.
//!
//! Every metric is prefixed `brdfd_`; counters end in `_total`. What is stored (scans, fits,
//! readings) is read from the store at each scrape, so the numbers survive restarts; what
//! happens in the process (device transitions, time split) counts from its start.

use std::fmt::Write as _;

use crate::service::{Service, ServiceError};

/// One metric family: `# HELP`, `# TYPE`, then its samples.
fn family(out: &mut String, name: &str, kind: &str, help: &str, samples: &[(String, f64)]) {
    let _ = writeln!(out, "# HELP brdfd_{name} {help}");
    let _ = writeln!(out, "# TYPE brdfd_{name} {kind}");
    for (labels, value) in samples {
        if labels.is_empty() {
            let _ = writeln!(out, "brdfd_{name} {value}");
        } else {
            let _ = writeln!(out, "brdfd_{name}{{{labels}}} {value}");
        }
    }
}

/// A label value, escaped as the exposition format asks (`\`, `"`, line feed).
fn label(value: &str) -> String {
    value
        .replace('\\', "\\\\")
        .replace('"', "\\\"")
        .replace('\n', "\\n")
}

/// The exposition text.
pub async fn render(service: &Service) -> Result<String, ServiceError> {
    let status = service.status().await?;
    let counts = service.store().metric_counts().await?;
    let mut out = String::new();
    family(
        &mut out,
        "scans",
        "gauge",
        "Scans in the store, by state.",
        &counts
            .scans
            .iter()
            .map(|(state, n)| (format!("state=\"{}\"", label(state)), *n as f64))
            .collect::<Vec<_>>(),
    );
    family(
        &mut out,
        "readings",
        "gauge",
        "Sample readings in the store.",
        &[(String::new(), counts.readings as f64)],
    );
    family(
        &mut out,
        "fit_runs",
        "gauge",
        "Fit runs in the store, by status and cost function.",
        &counts
            .fits
            .iter()
            .map(|(status, cost, n, _)| {
                (
                    format!(
                        "status=\"{}\",cost_function=\"{}\"",
                        label(status),
                        label(cost)
                    ),
                    *n as f64,
                )
            })
            .collect::<Vec<_>>(),
    );
    family(
        &mut out,
        "fit_seconds",
        "gauge",
        "Summed wall time of the finished fit runs in the store, by cost function (divide by \
         brdfd_fit_runs{status=\"done\"} for the mean).",
        &counts
            .fits
            .iter()
            .filter(|(status, ..)| status == "done")
            .map(|(_, cost, _, ms)| {
                (
                    format!("cost_function=\"{}\"", label(cost)),
                    ms.unwrap_or(0.0) / 1000.0,
                )
            })
            .collect::<Vec<_>>(),
    );
    family(
        &mut out,
        "fits_queued",
        "gauge",
        "Fits waiting for the fit worker.",
        &[(String::new(), status.fits_queued as f64)],
    );
    family(
        &mut out,
        "fits_running",
        "gauge",
        "Fits being computed.",
        &[(String::new(), status.fits_running as f64)],
    );
    family(
        &mut out,
        "busy",
        "gauge",
        "1 while the instruments measure a reference or a scan.",
        &[(String::new(), f64::from(u8::from(status.busy.is_some())))],
    );
    family(
        &mut out,
        "reference_age_hours",
        "gauge",
        "Age of the reference in force (absent before the first reference).",
        &status
            .reference
            .iter()
            .map(|r| (String::new(), r.age_hours))
            .collect::<Vec<_>>(),
    );
    family(
        &mut out,
        "device_transitions_total",
        "counter",
        "Connection changes of each instrument since start (connected, disconnected, \
         reconnecting, error).",
        &service
            .device_transitions()
            .iter()
            .map(|((device, state), n)| {
                (
                    format!(
                        "instrument=\"{}\",state=\"{}\"",
                        label(device),
                        label(state)
                    ),
                    *n as f64,
                )
            })
            .collect::<Vec<_>>(),
    );
    family(
        &mut out,
        "simulated",
        "gauge",
        "1 for an instrument that is simulated (replayed recordings).",
        &[
            (
                "instrument=\"ma_t12\"".into(),
                f64::from(u8::from(status.simulated.ma_t12)),
            ),
            (
                "instrument=\"sra\"".into(),
                f64::from(u8::from(status.simulated.sra)),
            ),
        ],
    );
    family(
        &mut out,
        "time_seconds_total",
        "counter",
        "Time spent since start measuring, in the store and fitting.",
        &[
            ("part=\"acquire\"".into(), status.timings.acquire_s),
            ("part=\"store\"".into(), status.timings.store_s),
            ("part=\"fit\"".into(), status.timings.fit_s),
        ],
    );
    if let Some(sync) = &status.sync {
        family(
            &mut out,
            "sync_backlog",
            "gauge",
            "Rows waiting to be forwarded to the central database.",
            &[(String::new(), sync.backlog as f64)],
        );
        family(
            &mut out,
            "sync_rows_forwarded_total",
            "counter",
            "Rows forwarded to the central database since start.",
            &[(String::new(), sync.rows_forwarded as f64)],
        );
        family(
            &mut out,
            "sync_connected",
            "gauge",
            "1 when the last attempt reached the central database.",
            &[(String::new(), f64::from(u8::from(sync.connected)))],
        );
    }
    let budget = service.import_budget();
    family(
        &mut out,
        "import_held_bytes",
        "gauge",
        "Bytes of import bodies held in memory now (uploads and watch-folder files).",
        &[(String::new(), budget.held_bytes() as f64)],
    );
    family(
        &mut out,
        "import_held_limit_bytes",
        "gauge",
        "The bound on import bodies held at once ([ingest] max_held_mib).",
        &[(String::new(), budget.total_bytes() as f64)],
    );
    Ok(out)
}
