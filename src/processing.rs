//! From device readings to measured BRDF (SCIENCE.md §3).
//!
//! MA-T12 readings are divided by the Munsell N9 reference reading at the same geometry;
//! SRA readings are normalised by the reference and spread flat over the 31 bands.
//! The result is a measured BRDF `M_g(λ) = R_g(λ) / π` in sr⁻¹ at all 14 geometries.
//!
//! - MA-T12: `R_g(λ) = S_g(λ) / W_g(λ) · ρ_ref(λ)`.
//! - SRA, `q_g = I_g / I_ref,g`, then by [`SpecularStrategy`]:
//!   `ratio` `R_g = q_g · ρ̄_ref`, or `paper-eq9` `R_g = q_g · π / 300 nm` (paper Eq. 9).
//!
//! A scan without an N9 reading (an instrument-software export) is already the reflectance
//! factor relative to the instrument's own calibrated white standard: `R_g(λ) = S_g(λ)`,
//! absolute scale, and no tile calibration applies. A scan without SRA readings has a measured
//! BRDF at the 12 MA-T12 geometries only ([`MeasuredBrdf::geometries`]).
//!
//! `ρ_ref` is the reference tile's calibrated reflectance factor; without a calibration table it
//! is 1 and results are relative to the tile, as the paper's are. The SRA is achromatic, so the
//! `ratio` strategy scales it by the band mean `ρ̄_ref` of the table: the specular readings stay
//! flat (the paper's assumption) and land on the same scale as the MA-T12 ones.

use std::f64::consts::PI;
use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::geometry::{GEOMETRIES, GEOMETRY_COUNT, GeometrySet, MA_T12_COUNT};
use crate::scan::{Scan, ScanError};
use crate::spectral::{BANDS, Spectrum, wavelengths_nm};

/// Measured BRDF, sr⁻¹, in [`crate::geometry::GEOMETRIES`] order, at the geometries the scan
/// measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuredBrdf {
    /// sr⁻¹; 0 at a geometry outside [`MeasuredBrdf::geometries`] (never read there).
    pub values: [Spectrum; GEOMETRY_COUNT],
    /// Which geometries were measured: all 14, or the 12 MA-T12 ones.
    pub geometries: GeometrySet,
}

impl MeasuredBrdf {
    /// A measurement at all 14 geometries.
    pub fn full(values: [Spectrum; GEOMETRY_COUNT]) -> MeasuredBrdf {
        MeasuredBrdf {
            values,
            geometries: GeometrySet::ALL,
        }
    }
}

/// The spectral range Eq. 9 divides by, λmax − λmin, nm.
pub const PAPER_EQ9_RANGE_NM: f64 = 300.0;

/// How an SRA reading becomes a flat reflectance factor (SCIENCE.md §3); recorded with every fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SpecularStrategy {
    /// `R = q · ρ̄_ref`: relative to the reference tile, exactly like the MA-T12 path.
    #[default]
    Ratio,
    /// `R = q · π / 300`: the paper's Eq. 9 taken literally on the normalised value. Puts the
    /// specular readings about 100× below the diffuse ones; kept to reproduce the paper.
    PaperEq9,
}

impl SpecularStrategy {
    /// Every strategy, for help texts and loops.
    pub const ALL: [SpecularStrategy; 2] = [SpecularStrategy::Ratio, SpecularStrategy::PaperEq9];

    /// The name used on the command line, in config files and in reports.
    pub const fn name(self) -> &'static str {
        match self {
            SpecularStrategy::Ratio => "ratio",
            SpecularStrategy::PaperEq9 => "paper-eq9",
        }
    }
}

impl fmt::Display for SpecularStrategy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// An unknown specular strategy name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown specular strategy \"{0}\"; valid: ratio, paper-eq9")]
pub struct UnknownSpecularStrategy(pub String);

impl FromStr for SpecularStrategy {
    type Err = UnknownSpecularStrategy;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        SpecularStrategy::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| UnknownSpecularStrategy(s.to_string()))
    }
}

/// Processing settings, recorded with every fit.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct ProcessingOptions {
    /// How SRA readings are turned into spectra.
    #[serde(default)]
    pub specular: SpecularStrategy,
    /// The reference tile's calibrated reflectance factor per band (0–1 scale); `None` means 1
    /// everywhere, i.e. results relative to the tile (the paper's choice and the default).
    #[serde(default)]
    pub reference_reflectance: Option<Spectrum>,
}

/// The scale of every reflectance and BRDF brdfd derives from a scan (SCIENCE.md §3): relative
/// to the reference tile (ρ_ref = 1, the paper's choice and the default) or absolute (the tile's
/// calibrated reflectance applied). Previews and renderer exports say which.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "scale", rename_all = "kebab-case")]
pub enum Scale {
    /// ρ_ref = 1: a reflectance of 1 means "as bright as the tile", not the perfect diffuser.
    RelativeToTile,
    /// The tile's certificate applied; `tile_mean` is its band mean ρ̄_ref.
    Absolute { tile_mean: f64 },
    /// No tile: the instrument's own reflectance factor, relative to its calibrated white
    /// standard (an instrument-software export).
    InstrumentCalibration,
}

impl Scale {
    /// The scale that a calibration table (or none) gives.
    pub fn of(reference_reflectance: Option<&Spectrum>) -> Scale {
        match reference_reflectance {
            None => Scale::RelativeToTile,
            Some(rho) => Scale::Absolute {
                tile_mean: rho.iter().sum::<f64>() / BANDS as f64,
            },
        }
    }

    /// One line for a picture or a file header.
    pub fn describe(&self) -> String {
        match self {
            Scale::RelativeToTile => "relative scale: reflectance relative to the reference tile \
                 (no tile calibration; a real Munsell N9 reflects about 0.77, so this is about \
                 30 % too bright)"
                .into(),
            Scale::Absolute { tile_mean } => format!(
                "absolute scale: reference tile calibrated (mean reflectance factor {tile_mean:.4})"
            ),
            Scale::InstrumentCalibration => "absolute scale: reference: instrument calibration \
                 (reflectance factor relative to the instrument's calibrated white standard)"
                .into(),
        }
    }

    /// `"absolute"` or `"relative-to-tile"`, for machine-readable fields.
    pub fn name(&self) -> &'static str {
        match self {
            Scale::RelativeToTile => "relative-to-tile",
            Scale::Absolute { .. } => "absolute",
            Scale::InstrumentCalibration => "instrument-calibration",
        }
    }

    /// The scale of one scan processed with `opts`: a scan without a tile reference is on the
    /// instrument's own scale whatever the tile calibration says.
    pub fn of_scan(scan: &Scan, opts: &ProcessingOptions) -> Scale {
        match scan.reference {
            Some(_) => opts.scale(),
            None => Scale::InstrumentCalibration,
        }
    }
}

/// Why a scan could not be turned into a measured BRDF.
#[derive(Debug, thiserror::Error)]
pub enum ProcessingError {
    /// The scan itself is invalid (e.g. a zero reference reading): fix or re-take the scan.
    #[error("scan \"{sample}\": {source}")]
    InvalidScan {
        sample: String,
        #[source]
        source: ScanError,
    },
    /// The calibration table is unusable: fix the `reference_reflectance` setting.
    #[error(
        "reference_reflectance[{band}] ({nm} nm): {value} must be a positive finite reflectance factor; fix the reference calibration table"
    )]
    BadCalibration { band: usize, nm: u32, value: f64 },
}

impl ProcessingOptions {
    /// The scale of what these options produce.
    pub fn scale(&self) -> Scale {
        Scale::of(self.reference_reflectance.as_ref())
    }

    fn rho_ref(&self) -> Result<Spectrum, ProcessingError> {
        let rho = self.reference_reflectance.unwrap_or([1.0; BANDS]);
        for (band, &value) in rho.iter().enumerate() {
            if !(value.is_finite() && value > 0.0) {
                return Err(ProcessingError::BadCalibration {
                    band,
                    nm: wavelengths_nm()[band],
                    value,
                });
            }
        }
        Ok(rho)
    }
}

/// Turns one scan into its measured BRDF (sr⁻¹) at the 14 geometries, SCIENCE.md §3.
pub fn process(scan: &Scan, opts: &ProcessingOptions) -> Result<MeasuredBrdf, ProcessingError> {
    // The fields of a Scan are public, so a caller may have built one that never went through
    // the file parser: the reference must be checked here too (SCIENCE.md §3).
    scan.validate()
        .map_err(|source| ProcessingError::InvalidScan {
            sample: scan.sample.clone(),
            source,
        })?;
    let rho = opts.rho_ref()?;
    let rho_mean = rho.iter().sum::<f64>() / BANDS as f64;
    let geometries = scan.geometries();

    let mut values = [[0.0; BANDS]; GEOMETRY_COUNT];
    for (geo, out) in GEOMETRIES.iter().zip(values.iter_mut()) {
        if !geometries.contains(geo.index) {
            continue;
        }
        if geo.index < MA_T12_COUNT {
            let s = &scan.readings.ma_t12[geo.index];
            match &scan.reference {
                Some(reference) => {
                    let w = &reference.readings.ma_t12[geo.index];
                    for b in 0..BANDS {
                        out[b] = s[b] / w[b] * rho[b] / PI;
                    }
                }
                // The instrument's own reflectance factor (SCIENCE.md §3): R = S.
                None => {
                    for b in 0..BANDS {
                        out[b] = s[b] / PI;
                    }
                }
            }
        } else {
            // `validate` guarantees the tile's SRA readings wherever the scan has its own.
            let (Some(sra), Some(sra_ref)) = (
                scan.readings.sra,
                scan.reference.as_ref().and_then(|r| r.readings.sra),
            ) else {
                unreachable!("a scan with SRA geometries has the tile's SRA readings (validate)")
            };
            let k = geo.index - MA_T12_COUNT;
            let q = sra[k] / sra_ref[k];
            let r = match opts.specular {
                SpecularStrategy::Ratio => q * rho_mean,
                SpecularStrategy::PaperEq9 => q * PI / PAPER_EQ9_RANGE_NM,
            };
            *out = [r / PI; BANDS];
        }
    }
    Ok(MeasuredBrdf { values, geometries })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scan::{DeviceReadings, Reference};

    /// Reference: 0.8 everywhere on the MA-T12, SRA 0.25 and 0.5. Sample: 0.4 (half the
    /// reference) except 15as-45 band 0 at 0.2, SRA 2.0 and 1.0.
    fn scan() -> Scan {
        let mut sample = [[0.4; BANDS]; MA_T12_COUNT];
        sample[0][0] = 0.2;
        Scan {
            sample: "hand".into(),
            reference: Some(Reference {
                name: "Munsell N9".into(),
                readings: DeviceReadings {
                    ma_t12: [[0.8; BANDS]; MA_T12_COUNT],
                    sra: Some([0.25, 0.5]),
                },
            }),
            readings: DeviceReadings {
                ma_t12: sample,
                sra: Some([2.0, 1.0]),
            },
            origin: None,
        }
    }

    fn close(got: f64, want: f64) {
        assert!(
            (got - want).abs() <= 1e-15 * want.abs().max(1.0),
            "got {got}, want {want}"
        );
    }

    #[test]
    fn instrument_calibration_takes_the_reflectance_factor_as_it_is() {
        let mut s = scan();
        s.reference = None;
        s.readings.sra = None;
        // A tile calibration does not apply to a scan without a tile.
        let opts = ProcessingOptions {
            reference_reflectance: Some([0.77; BANDS]),
            ..Default::default()
        };
        let m = process(&s, &opts).unwrap();
        assert_eq!(m.geometries, GeometrySet::MA_T12);
        close(m.values[0][0], 0.2 / PI);
        close(m.values[11][30], 0.4 / PI);
        assert_eq!(m.values[12], [0.0; BANDS]);
        assert_eq!(Scale::of_scan(&s, &opts), Scale::InstrumentCalibration);
        assert_eq!(Scale::of_scan(&scan(), &opts).name(), "absolute");
        // SRA readings without a tile cannot be normalised.
        let mut s = scan();
        s.reference = None;
        assert!(
            process(&s, &opts)
                .unwrap_err()
                .to_string()
                .contains("SRA readings need")
        );
    }

    #[test]
    fn ratio_strategy_by_hand() {
        let m = process(&scan(), &ProcessingOptions::default()).unwrap();
        // MA-T12: 0.4 / 0.8 = 0.5 → 0.5/π = 0.15915494309189535 sr⁻¹; 0.2/0.8/π = 0.0795774715.
        close(m.values[0][0], 0.5 / 2.0 / PI);
        close(m.values[0][1], 0.15915494309189535);
        close(m.values[11][30], 0.15915494309189535);
        // SRA: q = 2.0/0.25 = 8 → 8/π = 2.5464790894703255 sr⁻¹; q = 1.0/0.5 = 2 → 2/π.
        assert!(m.values[12].iter().all(|&v| v == m.values[12][0]));
        close(m.values[12][0], 2.5464790894703255);
        close(m.values[13][30], 2.0 / PI); // 0.63661977236758…
    }

    #[test]
    fn paper_eq9_strategy_by_hand() {
        let opts = ProcessingOptions {
            specular: SpecularStrategy::PaperEq9,
            ..Default::default()
        };
        let m = process(&scan(), &opts).unwrap();
        // MA-T12 unchanged by the strategy.
        close(m.values[5][7], 0.15915494309189535);
        // SRA: R = q·π/300, M = R/π = q/300: 8/300 = 0.02666…, 2/300 = 0.00666…
        close(m.values[12][0], 8.0 / 300.0);
        close(m.values[13][15], 2.0 / 300.0);
    }

    #[test]
    fn calibrated_reference_scales_diffuse_per_band_and_specular_by_the_mean() {
        let mut rho = [0.75; BANDS];
        rho[0] = 0.5;
        rho[30] = 1.0;
        // band mean = (29·0.75 + 0.5 + 1.0)/31 = 0.75 exactly.
        let opts = ProcessingOptions {
            reference_reflectance: Some(rho),
            ..Default::default()
        };
        let m = process(&scan(), &opts).unwrap();
        close(m.values[3][0], 0.5 * 0.5 / PI);
        close(m.values[3][30], 0.5 * 1.0 / PI);
        close(m.values[3][10], 0.5 * 0.75 / PI);
        close(m.values[12][0], 8.0 * 0.75 / PI);
        close(m.values[12][30], 8.0 * 0.75 / PI);
    }

    #[test]
    fn rejects_a_bad_reference_or_calibration() {
        let mut s = scan();
        s.reference.as_mut().unwrap().readings.ma_t12[4][2] = 0.0;
        let e = process(&s, &ProcessingOptions::default())
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "scan \"hand\": reference.ma_t12.15as45[2] (420 nm): reference reading 0 must be positive; re-measure the reference tile"
        );
        let mut s = scan();
        s.reference.as_mut().unwrap().readings.sra.as_mut().unwrap()[0] = f64::NAN;
        assert!(matches!(
            process(&s, &ProcessingOptions::default()),
            Err(ProcessingError::InvalidScan { .. })
        ));
        let mut rho = [0.77; BANDS];
        rho[3] = -0.1;
        let opts = ProcessingOptions {
            reference_reflectance: Some(rho),
            ..Default::default()
        };
        let e = process(&scan(), &opts).unwrap_err().to_string();
        assert!(
            e.starts_with("reference_reflectance[3] (430 nm): -0.1 must be"),
            "{e}"
        );
    }

    #[test]
    fn scale_says_absolute_only_with_a_calibration() {
        assert_eq!(ProcessingOptions::default().scale(), Scale::RelativeToTile);
        let opts = ProcessingOptions {
            reference_reflectance: Some([0.77; BANDS]),
            ..Default::default()
        };
        let Scale::Absolute { tile_mean } = opts.scale() else {
            panic!("a calibration gives the absolute scale")
        };
        close(tile_mean, 0.77);
        assert!(opts.scale().describe().starts_with("absolute scale"));
        assert!(
            Scale::RelativeToTile
                .describe()
                .starts_with("relative scale")
        );
    }

    #[test]
    fn strategy_names_parse_and_print() {
        for k in SpecularStrategy::ALL {
            assert_eq!(k.to_string().parse::<SpecularStrategy>().unwrap(), k);
            assert_eq!(serde_json::to_string(&k).unwrap(), format!("\"{k}\""));
        }
        assert_eq!(SpecularStrategy::default(), SpecularStrategy::Ratio);
        let e = "eq9".parse::<SpecularStrategy>().unwrap_err().to_string();
        assert_eq!(
            e,
            "unknown specular strategy \"eq9\"; valid: ratio, paper-eq9"
        );
    }
}
