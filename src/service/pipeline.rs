//! The pipeline from a complete scan to queued fits: processing against the scan's reference
//! (refused when the reference is older than `[scan] reference_max_age_hours`, unless the
//! operator allows it), one fit per cost function handed to the fit worker; refits of stored
//! scans; imports of files (`brdfd.scan/1` files, X-Rite `.xlsx` exports), each file once by
//! its content ([`already_imported`] says so to every door) and named once in its scans'
//! provenance ([`file_provenance`]). Also the one conversion between the store's rows
//! and the scan model ([`scan_from_detail`], [`new_readings`]) that the demo, the exports and
//! the report use too, and the name rules every sample and reference name passes.
//!
//! Measured and imported scans enter here the same way: measured ones from the orchestrator
//! when their 14th reading is stored, imported ones from [`Pipeline::import_scan`] (the API,
//! `brdfd import`) and the watch folder.
//!
//! [`Pipeline`] holds no state of its own: the shared handles, and the fit worker it hands
//! each queued fit to. Everything a fit needs is recorded with it when it is queued (the
//! processed scan, every optimiser setting, the colorimetry), so that running it, or running
//! it again after a restart, never reads the configuration of the day.

use crate::formats::xrite_xlsx::TextureImage;
use crate::geometry::{Device, MA_T12_COUNT};
use crate::processing::{self, ProcessingOptions};
use crate::scan::{DeviceReadings, Scan, ScanError};
use crate::store::{
    FitRunId, FitStatus, ImportFile, ImportedScan, InstrumentOrigin, InstrumentProvenance, NewFit,
    NewReading, NewTexture, PriorImport, Provenance, ReadingValues, ScanDetail, ScanId, ScanState,
    ScansImport, Source, StoreError,
};

use std::sync::Arc;

use super::context::Context;
use super::events::Event;
use super::fit_worker::FitWorker;
use super::{RefitRequest, ServiceError};

/// What a `brdfd.scan/1` file is called in the provenance of the scans imported from it.
pub const SCAN_FILE: &str = "brdfd.scan/1 file";

/// What an X-Rite QC `.xlsx` export is called there (it names itself when it has a name).
pub const XRITE_XLSX: &str = "X-Rite QC .xlsx export";

/// Appended to the name of a reference set that came with an imported scan; such a set is
/// never the reference in force for new scans.
pub const IMPORTED_SUFFIX: &str = " (imported)";

/// A stored scan (complete, with its reference) as a `brdfd.scan/1` scan: the store's one
/// conversion ([`ScanDetail::to_scan`]), with the name the reference had before it was
/// imported.
pub fn scan_from_detail(detail: &ScanDetail) -> Result<Scan, ScanError> {
    let mut scan = detail.to_scan()?;
    if let Some(reference) = scan.reference.as_mut() {
        reference.name = reference.name.trim_end_matches(IMPORTED_SUFFIX).to_string();
    }
    scan.origin = Some(origin_of(&detail.scan));
    Ok(scan)
}

/// What a scan file exported from the store says of where its readings came from: when they
/// were taken, the instruments as they identified themselves (simulated or not), and how they
/// came in ("simulated — replayed from …" for a simulated instrument's), so that the file,
/// read or imported elsewhere, cannot pass for a measurement.
fn origin_of(scan: &crate::store::ScanSummary) -> crate::scan::Origin {
    let p = &scan.provenance;
    let instrument = |i: &InstrumentProvenance| {
        (i.model != "unknown" || i.simulated.is_some()).then(|| crate::scan::OriginInstrument {
            model: i.model.clone(),
            serial: (i.serial != "unknown").then(|| i.serial.clone()),
            simulated: i.simulated == Some(true),
        })
    };
    let at = scan.started_at_ms.unwrap_or(scan.requested_at_ms);
    crate::scan::Origin {
        measured_at: jiff::Timestamp::from_millisecond(at)
            .ok()
            .map(|t| t.to_string()),
        ma_t12: instrument(&p.ma_t12),
        sra: scan.specular_readings.then(|| instrument(&p.sra)).flatten(),
        source: Some(p.source_detail.clone().unwrap_or_else(|| p.summary())),
        notes: Default::default(),
    }
}

/// From a complete scan to queued fits (module docs).
#[derive(Clone)]
pub(super) struct Pipeline {
    ctx: Context,
    fits: Arc<FitWorker>,
}

impl Pipeline {
    pub(super) fn new(ctx: Context, fits: Arc<FitWorker>) -> Pipeline {
        Pipeline { ctx, fits }
    }

    /// Processes a complete scan (once per specular strategy) and queues one fit per cost
    /// function asked for. Refused when the scan's reference is too old, unless allowed.
    pub(super) async fn process_and_queue(
        &self,
        scan: ScanId,
        request: &RefitRequest,
    ) -> Result<Vec<FitRunId>, ServiceError> {
        let settings = &self.ctx.settings;
        let store = &self.ctx.store;
        let detail = self.ctx.timed_store(store.scan_detail(scan)).await?;
        if detail.scan.state != ScanState::Complete {
            return Err(ServiceError::NotComplete {
                scan,
                state: detail.scan.state,
                action: "fitting it",
            });
        }
        let reference = &detail.reference.reference;
        let reference_done = reference.completed_at_ms.unwrap_or(reference.taken_at_ms);
        let age_ms = (detail.scan.requested_at_ms - reference_done).max(0);
        let max = settings.reference_max_age;
        if age_ms as u128 > max.as_millis() && !request.allow_stale_reference {
            return Err(ServiceError::StaleReference {
                scan,
                reference: reference.id,
                age_hours: age_ms as f64 / 3.6e6,
                max_age_hours: max.as_secs_f64() / 3600.0,
            });
        }
        let processed = match self
            .ctx
            .timed_store(store.processed_for_scan(scan))
            .await?
            .into_iter()
            .find(|p| p.specular == settings.specular)
        {
            Some(p) => p.id,
            None => {
                let file = scan_from_detail(&detail)?;
                let options = ProcessingOptions {
                    specular: settings.specular,
                    reference_reflectance: reference.rho_ref,
                };
                let brdf = processing::process(&file, &options)?;
                self.ctx
                    .timed_store(store.add_processed(scan, settings.specular, &brdf))
                    .await?
            }
        };
        let costs = if request.cost_functions.is_empty() {
            settings.cost_functions.clone()
        } else {
            request.cost_functions.clone()
        };
        let method = request.method.unwrap_or(settings.method);
        let seed = request.seed.unwrap_or(settings.seed);
        let mut every = costs
            .iter()
            .map(|&cost| settings.refit_settings(cost, request).map(|s| (cost, s)))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| ServiceError::BadRequest(e.to_string()))?;
        if request.missing_only {
            let existing = self.ctx.timed_store(store.fits_for_scan(scan)).await?;
            every.retain(|(_, wanted)| {
                !existing.iter().any(|run| {
                    matches!(
                        run.status,
                        FitStatus::Done | FitStatus::Queued | FitStatus::Running
                    ) && serde_json::from_value::<crate::optimise::Settings>(run.settings.clone())
                        .is_ok_and(|had| same_configuration(&had, wanted))
                })
            });
        }
        let mut ids = Vec::with_capacity(every.len());
        for (cost, fit_settings) in every {
            let new = NewFit {
                method: method.name().to_string(),
                cost_function: cost,
                settings: serde_json::to_value(fit_settings).map_err(|e| {
                    ServiceError::Store(StoreError::Json {
                        field: "fit settings",
                        source: e,
                    })
                })?,
                seed,
                colorimetry: settings.colorimetry,
            };
            let id = self
                .ctx
                .timed_store(store.queue_fit(processed, &new))
                .await?;
            self.ctx.events.send(Event::FitQueued {
                fit: id,
                scan,
                cost_function: cost,
            });
            self.fits.submit(id);
            ids.push(id);
        }
        Ok(ids)
    }

    /// Queues fits of a complete scan again (other cost functions, method, seed or science).
    pub(super) async fn refit(
        &self,
        scan: ScanId,
        request: &RefitRequest,
    ) -> Result<Vec<FitRunId>, ServiceError> {
        // A request naming a cost function many times queues it once: the list is a set.
        let mut request = request.clone();
        let mut seen = Vec::with_capacity(request.cost_functions.len().min(8));
        request.cost_functions.retain(|cf| {
            let first = !seen.contains(cf);
            if first {
                seen.push(*cf);
            }
            first
        });
        self.process_and_queue(scan, &request).await
    }

    /// Imports a `brdfd.scan/1` scan: its reference readings become a reference set (named
    /// with [`IMPORTED_SUFFIX`]; never the reference in force for new scans), its readings a
    /// complete scan, all in one transaction, which is then processed and fitted like a
    /// measured one. Returns the scan's id and its fits.
    pub(super) async fn import_scan(
        &self,
        file: &Scan,
    ) -> Result<(ScanId, Vec<FitRunId>), ServiceError> {
        // A file that says where its readings came from (every scan file brdfd exports does)
        // keeps that account as it is, so that export → import → export gives the same file.
        let (provenance, taken_at_ms) = file_provenance(file, SCAN_FILE, None)?;
        self.import_scan_as(file, &provenance, taken_at_ms, &[])
            .await
    }

    /// [`Pipeline::import_scan`] with what the file says of its origin: the instruments and
    /// source (`provenance`), when the readings were taken (`taken_at_ms`, else now), and the
    /// instrument camera's images of the measurement, kept with the scan.
    pub(super) async fn import_scan_as(
        &self,
        file: &Scan,
        provenance: &Provenance,
        taken_at_ms: Option<i64>,
        textures: &[TextureImage],
    ) -> Result<(ScanId, Vec<FitRunId>), ServiceError> {
        let one = ScanToImport {
            scan: file,
            provenance: provenance.clone(),
            taken_at_ms,
            textures,
        };
        match self.import_file(None, &[one], false).await? {
            FileImported::Imported(mut scans) if scans.len() == 1 => Ok(scans.remove(0)),
            other => Err(ServiceError::BadRequest(format!(
                "importing one scan gave {other:?}"
            ))),
        }
    }

    /// Imports the scans of one file in one transaction (none is stored unless all are), then
    /// processes each and queues its fits like a measured scan's. With `file` (the bytes'
    /// hash and the file's name, which each scan records) the import is idempotent by content:
    /// a file imported before through any door writes nothing and gives the earlier import,
    /// unless `again`.
    pub(super) async fn import_file(
        &self,
        file: Option<ImportFile<'_>>,
        scans: &[ScanToImport<'_>],
        again: bool,
    ) -> Result<FileImported, ServiceError> {
        for s in scans {
            s.scan.validate()?;
            check_name("sample name", &s.scan.sample)?;
            check_name("reference name", s.scan.reference_label())?;
        }
        let store = &self.ctx.store;
        let names: Vec<String> = scans
            .iter()
            .map(|s| format!("{}{IMPORTED_SUFFIX}", s.scan.reference_label()))
            .collect();
        let readings: Vec<_> = scans
            .iter()
            .map(|s| {
                (
                    s.scan.reference.as_ref().map(|r| new_readings(&r.readings)),
                    new_readings(&s.scan.readings),
                )
            })
            .collect();
        let textures: Vec<Vec<NewTexture<'_>>> =
            scans.iter().map(|s| new_textures(s.textures)).collect();
        let imports: Vec<ImportedScan<'_>> = scans
            .iter()
            .zip(&names)
            .zip(&readings)
            .zip(&textures)
            .map(|(((s, name), (r, m)), t)| ImportedScan {
                sample_name: &s.scan.sample,
                reference_name: name,
                provenance: &s.provenance,
                reference_readings: r.as_deref(),
                readings: m,
                taken_at_ms: s.taken_at_ms,
                textures: t,
            })
            .collect();
        // One transaction: a failure leaves no half-imported reference or scan behind.
        let ids = match self
            .ctx
            .timed_store(store.import_scans(file.as_ref(), &imports, again))
            .await?
        {
            ScansImport::Imported(ids) => ids,
            ScansImport::AlreadyImported(prior) => return Ok(FileImported::Already(prior)),
        };
        for &scan in &ids {
            self.ctx.events.send(Event::ScanComplete { scan });
        }
        let mut out = Vec::with_capacity(ids.len());
        for scan in ids {
            let fits = self
                .process_and_queue(scan, &RefitRequest::default())
                .await?;
            out.push((scan, fits));
        }
        Ok(FileImported::Imported(out))
    }

    /// Exports a complete scan as a `brdfd.scan/1` scan (with its reference readings).
    pub(super) async fn export_scan(&self, scan: ScanId) -> Result<Scan, ServiceError> {
        let detail = self.ctx.store.scan_detail(scan).await?;
        if detail.scan.state != ScanState::Complete {
            return Err(ServiceError::NotComplete {
                scan,
                state: detail.scan.state,
                action: "exporting it",
            });
        }
        Ok(scan_from_detail(&detail)?)
    }
}

/// One scan of a file to import, with what the file says of it.
#[derive(Debug, Clone)]
pub struct ScanToImport<'a> {
    pub scan: &'a Scan,
    /// Its provenance ([`file_provenance`]).
    pub provenance: Provenance,
    /// When the readings were taken, ms since the epoch (else the import time is recorded).
    pub taken_at_ms: Option<i64>,
    /// The instrument camera's images of the measurement, kept with the scan.
    pub textures: &'a [TextureImage],
}

/// What an import of a file did.
#[derive(Debug, Clone, PartialEq)]
pub enum FileImported {
    /// Its scans, in the file's order, each with the fits queued for it.
    Imported(Vec<(ScanId, Vec<FitRunId>)>),
    /// The same content was imported before (through any door); nothing was imported.
    Already(PriorImport),
}

/// The provenance of a scan imported from a file of `kind` ("brdfd.scan/1 file", "X-Rite QC
/// .xlsx export", …) named `file_name`: [`imported_provenance`], with `source_detail` naming
/// the file once, whatever the door. A file that gives its own account of where it came from
/// keeps it as it is (an instrument export names itself, "X-Rite QC export PAR_1.xlsx; …";
/// a scan file brdfd exported keeps its account, so that export → import → export gives the
/// same file), followed by "; KIND FILE" when the account does not name the file; any other
/// is "KIND FILE", followed by what its `origin` notes.
pub fn file_provenance(
    scan: &Scan,
    kind: &str,
    file_name: Option<&str>,
) -> Result<(Provenance, Option<i64>), ScanError> {
    let named = match file_name {
        Some(f) => format!("{kind} {f}"),
        None => kind.to_string(),
    };
    let (mut provenance, taken_at_ms) = imported_provenance(scan, &named)?;
    if let Some(origin) = scan.origin.as_ref().filter(|o| o.source.is_some()) {
        let mut detail = origin.describe();
        if let Some(f) = file_name.filter(|f| !detail.contains(f)) {
            detail.push_str(&format!("; {kind} {f}"));
        }
        provenance.source_detail = Some(detail);
    }
    Ok((provenance, taken_at_ms))
}

/// What every door answers a file imported before: "already imported as scan 3 on
/// 2026-12-04T19:14:14Z from PAR_1.xlsx (the same content, SHA-256 …); nothing was imported
/// again". The door adds how to import it anyway.
pub fn already_imported(prior: &PriorImport) -> String {
    let ids: Vec<String> = prior.scans.iter().map(|s| s.to_string()).collect();
    let scans = match ids.as_slice() {
        [one] => format!("scan {one}"),
        [rest @ .., last] => format!("scans {} and {last}", rest.join(", ")),
        [] => "no scan".to_string(),
    };
    format!(
        "already imported as {scans} on {}{} (the same content, SHA-256 {}); nothing was \
         imported again",
        crate::formats::rfc3339_utc(prior.imported_at_ms.div_euclid(1000)),
        prior
            .file_name
            .as_deref()
            .map(|f| format!(" from {f}"))
            .unwrap_or_default(),
        prior.sha256
    )
}

/// An export's texture images as the store takes them.
pub(crate) fn new_textures(textures: &[TextureImage]) -> Vec<NewTexture<'_>> {
    textures
        .iter()
        .map(|t| NewTexture {
            label: &t.geometry,
            anchor: &t.anchor,
            png: &t.png,
        })
        .collect()
}

/// The provenance of an imported scan: what its `origin` says (instruments, measurement time,
/// source and notes), `detail` naming how it came in; unknown where the file is silent. The
/// measurement time, ms since the epoch, is returned beside it.
pub fn imported_provenance(
    scan: &Scan,
    detail: &str,
) -> Result<(Provenance, Option<i64>), ScanError> {
    let mut provenance = Provenance {
        source: Source::Imported,
        source_detail: Some(detail.to_string()),
        ..Provenance::unknown()
    };
    let Some(origin) = &scan.origin else {
        return Ok((provenance, None));
    };
    let instrument = |i: &crate::scan::OriginInstrument| InstrumentProvenance {
        model: i.model.clone(),
        serial: i.serial.clone().unwrap_or_else(|| "unknown".into()),
        firmware: "unknown".into(),
        simulated: Some(i.simulated),
        origin: if i.simulated {
            InstrumentOrigin::Simulated
        } else {
            InstrumentOrigin::Imported
        },
    };
    if let Some(i) = &origin.ma_t12 {
        provenance.ma_t12 = instrument(i);
    }
    if let Some(i) = &origin.sra {
        provenance.sra = instrument(i);
    }
    let said = origin.describe();
    if !said.is_empty() {
        provenance.source_detail = Some(format!("{detail}; {said}"));
    }
    Ok((provenance, origin.measured_at_ms()?))
}

/// The longest sample or reference name accepted.
pub const MAX_NAME_CHARS: usize = 200;

/// Names end up in terminals (`brdfd scans`), file names and reports: at most
/// [`MAX_NAME_CHARS`] characters, and no control characters (an escape sequence in a sample
/// name would otherwise reach the operator's terminal).
pub fn check_name(what: &str, name: &str) -> Result<(), ServiceError> {
    let count = name.chars().count();
    if count > MAX_NAME_CHARS {
        return Err(ServiceError::BadRequest(format!(
            "the {what} has {count} characters: at most {MAX_NAME_CHARS}"
        )));
    }
    if let Some(c) = name.chars().find(|c| c.is_control()) {
        return Err(ServiceError::BadRequest(format!(
            "the {what} {:?} holds the control character U+{:04X}: names are printable text",
            name.escape_debug().to_string(),
            c as u32
        )));
    }
    Ok(())
}

/// A scan file's readings as store readings, in table order, with empty raw frames (the 12
/// MA-T12 ones only when there are no SRA readings).
pub(super) fn new_readings(r: &DeviceReadings) -> Vec<NewReading<'static>> {
    r.geometries()
        .iter()
        .map(|g| NewReading {
            device: g.device,
            geometry: g,
            values: match (g.device, r.sra) {
                (Device::Sra, Some(sra)) => ReadingValues::Intensity(sra[g.index - MA_T12_COUNT]),
                _ => ReadingValues::Spectrum(r.ma_t12[g.index]),
            },
            raw_frame: &[],
        })
        .collect()
}

/// Whether two fits' settings are the same configuration for `missing_only`: cost function,
/// method, model form, Fresnel factor, SRA reading model and weight (not the seed).
fn same_configuration(a: &crate::optimise::Settings, b: &crate::optimise::Settings) -> bool {
    a.cost == b.cost
        && a.method == b.method
        && a.model == b.model
        && a.fresnel == b.fresnel
        && a.sra.model == b.sra.model
        && a.sra.weight == b.sra.weight
}
