//! glTF 2.0 materials of fitted BRDFs (`brdfd export-format --format gltf`): one `.gltf` file
//! per finished fit, a metallic-roughness material on a UV sphere (mesh data embedded as a
//! base64 data URI), an orthographic camera framing it like the preview, for Blender, three.js
//! and game engines. Checked with the Khronos glTF-Validator (`tests/export_gltf.rs`).
//!
//! The mapping (SCIENCE.md §11) is an approximation, and the file says so in `extras`:
//! - `baseColorFactor`: the diffuse albedo π·kd(λ) under D65 → XYZ (CIE 15 sums, 31 bands) →
//!   linear sRGB (glTF colour factors are linear), clamped to [0, 1]; the spectrum itself is
//!   kept in `extras.brdfd.kd`. glTF's BRDF is RGB.
//! - `metallicFactor` 0 (a dielectric); `roughnessFactor` = √α (glTF's α is roughness²).
//! - `KHR_materials_ior`: `ior` = μ.
//! - `KHR_materials_specular`: `specularFactor` = 4·ks/π, the strength of brdfd's lobe relative
//!   to the standard `F·D·G/(4 cosθi cosθr)` microfacet lobe, clamped to [0, 1] (the extension's
//!   range). glTF's Fresnel is Schlick on the microfacet normal (v·h), brdfd's on cosθi.
//! - glTF mixes diffuse and specular by energy (the diffuse is weighted by 1 − F), brdfd adds
//!   them: the glTF diffuse is slightly darker, most at grazing angles.

use std::fmt::Write as _;

use serde_json::json;

use crate::colour::{brdf_to_reflectance, reflectance_to_xyz};
use crate::study::{DoneFit, SampleStudy, Study};

use super::{ExportOptions, FormatError};

/// XYZ (Y = 1 white) → linear sRGB, IEC 61966-2-1 (the swatches' matrix).
const XYZ_TO_LINEAR_SRGB: [[f64; 3]; 3] = [
    [3.2406, -1.5372, -0.4986],
    [-0.9689, 1.8758, 0.0415],
    [0.0557, -0.2040, 1.0570],
];

/// Latitude and longitude segments of the sphere mesh.
const LAT: u32 = 32;
const LON: u32 = 64;

/// The material's glTF parameters and what was clamped.
#[derive(Debug, Clone, PartialEq)]
pub struct GltfMaterial {
    /// Linear sRGB, clamped to [0, 1].
    pub base_color: [f64; 3],
    /// Whether the albedo was outside [0, 1] in some channel before clamping.
    pub base_color_clamped: bool,
    pub roughness: f64,
    pub ior: f64,
    pub specular_factor: f64,
    pub specular_clamped: bool,
}

impl GltfMaterial {
    pub fn of(fit: &DoneFit) -> GltfMaterial {
        let xyz = reflectance_to_xyz(&brdf_to_reflectance(&fit.params.kd));
        let v = [xyz.x / 100.0, xyz.y / 100.0, xyz.z / 100.0];
        let linear = XYZ_TO_LINEAR_SRGB.map(|r| r[0] * v[0] + r[1] * v[1] + r[2] * v[2]);
        let spec = 4.0 * fit.params.ks / std::f64::consts::PI;
        GltfMaterial {
            base_color: linear.map(|c| c.clamp(0.0, 1.0)),
            base_color_clamped: linear.iter().any(|c| !(0.0..=1.0).contains(c)),
            roughness: fit.params.alpha.sqrt().clamp(0.0, 1.0),
            ior: fit.params.ior,
            specular_factor: spec.clamp(0.0, 1.0),
            specular_clamped: !(0.0..=1.0).contains(&spec),
        }
    }
}

/// RFC 4648 base64 with padding.
fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(A[((n >> (18 - 6 * i)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// A unit UV sphere: positions (= normals) as f32 and u16 triangle indices, counter-clockwise
/// seen from outside, no degenerate triangles at the poles.
fn sphere() -> (Vec<[f32; 3]>, Vec<u16>) {
    let mut pos = Vec::new();
    for i in 0..=LAT {
        let theta = std::f64::consts::PI * f64::from(i) / f64::from(LAT);
        for j in 0..=LON {
            let phi = 2.0 * std::f64::consts::PI * f64::from(j) / f64::from(LON);
            pos.push([
                (theta.sin() * phi.cos()) as f32,
                theta.cos() as f32,
                (-theta.sin() * phi.sin()) as f32,
            ]);
        }
    }
    let at = |i: u32, j: u32| (i * (LON + 1) + j) as u16;
    let mut idx = Vec::new();
    for i in 0..LAT {
        for j in 0..LON {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            if i != 0 {
                idx.extend_from_slice(&[a, b, d]);
            }
            if i != LAT - 1 {
                idx.extend_from_slice(&[b, c, d]);
            }
        }
    }
    (pos, idx)
}

/// The glTF document of one finished fit.
pub fn document(
    sample: &SampleStudy,
    cost: crate::cost::CostFunction,
    method: &str,
    fit: &DoneFit,
    opts: &ExportOptions,
) -> serde_json::Value {
    let m = GltfMaterial::of(fit);
    let (pos, idx) = sphere();
    let mut bin = Vec::new();
    for p in &pos {
        for c in p {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    let pos_len = bin.len();
    // On a unit sphere the normal is the position.
    bin.extend_from_slice(&bin.clone());
    let idx_offset = bin.len();
    for i in &idx {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let idx_len = bin.len() - idx_offset;
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let mut min = [f32::MAX; 3];
    let mut max = [f32::MIN; 3];
    for p in &pos {
        for c in 0..3 {
            min[c] = min[c].min(p[c]);
            max[c] = max[c].max(p[c]);
        }
    }
    let p = &fit.params;
    let mut notes = String::new();
    let _ = write!(
        notes,
        "RGB approximation of brdfd's spectral model (brdfd SCIENCE.md §11): baseColor is the diffuse albedo under D65 in linear sRGB{}; roughness = sqrt(alpha); specularFactor = 4·ks/π{}; glTF mixes diffuse and specular by energy, brdfd adds them.",
        if m.base_color_clamped {
            " (clamped to [0, 1])"
        } else {
            ""
        },
        if m.specular_clamped {
            " (clamped to 1)"
        } else {
            ""
        }
    );
    if let Some(omitted) = fit.model.export_omission(&p.extra) {
        let _ = write!(notes, " Also {omitted}.");
    }
    json!({
        "asset": {
            "version": "2.0",
            "generator": opts.originator,
            "extras": {
                "brdfd": {
                    "sample": sample.name,
                    "cost_function": cost.name(),
                    "method": method,
                    "created": opts.created,
                    "scale": sample.scale().name(),
                    "scale_note": sample.scale().describe(),
                    // How the readings came in: "simulated — replayed from …" for a simulated
                    // instrument's, so a file read later cannot pass for a measurement.
                    "provenance": sample.provenance_summary(),
                    "simulated": sample.simulated(),
                    "approximation": notes,
                    "kd_sr-1": p.kd.to_vec(),
                    "wavelengths_nm": crate::spectral::wavelengths_nm().to_vec(),
                    "ks": p.ks,
                    "alpha": p.alpha,
                    "ior": p.ior,
                    "model": fit.model.name(),
                    "fresnel": fit.fresnel.name(),
                }
            }
        },
        "extensionsUsed": ["KHR_materials_ior", "KHR_materials_specular"],
        "scene": 0,
        "scenes": [{"nodes": [0, 1]}],
        "nodes": [
            {"name": "sphere", "mesh": 0},
            {"name": "camera", "camera": 0, "translation": [0.0, 0.0, 5.0]}
        ],
        "cameras": [{
            "type": "orthographic",
            "orthographic": {"xmag": 1.05, "ymag": 1.05, "znear": 0.1, "zfar": 10.0}
        }],
        "meshes": [{
            "name": format!("{} ({cost})", sample.name),
            "primitives": [{
                "attributes": {"POSITION": 0, "NORMAL": 1},
                "indices": 2,
                "material": 0,
                "mode": 4
            }]
        }],
        "materials": [{
            "name": format!("{} {cost}", sample.name),
            "pbrMetallicRoughness": {
                "baseColorFactor": [m.base_color[0], m.base_color[1], m.base_color[2], 1.0],
                "metallicFactor": 0.0,
                "roughnessFactor": m.roughness
            },
            "extensions": {
                "KHR_materials_ior": {"ior": m.ior},
                "KHR_materials_specular": {
                    "specularFactor": m.specular_factor,
                    "specularColorFactor": [1.0, 1.0, 1.0]
                }
            }
        }],
        "buffers": [{
            "byteLength": bin.len(),
            "uri": format!("data:application/octet-stream;base64,{}", base64(&bin))
        }],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": pos_len, "target": 34962},
            {"buffer": 0, "byteOffset": pos_len, "byteLength": pos_len, "target": 34962},
            {"buffer": 0, "byteOffset": idx_offset, "byteLength": idx_len, "target": 34963}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": pos.len(), "type": "VEC3",
             "min": min, "max": max},
            {"bufferView": 1, "componentType": 5126, "count": pos.len(), "type": "VEC3"},
            {"bufferView": 2, "componentType": 5123, "count": idx.len(), "type": "SCALAR"}
        ]
    })
}

/// Every finished fit of the study as `(file name, bytes)`: `<sample>-<cost>.gltf`.
pub fn files(study: &Study, opts: &ExportOptions) -> Result<Vec<(String, Vec<u8>)>, FormatError> {
    let mut out = Vec::new();
    for s in &study.samples {
        for f in &s.fits {
            if let Some(d) = f.done() {
                let name = format!("{}-{}.gltf", crate::names::slug(&s.name), f.cost);
                let doc = document(s, f.cost, &f.method, d, opts);
                let text =
                    serde_json::to_vec_pretty(&doc).map_err(|e| FormatError::Unwritable {
                        format: "gltf",
                        message: e.to_string(),
                    })?;
                out.push((name, text));
            }
        }
    }
    if out.is_empty() {
        return Err(FormatError::Unwritable {
            format: "gltf",
            message: "no finished fit in the selection: nothing to export".into(),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc_4648_test_vectors() {
        for (plain, coded) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(plain.as_bytes()), coded);
        }
    }

    #[test]
    fn the_material_maps_alpha_ks_and_a_grey_albedo() {
        let s = crate::render::tests::sample(false);
        let mut d = s.done(crate::cost::CostFunction::Cf1).unwrap().clone();
        d.params.kd = [0.18 / std::f64::consts::PI; 31];
        d.params.alpha = 0.25;
        d.params.ks = 0.5;
        let m = GltfMaterial::of(&d);
        // A flat 0.18 reflectance is neutral grey 0.18 in linear sRGB (to the 4-decimal
        // matrix and brdfd's 31-band white, SCIENCE.md §7).
        for c in m.base_color {
            assert!((c - 0.18).abs() < 0.002, "{:?}", m.base_color);
        }
        assert_eq!(m.roughness, 0.5);
        assert!((m.specular_factor - 2.0 / std::f64::consts::PI).abs() < 1e-15);
        let (pos, idx) = sphere();
        assert_eq!(pos.len(), ((LAT + 1) * (LON + 1)) as usize);
        assert_eq!(idx.len(), (3 * 2 * LON * (LAT - 1)) as usize);
    }
    /// The file says how its readings came in: "simulated — replayed from …" for a simulated
    /// instrument's, so a glTF read later cannot pass for a measurement.
    #[test]
    fn the_document_says_whether_the_readings_were_simulated() {
        let mut s = crate::render::tests::sample(false);
        let d = s.done(crate::cost::CostFunction::Cf1).unwrap().clone();
        let opts = ExportOptions::default();
        let doc = document(&s, crate::cost::CostFunction::Cf1, "separable", &d, &opts);
        assert_eq!(doc["asset"]["extras"]["brdfd"]["simulated"], false);
        assert!(doc["asset"]["extras"]["brdfd"]["provenance"].is_null());
        s.origin = Some(crate::study::Origin {
            station: None,
            measured_at_ms: 0,
            provenance: crate::store::Provenance {
                sra: crate::store::InstrumentProvenance {
                    simulated: Some(true),
                    ..crate::store::InstrumentProvenance::unknown()
                },
                source: crate::store::Source::Measured,
                source_detail: Some("simulated — replayed from synthetic-t-sky-blue".into()),
                ..crate::store::Provenance::unknown()
            },
        });
        let doc = document(&s, crate::cost::CostFunction::Cf1, "separable", &d, &opts);
        let brdfd = &doc["asset"]["extras"]["brdfd"];
        assert_eq!(brdfd["simulated"], true);
        assert_eq!(
            brdfd["provenance"],
            "simulated — replayed from synthetic-t-sky-blue"
        );
    }
}
