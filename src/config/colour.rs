//! `[colour]`: the observer and weighting of every L*a*b* and ΔE00 (SCIENCE.md §7.1), checked
//! into a [`crate::colour::Colorimetry`].

use serde::Deserialize;

use super::check::{Checker, ConfigError, S};

// ---- Stage 1: the section's shape ----------------------------------------------------------

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawColour {
    observer: S<String>,
    weighting: S<String>,
}

// ---- Stage 2: its checks ------------------------------------------------------------------

impl Checker<'_> {
    /// `[colour]`
    pub(super) fn colour(
        &self,
        raw: &RawColour,
    ) -> Result<crate::colour::Colorimetry, ConfigError> {
        Ok(crate::colour::Colorimetry {
            observer: self.value(
                "colour.observer",
                &raw.observer,
                crate::colour::Observer::default().to_string(),
                |o| {
                    o.parse()
                        .map_err(|e: crate::colour::ColorimetryError| e.to_string())
                },
            )?,
            weighting: self.value(
                "colour.weighting",
                &raw.weighting,
                crate::colour::Weighting::default().to_string(),
                |w| {
                    w.parse()
                        .map_err(|e: crate::colour::ColorimetryError| e.to_string())
                },
            )?,
        })
    }
}

#[cfg(test)]
mod tests {
    use crate::config::tests::parse;

    #[test]
    fn colour_and_bootstrap_settings() {
        let c =
            parse("[colour]\nobserver = \"10\"\nweighting = \"astm-e308\"\n[fit]\nbootstrap = 0\ncrossval = false\n")
                .unwrap();
        assert_eq!(c.colour.observer, crate::colour::Observer::Cie1964TenDegree);
        assert_eq!(c.colour.weighting, crate::colour::Weighting::AstmE308);
        assert_eq!(c.fit.bootstrap, 0);
        assert!(!c.fit.crossval);
        assert!(crate::config::Config::default().fit.crossval);
        let e = parse("[colour]\nobserver = \"5\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("colour.observer") && e.contains("\"10\""), "{e}");
        let e = parse("[fit]\nbootstrap = 20000\n").unwrap_err().to_string();
        assert!(e.contains("fit.bootstrap"), "{e}");
    }
}
