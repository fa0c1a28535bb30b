//! ASTM E308 tristimulus weighting factors for the 31-band grid (10 nm, 400–700 nm), built the
//! way ASTM E2022 prescribes from the 1 nm colour-matching functions and CIE D65, so a lab's
//! instrument software and brdfd agree on L*a*b* when both follow E308 (SCIENCE.md §7.1).
//!
//! Decisions, each the standard's:
//! - The range is E308's practice range, 360–780 nm. D65 is tabulated every 5 nm; it is brought
//!   to 1 nm by linear interpolation, as CIE 15:2018 prescribes for D65 (its 5 nm values are
//!   themselves derived from 10 nm data, so a smooth interpolant adds nothing real).
//! - ASTM E2022: the weight of each 10 nm node is `S·x̄` at the node plus, for every 1 nm
//!   wavelength between nodes, `S·x̄` there times the Lagrange coefficient of that node — cubic
//!   (four nodes) in the inner intervals, quadratic (three nodes) in the first and last.
//! - ASTM E308 §7.3.2.3: a spectrum measured over 400–700 nm only is extended by its end values,
//!   i.e. the weights of the nodes below 400 nm are added to 400 nm, those above 700 nm to 700 nm.
//! - Normalised so the perfect diffuser (R = 1 everywhere) has Y = 100.
//!
//! Checked against colour-science 0.4.7's `sd_to_XYZ(method="ASTM E308")` for the 24 ColorChecker
//! spectra, both observers, to 1e-4 (`src/colour/data/colorchecker_xyz_d65_astm_e308_colour_science.csv`).

use crate::spectral::BANDS;

/// First wavelength of the 1 nm observer tables, nm.
const CMF_START_NM: usize = 360;
/// The end of the range the weights are built over: ASTM E308's practice range is 360–780 nm
/// (the observer tables' last 50 nm carry less than 10⁻⁵ of Y, and E308's published tables stop
/// at 780 nm).
const E308_END_NM: usize = 780;
/// The grid's step and first band centre, nm.
const STEP_NM: usize = 10;
const GRID_START_NM: usize = 400;

/// The coefficients of the Lagrange polynomial through the nodes `0, 1, …, n − 1`, at `r`.
fn lagrange(r: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|j| {
            (0..n)
                .filter(|&i| i != j)
                .map(|i| (r - i as f64) / (j as f64 - i as f64))
                .product()
        })
        .collect()
}

/// D65 (5 nm, `(nm, value)` rows in increasing order) at every nm of the E308 range,
/// 360–780 nm, by linear interpolation between the 5 nm rows (CIE 15:2018 §3.1 prescribes
/// linear interpolation for intermediate values of D65).
pub fn d65_1nm(rows: &[(f64, f64)]) -> Vec<f64> {
    (CMF_START_NM..=E308_END_NM)
        .map(|nm| {
            let x = nm as f64;
            let i = rows
                .windows(2)
                .position(|w| w[0].0 <= x && x <= w[1].0)
                .unwrap_or_else(|| panic!("D65 table does not cover {nm} nm"));
            let (x0, y0) = rows[i];
            let (x1, y1) = rows[i + 1];
            if x == x0 {
                y0
            } else {
                y0 + (x - x0) / (x1 - x0) * (y1 - y0)
            }
        })
        .collect()
}

/// ASTM E308 weights `W[band][x̄, ȳ, z̄]` for the 31 bands, from 1 nm CMFs (from 360 nm, one
/// row per nm; rows past 780 nm are not used) and 1 nm D65 over 360–780 nm. `Σ W·R` is XYZ with Y(white) = 100.
pub fn weights(cmf_1nm: &[[f64; 3]], d65_1nm: &[f64]) -> [[f64; 3]; BANDS] {
    let w_c = E308_END_NM - CMF_START_NM + 1;
    assert!(
        cmf_1nm.len() >= w_c,
        "observer table must cover 360–780 nm at 1 nm"
    );
    assert!(d65_1nm.len() >= w_c, "D65 must cover 360–780 nm at 1 nm");
    let sy = |j: usize, c: usize| d65_1nm[j] * cmf_1nm[j][c];
    let nodes = (w_c - 1) / STEP_NM + 1; // 43: 360, 370, …, 780
    let r_c = STEP_NM - 1; // the 9 wavelengths inside each interval
    let boundary: Vec<Vec<f64>> = (1..STEP_NM)
        .map(|j| lagrange(j as f64 / STEP_NM as f64, 3))
        .collect();
    let inner: Vec<Vec<f64>> = (1..STEP_NM)
        .map(|j| lagrange(1.0 + j as f64 / STEP_NM as f64, 4))
        .collect();
    let mut w = vec![[0.0; 3]; nodes];
    for c in 0..3 {
        for (k, wk) in w.iter_mut().enumerate() {
            wk[c] = sy(k * STEP_NM, c);
        }
        // First interval: quadratic through nodes 0, 1, 2.
        for j in 0..r_c {
            for k in 0..3 {
                w[k][c] += boundary[j][k] * sy(j + 1, c);
            }
        }
        // Last interval: the same, mirrored onto the last three nodes.
        let last = nodes - 1;
        let first_of_last = (nodes - 2) * STEP_NM + 1;
        for j in 0..r_c {
            for k in 0..3 {
                w[last - k][c] += boundary[r_c - 1 - j][k] * sy(first_of_last + j, c);
            }
        }
        // Inner intervals: cubic through the two nodes either side.
        for j in 0..nodes - 3 {
            for (kk, coeffs) in inner.iter().enumerate() {
                let wl = STEP_NM * (j + 1) + 1 + kk;
                for m in 0..4 {
                    w[j + m][c] += coeffs[m] * sy(wl, c);
                }
            }
        }
    }
    let norm = 100.0 / w.iter().map(|v| v[1]).sum::<f64>();
    // Fold the nodes outside 400–700 nm onto the end bands (ASTM E308 §7.3.2.3).
    let first = (GRID_START_NM - CMF_START_NM) / STEP_NM;
    let mut out = [[0.0; 3]; BANDS];
    for (k, wk) in w.iter().enumerate() {
        let band = k.saturating_sub(first).min(BANDS - 1);
        for c in 0..3 {
            out[band][c] += wk[c] * norm;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lagrange_coefficients_reproduce_polynomials_and_sum_to_one() {
        for n in [3, 4] {
            for j in 1..10 {
                let r = j as f64 / 10.0 + if n == 4 { 1.0 } else { 0.0 };
                let c = lagrange(r, n);
                assert!((c.iter().sum::<f64>() - 1.0).abs() < 1e-14);
                // Exact for a polynomial of degree n − 1: p(x) = x^(n−1).
                let p: f64 = c
                    .iter()
                    .enumerate()
                    .map(|(i, ci)| ci * (i as f64).powi(n as i32 - 1))
                    .sum();
                assert!((p - r.powi(n as i32 - 1)).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn d65_is_interpolated_linearly_and_keeps_the_table_rows() {
        let rows = crate::colour::cie::d65_rows();
        let v = d65_1nm(&rows);
        assert_eq!(v.len(), 421);
        // 560 nm is a row (100, the normalisation point); 562 nm is 2/5 of the way to 565 nm.
        assert_eq!(v[560 - 360], 100.0);
        let at = |nm: f64| rows.iter().find(|r| r.0 == nm).unwrap().1;
        let want = at(560.0) + 0.4 * (at(565.0) - at(560.0));
        assert!((v[562 - 360] - want).abs() < 1e-12);
    }

    /// Σ S·ȳ over 360–780 nm at 1 nm (the E2022 normalisation before interpolation terms).
    fn w_sum_sy() -> f64 {
        let cmf = crate::colour::cie::cmf_1nm(false);
        let d65 = d65_1nm(&crate::colour::cie::d65_rows());
        (0..421)
            .step_by(10)
            .map(|j| d65[j] * cmf[j][1])
            .sum::<f64>()
            * 10.0
    }

    #[test]
    fn weights_fold_the_ends_and_give_white_y_100() {
        let w = weights(
            &crate::colour::cie::cmf_1nm(false),
            &d65_1nm(&crate::colour::cie::d65_rows()),
        );
        let y: f64 = w.iter().map(|b| b[1]).sum();
        assert!((y - 100.0).abs() < 1e-10);
        assert!(w.iter().all(|b| b.iter().all(|v| v.is_finite())));
        // Folding: the 400 nm x̄ weight exceeds its own node term S(400)·x̄(400)·k, since the
        // 360–390 nm nodes were added to it.
        let own = crate::colour::cie::d65()[0] * crate::colour::cie::cmf()[0][0];
        let k = 100.0 / w_sum_sy();
        assert!(w[0][0] > own * k, "{} vs {}", w[0][0], own * k);
    }
}
