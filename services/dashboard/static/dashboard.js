// The dashboard page: polls /api/state and redraws on canvas. Vanilla JS, no build step, no CDN.
// Text from the network is only ever set with textContent.
"use strict";

const ROLE_COLORS = { source: ["#2ca02c", "#17becf"], tl: ["#1f77b4", "#9467bd"],
                      isolated: ["#ff7f0e", "#d62728"] };
const TRUTH_COLOR = "#111827";
const DETECTION_COLOR = "#6b7280", CLUTTER_COLOR = "#c4c9d1";
const ROLE_LABEL = { source: "source", tl: "primary TL", isolated: "primary isolated" };

let pollMs = 250;
let lastVersion = -1;
let lastSnap = null;
let chosenEpisode = "";

function $(id) { return document.getElementById(id); }

function el(tag, text, cls) {
  const e = document.createElement(tag);
  if (text !== undefined && text !== null) e.textContent = String(text);
  if (cls) e.className = cls;
  return e;
}

function fmt(v, digits = 2) {
  return v === null || v === undefined || !isFinite(v) ? "–" : Number(v).toFixed(digits);
}

function colorsFor(filters) {
  const used = { source: 0, tl: 0, isolated: 0 };
  const out = {};
  for (const f of filters) {
    const palette = ROLE_COLORS[f.role] || ["#555"];
    out[f.name] = palette[used[f.role]++ % palette.length];
  }
  return out;
}

// ---- canvas helpers ---------------------------------------------------------------------------

function setupCanvas(canvas) {
  const dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
    canvas.width = Math.round(w * dpr);
    canvas.height = Math.round(h * dpr);
  }
  const ctx = canvas.getContext("2d");
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, w, h);
  return { ctx, w, h };
}

function niceStep(range, target) {
  const raw = range / Math.max(1, target);
  const mag = Math.pow(10, Math.floor(Math.log10(raw)));
  const norm = raw / mag;
  const nice = norm < 1.5 ? 1 : norm < 3 ? 2 : norm < 7 ? 5 : 10;
  return nice * mag;
}

function ticks(lo, hi, target) {
  if (!(hi > lo)) return [lo];
  const step = niceStep(hi - lo, target);
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) out.push(v);
  return out;
}

function tickLabel(v) {
  const a = Math.abs(v);
  if (a >= 1e4) return (v / 1e3).toFixed(0) + "k";
  if (a >= 100 || v === 0) return v.toFixed(0);
  return String(Number(v.toPrecision(3)));
}

// A plot frame: margins, axes with ticks and labels; returns the data->pixel mapping.
function frame(ctx, w, h, xr, yr, xlabel, ylabel) {
  const m = { l: 62, r: 12, t: 10, b: 40 };
  const pw = w - m.l - m.r, ph = h - m.t - m.b;
  const X = (x) => m.l + ((x - xr[0]) / (xr[1] - xr[0])) * pw;
  const Y = (y) => m.t + ph - ((y - yr[0]) / (yr[1] - yr[0])) * ph;
  ctx.font = "11px system-ui, sans-serif";
  ctx.strokeStyle = "#e5e7eb";
  ctx.fillStyle = "#6b7280";
  ctx.lineWidth = 1;
  ctx.textAlign = "center";
  ctx.textBaseline = "top";
  for (const t of ticks(xr[0], xr[1], Math.max(3, pw / 90))) {
    const x = X(t);
    ctx.beginPath(); ctx.moveTo(x, m.t); ctx.lineTo(x, m.t + ph); ctx.stroke();
    ctx.fillText(tickLabel(t), x, m.t + ph + 4);
  }
  ctx.textAlign = "right";
  ctx.textBaseline = "middle";
  for (const t of ticks(yr[0], yr[1], Math.max(3, ph / 60))) {
    const y = Y(t);
    ctx.beginPath(); ctx.moveTo(m.l, y); ctx.lineTo(m.l + pw, y); ctx.stroke();
    ctx.fillText(tickLabel(t), m.l - 5, y);
  }
  ctx.strokeStyle = "#9ca3af";
  ctx.strokeRect(m.l, m.t, pw, ph);
  ctx.fillStyle = "#374151";
  ctx.font = "12px system-ui, sans-serif";
  ctx.textAlign = "center";
  ctx.textBaseline = "bottom";
  ctx.fillText(xlabel, m.l + pw / 2, h - 2);
  ctx.save();
  ctx.translate(13, m.t + ph / 2);
  ctx.rotate(-Math.PI / 2);
  ctx.textBaseline = "middle";
  ctx.fillText(ylabel, 0, 0);
  ctx.restore();
  return { X, Y, m, pw, ph };
}

function polyline(ctx, pts, X, Y, color, width, dash) {
  if (pts.length === 0) return;
  ctx.save();
  ctx.strokeStyle = color;
  ctx.lineWidth = width;
  ctx.setLineDash(dash || []);
  ctx.lineJoin = "round";
  ctx.beginPath();
  pts.forEach((p, i) => (i ? ctx.lineTo(X(p[0]), Y(p[1])) : ctx.moveTo(X(p[0]), Y(p[1]))));
  ctx.stroke();
  const last = pts[pts.length - 1];
  ctx.setLineDash([]);
  ctx.fillStyle = color;
  ctx.beginPath();
  ctx.arc(X(last[0]), Y(last[1]), width + 2, 0, 2 * Math.PI);
  ctx.fill();
  ctx.restore();
}

// The plot corner of a w x h box that covers the fewest of the pixel points `px`.
function quietCorner(f, w, h, px, taken) {
  const pad = 8;
  const corners = [
    [f.m.l + pad, f.m.t + pad], [f.m.l + f.pw - w - pad, f.m.t + pad],
    [f.m.l + pad, f.m.t + f.ph - h - pad], [f.m.l + f.pw - w - pad, f.m.t + f.ph - h - pad],
  ];
  let best = null, bestN = Infinity;
  corners.forEach(([x, y], i) => {
    if (taken === i) return;
    const n = px.filter(([a, b]) => a >= x && a <= x + w && b >= y && b <= y + h).length;
    if (n < bestN) { best = i; bestN = n; }
  });
  return { i: best, x: corners[best][0], y: corners[best][1] };
}

function legend(ctx, f, items, px) {
  ctx.save();
  ctx.font = "12px system-ui, sans-serif";
  const lw = Math.max(...items.map((it) => ctx.measureText(it.label).width)) + 40;
  const lh = items.length * 18 + 8;
  const c = quietCorner(f, lw, lh, px || []);
  const x0 = c.x, y0 = c.y;
  ctx.fillStyle = "rgba(255,255,255,0.88)";
  ctx.strokeStyle = "#d1d5db";
  ctx.fillRect(x0, y0, lw, lh);
  ctx.strokeRect(x0, y0, lw, lh);
  items.forEach((it, i) => {
    const y = y0 + 13 + i * 18;
    if (it.dot) {
      ctx.fillStyle = it.color;
      ctx.beginPath(); ctx.arc(x0 + 17, y, 3, 0, 2 * Math.PI); ctx.fill();
    } else {
      ctx.strokeStyle = it.color;
      ctx.lineWidth = it.width || 2;
      ctx.setLineDash(it.dash || []);
      ctx.beginPath(); ctx.moveTo(x0 + 6, y); ctx.lineTo(x0 + 28, y); ctx.stroke();
      ctx.setLineDash([]);
    }
    ctx.fillStyle = "#111827";
    ctx.textAlign = "left";
    ctx.textBaseline = "middle";
    ctx.fillText(it.label, x0 + 34, y);
  });
  ctx.restore();
  return c.i;
}

// The primary's latest scan as the simulation drew it, as dots clipped to the box: false alarms
// light grey under the target's detections in dark grey. How many of each the box shows.
function scanDots(ctx, pts, X, Y, box, r) {
  const shown = { detections: 0, clutter: 0 };
  ctx.save();
  ctx.beginPath(); ctx.rect(box.x, box.y, box.w, box.h); ctx.clip();
  for (const fake of [1, 0]) {
    ctx.fillStyle = fake ? CLUTTER_COLOR : DETECTION_COLOR;
    for (const [x, y, c] of pts) {
      if (c !== fake) continue;
      const px = X(x), py = Y(y);
      if (px < box.x || px > box.x + box.w || py < box.y || py > box.y + box.h) continue;
      ctx.beginPath(); ctx.arc(px, py, r, 0, 2 * Math.PI); ctx.fill();
      shown[fake ? "clutter" : "detections"] += 1;
    }
  }
  ctx.restore();
  return shown;
}

// A zoomed view around the latest true position, where the filters' differences show.
function inset(ctx, f, series, colors, px, taken, scan) {
  const truth = series.find((s) => s.name === "truth");
  if (!truth || truth.pts.length === 0) return;
  const w = Math.min(240, f.pw * 0.42), h = Math.min(190, f.ph * 0.45);
  const c = quietCorner(f, w, h, px, taken);
  const [tx, ty] = truth.pts[truth.pts.length - 1];
  let r = 20;
  for (const s of series) {
    if (s.name === "truth" || s.pts.length === 0) continue;
    const [x, y] = s.pts[s.pts.length - 1];
    r = Math.max(r, 1.6 * Math.hypot(x - tx, y - ty));
  }
  const mpp = (2 * r) / Math.min(w, h);
  const X = (x) => c.x + w / 2 + (x - tx) / mpp;
  const Y = (y) => c.y + h / 2 - (y - ty) / mpp;
  ctx.save();
  ctx.fillStyle = "#ffffff";
  ctx.strokeStyle = "#9ca3af";
  ctx.fillRect(c.x, c.y, w, h);
  ctx.strokeRect(c.x, c.y, w, h);
  ctx.beginPath();
  ctx.rect(c.x, c.y, w, h);
  ctx.clip();
  scanDots(ctx, scan, X, Y, { x: c.x, y: c.y, w, h }, 3);
  for (const s of series) {
    const isTruth = s.name === "truth";
    polyline(ctx, s.pts.slice(-12), X, Y, isTruth ? TRUTH_COLOR : colors[s.name],
             isTruth ? 2 : 1.5, isTruth ? [6, 4] : null);
  }
  ctx.fillStyle = "#374151";
  ctx.font = "11px system-ui, sans-serif";
  ctx.textAlign = "left";
  ctx.textBaseline = "top";
  ctx.fillText(`zoom: last 12 steps, ±${tickLabel(r)} m`, c.x + 5, c.y + 4);
  ctx.restore();
}

function emptyNote(ctx, w, h, text) {
  ctx.fillStyle = "#9ca3af";
  ctx.font = "14px system-ui, sans-serif";
  ctx.textAlign = "center";
  ctx.textBaseline = "middle";
  ctx.fillText(text, w / 2, h / 2);
}

// ---- the plots ------------------------------------------------------------------------------

// The trajectories, the sensors and the latest scan; what it drew: steps and the scan's dots.
// The axes follow the tracks, not the clutter, which may fill the whole field of view.
function drawTrajectory(ep, colors) {
  const { ctx, w, h } = setupCanvas($("trajectory"));
  const none = { steps: 0, k: 0, scan: { detections: 0, clutter: 0 } };
  const series = ep ? [{ name: "truth", pts: ep.truth.map((p) => [p[1], p[2]]) },
    ...ep.filters.map((f) => ({ name: f.name, role: f.role, pts: f.points.map((p) => [p[1], p[2]]) }))] : [];
  const all = series.flatMap((s) => s.pts).concat(ep ? ep.sensors.map((s) => [s.x, s.y]) : []);
  if (!ep || series.every((s) => s.pts.length === 0)) {
    emptyNote(ctx, w, h, "waiting for the first step…");
    return none;
  }
  let [x0, x1] = [Math.min(...all.map((p) => p[0])), Math.max(...all.map((p) => p[0]))];
  let [y0, y1] = [Math.min(...all.map((p) => p[1])), Math.max(...all.map((p) => p[1]))];
  // equal scale on both axes (metres are metres), with a margin
  const plotW = w - 74, plotH = h - 50;
  let sx = Math.max(x1 - x0, 1), sy = Math.max(y1 - y0, 1);
  const mpp = Math.max(sx / plotW, sy / plotH) * 1.08;
  const cx = (x0 + x1) / 2, cy = (y0 + y1) / 2;
  [x0, x1] = [cx - (mpp * plotW) / 2, cx + (mpp * plotW) / 2];
  [y0, y1] = [cy - (mpp * plotH) / 2, cy + (mpp * plotH) / 2];
  const f = frame(ctx, w, h, [x0, x1], [y0, y1], "x [m]", "y [m]");
  const sites = new Map();  // sensors sharing a position get one marker and one label
  for (const s of ep.sensors) {
    const at = `${s.x},${s.y}`;
    const label = `${s.name} (${s.kind})`;  // who, and what it measures
    sites.set(at, { x: s.x, y: s.y, names: [...(sites.get(at)?.names || []), label] });
  }
  ctx.font = "11px system-ui, sans-serif";
  ctx.textAlign = "left";
  ctx.textBaseline = "middle";
  for (const site of sites.values()) {
    const px = f.X(site.x), py = f.Y(site.y);
    ctx.fillStyle = "#6b7280";
    ctx.beginPath(); ctx.moveTo(px, py - 7); ctx.lineTo(px - 6, py + 5); ctx.lineTo(px + 6, py + 5);
    ctx.fill();
    ctx.fillText(`sensor ${site.names.join(", ")}`, px + 9, py);
  }
  const scan = ep.scan ? ep.scan.points : [];
  const shown = scanDots(ctx, scan, f.X, f.Y, { x: f.m.l, y: f.m.t, w: f.pw, h: f.ph }, 2.5);
  const items = [];
  let drawn = 0;
  for (const s of series) {
    const isTruth = s.name === "truth";
    const color = isTruth ? TRUTH_COLOR : colors[s.name];
    polyline(ctx, s.pts, f.X, f.Y, color, isTruth ? 2.5 : 1.6, isTruth ? [6, 4] : null);
    drawn = Math.max(drawn, s.pts.length);
    items.push({ label: isTruth ? "truth" : `${s.name} (${ROLE_LABEL[s.role] || s.role})`,
                 color, width: isTruth ? 2.5 : 1.6, dash: isTruth ? [6, 4] : null });
  }
  if (scan.some((p) => !p[2])) items.push({ label: `detections, step ${ep.scan.k}`, color: DETECTION_COLOR, dot: true });
  if (scan.some((p) => p[2])) items.push({ label: "false alarms", color: CLUTTER_COLOR, dot: true });
  const px = all.map(([x, y]) => [f.X(x), f.Y(y)]);
  const taken = legend(ctx, f, items, px);
  inset(ctx, f, series, colors, px, taken, scan);
  return { steps: drawn, k: ep.scan ? ep.scan.k : 0, scan: shown };
}

function drawRmse(ep, colors) {
  const { ctx, w, h } = setupCanvas($("rmse"));
  const fs = ep ? ep.filters.filter((f) => f.error.length > 0) : [];
  if (fs.length === 0) {
    emptyNote(ctx, w, h, ep ? "waiting for the truth and estimates of a step…" : "no episode yet");
    return;
  }
  const K = Math.max(ep.K || 0, ...fs.map((f) => f.error[f.error.length - 1][0]));
  const ymax = Math.max(1, ...fs.flatMap((f) => f.error.map((p) => p[1]))) * 1.1;
  const f = frame(ctx, w, h, [0, K], [0, ymax], "step k", "RMSE(k) [m]");
  for (const s of fs) polyline(ctx, s.error, f.X, f.Y, colors[s.name], 1.6);
  const px = fs.flatMap((s) => s.error.map(([k, e]) => [f.X(k), f.Y(e)]));
  legend(ctx, f, fs.map((s) => ({ label: `${s.name}: RMSE ${fmt(s.rmse)} m`, color: colors[s.name] })), px);
}

function drawTransfer(ep) {
  const { ctx, w, h } = setupCanvas($("transfer"));
  const tr = ep ? ep.transfer : [];
  const K = Math.max(ep && ep.K ? ep.K : 0, tr.length ? tr[tr.length - 1][0] : 0);
  if (!K) return;
  const l = 62, r = 12, cw = (w - l - r) / K;
  ctx.fillStyle = "#f3f4f6";
  ctx.fillRect(l, 4, w - l - r, h - 20);
  for (const [k, used] of tr) {
    ctx.fillStyle = used ? "#16a34a" : "#dc2626";
    ctx.fillRect(l + (k - 1) * cw, 4, Math.max(1, cw - (cw > 4 ? 1 : 0)), h - 20);
  }
  ctx.fillStyle = "#374151";
  ctx.font = "11px system-ui, sans-serif";
  ctx.textBaseline = "top";
  ctx.textAlign = "right";
  ctx.fillText("step k", l - 6, 8);
  ctx.textAlign = "center";
  for (const t of ticks(1, K, Math.max(3, (w - l - r) / 90))) {
    ctx.fillText(tickLabel(t), l + (t - 0.5) * cw, h - 14);
  }
}

// ---- tables and header ------------------------------------------------------------------------

function fillFilters(ep, colors) {
  const body = $("rmse-table").tBodies[0];
  body.replaceChildren();
  if (!ep || ep.filters.length === 0) {
    const tr = body.insertRow();
    const td = el("td", "no estimates yet", "empty");
    td.colSpan = 12;
    tr.append(td);
    fillStages(undefined);
    fillConsistency([]);
    return;
  }
  for (const f of ep.filters) {
    const tr = body.insertRow();
    tr.dataset.filter = f.name;
    const name = el("td");
    const sw = el("span", null, "swatch");
    sw.style.background = colors[f.name];
    name.append(sw, document.createTextNode(f.name));
    const tl = f.role === "tl";
    tr.append(name, el("td", ROLE_LABEL[f.role] || f.role), el("td", f.steps),
      el("td", fmt(f.rmse), "rmse"), el("td", fmt(f.rmse_k), "rmse-k"),
      el("td", fmt(f.latency_ms.p50, 1)), el("td", fmt(f.latency_ms.p95, 1)),
      el("td", fmt(f.latency_ms.p99, 1)), el("td", fmt(f.step_ms.p50, 1)),
      el("td", tl ? f.transfer_used : "–"), el("td", tl ? f.transfer_skipped : "–"),
      el("td", fmt(f.nis_window), f.consistency ? "nis warn" : "nis"));
  }
  fillStages(ep.filters.find((f) => f.role === "tl"));
  fillConsistency(ep.filters);
}

// What the NIS of a filter's own measurements says when its model does not fit the target
// (tltrack.filters.consistency): no truth needed, so a deployment sees it too.
function fillConsistency(filters) {
  const list = $("consistency");
  list.replaceChildren(...filters.filter((f) => f.consistency).map(
    (f) => el("li", `${f.name}: ${f.consistency}`, "warning")));
}

const STAGE_LABEL = {
  to_tracker: "sensor → tracker", wait: "wait", step: "step", publish: "publish",
  to_receiver: "tracker → here",
};

// Where the TL estimate's latency goes, stage by stage (p50 of each, tltrack.latency).
function fillStages(f) {
  const parts = f && f.stages_ms
    ? Object.entries(f.stages_ms).filter(([, v]) => v !== null)
      .map(([s, v]) => `${STAGE_LABEL[s] || s} ${fmt(v, 2)}`)
    : [];
  $("stages").textContent = parts.length
    ? `TL estimate, p50 by stage [ms]: ${parts.join(" · ")}`
    : "";
}

function age(s) {
  if (s === null || s === undefined) return "no statistics";
  return s < 2 ? "stats just now" : `stats ${s.toFixed(0)} s ago`;
}

function fillHealth(services) {
  const ul = $("health");
  ul.replaceChildren();
  if (services.length === 0) ul.append(el("li", "no service seen yet", "empty"));
  for (const s of services) {
    const li = el("li");
    li.dataset.alive = String(s.alive);
    li.dataset.service = s.name;
    const steps = s.counters.steps !== undefined ? ` · ${s.counters.steps} steps` : "";
    li.append(el("span", null, "dot"), el("span", s.name, "name"));
    for (const [sid, state] of Object.entries(s.links || {})) {  // the primary's direct links
      const link = el("span", `link ${sid}: ${state}`, "link");
      link.dataset.state = state;
      li.append(link);
    }
    li.append(el("span", `${s.alive ? "alive" : "gone"} · ${age(s.stats_age_s)}${steps}`, "meta"));
    ul.append(li);
  }
}

function fillRejected(snap) {
  const body = $("rejected-table").tBodies[0];
  body.replaceChildren();
  let rows = 0;
  for (const s of snap.services) {
    for (const [reason, n] of Object.entries(s.rejected_by_reason)) {
      const tr = body.insertRow();
      tr.append(el("td", s.name), el("td", reason), el("td", n));
      rows++;
    }
  }
  if (!rows) {
    const tr = body.insertRow();
    const td = el("td", "none", "empty");
    td.colSpan = 3;
    tr.append(td);
  }
  $("rejected-total").textContent = String(snap.rejected.total);
}

function fillHeader(snap) {
  const ep = snap.episode;
  const sel = $("episode-select");
  const want = ["", ...snap.episodes.map((e) => e.id)];
  const have = Array.from(sel.options).map((o) => o.value);
  if (want.join("\n") !== have.join("\n")) {
    sel.replaceChildren(...want.map((id) => {
      const o = el("option", id || "latest");
      o.value = id;
      return o;
    }));
    sel.value = chosenEpisode;
  }
  const status = $("episode-status");
  if (!ep) {
    status.textContent = "waiting for an episode";
    status.className = "pill";
  } else {
    const run = ep.run === null ? "" : ` (run ${ep.run})`;
    status.textContent = `${ep.id}${run}: ${ep.ended ? ep.ended : "running"}`;
    status.className = "pill " + (ep.ended === "complete" ? "ok" : ep.ended ? "bad" : "run");
  }
  $("step-k").textContent = ep ? String(ep.last_k) : "0";
  $("step-K").textContent = ep && ep.K ? String(ep.K) : "?";
  const tl = ep ? ep.filters.find((f) => f.role === "tl") : null;
  $("transfer-text").textContent = tl
    ? `${tl.name}: used at ${tl.transfer_used} steps (green), skipped at ${tl.transfer_skipped} (red)`
    : "used / skipped per step of the TL filter";
}

// What the plot shows of the latest scan, in words (and in data-* for the browser test).
function fillScan(drawn) {
  const out = $("scan-drawn");
  const { detections, clutter } = drawn.scan;
  out.textContent = drawn.k ? `step ${drawn.k}: target ${detections}, false alarms ${clutter}` : "–";
  out.dataset.k = String(drawn.k);
  out.dataset.detections = String(detections);
  out.dataset.clutter = String(clutter);
}

function render(snap) {
  const ep = snap.episode;
  const colors = colorsFor(ep ? ep.filters : []);
  fillHeader(snap);
  const drawn = drawTrajectory(ep, colors);
  fillScan(drawn);
  drawRmse(ep, colors);
  drawTransfer(ep);
  fillFilters(ep, colors);
  fillHealth(snap.services);
  fillRejected(snap);
  const counter = $("steps-drawn");
  counter.textContent = String(drawn.steps);
  counter.dataset.steps = String(drawn.steps);
  document.body.dataset.version = String(snap.version);
}

// ---- polling --------------------------------------------------------------------------------

async function poll() {
  const conn = $("conn");
  try {
    const q = chosenEpisode ? `?episode=${encodeURIComponent(chosenEpisode)}` : "";
    const r = await fetch(`/api/state${q}`, { cache: "no-store" });
    if (!r.ok) throw new Error(`HTTP ${r.status}`);
    const snap = await r.json();
    pollMs = snap.poll_ms || pollMs;
    conn.textContent = "connected";
    conn.className = "pill ok";
    if (snap.version !== lastVersion) {
      lastVersion = snap.version;
      lastSnap = snap;
      render(snap);
    } else {
      fillHealth(snap.services);  // ages move on even when nothing else does
    }
  } catch (err) {
    conn.textContent = "disconnected";
    conn.className = "pill bad";
  }
  setTimeout(poll, pollMs);
}

window.addEventListener("DOMContentLoaded", () => {
  $("episode-select").addEventListener("change", (ev) => {
    chosenEpisode = ev.target.value;
    lastVersion = -1;
  });
  window.addEventListener("resize", () => lastSnap && render(lastSnap));
  poll();
});
