//! Measured goniometric BRDFs: the ground truth the handheld estimate is validated against
//! (`brdfd validate`, SCIENCE.md §12.6).
//!
//! Two file formats, each behind a bounded `&[u8]` parser and a writer (the tests generate
//! their own files from known BRDFs):
//! - [`astm`]: ASTM E1392 text files (header keys, `VARS`, one line per direction; spectral or
//!   RGB), evaluated between the measured directions by [`astm::AstmFile::interpolate`].
//! - [`rgl`]: RGL-EPFL tensor files (`.bsdf`; Dupuy & Jakob 2018), spectral or RGB, evaluated
//!   anywhere by the format's own interpolation.
//!
//! [`Measurement`] is either, with the one question [`validate`] asks of both: the BRDF in
//! sr⁻¹ for a pair of directions, as the file gives it ([`Measurement::raw`]: one value per
//! channel), and as a spectrum on brdfd's 31-band grid ([`Measurement::spectrum`]; RGB through
//! [`upsample_rgb`]).

pub mod astm;
pub mod figures;
pub mod rgl;
pub mod validate;

use crate::geometry::Vec3;
use crate::spectral::{Spectrum, wavelengths_nm};

/// A range of angles, degrees: `(first, last, step)`.
pub type Steps = (f64, f64, f64);

/// The largest goniometric file brdfd reads, bytes (the shared RGL files are 0.7 MB).
pub const MAX_FILE_BYTES: usize = 256 << 20;

/// Why a goniometric file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum GonioError {
    /// A field of the file is missing, malformed or out of range; the message says which and
    /// what was expected.
    #[error("{format} file: {field}: {message}")]
    Field {
        format: &'static str,
        field: String,
        message: String,
    },
    /// The file is neither an ASTM E1392 nor an RGL tensor file.
    #[error(
        "not a goniometric BRDF file brdfd reads: expected an RGL tensor file (starting \
         \"tensor_file\") or an ASTM E1392 text file (header keys and a VARS line); check the path"
    )]
    UnknownFormat,
    /// The file is larger than [`MAX_FILE_BYTES`].
    #[error(
        "the file has more than {MAX_FILE_BYTES} bytes; goniometric files are far smaller: check the path"
    )]
    TooLarge,
    /// The file could not be read.
    #[error("reading the file: {0}")]
    Io(#[from] std::io::Error),
}

/// What the values of a file are: one per wavelength, or linear RGB.
#[derive(Debug, Clone, PartialEq)]
pub enum Channels {
    /// One value per wavelength, nm, increasing.
    Spectral(Vec<f64>),
    /// Linear RGB (three values).
    Rgb,
}

impl Channels {
    /// How many values one direction pair has.
    pub fn len(&self) -> usize {
        match self {
            Channels::Spectral(w) => w.len(),
            Channels::Rgb => 3,
        }
    }

    /// Whether there are no channels (never, for a file that was read).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The values of one direction pair as a spectrum on brdfd's grid: linear interpolation
    /// between the file's wavelengths (the end values held beyond them), or [`upsample_rgb`].
    pub fn to_spectrum(&self, raw: &[f64]) -> Spectrum {
        match self {
            Channels::Rgb => upsample_rgb([raw[0], raw[1], raw[2]]),
            Channels::Spectral(w) => {
                let nm = wavelengths_nm();
                std::array::from_fn(|b| interp(w, raw, f64::from(nm[b])))
            }
        }
    }
}

fn interp(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    if x <= xs[0] {
        return ys[0];
    }
    let n = xs.len();
    if x >= xs[n - 1] {
        return ys[n - 1];
    }
    let k = xs.partition_point(|&v| v <= x).clamp(1, n - 1);
    let (x0, x1) = (xs[k - 1], xs[k]);
    let t = (x - x0) / (x1 - x0);
    ys[k - 1] * (1.0 - t) + ys[k] * t
}

/// The spectral upsampling of a linear-RGB value: three abutting boxes, blue 400–490 nm,
/// green 500–590 nm, red 600–700 nm (`b, g, r` in those bands). White (1, 1, 1) is the flat
/// spectrum 1 and grey stays grey, so lightness and neutrality survive; hue is approximate.
/// Measured and predicted values go through the same upsampling (SCIENCE.md §12.6), so what it
/// does to hue it does to both.
pub fn upsample_rgb(rgb: [f64; 3]) -> Spectrum {
    let nm = wavelengths_nm();
    std::array::from_fn(|b| match nm[b] {
        ..=490 => rgb[2],
        491..=590 => rgb[1],
        _ => rgb[0],
    })
}

/// The name of the upsampling [`upsample_rgb`] implements, as reports write it.
pub const RGB_UPSAMPLING: &str = "three-box (b 400-490, g 500-590, r 600-700 nm)";

/// A measured BRDF read from a file.
#[derive(Debug, Clone)]
pub enum Measurement {
    Astm(astm::AstmFile),
    Rgl(rgl::RglBsdf),
}

impl Measurement {
    /// Reads either format from bytes (an RGL tensor file starts with `tensor_file`).
    pub fn parse(bytes: &[u8]) -> Result<Measurement, GonioError> {
        if bytes.len() > MAX_FILE_BYTES {
            return Err(GonioError::TooLarge);
        }
        if bytes.starts_with(rgl::MAGIC) {
            return Ok(Measurement::Rgl(rgl::RglBsdf::parse(bytes)?));
        }
        let head = &bytes[..bytes.len().min(64 << 10)];
        let text = String::from_utf8_lossy(head);
        if text.lines().any(|l| l.trim_start().starts_with("VARS")) {
            return Ok(Measurement::Astm(astm::AstmFile::parse(bytes)?));
        }
        Err(GonioError::UnknownFormat)
    }

    /// Reads a file (at most [`MAX_FILE_BYTES`]).
    pub fn read(r: impl std::io::Read) -> Result<Measurement, GonioError> {
        use std::io::Read as _;
        let mut bytes = Vec::new();
        r.take(MAX_FILE_BYTES as u64 + 1).read_to_end(&mut bytes)?;
        Measurement::parse(&bytes)
    }

    /// `astm-e1392` or `rgl-bsdf`.
    pub fn format(&self) -> &'static str {
        match self {
            Measurement::Astm(_) => "astm-e1392",
            Measurement::Rgl(_) => "rgl-bsdf",
        }
    }

    /// The material's name as the file gives it.
    pub fn material(&self) -> &str {
        match self {
            Measurement::Astm(a) => &a.sample_name,
            Measurement::Rgl(r) => &r.description,
        }
    }

    /// The file's channels.
    pub fn channels(&self) -> &Channels {
        match self {
            Measurement::Astm(a) => &a.channels,
            Measurement::Rgl(r) => &r.channels,
        }
    }

    /// The BRDF (sr⁻¹, one value per channel) for light from `wi` seen from `wo` (unit
    /// vectors, normal +z): the format's own evaluation (RGL) or the interpolation between
    /// measured directions (ASTM, [`astm::AstmFile::interpolate`]).
    pub fn raw(&self, wi: Vec3, wo: Vec3) -> Vec<f64> {
        match self {
            Measurement::Astm(a) => a.interpolate(wi, wo, None),
            Measurement::Rgl(r) => r.eval(wi, wo),
        }
    }

    /// [`Measurement::raw`] as a spectrum on brdfd's grid.
    pub fn spectrum(&self, wi: Vec3, wo: Vec3) -> Spectrum {
        self.channels().to_spectrum(&self.raw(wi, wo))
    }
}

/// The unit vector at zenith `theta` and azimuth `phi` (radians).
pub fn direction(theta: f64, phi: f64) -> Vec3 {
    [
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    ]
}

pub(crate) fn normalize(v: Vec3) -> Vec3 {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    [v[0] / n, v[1] / n, v[2] / n]
}

pub(crate) fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spectral::BANDS;

    #[test]
    fn rgb_upsampling_keeps_white_and_grey_flat() {
        assert_eq!(upsample_rgb([1.0; 3]), [1.0; BANDS]);
        assert_eq!(upsample_rgb([0.2; 3]), [0.2; BANDS]);
        let s = upsample_rgb([0.9, 0.5, 0.1]);
        assert_eq!((s[0], s[15], s[30]), (0.1, 0.5, 0.9));
    }

    #[test]
    fn spectral_channels_interpolate_onto_the_grid() {
        let c = Channels::Spectral(vec![380.0, 500.0, 800.0]);
        let s = c.to_spectrum(&[0.0, 1.2, 0.0]);
        assert!((s[10] - 1.2).abs() < 1e-12);
        assert!((s[0] - 0.2).abs() < 1e-12);
        assert!((s[30] - 0.4).abs() < 1e-12);
    }

    #[test]
    fn unknown_bytes_are_refused_with_the_formats_named() {
        let e = Measurement::parse(b"hello").unwrap_err();
        assert!(e.to_string().contains("tensor_file"));
    }
}
