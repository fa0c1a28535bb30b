//! `brdfd scans`: the scans in the daemon's store, newest first, a page at a time.

use serde_json::Value;

use super::operator::{DaemonArgs, id, local_time, s};

#[derive(Debug, clap::Args)]
pub struct ScansArgs {
    #[command(flatten)]
    pub daemon: DaemonArgs,
    /// Only scans in this state: requested, measuring, complete, failed, aborted.
    #[arg(long, value_name = "STATE")]
    pub state: Option<String>,
    /// Only scans of this sample.
    #[arg(long, value_name = "NAME")]
    pub sample: Option<String>,
    /// At most this many (1 to 500).
    #[arg(long, value_name = "N", default_value_t = 50)]
    pub limit: u32,
    /// Only scans older than scan ID: the next page after a listing whose last id was ID.
    #[arg(long, value_name = "ID")]
    pub before: Option<i64>,
    /// Print the daemon's JSON.
    #[arg(long)]
    pub json: bool,
}
pub fn scans(args: &ScansArgs) -> anyhow::Result<()> {
    let client = args.daemon.client()?;
    let mut query = format!("/scans?limit={}", args.limit);
    if let Some(before) = args.before {
        query.push_str(&format!("&before={before}"));
    }
    if let Some(state) = &args.state {
        query.push_str(&format!("&state={}", urlencode(state)));
    }
    if let Some(sample) = &args.sample {
        query.push_str(&format!("&sample={}", urlencode(sample)));
    }
    let v = client.get(&query)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    let rows = v.as_array().cloned().unwrap_or_default();
    if rows.is_empty() {
        println!("no scans");
        return Ok(());
    }
    println!(
        "{:>5}  {:<22} {:<9} {:>8}  {:<26}  {:<4} reason; source of a simulated scan",
        "id", "sample", "state", "readings", "requested (local time)", "sim"
    );
    let mut last = None;
    for r in &rows {
        println!(
            "{:>5}  {:<22} {:<9} {:>8}  {:<26}  {:<4} {}",
            id(r, "id"),
            s(r, "sample"),
            s(r, "state"),
            id(r, "reading_count"),
            local_time(r["requested_at_ms"].as_i64().unwrap_or(0)),
            simulated_mark(&r["provenance"]),
            [
                r["reason"].as_str().map(super::operator::terminal_safe),
                super::show::simulated_note(&r["provenance"]),
            ]
            .into_iter()
            .flatten()
            .collect::<Vec<_>>()
            .join("; ")
        );
        last = Some(id(r, "id"));
    }
    if let Some(last) = last
        && rows.len() as u32 == args.limit
    {
        eprintln!("(more may follow: `brdfd scans --before {last}`)");
    }
    Ok(())
}
/// A percent-encoding of a query value (sample names have spaces and dots).
fn urlencode(text: &str) -> String {
    text.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'.' | b'_' | b'~' => {
                (b as char).to_string()
            }
            _ => format!("%{b:02X}"),
        })
        .collect()
}
/// "sim" when either instrument was simulated, "?" when not recorded, "" for real ones.
fn simulated_mark(provenance: &Value) -> &'static str {
    let flags = [
        provenance["ma_t12"]["simulated"].as_bool(),
        provenance["sra"]["simulated"].as_bool(),
    ];
    if flags.contains(&Some(true)) {
        "sim"
    } else if flags.contains(&None) {
        "?"
    } else {
        ""
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn query_values_are_percent_encoded() {
        assert_eq!(urlencode("T.Sky blue"), "T.Sky%20blue");
        assert_eq!(urlencode("a&b=c"), "a%26b%3Dc");
    }
}
