//! The three cost functions a fit minimises (paper Eq. 6–8, SCIENCE.md §5).
//!
//! Every cost sums over the geometries the scan measured × 31 bands — all 14, N = 434 terms, or
//! the 12 MA-T12 ones of a scan without SRA readings, N = 372 ([`terms`]) — with the cosine weight
//! `w_g = cos θi` of the geometry; `M` is the measured and `A` the model BRDF, both in sr⁻¹.
//!
//! - [`CostFunction::Cf1`], cosine-weighted RMSE: `sqrt(Σ (M·w − A·w)² / N)`.
//! - [`CostFunction::Cf2`], cube-root cosine-weighted RMSE: `sqrt(Σ ((M·w − A·w)²)^(1/3) / N)`,
//!   from Forés, Ferwerda & Gu, "Toward a perceptually based metric for BRDF modeling",
//!   Color and Imaging Conference 2012.
//! - [`CostFunction::M2`], the logarithmic metric `sqrt(Σ (ln(1 + M·w) − ln(1 + A·w))² / N)` of
//!   Löw, Kronander, Ynnerman & Unger, "BRDF models for accurate and efficient rendering of
//!   glossy surfaces", ACM Transactions on Graphics 31(1), 2012.
//!
//! With the `luminance` SRA reading model ([`cost_with`], SCIENCE.md §5.1) the two SRA
//! geometries contribute one luminance residual each, `w·(Y(M) − Y(A))`, counted `BANDS` = 31
//! times (the 31 flat-model terms it replaces), so N stays 434 and the SRA geometries keep
//! their paper share of 2 in 14.
//!
//! [`cost`] is the reference implementation, written to read like the equations; the optimiser
//! (`crate::optimise`) uses allocation-free equivalents and reports every final cost through
//! this function.

// Numeric loops index parallel per-geometry and per-band arrays; `for g in 0..G` reads
// closest to the equations.
#![allow(clippy::needless_range_loop)]

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::geometry::{GEOMETRIES, GEOMETRY_COUNT, GeometrySet, MA_T12_COUNT};
use crate::processing::MeasuredBrdf;
use crate::spectral::{BANDS, Spectrum};
use crate::sra_reading::{SraModel, SraReading, SraWeight, luminance_with};

/// Number of (geometry, band) terms in the cost of a full scan: 14 · 31.
pub const TERMS: usize = GEOMETRY_COUNT * BANDS;

/// Number of (geometry, band) terms in the cost of a scan that measured `geometries`.
pub const fn terms(geometries: GeometrySet) -> usize {
    geometries.len() * BANDS
}

/// Which of the paper's cost functions a fit minimises.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CostFunction {
    /// Cosine-weighted RMSE (paper Eq. 6).
    Cf1,
    /// Cube-root cosine-weighted RMSE (paper Eq. 7, Forés et al. 2012). The default: the paper
    /// found it the most consistent of the three.
    #[default]
    Cf2,
    /// Logarithmic error of Löw et al. 2012 (paper Eq. 8).
    M2,
}

impl CostFunction {
    /// All three, in the paper's order.
    pub const ALL: [CostFunction; 3] = [CostFunction::Cf1, CostFunction::Cf2, CostFunction::M2];

    /// The name used on the command line, in settings and in reports.
    pub const fn name(self) -> &'static str {
        match self {
            CostFunction::Cf1 => "cf1",
            CostFunction::Cf2 => "cf2",
            CostFunction::M2 => "m2",
        }
    }
}

impl fmt::Display for CostFunction {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A cost-function name that is not one of `cf1`, `cf2`, `m2`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown cost function \"{name}\": expected one of cf1, cf2, m2")]
pub struct ParseCostFunctionError {
    /// The name as given.
    pub name: String,
}

impl FromStr for CostFunction {
    type Err = ParseCostFunctionError;

    /// Parses `cf1`, `cf2` or `m2` (ASCII case-insensitive, as a user may type `CF2`).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        CostFunction::ALL
            .into_iter()
            .find(|cf| cf.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| ParseCostFunctionError {
                name: s.to_string(),
            })
    }
}

/// The cosine weights `w_g = cos θi`, in [`GEOMETRIES`] order.
pub fn weights() -> [f64; GEOMETRY_COUNT] {
    std::array::from_fn(|g| GEOMETRIES[g].cos_theta_i())
}

/// The weights of `measured`'s geometries in a cost under `weight` (SCIENCE.md §5.2): the
/// cosine weights, with the SRA geometries' scaled by [`SraWeight::scale`] of the scan's mean
/// weighted readings (band mean) at its measured MA-T12 and SRA geometries. The paper's
/// weighting is [`weights`] itself.
pub fn weights_for(weight: SraWeight, measured: &MeasuredBrdf) -> [f64; GEOMETRY_COUNT] {
    let w = weights();
    if weight.is_paper() || !measured.geometries.has_sra() {
        return w;
    }
    let level = |range: std::ops::Range<usize>| {
        let (mut sum, mut n) = (0.0, 0.0);
        for g in range.filter(|&g| measured.geometries.contains(g)) {
            sum += w[g] * measured.values[g].iter().sum::<f64>() / BANDS as f64;
            n += 1.0;
        }
        if n > 0.0 { sum / n } else { 0.0 }
    };
    let scale = weight.scale(level(0..MA_T12_COUNT), level(MA_T12_COUNT..GEOMETRY_COUNT));
    std::array::from_fn(|g| if g < MA_T12_COUNT { w[g] } else { w[g] * scale })
}

/// The cost of a model BRDF `model` (sr⁻¹, [`GEOMETRIES`] order) against `measured`, every
/// geometry weighted by cos θi (the paper's weighting).
///
/// Non-finite inputs give a non-finite cost; the optimiser rejects such scans before fitting.
pub fn cost(cf: CostFunction, measured: &MeasuredBrdf, model: &[Spectrum; GEOMETRY_COUNT]) -> f64 {
    cost_weighted(cf, measured, model, &weights())
}

/// [`cost`] with the geometries weighted by `w`.
fn cost_weighted(
    cf: CostFunction,
    measured: &MeasuredBrdf,
    model: &[Spectrum; GEOMETRY_COUNT],
    w: &[f64; GEOMETRY_COUNT],
) -> f64 {
    let mut sum = 0.0;
    for g in 0..GEOMETRY_COUNT {
        if !measured.geometries.contains(g) {
            continue;
        }
        for b in 0..BANDS {
            let (m, a) = (measured.values[g][b] * w[g], model[g][b] * w[g]);
            sum += match cf {
                CostFunction::Cf1 => (m - a) * (m - a),
                CostFunction::Cf2 => ((m - a) * (m - a)).cbrt(),
                CostFunction::M2 => {
                    let d = m.ln_1p() - a.ln_1p();
                    d * d
                }
            };
        }
    }
    (sum / terms(measured.geometries) as f64).sqrt()
}

/// One term of cost function `cf` for weighted measured and model values `m = w·M`, `a = w·A`.
fn term(cf: CostFunction, m: f64, a: f64) -> f64 {
    match cf {
        CostFunction::Cf1 => (m - a) * (m - a),
        CostFunction::Cf2 => ((m - a) * (m - a)).cbrt(),
        CostFunction::M2 => {
            let d = m.ln_1p() - a.ln_1p();
            d * d
        }
    }
}

/// The cost of `model` against `measured` under the SRA reading model `sra`, its geometries
/// weighted as `sra.weight` says ([`weights_for`]): for the paper's flat model the terms of
/// [`cost`]; for `luminance`, the 12 × 31 MA-T12 terms as in [`cost`] and at each SRA geometry
/// the term of the luminance residual, `BANDS · φ(w·Y(M), w·Y(A))` with `Y` under the
/// instrument's illuminant and observer. N = 434 either way.
pub fn cost_with(
    cf: CostFunction,
    sra: SraReading,
    measured: &MeasuredBrdf,
    model: &[Spectrum; GEOMETRY_COUNT],
) -> f64 {
    let w = weights_for(sra.weight, measured);
    if sra.model == SraModel::Flat {
        return cost_weighted(cf, measured, model, &w);
    }
    let c = sra.weights();
    let mut sum = 0.0;
    for g in 0..MA_T12_COUNT {
        if !measured.geometries.contains(g) {
            continue;
        }
        for b in 0..BANDS {
            sum += term(cf, measured.values[g][b] * w[g], model[g][b] * w[g]);
        }
    }
    for g in MA_T12_COUNT..GEOMETRY_COUNT {
        if !measured.geometries.contains(g) {
            continue;
        }
        let (m, a) = (
            luminance_with(&c, &measured.values[g]) * w[g],
            luminance_with(&c, &model[g]) * w[g],
        );
        sum += BANDS as f64 * term(cf, m, a);
    }
    (sum / terms(measured.geometries) as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::by_name;

    const N: f64 = TERMS as f64;

    fn close(got: f64, want: f64, rel: f64) {
        assert!(((got - want) / want).abs() <= rel, "got {got}, want {want}");
    }

    fn zeros() -> [Spectrum; GEOMETRY_COUNT] {
        [[0.0; BANDS]; GEOMETRY_COUNT]
    }

    /// Measured: 0.4 sr⁻¹ at 15as-45 (θi = 60°, w = 0.5) in band 0 and 0.1 sr⁻¹ at 15as15
    /// (θi = 0°, w = 1) in band 5, zero elsewhere; model zero everywhere. So the weighted
    /// differences are 0.2 and 0.1 and the other 432 terms vanish.
    fn two_term_case() -> (MeasuredBrdf, [Spectrum; GEOMETRY_COUNT]) {
        let mut m = zeros();
        m[by_name("15as-45").unwrap().index][0] = 0.4;
        m[by_name("15as15").unwrap().index][5] = 0.1;
        (MeasuredBrdf::full(m), zeros())
    }

    #[test]
    fn weights_are_cos_theta_i() {
        let w = weights();
        assert_eq!(w[by_name("15as15").unwrap().index], 1.0);
        close(w[by_name("15as-45").unwrap().index], 0.5, 1e-15);
        close(
            w[by_name("15as80").unwrap().index],
            65f64.to_radians().cos(),
            1e-15,
        );
        close(w[by_name("sra-60").unwrap().index], 0.5, 1e-15);
    }

    #[test]
    fn cf1_by_hand() {
        let (m, a) = two_term_case();
        // Σ = 0.2² + 0.1² = 0.04 + 0.01 = 0.05; 0.05 / 434 = 1.152073732718894e-4;
        // sqrt → 0.010733469768527296.
        close(cost(CostFunction::Cf1, &m, &a), 0.010733469768527296, 1e-14);
        close(cost(CostFunction::Cf1, &m, &a), (0.05 / N).sqrt(), 1e-15);
    }

    #[test]
    fn cf2_by_hand() {
        let (m, a) = two_term_case();
        // (0.2²)^(1/3) = 0.04^(1/3) = 0.3419951893353394; (0.1²)^(1/3) = 0.01^(1/3) =
        // 0.2154434690031884; Σ = 0.5574386583385278; / 434 = 1.2844208717477e-3;
        // sqrt → 0.03583881794573811.
        close(cost(CostFunction::Cf2, &m, &a), 0.03583881794573811, 1e-14);
    }

    #[test]
    fn m2_by_hand() {
        let (m, a) = two_term_case();
        // ln(1 + 0.2) − ln 1 = 0.1823215567939546; ln(1.1) = 0.09531017980432493;
        // Σ squares = 0.033241150 + 0.009084030 = 0.042325180; / 434 = 9.7523457e-5;
        // sqrt → 0.009875396561611462.
        close(cost(CostFunction::M2, &m, &a), 0.009875396561611462, 1e-14);
    }

    #[test]
    fn model_term_enters_with_the_same_weight() {
        // One term at sra-20 (θi = 20°, w = cos 20° = 0.9396926207859084), band 30:
        // M = 0.3, A = 0.1 → w·(M − A) = 0.1879385241571817, squared 0.03532088886237957.
        let g = by_name("sra-20").unwrap().index;
        let mut mv = zeros();
        let mut a = zeros();
        mv[g][30] = 0.3;
        a[g][30] = 0.1;
        let m = MeasuredBrdf::full(mv);
        // cf1: sqrt(0.03532088886237957 / 434) = 0.009021337846974899.
        close(cost(CostFunction::Cf1, &m, &a), 0.009021337846974899, 1e-14);
        // cf2: 0.03532088886237957^(1/3) = 0.32810325689657616; / 434, sqrt → 0.027495423033300093.
        close(cost(CostFunction::Cf2, &m, &a), 0.027495423033300093, 1e-14);
        // m2: ln(1 + 0.28190779) − ln(1 + 0.09396926) = 0.24834943 − 0.08981261 =
        // 0.15853681951337206; squared / 434, sqrt → 0.007610010860885858.
        close(cost(CostFunction::M2, &m, &a), 0.007610010860885858, 1e-14);
        // cf1 and cf2 depend on |M − A| only; m2 does not (it is a log ratio).
        let swapped = MeasuredBrdf::full(a);
        close(
            cost(CostFunction::Cf1, &swapped, &mv),
            0.009021337846974899,
            1e-14,
        );
        close(
            cost(CostFunction::M2, &swapped, &mv),
            0.007610010860885858,
            1e-14,
        );
    }

    #[test]
    fn flat_cost_with_is_cost_bit_for_bit() {
        let mut m = zeros();
        let mut a = zeros();
        for g in 0..GEOMETRY_COUNT {
            for b in 0..BANDS {
                m[g][b] = 0.05 + 0.013 * g as f64 + 0.001 * (b as f64).sin();
                a[g][b] = 0.06 + 0.011 * g as f64 - 0.002 * (b as f64).cos();
            }
        }
        let m = MeasuredBrdf::full(m);
        for cf in CostFunction::ALL {
            assert_eq!(
                cost_with(cf, SraReading::FLAT, &m, &a).to_bits(),
                cost(cf, &m, &a).to_bits()
            );
        }
    }

    /// Luminance model, by hand: measured flat 0.3 sr⁻¹ at sra-60 (w = 0.5), model a spectrum
    /// whose luminance is 0.1 but which is far from flat; zero elsewhere. The flat model sees
    /// 31 band differences, the luminance model one difference of 0.2 counted 31 times.
    #[test]
    fn luminance_cost_by_hand() {
        let g = by_name("sra-60").unwrap().index;
        let mut mv = zeros();
        mv[g] = [0.3; BANDS];
        let m = MeasuredBrdf::full(mv);
        let c = SraReading::LUMINANCE.weights();
        let mut a = zeros();
        let shape: Spectrum = std::array::from_fn(|b| 1.0 + (b as f64 / 5.0).sin());
        let k = 0.1 / luminance_with(&c, &shape);
        a[g] = shape.map(|x| x * k);
        // w·ΔY = 0.5 · 0.2 = 0.1: cf1 sqrt(31 · 0.01 / 434), cf2 sqrt(31 · 0.01^(1/3) / 434),
        // m2 sqrt(31 · (ln 1.15 − ln 1.05)² / 434).
        let lum = SraReading::LUMINANCE;
        close(
            cost_with(CostFunction::Cf1, lum, &m, &a),
            (31.0 * 0.01 / N).sqrt(),
            1e-12,
        );
        close(
            cost_with(CostFunction::Cf2, lum, &m, &a),
            (31.0 * 0.01f64.cbrt() / N).sqrt(),
            1e-12,
        );
        let d = 1.15f64.ln() - 1.05f64.ln();
        close(
            cost_with(CostFunction::M2, lum, &m, &a),
            (31.0 * d * d / N).sqrt(),
            1e-12,
        );
        // A model with the right luminance at the SRA geometries costs nothing there, however
        // coloured; the flat model charges its colour.
        let k = 0.3 / luminance_with(&c, &shape);
        a[g] = shape.map(|x| x * k);
        for cf in CostFunction::ALL {
            assert!(cost_with(cf, lum, &m, &a) < 1e-6, "{cf}");
            assert!(cost(cf, &m, &a) > 1e-3, "{cf}");
        }
    }

    #[test]
    fn a_perfect_model_costs_zero() {
        let mut v = zeros();
        for (g, row) in v.iter_mut().enumerate() {
            for (b, x) in row.iter_mut().enumerate() {
                *x = 0.05 + 0.01 * g as f64 + 0.002 * b as f64;
            }
        }
        let m = MeasuredBrdf::full(v);
        for cf in CostFunction::ALL {
            assert_eq!(cost(cf, &m, &v), 0.0, "{cf}");
        }
    }

    #[test]
    fn names_round_trip_and_errors_list_the_valid_names() {
        for cf in CostFunction::ALL {
            assert_eq!(cf.to_string().parse::<CostFunction>().unwrap(), cf);
            assert_eq!(serde_json::to_string(&cf).unwrap(), format!("\"{cf}\""));
            let back: CostFunction = serde_json::from_str(&format!("\"{cf}\"")).unwrap();
            assert_eq!(back, cf);
        }
        assert_eq!("CF2".parse::<CostFunction>().unwrap(), CostFunction::Cf2);
        let err = "rmse".parse::<CostFunction>().unwrap_err();
        assert_eq!(
            err.to_string(),
            "unknown cost function \"rmse\": expected one of cf1, cf2, m2"
        );
        assert!(serde_json::from_str::<CostFunction>("\"cf3\"").is_err());
    }
}
