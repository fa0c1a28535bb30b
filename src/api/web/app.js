// brdfd's operator page: one plain ES module, no build step, no dependency.
//
// Views (by the address's #fragment): the bench (#/), the scan list (#/scans?…) and one scan's
// result (#/scans/ID). Live progress comes from the daemon's event stream (GET /events); every
// POST carries the session's CSRF header (GET /session). Text from the daemon is always set as
// text, never parsed as HTML.

/** The 14 geometries in the daemon's order (MA-T12 then SRA); a Rust test pins this list. */
const GEOMETRIES = ["15as-45","15as-30","15as-15","15as15","15as45","15as80","45as-15","45as15","45as25","45as45","45as75","45as110","sra-20","sra-60"];
const COSTS = ["cf1", "cf2", "m2"];
const EVENT_KINDS = [
  "reference_started", "reference_reading", "reference_complete", "reference_failed",
  "scan_started", "scan_reading", "scan_complete", "scan_failed", "scan_aborted",
  "reference_stale", "processing_failed", "fit_queued", "fit_started", "fit_progress",
  "fit_done", "fit_failed", "fit_cancelled", "device", "file_imported", "file_rejected",
  "shutting_down", "lagged",
];

/** What the page measures of itself, read by the browser tests and the README's figures. */
const metrics = { readingLatencyMs: [], firstRenderMs: null, errors: [], streamOpens: 0, streamErrors: 0 };
window.brdfdMetrics = metrics;
window.addEventListener("error", (e) => metrics.errors.push(String(e.message)));

let session = null;       // {csrf, csrf_header, expires_at_ms}
let status = null;        // GET /status
let live = null;          // what the bench shows: {kind, id, sample, readings: Map, fits: Map, state}
let events = null;        // the EventSource
let streamWasDown = false;

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
      refreshStatus();
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
      onEvent(kind, ev);
    });
  }
}

let logText = "";

function logLine(text) {
  const line = `${new Date().toLocaleTimeString()}  ${text}\n`;
  logText = (line + logText).split("\n").slice(0, 40).join("\n");
  const log = $("log");
  if (log) log.textContent = logText;
}

function newLive(kind, id, sample) {
  return { kind, id, sample, readings: new Map(), fits: new Map(), state: "measuring", reason: null };
}

/** One event: update what the bench shows. */
function onEvent(kind, ev) {
  switch (kind) {
    case "reference_started":
      live = newLive("reference", ev.reference, "Munsell N9 (reference)");
      logLine(`reference ${ev.reference} started`);
      refreshStatus();
      break;
    case "scan_started":
      live = newLive("scan", ev.scan, ev.sample);
      logLine(`scan ${ev.scan} of "${ev.sample}" started`);
      refreshStatus();
      break;
    case "reference_reading":
    case "scan_reading": {
      const id = kind === "scan_reading" ? ev.scan : ev.reference;
      const k = kind === "scan_reading" ? "scan" : "reference";
      if (!live || live.kind !== k || live.id !== id) live = newLive(k, id, live ? live.sample : "");
      live.readings.set(ev.geometry, ev);
      paintCell(ev.geometry, ev);
      if (typeof ev.at_ms === "number") {
        // Committed → painted: the next frame after the cell changed.
        requestAnimationFrame(() => metrics.readingLatencyMs.push(Date.now() - ev.at_ms));
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
      f.status = { fit_queued: "queued", fit_started: "running", fit_progress: "running",
        fit_done: "done", fit_failed: "failed", fit_cancelled: "cancelled" }[kind];
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
      refreshStatus();
      return;
    default:
      return;
  }
  if (location.hash === "" || location.hash === "#/") renderBench();
}

// ---------- status ----------

async function refreshStatus() {
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

function deviceBanner() {
  if (!status) return;
  const down = status.devices.filter((d) => d.state !== "connected" && d.state !== "unknown");
  if (down.length) {
    setBanner(down.map((d) => `${d.instrument} is ${d.state}: ${d.detail}`).join(" · "), true);
  } else if ($("banner").className === "bad" && /is (disconnected|reconnecting|error)/.test($("banner").textContent)) {
    setBanner(null);
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
      h("div", { class: "cells", id: "cells" },
        GEOMETRIES.map((g) => h("div", { class: `cell${g.startsWith("sra") ? " sra" : ""}`, id: `cell-${g}`, "data-geometry": g },
          h("div", { class: "g" }, g), h("div", { class: "sw", "aria-hidden": "true" }),
          h("div", { class: "num" }, "waiting")))),
      h("table", { class: "fits", id: "fits", "aria-label": "Fits of this scan" })),
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
        d.simulated ? [" ", h("span", { class: "badge sim" }, "SIMULATED")] : null),
      h("p", { class: "muted" }, d.model ? `${d.model} · serial ${d.serial} · firmware ${d.firmware}` : "no identity yet"),
      d.state !== "connected" ? h("p", { class: "muted" }, d.detail) : null)));
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
  const ready = status && status.devices.every((d) => d.state === "connected" || d.state === "unknown");
  for (const [id, on] of [["measure-reference", !busy], ["scan", !busy && status && status.reference], ["abort", !!busy]]) {
    const b = $(id);
    if (b) b.disabled = !on;
  }
  if (!ready && $("scan")) $("scan").title = "an instrument is not connected";
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
    num.replaceChildren("intensity", h("br"), fmt(ev.intensity, 3));
    cell.setAttribute("aria-label", `${geometry}: intensity ${fmt(ev.intensity, 3)}`);
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
  let text = `${what}: ${n} of 14 readings`;
  if (live.state !== "measuring") text += ` — ${live.state}`;
  if (live.reason) text += `: ${live.reason}`;
  op.replaceChildren(text, ...(live.kind === "scan" && live.state === "complete"
    ? [" — ", h("a", { href: `#/scans/${live.id}` }, "open the result")] : []));
  op.dataset.state = live.state;
  op.dataset.readings = String(n);
}

function renderFits() {
  const t = $("fits");
  if (!t) return;
  if (!live || live.kind !== "scan" || live.fits.size === 0) { t.replaceChildren(); return; }
  const rows = [...live.fits.values()].sort((a, b) => a.fit - b.fit);
  t.replaceChildren(
    h("thead", {}, h("tr", {}, ["fit", "cost function", "status", "progress", "ΔE00 diffuse", "ΔE00 specular", "ΔE00 all"].map((c) => h("th", { scope: "col" }, c)))),
    h("tbody", {}, rows.map((f) => h("tr", { "data-fit": f.fit, "data-status": f.status, "data-cost": f.cost || "" },
      h("td", {}, String(f.fit)), h("td", {}, f.cost || "?"), h("td", {}, f.status, f.error ? `: ${f.error}` : ""),
      h("td", {}, f.status === "running" && f.total
        ? [h("progress", { max: f.total, value: f.generation, "aria-label": `generation ${f.generation} of ${f.total}` }), ` ${f.generation}/${f.total}`]
        : f.status === "done" ? `${fmt(f.wall, 0)} ms` : ""),
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
  if (sample) q.set("sample", sample);
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
  h("label", { for: "f-sample" }, "Sample"), h("input", { id: "f-sample", value: sample }),
  h("label", { for: "f-state" }, "State"),
  h("select", { id: "f-state" }, ["", "requested", "measuring", "complete", "failed", "aborted"].map((s) =>
    h("option", { value: s, selected: s === state }, s || "any"))),
  h("button", { type: "submit" }, "Filter"));
  const rows = list.map((s) => h("tr", { "data-scan": s.id },
    h("td", {}, s.state === "complete" ? h("input", { type: "checkbox", "aria-label": `select scan ${s.id}`,
      onchange: (e) => { if (e.target.checked) selected.add(s.id); else selected.delete(s.id); updateReport(); } }) : ""),
    h("td", {}, h("a", { href: `#/scans/${s.id}` }, String(s.id))),
    h("td", {}, s.sample), h("td", {}, s.state, s.reason ? h("span", { class: "muted" }, ` — ${s.reason}`) : ""),
    h("td", {}, when(s.requested_at_ms)), h("td", {}, `${s.reading_count}/14`)));
  const last = list.length ? list[list.length - 1].id : null;
  const older = new URLSearchParams(params); if (last) older.set("before", String(last));
  const newest = new URLSearchParams(params); newest.delete("before");
  fill(main, 
    h("h2", {}, "Scans, newest first"), form,
    list.length ? h("div", { class: "scroll" }, h("table", { class: "data", id: "scan-list" },
      h("thead", {}, h("tr", {}, ["", "scan", "sample", "state", "requested", "readings"].map((c) => h("th", { scope: "col" }, c)))),
      h("tbody", {}, rows))) : h("p", {}, "No scans match."),
    h("div", { class: "pager" },
      before ? h("a", { href: `#/scans?${newest}` }, "← Newest") : null,
      list.length === 25 ? h("a", { href: `#/scans?${older}`, id: "older" }, "Older →") : null,
      reportLink));
}

// ---------- one scan's result ----------

async function renderResult(id) {
  const main = $("main");
  fill(main, h("p", {}, `Loading scan ${id}…`));
  let view;
  try { view = await api(`/scans/${id}`); } catch (e) {
    if (e.status === 401) return showLogin(e.message);
    fill(main, h("p", { class: "stale" }, e.message));
    return;
  }
  let sw = null;
  if (view.scan.state === "complete") {
    try { sw = await api(`/scans/${id}/swatches`); } catch (e) { sw = { error: e.message }; }
  }
  const scan = view.scan;
  const ref = view.reference.reference;
  const prov = scan.provenance || {};
  const inst = (p, name) => p ? `${name}: ${p.model} · serial ${p.serial} · firmware ${p.firmware}${p.simulated ? " · SIMULATED" : ""}` : `${name}: unknown`;
  const fitsDone = (sw && sw.fits) || [];
  const best = fitsDone.length ? fitsDone.reduce((a, b) => (b.delta_e00_all < a.delta_e00_all ? b : a)) : null;
  const latestDone = new Map();
  for (const f of view.fits) if (f.run.status === "done") latestDone.set(f.run.cost_function, f);
  const latest = new Map();
  for (const f of view.fits) latest.set(f.run.cost_function, f);
  fill(main, 
    h("h2", {}, `Scan ${scan.id}: ${scan.sample}`),
    h("p", { id: "result-state" }, `${scan.state}${scan.reason ? ` — ${scan.reason}` : ""} · requested ${when(scan.requested_at_ms)} · ${scan.reading_count}/14 readings`),
    sw && sw.error ? h("p", { class: "stale" }, sw.error) : null,
    sw && !sw.error ? h("section", { "aria-labelledby": "h-sw" },
      h("h3", { id: "h-sw" }, "Measured and fitted colour per geometry (sRGB, D65, 2°)"),
      h("div", { class: "scroll" }, h("table", { class: "swatches", id: "swatches" },
        h("thead", {}, h("tr", {}, h("th", {}), sw.geometries.map((g) => h("th", { scope: "col" }, g)))),
        h("tbody", {},
          swatchRow("measured", sw.measured),
          fitsDone.map((f) => swatchRow(`fitted ${f.cost_function}`, f.estimated, f.delta_e00))))),
      h("p", { class: "muted" }, "! marks a colour outside the sRGB gamut (shown as the nearest displayable one)."))
      : null,
    h("section", { "aria-labelledby": "h-de" },
      h("h3", { id: "h-de" }, "ΔE00 (mean)"),
      fitsDone.length ? h("table", { class: "data", id: "de-table" },
        h("thead", {}, h("tr", {}, ["cost function", "method", "diffuse (12)", "specular (2, vs the paper's grey spectrum)", "all (14)", "specular |ΔL*| (SRA model)", ""].map((c) => h("th", { scope: "col" }, c)))),
        h("tbody", {}, fitsDone.map((f) => h("tr", { "data-cost": f.cost_function },
          h("td", {}, f.cost_function), h("td", {}, f.method), h("td", {}, fmt(f.delta_e00_diffuse)),
          h("td", {}, fmt(f.delta_e00_specular)), h("td", {}, fmt(f.delta_e00_all)),
          h("td", {}, deltaL(latestDone.get(f.cost_function))),
          h("td", { class: f === best ? "best" : "" }, f === best ? "★ best" : "")))))
        : h("p", {}, "No finished fit yet.")),
    h("section", { "aria-labelledby": "h-params" },
      h("h3", { id: "h-params" }, "Fitted parameters"),
      h("table", { class: "data", id: "params" },
        h("thead", {}, h("tr", {}, ["fit", "cost function", "status", "ks", "α", "μ", "kd at 450 / 550 / 650 nm"].map((c) => h("th", { scope: "col" }, c)))),
        h("tbody", {}, [...latest.values()].map((f) => paramRow(f))))),
    fitsDone.length ? h("section", { class: "previews", "aria-labelledby": "h-prev" },
      h("h3", { id: "h-prev" }, "Previews"),
      [...latest.values()].filter((f) => f.run.status === "done").map((f) =>
        h("img", { src: `/fits/${f.run.id}/preview.png`, alt: `sphere rendered from fit ${f.run.id} (${f.run.cost_function})`, width: 160, height: 160 }))) : null,
    h("section", { "aria-labelledby": "h-prov" },
      h("h3", { id: "h-prov" }, "Reference and instruments"),
      h("p", {}, `${ref.name} (reference ${ref.id}), measured ${when(ref.completed_at_ms)}, ${fmt(view.reference_age_hours, 1)} h before the scan`,
        view.reference_stale ? h("span", { class: "stale" }, " — stale") : ""),
      h("p", {}, inst(prov.ma_t12, "MA-T12")), h("p", {}, inst(prov.sra, "SRA")),
      h("p", { class: "muted" }, `source: ${prov.source || "?"}${prov.source_detail ? ` (${prov.source_detail})` : ""}`)),
    scan.state === "complete" ? refitForm(scan.id, view.reference_stale) : null,
    h("section", { class: "downloads", "aria-labelledby": "h-dl" },
      h("h3", { id: "h-dl" }, "Downloads"),
      h("a", { href: `/scans/${scan.id}/export`, download: `scan-${scan.id}.scan.json` }, "scan file (brdfd.scan/1)"),
      scan.state === "complete" ? [
        ["cgats", "CGATS"], ["cxf3", "CxF3"], ["csv", "CSV"], ["json", "JSON"],
      ].map(([f, name]) => h("a", { href: `/scans/${scan.id}/export/${f}`, id: `dl-${f}` }, name)) : null,
      scan.state === "complete" ? h("a", { href: `/report.html?scans=${scan.id}`, id: "dl-report" }, "study report") : null),
  );
}

/** A fit's specular |ΔL*| and its SRA reading model (SCIENCE.md §5.1, §7.2). */
function deltaL(fit) {
  if (!fit || !fit.specular_delta_l) return "—";
  return `${fmt(fit.specular_delta_l.mean, 3)} (${fit.sra ? fit.sra.model : "flat"})`;
}

function swatchRow(label, swatches, de) {
  return h("tr", {}, h("th", { scope: "row" }, label), swatches.map((s, i) => h("td", {},
    h("div", { class: "sw", style: null, "data-srgb": s.srgb, "aria-hidden": "true" }),
    h("div", {}, `L* ${fmt(s.lab[0], 1)}`), h("div", {}, `a* ${fmt(s.lab[1], 1)}`), h("div", {}, `b* ${fmt(s.lab[2], 1)}`),
    s.clipped ? h("div", { class: "clip", title: "outside the sRGB gamut" }, "!") : null,
    de ? h("div", {}, `ΔE ${fmt(de[i])}`) : null)));
}

function paramRow(f) {
  const r = f.run.result;
  const p = r && r.params;
  const u = f.uncertainty;
  // Intervals whose coverage was not measured to hold are marked, with the reason as a tooltip.
  const rated = u && u.calibrated ? "" : " (not 95 %)";
  const iv = (v, range) => (range ? `${fmt(v, 3)} [${fmt(range[0], 3)}, ${fmt(range[1], 3)}]${rated}` : fmt(v, 3));
  return h("tr", { "data-fit": f.run.id, "data-calibrated": u ? String(Boolean(u.calibrated)) : null, title: u && !u.calibrated ? u.note || "" : null },
    h("td", {}, h("a", { href: `/fits/${f.run.id}` }, String(f.run.id))),
    h("td", {}, f.run.cost_function), h("td", {}, f.run.status, f.run.error ? `: ${f.run.error}` : ""),
    h("td", {}, p ? iv(p.ks, u && u.ks) : "—"), h("td", {}, p ? iv(p.alpha, u && u.alpha) : "—"),
    h("td", {}, p ? iv(p.ior, u && u.ior) : "—"),
    h("td", {}, p ? [5, 15, 25].map((b) => fmt(p.kd[b], 4)).join(" / ") : "—"));
}

function refitForm(scanId, stale) {
  const form = h("form", { id: "refit", onsubmit: async (e) => {
    e.preventDefault();
    const cost_functions = COSTS.filter((c) => $(`refit-${c}`).checked);
    const body = { cost_functions, method: $("refit-method").value };
    const seed = $("refit-seed").value.trim();
    if (seed) body.seed = Number(seed);
    if ($("refit-stale").checked) body.allow_stale_reference = true;
    const answer = await act($("refit-go"), `/scans/${scanId}/refit`, body);
    if (answer) setBanner(`Fits ${answer.fits.join(", ")} queued; this page shows them when they are done (reload).`);
  } },
  h("div", { class: "form-row" }, COSTS.map((c) => [
    h("input", { type: "checkbox", id: `refit-${c}`, checked: true }), h("label", { for: `refit-${c}` }, c)]),
  h("label", { for: "refit-method" }, "method"),
  h("select", { id: "refit-method" }, h("option", { value: "separable" }, "separable"), h("option", { value: "paper" }, "paper (GA)")),
  h("label", { for: "refit-seed" }, "seed"), h("input", { id: "refit-seed", inputmode: "numeric", size: 6 }),
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
  if (status && status.busy) {
    const op = status.busy.operation;
    live = op.kind === "scan" ? newLive("scan", op.scan, "") : newLive("reference", op.reference, "");
  }
  connectEvents();
  await route();
  requestAnimationFrame(() => {
    const paint = performance.getEntriesByType("paint").find((p) => p.name === "first-contentful-paint");
    metrics.firstRenderMs = paint ? paint.startTime : performance.now();
  });
}

start();
