//! Scanners denser than the SICK family's 0.5 degree: their local lines come from the means of
//! runs of rays (`NormalParams::max_rays_per_degree`), where lines fitted over a few raw rays
//! at 0.25 degree spanned too little of a wall to beat the range noise.

mod matching_support;

use levelscan::eval::metrics::ate;
use levelscan::geometry::Pose2;
use levelscan::matching::{Matcher, MatcherParams, Mode, NormalParams};
use matching_support::*;

/// Metascan ATE round the office loop with `nrays` over 180 degrees at 1 cm, odometry off by
/// 2 cm and 1 degree a step, lines from runs of rays denser than `max_rays_per_degree`.
fn loop_ate(nrays: usize, max_rays_per_degree: f64) -> f64 {
    let walls = office();
    let truth = office_loop(120);
    let odo = noisy_odometry(&truth, 0.02, 1f64.to_radians(), 7);
    let mut m = Matcher::new(MatcherParams {
        mode: Mode::Metascan,
        normals: NormalParams {
            max_rays_per_degree,
            ..NormalParams::default()
        },
        ..MatcherParams::default()
    });
    let est: Vec<Pose2> = truth
        .iter()
        .zip(&odo)
        .enumerate()
        .map(|(i, (t, o))| {
            let points = scan_at(t, &walls, nrays, 0.01, 100 + i as u64);
            m.push(&points, Some(*o)).estimate
        })
        .collect();
    let a = ate(&est, &truth).unwrap().rmse;
    eprintln!("{nrays} rays, at most {max_rays_per_degree} a degree: ATE {a}");
    a
}

/// At 0.25 and 0.167 degree (721 and 1081 rays over 180) the dense lines keep metascan as
/// accurate as at the paper's 1 degree; the raw rays' lines did not.
#[test]
fn dense_scans_match_as_well_as_the_papers() {
    let paper = loop_ate(181, 2.0);
    for nrays in [721, 1081] {
        let dense = loop_ate(nrays, 2.0);
        let raw = loop_ate(nrays, 0.0);
        assert!(
            dense < 0.004 && dense < 1.5 * paper,
            "{nrays} rays: {dense} m (181 rays: {paper} m)"
        );
        assert!(
            raw > 2.0 * dense,
            "{nrays} rays: raw lines {raw} m, dense {dense} m"
        );
    }
}

/// A scan at or below the density is matched exactly as before: the setting changes nothing
/// for the paper's scanner or the CARMEN logs' 0.5 degree.
#[test]
fn scans_at_the_sick_densities_are_untouched() {
    for nrays in [181, 361] {
        assert_eq!(
            loop_ate(nrays, 2.0).to_bits(),
            loop_ate(nrays, 0.0).to_bits()
        );
    }
}
