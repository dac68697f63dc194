//! The demo report's text and tables around its figures: the verdict, the matching table
//! (sect. 8.2), Table I (sect. 8.1), the 3D views (Fig. 5) and the matched maps (Figs. 8-10),
//! laid out as a [`Report`] from the demo's data ([`crate::eval::demo::DemoData`]).

use super::demo_figures::Figures;
use super::report::{Block, Figure, Panel, Report, Section, Table};
use super::scene::Scene;
use crate::eval::accuracy::AccuracyParams;
use crate::eval::demo::DemoData;

/// Three decimals, or "-" for a missing or undefined number (a cell with no leveled pose).
pub fn fmt_m(v: Option<f64>) -> String {
    v.filter(|v| v.is_finite())
        .map_or("-".into(), |v| format!("{v:.3}"))
}

/// A fraction as a percentage, or "-" when undefined (no leveled pose to count over).
fn percent(v: f64, decimals: usize) -> String {
    if v.is_finite() {
        format!("{:.*}%", decimals, v * 100.0)
    } else {
        "-".into()
    }
}

fn verdict(data: &DemoData) -> String {
    match (
        data.ate_rmse("raw", "metascan"),
        data.ate_rmse("leveled", "metascan"),
    ) {
        (Some(raw), Some(lev)) if lev < raw => format!(
            "Leveling works: on this tilted run, metascan matching of leveled scans ends with ATE \
             {lev:.3} m, against {raw:.3} m for the raw scans ({:.0}x smaller).",
            raw / lev.max(1e-6)
        ),
        (Some(raw), Some(lev)) => format!(
            "On this run leveling did not help metascan matching: ATE {lev:.3} m leveled, \
             {raw:.3} m raw."
        ),
        _ => "The matching runs did not produce trajectories to compare.".to_string(),
    }
}

/// The report of the demo's run, around its figures.
pub fn build_report(data: &DemoData, figures: Figures) -> Report {
    let s = &data.settings;
    let [raw_meta, lev_meta] = figures.metascan;
    Report {
        title: "levelscan demo: leveling scans taken on an uneven floor".into(),
        subtitle: format!(
            "{} poses through {}, {} scans per pose, {:.0} mm noise, seed {}",
            s.poses,
            s.plan,
            s.scans_per_pose,
            s.noise_m * 1000.0,
            s.seed
        ),
        verdict: verdict(data),
        headline: headline(data, raw_meta, lev_meta),
        sections: vec![
            matching_section(data),
            run_section(figures.attitude, figures.trajectory_error),
            accuracy_section(data, figures.table_one, figures.histogram),
            viewer_section(data, figures.pose_view),
            maps_section(
                data,
                figures.pairwise,
                figures.level_floor,
                figures.matched_view,
            ),
            about_section(data),
        ],
    }
}

/// "ATE 0.006 m" for a run.
fn metric(data: &DemoData, run: &str, mode: &str) -> String {
    format!("ATE {} m", fmt_m(data.ate_rmse(run, mode)))
}

/// The first screen: raw and leveled metascan maps side by side.
fn headline(data: &DemoData, raw_meta: Figure, lev_meta: Figure) -> Vec<Panel> {
    let metric = |run: &str, mode: &str| metric(data, run, mode);
    vec![
        Panel {
            title: "Raw scans, metascan".into(),
            metric: metric("raw", "metascan"),
            caption: "Each pose's scan nearest level, used as it is: floor hits and tilted walls \
                      become phantom obstacles (the paper's Fig. 9b)."
                .into(),
            figure: raw_meta,
        },
        Panel {
            title: "Leveled scans, metascan".into(),
            metric: metric("leveled", "metascan"),
            caption: "Pseudo-level scans from levelscan level (the paper's Fig. 10b). Grey: true \
                      walls; red: matched points; green: true path; blue: estimated path."
                .into(),
            figure: lev_meta,
        },
    ]
}

/// The matching runs' table (sect. 8.2).
fn matching_section(data: &DemoData) -> Section {
    let matching_rows = data
        .matching
        .iter()
        .map(|r| {
            vec![
                r.run.clone(),
                r.mode.clone(),
                fmt_m(r.ate.map(|a| a.rmse)),
                fmt_m(r.ate.map(|a| a.max)),
                r.rpe.map_or("-".into(), |p| {
                    format!("{:.1}", p.median_translation * 1000.0)
                }),
                r.rpe
                    .map_or("-".into(), |p| format!("{:.1}", p.p95_translation * 1000.0)),
                r.rpe.map_or("-".into(), |p| {
                    format!("{:.2}", p.median_rotation.to_degrees())
                }),
                r.rpe
                    .map_or("-".into(), |p| format!("{} / {}", p.bad_pairs, p.pairs)),
                format!("{} / {}", r.fallbacks, r.scans),
            ]
        })
        .collect();
    Section {
        id: "matching".into(),
        title: "Scan matching: raw vs leveled (sect. 8.2)".into(),
        blocks: vec![Block::Table(Table {
            caption: "ATE: RMSE of positions after the best SE(2) alignment. RPE over \
                          consecutive pairs; a bad pair is off by more than 5 cm or 1 degree. \
                          Fallback: the step came from odometry."
                .into(),
            header: [
                "scans",
                "mode",
                "ATE [m]",
                "ATE max [m]",
                "RPE median [mm]",
                "RPE p95 [mm]",
                "RPE median [deg]",
                "bad pairs",
                "fallbacks",
            ]
            .map(String::from)
            .to_vec(),
            rows: matching_rows,
        })],
    }
}

/// Roll and pitch over the run, and the position error along it (`levelscan eval run`).
fn run_section(attitude: Figure, trajectory_error: Figure) -> Section {
    Section {
        id: "run".into(),
        title: "Attitude and error along the run".into(),
        blocks: vec![
            Block::Panels(vec![Panel {
                title: "Roll and pitch over the run".into(),
                metric: String::new(),
                caption: "Blue: level's estimate at each pose with its 3-sigma band (the sigmas \
                          level reports); black: the simulator's truth; red marks: poses level \
                          could not level."
                    .into(),
                figure: attitude,
            }]),
            Block::Panels(vec![Panel {
                title: "Position error along the trajectory".into(),
                metric: String::new(),
                caption: "Leveled scans, metascan: each estimate after the ATE's alignment, \
                          coloured by its distance from the true position (left), and that \
                          error over the distance travelled (right)."
                    .into(),
                figure: trajectory_error,
            }]),
            Block::Code("levelscan eval run scans.jsonl matched.jsonl --out run".into()),
        ],
    }
}

/// Table I, as a table and a chart, and the Fig. 6 histogram (sect. 8.1).
fn accuracy_section(data: &DemoData, table_one: Figure, histogram: Figure) -> Section {
    let s = &data.settings;
    let accuracy_rows = data
        .accuracy
        .iter()
        .map(|c| {
            vec![
                format!("{} scans, {:.0} cm", c.scans, c.noise * 100.0),
                fmt_m(Some(c.mean_deg)),
                fmt_m(c.paper_mean_deg),
                fmt_m(Some(c.median_deg)),
                fmt_m(Some(c.p95_deg)),
                fmt_m(Some(c.max_deg)),
                percent(c.leveled_fraction, 0),
                c.wrong_over_5_deg.to_string(),
                percent(c.phantom_rate, 2),
                percent(c.floor_kept_rate, 2),
                percent(c.coverage, 0),
            ]
        })
        .collect();
    Section {
        id: "accuracy".into(),
        title: "Level accuracy: Table I (sect. 8.1)".into(),
        blocks: vec![
            Block::Text(format!(
                "{} random poses per cell in the office plan, with the paper's protocol: roll \
                 and pitch uniform in +-20 degrees, scanner 0.45 m high, 181 rays over 180 \
                 degrees, elevations 5 degrees apart, Gaussian range noise. Error = \
                 max(|dtheta_x|, |dtheta_y|) over leveled poses. `levelscan eval accuracy` runs \
                 it over several plans and both estimators.",
                s.accuracy_poses
            )),
            Block::Table(Table {
                caption: "Mean error in degrees, beside the paper's Table I.".into(),
                header: [
                    "cell",
                    "mean [deg]",
                    "paper [deg]",
                    "median",
                    "p95",
                    "max",
                    "leveled",
                    "ok but > 5 deg",
                    "phantoms",
                    "floor/ceiling kept",
                    "coverage",
                ]
                .map(String::from)
                .to_vec(),
                rows: accuracy_rows,
            }),
            Block::Definitions(accuracy_definitions()),
            Block::Panels(vec![
                Panel {
                    title: "Table I as a figure".into(),
                    metric: String::new(),
                    caption: "Filled bars: levelscan; outlined: the paper's values.".into(),
                    figure: table_one,
                },
                Panel {
                    title: "Distribution of error (Fig. 6)".into(),
                    metric: String::new(),
                    caption: "Share of leveled poses per 0.5 degree bucket, labelled by its \
                              upper bound; the axis ends where 99% of the errors do, and the \
                              last bin (outlined) counts every pose beyond it."
                        .into(),
                    figure: histogram,
                },
            ]),
        ],
    }
}

/// What Table I's columns mean.
fn accuracy_definitions() -> Vec<(String, String)> {
    let phantom_cm = AccuracyParams::default().phantom_distance * 100.0;
    [
        (
            "mean, median, p95, max",
            "of the error max(|dtheta_x|, |dtheta_y|) over the leveled poses, in degrees \
             (p95: the 95th percentile)."
                .to_string(),
        ),
        (
            "leveled",
            "share of the poses that level reported as ok (the rest failed with a reason, \
             e.g. facing_floor)."
                .to_string(),
        ),
        (
            "ok but > 5 deg",
            "poses reported ok whose error is above 5 degrees: the leveler's silent failures, \
             the ones a matcher downstream cannot know about."
                .to_string(),
        ),
        (
            "phantoms",
            format!(
                "share of the valid pseudo-level points that lie farther than {phantom_cm:.0} cm \
                 from every true wall: floor or ceiling hits, or misplaced points, that a \
                 matcher would take for obstacles."
            ),
        ),
        (
            "floor/ceiling kept",
            "share of the valid pseudo-level points whose ray hit the floor or the ceiling \
             (the simulator's hit labels): the phantom obstacles a scan matcher suffers from, \
             as opposed to wall points misplaced by range noise."
                .to_string(),
        ),
        (
            "coverage",
            "valid pseudo-level points over the wall hits of the pose's best single scan (the \
             one with most wall hits): how much of the visible walls the pseudo-level scan \
             keeps."
                .to_string(),
        ),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

/// The 3D view of the pose with most wall polygons (Fig. 5a).
fn viewer_section(data: &DemoData, pose_view: Scene) -> Section {
    let lv = &data.level;
    let level_text = format!(
        "On the demo run, {} of {} poses were leveled; mean attitude error {} deg, largest {} deg \
         (against the simulator's truth).",
        lv.leveled,
        lv.poses,
        lv.mean_error_deg.map_or("-".into(), |e| format!("{e:.3}")),
        lv.max_error_deg.map_or("-".into(), |e| format!("{e:.3}")),
    );
    Section {
        id: "viewer".into(),
        title: "3D view of a pose (Fig. 5a)".into(),
        blocks: vec![
            Block::Text(level_text),
            Block::Text(
                "Red: the pose's scans at each hinge elevation; green and red: the wall polygons \
                 found; blue: the pseudo-level scan; grey: the floor plan. Drag to orbit, wheel to \
                 zoom, untick a layer to hide it."
                    .into(),
            ),
            Block::Viewer(Box::new(pose_view)),
        ],
    }
}

/// The pairwise maps, the level floor's and the matched scans top down (Figs. 8-10, 5b).
fn maps_section(
    data: &DemoData,
    pairwise: [Figure; 2],
    level_floor: Figure,
    matched_view: Scene,
) -> Section {
    let metric = |run: &str, mode: &str| metric(data, run, mode);
    let [raw_pair, lev_pair] = pairwise;
    Section {
        id: "maps".into(),
        title: "Matched maps (Figs. 8-10)".into(),
        blocks: vec![
            Block::Panels(vec![
                Panel {
                    title: "Raw scans, pairwise".into(),
                    metric: metric("raw", "pairwise"),
                    caption: "The paper's Fig. 9a.".into(),
                    figure: raw_pair,
                },
                Panel {
                    title: "Leveled scans, pairwise".into(),
                    metric: metric("leveled", "pairwise"),
                    caption: "The paper's Fig. 10a.".into(),
                    figure: lev_pair,
                },
            ]),
            Block::Panels(vec![Panel {
                title: "Reference: the same path on a level floor".into(),
                metric: format!(
                    "pairwise {}, metascan {}",
                    metric("level floor", "pairwise"),
                    metric("level floor", "metascan")
                ),
                caption: "The paper's Fig. 8: what matching achieves when the floor is flat."
                    .into(),
                figure: level_floor,
            }]),
            Block::Viewer(Box::new(matched_view)),
        ],
    }
}

/// Settings, timings, the files beside the report and the commands that redo it.
fn about_section(data: &DemoData) -> Section {
    let s = &data.settings;
    let timings: Vec<String> = data
        .timings_s
        .iter()
        .map(|(k, v)| format!("{k} {v:.2} s"))
        .collect();
    Section {
        id: "data".into(),
        title: "Data and reproduction".into(),
        blocks: vec![
            Block::Text(format!(
                "Settings: {} poses of {}, {} scans per pose {} degrees apart, {:.0} mm range \
                 noise, seed {}; robot: {}. Timings: {}.",
                s.poses,
                s.plan,
                s.scans_per_pose,
                s.elevation_step_deg,
                s.noise_m * 1000.0,
                s.seed,
                s.robot,
                timings.join(", ")
            )),
            Block::Text(
                "Beside this page: report.json (every number here), scans_tilted.jsonl (the \
                 simulated scans), leveled.jsonl (level output with wall polygons), \
                 matched.jsonl (the leveled scans at their metascan estimates), map.yaml and \
                 map.pgm (their occupancy grid, for ROS map_server), pose.ply (the 3D view's \
                 pose as a point cloud in the robot frame), view_pose.html, and the figures as \
                 PNG and SVG. The same steps by hand:"
                    .into(),
            ),
            Block::Code(
                "levelscan simulate examples/plans/office.wall --scans 5 > scans.jsonl\n\
                 levelscan level --polygons scans.jsonl > leveled.jsonl\n\
                 levelscan match --mode metascan leveled.jsonl > matched.jsonl\n\
                 levelscan view scans.jsonl leveled.jsonl --plan examples/plans/office.wall -o view.html\n\
                 levelscan eval run scans.jsonl matched.jsonl --out run\n\
                 levelscan map matched.jsonl -o map.yaml\n\
                 levelscan cloud scans.jsonl --sequence 0 -o pose.ply"
                    .into(),
            ),
        ],
    }
}
