//! Scan matching (paper sect. 2.2 and 8.2): ICP point-to-point and point-to-line, pairwise and
//! against a growing map (metascan).
//!
//! - [`solve`]: the exact closed-form least-squares motion for both metrics (Censi 2008).
//! - [`reference`](mod@reference): match targets: a scan with line normals and a search grid.
//! - `grid`: exact nearest-neighbour search in a hashed uniform grid (ICP's association).
//! - [`icp`](mod@icp): the ICP loop with trimming (Chetverikov et al. 2002) and a robust kernel.
//! - [`correlative`]: the coarse correlative search (Olson 2009) that widens the basin.
//! - [`map`]: the bounded voxel map for metascan matching.
//! - [`covariance`]: the match's covariance (sandwich estimator, Censi 2007).
//! - `dense`: local lines of scans denser than they are built for, from runs of rays.
//! - [`deskew`](mod@deskew): each ray moved to where the scanner was at the scan's stamp (the
//!   robot's motion during the sweep).
//! - `degeneracy`: where the odometry anchors a degeneracy-aware solve (solution remapping,
//!   Zhang, Kaess and Singh 2016, in [`solve`]) and whether a match slid where the scan lets it.
//! - [`params`]: the matcher's settings.
//! - [`report`]: what each scan's match reports.
//! - [`matcher`]: a run of scans, one at a time, with fallback to odometry (its `align`: one
//!   match, the coarse search, the odometry prior or anchor, and the checks).
//!
//! All of it is pure: points and poses in, poses and reports out.

pub mod correlative;
pub mod covariance;
pub(crate) mod degeneracy;
pub(crate) mod dense;
pub mod deskew;
pub(crate) mod grid;
pub mod icp;
pub mod map;
pub mod matcher;
pub mod params;
pub mod reference;
pub mod report;
pub mod solve;

pub use correlative::{
    CorrelativeParams, CorrelativeScratch, correlative_search, correlative_search_with,
};
pub use covariance::{CovarianceParams, rays_per_degree};
pub use dense::LineRuns;
pub use deskew::{DeskewParams, RayTiming, SweepMotion, SweepTracker, deskew, deskew_summary};
pub use icp::{IcpParams, IcpResult, Kernel, Metric, icp, icp_with_prior};
pub use map::{MapParams, VoxelMap};
pub use matcher::{
    FallbackReason, MatchReport, MatchStatus, Matcher, match_run, odometry_step, scan_points,
    timed_scan_points,
};
pub use params::{CheckParams, Coarse, MatcherParams, Mode, OdometryPrior, RangeParams};
pub use reference::{Line, NormalParams, ScanReference, Target, estimate_lines};
pub use solve::PosePrior;
