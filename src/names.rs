//! Names of the files brdfd writes: the file-system friendly slug of a sample name (report
//! previews and spectra, exports, scan files) and random hex for names nobody may guess
//! (temporary files, the web page's report directories); and the names of the fit's choices
//! (model form, Fresnel factor, preset) as the command line and the settings spell them.

/// `Display` (the name) and `FromStr` (the name in any case, trimmed; anything else "unknown
/// WHAT \"…\": expected EXPECTED") for a choice enum with `ALL` and `const fn name(self)`.
macro_rules! choice_by_name {
    ($t:ty, $what:literal, $expected:literal) => {
        impl std::fmt::Display for $t {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.name())
            }
        }

        impl std::str::FromStr for $t {
            type Err = String;

            fn from_str(s: &str) -> Result<Self, Self::Err> {
                <$t>::ALL
                    .into_iter()
                    .find(|c| c.name().eq_ignore_ascii_case(s.trim()))
                    .ok_or_else(|| {
                        format!(
                            concat!("unknown ", $what, " \"{}\": expected ", $expected),
                            s
                        )
                    })
            }
        }
    };
}
pub(crate) use choice_by_name;

use rand::RngCore;

/// A file-system friendly name: "T.Freesia pink" → "t-freesia-pink".
pub fn slug(sample: &str) -> String {
    let mut out = String::new();
    for c in sample.chars() {
        if c.is_ascii_alphanumeric() {
            out.push(c.to_ascii_lowercase());
        } else if !out.ends_with('-') && !out.is_empty() {
            out.push('-');
        }
    }
    out.trim_end_matches('-').to_string()
}

/// `n` random bytes as hex (names of temporary files).
pub fn random_hex(n: usize) -> String {
    let mut bytes = vec![0u8; n];
    rand::rng().fill_bytes(&mut bytes);
    hex::encode(&bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slugs() {
        assert_eq!(slug("T.Freesia pink"), "t-freesia-pink");
        assert_eq!(slug("  A--b__c "), "a-b-c");
    }
}
