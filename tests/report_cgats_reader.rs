//! The CGATS export read by an independent CGATS reader: LittleCMS's IT8/CGATS parser
//! (`cmsIT8LoadFromMem`), built with `CMS_STRICT_CGATS` so a header keyword that is neither
//! standard nor declared with `KEYWORD` is an error.
//!
//! Why not the `cgats` crate: it splits data on whitespace (so a quoted sample name such as
//! "T.Freesia pink" breaks the row), stores numbers as f32 and names spectral fields
//! `SPECTRAL_400`; it cannot read standard files with such names.

use std::ffi::{CStr, CString, c_char};
use std::sync::Mutex;

use brdfd::formats::{self, ExportOptions, Format};
use brdfd::geometry::GEOMETRIES;
use brdfd::report::Study;
use brdfd::spectral::wavelengths_nm;
use lcms2_sys as ffi;

/// The last message LittleCMS logged.
static LAST_ERROR: Mutex<String> = Mutex::new(String::new());

unsafe extern "C" fn log_error(_ctx: ffi::Context, _code: u32, text: *const c_char) {
    // SAFETY: LittleCMS passes a NUL-terminated message.
    let msg = unsafe { CStr::from_ptr(text) }
        .to_string_lossy()
        .into_owned();
    *LAST_ERROR.lock().unwrap() = msg;
}

/// A parsed CGATS document held by LittleCMS.
struct It8(ffi::HANDLE);

impl Drop for It8 {
    fn drop(&mut self) {
        // SAFETY: the handle came from cmsIT8LoadFromMem and is freed once.
        unsafe { ffi::cmsIT8Free(self.0) }
    }
}

impl It8 {
    fn load(text: &str) -> Result<It8, String> {
        // SAFETY: a plain C function pointer with the signature LittleCMS expects.
        unsafe { ffi::cmsSetLogErrorHandler(Some(log_error)) };
        // SAFETY: the buffer outlives the call; LittleCMS copies what it keeps.
        let h = unsafe {
            ffi::cmsIT8LoadFromMem(
                std::ptr::null_mut(),
                text.as_ptr().cast(),
                text.len() as u32,
            )
        };
        if h.is_null() {
            Err(LAST_ERROR.lock().unwrap().clone())
        } else {
            Ok(It8(h))
        }
    }

    fn fields(&self) -> Vec<String> {
        let mut names: *mut *mut c_char = std::ptr::null_mut();
        // SAFETY: LittleCMS fills `names` with `n` NUL-terminated strings it owns.
        let n = unsafe { ffi::cmsIT8EnumDataFormat(self.0, &mut names) };
        (0..n as usize)
            .map(|i| {
                // SAFETY: i < n, as LittleCMS reported.
                unsafe { CStr::from_ptr(*names.add(i)) }
                    .to_string_lossy()
                    .into_owned()
            })
            .collect()
    }

    fn text(&self, row: usize, col: usize) -> String {
        // SAFETY: row and col are within the table (checked by the callers via fields/rows).
        let p = unsafe { ffi::cmsIT8GetDataRowCol(self.0, row as i32, col as i32) };
        assert!(!p.is_null(), "no value at row {row}, column {col}");
        // SAFETY: a NUL-terminated string owned by the handle.
        unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
    }

    fn number(&self, row: usize, col: usize) -> f64 {
        // SAFETY: as for `text`.
        unsafe { ffi::cmsIT8GetDataRowColDbl(self.0, row as i32, col as i32) }
    }

    fn property(&self, key: &str) -> Option<String> {
        let key = CString::new(key).unwrap();
        // SAFETY: `key` is NUL-terminated; the result is owned by the handle or null.
        let p = unsafe { ffi::cmsIT8GetProperty(self.0, key.as_ptr()) };
        (!p.is_null()).then(|| unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned())
    }
}

/// Two samples with three finished fits each (parameters near the truth; no optimiser run).
fn study() -> Study {
    Study::from_truth(2, |_, k, mut p| {
        p.ks *= 1.0 + 0.1 * k as f64;
        Ok(p)
    })
}

#[test]
fn littlecms_reads_the_cgats_export_in_strict_mode() {
    let study = study();
    let opts = ExportOptions {
        created: "2024-05-01T12:00:00Z".into(),
        originator: "brdfd test".into(),
    };
    let text = formats::export(&study, Format::Cgats, &opts).unwrap();
    let it8 = It8::load(&text).unwrap_or_else(|e| panic!("LittleCMS refused the export: {e}"));

    let fields = it8.fields();
    assert_eq!(fields.len(), 52);
    assert_eq!(
        &fields[..7],
        [
            "SAMPLE_ID",
            "SAMPLE_NAME",
            "DATA_KIND",
            "REFERENCE_NAME",
            "COST_FUNCTION",
            "METHOD",
            "GEOMETRY"
        ]
    );
    // The sample's provenance, then the spectrum.
    for (i, name) in formats::PROVENANCE_FIELDS.iter().enumerate() {
        assert_eq!(fields[7 + i], name.to_uppercase());
    }
    let spectral = 7 + formats::PROVENANCE_FIELDS.len();
    for (i, nm) in wavelengths_nm().iter().enumerate() {
        assert_eq!(fields[spectral + i], format!("SPECTRAL_NM{nm}"));
    }
    assert_eq!(it8.property("ORIGINATOR").as_deref(), Some("brdfd test"));
    let rows = formats::rows(&study);
    assert_eq!(
        it8.property("NUMBER_OF_SETS").unwrap(),
        rows.len().to_string()
    );
    assert_eq!(rows.len(), 2 * (3 + 3) * GEOMETRIES.len());
    for (i, r) in rows.iter().enumerate() {
        assert_eq!(it8.text(i, 1), r.sample);
        assert_eq!(it8.text(i, 2), r.kind.name());
        assert_eq!(it8.text(i, 6), r.geometry.name);
        assert_eq!(it8.text(i, 10), r.origin[3], "SOURCE");
        for (b, v) in r.values.iter().enumerate() {
            // LittleCMS keeps a number it parsed as text with 10 significant digits ("%.10g"),
            // so agreement to that is what it can show (brdfd's own import, with str::parse,
            // is exact to the bit: see the formats module's tests).
            let got = it8.number(i, spectral + b);
            assert!(
                (got - v).abs() <= 5e-10 * v.abs().max(1e-300),
                "row {i} band {b}: {got} vs {v}"
            );
        }
    }
}

#[test]
fn strict_littlecms_refuses_an_undeclared_keyword() {
    // The check above can fail: the same header with a keyword nobody declared is refused.
    let text = formats::export(
        &study(),
        Format::Cgats,
        &ExportOptions {
            created: "2024-05-01T12:00:00Z".into(),
            originator: "brdfd test".into(),
        },
    )
    .unwrap()
    .replacen(
        "KEYWORD \"GEOMETRY\"\n",
        "KEYWORD \"GEOMETRY\"\nGEOMETRY_TABLE \"SCIENCE\"\n",
        1,
    );
    let e = It8::load(&text)
        .err()
        .expect("an undeclared keyword must be refused");
    assert!(e.contains("Undefined keyword 'GEOMETRY_TABLE'"), "{e}");
}
