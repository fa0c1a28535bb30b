//! ASTM E1392 goniometric BRDF text files: reader, writer, and the interpolation between
//! measured directions (SCIENCE.md §12.6).
//!
//! A header of `KEY value` lines (`SAMPLE_NAME`, `SAMPLE_TYPE`, `NUM_POINTS`, and `VARS`
//! naming the comma-separated columns), then one line per direction: `theta_i, phi_i,
//! theta_s, phi_s` in radians, then the BRDF in sr⁻¹ per channel: one per wavelength
//! (`400nm`, `410nm`, … or bare numbers) or `R, G, B`.
//!
//! **Interpolation** ([`AstmFile::interpolate`]): the measured directions are scattered, and
//! the instrument geometries fall between them. Each direction pair is put in a canonical form
//! that the BRDF of an isotropic sample does not change: rotated so the light is at azimuth 0,
//! mirrored so the view is at y ≥ 0; by reciprocity each pair also stands for its swap. The
//! value at a query is the inverse-square-distance weighted mean of the [`NEIGHBOURS`] nearest
//! canonical pairs, distance the Euclidean one between the two unit vectors of each pair
//! concatenated; a query on a measured pair returns it exactly. [`AstmFile::leave_one_out`]
//! measures the interpolation's own error: every measured pair predicted from the others.

use std::fmt::Write as _;

use super::{Channels, GonioError, Steps, direction};
use crate::geometry::Vec3;

const FORMAT: &str = "ASTM E1392";

/// The most directions a file may have.
pub const MAX_POINTS: usize = 2_000_000;

/// The directions of [`AstmFile::sampled`], degrees `(first, last, step)`: θi 10–70°, θs 0–80°,
/// φs 0–180° (0 the light's side, 180 the mirror side), 7 × 17 × 13 = 1,547 pairs.
pub const SAMPLED_GRID: (Steps, Steps, Steps) =
    ((10.0, 70.0, 10.0), (0.0, 80.0, 5.0), (0.0, 180.0, 15.0));

/// How many nearest measured pairs the interpolation weighs.
pub const NEIGHBOURS: usize = 6;

fn err(field: impl Into<String>, message: impl Into<String>) -> GonioError {
    GonioError::Field {
        format: FORMAT,
        field: field.into(),
        message: message.into(),
    }
}

/// One measured direction pair.
#[derive(Debug, Clone, PartialEq)]
pub struct Point {
    /// `theta_i, phi_i, theta_s, phi_s`, radians, as the file gives them.
    pub angles: [f64; 4],
    /// The BRDF per channel, sr⁻¹.
    pub values: Vec<f64>,
}

impl Point {
    /// Light and view unit vectors (normal +z).
    pub fn directions(&self) -> (Vec3, Vec3) {
        let [ti, pi, ts, ps] = self.angles;
        (direction(ti, pi), direction(ts, ps))
    }
}

/// An ASTM E1392 file.
#[derive(Debug, Clone)]
pub struct AstmFile {
    pub sample_name: String,
    pub sample_type: String,
    pub channels: Channels,
    pub points: Vec<Point>,
    /// Canonical pairs for the interpolation: (6-vector, index into `points`).
    canonical: Vec<([f64; 6], usize)>,
}

/// The canonical form of a pair (see the module text): light at azimuth 0, view at y ≥ 0.
fn canonical(wi: Vec3, wo: Vec3) -> [f64; 6] {
    let phi = wi[1].atan2(wi[0]);
    let (s, c) = (-phi).sin_cos();
    let rot = |v: Vec3| [c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]];
    let (a, b) = (rot(wi), rot(wo));
    [a[0], 0.0, a[2], b[0], b[1].abs(), b[2]]
}

fn dist2(a: &[f64; 6], b: &[f64; 6]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

impl AstmFile {
    /// Reads a file; every problem names its line and column.
    pub fn parse(bytes: &[u8]) -> Result<AstmFile, GonioError> {
        if bytes.len() > super::MAX_FILE_BYTES {
            return Err(GonioError::TooLarge);
        }
        let text = std::str::from_utf8(bytes).map_err(|e| {
            err(
                "text",
                format!(
                    "not UTF-8 at byte {}: ASTM E1392 files are text",
                    e.valid_up_to()
                ),
            )
        })?;
        let mut keys: Vec<(String, String)> = Vec::new();
        let mut vars: Option<Vec<String>> = None;
        let mut points = Vec::new();
        let mut expected: Option<usize> = None;
        for (lineno, line) in text.lines().enumerate() {
            let line = line.trim();
            let n = lineno + 1;
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let first = line.chars().next().unwrap_or(' ');
            if !(first.is_ascii_digit() || matches!(first, '-' | '+' | '.')) {
                let (key, value) = line.split_once(char::is_whitespace).unwrap_or((line, ""));
                let value = value.trim().to_string();
                if key.eq_ignore_ascii_case("VARS") {
                    vars = Some(value.split(',').map(|v| v.trim().to_string()).collect());
                } else if key.eq_ignore_ascii_case("NUM_POINTS") {
                    expected = Some(value.parse().map_err(|_| {
                        err(
                            format!("line {n}: NUM_POINTS"),
                            format!("\"{value}\" is not a count"),
                        )
                    })?);
                }
                keys.push((key.to_ascii_uppercase(), value));
                continue;
            }
            let Some(v) = &vars else {
                return Err(err(
                    format!("line {n}"),
                    "a data line before the VARS line that names the columns",
                ));
            };
            if points.len() >= MAX_POINTS {
                return Err(err(
                    format!("line {n}"),
                    format!("more than {MAX_POINTS} directions"),
                ));
            }
            let cols: Vec<&str> = line.split(',').map(str::trim).collect();
            if cols.len() != v.len() {
                return Err(err(
                    format!("line {n}"),
                    format!("{} values; VARS names {}", cols.len(), v.len()),
                ));
            }
            let mut nums = Vec::with_capacity(cols.len());
            for (c, s) in cols.iter().enumerate() {
                let x: f64 = s
                    .parse()
                    .ok()
                    .filter(|x: &f64| x.is_finite())
                    .ok_or_else(|| {
                        err(
                            format!("line {n}, column {} ({})", c + 1, v[c]),
                            format!("\"{s}\" is not a finite number"),
                        )
                    })?;
                nums.push(x);
            }
            for (c, name) in [(0, "theta_i"), (2, "theta_s")] {
                if !(0.0..=std::f64::consts::FRAC_PI_2 + 1e-6).contains(&nums[c]) {
                    return Err(err(
                        format!("line {n}, {name}"),
                        format!(
                            "{} rad is not a zenith angle in [0, π/2] (angles are in radians)",
                            nums[c]
                        ),
                    ));
                }
            }
            if nums[4..].iter().any(|&x| x < 0.0) {
                return Err(err(format!("line {n}"), "a negative BRDF value"));
            }
            points.push(Point {
                angles: [nums[0], nums[1], nums[2], nums[3]],
                values: nums[4..].to_vec(),
            });
        }
        let vars = vars.ok_or_else(|| err("VARS", "missing: the header must name the columns"))?;
        let angle_names = ["theta_i", "phi_i", "theta_s", "phi_s"];
        if vars.len() < 5
            || !vars
                .iter()
                .zip(angle_names)
                .all(|(v, a)| v.eq_ignore_ascii_case(a))
        {
            return Err(err(
                "VARS",
                format!(
                    "\"{}\": expected theta_i,phi_i,theta_s,phi_s then one column per channel",
                    vars.join(",")
                ),
            ));
        }
        let chans = &vars[4..];
        let channels = if chans.len() == 3
            && chans
                .iter()
                .zip(["r", "g", "b"])
                .all(|(c, w)| c.to_ascii_lowercase().starts_with(w))
        {
            Channels::Rgb
        } else {
            let mut w = Vec::new();
            for c in chans {
                let t = c.trim_end_matches("nm").trim();
                let x: f64 = t
                    .parse()
                    .ok()
                    .filter(|x: &f64| x.is_finite() && *x > 0.0)
                    .ok_or_else(|| {
                        err(
                            "VARS",
                            format!(
                                "channel \"{c}\" is neither a wavelength (e.g. 400nm) nor R, G, B"
                            ),
                        )
                    })?;
                w.push(x);
            }
            if !w.windows(2).all(|p| p[0] < p[1]) {
                return Err(err("VARS", "wavelengths must increase"));
            }
            Channels::Spectral(w)
        };
        if points.is_empty() {
            return Err(err("data", "no direction lines after the header"));
        }
        if let Some(e) = expected
            && e != points.len()
        {
            return Err(err(
                "NUM_POINTS",
                format!(
                    "says {e}, the file has {} direction lines (truncated?)",
                    points.len()
                ),
            ));
        }
        let get = |k: &str| {
            keys.iter()
                .find(|(key, _)| key == k)
                .map(|(_, v)| v.clone())
                .unwrap_or_default()
        };
        Ok(AstmFile::new(
            get("SAMPLE_NAME"),
            get("SAMPLE_TYPE"),
            channels,
            points,
        ))
    }

    /// A file from its parts (what the parser builds, and what tests write).
    pub fn new(
        sample_name: String,
        sample_type: String,
        channels: Channels,
        points: Vec<Point>,
    ) -> AstmFile {
        let mut canonical = Vec::with_capacity(2 * points.len());
        for (k, p) in points.iter().enumerate() {
            let (wi, wo) = p.directions();
            canonical.push((self::canonical(wi, wo), k));
            canonical.push((self::canonical(wo, wi), k));
        }
        AstmFile {
            sample_name,
            sample_type,
            channels,
            points,
            canonical,
        }
    }

    /// A spectral file (brdfd's 31 bands) of the BRDF `f` (light `wi`, view `wo` → sr⁻¹ per
    /// band) sampled on [`SAMPLED_GRID`] and at the 14 instrument geometries: what the project
    /// generates to validate against known materials.
    pub fn sampled(
        sample_name: &str,
        sample_type: &str,
        f: &dyn Fn(Vec3, Vec3) -> Vec<f64>,
    ) -> AstmFile {
        let mut points = Vec::new();
        let mut push = |angles: [f64; 4]| {
            let p = Point {
                angles,
                values: vec![],
            };
            let (wi, wo) = p.directions();
            points.push(Point {
                values: f(wi, wo),
                ..p
            });
        };
        let steps = |(a, b, s): Steps| {
            (0..=((b - a) / s).round() as usize).map(move |k| (a + s * k as f64).to_radians())
        };
        let (ti, ts, ps) = SAMPLED_GRID;
        for t_i in steps(ti) {
            for t_s in steps(ts) {
                for p_s in steps(ps) {
                    push([t_i, 0.0, t_s, p_s]);
                }
            }
        }
        for g in &crate::geometry::GEOMETRIES {
            push([
                g.theta_i_deg.to_radians(),
                0.0,
                g.theta_r_deg.to_radians(),
                g.phi_r_deg.to_radians(),
            ]);
        }
        let nm = crate::spectral::wavelengths_nm()
            .iter()
            .map(|&n| f64::from(n))
            .collect();
        AstmFile::new(
            sample_name.into(),
            sample_type.into(),
            Channels::Spectral(nm),
            points,
        )
    }

    /// The file's text.
    pub fn write(&self) -> String {
        let mut t = String::new();
        let _ = writeln!(t, "SAMPLE_NAME {}", self.sample_name);
        let _ = writeln!(t, "SAMPLE_TYPE {}", self.sample_type);
        let _ = writeln!(t, "MEAS_NAME BRDF");
        let _ = writeln!(t, "NUM_POINTS {}", self.points.len());
        let chans: Vec<String> = match &self.channels {
            Channels::Rgb => vec!["R".into(), "G".into(), "B".into()],
            Channels::Spectral(w) => w.iter().map(|x| format!("{x}nm")).collect(),
        };
        let _ = writeln!(t, "VARS theta_i,phi_i,theta_s,phi_s,{}", chans.join(","));
        t.push('\n');
        for p in &self.points {
            let cells: Vec<String> = p
                .angles
                .iter()
                .chain(&p.values)
                .map(|v| format!("{v:.9}"))
                .collect();
            let _ = writeln!(t, "{}", cells.join(","));
        }
        t
    }

    /// The BRDF at (wi, wo) interpolated from the measured pairs (module text), leaving
    /// `points[exclude]` out when given.
    pub fn interpolate(&self, wi: Vec3, wo: Vec3, exclude: Option<usize>) -> Vec<f64> {
        let q = canonical(wi, wo);
        let mut best: [(f64, usize); NEIGHBOURS] = [(f64::INFINITY, usize::MAX); NEIGHBOURS];
        for (c, k) in &self.canonical {
            if Some(*k) == exclude {
                continue;
            }
            let d = dist2(&q, c);
            if d < best[NEIGHBOURS - 1].0 {
                // Keep the same point once (a pair and its swap may both be near).
                if let Some(slot) = best.iter_mut().find(|(_, i)| *i == *k) {
                    if d < slot.0 {
                        slot.0 = d;
                    }
                } else {
                    best[NEIGHBOURS - 1] = (d, *k);
                }
                best.sort_by(|a, b| a.0.total_cmp(&b.0));
            }
        }
        let nc = self.channels.len();
        if best[0].0 < 1e-18 {
            return self.points[best[0].1].values.clone();
        }
        let mut out = vec![0.0; nc];
        let mut wsum = 0.0;
        for &(d, k) in best.iter().filter(|(_, k)| *k != usize::MAX) {
            let w = 1.0 / d;
            wsum += w;
            for (o, v) in out.iter_mut().zip(&self.points[k].values) {
                *o += w * v;
            }
        }
        out.iter_mut().for_each(|o| *o /= wsum);
        out
    }

    /// Every measured pair interpolated from the others: `(index, interpolated values)`.
    pub fn leave_one_out(&self) -> Vec<Vec<f64>> {
        self.points
            .iter()
            .enumerate()
            .map(|(k, p)| {
                let (wi, wo) = p.directions();
                self.interpolate(wi, wo, Some(k))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file() -> AstmFile {
        let mut points = Vec::new();
        for ti in [10.0f64, 30.0, 50.0] {
            for ts in [0.0f64, 20.0, 40.0, 60.0] {
                for ps in [0.0f64, 90.0, 180.0] {
                    let v = 0.1 + 0.001 * ti + 0.002 * ts + 0.0001 * ps;
                    points.push(Point {
                        angles: [ti.to_radians(), 0.0, ts.to_radians(), ps.to_radians()],
                        values: vec![v, 2.0 * v],
                    });
                }
            }
        }
        AstmFile::new(
            "grey".into(),
            "test".into(),
            Channels::Spectral(vec![450.0, 650.0]),
            points,
        )
    }

    #[test]
    fn written_file_reads_back() {
        let f = file();
        let back = AstmFile::parse(f.write().as_bytes()).unwrap();
        assert_eq!(back.sample_name, "grey");
        assert_eq!(back.channels, f.channels);
        assert_eq!(back.points.len(), f.points.len());
        for (a, b) in back.points.iter().zip(&f.points) {
            for (x, y) in a.values.iter().zip(&b.values) {
                assert!((x - y).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn interpolation_is_exact_on_measured_pairs_and_uses_symmetry() {
        let f = file();
        let p = &f.points[7];
        let (wi, wo) = p.directions();
        assert_eq!(f.interpolate(wi, wo, None), p.values);
        // Rotated about the normal and mirrored: the same pair for an isotropic sample.
        let rot = |v: Vec3| [-v[1], v[0], v[2]];
        let got = f.interpolate(rot(wi), rot([wo[0], -wo[1], wo[2]]), None);
        assert!((got[0] - p.values[0]).abs() < 1e-12);
        // Between measured pairs: a weighted mean of their values, within their range.
        let q = f.interpolate(direction(0.35, 0.0), direction(0.5, 3.0), None);
        assert!(q[0] > 0.1 && q[0] < 0.3 && (q[1] / q[0] - 2.0).abs() < 1e-12);
        assert_eq!(f.leave_one_out().len(), f.points.len());
    }

    #[test]
    fn errors_name_the_line_and_field() {
        let e = AstmFile::parse(b"SAMPLE_NAME x\n0.1,0,0.2,0,0.5\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2") && e.contains("VARS"), "{e}");
        let e = AstmFile::parse(b"VARS theta_i,phi_i,theta_s,phi_s,400nm\n0.1,0,0.2,0,abc\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("column 5 (400nm)"), "{e}");
        let e = AstmFile::parse(
            b"NUM_POINTS 3\nVARS theta_i,phi_i,theta_s,phi_s,400nm\n0.1,0,0.2,0,0.5\n",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("NUM_POINTS") && e.contains("truncated"), "{e}");
        let e = AstmFile::parse(b"VARS theta_i,phi_i,theta_s,phi_s,400nm\n20,0,0.2,0,0.5\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("radians"), "{e}");
        let rgb =
            AstmFile::parse(b"VARS theta_i,phi_i,theta_s,phi_s,R,G,B\n0.1,0,0.2,0,0.5,0.4,0.3\n")
                .unwrap();
        assert_eq!(rgb.channels, Channels::Rgb);
    }
}
