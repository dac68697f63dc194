//! Visualization (paper sect. 7.2.3): static plots, the 3D viewer page and reports.

pub mod histogram;
