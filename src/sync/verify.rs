//! Proving what the central database holds of a station, and re-sending what it lacks
//! (`brdfd sync --verify`; the daemon runs it by itself when the central database is behind
//! entries the store already deleted, e.g. after the database was restored from a backup).
//!
//! Every forwarded row has a digest: SHA-256 over its columns in [`TABLES`] order, each column
//! encoded as one tag byte (0 NULL, 1 integer, 2 float, 3 text, 4 bytes) followed, for a value,
//! by the integer as 8 bytes big-endian, the float's IEEE-754 bits as 8 bytes big-endian, or
//! the length (4 bytes big-endian) and the UTF-8 or raw bytes. The station computes it in Rust,
//! the central database in SQL (`int8send`, `float8send`, `sha256`), so only keys and digests
//! cross the network. Rows whose digest is missing or differs centrally are upserted again
//! (a resend of an identical row changes nothing); rows the central database holds for the
//! station that the store does not are counted, never deleted.
//!
//! One comparison is one PostgreSQL transaction holding the station's row lock (batches of the
//! same station wait), against one SQLite snapshot; the cursor then moves to the snapshot's
//! last entry, because the central rows are now the store's rows as of that entry.

use std::collections::{HashMap, HashSet};

use sha2::{Digest, Sha256};
use sqlx::Row;

use super::SyncError;
use super::forward::{
    Forwarder, Value, advance_station, decode_row, highest_seq, lock_station, read_rows, upsert,
};
use super::lineage;
use super::tables::{Kind, TABLES, Table};

/// One table's comparison.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct TableCheck {
    pub table: &'static str,
    /// Rows of the station's store.
    pub local: usize,
    /// Rows the central database held for the station before the comparison.
    pub central: usize,
    /// Rows missing or different centrally, sent again.
    pub resent: usize,
    /// Rows the central database holds for the station that the store does not.
    pub extra: usize,
    /// SHA-256 over the store's row digests in key order (hex), the table's fingerprint.
    pub digest: String,
}

/// What [`Forwarder::verify`] found and did.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct VerifyReport {
    pub tables: Vec<TableCheck>,
    /// The cursor after the comparison.
    pub cursor: i64,
}

impl VerifyReport {
    pub fn resent(&self) -> usize {
        self.tables.iter().map(|t| t.resent).sum()
    }
    pub fn extra(&self) -> usize {
        self.tables.iter().map(|t| t.extra).sum()
    }
}

impl std::fmt::Display for VerifyReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let local: usize = self.tables.iter().map(|t| t.local).sum();
        write!(
            f,
            "compared {local} rows in {} tables: {} re-sent, {} held centrally but not in the \
             store; cursor {}",
            self.tables.len(),
            self.resent(),
            self.extra(),
            self.cursor
        )
    }
}

/// The canonical encoding of `values` (see the module doc).
fn encode(values: &[Value], out: &mut Vec<u8>) {
    for v in values {
        match v {
            Value::Int(None) | Value::Text(None) | Value::Blob(None) | Value::Real(None) => {
                out.push(0)
            }
            Value::Int(Some(x)) => {
                out.push(1);
                out.extend_from_slice(&x.to_be_bytes());
            }
            Value::Real(Some(x)) => {
                out.push(2);
                out.extend_from_slice(&x.to_bits().to_be_bytes());
            }
            Value::Text(Some(x)) => {
                out.push(3);
                out.extend_from_slice(&(x.len() as u32).to_be_bytes());
                out.extend_from_slice(x.as_bytes());
            }
            Value::Blob(Some(x)) => {
                out.push(4);
                out.extend_from_slice(&(x.len() as u32).to_be_bytes());
                out.extend_from_slice(x);
            }
        }
    }
}

/// The same encoding of one column, in PostgreSQL.
fn encode_sql(column: &str, kind: Kind) -> String {
    let value = match kind {
        Kind::Int => format!("'\\x01'::bytea || int8send({column}::bigint)"),
        Kind::Real => format!("'\\x02'::bytea || float8send({column}::float8)"),
        Kind::Text => format!(
            "'\\x03'::bytea || int4send(octet_length({column})) || convert_to({column}, 'UTF8')"
        ),
        Kind::Blob => format!("'\\x04'::bytea || int4send(length({column})) || {column}"),
    };
    format!("(CASE WHEN {column} IS NULL THEN '\\x00'::bytea ELSE {value} END)")
}

/// The key of a row (its key columns, encoded) and its digest.
fn key_and_digest(table: &Table, row: &[Value]) -> (Vec<u8>, [u8; 32]) {
    let mut key = Vec::new();
    for k in table.key {
        let i = table
            .columns
            .iter()
            .position(|(n, _)| n == k)
            .expect("a key column is a column");
        encode(std::slice::from_ref(&row[i]), &mut key);
    }
    let mut all = Vec::new();
    encode(row, &mut all);
    (key, Sha256::digest(&all).into())
}

impl Forwarder {
    /// Compares every forwarded table of the store with what the central database holds for
    /// the station, re-sends what is missing or different, and moves the cursor to the
    /// compared snapshot (see the module doc).
    pub async fn verify(&mut self) -> Result<VerifyReport, SyncError> {
        let result = self.try_verify().await;
        match &result {
            Ok(report) => {
                let line = report.to_string();
                let cursor = report.cursor;
                self.set_status(|s| {
                    s.cursor = Some(cursor);
                    s.last_verify = Some(line);
                    s.last_verify_ms = Some(crate::store::now_ms());
                });
            }
            Err(_) => self.cursor = None,
        }
        result
    }

    async fn try_verify(&mut self) -> Result<VerifyReport, SyncError> {
        if self.central.is_none() || self.cursor.is_none() {
            self.ensure_ready().await?;
        }
        let station = self.options.station.clone();
        let expected = self.cursor.expect("ensure_ready sets it");
        let mut local = self.source.begin().await.map_err(SyncError::Local)?;
        let high = highest_seq(&mut local).await.map_err(SyncError::Local)?;
        let lineage = lineage::read(&mut *local).await.map_err(SyncError::Local)?;
        let central = self.central.as_ref().expect("ensure_ready connects");
        let mut tx = central.pool.begin().await.map_err(|e| central.error(e))?;
        let incarnation = lock_station(
            &mut tx, central, &station, &self.uid, expected, &lineage, high,
        )
        .await?;
        let mut checks = Vec::new();
        for table in &TABLES {
            // The store's rows: key → (the id that selects it, digest).
            let names: Vec<&str> = table.columns.iter().map(|(n, _)| *n).collect();
            let rows = sqlx::query(&format!(
                "SELECT {} FROM {} ORDER BY {}",
                names.join(", "),
                table.name,
                table.key.join(", ")
            ))
            .fetch_all(&mut *local)
            .await
            .map_err(SyncError::Local)?;
            let mut mine: Vec<(Vec<u8>, i64, [u8; 32])> = Vec::with_capacity(rows.len());
            let by = table
                .columns
                .iter()
                .position(|(n, _)| *n == table.selected_by)
                .expect("selected_by is a column");
            let mut fingerprint = Sha256::new();
            for row in &rows {
                let values = decode_row(table, row).map_err(SyncError::Local)?;
                let (key, digest) = key_and_digest(table, &values);
                let Value::Int(Some(id)) = values[by] else {
                    unreachable!("selected_by is an integer key column")
                };
                fingerprint.update(digest);
                mine.push((key, id, digest));
            }
            drop(rows);
            // The central database's.
            let key_sql: Vec<String> = table
                .key
                .iter()
                .map(|k| {
                    let kind = table.columns.iter().find(|(n, _)| n == k).unwrap().1;
                    encode_sql(k, kind)
                })
                .collect();
            let all_sql: Vec<String> = table
                .columns
                .iter()
                .map(|(n, k)| encode_sql(n, *k))
                .collect();
            let theirs: HashMap<Vec<u8>, Vec<u8>> = sqlx::query(&format!(
                "SELECT {}, sha256({}) FROM {} WHERE station = $1",
                key_sql.join(" || "),
                all_sql.join(" || "),
                table.name
            ))
            .bind(&station)
            .fetch_all(&mut *tx)
            .await
            .map_err(|e| central.error(e))?
            .iter()
            .map(|r| (r.get::<Vec<u8>, _>(0), r.get::<Vec<u8>, _>(1)))
            .collect();
            let mut resend: Vec<i64> = Vec::new();
            let mut seen = HashSet::new();
            let mut resent = 0;
            for (key, id, digest) in &mine {
                if theirs.get(key).map(Vec::as_slice) != Some(digest.as_slice()) {
                    resent += 1;
                    if seen.insert(*id) {
                        resend.push(*id);
                    }
                }
            }
            let local_keys: HashSet<&[u8]> = mine.iter().map(|(k, _, _)| k.as_slice()).collect();
            let extra = theirs
                .keys()
                .filter(|k| !local_keys.contains(k.as_slice()))
                .count();
            if !resend.is_empty() {
                let rows = read_rows(&mut local, table, &resend)
                    .await
                    .map_err(SyncError::Local)?;
                upsert(&mut tx, &station, table, &rows)
                    .await
                    .map_err(|e| central.error(e))?;
            }
            checks.push(TableCheck {
                table: table.name,
                local: mine.len(),
                central: theirs.len(),
                resent,
                extra,
                digest: hex::encode(&fingerprint.finalize()),
            });
        }
        let cursor = expected.max(high);
        let head = lineage::chain_head(&self.uid, &lineage, high);
        advance_station(
            &mut tx,
            central,
            &station,
            cursor,
            high,
            &head,
            &incarnation,
        )
        .await?;
        tx.commit().await.map_err(|e| central.error(e))?;
        local.commit().await.map_err(SyncError::Local)?;
        self.cursor = Some(cursor);
        self.needs_verify = false;
        Ok(VerifyReport {
            tables: checks,
            cursor,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_encoding_tells_values_and_nulls_apart() {
        let mut a = Vec::new();
        encode(
            &[
                Value::Text(Some("ab".into())),
                Value::Text(Some("c".into())),
            ],
            &mut a,
        );
        let mut b = Vec::new();
        encode(
            &[
                Value::Text(Some("a".into())),
                Value::Text(Some("bc".into())),
            ],
            &mut b,
        );
        assert_ne!(a, b);
        let mut n = Vec::new();
        encode(&[Value::Int(None), Value::Real(Some(-0.0))], &mut n);
        assert_eq!(n, [0, 2, 0x80, 0, 0, 0, 0, 0, 0, 0]);
        let mut i = Vec::new();
        encode(&[Value::Int(Some(1))], &mut i);
        assert_eq!(i, [1, 0, 0, 0, 0, 0, 0, 0, 1]);
    }
}
