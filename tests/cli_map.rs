//! End-to-end runs of `levelscan map` (an occupancy grid for ROS map_server) and `levelscan
//! cloud` (a pose's scans as PLY), as a user types them, their files parsed back here by
//! readers of this test's own and checked against known geometry.

mod cli_support;

use cli_support::bin;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Output;

fn temp_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("levelscan-cli-map-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn run(args: &[&str]) -> Output {
    bin().args(args).output().unwrap()
}

fn ok(out: &Output) {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A 6 x 4 m room and four poses in it; scans all around (360 degrees, 720 rays), no noise, one
/// level scan per pose.
fn room_scans(dir: &Path) -> PathBuf {
    let plan = dir.join("room.wall");
    std::fs::write(
        &plan,
        r#"{"version": "w0.1", "wallheight": 2.5, "walls": [[[0, 0], [6, 0], [6, 4], [0, 4], [0, 0]]],
            "poses": [[1.5, 1, 0.45, 0, 0, 0], [3, 2, 0.45, 90, 0, 0], [4.5, 3, 0.45, 180, 0, 0],
                      [3, 1, 0.45, -90, 0, 0]]}"#,
    )
    .unwrap();
    let scans = dir.join("scans.jsonl");
    let out = run(&[
        "simulate",
        plan.to_str().unwrap(),
        "--fov",
        "360",
        "--rays",
        "720",
        "--sigma",
        "0",
        "--elevations",
        "0",
    ]);
    ok(&out);
    std::fs::write(&scans, &out.stdout).unwrap();
    scans
}

/// A map as map_server reads it: the YAML's keys, and the PGM's pixels (row 0 at the top).
struct Map {
    yaml: Vec<(String, String)>,
    resolution: f64,
    origin: [f64; 2],
    width: usize,
    height: usize,
    pixels: Vec<u8>,
}

impl Map {
    fn read(yaml_path: &Path) -> Map {
        let text = std::fs::read_to_string(yaml_path).unwrap();
        let yaml: Vec<(String, String)> = text
            .lines()
            .filter_map(|l| l.split_once(": "))
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        let get = |k: &str| yaml.iter().find(|(key, _)| key == k).unwrap().1.clone();
        let origin: Vec<f64> = get("origin")
            .trim_matches(['[', ']'])
            .split(',')
            .map(|v| v.trim().parse().unwrap())
            .collect();
        assert_eq!(origin.len(), 3);
        let image = yaml_path.parent().unwrap().join(get("image"));
        let (width, height, pixels) = read_pgm(&std::fs::read(image).unwrap());
        Map {
            resolution: get("resolution").parse().unwrap(),
            origin: [origin[0], origin[1]],
            width,
            height,
            pixels,
            yaml,
        }
    }

    /// The pixel holding world point (x, y), as map_server places it.
    fn at(&self, x: f64, y: f64) -> Option<u8> {
        let c = ((x - self.origin[0]) / self.resolution).floor();
        let r = ((y - self.origin[1]) / self.resolution).floor();
        if c < 0.0 || r < 0.0 || c as usize >= self.width || r as usize >= self.height {
            return None;
        }
        Some(self.pixels[(self.height - 1 - r as usize) * self.width + c as usize])
    }

    /// Whether some pixel within one cell of (x, y) has `value`.
    fn near(&self, x: f64, y: f64, value: u8) -> bool {
        let d = self.resolution;
        [-d, 0.0, d].iter().any(|&dx| {
            [-d, 0.0, d]
                .iter()
                .any(|&dy| self.at(x + dx, y + dy) == Some(value))
        })
    }
}

/// A binary PGM: `P5`, comments, width, height, maxval 255, then the bytes.
fn read_pgm(bytes: &[u8]) -> (usize, usize, Vec<u8>) {
    let mut fields = Vec::new();
    let mut i = 0;
    while fields.len() < 4 {
        if bytes[i] == b'#' {
            while bytes[i] != b'\n' {
                i += 1;
            }
        } else if bytes[i].is_ascii_whitespace() {
            i += 1;
        } else {
            let start = i;
            while !bytes[i].is_ascii_whitespace() {
                i += 1;
            }
            fields.push(String::from_utf8(bytes[start..i].to_vec()).unwrap());
        }
    }
    assert_eq!((fields[0].as_str(), fields[3].as_str()), ("P5", "255"));
    let (w, h): (usize, usize) = (fields[1].parse().unwrap(), fields[2].parse().unwrap());
    let pixels = bytes[i + 1..].to_vec();
    assert_eq!(pixels.len(), w * h);
    (w, h, pixels)
}

#[test]
fn map_of_a_square_room_has_its_walls_where_they_are_and_free_space_inside() {
    let dir = temp_dir("room");
    let scans = room_scans(&dir);
    let yaml = dir.join("room.yaml");
    let out = run(&[
        "map",
        scans.to_str().unwrap(),
        "--pose",
        "true_pose",
        "--resolution",
        "0.05",
        "-o",
        yaml.to_str().unwrap(),
    ]);
    ok(&out);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("4 scans") && err.contains("room.pgm"), "{err}");
    let map = Map::read(&yaml);
    for (k, v) in [
        ("image", "room.pgm"),
        ("mode", "trinary"),
        ("resolution", "0.05"),
        ("negate", "0"),
        ("occupied_thresh", "0.65"),
        ("free_thresh", "0.196"),
    ] {
        assert!(
            map.yaml.contains(&(k.into(), v.into())),
            "{k}: {:?}",
            map.yaml
        );
    }
    // The grid covers the room and its 0.5 m margin: 7 x 5 m.
    assert!((map.origin[0] + 0.5).abs() < 1e-6 && (map.origin[1] + 0.5).abs() < 1e-6);
    assert_eq!((map.width, map.height), (141, 101));
    // Every 5 cm along the four walls: occupied (black), within a cell.
    let mut wall = Vec::new();
    for k in 0..=120 {
        let t = f64::from(k) * 0.05;
        wall.push((t, 0.0));
        wall.push((t, 4.0));
        if t <= 4.0 {
            wall.push((0.0, t));
            wall.push((6.0, t));
        }
    }
    let hit = wall.iter().filter(|&&(x, y)| map.near(x, y, 0)).count();
    assert!(
        hit * 100 >= wall.len() * 97,
        "{hit} of {} wall samples occupied",
        wall.len()
    );
    // Inside, 20 cm and more from the walls: free (white), nothing occupied.
    let (mut inside, mut free, mut outside, mut unknown) = (0, 0, 0, 0);
    for i in -8..=128 {
        for j in -8..=88 {
            let (x, y) = (f64::from(i) * 0.05 + 0.025, f64::from(j) * 0.05 + 0.025);
            let Some(v) = map.at(x, y) else { continue };
            if (0.2..=5.8).contains(&x) && (0.2..=3.8).contains(&y) {
                inside += 1;
                free += usize::from(v == 254);
                assert_ne!(v, 0, "occupied cell inside the room at ({x}, {y})");
            } else if !(-0.2..=6.2).contains(&x) || !(-0.2..=4.2).contains(&y) {
                // Beyond the walls no ray went: unknown (grey).
                outside += 1;
                unknown += usize::from(v == 205);
            }
        }
    }
    assert!(
        free * 100 >= inside * 99,
        "{free} of {inside} inside cells free"
    );
    assert!(outside > 1000);
    assert_eq!(unknown, outside, "a cell beyond the walls is not unknown");
}

#[test]
fn map_refuses_raw_tilted_scans_and_scans_without_the_pose() {
    let dir = temp_dir("bad");
    let scans = room_scans(&dir);
    // simulate writes true_pose and odometry but no estimate: map needs match output.
    let out = run(&[
        "map",
        scans.to_str().unwrap(),
        "-o",
        dir.join("m.yaml").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("scans.jsonl:1: no estimate"), "{err}");
    assert!(!dir.join("m.yaml").exists() && !dir.join("m.pgm").exists());
    let tilted = dir.join("tilted.jsonl");
    let sim = run(&[
        "simulate",
        dir.join("room.wall").to_str().unwrap(),
        "--scans",
        "3",
    ]);
    ok(&sim);
    std::fs::write(&tilted, &sim.stdout).unwrap();
    let out = run(&["map", tilted.to_str().unwrap(), "--pose", "true_pose"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("tilted.jsonl:1: a raw scan at hinge elevation -5.0 deg"),
        "{err}"
    );
    assert!(!err.contains("panicked"));
}

/// One vertex as written: x, y, z, scan, range.
type Vertex = ([f32; 3], u8, f32);

/// A PLY file of this project's layout, binary little-endian or ASCII.
fn read_ply(bytes: &[u8]) -> (Vec<String>, Vec<Vertex>) {
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let header: Vec<String> = String::from_utf8(bytes[..end].to_vec())
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect();
    let n: usize = header
        .iter()
        .find_map(|l| l.strip_prefix("element vertex "))
        .unwrap()
        .parse()
        .unwrap();
    let body = &bytes[end..];
    let f = |b: &[u8]| f32::from_le_bytes(b.try_into().unwrap());
    let vertices: Vec<Vertex> = if header[1] == "format ascii 1.0" {
        String::from_utf8(body.to_vec())
            .unwrap()
            .lines()
            .map(|l| {
                let v: Vec<f32> = l.split(' ').map(|t| t.parse().unwrap()).collect();
                ([v[0], v[1], v[2]], v[3] as u8, v[4])
            })
            .collect()
    } else {
        assert_eq!(header[1], "format binary_little_endian 1.0");
        assert_eq!(body.len(), n * 20);
        body.chunks(20)
            .map(|r| {
                (
                    [f(&r[0..4]), f(&r[4..8]), f(&r[8..12])],
                    r[12],
                    f(&r[13..17]),
                )
            })
            .collect()
    };
    assert_eq!(vertices.len(), n);
    (header, vertices)
}

#[test]
fn cloud_writes_a_poses_scans_in_the_robot_frame() {
    let dir = temp_dir("cloud");
    let plan = dir.join("room.wall");
    room_scans(&dir);
    let sim = run(&[
        "simulate",
        plan.to_str().unwrap(),
        "--scans",
        "3",
        "--step",
        "10",
    ]);
    ok(&sim);
    let scans = dir.join("tilted.jsonl");
    std::fs::write(&scans, &sim.stdout).unwrap();
    // The expected points, from the JSON: Ry(e) (r cos phi, r sin phi, 0), elevation e
    // tilting the beam down (the contract), for pose 2's scans in file order.
    let mut expected = Vec::new();
    for (k, line) in String::from_utf8(sim.stdout.clone())
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str::<Value>(l).unwrap())
        .filter(|v| v["sequence"] == 2)
        .enumerate()
    {
        let e = line["elevation"].as_f64().unwrap();
        for (phi, r) in line["theta"]
            .as_array()
            .unwrap()
            .iter()
            .zip(line["readings"].as_array().unwrap())
        {
            let (Some(phi), Some(r)) = (phi.as_f64(), r.as_f64()) else {
                continue;
            };
            let (x, y) = (r * phi.cos(), r * phi.sin());
            expected.push(([x * e.cos(), y, -x * e.sin()], k as u8, r));
        }
    }
    assert!(expected.len() > 400);
    for ascii in [false, true] {
        let ply = dir.join(if ascii { "a.ply" } else { "b.ply" });
        let mut args = vec![
            "cloud",
            scans.to_str().unwrap(),
            "--sequence",
            "2",
            "-o",
            ply.to_str().unwrap(),
        ];
        if ascii {
            args.push("--ascii");
        }
        ok(&run(&args));
        let (header, vertices) = read_ply(&std::fs::read(&ply).unwrap());
        assert!(
            header.iter().any(|l| l.contains("sequence 2")),
            "{header:?}"
        );
        assert!(
            header.iter().any(|l| l.contains("frame robot")),
            "{header:?}"
        );
        assert_eq!(vertices.len(), expected.len());
        for (v, (p, scan, r)) in vertices.iter().zip(&expected) {
            for d in 0..3 {
                assert!((f64::from(v.0[d]) - p[d]).abs() < 1e-5, "{v:?} vs {p:?}");
            }
            assert_eq!(v.1, *scan);
            assert!((f64::from(v.2) - r).abs() < 1e-5);
        }
    }
    // Without -o the cloud goes to standard output (here a pipe), as every command's output.
    let piped = run(&["cloud", scans.to_str().unwrap(), "--sequence", "2"]);
    ok(&piped);
    assert_eq!(piped.stdout, std::fs::read(dir.join("b.ply")).unwrap());
    // Several poses and no --sequence: the user is asked to choose.
    let out = run(&[
        "cloud",
        scans.to_str().unwrap(),
        "-o",
        dir.join("c.ply").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("4 poses in it (sequence 0 to 3); choose one with --sequence"),
        "{err}"
    );
}
