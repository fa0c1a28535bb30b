//! The spectral grid every spectrum in brdfd lives on (SCIENCE.md §1): 31 bands,
//! 400–700 nm every 10 nm, the X-Rite MA-T12's native grid.

/// Number of spectral bands.
pub const BANDS: usize = 31;
/// First band centre, nm.
pub const FIRST_NM: u32 = 400;
/// Band spacing, nm.
pub const STEP_NM: u32 = 10;
/// Last band centre, nm.
pub const LAST_NM: u32 = FIRST_NM + STEP_NM * (BANDS as u32 - 1);

/// One value per band, band `i` at `FIRST_NM + i * STEP_NM` nm. Units depend on the use:
/// reflectance factor (0–1), BRDF (sr⁻¹), or a device's raw value.
pub type Spectrum = [f64; BANDS];

/// The band centres in nm, in order.
pub const fn wavelengths_nm() -> [u32; BANDS] {
    let mut out = [0u32; BANDS];
    let mut i = 0;
    while i < BANDS {
        out[i] = FIRST_NM + STEP_NM * i as u32;
        i += 1;
    }
    out
}

/// A spectrum with the same value in every band.
pub const fn flat(value: f64) -> Spectrum {
    [value; BANDS]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_runs_400_to_700_every_10() {
        let w = wavelengths_nm();
        assert_eq!(w[0], 400);
        assert_eq!(w[BANDS - 1], 700);
        assert_eq!(LAST_NM, 700);
        assert!(w.windows(2).all(|p| p[1] - p[0] == 10));
    }
}
