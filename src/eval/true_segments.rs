//! The maximum-likelihood core ([`crate::level::ml`]) fed the true segmentation: the simulator's
//! `hit` labels, with each wall hit's plane from the nearest plan wall ([`super::bound`]'s
//! rays). How close it comes to the Cramér-Rao bound, in error and in sigma, is what the core
//! is worth before any segmentation is searched for; the leveler's own gap to it is what
//! finding the surfaces costs.

use super::bound::{BoundRay, Surface as BoundSurface};
use crate::level::ml::{self, LabelledPoint, MlParams, Surface};
use nalgebra::Vector3;

/// What the core found at one pose: the attitude and its 1-sigmas \[rad\], the inflation
/// its chi-square test applied, and whether it converged.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrueSegmentsFit {
    pub attitude: [f64; 2],
    pub sigmas: [f64; 2],
    pub inflation: f64,
    pub converged: bool,
}

/// The rays as labelled points with range noise `sigma` \[m\] (their measured ranges).
pub(crate) fn labelled_points(rays: &[BoundRay], sigma: f64) -> Vec<LabelledPoint> {
    rays.iter()
        .map(|r| LabelledPoint {
            origin: r.origin,
            dir: r.dir,
            range: r.measured,
            sigma,
            surface: match r.surface {
                BoundSurface::Wall(k) => Surface::Wall(k),
                BoundSurface::Floor => Surface::Floor,
                BoundSurface::Ceiling => Surface::Ceiling,
            },
        })
        .collect()
}

/// Refines up from `start` (robot frame) on the true segmentation; `None` when the surfaces
/// cannot fix the attitude.
pub fn fit_true_segments(
    rays: &[BoundRay],
    sigma: f64,
    start: &Vector3<f64>,
) -> Option<TrueSegmentsFit> {
    let points = labelled_points(rays, sigma);
    let sol = ml::refine(&points, start, &MlParams::default()).ok()?;
    Some(TrueSegmentsFit {
        attitude: sol.attitude,
        sigmas: sol.sigmas(),
        inflation: sol.inflation,
        converged: sol.converged,
    })
}
