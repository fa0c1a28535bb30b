//! Spectral sphere previews of fitted materials: the model of SCIENCE.md §4 on a sphere under
//! a directional D65 light, in sRGB through the swatches' colour path (SCIENCE.md §7, §11).
//!
//! Scene (camera frame: x right, y up, z toward the viewer):
//! - an orthographic camera looking down −z, so the view direction is v = (0, 0, 1) at every
//!   pixel; a unit sphere of radius [`View::radius_px`] pixels centred in the image;
//! - one directional light of D65 spectrum from [`DEFAULT_LIGHT`]: up and to the left, 45°
//!   from the view direction, l = (−½, ½, 1/√2). Its irradiance is the exposure unit: a white
//!   diffuser facing the light has reflectance factor 1 (Y = 100);
//! - a weak uniform ambient of D65 spectrum, [`AMBIENT`] of the light's irradiance, reflected
//!   by the diffuse term only (the lobe's share of a uniform ambient, its directional albedo,
//!   is left out: it would need an integral per pixel and is below a few per cent for the
//!   lobes fitted here).
//!
//! A pixel whose normal is n shows the radiance factor
//! `R(λ) = π·f(λ; l, v)·cosθi + AMBIENT·π·kd(λ)` with cosθi = n·l (the lobe only where
//! cosθi > 0), where f is [`crate::model`]'s BRDF at the local angles (θi, θr, θh, l·h, v·h)
//! with the fit's Fresnel cosine. Colour: XYZ by the CIE 15 sums over the 31 bands under D65
//! ([`crate::colour::reflectance_to_xyz`]), then sRGB as the swatches. The lobe is the same in
//! every band, so the 31-band sum is done once per material for π·kd and for a flat 1 and the
//! pixel is their weighted sum: identical to summing R(λ) per pixel (the sums are linear) and
//! 31× cheaper. Clipped pixels (outside sRGB, usually the highlight above white) are hatched
//! in magenta and counted in the caption, never silently clamped.
//!
//! At a pixel where n puts l and v at one of the 14 measurement geometries, the colour is the
//! model's colour at that geometry (the fit report's estimate) scaled by cosθi, plus ambient;
//! the tests check it for all 14 geometries.

use plotters::prelude::*;

use crate::colour::srgb::xyz_to_srgb_unclipped;
use crate::colour::{Xyz, brdf_to_reflectance, reflectance_to_xyz, xyz_to_srgb8};
use crate::cost::CostFunction;
use crate::fonts::{font, register_font};
use crate::geometry::{MA_T12_COUNT, Vec3};
use crate::model::{
    FresnelCosine, ModelKind, Params, SpecularGeometry, oren_nayar_factor_angles, specular_term,
};
use crate::spectral::flat;
use crate::study::SampleStudy;

/// Direction toward the light in the camera frame: up-left, 45° from the view direction.
pub const DEFAULT_LIGHT: Vec3 = [-0.5, 0.5, std::f64::consts::FRAC_1_SQRT_2];

/// Uniform ambient irradiance as a fraction of the directional light's.
pub const AMBIENT: f64 = 0.08;

/// Side of one sphere's square, pixels.
pub const SPHERE_PX: u32 = 256;

/// Background: neutral mid grey (sRGB 119, linear 0.18, an 18 % grey card).
pub const BACKGROUND: [u8; 3] = [119, 119, 119];

/// Marks clipped pixels.
const CLIP_MARK: [u8; 3] = [255, 0, 255];

/// How one sphere is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// Side of the square image, pixels.
    pub size: u32,
    /// The sphere's radius, pixels; centred at (size/2, size/2).
    pub radius_px: f64,
    /// Unit vector toward the light, camera frame.
    pub light: Vec3,
    /// Ambient irradiance as a fraction of the light's.
    pub ambient: f64,
}

impl Default for View {
    fn default() -> Self {
        View {
            size: SPHERE_PX,
            radius_px: f64::from(SPHERE_PX) / 2.0 - 6.0,
            light: DEFAULT_LIGHT,
            ambient: AMBIENT,
        }
    }
}

impl View {
    /// The unit normal of the sphere under pixel (px, py) (row 0 at the top), or `None` off
    /// the sphere. Pixel centres are sampled.
    pub fn normal(&self, px: u32, py: u32) -> Option<Vec3> {
        let half = f64::from(self.size) / 2.0;
        let x = (f64::from(px) + 0.5 - half) / self.radius_px;
        let y = (half - (f64::from(py) + 0.5)) / self.radius_px;
        let r2 = x * x + y * y;
        if r2 >= 1.0 {
            return None;
        }
        Some([x, y, (1.0 - r2).sqrt()])
    }
}

/// One rendered sphere: per pixel, sRGB before clipping and quantisation (1 = code 255), or
/// `None` for the background.
#[derive(Debug, Clone, PartialEq)]
pub struct SphereImage {
    pub size: u32,
    pub pixels: Vec<Option<[f64; 3]>>,
}

impl SphereImage {
    /// Pixel (px, py).
    pub fn at(&self, px: u32, py: u32) -> Option<[f64; 3]> {
        self.pixels[(py * self.size + px) as usize]
    }

    /// Clipped pixels and sphere pixels.
    pub fn clipped(&self) -> (usize, usize) {
        let on: Vec<&[f64; 3]> = self.pixels.iter().flatten().collect();
        let clipped = on
            .iter()
            .filter(|p| {
                p.iter()
                    .any(|c| !(0.0..=255.0).contains(&(c * 255.0).round()))
            })
            .count();
        (clipped, on.len())
    }

    /// 8-bit RGB rows, background grey, clipped pixels hatched (diagonal magenta stripes).
    pub fn rgb8(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity((self.size * self.size * 3) as usize);
        for (i, p) in self.pixels.iter().enumerate() {
            let (px, py) = (i as u32 % self.size, i as u32 / self.size);
            let rgb = match p {
                None => BACKGROUND,
                Some(c) => {
                    let codes = c.map(|v| (v * 255.0).round());
                    let clipped = codes.iter().any(|k| !(0.0..=255.0).contains(k));
                    if clipped && (px + py) % 6 < 2 {
                        CLIP_MARK
                    } else {
                        codes.map(|k| {
                            if k.is_nan() {
                                0
                            } else {
                                k.clamp(0.0, 255.0) as u8
                            }
                        })
                    }
                }
            };
            out.extend_from_slice(&rgb);
        }
        out
    }
}

fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The part of `x` perpendicular to the unit normal `n`.
fn tangential(x: Vec3, n: Vec3) -> Vec3 {
    let c = dot(x, n);
    [x[0] - c * n[0], x[1] - c * n[1], x[2] - c * n[2]]
}

/// The radiance factor's XYZ at a normal, for a material whose π·kd and flat-1 XYZ are given,
/// of the model form `kind` (its diffuse factor and added term at the local angles; the
/// ambient is reflected by kd alone, as for the paper's model).
fn shade(
    params: &Params,
    kind: ModelKind,
    fresnel: FresnelCosine,
    view: &View,
    kd_xyz: Xyz,
    white: Xyz,
    n: Vec3,
) -> Xyz {
    let l = view.light;
    let v = [0.0, 0.0, 1.0];
    let cos_i = dot(n, l);
    let cos_r = n[2];
    let mut diffuse = view.ambient;
    let mut lobe = 0.0;
    if cos_i > 0.0 {
        let s = [l[0] + v[0], l[1] + v[1], l[2] + v[2]];
        let len = dot(s, s).sqrt();
        if len == 0.0 || cos_r <= 0.0 {
            diffuse += cos_i;
        } else {
            let h = [s[0] / len, s[1] / len, s[2] / len];
            let g = SpecularGeometry {
                cos_i,
                cos_r,
                cos_h: dot(h, n),
                l_dot_h: dot(l, h),
                v_dot_h: dot(v, h),
                // l and v on the same side of the normal: their tangential parts agree.
                same_side: dot(l, v) - cos_i * cos_r > 0.0,
            };
            let spec = specular_term(params.ks, params.alpha, params.ior, fresnel, &g);
            let (factor, added) = match kind {
                ModelKind::OrenNayar => {
                    // The azimuth between l and v about the normal, from their tangential parts.
                    let (lt, vt) = (tangential(l, n), tangential(v, n));
                    let (pl, pv) = (dot(lt, lt).sqrt(), dot(vt, vt).sqrt());
                    let cos_dphi = if pl > 0.0 && pv > 0.0 {
                        dot(lt, vt) / (pl * pv)
                    } else {
                        0.0
                    };
                    let f = oren_nayar_factor_angles(params.extra[0], cos_i, cos_r, cos_dphi);
                    (f, 0.0)
                }
                _ => kind.shape(&params.extra, params.ior, fresnel, &g),
            };
            diffuse += factor * cos_i;
            // Reflectance factor of the lobe (π·f) times the irradiance cosθi.
            lobe = std::f64::consts::PI * (spec + added) * cos_i;
        }
    }
    Xyz {
        x: diffuse * kd_xyz.x + lobe * white.x,
        y: diffuse * kd_xyz.y + lobe * white.y,
        z: diffuse * kd_xyz.z + lobe * white.z,
    }
}

/// Renders the material `params` (fitted as model form `kind` with `fresnel`) on a sphere.
pub fn render_sphere(
    params: &Params,
    kind: ModelKind,
    fresnel: FresnelCosine,
    view: &View,
) -> SphereImage {
    let kd_xyz = reflectance_to_xyz(&brdf_to_reflectance(&params.kd));
    let white = reflectance_to_xyz(&flat(1.0));
    let mut pixels = Vec::with_capacity((view.size * view.size) as usize);
    for py in 0..view.size {
        for px in 0..view.size {
            pixels.push(view.normal(px, py).map(|n| {
                xyz_to_srgb_unclipped(shade(params, kind, fresnel, view, kd_xyz, white, n))
            }));
        }
    }
    SphereImage {
        size: view.size,
        pixels,
    }
}

/// Why a preview could not be made.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// No cost function to show was asked for or none has a fit.
    #[error(
        "sample \"{sample}\" has no fit under {asked}; fit it first (brdfd refit) or ask for another cost function"
    )]
    NoFit { sample: String, asked: String },
    /// plotters failed to draw text or shapes.
    #[error("cannot draw the preview: {0}")]
    Draw(String),
    /// The PNG encoder failed.
    #[error("cannot encode the preview as PNG: {0}")]
    Png(String),
    #[error("cannot write {}: {source}", path.display())]
    Write {
        path: std::path::PathBuf,
        source: std::io::Error,
    },
}

/// An RGB picture, 8 bits per channel, rows top to bottom.
#[derive(Debug, Clone, PartialEq)]
pub struct Picture {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
}

impl Picture {
    /// PNG bytes.
    pub fn png(&self) -> Result<Vec<u8>, RenderError> {
        let mut out = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut out, self.width, self.height);
            enc.set_color(png::ColorType::Rgb);
            enc.set_depth(png::BitDepth::Eight);
            let mut w = enc
                .write_header()
                .map_err(|e| RenderError::Png(e.to_string()))?;
            w.write_image_data(&self.rgb)
                .map_err(|e| RenderError::Png(e.to_string()))?;
        }
        Ok(out)
    }
}

const MARGIN: u32 = 20;
const GAP: u32 = 20;
const TOP: u32 = 104;
const SWATCH_W: u32 = 52;

/// The preview of one sample: a sphere per cost function in `costs` (those without a finished
/// fit are drawn as a grey box saying why), the measured swatches below (the 14 geometries, or
/// the 12 MA-T12 ones of a scan without SRA readings: a geometry not measured is not drawn),
/// and captions saying the light, the ambient, the scale (the sample's: relative to the tile,
/// absolute through a calibrated tile, or absolute through the instrument's own calibration)
/// and clipping.
pub fn preview(sample: &SampleStudy, costs: &[CostFunction]) -> Result<Picture, RenderError> {
    if costs.is_empty() || !costs.iter().any(|c| sample.done(*c).is_some()) {
        return Err(RenderError::NoFit {
            sample: sample.name.clone(),
            asked: costs
                .iter()
                .map(|c| c.name())
                .collect::<Vec<_>>()
                .join(", "),
        });
    }
    register_font();
    let n = costs.len() as u32;
    let width =
        (2 * MARGIN + n * SPHERE_PX + (n - 1) * GAP).max(2 * MARGIN + 14 * (SWATCH_W + 4) + GAP);
    let height = TOP + SPHERE_PX + 156;
    let mut rgb = vec![255u8; (width * height * 3) as usize];
    let view = View::default();
    let mut spheres = Vec::new();
    let mut clip_total = (0, 0);
    for &c in costs {
        let s = sample
            .done(c)
            .map(|d| render_sphere(&d.params, d.model, d.fresnel, &view));
        if let Some(s) = &s {
            let (k, on) = s.clipped();
            clip_total = (clip_total.0 + k, clip_total.1 + on);
        }
        spheres.push(s);
    }
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
        let err = |e: DrawingAreaErrorKind<_>| RenderError::Draw(e.to_string());
        root.fill(&WHITE).map_err(err)?;
        root.draw(&Text::new(
            format!(
                "{} — fitted material on a sphere, 31 bands under D65",
                sample.name
            ),
            (MARGIN as i32, 10),
            font(20),
        ))
        .map_err(err)?;
        root.draw(&Text::new(
            sample.scale().describe(),
            (MARGIN as i32, 36),
            font(13),
        ))
        .map_err(err)?;
        for (i, &c) in costs.iter().enumerate() {
            let x0 = (MARGIN + i as u32 * (SPHERE_PX + GAP)) as i32;
            let (line1, line2) = match sample.fit(c).map(|f| (f, f.done())) {
                Some((f, Some(d))) => (
                    format!("{c} ({}): ΔE00 mean {:.2}", f.method, d.evaluation.all.mean),
                    format!(
                        "ks {:.3}  α {:.3}  μ {:.3}",
                        d.params.ks, d.params.alpha, d.params.ior
                    ),
                ),
                Some((f, None)) => (format!("{c}"), f.problem().unwrap_or_default()),
                None => (format!("{c}"), "not fitted with this cost function".into()),
            };
            root.draw(&Text::new(line1, (x0, 62), font(14)))
                .map_err(err)?;
            root.draw(&Text::new(line2, (x0, 82), font(12)))
                .map_err(err)?;
            if spheres[i].is_none() {
                let y0 = TOP as i32;
                root.draw(&Rectangle::new(
                    [(x0, y0), (x0 + SPHERE_PX as i32, y0 + SPHERE_PX as i32)],
                    RGBColor(200, 200, 200).filled(),
                ))
                .map_err(err)?;
                root.draw(&Text::new("no fit", (x0 + 100, y0 + 120), font(16)))
                    .map_err(err)?;
            }
        }
        // The measured swatches, as in the report's Fig. 4: only the geometries the scan
        // measured (a scan without SRA readings has no specular swatch, never a black one).
        let sy = (TOP + SPHERE_PX + 16) as i32;
        root.draw(&Text::new(
            swatch_caption(sample),
            (MARGIN as i32, sy),
            font(12),
        ))
        .map_err(err)?;
        for g in sample.measured.geometries.iter() {
            let x = (MARGIN
                + g.index as u32 * (SWATCH_W + 4)
                + if g.index >= MA_T12_COUNT { GAP } else { 0 }) as i32;
            let y = sy + 20;
            let c = xyz_to_srgb8(reflectance_to_xyz(&brdf_to_reflectance(
                &sample.measured.values[g.index],
            )));
            root.draw(&Rectangle::new(
                [(x, y), (x + SWATCH_W as i32, y + 36)],
                RGBColor(c.rgb[0], c.rgb[1], c.rgb[2]).filled(),
            ))
            .map_err(err)?;
            if c.clipped {
                let x1 = x + SWATCH_W as i32;
                root.draw(&Polygon::new(
                    vec![(x1 - 12, y), (x1, y), (x1, y + 12)],
                    WHITE.filled(),
                ))
                .map_err(err)?;
            }
            root.draw(&Text::new(g.name, (x, y + 40), font(10)))
                .map_err(err)?;
        }
        let (k, on) = clip_total;
        let lines = [
            "light: directional D65 from the upper left, 45° from the view (l = (−½, ½, 1/√2), camera along +z, orthographic); ambient: uniform D65, 8 % (diffuse term only)".to_string(),
            "pixel = π·f(λ)·cosθi + 0.08·π·kd(λ), XYZ by CIE 15 sums over 400–700 nm, sRGB as the swatches; on an 18 % grey background".to_string(),
            format!(
                "magenta hatching: clipped, outside sRGB ({:.1} % of the sphere pixels shown)",
                100.0 * k as f64 / on.max(1) as f64
            ),
        ];
        for (i, l) in lines.iter().enumerate() {
            root.draw(&Text::new(
                l.as_str(),
                (MARGIN as i32, sy + 76 + 18 * i as i32),
                font(11),
            ))
            .map_err(err)?;
        }
        root.present().map_err(err)?;
    }
    for (i, s) in spheres.iter().enumerate() {
        let Some(s) = s else { continue };
        let x0 = MARGIN + i as u32 * (SPHERE_PX + GAP);
        let px = s.rgb8();
        for row in 0..SPHERE_PX {
            let dst = (((TOP + row) * width + x0) * 3) as usize;
            let src = (row * SPHERE_PX * 3) as usize;
            rgb[dst..dst + (SPHERE_PX * 3) as usize]
                .copy_from_slice(&px[src..src + (SPHERE_PX * 3) as usize]);
        }
    }
    Ok(Picture { width, height, rgb })
}

/// The line over a preview's swatches: what they show and which instruments measured them.
fn swatch_caption(sample: &SampleStudy) -> &'static str {
    if sample.measured.geometries.has_sra() {
        "measured colour per geometry (sRGB swatches, D65; white corner: clipped) — diffuse: MA-T12, specular: SRA"
    } else {
        "measured colour per geometry (sRGB swatches, D65; white corner: clipped) — diffuse: MA-T12; no SRA readings: the 12 MA-T12 geometries only"
    }
}

/// Writes the preview of `sample` as PNG to `path`.
pub fn write_preview(
    sample: &SampleStudy,
    costs: &[CostFunction],
    path: &std::path::Path,
) -> Result<(), RenderError> {
    let png = preview(sample, costs)?.png()?;
    std::fs::write(path, png).map_err(|source| RenderError::Write {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::geometry::GEOMETRIES;
    use crate::model::{self, SpecularGeometry};
    use crate::spectral::BANDS;
    use crate::study::{DoneFit, FitState, FitStudy};

    fn params() -> Params {
        // A saturated orange with a fairly sharp lobe, so the highlight clips.
        let kd = std::array::from_fn(|b| if b > 15 { 0.2 } else { 0.03 });
        Params {
            kd,
            ks: 0.6,
            alpha: 0.15,
            ior: 1.5,
            extra: [0.0; crate::model::EXTRA],
        }
    }

    /// For every geometry of SCIENCE.md §2: a light direction and a pixel that realise it
    /// exactly (pixel on the centre row of an odd-sized image, at 30 px from the centre, with
    /// the radius chosen so that its normal is θr from the view; the light then θi from the
    /// normal in the same plane, on the far or the same side as φr says), and the pixel's
    /// colour against the model's estimate at that geometry (the fit report's), times cosθi,
    /// plus ambient, through the full 31-band sum.
    #[test]
    fn pixels_at_the_measurement_geometries_show_the_models_colour() {
        // Every model form draws its own BRDF: the paper's, Oren–Nayar's rough diffuse and a
        // second lobe, under each Fresnel factor.
        let forms = [
            (ModelKind::Paper, [0.0, 0.0]),
            (ModelKind::OrenNayar, [0.6, 0.0]),
            (ModelKind::TwoLobe, [0.4, 0.5]),
        ];
        for ((kind, extra), fresnel) in forms.into_iter().flat_map(|f| {
            [
                FresnelCosine::Incidence,
                FresnelCosine::LightHalf,
                FresnelCosine::Exact,
            ]
            .map(move |fr| (f, fr))
        }) {
            let p = Params { extra, ..params() };
            let estimated = model::evaluate_model(&p, kind, fresnel, &SpecularGeometry::all());
            for g in &GEOMETRIES {
                let (ti, tr) = (g.theta_i_deg.to_radians(), g.theta_r_deg.to_radians());
                // The normal at (sin θr, 0, cos θr); v = +z is θr toward −x from it. Far side:
                // the light θi toward +x from the normal; same side: θi toward −x.
                let tl = if g.phi_r_deg == 180.0 {
                    tr + ti
                } else {
                    tr - ti
                };
                let view = View {
                    size: 257,
                    radius_px: 30.0 / tr.sin(),
                    light: [tl.sin(), 0.0, tl.cos()],
                    ambient: AMBIENT,
                };
                let img = render_sphere(&p, kind, fresnel, &view);
                let n = view.normal(128 + 30, 128).unwrap();
                assert!((n[2] - tr.cos()).abs() < 1e-12, "{}: normal {n:?}", g.name);
                let got = img.at(128 + 30, 128).unwrap();
                let r: [f64; BANDS] = std::array::from_fn(|b| {
                    std::f64::consts::PI * (estimated[g.index][b] * ti.cos() + AMBIENT * p.kd[b])
                });
                let want = xyz_to_srgb_unclipped(reflectance_to_xyz(&r));
                for c in 0..3 {
                    // 1/255 before clipping is the requirement; the evaluation is exact, so
                    // the difference is rounding only.
                    assert!(
                        (got[c] - want[c]).abs() < 1e-9,
                        "{} ({kind}, {fresnel:?}) channel {c}: pixel {} vs model {}",
                        g.name,
                        got[c],
                        want[c]
                    );
                    assert!((got[c] - want[c]).abs() * 255.0 < 1.0);
                }
            }
        }
    }

    #[test]
    fn background_is_grey_and_the_highlight_clips_visibly() {
        let img = render_sphere(
            &params(),
            ModelKind::Paper,
            FresnelCosine::Incidence,
            &View::default(),
        );
        assert_eq!(img.at(0, 0), None);
        let rgb = img.rgb8();
        assert_eq!(&rgb[0..3], &BACKGROUND);
        let (k, on) = img.clipped();
        assert!(on > 40_000 && k > 0, "{k} of {on}");
        assert!(rgb.chunks(3).any(|p| p == CLIP_MARK));
    }

    /// A sample of the synthetic set: cf1 and cf2 "fitted" at the truth and at a broader lobe,
    /// m2 failed.
    pub(crate) fn sample(calibrated: bool) -> SampleStudy {
        sample_of(calibrated, |_| {})
    }

    /// [`sample`] of a scan as an instrument's software exports it: no tile reference (the
    /// instrument's own calibration) and no SRA readings (the 12 MA-T12 geometries).
    pub(crate) fn exported_sample() -> SampleStudy {
        sample_of(false, |scan| {
            scan.reference = None;
            scan.readings.sra = None;
        })
    }

    fn sample_of(calibrated: bool, edit: impl FnOnce(&mut crate::scan::Scan)) -> SampleStudy {
        let truth = &crate::synth::paper_samples()[0];
        let mut scan = crate::synth::synth_scan(truth, &Default::default()).unwrap();
        edit(&mut scan);
        let opts = crate::processing::ProcessingOptions {
            reference_reflectance: calibrated.then_some([0.77; BANDS]),
            ..Default::default()
        };
        let measured = crate::processing::process(&scan, &opts).unwrap();
        let mut broad = truth.params;
        broad.alpha *= 2.0;
        let done = |p: Params| {
            FitState::Done(Box::new(DoneFit::from_params(
                &measured,
                p,
                FresnelCosine::Incidence,
            )))
        };
        SampleStudy {
            name: truth.sample.clone(),
            scan_id: None,
            origin: None,
            scan,
            specular: opts.specular,
            reference_reflectance: opts.reference_reflectance,
            measured,
            fits: vec![
                FitStudy {
                    cost: CostFunction::Cf1,
                    method: "separable".into(),
                    state: done(truth.params),
                },
                FitStudy {
                    cost: CostFunction::Cf2,
                    method: "separable".into(),
                    state: done(broad),
                },
                FitStudy {
                    cost: CostFunction::M2,
                    method: "separable".into(),
                    state: FitState::Failed {
                        reason: "cancelled by the operator".into(),
                    },
                },
            ],
        }
    }

    #[test]
    fn preview_draws_a_sphere_per_cost_function_and_refuses_no_fit() {
        let s = sample(false);
        let pic = preview(&s, &CostFunction::ALL).unwrap();
        assert_eq!(pic.width, 2 * MARGIN + 3 * SPHERE_PX + 2 * GAP);
        assert_eq!(pic.rgb.len(), (pic.width * pic.height * 3) as usize);
        // The corner of the first sphere's square is background grey, its centre is not.
        let at = |x: u32, y: u32| {
            let i = ((y * pic.width + x) * 3) as usize;
            [pic.rgb[i], pic.rgb[i + 1], pic.rgb[i + 2]]
        };
        assert_eq!(at(MARGIN, TOP), BACKGROUND);
        assert_ne!(at(MARGIN + 128, TOP + 128), BACKGROUND);
        // The failed m2 fit is a grey box, not a sphere.
        let x_m2 = MARGIN + 2 * (SPHERE_PX + GAP);
        assert_eq!(at(x_m2 + 5, TOP + 5), [200, 200, 200]);
        let png = pic.png().unwrap();
        assert_eq!(&png[1..4], b"PNG");
        let e = preview(&s, &[CostFunction::M2]).unwrap_err().to_string();
        assert!(e.contains("has no fit under m2"), "{e}");
    }

    /// The preview of an instrument-calibrated scan without SRA readings says its scale is the
    /// instrument's calibration (no tile, no "30 % too bright"), and draws the 12 swatches it
    /// measured and nothing where the SRA swatches would be: the same preview of a full scan
    /// draws them there.
    #[test]
    fn preview_of_an_exported_scan_says_its_scale_and_draws_only_its_geometries() {
        let s = exported_sample();
        assert_eq!(s.scale(), crate::processing::Scale::InstrumentCalibration);
        let note = s.scale().describe();
        assert!(note.contains("instrument calibration"), "{note}");
        assert!(
            !note.contains("reference tile") && !note.contains("30 %"),
            "{note}"
        );
        assert!(swatch_caption(&s).contains("no SRA readings"));
        // A scan with its tile keeps the relative scale and its note.
        assert!(sample(false).scale().describe().contains("30 %"));

        let swatch_rows = |pic: &Picture, g: usize| -> Vec<[u8; 3]> {
            let x0 = MARGIN + g as u32 * (SWATCH_W + 4) + if g >= MA_T12_COUNT { GAP } else { 0 };
            let y0 = TOP + SPHERE_PX + 16 + 20;
            (y0 + 4..y0 + 32)
                .flat_map(|y| (x0 + 4..x0 + SWATCH_W - 14).map(move |x| (x, y)))
                .map(|(x, y)| {
                    let i = ((y * pic.width + x) * 3) as usize;
                    [pic.rgb[i], pic.rgb[i + 1], pic.rgb[i + 2]]
                })
                .collect()
        };
        let full = preview(&sample(false), &CostFunction::ALL).unwrap();
        let exported = preview(&s, &CostFunction::ALL).unwrap();
        for g in 0..14 {
            let (a, b) = (swatch_rows(&full, g), swatch_rows(&exported, g));
            assert!(
                a.iter().all(|p| *p != [255, 255, 255]),
                "geometry {g} drawn"
            );
            if g < MA_T12_COUNT {
                assert!(
                    b.iter().all(|p| *p != [255, 255, 255]),
                    "geometry {g} drawn"
                );
            } else {
                assert!(
                    b.iter().all(|p| *p == [255, 255, 255]),
                    "geometry {g} was not measured but is drawn"
                );
            }
        }
    }
}
