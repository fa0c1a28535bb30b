//! Mitsuba 3 scenes of fitted materials (`brdfd export-format --format mitsuba`): one XML
//! scene per finished fit, with the material, a unit sphere, an orthographic camera and the
//! preview's light ([`crate::render`]), so `mitsuba -m scalar_spectral scene.xml` draws what
//! `brdfd render` draws, on the same brightness scale.
//!
//! The variant: the 31-band kd needs a spectral variant, and Mitsuba 3 has no way to name one
//! inside a scene file (its XML carries only the format version; the variant is chosen by the
//! program that loads it, and a bare `mitsuba scene.xml` picks the first RGB variant whose
//! backend is available, `llvm_ad_rgb` where LLVM is installed). Each scene's opening comment
//! gives the command with `-m scalar_spectral`, the variant the tests load it in.
//!
//! The material, SCIENCE.md §11: brdfd's `f = kd(λ) + ks·F·D·G/(π cosθi cosθr)` as Mitsuba's
//! `blendbsdf` at weight ½ of
//! - `diffuse` with reflectance `2π·kd(λ)` as `<spectrum>` wavelength:value pairs at the 31
//!   band centres, held flat to 360 and 830 nm (Mitsuba's range; its `diffuse` is
//!   reflectance/π; the blend halves it);
//! - `roughconductor`, GGX, `alpha` = α, `eta` = μ, `k` = 0 (a dielectric's Fresnel), with
//!   `specular_reflectance` = `2·ks·4/π`: Mitsuba's lobe is `F·D·G/(4 cosθi cosθr)`, so the 4
//!   vs π denominator and the blend's ½ are folded into this weight.
//!
//! A two-lobe fit (`--model two-lobe`) draws its second lobe too: the outer blend at weight ⅔
//! of `diffuse` (reflectance `3π·kd(λ)`) and an inner `blendbsdf` at ½ of two
//! `roughconductor`s (α and α2, each `specular_reflectance` `3·ks·4/π`), so each of the three
//! terms is weighted ⅓ and the weights fold that in. Mitsuba 3 has no Oren–Nayar BSDF: an
//! `oren-nayar` fit is drawn with its Lambertian kd, and the scene's comment says so.
//!
//! Mitsuba's Fresnel factor is the exact dielectric Fresnel on the microfacet normal (l·h):
//! brdfd's `--fresnel exact` ([`FresnelCosine::Exact`]). A fit made with it exports without
//! approximation. A fit made with the paper's Schlick on cosθi (or on l·h) is exported with its
//! lobe scaled, in effect, by `F_exact(l·h; μ) / F_Schlick(cos; f0)`; SCIENCE.md §11 tabulates
//! that ratio at the 14 geometries, the scene's comment says which case it is, and
//! `tests/export_mitsuba.rs` checks both in Mitsuba itself. D and G are the same functions in
//! both (GGX, Smith–Walter G1).
//!
//! The light and the brightness scale: the preview shows the radiance factor, π·radiance per
//! unit irradiance. The scene's `directional` emitter (the `d65` spectrum along −l, l =
//! [`crate::render::DEFAULT_LIGHT`]) therefore has irradiance π, and the `constant` D65
//! environment radiance [`AMBIENT`] (irradiance π·AMBIENT on an unshadowed surface), so a pixel
//! of Mitsuba's film holds the preview's linear value: a white diffuser facing the light renders
//! 1, as in the preview. Mitsuba's ambient also reaches the lobe (the preview leaves that out).

use std::fmt::Write as _;

use crate::model::{FresnelCosine, ModelKind};
use crate::render::{AMBIENT, DEFAULT_LIGHT, SPHERE_PX};
use crate::spectral::wavelengths_nm;
use crate::study::{DoneFit, SampleStudy};

use super::{ExportOptions, FormatError};

/// `specular_reflectance` for a given ks: `2 · ks · 4/π` (the blend's ½ and the 4-vs-π
/// denominator folded in).
pub fn specular_weight(ks: f64) -> f64 {
    2.0 * ks * 4.0 / std::f64::consts::PI
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace("--", "- -")
}

/// The Mitsuba 3 scene of one finished fit of `sample`.
pub fn scene(
    sample: &SampleStudy,
    cost: crate::cost::CostFunction,
    method: &str,
    fit: &DoneFit,
    opts: &ExportOptions,
) -> Result<String, FormatError> {
    let p = &fit.params;
    let finite =
        p.kd.iter().all(|v| v.is_finite()) && [p.ks, p.alpha, p.ior].iter().all(|v| v.is_finite());
    if !finite || p.alpha <= 0.0 || p.ior < 1.0 {
        return Err(FormatError::Unwritable {
            format: "mitsuba",
            message: format!(
                "{} ({cost}): parameters out of the model's domain (α {}, μ {}); refit the scan",
                sample.name, p.alpha, p.ior
            ),
        });
    }
    let mut t = String::new();
    let _ = writeln!(t, r#"<?xml version="1.0" encoding="utf-8"?>"#);
    let fresnel_note = match fit.fresnel {
        FresnelCosine::Exact => {
            "Fresnel: exact dielectric Fresnel on l·h in both, so Mitsuba's BSDF is brdfd's model"
                .to_string()
        }
        f => format!(
            "Remaining difference: Mitsuba's exact Fresnel on l·h against brdfd's Schlick on {} \
             (brdfd's SCIENCE.md §11); a fit with the Fresnel choice `exact` exports without it",
            if f == FresnelCosine::Incidence {
                "cosθi"
            } else {
                "l·h"
            }
        ),
    };
    // The second lobe of a two-lobe fit is drawn (a second roughconductor); Oren–Nayar's
    // diffuse factor has no Mitsuba 3 BSDF.
    let two_lobes = fit.model == ModelKind::TwoLobe && p.extra[0] > 0.0;
    let omission = match fit.model {
        ModelKind::TwoLobe => None,
        m => m.export_omission(&p.extra),
    };
    let fresnel_note = match omission {
        Some(omitted) => format!("{fresnel_note}.\n     Not exact: {omitted}"),
        None => fresnel_note,
    };
    let _ = writeln!(
        t,
        "<!-- {}: sample \"{}\", cost function {cost}, method {method}, Fresnel {}; written {}.\n     {}.\n     Render with a spectral variant: mitsuba -m scalar_spectral this-file.xml (a scene file cannot name its variant; a bare `mitsuba` picks an RGB one).\n     The film holds brdfd's preview values: linear sRGB radiance factor (light irradiance π, so a white diffuser facing it is 1).\n     {}.\n     {}.\n     Readings: {}. -->",
        esc(&opts.originator),
        esc(&sample.name),
        fit.fresnel.name(),
        esc(&opts.created),
        esc(&sample.scale().describe()),
        if two_lobes {
            "brdfd's model f = kd + ks·F·D(α)·G(α)/(π cosθi cosθr) + ks2·F·D(α2)·G(α2)/(π cosθi cosθr) (model two-lobe) as blendbsdf(⅓ diffuse 3π·kd, ⅔ blendbsdf(½ roughconductor GGX α with specular_reflectance 3·ks·4/π, ½ roughconductor GGX α2 with 3·ks2·4/π))"
        } else {
            "brdfd's model f = kd + ks·F·D·G/(π cosθi cosθr) as blendbsdf(½ diffuse 2π·kd, ½ roughconductor GGX with specular_reflectance 2·ks·4/π)"
        },
        esc(&fresnel_note),
        esc(&sample
            .provenance_summary()
            .unwrap_or_else(|| "provenance not recorded (a study made in memory)".into())),
    );
    let _ = writeln!(t, r#"<scene version="3.0.0">"#);
    // Resolution and samples per pixel can be overridden: `mitsuba -D res=64 -D spp=16`.
    let _ = writeln!(
        t,
        r#"    <default name="res" value="{SPHERE_PX}"/>
    <default name="spp" value="64"/>"#
    );
    // Mitsuba samples 360–830 nm and a spectrum is zero outside the wavelengths it is given,
    // which would darken the blue and red ends of a render: the end values are held flat to
    // 360 and 830 nm, as brdfd's colour sums (400–700 nm only) implicitly do.
    // Each of the blend's n parts is weighted 1/n: n = 2 (diffuse, lobe) or 3 (two lobes).
    let parts = if two_lobes { 3.0 } else { 2.0 };
    let reflectance: Vec<f64> =
        p.kd.iter()
            .map(|kd| parts * std::f64::consts::PI * kd)
            .collect();
    let mut pairs = vec![format!("360:{}", reflectance[0])];
    pairs.extend(
        wavelengths_nm()
            .iter()
            .zip(&reflectance)
            .map(|(nm, r)| format!("{nm}:{r}")),
    );
    pairs.push(format!("830:{}", reflectance[reflectance.len() - 1]));
    let lobe = |indent: &str, ks: f64, alpha: f64| {
        format!(
            r#"{indent}<bsdf type="roughconductor">
{indent}    <string name="distribution" value="ggx"/>
{indent}    <float name="alpha" value="{alpha}"/>
{indent}    <float name="eta" value="{}"/>
{indent}    <float name="k" value="0"/>
{indent}    <float name="specular_reflectance" value="{}"/>
{indent}</bsdf>"#,
            p.ior,
            specular_weight(ks) * parts / 2.0
        )
    };
    let specular = if two_lobes {
        format!(
            r#"        <bsdf type="blendbsdf">
            <float name="weight" value="0.5"/>
{}
{}
        </bsdf>"#,
            lobe("            ", p.ks, p.alpha),
            lobe("            ", p.extra[0], p.extra[1])
        )
    } else {
        lobe("        ", p.ks, p.alpha)
    };
    let _ = writeln!(
        t,
        r#"    <bsdf type="blendbsdf" id="material">
        <float name="weight" value="{}"/>
        <bsdf type="diffuse">
            <spectrum name="reflectance" value="{}"/>
        </bsdf>
{specular}
    </bsdf>
    <shape type="sphere">
        <ref id="material"/>
    </shape>"#,
        (parts - 1.0) / parts,
        pairs.join(", "),
    );
    let [lx, ly, lz] = DEFAULT_LIGHT;
    let radius_px = crate::render::View::default().radius_px;
    let _ = writeln!(
        t,
        r#"    <emitter type="directional">
        <vector name="direction" x="{}" y="{}" z="{}"/>
        <spectrum type="d65" name="irradiance">
            <float name="scale" value="{}"/>
        </spectrum>
    </emitter>
    <emitter type="constant">
        <spectrum type="d65" name="radiance">
            <float name="scale" value="{}"/>
        </spectrum>
    </emitter>
    <integrator type="direct"/>
    <sensor type="orthographic">
        <transform name="to_world">
            <scale x="{s}" y="{s}"/>
            <lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/>
        </transform>
        <sampler type="independent">
            <integer name="sample_count" value="$spp"/>
        </sampler>
        <film type="hdrfilm">
            <integer name="width" value="$res"/>
            <integer name="height" value="$res"/>
            <string name="pixel_format" value="rgb"/>
            <rfilter type="box"/>
        </film>
    </sensor>
</scene>"#,
        -lx,
        -ly,
        -lz,
        std::f64::consts::PI,
        AMBIENT,
        s = f64::from(SPHERE_PX) / 2.0 / radius_px,
    );
    Ok(t)
}

/// Every finished fit of the study as `(file name, scene)`: `<sample>-<cost>.xml`.
pub fn scenes(
    study: &crate::study::Study,
    opts: &ExportOptions,
) -> Result<Vec<(String, String)>, FormatError> {
    let mut out = Vec::new();
    for s in &study.samples {
        for f in &s.fits {
            if let Some(d) = f.done() {
                let name = format!("{}-{}.xml", crate::names::slug(&s.name), f.cost);
                out.push((name, scene(s, f.cost, &f.method, d, opts)?));
            }
        }
    }
    if out.is_empty() {
        return Err(FormatError::Unwritable {
            format: "mitsuba",
            message: "no finished fit in the selection: nothing to export".into(),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The scene of `fit` as cf1's, by the separable method, with the default options.
    fn cf1_scene(sample: &SampleStudy, fit: &DoneFit) -> String {
        scene(
            sample,
            crate::cost::CostFunction::Cf1,
            "separable",
            fit,
            &ExportOptions::default(),
        )
        .unwrap()
    }

    #[test]
    fn a_scene_holds_the_material_sphere_camera_and_light() {
        let s = crate::render::tests::sample(true);
        let d = s.done(crate::cost::CostFunction::Cf1).unwrap();
        let xml = cf1_scene(&s, d);
        roxmltree::Document::parse(&xml).unwrap();
        assert!(xml.contains("absolute scale"));
        assert!(xml.contains(&format!(
            "400:{}",
            2.0 * std::f64::consts::PI * d.params.kd[0]
        )));
        assert!(xml.contains(&format!(
            r#"<float name="specular_reflectance" value="{}"/>"#,
            specular_weight(d.params.ks)
        )));
        assert!(xml.contains(r#"<shape type="sphere">"#));
        // The preview's scale: light irradiance π, ambient radiance AMBIENT; the variant named.
        assert!(xml.contains(&format!(
            r#"<spectrum type="d65" name="irradiance">
            <float name="scale" value="{}"/>"#,
            std::f64::consts::PI
        )));
        assert!(xml.contains(&format!(
            r#"<spectrum type="d65" name="radiance">
            <float name="scale" value="{AMBIENT}"/>"#
        )));
        assert!(xml.contains("mitsuba -m scalar_spectral"));
        assert!(xml.contains("Remaining difference: Mitsuba's exact Fresnel"));
        assert!(xml.contains("Readings: provenance not recorded"));
        // A simulated scan's scene says so, with the recording that answered.
        let mut simulated = s.clone();
        simulated.origin = Some(crate::study::Origin {
            station: None,
            measured_at_ms: 0,
            provenance: crate::store::Provenance {
                ma_t12: crate::store::InstrumentProvenance {
                    simulated: Some(true),
                    ..crate::store::InstrumentProvenance::unknown()
                },
                source: crate::store::Source::Measured,
                source_detail: Some("simulated — replayed from synthetic-t-sky-blue".into()),
                ..crate::store::Provenance::unknown()
            },
        });
        let xml = cf1_scene(&simulated, d);
        roxmltree::Document::parse(&xml).unwrap();
        assert!(
            xml.contains("Readings: simulated — replayed from synthetic-t-sky-blue."),
            "{xml}"
        );
        let exact = DoneFit {
            fresnel: FresnelCosine::Exact,
            ..d.clone()
        };
        let xml = cf1_scene(&s, &exact);
        assert!(xml.contains("Fresnel exact"));
        assert!(xml.contains("so Mitsuba's BSDF is brdfd's model"));
        assert!(!xml.contains("Not exact"), "{xml}");
        // A model option's extra term is named as left out, with its fitted values.
        let rough = DoneFit {
            model: crate::model::ModelKind::OrenNayar,
            params: crate::model::Params {
                extra: [0.25, 0.0],
                ..exact.params
            },
            ..exact.clone()
        };
        let xml = cf1_scene(&s, &rough);
        roxmltree::Document::parse(&xml).unwrap();
        assert!(
            xml.contains("Not exact: model oren-nayar: its rough diffuse factor (σ = 0.2500 rad)"),
            "{xml}"
        );
        // A two-lobe fit draws its second lobe: three terms at ⅓ each, nothing left out.
        let two = DoneFit {
            model: crate::model::ModelKind::TwoLobe,
            params: crate::model::Params {
                extra: [0.3, 0.5],
                ..exact.params
            },
            ..exact.clone()
        };
        let xml = cf1_scene(&s, &two);
        let doc = roxmltree::Document::parse(&xml).unwrap();
        assert!(!xml.contains("Not exact"), "{xml}");
        let lobes: Vec<(f64, f64)> = doc
            .descendants()
            .filter(|n| n.attribute("type") == Some("roughconductor"))
            .map(|n| {
                let value = |name: &str| {
                    n.children()
                        .find(|c| c.attribute("name") == Some(name))
                        .and_then(|c| c.attribute("value")?.parse().ok())
                        .unwrap()
                };
                (value("alpha"), value("specular_reflectance"))
            })
            .collect();
        let third = |ks: f64| 3.0 * ks * 4.0 / std::f64::consts::PI;
        let want = [(two.params.alpha, third(two.params.ks)), (0.5, third(0.3))];
        assert_eq!(lobes.len(), 2, "{xml}");
        for (got, want) in lobes.iter().zip(want) {
            assert_eq!(got.0, want.0);
            assert!(
                (got.1 - want.1).abs() < 1e-12 * want.1,
                "{got:?} vs {want:?}"
            );
        }
        assert!(xml.contains(r#"<float name="weight" value="0.6666666666666666"/>"#));
        assert!(xml.contains(&format!(
            "400:{}",
            3.0 * std::f64::consts::PI * two.params.kd[0]
        )));
        let names: Vec<String> = scenes(
            &crate::study::Study {
                samples: vec![s.clone()],
            },
            &ExportOptions::default(),
        )
        .unwrap()
        .into_iter()
        .map(|(n, _)| n)
        .collect();
        assert_eq!(names.len(), 2, "m2 failed, so two scenes: {names:?}");
    }
}
