// twinfleet view: draws a live fleet (websocket /ws) or steps through a checker trace
// (/api/trace) on one canvas, which pans (drag) and zooms (wheel); lists every topic of the
// fleet with an inspector of its latest message, whatever the nodes are. No build step, no
// dependencies. Everything the page knows is in window.twinfleetView (tests and the console
// read it; view.probe() samples pixels).
//
// The page knows no message type: the server sends what the fleet's scene draws
// (twinfleet/runtime/contract/scene.py), by kind. The map is a grid; each body (robot) has
// a body (place x, y in cells, heading theta, half_m), a table row (the scene's columns), a
// scan, a path, a start and a goal, all optional, and a trail of its places; collisions are
// points with a label. Places are in cells: the centre of cell (row r, column c) is
// (c + 0.5, r + 0.5).
"use strict";
(() => {
  const PALETTE = [[220, 40, 40], [40, 90, 220], [30, 160, 60], [240, 140, 20], [150, 60, 190],
    [0, 170, 170], [200, 0, 120], [120, 120, 0]];  // the colours of the fleet's bodies, in order
  const FIELDS = ["body", "row", "scan", "path", "goal", "start"];  // a body's drawn fields
  const $ = (id) => document.getElementById(id);
  const canvas = $("world");
  const g = canvas.getContext("2d", { willReadFrequently: true });
  const emptyLog = () => ({ start: 0, items: [] });
  const view = window.twinfleetView = {
    mode: null, fleet: null, link: { session: false, router: false }, wsOpen: false,
    map: null, mapDrawn: false, cellPx: 12, robots: {}, order: [],
    collisions: emptyLog(), violations: emptyLog(), fleetStatus: null, ended: null,
    stats: null, selected: null, frames: 0, firstFrameMs: null, drawnRobots: [],
    positions: {}, messages: 0, trace: null, step: 0, playing: false,
    zoom: 1, pan: [0, 0], topics: {}, inspected: null, columns: [],
  };
  let mapCanvas = null, drawPending = false, traceStates = [], traceFrames = [], traceTrails = [],
    timer = null;

  const colourOf = (name) => PALETTE[Math.max(0, view.order.indexOf(name)) % PALETTE.length];
  const rgb = (c, a = 1) => `rgba(${c[0]},${c[1]},${c[2]},${a})`;
  const light = (c) => c.map((v) => Math.round(v + (255 - v) * 0.55));
  const centre = (p) => [p[0] * view.cellPx, p[1] * view.cellPx];
  const samePlace = (a, b) => a[0] === b[0] && a[1] === b[1];
  const escape = (t) => String(t).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" })[c]);

  function setMap(map) {
    view.map = map;
    view.mapDrawn = false;
    mapCanvas = null;
    if (!map) return;
    const raw = atob(map.cells), w = map.width, h = map.height;
    view.cellPx = Math.max(3, Math.min(48, Math.floor(700 / Math.max(w, h))));
    canvas.width = w * view.cellPx;
    canvas.height = h * view.cellPx;
    mapCanvas = document.createElement("canvas");
    mapCanvas.width = w; mapCanvas.height = h;
    const mg = mapCanvas.getContext("2d"), img = mg.createImageData(w, h);
    for (let i = 0; i < w * h; i++) {
      const v = raw.charCodeAt(i);  // 100 occupied, 0 free, 255 (-1 as int8) unknown
      const shade = v === 255 ? 200 : v >= 50 ? 60 : 255;
      img.data.set([shade, shade, shade, 255], i * 4);
    }
    mg.putImageData(img, 0, 0);
    view.map.occupied = (r, c) => { const v = raw.charCodeAt(r * w + c); return v >= 50 && v !== 255; };
  }

  function robotRect(body) {  // the footprint square, turned to the heading
    const u = [Math.cos(body.theta), Math.sin(body.theta)], v = [-u[1], u[0]];
    const res = view.map ? view.map.resolution || 1 : 1;
    const half = (body.half_m / res) * view.cellPx, [cx, cy] = centre([body.x, body.y]);
    const corners = [[1, 1], [1, -1], [-1, -1], [-1, 1]].map(([a, b]) =>
      [cx + a * half * u[0] + b * half * v[0], cy + a * half * u[1] + b * half * v[1]]);
    return { cx, cy, u, half, corners };
  }

  function poly(points, close) {
    g.beginPath();
    points.forEach(([x, y], i) => (i ? g.lineTo(x, y) : g.moveTo(x, y)));
    if (close) g.closePath();
  }

  function cross(point, colour, r) {
    const [x, y] = centre(point);
    g.strokeStyle = rgb(colour); g.lineWidth = 2;
    poly([[x - r, y - r], [x + r, y + r]]); g.stroke();
    poly([[x - r, y + r], [x + r, y - r]]); g.stroke();
  }

  function placeOf(r) { return r.body ? [r.body.x, r.body.y] : null; }

  function noMapText() {
    if (view.mode === "trace") {
      return view.trace ? "this trace has no map: its steps and node states are on the right"
        : "loading trace…";
    }
    const n = Object.keys(view.topics).length;
    return n ? `no map on fleet ${view.fleet}: its ${n} topic${n > 1 ? "s are" : " is"} listed on the right`
      : "waiting for the fleet's messages…";
  }

  function draw() {
    drawPending = false;
    g.setTransform(1, 0, 0, 1, 0, 0);
    g.fillStyle = "#fff"; g.fillRect(0, 0, canvas.width, canvas.height);
    if (!mapCanvas) {
      g.fillStyle = "#555"; g.font = "16px sans-serif";
      g.fillText(noMapText(), 20, 30);
      return finishFrame([]);
    }
    g.setTransform(view.zoom, 0, 0, view.zoom, view.pan[0], view.pan[1]);
    g.imageSmoothingEnabled = false;
    g.drawImage(mapCanvas, 0, 0, canvas.width, canvas.height);
    view.mapDrawn = true;
    const px = view.cellPx, names = view.order.filter((n) => view.robots[n]);
    for (const name of names) {
      const r = view.robots[name], c = colourOf(name), here = placeOf(r);
      g.lineWidth = 2; g.strokeStyle = rgb(light(c));
      if (r.trail && r.trail.items.length > 1) { poly(r.trail.items.map(centre)); g.stroke(); }
      if (r.path && r.path.length && here) {
        // A live plan still holds the waypoints already passed: draw from the robot on.
        const at = r.path.findIndex((p) => samePlace(p, here));
        const ahead = r.path.slice(at + 1);
        g.setLineDash([4, 3]); g.strokeStyle = rgb(c, 0.8);
        if (ahead.length) { poly([here, ...ahead].map(centre)); g.stroke(); }
        g.setLineDash([]);
      }
      if (r.start) {
        const [sx, sy] = centre(r.start);
        g.strokeStyle = rgb(c); g.beginPath(); g.arc(sx, sy, px * 0.45, 0, 2 * Math.PI); g.stroke();
      }
      if (r.goal) cross(r.goal, c, px * 0.45);
    }
    const sel = view.selected && view.robots[view.selected];
    if (sel && sel.scan && placeOf(sel)) {
      const [x0, y0] = centre(placeOf(sel));
      g.strokeStyle = rgb(colourOf(view.selected), 0.6); g.lineWidth = 1;
      for (const hit of sel.scan) { poly([[x0, y0], centre(hit)]); g.stroke(); }
    }
    const drawn = [];
    for (const name of names) {
      const r = view.robots[name], here = placeOf(r);
      if (!here) continue;
      const rect = robotRect(r.body);
      g.fillStyle = rgb(colourOf(name)); g.strokeStyle = "#000"; g.lineWidth = 1;
      poly(rect.corners, true); g.fill(); g.stroke();
      g.lineWidth = 2;
      poly([[rect.cx, rect.cy], [rect.cx + rect.u[0] * rect.half * 1.2, rect.cy + rect.u[1] * rect.half * 1.2]]);
      g.stroke();
      g.fillStyle = "#000"; g.font = "10px sans-serif";
      g.fillText(name, rect.cx + rect.half + 2, rect.cy - rect.half - 1);
      drawn.push(name);
      view.positions[name] = here;
    }
    g.strokeStyle = "rgb(255,0,0)"; g.lineWidth = 3;
    for (const hit of collisionMarks()) {
      for (const p of hit.points) { const [x, y] = centre(p); g.beginPath(); g.arc(x, y, px * 1.1, 0, 2 * Math.PI); g.stroke(); }
      poly(hit.points.map(centre)); g.stroke();
    }
    finishFrame(drawn);
  }

  function collisionMarks() {  // the collisions drawn now: a live fleet's last 20, a trace step's
    if (view.mode !== "trace") return view.collisions.items.slice(-20);
    return (traceFrames[view.step] || { collisions: [] }).collisions;
  }

  function finishFrame(drawn) {
    view.frames += 1;
    view.drawnRobots = drawn;
    if (view.firstFrameMs === null && view.mapDrawn && drawn.length) view.firstFrameMs = performance.now();
    canvas.dataset.map = view.map ? `${view.map.width}x${view.map.height}` : "";
    canvas.dataset.robots = String(drawn.length);
    canvas.dataset.frame = String(view.frames);
    renderPanel();
  }

  function scheduleDraw() {
    if (!drawPending) { drawPending = true; setTimeout(draw, 0); }
  }

  view.draw = draw;
  view.probe = () => {  // canvas pixels where the map and each robot are drawn (for tests)
    const px = (x, y) => Array.from(g.getImageData(Math.round(x * view.zoom + view.pan[0]),
      Math.round(y * view.zoom + view.pan[1]), 1, 1).data.slice(0, 3));
    const out = { map: null, robots: {} };
    if (view.map) {
      const { width: w, height: h } = view.map;
      for (let i = 0; i < w * h && !out.map; i++) {
        const r = Math.floor(i / w), c = i % w;
        if (view.map.occupied(r, c)) out.map = { cell: [r, c], pixel: px(...centre([c + 0.5, r + 0.5])), expected: [60, 60, 60] };
      }
    }
    for (const name of view.drawnRobots) {
      const r = view.robots[name], rect = robotRect(r.body);
      const x = rect.cx - rect.u[0] * rect.half * 0.5, y = rect.cy - rect.u[1] * rect.half * 0.5;
      out.robots[name] = { place: placeOf(r), pixel: px(x, y), expected: colourOf(name) };
    }
    return out;
  };

  function shortJson(value) {  // long strings (a map's base64 bytes) shortened for reading
    return JSON.stringify(value, (k, v) => (typeof v === "string" && v.length > 300
      ? `${v.slice(0, 300)}… (${v.length} chars)` : v), 1);
  }

  function renderTopics() {
    const names = Object.keys(view.topics).sort();
    $("topics").innerHTML = names.map((t) => {
      const e = view.topics[t];
      return `<tr class="topic${t === view.inspected ? " selected" : ""}" data-topic="${escape(t)}">` +
        `<td>${escape(t)}</td><td>${escape(e.type)}</td><td>${e.count}</td></tr>`;
    }).join("");
    const e = view.inspected && view.topics[view.inspected];
    $("inspector-title").textContent = e ? `message inspector: ${view.inspected} (${e.type}, #${e.count})` : "message inspector";
    $("inspector").textContent = e ? shortJson(e.last) : "no topic selected";
    $("inspector").className = e ? "" : "muted";
  }

  function renderPanel() {
    const head = ["", "robot", ...view.columns].map((t) => `<th>${escape(t)}</th>`).join("");
    if ($("robot-columns").innerHTML !== head) $("robot-columns").innerHTML = head;
    const rows = view.order.filter((n) => view.robots[n]).map((name) => {
      const r = view.robots[name], row = r.row || {}, c = colourOf(name);
      return `<tr class="robot${name === view.selected ? " selected" : ""}" data-robot="${escape(name)}">` +
        `<td><span class="swatch" style="background:${rgb(c)}"></span></td><td>${escape(name)}</td>` +
        view.columns.map((k) => `<td>${escape(row[k] ?? "–")}</td>`).join("") + "</tr>";
    });
    $("robots").innerHTML = rows.join("");
    const marks = (view.mode === "trace" ? collisionMarks() : view.collisions.items).map((c) => c.label);
    $("collision-count").textContent = String(view.mode === "trace" ? marks.length : view.collisions.start + marks.length);
    $("collisions").textContent = marks.join("\n");
    if (view.mode === "live") {
      $("events").textContent = view.violations.items.map((v) => `violation ${v.node}.${v.handler}: ${v.reason}`).join("\n");
      const l = view.link;
      $("link").textContent = l.router ? "connected" : l.session ? "no router" : "connecting…";
      $("link").className = l.router ? "ok" : "bad";
      const st = view.stats;
      $("stats").textContent = st ? `${st.messages} messages on ${Object.keys(st.topics).length} topics` : "";
      $("ended").textContent = view.ended ? `fleet ended: ${view.ended}` : "";
      renderTopics();
    }
    $("zoom-label").textContent = view.zoom === 1 ? "" : `(×${view.zoom.toFixed(2)})`;
  }

  $("topics").addEventListener("click", (ev) => {
    const row = ev.target.closest("tr.topic");
    if (!row) return;
    view.inspected = view.inspected === row.dataset.topic ? null : row.dataset.topic;
    renderTopics();
  });

  // ---- pan and zoom: the canvas transform is (zoom, pan); probe() and clicks follow it ----
  function canvasPoint(ev) {
    const r = canvas.getBoundingClientRect();
    return [(ev.clientX - r.left) * (canvas.width / r.width), (ev.clientY - r.top) * (canvas.height / r.height)];
  }
  function zoomAt(point, factor) {
    const z = Math.max(0.5, Math.min(16, view.zoom * factor)), k = z / view.zoom;
    view.pan = [point[0] - (point[0] - view.pan[0]) * k, point[1] - (point[1] - view.pan[1]) * k];
    view.zoom = z;
    scheduleDraw();
  }
  view.zoomAt = zoomAt;
  view.resetView = () => { view.zoom = 1; view.pan = [0, 0]; scheduleDraw(); };
  canvas.addEventListener("wheel", (ev) => { ev.preventDefault(); zoomAt(canvasPoint(ev), Math.pow(1.1, -ev.deltaY / 100)); }, { passive: false });
  let drag = null;
  canvas.addEventListener("mousedown", (ev) => { drag = canvasPoint(ev); canvas.classList.add("dragging"); });
  window.addEventListener("mouseup", () => { drag = null; canvas.classList.remove("dragging"); });
  window.addEventListener("mousemove", (ev) => {
    if (!drag) return;
    const p = canvasPoint(ev);
    view.pan = [view.pan[0] + p[0] - drag[0], view.pan[1] + p[1] - drag[1]];
    drag = p;
    scheduleDraw();
  });
  canvas.addEventListener("dblclick", () => view.resetView());
  const middle = () => [canvas.width / 2, canvas.height / 2];
  $("zoom-in").addEventListener("click", () => zoomAt(middle(), 1.25));
  $("zoom-out").addEventListener("click", () => zoomAt(middle(), 0.8));
  $("zoom-reset").addEventListener("click", () => view.resetView());

  $("robots").addEventListener("click", (ev) => {
    const row = ev.target.closest("tr.robot");
    if (!row) return;
    view.selected = view.selected === row.dataset.robot ? null : row.dataset.robot;
    scheduleDraw();
  });

  // ---- live mode ----
  function applyLog(log, chunk) {
    const idx = chunk.start - log.start;
    if (idx < 0 || idx > log.items.length) { log.start = chunk.start; log.items = chunk.items.slice(); return; }
    log.items.length = idx;
    for (const item of chunk.items) log.items.push(item);
  }

  function applyLive(msg) {
    const fresh = msg.kind === "snapshot";
    if (fresh) { view.robots = {}; view.collisions = emptyLog(); view.violations = emptyLog(); view.topics = {}; }
    if (msg.columns) view.columns = msg.columns;
    for (const [t, e] of Object.entries(msg.topics || {})) view.topics[t] = e;
    if ("fleet" in msg) {
      view.fleet = msg.fleet;
      $("mode").textContent = `live: fleet ${view.fleet} via ${view.connect}`;
    }
    if ("map" in msg) setMap(msg.map);
    if (msg.order) view.order = msg.order;
    for (const [name, e] of Object.entries(msg.robots || {})) {
      if (e.reset) delete view.robots[name];  // a new run: nothing of the last one stays
      const r = view.robots[name] || (view.robots[name] = { trail: emptyLog() });
      for (const k of FIELDS) if (k in e) r[k] = e[k];
      if (e.trail) applyLog(r.trail, e.trail);
      if (!view.order.includes(name)) view.order = [...view.order, name];
    }
    if (msg.collisions) applyLog(view.collisions, msg.collisions);
    if (msg.violations) applyLog(view.violations, msg.violations);
    for (const k of ["ended", "link", "stats"]) if (k in msg) view[k] = msg[k];
    view.messages += 1;
    scheduleDraw();
  }

  function connect() {
    const ws = new WebSocket(`ws://${location.host}/ws`);
    ws.onopen = () => { view.wsOpen = true; };
    ws.onmessage = (ev) => applyLive(JSON.parse(ev.data));
    ws.onclose = () => { view.wsOpen = false; view.link = { session: false, router: false }; scheduleDraw(); setTimeout(connect, 1000); };
  }

  // ---- trace mode: doc.frames[k] is what the scene draws after step k, as its changes ----
  function loadTrace(doc) {
    view.trace = doc;
    view.columns = doc.columns;
    setMap(doc.map);
    traceStates = [doc.initial];
    for (const step of doc.steps) {
      traceStates.push({ ...traceStates[traceStates.length - 1], ...(step.changed || {}) });
    }
    traceFrames = [];
    let frame = { order: [], robots: {}, collisions: [] };
    for (const change of doc.frames) {
      frame = { order: change.order || frame.order, robots: { ...frame.robots, ...change.robots },
        collisions: change.collisions || frame.collisions };
      traceFrames.push(frame);
    }
    const trail = {};  // each body's places, each new one once
    traceTrails = traceFrames.map((f) => {
      for (const [n, r] of Object.entries(f.robots)) {
        const t = trail[n] || (trail[n] = []), here = placeOf(r);
        if (here && (!t.length || !samePlace(t[t.length - 1], here))) t.push(here);
      }
      return Object.fromEntries(Object.entries(trail).map(([n, t]) => [n, t.length]));
    });
    view.traceTrail = trail;
    // A trace whose scene draws no body and no collision (a system without robots) shows
    // its node states, not two panels that stay empty.
    const drawn = traceFrames.some((f) => Object.keys(f.robots).length || f.collisions.length);
    $("robots-panel").hidden = !drawn;
    $("collisions-panel").hidden = !drawn;
    $("trace-title").textContent = `${doc.scenario}: ${doc.message || "trace"}`;
    $("step-range").max = String(doc.steps.length);
    $("mode").textContent = `trace ${doc.file} (${doc.steps.length} steps)`;
    showStep(doc.steps.length);
  }

  function showStep(k) {
    const doc = view.trace;
    view.step = Math.max(0, Math.min(doc.steps.length, k));
    const frame = traceFrames[view.step];
    view.order = frame.order;
    view.robots = {};
    for (const [name, r] of Object.entries(frame.robots)) {
      const seen = traceTrails[view.step][name] || 0;
      view.robots[name] = { ...r, trail: { start: 0, items: view.traceTrail[name].slice(0, seen) } };
    }
    $("step-range").value = String(view.step);
    $("step-label").textContent = `step ${view.step}/${doc.steps.length}`;
    $("step-info").textContent = stepText(view.step);
    $("states").textContent = statesText(view.step);
    draw();  // at once: the canvas, the panel and the step text always show the same step
  }

  function stepText(k) {
    if (k === 0) return "initial states";
    const s = view.trace.steps[k - 1], before = traceStates[k - 1], lines = [];
    lines.push(`t=${s.time} ms  #${s.index}  ${s.node}.${s.handler}(${s.args ?? ""})  [${s.kind}]`);
    for (const [node, st] of Object.entries(s.changed || {})) {
      const old = before[node] || {};
      for (const [f, v] of Object.entries(st)) {
        if (JSON.stringify(old[f]) !== JSON.stringify(v)) lines.push(`  ${node}.${f}: ${JSON.stringify(old[f])} → ${JSON.stringify(v)}`);
      }
    }
    for (const log of s.logs || []) lines.push(`  log ${JSON.stringify(log)}`);
    for (const fault of s.faults || []) lines.push(`  FAULT ${fault}`);
    if (s.failure) lines.push(`  FAILURE ${JSON.stringify(s.failure)}`);
    if (k === view.trace.steps.length && view.trace.message) lines.push(`→ ${view.trace.message}`);
    return lines.join("\n");
  }

  function statesText(k) {
    const changed = k > 0 ? view.trace.steps[k - 1].changed || {} : {};
    return Object.entries(traceStates[k] || {}).map(([node, st]) =>
      `${node in changed ? "*" : " "} ${node}: ${JSON.stringify(st)}`).join("\n");
  }

  function play(on) {
    view.playing = on;
    $("play").textContent = on ? "pause" : "play";
    clearInterval(timer);
    if (!on) return;
    if (view.step >= view.trace.steps.length) showStep(0);
    timer = setInterval(() => (view.step >= view.trace.steps.length ? play(false) : showStep(view.step + 1)), 150);
  }

  const controls = { first: () => showStep(0), prev: () => showStep(view.step - 1), next: () => showStep(view.step + 1),
    last: () => showStep(Infinity), play: () => play(!view.playing) };
  for (const [id, fn] of Object.entries(controls)) $(id).addEventListener("click", () => { if (view.trace) fn(); });
  $("step-range").addEventListener("input", (ev) => showStep(Number(ev.target.value)));
  document.addEventListener("keydown", (ev) => {
    if (!view.trace) return;
    const fn = { ArrowLeft: controls.prev, ArrowRight: controls.next, Home: controls.first, End: controls.last, " ": controls.play }[ev.key];
    if (fn) { ev.preventDefault(); fn(); }
  });
  view.showStep = (k) => showStep(k);

  async function start() {
    const info = await (await fetch("/api/info")).json();
    view.mode = info.mode;
    document.body.classList.add(info.mode);
    if (info.mode === "trace") {
      $("link").textContent = ""; loadTrace(await (await fetch("/api/trace")).json());
    } else {
      view.connect = info.connect;
      $("mode").textContent = `live: fleet ${info.fleet} via ${info.connect}`;
      connect();
    }
    draw();
  }
  start();
})();
