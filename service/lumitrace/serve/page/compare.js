// lumitrace live view: comparing the design with a reference, a pinned revision (its last
// preview, kept by the service) or a target IES or LDT file (read by the service into a
// frame like the preview's). The key figures are shown as differences with the combined
// standard error of both; the polar curve and the map show the reference too.
"use strict";

// [figure, label, how the difference is given, unit, how it moves with the lamp flux]
const KEY_FIGURES = [
  ["luminous_flux", "luminous flux", "relative", "%", "flux"],
  ["light_output_ratio", "light output ratio", "relative", "%", null],
  ["peak_intensity", "peak intensity", "relative", "%", "flux"],
  ["beam_angle_c0_c180", "beam angle C0-C180", "absolute", "°", null],
  ["beam_angle_c90_c270", "beam angle C90-C270", "absolute", "°", null],
  ["field_angle_c0_c180", "field angle C0-C180", "absolute", "°", null],
  ["field_angle_c90_c270", "field angle C90-C270", "absolute", "°", null],
  ["ugr_4h8h_70_50_20", "UGR 4H8H 70/50/20 crosswise", "absolute", "", "ugr"],
  ["ugr_4h8h_70_50_20_endwise", "UGR 4H8H 70/50/20 endwise", "absolute", "", "ugr"],
];
// A difference within this many combined standard errors is within the noise (about 95%).
const NOISE_SIGMAS = 2;

// The reference as drawn: its frame, the factor its intensities are shown at (a target
// file at this design's lamp flux; a revision as it was) and its name.
function referenceFrame() {
  const ref = LT.reference;
  if (!ref || !ref.frame) return null;
  const h = ref.frame.header;
  let scale = 1, label;
  if (ref.kind === "file") {
    if (h.lamp_lumens && LT.preview) scale = LT.preview.header.lamp_lumens / h.lamp_lumens;
    label = `${ref.name} (${h.format.toUpperCase()}` + (h.lamp_lumens
      ? `, ${fmtInt(h.lamp_lumens)} lm lamp, shown at this design's ${fmtInt(LT.preview ? LT.preview.header.lamp_lumens : h.lamp_lumens)} lm)`
      : ", absolute photometry)");
  } else {
    label = `revision ${ref.revision} (${fmtInt(h.photons)} photons)`;
  }
  return { kind: ref.kind, frame: ref.frame, scale, label };
}

// The reference's figures at the factor it is shown at: fluxes and intensities scale, UGR
// moves by 8 log10 of it (L^2 omega over the background's luminance), the rest stays.
function referenceFigures(ref) {
  const f = Object.assign({}, ref.frame.header.figures);
  if (ref.scale !== 1) {
    for (const k of ["luminous_flux", "luminous_flux_error", "peak_intensity", "peak_intensity_error"]) {
      if (f[k] != null) f[k] *= ref.scale;
    }
    for (const k of ["ugr_4h8h_70_50_20", "ugr_4h8h_70_50_20_endwise"]) {
      if (f[k] != null) f[k] += 8 * Math.log10(ref.scale);
    }
  }
  return f;
}

// now - reference with its standard error, both errors combined (independent estimates):
// in percent of the reference ("relative") or in the figure's unit ("absolute").
function difference(a, ea, b, eb, kind) {
  if (a == null || b == null || !isFinite(a) || !isFinite(b)) return null;
  const known = ea != null && eb != null;
  if (kind === "relative") {
    if (!(b > 0)) return null;
    const value = 100 * (a / b - 1);
    const error = known ? 100 * Math.hypot(ea, a * eb / b) / b : null;
    return { value, error };
  }
  return { value: a - b, error: known ? Math.hypot(ea, eb) : null };
}

function withinNoise(d) {
  if (!d || d.error == null) return null;
  return Math.abs(d.value) <= NOISE_SIGMAS * d.error;
}

// "+3.1 ± 0.4 %": as many decimals as the error's first significant digit asks for.
function formatDifference(d, unit) {
  if (!d) return "-";
  const e = d.error;
  const decimals = e > 0 ? Math.min(4, Math.max(0, 1 - Math.floor(Math.log10(e)))) : 2;
  const sign = d.value > 0 ? "+" : d.value < 0 ? "-" : "";
  const v = Math.abs(d.value).toFixed(decimals);
  const space = unit === "°" ? "" : " ";
  return `${Number(v) === 0 ? "" : sign}${v}${e == null ? " ± ?" : " ± " + e.toFixed(decimals)}${unit ? space + unit : ""}`;
}

function drawComparison() {
  const table = document.getElementById("differences"), verdict = document.getElementById("noise-verdict");
  const ref = referenceFrame();
  document.getElementById("unpin").disabled = !LT.reference;
  document.getElementById("reference-name").textContent = ref ? "reference: " + ref.label
    : "no reference: pin a revision or load a target IES or LDT file";
  if (!ref || !LT.preview) {
    table.innerHTML = "";
    verdict.textContent = "";
    LT.comparison = null;
    return;
  }
  const now = LT.preview.header.figures, then = referenceFigures(ref);
  const rows = [];
  for (const [key, label, kind, unit] of KEY_FIGURES) {
    const d = difference(now[key], now[key + "_error"], then[key], then[key + "_error"], kind);
    rows.push({ key, label, now: now[key], reference: then[key], difference: d,
                within: withinNoise(d), text: formatDifference(d, unit) });
  }
  const decided = rows.filter((r) => r.within != null);
  const beyond = decided.filter((r) => !r.within);
  const fmtFig = (v) => v == null ? "-" : Number(v).toPrecision(4);
  table.innerHTML = `<tr><th>figure</th><th>now</th><th>reference</th><th>now - reference</th><th></th></tr>` +
    rows.map((r) => `<tr data-key="${r.key}" class="${r.within === false ? "beyond" : ""}"><td>${r.label}</td>` +
      `<td>${fmtFig(r.now)}</td><td>${fmtFig(r.reference)}</td><td class="diff">${r.text}</td>` +
      `<td class="verdict">${r.within == null ? (r.difference ? "error unknown" : "") : r.within ? "within the noise" : "beyond the noise"}</td></tr>`).join("");
  verdict.textContent = !decided.length ? "" : !beyond.length
    ? `Every difference is within the noise (${NOISE_SIGMAS} combined standard errors): this cannot tell the two apart yet.`
    : `${beyond.length} of ${decided.length} differences beyond the noise (${NOISE_SIGMAS} combined standard errors): ` +
      beyond.map((r) => r.label).join(", ") + ".";
  LT.comparison = { reference: ref.label, kind: ref.kind, scale: ref.scale, rows };
}

function redrawComparison() {
  if (!LT.preview) { drawComparison(); return; }
  drawMap();
  drawPolar();
  drawComparison();
}

function setReference(ref) {
  LT.reference = ref;
  document.getElementById("compare-problem").textContent = "";
  if (!ref) {
    document.getElementById("revision-select").value = "";
    document.getElementById("target-file").value = "";
  }
  redrawComparison();
  if (typeof showFitTarget !== "undefined") showFitTarget();
}

async function refreshRevisions() {
  try {
    const { revisions } = await getJSON("/revisions");
    const sel = document.getElementById("revision-select");
    const keep = sel.value;
    sel.innerHTML = `<option value="">(a kept revision)</option>` + revisions.map((r) =>
      `<option value="${r.revision}">revision ${r.revision} · ${fmtInt(r.photons)} photons` +
      (r.photometry_error != null ? ` · files ${pctShort(r.photometry_error)}` : "") + `</option>`).join("");
    if (revisions.some((r) => String(r.revision) === keep)) sel.value = keep;
    LT.revisions = revisions;
  } catch (e) { /* none kept yet */ }
}

document.getElementById("pin").addEventListener("click", () => {
  if (!LT.preview) return;
  const n = LT.preview.header.revision;
  setReference({ kind: "revision", revision: n, frame: LT.preview });
  refreshRevisions().then(() => { document.getElementById("revision-select").value = String(n); });
});

document.getElementById("revision-select").addEventListener("change", async (e) => {
  const n = e.target.value;
  if (n === "") return;
  try {
    const frame = await getFrame(`/revisions/${n}/preview`);
    if (frame) setReference({ kind: "revision", revision: Number(n), frame });
  } catch (err) {
    document.getElementById("compare-problem").textContent = err.message;
  }
});

// A file's text: UTF-8 where it is, else Latin-1 (EULUMDAT files often are).
async function fileText(file) {
  const bytes = await file.arrayBuffer();
  try { return new TextDecoder("utf-8", { fatal: true }).decode(bytes); } catch (e) {
    return new TextDecoder("latin1").decode(bytes);
  }
}

async function loadTarget(name, text) {
  const problem = document.getElementById("compare-problem");
  problem.textContent = "";
  const r = await request("/reference", { method: "POST", json: { name, text } });
  if (!r.ok) {
    let why = r.statusText;
    try { why = (await r.json()).error || why; } catch (e) { /* not JSON */ }
    problem.textContent = why;
    return false;
  }
  setReference({ kind: "file", name, text, frame: readFrame(await r.arrayBuffer()) });
  return true;
}

document.getElementById("target-file").addEventListener("change", async (e) => {
  const file = e.target.files[0];
  if (file) await loadTarget(file.name, await fileText(file));
});

document.getElementById("unpin").addEventListener("click", () => setReference(null));
