//! What one SRA reading says about the sample, chosen per fit and recorded with it
//! (SCIENCE.md §5.1).
//!
//! The Canon SRA reports one achromatic number per geometry. Processing spreads it flat over the
//! 31 bands (`crate::processing`); how the fit and the evaluation then read that flat spectrum
//! is the [`SraModel`]:
//!
//! - [`SraModel::Flat`] (the paper's, the type's default and `brdfd demo`'s): the reading *is* a
//!   grey spectrum. The cost
//!   compares the model with it band by band (31 terms per SRA geometry) and the evaluation
//!   takes ΔE00 against it. Bit for bit what brdfd did before the option existed.
//! - [`SraModel::Luminance`] ([`SraModel::MEASURED_DEFAULT`]: what a measured scan is fitted
//!   with unless told otherwise): the reading is the sample's luminous reflectance at that geometry,
//!   `Y = Σ S(λ) ȳ(λ) f(λ) / Σ S(λ) ȳ(λ)` under the instrument's illuminant `S` and observer `ȳ`
//!   ([`SraReading`]; ISO 2813's CIE illuminant C and the 2° V(λ) by default), which is what a
//!   gloss meter or surface reflectance analyser is built to read. The cost compares the model's
//!   `Y` with the reading (one residual per SRA geometry, weighted as the 31 terms it replaces);
//!   the model's spectral shape at those geometries is left to the 12 MA-T12 geometries.
//!
//! Either way the evaluation also reports |ΔL*| between the model's and the measured luminance
//! at the two SRA geometries ([`specular_delta_l`]), the specular metric that does not depend on
//! how the reading was spread.
//!
//! `Y` here is normalised so that a flat spectrum of value `v` has `Y = v` (same units as the
//! spectrum, sr⁻¹ for a BRDF); L* takes `π·Y` as a luminous reflectance factor with white 1.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::colour::{Observer, Xyz, cie, xyz_to_lab};
use crate::geometry::{GEOMETRIES, GEOMETRY_COUNT, MA_T12_COUNT, SRA_COUNT};
use crate::spectral::{BANDS, Spectrum};

/// How an SRA reading constrains the model (`brdfd fit --sra`, `[fit] sra`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SraModel {
    /// The reading spread flat over the 31 bands is a grey spectrum (the paper's).
    #[default]
    Flat,
    /// The reading is the luminous reflectance Y at that geometry.
    Luminance,
}

impl SraModel {
    /// The model a measured scan is fitted with unless told otherwise (`brdfd fit`, `[fit] sra`,
    /// the Python package): `luminance`, the one whose bootstrap intervals are calibrated and
    /// the only one that can be right on a real SRA (SCIENCE.md §10). The type's `Default`
    /// stays the paper's `flat`, which settings stored without an SRA model were fitted with.
    pub const MEASURED_DEFAULT: SraModel = SraModel::Luminance;

    /// Both models, the type's default first.
    pub const ALL: [SraModel; 2] = [SraModel::Flat, SraModel::Luminance];

    /// The name used on the command line, in settings, in the store and in reports.
    pub const fn name(self) -> &'static str {
        match self {
            SraModel::Flat => "flat",
            SraModel::Luminance => "luminance",
        }
    }
}

impl fmt::Display for SraModel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// An SRA model name that is not `flat` or `luminance`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown SRA reading model \"{0}\": expected flat (the paper's, the default) or luminance")]
pub struct ParseSraModelError(pub String);

impl FromStr for SraModel {
    type Err = ParseSraModelError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        SraModel::ALL
            .into_iter()
            .find(|m| m.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| ParseSraModelError(s.to_string()))
    }
}

/// The illuminant the SRA's luminance is read under.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
pub enum SraIlluminant {
    /// CIE illuminant C, which ISO 2813 specifies for gloss measurement (the default).
    #[default]
    #[serde(rename = "C")]
    C,
    /// CIE D65, the illuminant of brdfd's colour evaluation.
    #[serde(rename = "D65")]
    D65,
}

impl fmt::Display for SraIlluminant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            SraIlluminant::C => "C",
            SraIlluminant::D65 => "D65",
        })
    }
}

impl FromStr for SraIlluminant {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim() {
            "C" | "c" => Ok(SraIlluminant::C),
            "D65" | "d65" => Ok(SraIlluminant::D65),
            _ => Err(format!(
                "unknown SRA illuminant \"{s}\": expected C (ISO 2813, the default) or D65"
            )),
        }
    }
}

/// How much the SRA's readings weigh in the cost beside the MA-T12's (`brdfd fit
/// --sra-weight`, `[fit] sra_weight`; SCIENCE.md §5.2).
///
/// The paper weighs every geometry by cos θi alone, so a glossy sample's specular readings,
/// tens to thousands of times its diffuse ones, carry residuals as many times larger: under cf1
/// and m2 a lobe that cannot follow them exactly pulls the whole fit, the diffuse colour
/// included, towards them. [`SraWeight::Balanced`] measures each instrument's residuals against
/// its own readings' level instead: when the SRA geometries' mean weighted reading `S` is above
/// the MA-T12's `D`, their weights are scaled by `D / S` ([`SraWeight::scale`]), so that a
/// relative miss at an SRA geometry costs what the same relative miss costs at an MA-T12 one.
/// A scan whose SRA readings are at or below its diffuse level is weighed as the paper does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SraWeight {
    /// Every geometry by cos θi (paper Eq. 6–8): the type's default, what settings stored
    /// without a weight were fitted with.
    #[default]
    Paper,
    /// The SRA geometries' weights scaled down to the MA-T12 readings' level when theirs is
    /// above it.
    Balanced,
}

impl SraWeight {
    /// Both, the type's default first.
    pub const ALL: [SraWeight; 2] = [SraWeight::Paper, SraWeight::Balanced];

    /// The name on the command line, in settings and in reports.
    pub const fn name(self) -> &'static str {
        match self {
            SraWeight::Paper => "paper",
            SraWeight::Balanced => "balanced",
        }
    }

    /// True for the paper's weighting (settings leave it out).
    pub fn is_paper(&self) -> bool {
        *self == SraWeight::Paper
    }

    /// The factor the SRA geometries' cosine weights are multiplied by, for a scan whose
    /// measured MA-T12 geometries have the mean weighted reading `diffuse_level` and whose SRA
    /// geometries `sra_level` (`w·` the band mean, sr⁻¹): 1 under the paper's weighting, or
    /// when the SRA level is not above the MA-T12 one (or either is not positive).
    pub fn scale(self, diffuse_level: f64, sra_level: f64) -> f64 {
        match self {
            SraWeight::Balanced if sra_level > diffuse_level && diffuse_level > 0.0 => {
                diffuse_level / sra_level
            }
            _ => 1.0,
        }
    }
}

crate::names::choice_by_name!(
    SraWeight,
    "SRA weight",
    "paper (every geometry by cos θi, as the paper) or balanced (the SRA readings weighed at \
     the MA-T12 readings' level)"
);

/// The SRA reading model of a fit, the instrument's illuminant and observer, and the SRA
/// readings' weight in the cost. The default is the paper's flat model and weights (the
/// illuminant and observer then only serve the |ΔL*| evaluation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SraReading {
    #[serde(default)]
    pub model: SraModel,
    #[serde(default)]
    pub illuminant: SraIlluminant,
    #[serde(default)]
    pub observer: Observer,
    /// Left out of the serialised settings when it is the paper's, so that they read as
    /// before the option existed.
    #[serde(default, skip_serializing_if = "SraWeight::is_paper")]
    pub weight: SraWeight,
}

impl fmt::Display for SraReading {
    /// e.g. `flat`, `luminance (C/2°)`, `luminance (C/2°), balanced`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.model {
            SraModel::Flat => f.write_str("flat")?,
            SraModel::Luminance => write!(f, "luminance ({}/{}°)", self.illuminant, self.observer)?,
        }
        if !self.weight.is_paper() {
            write!(f, ", {}", self.weight)?;
        }
        Ok(())
    }
}

impl SraReading {
    /// The paper's model with the default instrument.
    pub const FLAT: SraReading = SraReading {
        model: SraModel::Flat,
        illuminant: SraIlluminant::C,
        observer: Observer::Cie1931TwoDegree,
        weight: SraWeight::Paper,
    };

    /// The luminance model with the default instrument (ISO 2813: illuminant C, 2° V(λ)).
    pub const LUMINANCE: SraReading = SraReading {
        model: SraModel::Luminance,
        illuminant: SraIlluminant::C,
        observer: Observer::Cie1931TwoDegree,
        weight: SraWeight::Paper,
    };

    /// The default (the paper's flat model, default instrument): settings leave it out.
    pub fn is_default(&self) -> bool {
        *self == SraReading::default()
    }

    /// `self` with another model, the same instrument.
    pub fn with_model(self, model: SraModel) -> SraReading {
        SraReading { model, ..self }
    }

    /// `self` with another weight in the cost.
    pub fn with_weight(self, weight: SraWeight) -> SraReading {
        SraReading { weight, ..self }
    }

    /// The normalised luminance weights `c_b = S(λ_b) ȳ(λ_b) / Σ S ȳ` at the band centres
    /// (they sum to 1, so a flat spectrum keeps its value).
    pub fn weights(&self) -> Spectrum {
        let s = match self.illuminant {
            SraIlluminant::C => cie::illuminant_c(),
            SraIlluminant::D65 => cie::d65(),
        };
        let ybar = match self.observer {
            Observer::Cie1931TwoDegree => cie::cmf(),
            Observer::Cie1964TenDegree => cie::cmf10(),
        };
        let raw: Spectrum = std::array::from_fn(|b| s[b] * ybar[b][1]);
        let sum: f64 = raw.iter().sum();
        raw.map(|x| x / sum)
    }

    /// The luminance `Y = Σ c_b f_b` of a spectrum, in its own units.
    pub fn luminance(&self, f: &Spectrum) -> f64 {
        luminance_with(&self.weights(), f)
    }

    /// CIE L* of a BRDF's luminance (sr⁻¹), read as the luminous reflectance factor `π·Y`
    /// relative to white 1. Specular readings above white give L* > 100.
    pub fn lightness(&self, brdf: &Spectrum) -> f64 {
        lightness_of(std::f64::consts::PI * self.luminance(brdf))
    }
}

/// `Σ c_b f_b`.
pub fn luminance_with(weights: &Spectrum, f: &Spectrum) -> f64 {
    weights.iter().zip(f).map(|(c, x)| c * x).sum()
}

/// CIE 1976 L* of a luminous reflectance factor `y` (white = 1), CIE 15:2018 §8.2.1.
pub fn lightness_of(y: f64) -> f64 {
    let one = Xyz {
        x: 1.0,
        y: 1.0,
        z: 1.0,
    };
    xyz_to_lab(Xyz { x: y, y, z: y }, one).l
}

/// |ΔL*| at the two SRA geometries between the measured and the model luminance.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SpecularDeltaL {
    /// |ΔL*| at sra-20 and sra-60, in [`GEOMETRIES`] order.
    pub per_geometry: [f64; SRA_COUNT],
    /// Their mean.
    pub mean: f64,
}

impl SpecularDeltaL {
    /// `(geometry name, |ΔL*|)` for the two SRA geometries.
    pub fn named(&self) -> [(&'static str, f64); SRA_COUNT] {
        std::array::from_fn(|k| (GEOMETRIES[MA_T12_COUNT + k].name, self.per_geometry[k]))
    }
}

/// |ΔL*| between measured and estimated luminance at the SRA geometries (both BRDF in sr⁻¹,
/// [`GEOMETRIES`] order), under the instrument of `reading` (its model does not matter: the
/// measured luminance of the flat spectrum processing makes is the reading itself).
pub fn specular_delta_l(
    measured: &[Spectrum; GEOMETRY_COUNT],
    estimated: &[Spectrum; GEOMETRY_COUNT],
    reading: SraReading,
) -> SpecularDeltaL {
    let c = reading.weights();
    let l = |f: &Spectrum| lightness_of(std::f64::consts::PI * luminance_with(&c, f));
    let per_geometry: [f64; SRA_COUNT] = std::array::from_fn(|k| {
        let g = MA_T12_COUNT + k;
        (l(&measured[g]) - l(&estimated[g])).abs()
    });
    SpecularDeltaL {
        per_geometry,
        mean: per_geometry.iter().sum::<f64>() / SRA_COUNT as f64,
    }
}

/// Replaces each SRA geometry's spectrum by its luminance, flat: what processing makes of a
/// luminance-reading SRA (the simulated instruments' `luminance` response).
pub fn luminance_sra(brdf: &mut [Spectrum; GEOMETRY_COUNT], reading: SraReading) {
    let c = reading.weights();
    for s in brdf.iter_mut().skip(MA_T12_COUNT) {
        *s = [luminance_with(&c, s); BANDS];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::colour::reflectance_to_xyz;
    use crate::spectral::flat;
    use std::f64::consts::PI;

    #[test]
    fn weights_sum_to_one_and_follow_v_lambda() {
        for reading in [
            SraReading::LUMINANCE,
            SraReading {
                illuminant: SraIlluminant::D65,
                observer: Observer::Cie1964TenDegree,
                ..SraReading::LUMINANCE
            },
        ] {
            let c = reading.weights();
            assert!((c.iter().sum::<f64>() - 1.0).abs() < 1e-15);
            assert!(c.iter().all(|&x| x >= 0.0));
            // V(λ) peaks at 555 nm: the 550 and 560 nm bands outweigh both ends by far.
            assert!(c[15] > 20.0 * c[0] && c[16] > 20.0 * c[30], "{c:?}");
            // A flat spectrum keeps its value.
            assert!((reading.luminance(&flat(0.3)) - 0.3).abs() < 1e-15);
        }
    }

    #[test]
    fn d65_two_degree_luminance_is_the_colour_modules_y() {
        // Same illuminant and observer as the colour evaluation: Y/100 of the reflectance.
        let reading = SraReading {
            illuminant: SraIlluminant::D65,
            ..SraReading::LUMINANCE
        };
        let r: Spectrum = std::array::from_fn(|b| 0.1 + 0.02 * b as f64);
        let y = reflectance_to_xyz(&r).y / 100.0;
        assert!((reading.luminance(&r) - y).abs() < 1e-14, "{y}");
    }

    #[test]
    fn weights_are_the_illuminant_times_y_bar() {
        // c(400)/c(560) = S(400) ȳ(400) / (S(560) ȳ(560)): C(400)/C(560) = 63.3/105.3,
        // D65(400)/D65(560) = 82.7549/100, ȳ(400)/ȳ(560) = 0.000396/0.995.
        let c = SraReading::LUMINANCE.weights();
        let d = SraReading {
            illuminant: SraIlluminant::D65,
            ..SraReading::LUMINANCE
        }
        .weights();
        assert!((c[0] / c[16] - (63.30 / 105.30) * (0.000396 / 0.995)).abs() < 1e-12);
        assert!((d[0] / d[16] - (82.7549 / 100.0) * (0.000396 / 0.995)).abs() < 1e-12);
    }

    #[test]
    fn lightness_is_cie_l_star() {
        assert!((lightness_of(1.0) - 100.0).abs() < 1e-12);
        // Y = 0.18 → L* = 116·0.18^(1/3) − 16 = 49.4961...
        assert!((lightness_of(0.18) - (116.0 * 0.18f64.cbrt() - 16.0)).abs() < 1e-12);
        // Below (6/29)³ the straight line: L* = 903.3 Y.
        assert!((lightness_of(0.001) - 0.001 * 24389.0 / 27.0).abs() < 1e-9);
        assert!(
            (SraReading::LUMINANCE.lightness(&flat(0.5 / PI)) - lightness_of(0.5)).abs() < 1e-12
        );
    }

    #[test]
    fn specular_delta_l_looks_only_at_the_sra_luminance() {
        let m = [flat(0.2); GEOMETRY_COUNT];
        let mut e = m;
        // Diffuse differences do not count; a coloured spectrum with the same luminance at an
        // SRA geometry gives 0, a brighter one gives its |ΔL*|.
        e[0] = flat(0.9);
        let c = SraReading::LUMINANCE.weights();
        let mut tilted: Spectrum = std::array::from_fn(|b| 0.1 + 0.01 * b as f64);
        let k = 0.2 / luminance_with(&c, &tilted);
        tilted = tilted.map(|x| x * k);
        e[MA_T12_COUNT] = tilted;
        e[MA_T12_COUNT + 1] = flat(0.3);
        let d = specular_delta_l(&m, &e, SraReading::FLAT);
        assert!(d.per_geometry[0] < 1e-12, "{d:?}");
        let want = lightness_of(0.3 * PI) - lightness_of(0.2 * PI);
        assert!((d.per_geometry[1] - want).abs() < 1e-12);
        assert!((d.mean - want / 2.0).abs() < 1e-12);
        assert_eq!(d.named()[0].0, "sra-20");
        assert_eq!(d.named()[1].0, "sra-60");
    }

    #[test]
    fn names_round_trip_and_the_default_is_flat() {
        for m in SraModel::ALL {
            assert_eq!(m.name().parse::<SraModel>().unwrap(), m);
            assert_eq!(serde_json::to_string(&m).unwrap(), format!("\"{m}\""));
        }
        assert_eq!(SraReading::default(), SraReading::FLAT);
        assert!(SraReading::FLAT.is_default() && !SraReading::LUMINANCE.is_default());
        let e = "grey".parse::<SraModel>().unwrap_err().to_string();
        assert!(e.contains("flat") && e.contains("luminance"), "{e}");
        let r: SraReading = serde_json::from_str(r#"{"model": "luminance"}"#).unwrap();
        assert_eq!(r, SraReading::LUMINANCE);
        assert_eq!(r.to_string(), "luminance (C/2°)");
        assert!(serde_json::from_str::<SraReading>(r#"{"modle": "flat"}"#).is_err());
        for i in [SraIlluminant::C, SraIlluminant::D65] {
            assert_eq!(i.to_string().parse::<SraIlluminant>(), Ok(i));
        }
        assert!("A".parse::<SraIlluminant>().unwrap_err().contains("D65"));
    }
}
