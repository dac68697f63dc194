//! The demo report: one self-contained HTML page (figures inline as SVG or base64 PNG, the 3D
//! viewer embedded) built from plain data. Rendering is a pure function of [`Report`].
//!
//! The first screen answers the paper's question (sect. 8.2), "does leveling improve scan
//! matching?", at a glance: the headline panels (raw and leveled matched maps side by side, each
//! with its ATE) come before anything else. Every section has a stable `id` (`summary`,
//! `matching`, `accuracy`, `viewer`, `maps`, ...) so tests and links can find it.

use super::html::{escape_html, page_head_assets, viewer_fragment};
use super::scene::Scene;
use serde::Serialize;

/// A figure as the page embeds it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum Figure {
    /// SVG text, inlined.
    Svg(String),
    /// PNG bytes, inlined as a base64 data URL.
    Png(Vec<u8>),
    /// The figure could not be made; the reason is shown in its place.
    Missing(String),
}

/// A captioned figure; panels in one row sit side by side.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Panel {
    pub title: String,
    /// A short emphasised line under the title (e.g. "ATE 0.021 m").
    pub metric: String,
    pub caption: String,
    #[serde(skip)]
    pub figure: Figure,
}

/// A table of preformatted cells.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Table {
    pub caption: String,
    pub header: Vec<String>,
    pub rows: Vec<Vec<String>>,
}

/// A piece of a section.
#[derive(Clone, Debug, PartialEq)]
pub enum Block {
    /// A paragraph of plain text.
    Text(String),
    /// A command line, shown verbatim.
    Code(String),
    Table(Table),
    /// Terms and what they mean (a table's columns), as a definition list.
    Definitions(Vec<(String, String)>),
    /// Panels side by side.
    Panels(Vec<Panel>),
    /// An interactive 3D viewer.
    Viewer(Box<Scene>),
}

#[derive(Clone, Debug, PartialEq)]
pub struct Section {
    /// The element id (`summary`, `matching`, ...).
    pub id: String,
    pub title: String,
    pub blocks: Vec<Block>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    pub title: String,
    /// One line under the title: what was run, on what.
    pub subtitle: String,
    /// The verdict in one sentence, shown above the headline panels.
    pub verdict: String,
    /// The first screen: raw and leveled matched maps side by side, with their ATE.
    pub headline: Vec<Panel>,
    pub sections: Vec<Section>,
}

const REPORT_CSS: &str = include_str!("report.css");

/// Standard base64 (RFC 4648, with padding), for PNG data URLs.
pub fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

fn figure_html(f: &Figure, alt: &str) -> String {
    match f {
        // Our SVGs come from plotters; strip any XML prologue so it inlines cleanly.
        Figure::Svg(svg) => {
            let start = svg.find("<svg").unwrap_or(0);
            format!("<div class=\"lsr-figure\">{}</div>", &svg[start..])
        }
        Figure::Png(bytes) => format!(
            "<div class=\"lsr-figure\"><img alt=\"{}\" src=\"data:image/png;base64,{}\"></div>",
            escape_html(alt),
            base64(bytes)
        ),
        Figure::Missing(why) => format!(
            "<div class=\"lsr-figure lsr-missing\">figure not available: {}</div>",
            escape_html(why)
        ),
    }
}

fn panels_html(panels: &[Panel], class: &str) -> String {
    let mut s = format!("<div class=\"lsr-panels {class}\">\n");
    for p in panels {
        s.push_str(&format!(
            "<figure class=\"lsr-panel\"><figcaption><span class=\"lsr-panel-title\">{}</span> \
             <span class=\"lsr-metric\">{}</span></figcaption>\n{}\n<p class=\"lsr-caption\">{}</p></figure>\n",
            escape_html(&p.title),
            escape_html(&p.metric),
            figure_html(&p.figure, &p.title),
            escape_html(&p.caption),
        ));
    }
    s.push_str("</div>\n");
    s
}

fn table_html(t: &Table) -> String {
    let mut s = String::from("<table class=\"lsr-table\">\n");
    if !t.caption.is_empty() {
        s.push_str(&format!("<caption>{}</caption>\n", escape_html(&t.caption)));
    }
    s.push_str("<thead><tr>");
    for h in &t.header {
        s.push_str(&format!("<th>{}</th>", escape_html(h)));
    }
    s.push_str("</tr></thead>\n<tbody>\n");
    for row in &t.rows {
        s.push_str("<tr>");
        for c in row {
            s.push_str(&format!("<td>{}</td>", escape_html(c)));
        }
        s.push_str("</tr>\n");
    }
    s.push_str("</tbody></table>\n");
    s
}

fn definitions_html(terms: &[(String, String)]) -> String {
    let mut s = String::from("<dl class=\"lsr-defs\">\n");
    for (term, meaning) in terms {
        s.push_str(&format!(
            "<dt>{}</dt><dd>{}</dd>\n",
            escape_html(term),
            escape_html(meaning)
        ));
    }
    s.push_str("</dl>\n");
    s
}

/// Renders the whole page.
pub fn render(report: &Report) -> String {
    let mut body = String::new();
    body.push_str(&format!(
        "<header class=\"lsr-header\"><h1>{}</h1><p class=\"lsr-subtitle\">{}</p></header>\n",
        escape_html(&report.title),
        escape_html(&report.subtitle)
    ));
    let nav: Vec<String> = report
        .sections
        .iter()
        .map(|s| {
            format!(
                "<a href=\"#{}\">{}</a>",
                escape_html(&s.id),
                escape_html(&s.title)
            )
        })
        .collect();
    body.push_str(&format!(
        "<section id=\"summary\" class=\"lsr-section lsr-summary\">\n<p class=\"lsr-verdict\">{}</p>\n{}<nav class=\"lsr-nav\">{}</nav>\n</section>\n",
        escape_html(&report.verdict),
        panels_html(&report.headline, "lsr-headline"),
        nav.join(" \u{b7} ")
    ));
    let mut viewers = 0;
    for section in &report.sections {
        body.push_str(&format!(
            "<section id=\"{}\" class=\"lsr-section\">\n<h2>{}</h2>\n",
            escape_html(&section.id),
            escape_html(&section.title)
        ));
        for block in &section.blocks {
            match block {
                Block::Text(t) => body.push_str(&format!("<p>{}</p>\n", escape_html(t))),
                Block::Code(c) => body.push_str(&format!(
                    "<pre class=\"lsr-code\">{}</pre>\n",
                    escape_html(c)
                )),
                Block::Table(t) => body.push_str(&table_html(t)),
                Block::Definitions(d) => body.push_str(&definitions_html(d)),
                Block::Panels(p) => body.push_str(&panels_html(p, "")),
                Block::Viewer(scene) => {
                    viewers += 1;
                    let id = format!("{}-viewer{}", section.id, viewers);
                    body.push_str(&viewer_fragment(scene, &id));
                }
            }
        }
        body.push_str("</section>\n");
    }
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>{title}</title>\n{assets}<style>\n{REPORT_CSS}</style>\n</head>\n\
         <body class=\"lsr\">\n{body}</body>\n</html>\n",
        title = escape_html(&report.title),
        assets = page_head_assets(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_test_vectors() {
        let cases = [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ];
        for (plain, encoded) in cases {
            assert_eq!(base64(plain.as_bytes()), encoded);
        }
        assert_eq!(base64(&[0xff, 0xfe, 0xfd]), "//79");
    }

    fn panel(title: &str) -> Panel {
        Panel {
            title: title.into(),
            metric: "ATE 1.0 m".into(),
            caption: "c".into(),
            figure: Figure::Svg("<?xml version=\"1.0\"?><svg width=\"1\"></svg>".into()),
        }
    }

    #[test]
    fn headline_comes_first_and_sections_keep_their_ids() {
        let report = Report {
            title: "T <1>".into(),
            subtitle: "s".into(),
            verdict: "Leveling works".into(),
            headline: vec![panel("raw"), panel("leveled")],
            sections: vec![
                Section {
                    id: "matching".into(),
                    title: "Matching".into(),
                    blocks: vec![Block::Table(Table {
                        caption: "cap".into(),
                        header: vec!["run".into(), "ATE".into()],
                        rows: vec![vec!["raw".into(), "1 & 2".into()]],
                    })],
                },
                Section {
                    id: "viewer".into(),
                    title: "3D".into(),
                    blocks: vec![Block::Viewer(Box::new(Scene {
                        title: "pose".into(),
                        notes: vec![],
                        top_down: false,
                        layers: vec![],
                    }))],
                },
            ],
        };
        let page = render(&report);
        let summary = page.find("id=\"summary\"").unwrap();
        let matching = page.find("id=\"matching\"").unwrap();
        let viewer = page.find("id=\"viewer-viewer1\"").unwrap();
        assert!(summary < matching && matching < viewer);
        let raw = page.find(">raw<").unwrap();
        let leveled = page.find(">leveled<").unwrap();
        assert!(summary < raw && raw < leveled && leveled < matching);
        assert!(page.contains("<td>1 &amp; 2</td>"));
        assert!(page.contains("<title>T &lt;1&gt;</title>"));
        assert!(!page.contains("<?xml"));
    }

    #[test]
    fn png_figures_are_inlined_and_missing_ones_say_why() {
        let png = figure_html(&Figure::Png(vec![1, 2, 3]), "m");
        assert!(png.contains("src=\"data:image/png;base64,AQID\""));
        let missing = figure_html(&Figure::Missing("no <font>".into()), "m");
        assert!(missing.contains("figure not available: no &lt;font&gt;"));
    }
}
