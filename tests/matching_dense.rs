//! Scanners denser than the SICK family's 0.5 degree, or noisier than 1 cm: their local lines
//! come from the means of runs of rays (`NormalParams::max_rays_per_degree`,
//! `NormalParams::range_sigma`), where lines fitted over a few raw rays at 0.25 degree spanned
//! too little of a wall to beat the range noise, and at 5 cm of noise were too thick.

mod matching_support;

use levelscan::eval::metrics::ate;
use levelscan::geometry::Pose2;
use levelscan::matching::{Matcher, MatcherParams, Mode, NormalParams};
use matching_support::*;

/// Metascan ATE round the office loop with `nrays` over 180 degrees at 1 cm, odometry off by
/// 2 cm and 1 degree a step, lines from runs of rays denser than `max_rays_per_degree`.
fn loop_ate(nrays: usize, max_rays_per_degree: f64) -> f64 {
    noisy_loop_ate(nrays, max_rays_per_degree, 0.01, None)
}

/// [`loop_ate`] at `noise` of range noise, each scan stating `stated` as its noise.
fn noisy_loop_ate(nrays: usize, max_rays_per_degree: f64, noise: f64, stated: Option<f64>) -> f64 {
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
            let points = scan_at(t, &walls, nrays, noise, 100 + i as u64);
            m.push_with_sigma(&points, Some(*o), stated).estimate
        })
        .collect();
    let a = ate(&est, &truth).unwrap().rmse;
    eprintln!(
        "{nrays} rays, at most {max_rays_per_degree} a degree, noise {noise} (stated \
         {stated:?}): ATE {a}"
    );
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

/// At 5 and 10 cm of range noise, lines through single rays are mostly too thick to pass: a
/// scan that states its noise fits them through runs of 3 and 5 rays, and metascan round the
/// loop errs less.
#[test]
fn noisy_scans_that_state_their_noise_match_better() {
    for noise in [0.05, 0.1] {
        let told = noisy_loop_ate(181, 2.0, noise, Some(noise));
        let untold = noisy_loop_ate(181, 2.0, noise, None);
        assert!(
            told < 0.6 * untold,
            "{noise} m: told {told} m, untold {untold} m"
        );
    }
}

/// A scan stating the noise the lines are made for (1 cm), or less, is matched exactly as one
/// stating none.
#[test]
fn a_stated_noise_of_1_cm_changes_nothing() {
    let none = noisy_loop_ate(181, 2.0, 0.01, None);
    for stated in [0.005, 0.01, 0.015] {
        assert_eq!(
            noisy_loop_ate(181, 2.0, 0.01, Some(stated)).to_bits(),
            none.to_bits()
        );
    }
}
