//! Row-id newtypes, one per table, so a scan id can never be passed where a fit-run id is
//! expected. Each wraps the table's 64-bit integer primary key; the inner value is public for
//! the HTTP API and CLI, which print and parse ids.

use std::fmt;
use std::str::FromStr;

macro_rules! id_type {
    ($(#[$doc:meta])* $name:ident, $what:literal) => {
        $(#[$doc])*
        #[derive(
            Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash,
            serde::Serialize, serde::Deserialize,
        )]
        #[serde(transparent)]
        pub struct $name(pub i64);

        impl $name {
            /// What the id names, for messages ("scan 12").
            pub const WHAT: &'static str = $what;
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                self.0.fmt(f)
            }
        }

        impl FromStr for $name {
            type Err = std::num::ParseIntError;

            fn from_str(s: &str) -> Result<Self, Self::Err> {
                s.parse().map($name)
            }
        }
    };
}

id_type!(
    /// An instrument (one physical MA-T12 or SRA), table `instruments`.
    InstrumentId,
    "instrument"
);
id_type!(
    /// A reference set (one measurement of the white tile), table `reference_sets`.
    ReferenceId,
    "reference"
);
id_type!(
    /// A sample, table `samples`.
    SampleId,
    "sample"
);
id_type!(
    /// A scan, table `scans`.
    ScanId,
    "scan"
);
id_type!(
    /// One reading of a scan or of a reference set (tables `readings`, `reference_readings`).
    ReadingId,
    "reading"
);
id_type!(
    /// A processed scan (measured BRDF under one specular strategy), table `processed`.
    ProcessedId,
    "processed scan"
);
id_type!(
    /// A fit run, table `fit_runs`.
    FitRunId,
    "fit run"
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_print_and_parse_as_plain_integers() {
        let id: ScanId = "42".parse().unwrap();
        assert_eq!(id, ScanId(42));
        assert_eq!(id.to_string(), "42");
        assert_eq!(serde_json::to_string(&FitRunId(7)).unwrap(), "7");
        assert!("x".parse::<ScanId>().is_err());
    }
}
