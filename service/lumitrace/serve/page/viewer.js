// lumitrace live view: one more client of the service's HTTP API (no framework, no build).
// Everything shown comes from the service: /preview and /geometry (binary frames),
// /scene, /status, /results, /settings and the event stream; edits are POST /deltas.
// Every request the page makes goes through request() below.
"use strict";

// the service's key for this page (in the page itself, which no other origin can read):
// every request carries it, so that the service tells the page from a forged request
const KEY = document.querySelector('meta[name="lumitrace-key"]').content;

const LT = (window.lumitrace = {
  token: sessionStorage.getItem("lumitrace-token") || null,
  status: null, scene: null, geometry: null, preview: null, results: null, settings: null,
  polar: null, history: [], events: [], lastEventId: 0, drawn: { preview: 0, view3d: 0 },
  timings: [], problems: [], errors: [], frames: 0, undo: [], selected: null,
  requests: [], paused: false, reference: null, solidPositions: null, framed: null,
  picked: null,  // the part the user picked (highlighted); none until one is
});
window.addEventListener("error", (e) => LT.errors.push(String(e.message)));

// ---- HTTP -------------------------------------------------------------------------------

// The one function that sends a request: the page's key, the token (where the service has
// one) and a JSON body's content type are added here, and nowhere else.
async function request(path, { method = "GET", json, headers } = {}) {
  const h = Object.assign({ "X-Lumitrace-Key": KEY }, headers || {});
  if (LT.token) h.Authorization = "Bearer " + LT.token;
  const opts = { method, headers: h };
  if (json !== undefined) {
    h["Content-Type"] = "application/json";
    opts.body = JSON.stringify(json);
  }
  LT.requests.push({ method, path });
  if (LT.requests.length > 500) LT.requests.splice(0, 250);
  const r = await fetch(path, opts);
  if (r.status === 401) { askToken("the token was not accepted"); throw new Error("401"); }
  return r;
}

async function getJSON(path) {
  const r = await request(path);
  const body = await r.json();
  if (!r.ok) throw Object.assign(new Error(body.error || r.statusText), { body, status: r.status });
  return body;
}

async function postJSON(path, data) {
  const r = await request(path, { method: "POST", json: data });
  const body = await r.json();
  return { ok: r.ok, status: r.status, body };
}

// A binary frame: "LTV1", uint32 header length, JSON header, float32 arrays.
function readFrame(buffer) {
  const view = new DataView(buffer);
  const magic = String.fromCharCode(...new Uint8Array(buffer, 0, 4));
  if (magic !== "LTV1") throw new Error("not a lumitrace view frame");
  const n = view.getUint32(4, true);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 8, n)));
  const arrays = {};
  for (const [name, spec] of Object.entries(header.arrays)) {
    const count = spec.shape.reduce((a, b) => a * b, 1);
    arrays[name] = { data: new Float32Array(buffer, 8 + n + spec.offset, count), shape: spec.shape };
  }
  return { header, arrays, bytes: buffer.byteLength };
}

// A frame, or null where there is none yet (204: nothing traced) or it failed.
async function getFrame(path, options) {
  const r = await request(path, options);
  if (r.status === 204) return null;
  if (!r.ok) {
    let why = r.statusText;
    try { why = (await r.json()).error || why; } catch (e) { /* not JSON */ }
    throw Object.assign(new Error(why), { status: r.status });
  }
  return readFrame(await r.arrayBuffer());
}

// ---- the token ----------------------------------------------------------------------------

function askToken(why) {
  document.getElementById("token-box").hidden = false;
  document.getElementById("token-problem").textContent = why || "";
  setConnection(false);
}

document.getElementById("token-form").addEventListener("submit", (e) => {
  e.preventDefault();
  LT.token = document.getElementById("token-input").value;
  sessionStorage.setItem("lumitrace-token", LT.token);  // this tab only, never in a URL
  document.getElementById("token-box").hidden = true;
  start();
});

// ---- the event stream (fetch, so the token travels in a header) ---------------------------

function setConnection(on) {
  const b = document.getElementById("connection");
  b.textContent = on ? "live" : "offline";
  b.classList.toggle("off", !on);
}

async function follow() {
  for (;;) {
    try {
      const r = await request("/events", { headers: LT.lastEventId ? { "Last-Event-ID": String(LT.lastEventId) } : {} });
      if (!r.ok || !r.body) throw new Error("event stream " + r.status);
      setConnection(true);
      const reader = r.body.getReader();
      const text = new TextDecoder();
      let buf = "";
      for (;;) {
        const { value, done } = await reader.read();
        if (done) break;
        buf += text.decode(value, { stream: true });
        let cut;
        while ((cut = buf.indexOf("\n\n")) >= 0) {
          handleBlock(buf.slice(0, cut));
          buf = buf.slice(cut + 2);
        }
      }
    } catch (err) {
      if (String(err.message) === "401") return;
    }
    setConnection(false);
    await new Promise((res) => setTimeout(res, 1000));  // reconnect, resuming at the last id
  }
}

// One server-sent-events block: an event, or only comments (the keep-alive), which is none.
function handleBlock(block) {
  let kind = null, id = null, data = null;
  for (const line of block.split("\n")) {
    if (!line || line.startsWith(":")) continue;
    const at = line.indexOf(":");
    const field = at < 0 ? line : line.slice(0, at);
    const value = at < 0 ? "" : line.slice(at + 1).replace(/^ /, "");
    if (field === "event") kind = value;
    else if (field === "id") id = parseInt(value, 10);
    else if (field === "data") data = data == null ? value : data + "\n" + value;
  }
  if (id) LT.lastEventId = id;
  if (data == null) return;  // no data, no event (the SSE rule)
  let payload = {};
  try { payload = data ? JSON.parse(data) : {}; } catch (e) { payload = { raw: data }; }
  onEvent(kind || "message", payload);
}

function onEvent(kind, e) {
  LT.events.push({ kind, ...e });
  if (LT.events.length > 2000) LT.events.splice(0, 1000);
  if (kind === "iteration" || kind === "retrace" || kind === "written") {
    for (const t of LT.timings) {
      if (t.evented == null && e.revision >= t.revision) t.evented = performance.now() - t.sent;
    }
  }
  logEvent(kind, e);
  if (kind === "settings") {
    LT.settings = { threshold: e.threshold, target_error: e.target_error, photons: e.photons,
                    paused: e.paused };
    showPaused(!!e.paused);
  }
  if (kind === "iteration" || kind === "written" || kind === "done" || kind === "retrace" ||
      kind === "settings") refresh();
  if (kind === "revision" || kind === "restart" || kind === "retrace") {
    if (LT.scene) refreshScene();  // the first scene waits for the first frame
    refresh();
  }
  if (kind === "revision" || kind === "done") refreshRevisions();
  if (kind === "fit" && typeof refreshFit !== "undefined") refreshFit();
  if (kind === "iteration") remember(e.revision, e.photons, e.seconds, e.relative_error, null);
  refreshStatus();
}

function logEvent(kind, e) {
  if (kind === "iteration" && LT.events.length > 3 && e.iteration > 3 && e.iteration % 4) return;
  const li = document.createElement("li");
  li.className = kind;
  const bits = [];
  if (e.revision != null) bits.push("rev " + e.revision);
  if (kind === "revision") bits.push(`from ${e.source || "?"}: ${e.effect ? e.effect.kind : ""}`);
  if (kind === "retrace") bits.push(`retraced ${fmtInt(e.photons)} of ${fmtInt(e.of)} photons (${pct(e.photons / Math.max(e.of, 1))})`);
  if (kind === "restart") bits.push(e.reason || "");
  if (kind === "iteration") bits.push(`${fmtInt(e.photons)} photons, map error ${pct(e.relative_error)}`);
  if (kind === "written") bits.push(`${fmtInt(e.photons)} photons${e.pictures ? ", pictures" : ""}`);
  if (kind === "done") bits.push(judgedText(e));
  if (kind === "settings") bits.push(e.paused ? "paused" : "running");
  if (kind === "fit") bits.push(`fit ${e.fit} ${e.state}${e.evaluations ? `, ${e.evaluations} evaluations, merit ${fmt(e.merit)}` : ""}`);
  if (e.message) bits.push(e.message);
  li.textContent = `${new Date().toLocaleTimeString()} ${kind}: ${bits.join(" · ")}`;
  const log = document.getElementById("log");
  log.prepend(li);
  while (log.children.length > 300) log.lastChild.remove();
}

// ---- refreshing -----------------------------------------------------------------------------

let inFlight = false, again = false;
async function refresh() {
  if (inFlight) { again = true; return; }
  inFlight = true;
  try {
    const asked = performance.now();
    const frame = await getFrame("/preview");
    if (frame) {
      for (const t of LT.timings) {
        if (t.fetched == null && frame.header.revision >= t.revision) {
          t.asked = asked - t.sent;
          t.fetched = performance.now() - t.sent;
        }
      }
      LT.preview = frame;
      drawPreview();
    }
  } catch (e) { /* shown by the connection badge */ }
  inFlight = false;
  if (again) { again = false; refresh(); }
}

let statusFlight = null, statusAgain = false;
async function refreshStatus() {
  if (statusFlight) { statusAgain = true; return statusFlight; }
  statusFlight = (async () => {
    try {
      LT.status = await getJSON("/status");
      showStatus();
      if (LT.status.written_revision != null &&
          (!LT.results || LT.results.revision !== LT.status.written_revision ||
           LT.results.photons !== LT.status.written_photons)) {
        try { LT.results = await getJSON("/results"); } catch (e) { /* none yet */ }
      }
    } catch (e) { /* offline */ }
  })();
  await statusFlight;
  statusFlight = null;
  if (statusAgain) { statusAgain = false; return refreshStatus(); }
}

// The header: what the service says (its judged error and verdict), the map's error beside.
function showStatus() {
  const s = LT.status;
  const stage = document.getElementById("stage");
  stage.textContent = (s.stage || "").split(/[\\/]/).pop();
  stage.title = s.stage || "";
  text("revision", s.revision);
  text("state", s.state);
  text("rate", fmtInt(s.photons_per_second));
  if (!LT.preview) text("photons", fmtInt(s.photons));
  text("judged", judgedText(s, false));  // the badge beside it says the verdict
  const c = document.getElementById("converged");
  c.textContent = s.converged ? "converged" : "not converged";
  c.classList.toggle("yes", !!s.converged);
  if (LT.preview && LT.preview.header.revision === s.traced_revision &&
      LT.preview.header.photons === s.photons) {
    text("error", pct(s.relative_error));
    text("bound", pct(s.relative_error_bound));
  }
}

// "files 1.8% (target 2%)": what the target is judged on, the judged error, the target.
function judgedText(s, verdict = true) {
  if (!s || s.judged_error == null) return s && s.target_of ? `${s.target_of} - (target ${pctShort(s.target_error)})` : "-";
  const target = s.target_error != null ? s.target_error : (LT.status || {}).target_error;
  return `${s.target_of} ${pctShort(s.judged_error)}` + (target != null ? ` (target ${pctShort(target)})` : "") +
    (verdict && s.converged != null ? `, ${s.converged ? "converged" : "not converged"}` : "");
}

function showPaused(paused) {
  LT.paused = paused;
  document.getElementById("pause").textContent = paused ? "Resume" : "Pause";
  document.getElementById("paused").hidden = !paused;
}

async function refreshScene() {
  if (!LT.scene && !(LT.status && LT.status.traced_revision != null) && !LT.preview) return;
  try {
    // the scene, the parts and the editor change together (a test, or a user, reading
    // LT.scene sees the editor that shows it)
    const scene = await getJSON("/scene");
    const geo = await getFrame("/geometry");
    LT.scene = scene;
    if (geo) { LT.geometry = geo; buildParts(); }
    fillEditor();
  } catch (e) { /* not yet */ }
}

function drawPreview() {
  const p = LT.preview, h = p.header;
  text("photons", fmtInt(h.photons));
  text("error", pct(h.relative_error));
  text("bound", pct(h.relative_error_bound));
  remember(h.revision, h.photons, h.seconds, h.relative_error, h.relative_error_bound);
  if (LT.reference && LT.reference.kind === "revision" && LT.reference.revision === h.revision) {
    LT.reference.frame = p;  // a pinned revision still refining: its newest frame
  }
  drawMap();
  drawPolar();
  drawConvergence();
  drawFigures();
  drawComparison();
  buildSolid();
  LT.drawn.preview = performance.now();
  LT.drawnRevision = h.revision;
  if (!LT.scene || LT.scene.revision !== h.revision) refreshScene();  // the scene it shows
  for (const t of LT.timings) {
    if (t.drawn == null && h.revision >= t.revision) t.drawn = performance.now() - t.sent;
  }
}

// The convergence history: one point per (revision, photons), in photon order.
function remember(revision, photons, seconds, error, bound) {
  const old = LT.history.find((q) => q.revision === revision && q.photons === photons);
  if (old) { if (bound != null) old.bound = bound; return; }
  LT.history.push({ revision, photons, seconds, error, bound });
  LT.history.sort((a, b) => a.revision - b.revision || a.photons - b.photons);
}

// ---- colour -----------------------------------------------------------------------------

// Turbo, Google's perceptual rainbow, as a polynomial fit (t in [0, 1] -> r, g, b in 0..1)
function turbo(t) {
  t = Math.min(1, Math.max(0, t));
  const r = 0.13572138 + t * (4.61539260 + t * (-42.66032258 + t * (132.13108234 + t * (-152.94239396 + t * 59.28637943))));
  const g = 0.09140261 + t * (2.19418839 + t * (4.84296658 + t * (-14.18503333 + t * (4.27729857 + t * 2.82956604))));
  const b = 0.10667330 + t * (12.64194608 + t * (-60.58204836 + t * (110.36276771 + t * (-89.90310912 + t * 27.34824973))));
  return [Math.min(1, Math.max(0, r)), Math.min(1, Math.max(0, g)), Math.min(1, Math.max(0, b))];
}

// Diverging blue - white - red for differences (t in [-1, 1]).
function diverging(t) {
  t = Math.min(1, Math.max(-1, t));
  const blue = [0.23, 0.30, 0.75], red = [0.71, 0.02, 0.15], white = [0.97, 0.97, 0.97];
  const end = t < 0 ? blue : red, a = Math.abs(t);
  return white.map((w, i) => w + (end[i] - w) * a);
}

function scaler(max, log) {
  if (!(max > 0)) return () => 0;
  if (!log) return (v) => v / max;
  const lo = max * 1e-3;
  return (v) => (v <= lo ? 0 : Math.log(v / lo) / Math.log(max / lo));
}

function legend(el, max, log, unit) {
  const stops = [];
  for (let i = 0; i <= 10; i++) {
    const [r, g, b] = turbo(i / 10);
    stops.push(`rgb(${r * 255 | 0},${g * 255 | 0},${b * 255 | 0})`);
  }
  el.innerHTML = `<div class="bar" style="background:linear-gradient(to right,${stops.join(",")})"></div>` +
    `<div class="ends"><span>${log ? fmt(max * 1e-3) : "0"}</span><span>${fmt(max)} ${unit}</span></div>`;
}

function divergingLegend(el, max, unit) {
  const stops = [];
  for (let i = -5; i <= 5; i++) {
    const [r, g, b] = diverging(i / 5);
    stops.push(`rgb(${r * 255 | 0},${g * 255 | 0},${b * 255 | 0})`);
  }
  el.innerHTML = `<div class="bar" style="background:linear-gradient(to right,${stops.join(",")})"></div>` +
    `<div class="ends"><span>-${fmt(max)}</span><span>0</span><span>+${fmt(max)} ${unit}</span></div>` +
    `<div class="caption">now - reference</div>`;
}

// ---- the intensity map (lat-long in the photometric frame) ---------------------------------

function drawMap() {
  const p = LT.preview;
  if (!p) return;
  let kind = document.querySelector("input[name=map-kind]:checked").value;
  const ref = referenceFrame();
  const diffBox = document.querySelector("input[name=map-kind][value=difference]");
  diffBox.disabled = !ref;
  if (kind === "difference" && !ref) {
    document.querySelector("input[name=map-kind][value=filtered]").checked = true;
    kind = "filtered";
  }
  const log = document.getElementById("map-log").checked;
  const a = p.arrays[kind === "difference" ? "filtered" : kind], [rows, cols] = a.shape;
  const canvas = document.getElementById("map"), ctx = canvas.getContext("2d");
  const img = ctx.createImageData(cols, rows);
  let max = 0;
  if (kind === "difference") {
    const b = ref.frame.arrays.filtered.data, k = ref.scale;
    const d = new Float32Array(rows * cols);
    for (let i = 0; i < d.length; i++) { d[i] = a.data[i] - k * b[i]; max = Math.max(max, Math.abs(d[i])); }
    for (let i = 0; i < d.length; i++) {
      const [r, g, bb] = diverging(max > 0 ? d[i] / max : 0);
      img.data[4 * i] = r * 255; img.data[4 * i + 1] = g * 255; img.data[4 * i + 2] = bb * 255;
      img.data[4 * i + 3] = 255;
    }
    divergingLegend(document.getElementById("map-legend"), max, "cd");
  } else {
    for (const v of a.data) if (v > max) max = v;
    const s = scaler(max, log);
    for (let i = 0; i < rows * cols; i++) {
      const [r, g, b] = turbo(s(a.data[i]));
      img.data[4 * i] = r * 255; img.data[4 * i + 1] = g * 255; img.data[4 * i + 2] = b * 255;
      img.data[4 * i + 3] = 255;
    }
    legend(document.getElementById("map-legend"), max, log, "cd");
  }
  const tmp = document.createElement("canvas");
  tmp.width = cols; tmp.height = rows;
  tmp.getContext("2d").putImageData(img, 0, 0);
  ctx.imageSmoothingEnabled = false;
  ctx.drawImage(tmp, 0, 0, canvas.width, canvas.height);
  LT.map = { kind, max, rows, cols };
}

// ---- the polar curve -------------------------------------------------------------------------

function planeIndex(cs, c) {
  let best = 0;
  for (let i = 0; i < cs.length; i++) if (Math.abs(cs[i] - c) < Math.abs(cs[best] - c)) best = i;
  return best;
}

// The four half-planes of a frame (cd and standard errors), for the polar curve.
function planesOf(frame) {
  const h = frame.header, g = frame.arrays.grid, sg = frame.arrays.sigma;
  const nG = h.gamma.length;
  const row = (c) => {
    const i = planeIndex(h.c, c);
    return { cd: Array.from(g.data.slice(i * nG, (i + 1) * nG)),
             sigma: Array.from(sg.data.slice(i * nG, (i + 1) * nG)), c: h.c[i] };
  };
  return { 0: row(0), 180: row(180), 90: row(90), 270: row(270) };
}

const POLAR_R = 180;

function drawPolar() {
  const h = LT.preview.header, perKlm = 1000 / h.lamp_lumens;
  const planes = planesOf(LT.preview);
  LT.polar = { gamma: h.gamma, planes, per_klm: perKlm, revision: h.revision, photons: h.photons };
  const ref = referenceFrame();
  // the reference in cd/klm of its own lamp flux (a file scaled to ours is the same)
  const refPerKlm = ref ? (ref.frame.header.lamp_lumens ? 1000 / ref.frame.header.lamp_lumens : perKlm) : 0;
  const refPlanes = ref ? planesOf(ref.frame) : null;
  let max = 0;
  for (const p of Object.values(planes)) p.cd.forEach((v, k) => { max = Math.max(max, (v + p.sigma[k]) * perKlm); });
  if (refPlanes) for (const p of Object.values(refPlanes)) p.cd.forEach((v) => { max = Math.max(max, v * refPerKlm); });
  const R = POLAR_R, scale = max > 0 ? R / max : 1;
  const pt = (gam, v, side) => {
    const a = gam * Math.PI / 180;
    return [side * v * scale * Math.sin(a), v * scale * Math.cos(a)];
  };
  const path = (gammas, right, left, pick) => {
    const pts = [];
    gammas.forEach((gam, k) => pts.push(pt(gam, pick(right, k), 1)));
    for (let k = gammas.length - 1; k >= 0; k--) pts.push(pt(gammas[k], pick(left, k), -1));
    return "M" + pts.map((q) => q[0].toFixed(1) + "," + q[1].toFixed(1)).join("L") + "Z";
  };
  let svg = "";
  const rings = niceTicks(max, 4);
  for (const t of rings) {
    svg += `<circle r="${(t * scale).toFixed(1)}" fill="none" stroke="#ddd"/>`;
  }
  for (let a = 0; a < 360; a += 30) {
    const r = a * Math.PI / 180;
    svg += `<line x1="0" y1="0" x2="${(R * Math.sin(r)).toFixed(1)}" y2="${(R * Math.cos(r)).toFixed(1)}" stroke="#eee"/>`;
  }
  // gamma labels as a datasheet has them: 0 at nadir (down), 90 at the sides, 180 up
  for (let a = 0; a <= 180; a += 30) {
    const r = a * Math.PI / 180, rl = R + 13;
    for (const side of a === 0 || a === 180 ? [1] : [1, -1]) {
      const x = side * rl * Math.sin(r), y = rl * Math.cos(r) + 4;
      svg += `<text class="angle" x="${x.toFixed(1)}" y="${y.toFixed(1)}" font-size="11" fill="#555" text-anchor="middle">${a}°</text>`;
    }
  }
  for (const t of rings) {  // the rings' values up the vertical, inside each ring
    const y = -t * scale;
    svg += `<text x="-3" y="${(y + 11).toFixed(1)}" font-size="10" fill="#888" text-anchor="end">${fmt(t)}</text>`;
  }
  const colours = { 0: "#c0392b", 90: "#2c5aa0" };
  for (const [c, other] of [[0, 180], [90, 270]]) {
    const right = planes[c], left = planes[other];
    const hi = (p, k) => (p.cd[k] + p.sigma[k]) * perKlm, lo = (p, k) => Math.max(0, p.cd[k] - p.sigma[k]) * perKlm;
    svg += `<path d="${path(h.gamma, right, left, hi)} ${path(h.gamma, right, left, lo)}" fill="${colours[c]}" fill-opacity="0.25" fill-rule="evenodd" stroke="none"/>`;
    svg += `<path d="${path(h.gamma, right, left, (p, k) => p.cd[k] * perKlm)}" fill="none" stroke="${colours[c]}" stroke-width="1.6" ${c === 90 ? 'stroke-dasharray="5,3"' : ""}/>`;
  }
  if (refPlanes) {
    const rg = ref.frame.header.gamma;
    for (const [c, other] of [[0, 180], [90, 270]]) {
      svg += `<path class="reference" d="${path(rg, refPlanes[c], refPlanes[other], (p, k) => p.cd[k] * refPerKlm)}" fill="none" stroke="#222" stroke-width="1.1" ${c === 90 ? 'stroke-dasharray="2,2"' : ""}/>`;
    }
  }
  const B = R + 42;
  svg += `<text x="${-R - 30}" y="${B}" font-size="11" fill="#c0392b">C0-C180</text>` +
    `<text x="${-R + 32}" y="${B}" font-size="11" fill="#2c5aa0">C90-C270 (dashed)</text>` +
    `<text x="${R + 30}" y="${B}" font-size="11" fill="#666" text-anchor="end">cd/klm, nadir down</text>`;
  if (ref) svg += `<text x="${-R - 30}" y="${B + 15}" font-size="11" fill="#222">black: reference, ${esc(ref.label)}</text>`;
  document.getElementById("polar").innerHTML = svg;
  LT.polar.reference = refPlanes ? { gamma: ref.frame.header.gamma, planes: refPlanes, per_klm: refPerKlm } : null;
}

function niceTicks(max, n) {
  if (!(max > 0)) return [];
  const raw = max / n, mag = Math.pow(10, Math.floor(Math.log10(raw)));
  const step = [1, 2, 2.5, 5, 10].map((m) => m * mag).find((s) => s >= raw) || raw;
  const out = [];
  for (let t = step; t <= max * 1.0001; t += step) out.push(t);
  return out;
}

// ---- convergence ------------------------------------------------------------------------------

function drawConvergence() {
  const h = LT.preview.header;
  const pts = LT.history.filter((q) => q.revision === h.revision && q.error != null && q.photons > 0);
  const W = 420, H = 240, L = 48, B = 30, T = 10, Rm = 10;
  let svg = `<rect x="${L}" y="${T}" width="${W - L - Rm}" height="${H - T - B}" fill="none" stroke="#ccc"/>`;
  if (pts.length) {
    const xs = pts.map((q) => Math.log10(q.photons));
    const ys = pts.flatMap((q) => [q.error, q.bound || q.error, h.target_error]).filter((v) => v > 0).map(Math.log10);
    const x0 = Math.min(...xs), x1 = Math.max(...xs, x0 + 1), y0 = Math.min(...ys) - 0.1, y1 = Math.max(...ys) + 0.1;
    const X = (v) => L + (v - x0) / (x1 - x0) * (W - L - Rm), Y = (v) => T + (y1 - v) / (y1 - y0) * (H - T - B);
    const line = (key, colour, dash) => {
      const q = pts.filter((p) => p[key] > 0);
      if (!q.length) return "";
      return `<polyline fill="none" stroke="${colour}" stroke-width="1.6" ${dash ? 'stroke-dasharray="4,3"' : ""} points="${q.map((p) => X(Math.log10(p.photons)).toFixed(1) + "," + Y(Math.log10(p[key])).toFixed(1)).join(" ")}"/>`;
    };
    svg += line("error", "#c0392b") + line("bound", "#c0392b", true);
    if (h.target_error > 0) {
      const y = Y(Math.log10(h.target_error)).toFixed(1);
      svg += `<line x1="${L}" x2="${W - Rm}" y1="${y}" y2="${y}" stroke="#1e8449"/><text x="${W - Rm - 4}" y="${y - 3}" font-size="10" fill="#1e8449" text-anchor="end">target ${pct(h.target_error)}</text>`;
    }
    svg += `<text x="${L}" y="${H - 8}" font-size="10" fill="#666">${fmtInt(Math.pow(10, x0))}</text>` +
      `<text x="${W - Rm}" y="${H - 8}" font-size="10" fill="#666" text-anchor="end">${fmtInt(Math.pow(10, x1))} photons</text>` +
      `<text x="2" y="${T + 10}" font-size="10" fill="#666">${pct(Math.pow(10, y1))}</text>` +
      `<text x="2" y="${H - B}" font-size="10" fill="#666">${pct(Math.pow(10, y0))}</text>` +
      `<text x="${L + 6}" y="${T + 14}" font-size="10" fill="#c0392b">map: estimate (solid), bound (dashed)</text>`;
  }
  document.getElementById("convergence").innerHTML = svg;
}

// ---- figures --------------------------------------------------------------------------------

function drawFigures() {
  const f = LT.preview.header.figures;
  const pm = (v, e, unit, d) => v == null ? "-" : `${Number(v).toFixed(d)}${unit ? " " + unit : ""}${e == null ? "" : " ± " + Number(e).toFixed(d)}`;
  const rows = [
    ["luminous flux", pm(f.luminous_flux, f.luminous_flux_error, "lm", 1)],
    ["light output ratio", pm(f.light_output_ratio, f.light_output_ratio_error, "", 4)],
    ["peak intensity", pm(f.peak_intensity, f.peak_intensity_error, "cd", 1)],
    ["beam angle C0-C180", pm(f.beam_angle_c0_c180, f.beam_angle_c0_c180_error, "°", 1)],
    ["beam angle C90-C270", pm(f.beam_angle_c90_c270, f.beam_angle_c90_c270_error, "°", 1)],
    ["field angle C0-C180", pm(f.field_angle_c0_c180, f.field_angle_c0_c180_error, "°", 1)],
    ["field angle C90-C270", pm(f.field_angle_c90_c270, f.field_angle_c90_c270_error, "°", 1)],
    ["UGR 4H8H 70/50/20", pm(f.ugr_4h8h_70_50_20, f.ugr_4h8h_70_50_20_error, "", 2)],
    ["downward flux", f.downward_flux_fraction == null ? "-" : pct(f.downward_flux_fraction)],
    ["files' error", pct(f.photometry_error)],
    ["CIE flux code", f.cie_flux_code || "-"],
  ];
  const col = LT.results ? (LT.results.colour || LT.results) : null;
  if (col && col.cct_K != null) {
    rows.push(["CCT", `${Number(col.cct_K).toFixed(0)} K`], ["Duv", Number(col.duv).toFixed(4)]);
  }
  document.getElementById("figures").innerHTML = rows.map(([k, v]) => `<tr><td>${k}</td><td>${v}</td></tr>`).join("");
  LT.figures = f;
}

// ---- the 3D view (WebGL2) -------------------------------------------------------------------

const gl = document.getElementById("view3d").getContext("webgl2", { alpha: false, antialias: true, preserveDrawingBuffer: true });
const cam = { theta: -0.9, phi: -0.3, dist: 0.6, target: [0, 0, 0] };  // from below: the light side
const FOV_HALF = 0.4;  // half the vertical field of view (rad)
const meshes = { parts: null, solid: null, picked: null };
const HIGHLIGHT = [1.0, 0.5, 0.0];

function shader(type, src) {
  const s = gl.createShader(type);
  gl.shaderSource(s, src);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
  return s;
}

const program = (() => {
  if (!gl) return null;
  const p = gl.createProgram();
  gl.attachShader(p, shader(gl.VERTEX_SHADER, `#version 300 es
    in vec3 pos; in vec3 nrm; in vec3 col;
    uniform mat4 mvp; out vec3 vn; out vec3 vc;
    void main() { gl_Position = mvp * vec4(pos, 1.0); vn = nrm; vc = col; }`));
  gl.attachShader(p, shader(gl.FRAGMENT_SHADER, `#version 300 es
    precision mediump float; in vec3 vn; in vec3 vc; uniform float alpha; uniform float flat_; out vec4 o;
    void main() { vec3 l = normalize(vec3(0.4, -0.5, 0.75));
      float d = abs(dot(normalize(vn), l)); o = vec4(vc * mix(0.35 + 0.65 * d, 1.0, flat_), alpha); }`));
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
  return p;
})();

function upload(positions, normals, colours) {
  const vao = gl.createVertexArray();
  gl.bindVertexArray(vao);
  const attrs = [["pos", positions], ["nrm", normals], ["col", colours]];
  for (const [name, data] of attrs) {
    const buf = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, buf);
    gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
    const loc = gl.getAttribLocation(program, name);
    gl.enableVertexAttribArray(loc);
    gl.vertexAttribPointer(loc, 3, gl.FLOAT, false, 0, 0);
  }
  gl.bindVertexArray(null);
  return { vao, count: positions.length / 3 };
}

const PART_COLOURS = [[0.85, 0.85, 0.82], [0.65, 0.72, 0.85], [0.80, 0.84, 0.90], [0.6, 0.8, 0.65],  // no orange: that is the pick's
                      [0.8, 0.6, 0.75], [0.7, 0.7, 0.7]];

function buildParts() {
  if (!gl || !LT.geometry) return;
  const pos = LT.geometry.arrays.positions.data, counts = LT.geometry.header.counts;
  const n = pos.length / 3, nrm = new Float32Array(pos.length), col = new Float32Array(pos.length);
  let lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  const partOf = new Int32Array(n / 3);
  let t = 0;
  counts.forEach((c, part) => { for (let k = 0; k < c; k++) partOf[t++] = part; });
  const picked = [], pickedN = [];
  for (let i = 0; i < n; i += 3) {
    const a = i * 3, b = a + 3, c = a + 6;
    const u = [pos[b] - pos[a], pos[b + 1] - pos[a + 1], pos[b + 2] - pos[a + 2]];
    const v = [pos[c] - pos[a], pos[c + 1] - pos[a + 1], pos[c + 2] - pos[a + 2]];
    const nx = u[1] * v[2] - u[2] * v[1], ny = u[2] * v[0] - u[0] * v[2], nz = u[0] * v[1] - u[1] * v[0];
    const part = partOf[i / 3];
    const colour = PART_COLOURS[part % PART_COLOURS.length];
    for (let k = 0; k < 3; k++) {
      nrm.set([nx, ny, nz], a + 3 * k);
      col.set(colour, a + 3 * k);
      for (let d = 0; d < 3; d++) { lo[d] = Math.min(lo[d], pos[a + 3 * k + d]); hi[d] = Math.max(hi[d], pos[a + 3 * k + d]); }
    }
    if (part === LT.picked) {
      for (let k = 0; k < 9; k++) picked.push(pos[a + k]);
      for (let k = 0; k < 3; k++) pickedN.push(nx, ny, nz);
    }
  }
  LT.partOf = partOf;
  if (n) {
    LT.extent = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / 2;
    LT.partBounds = { lo, hi };
    if (!LT.framed) {  // until the solid is there to frame with them
      cam.target = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2];
      cam.dist = LT.extent * 6;
    }
  }
  meshes.parts = upload(pos, nrm, col);
  // the picked part again, drawn over the solid: it stays in sight inside the lobe
  const pc = new Float32Array(picked.length);
  for (let i = 0; i < pc.length; i += 3) pc.set(HIGHLIGHT, i);
  meshes.picked = picked.length ? upload(new Float32Array(picked), new Float32Array(pickedN), pc) : null;
  buildSolid();
}

function direction(cDeg, gDeg) {
  const c = cDeg * Math.PI / 180, g = gDeg * Math.PI / 180;
  return [Math.sin(g) * Math.cos(c), Math.sin(g) * Math.sin(c), -Math.cos(g)];
}

function buildSolid() {
  if (!gl || !LT.preview) return;
  const h = LT.preview.header, g = LT.preview.arrays.grid.data;
  const log = document.getElementById("solid-log").checked;
  const cs = h.c.concat([360]), nC = h.c.length, nG = h.gamma.length;
  let max = 0;
  for (const v of g) max = Math.max(max, v);
  const s = scaler(max, log), R = (LT.extent || 0.05) * 2.5;
  const at = (i, k) => g[(i % nC) * nG + k];
  const pos = [], nrm = [], col = [];
  const vert = (i, k) => {
    const v = at(i, k), d = direction(cs[i], h.gamma[k]), r = s(v) * R;
    return { p: [d[0] * r, d[1] * r, d[2] * r], c: turbo(s(v)) };
  };
  for (let i = 0; i < nC; i++) {
    for (let k = 0; k + 1 < nG; k++) {
      const q = [vert(i, k), vert(i + 1, k), vert(i + 1, k + 1), vert(i, k + 1)];
      for (const tri of [[0, 1, 2], [0, 2, 3]]) {
        const [a, b, c] = tri.map((j) => q[j]);
        const u = a.p.map((x, d) => b.p[d] - x), v = a.p.map((x, d) => c.p[d] - x);
        const n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
        for (const w of [a, b, c]) { pos.push(...w.p); nrm.push(...n); col.push(...w.c); }
      }
    }
  }
  LT.solidPositions = new Float32Array(pos);
  meshes.solid = upload(LT.solidPositions, new Float32Array(nrm), new Float32Array(col));
  legend(document.getElementById("solid-legend"), max, log, "cd");
  const key = (log ? "log" : "linear") + (LT.geometry ? "+parts" : "");
  if (!LT.framed || LT.framed.key !== key) frameView(key);
}

// Frame the luminaire and its solid: the camera aims at the middle of both and stands back
// far enough that the sphere around them fits the narrower of the two fields of view.
function frameView(key) {
  const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  const take = (arr) => {
    for (let i = 0; i < arr.length; i += 3) {
      for (let d = 0; d < 3; d++) { lo[d] = Math.min(lo[d], arr[i + d]); hi[d] = Math.max(hi[d], arr[i + d]); }
    }
  };
  if (LT.geometry) take(LT.geometry.arrays.positions.data);
  if (LT.solidPositions) take(LT.solidPositions);
  if (!(hi[0] >= lo[0])) return;
  const centre = [0, 1, 2].map((d) => (lo[d] + hi[d]) / 2);
  let radius = 0;
  const reach = (arr) => {
    for (let i = 0; i < arr.length; i += 3) {
      radius = Math.max(radius, Math.hypot(arr[i] - centre[0], arr[i + 1] - centre[1], arr[i + 2] - centre[2]));
    }
  };
  if (LT.geometry) reach(LT.geometry.arrays.positions.data);
  if (LT.solidPositions) reach(LT.solidPositions);
  const canvas = document.getElementById("view3d");
  const aspect = (canvas.clientWidth || canvas.width) / Math.max(canvas.clientHeight || canvas.height, 1);
  const half = Math.min(FOV_HALF, Math.atan(Math.tan(FOV_HALF) * aspect));
  cam.target = centre;
  cam.dist = Math.max(radius, 1e-6) / Math.sin(half) * 1.08;
  LT.framed = { key, radius, centre, aspect };
}

function matMul(a, b) {
  const o = new Float32Array(16);
  for (let i = 0; i < 4; i++) for (let j = 0; j < 4; j++) {
    let s = 0;
    for (let k = 0; k < 4; k++) s += a[k * 4 + j] * b[i * 4 + k];
    o[i * 4 + j] = s;
  }
  return o;
}

function viewProjection(aspect) {
  const eye = [cam.target[0] + cam.dist * Math.cos(cam.phi) * Math.cos(cam.theta),
               cam.target[1] + cam.dist * Math.cos(cam.phi) * Math.sin(cam.theta),
               cam.target[2] + cam.dist * Math.sin(cam.phi)];
  const f = norm(sub(cam.target, eye)), r = norm(cross(f, [0, 0, 1])), u = cross(r, f);
  const view = new Float32Array([r[0], u[0], -f[0], 0, r[1], u[1], -f[1], 0, r[2], u[2], -f[2], 0,
    -dot(r, eye), -dot(u, eye), dot(f, eye), 1]);
  const near = cam.dist / 100, far = cam.dist * 100, t = 1 / Math.tan(FOV_HALF);
  const proj = new Float32Array([t / aspect, 0, 0, 0, 0, t, 0, 0, 0, 0, (far + near) / (near - far), -1,
    0, 0, 2 * far * near / (near - far), 0]);
  return { vp: matMul(proj, view), eye, r, u, f };
}

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const norm = (a) => { const l = Math.hypot(...a) || 1; return [a[0] / l, a[1] / l, a[2] / l]; };

function render() {
  requestAnimationFrame(render);
  if (!gl || !program) return;
  const canvas = gl.canvas;
  const w = canvas.clientWidth | 0, hgt = canvas.clientHeight | 0;
  if (w && (canvas.width !== w || canvas.height !== hgt)) { canvas.width = w; canvas.height = hgt; }
  gl.viewport(0, 0, canvas.width, canvas.height);
  gl.clearColor(0.07, 0.07, 0.08, 1);
  gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  gl.enable(gl.DEPTH_TEST);
  gl.depthFunc(gl.LEQUAL);
  gl.useProgram(program);
  const { vp } = viewProjection(canvas.width / Math.max(canvas.height, 1));
  gl.uniformMatrix4fv(gl.getUniformLocation(program, "mvp"), false, vp);
  const alpha = gl.getUniformLocation(program, "alpha"), flat = gl.getUniformLocation(program, "flat_");
  gl.uniform1f(flat, 0.0);
  if (meshes.parts) {
    gl.disable(gl.BLEND);
    gl.uniform1f(alpha, 1.0);
    gl.bindVertexArray(meshes.parts.vao);
    gl.drawArrays(gl.TRIANGLES, 0, meshes.parts.count);
  }
  if (meshes.solid && document.getElementById("solid-show").checked) {
    gl.enable(gl.BLEND);
    gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA);
    gl.depthMask(false);
    gl.uniform1f(alpha, 0.55);
    gl.bindVertexArray(meshes.solid.vao);
    gl.drawArrays(gl.TRIANGLES, 0, meshes.solid.count);
    gl.depthMask(true);
  }
  if (meshes.picked) {
    // the picked part: over the solid where nothing nearer hides it, and faintly through
    // the parts in front of it (a reflector inside its housing is seen)
    gl.uniform1f(flat, 0.6);
    gl.bindVertexArray(meshes.picked.vao);
    gl.disable(gl.BLEND);
    gl.uniform1f(alpha, 1.0);
    gl.drawArrays(gl.TRIANGLES, 0, meshes.picked.count);
    gl.enable(gl.BLEND);
    gl.disable(gl.DEPTH_TEST);
    gl.depthMask(false);
    gl.uniform1f(alpha, 0.35);
    gl.drawArrays(gl.TRIANGLES, 0, meshes.picked.count);
    gl.depthMask(true);
    gl.enable(gl.DEPTH_TEST);
  }
  gl.bindVertexArray(null);
  LT.frames++;
  LT.drawn.view3d = performance.now();
}

// orbit, pan, zoom, pick
(function controls() {
  const canvas = document.getElementById("view3d");
  let drag = null;
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("mousedown", (e) => { drag = { x: e.clientX, y: e.clientY, pan: e.shiftKey || e.button === 2, moved: false }; });
  window.addEventListener("mouseup", (e) => {
    if (drag && !drag.moved && e.target === canvas) pick(e);
    drag = null;
  });
  window.addEventListener("mousemove", (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    if (Math.abs(dx) + Math.abs(dy) > 2) drag.moved = true;
    drag.x = e.clientX; drag.y = e.clientY;
    if (drag.pan) {
      const { r, u } = viewProjection(1), k = cam.dist * 0.002;
      cam.target = cam.target.map((t, d) => t - r[d] * dx * k + u[d] * dy * k);
    } else {
      cam.theta -= dx * 0.008;
      cam.phi = Math.max(-1.5, Math.min(1.5, cam.phi + dy * 0.008));
    }
  });
  canvas.addEventListener("wheel", (e) => { e.preventDefault(); cam.dist *= Math.exp(e.deltaY * 0.001); }, { passive: false });
})();

document.getElementById("frame").addEventListener("click", () => frameView(LT.framed ? LT.framed.key : ""));

function pick(e) {
  if (!LT.geometry) return;
  const canvas = gl.canvas, rect = canvas.getBoundingClientRect();
  const x = ((e.clientX - rect.left) / rect.width) * 2 - 1, y = 1 - ((e.clientY - rect.top) / rect.height) * 2;
  const { eye, r, u, f } = viewProjection(rect.width / rect.height);
  const t = Math.tan(FOV_HALF), aspect = rect.width / rect.height;
  const dir = norm([0, 1, 2].map((d) => f[d] + r[d] * x * t * aspect + u[d] * y * t));
  const pos = LT.geometry.arrays.positions.data;
  let best = Infinity, part = null;
  for (let i = 0; i < pos.length; i += 9) {  // Moller-Trumbore against every triangle
    const a = [pos[i], pos[i + 1], pos[i + 2]];
    const e1 = [pos[i + 3] - a[0], pos[i + 4] - a[1], pos[i + 5] - a[2]];
    const e2 = [pos[i + 6] - a[0], pos[i + 7] - a[1], pos[i + 8] - a[2]];
    const p = cross(dir, e2), det = dot(e1, p);
    if (Math.abs(det) < 1e-12) continue;
    const s = sub(eye, a), uu = dot(s, p) / det;
    if (uu < 0 || uu > 1) continue;
    const q = cross(s, e1), vv = dot(dir, q) / det;
    if (vv < 0 || uu + vv > 1) continue;
    const d = dot(e2, q) / det;
    if (d > 0 && d < best) { best = d; part = LT.partOf[i / 9]; }
  }
  if (part != null) selectPart(part);
}

// ---- the editor ------------------------------------------------------------------------------

// A part picked (in the view or the list): the editor shows it, the view highlights it.
function selectPart(index) {
  LT.selected = index;
  LT.picked = index;
  document.getElementById("part-select").value = String(index);
  buildParts();
  fillEditor();
}

document.getElementById("part-select").addEventListener("change", (e) => selectPart(parseInt(e.target.value, 10)));

const FIELDS = [["reflectance", "reflectance"], ["specularReflectance", "specular reflectance"],
                ["transmittance", "transmittance"], ["roughness", "roughness"], ["ior", "index of refraction"]];

// The number a field holds, or null where it holds none: then the problem is shown beside
// it, the field goes back to the stage's value (its data-stage), and nothing is sent.
function readNumber(input, label) {
  const raw = input.value.trim();
  let why = null;
  if (input.validity && input.validity.badInput) why = "is not a number";
  else if (raw === "") why = "is empty";
  else if (!isFinite(Number(raw))) why = "is not a number";
  if (why == null) {
    // a field left as shown sends the stage's value itself, not its rounding
    if (input.dataset.exact != null && raw === input.dataset.stage) return Number(input.dataset.exact);
    return Number(raw);
  }
  const back = input.dataset.stage != null ? input.dataset.stage : input.defaultValue;
  const problem = problemOf(input);
  problem.textContent = `${label || input.dataset.label || "the value"} ${why}: not sent` +
    (back !== "" ? `, back to ${back}` : "");
  input.value = back;
  LT.problems.push({ field: label || input.dataset.label || input.id, why });
  return null;
}

// A field showing the stage's value ``v`` (rounded for the eye; sent exactly if left so).
function stageValue(input, v) {
  const shown = v == null ? "" : String(round(v));
  input.value = shown;
  input.defaultValue = shown;
  input.dataset.stage = shown;
  if (v != null) input.dataset.exact = String(v); else delete input.dataset.exact;
}

function fillEditor() {
  const sc = LT.scene;
  if (!sc) return;
  const sel = document.getElementById("part-select");
  const keep = LT.selected != null && LT.selected < sc.parts.length ? LT.selected : 0;
  sel.innerHTML = sc.parts.map((p, i) => `<option value="${i}">${esc(p.path)}</option>`).join("");
  if (sc.parts.length) { sel.value = String(keep); LT.selected = keep; }
  const part = sc.parts[LT.selected];
  const box = document.getElementById("material-box");
  box.innerHTML = "";
  if (part) {
    for (const mpath of part.materials) {
      const m = sc.materials.find((x) => x.path === mpath);
      if (!m) continue;
      const fs = document.createElement("fieldset");
      fs.innerHTML = `<legend>material ${esc(m.path)}</legend>`;
      const scat = document.createElement("div");
      scat.className = "row";
      scat.innerHTML = `<label>scattering <select data-prop="scattering">${sc.scattering_models.map((t) => `<option ${t === m.scattering ? "selected" : ""}>${t}</option>`).join("")}</select></label><span class="problem"></span>`;
      fs.appendChild(scat);
      for (const [key, label] of FIELDS) {
        const range = sc.ranges[key] || [0, null];
        const row = document.createElement("div");
        row.className = "row";
        const max = range[1] == null ? "" : `max="${range[1]}"`;
        row.innerHTML = `<label>${label} <input type="number" step="any" data-prop="${key}" data-label="${label}" min="${range[0]}" ${max}></label><span class="problem"></span>`;
        stageValue(row.querySelector("input"), m[key]);
        varyTick(row, `${m.path}.${sc.properties[key]}`, m[key], range);
        fs.appendChild(row);
      }
      fs.querySelectorAll("[data-prop]").forEach((input) => {
        input.disabled = !m.editable;
        input.addEventListener("change", () => {
          const prop = input.dataset.prop;
          problemOf(input).textContent = "";
          const value = prop === "scattering" ? input.value : readNumber(input);
          if (value == null) return;
          const old = m[prop];
          edit([{ op: "set", path: m.path, property: sc.properties[prop], value }],
               [{ op: "set", path: m.path, property: sc.properties[prop], value: old }], input);
        });
      });
      box.appendChild(fs);
    }
  }
  fillTransform(part);
  const ebox = document.getElementById("emitter-box");
  ebox.innerHTML = `<fieldset><legend>emitters (lm)</legend>${sc.emitters.map((e, i) =>
    `<div class="row"><label><span class="name" title="${esc(e.path)}">${esc(e.path)}</span> <input type="number" min="0" step="any" data-emitter="${i}" data-label="flux" ${e.editable ? "" : "disabled"}></label><span class="problem"></span></div>`).join("")}</fieldset>`;
  ebox.querySelectorAll("[data-emitter]").forEach((input) => {
    const e = sc.emitters[parseInt(input.dataset.emitter, 10)];
    stageValue(input, e.flux);
    varyTick(input.closest(".row"), `${e.path}.${sc.properties.flux}`, e.flux, [0, null]);
    input.addEventListener("change", () => {
      problemOf(input).textContent = "";
      const value = readNumber(input, `the flux of ${e.path}`);
      if (value == null) return;
      edit([{ op: "set", path: e.path, property: sc.properties.flux, value }],
           [{ op: "set", path: e.path, property: sc.properties.flux, value: e.flux }], input);
    });
  });
}

const AXES = ["x", "y", "z"];
const TRANSFORM_ROWS = [["translate", "t", "move"], ["rotate", "r", "turn"], ["scale", "s", "scale"]];

// The part's local transform, as its xformOps hold it (stage units, XYZ degrees); a
// transform the fields cannot show is shown read-only and kept.
function fillTransform(part) {
  const tbox = document.getElementById("transform-box");
  if (!part) { tbox.innerHTML = ""; return; }
  const tf = part.transform || { editable: false, note: "the service did not say" };
  const rows = TRANSFORM_ROWS.map(([key, id, label]) =>
    `<div class="row">${key} ${AXES.map((a) => `<label class="axis">${a}<input type="number" step="any" id="${id}${a}" data-label="${label} ${a}"></label>`).join("")}<span class="problem"></span></div>`).join("");
  tbox.innerHTML = `<fieldset><legend>transform of ${esc(part.path)} (local: stage units, degrees)</legend>${rows}
    <div class="row"><button id="apply-transform">Set transform</button><span class="problem"></span></div>
    <p class="note" id="transform-note" ${tf.editable ? "hidden" : ""}>read-only: ${esc(tf.note || "")}</p></fieldset>`;
  for (const [key, id] of TRANSFORM_ROWS) {
    AXES.forEach((a, k) => {
      const input = document.getElementById(id + a);
      stageValue(input, tf.editable ? tf[key][k] : null);
      input.disabled = !tf.editable;
      const op = TRANSFORM_OPS[key];
      if (tf.editable && (tf.ops || []).includes(op)) {
        const v = tf[key][k];
        varyTick(input.closest(".row"), `${part.path}.${op}[${k}]`, v, transformRange(key, v),
                 input.closest("label").nextSibling);
      }
    });
  }
  const at = document.getElementById("apply-transform");
  at.disabled = !tf.editable;
  at.addEventListener("click", () => {
    tbox.querySelectorAll(".problem").forEach((p) => { p.textContent = ""; });
    const values = {};
    let bad = false;
    for (const [key, id] of TRANSFORM_ROWS) {
      values[key] = AXES.map((a) => {
        const v = readNumber(document.getElementById(id + a));
        if (v == null) bad = true;
        return v;
      });
    }
    if (bad) return;
    const inverse = tf.matrix ? [{ op: "transform", path: part.path, matrix: tf.matrix }] : null;
    edit([{ op: "transform", path: part.path, ...values }], inverse, at);
  });
}

// A "fit" tick beside an editor field: ticked, the field's attribute is a parameter of the
// next fit (fit.js), its range the schema's, or half to twice the value where it has none.
function varyTick(row, name, value, range, before = row.querySelector(".problem")) {
  if (typeof fitParameters === "undefined" || value == null || typeof value !== "number") return;
  // (range: [lo, hi]; hi null: half to twice the value, no less than lo)
  const label = document.createElement("label");
  label.className = "vary";
  label.innerHTML = `<input type="checkbox" data-vary="${esc(name)}"> fit`;
  const box = label.querySelector("input");
  box.checked = fitParameters.has(name);
  box.addEventListener("change", () => {
    if (box.checked) {
      // (an open end: half or twice the value, within the schema's least)
      const lo = range[1] != null ? range[0] : Math.max(range[0] ?? -Infinity, 0.5 * value);
      const hi = range[1] != null ? range[1] : 2 * value;
      addFitParameter(name, lo, hi);
    } else removeFitParameter(name);
  });
  row.insertBefore(label, before);
}

// The op a transform row's fields are, where the part's transform is that op's value
// (XformCommonAPI's stack), and the range a fit varies a component over: a fifth of the
// luminaire's size about a position, 15 degrees about an angle, half to twice a scale.
const TRANSFORM_OPS = { translate: "xformOp:translate", rotate: "xformOp:rotateXYZ", scale: "xformOp:scale" };
function transformRange(key, v) {
  if (key === "translate") { const d = 0.2 * (LT.extent || 0.05) * 2; return [v - d, v + d]; }
  if (key === "rotate") return [v - 15, v + 15];
  return v > 0 ? [0.5 * v, 2 * v] : [v - 1, v + 1];
}

function problemOf(control) {
  const row = control && control.closest(".row");
  return (row && row.querySelector(".problem")) || document.getElementById("editor-problem");
}

async function edit(deltas, inverse, control) {
  // the control again after the editor is rebuilt (same data attributes in the same box)
  const box = control.closest("fieldset") ? control.closest("fieldset").parentElement : null;
  const attrs = ["data-prop", "data-emitter", "id"].filter((a) => control.hasAttribute(a))
    .map((a) => `[${a}="${control.getAttribute(a)}"]`).join("");
  const legend = control.closest("fieldset") ? control.closest("fieldset").querySelector("legend").textContent : "";
  const find = () => {
    if (!box) return control;
    for (const fs of box.querySelectorAll("fieldset")) {
      if (fs.querySelector("legend").textContent === legend) return fs.querySelector(attrs) || control;
    }
    return control;
  };
  let shown = problemOf(control);
  shown.textContent = "";
  const sent = performance.now();
  const base = LT.status ? LT.status.revision : undefined;
  const r = await postJSON("/deltas", { deltas, base_revision: base });
  if (!r.ok) {
    const why = (r.body.problems || []).map((p) => (p.where ? p.where + ": " : "") + p.why).join("; ") || r.body.error;
    shown.textContent = why;
    LT.problems.push({ deltas, status: r.status, why });
    await refreshScene();  // the control goes back to the stage's value
    problemOf(find()).textContent = why;
    return;
  }
  LT.timings.push({ revision: r.body.revision, sent, drawn: null, effect: r.body.effect,
                    posted: performance.now() - sent });
  if (inverse) LT.undo.push(inverse);
  document.getElementById("undo").disabled = LT.undo.length === 0;
  await refreshStatus();
}

document.getElementById("undo").addEventListener("click", async () => {
  const inverse = LT.undo.pop();
  document.getElementById("undo").disabled = LT.undo.length === 0;
  if (inverse) {
    const r = await postJSON("/deltas", { deltas: inverse });
    if (!r.ok) document.getElementById("editor-problem").textContent = r.body.error;
  }
});

// ---- the session's knobs -------------------------------------------------------------------

async function loadSession() {
  try {
    const s = await getJSON("/settings");
    stageValue(document.getElementById("threshold"), s.threshold);
    stageValue(document.getElementById("target-error"), s.target_error);
    stageValue(document.getElementById("budget"), s.photons);
    LT.settings = s;
    showPaused(!!s.paused);
  } catch (e) { /* not yet */ }
}

document.getElementById("apply-session").addEventListener("click", async () => {
  document.querySelectorAll("#session-panel .problem").forEach((p) => { p.textContent = ""; });
  const threshold = readNumber(document.getElementById("threshold"), "the filter threshold");
  const target = document.getElementById("target-error"), budget = document.getElementById("budget");
  const body = {};
  if (threshold == null) return;
  body.threshold = threshold;
  // the session has a photon budget or a target error: an empty budget means the target
  if (budget.value.trim() !== "" || (budget.validity && budget.validity.badInput)) {
    const n = readNumber(budget, "the photon budget");
    if (n == null) return;
    body.photons = n;
  } else {
    const t = readNumber(target, "the target error (or a photon budget)");
    if (t == null) return;
    body.target_error = t;
  }
  const r = await postJSON("/settings", body);
  if (!r.ok) {
    const prop = (r.body.error || "").split(":")[0];
    const el = document.querySelector(`#session-panel .problem[data-for="${prop}"]`) ||
      document.querySelector("#session-panel .problem");
    el.textContent = r.body.error;
  } else LT.settings = r.body;
  loadSession();
});

document.getElementById("pause").addEventListener("click", async () => {
  const r = await postJSON("/settings", { paused: !LT.paused });
  if (r.ok) { LT.settings = r.body; showPaused(!!r.body.paused); }
  else document.getElementById("session-problem").textContent = r.body.error;
  refreshStatus();
});

for (const id of ["map-log"]) document.getElementById(id).addEventListener("change", drawMap);
document.querySelectorAll("input[name=map-kind]").forEach((el) => el.addEventListener("change", drawMap));
document.getElementById("solid-log").addEventListener("change", buildSolid);

// ---- helpers and start ---------------------------------------------------------------------

function round(v) { return Number(Number(v).toPrecision(6)); }
function text(id, v) { document.getElementById(id).textContent = v == null ? "-" : String(v); }
function pct(v) { return v == null || !isFinite(v) ? "undefined" : (100 * v).toFixed(2) + "%"; }
function pctShort(v) { return v == null || !isFinite(v) ? "-" : Number((100 * v).toPrecision(2)) + "%"; }
function fmt(v) { return v >= 100 ? Math.round(v).toLocaleString("en") : Number(v).toPrecision(3); }
function fmtInt(v) { return v == null ? "-" : Math.round(v).toLocaleString("en"); }
function esc(s) { return String(s).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" })[c]); }

async function start() {
  try {
    await refreshStatus();
    if (!LT.status) { askToken(""); return; }
  } catch (e) { return; }
  await refreshScene();
  await loadSession();
  if (LT.status.photons > 0) await refresh();  // else the first iteration's event brings it
  refreshRevisions();
  follow();
}

requestAnimationFrame(render);
start();
