// beliefnav dashboard: Server-Sent Events -> per-vehicle buffers -> uPlot charts and a canvas map.
// The page starts from window.BOOT (inline in the HTML: the palette, the figures' colours, one per
// meaning; the counter labels; for /?snapshot=1 the server's retained history), so the snapshot view
// is drawn while the page loads and opens no event stream: `chromium --headless --screenshot` of it
// shows the data without waiting.
"use strict";

const MAX_POINTS = 30000;     // per series, per vehicle (the server keeps as many)
const STALE_S = 2.0;          // a vehicle or process silent this long is marked stale
const REDRAW_MS = 100;        // charts are redrawn at most this often
const SNAPSHOT = new URLSearchParams(location.search).has("snapshot");

const vehicles = {};          // name -> {series: {name: [[t, a, b]...]}, counters, status, route, messages, age}
const stats = { frames: 0, snapshots: 0, points: 0, malformed: 0, received: 0, draws: 0, lastFrameMs: 0 };
window.dashboardStats = stats; // read by the browser test
window.dashboardVehicles = vehicles;
let P = null;                 // palette: {quantity: {...}, method: {...}}
let LABELS = null;            // counter labels: {key: [[name, label, red]...], other_rejected}
let selected = null;
let live = false;             // true once the first message was merged: later vehicles are "new"
let dirty = true;
let follow = true;            // x range follows the newest data; a user zoom or pan turns it off
let windowS = 120;            // how much of the past "follow live" shows (0: everything retained)
let hovering = false;         // the cursor is over a chart: its legend shows the values there
let lastDraw = 0;
const charts = {};
const order = [];             // vehicle names in order of appearance
window.dashboardView = () => ({ selected, follow, order, windowS,
  x: Object.fromEntries(Object.entries(charts).map(([id, c]) => [id, [c.scales.x.min, c.scales.x.max]])) });

// ---- data -----------------------------------------------------------------------------------------

function select(name) {
  selected = name;
  document.getElementById("vehicle").value = name;
  follow = true;
  dirty = true;
}

function vehicle(name) {
  if (!vehicles[name]) {
    vehicles[name] = { series: {}, counters: {}, status: {}, latest: {}, route: null, messages: {},
                       age_s: Infinity, process_age_s: {}, at_goal: false, ageAtMs: performance.now() };
    order.push(name);
    const opt = document.createElement("option");
    opt.value = opt.textContent = name;
    document.getElementById("vehicle").appendChild(opt);
    if (selected === null || live) select(name);   // the newest vehicle is shown
  }
  return vehicles[name];
}

function merge(msg) {
  for (const [name, data] of Object.entries(msg.vehicles)) {
    const v = vehicle(name);
    for (const [s, pts] of Object.entries(data.series)) {
      const buf = v.series[s] || (v.series[s] = []);
      for (const p of pts) buf.push(p);
      if (buf.length > MAX_POINTS) buf.splice(0, buf.length - MAX_POINTS);
      stats.points += pts.length;
    }
    if (data.route) v.route = data.route;
    v.counters = data.counters; v.status = data.status; v.messages = data.messages; v.latest = data.latest || {};
    v.age_s = data.age_s; v.process_age_s = data.process_age_s; v.at_goal = data.at_goal;
    v.ageAtMs = performance.now();
  }
  const names = Object.keys(msg.vehicles);  // the server lists vehicles in order of first message
  if (msg.type === "snapshot" && names.length > 1) select(names[names.length - 1]);  // the newest
  live = true;
  stats.malformed = msg.malformed;
  stats.received = msg.received;
  const m = document.getElementById("malformed");
  m.textContent = `malformed payloads: ${msg.malformed}` + (msg.last_malformed ? ` (last: ${msg.last_malformed})` : "");
  m.className = msg.malformed ? "bad" : "";
  dirty = true;
}

function ageNow(v, age) { return age + (SNAPSHOT ? 0 : (performance.now() - v.ageAtMs) / 1000); }

// ---- charts (uPlot) ---------------------------------------------------------------------------------

const fmt = (digits, unit = "") => (u, x) => (x === null || x === undefined ? "–" : x.toFixed(digits) + unit);

function applyX(min, max, except) {
  for (const c of Object.values(charts)) if (c !== except) c.setScale("x", { min, max });
}

function userRange(u, min, max) {
  follow = false;
  u.setScale("x", { min, max });
  applyX(min, max, u);
}

function panZoomPlugin() {
  return { hooks: { ready: [(u) => {
    const over = u.over;
    over.addEventListener("wheel", (e) => {
      e.preventDefault();
      const x = u.posToVal(e.offsetX, "x"), { min, max } = u.scales.x, f = e.deltaY < 0 ? 0.8 : 1.25;
      userRange(u, x - (x - min) * f, x + (max - x) * f);
    }, { passive: false });
    over.addEventListener("mousedown", (e) => {
      if (!e.shiftKey) return;
      e.preventDefault(); e.stopPropagation();
      const x0 = e.clientX, { min, max } = u.scales.x, perPx = (max - min) / over.clientWidth;
      const move = (ev) => userRange(u, min - (ev.clientX - x0) * perPx, max - (ev.clientX - x0) * perPx);
      const up = () => { document.removeEventListener("mousemove", move); document.removeEventListener("mouseup", up); };
      document.addEventListener("mousemove", move); document.addEventListener("mouseup", up);
    }, true);
    over.addEventListener("dblclick", () => { follow = true; dirty = true; });
    over.addEventListener("mouseenter", () => { hovering = true; });
    over.addEventListener("mouseleave", () => { hovering = false; dirty = true; });
  }], draw: [(u) => {  // after each redraw: the legend shows the newest values unless the cursor is over a chart
    const n = u.data[0].length;
    if (!hovering && n) u.setLegend({ idx: n - 1 });
  }], setSelect: [(u) => {  // a drag selection: zoom every chart to it (uPlot's own zoom is off)
    if (u.select.width < 3) return;
    const min = u.posToVal(u.select.left, "x"), max = u.posToVal(u.select.left + u.select.width, "x");
    u.setSelect({ left: 0, top: 0, width: 0, height: 0 }, false);
    userRange(u, min, max);
  }] } };
}

function makeChart(id, series, scales, axes) {
  const el = document.getElementById(id);
  const opts = {
    width: Math.max(el.clientWidth, 200), height: 190,
    scales: { x: { time: false }, ...scales },
    series: [{ label: "t", value: fmt(2, " s") }, ...series],
    axes: [{ label: "time [s]", labelSize: 18, size: 36 }, ...axes],
    cursor: { sync: { key: "t" }, drag: { x: true, y: false, setScale: false } },
    legend: { live: true },
    plugins: [panZoomPlugin()],
  };
  charts[id] = new uPlot(opts, [[], ...series.map(() => [])], el);
}

function buildCharts() {
  const q = P.quantity;
  makeChart("beta",
    [{ label: "β", scale: "beta", stroke: q.beta, width: 1.5, value: fmt(3) },
     { label: "NIS", scale: "nis", stroke: q.nis, width: 1.2, value: fmt(2) }],
    { beta: { range: [0, 1] }, nis: { auto: true, range: (u, lo, hi) => [0, Math.max(hi, 1)] } },
    [{ scale: "beta", label: "β", stroke: q.beta, size: 44 },
     { scale: "nis", label: "NIS", side: 1, stroke: q.nis, grid: { show: false }, size: 48 }]);
  makeChart("err", [{ label: "‖p̂ − p‖", scale: "m", stroke: q.est_error, width: 1.5, value: fmt(2, " m") }],
    { m: { auto: true, range: (u, lo, hi) => [0, Math.max(hi, 0.1)] } },
    [{ scale: "m", label: "error [m]", size: 48 }]);
  makeChart("latency", [{ label: "latency", scale: "s", stroke: q.latency, width: 1.5, value: fmt(3, " s") }],
    { s: { auto: true, range: (u, lo, hi) => [0, Math.max(hi, 0.05)] } },
    [{ scale: "s", label: "latency [s]", size: 48 }]);
  new ResizeObserver(() => {
    for (const [id, c] of Object.entries(charts)) c.setSize({ width: document.getElementById(id).clientWidth, height: 190 });
    dirty = true;
  }).observe(document.querySelector("main"));
}

function columns(pts, cols, scale = 1) {
  const out = [pts.map((p) => p[0])];
  for (const c of cols) out.push(pts.map((p) => (p[c] === null ? null : p[c] * scale)));
  return out;
}

function drawCharts(v) {
  const s = v.series;
  const data = {
    beta: columns(s.beta || [], [1, 2]),
    err: columns(s.err || [], [1]),
    latency: columns(s.latency || [], [1]),
  };
  const why = { beta: "no belief messages from this vehicle", err: "not available: needs the simulation's truth",
                latency: "not available: needs the vehicle's GNSS topic" };
  for (const id of Object.keys(data)) document.getElementById(`${id}-nodata`).textContent = data[id][0].length ? "" : `— ${why[id]}`;
  let tmax = -Infinity, tmin = Infinity;
  for (const d of Object.values(data)) if (d[0].length) { tmax = Math.max(tmax, d[0][d[0].length - 1]); tmin = Math.min(tmin, d[0][0]); }
  for (const [id, c] of Object.entries(charts)) {
    c.setData(data[id], false);
    // setting x (even to its current range) re-fits every y scale to the data in view
    if (follow || c.scales.x.min === null || c.scales.x.min === undefined) {
      if (isFinite(tmax)) {
        const lo = windowS > 0 ? Math.max(tmin, tmax - windowS) : tmin;
        c.setScale("x", { min: lo, max: Math.max(tmax, lo + 1) });
      }
    } else {
      c.setScale("x", { min: c.scales.x.min, max: c.scales.x.max });
    }
  }
}

// ---- map (canvas, north up) -----------------------------------------------------------------------

function niceStep(span) {
  const raw = span / 5, p = Math.pow(10, Math.floor(Math.log10(raw))), m = raw / p;
  return (m < 1.5 ? 1 : m < 3.5 ? 2 : m < 7.5 ? 5 : 10) * p;
}

function drawMap(v) {
  const c = document.getElementById("map"), dpr = window.devicePixelRatio || 1;
  const w = c.clientWidth, h = c.clientHeight;
  if (c.width !== Math.round(w * dpr) || c.height !== Math.round(h * dpr)) { c.width = Math.round(w * dpr); c.height = Math.round(h * dpr); }
  const ctx = c.getContext("2d");
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, w, h);
  ctx.font = "11px system-ui, sans-serif";
  const q = P.quantity;
  let nmin = Infinity, nmax = -Infinity, emin = Infinity, emax = -Infinity;
  const grow = (n, e) => { if (n === null || e === null) return; nmin = Math.min(nmin, n); nmax = Math.max(nmax, n); emin = Math.min(emin, e); emax = Math.max(emax, e); };
  const route = v.route || { buildings_ne_m: [], waypoints_ne_m: [] };
  for (const b of route.buildings_ne_m) { grow(b[0], b[1]); grow(b[2], b[3]); }
  for (const p of route.waypoints_ne_m) grow(p[0], p[1]);
  for (const s of ["truth", "est", "ref"]) for (const p of v.series[s] || []) grow(p[1], p[2]);
  if (!isFinite(nmin)) { ctx.fillStyle = "#999"; ctx.fillText("no position yet", w / 2 - 40, h / 2); return; }
  const pad = { l: 52, r: 10, t: 10, b: 28 };
  const span = Math.max(nmax - nmin, emax - emin, 2) * 1.08;
  const k = Math.min(w - pad.l - pad.r, h - pad.t - pad.b) / span;   // px per metre, equal on both axes
  const cx = pad.l + (w - pad.l - pad.r) / 2, cy = pad.t + (h - pad.t - pad.b) / 2;
  const X = (e) => cx + k * (e - (emin + emax) / 2), Y = (n) => cy - k * (n - (nmin + nmax) / 2);
  // metric grid with labels (a real log has no map: the grid is its reference)
  const step = niceStep(span);
  ctx.strokeStyle = "#e4e6ea"; ctx.fillStyle = "#666"; ctx.lineWidth = 1;
  const eLo = (emin + emax) / 2 - (w / 2) / k, eHi = (emin + emax) / 2 + (w / 2) / k;
  const nLo = (nmin + nmax) / 2 - (h / 2) / k, nHi = (nmin + nmax) / 2 + (h / 2) / k;
  for (let e = Math.ceil(eLo / step) * step; e <= eHi; e += step) {
    const x = X(e); if (x < pad.l || x > w - pad.r) continue;
    ctx.beginPath(); ctx.moveTo(x, pad.t); ctx.lineTo(x, h - pad.b); ctx.stroke();
    ctx.fillText(`${+e.toFixed(6)}`, x - 8, h - pad.b + 12);
  }
  for (let n = Math.ceil(nLo / step) * step; n <= nHi; n += step) {
    const y = Y(n); if (y < pad.t || y > h - pad.b) continue;
    ctx.beginPath(); ctx.moveTo(pad.l, y); ctx.lineTo(w - pad.r, y); ctx.stroke();
    ctx.fillText(`${+n.toFixed(6)}`, pad.l - 26, y + 4);
  }
  ctx.fillText("east [m] →", w - pad.r - 62, h - 3);
  ctx.save(); ctx.translate(pad.l - 32, cy + 30); ctx.rotate(-Math.PI / 2); ctx.fillText("north [m] →", 0, 0); ctx.restore();
  ctx.fillStyle = q.building; ctx.strokeStyle = "#666";
  for (const b of route.buildings_ne_m) {
    ctx.fillRect(X(b[1]), Y(b[2]), k * (b[3] - b[1]), k * (b[2] - b[0]));
    ctx.strokeRect(X(b[1]), Y(b[2]), k * (b[3] - b[1]), k * (b[2] - b[0]));
  }
  const poly = (pts, color, width, dash, ni, ei) => {
    ctx.strokeStyle = color; ctx.lineWidth = width; ctx.setLineDash(dash); ctx.beginPath();
    let pen = false;
    for (const p of pts) {
      if (p[ni] === null || p[ei] === null) { pen = false; continue; }
      if (pen) ctx.lineTo(X(p[ei]), Y(p[ni])); else ctx.moveTo(X(p[ei]), Y(p[ni]));
      pen = true;
    }
    ctx.stroke(); ctx.setLineDash([]);
  };
  // GNSS fixes of the time window (dots), under the tracks
  const tNow = Math.max(...["est", "truth", "fix"].map((k) => { const a = v.series[k] || []; return a.length ? a[a.length - 1][0] : -Infinity; }));
  const since = windowS > 0 ? tNow - windowS : -Infinity;
  ctx.fillStyle = q.gnss;
  for (const p of v.series.fix || []) {
    if (p[0] < since || p[1] === null) continue;
    ctx.beginPath(); ctx.arc(X(p[2]), Y(p[1]), 1.8, 0, 2 * Math.PI); ctx.fill();
  }
  poly(route.waypoints_ne_m, q.reference, 1.5, [6, 4], 0, 1);
  poly(v.series.est || [], q.estimated, 1.3, [], 1, 2);
  poly(v.series.truth || [], q.true, 1.5, [], 1, 2);
  const wp = route.waypoints_ne_m;
  if (wp.length) {
    ctx.fillStyle = "#000"; ctx.fillRect(X(wp[0][1]) - 4, Y(wp[0][0]) - 4, 8, 8);
    ctx.font = "16px system-ui"; ctx.fillText("★", X(wp[wp.length - 1][1]) - 7, Y(wp[wp.length - 1][0]) + 6);
    ctx.font = "11px system-ui, sans-serif";
  }
  // fixes the filter's gate rejected, over the tracks
  ctx.strokeStyle = q.rejected; ctx.lineWidth = 2;
  for (const p of v.series.rejected || []) {
    if (p[1] === null) continue;
    const x = X(p[2]), y = Y(p[1]);
    ctx.beginPath(); ctx.moveTo(x - 5, y - 5); ctx.lineTo(x + 5, y + 5); ctx.moveTo(x - 5, y + 5); ctx.lineTo(x + 5, y - 5); ctx.stroke();
  }
  // 95 % horizontal uncertainty of the newest estimate (axis-aligned: the telemetry has the variances only)
  const L = v.latest || {};
  if (L.var_n_m2 != null && L.var_e_m2 != null && L.est_n_m != null) {
    const k95 = Math.sqrt(5.991);   // chi-square, 2 degrees of freedom, 95 %
    const rx = Math.max(k * k95 * Math.sqrt(L.var_e_m2), 2), ry = Math.max(k * k95 * Math.sqrt(L.var_n_m2), 2);
    ctx.strokeStyle = q.uncertainty; ctx.fillStyle = q.uncertainty + "22"; ctx.lineWidth = 1.5;
    ctx.beginPath(); ctx.ellipse(X(L.est_e_m), Y(L.est_n_m), rx, ry, 0, 0, 2 * Math.PI); ctx.fill(); ctx.stroke();
  }
  for (const [s, color] of [["truth", q.true], ["est", q.estimated]]) {
    const pts = v.series[s] || [];
    if (!pts.length) continue;
    const p = pts[pts.length - 1];
    if (p[1] === null || p[2] === null) continue;
    ctx.fillStyle = color; ctx.beginPath(); ctx.arc(X(p[2]), Y(p[1]), 4, 0, 2 * Math.PI); ctx.fill();
  }
  // north arrow and scale bar
  ctx.fillStyle = "#222"; ctx.strokeStyle = "#222"; ctx.lineWidth = 2;
  const ax = w - pad.r - 16, ay = pad.t + 8;
  ctx.beginPath(); ctx.moveTo(ax, ay + 26); ctx.lineTo(ax, ay); ctx.stroke();
  ctx.beginPath(); ctx.moveTo(ax - 5, ay + 8); ctx.lineTo(ax, ay); ctx.lineTo(ax + 5, ay + 8); ctx.fill();
  ctx.fillText("N", ax - 4, ay + 40);
  const bar = niceStep(span / 1.5);
  ctx.beginPath(); ctx.moveTo(pad.l + 10, h - pad.b - 10); ctx.lineTo(pad.l + 10 + k * bar, h - pad.b - 10); ctx.stroke();
  ctx.fillText(`${+bar.toFixed(6)} m`, pad.l + 12, h - pad.b - 14);
}

function mapLegend() {
  const q = P.quantity;
  document.getElementById("map-legend").innerHTML =
    [["true", q.true], ["estimated", q.estimated], ["planned", q.reference]]
      .map(([n, c]) => `<span class="k" style="--c:${c}">${n}</span>`).join("") +
    `<span class="dot" style="--c:${q.gnss}">GNSS fixes (window)</span>` +
    `<span class="cross" style="--c:${q.rejected}">rejected fix</span>` +
    `<span class="ell" style="--c:${q.uncertainty}">95 % uncertainty</span>` +
    `<span class="k" style="--c:#000">■ start ★ goal</span>`;
}

// ---- status -------------------------------------------------------------------------------------------

function isEnded(v) {
  // the vehicle arrived, or the estimator said it stopped cleanly (its last health says "ended")
  return v.at_goal || Object.values(v.status || {}).includes("ended");
}

function drawFreshness(v) {
  const el = document.getElementById("freshness");
  const age = ageNow(v, v.age_s);
  if (!isFinite(age)) { el.className = "fresh none"; el.textContent = "no data"; return; }
  if (age < STALE_S) { el.className = "fresh live"; el.textContent = "live"; }
  else if (isEnded(v)) {
    el.className = "fresh ended";
    el.textContent = `ended${v.at_goal ? " at goal" : ""} · last data ${age.toFixed(0)} s ago`;
  } else { el.className = "fresh stale"; el.textContent = `stale · no data for ${age.toFixed(0)} s`; }
}

const FIX_TYPES = { 0: "no GPS", 1: "no fix", 2: "2D fix", 3: "3D fix", 4: "DGPS", 5: "RTK float", 6: "RTK fixed" };

function tile(id, text, cls = "") {
  const el = document.getElementById(id);
  el.textContent = text;
  el.className = "v " + cls;
}

function drawFlight(v) {
  // what QGroundControl shows first: mode, armed, GPS fix, satellites, HDOP, altitude; then the belief
  const L = v.latest || {}, has = (x) => x !== null && x !== undefined;
  tile("f-mode", has(L.mode) ? L.mode : "–", L.mode === "HOLD" ? "warn" : "");
  tile("f-armed", has(L.armed) ? (L.armed ? "ARMED" : "disarmed") : "–", L.armed ? "good" : "");
  tile("f-fix", has(L.fix_type) ? (FIX_TYPES[L.fix_type] || `type ${L.fix_type}`) : "–",
       has(L.fix_type) ? (L.fix_type >= 3 ? "good" : "bad") : "");
  tile("f-sats", has(L.satellites) && L.satellites < 255 ? String(L.satellites) : "–");
  tile("f-hdop", has(L.hdop) ? L.hdop.toFixed(1) : "–");
  tile("f-hacc", has(L.h_acc_m) ? `${L.h_acc_m.toFixed(2)} m` : "–");
  tile("f-alt", has(L.altitude_m) ? `${L.altitude_m.toFixed(1)} m` : "–");
  tile("f-beta", has(L.beta) ? L.beta.toFixed(2) : "–", has(L.beta) && L.beta < 0.3 ? "warn" : "");
  tile("f-err", has(L.est_error_m) ? `${L.est_error_m.toFixed(2)} m` : "–");
  tile("f-lat", has(L.gnss_latency_s) ? `${L.gnss_latency_s.toFixed(2)} s` : "–");
}

const esc = (t) => String(t).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" }[c]));

function drawCounters(v) {
  // processes: live, ended (after a clean finish) or stale, and when each was last heard
  const ended = isEnded(v);
  const rows = [];
  const procs = new Set([...Object.keys(v.process_age_s || {}), ...Object.keys(v.counters)]);
  for (const proc of procs) {
    const age = ageNow(v, (v.process_age_s || {})[proc] ?? Infinity);
    const heard = isFinite(age) ? `last heard ${age.toFixed(0)} s ago` : "never heard";
    const state = age < STALE_S ? `<span class="proc-live">live</span>`
      : ended ? `<span class="proc-ended">ended</span>` : `<span class="proc-stale">stale</span>`;
    rows.push(`<tr><td><b>${esc(proc)}</b></td><td>${state}</td><td>${age < STALE_S ? "" : heard}</td></tr>`);
  }
  const total = Object.values(v.messages).reduce((a, b) => a + b, 0);
  rows.push(`<tr><td>messages received</td><td colspan="2">${total.toLocaleString("en")}</td></tr>`);
  document.getElementById("processes").innerHTML = rows.join("");
  // the key counters with their labels; the rest on demand
  const key = [], raw = [];
  for (const [proc, counters] of Object.entries(v.counters)) {
    const known = new Set(LABELS.key.map((k) => k[0]));
    let other = 0;
    for (const [name, label, red] of LABELS.key) {
      if (!(name in counters)) continue;
      const n = counters[name];
      key.push(`<tr><td>${esc(label)}</td><td${red && n > 0 ? ' class="bad"' : ""}>${n.toLocaleString("en")}</td></tr>`);
    }
    for (const [name, n] of Object.entries(counters)) {
      if (!known.has(name) && name.includes("rejected")) other += n;
      raw.push(`<tr><td class="raw">${esc(proc)}/${esc(name)}</td><td${name.includes("reject") && n > 0 ? ' class="bad"' : ""}>${n.toLocaleString("en")}</td></tr>`);
    }
    if (Object.keys(counters).some((k) => known.has(k) || k.includes("rejected")))
      key.push(`<tr><td>${esc(LABELS.other_rejected)}</td><td${other > 0 ? ' class="bad"' : ""}>${other.toLocaleString("en")}</td></tr>`);
  }
  document.getElementById("counters").innerHTML = key.join("") || `<tr><td class="nodata">no estimator counters yet</td></tr>`;
  document.getElementById("raw-counters").innerHTML = raw.join("");
  document.querySelector("#all-counters summary").textContent = `all counters (${raw.length})`;
}

function draw() {
  if (selected === null) return;
  const v = vehicles[selected];
  drawMap(v);
  drawCharts(v);
  drawCounters(v);
  drawFreshness(v);
  drawFlight(v);
  stats.draws++;
  dirty = false;
  lastDraw = performance.now();
}

function loop() {
  requestAnimationFrame(loop);
  if (dirty && performance.now() - lastDraw >= REDRAW_MS) draw();
}

function connect() {
  const es = new EventSource("/events");
  es.onmessage = (ev) => {
    const msg = JSON.parse(ev.data);
    if (msg.type === "snapshot") stats.snapshots++; else stats.frames++;
    stats.lastFrameMs = performance.now();
    merge(msg);
    document.getElementById("status").textContent =
      `${stats.received} messages · ${Object.keys(vehicles).length} vehicle(s) · server up ${msg.uptime_s} s`;
  };
  es.onerror = () => { document.getElementById("status").textContent = "disconnected — retrying…"; };
}

function main() {
  const boot = window.BOOT;
  P = boot.palette;
  LABELS = boot.labels;
  mapLegend();
  buildCharts();
  document.getElementById("vehicle").addEventListener("change", (e) => select(e.target.value));
  document.getElementById("follow").addEventListener("click", () => { follow = true; dirty = true; });
  const win = document.getElementById("window");
  const chosen = new URLSearchParams(location.search).get("window");
  if (chosen !== null && [...win.options].some((o) => o.value === chosen)) win.value = chosen;
  windowS = Number(win.value);
  win.addEventListener("change", () => { windowS = Number(win.value); follow = true; dirty = true; });
  if (SNAPSHOT) {  // drawn now, while the page loads: nothing to wait for
    const msg = boot.snapshot;
    stats.snapshots++;
    merge(msg);
    document.getElementById("status").textContent = `snapshot of ${msg.received} messages · ${Object.keys(vehicles).length} vehicle(s)`;
    draw();
    document.body.dataset.ready = "1";
    return;
  }
  connect();
  setInterval(() => { if (selected !== null) { drawFreshness(vehicles[selected]); drawCounters(vehicles[selected]); } }, 500);
  requestAnimationFrame(loop);
}

main();
