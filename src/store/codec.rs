//! How values are laid out in the database and checked on the way in: f64 arrays as
//! little-endian BLOBs, reading values per device, and the finiteness and positivity rules.

use crate::geometry::{self, Device, GEOMETRIES, GEOMETRY_COUNT, Geometry, GeometrySet};
use crate::processing::MeasuredBrdf;
use crate::spectral::{BANDS, Spectrum, wavelengths_nm};

use super::error::StoreError;
use super::ids::ReadingId;
use super::records::{Reading, ReadingValues};

/// Bytes of one f64.
const F64: usize = 8;

/// `values` as consecutive little-endian f64.
pub(crate) fn encode_f64s(values: &[f64]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// The inverse of [`encode_f64s`]; `None` if the length is not a multiple of 8.
pub(crate) fn decode_f64s(bytes: &[u8]) -> Option<Vec<f64>> {
    if !bytes.len().is_multiple_of(F64) {
        return None;
    }
    Some(
        bytes
            .chunks_exact(F64)
            .map(|c| f64::from_le_bytes(c.try_into().expect("chunks of 8")))
            .collect(),
    )
}

/// A 31-band spectrum from its 248-byte BLOB.
pub(crate) fn decode_spectrum(bytes: &[u8]) -> Option<Spectrum> {
    decode_f64s(bytes)?.try_into().ok()
}

/// A measured BRDF as 14 × 31 f64, geometry-major in table order (3472 bytes).
pub(crate) fn encode_brdf(brdf: &MeasuredBrdf) -> Vec<u8> {
    encode_f64s(brdf.values.as_flattened())
}

/// The inverse of [`encode_brdf`], for a scan that measured `geometries` (the others hold 0).
pub(crate) fn decode_brdf(bytes: &[u8], geometries: GeometrySet) -> Option<MeasuredBrdf> {
    let flat = decode_f64s(bytes)?;
    if flat.len() != GEOMETRY_COUNT * BANDS {
        return None;
    }
    let mut values = [[0.0; BANDS]; GEOMETRY_COUNT];
    for (g, chunk) in flat.chunks_exact(BANDS).enumerate() {
        values[g].copy_from_slice(chunk);
    }
    Some(MeasuredBrdf { values, geometries })
}

/// A stored reading's values, by its device.
pub(crate) fn decode_values(device: Device, bytes: &[u8]) -> Option<ReadingValues> {
    match device {
        Device::MaT12 => decode_spectrum(bytes).map(ReadingValues::Spectrum),
        Device::Sra => match decode_f64s(bytes)?.as_slice() {
            [v] => Some(ReadingValues::Intensity(*v)),
            _ => None,
        },
    }
}

/// A device key as stored ('ma_t12', 'sra') back to the device.
pub(crate) fn device_from_key(key: &str) -> Option<Device> {
    [Device::MaT12, Device::Sra]
        .into_iter()
        .find(|d| d.key() == key)
}

/// The geometry of the table whose name is `name`.
pub(crate) fn geometry(name: &str) -> Result<&'static Geometry, StoreError> {
    geometry::by_name(name).ok_or_else(|| StoreError::UnknownGeometry(name.to_string()))
}

/// What one number of a reading is, for messages: "the value at 540 nm" or "the intensity".
fn what(values: &ReadingValues, i: usize) -> String {
    match values {
        ReadingValues::Spectrum(_) => format!("the value at {} nm", wavelengths_nm()[i]),
        ReadingValues::Intensity(_) => "the intensity".to_string(),
    }
}

/// Checks a reading before it is stored: the geometry is one of the table's and belongs to
/// `device`, the values are of the device's kind, and every number is finite. With
/// `reference`, every number must also be positive (SCIENCE.md §3: samples are divided by it).
/// Returns the table's own geometry.
pub(crate) fn check_reading(
    owner: &dyn Fn() -> String,
    device: Device,
    geometry: &Geometry,
    values: &ReadingValues,
    reference: bool,
) -> Result<&'static Geometry, StoreError> {
    let table = GEOMETRIES
        .iter()
        .find(|g| g.name == geometry.name)
        .ok_or_else(|| StoreError::UnknownGeometry(geometry.name.to_string()))?;
    if table.device != device {
        return Err(StoreError::WrongDevice {
            geometry: table.name,
            expected: table.device,
            device,
        });
    }
    let kind_ok = matches!(
        (device, values),
        (Device::MaT12, ReadingValues::Spectrum(_)) | (Device::Sra, ReadingValues::Intensity(_))
    );
    if !kind_ok {
        return Err(StoreError::WrongValueKind {
            geometry: table.name,
            device,
            expected: ReadingValues::expected_kind(device),
            got: values.kind_name(),
        });
    }
    for (i, &v) in values.as_slice().iter().enumerate() {
        if !v.is_finite() {
            return Err(StoreError::NonFinite {
                owner: format!("{} reading at {}", owner(), table.name),
                what: what(values, i),
                value: v,
            });
        }
        if reference && v <= 0.0 {
            return Err(StoreError::NonPositiveReference {
                owner: format!("{} reading at {}", owner(), table.name),
                what: what(values, i),
                value: v,
            });
        }
    }
    Ok(table)
}

/// Checks every number of `values` is finite; `name(i)` says what number `i` is.
pub(crate) fn check_finite(
    owner: &dyn Fn() -> String,
    values: &[f64],
    name: impl Fn(usize) -> String,
) -> Result<(), StoreError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(StoreError::NonFinite {
            owner: owner(),
            what: name(i),
            value: values[i],
        }),
        None => Ok(()),
    }
}

/// The names of the geometries not in `present`, in table order, comma-separated.
pub(crate) fn missing_geometries(present: &[String]) -> String {
    GEOMETRIES
        .iter()
        .filter(|g| !present.iter().any(|p| p == g.name))
        .map(|g| g.name)
        .collect::<Vec<_>>()
        .join(", ")
}

/// A stored reading as it comes out of `readings` or `reference_readings`.
#[derive(sqlx::FromRow)]
pub(crate) struct ReadingRow {
    pub id: i64,
    pub device: String,
    pub geometry: String,
    pub values_f64le: Vec<u8>,
    pub raw_frame: Vec<u8>,
    pub at_ms: i64,
}

impl ReadingRow {
    /// Decodes the row; `table` names it in the error if it cannot be.
    pub(crate) fn into_reading(self, table: &'static str) -> Result<Reading, StoreError> {
        let corrupt = |detail: String| StoreError::Corrupt {
            table,
            id: self.id,
            detail,
        };
        let device = device_from_key(&self.device)
            .ok_or_else(|| corrupt(format!("unknown device \"{}\"", self.device)))?;
        let geometry = geometry::by_name(&self.geometry)
            .ok_or_else(|| corrupt(format!("unknown geometry \"{}\"", self.geometry)))?;
        // The column is kept for SQL readers; the geometry says which instrument it is.
        if device != geometry.device {
            return Err(corrupt(format!(
                "device \"{}\" for geometry {}, which the {} measures",
                self.device, geometry.name, geometry.device
            )));
        }
        let values = decode_values(device, &self.values_f64le).ok_or_else(|| {
            corrupt(format!(
                "{} bytes of values for a {} reading",
                self.values_f64le.len(),
                device
            ))
        })?;
        Ok(Reading {
            id: ReadingId(self.id),
            geometry,
            values,
            raw_frame: self.raw_frame,
            at_ms: self.at_ms,
        })
    }
}

/// Sorts readings into geometry-table order.
pub(crate) fn sort_readings(readings: &mut [Reading]) {
    readings.sort_by_key(|r| r.geometry.index);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f64_blobs_round_trip_every_bit() {
        let values = [
            0.1,
            1.0 / 3.0,
            f64::MIN_POSITIVE,
            5e-324,
            -0.0,
            f64::MAX,
            0.7712345678901234,
        ];
        let bytes = encode_f64s(&values);
        assert_eq!(bytes.len(), 8 * values.len());
        let back = decode_f64s(&bytes).unwrap();
        for (a, b) in values.iter().zip(&back) {
            assert_eq!(a.to_bits(), b.to_bits());
        }
        // Little-endian: the first byte of 1.0 (0x3FF0_0000_0000_0000) is its lowest.
        assert_eq!(encode_f64s(&[1.0]), [0, 0, 0, 0, 0, 0, 0xf0, 0x3f]);
        assert!(decode_f64s(&[0; 7]).is_none());
    }

    #[test]
    fn brdf_blob_is_geometry_major() {
        let mut values = [[0.0; BANDS]; GEOMETRY_COUNT];
        for (g, row) in values.iter_mut().enumerate() {
            for (b, v) in row.iter_mut().enumerate() {
                *v = (g * 100 + b) as f64;
            }
        }
        let brdf = MeasuredBrdf::full(values);
        let bytes = encode_brdf(&brdf);
        assert_eq!(bytes.len(), 3472);
        // Second value stored is geometry 0, band 1.
        assert_eq!(f64::from_le_bytes(bytes[8..16].try_into().unwrap()), 1.0);
        assert_eq!(decode_brdf(&bytes, GeometrySet::ALL).unwrap(), brdf);
        assert!(decode_brdf(&bytes[..3464], GeometrySet::ALL).is_none());
        let partial = decode_brdf(&bytes, GeometrySet::MA_T12).unwrap();
        assert_eq!(partial.geometries, GeometrySet::MA_T12);
    }

    #[test]
    fn readings_are_checked_against_their_device() {
        let owner = || "scan 1".to_string();
        let g = geometry::by_name("15as45").unwrap();
        let sra = geometry::by_name("sra-60").unwrap();
        let spectrum = ReadingValues::Spectrum([0.5; BANDS]);
        assert!(check_reading(&owner, Device::MaT12, g, &spectrum, false).is_ok());
        let e = check_reading(&owner, Device::Sra, g, &spectrum, false).unwrap_err();
        assert!(matches!(e, StoreError::WrongDevice { .. }), "{e}");
        let e = check_reading(&owner, Device::Sra, sra, &spectrum, false).unwrap_err();
        assert_eq!(
            e.to_string(),
            "a reading at sra-60 (Canon RA-532H) is a single intensity, got a 31-band spectrum"
        );
        let mut s = [0.5; BANDS];
        s[14] = f64::NAN;
        let e = check_reading(&owner, Device::MaT12, g, &ReadingValues::Spectrum(s), false)
            .unwrap_err();
        assert!(
            e.to_string()
                .starts_with("scan 1 reading at 15as45: the value at 540 nm is NaN")
        );
        // Zero is a legal sample value but not a legal reference value.
        let zero = ReadingValues::Intensity(0.0);
        assert!(check_reading(&owner, Device::Sra, sra, &zero, false).is_ok());
        let e = check_reading(&owner, Device::Sra, sra, &zero, true).unwrap_err();
        assert!(matches!(e, StoreError::NonPositiveReference { .. }), "{e}");
    }

    #[test]
    fn missing_geometries_are_listed_in_table_order() {
        let present: Vec<String> = GEOMETRIES[..12].iter().map(|g| g.name.into()).collect();
        assert_eq!(missing_geometries(&present), "sra-20, sra-60");
    }
}
