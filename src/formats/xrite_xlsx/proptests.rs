//! Property tests: mutated copies of a real export are read or refused, never a panic.

use std::sync::LazyLock;

use super::tests::{bytes, read, rezip, unzip};
use super::*;
use proptest::prelude::*;

/// `PAR_PW_CB_NG_1.xlsx` with each image cut to a 64-byte PNG head, so that an edit often
/// lands in the sheets, and a case is fast.
static BASE: LazyLock<Vec<(String, Vec<u8>)>> = LazyLock::new(|| {
    unzip(&bytes("PAR_PW_CB_NG_1.xlsx"))
        .into_iter()
        .map(|(n, b)| {
            let b = if n.starts_with("xl/media/") {
                b[..64].to_vec()
            } else {
                b
            };
            (n, b)
        })
        .collect()
});

const PARTS: [&str; 6] = [
    "xl/worksheets/sheet1.xml",
    "xl/worksheets/sheet3.xml",
    "xl/worksheets/sheet4.xml",
    "xl/sharedStrings.xml",
    "xl/workbook.xml",
    "xl/drawings/drawing1.xml",
];

/// What goes into an edited value.
const PIECES: [&str; 16] = [
    "",
    "0",
    "-0.01",
    "0.5",
    "1e999",
    "NaN",
    "abc",
    "45as45",
    "15as-45",
    "400",
    "705",
    "D50/10",
    "D65/2",
    "45441.7965277778",
    "Name",
    "<",
];

#[derive(Debug, Clone)]
enum Edit {
    /// Replace the text of the k-th `<v>` or `<t>` element of a part.
    Value(usize, usize, String),
    /// Delete the k-th `<c …>` cell, or `<row …>` row, of a part.
    Delete(usize, usize, bool),
    /// Duplicate the k-th row of a part (same row number).
    DuplicateRow(usize, usize),
    /// Flip a byte of a part.
    Flip(usize, usize, u8),
    /// Cut the archive at a fraction (per mille) of its length.
    Truncate(u16),
    /// Flip a byte of the archive.
    FlipArchive(usize, u8),
}

fn edit() -> impl Strategy<Value = Edit> {
    let part = 0..PARTS.len();
    prop_oneof![
        4 => (part.clone(), any::<usize>(), proptest::sample::select(&PIECES[..]))
            .prop_map(|(p, k, t)| Edit::Value(p, k, t.to_string())),
        2 => (part.clone(), any::<usize>(), any::<bool>())
            .prop_map(|(p, k, row)| Edit::Delete(p, k, row)),
        1 => (part.clone(), any::<usize>()).prop_map(|(p, k)| Edit::DuplicateRow(p, k)),
        1 => (part, any::<usize>(), 1..=255u8).prop_map(|(p, i, x)| Edit::Flip(p, i, x)),
        1 => (0..1000u16).prop_map(Edit::Truncate),
        1 => (any::<usize>(), 1..=255u8).prop_map(|(i, x)| Edit::FlipArchive(i, x)),
    ]
}

/// The byte ranges of the elements of `xml` opened by `open` and closed by `close`.
fn elements(xml: &[u8], open: &[u8], close: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut at = 0;
    while let Some(s) = find(&xml[at..], open).map(|i| i + at) {
        let Some(gt) = find(&xml[s..], b">").map(|i| i + s) else {
            break;
        };
        let end = if xml[gt - 1] == b'/' {
            gt + 1
        } else {
            match find(&xml[gt..], close) {
                Some(i) => gt + i + close.len(),
                None => break,
            }
        };
        out.push((s, end));
        at = end;
    }
    out
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

fn apply(edits: &[Edit]) -> Vec<u8> {
    let mut parts = BASE.clone();
    let mut archive_edits = Vec::new();
    for e in edits {
        let part = |p: usize| PARTS[p];
        let get = |parts: &mut Vec<(String, Vec<u8>)>, p: usize| -> usize {
            parts.iter().position(|(n, _)| n == part(p)).expect("part")
        };
        match e {
            Edit::Value(p, k, text) => {
                let i = get(&mut parts, *p);
                let x = &parts[i].1;
                let mut spots = elements(x, b"<v>", b"</v>");
                spots.extend(elements(x, b"<t>", b"</t>"));
                if spots.is_empty() {
                    continue;
                }
                let (s, end) = spots[k % spots.len()];
                let new = [&x[..s + 3], text.as_bytes(), &x[end - 4..]].concat();
                parts[i].1 = new;
            }
            Edit::Delete(p, k, row) => {
                let i = get(&mut parts, *p);
                let x = &parts[i].1;
                let spots = if *row {
                    elements(x, b"<row ", b"</row>")
                } else {
                    elements(x, b"<c ", b"</c>")
                };
                if spots.is_empty() {
                    continue;
                }
                let (s, end) = spots[k % spots.len()];
                parts[i].1 = [&x[..s], &x[end..]].concat();
            }
            Edit::DuplicateRow(p, k) => {
                let i = get(&mut parts, *p);
                let x = &parts[i].1;
                let spots = elements(x, b"<row ", b"</row>");
                if spots.is_empty() {
                    continue;
                }
                let (s, end) = spots[k % spots.len()];
                parts[i].1 = [&x[..end], &x[s..end], &x[end..]].concat();
            }
            Edit::Flip(p, at, x) => {
                let i = get(&mut parts, *p);
                let n = parts[i].1.len();
                parts[i].1[at % n] ^= x;
            }
            e => archive_edits.push(e.clone()),
        }
    }
    let mut z = rezip(&parts);
    for e in archive_edits {
        match e {
            Edit::Truncate(f) => z.truncate(z.len() * f as usize / 1000),
            Edit::FlipArchive(at, x) => {
                let n = z.len();
                if n > 0 {
                    z[at % n] ^= x;
                }
            }
            _ => unreachable!(),
        }
    }
    z
}

/// Either an error that names the file, or measurements that hold what the docs promise.
fn check(bytes: &[u8]) -> Result<(), TestCaseError> {
    match read(bytes, "m.xlsx") {
        Err(e) => {
            let s = e.to_string();
            prop_assert!(s.starts_with("m.xlsx: "), "error names no file: {s}");
        }
        Ok(x) => {
            prop_assert!(!x.measurements.is_empty());
            for m in &x.measurements {
                for s in &m.spectra {
                    prop_assert!(s.iter().all(|v| v.is_finite() && *v >= 0.0), "{s:?}");
                }
                for l in &m.lab {
                    prop_assert!(l.l.is_finite() && l.a.is_finite() && l.b.is_finite());
                }
                prop_assert!(!m.name.is_empty());
                match check_colorimetry(m) {
                    Ok(c) => prop_assert_eq!(c.delta_e00.len(), MA_T12_COUNT),
                    Err(e) => {
                        prop_assert!(matches!(e, XlsxError::UnsupportedColorimetry { .. }), "{e}")
                    }
                }
            }
        }
    }
    Ok(())
}

#[test]
fn the_base_reads() {
    let x = read(&apply(&[]), "m.xlsx").unwrap();
    assert_eq!(x.measurements[0].textures.len(), 7);
    assert!(
        check_colorimetry(&x.measurements[0])
            .unwrap()
            .flagged
            .is_empty()
    );
}

proptest! {
    #![proptest_config(crate::test_support::proptest_config())]

    #[test]
    fn a_mutated_export_is_read_or_refused(edits in proptest::collection::vec(edit(), 1..4)) {
        check(&apply(&edits))?;
    }
}
