//! The one typeface every drawn image uses (report figures, sphere previews): DejaVu Sans,
//! embedded from `fonts/` (its licence beside it), so a PNG looks the same on every machine,
//! with no system font looked up.

use std::sync::Once;

use plotters::prelude::*;

pub(crate) static FONT: &[u8] = include_bytes!("fonts/DejaVuSans.ttf");
const FAMILY: &str = "sans-serif";

/// Registers the embedded font with plotters under the family [`font`] asks for; once per
/// process, before the first text is drawn.
pub(crate) fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        if plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_err() {
            panic!("the embedded DejaVu Sans does not load");
        }
    });
}

/// Black text in the embedded font, `size` pixels.
pub(crate) fn font(size: u32) -> TextStyle<'static> {
    (FAMILY, size).into_font().color(&BLACK)
}
