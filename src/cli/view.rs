//! `levelscan view`: one self-contained HTML page with the 3D viewer (paper sect. 7.2.3).
//! Each input is sniffed: a JSON object with `walls` is a floor plan; anything else is read as
//! scans (raw scans, CSM logs, `level` output and `match` output are told apart per record by
//! `viz::html`).

use super::{open_input, open_output};
use anyhow::{Context, bail};
use levelscan::formats::{ScanReader, parse_plan};
use levelscan::plan::Plan;
use levelscan::viz::html::{Source, ViewParams, build_scene, viewer_page};
use std::io::{Read, Write};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scan files (simulate, level or match output, CSM logs) and `.wall` floor plans; none or
    /// `-` reads standard input.
    pub files: Vec<PathBuf>,
    /// A floor plan to overlay (same as giving it among FILES).
    #[arg(long)]
    pub plan: Option<PathBuf>,
    /// Output HTML file (`-` for standard output).
    #[arg(short, long, default_value = "view.html")]
    pub output: PathBuf,
    /// Most scan points embedded in the page; bigger inputs keep every k-th pose.
    #[arg(long, default_value_t = ViewParams::default().max_points)]
    pub max_points: usize,
    /// Scanner height [m] for `level` output whose raw scans are not loaded alongside.
    #[arg(long, default_value_t = ViewParams::default().default_height)]
    pub height: f64,
    /// Page title.
    #[arg(long, default_value_t = ViewParams::default().title)]
    pub title: String,
}

/// What one input turned out to be.
enum Loaded {
    Plan(Plan),
    Scans(Source),
}

fn load(path: Option<&std::path::Path>) -> anyhow::Result<Loaded> {
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
    for item in ScanReader::new(text.as_bytes(), name.clone()) {
        let (_, scan) = item?;
        scans.push(scan);
    }
    if scans.is_empty() {
        bail!("{name}: no scans and no floor plan in it");
    }
    Ok(Loaded::Scans(Source { name, scans }))
}

/// A `.wall` file is one JSON object with a `walls` key (maybe over many lines); scan files
/// have one object per line, so parsing the whole text as one value fails or lacks `walls`.
fn is_floor_plan(text: &str) -> bool {
    if !text.trim_start().starts_with('{') {
        return false;
    }
    let mut de = serde_json::Deserializer::from_str(text);
    // Only the first object is looked at: a scan file fails fast on its second line.
    match <serde_json::Value as serde::Deserialize>::deserialize(&mut de) {
        Ok(v) => v.get("walls").is_some() || v.get("wallheight").is_some(),
        Err(_) => false,
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut plan: Option<(String, Plan)> = None;
    if let Some(p) = &args.plan {
        match load(Some(p))? {
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
        match load(path.as_deref())? {
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
        default_height: args.height,
        title: args.title,
    };
    let scene = build_scene(plan.as_ref().map(|(_, p)| p), &sources, &params);
    for note in &scene.notes {
        eprintln!("levelscan view: {note}");
    }
    let page = viewer_page(&scene);
    let mut out = open_output(Some(&args.output))?;
    out.write_all(page.as_bytes())
        .and_then(|_| out.flush())
        .with_context(|| format!("{}: cannot write", args.output.display()))?;
    if args.output.as_os_str() != "-" {
        eprintln!(
            "levelscan view: wrote {} ({} KB)",
            args.output.display(),
            page.len().div_ceil(1024)
        );
    }
    Ok(())
}
