//! brdfd: spectral BRDF from two handheld instruments.
//!
//! # Layout
//! Science (pure, synchronous, no I/O):
//! - [`spectral`]: the 31-band grid, 400–700 nm.
//! - [`geometry`]: the 14 measurement geometries and their directions.
//! - [`model`]: the spectral Cook–Torrance/GGX model.
//! - [`processing`]: device readings → measured BRDF against the N9 reference.
//! - [`cost`]: the paper's three cost functions (cf1, cf2, m2) of a model against a measurement.
//!
//! Scans and fits (pure, synchronous; file I/O only at the edges):
//! - [`scan`]: the `brdfd.scan/1` scan file, read and written with every field checked.
pub mod geometry;
pub mod model;
pub mod spectral;
pub mod processing;
pub mod cost;
pub mod scan;
