//! Test-only support: how many cases every property test of this crate runs, and made-up
//! intervals for tests of what carries them.
//!
//! Decision: 2,000 cases per property in every `cargo test` run (CI included), so each parser
//! of outside input (scan files, brdfd.toml, CGATS, CxF3, CSV, JSON and instrument-software
//! imports) sees at least 2,000 generated inputs per run; `PROPTEST_CASES=N` overrides it for a
//! long run (TESTING.md gives the command and the last result). Failures are persisted by
//! proptest's default, `proptest-regressions/` beside `src/`, which is committed so that a case
//! once found is replayed first on every later run.
use proptest::test_runner::Config;

/// Cases per property when `PROPTEST_CASES` is not set.
pub(crate) const CI_CASES: u32 = 2_000;

/// proptest's defaults (failure persistence included) with [`CI_CASES`] cases unless
/// `PROPTEST_CASES` says otherwise.
pub(crate) fn proptest_config() -> Config {
    let mut c = Config::default();
    if std::env::var_os("PROPTEST_CASES").is_none() {
        c.cases = CI_CASES;
    }
    c
}

/// Made-up intervals around `p` (ks and α ±20 %, n and kd ±10 %, ΔE00 means fixed), as a
/// bootstrap with `calibrated` would record them.
pub(crate) fn made_up_uncertainty(
    p: &crate::model::Params,
    calibrated: bool,
) -> crate::uncertainty::Uncertainty {
    crate::uncertainty::Uncertainty {
        method: crate::uncertainty::METHOD.into(),
        resamples: 200,
        noise: 0.014,
        seed: 1,
        percentile_level: 0.95,
        ks: [p.ks * 0.8, p.ks * 1.2],
        alpha: [p.alpha * 0.8, p.alpha * 1.2],
        ior: [p.ior * 0.9, p.ior * 1.1],
        kd: p.kd.iter().map(|k| [k * 0.9, k * 1.1]).collect(),
        delta_e00_mean: [0.1, 0.2],
        delta_e00_diffuse_mean: [0.1, 0.2],
        delta_e00_specular_mean: Some([1.0, 2.0]),
        calibrated,
        note: None,
        at_bound: Vec::new(),
        misfit: None,
    }
}
