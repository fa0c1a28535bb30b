//! Times in exchange files: RFC 3339 UTC as brdfd writes it, and an instrument export's
//! creation time as brdfd reads it.

/// The current time as RFC 3339 UTC, whole seconds (`2024-05-01T12:00:00Z`).
pub fn rfc3339_utc_now() -> String {
    rfc3339_utc(crate::store::now_ms() / 1000)
}

/// Seconds since the Unix epoch → RFC 3339 UTC, whole seconds (e.g. `2024-05-01T12:00:00Z`).
pub fn rfc3339_utc(secs: i64) -> String {
    jiff::Timestamp::from_second(secs)
        .map(|t| t.strftime("%Y-%m-%dT%H:%M:%SZ").to_string())
        .unwrap_or_else(|_| format!("{secs} s after 1970-01-01T00:00:00Z"))
}

/// A time as an instrument's export writes it, as RFC 3339 UTC: RFC 3339 itself, or a civil
/// ISO 8601 date and time without an offset, which is taken as UTC (`None` otherwise).
pub(crate) fn export_time(text: &str) -> Option<(String, bool)> {
    let text = text.trim();
    if let Ok(t) = text.parse::<jiff::Timestamp>() {
        return Some((t.to_string(), true));
    }
    let civil: jiff::civil::DateTime = text.parse().ok()?;
    let t = jiff::tz::TimeZone::UTC.to_timestamp(civil).ok()?;
    Some((t.to_string(), false))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_are_rfc3339() {
        assert_eq!(rfc3339_utc(0), "1970-01-01T00:00:00Z");
        assert_eq!(rfc3339_utc(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(rfc3339_utc(1_714_564_800), "2024-05-01T12:00:00Z");
        assert_eq!(rfc3339_utc(4_107_542_399), "2100-02-28T23:59:59Z");
        assert_eq!(rfc3339_utc(-1), "1969-12-31T23:59:59Z");
        assert_eq!(
            rfc3339_utc(i64::MAX),
            format!("{} s after 1970-01-01T00:00:00Z", i64::MAX)
        );
    }
}
