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
    let fields = null;
    if (data && typeof data.detail === "string") msg = data.detail;
    else if (data && Array.isArray(data.detail)) {
      fields = data.detail.map(fieldProblem);
      msg = fields.map((f) => f.text).join("; ");
    }
    if (res.status === 403) msg = "wrong operator token: this page can only watch. Log out and " +
      "log in with the token printed by rig serve";
    else if (res.status === 401) msg = "this needs the operator token: log in first";
    const err = new Error(msg);
    err.fields = fields;
    err.status = res.status;
    throw err;
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

// One name for a run wherever the page shows it, live and in History (issue 33 item 16):
// the plan's label with the run id, "pos090-a100-r0 (U-7-20261128T101500Z-1)"; the id alone
// for a run without a label
const runName = (label, id) => (label && id && label !== id ? `${label} (${id})` : label || id || "");
const runLabels = {};   // run id -> label, as the live events, the status and History name them
function rememberLabel(id, label) { if (id && label) runLabels[id] = label; }
const liveRunName = (id) => runName(runLabels[id], id);

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

const cssVar = (name) => getComputedStyle(document.documentElement).getPropertyValue(name).trim();
function axis(label) {
  const ink = cssVar("--ink") || "#1d2330", line = cssVar("--line") || "#d5d8de";
  return { label, stroke: ink, grid: { stroke: line, width: 1 }, ticks: { stroke: line, width: 1 } };
}
const plotWidth = (el) => Math.max(200, el.clientWidth || 800);

// A loop's path: every point joined in the order measured, broken at a missing value (issue
// 33 item 16). uPlot's own linear path thins points that share a pixel column assuming x
// only grows; a loop's torque goes up and down, so on a narrow plot (a phone) it drew
// vertical segments the data do not have.
function loopPath(u, seriesIdx) {
  const [xs, ys] = u.data[seriesIdx];
  const stroke = new Path2D();
  let pen = false;
  for (let i = 0; i < xs.length; i++) {
    const x = xs[i], y = ys[i];
    if (x === null || y === null || x === undefined || y === undefined || !isFinite(x) || !isFinite(y)) {
      pen = false;
      continue;
    }
    const px = u.valToPos(x, "x", true), py = u.valToPos(y, "y", true);
    if (pen) stroke.lineTo(px, py); else stroke.moveTo(px, py);
    pen = true;
  }
  const clip = new Path2D();
  clip.rect(u.bbox.left, u.bbox.top, u.bbox.width, u.bbox.height);
  return { stroke, fill: null, clip, band: null, gaps: null, flags: 0 };
}
const PLOT_HEIGHT = 400;

function makePlot() {
  const el = $("loop-plot");
  const width = plotWidth(el);
  const opts = {
    mode: 2, width, height: PLOT_HEIGHT,
    title: "",
    scales: { x: { time: false }, y: {} },
    axes: [axis("output torque T (N·m)"), axis("output twist (arcmin, centred)")],
    legend: { show: true, live: false },
    cursor: { drag: { x: true, y: true } },
    series: [
      {},
      { label: "measured", stroke: "#1f5fbf", width: 1.2, paths: loopPath,
        points: { show: false }, facets: [{ scale: "x", auto: true }, { scale: "y", auto: true }] },
      { label: "nominal model (no runout)", stroke: cssVar("--ink") || "#222", width: 1.2, dash: [6, 4], paths: loopPath,
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
  if (msg.te_arcsec) { addTERows(msg); return; }   // a TE run: its panel, never a loop
  // a loop clicked in History stays until another run is drawn: a late batch of the run
  // measured before never replaces it (issue 33 item 16)
  if (msg.run_id && msg.run_id !== live.runId) { live.T = []; live.W = []; live.runId = msg.run_id; live.stored = null; }
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
  if (!live.stored) $("loop-title").textContent = live.runId ? "live: " + liveRunName(live.runId) : "";
  if (msg.type === "rows" && msg.t_s.length) {
    const span = msg.t_s[msg.t_s.length - 1] - msg.t_s[0];
    scheduleDraw(msg.t_wall_s, msg.t_wall_s - span);
  } else scheduleDraw();
}

// Quantities that cannot be below zero: a negative figure is noise or a bad loop, never shown
// as a measurement (issue 21 item 15)
const NON_NEGATIVE = new Set(["lost_motion_arcmin", "loop_area_J"]);
const BELOW_ZERO = " below zero: no measurement";   // rig/results/outcome.py BELOW_ZERO: one wording
const measurable = (v) => v !== null && v !== undefined && isFinite(v) && Number(v) >= 0;

function withU(m, key, digits = 3) {   // ["4.304", " ± 0.001"] (the uncertainty when known)
  const v = m ? m[key] : null;
  if (v === null || v === undefined || !isFinite(v)) {
    // a metric the analysis could not measure says why (analysis.loop's errors)
    const why = m && m.errors ? m.errors[key] : null;
    return ["–", why ? " (not measured: " + why + ")" : ""];
  }
  if (NON_NEGATIVE.has(key) && v < 0) return ["–", BELOW_ZERO];
  const u = m.uncertainty ? m.uncertainty[key] : null;
  return [fmt(v, digits), u !== null && u !== undefined && isFinite(u) ? " ± " + fmt(u, digits) : ""];
}
function showU(id, parts) { $(id).textContent = parts[0]; $(id + "-u").textContent = parts[1]; }

function setupNumber(name, fallback) {
  const v = Number($("setup").elements[name].value);
  return isFinite(v) && v > 0 ? v : fallback;
}

// What the metrics panel shows, and its title: the numbers of that run or campaign only
const shown = { key: null };
function titleMetrics(text) { $("metrics-title").textContent = text; }
function clearResult(key, title) {
  shown.key = key;
  showMetrics(null, live.model);
  $("m-verdict").innerHTML = '<span class="muted">–</span>';
  $("result").textContent = "";
  titleMetrics(title);
}

function showMetrics(m, model, partial = false) {
  showU("m-lost", withU(m, "lost_motion_arcmin"));
  showU("m-backlash", withU(m, "backlash_arcmin"));
  showU("m-stiffness", withU(m, "stiffness_Nm_per_arcmin", 2));
  for (const el of $("metrics").querySelectorAll(".num"))
    el.classList.toggle("partial", partial && !["m-model", "m-batch"].includes(el.id));
  // a loop not closed yet has no area: the figure of half a loop is not shown
  const mJ = partial ? null : m && m.loop_area_J !== undefined && m.loop_area_J !== null ? {
    loop_area_J: 1000 * m.loop_area_J,
    uncertainty: { loop_area_J: m.uncertainty && m.uncertainty.loop_area_J !== undefined
      && m.uncertainty.loop_area_J !== null ? 1000 * m.uncertainty.loop_area_J : null } } : null;
  showU("m-hysteresis", withU(mJ, "loop_area_J", 3));
  if (partial) $("m-hysteresis-u").textContent = " (the loop is not closed yet)";
  const mm = (m && m.model) || model;
  $("m-model").textContent = fmt(mm && mm.lost_motion_arcmin);
  // the unit kind's own model and batch band are named (cycloid: seed 002, beveloid: seed 001)
  const own = live.design || (model && model.kind ? model : null);
  const labels = designLabels(own);
  $("m-model-label").textContent = labels.model;
  $("m-batch-label").textContent = labels.batch;
  const band = live.batch && live.batch.band_95_arcmin;
  $("m-batch").textContent = band ? `${fmt(band[0])} .. ${fmt(band[1])}` : "–";
  const flags = [];
  // stiffness asymmetry: the stiffer side over the other
  const kp = m && m.stiffness_pos_Nm_per_arcmin, kn = m && m.stiffness_neg_Nm_per_arcmin;
  const maxRatio = setupNumber("asymmetry_flag_ratio", 1.3);
  if (kp > 0 && kn > 0) {
    const ratio = Math.max(kp, kn) / Math.min(kp, kn);
    $("m-asym").textContent = `${fmt(kp, 2)} / ${fmt(kn, 2)} (ratio ${fmt(ratio, 2)})`;
    if (ratio > maxRatio) flags.push(`stiffness asymmetry: ${fmt(ratio, 2)} between the sides ` +
      `(+ ${fmt(kp, 2)}, − ${fmt(kn, 2)} N·m/arcmin) exceeds ${fmt(maxRatio, 2)}`);
  } else $("m-asym").textContent = "–";
  // the torque cross-check: its largest disagreement against a share of rated torque
  const diff = m ? m.crosscheck_max_diff_Nm : null;
  const rated = (m && m.rated_torque_Nm) || num($("setup").elements.rated_torque_Nm.value);
  const pct = setupNumber("crosscheck_flag_pct", 10);
  if (diff !== null && diff !== undefined && isFinite(diff)) {
    const share = rated > 0 ? 100 * diff / rated : null;
    $("m-cross").textContent = fmt(diff, 3) + " N·m" + (share !== null ? ` (${fmt(share, 1)} % of rated)` : "");
    if (share !== null && share > pct) flags.push(`torque cross-check: the transducer and the ` +
      `cross-check sensor differed by up to ${fmt(diff, 3)} N·m, ${fmt(share, 1)} % of rated ` +
      `(flag above ${fmt(pct, 1)} %): check both sensors' zero and calibration`);
  } else $("m-cross").textContent = "–";
  $("m-cross").classList.toggle("flag", flags.some((f) => f.startsWith("torque")));
  $("m-asym").classList.toggle("flag", flags.some((f) => f.startsWith("stiffness")));
  $("flags").innerHTML = flags.map((f) => `<div class="flag">⚠ ${esc(f)}</div>`).join("");
}

// The result panel's labels of the nominal model and the batch band for a unit design
// ({kind, model_name, band_source}: a preview's model or a result's unit_kind): the seed 000
// pair keeps its short labels, another kind is named with its model and its tolerances
function designLabels(d) {
  if (!d || !d.kind || d.kind === "internal_involute" || !d.model_name)
    return { model: "nominal model (no runout): lost motion", batch: "batch band (95 %)" };
  return { model: `nominal model, ${d.kind} (${d.model_name}): lost motion`,
           batch: `batch band (95 %, ${d.kind}: ${d.band_source || "the kind's tolerances"})` };
}
const designOf = (r) => (r && r.unit_kind
  ? { kind: r.unit_kind, model_name: r.model_name, band_source: r.band_source } : null);

// ---------------------------------------------------------------- campaign: lost motion vs position
let campaignPlot = null;
function showCampaign(title, summary) {
  const pts = (summary && summary.lost_motion_by_position) || [];
  const box = $("campaign-box");
  box.hidden = pts.length === 0;
  if (!pts.length) return;
  $("campaign-title").textContent = title;
  const x = pts.map((p) => p.input_angle_deg);
  const y = pts.map((p) => (measurable(p.lost_motion_arcmin) ? p.lost_motion_arcmin : null));
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
      width: plotWidth($("loop-plot")), height: 240,
      scales: { x: { time: false } },
      axes: [axis("input angle (deg)"), axis("lost motion (arcmin)")],
      series: [{}, { label: "measured", stroke: "#1f5fbf", paths: () => null,
                     points: { show: true, size: 9, fill: "#1f5fbf" } },
               { label: "runout signature", stroke: "#c62828", dash: [6, 4], points: { show: false } },
               { label: "batch 2.5 %", stroke: "#888", dash: [2, 3], points: { show: false } },
               { label: "batch 97.5 %", stroke: "#888", dash: [2, 3], points: { show: false } }],
    }, data, $("campaign-plot"));
  } else campaignPlot.setData(data);
  // the unit kind, its nominal model and the tolerances of its band (cycloid: seed 002,
  // beveloid: seed 001), with the kind's compensation advice
  const b = summary.batch || {};
  const advice = b.advice && b.advice.band_95_arcmin ? (b.advice.rotation_modification_mm !== undefined
    ? `rotation modification Δ2 = ${fmt(b.advice.rotation_modification_mm, 4)} mm`
    : `gear axial position ${fmt(b.advice.axial_shift_mm, 3)} mm`) +
    ` gives ${fmt(b.advice.band_95_arcmin[0])} .. ${fmt(b.advice.band_95_arcmin[1])} arcmin` : "";
  const model = summary.model && summary.model.lost_motion_arcmin;
  $("campaign-note").textContent = summary.unit_kind ? `unit kind ${summary.unit_kind}; ` +
    `nominal model (${summary.model_name}): ${fmt(model)} arcmin; ` +
    (band ? `batch band (${b.what ? b.what.split(" (")[0] : "95 %"}): ${fmt(band[0])} .. ${fmt(band[1])} arcmin` : "no batch band") +
    (band && b.nominal_relation ? `; nominal and band: ${b.nominal_relation}` : "") +
    (advice ? `; advice: ${advice}` : "") : "";
}

// ---------------------------------------------------------------- status
let lastStatus = null;
function renderStatus(s) {
  lastStatus = s;
  const st = $("state");
  st.textContent = s.state.replace("_", " ");
  st.className = "badge " + s.state;
  $("rig-name").textContent = s.rig_id || (s.simulated ? "simulated rig" : "");
  $("rig-name").title = s.rig ? "rig: " + s.rig : "";
  document.title = (s.rig_id ? s.rig_id + " · " : "") + "backlash-rig control page";
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
  $("v-angle").textContent = fmt(v.output_angle_deg, 3);
  $("v-torque").textContent = fmt(v.torque_Nm, 3);
  $("v-temp").textContent = fmt(v.temperature_C, 1);
  $("v-setpoint").textContent = fmt(v.setpoint_Nm, 3);
  $("v-drive").textContent = v.drive_enabled === undefined || v.drive_enabled === null ? "–"
    : (v.drive_enabled ? "enabled" : "disabled");
  $("v-safe").textContent = s.safe === null ? "–" : (s.safe ? "yes" : "no");
  $("v-safe").className = "num " + (s.safe ? "pass" : "");
  const lock = s.input_lock;
  showLockState(lock);
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
  const faultWasHidden = $("fault").hidden;
  $("fault").hidden = !f;
  if (f && faultWasHidden) reveal($("fault"));  // a fault comes into view, wherever one is
  if (f) {
    $("fault-title").textContent = f.title;
    const listed = latched.map((x) => x.device + ": " + x.detail).join("\n");
    $("fault-action").textContent = latched.length
      ? "Latched: " + latched.map((x) => x.device).join(", ") + ". Remove the cause, then press Reset faults."
      : f.action;
    $("fault-detail").textContent = [f.detail, listed].filter(Boolean).join("\n");
  }
  $("reset-faults").hidden = !latched.length;
  renderCalibration(s.calibration || []);
  renderCampaignNow(s.current, busy);
  // buttons
  const op = s.operator;
  const connected = s.state !== "no_rig" && s.state !== "starting";
  const faulted = latched.length > 0;
  const why = startBlockers(s, { op, busy, connected, faulted, lock });
  $("start").disabled = why.length > 0;
  $("start").title = why.join("; ");
  $("start-why").textContent = why.length && !busy ? "Start is off: " + why.join("; ") + "." : "";
  $("preview").disabled = busy || faulted;
  $("reset-faults").disabled = !op || busy;
  $("pause").disabled = !op || s.state !== "running";
  $("resume").disabled = !op || s.state !== "paused";
  $("abort").disabled = !op || !busy;
  $("tare").disabled = !op || busy || !connected;
  $("lock").disabled = !op || busy || !connected || !!lock.moving;
  // while measuring, the panel shows the run measured now or nothing (never the last result)
  const nowRun = (s.current && s.current.run_id) || (p && p.run_id) || null;
  if (p) rememberLabel(p.run_id, p.run_label);
  if (s.current && s.current.measuring) rememberLabel(s.current.measuring.run_id, s.current.measuring.label);
  if (busy && shown.key !== "live:" + nowRun) {
    live.stored = null;   // the loop too is the run measured now
    clearResult("live:" + nowRun, nowRun ? `run ${liveRunName(nowRun)}: measuring` : "measurement starting");
  }
  // a stored run drawn from the history keeps its own numbers beside it
  if (busy && s.current && s.current.test) showTEMode(s.current.test === TE_TEST);
  if (s.last_result && !busy && !live.stored) renderResult(s.last_result);
}

// Why Start is greyed out, in words (empty: it may start)
function startBlockers(s, st) {
  const why = [];
  if (!st.op) why.push("log in with the operator token");
  if (!st.connected) why.push("no rig is connected");
  if (st.busy) why.push("a measurement is " + s.state);
  if (st.faulted) why.push("a fault is latched: Reset faults first");
  if (st.connected && !st.lock.confirmed)
    why.push("input lock not confirmed (Devices: Confirm input lock)");
  const expired = (s.calibration || []).filter((c) => c.expired);
  if (expired.length && !overrideGiven())
    why.push("calibration expired (" + expired.map((c) => c.sensor).join(", ") +
      "): tick 'start with expired calibration' and give the reason");
  if (formProblems > 0) why.push("fix the set-up fields marked in red");
  // no part result without who measured it and which part it is (a test station asks both)
  const f = $("setup").elements;
  if (!f.operator.value.trim()) why.push("enter the operator (Set up: operator)");
  if (!f.serial.value.trim()) why.push("enter this unit's serial (Set up: serial)");
  return why;
}

function overrideGiven() {
  const f = $("setup").elements;
  return f.override.checked && f.override_reason.value.trim().length > 0;
}

function renderCalibration(cal) {
  const tb = $("calibration").querySelector("tbody");
  tb.innerHTML = "";
  for (const c of cal) {
    const tr = document.createElement("tr");
    tr.innerHTML = "<td></td><td></td><td></td><td></td><td></td>";
    tr.children[0].textContent = c.sensor;
    tr.children[1].textContent = c.id;
    tr.children[2].textContent = c.certificate;
    tr.children[3].textContent = c.due + (c.expired ? " (expired)" : "");
    tr.children[3].className = c.expired ? "expired" : "";
    tr.children[4].textContent = c.uncertainty;
    tb.appendChild(tr);
  }
  const expired = cal.filter((c) => c.expired);
  $("calibration-state").textContent = !cal.length ? "none in the rig configuration"
    : expired.length ? "EXPIRED: " + expired.map((c) => c.sensor).join(", ") : "all valid";
  $("calibration-state").className = expired.length ? "expired" : "muted";
  $("override-box").hidden = expired.length === 0;
}

// What a campaign measures now, and each finished run's lost motion as it completes
function renderCampaignNow(cur, busy) {
  const box = $("campaign-now");
  if (!cur || !busy) { box.hidden = true; return; }
  const m = cur.measuring;
  let html = "";
  if (m) {
    const parts = [];
    if (m.input_angle_deg !== null && m.input_angle_deg !== undefined)
      parts.push(`input position ${fmt(m.input_angle_deg, 1)}°`);
    if (m.amplitude_pct !== null && m.amplitude_pct !== undefined)
      parts.push(`amplitude ${fmt(m.amplitude_pct, 0)} % of rated`);
    parts.push(m.temperature_C !== null && m.temperature_C !== undefined
      ? `housing ${fmt(m.temperature_C, 1)} °C` : "temperature not controlled");
    html += `<b>Now measuring run ${esc(m.number)}${m.n_runs ? " of " + esc(m.n_runs) : ""}: ` +
      `${esc(runName(m.label, m.run_id))}</b> · ${parts.map(esc).join(" · ")}`;
  } else html += "<b>between runs</b>";
  const done = cur.finished || [];
  if (done.length) {
    html += "<ol class=\"finished\">" + done.map((r) => `<li>${esc(runName(r.label, r.run_id))}: ` +
      (measurable(r.lost_motion_arcmin)
        ? `lost motion ${fmt(r.lost_motion_arcmin)}${r.lost_motion_u_arcmin ? " ± " + fmt(r.lost_motion_u_arcmin) : ""} arcmin`
        : esc((r.status || "") + (r.reason ? " (" + r.reason + ")" : ""))) +
      ` ${outcomeHtml(r.outcome)}</li>`).join("") + "</ol>";
  }
  box.innerHTML = html;
  box.hidden = false;
  if (cur.kind === "campaign" && done.length) {   // the positions so far, on the plot
    const byPos = {};
    for (const r of done) {
      if (!measurable(r.lost_motion_arcmin) || r.input_angle_deg === null) continue;
      (byPos[r.input_angle_deg] = byPos[r.input_angle_deg] || []).push(r.lost_motion_arcmin);
    }
    const pts = Object.keys(byPos).map(Number).sort((a, b) => a - b).map((a) => ({
      input_angle_deg: a, lost_motion_arcmin: byPos[a].reduce((x, y) => x + y, 0) / byPos[a].length }));
    showCampaign("so far: " + pts.length + " position(s)", {
      lost_motion_by_position: pts, runout_signature: null, batch: live.batch });
  }
}

// The verdict's words come from the server (GET /api/outcomes, rig/results/outcome.py): one
// vocabulary for the page, the certificate, the CLI, SPC and the Python API.
let OUTCOME_WORDS = {};
const OUTCOME_CLASS = { ok: "pass", not_ok: "fail", incomplete: "incomplete", no_limits: "no-limits" };
async function loadOutcomeWords() {
  try { OUTCOME_WORDS = await api("GET", "/api/outcomes"); } catch (e) { notice("verdict words: " + e.message, true); }
}
function outcomeHtml(outcome) {
  if (!outcome) return '<span class="muted">–</span>';
  const known = OUTCOME_WORDS[outcome];
  const title = known ? ` title="${esc(known.meaning)}"` : "";
  return `<span class="${OUTCOME_CLASS[outcome] || "incomplete"}"${title}>${esc(known ? known.word : outcome)}</span>`;
}

function renderResult(r) {
  const el = $("result");
  const verdict = outcomeHtml(r.outcome);
  $("m-verdict").innerHTML = verdict;
  let html = `${esc(r.kind)} ${esc(r.status)}: ${verdict}`;
  if (r.failures && r.failures.length) html += "<br>" + r.failures.map(esc).join("<br>");
  if (r.lost_motion_by_position && r.lost_motion_by_position.length) {
    html += "<br>lost motion against position: " + r.lost_motion_by_position
      .map((x) => `${fmt(x.input_angle_deg, 0)}°: ${measurable(x.lost_motion_arcmin)
        ? fmt(x.lost_motion_arcmin) : "–"}`).join(", ");
  }
  if (r.batch) live.batch = r.batch;
  if (designOf(r)) live.design = designOf(r);
  const band = r.batch && r.batch.band_95_arcmin;
  if (r.kind !== "campaign" && r.unit_kind) {   // a run: its unit kind and nominal model
    const ran = (r.runs || []).map((x) => x.model && x.model.lost_motion_arcmin).filter(measurable);
    html += `<br>unit kind ${esc(r.unit_kind)}; nominal model (${esc(r.model_name)}): ` +
      `${ran.length ? fmt(ran[ran.length - 1]) + " arcmin" : "not available"}`;
  }
  if (band) {
    html += `<br>production batch of this design (${esc(r.band_source || "seed 000 Table 1 tolerances")}, 95 %): ` +
      `${fmt(band[0])} .. ${fmt(band[1])} arcmin`;
    // how the band and the nominal relate where the kind's batch says (cycloid: issue 33 item 17)
    if (r.batch.nominal_relation) html += `<br>nominal and band: ${esc(r.batch.nominal_relation)}`;
  }
  el.innerHTML = html;
  const runs = r.runs || [];
  if (r.kind === "campaign") {
    showCampaign(r.campaign_id || "", r);
    const worst = worstRun(runs);
    showMetrics(worst, null);
    titleMetrics(worst ? `campaign ${r.campaign_id || ""} ${r.status}: worst run ` +
      `${runName(worst.label, worst.run_id)} (the largest lost motion of ${runs.length} run(s))`
      : `campaign ${r.campaign_id || ""} ${r.status}: no run measured`);
  } else {
    const last = runs.length ? runs[runs.length - 1] : null;
    showMetrics(last && last.status === "completed" ? last : null, null);
    titleMetrics(last ? `run ${runName(last.label, last.run_id)} ${last.status || r.status}` : `run ${r.status}`);
  }
  shown.key = "result";
  $("m-verdict").innerHTML = verdict;   // the verdict of what the title names
  const teRun = runs.filter((x) => x.te_raw || x.test_kind === "transmission_error").pop();
  if (teRun) showTEResult(teRun, r.limits || teRun.limits || {});
  showTEMode(!!teRun);   // a later loop run hides an earlier TE run's panel
}

// The run of a campaign with the largest lost motion (completed runs; a figure below zero is
// not a measurement); each run as the result or the history lists it
function worstRun(runs) {
  let worst = null;
  for (const r of runs) {
    const v = r.lost_motion_arcmin;
    if ((r.status && r.status !== "completed") || !measurable(v)) continue;
    if (!worst || v > worst.lost_motion_arcmin) worst = r;
  }
  return worst;
}

// Text as HTML, safe in element content and in quoted attribute values alike: & < > " '
const ESCAPES = { "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" };
function esc(text) {
  return String(text === null || text === undefined ? "" : text).replace(/[&<>"']/g, (c) => ESCAPES[c]);
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
    rememberLabel(m.run_id, m.label);
    live.T = []; live.W = []; live.runId = m.run_id; live.stored = null;
    showTEMode(m.test === TE_TEST);
    clearResult("live:" + m.run_id, `run ${liveRunName(m.run_id)}: measuring`);
    scheduleDraw();
  });
  es.addEventListener("metrics", (e) => {
    const m = JSON.parse(e.data);
    if (m.run_id !== live.runId || shown.key !== "live:" + m.run_id || live.finished === m.run_id) return;
    showMetrics(m.metrics, live.model, m.partial !== false);
    titleMetrics(`run ${liveRunName(m.run_id)}: measuring, partial figures (the loop is not closed yet)`);
    window.rigStats.partial = (window.rigStats.partial || 0) + 1;
  });
  es.addEventListener("progress", (e) => {
    const ev = JSON.parse(e.data);
    rememberLabel(ev.run_id, ev.run_label);
    if (ev.kind === "run_finished" && ev.data && shown.key === "live:" + ev.run_id) {
      live.finished = ev.run_id;
      showMetrics(ev.data, live.model);
      const cur = lastStatus && lastStatus.current;
      const name = liveRunName(ev.run_id);
      if (cur && cur.kind === "campaign") {
        // a run of a campaign: its verdict is listed with the campaign's runs above; the big
        // verdict waits for the campaign's own (issue 33 item 16)
        const k = cur.measuring && cur.measuring.run_id === ev.run_id ? cur.measuring.number
          : (cur.finished || []).length + 1;
        const of = cur.n_runs ? ` of ${cur.n_runs}` : "";
        $("m-verdict").innerHTML = `<span class="between">campaign running: run ${esc(k)}${esc(of)} done</span>`;
        titleMetrics(`run ${k}${of} ${name} ${ev.data.status || "finished"}; the campaign goes on ` +
          "(its verdict at its end)");
      } else {
        $("m-verdict").innerHTML = outcomeHtml(ev.data.outcome);
        titleMetrics(`run ${name} ${ev.data.status || "finished"}`);
      }
    }
    refreshStatus();
  });
  es.addEventListener("state", () => { refreshStatus(); refreshHistory(); });
  es.addEventListener("status", () => refreshStatus());
  es.addEventListener("input_lock", (e) => onInputLock(JSON.parse(e.data)));
  window.rigEvents = es;
}

// ---------------------------------------------------------------- set-up form
let units = [];
// Each unit kind's fields on the form (rig/web/models.py: UnitData, CycloidUnitData,
// BeveloidUnitData, PlanetaryUnitData), and its keys the form has no field for (kept from the example or the
// campaign file the unit came from, sent with it)
const UNIT_KIND_FIELDS = {
  internal_involute: ["z_internal", "z_external", "module_mm", "pressure_angle_deg", "addendum_coeff",
    "face_width_mm", "center_distance_mm", "m_value_internal_mm", "m_value_external_mm",
    "runout_internal_mm", "runout_external_mm"],
  cycloid: ["z_internal", "z_external", "module_mm", "height_coeff", "shape_coeff", "eccentricity_mm",
    "shift_modification_mm", "rotation_modification_mm", "face_width_mm", "reference_torque_Nm",
    "runout_internal_mm", "runout_external_mm"],
  beveloid: ["z_pinion", "z_gear", "module_mm", "pressure_angle_deg", "helix_angle_deg", "cone_angle_deg",
    "face_width_mm", "addendum_coeff", "center_distance_mm", "axial_shift_mm",
    "runout_internal_mm", "runout_external_mm"],
  planetary: ["ratio", "planets", "backlash_um", "face_width_mm"],
};
const UNIT_KIND_EXTRA = {
  internal_involute: ["clearance_coeff", "pin_diameter_mm", "bearing_clearance_mm"],
  cycloid: ["pitch_deviation_mm", "bearing_clearance_mm"],
  beveloid: ["runout_pinion_mm", "runout_gear_mm", "bearing_clearance_mm"],
  planetary: ["design", "reference_torque_Nm"],
};
const LIST_FIELDS = ["m_value_internal_mm", "m_value_external_mm", "backlash_um"];   // comma separated
const UNIT_FIELDS = [...new Set(Object.values(UNIT_KIND_FIELDS).flat())];
const unitKindOf = (u) => (u && UNIT_KIND_FIELDS[u.kind || "internal_involute"] ? u.kind || "internal_involute" : null);

// show the fields of the unit kind chosen on the form (the others are kept, hidden)
function showUnitKind() {
  const f = $("setup");
  if (!UNIT_KIND_FIELDS[f.elements.unit_kind.value]) f.elements.unit_kind.value = "internal_involute";
  f.dataset.unitKind = f.elements.unit_kind.value;
}

function fillUnit(u) {
  const f = $("setup");
  const kind = unitKindOf(u) || "internal_involute";
  f.elements.unit_kind.value = kind;
  showUnitKind();
  for (const k of UNIT_FIELDS) {
    const v = UNIT_KIND_FIELDS[kind].includes(k) ? u[k] : undefined;
    f.elements[k].value = v === undefined || v === null ? "" : (Array.isArray(v) ? v.join(", ") : v);
  }
  live.unitExtra = {};
  for (const k of UNIT_KIND_EXTRA[kind]) live.unitExtra[k] = u[k];
}

const num = (v) => (v === "" || v === undefined ? null : Number(v));
const list = (v) => (v.trim() === "" ? null : v.split(/[,\s]+/).filter((x) => x).map(Number));

function request() {
  const f = $("setup").elements;
  const unitKind = UNIT_KIND_FIELDS[f.unit_kind.value] ? f.unit_kind.value : "internal_involute";
  const unit = { kind: unitKind, serial: f.serial.value || null };
  for (const k of UNIT_KIND_FIELDS[unitKind]) {
    const v = f[k].value;
    unit[k] = LIST_FIELDS.includes(k) ? list(v) : num(v);
  }
  for (const k of UNIT_KIND_EXTRA[unitKind]) if (live.unitExtra) unit[k] = live.unitExtra[k];
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
    operator: f.operator.value.trim() || null,
  };
  body.test = f.test.value;
  if (body.test === "transmission_error") {
    body.te = { input_speed_rpm: num(f.te_speed_rpm.value), brake_torque_fraction: num(f.te_brake_fraction.value),
      output_revolutions: num(f.te_revolutions.value), ratio: num(f.te_ratio.value) };
    body.limits.te_pp_max_arcsec = num(f.te_pp_max_arcsec.value);
    body.limits.te_hysteresis_max_arcmin = num(f.te_hysteresis_max_arcmin.value);
  }
  if (f.override.checked && f.override_reason.value.trim())
    body.calibration_override = f.override_reason.value.trim();
  if (f.confirm_long.checked) body.confirm_long = true;
  if (kind === "campaign") {
    body.name = f.name.value || "web";
    body.axes = { positions_deg: list(f.positions_deg.value) || [0], repeats: num(f.repeats.value) || 1,
      amplitudes_pct: [body.plan.amplitude_pct] };
    const fe = live.fileExtra;   // a campaign file's settings the form has no field for
    if (body.test === "transmission_error") body.axes = { repeats: body.axes.repeats };
    if (fe) {
      Object.assign(body.plan, fe.plan);
      Object.assign(body.axes, fe.axes);
      Object.assign(body.limits, fe.limits);
      body.profile = fe.profile;
    }
  }
  return body;
}

// previews answered out of order (a cold analysis worker under load) must not overwrite a
// newer one: only the latest request's answer is shown
let previewSeq = 0;

async function previewPlan() {
  if (!validateForm()) throw new Error("fix the set-up fields marked in red");
  const body = request();
  const seq = ++previewSeq;
  const p = await api("POST", "/api/plan/preview", body);
  if (seq !== previewSeq) return p;
  live.model = p.model;
  live.batch = p.batch || null;
  live.design = p.model && p.model.kind ? p.model : null;
  live.amplitudeNm = p.amplitude_Nm;
  live.bandNm = p.model ? p.model.lost_motion_pct / 100 * body.plan.rated_torque_Nm : null;
  const mins = (p.estimated_s / 60).toFixed(1);
  let html = `<b>${esc(p.name)}</b>: ${esc(p.n_steps)} steps, ${esc(p.n_runs)} run(s), about ` +
    `${Math.round(p.estimated_s)} s (${mins} min); amplitude ${fmt(p.amplitude_Nm, 2)} N·m` +
    (p.torque_limit_Nm !== null ? `, rig limit ±${fmt(p.torque_limit_Nm, 2)} N·m` : "") +
    (p.fits ? ' <span class="pass">fits the rig</span>' : ' <span class="fail">does not fit</span>');
  if (p.problems.length) html += "<br>" + p.problems.map(esc).join("<br>");
  if (p.model) html += `<br>${esc(designLabels(p.model).model)} ${fmt(p.model.lost_motion_arcmin)} arcmin, ` +
    `backlash ${fmt(p.model.backlash_arcmin)} arcmin, torsional stiffness ${fmt(p.model.stiffness_Nm_per_arcmin, 2)} N·m/arcmin`;
  if (p.batch && p.batch.band_95_arcmin) html += `; production batch of this design (95 %` +
    `${p.model && p.model.band_source ? ", " + esc(p.model.band_source) : ""}): ` +
    `${fmt(p.batch.band_95_arcmin[0])} .. ${fmt(p.batch.band_95_arcmin[1])} arcmin`;
  const dd = p.diagnosis_design;
  if (dd) html += `<div id="preview-design">diagnosis of this design: can test ` +
    `${esc(dd.testable.join(", ") || "no effect")}` +
    (Object.keys(dd.untestable).length ? "; cannot test " + Object.entries(dd.untestable)
      .map(([k, why]) => `${esc(k)} (${esc(why)})`).join("; ") : "") + "</div>";
  html += `<details><summary>steps</summary><pre>${esc(p.steps.join("\n"))}` +
    `${p.truncated ? "\n…" : ""}</pre></details>`;
  $("preview-out").innerHTML = html;
  showMetrics(null, live.model);
  scheduleDraw();
  return p;
}

// Scroll so that el's top sits just under the sticky header, unless it is in view already
// (a phone: the loop is far above the Start button, the fault box far above the history)
function reveal(el) {
  const header = document.querySelector("header").getBoundingClientRect().bottom;
  const r = el.getBoundingClientRect();
  if (r.top >= header && r.top < innerHeight - Math.min(r.height, innerHeight / 2)) return;
  window.scrollTo({ top: Math.max(0, scrollY + r.top - header - 8), behavior: "instant" });
}

// ---------------------------------------------------------------- a campaign file as the set-up
const PLAN_FIELDS = ["rated_torque_Nm", "mode", "rate_Nm_per_s", "cycles", "pre_cycles",
  "steps_per_quarter", "dwell_s", "zero_band_Nm", "zero_rate_Nm_per_s"];
const shownList = (v) => (Array.isArray(v) ? v.join(", ") : "");

async function loadCampaignNames() {
  try {
    const names = await api("GET", "/api/campaign-files");
    const sel = $("campaign-example");
    for (const c of names) {
      const o = document.createElement("option");
      o.value = c.name; o.textContent = c.name; o.title = c.description;
      sel.appendChild(o);
    }
  } catch (e) { notice("campaign files: " + e.message, true); }
}

// The set-up of a campaign file (GET /api/campaign-files/NAME or an upload): the form's fields,
// and what the form has no field for kept with it (sent with the next start)
function fillFromCampaign(c) {
  const q = c.request, f = $("setup").elements;
  f.kind.value = "campaign";
  $("setup").className = "campaign";
  f.name.value = q.name;
  f.test.value = q.test || "lost_motion";
  if (q.te) {
    f.te_speed_rpm.value = String(q.te.input_speed_rpm);
    f.te_brake_fraction.value = String(q.te.brake_torque_fraction);
    f.te_revolutions.value = String(q.te.output_revolutions);
    f.te_ratio.value = q.te.ratio === null || q.te.ratio === undefined ? "" : String(q.te.ratio);
  }
  for (const k of ["te_pp_max_arcsec", "te_hysteresis_max_arcmin"]) {
    const v = q.limits[k];
    f[k].value = v === null || v === undefined ? "" : String(v);
  }
  showTestFields();
  if (q.unit) {
    fillUnit(q.unit);
    if (q.unit.serial) f.serial.value = q.unit.serial;
  }
  for (const k of PLAN_FIELDS) {
    const v = q.plan[k];
    f[k].value = v === null || v === undefined ? "" : String(v);
  }
  f.extra_levels_pct.value = shownList(q.plan.extra_levels_pct);
  const amps = q.axes.amplitudes_pct || [q.plan.amplitude_pct];
  f.amplitude_pct.value = String(amps.length === 1 ? amps[0] : q.plan.amplitude_pct);
  f.positions_deg.value = shownList(q.axes.positions_deg || [0]);
  f.repeats.value = String(q.axes.repeats);
  const lm = q.limits.lost_motion_arcmin_max;
  f.lost_motion_arcmin_max.value = lm === null || lm === undefined ? "" : String(lm);
  f.torque_limit_Nm.value = q.torque_limit_Nm === null ? "" : String(q.torque_limit_Nm);
  if (q.operator) f.operator.value = q.operator;
  if (q.calibration_override) { f.override.checked = true; f.override_reason.value = q.calibration_override; }
  f.confirm_long.checked = !!q.confirm_long;
  const extra = { plan: {}, axes: {}, limits: {}, profile: q.profile };
  for (const k of ["twist_step_arcmin", "settle_rate_arcmin_per_s", "settle_hold_s", "settle_timeout_s", "sample_s"])
    if (q.plan[k] !== undefined) extra.plan[k] = q.plan[k];
  const more = [];
  if (amps.length > 1) { extra.axes.amplitudes_pct = amps; more.push(`amplitudes ${amps.join(", ")} %`); }
  if ((q.axes.temperatures_C || []).length) {
    extra.axes.temperatures_C = q.axes.temperatures_C;
    more.push(`housing temperatures ${q.axes.temperatures_C.join(", ")} °C`);
  }
  for (const k of ["backlash_arcmin_max", "stiffness_Nm_per_arcmin_min"])
    if (q.limits[k] !== null && q.limits[k] !== undefined) { extra.limits[k] = q.limits[k]; more.push(`${k} ${q.limits[k]}`); }
  if (q.profile !== "nabtesco") more.push(`profile ${q.profile}`);
  live.fileExtra = extra;
  const lines = [`opened ${c.source}` + (c.description ? `: ${c.description}` : "")];
  if (more.length) lines.push("also from the file (no field here; sent with Start): " + more.join("; "));
  if (!q.unit) lines.push("the file gives no complete unit: the unit fields are unchanged");
  $("campaign-file-note").textContent = lines.concat(c.notes).join(" · ");
  validateForm();
  saveSetup();
  previewPlan().catch((e) => notice("preview: " + e.message, true));
  return { message: `campaign file ${c.source} opened: check the set-up, then Start` };
}

function operatorName() {
  const v = $("setup").elements.operator.value.trim();
  return v ? v.slice(0, 80) : null;
}

async function run(action, fn) {
  try { const r = await fn(); if (r && r.message) notice(r.message, false); }
  catch (e) {
    if (e.fields) showServerFieldErrors(e.fields);
    notice(action + ": " + e.message, true);
  }
  refreshStatus();
}

// ---------------------------------------------------------------- set-up checks, at the field
const FIELD_NAMES = {
  serial: "serial", operator: "operator", z_internal: "teeth of the ring gear (z internal)",
  z_external: "teeth of the pinion (z external)", module_mm: "module", pressure_angle_deg: "pressure angle",
  addendum_coeff: "addendum coefficient", face_width_mm: "face width", center_distance_mm: "centre distance",
  m_value_internal_mm: "M value of the ring gear", m_value_external_mm: "M value of the pinion",
  runout_internal_mm: "runout of the ring gear", runout_external_mm: "runout of the pinion",
  unit_kind: "unit kind", height_coeff: "height coefficient h1", shape_coeff: "shape coefficient f1",
  eccentricity_mm: "eccentricity", shift_modification_mm: "shift modification Δ1",
  rotation_modification_mm: "rotation modification Δ2", reference_torque_Nm: "reference torque",
  z_pinion: "teeth of the pinion (z pinion)", z_gear: "teeth of the gear (z gear)",
  helix_angle_deg: "helix angle", cone_angle_deg: "cone angle", axial_shift_mm: "axial shift",
  ratio: "ratio", planets: "planets per stage", backlash_um: "backlash of the stages",
  rated_torque_Nm: "rated torque", amplitude_pct: "amplitude", rate_Nm_per_s: "loading rate",
  cycles: "cycles", pre_cycles: "pre-cycles", steps_per_quarter: "steps per quarter",
  dwell_s: "dwell", extra_levels_pct: "extra levels", zero_band_Nm: "slow band",
  zero_rate_Nm_per_s: "slow rate", lost_motion_arcmin_max: "lost motion limit",
  torque_limit_Nm: "torque limit", name: "campaign name", positions_deg: "positions",
  repeats: "repeats", crosscheck_flag_pct: "cross-check flag share",
  asymmetry_flag_ratio: "stiffness asymmetry ratio", override_reason: "override reason",
};
const isNum = (v) => v.trim() !== "" && isFinite(Number(v));
const numbersIn = (v) => v.split(/[,\s]+/).filter((x) => x);
function rule(kind, lo, hi) {      // a checker of one field's text: a problem in words or null
  return (v, optional) => {
    if (v.trim() === "") return optional ? null : "is needed";
    if (!isNum(v)) return "must be a number";
    const x = Number(v);
    if (kind === "int" && !Number.isInteger(x)) return "must be a whole number";
    if (kind === "gt" && !(x > lo)) return `must be above ${lo}`;
    if (kind !== "gt" && lo !== undefined && x < lo) return `must be at least ${lo}`;
    if (hi !== undefined && x > hi) return `must be at most ${hi}`;
    return null;
  };
}
function listRule(lo, hi, optional) {
  return (v) => {
    if (v.trim() === "") return optional ? null : "is needed";
    for (const t of numbersIn(v)) {
      if (!isFinite(Number(t))) return `must be numbers separated by commas ("${t}" is not one)`;
      const x = Number(t);
      if (lo !== undefined && !(x > lo)) return `must all be above ${lo}`;
      if (hi !== undefined && !(x < hi)) return `must all be below ${hi}`;
    }
    return null;
  };
}
const RULES = {
  serial: (v) => v.trim() === "" || /^[A-Za-z0-9][A-Za-z0-9._-]{0,79}$/.test(v.trim()) ? null
    : "may hold letters, digits, dot, dash and underscore (up to 80), starting with a letter or digit",
  operator: (v) => v.length <= 80 ? null : "must be at most 80 characters",
  z_internal: rule("int", 3, 2000), z_external: rule("int", 3, 2000), module_mm: rule("gt", 0),
  pressure_angle_deg: (v) => v.trim() === "" ? null : (rule("gt", 0)(v) || (Number(v) < 45 ? null : "must be below 45°")),
  addendum_coeff: (v) => rule("ge", 0, 2)(v, true), face_width_mm: (v) => rule("gt", 0)(v, true),
  center_distance_mm: (v) => rule("ge", 0)(v, true),
  m_value_internal_mm: listRule(0, undefined, true), m_value_external_mm: listRule(0, undefined, true),
  runout_internal_mm: (v) => rule("ge", 0, 10)(v, true), runout_external_mm: (v) => rule("ge", 0, 10)(v, true),
  rated_torque_Nm: rule("gt", 0), amplitude_pct: (v) => rule("gt", 0)(v) || rule("ge", 0, 100)(v),
  rate_Nm_per_s: rule("gt", 0), cycles: rule("int", 1, 20), pre_cycles: rule("int", 0, 10),
  steps_per_quarter: rule("int", 1, 200), dwell_s: rule("ge", 0, 3600),
  extra_levels_pct: listRule(0, 100, true), zero_band_Nm: (v) => rule("ge", 0)(v, true),
  zero_rate_Nm_per_s: (v) => rule("gt", 0)(v, true),
  lost_motion_arcmin_max: (v) => rule("gt", 0)(v, true), torque_limit_Nm: (v) => rule("gt", 0)(v, true),
  name: (v) => /^[A-Za-z0-9][A-Za-z0-9._-]{0,79}$/.test(v.trim()) ? null : "may hold letters, digits, dot, dash and underscore",
  positions_deg: listRule(undefined, undefined, false), repeats: rule("int", 1, 50),
  crosscheck_flag_pct: rule("gt", 0), asymmetry_flag_ratio: (v) => rule("ge", 1)(v),
};
// a unit field whose bounds differ by kind (rig/web/models.py); else RULES
const UNIT_KIND_RULES = {
  cycloid: {
    height_coeff: (v) => rule("gt", 0)(v) || rule("ge", 0, 1)(v), shape_coeff: rule("ge", 0, 1),
    eccentricity_mm: (v) => rule("gt", 0)(v, true) || rule("ge", 0, 1000)(v, true),
    shift_modification_mm: (v) => rule("ge", -1, 1)(v, true),
    rotation_modification_mm: (v) => rule("ge", -1, 1)(v, true),
    reference_torque_Nm: (v) => rule("gt", 0)(v, true),
  },
  beveloid: {
    z_pinion: rule("int", 5, 2000), z_gear: rule("int", 5, 2000),
    pressure_angle_deg: rule("ge", 5, 35),
    helix_angle_deg: (v) => rule("ge")(v) || (Math.abs(Number(v)) < 45 ? null : "must be between -45° and 45°"),
    cone_angle_deg: (v) => rule("ge")(v) || (Math.abs(Number(v)) < 30 ? null : "must be between -30° and 30°"),
    face_width_mm: rule("gt", 0), addendum_coeff: (v) => rule("ge", 0, 1.5)(v, true),
    center_distance_mm: (v) => rule("gt", 0)(v, true), axial_shift_mm: (v) => rule("ge", -100, 100)(v, true),
  },
  planetary: {   // seed 003's paper train: ratio 320 only, one backlash per stage
    ratio: (v) => rule("ge")(v) || (Number(v) === 320 ? null : "must be 320 (seed 003's paper train)"),
    planets: (v) => rule("int", 1, 12)(v, true), face_width_mm: (v) => rule("gt", 0)(v) || rule("ge", 0, 10000)(v),
    backlash_um: (v) => {
      if (v.trim() === "") return "is needed";
      const xs = numbersIn(v);
      if (xs.some((t) => !isNum(t))) return "must be numbers separated by commas";
      if (xs.length !== 3) return `must be 3 values, one per stage (${xs.length} given)`;
      return xs.every((t) => Number(t) >= 0 && Number(t) <= 1000) ? null : "must each be 0 to 1000 µm";
    },
  },
};
let formProblems = 0;

function fieldErrorEl(input) {
  let el = input.parentElement.querySelector(".field-error");
  if (!el) {
    el = document.createElement("span");
    el.className = "field-error";
    el.setAttribute("role", "alert");
    el.dataset.for = input.name;
    input.parentElement.appendChild(el);
  }
  return el;
}
function setFieldError(input, text) {
  fieldErrorEl(input).textContent = text || "";
  input.setAttribute("aria-invalid", text ? "true" : "false");
}

function validateForm() {
  const f = $("setup").elements;
  const campaign = f.kind.value === "campaign";
  const unitKind = UNIT_KIND_FIELDS[f.unit_kind.value] ? f.unit_kind.value : "internal_involute";
  const kindRules = UNIT_KIND_RULES[unitKind] || {};
  let problems = 0;
  for (const name of new Set([...Object.keys(RULES), ...UNIT_FIELDS])) {
    const input = f[name];
    if (!input) continue;
    if (input.closest(".campaign-only") && !campaign) { setFieldError(input, ""); continue; }
    // a unit field of another kind is not sent: not checked
    if (UNIT_FIELDS.includes(name) && !UNIT_KIND_FIELDS[unitKind].includes(name)) { setFieldError(input, ""); continue; }
    const check = kindRules[name] || RULES[name];
    if (!check) continue;
    const why = check(input.value);
    setFieldError(input, why ? `${FIELD_NAMES[name] || name} ${why}` : "");
    if (why) problems++;
  }
  // between fields: the ring has more teeth than the pinion (an internal pair, a cycloid)
  if (["internal_involute", "cycloid"].includes(unitKind) && !RULES.z_internal(f.z_internal.value) && !RULES.z_external(f.z_external.value) &&
      Number(f.z_internal.value) <= Number(f.z_external.value)) {
    setFieldError(f.z_internal, `teeth of the ring gear must exceed the pinion's (${f.z_external.value})`);
    problems++;
  }
  const reason = f.override.checked && !f.override_reason.value.trim();
  setFieldError(f.override_reason, reason ? "give the reason for starting with an expired calibration" : "");
  if (reason) problems++;
  formProblems = problems;
  return problems === 0;
}

// a 422 of the API, in words at its field ("rated torque must be above 0"), never a path
function fieldProblem(d) {
  const loc = (d.loc || []).filter((x) => typeof x === "string" && x !== "body");
  const f = $("setup").elements;
  let name = [...loc].reverse().find((x) => f[x]);
  // the unit as a whole: its kind unknown, or its tooth counts between them
  if (!name && loc.includes("unit")) name = d.type === "unit_kind" ? "unit_kind" : "z_internal";
  const msg = String(d.msg || "").replace(/^Value error, /, "").replace(/^expected /, "must be ")
    .replace(/^Input should be greater than or equal to (.*)$/, "must be at least $1")
    .replace(/^Input should be greater than (.*)$/, "must be above $1")
    .replace(/^Input should be less than or equal to (.*)$/, "must be at most $1")
    .replace(/^Input should be less than (.*)$/, "must be below $1")
    .replace(/^Input should be a valid (number|integer).*$/, "must be a $1")
    .replace(/^Field required$/, "is needed")
    .replace(/^String should match pattern .*$/, "has characters that are not allowed");
  const label = name ? (FIELD_NAMES[name] || name.replace(/_/g, " ")) : "set-up";
  return { name, text: msg.startsWith(name || "\u0000") ? msg : `${label} ${msg}` };
}
function showServerFieldErrors(fields) {
  const f = $("setup").elements;
  for (const p of fields) if (p.name && f[p.name]) setFieldError(f[p.name], p.text);
}

// ---------------------------------------------------------------- the set-up kept across a reload
const SETUP_KEY = "rigSetup";
function saveSetup() {
  const data = { unitExample: $("unit-example").value, lockAngle: $("lock-angle").value };
  for (const el of $("setup").elements) {
    if (!el.name) continue;
    data[el.name] = el.type === "checkbox" ? el.checked : el.value;
  }
  try { localStorage.setItem(SETUP_KEY, JSON.stringify(data)); } catch (e) { /* private mode */ }
}
function restoreSetup() {
  let data = null;
  try { data = JSON.parse(localStorage.getItem(SETUP_KEY) || "null"); } catch (e) { data = null; }
  if (!data || typeof data !== "object") return false;
  if (data.unitExample && units.some((u) => u.name === data.unitExample)) {
    $("unit-example").value = data.unitExample;
    fillUnit(units.find((u) => u.name === data.unitExample).unit);
  }
  if (typeof data.lockAngle === "string") $("lock-angle").value = data.lockAngle;
  for (const el of $("setup").elements) {
    if (!el.name || !(el.name in data)) continue;
    if (el.type === "checkbox") el.checked = !!data[el.name];
    else el.value = String(data[el.name]);
  }
  $("setup").className = $("setup").elements.kind.value === "campaign" ? "campaign" : "";
  showUnitKind();
  return true;
}

// ---------------------------------------------------------------- keyboard
function typingIn(el) {
  if (!el) return false;
  const tag = el.tagName;
  if (tag === "TEXTAREA" || tag === "SELECT" || el.isContentEditable) return true;
  return tag === "INPUT" && !["checkbox", "radio", "button", "submit"].includes(el.type);
}
function onKey(e) {
  if (e.ctrlKey || e.metaKey || e.altKey) return;
  if (e.key === "Escape" || (e.key === " " && !typingIn(e.target))) {
    e.preventDefault();        // Space never clicks a focused button instead
    $("estop").click();
    return;
  }
  if (typingIn(e.target) || e.repeat) return;
  const key = e.key.toLowerCase();
  const press = (id) => { e.preventDefault(); if (!$(id).disabled) $(id).click(); };
  if (key === "s") press("start");
  else if (key === "p") press(lastStatus && lastStatus.state === "paused" ? "resume" : "pause");
  else if (key === "a") press("abort");
}

// ---------------------------------------------------------------- history
// The tables are rebuilt only when what the server lists has changed: a refresh that finds
// the same runs leaves every row (and a link under the operator's finger) where it was
let historyShown = null;
async function refreshHistory() {
  try {
    const [runs, camps] = await Promise.all([api("GET", "/api/runs?limit=50"), api("GET", "/api/campaigns")]);
    const listed = JSON.stringify([runs, camps]);
    if (listed === historyShown) return;
    historyShown = listed;
    const tb = $("runs").querySelector("tbody");
    tb.innerHTML = "";
    for (const r of runs) {
      const tr = document.createElement("tr");
      const id = encodeURIComponent(r.run_id);
      rememberLabel(r.run_id, r.label);
      tr.innerHTML = `<td><a href="#" data-run="${esc(r.run_id)}">${esc(runName(r.label, r.run_id))}</a></td>` +
        `<td>${esc(r.status)}${r.reason ? ": " + esc(r.reason) : ""}</td>` +
        `<td class="verdict">${outcomeHtml(r.outcome)}</td><td>${esc(r.unit_serial || "")}</td>` +
        `<td>${esc(r.started_at)}</td><td class="lost-motion">${lostMotionText(r.metrics)}</td>` +
        `<td><a href="/api/runs/${id}/run.zip">zip</a> · <a href="/api/runs/${id}/samples.csv">csv</a> · ` +
        `<a href="/api/runs/${id}/loop.png">png</a> · <a href="/api/runs/${id}/certificate.pdf">Certificate</a>` +
        ` (<a href="/api/runs/${id}/certificate.html" target="_blank">as a page</a>)</td>`;
      tb.appendChild(tr);
    }
    const cb = $("campaigns").querySelector("tbody");
    cb.innerHTML = "";
    for (const c of camps) {
      const s = c.summary || {};
      const id = encodeURIComponent(c.campaign_id);
      const causes = c.outcome === "not_ok" || c.outcome === "incomplete" ? (s.failures || []).slice(0, 3) : [];
      const verdict = outcomeHtml(c.outcome) + (causes.length ? " " + esc(causes.join("; ")) : "");
      const byPos = (s.lost_motion_by_position || [])
        .map((x) => `${fmt(x.input_angle_deg, 0)}°: ${measurable(x.lost_motion_arcmin)
          ? fmt(x.lost_motion_arcmin) : "–"}`).join(", ");
      const tr = document.createElement("tr");
      // only the reports that exist; a campaign without a diagnosis says why (issue 33 item 13)
      const diagnosis = c.no_diagnosis ? `<span class="no-diagnosis">${esc(c.no_diagnosis)}</span>`
        : `<a href="/api/campaigns/${id}/diagnosis.html" target="_blank" data-diagnosis="page">diagnosis</a>` +
          ` · <a href="/api/campaigns/${id}/diagnosis.html" download="${esc(c.campaign_id)}-diagnosis.html" data-diagnosis="html">html</a>` +
          ` · <a href="/api/campaigns/${id}/diagnosis.json" download="${esc(c.campaign_id)}-diagnosis.json" data-diagnosis="json">json</a>`;
      tr.innerHTML = `<td><a href="#" data-campaign="${esc(c.campaign_id)}">${esc(c.campaign_id)}</a></td><td>${esc(c.status)}</td><td class="verdict">${verdict}</td>` +
        `<td>${byPos}</td><td class="reports">${diagnosis}` +
        ` · <a href="/api/campaigns/${id}/certificate.pdf">Certificate</a>` +
        ` (<a href="/api/campaigns/${id}/certificate.html" target="_blank">as a page</a>)</td>`;
      cb.appendChild(tr);
    }
  } catch (e) { notice("history: " + e.message, true); }
}

// A diagnosis link: asked for first (a campaign's diagnosis is made on the first request),
// then opened or downloaded; a refusal is said in the notice and History then says why
// (never a raw error page, never a silent download that fails: issue 33 item 13)
async function openDiagnosis(a) {
  const tab = a.dataset.diagnosis === "page" ? window.open("", "_blank") : null;
  try {
    const res = await fetch(a.href);
    if (!res.ok) {
      let msg = res.status + " " + res.statusText;
      try { const d = await res.json(); if (d && typeof d.detail === "string") msg = d.detail; } catch (e) { /* none */ }
      throw new Error(msg);
    }
    if (tab) { tab.location.href = a.href; return; }   // made and kept: served at once
    const link = document.createElement("a");
    link.href = a.href;
    link.download = a.getAttribute("download") || "";
    document.body.appendChild(link);
    link.click();
    link.remove();
  } catch (err) {
    if (tab) tab.close();
    notice(err.message, true);
    refreshHistory();
  }
}

// A run's lost motion (arcmin) ± its uncertainty, as History lists it
function lostMotionText(metrics) {
  const m = metrics || {};
  const v = m.lost_motion_arcmin;
  if (v === null || v === undefined) return "–";
  if (!measurable(v)) return "–" + BELOW_ZERO;
  const u = (m.uncertainty || {}).lost_motion_arcmin;
  return fmt(v) + (u !== null && u !== undefined && isFinite(u) ? " ± " + fmt(u) : "");
}

// ctx (a campaign's worst run): {title, outcome, result} of the campaign instead of the run's
async function showStoredRun(runId, ctx) {
  const d = await api("GET", `/api/runs/${encodeURIComponent(runId)}/loop?max_points=5000`);
  live.stored = { T: d.torque_Nm, W: d.twist_arcmin, M: d.model_twist_arcmin };
  live.bandNm = d.band_Nm;
  const name = liveRunName(runId);
  $("loop-title").textContent = "stored: " + name + (d.analysis_error ? " (" + d.analysis_error + ")" : "");
  showMetrics(d.metrics, null);
  shown.key = "stored";
  titleMetrics(ctx ? ctx.title : `stored run ${name} ${d.status || ""}`);
  $("m-verdict").innerHTML = outcomeHtml(ctx ? ctx.outcome : d.outcome);
  $("result").innerHTML = ctx ? ctx.result
    : `stored run ${esc(name)} ${esc(d.status || "")}: ${outcomeHtml(d.outcome)}`;
  scheduleDraw();
}

// A campaign from History: its verdict, its plot, and its worst run's loop and figures
async function showStoredCampaign(campaignId) {
  const c = await api("GET", `/api/campaigns/${encodeURIComponent(campaignId)}`);
  showCampaign(c.campaign_id, c.summary);
  const s = c.summary || {};
  if (designOf(s)) { live.design = designOf(s); live.batch = s.batch || null; }  // its own kind and band
  const causes = (s.failures || []).slice(0, 5);
  const result = `campaign ${esc(c.campaign_id)} ${esc(c.status)}: ${outcomeHtml(c.outcome)}` +
    (causes.length ? "<br>" + causes.map(esc).join("<br>") : "");
  for (const r of c.runs || []) rememberLabel(r.run_id, r.label);
  const runs = (c.runs || []).map((r) => ({ ...(r.metrics || {}), run_id: r.run_id, status: r.status }));
  const worst = worstRun(runs);
  if (worst) {
    await showStoredRun(worst.run_id, { outcome: c.outcome, result,
      title: `campaign ${c.campaign_id} ${c.status}: worst run ${liveRunName(worst.run_id)} ` +
        `(the largest lost motion of ${runs.length} run(s))` });
  } else {
    live.stored = { T: [], W: [], M: null };
    clearResult("stored", `campaign ${c.campaign_id} ${c.status}: no run measured`);
    $("m-verdict").innerHTML = outcomeHtml(c.outcome);
    $("result").innerHTML = result;
    $("loop-title").textContent = "stored: " + c.campaign_id;
    scheduleDraw();
  }
}

// ---------------------------------------------------------------- wiring
function wire() {
  $("estop").addEventListener("click", () => run("E-stop", () => api("POST", "/api/control/estop")));
  $("token-set").addEventListener("click", logIn);
  $("token").addEventListener("keydown", (e) => { if (e.key === "Enter") logIn(); });
  $("token-clear").addEventListener("click", () => { sessionStorage.removeItem("rigToken"); refreshStatus(); });
  $("tare").addEventListener("click", () => run("tare", () => api("POST", "/api/devices/tare")));
  $("reset-faults").addEventListener("click", () => run("reset faults", () =>
    api("POST", "/api/devices/reset-faults", { operator: operatorName() })));
  $("lock").addEventListener("click", () => run("input lock", () => {
    $("start").disabled = true;   // not confirmed while the input moves to its angle
    $("lock-state").textContent = "locking …";
    const a = num($("lock-angle").value);
    return api("POST", "/api/devices/input-lock", a === null ? { confirm: true } : { angle_deg: a, confirm: true });
  }));
  $("preview").addEventListener("click", () => run("preview", previewPlan));
  $("start").addEventListener("click", () => run("start", async () => {
    await previewPlan();
    const answer = await api("POST", "/api/control/start", request());
    // the next unit is another unit: its serial is asked again (the operator is kept)
    $("setup").elements.serial.value = "";
    validateForm(); saveSetup();
    live.T = []; live.W = []; live.stored = null; live.finished = null;
    resetTE(request().test === "transmission_error");
    clearResult("starting", "measurement starting");
    reveal($(teMode ? "te-panel" : "loop-panel"));   // the progress and the loop (or TE), wherever the Start button was
    return answer;
  }));
  // the state badge: tapped, it shows the fault and Reset faults (else the loop)
  $("state").addEventListener("click", () => reveal($("fault").hidden ? $("loop-panel") : $("fault")));
  $("campaign-example").addEventListener("change", (e) => {
    if (e.target.value) run("campaign", () => api("GET",
      `/api/campaign-files/${encodeURIComponent(e.target.value)}`).then(fillFromCampaign));
  });
  $("campaign-upload").addEventListener("change", (e) => {
    const file = e.target.files && e.target.files[0];
    if (file) run("campaign file", async () => {
      let answer;
      try {
        answer = await api("POST", "/api/campaign-upload", { file_name: file.name, text: await file.text() });
      } catch (err) {
        // the note says what was opened: a file that could not be, and that the set-up is
        // unchanged (never "opened" of the previous file, issue 33 item 16)
        $("campaign-file-note").textContent = `${file.name} was not opened (${err.message}); ` +
          "the set-up is unchanged";
        throw err;
      } finally { e.target.value = ""; }   // the same file chosen again is read again
      return fillFromCampaign(answer);
    });
  });
  $("pause").addEventListener("click", () => run("pause", () => api("POST", "/api/control/pause")));
  $("resume").addEventListener("click", () => run("resume", () => api("POST", "/api/control/resume")));
  $("abort").addEventListener("click", () => run("abort", () => api("POST", "/api/control/abort")));
  $("refresh").addEventListener("click", refreshHistory);
  $("setup").elements.kind.addEventListener("change", (e) => {
    $("setup").className = e.target.value === "campaign" ? "campaign" : "";
  });
  $("setup").elements.test.addEventListener("change", showTestFields);
  $("setup").elements.unit_kind.addEventListener("change", (e) => {
    // another kind: its example unit (the first of that kind) fills the unit's fields
    const u = units.find((x) => unitKindOf(x.unit) === e.target.value);
    if (u) { $("unit-example").value = u.name; fillUnit(u.unit); } else showUnitKind();
  });
  $("unit-example").addEventListener("change", (e) => {
    const u = units.find((x) => x.name === e.target.value);
    if (u) fillUnit(u.unit);
    validateForm(); saveSetup();
  });
  const onSetup = () => {
    validateForm();
    saveSetup();
    if (lastStatus) renderStatus(lastStatus);
  };
  $("setup").addEventListener("input", onSetup);
  $("setup").addEventListener("change", onSetup);
  $("lock-angle").addEventListener("input", saveSetup);
  document.addEventListener("keydown", onKey);
  // a run or campaign clicked in History: its loop is drawn, and brought into view (the loop
  // panel is far above History, issue 33 item 16)
  $("campaigns").addEventListener("click", async (e) => {
    const d = e.target.closest("a[data-diagnosis]");
    if (d) { e.preventDefault(); openDiagnosis(d); return; }
    const a = e.target.closest("a[data-campaign]");
    if (!a) return;
    e.preventDefault();
    try { await showStoredCampaign(a.dataset.campaign); reveal($("loop-panel")); } catch (err) { notice(err.message, true); }
  });
  // a transmission error run shows its TE panel, never a loop (issue 33 item 15)
  $("runs").addEventListener("click", async (e) => {
    const a = e.target.closest("a[data-run]");
    if (!a) return;
    e.preventDefault();
    try {
      if (await showStoredTE(a.dataset.run)) return;
      await showStoredRun(a.dataset.run);
      reveal($("loop-panel"));
    } catch (err) { notice(err.message, true); }
  });
  window.addEventListener("resize", () => {
    plot.setSize({ width: plotWidth($("loop-plot")), height: PLOT_HEIGHT });
    if (campaignPlot) campaignPlot.setSize({ width: plotWidth($("loop-plot")), height: 240 });
  });
}

// a wrong token says so (the page would otherwise just stay a viewer)
async function logIn() {
  const given = $("token").value.trim();
  if (!given) { notice("log in: type the operator token first", true); return; }
  sessionStorage.setItem("rigToken", given);
  $("token").value = "";
  await refreshStatus();
  if (lastStatus && !lastStatus.operator) {
    sessionStorage.removeItem("rigToken");
    notice("wrong operator token: this page can only watch. Use the token printed by rig serve", true);
    refreshStatus();
  } else if (lastStatus) notice("logged in as operator", false);
}

// ---------------------------------------------------------------- transmission error
// The live TE plot: TE = 3600 (output - input / ratio) against the output angle modulo 360
// (docs/run-format.md), each direction less its running mean (c_d); the rig sends the raw
// TE of each recorded row (rig/web/live_tap.py). After the run: the figures of the run's
// analysis (rig/results/te.py), its limits and the verdict.
const te = { F: [[], []], R: [[], []], sumF: 0, nF: 0, sumR: 0, nR: 0, runId: null };
let tePlot = null;
const TE_TEST = "transmission_error";
const TE_PLOT_HEIGHT = 320;

function makeTEPlot() {
  const el = $("te-plot");
  // the whole output turn always (0-360 deg), whatever part of it is measured yet
  const facets = [{ scale: "x", auto: false }, { scale: "y", auto: true }];
  return new uPlot({
    mode: 2, width: plotWidth(el), height: TE_PLOT_HEIGHT, title: "",
    scales: { x: { time: false, auto: false, range: [0, 360] }, y: {} },
    axes: [axis("output angle (deg)"), axis("transmission error (arcsec)")],
    legend: { show: true, live: false },
    series: [{},
      // points, not lines: the output angle wraps at 360 deg
      { label: "forward", stroke: "#1f5fbf", fill: "#1f5fbf", paths: uPlot.paths.points(), points: { show: true, size: 3 }, facets },
      { label: "reverse", stroke: "#c0392b", fill: "#c0392b", paths: uPlot.paths.points(), points: { show: true, size: 3 }, facets }],
  }, [null, [[], []], [[], []]], el);
}

function showTestFields() {
  const f = $("setup");
  f.dataset.test = f.elements.test.value;
}

// A transmission error run is shown in the TE panel, in the loop panel's place (top right,
// pinned); a loop run in the loop panel: never the one drawn as the other (issue 33 item 15).
// The progress bar and the campaign line go with the panel shown.
let teMode = false;
function showTEMode(on) {
  teMode = !!on;
  $("loop-panel").hidden = teMode;
  $("te-panel").hidden = !teMode;
  const host = teMode ? $("te-panel") : $("loop-panel");
  if ($("progress").parentElement !== host)
    host.querySelector("h2").after($("progress"), $("campaign-now"));
  if (teMode) sizeTEPlot();
}

// The TE plot as wide as its panel (it was made while hidden, at no width)
function sizeTEPlot() {
  if (!tePlot || $("te-panel").hidden) return;
  const width = plotWidth($("te-plot"));
  if (Math.abs(width - tePlot.width) > 1) tePlot.setSize({ width, height: TE_PLOT_HEIGHT });
}

function resetTE(show) {
  te.F = [[], []]; te.R = [[], []]; te.sumF = te.sumR = 0; te.nF = te.nR = 0; te.runId = null;
  for (const id of ["te-pp", "te-pp-u", "te-pp-dirs", "te-hyst", "te-limit", "te-verdict", "te-note"]) $(id).textContent = "";
  $("te-title").textContent = "";
  showTEMode(show);
  drawTE();
}

function addTERows(msg) {
  if (msg.run_id && msg.run_id !== te.runId) {   // another run (a campaign's next): its own curve
    resetTE(true);
    te.runId = msg.run_id;
  }
  for (let i = 0; i < msg.te_arcsec.length; i++) {
    const d = msg.direction[i], v = msg.te_arcsec[i], a = msg.output_deg[i];
    if (v === null || a === null || !d) continue;
    const x = ((a % 360) + 360) % 360;
    if (d > 0) { te.F[0].push(x); te.F[1].push(v); te.sumF += v; te.nF += 1; }
    else { te.R[0].push(x); te.R[1].push(v); te.sumR += v; te.nR += 1; }
  }
  showTEMode(true);
  if (msg.type === "rows") $("te-title").textContent = msg.run_id ? "live: " + msg.run_id : "";
  else if (!$("te-title").textContent) $("te-title").textContent = msg.run_id || "";
  window.rigStats.batches += 1;
  drawTE();
}

function drawTE() {
  if (!tePlot) return;
  const mF = te.nF ? te.sumF / te.nF : 0, mR = te.nR ? te.sumR / te.nR : 0;
  tePlot.setData([null, [te.F[0], te.F[1].map((v) => v - mF)], [te.R[0], te.R[1].map((v) => v - mR)]]);
  window.rigStats.te_points = te.nF + te.nR;
}

function showTEResult(run, limits) {
  const raw = run.te_raw || {};
  const pp = run.te_pp_arcsec !== undefined && run.te_pp_arcsec !== null ? run.te_pp_arcsec : raw.pp_arcsec;
  $("te-pp").textContent = fmt(pp, 1);
  const u = run.te_pp_arcsec_u;
  $("te-pp-u").textContent = u !== undefined && u !== null && isFinite(u) ? " ± " + fmt(u, 1) : "";
  const fwd = run.te_pp_forward_arcsec !== undefined ? run.te_pp_forward_arcsec : raw.pp_forward_arcsec;
  const rev = run.te_pp_reverse_arcsec !== undefined ? run.te_pp_reverse_arcsec : raw.pp_reverse_arcsec;
  $("te-pp-dirs").textContent = `${fmt(fwd, 1)} / ${fmt(rev, 1)}`;
  const hyst = run.te_hysteresis_arcmin !== undefined && run.te_hysteresis_arcmin !== null
    ? run.te_hysteresis_arcmin : raw.hysteresis_arcmin;
  $("te-hyst").textContent = fmt(hyst, 3);
  const lim = [];
  if (limits.te_pp_max_arcsec) lim.push(`peak-to-peak ≤ ${fmt(limits.te_pp_max_arcsec, 1)} arcsec`);
  if (limits.te_hysteresis_max_arcmin) lim.push(`hysteresis ≤ ${fmt(limits.te_hysteresis_max_arcmin, 3)} arcmin`);
  $("te-limit").textContent = lim.length ? lim.join(", ") : "none set";
  $("te-verdict").innerHTML = outcomeHtml(run.outcome);
  $("te-title").textContent = run.run_id ? runName(run.label || runLabels[run.run_id], run.run_id) : (run.label || "");
  $("te-note").textContent = run.te_pp_arcsec !== undefined && run.te_pp_arcsec !== null
    ? "the run's analysis (docs/transmission-error.md: the encoder eccentricity as calibrated); the plot: the raw TE"
    : "raw TE (docs/run-format.md), nothing removed";
}

// A run clicked in History: a TE run shows its stored curve and figures in the TE panel
// (GET /api/runs/ID/te; showStoredTE says true), any other run or a campaign the loop panel
// (showStoredRun draws it; the History click handlers in wire())
function wireStoredTE() {
  $("campaigns").addEventListener("click", (e) => {
    if (e.target.closest("a[data-campaign]")) showTEMode(false);
  });
}

async function showStoredTE(runId) {
  const id = encodeURIComponent(runId);
  const d = await api("GET", `/api/runs/${id}`);
  if (((d.meta && d.meta.test) || {}).kind !== TE_TEST) { showTEMode(false); return false; }
  if (!live.stored) live.stored = { T: [], W: [], M: null };   // a stored run is shown: not the last result
  const t = await api("GET", `/api/runs/${id}/te?max_points=5000`);
  resetTE(true);
  te.runId = runId;
  addTERows({ type: "stored", run_id: runId, output_deg: t.output_deg, te_arcsec: t.te_arcsec,
    direction: t.direction });
  showTEResult({ ...t.result, outcome: t.outcome, run_id: runId }, t.limits || {});
  $("te-title").textContent = `stored: ${liveRunName(runId)} ${t.status || ""}`;
  reveal($("te-panel"));
  return true;
}

// ---------------------------------------------------------------- input lock
// A lock move answers at once; the input's angle comes on the live stream (input_lock
// events) and in the status until it is locked or fails (issue 33 item 7)
function showLockState(lock) {
  const el = $("lock-state");
  if (lock.moving) {
    el.textContent = `moving to ${fmt(lock.moving.target_deg, 1)} deg` +
      (lock.moving.angle_deg !== null && lock.moving.angle_deg !== undefined
        ? `: now at ${fmt(lock.moving.angle_deg, 1)} deg` : "") + " (not confirmed yet)";
  } else if (lock.confirmed) {
    el.textContent = "confirmed" + (lock.angle_deg !== null ? " at " + fmt(lock.angle_deg, 2) + " deg" : "");
  } else el.textContent = lock.failed ? "not confirmed: " + lock.failed : "not confirmed";
  el.className = lock.failed && !lock.confirmed && !lock.moving ? "fail" : "muted";
}

function onInputLock(ev) {
  if (ev.state === "moving") {
    showLockState({ moving: { target_deg: ev.target_deg, angle_deg: ev.angle_deg } });
    $("lock").disabled = true;
    $("start").disabled = true;
  } else {
    notice("input lock: " + (ev.message || ev.state), ev.state === "failed");
    refreshStatus();
  }
}

async function init() {
  plot = makePlot();
  tePlot = makeTEPlot();
  window.addEventListener("resize", sizeTEPlot);
  wireStoredTE();
  showTestFields();
  window.rigPage = { plot, live, scheduleDraw, addRows, tePlot };
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
  await loadOutcomeWords();
  await loadCampaignNames();
  restoreSetup();
  validateForm();
  connectLive();
  await refreshStatus();
  if (token() && lastStatus && !lastStatus.operator)
    notice("wrong operator token: this page can only watch. Log out and use the token printed by rig serve", true);
  refreshHistory();
  setInterval(refreshStatus, STATUS_POLL_MS);
  previewPlan().catch(() => {});
}

init();
