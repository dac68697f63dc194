//! A real browser test: headless Chromium loads the viewer page and the demo report, and the
//! test fails on any console error or uncaught exception, checks the report's named sections,
//! and checks from screenshots that the 3D canvas drew and that a layer toggle changes it.
//!
//! Chromium is driven over the Chrome DevTools Protocol (its websocket, flattened sessions).
//! Without Chromium the tests say they are skipped, unless `LEVELSCAN_REQUIRE_BROWSER=1`, when
//! they fail. `LEVELSCAN_SCREENSHOT_DIR=DIR` also writes the screenshots there as PNG:
//!
//! ```text
//! LEVELSCAN_SCREENSHOT_DIR=/tmp/shots cargo test --release --test browser
//! ```

use serde_json::{Value, json};
use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use tungstenite::stream::MaybeTlsStream;
use tungstenite::{Message, WebSocket};

const BIN: &str = env!("CARGO_BIN_EXE_levelscan");
/// The viewer's background colour (`BACKGROUND` in src/viz/viewer.js).
const BACKGROUND: [u8; 3] = [246, 246, 242];
const TIMEOUT: Duration = Duration::from_secs(60);

fn chromium_path() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("LEVELSCAN_CHROMIUM") {
        return Some(PathBuf::from(p));
    }
    ["/usr/bin/chromium", "/usr/bin/chromium-browser"]
        .iter()
        .map(PathBuf::from)
        .find(|p| p.exists())
}

/// Chromium's path, or `None` after saying the test is skipped; fails instead when the
/// environment requires the browser (CI).
fn chromium_or_skip(test: &str) -> Option<PathBuf> {
    let found = chromium_path();
    if found.is_none() {
        if std::env::var("LEVELSCAN_REQUIRE_BROWSER").as_deref() == Ok("1") {
            panic!("{test}: chromium not found and LEVELSCAN_REQUIRE_BROWSER=1");
        }
        eprintln!(
            "{test}: SKIPPED: chromium not found (install it, e.g. apt-get install chromium)"
        );
    }
    found
}

/// A fresh directory under the system temp dir, removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new(tag: &str) -> TempDir {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0);
        let dir =
            std::env::temp_dir().join(format!("levelscan-{tag}-{}-{nanos}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        TempDir(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// One headless Chromium with one page, attached over a flattened DevTools session.
struct Browser {
    child: Child,
    ws: WebSocket<MaybeTlsStream<TcpStream>>,
    session: String,
    next_id: u64,
    events: Vec<Value>,
    _profile: TempDir,
}

impl Browser {
    fn launch(chromium: &Path) -> Browser {
        let profile = TempDir::new("chromium-profile");
        let mut child = Command::new(chromium)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--hide-scrollbars",
                "--mute-audio",
                "--force-device-scale-factor=1",
                "--window-size=1280,1000",
                "--remote-debugging-port=0",
            ])
            .arg(format!("--user-data-dir={}", profile.0.display()))
            .arg("about:blank")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start chromium");
        // Chromium prints `DevTools listening on ws://...` on stderr; keep draining it after
        // that so the pipe never fills.
        let stderr = child.stderr.take().expect("chromium stderr");
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                if let Some(i) = line.find("ws://") {
                    let _ = tx.send(line[i..].trim().to_string());
                }
            }
        });
        let url = match rx.recv_timeout(TIMEOUT) {
            Ok(u) => u,
            Err(_) => {
                let _ = child.kill();
                let _ = child.wait();
                panic!("chromium did not print its DevTools websocket address");
            }
        };
        let (ws, _) = tungstenite::connect(url.as_str()).expect("connect to DevTools");
        if let MaybeTlsStream::Plain(s) = ws.get_ref() {
            s.set_read_timeout(Some(TIMEOUT)).unwrap();
        }
        let mut b = Browser {
            child,
            ws,
            session: String::new(),
            next_id: 0,
            events: Vec::new(),
            _profile: profile,
        };
        let target = b.call_browser("Target.createTarget", json!({"url": "about:blank"}));
        let target_id = target["targetId"].as_str().unwrap().to_string();
        let attached = b.call_browser(
            "Target.attachToTarget",
            json!({"targetId": target_id, "flatten": true}),
        );
        b.session = attached["sessionId"].as_str().unwrap().to_string();
        b.call("Runtime.enable", json!({}));
        b.call("Log.enable", json!({}));
        b.call("Page.enable", json!({}));
        b.call(
            "Emulation.setDeviceMetricsOverride",
            json!({"width": 1280, "height": 1000, "deviceScaleFactor": 1, "mobile": false}),
        );
        b
    }

    fn send(&mut self, method: &str, params: Value, session: Option<String>) -> Value {
        self.next_id += 1;
        let id = self.next_id;
        let mut msg = json!({"id": id, "method": method, "params": params});
        if let Some(s) = session {
            msg["sessionId"] = Value::String(s);
        }
        self.ws
            .send(Message::text(msg.to_string()))
            .expect("send to DevTools");
        let start = Instant::now();
        loop {
            assert!(start.elapsed() < TIMEOUT, "{method}: no answer");
            let m = self.ws.read().expect("read from DevTools");
            let Ok(text) = m.to_text() else { continue };
            let Ok(v) = serde_json::from_str::<Value>(text) else {
                continue;
            };
            if v["id"].as_u64() == Some(id) {
                if let Some(e) = v.get("error") {
                    panic!("{method} failed: {e}");
                }
                return v["result"].clone();
            }
            if v.get("method").is_some() {
                self.events.push(v);
            }
        }
    }

    fn call_browser(&mut self, method: &str, params: Value) -> Value {
        self.send(method, params, None)
    }

    fn call(&mut self, method: &str, params: Value) -> Value {
        let s = self.session.clone();
        self.send(method, params, Some(s))
    }

    /// Waits for an event of the page's session.
    fn wait_event(&mut self, method: &str) {
        let start = Instant::now();
        let seen = |e: &Value| e["method"] == method;
        while !self.events.iter().any(seen) {
            assert!(start.elapsed() < TIMEOUT, "no {method} event");
            let m = self.ws.read().expect("read from DevTools");
            if let Ok(v) = serde_json::from_str::<Value>(m.to_text().unwrap_or("")) {
                if v.get("method").is_some() {
                    self.events.push(v);
                }
            }
        }
    }

    fn open(&mut self, path: &Path) {
        let url = format!("file://{}", path.canonicalize().unwrap().display());
        self.call("Page.navigate", json!({"url": url}));
        self.wait_event("Page.loadEventFired");
        // Two animation frames: every viewer has drawn.
        self.eval(
            "new Promise(r => requestAnimationFrame(() => requestAnimationFrame(() => r(true))))",
        );
    }

    /// Evaluates an expression in the page (awaiting promises) and returns its value.
    fn eval(&mut self, expr: &str) -> Value {
        let r = self.call(
            "Runtime.evaluate",
            json!({"expression": expr, "returnByValue": true, "awaitPromise": true}),
        );
        if let Some(e) = r.get("exceptionDetails") {
            panic!("evaluating `{expr}` threw: {e}");
        }
        r["result"]["value"].clone()
    }

    /// Console errors, failed asserts, uncaught exceptions and error log entries so far.
    fn errors(&self) -> Vec<String> {
        self.events
            .iter()
            .filter_map(|e| match e["method"].as_str()? {
                "Runtime.exceptionThrown" => Some(format!(
                    "uncaught exception: {}",
                    e["params"]["exceptionDetails"]
                )),
                "Runtime.consoleAPICalled"
                    if matches!(e["params"]["type"].as_str(), Some("error" | "assert")) =>
                {
                    Some(format!("console.error: {}", e["params"]["args"]))
                }
                "Log.entryAdded" if e["params"]["entry"]["level"] == "error" => {
                    Some(format!("log error: {}", e["params"]["entry"]))
                }
                _ => None,
            })
            .collect()
    }

    fn assert_no_errors(&self, what: &str) {
        let errors = self.errors();
        assert!(
            errors.is_empty(),
            "{what}: the page reported errors:\n{}",
            errors.join("\n")
        );
    }

    /// A screenshot of the element matched by `selector`, scrolled into view, as RGB rows.
    fn screenshot_element(&mut self, selector: &str, name: &str) -> Image {
        let rect = self.eval(&format!(
            "(() => {{ const e = document.querySelector({sel}); e.scrollIntoView({{block: 'start'}}); \
             const r = e.getBoundingClientRect(); return [r.left, r.top, r.width, r.height]; }})()",
            sel = serde_json::to_string(selector).unwrap()
        ));
        let r: Vec<f64> = rect
            .as_array()
            .unwrap_or_else(|| panic!("no element {selector}"))
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let shot = self.call("Page.captureScreenshot", json!({"format": "png"}));
        let bytes = data_encoding::BASE64
            .decode(shot["data"].as_str().unwrap().as_bytes())
            .unwrap();
        if let Some(dir) = std::env::var_os("LEVELSCAN_SCREENSHOT_DIR") {
            std::fs::create_dir_all(&dir).unwrap();
            std::fs::write(Path::new(&dir).join(format!("{name}.png")), &bytes).unwrap();
        }
        decode_png(&bytes).crop(r[0] as usize, r[1] as usize, r[2] as usize, r[3] as usize)
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.ws.close(None);
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// An RGB image.
struct Image {
    width: usize,
    height: usize,
    rgb: Vec<u8>,
}

impl Image {
    fn pixel(&self, x: usize, y: usize) -> [u8; 3] {
        let i = 3 * (y * self.width + x);
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    fn crop(&self, x0: usize, y0: usize, w: usize, h: usize) -> Image {
        let x1 = (x0 + w).min(self.width);
        let y1 = (y0 + h).min(self.height);
        let mut rgb = Vec::new();
        for y in y0..y1 {
            for x in x0..x1 {
                rgb.extend(self.pixel(x, y));
            }
        }
        Image {
            width: x1.saturating_sub(x0),
            height: y1.saturating_sub(y0),
            rgb,
        }
    }

    fn pixels(&self) -> usize {
        self.width * self.height
    }

    /// Pixels that differ from `color` by more than a small tolerance in some channel.
    fn count_unlike(&self, color: [u8; 3]) -> usize {
        self.rgb
            .chunks(3)
            .filter(|p| (0..3).any(|c| p[c].abs_diff(color[c]) > 16))
            .count()
    }

    fn count_changed(&self, other: &Image) -> usize {
        assert_eq!((self.width, self.height), (other.width, other.height));
        self.rgb
            .chunks(3)
            .zip(other.rgb.chunks(3))
            .filter(|(a, b)| (0..3).any(|c| a[c].abs_diff(b[c]) > 16))
            .count()
    }
}

fn decode_png(bytes: &[u8]) -> Image {
    let mut decoder = png::Decoder::new(bytes);
    decoder.set_transformations(png::Transformations::normalize_to_color8());
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    let rgb = buf[..info.buffer_size()]
        .chunks(channels)
        .flat_map(|p| match channels {
            1 | 2 => [p[0], p[0], p[0]],
            _ => [p[0], p[1], p[2]],
        })
        .collect();
    Image {
        width: info.width as usize,
        height: info.height as usize,
        rgb,
    }
}

fn run_levelscan(args: &[&str]) {
    let out = Command::new(BIN).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "levelscan {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Checks a viewer on the current page: it drew, and hiding `layer` changes the canvas.
fn check_viewer_draws_and_toggles(b: &mut Browser, root: &str, layer: &str, name: &str) {
    let canvas = format!("{root} canvas.lsv-canvas");
    let before = b.screenshot_element(&canvas, &format!("{name}-all-layers"));
    assert!(before.pixels() > 100_000, "{name}: canvas too small");
    let drawn = before.count_unlike(BACKGROUND);
    assert!(
        drawn * 100 > before.pixels(),
        "{name}: only {drawn} of {} canvas pixels drawn",
        before.pixels()
    );
    let toggle = format!("{root} .lsv-toggle[data-layer=\"{layer}\"]");
    let clicked = b.eval(&format!(
        "(() => {{ const t = document.querySelector({sel}); if (!t) return false; t.click(); return !t.checked; }})()",
        sel = serde_json::to_string(&toggle).unwrap()
    ));
    assert_eq!(clicked, Value::Bool(true), "{name}: no toggle for {layer}");
    let after = b.screenshot_element(&canvas, &format!("{name}-without-{layer}"));
    let changed = after.count_changed(&before);
    assert!(
        changed * 1000 > before.pixels(),
        "{name}: hiding {layer} changed only {changed} pixels"
    );
    // Ticking it again brings back exactly the first picture.
    b.eval(&format!(
        "document.querySelector({}).click()",
        serde_json::to_string(&toggle).unwrap()
    ));
    let again = b.screenshot_element(&canvas, &format!("{name}-all-layers-again"));
    assert_eq!(
        again.count_changed(&before),
        0,
        "{name}: showing {layer} again did not restore the view"
    );
}

/// Checks a viewer's scale bar: present, labelled in metres, as long on screen as it says
/// (the viewer's pixels per metre at the view's centre), and following a zoom.
fn check_scale_bar(b: &mut Browser, root: &str, name: &str) {
    let read = |b: &mut Browser| {
        b.eval(&format!(
            "(() => {{ const r0 = document.querySelector({sel}); const r = r0.classList.contains('lsv') ? r0 : r0.querySelector('.lsv');
               const bar = r.querySelector('.lsv-scale-bar');
               const label = r.querySelector('.lsv-scale-label'); const api = LevelscanViewer.instances.find(v => v.root === r);
               if (!bar || !label || !api) return null;
               return {{width: bar.getBoundingClientRect().width, label: label.textContent, scale: api.stats.scale}}; }})()",
            sel = serde_json::to_string(root).unwrap()
        ))
    };
    let before = read(b);
    assert!(before.is_object(), "{name}: no scale bar in {root}");
    let label = before["label"].as_str().unwrap();
    let metres = before["scale"]["metres"].as_f64().unwrap();
    let per_metre = before["scale"]["pxPerMetre"].as_f64().unwrap();
    let width = before["width"].as_f64().unwrap();
    assert!(
        label.contains(" m") || label.contains(" cm"),
        "{name}: scale label {label:?}"
    );
    assert!(
        label.contains("grid"),
        "{name}: grid step not named: {label:?}"
    );
    // The bar's border adds 2 px on each side.
    assert!(
        (width - 4.0 - metres * per_metre).abs() < 1.5,
        "{name}: bar {width} px for {metres} m at {per_metre} px/m"
    );
    assert!((20.0..=150.0).contains(&width), "{name}: bar {width} px");
    b.eval(&format!(
        "(() => {{ const c = document.querySelector({sel}); c.dispatchEvent(new WheelEvent('wheel', {{deltaY: 800, bubbles: true, cancelable: true}}));
           return new Promise(res => requestAnimationFrame(() => res(true))); }})()",
        sel = serde_json::to_string(&format!("{root} canvas.lsv-canvas")).unwrap()
    ));
    let after = read(b);
    let zoomed = after["scale"]["pxPerMetre"].as_f64().unwrap();
    assert!(
        zoomed < per_metre * 0.8,
        "{name}: zooming out left {zoomed} px/m"
    );
    // Back to the first view for the checks that follow.
    b.eval(&format!(
        "document.querySelector({}).dispatchEvent(new MouseEvent('dblclick', {{bubbles: true}}))",
        serde_json::to_string(&format!("{root} canvas.lsv-canvas")).unwrap()
    ));
}

#[test]
fn viewer_page_draws_and_layer_toggle_changes_it() {
    let Some(chromium) = chromium_or_skip("viewer_page_draws_and_layer_toggle_changes_it") else {
        return;
    };
    let dir = TempDir::new("browser-view");
    let (plan, scans) = write_box_room_inputs(&dir.0);
    let page = dir.0.join("view.html");
    run_levelscan(&[
        "view",
        scans.to_str().unwrap(),
        "--plan",
        plan.to_str().unwrap(),
        "-o",
        page.to_str().unwrap(),
    ]);
    let mut b = Browser::launch(&chromium);
    b.open(&page);
    b.assert_no_errors("view.html");
    let layers = b.eval(
        "Array.from(document.querySelectorAll('#viewer .lsv-toggle')).map(t => t.dataset.layer)",
    );
    assert_eq!(layers, json!(["plan", "scans", "poses"]));
    check_viewer_draws_and_toggles(&mut b, "#viewer", "scans", "view");
    check_scale_bar(&mut b, "#viewer", "view");
    // Orbit and zoom with the mouse: the view changes and nothing throws.
    let before = b.screenshot_element("#viewer canvas.lsv-canvas", "view-before-orbit");
    b.eval(
        "(() => { const c = document.querySelector('#viewer canvas'); const r = c.getBoundingClientRect();
           const at = (t, x, y) => c.dispatchEvent(new PointerEvent(t, {clientX: x, clientY: y, button: 0, bubbles: true, pointerId: 1}));
           at('pointerdown', r.left + 300, r.top + 300); at('pointermove', r.left + 420, r.top + 340); at('pointerup', r.left + 420, r.top + 340);
           c.dispatchEvent(new WheelEvent('wheel', {deltaY: -300, bubbles: true, cancelable: true}));
           return new Promise(res => requestAnimationFrame(() => res(true))); })()",
    );
    let after = b.screenshot_element("#viewer canvas.lsv-canvas", "view-after-orbit");
    assert!(after.count_changed(&before) * 100 > before.pixels());
    b.assert_no_errors("view.html after orbit and zoom");
}

/// A box room 8 m x 6 m (walls 2.5 m high) and, from one tilted pose in it, three analytic
/// scans at elevations -5, 0 and 5 degrees: ray casting against the four walls, the floor and
/// the ceiling, written as the contract's scan JSON Lines.
fn write_box_room_inputs(dir: &Path) -> (PathBuf, PathBuf) {
    let plan = dir.join("box.wall");
    std::fs::write(
        &plan,
        r#"{"version": "w0.1", "wallheight": 2.5,
            "walls": [[[0, 0], [8, 0], [8, 6], [0, 6], [0, 0]]]}"#,
    )
    .unwrap();
    let pose = levelscan::geometry::Pose::new(3.0, 2.0, 0.45, 0.4, 0.12, -0.08);
    let r = pose.world_from_robot_rotation();
    let origin = nalgebra::Vector3::new(pose.x, pose.y, pose.z);
    let mut text = String::new();
    for e_deg in [-5.0f64, 0.0, 5.0] {
        let e = e_deg.to_radians();
        let bearings: Vec<f64> = (0..181).map(|i| (i as f64 - 90.0).to_radians()).collect();
        let readings: Vec<f64> = bearings
            .iter()
            .map(|&phi| {
                let d = r * levelscan::geometry::beam_direction(e, phi);
                let mut best = f64::INFINITY;
                for (axis, lo, hi) in [(0, 0.0, 8.0), (1, 0.0, 6.0), (2, 0.0, 2.5)] {
                    for plane in [lo, hi] {
                        let t = (plane - origin[axis]) / d[axis];
                        if t > 1e-9 && t < best {
                            best = t;
                        }
                    }
                }
                best
            })
            .collect();
        let line = json!({
            "sequence": 0, "nrays": 181, "elevation": e, "theta": bearings, "readings": readings,
            "true_pose": pose.to_array(),
        });
        text.push_str(&line.to_string());
        text.push('\n');
    }
    let scans = dir.join("scans.jsonl");
    std::fs::write(&scans, text).unwrap();
    (plan, scans)
}

#[test]
fn demo_report_has_its_sections_and_its_viewer_draws() {
    let Some(chromium) = chromium_or_skip("demo_report_has_its_sections_and_its_viewer_draws")
    else {
        return;
    };
    let dir = TempDir::new("browser-demo");
    let out = dir.0.join("demo");
    run_levelscan(&[
        "demo",
        "--out",
        out.to_str().unwrap(),
        "--accuracy-poses",
        "5",
    ]);
    let mut b = Browser::launch(&chromium);
    b.open(&out.join("report.html"));
    b.assert_no_errors("report.html");
    let sections = b.eval("Array.from(document.querySelectorAll('section')).map(s => s.id)");
    for id in [
        "summary", "matching", "run", "accuracy", "viewer", "maps", "data",
    ] {
        assert!(
            sections.as_array().unwrap().iter().any(|s| s == id),
            "section {id} missing from {sections}"
        );
    }
    // The first screen: raw and leveled maps side by side, each with its ATE, both drawn.
    let headline = b.eval(
        "Array.from(document.querySelectorAll('#summary .lsr-panel')).map(p => {
           const r = p.getBoundingClientRect(); const img = p.querySelector('img, svg');
           return {title: p.querySelector('.lsr-panel-title').textContent,
                   metric: p.querySelector('.lsr-metric').textContent,
                   top: r.top, left: r.left, bottom: r.bottom,
                   drawn: !!img && (img.tagName !== 'IMG' || (img.complete && img.naturalWidth > 0))}; })",
    );
    let panels = headline.as_array().unwrap();
    assert_eq!(panels.len(), 2, "{headline}");
    assert!(panels[0]["title"].as_str().unwrap().starts_with("Raw"));
    assert!(panels[1]["title"].as_str().unwrap().starts_with("Leveled"));
    for p in panels {
        assert!(p["metric"].as_str().unwrap().starts_with("ATE 0."), "{p}");
        assert_eq!(p["drawn"], Value::Bool(true), "{p}");
        // Within the first screen (1000 px high), and side by side.
        assert!(p["bottom"].as_f64().unwrap() < 1000.0, "{p}");
    }
    assert_eq!(panels[0]["top"], panels[1]["top"]);
    assert!(panels[0]["left"].as_f64() < panels[1]["left"].as_f64());
    let tables = b.eval(
        "[document.querySelectorAll('#matching table tbody tr').length,
          document.querySelectorAll('#accuracy table tbody tr').length]",
    );
    assert_eq!(tables, json!([6, 9]), "matching runs and Table I cells");
    let figures = b.eval(
        "[document.querySelectorAll('#accuracy svg').length, document.querySelectorAll('#maps img').length,
          document.querySelectorAll('#run svg').length, document.querySelectorAll('.lsr-missing').length]",
    );
    assert_eq!(
        figures,
        json!([2, 3, 2, 0]),
        "accuracy charts, maps, run plots, missing figures"
    );
    // Roll and pitch over time and the error along the trajectory: axes named, readable.
    let run_texts = b.eval(
        "Array.from(document.querySelectorAll('#run svg text')).map(t => t.textContent.trim())",
    );
    for name in [
        "roll theta_x [deg]",
        "pitch theta_y [deg]",
        "estimate +- 3 sigma",
        "x [m]",
        "position error [m]",
        "distance travelled [m]",
    ] {
        assert!(
            run_texts.as_array().unwrap().iter().any(|t| t == name),
            "{name} missing from the run plots"
        );
    }
    // Table I and Fig. 6: every text at least 12 px on the page, as the report shows them.
    let smallest = b.eval(
        "Math.min(...Array.from(document.querySelectorAll('#accuracy svg')).flatMap(svg => {
           const k = svg.getBoundingClientRect().width / svg.viewBox.baseVal.width;
           return Array.from(svg.querySelectorAll('text')).filter(t => t.textContent.trim())
             .map(t => parseFloat(t.getAttribute('font-size')) * k); }))",
    );
    assert!(
        smallest.as_f64().unwrap() >= 12.0,
        "smallest chart text {smallest} px"
    );
    // Fig. 6 keeps the poses beyond its axis in an overflow bin.
    let fig6 = b.eval(
        "Array.from(document.querySelectorAll('#accuracy svg')[1].querySelectorAll('text')).map(t => t.textContent.trim())",
    );
    assert!(
        fig6.as_array()
            .unwrap()
            .iter()
            .any(|t| t.as_str().unwrap().starts_with("> ")),
        "no overflow bin in {fig6}"
    );
    // The columns are defined.
    let terms =
        b.eval("Array.from(document.querySelectorAll('#accuracy dl dt')).map(d => d.textContent)");
    for term in ["ok but > 5 deg", "phantoms", "coverage"] {
        assert!(
            terms.as_array().unwrap().iter().any(|t| t == term),
            "{term} not defined: {terms}"
        );
    }
    let _ = b.screenshot_element("#summary", "report-first-screen");
    let _ = b.screenshot_element("#accuracy", "report-accuracy");
    check_viewer_draws_and_toggles(&mut b, "#viewer", "polygons", "report-pose");
    check_viewer_draws_and_toggles(&mut b, "#maps", "matched", "report-matched");
    check_scale_bar(&mut b, "#viewer", "report-pose");
    check_scale_bar(&mut b, "#maps", "report-matched");
    let matched = b.eval(
        "Array.from(document.querySelectorAll('#maps .lsv-toggle')).map(t => t.parentElement.textContent)",
    );
    let labels = matched.as_array().unwrap();
    assert!(
        labels
            .iter()
            .any(|l| l.as_str().unwrap().starts_with("Reference path")),
        "{matched}"
    );
    assert!(
        labels
            .iter()
            .any(|l| l.as_str().unwrap().starts_with("Robot path")),
        "{matched}"
    );
    b.assert_no_errors("report.html after toggles");
    for map in ["map_leveled_metascan.svg", "map_level_floor.svg"] {
        check_map_axes_and_legend(&mut b, &out.join(map), map);
    }
}

/// A map as the demo writes it: axes named in metres with numbered ticks, a scale bar, and a
/// legend that covers no wall (its texts lie outside the box of the plan's wall lines).
fn check_map_axes_and_legend(b: &mut Browser, svg: &Path, name: &str) {
    b.open(svg);
    b.assert_no_errors(name);
    let found = b.eval(
        "(() => { const texts = Array.from(document.querySelectorAll('text'));
           const t = s => texts.filter(e => e.textContent.trim() === s);
           const box = r => ({l: r.left, r: r.right, t: r.top, b: r.bottom});
           const walls = Array.from(document.querySelectorAll('polyline[stroke=\"#969696\"]'))
             .map(e => box(e.getBoundingClientRect()));
           const legend = ['plan walls', 'matched points', 'true path', 'estimated path']
             .flatMap(s => t(s)).map(e => box(e.getBoundingClientRect()));
           const hits = legend.filter(l => walls.some(w => l.l < w.r && l.r > w.l && l.t < w.b && l.b > w.t));
           return {x: t('x [m]').length, y: t('y [m]').length,
                   ticks: texts.filter(e => /^-?[0-9]+$/.test(e.textContent.trim())).length,
                   scale: texts.filter(e => /^scale [0-9]+ c?m$/.test(e.textContent.trim())).length,
                   walls: walls.length, legend: legend.length, covered: hits.length}; })()",
    );
    let n = |k: &str| found[k].as_u64().unwrap();
    assert!(
        n("x") >= 1 && n("y") >= 1,
        "{name}: axes not named: {found}"
    );
    assert!(n("ticks") >= 8, "{name}: too few tick labels: {found}");
    assert!(n("scale") >= 1, "{name}: no scale bar: {found}");
    assert!(n("walls") >= 10 && n("legend") >= 4, "{name}: {found}");
    assert_eq!(n("covered"), 0, "{name}: the legend covers a wall: {found}");
}
