//! When simulated scans were taken: the simulator's clock, so that its scans carry
//! `timestamp` like a real log's and a trajectory written from them (TUM, `match
//! --trajectory`, `--reference-trajectory`) has real times that tools such as evo associate.
//!
//! The same clock as the contract's simulated bags: pose `k` starts at
//! [`START_S`] + k [`POSE_PERIOD_S`] and its scans follow [`SCAN_PERIOD_S`] apart, in the
//! order they were taken (a retaken scan after the first set).

use crate::scan::Timestamp;

/// Time of the first pose's first scan [s]: 1000 s, away from 0 so that no time is mistaken
/// for "unset".
pub const START_S: i64 = 1000;
/// Time from one pose to the next [s]: the paper's robot stops, scans and drives on.
pub const POSE_PERIOD_S: i64 = 2;
/// Time between two scans of a pose [us]: 0.1 s, a 10 Hz scanner. A pose of more than 20
/// scans runs into the next pose's time.
pub const SCAN_PERIOD_US: i64 = 100_000;

/// The timestamp of scan `index` (in the order taken) of the pose with `sequence`; exact in
/// whole microseconds (no rounding of seconds through f64).
pub fn scan_timestamp(sequence: u64, index: usize) -> Timestamp {
    let us = index as i64 * SCAN_PERIOD_US;
    Timestamp {
        sec: START_S + POSE_PERIOD_S * sequence as i64 + us / 1_000_000,
        usec: us % 1_000_000,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poses_start_two_seconds_apart_and_scans_a_tenth_apart() {
        assert_eq!(scan_timestamp(0, 0), Timestamp { sec: 1000, usec: 0 });
        assert_eq!(
            scan_timestamp(3, 4),
            Timestamp {
                sec: 1006,
                usec: 400_000
            }
        );
        assert_eq!(
            scan_timestamp(1, 12),
            Timestamp {
                sec: 1003,
                usec: 200_000
            }
        );
        assert_eq!(scan_timestamp(7, 5).seconds(), 1014.5);
    }
}
