//! Study reports: the paper's figures 4–12 and statistics (SCIENCE.md §8–9) from a [`Study`].
//!
//! - [`study`]: the in-memory study model (samples, measured BRDF, fits per cost function).

pub mod study;

pub use study::{DoneFit, FitState, FitStudy, SampleStudy, Study};
