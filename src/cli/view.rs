//! `levelscan view`: one self-contained HTML page with the 3D viewer (paper sect. 7.2.3).
//! Each input is sniffed: a JSON object with `walls` is a floor plan; anything else is read as
//! scans, JSON Lines or a CARMEN log (raw scans, CSM logs, `level` output and `match` output are
//! told apart per record by `viz::html`).

use super::scan_input::{BagArgs, open_bag};
use super::{open_input, open_output};
use anyhow::{Context, bail};
use levelscan::formats::carmen::CarmenParams;
use levelscan::formats::{parse_plan, read_any};
use levelscan::plan::Plan;
use levelscan::viz::html::viewer_page;
use levelscan::viz::scene::{Source, ViewParams, build_scene};
use std::io::{IsTerminal, Read, Write};
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scan files (simulate, level or match output, CSM or CARMEN logs, gzipped or not) and
    /// `.wall` floor plans; none or `-` reads standard input.
    pub files: Vec<PathBuf>,
    /// A floor plan to overlay (same as giving it among FILES).
    #[arg(long)]
    pub plan: Option<PathBuf>,
    /// Output file; standard output when absent or `-`: the HTML page. (Standard output on
    /// a terminal is refused: give `-o view.html` or redirect it.)
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Most scan points embedded in the page; bigger inputs keep every k-th pose.
    #[arg(long, default_value_t = ViewParams::default().max_points)]
    pub max_points: usize,
    /// Most pose cones drawn; longer runs keep one pose in k (the robot path joins them all).
    #[arg(long, default_value_t = ViewParams::default().max_cones)]
    pub max_cones: usize,
    /// Scanner height above the floor, the pose's z (m), for `level` output whose raw scans
    /// are not loaded alongside.
    #[arg(long, default_value_t = ViewParams::default().default_height)]
    pub height: f64,
    /// Page title.
    #[arg(long, default_value_t = ViewParams::default().title)]
    pub title: String,
    #[command(flatten)]
    pub bag: BagArgs,
}

/// What one input turned out to be.
enum Loaded {
    Plan(Plan),
    Scans(Source),
}

fn load(path: Option<&std::path::Path>, bag: &BagArgs) -> anyhow::Result<Loaded> {
    if let Some(input) = open_bag(path, &bag.options(false, None))? {
        let scans = input
            .source
            .map(|item| item.map(|(_, scan)| scan))
            .collect::<Result<Vec<_>, _>>()?;
        if scans.is_empty() {
            bail!("{}: no scans in the bag", input.name);
        }
        return Ok(Loaded::Scans(Source {
            name: input.name,
            scans,
        }));
    }
    let mut input = open_input(path)?;
    let mut text = String::new();
    input
        .reader
        .read_to_string(&mut text)
        .with_context(|| format!("{}: cannot read (not UTF-8 text?)", input.name))?;
    let name = input.name;
    if is_floor_plan(&text) {
        return Ok(Loaded::Plan(parse_plan(&text, &name)?));
    }
    let mut scans = Vec::new();
    for item in read_any(text.as_bytes(), name.clone(), CarmenParams::default())? {
        let (_, scan) = item?;
        scans.push(scan);
    }
    if scans.is_empty() {
        bail!("{name}: no scans and no floor plan in it");
    }
    Ok(Loaded::Scans(Source { name, scans }))
}

/// Refuses to pour a page or a binary file over a terminal when no `-o` was given: the user
/// almost surely wanted a file (`what` names the output, `example` a file for it).
pub(super) fn refuse_terminal(
    output: Option<&Path>,
    what: &str,
    example: &str,
) -> anyhow::Result<()> {
    if output.is_none() && std::io::stdout().is_terminal() {
        bail!(
            "{what} is not written to a terminal: give -o {example} (or -o - to force it), or \
             redirect standard output"
        );
    }
    Ok(())
}

/// Tells a `.wall` floor plan (one JSON object, maybe over many lines, maybe with `//`
/// comment lines) from scan JSON Lines (one object per line, each with `nrays`): a first line
/// that is a whole scan object means scans; otherwise a `walls` or `wallheight` key means a plan.
fn is_floor_plan(text: &str) -> bool {
    let first = text
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with("//"));
    let Some(first) = first else {
        return false;
    };
    if let Ok(v) = serde_json::from_str::<serde_json::Value>(first) {
        return v.get("walls").is_some() || v.get("wallheight").is_some();
    }
    first.starts_with('{') && (text.contains("\"walls\"") || text.contains("\"wallheight\""))
}

pub fn run(args: Args) -> anyhow::Result<()> {
    refuse_terminal(args.output.as_deref(), "the HTML page", "view.html")?;
    let mut plan: Option<(String, Plan)> = None;
    if let Some(p) = &args.plan {
        match load(Some(p), &args.bag)? {
            Loaded::Plan(plan_read) => plan = Some((p.display().to_string(), plan_read)),
            Loaded::Scans(_) => bail!("{}: --plan needs a .wall floor plan", p.display()),
        }
    }
    let mut paths: Vec<Option<PathBuf>> = args.files.iter().cloned().map(Some).collect();
    if paths.is_empty() && plan.is_none() {
        paths.push(None);
    }
    let mut sources = Vec::new();
    for path in paths {
        let shown = path
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "<stdin>".into());
        match load(path.as_deref(), &args.bag)? {
            Loaded::Plan(p) => {
                if let Some((first, _)) = &plan {
                    bail!("{shown}: a second floor plan (the first was {first}); give one");
                }
                plan = Some((shown, p));
            }
            Loaded::Scans(s) => sources.push(s),
        }
    }
    let params = ViewParams {
        max_points: args.max_points,
        max_cones: args.max_cones,
        default_height: args.height,
        title: args.title,
    };
    let scene = build_scene(plan.as_ref().map(|(_, p)| p), &sources, &params);
    for note in &scene.notes {
        eprintln!("levelscan view: {note}");
    }
    let page = viewer_page(&scene);
    // The inputs read (standard input, `None`, when no file was given).
    let mut inputs: Vec<Option<&std::path::Path>> =
        args.files.iter().map(|p| Some(p.as_path())).collect();
    inputs.extend(args.plan.as_deref().map(Some));
    if inputs.is_empty() {
        inputs.push(None);
    }
    let mut out = open_output(args.output.as_deref(), &inputs)?;
    out.write_all(page.as_bytes())?;
    out.finish()?;
    if let Some(file) = args.output.as_ref().filter(|p| p.as_os_str() != "-") {
        eprintln!(
            "levelscan view: wrote {} ({} KB)",
            file.display(),
            page.len().div_ceil(1024)
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::is_floor_plan;

    #[test]
    fn commented_multi_line_plan_is_a_plan() {
        let plan =
            "// an office\n{\n  \"version\": \"w0.1\",\n  \"wallheight\": 3,\n  \"walls\": []\n}\n";
        assert!(is_floor_plan(plan));
        assert!(is_floor_plan(
            "{\"walls\": [[[0, 0], [1, 0]]], \"wallheight\": 2}"
        ));
    }

    #[test]
    fn scan_lines_are_not_a_plan_even_with_a_walls_field() {
        let scans = "{\"nrays\": 1, \"readings\": [1], \"theta\": [0], \"note\": \"walls\"}\n{\"nrays\": 1}\n";
        assert!(!is_floor_plan(scans));
        assert!(!is_floor_plan("FLASER 3 1 1 1 0 0 0 0 0 0 1 h 1\n"));
        assert!(!is_floor_plan(""));
    }
}
