//! Study statistics (SCIENCE.md §8, the paper's "Results"): the mean ΔE00 of a cost function
//! with its 95 % Student-t confidence interval, and the exact two-sided sign test between two
//! cost functions on paired ΔE00 values.
//!
//! The t quantile is `statrs`'s (`StudentsT::inverse_cdf`, no default features, so no
//! nalgebra or rand); the tests pin it to textbook values. The binomial tail of the sign test is
//! summed exactly here: it is a short loop and the checks in SCIENCE.md §8 need 10 digits.
//!
//! [`standard_normal`] is the one normal draw the synthetic scans' noise and the bootstrap's
//! resampling share, so both stay reproducible from their seeds.

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use statrs::distribution::{ContinuousCDF, StudentsT};

/// A mean with its two-sided 95 % confidence interval, `mean ± t(0.975, n−1) · s / √n`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MeanCi {
    pub mean: f64,
    /// `t(0.975, n−1) · s / √n`, with `s` the sample standard deviation (n − 1 denominator).
    pub half_width: f64,
    /// `mean − half_width`.
    pub lo: f64,
    /// `mean + half_width`.
    pub hi: f64,
    pub n: usize,
}

/// Student-t quantile: the `t` with `P(T ≤ t) = p` for `df` degrees of freedom; a two-sided
/// 95 % interval uses `p = 0.975`. `None` for df < 1 or `p` outside (0, 1).
pub fn t_quantile(p: f64, df: f64) -> Option<f64> {
    // Written so that a NaN df or p also lands in the `None` branch.
    let usable = df >= 1.0 && p > 0.0 && p < 1.0;
    if !usable {
        return None;
    }
    let t = StudentsT::new(0.0, 1.0, df).ok()?;
    Some(t.inverse_cdf(p))
}

/// Mean of `xs` with its 95 % Student-t confidence interval. `None` when there are fewer than
/// two values (no spread to estimate) or any value is not finite (e.g. a failed fit's NaN,
/// which the caller must leave out and report, SCIENCE.md §8).
pub fn mean_ci95(xs: &[f64]) -> Option<MeanCi> {
    let n = xs.len();
    if n < 2 || xs.iter().any(|x| !x.is_finite()) {
        return None;
    }
    let nf = n as f64;
    let mean = xs.iter().sum::<f64>() / nf;
    let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (nf - 1.0);
    let half_width = t_quantile(0.975, nf - 1.0)? * (var / nf).sqrt();
    Some(MeanCi {
        mean,
        half_width,
        lo: mean - half_width,
        hi: mean + half_width,
        n,
    })
}

/// The result of a paired sign test.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SignTest {
    /// Pairs that count: `plus + minus` (ties dropped).
    pub n: usize,
    /// Pairs with `a > b` (for ΔE00: the first cost function did worse).
    pub plus: usize,
    /// Pairs with `a < b`.
    pub minus: usize,
    /// Pairs with `a == b`, or where either value is NaN; dropped.
    pub ties: usize,
    /// Exact two-sided p: `min(1, 2 · P(X ≤ min(plus, minus)))`, X ~ Bin(n, ½); 1 when n = 0.
    pub p: f64,
}

/// `P(X ≤ k)` for X ~ Bin(n, ½).
///
/// Up to n = 120 the tail is summed in integers (every C(120, i) and the running product fit
/// in u128) and divided by 2ⁿ once, so the result is the exact fraction rounded once. Above
/// that it is summed term by term in log space, so that n in the thousands neither overflows
/// the coefficients nor underflows 2⁻ⁿ before the sum (relative error ~1e-13).
pub fn binomial_half_cdf(k: usize, n: usize) -> f64 {
    if k >= n {
        return 1.0;
    }
    if n <= EXACT_MAX_N {
        let mut choose: u128 = 1; // C(n, 0)
        let mut sum: u128 = 1;
        for i in 1..=k {
            // C(n, i) = C(n, i−1) · (n − i + 1) / i, exact: i divides the product.
            choose = choose * (n - i + 1) as u128 / i as u128;
            sum += choose;
        }
        // 2ⁿ is a power of two, so the division is exact; only the u128 → f64 step rounds.
        return sum as f64 / 2f64.powi(n as i32);
    }
    let ln_half_n = -(n as f64) * std::f64::consts::LN_2;
    let mut ln_choose = 0.0; // ln C(n, 0)
    let mut sum = 0.0;
    for i in 0..=k {
        if i > 0 {
            ln_choose += ((n - i + 1) as f64).ln() - (i as f64).ln();
        }
        sum += (ln_choose + ln_half_n).exp();
    }
    sum.min(1.0)
}

/// Largest n for which [`binomial_half_cdf`] sums exactly in u128: C(120, 60) · 61 < 2¹²⁸.
const EXACT_MAX_N: usize = 120;

/// Paired two-sided sign test of `a` against `b` (SCIENCE.md §8). Pair `i` is `(a[i], b[i])`.
///
/// # Panics
/// If `a` and `b` differ in length: the values are pairs by construction (same sample, same
/// geometry), so a mismatch is a bug in the caller, not a property of the data.
pub fn sign_test(a: &[f64], b: &[f64]) -> SignTest {
    assert_eq!(
        a.len(),
        b.len(),
        "sign_test: paired values must have equal lengths ({} vs {})",
        a.len(),
        b.len()
    );
    let (mut plus, mut minus, mut ties) = (0, 0, 0);
    for (x, y) in a.iter().zip(b) {
        match x.partial_cmp(y) {
            Some(std::cmp::Ordering::Greater) => plus += 1,
            Some(std::cmp::Ordering::Less) => minus += 1,
            _ => ties += 1,
        }
    }
    let n = plus + minus;
    let p = (2.0 * binomial_half_cdf(plus.min(minus), n)).min(1.0);
    SignTest {
        n,
        plus,
        minus,
        ties,
        p,
    }
}

/// One standard normal draw by the Box–Muller transform (keeps the crate free of rand_distr).
pub(crate) fn standard_normal(rng: &mut ChaCha8Rng) -> f64 {
    let u1 = 1.0 - rng.random::<f64>(); // (0, 1]: ln is finite
    let u2 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn t_quantile_matches_textbook_values() {
        // Two-sided 95 % critical values of Student's t (any statistics table).
        for (df, t) in [
            (1.0, 12.7062),
            (5.0, 2.5706),
            (10.0, 2.2281),
            (30.0, 2.0423),
        ] {
            let got = t_quantile(0.975, df).unwrap();
            assert!((got - t).abs() < 1e-4, "df {df}: {got}");
        }
        // More digits where a table gives them: t(0.975, 1) = tan(0.475 π).
        let exact = (0.475 * std::f64::consts::PI).tan();
        assert!((t_quantile(0.975, 1.0).unwrap() - exact).abs() < 1e-9);
        assert_eq!(t_quantile(0.975, 0.0), None);
        assert_eq!(t_quantile(1.0, 5.0), None);
        assert_eq!(t_quantile(f64::NAN, 5.0), None);
        assert_eq!(t_quantile(0.975, f64::NAN), None);
    }

    #[test]
    fn ci_by_hand() {
        // xs = 1, 2, 3, 4, 5: mean 3, s² = 10/4 = 2.5, s/√n = √0.5 = 0.70711,
        // t(0.975, 4) = 2.7764 → half width 1.9632, CI [1.0368, 4.9632].
        let ci = mean_ci95(&[1.0, 2.0, 3.0, 4.0, 5.0]).unwrap();
        assert_eq!(ci.n, 5);
        assert!((ci.mean - 3.0).abs() < 1e-12);
        assert!((ci.half_width - 1.9632).abs() < 1e-4, "{}", ci.half_width);
        assert!((ci.lo - 1.0368).abs() < 1e-4 && (ci.hi - 4.9632).abs() < 1e-4);
    }

    #[test]
    fn ci_needs_two_finite_values() {
        assert_eq!(mean_ci95(&[]), None);
        assert_eq!(mean_ci95(&[1.0]), None);
        assert_eq!(mean_ci95(&[1.0, f64::NAN]), None);
        // No spread: a zero-width interval, not an error.
        let ci = mean_ci95(&[2.0, 2.0, 2.0]).unwrap();
        assert_eq!((ci.lo, ci.hi), (2.0, 2.0));
    }

    /// Builds paired values with `k` pairs a > b and `n − k` pairs a < b.
    fn pairs(k: usize, n: usize) -> (Vec<f64>, Vec<f64>) {
        let a = (0..n).map(|i| if i < k { 2.0 } else { 1.0 }).collect();
        let b = vec![1.5; n];
        (a, b)
    }

    #[test]
    fn sign_test_matches_science_md_checks() {
        for (k, n, p) in [
            (1, 8, 0.0703125),
            (2, 10, 0.109375),
            (3, 14, 0.0573730469),
            (7, 14, 1.0),
        ] {
            let (a, b) = pairs(k, n);
            let t = sign_test(&a, &b);
            assert_eq!((t.n, t.plus, t.minus, t.ties), (n, k, n - k, 0));
            assert!((t.p - p).abs() < 1e-10, "k={k} n={n}: {}", t.p);
            // The test is two-sided: swapping the sides gives the same p.
            assert_eq!(sign_test(&b, &a).p, t.p);
        }
    }

    #[test]
    fn sign_test_drops_ties_and_nan() {
        let a = [1.0, 2.0, 3.0, 4.0, f64::NAN];
        let b = [1.0, 1.0, 1.0, 1.0, 1.0];
        let t = sign_test(&a, &b);
        assert_eq!((t.n, t.plus, t.minus, t.ties), (3, 3, 0, 2));
        // 2 · P(X ≤ 0), X ~ Bin(3, ½) = 2/8.
        assert_eq!(t.p, 0.25);
        assert_eq!(sign_test(&[], &[]).p, 1.0);
    }

    #[test]
    fn binomial_tail_is_exact_and_survives_large_n() {
        // P(X ≤ 3), Bin(14, ½) = (1 + 14 + 91 + 364) / 16384.
        assert_eq!(binomial_half_cdf(3, 14), 470.0 / 16384.0);
        // The exact and log-space paths agree where they meet: P(X ≤ 55), n = 120 and 121.
        let (a, b) = (binomial_half_cdf(55, 120), binomial_half_cdf(55, 121));
        let b_from_a = a - (binomial_half_cdf(55, 120) - binomial_half_cdf(54, 120)) / 2.0;
        assert!((b - b_from_a).abs() < 1e-12, "{b} vs {b_from_a}");
        // By symmetry P(X ≤ 999) for Bin(2000, ½) = (1 − P(X = 1000)) / 2, and
        // P(X = 1000) ≈ 1/√(1000π) = 0.017839 (Stirling, relative error < 1e-4).
        let p = binomial_half_cdf(999, 2000);
        assert!((p - (1.0 - 0.017839) / 2.0).abs() < 1e-5, "{p}");
        assert!(binomial_half_cdf(0, 2000) >= 0.0);
    }

    #[test]
    #[should_panic(expected = "equal lengths")]
    fn sign_test_rejects_unpaired_input() {
        sign_test(&[1.0], &[1.0, 2.0]);
    }
}
