// The status page: polls the JSON API every 2 s and redraws. No libraries, no
// network access beyond this server, text only through textContent.
"use strict";

const PERIOD_MS = 2000;
const ALARM_BITS = new Set(["trip", "error", "trip_lock", "warning", "fault", "alarm",
  "voltage_exceeded", "torque_exceeded", "timer_exceeded"]);
// A value is stale when it is older than this many seconds (3 refreshes of a slow poll).
const STALE_SECONDS = 30;

function el(tag, attrs, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(attrs || {})) {
    if (key === "class") node.className = value;
    else node.setAttribute(key, value);
  }
  for (const child of children) {
    node.append(child instanceof Node ? child : document.createTextNode(String(child)));
  }
  return node;
}

function age(seconds) {
  if (seconds < 60) return `${Math.max(0, Math.round(seconds))} s`;
  if (seconds < 3600) return `${Math.round(seconds / 60)} min`;
  return `${(seconds / 3600).toFixed(1)} h`;
}

function words(name) {
  return name.replace(/_/g, " ");
}

function drawLive(drives) {
  const slaves = drives.filter((d) => d.dp);
  const section = document.getElementById("live");
  section.hidden = slaves.length === 0;
  const rows = slaves.map((d) => {
    const dp = d.dp;
    const ident = dp.ident === null ? "-" : `0x${dp.ident.toString(16).padStart(4, "0")}`;
    const owner = dp.owner === null ? "none" : `${dp.owner}`;
    const diag = dp.diagnosed === null ? "none read yet"
      : (dp.diagnosis.length ? dp.diagnosis.join(", ") : "no flag set");
    return el("tr", { "data-slave": d.name, class: dp.state === "data_exchange" ? "" : "bad" },
      el("td", {}, d.name), el("td", {}, d.line), el("td", { class: "num" }, d.address),
      el("td", {}, words(dp.state)), el("td", {}, ident), el("td", {}, owner),
      el("td", {}, diag));
  });
  section.querySelector("tbody").replaceChildren(...rows);
}

function drawLines(lines) {
  const body = document.querySelector("#lines tbody");
  const rows = lines.map((line) => {
    const busy = line.utilisation === null ? "-" : `${Math.round(line.utilisation * 100)} %`;
    return el("tr", { "data-line": line.name },
      el("td", {}, line.name),
      el("td", { class: line.open ? "" : "bad" }, line.open ? "open" : "closed"),
      el("td", { class: "num" + (line.drives_up < line.drives ? " bad" : "") },
        `${line.drives_up} / ${line.drives}`),
      el("td", { class: "num busy" }, busy));
  });
  body.replaceChildren(...rows);
}

// The values' last 15 minutes (/api/v1/trends), fetched every 15 s: drive -> name -> points.
let trendData = {};
let trendsFetched = 0;  // when they were last asked for
let trendsVersion = 0;  // counts the trends that arrived: a row draws its sparkline anew
const TREND_PERIOD_MS = 15000;
const SVG = "http://www.w3.org/2000/svg";

function sparkline() {  // one per value, made once; drawTrend draws its line
  const svg = document.createElementNS(SVG, "svg");
  svg.setAttribute("class", "spark");
  svg.setAttribute("viewBox", "0 0 120 24");
  svg.setAttribute("width", "120");
  svg.setAttribute("height", "24");
  const line = document.createElementNS(SVG, "path");
  const title = document.createElementNS(SVG, "title");
  svg.append(line, title);
  return { svg, line, title };
}

function drawTrend(spark, points) {
  const known = points.filter((v) => v !== null);
  if (known.length < 2) {
    spark.line.removeAttribute("d");
    spark.title.textContent = "";
    return;
  }
  const low = Math.min(...known), high = Math.max(...known);
  const span = high - low || 1;
  let path = "", pen = "M";
  points.forEach((v, i) => {
    if (v === null) { pen = "M"; return; }
    const x = (i / (points.length - 1)) * 118 + 1;
    const y = 22 - ((v - low) / span) * 20;
    path += `${pen}${x.toFixed(1)},${y.toFixed(1)} `;
    pen = "L";
  });
  spark.line.setAttribute("d", path.trim());
  spark.title.textContent = `last 15 min: ${low} to ${high}`;
}

async function refreshTrends() {
  if (Date.now() - trendsFetched < TREND_PERIOD_MS) return;
  trendsFetched = Date.now();
  trendData = await getJson("api/v1/trends");
  trendsVersion += 1;
}

// A value's row: its cells are made once and filled at each refresh (fillRow).
function valueRow(name) {
  const spark = sparkline();
  const cells = { title: el("td", { class: "title" }), value: el("td", { class: "num value" }),
    age: el("td", { class: "num age" }) };
  const row = el("tr", { "data-parameter": name }, el("td", {}, name), cells.title,
    cells.value, el("td", { class: "trend" }, spark.svg), cells.age);
  return { row, spark, ...cells, drawnTrends: -1 };
}

function setText(node, text) {  // only a change touches the page
  if (node.textContent !== text) node.textContent = text;
}

function fillRow(r, drive, v, now) {
  const seconds = now - v.timestamp;
  const shown = v.shown || `${v.value}`;  // to its resolution; the API keeps full precision
  const cls = seconds > STALE_SECONDS || !drive.up ? "stale" : "";
  if (r.row.className !== cls) r.row.className = cls;
  setText(r.title, v.name || "");
  setText(r.value, v.unit ? `${shown} ${v.unit}` : shown);
  if (r.value.title !== `${v.value}`) r.value.title = `${v.value}`;
  setText(r.age, age(seconds));
  if (r.drawnTrends !== trendsVersion) {  // the sparklines change with the trends, every 15 s
    const name = r.row.dataset.parameter;
    drawTrend(r.spark, (trendData[drive.name] || {})[name] || []);
    r.drawnTrends = trendsVersion;
  }
}

// The drive's heading, status bits and alarms: what makes its section's shape. Its
// counts, values and ages are filled in place, and it folds in place; a new shape draws
// the section anew.
function shapeOf(drive) {
  return JSON.stringify([drive.up, drive.line, drive.address, drive.protocol, drive.status_word,
    drive.status, drive.alarms, drive.maintenance,
    drive.values.map((v) => [v.parameter, v.index])]);
}

function fillCounts(section, drive) {
  const { faults, errors } = section;
  setText(faults, `${drive.faults} faults`);
  faults.className = drive.faults ? "alarm" : "";
  setText(errors, `${drive.telegram_errors} telegram errors`);
  errors.className = drive.telegram_errors ? "alarm" : "";
}

function drawDrive(drive) {
  const bits = Object.entries(drive.status || {}).filter(([, on]) => on)
    .map(([name]) => el("span", { class: ALARM_BITS.has(name) ? "alarm" : "" }, words(name)));
  const rows = drive.values.map((v) => valueRow(v.index ? `${v.parameter}[${v.index}]` : v.parameter));
  const alarms = (drive.alarms || []).map((a) => {
    const since = new Date(a.since * 1000).toLocaleString();
    return el("li", { class: a.kind === "alarm" ? "alarm" : "warning", "data-code": a.code },
      `${a.kind} ${a.code}`, a.text ? ` ${a.text}` : "", ` (${a.parameter}, since ${since})`);
  });
  const word = drive.status_word === null ? "no status word"
    : `status word 0x${drive.status_word.toString(16).padStart(4, "0")}`;
  const fold = el("button", { class: "fold", type: "button", title: "fold or unfold" },
    folded.has(drive.name) ? "+" : "\u2212");
  const held = drive.maintenance;  // nothing goes out to it: neither up nor down
  const state = held ? "maintenance" : (drive.up ? "up" : "down");
  const cls = `drive ${state}${folded.has(drive.name) ? " folded" : ""}`;
  const faults = el("span", {}), errors = el("span", {});
  const settings = el("div", { class: "settings" });  // drawSettings fills it
  settings.hidden = true;
  const heldNote = held ? el("p", { class: "maintenance" },
    `in maintenance since ${new Date(held.since * 1000).toLocaleString()}`,
    held.reason ? `: ${held.reason}` : "", " - nothing goes out to it") : "";
  const node = el("div", { class: cls, "data-drive": drive.name },
    el("h3", {}, fold, ` ${drive.name} `, el("span", { class: "state" }, state),
      ` - line ${drive.line}, address ${drive.address}, ${drive.protocol}, ${word}`),
    heldNote,
    el("div", { class: "counts" }, faults, errors, " since the service started"),
    el("div", { class: "bits" }, ...bits),
    alarms.length ? el("ul", { class: "alarms" }, ...alarms) : "",
    settings,
    el("table", {}, el("thead", {}, el("tr", {}, el("th", {}, "parameter"), el("th", {}, "name"),
      el("th", {}, "value"), el("th", {}, "15 min"), el("th", {}, "age"))),
      el("tbody", {}, ...rows.map((r) => r.row))));
  fold.addEventListener("click", () => {  // folds in place: the button keeps its focus
    const now = !folded.has(drive.name);
    if (now) folded.add(drive.name); else folded.delete(drive.name);
    node.classList.toggle("folded", now);
    fold.textContent = now ? "+" : "\u2212";
  });
  return { node, rows, faults, errors, settings, sweptAge: null, drawnSettings: -1 };
}

// Drives folded by the reader (kept across refreshes); drives down or in alarm come first.
const folded = new Set();

function urgency(drive) {
  if (drive.maintenance) return 3;  // nothing is asked of it: not urgent
  if (!drive.up) return 0;
  if ((drive.alarms || []).some((a) => a.kind === "alarm")) return 1;
  if ((drive.alarms || []).length || changedSettings(drive.name).length) return 2;
  return 3;
}

// The token for the audit log: in this variable only (no storage), for this page's life.
let auditToken = "";

function drawWrites(entries) {
  const rows = entries.map((e) => {
    const when = new Date(e.time * 1000).toLocaleString();
    const where = e.index ? `${e.parameter}[${e.index}]` : e.parameter;
    const change = e.count ? `${e.count} refused` : `${e.old_value ?? "?"} \u2192 ${e.new_value ?? "?"}`;
    return el("tr", { class: e.outcome === "ok" ? "" : "bad" },
      el("td", {}, when), el("td", {}, e.drive || "-"), el("td", {}, where || "-"),
      el("td", {}, change), el("td", {}, e.outcome), el("td", {}, e.client || ""));
  });
  const table = document.getElementById("audit");
  table.querySelector("tbody").replaceChildren(...rows);
  table.hidden = false;
}

async function refreshWrites() {
  if (!auditToken) return;
  const response = await fetch("api/v1/audit?limit=10", {
    cache: "no-store", headers: { Authorization: `Bearer ${auditToken}` } });
  if (response.status === 401 || response.status === 403) {
    auditToken = "";
    document.getElementById("audit").hidden = true;
    throw new Error("the token was refused");
  }
  if (response.ok) drawWrites(await response.json());
}

document.getElementById("token-form").addEventListener("submit", (event) => {
  event.preventDefault();
  const input = document.getElementById("token");
  auditToken = input.value.trim();
  input.value = "";
  refreshWrites().catch((error) => showResult(`token: ${error.message}`, true));
});

// The write form: the writable parameters of every drive, kept across refreshes.
let writables = new Map();  // "drive/parameter[index]" -> {drive, w}
let pending = null;  // the write waiting for its confirmation: {key, value}

function writeKey(drive, w) {
  return `${drive}/${w.parameter}` + (w.index ? `[${w.index}]` : "");
}

function describeWritable(w) {
  const unit = w.unit ? ` ${w.unit}` : "";
  const option = w.value === null ? undefined : (w.options || {})[w.value];
  const shown = option ? `${option} [${w.value}]` : `${w.value}`;
  const now = w.value === null ? "not read yet" : `now ${shown}${unit}`;
  const low = w.minimum === null ? "" : `${w.minimum}`;
  const high = w.maximum === null ? "" : `${w.maximum}`;
  const limits = low || high ? `, limits ${low || "-"} to ${high || "-"}${unit}` : "";
  const options = Object.entries(w.options || {}).map(([n, text]) => `${n} ${text}`).join(", ");
  const listed = options ? `; options ${options}` : "";
  return `${w.name ? w.name + ": " : ""}${now}${limits}${listed}`;
}

function drawWritable(drives) {
  const select = document.getElementById("write-target");
  const chosen = select.value;
  writables = new Map();
  const options = [];
  for (const d of drives) {
    for (const w of d.writable || []) {
      const key = writeKey(d.name, w);
      writables.set(key, { drive: d.name, w });
      options.push(el("option", { value: key }, key));
    }
  }
  if (options.length === 0) options.push(el("option", { value: "" }, "(none writable)"));
  select.replaceChildren(...options);
  if (writables.has(chosen)) select.value = chosen;
  const item = writables.get(select.value);
  document.getElementById("write-now").textContent = item ? describeWritable(item.w) : "";
}

function showResult(text, bad) {
  const out = document.getElementById("write-result");
  out.textContent = text;
  out.className = bad ? "bad" : "ok";
  out.hidden = false;
}

async function submitWrite(event) {
  event.preventDefault();
  const button = document.getElementById("write-button");
  const key = document.getElementById("write-target").value;
  const raw = document.getElementById("write-value").value.trim();
  const item = writables.get(key);
  if (!item || raw === "") return showResult("choose a parameter and type its new value", true);
  if (!auditToken) return showResult("type the write token below first", true);
  const value = item.w.text ? raw : Number(raw);
  if (!item.w.text && !Number.isFinite(value)) return showResult(`${raw} is not a number`, true);
  if (!pending || pending.key !== key || pending.value !== value) {
    pending = { key, value };
    const old = item.w.value === null ? "?" : item.w.value;
    button.textContent = `Confirm: ${old} \u2192 ${value}${item.w.unit ? " " + item.w.unit : ""}`;
    return;
  }
  pending = null;
  button.textContent = "Write";
  const index = item.w.index ? `?index=${item.w.index}` : "";
  const response = await fetch(
    `api/v1/drives/${encodeURIComponent(item.drive)}/parameters/` +
      `${encodeURIComponent(item.w.parameter)}${index}`,
    { method: "PUT", cache: "no-store",
      headers: { Authorization: `Bearer ${auditToken}`, "Content-Type": "application/json" },
      body: JSON.stringify({ value }) });
  const body = await response.json().catch(() => ({}));
  if (response.ok) {
    const unit = body.unit ? ` ${body.unit}` : "";
    const shown = body.value === null || body.value === undefined ? value : body.value;
    showResult(`${key}: written ${shown}${unit} (the drive's answer; audit entry ${body.audit_id})`,
      false);
  } else {
    const error = body.error || {};
    showResult(`${key}: refused (${response.status} ${error.kind || ""}): ` +
      `${error.message || response.statusText}`, true);
  }
  refreshWrites().catch(() => {});
}

document.getElementById("write-form").addEventListener("submit", (event) => {
  submitWrite(event).catch((error) => showResult(`no answer from pkwbus (${error.message})`, true));
});
document.getElementById("write-target").addEventListener("change", () => {
  pending = null;
  document.getElementById("write-button").textContent = "Write";
  const item = writables.get(document.getElementById("write-target").value);
  document.getElementById("write-now").textContent = item ? describeWritable(item.w) : "";
});

// The drives' own log entries (/api/v1/events), the newest 20, fetched every 10 s.
const EVENTS_EVERY_MS = 10000;
let eventsAt = 0;
const TIME_FROM = { runtime: "the drive's runtime", drive_clock: "the drive's clock",
  seen: "when read" };

// Red: a trip, or a setting nobody audited; a SINAMICS alarm (A-number) is a warning's kind.
const BAD_EVENTS = new Set(["fault", "setting"]);

function drawEvents(events) {
  const rows = events.map((e) => el("tr", { class: BAD_EVENTS.has(e.kind) ? "bad" : "" },
    el("td", {}, new Date(e.time).toLocaleString()), el("td", {}, e.drive),
    el("td", {}, e.kind), el("td", {}, e.text ? `${e.code} ${e.text}` : e.code),
    el("td", {}, e.value ?? ""), el("td", {}, TIME_FROM[e.time_source] || e.time_source)));
  const section = document.getElementById("events");
  section.querySelector("tbody").replaceChildren(...rows);
  section.hidden = rows.length === 0;
}

async function refreshEvents() {
  if (Date.now() - eventsAt < EVENTS_EVERY_MS) return;
  eventsAt = Date.now();
  drawEvents((await getJson("api/v1/events?limit=20")).events || []);
}

// The settings of each drive that differ from its baseline (/api/v1/drives/{drive}/settings),
// asked for every 30 s, a few drives at a time and beside the 2 s redraws, not in them. A
// drive whose settings are not swept (404 not_swept) has nothing to show: asked again
// only after 10 minutes.
const SETTINGS_EVERY_MS = 30000;
const NOT_SWEPT_AGAIN_MS = 600000;
const SETTINGS_AT_ONCE = 4;
let settingsAt = 0;  // when they were last asked for
let settingsBusy = false;  // a round is under way
let settingsVersion = 0;  // counts the rounds that arrived: a section draws its settings anew
let settingsData = new Map();  // drive -> {swept, every, count, changed}
const notSwept = new Map();  // drive -> when pkwbus said its settings are not swept

function changedSettings(name) {
  const found = settingsData.get(name);
  return found ? found.changed : [];
}

async function settingsOf(name) {  // what to show of one drive's settings; null: nothing
  const path = `api/v1/drives/${encodeURIComponent(name)}/settings`;
  const response = await fetch(path, { cache: "no-store" });
  if (response.status === 404) {
    const body = await response.json().catch(() => ({}));
    if ((body.error || {}).kind === "not_swept") notSwept.set(name, Date.now());
    return null;
  }
  if (!response.ok) throw new Error(`${path}: ${response.status}`);
  const view = await response.json();
  const parameters = view.parameters || [];
  return { swept: view.swept, every: view.every, count: parameters.length,
    changed: parameters.filter((p) => p.changed) };
}

async function refreshSettings(names) {
  if (settingsBusy || Date.now() - settingsAt < SETTINGS_EVERY_MS) return;
  settingsAt = Date.now();
  settingsBusy = true;
  const found = new Map();
  try {
    const asked = names.filter((n) => {
      const said = notSwept.get(n);
      return said === undefined || Date.now() - said >= NOT_SWEPT_AGAIN_MS;
    });
    let next = 0;
    const worker = async () => {
      while (next < asked.length) {
        const name = asked[next++];
        try {
          const view = await settingsOf(name);
          if (view) {
            found.set(name, view);
            notSwept.delete(name);
          }
        } catch (error) {  // no answer this time: the last one stays
          if (settingsData.has(name)) found.set(name, settingsData.get(name));
        }
      }
    };
    await Promise.all(Array.from({ length: SETTINGS_AT_ONCE }, worker));
  } finally {
    settingsBusy = false;
  }
  settingsData = found;
  settingsVersion += 1;
  refreshNow();  // shown now, not at the next redraw
}

function shownSetting(value, unit) {
  if (value === null || value === undefined) return "?";
  return unit ? `${value} ${unit}` : `${value}`;
}

function drawSettings(section, found) {
  const box = section.settings;
  section.sweptAge = null;
  if (!found) {
    box.replaceChildren();
    box.hidden = true;
    return;
  }
  const changed = found.changed;
  const differ = changed.length
    ? el("span", { class: "alarm" },
      `${changed.length} of ${found.count} settings differ from the baseline`)
    : `none of ${found.count} settings differs from the baseline`;
  let sweep = "no complete sweep of the settings yet";
  if (found.swept) {
    section.sweptAge = el("span", { class: "swept-age" });
    sweep = el("span", {}, `last complete sweep ${new Date(found.swept).toLocaleString()} (`,
      section.sweptAge, " ago)");
  }
  const every = found.every ? `, every ${age(found.every)}` : "";
  const parts = [el("p", { class: "sweep" }, differ, "; ", sweep, every)];
  if (changed.length) {
    const rows = changed.map((p) => {
      const where = p.index ? `${p.parameter}[${p.index}]` : p.parameter;
      const when = (iso) => (iso ? new Date(iso).toLocaleString() : "?");
      const value = el("td", { class: "value" }, shownSetting(p.value, p.unit));
      if (p.raw !== null && p.raw !== undefined) value.title = `raw ${p.raw}`;
      return el("tr", { "data-parameter": where }, el("td", {}, where),
        el("td", { class: "title" }, p.name || ""), value,
        el("td", { class: "baseline" }, shownSetting(p.baseline, p.unit)),
        el("td", { class: "baseline-since" }, when(p.baseline_since),
          p.baseline_by ? ` (${p.baseline_by})` : ""),
        el("td", { class: "since" }, when(p.changed_seen)));
    });
    parts.push(el("table", { class: "changed" },
      el("thead", {}, el("tr", {}, el("th", {}, "setting changed"), el("th", {}, "name"),
        el("th", {}, "value"), el("th", {}, "baseline"), el("th", {}, "baseline since"),
        el("th", {}, "differs since"))),
      el("tbody", {}, ...rows)));
    parts.push(el("p", { class: "note" }, "not written through pkwbus (keypad, another ",
      "master?): a wanted change becomes the baseline with PUT api/v1/drives/",
      section.node.dataset.drive, "/settings/baseline (write token); a write through pkwbus ",
      "moves the baseline itself"));
  }
  box.replaceChildren(...parts);
  box.hidden = false;
}

function fillSettings(section, drive, now) {
  const found = settingsData.get(drive.name);
  if (section.drawnSettings !== settingsVersion) {
    drawSettings(section, found);
    section.drawnSettings = settingsVersion;
  }
  if (section.sweptAge && found && found.swept) {
    setText(section.sweptAge, age(now - Date.parse(found.swept) / 1000));
  }
}

async function getJson(path) {
  const response = await fetch(path, { cache: "no-store" });
  if (!response.ok && response.status !== 503) throw new Error(`${path}: ${response.status}`);
  return response.json();
}

let lastDrives = [];

// Each drive's section, kept across refreshes: name -> {shape, node, rows}.
let sections = new Map();
const drivesHeading = el("h2", {}, "Drives");

function refreshNow() {  // the drives from the last data: down or in alarm first, as folded
  const now = Date.now() / 1000;
  const kept = new Map();
  const nodes = lastDrives.map((d, i) => [urgency(d), i, d])
    .sort((a, b) => a[0] - b[0] || a[1] - b[1])
    .map(([, , d]) => {
      const shape = shapeOf(d);
      let section = sections.get(d.name);
      if (!section || section.shape !== shape) section = { shape, ...drawDrive(d) };
      fillCounts(section, d);
      fillSettings(section, d, now);
      d.values.forEach((v, i) => fillRow(section.rows[i], d, v, now));
      kept.set(d.name, section);
      return section.node;
    });
  sections = kept;
  const box = document.getElementById("drives");
  const shown = box.children;
  const same = shown.length === nodes.length + 1 && nodes.every((n, i) => shown[i + 1] === n);
  if (!same) box.replaceChildren(drivesHeading, ...nodes);
}

async function refresh() {
  const problem = document.getElementById("problem");
  try {
    const [lines, drives, ready] = await Promise.all(
      [getJson("api/v1/lines"), getJson("api/v1/drives"), getJson("readyz")]);
    await refreshTrends().catch(() => {});  // the sparklines wait for the next try
    await refreshEvents().catch(() => {});  // so do the log entries
    drawLines(lines);
    lastDrives = drives;
    // Only the drives whose settings are swept (the drive's view says so): beside the redraw.
    refreshSettings(drives.filter((d) => d.settings).map((d) => d.name)).catch(() => {});
    refreshNow();
    drawWritable(drives);
    drawLive(drives);
    problem.hidden = ready.writes !== false;
    problem.textContent = ready.reason || "";
    await refreshWrites();
    document.getElementById("updated").textContent =
      `updated ${new Date().toLocaleTimeString()}`;
  } catch (error) {
    problem.hidden = false;
    problem.textContent = `no answer from pkwbus (${error.message}): showing the last data`;
  } finally {
    setTimeout(refresh, PERIOD_MS);
  }
}

refresh();
