//! Golden corpus of the leveler: a fixed, deterministic set of simulated poses is leveled and
//! every pose's outcome is compared with `tests/golden/level_poses.jsonl`. Any decision that
//! moves (a status or failure reason, an angle or sigma beyond 1e-9 rad, a ray the pseudo-level
//! scan keeps or drops, the base scan, the counts of quads and patches) fails the test, which
//! names the pose and the field. It pins today's behaviour so that the leveler can be
//! restructured without changing what it decides.
//!
//! The corpus: every example plan and the holdout plans, random poses drawn as `eval accuracy`
//! draws them (tilt up to 25 degrees, so that some poses face the floor or see too little),
//! at 1, 3 and 5 cm of Gaussian noise with 3 and 5 scans and at 10 cm with 3 and 4; some with the paper's estimator, with
//! `readings_sigma` given, with uniform noise, with a hinge offset, and with two scans only
//! (too_few_scans). 800 poses, under a second in release.
//!
//! Regenerate (after a change meant to alter outputs, and say so in its commit):
//! `LEVELSCAN_BLESS=1 cargo test --release --test level_golden`.
//! Each line holds the pose's id, then the per-stage trace (range sigma, quads, patches, base
//! scan), the status, the attitude and sigmas \[rad\], and the kept-ray mask in hex (bit `i` of
//! the mask is ray `i` of the pseudo-level scan, four rays per hex digit, ray 0 first).

use levelscan::geometry::Pose;
use levelscan::level::{Estimator, LevelEstimate, LevelParams, level_pose};
use levelscan::plan::Plan;
use levelscan::pseudo_level::{PseudoLevelParams, pseudo_level_scan};
use levelscan::simulate::{
    NoiseModel, RandomPoseParams, ScannerParams, Stream, World, elevations_centred, random_poses,
    simulate_pose, stream_rng,
};
use serde_json::{Value, json};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Angles and sigmas must agree to this \[rad\]; the range sigma to this \[m\].
const TOLERANCE: f64 = 1e-9;

/// The golden file.
fn golden_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden/level_poses.jsonl")
}

/// Plans of the corpus: the example plans and the holdout plans, by path under examples/plans.
const PLANS: [&str; 10] = [
    "office",
    "angled",
    "ceiling",
    "two_rooms",
    "corridor",
    "holdout/l_room",
    "holdout/zigzag",
    "holdout/hall",
    "holdout/dividers",
    "holdout/hexagon_ceiling",
];

fn plan(name: &str) -> Plan {
    let path = format!("{}/examples/plans/{name}.wall", env!("CARGO_MANIFEST_DIR"));
    levelscan::formats::read_plan(path.as_ref()).unwrap()
}

/// One variant of how a pose is scanned and leveled.
struct Variant {
    tag: &'static str,
    scans: usize,
    noise: f64,
    model: NoiseModel,
    estimator: Estimator,
    write_sigma: bool,
    hinge_offset: Option<[f64; 3]>,
    /// Which poses of the plan (by index) this variant levels.
    poses: std::ops::Range<usize>,
}

fn variants() -> Vec<Variant> {
    let base = |tag, scans, noise, poses| Variant {
        tag,
        scans,
        noise,
        model: NoiseModel::Gaussian,
        estimator: Estimator::Robust,
        write_sigma: false,
        hinge_offset: None,
        poses,
    };
    let mut out = Vec::new();
    for (scans, noise, tag) in [
        (3, 0.01, "s3n1"),
        (3, 0.03, "s3n3"),
        (3, 0.05, "s3n5"),
        (5, 0.01, "s5n1"),
        (5, 0.03, "s5n3"),
        (5, 0.05, "s5n5"),
        (3, 0.10, "s3n10"),
        (4, 0.10, "s4n10"),
    ] {
        out.push(base(tag, scans, noise, 0..8));
    }
    out.push(Variant {
        estimator: Estimator::Paper,
        ..base("paper_s4n1", 4, 0.01, 0..3)
    });
    out.push(Variant {
        estimator: Estimator::Paper,
        ..base("paper_s4n5", 4, 0.05, 0..3)
    });
    out.push(Variant {
        write_sigma: true,
        ..base("given_s4n3", 4, 0.03, 0..3)
    });
    out.push(Variant {
        model: NoiseModel::Uniform,
        ..base("uniform_s4n5", 4, 0.05, 0..3)
    });
    out.push(Variant {
        hinge_offset: Some([0.05, 0.0, 0.03]),
        ..base("hinge_s4n3", 4, 0.03, 0..3)
    });
    out.push(base("two_scans", 2, 0.01, 0..1));
    out
}

/// The kept-ray mask of a pseudo-level scan, four rays per hex digit, ray 0 in the lowest bit
/// of the first digit.
fn mask_hex(valid: &[bool]) -> String {
    valid
        .chunks(4)
        .map(|c| {
            let v = c
                .iter()
                .enumerate()
                .fold(0u32, |acc, (i, &b)| acc | (u32::from(b) << i));
            char::from_digit(v, 16).unwrap()
        })
        .collect()
}

fn record(id: &str, est: &LevelEstimate, kept: &[bool]) -> Value {
    let status = est.failure.map_or("ok", |f| f.as_str());
    let (roll, pitch) = est.attitude.map_or((Value::Null, Value::Null), |a| {
        (json!(a.theta_x), json!(a.theta_y))
    });
    let sigmas = est.sigmas.map_or(Value::Null, |s| json!([s[0], s[1]]));
    json!({
        "id": id,
        "range_sigma": est.range_sigma,
        "quads": est.quads.len(),
        "wall_quads": est.wall_polygons(),
        "patches": est.patches.len(),
        "base": est.base_scan,
        "status": status,
        "roll": roll,
        "pitch": pitch,
        "sigmas": sigmas,
        "kept": mask_hex(kept),
    })
}

/// Levels the whole corpus, one record per pose, in a fixed order.
fn corpus() -> Vec<Value> {
    let pose_params = RandomPoseParams {
        tilt: 25f64.to_radians(),
        ..RandomPoseParams::default()
    };
    let variants = variants();
    let most = variants.iter().map(|v| v.poses.end).max().unwrap_or(0);
    let mut out = Vec::new();
    for (pi, name) in PLANS.iter().enumerate() {
        let plan = plan(name);
        let world = World::from_plan(&plan);
        let poses: Vec<Pose> = random_poses(&world, most, &pose_params, 1000 + pi as u64).unwrap();
        for v in &variants {
            let scanner = ScannerParams {
                noise_sigma: v.noise,
                noise_model: v.model,
                write_sigma: v.write_sigma,
                hinge_offset: v.hinge_offset,
                ..ScannerParams::default()
            };
            let params = LevelParams {
                estimator: v.estimator,
                ..LevelParams::default()
            };
            let elevations = elevations_centred(v.scans, 5f64.to_radians());
            for k in v.poses.clone() {
                let stream = 7 + ((pi as u64) << 32) + ((v.scans as u64) << 48);
                let mut rng = stream_rng(stream, Stream::Scans, k as u64);
                let scans =
                    simulate_pose(&world, k as u64, &poses[k], &elevations, &scanner, &mut rng);
                let est = level_pose(&scans, &params);
                let pseudo = pseudo_level_scan(&scans, &est, &PseudoLevelParams::default());
                let id = format!("{name}/{}/{k}", v.tag);
                out.push(record(&id, &est, &pseudo.valid));
            }
        }
    }
    out
}

/// Differences of one record from its golden twin, as `field: got vs want` lines.
fn differences(got: &Value, want: &Value) -> Vec<String> {
    let (Some(g), Some(w)) = (got.as_object(), want.as_object()) else {
        return vec!["not an object".into()];
    };
    let mut out = Vec::new();
    let keys: std::collections::BTreeSet<&String> = g.keys().chain(w.keys()).collect();
    for key in keys {
        let (a, b) = (g.get(key), w.get(key));
        if !same(a.unwrap_or(&Value::Null), b.unwrap_or(&Value::Null)) {
            out.push(format!("{key}: got {a:?}, golden {b:?}"));
        }
    }
    out
}

/// Equal values, numbers within `TOLERANCE` (integers exactly).
fn same(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) if x.is_f64() || y.is_f64() => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            (x - y).abs() <= TOLERANCE
        }
        (Value::Array(x), Value::Array(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(a, b)| same(a, b))
        }
        _ => a == b,
    }
}

#[test]
fn every_pose_of_the_corpus_levels_as_the_golden_file_says() {
    let records = corpus();
    let path = golden_path();
    if std::env::var("LEVELSCAN_BLESS").is_ok_and(|v| v == "1") {
        let text: String = records.iter().map(|r| format!("{r}\n")).collect();
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, text).unwrap();
        eprintln!("blessed {} poses into {}", records.len(), path.display());
        return;
    }
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("{}: {e} (LEVELSCAN_BLESS=1 writes it)", path.display()));
    let golden: BTreeMap<String, Value> = text
        .lines()
        .map(|l| {
            let v: Value = serde_json::from_str(l).unwrap();
            (v["id"].as_str().unwrap().to_string(), v)
        })
        .collect();
    assert_eq!(golden.len(), records.len(), "pose count");
    let mut report = Vec::new();
    for r in &records {
        let id = r["id"].as_str().unwrap();
        match golden.get(id) {
            None => report.push(format!("{id}: not in the golden file")),
            Some(want) => report.extend(
                differences(r, want)
                    .into_iter()
                    .map(|d| format!("{id}: {d}")),
            ),
        }
    }
    assert!(
        report.is_empty(),
        "{} differences from the golden file, first ones:\n{}",
        report.len(),
        report[..report.len().min(30)].join("\n")
    );
}

/// The corpus must exercise what it pins: leveled poses, each failure the simulated rooms
/// produce, and the pseudo-level scan's masks.
#[test]
fn the_golden_file_covers_successes_and_failures() {
    if std::env::var("LEVELSCAN_BLESS").is_ok_and(|v| v == "1") {
        return; // being rewritten by the other test
    }
    let text = std::fs::read_to_string(golden_path()).unwrap();
    let mut statuses: BTreeMap<String, usize> = BTreeMap::new();
    for l in text.lines() {
        let v: Value = serde_json::from_str(l).unwrap();
        *statuses
            .entry(v["status"].as_str().unwrap().to_string())
            .or_default() += 1;
    }
    for s in ["ok", "too_few_scans", "parallel_walls"] {
        assert!(
            statuses.get(s).is_some_and(|&n| n > 0),
            "no {s}: {statuses:?}"
        );
    }
    assert!(statuses["ok"] >= 200, "{statuses:?}");
    assert!(text.len() < 300_000, "golden file {} bytes", text.len());
}
