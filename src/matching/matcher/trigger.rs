//! When `Coarse::Auto` runs the coarse search: when ICP from the odometry guess fails a check,
//! or when its share of inlier points falls well below what this run's recent matches
//! reached.
//!
//! The share of a scan's points that find a partner within the kernel scale depends on the
//! sensor and the place (range noise, clutter, glass, open doors) far more than on whether
//! ICP found the right basin: on the CARMEN ACES log it is below 0.8 on nearly every scan,
//! on simulated rooms above 0.95. A fixed share therefore ran the search on 99% of ACES'
//! scans and 61% of Intel's, where it changed little. A wrong basin shows as a drop against
//! the scans just before (which saw nearly the same place), so the trigger compares the
//! share with the median of the last [`HISTORY`] accepted matches'.

use std::collections::VecDeque;

/// Accepted matches whose inlier shares make the run's recent level [-].
const HISTORY: usize = 16;

/// The inlier shares of the run's recent accepted matches.
#[derive(Clone, Debug, Default)]
pub(super) struct CoarseTrigger {
    recent: VecDeque<f64>,
}

impl CoarseTrigger {
    /// The share below which the coarse search runs: `ratio` times the recent median, or
    /// `ratio` itself until [`HISTORY`] matches have been seen (a share of 1 as the level).
    pub fn threshold(&self, ratio: f64) -> f64 {
        if self.recent.len() < HISTORY {
            return ratio;
        }
        // A copy on the stack: the median is taken once per scan, without allocating.
        let mut shares = [0.0; HISTORY];
        for (s, &r) in shares.iter_mut().zip(&self.recent) {
            *s = r;
        }
        let mid = HISTORY / 2;
        let (_, median, _) = shares.select_nth_unstable_by(mid, f64::total_cmp);
        ratio * *median
    }

    /// Notes an accepted match's inlier share.
    pub fn record(&mut self, share: f64) {
        if !share.is_finite() {
            return;
        }
        if self.recent.len() == HISTORY {
            self.recent.pop_front();
        }
        self.recent.push_back(share);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absolute_until_the_history_fills_then_relative_to_its_median() {
        let mut t = CoarseTrigger::default();
        for _ in 0..HISTORY - 1 {
            t.record(0.5);
        }
        assert_eq!(t.threshold(0.8), 0.8);
        t.record(0.5);
        assert!((t.threshold(0.8) - 0.4).abs() < 1e-12);
        // The oldest shares leave: sixteen more at 0.9 make the median 0.9.
        for _ in 0..HISTORY {
            t.record(0.9);
        }
        assert!((t.threshold(0.8) - 0.72).abs() < 1e-12);
        // One outlier does not move the median.
        t.record(0.0);
        assert!((t.threshold(0.8) - 0.72).abs() < 1e-12);
        t.record(f64::NAN);
        assert_eq!(t.recent.len(), HISTORY);
    }
}
