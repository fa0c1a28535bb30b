//! Test-only support shared by the codec and session tests: how many cases every property test
//! runs, and an independent CRC.
//!
//! Case count: 2,000 cases per property in every `cargo test` run (CI included), so each parser
//! of outside bytes sees at least 2,000 generated inputs per run; `PROPTEST_CASES=N` overrides
//! it for a long run (TESTING.md gives the command and the last result). Failures are persisted
//! by proptest's default, `proptest-regressions/` beside `src/`, which is committed so that a
//! case once found is replayed first on every later run.
use proptest::test_runner::Config;

/// Cases per property when `PROPTEST_CASES` is not set.
pub(crate) const CI_CASES: u32 = 2_000;

/// proptest's defaults (failure persistence included) with [`CI_CASES`] cases unless
/// `PROPTEST_CASES` says otherwise.
pub(crate) fn config() -> Config {
    let mut c = Config::default();
    if std::env::var_os("PROPTEST_CASES").is_none() {
        c.cases = CI_CASES;
    }
    c
}

/// CRC-16/IBM-3740 (poly 0x1021, init 0xFFFF, no reflection, no final xor) computed bit by bit,
/// independently of the `crc` crate the codecs use: the fuzz tests frame their payloads with it,
/// so a codec whose checksum drifted would refuse them.
pub(crate) fn crc16_bitwise(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in bytes {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

#[test]
fn the_bitwise_crc_matches_the_catalogue_check_value() {
    // CRC RevEng catalogue, CRC-16/IBM-3740: check = 0x29B1 over "123456789".
    assert_eq!(crc16_bitwise(b"123456789"), 0x29B1);
}
