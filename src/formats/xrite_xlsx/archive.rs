//! The `.xlsx` archive's parts that calamine does not read: each part read within its size
//! limit ("archive part size", "markup part size"), the relationships between parts, and the
//! workbook part's sheet list and date system.

use std::collections::BTreeMap;
use std::io::{Cursor, Read};

use super::XlsxError;
use crate::formats::budget::{Budget, Limit};

/// What the workbook part says that calamine does not give.
pub(super) struct Workbook {
    pub(super) date1904: bool,
    /// Sheet name → its part's path in the archive.
    pub(super) sheets: BTreeMap<String, String>,
}

/// The archive, for the parts calamine does not read.
pub(super) struct Parts<'a, 'b> {
    pub(super) file: &'a str,
    pub(super) zip: &'a mut zip::ZipArchive<Cursor<&'b [u8]>>,
    pub(super) budget: &'a Budget,
    /// Each image part as read, once however many anchors point at it.
    pub(super) images: BTreeMap<String, std::rc::Rc<Vec<u8>>>,
}

pub(super) const REL_NS: &str =
    "http://schemas.openxmlformats.org/officeDocument/2006/relationships";

impl Parts<'_, '_> {
    pub(super) fn not_xlsx(&self, message: String) -> XlsxError {
        XlsxError::NotXlsx {
            file: self.file.to_string(),
            message,
        }
    }

    /// The part's bytes, read up to `limit`'s allowance (a part that unpacks to more is
    /// refused, whatever size the archive declares); `None` when the archive has no such part.
    pub(super) fn bytes(&mut self, part: &str, limit: Limit) -> Result<Option<Vec<u8>>, XlsxError> {
        let file = self.file;
        let not_xlsx = |e: &dyn std::fmt::Display| XlsxError::NotXlsx {
            file: file.to_string(),
            message: format!("part \"{part}\": {e}"),
        };
        let allowed = self.budget.allowed(limit);
        let mut f = match self.zip.by_name(part) {
            Ok(f) => f,
            Err(zip::result::ZipError::FileNotFound) => return Ok(None),
            Err(e) => return Err(not_xlsx(&e)),
        };
        self.budget
            .check(limit, file, &format!("part \"{part}\""), f.size())?;
        let mut out = Vec::with_capacity(f.size() as usize);
        if let Err(e) = (&mut f).take(allowed + 1).read_to_end(&mut out) {
            return Err(not_xlsx(&e));
        }
        drop(f);
        self.budget
            .check(limit, file, &format!("part \"{part}\""), out.len() as u64)?;
        Ok(Some(out))
    }

    pub(super) fn text(&mut self, part: &str) -> Result<Option<String>, XlsxError> {
        match self.bytes(part, Limit::MarkupBytes)? {
            None => Ok(None),
            Some(b) => String::from_utf8(b)
                .map(Some)
                .map_err(|_| self.not_xlsx(format!("part \"{part}\" is not UTF-8 XML"))),
        }
    }

    pub(super) fn with_xml<T>(
        &mut self,
        part: &str,
        f: impl FnOnce(&roxmltree::Document) -> T,
    ) -> Result<Option<T>, XlsxError> {
        let Some(text) = self.text(part)? else {
            return Ok(None);
        };
        let doc = roxmltree::Document::parse(&text)
            .map_err(|e| self.not_xlsx(format!("part \"{part}\": {e}")))?;
        Ok(Some(f(&doc)))
    }

    /// The relationships of `part`: id → (type, target part path).
    pub(super) fn relationships(
        &mut self,
        part: &str,
    ) -> Result<BTreeMap<String, (String, String)>, XlsxError> {
        let (dir, file) = part.rsplit_once('/').unwrap_or(("", part));
        let rels = if dir.is_empty() {
            format!("_rels/{file}.rels")
        } else {
            format!("{dir}/_rels/{file}.rels")
        };
        let dir = dir.to_string();
        Ok(self
            .with_xml(&rels, |doc| {
                doc.descendants()
                    .filter(|n| n.has_tag_name("Relationship"))
                    .filter_map(|n| {
                        let id = n.attribute("Id")?;
                        let target = n.attribute("Target")?;
                        let typ = n.attribute("Type").unwrap_or_default();
                        Some((
                            id.to_string(),
                            (typ.to_string(), resolve_part(&dir, target)),
                        ))
                    })
                    .collect()
            })?
            .unwrap_or_default())
    }

    pub(super) fn workbook(&mut self) -> Result<Workbook, XlsxError> {
        let part = "xl/workbook.xml";
        let rels = self.relationships(part)?;
        let parsed = self
            .with_xml(part, |doc| {
                let date1904 = doc
                    .descendants()
                    .find(|n| n.has_tag_name("workbookPr"))
                    .and_then(|n| n.attribute("date1904"))
                    .is_some_and(|v| v == "1" || v.eq_ignore_ascii_case("true"));
                let sheets: Vec<(String, String)> = doc
                    .descendants()
                    .filter(|n| n.has_tag_name("sheet"))
                    .filter_map(|n| {
                        Some((
                            n.attribute("name")?.to_string(),
                            n.attribute((REL_NS, "id"))?.to_string(),
                        ))
                    })
                    .collect();
                (date1904, sheets)
            })?
            .ok_or_else(|| self.not_xlsx(format!("no part \"{part}\"")))?;
        let sheets = parsed
            .1
            .into_iter()
            .filter_map(|(name, id)| rels.get(&id).map(|(_, target)| (name, target.clone())))
            .collect();
        Ok(Workbook {
            date1904: parsed.0,
            sheets,
        })
    }
}

/// The part a relationship target names, from the directory of the part it belongs to.
pub(super) fn resolve_part(dir: &str, target: &str) -> String {
    let mut parts: Vec<&str> = if let Some(abs) = target.strip_prefix('/') {
        return normalise(abs.split('/'));
    } else {
        dir.split('/').filter(|p| !p.is_empty()).collect()
    };
    parts.extend(target.split('/'));
    normalise(parts.into_iter())
}

pub(super) fn normalise<'a>(parts: impl Iterator<Item = &'a str>) -> String {
    let mut out: Vec<&str> = Vec::new();
    for p in parts {
        match p {
            "" | "." => {}
            ".." => {
                out.pop();
            }
            p => out.push(p),
        }
    }
    out.join("/")
}
