//! `levelscan eval run FILES... --out DIR`: the plots of one run, roll and pitch over time (the
//! estimate with its 3-sigma band, against the truth) and the position error along the
//! trajectory, with the numbers behind them in `run.json`.

use super::open_input;
use anyhow::{Context, bail};
use levelscan::eval::run::{evaluate_run, run_poses};
use levelscan::formats::carmen::CarmenParams;
use levelscan::formats::read_any;
use levelscan::viz::run_plots::write_run_figures;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The run's files, in any order: level or match output (the estimates), and the raw
    /// scans for the true attitude (simulate output keeps a 6-DOF true_pose; level output
    /// only [x, y, rz]).
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Directory for attitude.png/svg, trajectory_error.png/svg and run.json.
    #[arg(long, default_value = "levelscan-run")]
    pub out: PathBuf,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut records = Vec::new();
    for path in &args.files {
        let input = open_input(Some(path))?;
        for item in read_any(input.reader, input.name.clone(), CarmenParams::default())? {
            records.push(item?.1);
        }
    }
    let poses = run_poses(&records);
    if poses.is_empty() {
        bail!(
            "{}: no level or match output in it (give what levelscan level or match wrote, \
             and the raw scans for the truth)",
            args.files
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let eval = evaluate_run(&poses);
    let dir = &args.out;
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    write_run_figures(dir, "", &poses, &eval).context("eval run: figures")?;
    let json = serde_json::json!({"summary": &eval, "poses": &poses});
    let path = dir.join("run.json");
    std::fs::write(&path, serde_json::to_string_pretty(&json)? + "\n")
        .with_context(|| format!("{}: cannot write", path.display()))?;
    let deg = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.3}"));
    let rmse = eval.attitude_rmse_deg;
    use std::fmt::Write as _;
    let mut table = String::new();
    let _ = writeln!(
        table,
        "| poses | leveled | roll RMSE [deg] | pitch RMSE [deg] | max [deg] | within 3 sigma | ATE [m] |"
    );
    let _ = writeln!(table, "|---|---|---|---|---|---|---|");
    let _ = writeln!(
        table,
        "| {} | {} | {} | {} | {} | {} | {} |",
        eval.poses,
        eval.leveled,
        deg(rmse.map(|r| r[0])),
        deg(rmse.map(|r| r[1])),
        deg(eval.attitude_max_deg),
        eval.within_3_sigma
            .map_or("-".into(), |w| format!("{:.1}%", 100.0 * w)),
        deg(eval.ate.map(|a| a.rmse)),
    );
    let mut out = super::open_output(None, &[])?;
    std::io::Write::write_all(&mut out, table.as_bytes())?;
    out.finish()?;
    eprintln!(
        "levelscan eval run: wrote {} (attitude, trajectory_error, run.json)",
        dir.display()
    );
    Ok(())
}
