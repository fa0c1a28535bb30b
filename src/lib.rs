//! brdfd: spectral BRDF from two handheld instruments.
//!
//! # Layout
//! Science (pure, synchronous, no I/O):
//! - [`spectral`]: the 31-band grid, 400–700 nm.
//! - [`geometry`]: the 14 measurement geometries and their directions.
//! - [`model`]: the spectral Cook–Torrance/GGX model.
//! - [`processing`]: device readings → measured BRDF against the N9 reference.
//! - [`cost`]: the paper's three cost functions (cf1, cf2, m2) of a model against a measurement.
//! - [`optimise`]: fits the 34 model parameters: the paper's GA and the default separable search;
//!   the presets (`measured`, `paper`) of the fit's science choices.
//! - [`colour`]: spectra → CIE XYZ/CIELAB (D65, 2°), CIEDE2000, 8-bit sRGB swatches.
//! - [`evaluation`]: ΔE00 between measured and estimated BRDF per geometry, with summaries.
//! - [`stats`]: study statistics: mean ΔE00 with 95 % t interval, exact sign test; the one
//!   standard normal draw the noise and the bootstrap share.
//! - [`uncertainty`]: parameter intervals of a fit by a parametric bootstrap widened by a
//!   leave-one-geometry-out jackknife, and their calibration (SCIENCE.md §10).
//! - [`crossval`]: leave-one-geometry-out cross-validation of a fit (`brdfd crossval`).
//!
//! Scans and fits (pure, synchronous; file I/O only at the edges):
//! - [`scan`]: the `brdfd.scan/1` scan file, read and written with every field checked.
//! - [`synth`]: synthetic scans from a known ground truth (ColorChecker spectra, matt lobes).
//! - [`gonio`]: measured goniometric BRDFs (ASTM E1392, RGL `.bsdf`) and `brdfd validate`:
//!   the handheld estimate against them.
//! - [`fit`]: one scan → processing → optimiser → ΔE00 evaluation, and the fit report (JSON).
//! - [`reach`]: whether a scan's material is in the model's reach, from its readings and fit,
//!   with the prediction error to expect (calibrated with `brdfd validate`).
//! - [`study`]: the study model (per sample: scan, measured BRDF, one fit per cost function) and
//!   its loader from a store; what reports, exports and previews are built from.
//! - [`report`]: study reports: the paper's figures 4–12 and Fig. 13 (PNG, SVG), statistics, HTML/Markdown.
//! - [`formats`]: exchange formats: CGATS.17, CxF3, CSV, JSON exports; instrument-software imports.
//! - [`render`]: spectral sphere previews of fitted materials (PNG).
//! - [`fonts`]: the embedded typeface of every figure and preview.
//! - [`names`]: file-name slugs of sample names; the names of the fit's choices.
//! - [`safe_fs`]: every file written outside the store: no links followed, never onto the store.
//!
//! Command line:
//! - [`cli`]: the `brdfd` subcommands (`fit`, `synth`, `demo`, …); `src/main.rs` only runs it.
//!
//! Service (async at the edges):
//! - [`config`]: `brdfd.toml` → a checked [`config::Config`]; defaults run on simulated devices.
//! - [`store`]: the SQLite store (sqlx, embedded migrations): scans, readings, references, fits.
//! - [`service`]: the daemon: scan orchestrator (both instruments at once, every reading stored
//!   as it arrives), fit worker (blocking threads behind a semaphore), events, shutdown.
//! - [`api`]: the local HTTP API (axum) and its server-sent event stream.
//! - [`wire`]: the API's request and answer types, the one contract of the daemon and its client.
//! - [`client`]: the operator commands' side of the HTTP API (`brdfd scan`, `scans`, …).
//! - [`sync`]: forwarding the store to the lab's central PostgreSQL database (several stations).
pub mod api;
pub mod cli;
pub mod client;
pub mod colour;
pub mod config;
pub mod cost;
pub mod crossval;
pub mod evaluation;
pub mod fit;
pub mod fonts;
pub mod formats;
pub mod geometry;
pub mod gonio;
pub mod model;
pub mod names;
pub mod optimise;
pub mod processing;
pub mod reach;
pub mod render;
pub mod report;
pub mod safe_fs;
pub mod scan;
pub mod service;
pub mod spectral;
pub mod sra_reading;
pub mod stats;
pub mod store;
pub mod study;
pub mod sync;
pub mod synth;
#[cfg(test)]
pub(crate) mod test_support;
pub mod uncertainty;
pub mod wire;
