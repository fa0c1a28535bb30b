//! The one conversion from each of the service's and the store's records to the wire type
//! ([`crate::wire`]) a handler answers with. The JSON is the record's own serialisation, field
//! for field: a wire type only owns its strings and opens its closed sets of values.

use crate::wire;

/// A number that serialises as `null` when not finite, as the record's `f64` did.
fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

impl From<crate::service::Operation> for wire::Operation {
    fn from(op: crate::service::Operation) -> Self {
        match op {
            crate::service::Operation::Reference { reference } => {
                wire::Operation::Reference { reference }
            }
            crate::service::Operation::Scan { scan } => wire::Operation::Scan { scan },
        }
    }
}

impl From<crate::service::Status> for wire::Status {
    fn from(s: crate::service::Status) -> Self {
        wire::Status {
            version: s.version.to_string(),
            busy: s.busy.map(|b| wire::Busy {
                operation: b.operation.into(),
                seconds: b.seconds,
            }),
            reference: s.reference.map(|r| wire::ReferenceInForce {
                id: r.id,
                name: r.name,
                completed_at_ms: r.completed_at_ms,
                age_hours: r.age_hours,
                stale: r.stale,
            }),
            fits_queued: s.fits_queued as u64,
            fits_running: s.fits_running as u64,
            bootstraps_pending: s.bootstraps_pending as u64,
            simulated: wire::Simulated {
                ma_t12: s.simulated.ma_t12,
                sra: s.simulated.sra,
            },
            devices: s.devices.into_iter().map(Into::into).collect(),
            timings: wire::Timings {
                acquire_s: s.timings.acquire_s,
                store_s: s.timings.store_s,
                fit_s: s.timings.fit_s,
            },
            sync: s.sync.map(Into::into),
            ingest: s.ingest.map(|i| wire::IngestStatus {
                dir: i.dir,
                waiting: i.waiting as u64,
                imported: i.imported,
                rejected: i.rejected,
                last_file: i.last_file,
                last_error: i.last_error,
            }),
        }
    }
}

/// A text the service gives as `&'static str`, read as the closed set it belongs to.
pub(super) fn open<T: serde::de::DeserializeOwned>(text: &str) -> wire::Open<T> {
    serde_json::from_value(serde_json::Value::String(text.to_string()))
        .unwrap_or_else(|_| wire::Open::Unknown(text.to_string()))
}

impl From<crate::service::DeviceStatus> for wire::DeviceStatus {
    fn from(d: crate::service::DeviceStatus) -> Self {
        wire::DeviceStatus {
            device: open(d.device),
            instrument: d.instrument,
            state: open(d.state),
            detail: d.detail,
            since_ms: d.since_ms,
            simulated: d.simulated,
            model: d.model,
            serial: d.serial,
            firmware: d.firmware,
        }
    }
}

impl From<crate::sync::SyncStatus> for wire::SyncStatus {
    fn from(s: crate::sync::SyncStatus) -> Self {
        wire::SyncStatus {
            station: s.station,
            central: s.central,
            connected: s.connected,
            backlog: s.backlog,
            cursor: s.cursor,
            rows_forwarded: s.rows_forwarded,
            last_forwarded_ms: s.last_forwarded_ms,
            last_error: s.last_error,
            last_error_ms: s.last_error_ms,
            refused: s.refused,
            last_verify: s.last_verify,
            last_verify_ms: s.last_verify_ms,
            lag: s.lag.map(|l| wire::Lag {
                entries: l.entries,
                p50_ms: l.p50_ms,
                p99_ms: l.p99_ms,
                max_ms: l.max_ms,
            }),
        }
    }
}

impl From<&crate::store::InstrumentProvenance> for wire::InstrumentProvenance {
    fn from(p: &crate::store::InstrumentProvenance) -> Self {
        wire::InstrumentProvenance {
            model: p.model.clone(),
            serial: p.serial.clone(),
            firmware: p.firmware.clone(),
            simulated: p.simulated,
        }
    }
}

impl From<&crate::store::Provenance> for wire::Provenance {
    fn from(p: &crate::store::Provenance) -> Self {
        wire::Provenance {
            ma_t12: (&p.ma_t12).into(),
            sra: (&p.sra).into(),
            source: p.source.into(),
            source_detail: p.source_detail.clone(),
        }
    }
}

impl From<&crate::store::ScanSummary> for wire::ScanSummary {
    fn from(s: &crate::store::ScanSummary) -> Self {
        wire::ScanSummary {
            id: s.id,
            sample_id: s.sample_id.0,
            sample: s.sample.clone(),
            reference_id: s.reference_id,
            state: s.state.into(),
            reason: s.reason.clone(),
            requested_at_ms: s.requested_at_ms,
            started_at_ms: s.started_at_ms,
            finished_at_ms: s.finished_at_ms,
            reading_count: s.reading_count as u64,
            specular_readings: s.specular_readings,
            provenance: (&s.provenance).into(),
        }
    }
}

impl From<&crate::store::Reading> for wire::Reading {
    fn from(r: &crate::store::Reading) -> Self {
        wire::Reading {
            id: r.id.0,
            device: r.device().into(),
            geometry: r.geometry.name.to_string(),
            values: match r.values {
                crate::store::ReadingValues::Spectrum(s) => wire::ReadingValues::Spectrum(s),
                crate::store::ReadingValues::Intensity(v) => wire::ReadingValues::Intensity(v),
            },
            raw_frame: hex::encode(&r.raw_frame),
            at_ms: r.at_ms,
        }
    }
}

impl From<&crate::store::ReferenceDetail> for wire::ReferenceDetail {
    fn from(d: &crate::store::ReferenceDetail) -> Self {
        let r = &d.reference;
        wire::ReferenceDetail {
            reference: wire::ReferenceSummary {
                id: r.id,
                name: r.name.clone(),
                status: r.status.into(),
                reason: r.reason.clone(),
                rho_ref: r.rho_ref,
                taken_at_ms: r.taken_at_ms,
                completed_at_ms: r.completed_at_ms,
                instrument_calibration: r.instrument_calibration,
                specular_readings: r.specular_readings,
                reading_count: r.reading_count as u64,
                provenance: (&r.provenance).into(),
            },
            readings: d.readings.iter().map(Into::into).collect(),
        }
    }
}

impl From<&crate::store::TextureSummary> for wire::TextureSummary {
    fn from(t: &crate::store::TextureSummary) -> Self {
        wire::TextureSummary {
            position: t.position,
            label: t.label.clone(),
            anchor: t.anchor.clone(),
            sha256: t.sha256.clone(),
            bytes: t.bytes,
        }
    }
}

impl From<crate::store::DeltaESummary> for wire::DeltaESummary {
    fn from(d: crate::store::DeltaESummary) -> Self {
        wire::DeltaESummary {
            mean: d.mean,
            median: d.median,
            max: d.max,
        }
    }
}

impl From<crate::store::FitDetail> for wire::FitDetail {
    fn from(d: crate::store::FitDetail) -> Self {
        let run = d.run;
        wire::FitDetail {
            run: wire::FitRun {
                id: run.id,
                scan: run.scan,
                processed: run.processed.0,
                specular: run.specular.into(),
                method: run.method,
                cost_function: run.cost_function.into(),
                settings: run.settings,
                seed: run.seed,
                status: run.status.into(),
                error: run.error,
                result: run.result.map(|r| wire::FitResult {
                    cost: r.cost,
                    params: r.params,
                    best_cost_per_generation: r
                        .best_cost_per_generation
                        .into_iter()
                        .map(finite)
                        .collect(),
                    evaluations: r.evaluations,
                    generations: r.generations,
                    wall_ms: r.wall_ms,
                }),
                queued_at_ms: run.queued_at_ms,
                started_at_ms: run.started_at_ms,
                finished_at_ms: run.finished_at_ms,
            },
            evaluation: d.evaluation.map(|e| wire::Evaluation {
                per_geometry: e.per_geometry.into_iter().map(finite).collect(),
                all: e.all.into(),
                diffuse: e.diffuse.into(),
                specular: e.specular.map(Into::into),
            }),
            colorimetry: d.colorimetry,
            uncertainty: d.uncertainty,
            sra: d.sra,
            specular_delta_l: d.specular_delta_l,
            lab: d.lab,
        }
    }
}
