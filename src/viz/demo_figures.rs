//! The demo report's figures (paper Figs. 5-10 and Table I): matched maps, Table I as a chart,
//! the Fig. 6 histogram and the two 3D views, drawn from the demo's run
//! ([`crate::eval::demo::DemoRun`]). Each figure is also written beside the report as PNG and
//! SVG; a figure that cannot be drawn becomes [`Figure::Missing`] with the reason.

use super::histogram;
use super::map_plot::{MapPanel, map_panels_png, map_panels_svg, run_map_panel};
use super::plots::{AccuracyCell, grouped_bars_png, grouped_bars_svg, table_one_chart};
use super::report::Figure;
use super::run_plots::write_run_figures;
use super::scene::{Scene, Source, ViewParams, build_scene};
use crate::eval::accuracy::CellStats;
use crate::eval::demo::{DemoRun, LeveledPose};
use crate::eval::matching::{RunKind, RunResult};
use crate::eval::run::{evaluate_run, run_poses};
use crate::geometry::{Pose, Pose2};
use crate::matching::matcher::Mode;
use crate::plan::Plan;
use crate::scan::Scan;
use std::path::Path;

/// The figures of the report.
pub struct Figures {
    /// Raw vs leveled metascan maps (the headline), then pairwise.
    pub metascan: [Figure; 2],
    pub pairwise: [Figure; 2],
    pub level_floor: Figure,
    pub table_one: Figure,
    pub histogram: Figure,
    /// The 3D view of one pose (Fig. 5a).
    pub pose_view: Scene,
    /// The leveled scans as metascan matched them, top down (Fig. 5b).
    pub matched_view: Scene,
    /// Roll and pitch over the run, and the position error along it.
    pub attitude: Figure,
    pub trajectory_error: Figure,
}

/// Draws the report's figures from the demo's run, writing each as PNG and SVG in `dir`.
pub fn make_figures(dir: &Path, run: &DemoRun) -> Figures {
    let (metascan, pairwise, level_floor) = map_figures(dir, &run.plan, &run.runs);
    let matched = run.matched_leveled();
    let [attitude, trajectory_error] = run_figures(dir, run, &matched);
    Figures {
        metascan,
        pairwise,
        level_floor,
        table_one: table_one_figure(dir, &run.data.accuracy),
        histogram: histogram_figure(dir, &run.data.accuracy),
        pose_view: pose_scene(&run.plan, &run.tilted, &run.leveled),
        matched_view: matched_scene(&run.plan, matched),
        attitude,
        trajectory_error,
    }
}

/// Roll and pitch over the run against the truth, and the leveled metascan run's position
/// error along its trajectory (`levelscan eval run`'s figures).
fn run_figures(dir: &Path, run: &DemoRun, matched: &[Scan]) -> [Figure; 2] {
    let records: Vec<Scan> = run
        .tilted
        .iter()
        .flatten()
        .chain(matched)
        .cloned()
        .collect();
    let poses = run_poses(&records);
    match write_run_figures(dir, "run_", &poses, &evaluate_run(&poses)) {
        Ok(svgs) => svgs.map(Figure::Svg),
        Err(e) => [
            Figure::Missing(e.to_string()),
            Figure::Missing(e.to_string()),
        ],
    }
}

/// Writes one map as PNG and SVG in `dir`, and returns the PNG for embedding (smaller than
/// the SVG's thousands of points).
fn map_figure(dir: &Path, stem: &str, panels: &[MapPanel], size: (u32, u32)) -> Figure {
    let png = dir.join(format!("{stem}.png"));
    let result = map_panels_png(panels, &png, size)
        .and_then(|_| map_panels_svg(panels, size))
        .map_err(|e| e.to_string())
        .and_then(|svg| {
            std::fs::write(dir.join(format!("{stem}.svg")), svg).map_err(|e| e.to_string())?;
            std::fs::read(&png).map_err(|e| e.to_string())
        });
    match result {
        Ok(bytes) => Figure::Png(bytes),
        Err(e) => Figure::Missing(e),
    }
}

/// The matched maps: raw and leveled metascan, raw and leveled pairwise, and the level floor's
/// pair; also both metascan maps side by side in one picture.
fn map_figures(dir: &Path, plan: &Plan, runs: &[RunResult]) -> ([Figure; 2], [Figure; 2], Figure) {
    let truth: Vec<Pose2> = plan.poses.iter().map(Pose::to_pose2).collect();
    let find = |kind: RunKind, mode: Mode| {
        runs.iter()
            .find(|r| r.kind == kind && r.mode == mode)
            .map(|r| run_map_panel(plan, r, &truth))
            .unwrap_or_default()
    };
    let one = |stem: &str, panel: MapPanel| map_figure(dir, stem, &[panel], (620, 520));
    let metascan = [
        one("map_raw_metascan", find(RunKind::Raw, Mode::Metascan)),
        one(
            "map_leveled_metascan",
            find(RunKind::Leveled, Mode::Metascan),
        ),
    ];
    let pairwise = [
        one("map_raw_pairwise", find(RunKind::Raw, Mode::Pairwise)),
        one(
            "map_leveled_pairwise",
            find(RunKind::Leveled, Mode::Pairwise),
        ),
    ];
    let level_floor = map_figure(
        dir,
        "map_level_floor",
        &[
            find(RunKind::LevelFloor, Mode::Pairwise),
            find(RunKind::LevelFloor, Mode::Metascan),
        ],
        (1240, 520),
    );
    // Side by side in one picture too, for papers and slides (the report embeds them apart,
    // so each keeps its own caption).
    let _ = map_figure(
        dir,
        "maps_raw_vs_leveled",
        &[
            find(RunKind::Raw, Mode::Metascan),
            find(RunKind::Leveled, Mode::Metascan),
        ],
        (1240, 520),
    );
    (metascan, pairwise, level_floor)
}

/// Table I as a grouped bar chart beside the paper's values.
fn table_one_figure(dir: &Path, accuracy: &[CellStats]) -> Figure {
    let cells: Vec<AccuracyCell> = accuracy
        .iter()
        .map(|c| AccuracyCell {
            noise: c.noise,
            scans: c.scans,
            mean_deg: c.mean_deg,
        })
        .collect();
    let chart = table_one_chart(&cells);
    match grouped_bars_svg(&chart, histogram::SIZE) {
        Ok(svg) => {
            let _ = std::fs::write(dir.join("table1.svg"), &svg);
            let _ = grouped_bars_png(&chart, &dir.join("table1.png"), histogram::SIZE);
            Figure::Svg(svg)
        }
        Err(e) => Figure::Missing(e.to_string()),
    }
}

/// The paper's Fig. 6: the distribution of error at the noise nearest 5 cm.
fn histogram_figure(dir: &Path, accuracy: &[CellStats]) -> Figure {
    // The paper's Fig. 6 shows 5 cm noise; take the noisiest level run when 5 cm is absent.
    let noise = accuracy
        .iter()
        .map(|c| c.noise)
        .min_by(|a, b| (a - 0.05).abs().total_cmp(&(b - 0.05).abs()))
        .unwrap_or(0.05);
    let series: Vec<histogram::Series> = accuracy
        .iter()
        .filter(|c| c.noise == noise)
        .map(|c| histogram::Series {
            label: format!("{} scans", c.scans),
            errors_deg: c.errors_deg.clone(),
        })
        .collect();
    let title = format!(
        "Distribution of error, {:.0} cm noise (paper Fig. 6)",
        noise * 100.0
    );
    match histogram::write_histogram(dir, "fig6_histogram", &title, &series) {
        Ok(()) => std::fs::read_to_string(dir.join("fig6_histogram.svg"))
            .map(Figure::Svg)
            .unwrap_or_else(|e| Figure::Missing(e.to_string())),
        Err(e) => Figure::Missing(e),
    }
}

fn polygons(s: &Scan) -> usize {
    s.extra
        .get("wall_polygons")
        .and_then(|v| v.as_array())
        .map_or(0, Vec::len)
}

/// The index of the pose the report shows in 3D: the leveled one with most wall polygons.
pub fn shown_pose(leveled: &[LeveledPose]) -> usize {
    (0..leveled.len())
        .max_by_key(|&k| (leveled[k].attitude.is_some(), polygons(&leveled[k].record)))
        .unwrap_or(0)
}

/// The 3D view of one pose (the paper's Fig. 5a): its scans, the wall polygons, the
/// pseudo-level scan and the plan. The pose shown is the leveled one with most wall polygons.
fn pose_scene(plan: &Plan, tilted: &[Vec<Scan>], leveled: &[LeveledPose]) -> Scene {
    let best = shown_pose(leveled);
    let (Some(scans), Some(LeveledPose { record, .. })) = (tilted.get(best), leveled.get(best))
    else {
        return build_scene(Some(plan), &[], &ViewParams::default());
    };
    let sources = [
        Source {
            name: "tilted scans".into(),
            scans: scans.clone(),
        },
        Source {
            name: "level output".into(),
            scans: vec![record.clone()],
        },
    ];
    let params = ViewParams {
        title: format!(
            "Pose {best}: {} scans, {} wall polygons, pseudo-level scan",
            scans.len(),
            polygons(record)
        ),
        ..ViewParams::default()
    };
    build_scene(Some(plan), &sources, &params)
}

/// The leveled scans as matched by metascan, top down (the paper's Fig. 5b).
fn matched_scene(plan: &Plan, scans: Vec<Scan>) -> Scene {
    let params = ViewParams {
        title: "Leveled scans matched with metascan, top down".into(),
        ..ViewParams::default()
    };
    build_scene(
        Some(plan),
        &[Source {
            name: "matched".into(),
            scans,
        }],
        &params,
    )
}
