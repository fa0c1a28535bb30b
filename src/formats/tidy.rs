//! The tidy CSV export for analysis (`brdfd export-format --format tidy --out DIR`): two files
//! in "one observation per row" form, ready for pandas, R or a spreadsheet's pivot table.
//!
//! - `spectra.csv`: one row per scan × geometry × band — `scan_id, measured_at, station, sample,
//!   reference, ma_t12_serial, sra_serial, simulated, device, geometry, theta_i_deg,
//!   theta_r_deg, phi_r_deg, nm`, then the values at that band: `reading` (the sample's device
//!   reading), `reference_reading`, `measured` (reflectance factor π·M) and `estimated_<cost>`
//!   per cost function of the study (π·f of the finished fit; empty when that fit did not
//!   finish). An SRA geometry's single intensity is repeated in every band, as processing spreads
//!   it (SCIENCE.md §3).
//! - `fits.csv`: one row per scan × cost function — `scan_id, measured_at, station, sample,
//!   cost_function, method, status, reason, fresnel, ks, alpha, ior` with their 95 % bootstrap
//!   interval ends (`ks_lo`, `ks_hi`, …; empty without intervals), the ΔE00 summaries
//!   (`delta_e00_mean`, `_diffuse_mean`, `_specular_mean`, `_max`), the colorimetry they were
//!   computed under, the resamples, and `kd_400` … `kd_700` (sr⁻¹).
//!
//! Numbers are Rust's shortest round-trip form, as in every export. Provenance fields are those
//! of [`super::PROVENANCE_FIELDS`].

use super::{FormatError, device_spectrum, provenance_values, reflectance};
use crate::spectral::wavelengths_nm;
use crate::study::{FitState, SampleStudy, Study};

/// The two files: (file name, contents).
pub fn files(study: &Study) -> Result<Vec<(String, String)>, FormatError> {
    Ok(vec![
        ("spectra.csv".into(), spectra(study)?),
        ("fits.csv".into(), fits(study)?),
    ])
}

fn csv_error(e: impl std::fmt::Display) -> FormatError {
    FormatError::Unwritable {
        format: "tidy",
        message: e.to_string(),
    }
}

/// The columns both tables open with, saying which scan a row is of.
const SCAN_COLUMNS: [&str; 4] = ["scan_id", "measured_at", "station", "sample"];

/// A table with its header written, [`SCAN_COLUMNS`] then `columns`, and how many columns it
/// has.
fn new_table(
    columns: impl IntoIterator<Item = String>,
) -> Result<(::csv::Writer<Vec<u8>>, usize), FormatError> {
    let head: Vec<String> = SCAN_COLUMNS
        .map(String::from)
        .into_iter()
        .chain(columns)
        .collect();
    let mut w = ::csv::Writer::from_writer(Vec::new());
    w.write_record(&head).map_err(csv_error)?;
    Ok((w, head.len()))
}

/// The values of [`SCAN_COLUMNS`] for sample `s`, whose provenance values are `origin`.
fn scan_values(s: &SampleStudy, origin: &[String]) -> Vec<String> {
    // PROVENANCE_FIELDS: 0 = scan_id, 1 = station, 2 = measured_at.
    vec![
        origin[0].clone(),
        origin[2].clone(),
        origin[1].clone(),
        s.scan.sample.clone(),
    ]
}

fn finish(w: ::csv::Writer<Vec<u8>>) -> Result<String, FormatError> {
    let bytes = w.into_inner().map_err(csv_error)?;
    Ok(String::from_utf8(bytes).expect("csv writes the UTF-8 it is given"))
}

/// `yes` when either instrument was simulated, `no` when both are known real, else `unknown`.
fn simulated(origin: &[String]) -> &'static str {
    // PROVENANCE_FIELDS: 7 = ma_t12_simulated, 11 = sra_simulated.
    match (origin[7].as_str(), origin[11].as_str()) {
        ("yes", _) | (_, "yes") => "yes",
        ("no", "no") => "no",
        _ => "unknown",
    }
}

/// The spectra table.
pub fn spectra(study: &Study) -> Result<String, FormatError> {
    let costs = study.cost_functions();
    let head = [
        "reference",
        "ma_t12_serial",
        "sra_serial",
        "simulated",
        "device",
        "geometry",
        "theta_i_deg",
        "theta_r_deg",
        "phi_r_deg",
        "nm",
        "reading",
        "reference_reading",
        "measured",
    ]
    .map(String::from);
    let (mut w, _) = new_table(
        head.into_iter()
            .chain(costs.iter().map(|c| format!("estimated_{c}"))),
    )?;
    let nms = wavelengths_nm();
    for s in &study.samples {
        let origin = provenance_values(s);
        let estimated: Vec<Option<[crate::spectral::Spectrum; 14]>> = costs
            .iter()
            .map(|c| s.done(*c).map(|d| d.estimated.map(|f| reflectance(&f))))
            .collect();
        let measured = s.measured.values.map(|f| reflectance(&f));
        // Rows at the geometries the scan measured; the reference column is empty without a
        // tile (the reference is the instrument's own calibration).
        for g in s.scan.geometries().iter() {
            let reading = device_spectrum(&s.scan.readings, g).unwrap_or([f64::NAN; 31]);
            let reference = s
                .scan
                .reference
                .as_ref()
                .and_then(|r| device_spectrum(&r.readings, g));
            for (b, nm) in nms.iter().enumerate() {
                let mut row = scan_values(s, &origin);
                row.extend([
                    s.scan.reference_label().to_string(),
                    origin[5].clone(),
                    origin[9].clone(),
                    simulated(&origin).into(),
                    g.device.key().into(),
                    g.name.into(),
                    g.theta_i_deg.to_string(),
                    g.theta_r_deg.to_string(),
                    g.phi_r_deg.to_string(),
                    nm.to_string(),
                    reading[b].to_string(),
                    reference.map_or(String::new(), |r| r[b].to_string()),
                    measured[g.index][b].to_string(),
                ]);
                row.extend(
                    estimated
                        .iter()
                        .map(|e| e.map_or(String::new(), |e| e[g.index][b].to_string())),
                );
                w.write_record(&row).map_err(csv_error)?;
            }
        }
    }
    finish(w)
}

/// The fits table.
pub fn fits(study: &Study) -> Result<String, FormatError> {
    let head = [
        "cost_function",
        "method",
        "status",
        "reason",
        "fresnel",
        "ks",
        "ks_lo",
        "ks_hi",
        "alpha",
        "alpha_lo",
        "alpha_hi",
        "ior",
        "ior_lo",
        "ior_hi",
        "delta_e00_mean",
        "delta_e00_mean_lo",
        "delta_e00_mean_hi",
        "delta_e00_diffuse_mean",
        "delta_e00_specular_mean",
        "delta_e00_max",
        "observer",
        "weighting",
        "resamples",
    ]
    .map(String::from);
    let (mut w, width) = new_table(
        head.into_iter()
            .chain(wavelengths_nm().iter().map(|nm| format!("kd_{nm}"))),
    )?;
    let n = |v: f64| v.to_string();
    for s in &study.samples {
        let origin = provenance_values(s);
        for f in &s.fits {
            let mut row = scan_values(s, &origin);
            row.extend([f.cost.to_string(), f.method.clone()]);
            match &f.state {
                FitState::Done(d) => {
                    let u = d.uncertainty.as_ref();
                    let lo_hi = |iv: Option<[f64; 2]>| match iv {
                        Some([lo, hi]) => [n(lo), n(hi)],
                        None => [String::new(), String::new()],
                    };
                    let p = &d.params;
                    let e = &d.evaluation;
                    row.extend(["done".into(), String::new(), format!("{:?}", d.fresnel)]);
                    row.push(n(p.ks));
                    row.extend(lo_hi(u.map(|u| u.ks)));
                    row.push(n(p.alpha));
                    row.extend(lo_hi(u.map(|u| u.alpha)));
                    row.push(n(p.ior));
                    row.extend(lo_hi(u.map(|u| u.ior)));
                    row.push(n(e.all.mean));
                    row.extend(lo_hi(u.map(|u| u.delta_e00_mean)));
                    row.extend([
                        n(e.diffuse.mean),
                        e.specular.map_or(String::new(), |s| n(s.mean)),
                        n(e.all.max),
                        d.colorimetry.observer.to_string(),
                        d.colorimetry.weighting.to_string(),
                        u.map_or(String::new(), |u| u.resamples.to_string()),
                    ]);
                    row.extend(p.kd.iter().map(|v| n(*v)));
                }
                FitState::Failed { reason } => {
                    row.extend(["failed".into(), reason.clone()]);
                    row.resize(width, String::new());
                }
                FitState::Unfinished { status } => {
                    row.extend([status.clone(), String::new()]);
                    row.resize(width, String::new());
                }
            }
            w.write_record(&row).map_err(csv_error)?;
        }
    }
    finish(w)
}

#[cfg(test)]
mod tests {
    use super::super::tests::stored_study;
    use super::*;
    use crate::cost::CostFunction;

    fn table(text: &str) -> (Vec<String>, Vec<Vec<String>>) {
        let mut r = ::csv::Reader::from_reader(text.as_bytes());
        let head = r.headers().unwrap().iter().map(String::from).collect();
        let rows = r
            .records()
            .map(|r| r.unwrap().iter().map(String::from).collect())
            .collect();
        (head, rows)
    }

    #[test]
    fn one_row_per_scan_geometry_and_band_with_every_value_exact() {
        let study = stored_study();
        let (head, rows) = table(&spectra(&study).unwrap());
        assert_eq!(rows.len(), study.samples.len() * 14 * 31);
        let col = |name: &str| head.iter().position(|h| h == name).unwrap();
        assert_eq!(head.last().unwrap(), "estimated_m2");
        // Sample 0, geometry 45as45 (index 9), 550 nm (band 15).
        let s = &study.samples[0];
        let row = &rows[9 * 31 + 15];
        assert_eq!(row[col("scan_id")], "11");
        assert_eq!(row[col("station")], "bench-2");
        assert_eq!(row[col("measured_at")], "2024-05-01T12:00:00Z");
        assert_eq!(row[col("ma_t12_serial")], "MT-7");
        assert_eq!(row[col("simulated")], "yes");
        assert_eq!(row[col("geometry")], "45as45");
        assert_eq!(row[col("nm")], "550");
        let parse = |c: &str| row[col(c)].parse::<f64>().unwrap();
        assert_eq!(parse("reading"), s.scan.readings.ma_t12[9][15]);
        assert_eq!(
            parse("reference_reading"),
            s.scan.reference.as_ref().unwrap().readings.ma_t12[9][15]
        );
        assert_eq!(
            parse("measured"),
            std::f64::consts::PI * s.measured.values[9][15]
        );
        let cf2 = s.done(CostFunction::Cf2).unwrap();
        assert_eq!(
            parse("estimated_cf2"),
            std::f64::consts::PI * cf2.estimated[9][15]
        );
        // The failed m2 fit of the third sample leaves its column empty.
        let last = &rows[2 * 14 * 31];
        assert_eq!(last[col("estimated_m2")], "");
    }

    #[test]
    fn one_row_per_fit_with_parameters_and_delta_e() {
        let study = stored_study();
        let (head, rows) = table(&fits(&study).unwrap());
        assert_eq!(rows.len(), 9);
        let col = |name: &str| head.iter().position(|h| h == name).unwrap();
        let d = study.samples[1].done(CostFunction::Cf1).unwrap();
        let row = &rows[3];
        assert_eq!(row[col("cost_function")], "cf1");
        assert_eq!(row[col("status")], "done");
        assert_eq!(row[col("ks")].parse::<f64>().unwrap(), d.params.ks);
        assert_eq!(row[col("kd_700")].parse::<f64>().unwrap(), d.params.kd[30]);
        assert_eq!(
            row[col("delta_e00_mean")].parse::<f64>().unwrap(),
            d.evaluation.all.mean
        );
        assert_eq!(row[col("ks_lo")], "", "no intervals in this study");
        let failed = &rows[8];
        assert_eq!(failed[col("status")], "failed");
        assert_eq!(failed[col("reason")], "cancelled by the operator");
        assert_eq!(failed.len(), head.len());
    }
}
