// brdfd's operator page: one plain ES module, no build step, no dependency.
//
// Views (by the address's #fragment): the bench (#/), the scan list (#/scans?…) and one scan's
// result (#/scans/ID). The bench is rebuilt from the daemon (GET /bench: the operation in
// progress, its readings and fits so far) when the page loads and whenever the event stream
// reconnects; live progress then comes from the event stream (GET /events). Every POST carries
// the session's CSRF header (GET /session). Text from the daemon is always set as text, never
// parsed as HTML.

/** The 14 geometries in the daemon's order (MA-T12 then SRA); a Rust test pins this list. */
const GEOMETRIES = ["15as-45","15as-30","15as-15","15as15","15as45","15as80","45as-15","45as15","45as25","45as45","45as75","45as110","sra-20","sra-60"];
/**
 * Each geometry's light zenith θi, view zenith θr, view azimuth φr (180: the far side of the
 * normal from the light, 0: the light's side) and aspecular angle, degrees (SCIENCE.md §2);
 * a Rust test pins this table to the daemon's.
 */
const GEOMETRY_ANGLES = [["15as-45",60,15,180,-45],["15as-30",45,15,180,-30],["15as-15",30,15,180,-15],["15as15",0,15,180,15],["15as45",30,15,0,45],["15as80",65,15,0,80],["45as-15",60,45,180,-15],["45as15",30,45,180,15],["45as25",20,45,180,25],["45as45",0,45,180,45],["45as75",30,45,0,75],["45as110",65,45,0,110],["sra-20",20,20,180,0],["sra-60",60,60,180,0]];
const COSTS = ["cf1", "cf2", "m2"];
const EVENT_KINDS = [
  "reference_started", "reference_reading", "reference_complete", "reference_failed",
  "scan_started", "scan_reading", "scan_complete", "scan_failed", "scan_aborted",
  "reference_stale", "processing_failed", "fit_queued", "fit_started", "fit_progress",
  "fit_done", "fit_failed", "fit_cancelled", "device", "file_imported", "file_rejected",
  "shutting_down", "lagged",
];

/** What the page measures of itself, read by the browser tests (BENCHMARKS.md quotes them). */
const metrics = { readingLatencyMs: [], firstRenderMs: null, errors: [], streamOpens: 0, streamErrors: 0, syncs: [] };
window.brdfdMetrics = metrics;
window.addEventListener("error", (e) => metrics.errors.push(String(e.message)));

let session = null;       // {csrf, csrf_header, expires_at_ms}
let status = null;        // GET /status
let live = null;          // what the bench shows: {kind, id, sample, readings: Map, fits: Map, state}
let events = null;        // the EventSource
let streamWasDown = false;
let pending = null;       // events that arrive while GET /bench is in flight, applied after it

// ---------- small helpers ----------

/** An element with attributes and children (strings become text nodes). */
function h(tag, attrs = {}, ...children) {
  const el = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === null || v === undefined || v === false) continue;
    if (k.startsWith("on")) el.addEventListener(k.slice(2), v);
    else if (k === "class") el.className = v;
    else el.setAttribute(k, v === true ? "" : String(v));
  }
  for (const c of children.flat(Infinity)) {
    if (c === null || c === undefined || c === false) continue;
    el.append(c instanceof Node ? c : document.createTextNode(String(c)));
  }
  return el;
}

/** Replaces an element's children (nulls and falses skipped, arrays flattened). */
function fill(el, ...children) {
  el.replaceChildren(...h("div", {}, ...children).childNodes);
}

const $ = (id) => document.getElementById(id);
const fmt = (v, d = 2) => (typeof v === "number" && isFinite(v) ? v.toFixed(d) : "—");
const when = (ms) => (ms ? new Date(ms).toLocaleString() : "—");
/** A duration in ms as people read it: "850 ms", "12.3 s", "2 min 05 s". */
function fmtDuration(ms) {
  if (typeof ms !== "number" || !isFinite(ms)) return "—";
  if (ms < 1000) return `${ms.toFixed(0)} ms`;
  const sec = ms / 1000;
  if (sec < 60) return `${sec.toFixed(1)} s`;
  return `${Math.floor(sec / 60)} min ${String(Math.round(sec % 60)).padStart(2, "0")} s`;
}

function setBanner(text, bad = false) {
  const b = $("banner");
  if (!text) { b.hidden = true; b.textContent = ""; return; }
  b.hidden = false;
  b.textContent = text;
  b.className = bad ? "bad" : "";
}

class ApiError extends Error {
  constructor(status, body) {
    super(body && body.error ? body.error : `HTTP ${status}`);
    this.status = status;
    this.kind = body && body.kind;
  }
}

/** A request to the daemon: JSON in and out, the CSRF header on every POST. */
async function api(path, { method = "GET", body } = {}) {
  const headers = { Accept: "application/json" };
  if (method !== "GET") {
    headers["Content-Type"] = "application/json";
    if (session) headers[session.csrf_header] = session.csrf;
  }
  const r = await fetch(path, {
    method, headers, credentials: "same-origin", cache: "no-store",
    body: body === undefined ? undefined : JSON.stringify(body),
  });
  const text = await r.text();
  let json = null;
  try { json = text ? JSON.parse(text) : null; } catch { json = null; }
  if (!r.ok) throw new ApiError(r.status, json);
  return json;
}

/** Runs a POST from a button: disables it meanwhile, shows a refusal in the banner. */
async function act(button, path, body) {
  button.disabled = true;
  try {
    const answer = await api(path, { method: "POST", body });
    setBanner(null);
    return answer;
  } catch (e) {
    setBanner(e.message, true);
    return null;
  } finally {
    button.disabled = false;
    refreshStatus();
  }
}

// ---------- the event stream ----------

function connectEvents() {
  if (events) events.close();
  metrics.streamOpens += 1;
  events = new EventSource("/events");
  events.onopen = () => {
    const s = $("stream");
    s.textContent = "live";
    s.className = "stream";
    if (streamWasDown) {
      streamWasDown = false;
      setBanner("Reconnected to the daemon; the state below is fresh.");
      syncBench("reconnect");
    }
  };
  events.onerror = () => {
    metrics.streamErrors += 1;
    // A refused stream (an HTTP error while the daemon starts) is not retried by the browser.
    if (events.readyState === EventSource.CLOSED) setTimeout(connectEvents, 2000);
    const s = $("stream");
    s.textContent = "connection lost — reconnecting…";
    s.className = "stream down";
    streamWasDown = true;
    setBanner("The connection to the brdfd daemon was lost (restarting or stopped). The page reconnects by itself.", true);
  };
  for (const kind of EVENT_KINDS) {
    events.addEventListener(kind, (msg) => {
      let ev;
      try { ev = JSON.parse(msg.data); } catch { return; }
      if (pending) pending.push([kind, ev]);
      else onEvent(kind, ev);
    });
  }
}

// The event log survives a reload of this tab (sessionStorage holds no secret: event text).
let logText = (() => { try { return sessionStorage.getItem("brdfd-log") || ""; } catch { return ""; } })();

function logLine(text) {
  const line = `${new Date().toLocaleTimeString()}  ${text}\n`;
  logText = (line + logText).split("\n").slice(0, 40).join("\n");
  try { sessionStorage.setItem("brdfd-log", logText); } catch { /* storage off: the log lives with the tab */ }
  const log = $("log");
  if (log) log.textContent = logText;
}

/** A fit's status as the bench shows it: a finished fit never goes back to running. */
const FIT_FINAL = new Set(["done", "failed", "cancelled"]);

/**
 * Rebuilds the bench from the daemon (GET /bench), then applies the events that came in
 * meanwhile (readings are keyed by geometry and fits by id, so one seen twice changes nothing).
 */
let syncing = false;
async function syncBench(why = "") {
  if (syncing || !session) return;
  syncing = true;
  if (!pending) pending = [];
  let answer = null;
  try {
    answer = await api("/bench");
  } catch (e) {
    if (e.status === 401) { pending = null; syncing = false; return showLogin(e.message); }
  }
  const queued = pending;
  pending = null;
  syncing = false;
  if (!session) return;
  if (answer) {
    const op = answer.operation;
    if (!op) {
      live = null;
    } else {
      live = newLive(op.kind, op.id, op.kind === "reference" ? `${op.sample} (reference)` : op.sample);
      live.state = op.state === "requested" ? "measuring" : op.state;
      live.reason = op.reason;
      live.provenance = op.provenance;
      for (const r of op.readings) live.readings.set(r.geometry, r);
      for (const f of op.fits) {
        live.fits.set(f.fit, {
          fit: f.fit, cost: f.cost_function, status: f.status, error: f.error,
          cost_value: f.cost, wall: f.wall_ms,
          de: f.status === "done" ? [f.delta_e00_diffuse_mean, f.delta_e00_specular_mean, f.delta_e00_mean] : null,
        });
      }
    }
    metrics.syncs.push({ kind: op ? op.kind : null, id: op ? op.id : null, state: op ? op.state : null,
      inProgress: op ? op.in_progress : false, readings: op ? op.readings.length : 0 });
    if (why && op && op.in_progress) logLine(`${op.kind} ${op.id}${op.kind === "scan" ? ` of "${op.sample}"` : ""} in progress: ${op.readings.length} of ${geometriesMeasuredNow()} readings so far (from the daemon)`);
  }
  for (const [kind, ev] of queued) onEvent(kind, ev);
  if (location.hash === "" || location.hash === "#/") renderBench();
  refreshStatus();
}

function newLive(kind, id, sample) {
  return { kind, id, sample, readings: new Map(), fits: new Map(), state: "measuring", reason: null, provenance: null };
}

/** One event: update what the bench shows. */
function onEvent(kind, ev) {
  switch (kind) {
    case "reference_started":
      if (!(live && live.kind === "reference" && live.id === ev.reference)) live = newLive("reference", ev.reference, "Munsell N9 (reference)");
      logLine(`reference ${ev.reference} started`);
      refreshStatus();
      break;
    case "scan_started":
      if (!(live && live.kind === "scan" && live.id === ev.scan)) live = newLive("scan", ev.scan, ev.sample);
      else live.sample = ev.sample;
      logLine(`scan ${ev.scan} of "${ev.sample}" started`);
      // The daemon knows which recording a simulated instrument answers from: ask.
      syncBench();
      break;
    case "reference_reading":
    case "scan_reading": {
      const id = kind === "scan_reading" ? ev.scan : ev.reference;
      const k = kind === "scan_reading" ? "scan" : "reference";
      if (!live || live.kind !== k || live.id !== id) {
        // A reading of an operation this page has not seen start: ask the daemon what it is.
        live = newLive(k, id, "");
        syncBench();
      }
      live.readings.set(ev.geometry, ev);
      paintCell(ev.geometry, ev);
      if (typeof ev.at_ms === "number") {
        // Committed → painted: the frame after the cell changed is rendered once its
        // animation-frame callbacks are done; a message posted from one runs after that frame.
        requestAnimationFrame(() => {
          const ch = new MessageChannel();
          ch.port1.onmessage = () => metrics.readingLatencyMs.push(Date.now() - ev.at_ms);
          ch.port2.postMessage(0);
        });
      }
      renderOp();
      return;
    }
    case "reference_complete":
      if (live && live.kind === "reference") live.state = "complete";
      logLine(`reference ${ev.reference} complete: in force for new scans`);
      refreshStatus();
      break;
    case "reference_failed":
      if (live && live.kind === "reference") { live.state = "failed"; live.reason = ev.reason; }
      logLine(`reference ${ev.reference} failed: ${ev.reason}`);
      refreshStatus();
      break;
    case "scan_complete":
      if (live && live.id === ev.scan && live.kind === "scan") live.state = "complete";
      logLine(`scan ${ev.scan} complete`);
      refreshStatus();
      break;
    case "scan_failed":
    case "scan_aborted":
      if (live && live.id === ev.scan && live.kind === "scan") {
        live.state = kind === "scan_failed" ? "failed" : "aborted";
        live.reason = ev.reason;
      }
      logLine(`scan ${ev.scan} ${kind === "scan_failed" ? "failed" : "aborted"}: ${ev.reason}`);
      refreshStatus();
      break;
    case "reference_stale":
      logLine(`scan ${ev.scan}: reference ${ev.reference} is ${fmt(ev.age_hours, 1)} h old (limit ${fmt(ev.max_age_hours, 1)} h): not fitted`);
      if (live && live.id === ev.scan) live.reason = "the reference is stale: not fitted (refit with --allow-stale-reference)";
      break;
    case "processing_failed":
      logLine(`scan ${ev.scan}: processing failed: ${ev.reason}`);
      break;
    case "fit_queued":
    case "fit_started":
    case "fit_progress":
    case "fit_done":
    case "fit_failed":
    case "fit_cancelled": {
      if (!live || live.kind !== "scan" || live.id !== ev.scan) {
        if (kind === "fit_done") logLine(`fit ${ev.fit} of scan ${ev.scan} done`);
        return;
      }
      const f = live.fits.get(ev.fit) || { fit: ev.fit, status: "queued" };
      if (ev.cost_function) f.cost = ev.cost_function;
      const next = { fit_queued: "queued", fit_started: "running", fit_progress: "running",
        fit_done: "done", fit_failed: "failed", fit_cancelled: "cancelled" }[kind];
      // An event older than what GET /bench said (it was in flight meanwhile) changes nothing.
      if (FIT_FINAL.has(f.status) && !FIT_FINAL.has(next)) return;
      f.status = next;
      if (kind === "fit_progress") {
        f.generation = ev.generation; f.total = ev.generations_total; f.best = ev.best_cost;
      }
      if (kind === "fit_done") {
        f.cost_value = ev.cost; f.de = [ev.delta_e00_diffuse_mean, ev.delta_e00_specular_mean, ev.delta_e00_mean];
        f.wall = ev.wall_ms;
        logLine(`fit ${ev.fit} (${ev.cost_function}) done: ΔE00 ${fmt(ev.delta_e00_mean)}`);
      }
      if (kind === "fit_failed") { f.error = ev.error; logLine(`fit ${ev.fit} failed: ${ev.error}`); }
      live.fits.set(ev.fit, f);
      if (kind !== "fit_progress") refreshStatus();
      renderFits();
      return;
    }
    case "device":
      logLine(`${ev.device}: ${ev.state} (${ev.detail})`);
      refreshStatus();
      return;
    case "file_imported":
      logLine(`imported ${ev.file}: scans ${ev.scans.join(", ")}`);
      return;
    case "file_rejected":
      logLine(`rejected ${ev.file}: ${ev.reason}`);
      return;
    case "shutting_down":
      setBanner("The daemon is shutting down; the page reconnects when it is back.", true);
      return;
    case "lagged":
      logLine(`missed ${ev.missed} events; refreshing`);
      syncBench();
      return;
    default:
      return;
  }
  if (location.hash === "" || location.hash === "#/") renderBench();
}

// ---------- status ----------

async function refreshStatus() {
  if (!session) return;   // logged out: nothing to refresh (and no 401 to show over the message)
  try {
    status = await api("/status");
  } catch (e) {
    if (e.status === 401) return showLogin(e.message);
    return;
  }
  if (location.hash === "" || location.hash === "#/") {
    renderInstruments();
    renderReference();
    renderControls();
    renderOp();
  }
  deviceBanner();
}

/** How many geometries a scan measures: 14, or the 12 MA-T12 ones without SRA readings. */
function geometryCount(scan) {
  return scan && scan.specular_readings === false ? 12 : 14;
}

/** How many geometries a measurement started now takes: 12 while the SRA is turned off. */
function geometriesMeasuredNow() {
  const off = status && status.devices.some((d) => d.device === "sra" && d.state === "off");
  return off ? 12 : 14;
}

/** What an instrument's trouble means for the operator: what happened, then what to do. */
function deviceAdvice(d) {
  switch (d.state) {
    case "disconnected":
      return `${d.instrument} is disconnected (${d.detail}). Check its cable and power; brdfd reconnects by itself and the next scan can start once it is back.`;
    case "reconnecting":
      return `${d.instrument} is reconnecting (${d.detail}). Wait a moment; if it does not come back, check its cable and power.`;
    case "error":
      return `${d.instrument} reported an error: ${d.detail}. Scan again; if it happens again, switch the instrument off and on and run brdfd doctor on the lab PC.`;
    default:
      return `${d.instrument} is ${d.state}: ${d.detail}.`;
  }
}

let deviceBannerText = null;   // the instruments' trouble, while the banner shows it
function deviceBanner() {
  if (!status) return;
  // An instrument turned off in the configuration is no trouble: the bench says so instead.
  const down = status.devices.filter((d) => !["connected", "unknown", "off"].includes(d.state));
  if (down.length) {
    deviceBannerText = down.map(deviceAdvice).join(" · ");
    setBanner(deviceBannerText, true);
  } else if (deviceBannerText !== null) {
    // The trouble is over: its message goes, any other message stays.
    if ($("banner").textContent === deviceBannerText) setBanner(null);
    deviceBannerText = null;
  }
}

// ---------- bench view ----------

function renderBench() {
  const main = $("main");
  fill(main, 
    h("div", { class: "grid" },
      h("section", { class: "panel", "aria-labelledby": "h-instruments" },
        h("h2", { id: "h-instruments" }, "Instruments"), h("div", { id: "instruments" })),
      h("section", { class: "panel", "aria-labelledby": "h-reference" },
        h("h2", { id: "h-reference" }, "Reference"), h("div", { id: "reference" }),
        h("div", { class: "form-row" },
          h("button", { type: "button", id: "measure-reference", onclick: (e) => act(e.currentTarget, "/reference") },
            "Measure reference"))),
      h("section", { class: "panel", "aria-labelledby": "h-scan" },
        h("h2", { id: "h-scan" }, "Scan a sample"),
        h("form", { id: "scan-form", onsubmit: onScanSubmit },
          h("div", { class: "form-row" },
            h("label", { for: "sample" }, "Sample"),
            h("input", { id: "sample", name: "sample", required: true, autocomplete: "off",
              placeholder: "e.g. T.Sky blue", maxlength: 200 })),
          h("div", { class: "form-row" },
            h("button", { type: "submit", class: "primary", id: "scan" }, "Scan"),
            h("button", { type: "button", class: "danger", id: "abort", onclick: (e) => act(e.currentTarget, "/abort") },
              "Abort"))))),
    h("section", { "aria-labelledby": "h-progress" },
      h("h2", { id: "h-progress", class: "sr" }, "Progress"),
      h("p", { id: "op", role: "status", "aria-live": "polite" }),
      h("p", { id: "op-sim", class: "sim-note", hidden: true }),
      h("div", { class: "cells", id: "cells" },
        GEOMETRIES.map((g) => h("div", { class: `cell${g.startsWith("sra") ? " sra" : ""}`, id: `cell-${g}`, "data-geometry": g },
          h("div", { class: "g" }, g), h("div", { class: "sw", "aria-hidden": "true" }),
          h("div", { class: "num" }, "waiting")))),
      h("p", { class: "muted", id: "cells-note" }, "Cells show the raw readings as the instruments report them: MA-T12 as CIELAB (D65, 2°) of the reflectance factor read, SRA as its intensity in the instrument's own units; neither is normalised by the N9 reference yet (the result view shows the normalised values)."),
      geometryLegend(),
      h("div", { class: "scroll" }, h("table", { class: "fits", id: "fits", "aria-label": "Fits of this scan" }))),
    h("section", { "aria-labelledby": "h-log" },
      h("h3", { id: "h-log" }, "Events"), h("pre", { id: "log", "aria-live": "off" }, logText)),
  );
  renderInstruments();
  renderReference();
  renderControls();
  if (live) for (const [g, ev] of live.readings) paintCell(g, ev);
  renderOp();
  renderFits();
}

// The SVG namespace, split so that the page holds no address of another origin.
const SVG = ["http", "://www.w3.org/2000/svg"].join("");
function svg(tag, attrs = {}) {
  const el = document.createElementNS(SVG, tag);
  for (const [k, v] of Object.entries(attrs)) el.setAttribute(k, String(v));
  return el;
}

/** A small side view of one geometry: the surface, its normal, the light and the view. */
function geometryDiagram(thetaI, thetaR, phiR) {
  const W = 72, H = 40, cx = W / 2, cy = H - 4, r = 32;
  const box = svg("svg", { viewBox: `0 0 ${W} ${H}`, width: W, height: H, role: "img",
    "aria-label": `light at ${thetaI}°, view at ${thetaR}° ${phiR === 180 ? "on the far side" : "on the light's side"}` });
  const ray = (deg, side, colour, dash) => {
    const a = (deg * Math.PI) / 180;
    const l = svg("line", { x1: cx, y1: cy, x2: cx + side * r * Math.sin(a), y2: cy - r * Math.cos(a),
      stroke: colour, "stroke-width": 2 });
    if (dash) l.setAttribute("stroke-dasharray", "3 2");
    return l;
  };
  box.append(
    svg("line", { x1: 2, y1: cy, x2: W - 2, y2: cy, stroke: "#57606a", "stroke-width": 2 }),
    svg("line", { x1: cx, y1: cy, x2: cx, y2: cy - r, stroke: "#d0d7de", "stroke-width": 1 }),
    ray(thetaI, -1, "#9a6700", false),
    // φr = 180: the view is on the far side of the normal from the light.
    ray(thetaR, phiR === 180 ? 1 : -1, "#0550ae", true));
  return box;
}

/** What the geometry names mean: a table of angles, each with its diagram. */
function geometryLegend() {
  return h("details", { class: "legend", id: "geometry-legend" },
    h("summary", {}, "What the geometry names mean"),
    h("p", { class: "muted" }, "MA-T12 names are view angle, \"as\", aspecular angle: 45as-15 views at 45° from the normal, 15° from the mirror direction towards the light's side (negative) or away from it (positive). The SRA measures at the mirror direction itself, at 20° and 60°. Angles in degrees from the surface normal; in the diagrams the light is solid, the view dashed."),
    h("div", { class: "scroll" }, h("table", { class: "data", id: "geometry-table" },
      h("thead", {}, h("tr", {}, ["geometry", "instrument", "light θi", "view θr", "view side", "aspecular", "diagram"].map((c) => h("th", { scope: "col" }, c)))),
      h("tbody", {}, GEOMETRY_ANGLES.map(([name, ti, tr, phi, asp]) => h("tr", { "data-geometry": name },
        h("th", { scope: "row" }, name), h("td", {}, name.startsWith("sra") ? "RA-532H" : "MA-T12"),
        h("td", {}, `${ti}°`), h("td", {}, `${tr}°`),
        h("td", {}, phi === 180 ? "far side of the normal" : "light's side"), h("td", {}, `${asp}°`),
        h("td", {}, geometryDiagram(ti, tr, phi))))))));
}

async function onScanSubmit(e) {
  e.preventDefault();
  const sample = $("sample").value.trim();
  if (!sample) return;
  const answer = await act($("scan"), "/scans", { sample });
  // The scan_started event may have come first: keep what it brought.
  if (answer && !(live && live.kind === "scan" && live.id === answer.scan)) {
    live = newLive("scan", answer.scan, sample);
    renderBench();
  }
}

function renderInstruments() {
  const box = $("instruments");
  if (!box || !status) return;
  box.replaceChildren(...status.devices.map((d) =>
    h("div", { class: "device", "data-device": d.device },
      h("p", {}, h("strong", {}, d.instrument), " ",
        h("span", { class: `badge state-${d.state}`, "data-state": d.state }, d.state),
        d.simulated && d.state !== "off" ? [" ", h("span", { class: "badge sim" }, "SIMULATED")] : null),
      // An instrument turned off has no identity to wait for: it is simply not used.
      d.state === "off"
        ? h("p", { class: "muted", "data-off": "yes" }, "turned off in the configuration: references and scans use the 12 MA-T12 geometries")
        : [h("p", { class: "muted" }, d.model ? `${d.model} · serial ${d.serial} · firmware ${d.firmware}` : "no identity yet"),
          d.state !== "connected" ? h("p", { class: "muted" }, d.detail) : null])));
  markSraOff();
}

/** With the SRA turned off, its two cells on the bench say so instead of "waiting". */
function markSraOff() {
  const off = geometriesMeasuredNow() === 12;
  for (const g of ["sra-20", "sra-60"]) {
    const cell = $(`cell-${g}`);
    if (!cell || cell.classList.contains("done")) continue;
    cell.classList.toggle("off", off);
    cell.querySelector(".num").textContent = off ? "SRA off" : "waiting";
  }
}

function renderReference() {
  const box = $("reference");
  if (!box || !status) return;
  const r = status.reference;
  if (!r) {
    box.replaceChildren(h("p", { class: "stale" }, "No reference measured yet: measure the Munsell N9 tile before scanning."));
    return;
  }
  box.replaceChildren(
    h("p", {}, `${r.name} (reference ${r.id})`),
    h("p", { class: r.stale ? "stale" : "muted", id: "reference-age" },
      `measured ${when(r.completed_at_ms)} — ${fmt(r.age_hours, 1)} h ago`,
      r.stale ? " — STALE: measure it again before scanning" : ""));
}

function renderControls() {
  const busy = (status && status.busy) || (live && live.state === "measuring");
  const ready = status && status.devices.every((d) => ["connected", "unknown", "off"].includes(d.state));
  const down = status ? status.devices.filter((d) => !["connected", "unknown", "off"].includes(d.state)).map((d) => d.instrument) : [];
  // Why a button is off, said on the button; nothing once it is on.
  const why = {
    "measure-reference": busy ? "the instruments are busy: wait, or abort" : !ready ? `not connected: ${down.join(", ")}` : "",
    scan: busy ? "the instruments are busy: wait, or abort" : !ready ? `not connected: ${down.join(", ")}`
      : !(status && status.reference) ? "measure the reference (Munsell N9) first" : "",
    abort: busy ? "" : "nothing is being measured",
  };
  for (const [id, on] of [["measure-reference", !busy], ["scan", !busy && status && status.reference], ["abort", !!busy]]) {
    const b = $(id);
    if (!b) continue;
    b.disabled = !on;
    if (why[id]) b.title = why[id]; else b.removeAttribute("title");
  }
}

function paintCell(geometry, ev) {
  const cell = $(`cell-${geometry}`);
  if (!cell) return;
  cell.classList.add("done");
  const sw = cell.querySelector(".sw");
  const num = cell.querySelector(".num");
  if (ev.srgb) {
    sw.style.background = ev.srgb;
    num.replaceChildren(`L* ${fmt(ev.lab[0], 1)}`, h("br"), `a* ${fmt(ev.lab[1], 1)}`, h("br"), `b* ${fmt(ev.lab[2], 1)}`);
    cell.setAttribute("aria-label", `${geometry}: L* ${fmt(ev.lab[0], 1)}, a* ${fmt(ev.lab[1], 1)}, b* ${fmt(ev.lab[2], 1)}`);
  } else if (typeof ev.intensity === "number") {
    sw.style.background = "#9a9a9a";
    num.replaceChildren("intensity", h("br"), fmt(ev.intensity, 3), h("br"), h("span", { class: "unit" }, "device units"));
    cell.setAttribute("aria-label", `${geometry}: intensity ${fmt(ev.intensity, 3)} in the SRA's own units (raw, not normalised)`);
  } else {
    num.textContent = "read";
  }
}

function renderOp() {
  const op = $("op");
  if (!op) return;
  if (!live) {
    const busy = status && status.busy;
    op.textContent = busy ? `busy: ${busy.operation.kind} ${busy.operation.scan || busy.operation.reference}` : "Idle.";
    return;
  }
  const what = live.kind === "scan" ? `Scan ${live.id} of "${live.sample}"` : `Reference ${live.id}`;
  const n = live.readings.size;
  let text = `${what}: ${n} of ${geometriesMeasuredNow()} readings`;
  if (live.state !== "measuring") text += ` — ${live.state}`;
  if (live.reason) text += `: ${live.reason}`;
  const ended = live.kind === "scan" && live.state !== "measuring";
  op.replaceChildren(text, ...(ended
    ? [" — ", h("a", { href: `#/scans/${live.id}` }, live.state === "complete" ? "open the result" : "open the scan")] : []));
  const sim = $("op-sim");
  if (sim) {
    const detail = live.provenance && live.provenance.source_detail;
    sim.textContent = detail && detail.startsWith("simulated") ? detail : "";
    sim.hidden = !sim.textContent;
  }
  op.dataset.state = live.state;
  op.dataset.readings = String(n);
}

function renderFits() {
  const t = $("fits");
  if (!t) return;
  if (!live || live.kind !== "scan" || live.fits.size === 0) { t.replaceChildren(); return; }
  const rows = [...live.fits.values()].sort((a, b) => a.fit - b.fit);
  t.replaceChildren(
    h("thead", {}, h("tr", {}, ["fit", "cost function", "status", "progress / fit time", "ΔE00 diffuse (mean)", "ΔE00 specular (mean, vs the paper's grey spectrum)", "ΔE00 all (mean)"].map((c) => h("th", { scope: "col" }, c)))),
    h("tbody", {}, rows.map((f) => h("tr", { "data-fit": f.fit, "data-status": f.status, "data-cost": f.cost || "" },
      h("td", {}, String(f.fit)), h("td", {}, f.cost || "?"), h("td", {}, f.status, f.error ? `: ${f.error}` : ""),
      h("td", {}, f.status === "running" && f.total
        ? [h("progress", { max: f.total, value: f.generation, "aria-label": `generation ${f.generation} of ${f.total}` }), ` ${f.generation}/${f.total}`]
        : f.status === "done" ? `took ${fmtDuration(f.wall)}` : ""),
      ...(f.de || [null, null, null]).map((v) => h("td", {}, fmt(v)))))));
}

// ---------- scan list ----------

async function renderScans(params) {
  const main = $("main");
  const state = params.get("state") || "";
  const sample = params.get("sample") || "";
  const before = params.get("before") || "";
  const q = new URLSearchParams({ limit: "25" });
  if (state) q.set("state", state);
  // Any part of the name, any case ("blue" finds "T.Sky blue" and "T.Lavender blue").
  if (sample) q.set("sample_contains", sample);
  if (before) q.set("before", before);
  let list;
  try { list = await api(`/scans?${q}`); } catch (e) {
    if (e.status === 401) return showLogin(e.message);
    fill(main, h("p", { class: "stale" }, e.message));
    return;
  }
  const selected = new Set();
  const reportLink = h("a", { id: "report-link", href: "#", "aria-disabled": "true" }, "Study report of the selected scans");
  const updateReport = () => {
    if (selected.size) {
      reportLink.href = `/report.html?scans=${[...selected].join(",")}`;
      reportLink.removeAttribute("aria-disabled");
    } else { reportLink.href = "#"; reportLink.setAttribute("aria-disabled", "true"); }
  };
  const form = h("form", { class: "form-row", id: "filter", onsubmit: (e) => {
    e.preventDefault();
    const p = new URLSearchParams();
    if ($("f-sample").value.trim()) p.set("sample", $("f-sample").value.trim());
    if ($("f-state").value) p.set("state", $("f-state").value);
    location.hash = `#/scans?${p}`;
  } },
  h("label", { for: "f-sample" }, "Sample name contains"), h("input", { id: "f-sample", value: sample, type: "search" }),
  h("label", { for: "f-state" }, "State"),
  h("select", { id: "f-state" }, ["", "requested", "measuring", "complete", "failed", "aborted"].map((s) =>
    h("option", { value: s, selected: s === state }, s || "any"))),
  h("button", { type: "submit" }, "Filter"));
  const rows = list.map((s) => h("tr", { "data-scan": s.id },
    h("td", {}, s.state === "complete" ? h("input", { type: "checkbox", "aria-label": `select scan ${s.id}`,
      onchange: (e) => { if (e.target.checked) selected.add(s.id); else selected.delete(s.id); updateReport(); } }) : ""),
    h("td", {}, h("a", { href: `#/scans/${s.id}` }, String(s.id))),
    h("td", {}, s.sample), h("td", {}, s.state, s.reason ? h("span", { class: "muted" }, ` — ${s.reason}`) : ""),
    h("td", {}, when(s.requested_at_ms)), h("td", {}, `${s.reading_count}/${geometryCount(s)}`),
    h("td", { class: simulatedNote(s.provenance) ? "sim" : "" }, sourceText(s.provenance))));
  const last = list.length ? list[list.length - 1].id : null;
  const older = new URLSearchParams(params); if (last) older.set("before", String(last));
  const newest = new URLSearchParams(params); newest.delete("before");
  fill(main, 
    h("h2", {}, "Scans, newest first"), form,
    list.length ? h("div", { class: "scroll" }, h("table", { class: "data", id: "scan-list" },
      h("thead", {}, h("tr", {}, ["", "scan", "sample", "state", "requested", "readings", "source"].map((c) => h("th", { scope: "col" }, c)))),
      h("tbody", {}, rows))) : h("p", {}, "No scans match."),
    h("div", { class: "pager" },
      before ? h("a", { href: `#/scans?${newest}` }, "← Newest") : null,
      list.length === 25 ? h("a", { href: `#/scans?${older}`, id: "older" }, "Older →") : null,
      reportLink));
}

// ---------- one scan's result ----------

/** What each instrument origin means, as the result page says it. */
const ORIGIN_TEXT = {
  measured: "measured on this bench",
  imported: "imported (real readings from a file)",
  simulated: "SIMULATED",
};

/** "simulated — replayed from …" of a provenance, or null when no instrument was simulated. */
function simulatedNote(prov) {
  if (!prov) return null;
  const sim = [prov.ma_t12, prov.sra].some((i) => i && (i.simulated || i.origin === "simulated"));
  if (!sim) return null;
  const d = prov.source_detail || "";
  return d.startsWith("simulated") ? d : `simulated${d ? ` — ${d}` : " — the recording was not recorded"}`;
}

/** How a scan's readings came in, in one phrase for the scan list. */
function sourceText(prov) {
  if (!prov) return "?";
  const sim = simulatedNote(prov);
  if (sim) return sim;
  if (prov.source === "imported") {
    const d = prov.source_detail || "";
    return d.startsWith("imported") ? d : `imported${d ? ` from ${d}` : ""}`;
  }
  return prov.source || "?";
}

/**
 * A download that says when it fails: the file is fetched, and a refusal of the daemon is
 * shown in the banner instead of a browser download that silently does nothing.
 */
async function download(e) {
  e.preventDefault();
  const a = e.currentTarget;
  a.setAttribute("aria-busy", "true");
  try {
    const r = await fetch(a.href, { credentials: "same-origin", cache: "no-store" });
    if (!r.ok) {
      let msg = `HTTP ${r.status}`;
      try { const j = await r.json(); if (j && j.error) msg = j.error; } catch { /* not JSON */ }
      setBanner(`The download of ${a.textContent} failed: ${msg}`, true);
      return;
    }
    const blob = await r.blob();
    const disp = r.headers.get("content-disposition") || "";
    const m = disp.match(/filename="([^"]+)"/);
    const url = URL.createObjectURL(blob);
    const save = h("a", { href: url, download: a.getAttribute("download") || (m ? m[1] : "brdfd-download") });
    document.body.append(save);
    save.click();
    save.remove();
    setTimeout(() => URL.revokeObjectURL(url), 60000);
  } catch (err) {
    setBanner(`The download of ${a.textContent} failed: ${err.message}; is the daemon running?`, true);
  } finally {
    a.removeAttribute("aria-busy");
  }
}

/** One camera image of an export: a thumbnail, whole (never cropped), that opens at full
 * size on a tap or click. */
function textureFigure(scanId, t) {
  const src = `/scans/${scanId}/textures/${t.position}.png`;
  const alt = `the MA-T12 camera's image at ${t.label}`;
  return h("figure", { "data-label": t.label },
    h("button", { type: "button", class: "enlarge", "aria-label": `full size: ${alt}`, onclick: () => {
      const dlg = $("texture-dialog");
      fill(dlg, h("img", { src, alt }), h("p", { class: "muted" }, t.label),
        h("form", { method: "dialog" }, h("button", { type: "submit" }, "Close")));
      dlg.showModal();
    } }, h("img", { src, alt, loading: "lazy" })),
    h("figcaption", {}, t.label));
}

/** One preview: shown at the image's own aspect ratio; a click opens it at full size. */
function previewFigure(f) {
  const src = `/fits/${f.run.id}/preview.png`;
  const alt = `sphere rendered from fit ${f.run.id} (${f.run.cost_function})`;
  return h("figure", { class: "preview" },
    h("button", { type: "button", class: "enlarge", "aria-label": `enlarge: ${alt}`, onclick: () => {
      const dlg = $("preview-dialog");
      fill(dlg, h("img", { src, alt }), h("form", { method: "dialog" }, h("button", { type: "submit" }, "Close")));
      dlg.showModal();
    } }, h("img", { src, alt, loading: "lazy" })),
    h("figcaption", {}, `fit ${f.run.id} · ${f.run.cost_function} — click to enlarge`));
}

async function renderResult(id) {
  const main = $("main");
  fill(main, h("p", {}, `Loading scan ${id}…`));
  let view;
  try { view = await api(`/scans/${id}`); } catch (e) {
    if (e.status === 401) return showLogin(e.message);
    fill(main, h("p", { class: "stale" }, e.message));
    return;
  }
  const scan = view.scan;
  const complete = scan.state === "complete";
  let sw = null;
  let kept = null;
  if (complete) {
    try { sw = await api(`/scans/${id}/swatches`); } catch (e) { sw = { error: e.message }; }
  } else {
    try { kept = await api(`/scans/${id}/readings`); } catch (e) { kept = { error: e.message }; }
  }
  const ref = view.reference.reference;
  const prov = scan.provenance || {};
  const inst = (p, name) => !p ? `${name}: not recorded`
    : p.origin === "absent" ? `${name}: absent (this scan has no readings of it)`
    : `${name}: ${p.model} · serial ${p.serial} · firmware ${p.firmware} · ${ORIGIN_TEXT[p.origin] || p.origin}`;
  const fitsDone = (sw && sw.fits) || [];
  const latestDone = new Map();
  for (const f of view.fits) if (f.run.status === "done") latestDone.set(f.run.cost_function, f);
  // The star goes to the fit that predicts the readings it did not see best (held-out ΔE00)
  // once every fit has its cross-validation; until then to the lowest ΔE00 at the readings.
  const heldOut = (f) => { const d = latestDone.get(f.cost_function); return d && d.crossval ? d.crossval.held_out_mean : null; };
  const byHeldOut = fitsDone.length > 0 && fitsDone.every((f) => heldOut(f) !== null);
  const score = (f) => (byHeldOut ? heldOut(f) : f.delta_e00_all);
  const best = fitsDone.length ? fitsDone.reduce((a, b) => (score(b) < score(a) ? b : a)) : null;
  const bestLabel = byHeldOut ? "★ predicts best" : "★ best fit";
  const bestTitle = byHeldOut
    ? "lowest held-out ΔE00: the fit that best predicts readings it was not fitted to"
    : "lowest ΔE00 at the readings it was fitted to (the held-out figures are not all computed)";
  const latest = new Map();
  for (const f of view.fits) latest.set(f.run.cost_function, f);
  const sim = simulatedNote(prov);
  const pendingFits = view.fits.filter((f) => f.run.status === "queued" || f.run.status === "running").length;
  const ended = { aborted: "was aborted", failed: "failed" }[scan.state];
  const notFitted = complete
    ? (pendingFits ? `${pendingFits} fit(s) queued or running: this view shows them when they are done (reload).`
      : view.reference_stale ? "Not fitted: the reference was stale when the scan was made; refit below with \"allow the stale reference\" if that is acceptable."
      : "No finished fit: see the fits below for why, or refit.")
    : ended ? `Not fitted: this scan ${ended} with ${scan.reading_count} of ${geometryCount(scan)} readings, and only a complete scan is fitted. Scan the sample again from the bench.`
    : "Not fitted yet: the scan is still being measured (see the bench).";
  fill(main,
    h("h2", {}, `Scan ${scan.id}: ${scan.sample}`),
    sim ? h("p", { class: "sim-note", id: "result-sim" }, sim) : null,
    h("p", { id: "result-state", "data-state": scan.state }, `${scan.state}${scan.reason ? ` — ${scan.reason}` : ""} · requested ${when(scan.requested_at_ms)} · ${scan.reading_count}/${geometryCount(scan)} readings`),
    kept && !kept.error ? h("section", { "aria-labelledby": "h-kept" },
      h("h3", { id: "h-kept" }, `Readings kept (${kept.length} of ${geometryCount(scan)}, raw as the instruments reported them)`),
      h("div", { class: "cells", id: "kept-cells" }, GEOMETRIES.map((g) => {
        const r = kept.find((k) => k.geometry === g);
        return h("div", { class: `cell${g.startsWith("sra") ? " sra" : ""}${r ? " done" : ""}`, "data-geometry": g, "data-kept": r ? "yes" : "no" },
          h("div", { class: "g" }, g),
          h("div", { class: "sw", "data-srgb": r && r.srgb ? r.srgb : null, "aria-hidden": "true" }),
          h("div", { class: "num" }, !r ? "not measured"
            : r.lab ? [`L* ${fmt(r.lab[0], 1)}`, h("br"), `a* ${fmt(r.lab[1], 1)}`, h("br"), `b* ${fmt(r.lab[2], 1)}`]
            : ["intensity", h("br"), fmt(r.intensity, 3), h("br"), h("span", { class: "unit" }, "device units")]));
      }))) : null,
    kept && kept.error ? h("p", { class: "stale" }, `The kept readings cannot be shown: ${kept.error}`) : null,
    sw && sw.error ? h("p", { class: "stale" }, sw.error) : null,
    sw && !sw.error ? h("section", { "aria-labelledby": "h-sw" },
      h("h3", { id: "h-sw" }, "Measured and fitted colour per geometry (sRGB, D65, 2°)"),
      h("p", { id: "result-reference" }, sw.reference === "instrument calibration"
        ? `Reference: instrument calibration — the MA-T12's reflectance factor as its software exported it, relative to the instrument's own white standard (no N9 tile).${sw.specular_readings ? "" : " No specular readings: fitted over the 12 MA-T12 geometries."}`
        : `Reference: ${sw.reference}.${sw.specular_readings ? "" : " No specular readings: fitted over the 12 MA-T12 geometries."}`),
      h("p", { class: "muted" }, sw.reference === "instrument calibration"
        ? "\"measured\" is the reflectance factor as exported (the BRDF the fit sees)."
        : "\"measured\" is the reading normalised by the N9 reference (the BRDF the fit sees, as a reflectance factor), so it differs from the raw values the bench showed while measuring."),
      h("div", { class: "scroll" }, h("table", { class: "swatches", id: "swatches" },
        h("thead", {}, h("tr", {}, h("th", {}), sw.geometries.map((g) => h("th", { scope: "col" }, g)))),
        h("tbody", {},
          swatchRow(sw.reference === "instrument calibration" ? "measured (as exported)" : "measured (normalised by N9)", sw.measured),
          fitsDone.map((f) => swatchRow(`fitted ${f.cost_function}`, f.estimated, f.delta_e00))))),
      h("p", { class: "muted" }, "! marks a colour outside the sRGB gamut (shown as the nearest displayable one)."),
      geometryLegend())
      : null,
    residualSection(view.fits),
    view.textures && view.textures.length ? h("section", { "aria-labelledby": "h-tex" },
      h("h3", { id: "h-tex" }, "The instrument camera's images (kept from the export)"),
      h("p", { class: "muted" }, "Tap or click an image to see it at full size."),
      h("div", { class: "textures", id: "textures" }, view.textures.map((t) => textureFigure(id, t))),
      h("dialog", { id: "texture-dialog", "aria-label": "camera image at full size" }))
      : null,
    h("section", { "aria-labelledby": "h-de" },
      h("h3", { id: "h-de" }, "ΔE00 (mean)"),
      fitsDone.length ? h("div", { class: "scroll" }, h("table", { class: "data", id: "de-table" },
        h("thead", {}, h("tr", {}, ["cost function", "method", "diffuse (12)", "held out (each of the 12 predicted without it)", scan.specular_readings === false ? "specular (no SRA readings)" : "specular (2, vs the paper's grey spectrum)", `all (${geometryCount(scan)})`, scan.specular_readings === false ? "specular |ΔL*| (no SRA readings)" : "specular |ΔL*| (SRA model)", "in the model's reach?", ""].map((c) => h("th", { scope: "col" }, c)))),
        h("tbody", {}, fitsDone.map((f) => h("tr", { "data-cost": f.cost_function },
          h("td", {}, f.cost_function), h("td", {}, f.method), h("td", {}, fmt(f.delta_e00_diffuse)),
          heldOutCell(latestDone.get(f.cost_function)),
          h("td", {}, f.delta_e00_specular === null ? "no specular readings" : fmt(f.delta_e00_specular)), h("td", {}, fmt(f.delta_e00_all)),
          h("td", {}, deltaL(latestDone.get(f.cost_function))),
          reachCell(latestDone.get(f.cost_function)),
          h("td", f === best ? { class: "best", title: bestTitle, "data-by": byHeldOut ? "held-out" : "fitted" } : {}, f === best ? bestLabel : ""))))))
        : h("p", { id: "not-fitted" }, notFitted),
      fitsDone.length ? h("p", { class: "muted" }, "Held out: each MA-T12 geometry predicted by a fit to the others (leave-one-geometry-out), mean ΔE00 — how far to trust the estimate at angles that were not measured. The diffuse figure beside it is the fit to every reading, which says less about other angles.") : null),
    latest.size ? h("section", { "aria-labelledby": "h-params" },
      h("h3", { id: "h-params" }, "Fitted parameters"),
      h("p", { class: "muted" }, "Brackets hold the 95 % interval of each parameter (bootstrap, SCIENCE.md §10), once computed; ks and kd in sr⁻¹, α (roughness) and μ (index of refraction) without unit."),
      h("div", { class: "scroll" }, h("table", { class: "data", id: "params" },
        h("thead", {}, h("tr", {}, ["fit", "cost function", "status", "ks [95 % interval]", "α [95 % interval]", "μ [95 % interval]", "kd at 450 / 550 / 650 nm"].map((c) => h("th", { scope: "col" }, c)))),
        h("tbody", {}, [...latest.values()].map((f) => paramRow(f))))),
      lobeNote([...latest.values()])) : null,
    fitsDone.length ? h("section", { class: "previews", "aria-labelledby": "h-prev" },
      h("h3", { id: "h-prev" }, "Previews"),
      h("div", { class: "preview-row" }, [...latest.values()].filter((f) => f.run.status === "done").map(previewFigure)),
      h("dialog", { id: "preview-dialog", "aria-label": "preview at full size" })) : null,
    h("section", { "aria-labelledby": "h-prov" },
      h("h3", { id: "h-prov" }, "Reference and instruments"),
      h("p", {}, `${ref.name} (reference ${ref.id}), measured ${when(ref.completed_at_ms)}, ${fmt(view.reference_age_hours, 1)} h before the scan`,
        view.reference_stale ? h("span", { class: "stale" }, " — stale") : ""),
      h("p", {}, inst(prov.ma_t12, "MA-T12")), h("p", {}, inst(prov.sra, "SRA")),
      h("p", { class: "muted" }, `source: ${prov.source || "?"}${prov.source_detail ? ` (${prov.source_detail})` : ""}`)),
    complete ? refitForm(scan.id, view.reference_stale) : null,
    h("section", { class: "downloads", "aria-labelledby": "h-dl" },
      h("h3", { id: "h-dl" }, "Downloads"),
      complete ? [
        h("a", { href: `/scans/${scan.id}/export`, id: "dl-scan", download: `scan-${scan.id}.scan.json`, onclick: download }, "scan file (brdfd.scan/1)"),
        [["cgats", "CGATS"], ["cxf3", "CxF3"], ["csv", "CSV"], ["json", "JSON"]].map(([f, name]) =>
          h("a", { href: `/scans/${scan.id}/export/${f}`, id: `dl-${f}`, onclick: download }, name)),
        h("a", { href: `/report.html?scans=${scan.id}`, id: "dl-report", onclick: download }, "study report"),
      ] : h("p", { id: "no-downloads" }, `No downloads: exports and the report need a complete scan (this one ${ended || "is still being measured"}); its ${scan.reading_count} readings stay in the store (brdfd show ${scan.id}).`)),
  );
}

/** A fit's specular |ΔL*| and its SRA reading model (SCIENCE.md §5.1, §7.2). */
function deltaL(fit) {
  if (!fit || !fit.specular_delta_l) return "—";
  const sra = fit.sra ? fit.sra.model + (fit.sra.weight && fit.sra.weight !== "paper" ? `, ${fit.sra.weight}` : "") : "flat";
  return `${fmt(fit.specular_delta_l.mean, 3)} (${sra})`;
}

/** Where the model misses: measured minus fitted ΔL* (and ΔC*, ΔH*, ΔE00 on hover) per
 * geometry, one row per finished fit, signed and shaded (blue: the fit is too bright there,
 * red: too dark). */
function residualSection(fits) {
  const done = (fits || []).filter((f) => f.lab && Object.keys(f.lab).length);
  if (!done.length) return null;
  const geometries = GEOMETRIES.filter((g) => done.some((f) => f.lab[g]));
  const cell = (r) => {
    if (!r) return h("td", {}, "—");
    const t = Math.min(1, Math.abs(r.dL) / 3);
    const bg = r.dL >= 0 ? `rgba(207, 34, 46, ${0.45 * t})` : `rgba(9, 105, 218, ${0.45 * t})`;
    const all = `ΔL* ${fmt(r.dL, 2)} · ΔC* ${fmt(r.dC, 2)} · ΔH* ${fmt(r.dH, 2)} · ΔE00 ${fmt(r.dE00, 2)}`;
    // Hover shows the title; a tap or click (or Enter on the focused cell) writes the same
    // values under the table, so a touch screen reads them too.
    const show = (e) => {
      const row = e.currentTarget.closest("tr");
      const g = e.currentTarget.dataset.geometry;
      $("residual-detail").textContent = `${row ? row.querySelector("th").textContent : ""} at ${g}: ${all}`;
    };
    const td = h("td", { title: all, tabindex: "0", class: "res", onclick: show,
      onkeydown: (e) => { if (e.key === "Enter" || e.key === " ") { e.preventDefault(); show(e); } } },
      `${r.dL >= 0 ? "+" : ""}${fmt(r.dL, 2)}`);
    // Through the CSSOM: the page's Content-Security-Policy allows no inline style attribute.
    td.style.background = bg;
    return td;
  };
  return h("section", { "aria-labelledby": "h-res" },
    h("h3", { id: "h-res" }, "Where the model misses: measured − fitted ΔL* per geometry"),
    h("p", { class: "muted" }, "Positive (red): the fit is too dark there; negative (blue): too bright. Tap, click or hover a value for ΔC*, ΔH* and ΔE00."),
    h("div", { class: "scroll" }, h("table", { class: "data residuals", id: "residuals" },
      h("thead", {}, h("tr", {}, h("th", { scope: "col" }, "fit"), geometries.map((g) => h("th", { scope: "col" }, g)))),
      h("tbody", {}, done.map((f) => h("tr", { "data-cost": f.run.cost_function },
        h("th", { scope: "row" }, `${f.run.cost_function} (fit ${f.run.id})`),
        geometries.map((g) => {
          const td = cell(f.lab[g] && f.lab[g].residual);
          td.dataset.geometry = g;
          return td;
        })))))),
    h("p", { id: "residual-detail", class: "muted", "aria-live": "polite" }, "Tap a value for its ΔL*, ΔC*, ΔH* and ΔE00."));
}

function swatchRow(label, swatches, de) {
  return h("tr", {}, h("th", { scope: "row" }, label), swatches.map((s, i) => h("td", {},
    h("div", { class: "sw", style: null, "data-srgb": s.srgb, "aria-hidden": "true" }),
    h("div", {}, `L* ${fmt(s.lab[0], 1)}`), h("div", {}, `a* ${fmt(s.lab[1], 1)}`), h("div", {}, `b* ${fmt(s.lab[2], 1)}`),
    s.clipped ? h("div", { class: "clip", title: "outside the sRGB gamut" }, "!") : null,
    de ? h("div", {}, `ΔE ${fmt(de[i])}`) : null)));
}

/** A fit's mean held-out ΔE00 (its cross-validation, once computed) and, under it, the worst
 * geometry: readable without hover, on a phone too. */
function heldOutCell(d) {
  const cv = d && d.crossval;
  if (!cv) return h("td", { class: "held-out" }, d ? "not computed (yet)" : "—");
  const worst = cv.held_out.reduce((a, b) => (b.delta_e00 > a.delta_e00 ? b : a));
  return h("td", { class: "held-out", "data-held-out": fmt(cv.held_out_mean) }, fmt(cv.held_out_mean),
    h("div", { class: "muted held-out-worst" }, `worst ${worst.geometry} ${fmt(worst.delta_e00)}`));
}

/** A fit's reach verdict (SCIENCE.md §12.7): whether the model can represent the material, the
 * prediction ΔE00 to expect over the hemisphere, and why on hover. */
function reachCell(d) {
  const r = d && d.reach;
  if (!r) return h("td", { class: "reach" }, "—");
  const [lo, hi] = r.expected_delta_e00;
  const [nlo, nhi] = r.expected_near_specular_delta_e00;
  const words = { "in-reach": "in reach", marginal: "marginal", "out-of-reach": "out of reach" }[r.verdict] || r.verdict;
  return h("td", { class: "reach", "data-reach": r.verdict,
    title: `${r.reasons.join("; ")}. Near the mirror direction: ΔE00 ${fmt(nlo, 1)}–${fmt(nhi, 1)}. Calibrated on ${r.calibration}.` },
  `${words}: expect ΔE00 ${fmt(lo, 1)}–${fmt(hi, 1)}`);
}

/** Where the cf1 and cf2 fits' intervals do not overlap, the lobe is not identified by the
 * readings (SCIENCE.md §10): said under the parameters, naming them; nothing otherwise. */
function lobeNote(fits) {
  const of = (cost) => fits.find((f) => f.run.cost_function === cost && f.uncertainty);
  const a = of("cf1");
  const b = of("cf2");
  if (!a || !b) return null;
  const names = { ks: "ks", alpha: "α", ior: "μ" };
  const apart = Object.keys(names).filter((k) => {
    const x = a.uncertainty[k];
    const y = b.uncertainty[k];
    return x && y && (x[1] < y[0] || y[1] < x[0]);
  });
  if (!apart.length) return null;
  return h("p", { id: "lobe-not-identified", class: "warning" },
    `Lobe not identified: the cf1 and cf2 intervals do not overlap on ${apart.map((k) => names[k]).join(", ")}. The readings do not fix the lobe; read neither interval as the parameter's, and trust the held-out ΔE00 instead.`);
}

function paramRow(f) {
  const r = f.run.result;
  const p = r && r.params;
  const u = f.uncertainty;
  // Intervals whose coverage was not measured to hold are marked, with the reason as a tooltip.
  const rated = u && u.calibrated ? "" : " (not 95 %)";
  // A parameter at a bound of its range is not identified there: flagged beside its interval.
  // From the fit's own bounds (`at_bound`), whether or not the intervals are computed.
  const bounded = new Set([...(f.at_bound || []), ...((u && u.at_bound) || [])]);
  const bound = (name) => (bounded.has(name) ? " (at bound)" : "");
  const iv = (v, range, name) => (range ? `${fmt(v, 3)} [${fmt(range[0], 3)}, ${fmt(range[1], 3)}]${rated}${bound(name)}` : `${fmt(v, 3)}${bound(name)}${p && f.run.status === "done" ? " (interval not computed yet)" : ""}`);
  return h("tr", { "data-fit": f.run.id, "data-calibrated": u ? String(Boolean(u.calibrated)) : null, title: u && !u.calibrated ? u.note || "" : null },
    h("td", {}, h("a", { href: `/fits/${f.run.id}` }, String(f.run.id))),
    h("td", {}, f.run.cost_function), h("td", {}, f.run.status, f.run.error ? `: ${f.run.error}` : ""),
    h("td", {}, p ? iv(p.ks, u && u.ks, "ks") : "—"), h("td", {}, p ? iv(p.alpha, u && u.alpha, "alpha") : "—"),
    h("td", {}, p ? iv(p.ior, u && u.ior, "ior") : "—"),
    h("td", {}, p ? [5, 15, 25].map((b) => fmt(p.kd[b], 4)).join(" / ") : "—"));
}

function refitForm(scanId, stale) {
  const form = h("form", { id: "refit", onsubmit: async (e) => {
    e.preventDefault();
    const cost_functions = COSTS.filter((c) => $(`refit-${c}`).checked);
    const body = { cost_functions, method: $("refit-method").value };
    const seed = $("refit-seed").value.trim();
    if (seed) body.seed = Number(seed);
    // Empty choices are left out: the daemon's configured ones apply.
    for (const k of ["preset", "model", "fresnel"]) {
      const v = $(`refit-${k}`).value;
      if (v) body[k] = v;
    }
    if ($("refit-stale").checked) body.allow_stale_reference = true;
    const answer = await act($("refit-go"), `/scans/${scanId}/refit`, body);
    if (answer) setBanner(`Fits ${answer.fits.join(", ")} queued; this page shows them when they are done (reload).`);
  } },
  h("div", { class: "form-row" }, COSTS.map((c) => [
    h("input", { type: "checkbox", id: `refit-${c}`, checked: true }), h("label", { for: `refit-${c}` }, c)]),
  h("label", { for: "refit-method" }, "method"),
  h("select", { id: "refit-method" }, h("option", { value: "separable" }, "separable"), h("option", { value: "paper" }, "paper (GA)")),
  h("label", { for: "refit-seed" }, "seed"), h("input", { id: "refit-seed", inputmode: "numeric", size: 6 })),
  h("div", { class: "form-row" },
  h("label", { for: "refit-preset" }, "preset"),
  h("select", { id: "refit-preset" }, h("option", { value: "" }, "as configured"),
    h("option", { value: "measured" }, "measured (exact Fresnel)"), h("option", { value: "paper" }, "paper's")),
  h("label", { for: "refit-model" }, "model"),
  h("select", { id: "refit-model" }, h("option", { value: "" }, "default"),
    ["paper", "oren-nayar", "two-lobe"].map((m) => h("option", { value: m }, m))),
  h("label", { for: "refit-fresnel" }, "Fresnel"),
  h("select", { id: "refit-fresnel" }, h("option", { value: "" }, "default"),
    ["exact", "incidence", "light-half"].map((f) => h("option", { value: f }, f))),
  h("input", { type: "checkbox", id: "refit-stale", checked: false }),
  h("label", { for: "refit-stale" }, stale ? "allow the stale reference" : "allow a stale reference"),
  h("button", { type: "submit", id: "refit-go" }, "Refit")));
  return h("section", { "aria-labelledby": "h-refit" }, h("h3", { id: "h-refit" }, "Refit with other settings"), form);
}

// ---------- routing and start ----------

function showLogin(message) {
  $("logout").hidden = true;
  if (events) { events.close(); events = null; }
  $("stream").textContent = "not signed in";
  $("main").replaceChildren(
    h("h2", {}, "Not signed in"),
    h("p", {}, message || "This page needs a session."),
    h("p", {}, "On the lab PC, run ", h("code", {}, "brdfd open"), " and open the link it prints (it works once, for two minutes)."));
}

function route() {
  const hash = location.hash || "#/";
  // A message belongs to the view it was shown on; an instrument's trouble stays.
  setBanner(null);
  deviceBanner();
  for (const a of document.querySelectorAll("nav a")) a.removeAttribute("aria-current");
  const m = hash.match(/^#\/scans\/(\d+)$/);
  if (m) { $("nav-scans").setAttribute("aria-current", "page"); return renderResult(m[1]); }
  if (hash.startsWith("#/scans")) {
    $("nav-scans").setAttribute("aria-current", "page");
    const q = hash.indexOf("?");
    return renderScans(new URLSearchParams(q >= 0 ? hash.slice(q + 1) : ""));
  }
  $("nav-bench").setAttribute("aria-current", "page");
  renderBench();
  refreshStatus();
}

/** Swatch colours are data: set them from data-srgb after each render (no inline style). */
function paintSwatches(root) {
  for (const el of root.querySelectorAll("[data-srgb]")) el.style.background = el.dataset.srgb;
}

async function start() {
  let answer;
  try {
    answer = await api("/session");
  } catch (e) {
    showLogin(`cannot reach the daemon: ${e.message}`);
    return;
  }
  if (!answer.signed_in) {
    showLogin(`Not signed in: ${answer.message}.`);
    return;
  }
  session = answer;
  $("logout").hidden = false;
  $("logout").addEventListener("click", async () => {
    await api("/session/logout", { method: "POST" }).catch(() => null);
    session = null;
    showLogin("You logged out.");
    $("logout").hidden = true;
  });
  new MutationObserver(() => paintSwatches($("main"))).observe($("main"), { childList: true, subtree: true });
  window.addEventListener("hashchange", route);
  try { status = await api("/status"); } catch { status = null; }
  // Subscribe first, then ask for the state: events between the two are held and applied
  // after it, so nothing falls in the gap.
  pending = [];
  connectEvents();
  await route();
  await syncBench("load");
  requestAnimationFrame(() => {
    const paint = performance.getEntriesByType("paint").find((p) => p.name === "first-contentful-paint");
    metrics.firstRenderMs = paint ? paint.startTime : performance.now();
  });
}

start();
