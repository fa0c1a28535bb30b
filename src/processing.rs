//! From device readings to measured BRDF (SCIENCE.md §3).
//!
//! MA-T12 readings are divided by the Munsell N9 reference reading at the same geometry;
//! SRA readings are normalised by the reference and spread flat over the 31 bands.
//! The result is a measured BRDF `M_g(λ) = R_g(λ) / π` in sr⁻¹ at all 14 geometries.

use crate::geometry::GEOMETRY_COUNT;
use crate::spectral::Spectrum;

/// Measured BRDF, sr⁻¹, at all 14 geometries in [`crate::geometry::GEOMETRIES`] order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuredBrdf {
    pub values: [Spectrum; GEOMETRY_COUNT],
}
