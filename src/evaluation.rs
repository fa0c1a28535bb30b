//! How well a fit reproduces a measurement, in colour (SCIENCE.md §7): ΔE00 between measured
//! and estimated colour at each of the 14 geometries, summarised over all geometries and
//! split into diffuse (the 12 MA-T12 geometries) and specular (the 2 SRA geometries).
//!
//! Both inputs are BRDF in sr⁻¹; each is turned into a reflectance factor `R = π · f` and then
//! into CIELAB by [`crate::colour`]: D65 with the paper's 2° observer and plain summation by
//! default ([`evaluate`]), or any [`Colorimetry`] ([`evaluate_with`]; SCIENCE.md §7.1).

use serde::{Deserialize, Serialize};

use crate::colour::{Colorimetry, Lab, brdf_to_reflectance, ciede2000, reflectance_to_lab};
use crate::geometry::{Device, GEOMETRIES, GEOMETRY_COUNT, GeometrySet};
use crate::spectral::Spectrum;

/// Mean, median and maximum of a set of ΔE00 values.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub mean: f64,
    /// For an even count, the mean of the two middle values.
    pub median: f64,
    pub max: f64,
}

impl Summary {
    /// Summarises `xs`; `None` when it is empty. A NaN anywhere makes the mean NaN and is
    /// ordered above every number (IEEE total order), so it also shows up as the maximum.
    pub fn of(xs: &[f64]) -> Option<Summary> {
        if xs.is_empty() {
            return None;
        }
        let mut sorted = xs.to_vec();
        sorted.sort_by(f64::total_cmp);
        let n = sorted.len();
        let median = if n % 2 == 1 {
            sorted[n / 2]
        } else {
            (sorted[n / 2 - 1] + sorted[n / 2]) / 2.0
        };
        Some(Summary {
            mean: xs.iter().sum::<f64>() / n as f64,
            median,
            max: sorted[n - 1],
        })
    }
}

/// The colour evaluation of one fit, over the geometries the scan measured.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Evaluation {
    /// ΔE00 at each geometry, in [`GEOMETRIES`] order; NaN at a geometry outside
    /// [`Evaluation::geometries`] (read them through [`Evaluation::per_geometry_named`] or
    /// [`Evaluation::at`]).
    pub per_geometry: [f64; GEOMETRY_COUNT],
    /// The geometries evaluated: those the scan measured.
    #[serde(skip)]
    pub geometries: GeometrySet,
    /// Over every geometry evaluated.
    pub all: Summary,
    /// Over the 12 MA-T12 geometries.
    pub diffuse: Summary,
    /// Over the 2 SRA geometries; `None` for a scan without SRA readings.
    pub specular: Option<Summary>,
}

impl Evaluation {
    /// `(geometry name, ΔE00)` of every geometry evaluated, in [`GEOMETRIES`] order, for the
    /// `"delta_e00": {"<geometry>": x}` objects of the CLI and the API.
    pub fn per_geometry_named(&self) -> Vec<(&'static str, f64)> {
        self.geometries
            .iter()
            .map(|g| (g.name, self.per_geometry[g.index]))
            .collect()
    }

    /// The ΔE00 of every geometry evaluated, in table order (12 or 14 values).
    pub fn evaluated(&self) -> Vec<f64> {
        self.geometries
            .iter()
            .map(|g| self.per_geometry[g.index])
            .collect()
    }

    /// ΔE00 at the geometry of table index `g`, `None` where it was not evaluated.
    pub fn at(&self, g: usize) -> Option<f64> {
        self.geometries.contains(g).then(|| self.per_geometry[g])
    }

    /// The evaluation from its stored parts: per-geometry values (NaN where absent) and the
    /// set they cover; the summaries are recomputed, so they cannot disagree with the values.
    pub fn from_per_geometry(
        per_geometry: [f64; GEOMETRY_COUNT],
        geometries: GeometrySet,
    ) -> Evaluation {
        summarise(per_geometry, geometries)
    }
}

/// CIELAB at each geometry of a BRDF (sr⁻¹), in [`GEOMETRIES`] order, for reports.
pub fn lab_per_geometry(brdf: &[Spectrum; GEOMETRY_COUNT]) -> [Lab; GEOMETRY_COUNT] {
    brdf.map(|f| reflectance_to_lab(&brdf_to_reflectance(&f)))
}

/// CIELAB at each geometry of a BRDF (sr⁻¹) under `colorimetry`.
pub fn lab_per_geometry_with(
    brdf: &[Spectrum; GEOMETRY_COUNT],
    colorimetry: Colorimetry,
) -> [Lab; GEOMETRY_COUNT] {
    brdf.map(|f| colorimetry.reflectance_to_lab(&brdf_to_reflectance(&f)))
}

/// The summaries of per-geometry ΔE00 over `geometries` (NaN is put at every other geometry).
fn summarise(mut per_geometry: [f64; GEOMETRY_COUNT], geometries: GeometrySet) -> Evaluation {
    for (g, v) in per_geometry.iter_mut().enumerate() {
        if !geometries.contains(g) {
            *v = f64::NAN;
        }
    }
    // Split by the device the geometry table names, not by position, so a reordered table
    // cannot silently move a geometry into the wrong group.
    let of = |device: Option<Device>| -> Vec<f64> {
        GEOMETRIES
            .iter()
            .filter(|g| geometries.contains(g.index) && device.is_none_or(|d| g.device == d))
            .map(|g| per_geometry[g.index])
            .collect()
    };
    Evaluation {
        per_geometry,
        geometries,
        all: Summary::of(&of(None)).expect("a scan measures at least one geometry"),
        diffuse: Summary::of(&of(Some(Device::MaT12)))
            .expect("every scan has the 12 MA-T12 geometries"),
        specular: Summary::of(&of(Some(Device::Sra))),
    }
}

/// ΔE00 between a measured and an estimated BRDF (both sr⁻¹, [`GEOMETRIES`] order) at all 14
/// geometries, D65/2° summation (the paper's colorimetry).
pub fn evaluate(
    measured: &[Spectrum; GEOMETRY_COUNT],
    estimated: &[Spectrum; GEOMETRY_COUNT],
) -> Evaluation {
    evaluate_with(
        measured,
        estimated,
        Colorimetry::default(),
        GeometrySet::ALL,
    )
}

/// ΔE00 between a measured and an estimated BRDF under `colorimetry`, at `geometries` (those
/// the scan measured).
pub fn evaluate_with(
    measured: &[Spectrum; GEOMETRY_COUNT],
    estimated: &[Spectrum; GEOMETRY_COUNT],
    colorimetry: Colorimetry,
    geometries: GeometrySet,
) -> Evaluation {
    let lab_m = lab_per_geometry_with(measured, colorimetry);
    let lab_e = lab_per_geometry_with(estimated, colorimetry);
    let per_geometry: [f64; GEOMETRY_COUNT] =
        std::array::from_fn(|g| ciede2000(lab_m[g], lab_e[g]));
    summarise(per_geometry, geometries)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::colour::xyz_to_lab;
    use crate::geometry::{MA_T12_COUNT, by_name};
    use crate::spectral::flat;
    use std::f64::consts::PI;

    fn uniform(reflectance: f64) -> [Spectrum; GEOMETRY_COUNT] {
        [flat(reflectance / PI); GEOMETRY_COUNT]
    }

    #[test]
    fn identical_brdfs_give_zero_everywhere() {
        let m = uniform(0.4);
        let e = evaluate(&m, &m);
        assert_eq!(e.per_geometry, [0.0; GEOMETRY_COUNT]);
        assert_eq!(
            e.all,
            Summary {
                mean: 0.0,
                median: 0.0,
                max: 0.0
            }
        );
    }

    #[test]
    fn grey_lightness_step_matches_the_hand_computed_de00() {
        // Measured grey R = 0.5 (L* = 76.0693), estimated grey R = 0.4, only at one diffuse
        // geometry; elsewhere identical. For neutral colours ΔE00 = |ΔL*| / S_L with
        // S_L = 1 + 0.015 (L̄ − 50)² / √(20 + (L̄ − 50)²) (CIE 142-2001).
        let m = uniform(0.5);
        let mut est = m;
        let g = by_name("45as45").unwrap().index;
        est[g] = flat(0.4 / PI);
        let l1 = 76.0693;
        // L* of grey 0.4: Y/Yn = 0.4 → 116·0.4^(1/3) − 16.
        let l2 = 116.0 * 0.4f64.cbrt() - 16.0;
        let lm = (l1 + l2) / 2.0;
        let s_l = 1.0 + 0.015 * (lm - 50.0f64).powi(2) / (20.0 + (lm - 50.0f64).powi(2)).sqrt();
        let expected = (l1 - l2) / s_l;

        let e = evaluate(&m, &est);
        assert!(
            (e.per_geometry[g] - expected).abs() < 1e-4,
            "{} vs {expected}",
            e.per_geometry[g]
        );
        let others: f64 = e
            .per_geometry
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != g)
            .map(|(_, v)| v)
            .sum();
        assert_eq!(others, 0.0);
        assert!((e.all.mean - e.per_geometry[g] / 14.0).abs() < 1e-12);
        assert_eq!(e.all.median, 0.0);
        assert_eq!(e.all.max, e.per_geometry[g]);
        assert!((e.diffuse.mean - e.per_geometry[g] / 12.0).abs() < 1e-12);
        assert_eq!(
            e.specular.unwrap(),
            Summary {
                mean: 0.0,
                median: 0.0,
                max: 0.0
            }
        );
    }

    #[test]
    fn specular_split_takes_the_two_sra_geometries() {
        let m = uniform(0.3);
        let mut est = m;
        // Specular readings far above white: still a finite ΔE00, carried only by the SRA group.
        est[by_name("sra-20").unwrap().index] = flat(2.0 / PI);
        est[by_name("sra-60").unwrap().index] = flat(1.0 / PI);
        let e = evaluate(&m, &est);
        let d20 = e.per_geometry[12];
        let d60 = e.per_geometry[13];
        assert!(d20 > d60 && d60 > 0.0);
        assert_eq!(
            e.diffuse,
            Summary {
                mean: 0.0,
                median: 0.0,
                max: 0.0
            }
        );
        assert!((e.specular.unwrap().mean - (d20 + d60) / 2.0).abs() < 1e-12);
        assert!((e.specular.unwrap().median - (d20 + d60) / 2.0).abs() < 1e-12);
        assert_eq!(e.specular.unwrap().max, d20);
        assert_eq!(e.all.max, d20);
        let named = e.per_geometry_named();
        assert_eq!(named[0], ("15as-45", 0.0));
        assert_eq!(named[12], ("sra-20", d20));
        assert_eq!(named[13], ("sra-60", d60));
        assert_eq!(GEOMETRY_COUNT - MA_T12_COUNT, 2);
    }

    #[test]
    fn lab_per_geometry_uses_r_equals_pi_f() {
        let labs = lab_per_geometry(&uniform(0.5));
        for lab in labs {
            assert!((lab.l - 76.0693).abs() < 1e-4 && lab.a.abs() < 1e-4 && lab.b.abs() < 1e-4);
        }
        // A BRDF of 1/π is the white diffuser: L* = 100.
        let white = lab_per_geometry(&uniform(1.0));
        let w = xyz_to_lab(crate::colour::white_point(), crate::colour::white_point());
        assert!((white[0].l - w.l).abs() < 1e-12 && (w.l - 100.0).abs() < 1e-12);
    }

    #[test]
    fn summary_median_and_empty() {
        assert_eq!(Summary::of(&[]), None);
        assert_eq!(
            Summary::of(&[3.0, 1.0, 2.0]),
            Some(Summary {
                mean: 2.0,
                median: 2.0,
                max: 3.0
            })
        );
        assert_eq!(
            Summary::of(&[4.0, 1.0, 3.0, 2.0]),
            Some(Summary {
                mean: 2.5,
                median: 2.5,
                max: 4.0
            })
        );
    }

    #[test]
    fn evaluation_serialises_with_its_field_names() {
        let m = uniform(0.5);
        let json = serde_json::to_value(evaluate(&m, &m)).unwrap();
        assert_eq!(json["per_geometry"].as_array().unwrap().len(), 14);
        for key in ["all", "diffuse", "specular"] {
            assert_eq!(json[key]["max"], 0.0, "{key}");
        }
    }
}
