//! The import budget through the CLI door: attack files made from a committed real export,
//! each read by the `brdfd` binary (`import-format`) under an address-space limit, refused with
//! a message naming the limit and the part of the file, within the memory the budget promises
//! (peak resident memory of the child at most 256 MiB above a genuine export's).

use std::io::{Cursor, Read, Write};
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::Command;

const REAL: &str = "tests/data/real-mat12/PAR_EW_RL_NG_3.xlsx";
const SPECTRAL: &str = "xl/worksheets/sheet3.xml";

fn unzip(bytes: &[u8]) -> Vec<(String, Vec<u8>)> {
    let mut z = zip::ZipArchive::new(Cursor::new(bytes)).unwrap();
    (0..z.len())
        .map(|i| {
            let mut f = z.by_index(i).unwrap();
            let mut b = Vec::new();
            f.read_to_end(&mut b).unwrap();
            (f.name().unwrap().into_owned(), b)
        })
        .collect()
}

fn rezip(parts: &[(String, Vec<u8>)]) -> Vec<u8> {
    let mut w = zip::ZipWriter::new(Cursor::new(Vec::new()));
    let opts = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    for (name, b) in parts {
        w.start_file(name.as_str(), opts).unwrap();
        w.write_all(b).unwrap();
    }
    w.finish().unwrap().into_inner()
}

/// The real export with `edit` applied to the text of `part`.
fn edited(part: &str, edit: impl FnOnce(String) -> String) -> Vec<u8> {
    let real = std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join(REAL)).unwrap();
    let mut parts = unzip(&real);
    let p = parts.iter_mut().find(|(n, _)| n == part).unwrap();
    let text = String::from_utf8(std::mem::take(&mut p.1)).unwrap();
    let new = edit(text.clone());
    assert_ne!(new, text);
    p.1 = new.into_bytes();
    rezip(&parts)
}

/// Runs `brdfd import-format FILE` under a 2 GiB address-space limit: (exit code, stderr,
/// peak resident memory in KiB).
fn import_format(file: &Path, out: &Path) -> (Option<i32>, String, i64) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_brdfd"));
    cmd.args(["import-format", file.to_str().unwrap(), "--out"])
        .arg(out)
        .env_remove("BRDFD_CONFIG");
    // SAFETY: setrlimit is async-signal-safe; nothing else runs between fork and exec.
    unsafe {
        cmd.pre_exec(|| {
            let limit = libc::rlimit {
                rlim_cur: 2 << 30,
                rlim_max: 2 << 30,
            };
            if libc::setrlimit(libc::RLIMIT_AS, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let before = children_peak_kib();
    let o = cmd.output().unwrap();
    let after = children_peak_kib();
    assert!(
        o.status.signal().is_none(),
        "{}: killed by signal {:?} (an allocation beyond the limit aborts)\n{}",
        file.display(),
        o.status.signal(),
        String::from_utf8_lossy(&o.stderr)
    );
    // ru_maxrss of the children is the largest child's peak: one child at a time here.
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
        after.max(before),
    )
}

fn children_peak_kib() -> i64 {
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: a valid pointer to a zeroed rusage.
    assert_eq!(unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut u) }, 0);
    u.ru_maxrss
}

#[test]
fn attack_files_are_refused_by_the_cli_within_the_budget() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, bytes: &[u8]| -> PathBuf {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let out = dir.path().join("out");

    // A genuine export: the baseline.
    let real = Path::new(env!("CARGO_MANIFEST_DIR")).join(REAL);
    let (code, err, baseline) = import_format(&real, &out);
    assert_eq!(code, Some(0), "{err}");

    let far = edited(SPECTRAL, |x| {
        x.replace(
            "</sheetData>",
            r#"<row r="1048576"><c r="XFD1048576"><v>1</v></c></row></sheetData>"#,
        )
    });
    let long_name = edited("xl/sharedStrings.xml", |x| {
        x.replace(
            "<t>PAR_EW_RL_NG_3</t>",
            &format!("<t>{}</t>", "N".repeat(6 << 20)),
        )
    });
    let huge = edited(SPECTRAL, |x| {
        let at = x.find("<c r=\"D7\"").unwrap();
        let v = at + x[at..].find("<v>").unwrap() + 3;
        let e = v + x[v..].find("</v>").unwrap();
        format!("{}1e308{}", &x[..v], &x[e..])
    });
    let control = edited("xl/sharedStrings.xml", |x| {
        x.replace("<t>PAR_EW_RL_NG_3</t>", "<t>PAR\tNG_3</t>")
    });
    let cases: [(&str, Vec<u8>, &[&str]); 4] = [
        (
            "far.xlsx",
            far,
            &[
                "far.xlsx: sheet \"Spectral Data\"",
                "to cell XFD1048576",
                "\"sheet cells\"",
                "ingest.max_sheet_cells",
            ],
        ),
        (
            "long.xlsx",
            long_name,
            &["part \"xl/sharedStrings.xml\"", "beyond the import limit"],
        ),
        (
            "huge.xlsx",
            huge,
            &["sheet \"Spectral Data\", cell D7: 1e308 is beyond any reflectance factor"],
        ),
        (
            "control.xlsx",
            control,
            &["control.xlsx: the sample name", "control character U+0009"],
        ),
    ];
    for (name, bytes, want) in cases {
        assert!(bytes.len() < 8 << 20, "{name}: {} bytes", bytes.len());
        let p = write(name, &bytes);
        let (code, err, peak) = import_format(&p, &out);
        assert_eq!(code, Some(1), "{name}: {err}");
        for w in want {
            assert!(err.contains(w), "{name}: {err:?} lacks {w:?}");
        }
        assert!(
            peak - baseline < 256 << 10,
            "{name}: peak {peak} KiB against {baseline} KiB for a genuine export"
        );
    }
}
