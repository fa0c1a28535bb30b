//! RGL-EPFL isotropic tensor files (`.bsdf`): the container, the adaptive parameterisation of
//! Dupuy & Jakob, "An Adaptive Parameterization for Efficient Material Acquisition and
//! Rendering", ACM TOG 37(6), 2018, its evaluation, and a writer.
//!
//! **Container.** `tensor_file\0`, a version (two bytes), the field count (u32), then per field
//! its name (u16 length + bytes), rank (u16), element type (u8: 1 u8, 2 i8, 3 u16, 4 i16,
//! 5 u32, 6 i32, 7 u64, 8 i64, 10 f32, 11 f64), data offset (u64) and shape (u64 per axis),
//! all little-endian; the data follow at their offsets.
//!
//! **Fields.** `theta_i`, `phi_i` (the incidence grid; one `phi_i` value: isotropic),
//! `ndf` and `sigma` (the microfacet distribution D(u_m) and the projected area σ(u_i), 2-D
//! over the unit square of (θ, φ)), `vndf` (per incidence, a density over the unit square
//! whose inverse warp maps a half vector to a sample position), `luminance` (for sampling),
//! `spectra` (+ `wavelengths`) or `rgb` (per incidence and channel, the values on a grid over
//! sample positions), `jacobian` (1: the values are stored divided by D/(4σ)), `description`.
//!
//! **Evaluation** ([`RglBsdf::eval`]): the half vector m of (wi, wo) in unit coordinates
//! `u = (√(2θ/π), (φ + π)/2π)`, φ relative to the incidence azimuth; the VNDF warp inverted at
//! u_m gives the sample position, where the channels are interpolated bilinearly (and
//! linearly between incidence angles); times `D(u_m) / (4 σ(u_i))` when `jacobian` is set.
//! That is `f · cos θo`, a renderer's BSDF value (what Mitsuba's `eval` returns); brdfd divides
//! the cosine out and reports the BRDF f, sr⁻¹.
//! The warps are the format's continuous "marginal 2-D" distributions: the bilinear
//! interpolant of a grid, its marginal CDF over rows and conditional CDF along each row.
//! Mitsuba 3's `measured` plugin evaluates the same files (`tests/gonio_mitsuba.rs` holds
//! brdfd to it).

use std::collections::BTreeMap;
use std::f64::consts::PI;

use super::{Channels, GonioError, dot, normalize};
use crate::geometry::Vec3;

/// The first bytes of a tensor file.
pub const MAGIC: &[u8] = b"tensor_file\0";

const FORMAT: &str = "RGL tensor";
const MAX_FIELDS: usize = 256;
const MAX_RANK: usize = 8;

fn err(field: impl Into<String>, message: impl Into<String>) -> GonioError {
    GonioError::Field {
        format: FORMAT,
        field: field.into(),
        message: message.into(),
    }
}

/// One array of a tensor file, its values widened to f64.
#[derive(Debug, Clone, PartialEq)]
pub struct Tensor {
    /// The element type code (see the module text).
    pub dtype: u8,
    pub shape: Vec<usize>,
    pub values: Vec<f64>,
}

fn dtype_size(dtype: u8) -> Option<usize> {
    Some(match dtype {
        1 | 2 => 1,
        3 | 4 => 2,
        5 | 6 | 10 => 4,
        7 | 8 | 11 => 8,
        _ => return None,
    })
}

struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], GonioError> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or_else(|| err(what, "the header ends early (truncated file)"))?;
        let s = &self.bytes[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    fn u16(&mut self, what: &str) -> Result<u16, GonioError> {
        Ok(u16::from_le_bytes(self.take(2, what)?.try_into().unwrap()))
    }
    fn u32(&mut self, what: &str) -> Result<u32, GonioError> {
        Ok(u32::from_le_bytes(self.take(4, what)?.try_into().unwrap()))
    }
    fn u64(&mut self, what: &str) -> Result<u64, GonioError> {
        Ok(u64::from_le_bytes(self.take(8, what)?.try_into().unwrap()))
    }
}

/// Reads the arrays of a tensor file, every offset and size checked against the file.
pub fn read_tensors(bytes: &[u8]) -> Result<BTreeMap<String, Tensor>, GonioError> {
    if !bytes.starts_with(MAGIC) {
        return Err(err("header", "does not start with \"tensor_file\""));
    }
    let mut c = Cursor {
        bytes,
        pos: MAGIC.len(),
    };
    let version = c.take(2, "version")?;
    if version[0] != 1 {
        return Err(err(
            "version",
            format!(
                "{}.{} is not a version brdfd reads (1.x)",
                version[0], version[1]
            ),
        ));
    }
    let count = c.u32("field count")? as usize;
    if count > MAX_FIELDS {
        return Err(err(
            "field count",
            format!("{count} fields (at most {MAX_FIELDS})"),
        ));
    }
    let mut out = BTreeMap::new();
    for k in 0..count {
        let len = c.u16(&format!("field {k} name length"))? as usize;
        let name = String::from_utf8(c.take(len, &format!("field {k} name"))?.to_vec())
            .map_err(|_| err(format!("field {k} name"), "not UTF-8"))?;
        let rank = c.u16(&format!("{name}: rank"))? as usize;
        if rank > MAX_RANK {
            return Err(err(&name, format!("rank {rank} (at most {MAX_RANK})")));
        }
        let dtype = c.take(1, &format!("{name}: type"))?[0];
        let size = dtype_size(dtype).ok_or_else(|| {
            err(
                &name,
                format!("element type {dtype} is not one brdfd reads"),
            )
        })?;
        let offset = c.u64(&format!("{name}: offset"))? as usize;
        let mut shape = Vec::with_capacity(rank);
        for _ in 0..rank {
            shape.push(c.u64(&format!("{name}: shape"))? as usize);
        }
        let n = shape
            .iter()
            .try_fold(1usize, |a, &d| a.checked_mul(d))
            .and_then(|n| n.checked_mul(size))
            .filter(|&b| offset.checked_add(b).is_some_and(|e| e <= bytes.len()))
            .ok_or_else(|| {
                err(
                    &name,
                    format!("shape {shape:?} at offset {offset} runs past the end of the file"),
                )
            })?
            / size;
        let data = &bytes[offset..offset + n * size];
        let values = data
            .chunks_exact(size)
            .map(|b| match dtype {
                1 => f64::from(b[0]),
                2 => f64::from(b[0] as i8),
                3 => f64::from(u16::from_le_bytes([b[0], b[1]])),
                4 => f64::from(i16::from_le_bytes([b[0], b[1]])),
                5 => f64::from(u32::from_le_bytes(b.try_into().unwrap())),
                6 => f64::from(i32::from_le_bytes(b.try_into().unwrap())),
                7 => u64::from_le_bytes(b.try_into().unwrap()) as f64,
                8 => i64::from_le_bytes(b.try_into().unwrap()) as f64,
                10 => f64::from(f32::from_le_bytes(b.try_into().unwrap())),
                _ => f64::from_le_bytes(b.try_into().unwrap()),
            })
            .collect();
        out.insert(
            name,
            Tensor {
                dtype,
                shape,
                values,
            },
        );
    }
    Ok(out)
}

/// Writes a tensor file (fields in the order given; f32 data for `dtype` 10, u8 for 1, u32
/// for 5).
pub fn write_tensors(fields: &[(&str, Tensor)]) -> Vec<u8> {
    let mut header = Vec::new();
    header.extend_from_slice(MAGIC);
    header.extend_from_slice(&[1, 0]);
    header.extend_from_slice(&(fields.len() as u32).to_le_bytes());
    let header_len = header.len()
        + fields
            .iter()
            .map(|(n, t)| 2 + n.len() + 2 + 1 + 8 + 8 * t.shape.len())
            .sum::<usize>();
    let mut data = Vec::new();
    let mut offset = header_len.next_multiple_of(8);
    for (name, t) in fields {
        header.extend_from_slice(&(name.len() as u16).to_le_bytes());
        header.extend_from_slice(name.as_bytes());
        header.extend_from_slice(&(t.shape.len() as u16).to_le_bytes());
        header.push(t.dtype);
        header.extend_from_slice(&(offset as u64).to_le_bytes());
        for &d in &t.shape {
            header.extend_from_slice(&(d as u64).to_le_bytes());
        }
        let mut bytes = Vec::new();
        for &v in &t.values {
            match t.dtype {
                1 => bytes.push(v as u8),
                5 => bytes.extend_from_slice(&(v as u32).to_le_bytes()),
                11 => bytes.extend_from_slice(&v.to_le_bytes()),
                _ => bytes.extend_from_slice(&(v as f32).to_le_bytes()),
            }
        }
        let padded = bytes.len().next_multiple_of(8);
        bytes.resize(padded, 0);
        offset += padded;
        data.extend_from_slice(&bytes);
    }
    let start = header_len.next_multiple_of(8);
    header.resize(start, 0);
    header.extend_from_slice(&data);
    header
}

/// A continuous "marginal 2-D" warp over the unit square: the bilinear interpolant of a
/// `nx × ny` grid per slice, slices indexed by up to three parameters (interpolated
/// linearly), with its marginal and conditional CDFs when it is sampled.
#[derive(Debug, Clone)]
pub struct Warp2D {
    nx: usize,
    ny: usize,
    params: Vec<Vec<f64>>,
    strides: Vec<usize>,
    data: Vec<f64>,
    marginal_cdf: Vec<f64>,
    conditional_cdf: Vec<f64>,
}

impl Warp2D {
    /// `data` is `[param0][param1]…[ny][nx]`; `normalize` makes each slice a density (and
    /// builds the CDFs that [`Warp2D::invert`] and [`Warp2D::sample`] need).
    pub fn new(
        data: &[f64],
        nx: usize,
        ny: usize,
        params: Vec<Vec<f64>>,
        normalize: bool,
    ) -> Warp2D {
        let mut slices = 1;
        let mut strides = vec![0; params.len()];
        for d in (0..params.len()).rev() {
            strides[d] = if params[d].len() > 1 { slices } else { 0 };
            slices *= params[d].len();
        }
        let n = nx * ny;
        let mut w = Warp2D {
            nx,
            ny,
            params,
            strides,
            data: vec![0.0; n * slices],
            marginal_cdf: Vec::new(),
            conditional_cdf: Vec::new(),
        };
        if !normalize {
            w.data.copy_from_slice(&data[..n * slices]);
            return w;
        }
        w.marginal_cdf = vec![0.0; ny * slices];
        w.conditional_cdf = vec![0.0; n * slices];
        for s in 0..slices {
            let d = &data[s * n..(s + 1) * n];
            let cc = &mut w.conditional_cdf[s * n..(s + 1) * n];
            for y in 0..ny {
                let mut sum = 0.0;
                cc[y * nx] = 0.0;
                for x in 0..nx - 1 {
                    sum += 0.5 * (d[y * nx + x] + d[y * nx + x + 1]);
                    cc[y * nx + x + 1] = sum;
                }
            }
            let mc = &mut w.marginal_cdf[s * ny..(s + 1) * ny];
            let mut sum = 0.0;
            mc[0] = 0.0;
            for y in 0..ny - 1 {
                sum += 0.5 * (cc[(y + 1) * nx - 1] + cc[(y + 2) * nx - 1]);
                mc[y + 1] = sum;
            }
            let norm = 1.0 / mc[ny - 1];
            cc.iter_mut().for_each(|v| *v *= norm);
            mc.iter_mut().for_each(|v| *v *= norm);
            for (o, v) in w.data[s * n..(s + 1) * n].iter_mut().zip(d) {
                *o = v * norm;
            }
        }
        w
    }

    /// The slice offset and the (w0, w1) weights per parameter.
    fn weights(&self, param: &[f64]) -> (usize, [(f64, f64); 3]) {
        let mut ws = [(1.0, 0.0); 3];
        let mut offset = 0;
        for (d, values) in self.params.iter().enumerate() {
            if values.len() == 1 {
                continue;
            }
            let count = values.partition_point(|&v| v < param[d]);
            let k = count.saturating_sub(1).min(values.len() - 2);
            let (p0, p1) = (values[k], values[k + 1]);
            let w1 = ((param[d] - p0) / (p1 - p0)).clamp(0.0, 1.0);
            ws[d] = (1.0 - w1, w1);
            offset += self.strides[d] * k;
        }
        (offset, ws)
    }

    /// `arr[i0 + …]` interpolated over the parameters; `size` is the slice size of `arr`.
    fn lookup(&self, arr: &[f64], i0: usize, size: usize, ws: &[(f64, f64); 3]) -> f64 {
        let dims = self.params.len();
        let mut total = 0.0;
        for corner in 0..(1usize << dims) {
            let mut w = 1.0;
            let mut i = i0;
            for d in 0..dims {
                if corner >> d & 1 == 1 {
                    w *= ws[d].1;
                    i += self.strides[d] * size;
                } else {
                    w *= ws[d].0;
                }
            }
            if w != 0.0 {
                total += w * arr[i];
            }
        }
        total
    }

    /// The interpolant at `pos` (times the patch count when normalised: a density).
    pub fn eval(&self, pos: [f64; 2], param: &[f64]) -> f64 {
        let (slice, ws) = self.weights(param);
        let (fx, fy) = ((self.nx - 1) as f64, (self.ny - 1) as f64);
        let (px, py) = (pos[0].clamp(0.0, 1.0) * fx, pos[1].clamp(0.0, 1.0) * fy);
        let (ox, oy) = (
            (px as usize).min(self.nx - 2),
            (py as usize).min(self.ny - 2),
        );
        let (w1x, w1y) = (px - ox as f64, py - oy as f64);
        let size = self.nx * self.ny;
        let i = ox + oy * self.nx + slice * size;
        let v00 = self.lookup(&self.data, i, size, &ws);
        let v10 = self.lookup(&self.data, i + 1, size, &ws);
        let v01 = self.lookup(&self.data, i + self.nx, size, &ws);
        let v11 = self.lookup(&self.data, i + self.nx + 1, size, &ws);
        let v =
            (1.0 - w1y) * ((1.0 - w1x) * v00 + w1x * v10) + w1y * ((1.0 - w1x) * v01 + w1x * v11);
        if self.marginal_cdf.is_empty() {
            v
        } else {
            v * fx * fy
        }
    }

    /// The sample position whose warp is `pos`, and the density there (the inverse of
    /// [`Warp2D::sample`]).
    pub fn invert(&self, pos: [f64; 2], param: &[f64]) -> ([f64; 2], f64) {
        let (slice, ws) = self.weights(param);
        let (fx, fy) = ((self.nx - 1) as f64, (self.ny - 1) as f64);
        let (px, py) = (pos[0].clamp(0.0, 1.0) * fx, pos[1].clamp(0.0, 1.0) * fy);
        let (ox, oy) = (
            (px as usize).min(self.nx - 2),
            (py as usize).min(self.ny - 2),
        );
        let (mut sx, mut sy) = (px - ox as f64, py - oy as f64);
        let size = self.nx * self.ny;
        let i = ox + oy * self.nx + slice * size;
        let v00 = self.lookup(&self.data, i, size, &ws);
        let v10 = self.lookup(&self.data, i + 1, size, &ws);
        let v01 = self.lookup(&self.data, i + self.nx, size, &ws);
        let v11 = self.lookup(&self.data, i + self.nx + 1, size, &ws);
        let c0 = (1.0 - sy) * v00 + sy * v01;
        let c1 = (1.0 - sy) * v10 + sy * v11;
        let pdf = (1.0 - sx) * c0 + sx * c1;
        sx *= c0 + 0.5 * sx * (c1 - c0);
        let cc = &self.conditional_cdf;
        let a0 = self.lookup(cc, i, size, &ws);
        let a1 = self.lookup(cc, i + self.nx, size, &ws);
        sx += (1.0 - sy) * a0 + sy * a1;
        let row = oy * self.nx + slice * size;
        let r0 = self.lookup(cc, row + self.nx - 1, size, &ws);
        let r1 = self.lookup(cc, row + 2 * self.nx - 1, size, &ws);
        sx /= (1.0 - sy) * r0 + sy * r1;
        sy *= r0 + 0.5 * sy * (r1 - r0);
        sy += self.lookup(&self.marginal_cdf, oy + slice * self.ny, self.ny, &ws);
        ([sx, sy], pdf * fx * fy)
    }

    /// The warp of a uniform sample (continuous inversion of the marginal CDF over rows and
    /// the conditional CDF along the row), and the density there.
    pub fn sample(&self, sample: [f64; 2], param: &[f64]) -> ([f64; 2], f64) {
        let (slice, ws) = self.weights(param);
        let eps = f64::from(f32::EPSILON) / 2.0;
        let (mut sx, mut sy) = (
            sample[0].clamp(eps, 1.0 - eps),
            sample[1].clamp(eps, 1.0 - eps),
        );
        let size = self.nx * self.ny;
        let mrow = slice * self.ny;
        let fetch_m = |k: usize| self.lookup(&self.marginal_cdf, mrow + k, self.ny, &ws);
        let row = find_interval(self.ny, |k| fetch_m(k) < sy);
        sy -= fetch_m(row);
        let mut col_offset = row * self.nx + slice * size;
        let cc = &self.conditional_cdf;
        let r0 = self.lookup(cc, col_offset + self.nx - 1, size, &ws);
        let r1 = self.lookup(cc, col_offset + 2 * self.nx - 1, size, &ws);
        let is_const = (r0 - r1).abs() < 1e-4 * (r0 + r1);
        sy = if is_const {
            2.0 * sy / (r0 + r1)
        } else {
            (r0 - (r0 * r0 - 2.0 * sy * (r0 - r1)).max(0.0).sqrt()) / (r0 - r1)
        };
        sx *= (1.0 - sy) * r0 + sy * r1;
        let fetch_c = |k: usize| {
            let v0 = self.lookup(cc, col_offset + k, size, &ws);
            let v1 = self.lookup(cc, col_offset + self.nx + k, size, &ws);
            (1.0 - sy) * v0 + sy * v1
        };
        let col = find_interval(self.nx, |k| fetch_c(k) < sx);
        sx -= fetch_c(col);
        col_offset += col;
        let v00 = self.lookup(&self.data, col_offset, size, &ws);
        let v10 = self.lookup(&self.data, col_offset + 1, size, &ws);
        let v01 = self.lookup(&self.data, col_offset + self.nx, size, &ws);
        let v11 = self.lookup(&self.data, col_offset + self.nx + 1, size, &ws);
        let c0 = (1.0 - sy) * v00 + sy * v01;
        let c1 = (1.0 - sy) * v10 + sy * v11;
        let is_const = (c0 - c1).abs() < 1e-4 * (c0 + c1);
        let divisor = if is_const { c0 + c1 } else { c0 - c1 };
        sx = if is_const {
            2.0 * sx
        } else {
            c0 - (c0 * c0 - 2.0 * sx * (c0 - c1)).max(0.0).sqrt()
        };
        if divisor != 0.0 {
            sx /= divisor;
        }
        let (fx, fy) = ((self.nx - 1) as f64, (self.ny - 1) as f64);
        (
            [(col as f64 + sx) / fx, (row as f64 + sy) / fy],
            ((1.0 - sx) * c0 + sx * c1) * fx * fy,
        )
    }
}

/// The last index `k` in `[0, n − 2]` with `pred(k)` (pred true then false along the array).
fn find_interval(n: usize, pred: impl Fn(usize) -> bool) -> usize {
    let (mut lo, mut hi) = (0usize, n);
    // Binary search for the first index where pred is false.
    while lo < hi {
        let mid = (lo + hi) / 2;
        if pred(mid) {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo.saturating_sub(1).min(n - 2)
}

fn theta2u(theta: f64) -> f64 {
    (theta * (2.0 / PI)).sqrt()
}
fn phi2u(phi: f64) -> f64 {
    (phi + PI) / (2.0 * PI)
}
fn u2theta(u: f64) -> f64 {
    u * u * (PI / 2.0)
}
fn u2phi(u: f64) -> f64 {
    (2.0 * u - 1.0) * PI
}

/// The zenith angle of a unit vector, stable near the normal.
fn elevation(d: Vec3) -> f64 {
    let dist = (d[0] * d[0] + d[1] * d[1] + (d[2] - 1.0) * (d[2] - 1.0)).sqrt();
    2.0 * (0.5 * dist).clamp(-1.0, 1.0).asin()
}

/// An isotropic RGL tensor file, ready to evaluate.
#[derive(Debug, Clone)]
pub struct RglBsdf {
    /// The material, as `description` names it.
    pub description: String,
    pub channels: Channels,
    /// The incidence zenith angles of the grid, radians.
    pub theta_i: Vec<f64>,
    jacobian: bool,
    ndf: Warp2D,
    sigma: Warp2D,
    vndf: Warp2D,
    values: Warp2D,
    channel_params: Vec<f64>,
}

fn field<'a>(t: &'a BTreeMap<String, Tensor>, name: &str) -> Result<&'a Tensor, GonioError> {
    t.get(name)
        .ok_or_else(|| err(name, "missing (an RGL BRDF file has it)"))
}

fn rank(t: &Tensor, name: &str, want: usize) -> Result<(), GonioError> {
    if t.shape.len() != want {
        return Err(err(
            name,
            format!("has shape {:?}; expected {want} axes", t.shape),
        ));
    }
    if t.shape.iter().any(|&d| d == 0) {
        return Err(err(
            name,
            format!("has an empty axis (shape {:?})", t.shape),
        ));
    }
    Ok(())
}

impl RglBsdf {
    /// Reads an isotropic RGL BRDF (spectral `spectra` + `wavelengths`, or `rgb`).
    pub fn parse(bytes: &[u8]) -> Result<RglBsdf, GonioError> {
        let t = read_tensors(bytes)?;
        let description = t
            .get("description")
            .map(|d| {
                String::from_utf8_lossy(&d.values.iter().map(|&v| v as u8).collect::<Vec<_>>())
                    .into_owned()
            })
            .unwrap_or_default();
        let theta_i = field(&t, "theta_i")?;
        let phi_i = field(&t, "phi_i")?;
        rank(theta_i, "theta_i", 1)?;
        rank(phi_i, "phi_i", 1)?;
        if phi_i.shape[0] > 2 {
            return Err(err(
                "phi_i",
                format!(
                    "{} incidence azimuths: an anisotropic material, which brdfd does not read (isotropic files have 1)",
                    phi_i.shape[0]
                ),
            ));
        }
        if theta_i.shape[0] < 2 || !theta_i.values.windows(2).all(|w| w[0] < w[1]) {
            return Err(err("theta_i", "needs at least two increasing angles"));
        }
        let (np, nt) = (phi_i.shape[0], theta_i.shape[0]);
        let grid2 = |name: &str| -> Result<Warp2D, GonioError> {
            let a = field(&t, name)?;
            rank(a, name, 2)?;
            if a.shape[0] < 2 || a.shape[1] < 2 {
                return Err(err(
                    name,
                    format!("shape {:?}: each axis needs ≥ 2", a.shape),
                ));
            }
            Ok(Warp2D::new(
                &a.values,
                a.shape[1],
                a.shape[0],
                vec![],
                false,
            ))
        };
        let ndf = grid2("ndf")?;
        let sigma = grid2("sigma")?;
        let vndf_t = field(&t, "vndf")?;
        rank(vndf_t, "vndf", 4)?;
        if vndf_t.shape[0] != np
            || vndf_t.shape[1] != nt
            || vndf_t.shape[2] < 2
            || vndf_t.shape[3] < 2
        {
            return Err(err(
                "vndf",
                format!(
                    "shape {:?} does not match phi_i × theta_i × n × n",
                    vndf_t.shape
                ),
            ));
        }
        let params = vec![phi_i.values.clone(), theta_i.values.clone()];
        let vndf = Warp2D::new(
            &vndf_t.values,
            vndf_t.shape[3],
            vndf_t.shape[2],
            params.clone(),
            true,
        );
        let (values_t, channels, channel_params, name) = if let Some(s) = t.get("spectra") {
            let w = field(&t, "wavelengths")?;
            rank(w, "wavelengths", 1)?;
            if !w.values.windows(2).all(|p| p[0] < p[1]) {
                return Err(err("wavelengths", "must increase"));
            }
            (
                s,
                Channels::Spectral(w.values.clone()),
                w.values.clone(),
                "spectra",
            )
        } else if let Some(s) = t.get("rgb") {
            (s, Channels::Rgb, vec![0.0, 1.0, 2.0], "rgb")
        } else {
            return Err(err(
                "spectra",
                "missing, and no rgb either: the file holds no BRDF values",
            ));
        };
        rank(values_t, name, 5)?;
        let s = &values_t.shape;
        if s[0] != np || s[1] != nt || s[2] != channel_params.len() || s[3] < 2 || s[4] < 2 {
            return Err(err(
                name,
                format!(
                    "shape {s:?}; expected [{np}, {nt}, {}, n, n]",
                    channel_params.len()
                ),
            ));
        }
        let mut vparams = params;
        vparams.push(channel_params.clone());
        let values = Warp2D::new(&values_t.values, s[4], s[3], vparams, false);
        let jacobian = t
            .get("jacobian")
            .is_some_and(|j| j.values.first().is_some_and(|&v| v != 0.0));
        Ok(RglBsdf {
            description,
            channels,
            theta_i: theta_i.values.clone(),
            jacobian,
            ndf,
            sigma,
            vndf,
            values,
            channel_params,
        })
    }

    /// The BRDF (sr⁻¹, one value per channel) for light from `wi` seen from `wo`; 0 below
    /// the horizon.
    pub fn eval(&self, wi: Vec3, wo: Vec3) -> Vec<f64> {
        let n = self.channel_params.len();
        if wi[2] <= 0.0 || wo[2] <= 0.0 {
            return vec![0.0; n];
        }
        let m = normalize([wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]]);
        let (theta_i, phi_i) = (elevation(wi), wi[1].atan2(wi[0]));
        let (theta_m, phi_m) = (elevation(m), m[1].atan2(m[0]));
        let u_wi = [theta2u(theta_i), phi2u(phi_i)];
        let mut u_m = [theta2u(theta_m), phi2u(phi_m - phi_i)];
        u_m[1] -= u_m[1].floor();
        let params = [phi_i, theta_i];
        let (sample, _) = self.vndf.invert(u_m, &params);
        let scale = if self.jacobian {
            self.ndf.eval(u_m, &[]) / (4.0 * self.sigma.eval(u_wi, &[]))
        } else {
            1.0
        };
        // The format's evaluation is f · cos θo (a renderer's BSDF value): the cosine out.
        let scale = scale / wo[2];
        self.channel_params
            .iter()
            .map(|&c| self.values.eval(sample, &[phi_i, theta_i, c]) * scale)
            .collect()
    }
}

/// How [`write`] lays out a file.
#[derive(Debug, Clone, Copy)]
pub struct WriteOptions {
    /// Incidence angles, evenly spaced in θ from 0 to `theta_i_max_deg`.
    pub theta_i_count: usize,
    pub theta_i_max_deg: f64,
    /// Resolution of `ndf`, `sigma` and `vndf` (per axis).
    pub warp_resolution: usize,
    /// Resolution of the values grid (per axis).
    pub value_resolution: usize,
    /// GGX width of the microfacet distribution the warp follows.
    pub alpha: f64,
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions {
            theta_i_count: 10,
            theta_i_max_deg: 85.0,
            warp_resolution: 64,
            value_resolution: 48,
            alpha: 0.3,
        }
    }
}

fn ggx(alpha: f64, cos: f64) -> f64 {
    crate::model::ggx_d(alpha, cos)
}

fn g1(alpha: f64, cos: f64) -> f64 {
    crate::model::smith_g1(alpha, cos, cos.max(1e-9))
}

/// An isotropic RGL tensor file of the BRDF `f(wi, wo)` (sr⁻¹, one value per channel of
/// `channels`), in the format's jacobian form with a GGX microfacet distribution of width
/// `opts.alpha` as its warp: what the tests evaluate back, here and in Mitsuba.
pub fn write(
    description: &str,
    channels: &Channels,
    f: &dyn Fn(Vec3, Vec3) -> Vec<f64>,
    opts: &WriteOptions,
) -> Vec<u8> {
    let nt = opts.theta_i_count.max(2);
    let nw = opts.warp_resolution.max(2);
    let nv = opts.value_resolution.max(2);
    let a = opts.alpha;
    let theta_i: Vec<f64> = (0..nt)
        .map(|k| (k as f64 / (nt - 1) as f64 * opts.theta_i_max_deg).to_radians())
        .map(|t| f64::from(t as f32))
        .collect();
    // D(u_m) and σ(u_i) on the unit square (x: θ, y: φ); two rows: isotropic.
    let ndf: Vec<f64> = (0..2 * nw)
        .map(|i| ggx(a, u2theta((i % nw) as f64 / (nw - 1) as f64).cos()))
        .collect();
    let sigma: Vec<f64> = (0..2 * nw)
        .map(|i| {
            let c = u2theta((i % nw) as f64 / (nw - 1) as f64).cos().max(1e-4);
            c / g1(a, c)
        })
        .collect();
    // The VNDF of wi in unit coordinates, with the area element of the map, and a floor.
    let mut vndf = Vec::with_capacity(nt * nw * nw);
    for &ti in &theta_i {
        let wi = super::direction(ti, 0.0);
        for y in 0..nw {
            for x in 0..nw {
                let (u0, u1) = (x as f64 / (nw - 1) as f64, y as f64 / (nw - 1) as f64);
                let (tm, pm) = (u2theta(u0), u2phi(u1));
                let m = super::direction(tm, pm);
                let d = ggx(a, m[2]) * dot(wi, m).max(0.0) * 2.0 * PI * PI * u0 * tm.sin();
                vndf.push(d + 1e-3);
            }
        }
    }
    let channel_params: Vec<f64> = match channels {
        Channels::Spectral(w) => w.clone(),
        Channels::Rgb => vec![0.0, 1.0, 2.0],
    };
    let nc = channel_params.len();
    let round = |v: &[f64]| v.iter().map(|&x| f64::from(x as f32)).collect::<Vec<_>>();
    let (ndf, sigma, vndf) = (round(&ndf), round(&sigma), round(&vndf));
    let params = vec![vec![0.0], theta_i.clone()];
    let vndf_w = Warp2D::new(&vndf, nw, nw, params, true);
    let ndf_w = Warp2D::new(&ndf, nw, 2, vec![], false);
    let sigma_w = Warp2D::new(&sigma, nw, 2, vec![], false);
    let mut values = vec![0.0; nt * nc * nv * nv];
    let mut luminance = vec![0.0; nt * nv * nv];
    for (k, &ti) in theta_i.iter().enumerate() {
        let wi = super::direction(ti, 0.0);
        let u_wi = [theta2u(ti), phi2u(0.0)];
        let s = sigma_w.eval(u_wi, &[]);
        for y in 0..nv {
            for x in 0..nv {
                let pos = [x as f64 / (nv - 1) as f64, y as f64 / (nv - 1) as f64];
                let (u_m, _) = vndf_w.sample(pos, &[0.0, ti]);
                let m = super::direction(u2theta(u_m[0]), u2phi(u_m[1]));
                let c = 2.0 * dot(m, wi);
                let mut wo = [c * m[0] - wi[0], c * m[1] - wi[1], c * m[2] - wi[2]];
                wo[2] = wo[2].max(1e-3);
                let wo = normalize(wo);
                let fv = f(wi, wo);
                let scale = 4.0 * s / ndf_w.eval(u_m, &[]) * wo[2];
                let mut lum = 0.0;
                for ch in 0..nc {
                    let v = fv[ch] * scale;
                    values[((k * nc + ch) * nv + y) * nv + x] = v;
                    lum += v / nc as f64;
                }
                luminance[(k * nv + y) * nv + x] = lum;
            }
        }
    }
    let f32t = |shape: Vec<usize>, values: Vec<f64>| Tensor {
        dtype: 10,
        shape,
        values,
    };
    let mut fields: Vec<(&str, Tensor)> = vec![
        (
            "description",
            Tensor {
                dtype: 1,
                shape: vec![description.len()],
                values: description.bytes().map(f64::from).collect(),
            },
        ),
        ("phi_i", f32t(vec![1], vec![0.0])),
        ("theta_i", f32t(vec![nt], theta_i)),
        ("sigma", f32t(vec![2, nw], sigma)),
        ("ndf", f32t(vec![2, nw], ndf)),
        ("vndf", f32t(vec![1, nt, nw, nw], vndf)),
        ("luminance", f32t(vec![1, nt, nv, nv], luminance)),
    ];
    match channels {
        Channels::Spectral(w) => {
            fields.push(("wavelengths", f32t(vec![nc], w.clone())));
            fields.push(("spectra", f32t(vec![1, nt, nc, nv, nv], values)));
        }
        Channels::Rgb => fields.push(("rgb", f32t(vec![1, nt, 3, nv, nv], values))),
    }
    fields.push((
        "jacobian",
        Tensor {
            dtype: 1,
            shape: vec![1],
            values: vec![1.0],
        },
    ));
    write_tensors(&fields)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gonio::direction;

    #[test]
    fn warp_invert_undoes_sample() {
        let data: Vec<f64> = (0..2 * 6 * 5)
            .map(|i| 0.2 + ((i * 37) % 11) as f64 / 7.0)
            .collect();
        let w = Warp2D::new(&data, 6, 5, vec![vec![0.0, 1.0]], true);
        for (sx, sy, p) in [(0.3, 0.7, 0.25), (0.9, 0.1, 0.0), (0.51, 0.49, 1.0)] {
            let (pos, pdf) = w.sample([sx, sy], &[p]);
            let (back, pdf2) = w.invert(pos, &[p]);
            assert!(
                (back[0] - sx).abs() < 1e-9 && (back[1] - sy).abs() < 1e-9,
                "{back:?}"
            );
            assert!((pdf - pdf2).abs() < 1e-9 * pdf);
            assert!((w.eval(pos, &[p]) - pdf).abs() < 1e-9 * pdf);
        }
    }

    #[test]
    fn written_file_reads_back_and_evaluates_the_brdf() {
        // A smooth BRDF: Lambert plus a wide lobe around the mirror direction.
        let f = |wi: Vec3, wo: Vec3| {
            let m = normalize([wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]]);
            let lobe = 0.05 * (-(1.0 - m[2]) * 8.0).exp();
            vec![0.1 + lobe, 0.2 + lobe, 0.3 + lobe]
        };
        let bytes = write("test", &Channels::Rgb, &f, &WriteOptions::default());
        let b = RglBsdf::parse(&bytes).unwrap();
        assert_eq!(b.description, "test");
        assert_eq!(b.channels, Channels::Rgb);
        let mut worst: f64 = 0.0;
        for (ti, to, p) in [
            (0.0, 30.0, 0.0),
            (30.0, 30.0, 180.0),
            (45.0, 45.0, 180.0),
            (60.0, 20.0, 90.0),
            (20.0, 70.0, 150.0),
        ] {
            let wi = direction(f64::to_radians(ti), 0.0);
            let wo = direction(f64::to_radians(to), f64::to_radians(p));
            let got = b.eval(wi, wo);
            let want = f(wi, wo);
            for c in 0..3 {
                worst = worst.max((got[c] / want[c] - 1.0).abs());
            }
        }
        // Between the value nodes the format interpolates: a percent or two on this lobe.
        assert!(worst < 0.03, "worst relative error {worst}");
        assert_eq!(b.eval(direction(0.3, 0.0), [0.0, 0.6, -0.8]), vec![0.0; 3]);
    }

    #[test]
    fn truncated_and_malformed_files_name_the_field() {
        let f = |_: Vec3, _: Vec3| vec![0.1; 3];
        let opts = WriteOptions {
            theta_i_count: 3,
            warp_resolution: 4,
            value_resolution: 4,
            ..WriteOptions::default()
        };
        let bytes = write("x", &Channels::Rgb, &f, &opts);
        let e = RglBsdf::parse(&bytes[..bytes.len() - 40])
            .unwrap_err()
            .to_string();
        assert!(e.contains("jacobian") || e.contains("rgb"), "{e}");
        assert!(e.contains("past the end"), "{e}");
        let e = RglBsdf::parse(&bytes[..30]).unwrap_err().to_string();
        assert!(e.contains("truncated"), "{e}");
        let mut bad = bytes.clone();
        bad[12] = 7;
        assert!(
            RglBsdf::parse(&bad)
                .unwrap_err()
                .to_string()
                .contains("version")
        );
    }
}
