//! Test-only support: how many cases every property test of this crate runs.
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
