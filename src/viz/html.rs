//! The self-contained 3D viewer page: the paper's visualizer (sect. 7.2.3, Fig. 5), as one
//! offline HTML file with hand-written JavaScript (`viewer.js`, canvas 2D with its own
//! projection) drawing a [`Scene`] ([`super::scene`]).

use super::scene::Scene;

/// The viewer's JavaScript, embedded so that pages work offline.
pub const VIEWER_JS: &str = include_str!("viewer.js");
/// The viewer's style sheet.
pub const VIEWER_CSS: &str = include_str!("viewer.css");

/// The scene as JSON that is safe inside a `<script>` element (`</` is escaped).
pub fn scene_json(scene: &Scene) -> String {
    let json = serde_json::to_string(scene).unwrap_or_else(|_| "{}".to_string());
    escape_script(&json)
}

/// Escapes text for embedding in a `<script>` element: a literal `</` would end it early.
pub fn escape_script(json: &str) -> String {
    json.replace("</", "<\\/")
}

/// Escapes text for HTML element content and attribute values.
pub fn escape_html(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for ch in s.chars() {
        match ch {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// The HTML fragment of one viewer: its container, the scene data and the call that mounts
/// it. The page must include [`VIEWER_JS`] and [`VIEWER_CSS`] once (see [`page_head_assets`]).
pub fn viewer_fragment(scene: &Scene, element_id: &str) -> String {
    viewer_fragment_with_class(scene, element_id, "lsv")
}

fn viewer_fragment_with_class(scene: &Scene, element_id: &str, class: &str) -> String {
    let id = escape_html(element_id);
    format!(
        "<div class=\"{class}\" id=\"{id}\"></div>\n\
         <script type=\"application/json\" id=\"{id}-data\">{json}</script>\n\
         <script>LevelscanViewer.mount(document.getElementById(\"{id}\"), \
         JSON.parse(document.getElementById(\"{id}-data\").textContent));</script>\n",
        json = scene_json(scene),
    )
}

/// The viewer's style and script, for a page's `<head>`.
pub fn page_head_assets() -> String {
    format!("<style>\n{VIEWER_CSS}</style>\n<script>\n{VIEWER_JS}</script>\n")
}

/// A whole self-contained page with one full-window viewer.
pub fn viewer_page(scene: &Scene) -> String {
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>{title}</title>\n{assets}</head>\n<body class=\"lsv-page\">\n\
         <h1 class=\"lsv-title\">{title}</h1>\n{viewer}</body>\n</html>\n",
        title = escape_html(&scene.title),
        assets = page_head_assets(),
        viewer = viewer_fragment_with_class(scene, "viewer", "lsv lsv-full"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn script_end_tag_in_title_cannot_break_the_page() {
        let scene = Scene {
            title: "</script><b>".into(),
            notes: vec![],
            top_down: false,
            layers: vec![],
        };
        let page = viewer_page(&scene);
        assert_eq!(page.matches("</script>").count(), 3);
        assert!(page.contains("&lt;/script&gt;&lt;b&gt;"));
        assert!(scene_json(&scene).contains("<\\/script>"));
    }
}
