/* levelscan viewer: the paper's 3D visualizer (Saunders 2008, sect. 7.2.3, Fig. 5) on a plain
 * canvas 2D context with its own perspective projection, so a page works offline and without a
 * GPU. Scene data (see src/viz/html.rs) is in integer millimetres.
 *
 * Controls: drag to orbit (pan in top-down mode), right-drag or shift-drag to pan, wheel to zoom,
 * double-click to reset. One checkbox per layer. A scale bar (bottom left) gives metres at the
 * view's centre; the floor grid's step is named beside it. */
(function (global) {
  "use strict";

  var FOV = 50 * Math.PI / 180;
  var BACKGROUND = "#f6f6f2";

  function el(tag, cls, text) {
    var e = document.createElement(tag);
    if (cls) e.className = cls;
    if (text !== undefined) e.textContent = text;
    return e;
  }

  function rgba(c, a) {
    return "rgba(" + c[0] + "," + c[1] + "," + c[2] + "," + a + ")";
  }

  function toMetres(list) {
    var out = new Float32Array(list.length);
    for (var i = 0; i < list.length; i++) out[i] = list[i] / 1000;
    return out;
  }

  // world = Rz(rz) * Ry(ry) * Rx(rx) * p + t  (the contract's pose convention)
  function poseMatrix(rz, ry, rx) {
    var cz = Math.cos(rz), sz = Math.sin(rz);
    var cy = Math.cos(ry), sy = Math.sin(ry);
    var cx = Math.cos(rx), sx = Math.sin(rx);
    return [
      cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx,
      sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx,
      -sy, cy * sx, cy * cx
    ];
  }

  // A flattened cone pointing forward (+x), as triangles in the world frame.
  function coneFaces(cone, length, shade) {
    var m = poseMatrix(cone.r[0], cone.r[1], cone.r[2]);
    var t = [cone.t[0] / 1000, cone.t[1] / 1000, cone.t[2] / 1000];
    function w(p) {
      return [
        m[0] * p[0] + m[1] * p[1] + m[2] * p[2] + t[0],
        m[3] * p[0] + m[4] * p[1] + m[5] * p[2] + t[1],
        m[6] * p[0] + m[7] * p[1] + m[8] * p[2] + t[2]
      ];
    }
    var apex = w([length, 0, 0]);
    var ring = [];
    var n = 10;
    for (var k = 0; k < n; k++) {
      var a = 2 * Math.PI * k / n;
      ring.push(w([0, 0.45 * length * Math.cos(a), 0.15 * length * Math.sin(a)]));
    }
    var g = Math.round(255 * (1 - shade));
    var fill = "rgba(" + g + "," + g + "," + g + ",0.95)";
    var faces = [];
    for (var j = 0; j < n; j++) {
      var b = ring[j], c = ring[(j + 1) % n];
      faces.push({ p: new Float32Array([apex[0], apex[1], apex[2], b[0], b[1], b[2], c[0], c[1], c[2]]), fill: fill, edge: true });
    }
    var cap = [];
    ring.forEach(function (q) { cap.push(q[0], q[1], q[2]); });
    faces.push({ p: new Float32Array(cap), fill: fill, edge: true });
    return faces;
  }

  function bounds(layers) {
    var lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    function add(arr) {
      for (var i = 0; i + 2 < arr.length; i += 3) {
        for (var d = 0; d < 3; d++) {
          if (arr[i + d] < lo[d]) lo[d] = arr[i + d];
          if (arr[i + d] > hi[d]) hi[d] = arr[i + d];
        }
      }
    }
    layers.forEach(function (L) {
      L.lines.forEach(add);
      L.faces.forEach(function (f) { add(f.p); });
      L.cones.forEach(function (c) { add([c.t[0] / 1000, c.t[1] / 1000, c.t[2] / 1000]); });
    });
    if (!isFinite(lo[0])) return { lo: [-1, -1, 0], hi: [1, 1, 1] };
    return { lo: lo, hi: hi };
  }

  function mount(root, scene) {
    var layers = scene.layers.map(function (L) {
      return {
        id: L.id, label: L.label, visible: L.visible, color: L.color, width: L.width,
        lines: L.lines.map(toMetres),
        faces: L.faces.map(function (f) {
          return { p: toMetres(f.p), fill: rgba(f.c, f.a), edge: L.id === "plan" };
        }),
        cones: L.cones,
        points: L.lines.reduce(function (s, l) { return s + l.length / 3; }, 0)
      };
    });
    // The view fits the data shown at first; the floor plan is context, fitted only alone.
    var data = layers.filter(function (L) { return L.visible && L.id !== "plan"; });
    var box = bounds(data.length ? data : layers);
    var size = [box.hi[0] - box.lo[0], box.hi[1] - box.lo[1], box.hi[2] - box.lo[2]];
    var diag = Math.max(1e-3, Math.sqrt(size[0] * size[0] + size[1] * size[1] + size[2] * size[2]));
    // Cones scale with the scene, and shrink when there are many so a long run stays readable.
    var coneCount = layers.reduce(function (n, L) { return n + L.cones.length; }, 0);
    var coneLength = Math.min(Math.max(diag / 40 / Math.sqrt(Math.max(1, coneCount / 60)), 0.15), 0.8);
    layers.forEach(function (L) {
      L.coneFaces = [];
      L.cones.forEach(function (c) { L.coneFaces = L.coneFaces.concat(coneFaces(c, coneLength, c.s)); });
    });

    root.textContent = "";
    var bar = el("div", "lsv-bar");
    layers.forEach(function (L) {
      var label = el("label", "lsv-layer");
      var box = el("input", "lsv-toggle");
      box.type = "checkbox";
      box.checked = L.visible;
      box.setAttribute("data-layer", L.id);
      box.addEventListener("change", function () { L.visible = box.checked; draw(); });
      var swatch = el("span", "lsv-swatch");
      swatch.style.background = rgba(L.color, 1);
      if (L.id === "polygons") swatch.style.background = "linear-gradient(90deg, rgb(30,170,60) 50%, rgb(220,40,40) 50%)";
      if (L.id === "plan") swatch.style.background = "rgba(40,40,48,0.4)";
      if (L.id === "patches") swatch.style.background = "rgba(240,150,20,0.5)";
      if (L.id === "poses") swatch.style.background = "linear-gradient(90deg, #fff, #000)";
      label.appendChild(box);
      label.appendChild(swatch);
      var count = L.points ? " (" + L.points + " points)" : (L.faces.length ? " (" + L.faces.length + ")" : (L.cones.length ? " (" + L.cones.length + ")" : ""));
      label.appendChild(document.createTextNode(L.label + count));
      bar.appendChild(label);
    });
    var modeButton = el("button", "lsv-mode", "");
    var resetButton = el("button", "lsv-reset", "Reset view");
    bar.appendChild(modeButton);
    bar.appendChild(resetButton);
    root.appendChild(bar);
    var stage = el("div", "lsv-stage");
    var canvas = el("canvas", "lsv-canvas");
    stage.appendChild(canvas);
    var scaleBox = el("div", "lsv-scale");
    var scaleBar = el("div", "lsv-scale-bar");
    var scaleLabel = el("span", "lsv-scale-label");
    scaleBox.appendChild(scaleBar);
    scaleBox.appendChild(scaleLabel);
    stage.appendChild(scaleBox);
    root.appendChild(stage);
    var foot = el("div", "lsv-notes");
    (scene.notes || []).forEach(function (n) { foot.appendChild(el("div", "lsv-note", n)); });
    foot.appendChild(el("div", "lsv-help", "Drag: orbit (top-down: pan) \u00b7 right-drag or shift-drag: pan \u00b7 wheel: zoom \u00b7 double-click: reset"));
    root.appendChild(foot);

    var cam = {};
    var topDown = !!scene.top_down;
    var width = 0, height = 0, dpr = 1;

    function reset() {
      cam.t = [(box.lo[0] + box.hi[0]) / 2, (box.lo[1] + box.hi[1]) / 2, (box.lo[2] + box.hi[2]) / 2];
      cam.yaw = -Math.PI / 2 - 0.6;
      cam.pitch = 0.6;
      cam.dist = (diag / 2) / Math.sin(FOV / 2);
      var sx = Math.max(size[0], 1e-3), sy = Math.max(size[1], 1e-3);
      cam.scale = 0.92 * Math.min(width / sx, height / sy);
      modeButton.textContent = topDown ? "3D view" : "Top-down 2D";
    }

    function resize() {
      dpr = global.devicePixelRatio || 1;
      width = Math.max(200, root.clientWidth || 800);
      // A page's only viewer (class lsv-full) takes the window's height; others a fixed one.
      var fixed = parseInt(root.getAttribute("data-height") || "560", 10);
      var full = (global.innerHeight || 0) - root.getBoundingClientRect().top - 120;
      height = Math.max(300, root.classList.contains("lsv-full") ? Math.max(full, 400) : fixed);
      canvas.style.width = width + "px";
      canvas.style.height = height + "px";
      canvas.width = Math.round(width * dpr);
      canvas.height = Math.round(height * dpr);
    }

    // Returns a function writing [screen x, screen y, depth] into out, false when behind.
    function projector() {
      if (topDown) {
        return function (x, y, z, out) {
          out[0] = width / 2 + (x - cam.t[0]) * cam.scale;
          out[1] = height / 2 - (y - cam.t[1]) * cam.scale;
          out[2] = 1e6 - z;
          return true;
        };
      }
      var cp = Math.cos(cam.pitch), sp = Math.sin(cam.pitch);
      var cy = Math.cos(cam.yaw), sy = Math.sin(cam.yaw);
      var eye = [cam.t[0] + cam.dist * cp * cy, cam.t[1] + cam.dist * cp * sy, cam.t[2] + cam.dist * sp];
      var f = [-cp * cy, -cp * sy, -sp];
      var r = [f[1], -f[0], 0]; // f x z
      var rn = Math.hypot(r[0], r[1]) || 1;
      r = [r[0] / rn, r[1] / rn, 0];
      var u = [r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2], r[0] * f[1] - r[1] * f[0]];
      var focal = (height / 2) / Math.tan(FOV / 2);
      var near = cam.dist * 0.01;
      return function (x, y, z, out) {
        var dx = x - eye[0], dy = y - eye[1], dz = z - eye[2];
        var depth = dx * f[0] + dy * f[1] + dz * f[2];
        if (depth < near) return false;
        out[0] = width / 2 + (dx * r[0] + dy * r[1] + dz * r[2]) * focal / depth;
        out[1] = height / 2 - (dx * u[0] + dy * u[1] + dz * u[2]) * focal / depth;
        out[2] = depth;
        return true;
      };
    }

    function gridStep() {
      var span = Math.max(size[0], size[1], 1);
      var step = 1;
      while (span / step > 40) step *= 2;
      return step;
    }

    function drawFaces(ctx, proj, faces) {
      var q = [0, 0, 0];
      var visible = [];
      faces.forEach(function (f) {
        var pts = [];
        var depth = 0;
        for (var i = 0; i + 2 < f.p.length; i += 3) {
          if (!proj(f.p[i], f.p[i + 1], f.p[i + 2], q)) return;
          pts.push(q[0], q[1]);
          depth += q[2];
        }
        visible.push({ pts: pts, depth: depth / (pts.length / 2), f: f });
      });
      // Painter's algorithm: translucent faces from far to near.
      visible.sort(function (a, b) { return b.depth - a.depth; });
      visible.forEach(function (v) {
        ctx.beginPath();
        ctx.moveTo(v.pts[0], v.pts[1]);
        for (var i = 2; i < v.pts.length; i += 2) ctx.lineTo(v.pts[i], v.pts[i + 1]);
        ctx.closePath();
        ctx.fillStyle = v.f.fill;
        ctx.fill();
        if (v.f.edge) {
          ctx.strokeStyle = "rgba(20,20,24,0.45)";
          ctx.lineWidth = 0.6;
          ctx.stroke();
        }
      });
      return visible.length;
    }

    function drawLines(ctx, proj, L) {
      var q = [0, 0, 0];
      ctx.beginPath();
      L.lines.forEach(function (line) {
        if (line.length === 3) {
          // A lone point: a small dot.
          if (proj(line[0], line[1], line[2], q)) {
            ctx.moveTo(q[0] + 1, q[1]);
            ctx.arc(q[0], q[1], 1, 0, 2 * Math.PI);
          }
          return;
        }
        var pen = false;
        for (var i = 0; i + 2 < line.length; i += 3) {
          if (!proj(line[i], line[i + 1], line[i + 2], q)) { pen = false; continue; }
          if (pen) ctx.lineTo(q[0], q[1]); else ctx.moveTo(q[0], q[1]);
          pen = true;
        }
      });
      ctx.strokeStyle = rgba(L.color, 1);
      ctx.lineWidth = L.width;
      ctx.stroke();
    }

    // A length that reads well (1, 2 or 5 times a power of ten) drawn at most maxPx long.
    function niceLength(pxPerMetre, maxPx) {
      var raw = maxPx / pxPerMetre;
      var p = Math.pow(10, Math.floor(Math.log10(raw)));
      var best = p;
      [1, 2, 5].forEach(function (m) { if (m * p <= raw) best = m * p; });
      return best;
    }

    function formatLength(m) {
      if (m >= 1) return m + " m";
      if (m >= 0.01) return Math.round(m * 100) + " cm";
      return Math.round(m * 1000) + " mm";
    }

    // The scale bar: pixels per metre on the screen at the view's centre (exact top down).
    function updateScale() {
      var focal = (height / 2) / Math.tan(FOV / 2);
      var pxPerMetre = topDown ? cam.scale : focal / cam.dist;
      var metres = niceLength(pxPerMetre, 140);
      var px = metres * pxPerMetre;
      scaleBar.style.width = px.toFixed(1) + "px";
      scaleLabel.textContent = formatLength(metres) + (topDown ? "" : " at the centre") +
        " \u00b7 grid " + formatLength(gridStep());
      stats.scale = { metres: metres, pixels: px, pxPerMetre: pxPerMetre, grid: gridStep() };
    }

    var stats = { draws: 0, faces: 0 };
    function draw() {
      pending = false;
      var ctx = canvas.getContext("2d");
      ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
      ctx.fillStyle = BACKGROUND;
      ctx.fillRect(0, 0, width, height);
      ctx.lineJoin = "round";
      var proj = projector();
      var q = [0, 0, 0], q2 = [0, 0, 0];
      // The floor grid at z = 0, for orientation.
      var step = gridStep();
      var x0 = Math.floor(box.lo[0] / step) * step, x1 = Math.ceil(box.hi[0] / step) * step;
      var y0 = Math.floor(box.lo[1] / step) * step, y1 = Math.ceil(box.hi[1] / step) * step;
      ctx.beginPath();
      for (var x = x0; x <= x1 + 1e-9; x += step) {
        if (proj(x, y0, 0, q) && proj(x, y1, 0, q2)) { ctx.moveTo(q[0], q[1]); ctx.lineTo(q2[0], q2[1]); }
      }
      for (var y = y0; y <= y1 + 1e-9; y += step) {
        if (proj(x0, y, 0, q) && proj(x1, y, 0, q2)) { ctx.moveTo(q[0], q[1]); ctx.lineTo(q2[0], q2[1]); }
      }
      ctx.strokeStyle = "rgba(0,0,0,0.07)";
      ctx.lineWidth = 1;
      ctx.stroke();
      var faces = 0;
      var shown = layers.filter(function (L) { return L.visible; });
      // Translucent surfaces first (plan walls behind wall polygons), then the scan lines on
      // top so they stay crisp, then the pose cones.
      shown.forEach(function (L) { if (L.id === "plan") faces += drawFaces(ctx, proj, L.faces); });
      var surfaces = [], cones = [];
      shown.forEach(function (L) {
        if (L.id !== "plan") surfaces = surfaces.concat(L.faces);
        cones = cones.concat(L.coneFaces);
      });
      faces += drawFaces(ctx, proj, surfaces);
      shown.forEach(function (L) { if (L.lines.length) drawLines(ctx, proj, L); });
      faces += drawFaces(ctx, proj, cones);
      stats.draws += 1;
      stats.faces = faces;
      updateScale();
    }

    var pending = false;
    function requestDraw() {
      if (pending) return;
      pending = true;
      global.requestAnimationFrame(draw);
    }

    function pan(dx, dy) {
      if (topDown) {
        cam.t[0] -= dx / cam.scale;
        cam.t[1] += dy / cam.scale;
        return;
      }
      var focal = (height / 2) / Math.tan(FOV / 2);
      var k = cam.dist / focal;
      var cy = Math.cos(cam.yaw), sy = Math.sin(cam.yaw), cp = Math.cos(cam.pitch), sp = Math.sin(cam.pitch);
      var r = [-sy, cy, 0];
      var u = [-sp * cy, -sp * sy, cp];
      // Move the target against the drag, along the screen's right and up directions.
      for (var d = 0; d < 3; d++) cam.t[d] += (-dx * r[d] + dy * u[d]) * k;
    }

    var drag = null;
    canvas.addEventListener("contextmenu", function (e) { e.preventDefault(); });
    canvas.addEventListener("pointerdown", function (e) {
      drag = { x: e.clientX, y: e.clientY, pan: e.button !== 0 || e.shiftKey || topDown };
      if (canvas.setPointerCapture) canvas.setPointerCapture(e.pointerId);
    });
    canvas.addEventListener("pointermove", function (e) {
      if (!drag) return;
      var dx = e.clientX - drag.x, dy = e.clientY - drag.y;
      drag.x = e.clientX;
      drag.y = e.clientY;
      if (drag.pan) pan(dx, dy);
      else {
        cam.yaw -= dx * 0.008;
        cam.pitch = Math.max(-1.5, Math.min(1.5, cam.pitch + dy * 0.008));
      }
      requestDraw();
    });
    function endDrag() { drag = null; }
    canvas.addEventListener("pointerup", endDrag);
    canvas.addEventListener("pointercancel", endDrag);
    canvas.addEventListener("wheel", function (e) {
      e.preventDefault();
      var k = Math.exp(e.deltaY * 0.0015);
      if (topDown) cam.scale /= k; else cam.dist *= k;
      requestDraw();
    }, { passive: false });
    canvas.addEventListener("dblclick", function () { reset(); draw(); });
    resetButton.addEventListener("click", function () { reset(); draw(); });
    modeButton.addEventListener("click", function () { topDown = !topDown; reset(); draw(); });
    global.addEventListener("resize", function () { resize(); draw(); });

    resize();
    reset();
    draw();
    var api = { root: root, stats: stats, draw: draw, layers: layers };
    LevelscanViewer.instances.push(api);
    return api;
  }

  var LevelscanViewer = { mount: mount, instances: [] };
  global.LevelscanViewer = LevelscanViewer;
})(window);
