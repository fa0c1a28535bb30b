//! The texture images of the `Texture Images` sheet: the drawing's anchors ("images per
//! file"), each image part read once however many anchors point at it ("image size"), the
//! images' bytes together ("images size per file") and each PNG's declared width × height
//! ("image pixels"), checked before anything is kept; and the heading each image is given to.

use super::archive::{Parts, REL_NS, Workbook};
use super::cells::{Sheet, cell_name};
use super::{TextureImage, XlsxError};
use crate::formats::budget::Limit;

impl Parts<'_, '_> {
    /// The `Texture Images` sheet's images with the heading above each (see the module docs).
    pub(super) fn textures(
        &mut self,
        sheet: &Sheet,
        workbook: &Workbook,
    ) -> Result<Vec<(Option<String>, TextureImage)>, XlsxError> {
        let me = self;
        let Some(sheet_part) = workbook.sheets.get(sheet.name) else {
            return Err(me.not_xlsx(format!("sheet \"{}\" has no part", sheet.name)));
        };
        let drawing = me
            .relationships(sheet_part)?
            .into_values()
            .find(|(typ, _)| typ.ends_with("/drawing"));
        let Some((_, drawing)) = drawing else {
            return Ok(Vec::new());
        };
        let rels = me.relationships(&drawing)?;
        // (row, col, relationship id) of each picture, in document order.
        let anchors: Vec<(u32, u32, Option<String>)> = me
            .with_xml(&drawing, |doc| {
                doc.descendants()
                    .filter(|n| n.has_tag_name("oneCellAnchor") || n.has_tag_name("twoCellAnchor"))
                    .filter_map(|a| {
                        let pic = a.children().find(|c| c.has_tag_name("pic"))?;
                        let from = a.children().find(|c| c.has_tag_name("from"))?;
                        let num = |tag: &str| -> Option<u32> {
                            from.children()
                                .find(|c| c.has_tag_name(tag))?
                                .text()?
                                .trim()
                                .parse()
                                .ok()
                        };
                        let embed = pic
                            .descendants()
                            .find(|c| c.has_tag_name("blip"))
                            .and_then(|b| b.attribute((REL_NS, "embed")))
                            .map(str::to_string);
                        Some((num("row")?, num("col")?, embed))
                    })
                    .collect()
            })?
            .ok_or_else(|| me.not_xlsx(format!("no part \"{drawing}\"")))?;

        let images = anchors.len() as u64;
        let what = format!("sheet \"{}\" ({images} image anchors)", sheet.name);
        me.budget.check(Limit::Images, me.file, &what, images)?;

        // Headings: rows with column A empty and text in column B, found in one pass over the
        // sheet (whose rows the budget bounds); an anchor's is the last one above it.
        let label_col = 0;
        let headings: Vec<(u32, String)> = sheet
            .rows()
            .filter(|&r| sheet.text(r, label_col).is_none())
            .filter_map(|r| sheet.text(r, label_col + 1).map(|h| (r, h)))
            .collect();
        let mut out = Vec::with_capacity(anchors.len());
        let mut total = 0u64;
        for (row, col, embed) in anchors {
            let anchor = cell_name(row, col);
            let geometry = sheet.text(row, label_col).ok_or_else(|| {
                sheet.cell_error(
                    row,
                    label_col,
                    format!(
                        "empty, but an image is anchored in {anchor}; a geometry name expected"
                    ),
                )
            })?;
            let above = headings.partition_point(|(r, _)| *r < row);
            let heading = above.checked_sub(1).map(|i| headings[i].1.clone());
            let image = embed
                .as_ref()
                .and_then(|id| rels.get(id))
                .map(|(_, target)| target.clone())
                .ok_or_else(|| {
                    sheet.cell_error(row, col, "the image anchored here has no image part")
                })?;
            let png = me.image(&image)?.ok_or_else(|| {
                sheet.cell_error(row, col, format!("the image part \"{image}\" is missing"))
            })?;
            total += png.len() as u64;
            me.budget.check(
                Limit::ImagesBytes,
                me.file,
                &format!(
                    "sheet \"{}\", the images up to the one anchored in {anchor}",
                    sheet.name
                ),
                total,
            )?;
            let Some((width, height)) = png_size(&png) else {
                return Err(sheet.cell_error(
                    row,
                    col,
                    format!("the image anchored here (\"{image}\") is not a PNG"),
                ));
            };
            me.budget.check(
                Limit::ImagePixels,
                me.file,
                &format!("image \"{image}\" of {width} × {height} pixels, anchored in {anchor}"),
                u64::from(width) * u64::from(height),
            )?;
            out.push((
                heading,
                TextureImage {
                    geometry,
                    anchor,
                    png: png.as_ref().clone(),
                },
            ));
        }
        Ok(out)
    }

    /// An image part, read once (within the image-size allowance) however many anchors point
    /// at it; `None` when the archive has no such part.
    pub(super) fn image(&mut self, part: &str) -> Result<Option<std::rc::Rc<Vec<u8>>>, XlsxError> {
        if let Some(png) = self.images.get(part) {
            return Ok(Some(png.clone()));
        }
        let Some(png) = self.bytes(part, Limit::ImageBytes)? else {
            return Ok(None);
        };
        let png = std::rc::Rc::new(png);
        self.images.insert(part.to_string(), png.clone());
        Ok(Some(png))
    }
}

/// A PNG's width and height as its IHDR chunk declares them; `None` when `png` is no PNG.
pub(super) fn png_size(png: &[u8]) -> Option<(u32, u32)> {
    if !png.starts_with(b"\x89PNG\r\n\x1a\n") || png.get(12..16)? != b"IHDR" {
        return None;
    }
    let be = |at: usize| -> Option<u32> {
        Some(u32::from_be_bytes(png.get(at..at + 4)?.try_into().ok()?))
    };
    Some((be(16)?, be(20)?))
}

#[cfg(test)]
mod tests {
    use crate::formats::xrite_xlsx::tests::{
        REGULAR, bytes, edited, err, path, read, read_file, rezip, unzip,
    };

    use crate::formats::budget::Budget;

    #[test]
    fn each_image_is_the_one_anchored_beside_its_geometry() {
        // In the padded file the drawing's relationships are shuffled: the anchor in row 2
        // (15as-45) embeds rId1, which is image3.png, and row 8 (15d) image7.png.
        let f = "PAR_NB_NP_CC_0.xlsx";
        let parts = unzip(&bytes(f));
        let media = |n: &str| &parts.iter().find(|(p, _)| p == n).unwrap().1;
        let m = &read_file(&path(f)).unwrap().measurements[0];
        assert_eq!(m.textures[0].geometry, "15as-45");
        assert_eq!(&m.textures[0].png, media("xl/media/image3.png"));
        assert_eq!(&m.textures[3].png, media("xl/media/image2.png"));
        assert_eq!(&m.textures[6].png, media("xl/media/image7.png"));
    }

    #[test]
    fn images_are_read_once_and_bounded_in_number_size_and_pixels() {
        const DRAWING: &str = "xl/drawings/drawing1.xml";
        // Every anchor points at the first anchor's image: read once, seven copies kept.
        let first_embed = |x: &str| {
            let at = x.find("r:embed=\"").unwrap() + 9;
            x[at..at + x[at..].find('"').unwrap()].to_string()
        };
        let b = edited(REGULAR, DRAWING, |x| {
            let id = first_embed(&x);
            let mut out = x.clone();
            for i in 1..=7 {
                out = out.replace(&format!("r:embed=\"rId{i}\""), &format!("r:embed=\"{id}\""));
            }
            out
        });
        let x = read(&b, "x.xlsx").unwrap();
        let t = &x.measurements[0].textures;
        assert!(t.len() == 7 && t.iter().all(|i| i.png == t[0].png));
        // 65 anchors.
        let b = edited(REGULAR, DRAWING, |x| {
            let s = x
                .find("<xdr:twoCellAnchor")
                .or_else(|| x.find("<xdr:oneCellAnchor"))
                .unwrap();
            let close = if x[s..].starts_with("<xdr:two") {
                "</xdr:twoCellAnchor>"
            } else {
                "</xdr:oneCellAnchor>"
            };
            let e = s + x[s..].find(close).unwrap() + close.len();
            format!("{}{}{}", &x[..e], x[s..e].repeat(58), &x[e..])
        });
        let e = err(&b);
        assert!(
            e.contains("(65 image anchors): 65 images is beyond")
                && e.contains("ingest.max_images"),
            "{e}"
        );
        // A PNG that declares 100,000 × 100,000 pixels.
        let mut parts = unzip(&bytes(REGULAR));
        let png = &mut parts
            .iter_mut()
            .find(|(n, _)| n == "xl/media/image1.png")
            .unwrap()
            .1;
        png[16..24].copy_from_slice(&[0, 1, 0x86, 0xa0, 0, 1, 0x86, 0xa0]);
        let e = err(&rezip(&parts));
        assert!(
            e.contains("of 100000 × 100000 pixels") && e.contains("ingest.max_image_megapixels"),
            "{e}"
        );
        // The images' bytes together, and each part's.
        let small = Budget {
            max_images_bytes: 1 << 20,
            ..Budget::default()
        };
        let e = crate::formats::xrite_xlsx::read(&bytes(REGULAR), "x.xlsx", &small)
            .unwrap_err()
            .to_string();
        assert!(e.contains("\"images size per file\""), "{e}");
        let small = Budget {
            max_image_bytes: 100_000,
            ..Budget::default()
        };
        let e = crate::formats::xrite_xlsx::read(&bytes(REGULAR), "x.xlsx", &small)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("\"image size\" of 100000 bytes") && e.contains("xl/media/"),
            "{e}"
        );
    }
}
