//! The instrument camera's texture images kept with an imported scan (migration 0019): each
//! PNG stored once by its SHA-256, each scan's images in the file's order with the label and
//! anchor cell the export gives them.

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::backend::Db;
use super::ids::ScanId;
use super::{Store, StoreError};

/// One texture image to keep with an imported scan.
#[derive(Debug, Clone, Copy)]
pub struct NewTexture<'a> {
    /// What the export writes beside it: a 15° geometry (`15as-45` …) or `15d`.
    pub label: &'a str,
    /// The cell its top-left corner is anchored in, e.g. `B2`.
    pub anchor: &'a str,
    /// The PNG file.
    pub png: &'a [u8],
}

/// A scan's texture image as the API lists it (the PNG itself comes from
/// [`Store::scan_texture_png`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct TextureSummary {
    /// Its place among the scan's images, from 0, in the export's order.
    pub position: u32,
    pub label: String,
    pub anchor: String,
    /// The PNG's SHA-256, lower-case hex: the same image has the same one in every scan.
    pub sha256: String,
    pub bytes: u64,
}

const PNG_SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";

/// The SHA-256 of `bytes`, lower-case hex.
fn sha256_hex(bytes: &[u8]) -> String {
    hex::encode(Sha256::digest(bytes))
}

/// Checks what [`insert_textures`] would write, before any write.
pub(super) fn check_textures(textures: &[NewTexture<'_>]) -> Result<(), StoreError> {
    for (i, t) in textures.iter().enumerate() {
        if !t.png.starts_with(PNG_SIGNATURE) {
            return Err(StoreError::NotPng {
                what: format!("texture image {i} ({})", t.label),
            });
        }
    }
    Ok(())
}

/// Writes `scan`'s texture images inside `tx`: each PNG once (an image already stored under
/// its SHA-256 is not written again), then the scan's list.
pub(super) async fn insert_textures(
    tx: &mut sqlx::Transaction<'_, Db>,
    scan: i64,
    textures: &[NewTexture<'_>],
) -> Result<(), StoreError> {
    for (position, t) in textures.iter().enumerate() {
        let sha = sha256_hex(t.png);
        sqlx::query(
            "INSERT INTO texture_images (sha256, png) VALUES ($1, $2)
             ON CONFLICT (sha256) DO NOTHING",
        )
        .bind(&sha)
        .bind(t.png)
        .execute(&mut **tx)
        .await?;
        sqlx::query(
            "INSERT INTO scan_textures (scan_id, position, label, anchor, sha256)
             VALUES ($1, $2, $3, $4, $5)",
        )
        .bind(scan)
        .bind(position as i64)
        .bind(t.label)
        .bind(t.anchor)
        .bind(&sha)
        .execute(&mut **tx)
        .await?;
    }
    Ok(())
}

impl Store {
    /// The texture images kept with `scan`, in the export's order; empty for a scan without
    /// any (every measured scan, and imports whose file had none).
    pub async fn scan_textures(&self, scan: ScanId) -> Result<Vec<TextureSummary>, StoreError> {
        let rows: Vec<(i64, String, String, String, i64)> = sqlx::query_as(
            "SELECT t.position, t.label, t.anchor, t.sha256, length(i.png)
             FROM scan_textures t JOIN texture_images i ON i.sha256 = t.sha256
             WHERE t.scan_id = $1 ORDER BY t.position",
        )
        .bind(scan.0)
        .fetch_all(&self.reader)
        .await?;
        Ok(rows
            .into_iter()
            .map(|(position, label, anchor, sha256, bytes)| TextureSummary {
                position: position as u32,
                label,
                anchor,
                sha256,
                bytes: bytes as u64,
            })
            .collect())
    }

    /// The PNG of `scan`'s texture image at `position`, or `NotFound`.
    pub async fn scan_texture_png(
        &self,
        scan: ScanId,
        position: u32,
    ) -> Result<Vec<u8>, StoreError> {
        let png: Option<Vec<u8>> = sqlx::query_scalar(
            "SELECT i.png FROM scan_textures t JOIN texture_images i ON i.sha256 = t.sha256
             WHERE t.scan_id = $1 AND t.position = $2",
        )
        .bind(scan.0)
        .bind(i64::from(position))
        .fetch_optional(&self.reader)
        .await?;
        png.ok_or(StoreError::NotFound {
            what: "texture image",
            id: i64::from(position),
        })
    }

    /// How many distinct texture images the store holds (each stored once).
    pub async fn texture_image_count(&self) -> Result<u64, StoreError> {
        let n: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM texture_images")
            .fetch_one(&self.reader)
            .await?;
        Ok(n as u64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::{ImportedScan, NewReading, Provenance, ReadingValues};

    /// A minimal PNG signature followed by `tag`: enough for the store, which keeps the bytes.
    fn png(tag: &[u8]) -> Vec<u8> {
        [PNG_SIGNATURE, tag].concat()
    }

    #[tokio::test]
    async fn an_image_is_stored_once_however_many_scans_keep_it() {
        let store = Store::open_in_memory().await.unwrap();
        let spectrum = ReadingValues::Spectrum([0.5; 31]);
        let readings: Vec<NewReading<'_>> = crate::geometry::ma_t12()
            .iter()
            .map(|g| NewReading {
                device: g.device,
                geometry: g,
                values: spectrum,
                raw_frame: &[],
            })
            .collect();
        let (a, b) = (png(b"a"), png(b"b"));
        let textures = [
            NewTexture {
                label: "15as-45",
                anchor: "B2",
                png: &a,
            },
            NewTexture {
                label: "15d",
                anchor: "B3",
                png: &b,
            },
        ];
        let provenance = Provenance::unknown();
        let import = ImportedScan {
            sample_name: "S",
            reference_name: "instrument calibration (imported)",
            provenance: &provenance,
            reference_readings: None,
            readings: &readings,
            taken_at_ms: None,
            textures: &textures,
        };
        let (_, first) = store.import(&import).await.unwrap();
        let (_, second) = store.import(&import).await.unwrap();
        assert_eq!(store.texture_image_count().await.unwrap(), 2);
        for scan in [first, second] {
            let listed = store.scan_textures(scan).await.unwrap();
            let labels: Vec<&str> = listed.iter().map(|t| t.label.as_str()).collect();
            assert_eq!(labels, ["15as-45", "15d"]);
            assert_eq!(listed[0].sha256, sha256_hex(&a));
            assert_eq!(store.scan_texture_png(scan, 1).await.unwrap(), b);
        }
        assert!(matches!(
            store.scan_texture_png(first, 2).await,
            Err(StoreError::NotFound { .. })
        ));
        // Not a PNG: refused before anything is written.
        let bad = [NewTexture {
            label: "15as15",
            anchor: "B4",
            png: b"GIF89a",
        }];
        let e = store
            .import(&ImportedScan {
                textures: &bad,
                ..import
            })
            .await
            .unwrap_err();
        assert!(matches!(e, StoreError::NotPng { .. }), "{e}");
        assert_eq!(
            store.list_scans(&Default::default()).await.unwrap().len(),
            2
        );
    }
}
