// lumitrace live view: a fit started from the page. The target is the reference in
// Compare (a loaded file, or a pinned revision); the parameters are ticked beside the Editor's fields (their ranges the
// schema's) or typed as `lumitrace fit --vary` spells them. The service runs the fit in a
// process of its own and tells each generation as a "fit" event: the merit with its
// standard error against evaluations, and the best's polar curves against the target's.
// "Apply best" sends the confirmed best to the session as one delta: a revision like any,
// which the Editor's Undo takes back.

const fitParameters = new Map();  // --vary name -> { lo, hi }

function addFitParameter(name, lo, hi) {
  fitParameters.set(name, { lo, hi });
  drawFitParameters();
}

function removeFitParameter(name) {
  fitParameters.delete(name);
  document.querySelectorAll("[data-vary]").forEach((box) => {
    if (box.dataset.vary === name) box.checked = false;
  });
  drawFitParameters();
}

function drawFitParameters() {
  const table = document.getElementById("fit-params");
  const best = (LT.fit && LT.fit.best) || {};
  const rows = [...fitParameters.entries()].map(([name, r]) => {
    const b = best[name];
    return `<tr data-name="${esc(name)}"><td class="name">${esc(name)}</td>` +
      `<td><input type="number" step="any" data-end="lo" value="${r.lo ?? ""}" placeholder="schema's"></td>` +
      `<td><input type="number" step="any" data-end="hi" value="${r.hi ?? ""}" placeholder="schema's"></td>` +
      `<td class="best">${b == null ? "-" : esc(typeof b === "number" ? round(b) : b)}</td>` +
      `<td><button type="button" data-remove>remove</button></td></tr>`;
  });
  table.innerHTML = `<tr><th>parameter</th><th>from</th><th>to</th><th>best</th><th></th></tr>` + rows.join("");
  table.querySelectorAll("tr[data-name]").forEach((tr) => {
    const name = tr.dataset.name;
    tr.querySelectorAll("[data-end]").forEach((input) => input.addEventListener("change", () => {
      const v = Number(input.value), range = fitParameters.get(name);
      if (input.value.trim() === "") range[input.dataset.end] = null;  // the schema's
      else if (Number.isFinite(v)) range[input.dataset.end] = v;
      else input.value = range[input.dataset.end] ?? "";
    }));
    tr.querySelector("[data-remove]").addEventListener("click", () => removeFitParameter(name));
  });
}

// The reference in Compare, as the fit's target: a loaded file, or a pinned revision
// (the service writes its kept preview as the target file).
function fitTarget() {
  const ref = LT.reference;
  if (ref && ref.kind === "file" && ref.text) return { label: ref.name, body: { name: ref.name, text: ref.text } };
  if (ref && ref.kind === "revision") return { label: `revision ${ref.revision} (pinned)`, body: { revision: ref.revision } };
  return null;
}

function showFitTarget() {
  const t = fitTarget();
  document.getElementById("fit-target").textContent = t ? `target: ${t.label}`
    : "target: pin a revision or load a target IES or LDT file in Compare";
}

async function refreshFit() {
  try {
    LT.fit = await getJSON("/fit");
  } catch (err) {
    return;
  }
  drawFit();
}

function drawFit() {
  const s = LT.fit;
  if (!s) return;
  const running = ["starting", "running", "stopping"].includes(s.state);
  document.getElementById("fit-start").disabled = running;
  document.getElementById("fit-stop").disabled = !running || s.state === "stopping";
  document.getElementById("fit-apply").disabled = !s.can_apply || s.applied != null;
  const last = s.history.length ? s.history[s.history.length - 1] : null;
  let text = s.state === "idle" ? "no fit yet" : `fit ${s.fit}: ${s.state}`;
  if (last) text += ` · ${fmtInt(last.evaluations)} evaluations in ${last.seconds.toFixed(1)} s · best merit ${fmt(last.merit)} ± ${fmt(last.merit_error)} at ${fmtInt(last.photons)} photons`;
  if (s.summary) text += ` · confirmed: merit ${fmt(s.summary.merit)} ± ${fmt(s.summary.merit_error)} (${fmtInt(s.summary.final_photons)} photons, another seed)`;
  if (s.applied != null) text += ` · applied as revision ${s.applied}`;
  if (s.error) text += ` · ${s.error}`;
  document.getElementById("fit-state").textContent = text;
  drawFitParameters();
  // the plots once there is something to draw: a fit's first generation
  document.querySelector("#fit-panel .fit-plots").hidden = !s.history.length && !s.curves;
  drawMeritCurve(s.history);
  drawFitPolar(s.curves);
}

// The best merit of each generation (with its standard error) against evaluations.
function drawMeritCurve(history) {
  const svg = document.getElementById("fit-merit");
  const W = 420, H = 240, L = 52, B = 30, T = 14, Rm = 12;
  if (!history.length) { svg.innerHTML = `<text x="${L}" y="${H / 2}" font-size="12" fill="#777">the merit appears after the first generation</text>`; return; }
  const xs = history.map((h) => h.evaluations), hi = history.map((h) => h.merit + h.merit_error);
  const x1 = Math.max(...xs, 1), y1 = Math.max(...hi) * 1.05 || 1;
  const X = (x) => L + (W - L - Rm) * x / x1, Y = (y) => H - B - (H - B - T) * Math.max(y, 0) / y1;
  let out = `<line x1="${L}" y1="${H - B}" x2="${W - Rm}" y2="${H - B}" stroke="#999"/><line x1="${L}" y1="${T}" x2="${L}" y2="${H - B}" stroke="#999"/>`;
  for (const t of niceTicks(y1, 4)) out += `<text x="${L - 4}" y="${Y(t) + 4}" font-size="10" text-anchor="end">${fmt(t)}</text><line x1="${L}" x2="${W - Rm}" y1="${Y(t)}" y2="${Y(t)}" stroke="#eee"/>`;
  for (const t of niceTicks(x1, 4)) out += `<text x="${X(t)}" y="${H - B + 14}" font-size="10" text-anchor="middle">${fmtInt(t)}</text>`;
  out += `<text x="${(L + W) / 2}" y="${H - 2}" font-size="11" text-anchor="middle">evaluations</text>`;
  out += `<text x="12" y="${(T + H - B) / 2}" font-size="11" text-anchor="middle" transform="rotate(-90 12 ${(T + H - B) / 2})">each generation's best merit ± 1 SE</text>`;
  for (const h of history) out += `<line x1="${X(h.evaluations)}" x2="${X(h.evaluations)}" y1="${Y(h.merit - h.merit_error)}" y2="${Y(h.merit + h.merit_error)}" stroke="#d95f02"/>`;
  out += `<polyline fill="none" stroke="#d95f02" stroke-width="1.5" points="${history.map((h) => `${X(h.evaluations)},${Y(h.merit)}`).join(" ")}"/>`;
  svg.innerHTML = out;
}

// The best's curves (orange) and the target's (black), C0-C180 solid and C90-C270
// dashed, in cd/klm of each one's own flux: nadir at the bottom, as the Polar panel.
function drawFitPolar(curves) {
  const svg = document.getElementById("fit-polar");
  if (!curves) { svg.innerHTML = `<text x="-150" y="0" font-size="12" fill="#777">the best's curves appear after the first generation</text>`; return; }
  let max = 0;
  for (const p of Object.values(curves.planes)) for (const v of [...p.best, ...p.target]) max = Math.max(max, v);
  const R = POLAR_R, k = max > 0 ? R / max : 1, g = curves.gamma.map((a) => a * Math.PI / 180);
  const path = (vals) => vals.map((v, i) => `${i ? "L" : "M"}${(v * k * Math.sin(g[i])).toFixed(2)},${(v * k * Math.cos(g[i])).toFixed(2)}`).join("");
  let out = "";
  for (const t of niceTicks(max, 4)) out += `<circle r="${t * k}" fill="none" stroke="#eee"/><text x="2" y="${-t * k - 2}" font-size="9" fill="#777">${fmt(t)}</text>`;
  out += `<line x1="${-R}" x2="${R}" y1="0" y2="0" stroke="#ddd"/><line y1="${-R}" y2="${R}" x1="0" x2="0" stroke="#ddd"/>`;
  for (const [c, p] of Object.entries(curves.planes)) {
    const dash = c === "0" ? "" : 'stroke-dasharray="4,3"';
    out += `<path class="target" data-plane="${c}" d="${path(p.target)}" fill="none" stroke="#222" stroke-width="1.1" ${dash}/>`;
    out += `<path class="best" data-plane="${c}" d="${path(p.best)}" fill="none" stroke="#d95f02" stroke-width="1.6" ${dash}/>`;
  }
  out += `<text x="${-R - 30}" y="${R + 22}" font-size="11">cd/klm · orange: the best so far · black: the target · dashed: C90-C270</text>`;
  svg.innerHTML = out;
}

function fitProblem(text) { document.getElementById("fit-problem").textContent = text || ""; }

document.getElementById("fit-add-button").addEventListener("click", () => {
  const input = document.getElementById("fit-add");
  const text = input.value.trim();
  const m = /^(.+?)(?:=(-?[\d.eE+-]+):(-?[\d.eE+-]+))?$/.exec(text);
  if (!text || !text.startsWith("/") || !text.includes(".")) { fitProblem("give a parameter as /PRIM/PATH.property (an element as [INDEX])"); return; }
  fitProblem("");
  addFitParameter(m[1], m[2] != null ? Number(m[2]) : null, m[3] != null ? Number(m[3]) : null);
  input.value = "";
});

document.getElementById("fit-start").addEventListener("click", async () => {
  fitProblem("");
  const target = fitTarget();
  if (!target) { fitProblem("pin a revision or load a target file in Compare first"); return; }
  if (!fitParameters.size) { fitProblem("tick a field in the Editor or add a parameter"); return; }
  const vary = [...fitParameters.entries()].map(([name, r]) =>
    r.lo == null || r.hi == null ? name : `${name}=${r.lo}:${r.hi}`);
  const evaluations = Number(document.getElementById("fit-evaluations").value);
  const photons = Number(document.getElementById("fit-photons").value);
  if (!Number.isInteger(evaluations) || !Number.isInteger(photons)) { fitProblem("evaluations and photons are whole numbers"); return; }
  const r = await postJSON("/fit", { target: target.body, vary, evaluations, photons });
  if (!r.ok) { fitProblem(r.body.error || `refused (${r.status})`); return; }
  LT.fit = r.body;
  drawFit();
});

document.getElementById("fit-stop").addEventListener("click", async () => {
  const r = await postJSON("/fit/stop", {});
  if (!r.ok) fitProblem(r.body.error || `refused (${r.status})`);
  refreshFit();
});

document.getElementById("fit-apply").addEventListener("click", async () => {
  fitProblem("");
  const r = await postJSON("/fit/apply", {});
  if (!r.ok) { fitProblem(r.body.error || `refused (${r.status})`); return; }
  LT.undo.push(r.body.inverse);  // Undo sets the parameters back to their values at the start
  document.getElementById("undo").disabled = false;
  refreshFit();
});

showFitTarget();
refreshFit();
