// beliefnav dashboard: Server-Sent Events -> per-vehicle buffers -> canvas plots (no libraries).
"use strict";

const WINDOW_S = 60;          // time plots show the last minute
const MAX_POINTS = 6000;      // per series, per vehicle
const COLORS = { truth: "#1f6fd0", est: "#e67e00", ref: "#444", beta: "#2a9d3a", nis: "#c23b3b",
                 err: "#e67e00", latency: "#7b3fb5" };

const vehicles = {};          // name -> {series: {name: [[t, a, b]...]}, counters, route, messages}
const stats = { frames: 0, snapshots: 0, points: 0, malformed: 0, received: 0, draws: 0, lastFrameMs: 0 };
window.dashboardStats = stats; // read by the browser test
window.dashboardVehicles = vehicles;
let selected = null;
let dirty = true;

function vehicle(name) {
  if (!vehicles[name]) {
    vehicles[name] = { series: {}, counters: {}, status: {}, route: null, messages: {} };
    const opt = document.createElement("option");
    opt.value = opt.textContent = name;
    document.getElementById("vehicle").appendChild(opt);
    if (selected === null) selected = name;
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
    v.counters = data.counters; v.status = data.status; v.messages = data.messages;
  }
  stats.malformed = msg.malformed;
  stats.received = msg.received;
  const m = document.getElementById("malformed");
  m.textContent = `malformed payloads: ${msg.malformed}` + (msg.last_malformed ? ` (last: ${msg.last_malformed})` : "");
  m.className = msg.malformed ? "bad" : "";
  dirty = true;
}

// ---- drawing ------------------------------------------------------------------------------------

function axes(ctx, w, h, x0, x1, y0, y1, pad) {
  ctx.strokeStyle = "#ccc"; ctx.fillStyle = "#666"; ctx.lineWidth = 1; ctx.font = "10px sans-serif";
  ctx.strokeRect(pad.l, pad.t, w - pad.l - pad.r, h - pad.t - pad.b);
  for (let i = 0; i <= 4; i++) {
    const y = y0 + (y1 - y0) * i / 4, py = pad.t + (h - pad.t - pad.b) * (1 - i / 4);
    ctx.fillText(fmt(y), 2, py + 3);
    ctx.beginPath(); ctx.moveTo(pad.l, py); ctx.lineTo(w - pad.r, py); ctx.stroke();
  }
  ctx.fillText(`${fmt(x0)} s`, pad.l, h - 2);
  ctx.fillText(`${fmt(x1)} s`, w - pad.r - 40, h - 2);
}

function fmt(x) { return Math.abs(x) >= 100 ? x.toFixed(0) : x.toFixed(2); }

function timePlot(id, lines, fixedRange) {
  const c = document.getElementById(id), ctx = c.getContext("2d"), w = c.width, h = c.height;
  const pad = { l: 40, r: 8, t: 6, b: 14 };
  ctx.clearRect(0, 0, w, h);
  let tmax = -Infinity, tfirst = Infinity;
  for (const l of lines) if (l.pts.length) { tmax = Math.max(tmax, l.pts[l.pts.length - 1][0]); tfirst = Math.min(tfirst, l.pts[0][0]); }
  if (!isFinite(tmax)) { ctx.fillStyle = "#999"; ctx.fillText("no data yet", w / 2 - 30, h / 2); return; }
  const tmin = Math.max(tfirst, tmax - WINDOW_S), span = Math.max(tmax - tmin, 1e-3);
  for (const l of lines) {
    let lo = l.range ? l.range[0] : Infinity, hi = l.range ? l.range[1] : -Infinity;
    if (!l.range) for (const p of l.pts) { const y = p[l.col] === null ? null : p[l.col] * l.scale; if (p[0] >= tmin && y !== null) { lo = Math.min(lo, y); hi = Math.max(hi, y); } }
    if (!isFinite(lo)) { lo = 0; hi = 1; }
    if (hi - lo < 1e-9) { hi = lo + 1; }
    l.lo = lo; l.hi = hi;
  }
  axes(ctx, w, h, tmin, tmax, lines[0].lo, lines[0].hi, pad);
  for (const l of lines) {
    ctx.strokeStyle = l.color; ctx.lineWidth = 1.5; ctx.beginPath();
    let pen = false;
    for (const p of l.pts) {
      if (p[0] < tmin || p[l.col] === null) { pen = false; continue; }
      const x = pad.l + (p[0] - tmin) / span * (w - pad.l - pad.r);
      const y = pad.t + (1 - (p[l.col] * l.scale - l.lo) / (l.hi - l.lo)) * (h - pad.t - pad.b);
      if (pen) ctx.lineTo(x, y); else ctx.moveTo(x, y);
      pen = true;
    }
    ctx.stroke();
  }
}

function drawMap(v) {
  const c = document.getElementById("map"), ctx = c.getContext("2d"), w = c.width, h = c.height;
  ctx.clearRect(0, 0, w, h);
  // bounds (north, east) over everything drawn
  let nmin = Infinity, nmax = -Infinity, emin = Infinity, emax = -Infinity;
  const grow = (n, e) => { if (n === null || e === null) return; nmin = Math.min(nmin, n); nmax = Math.max(nmax, n); emin = Math.min(emin, e); emax = Math.max(emax, e); };
  const route = v.route || { buildings_ne_m: [], waypoints_ne_m: [] };
  for (const b of route.buildings_ne_m) { grow(b[0], b[1]); grow(b[2], b[3]); }
  for (const p of route.waypoints_ne_m) grow(p[0], p[1]);
  for (const s of ["truth", "est"]) for (const p of v.series[s] || []) grow(p[1], p[2]);
  if (!isFinite(nmin)) { ctx.fillStyle = "#999"; ctx.fillText("no data yet", w / 2 - 30, h / 2); return; }
  const m = 10, span = Math.max(nmax - nmin, emax - emin, 1);
  const k = Math.min(w, h) / (span + 2 * m);
  const ox = w / 2 - k * (emin + emax) / 2, oy = h / 2 + k * (nmin + nmax) / 2;
  const X = (e) => ox + k * e, Y = (n) => oy - k * n;
  ctx.fillStyle = "#9aa3ad";
  for (const b of route.buildings_ne_m) ctx.fillRect(X(b[1]), Y(b[2]), k * (b[3] - b[1]), k * (b[2] - b[0]));
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
  poly(route.waypoints_ne_m, COLORS.ref, 1.5, [6, 4], 0, 1);
  poly(v.series.est || [], COLORS.est, 1.2, [], 1, 2);
  poly(v.series.truth || [], COLORS.truth, 1.5, [], 1, 2);
  for (const s of ["truth", "est"]) {
    const pts = v.series[s] || [];
    if (!pts.length) continue;
    const p = pts[pts.length - 1];
    ctx.fillStyle = COLORS[s]; ctx.beginPath(); ctx.arc(X(p[2]), Y(p[1]), 4, 0, 2 * Math.PI); ctx.fill();
  }
  // scale bar
  const bar = Math.pow(10, Math.floor(Math.log10(span / 3)));
  ctx.strokeStyle = "#333"; ctx.lineWidth = 2; ctx.beginPath(); ctx.moveTo(10, h - 10); ctx.lineTo(10 + k * bar, h - 10); ctx.stroke();
  ctx.fillStyle = "#333"; ctx.fillText(`${bar} m`, 12, h - 14);
}

function drawCounters(v) {
  const rows = [];
  for (const [proc, counters] of Object.entries(v.counters)) {
    rows.push(`<tr><td colspan="2"><b>${proc}</b> ${v.status[proc] || ""}</td></tr>`);
    for (const [k, n] of Object.entries(counters)) {
      const bad = k.includes("reject") && n > 0 ? " class=\"bad\"" : "";
      rows.push(`<tr><td>${k}</td><td${bad}>${n}</td></tr>`);
    }
  }
  const total = Object.values(v.messages).reduce((a, b) => a + b, 0);
  rows.push(`<tr><td><b>messages received</b></td><td>${total}</td></tr>`);
  document.getElementById("counters").innerHTML = rows.join("");
}

function draw() {
  requestAnimationFrame(draw);
  if (!dirty || selected === null) return;
  dirty = false;
  const v = vehicles[selected], s = v.series;
  drawMap(v);
  timePlot("beta", [{ pts: s.beta || [], col: 1, color: COLORS.beta, range: [0, 1], scale: 1 },
                    { pts: s.beta || [], col: 2, color: COLORS.nis, scale: 1 }]);
  timePlot("err", [{ pts: s.err || [], col: 1, color: COLORS.err, scale: 1 }]);
  timePlot("latency", [{ pts: s.latency || [], col: 1, color: COLORS.latency, scale: 1000 }]);
  drawCounters(v);
  stats.draws++;
}

function connect() {
  const es = new EventSource("/events");
  es.onmessage = (ev) => {
    const msg = JSON.parse(ev.data);
    if (msg.type === "snapshot") stats.snapshots++; else stats.frames++;
    stats.lastFrameMs = performance.now();
    merge(msg);
    document.getElementById("status").textContent =
      `${stats.received} messages · ${Object.keys(vehicles).length} vehicle(s) · up ${msg.uptime_s} s`;
  };
  es.onerror = () => { document.getElementById("status").textContent = "disconnected — retrying…"; };
}

document.getElementById("vehicle").addEventListener("change", (e) => { selected = e.target.value; dirty = true; });
connect();
requestAnimationFrame(draw);
