//! `brdfd._native`: the Rust side of the Python package. Every number comes from the brdfd
//! library itself — the scan readers and instrument-export importers of `brdfd::formats`, the
//! fit of `brdfd fit` ([`brdfd::cli::fit::fit_with`]), the model of `brdfd::model`, the tidy
//! export of a read-only store — and crosses into Python as an `f64` or as the shortest
//! round-trip JSON text `brdfd fit --json` prints, which Python reads back to the same bits.
//! `brdfd/__init__.py` turns these into numpy, pandas and colour-science values.

use std::path::{Path, PathBuf};

use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;

use brdfd::cli::crossval::{CrossvalArgs, crossval_with};
use brdfd::cli::exchange::{ImportArgs, read_one};
use brdfd::cli::fit::{FitArgs, ScienceArgs, fit_with};
use brdfd::fit::FitReport;
use brdfd::geometry::{Device, GEOMETRIES, Geometry, by_name};
use brdfd::model::{self, Params, SpecularGeometry};
use brdfd::scan::Scan;
use brdfd::spectral::{BANDS, wavelengths_nm};

/// An error of the library, with its whole chain of causes, as a Python exception.
fn value_error(e: anyhow::Error) -> PyErr {
    PyValueError::new_err(format!("{e:#}"))
}

fn parse<T: std::str::FromStr>(what: &str, s: &str) -> PyResult<T>
where
    T::Err: std::fmt::Display,
{
    s.parse()
        .map_err(|e: T::Err| PyValueError::new_err(format!("{what} \"{s}\": {e}")))
}

/// An optional option: `None` stays `None`, a value is parsed by name.
fn parse_opt<T: std::str::FromStr>(what: &str, s: Option<&str>) -> PyResult<Option<T>>
where
    T::Err: std::fmt::Display,
{
    s.map(|s| parse(what, s)).transpose()
}

/// The science choices of `fit` and `crossval`, as `brdfd fit --preset --model --fresnel --sra
/// --sra-weight` take them: the preset's (`measured` by default) where one is not given.
fn science(
    preset: Option<&str>,
    model: Option<&str>,
    fresnel: Option<&str>,
    sra: Option<&str>,
    sra_weight: Option<&str>,
) -> PyResult<ScienceArgs> {
    Ok(ScienceArgs {
        preset: parse_opt("preset", preset)?.unwrap_or_default(),
        model: parse_opt("model", model)?,
        fresnel: parse_opt("Fresnel factor", fresnel)?,
        sra: parse_opt("SRA model", sra)?,
        sra_weight: parse_opt("SRA weight", sra_weight)?,
    })
}

/// One scan: a sample and the readings it is normalised by.
#[pyclass(name = "Scan", module = "brdfd._native", frozen)]
struct PyScan {
    scan: Scan,
    /// Where it was read from (named in errors).
    source: PathBuf,
}

#[pymethods]
impl PyScan {
    #[getter]
    fn sample(&self) -> &str {
        &self.scan.sample
    }

    /// The reference tile's name, or "instrument calibration" for an instrument export.
    #[getter]
    fn reference(&self) -> String {
        match &self.scan.reference {
            Some(r) => r.name.clone(),
            None => "instrument calibration".into(),
        }
    }

    /// The `brdfd.scan/1` document.
    fn to_json(&self) -> PyResult<String> {
        self.scan
            .to_json_pretty()
            .map_err(|e| value_error(anyhow::anyhow!(e)))
    }

    fn __repr__(&self) -> String {
        format!(
            "Scan(sample={:?}, reference={:?})",
            self.scan.sample,
            self.reference()
        )
    }
}

/// Reads a `brdfd.scan/1` file.
#[pyfunction]
fn read_scan(path: PathBuf) -> PyResult<PyScan> {
    let scan = Scan::read_file(&path)
        .map_err(|e| PyOSError::new_err(format!("{}: {e}", path.display())))?;
    Ok(PyScan { scan, source: path })
}

/// Reads an instrument's export (X-Rite .xlsx, the MA-T12's CGATS or CxF3 with an SRA CSV, or
/// a brdfd export) as `brdfd import-format` does: (scan, colorimetry-check JSON or None) pairs.
#[pyfunction]
#[pyo3(signature = (path, sra=None, reference=None))]
fn import_export(
    path: PathBuf,
    sra: Option<PathBuf>,
    reference: Option<String>,
) -> PyResult<Vec<(PyScan, Option<String>)>> {
    let args = ImportArgs {
        files: vec![path.clone()],
        format: None,
        sra,
        reference: reference.unwrap_or_else(|| brdfd::formats::DEFAULT_REFERENCE.into()),
        out: PathBuf::new(),
        force: false,
        json: false,
    };
    let imported = read_one(&args, &path).map_err(value_error)?;
    Ok(imported
        .into_iter()
        .map(|i| {
            let check = i.check.map(|(largest, at, warning)| {
                serde_json::json!({"largest_delta_e00": largest, "at": at, "warning": warning})
                    .to_string()
            });
            (
                PyScan {
                    scan: i.scan,
                    source: path.clone(),
                },
                check,
            )
        })
        .collect())
}

/// A finished fit.
#[pyclass(name = "FitReport", module = "brdfd._native", frozen)]
struct PyFitReport {
    report: FitReport,
}

#[pymethods]
impl PyFitReport {
    /// The fit document, exactly as `brdfd fit --json` prints it (its reach verdict included).
    fn to_json(&self) -> PyResult<String> {
        brdfd::cli::fit::fit_document_json(&self.report).map_err(|e| value_error(e.into()))
    }

    /// The measured BRDF (sr⁻¹), one 31-band list per geometry in table order; `None` where
    /// the scan has no reading.
    fn measured(&self) -> Vec<Option<Vec<f64>>> {
        let m = &self.report.measured;
        GEOMETRIES
            .iter()
            .map(|g| {
                m.geometries
                    .contains(g.index)
                    .then(|| m.values[g.index].to_vec())
            })
            .collect()
    }

    /// The fitted model's BRDF (sr⁻¹) at the 14 geometries, in table order.
    fn estimated(&self) -> Vec<Vec<f64>> {
        self.report.estimated.iter().map(|s| s.to_vec()).collect()
    }
}

/// Fits a scan exactly as `brdfd fit` does with the same options.
#[pyfunction]
#[pyo3(signature = (scan, cost, method=None, seed=None, bootstrap=0, sra=None, specular=None,
    fresnel=None, observer=None, weighting=None, sra_illuminant=None, sra_observer=None,
    model=None, hold_out=None, preset=None, sra_weight=None))]
#[allow(clippy::too_many_arguments)]
fn fit(
    py: Python<'_>,
    scan: &PyScan,
    cost: &str,
    method: Option<&str>,
    seed: Option<u64>,
    bootstrap: u32,
    sra: Option<&str>,
    specular: Option<&str>,
    fresnel: Option<&str>,
    observer: Option<&str>,
    weighting: Option<&str>,
    sra_illuminant: Option<&str>,
    sra_observer: Option<&str>,
    model: Option<&str>,
    hold_out: Option<Vec<String>>,
    preset: Option<&str>,
    sra_weight: Option<&str>,
) -> PyResult<PyFitReport> {
    let args = FitArgs {
        input: scan.source.clone(),
        cost: parse("cost function", cost)?,
        method: method
            .map(|m| parse("method", m))
            .transpose()?
            .unwrap_or_default(),
        seed: seed.unwrap_or(brdfd::optimise::Settings::default().seed),
        specular: specular
            .map(|s| parse("specular strategy", s))
            .transpose()?
            .unwrap_or_default(),
        science: science(preset, model, fresnel, sra, sra_weight)?,
        observer: observer
            .map(|o| parse("observer", o))
            .transpose()?
            .unwrap_or_default(),
        weighting: weighting
            .map(|w| parse("weighting", w))
            .transpose()?
            .unwrap_or_default(),
        sra_illuminant: sra_illuminant
            .map(|s| parse("SRA illuminant", s))
            .transpose()?
            .unwrap_or_default(),
        sra_observer: sra_observer
            .map(|s| parse("SRA observer", s))
            .transpose()?
            .unwrap_or_default(),
        bootstrap,
        hold_out: hold_out.unwrap_or_default(),
        json: true,
    };
    let scan = &scan.scan;
    let report = py.detach(|| fit_with(scan, &args)).map_err(value_error)?;
    Ok(PyFitReport { report })
}

/// Leave-one-geometry-out cross-validation exactly as `brdfd crossval` makes it with the same
/// options: the JSON text `brdfd crossval --json` prints. `cost`: the cost functions (all
/// three when `None`).
#[pyfunction]
#[pyo3(signature = (scan, cost=None, model=None, fresnel=None, method=None, seed=None,
    sra=None, observer=None, weighting=None, preset=None, sra_weight=None))]
#[allow(clippy::too_many_arguments)]
fn crossval(
    py: Python<'_>,
    scan: &PyScan,
    cost: Option<Vec<String>>,
    model: Option<&str>,
    fresnel: Option<&str>,
    method: Option<&str>,
    seed: Option<u64>,
    sra: Option<&str>,
    observer: Option<&str>,
    weighting: Option<&str>,
    preset: Option<&str>,
    sra_weight: Option<&str>,
) -> PyResult<String> {
    let args = CrossvalArgs {
        input: scan.source.clone(),
        cost: cost
            .unwrap_or_default()
            .iter()
            .map(|c| parse("cost function", c))
            .collect::<PyResult<_>>()?,
        science: science(preset, model, fresnel, sra, sra_weight)?,
        method: method
            .map(|m| parse("method", m))
            .transpose()?
            .unwrap_or_default(),
        seed: seed.unwrap_or(brdfd::optimise::Settings::default().seed),
        observer: observer
            .map(|o| parse("observer", o))
            .transpose()?
            .unwrap_or_default(),
        weighting: weighting
            .map(|w| parse("weighting", w))
            .transpose()?
            .unwrap_or_default(),
        json: true,
    };
    let scan = &scan.scan;
    let doc = py
        .detach(|| crossval_with(scan, &args))
        .map_err(value_error)?;
    serde_json::to_string(&doc).map_err(|e| value_error(e.into()))
}

/// The 14 geometries: (name, device, θi, θr, φr, aspecular), degrees, in table order.
#[pyfunction]
fn geometries() -> Vec<(&'static str, &'static str, f64, f64, f64, f64)> {
    GEOMETRIES
        .iter()
        .map(|g| {
            (
                g.name,
                g.device.key(),
                g.theta_i_deg,
                g.theta_r_deg,
                g.phi_r_deg,
                g.aspecular_deg,
            )
        })
        .collect()
}

/// The band centres, nm.
#[pyfunction]
fn wavelengths() -> Vec<u32> {
    wavelengths_nm().to_vec()
}

/// A geometry given by name or as (θi, θr, φr) in degrees.
#[derive(FromPyObject)]
enum GeometryArg {
    Name(String),
    Angles(f64, f64, f64),
}

/// The model's BRDF (sr⁻¹): one row per geometry, one column per wavelength (band centres).
/// `model` is a model option (`paper`, `oren-nayar`, `two-lobe`) and `extra` its own
/// parameters in order (Oren–Nayar `[sigma]`, second lobe `[ks2, alpha2]`).
#[pyfunction]
#[pyo3(signature = (kd, ks, alpha, ior, geometries, wavelengths, fresnel=None, model=None, extra=None))]
#[allow(clippy::too_many_arguments)]
fn evaluate(
    kd: Vec<f64>,
    ks: f64,
    alpha: f64,
    ior: f64,
    geometries: Vec<GeometryArg>,
    wavelengths: Vec<u32>,
    fresnel: Option<&str>,
    model: Option<&str>,
    extra: Option<Vec<f64>>,
) -> PyResult<Vec<Vec<f64>>> {
    let kd: [f64; BANDS] = kd.try_into().map_err(|v: Vec<f64>| {
        PyValueError::new_err(format!(
            "kd has {} values; the model has {BANDS} bands (400–700 nm every 10 nm)",
            v.len()
        ))
    })?;
    // The paper's factor unless told: a fit's document names the factor it was made with.
    let fresnel: model::FresnelCosine = parse("Fresnel factor", fresnel.unwrap_or("incidence"))?;
    let kind: model::ModelKind = model
        .unwrap_or("paper")
        .parse()
        .map_err(PyValueError::new_err)?;
    let given = extra.unwrap_or_default();
    let names = kind.extra_names();
    if given.len() != names.len() {
        return Err(PyValueError::new_err(format!(
            "model \"{kind}\" has {} extra parameters ({}), {} given",
            names.len(),
            if names.is_empty() {
                "none".to_string()
            } else {
                names.join(", ")
            },
            given.len()
        )));
    }
    let mut extra = [0.0; model::EXTRA];
    extra[..given.len()].copy_from_slice(&given);
    let params = Params {
        kd,
        ks,
        alpha,
        ior,
        extra,
    };
    let nm = wavelengths_nm();
    let bands: Vec<usize> = wavelengths
        .iter()
        .map(|w| {
            nm.iter().position(|n| n == w).ok_or_else(|| {
                PyValueError::new_err(format!(
                    "wavelength {w} nm is not one of the model's bands (400–700 nm every 10 nm)"
                ))
            })
        })
        .collect::<PyResult<_>>()?;
    let mut rows = Vec::with_capacity(geometries.len());
    for g in geometries {
        let sg = match g {
            GeometryArg::Name(name) => SpecularGeometry::new(by_name(&name).ok_or_else(|| {
                let names: Vec<&str> = GEOMETRIES.iter().map(|g| g.name).collect();
                PyValueError::new_err(format!(
                    "unknown geometry \"{name}\"; valid: {}",
                    names.join(", ")
                ))
            })?),
            GeometryArg::Angles(theta_i_deg, theta_r_deg, phi_r_deg) => {
                SpecularGeometry::new(&Geometry {
                    index: 0,
                    device: Device::MaT12,
                    name: "",
                    theta_i_deg,
                    theta_r_deg,
                    phi_r_deg,
                    aspecular_deg: f64::NAN,
                })
            }
        };
        // The same arithmetic as model::evaluate_model, at one geometry: kd(λ)·a + (lobe + t)
        // (the paper's model: a = 1, t = 0, which is model::evaluate bit for bit).
        let s = model::specular_term(params.ks, params.alpha, params.ior, fresnel, &sg);
        if kind == model::ModelKind::Paper {
            rows.push(bands.iter().map(|&b| params.kd[b] + s).collect());
        } else {
            let (a, t) = kind.shape(&params.extra, params.ior, fresnel, &sg);
            rows.push(bands.iter().map(|&b| params.kd[b] * a + (s + t)).collect());
        }
    }
    Ok(rows)
}

/// The tidy export of a store, read-only: (spectra.csv, fits.csv) text.
#[pyfunction]
#[pyo3(signature = (path, include_simulated=true))]
fn store_tidy(
    py: Python<'_>,
    path: PathBuf,
    include_simulated: bool,
) -> PyResult<(String, String)> {
    py.detach(|| -> anyhow::Result<(String, String)> {
        let study = brdfd::cli::report::load_study_checked(
            Path::new(&path),
            &brdfd::report::load::Selection::All,
            include_simulated,
        )?;
        Ok((
            brdfd::formats::tidy::spectra(&study)?,
            brdfd::formats::tidy::fits(&study)?,
        ))
    })
    .map_err(value_error)
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyScan>()?;
    m.add_class::<PyFitReport>()?;
    m.add_function(wrap_pyfunction!(read_scan, m)?)?;
    m.add_function(wrap_pyfunction!(import_export, m)?)?;
    m.add_function(wrap_pyfunction!(fit, m)?)?;
    m.add_function(wrap_pyfunction!(crossval, m)?)?;
    m.add_function(wrap_pyfunction!(geometries, m)?)?;
    m.add_function(wrap_pyfunction!(wavelengths, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(store_tidy, m)?)?;
    m.add("VERSION", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
