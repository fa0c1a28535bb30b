//! Property tests: mutated copies of a real export (cell values, deleted and duplicated rows,
//! flipped bytes, a cut archive, and the structure the import budget bounds: the sheets'
//! declared dimension and far cells, the image anchors' positions and number, the shared
//! strings' length and declared count) are read or refused, never a panic.

#![cfg(test)]

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

/// The sheet parts of [`PARTS`], by index; its shared strings and drawing.
const SHEETS: [usize; 3] = [0, 1, 2];
const STRINGS: usize = 3;
const DRAWING: usize = 5;

/// What a mutated dimension says.
const REFS: [&str; 8] = [
    "A1",
    "A1:AH40",
    "A1:XFD1048576",
    "B2:A1",
    "",
    "ZZZZ99999999999",
    "A0:$A$0",
    "1:4",
];

/// What a mutated anchor position or shared-string count says.
const NUMBERS: [&str; 8] = ["0", "1", "7", "1048575", "4294967295", "-1", "x", ""];

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
    /// Set the declared dimension (`<dimension ref>`) of a sheet part.
    Dimension(usize, String),
    /// Add a cell at (1-based row, column) to a sheet part.
    Cell(usize, u64, u64),
    /// Move the k-th image anchor of the drawing to (0-based row, column), as written.
    Anchor(usize, String, String),
    /// Repeat the k-th image anchor of the drawing n more times.
    Anchors(usize, usize),
    /// Make the k-th shared string n bytes long.
    LongString(usize, usize),
    /// Set the shared strings' declared count.
    StringCount(String),
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
        1 => (proptest::sample::select(&SHEETS[..]), proptest::sample::select(&REFS[..]))
            .prop_map(|(p, r)| Edit::Dimension(p, r.to_string())),
        1 => (
            proptest::sample::select(&SHEETS[..]),
            prop_oneof![1..=2_000u64, 1..=1_048_576u64],
            prop_oneof![1..=40u64, 1..=16_384u64],
        )
            .prop_map(|(p, r, c)| Edit::Cell(p, r, c)),
        1 => (
            any::<usize>(),
            proptest::sample::select(&NUMBERS[..]),
            proptest::sample::select(&NUMBERS[..]),
        )
            .prop_map(|(k, r, c)| Edit::Anchor(k, r.to_string(), c.to_string())),
        1 => (any::<usize>(), prop_oneof![1..=10usize, 50..=100usize])
            .prop_map(|(k, n)| Edit::Anchors(k, n)),
        1 => (any::<usize>(), prop_oneof![0..=10usize, 4_090..=4_100usize, 5_000..=20_000usize])
            .prop_map(|(k, n)| Edit::LongString(k, n)),
        1 => proptest::sample::select(&NUMBERS[..])
            .prop_map(|n| Edit::StringCount(n.to_string())),
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
            Edit::Dimension(p, r) => {
                let i = get(&mut parts, *p);
                let x = &parts[i].1;
                let Some(&(s, end)) = elements(x, b"<dimension ", b"/>").first() else {
                    continue;
                };
                let new = format!("<dimension ref=\"{r}\"/>");
                parts[i].1 = [&x[..s], new.as_bytes(), &x[end..]].concat();
            }
            Edit::Cell(p, r, c) => {
                let i = get(&mut parts, *p);
                let x = &parts[i].1;
                let Some(at) = find(x, b"</sheetData>") else {
                    continue;
                };
                let cell = format!(
                    "<row r=\"{r}\"><c r=\"{}\"><v>1</v></c></row>",
                    super::cells::cell_name_u64(*r, *c)
                );
                parts[i].1 = [&x[..at], cell.as_bytes(), &x[at..]].concat();
            }
            Edit::Anchor(k, row, col) => {
                let i = get(&mut parts, DRAWING);
                let x = &parts[i].1;
                let spots = elements(x, b"<xdr:from>", b"</xdr:from>");
                if spots.is_empty() {
                    continue;
                }
                let (s, end) = spots[k % spots.len()];
                let from = format!(
                    "<xdr:from><xdr:col>{col}</xdr:col><xdr:colOff>0</xdr:colOff>\
                     <xdr:row>{row}</xdr:row><xdr:rowOff>0</xdr:rowOff></xdr:from>"
                );
                parts[i].1 = [&x[..s], from.as_bytes(), &x[end..]].concat();
            }
            Edit::Anchors(k, n) => {
                let i = get(&mut parts, DRAWING);
                let x = &parts[i].1;
                let spots = elements(x, b"<xdr:oneCellAnchor>", b"</xdr:oneCellAnchor>");
                if spots.is_empty() {
                    continue;
                }
                let (s, end) = spots[k % spots.len()];
                parts[i].1 = [&x[..end], &x[s..end].repeat(*n), &x[end..]].concat();
            }
            Edit::LongString(k, n) => {
                let i = get(&mut parts, STRINGS);
                let x = &parts[i].1;
                let spots = elements(x, b"<t>", b"</t>");
                if spots.is_empty() {
                    continue;
                }
                let (s, end) = spots[k % spots.len()];
                let text = "N".repeat(*n);
                parts[i].1 = [&x[..s + 3], text.as_bytes(), &x[end - 4..]].concat();
            }
            Edit::StringCount(n) => {
                let i = get(&mut parts, STRINGS);
                let x = &parts[i].1;
                let Some(at) = find(x, b"uniqueCount=\"").map(|at| at + 13) else {
                    continue;
                };
                let Some(len) = x[at..].iter().position(|&b| b == b'"') else {
                    continue;
                };
                parts[i].1 = [&x[..at], n.as_bytes(), &x[at + len..]].concat();
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

/// Each structural edit is live: on its own it breaks the limit it aims at.
#[test]
fn the_structural_edits_reach_the_limits() {
    let refused = |e: Edit, want: &str| {
        let err = read(&apply(std::slice::from_ref(&e)), "m.xlsx")
            .expect_err(want)
            .to_string();
        assert!(err.contains(want), "{e:?}: {err}");
    };
    refused(
        Edit::Dimension(1, "A1:XFD1048576".into()),
        "declared dimension of 1048576 rows × 16384 columns",
    );
    refused(Edit::Cell(0, 1_048_576, 16_384), "to cell XFD1048576");
    refused(Edit::Anchors(2, 60), "(67 image anchors)");
    refused(
        Edit::Anchor(0, "1048575".into(), "1".into()),
        "cell A1048576: empty, but an image is anchored in B1048576",
    );
    refused(Edit::LongString(3, 5_000), "shared string 3: 5007 bytes");
    refused(
        Edit::StringCount("4294967295".into()),
        "4294967295 strings is beyond",
    );
}

proptest! {
    #![proptest_config(crate::test_support::proptest_config())]

    #[test]
    fn a_mutated_export_is_read_or_refused(edits in proptest::collection::vec(edit(), 1..4)) {
        check(&apply(&edits))?;
    }
}
