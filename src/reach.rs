//! The reach verdict (SCIENCE.md §12.7): whether a scan's material is one the model can
//! represent, told from the scan's readings and its fit alone, with the prediction error over
//! the hemisphere to expect and how that expectation was calibrated.
//!
//! The evidence is what every fit has (and what the store keeps: measured L* per geometry,
//! the fit's ΔE00, a cross-validation once computed), so the verdict is derived whenever a fit
//! is read, never stored:
//! - the **specular excess**: the brightest reading's luminance above the diffuse one (45as45,
//!   0°/45°), as a reflectance factor (the white diffuser is 1). Matt and medium-gloss paints
//!   stay within a few units; glossy coatings put their mirror peak hundreds above, a peak
//!   the paper's one GGX lobe cannot follow from 14 readings;
//! - the fit's own ΔE00 at the MA-T12 geometries: a material the model cannot even fit;
//! - the held-out ΔE00 (`brdfd crossval`, `fit --hold-out`), when there is one: each reading
//!   predicted by a fit without it, the nearest a scan has to a prediction off its angles.
//!
//! [`CALIBRATION`] holds every threshold and expected error, with the command that measured
//! them; nothing else in brdfd decides a verdict.

use serde::{Deserialize, Serialize};

use crate::fit::{FitReport, LabPerGeometry};
use crate::geometry::GEOMETRIES;
use crate::model::FresnelCosine;

/// Whether the model can represent the material.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Verdict {
    /// Matt or medium gloss: the 14 readings predict the hemisphere about as well as the model
    /// can.
    InReach,
    /// Between the calibrated groups: the estimate may hold or not.
    Marginal,
    /// Glossy, or not fitted even at its readings: the model cannot represent the material,
    /// however it is measured or fitted.
    OutOfReach,
}

impl Verdict {
    /// `in reach`, `marginal`, `out of reach`.
    pub const fn text(self) -> &'static str {
        match self {
            Verdict::InReach => "in reach",
            Verdict::Marginal => "marginal",
            Verdict::OutOfReach => "out of reach",
        }
    }
}

impl std::fmt::Display for Verdict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.text())
    }
}

/// The thresholds and expected errors of the verdict, and where they come from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    /// Specular excess (reflectance factor) at or below which a material is in reach.
    pub excess_in_reach: f64,
    /// Specular excess above which a material is out of reach.
    pub excess_out_of_reach: f64,
    /// MA-T12 fit ΔE00 above which the verdict is at best marginal.
    pub fit_marginal: f64,
    /// MA-T12 fit ΔE00 above which the material is out of reach.
    pub fit_out_of_reach: f64,
    /// Held-out ΔE00 above which the verdict is at best marginal.
    pub held_out_marginal: f64,
    /// Held-out ΔE00 above which the material is out of reach.
    pub held_out_out_of_reach: f64,
    /// Prediction ΔE00 over the hemisphere (mean) of the materials in reach, exact Fresnel:
    /// lowest and highest.
    pub in_reach_exact: [f64; 2],
    /// The same with Schlick's Fresnel (the paper's, on cos θi).
    pub in_reach_incidence: [f64; 2],
    /// Their near-specular prediction ΔE00 (half vector within 10° of the normal), exact
    /// Fresnel.
    pub in_reach_near_specular: [f64; 2],
    /// Prediction ΔE00 over the hemisphere (mean) of the glossy materials, exact Fresnel.
    pub out_of_reach: [f64; 2],
    /// Their near-specular prediction ΔE00: where a glossy material's error is.
    pub out_of_reach_near_specular: [f64; 2],
    /// How the figures were measured, as reports print it.
    pub source: &'static str,
}

/// The one calibration of the verdict (SCIENCE.md §12.7), measured with
/// `cargo run --release --example reach_calibration -- krylon_blue.astm garnet_red.astm
/// paper_white_rgb.bsdf colodur_napoli_4f_rgb.bsdf`: the four measured goniometric files
/// (specular excess 0.24–5.39, MA-T12 fit ΔE00 0.57–3.47, held-out 0.90–3.97, all cf2 with
/// exact Fresnel) and six generated glossy materials the example writes itself (clear coats of
/// two grey lobes, and metallic lacquers with a coloured flake lobe: excess 11–4,543, fit
/// 0.16–9.27, held-out 0.19–9.98). The satin (excess 11) sits between the groups.
pub const CALIBRATION: Calibration = Calibration {
    excess_in_reach: 6.0,
    excess_out_of_reach: 50.0,
    fit_marginal: 4.0,
    fit_out_of_reach: 8.0,
    held_out_marginal: 5.0,
    held_out_out_of_reach: 9.0,
    in_reach_exact: [1.2, 5.4],
    in_reach_incidence: [1.2, 7.2],
    in_reach_near_specular: [0.9, 6.5],
    out_of_reach: [0.7, 5.8],
    out_of_reach_near_specular: [2.7, 23.3],
    source: "four measured materials (two matt, two medium-gloss paints) and six generated \
             glossy ones, with brdfd validate (SCIENCE.md §12.7)",
};

/// What a verdict is made from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Evidence {
    /// The brightest reading's luminance minus the 45as45 (0°/45°) one, reflectance factor.
    pub specular_excess: f64,
    /// The geometry of the brightest reading.
    pub peak_geometry: String,
    /// Mean ΔE00 of the fit at the MA-T12 geometries it was fitted to.
    pub fit_delta_e00: f64,
    /// Mean held-out ΔE00, when the fit has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out_delta_e00: Option<f64>,
    /// The fit's Fresnel factor (the expected error depends on it).
    pub fresnel: FresnelCosine,
}

/// A scan's reach verdict (`reach` in `brdfd fit --json`, `validate --json`, `show`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Reach {
    pub verdict: Verdict,
    /// The prediction ΔE00 to expect over the hemisphere (mean over directions), `[low, high]`:
    /// the range the calibration materials of this verdict showed.
    pub expected_delta_e00: [f64; 2],
    /// The same near the mirror direction (half vector within 10° of the normal), where a
    /// glossy material's error lies.
    pub expected_near_specular_delta_e00: [f64; 2],
    /// Why, in words: every piece of evidence that set the verdict.
    pub reasons: Vec<String>,
    pub evidence: Evidence,
    /// How the thresholds and expected errors were calibrated.
    pub calibration: String,
}

/// `Y/Yn` of an L* (CIE 15 inverse of `f`).
fn luminance_of(l: f64) -> f64 {
    if l > 8.0 {
        ((l + 16.0) / 116.0).powi(3)
    } else {
        l / (24389.0 / 27.0)
    }
}

impl Evidence {
    /// The evidence of a fit from its measured L* per geometry (any colorimetry: only the
    /// luminance is read), its MA-T12 fit ΔE00 and its held-out ΔE00. `None` without a
    /// 45as45 reading.
    pub fn of(
        lab: &LabPerGeometry,
        fit_delta_e00: f64,
        held_out_delta_e00: Option<f64>,
        fresnel: FresnelCosine,
    ) -> Option<Evidence> {
        let y: Vec<(&str, f64)> = lab
            .0
            .iter()
            .filter_map(|p| {
                let g = GEOMETRIES.iter().find(|g| g.name == p.geometry)?;
                Some((g.name, luminance_of(p.measured[0])))
            })
            .collect();
        let diffuse = y.iter().find(|(n, _)| *n == "45as45")?.1;
        let (peak_geometry, peak) = y.iter().copied().max_by(|a, b| a.1.total_cmp(&b.1))?;
        Some(Evidence {
            specular_excess: (peak - diffuse).max(0.0),
            peak_geometry: peak_geometry.to_string(),
            fit_delta_e00,
            held_out_delta_e00,
            fresnel,
        })
    }
}

/// The verdict on `e` under `c` ([`CALIBRATION`] in brdfd).
pub fn assess_with(e: &Evidence, c: &Calibration) -> Reach {
    let mut verdict = Verdict::InReach;
    let mut reasons = Vec::new();
    let mut raise = |v: Verdict, why: String, reasons: &mut Vec<String>| {
        let rank = |v: Verdict| v as u8;
        if rank(v) > rank(verdict) {
            verdict = v;
        }
        reasons.push(why);
    };
    let x = e.specular_excess;
    if x > c.excess_out_of_reach {
        raise(
            Verdict::OutOfReach,
            format!(
                "glossy: the {} reading is {x:.1} above the diffuse one (reflectance factor; out of \
                 reach above {})",
                e.peak_geometry, c.excess_out_of_reach
            ),
            &mut reasons,
        );
    } else if x > c.excess_in_reach {
        raise(
            Verdict::Marginal,
            format!(
                "glossier than the materials calibrated in reach: the {} reading is {x:.1} above \
                 the diffuse one (in reach up to {}, out of reach above {})",
                e.peak_geometry, c.excess_in_reach, c.excess_out_of_reach
            ),
            &mut reasons,
        );
    }
    let f = e.fit_delta_e00;
    if f > c.fit_out_of_reach {
        raise(
            Verdict::OutOfReach,
            format!(
                "the model does not fit the readings themselves: ΔE00 {f:.2} at the MA-T12 \
                 geometries (out of reach above {})",
                c.fit_out_of_reach
            ),
            &mut reasons,
        );
    } else if f > c.fit_marginal {
        raise(
            Verdict::Marginal,
            format!(
                "a loose fit at the readings: ΔE00 {f:.2} at the MA-T12 geometries (above {})",
                c.fit_marginal
            ),
            &mut reasons,
        );
    }
    if let Some(h) = e.held_out_delta_e00 {
        if h > c.held_out_out_of_reach {
            raise(
                Verdict::OutOfReach,
                format!(
                    "readings held out of the fit are predicted at ΔE00 {h:.2} (out of reach above {})",
                    c.held_out_out_of_reach
                ),
                &mut reasons,
            );
        } else if h > c.held_out_marginal {
            raise(
                Verdict::Marginal,
                format!(
                    "readings held out of the fit are predicted at ΔE00 {h:.2} (above {})",
                    c.held_out_marginal
                ),
                &mut reasons,
            );
        }
    }
    let band = match e.fresnel {
        FresnelCosine::Exact => c.in_reach_exact,
        _ => c.in_reach_incidence,
    };
    let span = |a: [f64; 2], b: [f64; 2]| [a[0].min(b[0]), a[1].max(b[1])];
    let (expected, near) = match verdict {
        Verdict::InReach => {
            reasons.push(format!(
                "matt or medium gloss: specular excess {x:.1}, fit ΔE00 {f:.2}{}",
                e.held_out_delta_e00
                    .map(|h| format!(", held-out ΔE00 {h:.2}"))
                    .unwrap_or_default()
            ));
            (band, c.in_reach_near_specular)
        }
        Verdict::Marginal => (
            span(band, c.out_of_reach),
            span(c.in_reach_near_specular, c.out_of_reach_near_specular),
        ),
        Verdict::OutOfReach => (c.out_of_reach, c.out_of_reach_near_specular),
    };
    if verdict == Verdict::InReach && e.fresnel != FresnelCosine::Exact {
        reasons.push(format!(
            "fitted with Schlick's Fresnel on {}: exact Fresnel predicts medium-gloss materials \
             better ({:.1}–{:.1} against {:.1}–{:.1})",
            match e.fresnel {
                FresnelCosine::LightHalf => "l·h",
                _ => "cos θi",
            },
            c.in_reach_exact[0],
            c.in_reach_exact[1],
            band[0],
            band[1]
        ));
    }
    if verdict == Verdict::OutOfReach {
        reasons.push(
            "the model's one grey lobe does not follow such a specular peak: the error lies \
             near the mirror direction, the hemisphere's mean hides it"
                .to_string(),
        );
    }
    Reach {
        verdict,
        expected_delta_e00: expected,
        expected_near_specular_delta_e00: near,
        reasons,
        evidence: e.clone(),
        calibration: c.source.to_string(),
    }
}

/// The verdict on `e` under [`CALIBRATION`].
pub fn assess(e: &Evidence) -> Reach {
    assess_with(e, &CALIBRATION)
}

/// The verdict on a fit: its readings' L*, its MA-T12 fit ΔE00 and its held-out ΔE00 (a fit
/// made with `--hold-out`). `None` without a 45as45 reading.
pub fn of_report(report: &FitReport) -> Option<Reach> {
    let held = report
        .held_out
        .as_ref()
        .filter(|h| !h.is_empty())
        .map(|h| h.iter().map(|x| x.delta_e00).sum::<f64>() / h.len() as f64);
    let e = Evidence::of(
        &report.lab(),
        report.evaluation.diffuse.mean,
        held,
        report.request.settings.fresnel,
    )?;
    Some(assess(&e))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn evidence(excess: f64, fit: f64, held: Option<f64>) -> Evidence {
        Evidence {
            specular_excess: excess,
            peak_geometry: "sra-20".into(),
            fit_delta_e00: fit,
            held_out_delta_e00: held,
            fresnel: FresnelCosine::Exact,
        }
    }

    #[test]
    fn the_thresholds_order_the_verdicts() {
        let c = CALIBRATION;
        assert!(c.excess_in_reach < c.excess_out_of_reach);
        assert!(c.fit_marginal < c.fit_out_of_reach);
        assert!(c.held_out_marginal < c.held_out_out_of_reach);
        let matt = assess(&evidence(0.5 * c.excess_in_reach, 0.5, None));
        assert_eq!(matt.verdict, Verdict::InReach);
        assert_eq!(matt.expected_delta_e00, c.in_reach_exact);
        let between = 0.5 * (c.excess_in_reach + c.excess_out_of_reach);
        assert_eq!(
            assess(&evidence(between, 0.5, None)).verdict,
            Verdict::Marginal
        );
        let glossy = assess(&evidence(2.0 * c.excess_out_of_reach, 0.5, None));
        assert_eq!(glossy.verdict, Verdict::OutOfReach);
        assert_eq!(
            glossy.expected_near_specular_delta_e00,
            c.out_of_reach_near_specular
        );
        assert!(glossy.reasons[0].contains("sra-20"), "{:?}", glossy.reasons);
    }

    #[test]
    fn a_bad_fit_or_held_out_error_overrides_a_matt_reading() {
        let c = CALIBRATION;
        let x = 0.5 * c.excess_in_reach;
        assert_eq!(
            assess(&evidence(x, c.fit_out_of_reach + 1.0, None)).verdict,
            Verdict::OutOfReach
        );
        assert_eq!(
            assess(&evidence(x, 0.5, Some(c.held_out_marginal + 0.1))).verdict,
            Verdict::Marginal
        );
        assert_eq!(
            assess(&evidence(x, 0.5, Some(c.held_out_out_of_reach + 0.1))).verdict,
            Verdict::OutOfReach
        );
        // The fit's Fresnel factor chooses the expected error in reach.
        let schlick = assess(&Evidence {
            fresnel: FresnelCosine::Incidence,
            ..evidence(x, 0.5, None)
        });
        assert_eq!(schlick.expected_delta_e00, c.in_reach_incidence);
    }

    #[test]
    fn luminance_inverts_lightness() {
        for y in [0.001, 0.05, 0.5, 1.0, 30.0] {
            let l = crate::colour::xyz_to_lab(
                crate::colour::Xyz {
                    x: y * 95.0,
                    y: y * 100.0,
                    z: y * 108.0,
                },
                crate::colour::Xyz {
                    x: 95.0,
                    y: 100.0,
                    z: 108.0,
                },
            )
            .l;
            assert!((luminance_of(l) - y).abs() < 1e-9 * y.max(1.0), "{y}");
        }
    }
}
