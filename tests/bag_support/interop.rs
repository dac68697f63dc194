//! The interop tests' fixture: a simulated run, the bags `rosbags` makes of it, the
//! reference decoder's findings on an output MCAP.

use super::*;
use serde_json::Value;

/// The contract's tolerance between a bag and its JSON Lines: 0.01 degree.
pub const ATTITUDE_TOL: f64 = 0.01 * std::f64::consts::PI / 180.0;

/// A simulated run and the bags made of it.
pub struct Fixture {
    pub dir: TempDir,
    pub python: String,
    pub scans: String,
}

impl Fixture {
    /// 6 random office poses, 3 scans each (simulate's defaults: 181 rays, 1 cm noise).
    pub fn new(test: &str) -> Option<Fixture> {
        let python = python_or_skip(test)?;
        let dir = TempDir::new(test);
        let scans = dir.join("scans.jsonl");
        let plan = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/plans/office.wall");
        ok_stdout(&[
            "simulate", plan, "--random", "6", "--seed", "7", "-o", &scans,
        ]);
        Some(Fixture { dir, python, scans })
    }

    /// Writes the scans as a bag with write_bag.py; returns its path.
    pub fn bag(&self, name: &str, format: &str, extra: &[&str]) -> String {
        let out = self.dir.join(name);
        let mut args = vec![self.scans.as_str(), out.as_str(), "--format", format];
        args.extend_from_slice(extra);
        run_script(&self.python, "write_bag.py", &args);
        out
    }

    /// check_output.py's findings on an output MCAP (the script fails on a broken file).
    pub fn check(&self, mcap: &str, extra: &[&str]) -> Value {
        let mut args = vec![mcap];
        args.extend_from_slice(extra);
        serde_json::from_str(&run_script(&self.python, "check_output.py", &args)).unwrap()
    }
}

pub fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("{v} is not a number"))
}

/// `level BAG` must give the poses and attitudes `level SCANS.jsonl` gives.
pub fn assert_same_levels(bag: &[Value], jsonl: &[Value], case: &str) {
    assert_eq!(bag.len(), jsonl.len(), "{case}: poses");
    for (k, (b, j)) in bag.iter().zip(jsonl).enumerate() {
        assert_eq!(b["sequence"], k as u64, "{case}: pose {k}'s sequence");
        let (lb, lj) = (&b["level"], &j["level"]);
        assert_eq!(lb["status"], lj["status"], "{case}: pose {k}: {lb} vs {lj}");
        assert_eq!(b["nrays"], j["nrays"], "{case}: pose {k}");
        if lj["status"] == "ok" {
            for key in ["theta_x", "theta_y"] {
                let d = (f(&lb[key]) - f(&lj[key])).abs();
                assert!(
                    d <= ATTITUDE_TOL,
                    "{case}: pose {k}: {key} differs by {d} rad"
                );
            }
        }
    }
}
