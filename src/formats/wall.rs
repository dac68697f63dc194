//! `.wall` floor plans (the paper's Fig. 14): JSON with `version`, `wallheight` (m), `walls`
//! (polylines of `[x, y]` points, m), optional `poses` (`[x, y, z, rz, ry, rx]`, metres and
//! DEGREES) and optional `ceiling`. Angles become radians in [`Plan`].
//!
//! The paper shows the format as commented JSON, and it is meant to be edited by hand, so `//`
//! comments are accepted (and ignored). Errors name the JSON path (`walls[3]`, `poses[2][4]`);
//! syntax errors name the line.

use super::{InputError, json_error_message};
use crate::geometry::Pose;
use crate::plan::Plan;
use nalgebra::Point2;
use serde_json::Value;
use std::fmt::Write as _;
use std::io::Read;
use std::path::Path;

/// The only version there is (the paper's).
pub const WALL_VERSION: &str = "w0.1";

/// Largest `.wall` file read \[bytes\]: 256 MiB. A plan of a million wall segments takes
/// about 40 MB; a larger file is not a floor plan.
pub const MAX_PLAN_BYTES: u64 = 256 << 20;

/// Reads and validates a `.wall` file. The error's file is `path` as given.
pub fn read_plan(path: &Path) -> Result<Plan, InputError> {
    let name = path.display().to_string();
    let file = std::fs::File::open(path)
        .map_err(|e| InputError::new(&name, "", format!("cannot open: {e}")))?;
    read_plan_from(file, &name)
}

/// Reads and validates a `.wall` plan from `reader` (at most [`MAX_PLAN_BYTES`]); `name` is
/// used in error messages.
pub fn read_plan_from(reader: impl Read, name: &str) -> Result<Plan, InputError> {
    let mut bytes = Vec::new();
    reader
        .take(MAX_PLAN_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| InputError::new(name, "", format!("cannot read: {e}")))?;
    let kind = super::kind::sniff(&bytes[..bytes.len().min(1 << 16)]);
    if matches!(
        kind,
        super::kind::FileKind::Mcap
            | super::kind::FileKind::Ros1Bag
            | super::kind::FileKind::Sqlite
            | super::kind::FileKind::Gzip
    ) {
        return Err(super::kind::wrong_kind(
            name,
            kind,
            "a floor plan (.wall) is wanted",
        ));
    }
    let text = String::from_utf8(bytes)
        .map_err(|_| InputError::new(name, "", "is not valid UTF-8 text"))?;
    if text.len() as u64 > MAX_PLAN_BYTES {
        return Err(InputError::new(
            name,
            "",
            format!(
                "is larger than {} MiB, the limit for a floor plan",
                MAX_PLAN_BYTES >> 20
            ),
        ));
    }
    parse_plan(&text, name)
}

/// Parses and validates the text of a `.wall` file; `name` is used in error messages.
pub fn parse_plan(text: &str, name: &str) -> Result<Plan, InputError> {
    // A byte order mark (editors on Windows write one) is no JSON: serde would stop at it.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let kind = super::kind::sniff(&text.as_bytes()[..text.len().min(1 << 16)]);
    use super::kind::FileKind;
    if !matches!(
        kind,
        FileKind::FloorPlan | FileKind::Unknown | FileKind::Empty
    ) {
        return Err(super::kind::wrong_kind(
            name,
            kind,
            "a floor plan (.wall) is wanted",
        ));
    }
    let value: Value = serde_json::from_str(&strip_comments(text))
        .map_err(|e| InputError::at_line(name, e.line().max(1), json_error_message(&e)))?;
    let err = |path: &str, msg: String| InputError::new(name, path, msg);
    let Value::Object(top) = value else {
        return Err(InputError::at_line(
            name,
            1,
            "a floor plan is a JSON object with `wallheight` and `walls`",
        ));
    };

    match top.get("version") {
        None | Some(Value::Null) => {}
        Some(Value::String(v)) if v == WALL_VERSION => {}
        Some(v) => {
            return Err(err(
                "version",
                format!("unsupported version {v}; this reads \"{WALL_VERSION}\""),
            ));
        }
    }
    let wall_height = match top.get("wallheight") {
        None => {
            return Err(err(
                "wallheight",
                "missing: the height of the walls in metres".into(),
            ));
        }
        Some(v) => number(v).ok_or_else(|| err("wallheight", expected("a number", v)))?,
    };
    let walls_value = top
        .get("walls")
        .ok_or_else(|| err("walls", "missing: a list of polylines [[x, y], ...]".into()))?;
    let walls = walls(walls_value, name)?;
    let poses = match top.get("poses") {
        None | Some(Value::Null) => Vec::new(),
        Some(v) => poses(v, name)?,
    };
    let ceiling = match top.get("ceiling") {
        None | Some(Value::Null) => false,
        Some(Value::Bool(b)) => *b,
        Some(v) => return Err(err("ceiling", expected("true or false", v))),
    };
    let plan = Plan {
        wall_height,
        walls,
        ceiling,
        poses,
    };
    plan.validate()
        .map_err(|e| InputError::new(name, e.path, e.message))?;
    Ok(plan)
}

/// `walls`: polylines of `[x, y]` points (their sizes are checked by [`Plan::validate`]).
fn walls(value: &Value, name: &str) -> Result<Vec<Vec<Point2<f64>>>, InputError> {
    let list = value
        .as_array()
        .ok_or_else(|| InputError::new(name, "walls", expected("an array of polylines", value)))?;
    let mut walls = Vec::with_capacity(list.len());
    for (i, wall) in list.iter().enumerate() {
        let path = format!("walls[{i}]");
        let points = wall.as_array().ok_or_else(|| {
            InputError::new(name, &path, expected("an array of [x, y] points", wall))
        })?;
        let mut polyline = Vec::with_capacity(points.len());
        for (j, p) in points.iter().enumerate() {
            let [x, y] = numbers::<2>(p, &format!("{path}[{j}]"), name, "an [x, y] point")?;
            polyline.push(Point2::new(x, y));
        }
        walls.push(polyline);
    }
    Ok(walls)
}

/// `poses`: `[x, y, z, rz, ry, rx]` in metres and degrees, angles made radians.
fn poses(value: &Value, name: &str) -> Result<Vec<Pose>, InputError> {
    let list = value
        .as_array()
        .ok_or_else(|| InputError::new(name, "poses", expected("an array of poses", value)))?;
    let mut poses = Vec::with_capacity(list.len());
    for (i, p) in list.iter().enumerate() {
        let [x, y, z, rz, ry, rx] = numbers::<6>(
            p,
            &format!("poses[{i}]"),
            name,
            "a pose [x, y, z, rz, ry, rx] (metres, degrees)",
        )?;
        poses.push(Pose::new(
            x,
            y,
            z,
            rz.to_radians(),
            ry.to_radians(),
            rx.to_radians(),
        ));
    }
    Ok(poses)
}

/// Writes a plan as `.wall` text (pose angles in degrees), one wall and one pose per line.
pub fn write_plan(plan: &Plan) -> String {
    let num = |v: f64| serde_json::to_string(&v).unwrap_or_else(|_| "null".into());
    let mut out = String::new();
    out.push_str("{\n");
    let _ = writeln!(out, "  \"version\": \"{WALL_VERSION}\",");
    let _ = writeln!(out, "  \"wallheight\": {},", num(plan.wall_height));
    let _ = writeln!(out, "  \"ceiling\": {},", plan.ceiling);
    out.push_str("  \"walls\": [");
    for (i, wall) in plan.walls.iter().enumerate() {
        out.push_str(if i == 0 { "\n    [" } else { ",\n    [" });
        for (j, p) in wall.iter().enumerate() {
            let sep = if j == 0 { "" } else { ", " };
            let _ = write!(out, "{sep}[{}, {}]", num(p.x), num(p.y));
        }
        out.push(']');
    }
    out.push_str(if plan.walls.is_empty() {
        "],\n"
    } else {
        "\n  ],\n"
    });
    out.push_str("  \"poses\": [");
    for (i, p) in plan.poses.iter().enumerate() {
        out.push_str(if i == 0 { "\n    [" } else { ",\n    [" });
        let values = [
            p.x,
            p.y,
            p.z,
            p.rz.to_degrees(),
            p.ry.to_degrees(),
            p.rx.to_degrees(),
        ];
        for (j, v) in values.iter().enumerate() {
            let sep = if j == 0 { "" } else { ", " };
            let _ = write!(out, "{sep}{}", num(*v));
        }
        out.push(']');
    }
    out.push_str(if plan.poses.is_empty() {
        "]\n"
    } else {
        "\n  ]\n"
    });
    out.push_str("}\n");
    out
}

fn number(v: &Value) -> Option<f64> {
    v.as_f64()
}

/// `what was expected, and what was there`, for messages.
fn expected(what: &str, v: &Value) -> String {
    let found = match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    };
    format!("expected {what}, found {found}")
}

/// An array of exactly `N` finite numbers; errors name the entry (`poses[2][4]`).
fn numbers<const N: usize>(
    v: &Value,
    path: &str,
    name: &str,
    what: &str,
) -> Result<[f64; N], InputError> {
    let list = v
        .as_array()
        .ok_or_else(|| InputError::new(name, path, expected(what, v)))?;
    if list.len() != N {
        return Err(InputError::new(
            name,
            path,
            format!("expected {what}: {N} numbers, found {}", list.len()),
        ));
    }
    let mut out = [0.0; N];
    for (k, item) in list.iter().enumerate() {
        let here = format!("{path}[{k}]");
        out[k] = number(item)
            .filter(|x| x.is_finite())
            .ok_or_else(|| InputError::new(name, &here, expected("a finite number", item)))?;
    }
    Ok(out)
}

/// Blanks out `//` comments outside strings, keeping every newline so that syntax errors
/// still point at the right line.
fn strip_comments(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut in_string = false;
    let mut escaped = false;
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        if in_string {
            out.push(c);
            if escaped {
                escaped = false;
            } else if c == '\\' {
                escaped = true;
            } else if c == '"' {
                in_string = false;
            }
        } else if c == '/' && chars.peek() == Some(&'/') {
            for rest in chars.by_ref() {
                if rest == '\n' {
                    out.push('\n');
                    break;
                }
            }
        } else {
            in_string = c == '"';
            out.push(c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const ROOM: &str = r#"{
  "version": "w0.1",
  "wallheight": 3.0,
  "walls": [
    [[0, 0], [0, 8], [8, 8], [8, 0], [0, 0]],
    [[4, 4], [4, 5], [5, 5], [5, 4], [4, 4]]
  ],
  "poses": [[2, 2, 0.5, 45, 0, 0], [3, 4, 0.5, 90, 10, -5]]
}"#;

    fn parse_err(text: &str) -> String {
        parse_plan(text, "room.wall").unwrap_err().to_string()
    }

    #[test]
    fn a_byte_order_mark_before_the_plan_is_skipped() {
        let plan = parse_plan(&format!("\u{feff}{ROOM}"), "room.wall").unwrap();
        assert_eq!(plan, parse_plan(ROOM, "room.wall").unwrap());
    }

    #[test]
    fn papers_fig14_plan_is_read_with_angles_in_radians() {
        let plan = parse_plan(ROOM, "room.wall").unwrap();
        assert_eq!(plan.wall_height, 3.0);
        assert!(!plan.ceiling);
        assert_eq!(plan.walls.len(), 2);
        assert_eq!(plan.walls[0].len(), 5);
        assert_eq!(plan.walls[0][2], Point2::new(8.0, 8.0));
        assert_eq!(plan.poses.len(), 2);
        assert!((plan.poses[0].rz - std::f64::consts::FRAC_PI_4).abs() < 1e-15);
        assert!((plan.poses[1].ry - 10f64.to_radians()).abs() < 1e-15);
        assert!((plan.poses[1].rx + 5f64.to_radians()).abs() < 1e-15);
        assert_eq!(plan.poses[1].z, 0.5);
    }

    #[test]
    fn comments_as_in_the_papers_figure_are_ignored() {
        let text = "{ \"version\":\"w0.1\", //version number\n \"wallheight\":2.5, // m\n\
                    \"walls\": [[[0,0],[1,0]]], \"note\": \"a // in a string stays\" }";
        let plan = parse_plan(text, "c.wall").unwrap();
        assert_eq!(plan.wall_height, 2.5);
        assert_eq!(plan.walls.len(), 1);
    }

    #[test]
    fn plan_without_poses_and_with_ceiling() {
        let plan = parse_plan(
            r#"{"wallheight": 2.4, "ceiling": true, "walls": [[[0,0],[1,1]]]}"#,
            "c.wall",
        )
        .unwrap();
        assert!(plan.ceiling);
        assert!(plan.poses.is_empty());
    }

    #[test]
    fn wall_of_one_point_names_its_path() {
        let text =
            r#"{"wallheight": 3, "walls": [[[0,0],[1,0]], [[0,0],[1,0]], [[0,0],[0,1]], [[2,2]]]}"#;
        assert_eq!(
            parse_err(text),
            "room.wall:walls[3]: a wall needs at least 2 points, this has 1"
        );
    }

    #[test]
    fn non_positive_wallheight_is_rejected() {
        assert_eq!(
            parse_err(r#"{"wallheight": 0, "walls": []}"#),
            "room.wall:wallheight: must be a positive number of metres, not 0"
        );
        assert!(
            parse_err(r#"{"wallheight": -2.5, "walls": []}"#)
                .starts_with("room.wall:wallheight: must be a positive")
        );
        assert_eq!(
            parse_err(r#"{"wallheight": "3", "walls": []}"#),
            "room.wall:wallheight: expected a number, found a string"
        );
        assert!(parse_err(r#"{"walls": []}"#).starts_with("room.wall:wallheight: missing"));
    }

    #[test]
    fn bad_pose_entry_names_its_path() {
        let text = r#"{"wallheight": 3, "walls": [], "poses": [[0,0,0,0,0,0],[1,1,1,1,1,1],[1,2,0.5,0,"x",0]]}"#;
        assert_eq!(
            parse_err(text),
            "room.wall:poses[2][4]: expected a finite number, found a string"
        );
        let short = r#"{"wallheight": 3, "walls": [], "poses": [[1,2,0.5]]}"#;
        assert!(parse_err(short).starts_with("room.wall:poses[0]: expected a pose"));
    }

    #[test]
    fn bad_point_names_its_path() {
        let text = r#"{"wallheight": 3, "walls": [[[0,0],[1,0,2]]]}"#;
        assert!(parse_err(text).starts_with("room.wall:walls[0][1]: expected an [x, y] point"));
        let text = r#"{"wallheight": 3, "walls": [[[0,0],[1,null]]]}"#;
        assert!(parse_err(text).starts_with("room.wall:walls[0][1][1]: expected a finite number"));
    }

    #[test]
    fn json_syntax_error_gives_the_line() {
        let text = "{\n\"wallheight\": 3,\n\"walls\": [[[0,0] [1,0]]]\n}";
        let e = parse_plan(text, "room.wall").unwrap_err();
        assert_eq!(e.location, "3");
        assert!(e.to_string().starts_with("room.wall:3: expected"), "{e}");
    }

    #[test]
    fn other_fields_have_their_type_checked() {
        assert!(
            parse_err(r#"{"wallheight": 3, "walls": [], "ceiling": 1}"#)
                .starts_with("room.wall:ceiling: expected true or false")
        );
        assert!(
            parse_err(r#"{"version": "w9", "wallheight": 3, "walls": []}"#)
                .starts_with("room.wall:version: unsupported")
        );
        assert!(parse_err("[1, 2]").starts_with("room.wall:1: a floor plan is a JSON object"));
    }

    #[test]
    fn missing_file_names_the_file() {
        let e = read_plan(Path::new("/nonexistent/dir/plan.wall")).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("/nonexistent/dir/plan.wall: cannot open:"),
            "{e}"
        );
    }

    fn arb_plan() -> impl Strategy<Value = Plan> {
        let point = (-1e3f64..1e3, -1e3f64..1e3).prop_map(|(x, y)| Point2::new(x, y));
        let wall = prop::collection::vec(point, 2..6);
        let pose = (
            -50.0f64..50.0,
            -50.0f64..50.0,
            0.0f64..2.0,
            -3.1f64..3.1,
            -0.5f64..0.5,
            -0.5f64..0.5,
        )
            .prop_map(|(x, y, z, rz, ry, rx)| Pose::new(x, y, z, rz, ry, rx));
        (
            0.1f64..10.0,
            prop::collection::vec(wall, 0..5),
            any::<bool>(),
            prop::collection::vec(pose, 0..4),
        )
            .prop_map(|(wall_height, walls, ceiling, poses)| Plan {
                wall_height,
                walls,
                ceiling,
                poses,
            })
    }

    proptest! {
        #[test]
        fn write_then_read_plan_roundtrips(plan in arb_plan()) {
            let back = parse_plan(&write_plan(&plan), "rt.wall").unwrap();
            prop_assert_eq!(back.wall_height, plan.wall_height);
            prop_assert_eq!(&back.walls, &plan.walls);
            prop_assert_eq!(back.ceiling, plan.ceiling);
            prop_assert_eq!(back.poses.len(), plan.poses.len());
            for (a, b) in back.poses.iter().zip(&plan.poses) {
                // Degrees and back cost at most an ulp or two.
                for (u, v) in a.to_array().iter().zip(b.to_array()) {
                    prop_assert!((u - v).abs() <= 1e-14 * v.abs().max(1.0));
                }
            }
        }
    }
}
