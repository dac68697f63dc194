//! levelscan: planar laser localization on floors that are not flat.
//!
//! Implements and extends J. Saunders, "Dealing with uneven floors during planar robot
//! localization" (University of Cape Town, 2008). Modules follow the paper:
//!
//! - [`geometry`], [`scan`], [`plan`]: frames, poses, scans and floor plans (sect. 3.4, App. B).
//! - [`simulate`]: the laser scan simulator and the adaptive robot, "cleverRobot" (sect. 7.2).
//! - [`level`]: level estimation: wall polygons, the up vector, attitude, failure (sect. 5).
//! - [`pseudo_level`]: pseudo-level scans (sect. 6).
//! - [`matching`]: ICP scan matching, pairwise and metascan (sect. 2.2, 8.2).
//! - [`eval`]: the paper's experiments and trajectory metrics (sect. 8).
//! - [`viz`]: plots, the 3D viewer and reports (sect. 7.2.3).
//! - [`occupancy`]: occupancy grids from matched scans (ROS map_server maps).
//! - [`formats`]: scan JSON Lines (CSM), `.wall`, CARMEN and TUM files, maps and point clouds.
//!
//! The algorithm modules are pure functions on plain types; all I/O lives in [`formats`] and
//! the command line.

pub mod eval;
pub mod formats;
pub mod geometry;
pub mod level;
pub mod matching;
pub mod occupancy;
pub mod plan;
pub mod pseudo_level;
pub mod scan;
pub mod simulate;
pub mod viz;
