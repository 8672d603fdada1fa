// backlash-rig control page: plain JS, no build step. Talks to the API of rig/web (REST for
// commands and history, server-sent events on /api/live for live data).
"use strict";

const $ = (id) => document.getElementById(id);
const MAX_POINTS = 20000;          // display points kept for the live loop
const STATUS_POLL_MS = 1000;

// ---------------------------------------------------------------- token (operator / viewer)
(function takeTokenFromFragment() {
  const m = location.hash.match(/token=([^&]+)/);
  if (m) {
    sessionStorage.setItem("rigToken", decodeURIComponent(m[1]));
    history.replaceState(null, "", location.pathname + location.search);
  }
})();
const token = () => sessionStorage.getItem("rigToken") || "";

async function api(method, path, body) {
  const headers = {};
  if (token()) headers["Authorization"] = "Bearer " + token();
  if (body !== undefined) headers["Content-Type"] = "application/json";
  const res = await fetch(path, { method, headers,
    body: body === undefined ? undefined : JSON.stringify(body) });
  let data = null;
  try { data = await res.json(); } catch (e) { data = null; }
  if (!res.ok) {
    let msg = res.status + " " + res.statusText;
    if (data && typeof data.detail === "string") msg = data.detail;
    else if (data && Array.isArray(data.detail))
      msg = data.detail.map((d) => d.loc.slice(1).join(".") + ": " + d.msg).join("; ");
    throw new Error(msg);
  }
  return data;
}

let noticeTimer = null;
function notice(text, isError) {   // an answer to the last command; errors stay until the next
  const el = $("notice");
  el.textContent = text;
  el.className = "notice" + (isError ? " error" : "");
  el.hidden = !text;
  clearTimeout(noticeTimer);
  if (!isError) noticeTimer = setTimeout(() => { el.hidden = true; }, 8000);
}

const fmt = (v, digits = 3) => (v === null || v === undefined || !isFinite(v)) ? "–"
  : Number(v).toFixed(digits);

// ---------------------------------------------------------------- the loop plot (uPlot)
const live = { T: [], W: [], runId: null, model: null, bandNm: null, stored: null };
window.rigStats = { latency_s: [], latency_oldest_s: [], batches: 0, points: 0, drawn: 0 };

function bandHook(u) {
  const b = live.bandNm;
  if (!b) return;
  const x0 = u.valToPos(-b, "x", true), x1 = u.valToPos(b, "x", true);
  const ctx = u.ctx;
  ctx.save();
  ctx.fillStyle = "rgba(120,120,120,0.12)";
  ctx.fillRect(Math.min(x0, x1), u.bbox.top, Math.abs(x1 - x0), u.bbox.height);
  ctx.restore();
}

function makePlot() {
  const el = $("loop-plot");
  const width = Math.max(400, el.clientWidth || 800);
  const opts = {
    mode: 2, width, height: 420,
    title: "",
    scales: { x: { time: false }, y: {} },
    axes: [{ label: "output torque T (N·m)" }, { label: "output twist (arcmin, centred)" }],
    legend: { show: true, live: false },
    cursor: { drag: { x: true, y: true } },
    series: [
      {},
      { label: "measured", stroke: "#1f5fbf", width: 1.2, paths: uPlot.paths.linear(),
        points: { show: false }, facets: [{ scale: "x", auto: true }, { scale: "y", auto: true }] },
      { label: "model", stroke: "#222", width: 1.2, dash: [6, 4], paths: uPlot.paths.linear(),
        points: { show: false }, facets: [{ scale: "x", auto: true }, { scale: "y", auto: true }] },
    ],
    hooks: { drawClear: [bandHook] },
  };
  return new uPlot(opts, [null, [[], []], [[], []]], el);
}
let plot = null;

function centred(W) {
  let lo = Infinity, hi = -Infinity;
  for (const w of W) { if (w < lo) lo = w; if (w > hi) hi = w; }
  const c = isFinite(lo) ? 0.5 * (lo + hi) : 0;
  return W.map((w) => w - c);
}

function modelPolyline() {
  const m = live.model;
  if (!m || !m.stiffness_Nm_per_arcmin || !live.amplitudeNm)
    return [[], []];
  const A = live.amplitudeNm, p = m.play_arcmin || 0, K = m.stiffness_Nm_per_arcmin;
  return [[-A, 0, 0, A], [-p / 2 - A / K, -p / 2, p / 2, p / 2 + A / K]];
}

// Batches waiting to be drawn: [wall time of the newest sample, of the oldest] (s).
let drawPending = null;
let pendingStamps = [];
function scheduleDraw(tWall, tWallOldest) {
  if (tWall !== undefined) pendingStamps.push([tWall, tWallOldest]);
  if (drawPending === null) { drawPending = true; requestAnimationFrame(drawNow); }
}
function drawNow() {
  drawPending = null;
  const stamps = pendingStamps;
  pendingStamps = [];
  const src = live.stored || { T: live.T, W: centred(live.W), M: null };
  const model = src.M ? [src.T, src.M] : modelPolyline();
  plot.setData([null, [src.T, src.W], model]);
  window.rigStats.drawn = src.T.length;
  const now = Date.now() / 1000;
  for (const [newest, oldest] of stamps) {   // measured -> drawn, per batch
    const a = window.rigStats.latency_s, b = window.rigStats.latency_oldest_s;
    a.push(now - newest); b.push(now - oldest);
    if (a.length > 5000) { a.shift(); b.shift(); }
  }
}

function addRows(msg) {
  if (msg.run_id && msg.run_id !== live.runId) { live.T = []; live.W = []; live.runId = msg.run_id; }
  live.stored = null;
  for (let i = 0; i < msg.torque_Nm.length; i++) {
    if (msg.torque_Nm[i] === null || msg.twist_arcmin[i] === null) continue;
    live.T.push(msg.torque_Nm[i]);
    live.W.push(msg.twist_arcmin[i]);
  }
  if (live.T.length > MAX_POINTS) {
    live.T.splice(0, live.T.length - MAX_POINTS);
    live.W.splice(0, live.W.length - MAX_POINTS);
  }
  window.rigStats.batches += 1;
  window.rigStats.points = live.T.length;
  $("loop-title").textContent = live.runId ? "live: " + live.runId : "";
  if (msg.type === "rows" && msg.t_s.length) {
    const span = msg.t_s[msg.t_s.length - 1] - msg.t_s[0];
    scheduleDraw(msg.t_wall_s, msg.t_wall_s - span);
  } else scheduleDraw();
}

function showMetrics(m, model) {
  $("m-lost").textContent = fmt(m && m.lost_motion_arcmin);
  $("m-backlash").textContent = fmt(m && m.backlash_arcmin);
  $("m-stiffness").textContent = fmt(m && m.stiffness_Nm_per_arcmin, 2);
  const mm = (m && m.model) || model;
  $("m-model").textContent = fmt(mm && mm.lost_motion_arcmin);
}

// ---------------------------------------------------------------- campaign: lost motion vs position
let campaignPlot = null;
function showCampaign(title, summary) {
  const pts = (summary && summary.lost_motion_by_position) || [];
  const box = $("campaign-box");
  box.hidden = pts.length === 0;
  if (!pts.length) return;
  $("campaign-title").textContent = title;
  const x = pts.map((p) => p.input_angle_deg);
  const y = pts.map((p) => p.lost_motion_arcmin);
  // the runout signature (seed 000 eq. 4): mean + amplitude cos(theta - phase), over one turn
  const sig = summary.runout_signature;
  const xs = [], fit = [], meas = [];
  const grid = new Set(x);
  for (let a = 0; a <= 360; a += 5) grid.add(a);
  for (const a of [...grid].sort((p, q) => p - q)) {
    xs.push(a);
    const i = x.indexOf(a);
    meas.push(i >= 0 ? y[i] : null);
    fit.push(sig ? sig.mean + sig.amplitude * Math.cos((a - sig.phase_deg) * Math.PI / 180) : null);
  }
  // where a production batch of this design lies (seed 000 tolerances, worst position, 95 %)
  const band = (summary.batch && summary.batch.band_95_arcmin) || null;
  const low = xs.map(() => (band ? band[0] : null));
  const high = xs.map(() => (band ? band[1] : null));
  const data = [xs, meas, fit, low, high];
  if (!campaignPlot) {
    campaignPlot = new uPlot({
      width: Math.max(400, $("loop-plot").clientWidth || 800), height: 240,
      scales: { x: { time: false } },
      axes: [{ label: "input angle (deg)" }, { label: "lost motion (arcmin)" }],
      series: [{}, { label: "measured", stroke: "#1f5fbf", paths: () => null,
                     points: { show: true, size: 9, fill: "#1f5fbf" } },
               { label: "runout signature", stroke: "#c62828", dash: [6, 4], points: { show: false } },
               { label: "batch 2.5 %", stroke: "#888", dash: [2, 3], points: { show: false } },
               { label: "batch 97.5 %", stroke: "#888", dash: [2, 3], points: { show: false } }],
    }, data, $("campaign-plot"));
  } else campaignPlot.setData(data);
}

// ---------------------------------------------------------------- status
let lastStatus = null;
function renderStatus(s) {
  lastStatus = s;
  const st = $("state");
  st.textContent = s.state.replace("_", " ");
  st.className = "badge " + s.state;
  $("rig-name").textContent = s.rig || "";
  const role = $("role");
  role.textContent = s.operator ? "operator" : "viewer";
  role.className = "badge " + (s.operator ? "operator" : "viewer");
  $("token-clear").hidden = !token();
  $("token").hidden = s.operator; $("token-set").hidden = s.operator;
  const tbody = $("devices").querySelector("tbody");
  tbody.innerHTML = "";
  for (const d of s.devices) {
    const tr = document.createElement("tr");
    const hb = d.heartbeat_age_s === null || d.heartbeat_age_s === undefined ? ""
      : (d.heartbeat_age_s * 1000).toFixed(0) + " ms";
    tr.innerHTML = `<td><span class="dot ${d.ok ? "ok" : "bad"}"></span></td><td></td><td>${hb}</td><td></td>`;
    tr.children[1].textContent = d.name;
    tr.children[3].textContent = d.detail;
    tbody.appendChild(tr);
  }
  const v = s.live || {};
  $("v-twist").textContent = fmt(v.twist_arcmin, 2);
  $("v-torque").textContent = fmt(v.torque_Nm, 3);
  $("v-temp").textContent = fmt(v.temperature_C, 1);
  $("v-setpoint").textContent = fmt(v.setpoint_Nm, 3);
  $("v-drive").textContent = v.drive_enabled === undefined || v.drive_enabled === null ? "–"
    : (v.drive_enabled ? "enabled" : "disabled");
  $("v-safe").textContent = s.safe === null ? "–" : (s.safe ? "yes" : "no");
  $("v-safe").className = "num " + (s.safe ? "pass" : "");
  const lock = s.input_lock;
  $("lock-state").textContent = lock.confirmed
    ? "confirmed" + (lock.angle_deg !== null ? " at " + fmt(lock.angle_deg, 2) + " deg" : "")
    : "not confirmed";
  // progress
  const p = s.progress;
  const busy = ["running", "paused", "stopping"].includes(s.state);
  if (p && busy) {
    const frac = p.n_steps ? Math.min(1, p.step / p.n_steps) : 0;
    $("progress-bar").style.width = (100 * frac).toFixed(1) + "%";
    $("progress-text").textContent = `step ${p.step + 1} of ${p.n_steps} · about ` +
      `${Math.ceil(p.remaining_s)} s left · ${p.description || ""}`;
  } else {
    $("progress-bar").style.width = s.state === "completed" ? "100%" : "0";
    $("progress-text").textContent = s.message || s.state;
  }
  // fault: the last stop's explanation, and what is latched now (reset by the operator)
  const latched = s.faults || [];
  const f = s.fault || (latched.length ? {
    title: "A fault is latched: nothing can start",
    action: "Remove its cause, then press Reset faults.",
    detail: "" } : null);
  $("fault").hidden = !f;
  if (f) {
    $("fault-title").textContent = f.title;
    const listed = latched.map((x) => x.device + ": " + x.detail).join("\n");
    $("fault-action").textContent = latched.length
      ? "Latched: " + latched.map((x) => x.device).join(", ") + ". Remove the cause, then press Reset faults."
      : f.action;
    $("fault-detail").textContent = [f.detail, listed].filter(Boolean).join("\n");
  }
  $("reset-faults").hidden = !latched.length;
  // buttons
  const op = s.operator;
  const connected = s.state !== "no_rig" && s.state !== "starting";
  const faulted = latched.length > 0;
  $("start").disabled = !op || busy || !connected || !lock.confirmed || faulted;
  $("start").title = faulted ? "a fault is latched: Reset faults first" : "";
  $("preview").disabled = busy || faulted;
  $("reset-faults").disabled = !op || busy;
  $("pause").disabled = !op || s.state !== "running";
  $("resume").disabled = !op || s.state !== "paused";
  $("abort").disabled = !op || !busy;
  $("tare").disabled = !op || busy || !connected;
  $("lock").disabled = !op || busy || !connected;
  // a stored run drawn from the history keeps its own numbers beside it
  if (s.last_result && !busy && !live.stored) renderResult(s.last_result);
}

const OUTCOME_WORDS = { ok: "OK", not_ok: "NOT OK", incomplete: "INCOMPLETE" };
function outcomeHtml(outcome) {
  if (!outcome) return '<span class="muted">–</span>';
  const cls = outcome === "ok" ? "pass" : outcome === "not_ok" ? "fail" : "incomplete";
  return `<span class="${cls}">${OUTCOME_WORDS[outcome] || esc(outcome)}</span>`;
}

function renderResult(r) {
  const el = $("result");
  const verdict = outcomeHtml(r.outcome || (r.passed ? "ok" : "not_ok"));
  $("m-verdict").innerHTML = verdict;
  let html = `${r.kind} ${r.status}: ${verdict}`;
  if (r.failures && r.failures.length) html += "<br>" + r.failures.map(esc).join("<br>");
  if (r.lost_motion_by_position && r.lost_motion_by_position.length) {
    html += "<br>lost motion against position: " + r.lost_motion_by_position
      .map((x) => `${fmt(x.input_angle_deg, 0)}°: ${fmt(x.lost_motion_arcmin)}`).join(", ");
  }
  const band = r.batch && r.batch.band_95_arcmin;
  if (band) {
    html += `<br>production batch of this design (seed 000 tolerances, 95 %): ` +
      `${fmt(band[0])} .. ${fmt(band[1])} arcmin`;
  }
  el.innerHTML = html;
  if (r.kind === "campaign") showCampaign(r.campaign_id || "", r);
  const last = r.runs && r.runs.length ? r.runs[r.runs.length - 1] : null;
  if (last && last.status === "completed") showMetrics(last, null);
}

function esc(text) {
  const d = document.createElement("div");
  d.textContent = String(text);
  return d.innerHTML;
}

let statusBusy = false;
async function refreshStatus() {
  if (statusBusy) return;
  statusBusy = true;
  try { renderStatus(await api("GET", "/api/status")); }
  catch (e) { $("state").textContent = "page offline"; $("state").className = "badge aborted"; }
  finally { statusBusy = false; }
}

// ---------------------------------------------------------------- live stream
function connectLive() {
  const es = new EventSource("/api/live");
  es.addEventListener("rows", (e) => addRows(JSON.parse(e.data)));
  es.addEventListener("rows_replay", (e) => addRows(JSON.parse(e.data)));
  es.addEventListener("run_begin", (e) => {
    const m = JSON.parse(e.data);
    live.T = []; live.W = []; live.runId = m.run_id; live.stored = null;
    showMetrics(null, live.model);
    scheduleDraw();
  });
  es.addEventListener("metrics", (e) => {
    const m = JSON.parse(e.data);
    if (m.run_id === live.runId) showMetrics(m.metrics, live.model);
  });
  es.addEventListener("progress", (e) => {
    const ev = JSON.parse(e.data);
    if (ev.kind === "run_finished" && ev.data) showMetrics(ev.data, live.model);
    refreshStatus();
  });
  es.addEventListener("state", () => { refreshStatus(); refreshHistory(); });
  es.addEventListener("status", () => refreshStatus());
  window.rigEvents = es;
}

// ---------------------------------------------------------------- set-up form
let units = [];
const UNIT_FIELDS = ["z_internal", "z_external", "module_mm", "pressure_angle_deg", "addendum_coeff",
  "face_width_mm", "center_distance_mm", "m_value_internal_mm", "m_value_external_mm",
  "runout_internal_mm", "runout_external_mm"];

function fillUnit(u) {
  const f = $("setup");
  for (const k of UNIT_FIELDS) {
    const v = u[k];
    f.elements[k].value = v === undefined || v === null ? "" : (Array.isArray(v) ? v.join(", ") : v);
  }
  live.unitExtra = { clearance_coeff: u.clearance_coeff, pin_diameter_mm: u.pin_diameter_mm,
    bearing_clearance_mm: u.bearing_clearance_mm };
}

const num = (v) => (v === "" || v === undefined ? null : Number(v));
const list = (v) => (v.trim() === "" ? null : v.split(/[,\s]+/).filter((x) => x).map(Number));

function request() {
  const f = $("setup").elements;
  const unit = { kind: "internal_involute", serial: f.serial.value || null };
  for (const k of UNIT_FIELDS) {
    const v = f[k].value;
    unit[k] = k.startsWith("m_value") ? list(v) : num(v);
  }
  Object.assign(unit, live.unitExtra || {});
  for (const k of Object.keys(unit)) if (unit[k] === null || unit[k] === undefined) delete unit[k];
  const kind = f.kind.value;
  const body = {
    kind, unit,
    plan: { rated_torque_Nm: num(f.rated_torque_Nm.value), amplitude_pct: num(f.amplitude_pct.value),
      mode: f.mode.value, rate_Nm_per_s: num(f.rate_Nm_per_s.value), cycles: num(f.cycles.value),
      pre_cycles: num(f.pre_cycles.value), steps_per_quarter: num(f.steps_per_quarter.value),
      dwell_s: num(f.dwell_s.value), extra_levels_pct: list(f.extra_levels_pct.value) || [],
      zero_band_Nm: num(f.zero_band_Nm.value) || 0, zero_rate_Nm_per_s: num(f.zero_rate_Nm_per_s.value) },
    limits: { lost_motion_arcmin_max: num(f.lost_motion_arcmin_max.value) },
    torque_limit_Nm: num(f.torque_limit_Nm.value),
    operator: f.operator.value || null,
  };
  if (kind === "campaign") {
    body.name = f.name.value || "web";
    body.axes = { positions_deg: list(f.positions_deg.value) || [0], repeats: num(f.repeats.value) || 1 };
  }
  return body;
}

async function previewPlan() {
  const body = request();
  const p = await api("POST", "/api/plan/preview", body);
  live.model = p.model;
  live.amplitudeNm = p.amplitude_Nm;
  live.bandNm = p.model ? p.model.lost_motion_pct / 100 * body.plan.rated_torque_Nm : null;
  const mins = (p.estimated_s / 60).toFixed(1);
  let html = `<b>${esc(p.name)}</b>: ${p.n_steps} steps, ${p.n_runs} run(s), about ` +
    `${Math.round(p.estimated_s)} s (${mins} min); amplitude ${fmt(p.amplitude_Nm, 2)} N·m` +
    (p.torque_limit_Nm !== null ? `, rig limit ±${fmt(p.torque_limit_Nm, 2)} N·m` : "") +
    (p.fits ? ' <span class="pass">fits the rig</span>' : ' <span class="fail">does not fit</span>');
  if (p.problems.length) html += "<br>" + p.problems.map(esc).join("<br>");
  if (p.model) html += `<br>model: lost motion ${fmt(p.model.lost_motion_arcmin)} arcmin, ` +
    `backlash ${fmt(p.model.backlash_arcmin)} arcmin, stiffness ${fmt(p.model.stiffness_Nm_per_arcmin, 2)} N·m/arcmin`;
  html += `<details><summary>steps</summary><pre>${esc(p.steps.join("\n"))}` +
    `${p.truncated ? "\n…" : ""}</pre></details>`;
  $("preview-out").innerHTML = html;
  showMetrics(null, live.model);
  scheduleDraw();
  return p;
}

function operatorName() {
  const v = $("setup").elements.operator.value.trim();
  return v ? v.slice(0, 80) : null;
}

async function run(action, fn) {
  try { const r = await fn(); if (r && r.message) notice(r.message, false); }
  catch (e) { notice(action + ": " + e.message, true); }
  refreshStatus();
}

// ---------------------------------------------------------------- history
async function refreshHistory() {
  try {
    const [runs, camps] = await Promise.all([api("GET", "/api/runs?limit=50"), api("GET", "/api/campaigns")]);
    const tb = $("runs").querySelector("tbody");
    tb.innerHTML = "";
    for (const r of runs) {
      const tr = document.createElement("tr");
      const lm = r.metrics ? fmt(r.metrics.lost_motion_arcmin) : "–";
      const id = encodeURIComponent(r.run_id);
      tr.innerHTML = `<td><a href="#" data-run="${esc(r.run_id)}">${esc(r.run_id)}</a></td>` +
        `<td>${esc(r.status)}${r.reason ? ": " + esc(r.reason) : ""}</td><td>${esc(r.unit_serial || "")}</td>` +
        `<td>${esc(r.started_at)}</td><td>${lm}</td>` +
        `<td><a href="/api/runs/${id}/run.zip">zip</a> · <a href="/api/runs/${id}/samples.csv">csv</a> · ` +
        `<a href="/api/runs/${id}/loop.png">png</a> · <a href="/api/runs/${id}/certificate.pdf">Certificate</a></td>`;
      tb.appendChild(tr);
    }
    const cb = $("campaigns").querySelector("tbody");
    cb.innerHTML = "";
    for (const c of camps) {
      const s = c.summary || {};
      const id = encodeURIComponent(c.campaign_id);
      const verdict = s.passed === undefined ? "" : (s.passed ? '<span class="pass">PASS</span>'
        : '<span class="fail">FAIL</span> ' + esc((s.failures || []).slice(0, 3).join("; ")));
      const byPos = (s.lost_motion_by_position || [])
        .map((x) => `${fmt(x.input_angle_deg, 0)}°: ${fmt(x.lost_motion_arcmin)}`).join(", ");
      const tr = document.createElement("tr");
      tr.innerHTML = `<td><a href="#" data-campaign="${esc(c.campaign_id)}">${esc(c.campaign_id)}</a></td><td>${esc(c.status)}</td><td>${verdict}</td>` +
        `<td>${byPos}</td><td><a href="/api/campaigns/${id}/diagnosis.html" target="_blank">diagnosis</a>` +
        ` · <a href="/api/campaigns/${id}/diagnosis.html" download="${esc(c.campaign_id)}-diagnosis.html">html</a>` +
        ` · <a href="/api/campaigns/${id}/diagnosis.json" download>json</a>` +
        ` · <a href="/api/campaigns/${id}/certificate.pdf">Certificate</a></td>`;
      cb.appendChild(tr);
    }
  } catch (e) { notice("history: " + e.message, true); }
}

async function showStoredRun(runId) {
  const d = await api("GET", `/api/runs/${encodeURIComponent(runId)}/loop?max_points=5000`);
  live.stored = { T: d.torque_Nm, W: d.twist_arcmin, M: d.model_twist_arcmin };
  live.bandNm = d.band_Nm;
  $("loop-title").textContent = "stored: " + runId + (d.analysis_error ? " (" + d.analysis_error + ")" : "");
  showMetrics(d.metrics, null);
  $("m-verdict").innerHTML = outcomeHtml(d.outcome);
  $("result").innerHTML = `stored run ${esc(runId)} ${esc(d.status || "")}: ${outcomeHtml(d.outcome)}`;
  scheduleDraw();
}

// ---------------------------------------------------------------- wiring
function wire() {
  $("estop").addEventListener("click", () => run("E-stop", () => api("POST", "/api/control/estop")));
  $("token-set").addEventListener("click", () => {
    sessionStorage.setItem("rigToken", $("token").value.trim());
    $("token").value = "";
    refreshStatus();
  });
  $("token-clear").addEventListener("click", () => { sessionStorage.removeItem("rigToken"); refreshStatus(); });
  $("tare").addEventListener("click", () => run("tare", () => api("POST", "/api/devices/tare")));
  $("reset-faults").addEventListener("click", () => run("reset faults", () =>
    api("POST", "/api/devices/reset-faults", { operator: operatorName() })));
  $("lock").addEventListener("click", () => run("input lock", () => {
    const a = num($("lock-angle").value);
    return api("POST", "/api/devices/input-lock", a === null ? { confirm: true } : { angle_deg: a, confirm: true });
  }));
  $("preview").addEventListener("click", () => run("preview", previewPlan));
  $("start").addEventListener("click", () => run("start", async () => {
    await previewPlan();
    live.T = []; live.W = []; live.stored = null;
    return api("POST", "/api/control/start", request());
  }));
  $("pause").addEventListener("click", () => run("pause", () => api("POST", "/api/control/pause")));
  $("resume").addEventListener("click", () => run("resume", () => api("POST", "/api/control/resume")));
  $("abort").addEventListener("click", () => run("abort", () => api("POST", "/api/control/abort")));
  $("refresh").addEventListener("click", refreshHistory);
  $("setup").elements.kind.addEventListener("change", (e) => {
    $("setup").className = e.target.value === "campaign" ? "campaign" : "";
  });
  $("unit-example").addEventListener("change", (e) => {
    const u = units.find((x) => x.name === e.target.value);
    if (u) fillUnit(u.unit);
  });
  $("campaigns").addEventListener("click", async (e) => {
    const a = e.target.closest("a[data-campaign]");
    if (!a) return;
    e.preventDefault();
    try {
      const c = await api("GET", `/api/campaigns/${encodeURIComponent(a.dataset.campaign)}`);
      showCampaign(c.campaign_id, c.summary);
    } catch (err) { notice(err.message, true); }
  });
  $("runs").addEventListener("click", (e) => {
    const a = e.target.closest("a[data-run]");
    if (a) { e.preventDefault(); showStoredRun(a.dataset.run).catch((err) => notice(err.message, true)); }
  });
  window.addEventListener("resize", () => plot.setSize({ width: $("loop-plot").clientWidth, height: 420 }));
}

async function init() {
  plot = makePlot();
  window.rigPage = { plot, live, scheduleDraw, addRows };
  wire();
  try {
    units = await api("GET", "/api/units");
    const sel = $("unit-example");
    for (const u of units) {
      const o = document.createElement("option");
      o.value = u.name; o.textContent = u.name;
      sel.appendChild(o);
    }
    if (units.length) fillUnit(units[0].unit);
  } catch (e) { notice("units: " + e.message, true); }
  connectLive();
  await refreshStatus();
  refreshHistory();
  setInterval(refreshStatus, STATUS_POLL_MS);
  previewPlan().catch(() => {});
}

init();
