//! Fuzzing the `.wall` floor plan reader (`formats::wall`), in the pattern of
//! `tests/fuzz_support`: arbitrary bytes and text, byte mutations of the seeds in
//! `tests/fuzz/corpus/wall/` (commented plans as in the paper's Fig. 14 among them), and
//! structured mutations (JSON values edited, then laid out compact, pretty or with comments).
//!
//! The oracle: no panic, no hang; an error is one line naming the file; and "no garbage
//! accepted": a plan read passes `Plan::validate`, writes back (`write_plan`) to a plan that
//! reads back the same (angles to the rounding of degrees and back), and the simulator's
//! scene and inside tests take it (`World::from_plan`, `is_free` at its points).

mod fuzz_support;
use fuzz_support::*;

use levelscan::formats::{parse_plan, read_plan_from, write_plan};
use levelscan::simulate::{World, is_free};
use nalgebra::Point2;
use proptest::prelude::*;
use proptest::sample::Index;
use serde_json::Value;
use std::io::Cursor;

const FILE: &str = "fuzz.wall";
const ALPHABET: &str = "{}[],:\" \n\t0123456789.-+eE/wallheightposesceilingversionnulltruef";
const TOKENS: &[&str] = &[
    "{",
    "}",
    "[",
    "]",
    ",",
    ":",
    "\"",
    "//",
    "// c\n",
    "/",
    "\n",
    "null",
    "true",
    "\"walls\": ",
    "\"wallheight\": ",
    "\"poses\": ",
    "\"ceiling\": ",
    "\"version\": ",
    "[[0,0],[0,0]]",
    "[0, 0]",
    "\"w0.1\"",
    "\u{feff}",
];
const FIELDS: &[&str] = &["version", "wallheight", "walls", "poses", "ceiling", "note"];

/// The seed without its `//` comments (the seeds have none inside strings).
fn uncommented(text: &str) -> String {
    text.lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n")
}

fn structured(seeds: Vec<Vec<u8>>) -> impl Strategy<Value = Vec<u8>> {
    (
        prop::sample::select(seeds),
        json_edits(),
        0u8..3,
        any::<Index>(),
    )
        .prop_map(|(seed, edits, layout, at)| {
            let text = String::from_utf8(seed).expect("seeds are UTF-8");
            let mut plan: Value =
                serde_json::from_str(&uncommented(&text)).expect("seeds are JSON");
            apply_json_edits(&mut plan, &edits, FIELDS);
            let text = match layout {
                0 => plan.to_string(),
                _ => serde_json::to_string_pretty(&plan).unwrap(),
            };
            if layout == 2 {
                // A comment at the end of one line, as in the paper's figure.
                let mut lines: Vec<String> = text.lines().map(String::from).collect();
                let i = at.index(lines.len());
                lines[i].push_str(" // a \"comment\", [with] {brackets}");
                return lines.join("\n").into_bytes();
            }
            text.into_bytes()
        })
}

fn oracle(input: &[u8]) -> Result<Outcome, String> {
    let plan = match read_plan_from(Cursor::new(input), FILE) {
        Ok(plan) => plan,
        Err(e) => {
            check_message(&e.to_string(), FILE, line_count(input))?;
            return Ok(Outcome::Refused(0));
        }
    };
    plan.validate()
        .map_err(|e| format!("read, but invalid: {e}"))?;
    let text = write_plan(&plan);
    let back = parse_plan(&text, "written.wall")
        .map_err(|e| format!("{text}\ndoes not read back: {e}"))?;
    let close = |u: f64, v: f64| (u - v).abs() <= 1e-14 * v.abs().max(1.0);
    let poses_back = back.poses.len() == plan.poses.len()
        && back.poses.iter().zip(&plan.poses).all(|(a, b)| {
            a.to_array()
                .iter()
                .zip(b.to_array())
                .all(|(u, v)| close(*u, v))
        });
    if back.wall_height != plan.wall_height
        || back.walls != plan.walls
        || back.ceiling != plan.ceiling
        || !poses_back
    {
        return Err(format!("{text}\nreads back as {back:?}, not {plan:?}"));
    }
    let world = World::from_plan(&plan);
    let points = plan.walls.iter().flatten().copied();
    for p in points
        .chain(plan.poses.iter().map(|p| Point2::new(p.x, p.y)))
        .take(64)
    {
        is_free(&world, &p, 0.5, 30.0);
    }
    Ok(Outcome::Accepted(1))
}

#[test]
fn fuzz_wall() {
    let seeds = corpus("wall");
    for s in &seeds {
        assert_eq!(oracle(s), Ok(Outcome::Accepted(1)), "seeds are valid");
    }
    run(
        "wall",
        inputs(seeds.clone(), ALPHABET, TOKENS, structured(seeds)),
        oracle,
    );
}
