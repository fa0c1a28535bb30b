//! Names of the files brdfd writes: the file-system friendly slug of a sample name (report
//! previews and spectra, exports, scan files) and random hex for names nobody may guess
//! (temporary files, the web page's report directories).

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
