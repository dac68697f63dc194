//! The account `level` and `match` give at the end of a run: one line on standard error with
//! the poses leveled and failed (or the scans matched, partly matched and fallen back) by
//! reason, a warning when most of the run failed, and a word when the input held nothing.
//! Without it a run that failed every pose ended with exit 0 and not a word (issue 25).
//!
//! The counts come from the records' own status objects (`level` and `match` in the contract),
//! so the line says what the output says, whatever statuses and reasons the output grows.

use indicatif::ProgressBar;
use levelscan::level::FailCause;
use levelscan::scan::Scan;
use std::collections::BTreeMap;

/// One record's status object: `status` and `reason` as the output spells them.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) struct Outcome {
    pub status: String,
    pub reason: Option<String>,
}

impl Outcome {
    /// The outcome in `record.extra[key]` (`"level"` or `"match"`); `"unknown"` when the
    /// record has none (it always has one: `level_record` and `annotate` write it).
    pub fn of(record: &Scan, key: &str) -> Outcome {
        let object = record.extra.get(key);
        let text = |field: &str| {
            object
                .and_then(|o| o.get(field))
                .and_then(|v| v.as_str())
                .map(str::to_string)
        };
        Outcome {
            status: text("status").unwrap_or_else(|| "unknown".to_string()),
            reason: text("reason"),
        }
    }
}

/// What is counted: poses for `level`, scans for `match`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    Level,
    Match,
}

/// The outcomes of one run, counted.
#[derive(Debug)]
pub(crate) struct Tally {
    kind: Kind,
    counts: BTreeMap<Outcome, usize>,
    total: usize,
    /// `match`: records that fell back as `no_valid_rays` because they are poses `level` could
    /// not level (their `level.status` is failed, so no ray was kept): the warning then blames
    /// the leveling, not the input's kind or units.
    unleveled: usize,
    /// `level`: the `parallel_walls` failures by what lies behind them. The contract has one
    /// reason for every way the gate refuses a pose; which way it was decides what helps.
    gated: BTreeMap<Gated, usize>,
    /// Poses or scans whose stated `readings_sigma` their ranges contradict (set aside).
    noise_set_aside: usize,
    /// Records counted so far, on a terminal's standard error (hidden elsewhere).
    bar: ProgressBar,
}

/// What lies behind a `parallel_walls` failure ([`FailCause`]s grouped by what helps).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Gated {
    /// Up was found, but not within the gate: the surfaces pin it too loosely for the noise.
    Loose,
    /// The walls fix only one tilt axis (or none).
    OneFamily,
    /// Two readings of the same scans lie farther apart than the gate allows.
    Disagree,
    /// Up came out farther from the robot's z axis than walls and floors are told apart by.
    Steep,
}

impl Gated {
    /// The group of a cause the contract reports as `parallel_walls`; `None` for the causes
    /// it reports under their own reasons. Every cause is named, so that a new one is sorted
    /// here when it is added.
    fn of(cause: FailCause) -> Option<Gated> {
        Some(match cause {
            FailCause::SigmaAboveGate => Gated::Loose,
            FailCause::NoUp | FailCause::WallsParallel => Gated::OneFamily,
            FailCause::ResegmentationDisagrees | FailCause::LastStageDisagrees => Gated::Disagree,
            FailCause::BeyondWallAngle => Gated::Steep,
            FailCause::TooFewScans
            | FailCause::InconsistentScans
            | FailCause::TooFewPolygons
            | FailCause::NoWallPatches
            | FailCause::FacingFloor
            | FailCause::FacingCeiling => return None,
        })
    }

    fn label(self) -> &'static str {
        match self {
            Gated::Loose => "sigma above --max-sigma",
            Gated::OneFamily => "walls of one direction",
            Gated::Disagree => "two readings disagree",
            Gated::Steep => "tilt beyond 45 degrees",
        }
    }

    fn hint(self) -> &'static str {
        match self {
            Gated::Loose => {
                "the walls, floor and ceiling in view do not pin roll and pitch within \
                 --max-sigma at this range noise; scans at more elevations per pose, or \
                 elevations farther apart, pin them better; a larger --max-sigma accepts \
                 looser attitudes"
            }
            Gated::OneFamily => "the walls in view all face one way, which pins only one tilt axis",
            Gated::Disagree => {
                "two segmentations of the same scans give attitudes farther apart than \
                 --max-sigma allows (clutter, or much noise for the scans per pose)"
            }
            Gated::Steep => {
                "up came out tilted more than 45 degrees from the robot's z axis, beyond which \
                 walls and floors cannot be told apart; are the elevations in radians and \
                 positive tilting the beam down?"
            }
        }
    }
}

impl Tally {
    pub fn new(kind: Kind) -> Tally {
        let bar = match kind {
            Kind::Level => super::progress::counter("level", "poses"),
            Kind::Match => super::progress::counter("match", "scans"),
        };
        Tally {
            kind,
            counts: BTreeMap::new(),
            total: 0,
            unleveled: 0,
            gated: BTreeMap::new(),
            noise_set_aside: 0,
            bar,
        }
    }

    pub fn add(&mut self, outcome: Outcome) {
        *self.counts.entry(outcome).or_default() += 1;
        self.total += 1;
        self.bar.inc(1);
    }

    /// Counts a `level` output record, with the leveler's `cause` for a failed pose (only the
    /// causes reported as `parallel_walls` are grouped, [`Gated::of`]).
    pub fn add_leveled(&mut self, record: &Scan, cause: Option<FailCause>) {
        if let Some(g) = cause.and_then(Gated::of) {
            *self.gated.entry(g).or_default() += 1;
        }
        self.add(Outcome::of(record, "level"));
    }

    /// Notes a pose or scan whose stated `readings_sigma` was set aside: its ranges contradict
    /// it (a converter's placeholder).
    pub fn note_noise_set_aside(&mut self) {
        self.noise_set_aside += 1;
    }

    /// Counts a `match` output record, noting one that had no ray because `level` failed it.
    pub fn add_matched(&mut self, record: &Scan) {
        let outcome = Outcome::of(record, "match");
        if outcome.reason.as_deref() == Some("no_valid_rays")
            && Outcome::of(record, "level").status == "failed"
        {
            self.unleveled += 1;
        }
        self.add(outcome);
    }

    /// Clears the progress counter and prints [`Tally::lines`] on standard error.
    pub fn report(&self, input: &str) {
        self.bar.finish_and_clear();
        for line in self.lines(input) {
            eprintln!("{line}");
        }
    }

    /// The summary line, then a warning when most of the run failed (or the input was empty).
    pub fn lines(&self, input: &str) -> Vec<String> {
        let command = self.command();
        let (one, many) = self.units();
        if self.total == 0 {
            return vec![format!(
                "levelscan {command}: warning: {input} holds no scans; nothing to {command}"
            )];
        }
        let groups: Vec<String> = self.groups().into_iter().map(|g| g.describe()).collect();
        let unit = if self.total == 1 { one } else { many };
        let mut lines = vec![format!(
            "levelscan {command}: {} {unit}: {}",
            self.total,
            groups.join(", ")
        )];
        lines.extend(self.warning());
        if self.noise_set_aside > 0 {
            let (one, many) = self.units();
            let unit = if self.total == 1 { one } else { many };
            let instead = match self.kind {
                Kind::Level => "the noise estimated from their ranges is used instead",
                Kind::Match => "they are matched as scans that state none",
            };
            lines.push(format!(
                "levelscan {command}: warning: {} of {} {unit} state a range noise \
                 (readings_sigma) over 3 times off the scatter of their own ranges, as \
                 converters' placeholders do: set aside, {instead} (--sigma sets one)",
                self.noise_set_aside, self.total
            ));
        }
        lines
    }

    fn command(&self) -> &'static str {
        match self.kind {
            Kind::Level => "level",
            Kind::Match => "match",
        }
    }

    fn units(&self) -> (&'static str, &'static str) {
        match self.kind {
            Kind::Level => ("pose", "poses"),
            Kind::Match => ("scan", "scans"),
        }
    }

    /// The outcomes gathered by what they mean to a user, in a fixed order; within a group,
    /// reasons by count (most first), then by name.
    fn groups(&self) -> Vec<Group> {
        let mut groups: Vec<Group> = Vec::new();
        for (outcome, &n) in &self.counts {
            let (rank, label, by_reason) = self.label(outcome);
            let group = match groups.iter_mut().position(|g| g.label == label) {
                Some(i) => &mut groups[i],
                None => {
                    groups.push(Group {
                        rank,
                        label,
                        count: 0,
                        reasons: Vec::new(),
                    });
                    groups.last_mut().expect("just pushed")
                }
            };
            group.count += n;
            if by_reason {
                let reason = outcome.reason.clone().unwrap_or_else(|| "none".to_string());
                group.reasons.push((reason, n));
            }
        }
        for g in &mut groups {
            g.reasons
                .sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
        }
        groups.sort_by(|a, b| a.rank.cmp(&b.rank).then_with(|| a.label.cmp(&b.label)));
        groups
    }

    /// (order, words, whether the reasons are listed) for one outcome.
    fn label(&self, o: &Outcome) -> (u8, String, bool) {
        match (self.kind, o.status.as_str(), o.reason.as_deref()) {
            (Kind::Level, "ok", _) => (0, "leveled".to_string(), false),
            (Kind::Level, "failed", _) => (2, "failed".to_string(), true),
            (Kind::Match, "ok", Some("first_scan")) => (3, "first scan".to_string(), false),
            (Kind::Match, "ok", _) => (0, "matched".to_string(), false),
            (Kind::Match, "partial", _) => (1, "partly matched".to_string(), true),
            (Kind::Match, "fallback", _) => (2, "fell back to odometry".to_string(), true),
            (_, other, _) => (4, other.to_string(), true),
        }
    }

    /// Failed, or fallen back: the outcomes that gave the user nothing of the command's own.
    fn failures(&self) -> Vec<(String, usize)> {
        let failed = match self.kind {
            Kind::Level => "failed",
            Kind::Match => "fallback",
        };
        let mut by_reason: Vec<(String, usize)> = self
            .counts
            .iter()
            .filter(|(o, _)| o.status == failed)
            .map(|(o, &n)| (o.reason.clone().unwrap_or_else(|| "none".to_string()), n))
            .collect();
        by_reason.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
        by_reason
    }

    /// A warning when more than half of the run failed. For `match` the first scan is left
    /// out: it has nothing to be matched against, so two scans of which the second fell back
    /// failed whole.
    fn warning(&self) -> Option<String> {
        let failures = self.failures();
        let failed: usize = failures.iter().map(|(_, n)| n).sum();
        let first = self
            .counts
            .iter()
            .filter(|(o, _)| self.label(o).1 == "first scan")
            .map(|(_, &n)| n)
            .sum::<usize>();
        let attempted = self.total - first;
        if attempted == 0 || 2 * failed <= attempted {
            return None;
        }
        let (_, many) = self.units();
        let verb = match self.kind {
            Kind::Level => "failed",
            Kind::Match => "fell back to odometry",
        };
        let (top, top_count) = &failures[0];
        let mut line = format!(
            "levelscan {}: warning: {failed} of {attempted} {many} {verb}, most often {top}",
            self.command()
        );
        if self.kind == Kind::Match && top == "no_valid_rays" && self.unleveled > 0 {
            line.push_str(&format!(
                ": {} {} poses level could not level (level.status failed: no ray kept); see \
                 level's summary for why: more scans per pose, or simulate --adaptive, level \
                 more of them",
                self.unleveled,
                if self.unleveled == 1 { "is" } else { "are" }
            ));
            let others = top_count - self.unleveled;
            if others > 0 {
                line.push_str(&format!(
                    "; the other {others}: {}",
                    hint(self.kind, top).unwrap_or_default()
                ));
            }
        } else if self.kind == Kind::Level && top == "parallel_walls" && !self.gated.is_empty() {
            // By count, most first; ties in the enum's order.
            let mut gated: Vec<(Gated, usize)> = self.gated.iter().map(|(g, n)| (*g, *n)).collect();
            gated.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
            let split: Vec<String> = gated
                .iter()
                .map(|(g, n)| format!("{} {n}", g.label()))
                .collect();
            line.push_str(&format!(" ({}): {}", split.join(", "), gated[0].0.hint()));
        } else if let Some(hint) = hint(self.kind, top) {
            line.push_str(": ");
            line.push_str(hint);
        }
        Some(line)
    }
}

impl Drop for Tally {
    /// A run that stops on an error clears its counter too, before the error is printed.
    fn drop(&mut self) {
        self.bar.finish_and_clear();
    }
}

/// A group of the summary line: `48 leveled` or `2 failed (too_few_scans 2)`.
#[derive(Debug)]
struct Group {
    rank: u8,
    label: String,
    count: usize,
    reasons: Vec<(String, usize)>,
}

impl Group {
    fn describe(&self) -> String {
        if self.reasons.is_empty() {
            return format!("{} {}", self.count, self.label);
        }
        let reasons: Vec<String> = self
            .reasons
            .iter()
            .map(|(r, n)| format!("{r} {n}"))
            .collect();
        format!("{} {} ({})", self.count, self.label, reasons.join(", "))
    }
}

/// What usually lies behind the most common failure, for the warning.
fn hint(kind: Kind, reason: &str) -> Option<&'static str> {
    Some(match (kind, reason) {
        (Kind::Level, "too_few_scans") => {
            "a pose needs scans at three or more distinct elevations; check the scans' \
             elevation values (simulate: --scans 3 or more, a --step other than 0)"
        }
        (Kind::Level, "inconsistent_scans") => "the scans of a pose must have the same nrays",
        (Kind::Level, "too_few_polygons") => {
            "too few wall patches in view; is the noise right (--sigma, readings_sigma) and are \
             the elevations in radians?"
        }
        (Kind::Level, "facing_floor" | "facing_ceiling") => {
            "the scanner sees more floor or ceiling than walls; use smaller elevations"
        }
        (Kind::Level, "parallel_walls") => {
            "the walls in view all face one way, which pins only one tilt axis"
        }
        (Kind::Match, "no_valid_rays") => {
            "no reading within --min-range and --max-range; are the scans leveled (level's \
             output) and the ranges in metres?"
        }
        (
            Kind::Match,
            "too_few_correspondences" | "degenerate" | "high_residual" | "large_correction",
        ) => {
            "consecutive scans must overlap: a robot's path, not unrelated poses (simulate \
             --random draws poses at random)"
        }
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn outcome(status: &str, reason: Option<&str>) -> Outcome {
        Outcome {
            status: status.to_string(),
            reason: reason.map(str::to_string),
        }
    }

    fn tally(kind: Kind, items: &[(&str, Option<&str>, usize)]) -> Tally {
        let mut t = Tally::new(kind);
        for &(s, r, n) in items {
            for _ in 0..n {
                t.add(outcome(s, r));
            }
        }
        t
    }

    #[test]
    fn outcome_is_read_from_the_records_status_object() {
        let mut scan = Scan::default();
        scan.extra.insert(
            "level".to_string(),
            json!({"status": "failed", "reason": "too_few_scans", "theta_x": null}),
        );
        assert_eq!(
            Outcome::of(&scan, "level"),
            outcome("failed", Some("too_few_scans"))
        );
        assert_eq!(Outcome::of(&scan, "match"), outcome("unknown", None));
    }

    #[test]
    fn level_counts_leveled_and_failed_by_reason() {
        let t = tally(
            Kind::Level,
            &[
                ("ok", None, 46),
                ("failed", Some("parallel_walls"), 1),
                ("failed", Some("too_few_polygons"), 3),
            ],
        );
        assert_eq!(
            t.lines("in.jsonl"),
            [
                "levelscan level: 50 poses: 46 leveled, 4 failed (too_few_polygons 3, parallel_walls 1)"
            ]
        );
    }

    #[test]
    fn every_pose_failed_warns_with_the_reason_and_a_hint() {
        let t = tally(Kind::Level, &[("failed", Some("too_few_scans"), 2)]);
        assert_eq!(
            t.lines("<stdin>"),
            [
                "levelscan level: 2 poses: 2 failed (too_few_scans 2)",
                "levelscan level: warning: 2 of 2 poses failed, most often too_few_scans: a \
                 pose needs scans at three or more distinct elevations; check the scans' \
                 elevation values (simulate: --scans 3 or more, a --step other than 0)"
            ]
        );
    }

    /// A leveled or failed record as `level_record` writes its status object.
    fn level_record(status: &str, reason: Option<&str>) -> Scan {
        let mut scan = Scan::default();
        scan.extra.insert(
            "level".to_string(),
            json!({"status": status, "reason": reason}),
        );
        scan
    }

    #[test]
    fn parallel_walls_is_explained_by_what_lies_behind_it() {
        let mut t = Tally::new(Kind::Level);
        t.add_leveled(&level_record("ok", None), None);
        let failed = level_record("failed", Some("parallel_walls"));
        for cause in [
            FailCause::SigmaAboveGate,
            FailCause::SigmaAboveGate,
            FailCause::NoUp,
            FailCause::LastStageDisagrees,
        ] {
            t.add_leveled(&failed, Some(cause));
        }
        let lines = t.lines("in.jsonl");
        // The summary line says what the records say; the warning, why.
        assert_eq!(
            lines[0],
            "levelscan level: 5 poses: 1 leveled, 4 failed (parallel_walls 4)"
        );
        assert_eq!(
            lines[1],
            "levelscan level: warning: 4 of 5 poses failed, most often parallel_walls (sigma \
             above --max-sigma 2, walls of one direction 1, two readings disagree 1): the \
             walls, floor and ceiling in view do not pin roll and pitch within --max-sigma at \
             this range noise; scans at more elevations per pose, or elevations farther apart, \
             pin them better; a larger --max-sigma accepts looser attitudes"
        );
        // Walls of one direction, the most common: the hint is theirs.
        let mut t = Tally::new(Kind::Level);
        for cause in [
            FailCause::WallsParallel,
            FailCause::NoUp,
            FailCause::SigmaAboveGate,
        ] {
            t.add_leveled(&failed, Some(cause));
        }
        assert!(
            t.lines("f")[1].ends_with(
                "(walls of one direction 2, sigma above --max-sigma 1): the walls in view all \
                 face one way, which pins only one tilt axis"
            ),
            "{:?}",
            t.lines("f")
        );
        // Another reason's count is not split.
        let mut t = Tally::new(Kind::Level);
        t.add_leveled(
            &level_record("failed", Some("too_few_polygons")),
            Some(FailCause::TooFewPolygons),
        );
        assert!(!t.lines("f")[1].contains("sigma above"));
    }

    #[test]
    fn half_failed_is_not_most() {
        let t = tally(
            Kind::Level,
            &[("ok", None, 2), ("failed", Some("facing_floor"), 2)],
        );
        assert_eq!(t.lines("f").len(), 1);
        let t = tally(
            Kind::Level,
            &[("ok", None, 2), ("failed", Some("facing_floor"), 3)],
        );
        assert_eq!(t.lines("f").len(), 2);
    }

    #[test]
    fn match_groups_first_matched_partial_and_fallback() {
        let t = tally(
            Kind::Match,
            &[
                ("ok", Some("first_scan"), 1),
                ("ok", None, 10),
                ("partial", Some("degenerate"), 2),
                ("fallback", Some("degenerate"), 1),
                ("fallback", Some("too_few_correspondences"), 3),
            ],
        );
        assert_eq!(
            t.lines("log"),
            [
                "levelscan match: 17 scans: 10 matched, 2 partly matched (degenerate 2), 4 fell \
                 back to odometry (too_few_correspondences 3, degenerate 1), 1 first scan"
            ]
        );
    }

    #[test]
    fn match_warning_leaves_the_first_scan_out() {
        let t = tally(
            Kind::Match,
            &[
                ("ok", Some("first_scan"), 1),
                ("fallback", Some("too_few_correspondences"), 1),
            ],
        );
        let lines = t.lines("log");
        assert_eq!(lines.len(), 2);
        assert!(
            lines[1].starts_with(
                "levelscan match: warning: 1 of 1 scans fell back to odometry, most often \
                 too_few_correspondences: consecutive scans must overlap"
            ),
            "{lines:?}"
        );
        // A single scan has nothing to match against: no warning.
        let t = tally(Kind::Match, &[("ok", Some("first_scan"), 1)]);
        assert_eq!(t.lines("log"), ["levelscan match: 1 scan: 1 first scan"]);
    }

    /// A `match` record with a `level` object of `level_status` that fell back as `reason`.
    fn matched_record(level_status: &str, status: &str, reason: Option<&str>) -> Scan {
        let mut scan = Scan::default();
        scan.extra
            .insert("level".into(), json!({"status": level_status}));
        scan.extra
            .insert("match".into(), json!({"status": status, "reason": reason}));
        scan
    }

    #[test]
    fn no_valid_rays_of_poses_level_failed_blames_the_leveling() {
        let mut t = Tally::new(Kind::Match);
        t.add_matched(&matched_record("ok", "ok", Some("first_scan")));
        t.add_matched(&matched_record("ok", "ok", None));
        for _ in 0..3 {
            t.add_matched(&matched_record("failed", "fallback", Some("no_valid_rays")));
        }
        assert_eq!(
            t.lines("level.jsonl")[1],
            "levelscan match: warning: 3 of 4 scans fell back to odometry, most often \
             no_valid_rays: 3 are poses level could not level (level.status failed: no ray \
             kept); see level's summary for why: more scans per pose, or simulate --adaptive, \
             level more of them"
        );
        // A leveled record without rays is still the input's fault.
        t.add_matched(&matched_record("ok", "fallback", Some("no_valid_rays")));
        assert!(
            t.lines("level.jsonl")[1].ends_with(
                "; the other 1: no reading within --min-range and --max-range; are the scans \
                 leveled (level's output) and the ranges in metres?"
            ),
            "{:?}",
            t.lines("level.jsonl")
        );
    }

    #[test]
    fn an_empty_input_says_so() {
        assert_eq!(
            Tally::new(Kind::Level).lines("empty.jsonl"),
            ["levelscan level: warning: empty.jsonl holds no scans; nothing to level"]
        );
        assert_eq!(
            Tally::new(Kind::Match).lines("<stdin>"),
            ["levelscan match: warning: <stdin> holds no scans; nothing to match"]
        );
    }

    #[test]
    fn unknown_statuses_are_named_as_written() {
        let t = tally(Kind::Match, &[("ok", None, 3), ("odd", Some("why"), 1)]);
        assert_eq!(
            t.lines("x"),
            ["levelscan match: 4 scans: 3 matched, 1 odd (why 1)"]
        );
    }
}
