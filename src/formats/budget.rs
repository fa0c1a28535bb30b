//! The import budget: every limit a reader of an imported file works within (the `.xlsx`
//! reader's sheets, shared strings and images, the records of CGATS, CxF3 and scan files), its
//! name, its default, its `[ingest]` key where a lab may need another value, and the refusal
//! that names the limit and the part of the file that broke it.
//!
//! Each limit is checked where its data is read, before anything of that size is allocated:
//! a file that claims more than the budget is refused, never half-read. The defaults keep an
//! import of any file within about 256 MiB of memory above the idle process and a few seconds:
//! the real exports hold a few hundred rows under 40 columns, seven 480 × 360 PNGs of about
//! 300 kB and a few shared strings of a few dozen characters, so every default is one to two
//! orders of magnitude above what a genuine file needs. Every door (`brdfd import-format`,
//! `brdfd import`, the watch folder, `POST /scans/import`) reads with the same budget.

/// The largest request body `POST /scans/import` takes (the file-size allowance then applies to
/// the file it carries): above the largest `ingest.max_file_mib` a lab is expected to set.
pub const MAX_UPLOAD_BYTES: u64 = 64 << 20;

/// One limit of the budget.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Limit {
    /// Bytes of one imported file.
    FileBytes,
    /// Uncompressed bytes of one part (member) of an `.xlsx` archive.
    PartBytes,
    /// Cells of a sheet's bounding box (first to last row × first to last column), declared
    /// or held: the spreadsheet reader holds the box as a dense grid.
    SheetCells,
    /// Uncompressed bytes of one markup part of an `.xlsx` that the reader holds whole (the
    /// shared strings, the workbook, a drawing, a relationships part).
    MarkupBytes,
    /// Bytes of one shared string (an inline cell text is bounded by its sheet part's size).
    TextBytes,
    /// Entries a shared-strings part declares (`uniqueCount`) or holds.
    SharedStrings,
    /// Texture images (anchors) in one file.
    Images,
    /// Bytes of one texture image.
    ImageBytes,
    /// Bytes of all the texture images of one file together.
    ImagesBytes,
    /// Pixels (width × height, as the PNG's IHDR declares) of one texture image.
    ImagePixels,
    /// Records of one CGATS or CSV file: its lines.
    Records,
}

impl Limit {
    /// The limit's name, as the refusal and GUIDE.md's table write it.
    pub fn name(self) -> &'static str {
        match self {
            Limit::FileBytes => "file size",
            Limit::PartBytes => "archive part size",
            Limit::SheetCells => "sheet cells",
            Limit::MarkupBytes => "markup part size",
            Limit::TextBytes => "text size",
            Limit::SharedStrings => "shared strings",
            Limit::Images => "images per file",
            Limit::ImageBytes => "image size",
            Limit::ImagesBytes => "images size per file",
            Limit::ImagePixels => "image pixels",
            Limit::Records => "records per file",
        }
    }

    /// The `[ingest]` key that sets it, when a lab may need another value.
    pub fn key(self) -> Option<&'static str> {
        match self {
            Limit::FileBytes => Some("ingest.max_file_mib"),
            Limit::SheetCells => Some("ingest.max_sheet_cells"),
            Limit::Images => Some("ingest.max_images"),
            Limit::ImageBytes => Some("ingest.max_image_mib"),
            Limit::ImagePixels => Some("ingest.max_image_megapixels"),
            Limit::Records => Some("ingest.max_records"),
            _ => None,
        }
    }

    /// What the limit counts.
    fn unit(self) -> &'static str {
        match self {
            Limit::FileBytes
            | Limit::PartBytes
            | Limit::MarkupBytes
            | Limit::TextBytes
            | Limit::ImageBytes
            | Limit::ImagesBytes => "bytes",
            Limit::SheetCells => "cells",
            Limit::SharedStrings => "strings",
            Limit::Images => "images",
            Limit::ImagePixels => "pixels",
            Limit::Records => "records",
        }
    }
}

/// A file refused because a part of it is beyond the budget.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "{file}: {part}: {found} {unit} is beyond the import limit \"{name}\" of {allowed} {unit}; {fix}",
    unit = limit.unit(),
    name = limit.name(),
    fix = match limit.key() {
        Some(key) => format!(
            "if the file is a genuine export, raise `{key}` in the configuration, else it is not \
             a file brdfd reads"
        ),
        None => "the file is not an export brdfd reads".to_string(),
    }
)]
pub struct OverBudget {
    /// The file, as named in every error of its reader.
    pub file: String,
    /// The part of the file that broke the limit (a sheet, an archive part, a cell, a line).
    pub part: String,
    pub limit: Limit,
    /// What the file holds or claims.
    pub found: u64,
    /// What the budget allows.
    pub allowed: u64,
}

/// The limits of one import (see the module docs); `Default` is the shipped budget.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Budget {
    pub max_file_bytes: u64,
    pub max_part_bytes: u64,
    pub max_sheet_cells: u64,
    pub max_markup_bytes: u64,
    pub max_text_bytes: u64,
    pub max_shared_strings: u64,
    pub max_images: u64,
    pub max_image_bytes: u64,
    pub max_images_bytes: u64,
    pub max_image_pixels: u64,
    pub max_records: u64,
}

/// The shipped values (also the defaults of the `[ingest]` keys).
pub mod defaults {
    /// A session's export is a few MiB at most.
    pub const MAX_FILE_MIB: u64 = 32;
    /// The largest part of a real export is a 340 kB PNG.
    pub const MAX_PART_MIB: u64 = 16;
    /// A real export's sheet: up to 1,000 rows (padded) × 34 columns = 34,000 cells. The
    /// reader holds a sheet as about 72 bytes a cell (its cells, then its dense grid): 250,000
    /// cells are 18 MiB a sheet.
    pub const MAX_SHEET_CELLS: u64 = 250_000;
    /// A real export's shared strings are about 1.4 kB, its drawing a few kB.
    pub const MAX_MARKUP_KIB: u64 = 1024;
    /// A name, a date, a geometry: a few dozen characters.
    pub const MAX_TEXT_BYTES: u64 = 4096;
    /// A real export has a few dozen.
    pub const MAX_SHARED_STRINGS: u64 = 50_000;
    /// Seven images per measurement; a session file of nine measurements has 63.
    pub const MAX_IMAGES: u64 = 64;
    /// The real images are 480 × 360 PNGs of 150–340 kB.
    pub const MAX_IMAGE_MIB: u64 = 4;
    /// All of a file's images together.
    pub const MAX_IMAGES_MIB: u64 = 48;
    /// 480 × 360 is 0.17 megapixels.
    pub const MAX_IMAGE_MEGAPIXELS: u64 = 16;
    /// A session's export holds a few hundred rows (14 per sample).
    pub const MAX_RECORDS: u64 = 20_000;
}

impl Default for Budget {
    fn default() -> Self {
        use defaults::*;
        Budget {
            max_file_bytes: MAX_FILE_MIB << 20,
            max_part_bytes: MAX_PART_MIB << 20,
            max_sheet_cells: MAX_SHEET_CELLS,
            max_markup_bytes: MAX_MARKUP_KIB << 10,
            max_text_bytes: MAX_TEXT_BYTES,
            max_shared_strings: MAX_SHARED_STRINGS,
            max_images: MAX_IMAGES,
            max_image_bytes: MAX_IMAGE_MIB << 20,
            max_images_bytes: MAX_IMAGES_MIB << 20,
            max_image_pixels: MAX_IMAGE_MEGAPIXELS * 1_000_000,
            max_records: MAX_RECORDS,
        }
    }
}

impl Budget {
    /// The allowance of `limit`.
    pub fn allowed(&self, limit: Limit) -> u64 {
        match limit {
            Limit::FileBytes => self.max_file_bytes,
            Limit::PartBytes => self.max_part_bytes,
            Limit::SheetCells => self.max_sheet_cells,
            Limit::MarkupBytes => self.max_markup_bytes,
            Limit::TextBytes => self.max_text_bytes,
            Limit::SharedStrings => self.max_shared_strings,
            Limit::Images => self.max_images,
            Limit::ImageBytes => self.max_image_bytes,
            Limit::ImagesBytes => self.max_images_bytes,
            Limit::ImagePixels => self.max_image_pixels,
            Limit::Records => self.max_records,
        }
    }

    /// The one check of every limit: `found` (what `part` of `file` holds or claims) against
    /// the allowance of `limit`.
    pub fn check(
        &self,
        limit: Limit,
        file: &str,
        part: &str,
        found: u64,
    ) -> Result<(), OverBudget> {
        let allowed = self.allowed(limit);
        if found <= allowed {
            return Ok(());
        }
        Err(OverBudget {
            file: file.to_string(),
            part: part.to_string(),
            limit,
            found,
            allowed,
        })
    }

    /// Reads at most the file-size allowance of `path` (one byte more, to tell), refusing a
    /// larger file unread: the one way a reader takes a file's bytes from disk.
    pub fn read_file(&self, path: &std::path::Path, file: &str) -> Result<Vec<u8>, ReadError> {
        use std::io::Read;
        let f = std::fs::File::open(path)?;
        let size = f.metadata()?.len();
        self.check(Limit::FileBytes, file, "the whole file", size)?;
        let mut bytes = Vec::with_capacity(size as usize);
        // The file may grow while read: never take more than the allowance plus one byte.
        f.take(self.max_file_bytes + 1).read_to_end(&mut bytes)?;
        self.check(Limit::FileBytes, file, "the whole file", bytes.len() as u64)?;
        Ok(bytes)
    }
}

/// Why [`Budget::read_file`] read nothing.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error(transparent)]
    Io(#[from] std::io::Error),
    #[error(transparent)]
    Over(#[from] OverBudget),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_refusal_names_the_file_the_part_the_limit_and_its_key() {
        let b = Budget::default();
        assert!(b.check(Limit::Images, "x.xlsx", "drawing", 64).is_ok());
        let e = b.check(Limit::Images, "x.xlsx", "sheet \"Texture Images\"", 65);
        assert_eq!(
            e.unwrap_err().to_string(),
            "x.xlsx: sheet \"Texture Images\": 65 images is beyond the import limit \"images per \
             file\" of 64 images; if the file is a genuine export, raise `ingest.max_images` in \
             the configuration, else it is not a file brdfd reads"
        );
        let e = b.check(Limit::TextBytes, "x.xlsx", "shared string 3", 5000);
        assert!(
            e.unwrap_err()
                .to_string()
                .ends_with("of 4096 bytes; the file is not an export brdfd reads")
        );
    }

    #[test]
    fn a_file_beyond_the_allowance_is_refused_unread() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("big.txt");
        std::fs::File::create(&p).unwrap().set_len(2 << 20).unwrap();
        let b = Budget {
            max_file_bytes: 1 << 20,
            ..Budget::default()
        };
        let e = b.read_file(&p, "big.txt").unwrap_err().to_string();
        assert!(
            e.starts_with("big.txt: the whole file: 2097152 bytes is beyond"),
            "{e}"
        );
        assert_eq!(
            Budget::default().read_file(&p, "big.txt").unwrap().len(),
            2 << 20
        );
    }
}
